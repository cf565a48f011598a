r"""The design studies (a)-(c), each a function returning a result with an independent check,
built on `jaxrod.design`'s objectives, parametrizations and `optimize`.

(a) `snap_angle_study`: $(\Psi_0, G/L)$ such that $\alpha_{c,\rm up}$ and $\alpha_{c,\rm down}$ hit
    targets (default 60 and -70 deg), $s_0 = 0.02$. Multi-start Levenberg-Marquardt on a coarse
    mesh, the best design refined on the design mesh, then re-checked by an independent
    forward solve (`jaxrod.snap_angles`, no gradients) on a finer mesh.
(b) `fastest_snap_study`: maximize the snapping speed $v_s/v^\*$ over $(\Psi_0, G/L)$ subject
    to $G/L\ge$ `min_gap` (default 0.3; the feasible parametrization keeps every iterate
    inside), $s_0 = 0.02$.
(c) `snap_speed_study`: the gap (and $s_0$ if freed) with $v_s = $ `target_speed` (default
    $20 v^\*$) at $\Psi_0 = $ `psi0_deg` (default 90 deg).
    Both use [`jaxrod.snap_speed`][] (the brink snap, fixed-step dynamics, differentiable)
    on the design mesh `n`, Levenberg-Marquardt from each start in turn (one compiled
    problem; starts are not `vmap`-ed: batched LAPACK kernels inside the solvers' while
    loops can deadlock XLA:CPU), then re-check the design by an independent forward solve
    (`verify_snap_speed`: `jaxrod.snap_dynamics`, the brink scene of `jaxrod.brink` with its
    own nudge, adaptive Dopri8 at tight tolerance, on the finer mesh `n_check`).
(d) `actuator_study` (left half, right half, both: the paper's Fig. 4) is in
    `jaxrod/paper/_actuator.py`.
"""

from __future__ import annotations

import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import jaxrod as jr
from jaxrod.design import (AlphaDown, AlphaUp, DesignResult, MultiStartResult, Parametrization, Problem, SnapSpeed,
                           design_scene, dynamics_available, linearize, optimize)


@dataclasses.dataclass
class Verification:
    """An independent forward check of a design at a finer mesh `n`."""

    n: int
    alpha_up_deg: float
    alpha_down_deg: float
    errors_deg: tuple
    reached: bool


def verify_snap_angles(result: DesignResult, n: int, tol: float = 0.1) -> Verification:
    """Re-solve the design's snap angles with `jaxrod.snap_angles` at `n` segments and
    compare with its targets (alpha_c_up / alpha_c_down terms, in degrees)."""
    sc = design_scene(jnp.deg2rad(result.psi0_deg), result.gap, result.s0, n)
    r = jr.snap_angles(sc)
    got = {"alpha_c_up": math.degrees(float(r.up.alpha_c)), "alpha_c_down": math.degrees(float(r.down.alpha_c))}
    errs = tuple(abs(got[nm] - float(t)) for nm, t in zip(result.names, np.asarray(result.targets)) if nm in got)
    return Verification(n, got["alpha_c_up"], got["alpha_c_down"], errs,
                        bool(all(e <= tol for e in errs) and all(math.isfinite(e) for e in errs)))


@dataclasses.dataclass
class StudyResult:
    coarse: MultiStartResult
    design: DesignResult
    verification: Verification

    @property
    def reached(self):
        return bool(self.design.reached) and self.verification.reached


def snap_angle_study(alpha_up_deg=60.0, alpha_down_deg=-70.0, *, bounds=None, s0=0.02, starts=4, n_coarse=40,
                     n=160, n_check=320, tol=0.1, max_iter=30, seed=0, progress=True, optimizer="lm") -> StudyResult:
    """Study (a): find (Psi0, G/L) with the given critical angles (degrees).

    `starts` random starts (uniform in the bounds; default bounds Psi0 in (10, 180) deg,
    G/L in (0.05, 0.95); pass e.g. `bounds={"gap": (0.3, 0.95)}`) run on `n_coarse`
    segments; the best is refined on `n` segments (discretization error of alpha_c
    ~ 1000 deg / N^2, so n = 160 is within ~0.04 deg of converged) and checked at `n_check`.
    `optimizer`: "lm" or an optax transformation (`optimize`; benchmarks/results/optimizers.md
    compares them)."""
    param = Parametrization(free=("psi0_deg", "gap"), bounds=bounds, fixed={"s0": s0})
    z0 = jnp.concatenate([param.from_values(psi0_deg=60.0, gap=0.5)[None],
                          param.sample(jax.random.PRNGKey(seed), max(starts - 1, 0))])
    terms_c = (AlphaUp(alpha_up_deg, tol=tol), AlphaDown(alpha_down_deg, tol=tol))
    coarse = optimize(terms_c, param, z0, n=n_coarse, max_iter=max_iter, progress=progress, optimizer=optimizer)
    fine = optimize(terms_c, param, coarse.best.z, n=n, max_iter=max_iter, progress=progress, optimizer=optimizer,
                    meta={"study": "a", "coarse_n": n_coarse})
    return StudyResult(coarse, fine.best, verify_snap_angles(fine.best, n_check, tol))


def _needs_dynamics(what):
    if not dynamics_available():
        raise NotImplementedError(f"{what} needs a differentiable snap speed from jaxrod's dynamics "
                                  "(jaxrod.snap_speed), which this jaxrod does not provide")


@dataclasses.dataclass
class SpeedVerification:
    """An independent forward check of a design's snapping speed: `v_s` of
    `jaxrod.snap_dynamics` (brink, `solver` adaptive at `rtol` = atol) on `n` segments,
    compared with `reference` (the target for study (c), the design-mesh value for (b));
    `error` = |v_s - reference| / |reference|; `reached` = error <= `tol` and it snapped."""

    n: int
    v_s: float
    reference: float
    error: float
    tol: float
    reached: bool
    solver: str
    rtol: float
    num_steps: int
    wall_time: float

    def to_dict(self):
        return {k: (v if not isinstance(v, float) or math.isfinite(v) else None)
                for k, v in dataclasses.asdict(self).items()}


def verify_snap_speed(psi0_deg, gap, s0, n, reference, *, tol=0.01, direction="up", solver="dopri8",
                      rtol=1e-9, t1=3.0) -> SpeedVerification:
    """Re-solve the snap of design (psi0_deg, gap, s0) by `jaxrod.snap_dynamics` (brink
    scene, its default nudge, adaptive `solver` at rtol = atol = `rtol`) on `n` segments and
    compare its v_s with `reference` (relative `tol`). No gradients, no fixed step."""
    import time

    t0 = time.perf_counter()
    sc = design_scene(math.radians(psi0_deg), gap, s0, n)
    try:
        _, tr = jr.snap_dynamics(sc, direction, solver=solver, rtol=rtol, atol=rtol, t1=t1, max_steps=1_000_000)
        solved = bool(tr.result == jr.RESULTS.successful)
        v, ok, steps = float(tr.v_s), bool(tr.snapped) and solved, int(tr.num_steps)
    except ValueError:  # the path does not snap: no brink
        v, ok, steps = math.nan, False, 0
    err = abs(v - reference) / abs(reference) if math.isfinite(v) and reference else math.nan
    return SpeedVerification(n, v, float(reference), err, tol, bool(ok and err <= tol), solver, rtol, steps,
                             time.perf_counter() - t0)


@dataclasses.dataclass
class SpeedStudyResult:
    """Result of study (b) or (c): `design` (the best [`DesignResult`][] on the design mesh;
    its `achieved[0]` is v_s / v*), `verification` (a [`SpeedVerification`][] on the finer
    mesh), `runs` (one [`MultiStartResult`][] per start), `study` ("b" or "c"), `v_s`
    (the design's speed on the design mesh), `v_s_start` ((b): at the best start),
    `start_miss` ((c): |v_s - target| at the best start), `min_gap` ((b) only), `wall_time`
    (s, optimization and check)."""

    study: str
    design: DesignResult
    verification: SpeedVerification
    runs: tuple
    v_s: float
    v_s_start: float
    wall_time: float
    min_gap: float | None = None
    start_miss: float | None = None
    polish: dict | None = None

    @property
    def reached(self):
        """(c): the target is met on the design mesh and by the independent check.
        (b): the speed improved on the start, the bound holds and the check agrees."""
        if self.study == "c":
            return bool(self.design.reached) and self.verification.reached
        return self.improved and self.bound_respected and self.verification.reached

    @property
    def improved(self):
        return bool(math.isfinite(self.v_s) and self.v_s > self.v_s_start)

    @property
    def bound_respected(self):
        return self.min_gap is None or self.design.gap >= self.min_gap

    @property
    def at_bound(self):
        """(b): the optimum is at the gap bound (within 1e-3 L)."""
        return self.min_gap is not None and self.design.gap - self.min_gap < 1e-3

    @property
    def message(self):
        v = self.verification
        chk = (f"check at N = {v.n}: v_s = {v.v_s:.4f} v* ({v.solver} {v.rtol:g}), "
               f"{'within' if v.reached else 'NOT within'} {100 * v.tol:g} % of {v.reference:.4f}")
        if self.study == "c":
            head = "target reached" if self.reached else (
                "target not reached: " + (self.design.message if not bool(self.design.reached)
                                         else "the finer-mesh check disagrees"))
            return f"{head}; {chk}"
        head = (f"fastest snap found: v_s = {self.v_s:.4f} v* (start {self.v_s_start:.4f}), "
                f"G/L = {self.design.gap:.5f} (bound {self.min_gap:g}{', active' if self.at_bound else ''}), "
                f"Psi0 = {self.design.psi0_deg:.3f} deg, stopped: {self.design.status}")
        if self.polish:
            pl = self.polish
            head += (f", Psi0 polished {pl['psi0_before']:.3f} -> {pl['psi0_after']:.3f} deg "
                     f"(v_s {pl['v_s_before']:.4f} -> {pl['v_s_after']:.4f}, {pl['evaluations']} evaluations)")
        if not self.improved:
            head = "no improvement on the start: " + head
        return f"{head}; {chk}"

    def to_dict(self):
        d = self.design.to_dict()
        d.update({"study": self.study, "v_s": self.v_s, "v_s_start": self.v_s_start, "reached": self.reached,
                  "design_reached": bool(self.design.reached), "message": self.message,
                  "verification": self.verification.to_dict(), "wall_time_s": self.wall_time,
                  "num_starts": len(self.runs), "start_miss": self.start_miss})
        if self.study == "b":
            d.update({"min_gap": self.min_gap, "improved": self.improved, "at_bound": self.at_bound,
                      "bound_respected": self.bound_respected, "polish": self.polish})
            for k in ("snap_speed", "target_snap_speed"):
                d.pop(k, None)
        return d


def _run_starts(terms, param, starts, n, max_iter, progress, meta, optimizer="lm"):
    """`optimize` from each start in turn (B = 1 each: one compiled problem, no vmap over
    the dynamics). Returns (best MultiStartResult, all)."""
    runs = []
    for vals in starts:
        z0 = param.from_values(**vals)
        runs.append(optimize(terms, param, z0, n=n, max_iter=max_iter, progress=progress, meta=meta,
                             optimizer=optimizer))

    def key(r):
        loss = float(r.best.loss)
        return (not bool(r.best.reached), loss if math.isfinite(loss) else math.inf)

    return min(runs, key=key), tuple(runs)


def _speed_of(run):
    """v_s of the best start's final design (design mesh)."""
    return float(np.asarray(run.best.achieved)[0])


def snap_speed_study(target_speed=20.0, psi0_deg=90.0, *, s0=0.02, free_s0=False, bounds=None, gaps=(0.5,),
                     n=48, n_check=96, tol=0.01, max_iter=20, check_rtol=1e-9, progress=True, optimizer="lm",
                     **speed_options) -> SpeedStudyResult:
    """Study (c): the gap G/L (and s0 with `free_s0`) at which the snap up of a strip with
    fold angle `psi0_deg` has v_s = `target_speed` v* (relative tolerance `tol`, 1 %).

    Levenberg-Marquardt (or the optax transformation `optimizer`) from each start gap in
    `gaps` on the design mesh `n` (default
    bounds G/L in (0.05, 0.95), s0 in (0.005, 0.1)), stopping at 0.1 `tol`; the best design
    is re-checked on `n_check` segments by `verify_snap_speed`. A target no design in the
    bounds reaches ends with the closest design found and `reached = False` ("target not
    reached")."""
    _needs_dynamics("snap_speed_study")
    import time

    t0 = time.perf_counter()
    free = ("gap",) + (("s0",) if free_s0 else ())
    param = Parametrization(free=free, bounds=bounds, fixed={"psi0_deg": psi0_deg, "s0": s0})
    term = SnapSpeed(target_speed, tol=tol * abs(target_speed), **speed_options)
    starts = [{"gap": float(g), "s0": s0} for g in gaps]
    best, runs = _run_starts((term,), param, starts, n, max_iter, progress, {"study": "c"}, optimizer)
    d = best.best
    v = _speed_of(best)
    chk = verify_snap_speed(d.psi0_deg, d.gap, d.s0, n_check, target_speed, tol=tol, rtol=check_rtol)
    # the start's |v_s - target| from its loss (0.5 r^2, r = (v_s - target) / tol); its sign is not kept
    miss0 = term.tol * math.sqrt(2.0 * float(d.history_loss[0]))
    return SpeedStudyResult("c", d, chk, runs, v, math.nan, time.perf_counter() - t0, start_miss=miss0)


def golden_max(f, lo, hi, *, xtol=0.02, x0=None, f0=None):
    r"""Maximize a unimodal $f$ on $[lo, hi]$ by golden-section search (no derivatives:
    `snap_speed`'s local slopes carry the small-scale wiggle of the discrete map; its values
    wiggle by ~2e-4 relative on a 0.25-deg scale, results/study_b_grid.md, small against the
    curvature of v_s over the bracket). The bracket
    shrinks by $0.618$ per evaluation until it is below `xtol`; `x0, f0`: a point already
    evaluated (kept if nothing better is found). Non-finite values count as $-\infty$.
    Returns `(x_best, f_best, evaluations)`."""
    g = (math.sqrt(5.0) - 1.0) / 2.0

    def F(x):
        v = float(f(x))
        return v if math.isfinite(v) else -math.inf

    a, b = float(lo), float(hi)
    c, d = b - g * (b - a), a + g * (b - a)
    fc, fd = F(c), F(d)
    pts = [(c, fc), (d, fd)]
    while b - a > xtol:
        if fc >= fd:
            b, d, fd = d, c, fc
            c = b - g * (b - a)
            fc = F(c)
            pts.append((c, fc))
        else:
            a, c, fc = c, d, fd
            d = a + g * (b - a)
            fd = F(d)
            pts.append((d, fd))
    if x0 is not None:
        pts.append((float(x0), -math.inf if f0 is None or not math.isfinite(f0) else float(f0)))
    x, v = max(pts, key=lambda t: t[1])
    return x, v, len(pts) - (x0 is not None)


def _polish_psi0(d, terms, param, n, window, xtol):
    """Golden-section polish of study (b)'s fold angle at the design's gap (`golden_max` on
    [Psi0 - window, Psi0 + window] within the bounds), on the very program the optimizer
    compiled (`jaxrod.design.linearize` of the same problem: no new compilation). Returns the
    design with the better of the two points and a record of the polish."""
    problem = Problem(terms, param, n)
    i = param.free.index("psi0_deg")
    z_best = np.asarray(d.z, float)
    lo_b, hi_b = param.describe()["psi0_deg"]["bounds"]
    cache = {}

    def v_at(p):
        z = z_best.copy()
        z[i] = float(param.from_values(psi0_deg=p)[i])
        r, _, vals, codes = linearize(problem, jnp.asarray(z)[None])  # batched as `optimize` ran it
        cache[p] = (z, np.asarray(r)[0], np.asarray(vals)[0], np.asarray(codes)[0])
        return float(cache[p][2][0])

    p0, v0 = d.psi0_deg, float(np.asarray(d.achieved)[0])
    lo, hi = max(lo_b + 1e-3, p0 - window), min(hi_b - 1e-3, p0 + window)
    p1, v1, evals = golden_max(v_at, lo, hi, xtol=xtol, x0=p0, f0=v0)
    rec = dict(psi0_before=p0, v_s_before=v0, psi0_after=p0, v_s_after=v0, evaluations=evals,
               window_deg=[lo, hi], xtol_deg=xtol)
    if p1 != p0 and v1 > v0:
        z, r, vals, codes = cache[p1]
        zj = jnp.asarray(z)
        d = eqx.tree_at(lambda x: (x.values, x.achieved, x.loss, x.z, x.codes), d,
                        (jnp.asarray(param.values(zj)), jnp.asarray(vals), jnp.asarray(0.5 * float(np.sum(r**2))), zj,
                         jnp.asarray(codes, jnp.int32)), is_leaf=lambda x: x is None)
        rec.update(psi0_after=float(d.psi0_deg), v_s_after=float(vals[0]))
    return d, rec


def fastest_snap_study(min_gap=0.3, *, s0=0.02, psi0_bounds=(10.0, 180.0), max_gap=0.95,
                       starts=((90.0, 0.5),), goal=100.0, n=48, n_check=96, max_iter=20, check_rtol=1e-9,
                       polish=True, polish_window=15.0, polish_xtol=0.05, progress=True, optimizer="lm",
                       **speed_options) -> SpeedStudyResult:
    """Study (b): maximize v_s / v* of the snap up over (Psi0, G/L), G/L in (`min_gap`,
    `max_gap`), Psi0 in `psi0_bounds` (degrees), s0 fixed.

    Maximization as least squares toward an unreachable `goal` (default 100 v*, 2.3 times
    the paper's G/L = 0 intercept 42.6 v*): Levenberg-Marquardt on (v_s - goal)^2 only
    ascends v_s while v_s < goal. The sigmoid parametrization never reaches a bound, it
    approaches it (gap -> min_gap as z -> -inf); `at_bound` reports an optimum within
    1e-3 of the gap bound. The run stops when stationary, without descent or after
    `max_iter`. The far-goal Gauss-Newton model is linear and does not see the curvature
    of v_s in Psi0, so its steps overshoot near the maximum and are rejected, and it stops
    short of the maximum in Psi0 (measured: 0.12 % below a grid maximum). With `polish`
    (default) the study then maximizes v_s over Psi0 alone at the design's gap by
    golden-section search (`golden_max`) on [Psi0 - `polish_window`, Psi0 +
    `polish_window`] to `polish_xtol` degrees, on the program the optimizer compiled (no
    new compilation; ~17 evaluations), and keeps the better point (`polish` on the result
    records both). The best design is re-checked on `n_check` segments. `optimizer`: "lm"
    or an optax transformation (gradient ascent on v_s then, by its own steps).

    Result (N = 48, check N = 96, from Psi0 = 90 deg, G/L = 0.5; `jaxrod.snap_speed` with
    RATTLE, benchmarks/results/design.md, which also times the study): 20 LM iterations end
    at G/L = 0.3 (the bound), Psi0 = 23.559 deg, v_s = 37.7251 v*; the polish (16
    evaluations) moves Psi0 to 26.135 deg, v_s = 37.7720 v* (check 37.7290, 0.11 %). A
    snap_speed grid on the same mesh (benchmarks/certify_study_b.py,
    results/study_b_grid.md) has its maximum at Psi0 = 26.5 deg (0.25-deg grid), G/L = 0.3:
    37.7712 v*, so the design is at or above it (to the map's wiggle: second differences of
    the 0.25-deg grid reach 8e-3 v*, 2e-4 relative); v_s falls with G/L (grid maxima 37.02,
    35.78, 33.44 at G/L = 0.32, 0.35, 0.40), so the bound is the optimum in G/L, and the
    maximum in Psi0 is interior. The paper's plane (v_s falling in G/L and in Psi0) would
    put the optimum at the gap bound and the smallest Psi0; jaxrod agrees on the gap, not
    on Psi0.
    """
    _needs_dynamics("fastest_snap_study")
    import time

    if not (isinstance(min_gap, (int, float)) and 0.0 <= min_gap < max_gap <= 1.0):
        raise ValueError(f"min_gap: must satisfy 0 <= min_gap < max_gap <= 1, got {min_gap!r}")
    t0 = time.perf_counter()
    param = Parametrization(free=("psi0_deg", "gap"),
                            bounds={"psi0_deg": tuple(psi0_bounds), "gap": (float(min_gap), float(max_gap))},
                            fixed={"s0": s0})
    term = SnapSpeed(goal, tol=1.0, **speed_options)
    st = [{"psi0_deg": float(p), "gap": float(g)} for p, g in starts]
    best, runs = _run_starts((term,), param, st, n, max_iter, progress, {"study": "b", "min_gap": min_gap},
                             optimizer)
    d = best.best
    rec = None
    if polish:
        d, rec = _polish_psi0(d, (term,), param, n, float(polish_window), float(polish_xtol))
    v = float(np.asarray(d.achieved)[0])
    v0 = goal - math.sqrt(2.0 * float(best.best.history_loss[0]))
    chk = verify_snap_speed(d.psi0_deg, d.gap, d.s0, n_check, v, tol=0.01, rtol=check_rtol)
    return SpeedStudyResult("b", d, chk, runs, v, v0, time.perf_counter() - t0, float(min_gap), polish=rec)
