r"""Snap routes: the second critical point of a path, past the one where it snaps.

A quasi-statically actuated path snaps at its first loss of stability $\alpha_c$
([`jaxrod.snap_angles`][]). Where that is a *branch point* (an asymmetric mode goes unstable
on the mirror-symmetric branch), the symmetric branch itself goes on, now unstable, to a
second critical point $\alpha_{c2}$ where another eigenvalue crosses zero, typically the
symmetric fold: on the flat strip at G/L = 0.5, 1.75 deg after the branch point. When the
two lie close together the route a real strip takes depends on how it is driven (a delayed
bifurcation): a slow, imperfect actuation snaps asymmetrically at the branch point; a fast
ramp of a nearly perfect strip passes it and snaps symmetrically at the fold, at another
speed. [`snap_routes`][] reports both points of each path and the angle between them;
`jaxrod.brink(..., route="second")` starts a snap at the second.

Past a *fold* the branch turns back in $\alpha$: a strip driven in the path's direction
cannot reach any later critical point of it, so a path that snaps at a fold has no second
route (`alpha_c2` NaN, `kind2` none).

**How.** The branch stage that decided the path ends on its first computed point past
$\alpha_c$ (unstable count $\nu_a+1$). Continuation from that point in the same direction
stops at the next change of $\nu$ (or at $|\alpha|=$`bound`: no second point); bisection
on arclength between the last two points and interpolation of the eigenvalue that
crosses zero, as for $\alpha_c$; then the extended system's residual check and implicit
derivative ([`jaxrod.branches.located_critical_point`][]). Kind: a fold where the tangent's
$\alpha$ component changes sign between the two bracketing points, else a branch point.
Its mode is the eigenvector of the crossing eigenvalue (the one nearest zero next to the
point; the lower ones are already negative). `alpha_c2` is differentiable in the scene's
float leaves (implicit function theorem) where the check passes.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array

from ..results import RESULTS
from ..statics import Equilibrium, float_scene, mode_parity
from .._misc import check_int, check_number, run_if
from .._compile import jit
from ._continuation import (STOP_FULL, STOP_STEP, STOP_UNSTABLE, Continuation, SymmetricAlpha, continue_branch,
                            require_float64)
from ._critical import located_critical_point
from ._landing import _fh, _is_mirror_symmetric
from ._snap import KIND_BRANCH_POINT, KIND_FOLD, KIND_NONE, SnapAngles, _refine, snap_angles


class Route(eqx.Module):
    """Both critical points of one path (`up` or `down`) of the quasi-static loop.

    `alpha_c`, `kind`: where the path snaps (as in [`jaxrod.SnapPath`][]); `alpha_c2`,
    `kind2` (1 fold, 2 branch point, 0 none): the next critical point on the same branch
    past `alpha_c` (rad; NaN where there is none before |alpha| = `bound`, or where the
    first is a fold); `separation` = |alpha_c2 - alpha_c| (rad; NaN without a second
    point); `theta2`, `force2`, `fold_height2`, `mode2` (the critical state and mode there;
    NaN without one); `result`: `successful` (a second point found, or shown not to exist
    before the bound), the path's own code where the path is not `successful`,
    `continuation_incomplete` where the search stopped short, `derivative_unavailable`
    where the located point does not solve the extended system to tolerance (`alpha_c2`
    then carries no derivative)."""

    alpha_c: Array
    kind: Array
    alpha_c2: Array
    kind2: Array
    separation: Array
    theta2: Array
    force2: Array
    fold_height2: Array
    mode2: Array
    result: RESULTS


class SnapRoutes(eqx.Module):
    """`up` and `down`: the [`jaxrod.Route`][]s of both paths; `snap` the
    [`jaxrod.SnapAngles`][] they continue."""

    up: Route
    down: Route
    snap: SnapAngles


def _second(scene_d, path, direction, settings, bound, bisections, tol):
    parameter = SymmetricAlpha.for_scene(scene_d)
    scene = lax.stop_gradient(scene_d)
    dtype = path.theta_before.dtype
    nan = jnp.full((), jnp.nan, dtype)
    pick = lambda tree: jax.tree.map(lambda x: x[path.stage], tree)  # noqa: E731
    br = pick(path.branch)
    i = br.count - 1
    search = path.snaps & (path.kind == KIND_BRANCH_POINT) & (path.result == RESULTS.successful)

    def run(t0, m0, lam0):
        sc = parameter.set(scene, lam0)
        start = Equilibrium(t0, m0, RESULTS.successful, jnp.zeros((), jnp.int32), jnp.zeros((), jnp.int32), sc)
        b = continue_branch(sc, start, parameter, direction=direction, bounds=(-bound, bound), settings=settings,
                            stop_on_instability=True, check_contact=False)
        # v: the mode whose eigenvalue crosses zero there (the one nearest zero just past it)
        t, m, lam, v = _refine(scene, parameter, b, settings, tol, bisections)
        j = b.count - 1
        fold = jnp.sign(b.tau_lam[j - 1]) != jnp.sign(b.tau_lam[j])
        nu_a = b.num_unstable[j - 1]
        asym = (mode_parity(v[:, None])[0] < 0) & _is_mirror_symmetric(t, scene)
        kind = jnp.where(fold | ~asym, KIND_FOLD, KIND_BRANCH_POINT).astype(jnp.int32)
        return b.stop, nu_a, t, m, lam, v, kind

    skipped = jax.tree.map(lambda s: jnp.zeros(s.shape, s.dtype),
                           jax.eval_shape(run, br.theta[i], br.force[i], br.lam[i]))
    stop, nu_a, t, m, lam, v, kind = run_if(search, run, skipped, (br.theta[i], br.force[i], br.lam[i]))
    found = search & (stop == STOP_UNSTABLE) & (nu_a <= 2)
    incomplete = search & ((stop == STOP_FULL) | (stop == STOP_STEP) | ((stop == STOP_UNSTABLE) & (nu_a > 2)))
    # the located point as a root of the extended system: the derivative (the scene with its
    # gradients, the state without)
    a0 = jnp.where(found, lam, 0.0)
    cp = located_critical_point(scene_d, t, m, a0, v, jnp.where(found, kind, KIND_FOLD), parameter=parameter)
    ok = found & (cp.result == RESULTS.successful)
    alpha2 = jnp.where(ok, cp.alpha, jnp.where(found, lam, nan))
    theta2 = jnp.where(ok, cp.theta, jnp.where(found, t, nan))
    force2 = jnp.where(ok, cp.force, jnp.where(found, m, nan))
    fh2 = jnp.where(ok, cp.fold_height, jnp.where(found, _fh(scene, parameter, t, m, lam), nan))
    mode2 = jnp.where(ok, cp.mode, jnp.where(found, v, nan))
    good = path.result == RESULTS.successful
    result = RESULTS.where(~good, path.result,
                           RESULTS.where(incomplete, RESULTS.continuation_incomplete,
                                         RESULTS.where(found & ~ok, RESULTS.derivative_unavailable,
                                                       RESULTS.successful)))
    return Route(path.alpha_c, path.kind, alpha2, jnp.where(found, kind, KIND_NONE).astype(jnp.int32),
                 jnp.abs(alpha2 - path.alpha_c), theta2, force2, fh2, mode2, result)


@jit
def _routes(scene_d, snap, settings, bound, bisections):
    scene = lax.stop_gradient(scene_d)
    dtype = jnp.result_type(scene.strip.psi0)
    tol = settings.tol if settings.tol is not None else 1e-9
    paths = jax.tree.map(lambda a, b: jnp.stack([a, b]), snap.up, snap.down)

    def body(_, x):
        path, direction = x
        return None, _second(scene_d, path, direction, settings, bound, bisections, tol)

    _, r = lax.scan(body, None, (paths, jnp.array([1.0, -1.0], dtype)))
    one = lambda k: jax.tree.map(lambda x: x[k], r)  # noqa: E731
    return SnapRoutes(one(0), one(1), snap)


def snap_routes(scene, *, snap: SnapAngles | None = None, settings: Continuation = Continuation(),
                bound: float = jnp.pi, bisections: int = 24) -> SnapRoutes:
    r"""Both critical points of each path of the quasi-static loop (see the module
    docstring): where it snaps ($\alpha_c$, from [`jaxrod.snap_angles`][]) and, past a
    branch point, the next critical point $\alpha_{c2}$ of the same branch and the angle
    between them. `snap`: a precomputed `jr.snap_angles(scene)` of the same scene (with its
    default `polish=True`) to continue; `settings`, `bound` and `bisections` as in
    `snap_angles`. Returns a [`jaxrod.SnapRoutes`][]."""
    if not isinstance(settings, Continuation):
        raise ValueError(f"settings must be a jaxrod.Continuation, got {settings!r}")
    check_number("bound", bound, lo=0.0, hi=jnp.pi, hi_open=False)
    check_int("bisections", bisections, lo=1)
    scene_d = float_scene(scene)
    scene_d = SymmetricAlpha.for_scene(scene_d).set(scene_d, 0.0)  # keeps a misalignment, as snap_angles does
    require_float64(jnp.result_type(scene_d.strip.psi0), "snap_routes")
    if snap is None:
        snap = snap_angles(scene, settings=settings, bound=bound, bisections=bisections)
    elif not isinstance(snap, SnapAngles) or snap.up.stage is None:
        raise ValueError("snap: give the jr.snap_angles(scene) result of the same scene")
    return _routes(scene_d, snap, settings, bound, bisections)
