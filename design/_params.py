r"""Feasible parametrization of a design $(\Psi_0, G/L, s_0/L)$.

Each free parameter $v$ with bounds $(l, u)$ is the image of an unconstrained real $z$:
$$v = l + (u - l)\,\sigma(z),\qquad \sigma(z) = 1/(1+e^{-z}),$$
so every optimizer iterate is feasible (open interval: the bounds themselves are never
reached). The fold width uses the same map on $\log s_0$ (a positive, scale-free
parameter). Defaults: $\Psi_0\in(10^\circ, 180^\circ)$, $G/L\in(0.05, 0.95)$,
$s_0/L\in(0.005, 0.1)$; user bounds must lie inside the model's domain
($\Psi_0\in(0,180]$ deg, $G/L\in(0,1)$, $s_0>0$). A parameter that is not free is held at
its `fixed` value.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

NAMES = ("psi0_deg", "gap", "s0")
_DOMAIN = {"psi0_deg": (0.0, 180.0), "gap": (0.0, 1.0), "s0": (0.0, math.inf)}
DEFAULT_BOUNDS = {"psi0_deg": (10.0, 180.0), "gap": (0.05, 0.95), "s0": (0.005, 0.1)}
DEFAULT_FIXED = {"psi0_deg": 60.0, "gap": 0.5, "s0": 0.02}


def _check_bounds(name, lo, hi):
    dlo, dhi = _DOMAIN[name]
    for v in (lo, hi):
        if not math.isfinite(v):
            raise ValueError(f"{name}: bound {v} is not finite")
    if not (dlo <= lo < hi <= dhi):
        raise ValueError(f"{name}: bounds ({lo:g}, {hi:g}) must satisfy {dlo:g} <= lower < upper <= {dhi:g}")
    if name == "s0" and lo <= 0:
        raise ValueError(f"s0: lower bound must be > 0, got {lo:g}")


class Parametrization(eqx.Module):
    """Which of (psi0_deg, gap, s0) are free, their bounds, and the values of the fixed ones.

    `to_design(z)` maps the unconstrained vector (one entry per free parameter, in the
    order of `NAMES`) to the physical triple (psi0 in radians, gap, s0);
    `from_values` is its inverse (values clipped 1e-6 inside the bounds)."""

    free: tuple = eqx.field(static=True)
    lower: tuple = eqx.field(static=True)
    upper: tuple = eqx.field(static=True)
    fixed: tuple = eqx.field(static=True)

    def __init__(self, free=("psi0_deg", "gap"), bounds=None, fixed=None):
        free = tuple(free)
        for f in free:
            if f not in NAMES:
                raise ValueError(f"free: unknown parameter {f!r} (choose from {NAMES})")
        if not free:
            raise ValueError("free: at least one parameter must be free")
        b = dict(DEFAULT_BOUNDS)
        for k, v in (bounds or {}).items():
            if k not in NAMES:
                raise ValueError(f"bounds: unknown parameter {k!r} (choose from {NAMES})")
            lo, hi = (float(x) for x in v)
            b[k] = (lo, hi)
        for k in NAMES:
            _check_bounds(k, *b[k])
        fx = dict(DEFAULT_FIXED)
        fx.update(fixed or {})
        for k in NAMES:
            if k not in free:
                v = float(fx[k])
                lo, hi = _DOMAIN[k]
                if not (lo < v <= hi if k == "psi0_deg" else lo < v < hi):
                    raise ValueError(f"{k}: fixed value {v:g} outside the domain")
        self.free = tuple(k for k in NAMES if k in free)
        self.lower = tuple(b[k][0] for k in NAMES)
        self.upper = tuple(b[k][1] for k in NAMES)
        self.fixed = tuple(float(fx[k]) for k in NAMES)

    @property
    def size(self):
        return len(self.free)

    def values(self, z):
        """Physical values (psi0_deg, gap, s0) as a (3,) array."""
        out = []
        j = 0
        for i, k in enumerate(NAMES):
            if k in self.free:
                lo, hi = self.lower[i], self.upper[i]
                s = jax.nn.sigmoid(z[j])
                if k == "s0":
                    v = jnp.exp(math.log(lo) + (math.log(hi) - math.log(lo)) * s)
                else:
                    v = lo + (hi - lo) * s
                v = jnp.clip(v, lo, hi)  # round-off at |z| >> 1 must not leave the bounds
                j += 1
            else:
                v = jnp.asarray(self.fixed[i], jnp.result_type(float))
            out.append(v)
        return jnp.stack(out)

    def to_design(self, z):
        """(psi0 [rad], gap, s0) from the unconstrained vector."""
        v = self.values(z)
        return jnp.deg2rad(v[0]), v[1], v[2]

    def from_values(self, **values):
        """Unconstrained vector of the given physical values (defaults: fixed values)."""
        z = []
        for i, k in enumerate(NAMES):
            if k not in self.free:
                continue
            v = float(values.get(k, self.fixed[i]))
            lo, hi = self.lower[i], self.upper[i]
            if k == "s0":
                v, lo, hi = math.log(v), math.log(lo), math.log(hi)
            u = (v - lo) / (hi - lo)
            u = min(max(u, 1e-6), 1 - 1e-6)
            z.append(math.log(u / (1 - u)))
        return jnp.asarray(z, jnp.result_type(float))

    def sample(self, key, num):
        """`num` unconstrained starts drawn uniformly in the (log-, for s0) bounds."""
        u = jax.random.uniform(key, (num, self.size), minval=0.02, maxval=0.98)
        return jnp.log(u / (1 - u)).astype(jnp.result_type(float))

    def describe(self):
        return {k: {"free": k in self.free, "bounds": [self.lower[i], self.upper[i]], "fixed": self.fixed[i]}
                for i, k in enumerate(NAMES)}


def as_numpy(x):
    return np.asarray(jax.device_get(x))
