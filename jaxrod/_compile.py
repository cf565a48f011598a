r"""How jaxrod's entry points are compiled: `equinox.filter_jit` with XLA options, and a
rent-or-buy switch from a fast code generation to XLA's optimizing one.

An entry point (`jit`) is `equinox.filter_jit` of a plain function. Called at the top level
on the CPU (no JAX transformation tracing it), it runs one of two variants of that function,
each an `equinox.filter_jit` with its own XLA options (`compiler_options`):

- *fast*: `COMPILER_OPTIONS` plus `FAST_COMPILE_OPTIONS` (LLVM at -O0): about half the
  compile and twice the run of
- *optimized*: `COMPILER_OPTIONS` alone, XLA's optimizing code generation.

`JAXROD_COMPILE` (read at every call) picks the variant: "fast", "optimized", or "auto" (the
default), which runs the fast variant until the calls of one argument signature have run for
`TIER_UP_FACTOR` times their first call (trace, compile and run), then the optimized one
(compiled on that call). A one-off query pays the short compile, a sweep the short runs, and
either way the total is at most about twice what the better choice would have cost in
hindsight (the rent-or-buy rule).

Inside a transformation (`jax.jit`, `jax.vmap`, `jax.grad`, a control-flow body) JAX allows
no compiler options on a nested jit: there the entry point is the plain `equinox.filter_jit`,
inlined into the caller's program, which carries the caller's options. So is every call on
an accelerator, where XLA's defaults are used.

Compile latency across processes comes from JAX's persistent compilation cache
(`jax_compilation_cache_dir`), which the command line turns on.
"""

from __future__ import annotations

import functools
import os
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np


COMPILER_OPTIONS = {
    "xla_disable_hlo_passes": "while-loop-invariant-code-motion,simplify-while-loops",
}
"""XLA options of the statics and branch entry points on the CPU. The two passes are disabled
because they are the slowest of XLA's HLO optimizations on those programs, which are deep
nests of small while loops (Newton, continuation, bisection), and buy nothing measurable at
run time there (`benchmarks/bench_compile.py` has the table for every entry point). The
dynamics keep XLA's defaults: their step loops run slower without the passes. Loop-invariant
code motion also hoists whole inner solves out of the one-pass loops of `run_if`, which then
run for every member of a batch."""

FAST_COMPILE_OPTIONS = {"xla_backend_optimization_level": 0, "xla_cpu_use_fusion_emitters": False}
"""Added to `COMPILER_OPTIONS` for the fast code generation: LLVM at -O0 and XLA's older loop
emitters instead of its MLIR fusion emitters, whose own lowering pipeline is most of the
compile time at -O0. The same IEEE operations (no fast-math), so the same results to
round-off (`benchmarks/results/compile*.md` has both code generations' times). The
dynamics' programs (`dynamics_jit`) take these options alone."""

COMPILE_MODES = ("auto", "fast", "optimized")

TIER_UP_FACTOR = 5.0
"""In the "auto" compile mode, the calls of one argument signature switch from the fast to
the optimized variant once they have run for `TIER_UP_FACTOR` times their first call. The
optimized compile costs a few times the fast one and saves about half of each run, so it
pays for itself after about five compiles' worth of fast runs
(`benchmarks/results/compile_fast.md` and `compile_optimized.md` have both code
generations' times)."""

MAX_SIGNATURES = 256
"""Argument signatures whose run time an entry point keeps account of in the "auto" mode (the
oldest are forgotten first: a forgotten signature starts again on the fast variant)."""


def compile_mode() -> str:
    """The compile mode from the environment variable `JAXROD_COMPILE` ("auto", the default,
    "fast" or "optimized"; module docstring), read at every call so that a process can switch."""
    mode = os.environ.get("JAXROD_COMPILE", "auto")
    if mode not in COMPILE_MODES:
        raise ValueError(f"JAXROD_COMPILE: must be one of {', '.join(COMPILE_MODES)}, got {mode!r}")
    return mode


def compiler_options(dynamics: bool = False, mode: str | None = None) -> dict:
    """XLA options of a program on the CPU for the code generation of `mode` (default
    `compile_mode()`; "auto" starts fast): `COMPILER_OPTIONS`, plus `FAST_COMPILE_OPTIONS`
    when fast. `dynamics`: the dynamics' programs, XLA's defaults when optimized and
    `FAST_COMPILE_OPTIONS` alone when fast. XLA's defaults on accelerators."""
    if jax.default_backend() != "cpu":
        return {}
    fast = (compile_mode() if mode is None else mode) in ("fast", "auto")
    if dynamics:
        return dict(FAST_COMPILE_OPTIONS) if fast else {}
    return {**COMPILER_OPTIONS, **FAST_COMPILE_OPTIONS} if fast else dict(COMPILER_OPTIONS)


def at_top_level(args=()) -> bool:
    """Whether no JAX transformation is tracing now: no leaf of `args` is a tracer, and a
    constant made now is not one (under `jax.jit` or a control-flow body every new array is
    staged into the traced program)."""
    if isinstance(jnp.zeros(()), jax.core.Tracer):
        return False
    return not any(isinstance(x, jax.core.Tracer) for x in jax.tree.leaves(args))


def _signature(args, kwargs):
    """A hashable stand-in for what an `equinox.filter_jit` program depends on: the arrays'
    structure, shapes, dtypes and weak types, the other (static) leaves by type and value,
    and whether 64-bit types are on; None where a static leaf is not hashable."""
    dynamic, static = eqx.partition((args, kwargs), eqx.is_array)
    arrays, arrays_tree = jax.tree.flatten(dynamic)
    leaves, static_tree = jax.tree.flatten(static)
    key = (arrays_tree, tuple((np.shape(x), np.dtype(x.dtype).name, bool(getattr(x, "weak_type", False)))
                              for x in arrays),
           static_tree, tuple((type(x), x) for x in leaves), bool(jax.config.jax_enable_x64))
    try:
        hash(key)
    except TypeError:
        return None
    return key


class _Account:
    """What one argument signature's calls have cost in the "auto" mode: its first call
    (trace, compile and run of the fast variant) and the run time of the calls after it."""

    __slots__ = ("first_s", "run_s", "optimized")

    def __init__(self):
        self.first_s, self.run_s, self.optimized = None, 0.0, False


class EntryPoint:
    """What [`jit`][] returns: a callable with `lower` (JAX's ahead-of-time path, with the
    options of the compile mode's first variant). The methods live on the class, not the
    instance: JAX's transformations copy a function's `__dict__` onto what they return
    (`functools.wraps`), and an instance attribute `lower` would hide the `.lower` of
    `jax.jit(jax.vmap(entry))`."""

    def __init__(self, fun, dynamics: bool):
        functools.update_wrapper(self, fun)
        self._fun, self._dynamics = fun, dynamics
        self._plain = eqx.filter_jit(fun)
        self._variants = {}
        self._accounts = {}

    def _variant(self, mode):
        """The `equinox.filter_jit` of the code generation of `mode` ("fast" or "optimized")."""
        if mode not in self._variants:
            opts = compiler_options(self._dynamics, mode)
            self._variants[mode] = eqx.filter_jit(self._fun, compiler_options=opts) if opts else self._plain
        return self._variants[mode]

    def __call__(self, *args, **kwargs):
        if jax.default_backend() != "cpu" or not at_top_level((args, kwargs)):
            return self._plain(*args, **kwargs)
        mode = compile_mode()
        if mode != "auto":
            return self._variant(mode)(*args, **kwargs)
        key = _signature(args, kwargs)
        if key is None:
            return self._variant("fast")(*args, **kwargs)
        account = self._accounts.pop(key, None) or _Account()
        self._accounts[key] = account  # most recently used last
        while len(self._accounts) > MAX_SIGNATURES:
            del self._accounts[next(iter(self._accounts))]
        if account.optimized:
            return self._variant("optimized")(*args, **kwargs)
        t0 = time.perf_counter()
        out = jax.block_until_ready(self._variant("fast")(*args, **kwargs))
        spent = time.perf_counter() - t0
        if account.first_s is None:
            account.first_s = spent
        else:
            account.run_s += spent
            account.optimized = account.run_s >= TIER_UP_FACTOR * account.first_s
        return out

    def lower(self, *args, **kwargs):
        """JAX's ahead-of-time lowering (`.compile()` then gives the program), with the options
        of the compile mode's first variant at the top level on the CPU."""
        if jax.default_backend() != "cpu" or not at_top_level((args, kwargs)):
            return self._plain.lower(*args, **kwargs)
        mode = compile_mode()
        return self._variant("optimized" if mode == "optimized" else "fast").lower(*args, **kwargs)

    def variant_of(self, *args, **kwargs) -> str:
        """The code generation ("fast" or "optimized") that a call with these arguments runs
        at the top level on the CPU now."""
        mode = compile_mode()
        if mode != "auto":
            return mode
        account = self._accounts.get(_signature(args, kwargs))
        return "optimized" if account is not None and account.optimized else "fast"

    def forget(self):
        """Forget the run time of every argument signature (`clear_caches`)."""
        self._accounts.clear()

    def __repr__(self):
        return f"<jaxrod entry point {getattr(self, '__qualname__', self._fun)}>"


_ENTRY_POINTS = []


def jit(fun, *, dynamics: bool = False) -> EntryPoint:
    """`equinox.filter_jit` of `fun` with jaxrod's XLA options and compile mode (module
    docstring). `dynamics`: XLA's defaults for the optimizing code generation (the dynamics'
    step loops run slower without the passes `COMPILER_OPTIONS` disables)."""
    entry = EntryPoint(fun, dynamics)
    _ENTRY_POINTS.append(entry)
    return entry


def dynamics_jit(fun) -> EntryPoint:
    """[`jit`][] for the dynamics' programs."""
    return jit(fun, dynamics=True)


def traced_once(fun):
    """`fun` as a nested jit (`equinox.filter_jit`) for the energy's building blocks, which a
    solver program calls at many sites (Newton, corrector, bisection, landing, refinement):
    JAX traces and lowers a jitted callee once per argument signature and reuses it at every
    other site (XLA inlines it again, so the compiled program is the same)."""
    return eqx.filter_jit(fun)


def clear_caches():
    """Release the compiled programs of jaxrod and JAX (`jax.clear_caches`): the next call of
    each entry point traces and compiles again, on the fast variant in the "auto" mode. A
    process that compiles thousands of distinct programs (many meshes) can reach Linux's limit
    on memory mappings without it (docs/limitations.md)."""
    jax.clear_caches()
    for entry in _ENTRY_POINTS:
        entry.forget()
