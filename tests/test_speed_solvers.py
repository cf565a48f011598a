"""`jr.snap_speed` / `jr.snap_speed_run` with the solvers as objects: `jr.Rattle(courant=...)`
is the string `"rattle"` with its Courant number's step, `jr.HHT()` the implicit adaptive
integrator (nightly: its v_s against RATTLE's and its gradient against central differences),
anything else refused by name."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import jaxrod as jr
from jaxrod.dynamics._snap_speed import default_dt, default_n_fine

jax.config.update("jax_enable_x64", True)

N = 16


@pytest.fixture(scope="module")
def scene():
    return jr.make_scene(30, 0.5, n=N)


def test_rattle_object_is_the_string(scene):
    """`jr.Rattle()` is the string `"rattle"`: the same options, hence the same compiled program
    (its key) and the same run; `Rattle(courant=c)` differs only in its step."""
    from jaxrod.dynamics._snap_speed import _options

    args = (scene, "up", 1e-3, 1e-3, None, 2.0, None)
    base = _options(*args, "rattle", None)
    assert _options(*args, jr.Rattle(), None) == base
    slow = _options(*args, jr.Rattle(courant=0.2), None)
    assert slow[6] == "rattle" and slow[:3] == base[:3] and slow[4:] == base[4:]
    assert slow[3] <= base[3]


@pytest.mark.slow  # a snap_speed program of its own (~12 s on 2 cores)
def test_rattle_object_runs_as_the_string(scene):
    """Run both: the same v_s and steps."""
    a = jr.snap_speed_run(scene, solver="rattle")
    b = jr.snap_speed_run(scene, solver=jr.Rattle())
    assert a.result == b.result == jr.RESULTS.successful
    assert float(a.v_s) == float(b.v_s) and int(a.num_steps) == int(b.num_steps)


def test_courant_sets_the_default_step():
    """At N = 48 RATTLE's step is its Courant number times h_min^2 (below the 2e-4 T cap): a
    `Rattle(courant=0.2)` takes 0.2 / 0.45 of the default step and samples as often."""
    sc = jr.make_scene(30, 0.5, n=48)
    dt0, dt1 = default_dt(sc, "rattle", 2.0), default_dt(sc, jr.Rattle(courant=0.2), 2.0)
    assert dt1 / dt0 == pytest.approx(0.2 / 0.45, rel=2e-3)
    assert default_n_fine(sc, jr.Rattle(courant=0.2), 2.0) > 2 * default_n_fine(sc, "rattle", 2.0)
    assert default_dt(sc, jr.HHT(), 2.0) is None and default_n_fine(sc, jr.HHT(), 2.0) == 4096


@pytest.mark.parametrize("solver, name", [("foo", "solver"), (jr.Rattle(substeps=2), "substeps"), (3, "solver")])
def test_bad_solver_named(scene, solver, name):
    with pytest.raises(ValueError, match=name):
        jr.snap_speed(scene, solver=solver)


@pytest.mark.slow  # an HHT program of its own (~20 s on 2 cores)
def test_hht_speed_matches_rattle(scene):
    """`jr.HHT()` at its defaults: v_s within 2e-3 of RATTLE's (measured 5.4e-4 at N = 16)
    in about a quarter of the steps."""
    a = jr.snap_speed_run(scene)
    b = jr.snap_speed_run(scene, solver=jr.HHT())
    assert b.result == jr.RESULTS.successful
    assert abs(float(b.v_s) / float(a.v_s) - 1.0) < 2e-3
    assert int(b.num_steps) < int(a.num_steps) / 3


@pytest.mark.slow  # reverse mode through 2,500 implicit steps (~45 s on 2 cores)
def test_hht_speed_gradient_matches_central_differences():
    """d v_s / d Psi0 through `snap_speed(solver=jr.HHT(...), dt=2.5e-4)` (fixed steps, Newton to
    1e-12) equals central differences of the same function (h = 1e-4 rad) to 2e-3 relative.
    With adaptive steps the derivative holds the step sequence fixed (diffrax's rule), while
    central differences see the steps move with Psi0 (measured 6.7 % apart at N = 16)."""
    solver = jr.HHT(newton_tol=1e-12, newton_iters=30)

    def v(p):
        # fixed steps of 2.5e-4 T leave 0.5 % of the energy to HHT's dissipation (1e-3 T: 1.2 %,
        # past the energy monitor's 1 %)
        return jr.snap_speed(jr.Scene(jr.Strip(psi0=p), jr.Clamps(0.5), jr.Mesh(N)), solver=solver, dt=2.5e-4)

    p0 = np.radians(30.0)
    g = float(jax.grad(v)(jax.numpy.asarray(p0)))
    h = 1e-4
    fd = (float(v(p0 + h)) - float(v(p0 - h))) / (2 * h)
    assert np.isfinite(g) and abs(g - fd) <= 2e-3 * abs(fd)
