"""Phase diagram (paper Fig. 2c): resumable NetCDF chunks, the CLI, the figure, and
the real chunked computation against single `snap_angles` calls, and the one vmapped call
against the chunks."""

import json
import os

import jax
import numpy as np
import pytest

import jaxrod as jr
from helpers import PHASE_GAPS, PHASE_N, PHASE_PSI, count_compiles, run_sweep_workers
from jaxrod.branches import _phase


def _fake_chunk(calls):
    """Stand-in for the compiled chunk: deterministic values, and a record of each call."""

    def f(psi0, gaps, s0, mesh, contact=None):
        calls.append(float(psi0))
        g = np.asarray(gaps)
        p = float(psi0)
        out = {k: np.sin(p * (i + 1) + 3.0 * g) for i, k in enumerate(_phase.VARIABLES)}
        for k in ("kind_up", "kind_down", "start_up", "start_down", "result_up", "result_down"):
            out[k] = (np.arange(g.size) % 3).astype(np.int32)
        out["alpha_c_down"][0] = np.nan  # a point that does not snap
        return out

    return f


class _Stop(Exception):
    pass


def test_resume_after_interrupt(tmp_path, monkeypatch):
    psis, gaps = [30.0, 60.0, 180.0], [0.2, 0.5, 0.8]
    calls = []
    monkeypatch.setattr(_phase, "_chunk", _fake_chunk(calls))

    def interrupt(p, computed):
        raise _Stop

    with pytest.raises(_Stop):  # interrupted right after the first chunk was written
        jr.phase_diagram(psis, gaps, n=40, out=str(tmp_path / "a"), progress=False, on_chunk=interrupt)
    assert calls == [pytest.approx(np.radians(30.0))]
    assert os.path.exists(tmp_path / "a" / "chunks" / "psi0_30.nc")
    assert not os.path.exists(tmp_path / "a" / "phase_diagram.nc")
    calls.clear()
    seen = []
    resumed = jr.phase_diagram(psis, gaps, n=40, out=str(tmp_path / "a"), progress=False,
                               on_chunk=lambda p, c: seen.append((p, c)))
    # the finished chunk is read back, only the two others are computed
    assert calls == [pytest.approx(np.radians(60.0)), pytest.approx(np.radians(180.0))]
    assert seen == [(30.0, False), (60.0, True), (180.0, True)]
    assert resumed.attrs["computed_chunks"] == [60.0, 180.0]
    calls.clear()
    whole = jr.phase_diagram(psis, gaps, n=40, out=str(tmp_path / "b"), progress=False)
    assert len(calls) == 3
    for k in _phase.VARIABLES:
        np.testing.assert_array_equal(resumed[k].values, whole[k].values)
    # the file on disk holds the same
    import xarray as xr

    with xr.open_dataset(tmp_path / "a" / "phase_diagram.nc", engine="scipy") as ds:
        np.testing.assert_array_equal(ds["alpha_c_up"].values, whole["alpha_c_up"].values)
        assert ds["alpha_c_up"].dims == ("psi0", "gap")
    # a different grid (or mesh) does not reuse the chunks
    calls.clear()
    jr.phase_diagram(psis, gaps, n=60, out=str(tmp_path / "a"), progress=False)
    assert len(calls) == 3
    # a truncated chunk file is recomputed, not trusted
    (tmp_path / "a" / "chunks" / "psi0_60.nc").write_bytes(b"CDF\x02garbage")
    calls.clear()
    jr.phase_diagram(psis, gaps, n=60, out=str(tmp_path / "a"), progress=False)
    assert calls == [pytest.approx(np.radians(60.0))]


def test_figure_and_termination_hook(tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr(_phase, "_chunk", _fake_chunk(calls))
    ds = jr.phase_diagram([60.0, 180.0], [0.2, 0.5, 0.8], progress=False)
    png = jr.plot_phase_diagram(ds, str(tmp_path / "pd.png"), termination_gaps={60.0: (0.7, 0.75)})
    assert os.path.getsize(png) > 10_000
    # the figure's vertical lines come from termination_gap, one call per Psi0, with the
    # caller's s0 and mesh
    from types import SimpleNamespace

    from jaxrod.branches import _termination

    seen = []

    def fake(psi0, *, s0, n):
        seen.append((psi0, s0, n))
        return SimpleNamespace(gap_up=0.7 + psi0 / 1e3, gap_down=0.6 + psi0 / 1e3)

    monkeypatch.setattr(_termination, "termination_gap", fake)
    assert _phase.termination_gaps([60.0, 90.0], s0=0.03, n=80) == {
        60.0: (pytest.approx(0.76), pytest.approx(0.66)), 90.0: (pytest.approx(0.79), pytest.approx(0.69))}
    assert seen == [(60.0, 0.03, 80), (90.0, 0.03, 80)]


@pytest.mark.parametrize("argv, name", [
    (["--psi0", "30,200"], "psi0"),
    (["--gaps", "0.1:1.2:0.1"], "gap"),
    (["--gaps", "0.5:0.1:0.1"], "gaps"),
    (["--psi0", "abc"], "psi0"),
    (["--s0", "0"], "s0"),
    (["--n", "7"], "n"),
    (["--gaps", "nan"], "gap"),
])
def test_cli_bad_input(argv, name, capsys, tmp_path):
    from jaxrod.cli._main import main

    assert main(["phase-diagram", "--out", str(tmp_path), *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and name in err[0]


def test_cli_json(tmp_path, monkeypatch, capsys):
    calls = []
    monkeypatch.setattr(_phase, "_chunk", _fake_chunk(calls))
    from jaxrod.cli._main import main

    out = tmp_path / "pd"
    # the stand-in's codes cycle through 0, 1, 2: flagged points, exit 3 with every file written
    assert main(["phase-diagram", "--psi0", "60,180", "--gaps", "0.2:0.6:0.2", "--out", str(out),
                 "--no-termination", "--json"]) == 3
    cap = capsys.readouterr()
    rec = json.loads(cap.out)
    assert rec["gaps"] == [0.2, 0.4, 0.6] and rec["psi0_deg"] == [60.0, 180.0]
    assert os.path.exists(rec["netcdf"]) and os.path.exists(rec["png"])
    assert rec["computed_chunks"] == [60.0, 180.0]
    assert rec["flagged"] and "points not successful" in cap.err
    assert main(["phase-diagram", "--psi0", "60,180", "--gaps", "0.2:0.6:0.2", "--out", str(out),
                 "--no-termination", "--json"]) == 3
    assert json.loads(capsys.readouterr().out)["computed_chunks"] == []
    # every point successful: exit 0
    ok = int(jr.RESULTS.successful._value)

    def all_ok(psi0, gaps, s0, mesh, contact=None):
        d = _fake_chunk([])(psi0, gaps, s0, mesh)
        for k in ("start_up", "start_down", "result_up", "result_down"):
            d[k] = np.full(np.asarray(gaps).size, ok, np.int32)
        return d

    monkeypatch.setattr(_phase, "_chunk", all_ok)
    assert main(["phase-diagram", "--psi0", "90", "--gaps", "0.3,0.5", "--out", str(tmp_path / "ok"),
                 "--no-termination", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["flagged"] == {}


@pytest.fixture(scope="module")
def chunks(tmp_path_factory):
    """The real computation on a small grid, one compiled call per fold angle."""
    return jr.phase_diagram(PHASE_PSI, PHASE_GAPS, n=PHASE_N, out=str(tmp_path_factory.mktemp("pd")), batch="scan",
                            progress=False)


def test_warm_started_chunk_equals_single_calls(chunks):
    """The real computation: the warm-started chunk (start states by Newton from the
    previous gap, `snap_angles` without the extended-system polish) gives the same kinds,
    start codes and landing states as single polished `snap_angles` calls, and alpha_c to
    1e-6 deg; a gap where the down state does not exist (30 deg, 0.8) falls back to the
    homotopy and does not poison the gaps after it."""
    gaps, n, ds = PHASE_GAPS, PHASE_N, chunks
    f = jax.jit(jr.snap_angles)
    for p in (30.0, 60.0):
        for g in gaps:
            r = f(jr.make_scene(p, g, 0.0, n=n))
            for name, path in (("up", r.up), ("down", r.down)):
                at = lambda k: float(ds[f"{k}_{name}"].sel(psi0=p, gap=g))  # noqa: E731
                a, b = at("alpha_c"), float(np.degrees(path.alpha_c))
                assert (np.isnan(a) and np.isnan(b)) or abs(a - b) < 1e-6, (p, g, name, a, b)
                assert int(at("kind")) == int(path.kind), (p, g, name)
                assert int(at("start")) == int(path.start_result._value), (p, g, name)
                assert int(at("result")) == int(path.result._value), (p, g, name)
                fa, fb = at("fold_height_after"), float(path.fold_height_after)
                assert (np.isnan(fa) and np.isnan(fb)) or abs(fa - fb) < 1e-6, (p, g, name, fa, fb)
    warm = ds["warm_starts"]
    assert int(warm.sel(psi0=60.0, gap=0.3)) == 0  # first gap: homotopy
    assert int(warm.sel(psi0=60.0, gap=0.5)) == 2  # both states from the previous gap
    # 30 deg, 0.8 and 0.82: no down state at alpha = 0 (the Newton from 0.5's down state is
    # rejected, the homotopy reports state_not_found); only the up state is warm-started
    down = jr.initial_state(jr.make_scene(30.0, 0.8, 0.0, n=n), "down")
    assert down.result == jr.RESULTS.state_not_found
    assert int(warm.sel(psi0=30.0, gap=0.8)) == 1 and int(warm.sel(psi0=30.0, gap=0.82)) == 1
    # the paths themselves start from the previous gap's critical points where those pass their
    # checks (`jaxrod.branches._warm`), and the answers above are the single cold calls' all the same
    paths = ds["warm_paths"]
    assert int(paths.sel(psi0=60.0, gap=0.3)) == 0  # first gap: both paths walk their branch
    assert int(paths.sum()) >= paths.size // 2, paths.values


def test_new_fold_angles_compile_nothing(chunks):
    """A chunk is one compiled program per grid of gaps and mesh: after the fixture's fold
    angles, another one runs without a single XLA compilation (a chunk traced afresh for each
    fold angle would compile the whole `snap_angles` machinery again, ~10 s on 2 cores)."""
    with count_compiles() as c:
        ds = jr.phase_diagram([45.0], PHASE_GAPS, n=PHASE_N, batch="scan", progress=False)
    assert c[0] == 0, f"{c[0]} XLA compilations for a new fold angle"
    assert ds.attrs["computed_chunks"] == [45.0]
    assert np.isfinite(ds["alpha_c_up"].sel(psi0=45.0, gap=0.5))


def _traced_fake_chunk(psi0, gaps, s0, mesh, settings=None, contact=None):
    """A traceable stand-in for the compiled chunk (deterministic values; one NaN angle)."""
    import jax.numpy as jnp

    out = {k: jnp.sin(psi0 * (i + 1) + 3.0 * gaps) for i, k in enumerate(_phase.VARIABLES)}
    for k in ("kind_up", "kind_down", "start_up", "start_down", "result_up", "result_down", "warm_starts"):
        out[k] = (jnp.arange(gaps.size) % 3).astype(jnp.int32)
    out["alpha_c_down"] = out["alpha_c_down"].at[0].set(jnp.nan)
    return out


def test_shard_batches_the_fold_angles(monkeypatch, tmp_path):
    """`batch="shard"`: the fold angles still to compute go through `jaxrod.ShardedMap` in
    batches of `per_device` x devices, each finished fold angle is written and reported, a
    rerun reads them back, and the numbers are those of the one-call-per-Psi0 path."""
    monkeypatch.setattr(_phase, "_chunk", _traced_fake_chunk)
    _phase._sharded.cache_clear()  # no ShardedMap traced with the real chunk
    try:
        psis, gaps = [30.0, 60.0, 90.0, 120.0, 180.0], [0.2, 0.4, 0.6]
        seen = []
        kw = dict(n=8, progress=False, on_chunk=lambda p, c: seen.append((p, c)))
        ds = jr.phase_diagram(psis, gaps, out=str(tmp_path), batch="shard", per_device=2, **kw)
        assert ds.attrs["batch"] == "shard" and ds.attrs["computed_chunks"] == psis
        assert seen == [(p, True) for p in psis]
        ref = jr.phase_diagram(psis, gaps, batch="scan", **kw)
        for k in _phase.VARIABLES:
            np.testing.assert_array_equal(ds[k].values, ref[k].values, err_msg=k)
        os.remove(_phase._chunk_path(str(tmp_path), 90.0))
        again = jr.phase_diagram(psis, gaps, out=str(tmp_path), batch="shard", per_device=2, **kw)
        assert again.attrs["computed_chunks"] == [90.0]
        for k in _phase.VARIABLES:
            np.testing.assert_array_equal(again[k].values, ref[k].values, err_msg=k)
        for k in ("jaxrod_version", "jax_version", "backend", "device_count", "process_count", "date_utc"):
            assert k in again.attrs, k
    finally:
        _phase._sharded.cache_clear()


@pytest.mark.slow  # a compile of the sharded chunk (~30 s); CI runs the sweep layer on 4 devices
# (test_sweeps.py) and the sharded phase diagram's batching with a stand-in chunk (above)
def test_fold_angles_split_across_four_devices(chunks, tmp_path):
    """`batch="shard"` on 4 virtual CPU devices (a child process: JAX reads the device count
    when it starts): the numbers of the one-call-per-Psi0 chunks (another compiled program:
    equal to round-off), the same kinds and codes, one fold angle per device."""
    (r,) = run_sweep_workers(tmp_path, "phase", devices=4)
    assert r["device_count"] == 4
    for k, got in r["phase_shard"].items():
        want = np.where(np.isnan(chunks[k].values), -999.0, chunks[k].values)
        if k.startswith(("kind", "result")):
            np.testing.assert_array_equal(got, want, err_msg=k)
        else:
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-9, err_msg=k)


def test_vmap_mode_computes_missing_chunks_in_one_call(tmp_path, monkeypatch):
    """`batch="vmap"`: one call of the vmapped grid for every chunk not on disk yet."""
    calls, grid_calls = [], []
    fake = _fake_chunk(calls)
    monkeypatch.setattr(_phase, "_chunk", fake)

    def grid(psis, gaps, s0, mesh, contact=None):
        grid_calls.append([float(p) for p in psis])
        outs = [fake(p, gaps, s0, mesh) for p in psis]
        return {k: np.stack([o[k] for o in outs]) for k in outs[0]}

    monkeypatch.setattr(_phase, "_grid", grid)
    gaps = [0.2, 0.5, 0.8]
    jr.phase_diagram([60.0], gaps, out=str(tmp_path), progress=False, batch="scan")
    ds = jr.phase_diagram([30.0, 60.0, 180.0], gaps, out=str(tmp_path), progress=False, batch="vmap")
    assert len(grid_calls) == 1 and np.allclose(grid_calls[0], np.radians([30.0, 180.0]))
    assert ds.attrs["computed_chunks"] == [30.0, 180.0] and ds.attrs["batch"] == "vmap"
    ref = jr.phase_diagram([30.0, 60.0, 180.0], gaps, progress=False, batch="scan")
    for k in _phase.VARIABLES:
        np.testing.assert_array_equal(ds[k].values, ref[k].values)
    with pytest.raises(ValueError, match="batch"):
        jr.phase_diagram([60.0], gaps, progress=False, batch="loop")


@pytest.mark.slow  # 66 s on 2 cores; the chunked mode it is compared with is checked against single calls in CI
def test_one_vmapped_call_equals_the_chunks():
    """The real computation as one jitted, vmapped call over Psi0 (`batch="vmap"`; batched
    linear algebra through `jaxrod.linalg.batched`, the homotopy fallback a masked while loop)
    gives the per-Psi0 chunks' numbers: same kinds, start codes and warm starts, alpha_c
    and fold heights to 1e-9. The grid includes a gap with no down state (30 deg, 0.8),
    where only that member falls back to the homotopy."""
    gaps = [0.3, 0.5, 0.8]
    kw = dict(n=40, progress=False)
    scan = jr.phase_diagram([30.0, 60.0, 180.0], gaps, batch="scan", **kw)
    vm = jr.phase_diagram([30.0, 60.0, 180.0], gaps, batch="vmap", **kw)
    for k in _phase.VARIABLES:
        a, b = scan[k].values, vm[k].values
        if a.dtype.kind == "f":
            np.testing.assert_allclose(b, a, rtol=0, atol=1e-9, err_msg=k)
            assert np.array_equal(np.isnan(a), np.isnan(b)), k
        else:
            np.testing.assert_array_equal(b, a, err_msg=k)
    assert np.isnan(vm["alpha_c_down"].sel(psi0=30.0, gap=0.8))
    assert np.isfinite(vm["alpha_c_up"].sel(psi0=60.0, gap=[0.3, 0.5])).all()  # G*_up(60) = 0.767


# The fold width as an axis: `s0` a list gives a grid (s0, psi0, gap) of (s0, Psi0) chunks

def _fake_chunk_s0(calls):
    """Stand-in for the compiled chunk whose values depend on the fold width too; records
    each call's `(s0, psi0 in deg)`."""

    def f(psi0, gaps, s0, mesh, contact=None):
        calls.append((round(float(s0), 12), round(float(np.degrees(psi0)), 9)))
        g = np.asarray(gaps)
        out = {k: np.sin(float(psi0) * (i + 1) + 3.0 * g + 7.0 * float(s0)) for i, k in enumerate(_phase.VARIABLES)}
        for k in ("kind_up", "kind_down", "start_up", "start_down", "result_up", "result_down"):
            out[k] = ((np.arange(g.size) + int(1000 * float(s0))) % 3).astype(np.int32)
        out["alpha_c_down"][0] = np.nan
        return out

    return f


def _assert_same(a, b):
    for k in _phase.VARIABLES:
        np.testing.assert_array_equal(a[k].values, b[k].values, err_msg=k)


def test_s0_axis_resumes_and_equals_single_widths(tmp_path, monkeypatch):
    """A list of fold widths: the dataset gains a leading `s0` dimension whose rows are the
    single-width diagrams; each (s0, Psi0) chunk has its own file with the width in its name,
    and an interrupted run computes only the chunks it had not finished."""
    import xarray as xr

    calls = []
    monkeypatch.setattr(_phase, "_chunk", _fake_chunk_s0(calls))
    psis, gaps, widths = [30.0, 60.0], [0.2, 0.5, 0.8], [0.02, 0.035]
    out = str(tmp_path / "a")

    def interrupt_third(chunk, computed):
        if len(calls) == 3:
            raise _Stop

    with pytest.raises(_Stop):
        jr.phase_diagram(psis, gaps, s0=widths, n=40, out=out, progress=False, on_chunk=interrupt_third)
    assert calls == [(0.02, 30.0), (0.02, 60.0), (0.035, 30.0)]
    assert sorted(os.listdir(os.path.join(out, "chunks"))) == [
        "s0_0.02_psi0_30.nc", "s0_0.02_psi0_60.nc", "s0_0.035_psi0_30.nc"]
    calls.clear()
    seen = []
    ds = jr.phase_diagram(psis, gaps, s0=widths, n=40, out=out, progress=False,
                          on_chunk=lambda c, fresh: seen.append((c, fresh)))
    assert calls == [(0.035, 60.0)]
    assert seen == [((0.02, 30.0), False), ((0.02, 60.0), False), ((0.035, 30.0), False), ((0.035, 60.0), True)]
    assert ds.attrs["computed_chunks"] == [(0.035, 60.0)]
    assert ds["s0"].values.tolist() == widths and "s0" not in ds.attrs
    for k in _phase.VARIABLES:
        assert ds[k].dims == ("s0", "psi0", "gap"), k
    # each row is the single-width phase diagram
    for w in widths:
        _assert_same(ds.sel(s0=w), jr.phase_diagram(psis, gaps, s0=w, n=40, progress=False))
    with xr.open_dataset(os.path.join(out, "phase_diagram.nc"), engine="scipy") as f:
        assert f["alpha_c_up"].dims == ("s0", "psi0", "gap") and f["s0"].values.tolist() == widths
        np.testing.assert_array_equal(f["alpha_c_up"].values, ds["alpha_c_up"].values)
    # another width list reuses the chunks of the widths it shares; a scalar run keeps its own files
    calls.clear()
    jr.phase_diagram(psis, gaps, s0=[0.035, 0.05], n=40, out=out, progress=False)
    assert calls == [(0.05, 30.0), (0.05, 60.0)]
    calls.clear()
    jr.phase_diagram(psis, gaps, s0=0.02, n=40, out=out, progress=False)
    assert len(calls) == 2 and os.path.exists(os.path.join(out, "chunks", "psi0_30.nc"))
    # a list of one width keeps its axis
    one = jr.phase_diagram(psis, gaps, s0=[0.02], n=40, progress=False)
    assert one["alpha_c_up"].dims == ("s0", "psi0", "gap") and one["s0"].values.tolist() == [0.02]


def test_s0_axis_vmap_and_shard_batch_the_pairs(tmp_path, monkeypatch):
    """`batch="vmap"`: the (s0, Psi0) chunks still missing go to one call of the vmapped grid,
    the fold widths batched beside the fold angles; `batch="shard"`: the pairs go through
    `jaxrod.ShardedMap`. Both give the numbers of one call per chunk."""
    import jax.numpy as jnp

    calls, grid_calls = [], []
    fake = _fake_chunk_s0(calls)
    monkeypatch.setattr(_phase, "_chunk", fake)

    def grid(psis, gaps, s0, mesh, contact=None):
        grid_calls.append((np.degrees(np.asarray(psis)).round(9).tolist(), np.asarray(s0).tolist()))
        outs = [fake(p, gaps, s, mesh) for p, s in zip(psis, np.broadcast_to(np.asarray(s0), np.shape(psis)))]
        return {k: np.stack([o[k] for o in outs]) for k in outs[0]}

    monkeypatch.setattr(_phase, "_grid", grid)
    psis, gaps, widths = [30.0, 60.0], [0.2, 0.5, 0.8], [0.02, 0.035]
    jr.phase_diagram([60.0], gaps, s0=[0.035], n=40, out=str(tmp_path), progress=False, batch="scan")
    ds = jr.phase_diagram(psis, gaps, s0=widths, n=40, out=str(tmp_path), progress=False, batch="vmap")
    assert grid_calls == [([30.0, 60.0, 30.0], [0.02, 0.02, 0.035])]
    assert ds.attrs["computed_chunks"] == [(0.02, 30.0), (0.02, 60.0), (0.035, 30.0)]
    calls.clear()
    ref = jr.phase_diagram(psis, gaps, s0=widths, n=40, progress=False, batch="scan")
    assert len(calls) == 4
    _assert_same(ds, ref)
    # a scalar s0 is passed to the vmapped grid as one shared width, as before
    grid_calls.clear()
    jr.phase_diagram(psis, gaps, s0=0.02, n=40, progress=False, batch="vmap")
    assert grid_calls == [([30.0, 60.0], 0.02)]

    def traced(psi0, gaps, s0, mesh, settings=None, contact=None):
        out = {k: jnp.sin(psi0 * (i + 1) + 3.0 * gaps + 7.0 * s0) for i, k in enumerate(_phase.VARIABLES)}
        for k in ("kind_up", "kind_down", "start_up", "start_down", "result_up", "result_down"):
            out[k] = ((jnp.arange(gaps.size) + (1000 * s0).astype(jnp.int32)) % 3).astype(jnp.int32)
        out["alpha_c_down"] = out["alpha_c_down"].at[0].set(jnp.nan)
        return out

    monkeypatch.setattr(_phase, "_chunk", traced)
    _phase._sharded.cache_clear()
    try:
        sh = jr.phase_diagram(psis, gaps, s0=widths, n=40, progress=False, batch="shard", per_device=3)
        assert sh.attrs["batch"] == "shard" and len(sh.attrs["computed_chunks"]) == 4
        for k in _phase.VARIABLES:
            np.testing.assert_allclose(sh[k].values, ref[k].values, rtol=0, atol=1e-12, err_msg=k)
    finally:
        _phase._sharded.cache_clear()


@pytest.mark.parametrize("s0, match", [
    ([0.02, 0.0], r"s0 must lie in \(0, 1\), got 0"),
    ([0.02, float("nan")], "s0 must be a finite number"),
    (1.0, r"s0 must lie in \(0, 1\), got 1"),
    ([0.02, float("inf")], "s0 must be a finite number"),
    ([], "s0 must hold at least one value"),
    ([0.02, 0.02], "s0 values must be distinct"),
    ([[0.02, 0.03]], "s0 must be a number or a one-dimensional list"),
    ("wide", "s0 must be a number"),
])
def test_s0_bad_input(s0, match, monkeypatch):
    calls = []
    monkeypatch.setattr(_phase, "_chunk", _fake_chunk_s0(calls))
    with pytest.raises(ValueError, match=match):
        jr.phase_diagram([60.0], [0.5], s0=s0, n=40, progress=False)
    assert calls == []


def test_s0_figure_one_panel_per_width(tmp_path, monkeypatch):
    """With an `s0` dimension the figure has one panel per fold width (wider than the single
    panel), termination gaps per width or shared."""
    from PIL import Image

    monkeypatch.setattr(_phase, "_chunk", _fake_chunk_s0([]))
    psis, gaps = [60.0, 180.0], [0.2, 0.5, 0.8]
    one = jr.plot_phase_diagram(jr.phase_diagram(psis, gaps, progress=False), str(tmp_path / "one.png"))
    ds = jr.phase_diagram(psis, gaps, s0=[0.01, 0.02, 0.04], progress=False)
    three = jr.plot_phase_diagram(ds, str(tmp_path / "three.png"),
                                  termination_gaps={0.01: {60.0: (0.7, 0.75)}, 0.04: {60.0: (0.72, 0.77)}})
    shared = jr.plot_phase_diagram(ds, str(tmp_path / "shared.png"), termination_gaps={60.0: (0.7, 0.75)})
    w1, w3 = Image.open(one).size[0], Image.open(three).size[0]
    assert w3 > 1.5 * w1 and Image.open(shared).size == Image.open(three).size


def test_cli_s0_list(tmp_path, monkeypatch, capsys):
    """`jaxrod phase-diagram --s0 LIST`: the dataset with an s0 axis, its figure, the widths
    in the JSON record; one width keeps the (psi0, gap) grid."""
    import xarray as xr

    calls = []
    monkeypatch.setattr(_phase, "_chunk", _fake_chunk_s0(calls))
    from jaxrod.cli._main import main

    out = tmp_path / "pd"
    assert main(["phase-diagram", "--psi0", "60,180", "--gaps", "0.2:0.6:0.2", "--s0", "0.01,0.03",
                 "--out", str(out), "--no-termination", "--json"]) == 3  # the stand-in's codes flag points
    rec = json.loads(capsys.readouterr().out)
    assert rec["s0"] == [0.01, 0.03] and os.path.exists(rec["png"])
    assert rec["computed_chunks"] == [[0.01, 60.0], [0.01, 180.0], [0.03, 60.0], [0.03, 180.0]]
    with xr.open_dataset(rec["netcdf"], engine="scipy") as ds:
        assert ds["alpha_c_up"].dims == ("s0", "psi0", "gap") and ds["s0"].values.tolist() == [0.01, 0.03]
    assert sorted(calls) == [(0.01, 60.0), (0.01, 180.0), (0.03, 60.0), (0.03, 180.0)]
    assert main(["phase-diagram", "--psi0", "60", "--gaps", "0.3", "--s0", "0.03", "--out", str(tmp_path / "one"),
                 "--no-termination", "--json"]) in (0, 3)
    rec = json.loads(capsys.readouterr().out)
    assert rec["s0"] == 0.03
    with xr.open_dataset(rec["netcdf"], engine="scipy") as ds:
        assert ds["alpha_c_up"].dims == ("psi0", "gap") and ds.attrs["s0"] == 0.03


def test_cli_s0_termination_gaps_per_width(tmp_path, monkeypatch, capsys):
    """Several widths: the figure's termination gaps are computed once per width."""
    monkeypatch.setattr(_phase, "_chunk", _fake_chunk_s0([]))
    seen = []

    def fake_gaps(psis, *, s0, n):
        seen.append((tuple(psis), s0, n))
        return {p: (0.6 + s0, 0.5 + s0) for p in psis}

    monkeypatch.setattr(jr.branches, "termination_gaps", fake_gaps)  # the CLI imports it from there
    from jaxrod.cli._main import main

    assert main(["phase-diagram", "--psi0", "60", "--gaps", "0.3,0.5", "--s0", "0.01,0.03", "--n", "40",
                 "--out", str(tmp_path), "--json"]) == 3
    rec = json.loads(capsys.readouterr().out)
    assert seen == [((60.0,), 0.01, 40), ((60.0,), 0.03, 40)]
    assert rec["termination_gaps"] == {"0.01": {"60": [0.61, 0.51]}, "0.03": {"60": [0.63, 0.53]}}


@pytest.mark.parametrize("value", ["0.02,0", "0.02,nan", "abc", "0.02,1.5", "0.02,0.02", "0.05:0.01:0.01", "-0.1"])
def test_cli_s0_bad_input(value, capsys, tmp_path):
    from jaxrod.cli._main import main

    assert main(["phase-diagram", "--out", str(tmp_path), "--s0", value]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--s0" in err[0] and "Traceback" not in err[0], err


def test_scalar_s0_keeps_the_grid(chunks):
    """A scalar `s0` (the default): dims `(psi0, gap)`, no `s0` coordinate, the width as the
    attribute `s0`, chunk files named by the fold angle alone."""
    assert set(chunks.dims) == {"psi0", "gap"} and "s0" not in chunks.coords
    assert chunks.attrs["s0"] == 0.02
    for k in _phase.VARIABLES:
        assert chunks[k].dims == ("psi0", "gap"), k
    assert _phase._chunk_path("d", 60.0) == os.path.join("d", "chunks", "psi0_60.nc")


def _assert_width_equals(ds, w, ref):
    """Every variable of `ds` at fold width `w` equals the single-width dataset `ref`: floats to
    1e-9 deg with NaN in the same places, codes and kinds exactly."""
    for k in _phase.VARIABLES:
        a, b = ds[k].sel(s0=w).values, ref[k].values
        if a.dtype.kind == "f":
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-9, err_msg=(w, k))
            assert np.array_equal(np.isnan(a), np.isnan(b)), (w, k)
        else:
            np.testing.assert_array_equal(a, b, err_msg=(w, k))


def test_s0_axis_equals_separate_phase_diagrams(chunks):
    """The real computation with an s0 axis (2 widths x 2 fold angles x the fixture's gaps,
    the chunk compiled for the fixture reused: s0 is traced) equals separate single-width
    phase diagrams: alpha_c and fold heights to 1e-9 deg, the same kinds and codes, and the
    widths change the numbers."""
    psis, widths = [30.0, 60.0], [0.02, 0.035]
    ds = jr.phase_diagram(psis, PHASE_GAPS, s0=widths, n=PHASE_N, progress=False)
    assert ds["alpha_c_up"].dims == ("s0", "psi0", "gap")
    other = jr.phase_diagram(psis, PHASE_GAPS, s0=0.035, n=PHASE_N, progress=False)
    for w, ref in ((0.02, chunks.sel(psi0=psis)), (0.035, other)):
        _assert_width_equals(ds, w, ref)
    up = ds["alpha_c_up"].sel(psi0=60.0, gap=0.5).values
    assert np.all(np.isfinite(up)) and abs(up[1] - up[0]) > 1e-3


@pytest.mark.slow  # compiles the vmapped chunk (25 s on 2 cores); CI checks the pairs' batching with stand-ins
def test_s0_axis_as_one_vmapped_call():
    """The s0 axis as one jitted, vmapped call over (s0, Psi0) pairs equals the separate
    single-width diagrams of one compiled call per Psi0: alpha_c to 1e-9 deg, same codes."""
    psis, gaps, widths = [30.0, 60.0], [0.3, 0.5, 0.8], [0.02, 0.035]
    vm = jr.phase_diagram(psis, gaps, s0=widths, n=24, batch="vmap", progress=False)
    for w in widths:
        _assert_width_equals(vm, w, jr.phase_diagram(psis, gaps, s0=w, n=24, batch="scan", progress=False))


def test_figure_marks_flagged_points_apart():
    """A point whose path is not successful is drawn as a red-edged triangle off the curve, with
    its own legend entry; the legend says which markers are snap up and snap down. A synthetic
    dataset: the figure reads nothing else."""
    import xarray as xr

    from jaxrod.plot import phase_figure

    gaps = np.array([0.1, 0.3, 0.5])
    up, dn = np.array([[50.0, 60.0, 70.0]]), np.array([[-50.0, -60.0, -70.0]])
    res_up = np.array([[int(jr.RESULTS.self_intersecting._value), 0, 0]], np.int32)
    zeros = np.zeros((1, 3), np.int32)
    ds = xr.Dataset({"alpha_c_up": (("psi0", "gap"), up), "alpha_c_down": (("psi0", "gap"), dn),
                     "kind_up": (("psi0", "gap"), zeros + 1), "kind_down": (("psi0", "gap"), zeros + 1),
                     "result_up": (("psi0", "gap"), res_up), "result_down": (("psi0", "gap"), zeros)},
                    coords={"psi0": [60.0], "gap": gaps})
    ax = phase_figure(ds).axes[0]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any(lab.startswith("flagged") for lab in labels), labels
    assert "snap up (filled)" in labels and "snap down (open)" in labels
    curve = [ln for ln in ax.get_lines() if ln.get_label() == "Ψ0 = 60°"][0]
    assert np.isnan(curve.get_ydata()[0]) and curve.get_ydata()[1] == 60.0  # off the curve
    marks = [ln for ln in ax.get_lines() if ln.get_marker() == "^" and len(ln.get_xdata())]
    assert len(marks) == 1 and list(marks[0].get_ydata()) == [50.0] and marks[0].get_markeredgecolor() == "red"
    # a dataset whose every path is successful has no flagged entry
    ok = ds.assign(result_up=(("psi0", "gap"), zeros))
    labels = [t.get_text() for t in phase_figure(ok).axes[0].get_legend().get_texts()]
    assert not any(lab.startswith("flagged") for lab in labels)
