"""Snap-speed design: `jaxrod.snap_speed` (gradient vs central differences), study (c) (the
gap with v_s = 20 v* at Psi0 = 90 deg, re-checked by an independent adaptive solve at a finer
mesh), study (b) (fastest snap with G/L >= 0.3), an unreachable target, the CLI.

CI versions run at N = 16 with the check at N = 24 (snap_speed at N = 16 is 2 % above the
converged v_s at Psi0 = 90 deg; N = 16 -> 24 moves it by 0.4 %); the design-mesh versions
(N = 48, check at N = 96) are marked slow. Every study compiles its own problem (40-50 s of
CPU each: snap_angles, the critical point's implicit derivative, the run and its reverse
pass), which is nearly all of this file's time; the CLI test reuses study (c)'s compiled
problem. The CI check of the v_s gradient against central differences is notebook 03's."""

import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod.design as ds
import jaxrod as jr
import jaxrod.paper as paper
from jaxrod.cli._main import main


N, N_CHECK = 16, 24
P0 = (math.radians(90.0), 0.46, 0.02)


def _value_and_jacfwd(n):
    """v_s and its forward-mode Jacobian (design's path: the custom JVP) in one compile."""

    def f(p):
        v = jr.snap_speed(ds.design_scene(p[0], p[1], p[2], n))
        return v, v

    return jax.jit(jax.jacfwd(f, has_aux=True))


# FD steps per parameter (Psi0 [rad], G, s0), measured. v_s carries a round-off noise of
# ~5e-8 v* (at N = 16 v_s(G + dG) is not smooth below dG ~ 1e-6: the snap amplifies
# round-off), so steps of 1e-6 or less measure noise; the truncation error grows with N (v_s
# has sharper features on finer meshes). N = 16, steps (3e-4, 1e-4, 1e-5): FD - AD = 5e-6,
# 7e-8, 1.3e-6 relative (in Psi0 the difference stays at 1.1e-5 for every step from 1e-6 to
# 1e-4, not understood; 1e-5 is far below any design tolerance). N = 48: FD -> AD as h^2
# (Psi0: 3.6e-4, 4e-5, 3.6e-6, 4e-7 at h = 3e-4, 1e-4, 3e-5, 1e-5; G: 4.9e-5, 4.4e-6, 4.8e-7
# at h = 1e-4, 3e-5, 1e-5; s0: 9e-6 at h = 1e-5).
FD_STEPS = {16: (3e-4, 1e-4, 1e-5), 48: (1e-5, 1e-5, 3e-6)}


def _check_gradient(n, rtol):
    fn = _value_and_jacfwd(n)
    p0 = jnp.array(P0)
    g, v = fn(p0)
    g = np.asarray(g)
    assert math.isfinite(float(v)) and float(v) > 5.0
    fd = []
    for j, h in enumerate(FD_STEPS[n]):
        e = np.zeros(3)
        e[j] = h
        vp = float(fn(p0 + e)[1])
        vm = float(fn(p0 - e)[1])
        fd.append((vp - vm) / (2 * h))
    np.testing.assert_allclose(g, np.array(fd), rtol=rtol)
    # the derivatives are not small: a missing dependence (e.g. of the critical state) shows
    assert np.all(np.abs(g) > 1.0)
    return float(v), g


def _study_b_problem(n):
    """The problem `fastest_snap_study(0.3, n=n)` builds (same static fields: one compile)."""
    param = ds.Parametrization(free=("psi0_deg", "gap"), bounds={"psi0_deg": (10.0, 180.0), "gap": (0.3, 0.95)},
                               fixed={"s0": 0.02})
    return ds.Problem((ds.SnapSpeed(100.0, tol=1.0),), param, n)


@pytest.mark.slow  # 77 s on 2 cores; in CI, test_snap_speed_gradient_matches_central_differences checks
# the same custom JVP against central differences at the same N and steps
def test_snap_speed_gradient_in_the_design_loop_matches_central_differences():
    """The Jacobian the design loop uses (jacfwd through snap_speed's custom JVP, in the
    unconstrained z of the parametrization, the compiled function of study (b)) vs central
    differences of the same function's residual r = v_s - 100. z steps 4e-4, 8e-4 are
    3e-4 rad in Psi0 and 1e-4 in G/L at (90 deg, 0.46): the N = 16 steps above."""
    from jaxrod.design._optimize import _linearize_batch

    problem = _study_b_problem(N)
    z0 = problem.param.from_values(psi0_deg=90.0, gap=0.46)
    r, J, v, codes = (np.asarray(a)[0] for a in _linearize_batch(problem, z0[None]))
    assert codes.tolist() == [int(jr.RESULTS.successful._value)]
    assert math.isfinite(v[0]) and v[0] > 5.0
    fd = []
    for j, h in enumerate((4e-4, 8e-4)):
        e = np.zeros(2)
        e[j] = h
        rp = float(np.asarray(_linearize_batch(problem, (z0 + e)[None])[0])[0, 0])
        rm = float(np.asarray(_linearize_batch(problem, (z0 - e)[None])[0])[0, 0])
        fd.append((rp - rm) / (2 * h))
    np.testing.assert_allclose(J[0], np.array(fd), rtol=1e-4)
    assert np.all(np.abs(J[0]) > 1.0)


@pytest.mark.slow  # 41 s on 2 cores; CI checks the same derivative (d v_s / d(Psi0, G, s0) through the
# implicit start state and the checkpointed run) in test_dynamics_physics.py
def test_snap_speed_gradient_matches_central_differences():
    """d v_s / d(Psi0, G, s0) of jr.snap_speed by jax.jacfwd (custom JVP: one reverse pass
    through the implicitly differentiated critical state and the fixed-step run) vs central
    differences, N = 16: the CI check of the snap-speed gradient."""
    _check_gradient(N, rtol=1e-4)


@pytest.fixture(scope="module")
def study_c():
    return paper.snap_speed_study(20.0, 90.0, n=N, n_check=N_CHECK, max_iter=10, progress=False)


@pytest.mark.slow  # 60 s of compiling the design loop; CI checks its Jacobian (the custom JVP) against FD
def test_study_c_reaches_20_and_the_finer_check_agrees(study_c):
    r = study_c
    assert r.reached, r.message
    assert abs(r.v_s - 20.0) <= 0.2 and r.design.psi0_deg == pytest.approx(90.0) and r.design.s0 == 0.02
    chk = r.verification
    assert chk.n == N_CHECK > N and chk.solver == "dopri8" and chk.rtol == 1e-9
    assert chk.error <= 0.01 and abs(chk.v_s - 20.0) <= 0.2
    assert 0.05 < r.design.gap < 0.95
    assert "target reached" in r.message


@pytest.mark.slow  # the same compiled problem as study (c)
def test_cli_design_target_speed_json(study_c, capsys):
    # same problem as the study (compiled once per process)
    code = main(["design", "--target-speed", "20", "--psi0", "90", "--n", str(N), "--check-n", str(N_CHECK),
                 "--max-iter", "10", "--json"])
    out = capsys.readouterr().out
    rec = json.loads(out)
    assert code == 0 and rec["reached"] is True
    assert {"psi0_deg", "gap", "s0", "snap_speed", "reached", "check"} <= set(rec)
    assert rec["psi0_deg"] == pytest.approx(90.0) and rec["s0"] == 0.02
    assert abs(rec["snap_speed"] - 20.0) <= 0.2 and rec["check"]["n"] == N_CHECK
    assert rec["gap"] == pytest.approx(study_c.design.gap, abs=1e-9)


@pytest.mark.parametrize("argv, word", [
    (["design", "--target-speed", "nan"], "target-speed"),
    (["design", "--target-speed", "-3"], "target-speed"),
    (["design", "--target-speed", "20", "--psi0", "200"], "psi0"),
    (["design", "--target-speed", "20", "--target-alpha-up", "60"], "target-speed"),
    (["design", "--target-speed", "20", "--n", "15"], "n"),
    (["design", "--target-speed", "20", "--n", "16", "--check-n", "16"], "check-n"),
    (["design", "--target-speed", "20", "--speed-tol", "0"], "speed-tol"),
    (["design", "--target-speed", "20", "--bounds", "gap=0.3:1.5"], "gap"),
    (["design", "--target-alpha-up", "60", "--psi0", "90"], "psi0"),
])
def test_cli_speed_bad_input_is_one_line_exit_2(argv, word, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("jaxrod: error:") and word in err and "Traceback" not in err


def test_snap_speed_bad_options():
    sc = ds.design_scene(P0[0], P0[1], P0[2], N)
    with pytest.raises(ValueError, match="direction"):
        jr.snap_speed(sc, "sideways")
    with pytest.raises(ValueError, match="dt"):
        jr.snap_speed(sc, dt=-1.0)
    with pytest.raises(ValueError, match="options"):
        ds.SnapSpeed(20.0, rate=1.0)
    assert ds.dynamics_available()
    assert ds.SnapSpeed(20.0).tol == pytest.approx(0.2)


@pytest.mark.slow  # 47 s: the optimizer run toward 500 v*; the angle studies test "not reached" in CI
def test_unreachable_speed_target_says_not_reached():
    """500 v* is far above anything a strip snaps at (the paper's G/L = 0 intercept is 42.6 v*):
    the best design found comes back with 'target not reached'."""
    r = paper.snap_speed_study(500.0, 90.0, n=N, n_check=N_CHECK, bounds={"gap": (0.3, 0.95)}, max_iter=4,
                               progress=False)
    assert not r.reached and not bool(r.design.reached) and not r.verification.reached
    assert "target not reached" in r.message and "target not reached" in r.design.message
    assert math.isfinite(r.v_s) and 5.0 < r.v_s < 500.0
    assert r.design.status in ds.STATUS and r.design.status != "reached"
    # the best design found is better than the start (gap 0.5): v_s rises as the gap closes
    assert r.start_miss > abs(r.v_s - 500.0)
    assert r.to_dict()["reached"] is False


@pytest.mark.slow  # its own compile of the design loop (~50 s); study (c) and the gradient run in CI
def test_study_b_respects_the_bound_and_beats_the_start():
    r = paper.fastest_snap_study(0.3, n=N, n_check=N_CHECK, max_iter=5, progress=False)
    assert r.design.gap >= 0.3 and r.bound_respected
    assert 10.0 <= r.design.psi0_deg <= 180.0
    assert r.improved and r.v_s > r.v_s_start + 1.0, r.message
    # independently (adaptive Dopri8 at the finer mesh), the design is faster than the start too
    start = paper.verify_snap_speed(90.0, 0.5, 0.02, N_CHECK, r.v_s_start)
    assert start.v_s < r.verification.v_s - 1.0
    d = r.to_dict()
    assert d["study"] == "b" and d["min_gap"] == 0.3 and "fastest snap found" in d["message"]


# --- the design mesh (slow) -----------------------------------------------------------------

@pytest.mark.slow
def test_snap_speed_gradient_design_mesh():
    """At N = 48, the design mesh of the studies (steps and measured errors above)."""
    _check_gradient(48, rtol=3e-5)


@pytest.mark.slow
def test_study_c_design_mesh():
    r = paper.snap_speed_study(20.0, 90.0, progress=False)  # N = 48, check at N = 96
    assert r.reached, r.message
    assert r.verification.n == 96 and r.verification.error <= 0.01


@pytest.mark.slow
def test_study_b_design_mesh():
    r = paper.fastest_snap_study(0.3, max_iter=30, progress=False)  # N = 48, check at N = 96
    assert r.bound_respected and r.improved, r.message
    assert r.verification.reached, r.message
    pl = r.polish
    assert pl and pl["v_s_after"] >= pl["v_s_before"] and r.v_s == pytest.approx(pl["v_s_after"], rel=1e-12)
    # the polished design is a maximum in Psi0 at its gap: forward snap_speed 1 deg to either side is slower
    # (by ~0.01 v* from the curvature, results/study_b_grid.md; the map's wiggle is ~0.004 v*)
    for dp in (-1.0, 1.0):
        v = float(jr.snap_speed(ds.design_scene(math.radians(r.design.psi0_deg + dp), r.design.gap, 0.02, 48)))
        assert v < r.v_s, (dp, v, r.v_s)
