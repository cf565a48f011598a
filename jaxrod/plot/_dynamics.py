"""Figures of a dynamic snap (matplotlib, Agg): the paper's Figs. 3a-c and an animated GIF."""

from __future__ import annotations

import os

import numpy as np


def _mpl():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _valid(traj):
    t = np.asarray(traj.t)
    ok = np.isfinite(t) & np.isfinite(np.asarray(traj.fold_height))
    tf = np.asarray(traj.t_frames)
    okf = np.isfinite(np.asarray(traj.speed)).all(axis=1) & (tf <= float(traj.t_end) + 1e-12)
    return ok, okf


def plot_snap(traj, out_dir, *, title=""):
    """Write `fold.png` (fold height and speed vs t), `speed_map.png` (v(s, t), Fig. 3b),
    `energies.png` (bending and kinetic energy vs t, Fig. 3c) and `chrono.png` (shapes,
    Fig. 3a) into `out_dir`. Returns the paths."""
    plt = _mpl()
    os.makedirs(out_dir, exist_ok=True)
    ok, okf = _valid(traj)
    t = np.asarray(traj.t)[ok]
    paths = []

    fig, ax = plt.subplots(2, 1, sharex=True, figsize=(6, 5))
    ax[0].plot(t, np.asarray(traj.fold_height)[ok])
    ax[0].axhline(0, color="k", lw=0.5)
    ax[0].set_ylabel("fold height y(L/2) / L")
    ax[1].plot(t, np.asarray(traj.fold_speed)[ok])
    ax[1].axvline(float(traj.t_peak), color="r", lw=0.5)
    ax[1].set_ylabel("fold speed / v*")
    ax[1].set_xlabel("t / T")
    ax[0].set_title(title)
    paths.append(os.path.join(out_dir, "fold.png"))
    fig.tight_layout()
    fig.savefig(paths[-1], dpi=120)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6, 4))
    tf = np.asarray(traj.t_frames)[okf]
    sp = np.asarray(traj.speed)[okf]
    s = np.linspace(0, 1, sp.shape[1])
    im = ax.pcolormesh(s, tf, sp, shading="auto", cmap="viridis")
    fig.colorbar(im, ax=ax, label="|v| / v*")
    ax.set_xlabel("s / L")
    ax.set_ylabel("t / T")
    ax.set_title("speed map v(s, t)")
    paths.append(os.path.join(out_dir, "speed_map.png"))
    fig.tight_layout()
    fig.savefig(paths[-1], dpi=120)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(t, np.asarray(traj.bending)[ok], label="bending E_b")
    ax.plot(t, np.asarray(traj.kinetic)[ok], label="kinetic E_k")
    # mask first: unused save slots hold inf/NaN, and inf - inf would warn
    ax.plot(t, np.asarray(traj.kinetic)[ok] + np.asarray(traj.potential)[ok] - np.asarray(traj.clamp_work)[ok],
            "k--", lw=0.8, label="E_k + V - W_clamps")
    ax.set_xlabel("t / T")
    ax.set_ylabel("energy / (B/L)")
    ax.legend()
    paths.append(os.path.join(out_dir, "energies.png"))
    fig.tight_layout()
    fig.savefig(paths[-1], dpi=120)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6, 4))
    pos = np.asarray(traj.positions)[okf]
    cmap = plt.get_cmap("plasma")
    for i, p in enumerate(pos):
        ax.plot(p[:, 0], p[:, 1], color=cmap(i / max(len(pos) - 1, 1)), lw=0.8)
    ax.set_aspect("equal")
    ax.set_xlabel("x / L")
    ax.set_ylabel("y / L")
    ax.set_title("chronophotography (early: dark, late: bright)")
    paths.append(os.path.join(out_dir, "chrono.png"))
    fig.tight_layout()
    fig.savefig(paths[-1], dpi=120)
    plt.close(fig)
    return paths


def animate_snap(traj, path, *, fps=20):
    """An animated GIF of the shapes (pillow writer)."""
    plt = _mpl()
    from matplotlib.animation import FuncAnimation, PillowWriter

    _, okf = _valid(traj)
    pos = np.asarray(traj.positions)[okf]
    tf = np.asarray(traj.t_frames)[okf]
    fig, ax = plt.subplots(figsize=(5, 4))
    lo, hi = pos.reshape(-1, 2).min(0) - 0.05, pos.reshape(-1, 2).max(0) + 0.05
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    (line,) = ax.plot([], [], "b-", lw=2)
    txt = ax.set_title("")

    def update(i):
        line.set_data(pos[i, :, 0], pos[i, :, 1])
        txt.set_text(f"t = {tf[i]:.4f} T")
        return line, txt

    anim = FuncAnimation(fig, update, frames=len(pos), blit=False)
    anim.save(path, writer=PillowWriter(fps=fps))
    plt.close(fig)
    return path


def animate_actuation(act, path, *, fps=20):
    """An animated GIF of an actuation run (`jaxrod.actuate`): the strip, the balls (circles,
    labelled) and the time; pillow writer."""
    plt = _mpl()
    from matplotlib.animation import FuncAnimation, PillowWriter
    from matplotlib.patches import Circle

    tf = np.asarray(act.t_frames)
    t_end = float(np.max(np.where(np.isfinite(np.asarray(act.t)), np.asarray(act.t), 0.0)))
    ok = tf <= t_end
    pos, balls, tf = np.asarray(act.positions)[ok], np.asarray(act.ball_frames)[ok], tf[ok]
    radius = np.asarray(act.ball_radius)
    # the strip over the whole run and the balls where they start (a launched ball leaves the view)
    pts = np.concatenate([pos.reshape(-1, 2), balls[0] - radius[:, None], balls[0] + radius[:, None]], 0)
    lo, hi = pts.min(0) - 0.1, pts.max(0) + 0.1
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    (line,) = ax.plot([], [], "b-", lw=2)
    circles = [ax.add_patch(Circle(balls[0, m], radius[m], color=f"C{m + 1}", alpha=0.8)) for m in range(radius.size)]
    labels = [ax.text(*balls[0, m], name, ha="center", va="center", fontsize=7, clip_on=True)
              for m, name in enumerate(act.names)]
    txt = ax.set_title("")

    def update(i):
        line.set_data(pos[i, :, 0], pos[i, :, 1])
        for m, (c, lab) in enumerate(zip(circles, labels)):
            c.center = balls[i, m]
            lab.set_position(balls[i, m])
        txt.set_text(f"t = {tf[i]:.3f} T")
        return [line, txt, *circles, *labels]

    anim = FuncAnimation(fig, update, frames=len(pos), blit=False)
    anim.save(path, writer=PillowWriter(fps=fps))
    plt.close(fig)
    return path
