"""Snap dynamics on the statics' energy (jaxrod.dynamics): equations, energy balance,
convergence, scenes, bad input. Small meshes (N = 24) keep the explicit runs short."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from jaxrod.dynamics._equations import accelerations, scene_at
from jaxrod.energy.bending import bending_energy
from jaxrod.energy.geometry import discretize


N = 24


@pytest.fixture(scope="module")
def snap30():
    sc = jr.make_scene(30, 0.5, 0, n=N)
    return sc, jr.snap_angles(sc)


@pytest.fixture(scope="module")
def brink_run(snap30):
    sc, snap = snap30
    start = jr.brink(sc, "up", snap=snap)
    # the adaptive explicit path (the default, RATTLE, is in test_rattle.py); tolerances as
    # arrays: one compilation for all three (Python floats would be static)
    runs = {tol: jr.simulate(start.scene, start.theta0, start.protocol, direction=1.0, t1=3.0, solver="tsit5",
                             rtol=jnp.asarray(tol), atol=jnp.asarray(tol))
            for tol in (1e-4, 1e-6, 1e-8)}
    return start, runs


def test_accelerations_match_dense_lagrange_equations():
    """The O(N) tension solve equals Lagrange's equations with the dense mass matrix
    M = J^T diag(m) J and the end constraint as a multiplier (moving clamps, random state)."""
    sc = jr.make_scene(60, 0.5, 0, n=12)
    d0 = discretize(sc)
    th = jnp.linspace(-0.8, 0.9, 12) + 0.1 * jnp.sin(jnp.arange(12.0) * 2.3)
    om = jnp.cos(jnp.arange(12.0) * 1.7)
    prot = jr.Protocol(0.1, 0.2, 0.3, -0.4)
    acc = accelerations(0.5, jnp.stack([th, om]), sc, prot, jr.Dissipation(), 0.0)
    s2 = scene_at(sc, *prot.angles(0.5)[:2])
    d = discretize(s2)
    h, m = d.h, d0.node_mass.at[0].set(0.0).at[-1].set(0.0)
    n = jnp.stack([-jnp.sin(th), jnp.cos(th)], -1)
    t = jnp.stack([jnp.cos(th), jnp.sin(th)], -1)
    lower = (jnp.arange(13)[:, None] > jnp.arange(12)[None, :]).astype(float)  # node k moves with segments i < k
    J = lower[:, :, None] * (h[:, None] * n)[None]
    M = jnp.einsum("k,kia,kja->ij", m, J, J)
    a_c = jnp.concatenate([jnp.zeros((1, 2)), jnp.cumsum(-(h * om**2)[:, None] * t, 0)])
    Q = -jax.grad(bending_energy)(th, s2, d)
    A = (h[:, None] * n).T
    K = jnp.block([[M, A.T], [A, jnp.zeros((2, 2))]])
    rhs = jnp.concatenate([Q - jnp.einsum("k,kia,ka->i", m, J, a_c), (h * om**2) @ t])
    ref = jnp.linalg.solve(K, rhs)[:12]
    assert float(jnp.max(jnp.abs(acc - ref)) / jnp.max(jnp.abs(ref))) < 1e-11


def test_undamped_energy_is_conserved(brink_run):
    """E_k + V is conserved to the integrator tolerance (fixed clamps, no dissipation), and
    the end condition holds (Baumgarte)."""
    _, runs = brink_run
    tr = runs[1e-8]
    assert bool(tr.snapped)
    assert float(tr.energy_drift) < 1e-7
    assert float(jnp.nanmax(jnp.where(jnp.isfinite(tr.constraint), tr.constraint, jnp.nan))) < 1e-8
    # the drift shrinks with the tolerance
    assert float(runs[1e-4].energy_drift) > float(runs[1e-8].energy_drift)


def test_vs_converges_with_tolerance(brink_run):
    _, runs = brink_run
    v = {k: float(r.v_s) for k, r in runs.items()}
    e4, e6 = abs(v[1e-4] - v[1e-8]), abs(v[1e-6] - v[1e-8])
    assert e6 < e4
    assert e6 / v[1e-8] < 1e-4


def test_energy_trade_at_snap(brink_run):
    """The bending energy of the critical state is mostly turned into kinetic energy (paper)."""
    start, runs = brink_run
    tr = runs[1e-8]
    ratio = float(tr.kinetic_peak / start.bending_before)
    assert 0.5 < ratio < 1.0


def test_damping_dissipates(snap30):
    sc, snap = snap30
    start = jr.brink(sc, "up", snap=snap)
    free = jr.simulate(start.scene, start.theta0, start.protocol, direction=1.0, t1=3.0)
    damped = jr.simulate(start.scene, start.theta0, start.protocol, direction=1.0, t1=3.0,
                         dissipation=jr.Dissipation(damping=2.0))
    assert float(damped.v_s) < float(free.v_s)
    assert math.isnan(float(damped.energy_drift))


@pytest.mark.parametrize("kwargs, name", [
    (dict(solver="rk4"), "solver"),
])
def test_bad_solver(kwargs, name, snap30):
    sc, _ = snap30
    with pytest.raises(ValueError, match=name):
        jr.simulate(sc, jnp.zeros(N), jr.Protocol(), **kwargs)


def test_bad_input():
    sc = jr.make_scene(30, 0.5, 0, n=N)
    with pytest.raises(ValueError, match="stretching"):
        jr.simulate(jr.make_scene(30, 0.5, 0, n=N, stretching=jr.Stretching(1e6)), jnp.zeros(N), jr.Protocol())
    with pytest.raises(ValueError, match="direction"):
        jr.brink(sc, "sideways")
    with pytest.raises(ValueError, match="nudge"):
        jr.brink(sc, "up", nudge=float("nan"))
    with pytest.raises(ValueError, match="rate"):
        jr.ramp(sc, "up", rate=-1.0, alpha_start=0.0)
    with pytest.raises(ValueError, match="damping"):
        jr.Dissipation(damping=-1.0)
    with pytest.raises(ValueError, match="rate_left"):
        jr.Protocol(rate_left=float("nan"))
    with pytest.raises(ValueError, match="float64"):
        jr.simulate(sc, jnp.zeros(N, jnp.float32), jr.Protocol())
    with pytest.raises(ValueError, match="kind"):
        jr.snap_dynamics(sc, kind="wobble")


# CI versions of the physics checks (N <= 24, loose tolerances; converged versions in
# test_dynamics_slow.py). Tolerances and t1 as arrays: one compilation per N for all of them.


def test_brink_and_slow_ramp_agree_small_n(snap30, brink_run):
    """A slow symmetric ramp (0.2 rad/T from alpha_c - 2 deg, a 1e-3 rad mirror-breaking seed:
    alpha_c is a branch point) snaps at the brink's v_s within 3 %."""
    sc, snap = snap30
    _, runs = brink_run
    start, r = jr.snap_dynamics(sc, "up", kind="ramp", rate=0.2, seed=1e-3, snap=snap, t1=3.0)
    b = runs[1e-6]
    assert bool(r.snapped) and bool(b.snapped)
    assert abs(float(r.v_s) / float(b.v_s) - 1) < 0.03, (float(r.v_s), float(b.v_s))


def test_flat_strip_snaps_at_statics_alpha_c_small_n():
    """A slow seeded ramp (0.05 rad/T, seed 1e-2 rad) of the flat strip leaves the down state
    where the statics say: the fold speed first exceeds 1 v* within 2 deg past alpha_c (a
    delayed bifurcation: the seeded mode needs a few e-foldings to grow; measured 1.5 deg, and
    1.9 deg with a 1e-3 seed, 2.3 deg at 0.1 rad/T; before alpha_c the fold's vibration from
    the seed stays below 0.1 v*)."""
    sc = jr.make_scene(180, 0.5, 0, n=N)
    snap = jr.snap_angles(sc)
    rate = 0.05
    start, tr = jr.snap_dynamics(sc, "up", kind="ramp", rate=rate, seed=1e-2, snap=snap, t1=3.0)
    assert bool(tr.snapped)
    t, fs = np.asarray(tr.t), np.asarray(tr.fold_speed)
    i = int(np.argmax(np.where(np.isfinite(fs), fs, 0) > 1.0))
    alpha_dep = float(start.protocol.alpha_left0) + rate * t[i]
    ac = float(snap.up.alpha_c)
    assert 0.0 <= alpha_dep - ac < math.radians(2.0), (math.degrees(alpha_dep), math.degrees(ac))


def asymmetric_quarters(n, t1=4.0):
    """Right clamp turned at 0.5 rad/T from 0 (left clamp held at 0), Psi0 = 60 deg, G/L = 0.5:
    the largest node displacement (from the start) in the left and right quarters while the
    clamp turns, up to 0.1 T before the fold crosses 0, and the largest node speeds in the
    quarters over the snap (to the first overshoot)."""
    sc = jr.make_scene(60, 0.5, 0, n=n)
    start, tr = jr.snap_dynamics(sc, "up", kind="asymmetric", rate=0.5, alpha_start=0.0, t1=t1,
                                 stop_at_snap=True, n_frames=128)
    assert bool(tr.snapped)
    x, sp, tf = np.asarray(tr.positions), np.asarray(tr.speed), np.asarray(tr.t_frames)
    ok = np.isfinite(sp).all(1)
    disp = np.linalg.norm(x - x[0], axis=-1)
    before = ok & (tf < float(tr.t_cross) - 0.1)
    q = n // 4
    return (disp[before][:, 1:q].max(), disp[before][:, n - q : n].max(), sp[ok][:, 1:q].max(),
            sp[ok][:, n - q : n].max())


def test_asymmetric_far_half_stays_put_small_n():
    """Only the right clamp rotates (paper Fig. 4): while it turns, the quarter next to the fixed
    left clamp (the far one) stays put, moving < 1/3 as far as the quarter next to the moving
    clamp. (In the snap itself the far half is the one that jumps: at N = 24 its quarter
    reaches ~19 v* against ~7 v* near the moving clamp, which has already turned over.)"""
    d_left, d_right, _, _ = asymmetric_quarters(N)
    assert d_right > 3 * d_left, (d_left, d_right)


def test_second_snap_dynamics_call_compiles_nothing(snap30):
    """A repeated `snap_dynamics` query runs compiled programs only: the brink start's
    projection onto the clamp constraint is jitted, not an eager loop compiled anew."""
    from helpers import count_compiles

    sc, snap = snap30
    kw = dict(snap=snap, t1=0.5)
    jr.snap_dynamics(sc, "up", **kw)
    with count_compiles() as c:
        start, tr = jr.snap_dynamics(sc, "up", **kw)
    assert c[0] == 0
    assert np.all(np.isfinite(np.asarray(tr.theta)))


def test_brink_start_gradient_matches_central_differences():
    """d(brink start)/d Psi0 against central differences at the fold of the down path
    (Psi0 = 60 deg, N = 24). The start is built from the refined critical state as it is,
    whose derivative is the extended system's; solving it again at alpha_c would attach the
    implicit derivative of a solve at a critical point, where the Hessian is singular (1.9 %
    off here). A fold, not a branch point: there the antisymmetric mode leaves
    the fold height unchanged to first order, and the nudge's sign is the mirror convention's
    (`test_branch_point_brink_takes_the_mirror_convention`)."""
    w = jnp.sin(jnp.arange(N) + 1.0)
    sc = lambda p: jr.make_scene(p, 0.5, 0, n=N)  # noqa: E731
    assert int(jr.snap_angles(sc(60.0)).down.kind) == 1  # fold

    def f(p):
        start = jr.brink(sc(p), "down")
        return jnp.dot(w, start.theta0) + start.bending_before

    g = jax.grad(f)(60.0)
    h = 1e-3
    fd = (f(60.0 + h) - f(60.0 - h)) / (2 * h)
    assert abs(float(g) - float(fd)) < 1e-7 * abs(float(fd)), (float(g), float(fd))


def test_branch_point_brink_takes_the_mirror_convention(snap30):
    """At a branch point the unstable mode is mirror-asymmetric and moves the fold height only to
    second order: the brink's image is the mirror convention's (mean angle of the nudge
    negative), whichever sign the mode comes with, not round-off's; at a fold the nudge moves
    the fold height the requested way."""
    from jaxrod.dynamics._scenes import nudge_start
    from jaxrod.energy.geometry import mode_sign

    sc, snap = snap30
    assert int(snap.up.kind) == 2  # a branch point
    start = jr.brink(sc, "up", snap=snap)
    t, v = snap.up.theta_before, snap.up.mode
    a = nudge_start(t, v, start.scene, 1.0, 0.03)
    b = nudge_start(t, -v, start.scene, -1.0, 0.03)
    np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(a), np.asarray(start.theta0), rtol=0, atol=1e-12)
    h = discretize(sc).h
    assert float(jnp.sum(h * (a - t))) < 0
    # a first-order effect decides where there is one, the mean angle where it is round-off
    assert float(mode_sign(0.3, h, v)) == 1.0 and float(mode_sign(-0.3, h, v)) == -1.0
    assert float(mode_sign(1e-17, h, v)) == float(mode_sign(-1e-17, h, v)) == -float(mode_sign(1e-17, h, -v))


def test_brink_from_a_snap_without_polish():
    """A `snap` computed with `polish=False` carries the bisection's critical mode (at the state
    just past the critical point): the brink's start agrees with the polished snap's to the
    bisection's accuracy."""
    sc = jr.make_scene(60.0, 0.5, 0, n=N)
    a = jr.brink(sc, "down")
    b = jr.brink(sc, "down", snap=jr.snap_angles(sc, polish=False))
    assert bool(a.ok) and bool(b.ok)
    np.testing.assert_allclose(np.asarray(b.theta0), np.asarray(a.theta0), rtol=0, atol=1e-7)
    assert abs(float(b.bending_before) - float(a.bending_before)) < 1e-7
