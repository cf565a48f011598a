"""`jaxrod._misc.run_if` / `run_if_each`: conditional work that stays cheap under `vmap`.

`run_if` is a loop of at most one pass (under `vmap` it runs only when some member needs
it); its operands pass an optimization barrier so XLA cannot hoist `fn` out of the loop
(the hoisting made the vmapped phase diagram run the homotopy at every gap; the cost is
measured in `benchmarks/bench_phase.py`). `run_if_each` runs the members one after another
under `vmap`, each through a real `lax.cond`, so `fn` runs only for the members that need it."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxrod._misc import run_if, run_if_each

jax.config.update("jax_enable_x64", True)


def _fn(x, scale, label):
    # a pytree operand with a non-array leaf (`label`) passes through as it is
    assert label == "static"
    return {"y": jnp.sin(x) * scale, "n": jnp.asarray(7, jnp.int32)}


def _default(x):
    return {"y": jnp.zeros_like(x), "n": jnp.asarray(-1, jnp.int32)}


def _expected(pred, x, scale):
    return np.where(pred, np.sin(x) * scale, 0.0), np.where(pred, 7, -1)


@pytest.mark.parametrize("runner", [run_if, run_if_each], ids=["run_if", "run_if_each"])
def test_values_unbatched_vmapped_and_nested(runner):
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


def test_run_if_each_runs_fn_only_for_members_that_need_it():
    """Under vmap `fn` executes once per member whose predicate holds (counted by a host
    callback inside `fn`), not for the whole batch."""
    calls = []

    def fn(x):
        jax.debug.callback(lambda v: calls.append(float(v)), x)
        return x * 10.0

    pred = jnp.array([False, True, False, False, True])
    x = jnp.arange(5.0)
    out = jax.jit(jax.vmap(lambda p, xi: run_if_each(p, fn, -xi, (xi,))))(pred, x)
    jax.block_until_ready(out)
    np.testing.assert_array_equal(np.asarray(out), [-0.0, 10.0, -2.0, -3.0, 40.0])
    assert sorted(calls) == [1.0, 4.0]
    calls.clear()
    out = jax.jit(jax.vmap(lambda p, xi: run_if_each(p, fn, -xi, (xi,))))(jnp.zeros(5, bool), x)
    jax.block_until_ready(out)
    assert calls == []  # nobody needs it: fn never runs
