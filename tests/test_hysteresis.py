"""Quasi-static hysteresis loop (paper Fig. 2a-b, 3c): branches through the snap points,
stability marks, energy released by each jump, a fold passed and come back, the CLI."""

import json
import os

import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr


@pytest.fixture(scope="module")
def loop():
    return jr.hysteresis(jr.make_scene(60.0, 0.5, 0.0))


def _branch(h, b):
    v = np.asarray(h.valid[b])
    return (np.asarray(h.alpha[b])[v], np.asarray(h.fold_height[b])[v], np.asarray(h.bending_energy[b])[v],
            np.asarray(h.num_unstable[b])[v])


def test_loop_brackets_the_snaps(loop):
    h = loop
    # no point of any branch passes through itself at G/L = 0.5
    assert h.result == jr.RESULTS.successful and not bool(jnp.any(h.crossing))
    assert h.crossing.shape == h.valid.shape
    up, down = float(h.snap.up.alpha_c), float(h.snap.down.alpha_c)
    # branch from the down state, alpha increasing: stable from 0 up to alpha_c_up, unstable after
    a, y, e, nu = _branch(h, 0)
    assert a[0] == 0.0 and y[0] < 0 and nu[0] == 0
    stable = nu == 0
    assert np.all(a[stable] <= up + 1e-12) and np.any(~stable)
    assert np.min(a[~stable][:1]) >= up - 1e-12 or np.max(a[~stable]) < up  # past a fold alpha turns back
    # branch from the up state, alpha decreasing: stable down to alpha_c_down
    a, y, e, nu = _branch(h, 3)
    assert a[0] == 0.0 and y[0] > 0 and nu[0] == 0
    assert np.all(a[nu == 0] >= down - 1e-12)
    # the stable start values equal the independent initial states
    for b, state in ((0, "down"), (3, "up")):
        eq = jr.initial_state(jr.make_scene(60.0, 0.5, 0.0), state)
        assert abs(_branch(h, b)[1][0] - float(jr.fold_height(eq))) < 1e-8
        assert abs(_branch(h, b)[2][0] - float(jr.bending_energy(eq))) < 1e-8


def test_energy_released_by_each_jump(loop):
    """A quasi-static snap lands in a stable state of lower energy at the same clamp angle."""
    h = loop
    for before, after in ((h.energy_before_up, h.energy_after_up), (h.energy_before_down, h.energy_after_down)):
        assert np.isfinite(float(before)) and float(after) < float(before)
    # the bending energy at the jump equals the energy of an independent solve there
    p = h.snap.up
    sc = jr.make_scene(60.0, 0.5, float(np.degrees(p.alpha_c)) + np.degrees(1e-3))
    eq = jr.solve_equilibrium(sc, p.theta_after, p.force_after)
    assert eq.result == jr.RESULTS.successful and bool(eq.stable)
    assert abs(float(jr.bending_energy(eq)) - float(h.energy_after_up)) < 1e-8


def test_passes_turning_point_and_comes_back(loop):
    """Continuation through a fold: alpha rises to a maximum and decreases again, and the
    unstable count changes by one exactly at the turn."""
    h = loop
    found = False
    for b in range(4):
        a, y, e, nu = _branch(h, b)
        d = np.diff(a)
        turns = np.nonzero(d[1:] * d[:-1] < 0)[0]
        for i in turns:
            j = i + 1  # a[j] is the extreme point
            if nu[j - 1] == 0 and np.all(nu[j + 1:j + 3] == 1):
                found = True
                # it comes back: at least 5 deg back from the turning point on the unstable side
                assert np.max(np.abs(a[j + 1:] - a[j])) > np.radians(5.0)
    assert found


def test_cli_hysteresis(loop, tmp_path, capsys):
    from jaxrod.cli._main import main

    png = tmp_path / "loop.png"
    assert main(["hysteresis", "--psi0", "60", "--gap", "0.5", "--plot", str(png), "--json"]) == 0
    rec = json.loads(capsys.readouterr().out)
    assert abs(rec["alpha_c_up_deg"] - np.degrees(float(loop.snap.up.alpha_c))) < 1e-9
    assert abs(rec["alpha_c_down_deg"] - np.degrees(float(loop.snap.down.alpha_c))) < 1e-9
    assert rec["bending_energy_after_up"] < rec["bending_energy_before_up"]
    assert set(rec["branches"]) == set(jr.HYSTERESIS_BRANCHES)
    assert os.path.getsize(png) > 20_000
    assert main(["hysteresis", "--gap", "1.5"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "gap" in err[0]


def test_float32_refused():
    f32 = jnp.float32
    sc = jr.Scene(jr.Strip(psi0=f32(np.pi / 3), s0=f32(0.02)), jr.Clamps(f32(0.5)), jr.Mesh(100))
    with pytest.raises(ValueError, match="float64"):
        jr.hysteresis(sc)
