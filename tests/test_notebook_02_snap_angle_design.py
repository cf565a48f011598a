"""Notebook 02_snap_angle_design.ipynb runs top to bottom in quick mode (JAXROD_QUICK=1, see
notebooks/README.md) and prints what it must. One file per notebook, so that the xdist
workers share them out (tests/conftest.py schedules the slowest first)."""

import re

import pytest

pytest.importorskip("nbclient")
pytest.importorskip("nbformat")

from helpers import notebook_text, run_notebook  # noqa: E402


# nightly (`pytest -m slow`): the notebook compiles most of the library afresh in its own kernel,
# 2-5 min on 2 cores; the CI set checks the same library calls in the unit tests
pytestmark = pytest.mark.slow


def test_notebook_02_snap_angle_design():
    out = notebook_text(run_notebook("02_snap_angle_design.ipynb"))
    assert "'reached': True" in out and "target not reached" in out
    assert re.search(r"LM: \d+ iterations, reached True; Adam: \d+ iterations, reached True", out)
