r"""Command-line interface: `jaxrod equilibrium ...` and `jaxrod demo` (the default).

Nondimensional units throughout ($L = B = \lambda = 1$), angles in degrees, float64.

Exit codes: 0 success; 2 bad input (one line on stderr naming the parameter);
3 the solver did not converge or the requested state does not exist (the JSON, with
`converged: false` and the result message, is still printed).
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import json
import logging
import math
import os
import sys
import warnings

from .._records import creases_record

EXIT_OK = 0
EXIT_USAGE = 2
EXIT_NOT_CONVERGED = 3

DEFAULTS = dict(psi0=60.0, gap=0.5, alpha=0.0, s0=0.02, n=100, refine=1.0)

_EPILOG = """\
Units: L = B = lambda = 1 (nondimensional); angles in degrees.
Exit codes: 0 ok, 2 bad input, 3 no converged equilibrium (JSON still printed).
Compiled code is cached between runs in ~/.cache/jaxrod/xla (or JAX_COMPILATION_CACHE_DIR),
and snap-angles' lowered programs in ~/.cache/jaxrod/exported; JAXROD_NO_CACHE=1 disables
both. JAXROD_COMPILE=auto|fast|optimized chooses XLA's code generation (auto, the default:
each program compiled fast first and optimized once its runs have taken long enough)."""


# modules that register more subcommands (see `_build_parser`)
_COMMAND_MODULES = ("._critical", "._statics", "._dynamics", "._actuate", "._design")


class InputError(Exception):
    """Bad user input: reported as one line on stderr, exit code 2."""


@contextlib.contextmanager
def writing(option, path=None):
    """Turn an `OSError` while writing an output file into one `InputError` line naming the
    option (and the path, when given)."""
    try:
        yield
    except OSError as e:
        where = f" {path!r}" if path is not None else ""
        raise InputError(f"{option}: cannot write{where}: {e.strerror or e}") from None


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line on stderr (no usage block), exit 2."""

    def error(self, message):
        raise InputError(message)


def _quiet():
    """Silence JAX/XLA/equinox chatter so CLI output is only what we print."""
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "3")
    os.environ.setdefault("GRPC_VERBOSITY", "ERROR")
    for name in ("jax", "jaxlib", "jax._src.xla_bridge", "equinox", "absl"):
        logging.getLogger(name).setLevel(logging.ERROR)
    for mod in ("jax", "jaxlib", "equinox", "jaxtyping", "matplotlib"):
        warnings.filterwarnings("ignore", module=rf"{mod}(\.|$)")  # not jaxrod itself
    warnings.filterwarnings("ignore", category=UserWarning, message=".*(GPU|TPU|CUDA|cuda).*")
    warnings.filterwarnings("ignore", category=FutureWarning)
    warnings.filterwarnings("ignore", category=DeprecationWarning)


def _number(text):
    """float() that also accepts 'nan'/'inf' so the library reports them by name."""
    return float(text)


def _crease(text):
    """`C:PSI0[:S0]` -> a tuple of floats."""
    parts = text.split(":")
    try:
        vals = tuple(float(v) for v in parts)
    except ValueError:
        vals = ()
    if len(vals) not in (2, 3):
        raise argparse.ArgumentTypeError(f"crease: expected C:PSI0 or C:PSI0:S0, got {text!r}")
    return vals


def resolve_scene_args(args):
    """Fill the defaults that depend on other options: `--psi0` is 60 alone, 180 (no centred
    crease) when `--crease` is given."""
    if hasattr(args, "crease") and getattr(args, "psi0", 0.0) is None:
        args.psi0 = 180.0 if args.crease else DEFAULTS["psi0"]
    return args


def add_scene_args(p):
    g = p.add_argument_group("strip and clamps (L = 1, angles in degrees)")
    g.add_argument("--psi0", type=_number, default=None, metavar="DEG",
                   help="fold angle Psi0 in (0, 180] degrees of the crease at L/2; 180 = flat strip "
                        f"(default {DEFAULTS['psi0']:g}, or 180 when --crease is given)")
    g.add_argument("--crease", type=_crease, action="append", default=None, metavar="C:PSI0[:S0]",
                   help="a crease at s = C (in L, 0 < C < 1) of fold angle PSI0 degrees and width S0 "
                        "(default --s0); repeat for several. They add to the centred --psi0 crease, "
                        "which is absent (180) unless --psi0 is given")
    g.add_argument("--gap", type=_number, default=DEFAULTS["gap"], metavar="G",
                   help="clamp gap G/L in (0, 1) (default %(default)g)")
    g.add_argument("--alpha", type=_number, default=DEFAULTS["alpha"], metavar="DEG",
                   help="clamp angle alpha (both clamps unless --alpha-right; default %(default)g)")
    g.add_argument("--alpha-right", type=_number, default=None, metavar="DEG",
                   help="right clamp angle alpha_R for asymmetric actuation (default: = --alpha)")
    g.add_argument("--s0", type=_number, default=DEFAULTS["s0"], metavar="S0",
                   help="fold width s0/L > 0 (default %(default)g)")
    g.add_argument("--n", type=int, default=DEFAULTS["n"], metavar="N",
                   help="number of segments, even, >= 8 (default %(default)d)")
    g.add_argument("--refine", type=_number, default=DEFAULTS["refine"], metavar="R",
                   help="mesh refinement ratio at the crease, >= 1 (default %(default)g)")
    g.add_argument("--stretching", type=_number, default=None, metavar="K",
                   help="axial stiffness K L^2/B (extensible strip; default: inextensible)")
    g.add_argument("--gravity", type=_number, default=None, metavar="g",
                   help="gravity g in units of B/(lambda L^3) (default: none)")


def add_contact_args(p):
    g = p.add_argument_group("self-contact (by default modelled only where a state needs it)")
    g.add_argument("--contact-thickness", type=_number, default=None, metavar="H",
                   help="model self-contact in every run, the centrelines touching at H (in L; jaxrod.Contact). "
                        "Default: run without contact and, where a reported state comes within 0.01 L of itself "
                        "(or passes through itself), run again with contact at H = 0.01")
    g.add_argument("--no-contact", action="store_true",
                   help="never model self-contact (a state through itself is reported as self_intersecting)")


def contact_mode(args):
    """'on' (`--contact-thickness`), 'off' (`--no-contact`) or 'auto'."""
    h, off = getattr(args, "contact_thickness", None), getattr(args, "no_contact", False)
    if h is not None and off:
        raise InputError("contact-thickness: --contact-thickness and --no-contact exclude each other")
    return "on" if h is not None else ("off" if off else "auto")


def needs_contact(clearances, results):
    """Auto mode: a reported state within the default contact thickness of itself (clearance
    in L, None where unknown) or passing through itself."""
    from ..model import CONTACT_THICKNESS

    return (any(c is not None and c < CONTACT_THICKNESS for c in clearances)
            or any(r == "self_intersecting" for r in results))


def _contact_record(scene):
    c = scene.contact
    return {"contact": c is not None, "contact_thickness": None if c is None else float(c.thickness)}


def _build_parser():
    from .. import __version__

    parser = _Parser(
        prog="jaxrod",
        description="Equilibria and stability of a creased elastic strip between two clamps.\n"
                    "Without a subcommand, runs `jaxrod demo`.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"jaxrod {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="{equilibrium,snap-angles,demo}")

    p = sub.add_parser("equilibrium", help="solve the up or down equilibrium of one strip",
                       description="Solve the stable up or down state of a creased strip and report\n"
                                   "fold height, energies, end compression and the smallest eigenvalues\n"
                                   "of the constrained Hessian (asymmetric modes included).",
                       epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_scene_args(p)
    add_contact_args(p)
    p.add_argument("--state", choices=("up", "down"), default="down",
                   help="which state: up (fold height > 0) or down (< 0) (default %(default)s)")
    p.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    p.add_argument("--plot", metavar="FILE.png", default=None, help="draw the shape with its clamps to FILE")

    q = sub.add_parser("snap-angles", help="critical clamp angles of both snapping paths",
                       description="Continue the down state (alpha increasing) and the up state (alpha\n"
                                   "decreasing) under symmetric clamp rotation and report where each loses\n"
                                   "stability (alpha_c), of what kind (fold or branch_point), and the fold\n"
                                   "height just before and after; past a branch point, the next critical\n"
                                   "point of the same branch (alpha_c2, kind2: the route a fast ramp of a\n"
                                   "nearly perfect strip takes, jaxrod.snap_routes); the clearance of the\n"
                                   "reported states (smallest distance between segments at least N/10 apart\n"
                                   "along the strip, in L).\n"
                                   "The loop starts at alpha = 0: --alpha alone is ignored; with\n"
                                   "--alpha-right, the clamps' difference is kept as a misalignment.",
                       epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_scene_args(q)
    add_contact_args(q)
    q.add_argument("--no-extrapolate", dest="extrapolate", action="store_false",
                   help="report the angles of the n-segment mesh only (error up to ~0.17 deg at n = 100) instead "
                        "of the default Richardson extrapolation from n and 2n segments (error ~1e-4 deg)")
    q.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")

    d = sub.add_parser("demo", help="up and down states of the default strip, table + PNG + JSON (default)",
                       description="Solve the up and down equilibria of the default strip (Psi0 = 60 deg,\n"
                                   "G/L = 0.5, s0 = 0.02, alpha = 0, n = 100), print a table and write\n"
                                   "DIR/equilibria.png and DIR/equilibria.json.",
                       epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    d.add_argument("--out", metavar="DIR", default="jaxrod-out", help="output directory (default %(default)s)")
    # further subcommands live in their own modules; each calls `sub.add_parser(...)` and
    # `set_defaults(handler=...)`, the handler taking the parsed args and returning an exit code
    import importlib

    for name in _COMMAND_MODULES:
        importlib.import_module(name, __package__).register(sub)
    sub.metavar = "{" + ",".join(sub.choices) + "}"
    return parser


CONTACT_THICKNESS_MAX = 0.1
"""Largest `--contact-thickness` (units of L): a strip ten times thinner than long at most."""


def make_scene_from_args(args, contact=None):
    """The scene of the parsed arguments; with self-contact where `--contact-thickness` is
    given, or where `contact` is True (auto mode's second run, default thickness)."""
    import jaxrod as jr

    stretching = gravity = None
    model = None
    if contact_mode(args) == "on":
        if not 0.0 < args.contact_thickness <= CONTACT_THICKNESS_MAX:
            raise InputError(f"contact-thickness: must lie in (0, {CONTACT_THICKNESS_MAX:g}] (units of L, the "
                             f"strip's thickness; default 0.01), got {args.contact_thickness:g}")
        try:
            model = jr.Contact(args.contact_thickness)
        except ValueError as e:
            raise InputError(f"contact-thickness: {e}") from None
    elif contact:
        model = jr.Contact()
    if args.stretching is not None:
        try:
            stretching = jr.Stretching(args.stretching)
        except ValueError as e:
            raise InputError(f"stretching: {e}") from None
    if args.gravity is not None:
        try:
            gravity = jr.Gravity(args.gravity)
        except ValueError as e:
            raise InputError(f"gravity: {e}") from None
    try:
        return jr.make_scene(args.psi0, args.gap, args.alpha, alpha_right_deg=args.alpha_right, s0=args.s0,
                             n=args.n, refine=args.refine, stretching=stretching, gravity=gravity, contact=model,
                             creases=getattr(args, "crease", None) or None)  # S0 defaults to --s0
    except ValueError as e:
        raise InputError(str(e)) from None


def _array_leaves(scene):
    """Python-number leaves -> float64 arrays, so the jitted solver is compiled once per
    (state, mesh) and reused for every parameter value (and hits JAX's persistent cache)."""
    import jax.numpy as jnp
    import jax.tree_util as jtu

    def conv(x):
        if isinstance(x, (float, int)) and not isinstance(x, bool):
            return jnp.asarray(x, jnp.float64)
        return x

    return jtu.tree_map(conv, scene)


def _finite(x):
    x = float(x)
    return x if math.isfinite(x) else None


def _result_name(result):
    from ..results import result_name

    return result_name(result)


def _record(eq, state, k=4, angles_deg=None):
    """Everything the CLI reports about one equilibrium, as JSON-ready Python values.

    `angles_deg` = (psi0, alpha_left, alpha_right) as requested, reported verbatim
    instead of the radians->degrees round trip of the scene's values.

    When the solve did not succeed (`converged` false) the solver's last iterate is not
    the requested state, so the observables are `None` (JSON null) and `stable` is false.
    """
    import numpy as np

    import jaxrod as jr

    sc = eq.scene
    message = jr.RESULTS[eq.result]
    converged = bool(eq.converged)
    stab = jr.stability(eq, k=k)
    en = jr.energies(eq)
    lam = [_finite(v) for v in np.asarray(stab.eigenvalues)]
    if angles_deg is None:
        angles_deg = tuple(math.degrees(float(a)) for a in (sc.strip.psi0, sc.clamps.alpha_left,
                                                             sc.clamps.alpha_right))
    psi0_deg, aL_deg, aR_deg = (float(a) for a in angles_deg)
    rec = {
        "converged": converged,
        "result": message if message else "successful",
        "result_code": _result_name(eq.result),
        "state": state,
        "psi0_deg": psi0_deg,
        "gap": float(sc.clamps.gap),
        "alpha_left_deg": aL_deg,
        "alpha_right_deg": aR_deg,
        "s0": float(sc.strip.s0),
        "n": int(sc.mesh.n),
        "refine": float(sc.mesh.refine),
        "stretching": None if sc.stretching is None else float(sc.stretching.stiffness),
        "gravity": None if sc.gravity is None else float(sc.gravity.g),
        "creases": creases_record(sc),
        "fold_height": _finite(jr.fold_height(eq)),
        "crease_heights": [_finite(v) for v in np.asarray(jr.crease_heights(eq))],
        "bending_energy": _finite(en["bending"]),
        "stretching_energy": _finite(en["stretching"]),
        "gravity_energy": _finite(en["gravity"]),
        "contact_energy": _finite(en["contact"]),
        "total_energy": _finite(en["total"]),
        "compression": _finite(jr.compression(eq)),
        "min_eigenvalue": lam[0],
        "eigenvalues": lam,
        "eigenvalue_parity": [_finite(v) for v in np.asarray(stab.parity)],
        "num_unstable": int(stab.num_unstable),
        "stable": bool(stab.stable),
        "num_steps": int(eq.num_steps),
    }
    if not converged:
        rec.update({key: None for key in _OBSERVABLES})
        rec["stable"] = False
    return rec


_OBSERVABLES = ("fold_height", "crease_heights", "bending_energy", "stretching_energy", "gravity_energy", "contact_energy", "total_energy",
                "compression", "min_eigenvalue", "eigenvalues", "eigenvalue_parity", "num_unstable")


def _fmt(x, spec="+.6f"):
    return "n/a" if x is None else format(x, spec)


def _summary(rec):
    a = (f"alpha = {rec['alpha_left_deg']:g} deg" if rec["alpha_left_deg"] == rec["alpha_right_deg"]
         else f"alpha_L = {rec['alpha_left_deg']:g} deg, alpha_R = {rec['alpha_right_deg']:g} deg")
    lines = [
        f"{rec['state']} state: Psi0 = {rec['psi0_deg']:g} deg, G/L = {rec['gap']:g}, {a}, "
        f"s0 = {rec['s0']:g}, n = {rec['n']}",
        f"  result          {rec['result']}",
    ]
    if not rec["converged"]:
        lines[-1] += "  (NOT CONVERGED: no equilibrium reported)"
        return "\n".join(lines)
    lines += [
        f"  fold height     {_fmt(rec['fold_height'])} L",
        f"  bending energy  {_fmt(rec['bending_energy'], '.6f')} B/L",
        f"  compression     {_fmt(rec['compression'], '.6f')} B/L^2",
        "  eigenvalues     " + ", ".join(_fmt(v, ".6g") for v in rec["eigenvalues"])
        + f"  (parity {', '.join(_fmt(v, '+.2f') for v in rec['eigenvalue_parity'])})",
        f"  stable          {'yes' if rec['stable'] else 'no'} ({rec['num_unstable']} unstable modes)",
    ]
    if rec["stretching"] is not None:
        lines.insert(4, f"  stretching en.  {_fmt(rec['stretching_energy'], '.6g')} B/L")
    if rec["gravity"] is not None:
        lines.insert(4, f"  gravity energy  {_fmt(rec['gravity_energy'], '.6g')} B/L")
    if rec.get("clearance") is not None:
        lines.append(f"  clearance       {rec['clearance']:.4f} L")
    if rec.get("contact"):
        lines.append(f"  self-contact    modelled, thickness {rec['contact_thickness']:g} L, "
                     f"contact energy {_fmt(rec['contact_energy'], '.6g')} B/L")
    return "\n".join(lines)


def _enable_x64():
    import jax

    jax.config.update("jax_enable_x64", True)
    _compilation_cache(jax)


def _compilation_cache(jax):
    """Reuse compiled code between CLI runs (a snap-angles run spends most of its time
    compiling, `benchmarks/results/compile.md`): JAX's persistent cache in
    JAX_COMPILATION_CACHE_DIR if set, else ~/.cache/jaxrod/xla; JAXROD_NO_CACHE=1 turns it
    off. Best effort: an unwritable directory only means no cache."""
    if os.environ.get("JAXROD_NO_CACHE") or os.environ.get("JAX_COMPILATION_CACHE_DIR"):
        return
    path = os.path.join(os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "jaxrod", "xla")
    try:
        os.makedirs(path, exist_ok=True)
        jax.config.update("jax_compilation_cache_dir", path)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
    except Exception:  # noqa: BLE001 - a cache is an optimization only
        pass


def add_distributed_args(p):
    """`--coordinator`, `--num-processes`, `--process-id`: join a multi-process run."""
    g = p.add_argument_group("several processes or hosts (jax.distributed; run the same command in each)")
    g.add_argument("--coordinator", metavar="HOST:PORT", default=None,
                   help="address of process 0's coordinator; on SLURM or Open MPI, give 'auto' to take "
                        "everything from the job's environment")
    g.add_argument("--num-processes", type=int, default=None, metavar="P", help="number of processes")
    g.add_argument("--process-id", type=int, default=None, metavar="I", help="this process's index, 0 ... P-1")


def start_distributed(args):
    """`jax.distributed.initialize` from the `add_distributed_args` options (nothing when
    `--coordinator` is not given). Bad combinations are an `InputError`."""
    given = [args.num_processes is not None, args.process_id is not None]
    if args.coordinator is None:
        if any(given):
            raise InputError("coordinator: --num-processes and --process-id need --coordinator HOST:PORT")
        return
    import jax

    if args.coordinator == "auto":
        if any(given):
            raise InputError("coordinator: 'auto' takes the processes from the job's environment; "
                             "leave out --num-processes and --process-id")
        _c_stdout_to_stderr()
        jax.distributed.initialize()
        return
    if not all(given):
        raise InputError("num-processes: --coordinator HOST:PORT needs --num-processes and --process-id")
    if args.num_processes < 1 or not 0 <= args.process_id < args.num_processes:
        raise InputError(f"process-id: must lie in 0 ... {args.num_processes - 1} (--num-processes "
                         f"{args.num_processes}), got {args.process_id}")
    _c_stdout_to_stderr()
    jax.distributed.initialize(args.coordinator, num_processes=args.num_processes, process_id=args.process_id)


def _c_stdout_to_stderr():
    """Send what the C++ runtime writes to file descriptor 1 (the collectives' connection
    messages) to stderr, and keep Python's `sys.stdout` on the real stdout, so that `--json`
    still prints exactly one JSON object there."""
    sys.stdout.flush()
    real = os.dup(1)
    os.dup2(2, 1)
    sys.stdout = os.fdopen(real, "w", buffering=1)


def _cmd_equilibrium(args):
    scene = make_scene_from_args(args)  # validates before anything is compiled
    import jaxrod as jr

    a_r = args.alpha if args.alpha_right is None else args.alpha_right

    def solve(scene):
        eq = jr.initial_state(_array_leaves(scene), args.state)
        rec = _record(eq, args.state, angles_deg=(args.psi0, args.alpha, a_r))
        c = float(jr.clearance(eq.theta, eq.scene, force=eq.force, min_separation=clearance_separation(args.n)))
        rec["clearance"] = _finite(c / float(eq.scene.strip.length))
        rec.update(_contact_record(eq.scene))
        return eq, rec

    eq, rec = solve(scene)
    if contact_mode(args) == "auto" and needs_contact([rec["clearance"]], [rec["result_code"]]):
        eq, rec = solve(make_scene_from_args(args, contact=True))
    if args.plot:
        with writing("plot", args.plot):
            jr.plot_equilibria([eq], [args.state], args.plot)
    if args.json:
        print(json.dumps(rec))
    else:
        print(_summary(rec))
        if args.plot:
            print(f"  plot            {args.plot}")
    return EXIT_OK if rec["converged"] else EXIT_NOT_CONVERGED


def clearance_separation(n):
    """The `min_separation` of the clearance the CLI reports: segments at least N / 10
    apart along the strip (nearer pairs are bounded by their arclength, see
    `jaxrod.clearance`), at least 2."""
    return max(2, -(-n // 10))


def _snap_arrays(scene, continue_after_snap=False):
    """What `jaxrod snap-angles` prints about one mesh, as a flat dict of arrays (one
    jittable function of the scene, exported by `_exported.call`): both paths' snap
    angles, their second critical points (`jaxrod.snap_routes`) and clearances."""
    import jax.numpy as jnp

    import jaxrod as jr

    def code(r):
        return r._value

    def clearance(p, sc):
        # the smallest clearance over the reported states (critical and landed), in L
        m = clearance_separation(sc.mesh.n)
        c = [jr.clearance(p.theta_before, sc, force=p.force_before, min_separation=m),
             jr.clearance(p.theta_after, sc, force=p.force_after, min_separation=m)]
        c = jnp.stack([jnp.where(jnp.isfinite(x), x, jnp.inf) for x in c])
        return jnp.where(p.snaps, jnp.min(c), c[0]) / sc.strip.length

    r = jr.snap_angles(scene, continue_after_snap=continue_after_snap)
    routes = jr.snap_routes(scene, snap=r)
    out = {}
    for name in ("up", "down"):
        p, q = getattr(r, name), getattr(routes, name)
        out.update({f"alpha_c_{name}": p.alpha_c, f"kind_{name}": p.kind, f"snaps_{name}": p.snaps,
                    f"fold_height_before_{name}": p.fold_height_before,
                    f"fold_height_after_{name}": p.fold_height_after,
                    f"start_{name}": code(p.start_result), f"result_{name}": code(p.result),
                    f"alpha_c2_{name}": q.alpha_c2, f"kind2_{name}": q.kind2, f"result2_{name}": code(q.result),
                    f"clearance_{name}": clearance(p, scene), f"clicks_{name}": p.clicks})
    return out


def _extrapolated_arrays(coarse, fine, factor=2):
    """`jaxrod.snap_angles_extrapolated`'s values from the two meshes' `_snap_arrays`
    (`jaxrod.extrapolate_path`), the second critical points extrapolated where both meshes
    find one of the same kind, the clearances of the fine mesh. One small jitted program,
    quick to compile, rather than a dozen eager operations each compiled on first use."""
    import jax
    import numpy as np

    from ..results import result_from_name, result_name

    def codes(d):
        return {f"{k}_{name}": result_from_name(result_name(d[f"{k}_{name}"]))
                for k in ("result", "start") for name in ("up", "down")}

    out = _combine_program()(coarse, fine, codes(coarse), codes(fine), factor)
    return {k: np.asarray(v) for k, v in jax.device_get(out).items()}


@functools.cache
def _combine_program():
    import jax

    return jax.jit(_combine_meshes, static_argnums=4)


def _combine_meshes(coarse, fine, coarse_codes, fine_codes, factor):
    from types import SimpleNamespace

    import jax.numpy as jnp

    import jaxrod as jr

    def path(d, codes, name):
        # the refinement's own code is not printed (a failed refinement is in `result` already)
        return SimpleNamespace(snaps=d[f"snaps_{name}"], kind=d[f"kind_{name}"], clicks=d[f"clicks_{name}"],
                               alpha_c=d[f"alpha_c_{name}"], fold_height_before=d[f"fold_height_before_{name}"],
                               fold_height_after=d[f"fold_height_after_{name}"], result=codes[f"result_{name}"],
                               start_result=codes[f"start_{name}"], refine_result=None)

    out = {}
    for name in ("up", "down"):
        e = jr.extrapolate_path(path(coarse, coarse_codes, name), path(fine, fine_codes, name))
        both = (coarse[f"kind2_{name}"] == fine[f"kind2_{name}"]) & (fine[f"kind2_{name}"] != 0)
        a2 = jnp.where(both, jr.richardson(coarse[f"alpha_c2_{name}"], fine[f"alpha_c2_{name}"], factor),
                       fine[f"alpha_c2_{name}"])
        out.update({f"alpha_c_{name}": e.alpha_c, f"kind_{name}": fine[f"kind_{name}"],
                    f"fold_height_before_{name}": e.fold_height_before,
                    f"fold_height_after_{name}": e.fold_height_after,
                    f"start_{name}": e.start_result._value, f"result_{name}": e.result._value,
                    f"alpha_c_{name}_n": e.alpha_c_coarse, f"alpha_c_{name}_n_fine": e.alpha_c_fine,
                    f"error_{name}": e.error, f"consistent_{name}": e.consistent,
                    f"alpha_c2_{name}": a2, f"kind2_{name}": fine[f"kind2_{name}"],
                    f"result2_{name}": fine[f"result2_{name}"], f"clearance_{name}": fine[f"clearance_{name}"],
                    f"clicks_{name}": fine[f"clicks_{name}"]})
    return out


def _cmd_snap_angles(args):
    scene = make_scene_from_args(args)
    import functools

    import numpy as np

    import jaxrod as jr
    from . import _exported

    # one exported program per (query, mesh, contact model): a repeated query traces nothing.
    # Extrapolated, the two meshes are two programs
    def one_mesh(scene, continue_after_snap):
        name = "snap_angles" if continue_after_snap else "snap_angles_no_continuation"
        out, _ = _exported.call(name, functools.partial(_snap_arrays, continue_after_snap=continue_after_snap),
                                _array_leaves(scene))
        return {k: np.asarray(v) for k, v in out.items()}

    def run(scene):
        if not args.extrapolate:
            return one_mesh(scene, False)
        fine_scene = jr.refined_scene(scene)
        fine, coarse = one_mesh(fine_scene, False), one_mesh(scene, False)
        return _extrapolated_arrays(coarse, fine)

    out = run(scene)
    if contact_mode(args) == "auto":
        clear = [float(out[f"clearance_{d}"]) for d in ("up", "down")]
        res = [_result_name(out[f"result_{d}"]) for d in ("up", "down")]
        if needs_contact([c if np.isfinite(c) else None for c in clear], res):
            scene = make_scene_from_args(args, contact=True)
            out = run(scene)

    def val(x, deg=False):
        x = float(x)
        if not np.isfinite(x):
            return None
        return float(np.degrees(x)) if deg else x

    rec = {"psi0_deg": args.psi0, "gap": args.gap, "s0": args.s0, "n": args.n, "refine": args.refine,
           "creases": creases_record(scene), "extrapolated": bool(args.extrapolate), **_contact_record(scene)}
    if args.extrapolate:
        rec["n_fine"] = jr.refined_scene(scene).mesh.n
    for name in ("up", "down"):
        rec[f"alpha_c_{name}_deg"] = val(out[f"alpha_c_{name}"], deg=True)
        rec[f"kind_{name}"] = jr.KIND_NAMES[int(out[f"kind_{name}"])]
        rec[f"fold_height_before_{name}"] = val(out[f"fold_height_before_{name}"])
        rec[f"fold_height_after_{name}"] = val(out[f"fold_height_after_{name}"])
        rec[f"start_{name}"] = _result_name(out[f"start_{name}"])
        rec[f"result_{name}"] = _result_name(out[f"result_{name}"])
        rec[f"alpha_c2_{name}_deg"] = val(out[f"alpha_c2_{name}"], deg=True)
        rec[f"kind2_{name}"] = jr.KIND_NAMES[int(out[f"kind2_{name}"])]
        rec[f"result2_{name}"] = _result_name(out[f"result2_{name}"])
        rec[f"clearance_{name}"] = val(out[f"clearance_{name}"])
        if rec["contact"]:
            rec[f"clicks_{name}"] = int(out[f"clicks_{name}"])
        if args.extrapolate:
            rec[f"alpha_c_{name}_deg_n"] = val(out[f"alpha_c_{name}_n"], deg=True)
            rec[f"alpha_c_{name}_deg_n_fine"] = val(out[f"alpha_c_{name}_n_fine"], deg=True)
            rec[f"error_estimate_{name}_deg"] = val(out[f"error_{name}"], deg=True)
            rec[f"meshes_consistent_{name}"] = bool(out[f"consistent_{name}"])
    # any code but success (an unknown outcome, a substituted start, a state through itself,
    # meshes that disagree, no derivative) is printed and ends with EXIT_NOT_CONVERGED
    codes = [rec[f"{k}_{name}"] for k in ("result", "start", "result2") for name in ("up", "down")]
    failed = [c for c in codes if c != "successful"]
    if args.json:
        print(json.dumps(rec))
    else:
        for name in ("up", "down"):
            a = rec[f"alpha_c_{name}_deg"]
            res = rec[f"result_{name}"]
            if a is None:
                text = "does not snap" if res == "successful" else f"unknown ({res})"
            else:
                fa = rec[f"fold_height_after_{name}"]
                text = (f"alpha_c = {a:+.6f} deg ({rec[f'kind_{name}']}), fold height "
                        f"{rec[f'fold_height_before_{name}']:+.4f} -> "
                        + (f"{fa:+.4f}" if fa is not None else f"unknown ({res})"))
            print(f"snap {name:<4}: " + text)
            if rec[f"alpha_c2_{name}_deg"] is not None:
                a2 = rec[f"alpha_c2_{name}_deg"]
                print(f"           next critical point {a2:+.6f} deg ({rec[f'kind2_{name}']}), "
                      f"{abs(a2 - a):.3f} deg further")
            if rec[f"clearance_{name}"] is not None:
                print(f"           clearance {rec[f'clearance_{name}']:.4f} L")
            if rec.get(f"clicks_{name}"):
                print(f"           {rec[f'clicks_{name}']} contact click(s) before the snap")
        if rec["contact"]:
            print(f"self-contact modelled (thickness {rec['contact_thickness']:g} L)")
    if failed:
        print(f"jaxrod snap-angles: path result {', '.join(sorted(set(failed)))} (see jaxrod.RESULTS)",
              file=sys.stderr)
        return EXIT_NOT_CONVERGED
    return EXIT_OK


def _table(recs):
    head = f"{'state':<6} {'fold height':>12} {'bending E':>11} {'compression':>12} {'min eig':>10} {'stable':>7}"
    rows = [head, "-" * len(head)]
    for r in recs:
        rows.append(f"{r['state']:<6} {_fmt(r['fold_height'], '+12.5f')} {_fmt(r['bending_energy'], '11.5f')} "
                    f"{_fmt(r['compression'], '12.5f')} {_fmt(r['min_eigenvalue'], '10.5f')} "
                    f"{'yes' if r['stable'] else 'no':>7}" + ("" if r["converged"] else f"  ({r['result']})"))
    return "\n".join(rows)


def _cmd_demo(args):
    import jaxrod as jr

    out = args.out
    try:
        os.makedirs(out, exist_ok=True)
    except OSError as e:
        raise InputError(f"out: cannot create directory {out!r}: {e.strerror or e}") from None
    scene = _array_leaves(jr.make_scene(DEFAULTS["psi0"], DEFAULTS["gap"], DEFAULTS["alpha"], s0=DEFAULTS["s0"],
                                        n=DEFAULTS["n"]))
    states = ("up", "down")
    try:
        from tqdm import tqdm

        it = tqdm(states, desc="solving", unit="state", file=sys.stderr, leave=False, disable=None)
    except ImportError:
        it = states
    eqs, recs = [], []
    for st in it:
        if hasattr(it, "set_postfix_str"):
            it.set_postfix_str(st)
        eq = jr.initial_state(scene, st)
        eqs.append(eq)
        recs.append(_record(eq, st, angles_deg=(DEFAULTS["psi0"], DEFAULTS["alpha"], DEFAULTS["alpha"])))
    png = os.path.join(out, "equilibria.png")
    js = os.path.join(out, "equilibria.json")
    jr.plot_equilibria(eqs, list(states), png)
    with open(js, "w") as f:
        json.dump({"jaxrod_version": jr.__version__, "units": "L = B = lambda = 1, angles in degrees",
                   "equilibria": recs}, f, indent=2)
        f.write("\n")
    print("jaxrod demo: creased strip, Psi0 = 60 deg, G/L = 0.5, s0 = 0.02, alpha = 0, n = 100 (L = B = 1)")
    print(_table(recs))
    print(f"wrote {png}")
    print(f"wrote {js}")
    return EXIT_OK if all(r["converged"] for r in recs) else EXIT_NOT_CONVERGED


def main(argv=None):
    """Entry point of the `jaxrod` console script. Returns the exit code.

    `argv` defaults to `sys.argv[1:]`. Without a subcommand (`jaxrod`, `jaxrod --out DIR`)
    runs `demo`.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or (argv[0].startswith("-") and argv[0] not in ("-h", "--help", "--version")):
        argv = ["demo", *argv]
    with warnings.catch_warnings():
        _quiet()
        # the library's warnings (an under-resolved crease, ...) as one line each
        warnings.showwarning = lambda message, *a, **k: print(f"jaxrod: warning: {message}", file=sys.stderr)
        try:
            from .._compile import compile_mode

            try:
                compile_mode()  # JAXROD_COMPILE: checked before anything is compiled
            except ValueError as e:
                raise InputError(str(e)) from None
            args = resolve_scene_args(_build_parser().parse_args(argv))
            if hasattr(args, "coordinator"):
                start_distributed(args)  # before JAX starts its backend
            _enable_x64()  # before anything is computed
            if args.command == "equilibrium":
                return _cmd_equilibrium(args)
            if args.command == "snap-angles":
                return _cmd_snap_angles(args)
            if getattr(args, "handler", None) is not None:
                return args.handler(args)
            return _cmd_demo(args)
        except InputError as e:
            print(f"jaxrod: error: {e}", file=sys.stderr)
            return EXIT_USAGE
        except KeyboardInterrupt:
            print("jaxrod: interrupted", file=sys.stderr)
            return 130


if __name__ == "__main__":
    sys.exit(main())
