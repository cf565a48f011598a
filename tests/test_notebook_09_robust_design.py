"""Notebook 09_robust_design.ipynb runs top to bottom in quick mode (JAXROD_QUICK=1, see
notebooks/README.md) and shows what it must: a nominal design whose snap angles meet two
targets, the statistics of strips made with a scatter of fold angle, gap and clamp alignment,
the clamp misalignment's eps^(2/3) law at the branch point, a robust design at the 0.9 quantile
confirmed by the independent check, and the two designs' snap angles side by side."""

import pytest

pytest.importorskip("nbclient")
pytest.importorskip("nbformat")

from helpers import notebook_images, notebook_record, notebook_text, run_notebook  # noqa: E402

# nightly (`pytest -m slow`), like the other notebooks: a robust design is minutes on 2 cores;
# CI checks the scatter, the imperfections and the quantiles in test_scatter.py,
# test_imperfections.py and test_robust.py
pytestmark = pytest.mark.slow


def test_notebook_09_robust_design():
    nb = run_notebook("09_robust_design.ipynb")
    out = notebook_text(nb)
    assert "quick mode" in out and "Traceback" not in out
    rec = notebook_record(nb, "ROBUST")
    nom, rob = rec["nominal"], rec["robust"]
    assert nom["result"] == "successful" and rob["result"] == "successful"
    # the robust design meets its quantiles on its draws, and its nominal strip lies inside the targets
    assert abs(rob["quantiles"][0] - 69.0) < 0.05 and abs(rob["quantiles"][1] - 73.5) < 0.05
    # (the snap down's nominal lies inside its target; the snap up's need not: a misalignment
    # only ever makes the branch point come earlier, so the up quantile can sit near the nominal)
    assert rob["nominal"][1] < 73.5
    # on the same fresh draws, the robust design snaps by the targets more often than the nominal one
    assert rob["p_up"] + rob["p_down"] > nom["p_up"] + nom["p_down"] + 0.2
    # the misalignment: Koiter's law at the up branch point, a fold's eps^2 for the snap down
    mis = rec["misalignment"]
    assert mis["up_kind"] == "branch_point" and abs(mis["up_exponent"] - 2 / 3) < 0.03
    assert mis["down_kind"] == "fold" and abs(mis["down_exponent"] - 2.0) < 0.05
    # one at a time: each scatter spreads the snap up; the misalignment leaves the snap down's fold alone
    assert all(v[0] > 0 for v in rec["alone"].values())
    assert rec["alone"]["misalignment +- 0.5 deg"][1] < 0.1 * rec["alone"]["misalignment +- 0.5 deg"][0]
    assert len(notebook_images(nb)) == 2
