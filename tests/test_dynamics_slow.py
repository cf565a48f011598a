"""Slower dynamics checks (run with -m slow): gradient of v_s vs central differences,
convergence with N, brink vs slow ramp, the flat strip snapping at the statics' alpha_c,
the asymmetric scene."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from helpers import central_difference, loglog_slope


# Written in the first session but not yet passing / not yet run to completion (a 2-core
# machine shared by four jobs): the gradient check failed because a symmetric ramp from a
# symmetric state never snaps at a branch point (nothing seeds the asymmetric mode; v_s
# stayed 0.5 v* at N = 16, Psi0 = 120 deg); an earlier variant matched d v_s/d Psi0 to 1e-5
# relative. The other four were never run. Remove the skip once they pass.
pytestmark = [pytest.mark.slow, pytest.mark.skip(reason="not yet verified, see the module comment")]


def _scene(p, n):
    return jr.Scene(jr.Strip(psi0=p[0], s0=p[2]), jr.Clamps(p[1], 0.0, 0.0), jr.Mesh(n))


def test_vs_gradient_matches_central_differences():
    """d v_s / d(Psi0, G, s0) through the ramp scene: the start state by implicit
    differentiation, the snap through diffrax (fixed step, so the discrete map is smooth).
    The run stops at the snap event, so v_s is the peak of the snap itself (not of later
    ringing, whose peaks can overtake it and make v_s jump)."""
    n = 16
    p0 = jnp.array([math.radians(120.0), 0.5, 0.05])
    snap = jr.snap_angles(_scene(p0, n))
    a0 = float(snap.up.alpha_c) - math.radians(1.0)
    base = jr.initial_state(eqx.tree_at(lambda s: (s.clamps.alpha_left, s.clamps.alpha_right),
                                        _scene(p0, n), (jnp.asarray(a0), jnp.asarray(a0))), "down")
    prot = jr.Protocol(a0, a0, 1.0, 1.0, t_stop=math.radians(6.0))  # clamps stop 5 deg past alpha_c

    def vs(p):
        sc = eqx.tree_at(lambda s: (s.clamps.alpha_left, s.clamps.alpha_right), _scene(p, n),
                         (jnp.asarray(a0), jnp.asarray(a0)))
        eq = jr.solve_equilibrium(sc, base.theta, base.force)
        tr = jr.simulate(sc, eq.theta, prot, t1=1.5, dt=2e-4, direction=1.0, max_steps=7600, n_fine=2048)
        return jnp.stack([tr.v_s, tr.t_peak])

    g = jax.jacrev(vs)(p0)[0]
    fd = central_difference(vs, p0)[0]
    v, t_peak = vs(p0)
    assert bool(v > 1.0) and bool(t_peak < 1.2)  # the peak lies well inside the window
    np.testing.assert_allclose(np.asarray(g), np.asarray(fd), rtol=1e-5, atol=1e-6 * float(jnp.max(jnp.abs(fd))))


def test_vs_converges_with_n():
    """Brink snap of Psi0 = 30 deg, G/L = 0.5: |v_s(N) - v_s(2N)| shrinks (N = 16, 32, 64)."""
    v = []
    for n in (16, 32, 64):
        sc = jr.make_scene(30, 0.5, 0, n=n)
        _, tr = jr.snap_dynamics(sc, "up", nudge=0.05, rtol=1e-8, atol=1e-8, t1=3.0)
        v.append(float(tr.v_s))
    d1, d2 = abs(v[1] - v[0]), abs(v[2] - v[1])
    assert d2 < d1, v


def test_brink_and_slow_ramp_agree():
    sc = jr.make_scene(30, 0.5, 0, n=32)
    snap = jr.snap_angles(sc)
    _, b = jr.snap_dynamics(sc, "up", kind="brink", nudge=0.05, snap=snap, rtol=1e-7, atol=1e-7, t1=3.0)
    _, r = jr.snap_dynamics(sc, "up", kind="ramp", rate=0.2, snap=snap, rtol=1e-7, atol=1e-7, t1=6.0)
    assert bool(b.snapped) and bool(r.snapped)
    assert abs(float(r.v_s) / float(b.v_s) - 1) < 0.05


def test_flat_strip_snaps_at_statics_alpha_c():
    """A slow ramp of the flat strip leaves the down state where the statics say: the fold
    speed first exceeds 1 v* within rate * (short delay) of alpha_c."""
    sc = jr.make_scene(180, 0.5, 0, n=32)
    snap = jr.snap_angles(sc)
    rate = 0.1
    start, tr = jr.snap_dynamics(sc, "up", kind="ramp", rate=rate, snap=snap, rtol=1e-7, atol=1e-7, t1=6.0)
    t = np.asarray(tr.t)
    fs = np.asarray(tr.fold_speed)
    i = int(np.argmax(np.where(np.isfinite(fs), fs, 0) > 1.0))
    alpha_dep = float(start.protocol.alpha_left0) + rate * t[i]
    ac = float(snap.up.alpha_c)
    assert 0.0 <= alpha_dep - ac < math.radians(2.0), (math.degrees(alpha_dep), math.degrees(ac))


def test_asymmetric_far_half_stays_put():
    """Only the right clamp rotates (paper Fig. 4): while the strip snaps, the half next to
    the fixed left clamp moves much less than the half next to the moving clamp."""
    sc = jr.make_scene(60, 0.5, 0, n=32)
    start, tr = jr.snap_dynamics(sc, "up", kind="asymmetric", rate=0.5, alpha_start=0.0,
                                 rtol=1e-7, atol=1e-7, t1=4.0)
    sp = np.asarray(tr.speed)
    sp = sp[np.isfinite(sp).all(1)]
    n = sp.shape[1] - 1
    left, right = sp[:, 1 : n // 4].max(), sp[:, 3 * n // 4 : n].max()
    assert right > 3 * left, (left, right)
