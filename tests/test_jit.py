"""jaxrod's entry points (`jaxrod._compile`): XLA options at the top level, the plain jit inside
any JAX transformation, the compile modes and the rent-or-buy switch of the default one."""

import contextlib
import os
import re

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from jaxrod import _compile
from jaxrod._compile import jit


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
    """The compiled program that a top-level call of `f` with these arguments runs now."""
    return f._variant(f.variant_of(*args, **kwargs)).lower(*args, **kwargs).compile()


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
    """JAXROD_COMPILE: "auto" (the default) and "fast" start with FAST_COMPILE_OPTIONS,
    "optimized" uses COMPILER_OPTIONS alone; the same values in every mode; a bad value is
    one ValueError naming the variable, and the CLI's exit 2."""
    from jaxrod._compile import COMPILER_OPTIONS, FAST_COMPILE_OPTIONS, compile_mode, compiler_options
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


def test_auto_mode_switches_after_enough_run_time(monkeypatch):
    """In the "auto" mode the calls of one argument signature run the fast variant until they
    have run for TIER_UP_FACTOR times their first call, then the optimized one (same values);
    "optimized" runs the optimized one at once and "fast" never switches. A new static value,
    dtype or weak type is a new signature, accounted apart."""
    monkeypatch.delenv("JAXROD_COMPILE", raising=False)
    f = jit(_sqrt)
    a = jnp.asarray(3.0)
    ref = float(f(a))
    assert f.variant_of(a) == "fast"
    (account,) = f._accounts.values()
    assert account.first_s > 0 and account.run_s == 0.0
    monkeypatch.setattr(_compile, "TIER_UP_FACTOR", 0.0)
    monkeypatch.setenv("JAXROD_COMPILE", "fast")
    assert float(f(a)) == ref and f.variant_of(a) == "fast" and account.run_s == 0.0
    monkeypatch.delenv("JAXROD_COMPILE")
    assert float(f(a)) == ref  # the fast variant's value; its run time reaches the factor ...
    assert account.run_s > 0 and f.variant_of(a) == "optimized"
    assert float(f(a)) == ref  # ... and the next call runs the optimized variant
    assert set(f._variants) == {"fast", "optimized"}
    monkeypatch.setattr(_compile, "TIER_UP_FACTOR", 1e9)
    b = jnp.asarray(np.float64(3.0), dtype=jnp.float64)
    w = jnp.asarray(3.0)  # weak-typed (a Python float)
    assert not b.weak_type and w.weak_type
    f(b)
    assert f.variant_of(b) == "fast" and len(f._accounts) == 2
    g = jit(lambda x, k: x * k)
    assert float(g(a, 2.0)) == 6.0 and float(g(a, 3.0)) == 9.0 and float(g(a, 3)) == 9.0
    assert len(g._accounts) == 3  # 2.0, 3.0 and the integer 3 are three static values
    monkeypatch.setenv("JAXROD_COMPILE", "optimized")
    h = jit(_sqrt)
    h(a)
    assert h.variant_of(a) == "optimized" and set(h._variants) == {"optimized"} and not h._accounts


def test_errors_reach_the_caller_in_every_mode(monkeypatch):
    """An `equinox.error_if` inside an entry point raises `equinox.EquinoxRuntimeError` with
    its message in every compile mode (the default's included), as a plain jit does (the
    suite's EQX_ON_ERROR=nan overridden by `on_error`)."""
    checked = jit(lambda x: eqx.error_if(x, x < 0, "x must not be negative", on_error="raise"))
    for mode in ("auto", "fast", "optimized"):
        monkeypatch.setenv("JAXROD_COMPILE", mode)
        assert float(checked(jnp.asarray(1.0))) == 1.0
        try:
            checked(jnp.asarray(-1.0))
        except eqx.EquinoxRuntimeError as e:
            assert "x must not be negative" in str(e)
        else:
            raise AssertionError(f"no error in mode {mode}")


def test_top_level_detection():
    """`at_top_level`: True for a plain call, False under every transformation, also where
    the arguments are concrete (a closure under `jax.jit`)."""
    c = jnp.asarray(1.0)
    assert _compile.at_top_level((c,))
    seen = []
    jax.jit(lambda: seen.append(_compile.at_top_level((c,))) or c)()
    jax.vmap(lambda y: seen.append(_compile.at_top_level((y,))) or y)(jnp.ones(2))
    jax.grad(lambda y: seen.append(_compile.at_top_level((y,))) or y)(1.0)
    lax.scan(lambda k, y: (seen.append(_compile.at_top_level((c,))) or k, y), 0.0, jnp.ones(2))
    assert seen == [False] * 4
    # a closure under jit calls the entry point with concrete arguments: the plain jit there
    np.testing.assert_allclose(jax.jit(lambda: _newton_sqrt(c * 4.0))(), 2.0, rtol=1e-15)
    np.testing.assert_allclose(jax.jit(lambda: _newton_sqrt(jnp.asarray(9.0)))(), 3.0, rtol=1e-15)


def test_dynamics_programs_keep_xla_loop_passes(monkeypatch):
    """The dynamics' jit compiles with XLA's defaults when optimized (the loop-invariant sine
    hoisted out of the loop, as without jaxrod's options), with FAST_COMPILE_OPTIONS alone
    when fast (the first variant of the default mode); the same values either way, through
    `.lower` and through the call."""
    from jaxrod._compile import FAST_COMPILE_OPTIONS, compiler_options, dynamics_jit

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


def test_clear_caches_forgets_the_accounts():
    """`jaxrod.clear_caches()` forgets every entry point's run-time accounts (and clears JAX's
    caches); the next call starts on the fast variant again, to the same value."""
    import jaxrod

    f = jit(_sqrt)
    a = jnp.asarray(7.0)
    with _env("JAXROD_COMPILE", "auto"):
        ref = float(f(a))
        assert len(f._accounts) == 1
        jaxrod.clear_caches()
        assert len(f._accounts) == 0
        assert float(f(a)) == ref and len(f._accounts) == 1
