"""Batched solves: vmap equals the loop, bad members fail alone, no recompilation."""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from helpers import count_compiles, solve, state


def with_params(scene, p):
    """p = (psi0, gap, alpha_left, alpha_right), set as traced leaves (no constructor checks)."""
    return eqx.tree_at(lambda s: (s.strip.psi0, s.clamps.gap, s.clamps.alpha_left, s.clamps.alpha_right),
                       scene, (p[0], p[1], p[2], p[3]))


def solve_p(p, scene, theta0, mu0):
    return jr.solve_equilibrium(with_params(scene, p), theta0, mu0)


one = jax.jit(solve_p)
batch = jax.jit(jax.vmap(solve_p, in_axes=(0, None, None, None)))


@pytest.fixture(scope="module")
def down():
    return state(60.0, 0.5, "down")


def base_params(n):
    return np.tile([math.radians(60.0), 0.5, 0.0, 0.0], (n, 1))


def assert_same(eq_batched, i, eq_single, atol=1e-12):
    np.testing.assert_allclose(np.asarray(eq_batched.theta[i]), np.asarray(eq_single.theta), rtol=0, atol=atol)
    np.testing.assert_allclose(np.asarray(eq_batched.force[i]), np.asarray(eq_single.force),
                               rtol=0, atol=atol * max(1.0, float(jnp.max(jnp.abs(eq_single.force)))))
    assert int(eq_batched.num_steps[i]) == int(eq_single.num_steps)
    assert int(eq_batched.num_unstable[i]) == int(eq_single.num_unstable)


def test_vmap_over_alpha_equals_loop(down):
    P = base_params(5)
    P[:, 2] = P[:, 3] = np.radians([-30.0, -10.0, 0.0, 10.0, 30.0])
    P[3, 3] = math.radians(2.0)  # one asymmetric member
    eb = batch(jnp.asarray(P), down.scene, down.theta, down.force)
    ok = np.asarray(eb.result == jr.RESULTS.successful)
    assert ok.all()
    for i in range(P.shape[0]):
        es = one(jnp.asarray(P[i]), down.scene, down.theta, down.force)
        assert es.result == jr.RESULTS.successful
        assert_same(eb, i, es)
    # the members are different equilibria (not one state broadcast)
    th = np.asarray(eb.theta)
    gaps = [np.max(np.abs(th[i] - th[j])) for i in range(len(th)) for j in range(i)]
    assert min(gaps) > 1e-2
    assert np.all(np.asarray(jax.vmap(jr.fold_height)(eb)) < 0)  # all still down states


@pytest.mark.parametrize("bad_gap", [float("nan"), 1.5])
def test_bad_member_fails_alone(down, bad_gap):
    """A NaN or impossible gap (> L, traced, so the constructor cannot reject it) gives that
    member a failure code; the other members equal their separate solves."""
    P = base_params(4)
    P[:, 1] = [0.45, 0.5, bad_gap, 0.55]
    eb = batch(jnp.asarray(P), down.scene, down.theta, down.force)
    ok = np.asarray(eb.result == jr.RESULTS.successful)
    assert ok.tolist() == [True, True, False, True]
    if math.isnan(bad_gap):
        assert bool((eb.result == jr.RESULTS.nonfinite)[2]), np.asarray(eb.result._value)
    else:  # no equilibrium exists: Newton stalls (line search) or runs out of steps
        assert bool((eb.result == jr.RESULTS.line_search_failed)[2] | (eb.result == jr.RESULTS.max_steps_reached)[2]), \
            np.asarray(eb.result._value)
    for i in (0, 1, 3):
        assert_same(eb, i, one(jnp.asarray(P[i]), down.scene, down.theta, down.force))
    # the failure does not depend on being batched
    es = one(jnp.asarray(P[2]), down.scene, down.theta, down.force)
    assert int(es.result._value) == int(np.asarray(eb.result._value)[2])


def test_no_recompilation_across_parameter_values(down):
    """Scenes built by `make_scene` with new float values reuse the compiled solver."""

    @eqx.filter_jit
    @eqx.debug.assert_max_traces(max_traces=1)
    def wrapped(scene, theta0, mu0):
        return jr.solve_equilibrium(scene, theta0, mu0)

    values = [(60.0, 0.5), (61.0, 0.5), (60.0, 0.52), (75.0, 0.45)]
    for psi0, gap in values:
        eq = wrapped(jr.make_scene(psi0, gap, n=100), down.theta, down.force)
        assert eq.result == jr.RESULTS.successful
    # the public entry points themselves (eqx.filter_jit inside): warm them up once...
    solve(jr.make_scene(60.0, 0.5, n=100), down.theta, down.force)
    jr.initial_state(jr.make_scene(60.0, 0.5, n=100), "down")
    # ...then new parameter values, clamp angles and stiffnesses compile nothing
    with count_compiles() as c:
        for psi0, gap in values[1:]:
            sc = jr.make_scene(psi0, gap, 3.0, n=100)
            solve(sc, down.theta, down.force)
            jr.initial_state(sc, "down")
        sc = jr.Scene(jr.Strip(psi0=1.0, s0=0.03, bending_stiffness=2.0), jr.Clamps(0.6, 0.1, -0.1), jr.Mesh(100))
        solve(sc, down.theta, down.force)
    assert c[0] == 0, f"{c[0]} backend compilations for new parameter values"
