"""Warm-started families: snap angles from a neighbour's critical point against cold calls.

Measured in one run, the same compiled programs throughout (`JAXROD_COMPILE=optimized`, the
steady state of the default compile mode), N = 100, float64:

- **gap sweeps**: the 16 x 8 grid of `bench_batch.py` (Psi0 15-180 deg x G/L 0.25-0.93), each
  Psi0 a chain along the gaps: a loop of cold `jr.snap_angles(scene)` beside a loop of
  `jr.snap_angles(scene, near=previous)` (the first gap of each chain cold);
- **optimizer steps**: 24 designs 0.5 deg of Psi0 apart at G/L = 0.5 (what an optimizer's
  successive iterates look like), cold beside warm;
- **a phase-diagram row**: `jr.phase_diagram` scans its gaps with warm paths; its `_chunk`
  timed as one compiled call at Psi0 = 90 deg, 41 gaps.

Every warm answer is compared with its cold call (alpha_c, kinds, codes). Results:
`benchmarks/results/warm.{json,md}`. `--quick`: N = 24, a 4 x 4 grid.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("JAXROD_COMPILE", "optimized")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from tqdm import tqdm  # noqa: E402

import jaxrod as jr  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_batch import GAP_BOX, PSI_BOX, machine_meta  # noqa: E402

HERE = Path(__file__).resolve().parent


def _paths(r):
    return (r.up, r.down)


def _compare(cold, warm):
    """max |d alpha_c| (deg) over snapping paths, whether every code and kind is equal, warm paths."""
    d, equal, n_warm = 0.0, True, 0
    for c, w in zip(cold, warm):
        for pc, pw in zip(_paths(c), _paths(w)):
            equal &= (pc.result == pw.result) and int(pc.kind) == int(pw.kind) and bool(pc.snaps) == bool(pw.snaps)
            if bool(pc.snaps) and bool(pw.snaps):
                d = max(d, abs(float(np.degrees(pc.alpha_c - pw.alpha_c))))
            n_warm += int(pw.warm)
    return d, bool(equal), n_warm


def _chains(chains, cold_fn, warm_fn, repeats):
    """Each chain a list of scenes: cold calls for all, warm calls from the previous answer."""
    def run_cold():
        return [[jax.block_until_ready(cold_fn(s)) for s in ch] for ch in chains]

    def run_warm():
        out = []
        for ch in chains:
            prev = jax.block_until_ready(cold_fn(ch[0]))
            row = [prev]
            for s in ch[1:]:
                prev = jax.block_until_ready(warm_fn(s, prev))
                row.append(prev)
            out.append(row)
        return out

    t_cold, t_warm = [], []
    for _ in range(repeats):
        t = time.perf_counter(); cold = run_cold(); t_cold.append(time.perf_counter() - t)  # noqa: E702
        t = time.perf_counter(); warm = run_warm(); t_warm.append(time.perf_counter() - t)  # noqa: E702
    flat = lambda xs: [x for row in xs for x in row]  # noqa: E731
    d, equal, n_warm = _compare(flat(cold), flat(warm))
    members = sum(len(ch) for ch in chains)
    tc, tw = float(np.median(t_cold)), float(np.median(t_warm))
    return dict(members=members, paths=2 * members, warm_paths=n_warm, cold_per_member_ms=1e3 * tc / members,
                warm_per_member_ms=1e3 * tw / members, speedup=tc / tw, max_dalpha_deg=d, codes_equal=equal,
                cold_runs_s=t_cold, warm_runs_s=t_warm)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="N = 24, a 4 x 4 grid, 6 optimizer steps")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default=str(HERE / "results"))
    args = ap.parse_args(argv)
    n = 24 if args.quick else 100
    shape = (4, 4) if args.quick else (16, 8)
    steps = 6 if args.quick else 24
    meta = machine_meta(script="benchmarks/bench_warm.py", argv=" ".join(argv or sys.argv[1:]), n=n)

    cold_fn = jax.jit(lambda s: jr.snap_angles(s))
    warm_fn = jax.jit(lambda s, near: jr.snap_angles(s, near=near))
    s0 = jr.make_scene(90.0, 0.5, n=n)
    t = time.perf_counter(); r0 = jax.block_until_ready(cold_fn(s0)); c_cold = time.perf_counter() - t  # noqa: E702
    t = time.perf_counter(); jax.block_until_ready(warm_fn(jr.make_scene(90.0, 0.51, n=n), r0))  # noqa: E702
    c_warm = time.perf_counter() - t
    rows = {"compile": dict(cold_first_call_s=c_cold, warm_first_call_s=c_warm)}

    psis = np.linspace(*PSI_BOX, shape[0])
    gaps = np.linspace(*GAP_BOX, shape[1])
    chains = [[jr.make_scene(float(p), float(g), n=n) for g in gaps] for p in psis]
    rows["gap_sweeps"] = _chains(tqdm(chains, desc="gap sweeps", file=sys.stderr), cold_fn, warm_fn, args.repeats)

    design = [[jr.make_scene(60.0 + 0.5 * k, 0.5, n=n) for k in range(steps)]]
    rows["optimizer_steps"] = _chains(design, cold_fn, warm_fn, args.repeats)

    # an inverse design: `jaxrod.design.optimize` (Levenberg-Marquardt, the CPU default of one start
    # after the other), each start's iterations warm-started from its previous iterate, against the
    # same run with every path walked (`_first_near` -> None)
    import jaxrod.design as ds
    import jaxrod.design._optimize as opt

    terms = (ds.AlphaUp(target=70.0, tol=0.05), ds.AlphaDown(target=-84.0, tol=0.05))
    param = ds.Parametrization()
    z0 = jnp.asarray(np.random.default_rng(0).normal(size=(2 if args.quick else 8, 2)))
    dn = 24 if args.quick else 40

    def design_runs():
        ds.optimize(terms, param, z0, n=dn, progress=False)
        runs, res = [], None
        for _ in range(args.repeats):
            t = time.perf_counter(); res = ds.optimize(terms, param, z0, n=dn, progress=False)  # noqa: E702
            runs.append(time.perf_counter() - t)
        return float(np.median(runs)), res

    tw, rw = design_runs()
    first = opt._first_near
    opt._first_near = lambda problem, b: None
    try:
        tc, rc = design_runs()
    finally:
        opt._first_near = first
    rows["design"] = dict(starts=int(z0.shape[0]), n=dn, warm_s=tw, cold_s=tc, speedup=tc / tw,
                          max_dvalue=float(np.nanmax(np.abs(np.asarray(rw.values) - np.asarray(rc.values)))),
                          status_equal=bool(np.array_equal(np.asarray(rw.status), np.asarray(rc.status))),
                          reached=int(rw.num_reached))

    from jaxrod.branches._phase import _chunk

    pgaps = jnp.asarray(np.linspace(*GAP_BOX, 41))
    chunk = jax.jit(lambda p, g: _chunk(p, g, 0.02, s0.mesh))
    p90 = jnp.asarray(np.radians(90.0))
    t = time.perf_counter(); out = jax.block_until_ready(chunk(p90, pgaps)); c_chunk = time.perf_counter() - t  # noqa: E702
    runs = []
    for _ in range(args.repeats):
        t = time.perf_counter(); jax.block_until_ready(chunk(p90, pgaps)); runs.append(time.perf_counter() - t)  # noqa: E702
    rows["phase_row"] = dict(gaps=41, first_call_s=c_chunk, call_s=float(np.median(runs)), runs_s=runs,
                             per_gap_ms=1e3 * float(np.median(runs)) / 41,
                             warm_paths=int(np.asarray(out["warm_paths"]).sum()), paths=82)

    meta["load_average_end"] = os.getloadavg()
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    name = "warm_quick" if args.quick else "warm"
    (out_dir / f"{name}.json").write_text(json.dumps(dict(meta=meta, **rows), indent=2, default=float) + "\n")
    g, o, ph, c = rows["gap_sweeps"], rows["optimizer_steps"], rows["phase_row"], rows["compile"]
    lines = [
        f"# Warm-started snap angles ({meta['platform']}: {meta['processor'] or meta['platform']})", "",
        f"Generated by `python benchmarks/bench_warm.py{' ' + meta['argv'] if meta['argv'] else ''}` on "
        f"{meta['date']}; {meta['machine']}, {meta['cpu_count']} CPUs, jax {meta['jax']}, jaxrod {meta['jaxrod']}, "
        f"git {meta['git']}. N = {n}, float64, JAXROD_COMPILE={meta['jaxrod_compile']}, load average "
        f"{meta['load_average_start'][0]:.2f} at the start, {meta['load_average_end'][0]:.2f} at the end.", "",
        "| family | members | warm paths | cold per member (ms) | warm per member (ms) | speed-up | "
        "max \\|d alpha_c\\| (deg) | codes equal |",
        "|---|---:|---:|---:|---:|---:|---:|---|",
    ]
    for label, r in ((f"gap sweeps: {shape[0]} Psi0 x {shape[1]} G/L, chains along G/L", g),
                     (f"optimizer steps: Psi0 60-{60 + 0.5 * (steps - 1):g} deg by 0.5, G/L = 0.5", o)):
        lines.append(f"| {label} | {r['members']} | {r['warm_paths']} of {r['paths']} | {r['cold_per_member_ms']:.1f} "
                     f"| {r['warm_per_member_ms']:.1f} | {r['speedup']:.2f}x | {r['max_dalpha_deg']:.1e} | "
                     f"{'yes' if r['codes_equal'] else '**no**'} |")
    de = rows["design"]
    lines.append(f"| `jaxrod.design.optimize`: AlphaUp 70 and AlphaDown -84 deg over (Psi0, G/L), {de['starts']} starts, "
                 f"N = {de['n']}, whole runs | {de['starts']} | – | {1e3 * de['cold_s']:.0f} (run) | "
                 f"{1e3 * de['warm_s']:.0f} (run) | {de['speedup']:.2f}x | max \\|d value\\| {de['max_dvalue']:.1e} | "
                 f"{'yes' if de['status_equal'] else '**no**'} ({de['reached']} reached) |")
    lines += [
        "",
        f"Phase-diagram row (`_chunk`, Psi0 = 90 deg, 41 gaps, one compiled call, warm paths): {ph['call_s']:.3f} s, "
        f"{ph['per_gap_ms']:.1f} ms a gap, {ph['warm_paths']} of {ph['paths']} paths warm; first call (trace, "
        f"compile, run) {ph['first_call_s']:.1f} s.",
        f"First calls (trace + compile + run): cold `snap_angles` {c['cold_first_call_s']:.1f} s; with `near` "
        f"{c['warm_first_call_s']:.1f} s (a program of its own).",
        "",
        "Cold per member: a loop of `jr.snap_angles(scene)`; warm: the same scenes in chain order, each "
        "`jr.snap_angles(scene, near=previous answer)`, the first of each chain cold (counted in the warm time). "
        "Warm paths: paths whose critical point came from the neighbour's (the rest walked their branch: the "
        "first of a chain, paths that do not snap or pass through themselves, changes of kind). Codes equal: "
        "`result`, `kind` and `snaps` of both paths identical to the cold call's.",
    ]
    (out_dir / f"{name}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
