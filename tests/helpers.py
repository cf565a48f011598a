"""Shared test utilities: finite differences, cached states, residuals, compile counting."""

from __future__ import annotations

import contextlib
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


def run_notebook(name, timeout=600):
    """Execute notebooks/NAME in quick mode (JAXROD_QUICK=1) with nbclient; returns the
    executed notebook. Checks it was committed without outputs."""
    import os
    from pathlib import Path

    import nbclient
    import nbformat

    nb_dir = Path(__file__).resolve().parent.parent / "notebooks"
    nb = nbformat.read(nb_dir / name, as_version=4)
    assert all(c.get("outputs", []) == [] for c in nb.cells if c.cell_type == "code"), "commit without outputs"
    old = os.environ.get("JAXROD_QUICK")
    os.environ["JAXROD_QUICK"] = "1"
    try:
        nbclient.NotebookClient(nb, timeout=timeout, kernel_name="python3",
                                resources={"metadata": {"path": str(nb_dir)}}).execute()
    finally:
        if old is None:
            os.environ.pop("JAXROD_QUICK", None)
        else:
            os.environ["JAXROD_QUICK"] = old
    return nb


def notebook_text(nb):
    """Concatenated stream outputs of the code cells."""
    return "\n".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []))
