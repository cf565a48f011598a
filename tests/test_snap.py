"""Snap angles by continuation: flat-strip symmetry, the paper's
qualitative facts, kinds of instability, and agreement of the refined alpha_c with
brute-force equilibrium checks on either side."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr


jax.config.update("jax_enable_x64", True)


@pytest.fixture(scope="module")
def snap():
    f = jax.jit(jr.snap_angles)
    return lambda psi0, gap: f(jr.make_scene(psi0, gap, 0.0))


def test_flat_strip_symmetric(snap):
    r = snap(180.0, 0.5)
    assert bool(r.up.snaps) and bool(r.down.snaps)
    assert abs(float(r.up.alpha_c) + float(r.down.alpha_c)) < 1e-6
    assert float(r.up.alpha_c) > 0
    # the flat strip snaps through an asymmetric mode (branch point), and lands in the mirror state
    assert int(r.up.kind) == 2 and int(r.down.kind) == 2
    assert float(r.up.fold_height_before) < 0 < float(r.up.fold_height_after)
    assert float(r.down.fold_height_after) < 0 < float(r.down.fold_height_before)


def test_paper_asymmetry_60_05(snap):
    r = snap(60.0, 0.5)
    up, down = np.degrees(float(r.up.alpha_c)), np.degrees(float(r.down.alpha_c))
    assert up > 0 > down
    assert up < abs(down)  # the paper: snap up at ~73.6 deg, snap down at ~ -80 deg
    for p in (r.up, r.down):  # decided by a loss of stability (Branch.stop 2), landed
        assert int(p.stop) == 2 and p.result == jr.RESULTS.successful
    # snapping up lands in the up state, snapping down in the down state
    assert float(r.up.fold_height_after) > 0 and float(r.down.fold_height_after) < 0


def test_no_snap_30_08(snap):
    r = snap(30.0, 0.8)  # the paper's Fig. 2b: smooth in both directions
    assert not bool(r.up.snaps) and not bool(r.down.snaps)
    assert np.isnan(float(r.up.alpha_c)) and int(r.up.kind) == 0
    for p in (r.up, r.down):  # a genuine "does not snap": the path reached |alpha| = pi (stop 1)
        assert int(p.stop) == 1 and p.result == jr.RESULTS.successful


def test_alpha_c_brackets_stability_loss(snap):
    """Independent check: plain equilibria just before alpha_c are stable, just after
    (continued from the critical state) unstable."""
    r = snap(60.0, 0.5)
    sc = jr.make_scene(60.0, 0.5, 0.0)
    for path in (r.up, r.down):
        a = float(path.alpha_c)
        sgn = np.sign(a)
        for da, expect_stable in ((-sgn * 1e-5, True), (sgn * 1e-5, False)):
            s = eqx.tree_at(lambda s: (s.clamps.alpha_left, s.clamps.alpha_right), sc,
                            (jnp.asarray(a + da), jnp.asarray(a + da)))
            # the stable side by minimization (near a fold, plain Newton from the critical
            # state converges only linearly), the far side by plain Newton
            solver = jr.Newton(minimize=expect_stable, max_steps=200)
            eq = jr.solve_equilibrium(s, path.theta_before, path.force_before, solver=solver)
            if expect_stable:
                assert eq.result == jr.RESULTS.successful and bool(eq.stable)
            elif int(path.kind) == 2:  # branch point: the symmetric branch goes on, unstable
                assert eq.result == jr.RESULTS.successful and not bool(eq.stable)
            else:  # fold: no equilibrium nearby past the limit point
                far = np.max(np.abs(np.asarray(eq.theta - path.theta_before))) > 1e-2
                assert eq.result != jr.RESULTS.successful or far


def test_float32_refused():
    f32 = jnp.float32
    sc = jr.Scene(jr.Strip(psi0=f32(np.pi / 3), s0=f32(0.02)), jr.Clamps(f32(0.5)), jr.Mesh(100))
    with pytest.raises(ValueError, match="float64"):
        jr.snap_angles(sc)


def test_cli_snap_angles_json(snap, capsys):
    import json

    from jaxrod.cli._main import main

    assert main(["snap-angles", "--psi0", "60", "--gap", "0.5", "--json", "--no-extrapolate"]) == 0
    rec = json.loads(capsys.readouterr().out)
    r = snap(60.0, 0.5)
    assert abs(rec["alpha_c_up_deg"] - np.degrees(float(r.up.alpha_c))) < 1e-9
    assert abs(rec["alpha_c_down_deg"] - np.degrees(float(r.down.alpha_c))) < 1e-9
    assert rec["extrapolated"] is False
    assert rec["kind_up"] in ("fold", "branch_point") and rec["kind_down"] in ("fold", "branch_point")
    # the second critical point of each path (jr.snap_routes) and the clearance of its states
    routes = jr.snap_routes(jr.make_scene(60.0, 0.5, n=100), snap=r)
    for name in ("up", "down"):
        q = getattr(routes, name)
        assert rec[f"kind2_{name}"] == jr.KIND_NAMES[int(q.kind2)]
        a2 = rec[f"alpha_c2_{name}_deg"]
        assert (a2 is None) == bool(np.isnan(float(q.alpha_c2)))
        assert a2 is None or abs(a2 - np.degrees(float(q.alpha_c2))) < 1e-9
        assert 0.0 < rec[f"clearance_{name}"] < 0.5
    assert rec["kind_up"] == "branch_point" and rec["kind2_up"] == "fold"
    # (a path whose start state does not exist, in the CLI: test_extrapolate.py, with the
    # extrapolated programs that test compiles anyway)
    # clamps that differ (--alpha-right) are a misalignment kept while both turn: the same
    # programs, the API's numbers, and the branch point unfolded into an earlier fold
    assert main(["snap-angles", "--psi0", "60", "--gap", "0.5", "--alpha", "0.5", "--alpha-right", "-0.5",
                 "--json", "--no-extrapolate"]) == 0
    mis = json.loads(capsys.readouterr().out)
    m = jr.snap_angles(jr.make_scene(60.0, 0.5, 0.5, alpha_right_deg=-0.5, n=100))
    assert abs(mis["alpha_c_up_deg"] - np.degrees(float(m.up.alpha_c))) < 1e-9
    assert mis["kind_up"] == "fold" and mis["alpha_c_up_deg"] < rec["alpha_c_up_deg"] - 0.5


@pytest.mark.parametrize("settings, stop", [
    (jr.Continuation(max_points=3), 0),  # the same compilation as the CLI test's
    pytest.param(jr.Continuation(ds=0.05, ds_min=0.1), 3, marks=pytest.mark.slow),  # a compile of its own
])
def test_continuation_that_gives_up_is_not_a_silent_no_snap(settings, stop):
    """A path whose continuation stops before a loss of stability or the bound |alpha| = pi
    (buffer full: stop 0; step below ds_min: stop 3) has an unknown outcome: it must say so
    through `result`, not read as "does not snap" with a successful code."""
    sc = jr.make_scene(60.0, 0.5, 0.0, n=40)
    # (the successful paths, stop 2 and stop 1, are checked in the two tests above)
    r = jr.snap_angles(sc, settings=settings, polish=False)
    for p in (r.up, r.down):
        assert int(p.stop) == stop
        assert p.result == jr.RESULTS.continuation_incomplete
        assert p.start_result == jr.RESULTS.successful  # the start state itself is fine
        assert not bool(p.snaps) and np.isnan(float(p.alpha_c)) and int(p.kind) == 0


def test_failed_landing_is_reported_not_dropped(snap, monkeypatch):
    """Where the strip loses stability but the relaxation past alpha_c finds no
    equilibrium, the loss of stability stands (alpha_c, kind) and `result` says the
    landing failed; before, the path went on to a second stage and read as no snap."""
    from jaxrod.branches import _snap

    real = _snap._land

    def no_landing(*args):
        t, m, fa, eq = real(*args)
        return t, m, fa, eqx.tree_at(lambda e: e.result, eq, jr.RESULTS.max_steps_reached)

    sc = jr.make_scene(60.0, 0.5, 0.0)
    ref = snap(60.0, 0.5)
    monkeypatch.setattr(_snap, "_land", no_landing)
    r = jax.jit(lambda s: _snap.snap_angles(s, settings=jr.Continuation(ds=0.0501)))(sc)  # a fresh trace
    for p, q in ((r.up, ref.up), (r.down, ref.down)):
        assert p.result == jr.RESULTS.landing_failed and p.start_result == jr.RESULTS.successful
        assert bool(p.snaps) and int(p.kind) == int(q.kind)
        assert abs(float(p.alpha_c) - float(q.alpha_c)) < 1e-7
        assert np.isnan(float(p.fold_height_after)) and np.all(np.isnan(np.asarray(p.theta_after)))


@pytest.fixture(scope="module")
def land():
    """`_land` of the scene of `snap(60.0, 0.5)` under symmetric actuation, jitted: (landed
    state, fold height, RESULTS code, unstable count of the last relaxation)."""
    from jaxrod.branches import SymmetricAlpha, _snap

    sc = jr.make_scene(60.0, 0.5, 0.0)

    @jax.jit
    def f(t, m, lam, v, direction):
        ta, _, fa, eq = _snap._land(sc, SymmetricAlpha(), t, m, lam, v, direction, direction > 0, jr.Newton())
        return ta, fa, eq.result, eq.num_unstable

    return lambda p, v, direction: f(p.theta_before, p.force_before, p.alpha_c, v, jnp.asarray(direction))


def test_landing_recomputes_a_nonfinite_mode(snap, land):
    """The mode handed to the landing can be NaN (at a fold, `_refine`'s corrector at the far end
    of a bracket at round-off, 2^-48 of a step as the actuator study asks, solves with a Hessian
    singular to round-off: the study's one-sided snap at N = 32 and 48 got NaN there). The
    landing does not push along it into a NaN start: it recomputes the mode at the critical
    state and lands where the true mode lands; before, the path was `landing_failed`."""
    r = snap(60.0, 0.5)
    for p, direction in ((r.up, 1.0), (r.down, -1.0)):
        ta, fa, res, nu = land(p, jnp.full_like(p.mode, jnp.nan), direction)
        assert res == jr.RESULTS.successful and int(nu) == 0
        assert np.max(np.abs(np.asarray(ta - p.theta_after))) < 1e-9
        assert abs(float(fa) - float(p.fold_height_after)) < 1e-9


def test_landing_leaves_a_saddle(snap, land):
    """A relaxation that keeps the mirror symmetry of the branch point (snap up of Psi0 = 60 deg,
    G/L = 0.5, a branch point: here no push at all) converges to the symmetric state past it, a
    saddle (`converged_to_saddle`, one unstable mode; before, the path was `landing_failed`). The
    landing accepts only a stable state: it pushes on along the saddle's unstable mode and lands
    where the snap's push along the critical mode does."""
    r = snap(60.0, 0.5)
    assert int(r.up.kind) == 2
    ta, fa, res, nu = land(r.up, jnp.zeros_like(r.up.mode), 1.0)
    assert res == jr.RESULTS.successful and int(nu) == 0
    assert np.max(np.abs(np.asarray(ta - r.up.theta_after))) < 1e-9
    assert float(fa) > 0 and abs(float(fa) - float(r.up.fold_height_after)) < 1e-9


def test_cli_snap_angles_reports_an_unknown_path(monkeypatch, capsys):
    """The CLI exits with 3 and names the result where a path's outcome is unknown."""
    import json

    from jaxrod.cli import _main as _cli

    real = jr.snap_angles
    monkeypatch.setattr(jr, "snap_angles",
                        lambda sc, **kw: real(sc, settings=jr.Continuation(max_points=3), polish=False, **kw))
    assert _cli.main(["snap-angles", "--psi0", "60", "--gap", "0.5", "--n", "40", "--json", "--no-extrapolate"]) == 3
    cap = capsys.readouterr()
    rec = json.loads(cap.out)
    assert rec["result_up"] == "continuation_incomplete" and rec["alpha_c_up_deg"] is None
    assert rec["start_up"] == "successful"
    assert "continuation_incomplete" in cap.err
