r"""Clamp programs: the clamp angles as piecewise-linear functions of time.

A `Program` holds knots $t_0<t_1<\dots<t_{K-1}$ and the clamp angles there,
$\alpha_{L,k}$, $\alpha_{R,k}$ (radians, the signs of docs/model.md: positive tilts an end upward). Between
knots each angle moves linearly; before $t_0$ and after $t_{K-1}$ it holds its end value.
The rates are the slopes of the current piece (zero outside the knots). Any number of knots:
a program can take the strip through several snaps in one run (`jaxrod.actuate`).

It has the interface of `jaxrod.Protocol` (`angles(t)` -> angles and rates), so every
integrator that takes a protocol takes a program, and it is differentiable in its knot
angles and knot times (`jnp.interp`), which is what designing a program by gradient needs.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._misc import is_concrete


class Program(eqx.Module):
    r"""Piecewise-linear clamp angles $\alpha_L(t)$, $\alpha_R(t)$ through knots (see the module
    docstring). `times` (K,) strictly increasing, `alpha_left`, `alpha_right` (K,) radians.
    `Program.from_degrees` takes degrees."""

    times: jax.Array
    alpha_left: jax.Array
    alpha_right: jax.Array

    def __init__(self, times, alpha_left, alpha_right):
        vals = {}
        for name, v in [("times", times), ("alpha_left", alpha_left), ("alpha_right", alpha_right)]:
            if is_concrete(v):
                a = np.asarray(v, dtype=float)
                if a.ndim != 1 or a.size < 1:
                    raise ValueError(f"{name} must be a 1-d sequence of at least one knot, got shape {a.shape}")
                if not np.all(np.isfinite(a)):
                    raise ValueError(f"{name} must be finite, got {v!r}")
                vals[name] = a
        sizes = {k: a.size for k, a in vals.items()}
        if len(set(sizes.values())) > 1:
            raise ValueError(f"times, alpha_left, alpha_right must have the same number of knots, got {sizes}")
        if "times" in vals:
            t = vals["times"]
            if t[0] < 0.0:
                raise ValueError(f"times must start at t >= 0, got {t[0]!r}")
            if np.any(np.diff(t) <= 0.0):
                raise ValueError(f"times must increase strictly, got {list(t)}")
        self.times = jnp.asarray(times, float)
        self.alpha_left = jnp.asarray(alpha_left, float)
        self.alpha_right = jnp.asarray(alpha_right, float)

    @classmethod
    def from_degrees(cls, times, alpha_left_deg, alpha_right_deg) -> "Program":
        """A program from knot angles in degrees."""
        return cls(times, jnp.deg2rad(jnp.asarray(alpha_left_deg, float)),
                   jnp.deg2rad(jnp.asarray(alpha_right_deg, float)))

    @property
    def duration(self):
        """The time of the last knot."""
        return self.times[-1]

    def angles(self, t):
        """(alpha_L(t), alpha_R(t)) and their rates (the slope of the piece that holds t)."""
        ts = self.times
        aL = jnp.interp(t, ts, self.alpha_left)
        aR = jnp.interp(t, ts, self.alpha_right)
        if ts.shape[0] == 1:
            z = jnp.zeros_like(aL)
            return aL, aR, z, z
        i = jnp.clip(jnp.searchsorted(ts, t, side="right") - 1, 0, ts.shape[0] - 2)
        dt = ts[i + 1] - ts[i]
        inside = (t >= ts[0]) & (t < ts[-1])
        rL = jnp.where(inside, (self.alpha_left[i + 1] - self.alpha_left[i]) / dt, 0.0)
        rR = jnp.where(inside, (self.alpha_right[i + 1] - self.alpha_right[i]) / dt, 0.0)
        return aL, aR, rL, rR

    def to_json(self) -> dict:
        """The program as the CLI's JSON (`times`, `alpha_left_deg`, `alpha_right_deg`)."""
        return dict(times=[float(x) for x in np.asarray(self.times)],
                    alpha_left_deg=[math.degrees(float(x)) for x in np.asarray(self.alpha_left)],
                    alpha_right_deg=[math.degrees(float(x)) for x in np.asarray(self.alpha_right)])

    @classmethod
    def from_json(cls, obj) -> "Program":
        """Inverse of `to_json`; ValueError naming a missing or bad field."""
        if not isinstance(obj, dict):
            raise ValueError(f"program must be a JSON object with times, alpha_left_deg, alpha_right_deg, got {obj!r}")
        fields = []
        for key in ("times", "alpha_left_deg", "alpha_right_deg"):
            if key not in obj:
                raise ValueError(f"program: missing field {key!r} (needs times, alpha_left_deg, alpha_right_deg)")
            try:
                fields.append([float(v) for v in obj[key]])
            except (TypeError, ValueError):
                raise ValueError(f"program: {key} must be a list of numbers, got {obj[key]!r}") from None
        return cls.from_degrees(*fields)


def hold_and_move(moves, *, start_left=0.0, start_right=0.0, rate=1.0, hold=1.0, t0=0.0) -> Program:
    """A program of straight moves: from (start_left, start_right) degrees, each move
    `(left_deg, right_deg)` is reached at `rate` rad per time unit on the clamp that moves
    most, then held for `hold`. A convenience for building knot lists; the result is a plain
    `Program`."""
    if not rate > 0:
        raise ValueError(f"rate must be > 0, got {rate!r}")
    if not hold >= 0:
        raise ValueError(f"hold must be >= 0, got {hold!r}")
    t, aL, aR = [float(t0)], [float(start_left)], [float(start_right)]
    for m in moves:
        try:
            l_deg, r_deg = m
        except (TypeError, ValueError):
            raise ValueError(f"moves must be (left_deg, right_deg) pairs, got {m!r}") from None
        span = max(abs(l_deg - aL[-1]), abs(r_deg - aR[-1]))
        dt = max(math.radians(span) / rate, 1e-9)
        t.append(t[-1] + dt)
        aL.append(float(l_deg))
        aR.append(float(r_deg))
        if hold > 0:
            t.append(t[-1] + hold)
            aL.append(float(l_deg))
            aR.append(float(r_deg))
    return Program.from_degrees(t, aL, aR)


__all__ = ["Program", "hold_and_move"]
