"""The paper's Fig. 2c with manufacturing scatter: alpha_c against G/L for Psi0 = 30, 60, 90 and
120 deg, each with the band that a +-10 deg scatter of the fold angle gives (the 10-90 %
quantiles of `jaxrod.design.scatter_statistics`), beside the paper's measured snap angles at
Psi0 ~ 60 deg, G/L = 0.5 (+73.6 deg up, -80 deg down); and what the offsets between model and
experiment there would take: the scatter of each parameter, a crease off centre (the branch
point's eps^(2/3) law), and the first-order shifts of alpha_c in G/L, s0 and Psi0.

    python benchmarks/paper_bands.py [--n 60] [--samples 48]

Writes benchmarks/results/paper_bands.{png,json,md}.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from tqdm import tqdm  # noqa: E402

import jaxrod as jr  # noqa: E402
import jaxrod.design as jd  # noqa: E402
from jaxrod.design._critical import design_scene  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_batch import machine_meta  # noqa: E402

OUT = Path(__file__).resolve().parent / "results"
PSIS = (30.0, 60.0, 90.0, 120.0)
GAPS = (0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8)
PAPER = dict(psi0=60.0, gap=0.5, up=73.6, down=-80.0)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=60)
    ap.add_argument("--samples", type=int, default=48)
    a = ap.parse_args(argv)
    meta = machine_meta(n=a.n, samples=a.samples, scatter="Psi0 +- 10 deg (normal)")
    sc = jd.Scatter(psi0_deg=10.0)
    bands = {}
    for p in tqdm(PSIS, desc="fold angles", file=sys.stderr):
        for g in GAPS:
            st = jd.scatter_statistics(p, g, scatter=sc, samples=a.samples, n=a.n, levels=(0.1, 0.5, 0.9))
            nom = jr.snap_angles(design_scene(math.radians(p), g, 0.02, a.n))
            bands[f"{p}/{g}"] = {d: dict(nominal=math.degrees(float(getattr(nom, d).alpha_c))
                                         if bool(getattr(nom, d).snaps) else None,
                                         nominal_result=jr.results.result_name(getattr(nom, d).result),
                                         q10=float(getattr(st, d).quantiles[0]), q50=float(getattr(st, d).quantiles[1]),
                                         q90=float(getattr(st, d).quantiles[2]), num_ok=getattr(st, d).num_ok,
                                         num_snapping=getattr(st, d).num_snapping)
                                 for d in ("up", "down")}
    # the experiment's point: the model (extrapolated, N and 2N), its first-order shifts, the scatter's spread
    n2 = 2 * a.n
    x = jnp.array([math.radians(PAPER["psi0"]), PAPER["gap"], 0.02])
    ext = jr.snap_angles_extrapolated(design_scene(x[0], x[1], x[2], n2))
    model = dict(up=math.degrees(float(ext.up.alpha_c)), down=math.degrees(float(ext.down.alpha_c)))
    J = jax.jacfwd(lambda v: jnp.rad2deg(jnp.stack([(r := jr.snap_angles(design_scene(v[0], v[1], v[2], n2))).up.alpha_c,
                                                   r.down.alpha_c])))(x)
    J = np.asarray(J) * np.array([math.pi / 180, 1.0, 1.0])[None, :]  # per deg of Psi0, per unit G/L and s0
    spread = {}
    for name, s in (("psi0 +- 10 deg", jd.Scatter(psi0_deg=10.0)), ("G/L +- 0.02", jd.Scatter(gap=0.02)),
                    ("s0 +- 0.01", jd.Scatter(s0=0.01))):
        st = jd.scatter_statistics(PAPER["psi0"], PAPER["gap"], scatter=s, samples=a.samples, n=n2, extrapolate=True)
        spread[name] = dict(up_std=st.up.std, down_std=st.down.std, up_mean=st.up.mean, down_mean=st.down.mean)
    imp = jd.imperfection_sensitivity(PAPER["psi0"], PAPER["gap"], "crease_offset", n=n2)
    off_up = PAPER["up"] - model["up"]
    eps_up = (abs(off_up) / imp.up.coefficient) ** (1 / imp.up.exponent)
    down_at_eps = imp.down.coefficient * eps_up ** imp.down.exponent
    res = dict(bands=bands, model=model, paper=PAPER, jacobian_deg=J.tolist(), spread=spread,
               offset_up=off_up, offset_down=PAPER["down"] - model["down"], crease_offset_for_up=eps_up,
               down_shift_at_that_offset=down_at_eps, offset_law=dict(C=imp.up.coefficient, beta=imp.up.exponent))
    meta["load_average_end"] = os.getloadavg()
    (OUT / "paper_bands.json").write_text(json.dumps(dict(meta=meta, results=res), indent=1, default=float))
    _figure(bands, a.n)
    lines = ["# The paper's Fig. 2c with scatter, and what the offsets at G/L = 0.5 would take", "",
             f"{meta['date']}, {meta['machine']}, jax {meta['jax']}, git {meta['git']}. Bands: the 10-90 % quantiles "
             f"of alpha_c over {a.samples} members with Psi0 +- 10 deg (normal), N = {a.n}; points at N = {n2} "
             "(extrapolated from N and 2N where marked).", "",
             "![alpha_c against G/L with bands](paper_bands.png)", "",
             f"At Psi0 = 60 deg, G/L = 0.5, s0 = 0.02 L the model gives alpha_c = {model['up']:+.2f} deg up and "
             f"{model['down']:+.2f} deg down (extrapolated); the paper measures {PAPER['up']:+.1f} and "
             f"{PAPER['down']:+.1f}: offsets {off_up:+.2f} and {PAPER['down'] - model['down']:+.2f} deg.", "",
             "| what | alpha_c up (deg) | alpha_c down (deg) |", "|---|---:|---:|",
             *[f"| spread (std) under {k} | {v['up_std']:.3f} | {v['down_std']:.3f} |" for k, v in spread.items()],
             f"| first-order shift per +1 deg of Psi0 | {J[0, 0]:+.3f} | {J[1, 0]:+.3f} |",
             f"| first-order shift per +0.01 of G/L | {0.01 * J[0, 1]:+.3f} | {0.01 * J[1, 1]:+.3f} |",
             f"| first-order shift per +0.005 L of s0 | {0.005 * J[0, 2]:+.3f} | {0.005 * J[1, 2]:+.3f} |",
             f"| crease {eps_up:.2e} L off centre (C eps^beta, beta = {imp.up.exponent:.3f}) | {off_up:+.2f} | "
             f"{down_at_eps:+.4f} (magnitude) |", ""]
    (OUT / "paper_bands.md").write_text("\n".join(lines))
    print("\n".join(lines))


def _figure(bands, n):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7, 4.6))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    flagged = [False]
    for k, p in enumerate(PSIS):
        c = f"C{k}"
        for d, style in (("up", "-"), ("down", "--")):
            rows = [bands[f"{p}/{g}"][d] for g in GAPS]
            nom = np.array([np.nan if r["nominal"] is None else r["nominal"] for r in rows])
            bad = np.array([r["nominal_result"] != "successful" for r in rows])
            lo = np.array([r["q10"] for r in rows])
            hi = np.array([r["q90"] for r in rows])
            ax.fill_between(GAPS, lo, hi, color=c, alpha=0.25, linewidth=0)
            ax.plot(GAPS, np.where(bad, np.nan, nom), style, color=c, label=f"Psi0 = {p:g} deg" if d == "up" else None)
            ax.plot(np.asarray(GAPS)[bad], nom[bad], "^", color=c, markerfacecolor="none", markeredgecolor="red")
            flagged[0] |= bool(bad.any())
    if flagged[0]:
        ax.plot([], [], "^", color="0.4", markerfacecolor="none", markeredgecolor="red",
                label="not successful (passes through itself: contact-free model)")
    ax.plot([PAPER["gap"]] * 2, [PAPER["up"], PAPER["down"]], "k*", markersize=10, label="paper's experiment (Psi0 ~ 60 deg)")
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xlabel("G / L")
    ax.set_ylabel("alpha_c (deg): up (solid), down (dashed)")
    ax.set_title(f"snap angles with the 10-90 % band of Psi0 +- 10 deg (N = {n})", fontsize=10)
    ax.legend(fontsize=8, loc="center left")
    fig.tight_layout()
    fig.savefig(OUT / "paper_bands.png", dpi=120)


if __name__ == "__main__":
    main()
