"""The `jaxrod` command line: JSON contract, plots, demo outputs, bad-input handling.

The solving subprocesses share a persistent JAX compilation cache in a temporary
directory and run in a background thread while the in-process reference values are
computed, so the module costs about one cold compile of each state.
"""

from __future__ import annotations

import concurrent.futures
import json
import math
import os
import subprocess
import sys

import jax
import pytest

import jaxrod as jr
from jaxrod.cli._main import main


REQUIRED = {
    "converged": bool, "result": str, "state": str, "psi0_deg": float, "gap": float, "alpha_left_deg": float,
    "alpha_right_deg": float, "s0": float, "n": int, "fold_height": float, "bending_energy": float,
    "stretching_energy": float, "compression": float, "min_eigenvalue": float, "eigenvalues": list,
    "num_unstable": int, "stable": bool, "num_steps": int,
}
SCENE = ["--psi0", "60", "--gap", "0.5", "--alpha", "0"]


def _cli(args, env=None, timeout=600):
    return subprocess.run([sys.executable, "-m", "jaxrod", *args], capture_output=True, text=True,
                          env=env, timeout=timeout)


@pytest.fixture(scope="module")
def tmp(tmp_path_factory):
    return tmp_path_factory.mktemp("cli")


@pytest.fixture(scope="module")
def runs(tmp):
    """The solving CLI calls, run one after another in a background thread (sharing a
    compilation cache when the suite's is on, see conftest.py) while the tests compute
    reference values in-process."""
    env = dict(os.environ)
    if "JAXROD_NO_CACHE" not in env:
        env["JAX_COMPILATION_CACHE_DIR"] = str(tmp / "jax-cache")
    jobs = {
        "demo": ["demo", "--out", str(tmp / "demo")],
        "down": ["equilibrium", *SCENE, "--state", "down", "--json", "--plot", str(tmp / "plots" / "down.png")],
        "up": ["equilibrium", *SCENE, "--state", "up", "--json"],
    }

    def work():
        return {name: _cli(args, env) for name, args in jobs.items()}

    pool = concurrent.futures.ThreadPoolExecutor(1)
    fut = pool.submit(work)
    yield fut
    pool.shutdown(wait=True)


@pytest.fixture(scope="module")
def x64():
    old = jax.config.jax_enable_x64
    jax.config.update("jax_enable_x64", True)
    yield
    jax.config.update("jax_enable_x64", old)


@pytest.fixture(scope="module")
def reference(runs, x64):
    """The same observables from the Python API (float64)."""
    scene = jr.make_scene(60.0, 0.5, 0.0)
    out = {}
    for state in ("up", "down"):
        eq = jr.initial_state(scene, state)
        st = jr.stability(eq, k=4)
        out[state] = {
            "converged": bool(eq.converged),
            "fold_height": float(jr.fold_height(eq)),
            "bending_energy": float(jr.bending_energy(eq)),
            "stretching_energy": float(jr.energies(eq)["stretching"]),
            "compression": float(jr.compression(eq)),
            "eigenvalues": [float(v) for v in st.eigenvalues],
            "min_eigenvalue": float(st.eigenvalues[0]),
            "num_unstable": int(st.num_unstable),
        }
    return out


@pytest.fixture(scope="module")
def done(runs, reference):
    return runs.result()


def _check_record(rec, state, ref):
    for key, typ in REQUIRED.items():
        assert key in rec, key
        assert isinstance(rec[key], typ) or (typ is float and type(rec[key]) is int), (key, rec[key])
    assert rec["converged"] is True and rec["result"] == "successful"
    assert rec["state"] == state
    assert (rec["psi0_deg"], rec["gap"], rec["alpha_left_deg"], rec["alpha_right_deg"]) == (60, 0.5, 0, 0)
    assert (rec["s0"], rec["n"]) == (0.02, 100)
    assert len(rec["eigenvalues"]) == 4 and rec["eigenvalues"] == sorted(rec["eigenvalues"])
    assert rec["min_eigenvalue"] == rec["eigenvalues"][0]
    assert rec["stable"] is (rec["num_unstable"] == 0)
    for key in ("fold_height", "bending_energy", "stretching_energy", "compression", "min_eigenvalue"):
        assert math.isclose(rec[key], ref[key], rel_tol=0, abs_tol=1e-10), (key, rec[key], ref[key])
    for a, b in zip(rec["eigenvalues"], ref["eigenvalues"]):
        assert math.isclose(a, b, rel_tol=0, abs_tol=1e-10)
    assert rec["num_unstable"] == ref["num_unstable"]


def test_solving_commands(done, reference, tmp):
    """`equilibrium --json [--plot]` for both states and `demo --out DIR` (one test, so
    pytest-xdist never runs the solving subprocesses twice)."""
    for state in ("down", "up"):
        p = done[state]
        assert p.returncode == 0, p.stderr
        assert p.stderr.strip() == "", p.stderr  # no JAX/equinox chatter
        lines = p.stdout.strip().splitlines()
        assert len(lines) == 1, p.stdout  # exactly one JSON object
        rec = json.loads(lines[0])
        _check_record(rec, state, reference[state])
    down = json.loads(done["down"].stdout)
    up = json.loads(done["up"].stdout)
    assert down["fold_height"] < 0 and down["stable"] is True
    assert up["fold_height"] > 0 and up["stable"] is True
    png = tmp / "plots" / "down.png"
    assert png.stat().st_size > 1000
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    p = done["demo"]
    assert p.returncode == 0, p.stderr
    assert "Traceback" not in p.stderr
    out = tmp / "demo"
    png, js = out / "equilibria.png", out / "equilibria.json"
    assert png.stat().st_size > 1000 and png.read_bytes()[:4] == b"\x89PNG"
    data = json.loads(js.read_text())
    recs = {r["state"]: r for r in data["equilibria"]}
    assert set(recs) == {"up", "down"}
    for state, rec in recs.items():
        _check_record(rec, state, reference[state])
    # the table: a header and one row per state
    assert "min eig" in p.stdout
    rows = [ln.split() for ln in p.stdout.splitlines() if ln.split()[:1] in (["up"], ["down"])]
    assert [r[0] for r in rows] == ["up", "down"] and all(r[-1] == "yes" for r in rows)


BAD = [
    (["--gap", "1.5"], "gap"),
    (["--gap", "0"], "gap"),
    (["--gap", "nan"], "gap"),
    (["--psi0", "0"], "psi0"),
    (["--psi0", "200"], "psi0"),
    (["--psi0", "nan"], "psi0"),
    (["--s0", "0"], "s0"),
    (["--s0", "-0.1"], "s0"),
    (["--s0", "nan"], "s0"),
    (["--n", "7"], "n"),
    (["--n", "4"], "n"),
    (["--n", "nan"], "--n"),
    (["--alpha", "nan"], "alpha"),
    (["--alpha-right", "inf"], "alpha_right"),
    (["--refine", "nan"], "refine"),
    (["--stretching", "-1"], "stretching"),
    (["--gravity", "nan"], "gravity"),
    (["--state", "sideways"], "--state"),
    (["--gap"], "--gap"),
    (["--bogus", "1"], "--bogus"),
]


@pytest.mark.parametrize("args,name", BAD, ids=[" ".join(a) for a, _ in BAD])
def test_bad_input_in_process(args, name, capsys):
    old = jax.config.jax_enable_x64
    try:
        code = main(["equilibrium", *args])
    finally:
        jax.config.update("jax_enable_x64", old)
    out, err = capsys.readouterr()
    assert code == 2
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("jaxrod: error: ")
    assert name in lines[0]
    assert "Traceback" not in err


def test_bad_input_subprocess():
    """The real process: non-zero exit, one stderr line naming the parameter, no traceback.
    These fail before anything is compiled, so they cost only the import."""
    cases = [
        (["equilibrium", "--gap", "1.5"], "gap must lie in (0, 1), got 1.5"),
        (["equilibrium", "--psi0", "nan"], "psi0 must be a finite number"),
        (["equilibrium", "--state", "sideways"], "--state"),
        (["frobnicate"], "frobnicate"),
    ]
    procs = [(subprocess.Popen([sys.executable, "-m", "jaxrod", *a], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True), needle) for a, needle in cases]
    for p, needle in procs:
        out, err = p.communicate(timeout=300)
        assert p.returncode == 2, (needle, err)
        assert out == ""
        assert len(err.strip().splitlines()) == 1, err
        assert err.startswith("jaxrod: error: ") and needle in err
        assert "Traceback" not in err


def test_help_and_version(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0
    assert jr.__version__ in capsys.readouterr().out
    with pytest.raises(SystemExit) as e:
        main(["equilibrium", "--help"])
    assert e.value.code == 0
    text = capsys.readouterr().out
    for flag in ("--psi0", "--gap", "--alpha", "--alpha-right", "--state", "--s0", "--n", "--json", "--plot"):
        assert flag in text


def test_unwritable_output_is_one_input_error(tmp_path):
    """Every CLI output file (plots, animations, saved designs) is written inside `writing`:
    an OSError becomes one InputError line naming the option and the path (exit 2)."""
    from jaxrod.cli._main import InputError, writing

    blocker = tmp_path / "file"
    blocker.write_text("")
    target = str(blocker / "shape.png")  # a path below a regular file
    with pytest.raises(InputError, match=r"^plot: cannot write '.*shape\.png': Not a directory$"):
        with writing("plot", target):
            open(target, "w")
    with pytest.raises(InputError, match=r"^animate: cannot write: "):
        with writing("animate"):
            raise PermissionError(13, "Permission denied")
    with writing("plot", target):  # nothing raised: nothing reported
        pass
