"""Statics subcommands beyond `equilibrium`/`snap-angles`: hysteresis, phase-diagram.

Each module in `jaxrod.cli._main._COMMAND_MODULES` defines `register(sub)`, which adds its
subparsers to the `jaxrod` parser and attaches `handler=<function(args) -> exit code>`
with `set_defaults`. Shared pieces: `jaxrod.cli._main.add_scene_args`, `make_scene_from_args`,
`InputError` (one-line error, exit 2), `EXIT_OK`, `EXIT_USAGE`, `EXIT_NOT_CONVERGED`.

    jaxrod hysteresis --psi0 60 --gap 0.5 [--s0 0.02] [--n 100] [--plot FILE.png] [--json]
    jaxrod phase-diagram --psi0 30,60,90,120,180 --gaps 0.1:0.9:0.02 [--s0 0.01,0.02,0.04] --out DIR [--json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys


def _fin(x, deg=False):
    x = float(x)
    if not math.isfinite(x):
        return None
    return math.degrees(x) if deg else x


def _cmd_hysteresis(args):
    from .._records import creases_record
    from ._main import EXIT_NOT_CONVERGED, EXIT_OK, _array_leaves, _result_name, make_scene_from_args, writing

    scene = make_scene_from_args(args)
    import numpy as np

    import jaxrod as jr

    h = jr.hysteresis(_array_leaves(scene))
    rec = {"psi0_deg": args.psi0, "gap": args.gap, "s0": args.s0, "n": args.n, "refine": args.refine,
           "creases": creases_record(scene)}
    for name, p, eb, ea in (("up", h.snap.up, h.energy_before_up, h.energy_after_up),
                            ("down", h.snap.down, h.energy_before_down, h.energy_after_down)):
        rec[f"snaps_{name}"] = bool(p.snaps)
        rec[f"alpha_c_{name}_deg"] = _fin(p.alpha_c, deg=True)
        rec[f"kind_{name}"] = jr.KIND_NAMES[int(p.kind)]
        rec[f"fold_height_before_{name}"] = _fin(p.fold_height_before)
        rec[f"fold_height_after_{name}"] = _fin(p.fold_height_after)
        rec[f"bending_energy_before_{name}"] = _fin(eb)
        rec[f"bending_energy_after_{name}"] = _fin(ea)
        rec[f"start_{name}"] = _result_name(p.start_result)
        rec[f"result_{name}"] = _result_name(p.result)
    branches = {}
    for b, bname in enumerate(jr.HYSTERESIS_BRANCHES):
        v = np.asarray(h.valid[b])
        branches[bname] = {
            "alpha_deg": np.degrees(np.asarray(h.alpha[b])[v]).tolist(),
            "fold_height": np.asarray(h.fold_height[b])[v].tolist(),
            "bending_energy": np.asarray(h.bending_energy[b])[v].tolist(),
            "num_unstable": np.asarray(h.num_unstable[b])[v].astype(int).tolist(),
        }
    rec["branches"] = branches
    if args.plot:
        title = f"Ψ0 = {args.psi0:g}°, G/L = {args.gap:g}, s0/L = {args.s0:g}, n = {args.n}"
        with writing("plot", args.plot):
            jr.plot_hysteresis(h, args.plot, title=title)
    bad = sorted({rec[f"{k}_{n}"] for k in ("start", "result") for n in ("up", "down")} - {"successful"})
    ok = not bad
    if args.json:
        print(json.dumps(rec))
    else:
        for name in ("up", "down"):
            a = rec[f"alpha_c_{name}_deg"]
            print(f"snap {name:<4}: " + ("does not snap" if a is None else
                  f"alpha_c = {a:+.6f} deg ({rec[f'kind_{name}']}), fold height "
                  f"{rec[f'fold_height_before_{name}']:+.4f} -> {rec[f'fold_height_after_{name}']:+.4f}, "
                  f"bending energy {rec[f'bending_energy_before_{name}']:.4f} -> "
                  f"{rec[f'bending_energy_after_{name}']:.4f}"))
        if args.plot:
            print(f"plot: {args.plot}")
    if bad:
        print(f"jaxrod hysteresis: path result {', '.join(bad)} (see jaxrod.RESULTS)", file=sys.stderr)
    return EXIT_OK if ok else EXIT_NOT_CONVERGED


def _parse_list(text, what):
    from ._main import InputError

    try:
        if ":" in text:
            parts = [float(x) for x in text.split(":")]
            if len(parts) != 3 or not parts[2] > 0 or not parts[1] >= parts[0]:
                raise ValueError
            lo, hi, step = parts
            k = int(math.floor((hi - lo) / step + 1e-9))
            return [round(lo + i * step, 12) for i in range(k + 1)]
        vals = [float(x) for x in text.split(",") if x.strip()]
        if not vals:
            raise ValueError
        return vals
    except ValueError:
        raise InputError(f"{what}: expected a comma list or START:STOP:STEP with STEP > 0, got {text!r}") from None


def _cmd_phase_diagram(args):
    from ._main import EXIT_NOT_CONVERGED, EXIT_OK, InputError

    psis = _parse_list(args.psi0, "psi0")
    gaps = _parse_list(args.gaps, "gaps")
    # one fold width: the (psi0, gap) grid; several: the grid gains an s0 axis
    s0s = _parse_list(args.s0, "--s0")
    from .._misc import check_param, fold_widths

    try:
        fold_widths(s0s)
    except ValueError as e:
        raise InputError(f"--s0: {e}") from None
    s0 = s0s[0] if len(s0s) == 1 else s0s
    try:
        for p in psis:
            check_param("psi0", p, lo=0.0, hi=180.0, hi_open=False, unit=" deg")
        for g in gaps:
            check_param("gap", g, lo=0.0, hi=1.0)
        import jaxrod as jr

        jr.Mesh(args.n, args.refine)
        layout = None
        if args.creases_at is not None:
            positions = _parse_list(args.creases_at, "creases-at")
            for w in s0s:
                layout = list(jr.model.crease_layout(positions, psis, w))
    except ValueError as e:
        raise InputError(str(e)) from None
    import jax  # joined to the other processes by `main` (`start_distributed`) when asked

    try:
        os.makedirs(args.out, exist_ok=True)
    except OSError as e:
        raise InputError(f"out: cannot create directory {args.out!r}: {e.strerror or e}") from None
    import time

    from ..branches import termination_gaps

    t0 = time.time()
    try:
        ds = jr.phase_diagram(psis, gaps, s0=s0, n=args.n, refine=args.refine, out=args.out,
                              batch=args.batch, split=args.split, progress=jax.process_index() == 0, creases=layout)
    except ValueError as e:  # a multi-process run without a shared --out
        raise InputError(str(e)) from None
    wall = time.time() - t0
    if jax.process_index() != 0:
        return EXIT_OK  # process 0 draws, prints and reports
    # the termination gaps are those of the centred crease: not drawn for a crease layout;
    # with several fold widths, one set per width ({s0: {psi0: (G*_up, G*_down)}})
    tg = None
    if not (args.no_termination or layout):
        tg = {w: termination_gaps(psis, s0=w, n=args.n) for w in s0s}
        if len(s0s) == 1:
            tg = tg[s0s[0]]
    png = os.path.join(args.out, "phase_diagram.png")
    width = f"s0/L = {s0s[0]:g}, " if len(s0s) == 1 else ""
    jr.plot_phase_diagram(ds, png, termination_gaps=tg,
                          title=f"critical clamp angles, {width}n = {args.n}, refine = {args.refine:g}"
                          + (f"; creases at {', '.join(f'{c:g}' for c in layout)} L" if layout else ""))

    def gaps_record(t):
        return {f"{k:g}": [_fin(a) for a in v] for k, v in t.items()}

    rec = {"out": args.out, "netcdf": os.path.join(args.out, "phase_diagram.nc"), "png": png,
           "psi0_deg": psis, "gaps": gaps, "s0": s0, "n": args.n, "refine": args.refine,
           "creases_at": layout, "computed_chunks": ds.attrs["computed_chunks"], "wall_s": wall, "batch": ds.attrs["batch"],
           "devices": int(ds.attrs["device_count"]), "processes": int(ds.attrs["process_count"]),
           "termination_gaps": None if tg is None else (gaps_record(tg) if len(s0s) == 1 else
                                                        {f"{w:g}": gaps_record(t) for w, t in tg.items()})}
    # paths whose outcome is unknown although their start state exists (the continuation
    # gave up, or the landing failed): NaN there does not mean "does not snap"
    import numpy as np

    ok = int(jr.RESULTS.successful._value)
    rec["unknown_paths"] = int(sum(np.sum((ds[f"start_{k}"].values == ok) & (ds[f"result_{k}"].values != ok))
                                   for k in ("up", "down")))
    # every code but success, counted over the grid (the codes themselves are in the file)
    names = {int(getattr(jr.RESULTS, nm)._value): nm for nm in jr.RESULTS._name_to_item}
    flagged = {}
    for k in ("start", "result"):
        for d in ("up", "down"):
            for v in ds[f"{k}_{d}"].values.ravel():
                if int(v) != ok:
                    key = f"{k}_{d}: {names.get(int(v), int(v))}"
                    flagged[key] = flagged.get(key, 0) + 1
    rec["flagged"] = flagged
    if args.json:
        print(json.dumps(rec))
    else:
        grid = f"{len(s0s)} x " if len(s0s) > 1 else ""
        print(f"wrote {rec['netcdf']} and {png} ({grid}{len(psis)} x {len(gaps)} points, {wall:.1f} s; "
              f"{len(rec['computed_chunks'])} chunks computed, the rest resumed)")
    if flagged:
        print("jaxrod phase-diagram: points not successful (codes in the NetCDF file): "
              + ", ".join(f"{k} x{v}" for k, v in sorted(flagged.items())), file=sys.stderr)
    # every file is written either way; the exit status says whether every point is trusted
    return EXIT_NOT_CONVERGED if flagged else EXIT_OK


def register(sub):
    """Add `hysteresis` and `phase-diagram` to the `jaxrod` argument parser."""
    from ._main import _EPILOG, DEFAULTS, add_distributed_args, add_scene_args

    p = sub.add_parser("hysteresis", help="quasi-static hysteresis loop: fold height and energy vs alpha",
                       description="Follow both equilibria of a creased strip under symmetric clamp rotation\n"
                                   "through their snap points (stable and unstable parts), report the jumps\n"
                                   "and draw the loop like the paper's Fig. 2a-b plus the bending energies\n"
                                   "(Fig. 3c). --alpha is ignored (the loop starts at 0).",
                       epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_scene_args(p)
    p.add_argument("--plot", metavar="FILE.png", default=None, help="write the loop figure to FILE")
    p.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    p.set_defaults(handler=_cmd_hysteresis)

    q = sub.add_parser("phase-diagram", help="alpha_c up/down over a grid of Psi0 and G/L (NetCDF + PNG)",
                       description="Critical clamp angles of both snapping paths over Psi0 x G/L (x s0 with\n"
                                   "several --s0), one compiled call per Psi0 (gaps in order, warm-started), or all\n"
                                   "Psi0 in one vmapped call (--batch vmap); with several fold widths each (s0, Psi0)\n"
                                   "pair is one such call. Writes DIR/phase_diagram.nc (xarray, NetCDF3) and\n"
                                   "DIR/phase_diagram.png; an interrupted run resumes from DIR/chunks/. With several\n"
                                   "devices (GPUs, or processes joined by --coordinator) the Psi0 are split across\n"
                                   "them (--batch shard).",
                       epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    q.add_argument("--psi0", default="30,60,90,120,180", metavar="LIST",
                   help="fold angles in degrees, comma list or START:STOP:STEP (default %(default)s)")
    q.add_argument("--gaps", default="0.1:0.9:0.02", metavar="LIST",
                   help="gaps G/L, comma list or START:STOP:STEP (default %(default)s)")
    q.add_argument("--s0", default=f"{DEFAULTS['s0']:g}", metavar="LIST",
                   help="fold width s0/L, or several (comma list or START:STOP:STEP): the grid gains an s0 axis, "
                        "one panel per s0 in the figure (default %(default)s)")
    q.add_argument("--n", type=int, default=DEFAULTS["n"], help="number of segments (default %(default)d)")
    q.add_argument("--refine", type=float, default=DEFAULTS["refine"],
                   help="mesh refinement ratio at the crease (default %(default)g)")
    q.add_argument("--out", default="jaxrod-phase", metavar="DIR", help="output directory (default %(default)s)")
    q.add_argument("--batch", choices=("auto", "scan", "vmap", "shard"), default="auto",
                   help="scan: one compiled call per Psi0; vmap: every Psi0 in one vmapped call; shard: the Psi0 "
                        "split across every device of every process (jaxrod.sweeps); auto: shard where JAX sees "
                        "several devices, else scan on the CPU (measured faster there), vmap on a GPU "
                        "(default %(default)s)")
    q.add_argument("--split", choices=("shard_map", "sharding"), default="shard_map",
                   help="--batch shard: jax.shard_map (each device runs its own loops) or jit with NamedSharding "
                        "(default %(default)s)")
    q.add_argument("--creases-at", default=None, metavar="LIST",
                   help="crease positions in L (comma list): a crease of each Psi0 at every one of them "
                        "instead of the centred crease (termination gaps are then not drawn)")
    q.add_argument("--no-termination", action="store_true",
                   help="do not compute the termination gaps G* (vertical lines) for the figure")
    q.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    add_distributed_args(q)
    q.set_defaults(handler=_cmd_phase_diagram)
