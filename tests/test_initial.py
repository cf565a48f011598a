"""Initial states by homotopy (`jaxrod.initial_state`): the deformation paths run in turn
and the first valid one gives the state, so a state reached only by a later path is found."""

import jax
import jax.numpy as jnp
import numpy as np

import jaxrod as jr
from jaxrod.statics import _initial
from jaxrod.statics._equilibrium import Newton


@jax.jit
def path_validity(scene, sgn):
    """Whether each of the three deformation paths reaches a valid state."""
    scene = _initial.float_scene(scene)
    eq0, ok0 = _initial._flat_start(scene, sgn, Newton())
    us = jnp.arange(1, 25, dtype=scene.strip.psi0.dtype) / 24
    return jnp.stack([_initial._run_path(scene, sgn, k, eq0, ok0, us, Newton())[2] for k in range(3)])


def test_state_only_the_last_path_reaches():
    """Psi0 = 10 deg, G/L = 0.9, alpha = -80 deg, N = 30: the down state is reached only by
    the clamps-first path; the other two lose it. It is found, stable, fold height down."""
    sc = jr.make_scene(10.0, 0.9, -80.0, n=30)
    assert np.asarray(path_validity(sc, -1.0)).tolist() == [False, False, True]
    eq = jr.initial_state(sc, "down")
    assert eq.result == jr.RESULTS.successful
    assert bool(eq.stable) and float(jr.fold_height(eq)) < 0
    # and the same state as the third path's end, polished
    eq0, ok0 = _initial._flat_start(_initial.float_scene(sc), -1.0, Newton())
    t, m, _ = _initial._run_path(_initial.float_scene(sc), -1.0, 2, eq0, ok0,
                                 jnp.arange(1, 25, dtype=jnp.float64) / 24, Newton())
    np.testing.assert_allclose(eq.theta, t, atol=1e-6)


def test_no_path_gives_state_not_found():
    """Psi0 = 10 deg, G/L = 0.6, alpha = -80 deg, N = 30: no path reaches the down state."""
    sc = jr.make_scene(10.0, 0.6, -80.0, n=30)
    assert not np.any(np.asarray(path_validity(sc, -1.0)))
    assert jr.initial_state(sc, "down").result == jr.RESULTS.state_not_found
