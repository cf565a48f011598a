#!/usr/bin/env python
"""Design benchmark: cost of the inverse-design pieces (`design/`).

    python benchmarks/bench_design.py            # n = 100, 1/64/1024 starts
    python benchmarks/bench_design.py --quick    # n = 40, same starts

Measured, side by side in one run (OPENBLAS_NUM_THREADS=1; compile excluded from steady
times, reported separately):

* forward: `jaxrod.snap_angles` (both critical angles) of one design, compiled;
* gradient: `jax.jacfwd` of the critical angles w.r.t. (Psi0, G, s0) via
  `design.critical_angles` (forward solve + implicit fold / branch-point sensitivity);
  ratio gradient / forward (target <= 3);
* study (a): wall time and iterations of alpha_c_up = 60, alpha_c_down = -70 (single start
  from the default design on the design mesh, compile included and excluded);
* multi-start throughput: one vmapped evaluation of residuals + Jacobian of a fold-height
  objective for B = 1, 64, 1024 starts (designs per second).

Writes benchmarks/results/design.json and design.md.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import design as ds  # noqa: E402
import jaxrod as jr  # noqa: E402


def timed(fn, repeats=5):
    t = time.perf_counter()
    jax.block_until_ready(fn())
    first = time.perf_counter() - t
    ts = []
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(fn())
        ts.append(time.perf_counter() - t)
    return first, float(np.median(ts))


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--batches", default="1,64,1024", help="multi-start batch sizes (comma separated)")
    args = ap.parse_args(argv)
    n = 40 if args.quick else 100
    batches = tuple(int(b) for b in args.batches.split(","))
    out = {"date": datetime.datetime.now().isoformat(timespec="seconds"), "machine": platform.platform(),
           "processor": platform.processor(), "cpus": os.cpu_count(), "python": sys.version.split()[0],
           "jax": jax.__version__, "jaxrod": jr.__version__, "n": n, "quick": args.quick}
    p = jnp.array([np.radians(60.0), 0.5, 0.02])
    fwd = jax.jit(lambda p: jr.snap_angles(ds.design_scene(p[0], p[1], p[2], n)).up.alpha_c)

    def crit(p):
        c = ds.critical_angles(p[0], p[1], p[2], n)
        return jnp.stack([c.alpha_up, c.alpha_down])

    grad = jax.jit(jax.jacfwd(crit))
    c_f, t_f = timed(lambda: fwd(p))
    c_g, t_g = timed(lambda: grad(p))
    out["forward"] = {"compile_and_first_s": c_f, "steady_s": t_f}
    out["gradient"] = {"compile_and_first_s": c_g, "steady_s": t_g, "ratio_to_forward": t_g / t_f}
    print(f"forward {t_f:.4f} s, gradient (3 directions, 2 outputs) {t_g:.4f} s, ratio {t_g / t_f:.2f}")

    param = ds.Parametrization(free=("psi0_deg", "gap"))
    terms = (ds.AlphaUp(60.0), ds.AlphaDown(-70.0))
    t = time.perf_counter()
    r1 = ds.optimize(terms, param, n=n, max_iter=30, progress=False)
    wall1 = time.perf_counter() - t
    t = time.perf_counter()
    r2 = ds.optimize(terms, param, n=n, max_iter=30, progress=False)
    wall2 = time.perf_counter() - t
    b = r2.best
    out["study_a"] = {"wall_with_compile_s": wall1, "wall_s": wall2, "iterations": int(b.num_iterations),
                      "reached": bool(b.reached), "psi0_deg": b.psi0_deg, "gap": b.gap,
                      "alpha_c_up": float(b.achieved[0]), "alpha_c_down": float(b.achieved[1])}
    print("study a", out["study_a"])
    del r1

    prob = ds.Problem((ds.FoldHeight(-0.2, state="down"),), param, n)
    out["multistart"] = []
    for B in batches:
        z = param.sample(jax.random.PRNGKey(B), B)
        f = eqx_jit_batch(prob)
        c, s = timed(lambda: f(z), repeats=2 if B > 64 else 3)
        out["multistart"].append({"starts": B, "compile_and_first_s": c, "steady_s": s, "designs_per_s": B / s})
        print(f"multistart B={B}: {s:.3f} s ({B / s:.1f} designs/s)")

    res = Path(__file__).parent / "results"
    res.mkdir(exist_ok=True)
    (res / "design.json").write_text(json.dumps(out, indent=2) + "\n")
    md = [f"# Design benchmark ({out['date']}, {out['machine']}, {out['cpus']} cpus, jax {out['jax']}, n = {n})",
          "", "| quantity | value |", "|---|---|",
          f"| forward `snap_angles` (steady) | {t_f * 1e3:.1f} ms |",
          f"| gradient of both alpha_c w.r.t. (Psi0, G, s0), jacfwd (steady) | {t_g * 1e3:.1f} ms |",
          f"| gradient / forward | {t_g / t_f:.2f} (target <= 3) |",
          f"| compile forward / gradient | {c_f:.1f} s / {c_g:.1f} s |",
          f"| study (a) 60 / -70 deg: wall (with compile) | {wall2:.2f} s ({wall1:.1f} s) |",
          f"| study (a) iterations, reached | {int(b.num_iterations)}, {bool(b.reached)} |",
          f"| study (a) design | Psi0 = {b.psi0_deg:.3f} deg, G/L = {b.gap:.4f} |", "",
          "| multi-start (fold-height residual + Jacobian), starts | steady time | designs / s |", "|---|---|---|"]
    md += [f"| {m['starts']} | {m['steady_s']:.3f} s | {m['designs_per_s']:.1f} |" for m in out["multistart"]]
    (res / "design.md").write_text("\n".join(md) + "\n")
    print("wrote", res / "design.json", res / "design.md")


def eqx_jit_batch(prob):
    from design._optimize import _linearize_batch

    return lambda z: _linearize_batch(prob, z)


if __name__ == "__main__":
    main()
