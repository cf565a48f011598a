#!/usr/bin/env python
"""Equilibrium benchmark: jaxrod's structured O(N) Newton vs. a naive dense baseline.

Run from the repository root:

    python benchmarks/bench_equilibrium.py            # full run, N = 50 ... 800 (a few minutes)
    python benchmarks/bench_equilibrium.py --quick    # smoke test, N = 50, 100

What is measured, at each N (scene: Psi0 = 60 deg, G/L = 0.5, s0 = 0.02 L, uniform mesh):

* continuation step -- from the converged down state at alpha = 0, solve at
  alpha = 0.5 deg (both clamps) with plain Newton (`jr.Newton(minimize=False)`), and with
  the globalized solver (`jr.Newton()`) on the same step;
* rough-guess solve -- `jr.Newton()` at alpha = 0 from `jr.buckled_guess(flat scene,
  up=False)` (the sine-shaped buckling mode of the flat strip), plus `jr.initial_state`
  (the full homotopy) itself;
* eigenvalues -- the 4 smallest constrained eigenvalues by `jr.stability(eq, k=4)`
  (bisection on the Sturm count, modes included) and by dense `eigvalsh` of
  `jr.dense_reduced_hessian(eq)`;
* the naive baseline, written here: the same `jr.lagrangian` on x = (theta, mu), Newton
  with a dense `jax.hessian` + `jnp.linalg.solve` inside a jitted `lax.while_loop`, same
  tolerance and same start; naive stability = `eigvalsh` of the Hessian projected on the
  null space of the constraint border;
* compile time (`jit(f).lower(...)` + `.compile()`), steady time = median over repeats of
  the compiled executable with `block_until_ready`;
* peak memory: peak RSS (`ru_maxrss`) of a fresh subprocess per (method, N) that compiles
  and runs the solve and the 4 eigenvalues, and XLA's own buffer estimate
  (`compiled.memory_analysis()`);
* slope of log(time) vs log(N) (least squares, N = 100 ... 800).

Results go to benchmarks/results/equilibrium.json and benchmarks/results/equilibrium.md.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path


# On small machines a multithreaded OpenBLAS (which jaxlib's CPU LAPACK kernels use, via
# scipy) fights XLA's own threads: a 100x100 eigvalsh took ~130 ms instead of ~1 ms on a
# 2-core VM. Default to one BLAS thread; set OPENBLAS_NUM_THREADS yourself to override.
# (Must happen before numpy / jax are imported.)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# run times of the steady state: XLA's optimizing code generation from the first call (jaxrod's
# default "auto" compile mode reaches it once a program's calls have run long enough)
os.environ.setdefault("JAXROD_COMPILE", "optimized")

import jax  # noqa: E402


jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import jax.tree_util as jtu  # noqa: E402
import numpy as np  # noqa: E402
from jax import lax  # noqa: E402

import jaxrod as jr  # noqa: E402


HERE = Path(__file__).resolve().parent
RESULTS_DIR = HERE / "results"

PSI0_DEG, GAP, ALPHA_STEP_DEG, S0 = 60.0, 0.5, 0.5, 0.02
GTOL = 1e-9  # jaxrod's float64 default, used by the naive baseline too
K_EIG = 4
FULL_NS = (50, 100, 200, 400, 800)
QUICK_NS = (50, 100)
EXTRA_NS = (1600, 3200, 6400)  # structured continuation step only (asymptotic slope)
SLOPE_NS = (100, 200, 400, 800)
TARGET_RATIO_N, TARGET_RATIO = 100, 20.0
TARGET_SLOPE = 1.15  # "no faster than about linearly"


# ----------------------------------------------------------------------------- scenes


def _as_arrays(scene):
    return jtu.tree_map(lambda x: jnp.asarray(x, jnp.float64) if eqx.is_array_like(x) else x, scene)


def target_scene(n, alpha_deg=0.0):
    return _as_arrays(jr.make_scene(PSI0_DEG, GAP, alpha_deg, s0=S0, n=n))


def with_alpha(scene, alpha_deg):
    a = jnp.asarray(math.radians(alpha_deg), jnp.float64)
    return eqx.tree_at(lambda s: (s.clamps.alpha_left, s.clamps.alpha_right), scene, (a, a))


# ----------------------------------------------------------------------------- structured (jaxrod)

PLAIN = jr.Newton(minimize=False)
GLOBAL = jr.Newton()


def _unpack(eq):
    return eq.theta, eq.force, eq.result == jr.RESULTS.successful, eq.num_steps, eq.num_unstable


@jax.jit
def structured_step(scene, theta0, mu0):
    """One continuation step: plain Newton (the full library call, stability count included)."""
    return _unpack(jr.solve_equilibrium(scene, theta0, mu0, solver=PLAIN))


@jax.jit
def globalized_solve(scene, theta0, mu0):
    return _unpack(jr.solve_equilibrium(scene, theta0, mu0, solver=GLOBAL))


@jax.jit
def initial_down(scene):
    return _unpack(jr.initial_state(scene, "down"))


def _equilibrium(scene, theta, mu):
    """An Equilibrium wrapper around a known solution (for stability)."""
    z = jnp.zeros((), jnp.int32)
    return jr.Equilibrium(theta, mu, jr.RESULTS.successful, z, z, scene)


@jax.jit
def bisection_eigs(scene, theta, mu):
    st = jr.stability(_equilibrium(scene, theta, mu), k=K_EIG)
    return st.eigenvalues, st.modes, st.num_unstable


@jax.jit
def dense_eigs(scene, theta, mu):
    return jnp.linalg.eigvalsh(jr.dense_reduced_hessian(_equilibrium(scene, theta, mu)))[:K_EIG]


# ----------------------------------------------------------------------------- naive baseline


def _residual(gt, gm, scene):
    st = scene.strip
    return jnp.maximum(jnp.max(jnp.abs(gt)) * st.length / st.bending_stiffness,
                       jnp.max(jnp.abs(gm)) / st.length)


def _naive_fns(scene, n):
    def f(x):
        return jr.lagrangian(x[:n], x[n:], scene)

    return jax.grad(f), jax.hessian(f)


@jax.jit
def naive_step(scene, theta0, mu0):
    """Newton with a dense autodiff Hessian and a dense LU solve, same stopping rule."""
    n = theta0.shape[0]
    grad, hess = _naive_fns(scene, n)

    def cond(c):
        return ~c[2]

    def body(c):
        x, steps, _ = c
        g = grad(x)
        converged = _residual(g[:n], g[n:], scene) <= GTOL
        dx = jnp.linalg.solve(hess(x), -g)
        stop = converged | (steps >= 100) | ~jnp.all(jnp.isfinite(dx))
        return jnp.where(converged, x, x + dx), jnp.where(converged, steps, steps + 1), stop

    x, steps, _ = lax.while_loop(cond, body, (jnp.concatenate([theta0, mu0]), jnp.zeros((), jnp.int32),
                                              jnp.zeros((), bool)))
    g = grad(x)
    return x[:n], x[n:], _residual(g[:n], g[n:], scene) <= GTOL, steps


@jax.jit
def naive_eigs(scene, theta, mu):
    """Dense Hessian, projected on the null space of the constraint border, eigvalsh."""
    n = theta.shape[0]
    _, hess = _naive_fns(scene, n)
    H = hess(jnp.concatenate([theta, mu]))
    T, P = H[:n, :n], H[:n, n:]
    q, _ = jnp.linalg.qr(P, mode="complete")
    Z = q[:, 2:]
    return jnp.linalg.eigvalsh(Z.T @ T @ Z)[:K_EIG]


# ----------------------------------------------------------------------------- timing


def _block(x):
    return jax.block_until_ready(x)


def _mem_analysis(compiled):
    try:
        m = compiled.memory_analysis()
        return {k: int(getattr(m, k)) for k in ("temp_size_in_bytes", "argument_size_in_bytes",
                                                 "output_size_in_bytes", "generated_code_size_in_bytes")
                if hasattr(m, k)}
    except Exception as e:  # noqa: BLE001 -- not every backend implements it
        return {"error": repr(e)}


def bench(fn, args, *, max_repeats, budget_s, min_repeats=3):
    """AOT-compile `fn` on `args`, then median wall time of the compiled executable."""
    t0 = time.perf_counter()
    lowered = fn.lower(*args)
    t1 = time.perf_counter()
    compiled = lowered.compile()
    t2 = time.perf_counter()
    out = _block(compiled(*args))
    t3 = time.perf_counter()
    times = []
    while len(times) < max_repeats and (len(times) < min_repeats or sum(times) < budget_s):
        s = time.perf_counter()
        _block(compiled(*args))
        times.append(time.perf_counter() - s)
    times = np.asarray(times)
    rec = dict(
        median_ms=1e3 * float(np.median(times)),
        min_ms=1e3 * float(np.min(times)),
        p90_ms=1e3 * float(np.percentile(times, 90)),
        repeats=int(times.size),
        trace_lower_s=t1 - t0,
        compile_s=t2 - t1,
        first_run_s=t3 - t2,
        xla_memory=_mem_analysis(compiled),
    )
    return rec, out, compiled


def bench_direct(call, *, max_repeats, budget_s):
    """Median wall time of an already-compiled Python-level call (dispatch included)."""
    _block(call())
    times = []
    while len(times) < max_repeats and (len(times) < 3 or sum(times) < budget_s):
        s = time.perf_counter()
        _block(call())
        times.append(time.perf_counter() - s)
    return 1e3 * float(np.median(times))


# ----------------------------------------------------------------------------- memory (subprocess)


def _peak_rss_mb():
    """Peak resident set size of this process image, MB. Linux: VmHWM, which (unlike
    ru_maxrss) is not inherited from the parent across fork + exec."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0  # kB
    except OSError:
        pass
    r = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return r / 2**20 if sys.platform == "darwin" else r / 1024.0  # bytes on macOS, KiB on Linux


def _memory_child(method, n, npz):
    """Runs in a fresh process: compile + run the solve and the 4 eigenvalues; print peak RSS."""
    data = np.load(npz)
    theta, mu = jnp.asarray(data["theta"]), jnp.asarray(data["mu"])
    scene = with_alpha(target_scene(n), ALPHA_STEP_DEG)
    _block((theta, mu, scene))
    base = _peak_rss_mb()
    if method == "structured":
        out = _block(structured_step(scene, theta, mu))
        _block(bisection_eigs(scene, out[0], out[1]))
    else:
        out = _block(naive_step(scene, theta, mu))
        _block(naive_eigs(scene, out[0], out[1]))
    peak = _peak_rss_mb()
    print(json.dumps(dict(baseline_mb=base, peak_mb=peak)))


def peak_memory(method, n, theta, mu, timeout_s=300):
    with tempfile.TemporaryDirectory() as td:
        npz = os.path.join(td, "start.npz")
        np.savez(npz, theta=np.asarray(theta), mu=np.asarray(mu))
        try:
            p = subprocess.run([sys.executable, __file__, "--_memory", method, str(n), npz],
                               capture_output=True, text=True, timeout=timeout_s)
        except subprocess.TimeoutExpired:
            return {"error": f"timed out after {timeout_s} s"}
    if p.returncode != 0:
        return {"error": p.stderr.strip().splitlines()[-1] if p.stderr.strip() else f"rc={p.returncode}"}
    rec = json.loads(p.stdout.strip().splitlines()[-1])
    rec["delta_mb"] = rec["peak_mb"] - rec["baseline_mb"]
    return rec


# ----------------------------------------------------------------------------- one N


def run_n(n, *, quick, naive=True, memory=True, log=print):
    reps = dict(max_repeats=30 if quick else 200, budget_s=0.5 if quick else 1.5)
    heavy = dict(max_repeats=5 if quick else 20, budget_s=0.5 if quick else 2.0)
    rec = {"N": n}
    scene0 = target_scene(n)
    scene1 = with_alpha(scene0, ALPHA_STEP_DEG)

    # the start: converged down state at alpha = 0 (also times jr.initial_state)
    r, out, _ = bench(initial_down, (scene0,), min_repeats=2, **heavy)
    theta0, mu0 = out[0], out[1]
    rec["initial_state"] = dict(r, converged=bool(out[2]), num_unstable=int(out[4]),
                                fold_height=float(jr.fold_height(_equilibrium(scene0, theta0, mu0))))
    if not bool(out[2]):
        raise RuntimeError(f"initial_state(down) failed at N={n}")
    log(f"  N={n}: initial_state {r['median_ms']:.1f} ms (compile {r['compile_s']:.1f} s)")

    # continuation step, plain Newton
    r, out, _ = bench(structured_step, (scene1, theta0, mu0), **reps)
    theta_s, mu_s = out[0], out[1]
    rec["step_structured"] = dict(r, converged=bool(out[2]), iterations=int(out[3]), num_unstable=int(out[4]))
    rec["step_structured"]["direct_api_ms"] = bench_direct(
        lambda: jr.solve_equilibrium(scene1, theta0, mu0, solver=PLAIN).theta, **reps)
    log(f"  N={n}: structured step {r['median_ms']:.3f} ms, {int(out[3])} it (compile {r['compile_s']:.2f} s)")

    # same step, globalized solver
    r, out, _ = bench(globalized_solve, (scene1, theta0, mu0), **reps)
    rec["step_globalized"] = dict(r, converged=bool(out[2]), iterations=int(out[3]), num_unstable=int(out[4]),
                                  max_abs_dtheta_vs_plain=float(jnp.max(jnp.abs(out[0] - theta_s))))
    log(f"  N={n}: globalized step {r['median_ms']:.3f} ms, {int(out[3])} it")

    # rough guess: flat strip's buckled-down mode, globalized Newton at alpha = 0
    flat = _as_arrays(jr.make_scene(180.0, GAP, 0.0, s0=S0, n=n))
    guess = jr.buckled_guess(flat, up=False)
    zeros2 = jnp.zeros(2, jnp.float64)
    r, out, _ = bench(globalized_solve, (scene0, guess, zeros2), **reps)
    fh = float(jr.fold_height(_equilibrium(scene0, out[0], out[1])))
    rec["rough_guess"] = dict(r, converged=bool(out[2]), iterations=int(out[3]), num_unstable=int(out[4]),
                              fold_height=fh, reached_down_state=bool(out[2]) and fh < 0 and int(out[4]) == 0,
                              max_abs_dtheta_vs_initial_state=float(jnp.max(jnp.abs(out[0] - theta0))))
    log(f"  N={n}: rough-guess solve {r['median_ms']:.3f} ms, {int(out[3])} it, converged={bool(out[2])}")

    # eigenvalues at the solved step
    r, out, _ = bench(bisection_eigs, (scene1, theta_s, mu_s), **reps)
    lam_b = np.asarray(out[0])
    rec["eig_bisection"] = dict(r, eigenvalues=lam_b.tolist(), num_unstable=int(out[2]))
    r, out, _ = bench(dense_eigs, (scene1, theta_s, mu_s), **heavy)
    lam_d = np.asarray(out)
    rec["eig_dense"] = dict(r, eigenvalues=lam_d.tolist(),
                            max_rel_diff_vs_bisection=float(np.max(np.abs(lam_b - lam_d) / np.abs(lam_d))))
    log(f"  N={n}: eigs bisection {rec['eig_bisection']['median_ms']:.3f} ms, "
        f"dense eigvalsh {r['median_ms']:.3f} ms")

    # naive baseline
    if naive:
        r, out, _ = bench(naive_step, (scene1, theta0, mu0), **heavy)
        rec["step_naive"] = dict(r, converged=bool(out[2]), iterations=int(out[3]),
                                 max_abs_dtheta_vs_structured=float(jnp.max(jnp.abs(out[0] - theta_s))),
                                 max_abs_dmu_vs_structured=float(jnp.max(jnp.abs(out[1] - mu_s))))
        rec["step_naive"]["agrees"] = rec["step_naive"]["max_abs_dtheta_vs_structured"] < 1e-8
        log(f"  N={n}: naive step {r['median_ms']:.3f} ms, {int(out[3])} it "
            f"(compile {r['compile_s']:.2f} s), |dtheta| = {rec['step_naive']['max_abs_dtheta_vs_structured']:.1e}")
        r, out, _ = bench(naive_eigs, (scene1, theta_s, mu_s), **heavy)
        lam_n = np.asarray(out)
        rec["eig_naive"] = dict(r, eigenvalues=lam_n.tolist(),
                                max_rel_diff_vs_bisection=float(np.max(np.abs(lam_b - lam_n) / np.abs(lam_n))))
        log(f"  N={n}: naive eigs {r['median_ms']:.3f} ms")
        rec["ratio_step_naive_over_structured"] = rec["step_naive"]["median_ms"] / rec["step_structured"]["median_ms"]
        rec["ratio_step_naive_over_structured_min"] = rec["step_naive"]["min_ms"] / rec["step_structured"]["min_ms"]
        rec["ratio_eigs_naive_over_bisection"] = rec["eig_naive"]["median_ms"] / rec["eig_bisection"]["median_ms"]

    if memory:
        rec["peak_rss_structured"] = peak_memory("structured", n, theta0, mu0)
        if naive:
            rec["peak_rss_naive"] = peak_memory("naive", n, theta0, mu0)
        log(f"  N={n}: peak RSS structured {rec['peak_rss_structured'].get('peak_mb', float('nan')):.0f} MB"
            + (f", naive {rec['peak_rss_naive'].get('peak_mb', float('nan')):.0f} MB" if naive else ""))
    return rec


def run_extra(n, *, log=print):
    scene0 = target_scene(n)
    scene1 = with_alpha(scene0, ALPHA_STEP_DEG)
    # start from the down state of the coarse problem's route: initial_state is costly to
    # compile at large N, so use the rough-guess solve to build the alpha = 0 state
    flat = _as_arrays(jr.make_scene(180.0, GAP, 0.0, s0=S0, n=n))
    out = globalized_solve(scene0, jr.buckled_guess(flat, up=False), jnp.zeros(2, jnp.float64))
    if not bool(out[2]):
        return {"N": n, "error": "rough-guess solve did not converge"}
    r, o, _ = bench(structured_step, (scene1, out[0], out[1]), max_repeats=100, budget_s=1.5)
    log(f"  N={n}: structured step {r['median_ms']:.3f} ms, {int(o[3])} it")
    return {"N": n, "step_structured": dict(r, converged=bool(o[2]), iterations=int(o[3]))}


# ----------------------------------------------------------------------------- profile of the pieces


def profile_pieces(n, *, log=print):
    """Time the building blocks of one structured Newton iteration (private API)."""
    from jaxrod.linalg import kkt
    from jaxrod.energy.geometry import discretize

    scene0 = target_scene(n)
    scene1 = with_alpha(scene0, ALPHA_STEP_DEG)
    flat = _as_arrays(jr.make_scene(180.0, GAP, 0.0, s0=S0, n=n))
    out = globalized_solve(scene0, jr.buckled_guess(flat, up=False), jnp.zeros(2, jnp.float64))
    theta, mu = out[0], out[1]

    def gfn(scene):
        d = discretize(scene)
        return lambda t, m: jax.grad(jr.lagrangian, argnums=(0, 1))(t, m, scene, d)

    @jax.jit
    def grad_only(scene, t, m):
        return gfn(scene)(t, m)

    @jax.jit
    def assemble(scene, t, m):
        return kkt.assemble(gfn(scene), t, m)

    @jax.jit
    def kkt_solve(K, g):
        return kkt.solve(K, -g[0], -g[1])

    @jax.jit
    def count1(K):
        return kkt.count_below(K, jnp.zeros(1, jnp.float64))

    @jax.jit
    def count14(K):
        return kkt.count_below(K, jnp.linspace(-1.0, 0.0, 14))

    @jax.jit
    def sturm1_scan_only(K):
        return kkt._pivot_negatives(K, jnp.zeros(1, jnp.float64))

    @jax.jit
    def tri3(K, g):
        return lax.linalg.tridiagonal_solve(K.lower, K.diag, K.upper,
                                            jnp.concatenate([g[0][:, None], K.border], axis=1))

    @jax.jit
    def one_plain_iteration(scene, t, m):
        g = gfn(scene)(t, m)
        K = kkt.assemble(gfn(scene), t, m)
        return kkt.solve(K, -g[0], -g[1])

    @jax.jit
    def naive_hessian(scene, t, m):
        return _naive_fns(scene, n)[1](jnp.concatenate([t, m]))

    @jax.jit
    def naive_lu(H, g):
        return jnp.linalg.solve(H, -g)

    K = assemble(scene1, theta, mu)
    g = grad_only(scene1, theta, mu)
    H = naive_hessian(scene1, theta, mu)
    gx = jnp.concatenate(g)
    kw = dict(max_repeats=300, budget_s=0.5)
    pieces = {
        "gradient": bench(grad_only, (scene1, theta, mu), **kw)[0]["median_ms"],
        "assemble_5_hvp": bench(assemble, (scene1, theta, mu), **kw)[0]["median_ms"],
        "tridiagonal_solve_3rhs": bench(tri3, (K, g), **kw)[0]["median_ms"],
        "kkt_solve_incl_schur": bench(kkt_solve, (K, g), **kw)[0]["median_ms"],
        "one_plain_newton_iteration": bench(one_plain_iteration, (scene1, theta, mu), **kw)[0]["median_ms"],
        "sturm_scan_1_shift": bench(sturm1_scan_only, (K,), **kw)[0]["median_ms"],
        "count_below_1_shift": bench(count1, (K,), **kw)[0]["median_ms"],
        "count_below_14_shifts": bench(count14, (K,), **kw)[0]["median_ms"],
        "naive_dense_hessian": bench(naive_hessian, (scene1, theta, mu), **kw)[0]["median_ms"],
        "naive_dense_lu_solve": bench(naive_lu, (H, gx), **kw)[0]["median_ms"],
    }
    log(f"  N={n}: " + ", ".join(f"{k} {v:.3f}" for k, v in pieces.items()))
    return {"N": n, "median_ms": pieces}


# ----------------------------------------------------------------------------- report


def slope(ns, ts):
    ns, ts = np.asarray(ns, float), np.asarray(ts, float)
    ok = np.isfinite(ts) & (ts > 0)
    if ok.sum() < 2:
        return float("nan")
    return float(np.polyfit(np.log(ns[ok]), np.log(ts[ok]), 1)[0])


def machine_info():
    def _v(mod):
        try:
            import importlib.metadata as md
            return md.version(mod)
        except Exception:  # noqa: BLE001
            return None

    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=HERE, capture_output=True, text=True).stdout.strip()
        dirty = bool(subprocess.run(["git", "status", "--porcelain"], cwd=HERE, capture_output=True,
                                    text=True).stdout.strip())
    except Exception:  # noqa: BLE001
        commit, dirty = None, None
    cpu = platform.processor() or None
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return dict(
        platform=platform.platform(), python=platform.python_version(), cpu=cpu, cpu_count=os.cpu_count(),
        jax=jax.__version__, jaxlib=_v("jaxlib"), equinox=_v("equinox"), jaxrod=jr.__version__,
        devices=[str(d) for d in jax.devices()], backend=jax.default_backend(),
        x64=bool(jax.config.read("jax_enable_x64")), git_commit=commit, git_dirty=dirty,
        env={k: os.environ.get(k) for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS",
                                            "XLA_FLAGS", "JAX_PLATFORMS")},
        load_average=list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
    )


def _fmt(x, digits=3):
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "n/a"
    if x >= 100:
        return f"{x:.0f}"
    if x >= 10:
        return f"{x:.1f}"
    return f"{x:.{digits}f}"


def markdown(report):
    m = report["machine"]
    lines = [
        "# Equilibrium benchmark",
        "",
        f"Generated by `python benchmarks/bench_equilibrium.py{' --quick' if report['quick'] else ''}` on "
        f"{report['date']}.",
        "",
        f"Machine: {m['cpu']} ({m['cpu_count']} CPUs), {m['platform']}; Python {m['python']}, "
        f"jax {m['jax']} / jaxlib {m['jaxlib']}, equinox {m['equinox']}, jaxrod {m['jaxrod']} "
        f"(git {str(m['git_commit'])[:10]}{', dirty tree' if m['git_dirty'] else ''}); devices {m['devices']}; "
        f"float64; OPENBLAS_NUM_THREADS={m['env']['OPENBLAS_NUM_THREADS']}; load average at start / end "
        f"{report['load_at_start']} / {m['load_average'][0] if m['load_average'] else 'n/a'}.",
        "",
        f"Scene: Psi0 = {PSI0_DEG:g} deg, G/L = {GAP:g}, s0 = {S0:g} L, uniform mesh of N segments. "
        f"Continuation step: down state at alpha = 0 -> alpha = {ALPHA_STEP_DEG:g} deg. "
        f"Tolerance max|grad| <= {GTOL:g} (nondimensional). Times are medians of the compiled "
        "executable (ms, `block_until_ready`); compile = `lower` + `compile` (s).",
        "",
        "| N | step (structured, ms) | step (globalized, ms) | step (naive, ms) | ratio naive/structured "
        "| rough-guess solve (ms, it) | 4 eigenvalues (bisection, ms) | eigvalsh dense (ms) "
        "| compile structured / naive (s) | peak MB structured / naive |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in report["runs"]:
        s, gl, rg = r["step_structured"], r["step_globalized"], r["rough_guess"]
        nv = r.get("step_naive")
        ratio = r.get("ratio_step_naive_over_structured")
        rough = f"{_fmt(rg['median_ms'])} ({rg['iterations']} it)" + ("" if rg["converged"] else " NOT CONVERGED")
        comp_s = s["trace_lower_s"] + s["compile_s"]
        comp_n = (nv["trace_lower_s"] + nv["compile_s"]) if nv else None
        pm_s = r.get("peak_rss_structured", {}).get("peak_mb")
        pm_n = r.get("peak_rss_naive", {}).get("peak_mb")
        naive_cell = f"{_fmt(nv['median_ms'])} ({nv['iterations']} it)" if nv else "skipped"
        ratio_cell = (f"{ratio:.1f}x (min/min {r['ratio_step_naive_over_structured_min']:.1f}x)"
                      if ratio else "n/a")
        lines.append(
            f"| {r['N']} | {_fmt(s['median_ms'])} ({s['iterations']} it) | {_fmt(gl['median_ms'])} "
            f"| {naive_cell} "
            f"| {ratio_cell} | {rough} | {_fmt(r['eig_bisection']['median_ms'])} "
            f"| {_fmt(r['eig_dense']['median_ms'])} | {_fmt(comp_s, 2)} / {_fmt(comp_n, 2)} "
            f"| {_fmt(pm_s, 0)} / {_fmt(pm_n, 0)} |"
        )
    sl = report["slopes"]
    lines += [
        "",
        "Details:",
        "",
        "| N | initial_state (ms) | naive 4 eigenvalues (ms) | direct `jr.solve_equilibrium` call (ms, dispatch incl.) "
        "| compile globalized / bisection / initial_state (s) | XLA temp buffers structured / naive (MB) "
        "| peak RSS over baseline structured / naive (MB) | max abs dtheta naive vs structured | eigenvalue rel. diff "
        "dense / naive vs bisection |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in report["runs"]:
        s, gl, ist = r["step_structured"], r["step_globalized"], r["initial_state"]
        nv, ne = r.get("step_naive"), r.get("eig_naive")

        def temp(x):
            v = (x or {}).get("xla_memory", {}).get("temp_size_in_bytes")
            return None if v is None else v / 2**20

        def c(x):
            return x["trace_lower_s"] + x["compile_s"]

        ds = r.get("peak_rss_structured", {}).get("delta_mb")
        dn = r.get("peak_rss_naive", {}).get("delta_mb")
        lines.append(
            f"| {r['N']} | {_fmt(ist['median_ms'])} | {_fmt(ne['median_ms']) if ne else 'skipped'} "
            f"| {_fmt(s['direct_api_ms'])} | {_fmt(c(gl), 2)} / {_fmt(c(r['eig_bisection']), 2)} / {_fmt(c(ist), 1)} "
            f"| {_fmt(temp(s), 3)} / {_fmt(temp(nv), 3)} | {_fmt(ds, 0)} / {_fmt(dn, 0)} "
            f"| {nv['max_abs_dtheta_vs_structured']:.1e} | "
            f"{r['eig_dense']['max_rel_diff_vs_bisection']:.1e} / "
            f"{(ne['max_rel_diff_vs_bisection'] if ne else float('nan')):.1e} |"
            if nv else
            f"| {r['N']} | {_fmt(ist['median_ms'])} | skipped | {_fmt(s['direct_api_ms'])} | "
            f"{_fmt(c(gl), 2)} / {_fmt(c(r['eig_bisection']), 2)} / {_fmt(c(ist), 1)} | {_fmt(temp(s), 3)} / n/a "
            f"| {_fmt(ds, 0)} / n/a | n/a | {r['eig_dense']['max_rel_diff_vs_bisection']:.1e} / n/a |"
        )
    if report.get("extra"):
        lines += ["", "Structured continuation step only, larger N (asymptotic check):", "",
                  "| N | step (structured, ms) | iterations |", "|---:|---:|---:|"]
        for r in report["extra"]:
            if "error" in r:
                lines.append(f"| {r['N']} | {r['error']} | |")
            else:
                lines.append(f"| {r['N']} | {_fmt(r['step_structured']['median_ms'])} "
                             f"| {r['step_structured']['iterations']} |")
    lines += ["", f"Slopes of log(time) vs log(N) (least squares over N = {report['slope_ns']}):", ""]
    slm = report.get("slopes_min_times", {})
    for k, v in sl.items():
        vm = slm.get(k, float("nan"))
        lines.append((f"- {k}: {v:.2f}" if math.isfinite(v) else f"- {k}: n/a")
                     + (f" (from min times: {vm:.2f})" if math.isfinite(vm) else ""))
    lines += ["", "Target checks:", ""]
    for t in report["targets"]:
        lines.append(f"- **{'PASS' if t['pass'] else 'FAIL'}** {t['name']}: {t['detail']}")
    if report.get("profile"):
        lines += ["", "Profile of the pieces (median ms; private `jaxrod.linalg.kkt` API):", ""]
        keys = list(report["profile"][0]["median_ms"])
        lines.append("| N | " + " | ".join(k.replace("_", " ") for k in keys) + " |")
        lines.append("|---:|" + "---:|" * len(keys))
        for p in report["profile"]:
            lines.append(f"| {p['N']} | " + " | ".join(_fmt(p["median_ms"][k]) for k in keys) + " |")
    notes = report.get("notes", [])
    if notes:
        lines += ["", "Notes:", ""] + [f"- {x}" for x in notes]
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="N = 50, 100 only, fewer repeats (smoke test)")
    ap.add_argument("--no-memory", action="store_true", help="skip the peak-RSS subprocesses")
    ap.add_argument("--out", type=Path, default=RESULTS_DIR, help="output folder (default benchmarks/results)")
    ap.add_argument("--_memory", nargs=3, metavar=("METHOD", "N", "NPZ"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args._memory:
        method, n, npz = args._memory
        _memory_child(method, int(n), npz)
        return 0

    t_start = time.perf_counter()
    load_at_start = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    ns = QUICK_NS if args.quick else FULL_NS
    print(f"jaxrod equilibrium benchmark, N = {ns}{' (quick)' if args.quick else ''}", flush=True)
    runs = []
    for n in ns:
        runs.append(run_n(n, quick=args.quick, memory=not args.no_memory, log=lambda s: print(s, flush=True)))
    extra, profile = [], []
    if not args.quick:
        print("structured step at larger N:", flush=True)
        extra = [run_extra(n, log=lambda s: print(s, flush=True)) for n in EXTRA_NS]
        print("profile of the pieces:", flush=True)
        profile = [profile_pieces(n, log=lambda s: print(s, flush=True)) for n in (100, 800)]

    slope_ns = [n for n in SLOPE_NS if n in ns] if not args.quick else list(ns)

    def t(key, r, stat="median_ms"):
        return r.get(key, {}).get(stat, float("nan"))

    by_n = {r["N"]: r for r in runs}
    items = {
        "step (structured)": "step_structured",
        "step (globalized)": "step_globalized",
        "step (naive)": "step_naive",
        "rough-guess solve": "rough_guess",
        "4 eigenvalues (bisection)": "eig_bisection",
        "eigvalsh dense": "eig_dense",
        "4 eigenvalues (naive)": "eig_naive",
    }
    slopes = {name: slope(slope_ns, [t(key, by_n[n]) for n in slope_ns]) for name, key in items.items()}
    slopes_min = {name: slope(slope_ns, [t(key, by_n[n], "min_ms") for n in slope_ns]) for name, key in items.items()}
    if extra and 800 in by_n:
        ok = [r for r in extra if "error" not in r]
        xs = [800] + [r["N"] for r in ok]
        name = f"step (structured), N = {xs[0]}..{xs[-1]}"
        slopes[name] = slope(xs, [t("step_structured", by_n[800])] + [r["step_structured"]["median_ms"] for r in ok])
        slopes_min[name] = slope(xs, [t("step_structured", by_n[800], "min_ms")]
                                 + [r["step_structured"]["min_ms"] for r in ok])

    targets = []
    if TARGET_RATIO_N in by_n and "ratio_step_naive_over_structured" in by_n[TARGET_RATIO_N]:
        ratio = by_n[TARGET_RATIO_N]["ratio_step_naive_over_structured"]
        targets.append(dict(name=f"continuation step at N = {TARGET_RATIO_N} >= {TARGET_RATIO:g}x faster than naive",
                            pass_=ratio >= TARGET_RATIO,
                            detail=f"{ratio:.1f}x; ratio per N: " + ", ".join(
                                f"{r['N']}: {r['ratio_step_naive_over_structured']:.1f}x" for r in runs
                                if "ratio_step_naive_over_structured" in r)))
    s = slopes["step (structured)"]
    targets.append(dict(name=f"structured step time grows no faster than ~linearly (slope <= {TARGET_SLOPE:g}) "
                             f"over N = {slope_ns}", pass_=bool(s <= TARGET_SLOPE), detail=f"slope {s:.2f}"))
    agree = all(r.get("step_naive", {}).get("agrees", True) for r in runs)
    worst = max((r.get("step_naive", {}).get("max_abs_dtheta_vs_structured", 0.0) for r in runs), default=0.0)
    targets.append(dict(name="naive and structured solutions agree (max|dtheta| < 1e-8)", pass_=agree,
                        detail=f"worst {worst:.1e}"))
    conv = all(r["step_structured"]["converged"] and r["step_globalized"]["converged"] for r in runs)
    targets.append(dict(name="all continuation steps converged", pass_=conv, detail=""))
    rg = all(r["rough_guess"]["reached_down_state"] for r in runs)
    targets.append(dict(name="rough-guess solve reaches the stable down state", pass_=rg,
                        detail=", ".join(f"N={r['N']}: {r['rough_guess']['iterations']} it, "
                                         f"|dtheta| vs initial_state {r['rough_guess']['max_abs_dtheta_vs_initial_state']:.0e}"
                                         for r in runs)))
    for tg in targets:
        tg["pass"] = bool(tg.pop("pass_"))

    notes = [
        "step (structured) is the whole library call `jr.solve_equilibrium(..., solver=jr.Newton(minimize=False))` "
        "inside `jax.jit`: Newton iterations plus the final Hessian assembly and Sturm count for `num_unstable`, "
        "which the naive baseline does not compute.",
        "The iteration count is Newton updates taken; both solvers then evaluate the gradient once more to see "
        "convergence (same stopping rule, max|grad| <= 1e-9).",
        "rough-guess solve: `jr.Newton()` from `jr.buckled_guess(flat, up=False)` at Psi0 = 60 deg, alpha = 0 "
        "(no homotopy); `initial_state` runs the 3-path homotopy (25 solves per path, vmapped).",
        "peak MB is the peak RSS (Linux VmHWM, else ru_maxrss) of a fresh Python process that imports jax, compiles and runs the solve and the "
        "4 eigenvalues once; most of it is the interpreter, jax and XLA compilation, so the XLA temp-buffer "
        "size is the cleaner measure of the solver's own memory.",
        "At small N both solvers are dominated by XLA:CPU's fixed cost per operation (about 1 us per fused "
        "kernel or custom call, ~50 per structured Newton iteration), not by arithmetic; see the profile table. "
        "The naive solver's O(N^2) Hessian and O(N^3) LU take over from N ~ 200.",
        "direct-call timings include `eqx.filter_jit` dispatch (pytree flattening, cache lookup) on top of the "
        "compiled executable.",
    ]
    report = dict(
        benchmark="equilibrium", quick=args.quick, load_at_start=load_at_start, date=datetime.datetime.now(datetime.timezone.utc).isoformat(),
        machine=machine_info(),
        config=dict(psi0_deg=PSI0_DEG, gap=GAP, s0=S0, alpha_step_deg=ALPHA_STEP_DEG, gtol=GTOL, k=K_EIG, ns=list(ns)),
        runs=runs, extra=extra, profile=profile, slope_ns=slope_ns, slopes=slopes, slopes_min_times=slopes_min,
        ratios_naive_over_structured={r["N"]: r.get("ratio_step_naive_over_structured") for r in runs},
        targets=targets, notes=notes, wall_s=time.perf_counter() - t_start,
    )
    args.out.mkdir(parents=True, exist_ok=True)
    stem = "equilibrium-quick" if args.quick else "equilibrium"  # a smoke test never overwrites the full run
    (args.out / f"{stem}.json").write_text(json.dumps(report, indent=2) + "\n")
    md = markdown(report)
    (args.out / f"{stem}.md").write_text(md)
    print(md)
    print(f"wrote {args.out / (stem + '.json')} and {args.out / (stem + '.md')} ({report['wall_s']:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
