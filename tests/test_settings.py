"""Solver and run settings: a bad value raises one ValueError naming the setting as the API
spells it, before anything is solved; the CLI turns the same mistakes into exit code 2 with one
line on stderr. (Scene inputs are in test_inputs.py, the CLI's scene options in test_cli.py.)

Every check here fails before anything is compiled: the whole module takes a few seconds.
"""

from __future__ import annotations

import math
import subprocess
import sys

import jax.numpy as jnp
import pytest

import jaxrod as jr
from jaxrod.cli._main import main
from jaxrod.branches._critical import CriticalPoint


NAN, INF = float("nan"), math.inf
N = 8


def raises_naming(name, fn, *args, **kwargs):
    with pytest.raises(ValueError, match=rf"^{name}\b") as e:
        fn(*args, **kwargs)
    assert "\n" not in str(e.value)


@pytest.fixture(scope="module")
def scene():
    return jr.make_scene(60.0, 0.5, n=N)


@pytest.fixture(scope="module")
def eq(scene):
    """A stand-in equilibrium (the checks run before it is used)."""
    return jr.Equilibrium(jnp.zeros(N), jnp.zeros(2), jr.RESULTS.successful, jnp.zeros((), jnp.int32),
                          jnp.zeros((), jnp.int32), scene)


@pytest.fixture(scope="module")
def cp():
    z = jnp.zeros(())
    return CriticalPoint(z, jnp.zeros(N), jnp.zeros(2), jnp.ones(N), jnp.zeros(2), z, jnp.ones((), jnp.int32), z,
                         jnp.zeros((), jnp.int32), jr.RESULTS.successful)


def test_defaults_construct():
    jr.Continuation()
    jr.Newton()
    jr.Newton(gtol=1e-4, max_backtracks=0, minimize=False)
    jr.Continuation(ds=0.05, ds_min=0.1)  # ds below ds_min: stops at once (test_snap uses it)
    jr.Continuation(max_points=3, corrector_steps=1, tol=1e-8)
    jr.Protocol(t_stop=1.0)
    jr.Protocol(t_stop=INF)


CONTINUATION = [
    ("ds", -0.1), ("ds", 0.0), ("ds", NAN), ("ds", "0.1"), ("ds", True),
    ("ds_min", 0.0), ("ds_min", -1e-7), ("ds_min", NAN), ("ds_min", 0.3),  # 0.3 > ds_max
    ("ds_max", 0.0), ("ds_max", INF), ("ds_max", NAN),
    ("max_points", 0), ("max_points", 1), ("max_points", 10.0), ("max_points", True), ("max_points", NAN),
    ("corrector_steps", 0), ("corrector_steps", 2.5), ("corrector_steps", False),
    ("tol", 0.0), ("tol", -1e-9), ("tol", NAN),
]


@pytest.mark.parametrize("name, value", CONTINUATION, ids=[f"{n}={v!r}" for n, v in CONTINUATION])
def test_continuation(name, value):
    raises_naming(name, jr.Continuation, **{name: value})


NEWTON = [
    ("max_steps", 0), ("max_steps", -1), ("max_steps", 100.0), ("max_steps", True),
    ("gtol", 0.0), ("gtol", -1e-9), ("gtol", NAN),
    ("minimize", 1), ("minimize", "yes"), ("minimize", None),
    ("max_backtracks", -1), ("max_backtracks", 3.0),
]


@pytest.mark.parametrize("name, value", NEWTON, ids=[f"{n}={v!r}" for n, v in NEWTON])
def test_newton(name, value):
    raises_naming(name, jr.Newton, **{name: value})


@pytest.mark.parametrize("k", [0, -1, N - 1, 2.0, True, None])
def test_stability_k(eq, k):
    raises_naming("k", jr.stability, eq, k=k)


SNAP = [
    ("bound", 0.0), ("bound", -1.0), ("bound", 3.2), ("bound", NAN), ("bound", INF),
    ("bisections", 0), ("bisections", -3), ("bisections", 2.5), ("bisections", True),
    ("polish", 1), ("continue_after_snap", None), ("settings", jr.Newton()),
]


@pytest.mark.parametrize("name, value", SNAP, ids=[f"{n}={v!r}" for n, v in SNAP])
def test_snap_angles(scene, name, value):
    raises_naming(name, jr.snap_angles, scene, **{name: value})


def test_snap_angles_extrapolated_passes_them_on(scene):
    raises_naming("bound", jr.snap_angles_extrapolated, scene, bound=0.0)


@pytest.mark.parametrize("name, value", [("bound", 0.0), ("bound", 4.0), ("max_unstable", -1),
                                         ("max_unstable", 1.0), ("settings", None)])
def test_hysteresis(scene, name, value):
    raises_naming(name, jr.hysteresis, scene, **{name: value})


BRANCH = [
    ("direction", 0.0), ("direction", 2.0), ("direction", NAN),
    ("bounds", (1.0, -1.0)), ("bounds", (0.0, 0.0)), ("bounds", (NAN, 1.0)), ("bounds", 3.0), ("bounds", (0, 1, 2)),
    ("settings", jr.Newton()), ("stop_on_instability", "yes"),
]


@pytest.mark.parametrize("name, value", BRANCH, ids=[f"{n}={v!r}" for n, v in BRANCH])
def test_continue_branch(scene, eq, name, value):
    raises_naming(name, jr.continue_branch, scene, eq, **{name: value})


def test_equilibrium_solvers(scene, eq):
    raises_naming("solver", jr.solve_equilibrium, scene, jnp.zeros(N), solver=jr.Continuation())
    raises_naming("throw", jr.solve_equilibrium, scene, jnp.zeros(N), throw="no")
    raises_naming("steps", jr.initial_state, scene, "up", steps=0)
    raises_naming("steps", jr.initial_state, scene, "up", steps=2.0)
    raises_naming("solver", jr.initial_state, scene, "up", solver=None)


@pytest.mark.parametrize("kwargs, name", [
    (dict(kind=0), "kind"), (dict(kind=3), "kind"), (dict(kind="fold"), "kind"),
    (dict(max_steps=0), "max_steps"), (dict(max_steps=2.5), "max_steps"),
    (dict(tol=0.0), "tol"), (dict(tol=NAN), "tol"),
])
def test_critical_point(scene, eq, kwargs, name):
    kw = dict(kind=1) | kwargs
    kind = kw.pop("kind")
    raises_naming(name, jr.critical_point, scene, eq.theta, eq.force, 0.0, jnp.ones(N), kind, **kw)


@pytest.mark.parametrize("kwargs, name", [(dict(max_steps=0), "max_steps"), (dict(tol=-1.0), "tol")])
def test_cusp_point(scene, eq, kwargs, name):
    raises_naming(name, jr.cusp_point, scene, eq.theta, eq.force, 0.0, jnp.ones(N), **kwargs)


@pytest.mark.parametrize("kwargs, name", [
    (dict(ds=0.0), "ds"), (dict(ds_min=NAN), "ds_min"), (dict(ds_max=-1.0), "ds_max"),
    (dict(ds_min=0.1, ds_max=0.05), "ds_min"), (dict(max_points=1), "max_points"),
    (dict(corrector_steps=0.5), "corrector_steps"), (dict(tol=0.0), "tol"),
    (dict(gap_bounds=(0.9, 0.1)), "gap_bounds"), (dict(gap_bounds=(0.0, 0.9)), "gap_bounds"),
    (dict(gap_bounds=(NAN, 0.9)), "gap_bounds"), (dict(direction=0.0), "direction"),
])
def test_continue_critical(scene, cp, kwargs, name):
    raises_naming(name, jr.continue_critical, scene, cp, **kwargs)


SIMULATE = [
    ("t1", 0.0), ("t1", -1.0), ("t1", NAN), ("t1", INF),
    ("direction", 0.5), ("direction", 0.0),
    ("rtol", -1e-6), ("rtol", NAN), ("atol", -1e-6), ("atol", INF),
    ("dt", 0.0), ("dt", -1e-4), ("dt", NAN),
    ("baumgarte", -1.0), ("baumgarte", NAN),
    ("n_fine", 1), ("n_fine", 100.0), ("n_fine", True),
    ("n_frames", 0), ("n_frames", 8.0),
    ("max_steps", 0), ("max_steps", 1e5),
    ("courant", 0.0), ("courant", 0.5), ("courant", NAN),
    ("frame_window", (0.5, 0.1)), ("frame_window", (0.0, 5.0)), ("frame_window", (-1.0, 1.0)), ("frame_window", 1.0),
    ("stop_at_snap", None), ("dissipation", 0.1),
    ("energy_tol", 0.0), ("constraint_tol", -1.0),
]


@pytest.mark.parametrize("name, value", SIMULATE, ids=[f"{n}={v!r}" for n, v in SIMULATE])
def test_simulate(scene, name, value):
    raises_naming(name, jr.simulate, scene, jnp.zeros(N), jr.Protocol(), **{name: value})


def test_simulate_tolerances_not_both_zero(scene):
    raises_naming("rtol", jr.simulate, scene, jnp.zeros(N), jr.Protocol(), rtol=0.0, atol=0.0)


@pytest.mark.parametrize("kwargs, name", [
    (dict(kind="wobble"), "kind"), (dict(nudge=0.0), "nudge"), (dict(past=-1e-3), "past"),
    (dict(rate=0.0), "rate"), (dict(seed=NAN), "seed"), (dict(alpha_start=NAN), "alpha_start"),
    # run settings fail before the start state is solved (no snap_angles here)
    (dict(t1=-1.0), "t1"), (dict(rtol=NAN), "rtol"), (dict(n_frames=0), "n_frames"), (dict(dt=0.0), "dt"),
])
def test_snap_dynamics(scene, kwargs, name):
    raises_naming(name, jr.snap_dynamics, scene, "up", **kwargs)


def test_ramp_and_protocol(scene):
    raises_naming("alpha_start", jr.ramp, scene, "up", alpha_start=NAN)
    raises_naming("t_stop", jr.Protocol, t_stop=-1.0)
    raises_naming("t_stop", jr.Protocol, t_stop=NAN)


def test_snap_speed_solver(scene):
    raises_naming("solver", jr.snap_speed, scene, solver="rk4")


def test_termination_gap_grid():
    raises_naming("grid", jr.termination_gap, 60.0, grid=(0.3, NAN))
    raises_naming("grid", jr.termination_gap, 60.0, grid=(0.3, 1.2))


# ----- the command line -----------------------------------------------------------------

CLI_BAD = [
    (["snap-angles", "--n", "0"], "n"),
    (["hysteresis", "--gap", "1.5"], "gap"),
    (["hysteresis", "--n", "1.5"], "--n"),
    (["termination-gap", "--tol", "0"], "tol"),
    (["termination-gap", "--n", "0"], "n"),
    (["termination-gap", "--s0", "nan"], "s0"),
    (["phase-diagram", "--n", "0"], "n"),
    (["phase-diagram", "--s0", "nan"], "s0"),
    (["phase-diagram", "--gaps", "0.5,1.5"], "gap"),
    (["phase-diagram", "--refine", "0.5"], "refine"),
    (["phase-diagram", "--gaps", "0.1:0.9:0"], "gaps"),
    (["snap", "--t1", "-1"], "t1"),
    (["snap", "--rtol", "nan"], "rtol"),
    (["snap", "--rate", "0"], "rate"),
    (["speed-plane", "--t1", "0"], "t1"),
    (["speed-plane", "--n", "0"], "n"),
    (["design", "--target-alpha-up", "60", "--max-iter", "0"], "max-iter"),
    (["design", "--target-speed", "5", "--speed-tol", "2"], "speed-tol"),
    (["snap", "--scene", "ramp", "--route", "second"], "route"),
    (["snap-angles", "--contact-thickness", "0.6"], "contact-thickness"),
    (["snap", "--s0", "0.6"], "s0"),
]


@pytest.mark.parametrize("argv, name", CLI_BAD, ids=[" ".join(a) for a, _ in CLI_BAD])
def test_cli_bad_setting_in_process(argv, name, capsys):
    assert main(argv) == 2
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert out == "" and len(lines) == 1, err
    assert lines[0].startswith("jaxrod: error: ") and name in lines[0] and "Traceback" not in err


def test_cli_bad_setting_subprocess():
    """The real process: exit 2, one stderr line naming the option, no traceback (each fails
    before anything is compiled: the cost is the import)."""
    cases = [
        (["equilibrium", "--n", "0"], "n (number of segments) must be an even integer >= 8, got 0"),
        (["snap", "--t1", "-1"], "t1 must be a finite number > 0"),
        (["termination-gap", "--tol", "0"], "tol must lie in (0, 0.1)"),
        (["phase-diagram", "--gaps", "0.5,1.5"], "gap must lie in (0, 1), got 1.5"),
    ]
    procs = [(subprocess.Popen([sys.executable, "-m", "jaxrod", *a], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True), needle) for a, needle in cases]
    for p, needle in procs:
        out, err = p.communicate(timeout=300)
        assert p.returncode == 2, (needle, err)
        assert out == "" and len(err.strip().splitlines()) == 1, err
        assert err.startswith("jaxrod: error: ") and needle in err and "Traceback" not in err
