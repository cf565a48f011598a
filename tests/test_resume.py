"""Interrupted sweeps resume without losing or recomputing finished work, proven with a real
SIGKILL of the CLI (`jaxrod phase-diagram`, `jaxrod speed-plane`) in a subprocess, plus
files torn by a kill during a write (half the bytes of a chunk, half a CSV row): those are
recomputed, never trusted.

The killed runs are on small meshes, where compiling is ~10-20 s of a run and one chunk or
row takes ~0.05-0.3 s. So the grids hold many chunks/rows (the kill lands after the first
one and long before the last) and each test runs its uninterrupted reference run beside the
killed one (two processes, one per core), without a persistent compilation cache. The
speed-plane SIGKILL test (three ~27 CPU-s runs) is `slow`; its bookkeeping (torn rows, other
settings, an older CSV) is checked in process with stand-in physics in the CI.
"""

import csv
import hashlib
import json
import os
import signal
import subprocess
import sys
import time
import types

import numpy as np
import pytest

from jaxrod.cli import _dynamics as _cli_dynamics
from jaxrod.branches import _phase

ENV = dict(os.environ, JAXROD_NO_CACHE="1")
ENV.pop("JAX_COMPILATION_CACHE_DIR", None)
STARTUP_TIMEOUT = 240.0  # s until the first finished chunk/row (compiling on a loaded 2-core machine)
RUN_TIMEOUT = 300.0


def _start(args, log_dir, name):
    out = open(os.path.join(log_dir, f"{name}.out"), "w")
    err = open(os.path.join(log_dir, f"{name}.err"), "w")
    proc = subprocess.Popen([sys.executable, "-m", "jaxrod", *args], env=ENV, stdout=out, stderr=err)
    out.close()
    err.close()
    return proc


def _log(log_dir, name):
    with open(os.path.join(log_dir, f"{name}.out")) as f, open(os.path.join(log_dir, f"{name}.err")) as g:
        return f.read(), g.read()


def _finish(proc, log_dir, name):
    try:
        rc = proc.wait(RUN_TIMEOUT)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
        raise
    out, err = _log(log_dir, name)
    # 3: finished, with points whose code is not successful (stored in the files)
    assert rc == 0 or (rc == 3 and "points not successful" in err), (name, rc, out, err[-3000:])
    return out, err


def _kill_when(proc, ready, log_dir, name):
    """Poll (every 5 ms) until `ready()` is true, then SIGKILL the process."""
    t0 = time.monotonic()
    while not ready():
        if proc.poll() is not None:
            pytest.fail(f"{name} ended (rc {proc.returncode}) before it was killed: {_log(log_dir, name)}")
        if time.monotonic() - t0 > STARTUP_TIMEOUT:
            proc.kill()
            proc.wait()
            pytest.fail(f"{name}: nothing finished within {STARTUP_TIMEOUT} s")
        time.sleep(0.005)
    os.kill(proc.pid, signal.SIGKILL)
    assert proc.wait(30) == -signal.SIGKILL


def _stamp(path):
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest(), os.stat(path).st_mtime_ns


def _assert_close(a, b, what):
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape, what
    if a.dtype.kind in "iub":
        np.testing.assert_array_equal(a, b, err_msg=what)
    else:
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12, equal_nan=True, err_msg=what)


# ---------------------------------------------------------------- phase diagram

PD_PSIS = [30.0 + 5.0 * i for i in range(31)]  # 30:180:5, 31 chunks of ~0.05 s at N = 16
PD_GAPS = [0.2, 0.3, 0.4, 0.5, 0.6]


def _pd_args(out):
    return ["phase-diagram", "--psi0", "30:180:5", "--gaps", "0.2:0.6:0.1", "--n", "16", "--out", str(out),
            "--no-termination", "--json"]


@pytest.mark.slow  # 63 s (three CLI processes); CI checks resuming from finished, torn and foreign chunks in-process
def test_phase_diagram_sigkill_resume(tmp_path):
    """Killed after its first chunk, the rerun reads the finished chunks back (files not
    rewritten: same hash and mtime; the CLI reports them as not computed), recomputes a
    chunk torn in half, computes the rest, and ends with an uninterrupted run's data."""
    a, ref = tmp_path / "a", tmp_path / "ref"
    reference = _start(_pd_args(ref), tmp_path, "ref")
    proc = _start(_pd_args(a), tmp_path, "killed")
    chunks = a / "chunks"

    def finished():
        return sorted(f for f in os.listdir(chunks) if f.endswith(".nc")) if chunks.is_dir() else []

    _kill_when(proc, lambda: finished(), tmp_path, "killed")
    done = {f: _stamp(chunks / f) for f in finished()}
    assert not (a / "phase_diagram.nc").exists()
    assert "psi0_30.nc" in done and len(done) < len(PD_PSIS) - 5, sorted(done)  # killed early in the sweep
    # a chunk torn by a kill during a (non-atomic) write: half the bytes of a finished chunk
    torn = chunks / "psi0_180.nc"
    data = (chunks / "psi0_30.nc").read_bytes()
    torn.write_bytes(data[: len(data) // 2])
    (chunks / "psi0_175.nc.part").write_bytes(data[:100])  # what a kill inside the atomic write leaves

    t0 = time.monotonic()
    out, err = _finish(_start(_pd_args(a), tmp_path, "rerun"), tmp_path, "rerun")
    rerun_s = time.monotonic() - t0
    rec = json.loads(out)
    reused = {float(f[len("psi0_"):-len(".nc")]) for f in done}
    assert rec["computed_chunks"] == [p for p in PD_PSIS if p not in reused]  # 180 among them
    for f, stamp in done.items():  # read back, not rewritten
        assert _stamp(chunks / f) == stamp, f
    assert sorted(finished()) == sorted(f"psi0_{p:g}.nc" for p in PD_PSIS)

    rec_ref = json.loads(_finish(reference, tmp_path, "ref")[0])
    assert rec_ref["computed_chunks"] == PD_PSIS
    import xarray as xr

    with xr.open_dataset(a / "phase_diagram.nc", engine="scipy") as got, \
            xr.open_dataset(ref / "phase_diagram.nc", engine="scipy") as want:
        assert got["psi0"].values.tolist() == PD_PSIS and got["gap"].values.tolist() == PD_GAPS
        assert want["psi0"].values.tolist() == PD_PSIS
        for k in _phase.VARIABLES:
            _assert_close(got[k].values, want[k].values, k)
        assert np.isfinite(got["alpha_c_up"].values).any()
    for p in PD_PSIS:  # every chunk file too, the torn one recomputed
        with xr.open_dataset(_phase._chunk_path(str(a), p), engine="scipy") as got, \
                xr.open_dataset(_phase._chunk_path(str(ref), p), engine="scipy") as want:
            for k in _phase.VARIABLES:
                _assert_close(got[k].values, want[k].values, f"{k} at {p}")
    print(f"phase-diagram rerun {rerun_s:.1f} s, {len(done)} chunks reused")


def _fake_chunk(calls):
    """Stand-in for the compiled chunk (as in test_phase_diagram): deterministic values."""

    def f(psi0, gaps, s0, mesh, contact=None):
        calls.append(round(float(np.degrees(psi0)), 9))
        g = np.asarray(gaps)
        out = {k: np.sin(float(psi0) * (i + 1) + 3.0 * g) for i, k in enumerate(_phase.VARIABLES)}
        for k in ("kind_up", "kind_down", "start_up", "start_down", "result_up", "result_down", "warm_starts"):
            out[k] = (np.arange(g.size) % 3).astype(np.int32)
        return out

    return f


def test_phase_diagram_torn_or_foreign_chunk_is_recomputed(tmp_path, monkeypatch):
    """A chunk file cut at any of several points (a kill during a write), or a whole chunk
    of another fold angle / grid under this chunk's name, is recomputed, never trusted."""
    import jaxrod as jr

    calls = []
    monkeypatch.setattr(_phase, "_chunk", _fake_chunk(calls))
    psis, gaps, out = [30.0, 60.0], [0.2, 0.4, 0.6], str(tmp_path / "pd")
    whole = jr.phase_diagram(psis, gaps, n=16, out=out, progress=False)
    path60, path30 = _phase._chunk_path(out, 60.0), _phase._chunk_path(out, 30.0)
    full = open(path60, "rb").read()
    stamp30 = _stamp(path30)
    for cut in (len(full) // 2, 1, len(full) // 4, 3 * len(full) // 4, len(full) - 1):
        with open(path60, "wb") as f:
            f.write(full[:cut])
        calls.clear()
        ds = jr.phase_diagram(psis, gaps, n=16, out=out, progress=False)
        assert calls == [60.0] and ds.attrs["computed_chunks"] == [60.0], cut
        assert open(path60, "rb").read() == full
        for k in _phase.VARIABLES:
            _assert_close(ds[k].values, whole[k].values, k)
    assert _stamp(path30) == stamp30  # never rewritten
    # a complete chunk of another fold angle under this one's name: not this chunk
    with open(path60, "wb") as f:
        f.write(open(path30, "rb").read())
    calls.clear()
    jr.phase_diagram(psis, gaps, n=16, out=out, progress=False)
    assert calls == [60.0]


# ---------------------------------------------------------------- speed plane

SP_PSIS, SP_GAPS = [30.0, 60.0, 90.0], [0.3, 0.4, 0.5, 0.6]  # 12 rows of ~0.3 s at N = 16


def _sp_args(out):
    return ["speed-plane", "--psi0", "30,60,90", "--gaps", "0.3,0.4,0.5,0.6", "--n", "16", "--out", str(out)]


def _data_lines(path):
    try:
        with open(path, newline="") as f:
            return f.read().splitlines(keepends=True)[1:]
    except FileNotFoundError:
        return []


def _rows_by_point(path):
    rows, dropped = _cli_dynamics._read_rows(str(path))
    assert dropped == 0
    return {(r["psi0_deg"], r["gap"]): r for r in rows}


@pytest.mark.slow  # ~27 s of CPU a run (compiling snap_angles + simulate), three runs: ~55 s on an idle
# 2-core machine, 164 s on a shared one; the CI runs the in-process test below for this sweep
def test_speed_plane_sigkill_resume(tmp_path):
    """Killed after its first row, the rerun reads the finished rows back (the CLI says how
    many and lists only the others as computed; the rows are byte-identical), drops a row
    torn in half and recomputes its point, and ends with an uninterrupted run's rows."""
    a, ref = tmp_path / "a", tmp_path / "ref"
    reference = _start(_sp_args(ref), tmp_path, "ref")
    proc = _start(_sp_args(a), tmp_path, "killed")
    csv_path = a / "speed_plane.csv"
    _kill_when(proc, lambda: _data_lines(csv_path), tmp_path, "killed")
    done = _data_lines(csv_path)
    assert 1 <= len(done) < len(SP_PSIS) * len(SP_GAPS) - 3, done
    assert all(line.endswith("\r\n") for line in done)  # whole rows only (atomic rewrite)
    finished = {tuple(float(x) for x in line.split(",")[:2]) for line in done}
    assert (SP_PSIS[-1], SP_GAPS[-1]) not in finished
    # a row torn by a kill during its write: half of the last point's row, no newline
    with open(csv_path, "a", newline="") as f:
        f.write("90.0,0.6,16,0.02,up,0.05,rattle,1e-06,4.0,True,81.40535643")

    t0 = time.monotonic()
    out, err = _finish(_start(_sp_args(a), tmp_path, "rerun"), tmp_path, "rerun")
    rerun_s = time.monotonic() - t0
    rec = json.loads(out.strip().splitlines()[-1])
    grid = [(p, g) for p in SP_PSIS for g in SP_GAPS]
    assert "dropped 1 unreadable row(s)" in err, err[-2000:]
    assert f"{len(done)} of {len(grid)} points read back" in err, err[-2000:]
    assert [tuple(x) for x in rec["computed_points"]] == [pt for pt in grid if pt not in finished]
    assert rec["points"] == len(grid)
    final = _data_lines(csv_path)
    assert final[: len(done)] == done  # the finished rows kept as they were
    assert len(final) == len(grid)

    _finish(reference, tmp_path, "ref")
    got, want = _rows_by_point(csv_path), _rows_by_point(ref / "speed_plane.csv")
    assert sorted(got) == sorted(want) == sorted(grid)
    for pt in grid:
        for k in _cli_dynamics.FIELDS:
            g, w = got[pt][k], want[pt][k]
            if isinstance(w, float):
                assert g is not None and abs(g - w) <= 1e-12, (pt, k, g, w)
            else:
                assert g == w, (pt, k, g, w)
    assert sum(r["snaps"] for r in got.values()) >= 4
    print(f"speed-plane rerun {rerun_s:.1f} s, {len(done)} rows reused")


def _fake_dynamics(monkeypatch, calls):
    """`jaxrod.snap_angles` / `snap_dynamics` as cheap deterministic stand-ins (the CLI's
    bookkeeping is under test here, not the physics)."""
    import jaxrod as jr

    def snap_angles(scene):
        p, g = np.degrees(float(scene.strip.psi0)), float(scene.clamps.gap)
        calls.append((round(float(p), 9), g))
        path = types.SimpleNamespace(snaps=g < 0.55, result=jr.RESULTS.successful)
        return types.SimpleNamespace(up=path, down=path)

    def snap_dynamics(scene, direction, **kw):
        p, g = float(scene.strip.psi0), float(scene.clamps.gap)
        start = types.SimpleNamespace(alpha_c=np.sin(p + g), bending_before=1.0 / 3.0 + p * g)
        tr = types.SimpleNamespace(v_s=40.0 - 30.0 * g - 5.0 * p + kw["t1"], t_cross=np.pi * g, kinetic_peak=np.e * p,
                                   num_steps=1000 + int(100 * g), snapped=True, result=jr.RESULTS.successful)
        return start, tr

    monkeypatch.setattr(jr, "snap_angles", snap_angles)
    monkeypatch.setattr(jr, "snap_dynamics", snap_dynamics)


def test_speed_plane_torn_rows_and_other_settings(tmp_path, monkeypatch, capsys):
    """A CSV row cut in half (a kill during a write, at the end or in the middle of the
    file) is dropped and its point recomputed, not trusted and no crash; rows computed
    with other settings are not reused (and are kept); a file without the settings columns
    is refused with one line."""
    from jaxrod.cli._main import main

    calls = []
    _fake_dynamics(monkeypatch, calls)
    out = tmp_path / "sp"
    argv = ["speed-plane", "--psi0", "30,60", "--gaps", "0.4,0.6", "--n", "16", "--out", str(out)]
    grid = [(30.0, 0.4), (30.0, 0.6), (60.0, 0.4), (60.0, 0.6)]
    assert main(argv) == 0
    assert calls == grid
    path = out / "speed_plane.csv"
    text = path.read_text()
    lines = text.splitlines(keepends=True)
    assert len(lines) == 5 and not (out / "speed_plane.csv.part").exists()
    for cut_row in (4, 2):  # the last row torn, then a row in the middle
        row = lines[cut_row]
        path.write_text("".join(lines[:cut_row]) + row[: len(row) // 2] + ("\n" if cut_row < 4 else "")
                        + "".join(lines[cut_row + 1:]))
        calls.clear()
        capsys.readouterr()
        assert main(argv) == 0
        cap = capsys.readouterr()
        assert calls == [grid[cut_row - 1]], cut_row
        assert "dropped 1 unreadable row(s)" in cap.err and "3 of 4 points read back" in cap.err
        assert json.loads(cap.out)["computed_points"] == [list(grid[cut_row - 1])]
        got = path.read_text().splitlines(keepends=True)
        assert sorted(got) == sorted(lines)  # the same rows, the recomputed one at the end
    # a complete rerun computes nothing and leaves the file alone
    stamp = _stamp(path)
    calls.clear()
    assert main(argv) == 0 and calls == [] and _stamp(path) == stamp
    # other settings (s0, t1): nothing reused, the first settings' rows kept
    before = path.read_text().splitlines(keepends=True)
    for extra in (["--s0", "0.03"], ["--t1", "3"]):
        calls.clear()
        capsys.readouterr()
        assert main(argv + extra) == 0
        assert calls == grid, extra
        assert json.loads(capsys.readouterr().out)["points"] == 4
    after = path.read_text().splitlines(keepends=True)
    assert after[: len(before)] == before and len(after) == len(before) + 8
    rows = list(csv.DictReader(after))
    assert {r["s0"] for r in rows} == {"0.02", "0.03"} and {r["t1"] for r in rows} == {"4.0", "3.0"}
    # an older jaxrod's CSV (no settings columns): refused with one line, file untouched
    old = tmp_path / "old"
    old.mkdir()
    (old / "speed_plane.csv").write_text("psi0_deg,gap,n,snaps,alpha_c_deg,v_s,t_snap,kinetic_energy_peak,"
                                         "bending_energy_before,num_steps\n30.0,0.4,16,True,1,2,3,4,5,6\n")
    capsys.readouterr()
    assert main(argv[:-1] + [str(old)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "speed_plane.csv" in err[0] and "--out" in err[0], err
    assert "bending_energy_before,num_steps\n30.0" in (old / "speed_plane.csv").read_text()


def test_speed_plane_rows_carry_codes(tmp_path, monkeypatch, capsys):
    """Every row of the speed plane carries its code: `successful` for a resolved snap,
    `no_snap` where the path does not snap, the path's code where its outcome is unknown
    (no dynamics run there), the trajectory's where the run failed; the flagged points are
    counted in the JSON record and on stderr."""
    import csv

    import jaxrod as jr
    from jaxrod.cli._main import main

    calls = []
    _fake_dynamics(monkeypatch, calls)
    fake_angles, fake_dynamics = jr.snap_angles, jr.snap_dynamics

    def snap_angles(scene):
        r = fake_angles(scene)
        if float(scene.clamps.gap) == 0.5:  # the continuation gave up here
            r.up.result = jr.RESULTS.continuation_incomplete
            r.up.snaps = False
        return r

    def snap_dynamics(scene, direction, **kw):
        start, tr = fake_dynamics(scene, direction, **kw)
        if float(scene.clamps.gap) == 0.3:
            tr.result, tr.snapped = jr.RESULTS.energy_drift, False
        return start, tr

    monkeypatch.setattr(jr, "snap_angles", snap_angles)
    monkeypatch.setattr(jr, "snap_dynamics", snap_dynamics)
    out = tmp_path / "sp"
    assert main(["speed-plane", "--psi0", "30", "--gaps", "0.3,0.4,0.5,0.6", "--n", "16", "--out", str(out)]) == 3
    cap = capsys.readouterr()
    with open(out / "speed_plane.csv", newline="") as fh:
        codes = {float(r["gap"]): r["result"] for r in csv.DictReader(fh)}
    assert codes == {0.3: "energy_drift", 0.4: "successful", 0.5: "continuation_incomplete", 0.6: "no_snap"}
    assert json.loads(cap.out)["flagged"] == {"continuation_incomplete": 1, "energy_drift": 1}
    assert "continuation_incomplete x1, energy_drift x1" in cap.err
