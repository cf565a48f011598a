"""Notebook 05_paper_figures.ipynb runs top to bottom in quick mode (JAXROD_QUICK=1, see
notebooks/README.md) and prints what it must. One file per notebook, so that the xdist
workers share them out (tests/conftest.py schedules the slowest first)."""

import pytest

pytest.importorskip("nbclient")
pytest.importorskip("nbformat")

from helpers import notebook_text, run_notebook  # noqa: E402


def test_notebook_05_paper_figures():
    out = notebook_text(run_notebook("05_paper_figures.ipynb"))
    assert "quick mode" in out and "jaxrod's plane:" in out and "which part jumps:" in out
    assert "not available" not in out
