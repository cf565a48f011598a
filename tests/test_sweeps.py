"""Sweeps across devices and processes (`jaxrod.sweeps`): the same numbers as one device, every
device used, a resumable store that loses no finished point and recomputes none. (The phase
diagram split across four devices is checked in test_phase_diagram.py.)

Several devices need a fresh JAX (`--xla_force_host_platform_device_count` is read when the
CPU backend starts), so those checks run `tests/sweep_worker.py` in child processes: one
with 4 virtual devices, and two joined by `jax.distributed` on the loopback with 2 each."""

import json
import os
import socket
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import xarray as xr

import jaxrod as jr
from helpers import SWEEP_WORKER as WORKER, run_sweep_workers
X = np.array([0.0, 1.0, 2.0, -1.0, 3.0, 4.0, 5.0])


def toy(member, shared):
    """As `sweep_worker.toy`: unequal loop lengths, a NaN member (x = -1), an integer output."""
    x = member["x"]
    k, y = jax.lax.while_loop(lambda c: c[0] < 3 + jnp.abs(x).astype(jnp.int32) * 2,
                              lambda c: (c[0] + 1, c[1] * shared + 1.0), (0, x))
    y = jnp.where(x == -1.0, jnp.sqrt(x), y)
    return {"y": y, "k": k, "v": jnp.stack([x, x * shared])}


def reference():
    """The toy outputs one member at a time (plain jit, no sweep)."""
    f = jax.jit(toy)
    outs = [f({"x": jnp.asarray(x)}, jnp.asarray(1.5)) for x in X]
    return {k: np.stack([np.asarray(o[k]) for o in outs]) for k in ("y", "k", "v")}


def _same_toy(got, ref):
    y = np.asarray(got["y"], float)
    assert np.array_equal(np.isnan(y), np.isnan(ref["y"]))
    np.testing.assert_array_equal(y[~np.isnan(y)], ref["y"][~np.isnan(ref["y"])])
    np.testing.assert_array_equal(got["k"], ref["k"])
    np.testing.assert_array_equal(got["v"], ref["v"])


# ---------------------------------------------------------------- one device, in this process

def test_sweep_matches_member_by_member():
    ref = reference()
    for split in ("shard_map", "sharding"):
        ds = jr.sweep(toy, {"x": X}, shared=np.float64(1.5), mode=split, per_device=3, progress=False)
        _same_toy({k: ds[k].values for k in ("y", "k", "v")}, ref)
        # the bad member stays its own: NaN there, every other member finite
        assert np.isnan(ds["y"].values[3]) and np.all(np.isfinite(np.delete(ds["y"].values, 3)))
        assert ds["v"].dims == ("point", "v_0") and ds["k"].dtype == np.int32
        assert ds.attrs["split"] == split and ds.attrs["device_count"] == 1 and ds.attrs["process_count"] == 1
        assert set(ds["device"].values) == {jax.devices()[0].id}
        assert len(ds.attrs["batch_seconds"]) == 3  # 7 members, 3 per batch


def test_grid_order_and_unstack():
    g = jr.grid(a=[1.0, 2.0], b=[10.0, 20.0, 30.0])
    np.testing.assert_array_equal(g["a"], [1, 1, 1, 2, 2, 2])
    np.testing.assert_array_equal(g["b"], [10, 20, 30, 10, 20, 30])
    ds = jr.sweep(lambda m, s: {"s": m["a"] + m["b"]}, g, progress=False)
    grid = ds.drop_vars("point").set_index(point=["a", "b"]).unstack("point")
    np.testing.assert_array_equal(grid["s"].values, [[11, 21, 31], [12, 22, 32]])


@pytest.mark.parametrize("call, match", [
    (lambda: jr.sweep(toy, {"x": [1.0, 2.0], "y": [1.0]}), "points: every parameter"),
    (lambda: jr.sweep(toy, {}), "points: at least one"),
    (lambda: jr.sweep(toy, {"x": [1.0]}, mode="pmap"), "mode must be one of"),
    (lambda: jr.sweep(toy, {"x": [1.0]}, per_device=0), "per_device must be a positive integer"),
    (lambda: jr.sweep(lambda m, s: m["x"], {"x": [1.0]}), "fn: must return a non-empty dict"),
    (lambda: jr.sweep(toy, {"x": [1.0]}, shared=1.5, dims={"v": ("a", "b")}), r"dims\['v'\]"),
    (lambda: jr.speed_plane([60.0], [1.2]), "gap"),
    (lambda: jr.phase_diagram([60.0], [0.5], batch="pmap"), "batch must be"),
    (lambda: jr.phase_diagram([60.0], [0.5], batch="shard", split="pmap"), "split must be one of"),
    (lambda: jr.speed_plane([60.0], [0.5], split="pmap"), "split must be one of"),
])
def test_bad_input_names_the_parameter(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_store_resumes_without_loss_or_recomputation(tmp_path):
    out = str(tmp_path / "store")
    ref = reference()

    class Killed(Exception):
        pass

    def kill_after_first(idx):
        raise Killed(idx)

    with pytest.raises(Killed):
        jr.sweep(toy, {"x": X}, shared=np.float64(1.5), out=out, name="toy", per_device=3, progress=False,
                 on_batch=kill_after_first)
    files = sorted(os.listdir(os.path.join(out, "chunks")))
    assert files == ["points_0_2.nc"]  # the finished batch, and no half-written file
    seen = []
    ds = jr.sweep(toy, {"x": X}, shared=np.float64(1.5), out=out, name="toy", per_device=3, progress=False,
                  on_batch=lambda idx: seen.extend(idx.tolist()))
    assert ds.attrs["computed_points"] == [3, 4, 5, 6] and seen == [3, 4, 5, 6]
    _same_toy({k: ds[k].values for k in ("y", "k", "v")}, ref)
    stored = xr.open_dataset(os.path.join(out, "toy.nc"), engine="scipy").load()
    for k in ("y", "k", "v", "device"):
        np.testing.assert_array_equal(stored[k].values, ds[k].values)
    for k in ("jaxrod_version", "jax_version", "backend", "devices", "device_count", "process_count", "date_utc",
              "fingerprint", "split", "per_device"):
        assert k in stored.attrs, k
    # everything read back: nothing computed, the same numbers
    again = jr.sweep(toy, {"x": X}, shared=np.float64(1.5), out=out, name="toy", per_device=2, progress=False)
    assert again.attrs["computed_points"] == []
    _same_toy({k: again[k].values for k in ("y", "k", "v")}, ref)
    # a damaged batch file: only its points are computed again
    with open(os.path.join(out, "chunks", "points_0_2.nc"), "r+b") as fh:
        fh.truncate(40)
    again = jr.sweep(toy, {"x": X}, shared=np.float64(1.5), out=out, name="toy", per_device=3, progress=False)
    assert again.attrs["computed_points"] == [0, 1, 2]
    _same_toy({k: again[k].values for k in ("y", "k", "v")}, ref)
    # other settings (another `shared`, other attrs): another fingerprint, every point computed
    other = jr.sweep(toy, {"x": X}, shared=np.float64(2.0), out=out, name="toy", per_device=3, progress=False)
    assert other.attrs["computed_points"] == list(range(7))
    other = jr.sweep(toy, {"x": X}, shared=np.float64(1.5), out=out, name="toy", attrs={"n": 2}, per_device=3,
                     progress=False)
    assert other.attrs["computed_points"] == list(range(7))


# ---------------------------------------------------------------- several devices and processes

def _same_phase(a, b, tol):
    for k in a:
        x, y = np.asarray(a[k]), np.asarray(b[k])
        if tol == 0 or k.startswith(("kind", "result")):
            np.testing.assert_array_equal(x, y, err_msg=k)
        else:
            np.testing.assert_allclose(x, y, rtol=0, atol=tol, err_msg=k)


def test_four_virtual_devices(tmp_path):
    (r,) = run_sweep_workers(tmp_path, "toy", devices=4)
    assert r["device_count"] == 4 and r["process_count"] == 1
    ref = reference()
    for split in ("shard_map", "sharding"):
        got = r[f"toy_{split}"]
        _same_toy(got, ref)
        assert got["device"] == [0, 1, 2, 3, 0, 1, 2]  # every device used, members dealt in order
    # (the phase diagram split across four devices: test_phase_diagram.py, beside the chunks it
    # is compared with)


def test_two_processes_on_the_loopback(tmp_path):
    r0, r1 = run_sweep_workers(tmp_path, "toy", devices=2, processes=2)
    assert r0["process_count"] == r1["process_count"] == 2 and r0["device_count"] == 4
    assert set(r0["local"]).isdisjoint(r1["local"])
    ref = reference()
    for r in (r0, r1):  # every process returns the whole result
        for split in ("shard_map", "sharding"):
            got = r[f"toy_{split}"]
            _same_toy(got, ref)
            assert set(got["device"]) == set(r0["local"]) | set(r1["local"])
            assert got["process_count"] == 2


@pytest.mark.slow
def test_devices_and_processes_give_identical_phase_diagrams(tmp_path):
    # 4 devices vs 1, 2 processes vs 1: the same kinds and codes, the angles to round-off (XLA
    # compiles the per-device program for each mesh; the critical angle interpolated across
    # its bisection bracket feels that round-off: 8.5e-11 deg measured)
    (r4,) = run_sweep_workers(tmp_path / "four", "phase,phase_sharding,phase_one,phase_scan", devices=4)
    _same_phase(r4["phase_shard"], r4["phase_one"], 1e-9)
    _same_phase(r4["phase_sharding"], r4["phase_one"], 1e-9)
    _same_phase(r4["phase_shard"], r4["phase_scan"], 1e-9)
    r0, r1 = run_sweep_workers(tmp_path / "two", "phase", devices=2, processes=2)
    _same_phase(r0["phase_shard"], r4["phase_shard"], 1e-9)
    _same_phase(r1["phase_shard"], r4["phase_shard"], 1e-9)


@pytest.mark.slow
def test_speed_plane_on_two_devices(tmp_path):
    (r,) = run_sweep_workers(tmp_path, "speed", devices=2)
    # the same numbers as `snap_speed` one scene at a time (another compiled program: round-off)
    np.testing.assert_allclose(r["speed"]["v_s"], r["speed_direct"], rtol=1e-9)
    assert r["speed"]["result"] == [[0, 0], [0, 0]]
    assert sorted(set(sum(r["speed"]["device"], []))) == [0, 1]


@pytest.mark.slow
def test_multistart_design_split_across_devices(tmp_path):
    (r,) = run_sweep_workers(tmp_path, "design", devices=4)
    np.testing.assert_allclose(r["design_devices"]["values"], r["design_loop"]["values"], rtol=1e-10, atol=1e-12)
    assert r["design_devices"]["reached"] == r["design_loop"]["reached"]


# ---------------------------------------------------------------- the CLI

@pytest.mark.parametrize("extra, needle", [
    (["--num-processes", "2"], "coordinator: --num-processes and --process-id need --coordinator"),
    (["--coordinator", "127.0.0.1:1", "--num-processes", "2"], "num-processes: --coordinator HOST:PORT needs"),
    (["--coordinator", "127.0.0.1:1", "--num-processes", "2", "--process-id", "5"], "process-id: must lie in 0 ... 1"),
    (["--coordinator", "auto", "--process-id", "0"], "coordinator: 'auto' takes"),
])
def test_cli_distributed_options_are_checked(tmp_path, capsys, extra, needle):
    from jaxrod.cli import main

    code = main(["phase-diagram", "--psi0", "60", "--gaps", "0.5", "--out", str(tmp_path / "pd"), *extra])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("jaxrod: error: ") and needle in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


@pytest.mark.slow
def test_cli_phase_diagram_in_two_processes(tmp_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = str(tmp_path / "pd")
    env = dict(os.environ, XLA_FLAGS=os.environ.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=1")
    args = ["phase-diagram", "--psi0", "40,90,180", "--gaps", "0.4,0.6", "--n", "16", "--no-termination", "--json",
            "--out", out, "--coordinator", f"127.0.0.1:{port}", "--num-processes", "2"]
    procs = [subprocess.Popen([sys.executable, "-m", "jaxrod", *args, "--process-id", str(i)], env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for i in range(2)]
    (out0, err0), (out1, err1) = (p.communicate(timeout=600) for p in procs)
    assert procs[0].returncode == 0 and procs[1].returncode == 0, err0[-2000:] + err1[-2000:]
    rec = json.loads(out0)
    assert out1 == "" and rec["devices"] == 2 and rec["processes"] == 2 and rec["batch"] == "shard"
    got = xr.open_dataset(rec["netcdf"], engine="scipy").load()
    ref = jr.phase_diagram([40.0, 90.0, 180.0], [0.4, 0.6], n=16, batch="scan", progress=False)
    for k in ("alpha_c_up", "alpha_c_down"):
        np.testing.assert_allclose(got[k].values, ref[k].values, rtol=0, atol=1e-9)
    for k in ("kind_up", "kind_down", "result_up", "result_down"):
        np.testing.assert_array_equal(got[k].values, ref[k].values)


def test_import_starts_no_backend():
    """`jax.distributed.initialize()` must come before JAX starts a backend: importing jaxrod
    (the CLI and the design package included) must not start one."""
    code = ("import jaxrod, jaxrod.cli, jaxrod.design, jaxrod.cli._statics, jaxrod.cli._dynamics\n"
            "from jax._src import xla_bridge\n"
            "assert not xla_bridge._backends, xla_bridge._backends\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]


def test_cli_speed_plane_shard_refuses_adaptive_solvers(tmp_path, capsys):
    from jaxrod.cli import main

    code = main(["speed-plane", "--batch", "shard", "--solver", "tsit5", "--psi0", "60", "--gaps", "0.5",
                 "--out", str(tmp_path / "sp")])
    err = capsys.readouterr().err
    assert code == 2 and "solver: --batch shard runs RATTLE" in err and len(err.strip().splitlines()) == 1


@pytest.mark.slow
def test_cli_speed_plane_on_two_devices(tmp_path):
    out = str(tmp_path / "sp")
    env = dict(os.environ, XLA_FLAGS=os.environ.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2")
    r = subprocess.run([sys.executable, "-m", "jaxrod", "speed-plane", "--batch", "shard", "--psi0", "60,180",
                        "--gaps", "0.4,0.6", "--n", "16", "--out", out], env=env, capture_output=True, text=True,
                       timeout=900)
    assert r.returncode == 0, r.stderr[-2000:]
    rec = json.loads(r.stdout)
    assert rec["points"] == 4 and rec["snapping"] == 4 and rec["devices"] == 2 and rec["flagged"] == {}
    assert "fit" in rec and os.path.exists(rec["figure"])
    ds = xr.open_dataset(rec["netcdf"], engine="scipy").load()
    assert sorted(set(ds["device"].values.tolist())) == [0, 1]
    direct = [float(jr.snap_speed(jr.make_scene(p, g, 0, n=16), t1=4.0)) for p, g in
              zip(ds["psi0"].values, ds["gap"].values)]
    np.testing.assert_allclose(ds["v_s"].values, direct, rtol=1e-9)


@pytest.mark.slow
def test_sweep_resumes_after_sigkill(tmp_path):
    """A real kill (SIGKILL) in the middle of a sweep: the rerun reads back every finished batch,
    computes exactly the others, and the whole equals a run member by member."""
    import signal
    import time

    from helpers import HEAVY_LOOP, heavy_member

    store = tmp_path / "store"
    p = subprocess.Popen([sys.executable, WORKER, "--jobs", "heavy", "--result", str(tmp_path / "r.json"),
                          "--out", str(store)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    chunks = store / "chunks"
    t0 = time.time()
    while time.time() - t0 < 300 and len(list(chunks.glob("points_*.nc")) if chunks.exists() else []) < 3:
        time.sleep(0.05)
    p.send_signal(signal.SIGKILL)
    p.wait()
    done = sorted(int(f.name.split("_")[1]) for f in chunks.glob("points_*.nc"))
    assert 3 <= len(done) < 12, done  # killed in the middle
    ds = jr.sweep(heavy_member, {"x": np.arange(12.0)}, shared=np.float64(HEAVY_LOOP), out=str(store), name="heavy",
                  progress=False)
    assert ds.attrs["computed_points"] == [i for i in range(12) if i not in done]
    f = jax.jit(heavy_member)
    ref = [float(f({"x": jnp.asarray(float(i))}, jnp.asarray(HEAVY_LOOP))["y"]) for i in range(12)]
    np.testing.assert_array_equal(ds["y"].values, ref)
