r"""Crease positions and fold angles as design variables.

A crease set of $m$ creases is designed through an unconstrained vector $z\in\mathbb R^{2m}$:
positions $c_k = c_{lo} + (c_{hi}-c_{lo})\,\sigma(z_k)$ and fold angles
$\Psi_k = \Psi_{lo} + (\Psi_{hi}-\Psi_{lo})\,\sigma(z_{m+k})$, $\sigma(z) = 1/(1+e^{-z})$,
so every iterate is a valid strip (`CreaseParametrization`). Derivatives of the snap angles
come from `jaxrod.snap_angles` (the implicit derivative of the refined critical point) and
of the snap speed from `jaxrod.snap_speed` (through the RATTLE integration), both with
respect to the crease set's leaves.

Two studies, each re-checked by an independent forward solve at a finer mesh:

* `two_crease_study`: two creases whose snap angles hit targets $(\alpha_{up}^*,\alpha_{down}^*)$
  and, among the designs that do (a two-dimensional family for four variables), the one with
  the fastest snap up. Levenberg-Marquardt minimum-norm steps reach the targets,
  $\delta z = -J^\top(JJ^\top+\mu I)^{-1}r$; then projected gradient ascent on $v_s$, with
  the step $P\nabla_z v_s$, $P = I - J^\top(JJ^\top)^{-1}J$ (tangent to the family), each
  trial pulled back onto the targets by the same LM steps and accepted only if $v_s$ grows
  and every path stays clean.
* `crease_position_study`: the position $c$ of a single crease that maximises the hysteresis
  width $W(c)=\alpha_{c,up}-\alpha_{c,down}$ at a given gap. By mirror symmetry
  $W(c)=W(L-c)$, so $c\in(c_{lo}, L/2]$ is scanned; the best grid point is refined by
  golden-section search. At $c=L/2$ the up path of many strips snaps at a branch point that
  any off-centre crease turns into a fold (an imperfect bifurcation): $W$ has a cusp there,
  not a smooth maximum, and the study says which one it found.

And one design of the gap: `crease_gap_for_speed`, the gap at which a given crease set snaps up
at a target speed (Newton on $v_s(G)$ with the autodiff derivative through the RATTLE snap),
re-checked at a finer mesh.
"""

from __future__ import annotations

import dataclasses
import json
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import jaxrod as jr

from ._studies import golden_max


class CreaseParametrization(eqx.Module):
    """Bounds of the crease positions (fractions of L) and fold angles (degrees) of an
    `m`-crease design. `to_creases(z)` gives `(positions, angles_rad)`; `from_values` is its
    inverse (values clipped 1e-6 inside the bounds)."""

    m: int = eqx.field(static=True)
    positions: tuple = eqx.field(static=True)
    angles_deg: tuple = eqx.field(static=True)

    def __init__(self, m=2, positions=(0.05, 0.95), angles_deg=(20.0, 179.0)):
        if isinstance(m, bool) or not isinstance(m, int) or m < 1:
            raise ValueError(f"m (number of creases) must be an integer >= 1, got {m!r}")
        lo, hi = (float(v) for v in positions)
        if not (0.0 < lo < hi < 1.0):
            raise ValueError(f"positions: bounds must satisfy 0 < lower < upper < 1, got {positions!r}")
        alo, ahi = (float(v) for v in angles_deg)
        if not (0.0 < alo < ahi <= 180.0):
            raise ValueError(f"angles_deg: bounds must satisfy 0 < lower < upper <= 180, got {angles_deg!r}")
        self.m, self.positions, self.angles_deg = m, (lo, hi), (alo, ahi)

    def to_creases(self, z):
        s = jax.nn.sigmoid(jnp.asarray(z))
        (lo, hi), (alo, ahi) = self.positions, self.angles_deg
        return lo + (hi - lo) * s[: self.m], jnp.radians(alo + (ahi - alo) * s[self.m:])

    def from_values(self, positions, angles_deg):
        (lo, hi), (alo, ahi) = self.positions, self.angles_deg

        def logit(v, a, b):
            u = np.clip((np.asarray(v, float) - a) / (b - a), 1e-6, 1 - 1e-6)
            return np.log(u / (1 - u))

        return jnp.asarray(np.concatenate([logit(positions, lo, hi), logit(angles_deg, alo, ahi)]))


def crease_scene(positions, angles, *, gap=0.5, n=48, s0=0.02, alpha_deg=0.0):
    """A flat strip with creases at `positions` (fractions of L) of fold angles `angles`
    (radians; traced values allowed: the scene is built on a concrete template and its
    crease leaves replaced), uniform mesh of `n` segments."""
    m = int(np.shape(positions)[0])
    template = jr.make_scene(180.0, 0.5, alpha_deg, n=n, s0=s0,
                             creases=[(0.1 + 0.8 * (k + 0.5) / m, 90.0) for k in range(m)])
    dtype = jnp.result_type(float)
    return eqx.tree_at(lambda s: (s.strip.creases.positions, s.strip.creases.angles, s.clamps.gap), template,
                       (jnp.asarray(positions, dtype), jnp.asarray(angles, dtype), jnp.asarray(gap, dtype)))


def _angles_deg(positions, angles, gap, n):
    r = jr.snap_angles(crease_scene(positions, angles, gap=gap, n=n))
    ok = (r.up.result == jr.RESULTS.successful) & (r.down.result == jr.RESULTS.successful) & r.up.snaps & r.down.snaps
    return jnp.degrees(jnp.stack([r.up.alpha_c, r.down.alpha_c])), ok


@dataclasses.dataclass
class CreaseCheck:
    """An independent forward solve of a design at a finer mesh `n`."""

    n: int
    alpha_up_deg: float
    alpha_down_deg: float
    v_s: float
    result: str


def check_creases(positions, angles_deg, *, gap, n, speed=True):
    """`snap_angles` (and the snap-up speed) of a crease set at `n` segments."""
    sc = crease_scene(np.asarray(positions, float), np.radians(np.asarray(angles_deg, float)), gap=gap, n=n)
    r = jr.snap_angles(sc)
    codes = [jr.result_name(p.result) for p in (r.up, r.down)]
    v = float(jr.snap_speed_run(sc, direction="up").v_s) if speed else math.nan
    bad = [c for c in codes if c != "successful"]
    return CreaseCheck(n, math.degrees(float(r.up.alpha_c)), math.degrees(float(r.down.alpha_c)), v,
                       bad[0] if bad else "successful")


@dataclasses.dataclass
class TwoCreaseResult:
    """`two_crease_study`'s design: crease `positions` (L) and `angles_deg`, its snap angles
    and snap-up speed `v_s` (v*) at the design mesh `n`, the `history` of accepted steps
    (v_s, positions, angles), the smallest clearance over its snap (L), whether the targets
    were `reached` (within `tol_deg`) and the finer mesh's `check`."""

    targets_deg: tuple
    gap: float
    n: int
    positions: list
    angles_deg: list
    alpha_up_deg: float
    alpha_down_deg: float
    v_s: float
    v_s_start: float
    snap_clearance: float
    history: list
    reached: bool
    tol_deg: float
    check: CreaseCheck
    seconds: float

    @property
    def check_errors_deg(self):
        """|alpha_c - target| at the check's finer mesh (the design mesh's discretization error)."""
        return (abs(self.check.alpha_up_deg - self.targets_deg[0]), abs(self.check.alpha_down_deg - self.targets_deg[1]))

    def to_dict(self):
        d = dataclasses.asdict(self)
        d["check_errors_deg"] = list(self.check_errors_deg)
        return d

    def save(self, path):
        with open(path, "w") as fh:
            json.dump(self.to_dict(), fh, indent=1)


def two_crease_study(alpha_up_deg=55.0, alpha_down_deg=-110.0, *, gap=0.5, start=((0.3, 0.68), (90.0, 90.0)),
                     n=48, n_check=96, tol_deg=0.02, steps=12, step=0.3, clearance=0.01, param=None,
                     progress=True) -> TwoCreaseResult:
    """Two creases with snap angles `alpha_up_deg`, `alpha_down_deg` (degrees) at `gap`, and
    among those designs the fastest snap up (module docstring). `start`: the initial
    (positions, angles_deg), where both paths must snap cleanly (a mirror-symmetric start can
    sit where a fold and a branch point coincide, whose critical point has no derivative);
    `n`: the design mesh, `n_check` the independent check's;
    `steps`: ascent steps tried; `step`: the first step length in z; `clearance` (in L): an
    ascent step is accepted only if the snap keeps parts of the strip at least this far apart
    (contact is not modelled: a faster snap through itself is not a design). Needs float64."""
    import time

    if not jax.config.jax_enable_x64:
        raise ValueError("two_crease_study needs float64; enable it with jax.config.update('jax_enable_x64', True)")
    for name, v in (("alpha_up_deg", alpha_up_deg), ("alpha_down_deg", alpha_down_deg), ("gap", gap)):
        if not math.isfinite(float(v)):
            raise ValueError(f"{name} must be a finite number, got {v!r}")
    if not 0.0 < gap < 1.0:
        raise ValueError(f"gap must lie in (0, 1), got {gap!r}")
    t0 = time.time()
    param = CreaseParametrization(2) if param is None else param
    target = jnp.asarray([alpha_up_deg, alpha_down_deg], float)

    def residual(z):
        c, a = param.to_creases(z)
        ang, ok = _angles_deg(c, a, gap, n)
        return ang - target, ok

    res_jac = jax.jit(lambda z: (residual(z), jax.jacrev(lambda q: residual(q)[0])(z)))

    def speed(z):
        c, a = param.to_creases(z)
        return jr.snap_speed(crease_scene(c, a, gap=gap, n=n), direction="up")

    speed_grad = jax.jit(jax.value_and_grad(speed))
    sep = max(2, -(-n // 10))  # segments at least N/10 apart, as the CLI's clearance

    @jax.jit
    def snap_clearance(z):
        """The smallest clearance (in L) over the brink snap up's frames: the snap a fast
        design is chasing must not pass the strip through itself (contact is not modelled)."""
        c, a = param.to_creases(z)
        sc = crease_scene(c, a, gap=gap, n=n)
        _, tr = jr.snap_dynamics(sc, "up", n_frames=32)
        th = tr.theta
        good = jnp.all(jnp.isfinite(th), axis=1)
        d = jax.vmap(lambda t: jr.clearance(t, sc, min_separation=sep))(jnp.where(good[:, None], th, 0.0))
        return jnp.min(jnp.where(good, d, jnp.inf))


    def clean(r, J, ok):
        return bool(ok) and bool(np.all(np.isfinite(r))) and bool(np.all(np.isfinite(J)))

    def project(z, iters=12, mu=1e-6):
        """LM minimum-norm steps onto the targets, each halved (up to 6 times) until the
        residual falls and both paths stay clean."""
        (r, ok), J = res_jac(z)
        r, J = np.asarray(r), np.asarray(J)
        if not clean(r, J, ok):
            return z, False, r
        for _ in range(iters):
            if np.max(np.abs(r)) < tol_deg / 10:
                return z, True, r
            dz = -J.T @ np.linalg.solve(J @ J.T + mu * np.eye(2), r)
            dz = dz / max(1.0, np.linalg.norm(dz))  # at most a unit step in z
            for _ in range(6):
                zt = z + jnp.asarray(dz)
                (rt, okt), Jt = res_jac(zt)
                rt, Jt = np.asarray(rt), np.asarray(Jt)
                if clean(rt, Jt, okt) and np.linalg.norm(rt) < np.linalg.norm(r):
                    break
                dz = 0.5 * dz
            else:
                return z, False, r
            z, r, J = zt, rt, Jt
        return z, bool(np.max(np.abs(r)) < tol_deg), r

    z = param.from_values(start[0], start[1])
    z, ok, r = project(z, iters=30)
    if progress:
        print(f"targets {'reached' if ok else 'not reached'}: residual {np.round(r, 4)} deg", flush=True)
    v, g = speed_grad(z)
    v0 = float(v)
    history = []

    def record(z, v):
        c, a = param.to_creases(z)
        history.append(dict(v_s=float(v), positions=np.asarray(c).tolist(), angles_deg=np.degrees(np.asarray(a)).tolist()))

    record(z, v)
    h = step
    for _ in range(steps if ok else 0):
        (_, _), J = res_jac(z)
        J = np.asarray(J)
        P = np.eye(J.shape[1]) - J.T @ np.linalg.solve(J @ J.T, J)
        d = P @ np.asarray(g)
        if not np.all(np.isfinite(d)) or np.linalg.norm(d) == 0:
            break
        accepted = False
        while h > 1e-3 and not accepted:
            zt, okt, _ = project(z + jnp.asarray(h * d / np.linalg.norm(d)))
            vt, gt = speed_grad(zt) if okt else (jnp.nan, None)
            okt = okt and np.isfinite(float(vt)) and float(vt) > float(v) and float(snap_clearance(zt)) >= clearance
            if okt:
                z, v, g, accepted = zt, vt, gt, True
                record(z, v)
                h *= 1.5
            else:
                h *= 0.5
        if progress:
            print(f"v_s {float(v):.3f} v* (step {h:.3g})", flush=True)
        if not accepted:
            break
    c, a = param.to_creases(z)
    (r, ok_end), _ = res_jac(z)
    r = np.asarray(r)
    reached = bool(ok_end) and bool(np.max(np.abs(r)) < tol_deg)
    pos, ang = np.asarray(c).tolist(), np.degrees(np.asarray(a)).tolist()
    check = check_creases(pos, ang, gap=gap, n=n_check)
    return TwoCreaseResult((float(alpha_up_deg), float(alpha_down_deg)), float(gap), int(n), pos, ang,
                           float(r[0] + target[0]), float(r[1] + target[1]), float(v), v0,
                           float(snap_clearance(z)) if reached else math.nan, history, reached,
                           float(tol_deg), check, time.time() - t0)


@dataclasses.dataclass
class PositionResult:
    """`crease_position_study`'s answer: the `grid` of positions (L) and widths W (deg; None
    where a path is flagged), the best `position` and `width_deg` at the design mesh `n`,
    `where`: "centre" (c = L/2, where the mirror symmetry makes W a cusp) or "interior"; the
    best interior point (`interior_position`, `interior_width_deg`) with `slope` dW/dc there
    (the implicit derivative, deg/L) and `interior_smooth`: whether it is a smooth maximum
    (|slope| xtol < 0.01 deg) rather than the edge of a jump of W (a snap path whose
    critical point changes branch: W is discontinuous there and the maximum a supremum); the
    centre's width (`centre_width_deg`), and the `check`s at a finer mesh."""

    psi0_deg: float
    gap: float
    n: int
    grid: list
    widths_deg: list
    position: float
    width_deg: float
    where: str
    interior_position: float
    interior_width_deg: float
    slope: float
    interior_smooth: bool
    centre_width_deg: float
    check: CreaseCheck
    check_interior: CreaseCheck
    seconds: float

    def to_dict(self):
        return dataclasses.asdict(self)


def crease_position_study(psi0_deg=120.0, gap=0.5, *, n=48, n_check=96, lo=0.1, points=17, xtol=1e-3,
                          progress=True) -> PositionResult:
    """The position of one crease of fold angle `psi0_deg` that maximises the hysteresis
    width at `gap` (module docstring): a scan of `points` positions on [lo, 1/2], the
    golden-section refinement of the best interior one to `xtol`, both checked at `n_check`."""
    import time

    if not jax.config.jax_enable_x64:
        raise ValueError("crease_position_study needs float64; enable it with "
                         "jax.config.update('jax_enable_x64', True)")
    if not (math.isfinite(psi0_deg) and 0.0 < psi0_deg < 180.0):
        raise ValueError(f"psi0_deg must lie in (0, 180), got {psi0_deg!r}")
    if not (math.isfinite(gap) and 0.0 < gap < 1.0):
        raise ValueError(f"gap must lie in (0, 1), got {gap!r}")
    if not 0.0 < lo < 0.5:
        raise ValueError(f"lo must lie in (0, 0.5), got {lo!r}")
    t0 = time.time()
    psi = math.radians(psi0_deg)
    f = jax.jit(lambda c: _angles_deg(jnp.reshape(c, (1,)), jnp.asarray([psi]), gap, n))

    def width(c):
        a, ok = f(jnp.asarray(c, float))
        return float(a[0] - a[1]) if bool(ok) else math.nan

    grid = np.linspace(lo, 0.5, points)
    W = [width(c) for c in grid]
    if progress:
        print("W(c):", [round(w, 2) for w in W], flush=True)
    finite = [(c, w) for c, w in zip(grid, W) if math.isfinite(w)]
    if not finite:
        raise ValueError("no position on the grid gives two clean snap paths")
    inner = [(c, w) for c, w in finite if c < 0.5 - 1e-12]
    ci, wi, slope = math.nan, math.nan, math.nan
    if inner:
        k = int(np.argmax([w for _, w in inner]))
        a = inner[max(k - 1, 0)][0]
        b = inner[min(k + 1, len(inner) - 1)][0] if k + 1 < len(inner) else 0.5 - 1e-9
        ci, wi, _ = golden_max(width, a, b, xtol=xtol, x0=inner[k][0], f0=inner[k][1])
        dw = jax.grad(lambda c: (lambda a: a[0] - a[1])(f(c)[0]))(jnp.asarray(ci, float))
        slope = float(dw)
    wc = W[-1]
    centre_best = math.isfinite(wc) and (not math.isfinite(wi) or wc >= wi)
    pos, wbest = (0.5, wc) if centre_best else (ci, wi)
    check = check_creases([pos], [psi0_deg], gap=gap, n=n_check, speed=False)
    check_i = (check_creases([ci], [psi0_deg], gap=gap, n=n_check, speed=False) if math.isfinite(ci)
               else CreaseCheck(n_check, math.nan, math.nan, math.nan, "not_run"))
    return PositionResult(float(psi0_deg), float(gap), int(n), grid.tolist(), [None if not math.isfinite(w) else w for w in W],
                          float(pos), float(wbest), "centre" if centre_best else "interior", float(ci), float(wi),
                          slope, bool(math.isfinite(slope) and abs(slope) * xtol < 0.01), float(wc), check, check_i,
                          time.time() - t0)


@dataclasses.dataclass
class CreaseGapResult:
    """`crease_gap_for_speed`'s design: the `gap` (G/L) at which the strip with `creases`
    (`(position, psi0_deg, s0)` each) and centred crease `psi0_deg` snaps up at `v_s` (v*)
    on the design mesh `n`, the Newton `history` of (gap, v_s), whether the target was
    `reached` (within `tol`, relative), and the `check`: v_s of `jaxrod.snap_speed_run` on the
    finer mesh `n_check` and its code; `confirmed` when the check is within `tol` too."""

    target_speed: float
    psi0_deg: float
    creases: list
    n: int
    gap: float
    v_s: float
    history: list
    reached: bool
    tol: float
    n_check: int
    check_v_s: float
    check_result: str
    confirmed: bool
    seconds: float

    def to_dict(self):
        return dataclasses.asdict(self)


def crease_gap_for_speed(target_speed, creases, *, psi0_deg=180.0, s0=0.02, gap=0.5, bounds=(0.05, 0.95), n=48,
                         n_check=96, tol=0.01, max_iter=12) -> CreaseGapResult:
    r"""The gap $G/L$ at which a strip with the given creases (`[(position, psi0_deg[, s0])]`,
    as `jaxrod.make_scene`; `psi0_deg` the centred crease, 180 for none) snaps up at
    `target_speed` v*: Newton's method on $v_s(G)$ with $dv_s/dG$ by autodiff through
    `jaxrod.snap_speed` (RATTLE), from `gap`, each step kept inside `bounds` (halved towards
    the current gap when it leaves them) and, once gaps on both sides of the target are
    known, inside that bracket (a bisection where the Newton step leaves it: the fixed-step
    snap's v_s wiggles on small scales, so its derivative can mislead near the root); a step to
    a gap whose snap has no speed (its path or its run passes through itself, or it does not
    snap) is halved back toward the last gap that had one; until
    $|v_s-v^\ast| \le 0.1\,$`tol`$\,v^\ast$ or
    `max_iter` steps; then re-checked by `jaxrod.snap_speed_run` on `n_check` segments.
    Needs float64."""
    import time

    if not jax.config.jax_enable_x64:
        raise ValueError("crease_gap_for_speed needs float64; enable it with jax.config.update('jax_enable_x64', True)")
    def number(name, v):
        if isinstance(v, bool) or np.ndim(v) != 0:
            raise ValueError(f"{name} must be a number, got {v!r}")
        try:
            return float(v)
        except (TypeError, ValueError):
            raise ValueError(f"{name} must be a number, got {v!r}") from None

    target_speed = number("target_speed", target_speed)
    if not (math.isfinite(target_speed) and target_speed > 0):
        raise ValueError(f"target_speed must be a finite number > 0, got {target_speed!r}")
    try:
        lo, hi = (number("bounds", b) for b in bounds)
    except (TypeError, ValueError):
        raise ValueError(f"bounds must be a pair (lower, upper) of numbers in (0, 1), got {bounds!r}") from None
    if not 0.0 < lo < hi < 1.0:
        raise ValueError(f"bounds must satisfy 0 < lower < upper < 1, got {bounds!r}")
    gap = number("gap", gap)
    if not lo < gap < hi:
        raise ValueError(f"gap must lie inside the bounds {bounds!r}, got {gap!r}")
    t0 = time.perf_counter()
    template = jr.make_scene(psi0_deg, gap, s0=s0, n=n, creases=creases)  # validates the creases
    record = [[float(v) for v in row] for row in zip(*(np.asarray(x) for x in template.strip.crease_list()))]

    def speed(g):
        return jr.snap_speed(eqx.tree_at(lambda s: s.clamps.gap, template, g))

    vg = jax.jit(jax.value_and_grad(speed))
    g = jnp.asarray(float(gap))
    history, reached = [], False
    for _ in range(max_iter + 1):
        v, dv = vg(g)
        v, dv = float(v), float(dv)
        history.append((float(g), v))
        if not math.isfinite(v):
            # a gap whose snap has no speed (it passes through itself, or does not snap): back
            # halfway toward the last gap that had one; none yet: give up
            ran = [h[0] for h in history if math.isfinite(h[1])]
            if not ran or len(history) > max_iter:
                break
            g = jnp.asarray(0.5 * (ran[-1] + float(g)))
            continue
        if abs(v - target_speed) <= 0.1 * tol * target_speed:
            reached = True
            break
        if len(history) > max_iter:
            break
        # the bracket: the closest gaps on either side of the target seen so far
        above = [h[0] for h in history if math.isfinite(h[1]) and h[1] > target_speed]
        below = [h[0] for h in history if math.isfinite(h[1]) and h[1] < target_speed]
        new = float(g) - (v - target_speed) / dv if math.isfinite(dv) and dv != 0.0 else math.nan
        if above and below:
            a_, b_ = sorted((min(above, key=lambda x: abs(x - float(g))), min(below, key=lambda x: abs(x - float(g)))))
            if not a_ < new < b_:
                new = 0.5 * (a_ + b_)  # a Newton step that leaves the bracket: bisect
        elif not math.isfinite(new):
            break
        step = new - float(g)
        while not lo < float(g) + step < hi:
            step *= 0.5
        g = jnp.asarray(float(g) + step)
    best_g, best_v = min((h for h in history if math.isfinite(h[1])), key=lambda h: abs(h[1] - target_speed),
                         default=(float(gap), math.nan))
    reached = reached or (math.isfinite(best_v) and abs(best_v - target_speed) <= tol * target_speed)
    run = jr.snap_speed_run(jr.make_scene(psi0_deg, best_g, s0=s0, n=n_check, creases=creases))
    cv, code = float(run.v_s), jr.result_name(run.result)
    confirmed = bool(reached and code == "successful" and abs(cv - target_speed) <= tol * target_speed)
    return CreaseGapResult(float(target_speed), float(psi0_deg), record, int(n), float(best_g), float(best_v),
                           [list(h) for h in history], bool(reached), float(tol), int(n_check), cv, code, confirmed,
                           time.perf_counter() - t0)
