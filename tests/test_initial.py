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
    eq3, found, _ = _initial._homotopy(_initial.float_scene(sc), -1.0, 24, Newton(), kinds=(2,))
    assert bool(found)
    np.testing.assert_allclose(eq.theta, eq3.theta, atol=1e-10)


def test_warm_start_kept_or_replaced_by_the_homotopy():
    """`initial_state_signed(..., warm=(theta, force, ok))` (the phase diagram's start states):
    from the state of a neighbouring gap (0.50 -> 0.52) Newton keeps the tracked state
    (`warmed`), the same state as the homotopy's to 1e-10; from a state of the other sign,
    or with `ok` False, the homotopy runs and gives its own state; the down state of
    (30 deg, 0.8), which does not exist, is `state_not_found` whatever the warm start."""
    sc = jr.make_scene(60.0, 0.52, n=30)
    prev = jr.initial_state(jr.make_scene(60.0, 0.5, n=30), "up")
    ref = jr.initial_state(sc, "up")
    f = jax.jit(lambda sc, sgn, t, m, ok: _initial.initial_state_signed(sc, sgn, warm=(t, m, ok)))
    eq, warmed = f(sc, 1.0, prev.theta, prev.force, True)
    assert bool(warmed) and eq.result == jr.RESULTS.successful
    np.testing.assert_allclose(eq.theta, ref.theta, atol=1e-10)
    other = jr.initial_state(sc, "down")
    for t, m, ok in ((other.theta, other.force, True), (prev.theta, prev.force, False)):
        eq, warmed = f(sc, 1.0, t, m, ok)
        assert not bool(warmed) and eq.result == jr.RESULTS.successful
        np.testing.assert_allclose(eq.theta, ref.theta, atol=1e-10)
    gone = jr.make_scene(30.0, 0.8, n=30)
    eq, warmed = f(gone, -1.0, prev.theta, prev.force, True)
    assert not bool(warmed) and eq.result == jr.RESULTS.state_not_found


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
