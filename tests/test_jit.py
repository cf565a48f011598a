"""jaxrod's jit: XLA options at the top level, the plain jit inside any JAX transformation."""

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


def test_fast_compile_mode(monkeypatch):
    """JAXROD_COMPILE=fast: jaxrod's jit compiles with FAST_COMPILE_OPTIONS (in its own
    variant, read at each call) and gives the same values; a bad value is one ValueError
    naming the variable, and the CLI's exit 2."""
    from jaxrod._misc import COMPILER_OPTIONS, FAST_COMPILE_OPTIONS, compiler_options
    from jaxrod.cli import main

    a = jnp.asarray(2.0)
    slow = float(_newton_sqrt(a))
    assert compiler_options() == COMPILER_OPTIONS
    monkeypatch.setenv("JAXROD_COMPILE", "fast")
    assert compiler_options() == {**COMPILER_OPTIONS, **FAST_COMPILE_OPTIONS}
    assert float(_newton_sqrt(a)) == slow
    monkeypatch.setenv("JAXROD_COMPILE", "quick")
    try:
        _newton_sqrt(a)
    except ValueError as e:
        assert "JAXROD_COMPILE" in str(e) and "'quick'" in str(e)
    else:
        raise AssertionError("no ValueError")
    assert main(["equilibrium", "--n", "8", "--json"]) == 2


def test_dynamics_programs_keep_xla_loop_passes(monkeypatch):
    """The dynamics' jit compiles with XLA's defaults (the loop-invariant sine hoisted out of
    the loop, as without jaxrod's options), and in the fast mode with FAST_COMPILE_OPTIONS
    alone; the same values either way."""
    from jaxrod._misc import FAST_COMPILE_OPTIONS, compiler_options, dynamics_jit

    args = (jnp.asarray(2.0), jnp.asarray(3.0))
    loop = dynamics_jit(_invariant_loop)
    assert compiler_options(dynamics=True) == {}
    ref = float(loop(*args))
    assert not _sine_in_loop_body(loop.lower(*args).compile().compiled.as_text())
    monkeypatch.setenv("JAXROD_COMPILE", "fast")
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


def test_lowered_first_lowers_once_per_key_and_only_at_the_top_level():
    """`lowered_first` traces and lowers before the first call of a key at the top level (under
    its lock), not again for that key, and not inside a transformation; its value is the
    call's."""
    from jaxrod import _misc

    f = jax.jit(lambda x: 2.0 * x)
    lowered = []

    class Counting:
        def lower(self, *a, **k):
            lowered.append(a)
            return f.lower(*a, **k)

        def __call__(self, *a, **k):
            return f(*a, **k)

    g = Counting()
    key = ("test", object())
    assert float(_misc.lowered_first(g, key, jnp.asarray(1.5))) == 3.0 and len(lowered) == 1
    assert float(_misc.lowered_first(g, key, jnp.asarray(2.0))) == 4.0 and len(lowered) == 1
    other = ("test", object())
    out = jax.jit(lambda x: _misc.lowered_first(g, other, x))(jnp.asarray(1.0))
    assert float(out) == 2.0 and len(lowered) == 1 and other not in _misc._LOWERED
    assert not _misc.TRACING.locked()
