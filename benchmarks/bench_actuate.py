"""The actuator's costs: a RATTLE step with and without balls, one program-design iteration
(value and gradient through the run) and the paper's three programs run in sequence.

    python benchmarks/bench_actuate.py [--quick]

Writes benchmarks/results/actuate.json (machine, date, numbers) and actuate.md. Compile
time is counted separately from the run (first call minus second).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import time

import jax

# run times of the steady state: XLA's optimizing code generation from the first call (jaxrod's
# default "auto" compile mode reaches it once a program's calls have run long enough)
os.environ.setdefault("JAXROD_COMPILE", "optimized")

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402

import jaxrod as jr  # noqa: E402
from jaxrod import design as D  # noqa: E402
from jaxrod import paper  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))


def timed(f):
    t = time.perf_counter()
    out = f()
    jax.block_until_ready(jax.tree.leaves(out))
    return out, time.perf_counter() - t


def step_costs(ns, t1=1.5):
    rows = []
    for n in ns:
        sc = jr.make_scene(60.0, 0.5, n=n)
        eq = jr.initial_state(sc, "down")
        prog = D.two_knot_program((70.0, 0.0))
        for label, bodies in [("far ball (no contact)", jr.Bodies([jr.Ball("far", (5.0, 5.0), 0.04, 0.05)])),
                              ("three balls (Fig. 4)", paper.fig4_bodies())]:
            _, first = timed(lambda: jr.actuate(sc, bodies, prog, theta0=eq.theta, t1=t1))
            a, run = timed(lambda: jr.actuate(sc, bodies, prog, theta0=eq.theta, t1=t1))
            steps = int(a.num_steps)
            rows.append(dict(n=n, bodies=label, steps=steps, run_s=run, compile_s=first - run,
                             us_per_step=1e6 * run / steps, result=jr.result_name(a.result)))
        # the strip alone with simulate's own step (no contact step limit)
        tr, first = timed(lambda: jr.simulate(sc, eq.theta, jr.Protocol(rate_left=1.2), t1=t1, stop_at_snap=False))
        tr, run = timed(lambda: jr.simulate(sc, eq.theta, jr.Protocol(rate_left=1.2), t1=t1, stop_at_snap=False))
        rows.append(dict(n=n, bodies="simulate (strip alone)", steps=int(tr.num_steps), run_s=run,
                         compile_s=first - run, us_per_step=1e6 * run / int(tr.num_steps),
                         result=jr.result_name(tr.result)))
    return rows


def design_iteration(n=16, t1=2.4):
    sc = jr.make_scene(60.0, 0.5, n=n)
    eq = jr.initial_state(sc, "down")
    bodies = paper.fig4_bodies()

    def loss(p):
        a = jr.actuate(sc, bodies, D.two_knot_program(p), theta0=eq.theta, t1=t1)
        return jnp.sum(a.peak_speed**2)

    vg = jax.value_and_grad(loss)
    p = jnp.array([70.0, 0.0])
    _, first = timed(lambda: vg(p))
    _, run = timed(lambda: vg(p + 1.0))
    _, fwd_first = timed(lambda: loss(p))
    _, fwd = timed(lambda: loss(p + 1.0))
    return dict(n=n, t1=t1, value_and_grad_s=run, compile_s=first - run, forward_s=fwd, ratio=run / fwd)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    ns = (16,) if args.quick else (16, 32, 64)
    res = dict(machine=dict(platform=platform.platform(), processor=platform.processor(), cpus=os.cpu_count(),
                            jax=jax.__version__, jaxrod=jr.__version__ if hasattr(jr, "__version__") else None),
               date=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"))
    res["steps"] = step_costs(ns)
    res["design_iteration"] = design_iteration()
    tic = time.perf_counter()
    study = paper.fig4_study()
    res["fig4"] = dict(seconds=time.perf_counter() - tic, confirmed=study.confirmed, stage_speeds=study.stage_speeds,
                       designs=[dict(target=d.target, peaks_deg=d.peaks_deg, iterations=d.iterations,
                                     seconds=d.seconds, speeds=d.speeds, check=d.check, reached=d.reached,
                                     confirmed=d.confirmed, codes=d.codes) for d in study.designs])
    s = study.sequence
    _, seq_run = timed(lambda: jr.actuate(jr.make_scene(60.0, 0.5, n=study.n_check), paper.fig4_bodies(),
                                          D.sequence_program([d.peaks_deg for d in study.designs])))
    res["sequence"] = dict(n=study.n_check, run_s=seq_run, steps=int(s.num_steps), result=jr.result_name(s.result),
                           energy_error=float(s.energy_error), hits=s.hits(),
                           snaps=[e for e in s.snaps() if e["kind"] == "snap"])
    out = os.path.join(HERE, "results")
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "actuate.json"), "w") as f:
        json.dump(res, f, indent=1, default=str)
    lines = [f"# Actuator costs ({res['date']}, {res['machine']['cpus']} CPUs, jax {res['machine']['jax']})", "",
             "One program (left clamp to 70 deg) for 1.5 T, Psi0 = 60 deg, G/L = 0.5.", "",
             "| N | run | steps | run (s) | compile (s) | us / step | result |", "|---|---|---|---|---|---|---|"]
    for r in res["steps"]:
        lines.append(f"| {r['n']} | {r['bodies']} | {r['steps']} | {r['run_s']:.2f} | {r['compile_s']:.1f} | "
                     f"{r['us_per_step']:.1f} | {r['result']} |")
    di = res["design_iteration"]
    lines += ["", f"One program-design iteration (value and gradient of the three peak speeds through a "
                  f"{di['t1']} T run, N = {di['n']}): {di['value_and_grad_s']:.2f} s "
                  f"({di['ratio']:.1f}x the forward run's {di['forward_s']:.2f} s; compile {di['compile_s']:.0f} s).", "",
              "## The paper's Fig. 4 programs", "", study.table(), "",
              f"Each program designed on the balls the ones before it left (N = {study.n}), then the three in "
              f"sequence in one run with the three balls (N = {res['sequence']['n']}, "
              f"{res['sequence']['steps']} steps, {res['sequence']['run_s']:.1f} s): "
              f"{res['sequence']['result']}, energy error {res['sequence']['energy_error']:.1e}; each program "
              f"launched its ball and spared the others: {res['fig4']['confirmed']}. Design and re-check: "
              f"{res['fig4']['seconds']:.0f} s.", "",
              "Every contact of the sequence run:", "",
              "| hit | time (T) | impulse (lambda L v*) | launch speed (v*) |", "|---|---|---|---|"]
    for h in res["sequence"]["hits"]:
        lines.append(f"| {h['name']} | {h['time']:.3f} | {h['impulse_norm']:.3f} | {h['launch_speed']:.2f} |")
    with open(os.path.join(out, "actuate.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
