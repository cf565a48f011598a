"""Small helpers: input validation on concrete values and dtype handling."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np


def is_concrete(x) -> bool:
    """True when `x` holds values known at trace time (not a JAX tracer)."""
    return not isinstance(x, jax.core.Tracer)


def check_param(name: str, value, *, lo=None, hi=None, lo_open=True, hi_open=True,
                unit: str = "", scale: float = 1.0) -> None:
    """Raise `ValueError` naming `name` if a concrete `value` is NaN or out of range.

    Traced values cannot be inspected; they pass through unchecked and a bad value
    shows up as a result code of the solver instead.
    """
    if not is_concrete(value):
        return
    arr = np.asarray(value, dtype=float) * scale
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    def fmt(b):
        return f"{b:g}{unit}"
    if lo is not None:
        bad = arr <= lo if lo_open else arr < lo
        if np.any(bad):
            rng = f"{'(' if lo_open else '['}{fmt(lo)}, {fmt(hi) if hi is not None else 'inf'}{')' if hi_open else ']'}"
            raise ValueError(f"{name} must lie in {rng}, got {value!r}")
    if hi is not None:
        bad = arr >= hi if hi_open else arr > hi
        if np.any(bad):
            rng = f"{'(' if lo_open else '['}{fmt(lo) if lo is not None else '-inf'}, {fmt(hi)}{')' if hi_open else ']'}"
            raise ValueError(f"{name} must lie in {rng}, got {value!r}")


def default_float():
    """The default floating dtype (float64 only if the user enabled x64)."""
    return jnp.zeros(()).dtype if jnp.zeros(()).dtype.kind == "f" else jnp.float32


def as_float(x, dtype=None):
    return jnp.asarray(x, dtype=dtype if dtype is not None else jnp.result_type(float))


deg = math.pi / 180.0

