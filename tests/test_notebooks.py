"""Every notebook is committed without outputs; each notebook is executed in quick mode by its
own test file (tests/test_notebook_*.py)."""

from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")

NB = Path(__file__).resolve().parent.parent / "notebooks"


def test_every_notebook_has_its_test():
    here = Path(__file__).resolve().parent
    for path in sorted(NB.glob("*.ipynb")):
        assert (here / f"test_notebook_{path.stem}.py").exists(), path.name


def test_notebooks_committed_without_outputs():
    for path in sorted(NB.glob("*.ipynb")):
        nb = nbformat.read(path, as_version=4)
        for c in nb.cells:
            if c.cell_type == "code":
                assert c.get("outputs", []) == [] and c.get("execution_count") is None, path.name


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
