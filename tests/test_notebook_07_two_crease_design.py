"""Notebook 07_two_crease_design.ipynb runs top to bottom in quick mode (JAXROD_QUICK=1, see
notebooks/README.md) and prints what it must: the symmetric pair's branch point and the
asymmetric pair's folds, the targets reached with a faster snap, the widest loop at the centre."""

import re

import pytest

pytest.importorskip("nbclient")
pytest.importorskip("nbformat")

from helpers import notebook_text, run_notebook  # noqa: E402

# nightly (`pytest -m slow`): reverse-mode compiles of snap paths and snaps; CI checks the
# crease gradients against central differences (test_creases.py)
pytestmark = pytest.mark.slow


def test_notebook_07_two_crease_design():
    out = notebook_text(run_notebook("07_two_crease_design.ipynb", timeout=900))
    assert "quick mode" in out and "Traceback" not in out
    sym, asym = out.split("asymmetric 0.30/0.65")[0], out.split("asymmetric 0.30/0.65")[1].split("crease heights")[0]
    assert "kind branch_point" in sym and "branch_point" not in asym and asym.count("kind fold") == 2
    assert "reached: True" in out
    m = re.search(r"v_s: (\S+) v\* at the start -> (\S+) v\*", out)
    assert m and float(m.group(2)) > float(m.group(1)), out
    assert re.search(r"widest loop: c = 0\.5000 L \(centre\)", out), out
