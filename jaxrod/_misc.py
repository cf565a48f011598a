"""Small helpers: input validation on concrete values and dtype handling."""

from __future__ import annotations

import functools
import math
import os
import threading

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np


COMPILER_OPTIONS = {
    "xla_disable_hlo_passes": "while-loop-invariant-code-motion,simplify-while-loops",
}
"""XLA options of the statics and branch entry points on the CPU (`jit`). The two passes are
disabled because they are the slowest of XLA's HLO optimizations on those programs, which are
deep nests of small while loops (Newton, continuation, bisection), and they buy nothing
measurable at run time there: `snap_angles` at N = 100 on a 2-core CPU compiles in 8.6 s
instead of 12 s and runs no slower (`benchmarks/bench_compile.py` has the table for every entry
point). The dynamics keep XLA's defaults: their step loops ran 20-45 % slower without the
passes. Loop-invariant code motion also hoisted whole inner solves out of the one-pass loops
of `run_if`, which then ran for every member of a batch."""


def _top_level() -> bool:
    """Whether no JAX transformation is tracing now. Under `jit` or a control-flow primitive
    a jitted callee is inlined into the caller's program (which carries the options); under
    an eager `grad` or `vmap`, JAX traces it into a jaxpr too and refuses options there."""
    try:
        from jax._src.core import trace_state_clean
    except ImportError:  # a JAX without it: no options rather than an error
        return False
    return trace_state_clean()


_POOL = None
_MISMATCH = object()
_WORKER_PREFIX = "jaxrod-worker"


def _trace_context():
    """JAX's thread-local configuration (`jax.enable_x64` and the other context managers),
    or None for a JAX without that accessor."""
    try:
        from jax._src.config import trace_context
    except ImportError:
        return None
    return trace_context()


def _in_worker(call, context):
    if context is None or _trace_context() != context:
        return _MISMATCH  # a thread-local setting of the caller's that this thread lacks
    return call()


def concurrently(*calls):
    """The results of the zero-argument `calls`, in order, computed concurrently where that
    is safe and useful: at the top level (no JAX transformation tracing) on a machine with
    more than one core, the first on the calling thread and each other on a worker thread.

    XLA:CPU runs the thunks of one program one after the other on the thread that calls it,
    and runs two independent computations inside one program one after the other too, so
    two independent programs (the coarse and the fine mesh of
    [`jaxrod.snap_angles_extrapolated`][]) take the time of the slower one instead of the sum
    this way. (Their first calls also compile side by side, which on a 2-core machine gains
    little: XLA's compiler keeps both cores busy already.) A worker whose thread-local JAX
    configuration differs from the caller's (a `with jax.enable_x64(...)` block is
    thread-local) hands its call back to the calling thread; under a transformation, with one
    core, or on a worker thread itself (no nested use of the pool), the calls run one after
    the other. Exceptions reach the caller as they would from a plain call."""
    global _POOL

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    if (len(calls) < 2 or cores < 2 or not _top_level()
            or threading.current_thread().name.startswith(_WORKER_PREFIX)):
        return tuple(call() for call in calls)
    if _POOL is None:
        import concurrent.futures

        _POOL = concurrent.futures.ThreadPoolExecutor(max_workers=3, thread_name_prefix=_WORKER_PREFIX)
    context = _trace_context()
    futures = [_POOL.submit(_in_worker, call, context) for call in calls[1:]]
    first = calls[0]()
    rest = [f.result() for f in futures]
    return (first,) + tuple(call() if r is _MISMATCH else r for call, r in zip(calls[1:], rest))


TRACING = threading.Lock()
"""Held while a first call's program is traced and lowered (pure Python, under the GIL):
[`lowered_first`][] and the CLI's exports take it, so that of two first calls on two threads
one compiles (XLA, off the GIL) while the other traces."""
_LOWERED = set()


def lowered_first(fun, key, *args, **kwargs):
    """`fun(*args, **kwargs)` for a jitted `fun` (with `.lower`), traced and lowered under a
    process-wide lock before its first call for `key` at the top level (a hashable that stands
    for the arguments' structure and options; it decides only whether to lower first).

    Tracing and lowering are Python, under the GIL; XLA's compile runs off it. Two first
    calls on two threads ([`concurrently`][]) then trace one after the other, and the first
    compiles while the second traces, instead of both tracing at half speed: the first call of
    `jaxrod.snap_angles_extrapolated` at N = 100 + 200 takes 16.2-16.3 s instead of 17.3 s on 2
    cores. The call itself reuses the lowering. Later calls for `key` skip the lock (a warm
    `.lower` costs about 0.2 ms)."""
    if key not in _LOWERED and _top_level():
        with TRACING:
            fun.lower(*args, **kwargs)
        _LOWERED.add(key)
    return fun(*args, **kwargs)


FAST_COMPILE_OPTIONS = {"xla_backend_optimization_level": 0, "xla_cpu_use_fusion_emitters": False}
"""Added to `COMPILER_OPTIONS` in the "fast" compile mode (`compile_mode`): LLVM at -O0 and
XLA's older loop emitters instead of its MLIR fusion emitters, whose own lowering pipeline is
most of the compile time at -O0. The same IEEE operations (no fast-math), so the same results
to round-off; measured on 2 cores for `snap_angles` at N = 100: 3.1 s of compile instead of
7.1 s, 0.096 s per call instead of 0.049 s. The dynamics' programs (`dynamics_jit`) take
these options alone in the fast mode (a brink `snap_dynamics` at N = 100: 6.5 s of trace and
compile instead of 9.1 s, 1.1 s of run instead of 0.3 s). Worth it for one-off queries; sweeps
and benchmarks want the default."""


def compile_mode() -> str:
    """"optimized" (XLA's default code generation, the default) or "fast" (less compile time,
    slower code: `FAST_COMPILE_OPTIONS`), from the environment variable `JAXROD_COMPILE`, read
    at every call so that a process can switch."""
    mode = os.environ.get("JAXROD_COMPILE", "optimized")
    if mode not in ("optimized", "fast"):
        raise ValueError(f"JAXROD_COMPILE: must be 'optimized' or 'fast', got {mode!r}")
    return mode


def compiler_options(dynamics: bool = False, mode: str | None = None) -> dict:
    """`COMPILER_OPTIONS` (plus `FAST_COMPILE_OPTIONS` in the "fast" `compile_mode`) where
    JAX's default backend is the CPU (where they were measured), XLA's defaults on
    accelerators. `dynamics`: the options of the dynamics' programs, XLA's defaults in the
    "optimized" mode (their step loops run slower without the disabled passes) and
    `FAST_COMPILE_OPTIONS` alone in the "fast" one. `mode`: the compile mode, default
    `compile_mode()`."""
    if jax.default_backend() != "cpu":
        return {}
    fast = (compile_mode() if mode is None else mode) == "fast"
    if dynamics:
        return dict(FAST_COMPILE_OPTIONS) if fast else {}
    return {**COMPILER_OPTIONS, **FAST_COMPILE_OPTIONS} if fast else COMPILER_OPTIONS


def jit(fun, *, dynamics: bool = False):
    """`equinox.filter_jit` with jaxrod's XLA options (`compiler_options(dynamics)`, one
    compiled variant per compile mode) where the call is not inside a JAX transformation;
    inside one (where JAX allows no options) the plain `equinox.filter_jit`, so an eager
    `jax.grad` or `jax.vmap` of an entry point compiles with XLA's defaults. `.lower` picks
    the same way."""
    plain = eqx.filter_jit(fun)
    variants = {}

    def pick():
        if not _top_level():
            return plain
        mode = compile_mode()
        opts = compiler_options(dynamics, mode)
        if not opts:
            return plain
        if mode not in variants:
            variants[mode] = eqx.filter_jit(fun, compiler_options=opts)
        return variants[mode]

    @functools.wraps(fun)
    def wrapper(*args, **kwargs):
        return pick()(*args, **kwargs)

    wrapper.lower = lambda *args, **kwargs: pick().lower(*args, **kwargs)
    return wrapper


def dynamics_jit(fun):
    """[`jit`][] for the dynamics' programs: XLA's defaults, or `FAST_COMPILE_OPTIONS` in the
    "fast" compile mode."""
    return jit(fun, dynamics=True)


def traced_once(fun):
    """`fun` as a nested jit (`equinox.filter_jit`) for the energy's building blocks, which a
    solver program calls at many sites (Newton, corrector, bisection, landing, refinement):
    JAX traces and lowers a jitted callee once per argument signature and reuses it at every
    other site (XLA inlines it again, so the compiled program is the same). Tracing them at
    every site was most of the lowering time: with self-contact, `snap_angles` traced the
    contact Hessian 22 times (14 of its 28 s of tracing and lowering under a profiler)."""
    return eqx.filter_jit(fun)


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
    (which reads nothing from the loop carry) out of the loop and runs it every time: that
    made the vmapped phase diagram run the homotopy at every gap (measured 0.2 s per gap at
    5 Psi0, N = 100, instead of 3 ms)."""
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
