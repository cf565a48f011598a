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
    """Whether each of the three deformation paths, tried alone, reaches a valid state."""
    scene = _initial.float_scene(scene)
    return jnp.stack([_initial._homotopy(scene, sgn, 24, Newton(), kinds=(k,))[1] for k in range(3)])


def test_state_only_the_last_path_reaches():
    """Psi0 = 10 deg, G/L = 0.9, alpha = -80 deg, N = 30: the down state is reached only by
    the clamps-first path; the other two lose it. It is found, stable, fold height down."""
    sc = jr.make_scene(10.0, 0.9, -80.0, n=30)
    assert np.asarray(path_validity(sc, -1.0)).tolist() == [False, False, True]
    eq = jr.initial_state(sc, "down")
    assert eq.result == jr.RESULTS.successful
    assert bool(eq.stable) and float(jr.fold_height(eq)) < 0
    # and the same state as the third path tried alone: the two lost paths leave no trace
    eq3, found = _initial._homotopy(_initial.float_scene(sc), -1.0, 24, Newton(), kinds=(2,))
    assert bool(found)
    np.testing.assert_allclose(eq.theta, eq3.theta, atol=1e-10)


def test_no_path_gives_state_not_found():
    """Psi0 = 10 deg, G/L = 0.6, alpha = -80 deg, N = 30: no path reaches the down state."""
    sc = jr.make_scene(10.0, 0.6, -80.0, n=30)
    assert not np.any(np.asarray(path_validity(sc, -1.0)))
    assert jr.initial_state(sc, "down").result == jr.RESULTS.state_not_found


def test_secant_prediction_and_retry(monkeypatch):
    """Homotopy steps start from the secant prediction: 3 steps (large extrapolations) reach
    the same states as 24; where a path is lost, each prediction that loses it is retried from
    the last state first (the down state at (30 deg, 0.8) does not exist: every path of the
    three is lost, with retries)."""
    events = []
    real = _initial.still_tracked

    def counted(eq, sgn, t, sc):
        ok = real(eq, sgn, t, sc)
        jax.debug.callback(lambda x: events.append(bool(x)), ok)
        return ok

    monkeypatch.setattr(_initial, "still_tracked", counted)
    for psi0, gap, state in ((60.0, 0.5, "up"), (60.0, 0.5, "down"), (20.0, 0.3, "down")):
        scene = jr.make_scene(psi0, gap, n=24)
        few, many = (jr.initial_state(scene, state, steps=k) for k in (3, 24))
        assert few.result == many.result == jr.RESULTS.successful
        np.testing.assert_allclose(few.theta, many.theta, rtol=0, atol=1e-9)
    events.clear()
    lost = jr.initial_state(jr.make_scene(30.0, 0.8, n=24), "down", steps=6)
    assert lost.result == jr.RESULTS.state_not_found
    # three paths lost; a path lost after its first step is lost twice (prediction, then retry)
    assert events.count(False) > 3, events
