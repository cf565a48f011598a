#!/usr/bin/env python
"""Batched throughput: many strips in one compiled call (`jax.vmap`), CPU and GPU.

Run from the repository root (on whatever device JAX sees first):

    python benchmarks/bench_batch.py            # batch sizes 1 ... 4096, snap angles up to 205
    python benchmarks/bench_batch.py --quick    # small batches only

What is measured at N = 100 (Psi0 = 60 deg, s0 = 0.02 unless swept):

* equilibria -- `jax.vmap(jr.solve_equilibrium)` over B strips whose fold angles are spread
  over Psi0 in [50, 70] deg and gaps over G/L in [0.45, 0.55], each started from the
  Psi0 = 60 deg, G/L = 0.5 down state (a "nearby state": 3-6 Newton iterations); every
  member's result code is checked;
* snap angles -- `jax.vmap(jr.snap_angles)` over B scenes of a (Psi0, G/L) grid (both
  paths, refined, as in the phase diagram), B = 1, 41, 205 (5 Psi0 x 41 gaps);
* per size: compile time, median wall time of the compiled call, time per member and
  members per second.

The JSON records the device; results go to benchmarks/results/batch_<platform>.json and
.md, so a GPU run (`jaxrod` needs only jax, equinox, jaxtyping there) sits beside the CPU
one.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path


os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# run times of the steady state: XLA's optimizing code generation from the first call (jaxrod's
# default "auto" compile mode reaches it once a program's calls have run long enough)
os.environ.setdefault("JAXROD_COMPILE", "optimized")

import jax  # noqa: E402


jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxrod as jr  # noqa: E402


HERE = Path(__file__).resolve().parent
N = 100


def _git():
    try:
        return subprocess.run(["git", "rev-parse", "--short=10", "HEAD"], capture_output=True, text=True,
                              cwd=HERE).stdout.strip()
    except OSError:
        return "unknown"


def _time(f, *args, repeats=5):
    jax.block_until_ready(f(*args))
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(f(*args))
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))


def _scenes(psis, gaps):
    return jax.vmap(lambda p, g: jr.make_scene(p, g, n=N))(jnp.asarray(psis), jnp.asarray(gaps))


def bench_equilibria(sizes):
    base = jr.make_scene(60.0, 0.5, n=N)
    down = jr.initial_state(base, "down")
    rows = []

    @eqx.filter_jit
    def batch(scenes, theta, force):
        eqs = jax.vmap(lambda s: jr.solve_equilibrium(s, theta, force))(scenes)
        return eqs.result == jr.RESULTS.successful, jax.vmap(jr.fold_height)(eqs)

    for b in sizes:
        rng = np.random.default_rng(0)
        scenes = _scenes(rng.uniform(50.0, 70.0, b), rng.uniform(0.45, 0.55, b))
        t0 = time.perf_counter()
        res, fh = batch(scenes, down.theta, down.force)
        jax.block_until_ready(fh)
        first = time.perf_counter() - t0
        t = _time(batch, scenes, down.theta, down.force)
        ok = int(np.sum(np.asarray(res)))
        rows.append(dict(batch=b, first_call_s=first, time_s=t, per_member_ms=1e3 * t / b,
                         members_per_s=b / t, converged=ok))
        print(f"equilibria B={b:6d}: {1e3 * t:9.2f} ms, {1e3 * t / b:8.4f} ms/member, {ok}/{b} converged",
              flush=True)
    return rows


def bench_snap(sizes):
    rows = []

    @eqx.filter_jit
    def batch(scenes):
        sa = jax.vmap(jr.snap_angles)(scenes)
        return sa.up.alpha_c, sa.down.alpha_c, sa.up.kind, sa.down.kind

    psis_all = np.repeat([30.0, 60.0, 90.0, 120.0, 180.0], 41)
    gaps_all = np.tile(np.linspace(0.1, 0.9, 41), 5)
    for b in sizes:
        if b == 1:
            psis, gaps = np.array([60.0]), np.array([0.5])
        elif b == 41:
            psis, gaps = np.full(41, 60.0), np.linspace(0.1, 0.9, 41)
        else:
            psis, gaps = psis_all[:b], gaps_all[:b]
        scenes = _scenes(psis, gaps)
        t0 = time.perf_counter()
        out = batch(scenes)
        jax.block_until_ready(out)
        first = time.perf_counter() - t0
        t = _time(batch, scenes, repeats=3)
        up = np.degrees(np.asarray(out[0]))
        rows.append(dict(batch=b, first_call_s=first, time_s=t, per_member_ms=1e3 * t / b, members_per_s=b / t,
                         snaps_up=int(np.sum(np.isfinite(up)))))
        print(f"snap_angles B={b:4d}: first call {first:6.1f} s, {t:8.3f} s, {1e3 * t / b:8.2f} ms/member",
              flush=True)
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    dev = jax.devices()[0]
    eq_sizes = (1, 16, 256) if args.quick else (1, 16, 256, 4096)
    sn_sizes = (1, 41) if args.quick else (1, 41, 205)
    meta = dict(date=datetime.datetime.now(datetime.timezone.utc).isoformat(), machine=platform.platform(),
                processor=platform.processor(), cpu_count=os.cpu_count(), device=str(dev),
                device_kind=getattr(dev, "device_kind", ""), platform=dev.platform, python=sys.version.split()[0],
                jax=jax.__version__, jaxrod=jr.__version__, git=_git(), n=N, quick=args.quick,
                load_average=os.getloadavg())
    print(meta, flush=True)
    res = dict(meta=meta, equilibria=bench_equilibria(eq_sizes), snap_angles=bench_snap(sn_sizes))
    out = Path(os.environ.get("BENCH_OUT", HERE / "results"))
    out.mkdir(parents=True, exist_ok=True)
    name = f"batch_{dev.platform}"
    (out / f"{name}.json").write_text(json.dumps(res, indent=2) + "\n")
    lines = [f"# Batched throughput ({dev.platform}: {meta['device_kind'] or meta['processor']})", "",
             f"Generated by `python benchmarks/bench_batch.py` on {meta['date']}; {meta['machine']}, "
             f"{meta['cpu_count']} CPUs, jax {meta['jax']}, git {meta['git']}, N = {N}, float64.", "",
             "| what | batch | compiled call (ms) | per member (ms) | members / s | ok |", "|---|---:|---:|---:|---:|---:|"]
    for r in res["equilibria"]:
        lines.append(f"| equilibria (nearby start) | {r['batch']} | {1e3 * r['time_s']:.2f} | "
                     f"{r['per_member_ms']:.4f} | {r['members_per_s']:.0f} | {r['converged']}/{r['batch']} |")
    for r in res["snap_angles"]:
        lines.append(f"| snap_angles (both paths) | {r['batch']} | {1e3 * r['time_s']:.1f} | "
                     f"{r['per_member_ms']:.2f} | {r['members_per_s']:.1f} | snaps up: {r['snaps_up']} |")
    lines += ["", "A vmapped `lax.while_loop` runs until its slowest member is done, so the per-member time of a",
              "batch is set by its hardest member (snap angles: the longest continuation)."]
    (out / f"{name}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
