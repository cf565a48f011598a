r"""The crease studies: two creases designed for target snap angles and the fastest snap, and
the position of one crease for the widest hysteresis. Built on `jaxrod.design`'s crease
parametrization (`CreaseParametrization`, `crease_scene`, `check_creases`); each study is
re-checked by an independent forward solve at a finer mesh.

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
"""

from __future__ import annotations

import dataclasses
import json
import math

import jax
import jax.numpy as jnp
import numpy as np

import jaxrod as jr
from jaxrod.design import CreaseCheck, CreaseParametrization, check_creases, crease_scene

from ._studies import golden_max


def _angles_deg(positions, angles, gap, n):
    r = jr.snap_angles(crease_scene(positions, angles, gap=gap, n=n))
    ok = (r.up.result == jr.RESULTS.successful) & (r.down.result == jr.RESULTS.successful) & r.up.snaps & r.down.snaps
    return jnp.degrees(jnp.stack([r.up.alpha_c, r.down.alpha_c])), ok


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
