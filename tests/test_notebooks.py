"""Every notebook is committed executed, with its outputs; each notebook is executed again in
quick mode by its own test file (tests/test_notebook_*.py)."""

from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")

NB = Path(__file__).resolve().parent.parent / "notebooks"


def test_every_notebook_has_its_test():
    here = Path(__file__).resolve().parent
    for path in sorted(NB.glob("*.ipynb")):
        assert (here / f"test_notebook_{path.stem}.py").exists(), path.name


def test_notebooks_committed_executed():
    """Committed with their outputs (so that the repository's page and the documentation site
    show their figures): every code cell executed, in order, in one run, none with an error,
    and at least one figure (`python notebooks/execute.py` writes them)."""
    for path in sorted(NB.glob("*.ipynb")):
        nb = nbformat.read(path, as_version=4)
        code = [c for c in nb.cells if c.cell_type == "code" and c.source.strip()]
        counts = [c.get("execution_count") for c in code]
        assert counts == list(range(1, len(code) + 1)), (path.name, counts)
        for c in code:
            for o in c.get("outputs", []):
                assert o.output_type != "error", (path.name, o.get("ename"))
        images = [o for c in code for o in c.get("outputs", []) if "image/png" in o.get("data", {})]
        assert images, path.name


def test_output_readers():
    """The readers the notebook tests use on an executed notebook: `notebook_record` takes the
    last `TAG {json}` line of the stream outputs (not a similar line of another tag, not the
    source), `notebook_images` decodes the displayed PNGs in order."""
    import base64

    from helpers import notebook_images, notebook_record, notebook_text

    v4 = nbformat.v4
    png = b"\x89PNG\r\n\x1a\n" + bytes(range(40))
    cells = [v4.new_markdown_cell('TAG {"x": 0}'),
             v4.new_code_cell('print("TAG")', outputs=[v4.new_output("stream", text='TAG {"x": 1}\nTAGS {"x": 9}\n')]),
             v4.new_code_cell("", outputs=[v4.new_output("display_data", data={
                 "image/png": base64.b64encode(png).decode(), "text/plain": "<Image>"})]),
             v4.new_code_cell("", outputs=[v4.new_output("stream", text='noise\nTAG {"x": 2, "y": [1.5]}\n')])]
    nb = v4.new_notebook(cells=cells)
    assert notebook_record(nb, "TAG") == {"x": 2, "y": [1.5]} and notebook_record(nb, "TAGS") == {"x": 9}
    assert notebook_images(nb) == [png]
    assert "noise" in notebook_text(nb) and "TAG {\"x\": 0}" not in notebook_text(nb)
    with pytest.raises(AssertionError, match="OTHER"):
        notebook_record(nb, "OTHER")


def test_no_notebook_rebinds_a_module_it_imports():
    """A module imported under a name (`import jaxrod.paper as paper`) is not bound again by a
    later cell (`paper = lambda ...`), which would break every use after it (no kernel run)."""
    import ast

    for path in sorted(NB.glob("*.ipynb")):
        nb = nbformat.read(path, as_version=4)
        source = "\n".join(c.source for c in nb.cells if c.cell_type == "code")
        source = "\n".join(line for line in source.splitlines() if not line.lstrip().startswith(("%", "!")))
        tree = ast.parse(source)
        modules = {(a.asname or a.name).split(".")[0] for node in ast.walk(tree)
                   if isinstance(node, ast.Import) for a in node.names}
        modules |= {a.asname or a.name for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
                    for a in node.names}
        bound = set()
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
                bound.add(node.name)
            elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
                bound.add(node.id)
        assert not modules & bound, (path.name, sorted(modules & bound))
