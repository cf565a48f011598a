"""jaxrod's jit: XLA options at the top level, the plain jit inside any JAX transformation."""

import contextlib
import os
import re

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from jaxrod._misc import jit


def _sqrt(a):
    """sqrt(a) by 30 Newton steps in a loop (the kind of program the options target)."""
    return lax.fori_loop(0, 30, lambda _, x: 0.5 * (x + a / x), jnp.ones_like(a))


_newton_sqrt = jit(_sqrt)


def test_top_level_and_under_every_transformation():
    """The same values called eagerly, under jit, vmap, grad and scan (JAX refuses compiler
    options on a nested jit and under an eager grad: the wrapper must not pass them there)."""
    a = jnp.asarray(2.0)
    ref = float(jnp.sqrt(a))
    np.testing.assert_allclose(_newton_sqrt(a), ref, rtol=1e-15)
    np.testing.assert_allclose(jax.jit(_newton_sqrt)(a), ref, rtol=1e-15)
    np.testing.assert_allclose(jax.vmap(_newton_sqrt)(jnp.array([2.0, 9.0])), [ref, 3.0], rtol=1e-15)
    np.testing.assert_allclose(jax.grad(_newton_sqrt)(a), 0.5 / ref, rtol=1e-12)
    _, ys = lax.scan(lambda c, x: (c, _newton_sqrt(x)), 0.0, jnp.array([4.0, 16.0]))
    np.testing.assert_allclose(ys, [2.0, 4.0], rtol=1e-15)


def _invariant_loop(a, x0):
    def body(c):
        x, k = c
        return x + jnp.sin(a) * jnp.cos(a), k + 1

    return lax.while_loop(lambda c: c[1] < c[0], body, (x0, 0))[0]


def _sine_in_loop_body(compiled_text):
    """Whether the (single) while loop's body computes the sine, directly or in a fusion."""
    comps = {m.group(1): m.group(2) for m in re.finditer(r"\n(%?[\w.\-]+) \([^\n]*\{\n(.*?)\n\}", compiled_text, re.S)}
    (body,) = re.findall(r"body=(%?[\w.\-]+)", compiled_text)
    called = re.findall(r"calls=(%?[\w.\-]+)", comps[body])
    return "sine" in comps[body] or any("sine" in comps.get(c, "") for c in called)


def test_options_reach_the_compiler():
    """With jaxrod's options XLA's loop-invariant code motion is off: a loop-invariant sine
    stays in the loop body, where XLA's defaults hoist it out. The ahead-of-time path
    (`.lower(...).compile()`) carries them too and gives the same values."""
    args = (jnp.asarray(2.0), jnp.asarray(3.0))
    ours = jit(_invariant_loop).lower(*args).compile()
    default = eqx.filter_jit(_invariant_loop).lower(*args).compile()
    assert _sine_in_loop_body(ours.compiled.as_text())
    assert not _sine_in_loop_body(default.compiled.as_text())
    np.testing.assert_allclose(ours(*args), default(*args), rtol=1e-15)
    called = jit(_invariant_loop)  # the call path's program, in every compile mode
    for mode in ("auto", "fast", "optimized"):
        with _env("JAXROD_COMPILE", mode):
            np.testing.assert_allclose(called(*args), default(*args), rtol=1e-15)
            assert _sine_in_loop_body(_program(called, *args).compiled.as_text())


def _program(f, *args, **kwargs):
    from jaxrod._misc import _signature

    return f.programs.table[_signature(args, kwargs)].compiled


@contextlib.contextmanager
def _env(name, value):
    old = os.environ.get(name)
    os.environ[name] = value
    try:
        yield
    finally:
        if old is None:
            os.environ.pop(name)
        else:
            os.environ[name] = old


def test_compile_modes(monkeypatch):
    """JAXROD_COMPILE: "auto" (the default) and "fast" compile the first tier with
    FAST_COMPILE_OPTIONS, "optimized" with COMPILER_OPTIONS alone; the same values in every
    mode; a bad value is one ValueError naming the variable, and the CLI's exit 2."""
    from jaxrod._misc import COMPILER_OPTIONS, FAST_COMPILE_OPTIONS, compile_mode, compiler_options
    from jaxrod.cli import main

    a = jnp.asarray(2.0)
    monkeypatch.delenv("JAXROD_COMPILE", raising=False)
    assert compile_mode() == "auto"
    fast = {**COMPILER_OPTIONS, **FAST_COMPILE_OPTIONS}
    assert compiler_options() == fast
    ref = float(_newton_sqrt(a))
    monkeypatch.setenv("JAXROD_COMPILE", "optimized")
    assert compiler_options() == COMPILER_OPTIONS
    assert float(_newton_sqrt(a)) == ref
    monkeypatch.setenv("JAXROD_COMPILE", "fast")
    assert compiler_options() == fast
    assert float(_newton_sqrt(a)) == ref
    monkeypatch.setenv("JAXROD_COMPILE", "quick")
    try:
        _newton_sqrt(a)
    except ValueError as e:
        assert "JAXROD_COMPILE" in str(e) and "'quick'" in str(e)
    else:
        raise AssertionError("no ValueError")
    assert main(["equilibrium", "--n", "8", "--json"]) == 2


def _tier(f, *args, **kwargs):
    from jaxrod._misc import _signature

    return f.programs.table[_signature(args, kwargs)].tier


def test_auto_mode_tiers_up_after_enough_run_time(monkeypatch):
    """In the "auto" mode a program is compiled with the fast code generation and runs from
    it until its calls have run for TIER_UP_FACTOR times that compile, then is compiled with
    the optimizing one on a thread of its own, which replaces it when done (same values);
    "optimized" compiles it optimized at once, and
    "fast" never tiers up. A new static value or weak type is a new program."""
    from jaxrod import _misc

    monkeypatch.delenv("JAXROD_COMPILE", raising=False)
    f = jit(_sqrt)
    a = jnp.asarray(3.0)
    ref = float(f(a))
    assert _tier(f, a) == "fast"
    prog = f.programs.table[_misc._signature((a,), {})]
    assert prog.run_s > 0 and prog.compile_s > 0
    monkeypatch.setenv("JAXROD_COMPILE", "fast")
    monkeypatch.setattr(_misc, "TIER_UP_FACTOR", 0.0)
    assert float(f(a)) == ref and _tier(f, a) == "fast"
    monkeypatch.delenv("JAXROD_COMPILE")
    fast = prog.compiled
    assert float(f(a)) == ref  # the fast program's value; the optimized compile starts on a thread
    assert prog.tier_up is not None and prog.tier_up.name == "jaxrod-tier-up" and not prog.tier_up.daemon
    prog.wait()
    assert _tier(f, a) == "optimized" and prog.compiled is not fast
    assert float(f(a)) == ref  # from the optimized program
    f(a)
    assert prog.compiled is not fast and _tier(f, a) == "optimized"  # no second tier-up
    monkeypatch.setattr(_misc, "TIER_UP_FACTOR", 1e9)
    b = jnp.asarray(np.float64(3.0), dtype=jnp.float64)
    w = jnp.asarray(3.0)  # weak-typed (a Python float)
    assert not b.weak_type and w.weak_type
    f(b)
    assert _tier(f, b) == "fast" and len(f.programs.table) == 2
    g = jit(lambda x, k: x * k)
    assert float(g(a, 2.0)) == 6.0 and float(g(a, 3.0)) == 9.0 and float(g(a, 3)) == 9.0
    assert len(g.programs.table) == 3  # 2.0, 3.0 and the integer 3 are three static values
    monkeypatch.setenv("JAXROD_COMPILE", "optimized")
    h = jit(_sqrt)
    h(a)
    assert _tier(h, a) == "optimized"


def test_prepare_and_program_beside(monkeypatch):
    """`.prepare` compiles without running, and a call then reuses that program; `with_program_beside` returns what `make()` returns and leaves
    the program compiled for the arguments that its result gives."""
    from jaxrod import _misc

    monkeypatch.delenv("JAXROD_COMPILE", raising=False)
    monkeypatch.setattr(_misc, "TIER_UP_FACTOR", 1e9)
    f = jit(_sqrt)
    a = jnp.asarray(5.0)
    f.prepare(a)
    prog = f.programs.table[_misc._signature((a,), {})]
    compiled = prog.compiled
    assert compiled is not None and prog.run_s == 0.0
    assert float(f(a)) == float(np.sqrt(5.0)) and prog.compiled is compiled

    double = jit(lambda x: 2.0 * x)
    monkeypatch.setattr(_misc.os, "sched_getaffinity", lambda _: {0, 1}, raising=False)
    x = jnp.arange(4.0)
    x = x + 1.0
    made = _misc.with_program_beside(lambda: double(x), _newton_sqrt, lambda y: ((y,), {}))
    np.testing.assert_array_equal(made, 2.0 * x)
    prog = _newton_sqrt.programs.table[_misc._signature((made,), {})]
    assert prog.compiled is not None and prog.run_s == 0.0  # compiled beside, not run
    np.testing.assert_allclose(_newton_sqrt(made), np.sqrt(2.0 * np.arange(1.0, 5.0)), rtol=1e-15)
    # a `make` that needs concrete values (no abstract trace): it runs alone
    concrete = _misc.with_program_beside(lambda: float(x[1]) * 2.0, _newton_sqrt, lambda y: ((y,), {}))
    assert concrete == 4.0
    assert not _misc.TRACING._is_owned()


def test_dynamics_programs_keep_xla_loop_passes(monkeypatch):
    """The dynamics' jit compiles with XLA's defaults when optimized (the loop-invariant sine
    hoisted out of the loop, as without jaxrod's options), with FAST_COMPILE_OPTIONS alone
    when fast (the first tier of the default mode); the same values either way, through
    `.lower` and through the call."""
    from jaxrod._misc import FAST_COMPILE_OPTIONS, compiler_options, dynamics_jit

    args = (jnp.asarray(2.0), jnp.asarray(3.0))
    loop = dynamics_jit(_invariant_loop)
    monkeypatch.setenv("JAXROD_COMPILE", "optimized")
    assert compiler_options(dynamics=True) == {}
    ref = float(loop(*args))
    assert not _sine_in_loop_body(loop.lower(*args).compile().compiled.as_text())
    assert not _sine_in_loop_body(_program(loop, *args).compiled.as_text())
    for mode in ("fast", "auto"):
        monkeypatch.setenv("JAXROD_COMPILE", mode)
        assert compiler_options(dynamics=True) == FAST_COMPILE_OPTIONS
        assert not _sine_in_loop_body(loop.lower(*args).compile().compiled.as_text())
        assert float(loop(*args)) == ref


def test_concurrently_runs_calls_in_threads_and_keeps_their_meaning(monkeypatch):
    """`concurrently`: results in order; calls on other threads where the machine has cores
    (each program runs on its caller's thread); a worker without the caller's thread-local
    JAX configuration hands its call back; exceptions reach the caller; under a
    transformation (or on one core) the calls run one after the other on the caller's
    thread."""
    import threading

    from jaxrod import _misc

    monkeypatch.setattr(_misc.os, "sched_getaffinity", lambda _: {0, 1}, raising=False)
    monkeypatch.setattr(_misc.os, "cpu_count", lambda: 2)
    a = jnp.asarray(2.0)
    names = []

    def call(x):
        names.append(threading.current_thread().name)
        return _newton_sqrt(x)

    r = _misc.concurrently(lambda: call(a), lambda: call(a + 7.0), lambda: call(a + 14.0))
    np.testing.assert_allclose(r, [np.sqrt(2.0), 3.0, 4.0], rtol=1e-15)
    assert threading.current_thread().name in names  # the first call ran on the caller's thread ...
    assert len(set(names)) >= 2, names  # ... and the others on worker threads
    # a thread-local configuration is honoured: the worker gives the call back
    with jax.enable_x64(False):
        dtypes = _misc.concurrently(lambda: jnp.ones(2).dtype, lambda: jnp.ones(2).dtype)
    assert dtypes == (jnp.float32, jnp.float32)
    with jax.enable_x64(True):
        assert _misc.concurrently(lambda: jnp.ones(2).dtype, lambda: jnp.ones(2).dtype) == (jnp.float64,) * 2

    def fails():
        raise ValueError("psi0 must be finite")

    try:
        _misc.concurrently(lambda: 1, fails)
    except ValueError as e:
        assert "psi0" in str(e)
    else:
        raise AssertionError("the worker's exception did not reach the caller")
    # nested: a call on a worker thread runs its own calls there, one after the other
    inner = _misc.concurrently(lambda: 0, lambda: _misc.concurrently(
        lambda: threading.current_thread().name, lambda: threading.current_thread().name))[1]
    assert inner[0] == inner[1] and inner[0].startswith("jaxrod-worker"), inner
    # under jit: one thread, and the values are those of the plain calls
    names.clear()
    out = jax.jit(lambda x: jnp.stack(_misc.concurrently(lambda: call(x), lambda: call(x + 7.0))))(a)
    np.testing.assert_allclose(out, [np.sqrt(2.0), 3.0], rtol=1e-15)
    assert set(names) == {threading.current_thread().name}
    # one core: one thread
    monkeypatch.setattr(_misc.os, "sched_getaffinity", lambda _: {0}, raising=False)
    names.clear()
    _misc.concurrently(lambda: call(a), lambda: call(a))
    assert set(names) == {threading.current_thread().name}


def test_clear_caches_releases_jaxrods_programs():
    """`jaxrod.clear_caches()` empties every jitted function's program table (and JAX's
    caches); the next call compiles again, to the same value."""
    import jaxrod

    f = jit(_sqrt)
    a = jnp.asarray(7.0)
    ref = float(f(a))
    assert len(f.programs.table) == 1
    jaxrod.clear_caches()
    assert len(f.programs.table) == 0
    assert float(f(a)) == ref and len(f.programs.table) == 1
