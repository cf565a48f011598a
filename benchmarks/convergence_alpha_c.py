#!/usr/bin/env python
r"""Convergence of the critical clamp angles alpha_c with the mesh and the stretching stiffness.

Run from the repository root (about 15-25 minutes on a loaded 2-core machine):

    OPENBLAS_NUM_THREADS=1 python benchmarks/convergence_alpha_c.py [--quick]

For a set of (Psi0, G/L) points (tight folds, large gaps, the flat strip; s0 = 0.02),
`jr.snap_angles` gives alpha_c_up and alpha_c_down on meshes of N segments, uniform
(`refine = 1`) and graded at the crease (`refine = 4`, only N = 50, 100: at s0 = 0.02 it is less accurate than the uniform mesh). The reference value of each
(point, path) is the Richardson extrapolation of the two finest uniform meshes (N = 200,
400) with the order observed on N = 100, 200, 400 (2 where those three do not give a clean
order); the error of every mesh is |alpha_c(N) - alpha_ref| in degrees.
Reported: the errors, the observed order (least-squares slope of log error vs log N), and
the smallest N of each family within 0.05 deg and 0.002 deg at every point (from the
measured errors; "> N_max" when none is). Then alpha_c at N = 100 with a stretching
stiffness K L^2/B = 1e4, 1e5, 1e6 against the inextensible value.

Writes benchmarks/results/convergence_alpha_c.json (every number, machine, date) and
convergence_alpha_c.md (tables). The run is resumable: finished (mesh, point) values are
kept in the JSON and not recomputed.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxrod as jr  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
POINTS = [(180.0, 0.5), (180.0, 0.9), (120.0, 0.3), (90.0, 0.5), (60.0, 0.5), (60.0, 0.2),
          (45.0, 0.7), (30.0, 0.3), (30.0, 0.6)]
FAMILIES = {"uniform": (1.0, [50, 100, 200, 400]), "refine4": (4.0, [50, 100])}
STIFFNESS = [1e4, 1e6]


def snap(psi0, gap, n, refine, stiffness=None):
    st = None if stiffness is None else jr.Stretching(stiffness)
    sc = jr.make_scene(psi0, gap, 0.0, s0=0.02, n=n, refine=refine, stretching=st)
    r = jr.snap_angles(sc)
    return [float(np.degrees(r.up.alpha_c)), float(np.degrees(r.down.alpha_c)),
            jr.KIND_NAMES[int(r.up.kind)], jr.KIND_NAMES[int(r.down.kind)]]


def machine():
    return {"platform": platform.platform(), "python": platform.python_version(), "jax": jax.__version__,
            "jaxrod": jr.__version__, "cpu_count": os.cpu_count(), "processor": platform.processor(),
            "backend": jax.default_backend()}


def key(psi0, gap):
    return f"{psi0:g}/{gap:g}"


def analyse(data):
    out = {}
    for p in POINTS:
        k = key(*p)
        rec = {}
        for j, path in enumerate(("up", "down")):
            fam = {}
            r4 = data["uniform"]
            ns = [n for n in FAMILIES["uniform"][1] if str(n) in r4 and k in r4[str(n)]]
            vals = [r4[str(n)][k][j] for n in ns]
            if len(vals) < 3 or any(v is None or not math.isfinite(v) for v in vals[-3:]):
                rec[path] = {"reference": None}
                continue
            a, b, c = vals[-3:]
            # observed order from the three finest uniform meshes (ratio 2), then Richardson
            ratio = (a - b) / (b - c) if b != c else float("inf")
            p_obs = math.log2(abs(ratio)) if ratio > 0 and math.isfinite(ratio) else 2.0
            p_use = p_obs if 1.0 <= p_obs <= 4.0 else 2.0
            ref = c + (c - b) / (2**p_use - 1)
            for name, (_, nlist) in FAMILIES.items():
                errs = {}
                for n in nlist:
                    v = data[name].get(str(n), {}).get(k)
                    if v is not None and v[j] is not None and math.isfinite(v[j]):
                        errs[n] = abs(v[j] - ref)
                nn = sorted(errs)
                slope = (float(np.polyfit(np.log(nn), np.log(np.maximum([errs[n] for n in nn], 1e-14)), 1)[0])
                         if len(nn) >= 3 else None)
                fam[name] = {"errors_deg": {str(n): errs[n] for n in nn}, "order": None if slope is None else -slope,
                             "n_for_0.05": next((n for n in nn if errs[n] <= 0.05), None),
                             "n_for_0.002": next((n for n in nn if errs[n] <= 0.002), None)}
            rec[path] = {"reference": ref, "order_richardson": p_obs, **fam}
        out[k] = rec
    return out


def markdown(res):
    lines = ["# Convergence of alpha_c with N (s0 = 0.02, inextensible)", "",
             f"Date {res['date']}, {res['machine']['platform']}, jax {res['machine']['jax']}.", "",
             "Reference: Richardson extrapolation of uniform N = 200 and 400 with the observed order. "
             "Errors in degrees.", ""]
    fams = list(FAMILIES)
    head = "| Psi0 | G/L | path | kind | alpha_ref (deg) | " + " | ".join(
        f"{f} N={n}" for f in fams for n in FAMILIES[f][1]) + " | order uniform | order refine4 |"
    lines += [head, "|" + "---|" * (head.count("|") - 1)]
    for p in POINTS:
        k = key(*p)
        for j, path in enumerate(("up", "down")):
            r = res["analysis"][k][path]
            kind = res["data"]["uniform"].get("100", {}).get(k, [None] * 4)[2 + j]
            if r.get("reference") is None:
                lines.append(f"| {p[0]:g} | {p[1]:g} | {path} | {kind} | no snap | " + " | ".join(
                    "-" for f in fams for n in FAMILIES[f][1]) + " | - | - |")
                continue
            cells = []
            for f in fams:
                for n in FAMILIES[f][1]:
                    e = r[f]["errors_deg"].get(str(n))
                    cells.append("-" if e is None else f"{e:.2e}")
            o = [r[f]["order"] for f in fams]
            lines.append(f"| {p[0]:g} | {p[1]:g} | {path} | {kind} | {r['reference']:.5f} | " + " | ".join(cells)
                         + " | " + " | ".join("-" if x is None else f"{x:.2f}" for x in o) + " |")
    lines += ["", "## Smallest N within tolerance (worst over all points and both paths)", "",
              "| family | N for 0.05 deg | N for 0.002 deg | max error at N = 100 (deg) |", "|---|---|---|---|"]
    for f in fams:
        lines.append(f"| {f} | {res['summary'][f]['n_for_0.05']} | {res['summary'][f]['n_for_0.002']} | "
                     f"{res['summary'][f]['max_err_n100']:.4f} |")
    lines += ["", "## Stretching stiffness (N = 100, uniform): alpha_c(K) - alpha_c(inextensible), deg", "",
              "| Psi0 | G/L | path | " + " | ".join(f"K={K:g}" for K in STIFFNESS) + " |",
              "|---|---|---|" + "---|" * len(STIFFNESS)]
    for p in POINTS:
        k = key(*p)
        base = res["data"]["uniform"].get("100", {}).get(k)
        for j, path in enumerate(("up", "down")):
            cells = []
            for K in STIFFNESS:
                v = res["data"]["stretching"].get(f"{K:g}", {}).get(k)
                d = None if (v is None or base is None or v[j] is None or base[j] is None) else v[j] - base[j]
                cells.append("-" if d is None or not math.isfinite(d) else f"{d:+.2e}")
            lines.append(f"| {p[0]:g} | {p[1]:g} | {path} | " + " | ".join(cells) + " |")
    lines += ["", f"Wall time of the whole run: {res['wall_s']:.0f} s."]
    return "\n".join(lines) + "\n"


def summary(analysis):
    s = {}
    for f, (_, nlist) in FAMILIES.items():
        need05, need002, e100 = 0, 0, 0.0
        for k, rec in analysis.items():
            for path in ("up", "down"):
                r = rec[path]
                if r.get("reference") is None:
                    continue
                a, b = r[f]["n_for_0.05"], r[f]["n_for_0.002"]
                need05 = max(need05, a if a is not None else 10**9)
                need002 = max(need002, b if b is not None else 10**9)
                e100 = max(e100, r[f]["errors_deg"].get("100", 0.0))
        s[f] = {"n_for_0.05": need05 if need05 < 10**9 else f"> {nlist[-1]}",
                "n_for_0.002": need002 if need002 < 10**9 else f"> {nlist[-1]}", "max_err_n100": e100}
    return s


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="two points, small meshes (smoke test)")
    args = ap.parse_args()
    global POINTS
    if args.quick:
        POINTS = POINTS[:2]
    RESULTS.mkdir(parents=True, exist_ok=True)
    jpath = RESULTS / "convergence_alpha_c.json"
    data = {"uniform": {}, "refine4": {}, "stretching": {}}
    if jpath.exists():
        data.update(json.loads(jpath.read_text()).get("data", {}))
    t0 = time.time()
    from tqdm import tqdm

    jobs = [(f, refine, n, None) for f, (refine, ns) in FAMILIES.items() for n in ns]
    jobs += [("stretching", 1.0, 100, K) for K in STIFFNESS]
    for fam, refine, n, K in tqdm(jobs, desc="meshes"):
        slot = data[fam].setdefault(f"{K:g}" if K else str(n), {})
        for p in POINTS:
            if key(*p) in slot:
                continue
            v = snap(*p, n, refine, K)
            slot[key(*p)] = [x if not isinstance(x, float) or math.isfinite(x) else None for x in v]
            jpath.write_text(json.dumps({"data": data}, indent=1))
    an = analyse(data)
    res = {"benchmark": "convergence_alpha_c", "date": datetime.datetime.now().isoformat(timespec="seconds"),
           "machine": machine(), "s0": 0.02, "points": POINTS, "families": FAMILIES, "stiffness": STIFFNESS,
           "data": data, "analysis": an, "summary": summary(an), "wall_s": time.time() - t0}
    jpath.write_text(json.dumps(res, indent=1))
    (RESULTS / "convergence_alpha_c.md").write_text(markdown(res))
    print(markdown(res))


if __name__ == "__main__":
    main()
