r"""Landing after a loss of stability: the critical state pushed along its unstable mode past
$\alpha_c$ and relaxed to a stable equilibrium (`_land`), and the small helpers the snap paths
share with it (fold height, mirror symmetry, the jump that makes a snap)."""

from __future__ import annotations

import jax.numpy as jnp
from jax import lax

from ..energy.contact import step_bound
from ..energy.geometry import discretize, mode_sign
from ..energy.lagrangian import positions
from ..linalg import kkt
from ..results import RESULTS
from ..statics import Newton, solve_unflagged


JUMP_DISTANCE = 0.1  # rad, L2 distance of the angle field; see `follow_path`


def _fh(scene, parameter, t, m, lam):
    sc = parameter.set(scene, lam)
    return positions(t, m, sc)[sc.mesh.n // 2, 1]


def _is_mirror_symmetric(theta, scene):
    """Whether a state is mirror-symmetric, theta(s) = -theta(L - s), to 1e-6 rad; 1e-4 with
    self-contact, whose pair sums are not evaluated in mirror-symmetric order: their
    round-off, amplified by the vanishing asymmetric eigenvalue near a branch point,
    leaves the bisected critical state asymmetric by up to about 1e-5 rad."""
    tol = 1e-6 if scene.contact is None else 1e-4
    return jnp.max(jnp.abs(theta + theta[::-1])) < tol


LANDING_TRIES = 4
"""Relaxations a landing may take (see `_land`) before the path is `landing_failed`."""


def _land(scene, parameter, t, m, lam, v, direction, up_expected, solver):
    """Push the critical state along the unstable mode slightly past alpha_c and relax, to a
    stable equilibrium only (the minimizing Newton flags a saddle `converged_to_saddle`).

    Where the relaxation does not end on a stable state, the landing pushes again, up to
    `LANDING_TRIES` relaxations in all: from a saddle (a mirror-symmetric relaxation can keep
    the symmetry of a state that is unstable to an asymmetric mode) along the saddle's unstable
    mode, otherwise (no equilibrium found) from the critical state along the mode recomputed
    there, the push doubled from the second such retry on. `v` itself can be non-finite: at a
    fold, the corrector at the far end of a bisection bracket at round-off (2^-48 of a step, as
    `jaxrod/paper/_actuator.py` asks) solves with a Hessian singular to round-off and can return NaN,
    and the mode with it (the actuator study's one-sided snaps at N = 32 and 48). Each push
    goes the way the fold height is expected to move. The retries are a while loop that runs
    only where a member needs them (under `vmap`, masked for the others). Returns the state,
    the force, the fold height and the `Equilibrium` of the last relaxation: its `result` is
    successful only for a stable state."""
    sc = parameter.set(scene, lam + direction * 1e-3)
    eps = 0.05
    newton = Newton(max_steps=200 if scene.contact is None else 2000)
    h = discretize(scene).h

    def relax(t0, m0, u, e):
        plus = _fh(scene, parameter, t0 + e * u, m0, lam)
        minus = _fh(scene, parameter, t0 - e * u, m0, lam)
        # the push that moves the fold height the expected way; mirror images (equal heights, a
        # branch point's asymmetric mode) by the mirror convention, not by round-off
        pick = mode_sign(jnp.where(up_expected, 1.0, -1.0) * (plus - minus), h, u)
        push = pick * e * u
        if scene.contact is not None:
            # the push itself may not carry two parts of the strip through each other (as no Newton
            # step may: `jaxrod.energy.contact.step_bound`); the steps of the relaxation are capped
            # the same way, and a landing that slides one part along another takes many short steps
            push = push * step_bound(t0, push, sc)
        return solve_unflagged(sc, t0 + push, m0, newton)

    def again(c):
        k, eq = c
        # a saddle is an equilibrium at the landing angle: push on from it, along the mode of its
        # lowest (negative) eigenvalue; anything else from the critical state, along its mode
        saddle = eq.result == RESULTS.converged_to_saddle
        t0, m0 = jnp.where(saddle, eq.theta, t), jnp.where(saddle, eq.force, m)
        K = kkt.structured(t0, m0, parameter.set(scene, jnp.where(saddle, lam + direction * 1e-3, lam)))
        u = kkt.modes(K, kkt.smallest_eigenvalues(K, 1))[:, 0]
        return k + 1, relax(t0, m0, u, jnp.where(saddle, 1.0, 2.0 ** (k - 1).astype(t.dtype)) * eps)

    _, eq = lax.while_loop(lambda c: ~c[1].converged & (c[0] < LANDING_TRIES), again,
                           (jnp.ones((), jnp.int32), relax(t, m, v, eps)))
    return eq.theta, eq.force, _fh(scene, parameter, eq.theta, eq.force, lam + direction * 1e-3), eq
