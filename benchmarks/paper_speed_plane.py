"""The paper's speed plane with manufacturing scatter: the coefficients of
v_s / v* = v_m - a G/L - b Psi0 (Psi0 in rad) fitted to the model's brink snaps on the grid
Psi0 = 30-180 deg x G/L = 0.3-0.7, nominal and with every strip of the grid made with a scatter
(Psi0 +- 10 deg, G/L +- 0.02, a clamp misalignment +- 1 deg, each alone and all three), fitted
against the nominal (Psi0, G/L) as an experimenter would; beside the paper's fit to its
experiments (v_m = 42.59 +- 1.33, a = 30.38 +- 2.57, b = 5.00 +- 0.26).

Each scatter is `--draws` independent sets of strips (standard normal deviations, common random
numbers across the scatters: draw d uses the same normals in every scatter). Each point is one
`jaxrod.snap_speed_run` (RATTLE, the brink of the up path) at mesh `--n`; a point that does not
snap or whose run is not successful is left out of its fit, as in `jaxrod.fit_speed_plane`.

    python benchmarks/paper_speed_plane.py [--n 40] [--draws 8]

Writes benchmarks/results/paper_speed_plane.{json,md,png}.
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

import numpy as np  # noqa: E402
from tqdm import tqdm  # noqa: E402

import jaxrod as jr  # noqa: E402
import jaxrod.paper as jp  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_batch import machine_meta  # noqa: E402

OUT = Path(__file__).resolve().parent / "results"
PSIS = (30.0, 60.0, 90.0, 120.0, 180.0)
GAPS = (0.3, 0.4, 0.5, 0.6, 0.7)
PAPER = dict(zip(("v_m", "a", "b"), zip(jp.SPEED_PLANE, (1.33, 2.57, 0.26))))
"""The paper's plane and its standard errors (its Eq. 3)."""
SCATTERS = {
    "Psi0 +- 10 deg": (10.0, 0.0, 0.0),
    "G/L +- 0.02": (0.0, 0.02, 0.0),
    "misalignment +- 1 deg": (0.0, 0.0, 1.0),
    "all three": (10.0, 0.02, 1.0),
}
"""Standard deviations of (Psi0 in deg, G/L, clamp misalignment alpha_L - alpha_R in deg)."""


def speed(psi0_deg, gap, misalignment_deg, n):
    """v_s (v*) of the up path's brink snap; NaN where it does not snap or is not successful."""
    psi0_deg = float(np.clip(psi0_deg, 1.0, 180.0))
    half = 0.5 * misalignment_deg
    run = jr.snap_speed_run(jr.make_scene(psi0_deg, float(gap), half, alpha_right_deg=-half, n=n))
    ok = run.result == jr.RESULTS.successful and np.isfinite(float(run.v_s))
    return float(run.v_s) if ok else math.nan


def fit(psi0_deg, gaps, v):
    """Least squares of v = v_m - a G - b Psi0 (rad) over the finite v: (coefficients, their
    standard errors, RMS residual, points used)."""
    ok = np.isfinite(v)
    A = np.stack([np.ones(ok.sum()), -gaps[ok], -np.radians(psi0_deg[ok])], 1)
    coef, *_ = np.linalg.lstsq(A, v[ok], rcond=None)
    res = A @ coef - v[ok]
    dof = max(int(ok.sum()) - 3, 1)
    cov = (res @ res / dof) * np.linalg.inv(A.T @ A)
    return coef, np.sqrt(np.diag(cov)), float(np.sqrt(np.mean(res**2))), int(ok.sum())


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=40)
    ap.add_argument("--draws", type=int, default=8)
    a = ap.parse_args(argv)
    meta = machine_meta(n=a.n, draws=a.draws, grid=dict(psi0_deg=PSIS, gaps=GAPS))
    P, G = (x.ravel() for x in np.meshgrid(PSIS, GAPS, indexing="ij"))
    nominal_v = np.array([speed(p, g, 0.0, a.n) for p, g in tqdm(zip(P, G), total=P.size, desc="nominal",
                                                                    file=sys.stderr)])
    coef, se, rms, used = fit(P, G, nominal_v)
    rows = {"nominal": dict(coef=coef.tolist(), stderr=se.tolist(), rms=rms, points=used)}
    draws = [np.random.default_rng(d).standard_normal((P.size, 3)) for d in range(a.draws)]
    points = {}
    for name, widths in SCATTERS.items():
        coefs, ses, vs = [], [], []
        for z in tqdm(draws, desc=name, file=sys.stderr):
            dev = z * np.asarray(widths)
            v = np.array([speed(p + d[0], min(max(g + d[1], 0.02), 0.98), d[2], a.n)
                          for p, g, d in zip(P, G, dev)])
            c, s, _, _ = fit(P, G, v)  # against the nominal (Psi0, G/L)
            coefs.append(c)
            ses.append(s)
            vs.append(v)
        coefs, ses, vs = np.array(coefs), np.array(ses), np.array(vs)
        rows[name] = dict(coef_mean=coefs.mean(0).tolist(), coef_std=coefs.std(0, ddof=1).tolist(),
                          stderr_mean=ses.mean(0).tolist(), shift=(coefs.mean(0) - coef).tolist(),
                          shift_sem=(coefs.std(0, ddof=1) / math.sqrt(len(draws))).tolist(),
                          lost=int(np.sum(~np.isfinite(vs)) - len(draws) * np.sum(~np.isfinite(nominal_v))))
        points[name] = vs.tolist()
    res = dict(meta=meta, paper=PAPER, nominal_v=nominal_v.tolist(), psi0_deg=P.tolist(), gaps=G.tolist(),
               fits=rows, points=points)
    OUT.mkdir(exist_ok=True)
    (OUT / "paper_speed_plane.json").write_text(json.dumps(res, indent=1))
    figure(res, OUT / "paper_speed_plane.png")
    write_md(res, OUT / "paper_speed_plane.md")


def figure(res, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    P, G = np.array(res["psi0_deg"]), np.array(res["gaps"])
    v0 = np.array(res["nominal_v"])
    scat = np.array(res["points"]["all three"])
    c = res["fits"]["nominal"]["coef"]
    pv = [PAPER[k][0] for k in ("v_m", "a", "b")]
    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    g_line = np.linspace(0.25, 0.75, 11)
    for k, p in enumerate(PSIS):
        col = f"C{k}"
        sel = P == p
        for v in scat:
            ax.plot(G[sel] + 0.004 * (k - 2), v[sel], ".", color=col, alpha=0.35, ms=4)
        ax.plot(G[sel], v0[sel], "o", color=col, label=f"Psi0 = {p:g} deg (model)")
        ax.plot(g_line, c[0] - c[1] * g_line - c[2] * math.radians(p), "-", color=col, lw=1)
        ax.plot(g_line, pv[0] - pv[1] * g_line - pv[2] * math.radians(p), "--", color=col, lw=1)
    ax.plot([], [], ".", color="0.4", label="strips with all three scatters")
    ax.plot([], [], "-", color="0.4", label="model's plane (nominal)")
    ax.plot([], [], "--", color="0.4", label="paper's plane (experiments)")
    ax.set_xlabel("G / L")
    ax.set_ylabel("v_s / v*")
    ax.set_title(f"Speed plane with scatter (N = {res['meta']['n']}, {res['meta']['draws']} draws)")
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def write_md(res, path):
    f = res["fits"]
    nom = f["nominal"]
    L = ["# The speed plane with scatter, beside the paper's fit", "",
         f"{res['meta']['date']}, {res['meta']['machine']}, jax {res['meta']['jax']}, git {res['meta']['git']}. "
         f"Brink snaps of the up path (`jaxrod.snap_speed_run`, RATTLE) at N = {res['meta']['n']} on Psi0 = "
         f"{', '.join(f'{p:g}' for p in PSIS)} deg x G/L = {', '.join(f'{g:g}' for g in GAPS)}; "
         f"each scatter: {res['meta']['draws']} sets of strips (normal deviations, the same draws in every "
         "scatter), fitted against the nominal (Psi0, G/L). v_s / v* = v_m - a G/L - b Psi0 (rad).", "",
         "![speed plane](paper_speed_plane.png)", "",
         "| fit | v_m | a | b | RMS (v*) | points |", "|---|---:|---:|---:|---:|---:|",
         "| paper (experiments) | " + " | ".join(f"{PAPER[k][0]:.2f} +- {PAPER[k][1]:.2f}" for k in ("v_m", "a", "b"))
         + " | - | - |",
         "| model, nominal strips | " + " | ".join(f"{c:.2f} +- {s:.2f}" for c, s in zip(nom["coef"], nom["stderr"]))
         + f" | {nom['rms']:.2f} | {nom['points']} |"]
    for name in SCATTERS:
        r = f[name]
        L.append(f"| model, {name} (mean +- std over draws) | "
                 + " | ".join(f"{c:.2f} +- {s:.2f}" for c, s in zip(r["coef_mean"], r["coef_std"]))
                 + f" | - | {r['lost']:+d} lost |")
    L += ["", "Shift of the mean coefficients from the nominal fit (+- its standard error over the draws):", "",
          "| scatter | v_m | a | b |", "|---|---:|---:|---:|"]
    for name in SCATTERS:
        r = f[name]
        L.append(f"| {name} | " + " | ".join(f"{s:+.2f} +- {e:.2f}" for s, e in zip(r["shift"], r["shift_sem"])) + " |")
    L += ["", "The discussion of what these numbers explain is in docs/robust.md.", ""]
    path.write_text("\n".join(L))


if __name__ == "__main__":
    main()
