r"""`jaxrod reproduce`: the paper's results beside jaxrod's, as a Markdown report + figures
(`run`; the command line's `jaxrod reproduce --out DIR` calls it).

The report is a list of *sections*; each computes its numbers (cached in `DIR/cache.json`
point by point, so an interrupted run resumes), returns Markdown and table rows
(quantity, paper, jaxrod, note), and may draw figures. Nothing is fitted to the paper.
Dynamic snaps also keep their trajectories in `DIR/traj/*.npz` (for the figures).

Defaults: the strip of docs/model.md ($L=B=\lambda=1$, $s_0=0.02$), symmetric actuation.
Statics mesh: $N=200$ ($N=60$ with `quick`); the critical angles converge as $N^{-2}$
($\approx 1000^\circ/N^2$). Dynamics (`dynamics_config`): brink snaps with `jr.snap_dynamics`,
$N=100$, jaxrod's default integrator (RATTLE at its automatic step, v_s error 1.7e-5 at
N = 100 against a converged reference, benchmarks/results/dynamics.md), the speed plane on
$\Psi_0\in\{30,60,90,120,180\}^\circ\times G/L\in\{0.3,\dots,0.7\}$ ($N=60$, a 4 x 3
grid with `quick`). A config with `solver="tsit5"` and `rtol` runs adaptive Tsit5 instead.
"""

from __future__ import annotations

import datetime
import json
import math
import os
import platform
import sys
import time

import numpy as np


class _Cache:
    """The computed points of a run (`DIR/cache.json`), so that an interrupted run resumes
    without computing them again. They hold for the code that computed them: the file
    records a digest of jaxrod's source (`SOURCE_KEY`), and a cache written by other code is
    dropped, with the trajectories it keeps beside it (`DIR/traj/`)."""

    SOURCE_KEY = "__jaxrod_source__"

    def __init__(self, path):
        from .._misc import source_digest

        self.path = path
        self.digest = source_digest()
        self.data = {}
        if os.path.exists(path):
            try:
                with open(path) as f:
                    self.data = json.load(f)
            except (OSError, ValueError):
                self.data = {}
        if self.data.get(self.SOURCE_KEY) != self.digest:
            self.data = {self.SOURCE_KEY: self.digest}
            traj = os.path.join(os.path.dirname(path), "traj")
            if os.path.isdir(traj):
                for name in os.listdir(traj):
                    if name.endswith(".npz"):
                        os.remove(os.path.join(traj, name))

    def get(self, key, fn):
        if key not in self.data:
            self.data[key] = fn()
            tmp = self.path + ".tmp"
            with open(tmp, "w") as f:
                json.dump(self.data, f)
            os.replace(tmp, self.path)
        return self.data[key]


def _deg(x):
    """Radians (array) to degrees, None where not finite (no snap)."""
    x = float(x)
    return math.degrees(x) if math.isfinite(x) else None


def _scene(psi0_deg, gap, n, s0):
    import jax.numpy as jnp

    from ..design import design_scene

    return design_scene(jnp.deg2rad(psi0_deg), gap, s0, n)


def _snap_record(psi0_deg, gap, n, s0=0.02):
    import jaxrod as jr

    r = jr.snap_angles(_scene(psi0_deg, gap, n, s0))
    return {"alpha_up": _deg(r.up.alpha_c), "alpha_down": _deg(r.down.alpha_c),
            "kind_up": jr.KIND_NAMES[int(r.up.kind)], "kind_down": jr.KIND_NAMES[int(r.down.kind)],
            "start_up": str(jr.RESULTS[r.up.start_result] or "successful"),
            "start_down": str(jr.RESULTS[r.down.start_result] or "successful"),
            "result_up": str(jr.RESULTS[r.up.result] or "successful"),
            "result_down": str(jr.RESULTS[r.down.result] or "successful")}


def _fmt(x, spec="+.2f"):
    return "none (no snap)" if x is None else format(x, spec) + " deg"


def _extrapolated_record(psi0_deg, gap, n, s0=0.02):
    import jaxrod as jr

    x = jr.snap_angles_extrapolated(_scene(psi0_deg, gap, n, s0))
    return {"alpha_up": _deg(x.up.alpha_c), "alpha_down": _deg(x.down.alpha_c),
            "error_up": _deg(x.up.error), "error_down": _deg(x.down.error),
            "alpha_up_mesh": _deg(x.up.alpha_c_coarse), "alpha_down_mesh": _deg(x.down.alpha_c_coarse),
            "kind_up": jr.KIND_NAMES[int(x.up.kind)], "kind_down": jr.KIND_NAMES[int(x.down.kind)]}


def section_snap_angles(cache, n, out, progress):
    a = cache.get(f"snap-extrapolated/60/0.5/{n}", lambda: _extrapolated_record(60.0, 0.5, n))

    def note(d):
        err = "unknown" if a[f"error_{d}"] is None else f"{a[f'error_{d}']:.1e} deg"
        return f"kind: {a[f'kind_{d}']}; N = {n} mesh alone: {_fmt(a[f'alpha_{d}_mesh'], '+.3f')}; " \
               f"estimated error of the {2 * n}-mesh value {err} (the extrapolated one is far smaller)"

    rows = [("alpha_c up, Psi0 = 60 deg, G/L = 0.5", "73.6 deg", _fmt(a["alpha_up"], "+.4f"), note("up")),
            ("alpha_c down, Psi0 = 60 deg, G/L = 0.5", "-80 deg", _fmt(a["alpha_down"], "+.4f"),
             note("down") + "; the paper's snap-down jump is the smaller one")]
    text = ("Critical clamp angles of the default strip under symmetric rotation, Richardson-extrapolated "
            f"from N = {n} and {2 * n} (`jaxrod.snap_angles_extrapolated`). The paper's values are experiments "
            "on PET strips; jaxrod's are the planar Kirchhoff model with s0 = 0.02 L.")
    return "Snap angles at Psi0 = 60 deg, G/L = 0.5", text, rows, a


def section_no_snap(cache, n, out, progress):
    a = cache.get(f"snap/30/0.8/{n}", lambda: _snap_record(30.0, 0.8, n))
    snaps = [d for d in ("up", "down") if a[f"alpha_{d}"] is not None]
    rows = [("snapping at Psi0 = 30 deg, G/L = 0.8", "none in either direction",
             "none" if not snaps else "snaps " + " and ".join(snaps),
             f"up path: {_fmt(a['alpha_up'])}; down path: {_fmt(a['alpha_down'])}; "
             f"down state at alpha = 0: {a['start_up']}")]
    return "No snap at Psi0 = 30 deg, G/L = 0.8", "Smooth transition expected (paper).", rows, a


def _loop_record(psi0_deg, gap, n, s0=0.02):
    """The two quasi-static paths of `jr.snap_angles` (stable continuation stages up to the
    snap: alpha in deg, fold height) and the jumps (fold height before -> after)."""
    import jaxrod as jr

    r = jr.snap_angles(_scene(psi0_deg, gap, n, s0), continue_after_snap=True)
    rec = {}
    for d, p in (("up", r.up), ("down", r.down)):
        br = p.branch
        stages = []
        for k in range(int(np.asarray(br.count).shape[0])):
            c = int(br.count[k])
            if c > 0:
                stages.append({"alpha_deg": np.degrees(np.asarray(br.lam[k, :c])).round(5).tolist(),
                               "fold_height": np.asarray(br.fold_height[k, :c]).round(6).tolist(),
                               "unstable": np.asarray(br.num_unstable[k, :c]).astype(int).tolist()})
        snaps = bool(p.snaps)
        rec[d] = {"snaps": snaps, "alpha_c": _deg(p.alpha_c) if snaps else None, "stages": stages,
                  "kind": jr.KIND_NAMES[int(p.kind)],
                  "before": float(p.fold_height_before) if snaps else None,
                  "after": float(p.fold_height_after) if snaps else None}
    return rec


def section_loops(cache, n, out, progress):
    """Figs. 2a-b: fold height against alpha on both quasi-static paths at Psi0 = 60 deg,
    G/L = 0.5 and Psi0 = 30 deg, G/L = 0.8 (`jr.snap_angles`' continuation branches)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    cases = [(60.0, 0.5), (30.0, 0.8)]
    recs = {c: cache.get(f"loop/{c[0]:g}/{c[1]:g}/{n}", lambda c=c: _loop_record(*c, n)) for c in cases}
    fig = Figure(figsize=(10, 3.8))
    FigureCanvasAgg(fig)
    for i, (c, rec) in enumerate(recs.items()):
        ax = fig.add_subplot(1, 2, i + 1)
        for d, col, lab in (("up", "C0", "snap-up path (from the down state)"),
                            ("down", "C3", "snap-down path (from the up state)")):
            for k, st in enumerate(rec[d]["stages"]):
                a, y, u = (np.asarray(st[key]) for key in ("alpha_deg", "fold_height", "unstable"))
                ax.plot(np.where(u == 0, a, np.nan), y, "-", color=col, label=lab if k == 0 else None)
                ax.plot(np.where(u > 0, a, np.nan), y, ":", color=col, lw=0.8)
            if rec[d]["snaps"]:
                ax.annotate("", (rec[d]["alpha_c"], rec[d]["after"]), (rec[d]["alpha_c"], rec[d]["before"]),
                            arrowprops=dict(arrowstyle="->", color=col))
        ax.axhline(0, color="k", lw=0.4)
        ax.set_xlabel("alpha (deg)")
        ax.set_ylabel("fold height y(L/2) / L")
        ax.set_title(f"Psi0 = {c[0]:g} deg, G/L = {c[1]:g} (N = {n})", fontsize=9)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "fig2ab_loops.png"), dpi=110)
    a = recs[(60.0, 0.5)]
    rows = []
    if a["up"]["snaps"] and a["down"]["snaps"]:
        ju, jd = abs(a["up"]["after"] - a["up"]["before"]), abs(a["down"]["after"] - a["down"]["before"])
        rows.append(("fold-height jump, snap up vs snap down, Psi0 = 60 deg, G/L = 0.5",
                     "snap down: the smaller jump", f"{ju:.3f} L up, {jd:.3f} L down",
                     "snap down smaller" if jd < ju else "snap down NOT smaller"))
    b = recs[(30.0, 0.8)]
    rows.append(("Psi0 = 30 deg, G/L = 0.8: fold height along alpha", "smooth, both directions",
                 "smooth (no loss of stability)" if not (b["up"]["snaps"] or b["down"]["snaps"]) else "snaps", ""))
    text = ("Fold height on the two quasi-static paths (stable: solid, unstable: dotted; arrows: the snaps, "
            f"from the critical state to where it lands), N = {n}. ![loops](fig2ab_loops.png)")
    return "Quasi-static loops (Figs. 2a-b)", text, rows, {f"{c[0]:g}/{c[1]:g}": {
        d: {k: v for k, v in r[d].items() if k != "stages"} for d in ("up", "down")} for c, r in recs.items()}


def section_master_curves(cache, n, out, progress, quick=False):
    psis = (30.0, 60.0, 90.0, 180.0) if quick else (30.0, 45.0, 60.0, 90.0, 120.0, 180.0)
    gaps = np.round(np.linspace(0.1, 0.9, 5 if quick else 17), 4)
    pts = [(p, float(g)) for p in psis for g in gaps]
    it = pts
    if progress:
        from tqdm.auto import tqdm

        it = tqdm(pts, desc="master curves", unit="pt", file=sys.stderr, leave=False)
    data = {}
    for p, g in it:
        data[(p, g)] = cache.get(f"snap/{p}/{g}/{n}", lambda p=p, g=g: _snap_record(p, g, n))
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7, 4.2))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    rows = []
    flagged_any = False
    for k, p in enumerate(psis):
        up = [data[(p, float(g))]["alpha_up"] for g in gaps]
        dn = [data[(p, float(g))]["alpha_down"] for g in gaps]
        c = f"C{k}"
        # a path that is not successful (a state through itself, an unknown outcome) is drawn
        # apart from the curve, as a red-edged open triangle
        for vals, key, style in ((up, "result_up", "o-"), (dn, "result_down", "s--")):
            bad = np.array([data[(p, float(g))].get(key, "successful") != "successful" and v is not None
                            for g, v in zip(gaps, vals)])
            y = np.array([np.nan if v is None else v for v in vals], float)
            flagged_any |= bool(bad.any())
            ax.plot(gaps, np.where(bad, np.nan, y), style, color=c,
                    label=f"Psi0 = {p:g} deg" if key == "result_up" else None)
            ax.plot(np.asarray(gaps)[bad], y[bad], "^", color=c, markerfacecolor="none", markeredgecolor="red")
        last_up = max([float(g) for g, v in zip(gaps, up) if v is not None], default=None)
        last_dn = max([float(g) for g, v in zip(gaps, dn) if v is not None], default=None)
        rows.append((f"largest sampled G/L that snaps, Psi0 = {p:g} deg", "grows with Psi0; never ends at 180",
                     f"up {last_up}, down {last_dn}", ""))
        if p == 180.0:
            sym = max(abs(u + d) for u, d in zip(up, dn) if u is not None and d is not None)
            rows.append(("flat strip symmetric: max abs(alpha_up + alpha_down)", "0", f"{sym:.2e} deg", ""))
    ax.set_xlabel("G / L")
    ax.set_ylabel("alpha_c (deg): up (solid), down (dashed)")
    ax.axhline(0, color="k", lw=0.5)
    if flagged_any:
        ax.plot([], [], "^", color="0.4", markerfacecolor="none", markeredgecolor="red",
                label="flagged: not successful (e.g. passes through itself)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "master_curves.png"), dpi=120)
    text = (f"alpha_c against G/L for several fold angles (N = {n}); branches that stop snapping end "
            "at the termination gap G*(Psi0). Red-edged open triangles: paths that are not successful (at "
            "small gaps the contact-free strip passes through itself; `jaxrod snap-angles` models self-contact "
            "there). ![master curves](master_curves.png)")
    return "Master curves and termination gap", text, rows, {f"{p}/{g}": v for (p, g), v in data.items()}


# ---------------------------------------------------------------------------------------------
# Dynamics (Figs. 1c, 3a-e, 4). Every run goes through `jr.snap_dynamics` with the same static
# arguments (tolerances, t1 and frame windows passed as arrays, stop at the first overshoot), so
# one compile of `jr.simulate` per mesh serves all of them.

_T1 = 4.0  # time limit in T; every brink snap here ends (first overshoot) before 1.6 T
_N_FRAMES = 64
# PET (docs/model.md): L = 20 cm, t = 80-250 um, E ~ 4-5 GPa, rho ~ 1380 kg/m^3. v* = (t/L) sqrt(E/(12 rho))
# does not depend on the width.
_PET = dict(youngs_modulus=4.5e9, density=1380.0, width=0.02, length=0.2)
_PET_THICKNESS = (80e-6, 250e-6)


def dynamics_config(quick):
    """Mesh, tolerance and speed-plane grid of the dynamics sections."""
    if quick:
        return dict(n=60, solver="rattle", psis=(30.0, 60.0, 90.0, 180.0), gaps=(0.3, 0.5, 0.7))
    return dict(n=100, solver="rattle", psis=(30.0, 60.0, 90.0, 120.0, 180.0), gaps=(0.3, 0.4, 0.5, 0.6, 0.7))


def _rattle(cfg):
    return cfg.get("solver", "rattle") == "rattle"


def _dyn_tag(cfg):
    """The solver's part of the cache keys ("rattle", or Tsit5's rtol as before)."""
    return "rattle" if _rattle(cfg) else f"{cfg['rtol']:g}"


def _dyn_words(cfg):
    """The integrator, in the report's words."""
    if _rattle(cfg):
        return "RATTLE, jaxrod's default symplectic integrator, at its default step"
    return f"Tsit5 rtol = atol = {cfg['rtol']:g}"


def _run_kwargs(cfg, window=None):
    import jax.numpy as jnp

    w = (0.0, _T1) if window is None else window
    kw = dict(stop_at_snap=True, n_frames=_N_FRAMES, frame_window=(jnp.asarray(float(w[0])), jnp.asarray(float(w[1]))))
    if _rattle(cfg):  # t1 a Python number: RATTLE samples every (macro) step and sizes max_steps from it
        return dict(solver="rattle", t1=float(_T1), **kw)
    return dict(solver="tsit5", rtol=jnp.asarray(cfg["rtol"]), atol=jnp.asarray(cfg["rtol"]), t1=jnp.asarray(_T1), **kw)


_TRAJ_FIELDS = ("t", "fold_height", "fold_speed", "bending", "potential", "kinetic", "clamp_work",
                "t_frames", "positions", "speed", "v_s", "t_peak", "t_cross", "t_end")


def _traj_arrays(tr):
    return {k: np.asarray(getattr(tr, k)) for k in _TRAJ_FIELDS}


class _Traj:
    """A stored trajectory (the fields `jaxrod.plot.plot_snap` reads)."""

    def __init__(self, d):
        for k in _TRAJ_FIELDS:
            setattr(self, k, d[k])


def _cached_traj(out, key, fn):
    """(record, trajectory arrays) of `fn()`, kept in `out/traj/<key>.npz` for a resumed run."""
    path = os.path.join(out, "traj", key.replace("/", "_") + ".npz")
    if os.path.exists(path):
        try:
            with np.load(path) as z:
                d = {k: z[k] for k in z.files}
            return json.loads(str(d.pop("record"))), _Traj(d)
        except (OSError, ValueError, KeyError):
            pass
    rec, arrays = fn()
    os.makedirs(os.path.dirname(path), exist_ok=True)
    tmp = path + ".tmp.npz"
    np.savez_compressed(tmp, record=json.dumps(rec), **arrays)
    os.replace(tmp, path)
    return rec, _Traj(arrays)


def _dyn_record(start, tr):
    from .._records import snap_record

    return snap_record(start, tr)


def _vs_record(psi0_deg, gap, cfg):
    """Brink snap up of (Psi0, G/L) (`jr.snap_dynamics(kind="brink")`), or {"snaps": False}
    where the quasi-static up path does not snap."""
    import jaxrod as jr

    scene = _scene(psi0_deg, gap, cfg["n"], 0.02)
    snap = jr.snap_angles(scene)
    if not bool(snap.up.snaps):
        return {"snaps": False, "kind": jr.KIND_NAMES[int(snap.up.kind)]}
    start, tr = jr.snap_dynamics(scene, "up", kind="brink", snap=snap, **_run_kwargs(cfg))
    rec = _dyn_record(start, tr)
    rec.update(snaps=bool(tr.snapped), kind=jr.KIND_NAMES[int(snap.up.kind)])
    return rec


def _vs_key(p, g, cfg):
    return f"vs/{p:g}/{g:g}/{cfg['n']}/{_dyn_tag(cfg)}"


def _vs(cache, p, g, cfg):
    return cache.get(_vs_key(p, g, cfg), lambda: _vs_record(p, g, cfg))


def _snap_window(rec):
    dur = rec.get("snap_duration") or 0.05
    return max(0.0, rec["t_peak"] - 4.0 * dur), rec["t_end"]


def _framed_snap(cache, out, p, g, cfg):
    """The brink snap of (p, g) rerun with its frames on the snap (a few durations before
    the peak to the first overshoot): (record, trajectory)."""
    rec = _vs(cache, p, g, cfg)
    if not rec.get("snaps"):
        return rec, None

    def fn():
        import jaxrod as jr

        scene = _scene(p, g, cfg["n"], 0.02)
        start, tr = jr.snap_dynamics(scene, "up", kind="brink", **_run_kwargs(cfg, _snap_window(rec)))
        r = _dyn_record(start, tr)
        r["kind"] = rec.get("kind")
        return r, _traj_arrays(tr)

    return _cached_traj(out, f"snap/{p:g}/{g:g}/{cfg['n']}/{_dyn_tag(cfg)}", fn)


def _fastest_points(traj, v_s):
    """s/L of the fastest node at the first frame where the fastest node exceeds 25 % and 50 %
    of v_s, and at the frame nearest the peak (the paper's Fig. 3b reading)."""
    sp, tf = np.asarray(traj.speed), np.asarray(traj.t_frames)
    ok = np.isfinite(sp).all(1) & (tf <= float(traj.t_end) + 1e-12)
    sp, tf = sp[ok], tf[ok]
    s = np.linspace(0.0, 1.0, sp.shape[1])
    out = {}
    for frac in (0.25, 0.5):
        i = np.flatnonzero(sp.max(1) >= frac * v_s)
        out[f"s_fastest_{int(frac * 100)}"] = float(s[np.argmax(sp[i[0]])]) if i.size else None
    k = int(np.argmin(np.abs(tf - float(traj.t_peak))))
    out["s_fastest_peak"] = float(s[np.argmax(sp[k])])
    out["mean_speed_max"] = float(sp.mean(1).max())
    return out


def _progress(items, desc, progress):
    if not progress:
        return items
    from tqdm.auto import tqdm

    return tqdm(items, desc=desc, unit="pt", file=sys.stderr, leave=False)


def section_snap_dynamics(cache, out, progress, cfg):
    """Figs. 3a-c: chronophotography, speed map and energies of the brink snap up at
    Psi0 = 30 deg, G/L = 0.5 (the paper's Fig. 3 case)."""
    from ..plot import plot_snap

    title = "One snap: Psi0 = 30 deg, G/L = 0.5 (Figs. 3a-c)"
    for _ in _progress([0], "snap 30/0.5", progress):
        rec, traj = _framed_snap(cache, out, 30.0, 0.5, cfg)
    if traj is None:
        return title, "jaxrod finds no snap up here.", [("snap up, Psi0 = 30, G/L = 0.5", "snaps", "no snap", "")], rec
    fast = cache.get(f"fastest/30/0.5/{cfg['n']}/{_dyn_tag(cfg)}", lambda: _fastest_points(traj, rec["v_s"]))
    d = os.path.join(out, "fig3_snap")
    plot_snap(traj, d, title=f"brink snap up, Psi0 = 30 deg, G/L = 0.5, N = {cfg['n']}")
    ratio = rec["kinetic_energy_peak"] / rec["bending_energy_before"]
    rows = [("E_k at its peak / E_b before the snap", "bending energy almost entirely traded for kinetic",
             f"{ratio:.2f}", f"E_b before {rec['bending_energy_before']:.1f} B/L, E_k peak "
             f"{rec['kinetic_energy_peak']:.1f} B/L; energy drift {rec['energy_drift']:.1e}"
             + (" (RATTLE's bounded O(dt^2) energy error)" if _rattle(cfg) else "")),
            ("typical bending energy of the equilibria", "~100 B/L", f"{rec['bending_energy_before']:.1f} B/L",
             "critical (pre-snap) state, Psi0 = 30 deg, G/L = 0.5"),
            ("mean speed along the strip at its largest", "~10 v*", f"{fast['mean_speed_max']:.1f} v*",
             f"max over the {_N_FRAMES} frames of the mean node speed"),
            ("fastest point along the strip as the snap develops (s/L)",
             "one half first (large s), then s ~ L/4, finally the fold (L/2)",
             f"{fast['s_fastest_25']:.2f} -> {fast['s_fastest_50']:.2f} -> {fast['s_fastest_peak']:.2f}",
             "at 25 % and 50 % of v_s and at the peak; the model is mirror-symmetric, so which half goes "
             "first is set by the nudge (the mirror image is an equally valid snap)")]
    from ..dynamics import NUDGE

    text = (f"`jr.snap_dynamics(scene, 'up', kind='brink', nudge={NUDGE})`: the critical state of the "
            "quasi-static path, clamps 1e-3 rad past alpha_c_up, nudged along the unstable mode "
            f"(kind: {rec.get('kind')}); {_dyn_words(cfg)}, N = {cfg['n']}, no dissipation. "
            f"v_s = {rec['v_s']:.3f} v* at t = {rec['t_peak']:.3f} T. The paper's Fig. 3 is a DER simulation "
            "as the clamps turn; here the clamps are held just past alpha_c (the `ramp` scene turns them).\n\n"
            "![chronophotography](fig3_snap/chrono.png) ![speed map](fig3_snap/speed_map.png) "
            "![energies](fig3_snap/energies.png) ![fold](fig3_snap/fold.png)")
    return title, text, rows, {"record": rec, "fastest": fast}


def section_speed_plane(cache, out, progress, cfg):
    """Figs. 3d-e: v_s over Psi0 x G/L and the plane fit beside the paper's."""
    from ._speed_plane import SPEED_PLANE, fit_plane, plot_plane

    title = "Snap speed plane (Figs. 3d-e)"
    pts = [(p, g) for p in cfg["psis"] for g in cfg["gaps"]]
    recs = {pt: _vs(cache, *pt, cfg) for pt in _progress(pts, "speed plane", progress)}
    rows_fit = [dict(psi0_deg=p, gap=g, snaps=bool(r.get("snaps")), v_s=r.get("v_s")) for (p, g), r in recs.items()]
    nsnap = sum(r["snaps"] for r in rows_fit)
    table = ["| Psi0 \\ G/L | " + " | ".join(f"{g:g}" for g in cfg["gaps"]) + " |",
             "|---|" + "---|" * len(cfg["gaps"])]
    for p in cfg["psis"]:
        table.append(f"| {p:g} deg | " + " | ".join(
            f"{recs[(p, g)]['v_s']:.2f}" if recs[(p, g)].get("snaps") else "no snap" for g in cfg["gaps"]) + " |")
    paper = [f"{SPEED_PLANE[0]} +- 1.33", f"{SPEED_PLANE[1]} +- 2.57", f"{SPEED_PLANE[2]} +- 0.26"]
    names = ["v_m (G/L = 0, Psi0 = 0 intercept)", "a (slope in G/L)", "b (slope in Psi0, rad)"]
    data = {"points": {f"{p:g}/{g:g}": r for (p, g), r in recs.items()}, "n": cfg["n"], "solver": _dyn_words(cfg)}
    if nsnap < 4:
        rows = [(f"v_s/v* = v_m - a G/L - b Psi0: {nm}", pv, "n/a (fewer than 4 snapping points)", "")
                for nm, pv in zip(names, paper)]
        return title, "\n".join(table), rows, data
    coef, err, rms = fit_plane(rows_fit)
    plot_plane(rows_fit, coef, os.path.join(out, "speed_plane.png"))
    rows = [(f"v_s/v* = v_m - a G/L - b Psi0: {nm}", pv, f"{c:.2f} +- {e:.2f}",
             f"least squares over {nsnap} snapping points, rms residual {rms:.2f} v*" if k == 0 else "")
            for k, (nm, pv, c, e) in enumerate(zip(names, paper, coef, err))]
    data["fit"] = dict(v_m=coef[0], a=coef[1], b=coef[2], stderr=err, rms=rms, points=nsnap)
    text = (f"Peak fold speed v_s / v* of the brink snap up (as in the section above) at every point of the grid "
            f"(N = {cfg['n']}, {_dyn_words(cfg)}); \"no snap\": the quasi-static up path does not lose "
            "stability there (past the termination gap). The paper's plane is a fit to experiments on PET "
            "strips, jaxrod's to the undamped planar model; nothing is tuned.\n\n" + "\n".join(table)
            + "\n\n![speed plane](speed_plane.png) (points and jaxrod's plane: solid; the paper's plane: dotted)")
    return title, text, rows, data


def pet_speed_gauges():
    """v* (m/s) of the paper's PET strips (docs/model.md) for the thinnest and thickest sheet,
    through `jr.Strip.from_physical`."""
    import jaxrod as jr

    return {t: float(jr.Strip.from_physical(thickness=t, **_PET).speed_gauge) for t in _PET_THICKNESS}


def section_folded_unfolded(cache, out, progress, cfg):
    """Fig. 1c: the fold speed of the folded strip (Psi0 = 30 deg) and the unfolded one at
    G/L = 0.5, their ratio and their values in m/s for the paper's PET strips."""
    title = "Folded vs unfolded snap speed (Fig. 1c)"
    q = "v_s(Psi0 = 30 deg) / v_s(flat), G/L = 0.5 (snap up from the brink)"
    res = {}
    for p in _progress([30.0, 180.0], "folded/flat", progress):
        res[p] = _framed_snap(cache, out, p, 0.5, cfg)
    (fold, tf), (flat, tl) = res[30.0], res[180.0]
    if tf is None or tl is None:
        return title, "One of the two strips does not snap up.", [(q, "~2 (8 m/s vs 4 m/s)", "n/a (no snap)", "")], \
            {"folded": fold, "flat": flat}
    ratio = fold["v_s"] / flat["v_s"]
    vstar = pet_speed_gauges()
    t0, t1 = _PET_THICKNESS
    rows = [(q, "~2 (8 m/s vs 4 m/s)", f"{ratio:.2f}",
             f"v_s = {fold['v_s']:.2f} v* (folded), {flat['v_s']:.2f} v* (flat); N = {cfg['n']}"),
            ("folded v_s in m/s (PET, L = 20 cm)", "8 m/s",
             f"{fold['v_s'] * vstar[t0]:.1f} - {fold['v_s'] * vstar[t1]:.1f} m/s",
             f"t = {t0 * 1e6:.0f} - {t1 * 1e6:.0f} um, E = {_PET['youngs_modulus'] / 1e9:g} GPa, "
             f"rho = {_PET['density']:g} kg/m^3: v* = {vstar[t0]:.3f} - {vstar[t1]:.3f} m/s "
             "(the paper does not give this strip's thickness)"),
            ("flat v_s in m/s (same strips)", "4 m/s",
             f"{flat['v_s'] * vstar[t0]:.1f} - {flat['v_s'] * vstar[t1]:.1f} m/s", "")]
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3.8))
    for tr, rec, c, lab in ((tf, fold, "C3", "Psi0 = 30 deg"), (tl, flat, "k", "no fold (mid-point)")):
        t = np.asarray(tr.t)
        ok = np.isfinite(t) & np.isfinite(np.asarray(tr.fold_speed))
        ax.plot(t[ok] - rec["t_peak"], np.asarray(tr.fold_speed)[ok], color=c,
                label=f"{lab}: v_s = {rec['v_s']:.1f} v*")
    ax.set_xlim(-0.4, 0.1)
    ax.set_xlabel("t - t_peak (T)")
    ax.set_ylabel("fold speed / v*")
    ax.set_title("snap up at G/L = 0.5 (brink)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "fig1c_fold_speed.png"), dpi=110)
    plt.close(fig)
    text = ("Both strips snap up from the brink at G/L = 0.5 (the section above); m/s through "
            "`jr.Strip.from_physical` (v* = sqrt(B / (lambda L^2)) = (t/L) sqrt(E / (12 rho)), independent of the "
            "width).\n\n![fold speed](fig1c_fold_speed.png)")
    return title, text, rows, {"folded": fold, "flat": flat, "ratio": ratio,
                               "v_star_m_per_s": {f"{t * 1e6:.0f}um": v for t, v in vstar.items()}}


_ASYM = dict(psi0=60.0, gap=0.5, rate=0.5)


def _quarter_motion(traj, n, t_lo=-np.inf, t_hi=np.inf):
    """Largest node displacement between the first and the last valid frame in [t_lo, t_hi],
    and the largest node speed there, in the quarter next to the fixed left clamp (far,
    s < L/4) and next to the turning right clamp (near, s > 3L/4)."""
    x, sp, tf = np.asarray(traj.positions), np.asarray(traj.speed), np.asarray(traj.t_frames)
    ok = np.isfinite(sp).all(1) & (tf <= float(traj.t_end) + 1e-12) & (tf >= t_lo) & (tf <= t_hi)
    x, sp, tf = x[ok], sp[ok], tf[ok]
    q = n // 4
    disp = np.linalg.norm(x[-1] - x[0], axis=-1)
    return dict(disp_far=float(disp[1:q + 1].max()), disp_near=float(disp[n - q:n].max()),
                speed_far=float(sp[:, 1:q + 1].max()), speed_near=float(sp[:, n - q:n].max()),
                t_from=float(tf[0]), t_to=float(tf[-1]))


def section_asymmetric(cache, out, progress, cfg):
    """Fig. 4: the left clamp held at 0, the right one turned at a constant rate from 0
    (`jr.snap_dynamics(kind="asymmetric")`); which end of the strip moves while the clamp
    turns, and which one jumps in the snap."""
    import math

    import jaxrod as jr
    from ..plot import plot_snap

    title = "Asymmetric actuation (Fig. 4)"
    p, g, rate, n = _ASYM["psi0"], _ASYM["gap"], _ASYM["rate"], cfg["n"]
    key = f"asym/{p:g}/{g:g}/{rate:g}/{n}/{_dyn_tag(cfg)}"
    scene = _scene(p, g, n, 0.02)
    lead = 0.15  # the snap frames start this long (T) before the fold crosses y = 0

    def run_(window=None):
        def fn():
            start, tr = jr.snap_dynamics(scene, "up", kind="asymmetric", rate=rate, alpha_start=0.0,
                                         **_run_kwargs(cfg, window))
            return _dyn_record(start, tr), _traj_arrays(tr)
        return fn

    for _ in _progress([0], "asymmetric", progress):
        rec, whole = _cached_traj(out, key + "/whole", run_())
        if rec["t_snap"] is None:
            return title, "The asymmetric ramp did not snap within t1.", [
                ("asymmetric snap", "only the half next to the turning clamp snaps", "no snap", "")], rec
        t_snap = rec["t_snap"]
        _, snapt = _cached_traj(out, key + "/snap", run_((max(0.0, t_snap - lead), rec["t_end"])))
    turn = cache.get(key + "/turn", lambda: _quarter_motion(whole, n, t_hi=t_snap - lead))
    jump = cache.get(key + "/jump", lambda: _quarter_motion(snapt, n))
    sym = _vs(cache, p, g, cfg)
    alpha_snap = math.degrees(rate * t_snap)
    for path in plot_snap(snapt, os.path.join(out, "fig4_asymmetric"),
                          title=f"right clamp turned at {rate:g} rad/T, left held at 0"):
        if os.path.basename(path) not in ("chrono.png", "speed_map.png"):
            os.remove(path)  # not shown in the report
    if jump["speed_far"] > 2.0 * jump["speed_near"]:
        verdict = "the far half (next to the fixed clamp)"
    elif jump["speed_near"] > 2.0 * jump["speed_far"]:
        verdict = "the near half (next to the turning clamp)"
    else:
        verdict = "both halves"
    rows = [("asymmetric: which part jumps in the snap", "only the part next to the turning clamp",
             verdict, "the quarter whose largest node speed in the snap is > 2x the other's (below); the near "
             "quarter instead moves while the clamp turns, smoothly"),
            ("asymmetric: right clamp angle when the fold crosses y = 0", "(not given)", f"{alpha_snap:.1f} deg",
             f"Psi0 = {p:g} deg, G/L = {g:g}, left clamp at 0, {rate:g} rad/T; symmetric alpha_c_up here "
             + (f"{sym['alpha_c_deg']:.1f} deg" if sym.get("alpha_c_deg") is not None else "none")),
            ("asymmetric, while the clamp turns: largest displacement, near / far quarter", "",
             f"{turn['disp_near']:.3f} / {turn['disp_far']:.3f} L", f"t = 0 to {turn['t_to']:.2f} T"),
            ("asymmetric, in the snap: largest displacement, near / far quarter", "",
             f"{jump['disp_near']:.3f} / {jump['disp_far']:.3f} L",
             f"t = {jump['t_from']:.2f} T to the first overshoot {jump['t_to']:.2f} T"),
            ("asymmetric, in the snap: largest node speed, near / far quarter", "",
             f"{jump['speed_near']:.1f} / {jump['speed_far']:.1f} v*", f"fold v_s {rec['v_s']:.1f} v*")]
    text = (f"`jr.snap_dynamics(scene, 'up', kind='asymmetric', rate={rate:g}, alpha_start=0)`: from the down state "
            "at alpha = 0 only the right clamp turns (the paper turns the left one; the model is mirror-symmetric). "
            "Near quarter: s > 3L/4, next to the turning clamp; far quarter: s < L/4. The paper's Fig. 4 is an "
            "experiment (which balls are hit), so only its qualitative statement is compared; the frames below "
            f"start {lead:g} T before the fold crosses y = 0.\n\n"
            "![chronophotography](fig4_asymmetric/chrono.png) ![speed map](fig4_asymmetric/speed_map.png)")
    return title, text, rows, {"record": rec, "turn": turn, "snap": jump, "alpha_snap_deg": alpha_snap,
                               "verdict": verdict}


def run(out, quick=False, progress=True):
    """Compute every section and write `out/report.md` and `out/results.json`. Returns the
    report's path."""
    import jax

    import jaxrod as jr

    n = 60 if quick else 200
    cfg = dynamics_config(quick)
    cache = _Cache(os.path.join(out, "cache.json"))
    sections = [section_snap_angles, section_no_snap, section_loops,
                lambda c, n, o, p: section_master_curves(c, n, o, p, quick=quick)]
    sections += [lambda c, n, o, p, f=f: f(c, o, p, cfg) for f in
                 (section_snap_dynamics, section_speed_plane, section_folded_unfolded, section_asymmetric)]
    md = ["# jaxrod reproduces Marzin et al., \"Augmented snap-through instability of folded strips\"", "",
          f"jaxrod {jr.__version__}, {datetime.date.today().isoformat()}, {platform.node()}, "
          f"jax {jax.__version__}, statics N = {n}, dynamics N = {cfg['n']} with {_dyn_words(cfg)}"
          f"{' (quick)' if quick else ''}. Units L = B = lambda = 1, s0 = 0.02 L, angles in degrees; "
          "the paper's numbers are experiments on PET strips unless noted, jaxrod's the planar Kirchhoff model "
          "(nothing fitted to the paper).", "", "| quantity | paper | jaxrod | note |", "|---|---|---|---|"]
    body, results = [], {"n": n, "quick": quick, "dynamics": cfg, "sections": {}}
    t_start = time.perf_counter()
    for sec in sections:
        t0 = time.perf_counter()
        title, text, rows, data = sec(cache, n, out, progress)
        md += [f"| {q} | {p} | {j} | {note} |" for q, p, j, note in rows]
        body += ["", f"## {title}", "", text]
        results["sections"][title] = {"rows": [list(r) for r in rows], "data": data,
                                      "wall_s": round(time.perf_counter() - t0, 1)}
    results["wall_s"] = round(time.perf_counter() - t_start, 1)
    body += ["", f"Wall time of this run: {results['wall_s']:.0f} s (points already in `cache.json` are not "
             "recomputed; compilation included unless JAX's persistent cache had it)."]
    md += body
    path = os.path.join(out, "report.md")
    with open(path, "w") as f:
        f.write("\n".join(md) + "\n")
    with open(os.path.join(out, "results.json"), "w") as f:
        json.dump(results, f, indent=2)
        f.write("\n")
    return path
