r"""Study (d): a programmable actuator (the paper's Fig. 4), quasi-static and dynamic.

**Per-half observable.** For a strip with one central crease the *state of a half* is the
sign of its quarter-point height: $h_L=y(L/4)$ (left half, node $N/4$) and $h_R=y(3L/4)$
(right half, node $3N/4$), heights above the line through the clamps (docs/model.md: $y>0$ up).
A state is labelled by two letters, left half first: ``"DD"`` (the down state, both halves
below), ``"UU"`` (the up state), ``"UD"`` (left half up, right half down), ``"DU"``.
A half *snaps* in a move when its letter changes across a loss of stability (a jump of the
quasi-static path, landing in a different stable state); a letter that changes while the
path is still continuous is a *drift*, not a snap, and disqualifies the move.

**What the statics show (N = 40..80, $s_0=0.02$).** Rotating one clamp alone with the
other held at $\alpha=0$ (the protocol of `jr.snap_dynamics(kind="asymmetric")`) the down
state loses stability at a fold ($\alpha_L\approx46.4^\circ$ for $\Psi_0=60^\circ$, $G/L=0.5$)
and lands in the *up state*: both letters flip (``DD -> UU``), and the half far from the
moving clamp is the one that moves most (tangent-angle change $L^2$ 1.48 vs 1.24 rad at
N = 40; cf. the paper: rotating the left clamp propels the right-most ball). A
left-half-only snap therefore needs the held clamp tilted down: with $\alpha_R=\beta\lesssim
-90^\circ$ (and a tight enough fold; the default design $\Psi_0=45^\circ$, $G/L=0.5$ has its
optimum at $\beta=-126.26^\circ$) the fold of the one-sided path lands in a mixed ``UD`` state
whose right quarter stays below the clamp line. `actuator_study` builds such a program and
reports "not reached" with the first step that does not do what it says (e.g. step 1 at
$\beta=0$, which lands in ``UU``).

The up-state branch is continuous in $\alpha_R$: raising the right clamp from
``UD`` lifts the right half *without* a snap (``UD -> UU`` continuously), so a
"then the right half" step cannot start from ``UD``. The program therefore returns to the
down state between actuations (the paper's experiment also consists of three separate
snaps, each propelling one ball).

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
import functools
import math
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

import jaxrod as jr
from jaxrod.branches import AbstractParameter, Continuation, LeftAlpha
from jaxrod.branches import critical_point
from jaxrod.energy.lagrangian import positions
from jaxrod.statics import initial_state_signed
from jaxrod.linalg.kkt import modes, smallest_eigenvalues, structured
from jaxrod.branches import follow_path
from jaxrod.results import RESULTS
from jaxrod.statics import Equilibrium


# ----- per-half observable --------------------------------------------------------------

def _check_n(n):
    if n % 4:
        raise ValueError(f"n: the per-half observable needs n divisible by 4 (quarter-point nodes), got {n}")


def half_heights(theta, force, scene):
    """(y(L/4), y(L/2), y(3L/4)): left quarter, fold, right quarter heights."""
    n = scene.mesh.n
    return positions(theta, force, scene)[jnp.array([n // 4, n // 2, 3 * n // 4]), 1]


def half_state(h) -> str:
    """Two letters from `half_heights`: left half then right half, U (above) or D; "?" for a
    height that is not finite (no state: a landing that found no stable equilibrium)."""
    h = np.asarray(h)
    return "".join("U" if x > 0 else "D" if x <= 0 else "?" for x in (h[0], h[2]))


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
    p = follow_path(sc0, eq, 1.0, par, settings, length + OVERSHOOT, 48, 1e-9, stages=2)
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
    return dict(snaps=snaps, t_c=t_c, a_c=a_c, a_land=a_land, landed=p.result != RESULTS.landing_failed,
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
    `a_from_deg`; after each snap continue from the landing state (a snap whose landing finds
    no stable state, `landing_failed`, ends the move there: final letters "??", not stable)."""
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
            if not bool(r["landed"]):
                # no stable state past the snap (`landing_failed`): the move ends there, unknown
                return MoveReport(tuple(np.asarray(a_from_deg, float)), tuple(np.asarray(a_to_deg, float)), start,
                                  events, drift, sa, tuple(ha), False, r["theta_after"], r["force_after"])
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
    p = follow_path(sc, eq, direction, parameter, settings, jnp.pi, 48, 1e-9, stages=1)
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
    the program held at beta, W1 placed `margin_deg` past the refined one-sided critical
    angle; differentiable (implicit gradients of alpha_c and of the equilibrium at W1) where
    the one-sided path snaps."""
    base = jr.make_scene(psi0_deg, gap, 0.0, s0=s0, n=n)
    dm = math.radians(margin_deg)

    def f(beta):
        sc = _at(base, jnp.stack([beta, beta]))
        eq0 = initial_state_signed(lax.stop_gradient(sc), -1.0)
        r = _one_sided(sc, eq0.theta, eq0.force, 1.0, LeftAlpha(), settings)
        sc1 = _at(base, jnp.stack([r["alpha_c"] + dm, beta]))
        eq1 = jr.solve_equilibrium(sc1, r["theta_after"], r["force_after"])
        h = half_heights(eq1.theta, eq1.force, sc1)
        return jnp.minimum(h[0], -h[2]), dict(alpha_c=r["alpha_c"], snaps=r["snaps"], refined=r["refined"],
                                              h=h, ok=eq1.result == RESULTS.successful, start_ok=eq0.result)

    return f


@functools.lru_cache(maxsize=8)
def _margin_tools(psi0_deg, gap, s0, n, margin_deg, settings):
    """Jitted (values, jacobian) of beta -> (alpha_c^L, h_L(W1), h_R(W1), snapped), memoized
    so that the optimizer and the gradient check share one compilation of each."""
    f = _ud_margin_fn(psi0_deg, gap, s0, n, margin_deg, settings)

    def vec(x):
        _, aux = f(x)
        return jnp.stack([aux["alpha_c"], aux["h"][0], aux["h"][2]])

    def prim(x):
        _, aux = f(x)
        return vec(x), aux["snaps"]

    return eqx.filter_jit(prim), eqx.filter_jit(jax.jacfwd(vec))


@dataclasses.dataclass
class GradientCheck:
    """d(quantity)/d(beta) by implicit differentiation vs a central difference (step `h` rad);
    `value` the quantity at beta (alpha_c1 in rad)."""

    name: str
    beta_deg: float
    grad: float
    fd: float
    h: float
    value: float = float("nan")

    @property
    def rel_error(self):
        return abs(self.grad - self.fd) / max(abs(self.fd), 1e-12)


def gradient_checks(psi0_deg, gap, beta_deg, *, s0=0.02, n=40, margin_deg=3.0, h=1e-4,
                    settings=Continuation()):
    """Implicit gradients w.r.t. the held angle beta (forward mode) of what the optimization
    uses: alpha_c^L (the refined one-sided critical angle) and the half heights h_L, h_R of
    the state at W1 (m1 = min(h_L, -h_R) itself has a kink at the optimum, where h_L = -h_R),
    each against a central difference of the full pipeline (bisection, refinement, landing,
    equilibrium at W1)."""
    prim, jac = _margin_tools(float(psi0_deg), float(gap), float(s0), int(n), float(margin_deg), settings)
    b = jnp.asarray(math.radians(beta_deg))
    gr = np.asarray(jac(b))
    val = np.asarray(prim(b)[0])
    fd = (np.asarray(prim(b + h)[0]) - np.asarray(prim(b - h)[0])) / (2 * h)
    names = ("alpha_c1", "h_L(W1)", "h_R(W1)")
    return [GradientCheck(nm, beta_deg, float(gr[i]), float(fd[i]), h, float(val[i])) for i, nm in enumerate(names)]


def optimize_hold(psi0_deg, gap, beta0_deg, *, bounds_deg=(-150.0, -60.0), s0=0.02, n=40, margin_deg=3.0,
                  max_iter=8, tol_deg=1e-6, settings=Continuation()):
    r"""Maximize $m_1(\beta)=\min(h_L,-h_R)$ (the landing margin of ``UD`` at $W_1$) over the
    held angle $\beta$. Where both terms are smooth the maximum of the min is where they are
    equal, $d(\beta)=h_L+h_R=0$ (in the explored designs $h_L$ falls and $-h_R$ rises as $\beta$
    decreases): safeguarded Newton on $d$ with its implicit derivative (clipped to the bounds).
    Returns (beta_deg, m1, history [(beta_deg, m1, d, dd/dbeta per rad)], local) with `local`
    True if m1 at the result is at least m1 at beta +- 1 deg (checked by evaluation)."""
    prim, jac = _margin_tools(float(psi0_deg), float(gap), float(s0), int(n), float(margin_deg), settings)

    def m1_of(x):
        v, snaps = prim(jnp.asarray(x))
        v = np.asarray(v)
        return (float(min(v[1], -v[2])) if bool(snaps) else float("nan")), v

    lo, hi = (math.radians(v) for v in bounds_deg)
    beta = float(np.clip(math.radians(beta0_deg), lo, hi))
    hist = []
    for _ in range(max_iter):
        m1, v = m1_of(beta)
        J = np.asarray(jac(jnp.asarray(beta)))
        dv, g = float(v[1] + v[2]), float(J[1] + J[2])
        hist.append((math.degrees(beta), m1, dv, g))
        if not (math.isfinite(m1) and math.isfinite(dv) and math.isfinite(g)) or g == 0.0:
            break
        new = float(np.clip(beta - dv / g, lo, hi))
        if abs(new - beta) < math.radians(tol_deg):
            beta = new
            break
        beta = new
    m_best = m1_of(beta)[0]
    side = [m1_of(beta + sg * math.radians(1.0))[0] for sg in (-1.0, 1.0)]
    local = bool(math.isfinite(m_best) and all(not math.isfinite(x) or m_best >= x for x in side))
    return math.degrees(beta), m_best, hist, local


def critical_angle_along(scene, theta, force, a_from_deg, a_far_deg, *, settings=MOVE_SETTINGS):
    """The first loss of stability of the branch through (theta, force) at `a_from_deg` on the
    straight move toward `a_far_deg` (deg): (alpha_L, alpha_R) at the critical point in deg
    (bisection on the arclength to ~2^-48 of a step: exact to round-off at this mesh), the
    half heights just before and after (landing), or None if the move does not snap."""
    a0 = jnp.deg2rad(jnp.asarray(a_from_deg, float))
    a1 = jnp.deg2rad(jnp.asarray(a_far_deg, float))
    r = jax.tree.map(np.asarray, _segment(scene, theta, force, a0, a1, settings))
    if not bool(r["snaps"]):
        return None
    return tuple(np.degrees(r["a_c"])), r["h_before"], r["h_after"]


FAR_DEG = 170.0  # how far the critical-angle searches turn a clamp


def program_waypoints(psi0_deg, gap, beta_deg, *, s0=0.02, n=40, margin_deg=3.0, settings=MOVE_SETTINGS):
    """The waypoints of the program (module docstring): the smallest moves that cross each
    critical angle by `margin_deg`. The three critical angles (left clamp alone, right clamp
    alone, both) of the down state at (beta, beta) are found on straight moves toward
    `FAR_DEG`. Returns (waypoints, info) with info the critical angles (deg); waypoints is
    None where the down state at (beta, beta) is not found or one of the paths does not snap."""
    base = jr.make_scene(psi0_deg, gap, beta_deg, s0=s0, n=n)
    eq0 = jr.initial_state(base, "down")
    info = {"down_state_found": bool(eq0.result == RESULTS.successful)}
    if not info["down_state_found"]:
        return None, info
    w0 = (float(beta_deg), float(beta_deg))
    far = {"L": (FAR_DEG, beta_deg), "R": (beta_deg, FAR_DEG), "sym": (FAR_DEG, FAR_DEG)}
    crit = {}
    for nm, a_far in far.items():
        c = critical_angle_along(base, eq0.theta, eq0.force, w0, a_far, settings=settings)
        crit[nm] = float("nan") if c is None else (c[0][0] if nm != "R" else c[0][1])
        info[f"alpha_c_{nm}_deg"] = crit[nm]
    if not all(math.isfinite(v) for v in crit.values()):
        return None, info
    wl = (crit["L"] + margin_deg, float(beta_deg))
    wr = (float(beta_deg), crit["R"] + margin_deg)
    ws = (crit["sym"] + margin_deg, crit["sym"] + margin_deg)
    return [w0, wl, w0, wr, w0, ws, w0], info


# ----- dynamic verification -------------------------------------------------------------

@dataclasses.dataclass
class DynamicMove:
    """One move run with `jr.simulate`: clamps ramped at `rate` (rad/T) from waypoint to
    waypoint, then held for `settle` T, with viscous damping. `t` frame times, `h` (frames, 3)
    half heights; `start`/`final` letters; `flips` the halves whose letter changed at any
    frame (a half that "stayed put" never changes letter); `kinetic_end` the kinetic energy
    at the end (settled if small); `distance_to_static` the L2 distance of the final angle
    field to the quasi-static end state of the move (rad)."""

    a_from: tuple
    a_to: tuple
    t: np.ndarray
    h: np.ndarray
    start: str
    final: str
    flips: frozenset
    kinetic_end: float
    distance_to_static: float
    v_peak: float
    theta: np.ndarray
    positions: np.ndarray
    result: str


def dynamic_ok(dm: DynamicMove, step: int, tol_distance=0.05, tol_kinetic=1e-4) -> bool:
    """The dynamic move lands in the intended state, settled and on the quasi-static end state;
    an actuation step flips exactly its halves (the other half keeps its letter at every frame)."""
    s0, s1, halves = INTENDED[step]
    ok = (dm.start == s0 and dm.final == s1 and dm.kinetic_end < tol_kinetic
          and dm.distance_to_static < tol_distance and dm.result == "successful")
    return ok and (halves is None or dm.flips == halves)


def simulate_program(scene, waypoints_deg, *, rate=1.0, settle=6.0, damping=3.0, n_frames=96, tol=1e-7,
                     max_steps=400_000, static_moves=None):
    """Run the program dynamically (`jr.simulate`, Tsit5 at rtol = atol = `tol`, passed
    explicitly), each move
    from rest in the state the previous one settled in. `static_moves`: the quasi-static
    reports of the same program at the same mesh, for `distance_to_static`."""
    _check_n(scene.mesh.n)
    n = scene.mesh.n
    sc = _at(scene, jnp.deg2rad(jnp.asarray(waypoints_deg[0], float)))
    theta = jr.initial_state(sc, "down").theta
    d = jr.discretize(scene)
    w = np.asarray(d.h)
    out = []
    for k, (a, b) in enumerate(zip(waypoints_deg[:-1], waypoints_deg[1:])):
        a0, a1 = np.radians(np.asarray(a, float)), np.radians(np.asarray(b, float))
        T = float(np.max(np.abs(a1 - a0))) / rate
        rl, rr = (a1 - a0) / T
        proto = jr.Protocol(a0[0], a0[1], rl, rr, T)
        t1 = T + settle
        tr = jr.simulate(_at(scene, jnp.asarray(a0)), theta, proto, t1=jnp.asarray(t1), stop_at_snap=False,
                         dissipation=jr.Dissipation(damping=damping), rtol=jnp.asarray(tol),
                         atol=jnp.asarray(tol), n_frames=n_frames, n_fine=2048, solver="tsit5",
                         max_steps=max_steps)
        x = np.asarray(tr.positions)
        h = x[:, [n // 4, n // 2, 3 * n // 4], 1]
        letters = [half_state(hh) for hh in h]
        flips = frozenset().union(*(flipped(letters[0], s) for s in letters))
        theta = jnp.asarray(np.asarray(tr.theta)[-1])
        kin = np.asarray(tr.kinetic)
        kin_end = float(kin[np.isfinite(kin)][-1]) if np.isfinite(kin).any() else float("nan")
        dist = float("nan")
        if static_moves is not None:
            dist = float(np.sqrt(np.sum(w * (np.asarray(theta) - static_moves[k].theta) ** 2)))
        out.append(DynamicMove(tuple(a), tuple(b), np.asarray(tr.t_frames), h, letters[0], letters[-1], flips,
                               kin_end, dist, float(tr.v_s), np.asarray(tr.theta), x,
                               "successful" if bool(tr.result == jr.RESULTS.successful) else str(tr.result)))
    return out


# ----- the study ------------------------------------------------------------------------

@dataclasses.dataclass
class ActuatorResult:
    """Study (d). `waypoints` (deg; None where no program exists), `info` the critical angles,
    `moves` the quasi-static program at `n`, `check` the same waypoints re-solved independently
    at `n_check`, `dynamics` the dynamic run at `n_dyn` (or None), `gradients` the gradient
    checks, `history` the optimization of the held angle, `timings` (s). `outcome`:
    "reached" or "not reached: <first failing step and why>"."""

    psi0_deg: float
    gap: float
    s0: float
    beta_deg: float
    margin_deg: float
    n: int
    n_check: int
    waypoints: list | None
    info: dict
    moves: list
    check: list
    dynamics: list | None
    gradients: list
    history: list
    timings: dict
    outcome: str

    @property
    def reached(self) -> bool:
        return self.outcome == "reached"

    def summary(self) -> str:
        lines = [f"design Psi0 = {self.psi0_deg:g} deg, G/L = {self.gap:g}, s0 = {self.s0:g}, "
                 f"held angle beta = {self.beta_deg:.3f} deg, margin {self.margin_deg:g} deg",
                 "critical angles: " + ", ".join(f"{k} = {v:.4f}" if isinstance(v, float) else f"{k} = {v}"
                                                 for k, v in self.info.items())]
        if self.waypoints is not None:
            lines.append("waypoints (alpha_L, alpha_R) deg: " + " -> ".join(f"({a:.3f}, {b:.3f})"
                                                                         for a, b in self.waypoints))
        for tag, reps in (("N = %d" % self.n, self.moves), ("check N = %d" % self.n_check, self.check)):
            for k, r in enumerate(reps):
                ev = "; ".join(f"snap at ({e.alpha_deg[0]:.3f}, {e.alpha_deg[1]:.3f}) {e.before}->{e.after}"
                               for e in r.events) or "no snap"
                lines.append(f"[{tag}] step {k + 1} {STEP_NAMES[k]}: {r.start} -> {r.final} ({ev}); "
                             f"h = ({r.h_final[0]:+.4f}, {r.h_final[1]:+.4f}, {r.h_final[2]:+.4f}); "
                             f"{'ok' if move_ok(r, k) else 'FAILED'}")
        for k, dmv in enumerate(self.dynamics or []):
            lines.append(f"[dynamics] step {k + 1} {STEP_NAMES[k]}: {dmv.start} -> {dmv.final}, flipped "
                         f"{''.join(sorted(dmv.flips)) or '-'}, v_peak = {dmv.v_peak:.2f}, E_k(end) = "
                         f"{dmv.kinetic_end:.1e}, |theta - static| = {dmv.distance_to_static:.1e}; "
                         f"{'ok' if dynamic_ok(dmv, k) else 'FAILED'}")
        for g in self.gradients:
            lines.append(f"gradient d{g.name}/dbeta at beta = {g.beta_deg:.3f}: implicit {g.grad:.6e}, "
                         f"central difference {g.fd:.6e}, rel. error {g.rel_error:.1e}")
        lines.append("outcome: " + self.outcome)
        return "\n".join(lines)


def _first_failure(reps, ok_fn, tag):
    for k, r in enumerate(reps):
        if not ok_fn(r, k):
            s0, s1, _ = INTENDED[k]
            got = f"{r.start} -> {r.final}"
            return f"not reached: {tag} step {k + 1} ({STEP_NAMES[k]}, intended {s0} -> {s1}) gave {got}"
    return None


def actuator_study(psi0_deg=45.0, gap=0.5, beta_deg=-120.0, *, optimize=True, beta_bounds=(-150.0, -60.0),
                   s0=0.02, n=40, n_check=80, n_dyn=32, margin_deg=3.0, max_iter=6, dynamics=True,
                   check_gradients=True, progress=False) -> ActuatorResult:
    """Study (d): a clamp-angle program that snaps the left half only, the right half only,
    then both (module docstring for the definitions and the program).

    With `optimize` the held angle beta (start `beta_deg`, within `beta_bounds`) maximizes
    the landing margin m1 on `n` segments; the waypoints are the smallest moves past each
    critical angle by `margin_deg`. The program is then run quasi-statically at `n`,
    independently re-solved at `n_check`, and (with `dynamics`) integrated with
    `jr.simulate` at `n_dyn`, each stage only if the previous one did what it says.
    `outcome` says "not reached: ..." with the first failing step (and the mesh or the
    dynamics where it failed)."""
    for nm, v in (("n", n), ("n_check", n_check), ("n_dyn", n_dyn)):
        _check_n(v)
    timings, hist, grads, info_opt = {}, [], [], {}
    say = print if progress else (lambda *a, **k: None)
    t0 = time.perf_counter()
    beta = float(beta_deg)
    if optimize:
        beta, m1, hist, local = optimize_hold(psi0_deg, gap, beta, bounds_deg=beta_bounds, s0=s0, n=n,
                                              margin_deg=margin_deg, max_iter=max_iter)
        info_opt = {"m1": m1, "local_max": local}
        timings["optimize"] = time.perf_counter() - t0
        say(f"held angle beta = {beta:.3f} deg, margin m1 = {m1:.4f} ({len(hist)} evaluations accepted)")
    if check_gradients:
        t1 = time.perf_counter()
        grads = gradient_checks(psi0_deg, gap, beta, s0=s0, n=n, margin_deg=margin_deg)
        timings["gradients"] = time.perf_counter() - t1
    t1 = time.perf_counter()
    wp, info = program_waypoints(psi0_deg, gap, beta, s0=s0, n=n, margin_deg=margin_deg)
    timings["waypoints"] = time.perf_counter() - t1
    info.update(info_opt)
    res = ActuatorResult(psi0_deg, gap, s0, beta, margin_deg, n, n_check, wp, info, [], [], None, grads, hist,
                         timings, "")
    if wp is None:
        res.outcome = ("not reached: no down state at (beta, beta)" if not info.get("down_state_found", True)
                       else "not reached: a critical angle of the program does not exist (a path does not snap)")
        return res
    fail = None
    for nn, attr in ((n, "moves"), (n_check, "check")):
        t1 = time.perf_counter()
        _, reps = run_program(jr.make_scene(psi0_deg, gap, 0.0, s0=s0, n=nn), wp)
        setattr(res, attr, reps)
        timings[attr] = time.perf_counter() - t1
        say(f"quasi-static program at N = {nn}: " + ", ".join(f"{r.start}->{r.final}" for r in reps))
        fail = _first_failure(reps, move_ok, f"N = {nn}")
        if fail is not None:  # the finer check (and the dynamics) of a failed program are not run
            break
    if dynamics and fail is None:
        t1 = time.perf_counter()
        scd = jr.make_scene(psi0_deg, gap, 0.0, s0=s0, n=n_dyn)
        _, st = run_program(scd, wp)
        res.dynamics = simulate_program(scd, wp, static_moves=st)
        timings["dynamics"] = time.perf_counter() - t1
        fail = _first_failure(res.dynamics, dynamic_ok, f"dynamics N = {n_dyn}")
    res.outcome = fail or "reached"
    timings["total"] = time.perf_counter() - t0
    return res
