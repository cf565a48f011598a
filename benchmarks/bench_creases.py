#!/usr/bin/env python
r"""Strips with several creases: snap angles, their convergence with the mesh, and snap speeds.

For a few crease sets (G/L = 0.5, s0 = 0.02 each), `jr.snap_angles` on meshes of N = 24, 48,
96 and 192 segments, uniform and graded around every crease (`Mesh.for_strip`, refine 3).
Reference: Richardson extrapolation of the two finest uniform meshes (order 2). Reported per
set and path: alpha_c and kind at every N, the error against the reference, the observed
order (least-squares slope of log error against log N over N >= 48), the critical point's
result code; then the brink snap speed (`jr.snap_speed_run`, N = 96) with each crease's
peak speed, and the time of one `snap_angles` call once compiled.

    python benchmarks/bench_creases.py [--quick]

Writes benchmarks/results/creases{_quick}.json (every number, machine, date) and .md.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# run times of the steady state: XLA's optimizing code generation from the first call (jaxrod's
# default "auto" compile mode reaches it once a program's calls have run long enough)
os.environ.setdefault("JAXROD_COMPILE", "optimized")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxrod as jr  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))

SETS = {
    "centred 90 (one crease)": [(0.5, 90.0)],
    "symmetric pair 0.25/0.75, 90+90": [(0.25, 90.0), (0.75, 90.0)],
    "asymmetric pair 0.30/0.65, 90+90": [(0.3, 90.0), (0.65, 90.0)],
    "asymmetric pair 0.30/0.70, 60+120": [(0.3, 60.0), (0.7, 120.0)],
    "three 0.25/0.50/0.75, 120 each": [(0.25, 120.0), (0.5, 120.0), (0.75, 120.0)],
}


def scene(creases, n, refine=1.0, gap=0.5):
    return jr.make_scene(180.0, gap, n=n, refine=refine, creases=creases)


def angles(sc):
    r = jr.snap_angles(sc)
    out = {}
    for name in ("up", "down"):
        p = getattr(r, name)
        out[name] = dict(alpha_c_deg=float(np.degrees(float(p.alpha_c))) if bool(p.snaps) else None,
                         kind=jr.KIND_NAMES[int(p.kind)], result=jr.result_name(p.result))
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    ns = [24, 48, 96] if args.quick else [24, 48, 96, 192]
    t_start = time.time()
    suffix = "_quick" if args.quick else ""
    out = os.path.join(HERE, "results", f"creases{suffix}")
    rows, spent = {}, 0.0
    if os.path.exists(out + ".json"):  # resume: sets finished on the same meshes are kept
        with open(out + ".json") as fh:
            old = json.load(fh)
        if old["meta"]["meshes"] == ns:
            rows, spent = old["sets"], old["meta"]["seconds"]
    for label, cr in SETS.items():
        if label in rows:
            continue
        rec = {"creases": cr, "uniform": {}, "graded": {}}
        for n in ns:
            rec["uniform"][n] = angles(scene(cr, n))
            rec["graded"][n] = angles(scene(cr, n, refine=3.0))
        for name in ("up", "down"):
            a = [rec["uniform"][n][name]["alpha_c_deg"] for n in ns]
            if any(x is None for x in a[-2:]):
                rec[f"reference_{name}"] = None
                continue
            ref = a[-1] + (a[-1] - a[-2]) / 3.0
            rec[f"reference_{name}"] = ref
            for fam in ("uniform", "graded"):
                errs = {n: (None if rec[fam][n][name]["alpha_c_deg"] is None
                            else abs(rec[fam][n][name]["alpha_c_deg"] - ref)) for n in ns}
                rec[f"error_{fam}_{name}"] = errs
                pts = [(n, e) for n, e in errs.items() if n >= 48 and e and e > 0 and (fam == "graded" or n < ns[-1])]
                if len(pts) >= 2:
                    x, y = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
                    rec[f"order_{fam}_{name}"] = float(-np.polyfit(x, y, 1)[0])
        sc = scene(cr, 96)
        f = jax.jit(jr.snap_angles)
        jax.block_until_ready(f(sc))
        t0 = time.perf_counter()
        for _ in range(5):
            jax.block_until_ready(f(sc))
        rec["snap_angles_ms_n96"] = 1e3 * (time.perf_counter() - t0) / 5
        for name in ("up", "down"):
            r = jr.snap_speed_run(sc, direction=name)
            rec[f"v_s_{name}"] = float(r.v_s) if np.isfinite(float(r.v_s)) else None
            rec[f"v_s_creases_{name}"] = [float(v) if np.isfinite(float(v)) else None for v in np.asarray(r.v_s_creases)]
            rec[f"speed_result_{name}"] = jr.result_name(r.result)
        rows[label] = json.loads(json.dumps(rec, default=str))  # mesh keys as strings, as when read back
        print(label, {k: v for k, v in rec.items() if k.startswith(("reference", "order", "v_s"))}, flush=True)
        meta = dict(date=datetime.date.today().isoformat(), machine=platform.platform(), cpus=os.cpu_count(),
                    jax=jax.__version__, seconds=spent + time.time() - t_start, gap=0.5, s0=0.02, meshes=ns)
        with open(out + ".json", "w") as fh:
            json.dump(dict(meta=meta, sets=rows), fh, indent=1, default=str)
        with open(out + ".md", "w") as fh:
            fh.write(_markdown(meta, rows, ns))
        # every (crease count, mesh) is its own compiled program: release them between sets,
        # or one process runs out of memory mappings (see tests/conftest.py)
        jax.clear_caches()
    print("wrote", out + ".json", out + ".md")


def _fmt(x, spec="+.4f"):
    return "-" if x is None else format(x, spec)


def _markdown(meta, rows, ns):
    lines = ["# Strips with several creases: snap angles, convergence, snap speeds", "",
             f"{meta['date']}, {meta['machine']}, {meta['cpus']} cores, jax {meta['jax']}; "
             f"{meta['seconds']:.0f} s. `python benchmarks/bench_creases.py`.", "",
             "G/L = 0.5, s0 = 0.02 L for every crease; positions in L, fold angles in degrees. "
             "Reference: Richardson extrapolation (order 2) of the two finest uniform meshes. "
             "Kinds: fold or branch_point (an asymmetric mode of a mirror-symmetric state).", ""]
    for label, rec in rows.items():
        lines += [f"## {label}", "", "| N | up: uniform | up: graded (refine 3) | down: uniform | down: graded |",
                  "|---|---|---|---|---|"]
        for n in ns:
            cells = []
            for name in ("up", "down"):
                for fam in ("uniform", "graded"):
                    r = rec[fam][str(n)][name]
                    tag = r["kind"] if r["result"] == "successful" else f"{r['kind']}, {r['result']}"
                    cells.append(f"{_fmt(r['alpha_c_deg'])} ({tag})")
            lines.append(f"| {n} | " + " | ".join(cells) + " |")
        for name in ("up", "down"):
            ref = rec.get(f"reference_{name}")
            if ref is None:
                lines.append(f"\n{name}: no reference (no snap on the finest meshes).")
                continue
            ou, og = rec.get(f"order_uniform_{name}"), rec.get(f"order_graded_{name}")
            eu = rec[f"error_uniform_{name}"]
            lines.append(f"\n{name}: reference {ref:+.4f} deg; observed order uniform {_fmt(ou, '.2f')}, graded "
                         f"{_fmt(og, '.2f')}; uniform error at N = 96: {_fmt(eu.get('96'), '.2e')} deg.")
        lines.append("")
        for name in ("up", "down"):
            vc = ", ".join(_fmt(v, ".2f") for v in rec[f"v_s_creases_{name}"])
            lines.append(f"- snap {name} (N = 96, brink): v_s at L/2 {_fmt(rec[f'v_s_{name}'], '.2f')} v*, per crease "
                         f"[{vc}] v* ({rec[f'speed_result_{name}']})")
        lines.append(f"- one `snap_angles` call at N = 96, compiled: {rec['snap_angles_ms_n96']:.1f} ms")
        lines.append("")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
