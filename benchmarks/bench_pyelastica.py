#!/usr/bin/env python
"""Side-by-side benchmark: jaxrod's snap dynamics vs PyElastica on the same scene.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_pyelastica.py [--quick] [--ns 50,100]

(`pip install pyelastica`, the `bench` extra.) Scene: Psi0 = 30 deg, G/L = 0.5, s0 = 0.02,
L = B = lambda = 1, symmetric clamps, snap up. Two protocols, run by both tools from the
same initial state (jaxrod's statics, `jr.ramp(...).theta0`, mapped node by node onto
PyElastica's positions and directors):

* snap phase: the down state at alpha_c - 2 deg, clamps ramped at `--rate` (0.3 rad/T);
* full ramp: the down state at alpha = 0, the same rate, through the snap.

Both runs stop when the snap is over (the fold node has crossed y = 0 and its vertical
velocity reverses, jaxrod's event). v_s = max |dx/dt| of the mid node.

**The PyElastica model.** A `CosseratRod.straight_rod` with n_elem = N, base radius r,
density 1/(pi r^2) (lambda = rho A = 1), E = 4/(pi r^4) (EI = 1), Poisson ratio 0.5
(shear modulus E/3, PyElastica's shear factor 4/3), so EA = 4/r^2 and the rotary inertia
per length is rho I = r^2/4; rest curvature `rest_kappa` = the exact differences of
theta0 at element midpoints over the Voronoi length (the same natural turning angles as
jaxrod's `discretize`). Clamps: the end nodes are held at (0,0) and (G,0) by a custom
constraint (which also keeps the motion planar: z = 0, only in-plane rotation); the clamp
*angles* enter as jaxrod's boundary hinges, a custom forcing class that applies the couple
of the half-length hinge between the end element and the clamp tangent alpha(t),
-(B/(h/2)) (theta_1 - alpha_L - phibar_0) on element 1 and the mirror on element N. That
is exactly jaxrod's discrete bending energy (its clamps are ghost segments of zero length),
so with this clamp both codes integrate the same discrete equations up to PyElastica's
finite stretch/shear stiffness and rotary inertia (O(r^2) model differences, measured
with `--radius`), and jaxrod's tight-tolerance run at the same N is the reference for
both. (The "director clamp" variant instead pins the end elements' directors to the clamp angles,
PyElastica's usual clamp: a different, first-order discretization of the clamp; then
jaxrod's initial state is not an equilibrium of PyElastica's model.) Time stepping:
PositionVerlet at fixed dt, with a LaplaceDissipationFilter of order `--filter-order`.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# run times of the steady state: XLA's optimizing code generation from the first call (jaxrod's
# default "auto" compile mode reaches it once a program's calls have run long enough)
os.environ.setdefault("JAXROD_COMPILE", "optimized")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxrod as jr  # noqa: E402
from jaxrod.energy.geometry import discretize  # noqa: E402

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
sys.path.insert(0, str(HERE))
from bench_dynamics import time_simulate  # noqa: E402  (the jaxrod timing of both dynamics benchmarks)


# ----------------------------------------------------------------------------------------
# PyElastica side
# ----------------------------------------------------------------------------------------

def _elastica():
    import elastica as ea
    from elastica.boundary_conditions import ConstraintBase
    from elastica.external_forces import NoForces

    class Sim(ea.BaseSystemCollection, ea.Constraints, ea.Forcing, ea.Damping, ea.CallBacks):
        pass

    class PlanarEnds(ConstraintBase):
        """End nodes at (0,0) and (G,0); z = 0 and in-plane rotation only (d1 = e_z)."""

        def __init__(self, *fixed, gap, **kw):
            super().__init__(**kw)
            self.gap = gap

        def constrain_values(self, system, time):
            rod = system
            x = rod.position_collection
            x[2, :] = 0.0
            x[0, 0] = x[1, 0] = 0.0
            x[0, -1], x[1, -1] = self.gap, 0.0

        def constrain_rates(self, system, time):
            rod = system
            v = rod.velocity_collection
            v[2, :] = 0.0
            v[:, 0] = 0.0
            v[:, -1] = 0.0
            rod.omega_collection[1:, :] = 0.0

    class DirectorClamps(ConstraintBase):
        """PyElastica-style rotating clamps: end elements' directors pinned to alpha(t)."""

        def __init__(self, *fixed, alpha, rate, **kw):
            super().__init__(**kw)
            self.alpha, self.rate = alpha, rate

        def constrain_values(self, system, time):
            rod = system
            a = self.alpha(time)
            rod.director_collection[..., 0] = _director(a)
            rod.director_collection[..., -1] = _director(-a)

        def constrain_rates(self, system, time):
            rod = system
            w = self.rate(time)
            rod.omega_collection[:, 0] = (w, 0.0, 0.0)
            rod.omega_collection[:, -1] = (-w, 0.0, 0.0)

    class HingeClamps(NoForces):
        """Rotating clamps as jaxrod's boundary hinges: couple -(B/ell0)(theta_1 - alpha_L -
        phibar_0) on the first element, +(B/ellN)(-alpha_R - theta_N - phibar_N) on the last
        (about e_z; external torques are in the material frame, whose d1 is e_z)."""

        def __init__(self, alpha, B, ell0, ellN, phi0_first, phi0_last, **kw):
            super().__init__()
            self.alpha, self.B = alpha, B
            self.ell0, self.ellN, self.p0, self.pN = ell0, ellN, phi0_first, phi0_last

        def apply_torques(self, system, time=0.0):
            rod = system
            a = self.alpha(time)
            Q = rod.director_collection
            th1 = math.atan2(Q[2, 1, 0], Q[2, 0, 0])
            thN = math.atan2(Q[2, 1, -1], Q[2, 0, -1])
            rod.external_torques[0, 0] += -self.B / self.ell0 * (th1 - a - self.p0)
            rod.external_torques[0, -1] += self.B / self.ellN * (-a - thN - self.pN)

    return ea, Sim, PlanarEnds, DirectorClamps, HingeClamps


def _director(theta):
    """Rows d1 = e_z, d2 = t x e_z, d3 = t = (cos, sin, 0)."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[0.0, 0.0, 1.0], [s, -c, 0.0], [c, s, 0.0]])


def build_pyelastica(scene, theta_init, alpha_fn, rate_fn, *, radius, filter_order, clamp="hinge"):
    """The PyElastica simulator for `scene` started at rest from jaxrod's angles `theta_init`."""
    ea, Sim, PlanarEnds, DirectorClamps, HingeClamps = _elastica()
    d = discretize(scene)
    n = scene.mesh.n
    h = np.asarray(d.h)
    th = np.asarray(theta_init, float)
    pos = np.zeros((3, n + 1))
    pos[0, 1:] = np.cumsum(h * np.cos(th))
    pos[1, 1:] = np.cumsum(h * np.sin(th))
    dirs = np.stack([_director(t) for t in th], -1)
    phi0 = np.asarray(d.phi0)  # (N+1,) natural turning angles at the hinges incl. the clamps
    B = float(scene.strip.bending_stiffness)
    lam = float(scene.strip.line_density)
    area = math.pi * radius**2
    E = 4.0 * B / (math.pi * radius**4)
    rest_kappa = np.zeros((3, n - 1))
    rest_kappa[0] = KAPPA_SIGN * phi0[1:-1] / h[1:]  # interior hinges, Voronoi length h
    rod = ea.CosseratRod.straight_rod(
        n, np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0]), float(np.sum(h)), radius,
        lam / area, youngs_modulus=E, shear_modulus=E / 3.0, position=pos, directors=dirs,
        rest_kappa=rest_kappa)
    sim = Sim()
    sim.append(rod)
    gap = float(scene.clamps.gap)
    sim.constrain(rod).using(PlanarEnds, gap=gap, constrained_position_idx=(0, n))
    if clamp == "hinge":
        sim.add_forcing_to(rod).using(HingeClamps, alpha=alpha_fn, B=B, ell0=float(d.ell[0]),
                                      ellN=float(d.ell[-1]), phi0_first=float(phi0[0]), phi0_last=float(phi0[-1]))
    else:
        sim.constrain(rod).using(DirectorClamps, alpha=alpha_fn, rate=rate_fn, constrained_director_idx=(0, n - 1))
    if filter_order:
        sim.dampen(rod).using(ea.LaplaceDissipationFilter, filter_order=int(filter_order))
    sim.finalize()
    return sim, rod


KAPPA_SIGN = 1.0  # set by check_kappa_sign()


def check_kappa_sign():
    """Which sign PyElastica's kappa[0] has for a turn +dtheta about e_z (with d1 = e_z)."""
    global KAPPA_SIGN
    import elastica as ea

    n = 8
    th = 0.1 * np.arange(n)
    pos = np.zeros((3, n + 1))
    pos[0, 1:] = np.cumsum(np.cos(th)) / n
    pos[1, 1:] = np.cumsum(np.sin(th)) / n
    dirs = np.stack([_director(t) for t in th], -1)
    rod = ea.CosseratRod.straight_rod(n, np.zeros(3), np.array([1.0, 0, 0]), np.array([0, 0, 1.0]), 1.0, 0.01,
                                      1.0, youngs_modulus=1.0, position=pos, directors=dirs)
    rod.compute_internal_forces_and_torques(0.0)
    k = rod.kappa[0, 0] * rod.rest_voronoi_lengths[0]
    KAPPA_SIGN = float(np.sign(k))
    assert abs(abs(k) - 0.1) < 1e-9, k
    return KAPPA_SIGN


def run_pyelastica(scene, theta_init, alpha0, rate, *, dt, t_max, radius, filter_order, clamp="hinge",
                   direction=1.0, stop_at_snap=True, t_relax=0.1, gamma_relax=200.0):
    """Integrate until the snap is over; returns a dict of v_s, t_cross, t_end, steps, wall.

    Before t = 0 the clamps are held at alpha0 for `t_relax` with a velocity damping
    exp(-gamma_relax dt) per step (a linear damper), then all rates are zeroed: jaxrod's
    inextensible equilibrium is not quite one of the extensible, shearable rod (strain
    ~ tension/EA), and started as it is the rod rings at ~0.5 v* in its stretch and shear
    modes. The relaxation lets it settle into its own equilibrium; its wall time is
    reported separately (`relax_s`) and not counted in `wall_s`."""
    ea = _elastica()[0]

    def alpha_fn(t):
        return alpha0 + rate * max(float(t), 0.0)

    def rate_fn(t):
        return rate if t > 0 else 0.0

    t0 = time.perf_counter()
    sim, rod = build_pyelastica(scene, theta_init, alpha_fn, rate_fn, radius=radius, filter_order=filter_order,
                                clamp=clamp)
    stepper = ea.PositionVerlet()
    t_build = time.perf_counter() - t0
    k = scene.mesh.n // 2
    x, v = rod.position_collection, rod.velocity_collection
    nmax = int(math.ceil(t_max / dt))
    speed = np.empty(nmax + 1)
    height = np.empty(nmax + 1)
    speed[0], height[0] = 0.0, x[1, k]
    t = np.float64(-t_relax)
    n_relax = int(round(t_relax / dt))
    fac = math.exp(-gamma_relax * dt)
    t0 = time.perf_counter()
    for _ in range(n_relax):
        t = stepper.step(sim, t, dt)
        v *= fac
        rod.omega_collection[...] *= fac
    v[...] = 0.0
    rod.omega_collection[...] = 0.0
    t = np.float64(0.0)
    t_relax_wall = time.perf_counter() - t0
    height[0] = x[1, k]
    crossed = False
    t_cross = math.nan
    i = 0
    t0 = time.perf_counter()
    blew_up = False
    while i < nmax:
        t = stepper.step(sim, t, dt)
        i += 1
        vx, vy = v[0, k], v[1, k]
        speed[i] = math.hypot(vx, vy)
        height[i] = x[1, k]
        if not crossed and direction * height[i] > 0.0 and direction * height[i - 1] <= 0.0:
            crossed = True
            frac = height[i - 1] / (height[i - 1] - height[i])
            t_cross = (i - 1 + frac) * dt
        if not math.isfinite(speed[i]) or speed[i] > 500.0:
            blew_up = True
            break
        if stop_at_snap and crossed and direction * vy < 0.0:
            break
    wall = time.perf_counter() - t0
    sp = speed[: i + 1]
    j = int(np.argmax(sp))
    vs = float(sp[j])
    if 0 < j < i:
        fm, f0, fp = sp[j - 1], sp[j], sp[j + 1]
        den = fm - 2 * f0 + fp
        if den < 0:
            u = 0.5 * (fm - fp) / den
            vs = float(f0 - 0.25 * (fm - fp) * u)
    # model diagnostics: max axial strain and shear angle at the end
    sigma = rod.sigma
    return dict(v_s=vs, t_peak=j * dt, t_cross=t_cross, t_end=i * dt, steps=i, wall_s=wall, build_s=t_build, relax_s=t_relax_wall, t_relax=t_relax,
                gamma_relax=gamma_relax,
                us_per_step=1e6 * wall / max(i, 1), snapped=bool(crossed), blew_up=blew_up,
                final_max_strain=float(np.max(np.abs(sigma[2]))), final_max_shear=float(np.max(np.abs(sigma[1]))),
                dt=dt, radius=radius, EA=4.0 / radius**2, rho_I=radius**2 / 4, filter_order=filter_order,
                clamp=clamp)


# ----------------------------------------------------------------------------------------
# jaxrod side
# ----------------------------------------------------------------------------------------

def run_jaxrod(start, tol, t1, n_fine, repeats, solver="tsit5"):
    """`tol`: rtol = atol for Tsit5, the Courant number for RATTLE (jaxrod's default)."""
    sub = int(solver.split("x")[1]) if solver.startswith("rattle x") else 1  # "rattle x4": 4 substeps
    base = "rattle" if solver.startswith("rattle") else solver
    kw = dict(courant=tol, substeps=sub) if base == "rattle" else dict(rtol=tol, atol=tol)
    # RATTLE samples every (macro) step by default (its step is then courant * h^2 itself)
    kw["n_fine"] = None if base == "rattle" else n_fine
    tr, wall, first = time_simulate(start, repeats, t1=t1, solver=base, **kw)
    return dict(solver=solver, tol=tol, v_s=float(tr.v_s), t_cross=float(tr.t_cross), t_end=float(tr.t_end),
                steps=int(tr.num_steps), wall_s=wall, compile_s=max(first - wall, 0.0),
                energy_drift=float(tr.energy_drift), snapped=bool(tr.snapped), n_fine=int(tr.t.shape[0]), t1=t1)


def machine_info():
    import importlib.metadata as md

    try:
        load = os.getloadavg()
    except OSError:
        load = None
    return dict(date=datetime.datetime.now().isoformat(timespec="seconds"), platform=platform.platform(),
                machine=platform.machine(), processor=platform.processor(), cpus=os.cpu_count(),
                python=platform.python_version(), jax=jax.__version__, jaxlib=md.version("jaxlib"),
                diffrax=md.version("diffrax"), pyelastica=md.version("pyelastica"), numba=md.version("numba"),
                numpy=np.__version__, openblas_threads=os.environ.get("OPENBLAS_NUM_THREADS"),
                loadavg_start=load)


def protocol_case(name, sc, snap, rate, alpha_start, args, tols, n_fine):
    """One protocol at one N: jaxrod reference + tolerance sweep, PyElastica variants."""
    n = sc.mesh.n
    start = jr.ramp(sc, "up", rate=rate, alpha_start=alpha_start, snap=snap)
    a0 = float(start.protocol.alpha_left0)
    alpha_c = float(snap.up.alpha_c)
    t_snap = (alpha_c - a0) / rate
    t1 = t_snap + 1.3  # the snap comes ~0.9 T after alpha_c is passed (critical slowing down)
    print(f"[{name} N={n}] alpha0 = {math.degrees(a0):.4f} deg, alpha_c = {math.degrees(alpha_c):.4f} deg, "
          f"t1 = {t1:.3f}", flush=True)
    ref = run_jaxrod(start, args.ref_tol, t1, n_fine, 0)
    print(f"  jaxrod reference tol {args.ref_tol:g}: {json.dumps(ref)}", flush=True)
    vref = ref["v_s"]
    jx = []
    for solver, tol in tols:
        r = run_jaxrod(start, tol, t1, n_fine, args.repeats, solver=solver)
        r["rel_err"] = abs(r["v_s"] - vref) / vref
        jx.append(r)
        print(f"  jaxrod {solver} {tol:g}: {json.dumps(r)}", flush=True)
    theta = np.asarray(start.theta0)
    pe = []
    variants = [dict(dt=args.dt, radius=args.radius, filter_order=args.filter_order, role="main")]
    if not args.quick and name == "snap" and n == args.ns[0]:
        variants += [dict(dt=args.dt / 2, radius=args.radius, filter_order=args.filter_order, role="dt/2"),
                     dict(dt=args.dt / 4, radius=args.radius / 2, filter_order=args.filter_order, role="r/2, dt/4"),
                     dict(dt=args.dt, radius=args.radius, filter_order=10, role="filter 10"),
                     dict(dt=args.dt, radius=args.radius, filter_order=6, role="filter 6"),
                     dict(dt=args.dt * 4 / 3, radius=args.radius, filter_order=args.filter_order, role="dt*4/3"),
                     dict(dt=args.dt, radius=args.radius, filter_order=args.filter_order, clamp="director",
                          role="director clamp")]
    for var in variants:
        dt = var["dt"] * min(1.0, 50.0 / n)  # the axial-wave bound dt ~ h r / 2 shrinks with h
        r = run_pyelastica(sc, theta, a0, rate, dt=dt, t_max=t1, radius=var["radius"],
                           filter_order=var["filter_order"], clamp=var.get("clamp", "hinge"))
        r["role"] = var["role"]
        r["rel_err"] = abs(r["v_s"] - vref) / vref if r["snapped"] and not r["blew_up"] else math.nan
        pe.append(r)
        print(f"  pyelastica {var['role']}: {json.dumps(r)}", flush=True)
    main = pe[0]
    # matched accuracy: the fastest jaxrod run whose v_s error is <= PyElastica's (main settings)
    ok = [r for r in jx if r["rel_err"] <= main["rel_err"]] if math.isfinite(main["rel_err"]) else []
    matched = min(ok, key=lambda r: r["wall_s"]) if ok else min(jx, key=lambda r: r["rel_err"])
    # jaxrod's default: RATTLE at Courant 0.45, 4 substeps (simulate's default at its automatic step)
    default = next((r for r in jx if r["solver"] == "rattle x4" and r["tol"] == 0.45), jx[0])
    summary = dict(protocol=name, n=n, rate=rate, alpha0_deg=math.degrees(a0), alpha_c_deg=math.degrees(alpha_c),
                   v_ref=vref, pyelastica_v_s=main["v_s"], pyelastica_rel_err=main["rel_err"],
                   pyelastica_wall_s=main["wall_s"], pyelastica_relax_s=main["relax_s"],
                   pyelastica_us_per_step=main["us_per_step"], pyelastica_steps=main["steps"],
                   matched_solver=matched["solver"], matched_tol=matched["tol"], matched_rel_err=matched["rel_err"], matched_wall_s=matched["wall_s"],
                   matched_compile_s=matched["compile_s"], matched_is_at_least_as_accurate=bool(ok),
                   ratio_matched=main["wall_s"] / matched["wall_s"],
                   ratio_matched_incl_relax=(main["wall_s"] + main["relax_s"]) / matched["wall_s"],
                   default_tol=default["tol"], default_wall_s=default["wall_s"], default_rel_err=default["rel_err"],
                   ratio_default=main["wall_s"] / default["wall_s"])
    summary["target_30x_met"] = summary["ratio_matched"] >= 30.0
    summary["aim_100x_met"] = summary["ratio_matched"] >= 100.0
    print(f"  SUMMARY {json.dumps(summary)}", flush=True)
    return dict(summary=summary, reference=ref, jaxrod=jx, pyelastica=pe)


def _label(solver, tol):
    if solver.startswith("rattle x"):
        return f"RATTLE Courant {tol:.2f}, {solver.split('x')[1]} substeps per diffrax step"
    return f"RATTLE Courant {tol:.2f}" if solver == "rattle" else f"Tsit5 tol {tol:.0e}"


def _row_ratio(pye, jx):
    """PyElastica row's wall time over the fastest jaxrod run at least as accurate ('' if none)."""
    err = pye.get("rel_err")
    if err is None or not math.isfinite(err) or pye.get("wall_s", 0) <= 0:
        return ""
    ok = [r for r in jx if math.isfinite(r["rel_err"]) and r["rel_err"] <= err]
    if not ok:
        return "none as accurate"
    r = min(ok, key=lambda r: r["wall_s"])
    return f"{pye['wall_s'] / r['wall_s']:.1f}x ({_label(r.get('solver', 'tsit5'), r['tol'])})"


def write_md(out, path):
    info = out["info"]
    L = [f"# jaxrod vs PyElastica: snap dynamics at matched accuracy ({info['date']})", "",
         f"Machine: {info['platform']}, {info['cpus']} CPUs, load average at start {info['loadavg_start']}, "
         f"at end {info['loadavg_end']} (a 2-core VM shared with other jobs: wall times are noisy upper bounds). "
         f"Python {info['python']}, JAX {info['jax']}, diffrax {info['diffrax']}, PyElastica {info['pyelastica']} "
         f"(numba {info['numba']}).", "",
         "Scene: Psi0 = 30 deg, G/L = 0.5, s0 = 0.02, L = B = lambda = 1, symmetric clamps, snap up; both tools "
         "start from the same jaxrod equilibrium (the down state at alpha0) and stop at the first overshoot of the "
         "fold node after it crosses y = 0. v_s = peak speed of the mid node (v*). Snap phase: alpha0 = alpha_c - 2 "
         f"deg; full ramp: alpha0 = 0; clamps at {out['settings']['rate']} rad/T. Reference: jaxrod Tsit5 at rtol = atol = "
         f"{out['settings']['ref_tol']:g}, same N (same discrete equations as the PyElastica set-up, see below).", "",
         "| protocol | N | v_ref | PyElastica v_s | PyE rel. err | PyE wall (s) | PyE us/step | jaxrod run (matched) | "
         "jaxrod rel. err | jaxrod wall (s) | jaxrod compile (s) | ratio PyE/jaxrod | >= 30x? | >= 100x? |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for c in out["cases"]:
        s = c["summary"]
        L.append(f"| {s['protocol']} | {s['n']} | {s['v_ref']:.5f} | {s['pyelastica_v_s']:.5f} | "
                 f"{s['pyelastica_rel_err']:.1e} | {s['pyelastica_wall_s']:.2f} | {s['pyelastica_us_per_step']:.1f} | "
                 f"{_label(s.get('matched_solver', 'tsit5'), s['matched_tol'])} | {s['matched_rel_err']:.1e} | {s['matched_wall_s']:.3f} | "
                 f"{s['matched_compile_s']:.1f} | {s['ratio_matched']:.1f} | "
                 f"{'yes' if s['target_30x_met'] else 'NO'} | {'yes' if s['aim_100x_met'] else 'no'} |")
    L += ["", "Ratio at jaxrod's default (RATTLE, Courant 0.45, 4 substeps) instead: " + ", ".join(
        f"{c['summary']['protocol']} N={c['summary']['n']}: {c['summary']['ratio_default']:.1f}x "
        f"(v_s error {c['summary'].get('default_rel_err', math.nan):.1e})" for c in out["cases"])
        + ". PyElastica's wall time excludes its pre-run relaxation (below) and its numba compilation; "
        "jaxrod's excludes its XLA compilation (column 'compile').", ""]
    for c in out["cases"]:
        s = c["summary"]
        L += [f"## {s['protocol']}, N = {s['n']}", "",
              "| tool | settings | v_s | rel. err | steps | wall (s) | ratio (PyElastica rows: wall / that of the "
              "fastest jaxrod run at least as accurate) |", "|---|---|---|---|---|---|---|"]
        r = c["reference"]
        L.append(f"| jaxrod (reference) | Tsit5 tol {r['tol']:.0e} | {r['v_s']:.7f} | 0 | {r['steps']} | "
                 f"{r['wall_s']:.2f} (incl. compile) | |")
        for r in c["jaxrod"]:
            L.append(f"| jaxrod | {_label(r.get('solver', 'tsit5'), r['tol'])} | {r['v_s']:.7f} | {r['rel_err']:.1e} | {r['steps']} | "
                     f"{r['wall_s']:.3f} | |")
        for r in c["pyelastica"]:
            L.append(f"| PyElastica ({r['role']}) | {r['clamp']} clamp, dt {r['dt']:.3g}, r {r['radius']:g} "
                     f"(EA {r['EA']:.3g}), filter {r['filter_order'] or 'none'} | {r['v_s']:.7f} | "
                     f"{r['rel_err']:.1e} | {r['steps']} | {r['wall_s']:.2f} | {_row_ratio(r, c['jaxrod'])} |")
        L.append("")
    L += ["## Notes and caveats", ""] + [f"- {x}" for x in out["notes"]]
    path.write_text("\n".join(L) + "\n")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="N = 50, snap phase only, fewer tolerances, no variants")
    ap.add_argument("--ns", default="50", help="comma-separated N (n_elem), e.g. 50,100")
    ap.add_argument("--rate", type=float, default=0.3, help="clamp rate (rad/T)")
    ap.add_argument("--dt", type=float, default=1.5e-5, help="PyElastica time step at N = 50 (scaled ~1/N)")
    ap.add_argument("--radius", type=float, default=0.005, help="PyElastica rod radius (EA = 4/r^2, rho I = r^2/4)")
    ap.add_argument("--filter-order", type=int, default=0, help="LaplaceDissipationFilter order (0: none)")
    ap.add_argument("--ref-tol", type=float, default=1e-10)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--out", default=str(RESULTS / "pyelastica"))
    ap.add_argument("--render-only", action="store_true", help="rewrite the .md from the existing .json")
    args = ap.parse_args()
    if args.render_only:
        base = Path(args.out)
        out = json.loads(base.with_suffix(".json").read_text())
        out["notes"] = NOTES
        base.with_suffix(".json").write_text(json.dumps(out, indent=1))
        write_md(out, base.with_suffix(".md"))
        return
    args.ns = [int(x) for x in args.ns.split(",")]
    tols = [("rattle", 0.45), ("rattle x2", 0.45), ("rattle x4", 0.45), ("rattle", 0.3), ("rattle", 0.15)]
    tols += [("tsit5", t) for t in ([1e-4, 1e-6, 1e-8] if args.quick else [1e-3, 1e-4, 1e-5, 1e-6, 1e-8])]
    info = machine_info()
    check_kappa_sign()
    # numba warm-up (compilation of PyElastica's kernels), timed separately
    sc = jr.make_scene(30, 0.5, 0, n=args.ns[0])
    snap = jr.snap_angles(sc)
    st = jr.ramp(sc, "up", rate=args.rate, snap=snap)
    t0 = time.perf_counter()
    run_pyelastica(sc, np.asarray(st.theta0), float(st.protocol.alpha_left0), 0.0, dt=args.dt, t_max=20 * args.dt,
                   radius=args.radius, filter_order=args.filter_order or 6, t_relax=2 * args.dt)
    info["pyelastica_warmup_s"] = time.perf_counter() - t0
    cases = []
    for n in args.ns:
        sc = jr.make_scene(30, 0.5, 0, n=n)
        snap = jr.snap_angles(sc)
        cases.append(protocol_case("snap", sc, snap, args.rate, None, args, tols, 16384))
        if not args.quick:
            cases.append(protocol_case("full ramp", sc, snap, args.rate, 0.0, args, tols, 32768))
    try:
        info["loadavg_end"] = os.getloadavg()
    except OSError:
        info["loadavg_end"] = None
    notes = NOTES
    out = dict(info=info, settings=dict(psi0_deg=30, gap=0.5, s0=0.02, rate=args.rate, dt=args.dt, radius=args.radius,
                                        filter_order=args.filter_order, ref_tol=args.ref_tol, tols=tols,
                                        quick=args.quick, argv=sys.argv[1:]),
               cases=cases, notes=notes)
    base = Path(args.out)
    base.parent.mkdir(parents=True, exist_ok=True)
    base.with_suffix(".json").write_text(json.dumps(out, indent=1))
    write_md(out, base.with_suffix(".md"))
    print(f"wrote {base.with_suffix('.json')} and {base.with_suffix('.md')}")


NOTES = [
    "RESULT (2026-12-02, third run of the day, load ~1.0-1.25, after RATTLE's forces were taken from its own "
    "Cartesian state, commit 2b6b829): jaxrod's default (RATTLE at Courant 0.45, `substeps=4`) is the matched run: "
    "35.9x faster than PyElastica on the snap phase (0.046 s vs 1.65 s, v_s error 4.3e-6 vs PyElastica's 1.7e-3) "
    "and 40.2x on the full ramp (0.205 s vs 8.24 s, error 4.0e-3 vs 4.3e-3): the 30x target is met on both; the "
    "100x aim is not. PyElastica's step cost 23.1 us here, the fastest of the day's three runs (34.2 and 25.7 us "
    "before): at its slower step times the ratios would be larger. At a tighter matched accuracy the ratio grows: "
    "PyElastica needs dt/2 (3.29 s) for a 1.4e-4 error, against jaxrod's 0.046 s (71.3x; column 'ratio' of the "
    "PyElastica rows: the fastest jaxrod run at least as accurate as that row). Earlier runs, before the force "
    "change (same settings): 26.6x / 32.9x (jaxrod 0.069 / 0.277 s) and 38.9x / 36.3x. What changed in jaxrod: "
    "RATTLE's applied forces now come from its own Cartesian state (link normals from the node differences, "
    "damping and drag at v_1/2, pads instead of scatter-adds) instead of being re-derived from the angles by "
    "trigonometry and cumulative sums; a bare loop of RATTLE steps went from 7.6 to 5.7 us/step at N = 50, "
    "through diffrax at 4 substeps 7.4 us/step (6200 steps in 0.046 s). Where the ratio comes from: RATTLE's step "
    "at N = 50 is 1.8e-4 T (0.45 of its stability limit on the highest bending mode, 4/h^2), 12x PyElastica's "
    "1.5e-5, whose PositionVerlet step is bounded by the stretch/shear modes that an inextensible chain does not "
    "have; per step RATTLE costs ~7.4 us (one bending gradient, two SHAKE Newton iterations and one velocity "
    "projection, each a ~0.9 us LAPACK tridiagonal solve, plus a quarter of diffrax's per-step work) against "
    "PyElastica's 23-34 us. `substeps` = RATTLE steps per diffrax step: the same steps (tests/test_rattle.py), "
    "with diffrax's per-step work done once per 4 steps; with one RATTLE step per diffrax step: 25.0x / 23.9x. "
    "The earlier Tsit5 default needed rtol = atol = 1e-8 to match (1.6x / 1.7x in this run).",
    "Full ramp caveat: alpha_c is a branch point here, and a symmetric ramp from a symmetric state leaves it only "
    "when round-off seeds the asymmetric mode, so the snap delay (and v_s, since the clamps keep turning) depends on "
    "each integrator's round-off: RATTLE at Courant 0.45, 0.3 and 0.15 gives 26.418, 26.423, 26.416 (26.421 at 0.45 with 4 substeps; converged in "
    "dt to 3e-4) against the Tsit5 1e-10 reference 26.525 and PyElastica 26.410. 'Matched accuracy' on the full "
    "ramp therefore compares two errors of this unseeded-departure kind; the snap phase is the cleaner comparison.",
    "Same discrete problem: PyElastica's interior bending energy sum (B/2h)(phi_k - phibar_k)^2 with rest_kappa = "
    "phibar_k/h is jaxrod's; the clamps are jaxrod's half-length boundary hinges applied as a custom forcing "
    "(HingeClamps) and the end nodes are pinned by a custom constraint (PlanarEnds, which also enforces z = 0 and "
    "in-plane rotation). Node masses agree (lambda h, ends held). What differs is the physics PyElastica adds: "
    "finite stretch and shear stiffness (EA = 4/r^2, GA = EA/3 with shear factor 4/3) and rotary inertia rho I = "
    "r^2/4 per length, versus jaxrod's exactly inextensible, unshearable links without rotary inertia. Halving r "
    "(EA/B 1.6e5 -> 6.4e5, dt/4) brings PyElastica's snap-phase v_s from 26.619 to 26.5807, within 4.8e-5 of "
    "jaxrod's reference 26.5795: the two codes agree, and PyElastica's 1.5e-3 error at r = 0.005 is mostly this "
    "O(r^2) model difference (halving dt alone: 1.5e-3 -> 9.3e-4). Peak axial strain during the snap: ~1.5 %.",
    "PyElastica's explicit PositionVerlet step is bounded by the stretch/shear/rotary-inertia modes: dt ~ h r/2 "
    "(axial waves) and ~ r^2 (shear-rotation mode), so a stiffer (more inextensible) rod costs ~1/r^2 more steps. "
    "With r = 0.005, dt = 1.5e-5 is stable and dt = 2e-5 blows up within 10 steps; the more accurate r = 0.0025 "
    "needs dt <= ~3.75e-6 (6.2 s for the snap phase).",
    "Starting PyElastica from jaxrod's inextensible equilibrium excites its stretch/shear modes at ~0.5 v* "
    "(tensions of O(100 B/L^2) need strains ~1e-3 it does not have); so before t = 0 it is relaxed for 0.1 T with "
    "the clamps held and a velocity damping of 200/T, then its rates are zeroed (relax_s ~0.15 s in the json, not "
    "counted in its wall time). Residual fold speed after relaxation: ~4e-3 v*.",
    "Dissipation: in this set-up (hinge clamps, planar constraint, no filter) PyElastica ran stably, without visible "
    "energy gain, through both protocols (snap phase ~7e4 steps, full ramp ~3.6e5 steps), so the main rows use no "
    "filter. The LaplaceDissipationFilter is applied every step and shifts v_s a lot: -1.8 % at order 10, -3.0 % at "
    "order 6 (it damps the snap's own bending modes over ~7e4 steps). A filter would only make PyElastica's "
    "matched-accuracy position worse.",
    "'director clamp' is PyElastica's usual clamp (end elements' directors pinned to alpha(t)): a different, "
    "first-order discretization of the clamp, whose equilibrium is not jaxrod's start state (the end elements are "
    "rotated by h/2 times the clamp curvature at t = 0, a jolt): v_s 26.27, 1.2 % off, mostly discretization and "
    "start mismatch, not time stepping.",
    "jaxrod rows: RATTLE (fixed step, every step sampled) and Tsit5 with a PID controller (rtol = atol = tol, "
    "n_fine samples on [0, t1]); v_s is the sampled maximum refined by a 7-point polynomial; PyElastica: v_s from "
    "every step, refined the same way. jaxrod wall time = median of 2 compiled runs (block_until_ready); compile "
    "time = first call minus that. The matched run is the fastest jaxrod run at least as accurate as PyElastica.",
    "Both tools' v_s errors are relative to jaxrod's own converged solution of the N-segment equations, not to "
    "the continuum strip: the N = 50 discretization error itself (O(1/N^2), see dynamics.md) is common to both.",
    "Timings on a 2-core VM (load average ~1 during this run): ratios can move by tens of percent between runs.",
]


if __name__ == "__main__":
    main()
