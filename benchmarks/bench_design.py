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
* multi-start throughput: one compiled evaluation of residuals + Jacobian of a fold-height
  objective for B = 1, 64, 1024 starts (designs per second), as one `vmap` over all starts
  (B <= 64 only: at B = 1024 it had not finished after 420 s in an earlier run) and as
  `lax.map` over `vmap`-ed chunks (`design.optimize(..., batch_size=...)`);
* the four design studies at their defaults (`--studies`, on unless `--quick`): wall time
  as a user sees it (first call, compile included), iterations, reached, the design.

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
# run times of the steady state: XLA's optimizing code generation from the first call (jaxrod's
# default "auto" compile mode reaches it once a program's calls have run long enough)
os.environ.setdefault("JAXROD_COMPILE", "optimized")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxrod.design as ds  # noqa: E402
import jaxrod as jr  # noqa: E402
import jaxrod.paper as paper  # noqa: E402
from jaxrod.design._optimize import _linearize_batch  # noqa: E402


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
    ap.add_argument("--chunks", default="1,8", help="lax.map chunk sizes for the multi-start (comma separated)")
    ap.add_argument("--vmap-max", type=int, default=64, help="largest B also run as one vmap")
    ap.add_argument("--studies", action=argparse.BooleanOptionalAction, default=None,
                    help="time the four design studies (default: on, off with --quick)")
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
    chunks = tuple(int(c) for c in args.chunks.split(","))
    out["multistart"] = []
    for B in batches:
        z = param.sample(jax.random.PRNGKey(B), B)
        modes = ([None] if B <= args.vmap_max else []) + [c for c in chunks if c < B]
        for chunk in modes:
            c, s = timed(lambda: _linearize_batch(prob, z, chunk), repeats=1 if B > 64 else 3)
            out["multistart"].append({"starts": B, "batch_size": chunk, "compile_and_first_s": c, "steady_s": s,
                                      "designs_per_s": B / s})
            how = "vmap" if chunk is None else f"lax.map chunks of {chunk}"
            print(f"multistart B={B} ({how}): {s:.3f} s ({B / s:.1f} designs/s)", flush=True)

    do_studies = (not args.quick) if args.studies is None else args.studies
    out["studies"] = run_studies() if do_studies else None

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
          "| multi-start (fold-height residual + Jacobian), starts | evaluation | steady time | designs / s |",
          "|---|---|---|---|"]
    md += [f"| {m['starts']} | {'one vmap' if m['batch_size'] is None else 'lax.map, vmap chunks of %d' % m['batch_size']}"
           f" | {m['steady_s']:.3f} s | {m['designs_per_s']:.1f} |" for m in out["multistart"]]
    if out["studies"]:
        md += ["", "| study | wall (first call, compile included) | iterations | reached | design | achieved |",
               "|---|---|---|---|---|---|"]
        md += [f"| {r['name']} | {r['wall_s']:.1f} s | {r['iterations']} | {r['reached']} | {r['design']} | "
               f"{r['achieved']} |" for r in out["studies"]]
    md += ["", "Notes:", ""] + [f"- {x}" for x in NOTES]
    (res / "design.md").write_text("\n".join(md) + "\n")
    print("wrote", res / "design.json", res / "design.md")


NOTES = [
    "Steady times are medians of repeated calls of the compiled function (B = 1024: one repeat); "
    "'compile' and the studies' wall times include XLA compilation, as a user's first call does.",
    "Multi-start on the CPU: one `vmap` over all starts is the slowest way (every batched loop runs as long "
    "as its slowest member); one start after the other (`lax.map`, chunks of 1) is 3x faster at B = 64, and "
    "is `design.optimize`'s default on the CPU (`batch_size=\"auto\"`). B = 1024 as one `vmap` is not run: it "
    "did not finish within 420 s, and study (a) with 4 starts as one `vmap` can stall at 0 % CPU (the XLA:CPU "
    "batched-LAPACK deadlock of docs/limitations.md); with the sequential default it finishes in the "
    "time above.",
    "Study (a) row: 4 starts on n = 40, the best refined on n = 160 (iterations: coarse best + refinement), "
    "re-checked by an independent `snap_angles` at n = 320 (0.1 deg tolerance). The first table's study (a) is a "
    "single start on the benchmark mesh.",
    "Studies (b) and (c): Levenberg-Marquardt through `jaxrod.snap_speed` (brink snap, RATTLE, differentiable) on "
    "n = 48, re-checked by adaptive Dopri8 (rtol 1e-9) at n = 96 (1 % tolerance for (c)). (b)'s optimum sits at the "
    "gap bound G/L = 0.3; LM stops short of the maximum over Psi0 (23.559 deg, 37.7251), and the study's "
    "golden-section polish in Psi0 at that gap (16 evaluations of the compiled program, no new compilation) "
    "moves it to 26.135 deg, 37.7720: at or above the maximum of a 0.25-deg snap_speed grid (37.7712 at 26.5 "
    "deg, `benchmarks/certify_study_b.py`, study_b_grid.md).",
    "Study (d): held angle beta optimized for the landing margin (4 accepted evaluations), the program run "
    "quasi-statically at n = 40, re-solved at n = 80 and integrated with `jr.simulate` at n = 32.",
]


def run_studies():
    """The four studies at their defaults, each timed from its first call (compile included)."""
    rows = []

    def row(name, wall, iterations, reached, design, achieved):
        rows.append({"name": name, "wall_s": wall, "iterations": iterations, "reached": bool(reached),
                     "design": design, "achieved": achieved})
        print("study", rows[-1], flush=True)

    t = time.perf_counter()
    a = paper.snap_angle_study(progress=False)
    d = a.design
    row("(a) alpha_c = 60 / -70 deg", time.perf_counter() - t,
        int(a.coarse.best.num_iterations) + int(d.num_iterations), a.reached,
        f"Psi0 {d.psi0_deg:.3f} deg, G/L {d.gap:.5f}",
        f"{a.verification.alpha_up_deg:.4f} / {a.verification.alpha_down_deg:.4f} deg at N = {a.verification.n}")
    for name, fn in (("(b) fastest snap, G/L >= 0.3", paper.fastest_snap_study),
                     ("(c) v_s = 20 v* at Psi0 = 90 deg", paper.snap_speed_study)):
        t = time.perf_counter()
        r = fn(progress=False)
        v = r.verification
        pl = getattr(r, "polish", None)
        row(name, time.perf_counter() - t, int(sum(int(x.best.num_iterations) for x in r.runs)), r.reached,
            f"Psi0 {r.design.psi0_deg:.3f} deg, G/L {r.design.gap:.5f}",
            f"v_s {r.v_s:.4f} v* (check {v.v_s:.4f} at N = {v.n})" + (
                f"; Psi0 polish {pl['psi0_before']:.3f} -> {pl['psi0_after']:.3f} deg, v_s {pl['v_s_before']:.4f} -> "
                f"{pl['v_s_after']:.4f} ({pl['evaluations']} evaluations)" if pl else ""))
    t = time.perf_counter()
    r = paper.actuator_study()
    row("(d) programmed actuator", time.perf_counter() - t, len(r.history), r.reached,
        f"Psi0 {r.psi0_deg:g} deg, G/L {r.gap:g}, beta {r.beta_deg:.3f} deg", r.outcome)
    return rows


if __name__ == "__main__":
    main()
