r"""Warm-started snap paths: a path's critical point found from a neighbouring design's.

In a sweep or an optimizer, consecutive scenes differ a little and so do their snap paths.
Instead of continuing the branch from $\alpha=0$, Newton's method on the extended system of
the neighbour's kind ([`jaxrod.critical_point`][]) is started from the neighbour's critical
state, angle and mode; the landing is computed as in a cold path. The warm point is
accepted only if every check a cold path would pass holds for it:

- the neighbour's path was decided by its first stage (no supercritical branch point or
  contact click before it), snapped, and is `successful` from its own start state, and this
  scene's start state on the path's side exists (no start substitution);
- Newton converged, the state is an equilibrium (residual below the path tolerance), and
  the angle lies on the path's side within the bound ($0<\mathrm{direction}\,\alpha_c<$`bound`);
- the point is the edge of a stable region: the constrained stiffness $\mathsf K$ has no
  eigenvalue below $-\epsilon$ and exactly one below $+\epsilon$ ($\epsilon=10^{-8}\max|\mathsf
  K_{ii}|$; a second eigenvalue near zero, as where a fold meets a branch point, rejects it);
- the path arrives from the stable side: at $\alpha_c-\mathrm{direction}\cdot10^{-6}$ a stable
  equilibrium lies within 0.05 rad ($L^2$) of the critical state (Newton with the inertia
  correction, started there). At a fold reached the other way (the return fold of an S-shaped
  branch, or a branch point at which the symmetric branch regains stability) there is none.

Where any check fails the path's first stage walks its branch as a cold path does (one
`run_if`, so a loop, a scan or a batch whose every member is accepted never runs it). Either
way the same landing follows, and the path is decided as a cold path is (`follow_path`: a
branch point landing close by is supercritical and the next stage continues from there; the
critical and landed states are checked for self-intersection). What the warm point does not
re-establish is the part of the path before it: that the branch from the start state reaches
this critical point without an earlier loss of stability rests on its continuity with the
neighbour's path; the checks above reject the cases where a second instability is near.
`tests/test_warm.py` checks warm chains against cold calls; benchmarks/results/warm.md measures
the saving (a design whose two paths are warm costs about half a cold one: the landing and the
start states remain). Scenes with self-contact always walk their branch."""

from __future__ import annotations

import functools
import operator

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array

from ..energy.geometry import discretize
from ..linalg import kkt
from ..results import RESULTS
from ..statics import Newton, solve_unflagged
from ._continuation import STOP_UNSTABLE, _pieces, _residual_norm
from ._critical import KIND_BRANCH_POINT, KIND_FOLD, critical_point

WARM_STEPS = 8
"""Newton iterations a warm start may take on the extended system before the cold path runs."""
STABLE_SIDE = 1e-6
"""rad: how far before the warm critical angle the stable side is checked."""
STABLE_DISTANCE = 0.05
"""rad ($L^2$ of the angle field): how close to the critical state that stable equilibrium must be."""


class Near(eqx.Module):
    """What a warm start needs of a neighbour's path (one direction): its critical state,
    angle, mode and kind, whether it may start another path (`usable`), and its start state
    at alpha = 0 (`start_theta`, `start_force`, `start_ok`: the start of this scene's path is
    found by Newton's method from it, the homotopy where that fails)."""

    alpha_c: Array
    kind: Array
    theta: Array
    force: Array
    mode: Array
    usable: Array
    start_theta: Array
    start_force: Array
    start_ok: Array


def near_of(path) -> Near:
    """The [`Near`][] of a computed [`jaxrod.SnapPath`][]: usable where it snapped, was
    decided by its first stage, and is successful from its own start state."""
    usable = (path.snaps & (path.result == RESULTS.successful) & (path.start_result == RESULTS.successful)
              & ((path.kind == KIND_FOLD) | (path.kind == KIND_BRANCH_POINT)) & jnp.all(jnp.isfinite(path.mode)))
    if path.stage is not None:
        usable = usable & (path.stage == 0)
    if path.clicks is not None:
        usable = usable & (path.clicks == 0)
    # the start state: the first point of the first stage's branch (a warm path keeps it there)
    start_ok = (path.start_result == RESULTS.successful) & (path.branch.count[0] >= 1)
    t0, m0 = path.branch.theta[0, 0], path.branch.force[0, 0]
    start_ok = start_ok & jnp.all(jnp.isfinite(t0)) & jnp.all(jnp.isfinite(m0))
    return Near(jnp.where(usable, path.alpha_c, 0.0), path.kind, path.theta_before, path.force_before,
                jnp.where(usable, path.mode, 1.0), usable, jnp.where(start_ok, t0, 0.0), jnp.where(start_ok, m0, 0.0),
                start_ok)


def near_pair(r) -> Near:
    """The (down, up) [`Near`][]s of a `SnapAngles`, stacked on a leading axis: all that
    `snap_angles(..., near=)` reads of a neighbour (a few kB instead of its walked branches)."""
    return jax.tree.map(lambda d, u: jnp.stack([d, u]), near_of(r.down), near_of(r.up))


def unusable_near(n, dtype) -> Near:
    """A [`Near`][] that starts nothing (the first member of a sweep)."""
    z = jnp.zeros((), dtype)
    return Near(z, jnp.full((), KIND_FOLD, jnp.int32), jnp.zeros(n, dtype), jnp.zeros(2, dtype),
                jnp.ones(n, dtype), jnp.zeros((), bool), jnp.zeros(n, dtype), jnp.zeros(2, dtype),
                jnp.zeros((), bool))


def warm_critical(scene, near: Near, ok, direction, parameter, bound, tol):
    """The critical point of `scene`'s path in `direction` from `near` (module docstring):
    `(theta, force, alpha, mode)` (mode of Euclidean unit norm, as the bisection's), whether it
    passes the checks that come before the landing (`accept`), and each check by name
    (`usable`, `converged`, `on_side`, `equilibrium`, `edge`, `stable_side`)."""
    cp = critical_point(scene, near.theta, near.force, near.alpha_c, near.mode, near.kind, parameter=parameter,
                        max_steps=WARM_STEPS)
    t, m, a, v = cp.theta, cp.force, cp.alpha, cp.mode
    F, _, Kf = _pieces(scene, parameter)
    finite = jnp.all(jnp.isfinite(t)) & jnp.all(jnp.isfinite(m)) & jnp.isfinite(a) & jnp.all(jnp.isfinite(v))
    t, m, a = jnp.where(finite, t, near.theta), jnp.where(finite, m, near.force), jnp.where(finite, a, near.alpha_c)
    v = jnp.where(finite, v, near.mode)
    on_side = (direction * a > 0) & (jnp.abs(a) < bound)
    equilibrium = _residual_norm(F(t, m, a), scene) <= tol
    K = Kf(t, m, a)
    eps = 1e-8 * jnp.max(jnp.abs(K.diag))
    counts = kkt.count_below(K, jnp.stack([-eps, eps]))
    edge = (counts[0] == 0) & (counts[1] == 1)
    # the stable side: a stable equilibrium close by just before alpha_c
    before = solve_unflagged(parameter.set(scene, a - direction * STABLE_SIDE), t, m, Newton(max_steps=30))
    w = discretize(scene).h
    stable_side = (before.result == RESULTS.successful) & (jnp.sqrt(jnp.sum(w * (before.theta - t) ** 2))
                                                           < STABLE_DISTANCE)
    checks = {"usable": near.usable & ok, "converged": (cp.result == RESULTS.successful) & finite,
              "on_side": on_side, "equilibrium": equilibrium, "edge": edge, "stable_side": stable_side}
    accept = functools.reduce(operator.and_, checks.values())
    return (t, m, a, v / jnp.linalg.norm(v)), accept, checks


def start_branch(shape, theta0, force0, lam0):
    """A `Branch` of the structure `shape` that holds only its start point (`count` 1) and
    ends at a loss of stability: the stage of a warm path, which walks no branch."""
    def empty(s):
        if jnp.issubdtype(s.dtype, jnp.floating):
            return jnp.full(s.shape, jnp.nan, s.dtype)
        return jnp.zeros(s.shape, s.dtype)

    b = jax.tree.map(empty, shape)
    return eqx.tree_at(lambda b: (b.theta, b.force, b.lam, b.count, b.stop), b,
                       (b.theta.at[0].set(theta0), b.force.at[0].set(force0), b.lam.at[0].set(lam0),
                        jnp.ones_like(b.count), jnp.full_like(b.stop, STOP_UNSTABLE)))
