#!/usr/bin/env python
"""Compile time of two versions of jaxrod side by side, interleaved, on one machine.

    python benchmarks/bench_compile_ab.py --base <git revision> [--reps 2] [--only snap_angles,phase_diagram]

On a machine whose speed drifts with other tenants' load (the 2-core CI machine: the same
program's compile time moves by up to 1.6x within an hour), two tables measured at different
times do not compare. This benchmark checks the base revision out into a temporary git
worktree and runs `bench_compile.py`'s child process (a fresh process, no persistent cache:
first call = trace + compile + run, second call = run) for each entry point alternately with
the base's source and the working tree's, `--reps` times, so both see the same machine.
Reports the median of the repetitions per entry point and version and their ratio.

Results: benchmarks/results/compile_ab.json and compile_ab.md.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
DEFAULT = "initial_state,snap_angles,snap_angles_extrapolated,phase_diagram,snap_dynamics,snap_speed"


def _git(*args, cwd=ROOT):
    return subprocess.run(["git", *args], cwd=cwd, check=True, capture_output=True, text=True).stdout.strip()


def _child(tree: Path, name: str, timeout: float) -> dict:
    env = dict(os.environ, JAXROD_NO_CACHE="1", OPENBLAS_NUM_THREADS="1", PYTHONPATH=str(tree))
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    cmd = [sys.executable, str(tree / "benchmarks" / "bench_compile.py"), "--child", name]
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=tree, env=env)
    except subprocess.TimeoutExpired:
        return dict(skipped=f"not finished within {timeout:.0f} s")
    lines = [ln for ln in p.stdout.splitlines() if ln.startswith("RESULT ")]
    if p.returncode or not lines:
        return dict(skipped=f"exit {p.returncode}: {p.stderr.strip()[-300:]}")
    return json.loads(lines[-1][len("RESULT "):])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", required=True, help="git revision to compare the working tree with")
    ap.add_argument("--reps", type=int, default=2)
    ap.add_argument("--only", default=DEFAULT, help="comma-separated entry points of bench_compile.py")
    ap.add_argument("--timeout", type=float, default=300.0)
    ap.add_argument("--out", default=str(HERE / "results"))
    args = ap.parse_args(argv)
    if args.reps < 1:
        print("--reps must be at least 1", file=sys.stderr)
        return 2
    names = [n for n in args.only.split(",") if n]
    base_rev = _git("rev-parse", "--short=10", args.base)
    head_rev = _git("rev-parse", "--short=10", "HEAD")
    dirty = bool(_git("status", "--porcelain", "--untracked-files=no", "--", "jaxrod", "design"))
    runs = {name: {"base": [], "new": []} for name in names}
    with tempfile.TemporaryDirectory(prefix="jaxrod-ab-") as tmp:
        base = Path(tmp) / "base"
        _git("worktree", "add", "--detach", str(base), base_rev)
        try:
            for rep in range(args.reps):
                for name in names:
                    for label, tree in (("base", base), ("new", ROOT)):
                        r = _child(tree, name, args.timeout)
                        runs[name][label].append(r)
                        print(f"rep {rep + 1} {name} {label}: "
                              + (r["skipped"] if "skipped" in r else
                                 f"trace + compile {r['trace_compile_s']:.2f} s, run {r['second_call_s']:.4f} s"),
                              flush=True)
        finally:
            _git("worktree", "remove", "--force", str(base))

    def med(rs, key):
        xs = [r[key] for r in rs if key in r]
        return statistics.median(xs) if xs else None

    rows = []
    for name in names:
        b, n = runs[name]["base"], runs[name]["new"]
        row = dict(name=name, base_trace_compile_s=med(b, "trace_compile_s"), new_trace_compile_s=med(n, "trace_compile_s"),
                   base_run_s=med(b, "second_call_s"), new_run_s=med(n, "second_call_s"),
                   base_xla_compile_s=med(b, "xla_compile_s"), new_xla_compile_s=med(n, "xla_compile_s"),
                   base_programs=med(b, "programs_compiled"), new_programs=med(n, "programs_compiled"),
                   base_all=[r.get("trace_compile_s") for r in b], new_all=[r.get("trace_compile_s") for r in n])
        rows.append(row)
    meta = dict(date=datetime.datetime.now(datetime.timezone.utc).isoformat(), machine=platform.platform(),
                cpu_count=os.cpu_count(), python=platform.python_version(), base=base_rev,
                new=head_rev + (" + uncommitted changes" if dirty else ""), reps=args.reps,
                load_average_end=os.getloadavg())
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "compile_ab.json").write_text(json.dumps(dict(meta=meta, rows=rows, runs=runs), indent=1))

    def f(x, d=2):
        return "-" if x is None else f"{x:.{d}f}"

    lines = [f"# Compile time, two versions side by side ({meta['machine']}, {meta['cpu_count']} CPUs)", "",
             f"Generated by `python benchmarks/bench_compile_ab.py --base {args.base}` on {meta['date']}: base "
             f"{base_rev}, new {meta['new']}; each entry point in a fresh process without a persistent cache "
             f"(`bench_compile.py --child`), base and new alternately, {args.reps} repetitions, medians. "
             "Scene `jr.make_scene(60, 0.5, n=100)`; trace + compile = first call - second call.", "",
             "| entry point | trace + compile base (s) | new (s) | new / base | XLA compile base (s) | new (s) "
             "| run base (s) | run new (s) | programs base / new |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        ratio = (r["new_trace_compile_s"] / r["base_trace_compile_s"]
                 if r["new_trace_compile_s"] and r["base_trace_compile_s"] else None)
        lines.append(f"| `{r['name']}` | {f(r['base_trace_compile_s'])} | {f(r['new_trace_compile_s'])} | {f(ratio)} "
                     f"| {f(r['base_xla_compile_s'])} | {f(r['new_xla_compile_s'])} | {f(r['base_run_s'], 3)} "
                     f"| {f(r['new_run_s'], 3)} | {f(r['base_programs'], 0)} / {f(r['new_programs'], 0)} |")
    (out / "compile_ab.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
