#!/usr/bin/env python
"""Batched snap angles: one compiled `jax.vmap` call against a loop of single calls, in one run.

Run from the repository root (on whatever device JAX sees first):

    python benchmarks/bench_batch.py                   # N = 100, B = 1, 16, 128, 1024 (~15-30 min on 2 cores)
    python benchmarks/bench_batch.py --quick           # smoke test: N = 24, B = 1, 4 (a minute or two)
    python benchmarks/bench_batch.py --batches 1,16 --n 60 --out /tmp/bench

Writes `results/batch_<platform>.json` and `.md` (`_quick` added with `--quick`, so a smoke
test never overwrites the full results; `--out` another folder), the platform being
`jax.devices()[0].platform`. `benchmarks/bench_gpu.py` calls the functions below with a time
budget for one accelerator.

**Scenes.** B scenes with fold angle Psi0 in [15, 180] deg and gap G/L in [0.25, 0.93]
(s0 = 0.02, N uniform segments, float64), built in one call,
`jax.vmap(lambda p, g: jr.make_scene(p, g, n=N))(psis, gaps)`. B = 128 is the 16 x 8 grid
(16 Psi0 evenly from 15 to 180 deg, 8 G/L evenly from 0.25 to 0.93, Psi0 the slow index).
Every other B is a seeded uniform sample of the same box: `numpy.random.default_rng(0)
.uniform(size=(B, 2))` scaled to the box, row i = (Psi0, G/L) of member i, so a smaller
sample is the first members of a larger one.

**What is measured**, per B, as a user writes it:

* the batch: `batched = jax.jit(jax.vmap(jr.snap_angles))` (both paths, polished, the
  defaults). compile = wall time of `batched.lower(scenes).compile()` (trace, lower and
  compile; the lowering alone is in the JSON); batch call = median wall time of the
  compiled call over `--repeats` runs (1 run from B = 1024 on); per member = batch call / B;
  members/s = B / batch call;
* the loop: `[jr.snap_angles(jr.make_scene(p, g, n=N)) for p, g in ...]`, the single
  program compiled once beforehand (its first call is the "single call" row), timed over
  all B members up to `--loop-cap` (128); above it over the first 128 members only, the
  per-member time extrapolated to the batch (the row says so);
* batch / loop throughput = loop per member / batch per member (> 1: the batch is faster);
* equality of every looped member to its batch member: max |d alpha_c| (deg) over both
  paths where both snap, and whether `snaps`, `kind` and `result` agree exactly
  ("codes equal", with the count of members checked);
* memory: the compiled batch's `memory_analysis()` (temp + argument + output bytes: what
  XLA allocates for one call) and the process's peak RSS (`resource.getrusage`, a
  high-water mark over the whole run so far) right after the batch runs; on an accelerator
  also the device's `peak_bytes_in_use`.

Besides: "equilibria (nearby start)", `jax.jit(jax.vmap(jr.solve_equilibrium))` over B
strips around Psi0 = 60 deg, G/L = 0.5 (Psi0 in [50, 70] deg, G/L in [0.45, 0.55], seeded),
each started from the Psi0 = 60, G/L = 0.5 down state (3-6 Newton iterations), against a
loop of single `jr.solve_equilibrium` calls (result codes and fold heights compared); and
`jr.phase_diagram` over 5 Psi0 (30, 60, 90, 120, 180 deg) x 41 G/L (0.1 ... 0.9) at N, in
each batch mode (`scan`, `vmap`, `shard`): first call (trace + compile + run) and a second
call (the run), its numbers compared with `scan`'s.

The batched program is compiled by `jax.jit` with XLA's default options: inside a JAX
transformation jaxrod's entry points are plain `equinox.filter_jit` and take no options,
whereas a single top-level `jr.snap_angles` call compiles with jaxrod's
`COMPILER_OPTIONS` (two of XLA's while-loop passes off). `--jaxrod-options` adds, per B, the
same batch compiled with those options (`lowered.compile(compiler_options())`).

On a CPU `jax.vmap(jr.snap_angles)` runs its members one after another through the single
call's program (`jaxrod._lanes.in_turn`): the batch saves the loop's dispatch, not arithmetic,
and uses no more cores than one call. On an accelerator it is one vectorized program, whose
solver loops run a lane per member.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path


os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# run times of the steady state: XLA's optimizing code generation from the first call (jaxrod's
# default "auto" compile mode reaches it once a program's calls have run long enough)
os.environ.setdefault("JAXROD_COMPILE", "optimized")

import jax  # noqa: E402


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from tqdm import tqdm  # noqa: E402

import jaxrod as jr  # noqa: E402


HERE = Path(__file__).resolve().parent
PSI_BOX = (15.0, 180.0)
GAP_BOX = (0.25, 0.93)
GRID_B, GRID_SHAPE = 128, (16, 8)  # Psi0 x G/L
SEED = 0
MEMORY_TARGET_BYTES = 4 * 2**30  # a batch of 1024 at N = 100 must fit in 4 GiB
EQUAL_TOL_DEG = 1e-6  # "every member equal to its single call": codes exactly, alpha_c to round-off
PHASE_PSIS = (30.0, 60.0, 90.0, 120.0, 180.0)
PHASE_GAPS = tuple(np.round(np.linspace(0.1, 0.9, 41), 10).tolist())
MiB = 2.0**20


def log(*a):
    print(*a, file=sys.stderr, flush=True)


def _git():
    try:
        out = subprocess.run(["git", "rev-parse", "--short=10", "HEAD"], capture_output=True, text=True,
                             cwd=HERE).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], capture_output=True,
                               text=True, cwd=HERE).stdout.strip()
        return (out + (" (modified)" if dirty else "")) if out else "unknown"
    except OSError:
        return "unknown"


def machine_meta(**extra):
    dev = jax.devices()[0]
    import jaxlib

    return dict(date=datetime.datetime.now(datetime.timezone.utc).isoformat(), machine=platform.platform(),
                processor=platform.processor(), cpu_count=os.cpu_count(), device=str(dev),
                device_kind=getattr(dev, "device_kind", ""), device_count=jax.device_count(),
                platform=dev.platform, python=sys.version.split()[0], jax=jax.__version__,
                jaxlib=jaxlib.__version__, jaxrod=jr.__version__, git=_git(), float64=True,
                jaxrod_compile=os.environ.get("JAXROD_COMPILE"),
                openblas_threads=os.environ.get("OPENBLAS_NUM_THREADS"), load_average_start=os.getloadavg(),
                **extra)


# -- scenes ----------------------------------------------------------------------------------------

def scene_points(b, seed=SEED):
    """(psis, gaps, how): the 16 x 8 grid for B = 128, else a seeded sample of the box."""
    if b == GRID_B:
        p, g = np.meshgrid(np.linspace(*PSI_BOX, GRID_SHAPE[0]), np.linspace(*GAP_BOX, GRID_SHAPE[1]),
                           indexing="ij")
        return p.ravel(), g.ravel(), f"grid {GRID_SHAPE[0]} x {GRID_SHAPE[1]}"
    u = np.random.default_rng(seed).uniform(size=(b, 2))
    lo = np.array([PSI_BOX[0], GAP_BOX[0]])
    hi = np.array([PSI_BOX[1], GAP_BOX[1]])
    x = lo + u * (hi - lo)
    return x[:, 0], x[:, 1], f"random (seed {seed})"


def make_scenes(psis, gaps, n):
    return jax.vmap(lambda p, g: jr.make_scene(p, g, n=n))(jnp.asarray(psis, jnp.float64),
                                                            jnp.asarray(gaps, jnp.float64))


# -- memory and timing -----------------------------------------------------------------------------

def peak_rss_bytes():
    """The process's peak resident set (Linux reports KiB, macOS bytes)."""
    r = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(r if sys.platform == "darwin" else r * 1024)


def device_peak_bytes():
    try:
        stats = jax.devices()[0].memory_stats() or {}
    except Exception:  # noqa: BLE001 - CPU devices may not report
        return None
    return stats.get("peak_bytes_in_use")


def program_memory(compiled):
    """XLA's buffer estimate of a compiled program (bytes), or None where it gives none."""
    try:
        m = compiled.memory_analysis()
    except Exception:  # noqa: BLE001
        return None
    if m is None:
        return None
    keys = ("temp_size_in_bytes", "argument_size_in_bytes", "output_size_in_bytes", "alias_size_in_bytes",
            "generated_code_size_in_bytes")
    out = {k: int(getattr(m, k)) for k in keys if getattr(m, k, None) is not None}
    out["total_bytes"] = sum(out.get(k, 0) for k in keys[:3])
    return out


def timed_runs(fn, repeats):
    """(median, runs, last output) of `repeats` blocking calls of fn()."""
    runs, out = [], None
    for _ in range(repeats):
        out = None  # the previous run's output freed before the next one allocates its own
        t0 = time.perf_counter()
        out = jax.block_until_ready(fn())
        runs.append(time.perf_counter() - t0)
    return float(np.median(runs)), runs, out


# -- snap angles -----------------------------------------------------------------------------------

def summary(sa):
    """The compared fields of a `SnapAngles` (batched or not) as NumPy arrays."""
    out = {}
    for path in ("up", "down"):
        p = getattr(sa, path)
        out[f"{path}_snaps"] = np.asarray(p.snaps)
        out[f"{path}_alpha_deg"] = np.degrees(np.asarray(p.alpha_c))
        out[f"{path}_kind"] = np.asarray(p.kind)
        out[f"{path}_result"] = np.asarray(p.result._value)
    return out


def compare(batch, singles):
    """Batch members against their single calls: `singles` maps member index -> summary."""
    if not singles:
        return dict(checked=0, max_dalpha_deg=None, codes_equal=None, mismatched_members=[])
    idx = np.array(sorted(singles))
    worst, bad = 0.0, set()
    for path in ("up", "down"):
        for field in ("snaps", "kind", "result"):
            b = batch[f"{path}_{field}"][idx]
            s = np.array([singles[i][f"{path}_{field}"] for i in idx])
            bad.update(idx[b != s].tolist())
        b = batch[f"{path}_alpha_deg"][idx]
        s = np.array([singles[i][f"{path}_alpha_deg"] for i in idx])
        both = batch[f"{path}_snaps"][idx] & np.array([singles[i][f"{path}_snaps"] for i in idx])
        if np.any(both):
            worst = max(worst, float(np.max(np.abs(b[both] - s[both]))))
    return dict(checked=len(idx), max_dalpha_deg=worst, codes_equal=not bad, mismatched_members=sorted(bad)[:20])


def counts(batch):
    out = {}
    for path in ("up", "down"):
        out[f"snaps_{path}"] = int(np.sum(batch[f"{path}_snaps"]))
        codes, k = np.unique(batch[f"{path}_result"], return_counts=True)
        out[f"results_{path}"] = {jr.result_name(int(c)): int(v) for c, v in zip(codes, k)}
    return out


class Singles:
    """The loop of single calls, with a cache of every member computed (by (Psi0, G/L)), so a
    batch whose members were looped for a smaller size is compared at no cost."""

    def __init__(self, n):
        self.n, self.cache, self.calls, self.time_s = n, {}, 0, 0.0
        self.first_call = None

    def compile(self, psi=60.0, gap=0.5):
        """The single program compiled (and run) once, before any loop is timed."""
        t0 = time.perf_counter()
        out = jax.block_until_ready(jr.snap_angles(jr.make_scene(psi, gap, n=self.n)))
        first = time.perf_counter() - t0
        t0 = time.perf_counter()
        jax.block_until_ready(jr.snap_angles(jr.make_scene(psi, gap, n=self.n)))
        second = time.perf_counter() - t0
        mem = None
        try:  # the program a top-level call runs now, from JAX's cache
            scene = jr.make_scene(psi, gap, n=self.n)
            mem = program_memory(jr.snap_angles.lower(scene).compile())
        except Exception:  # noqa: BLE001
            pass
        self.first_call = dict(first_call_s=first, second_call_s=second, program_memory=mem,
                               peak_rss_bytes=peak_rss_bytes(), device_peak_bytes=device_peak_bytes(),
                               up_snaps=bool(out.up.snaps))
        return self.first_call

    def loop(self, psis, gaps, desc):
        """Time `[jr.snap_angles(jr.make_scene(p, g, n=N)) for p, g in ...]`; cache the results."""
        n = self.n
        pts = [(float(p), float(g)) for p, g in zip(psis, gaps)]
        t0 = time.perf_counter()
        outs = [jr.snap_angles(jr.make_scene(p, g, n=n))
                for p, g in tqdm(pts, desc=desc, file=sys.stderr, leave=False, mininterval=1.0)]
        jax.block_until_ready(outs)
        t = time.perf_counter() - t0
        for pt, o in zip(pts, outs):
            self.cache[pt] = summary(o)
        self.calls += len(pts)
        self.time_s += t
        return t

    def lookup(self, psis, gaps):
        out = {}
        for i, (p, g) in enumerate(zip(psis, gaps)):
            s = self.cache.get((float(p), float(g)))
            if s is not None:
                out[i] = s
        return out


def project_s(b, rows, repeats, loop_new, singles, min_exponent=1.0):
    """Projected wall time of size `b` from the rows measured so far (None: nothing to go by):
    the largest compile so far x 1.25, the batch run scaled from the last measured size as
    B^k (k fitted to the last two sizes, within [min_exponent, 1]), the new loop calls at the
    per-member time measured so far."""
    done = [r for r in rows if r.get("batch_call_s") is not None]
    if not done:
        return None
    compile_est = 1.25 * max(r["compile_s"] for r in done)
    last = done[-1]
    k = 1.0
    if len(done) >= 2 and done[-2]["batch"] != last["batch"]:
        prev = done[-2]
        k = math.log(last["batch_call_s"] / prev["batch_call_s"]) / math.log(last["batch"] / prev["batch"])
    elif len(done) == 1:
        k = min_exponent
    k = min(max(k, min_exponent), 1.0)
    run_est = last["batch_call_s"] * (b / last["batch"]) ** k
    loop_est = (singles.time_s / singles.calls) * loop_new if singles.calls else 0.0
    return compile_est + repeats * run_est + loop_est


def bench_snap_angles(batches, n, *, repeats=3, loop_cap=128, loop_max_batch=None, singles=None,
                      jaxrod_options=False, budget=None, min_exponent=1.0, on_row=None):
    """Rows of the snap-angle table (see the module docstring). `loop_cap`: most members looped
    per size; `loop_max_batch`: no loop above this size (its per-member figure then comes from
    the loops so far, its members compared where looped before); `budget`: a callable giving
    the seconds left, sizes whose projected time exceeds it skipped (with every larger one);
    `on_row(rows)` after each row."""
    singles = singles or Singles(n)
    rows = []
    log(f"snap_angles: compiling the single call (N = {n})")
    fc = singles.compile()
    rows.append(dict(what="snap_angles single call (the loop's program)", batch=1, compile_s=fc["first_call_s"],
                     batch_call_s=fc["second_call_s"], per_member_ms=1e3 * fc["second_call_s"],
                     members_per_s=1.0 / fc["second_call_s"], program_memory=fc["program_memory"],
                     peak_rss_bytes=fc["peak_rss_bytes"], device_peak_bytes=fc["device_peak_bytes"],
                     note="compile = first call (trace + compile + run); batch call = second call"))
    log(f"  first call {fc['first_call_s']:.1f} s, second {1e3 * fc['second_call_s']:.1f} ms")
    if on_row:
        on_row(rows)
    batched = jax.jit(jax.vmap(jr.snap_angles))
    variants = [("snap_angles jit(vmap)", None)]
    if jaxrod_options:
        from jaxrod._compile import compiler_options

        variants.append(("snap_angles jit(vmap), jaxrod's XLA options", compiler_options()))
    skip_rest = None
    for b in batches:
        reps = 1 if b >= 1024 else repeats
        looped = b <= loop_max_batch if loop_max_batch is not None else True
        m = min(b, loop_cap) if looped else 0
        psis, gaps, how = scene_points(b)
        if skip_rest is None and budget is not None:
            left = budget()
            proj = project_s(b, [r for r in rows if r["what"].startswith("snap_angles jit")], reps * len(variants),
                             m, singles, min_exponent)
            if proj is not None and proj > left:
                skip_rest = f"skipped: projected {proj:.0f} s > {left:.0f} s left of the time budget"
        if skip_rest is not None:
            rows.append(dict(what=variants[0][0], batch=b, scenes=how, skipped=skip_rest))
            log(f"B = {b}: {skip_rest}")
            if on_row:
                on_row(rows)
            continue
        log(f"B = {b} ({how}): building scenes")
        scenes = jax.block_until_ready(make_scenes(psis, gaps, n))
        loop_t = None
        if m:
            loop_t = singles.loop(psis[:m], gaps[:m], f"loop B={b}")
            loop_pm = loop_t / m
            loop_note = ((f"loop over all {m} members" if m > 1 else "loop over the 1 member") if m == b else
                         f"loop over the first {m} members, per member extrapolated to B = {b}")
        else:
            loop_pm = singles.time_s / singles.calls if singles.calls else None
            loop_note = (f"no loop at this size: loop per member from the {singles.calls} single calls so far"
                         if singles.calls else "no loop")
        ref = singles.lookup(psis, gaps)
        for what, opts in variants:
            log(f"B = {b}: {what}: lower + compile")
            t0 = time.perf_counter()
            lowered = batched.lower(scenes)
            t1 = time.perf_counter()
            compiled = lowered.compile(opts) if opts else lowered.compile()
            t2 = time.perf_counter()
            mem = program_memory(compiled)
            log(f"  lower {t1 - t0:.1f} s, compile {t2 - t1:.1f} s; running {reps}x")
            t, runs, out = timed_runs(lambda: compiled(scenes), reps)
            rss, dpeak = peak_rss_bytes(), device_peak_bytes()
            res = summary(out)
            del out
            cmp = compare(res, ref)
            row = dict(what=what, batch=b, scenes=how, n=n, lower_s=t1 - t0, compile_s=t2 - t0,
                       compile_only_s=t2 - t1, batch_call_s=t, runs_s=runs, per_member_ms=1e3 * t / b,
                       members_per_s=b / t, evaluations_per_minute=60.0 * b / t,
                       loop_members=m, loop_s=loop_t, loop_per_member_ms=None if loop_pm is None else 1e3 * loop_pm,
                       batch_over_loop_throughput=None if loop_pm is None else loop_pm / (t / b),
                       checked_members=cmp["checked"], max_dalpha_deg=cmp["max_dalpha_deg"],
                       codes_equal=cmp["codes_equal"], mismatched_members=cmp["mismatched_members"],
                       program_memory=mem, peak_rss_bytes=rss, device_peak_bytes=dpeak, note=loop_note,
                       **counts(res))
            rows.append(row)
            log(f"  batch {t:.3f} s ({row['per_member_ms']:.2f} ms/member), loop "
                f"{'-' if loop_pm is None else f'{1e3 * loop_pm:.2f}'} ms/member, "
                f"{cmp['checked']} checked: max |d alpha_c| {cmp['max_dalpha_deg']}, codes equal {cmp['codes_equal']}")
            if on_row:
                on_row(rows)
        del scenes
    return rows


# -- equilibria and the phase diagram ----------------------------------------------------------------

def bench_equilibria(batches, n, *, repeats=5, loop_cap=128):
    base = jr.make_scene(60.0, 0.5, n=n)
    down = jax.block_until_ready(jr.initial_state(base, "down"))
    theta, force = down.theta, down.force

    def one(scene):
        eq = jr.solve_equilibrium(scene, theta, force)
        return eq.result._value, jr.fold_height(eq)

    batched = jax.jit(jax.vmap(one))
    jax.block_until_ready(jr.solve_equilibrium(base, theta, force))  # the single program, compiled
    rows = []
    for b in batches:
        rng = np.random.default_rng(SEED)
        psis, gaps = rng.uniform(50.0, 70.0, b), rng.uniform(0.45, 0.55, b)
        scenes = make_scenes(psis, gaps, n)
        t0 = time.perf_counter()
        compiled = batched.lower(scenes).compile()
        comp = time.perf_counter() - t0
        t, runs, (codes, fh) = timed_runs(lambda: compiled(scenes), 1 if b >= 1024 else repeats)
        rss = peak_rss_bytes()
        m = min(b, loop_cap)
        pts = [(float(p), float(g)) for p, g in zip(psis[:m], gaps[:m])]
        t0 = time.perf_counter()
        outs = [jr.solve_equilibrium(jr.make_scene(p, g, n=n), theta, force) for p, g in pts]
        jax.block_until_ready(outs)
        loop_t = time.perf_counter() - t0
        s_codes = np.array([int(o.result._value) for o in outs])
        s_fh = np.array([float(jr.fold_height(o)) for o in outs])
        codes, fh = np.asarray(codes), np.asarray(fh)
        loop_pm = loop_t / m
        rows.append(dict(what="equilibria (nearby start)", batch=b, n=n, compile_s=comp, batch_call_s=t, runs_s=runs,
                         per_member_ms=1e3 * t / b, members_per_s=b / t, loop_members=m,
                         loop_per_member_ms=1e3 * loop_pm, batch_over_loop_throughput=loop_pm / (t / b),
                         checked_members=m, codes_equal=bool(np.array_equal(codes[:m], s_codes)),
                         max_dfold_height=float(np.max(np.abs(fh[:m] - s_fh))),
                         converged=int(np.sum(codes == 0)), program_memory=program_memory(compiled),
                         peak_rss_bytes=rss, device_peak_bytes=device_peak_bytes(),
                         note=f"converged {int(np.sum(codes == 0))}/{b}; max |d fold height| "
                              f"{float(np.max(np.abs(fh[:m] - s_fh))):.1e} L"
                              + ("" if m == b else f"; loop over the first {m} members")))
        log(f"equilibria B={b}: compile {comp:.1f} s, {1e3 * t:.2f} ms, {1e3 * t / b:.4f} ms/member, "
            f"loop {1e3 * loop_pm:.4f} ms/member")
    return rows


def bench_phase(n, psis=PHASE_PSIS, gaps=PHASE_GAPS, modes=("scan", "vmap", "shard")):
    rows, ref = [], None
    keys = ("alpha_c_up", "alpha_c_down")
    codes = ("kind_up", "kind_down", "result_up", "result_down")
    for mode in modes:
        log(f"phase_diagram {len(psis)} x {len(gaps)}, batch={mode!r}: first call")
        t0 = time.perf_counter()
        jr.phase_diagram(psis, gaps, n=n, batch=mode, progress=False)
        first = time.perf_counter() - t0
        t0 = time.perf_counter()
        ds = jr.phase_diagram(psis, gaps, n=n, batch=mode, progress=False)
        run = time.perf_counter() - t0
        vals = {k: np.asarray(ds[k].values) for k in keys + codes}
        if ref is None:
            ref = vals
        d = max(float(np.nanmax(np.abs(vals[k] - ref[k]), initial=0.0)) for k in keys)
        same = all(np.array_equal(np.isnan(vals[k]), np.isnan(ref[k])) for k in keys) and all(
            np.array_equal(vals[k], ref[k]) for k in codes)
        b = len(psis) * len(gaps)
        rows.append(dict(what=f"phase_diagram {len(psis)} x {len(gaps)}, batch={mode}", batch=b, n=n,
                         first_call_s=first, compile_s=first - run, batch_call_s=run, per_member_ms=1e3 * run / b,
                         members_per_s=b / run, max_dalpha_deg=d, codes_equal=same, peak_rss_bytes=peak_rss_bytes(),
                         device_peak_bytes=device_peak_bytes(),
                         note="compile = first call - second call; "
                              + ("the reference of the other modes" if mode == modes[0]
                                 else f"compared with batch={modes[0]}")))
        log(f"  first call {first:.1f} s, run {run:.2f} s, max |d alpha_c| vs {modes[0]} {d:.1e} deg, "
            f"same codes {same}")
    return rows


# -- output ------------------------------------------------------------------------------------------

def _f(x, fmt):
    return "–" if x is None else format(x, fmt)


def table(rows, extra_gpu=False):
    head = ["what", "B", "compile (s)", "batch call (s)", "per member (ms)", "members/s", "loop per member (ms)",
            "batch/loop throughput", "max \\|d alpha_c\\| (deg)", "codes equal", "program memory (MiB)",
            "peak RSS (MiB)"]
    if extra_gpu:
        head += ["evaluations / min", "device peak (MiB)"]
    head.append("notes")
    lines = ["| " + " | ".join(head) + " |", "|---|" + "---:|" * (len(head) - 2) + "---|"]
    for r in rows:
        if r.get("skipped"):
            cells = [r["what"], str(r["batch"])] + ["–"] * (len(head) - 3) + [r["skipped"].replace("|", "\\|")]
            lines.append("| " + " | ".join(cells) + " |")
            continue
        mem = r.get("program_memory") or {}
        eq = r.get("codes_equal")
        eq = "–" if eq is None else (f"{'yes' if eq else '**no**'} ({r['checked_members']})"
                                     if r.get("checked_members") is not None else ("yes" if eq else "**no**"))
        cells = [r["what"], str(r["batch"]), _f(r.get("compile_s"), ".1f"), _f(r.get("batch_call_s"), ".3f"),
                 _f(r.get("per_member_ms"), ".2f"), _f(r.get("members_per_s"), ".1f"),
                 _f(r.get("loop_per_member_ms"), ".2f"), _f(r.get("batch_over_loop_throughput"), ".2f"),
                 _f(r.get("max_dalpha_deg"), ".1e"), eq,
                 _f(mem.get("total_bytes") / MiB if mem.get("total_bytes") is not None else None, ".0f"),
                 _f(r["peak_rss_bytes"] / MiB if r.get("peak_rss_bytes") else None, ".0f")]
        if extra_gpu:
            cells += [_f(r.get("evaluations_per_minute"), ".0f"),
                      _f(r["device_peak_bytes"] / MiB if r.get("device_peak_bytes") else None, ".0f")]
        cells.append((r.get("note") or "").replace("|", "\\|"))
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def targets(snap_rows, n):
    """The issue's targets, checked on the rows measured."""
    out = {}
    measured = [r for r in snap_rows if r["what"] == "snap_angles jit(vmap)" and r.get("batch_call_s") is not None]
    out["every_member_equal"] = bool(measured) and all(
        r["codes_equal"] is not False and (r["max_dalpha_deg"] is None or r["max_dalpha_deg"] <= EQUAL_TOL_DEG)
        for r in measured)
    big = [r for r in measured if r["batch"] == 1024]
    if big and n == 100:
        mem = (big[0].get("program_memory") or {}).get("total_bytes")
        out["batch_1024_program_bytes"] = mem
        out["batch_1024_peak_rss_bytes"] = big[0]["peak_rss_bytes"]
        out["batch_1024_program_within_4GiB"] = bool(mem is not None and mem <= MEMORY_TARGET_BYTES)
        out["batch_1024_peak_rss_within_4GiB"] = bool(big[0]["peak_rss_bytes"] <= MEMORY_TARGET_BYTES)
    return out


def describe(meta, n):
    return (f"N = {n}, float64, s0 = 0.02; scenes: Psi0 in [{PSI_BOX[0]:g}, {PSI_BOX[1]:g}] deg x G/L in "
            f"[{GAP_BOX[0]:g}, {GAP_BOX[1]:g}]: B = {GRID_B} the {GRID_SHAPE[0]} x {GRID_SHAPE[1]} grid, other B a "
            f"uniform sample (`numpy.random.default_rng({SEED}).uniform(size=(B, 2))` scaled to the box; a smaller "
            f"sample is the first members of a larger one). JAXROD_COMPILE={meta['jaxrod_compile']}, "
            f"OPENBLAS_NUM_THREADS={meta['openblas_threads']}; load average "
            f"{meta['load_average_start'][0]:.2f} at the start, {meta.get('load_average_end', [float('nan')])[0]:.2f} "
            "at the end.")


COLUMNS_NOTE = [
    "Columns: compile = wall time of `batched.lower(scenes).compile()` with `batched = "
    "jax.jit(jax.vmap(jr.snap_angles))` (trace + lower + compile); batch call = median wall time of the compiled "
    "call (one run from B = 1024 on); loop per member = wall time of `[jr.snap_angles(jr.make_scene(p, g, n=N)) "
    "for ...]` / members looped, the single program compiled beforehand; batch/loop throughput = loop per member / "
    "batch per member (> 1: the batch is faster); max |d alpha_c| over both paths where batch and single call both "
    f"snap, codes equal = `snaps`, `kind` and `result` identical on both paths (members checked in brackets; equal "
    f"means codes equal and |d alpha_c| <= {EQUAL_TOL_DEG:g} deg); program memory = the compiled program's "
    "`memory_analysis()` temp + argument + output bytes; peak RSS = the process's high-water mark "
    "(`resource.getrusage`) right after the batch ran (it includes everything run before).",
    "",
    "On a CPU `jax.vmap(jr.snap_angles)` runs its members one after another through the single call's "
    "program (`jaxrod._lanes.in_turn`): the batch saves the loop's dispatch, not arithmetic, and uses no more "
    "cores than one call; on an accelerator it is one vectorized program with a lane per member.",
]


def write(out_dir, name, meta, sections, n, title, extra_gpu=False, notes=()):
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    meta = dict(meta, load_average_end=os.getloadavg())
    snap_rows = sections.get("snap_angles", [])
    res = dict(meta=meta, **sections, targets=targets(snap_rows, n))
    (out_dir / f"{name}.json").write_text(json.dumps(res, indent=2, default=float) + "\n")
    script = meta.get("script", "benchmarks/bench_batch.py")
    lines = [f"# {title} ({meta['platform']}: {meta['device_kind'] or meta['processor'] or meta['platform']})", "",
             f"Generated by `python {script}{' ' + meta['argv'] if meta.get('argv') else ''}` on {meta['date']}; "
             f"{meta['machine']}, {meta['cpu_count']} CPUs, jax {meta['jax']}, jaxrod {meta['jaxrod']}, "
             f"git {meta['git']}.", "", describe(meta, n), ""]
    rows = [r for sec in sections.values() for r in sec]
    lines += table(rows, extra_gpu=extra_gpu)
    lines.append("")
    t = res["targets"]
    lines.append(f"Every measured member equal to its single call: **{t['every_member_equal']}**.")
    if "batch_1024_program_within_4GiB" in t:
        mem = t["batch_1024_program_bytes"]
        lines.append(f"B = 1024 at N = 100 within 4 GiB: program (temp + arguments + output) "
                     f"{'–' if mem is None else f'{mem / MiB:.0f}'} MiB: **{t['batch_1024_program_within_4GiB']}**; "
                     f"the process's peak RSS {t['batch_1024_peak_rss_bytes'] / MiB:.0f} MiB: "
                     f"**{t['batch_1024_peak_rss_within_4GiB']}**.")
    lines.append("")
    lines += list(notes)
    lines += COLUMNS_NOTE
    (out_dir / f"{name}.md").write_text("\n".join(lines) + "\n")
    return lines


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=None, help="segments (default 100; 24 with --quick)")
    ap.add_argument("--batches", default=None, help="comma-separated batch sizes (default 1,16,128,1024; 1,4 quick)")
    ap.add_argument("--quick", action="store_true", help="smoke test: N = 24, B = 1, 4, a small phase diagram")
    ap.add_argument("--repeats", type=int, default=3, help="timed runs of each compiled batch below B = 1024")
    ap.add_argument("--loop-cap", type=int, default=128, help="most members looped per batch size")
    ap.add_argument("--jaxrod-options", action="store_true",
                    help="also compile each batch with jaxrod's XLA options (compiler_options())")
    ap.add_argument("--skip", default="", help="comma-separated sections to skip: equilibria, phase")
    ap.add_argument("--out", default=str(HERE / "results"), help="output folder")
    args = ap.parse_args(argv)
    n = args.n or (24 if args.quick else 100)
    batches = [int(b) for b in (args.batches or ("1,4" if args.quick else "1,16,128,1024")).split(",")]
    skip = {s for s in args.skip.split(",") if s}
    meta = machine_meta(n=n, batches=batches, quick=args.quick, repeats=args.repeats, loop_cap=args.loop_cap,
                        argv=" ".join(sys.argv[1:] if argv is None else argv))
    log(meta)
    name = f"batch_{meta['platform']}" + ("_quick" if args.quick else "")
    sections = {}

    def save(_rows=None):
        return write(args.out, name, meta, sections, n, "Batched snap angles")

    sections["snap_angles"] = []

    def on_row(rows):
        sections["snap_angles"] = rows
        save()

    bench_snap_angles(batches, n, repeats=args.repeats, loop_cap=args.loop_cap, jaxrod_options=args.jaxrod_options,
                      on_row=on_row)
    if "equilibria" not in skip:
        sections["equilibria"] = bench_equilibria(batches, n)
        save()
    if "phase" not in skip:
        if args.quick:
            sections["phase_diagram"] = bench_phase(n, psis=(30.0, 120.0), gaps=(0.3, 0.5, 0.7))
        else:
            sections["phase_diagram"] = bench_phase(n)
    print("\n".join(save()))


if __name__ == "__main__":
    main()
