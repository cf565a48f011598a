#!/usr/bin/env python
"""The implicit integrator against RATTLE: the speed/accuracy trade of the brink snap.

    python benchmarks/bench_implicit.py [--ns 50,100,200] [--ring]

Brink snap of Psi0 = 30 deg, G/L = 0.5, s0 = 0.02 (`jr.brink(scene, "up", nudge=0.05)`),
N = 50, 100, 200, in the configuration a user gets (`jr.simulate` with its defaults, run times of
the compiled programs in the optimized compile mode). Per N, side by side in one run:

* a tight reference v_s: RATTLE at courant 0.05 (9x the default's steps); at N = 50 it is
  also checked against Dopri8 at rtol = atol = 1e-9;
* RATTLE at its default step (courant 0.45) and at courant 0.25;
* `jr.HHT()` (the default alpha = -0.02, tol = 3e-6) and tol = 1e-5, 1e-6, alpha = -0.01, -0.05;
* the trapezoidal rule (alpha = 0) at a fixed dt = 1e-4 T.

Each row: wall time of the compiled run (median of `--repeats`), the first call's time
(compilation included), steps, |v_s - v_ref| / v_ref, the energy drift. `--ring`: 5 T of
undamped ringing past the snap at N = 200 by the implicit solvers (RATTLE's, at its ringing
step, are in tests/test_long_horizon.py) (`stop_at_snap=False`, the default energy monitor:
a run whose balance drifts by 1 % is stopped with `energy_drift`), per solver.
Writes benchmarks/results/implicit.json, implicit.md and implicit.png (error against time).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import time
from pathlib import Path

# run times of the steady state: XLA's optimizing code generation from the first call, as
# benchmarks/bench_dynamics.py (jaxrod's default "auto" mode tiers up to it after a program has
# run long enough; its timing of a few repeated runs mixes both tiers)
os.environ.setdefault("JAXROD_COMPILE", "optimized")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxrod as jr  # noqa: E402

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"


def timed(start, repeats, **kw):
    """(trajectory, median compiled wall time, first-call time) of `jr.simulate` from a start."""
    kw = dict(direction=start.direction, max_steps=4_000_000) | kw

    def call():
        t0 = time.perf_counter()
        tr = jr.simulate(start.scene, start.theta0, start.protocol, **kw)
        jax.block_until_ready(tr.v_s)
        return tr, time.perf_counter() - t0

    tr, first = call()
    times = [call()[1] for _ in range(repeats)]
    return tr, float(np.median(times)) if times else first, first


def configs():
    yield "RATTLE (default, courant 0.45)", dict()
    yield "RATTLE courant 0.25", dict(solver=jr.Rattle(courant=0.25))
    yield "HHT (default: alpha -0.02, tol 3e-6)", dict(solver=jr.HHT())
    yield "HHT tol 1e-5", dict(solver=jr.HHT(tol=1e-5))
    yield "HHT tol 1e-6", dict(solver=jr.HHT(tol=1e-6))
    yield "HHT alpha -0.01", dict(solver=jr.HHT(alpha=-0.01))
    yield "HHT alpha -0.05", dict(solver=jr.HHT(alpha=-0.05))
    yield "trapezoidal (alpha 0), dt 1e-4", dict(solver=jr.HHT(alpha=0.0), dt=1e-4)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ns", default="50,100,200")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--ring", action="store_true")
    ap.add_argument("--from-json", action="store_true", help="rewrite the table and figure from implicit.json")
    args = ap.parse_args()
    if args.from_json:
        data = json.loads((RESULTS / "implicit.json").read_text())
        refs = {int(k): v for k, v in data["refs"].items()}
        write_md(data["info"], refs, data["rows"], data["ring"])
        plot(data["rows"])
        return
    t_start = time.perf_counter()
    load0 = os.getloadavg()
    rows, refs, ring = [], {}, []
    for n in [int(x) for x in args.ns.split(",")]:
        scene = jr.make_scene(30.0, 0.5, n=n)
        start = jr.brink(scene, "up", nudge=0.05)
        ref, wall, _ = timed(start, 0, solver=jr.Rattle(courant=0.05))
        refs[n] = dict(v_ref=float(ref.v_s), steps=int(ref.num_steps), wall_s=wall)
        if n == 50:
            d8, _, _ = timed(start, 0, solver="dopri8", rtol=1e-9, atol=1e-9)
            refs[n]["dopri8_1e-9"] = float(d8.v_s)
        print(json.dumps(dict(n=n, **refs[n])), flush=True)
        for name, kw in configs():
            tr, wall, first = timed(start, args.repeats, **kw)
            row = dict(n=n, solver=name, wall_s=wall, first_s=first, steps=int(tr.num_steps),
                       v_s=float(tr.v_s), rel_err=abs(float(tr.v_s) / refs[n]["v_ref"] - 1.0),
                       energy_drift=float(tr.energy_drift), result=jr.result_name(tr.result))
            rows.append(row)
            print(json.dumps(row), flush=True)
    if args.ring:
        scene = jr.make_scene(30.0, 0.5, n=200)
        start = jr.brink(scene, "up", nudge=0.05)
        for name, kw in [("HHT (default)", dict(solver=jr.HHT())),
                         ("trapezoidal (alpha 0), dt 5e-5", dict(solver=jr.HHT(alpha=0.0), dt=5e-5))]:
            tr, wall, _ = timed(start, 0, t1=5.0, stop_at_snap=False, **kw)
            ring.append(dict(solver=name, t1=5.0, n=200, wall_s=wall, steps=int(tr.num_steps), t_end=float(tr.t_end),
                             energy_drift=float(tr.energy_drift), result=jr.result_name(tr.result)))
            print(json.dumps(ring[-1]), flush=True)
    info = dict(date=datetime.datetime.now().isoformat(timespec="seconds"), machine=platform.machine(),
                processor=platform.processor(), cpus=os.cpu_count(), python=platform.python_version(),
                jax=jax.__version__, loadavg_start=load0, loadavg_end=os.getloadavg(),
                total_s=time.perf_counter() - t_start)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "implicit.json").write_text(json.dumps(dict(info=info, refs=refs, rows=rows, ring=ring), indent=1))
    write_md(info, refs, rows, ring)
    plot(rows)


def write_md(info, refs, rows, ring):
    out = [f"# Implicit integrator against RATTLE ({info['date']}, {info['cpus']} CPUs)", "",
           "Brink snap of Psi0 = 30 deg, G/L = 0.5, s0 = 0.02 (`jr.brink(scene, 'up', nudge=0.05)`), "
           "`jr.simulate` with its defaults otherwise. Reference v_s: RATTLE at courant 0.05. Wall: compiled "
           "run (`JAXROD_COMPILE=optimized`), median of the repeats; first: the first call, compilation included. "
           f"Load average {info['loadavg_start']} at the start, {info['loadavg_end']} at the end.", ""]
    if 50 in refs and "dopri8_1e-9" in refs[50]:
        d = abs(refs[50]["dopri8_1e-9"] / refs[50]["v_ref"] - 1)
        out += [f"Reference check at N = 50: Dopri8 (rtol = atol = 1e-9) differs from it by {d:.1e}.", ""]
    out += ["| N | solver | wall (s) | first call (s) | steps | v_s / v* | rel. error | energy drift | result | vs RATTLE default |",
            "|---|---|---|---|---|---|---|---|---|---|"]
    for n in sorted(refs):
        base = next(r["wall_s"] for r in rows if r["n"] == n and r["solver"].startswith("RATTLE (default"))
        for r in (r for r in rows if r["n"] == n):
            out.append(f"| {n} | {r['solver']} | {r['wall_s']:.3f} | {r['first_s']:.1f} | {r['steps']} | "
                       f"{r['v_s']:.5f} | {r['rel_err']:.1e} | {r['energy_drift']:.1e} | {r['result']} | "
                       f"{base / r['wall_s']:.2f}x |")
    hht = {r["n"]: r["wall_s"] for r in rows if r["solver"].startswith("HHT (default")}
    rat = {r["n"]: r["wall_s"] for r in rows if r["solver"].startswith("RATTLE (default")}
    if 50 in hht and 200 in hht:
        out += ["", f"HHT (default): N = 200 takes {hht[200] / hht[50]:.1f}x the N = 50 run; RATTLE (default) "
                f"{rat[200] / rat[50]:.1f}x."]
    if ring:
        out += ["", "5 T of undamped ringing past the snap, N = 200 (`stop_at_snap=False`):", "",
                "| solver | wall (s) | steps | reached t | energy drift | result |", "|---|---|---|---|---|---|"]
        for r in ring:
            out.append(f"| {r['solver']} | {r['wall_s']:.2f} | {r['steps']} | {r['t_end']:.3f} | "
                       f"{r['energy_drift']:.1e} | {r['result']} |")
    (RESULTS / "implicit.md").write_text("\n".join(out) + "\n")


def plot(rows):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for n, marker in zip(sorted({r["n"] for r in rows}), "osD^"):
        for fam, color in (("RATTLE", "C0"), ("HHT", "C1"), ("trapezoidal", "C2")):
            pts = [(r["wall_s"], max(r["rel_err"], 1e-8)) for r in rows if r["n"] == n and r["solver"].startswith(fam)]
            if pts:
                x, y = zip(*pts)
                ax.loglog(x, y, marker, color=color, label=f"{fam}, N = {n}")
    ax.axhline(1e-3, color="0.6", lw=0.8, ls="--")
    ax.set_xlabel("wall time of the compiled run (s)")
    ax.set_ylabel("|v_s - v_ref| / v_ref")
    ax.set_title("Brink snap, Psi0 = 30 deg, G/L = 0.5")
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(RESULTS / "implicit.png", dpi=120)


if __name__ == "__main__":
    main()
