"""The lane scheduler (`jaxrod._lanes`): a batch of iterative solves on fewer lanes than
members gives every member what it gives alone, in its own place, whatever the company.

A toy machine whose members need very different numbers of passes (Newton on x^2 = a from
x = a + 1, for a over six decades, and a member that never converges within its budget)
checks the scheduler itself; the library's own machines (the start states' homotopy and the
continuation) are checked against their single calls in test_batch.py, on fewer lanes than
members."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxrod import _lanes

jax.config.update("jax_enable_x64", True)

BUDGET = 60


def _init(x):
    a, = x
    return dict(v=a + 1.0, k=jnp.zeros((), jnp.int32))


def _step(x, s):
    a, = x
    return dict(v=0.5 * (s["v"] + a / s["v"]), k=s["k"] + 1)


def _done(x, s):
    a, = x
    return (jnp.abs(s["v"] ** 2 - a) <= 1e-12 * a) | (s["k"] >= BUDGET) | ~jnp.isfinite(s["v"])


def _finish(x, s):
    return s["v"], s["k"]


A = np.array([1e-3, 2.0, 1e6, np.nan, 7.0, 1e3, -4.0, 0.5, 3e2, 11.0])


def _alone():
    one = jax.jit(lambda a: _lanes.run_machine(_init, _step, _done, _finish, (a,)))
    return [tuple(np.asarray(v) for v in one(jnp.asarray(a))) for a in A]


@pytest.mark.parametrize("lanes", [1, 3, 4, 10, 16])
def test_every_member_as_alone(lanes):
    """On 1, 3, 4, 10 or more lanes each member's result (value and passes) is its single
    run's, in its own row; the NaN member and the one that never converges (a = -4: its
    budget) keep theirs."""
    v, k = jax.jit(lambda a: _lanes.run_lanes(_init, _step, _done, _finish, (a,), lanes))(jnp.asarray(A))
    for i, (v1, k1) in enumerate(_alone()):
        assert int(k[i]) == int(k1), i
        np.testing.assert_array_equal(np.asarray(v[i]), v1)
    assert int(k[6]) == BUDGET and np.isnan(float(v[3]))
    assert sorted(int(x) for x in k) != [int(k[0])] * len(A)  # the members do differ in passes


def test_vmap_runs_on_lanes(monkeypatch):
    """`jax.vmap` of a `machine_vmap` function runs the scheduler with `lanes_for(B)` lanes
    (patched to 3 here) and gives the single runs' results; an unbatched input is broadcast."""
    monkeypatch.setitem(_lanes.LANES, jax.default_backend(), 3)
    monkeypatch.setitem(_lanes.MIN_QUEUE, jax.default_backend(), 4)
    assert _lanes.lanes_for(10) == 3 and _lanes.lanes_for(4) == 3 and _lanes.lanes_for(3) == 3
    assert _lanes.lanes_for(2) == 2
    fun = _lanes.machine_vmap(_init, _step, _done, _finish)
    v, k = jax.jit(jax.vmap(lambda a: fun((a,))))(jnp.asarray(A))
    for i, (v1, k1) in enumerate(_alone()):
        assert int(k[i]) == int(k1)
        np.testing.assert_array_equal(np.asarray(v[i]), v1)
    # a closed-over (unbatched) input next to a batched one
    fun2 = _lanes.machine_vmap(lambda x: _init((x[0] * x[1],)), lambda x, s: _step((x[0] * x[1],), s),
                               lambda x, s: _done((x[0] * x[1],), s), lambda x, s: _finish((x[0] * x[1],), s))
    v2, _ = jax.vmap(lambda a: fun2((a, jnp.asarray(2.0))))(jnp.asarray([2.0, 8.0]))
    np.testing.assert_allclose(np.asarray(v2), [2.0, 4.0], rtol=1e-12)


def test_lanes_per_platform(monkeypatch):
    """A platform without an entry, or a batch below the platform's `MIN_QUEUE`, runs every
    member in a lane of its own."""
    key = jax.default_backend()
    monkeypatch.setitem(_lanes.LANES, key, 4)
    monkeypatch.setitem(_lanes.MIN_QUEUE, key, 32)
    assert _lanes.lanes_for(31) == 31 and _lanes.lanes_for(32) == 4
    monkeypatch.delitem(_lanes.LANES, key)
    assert _lanes.lanes_for(1000) == 1000


def test_batch_of_one():
    """A batch of one member runs its own loop (no scheduler) and gives its single run."""
    fun = _lanes.machine_vmap(_init, _step, _done, _finish)
    v, k = jax.vmap(lambda a: fun((a,)))(jnp.asarray(A[2:3]))
    v1, k1 = _alone()[2]
    assert v.shape == (1,) and int(k[0]) == int(k1)
    np.testing.assert_array_equal(np.asarray(v[0]), v1)


def _newton(x):
    return _lanes.run_machine(_init, _step, _done, _finish, x)


@pytest.mark.parametrize("platforms", [("cpu",), ()])
def test_in_turn_members_equal_their_own_runs(monkeypatch, platforms):
    """`in_turn`: under `jax.vmap` (one axis, two nested axes, an unbatched argument) every
    member equals its own run to the bit, whether the platform runs members one after another
    (`IN_TURN` holds it) or vectorized; a NaN member stays its own."""
    monkeypatch.setattr(_lanes, "IN_TURN", platforms)
    f = _lanes.in_turn(lambda x: _newton((x[0] * x[1],)))
    a = jnp.asarray([2.0, 1e-3, jnp.nan, 7e5, 3.0, 0.5])
    one = [f((ai, jnp.asarray(1.0))) for ai in a]
    got = jax.jit(jax.vmap(f, in_axes=((0, None),)))((a, jnp.asarray(1.0)))
    for k, (v, n) in enumerate(one):
        assert np.array_equal(np.asarray(got[0][k]), np.asarray(v), equal_nan=True) and int(got[1][k]) == int(n)
    nested = jax.jit(jax.vmap(jax.vmap(f)))((a.reshape(2, 3), jnp.ones((2, 3))))
    np.testing.assert_array_equal(np.asarray(nested[0]).ravel(), np.asarray(got[0]))
