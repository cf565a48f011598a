"""One process of the sweep tests (`tests/test_sweeps.py`): JAX with `--devices` virtual CPU
devices and, with `--num-processes` > 1, joined to the others through `jax.distributed` on
the loopback. Runs the named jobs and writes their results to `--result` as JSON (process 0)
or `--result.<k>` (process k)."""

import argparse
import json
import os
import sys

p = argparse.ArgumentParser()
p.add_argument("--devices", type=int, default=1)
p.add_argument("--num-processes", type=int, default=1)
p.add_argument("--process-id", type=int, default=0)
p.add_argument("--port", type=int, default=0)
p.add_argument("--jobs", default="toy")
p.add_argument("--out", default=None)
p.add_argument("--result", required=True)
args = p.parse_args()

os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "")
                           + f" --xla_force_host_platform_device_count={args.devices}").strip()
import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
if args.num_processes > 1:
    jax.distributed.initialize(f"127.0.0.1:{args.port}", num_processes=args.num_processes,
                               process_id=args.process_id, initialization_timeout=120)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxrod as jr  # noqa: E402

from helpers import PHASE_GAPS, PHASE_N, PHASE_PSI  # noqa: E402


def toy(member, shared):
    """A member whose loop length depends on the member (unequal costs), with a bad member
    (x = -1 gives NaN) and an integer code."""
    x = member["x"]
    k, y = jax.lax.while_loop(lambda c: c[0] < 3 + jnp.abs(x).astype(jnp.int32) * 2,
                              lambda c: (c[0] + 1, c[1] * shared + 1.0), (0, x))
    y = jnp.where(x == -1.0, jnp.sqrt(x), y)
    return {"y": y, "k": k, "v": jnp.stack([x, x * shared])}


def run_toy(split, devices=None):
    pts = {"x": np.array([0.0, 1.0, 2.0, -1.0, 3.0, 4.0, 5.0])}
    out = None if args.out is None else os.path.join(args.out, f"toy_{split}")
    ds = jr.sweep(toy, pts, shared=np.float64(1.5), out=out, name="toy", mode=split, devices=devices,
                  progress=False)
    return {"y": ds["y"].values.tolist(), "k": ds["k"].values.tolist(), "v": ds["v"].values.tolist(),
            "device": ds["device"].values.tolist(), "device_count": int(ds.attrs["device_count"]),
            "process_count": int(ds.attrs["process_count"])}


def run_phase(batch, split="shard_map", devices=None):
    ds = jr.phase_diagram(PHASE_PSI, PHASE_GAPS, n=PHASE_N, batch=batch, split=split, devices=devices,
                          progress=False)
    return {k: np.where(np.isnan(ds[k].values), -999.0, ds[k].values).tolist()
            for k in ("alpha_c_up", "alpha_c_down", "kind_up", "kind_down", "result_up", "result_down")}


res = {"device_count": jax.device_count(), "process_count": jax.process_count(),
       "local": [d.id for d in jax.local_devices()]}
for job in args.jobs.split(","):
    if job == "toy":
        res["toy_shard_map"] = run_toy("shard_map")
        res["toy_sharding"] = run_toy("sharding")
    elif job == "toy1":
        res["toy_one"] = run_toy("shard_map", devices=jax.devices()[:1])
    elif job == "phase":
        res["phase_shard"] = run_phase("shard")
    elif job == "phase_sharding":
        res["phase_sharding"] = run_phase("shard", split="sharding")
    elif job == "phase_one":
        res["phase_one"] = run_phase("shard", devices=jax.devices()[:1])
    elif job == "phase_scan":
        res["phase_scan"] = run_phase("scan")
    elif job == "speed":
        ds = jr.speed_plane([60.0, 180.0], [0.4, 0.6], n=16, progress=False)
        res["speed"] = {"v_s": ds["v_s"].values.tolist(), "result": ds["result"].values.tolist(),
                        "device": ds["device"].values.tolist()}
        res["speed_direct"] = [[float(jr.snap_speed(jr.make_scene(p, g, 0, n=16))) for g in (0.4, 0.6)]
                               for p in (60.0, 180.0)]
    elif job == "heavy":
        from helpers import HEAVY_LOOP, heavy_member

        jr.sweep(heavy_member, {"x": np.arange(12.0)}, shared=np.float64(HEAVY_LOOP), out=args.out, name="heavy",
                 progress=False)
    elif job == "design":
        import jaxrod.design as dsn

        param = dsn.Parametrization(free=("psi0_deg", "gap"), bounds={"gap": (0.3, 0.9)})
        terms = (dsn.FoldHeight(-0.22, tol=1e-4, state="down"),)
        z0 = jnp.stack([param.from_values(psi0_deg=70.0, gap=0.5), param.from_values(psi0_deg=100.0, gap=0.4),
                        param.from_values(psi0_deg=50.0, gap=0.6)])
        for name, bs in (("design_devices", "devices"), ("design_loop", 1)):
            r = dsn.optimize(terms, param, z0, n=16, max_iter=15, progress=False, batch_size=bs)
            res[name] = {"values": np.asarray(r.values).tolist(), "reached": np.asarray(r.reached).tolist()}
    else:
        sys.exit(f"unknown job {job}")
path = args.result if jax.process_index() == 0 else f"{args.result}.{jax.process_index()}"
with open(path, "w") as fh:
    json.dump(res, fh)
