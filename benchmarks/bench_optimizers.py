#!/usr/bin/env python
"""Levenberg-Marquardt beside Adam (optax) on the design package's least-squares problems.

    python benchmarks/bench_optimizers.py [--quick]

Each problem is solved from the same start by `design.optimize` with `optimizer="lm"` and
with `optax.adam(lr)` for a few learning rates, on the same compiled problem (one residual
and Jacobian evaluation per iteration either way; the first call, which compiles, is run
once before the timed ones). Reported: iterations to the target's tolerance (or the cap),
reached, the design, its achieved values and the steady wall time.

Problems: the fold height of the down state (-0.22 L, G/L free, Psi0 = 70 deg, N = 24);
the two snap angles (alpha_c = 60 / -70 deg, (Psi0, G/L) free, N = 40); the snapping speed
(v_s = 20 v* at Psi0 = 90 deg, G/L free, N = 48, RATTLE brink snap; skipped with --quick).

Writes benchmarks/results/optimizers.json and optimizers.md.
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
# run times of the steady state: XLA's optimizing code generation from the first call (jaxrod's
# default "auto" compile mode reaches it once a program's calls have run long enough)
os.environ.setdefault("JAXROD_COMPILE", "optimized")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
import optax  # noqa: E402

import jaxrod as jr  # noqa: E402
import jaxrod.design as ds  # noqa: E402


def problems(quick):
    out = [("fold height -0.22 L (G/L free, N = 24)", (ds.FoldHeight(-0.22, state="down", tol=1e-5),),
            ds.Parametrization(free=("gap",), fixed={"psi0_deg": 70.0, "s0": 0.02}), 24, 300),
           ("alpha_c = 60 / -70 deg ((Psi0, G/L) free, N = 40)", (ds.AlphaUp(60.0, tol=0.1), ds.AlphaDown(-70.0, tol=0.1)),
            ds.Parametrization(free=("psi0_deg", "gap")), 40, 150)]
    if not quick:
        out.append(("v_s = 20 v* at Psi0 = 90 deg (G/L free, N = 48)", (ds.SnapSpeed(20.0, tol=0.2),),
                    ds.Parametrization(free=("gap",), fixed={"psi0_deg": 90.0, "s0": 0.02}), 48, 60))
    return out


def run(name, terms, param, n, cap, rates):
    rows = []
    ds.optimize(terms, param, n=n, max_iter=1, progress=False)  # compile
    for label, opt, max_iter in [("Levenberg-Marquardt", "lm", 40)] + [
            (f"Adam, lr {lr:g}", optax.adam(lr), cap) for lr in rates]:
        t = time.perf_counter()
        b = ds.optimize(terms, param, n=n, optimizer=opt, max_iter=max_iter, progress=False).best
        wall = time.perf_counter() - t
        rows.append({"problem": name, "optimizer": label, "iterations": int(b.num_iterations), "cap": max_iter,
                     "reached": bool(b.reached), "status": b.status, "psi0_deg": b.psi0_deg, "gap": b.gap,
                     "achieved": [float(x) for x in np.asarray(b.achieved)],
                     "targets": [float(x) for x in np.asarray(b.targets)], "wall_s": wall})
        print(rows[-1], flush=True)
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="skip the snapping-speed problem")
    args = ap.parse_args(argv)
    rates = (0.02, 0.05, 0.2)
    out = {"date": datetime.datetime.now().isoformat(timespec="seconds"), "machine": platform.platform(),
           "cpus": os.cpu_count(), "python": sys.version.split()[0], "jax": jax.__version__,
           "optax": optax.__version__, "jaxrod": jr.__version__, "rows": []}
    for name, terms, param, n, cap in problems(args.quick):
        out["rows"] += run(name, terms, param, n, cap, rates)
    res = Path(__file__).parent / "results"
    (res / "optimizers.json").write_text(json.dumps(out, indent=2) + "\n")
    md = [f"# Levenberg-Marquardt beside Adam ({out['date']}, {out['machine']}, {out['cpus']} cpus, "
          f"jax {out['jax']}, optax {out['optax']})", "",
          "Same start, same compiled problem (one residual and Jacobian evaluation per iteration); wall time "
          "after a first, compiling call.", "",
          "| problem | optimizer | iterations | reached | design | achieved | wall (s) |", "|---|---|---|---|---|---|---|"]
    for r in out["rows"]:
        it = f"{r['iterations']}" + (" (cap)" if r["iterations"] >= r["cap"] and not r["reached"] else "")
        md.append(f"| {r['problem']} | {r['optimizer']} | {it} | {r['reached']} | Psi0 {r['psi0_deg']:.3f} deg, "
                  f"G/L {r['gap']:.5f} | {', '.join(f'{a:.4f}' for a in r['achieved'])} | {r['wall_s']:.2f} |")
    md += ["", "Levenberg-Marquardt solves the Gauss-Newton model of the residuals at each step, so on these "
           "least-squares targets it needs a few iterations where Adam, whose step has a fixed size in the "
           "optimizer's coordinates, needs tens to hundreds; the design package therefore uses LM for "
           "target problems (`optimize`'s default) and optax where the objective is not a sum of squares of "
           "smooth residuals: the actuator programs' hinge losses (`design_program`, Adam)."]
    (res / "optimizers.md").write_text("\n".join(md) + "\n")
    print("wrote", res / "optimizers.md")


if __name__ == "__main__":
    main()
