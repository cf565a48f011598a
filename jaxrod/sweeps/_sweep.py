r"""A resumable sweep: one function over a list (or grid) of points, on every device.

`sweep(fn, points)` evaluates `fn(member, shared)` at every point (a member is one value of
each named parameter) in batches of `devices x per_device` members through
[`ShardedMap`][jaxrod.ShardedMap] and returns an `xarray.Dataset` with dimension
`point`, the parameters as coordinates, one variable per output of `fn` (integer result
codes included, as `fn` returns them) and `device`, the id of the device that computed each
point (`-1` for points read back from an earlier run).

**Store.** With `out`, every finished batch is written at once to
`out/chunks/points_<first>_<last>.nc` (NetCDF3 through scipy; the file is written under a
temporary name and renamed, so a kill never leaves half a batch), and the assembled dataset
to `out/<name>.nc`. A rerun with the same `name`, points, `shared` and `attrs` (their
SHA-256 is the store's `fingerprint`) reads back every point some batch file holds and
computes only the others, in batches of the devices it has now: a run killed anywhere loses
at most the batch in flight, and no finished point is computed twice. Files with another
fingerprint are ignored, never deleted.

**Processes.** After `jax.distributed.initialize()` (one process per host, the same script
everywhere) the batches span every device of every process. Process 0 decides what is left
to compute (it reads the store) and broadcasts that; it alone writes files and draws the
progress bar; every process returns the whole dataset.

**Provenance** (dataset attributes): `jaxrod_version`, `jax_version`, `backend`,
`devices` (kind and id of each), `device_count`, `process_count`, `split` (the `mode`), `per_device`,
`date_utc`, `fingerprint`, and the caller's `attrs`; `computed_points` (indices computed by
this call) and `batch_seconds` (wall time of each of this call's batches).
"""

from __future__ import annotations

import datetime as _dt
import glob
import hashlib
import json
import os
import time

import numpy as np

import jax

from .._misc import package_version
from ._map import ShardedMap, agree, process_index


def grid(**axes):
    """The Cartesian product of the named 1-D `axes` as a dict of flat arrays (C order: the
    last axis varies fastest), for `sweep`; `Dataset.set_index(point=list(axes)).unstack("point")`
    turns a sweep's result back into the grid."""
    if not axes:
        raise ValueError("grid: at least one axis is needed")
    vals = [np.atleast_1d(np.asarray(v, float)) for v in axes.values()]
    for k, v in zip(axes, vals):
        if v.ndim != 1 or v.size == 0:
            raise ValueError(f"{k}: a non-empty 1-D list of values is needed")
    mesh = np.meshgrid(*vals, indexing="ij")
    return {k: m.ravel() for k, m in zip(axes, mesh)}


def _points(points):
    if not points:
        raise ValueError("points: at least one named parameter is needed")
    out = {}
    for k, v in points.items():
        a = np.atleast_1d(np.asarray(v, float))
        if a.ndim != 1 or a.size == 0:
            raise ValueError(f"points[{k!r}]: a non-empty 1-D list of values is needed")
        out[k] = a
    sizes = {a.size for a in out.values()}
    if len(sizes) != 1:
        raise ValueError(f"points: every parameter needs the same number of values, got "
                         f"{ {k: a.size for k, a in out.items()} }")
    return out


def _fingerprint(name, points, shared, attrs):
    h = hashlib.sha256()
    h.update(json.dumps({"name": name, "attrs": attrs}, sort_keys=True, default=str).encode())
    for k in sorted(points):
        h.update(k.encode())
        h.update(np.ascontiguousarray(points[k], np.float64).tobytes())
    for leaf in jax.tree.leaves(shared):
        a = np.asarray(leaf)
        h.update(str(a.dtype).encode() + str(a.shape).encode())
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def _storage_dtype(dtype):
    """NetCDF3 holds int8/16/32 and float32/64: booleans and 64-bit integers become int32."""
    dtype = np.dtype(dtype)
    if dtype.kind in "biu":
        return np.dtype(np.int32)
    return dtype


def _provenance(sm: ShardedMap):
    return {"jaxrod_version": package_version(), "jax_version": jax.__version__,
            "backend": jax.default_backend(), "device_count": len(sm.devices),
            "devices": ", ".join(f"{d.device_kind} {d.id}" for d in sm.devices),
            "process_count": jax.process_count(), "split": sm.mode, "per_device": sm.per_device,
            "date_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}


def _batch_dataset(idx, values, device, names, dims):
    import xarray as xr

    data = {k: (("point",) + dims[k], values[k][idx]) for k in names}
    data["device"] = (("point",), device[idx].astype(np.int32))
    return xr.Dataset(data, coords={"point": idx.astype(np.int32)})


def _write(ds, path):
    tmp = path + ".part"
    ds.to_netcdf(tmp, engine="scipy", format="NETCDF3_64BIT")
    os.replace(tmp, path)


def _read_store(chunks, fingerprint, values, device, done, names, dims):
    """Fill `values`, `device`, `done` from every readable batch file of this fingerprint."""
    import xarray as xr

    for path in sorted(glob.glob(os.path.join(chunks, "points_*.nc"))):
        try:
            with xr.open_dataset(path, engine="scipy") as ds:
                ds = ds.load()
            if ds.attrs.get("fingerprint") != fingerprint:
                continue
            idx = ds["point"].values.astype(np.int64)
            if idx.size == 0 or idx.min() < 0 or idx.max() >= done.size:
                continue
            got = {k: ds[k].values for k in names}
            dev = ds["device"].values
            if any(ds[k].dims != ("point",) + dims[k] or got[k].shape[1:] != values[k].shape[1:] for k in names):
                continue
        except Exception:  # a foreign or damaged file: its points are computed again
            continue
        for k in names:
            values[k][idx] = got[k]
        device[idx] = dev
        done[idx] = True


def sweep(fn, points, *, shared=None, out=None, name="sweep", attrs=None, dims=None, devices=None,
          per_device=1, mode="shard_map", progress=True, on_batch=None):
    r"""`fn(member, shared)` at every point of `points`, split across all devices (module docstring).

    **Arguments:**

    - `fn`: a traceable function of `member` (a dict: parameter name -> scalar array) and
      `shared` returning a dict of arrays (scalars or any fixed shape), for example result
      codes and numbers. It runs under `vmap`: one member's failure must show in its own
      outputs (jaxrod's functions carry a result code for that).
    - `points`: dict parameter name -> 1-D values, all of one length (`grid` makes a product).
    - `shared`: a pytree of arrays every member sees (replicated on the devices).
    - `out`: a directory for the resumable store (module docstring); `name` the stored
      dataset's file name; `attrs` a dict of settings stored with it (part of the
      fingerprint: give every setting `fn` closes over, such as the mesh size).
    - `dims`: dict output name -> names of its axes beyond `point` (default `<name>_<k>`).
    - `devices`, `per_device`, `mode`: as [`ShardedMap`][jaxrod.ShardedMap]. `fn` may
      itself be a `ShardedMap` (then these three are its own): repeated sweeps of one
      function then reuse its compiled program instead of tracing and compiling a new one.
    - `progress`: a tqdm bar over points (process 0); `on_batch(indices)` is called after each
      computed batch is stored.

    **Returns:** an `xarray.Dataset` (module docstring).
    """
    import xarray as xr

    pts = _points(points)
    count = next(iter(pts.values())).size
    attrs = dict(attrs or {})
    sm = fn if isinstance(fn, ShardedMap) else ShardedMap(fn, devices=devices, per_device=per_device, mode=mode)
    shapes = sm.output_shapes({k: a[:1] for k, a in pts.items()}, shared)
    if not isinstance(shapes, dict) or not shapes:
        raise ValueError("fn: must return a non-empty dict of arrays")
    names = list(shapes)
    dims = dict(dims or {})
    dims = {k: tuple(dims.get(k, tuple(f"{k}_{i}" for i in range(len(shapes[k].shape))))) for k in names}
    for k in names:
        if len(dims[k]) != len(shapes[k].shape):
            raise ValueError(f"dims[{k!r}]: {len(shapes[k].shape)} names needed, got {dims[k]!r}")
    values = {}
    for k in names:
        dt = _storage_dtype(shapes[k].dtype)
        fill = np.nan if dt.kind == "f" else -1
        values[k] = np.full((count,) + tuple(shapes[k].shape), fill, dt)
    device = np.full(count, -1, np.int64)
    done = np.zeros(count, bool)
    fingerprint = _fingerprint(name, pts, shared, attrs)
    lead = process_index() == 0
    chunks = None
    if out is not None:
        chunks = os.path.join(out, "chunks")
        if lead:
            os.makedirs(chunks, exist_ok=True)
            _read_store(chunks, fingerprint, values, device, done, names, dims)
        values, device, done = agree((values, device, done))
    todo = np.flatnonzero(~done)
    bar = None
    if progress and lead:
        from tqdm.auto import tqdm

        bar = tqdm(total=count, initial=count - todo.size, desc=name, unit="pt")
    seconds = []
    for start in range(0, todo.size, sm.size):
        idx = todo[start:start + sm.size]
        t0 = time.perf_counter()
        res, dev = sm({k: a[idx] for k, a in pts.items()}, shared)
        seconds.append(time.perf_counter() - t0)
        for k in names:
            values[k][idx] = np.asarray(res[k]).astype(values[k].dtype)
        device[idx] = dev
        if chunks is not None and lead:
            ds = _batch_dataset(idx, values, device, names, dims)
            ds.attrs["fingerprint"] = fingerprint
            _write(ds, os.path.join(chunks, f"points_{idx[0]}_{idx[-1]}.nc"))
        if bar is not None:
            bar.update(idx.size)
        if on_batch is not None:
            on_batch(idx)
    if bar is not None:
        bar.close()
    data = {k: (("point",) + dims[k], values[k]) for k in names}
    data["device"] = (("point",), device.astype(np.int32))
    ds = xr.Dataset(data, coords={"point": np.arange(count, dtype=np.int32), **{k: ("point", a) for k, a in pts.items()}})
    ds.attrs.update({k: (json.dumps(v) if not isinstance(v, (str, int, float)) else v) for k, v in attrs.items()})
    ds.attrs.update(_provenance(sm), fingerprint=fingerprint, name=name)
    if out is not None and lead:
        _write(ds, os.path.join(out, f"{name}.nc"))
    ds.attrs["computed_points"] = todo.tolist()
    ds.attrs["batch_seconds"] = seconds
    return ds
