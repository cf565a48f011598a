r"""The paper's speed plane (its Eq. 3, Figs. 3d-e): the snapping speed of the brink snap up
over the fold angle and the gap, $v_s/v^\ast = v_m - a\,G/L - b\,\Psi_0$ ($\Psi_0$ in radians),
fitted to a grid of snaps and drawn beside the paper's plane. `jaxrod speed-plane` and
`jaxrod reproduce` report both."""

from __future__ import annotations

import math

import numpy as np

SPEED_PLANE = (42.59, 30.38, 5.00)
"""The paper's plane $(v_m, a, b)$: $v_s/v^\\ast = v_m - a\\,G/L - b\\,\\Psi_0$ ($\\Psi_0$ in
radians), fitted to experiments on PET strips."""


def fit_plane(rows):
    """Least-squares $v_s = v_m - a G - b \\Psi_0$ ($\\Psi_0$ in rad) over the snapping rows
    (dicts with `psi0_deg`, `gap`, `snaps`, `v_s`); returns `(v_m, a, b)`, their standard
    errors, and the rms residual."""
    r = [x for x in rows if x["snaps"] and x["v_s"] is not None and math.isfinite(x["v_s"])]
    G = np.array([x["gap"] for x in r])
    P = np.radians([x["psi0_deg"] for x in r])
    v = np.array([x["v_s"] for x in r])
    A = np.stack([np.ones_like(G), -G, -P], 1)
    coef, *_ = np.linalg.lstsq(A, v, rcond=None)
    res = v - A @ coef
    dof = max(len(v) - 3, 1)
    cov = np.linalg.inv(A.T @ A) * (res @ res) / dof
    return coef.tolist(), np.sqrt(np.diag(cov)).tolist(), float(np.sqrt(np.mean(res**2)))


def plot_plane(rows, coef, path):
    """Draw the snapping rows (points), the plane `coef` = `(v_m, a, b)` through them (solid)
    and the paper's `SPEED_PLANE` (dotted), one colour per fold angle, to the image `path`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    psis = sorted({r["psi0_deg"] for r in rows})
    g = np.linspace(0.25, 0.75, 20)
    vm, a, b = SPEED_PLANE
    for i, p in enumerate(psis):
        r = sorted([x for x in rows if x["psi0_deg"] == p and x["snaps"]], key=lambda x: x["gap"])
        c = f"C{i}"
        ax.plot([x["gap"] for x in r], [x["v_s"] for x in r], "o", color=c, label=f"Psi0 = {p:g} deg")
        ax.plot(g, coef[0] - coef[1] * g - coef[2] * np.radians(p), "-", color=c, lw=0.8)
        ax.plot(g, vm - a * g - b * np.radians(p), ":", color=c, lw=0.8)
    ax.set_xlabel("G / L")
    ax.set_ylabel("v_s / v*")
    ax.set_title("brink snaps: points; fit (solid); paper's plane (dotted)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
