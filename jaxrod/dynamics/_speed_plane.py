r"""The speed plane: the brink snap's speed $v_s$ over fold angles $\Psi_0$ and gaps $G/L$.

Each point is the run of one [`jaxrod.snap_speed`][] (snap angles, the
critical state nudged along its unstable mode, RATTLE to the snap's overshoot) of the
strip `make_scene(psi0, gap, 0, s0=s0, n=n)` (or, with `creases`, a crease of fold angle
psi0 at each given position), all points run by [`jaxrod.sweep`][] across
every device JAX sees (and every process after `jax.distributed.initialize()`), resumable
from `out`. The paper fits $v_s/v^\ast = v_m - a\,G/L - b\,\Psi_0$ to such points
(docs/model.md); `fit_speed_plane` does the same least-squares fit.
"""

from __future__ import annotations

import functools
import math

import numpy as np

import jax.numpy as jnp

from .._misc import check_grid
from ..model import Clamps, crease_layout, layout_strip, Mesh, Scene
from ..statics import float_scene
from ..sweeps import grid, MODES, ShardedMap, sweep
from ._scenes import NUDGE
from ._snap_speed import _options, _run

def _member(point, shared, *, mesh, opts, layout=()):
    strip = layout_strip(jnp.radians(point["psi0"]), shared, layout)
    scene = float_scene(Scene(strip, Clamps(point["gap"]), mesh))
    r = _run(scene, *opts)
    extra = {"v_s_creases": r.v_s_creases} if layout else {}
    return {**extra, "v_s": r.v_s, "v_s_raw": r.v_s_raw, "alpha_c_deg": jnp.degrees(r.alpha_c),
            "kind": r.kind.astype(jnp.int32), "t_peak": r.t_peak, "energy_drift": r.energy_drift,
            "num_steps": r.num_steps.astype(jnp.int32), "result": r.result._value.astype(jnp.int32)}


@functools.lru_cache(maxsize=8)
def _sharded(mesh, opts, devices, per_device, split, layout=()):
    """One `ShardedMap` per mesh, run options, split and crease layout (repeated calls reuse
    its compilation)."""
    return ShardedMap(functools.partial(_member, mesh=mesh, opts=opts, layout=layout), devices=devices,
                      per_device=per_device, mode=split)


def speed_plane(psi0_deg, gaps, *, direction="up", s0=0.02, n=48, nudge=NUDGE, t1=2.0, out=None, progress=True,
                devices=None, per_device=1, split="shard_map", on_batch=None, creases=None):
    r"""Brink snap speeds over the grid `psi0_deg` x `gaps` (an `xarray.Dataset`, dims
    `(psi0, gap)`).

    **Arguments:** `psi0_deg` fold angles in (0, 180] (degrees), `gaps` values of $G/L$ in
    (0, 1), `direction` "up" or "down", `s0`, `n` as in [`jaxrod.make_scene`][]; `nudge`,
    `t1` as in [`jaxrod.snap_speed`][] (RATTLE at its default step); `out` a directory for
    the resumable store (`speed_plane.nc` and its batch files); `progress`, `devices`,
    `per_device`, `split` (the `mode`) and `on_batch` as in [`jaxrod.sweep`][];
    `creases`: crease positions (fractions of L) for a strip with a crease of fold angle
    $\Psi_0$ and width `s0` at each (no centred crease; the mesh places a node at each),
    checked by `jaxrod.model.crease_layout` for every $\Psi_0$ of the grid.

    **Returns:** `v_s` (in $v^\ast$; NaN where the point does not snap or its run failed a
    check), `v_s_raw`, `alpha_c_deg`, `kind` (1 fold, 2 branch point), `t_peak`,
    `energy_drift`, `num_steps`, `result` (RESULTS codes: `successful`, `no_snap`, ...) and
    `device`, with the sweep's provenance attributes (`crease_positions` with `creases`);
    with `creases` also `v_s_creases` (dims `(psi0, gap, crease)`: each crease's peak speed
    in the snap, in the layout's order). `v_s` is the speed of the strip's midpoint
    ([`jaxrod.snap_speed`][]). Needs float64.
    """
    psis, gs = check_grid(psi0_deg, gaps, s0, "speed_plane")
    layout = () if creases is None else crease_layout(creases, psis, s0)
    mesh = Mesh(n, centres=layout) if layout else Mesh(n)
    if split not in MODES:
        raise ValueError(f"split must be one of {MODES}, got {split!r}")
    template = Scene(layout_strip(math.radians(psis[0]), s0, layout), Clamps(gs[0]), mesh)
    opts = _options(template, direction, nudge, 1e-3, None, t1, None, "rattle", None)
    attrs = {"n": int(n), "s0": float(s0), "direction": direction, "nudge": float(nudge), "t1": float(t1),
             "dt": opts[3], "solver": "rattle", "units": "v_s in v* = sqrt(B / (lambda L^2)), t in T = L / v*"}
    if layout:
        attrs["crease_positions"] = ",".join(f"{c:.12g}" for c in layout)
    sm = _sharded(mesh, opts, None if devices is None else tuple(devices), per_device, split, layout)
    ds = sweep(sm, grid(psi0=psis, gap=gs), shared=np.float64(s0), out=out, name="speed_plane", attrs=attrs,
               progress=progress, on_batch=on_batch, dims={"v_s_creases": ("crease",)} if layout else None)
    keep = dict(ds.attrs)
    ds = ds.drop_vars("point").set_index(point=["psi0", "gap"]).unstack("point")
    if layout:
        ds = ds.assign_coords(crease=np.asarray(layout)).transpose("psi0", "gap", ...)
    ds.attrs = keep
    return ds


def fit_speed_plane(ds):
    r"""Least-squares plane $v_s/v^\ast = v_m - a\,G/L - b\,\Psi_0$ ($\Psi_0$ in radians) through
    the finite `v_s` of a `speed_plane` dataset: `(v_m, a, b)` and the RMS residual."""
    v = np.asarray(ds["v_s"].values)
    P, G = np.meshgrid(np.radians(ds["psi0"].values), ds["gap"].values, indexing="ij")
    ok = np.isfinite(v)
    if ok.sum() < 3:
        raise ValueError("speed plane: at least 3 points with a finite v_s are needed for the fit")
    A = np.stack([np.ones(ok.sum()), -G[ok], -P[ok]], 1)
    coef, *_ = np.linalg.lstsq(A, v[ok], rcond=None)
    rms = float(np.sqrt(np.mean((A @ coef - v[ok]) ** 2)))
    return tuple(float(c) for c in coef), rms
