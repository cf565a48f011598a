"""Snap angles by continuation (issue 3, first part): flat-strip symmetry, the paper's
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
    # snapping up lands in the up state, snapping down in the down state
    assert float(r.up.fold_height_after) > 0 and float(r.down.fold_height_after) < 0


def test_no_snap_30_08(snap):
    r = snap(30.0, 0.8)  # the paper's Fig. 2b: smooth in both directions
    assert not bool(r.up.snaps) and not bool(r.down.snaps)
    assert np.isnan(float(r.up.alpha_c)) and int(r.up.kind) == 0


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

    from jaxrod._cli import main

    assert main(["snap-angles", "--psi0", "60", "--gap", "0.5", "--json", "--no-extrapolate"]) == 0
    rec = json.loads(capsys.readouterr().out)
    r = snap(60.0, 0.5)
    assert abs(rec["alpha_c_up_deg"] - np.degrees(float(r.up.alpha_c))) < 1e-9
    assert abs(rec["alpha_c_down_deg"] - np.degrees(float(r.down.alpha_c))) < 1e-9
    assert rec["extrapolated"] is False
    assert rec["kind_up"] in ("fold", "branch_point") and rec["kind_down"] in ("fold", "branch_point")
    assert main(["snap-angles", "--psi0", "30", "--gap", "0.8", "--json"]) == 0
    rec = json.loads(capsys.readouterr().out)
    assert rec["alpha_c_up_deg"] is None and rec["kind_up"] == "none"
