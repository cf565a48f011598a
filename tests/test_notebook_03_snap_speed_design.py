"""Notebook 03_snap_speed_design.ipynb runs top to bottom in quick mode (JAXROD_QUICK=1, see
notebooks/README.md) and prints what it must. One file per notebook, so that the xdist
workers share them out (tests/conftest.py schedules the slowest first).

The notebook's gradient cell checks d v_s / d(Psi0, G, s0) against central differences
(jacfwd through snap_speed's custom JVP at N = 16, FD steps 3e-4, 1e-4, 1e-5); the CI set
checks the same in test_design_speed.py::test_snap_speed_gradient_matches_central_differences."""

import re

import numpy as np
import pytest

pytest.importorskip("nbclient")
pytest.importorskip("nbformat")

from helpers import notebook_text, run_notebook  # noqa: E402


# nightly (`pytest -m slow`): the notebook compiles most of the library afresh in its own kernel,
# 2-5 min on 2 cores; the CI set checks the same library calls in the unit tests
pytestmark = pytest.mark.slow


def test_notebook_03_snap_speed_design():
    out = notebook_text(run_notebook("03_snap_speed_design.ipynb"))
    assert "quick mode" in out and "target reached" in out and "target not reached" in out
    assert "fastest snap found" in out
    m = re.search(r"relative differences: \[([^\]]*)\]", out)
    assert m, out
    rel = np.array([float(x) for x in m.group(1).split()])
    assert rel.shape == (3,) and np.all(np.isfinite(rel)) and np.all(rel < 1e-4), rel
