r"""Phase diagram of the snap angles (paper Fig. 2c): $\alpha_{c,\rm up}$ and
$\alpha_{c,\rm down}$ of [`jaxrod.snap_angles`][] over a grid of fold angles $\Psi_0$ and
gaps $G/L$ (symmetric actuation, $\alpha_L=\alpha_R=\alpha$, conventions of docs/model.md), and
optionally over fold widths $s_0$.

One chunk per $\Psi_0$: a single jitted call that runs through the gaps in order
(`lax.scan`). The start states of each gap (up and down at $\alpha=0$) come from Newton
started at the previous gap's states, accepted when the result is the same state
(converged, stable, fold height of the same sign, no angle changed by $\pi/2$ or more);
otherwise (the first gap, a state that stops existing) from the homotopy of
[`jaxrod.initial_state`][], as `snap_angles` builds them. `warm_starts` (0, 1 or 2) records
which. Then `snap_angles` runs from those states without its polish (no derivative) and
without following the landed branch after a snap (`continue_after_snap=False`), with
the same $\alpha_c$; each path starts from the previous gap's critical point
(`snap_angles(..., near=)`, checked as `jaxrod.branches._warm` describes) and walks its
whole branch only where that start fails its checks (the first gap, a change of kind, the
end of snapping). `warm_paths` (0, 1 or 2) records how many paths were warm. The homotopy
is most of the cost of a single call, which the warm starts save;
`tests/test_phase_diagram.py` checks a small grid against single `snap_angles` calls (the
same kinds, start codes and landing states).
$\Psi_0$ and the gaps are traced, so every chunk reuses one compilation (per mesh and grid
length). Each gap keeps its own result code: a gap where a state does not exist gives
NaN angles there and does not affect the others.

**One vmapped call** (`batch="vmap"`, the default on a GPU): every $\Psi_0$ chunk of the
grid in a single jitted call, `vmap` over $\Psi_0$ of the same scan over the gaps (same
warm starts, same per-gap result codes). Batched, each loop runs as long as its slowest
member and does every member's work, and an `lax.cond` on a batched predicate would run
both branches. So the Newton's inertia-correction ladder and the later stages of a snap
path are loops of at most one pass (`jaxrod._misc.run_if`), which under `vmap` run only when
some member needs them, with their inputs passed through an optimization barrier (without
it XLA hoisted the work out of the loop and ran it every time). The warm start and the
homotopy that replaces it where it fails are one loop with one Newton solve
(`initial_state_signed(..., warm=...)`): batched, a member whose warm start held waits
while another member runs its homotopy. On XLA:CPU the batched linear algebra goes through
`jaxrod.linalg.batched` (batched LAPACK calls inside the loops can deadlock XLA:CPU,
docs/limitations.md). On a CPU the sequential chunks run faster than the vmapped call
(`benchmarks/bench_phase.py` times both side by side, `benchmarks/results/phase.md`), so
`batch="auto"` picks `"scan"` (one call per $\Psi_0$) on the CPU and `"vmap"` elsewhere.

**The fold width as an axis** (`s0` a list or array): a chunk is then one pair
$(s_0, \Psi_0)$, and the pairs are the batch of the same machinery: one call per pair
(`"scan"`), every pair in one vmapped call (`"vmap"`, $s_0$ batched beside $\Psi_0$), or the
pairs split across the devices (`"shard"`). $s_0$ is traced like $\Psi_0$, so every pair
reuses the one compiled chunk (the mesh does not depend on $s_0$). The dataset gains a
leading `s0` dimension; a scalar `s0` keeps the `(psi0, gap)` grid and its files as they
are, so its stored chunks stay valid.

With `out`, each finished chunk is written to `out/chunks/psi0_<deg>.nc`
(`out/chunks/s0_<s0>_psi0_<deg>.nc` with an `s0` axis; NetCDF3 via scipy) and the run is
resumable: a chunk whose file exists with the same grid, $s_0$ and mesh is read back, not
recomputed. The assembled `xarray.Dataset` goes to `out/phase_diagram.nc`.
"""

from __future__ import annotations

import datetime
import functools
import math
import os

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jax import lax

from ._continuation import Continuation, SymmetricAlpha
from ..statics import float_scene
from ..statics import initial_state_signed
from .._misc import check_grid, fold_widths, package_version
from .._compile import jit
from ..model import Clamps, Contact, crease_layout, layout_strip, Mesh, Scene
from ._snap import _snap_angles_from
from ._warm import near_pair, unusable_near
from ..results import RESULTS
from ..sweeps import agree, MODES, ShardedMap

VARIABLES = ("alpha_c_up", "alpha_c_down", "kind_up", "kind_down", "fold_height_before_up",
             "fold_height_after_up", "fold_height_before_down", "fold_height_after_down",
             "start_up", "start_down", "result_up", "result_down", "warm_starts",
             "warm_paths")


def _warm_or_homotopy(scene, sgn, t_prev, m_prev, ok_prev):
    """The up (`sgn` = +1) or down (-1) state of `scene` at alpha = 0: Newton from the
    neighbouring gap's state when that exists and the result is the same state (converged,
    stable, fold height of the right sign, no angle changed by pi/2 or more, not passing
    through itself), else the homotopy of `jaxrod.initial_state`: one loop, one compiled
    Newton solve for both (`initial_state_signed(..., warm=...)`). Returns the equilibrium
    and whether the warm start was used."""
    return initial_state_signed(scene, sgn, warm=(t_prev, m_prev, ok_prev))


def _contact(key):
    """A `Contact` from its `(thickness, stiffness, exclusion)` key, None for None."""
    return None if key is None else Contact(*key)


def _contact_key(contact):
    if contact is None:
        return None
    if not isinstance(contact, Contact):
        raise ValueError(f"contact must be a jaxrod.Contact or None, got {type(contact).__name__}")
    return (float(contact.thickness), float(contact.stiffness), float(contact.exclusion))


def _kw(layout):
    """`layout` as a keyword only where there is one (stand-ins for `_chunk` need not know it)."""
    return {"layout": layout} if layout else {}


@jit
def _chunk(psi0, gaps, s0, mesh, keep_branch=False, settings=Continuation(), contact=None, layout=()):
    """All gaps at one fold angle (rad), one gap after the other (`lax.scan`): the start
    states of each gap by Newton from the previous gap's (homotopy where that fails), then
    `snap_angles` from them without the polish (no derivative) and
    without following the landed branch. `keep_branch` (static) also returns each path's
    walked branch (`branch_up`, `branch_down`: the first continuation stage, a `Branch`
    per gap) for the tests that check the walks themselves. `contact`: a
    `(thickness, stiffness, exclusion)` key of the scenes' `jaxrod.Contact`, or None;
    `layout`: crease positions (fractions of L, static) each folded by `psi0`, or () for the
    centred crease."""
    par = SymmetricAlpha()
    dtype = psi0.dtype
    N = mesh.n

    def one(carry, g):
        t_prev, m_prev, ok_prev, near = carry
        strip = layout_strip(psi0, s0, layout)
        scene = par.set(float_scene(Scene(strip, Clamps(g), mesh, contact=_contact(contact))), 0.0)
        # both start states through one traced body (`lax.map` over the side): one compiled
        # copy of the warm Newton and of the homotopy instead of two (a shorter XLA compile)
        is_sds = lambda x: isinstance(x, jax.ShapeDtypeStruct)  # noqa: E731
        static = eqx.filter(eqx.filter_eval_shape(initial_state_signed, scene, jnp.ones((), dtype)), is_sds, inverse=True)

        def start(args):
            eq, good = _warm_or_homotopy(scene, *args)
            return eqx.filter(eq, eqx.is_array), good

        eqs, warmed = lax.map(start, (jnp.asarray([1.0, -1.0], dtype), t_prev, m_prev, ok_prev))
        starts = eqx.combine(eqs, static)
        # each path from the previous gap's critical point where that passes the checks of
        # `jaxrod.branches._warm` (the whole path elsewhere); not where the walks are kept
        r = _snap_angles_from(scene, starts, settings, jnp.pi, 24, continue_after_snap=False,
                              near_paths=None if keep_branch else near)
        out = {}
        for name, p in (("up", r.up), ("down", r.down)):
            out[f"alpha_c_{name}"] = jnp.degrees(p.alpha_c)
            out[f"kind_{name}"] = p.kind.astype(jnp.int32)
            out[f"fold_height_before_{name}"] = p.fold_height_before
            out[f"fold_height_after_{name}"] = p.fold_height_after
            out[f"start_{name}"] = p.start_result._value.astype(jnp.int32)
            out[f"result_{name}"] = p.result._value.astype(jnp.int32)
        out["warm_starts"] = warmed.astype(jnp.int32).sum()
        out["warm_paths"] = r.up.warm.astype(jnp.int32) + r.down.warm.astype(jnp.int32)
        if keep_branch:
            for name, p in (("up", r.up), ("down", r.down)):
                out[f"branch_{name}"] = jax.tree.map(lambda x: x[0], p.branch)
        near = near_pair(r)
        return (starts.theta, starts.force, starts.result == RESULTS.successful, near), out

    first = unusable_near(N, dtype)
    init = (jnp.zeros((2, N), dtype), jnp.zeros((2, 2), dtype), jnp.zeros((2,), bool),
            jax.tree.map(lambda x: jnp.stack([x, x]), first))
    return lax.scan(one, init, gaps)[1]


@jit
def _grid(psis, gaps, s0, mesh, settings=Continuation(), contact=None, layout=()):
    """All chunks in one call: `vmap` of `_chunk` over the fold angles (rad) and, where `s0`
    holds one width per member (the `(s0, Psi0)` chunks of a grid with an `s0` axis), over
    the fold widths beside them; a scalar `s0` is shared by every member."""
    def one(p, s):
        return _chunk(p, gaps, s, mesh, settings=settings, contact=contact, **_kw(layout))

    return jax.vmap(one, in_axes=(0, None if jnp.ndim(s0) == 0 else 0))(psis, s0)


def _resolve_batch(batch):
    if batch not in ("auto", "scan", "vmap", "shard"):
        raise ValueError(f"batch must be 'auto', 'scan', 'vmap' or 'shard', got {batch!r}")
    if batch == "auto":
        if jax.device_count() > 1:
            return "shard"
        return "scan" if jax.default_backend() == "cpu" else "vmap"
    return batch


@functools.lru_cache(maxsize=8)
def _sharded(mesh, settings, devices, per_device, mode, contact=None, layout=()):
    """One `ShardedMap` of `_chunk` per mesh and split (so repeated calls reuse its
    compilation). A member is one chunk's `(psi0 (rad), s0)`, the gaps are shared: the
    fold widths of a grid with an `s0` axis are split across the devices with the fold
    angles."""
    return ShardedMap(lambda member, gaps: _chunk(member[0], gaps, member[1], mesh, settings=settings,
                                                  contact=contact, **_kw(layout)),
                      devices=devices, per_device=per_device, mode=mode)


def _attrs(gaps, s0, n, refine, contact=None, layout=()):
    # `chunk_variables` (not `variables`: scipy's netcdf_file has an attribute of that name):
    # a chunk written by a version with other variables is recomputed
    a = {"gaps_hash": ",".join(f"{g:.12g}" for g in gaps), "s0": float(s0), "n": int(n),
         "refine": float(refine), "chunk_variables": ",".join(VARIABLES),
         "contact": "none" if contact is None else "thickness {:.12g} stiffness {:.12g} exclusion {:.12g}".format(*contact)}
    if layout:
        a["crease_positions"] = ",".join(f"{c:.12g}" for c in layout)
    return a


def _chunk_dataset(psi0_deg, gaps, values, attrs):
    import xarray as xr

    data = {}
    for k in VARIABLES:
        v = np.asarray(values[k])
        data[k] = (("gap",), v.astype(np.int32) if v.dtype.kind in "iub" else v.astype(np.float64))
    ds = xr.Dataset(data, coords={"gap": np.asarray(gaps, float)}, attrs=attrs)
    return ds.expand_dims(psi0=[float(psi0_deg)])


def _chunk_path(out, psi0_deg, s0=None):
    # 12 significant digits (the CLI rounds its ranges to 12): two fold angles that differ
    # in the 7th digit get two files instead of overwriting each other's chunk on every run.
    # `s0` (a grid with an s0 axis) names the fold width too; a scalar s0 keeps the names
    # of the (psi0, gap) grid
    name = f"psi0_{psi0_deg:.12g}.nc" if s0 is None else f"s0_{s0:.12g}_psi0_{psi0_deg:.12g}.nc"
    return os.path.join(out, "chunks", name)


def _read_chunk(path, attrs, psi0_deg, gaps):
    """The finished chunk at `path` if it holds exactly this fold angle, these gaps and
    settings (`attrs`: mesh, s0, grid, variables), every variable of shape (1, gaps); else
    None, and the chunk is recomputed (a missing, truncated or foreign file alike)."""
    import xarray as xr

    if not os.path.exists(path):
        return None
    try:
        with xr.open_dataset(path, engine="scipy") as ds:
            ds = ds.load()
    except Exception:  # a truncated file from an interrupted write: recompute it
        return None
    try:
        if any(ds.attrs.get(k) != v for k, v in attrs.items()):
            return None
        if (ds["psi0"].values.tolist() != [float(psi0_deg)]
                or ds["gap"].values.tolist() != [float(g) for g in gaps]):
            return None
        if any(ds[k].dims != ("psi0", "gap") or ds[k].shape != (1, len(gaps)) for k in VARIABLES):
            return None
    except (KeyError, ValueError, TypeError):
        return None
    return ds


def _write(ds, path):
    tmp = path + ".part"
    ds.to_netcdf(tmp, engine="scipy", format="NETCDF3_64BIT")
    os.replace(tmp, path)  # atomic: an interrupted write never leaves a half chunk


def phase_diagram(psi0_deg, gaps, *, s0=0.02, n=100, refine=1.0, out=None, progress=True, on_chunk=None,
                  batch="auto", devices=None, per_device=1, split="shard_map", contact=None, creases=None):
    r"""Critical clamp angles over the grid `psi0_deg` x `gaps`, or `s0` x `psi0_deg` x
    `gaps` (an `xarray.Dataset`).

    **Arguments:** `psi0_deg` fold angles in (0, 180] (degrees), `gaps` values of $G/L$ in
    (0, 1), `n`, `refine`, `contact` (a [`jaxrod.Contact`][]: self-contact modelled)
    as in [`jaxrod.make_scene`][]; `s0` the fold width (units of L), one value or a list or
    array of distinct values (the grid's `s0` axis), each in (0, 1); `creases`: crease
    positions (fractions of L) for a strip
    with a crease at each, all of fold angle $\Psi_0$ and width `s0` (the mesh refined around
    them with `refine`; attribute `crease_positions`), instead of the one centred crease;
    `out` a directory for the
    resumable chunk files and `phase_diagram.nc`; `progress` a tqdm bar;
    `on_chunk(chunk, computed: bool)` called after each chunk, `chunk` its `psi0_deg` (the
    pair `(s0, psi0_deg)` with an `s0` axis); `batch` `"scan"` (one
    compiled call per chunk), `"vmap"` (every chunk still to compute in one vmapped
    call), `"shard"` (the chunks still to compute split across `devices`, default every
    device of every process, `per_device` of them per device in each call, by
    [`jaxrod.sweeps.ShardedMap`][] with its `mode` = `split`) or `"auto"` (`"shard"` where JAX
    sees more than one device, else `"scan"` on the CPU, where it runs faster, and
    `"vmap"` elsewhere). A chunk is one $\Psi_0$ (one pair $(s_0, \Psi_0)$ with an `s0`
    axis) and all the gaps. All give the same numbers. With several processes
    (`jax.distributed.initialize()`), process 0 writes the files and every process reads
    `out`, which must then be one shared folder.

    **Returns:** dataset with dims `(psi0, gap)` (`(s0, psi0, gap)` where `s0` is a list or
    array, with the coordinate `s0`; for a scalar the attribute `s0`): `alpha_c_up`,
    `alpha_c_down` (degrees,
    NaN where the path does not snap), `kind_up`/`kind_down` (0 none, 1 fold, 2 branch
    point), fold heights before/after each snap, `start_up`/`start_down` (RESULTS codes of
    the start states), `result_up`/`result_down` (RESULTS codes of the whole paths, as
    `SnapPath.result`: not successful where NaN angles do not mean "does not snap"), `warm_starts` (how many of the two start states came from the
    previous gap), `warm_paths` (how many of the two paths started from the previous gap's
    critical point; see the module docstring); attribute `computed_chunks` lists the chunks
    computed by this call, as `on_chunk` names them
    (the others were read back from `out`), `batch` the mode used, and the provenance
    `jaxrod_version`, `jax_version`, `backend`, `device_count`, `process_count`, `date_utc`
    (also in `phase_diagram.nc`). Needs float64.
    """
    import xarray as xr

    widths, axis = fold_widths(s0)
    psis, gaps = check_grid(psi0_deg, gaps, widths[0], "phase_diagram")
    layout = _layout(creases, psis, widths)
    mesh = Mesh(n, refine, centres=layout) if layout else Mesh(n, refine)
    ckey = _contact_key(contact)
    attrs = {w: _attrs(gaps, w, n, refine, ckey, layout) for w in widths}
    if out is not None:
        os.makedirs(os.path.join(out, "chunks"), exist_ok=True)
    g_arr = jnp.asarray(gaps, jnp.float64)
    batch = _resolve_batch(batch)
    if split not in MODES:
        raise ValueError(f"split must be one of {MODES}, got {split!r}")
    # the chunks, (s0, psi0) pairs in the order of the grid; named by psi0 alone without an s0 axis
    keys = [(w, p) for w in widths for p in psis]
    name = (lambda k: k) if axis else (lambda k: k[1])  # noqa: E731

    def path(k):
        return _chunk_path(out, k[1], k[0] if axis else None)

    cached = {k: (_read_chunk(path(k), attrs[k[0]], k[1], gaps) if out is not None else None) for k in keys}
    missing = np.asarray([cached[k] is None for k in keys])
    if not np.array_equal(agree(missing), missing):
        raise ValueError(f"out: process {jax.process_index()} finds other finished chunks in {out!r} than "
                         "process 0; a run of several processes needs `out` on one shared file system")
    todo = [k for k in keys if cached[k] is None]
    lead = jax.process_index() == 0
    batched = {}
    if batch == "vmap" and todo:
        # one call for every chunk still missing (the finished ones were read back above);
        # with an s0 axis the fold widths are batched beside the fold angles
        s0_arg = (jnp.asarray([k[0] for k in todo], jnp.float64) if axis
                  else jnp.asarray(widths[0], jnp.float64))
        vals = jax.device_get(_grid(jnp.asarray([math.radians(k[1]) for k in todo], jnp.float64), g_arr, s0_arg, mesh,
                                     contact=ckey, **_kw(layout)))
        batched = {k: {v: a[i] for v, a in vals.items()} for i, k in enumerate(todo)}
    sharded = None
    if batch == "shard":
        sharded = _sharded(mesh, Continuation(), None if devices is None else tuple(devices), per_device, split, ckey,
                           layout)
    chunks, computed = [], []
    it = keys
    if progress and lead:
        from tqdm import tqdm

        it = tqdm(keys, desc="phase diagram", unit="chunk" if axis else "Psi0")
    for k in it:
        ds = cached[k]
        fresh = ds is None
        if fresh:
            if sharded is not None and k not in batched:
                # the next batch of chunks still to compute, one (or `per_device`) per device
                left = todo[todo.index(k):][:sharded.size]
                members = (np.radians([q[1] for q in left]), np.asarray([q[0] for q in left], np.float64))
                vals, _ = sharded(members, np.asarray(gaps, np.float64))
                batched.update({q: {v: a[i] for v, a in vals.items()} for i, q in enumerate(left)})
            vals = batched.pop(k, None)
            if vals is None:
                vals = jax.device_get(_chunk(jnp.asarray(math.radians(k[1]), jnp.float64), g_arr,
                                             jnp.asarray(k[0], jnp.float64), mesh, contact=ckey, **_kw(layout)))
            ds = _chunk_dataset(k[1], gaps, vals, attrs[k[0]])
            if out is not None and lead:
                _write(ds, path(k))
            computed.append(name(k))
        chunks.append(ds)
        if on_chunk is not None:
            on_chunk(name(k), fresh)
    m = len(psis)
    if axis:
        rows = [xr.concat(chunks[i * m:(i + 1) * m], dim="psi0").expand_dims(s0=[w]) for i, w in enumerate(widths)]
        full = xr.concat(rows, dim="s0")
        base = {a: v for a, v in attrs[widths[0]].items() if a != "s0"}  # the coordinate holds them
    else:
        full = xr.concat(chunks, dim="psi0")
        base = attrs[widths[0]]
    full.attrs = dict(base, units="alpha in degrees, G/L and fold heights in units of L",
                      kinds="0 none, 1 fold, 2 branch_point")
    full["alpha_c_up"].attrs["long_name"] = "snap-up critical clamp angle (deg)"
    full["alpha_c_down"].attrs["long_name"] = "snap-down critical clamp angle (deg)"
    if axis:
        full["s0"].attrs["long_name"] = "fold width s0 / L"
    full.attrs.update(jaxrod_version=package_version(), jax_version=jax.__version__, backend=jax.default_backend(),
                      device_count=len(sharded.devices) if sharded is not None else 1,
                      process_count=jax.process_count(),
                      date_utc=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"))
    if out is not None and lead:
        _write(full, os.path.join(out, "phase_diagram.nc"))
    full.attrs["computed_chunks"] = computed
    full.attrs["batch"] = batch
    return full


def _layout(creases, psis, widths):
    """`creases` (positions, fractions of L) as a sorted static tuple (`crease_layout`),
    checked at every fold width of `widths`; () for None."""
    if creases is None:
        return ()
    for w in widths:
        layout = crease_layout(creases, psis, w)
    return layout


def termination_gaps(psi0_deg, *, s0=0.02, n=100):
    """`{psi0: (G*_up, G*_down)}` from `termination_gap` for each Psi0 (deg): the vertical
    lines of the phase-diagram figure."""
    from ._termination import termination_gap

    out = {}
    for p in np.atleast_1d(psi0_deg):
        t = termination_gap(float(p), s0=s0, n=n)
        out[float(p)] = (float(t.gap_up), float(t.gap_down))
    return out
