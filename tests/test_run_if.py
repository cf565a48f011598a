"""`jaxrod._misc.run_if`: conditional work that stays cheap under `vmap`.

`run_if` is a loop of at most one pass (under `vmap` it runs only when some member needs
it); its operands pass an optimization barrier so XLA cannot hoist `fn` out of the loop
(the hoisting made the vmapped phase diagram run the homotopy at every gap; the cost is
measured in `benchmarks/bench_phase.py`)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxrod._misc import run_if

jax.config.update("jax_enable_x64", True)


def _fn(x, scale, label):
    # a pytree operand with a non-array leaf (`label`) passes through as it is
    assert label == "static"
    return {"y": jnp.sin(x) * scale, "n": jnp.asarray(7, jnp.int32)}


def _default(x):
    return {"y": jnp.zeros_like(x), "n": jnp.asarray(-1, jnp.int32)}


def _expected(pred, x, scale):
    return np.where(pred, np.sin(x) * scale, 0.0), np.where(pred, 7, -1)


def test_values_unbatched_vmapped_and_nested():
    runner = run_if
    x = jnp.linspace(0.1, 2.0, 6)
    pred = jnp.array([True, False, True, True, False, False])
    call = lambda p, xi: runner(p, _fn, _default(xi), (xi, 2.0, "static"))  # noqa: E731
    for p, xi in zip(pred, x):  # unbatched, under jit
        out = jax.jit(call)(p, xi)
        y, n = _expected(bool(p), float(xi), 2.0)
        assert float(out["y"]) == pytest.approx(float(y), abs=1e-15) and int(out["n"]) == int(n)
    out = jax.jit(jax.vmap(call))(pred, x)  # vmapped: each member its own branch
    y, n = _expected(np.asarray(pred), np.asarray(x), 2.0)
    np.testing.assert_allclose(np.asarray(out["y"]), y, atol=1e-15)
    np.testing.assert_array_equal(np.asarray(out["n"]), n)
    # nested vmap, an unbatched operand, inside a scan (where XLA hoisting would bite)
    def scanned(p2, x2):
        return jax.lax.scan(lambda c, a: (c, runner(a[0], _fn, _default(a[1]), (a[1], 3.0, "static"))), 0,
                            (p2, x2))[1]
    P, X = pred.reshape(2, 3), x.reshape(2, 3)
    out = jax.jit(jax.vmap(jax.vmap(scanned)))(P[:, :, None], X[:, :, None])
    y, n = _expected(np.asarray(P), np.asarray(X), 3.0)
    np.testing.assert_allclose(np.asarray(out["y"])[..., 0], y, atol=1e-15)
    np.testing.assert_array_equal(np.asarray(out["n"])[..., 0], n)
