"""CPU scaling of the sweep layer: the phase diagram split across 1, 2 and 4 virtual CPU
devices and across 1 and 2 processes (`jax.distributed` on the loopback), both splits
(`shard_map` and `sharding`), and the load imbalance of its members.

Each configuration runs in fresh processes (`--xla_force_host_platform_device_count` is read
when JAX starts): the first `phase_diagram(batch="shard")` call pays the trace and compile,
a second call on other fold angles (the same shapes: the same program) measures the run.
Numbers are checked against the one-device run (identical to 1e-9 deg, same kinds).

Load balance: every fold angle's row is also timed alone (one device, one member per call).
A batch of D members takes as long as its slowest, so dealing the rows in order in batches
of D costs sum(max of each batch), against sum(costs) / D for a perfect split; the ratio is
the imbalance.

    python benchmarks/bench_sweep.py          # writes results/sweep.{json,md}
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import socket
import subprocess
import sys
import time

# run times of the steady state: XLA's optimizing code generation from the first call (jaxrod's
# default "auto" compile mode reaches it once a program's calls have run long enough)
os.environ.setdefault("JAXROD_COMPILE", "optimized")

HERE = os.path.dirname(os.path.abspath(__file__))
GAPS = [round(0.2 + 0.05 * i, 2) for i in range(13)]
PSI_A = [20.0, 40.0, 60.0, 80.0, 100.0, 120.0, 150.0, 180.0]
PSI_B = [round(22.0 + 5.0 * i, 1) for i in range(32)]  # 22 ... 177 deg
N = 48
POINT_GAPS = [0.3, 0.5, 0.7, 0.8, 0.9]


def worker(args):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "")
                               + f" --xla_force_host_platform_device_count={args.devices}").strip()
    import jax

    jax.config.update("jax_enable_x64", True)
    if args.processes > 1:
        jax.distributed.initialize(f"127.0.0.1:{args.port}", num_processes=args.processes,
                                   process_id=args.process_id, initialization_timeout=300)
    import numpy as np

    import jaxrod as jr

    res = {"devices": jax.device_count(), "processes": jax.process_count(), "split": args.split}
    t0 = time.perf_counter()
    a = jr.phase_diagram(PSI_A, GAPS, n=N, batch="shard", split=args.split, progress=False)
    res["first_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    b = jr.phase_diagram(PSI_B, GAPS, n=N, batch="shard", split=args.split, progress=False)
    res["run_s"] = time.perf_counter() - t0
    res["alpha_c_up"] = np.nan_to_num(a["alpha_c_up"].values, nan=-999).tolist()
    res["kind_up"] = a["kind_up"].values.tolist()
    res["alpha_c_up_b"] = np.nan_to_num(b["alpha_c_up"].values, nan=-999).tolist()
    if args.member_costs:
        # snap angles point by point (both paths): points that snap against points that do not
        import jax.numpy as jnp

        mesh = jr.Mesh(N)

        def angles(pt, _):
            r = jr.snap_angles(jr.Scene(jr.Strip(psi0=jnp.radians(pt["psi0"])), jr.Clamps(pt["gap"]), mesh))
            return {"snaps": r.up.snaps.astype(jnp.int32) + r.down.snaps.astype(jnp.int32)}

        sm = jr.ShardedMap(angles)
        pts = jr.grid(psi0=[30.0, 90.0, 180.0], gap=POINT_GAPS)
        sm({k: v[:1] for k, v in pts.items()})  # compile
        point_costs, snapping = [], []
        for i in range(pts["psi0"].size):
            t0 = time.perf_counter()
            out, _ = sm({k: v[i:i + 1] for k, v in pts.items()})
            point_costs.append(time.perf_counter() - t0)
            snapping.append(int(out["snaps"][0]))
        res["point_costs"], res["point_snapping_paths"] = point_costs, snapping
        res["points"] = {k: v.tolist() for k, v in pts.items()}
        costs = []
        for p in PSI_B:
            t0 = time.perf_counter()
            jr.phase_diagram([p], GAPS, n=N, batch="shard", split=args.split, progress=False)
            costs.append(time.perf_counter() - t0)
        res["member_costs"] = costs
    if jax.process_index() == 0:
        with open(args.result, "w") as fh:
            json.dump(res, fh)


def run(devices, processes, split, member_costs=False, timeout=1800):
    port = 0
    if processes > 1:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
    result = f"/tmp/bench_sweep_{devices}_{processes}_{split}.json"
    if os.path.exists(result):
        os.remove(result)
    cmd = [sys.executable, __file__, "--worker", "--devices", str(devices), "--processes", str(processes),
           "--port", str(port), "--split", split, "--result", result] + (["--member-costs"] if member_costs else [])
    t0 = time.perf_counter()
    procs = [subprocess.Popen(cmd + ["--process-id", str(i)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                              text=True) for i in range(processes)]
    for p in procs:
        _, err = p.communicate(timeout=timeout)
        if p.returncode:
            raise RuntimeError(err[-2000:])
    wall = time.perf_counter() - t0
    with open(result) as fh:
        r = json.load(fh)
    r["wall_s"] = wall
    return r


def imbalance(costs, d):
    batches = [costs[i:i + d] for i in range(0, len(costs), d)]
    return sum(max(b) for b in batches) / (sum(costs) / d)


def main():
    import numpy as np

    # the benchmark measures compiles: no persistent compilation cache
    os.environ.pop("JAX_COMPILATION_CACHE_DIR", None)
    configs = [(1, 1, "shard_map"), (2, 1, "shard_map"), (4, 1, "shard_map"), (2, 1, "sharding"),
               (4, 1, "sharding"), (1, 2, "shard_map"), (2, 2, "shard_map")]  # (devices per process, processes, split)
    rows = []
    base = None
    for dev, proc, split in configs:
        print(f"devices per process {dev}, processes {proc}, {split} ...", file=sys.stderr, flush=True)
        r = run(dev, proc, split, member_costs=(dev, proc, split) == (1, 1, "shard_map"))
        if base is None:
            base = r
        err = float(np.max(np.abs(np.asarray(r["alpha_c_up"]) - np.asarray(base["alpha_c_up"]))))
        same_kinds = r["kind_up"] == base["kind_up"]
        rows.append(dict(devices=r["devices"], processes=r["processes"], split=split,
                         first_call_s=round(r["first_s"], 2), run_s=round(r["run_s"], 2),
                         rows_per_min=round(len(PSI_B) * 60 / r["run_s"], 1),
                         speedup=round(base["run_s"] / r["run_s"], 2), max_diff_deg=err, same_kinds=same_kinds))
        if "member_costs" in r:
            costs = r["member_costs"]
            points = dict(points=r["points"], cost_s=[round(c, 4) for c in r["point_costs"]],
                          snapping_paths=r["point_snapping_paths"])
    imb = {d: round(imbalance(costs, d), 3) for d in (2, 4, 8)}
    out = dict(benchmark="bench_sweep", date=datetime.date.today().isoformat(), machine=platform.processor()
               or platform.machine(), cpus=os.cpu_count(), python=platform.python_version(),
               grid=dict(psi0_deg=PSI_A, psi0_deg_run=PSI_B, gaps=GAPS, n=N), rows=rows,
               member_costs_s=[round(c, 3) for c in costs], imbalance=imb,
               member_cost_spread=round(max(costs) / (sum(costs) / len(costs)), 3), snap_angle_points=points)
    pc, sn = np.asarray(points["cost_s"]), np.asarray(points["snapping_paths"])
    by = {k: float(np.mean(pc[sn == k])) for k in sorted(set(sn.tolist()))}
    out["snap_angle_point_cost_by_snapping_paths"] = by
    out["snap_angle_point_imbalance"] = {d: round(imbalance(pc.tolist(), d), 3) for d in (2, 4, 8)}
    res_dir = os.path.join(HERE, "results")
    with open(os.path.join(res_dir, "sweep.json"), "w") as fh:
        json.dump(out, fh, indent=1)
    lines = [f"# Sweep scaling on the CPU ({out['date']}, {out['cpus']} cores)", "",
             f"Phase diagram, {len(PSI_B)} fold angles x {len(GAPS)} gaps at N = {N} "
             "(`phase_diagram(batch=\"shard\")`): one fold angle's row of gaps per device per call. "
             "`first call` includes trace and compile (no persistent cache); `run` is a second call "
             "on other fold angles (the same program). `speedup` is against one device.", "",
             "| devices | processes | split | first call (s) | run (s) | rows / min | speedup | max diff vs 1 device (deg) | same kinds |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['devices']} | {r['processes']} | {r['split']} | {r['first_call_s']} | {r['run_s']} | "
                     f"{r['rows_per_min']} | {r['speedup']} | {r['max_diff_deg']:.1e} | {r['same_kinds']} |")
    lines += ["", f"Load balance: the {len(costs)} rows alone cost "
              f"{min(costs):.2f} ... {max(costs):.2f} s (max / mean {out['member_cost_spread']}). "
              "Dealt in order in batches of D, the batches cost this much more than a perfect split: "
              + ", ".join(f"D = {d}: {v}x" for d, v in imb.items()) + ".",
              "", f"Snap angles point by point (`snap_angles`, both paths, N = {N}, Psi0 = 30, 90, 180 deg x "
              f"G/L = {', '.join(map(str, POINT_GAPS))}): mean cost by the number of paths that snap: "
              + ", ".join(f"{k} paths {v * 1e3:.0f} ms" for k, v in by.items())
              + "; dealt in order in batches of D: "
              + ", ".join(f"D = {d}: {v}x" for d, v in out["snap_angle_point_imbalance"].items()) + "."]
    with open(os.path.join(res_dir, "sweep.md"), "w") as fh:
        fh.write("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--worker", action="store_true")
    ap.add_argument("--devices", type=int, default=1)
    ap.add_argument("--processes", type=int, default=1)
    ap.add_argument("--process-id", type=int, default=0)
    ap.add_argument("--port", type=int, default=0)
    ap.add_argument("--split", default="shard_map")
    ap.add_argument("--result", default=None)
    ap.add_argument("--member-costs", action="store_true")
    a = ap.parse_args()
    worker(a) if a.worker else main()
