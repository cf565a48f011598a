r"""Up and down states built on their own, by homotopy from the flat buckled strip.

The up and down states need not be connected by continuation in alpha (docs/model.md), so
each is built from the flat strip ($\Psi_0=\pi$, $\alpha=0$) buckled up or down at the
requested gap, then deformed to the requested $(\Psi_0,\alpha_L,\alpha_R)$ (and
gravity) in `steps` Newton-minimization steps. Three deformation paths are tried in
turn (all parameters together; crease first then clamps; clamps first then crease); a
path is valid when every step converges to a stable equilibrium whose fold
height keeps the requested sign and whose angles change by less than pi/2 from the
previous step (no jump to another branch). The first valid path wins; if none is valid the
result is `state_not_found` (for example the down state of a tight fold at a large gap,
which does not exist at $\alpha=0$).

With self-contact (`scene.contact`) the flat start is built at the gap
$\max(G, 0.35L)$, where no buckled state touches itself, and the gap closes to $G$ along
the homotopy together with the other parameters, so contact develops step by step (a start
built at a small gap would already pass through itself, and a penalty cannot undo that).
Pressed together, the two legs of a mirror-symmetric state would have to pass through each
other: the symmetric contact state is a saddle, and each homotopy step starts from its
predecessor turned by `CONTACT_SEED` rad (a mirror-asymmetric perturbation) so that Newton
minimization leaves it for the stable asymmetric state (in which the right leg lies above
the left one); where the symmetric state is stable, the seed relaxes away.

Each step of a path starts Newton from the secant prediction (the previous step's change of
the angles and end force added once more): two Newton iterations per step instead of three
from the previous state. A step that loses the tracked state from the prediction is solved
again from the previous state before the path is abandoned, so a poor prediction costs a
second solve, not the path; every accepted step passes the same tests as before. Not with
self-contact: a predicted state could already pass through itself, which the penalty cannot
undo.

The flat buckled start is $\theta_i=\pm A\sin(2\pi m_i/L)$ with $A$ chosen so that
$\sum_i h_i\cos\theta_i=G$ exactly; Newton then relaxes it onto the elastica.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from ..energy.geometry import discretize, scene_dtype
from ..energy.lagrangian import positions
from ._equilibrium import Newton, _implicit, float_scene, newton_iteration, newton_start, solve_unflagged, flag_contact
from .._lanes import machine_vmap
from .._misc import check_int
from .._compile import jit
from ..results import RESULTS
from ._solution import Equilibrium


def buckled_guess(scene, up: bool = True):
    """Sine-shaped first buckling mode meeting the gap exactly: shape (N,)."""
    scene = float_scene(scene)
    d = discretize(scene)
    L = scene.strip.length
    shape = jnp.sin(2 * jnp.pi * d.mid[1:-1] / L)
    G = scene.clamps.gap

    def body(_, lh):
        lo, hi = lh
        A = 0.5 * (lo + hi)
        x = jnp.sum(d.h * jnp.cos(A * shape))
        too_long = x > G  # amplitude too small
        return jnp.where(too_long, A, lo), jnp.where(too_long, hi, A)

    lo, hi = lax.fori_loop(0, 60, body, (jnp.zeros((), d.h.dtype), jnp.full((), 2.4048, d.h.dtype)))
    A = 0.5 * (lo + hi)
    return (1.0 if up else -1.0) * A * shape


_MAX_STEP_CHANGE = 0.5 * jnp.pi
"""Largest change of any angle in one homotopy step along a tracked branch (rad). Valid
paths change by < 0.5 rad per step (24 steps); lost branches jump by several rad."""


def _path_params(kind, u):
    """Progress of (crease, clamps) along path `kind` at homotopy time u in [0, 1]."""
    both = u
    crease_first = (jnp.clip(2 * u, 0, 1), jnp.clip(2 * u - 1, 0, 1))
    clamps_first = (jnp.clip(2 * u - 1, 0, 1), jnp.clip(2 * u, 0, 1))
    uc = jnp.select([kind == 0, kind == 1], [both, crease_first[0]], clamps_first[0])
    ua = jnp.select([kind == 0, kind == 1], [both, crease_first[1]], clamps_first[1])
    return uc, ua


def _deformed(scene, uc, ua):
    st, cl = scene.strip, scene.clamps
    scene = eqx.tree_at(lambda s: s.strip, scene, st.unfolded(uc))
    scene = eqx.tree_at(lambda s: (s.clamps.alpha_left, s.clamps.alpha_right), scene,
                        (ua * cl.alpha_left, ua * cl.alpha_right))
    if scene.gravity is not None:
        scene = eqx.tree_at(lambda s: s.gravity.g, scene, uc * scene.gravity.g)
    return scene


CONTACT_START_GAP = 0.35
"""With self-contact, the homotopy starts at the gap max(G, 0.35 L) (module docstring)."""


CONTACT_SEED = 1e-3
"""With self-contact, the mirror-asymmetric seed of every homotopy step (module docstring)."""


def _with_gap(target, u):
    """`target` with the gap at homotopy time u: the target's own without contact, else
    from max(G, CONTACT_START_GAP L) at u = 0 to G at u = 1."""
    if target.contact is None:
        return target
    G = target.clamps.gap
    g0 = jnp.maximum(G, CONTACT_START_GAP * target.strip.length)
    return eqx.tree_at(lambda s: s.clamps.gap, target, g0 + u * (G - g0))


def _fold_height(theta, mu, scene):
    return positions(theta, mu, scene)[scene.mesh.n // 2, 1]


def still_tracked(eq, sgn, theta_prev, scene):
    """`eq` (solved on `scene` from `theta_prev`) is still the tracked state: converged,
    stable, fold height of sign `sgn`, and no angle changed by `_MAX_STEP_CHANGE` or more (a
    jump means the branch was lost, even when Newton lands on a stable state of the right
    sign, e.g. one wound into loops)."""
    return (eq.converged & eq.stable & (sgn * _fold_height(eq.theta, eq.force, scene) > 0)
            & (jnp.max(jnp.abs(eq.theta - theta_prev)) < _MAX_STEP_CHANGE))


@jit
def initial_state(scene, state: str = "up", *, steps: int = 24, solver: Newton = Newton()) -> Equilibrium:
    r"""The stable up (`state="up"`, $y(L/2)>0$) or down (`"down"`) equilibrium of
    `scene`, built from the flat buckled strip by homotopy (see the module docstring).

    **Returns:** an [`jaxrod.Equilibrium`][] whose `result` is `successful`, or
    `state_not_found` when no deformation path reaches a stable state of that sign, or
    `self_intersecting` when the state found passes through itself.
    """
    if state not in ("up", "down"):
        raise ValueError(f"state must be 'up' or 'down', got {state!r}")
    check_int("steps", steps, lo=1)
    if not isinstance(solver, Newton):
        raise ValueError(f"solver must be a jaxrod.Newton, got {solver!r}")
    return flag_contact(initial_state_signed(scene, 1.0 if state == "up" else -1.0, steps=steps, solver=solver))


_FLAT, _PATH, _FINAL, _DONE, _WARM = 0, 1, 2, 3, 4
"""Phases of `_homotopy`'s loop: the flat start, a step of a deformation path, the polish on
the target scene, finished, and Newton on the target from a warm start."""


def _tree_where(pred, a, b):
    return jax.tree.map(lambda x, y: jnp.where(pred, x, y), a, b)


def _homotopy(target, sgn, steps, solver, kinds=(0, 1, 2), warm=None):
    """The homotopy of `initial_state` on the (gradient-free) `target` scene: the flat start,
    then the deformation paths `kinds` (0 all together, 1 crease first, 2 clamps first) in
    turn, each abandoned at its first step that loses the tracked state, then the polish on
    the target from the end of the first valid path (or of the last one tried).

    `warm`: `(theta, force, ok)`, a state of a neighbouring scene (`jaxrod.phase_diagram`'s
    previous gap) that, where `ok`, is tried first: Newton on the target from it, accepted
    when it is still the tracked state (`still_tracked`) and does not pass through itself;
    otherwise the homotopy runs as without it.

    Every Newton solve of the homotopy runs at one call site, in one loop whose phase picks
    the scene and the guess: one compiled copy of the Newton iteration instead of one per
    phase. Each pass of the loop is one Newton iteration (`newton_iteration`); a pass whose
    iteration ends its solve also takes the phase's decision and starts the next solve. Under
    `vmap` every member thus runs its own sequence of solves, and the batch costs the most
    Newton iterations any member needs, not, solve by solve, the most any member needs for
    that solve.

    Returns `(eq, found, warmed)`: the polished equilibrium (scene `target`), whether a path
    (or the warm start) was valid, and whether the warm start was."""
    kinds = tuple(int(k) for k in kinds)
    arrays, static = eqx.partition(target, eqx.is_array)
    x = (arrays, jnp.asarray(sgn, scene_dtype(target)), warm)
    eq_static = eqx.filter(jax.eval_shape(lambda: solve_unflagged(target, jnp.zeros(target.mesh.n, scene_dtype(target)),
                                                                  None, solver)),
                           lambda v: isinstance(v, jax.ShapeDtypeStruct), inverse=True)
    out, found, warmed = _homotopy_machine(static, steps, solver, kinds, warm is not None)(x)
    return eqx.combine(out, eq_static), found, warmed


def _homotopy_machine(static, steps, solver, kinds, has_warm):
    """`_homotopy`'s loop as a machine (`jaxrod._lanes`): inputs `(arrays, sgn, warm)`, the
    target scene's arrays (`static` its other leaves), the side and the warm start or None.
    A batch of them runs on lanes: each member's solves as alone, the batch costing the
    members' passes, not its slowest member's for each."""
    kinds_a = np.asarray(kinds, np.int32)

    def unpack(x):
        arrays, sgn, warm = x
        target = eqx.combine(arrays, static)
        dtype = scene_dtype(target)
        zero = jnp.zeros((), dtype)
        flat = _deformed(_with_gap(target, zero), zero, zero)
        return target, arrays, sgn, warm, dtype, flat

    seed_for = lambda target: 0.0 if target.contact is None else CONTACT_SEED  # noqa: E731
    # the secant prediction (module docstring); not with self-contact, where a predicted state
    # could already pass through itself, which no penalty undoes
    secant_for = lambda target: 1.0 if target.contact is None else 0.0  # noqa: E731

    def scene_at(target, arrays, dtype, phase, kind, step):
        u = jnp.where(phase == _FLAT, 0.0, (step + 1).astype(dtype) / steps)
        uc, ua = _path_params(kind, u)
        deformed = eqx.filter(_deformed(_with_gap(target, u), uc, ua), eqx.is_array)
        return eqx.combine(_tree_where((phase == _FINAL) | (phase == _WARM), arrays, deformed), static)

    def start_of(target, guess, phase, t, m, dt, dm):
        # where the solve of a phase starts: a path step from the secant prediction (the last
        # step's change added again)
        t_in = jnp.where(phase == _FLAT, guess,
                         jnp.where(phase == _PATH, t + secant_for(target) * dt + seed_for(target), t))
        m_in = jnp.where(phase == _FLAT, jnp.zeros_like(m), jnp.where(phase == _PATH, m + secant_for(target) * dm, m))
        return newton_start(t_in, m_in)

    def init(x):
        target, arrays, sgn, warm, dtype, flat = unpack(x)
        guess = sgn * buckled_guess(flat, True)
        shapes = eqx.filter(jax.eval_shape(lambda: solve_unflagged(target, guess, None, solver)),
                            lambda v: isinstance(v, jax.ShapeDtypeStruct))
        out0 = jax.tree.map(lambda s: jnp.zeros(s.shape, s.dtype), shapes)
        i0 = jnp.zeros((), jnp.int32)
        f0 = jnp.zeros((), bool)
        t_init, m_init, phase0 = guess, jnp.zeros(2, dtype), i0 + _FLAT
        if has_warm:
            t_w, m_w, ok_w = warm
            t_init, m_init = jnp.where(ok_w, t_w, t_init), jnp.where(ok_w, m_w, m_init)
            phase0 = jnp.where(ok_w, _WARM, _FLAT).astype(jnp.int32)
        c0 = (phase0, i0, i0, t_init, m_init, f0, f0, guess, jnp.zeros(2, dtype), f0, jnp.zeros_like(t_init),
              jnp.zeros_like(m_init), out0)
        return c0 + (start_of(target, guess, phase0, t_init, m_init, c0[10], c0[11]), guess)

    def step(x, c):
        target, arrays, sgn, warm, dtype, flat = unpack(x)
        c, nw, guess = c[:13], c[13], c[14]
        phase, k, step, t, m, ok, found, t0, m0, ok0, dt, dm, out = c
        sc = scene_at(target, arrays, dtype, phase, jnp.asarray(kinds_a)[jnp.minimum(k, len(kinds) - 1)], step)
        nw, nneg = newton_iteration(sc, solver, nw, count=True)
        # the solve as `solve_unflagged` reports it (a converged iterate is kept, so `nneg`,
        # counted at the iterate, is its unstable count)
        result = RESULTS.where((nw["result"] == RESULTS.successful) & (nneg > 0), RESULTS.converged_to_saddle,
                               nw["result"])
        eq = Equilibrium(nw["theta"], nw["mu"], result, nw["steps"], nneg, sc)
        good = eq.converged & eq.stable & (sgn * _fold_height(eq.theta, eq.force, sc) > 0)
        no_dt, no_dm = jnp.zeros_like(dt), jnp.zeros_like(dm)
        # flat start: valid -> the first path from it; else nothing to deform: polish
        after_flat = (jnp.where(good, _PATH, _FINAL), k, jnp.zeros_like(step), eq.theta, eq.force, good, found,
                      eq.theta, eq.force, good, no_dt, no_dm)
        # path step: still tracked -> next step, or the polish after the last one; lost from a
        # secant prediction -> the same step again from the last state; lost from there -> the
        # next path from the flat start, or the polish if none is left
        tracked = ok & still_tracked(eq, sgn, t, sc)
        retry = ~tracked & ok & jnp.any(secant_for(target) * dt != 0)
        last = step + 1 == steps
        more = k + 1 < len(kinds)
        lost = ~tracked & ~retry & more
        after_path = (jnp.where(tracked, jnp.where(last, _FINAL, _PATH),
                                jnp.where(retry | more, _PATH, _FINAL)),
                      jnp.where(tracked | retry, k, k + 1), jnp.where(tracked, step + 1, jnp.where(retry, step, 0)),
                      jnp.where(lost, t0, jnp.where(retry, t, eq.theta)),
                      jnp.where(lost, m0, jnp.where(retry, m, eq.force)),
                      jnp.where(lost, ok0, tracked | retry),
                      tracked & last, t0, m0, ok0,
                      jnp.where(tracked, eq.theta - t, no_dt), jnp.where(tracked, eq.force - m, no_dm))
        head = _tree_where(phase == _FLAT, after_flat, after_path)
        if has_warm:
            from ..energy.contact import self_intersects

            # the warm start (from the carried state): kept, or the flat start next
            warm_ok = still_tracked(eq, sgn, t, sc) & ~self_intersects(eq.theta, sc, force=eq.force)
            after_warm = (jnp.where(warm_ok, _DONE, _FLAT), k, jnp.zeros_like(step), guess, jnp.zeros_like(m),
                          jnp.zeros_like(ok), warm_ok, guess, jnp.zeros_like(m), jnp.zeros_like(ok), no_dt, no_dm)
            head = _tree_where(phase == _WARM, after_warm, head)
            out = _tree_where((phase == _WARM) & warm_ok, eqx.filter(eq, eqx.is_array), out)
        head = _tree_where(phase == _FINAL, (_DONE,) + c[1:12], head)
        out = _tree_where(phase == _FINAL, eqx.filter(eq, eqx.is_array), out)
        decided = head + (out,)
        # a solve that has not ended goes on in the next pass; one that has ended hands over
        # to the next phase, whose solve starts at once
        new = _tree_where(nw["done"], decided, c)
        nw = _tree_where(nw["done"], start_of(target, guess, new[0], new[3], new[4], new[10], new[11]), nw)
        # finished members keep their state
        return _tree_where(phase == _DONE, c + (nw, guess), new + (nw, guess))

    def done(x, c):
        return c[0] == _DONE

    def finish(x, c):
        # a kept warm start ends with `found` and not `ok`; a valid path ends with both
        return c[12], c[6], c[6] & ~c[5]

    return machine_vmap(init, step, done, finish)


def _finite(tree):
    """True when every float leaf of `tree` is finite."""
    leaves = jax.tree.leaves(eqx.filter(tree, eqx.is_inexact_array))
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in leaves]))


def initial_state_signed(scene, sgn, *, steps: int = 24, solver: Newton = Newton(), warm=None) -> Equilibrium:
    """`initial_state` with the side as a number, +1 up or -1 down (may be traced, e.g.
    mapped with `lax.map` to build both states through one traced body). `warm`:
    `(theta, force, ok)`, a state of a neighbouring scene tried first (see `_homotopy`);
    with it the result is `(equilibrium, whether the warm start was kept)`."""
    if not solver.minimize:
        raise ValueError("initial_state needs a minimizing Newton solver (minimize=True)")
    scene = float_scene(scene)
    dtype = scene_dtype(scene)
    sgn = jnp.asarray(sgn, dtype)
    target = lax.stop_gradient(scene)

    polished, found, warmed = _homotopy(target, sgn, steps, solver, warm=warm)
    # the derivatives of the polished state (implicit function theorem, as `solve_equilibrium`)
    t, m = _implicit(polished.theta, polished.force, scene)
    eq = Equilibrium(t, m, polished.result, polished.num_steps, polished.num_unstable, scene)
    good = eq.converged & eq.stable & (sgn * _fold_height(eq.theta, eq.force, eq.scene) > 0)
    result = RESULTS.where(found & good, eq.result,
                           RESULTS.where(eq.converged | ~found, RESULTS.state_not_found, eq.result))
    # a NaN or infinite parameter (a bad member of a batch) is a bad input, not a missing state
    result = RESULTS.where(_finite(scene), result, RESULTS.nonfinite)
    eq = eqx.tree_at(lambda e: e.result, eq, result)
    return eq if warm is None else (eq, warmed)
