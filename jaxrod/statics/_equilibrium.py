r"""Equilibria by Newton's method on the autodiff Hessian of $\tilde{\mathcal L}(\theta,\mu)$.

Each iteration solves the KKT system $\mathsf K\,(p,q) = -\nabla\tilde{\mathcal L}$ with
the bordered tridiagonal structure of `kkt.py` in $O(N)$.

With `minimize=True` (default) the iteration is globalized so it reaches a local
minimum from a rough guess, not a saddle:
* inertia correction: if the constrained Hessian has $\nu(0)>0$ negative eigenvalues,
  $\delta\,I$ is added to the $\theta\theta$ block, with the smallest $\delta$ of a
  geometric ladder that makes $\nu(-\delta)=0$ (one vectorized Sturm count for the whole
  ladder);
* backtracking on the augmented-Lagrangian merit
  $\phi(\theta)=\tilde{\mathcal L}(\theta,\mu^+) + \tfrac\rho2|\nabla_\mu\tilde{\mathcal L}(\theta,\mu^+)|^2$,
  where a full step that halves the KKT residual is always accepted; $\rho$ is raised
  within an iteration where needed to make the Newton direction a descent direction.

With `minimize=False` it is plain Newton (for following unstable branches).

Every step is capped at 0.5 rad in any angle; with self-contact (`scene.contact`) also by
`jaxrod.energy.contact.step_bound`, so that no step carries two parts of the strip through
each other (a penalty could not undo a crossing once made). The Hessian is then dense.

Derivatives of the solution with respect to any float leaf of the scene are by the
implicit function theorem (one extra structured solve, `lax.custom_linear_solve`),
never by unrolling the iterations.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np
from jax import lax

from ..linalg import kkt
from ..energy.geometry import discretize, scene_dtype
from ..energy.contact import step_bound
from ..energy.lagrangian import lagrangian, lagrangian_gradient
from .._misc import check_bool, check_int, check_number, run_if
from .._compile import jit
from ..results import RESULTS
from ._solution import Equilibrium


class Newton(eqx.Module):
    """Newton settings.

    **Arguments:**
    - `max_steps`: iteration cap (the `max_steps_reached` code beyond it).
    - `gtol`: convergence when $\\max_i|\\partial\\tilde{\\mathcal L}/\\partial\\theta_i|\\,L/B$
      and $\\max|\\partial\\tilde{\\mathcal L}/\\partial\\mu|/L$ are below it. Default:
      `1e-9` in float64, `1e-3` in float32.
    - `minimize`: globalize toward a local minimum (inertia correction + line search).
    - `max_backtracks`: line-search halvings before `line_search_failed`.
    """

    max_steps: int = eqx.field(static=True, default=100)
    gtol: float | None = eqx.field(static=True, default=None)
    minimize: bool = eqx.field(static=True, default=True)
    max_backtracks: int = eqx.field(static=True, default=30)

    def __check_init__(self):
        check_int("max_steps", self.max_steps, lo=1)
        if self.gtol is not None:
            check_number("gtol", self.gtol, lo=0.0)
        check_bool("minimize", self.minimize)
        check_int("max_backtracks", self.max_backtracks, lo=0)


def float_scene(scene):
    """`scene` with its numbers as arrays of the scene's float type; `ValueError` naming
    `scene` for anything that is not a `jaxrod.Scene`."""
    from ..model import Scene

    if not isinstance(scene, Scene):
        raise ValueError(f"scene must be a jaxrod.Scene (from jr.make_scene), got {type(scene).__name__}")
    dtype = scene_dtype(scene)
    return jtu.tree_map(lambda x: jnp.asarray(x, dtype) if eqx.is_array_like(x) else x, scene)


def _grad_fn(scene, d=None):
    d = discretize(scene) if d is None else d
    return lambda t, m: lagrangian_gradient(t, m, scene, d)


def _residual(g, scene):
    st = scene.strip
    rt = jnp.max(jnp.abs(g[0])) * st.length / st.bending_stiffness
    rm = jnp.max(jnp.abs(g[1])) / st.length
    return jnp.maximum(rt, rm)


MAX_ANGLE_STEP = 0.5  # rad
# inertia-correction ladder, relative to max|diag T| (NumPy: importing jaxrod starts no JAX backend)
_DELTAS = 10.0 ** np.arange(-8, 5)


def newton_start(theta0, mu0):
    """The state of a Newton solve before its first iteration (see `newton_iteration`)."""
    return dict(theta=theta0, mu=mu0, steps=jnp.zeros((), jnp.int32), done=jnp.zeros((), bool),
                result=RESULTS.successful)


def newton_iteration(scene, solver: Newton, c, d=None, count=False):
    r"""One iteration of `solver` on `scene` from the Newton state `c` (`newton_start`):
    the residual at the current iterate, and where it is above tolerance the (globalized)
    Newton step. Returns the next state, whose `done` says the solve has ended and `result`
    how (`successful` once converged, or why it stopped). With `count=True` also
    $\nu(0)$ of the Hessian at the current iterate (the unstable count of a converged
    state: the iterate is kept once converged).

    `_newton` runs it in a loop of its own; a solver loop that runs many solves one after
    another (the homotopy of `jaxrod.initial_state`) calls it once per pass of its own loop,
    so that under `vmap` each member's solves follow each other without waiting, at every
    solve, for the member with the most iterations."""
    t, m = c["theta"], c["mu"]
    dtype = t.dtype
    gtol = solver.gtol if solver.gtol is not None else (1e-9 if dtype == jnp.float64 else 1e-3)
    if d is None:
        d = discretize(scene)
    grad_fn = _grad_fn(scene, d)
    st = scene.strip
    rho = 100.0 * st.bending_stiffness / st.length**3

    def L(t, m):
        return lagrangian(t, m, scene, d)

    g = grad_fn(t, m)
    res = _residual(g, scene)
    K_here = kkt.structured(t, m, scene, d) if count else None

    def work():
        K = K_here if K_here is not None else kkt.structured(t, m, scene, d)
        if solver.minimize:
            # eigenvalues must exceed a small positive floor: a nearly singular
            # Hessian (a critical state) would otherwise give a huge, useless step
            scale = jnp.max(jnp.abs(K.diag))
            floor = 1e-8 * scale

            def ladder(K, scale, floor):
                # the smallest rung delta with nu(floor - delta) = 0 (else the last): nu
                # falls as delta grows, so a bisection over the rungs finds it in
                # ceil(log2(13)) = 4 Sturm counts, the same for every member of a batch
                # (a 13-shift count at once would be a 13x wider batched solve)
                deltas = scale * _DELTAS.astype(dtype)

                def ok_at(j):
                    return kkt.count_below(K, (floor - deltas[j])[None])[0] == 0

                def halve(_, lh):
                    lo, hi = lh  # not ok at lo (or lo = -1); ok at hi (or hi = the last rung)
                    mid = (lo + hi) // 2
                    split = hi - lo > 1
                    good = ok_at(jnp.maximum(mid, 0))
                    return jnp.where(split & ~good, mid, lo), jnp.where(split & good, mid, hi)

                last = deltas.shape[0] - 1
                _, j = lax.fori_loop(0, int(np.ceil(np.log2(deltas.shape[0]))), halve,
                                     (jnp.full((), -1, jnp.int32), jnp.full((), last, jnp.int32)))
                return deltas[j]

            # the ladder of shifts is only needed away from a local minimum; `run_if`, not
            # `lax.cond`: under `vmap` a cond would run the 13-shift ladder for every member
            # at every iteration (a batched tridiagonal solve per shift: it dominated the
            # vmapped phase diagram)
            is_min = kkt.count_below(K, jnp.full((1,), floor, dtype))[0] == 0
            delta = run_if(~is_min, ladder, jnp.zeros((), dtype), (K, scale, floor))
        else:
            delta = jnp.zeros((), dtype)
        p, q = kkt.solve(K, -g[0], -g[1], shift=-delta)
        # cap the angle update at MAX_ANGLE_STEP rad (inactive near convergence)
        cap = jnp.minimum(1.0, MAX_ANGLE_STEP / jnp.maximum(jnp.max(jnp.abs(p)), 1e-300))
        cap = jnp.where(jnp.isfinite(cap), cap, 1.0)
        if scene.contact is not None:
            # with self-contact, no step may carry two parts of the strip through each other
            cap = cap * step_bound(t, cap * p, scene, d)
        p, q = cap * p, cap * q
        if solver.minimize:
            # The penalty rho is raised for this iteration where the Newton direction
            # would not descend the merit: with phi = L + rho P, P = |grad_mu L|^2 / 2,
            # the slope is L' + rho P' and P' ~ -|c|^2 < 0 along a Newton step, so
            # rho >= 2 max(L', 0) / (-P') + rho_0 makes it <= -|L'| - rho_0 |P'|. Needed
            # where the force changes a lot while the end condition is nearly met
            # (the landing after a snap of a shallow arch: |q| ~ 1e2, |c| ~ 1e-3).
            # Both slopes come from the gradient and the Hessian at hand:
            # L' = g . (p, q), P' = g_mu . (K (p, q))_mu.
            slope_l = jnp.dot(g[0], p) + jnp.dot(g[1], q)
            slope_p = jnp.dot(g[1], kkt.matvec(K, p, q)[1])
            need = 2.0 * jnp.maximum(slope_l, 0.0) / jnp.maximum(-slope_p, jnp.finfo(dtype).tiny) + rho
            rho_it = jnp.where(slope_p < 0.0, jnp.maximum(rho, need), rho)
            rho_it = jnp.where(jnp.isfinite(rho_it), rho_it, rho)
            f0 = L(t, m) + rho_it * 0.5 * jnp.sum(g[1] ** 2)
            slope = jnp.minimum(slope_l + rho_it * slope_p, 0.0)

            def accept(step):
                # Armijo on the merit; the full step is also taken where it halves the
                # residual, descent or not (one gradient serves both tests)
                ts, ms = t + step * p, m + step * q
                gs = grad_fn(ts, ms)
                f = L(ts, ms) + rho_it * 0.5 * jnp.sum(gs[1] ** 2)
                armijo = jnp.isfinite(f) & (f <= f0 + 1e-4 * step * slope)
                res_s = _residual(gs, scene)
                halves = (step == 1.0) & (res_s <= 0.5 * res) & jnp.isfinite(res_s)
                return armijo | halves

            # The test is carried as a flag, never re-evaluated in `ls_cond`: under `vmap`
            # the loop condition is recomputed inside the body, and a differently fused
            # copy of the merit can round the other way when f == f0 (a converged
            # iterate), so the loop would run forever without updating that member. The
            # first pass tries the full step: one call site of the trial
            def ls_cond(s):
                step, k, ok = s
                return (~ok) & (k < solver.max_backtracks)

            def ls_body(s):
                step, k, _ = s
                return 0.5 * step, k + 1, accept(0.5 * step)

            step, _, ok = lax.while_loop(ls_cond, ls_body, (jnp.full((), 2.0, dtype), jnp.full((), -1, jnp.int32),
                                                            jnp.zeros((), bool)))
            ls_failed = ~ok
            t_new, m_upd = t + step * p, m + step * q
        else:
            ls_failed = jnp.zeros((), bool)
            t_new, m_upd = t + p, m + q
        return t_new, m_upd, ls_failed

    # a converged iterate skips the (discarded) Hessian assembly and step
    t_new, m_upd, ls_failed = lax.cond(res <= gtol, lambda: (t, m, jnp.zeros((), bool)), work)
    converged = res <= gtol
    finite = jnp.all(jnp.isfinite(t_new)) & jnp.all(jnp.isfinite(m_upd)) & jnp.isfinite(res)
    steps = c["steps"] + 1
    result = RESULTS.where(
        converged,
        RESULTS.successful,
        RESULTS.where(
            ~finite,
            RESULTS.nonfinite,
            RESULTS.where(
                ls_failed,
                RESULTS.line_search_failed,
                RESULTS.where(steps >= solver.max_steps, RESULTS.max_steps_reached, RESULTS.successful),
            ),
        ),
    )
    stop = converged | ~finite | ls_failed | (steps >= solver.max_steps)
    keep = converged | ~finite
    out = dict(
        theta=jnp.where(keep, t, t_new),
        mu=jnp.where(keep, m, m_upd),
        steps=jnp.where(converged, c["steps"], steps),
        done=stop,
        result=result,
    )
    if count:
        return out, kkt.count_below(K_here, jnp.zeros(1, dtype))[0]
    return out


def _newton(scene, theta0, mu0, solver: Newton):
    d = discretize(scene)
    out = lax.while_loop(lambda c: ~c["done"], lambda c: newton_iteration(scene, solver, c, d),
                         newton_start(theta0, mu0))
    return out["theta"], out["mu"], out["result"], out["steps"]


@jax.custom_jvp
def _implicit(theta, mu, scene):
    return theta, mu


@_implicit.defjvp
def _implicit_jvp(primals, tangents):
    theta, mu, scene = primals
    _, _, dscene = tangents
    d_fn = lambda sc: lagrangian_gradient(theta, mu, sc)  # noqa: E731
    _, (rt, rm) = jax.jvp(d_fn, (scene,), (dscene,))
    K = kkt.structured(theta, mu, scene)
    N = theta.shape[0]
    # one flat right-hand side: it is then linear in the tangents as a whole, even when
    # the parameter moves only the theta or only the mu residual (the transpose of
    # custom_linear_solve needs that)
    b = -jnp.concatenate([rt, rm])

    def mv(x):
        return jnp.concatenate(kkt.matvec(K, x[:N], x[N:]))

    def sol(_, r):
        return jnp.concatenate(kkt.solve(K, r[:N], r[N:]))

    dx = lax.custom_linear_solve(mv, b, sol, symmetric=True)
    dt, dm = dx[:N], dx[N:]
    return (theta, mu), (dt, dm)


def solve_unflagged(scene, theta0, mu0, solver):
    scene = float_scene(scene)
    dtype = scene_dtype(scene)
    theta0 = jnp.asarray(theta0, dtype)
    mu0 = jnp.zeros(2, dtype) if mu0 is None else jnp.asarray(mu0, dtype)
    if theta0.shape != (scene.mesh.n,):
        raise ValueError(f"theta0 must have shape ({scene.mesh.n},), got {theta0.shape}")
    t, m, result, steps = _newton(lax.stop_gradient(scene), lax.stop_gradient(theta0),
                                  lax.stop_gradient(mu0), solver)
    K = kkt.structured(t, m, lax.stop_gradient(scene))
    nneg = kkt.count_below(K, jnp.zeros(1, dtype))[0]
    if solver.minimize:
        result = RESULTS.where((result == RESULTS.successful) & (nneg > 0), RESULTS.converged_to_saddle, result)
    t, m = _implicit(t, m, scene)
    return Equilibrium(t, m, result, steps, nneg, scene)


def flag_contact(eq):
    """`eq` with `result` set to `self_intersecting` where it converged to a state that
    passes through itself (two non-neighbouring segments cross), `contact_underresolved` where it
    converged to a state in self-contact on a mesh too coarse for the contact thickness."""
    from ..energy.contact import self_intersects, underresolved_contact

    ok = eq.result == RESULTS.successful
    bad = ok & self_intersects(eq.theta, eq.scene, force=eq.force)
    coarse = ok & underresolved_contact(eq.theta, eq.scene)
    return eqx.tree_at(lambda e: e.result, eq,
                       RESULTS.where(bad, RESULTS.self_intersecting,
                                     RESULTS.where(coarse, RESULTS.contact_underresolved, eq.result)))


@jit
def solve_equilibrium(scene, theta0, mu0=None, *, solver: Newton = Newton(), throw: bool = False) -> Equilibrium:
    r"""Solve for an equilibrium of `scene` starting from angles `theta0`.

    **Arguments:**
    - `scene`: a [`jaxrod.Scene`][].
    - `theta0`: initial segment angles, shape (N,) (for example a previous solution, or
      [`jaxrod.initial_state`][]).
    - `mu0`: initial end force (default zero).
    - `solver`: a [`jaxrod.Newton`][].
    - `throw`: raise (via `eqx.error_if`) if the result is not `successful`. Keep it
      `False` under `vmap` and read `eq.result` per member.

    **Returns:** an [`jaxrod.Equilibrium`][]; a converged state that passes through itself
    (`jaxrod.self_intersects`) is `self_intersecting`. Differentiable with respect to every
    float leaf of `scene` (implicit function theorem).
    """
    if not isinstance(solver, Newton):
        raise ValueError(f"solver must be a jaxrod.Newton, got {solver!r}")
    check_bool("throw", throw)
    eq = flag_contact(solve_unflagged(scene, theta0, mu0, solver))
    if throw:
        eq = eqx.tree_at(lambda e: e.theta, eq,
                         eq.result.error_if(eq.theta, eq.result != RESULTS.successful))
    return eq
