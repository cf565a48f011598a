r"""Clamp programs designed by gradient: launch one ball, spare the others.

**Program.** Two straight moves of the clamps from the down state at $\alpha_L=\alpha_R=0$:
both clamps reach their peak angles $(p_L, p_R)$ at $t=$ `ramp` and hold them for `hold`
(`two_knot_program`). The design variables are $(p_L,p_R)$ in degrees.

**Objective.** With $v_m$ the peak speed of ball $m$ over the run (`jaxrod.Actuation.peak_speed`),
target $t$, a launch speed $v_L$ and a spare speed $v_S$,

$$\mathcal L(p)=\Big(\frac{\max(0,\,(1+\mu)v_L-v_t)}{v_L}\Big)^2+\sum_{m\ne t}\Big[\Big(\frac{\max(0,\,v_m-(1-\mu)v_S)}{v_S}\Big)^2
+\Big(\frac{\max(0,\,d_m-(1-\mu)d_S)}{d_S}\Big)^2\Big],$$

the last sum only with a displacement bound $d_S$ (`d_spare`), $d_m$ the distance ball $m$
ends up from where it started: a spared ball can be required to stay put, not only slow (a
ball nudged below $v_S$ still slides on the table, and may leave the next program's reach),

plus, while the strip never touches the target, its smallest gap beyond the contact layer in
layer thicknesses squared (a run that misses the target would otherwise have no gradient).
It is zero exactly when the target leaves faster than $(1+\mu)v_L$ and every other ball stays
below $(1-\mu)v_S$ and within $(1-\mu)d_S$ of its place (the margin $\mu$ = 0.1 keeps the design inside the goal when it is re-checked on
a finer mesh). Its gradient goes through the whole run (`jaxrod.actuate`: RATTLE, the
contacts, the table's friction) by reverse-mode autodiff; the contact law is twice
differentiable and the hinge viscosity of `jaxrod.ACTUATOR_VISCOSITY` damps the grid-scale
ringing that would otherwise make the launch speed wiggle on the scale of 1e-4 rad
(`jaxrod.dynamics._actuate`). It is minimized by Adam (optax) on $p$ in degrees, and the
design is re-checked by an independent forward run on a finer mesh.

**Steps** (`descend`). A step that does not lower the loss is undone, and Adam restarts from
the best program at half the step.

**Start.** The loss is rugged in the peaks (a ball is struck by one part of the strip or
another, or brushed twice), so with `scan_deg` the optimizer starts from the best of a grid
of programs around the naive start, `scan_deg` degrees apart (forward runs only): the one
with the widest margin, $\min(v_t/v_L-1,\ \min_{m\ne t}(1-v_m/v_S))$, so that a design
that meets its goal at once also keeps it on a finer mesh.

**Sequences** (`sequence_program`). Programs run one after the other in one run, the strip
reset down between them; `sequence_speeds` and `stage_outcome` judge each program in its
window. The paper's Fig. 4, three such programs designed and run in sequence, is
`jaxrod.paper.fig4_study`.
"""

from __future__ import annotations

import dataclasses
import math
import time

import jax
import jax.numpy as jnp
import numpy as np

import jaxrod as jr
from jaxrod.energy.contact import safe_norm

SEQUENCE_TIMING = dict(ramp=1.0, hold=0.8, reset=-110.0, rest=1.0)
"""`sequence_program`'s default timing (T, degrees)."""


def two_knot_program(peaks_deg, *, ramp=1.0, hold=0.8) -> jr.Program:
    """Both clamps from 0 to their peaks (p_L, p_R) degrees by t = `ramp`, held for `hold`."""
    p = jnp.deg2rad(jnp.asarray(peaks_deg, float))
    z = jnp.zeros((), p.dtype)
    return jr.Program(jnp.array([0.0, ramp, ramp + hold]), jnp.stack([z, p[0], p[0]]), jnp.stack([z, p[1], p[1]]))


def sequence_windows(count, *, ramp=SEQUENCE_TIMING["ramp"], hold=SEQUENCE_TIMING["hold"],
                     rest=SEQUENCE_TIMING["rest"]):
    """The time windows (start, end) in T of the `count` programs of `sequence_program` with
    the same timing: each from its first move to the end of its reset and rest (the last to
    the end of its hold)."""
    period = ramp + hold + 2.0 * ramp + rest
    return [(k * period, k * period + (period if k < count - 1 else ramp + hold)) for k in range(count)]


def sequence_program(peaks, *, ramp=SEQUENCE_TIMING["ramp"], hold=SEQUENCE_TIMING["hold"],
                     reset=SEQUENCE_TIMING["reset"], rest=SEQUENCE_TIMING["rest"]) -> jr.Program:
    """The designed programs one after the other in one run: each move to its peaks and hold,
    then a reset (both clamps to `reset` degrees, which snaps the strip back down, then to 0)
    and `rest` T of rest before the next (`sequence_windows` gives each program's window)."""
    t, aL, aR = [0.0], [0.0], [0.0]
    for k, (pl, pr) in enumerate(peaks):
        for (l, r), dt in [((pl, pr), ramp), ((pl, pr), hold)]:
            t.append(t[-1] + dt)
            aL.append(l)
            aR.append(r)
        if k < len(peaks) - 1:
            for (l, r), dt in [((reset, reset), ramp), ((0.0, 0.0), ramp), ((0.0, 0.0), rest)]:
                t.append(t[-1] + dt)
                aL.append(l)
                aR.append(r)
    return jr.Program.from_degrees(t, aL, aR)


def _loss(speeds, moved, reach, target, v_launch, v_spare, d_spare, margin):
    others = jnp.arange(speeds.shape[0]) != target
    miss = jnp.maximum(0.0, (1.0 + margin) * v_launch - speeds[target]) / v_launch
    hit = jnp.where(others, jnp.maximum(0.0, speeds - (1.0 - margin) * v_spare) / v_spare, 0.0)
    loss = miss**2 + jnp.sum(hit**2) + reach**2
    if d_spare is not None:  # (M,) bounds, inf where a ball may move
        bound = jnp.isfinite(d_spare) & others
        d = jnp.where(bound, d_spare, 1.0)
        push = jnp.where(bound, jnp.maximum(0.0, moved - (1.0 - margin) * d) / d, 0.0)
        loss = loss + jnp.sum(push**2)
    return loss


@dataclasses.dataclass
class ProgramDesign:
    """A designed program: `target`, `peaks_deg` (p_L, p_R), `speeds` (ball name -> peak
    speed, v*) and `displaced` (ball name -> distance from its start at the end, L) at the
    design mesh, `check` and `check_displaced` (the same at the finer re-check mesh), `reached`
    (the goal holds at the design mesh), `confirmed` (and at the re-check), `history` (loss
    per iteration), `iterations`, `seconds`, `codes` (the runs' result names)."""

    target: str
    peaks_deg: tuple
    speeds: dict
    check: dict
    displaced: dict
    check_displaced: dict
    reached: bool
    confirmed: bool
    history: list
    iterations: int
    seconds: float
    codes: tuple
    v_launch: float
    v_spare: float

    def program(self, **kw) -> jr.Program:
        return two_knot_program(self.peaks_deg, **kw)


def _speeds_and_code(scene, bodies, peaks, theta0, t1, target):
    """Peak speeds, the balls' displacements at the end, the target's reach term (its smallest gap beyond the contact layer, in
    layer thicknesses: nonzero only while the strip never touches it) and the run's code."""
    a = jr.actuate(scene, bodies, two_knot_program(peaks), theta0=theta0, t1=t1)
    reach = jnp.maximum(0.0, a.min_clearance[target] - bodies.thickness) / bodies.thickness
    moved = safe_norm(a.ball_position[-1] - bodies.position)
    return a.peak_speed, moved, reach, a.result


def design_program(scene, bodies, target, start_deg, *, v_launch=5.0, v_spare=1.0, d_spare=None, margin=0.1, steps=30,
                   lr=3.0, t1=1.8, n_check=32, check_scene=None, scan_deg=None, scan_size=5) -> ProgramDesign:
    """Find peaks (p_L, p_R) that launch ball `target` faster than `v_launch` and leave the
    others slower than `v_spare` (module docstring): Adam with learning rate `lr` degrees from
    `start_deg` (with `scan_deg`, from the best of the `scan_size` x `scan_size` grid of that
    spacing around it: the program with the widest margin, the smaller of the target's
    speed over `v_launch` and the others' under `v_spare`, relative),
    at most `steps` iterations, stopping once the loss is zero; a step that does not lower the
    loss is undone and Adam restarts from the best program at half the step (the loss is flat
    wherever a program misses every ball or does not snap, and Adam's momentum would carry it
    there and leave it); (with `d_spare`, a distance or
    a dict ball name -> distance, those spared balls must also end within it of their
    places); then a forward run
    of the design on the finer `check_scene` (default: `scene` at `n_check` segments)."""
    names = bodies.names
    if target not in names:
        raise ValueError(f"target must be one of {names}, got {target!r}")
    k = names.index(target)
    if d_spare is None:
        bounds = None
    elif isinstance(d_spare, dict):
        unknown = set(d_spare) - set(names)
        if unknown:
            raise ValueError(f"d_spare: unknown balls {sorted(unknown)} (balls: {names})")
        bounds = jnp.asarray([float(d_spare.get(nm, math.inf)) for nm in names])
    else:
        bounds = jnp.full((len(names),), float(d_spare))
    tic = time.perf_counter()
    theta0 = jr.initial_state(scene, "down").theta

    def loss_fn(p):
        v, moved, reach, code = _speeds_and_code(scene, bodies, p, theta0, t1, k)
        return _loss(v, moved, reach, k, v_launch, v_spare, bounds, margin), (v, moved, code)

    vg = jax.value_and_grad(loss_fn, has_aux=True)
    p = jnp.asarray(start_deg, float)
    if scan_deg is not None:
        h = scan_size // 2
        offsets = [(i * scan_deg, j * scan_deg) for i in range(-h, h + 1) for j in range(-h, h + 1)]
        scores = []
        for o in offsets:
            _, (v, moved, c) = loss_fn(p + jnp.asarray(o))
            v, moved = np.asarray(v), np.asarray(moved)
            spare = [1.0 - v[m] / v_spare for m in range(v.size) if m != k]
            if bounds is not None:
                spare += [1.0 - moved[m] / float(bounds[m]) for m in range(v.size)
                          if m != k and math.isfinite(float(bounds[m]))]
            score = min([v[k] / v_launch - 1.0] + spare)
            scores.append(score if c == jr.RESULTS.successful and np.isfinite(score) else -math.inf)
        p = p + jnp.asarray(offsets[int(np.argmax(scores))])
    best, history, (p, aux) = descend(vg, p, lr=lr, steps=steps, accept=lambda a: a[2] == jr.RESULTS.successful)
    if best is not None:
        loss, p, aux = best
    else:
        loss = float("inf")
    peaks = np.asarray(p)
    v, moved, code = np.asarray(aux[0]), np.asarray(aux[1]), jr.result_name(aux[2])
    speeds = {n: float(v[m]) for m, n in enumerate(names)}
    displaced = {n: float(moved[m]) for m, n in enumerate(names)}
    reached = bool(loss == 0.0)
    fine = check_scene if check_scene is not None else jr.make_scene(
        float(np.degrees(float(scene.strip.psi0))), float(scene.clamps.gap), s0=float(scene.strip.s0), n=n_check)
    eq = jr.initial_state(fine, "down")
    a = jr.actuate(fine, bodies, two_knot_program(peaks), theta0=eq.theta, t1=t1)
    check = {n: float(a.peak_speed[m]) for m, n in enumerate(names)}
    moved_fine = np.asarray(safe_norm(a.ball_position[-1] - bodies.position))
    check_displaced = {n: float(moved_fine[m]) for m, n in enumerate(names)}
    confirmed = bool(a.result == jr.RESULTS.successful and check[target] >= v_launch
                     and all(s <= v_spare for n, s in check.items() if n != target)
                     and (bounds is None or all(check_displaced[n] <= float(bounds[m]) for m, n in enumerate(names)
                                                if n != target)))
    return ProgramDesign(target=target, peaks_deg=tuple(float(x) for x in peaks), speeds=speeds, check=check,
                         displaced=displaced, check_displaced=check_displaced,
                         reached=reached, confirmed=confirmed, history=history, iterations=len(history) - 1,
                         seconds=time.perf_counter() - tic, codes=(code, jr.result_name(a.result)),
                         v_launch=v_launch, v_spare=v_spare)


def descend(value_and_grad, p, *, lr, steps, accept=lambda aux: True):
    """Adam (optax, learning rate `lr`) on `value_and_grad(p) -> ((loss, aux), grad)` from `p`:
    at most `steps` steps, stopping once an accepted iterate's loss is zero. A step that does
    not lower the loss below the best accepted one is undone, and Adam restarts from that best
    point with its steps halved (a descent method: the design losses are flat where a program
    misses every ball or does not snap, and Adam's momentum would carry it there and leave it).
    `accept(aux)`: whether an iterate may be kept (its run succeeded).

    Returns `(best, history, last)`: `best` = (loss, p, aux) of the lowest accepted iterate or
    None, `history` every evaluated loss, `last` = (p, aux) of the last evaluation."""
    import optax

    opt = optax.adam(lr)
    state = opt.init(p)
    history, best, best_grad, scale = [], None, None, 1.0
    for it in range(steps + 1):
        (loss, aux), g = value_and_grad(p)
        loss = float(loss)
        history.append(loss)
        last = (p, aux)
        ok = bool(accept(aux)) and math.isfinite(loss)
        if ok and (best is None or loss < best[0]):
            best, best_grad = (loss, p, aux), g
        elif best is not None:  # no descent: back to the best point, Adam restarted at half the step
            p, g = best[1], best_grad
            state = opt.init(p)
            scale *= 0.5
        if ok and loss == 0.0 or it == steps or not np.all(np.isfinite(np.asarray(g))):
            break
        upd, state = opt.update(g, state, p)
        p = optax.apply_updates(p, jax.tree.map(lambda u: scale * u, upd))
    return best, history, last


def remaining_bodies(bodies, run, launched):
    """The balls a run leaves on the table: every ball but those named in `launched`, at rest
    where the run left them (the table's friction stops a nudged ball within the run; a
    ball still faster than 1e-3 v* at the end is a ValueError). None when none is left."""
    names = [nm for nm in bodies.names if nm not in launched]
    pos, vel = np.asarray(run.ball_position[-1]), np.asarray(run.ball_velocity[-1])
    balls = []
    for nm in names:
        m = bodies.names.index(nm)
        if np.hypot(*vel[m]) > 1e-3:
            raise ValueError(f"ball {nm!r} still moves at {np.hypot(*vel[m]):.3g} v* at the end of the run")
        balls.append(jr.Ball(nm, tuple(float(x) for x in pos[m]), float(bodies.radius[m]), float(bodies.mass[m])))
    if not balls:
        return None
    return jr.Bodies(balls, stiffness=bodies.stiffness, thickness=bodies.thickness, table=bodies.table,
                     floor=bodies.floor)


def _per_window(run, targets, values, reduce, timing):
    """`reduce` of the samples `values` (n, M) within each program's window, per ball still
    on the table then (not the target of an earlier program)."""
    t = np.asarray(run.t)
    out = []
    for k, (a, b) in enumerate(sequence_windows(len(targets), **timing)):
        w = np.isfinite(t) & (t >= a) & (t <= b)
        out.append({nm: float(reduce(values[w, m])) for m, nm in enumerate(run.names) if nm not in targets[:k]})
    return out


def sequence_speeds(run, targets, **timing):
    """Per program of a sequence run (`targets` in order): each ball's peak speed (v*) within
    the program's window (`sequence_windows`, with its `timing` keywords), for the balls
    still on the table then (not the target of an earlier program)."""
    v = np.hypot(*np.moveaxis(np.asarray(run.ball_velocity), -1, 0))
    return _per_window(run, targets, v, np.max, timing)


def sequence_clearances(run, targets, **timing):
    """As `sequence_speeds`, each ball's smallest clearance (L) to the strip within the
    program's window (`Actuation.ball_clearance`: the gap between the ball's surface and the
    centreline; the contact layer acts below `Bodies.thickness`): by how much a spared ball
    stayed out of the strip's reach."""
    return _per_window(run, targets, np.asarray(run.ball_clearance), np.min, timing)


def stage_outcome(speeds, target, *, v_launch=5.0, v_spare=1.2):
    """One program of a sequence, from its balls' peak speeds (`sequence_speeds`): the balls it
    launched (at least `v_launch`), whether it spared the others (none above `v_spare`), and
    whether it did as designed (its `target` launched and the others spared). The default
    speeds are the paper's Fig. 4 goal (`jaxrod.paper.FIG4_V_LAUNCH`, `FIG4_V_SPARE`)."""
    launched = [nm for nm, v in speeds.items() if v >= v_launch]
    spared = all(v <= v_spare for nm, v in speeds.items() if nm != target)
    return launched, spared, speeds[target] >= v_launch and spared
