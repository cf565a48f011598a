"""Shared test utilities: finite differences, cached states, residuals, compile counting."""

from __future__ import annotations

import ast
import contextlib
import os
import functools

import jax
import jax.monitoring
import jax.numpy as jnp
import numpy as np

import jaxrod as jr


EPS = float(np.finfo(np.float64).eps)

# Central differences: truncation error ~ h^2 f''' / 6, rounding error ~ eps |f| / h, so the
# best step is h ~ eps^(1/3) * scale (sqrt(eps) is the optimum of a *one-sided* difference;
# for the Newton-solved observables here it gives errors ~1e-7 instead of ~1e-9).
FD_STEP = EPS ** (1.0 / 3.0)


def central_difference(f, x, scale=None):
    """Jacobian of `f: (P,) -> (M,)` at `x` by central differences, shape (M, P).

    Step `h_j = eps^(1/3) * scale_j`. The 2P evaluations run under one `jax.vmap`, so
    `f` may contain a Newton solve (compiled once)."""
    x = jnp.asarray(x, jnp.float64)
    scale = jnp.ones_like(x) if scale is None else jnp.asarray(scale, jnp.float64)
    h = FD_STEP * scale
    # make x +- h exactly representable so the divisor is the true step
    h = (x + h) - x
    E = jnp.diag(h)
    fp = jax.vmap(f)(x[None, :] + E)
    fm = jax.vmap(f)(x[None, :] - E)
    return ((fp - fm) / (2.0 * h[:, None])).T


def solve(scene, theta0, mu0=None, solver=jr.Newton()):
    """`jr.solve_equilibrium` with `mu0` always an array, so every call hits one cache entry."""
    mu0 = jnp.zeros(2) if mu0 is None else mu0
    return jr.solve_equilibrium(scene, theta0, mu0, solver=solver)


@functools.lru_cache(maxsize=None)
def state(psi0_deg=60.0, gap=0.5, kind="up", alpha_deg=0.0, n=100, s0=0.02):
    """A stable up/down state built by `jr.initial_state` (cached per process)."""
    eq = jr.initial_state(jr.make_scene(psi0_deg, gap, alpha_deg, s0=s0, n=n), kind)
    assert eq.result == jr.RESULTS.successful, (psi0_deg, gap, kind, jr.RESULTS[eq.result])
    return eq


def residual(eq):
    """Equilibrium residual computed independently of the solver: the gradient of
    `jr.lagrangian` (theta part in units B/L, force part in units L). Returns two floats."""
    gt, gm = jax.grad(jr.lagrangian, argnums=(0, 1))(eq.theta, eq.force, eq.scene)
    st = eq.scene.strip
    return (float(jnp.max(jnp.abs(gt)) * st.length / st.bending_stiffness),
            float(jnp.max(jnp.abs(gm)) / st.length))


_BACKEND_COMPILE = "/jax/core/compile/backend_compile_duration"


@contextlib.contextmanager
def count_compiles():
    """Counts XLA backend compilations inside the block: `with count_compiles() as c: ...; c[0]`."""
    box = [0]

    def listener(event, duration, **kwargs):
        if event == _BACKEND_COMPILE:
            box[0] += 1

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        yield box
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)


def loglog_slope(x, y):
    """Least-squares slope of log|y| against log x."""
    return float(np.polyfit(np.log(np.asarray(x, float)), np.log(np.abs(np.asarray(y, float))), 1)[0])


def run_notebook(name, timeout=600, extra_cells=()):
    """Execute notebooks/NAME in quick mode (JAXROD_QUICK=1) with nbclient, its committed
    outputs dropped first (`notebooks/execute.py`'s `execute`); returns the executed notebook.
    `extra_cells`: sources of code cells appended to the executed copy (the committed notebook
    is untouched), to report what the kernel holds at the end (figures, variables) for the test
    to read."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parent.parent / "notebooks" / "execute.py"
    spec = importlib.util.spec_from_file_location("_notebooks_execute", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.execute(path.parent / name, quick=True, timeout=timeout, extra_cells=extra_cells)


def notebook_text(nb):
    """Concatenated stream outputs of the code cells."""
    return "\n".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []))


def notebook_record(nb, tag):
    """The JSON object a notebook cell printed on a line `TAG {...}` (the last such line)."""
    import json

    lines = [ln for ln in notebook_text(nb).splitlines() if ln.startswith(tag + " ")]
    assert lines, f"no {tag} line in the notebook's output"
    return json.loads(lines[-1][len(tag) + 1:])


def notebook_images(nb):
    """The PNG images the notebook displayed (bytes), in order."""
    import base64

    return [base64.b64decode(o["data"]["image/png"]) for c in nb.cells if c.cell_type == "code"
            for o in c.get("outputs", []) if "image/png" in o.get("data", {})]


def alpha_c_benchmark(psi0_deg, gap, n=None):
    """alpha_c (deg, up, down) of the committed convergence study
    (benchmarks/results/convergence_alpha_c.json: uniform meshes N = 50, 100, 200, 400,
    s0 = 0.02): the values on an N-segment mesh predicted by the least-squares fit
    a + b / N^2 + c / N^4 to the four (n=None: the fit's limit a, the converged value),
    and the kinds. The fit reproduces the four to < 1e-4 deg; at N = 40, just outside its
    range, it agrees with a two-term fit to 0.015 deg (the predictions' uncertainty)."""
    import json
    from pathlib import Path

    path = Path(__file__).resolve().parent.parent / "benchmarks" / "results" / "convergence_alpha_c.json"
    data = json.loads(path.read_text())["data"]["uniform"]
    key = f"{psi0_deg:g}/{gap:g}"
    ns = np.array([50.0, 100.0, 200.0, 400.0])
    X = np.stack([np.ones(4), ns**-2, ns**-4], 1)
    out = []
    for k in (0, 1):
        c = np.linalg.lstsq(X, np.array([data[f"{int(m)}"][key][k] for m in ns]), rcond=None)[0]
        out.append(float(c[0] if n is None else c @ [1.0, n**-2.0, n**-4.0]))
    return out[0], out[1], data["50"][key][2], data["50"][key][3]



def np_crossings(x, tol=1e-12):
    """Pairs (i, j), j >= i + 2, of segments [x_i, x_i+1], [x_j, x_j+1] that meet, by
    solving p + t r = q + u s for (t, u) (non-parallel segments only): an independent
    numpy check of `jaxrod.energy.contact`."""
    n = len(x) - 1
    out = []
    for i in range(n):
        p, r = x[i], x[i + 1] - x[i]
        for j in range(i + 2, n):
            q, s = x[j], x[j + 1] - x[j]
            den = r[0] * s[1] - r[1] * s[0]
            if abs(den) < 1e-300:
                continue
            w = q - p
            t = (w[0] * s[1] - w[1] * s[0]) / den
            u = (w[0] * r[1] - w[1] * r[0]) / den
            if -tol <= t <= 1 + tol and -tol <= u <= 1 + tol:
                out.append((i, j))
    return out


def crosses(theta, h):
    """Does the chain with angles `theta` and lengths `h` (node 0 at the origin) pass
    through itself (`np_crossings` non-empty)?"""
    t = np.asarray(theta, float)
    h = np.asarray(h, float)
    x = np.concatenate([[[0.0, 0.0]], np.cumsum(h[:, None] * np.stack([np.cos(t), np.sin(t)], 1), 0)])
    return bool(np_crossings(x))


# the phase-diagram grid of the sweep tests: test_phase_diagram's (its compiled chunk is shared)
PHASE_PSI = [30.0, 60.0, 90.0, 180.0]
PHASE_GAPS = [0.3, 0.5, 0.8, 0.82]
PHASE_N = 40

HEAVY_LOOP = 4e6  # loop length of `heavy_member` (about 0.1 s on one CPU core)


def heavy_member(member, shared):
    """A sweep member that takes a while (a long scalar loop; tests that kill a sweep mid-run)."""
    x = member["x"]
    n = (shared * (1.0 + 0.1 * x)).astype(jnp.int32)
    _, y = jax.lax.fori_loop(0, n, lambda i, c: (c[0], c[1] * 0.999999 + c[0] * 1e-6), (x, x))
    return {"y": y}


SWEEP_WORKER = os.path.join(os.path.dirname(os.path.abspath(__file__)), "sweep_worker.py")


def run_sweep_workers(tmp_path, jobs, devices, processes=1, timeout=600):
    """Run `tests/sweep_worker.py --jobs JOBS` in `processes` child processes with `devices`
    virtual CPU devices each (joined by `jax.distributed` on a free loopback port when more
    than one); returns each process's result dict."""
    import json
    import socket
    import subprocess
    import sys

    port = 0
    if processes > 1:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
    tmp_path.mkdir(parents=True, exist_ok=True)
    result = str(tmp_path / "result.json")
    procs = [subprocess.Popen([sys.executable, SWEEP_WORKER, "--devices", str(devices),
                               "--num-processes", str(processes), "--process-id", str(i), "--port", str(port),
                               "--jobs", jobs, "--result", result, "--out", str(tmp_path / "store")],
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
             for i in range(processes)]
    logs = []
    for p in procs:
        try:
            logs.append(p.communicate(timeout=timeout)[0])
        except subprocess.TimeoutExpired:
            for q in procs:
                q.kill()
            raise
    for p, log in zip(procs, logs):
        assert p.returncode == 0, log[-3000:]
    paths = [result] + [f"{result}.{i}" for i in range(1, processes)]
    return [json.load(open(pth)) for pth in paths]


def parse_source(text):
    """`ast.parse` on a fresh thread: CPython 3.11.7's AST constructor checks its recursion
    depth against the thread's, which an earlier test in the same worker can leave off
    ("SystemError: AST constructor recursion depth mismatch", seen under pytest-xdist)."""
    import threading

    out = {}

    def run():
        try:
            out["tree"] = ast.parse(text)
        except BaseException as e:  # handed to the caller's thread
            out["error"] = e

    t = threading.Thread(target=run)
    t.start()
    t.join()
    if "error" in out:
        raise out["error"]
    return out["tree"]
