r"""Crease positions and fold angles as design variables.

A crease set of $m$ creases is designed through an unconstrained vector $z\in\mathbb R^{2m}$:
positions $c_k = c_{lo} + (c_{hi}-c_{lo})\,\sigma(z_k)$ and fold angles
$\Psi_k = \Psi_{lo} + (\Psi_{hi}-\Psi_{lo})\,\sigma(z_{m+k})$, $\sigma(z) = 1/(1+e^{-z})$,
so every iterate is a valid strip (`CreaseParametrization`). Derivatives of the snap angles
come from `jaxrod.snap_angles` (the implicit derivative of the refined critical point) and
of the snap speed from `jaxrod.snap_speed` (through the RATTLE integration), both with
respect to the crease set's leaves (`crease_scene` builds a scene from traced positions and
angles). `check_creases` is the independent forward solve of a crease set at a finer mesh.

One design of the gap: `crease_gap_for_speed`, the gap at which a given crease set snaps up
at a target speed (Newton on $v_s(G)$ with the autodiff derivative through the RATTLE snap),
re-checked at a finer mesh. The two crease studies (`two_crease_study`,
`crease_position_study`) are in `jaxrod.paper`.
"""

from __future__ import annotations

import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import jaxrod as jr


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
