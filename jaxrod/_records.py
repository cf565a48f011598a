"""JSON records of results, shared by the command line (`jaxrod snap`, `jaxrod actuate`, ...) and
the paper's report (`jaxrod.paper.reproduce`): plain dicts of Python numbers, `None` for a value
that is not finite. Units: $L = B = \\lambda = 1$, speeds in $v^\\ast$, times in $T = L/v^\\ast$,
energies in $B/L$."""

from __future__ import annotations

import math

import numpy as np

from .results import RESULTS, result_name


def _finite_or_none(x):
    x = float(x)
    return x if math.isfinite(x) else None


def creases_record(scene):
    """The scene's creases for the JSON output: `[{"position", "psi0_deg", "s0"}, ...]` in
    `Strip.crease_list` order, the centred crease first (the flat strip lists none)."""
    st = scene.strip
    pos, ang, wid = (np.asarray(v, float) for v in st.crease_list())
    L = float(st.length)
    return [{"position": float(c) / L, "psi0_deg": math.degrees(float(a)), "s0": float(w) / L}
            for c, a, w in zip(pos, ang, wid)] if (st.creases is not None or float(st.psi0) < math.pi) else []


def snap_record(start, tr, phys=None):
    """One snap, `(start, trajectory)` of `jaxrod.snap_dynamics`: its critical angle, speed
    (`v_s` at the fold, `v_s_creases` at each crease), times, energies, steps and result code.
    `phys`: `(v*, T)` in m/s and s, to add the speed and the times in SI units."""
    t = np.asarray(tr.t)
    fs = np.asarray(tr.fold_speed)
    ok = np.isfinite(fs)
    # snap duration: time the fold speed stays above half its peak
    above = t[ok][fs[ok] >= 0.5 * float(tr.v_s)]
    duration = float(above[-1] - above[0]) if above.size else float("nan")
    solved = bool(start.ok) and bool(tr.result == RESULTS.successful)
    f = _finite_or_none
    rec = dict(
        alpha_c_deg=f(np.degrees(float(start.alpha_c))),
        snapped=bool(tr.snapped),
        v_s=f(tr.v_s),
        t_peak=f(tr.t_peak),
        t_snap=f(tr.t_cross),
        snap_duration=f(duration),
        t_end=f(tr.t_end),
        bending_energy_before=f(start.bending_before),
        kinetic_energy_peak=f(tr.kinetic_peak),
        energy_drift=f(tr.energy_drift),
        num_steps=int(tr.num_steps),
        converged=solved,
        result=result_name(tr.result),
        units="L = B = lambda = 1: speeds in v*, times in T = L/v*, energies in B/L",
        creases=creases_record(start.scene),
    )
    # each crease's peak speed (the centred crease first), beside the fold's v_s at L/2
    rec["v_s_creases"] = [f(v) for v in np.asarray(tr.v_s_creases)] if rec["creases"] else []
    if phys is not None:
        vstar, T = phys
        rec.update(v_s_m_per_s=f(float(tr.v_s) * vstar), t_snap_s=f(float(tr.t_cross) * T),
                   snap_duration_s=f(duration * T), v_star_m_per_s=vstar, time_unit_s=T)
    return rec
