"""Snap dynamics, CI versions of the issue's physics checks at small N (N = 12-24, loose
tolerances): the gradient of v_s against central differences. The converged versions are
in test_dynamics_slow.py; the trend with N, brink vs ramp, the flat strip's alpha_c and the
asymmetric scene are in test_dynamics.py (they share its N = 24 compiles)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from helpers import central_difference
from jaxrod.dynamics._scenes import mirror_seed


def _scene(p, n, alpha):
    """(Psi0, G, s0) -> scene with both clamps at `alpha`."""
    return jr.Scene(jr.Strip(psi0=p[0], s0=p[2]), jr.Clamps(p[1], alpha, alpha), jr.Mesh(n))


def seeded_ramp_vs(p, n, a0, base, *, seed=0.02, dt=5e-4, t1=1.2, n_fine=2048, solver="tsit5"):
    """v_s of a snap up that is smooth in p = (Psi0, G, s0): the down state at clamp angle a0
    (Newton from `base`, implicit derivative), seeded along the mirror-breaking shape (a
    symmetric ramp from a symmetric state never leaves it at a branch point), the clamps then
    turned by 1 deg at 1 rad/T and held; a fixed step (no step-size control, so the discrete
    map is smooth; Tsit5 by default, RATTLE in test_rattle.py); the run stops at the snap's first overshoot. Returns (v_s, t_peak, t_end)."""
    sc = _scene(p, n, a0)
    eq = jr.solve_equilibrium(sc, base.theta, base.force)
    theta = mirror_seed(eq.theta, sc, seed)
    prot = jr.Protocol(a0, a0, 1.0, 1.0, t_stop=math.radians(1.0))
    tr = jr.simulate(sc, theta, prot, t1=t1, dt=dt, solver=solver, direction=1.0, max_steps=int(round(t1 / dt)) + 10,
                     n_fine=n_fine)
    return jnp.stack([tr.v_s, tr.t_peak, tr.t_end])


# Psi0 = 120 deg, G/L = 0.5, s0 = 0.05 at N = 16: jr.snap_angles gives alpha_c_up = 75.11 deg,
# a branch point; start 0.5 deg below it
P0 = (math.radians(120.0), 0.5, 0.05)
A0_N16 = math.radians(74.6)
# FD steps h_j = eps^(1/3) * scale_j. v_s(G) is strongly curved (the peak time moves by
# dt_peak/dG ~ -67 T): the central difference of v_s in G converged to jax.grad as
# 3.4e10 h^2 (measured for h = 1e-5 .. 1e-7: -192.0, -188.64, -188.611 vs -188.611), so the
# default step 6e-6 is off by 1.2 (0.6 %); with h_G = 1.2e-7 the truncation error is ~5e-4
# (3e-6 relative) and rounding ~eps |v_s| / h ~ 3e-8. Psi0, s0: scale 0.1 (h = 6e-7).
FD_SCALE = (0.1, 0.02, 0.1)


@pytest.mark.slow  # 23 s; CI checks d v_s/d(crease) against differences (test_crease_design.py)
def test_vs_gradient_matches_central_differences_small_n():
    """d v_s / d(Psi0, G, s0) by jax.jacrev (implicit derivative of the start state, then
    diffrax's checkpointed reverse pass) equals central differences."""
    n = 16
    p0 = jnp.array(P0)
    base = jr.initial_state(_scene(p0, n, A0_N16), "down")
    assert base.result == jr.RESULTS.successful

    def f(p):
        out = seeded_ramp_vs(p, n, A0_N16, base)
        return out[:1], out

    g, out = jax.jacrev(f, has_aux=True)(p0)
    v, t_peak, t_end = (float(x) for x in out)
    assert v > 5.0 and t_peak < t_end < 1.15  # it snapped, and stopped after the peak, inside the window
    fd = central_difference(lambda p: f(p)[0], p0, scale=jnp.asarray(FD_SCALE))
    # tolerance: the FD truncation error above (<= 3e-6 of |dv_s/dG|) with a 3x margin; the
    # fixed-step map itself is differentiated exactly
    np.testing.assert_allclose(np.asarray(g[0]), np.asarray(fd[0]), rtol=1e-5,
                               atol=1e-5 * float(jnp.max(jnp.abs(fd))))
