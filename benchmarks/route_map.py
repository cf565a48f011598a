"""Which route a ramped snap takes: the map over ramp rate and imperfection amplitude.

Where a branch point is followed closely by a fold on the same branch (`jr.snap_routes`),
a symmetric ramp of the clamps (`jr.snap_dynamics(kind="ramp", rate=..., seed=...)`, from
alpha_c - 2 deg at rest, the start seeded with the mirror-breaking shape of amplitude
`seed`) snaps either asymmetrically at the branch point (route 1) or, passing it while the
asymmetric mode is still too small to grow (a delayed bifurcation), symmetrically at the
fold (route 2). A run is route 1 when the strip leaves mirror symmetry by more than 0.3 rad
(max |theta(s) + theta(L - s)|) before its speed peak. Three strips: the flat strip at
G/L = 0.5 and two creased strips whose fold lies a few degrees past the branch point.

    python benchmarks/route_map.py            # N = 48, 7 rates x 6 seeds x 3 strips
    python benchmarks/route_map.py --quick    # N = 24, 4 x 3 x 3

Writes benchmarks/results/route_map{_quick}.json, .md and .png.
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
import numpy as np

jax.config.update("jax_enable_x64", True)

import jaxrod as jr  # noqa: E402

STRIPS = ((180.0, 0.5), (150.0, 0.7), (170.0, 0.5))
N_FRAMES = 4096
ASYMMETRIC = 0.3  # rad: max |theta(s) + theta(L - s)| before the peak that makes a run route 1


def run(psi0, gap, n, rates, seeds, progress):
    sc = jr.make_scene(psi0, gap, n=n)
    snap = jr.snap_angles(sc)
    routes = jr.snap_routes(sc, snap=snap)
    r = routes.up
    out = dict(psi0_deg=psi0, gap=gap, n=n, alpha_c_deg=float(np.degrees(r.alpha_c)),
               kind=jr.KIND_NAMES[int(r.kind)], alpha_c2_deg=float(np.degrees(r.alpha_c2)),
               kind2=jr.KIND_NAMES[int(r.kind2)], separation_deg=float(np.degrees(r.separation)),
               result=jr.result_name(r.result))
    brinks = {}
    for route in ("first", "second"):
        _, tr = jr.snap_dynamics(sc, "up", route=route, snap=snap, rtol=1e-8, atol=1e-8)
        brinks[route] = dict(v_s=float(tr.v_s), result=jr.result_name(tr.result))
    out["brink"] = brinks
    a0 = float(snap.up.alpha_c) - np.radians(2.0)
    reach = float(r.alpha_c2) - a0 + np.radians(6.0)  # past the fold, with room for the lag
    grid = []
    for rate in rates:
        for seed in seeds:
            t1 = reach / rate + 1.0
            # frames dense enough to see the snap itself (it lasts ~0.02 T; a slow ramp runs ~15 T)
            _, tr = jr.snap_dynamics(sc, "up", kind="ramp", rate=rate, seed=seed, snap=snap, t1=t1,
                                     n_frames=N_FRAMES)
            th, tf = np.asarray(tr.theta), np.asarray(tr.t_frames)
            before = np.all(np.isfinite(th), axis=1) & (tf <= float(tr.t_peak))
            asym = float(np.max(np.abs(th[before] + th[before][:, ::-1]))) if before.any() else float("nan")
            ok = tr.result == jr.RESULTS.successful and bool(tr.snapped)
            grid.append(dict(rate=rate, seed=seed, v_s=float(tr.v_s), asymmetry=asym,
                             route=(1 if asym > ASYMMETRIC else 2) if ok else None,
                             alpha_peak_deg=float(np.degrees(a0 + rate * float(tr.t_peak))),
                             result=jr.result_name(tr.result)))
            progress.update(1)
    out["grid"] = grid
    return out


def figure(recs, rates, seeds, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap

    fig, axes = plt.subplots(1, len(recs), figsize=(4.6 * len(recs), 4.2), constrained_layout=True)
    cmap = ListedColormap(["#4c72b0", "#dd8452"])
    for ax, rec in zip(np.atleast_1d(axes), recs):
        R = np.full((len(seeds), len(rates)), np.nan)
        V = np.full_like(R, np.nan)
        for g in rec["grid"]:
            i, j = seeds.index(g["seed"]), rates.index(g["rate"])
            R[i, j] = np.nan if g["route"] is None else g["route"]
            V[i, j] = g["v_s"]
        ax.imshow(R, origin="lower", cmap=cmap, vmin=1, vmax=2, aspect="auto")
        for i in range(len(seeds)):
            for j in range(len(rates)):
                if np.isfinite(V[i, j]):
                    ax.text(j, i, f"{V[i, j]:.1f}", ha="center", va="center", fontsize=7, color="k")
        ax.set_xticks(range(len(rates)), [f"{r:g}" for r in rates])
        ax.set_yticks(range(len(seeds)), [f"{s:.0e}" if s else "0" for s in seeds])
        ax.set_xlabel("ramp rate (rad/T)")
        ax.set_ylabel("imperfection amplitude (rad)")
        ax.set_title(f"Psi0 = {rec['psi0_deg']:g} deg, G/L = {rec['gap']:g}\n"
                     f"branch point {rec['alpha_c_deg']:.2f}, fold {rec['alpha_c2_deg']:.2f} deg", fontsize=9)
    fig.suptitle("snap route of a ramp (blue: asymmetric at the branch point; orange: symmetric at the fold); "
                 "numbers: v_s / v*", fontsize=9)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    n = 24 if args.quick else 48
    rates = [0.03, 0.3, 1.0, 3.0] if args.quick else [0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0]
    seeds = [0.0, 1e-6, 1e-2] if args.quick else [0.0, 1e-10, 1e-8, 1e-6, 1e-4, 1e-2]
    from tqdm import tqdm

    t0 = time.time()
    with tqdm(total=len(STRIPS) * len(rates) * len(seeds), desc="ramps", file=sys.stderr) as bar:
        recs = [run(p, g, n, rates, seeds, bar) for p, g in STRIPS]
    tag = "route_map_quick" if args.quick else "route_map"
    base = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results", tag)
    meta = dict(date=datetime.date.today().isoformat(), machine=platform.platform(), cpus=os.cpu_count(),
                jax=jax.__version__, n=n, rates=rates, seeds=seeds, asymmetric_threshold=ASYMMETRIC,
                wall_s=round(time.time() - t0, 1))
    with open(base + ".json", "w") as f:
        json.dump(dict(meta=meta, strips=recs), f, indent=1)
    figure(recs, rates, seeds, base + ".png")
    lines = [f"# Snap routes of ramped strips (N = {n})", "",
             f"{meta['date']}, {meta['machine']}, {meta['cpus']} cores, jax {meta['jax']}; {meta['wall_s']} s.", "",
             "| Psi0 (deg) | G/L | branch point (deg) | fold (deg) | apart (deg) | brink v_s route 1 | "
             "brink v_s route 2 | ramps on route 1 | slowest ramp on route 2 |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in recs:
        on1 = [g for g in r["grid"] if g["route"] == 1]
        on2 = [g["rate"] for g in r["grid"] if g["route"] == 2 and g["seed"] == 0.0]
        lines.append(f"| {r['psi0_deg']:g} | {r['gap']:g} | {r['alpha_c_deg']:.3f} | {r['alpha_c2_deg']:.3f} | "
                     f"{r['separation_deg']:.3f} | {r['brink']['first']['v_s']:.2f} | "
                     f"{r['brink']['second']['v_s']:.2f} | {len(on1)} of {len(r['grid'])} | "
                     f"{min(on2) if on2 else '-'} rad/T (perfect start) |")
    lines += ["", f"![route map]({tag}.png)", "",
              "Route 1: asymmetric snap at the branch point; route 2: symmetric snap at the fold. A run is "
              f"route 1 when max |theta(s) + theta(L - s)| exceeds {ASYMMETRIC} rad before the speed peak. "
              "Brink: the strip released at each critical point (`jr.brink(..., route=...)`)."]
    with open(base + ".md", "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
