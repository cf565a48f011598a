"""Self-contact: what it costs and what it changes at small gaps.

1. Cost (N = 48 and 100, a state with its legs pressed together, Psi0 = 180 deg, G/L = 0.1):
   one Hessian assembly and one Newton solve of the KKT system with contact (dense) and
   without (bordered tridiagonal); one `snap_angles` (run, compile excluded) and its compile;
   one brink snap (`snap_dynamics`, Psi0 = 60 deg, G/L = 0.2, down).
2. Snap angles and brink snap speeds with and without contact at G/L = 0.1, 0.2, 0.3 (and
   0.05) for Psi0 = 30, 60, 90, 180 deg (N = 48): alpha_c, kind, result code, clearance of the
   reported states (segments at least N/10 apart), v_s.
3. The phase diagram down to G/L = 0.05 with contact (Psi0 30-180 deg) and the contact-free
   one on the same grid (a figure), with its cost.
4. v_s at the smallest gaps against the speed plane's G/L = 0 intercept (the paper: self-contact
   limits real strips to about 75 % of it).

    python benchmarks/bench_contact.py            # everything (about 25 min on 2 cores)
    python benchmarks/bench_contact.py --quick    # fewer points
    python benchmarks/bench_contact.py --costs-only   # re-measure the costs into the results

Writes benchmarks/results/contact{_quick}.json, .md and contact_phase{_quick}.png.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

# run times of the steady state: XLA's optimizing code generation from the first call (jaxrod's
# default "auto" compile mode reaches it once a program's calls have run long enough)
os.environ.setdefault("JAXROD_COMPILE", "optimized")

jax.config.update("jax_enable_x64", True)

import jaxrod as jr  # noqa: E402
from jaxrod.dynamics._snap_speed import snap_speed_run  # noqa: E402
from jaxrod.linalg import kkt  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
PAPER_PLANE = (42.59, 30.38, 5.00)
_SHORT = {"successful": "ok", "self_intersecting": "X"}  # v_s / v* = v_m - a G/L - b Psi0 (rad)


def _best(f, *a, reps=20):
    jax.block_until_ready(f(*a))
    ts = []
    for _ in range(3):
        t0 = time.perf_counter()
        for _ in range(reps):
            jax.block_until_ready(f(*a))
        ts.append((time.perf_counter() - t0) / reps)
    return min(ts)


def costs(ns):
    out = []
    for n in ns:
        sc = jr.make_scene(180.0, 0.1, n=n, contact=jr.Contact())
        free = jr.make_scene(180.0, 0.1, n=n)
        eq = jr.initial_state(sc, "up")
        th, mu = eq.theta, eq.force
        rec = dict(n=n, contact_energy=float(jr.energies(eq)["contact"]))
        for name, s in (("contact", sc), ("free", free)):
            hess = jax.jit(lambda t, m, s=s: kkt.structured(t, m, s))
            step = jax.jit(lambda t, m, s=s: kkt.solve(kkt.structured(t, m, s), t, m))
            count = jax.jit(lambda t, m, s=s: kkt.count_below(kkt.structured(t, m, s), jnp.zeros(1)))
            rec[f"hessian_ms_{name}"] = 1e3 * _best(hess, th, mu)
            rec[f"newton_step_ms_{name}"] = 1e3 * _best(step, th, mu)
            rec[f"stability_count_ms_{name}"] = 1e3 * _best(count, th, mu)
        for name, s in (("contact", jr.make_scene(60.0, 0.2, n=n, contact=jr.Contact())),
                        ("free", jr.make_scene(60.0, 0.2, n=n))):
            t0 = time.perf_counter()
            jax.block_until_ready(jr.snap_angles(s).up.alpha_c)
            first = time.perf_counter() - t0
            t0 = time.perf_counter()
            jax.block_until_ready(jr.snap_angles(s).up.alpha_c)
            run = time.perf_counter() - t0
            rec[f"snap_angles_s_{name}"] = run
            rec[f"snap_angles_compile_s_{name}"] = first - run
            # one brink snap down (its snap path, then RATTLE to the overshoot)
            jax.block_until_ready(jr.snap_dynamics(s, "down")[1].v_s)
            t0 = time.perf_counter()
            jax.block_until_ready(jr.snap_dynamics(s, "down")[1].v_s)
            rec[f"snap_s_{name}"] = time.perf_counter() - t0
        out.append(rec)
        print(rec, flush=True)
    return out


def _clear(path, sc, m):
    c = [float(jr.clearance(path.theta_before, sc, min_separation=m))]
    if bool(path.snaps):
        c.append(float(jr.clearance(path.theta_after, sc, min_separation=m)))
    return min(c)


def table(psis, gaps, n, progress):
    recs = []
    for psi in psis:
        for g in gaps:
            for contact in (None, jr.Contact()):
                sc = jr.make_scene(psi, g, n=n, contact=contact)
                t0 = time.perf_counter()
                r = jr.snap_angles(sc)
                rec = dict(psi0_deg=psi, gap=g, contact=contact is not None)
                for d in ("up", "down"):
                    p = getattr(r, d)
                    rec[f"alpha_c_{d}_deg"] = float(np.degrees(p.alpha_c))
                    rec[f"kind_{d}"] = jr.KIND_NAMES[int(p.kind)]
                    rec[f"result_{d}"] = jr.result_name(p.result)
                    rec[f"clearance_{d}"] = _clear(p, sc, max(n // 10, 2))
                    rec[f"clicks_{d}"] = int(p.clicks)
                    s = snap_speed_run(sc, d)
                    rec[f"v_s_{d}"] = float(s.v_s)
                    # the trajectory's own peak, also where the critical point was not refined
                    # (derivative_unavailable: the brink at the bisection value of alpha_c)
                    rec[f"v_s_raw_{d}"] = float(s.v_s_raw)
                    rec[f"v_s_result_{d}"] = jr.result_name(s.result)
                    rec[f"energy_drift_{d}"] = float(s.energy_drift)
                rec["seconds"] = time.perf_counter() - t0
                recs.append(rec)
                if progress:
                    print({k: (round(v, 4) if isinstance(v, float) else v) for k, v in rec.items()}, flush=True)
    return recs


def phase(psis, gaps, n):
    out = {}
    for name, contact in (("contact", jr.Contact()), ("free", None)):
        t0 = time.perf_counter()
        ds = jr.phase_diagram(psis, gaps, n=n, contact=contact, progress=False)
        out[name] = dict(seconds=time.perf_counter() - t0,
                         **{v: np.asarray(ds[v]).tolist() for v in ("alpha_c_up", "alpha_c_down", "kind_up",
                                                                    "kind_down", "result_up", "result_down")})
        print(name, out[name]["seconds"], flush=True)
    return out


def figure(ph, psis, gaps, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
    cmap = plt.get_cmap("viridis")
    for ax, name in zip(axes, ("free", "contact")):
        d = ph[name]
        for i, p in enumerate(psis):
            col = cmap(i / max(len(psis) - 1, 1))
            for key, ls in (("up", "-"), ("down", "--")):
                a = np.asarray(d[f"alpha_c_{key}"][i], float)
                ok = np.array([jr.result_name(c) == "successful" for c in d[f"result_{key}"][i]])
                ax.plot(gaps, np.where(ok, a, np.nan), ls, color=col, marker="o", ms=3,
                        label=f"{p:g} deg" if key == "up" else None)
                bad = ~ok & np.isfinite(a)
                ax.plot(np.asarray(gaps)[bad], a[bad], "x", color=col, ms=6)
        ax.axhline(0, color="0.6", lw=0.5)
        ax.set_xlabel("G / L")
        ax.set_title("without contact (x: flagged, e.g. self-intersecting)" if name == "free"
                     else "with self-contact (thickness 0.01 L)")
    axes[0].set_ylabel("alpha_c (deg): snap up (solid), snap down (dashed)")
    axes[1].legend(title="Psi0", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--costs-only", action="store_true",
                    help="measure the costs only and merge them into the existing results")
    args = ap.parse_args(argv)
    q = args.quick
    if args.costs_only:
        suffix = "_quick" if q else ""
        path = os.path.join(HERE, "results", f"contact{suffix}.json")
        res = json.load(open(path))
        meta = res.pop("meta")
        res["costs"] = costs([24] if q else [48, 100])
        meta["costs_date"] = datetime.date.today().isoformat()
        with open(path, "w") as f:
            json.dump(dict(meta=meta, **res), f, indent=1)
        write_md(meta, res, os.path.join(HERE, "results", f"contact{suffix}.md"), suffix)
        return
    t_start = time.perf_counter()
    n = 24 if q else 48
    res = dict(costs=costs([24] if q else [48, 100]))
    psis = [60.0, 180.0] if q else [30.0, 60.0, 90.0, 180.0]
    gaps = [0.1, 0.3] if q else [0.05, 0.1, 0.2, 0.3]
    res["table"] = table(psis, gaps, n, progress=True)
    ph_psis = [60.0, 180.0] if q else [30.0, 60.0, 90.0, 120.0, 150.0, 180.0]
    ph_gaps = [0.05, 0.1, 0.2] if q else [0.05, 0.075, 0.1, 0.15, 0.2, 0.25, 0.3, 0.4, 0.5]
    res["phase"] = dict(psi0_deg=ph_psis, gaps=ph_gaps, n=n, **phase(ph_psis, ph_gaps, n))
    suffix = "_quick" if q else ""
    out = os.path.join(HERE, "results")
    figure(res["phase"], ph_psis, ph_gaps, os.path.join(out, f"contact_phase{suffix}.png"))
    # the speed plane's G/L = 0 intercept, against v_s with contact at the smallest gap
    fit = json.load(open(os.path.join(out, "dynamics_speed_plane_n40_fit.json")))["fit"]
    limit = []
    g0 = min(gaps)
    for r in res["table"]:
        if r["contact"] and r["gap"] == g0:
            p = np.radians(r["psi0_deg"])
            icpt = fit["v_m"] - fit["b"] * p
            icpt_paper = PAPER_PLANE[0] - PAPER_PLANE[2] * p
            v = np.nanmax([r["v_s_raw_up"], r["v_s_raw_down"]])
            limit.append(dict(psi0_deg=r["psi0_deg"], gap=g0, v_s_max=float(v), intercept_jaxrod=icpt,
                              intercept_paper=icpt_paper, ratio_jaxrod=float(v / icpt),
                              ratio_paper=float(v / icpt_paper)))
    res["intercept"] = limit
    meta = dict(date=datetime.date.today().isoformat(), machine=platform.platform(), cpus=os.cpu_count(),
                jax=jax.__version__, python=sys.version.split()[0], n=n, seconds=time.perf_counter() - t_start,
                contact=dict(thickness=0.01, stiffness=1e5, exclusion=0.1))
    with open(os.path.join(out, f"contact{suffix}.json"), "w") as f:
        json.dump(dict(meta=meta, **res), f, indent=1)
    write_md(meta, res, os.path.join(out, f"contact{suffix}.md"), suffix)


def _f(x, fmt="{:.3f}"):
    return "-" if x is None or not np.isfinite(x) else fmt.format(x)


def write_md(meta, res, path, suffix):
    L = [f"# Self-contact: cost and effect (N = {meta['n']})", "",
         f"{meta['date']}, {meta['machine']}, {meta['cpus']} cores, jax {meta['jax']}; {meta['seconds']:.0f} s"
         + (f"; the cost section measured {meta['costs_date']} in a run of its own (`--costs-only`). "
            if meta.get("costs_date") else ". ") +
         "Contact: thickness 0.01 L, stiffness 1e5 B/L^3, exclusion 0.1 L (`jaxrod.Contact()`).", "",
         "## Cost", "",
         "| N | Hessian (ms) contact / free | Newton step (ms) contact / free | stability count (ms) contact / free "
         "| snap_angles run (s) contact / free | its compile (s) contact / free | brink snap (s) contact / free |",
         "|---|---|---|---|---|---|---|"]
    for c in res["costs"]:
        L.append(f"| {c['n']} | {c['hessian_ms_contact']:.2f} / {c['hessian_ms_free']:.3f} "
                 f"| {c['newton_step_ms_contact']:.2f} / {c['newton_step_ms_free']:.3f} "
                 f"| {c['stability_count_ms_contact']:.2f} / {c['stability_count_ms_free']:.3f} "
                 f"| {c['snap_angles_s_contact']:.3f} / {c['snap_angles_s_free']:.3f} "
                 f"| {c['snap_angles_compile_s_contact']:.1f} / {c['snap_angles_compile_s_free']:.1f} "
                 f"| {_f(c.get('snap_s_contact'), '{:.2f}')} / {_f(c.get('snap_s_free'), '{:.2f}')} |")
    L += ["", "## Snap angles and brink snap speeds with and without contact", "",
          "| Psi0 | G/L | contact | alpha_c up (deg) | kind, result | clearance | v_s up | alpha_c down (deg) "
          "| kind, result | clearance | v_s down |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in res["table"]:
        row = [f"{r['psi0_deg']:g}", f"{r['gap']:g}", "yes" if r["contact"] else "no"]
        for d in ("up", "down"):
            clicks = r.get(f"clicks_{d}", 0)
            row += [_f(r[f"alpha_c_{d}_deg"]) + (f" ({clicks} click{'s' if clicks > 1 else ''})" if clicks else ""),
                    f"{r[f'kind_{d}']}, {r[f'result_{d}']}",
                    _f(r[f"clearance_{d}"], "{:.4f}"),
                    _f(r[f"v_s_{d}"], "{:.2f}") if r[f"v_s_result_{d}"] == "successful"
                    else (f"{_f(r[f'v_s_raw_{d}'], '{:.2f}')}* ({r[f'v_s_result_{d}']})")]
        L.append("| " + " | ".join(row) + " |")
    L += ["", "*: the run's peak fold speed where `snap_speed` gives no value (`derivative_unavailable`: the "
          "brink at the bisection value of alpha_c, whose extended-system refinement failed; `snap_not_resolved`: "
          "the run's fold never crossed y = 0). Clicks: losses of stability in contact before the snap whose "
          "landing lay within 0.1 rad and kept the fold on its side (`SnapPath.clicks`; the path continued).", ""]
    ph = res["phase"]
    L += ["", f"## Phase diagram down to G/L = {min(ph['gaps']):g}", "",
          f"{len(ph['psi0_deg'])} x {len(ph['gaps'])} grid: with contact {ph['contact']['seconds']:.0f} s, "
          f"without {ph['free']['seconds']:.0f} s (compile included).", "",
          f"![phase diagram with and without contact](contact_phase{suffix}.png)", "",
          "| Psi0 | result codes without contact (up; down) | with contact (up; down) |", "|---|---|---|"]
    for i, p in enumerate(ph["psi0_deg"]):
        def codes(d):
            return ", ".join(_SHORT.get(jr.result_name(c), jr.result_name(c)) for c in d[i])
        L.append(f"| {p:g} | {codes(ph['free']['result_up'])}; {codes(ph['free']['result_down'])} "
                 f"| {codes(ph['contact']['result_up'])}; {codes(ph['contact']['result_down'])} |")
    L += ["", "Per gap, in the order of the grid: ok = successful, X = self_intersecting (the contact-free model "
          "passes through itself), others by their `jaxrod.RESULTS` name.", "",
          "## The speed plane's G/L = 0 intercept", "",
          "| Psi0 | G/L | v_s with contact (max of up, down; peak of the run) | jaxrod plane intercept | ratio | paper plane intercept "
          "| ratio |", "|---|---|---|---|---|---|---|"]
    for r in res["intercept"]:
        L.append(f"| {r['psi0_deg']:g} | {r['gap']:g} | {r['v_s_max']:.2f} | {r['intercept_jaxrod']:.2f} "
                 f"| {r['ratio_jaxrod']:.2f} | {r['intercept_paper']:.2f} | {r['ratio_paper']:.2f} |")
    with open(path, "w") as f:
        f.write("\n".join(L) + "\n")


if __name__ == "__main__":
    main()
