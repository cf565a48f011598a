"""Small helpers: input validation on concrete values and dtype handling."""

from __future__ import annotations

import contextlib
import functools
import logging
import math
import os
import threading
import time

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


def _cores() -> int:
    """The cores this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


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

    if (len(calls) < 2 or _cores() < 2 or not _top_level()
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


TRACING = threading.RLock()
"""Held while a program is traced and lowered (pure Python, under the GIL): [`jit`][]'s
programs and the CLI's exports take it, so that of two first calls on two threads (the two
meshes of `jaxrod.snap_angles_extrapolated`) one compiles (XLA, off the GIL) while the
other traces, instead of both tracing at half speed: the first call of
`snap_angles_extrapolated` at N = 100 + 200 takes 16.2-16.3 s instead of 17.3 s on 2 cores
(at XLA's optimizing code generation). Reentrant: a lowering may start another."""


FAST_COMPILE_OPTIONS = {"xla_backend_optimization_level": 0, "xla_cpu_use_fusion_emitters": False}
"""Added to `COMPILER_OPTIONS` for a program's fast code generation (`compile_mode`): LLVM at
-O0 and XLA's older loop emitters instead of its MLIR fusion emitters, whose own lowering
pipeline is most of the compile time at -O0. The same IEEE operations (no fast-math), so the
same results to round-off; `snap_angles` at N = 100 on 2 cores compiles in about 2 s instead
of 4.7 s and runs in 0.047 s instead of 0.026 s (`benchmarks/results/compile*.md`). The
dynamics' programs (`dynamics_jit`) take these options alone."""

COMPILE_MODES = ("auto", "fast", "optimized")

TIER_UP_FACTOR = 5.0
"""In the "auto" compile mode a program compiled with the fast code generation is compiled
again with XLA's optimizing one once its calls have run for `TIER_UP_FACTOR` times its fast
compile. Measured at N = 100 on 2 cores, the optimized compile costs 2.5-3.3x the fast one
(`snap_angles` 2.0 -> 5.0 s, `simulate` 0.58 -> 1.9 s) and saves about half of each run
(0.045 -> 0.023 s, 0.6 -> 0.3 s), so it pays for itself once the fast program has run for
about five of its compiles; tiering up then (the rent-or-buy rule) costs at most about twice
what the better of the two choices would have cost in hindsight."""


def compile_mode() -> str:
    """How jaxrod's jitted programs are compiled on the CPU, from the environment variable
    `JAXROD_COMPILE`, read at every call so that a process can switch:

    - "auto" (the default): tiered. Each program (one per function and argument signature)
      is first compiled with the fast code generation (`FAST_COMPILE_OPTIONS`: half the
      compile, about twice the run), and compiled again with XLA's optimizing code
      generation once its calls have run for `TIER_UP_FACTOR` times that first compile, so a
      one-off query pays the short compile and a sweep or a benchmark loop the short runs.
      The second compile runs on a thread of its own; calls use the fast program until it
      is done.
    - "fast": the fast code generation only.
    - "optimized": XLA's optimizing code generation from the first call.

    A program already compiled with the optimizing code generation is kept when the mode
    changes to "fast" or "auto" (its values are the same to round-off)."""
    mode = os.environ.get("JAXROD_COMPILE", "auto")
    if mode not in COMPILE_MODES:
        raise ValueError(f"JAXROD_COMPILE: must be one of {', '.join(COMPILE_MODES)}, got {mode!r}")
    return mode


def compiler_options(dynamics: bool = False, mode: str | None = None) -> dict:
    """XLA options of a program on the CPU: `COMPILER_OPTIONS` in the "optimized" mode, plus
    `FAST_COMPILE_OPTIONS` in the "fast" one (and for the first tier of the "auto" one);
    XLA's defaults on accelerators. `dynamics`: the options of the dynamics' programs, XLA's
    defaults when optimized (their step loops run slower without the disabled passes) and
    `FAST_COMPILE_OPTIONS` alone when fast. `mode`: the compile mode, default
    `compile_mode()`."""
    if jax.default_backend() != "cpu":
        return {}
    fast = (compile_mode() if mode is None else mode) in ("fast", "auto")
    if dynamics:
        return dict(FAST_COMPILE_OPTIONS) if fast else {}
    return {**COMPILER_OPTIONS, **FAST_COMPILE_OPTIONS} if fast else dict(COMPILER_OPTIONS)


def _signature(args, kwargs):
    """A hashable stand-in for what an `equinox.filter_jit` program depends on: the arrays'
    structure, shapes, dtypes and weak types, the other (static) leaves by type and value,
    and JAX's thread-local configuration; None where a static leaf is not hashable."""
    dynamic, static = eqx.partition((args, kwargs), eqx.is_array)
    arrays, arrays_tree = jax.tree.flatten(dynamic)
    leaves, static_tree = jax.tree.flatten(static)
    key = (arrays_tree, tuple((np.shape(x), np.dtype(x.dtype).name, bool(getattr(x, "weak_type", False)))
                              for x in arrays),
           static_tree, tuple((type(x), x) for x in leaves), _trace_context())
    try:
        hash(key)
    except TypeError:
        return None
    return key


class _Program:
    """One compiled program of a jitted function for one argument signature: its executable,
    the code generation it was compiled with ("fast" or "optimized"), how long that compile
    took, how long its calls have run, and the thread that compiles its next tier."""

    __slots__ = ("lowered", "compiled", "tier", "compile_s", "run_s", "tier_up")

    def __init__(self):
        self.lowered, self.compiled, self.tier, self.compile_s, self.run_s = False, None, None, 0.0, 0.0
        self.tier_up = None

    def wait(self):
        """Wait for a tier-up compile in progress (if any)."""
        if self.tier_up is not None:
            self.tier_up.join()


_TABLES = []


def clear_programs():
    """Drop every program compiled through [`jit`][] (what `jax.clear_caches` does for
    JAX's own caches)."""
    for table in _TABLES:
        table.clear()


def clear_caches():
    """Release the compiled programs of jaxrod and JAX (`jax.clear_caches`): the next call
    of each entry point traces and compiles again. A process that compiles thousands of
    distinct programs (many meshes) can reach Linux's limit on memory mappings without it
    (docs/limitations.md)."""
    jax.clear_caches()
    clear_programs()


class _Programs:
    """The compiled programs of one function at the top level, one per argument signature
    (the `MAX_PROGRAMS` most recently used), each lowered once (under `TRACING`) and compiled
    ahead of time with the options of its tier (`compile_mode`)."""

    MAX_PROGRAMS = 64

    def __init__(self, plain, dynamics):
        import collections

        self.plain, self.dynamics = plain, dynamics
        self.table = collections.OrderedDict()
        self.lock = threading.Lock()  # the table's bookkeeping (two threads' first calls)
        _TABLES.append(self.table)

    def _lower(self, prog, args, kwargs):
        # the first lowering under TRACING; later ones are warm (JAX caches them) and skip it
        with (contextlib.nullcontext() if prog.lowered else TRACING):
            lowered = self.plain.lower(*args, **kwargs)
        prog.lowered = True
        return lowered

    def _compile(self, prog, lowered, tier):
        """Compile `lowered` for `tier` and make it `prog`'s program (the fields set together
        at the end, so that a call on another thread sees the old program or the new one)."""
        t0 = time.perf_counter()
        compiled = lowered.compile(compiler_options(self.dynamics, tier))
        prog.compile_s, prog.tier, prog.compiled = time.perf_counter() - t0, tier, compiled

    def entry(self, args, kwargs, mode):
        """The program for `args`, compiled for `mode`; None where the arguments have no
        hashable signature."""
        key = _signature(args, kwargs)
        if key is None:
            return None
        with self.lock:
            prog = self.table.get(key)
            if prog is None:
                prog = self.table[key] = _Program()
                while len(self.table) > self.MAX_PROGRAMS:
                    self.table.popitem(last=False)
            else:
                self.table.move_to_end(key)
        want = "optimized" if mode == "optimized" else "fast"
        if prog.tier is None or (want == "optimized" and prog.tier == "fast"):
            self._compile(prog, self._lower(prog, args, kwargs), want)
        return prog

    def __call__(self, args, kwargs, mode):
        prog = self.entry(args, kwargs, mode)
        if prog is None:
            return _MISMATCH
        t0 = time.perf_counter()
        out = jax.block_until_ready(_run_compiled(prog.compiled, args, kwargs))
        prog.run_s += time.perf_counter() - t0
        if (mode == "auto" and prog.tier == "fast" and prog.tier_up is None
                and prog.run_s >= TIER_UP_FACTOR * prog.compile_s):
            self._tier_up(prog, args, kwargs)
        return out

    def _tier_up(self, prog, args, kwargs):
        """Compile `prog` with the optimizing code generation on a thread of its own (lowered
        here, warm from JAX's cache); calls run the fast program until the optimized one
        replaces it. A compile that fails leaves the fast program in place. The thread is not
        a daemon: a process that ends during a tier-up waits for it (seconds)."""
        lowered = self._lower(prog, args, kwargs)

        def compile_optimized():
            try:
                self._compile(prog, lowered, "optimized")
            except Exception:  # noqa: BLE001 - e.g. out of memory: the fast program stays
                pass

        prog.tier_up = threading.Thread(target=compile_optimized, name="jaxrod-tier-up")
        prog.tier_up.start()


def _run_compiled(compiled, args, kwargs):
    """An ahead-of-time compiled `equinox.filter_jit` program called on `args`, with the
    message of an `equinox.error_if` raised as `equinox.EquinoxRuntimeError` (and JAX's log
    record of the failed callback dropped), as a jitted call raises it."""
    logger = logging.getLogger("jax._src.callback")
    logger.addFilter(_quiet_callback_failure)
    try:
        return compiled(*args, **kwargs)
    except jax.errors.JaxRuntimeError as e:
        text = str(e)
        marker = "_EquinoxRuntimeError: "
        if marker not in text:
            raise
        raise eqx.EquinoxRuntimeError(text.split(marker, 1)[1].split("\n", 1)[0]) from None
    finally:
        logger.removeFilter(_quiet_callback_failure)


def _quiet_callback_failure(record) -> bool:
    """A logging filter that drops JAX's "jax.pure_callback failed" record (with the
    traceback of an `equinox.error_if`, whose message the caller raises instead)."""
    return record.getMessage() != "jax.pure_callback failed"


def jit(fun, *, dynamics: bool = False):
    """`equinox.filter_jit` with jaxrod's XLA options (`compiler_options(dynamics)`) and
    compile mode (`compile_mode`) where the call is not inside a JAX transformation: there
    each argument signature's program is lowered once and compiled ahead of time for its
    tier (`_Programs`; in the default "auto" mode it tiers up from the fast to the
    optimizing code generation). Inside a transformation (where JAX allows no options) the
    plain `equinox.filter_jit`, so an eager `jax.grad` or `jax.vmap` of an entry point
    compiles with XLA's defaults; so does an accelerator backend.

    The wrapper has `.lower(*args, **kwargs)` (JAX's ahead-of-time path with the options of
    the mode's first tier) and `.prepare(*args, **kwargs)`, which traces, lowers and compiles
    the top-level program for those arguments without running it, so that a worker thread
    can prepare one program while the caller compiles another (`with_program_beside`)."""
    return _Entry(fun, dynamics)


def _tiered():
    return _top_level() and jax.default_backend() == "cpu"


class _Entry:
    """What `jit` returns: a callable with `.lower`, `.prepare` and `.programs` as
    methods and a property of its class, not as attributes of the instance. JAX's
    transformations copy a function's `__dict__` onto what they return (`functools.wraps`),
    so an instance attribute `lower` would hide the `.lower` of `jax.jit(jax.vmap(entry))`
    behind the unbatched entry's own."""

    def __init__(self, fun, dynamics):
        functools.update_wrapper(self, fun)
        self._plain = eqx.filter_jit(fun)
        self._fun = fun
        self._dynamics = dynamics
        self._variants = {}
        self._programs = _Programs(self._plain, dynamics)

    def __call__(self, *args, **kwargs):
        if not _tiered():
            return self._plain(*args, **kwargs)
        out = self._programs(args, kwargs, compile_mode())
        return self._plain(*args, **kwargs) if out is _MISMATCH else out

    @property
    def programs(self):
        """The per-signature program table (`_Programs`)."""
        return self._programs

    def lower(self, *args, **kwargs):
        """JAX's ahead-of-time lowering, with the options of the compile mode's first tier."""
        mode = compile_mode()
        opts = compiler_options(self._dynamics, mode) if _top_level() else {}
        if not opts:
            return self._plain.lower(*args, **kwargs)
        if mode not in self._variants:
            self._variants[mode] = eqx.filter_jit(self._fun, compiler_options=opts)
        return self._variants[mode].lower(*args, **kwargs)

    def prepare(self, *args, **kwargs):
        """Trace, lower and compile the top-level program for these arguments, without running it."""
        if _tiered():
            self._programs.entry(args, kwargs, compile_mode())

    def __repr__(self):
        return f"<jaxrod entry point {getattr(self, '__qualname__', self._fun)}>"


def _placeholder(x):
    """A zero array of `x`'s shape, dtype and weak type (a `jax.ShapeDtypeStruct`), or `x`
    itself where it is not one."""
    if not isinstance(x, jax.ShapeDtypeStruct):
        return x
    if getattr(x, "weak_type", False):
        return jnp.broadcast_to(jnp.asarray(np.zeros((), x.dtype).item()), x.shape)
    return jnp.zeros(x.shape, x.dtype)


def with_program_beside(make, program, arguments):
    """`make()`, with `program` (a [`jit`][]-wrapped function) compiled for the arguments
    that `arguments(make())` will give, on a worker thread while `make()` runs: the
    arguments' shapes come from `equinox.filter_eval_shape(make)` (which traces what `make`
    calls, so its own calls then lower from JAX's caches), stood in for by zeros of those
    shapes. On two cores the worker traces `program` (Python, under the GIL) while `make()`
    compiles (XLA, off it): a first `jaxrod.snap_dynamics` overlaps the trace of `simulate`
    with the compile of `snap_angles`. Values are unaffected: the real call of `program`
    looks its compiled program up by its own arguments' signature (a mismatch would compile
    again). Only at the top level (otherwise, with one core, or where `make` cannot be
    traced abstractly, `make()` alone)."""
    if (_cores() < 2 or not _top_level() or jax.default_backend() != "cpu"
            or threading.current_thread().name.startswith(_WORKER_PREFIX)):
        return make()
    try:
        shapes = eqx.filter_eval_shape(make)
    except Exception:  # noqa: BLE001 - only an optimization: make() then runs alone, raising its own errors
        return make()
    args, kwargs = jax.tree.map(_placeholder, arguments(shapes))
    made, _ = concurrently(make, lambda: program.prepare(*args, **kwargs))
    return made


def dynamics_jit(fun):
    """[`jit`][] for the dynamics' programs: XLA's defaults for the optimizing code
    generation, `FAST_COMPILE_OPTIONS` alone for the fast one."""
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
