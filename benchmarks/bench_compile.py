#!/usr/bin/env python
"""Compile and latency budget of jaxrod's public entry points and of `jaxrod snap-angles`.

First-call (trace + compile + run) and second-call times of every public entry point, and
the wall time of the `jaxrod snap-angles` command, cold and warm.

    python benchmarks/bench_compile.py                   # everything (~10-15 min on 2 cores)
    python benchmarks/bench_compile.py --skip termination_gap,cli
    python benchmarks/bench_compile.py --only snap_angles --out /tmp/x

What is measured (scene: `jr.make_scene(60, 0.5, n=100)`, i.e. Psi0 = 60 deg, G/L = 0.5,
s0 = 0.02 L, N = 100, float64):

* Each entry point runs in its own fresh Python process, so each starts cold: no persistent
  compilation cache (JAXROD_NO_CACHE=1, JAX_COMPILATION_CACHE_DIR unset) and no in-memory
  trace or executable caches. Inputs the call needs (the scene; the equilibrium that
  `stability` takes, from `jr.initial_state`) are built before the clock starts. The process
  calls the entry point twice with the same arguments and blocks on the result:
  *first call* = trace + lower + XLA compile + run, *second call* = run (plus Python
  dispatch), *trace + compile* = first - second. This is the latency a user sees at the
  first call of a session; the budget targets apply to it.
* With `jax_log_compiles` on, JAX logs one "Finished XLA compilation of F in T sec" record
  per XLA program it compiles (jax/_src/interpreters/pxla.py), besides "Finished tracing"
  and "Finished jaxpr to MLIR module conversion" records. A handler on the `jax` logger
  collects them: *programs compiled* is the number of XLA-compilation records during the
  first call (eager operations count: each is a small program of its own); the record
  durations give XLA's compile time (summed), the lowering time (summed) and the tracing
  time (union of the intervals, since nested jits are traced inside their caller).
* For the entry points that are themselves jitted (`jaxrod._compile.jit`, an `equinox.filter_jit` with XLA options: `initial_state`,
  `solve_equilibrium`, `stability`, `snap_angles`) and cheap (first call under `--aot-below`,
  default 15 s; `--aot-below 0` turns it off), a second fresh process times the ahead-of-time
  path: `f.lower(...)` (trace + lowering), `.compile()` (XLA), and a call of the compiled
  executable; its lower / compile split agrees with the log records' one.
* The CLI: the installed console script `jaxrod snap-angles --psi0 60 --gap 0.5 --json`
  (in jaxrod's default compile mode unless `--mode` sets another)
  run three times against one fresh persistent cache (XDG_CACHE_HOME pointed at an empty
  temporary directory, so the CLI's default ~/.cache/jaxrod/xla lands there): cold (empty
  cache: compiles and writes the cache), warm (reads it), and warm again. Wall time of the
  whole process, including interpreter start and the imports. JAX_LOG_COMPILES=1 plus a
  `sitecustomize` on PYTHONPATH that re-enables the compile records the CLI otherwise
  silences (it sets the `jax` logger to ERROR) count the programs: XLA compilations, of
  which persistent-cache hits (programs under the CLI's 0.5 s threshold are not cached and
  are compiled again in every run). The command's default is Richardson extrapolation
  (`--no-extrapolate` turns it off), i.e. `jr.snap_angles_extrapolated` (`snap_angles` at
  N = 100 and at N = 200) in one program, which the CLI exports on its first run
  (`jaxrod.cli._exported`, beside the XLA cache) and loads on later runs: a warm run traces
  no library code.

Targets (the compile budget): `snap_angles`, `phase_diagram`, `snap_dynamics` trace + compile
<= 5 s each; `jaxrod snap-angles` <= 3 s wall warm, <= 15 s cold.

`--mode` sets `JAXROD_COMPILE` in every process: "auto" (jaxrod's default: each program
compiled first with the fast code generation and again with XLA's optimizing one once its
calls have run long enough, `jaxrod._compile.compile_mode`; the second call of this benchmark
stays below that point, so both calls time the fast variant), "fast" (XLA's -O0 and older loop
emitters, `jaxrod._compile.FAST_COMPILE_OPTIONS`, writes compile_fast.json / .md) or
"optimized" (XLA's optimizing code generation from the first call, writes
compile_optimized.json / .md).

Results: benchmarks/results/compile.json and compile.md (the default mode). The numbers are wall times on the
machine recorded there; on a machine shared with other jobs they are upper bounds (the load
average at start and end is recorded).
"""

from __future__ import annotations

import argparse
import datetime
import json
import logging
import os
import platform
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
SCENE = dict(psi0_deg=60.0, gap=0.5, n=100, s0=0.02)
PHASE_GAPS = [0.3, 0.4, 0.5, 0.6, 0.7]
CLI_ARGS = ["snap-angles", "--psi0", "60", "--gap", "0.5", "--json"]

# name -> (what is called, jitted itself)
ENTRIES = {
    "initial_state": ('jr.initial_state(scene, "down")', True),
    "solve_equilibrium": ("jr.solve_equilibrium(scene, theta0), theta0 = jr.buckled_guess(scene, up=False)", True),
    "stability": ('jr.stability(eq), eq = jr.initial_state(scene, "down")', True),
    "snap_angles": ("jr.snap_angles(scene)", True),
    "snap_angles_unpolished": ("jr.snap_angles(scene, polish=False) (no polish: no extended-system residual check or derivative)", False),
    "snap_angles_extrapolated": ("jr.snap_angles_extrapolated(scene) (N = 100 and 200)", False),
    "hysteresis": ("jr.hysteresis(scene)", False),
    "phase_diagram": (f"jr.phase_diagram([60], {PHASE_GAPS}, n=100, progress=False)", False),
    "snap_dynamics": ('jr.snap_dynamics(scene, "up") (brink, defaults)', False),
    "snap_speed": ('jr.snap_speed(scene, "up")', False),
    "termination_gap": ("jr.termination_gap(60, n=100) (tol 1e-5, default grid)", False),
}
TARGETS = {  # row -> (quantity, limit in s)
    "snap_angles": ("trace_compile_s", 5.0),
    "phase_diagram": ("trace_compile_s", 5.0),
    "snap_dynamics": ("trace_compile_s", 5.0),
    "cli_cold": ("wall_s", 15.0),
    "cli_warm": ("wall_s", 3.0),
}
_ELAPSED = re.compile(r" in ([0-9.eE+-]+) sec")
_SITECUSTOMIZE = '''\
import logging, sys
_h = logging.StreamHandler(sys.stderr)
_h.setFormatter(logging.Formatter("JAXLOG %(created).6f %(message)s"))
for _n in ("jax._src.dispatch", "jax._src.interpreters.pxla", "jax._src.compiler", "jax._src.pjit"):
    _l = logging.getLogger(_n)
    _l.setLevel(logging.WARNING)
    _l.addHandler(_h)
    _l.propagate = False
'''


# ----------------------------------------------------------------------------- child side


class _Records(logging.Handler):
    """Collects JAX's compile-log records as (kind, function, start, end)."""

    KINDS = (("Finished XLA compilation", "compile"), ("Finished jaxpr to MLIR", "lower"),
             ("Finished tracing", "trace"), ("Persistent compilation cache hit", "cache_hit"))

    def __init__(self):
        super().__init__(logging.DEBUG)
        self.items = []

    def emit(self, record):
        item = self.parse(record.getMessage(), record.created)
        if item:
            self.items.append(item)

    @classmethod
    def parse(cls, msg, created):
        for prefix, kind in cls.KINDS:
            if msg.startswith(prefix):
                m = _ELAPSED.search(msg)
                dt = float(m.group(1)) if m else 0.0
                fun = msg[len(prefix):].split(" in ")[0].replace(" of ", "").replace(" module conversion ", "")
                fun = fun.replace(" for jit", "").strip()
                return kind, fun, created - dt, created
        return None


def _union(intervals):
    total, end = 0.0, -float("inf")
    for a, b in sorted(intervals):
        if b > end:
            total += b - max(a, end)
            end = b
    return total


def _summary(items):
    comp = [(f, b - a) for k, f, a, b in items if k == "compile"]
    top = sorted(comp, key=lambda x: -x[1])[:5]
    return dict(programs_compiled=len(comp),
                cache_hits=sum(k == "cache_hit" for k, *_ in items),
                xla_compile_s=sum(d for _, d in comp),
                lowering_s=sum(b - a for k, _, a, b in items if k == "lower"),
                tracing_s=_union([(a, b) for k, _, a, b in items if k == "trace"]),
                jax_overhead_s=_union([(a, b) for k, _, a, b in items if k in ("trace", "lower", "compile")]),
                top_programs=[dict(name=f, compile_s=d) for f, d in top])


def _setup(jr, name):
    """(call, jitted function and its args for the AOT path or None): inputs built here."""
    scene = jr.make_scene(SCENE["psi0_deg"], SCENE["gap"], n=SCENE["n"], s0=SCENE["s0"])
    if name == "initial_state":
        return (lambda: jr.initial_state(scene, "down")), (jr.initial_state, (scene, "down"))
    if name == "solve_equilibrium":
        theta0 = jr.buckled_guess(scene, up=False)
        return (lambda: jr.solve_equilibrium(scene, theta0)), (jr.solve_equilibrium, (scene, theta0))
    if name == "stability":
        eq = jr.initial_state(scene, "down")
        return (lambda: jr.stability(eq)), (jr.stability, (eq,))
    if name == "snap_angles":
        return (lambda: jr.snap_angles(scene)), (jr.snap_angles, (scene,))
    if name == "snap_angles_unpolished":
        return (lambda: jr.snap_angles(scene, polish=False)), None
    if name == "snap_angles_extrapolated":
        return (lambda: jr.snap_angles_extrapolated(scene)), None
    if name == "hysteresis":
        return (lambda: jr.hysteresis(scene)), None
    if name == "phase_diagram":
        return (lambda: jr.phase_diagram([SCENE["psi0_deg"]], PHASE_GAPS, s0=SCENE["s0"], n=SCENE["n"],
                                         progress=False)), None
    if name == "snap_dynamics":
        return (lambda: jr.snap_dynamics(scene, "up")), None
    if name == "snap_speed":
        return (lambda: jr.snap_speed(scene, "up")), None
    if name == "termination_gap":
        return (lambda: jr.termination_gap(SCENE["psi0_deg"], s0=SCENE["s0"], n=SCENE["n"])), None
    raise ValueError(name)


def child(name, aot):
    t0 = time.perf_counter()
    import jax

    jax.config.update("jax_enable_x64", True)
    jax.config.update("jax_log_compiles", True)
    import jaxrod as jr

    import_s = time.perf_counter() - t0
    rec = _Records()
    logging.getLogger("jax").addHandler(rec)
    call, jitted = _setup(jr, name)
    jax.block_until_ready(jax.numpy.zeros(()))
    out = dict(name=name, import_s=import_s, setup_programs=_summary(rec.items)["programs_compiled"])
    rec.items.clear()
    if aot:
        f, args = jitted
        t0 = time.perf_counter()
        lowered = f.lower(*args)
        t1 = time.perf_counter()
        compiled = lowered.compile()
        t2 = time.perf_counter()
        jax.block_until_ready(compiled(*args))
        t3 = time.perf_counter()
        runs = []
        for _ in range(3):
            s = time.perf_counter()
            jax.block_until_ready(compiled(*args))
            runs.append(time.perf_counter() - s)
        # fused kernels of the optimized program: a count that does not drift with the machine's
        # speed (XLA's backend, most of the compile, emits one kernel per fusion)
        try:
            kernels = getattr(compiled, "compiled", compiled).as_text().count(" fusion(")
        except Exception:  # a backend without the optimized text
            kernels = None
        out.update(lower_s=t1 - t0, compile_s=t2 - t1, first_run_s=t3 - t2, run_s=statistics.median(runs),
                   fused_kernels=kernels,
                   **{f"aot_{k}": v for k, v in _summary(rec.items).items() if k != "top_programs"})
    else:
        t0 = time.perf_counter()
        jax.block_until_ready(call())
        first = time.perf_counter() - t0
        s1 = _summary(rec.items)
        rec.items.clear()
        t0 = time.perf_counter()
        jax.block_until_ready(call())
        second = time.perf_counter() - t0
        s2 = _summary(rec.items)
        out.update(first_call_s=first, second_call_s=second, trace_compile_s=first - second, **s1,
                   second_call_programs_compiled=s2["programs_compiled"],
                   second_call_programs=[f for k, f, *_ in rec.items if k == "compile"])
    print("RESULT " + json.dumps(out), flush=True)


# ---------------------------------------------------------------------------- parent side


def _git():
    """HEAD, and whether the library in the working tree differs from it."""
    try:
        head = subprocess.run(["git", "rev-parse", "--short=10", "HEAD"], capture_output=True, text=True,
                              cwd=HERE).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "jaxrod"], capture_output=True, text=True,
                               cwd=ROOT).stdout.strip()
    except OSError:
        return "unknown"
    return head + (" + uncommitted changes in jaxrod/" if dirty else "")


def _env(**extra):
    env = {k: v for k, v in os.environ.items() if k not in ("JAX_COMPILATION_CACHE_DIR", "JAXROD_NO_CACHE",
                                                            "JAX_LOG_COMPILES")}
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    env.update(extra)
    return env


def _run_child(name, aot, timeout):
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", name] + (["--aot"] if aot else [])
    t0 = time.perf_counter()
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=ROOT,
                           env=_env(JAXROD_NO_CACHE="1"))
    except subprocess.TimeoutExpired:
        return dict(name=name, skipped=f"not finished within the {timeout:.0f} s limit per process")
    wall = time.perf_counter() - t0
    lines = [ln for ln in p.stdout.splitlines() if ln.startswith("RESULT ")]
    if p.returncode or not lines:
        return dict(name=name, skipped=f"process failed (exit {p.returncode}): {p.stderr.strip()[-400:]}")
    res = json.loads(lines[-1][len("RESULT "):])
    res["process_wall_s"] = wall
    return res


def _cli(timeout):
    exe = Path(sys.executable).with_name("jaxrod")
    cmd = [str(exe)] + CLI_ARGS if exe.exists() else [sys.executable, "-m", "jaxrod"] + CLI_ARGS
    runs = []
    with tempfile.TemporaryDirectory(prefix="jaxrod-bench-compile-") as tmp:
        site = Path(tmp) / "site"
        site.mkdir()
        (site / "sitecustomize.py").write_text(_SITECUSTOMIZE)
        xdg = Path(tmp) / "cache"
        pp = os.pathsep.join([str(site)] + ([os.environ["PYTHONPATH"]] if os.environ.get("PYTHONPATH") else []))
        env = _env(XDG_CACHE_HOME=str(xdg), JAX_LOG_COMPILES="1", PYTHONPATH=pp)
        if env.get("JAXROD_COMPILE") == "auto":
            env.pop("JAXROD_COMPILE")  # the CLI as users run it: the default mode
        for label in ("cold", "warm", "warm_again"):
            t0 = time.perf_counter()
            try:
                p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env, cwd=tmp)
            except subprocess.TimeoutExpired:
                runs.append(dict(run=label, skipped=f"not finished within {timeout:.0f} s"))
                break
            wall = time.perf_counter() - t0
            items = []
            for ln in p.stderr.splitlines():
                if ln.startswith("JAXLOG "):
                    created, msg = ln[len("JAXLOG "):].split(" ", 1)
                    items.append(_Records.parse(msg, float(created)))
            summ = _summary([x for x in items if x])
            cache_files = sum(1 for f in (xdg / "jaxrod" / "xla").rglob("*") if f.is_file()) \
                if (xdg / "jaxrod" / "xla").exists() else 0
            try:
                ok = p.returncode == 0 and "alpha_c_up_deg" in json.loads(p.stdout)
            except ValueError:
                ok = False
            runs.append(dict(run=label, wall_s=wall, returncode=p.returncode, output_ok=ok,
                             xla_compilations=summ["programs_compiled"], cache_hits=summ["cache_hits"],
                             programs_compiled=summ["programs_compiled"] - summ["cache_hits"],
                             xla_compile_s=summ["xla_compile_s"], tracing_s=summ["tracing_s"],
                             lowering_s=summ["lowering_s"], top_programs=summ["top_programs"],
                             cache_files_after=cache_files))
    return dict(command="jaxrod " + " ".join(CLI_ARGS), runs=runs)


def _met(row, value):
    if row not in TARGETS or value is None:
        return None, None
    key, lim = TARGETS[row]
    return lim, bool(value <= lim)


def _again(r):
    names = r.get("second_call_programs") or []
    return str(r["second_call_programs_compiled"]) + (f" ({', '.join(f'`{n}`' for n in names)})" if names else "")


def _f(x, fmt=".2f"):
    return "-" if x is None else format(x, fmt)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--child", help=argparse.SUPPRESS)
    ap.add_argument("--aot", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--only", default="", help="comma-separated entry points (" + ", ".join(ENTRIES) + ") and/or 'cli' to run")
    ap.add_argument("--skip", default="", help="comma-separated entry points (and/or 'cli') to leave out")
    ap.add_argument("--aot-below", type=float, default=15.0,
                    help="time lower()/compile() of a jitted entry point whose first call took less (s)")
    ap.add_argument("--timeout", type=float, default=300.0, help="limit per process, seconds")
    ap.add_argument("--out", default=str(HERE / "results"), help="results directory")
    ap.add_argument("--mode", choices=("auto", "optimized", "fast"), default="auto",
                    help="jaxrod's compile mode (JAXROD_COMPILE) in every process; 'auto' (the default) writes "
                         "compile.*, 'fast' compile_fast.*, 'optimized' compile_optimized.*")
    args = ap.parse_args(argv)
    if args.child:
        return child(args.child, args.aot)

    os.environ["JAXROD_COMPILE"] = args.mode  # the children inherit it (`_env`)
    names = list(ENTRIES) + ["cli"]
    if args.only:
        names = [n for n in names if n in args.only.split(",")]
    skip = set(filter(None, args.skip.split(",")))
    import jax
    import jaxlib

    t_start = time.perf_counter()
    meta = dict(date=datetime.datetime.now(datetime.timezone.utc).isoformat(), machine=platform.platform(),
                processor=platform.processor() or platform.machine(), cpu_count=os.cpu_count(),
                python=sys.version.split()[0], jax=jax.__version__, jaxlib=jaxlib.__version__,
                backend="cpu", git=_git(), scene=SCENE, phase_gaps=PHASE_GAPS, load_average_start=os.getloadavg(),
                openblas_threads=_env()["OPENBLAS_NUM_THREADS"], per_process_timeout_s=args.timeout, aot_below_s=args.aot_below,
                compile_mode=args.mode)
    try:
        import jaxrod

        meta["jaxrod"] = jaxrod.__version__
    except ImportError:
        pass
    print(meta, flush=True)
    entries, aot, cli = {}, {}, None
    for name in names:
        if name == "cli":
            continue
        if name in skip:
            entries[name] = dict(name=name, skipped="left out with --skip")
            continue
        r = _run_child(name, False, args.timeout)
        entries[name] = r
        print(name, {k: v for k, v in r.items() if k != "top_programs"}, flush=True)
        if ENTRIES[name][1] and r.get("first_call_s", float("inf")) < args.aot_below:
            aot[name] = _run_child(name, True, args.timeout)
            print("  aot", aot[name], flush=True)
    if "cli" in names and "cli" not in skip:
        cli = _cli(args.timeout)
        print("cli", cli, flush=True)
    meta["load_average_end"] = os.getloadavg()
    meta["total_run_s"] = time.perf_counter() - t_start

    rows = []
    for name, r in entries.items():
        v = r.get("trace_compile_s")
        lim, ok = _met(name, v)
        rows.append(dict(row=name, call=ENTRIES[name][0], first_call_s=r.get("first_call_s"),
                         second_call_s=r.get("second_call_s"), trace_compile_s=v,
                         programs_compiled=r.get("programs_compiled"), target_s=lim, met=ok, skipped=r.get("skipped")))
    if cli:
        for row, label in (("cli_cold", "cold"), ("cli_warm", "warm")):
            r = next((x for x in cli["runs"] if x["run"] == label), {})
            lim, ok = _met(row, r.get("wall_s"))
            rows.append(dict(row=row, call=f"`{cli['command']}` ({label})", first_call_s=r.get("wall_s"),
                             second_call_s=None, trace_compile_s=None, programs_compiled=r.get("programs_compiled"),
                             target_s=lim, met=ok, skipped=r.get("skipped")))
    res = dict(meta=meta, targets={k: dict(quantity=q, max_s=v) for k, (q, v) in TARGETS.items()},
               entries=entries, aot=aot, cli=cli, table=rows)
    outdir = Path(args.out)
    outdir.mkdir(parents=True, exist_ok=True)
    stem = {"auto": "compile", "fast": "compile_fast", "optimized": "compile_optimized"}[args.mode]
    (outdir / f"{stem}.json").write_text(json.dumps(res, indent=2) + "\n")
    md = _markdown(res)
    (outdir / f"{stem}.md").write_text(md)
    print(md)


def _markdown(res):
    meta, entries, aot, cli = res["meta"], res["entries"], res["aot"], res["cli"]
    la0, la1 = meta["load_average_start"], meta["load_average_end"]
    L = ["# Compile and latency budget (cpu)", "",
         "Generated by `python benchmarks/bench_compile.py"
         + (f" --mode {meta['compile_mode']}" if meta.get("compile_mode", "auto") != "auto" else "")
         + f"` on {meta['date']}; {meta['machine']} "
         f"({meta['processor']}), {meta['cpu_count']} CPUs, jax {meta['jax']} / jaxlib {meta['jaxlib']}, "
         f"git {meta['git']}; OPENBLAS_NUM_THREADS={meta['openblas_threads']}; whole run "
         f"{meta['total_run_s']:.0f} s." + (f" {meta['note']}" if meta.get("note") else ""), "",
         f"Load average (1 / 5 / 15 min) at start {la0[0]:.2f} / {la0[1]:.2f} / {la0[2]:.2f}, at end "
         f"{la1[0]:.2f} / {la1[1]:.2f} / {la1[2]:.2f}, on {meta['cpu_count']} cores: "
         + ("other jobs shared the cores during the run, so every time below is an upper bound."
            if max(la0[0], la1[0]) > 0.5 else "the machine was otherwise idle."), "",
         *([{"fast": "Compile mode `JAXROD_COMPILE=fast` in every process: XLA's -O0 and older loop emitters "
                    "(`jaxrod._compile.FAST_COMPILE_OPTIONS`), slower code, the same results to round-off.",
            "optimized": "Compile mode `JAXROD_COMPILE=optimized` in every process: XLA's optimizing code "
                         "generation from the first call.",
            "auto": "Compile mode `auto`, jaxrod's default, in every process: each program is compiled first "
                    "with the fast code generation (`jaxrod._compile.FAST_COMPILE_OPTIONS`) and again with XLA's "
                    "optimizing one once its calls have run for `jaxrod._compile.TIER_UP_FACTOR` times that first "
                    "compile; both calls below run the fast variant (compile_optimized.md has the optimized one "
                    "from the start)."}[meta.get("compile_mode", "optimized")], ""]),
         "Scene `jr.make_scene(60, 0.5, n=100)` (Psi0 = 60 deg, G/L = 0.5, s0 = 0.02 L, N = 100), float64. "
         "Each entry point runs in a fresh process without a persistent compilation cache and is called twice: "
         "first call = trace + compile + run, second call = run; trace + compile = first - second; programs "
         "compiled = XLA programs compiled during the first call (`jax_log_compiles` records; eager operations "
         "count). The CLI is the installed console script, whole-process wall time, cold = empty persistent "
         "cache, warm = the next run on that cache. Targets: the compile budget.", "",
         "| entry point | first call (s) | second call (s) | trace + compile (s) | programs compiled | target | met |",
         "|---|---:|---:|---:|---:|---|---|"]
    for r in res["table"]:
        name = r["row"]
        label = f"`{name}`" if not name.startswith("cli") else r["call"]
        if r["skipped"]:
            L.append(f"| {label} | skipped: {r['skipped']} | | | | | |")
            continue
        if name in TARGETS:
            q, lim = TARGETS[name]
            tgt = f"{'trace + compile' if q == 'trace_compile_s' else 'wall'} <= {lim:g} s"
            met = "**met**" if r["met"] else "**not met**"
        else:
            tgt, met = "-", "-"
        L.append(f"| {label} | {_f(r['first_call_s'])} | {_f(r['second_call_s'], '.3f')} | "
                 f"{_f(r['trace_compile_s'])} | {_f(r['programs_compiled'], 'd')} | {tgt} | {met} |")
    L += ["", "What the first call spends, from JAX's log records: tracing (union of the 'Finished tracing' "
          "intervals), lowering to MLIR (summed), XLA compilation (summed); the rest of the first call is Python, "
          "execution and dispatch. Largest program = the XLA program that took longest to compile.", "",
          "| entry point | called as | tracing (s) | lowering (s) | XLA compile (s) | largest program (s) | "
          "recompiled in 2nd call | import jax + jaxrod (s) |",
          "|---|---|---:|---:|---:|---|---:|---:|"]
    for name, r in entries.items():
        if r.get("skipped"):
            continue
        top = r["top_programs"][0] if r["top_programs"] else None
        big = f"`{top['name']}` {top['compile_s']:.2f}" if top else "-"
        L.append(f"| `{name}` | `{ENTRIES[name][0]}` | {r['tracing_s']:.2f} | {r['lowering_s']:.2f} | "
                 f"{r['xla_compile_s']:.2f} | {big} | {_again(r)} | {r['import_s']:.2f} |")
    same = {n: next((t["compile_s"] for t in entries[n]["top_programs"] if t["name"] == "jit(snap_angles)"), None)
            for n in ("snap_angles", "hysteresis", "snap_dynamics") if n in entries and not entries[n].get("skipped")}
    same = {n: v for n, v in same.items() if v is not None}
    if len(same) > 1:
        L += ["", "The same program, `jit(snap_angles)` at N = 100, took "
              + ", ".join(f"{v:.1f} s (in `{n}`)" for n, v in same.items())
              + " to compile in the processes of this run that compile it (the same function and arguments; the "
              "processes differ only in what else ran on the cores at the time)."]
    if aot:
        L += ["", "Ahead of time, for the entry points that are jitted themselves (`jaxrod._compile.jit`, an `equinox.filter_jit` with XLA options) and whose "
              f"first call took under {meta['aot_below_s']:g} s, each in another fresh process: `f.lower(*args)` "
              "(trace + lowering), `.compile()` (XLA), the compiled executable's first and steady (median of 3) "
              "run, and its fused kernels (` fusion(` calls in its optimized HLO: a measure of the compile's size "
              "that does not drift with the machine's speed).", "",
              "| entry point | lower (s) | compile (s) | programs compiled | fused kernels | first run (s) | run (s) |",
              "|---|---:|---:|---:|---:|---:|---:|"]
        for name, r in aot.items():
            if r.get("skipped"):
                L.append(f"| `{name}` | skipped: {r['skipped']} | | | | | |")
                continue
            L.append(f"| `{name}` | {r['lower_s']:.2f} | {r['compile_s']:.2f} | {r['aot_programs_compiled']} | "
                     f"{r.get('fused_kernels', '-')} | {r['first_run_s']:.3f} | {r['run_s']:.3f} |")
    if cli:
        L += ["", f"`{cli['command']}` on one fresh cache directory (the CLI caches programs that take >= 0.5 s "
              "to compile; the smaller ones are compiled again in every run):", "",
              "| run | wall (s) | XLA compilations | persistent-cache hits | XLA compile (s, summed) | tracing (s) | "
              "lowering (s) | cache files after | output ok |", "|---|---:|---:|---:|---:|---:|---:|---:|---|"]
        for r in cli["runs"]:
            if r.get("skipped"):
                L.append(f"| {r['run']} | skipped: {r['skipped']} | | | | | | | |")
                continue
            L.append(f"| {r['run']} | {r['wall_s']:.2f} | {r['xla_compilations']} | {r['cache_hits']} | "
                     f"{r['xla_compile_s']:.2f} | {r['tracing_s']:.2f} | {r['lowering_s']:.2f} | "
                     f"{r['cache_files_after']} | {r['output_ok']} |")
        cold = next((r for r in cli["runs"] if r["run"] == "cold" and not r.get("skipped")), None)
        big = ", ".join(f"`{t['name']}` {t['compile_s']:.1f} s" for t in cold["top_programs"][:2]) if cold else ""
        L += ["", "The command's default is Richardson extrapolation (`--no-extrapolate` turns it off): the values "
              "of `jr.snap_angles_extrapolated` from `snap_angles` at N = 100 and at N = 200, two programs, one per "
              "mesh, compiled with the fast code generation (the first variant of the default compile mode; the "
              "optimized one where `JAXROD_COMPILE=optimized`)"
              + (f" (the largest programs of the cold run: {big})" if big else "") + ". "
              "The first run exports each (`jax.export`; one traces while the other compiles) beside the XLA "
              "cache; a warm run loads both, side by side, so it neither traces nor lowers the library, and "
              "reads the executables from the persistent cache."]
    return "\n".join(L) + "\n"


if __name__ == "__main__":
    main()
