"""Snap angles under manufacturing scatter: what a batch of members costs.

    python benchmarks/bench_scatter.py [--n 100] [--samples 256] [--quick]

Design Psi0 = 60 deg, G/L = 0.5, s0 = 0.02 L with Psi0 +- 10 deg (normal), float64, in
jaxrod's default compile mode as users call it:

- `jaxrod.design.scatter_statistics` (one batch of `samples` members, `jax.vmap` of
  `jr.snap_angles`): first call (trace + compile + run) and the median of 3 calls once compiled;
- the same members as a loop of single `jr.snap_angles` calls (compiled once before timing);
- `jax.grad` of `jaxrod.design.scatter_mean` (the mean's gradient in Psi0, G, s0): first call
  and once compiled.

Results: benchmarks/results/scatter.{json,md} (the machine, date and load average with them).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxrod as jr  # noqa: E402
import jaxrod.design as jd  # noqa: E402
from jaxrod.design._critical import design_scene  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_batch import machine_meta  # noqa: E402

HERE = Path(__file__).resolve().parent
DESIGN = (60.0, 0.5, 0.02)


def _timed(f, reps=3):
    t0 = time.perf_counter()
    out = f()
    first = time.perf_counter() - t0
    runs = []
    for _ in range(reps):
        t0 = time.perf_counter()
        f()
        runs.append(time.perf_counter() - t0)
    return out, first, statistics.median(runs)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=100)
    ap.add_argument("--samples", type=int, default=256)
    ap.add_argument("--quick", action="store_true", help="N = 24, 32 samples")
    ap.add_argument("--out", default=str(HERE / "results"))
    a = ap.parse_args(argv)
    n, m = (24, 32) if a.quick else (a.n, a.samples)
    sc = jd.Scatter(psi0_deg=10.0)
    meta = machine_meta(n=n, samples=m, design=DESIGN, scatter="Psi0 +- 10 deg (normal)")

    st, first, once = _timed(lambda: jd.scatter_statistics(*DESIGN, scatter=sc, samples=m, seed=0, n=n))
    members = st.members
    single = jax.block_until_ready(jr.snap_angles(design_scene(math.radians(60.0), 0.5, 0.02, n)))
    del single
    t0 = time.perf_counter()
    loop = [jr.snap_angles(design_scene(math.radians(p), g, s, n)) for p, g, s, _ in members]
    jax.block_until_ready(loop)
    loop_s = time.perf_counter() - t0
    equal = max(abs(float(np.degrees(r.up.alpha_c)) - st.up.alpha_deg[k]) for k, r in enumerate(loop)
                if np.isfinite(st.up.alpha_deg[k]))

    def grad():
        return jax.block_until_ready(jax.jacrev(lambda x: jnp.stack(jd.scatter_mean(
            x[0], x[1], x[2], scatter=sc, samples=m, seed=0, n=n)[:2]))(jnp.array(DESIGN)))

    g, g_first, g_once = _timed(grad, reps=1)
    rows = dict(statistics_first_s=first, statistics_s=once, loop_s=loop_s, per_member_batch_ms=1e3 * once / m,
                per_member_loop_ms=1e3 * loop_s / m, batch_over_loop=loop_s / once, max_member_difference_deg=equal,
                gradient_first_s=g_first, gradient_s=g_once,
                mean_up_deg=st.up.mean, sem_up_deg=st.up.sem, std_up_deg=st.up.std,
                mean_down_deg=st.down.mean, sem_down_deg=st.down.sem, std_down_deg=st.down.std,
                quantiles_up=st.up.quantiles.tolist(), quantiles_down=st.down.quantiles.tolist(),
                dmean_up_dpsi0_deg_per_deg=float(g[0, 0]) * 180 / math.pi)
    meta["load_average_end"] = os.getloadavg()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "scatter.json").write_text(json.dumps(dict(meta=meta, results=rows), indent=1, default=float))
    la0, la1 = meta["load_average_start"], meta["load_average_end"]
    md = [f"# Snap angles under scatter: cost of a batch ({meta['device']})", "",
          f"{meta['date']}, {meta['machine']}, {meta['cpu_count']} cores, jax {meta['jax']}, git {meta['git']}. "
          f"Load average at start {la0[0]:.2f}, at end {la1[0]:.2f}"
          + (" (other jobs shared the cores: times are upper bounds)." if max(la0[0], la1[0]) > 0.5 else "."), "",
          f"Design Psi0 = 60 deg, G/L = 0.5, s0 = 0.02 L; Psi0 +- 10 deg (normal); N = {n}; {m} members; "
          "default compile mode. The batch starts every member from the nominal strip's critical points "
          "(`snap_angles(..., near=)`, checked); the loop is what a user writes: cold single calls.", "",
          "| what | time |", "|---|---:|",
          f"| `scatter_statistics`, first call (trace + compile + run) | {first:.2f} s |",
          f"| `scatter_statistics`, compiled (median of 3) | {once:.3f} s ({1e3 * once / m:.1f} ms a member) |",
          f"| the same members, a loop of single `snap_angles` calls | {loop_s:.3f} s ({1e3 * loop_s / m:.1f} ms a member) |",
          f"| batch against loop | {loop_s / once:.2f}x |",
          f"| `jax.jacrev` of `scatter_mean`, first call | {g_first:.2f} s |",
          f"| `jax.jacrev` of `scatter_mean`, compiled | {g_once:.3f} s |", "",
          f"Members equal their single calls to {equal:.1e} deg. alpha_c up {st.up.mean:.3f} +- {st.up.sem:.3f} deg "
          f"(spread {st.up.std:.3f}), down {st.down.mean:.3f} +- {st.down.sem:.3f} deg (spread {st.down.std:.3f}).", ""]
    (out / "scatter.md").write_text("\n".join(md))
    print("\n".join(md))


if __name__ == "__main__":
    main()
