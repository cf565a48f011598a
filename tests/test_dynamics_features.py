"""Dynamics features beyond the conservative snap: dissipation (`jr.Dissipation`: quadratic air
drag, Kelvin-Voigt bending viscosity, viscous damping), gravity (`jr.Gravity`) in `jr.simulate`,
and a physical strip (`jr.Strip.from_physical`) fed into `jr.simulate`.

Every check compares with something computed here, independently of the integrator:
- dissipation: the energy lost over a window equals the work of the dissipative forces,
  integrated from the trajectory's own frames with the formulas of docs/model.md /
  `jaxrod.dynamics._equations` (drag power -c_d sum_k (m_k / lambda) |v_k|^3, viscous power
  -eta sum_k phidot_k^2 / ell_k, damping power -gamma sum_k m_k |v_k|^2);
- gravity: the initial acceleration of a strip released from rest is the mass-weighted
  projection of uniform gravity onto the motions the links allow (Gauss's principle of least
  constraint, solved here as a dense KKT system with NumPy);
- physical units: B = E t^3 w / 12, lambda = rho t w, v* = sqrt(B / (lambda L^2)), T = L / v*
  computed by hand (docs/model.md), speeds scale by v*, times by T, energies by B / L.

Small meshes (N = 24) and short horizons (t1 <= 0.8 T); clamps held fixed from a stable
equilibrium plus a perturbation (no snap), or a snap stopped at its first overshoot (RATTLE,
the default integrator, is not used past the slam)."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from jaxrod.dynamics._scenes import project
from jaxrod.energy.geometry import discretize

N = 24
T1 = 0.8
NS = 2048  # fine-grid samples = frames: every frame is a sample of the energies, at a step point


def _cumtrapz(y, t):
    return np.concatenate([[0.0], np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(t))])


# --- dissipation ----------------------------------------------------------------------------

LAMBDA = 2.0  # line density != 1, so that m_k / lambda (drag) and m_k (damping) differ
DISSIPATIONS = {"none": jr.Dissipation(), "drag": jr.Dissipation(drag=0.5),
                "viscosity": jr.Dissipation(viscosity=1e-3), "damping": jr.Dissipation(damping=0.5),
                "drag+viscosity": jr.Dissipation(drag=0.5, viscosity=1e-3)}


@pytest.fixture(scope="module")
def wobble():
    """Psi0 = 60 deg, G/L = 0.5, alpha = 0, lambda = 2: the stable down state, its angles
    perturbed by 0.4 sin(3 pi s / L) (projected back onto the end condition) and released
    at rest with the clamps held; one run per dissipation (one compiled program)."""
    scene = jr.Scene(jr.Strip(psi0=math.radians(60.0), line_density=LAMBDA), jr.Clamps.symmetric(0.5), jr.Mesh(N))
    eq = jr.initial_state(scene, "down")
    assert eq.result == jr.RESULTS.successful
    d = discretize(scene)
    mid = d.mid[1:-1]
    theta0 = project(eq.theta + 0.4 * jnp.sin(3 * jnp.pi * mid), scene)
    runs = {k: jr.simulate(scene, theta0, jr.Protocol(0.0, 0.0), t1=jnp.asarray(T1), n_fine=NS, n_frames=NS,
                           dissipation=dis) for k, dis in DISSIPATIONS.items()}
    return dict(scene=scene, d=d, e_eq=float(jr.bending_energy(eq)), runs=runs)


def _energy(tr):
    return np.asarray(tr.kinetic) + np.asarray(tr.potential)


def test_runs_are_clean_and_do_not_snap(wobble):
    for k, tr in wobble["runs"].items():
        assert tr.result == jr.RESULTS.successful, (k, jr.RESULTS[tr.result])
        assert np.all(np.isfinite(_energy(tr))) and float(tr.t_end) == pytest.approx(T1), k
        assert np.all(np.asarray(tr.fold_height) < -0.2), k  # stays in the down well
        assert np.all(np.asarray(tr.clamp_work) == 0.0), k  # clamps held: E_k + V is the balance
        np.testing.assert_allclose(np.asarray(tr.t_frames), np.asarray(tr.t), rtol=0, atol=1e-14)


def test_dissipation_never_adds_energy(wobble):
    """Drag, viscosity, damping: E_k + V never rises above its running minimum by more than
    twice the undamped run's energy error (RATTLE's bounded O(dt^2) error; measured 2.9e-4
    B/L against an excess energy of 2.6 B/L above the equilibrium), and each ends well below the undamped run."""
    runs = wobble["runs"]
    e_ref = _energy(runs["none"])
    err = np.max(np.abs(e_ref - e_ref[0]))
    excess = e_ref[0] - wobble["e_eq"]  # energy above the equilibrium the strip oscillates about
    assert err < 1e-3 and excess > 1.0, (err, excess)
    for k in DISSIPATIONS:
        if k == "none":
            continue
        e = _energy(runs[k])
        assert e[0] == e_ref[0], k
        rise = np.max(e - np.minimum.accumulate(e))
        assert rise <= 2.0 * err, (k, rise, err)
        # strictly lower at the end: at least a fifth of the excess dissipated (measured: drag
        # 0.69, viscosity 1.34, damping 0.87 B/L of 2.6)
        assert e[-1] < e_ref[-1] - 0.2 * excess, (k, e[-1], e_ref[-1], excess)
    # both together dissipate more than either alone
    both = _energy(runs["drag+viscosity"])[-1]
    assert both < min(_energy(runs["drag"])[-1], _energy(runs["viscosity"])[-1]) - 0.05 * excess


def _node_power(tr, wobble, name):
    """Power of the dissipative node forces from the frames' node speeds |v_k| (N+1 nodes,
    the clamped ends at rest): drag -c_d sum (m_k / lambda) |v_k|^3, damping -gamma sum m_k |v_k|^2."""
    m = np.asarray(wobble["d"].node_mass)
    sp = np.asarray(tr.speed)
    dis = DISSIPATIONS[name]
    if name == "drag":
        return -float(dis.drag) * np.sum((m / LAMBDA) * sp**3, axis=1)
    return -float(dis.damping) * np.sum(m * sp**2, axis=1)


@pytest.mark.parametrize("name", ["drag", "damping"])
def test_energy_loss_is_the_work_of_the_node_forces(wobble, name):
    """Quadratic drag -c_d (m_k/lambda) |v_k| v_k (and viscous damping -gamma m_k v_k): over
    each quarter of the run, the energy lost equals the integral of the analytic power
    evaluated on the trajectory's frames (measured agreement 4e-4 relative over the whole run).
    The check tells the forces apart: with the drag's power written as a linear damping's
    (|v|^2) or without the 1/lambda, it misses by 35 % and 100 %."""
    tr = wobble["runs"][name]
    e, tf = _energy(tr), np.asarray(tr.t_frames)
    work = _cumtrapz(_node_power(tr, wobble, name), tf)
    err = np.max(np.abs(_energy(wobble["runs"]["none"]) - _energy(wobble["runs"]["none"])[0]))
    edges = np.linspace(0, NS - 1, 5).astype(int)
    for a, b in zip(edges[:-1], edges[1:]):
        de, w = e[b] - e[a], work[b] - work[a]
        assert w < -0.05, (name, a, b, w)
        assert abs(de - w) <= 0.01 * abs(w) + 2.0 * err, (name, a, b, de, w)
    if name == "drag":  # what a wrong force law would have given: far outside the tolerance
        m, sp = np.asarray(wobble["d"].node_mass), np.asarray(tr.speed)
        c = float(DISSIPATIONS["drag"].drag)
        for wrong in (-c * np.sum((m / LAMBDA) * sp**2, 1), -c * np.sum(m * sp**3, 1)):
            assert abs(_cumtrapz(wrong, tf)[-1] - (e[-1] - e[0])) > 0.2 * abs(e[-1] - e[0])


def test_energy_loss_is_the_viscous_dissipation(wobble):
    """Kelvin-Voigt bending viscosity, Rayleigh function R = sum_k eta phidot_k^2 / (2 ell_k)
    over the N + 1 hinges (clamps held: the ghost segments do not turn): dE/dt = -2R. The
    hinge rates phidot_k are central differences of the frames' angles (spacing 4e-4 T),
    so the agreement is limited to ~0.3 % (measured); a factor 2 error in R would fail."""
    tr = wobble["runs"]["viscosity"]
    eta = float(DISSIPATIONS["viscosity"].viscosity)
    ell = np.asarray(wobble["d"].ell)
    th, tf = np.asarray(tr.theta), np.asarray(tr.t_frames)
    zeros = np.zeros((th.shape[0], 1))
    phi = np.diff(np.concatenate([zeros, th, zeros], 1), axis=1)  # (frames, N + 1) hinge angles minus clamps
    phidot = np.gradient(phi, tf, axis=0)
    work = _cumtrapz(-eta * np.sum(phidot**2 / ell, 1), tf)
    e = _energy(tr)
    edges = np.linspace(0, NS - 1, 5).astype(int)
    for a, b in zip(edges[:-1], edges[1:]):
        de, w = e[b] - e[a], work[b] - work[a]
        assert w < -0.05 and abs(de - w) <= 0.02 * abs(w), (a, b, de, w)


# --- gravity ---------------------------------------------------------------------------------

G = 10.0  # in B / (lambda L^3): a sag of the fold by ~2e-3 L, well resolved
T1_G = 0.1
NS_G = 4096  # fine-grid spacing 2.4e-5 T: resolves the first 2.5e-4 T of the release


@pytest.fixture(scope="module")
def gravity_runs():
    """The up state of Psi0 = 60 deg, G/L = 0.5 (N = 24) without gravity, the equilibrium of
    the same scene under gravity g = 10 (from `jr.solve_equilibrium`, started from the
    former), and both released at rest into the gravity scene with the clamps held."""
    plain = jr.make_scene(60.0, 0.5, 0.0, n=N)
    heavy = jr.make_scene(60.0, 0.5, 0.0, n=N, gravity=jr.Gravity(G))
    eq0 = jr.initial_state(plain, "up")
    eqg = jr.solve_equilibrium(heavy, eq0.theta, eq0.force)
    run = lambda th: jr.simulate(heavy, th, jr.Protocol(0.0, 0.0), t1=jnp.asarray(T1_G), n_fine=NS_G,  # noqa: E731
                                 n_frames=8, direction=-1.0)
    return dict(heavy=heavy, eq0=eq0, eqg=eqg, rest=run(eqg.theta), released=run(eq0.theta))


def test_gravity_equilibrium_stays_at_rest(gravity_runs):
    """The statics' equilibrium under gravity is an equilibrium of the dynamics' forces: it
    stays put (fold speed < 1e-7 v*; measured 2e-9, the Newton tolerance), where the
    no-gravity equilibrium, released into the same scene, moves (0.075 v* within 0.01 T).
    The gravity state sags below the plain one."""
    eq0, eqg = gravity_runs["eq0"], gravity_runs["eqg"]
    assert eq0.result == jr.RESULTS.successful and eqg.result == jr.RESULTS.successful
    assert int(eqg.num_unstable) == 0
    assert float(jr.fold_height(eq0)) - 5e-4 > float(jr.fold_height(eqg)) > 0.3
    rest, moved = gravity_runs["rest"], gravity_runs["released"]
    for tr in (rest, moved):
        assert tr.result == jr.RESULTS.successful and float(tr.t_end) == pytest.approx(T1_G)
        # undamped: E_k + V (gravity included) is conserved
        assert float(tr.energy_drift) < 1e-7, float(tr.energy_drift)
    fh = np.asarray(rest.fold_height)
    assert np.max(np.asarray(rest.fold_speed)) < 1e-7 and np.max(np.abs(fh - fh[0])) < 1e-10
    t = np.asarray(moved.t)
    assert np.max(np.asarray(moved.fold_speed)[t <= 0.01]) > 0.05


def test_gravity_potential_is_g_sum_m_y(gravity_runs):
    """V = E_b + g sum_k m_k y_k with the lumped node masses m_k = lambda (h_k + h_{k+1}) / 2
    and the node heights of the frames (gravity lowers the energy of low nodes)."""
    tr, d = gravity_runs["released"], discretize(gravity_runs["heavy"])
    h = np.asarray(d.h)
    m = np.concatenate([[h[0] / 2], (h[1:] + h[:-1]) / 2, [h[-1] / 2]])  # lambda = 1
    np.testing.assert_allclose(np.asarray(d.node_mass), m, rtol=1e-14)
    for i in (0, -1):
        y = np.asarray(tr.positions[i])[:, 1]
        k = np.argmin(np.abs(np.asarray(tr.t) - float(tr.t_frames[i])))
        assert float(tr.t[k]) == pytest.approx(float(tr.t_frames[i]), abs=1e-14)
        assert float(tr.potential[k]) == pytest.approx(float(tr.bending[k]) + G * np.sum(m * y), rel=1e-12)


def _gauss_acceleration(theta, scene, g):
    """Node accelerations (N - 1, 2) of the free nodes of a link chain at rest, both ends held,
    in equilibrium without gravity and then loaded by gravity: Gauss's principle, min
    sum_k m_k |a_k - g_vec|^2 / 2 subject to t_i . (a_i - a_{i-1}) = 0 for every link i
    (the second derivative of the link length at zero velocity) and a_0 = a_N = 0. The
    equilibrium's own forces are balanced by the constraints and drop out. Dense KKT, NumPy."""
    d = discretize(scene)
    m, th = np.asarray(d.node_mass)[1:-1], np.asarray(theta)
    n = th.shape[0]
    tan = np.stack([np.cos(th), np.sin(th)], 1)
    nu = 2 * (n - 1)
    C = np.zeros((n, nu))
    for i in range(n):  # link i joins node i and node i + 1 (0-based); unknown j is node j + 1
        if i + 1 <= n - 1:
            C[i, 2 * i:2 * i + 2] += tan[i]
        if i >= 1:
            C[i, 2 * (i - 1):2 * (i - 1) + 2] -= tan[i]
    M = np.diag(np.repeat(m, 2))
    f = (np.tile([0.0, -g], n - 1) * np.repeat(m, 2))
    K = np.block([[M, C.T], [C, np.zeros((n, n))]])
    return np.linalg.solve(K, np.concatenate([f, np.zeros(n)]))[:nu].reshape(n - 1, 2)


def test_released_strip_falls_at_the_constrained_rate(gravity_runs):
    """Released at rest from the no-gravity equilibrium, the fold starts to fall with the
    acceleration of Gauss's principle (-9.620 L/T^2 here, not the free fall -10: the links
    and the clamps carry part of the weight), read from the fold height's first 2.5e-4 T
    (11 samples, a quartic fit: 3e-6 relative; the highest bending modes ring with a period of
    2.7e-3 T, a cubic fit is 5e-4 off)."""
    tr = gravity_runs["released"]
    a = _gauss_acceleration(gravity_runs["eq0"].theta, gravity_runs["heavy"], G)
    a_fold = a[N // 2 - 1]  # node N/2, the fold
    assert abs(a_fold[0]) < 1e-10 and -G < a_fold[1] < -0.9 * G, a_fold  # symmetric state: straight down
    t, fh = np.asarray(tr.t), np.asarray(tr.fold_height)
    sel = t <= 2.5e-4
    assert sel.sum() >= 10
    ay = 2.0 * np.polyfit(t[sel], fh[sel] - fh[0], 4)[-3]
    assert ay == pytest.approx(a_fold[1], rel=1e-4), (ay, a_fold)
    assert abs(ay + G) > 0.02 * G  # distinguishable from free fall


# --- a physical strip --------------------------------------------------------------------------

PET = dict(youngs_modulus=4.5e9, density=1380.0, thickness=250e-6, width=0.02, length=0.2)  # docs/model.md's PET
RATE = 3.0  # rad/T: a fast symmetric ramp from the down state at alpha = 0, snaps up at ~0.58 T


@pytest.fixture(scope="module")
def pet_runs():
    E, rho, t, w, L = (PET[k] for k in ("youngs_modulus", "density", "thickness", "width", "length"))
    B, lam = E * t**3 * w / 12.0, rho * t * w  # by hand (docs/model.md)
    vstar = math.sqrt(B / (lam * L**2))
    T = L / vstar
    psi0 = math.radians(30.0)
    nondim = jr.make_scene(30.0, 0.5, 0.0, n=N)
    strip = jr.Strip.from_physical(psi0=psi0, **PET)
    physical = jr.Scene(strip, jr.Clamps.symmetric(0.5 * L), jr.Mesh(N))
    eq = jr.initial_state(nondim, "down")  # the angles are the same in any units
    tn = jr.simulate(nondim, eq.theta, jr.Protocol(0.0, 0.0, RATE, RATE), t1=jnp.asarray(T1), n_fine=NS,
                     n_frames=NS)
    tp = jr.simulate(physical, eq.theta, jr.Protocol(0.0, 0.0, RATE / T, RATE / T), t1=jnp.asarray(T1 * T),
                     n_fine=NS, n_frames=NS)
    return dict(B=B, lam=lam, vstar=vstar, T=T, L=L, strip=strip, tn=tn, tp=tp)


def test_from_physical_strip_fields(pet_runs):
    r = pet_runs
    st = r["strip"]
    assert float(st.bending_stiffness) == pytest.approx(r["B"], rel=1e-14)
    assert float(st.line_density) == pytest.approx(r["lam"], rel=1e-14)
    assert float(st.length) == r["L"] and float(st.s0) == pytest.approx(0.02 * r["L"], rel=1e-14)
    assert float(st.speed_gauge) == pytest.approx(r["vstar"], rel=1e-14)
    # docs/model.md's closed form, independent of the width: v* = (t / L) sqrt(E / (12 rho))
    closed = PET["thickness"] / r["L"] * math.sqrt(PET["youngs_modulus"] / (12 * PET["density"]))
    assert r["vstar"] == pytest.approx(closed, rel=1e-14)
    assert float(st.time_unit) == pytest.approx(r["T"], rel=1e-14)


def test_physical_snap_scales_by_v_star_and_T(pet_runs):
    """The same snap (same angles, clamps ramped at RATE / T rad/s) on the PET strip in SI
    units and on the nondimensional strip: v_s in m/s = v_s in v* times v* (by hand), every
    time in s = the time in T times T, energies scale by B / L, positions by L."""
    r = pet_runs
    tn, tp = r["tn"], r["tp"]
    for tr in (tn, tp):
        assert tr.result == jr.RESULTS.successful and bool(tr.snapped)
        assert float(tr.t_end) < float(tr.t[-1])  # stopped at the first overshoot, before t1
    assert 10.0 < float(tn.v_s) < 40.0  # a snap, v_s ~ 17 v*
    assert float(tp.v_s) == pytest.approx(float(tn.v_s) * r["vstar"], rel=1e-6)
    for k in ("t_peak", "t_cross", "t_end"):
        assert float(getattr(tp, k)) == pytest.approx(float(getattr(tn, k)) * r["T"], rel=1e-6), k
    assert float(tp.kinetic_peak) == pytest.approx(float(tn.kinetic_peak) * r["B"] / r["L"], rel=1e-6)
    np.testing.assert_allclose(np.asarray(tp.fold_speed), np.asarray(tn.fold_speed) * r["vstar"], rtol=1e-6,
                               atol=1e-6 * float(tp.v_s))
    ok = np.asarray(tn.t_frames) <= float(tn.t_end)
    np.testing.assert_allclose(np.asarray(tp.positions)[ok], np.asarray(tn.positions)[ok] * r["L"], rtol=0,
                               atol=1e-6 * r["L"])
