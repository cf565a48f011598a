"""Notebook 01_getting_started.ipynb runs top to bottom in quick mode (JAXROD_QUICK=1, see
notebooks/README.md), and what it prints and draws is checked against values it did not
compute: the critical angles against the committed convergence study
(benchmarks/results/convergence_alpha_c.json, predicted at the notebook's N = 40), the two
figures' data (read from the kernel by one appended cell) against the printed states, the
clamps and the strip's length. One file per notebook, so that the xdist workers share them
out (tests/conftest.py schedules the slowest first)."""

import math
import re

import numpy as np
import pytest

pytest.importorskip("nbclient")
pytest.importorskip("nbformat")

from helpers import alpha_c_benchmark, notebook_record, notebook_text, run_notebook  # noqa: E402

# Appended to the executed copy: the lines of every open figure (matplotlib's Agg backend
# keeps them), so the test sees what was drawn.
FIGURES = """
import json as _json
print("NBTEST " + _json.dumps({"N": N, "gap": float(scene.clamps.gap), "figures": [
    [{"label": l.get_label(), "x": np.asarray(l.get_xdata(), float).tolist(),
      "y": np.asarray(l.get_ydata(), float).tolist()} for a in plt.figure(k).axes for l in a.get_lines()]
    for k in plt.get_fignums()]}))
"""

NUM = r"([-+]?\d+\.?\d*(?:[eE][-+]?\d+)?)"

# nightly (`pytest -m slow`), like the other notebooks: 32 s on 2 cores in its own kernel; CI checks
# the same library calls (states, stability, hysteresis, snap angles) in the unit tests
pytestmark = pytest.mark.slow


def test_notebook_01_getting_started():
    check(run_notebook("01_getting_started.ipynb", extra_cells=[FIGURES]))


def check(nb):
    out = notebook_text(nb)
    rec = notebook_record(nb, "NBTEST")
    assert "quick mode N = 40" in out and rec["N"] == 40 and rec["gap"] == 0.5
    n = rec["N"]

    # the states at alpha = 0: found, on their sides
    states = {m.group(1): (m.group(2), float(m.group(3)), float(m.group(4))) for m in re.finditer(
        rf"^(up|down) (\S+) fold height {NUM} bending energy {NUM}$", out, re.M)}
    assert set(states) == {"up", "down"}, out
    assert states["up"][0] == states["down"][0] == "successful"
    h_up, h_down = states["up"][1], states["down"][1]
    assert h_up > 0.2 and h_down < -0.2, states
    assert all(e > 0 for _, _, e in states.values())

    # stability of the down state: the smallest eigenvalues, positive and ascending; each mode
    # symmetric or antisymmetric (parity +-1, the mirror symmetry)
    m = re.search(r"eigenvalues \[([^\]]*)\] parity \[([^\]]*)\] stable (True|False)", out)
    assert m, out
    eig, par = np.array(m.group(1).split(), float), np.array(m.group(2).split(), float)
    assert eig.shape == par.shape == (4,) and m.group(3) == "True"
    assert np.all(eig > 0) and np.all(np.diff(eig) >= 0), eig
    np.testing.assert_allclose(np.abs(par), 1.0, atol=1e-3)

    # the critical angles against the committed convergence study, at N = 40: the mesh's own
    # error there is ~0.6 deg (~1000 deg / N^2), the prediction's uncertainty 0.015 deg
    up_ref, down_ref, kind_up, kind_down = alpha_c_benchmark(60.0, 0.5, n)
    snaps = {m.group(1): (float(m.group(2)), m.group(3), float(m.group(4)), float(m.group(5))) for m in re.finditer(
        rf"snap (up|down): alpha_c = {NUM} deg, kind (\w+), fold height {NUM} -> {NUM}", out)}
    assert set(snaps) == {"up", "down"}, out
    assert snaps["up"][0] == pytest.approx(up_ref, abs=0.03), (snaps, up_ref)
    assert snaps["down"][0] == pytest.approx(down_ref, abs=0.03), (snaps, down_ref)
    assert (snaps["up"][1], snaps["down"][1]) == (kind_up, kind_down)
    # each snap lands in the other state; the paper: the snap down is the smaller jump
    (_, _, b_up, a_up), (_, _, b_dn, a_dn) = snaps["up"], snaps["down"]
    assert b_up < 0 < a_up and b_dn > 0 > a_dn, snaps
    assert abs(a_dn - b_dn) < abs(a_up - b_up)

    # figure 1: the two states as drawn, N + 1 nodes from the left clamp (0, 0) to the right
    # one (G, 0), segments of length L / N (inextensible, L = 1), the fold node at the
    # printed fold height
    shapes, loops = rec["figures"]
    assert [ln["label"] for ln in shapes] == ["up", "down"]
    for ln, h in zip(shapes, (h_up, h_down)):
        x, y = np.array(ln["x"]), np.array(ln["y"])
        assert x.shape == y.shape == (n + 1,)
        np.testing.assert_allclose([x[0], y[0], x[-1], y[-1]], [0.0, 0.0, rec["gap"], 0.0], atol=1e-9)
        np.testing.assert_allclose(np.hypot(np.diff(x), np.diff(y)), 1.0 / n, rtol=1e-9)
        assert y[n // 2] == pytest.approx(h, rel=1e-9)
    # figure 2: each path's branch (the first continuation stage, up to its first unstable
    # point) starts at alpha = 0 in its start state (the snap-up path in the down state printed
    # above, found there by snap_angles' own homotopy), advances monotonically to alpha_c on
    # one side; past a fold the branch turns back in alpha (what a fold is), past a branch point
    # it goes on; the dotted jump stands at the printed alpha_c, from the printed critical fold
    # height to the landing one
    branches = [ln for ln in loops if ln["label"].startswith("snap")]
    jumps = [ln for ln in loops if not ln["label"].startswith("snap")]
    assert [ln["label"] for ln in branches] == ["snap up (from down)", "snap down (from up)"] and len(jumps) == 2
    for br, jump, name, h0, sign in ((branches[0], jumps[0], "up", h_down, 1.0),
                                     (branches[1], jumps[1], "down", h_up, -1.0)):
        a, y = np.array(br["x"]), np.array(br["y"])
        alpha_c, _, before, after = snaps[name]
        assert len(a) >= 3 and a[0] == 0.0 and y[0] == pytest.approx(h0, rel=1e-6), (name, a[0], y[0], h0)
        assert np.all(sign * np.diff(a[:-1]) > 0) and np.all(np.sign(y) == np.sign(h0)), (name, a, y)
        assert np.all(sign * a[:-1] <= sign * alpha_c + 1e-9) and sign * (alpha_c - a[-2]) < 10.0, (name, a, alpha_c)
        if snaps[name][1] == "fold":
            assert sign * a[-1] < sign * a[-2], (name, a)
        else:
            assert sign * a[-1] > sign * alpha_c, (name, a)
        np.testing.assert_allclose(jump["x"], [alpha_c, alpha_c], atol=1e-3)
        np.testing.assert_allclose(jump["y"], [before, after], atol=1e-3)
    assert math.isfinite(sum(eig))
