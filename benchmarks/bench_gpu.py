#!/usr/bin/env python
"""One prepared accelerator benchmark: batched snap angles at N = 100 on one GPU, within 5 minutes.

    python benchmarks/bench_gpu.py                        # B = 1, 128, 1024, 4096; results/batch_gpu.{json,md}
    python benchmarks/bench_gpu.py --quick --out /tmp/b   # smoke test anywhere (N = 24, B = 1, 4)

It runs `bench_batch.py`'s snap-angle measurement (see its docstring for the scenes and the
columns) on the first device JAX sees: per B, the compile of `jax.jit(jax.vmap(
jr.snap_angles))`, the compiled batch's run (median of `--repeats` = 2 runs, i.e. their mean,
below B = 1024, one run from 1024 on: repeats cost budget), members/s and snap-angle evaluations
per minute (the target on one modern GPU: at least 10^4 per minute at N = 100), the program's
`memory_analysis()` and the device's peak memory. The loop of single calls runs over the first
16 members at B <= 128 only (single calls on a GPU cost about a second each); a larger batch
takes the loop's per-member time measured so far and is compared with the single calls of the
members that were looped before (a smaller random sample is the first members of a larger one,
so B = 1's member is checked in every random batch).

Time budget (`--budget-s`, default 300 s for the whole command, import and compiles included,
`--margin-s` of it kept for writing): before each size the time it would take is projected
from the sizes measured (the largest compile so far x 1.25 plus the runs, scaled from the
last size as B^k with k fitted to the last two sizes within [0.5, 1]); a size whose projection
exceeds what is left is skipped with every larger one, and the table says so. If a size
still overruns, the command writes what it has (that size marked as stopped by the budget)
and exits when the budget is spent. The tables are also rewritten after every size.

The brink-snap throughput (`snap_speed`'s RATTLE run over 2 T) of the earlier version of
this script was dropped: its own compile and batched runs of thousands of steps do not fit
in the 5-minute budget beside the snap angles. Only one device is used (`jax.jit`'s default).
"""

from __future__ import annotations

import time


T_START = time.perf_counter()

import argparse  # noqa: E402
import os  # noqa: E402
import sys  # noqa: E402
import threading  # noqa: E402
from pathlib import Path  # noqa: E402


HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import bench_batch as bb  # noqa: E402  (enables float64, sets JAXROD_COMPILE=optimized unless set)


TARGET_PER_MINUTE = 1e4


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=None, help="segments (default 100; 24 with --quick)")
    ap.add_argument("--batches", default=None, help="comma-separated sizes (default 1,128,1024,4096; 1,4 quick)")
    ap.add_argument("--quick", action="store_true", help="smoke test: N = 24, B = 1, 4")
    ap.add_argument("--budget-s", type=float, default=300.0, help="wall-time budget of the whole command")
    ap.add_argument("--margin-s", type=float, default=15.0, help="part of the budget kept for writing and exit")
    ap.add_argument("--repeats", type=int, default=2, help="timed runs of each compiled batch below B = 1024")
    ap.add_argument("--loop-members", type=int, default=16, help="single calls timed per size")
    ap.add_argument("--loop-max-batch", type=int, default=128, help="no loop above this size")
    ap.add_argument("--out", default=str(HERE / "results"), help="output folder")
    args = ap.parse_args(argv)
    n = args.n or (24 if args.quick else 100)
    batches = [int(b) for b in (args.batches or ("1,4" if args.quick else "1,128,1024,4096")).split(",")]
    deadline = T_START + args.budget_s - args.margin_s

    def left():
        return deadline - time.perf_counter()

    meta = bb.machine_meta(n=n, batches=batches, quick=args.quick, repeats=args.repeats,
                           loop_members=args.loop_members, loop_max_batch=args.loop_max_batch,
                           budget_s=args.budget_s, script="benchmarks/bench_gpu.py",
                           argv=" ".join(sys.argv[1:] if argv is None else argv))
    bb.log(meta)
    platform = meta["platform"]
    name = ("batch_gpu" if platform == "gpu" else f"batch_gpu_script_{platform}") + ("_quick" if args.quick else "")
    state = dict(rows=[], error=None, closed=False)
    lock = threading.Lock()

    def notes(rows):
        measured = [r for r in rows if r["what"] == "snap_angles jit(vmap)" and r.get("batch_call_s") is not None]
        best = max(measured, key=lambda r: r["evaluations_per_minute"], default=None)
        out = []
        if best is not None:
            ok = best["evaluations_per_minute"] >= TARGET_PER_MINUTE
            out.append(f"Best throughput: {best['evaluations_per_minute']:.0f} snap-angle evaluations per minute "
                       f"(B = {best['batch']}, N = {n}); target >= {TARGET_PER_MINUTE:.0e} per minute at N = 100: "
                       f"**{'met' if ok and n == 100 else ('not met' if n == 100 else 'not applicable (N != 100)')}**.")
        out.append(f"Time budget {args.budget_s:.0f} s for the whole command; wall time so far "
                   f"{time.perf_counter() - T_START:.0f} s. Loop of single calls: the first {args.loop_members} "
                   f"members, at B <= {args.loop_max_batch} only.")
        return out + [""]

    def save(rows, final=False):
        with lock:
            if state["closed"]:
                return None  # the main thread wrote the final tables (budget spent)
            state["closed"] = final
            rows = list(rows)
            return bb.write(args.out, name, meta, {"snap_angles": rows}, n, "Batched snap angles, one accelerator",
                            extra_gpu=True, notes=notes(rows))

    def on_row(rows):
        with lock:
            state["rows"] = list(rows)
        save(rows)

    def work():
        try:
            bb.bench_snap_angles(batches, n, repeats=args.repeats, loop_cap=args.loop_members,
                                 loop_max_batch=args.loop_max_batch, budget=left,
                                 min_exponent=0.5 if platform != "cpu" else 1.0, on_row=on_row)
        except BaseException as e:  # noqa: BLE001 - reported in the table, then re-raised below
            state["error"] = e

    worker = threading.Thread(target=work, name="bench-gpu", daemon=True)
    worker.start()
    worker.join(timeout=max(left(), 0.0))
    with lock:
        rows = list(state["rows"])
    if worker.is_alive():
        done = {r["batch"] for r in rows if r["what"].startswith("snap_angles jit")}
        rest = [b for b in batches if b not in done]
        for i, b in enumerate(rest):
            why = ("stopped: the time budget ran out during this size" if i == 0
                   else "not run: the time budget ran out")
            rows.append(dict(what="snap_angles jit(vmap)", batch=b, skipped=why))
        bb.log(f"time budget spent; {rest} not finished")
    lines = save(rows, final=True)
    print("\n".join(lines), flush=True)
    if worker.is_alive():
        os._exit(0)  # the worker is inside an XLA call that cannot be interrupted
    if state["error"] is not None:
        raise state["error"]


if __name__ == "__main__":
    main()
