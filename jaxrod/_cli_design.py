"""Design subcommands: `jaxrod design` (inverse design of snap angles) and
`jaxrod reproduce` (the paper's numbers beside jaxrod's, Markdown report + figures).

Each module in `jaxrod._cli._COMMAND_MODULES` defines `register(sub)`, which adds its
subparsers to the `jaxrod` parser and attaches `handler=<function(args) -> exit code>`
with `set_defaults`. Shared pieces: `jaxrod._cli.add_scene_args`, `make_scene_from_args`,
`InputError` (one-line error, exit 2), `EXIT_OK`, `EXIT_USAGE`, `EXIT_NOT_CONVERGED`.

`design` exit codes: 0 target reached, 3 not reached (the JSON, with `reached: false` and
the best design found, is still printed), 2 bad input.
"""

from __future__ import annotations

import json
import math
import os

from ._cli import EXIT_NOT_CONVERGED, EXIT_OK, InputError


def _bounds(text):
    """'psi0=30:120,gap=0.3:0.95,s0=0.01:0.05' -> {'psi0_deg': (30, 120), ...}."""
    out = {}
    if not text:
        return out
    alias = {"psi0": "psi0_deg", "psi0_deg": "psi0_deg", "gap": "gap", "s0": "s0"}
    for item in text.split(","):
        try:
            name, rng = item.split("=")
            lo, hi = (float(v) for v in rng.split(":"))
        except ValueError:
            raise InputError(f"bounds: cannot parse {item!r} (expected NAME=LO:HI, e.g. gap=0.3:0.95)") from None
        if name.strip() not in alias:
            raise InputError(f"bounds: unknown parameter {name!r} (psi0, gap, s0)")
        out[alias[name.strip()]] = (lo, hi)
    return out


def _finite_or_none(x):
    x = float(x)
    return x if math.isfinite(x) else None


def _cmd_design(args):
    if args.target_speed is not None:
        import design as ds

        if not ds.dynamics_available():
            raise InputError("target-speed: the snapping-speed design needs jaxrod's dynamics API, "
                             "which is not available yet")
    targets = [(args.target_alpha_up, "up"), (args.target_alpha_down, "down"), (args.target_hysteresis, "hyst")]
    if all(t is None for t, _ in targets):
        raise InputError("design: give at least one target (--target-alpha-up, --target-alpha-down, "
                         "--target-hysteresis)")
    for val, name in ((args.target_alpha_up, "target-alpha-up"), (args.target_alpha_down, "target-alpha-down"),
                      (args.target_hysteresis, "target-hysteresis"), (args.tol, "tol"), (args.s0, "s0")):
        if val is not None and not math.isfinite(val):
            raise InputError(f"{name}: must be a finite number, got {val}")
    if args.tol <= 0:
        raise InputError(f"tol: must be > 0, got {args.tol}")
    if args.starts < 1:
        raise InputError(f"starts: must be >= 1, got {args.starts}")
    if args.n < 8 or args.n % 2:
        raise InputError(f"n: must be an even integer >= 8, got {args.n}")
    if args.max_iter < 1:
        raise InputError(f"max-iter: must be >= 1, got {args.max_iter}")
    import jax
    import jax.numpy as jnp

    import design as ds

    free = ("psi0_deg", "gap") + (("s0",) if args.free_s0 else ())
    try:
        param = ds.Parametrization(free=free, bounds=_bounds(args.bounds), fixed={"s0": args.s0})
        terms = []
        if args.target_alpha_up is not None:
            terms.append(ds.AlphaUp(args.target_alpha_up, tol=args.tol))
        if args.target_alpha_down is not None:
            terms.append(ds.AlphaDown(args.target_alpha_down, tol=args.tol))
        if args.target_hysteresis is not None:
            terms.append(ds.Hysteresis(args.target_hysteresis, tol=args.tol))
    except ValueError as e:
        raise InputError(str(e)) from None
    z0 = jnp.concatenate([param.from_values()[None], param.sample(jax.random.PRNGKey(args.seed), args.starts - 1)])
    res = ds.optimize(terms, param, z0, n=args.n, max_iter=args.max_iter, progress=not args.json)
    b = res.best
    rec = b.to_dict()
    rec.update({"num_starts": res.num_starts, "num_reached": res.num_reached, "wall_time_s": res.wall_time})
    if args.save:
        try:
            b.save(args.save)
        except OSError as e:
            raise InputError(f"save: cannot write {args.save!r}: {e.strerror or e}") from None
        rec["saved"] = [args.save + ".eqx", args.save + ".json"]
    if args.json:
        print(json.dumps(rec))
    else:
        print(f"design: Psi0 = {b.psi0_deg:.4f} deg, G/L = {b.gap:.5f}, s0 = {b.s0:.5g}  (n = {b.n})")
        for nm, a, t in zip(b.names, b.achieved.tolist(), b.targets.tolist()):
            print(f"  {nm:<18} {a:+.4f} deg  (target {t:+g} +- {args.tol:g})")
        print(f"  {b.message}; {res.num_reached}/{res.num_starts} starts reached the target "
              f"in {res.wall_time:.1f} s")
    return EXIT_OK if bool(b.reached) else EXIT_NOT_CONVERGED


def _cmd_reproduce(args):
    from design import _reproduce

    try:
        os.makedirs(args.out, exist_ok=True)
    except OSError as e:
        raise InputError(f"out: cannot create directory {args.out!r}: {e.strerror or e}") from None
    path = _reproduce.run(args.out, quick=args.quick, progress=True)
    print(f"wrote {path}")
    return EXIT_OK


def register(sub):
    """Add `design` and `reproduce` to the `jaxrod` argument parser."""
    import argparse

    from ._cli import _EPILOG, _number

    p = sub.add_parser("design", help="find (Psi0, G/L) with given snap angles",
                       description="Inverse design: multi-start Levenberg-Marquardt on (Psi0, G/L) [and s0]\n"
                                   "with implicit derivatives of the critical clamp angles; prints the design,\n"
                                   "the achieved values (on the design mesh --n) and whether the targets were\n"
                                   "reached (exit 3 if not).",
                       epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--target-alpha-up", type=_number, default=None, metavar="DEG", help="alpha_c_up target")
    p.add_argument("--target-alpha-down", type=_number, default=None, metavar="DEG", help="alpha_c_down target")
    p.add_argument("--target-hysteresis", type=_number, default=None, metavar="DEG",
                   help="alpha_c_up - alpha_c_down target")
    p.add_argument("--target-speed", type=_number, default=None, metavar="V",
                   help="snapping speed v_s / v* (needs the dynamics API)")
    p.add_argument("--tol", type=_number, default=0.1, metavar="DEG", help="tolerance (default %(default)g)")
    p.add_argument("--bounds", default="", metavar="SPEC",
                   help="e.g. psi0=30:120,gap=0.3:0.95 (defaults psi0 10:180, gap 0.05:0.95, s0 0.005:0.1)")
    p.add_argument("--s0", type=_number, default=0.02, help="fold width (fixed unless --free-s0)")
    p.add_argument("--free-s0", action="store_true", help="also optimize s0")
    p.add_argument("--n", type=int, default=100, help="design mesh, segments (default %(default)d)")
    p.add_argument("--starts", type=int, default=4, help="number of starts (default %(default)d)")
    p.add_argument("--max-iter", type=int, default=30, help="iterations per start (default %(default)d)")
    p.add_argument("--seed", type=int, default=0, help="random starts seed")
    p.add_argument("--save", metavar="PATH", default=None, help="write PATH.eqx and PATH.json")
    p.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    p.set_defaults(handler=_cmd_design)

    r = sub.add_parser("reproduce", help="the paper's numbers beside jaxrod's (Markdown report + figures)",
                       description="Compute the paper's results with the default strip and write\n"
                                   "DIR/report.md, DIR/results.json and figures. Sections that need the\n"
                                   "dynamics are marked 'not available yet' until that API exists.\n"
                                   "An interrupted run resumes from DIR/cache.json.",
                       epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    r.add_argument("--out", metavar="DIR", default="jaxrod-reproduce", help="output directory")
    r.add_argument("--quick", action="store_true", help="coarser mesh and sweep (< 3 min on 2 cores)")
    r.set_defaults(handler=_cmd_reproduce)
