#!/usr/bin/env python
"""How far study (b)'s design (the fastest snap up, G/L >= 0.3) is from the grid maximum.

Run from the repository root (after `python benchmarks/bench_design.py`, whose study (b)
design it reads from benchmarks/results/design.json, or with --psi0/--gap):

    python benchmarks/certify_study_b.py

`jaxrod.snap_speed` (the objective the study maximizes, same mesh n = 48, same defaults) on
a grid Psi0 = 10, 12, ..., 60 deg x G/L = 0.30, 0.32, 0.35, 0.40, then on a 0.25-deg grid
around the best grid Psi0 at G/L = 0.3. Reports the grid maximum beside the design's v_s and
their relative difference: Levenberg-Marquardt stationarity is not a certificate of a
maximum; this is. Results: benchmarks/results/study_b_grid.json and .md.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import re
import platform
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxrod.design as ds  # noqa: E402
import jaxrod as jr  # noqa: E402


HERE = Path(__file__).resolve().parent
N = 48


def v_s(p, g):
    """snap_speed (snap up) at Psi0 = p deg, G/L = g, s0 = 0.02, n = 48 (study (b)'s mesh)."""
    return float(jr.snap_speed(ds.design_scene(math.radians(p), g, 0.02, N)))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--psi0", type=float, default=None)
    ap.add_argument("--gap", type=float, default=None)
    args = ap.parse_args()
    if args.psi0 is None:
        rec = json.loads((HERE / "results" / "design.json").read_text())
        row = next(r for r in rec["studies"] if r["name"].startswith("(b)"))
        m = re.search(r"Psi0 ([0-9.]+) deg, G/L ([0-9.]+)", row["design"])
        args.psi0, args.gap = float(m.group(1)), float(m.group(2))
    t0 = time.perf_counter()
    v_design = v_s(args.psi0, args.gap)
    psis = np.arange(10.0, 60.01, 2.0)
    gaps = (0.30, 0.32, 0.35, 0.40)
    grid = {g: [v_s(p, g) for p in psis] for g in gaps}
    i = int(np.nanargmax(grid[0.30]))
    fine = np.arange(psis[max(i - 1, 0)], psis[min(i + 1, len(psis) - 1)] + 1e-9, 0.25)
    vf = [v_s(p, 0.30) for p in fine]
    j = int(np.nanargmax(vf))
    best = dict(psi0_deg=float(fine[j]), gap=0.30, v_s=float(vf[j]))
    coarse_best_other_gaps = {g: float(np.nanmax(grid[g])) for g in gaps[1:]}
    out = dict(date=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
               machine=dict(platform=platform.platform(), cpus=os.cpu_count(), jax=jax.__version__), n=N,
               design=dict(psi0_deg=args.psi0, gap=args.gap, v_s=v_design), grid_psi0_deg=psis.tolist(),
               grid=grid_to_json(grid), fine_psi0_deg=fine.tolist(), fine_v_s=vf, grid_max=best,
               max_at_other_gaps=coarse_best_other_gaps, design_below_grid_max=(best["v_s"] - v_design) / best["v_s"],
               wall_s=time.perf_counter() - t0)
    (HERE / "results" / "study_b_grid.json").write_text(json.dumps(out, indent=1))
    L = [f"# Study (b) against a grid of snap_speed (n = {N}, {out['date']})", "",
         f"Design found (benchmarks/results/design.json): Psi0 = {args.psi0:.3f} deg, G/L = {args.gap:.5f}, "
         f"v_s = {v_design:.4f} v*.", "",
         f"Grid maximum: Psi0 = {best['psi0_deg']:.2f} deg (0.25-deg grid), G/L = 0.30, v_s = {best['v_s']:.4f} v*; "
         + (f"the design is {100 * out['design_below_grid_max']:.3f} % below it." if out["design_below_grid_max"] > 0
          else f"the design is at or above it ({-100 * out['design_below_grid_max']:.3f} % above: it lies between "
               "grid points)."), "",
         "Largest v_s on the 2-deg Psi0 grid at larger gaps (v_s falls with G/L, so the bound is active): "
         + ", ".join(f"G/L = {g:.2f}: {v:.4f}" for g, v in coarse_best_other_gaps.items()) + ".", "",
         "| Psi0 (deg) | " + " | ".join(f"G/L = {g:.2f}" for g in gaps) + " |",
         "|---|" + "---|" * len(gaps)]
    for k, p in enumerate(psis):
        L.append(f"| {p:.0f} | " + " | ".join(f"{grid[g][k]:.4f}" for g in gaps) + " |")
    L += ["", f"Machine: {out['machine']}; {out['wall_s']:.0f} s."]
    (HERE / "results" / "study_b_grid.md").write_text("\n".join(L) + "\n")
    print("\n".join(L))


def grid_to_json(grid):
    return {f"{g:.2f}": v for g, v in grid.items()}


if __name__ == "__main__":
    main()
