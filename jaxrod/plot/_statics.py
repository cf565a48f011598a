r"""Pictures of equilibria: the strip, its fold and its two clamps (matplotlib).

Matplotlib is imported lazily, inside the functions, so `import jaxrod` stays cheap and
never touches the user's matplotlib backend. Functions that write files draw on an
off-screen Agg canvas of their own (no `pyplot`, no global backend switch).

Clamps follow docs/model.md: the left clamp holds $\mathbf r(0)=(0,0)$ with tangent angle
$\theta(0)=+\alpha_L$, the right clamp holds $\mathbf r(L)=(G,0)$ with
$\theta(L)=-\alpha_R$. Each clamp is drawn as a hatched block lying on the clamp
tangent, outside the strip: behind $s=0$ on the left, beyond $s=L$ on the right.
"""

from __future__ import annotations

import math
import os

import numpy as np

from ..statics import fold_height, node_positions
from ..results import RESULTS

_CLAMP_LENGTH = 0.09  # in units of L
_CLAMP_WIDTH = 0.035


def _clamp_geometry(eq):
    """((x, y), outward unit tangent) for the left and right clamp, in plot units."""
    sc = eq.scene
    L = float(sc.strip.length)
    G = float(sc.clamps.gap)
    aL = float(sc.clamps.alpha_left)
    aR = float(sc.clamps.alpha_right)
    # left: the strip leaves (0,0) along (cos aL, sin aL); the clamp lies behind it
    left = ((0.0, 0.0), (-math.cos(aL), -math.sin(aL)))
    # right: the strip arrives at (G,0) along (cos(-aR), sin(-aR)); the clamp lies beyond it
    right = ((G, 0.0), (math.cos(aR), -math.sin(aR)))
    return L, left, right


def _draw_clamp(ax, origin, direction, L, zorder=3):
    from matplotlib.patches import Polygon

    x0, y0 = origin
    tx, ty = direction
    nx, ny = -ty, tx
    a, w = _CLAMP_LENGTH * L, 0.5 * _CLAMP_WIDTH * L
    corners = np.array([
        [x0 + w * nx, y0 + w * ny],
        [x0 + a * tx + w * nx, y0 + a * ty + w * ny],
        [x0 + a * tx - w * nx, y0 + a * ty - w * ny],
        [x0 - w * nx, y0 - w * ny],
    ])
    ax.add_patch(Polygon(corners, closed=True, facecolor="0.82", edgecolor="0.15", hatch="////",
                         linewidth=1.2, zorder=zorder))
    # the clamped end of the strip, a short thick bar along the clamp tangent
    ax.plot([x0, x0 + a * tx], [y0, y0 + a * ty], color="0.15", linewidth=3.0,
            solid_capstyle="butt", zorder=zorder + 0.1)


def plot_shape(eq, ax=None, label=None, color=None, show_clamps=True):
    r"""Draw the shape of equilibrium `eq` on `ax` (a new figure if `None`).

    Draws the strip through its node positions, marks the fold node ($s=L/2$) (with several
    creases: every crease, and the midpoint smaller) and, with
    `show_clamps`, the two clamps as hatched blocks along the clamp tangents
    ($+\alpha_L$ at $(0,0)$, $-\alpha_R$ at $(G,0)$). Axes are in units of $L$ with equal
    aspect. **Returns:** the axes.
    """
    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=(6.4, 4.8))
    L = float(eq.scene.strip.length)
    xy = np.asarray(node_positions(eq), dtype=float) / L
    mid = eq.scene.mesh.n // 2
    (line,) = ax.plot(xy[:, 0], xy[:, 1], "-", color=color, linewidth=2.2, label=label, zorder=4)
    c = line.get_color()
    if eq.scene.strip.creases is None:
        ax.plot(xy[mid, 0], xy[mid, 1], "o", markersize=8, markerfacecolor=c, markeredgecolor="k",
                markeredgewidth=1.0, zorder=5)
    else:  # every crease at its own arclength (the midpoint stays marked, smaller)
        from ..statics import crease_points

        pts = np.asarray(crease_points(eq), float) / L
        ax.plot(pts[:, 0], pts[:, 1], "o", markersize=8, markerfacecolor=c, markeredgecolor="k",
                markeredgewidth=1.0, zorder=5)
        ax.plot(xy[mid, 0], xy[mid, 1], "o", markersize=3, color="k", zorder=5)
    if show_clamps:
        _, left, right = _clamp_geometry(eq)
        for origin, direction in (left, right):
            _draw_clamp(ax, (origin[0] / L, origin[1] / L), direction, 1.0)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x / L")
    ax.set_ylabel("y / L")
    return ax


def _scene_title(eq):
    sc = eq.scene
    psi0 = math.degrees(float(sc.strip.psi0))
    aL = math.degrees(float(sc.clamps.alpha_left))
    aR = math.degrees(float(sc.clamps.alpha_right))
    G = float(sc.clamps.gap) / float(sc.strip.length)
    alpha = f"α = {aL:g}°" if aL == aR else f"α_L = {aL:g}°, α_R = {aR:g}°"
    if sc.strip.creases is not None:
        L = float(sc.strip.length)
        pos, ang, _ = (np.asarray(v, float) for v in sc.strip.crease_list())
        folds = ", ".join(f"{math.degrees(a):g}° at {c / L:g}" for c, a in zip(pos, ang))
        return f"creases {folds}; G/L = {G:g}, {alpha}"
    return f"Ψ0 = {psi0:g}°, G/L = {G:g}, {alpha}, s0/L = {float(sc.strip.s0) / float(sc.strip.length):g}"


def plot_equilibria(eqs, labels, path, title=None):
    """Write a PNG (or any format matplotlib infers from `path`) with the shapes of
    `eqs`, their clamps, the fold nodes marked, and a legend of fold heights.

    `labels` names each equilibrium (e.g. `["up", "down"]`); `None` numbers them.
    Uses an off-screen Agg canvas; the user's backend is left alone. **Returns:** `path`.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    eqs = list(eqs)
    if labels is None:
        labels = [f"#{i}" for i in range(len(eqs))]
    labels = list(labels)
    if len(labels) != len(eqs):
        raise ValueError(f"labels must have one entry per equilibrium ({len(eqs)}), got {len(labels)}")
    fig = Figure(figsize=(7.0, 5.0), dpi=130)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    ax.axhline(0.0, color="0.6", linewidth=0.8, linestyle=":", zorder=1)
    drawn = set()
    colors = ["tab:red", "tab:blue", "tab:green", "tab:purple", "tab:orange", "tab:brown"]
    for i, (eq, lab) in enumerate(zip(eqs, labels)):
        L = float(eq.scene.strip.length)
        h = float(fold_height(eq)) / L
        ok = bool(eq.result == RESULTS.successful)
        text = f"{lab}: fold height y(L/2) = {h:+.4f} L" + ("" if ok else " [not converged]")
        key = tuple(round(float(v), 12) for v in (eq.scene.clamps.gap / L, eq.scene.clamps.alpha_left,
                                                   eq.scene.clamps.alpha_right))
        plot_shape(eq, ax=ax, label=text, color=colors[i % len(colors)], show_clamps=key not in drawn)
        drawn.add(key)
    handles, _ = ax.get_legend_handles_labels()
    creased = any(eq.scene.strip.creases is not None for eq in eqs)
    handles.append(Line2D([], [], linestyle="none", marker="o", markerfacecolor="white", markeredgecolor="k",
                          markersize=8, label="creases" if creased else "fold (s = L/2)"))
    if creased:
        handles.append(Line2D([], [], linestyle="none", marker="o", color="k", markersize=3, label="s = L/2"))
        # below the axes: several creases' shapes fill the plot
        ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.13), fontsize=8, framealpha=0.9)
        fig.set_size_inches(7.0, 6.4)
    else:
        ax.legend(handles=handles, loc="best", fontsize=9, framealpha=0.9)
    if eqs:
        ax.set_title(title if title is not None else _scene_title(eqs[0]), fontsize=10)
    ax.grid(True, linewidth=0.3, alpha=0.5)
    ax.margins(0.08)
    fig.tight_layout()
    d = os.path.dirname(os.fspath(path))
    if d:
        os.makedirs(d, exist_ok=True)
    fig.savefig(path)
    return path


def _agg_figure(figsize):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, dpi=130)
    FigureCanvasAgg(fig)
    return fig


def _save(fig, path):
    d = os.path.dirname(os.fspath(path))
    if d:
        os.makedirs(d, exist_ok=True)
    fig.savefig(path)
    return path


def plot_hysteresis(h, path, title=None):
    r"""Write the quasi-static loop of a [`jaxrod.Hysteresis`][] `h` to `path`, laid out
    like the paper's Fig. 2a-b (fold height $y(L/2)/L$ vs $\alpha$) with a second panel
    like its Fig. 3c (bending energy $E_b L/B$ of both equilibria vs $\alpha$).

    Branch through the down start state in blue, through the up start state in red;
    stable points solid, unstable dashed; the snaps are arrows at $\alpha_c$ from the
    critical state to the state it lands in. **Returns:** `path`."""
    fig = _agg_figure((11.0, 4.4))
    ax, bx = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    alpha = np.degrees(np.asarray(h.alpha, float))
    fh = np.asarray(h.fold_height, float)
    eb = np.asarray(h.bending_energy, float)
    nu = np.asarray(h.num_unstable)
    valid = np.asarray(h.valid)
    colors = ["tab:blue", "tab:blue", "tab:red", "tab:red"]
    labels = ["from the down state", None, "from the up state", None]
    for b in range(alpha.shape[0]):
        v = valid[b]
        a, y, e, u = alpha[b][v], fh[b][v], eb[b][v], nu[b][v]
        for ys, axis, marker in ((y, ax, None), (e, bx, "o")):
            stable = np.where(u == 0, ys, np.nan)
            unstable = np.where(u > 0, ys, np.nan)
            # join the two styles at the stability change
            for i in range(1, len(u)):
                if (u[i] == 0) != (u[i - 1] == 0):
                    unstable[i - 1 if u[i] == 0 else i - 1] = ys[i - 1]
                    unstable[i] = ys[i]
            axis.plot(a, stable, "-", color=colors[b], linewidth=2.0, marker=marker, markersize=3,
                      label=labels[b] + " (stable)" if labels[b] and axis is ax else None)
            axis.plot(a, unstable, "--", color=colors[b], linewidth=1.2,
                      label=labels[b] + " (unstable)" if labels[b] and axis is ax else None)
    for p, sign, eb0, eb1, name in ((h.snap.up, 1, h.energy_before_up, h.energy_after_up, "snap up"),
                                    (h.snap.down, -1, h.energy_before_down, h.energy_after_down, "snap down")):
        if not bool(p.snaps):
            continue
        ac = math.degrees(float(p.alpha_c))
        y0, y1 = float(p.fold_height_before), float(p.fold_height_after)
        ax.annotate("", xy=(ac, y1), xytext=(ac, y0),
                    arrowprops=dict(arrowstyle="->", color="k", linewidth=1.4))
        ax.text(ac, 0.5 * (y0 + y1), f" {name}\n α_c = {ac:+.2f}°", fontsize=8,
                ha="left" if sign > 0 else "right")
        bx.annotate("", xy=(ac, float(eb1)), xytext=(ac, float(eb0)),
                    arrowprops=dict(arrowstyle="->", color="k", linewidth=1.2))
    ax.axhline(0.0, color="0.6", linewidth=0.8, linestyle=":")
    ax.set_xlabel("α (deg)")
    ax.set_ylabel("fold height y(L/2) / L")
    ax.legend(fontsize=8, loc="upper left")
    bx.set_xlabel("α (deg)")
    bx.set_ylabel("bending energy E_b L / B")
    for axis in (ax, bx):
        axis.grid(True, linewidth=0.3, alpha=0.5)
        lo, hi = np.nanmin(alpha), np.nanmax(alpha)
        axis.set_xlim(max(lo, -150.0) - 5, min(hi, 150.0) + 5)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return _save(fig, path)


def _flagged(ds, direction):
    """Where the `direction` path's angle is a number but its `result_{direction}` is not
    `successful` (a boolean `DataArray` over `ds`'s grid; all False without result codes)."""
    alpha = ds[f"alpha_c_{direction}"]
    name = f"result_{direction}"
    if name not in ds:
        return alpha.notnull() & alpha.isnull()
    return alpha.notnull() & (ds[name] != int(RESULTS.successful._value))


def phase_figure(ds, termination_gaps=None, title=None):
    """The matplotlib `Figure` that [`plot_phase_diagram`][] writes."""
    import matplotlib

    widths = [float(w) for w in ds["s0"].values] if "s0" in ds.dims else [None]
    cols = min(len(widths), 3)
    rows = -(-len(widths) // cols)
    fig = _agg_figure((7.5, 5.5) if len(widths) == 1 else (5.0 * cols, 4.2 * rows + 0.4))
    cmap = matplotlib.colormaps["viridis"]
    psis = np.asarray(ds["psi0"].values, float)
    g = np.asarray(ds["gap"].values, float)
    first = None
    flagged = {d: _flagged(ds, d) for d in ("up", "down")}
    any_flagged = any(bool(f.any()) for f in flagged.values())
    for j, w in enumerate(widths):
        ax = fig.add_subplot(rows, cols, j + 1, sharey=first)
        if first is None:
            first = ax
        sub = ds if w is None else ds.sel(s0=w)
        tg = termination_gaps
        if w is not None and tg and any(isinstance(v, dict) for v in tg.values()):
            tg = tg.get(w)
        for i, psi in enumerate(psis):
            c = cmap(i / max(len(psis) - 1, 1))
            up = np.asarray(sub["alpha_c_up"].sel(psi0=psi).values, float)
            dn = np.asarray(sub["alpha_c_down"].sel(psi0=psi).values, float)
            ku = np.asarray(sub["kind_up"].sel(psi0=psi).values)
            kd = np.asarray(sub["kind_down"].sel(psi0=psi).values)
            # a point whose path is not `successful` (it passes through itself, its outcome is
            # unknown, ...) is drawn apart, never as an ordinary marker on the curve
            bad_up, bad_dn = (np.asarray((f if w is None else f.sel(s0=w)).sel(psi0=psi).values)
                              for f in (flagged["up"], flagged["down"]))
            ax.plot(g, np.where(bad_up, np.nan, up), "o-", color=c, markersize=4, linewidth=1.2,
                    label=f"Ψ0 = {psi:g}°")
            ax.plot(g, np.where(bad_dn, np.nan, dn), "o--", color=c, markersize=4, markerfacecolor="white",
                    linewidth=1.2)
            for y, bad in ((up, bad_up), (dn, bad_dn)):
                ax.plot(g[bad], y[bad], "^", color=c, markersize=6, markerfacecolor="none",
                        markeredgecolor="red", markeredgewidth=1.0)
            for y, k, bad in ((up, ku, bad_up), (dn, kd, bad_dn)):
                bp = (k == 2) & ~bad
                ax.plot(g[bp], y[bp], "x", color="k", markersize=4, linewidth=0.8)
            if tg and psi in tg:
                for gs, ls in zip(tg[psi], ("-.", ":")):
                    if gs is not None and np.isfinite(gs) and gs < 1.0:
                        ax.axvline(gs, color=c, linestyle=ls, linewidth=1.0)
        ax.axhline(0.0, color="0.3", linewidth=0.8)
        ax.set_xlabel("G / L")
        if j % cols == 0:
            ax.set_ylabel("α_c (deg): snap up > 0, snap down < 0")
        ax.grid(True, linewidth=0.3, alpha=0.5)
        if j == 0:
            ax.plot([], [], "o-", color="0.4", markersize=4, label="snap up (filled)")
            ax.plot([], [], "o--", color="0.4", markersize=4, markerfacecolor="white", label="snap down (open)")
            ax.plot([], [], "x", color="k", label="branch point (else fold)")
            if any_flagged:
                ax.plot([], [], "^", color="0.4", markerfacecolor="none", markeredgecolor="red",
                        label="flagged: not successful (result_up/down)")
            if tg:
                ax.plot([], [], "-.", color="0.4", label="G* snap up")
                ax.plot([], [], ":", color="0.4", label="G* snap down")
            ax.legend(fontsize=8, loc="best", ncol=2)
        if w is None:
            ax.set_title(title or "critical clamp angles (symmetric actuation)", fontsize=10)
        else:
            ax.set_title(f"s0/L = {w:g}", fontsize=10)
    if widths[0] is not None:
        fig.suptitle(title or "critical clamp angles (symmetric actuation)", fontsize=10)
    fig.tight_layout()
    return fig


def plot_phase_diagram(ds, path, termination_gaps=None, title=None):
    r"""Write the phase diagram of an `xarray.Dataset` from [`jaxrod.phase_diagram`][]
    like the paper's Fig. 2c: $\alpha_{c,\rm up}$ (above zero, filled circles) and
    $\alpha_{c,\rm down}$ (below zero, open circles) vs $G/L$, one colour per $\Psi_0$;
    branch points marked with a cross; a point whose path is not `successful` (`result_up`,
    `result_down`: a state through itself, an unknown outcome) as a red-edged open triangle, off
    the curve, with its own legend entry. A dataset with an `s0` dimension gets one panel per
    fold width (up to three in a row, on a shared angle axis). `termination_gaps`, a dict
    `{psi0_deg: (G*_up, G*_down)}` (with an `s0` dimension either that, for every panel, or
    `{s0: {psi0_deg: (G*_up, G*_down)}}`, one per panel), adds dashed vertical lines.
    **Returns:** `path`."""
    return _save(phase_figure(ds, termination_gaps, title), path)


def plot_imperfection_sensitivity(sens, path, title=None):
    r"""Write the imperfection sensitivity `sens` (a `jaxrod.design.ImperfectionSensitivity`)
    to `path`: $|\Delta\alpha_c|$ against the amplitude $\epsilon$ on log-log axes, snap up
    and down, each beside its nominal kind's law $C\epsilon^\beta$ (dashed over the range where
    it holds, with the fitted $\beta$ and the predicted one in the legend). Amplitudes whose
    paths are not successful are left out. **Returns:** `path`."""
    fig = _agg_figure((5.6, 4.2))
    ax = fig.add_subplot(1, 1, 1)
    eps = np.asarray(sens.amplitudes, float)
    for d, name, c in ((sens.up, "up", "tab:red"), (sens.down, "down", "tab:blue")):
        ax.loglog(eps, d.change_deg, "o-", color=c, label=f"snap {name} (nominal: {d.nominal_kind})")
        if np.isfinite(d.exponent):
            lo, hi = d.holds
            x = np.geomspace(lo, hi, 20)
            pred = "" if d.predicted is None else f", predicted {d.predicted:.3g}"
            ax.loglog(x, d.coefficient * x ** d.exponent, "--", color="0.3", linewidth=1.0,
                      label=f"$C\\epsilon^{{\\beta}}$, $\\beta$ = {d.exponent:.3f}{pred}")
    unit = "L" if sens.kind == "crease_offset" else "deg"
    ax.set_xlabel(f"imperfection amplitude ({sens.kind.replace('_', ' ')}, {unit})")
    ax.set_ylabel(r"$|\Delta\alpha_c|$ (deg)")
    ax.set_title(title or f"imperfection sensitivity (N = {sens.n})", fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    return path

