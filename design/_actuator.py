r"""Study (d): a programmable actuator (the paper's Fig. 4), quasi-static and dynamic.

**Per-half observable.** For a strip with one central crease the *state of a half* is the
sign of its quarter-point height: $h_L=y(L/4)$ (left half, node $N/4$) and $h_R=y(3L/4)$
(right half, node $3N/4$), heights above the line through the clamps (MODEL.md: $y>0$ up).
A state is labelled by two letters, left half first: ``"DD"`` (the down state, both halves
below), ``"UU"`` (the up state), ``"UD"`` (left half up, right half down), ``"DU"``.
A half *snaps* in a move when its letter changes across a loss of stability (a jump of the
quasi-static path, landing in a different stable state); a letter that changes while the
path is still continuous is a *drift*, not a snap, and disqualifies the move.

**What the statics show (N = 40..80, $s_0=0.02$).** Rotating one clamp alone with the
other held at $\alpha=0$ (the protocol of `jr.snap_dynamics(kind="asymmetric")`) the down
state loses stability at a fold ($\alpha_L\approx46.4^\circ$ for $\Psi_0=60^\circ$, $G/L=0.5$)
and lands in the *up state*: both letters flip (``DD -> UU``), and the half far from the
moving clamp is the one that moves most (tangent-angle change $L^2$ 1.48 vs 1.24 rad). A
left-half-only snap therefore needs the held clamp tilted down: with $\alpha_R=\beta\lesssim
-90^\circ$ (and a tight enough fold, e.g. $\Psi_0=45^\circ$, $G/L=0.5$, $\beta=-120^\circ$) the
fold of the one-sided path lands in a mixed ``UD`` state whose right quarter stays below
the clamp line. `actuator_study` finds such a program and reports ``reached=False`` where
none of its moves does what it says (e.g. at $\beta=0$).

The up-state branch is continuous in $\alpha_R$: raising the right clamp from
``UD`` lifts the right half *without* a snap (``UD -> UU`` continuously), so a
"then the right half" step cannot start from ``UD``. The program therefore returns to the
down state between actuations, as the paper's experiment does (three separate snaps, each
propelling one ball).

**The program.** Straight moves in the clamp-angle plane $(\alpha_L,\alpha_R)$ between
waypoints, starting at $W_0=(\beta,\beta)$ in the down state ``DD``:

1. left half only: $W_1=(\alpha^{L}_{c}+\delta,\beta)$, the left clamp alone crosses the
   one-sided critical angle $\alpha^L_c$ of ``DD`` (a fold) by the margin $\delta$ (the
   smallest such move); lands in ``UD``;
2. reset: back to $W_0$; the strip snaps back to ``DD``;
3. right half only: $W_3=(\beta,\alpha^{R}_{c}+\delta)$ (the mirror image; $\alpha^R_c$ is
   computed independently and equals $\alpha^L_c$ to round-off by the mirror symmetry);
   lands in ``DU``;
4. reset to $W_0$, ``DD``;
5. both halves: $W_5=(\alpha^{s}_{c}+\delta,\alpha^{s}_{c}+\delta)$, both clamps together
   past the symmetric snap-up angle (`jr.snap_angles`); lands in ``UU``;
6. reset to $W_0$: both clamps back down, the strip snaps back to ``DD`` (the cycle can
   repeat).

A step is *reached* when its move starts in the intended state, lands stable in the intended
one, and (actuation steps) gets there by snapping exactly the intended halves with no drift
(`move_ok`). The held angle $\beta$ is optimized (projected gradient ascent on implicit
gradients, checked against central differences) for the largest landing margin
$m_1=\min(h_L,-h_R)$ of ``UD`` at $W_1$.
"""

from __future__ import annotations

import dataclasses
import math
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

import jaxrod as jr
from jaxrod._continuation import AbstractParameter, Continuation, LeftAlpha, RightAlpha
from jaxrod._critical import critical_point
from jaxrod._energy.lagrangian import positions
from jaxrod._initial import _initial_state
from jaxrod._kkt import modes, smallest_eigenvalues, structured
from jaxrod._snap import KIND_NAMES, _path
from jaxrod._solution import RESULTS, Equilibrium


# ----- per-half observable --------------------------------------------------------------

def _check_n(n):
    if n % 4:
        raise ValueError(f"n: the per-half observable needs n divisible by 4 (quarter-point nodes), got {n}")


def half_heights(theta, force, scene):
    """(y(L/4), y(L/2), y(3L/4)): left quarter, fold, right quarter heights."""
    n = scene.mesh.n
    return positions(theta, force, scene)[jnp.array([n // 4, n // 2, 3 * n // 4]), 1]


def half_state(h) -> str:
    """Two letters from `half_heights`: left half then right half, U (above) or D."""
    h = np.asarray(h)
    return ("U" if h[0] > 0 else "D") + ("U" if h[2] > 0 else "D")


def flipped(a: str, b: str) -> frozenset:
    """The halves ("L", "R") whose letter differs between states a and b."""
    return frozenset(nm for nm, x, y in zip("LR", a, b) if x != y)


# ----- straight moves in the clamp-angle plane ------------------------------------------

class LinePath(AbstractParameter):
    r"""Continuation parameter $t$ (radians of clamp-angle travel) along the straight move
    $(\alpha_L,\alpha_R)=a_0+t\,u$, $u=(a_1-a_0)/|a_1-a_0|$."""

    a0: jax.Array
    u: jax.Array

    def get(self, scene):
        a = jnp.stack([scene.clamps.alpha_left, scene.clamps.alpha_right])
        return jnp.dot(a - self.a0, self.u)

    def set(self, scene, value):
        a = self.a0 + value * self.u
        return eqx.tree_at(lambda s: (s.clamps.alpha_left, s.clamps.alpha_right), scene, (a[0], a[1]))


def _at(scene, a):
    return eqx.tree_at(lambda s: (s.clamps.alpha_left, s.clamps.alpha_right), scene, (a[0], a[1]))


# continuation steps of at most ~3 deg of clamp travel, so the end state of a move is re-solved
# from close by
MOVE_SETTINGS = Continuation(ds_max=0.05, max_points=600)
OVERSHOOT = 0.5  # rad: the continuation runs this far past the end of a move (see `_segment`)


@eqx.filter_jit
def _segment(scene, theta, force, a0, a1, settings):
    """Follow the branch through (theta, force) at angles a0 toward a1 until stability changes
    (then refine and land, as `jr.snap_angles` does). The continuation runs `OVERSHOOT` past
    a1, so that a loss of stability just before a1 is not lost to the bound test (a point
    past the bound is not tested for stability); a loss of stability past a1 is no snap of
    this move. Without a snap, the end state is re-solved at a1 from the last branch point
    before a1 (the stable branch is monotone in t up to its loss of stability)."""
    length = jnp.sqrt(jnp.sum((a1 - a0) ** 2))
    par = LinePath(a0, (a1 - a0) / length)
    sc0 = _at(scene, a0)
    eq = Equilibrium(theta, force, RESULTS.successful, jnp.zeros((), jnp.int32), jnp.zeros((), jnp.int32), sc0)
    p = _path(sc0, eq, 1.0, par, settings, length + OVERSHOOT, 48, 1e-9, stages=2)
    snaps = p.snaps & (p.alpha_c <= length)
    br = jax.tree.map(lambda x: x[0], p.branch)
    idx = jnp.arange(br.lam.shape[0])
    before_end = (idx < br.count) & (br.lam <= length)
    last = jnp.max(jnp.where(before_end, idx, 0))
    t_c = jnp.where(snaps, p.alpha_c, 0.0)
    a_c = a0 + t_c * par.u
    a_land = a0 + (t_c + 1e-3) * par.u
    sc_c, sc_l = _at(scene, a_c), _at(scene, a_land)
    end = jr.solve_equilibrium(_at(scene, a1), br.theta[last], br.force[last])
    return dict(snaps=snaps, t_c=t_c, a_c=a_c, a_land=a_land,
                h_before=half_heights(p.theta_before, p.force_before, sc_c),
                theta_after=p.theta_after, force_after=p.force_after,
                h_after=half_heights(p.theta_after, p.force_after, sc_l),
                theta_end=end.theta, force_end=end.force, end_ok=end.result == RESULTS.successful,
                h_end=half_heights(end.theta, end.force, _at(scene, a1)), stop=br.stop)


@dataclasses.dataclass
class SnapEvent:
    """A loss of stability on a move: the clamp angles (deg), the half heights just before
    and just after (landing), the state letters, the halves that flipped."""

    alpha_deg: tuple
    h_before: tuple
    h_after: tuple
    before: str
    after: str
    halves: frozenset


@dataclasses.dataclass
class MoveReport:
    """One straight move from `a_from` to `a_to` (deg): its snap events, the drifts (letters
    that changed without a snap), the final state, its half heights, its stability."""

    a_from: tuple
    a_to: tuple
    start: str
    events: list
    drift: frozenset
    final: str
    h_final: tuple
    stable: bool
    theta: np.ndarray
    force: np.ndarray

    @property
    def snapped(self) -> frozenset:
        out = frozenset()
        for e in self.events:
            out = out | e.halves
        return out


def quasi_static_move(scene, theta, force, a_from_deg, a_to_deg, *, settings=MOVE_SETTINGS,
                      max_snaps=3) -> MoveReport:
    """Move the clamps quasi-statically along a straight line from `a_from_deg` to `a_to_deg`
    ((alpha_L, alpha_R) in degrees), starting from the equilibrium (theta, force) at
    `a_from_deg`; after each snap continue from the landing state."""
    _check_n(scene.mesh.n)
    a0 = jnp.deg2rad(jnp.asarray(a_from_deg, float))
    a1 = jnp.deg2rad(jnp.asarray(a_to_deg, float))
    h0 = np.asarray(half_heights(theta, force, _at(scene, a0)))
    state = half_state(h0)
    start = state
    events, drift = [], frozenset()
    t, m, a = theta, force, a0
    for _ in range(max_snaps + 1):
        r = jax.tree.map(np.asarray, _segment(scene, t, m, a, a1, settings))
        if bool(r["snaps"]):
            hb, ha = r["h_before"], r["h_after"]
            sb, sa = half_state(hb), half_state(ha)
            drift = drift | flipped(state, sb)
            events.append(SnapEvent(tuple(np.degrees(r["a_c"]).round(6)), tuple(hb), tuple(ha), sb, sa,
                                    flipped(sb, sa)))
            state = sa
            t, m, a = jnp.asarray(r["theta_after"]), jnp.asarray(r["force_after"]), jnp.asarray(r["a_land"])
            continue
        break
    else:  # pragma: no cover - more snaps on one move than max_snaps
        raise RuntimeError("quasi_static_move: more than max_snaps snaps on one move")
    he = r["h_end"]
    final = half_state(he)
    drift = drift | flipped(state, final)
    eq = jr.solve_equilibrium(_at(scene, a1), jnp.asarray(r["theta_end"]), jnp.asarray(r["force_end"]))
    stable = bool(r["end_ok"]) and int(jr.stability(eq, k=2).num_unstable) == 0
    return MoveReport(tuple(np.asarray(a_from_deg, float)), tuple(np.asarray(a_to_deg, float)), start, events,
                      drift, final, tuple(he), stable, np.asarray(r["theta_end"]), np.asarray(r["force_end"]))


# ----- the program ----------------------------------------------------------------------

# (start state, final state, halves that must snap; None: a reset, any snap allowed)
INTENDED = (("DD", "UD", frozenset("L")), ("UD", "DD", None), ("DD", "DU", frozenset("R")),
            ("DU", "DD", None), ("DD", "UU", frozenset("LR")), ("UU", "DD", None))
STEP_NAMES = ("left half only", "reset", "right half only", "reset", "both halves", "reset")


def move_ok(rep: MoveReport, step: int) -> bool:
    """The move does what step `step` of the program says: from the intended start state it
    lands, stable, in the intended state; an actuation step (not a reset) must get there by
    snapping exactly the intended halves, with no letter drifting."""
    s0, s1, halves = INTENDED[step]
    if not (rep.start == s0 and rep.final == s1 and rep.stable and len(rep.events) >= 1):
        return False
    return halves is None or (rep.snapped == halves and not rep.drift)


def run_program(scene, waypoints_deg, *, settings=MOVE_SETTINGS):
    """The quasi-static program through `waypoints_deg` (list of (alpha_L, alpha_R), deg),
    starting in the down state at the first waypoint. Returns (start equilibrium, reports)."""
    sc = _at(scene, jnp.deg2rad(jnp.asarray(waypoints_deg[0], float)))
    eq = jr.initial_state(sc, "down")
    reps = []
    t, m = eq.theta, eq.force
    for a, b in zip(waypoints_deg[:-1], waypoints_deg[1:]):
        rep = quasi_static_move(scene, t, m, a, b, settings=settings)
        reps.append(rep)
        t, m = jnp.asarray(rep.theta), jnp.asarray(rep.force)
    return eq, reps


# ----- one-sided critical angles, differentiable ----------------------------------------

@eqx.filter_jit
def _one_sided(scene, theta, force, direction, parameter, settings):
    """Bisection (as `jr.snap_angles`) then the extended-system refinement of the first loss
    of stability of the branch through (theta, force) when `parameter` (LeftAlpha or
    RightAlpha) moves in `direction`; alpha_c is differentiable w.r.t. the scene."""
    sg = lax.stop_gradient
    sc = sg(scene)
    eq = Equilibrium(sg(theta), sg(force), RESULTS.successful, jnp.zeros((), jnp.int32),
                     jnp.zeros((), jnp.int32), sc)
    p = _path(sc, eq, direction, parameter, settings, jnp.pi, 48, 1e-9, stages=1)
    a0 = jnp.where(p.snaps, p.alpha_c, parameter.get(sc))
    scc = parameter.set(sc, a0)
    K = structured(p.theta_before, p.force_before, scc)
    v = modes(K, smallest_eigenvalues(K, 1))[:, 0]
    cp = critical_point(scene, p.theta_before, p.force_before, a0, v, 1, parameter=parameter)
    ok = p.snaps & (cp.result == RESULTS.successful) & (jnp.abs(sg(cp.alpha) - a0) < 1e-6)
    return dict(snaps=p.snaps, refined=ok, alpha_c=jnp.where(ok, cp.alpha, a0), alpha_bisect=a0,
                theta_after=p.theta_after, force_after=p.force_after)


def _ud_margin_fn(psi0_deg, gap, s0, n, margin_deg, settings):
    """beta (rad) -> (m1, details): the landing margin min(h_L, -h_R) of the state at W1 of
    the program held at beta; differentiable (implicit gradients of alpha_c and of the
    equilibrium at W1) where the one-sided path snaps."""
    base = jr.make_scene(psi0_deg, gap, 0.0, s0=s0, n=n)
    dm = math.radians(margin_deg)

    def f(beta):
        sc = _at(base, jnp.stack([beta, beta]))
        eq0 = _initial_state(lax.stop_gradient(sc), -1.0)
        r = _one_sided(sc, eq0.theta, eq0.force, 1.0, LeftAlpha(), settings)
        sc1 = _at(base, jnp.stack([r["alpha_c"] + dm, beta]))
        eq1 = jr.solve_equilibrium(sc1, r["theta_after"], r["force_after"])
        h = half_heights(eq1.theta, eq1.force, sc1)
        return jnp.minimum(h[0], -h[2]), dict(alpha_c=r["alpha_c"], snaps=r["snaps"], refined=r["refined"],
                                              h=h, ok=eq1.result == RESULTS.successful, start_ok=eq0.result)

    return f


@dataclasses.dataclass
class GradientCheck:
    """d(quantity)/d(beta) by implicit differentiation vs a central difference (step `h` rad)."""

    name: str
    beta_deg: float
    grad: float
    fd: float
    h: float

    @property
    def rel_error(self):
        return abs(self.grad - self.fd) / max(abs(self.fd), 1e-12)


def gradient_checks(psi0_deg, gap, beta_deg, *, s0=0.02, n=40, margin_deg=3.0, h=1e-4,
                    settings=Continuation()):
    """Implicit gradients of alpha_c^(1) and of the landing margin m1 w.r.t. the held angle
    beta, each against a central difference of the full (bisection + refinement) pipeline."""
    f = _ud_margin_fn(psi0_deg, gap, s0, n, margin_deg, settings)
    b = jnp.asarray(math.radians(beta_deg))
    out = []
    for name, g in (("alpha_c1", lambda x: f(x)[1]["alpha_c"]), ("m1", lambda x: f(x)[0])):
        gr = float(jax.grad(g)(b))
        fd = (float(g(b + h)) - float(g(b - h))) / (2 * h)
        out.append(GradientCheck(name, beta_deg, gr, fd, h))
    return out


def optimize_hold(psi0_deg, gap, beta0_deg, *, bounds_deg=(-150.0, -60.0), s0=0.02, n=40, margin_deg=3.0,
                  max_iter=8, settings=Continuation()):
    """Projected gradient ascent on m1(beta) with a backtracking line search (steps in
    degrees). Returns (beta_deg, m1, history[(beta_deg, m1, dm1/dbeta per rad)])."""
    f = _ud_margin_fn(psi0_deg, gap, s0, n, margin_deg, settings)
    vg = jax.value_and_grad(lambda x: f(x)[0])
    lo, hi = bounds_deg
    beta = float(np.clip(beta0_deg, lo, hi))
    val, g = (float(v) for v in vg(jnp.asarray(math.radians(beta))))
    hist = [(beta, val, g)]
    step = 10.0  # deg per unit of (normalized) gradient sign
    for _ in range(max_iter):
        if not (math.isfinite(val) and math.isfinite(g)) or step < 0.05:
            break
        improved = False
        while step >= 0.05:
            cand = float(np.clip(beta + step * np.sign(g), lo, hi))
            if cand == beta:
                break
            cv, cg = (float(v) for v in vg(jnp.asarray(math.radians(cand))))
            if math.isfinite(cv) and cv > val:
                beta, val, g = cand, cv, cg
                hist.append((beta, val, g))
                improved = True
                step *= 1.5
                break
            step *= 0.5
        if not improved:
            break
    return beta, val, hist


def program_waypoints(psi0_deg, gap, beta_deg, *, s0=0.02, n=40, margin_deg=3.0, settings=Continuation()):
    """The waypoints of the program (module docstring): the smallest moves that cross each
    critical angle by `margin_deg`. Returns (waypoints, info) with info the critical angles
    (deg) and whether their extended-system refinement converged; waypoints is None where
    the down state at (beta, beta) is not found or a path does not snap."""
    base = jr.make_scene(psi0_deg, gap, beta_deg, s0=s0, n=n)
    eq0 = jr.initial_state(base, "down")
    info = {"down_state_found": bool(eq0.result == RESULTS.successful)}
    if not info["down_state_found"]:
        return None, info
    crit = {}
    for nm, par in (("L", LeftAlpha()), ("R", RightAlpha())):
        r = jax.tree.map(np.asarray, _one_sided(base, eq0.theta, eq0.force, 1.0, par, settings))
        crit[nm] = math.degrees(float(r["alpha_c"])) if r["snaps"] else float("nan")
        info[f"alpha_c_{nm}_deg"] = crit[nm]
        info[f"alpha_c_{nm}_refined"] = bool(r["refined"])
    sym = jr.snap_angles(jr.make_scene(psi0_deg, gap, 0.0, s0=s0, n=n), settings=settings)
    crit["S"] = math.degrees(float(sym.up.alpha_c)) if bool(sym.up.snaps) else float("nan")
    info["alpha_c_sym_deg"] = crit["S"]
    info["alpha_c_sym_kind"] = KIND_NAMES[int(sym.up.kind)]
    if not all(math.isfinite(v) for v in crit.values()) or crit["S"] <= beta_deg:
        return None, info
    w0 = (beta_deg, beta_deg)
    wl = (crit["L"] + margin_deg, beta_deg)
    wr = (beta_deg, crit["R"] + margin_deg)
    ws = (crit["S"] + margin_deg, crit["S"] + margin_deg)
    return [w0, wl, w0, wr, w0, ws, w0], info
