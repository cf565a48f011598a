"""Design subcommands: `jaxrod design` (inverse design of snap angles or of the snapping
speed, `--target-speed`) and
`jaxrod reproduce` (the paper's numbers beside jaxrod's, Markdown report + figures:
`jaxrod.paper.reproduce`).

Each module in `jaxrod.cli._main._COMMAND_MODULES` defines `register(sub)`, which adds its
subparsers to the `jaxrod` parser and attaches `handler=<function(args) -> exit code>`
with `set_defaults`. Shared pieces: `jaxrod.cli._main.add_scene_args`, `make_scene_from_args`,
`InputError` (one-line error, exit 2), `EXIT_OK`, `EXIT_USAGE`, `EXIT_NOT_CONVERGED`.

`design` exit codes: 0 target reached, 3 not reached (the JSON, with `reached: false` and
the best design found, is still printed), 2 bad input. `--target-speed` runs study (c) and
`--study two-creases` and `--study crease-position` the crease design studies, all of
`jaxrod.paper`.
"""

from __future__ import annotations

import json
import math
import os

from ..results import result_name
from ._main import EXIT_NOT_CONVERGED, EXIT_OK, InputError, writing


def _save(design, path, rec):
    """`--save PATH`: write PATH.eqx and PATH.json, record them in `rec` (InputError if not writable)."""
    if not path:
        return
    with writing("save", path):
        design.save(path)
    rec["saved"] = [path + ".eqx", path + ".json"]


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


def _optimizer(args):
    """`--optimizer lm|adam[:LR]` -> "lm" or an `optax.adam` transformation (InputError otherwise)."""
    text = args.optimizer.strip().lower()
    if text == "lm":
        return "lm"
    name, _, lr = text.partition(":")
    if name != "adam":
        raise InputError(f"optimizer: expected lm or adam[:LR], got {args.optimizer!r}")
    try:
        rate = float(lr) if lr else 0.05
    except ValueError:
        raise InputError(f"optimizer: the learning rate in {args.optimizer!r} is not a number") from None
    if not (math.isfinite(rate) and rate > 0):
        raise InputError(f"optimizer: the learning rate must be a finite number > 0, got {rate:g}")
    import optax

    return optax.adam(rate)


def _finite_or_none(x):
    x = float(x)
    return x if math.isfinite(x) else None


def _meshes(args):
    """The design mesh `--n` (default 48) and the check's `--check-n` (default 2n), checked."""
    n = 48 if args.n is None else args.n
    if n < 8 or n % 2:
        raise InputError(f"n: must be an even integer >= 8, got {n}")
    n_check = 2 * n if args.check_n is None else args.check_n
    if n_check < 8 or n_check % 2 or n_check <= n:
        raise InputError(f"check-n: must be an even integer > n = {n}, got {n_check}")
    return n, n_check


def _speed_psi0_and_tol(args, default_psi0):
    """`--psi0` (default `default_psi0`) and `--speed-tol` of a snap-speed design, checked."""
    psi0 = default_psi0 if args.psi0 is None else args.psi0
    if not math.isfinite(psi0) or not 0 < psi0 <= 180:
        raise InputError(f"psi0: must be in (0, 180] degrees, got {psi0}")
    tol = args.speed_tol
    if not math.isfinite(tol) or not 0 < tol < 1:
        raise InputError(f"speed-tol: must be a relative tolerance in (0, 1), got {tol}")
    return psi0, tol


def _cmd_design_speed(args, optimizer):
    """`--target-speed`: study (c), the gap (and s0 with --free-s0) with v_s = target at --psi0,
    by `optimizer` ("lm" or an optax transformation)."""
    angle_targets = (args.target_alpha_up, args.target_alpha_down, args.target_hysteresis)
    if any(t is not None for t in angle_targets):
        raise InputError("target-speed: cannot be combined with angle targets (--target-alpha-up/-down, "
                         "--target-hysteresis); design one or the other")
    v = args.target_speed
    if not math.isfinite(v) or v <= 0:
        raise InputError(f"target-speed: must be a finite number > 0 (v_s / v*), got {v}")
    if args.design_creases:
        return _cmd_design_crease_gap(args)
    psi0, tol = _speed_psi0_and_tol(args, 90.0)
    n, n_check = _meshes(args)
    starts = 1 if args.starts is None else args.starts
    if starts < 1:
        raise InputError(f"starts: must be >= 1, got {starts}")
    if args.max_iter < 1:
        raise InputError(f"max-iter: must be >= 1, got {args.max_iter}")
    if not math.isfinite(args.s0) or args.s0 <= 0:
        raise InputError(f"s0: must be a finite number > 0, got {args.s0}")
    import jaxrod.design as ds
    import jaxrod.paper as paper

    if not ds.dynamics_available():
        raise InputError("target-speed: the snapping-speed design needs jaxrod.snap_speed, which is not available")
    bounds = _bounds(args.bounds)
    lo, hi = bounds.get("gap", (0.05, 0.95))
    gaps = [0.5] if starts == 1 else [lo + (hi - lo) * (k + 1) / (starts + 1) for k in range(starts)]
    gaps = [min(max(g, lo + 1e-3), hi - 1e-3) for g in gaps]
    try:
        res = paper.snap_speed_study(v, psi0, s0=args.s0, free_s0=args.free_s0, bounds=bounds, gaps=gaps, n=n,
                                     n_check=n_check, tol=tol, max_iter=args.max_iter, progress=not args.json,
                                     optimizer=optimizer)
    except ValueError as e:
        raise InputError(str(e)) from None
    b, chk = res.design, res.verification
    rec = {"psi0_deg": b.psi0_deg, "gap": b.gap, "s0": b.s0, "snap_speed": _finite_or_none(res.v_s),
           "target_snap_speed": v, "tol": tol, "reached": res.reached, "design_reached": bool(b.reached),
           "status": b.status, "result": result_name(b.result) if res.reached else
           ("target_not_reached" if b.status != "infeasible_start" else "infeasible_start"),
           "num_iterations": int(b.num_iterations), "n": n, "optimizer": args.optimizer,
           "check": chk.to_dict(), "message": res.message, "num_starts": len(res.runs),
           "wall_time_s": res.wall_time}
    _save(b, args.save, rec)
    if args.json:
        print(json.dumps(rec))
    else:
        print(f"design: Psi0 = {b.psi0_deg:.4f} deg, G/L = {b.gap:.5f}, s0 = {b.s0:.5g}  (n = {n})")
        print(f"  snap_speed  {res.v_s:.4f} v*  (target {v:g} +- {100 * tol:g} %)")
        print(f"  check at N = {chk.n} ({chk.solver}, rtol {chk.rtol:g}): v_s = {chk.v_s:.4f} v*, "
              f"error {100 * chk.error:.3f} %")
        print(f"  {res.message}; {res.wall_time:.1f} s; result {rec['result']}")
    return EXIT_OK if rec["result"] == "successful" else EXIT_NOT_CONVERGED


def _cmd_design_crease_gap(args):
    """`--target-speed V --crease ...`: the gap at which the strip with those creases snaps up
    at V (`jaxrod.design.crease_gap_for_speed`), re-checked at --check-n."""
    if args.free_s0 or args.save:
        raise InputError("crease: --target-speed with --crease designs the gap only (no --free-s0 or --save)")
    if args.starts is not None and args.starts != 1:
        raise InputError(f"starts: --target-speed with --crease runs from one start, got {args.starts}")
    psi0, tol = _speed_psi0_and_tol(args, 180.0)
    n, n_check = _meshes(args)
    bounds = _bounds(args.bounds)
    if set(bounds) - {"gap"}:
        raise InputError("bounds: --target-speed with --crease designs the gap only (gap=LO:HI)")
    lo, hi = bounds.get("gap", (0.05, 0.95))
    gap = 0.5 if args.gap is None else args.gap
    import jaxrod.design as ds

    try:
        res = ds.crease_gap_for_speed(args.target_speed, args.design_creases, psi0_deg=psi0, s0=args.s0, gap=gap,
                                      bounds=(lo, hi), n=n, n_check=n_check, tol=tol, max_iter=args.max_iter)
    except ValueError as e:
        raise InputError(str(e)) from None
    rec = res.to_dict()
    rec["result"] = ("successful" if res.confirmed else "target_not_reached" if not res.reached
                     else res.check_result if res.check_result != "successful" else "check_failed")
    if args.json:
        print(json.dumps(rec))
    else:
        print(f"design: G/L = {res.gap:.5f} for the creases {rec['creases']} (n = {n})")
        print(f"  snap_speed {res.v_s:.4f} v* (target {res.target_speed:g} +- {100 * tol:g} %), "
              f"{len(res.history)} Newton evaluations")
        print(f"  check at N = {res.n_check}: v_s = {res.check_v_s:.4f} v* ({res.check_result}); "
              f"{res.seconds:.1f} s; result {rec['result']}")
    return EXIT_OK if rec["result"] == "successful" else EXIT_NOT_CONVERGED


def _check_crease_study(args):
    """The options of `--study two-creases|crease-position`: InputError naming the first
    one that does not fit."""
    if args.target_speed is not None or args.target_hysteresis is not None:
        raise InputError(f"study: {args.study} takes no --target-speed or --target-hysteresis")
    if args.free_s0 or args.bounds or args.save:
        raise InputError(f"study: {args.study} takes no --free-s0, --bounds or --save")
    two = args.study == "two-creases"
    if two:
        if args.target_alpha_up is None or args.target_alpha_down is None:
            raise InputError("study: two-creases needs --target-alpha-up and --target-alpha-down")
        if args.psi0 is not None:
            raise InputError("psi0: two-creases designs both fold angles; --psi0 is for crease-position")
    elif args.target_alpha_up is not None or args.target_alpha_down is not None:
        raise InputError("study: crease-position maximises the hysteresis width; it takes no angle targets")
    for name in ("target_alpha_up", "target_alpha_down", "psi0", "gap", "s0", "tol"):
        v = getattr(args, name)
        if v is not None and not math.isfinite(v):
            raise InputError(f"{name.replace('_', '-')}: must be a finite number, got {v}")
    if args.gap is not None and not 0.0 < args.gap < 1.0:
        raise InputError(f"gap: must lie in (0, 1), got {args.gap}")
    if args.psi0 is not None and not 0.0 < args.psi0 < 180.0:
        raise InputError(f"psi0: must lie in (0, 180) degrees for crease-position, got {args.psi0}")
    if args.s0 != 0.02:
        raise InputError("s0: the crease studies use creases of width 0.02 L")
    if args.tol is not None and args.tol <= 0:
        raise InputError(f"tol: must be > 0, got {args.tol}")
    n, n_check = _meshes(args)
    if args.starts is not None and args.starts != 1:
        raise InputError(f"starts: the crease studies run from one start, got {args.starts}")
    return n, n_check


def _cmd_design_creases(args):
    """`--study two-creases`: two creases with the target snap angles, then the fastest snap
    up among them (`jaxrod.paper.two_crease_study`); `--study crease-position`: the position of
    one crease of angle --psi0 with the widest hysteresis (`crease_position_study`). Both are
    re-checked at --check-n."""
    n, n_check = _check_crease_study(args)
    import jaxrod.paper as paper

    gap = 0.5 if args.gap is None else args.gap
    quiet = args.json
    try:
        if args.study == "two-creases":
            res = paper.two_crease_study(args.target_alpha_up, args.target_alpha_down, gap=gap, n=n,
                                         n_check=n_check, tol_deg=0.02 if args.tol is None else args.tol,
                                         progress=not quiet)
            ok = res.reached and res.check.result == "successful"
        else:
            res = paper.crease_position_study(120.0 if args.psi0 is None else args.psi0, gap, n=n,
                                              n_check=n_check, progress=not quiet)
            ok = res.check.result == "successful"
    except ValueError as e:
        raise InputError(str(e)) from None
    rec = res.to_dict()
    rec.update(study=args.study, result="successful" if ok else
               ("target_not_reached" if args.study == "two-creases" and not res.reached else res.check.result))
    if args.json:
        print(json.dumps(rec))
    elif args.study == "two-creases":
        print(f"design: creases at {', '.join(f'{c:.4f}' for c in res.positions)} L, fold angles "
              f"{', '.join(f'{a:.3f}' for a in res.angles_deg)} deg (G/L = {gap:g}, n = {n})")
        print(f"  alpha_c up {res.alpha_up_deg:+.4f}, down {res.alpha_down_deg:+.4f} deg "
              f"(targets {res.targets_deg[0]:+g}, {res.targets_deg[1]:+g} +- {res.tol_deg:g})")
        print(f"  v_s {res.v_s_start:.3f} -> {res.v_s:.3f} v*; snap clearance {res.snap_clearance:.4f} L")
        print(f"  check at N = {res.check.n}: {res.check.alpha_up_deg:+.4f} / {res.check.alpha_down_deg:+.4f} deg, "
              f"v_s {res.check.v_s:.3f} v*; {res.seconds:.1f} s; result {rec['result']}")
    else:
        print(f"design: widest hysteresis of one {res.psi0_deg:g} deg crease at G/L = {gap:g}: position "
              f"{res.position:.4f} L, W = {res.width_deg:.3f} deg ({res.where}; centre {res.centre_width_deg:.3f})")
        print(f"  best off-centre: {res.interior_position:.4f} L, W = {res.interior_width_deg:.3f} deg, "
              f"smooth maximum: {res.interior_smooth}")
        print(f"  check at N = {res.check.n}: W = {res.check.alpha_up_deg - res.check.alpha_down_deg:.3f} deg; "
              f"{res.seconds:.1f} s; result {rec['result']}")
    return EXIT_OK if ok else EXIT_NOT_CONVERGED


def _scatter(text):
    """`--scatter psi0=DEG[,gap=G][,s0=S][,misalignment=DEG][,uniform]` as a `jaxrod.design.Scatter` (InputError
    naming the option on a bad spec)."""
    import jaxrod.design as ds

    widths, distribution = {}, "normal"
    for part in (p.strip() for p in text.split(",") if p.strip()):
        if part in ("normal", "uniform"):
            distribution = part
            continue
        name, _, value = part.partition("=")
        if name not in ("psi0", "gap", "s0", "misalignment") or not value:
            raise InputError(f"scatter: expected psi0=DEG,gap=G,s0=S,misalignment=DEG[,uniform], got {text!r}")
        try:
            widths[{"psi0": "psi0_deg", "misalignment": "misalignment_deg"}.get(name, name)] = float(value)
        except ValueError:
            raise InputError(f"scatter: {name} must be a number, got {value!r}") from None
    if not widths:
        raise InputError(f"scatter: give at least one width (psi0=DEG, gap=G, s0=S or misalignment=DEG), "
                         f"got {text!r}")
    try:
        return ds.Scatter(**widths, distribution=distribution)
    except ValueError as e:
        raise InputError(f"scatter: {e}") from None


def _cmd_design_robust(args):
    """`--quantile Q --scatter SPEC`: `jaxrod.design.robust_design`, both snap angles at the
    quantile Q of the scatter, re-checked by an independent Monte Carlo."""
    if args.target_alpha_up is None or args.target_alpha_down is None:
        raise InputError("quantile: a robust design needs --target-alpha-up and --target-alpha-down")
    for flag, given in (("target-hysteresis", args.target_hysteresis is not None),
                        ("target-speed", args.target_speed is not None), ("study", args.study is not None),
                        ("crease", bool(args.design_creases)), ("free-s0", args.free_s0), ("bounds", bool(args.bounds)),
                        ("save", args.save is not None), ("optimizer", args.optimizer.strip().lower() != "lm"),
                        ("starts", args.starts is not None)):
        if given:
            raise InputError(f"{flag}: not used with --quantile (a robust design of the two snap angles)")
    if args.scatter is None:
        raise InputError("quantile: give the scatter, e.g. --scatter psi0=10")
    scatter = _scatter(args.scatter)
    import jaxrod as jr
    import jaxrod.design as ds

    start = (90.0 if args.psi0 is None else args.psi0, 0.5 if args.gap is None else args.gap)
    try:
        r = ds.robust_design(args.target_alpha_up, args.target_alpha_down, quantile=args.quantile, scatter=scatter,
                             start=start, s0=args.s0, samples=args.samples, seed=args.seed,
                             n=60 if args.n is None else args.n, max_steps=args.max_iter,
                             tol_deg=0.01 if args.tol is None else args.tol, check_n=args.check_n)
    except ValueError as e:
        raise InputError(str(e)) from None
    rec = dict(psi0_deg=r.psi0_deg, gap=r.gap, s0=r.s0, quantile=r.quantile, quantiles_deg=r.quantiles.tolist(),
               targets_deg=[float(r.targets[0]), -float(r.targets[1])], nominal_deg=[r.nominal[0], -r.nominal[1]],
               num_steps=r.num_steps, check_probability=r.check_probability.tolist(),
               check_sem=r.check_sem.tolist(), check_members=r.check_ok.tolist(), message=r.message,
               result=result_name(r.result))
    if args.json:
        print(json.dumps(rec))
    else:
        print(f"robust design: Psi0 = {r.psi0_deg:.4f} deg, G/L = {r.gap:.5f} ({r.num_steps} steps)")
        print(f"  {r.quantile:g} quantiles: up {r.quantiles[0]:.4f} deg, down {-r.quantiles[1]:.4f} deg; "
              f"nominal strip: up {r.nominal[0]:.4f}, down {-r.nominal[1]:.4f}")
        print(f"  independent check: P(up) = {r.check_probability[0]:.3f} +- {r.check_sem[0]:.3f}, "
              f"P(down) = {r.check_probability[1]:.3f} +- {r.check_sem[1]:.3f}; result {rec['result']}"
              + (f" ({r.message})" if r.message else ""))
    return EXIT_OK if r.result == jr.RESULTS.successful else EXIT_NOT_CONVERGED


def _cmd_design(args):
    if args.quantile is not None:
        return _cmd_design_robust(args)
    if args.scatter is not None:
        raise InputError("scatter: only used with --quantile (a robust design)")
    if args.samples != 64:
        raise InputError("samples: only used with --quantile (a robust design)")
    optimizer = _optimizer(args)
    if optimizer != "lm" and (args.study is not None or args.design_creases):
        raise InputError("optimizer: the crease designs (--study, --crease) run their own optimizers; "
                         "--optimizer is for the angle and snap-speed designs")
    if args.design_creases and (args.study is not None or args.target_speed is None):
        raise InputError("crease: only used with --target-speed (the gap of a strip with those creases)")
    if args.study is not None:
        return _cmd_design_creases(args)
    if args.gap is not None and not args.design_creases:
        raise InputError("gap: only used with --study or --crease (the angle design optimizes G/L; fix it with "
                         "--bounds)")
    if args.gap is not None and not (math.isfinite(args.gap) and 0.0 < args.gap < 1.0):
        raise InputError(f"gap: must lie in (0, 1), got {args.gap}")
    if args.tol is None:
        args.tol = 0.1
    if args.target_speed is not None:
        return _cmd_design_speed(args, optimizer)
    if args.psi0 is not None:
        raise InputError("psi0: only used with --target-speed (the angle design optimizes Psi0; "
                         "fix it with --bounds psi0=LO:HI)")
    if args.n is None:
        args.n = 100
    if args.starts is None:
        args.starts = 4
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

    import jaxrod.design as ds

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
    res = ds.optimize(terms, param, z0, n=args.n, max_iter=args.max_iter, progress=not args.json, optimizer=optimizer)
    b = res.best
    rec = b.to_dict()
    rec.update({"num_starts": res.num_starts, "num_reached": res.num_reached, "wall_time_s": res.wall_time,
                "optimizer": args.optimizer})
    _save(b, args.save, rec)
    if args.json:
        print(json.dumps(rec))
    else:
        print(f"design: Psi0 = {b.psi0_deg:.4f} deg, G/L = {b.gap:.5f}, s0 = {b.s0:.5g}  (n = {b.n})")
        for nm, a, t in zip(b.names, b.achieved.tolist(), b.targets.tolist()):
            print(f"  {nm:<18} {a:+.4f} deg  (target {t:+g} +- {args.tol:g})")
        print(f"  {b.message}; {res.num_reached}/{res.num_starts} starts reached the target "
              f"in {res.wall_time:.1f} s; result {rec['result']}")
    return EXIT_OK if rec["result"] == "successful" else EXIT_NOT_CONVERGED


def _cmd_reproduce(args):
    from ..paper import reproduce

    try:
        os.makedirs(args.out, exist_ok=True)
    except OSError as e:
        raise InputError(f"out: cannot create directory {args.out!r}: {e.strerror or e}") from None
    path = reproduce.run(args.out, quick=args.quick, progress=True)
    print(f"wrote {path}")
    return EXIT_OK


def register(sub):
    """Add `design` and `reproduce` to the `jaxrod` argument parser."""
    import argparse

    from ._main import _EPILOG, _crease, _number

    p = sub.add_parser("design", help="find (Psi0, G/L) with given snap angles, or the gap with a snap speed",
                       description="Inverse design: multi-start Levenberg-Marquardt on (Psi0, G/L) [and s0]\n"
                                   "with implicit derivatives of the critical clamp angles; prints the design,\n"
                                   "the achieved values (on the design mesh --n) and whether the targets were\n"
                                   "reached (exit 3 if not).\n\n"
                                   "With --target-speed V: the gap G/L [and s0] at fold angle --psi0 whose\n"
                                   "quasi-static snap up has v_s = V v* (jaxrod.snap_speed: fixed-step brink\n"
                                   "dynamics, differentiable), within --speed-tol, then an independent check by\n"
                                   "jaxrod.snap_dynamics (adaptive Dopri8, rtol 1e-9) on --check-n segments;\n"
                                   "reached only if both agree.",
                       epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--target-alpha-up", type=_number, default=None, metavar="DEG", help="alpha_c_up target")
    p.add_argument("--target-alpha-down", type=_number, default=None, metavar="DEG", help="alpha_c_down target")
    p.add_argument("--target-hysteresis", type=_number, default=None, metavar="DEG",
                   help="alpha_c_up - alpha_c_down target")
    p.add_argument("--target-speed", type=_number, default=None, metavar="V",
                   help="snapping speed v_s / v* of the snap up (designs the gap at --psi0)")
    p.add_argument("--psi0", type=_number, default=None, metavar="DEG",
                   help="fold angle for --target-speed (default 90, or 180 with --crease: the centred crease) "
                        "and --study crease-position (default 120)")
    p.add_argument("--crease", dest="design_creases", type=_crease, action="append", default=None,
                   metavar="C:PSI0[:S0]",
                   help="with --target-speed: a crease at C (in L) of fold angle PSI0 (deg), repeatable; the gap "
                        "of that strip is designed (jaxrod.design.crease_gap_for_speed)")
    p.add_argument("--study", choices=("two-creases", "crease-position"), default=None,
                   help="two-creases: place and fold two creases for --target-alpha-up/-down, then maximise "
                        "the snap-up speed; crease-position: the position of one --psi0 crease with the "
                        "widest hysteresis (default mesh --n 48, checked at --check-n)")
    p.add_argument("--gap", type=_number, default=None, metavar="G",
                   help="G/L of the --study designs (default 0.5)")
    p.add_argument("--speed-tol", type=_number, default=0.01, metavar="FRAC",
                   help="relative tolerance of --target-speed (default %(default)g)")
    p.add_argument("--check-n", type=int, default=None, metavar="N",
                   help="mesh of the independent check of --target-speed (default 2 x --n)")
    p.add_argument("--tol", type=_number, default=None, metavar="DEG",
                   help="angle tolerance, deg (default 0.1; 0.02 with --study two-creases)")
    p.add_argument("--bounds", default="", metavar="SPEC",
                   help="e.g. psi0=30:120,gap=0.3:0.95 (defaults psi0 10:180, gap 0.05:0.95, s0 0.005:0.1)")
    p.add_argument("--s0", type=_number, default=0.02, help="fold width (fixed unless --free-s0)")
    p.add_argument("--free-s0", action="store_true", help="also optimize s0")
    p.add_argument("--n", type=int, default=None,
                   help="design mesh, segments (default 100; 48 with --target-speed)")
    p.add_argument("--starts", type=int, default=None,
                   help="number of starts (default 4; 1 with --target-speed, gap 0.5)")
    p.add_argument("--max-iter", type=int, default=30, help="iterations per start (default %(default)d)")
    p.add_argument("--optimizer", default="lm", metavar="lm|adam[:LR]",
                   help="Levenberg-Marquardt (default) or Adam (optax) with learning rate LR (default 0.05) in "
                        "the optimizer's unconstrained coordinates; Adam needs 5-40x LM's iterations on these "
                        "least-squares targets, so raise --max-iter with it, e.g. 200 "
                        "(benchmarks/results/optimizers.md)")
    p.add_argument("--seed", type=int, default=0, help="random starts seed")
    p.add_argument("--save", metavar="PATH", default=None, help="write PATH.eqx and PATH.json")
    p.add_argument("--quantile", type=_number, default=None, metavar="Q",
                   help="robust design: both snap angles at this quantile of --scatter (needs both angle targets; "
                        "--psi0/--gap give the start, default 90 deg, 0.5)")
    p.add_argument("--scatter", default=None, metavar="SPEC",
                   help="the scatter of a robust design: psi0=DEG[,gap=G][,s0=S][,misalignment=DEG][,uniform] (standard deviations, or "
                        "half-widths with uniform)")
    p.add_argument("--samples", type=int, default=64, metavar="M",
                   help="members of the scatter in a robust design (default %(default)d)")
    p.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    p.set_defaults(handler=_cmd_design)

    r = sub.add_parser("reproduce", help="the paper's numbers beside jaxrod's (Markdown report + figures)",
                       description="Compute the paper's results with the default strip and write\n"
                                   "DIR/report.md, DIR/results.json and figures. Sections that need the\n"
                                   "dynamics are marked 'not available yet' until that API exists.\n"
                                   "An interrupted run resumes from DIR/cache.json.",
                       epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    r.add_argument("--out", metavar="DIR", default="jaxrod-reproduce", help="output directory")
    r.add_argument("--quick", action="store_true", help="coarser mesh and sweep (about 1 min on 2 cores; the default about 2 min)")
    r.set_defaults(handler=_cmd_reproduce)
