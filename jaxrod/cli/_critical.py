"""Critical-point subcommands: termination-gap.

Each module in `jaxrod.cli._main._COMMAND_MODULES` defines `register(sub)`, which adds its
subparsers to the `jaxrod` parser and attaches `handler=<function(args) -> exit code>`
with `set_defaults`. Shared pieces: `jaxrod.cli._main.add_scene_args`, `make_scene_from_args`,
`InputError` (one-line error, exit 2), `EXIT_OK`, `EXIT_USAGE`, `EXIT_NOT_CONVERGED`.
"""

from __future__ import annotations

import argparse
import json
import sys
import math


def register(sub):
    """Add `termination-gap` to the `jaxrod` argument parser."""
    from ._main import _EPILOG, _number

    p = sub.add_parser(
        "termination-gap", help="gap G*/L beyond which each path stops snapping",
        description="Scan the gap G/L with snap-angles and bisect where each path (snap up, snap down)\n"
                    "stops snapping by its criterion, to --tol in G/L (gap_criterion_*, the bracket), then\n"
                    "locate what ends each path exactly: the cusp of the snap-down fold pair (two-parameter\n"
                    "continuation of the fold in (G, alpha)) or the fold in G of the path's start state.\n"
                    "Reports gap_up, gap_down (the exact end where located: gap_source_*), the reason\n"
                    "(cusp, supercritical, start_state_lost, ...) and the instability kind just below G*.\n"
                    "A flat strip (--psi0 180) never stops snapping (gap 1).",
        epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--psi0", type=_number, default=60.0, metavar="DEG",
                   help="fold angle Psi0 in (0, 180] degrees (default %(default)g)")
    p.add_argument("--s0", type=_number, default=0.02, metavar="S0", help="fold width s0/L > 0 (default %(default)g)")
    p.add_argument("--n", type=int, default=100, metavar="N", help="number of segments, even, >= 8 (default %(default)d)")
    p.add_argument("--tol", type=_number, default=1e-5, metavar="TOL",
                   help="bracket width in G/L (default %(default)g)")
    p.add_argument("--creases-at", default=None, metavar="LIST",
                   help="crease positions in L (comma list): a crease of fold angle --psi0 at each, "
                        "instead of the centred crease")
    p.add_argument("--progress", action="store_true", help="show a progress bar on stderr")
    p.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    p.set_defaults(handler=_cmd_termination_gap)


def _cmd_termination_gap(args):
    from ._main import EXIT_NOT_CONVERGED, EXIT_OK, InputError

    import jaxrod as jr

    if not (math.isfinite(args.tol) and 0.0 < args.tol < 0.1):
        raise InputError(f"tol must lie in (0, 0.1), got {args.tol!r}")
    try:
        jr.make_scene(args.psi0, 0.5, s0=args.s0, n=args.n)  # validates psi0, s0, n
        from ._statics import _parse_list

        layout = None if args.creases_at is None else _parse_list(args.creases_at, "creases-at")
        r = jr.termination_gap(args.psi0, s0=args.s0, n=args.n, tol=args.tol, progress=args.progress,
                               creases=layout)
    except ValueError as e:
        raise InputError(str(e)) from None
    rec = r.to_dict()
    rec.update(s0=args.s0, n=args.n, tol=args.tol, creases_at=layout)
    if args.json:
        print(json.dumps(rec))
    else:
        for name in ("up", "down"):
            g = rec[f"gap_{name}"]
            crit = rec.get(f"gap_criterion_{name}")
            src = rec.get(f"gap_source_{name}", "none")
            extra = (f"; snap criterion {crit:.6f}" if src not in ("bisection", "none") and crit is not None else "")
            print(f"snap {name:<4}: " + ("never snaps" if g is None else
                  f"G*/L = {g:.6f} ({rec[f'reason_{name}']}, from {src}{extra}; last snap: {rec[f'kind_{name}']})")
                  + f"; result {rec[f'result_{name}']}")
    # `no_snap` is an answer ("this path never snaps"), every other code leaves G* in doubt
    bad = [f"{name}: {rec[f'result_{name}']}" for name in ("up", "down")
           if rec[f"result_{name}"] not in ("successful", "no_snap")]
    if bad:
        print(f"jaxrod termination-gap: {', '.join(bad)} (see jaxrod.RESULTS)", file=sys.stderr)
        return EXIT_NOT_CONVERGED
    return EXIT_OK
