"""RATTLE, the default snap integrator (jaxrod.dynamics._rattle): exact constraints, second-order and
bounded energy error, v_s against the adaptive reference, gradients, bad input. N <= 24."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from helpers import central_difference
from test_dynamics_physics import A0_N16, FD_SCALE, P0, _scene, seeded_ramp_vs

N = 24


@pytest.fixture(scope="module")
def brink24():
    sc = jr.make_scene(30, 0.5, 0, n=N)
    return jr.brink(sc, "up")


def _run(start, **kw):
    return jr.simulate(start.scene, start.theta0, start.protocol, direction=1.0, t1=3.0, **kw)


def _energy_error(tr):
    e = np.asarray(tr.kinetic + tr.potential - tr.clamp_work)
    e = e[np.isfinite(e)]
    return np.abs(e - e[0]) / abs(float(tr.potential[0]))


def test_links_and_ends_stay_exact(brink24):
    """Every link keeps its length and node N stays at (G, 0) through the snap (no Baumgarte
    drift: SHAKE solves the constraints each step). Frames on step points (every 200th step;
    between steps the saved angles are interpolated linearly, which does not keep them)."""
    tr = _run(brink24, dt=1e-4, max_steps=30_010, n_fine=30_001, n_frames=32, frame_window=(0.0, 0.62))
    assert bool(tr.snapped)
    x = np.asarray(tr.positions)
    ok = np.isfinite(x).all((1, 2))
    h = np.diff(np.asarray(brink24.scene.mesh.fractions))
    lengths = np.linalg.norm(np.diff(x[ok], axis=1), axis=-1)
    assert np.max(np.abs(lengths - h)) < 1e-10
    assert np.max(np.abs(x[ok][:, -1] - [0.5, 0.0])) < 1e-10
    assert np.nanmax(np.where(np.isfinite(tr.constraint), tr.constraint, np.nan)) < 1e-10


@pytest.mark.slow  # 8-15 s (three step sizes); CI checks RATTLE's energy over long times and v_s against a reference
def test_energy_error_is_second_order(brink24):
    """Undamped, clamps held: the largest |E_k + V - E(0)| / V(0) over the snap falls 4x when
    the step halves (order 2; measured 1.06e-3 at the default step 1.83e-4 here, where the
    fast rotation of the crease during the snap sets the constant), samples on step points."""
    errs = []
    for dt in (4e-4, 2e-4, 1e-4):
        # n_fine - 1 = t1 / dt: every step is sampled
        tr = _run(brink24, dt=dt, n_fine=int(round(3.0 / dt)) + 1, max_steps=int(3.0 / dt) + 10)
        assert bool(tr.snapped)
        errs.append(float(np.max(_energy_error(tr))))
    r1, r2 = errs[0] / errs[1], errs[1] / errs[2]
    assert 3.2 < r1 < 5.0 and 3.2 < r2 < 5.0, errs
    assert float(_run(brink24).energy_drift) < 2e-3


def test_no_energy_drift_over_long_times():
    """Symplectic: a stable state set vibrating (1e-2 rad, mirror-breaking), undamped, for
    200 periods of its slowest mode: the energy error oscillates, bounded, instead of growing
    (the largest error in the last fifth is no larger than in the first fifth, x1.5)."""
    from jaxrod.dynamics._scenes import mirror_seed

    sc = jr.make_scene(60, 0.5, 0, n=16)
    down = jr.initial_state(sc, "down")
    theta = mirror_seed(down.theta, sc, 0.05)
    t1 = 40.0
    # no snap, no slam: RATTLE steps of 2e-4 T (the snap's own cap, DT_CAP) rather than the
    # ringing step that `stop_at_snap=False` defaults to; 25 per diffrax step of t1 / 8000
    tr = jr.simulate(sc, theta, jr.Protocol(), t1=t1, stop_at_snap=False, n_fine=8001, direction=1.0,
                     dt=t1 / 8000, substeps=25)
    assert tr.result == jr.RESULTS.successful
    err = _energy_error(tr)
    assert err.size == 8001
    k = err.size // 5
    assert np.max(err[-k:]) < 1.5 * np.max(err[:k]), (np.max(err[:k]), np.max(err[-k:]))
    assert np.max(err) < 1e-4


def test_vs_matches_adaptive_reference(brink24):
    """v_s at the default step (Courant 0.45 or the grid) and at Courant 0.2 equals Tsit5 at
    rtol = atol = 1e-10 to 3e-4 (measured 8e-5)."""
    r = _run(brink24, solver="tsit5", rtol=1e-10, atol=1e-10, max_steps=400_000)
    ref, t_ref = float(r.v_s), float(r.t_cross)
    for kw in ({}, dict(courant=0.2)):
        tr = _run(brink24, **kw)
        assert abs(float(tr.v_s) / ref - 1) < 3e-4, (kw, float(tr.v_s), ref)
        assert abs(float(tr.t_cross) - t_ref) < 2e-3


@pytest.mark.slow  # ~35 s of compiling; the fixed-step Tsit5 gradient runs in CI (test_dynamics_physics.py)
def test_gradient_matches_central_differences():
    """d v_s / d(Psi0, G, s0) through RATTLE (fixed steps, 2 SHAKE iterations, all
    differentiated) equals central differences, as for the Tsit5 version."""
    n = 16
    p0 = jnp.array(P0)
    base = jr.initial_state(_scene(p0, n, A0_N16), "down")

    def f(p):
        return seeded_ramp_vs(p, n, A0_N16, base, solver="rattle")[:1]

    g = jax.jacrev(f)(p0)
    v = float(f(p0)[0])
    assert v > 5.0
    fd = central_difference(f, p0, scale=jnp.asarray(FD_SCALE))
    np.testing.assert_allclose(np.asarray(g[0]), np.asarray(fd[0]), rtol=1e-4,
                               atol=1e-5 * float(jnp.max(jnp.abs(fd))))


@pytest.mark.parametrize("courant", [0.5, 0.0, -0.1, math.nan])
def test_bad_courant(brink24, courant):
    with pytest.raises(ValueError, match="courant"):
        _run(brink24, courant=courant)


@pytest.mark.slow  # 7 s; CI runs substeps through the actuator (test_actuate.py)
def test_substeps_take_the_same_steps(brink24):
    """`substeps=4` with a macro step of 4e-4 takes the same RATTLE steps as 1e-4 without
    substeps: the samples every 4e-4 agree to round-off (1e-8), and so does v_s; bad values
    raise."""
    n_fine = int(round(3.0 / 4e-4)) + 1
    a = _run(brink24, dt=1e-4, n_fine=n_fine, max_steps=30_010)
    b = _run(brink24, dt=4e-4, substeps=4, n_fine=n_fine, max_steps=7_510)
    assert bool(a.snapped) and bool(b.snapped)
    fa, fb = np.asarray(a.fold_height), np.asarray(b.fold_height)
    both = np.isfinite(fa) & np.isfinite(fb)
    assert both.sum() > 1000
    # measured up to 5.8e-10 (round-off of the step times, grown by the unstable brink start);
    # a different step would differ by ~1e-4 here (second order, energy error ~1e-3)
    np.testing.assert_allclose(fa[both], fb[both], rtol=0, atol=1e-8)
    np.testing.assert_allclose(float(a.v_s), float(b.v_s), rtol=1e-9)
    assert int(b.num_steps) % 4 == 0  # counted in RATTLE steps
    for bad in (0, 2.5, True):
        with pytest.raises(ValueError, match="substeps"):
            _run(brink24, substeps=bad)
    with pytest.raises(ValueError, match="substeps"):
        _run(brink24, solver="tsit5", substeps=2)
