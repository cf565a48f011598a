"""Small helpers: input validation on concrete values, dtype handling, the package's version
and a digest of its source."""

from __future__ import annotations

import functools
import math

import equinox as eqx
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
    try:
        arr = np.asarray(value, dtype=float) * scale
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
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


def check_int(name: str, value, *, lo: int = 1, hi: int | None = None) -> None:
    """Raise `ValueError` naming `name` unless `value` is an integer (Python or NumPy, not a
    bool) in [`lo`, `hi`]: for the integer settings (loop counts, buffer sizes). A 0-d
    integer array counts as an integer; a traced value passes unchecked."""
    if not is_concrete(value):
        return
    if isinstance(value, (jax.Array, np.ndarray)) and value.ndim == 0 and jnp.issubdtype(value.dtype, jnp.integer):
        value = int(value)
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    if value < lo or (hi is not None and value > hi):
        rng = f">= {lo}" if hi is None else f"in [{lo}, {hi}]"
        raise ValueError(f"{name} must be an integer {rng}, got {value!r}")


def check_bool(name: str, value) -> None:
    """Raise `ValueError` naming `name` unless `value` is a bool (a static flag)."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {value!r}")


def check_number(name: str, value, **bounds) -> None:
    """[`check_param`][] for a scalar setting that must be a real number: also rejects a
    bool, a string or None by name (a traced value passes unchecked)."""
    if is_concrete(value) and (isinstance(value, (bool, np.bool_, str, bytes)) or value is None
                               or np.ndim(value) != 0 or not np.isrealobj(value)):
        raise ValueError(f"{name} must be a real number, got {value!r}")
    check_param(name, value, **bounds)


def check_sign(name: str, value) -> None:
    """Raise `ValueError` naming `name` unless a concrete `value` is +1 or -1."""
    if is_concrete(value) and (isinstance(value, (bool, np.bool_, str)) or np.ndim(value) != 0
                               or not np.isrealobj(value) or float(value) not in (1.0, -1.0)):
        raise ValueError(f"{name} must be +1 or -1, got {value!r}")


def default_float():
    """The default floating dtype (float64 only if the user enabled x64)."""
    return jnp.zeros(()).dtype if jnp.zeros(()).dtype.kind == "f" else jnp.float32


def as_float(x, dtype=None):
    return jnp.asarray(x, dtype=dtype if dtype is not None else jnp.result_type(float))


deg = math.pi / 180.0


def run_if(pred, fn, default, operands=()):
    """`fn(*operands)` where `pred`, else `default` (same structure). A while loop of at
    most one pass rather than `lax.cond`: unbatched the two are the same, but under `vmap` a
    cond on a batched predicate becomes a select that runs `fn` for every member every
    time, while this loop runs it only when some member needs it (masked for the others).

    Everything `fn` computes from must reach it through `operands` (a pytree; non-array
    leaves are passed through as they are), not only by closure: inside the loop they pass
    an `optimization_barrier` together with the loop's flag, so XLA cannot see them as
    loop-invariant. Otherwise its while-loop-invariant code motion hoists the whole of `fn`
    (which reads nothing from the loop carry) out of the loop and runs it every time: the
    vmapped phase diagram would then run the homotopy at every gap, not only where a warm
    start fails (`tests/test_run_if.py`)."""
    arrays, static = eqx.partition(operands, eqx.is_array)

    def body(c):
        flag, _, ops = c
        _, ops = jax.lax.optimization_barrier((flag, ops))
        return jnp.zeros((), bool), fn(*eqx.combine(ops, static)), ops

    init = (jnp.asarray(pred, bool), default, arrays)
    return jax.lax.while_loop(lambda c: c[0], body, init)[1]


def package_version() -> str:
    """jaxrod's installed version ("0.0.0" when run from a source tree that is not installed)."""
    import importlib.metadata

    try:
        return importlib.metadata.version("jaxrod")
    except importlib.metadata.PackageNotFoundError:
        return "0.0.0"


@functools.lru_cache(maxsize=1)
def source_digest() -> str:
    """SHA-256 of jaxrod's source (the path and bytes of every `.py` file of the package): the
    key of what the command line's exported programs and `jaxrod reproduce`'s cache hold, so
    that anything computed by other code is not reused."""
    import hashlib
    import pathlib

    root = pathlib.Path(__file__).parent
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(str(path.relative_to(root)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def check_grid(psi0_deg, gaps, s0, what: str):
    """The fold angles (deg) and gaps of a (Psi0, G/L) grid as lists of floats, each value and
    `s0` checked; `what` (the function's name) is named when float64 is not enabled."""
    psis = [float(p) for p in np.atleast_1d(psi0_deg)]
    gs = [float(g) for g in np.atleast_1d(gaps)]
    if not psis or not gs:
        raise ValueError("psi0 and gaps must each hold at least one value")
    for p in psis:
        check_param("psi0", p, lo=0.0, hi=180.0, hi_open=False, unit=" deg")
    for g in gs:
        check_param("gap", g, lo=0.0, hi=1.0)
    check_param("s0", s0, lo=0.0)
    if not jax.config.jax_enable_x64:
        raise ValueError(f"{what} needs float64; enable it with jax.config.update('jax_enable_x64', True)")
    return psis, gs


S0_MAX = 1.0  # fold widths of a phase diagram lie in (0, S0_MAX): below the strip's length L = 1


def fold_widths(s0):
    """The fold widths of a phase diagram: `(widths, axis)`, the widths as floats and whether
    they form an `s0` axis (a list or 1-d array, even of one width) or are one width (a
    scalar: the `(psi0, gap)` grid). Each width must be finite and in (0, `S0_MAX`) (narrower
    than the strip, L = 1), and the widths distinct; `ValueError` naming `s0` otherwise."""
    try:
        arr = np.asarray(s0, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"s0 must be a number or a list of numbers, got {s0!r}") from None
    if arr.ndim > 1:
        raise ValueError(f"s0 must be a number or a one-dimensional list of numbers, got shape {arr.shape}")
    widths = [float(v) for v in np.atleast_1d(arr)]
    if not widths:
        raise ValueError("s0 must hold at least one value")
    for v in widths:
        check_param("s0", v, lo=0.0, hi=S0_MAX)
    if len(set(widths)) != len(widths):
        raise ValueError(f"s0 values must be distinct, got {', '.join(f'{v:g}' for v in widths)}")
    return widths, arr.ndim == 1
