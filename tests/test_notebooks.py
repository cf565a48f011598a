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
