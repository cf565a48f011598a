r"""Design objectives: each term maps a design $(\Psi_0, G, s_0)$ to a value, compared with a
target within a tolerance.

A term contributes the residual $r = \sqrt{w}\,(v - v^\*)/\mathrm{tol}$; the objective is
$\tfrac12\sum r^2$ (a weighted combination of terms is simply a tuple of terms with
weights $w$). A design *reaches* its targets when $|v - v^\*| \le \mathrm{tol}$ for every term.

Values (angles in degrees, lengths in $L$, energies in $B/L$):

* `AlphaUp`, `AlphaDown`: the critical clamp angles $\alpha_{c,\rm up}$, $\alpha_{c,\rm down}$ of
  symmetric actuation (docs/model.md; [`design.critical_angles`][] gives their implicit derivatives).
* `Hysteresis`: the width $\alpha_{c,\rm up} - \alpha_{c,\rm down}$ of the loop.
* `FoldHeight(state, alpha_deg)`, `BendingEnergy(state, alpha_deg)`: $y(L/2)$ and $E_b$ of the
  stable up/down equilibrium at clamp angle $\alpha$ (implicit derivatives of
  `jaxrod.solve_equilibrium`).
* `EnergyReleased`: $E_b$ just before the snap minus $E_b$ of the state it lands in (snap up
  or down); reported, but its derivative needs the critical state's sensitivity, which is
  not implemented: it is refused as an optimization term.
* `Snaps(direction, snaps)`: a constraint (snap or no snap on that path), no residual;
  an iterate that violates it counts as infeasible (infinite objective) and is rejected.
* `SnapSpeed`: the snapping speed $v_s/v^*$ (`jaxrod.snap_speed`); where that function is
  not available, constructing the term raises `NotImplementedError`.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp

import jaxrod as jr

from ._critical import critical_angles, design_scene


class Term(eqx.Module):
    """Base class: `name`, `target`, `tol`, `weight`, `unit`; `value(ctx)` in traced code."""

    target: float = eqx.field(static=True)
    tol: float = eqx.field(static=True)
    weight: float = eqx.field(static=True)

    name = "term"
    unit = ""
    is_constraint = False

    def value(self, ctx):
        raise NotImplementedError

    def code(self, ctx, value):
        """The [`jaxrod.RESULTS`][] code of `value` (traced): the verdict of what it was
        computed from. Default: `successful` where the value is finite, else `nonfinite`."""
        return jr.RESULTS.where(jnp.isfinite(value), jr.RESULTS.successful, jr.RESULTS.nonfinite)

    def describe(self):
        return {"name": self.name, "target": self.target, "tol": self.tol, "weight": self.weight,
                "unit": self.unit}


def _first_failure(*codes):
    """The first of `codes` that is not `successful` (traced), else `successful`."""
    out = codes[-1]
    for c in reversed(codes[:-1]):
        out = jr.RESULTS.where(c != jr.RESULTS.successful, c, out)
    return out


def _check(target, tol, weight):
    for nm, v in (("target", target), ("tol", tol), ("weight", weight)):
        if not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ValueError(f"{nm}: must be a finite number, got {v!r}")
    if tol <= 0:
        raise ValueError(f"tol: must be > 0, got {tol}")
    if weight <= 0:
        raise ValueError(f"weight: must be > 0, got {weight}")


class AlphaUp(Term):
    name = "alpha_c_up"
    unit = "deg"

    def __init__(self, target, tol=0.1, weight=1.0):
        _check(target, tol, weight)
        self.target, self.tol, self.weight = float(target), float(tol), float(weight)

    def value(self, ctx):
        return jnp.rad2deg(ctx.critical.alpha_up)

    def code(self, ctx, value):
        return ctx.critical.result_up


class AlphaDown(AlphaUp):
    name = "alpha_c_down"

    def value(self, ctx):
        return jnp.rad2deg(ctx.critical.alpha_down)

    def code(self, ctx, value):
        return ctx.critical.result_down


class Hysteresis(AlphaUp):
    name = "hysteresis_width"

    def value(self, ctx):
        c = ctx.critical
        return jnp.rad2deg(c.alpha_up - c.alpha_down)

    def code(self, ctx, value):
        return _first_failure(ctx.critical.result_up, ctx.critical.result_down)


def _state_name(state):
    if state not in ("up", "down"):
        raise ValueError(f"state: must be 'up' or 'down', got {state!r}")
    return state


class FoldHeight(Term):
    name = "fold_height"
    unit = "L"
    state: str = eqx.field(static=True)
    alpha_deg: float = eqx.field(static=True)

    def __init__(self, target, state="down", alpha_deg=0.0, tol=1e-4, weight=1.0):
        _check(target, tol, weight)
        self.state = _state_name(state)
        self.alpha_deg = float(alpha_deg)
        self.target, self.tol, self.weight = float(target), float(tol), float(weight)

    def value(self, ctx):
        return jr.fold_height(ctx.equilibrium(self.state, self.alpha_deg))

    def code(self, ctx, value):
        return ctx.equilibrium(self.state, self.alpha_deg).result

    def describe(self):
        return {**super().describe(), "state": self.state, "alpha_deg": self.alpha_deg}


class BendingEnergy(FoldHeight):
    name = "bending_energy"
    unit = "B/L"

    def value(self, ctx):
        return jr.bending_energy(ctx.equilibrium(self.state, self.alpha_deg))


class Snaps(Term):
    """Constraint: the `direction` ('up' or 'down') path snaps (`snaps=True`) or does not."""

    name = "snaps"
    is_constraint = True
    direction: str = eqx.field(static=True)
    snaps: bool = eqx.field(static=True)

    def __init__(self, direction="up", snaps=True):
        self.direction = _state_name(direction)
        self.snaps = bool(snaps)
        self.target, self.tol, self.weight = float(self.snaps), 0.5, 1.0

    def value(self, ctx):
        c = ctx.critical
        return (c.snaps_up if self.direction == "up" else c.snaps_down).astype(jnp.result_type(float))

    def code(self, ctx, value):
        return ctx.critical.result_up if self.direction == "up" else ctx.critical.result_down

    def describe(self):
        return {**super().describe(), "name": f"snaps_{self.direction}"}


def dynamics_available():
    """Whether design can use a snap-speed objective: needs `jaxrod.snap_speed`, a
    differentiable v_s of a design."""
    return hasattr(jr, "snap_speed")


_SPEED_OPTIONS = {"nudge", "past", "dt", "t1", "n_fine", "solver", "max_drift"}


class SnapSpeed(Term):
    """The snapping speed v_s / v* of the `direction` snap ([`jaxrod.snap_speed`][]).
    Default `tol` 1 % of the target. `options`: keyword arguments of `jaxrod.snap_speed`."""

    name = "snap_speed"
    unit = "v*"
    direction: str = eqx.field(static=True)
    options: tuple = eqx.field(static=True)

    def __init__(self, target, tol=None, weight=1.0, direction="up", **options):
        if not dynamics_available():
            raise NotImplementedError("snap_speed: the snapping-speed objective needs jaxrod.snap_speed "
                                      "(jaxrod's dynamics), which is not available")
        if tol is None and isinstance(target, (int, float)) and math.isfinite(target):
            tol = 0.01 * abs(target) if target != 0 else 0.1
        _check(target, tol, weight)
        unknown = set(options) - _SPEED_OPTIONS
        if unknown:
            raise ValueError(f"options: unknown snap_speed option(s) {sorted(unknown)} "
                             f"(choose from {sorted(_SPEED_OPTIONS)})")
        self.direction = _state_name(direction)
        self.options = tuple(sorted(options.items()))
        self.target, self.tol, self.weight = float(target), float(tol), float(weight)

    def value(self, ctx):
        return ctx.snap_speed(self.direction, self.options)

    def describe(self):
        return {**super().describe(), "direction": self.direction, "options": dict(self.options)}


class Context:
    """Lazily computed observables of one design (inside traced code): the critical angles
    and stable equilibria are computed once and shared by all terms."""

    def __init__(self, psi0, gap, s0, n, near=None):
        self.psi0, self.gap, self.s0, self.n = psi0, gap, s0, n
        self.near = near  # a neighbouring design's paths, to start the snap paths from
        self.scene = design_scene(psi0, gap, s0, n)
        self._critical = None
        self._eq = {}
        self._speed = {}

    def snap_speed(self, direction, options):
        key = (direction, options)
        if key not in self._speed:
            self._speed[key] = jr.snap_speed(self.scene, direction, **dict(options))
        return self._speed[key]

    @property
    def critical(self):
        if self._critical is None:
            self._critical = critical_angles(self.psi0, self.gap, self.s0, self.n, self.near)
        return self._critical

    def equilibrium(self, state, alpha_deg):
        key = (state, alpha_deg)
        if key not in self._eq:
            sc = jr.SymmetricAlpha().set(self.scene, jnp.deg2rad(alpha_deg))
            start = jr.initial_state(jax.lax.stop_gradient(sc), state)
            eq = jr.solve_equilibrium(sc, start.theta, start.force)
            ok = (start.result == jr.RESULTS.successful) & (eq.result == jr.RESULTS.successful)
            # a missing state makes every observable NaN (an infeasible design), never a wrong state
            nan_theta = jnp.where(ok, eq.theta, jnp.nan)
            self._eq[key] = eqx.tree_at(lambda e: (e.theta, e.result), eq,
                                        (nan_theta, _first_failure(start.result, eq.result)))
        return self._eq[key]


NUMBERS = ("target", "tol", "weight")


def term_key(t):
    """A term's structure without its numbers: its class and every field but `target`,
    `tol` and `weight` (two terms with equal keys trace to the same program)."""
    import dataclasses

    return (type(t),) + tuple((f.name, getattr(t, f.name)) for f in dataclasses.fields(t) if f.name not in NUMBERS)


def term_numbers(terms):
    """(k, 3) array of each term's (target, tol, weight)."""
    return jnp.asarray([[float(t.target), float(t.tol), float(t.weight)] for t in terms])


def evaluate_terms(terms, psi0, gap, s0, n, numbers=None):
    """(residuals, values, codes) of `terms` at one design. Constraint terms have no
    residual; a violated constraint makes every residual NaN (infeasible design). `codes`
    (k,): each term's [`jaxrod.RESULTS`][] value (`Term.code`: the verdict of the snap path
    or state it was computed from). `numbers`: the terms' (target, tol, weight) as a (k, 3)
    array (default `term_numbers(terms)`); the traced code reads them only from there, so
    problems that differ only in their targets share one compiled program."""
    return evaluate_terms_near(terms, psi0, gap, s0, n, numbers)[:3]


def evaluate_terms_near(terms, psi0, gap, s0, n, numbers=None, near=None):
    """`evaluate_terms`, with the snap paths started from a neighbouring design's (`near`, a
    `Critical.near`, or None), and what this design's paths leave for the next: returns
    `(residuals, values, codes, near)` (`near` passed on unchanged where no term needs the
    snap angles)."""
    ctx = Context(psi0, gap, s0, n, near)
    numbers = term_numbers(terms) if numbers is None else numbers
    values = jnp.stack([t.value(ctx) for t in terms])
    codes = jnp.stack([t.code(ctx, values[i])._value.astype(jnp.int32) for i, t in enumerate(terms)])
    res = [jnp.sqrt(numbers[i, 2]) * (values[i] - numbers[i, 0]) / numbers[i, 1]
           for i, t in enumerate(terms) if not t.is_constraint]
    res = jnp.stack(res) if res else jnp.zeros((0,), values.dtype)
    ok = jnp.ones((), bool)
    for i, t in enumerate(terms):
        if t.is_constraint:
            ok = ok & (values[i] == numbers[i, 0])
    res = jnp.where(ok, res, jnp.nan)
    near_out = ctx._critical.near if ctx._critical is not None else near
    return res, values, codes, near_out


def energy_released(psi0, gap, s0, n=100, direction="up"):
    r"""Bending energy released by the snap on the `direction` path (B/L):
    $E_b(\theta_{\rm before}) - E_b(\theta_{\rm after})$ at $\alpha_c$ (NaN if it does not snap).
    Not differentiable (see the module docstring)."""
    sc = design_scene(psi0, gap, s0, n)
    r = jr.snap_angles(sc)
    p = r.up if _state_name(direction) == "up" else r.down
    at = jr.SymmetricAlpha().set(sc, p.alpha_c)
    eb = lambda th, mu: jr.bending_energy(jr.Equilibrium(th, mu, jr.RESULTS.successful,  # noqa: E731
                                                         jnp.zeros((), jnp.int32), jnp.zeros((), jnp.int32), at))
    return eb(p.theta_before, p.force_before) - eb(p.theta_after, p.force_after)
