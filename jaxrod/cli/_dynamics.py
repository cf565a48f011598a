"""Dynamics subcommands: snap, speed-plane.

Each module in `jaxrod.cli._main._COMMAND_MODULES` defines `register(sub)`, which adds its
subparsers to the `jaxrod` parser and attaches `handler=<function(args) -> exit code>`
with `set_defaults`. Shared pieces: `jaxrod.cli._main.add_scene_args`, `make_scene_from_args`,
`InputError` (one-line error, exit 2), `EXIT_OK`, `EXIT_USAGE`, `EXIT_NOT_CONVERGED`.

`jaxrod snap` integrates one snap (brink, ramp or asymmetric scene) and prints v_s in
units of v* (and in m/s when the strip's material is given); `jaxrod speed-plane` runs
the grid Psi0 x G/L of brink snaps, writes each point to `DIR/speed_plane.csv` as it is
done (the whole file rewritten atomically: temp file, then `os.replace`; each row carries
the settings it was computed with), fits v_s/v* = v_m - a G/L - b Psi0 and draws
`DIR/speed_plane.png` beside the paper's plane (`jaxrod.paper.fit_plane`, `plot_plane`). A
rerun reads back the points already there with the same settings and computes only the
others; a torn or unreadable row is dropped and its
point recomputed. `jaxrod speed-plane --batch shard` runs the grid through
`jaxrod.speed_plane` instead: every point split across every device of every process
(`--coordinator` joins several), RATTLE only, stored in `DIR/speed_plane.nc` and resumable
from `DIR/chunks/`; the fit, figure and JSON are the same.
"""

from __future__ import annotations

import csv
import functools
import json
import math
import os

from .._records import snap_record
from ..results import RESULTS
from ._main import (EXIT_NOT_CONVERGED, EXIT_OK, InputError, _array_leaves, _contact_record, _result_name,
                    add_contact_args, add_distributed_args, add_scene_args, clearance_separation, contact_mode,
                    make_scene_from_args, needs_contact, writing)



def _add_run_args(p):
    g = p.add_argument_group("dynamics")
    g.add_argument("--direction", choices=("up", "down"), default="up", help="snap up or down (default up)")
    g.add_argument("--nudge", type=float, default=None,
                   help="brink: nudge along the unstable mode, rad RMS (default: the library's, "
                        "jaxrod.dynamics.NUDGE)")
    g.add_argument("--rate", type=float, default=0.5, help="ramp/asymmetric: clamp rate, rad per T (default 0.5)")
    g.add_argument("--solver", default="rattle",
                   help="rattle (default: fixed step, symplectic), hht (implicit, its step set by accuracy: "
                        "jaxrod.HHT() at its defaults, --rtol not used), tsit5, dopri5, dopri8, kvaerno3, kvaerno5")
    g.add_argument("--rtol", type=float, default=1e-6,
                   help="adaptive solvers: relative = absolute tolerance (default 1e-6)")
    g.add_argument("--t1", type=float, default=4.0, help="time limit in T (default 4)")


def register(sub):
    """Add `snap` and `speed-plane` to the `jaxrod` argument parser."""
    p = sub.add_parser("snap", help="integrate one dynamic snap, report the snapping speed v_s")
    add_scene_args(p)
    add_contact_args(p)
    p.add_argument("--scene", choices=("brink", "ramp", "asymmetric"), default="brink",
                   help="brink (critical state nudged), ramp (clamps rotated through alpha_c), asymmetric "
                        "(only the right clamp rotated from --alpha-right, left held at --alpha)")
    p.add_argument("--route", choices=("first", "second"), default=None,
                   help="brink: start at the critical point where the path snaps (first, default) or at the "
                        "next one of its branch past a branch point (second; jaxrod.snap_routes)")
    _add_run_args(p)
    m = p.add_argument_group("physical units (all five to report m/s and s)")
    for name in ("youngs-modulus", "density", "thickness", "width", "length"):
        m.add_argument(f"--{name}", type=float, default=None)
    p.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    p.add_argument("--plot", metavar="DIR", default=None, help="write fold.png, speed_map.png, energies.png, chrono.png")
    p.add_argument("--animate", metavar="FILE.gif", default=None, help="write an animated GIF of the snap")
    p.set_defaults(handler=_cmd_snap)

    q = sub.add_parser("speed-plane", help="v_s over Psi0 x G/L (brink snaps), CSV + fit + figure; resumable")
    q.add_argument("--out", metavar="DIR", default="jaxrod-speed-plane",
                   help="output directory; a rerun resumes from DIR/speed_plane.csv, reusing the points computed "
                        "with the same settings (default %(default)s)")
    q.add_argument("--psi0", default="30,60,90,120,180", help="comma-separated fold angles, deg")
    q.add_argument("--gaps", default="0.3,0.4,0.5,0.6,0.7", help="comma-separated G/L")
    q.add_argument("--n", type=int, default=60, help="segments (default 60)")
    q.add_argument("--s0", type=float, default=0.02)
    q.add_argument("--creases-at", default=None, metavar="LIST",
                   help="crease positions in L (comma list): a crease of each fold angle of --psi0 at each, "
                        "instead of the centred crease; the rows then carry each crease's v_s")
    _add_run_args(q)
    q.add_argument("--batch", choices=("points", "shard"), default="points",
                   help="points: one brink snap after the other, any --solver, DIR/speed_plane.csv (default); "
                        "shard: every point through jaxrod.speed_plane, split across every device of every "
                        "process (RATTLE), DIR/speed_plane.nc")
    add_distributed_args(q)
    q.set_defaults(handler=_cmd_speed_plane)


def _check_run_args(args):
    from ..dynamics import NUDGE, SOLVERS

    if args.nudge is None:  # the parser leaves it out: the dynamics are imported only where needed
        args.nudge = NUDGE
    if args.solver not in SOLVERS and args.solver != "hht":
        raise InputError(f"solver must be one of {sorted([*SOLVERS, 'hht'])}, got {args.solver!r}")
    for name in ("nudge", "rate", "rtol", "t1"):
        v = getattr(args, name)
        if not (math.isfinite(v) and v > 0):
            raise InputError(f"{name} must be a finite number > 0, got {v!r}")


def _physical(args):
    vals = [getattr(args, k) for k in ("youngs_modulus", "density", "thickness", "width", "length")]
    if all(v is None for v in vals):
        return None
    if any(v is None for v in vals):
        raise InputError("youngs-modulus, density, thickness, width, length: give all five or none")
    import jaxrod as jr

    try:
        st = jr.Strip.from_physical(youngs_modulus=vals[0], density=vals[1], thickness=vals[2], width=vals[3],
                                    length=vals[4])
    except ValueError as e:
        raise InputError(str(e)) from None
    return float(st.speed_gauge), float(st.time_unit)


def _solver(args):
    """`--solver` as `jr.simulate` takes it: "hht" is `jaxrod.HHT()`, the rest are its strings."""
    import jaxrod as jr

    return jr.HHT() if args.solver == "hht" else args.solver


def run_snap(scene, args, kind):
    import jaxrod as jr

    kw = dict(solver=_solver(args), rtol=args.rtol, atol=args.rtol, t1=args.t1)
    try:
        if kind == "asymmetric":
            start, tr = jr.snap_dynamics(scene, args.direction, kind="asymmetric", rate=args.rate,
                                         alpha_start=float(scene.clamps.alpha_right), **kw)
        else:
            route = (getattr(args, "route", None) or "first") if kind == "brink" else "first"
            start, tr = jr.snap_dynamics(scene, args.direction, kind=kind, nudge=args.nudge, rate=args.rate,
                                         route=route, **kw)
    except ValueError as e:
        raise InputError(str(e)) from None
    return start, tr


def _clearance(scene, tr, theta0=None):
    """The smallest clearance over the run's frames and the start state `theta0` (segments
    at least N/10 apart, as `jaxrod snap-angles` reports it), in L; NaN without a finite
    state."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import numpy as np

    import jaxrod as jr

    th = np.asarray(tr.theta)
    if theta0 is not None:
        th = np.concatenate([np.asarray(theta0)[None], th])
    th = th[np.all(np.isfinite(th), axis=1)]  # frames after the run's stop are inf
    if not th.size:
        return float("nan")
    m = clearance_separation(scene.mesh.n)
    # one compiled program for all frames (a CLI run calls this once)
    c = eqx.filter_jit(jax.vmap(functools.partial(jr.clearance, min_separation=m), in_axes=(0, None)))(
        jnp.asarray(th), scene)
    return float(np.min(np.asarray(c))) / float(scene.strip.length)


def _cmd_snap(args):
    _check_run_args(args)
    if args.route is not None and args.scene != "brink":
        raise InputError(f"route: --route chooses the critical point of a brink start; --scene {args.scene} "
                         "has none (use --scene brink, or leave --route out)")
    phys = _physical(args)
    import jaxrod as jr

    def run(scene):
        start, tr = run_snap(_array_leaves(scene), args, args.scene)
        rec = snap_record(start, tr, phys)
        c = _clearance(start.scene, tr, start.theta0)  # the start state and every frame, one program
        rec["clearance"] = c if math.isfinite(c) else None
        rec.update(_contact_record(start.scene))
        return start, tr, rec

    start, tr, rec = run(make_scene_from_args(args))
    if contact_mode(args) == "auto" and needs_contact([rec["clearance"]], [rec["result"]]):
        start, tr, rec = run(make_scene_from_args(args, contact=True))

    from ..plot import animate_snap, plot_snap

    if args.plot or args.animate:
        # rerun with the frames on the snap itself (a few durations before the peak to the end)
        dur = rec["snap_duration"] or 0.05
        ta = max(0.0, float(tr.t_peak) - 4.0 * dur)
        tb = float(tr.t_end)
        tr = jr.simulate(start.scene, start.theta0, start.protocol, direction=start.direction, t1=tb,
                         stop_at_snap=args.scene != "asymmetric", solver=_solver(args), rtol=args.rtol, atol=args.rtol,
                         frame_window=(ta, tb), n_frames=48)
    with writing("plot/animate"):
        if args.plot:
            rec["figures"] = plot_snap(tr, args.plot, title=f"Psi0 = {args.psi0:g} deg, G/L = {args.gap:g}")
        if args.animate:
            rec["animation"] = animate_snap(tr, args.animate)
    if args.json:
        print(json.dumps(rec))
    else:
        for k, v in rec.items():
            print(f"{k:24s} {v}")
    return EXIT_OK if rec["converged"] else EXIT_NOT_CONVERGED


# One row per grid point. The settings a row was computed with are columns of the row
# itself (`SETTINGS`): a rerun reuses exactly the rows of its own settings and computes the
# rest, rows of other settings stay in the file untouched (and out of this run's fit).
SETTINGS = ["n", "s0", "direction", "nudge", "solver", "rtol", "t1", "creases_at"]
RESULT_FIELDS = ["snaps", "alpha_c_deg", "v_s", "t_snap", "kinetic_energy_peak", "bending_energy_before",
                 "num_steps", "result", "v_s_creases"]
FIELDS = ["psi0_deg", "gap", *SETTINGS, *RESULT_FIELDS]


def _settings(args, layout=()):
    """A row's settings columns; the crease layout as `;`-separated positions ("" for the
    centred crease)."""
    return dict(n=int(args.n), s0=float(args.s0), direction=args.direction, nudge=float(args.nudge),
                solver=args.solver, rtol=float(args.rtol), t1=float(args.t1),
                creases_at=";".join(f"{c:.12g}" for c in layout))


def _parse_row(r):
    """One CSV row (a list of strings in FIELDS order) -> dict; ValueError when it is not a
    complete row this code wrote (a row torn by an interrupted write, an edited file)."""
    if len(r) != len(FIELDS):
        raise ValueError(f"{len(r)} fields instead of {len(FIELDS)}")
    r = dict(zip(FIELDS, r))

    def num(text, kind=float):
        if text in ("", "None", "nan"):
            return None
        return kind(text)

    if r["direction"] not in ("up", "down") or r["snaps"] not in ("True", "False") or not r["solver"]:
        raise ValueError("bad direction, snaps or solver")
    if r["result"] not in RESULTS._name_to_item:
        raise ValueError("bad result code")
    row = dict(psi0_deg=float(r["psi0_deg"]), gap=float(r["gap"]), n=int(r["n"]), s0=float(r["s0"]),
               direction=r["direction"], nudge=float(r["nudge"]), solver=r["solver"], rtol=float(r["rtol"]),
               t1=float(r["t1"]), creases_at=r["creases_at"], snaps=r["snaps"] == "True",
               num_steps=num(r["num_steps"], int), result=r["result"], v_s_creases=r["v_s_creases"] or None)
    row.update({k: num(r[k]) for k in RESULT_FIELDS if k not in row})
    return row


def _read_rows(path):
    """The complete rows of `path` and how many lines were dropped as unreadable (`[]`, 0
    when there is no file). A last line without its newline is a torn write and dropped.
    A file whose header is not FIELDS (an older jaxrod's, without the settings columns, or
    not this command's) is refused with one line: its rows cannot be matched to settings."""
    if not os.path.exists(path):
        return [], 0
    with open(path, newline="") as fh:
        text = fh.read()
    lines = text.splitlines(keepends=True)
    dropped = 0
    if lines and not lines[-1].endswith("\n"):  # torn by a kill during the write
        lines.pop()
        dropped += 1
    if not lines:
        return [], dropped
    records = list(csv.reader(lines))
    if records[0] != FIELDS:
        raise InputError(f"out: {path} is not a speed-plane CSV with the columns {','.join(FIELDS)} (an older "
                         "jaxrod's lacks the settings or result columns): move it away or choose another --out")
    rows = []
    for r in records[1:]:
        try:
            rows.append(_parse_row(r))
        except (ValueError, TypeError):
            dropped += 1
    return rows, dropped


def _write_atomic(path, write):
    """`write(fh)` into `path` + ".part", then `os.replace` onto `path`: a kill at any
    moment leaves either the old file or the new one, never a part of one."""
    tmp = path + ".part"
    with open(tmp, "w", newline="") as fh:
        write(fh)
    os.replace(tmp, path)


def _write_rows(path, rows):
    def write(fh):
        w = csv.DictWriter(fh, FIELDS)
        w.writeheader()
        for r in rows:
            w.writerow({k: r.get(k) for k in FIELDS})

    _write_atomic(path, write)


def _cmd_speed_plane(args):
    import sys

    import numpy as np
    from tqdm import tqdm

    import jaxrod as jr

    _check_run_args(args)
    try:
        psis = [float(x) for x in args.psi0.split(",")]
        gaps = [float(x) for x in args.gaps.split(",")]
    except ValueError:
        raise InputError("psi0/gaps: comma-separated numbers expected") from None
    from ._statics import _parse_list

    try:
        layout = () if args.creases_at is None else jr.model.crease_layout(
            _parse_list(args.creases_at, "creases-at"), psis, args.s0)
        for p in psis:
            for g in gaps:
                jr.make_scene(p, g, 0, s0=args.s0, n=args.n)
        os.makedirs(args.out, exist_ok=True)
    except ValueError as e:
        raise InputError(str(e)) from None
    except OSError as e:
        raise InputError(f"out: cannot create {args.out!r}: {e.strerror or e}") from None
    if args.batch == "shard":
        return _speed_plane_sharded(args, psis, gaps, layout)
    path = os.path.join(args.out, "speed_plane.csv")
    settings = _settings(args, layout)
    mine = lambda r: all(r[k] == v for k, v in settings.items())  # noqa: E731
    rows, dropped = _read_rows(path)
    done = {(r["psi0_deg"], r["gap"]) for r in rows if mine(r)}
    grid = [(p, g) for p in psis for g in gaps]
    todo = [pt for pt in grid if pt not in done]
    if dropped:
        print(f"jaxrod speed-plane: dropped {dropped} unreadable row(s) of {path} (an interrupted write?); "
              "their points are recomputed", file=sys.stderr)
    print(f"jaxrod speed-plane: {len(grid) - len(todo)} of {len(grid)} points read back from {path}, "
          f"{len(todo)} to compute", file=sys.stderr)
    if dropped or not os.path.exists(path):
        _write_rows(path, rows)
    computed = []
    for p, g in tqdm(todo, desc="speed plane", unit="strip"):
        scene = _array_leaves(jr.make_scene(p, g, 0, s0=args.s0, n=args.n) if not layout else
                              jr.make_scene(180.0, g, 0, s0=args.s0, n=args.n, creases=[(c, p) for c in layout]))
        snap = jr.snap_angles(scene)
        path_ = snap.up if args.direction == "up" else snap.down
        row = dict(psi0_deg=p, gap=g, **settings, snaps=bool(path_.snaps),
                   result=_result_name(path_.result) if path_.result != jr.RESULTS.successful else
                   ("successful" if bool(path_.snaps) else "no_snap"))
        if row["snaps"] and row["result"] == "successful":
            start, tr = jr.snap_dynamics(scene, args.direction, kind="brink", nudge=args.nudge, snap=snap,
                                         solver=_solver(args), rtol=args.rtol, atol=args.rtol, t1=args.t1)
            if layout:
                row["v_s_creases"] = ";".join(f"{float(v):.10g}" for v in np.asarray(tr.v_s_creases))
            row.update(alpha_c_deg=float(np.degrees(start.alpha_c)), v_s=float(tr.v_s),
                       t_snap=float(tr.t_cross), kinetic_energy_peak=float(tr.kinetic_peak),
                       bending_energy_before=float(start.bending_before), num_steps=int(tr.num_steps))
            row["snaps"] = bool(tr.snapped)
            row["result"] = (_result_name(tr.result) if tr.result != jr.RESULTS.successful else
                             "successful" if row["snaps"] else "snap_not_resolved")
        rows.append({k: row.get(k) for k in FIELDS})
        _write_rows(path, rows)  # the whole file, atomically, after every point
        computed.append([p, g])
    first, wanted = {}, set(grid)
    for r in rows:  # this run's rows in grid order (the first where a point is there twice)
        if mine(r) and (r["psi0_deg"], r["gap"]) in wanted:
            first.setdefault((r["psi0_deg"], r["gap"]), r)
    rows = [first[pt] for pt in grid]
    out = dict(points=len(rows), snapping=sum(bool(r["snaps"]) for r in rows), csv=path, computed_points=computed,
               creases_at=list(layout) or None)
    return _report_plane(args, rows, out, "the CSV")


def _report_plane(args, rows, out, where):
    """Count the flagged points, fit the plane and draw it (with 4 snapping points or more),
    write DIR/speed_plane_fit.json and print `out` as JSON; the exit status says whether
    every point is trusted (every file is written either way)."""
    import sys

    # every point whose code is neither `successful` nor `no_snap` (the codes are in `where`)
    flagged = {}
    for r in rows:
        if r["result"] not in ("successful", "no_snap"):
            flagged[r["result"]] = flagged.get(r["result"], 0) + 1
    out["flagged"] = flagged
    if flagged:
        print(f"jaxrod speed-plane: points not successful (codes in {where}): "
              + ", ".join(f"{k} x{v}" for k, v in sorted(flagged.items())), file=sys.stderr)
    if out["snapping"] >= 4:
        from ..paper import SPEED_PLANE, fit_plane, plot_plane

        coef, err, rms = fit_plane(rows)
        out.update(fit=dict(v_m=coef[0], a=coef[1], b=coef[2], stderr=err, rms=rms),
                   paper=dict(v_m=SPEED_PLANE[0], a=SPEED_PLANE[1], b=SPEED_PLANE[2]))
        plot_plane(rows, coef, os.path.join(args.out, "speed_plane.png"))
        out["figure"] = os.path.join(args.out, "speed_plane.png")
    _write_atomic(os.path.join(args.out, "speed_plane_fit.json"), lambda fh: json.dump(out, fh, indent=1))
    print(json.dumps(out))
    return EXIT_NOT_CONVERGED if flagged else EXIT_OK


def _speed_plane_sharded(args, psis, gaps, layout=()):
    """`jaxrod speed-plane --batch shard`: `jaxrod.speed_plane` across every device of every
    process (resumable from DIR/chunks), then the same fit, figure and JSON as the point-by-point run."""
    import jax

    import jaxrod as jr

    if args.solver != "rattle":
        raise InputError(f"solver: --batch shard runs RATTLE (jaxrod.speed_plane); got --solver {args.solver}")
    ds = jr.speed_plane(psis, gaps, direction=args.direction, s0=args.s0, n=args.n, nudge=args.nudge, t1=args.t1,
                        out=args.out, progress=jax.process_index() == 0, creases=layout or None)
    if jax.process_index() != 0:
        return EXIT_OK  # process 0 fits, draws and prints
    ok = int(jr.RESULTS.successful._value)
    rows = []
    for i, p in enumerate(ds["psi0"].values):
        for j, g in enumerate(ds["gap"].values):
            code = int(ds["result"].values[i, j])
            name = _result_name(code)
            v = float(ds["v_s"].values[i, j])
            row = dict(psi0_deg=float(p), gap=float(g), v_s=v if math.isfinite(v) else None,
                       snaps=code == ok, result=name)
            if layout:
                row["v_s_creases"] = ";".join(f"{float(x):.10g}" for x in ds["v_s_creases"].values[i, j])
            rows.append(row)
    out = dict(points=len(rows), snapping=sum(r["snaps"] for r in rows), netcdf=os.path.join(args.out,
               "speed_plane.nc"), computed_points=len(ds.attrs["computed_points"]),
               devices=int(ds.attrs["device_count"]), processes=int(ds.attrs["process_count"]),
               creases_at=list(layout) or None)
    return _report_plane(args, rows, out, "the NetCDF file")
