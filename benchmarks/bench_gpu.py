"""One-command accelerator benchmark: snap-angle evaluations and brink snaps per minute at
N = 100 for batches of 1 to 16384 designs, with the compile time and the peak device memory.

    python benchmarks/bench_gpu.py                 # every device JAX sees; writes results/gpu.{json,md}
    python benchmarks/bench_gpu.py --max-batch 64  # a quick run (for example on a CPU)

Each batch is a list of random designs (Psi0 in [30, 180] deg, G/L in [0.3, 0.8], seeded)
evaluated by `jaxrod.ShardedMap` over all devices, `batch / devices` members per device:
`snap_angles` (both paths, codes included) and `jaxrod.snap_speed`'s brink snap (RATTLE,
t1 = 2 T, its default). The first call of each batch size is timed as compile + run, then the run is
repeated and the faster of two timed. Target on one modern GPU: at least 10^4 snap-angle
designs per minute.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import time


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--max-batch", type=int, default=16384)
    ap.add_argument("--max-batch-snap", type=int, default=4096, help="largest batch of brink snaps")
    ap.add_argument("--batches", default="", help="comma-separated snap-angle batch sizes (default: 1, 4, 16, "
                    "then doubling up to --max-batch); each size is a program of its own to compile")
    ap.add_argument("--snap-batches", default="", help="likewise for the brink snaps (up to --max-batch-snap)")
    ap.add_argument("--n", type=int, default=100)
    ap.add_argument("--out", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "results"))
    args = ap.parse_args()

    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np

    import jaxrod as jr
    from jaxrod.dynamics._snap_speed import _options, _run

    devices = jax.devices()
    D = len(devices)
    mesh = jr.Mesh(args.n)

    def scene(pt):
        return jr.Scene(jr.Strip(psi0=jnp.radians(pt["psi0"])), jr.Clamps(pt["gap"]), mesh)

    def angles(pt, _):
        s = jr.snap_angles(scene(pt))
        return {"up": s.up.alpha_c, "down": s.down.alpha_c, "code_up": s.up.result._value,
                "code_down": s.down.result._value}

    opts = _options(jr.make_scene(90.0, 0.5, n=args.n), "up", jr.dynamics.NUDGE, 1e-3, None, 2.0, None, "rattle", None)

    def snap(pt, _):
        r = _run(scene(pt), *opts)
        return {"v_s": r.v_s, "code": r.result._value}

    def peak_memory():
        stats = [d.memory_stats() or {} for d in devices]
        peaks = [s.get("peak_bytes_in_use") for s in stats]
        return None if any(p is None for p in peaks) else int(sum(peaks))

    rng = np.random.default_rng(0)
    rows = []
    def sizes(given, top):
        if given:
            return [int(b) for b in given.split(",")]
        out, b = [], 1
        while b <= top:
            out.append(b)
            b *= 4 if b < 16 else 2
        return out

    for what, fn, batches in (("snap_angles", angles, sizes(args.batches, args.max_batch)),
                              ("brink_snap", snap, sizes(args.snap_batches, args.max_batch_snap))):
        for b in batches:
            per = -(-b // D)
            sm = jr.ShardedMap(fn, per_device=per)
            pts = {"psi0": rng.uniform(30.0, 180.0, sm.size), "gap": rng.uniform(0.3, 0.8, sm.size)}
            t0 = time.perf_counter()
            out, _ = sm(pts)
            first = time.perf_counter() - t0
            runs = []
            for _ in range(2):
                t0 = time.perf_counter()
                out, _ = sm(pts)
                runs.append(time.perf_counter() - t0)
            run = min(runs)
            codes = np.concatenate([np.ravel(v) for k, v in out.items() if k.startswith("code")])
            names, counts = np.unique([jr.result_name(int(c)) for c in codes], return_counts=True)
            rows.append(dict(what=what, batch=sm.size, per_device=per, compile_and_first_s=round(first, 3),
                             run_s=round(run, 4), per_minute=round(sm.size * 60.0 / run, 1),
                             successful=float(np.mean(codes == 0)), codes=dict(zip(names.tolist(), counts.tolist())),
                             peak_memory_bytes=peak_memory()))
            print(rows[-1], flush=True)
    out = dict(benchmark="bench_gpu", date=datetime.date.today().isoformat(), backend=jax.default_backend(),
               devices=[d.device_kind for d in devices], machine=platform.machine(), n=args.n, rows=rows)
    os.makedirs(args.out, exist_ok=True)
    tag = "gpu" if jax.default_backend() == "gpu" else jax.default_backend()
    with open(os.path.join(args.out, f"{tag}.json"), "w") as fh:
        json.dump(out, fh, indent=1)
    lines = [f"# Batched throughput on {out['devices'][0]} x {len(devices)} ({out['date']}, N = {args.n})", "",
             "| what | batch | compile + first (s) | run (s) | per minute | successful | codes | peak memory (MB) |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        mem = "" if r["peak_memory_bytes"] is None else f"{r['peak_memory_bytes'] / 2**20:.0f}"
        lines.append(f"| {r['what']} | {r['batch']} | {r['compile_and_first_s']} | {r['run_s']} | {r['per_minute']} | "
                     f"{r['successful']:.3f} | {', '.join(f'{k} {v}' for k, v in r['codes'].items())} | {mem} |")
    with open(os.path.join(args.out, f"{tag}.md"), "w") as fh:
        fh.write("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
