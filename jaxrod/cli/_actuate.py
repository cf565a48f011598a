"""`jaxrod actuate`: run a clamp program on the strip with balls to strike.

`--program FILE.json` holds the knots, `{"times": [...], "alpha_left_deg": [...],
"alpha_right_deg": [...]}` (`jaxrod.Program.to_json`), optionally with `"t1"` and `"state"`
("down" or "up", the start state at the first knot). `--program paper-fig4` runs the paper's
Fig. 4 sequence: the three programs of `jaxrod.paper.FIG4_PEAKS` one after the other
(`jaxrod.design.sequence_program`, the strip reset down between them) on the three balls,
and reports per program (`programs`) the peak speed of each ball still on the table, which
ball it launched (faster than `FIG4_V_LAUNCH`) and whether it spared the others (slower than
`FIG4_V_SPARE`); exit 3 unless every program launched its own ball and only it. The mesh
is `--n` 24 by default, with paper-fig4 the sequence's re-check mesh `FIG4_N_CHECK` (48).
`--objects FILE.json` holds the balls and the contact law, `{"balls": [{"name", "x", "y",
"radius", "mass"}, ...], "stiffness", "thickness", "table": {"deceleration"} | "floor":
{"height"}}` (only `balls` required);
without it the three balls of `jaxrod.paper.fig4_bodies` lie on a table above the strip. The JSON
output has the hits in time order (name, time, impulse, launch speed), the snaps (time,
kind, from, to, fold), the energy balance's relative error and the result code; exit code 0
for a successful run, 3 for a flagged one, 2 for bad input.
"""

from __future__ import annotations

import json
import math

from .._records import creases_record
from ._main import EXIT_NOT_CONVERGED, EXIT_OK, InputError, add_scene_args, make_scene_from_args, writing

def register(sub):
    p = sub.add_parser("actuate", help="run a clamp program on the strip with balls it strikes: hits, snaps, energy")
    add_scene_args(p)
    n_opt = p._option_string_actions["--n"]  # the mesh's default depends on --program
    n_opt.default, n_opt.help = None, "number of segments, even, >= 8 (default 24; 48 with --program paper-fig4)"
    p.add_argument("--program", metavar="FILE.json|paper-fig4", required=True,
                   help='knots {"times": [...], "alpha_left_deg": [...], "alpha_right_deg": [...]} (T, degrees), '
                        "or paper-fig4: the paper's three programs in sequence (jaxrod.paper.FIG4_PEAKS)"),
    p.add_argument("--objects", metavar="FILE.json", default=None,
                   help='balls {"balls": [{"name", "x", "y", "radius", "mass"}], "stiffness", "thickness", '
                        '"table": {"deceleration"} or "floor": {"height"}} (default: three balls on a table)')
    p.add_argument("--t1", type=float, default=None, help="end time in T (default: the last knot + 2)")
    p.add_argument("--undamped", action="store_true",
                   help="no dissipation (default: jaxrod.ACTUATOR_DAMPING and ACTUATOR_VISCOSITY)")
    p.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    p.add_argument("--animate", metavar="FILE.gif", default=None, help="write an animated GIF of the run")
    p.add_argument("--frames", type=int, default=96, metavar="K",
                   help="frames of the animation, evenly spaced over the run (default %(default)d)")
    p.set_defaults(handler=_cmd_actuate)


def _read_json(path, what):
    try:
        with open(path) as f:
            return json.load(f)
    except OSError as e:
        raise InputError(f"{what}: cannot read {path}: {e.strerror or e}") from None
    except json.JSONDecodeError as e:
        raise InputError(f"{what}: {path} is not valid JSON ({e.msg}, line {e.lineno})") from None


def bodies_from_json(obj):
    """`jaxrod.Bodies` from the `--objects` JSON; ValueError naming the bad field."""
    import jaxrod as jr

    if not isinstance(obj, dict) or not isinstance(obj.get("balls"), list) or not obj["balls"]:
        raise ValueError('objects: needs "balls", a non-empty list of {"name", "x", "y", "radius", "mass"}')
    balls = []
    for i, b in enumerate(obj["balls"]):
        if not isinstance(b, dict):
            raise ValueError(f"objects: balls[{i}] must be an object")
        missing = [k for k in ("name", "x", "y", "radius", "mass") if k not in b]
        if missing:
            raise ValueError(f"objects: balls[{i}] lacks {', '.join(missing)}")
        try:
            pos = (float(b["x"]), float(b["y"]))
            vel = tuple(float(v) for v in b.get("velocity", (0.0, 0.0)))
        except (TypeError, ValueError):
            raise ValueError(f"objects: balls[{i}]: x, y and velocity must be numbers") from None
        balls.append(jr.Ball(str(b["name"]), pos, b["radius"], b["mass"], vel))
    kw = {k: obj[k] for k in ("stiffness", "thickness") if k in obj}
    if "table" in obj:
        kw["table"] = jr.Table(**obj["table"]) if isinstance(obj["table"], dict) else jr.Table(obj["table"])
    if "floor" in obj:
        kw["floor"] = jr.Floor(**obj["floor"]) if isinstance(obj["floor"], dict) else jr.Floor(obj["floor"])
    return jr.Bodies(balls, **kw)


def _cmd_actuate(args):
    import numpy as np

    import jaxrod as jr

    fig4 = args.program == "paper-fig4"
    if fig4:
        import jaxrod.design as ds
        import jaxrod.paper as paper

        if args.n is None:
            args.n = paper.FIG4_N_CHECK

        program = ds.sequence_program(paper.FIG4_PEAKS)
        raw = {"t1": float(program.times[-1]) + 2.0}
    else:
        raw = _read_json(args.program, "program")
    try:
        if not fig4:
            program = jr.Program.from_json(raw)
        if args.objects:
            bodies = bodies_from_json(_read_json(args.objects, "objects"))
        else:
            from jaxrod.paper import fig4_objects_json

            bodies = bodies_from_json(fig4_objects_json())
    except (ValueError, TypeError) as e:
        raise InputError(str(e)) from None
    if args.n is None:
        args.n = 24
    if args.frames < 2:
        raise InputError(f"frames: must be an integer >= 2, got {args.frames}")
    state = raw.get("state", "down")
    t1 = args.t1 if args.t1 is not None else raw.get("t1")
    if t1 is not None and not (isinstance(t1, (int, float)) and math.isfinite(t1) and t1 > 0):
        raise InputError(f"t1 must be a finite number > 0, got {t1!r}")
    scene = make_scene_from_args(args)
    diss = jr.Dissipation() if args.undamped else None
    try:
        act = jr.actuate(scene, bodies, program, state=state, t1=t1, dissipation=diss, n_frames=args.frames)
    except ValueError as e:
        raise InputError(str(e)) from None
    res = jr.result_name(act.result)
    rec = dict(
        result=res, hits=act.hits(), snaps=act.snaps(), energy_error=float(act.energy_error),
        balls={name: dict(hit=bool(act.hit[m]), launch_speed=float(act.launch_speed[m]),
                          peak_speed=float(act.peak_speed[m]), min_clearance=float(act.min_clearance[m]),
                          final_position=[float(v) for v in np.asarray(act.ball_position[-1, m])])
               for m, name in enumerate(act.names)},
        program=program.to_json(), t1=float(np.nanmax(np.where(np.isfinite(np.asarray(act.t)), np.asarray(act.t), np.nan))),
        num_steps=int(act.num_steps), psi0_deg=args.psi0, creases=creases_record(scene), gap=args.gap, n=args.n,
        state=state,
        dissipation="none" if args.undamped else dict(damping=jr.ACTUATOR_DAMPING, viscosity=jr.ACTUATOR_VISCOSITY),
    )
    ok = res == "successful"
    if fig4:
        rec["programs"], confirmed = _fig4_programs(act)
        rec["sequence_confirmed"] = confirmed
        ok = ok and confirmed
    if args.animate:
        from ..plot import animate_actuation

        with writing("animate"):
            rec["animation"] = animate_actuation(act, args.animate)
    if args.json:
        print(json.dumps(rec))
    else:
        for h in rec["hits"]:
            print(f"hit   {h['name']:10s} t = {h['time']:.4f} T  impulse {h['impulse_norm']:.4g}  "
                  f"launch {h['launch_speed']:.3f} v*")
        for s in rec["snaps"]:
            print(f"{s['kind']:5s} t = {s['time']:.4f} T  {s['from']} -> {s['to']}  fold {s['fold']}")
        for q in rec.get("programs", []):
            spared = {k: v for k, v in q["min_clearance"].items() if k != q["target"]}
            print(f"program {q['program']} ({q['target']}): launched {', '.join(q['launched']) or 'nothing'}; "
                  + ", ".join(f"{k} {v:.2f}" for k, v in q["peak_speeds"].items()) + " v*"
                  + ("; clearance " + ", ".join(f"{k} {v:.3f}" for k, v in spared.items()) + " L" if spared else ""))
        print(f"energy_error {rec['energy_error']:.2e}  result {res}"
              + (f"  sequence_confirmed {rec['sequence_confirmed']}" if fig4 else ""))
    return EXIT_OK if ok else EXIT_NOT_CONVERGED


def _fig4_programs(act):
    """Per program of the paper's Fig. 4 sequence: its target, peaks, time window, the peak
    speed and the smallest clearance to the strip (L) of each ball still on the table, the
    balls it launched and whether it launched its own ball and spared the others; and whether
    all three did."""
    import jaxrod.design as ds
    import jaxrod.paper as paper

    targets = list(paper.FIG4_PROGRAMS)
    out, confirmed = [], True
    clear = ds.sequence_clearances(act, targets)
    for k, (sp, win) in enumerate(zip(ds.sequence_speeds(act, targets), ds.sequence_windows(len(targets)))):
        launched, spared, good = ds.stage_outcome(sp, targets[k], v_launch=paper.FIG4_V_LAUNCH,
                                                  v_spare=paper.FIG4_V_SPARE)
        confirmed = confirmed and good
        out.append(dict(program="ABC"[k], target=targets[k], peaks_deg=list(paper.FIG4_PEAKS[k]), window=list(win),
                        peak_speeds=sp, min_clearance=clear[k], launched=launched, spared_others=spared,
                        as_designed=good))
    return out, confirmed
