r"""Snap angles: where the quasi-statically actuated strip loses stability, and of what kind.

Snap up: start in the down state at $\alpha=0$, increase $\alpha$ along the branch
(pseudo-arclength continuation) until the unstable count $\nu$ of the constrained Hessian
changes. Snap down: start in the up state, decrease $\alpha$. When the down state does
not exist at $\alpha=0$ (tight folds at large gaps), the snap-up path starts from the
state the snap-down path reached at its most negative angle, i.e. the other half of the
quasi-static hysteresis protocol, and says so (`start_result` is `start_substituted`).
A loss of stability at a fold is a snap however small the jump; at a branch point a
landing close by means a supercritical branch is followed (see `follow_path`). The critical
and landed states and every computed point of the path's stages are checked for
self-intersection (`jaxrod.self_intersects`).

The critical point between the last stable and the first unstable point is located by
bisection on the arclength along the stable point's tangent (each trial is a corrector
solve, finished by one Newton step past its tolerance, plus one Sturm count), to a bracket
$\Delta s\sim 2^{-24}$ of the step wide, then by linear interpolation of the eigenvalue that
crosses zero ($\mathsf K$'s eigenvalue nearest zero at both ends of the bracket,
`jaxrod.linalg.kkt.critical_pair`): the state, the angle and the mode at its zero are off by
the bracket's square, so $\alpha_c$ is exact to round-off at the given mesh: Newton on the
extended system (`jaxrod.critical_point`) started there moves it by at most 1.3e-13 rad at
149 of the 150 snapping paths of a 5 x 17 grid of (Psi0, G/L) at N = 100, by 5e-11 rad at
the other (a state through itself). On the mirror-symmetric branch the
bracket's states are kept mirror-symmetric. The polish
(`jaxrod.branches.located_critical_point`) checks that residual of the extended system and
attaches its implicit derivative. Its kind: under symmetric actuation, a *branch point* if
the mode that goes unstable is mirror-asymmetric, a *fold* (limit point in $\alpha$) if it
is symmetric; under one-sided actuation, a fold.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array

from ..linalg import kkt
from ._continuation import (STOP_BOUND, STOP_UNSTABLE, Continuation, SymmetricAlpha, _bordered_columns, _pieces,
                            _residual_norm, continue_branch, require_float64)
from ..energy.contact import coarse_for_contact, contact_energy, self_intersects, underresolved_contact
from ._critical import KIND_BRANCH_POINT, KIND_FOLD, KIND_NONE, located_critical_point
from ..energy.geometry import discretize
from ..statics import Newton, float_scene
from ..statics import initial_state_signed
from .._lanes import in_turn
from .._misc import check_bool, check_int, check_number, run_if
from .._compile import jit
from ..results import RESULTS
from ..statics import Equilibrium
from ..statics import mode_parity
from ._warm import Near, near_pair, start_branch, warm_critical
from ._landing import JUMP_DISTANCE, _fh, _is_mirror_symmetric, _land


KIND_NAMES = {KIND_NONE: "none", KIND_FOLD: "fold", KIND_BRANCH_POINT: "branch_point"}


class SnapPath(eqx.Module):
    """One direction of the hysteresis loop.

    `snaps` (bool), `alpha_c` (rad; NaN if it does not snap), `kind` (0 none, 1 fold,
    2 branch point), `theta_before`/`force_before` the critical state,
    `fold_height_before`, `theta_after`/`fold_height_after` the state it lands in,
    `branch` the continuation stages (leading axis: stage; a supercritical branch point
    is followed by a second stage on the asymmetric branch, a snap by one on the landed
    branch with `continue_after_snap=True`), `result` and `start_result` (below),
    `stop` (the deciding `Branch.stop`), `refine_result` (the RESULTS code of the polish: whether the located critical
    point solves the extended system, `jaxrod.branches.located_critical_point`),
    `mode` the critical mode (angle part, unit $L^2$ norm, at the located critical point), `jump` the $L^2$ distance of the
    landed angle field from the critical one (rad; NaN if it does not snap), `stage` the
    index of the `branch` stage that decided the path (holds the critical point; the stages
    before it were supercritical branch points or contact clicks), `clicks` the number of
    contact clicks before it (always 0 without self-contact; see `follow_path`), `warm` whether the
    critical point was found from a neighbouring design's (`snap_angles(..., near=)`,
    `jaxrod.branches._warm`; such a path walked no branch: its first stage holds only its start,
    `branch.count` 1).

    `result` is the whole path's code: `successful`, or the start state's code where it does
    not exist, `continuation_incomplete`, `landing_failed`, `self_intersecting` (the
    critical or the landed state, or a computed point of a stage up to the deciding one,
    passes through itself; `branch.crossing` marks the points), `derivative_unavailable` (the
    located point does not solve the extended system to tolerance: `alpha_c` carries no
    derivative). `start_result` is
    `start_substituted` where the path started from the other path's end (see the module
    docstring).

    `alpha_c`, `theta_before`, `force_before` and `fold_height_before` are differentiable
    with respect to the float leaves of the scene (implicit differentiation of the
    extended system; the discrete search itself carries no gradient). At a branch point
    (`kind` 2) the derivative is that of the mirror-symmetric family: it is taken through
    the scene's mirror-symmetric part (`jaxrod.branches.mirror_symmetric_part`), so it is
    exact along symmetric changes and zero along antisymmetric ones (one crease of a
    symmetric pair moved alone counts half of each), where alpha_c itself has no
    derivative."""

    snaps: Array
    alpha_c: Array
    kind: Array
    theta_before: Array
    force_before: Array
    fold_height_before: Array
    theta_after: Array
    force_after: Array
    fold_height_after: Array
    branch: object
    result: RESULTS
    start_result: RESULTS
    stop: Array
    jump: Array | None = None
    refine_result: RESULTS | None = None
    mode: Array | None = None
    stage: Array | None = None
    clicks: Array | None = None
    warm: Array | None = None


def _refine(scene, parameter, branch, settings, tol, bisections):
    """The critical point between the last stable and the first unstable point of `branch`:
    bisection on arclength, then linear interpolation of the crossing eigenvalue across the
    final bracket (module docstring). Returns its state `(theta, force, alpha)` and mode
    (Euclidean unit norm)."""
    F, F_lam, Kf = _pieces(scene, parameter)
    w = discretize(scene).h
    i = branch.count - 1
    ta, ma, la = branch.theta[i - 1], branch.force[i - 1], branch.lam[i - 1]
    tb, lb = branch.theta[i], branch.lam[i]
    nu_a = branch.num_unstable[i - 1]
    Ka = Kf(ta, ma, la)
    # tangent at a, oriented along the secant a -> b
    zt, zm = kkt.solve(Ka, -F_lam(ta, ma, la)[0], -F_lam(ta, ma, la)[1])
    nrm = jnp.sqrt(jnp.sum(w * zt**2) + 1.0)
    tau = (zt / nrm, zm / nrm, 1.0 / nrm)
    sgn = jnp.sign(jnp.sum(w * tau[0] * (tb - ta)) + tau[2] * (lb - la))
    sgn = jnp.where(sgn == 0, 1.0, sgn)
    tau = jax.tree.map(lambda v: sgn * v, tau)
    ds_b = branch.ds[i]
    # a bracket on the mirror-symmetric branch under symmetric actuation (where a branch point
    # lies) keeps its states mirror-symmetric: next to the branch point the corrector's solves
    # amplify the asymmetric round-off by 1/|eigenvalue| (to ~1e-6 rad at N = 60), which would
    # hide that the state is symmetric
    sym = isinstance(parameter, SymmetricAlpha) & _is_mirror_symmetric(ta, scene)
    flip = jnp.array([1.0, -1.0], ta.dtype)

    def symmetric(t, m):
        return jnp.where(sym, 0.5 * (t - t[::-1]), t), jnp.where(sym, 0.5 * (m + flip * m), m)

    # `bisections` halvings, then one more trial that corrects at `hi`, the state just past
    # the critical point (whose critical mode tells the kind). Each correction starts from
    # the last stable state moved along the tangent to `s`, at most the bracket's width away
    # (the prediction from `a` is up to the whole step away), so it takes fewer Newton
    # iterations to the same point. Each trial is a corrector: Newton on the residual and the
    # hyperplane `s` from `a` along the tangent, with one more step once converged; a
    # point farther than `s` from its prediction has left the branch. One pass of the loop is
    # one Newton iteration, or the unstable count of a corrected point (from the same
    # bordered solve), so that under `vmap` each member goes from trial to trial on its own
    steps = settings.steps_for(scene)
    cw = w * tau[0]
    solve, count = 0, 1

    def at(lo, hi, j):
        return jnp.where(j == bisections, hi, 0.5 * (lo + hi))

    def cond(c):
        return c["j"] <= bisections

    def body(c):
        lo, hi, j, (xt, xm, xl) = c["lo"], c["hi"], c["j"], c["x"]
        s = at(lo, hi, j)
        tp, lp = ta + s * tau[0], la + s * tau[2]
        g = F(xt, xm, xl)
        rs = jnp.dot(cw, xt - tp) + tau[2] * (xl - lp)
        Dt, Dm, Dl, nu = _bordered_columns(Kf(xt, xm, xl), F_lam(xt, xm, xl), cw, tau[2], -g[0][:, None],
                                           -g[1][:, None], jnp.reshape(-rs, (1,)))
        converged = (_residual_norm(g, scene) <= tol) & (jnp.abs(rs) <= tol)
        k = c["k"] + 1
        yt, ym, yl = xt + Dt[:, 0], xm + Dm[:, 0], xl + Dl[0]
        solving = c["phase"] == solve
        gave_up = ~converged & ((k >= steps) | ~(jnp.all(jnp.isfinite(yt)) & jnp.isfinite(yl)))
        far = jnp.sqrt(jnp.sum(w * (yt - tp) ** 2) + (yl - lp) ** 2) > jnp.abs(s)
        yt, ym = symmetric(yt, ym)
        # the trial is decided by the count of its corrected point, or where its solve gives up
        decide = ~solving | gave_up
        last = j == bisections
        stable_side = ~solving & c["conv"] & (nu == nu_a) & ~last
        point = jax.tree.map(lambda a_, b_: jnp.where(solving, a_, b_), (yt, ym, yl), c["x"])
        lo_n = jnp.where(decide & stable_side, s, lo)
        hi_n = jnp.where(decide & ~stable_side, s, hi)
        best = jax.tree.map(lambda new, old: jnp.where(decide & stable_side, new, old), point, c["best"])
        after = jax.tree.map(lambda new, old: jnp.where(decide & last, new, old), point, c["after"])
        j_n = jnp.where(decide, j + 1, j)
        s_n = at(lo_n, hi_n, j_n)
        guess = tuple(b_ + (s_n - lo_n) * d_ for b_, d_ in zip(best, tau))
        x = jax.tree.map(lambda g_, p_, o_: jnp.where(decide, g_, jnp.where(solving, p_, o_)),
                         guess, (yt, ym, yl), c["x"])
        phase = jnp.where(decide, solve, jnp.where(solving & converged, count, c["phase"]))
        return dict(lo=lo_n, hi=hi_n, j=j_n, best=best, after=after, x=x, phase=phase.astype(jnp.int32),
                    k=jnp.where(decide, 0, k), conv=jnp.where(solving, converged & ~far, c["conv"]))

    start = (ta, ma, la)
    lo0, hi0 = jnp.zeros_like(ds_b), ds_b
    x0 = tuple(b_ + at(lo0, hi0, 0) * d_ for b_, d_ in zip(start, tau))
    out = lax.while_loop(cond, body, dict(lo=lo0, hi=hi0, j=jnp.zeros((), jnp.int32), best=start, after=start,
                                          x=x0, phase=jnp.zeros((), jnp.int32), k=jnp.zeros((), jnp.int32),
                                          conv=jnp.zeros((), bool)))
    best, after = out["best"], out["after"]
    # the eigenvalue that crosses zero, on both sides of the bracket (one program for both)
    V, mu = lax.map(lambda x: kkt.critical_pair(Kf(*x)), jax.tree.map(lambda a, b: jnp.stack([a, b]), best, after))
    v_lo, v_hi = V[0], V[1] * jnp.where(jnp.dot(V[0], V[1]) < 0, -1.0, 1.0)
    # linear interpolation to its zero: the bracket is ~2^-bisections of a step wide, so the
    # interpolated state and angle are off by its square (round-off). Where the two values do
    # not straddle zero (a side that did not converge), the last stable state and the mode
    # past the point are kept
    crossed = (mu[0] * mu[1] < 0) & jnp.all(jnp.isfinite(V)) & jnp.all(jnp.isfinite(after[0]))
    f = jnp.where(crossed, mu[0] / jnp.where(crossed, mu[0] - mu[1], 1.0), 0.0)
    t, m, lam = jax.tree.map(lambda a, b: jnp.where(crossed, a + f * (b - a), a), best, after)
    v = jnp.where(crossed, v_lo + f * (v_hi - v_lo), v_hi)
    return t, m, lam, v / jnp.linalg.norm(v)


CONTACT_STAGES = 6
"""Stages of a path (see `follow_path`) in a scene with self-contact (2 without)."""
NEAR_FOLD = 0.02
"""|tau_lam| below which a path that does not snap is `fold_unresolved` (see `follow_path`)."""


def _stage(scene, parameter, t0, m0, lam0, ok0, direction, settings, bound, bisections, tol, near=None,
           use_near=False):
    """Continue from (t0, m0) at parameter lam0 until stability changes; refine; land. With
    `near` (a `_warm.Near`; used where `use_near`), the critical point from the neighbour's
    where that passes its checks, the walk and bisection only where it does not. Returns also
    whether the critical point was the warm one."""
    sc = parameter.set(scene, lam0)
    start = Equilibrium(t0, m0, RESULTS.successful, jnp.zeros((), jnp.int32), jnp.zeros((), jnp.int32), sc)

    def walk(start):
        branch = continue_branch(sc, start, parameter, direction=direction, bounds=(-bound, bound),
                                 settings=settings, stop_on_instability=True, check_contact=True)
        return (branch, *_refine(scene, parameter, branch, settings, tol, bisections))

    if near is None:
        branch, t, m, lam, v = walk(start)
        warm = jnp.zeros((), bool)
    else:
        def attempt(n, o):
            return warm_critical(scene, n, o, direction, parameter, bound, tol)

        args = (near, ok0 & use_near)
        nothing = jax.tree.map(lambda x: jnp.zeros(x.shape, x.dtype), jax.eval_shape(attempt, *args))
        critical, warm, _ = run_if(ok0 & use_near & near.usable, attempt, nothing, args)
        branch0 = start_branch(jax.eval_shape(walk, start)[0], t0, m0, lam0)
        branch, t, m, lam, v = run_if(~warm, walk, (branch0, *critical), (start,))
    snaps = (branch.stop == STOP_UNSTABLE) & ok0
    if isinstance(parameter, SymmetricAlpha):
        asym = (mode_parity(v[:, None])[0] < 0) & _is_mirror_symmetric(t, scene)
        kind = jnp.where(asym, KIND_BRANCH_POINT, KIND_FOLD)
    else:
        kind = jnp.full((), KIND_FOLD)
    kind = jnp.where(snaps, kind, KIND_NONE).astype(jnp.int32)
    ta, ma, fa, eq_after = _land(scene, parameter, t, m, lam, v, direction, direction > 0, Newton())
    fb = _fh(scene, parameter, t, m, lam)
    v = v / jnp.sqrt(jnp.sum(discretize(scene).h * v**2))  # unit L2 norm, as `critical_point`'s
    # landed: a stable equilibrium (`_land` accepts no other)
    return branch, snaps, kind, t, m, lam, fb, ta, ma, fa, eq_after.converged & eq_after.stable, v, warm


def follow_path(scene, start_eq, direction, parameter, settings, bound, bisections, tol, stages=2,
                continue_after_snap=False, substituted=False, near=None):
    """One direction of the loop. After a loss of stability the critical state is pushed
    along the unstable mode 1e-3 rad past alpha_c and relaxed. At a fold the strip snaps
    there, however small the jump (past a fold the branch has no equilibrium nearby: the
    landed state is another one). At a branch point it snaps if it lands more than
    `JUMP_DISTANCE` away (L2 norm of the angle field; to the other state, or to a distant
    asymmetric one); if it lands close by, the instability was supercritical (a stable
    asymmetric branch grows continuously out of the branch point, amplitude
    ~ sqrt(1e-3) ~ 0.03): no snap yet, and the path continues from that state, up to
    `stages` times. `substituted` (traced bool): the start is the other path's end. `near`: a
    neighbour's path (`jaxrod.branches._warm.Near`) whose critical point the first stage starts
    from (see `_stage`), or None.

    With self-contact, a loss of stability of a state in contact (contact energy above zero)
    whose landing lies within `JUMP_DISTANCE` and leaves the fold height $y(L/2)$ on its side
    is a *click*: pressed parts of the strip slip past each other (at Psi0 = 60 deg,
    G/L = 0.2, N = 48 the fold height moves by 7e-4 L), the fold does not go through, and
    the path continues from the landed state as after a supercritical branch point
    (`SnapPath.clicks` counts them). The snap is the next loss of stability with a larger
    jump, with the fold going through, or out of contact. (Without contact every fold is a
    snap however small its jump, which is what ends a path at a cusp, see
    `jaxrod.termination_gap`.)

    A path that reaches the bound without losing stability is a "no snap" only if its
    tangent never all but turned in alpha on the way: a computed point with
    |tau_lam| < `NEAR_FOLD` (next to a cusp, where the fold pair can be shorter than one
    step and lie between two computed points) makes it `fold_unresolved`."""
    def body(c, stage):
        t0, m0, lam0, ok, done, clicks, out = c
        def run(sc, d, args):
            t0, m0, lam0, ok0, nr, use = args
            return _stage(sc, parameter, t0, m0, lam0, ok0, d, settings, bound, bisections, tol, near=nr,
                          use_near=use)

        # (the neighbour reaches the stage through the operands, as `run_if` asks)
        args = (t0, m0, lam0, ok & ~done, near, (stage == 0) & ~jnp.asarray(substituted, bool))
        if continue_after_snap:
            # after a snap the next stage follows the landed branch (to |alpha| = bound or its
            # own loss of stability): the post-snap branch of the hysteresis figures
            br, snaps, kind, t, m, lam, fb, ta, ma, fa, landed, v, warm = run(scene, direction, args)
        else:
            # skip the later stages of a path that has been decided: `run_if`, a loop of at most
            # one pass, not `lax.cond`, which under `vmap` (a batched `done`) would run the whole
            # stage for every member at every stage (2x the continuation work of a phase diagram)
            shapes = jax.eval_shape(lambda a: run(scene, direction, a), args)
            skipped = jax.tree.map(lambda s: jnp.zeros(s.shape, s.dtype), shapes)
            br, snaps, kind, t, m, lam, fb, ta, ma, fa, landed, v, warm = run_if(~done, run, skipped,
                                                                                 (scene, direction, args))
        w = discretize(scene).h
        dist = jnp.sqrt(jnp.sum(w * (ta - t) ** 2))
        if scene.contact is None:
            click = jnp.zeros((), bool)
        else:
            # a small jump of a state in contact after which the fold keeps its side
            click = (contact_energy(t, scene) > 0) & (jnp.sign(fa) == jnp.sign(fb)) & (dist <= JUMP_DISTANCE)
        jumped = snaps & ~click & ((dist > JUMP_DISTANCE) | (kind == KIND_FOLD)) & landed
        # the path is decided here if it did not lose stability (bound reached, start
        # missing, or the continuation gave up: `stop` tells which), if it jumped, or if it
        # lost stability but the relaxation past alpha_c found no equilibrium (`landed`
        # False: a loss of stability all the same, whose landing is unknown)
        final = ~done & (~snaps | jumped | ~landed)
        new_out = (snaps, kind, t, m, lam, fb, ta, ma, fa, br.stop, landed, dist, stage, v, warm)
        out = jax.tree.map(lambda n, o: jnp.where(final, n, o), new_out, out)
        lam_next = lam + direction * 1e-3
        clicks = clicks + (~done & snaps & landed & click).astype(jnp.int32)
        nxt = (ta, ma, lam_next, ok & snaps & landed, done | final, clicks, out)
        return nxt, br

    dtype = start_eq.theta.dtype
    nan = jnp.full((), jnp.nan, dtype)
    out0 = (jnp.zeros((), bool), jnp.zeros((), jnp.int32), start_eq.theta, start_eq.force, nan, nan,
            start_eq.theta, start_eq.force, nan, jnp.full((), -1, jnp.int32), jnp.ones((), bool), nan,
            jnp.full((), stages - 1, jnp.int32), jnp.zeros_like(start_eq.theta), jnp.zeros((), bool))
    lam0 = parameter.get(start_eq.scene)
    ok0 = start_eq.result == RESULTS.successful
    init = (start_eq.theta, start_eq.force, jnp.asarray(lam0, dtype), ok0, jnp.zeros((), bool),
            jnp.zeros((), jnp.int32), out0)
    (_, _, _, _, done, clicks, out), branches = lax.scan(body, init, jnp.arange(stages, dtype=jnp.int32))
    snaps, kind, t, m, lam, fb, ta, ma, fa, stop, landed, dist, last_stage, mode, warm = out
    snaps = snaps & done
    # decided without a snap, but not at the parameter bound (`STOP_BOUND`): the continuation
    # gave up (buffer full, step too small); or never decided (every stage supercritical)
    incomplete = ~done | (~snaps & (stop != STOP_BOUND))
    # a path that reached the bound without losing stability but whose tangent all but turned
    # in alpha at some computed point (|tau_lam| < NEAR_FOLD): near a cusp the fold pair can be
    # shorter than a step and lie between two computed points, so "no snap" is not known
    k = jnp.arange(branches.tau_lam.shape[-1])
    inside = (k >= 1) & (k < branches.count[:, None]) & (jnp.arange(stages)[:, None] <= last_stage)
    near_fold = jnp.any(inside & (jnp.abs(branches.tau_lam) < NEAR_FOLD))
    # the reported states must be configurations of the contact-free model: the critical
    # state (the start state where the path does not snap), the landed one, and every
    # computed point of the stages that decided the path (both states through one check)
    through = lax.map(lambda x: self_intersects(x, scene), jnp.stack([t, ta]))
    crossed = through[0] | (snaps & landed & through[1]) | jnp.any(inside & branches.crossing)
    # a state in contact (the critical or landed one, or a click on the way) on a mesh too coarse
    # for the contact thickness (`jaxrod.energy.contact.CONTACT_RESOLUTION`)
    if scene.contact is None:
        coarse = jnp.zeros((), bool)
    else:
        touched = lax.map(lambda x: underresolved_contact(x, scene), jnp.stack([t, ta]))
        clicked = (clicks > 0) & coarse_for_contact(scene)
        coarse = touched[0] | (snaps & landed & touched[1]) | clicked
    result = RESULTS.where(
        ~ok0, start_eq.result,
        RESULTS.where(incomplete, RESULTS.continuation_incomplete,
                      RESULTS.where(snaps & ~landed, RESULTS.landing_failed,
                                    RESULTS.where(crossed, RESULTS.self_intersecting,
                                                  RESULTS.where(~snaps & near_fold, RESULTS.fold_unresolved,
                                                                RESULTS.where(coarse,
                                                                              RESULTS.contact_underresolved,
                                                                              RESULTS.successful))))))
    start_result = RESULTS.where(ok0 & substituted, RESULTS.start_substituted, start_eq.result)
    lost = snaps & ~landed  # no landed state: NaN rather than the failed relaxation's iterate
    return SnapPath(
        snaps=snaps,
        alpha_c=jnp.where(snaps, lam, nan),
        kind=jnp.where(snaps, kind, KIND_NONE),
        theta_before=t,
        force_before=m,
        fold_height_before=jnp.where(snaps, fb, nan),
        theta_after=jnp.where(lost, nan, ta),
        force_after=jnp.where(lost, nan, ma),
        fold_height_after=jnp.where(snaps & landed, fa, nan),
        branch=branches,
        result=result,
        start_result=start_result,
        stop=stop,
        jump=jnp.where(snaps & landed, dist, nan),
        stage=last_stage,
        clicks=clicks,
        mode=mode,
        warm=warm & done,
    )


class SnapAngles(eqx.Module):
    """Both paths of the quasi-static hysteresis loop: `up` and `down` are
    [`jaxrod.SnapPath`][]s."""

    up: SnapPath
    down: SnapPath


@jit
def snap_angles(scene, *, settings: Continuation = Continuation(), bound: float = jnp.pi,
                bisections: int = 24, polish: bool = True, continue_after_snap: bool = False,
                near: SnapAngles | None = None) -> SnapAngles:
    r"""Critical clamp angles $\alpha_{c,\rm up}>0$ and $\alpha_{c,\rm down}<0$ of a scene
    under symmetric clamp rotation, their kinds, the states just before and after.

    Both clamps turn together, $\alpha_L=\alpha+\delta/2$, $\alpha_R=\alpha-\delta/2$, from the
    loop's start at $\alpha=0$; $\delta=\alpha_L-\alpha_R$ is the clamp misalignment of `scene`
    (0 for the paper's symmetric clamps, see [`jaxrod.SymmetricAlpha`][]), and $\alpha$ is the
    mean clamp angle. Only the difference of the scene's clamp angles matters. A path that
    reaches $|\alpha|=$`bound` without losing stability does not snap (`snaps=False`,
    `alpha_c=NaN`, kind "none").

    `polish=False` skips the polish (the extended system's residual and implicit
    derivative, `jaxrod.branches.located_critical_point`): the same $\alpha_c$, without a
    gradient (`refine_result` is `None`; a branch point's critical state is not projected
    onto the mirror-symmetric states, ~1e-7 rad). Used by [`jaxrod.phase_diagram`][].
    `continue_after_snap=True` also follows the landed branch after a snap to $|\alpha|=$`bound`
    (the post-snap branch of a hysteresis figure, in the `branch` stage after the deciding
    one); by default that stage is empty (`count` 0): the critical angles, kinds, states and
    codes are the same either way, and the landed branch costs about as much again as the
    rest of the call.

    The angles are those of the scene's mesh: second-order accurate, off by up to 0.17 deg
    at N = 100 ($s_0=0.02$). For the continuum value use
    [`jaxrod.snap_angles_extrapolated`][] (Richardson from $N$ and $2N$, ~1e-5 deg).

    `near`: the `SnapAngles` of a neighbouring scene (the previous design of an optimizer,
    the previous gap of a sweep; same mesh), or the few kB of it that
    `jaxrod.branches.near_pair` keeps. Each path then starts from the neighbour's
    critical point, by Newton's method on the extended system, accepted only where it passes
    the checks of `jaxrod.branches._warm` (an equilibrium at the edge of a stable region,
    reached from its stable side); elsewhere the whole path is walked. Landing, codes and
    self-intersection checks are a cold path's either way. An accepted path has `warm` True and
    no walked `branch`. Its angle is
    the same critical point's to round-off (~1e-12 deg), at about half the cost of the call
    (benchmarks/results/warm.md). Ignored
    with self-contact and with `continue_after_snap`.

    `bound` must lie in $(0,\pi]$ (rad), `bisections` be a positive integer.
    """
    if not isinstance(settings, Continuation):
        raise ValueError(f"settings must be a jaxrod.Continuation, got {settings!r}")
    check_number("bound", bound, lo=0.0, hi=jnp.pi, hi_open=False)
    check_int("bisections", bisections, lo=1)
    check_bool("polish", polish)
    check_bool("continue_after_snap", continue_after_snap)
    scene_d = float_scene(scene)
    parameter = SymmetricAlpha.for_scene(scene_d)  # keeps the clamps' misalignment, if any
    scene_d = parameter.set(scene_d, 0.0)  # carries gradients to the refinement
    scene = lax.stop_gradient(scene_d)
    require_float64(jnp.result_type(scene.strip.psi0), "snap_angles")
    near_paths = None
    if near is not None:
        if isinstance(near, Near):  # what `near_pair` kept of a neighbour: (down, up) stacked
            shape, near_paths = near.theta.shape[-1:], lax.stop_gradient(near)
        elif isinstance(near, SnapAngles):
            shape, near_paths = near.up.theta_before.shape, lax.stop_gradient(near_pair(near))
        else:
            raise ValueError(f"near must be the jaxrod.SnapAngles of a neighbouring scene or None, got {near!r}")
        if shape != (scene.mesh.n,):
            raise ValueError(f"near must come from a scene with the same mesh (n = {scene.mesh.n}), "
                             f"got states of shape {shape}")
    arrays, static = eqx.partition(scene, eqx.is_array)

    def search(x):
        # the start states and both paths, without derivatives: under `jax.vmap` on a CPU the
        # members run one after another (`jaxrod._lanes.in_turn`)
        sc = eqx.combine(x[0], static)
        # both start states through one traced body (index 0 up, 1 down), one after the other:
        # `lax.map`, not `vmap`, which would batch the LAPACK kernels inside the Newton loops
        # (see `_phase.py` for the XLA:CPU deadlock that batching caused)
        signs = jnp.array([1.0, -1.0], sc.strip.psi0.dtype)
        near_p = x[1]
        if near_p is None:
            starts = lax.map(lambda sg: initial_state_signed(sc, sg), signs)
        else:
            # the up state starts the down path (index 0 of `near_p`), the down state the up path:
            # each by Newton from the neighbour's start state, the homotopy where that fails
            warm = (near_p.start_theta, near_p.start_force, near_p.start_ok)
            starts = lax.map(lambda a: initial_state_signed(sc, a[0], warm=a[1:])[0], (signs, *warm))
        return _snap_angles_from(sc, starts, settings, bound, bisections, continue_after_snap, near_p)

    raw = in_turn(search)((arrays, near_paths))
    return _polish_both(scene_d, raw) if polish else raw


def _polish_both(scene_d, r):
    """[`_polish`][] of both paths of `r` (through one traced body, `lax.map` over the paths)."""
    parameter = SymmetricAlpha.for_scene(scene_d)
    paths = jax.tree.map(lambda a, b: jnp.stack([a, b]), r.down, r.up)
    out = lax.map(lambda p: _polish(scene_d, p, parameter), paths)
    return SnapAngles(up=jax.tree.map(lambda x: x[1], out), down=jax.tree.map(lambda x: x[0], out))


def _snap_angles_from(scene, starts, settings, bound, bisections, continue_after_snap=False, near_paths=None):
    """`snap_angles` from given start states (`starts`: the up and down equilibria of the
    scene at alpha = 0 stacked on a leading axis, as `lax.map` of `initial_state_signed` makes
    them; a member whose `result` is not successful does not exist). `near_paths`: a
    `jaxrod.branches._warm.Near` stacked (down, up) to start each path from, or None. The
    paths are not polished (`_polish_both`) and carry no derivative."""
    parameter = SymmetricAlpha.for_scene(scene)
    scene = lax.stop_gradient(scene)
    dtype = jnp.result_type(scene.strip.psi0)
    tol = settings.tol if settings.tol is not None else (1e-9 if dtype == jnp.float64 else 1e-3)
    pick = lambda tree, i: jax.tree.map(lambda x: x[i], tree)  # noqa: E731
    up_eq, down_eq = pick(starts, 0), pick(starts, 1)
    arrays = lambda e: eqx.filter(e, eqx.is_array)  # noqa: E731
    static = eqx.filter(down_eq, eqx.is_array, inverse=True)

    # The two paths run one after the other through a single traced body (one compiled
    # copy of the continuation, refinement and landing): first snap down from the up
    # state, then snap up from the down state; where the down state does not exist at
    # alpha = 0, snap up starts from the state the snap-down half of the loop reached: its
    # landing state (an equilibrium at alpha_c - 1e-3, relaxed by the landing), or the last
    # point of its branch if it did not snap (a converged continuation point). Both are
    # equilibria already, so they start the path as they are.
    def body(prev, direction):
        lam_end, t_end, m_end, end_ok, down_snaps, down_alpha, t_after, m_after = prev
        has_down = down_eq.result == RESULTS.successful
        need_alt = (direction > 0) & ~has_down
        landed = jnp.all(jnp.isfinite(t_after))
        alt_ok = jnp.where(down_snaps, landed, end_ok)
        alt = Equilibrium(jnp.where(down_snaps, t_after, t_end), jnp.where(down_snaps, m_after, m_end),
                          RESULTS.where(alt_ok, RESULTS.successful,
                                        RESULTS.where(down_snaps, RESULTS.landing_failed, up_eq.result)),
                          jnp.zeros((), jnp.int32), jnp.zeros((), jnp.int32),
                          parameter.set(scene, jnp.where(down_snaps, down_alpha - 1e-3, lam_end)))
        start = jax.tree.map(lambda u, d, a: jnp.where(direction < 0, u, jnp.where(has_down, d, a)),
                             arrays(up_eq), arrays(down_eq), arrays(alt))
        # with self-contact, legs pressed together mirror-symmetrically break the symmetry at
        # branch points of their own (supercritical: more stages before the snap)
        stages = 2 if scene.contact is None else CONTACT_STAGES

        # each path from the neighbour's critical point where that passes its checks (`_warm`)
        use_near = near_paths is not None and scene.contact is None and not continue_after_snap
        near = pick(near_paths, (direction > 0).astype(jnp.int32)) if use_near else None
        path = follow_path(scene, eqx.combine(start, static), direction, parameter, settings, bound, bisections, tol,
                           stages=stages, continue_after_snap=continue_after_snap, substituted=need_alt, near=near)
        br = jax.tree.map(lambda x: x[0], path.branch)  # first stage
        last = br.count - 1
        end_ok = (last >= 0) & (path.start_result == RESULTS.successful)
        nxt = (br.lam[last], br.theta[last], br.force[last], end_ok, path.snaps, path.alpha_c, path.theta_after,
               path.force_after)
        return nxt, path

    N = scene.mesh.n
    z = jnp.zeros((), dtype)
    init = (z, jnp.zeros(N, dtype), jnp.zeros(2, dtype), jnp.zeros((), bool), jnp.zeros((), bool), z,
            jnp.zeros(N, dtype), jnp.zeros(2, dtype))
    _, paths = lax.scan(body, init, jnp.array([-1.0, 1.0], dtype))
    return SnapAngles(up=pick(paths, 1), down=pick(paths, 0))


def _polish(scene_d, path, parameter):
    """The located critical point as a root of the extended system
    (`jaxrod.branches.located_critical_point`): the differentiable alpha_c and critical state
    (a branch point's projected onto the mirror-symmetric states). Where its residual is too
    large the path keeps its values, which carry no derivative, and says so."""
    a0 = jnp.where(path.snaps, path.alpha_c, 0.0)
    kind = jnp.where(path.kind == KIND_NONE, KIND_FOLD, path.kind)
    cp = located_critical_point(scene_d, path.theta_before, path.force_before, a0, path.mode, kind,
                                parameter=parameter)
    ok = path.snaps & (cp.result == RESULTS.successful)
    pick = lambda new, old: jnp.where(ok, new, old)  # noqa: E731
    refine_result = RESULTS.where(path.snaps, cp.result, RESULTS.successful)
    # a point that does not solve the extended system carries no derivative: say so
    result = RESULTS.where((path.result == RESULTS.successful) & path.snaps & ~ok,
                           RESULTS.derivative_unavailable, path.result)
    return eqx.tree_at(
        lambda p: (p.alpha_c, p.theta_before, p.force_before, p.fold_height_before, p.refine_result, p.mode,
                   p.result),
        path,
        (pick(cp.alpha, path.alpha_c), pick(cp.theta, path.theta_before), pick(cp.force, path.force_before),
         pick(cp.fold_height, path.fold_height_before), refine_result, pick(cp.mode, path.mode), result),
        is_leaf=lambda x: x is None,
    )
