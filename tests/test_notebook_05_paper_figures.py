"""Notebook 05_paper_figures.ipynb runs top to bottom in quick mode (JAXROD_QUICK=1, see
notebooks/README.md), and the numbers it computes (read back from the `cache.json` it writes
in its output folder, and from its printed rows) are checked against values it did not
compute: the snap angles against the committed convergence study
(benchmarks/results/convergence_alpha_c.json, predicted at the notebook's N = 40, and its
converged values for the Richardson-extrapolated ones), where each master curve ends against
the committed termination gaps (benchmarks/results/termination.json), the snap speeds against
the converged brink snap of benchmarks/results/dynamics.md, the PET speeds in m/s against
v* = (t / L) sqrt(E / (12 rho)) by hand; the figures it displays must be real images. One file
per notebook, so that the xdist workers share them out (tests/conftest.py schedules the
slowest first)."""

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("nbclient")
pytest.importorskip("nbformat")

from helpers import alpha_c_benchmark, notebook_images, notebook_text, run_notebook  # noqa: E402

RESULTS = Path(__file__).resolve().parent.parent / "benchmarks" / "results"
N, N_DYN = 40, 24  # the notebook's quick mode: statics mesh, dynamics mesh
# converged v_s / v* of the brink snap up at Psi0 = 30 deg, G/L = 0.5 (dopri8 rtol 1e-9, N = 200,
# benchmarks/results/dynamics.md; 26.4827 at N = 50); N = 24 is coarse, so within 5 %
V_S_30_05 = 26.3328


# nightly (`pytest -m slow`): the notebook compiles most of the library afresh in its own kernel,
# 2-5 min on 2 cores; the CI set checks the same library calls in the unit tests
pytestmark = pytest.mark.slow


def test_notebook_05_paper_figures():
    check(run_notebook("05_paper_figures.ipynb"))


def _row(out, quantity):
    """The jaxrod column of a printed row `quantity: paper ...; jaxrod VALUE`."""
    m = re.search(rf"^{re.escape(quantity)}: paper .*?; jaxrod (.*)$", out, re.M)
    assert m, quantity
    return m.group(1)


def check(nb):
    out = notebook_text(nb)
    assert "not available" not in out
    m = re.search(r"^quick mode statics N = (\d+) dynamics (\{.*\}) out (\S+)$", out, re.M)
    assert m and int(m.group(1)) == N and f"'n': {N_DYN}" in m.group(2), out[:500]
    folder = Path(m.group(3))
    cache = json.loads((folder / "cache.json").read_text())

    # --- snap angles at Psi0 = 60 deg, G/L = 0.5: Richardson from N = 40 and 80 against the
    # converged values (the extrapolation's own residual, predicted from the same study: 6e-3 deg),
    # the N = 40 mesh alone against its predicted value (its error is ~0.6 deg)
    up_inf, down_inf, kind_up, kind_down = alpha_c_benchmark(60.0, 0.5)
    up_40, down_40, _, _ = alpha_c_benchmark(60.0, 0.5, N)
    x = cache[f"snap-extrapolated/60/0.5/{N}"]
    assert x["alpha_up"] == pytest.approx(up_inf, abs=0.02) and x["alpha_down"] == pytest.approx(down_inf, abs=0.02), x
    assert x["alpha_up_mesh"] == pytest.approx(up_40, abs=0.03)
    assert x["alpha_down_mesh"] == pytest.approx(down_40, abs=0.03)
    assert (x["kind_up"], x["kind_down"]) == (kind_up, kind_down)
    # the estimated error of the N = 80 value, |a_80 - a_40| / 3, is that value's actual error
    # (against the converged one) to within a factor 1.5: second-order convergence
    for d, ref in (("up", up_inf), ("down", down_inf)):
        a80 = (3.0 * x[f"alpha_{d}"] + x[f"alpha_{d}_mesh"]) / 4.0
        assert x[f"error_{d}"] == pytest.approx(abs(a80 - x[f"alpha_{d}_mesh"]) / 3.0, rel=1e-6)
        assert 1 / 1.5 < abs(a80 - ref) / x[f"error_{d}"] < 1.5, (d, a80, ref, x)
    for q, key in (("alpha_c up, Psi0 = 60 deg, G/L = 0.5", "alpha_up"), ("alpha_c down, Psi0 = 60 deg, G/L = 0.5",
                                                                         "alpha_down")):
        assert float(_row(out, q).split()[0]) == pytest.approx(x[key], abs=1e-4)

    # --- no snap at Psi0 = 30 deg, G/L = 0.8 (the paper), both paths
    ns = cache[f"snap/30/0.8/{N}"]
    assert ns["alpha_up"] is None and ns["alpha_down"] is None
    assert _row(out, "snapping at Psi0 = 30 deg, G/L = 0.8") == "none"

    # --- master curves: where the convergence study has the point, the N = 40 angles; where a
    # path snaps, against the termination gaps G*(Psi0) (n = 100; points within 0.02 of G* are
    # not judged); the flat strip symmetric and snapping at every gap (docs/model.md)
    term = json.loads((RESULTS / "termination.json").read_text())["rows"]
    conv = json.loads((RESULTS / "convergence_alpha_c.json").read_text())["data"]["uniform"]["50"]
    judged = 0
    for p in (30.0, 60.0, 90.0, 180.0):
        for g in (0.1, 0.3, 0.5, 0.7, 0.9):
            r = cache[f"snap/{p}/{g}/{N}"]
            if f"{p:g}/{g:g}" in conv:
                a_up, a_dn, k_up, k_dn = alpha_c_benchmark(p, g, N)
                assert r["alpha_up"] == pytest.approx(a_up, abs=0.03), (p, g, r, a_up)
                assert r["alpha_down"] == pytest.approx(a_dn, abs=0.03), (p, g, r, a_dn)
                assert (r["kind_up"], r["kind_down"]) == (k_up, k_dn), (p, g, r)
            for d in ("up", "down"):
                g_star = term[f"{p:g}"][f"gap_{d}"]
                if g < 0.2 or abs(g - g_star) < 0.02:  # G/L = 0.1: self-contact, not judged
                    continue
                judged += 1
                assert (r[f"alpha_{d}"] is not None) == (g < g_star), (p, g, d, g_star, r)
        if p == 180.0:
            for g in (0.1, 0.3, 0.5, 0.7, 0.9):
                r = cache[f"snap/{p}/{g}/{N}"]
                assert r["alpha_up"] is not None and r["alpha_up"] == -r["alpha_down"], (g, r)
    assert judged >= 25, judged

    # --- the loops (Figs. 2a-b): the paper's snap down is the smaller jump, both land across
    loop = cache[f"loop/60/0.5/{N}"]
    ju, jd = (abs(loop[d]["after"] - loop[d]["before"]) for d in ("up", "down"))
    assert loop["up"]["before"] < 0 < loop["up"]["after"] and loop["down"]["after"] < 0 < loop["down"]["before"]
    assert jd < ju and loop["up"]["alpha_c"] == pytest.approx(up_40, abs=0.03)
    assert not cache[f"loop/30/0.8/{N}"]["up"]["snaps"] and not cache[f"loop/30/0.8/{N}"]["down"]["snaps"]

    # --- dynamics (N = 24): the brink snap at Psi0 = 30 deg, G/L = 0.5. The integrator is
    # the one `jaxrod.paper.reproduce` picks for the notebook's configuration (its cache keys end
    # in it: "rattle", or Tsit5's rtol)
    tags = {k.rsplit("/", 1)[1] for k in cache if k.startswith(f"vs/30/0.5/{N_DYN}/")}
    assert len(tags) == 1, tags
    TAG = tags.pop()
    vs = {(p, g): cache[f"vs/{p:g}/{g:g}/{N_DYN}/{TAG}"] for p in (30.0, 90.0, 180.0) for g in (0.3, 0.5)}
    rec = vs[(30.0, 0.5)]
    assert rec["snaps"] and rec["v_s"] == pytest.approx(V_S_30_05, rel=0.05), rec["v_s"]  # measured +2.2 %
    # clamps held, undamped: the kinetic energy at its peak cannot exceed the bending energy
    # released, and most of it is traded (the paper); the energy balance holds (RATTLE at
    # N = 24: ~1e-3, its bounded O(dt^2) error, tests/test_reproduce.py; a wrong force: O(1))
    ratio = rec["kinetic_energy_peak"] / rec["bending_energy_before"]
    assert 0.8 < ratio < 1.0 and rec["energy_drift"] < 3e-3, rec
    assert float(_row(out, "E_k at its peak / E_b before the snap")) == pytest.approx(ratio, abs=0.006)
    fast = cache[f"fastest/30/0.5/{N_DYN}/{TAG}"]
    assert abs(fast["s_fastest_peak"] - 0.5) < 0.1 and 5.0 < fast["mean_speed_max"] < 20.0, fast  # the paper: ~10 v*
    # the speed plane: every grid point snaps (all below G*), v_s falls with the gap and with the
    # fold angle (the paper's a, b > 0), the printed fit is a plane through these points
    assert all(r["snaps"] and r["energy_drift"] < 3e-3 for r in vs.values()), vs
    for p in (30.0, 90.0, 180.0):
        assert vs[(p, 0.3)]["v_s"] > vs[(p, 0.5)]["v_s"], p
    for g in (0.3, 0.5):
        assert vs[(30.0, g)]["v_s"] > vs[(90.0, g)]["v_s"] > vs[(180.0, g)]["v_s"], g
    fit = re.search(r"jaxrod's plane: \{'v_m': ([-\d.]+), 'a': ([-\d.]+), 'b': ([-\d.]+)\}", out)
    assert fit, out
    vm, a, b = (float(v) for v in fit.groups())
    pts = np.array([[1.0, -g, -math.radians(p), r["v_s"]] for (p, g), r in vs.items()])
    coef = np.linalg.lstsq(pts[:, :3], pts[:, 3], rcond=None)[0]
    np.testing.assert_allclose([vm, a, b], coef, atol=0.006)
    assert a > 0 and b > 0

    # --- Fig. 1c: folded against flat at G/L = 0.5, and in m/s for the PET strips
    fold, flat = vs[(30.0, 0.5)]["v_s"], vs[(180.0, 0.5)]["v_s"]
    q = "v_s(Psi0 = 30 deg) / v_s(flat), G/L = 0.5 (snap up from the brink)"
    assert float(_row(out, q)) == pytest.approx(fold / flat, abs=0.006) and fold / flat > 1.5
    vstar = {t: t / 0.2 * math.sqrt(4.5e9 / (12 * 1380.0)) for t in (80e-6, 250e-6)}  # L = 20 cm, E = 4.5 GPa
    for quantity, v in (("folded v_s in m/s (PET, L = 20 cm)", fold), ("flat v_s in m/s (same strips)", flat)):
        lo, hi = (float(s) for s in _row(out, quantity).replace(" m/s", "").split(" - "))
        assert lo == pytest.approx(v * vstar[80e-6], abs=0.06) and hi == pytest.approx(v * vstar[250e-6], abs=0.06)

    # --- Fig. 4: while the right clamp turns, the far end (next to the held clamp) stays put
    turn = cache[f"asym/60/0.5/0.5/{N_DYN}/{TAG}/turn"]
    assert turn["disp_near"] > 3 * turn["disp_far"], turn
    assert "which part jumps: " in out

    # --- the figures: every displayed image is a PNG of real size, and the files exist
    imgs = notebook_images(nb)
    assert len(imgs) == 8, len(imgs)  # loops, master curves, 3 of Fig. 3, speed plane, Fig. 1c, Fig. 4
    assert all(im[:8] == b"\x89PNG\r\n\x1a\n" and len(im) > 10_000 for im in imgs), [len(im) for im in imgs]
    for name in ("fig2ab_loops.png", "master_curves.png", "speed_plane.png", "fig1c_fold_speed.png",
                 "fig3_snap/chrono.png", "fig3_snap/speed_map.png", "fig3_snap/energies.png",
                 "fig4_asymmetric/chrono.png"):
        assert (folder / name).is_file() and (folder / name).stat().st_size > 10_000, name
