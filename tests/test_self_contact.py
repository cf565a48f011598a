"""Self-contact (`jaxrod.Contact`): the penalty, its derivatives against autodiff and central
differences, the dense bordered Hessian's linear algebra against dense NumPy, the
continuous collision bound, equilibria pressed against themselves (never crossing, fuzzed
over small gaps and clamp angles), unchanged results where the strip stays clear, and the
energy of an undamped run with contacts."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from jaxrod.energy import contact as C
from jaxrod.energy.lagrangian import lagrangian, lagrangian_gradient
from jaxrod.linalg import kkt
from helpers import np_crossings

N = 24
THICKNESS = 0.02
"""The contact thickness of this module's scenes: at N = 24 (segments of 0.042 L) the default 0.01 L
is under-resolved (`contact_underresolved`, `jaxrod.energy.contact.CONTACT_RESOLUTION`)."""


def _scene(psi0=180.0, gap=0.1, alpha=0.0, n=N, contact=True, **kw):
    kw.setdefault("thickness", THICKNESS)
    return jr.make_scene(psi0, gap, alpha, n=n, contact=jr.Contact(**kw) if contact else None)


def _angles(seed, n=N, scale=0.7):
    return jnp.asarray(np.random.default_rng(seed).normal(size=n)) * scale


@pytest.fixture(scope="module")
def pressed():
    """The flat strip's up state at G/L = 0.1 with contact: its legs pressed together."""
    return jr.initial_state(_scene(), "up")


# ------------------------------------------------------------------ the contact law
def test_penalty_vanishes_smoothly_at_the_thickness():
    """phi, phi' and phi'' are continuous and zero at d = delta (a contact opening or closing
    is smooth for Newton); phi' = -k (1 - d/delta)^2 is the line force."""
    delta, k = 0.01, 3.0e4
    phi = lambda d: C.penalty(d, delta, k)  # noqa: E731
    d1, d2 = jax.grad(phi), jax.grad(jax.grad(phi))
    for f, scale in ((phi, k * delta), (d1, k), (d2, k / delta)):
        assert float(f(jnp.asarray(delta))) == 0.0
        assert float(f(jnp.asarray(1.5 * delta))) == 0.0
        assert abs(float(f(jnp.asarray(delta * (1 - 1e-6))))) < 1e-5 * scale
    d = jnp.asarray(0.4 * delta)
    assert float(d1(d)) == pytest.approx(-k * 0.6**2, rel=1e-12)


def test_line_distance_rounded_off_smoothly():
    """`smooth_abs` equals |s| from eps on and meets it there with equal value, slope and
    curvature; it is even and smooth at 0. A node crossing the line of a segment half a
    segment past its end (where the window still acts) feels a continuous force, where
    |s| would jump it by the penalty's slope times the window; over the segment the
    penalty acts on the exact distance."""
    eps = 1e-3
    f = lambda s: C.smooth_abs(s, eps)  # noqa: E731
    d1, d2 = jax.grad(f), jax.grad(jax.grad(f))
    for s in (eps, -eps, 2 * eps, 0.5):
        assert float(f(jnp.asarray(s))) == pytest.approx(abs(s), rel=1e-14)
    for sgn in (1.0, -1.0):
        lo, hi = jnp.asarray(sgn * eps * (1 - 1e-9)), jnp.asarray(sgn * eps * (1 + 1e-9))
        assert abs(float(f(lo)) - float(f(hi))) < 3e-9 * eps  # the inputs are 2e-9 eps apart
        assert float(d1(lo)) == pytest.approx(float(d1(hi)), abs=1e-8)
        assert abs(float(d2(lo)) - float(d2(hi))) < 1e-5 / eps
    assert float(d1(jnp.asarray(0.0))) == 0.0 and float(f(jnp.asarray(0.0))) == pytest.approx(0.375 * eps)
    assert float(f(jnp.asarray(0.3 * eps))) == pytest.approx(float(f(jnp.asarray(-0.3 * eps))), abs=0.0)
    # node p moving across the line y = 0 of the segment [(0, 0), (1, 0)] at t = -0.42
    delta, k = 0.01, 1e5
    grad = jax.grad(lambda y: C._pair_energy(jnp.array([-0.42, y, 0.0, 0.0, 1.0, 0.0]), delta, k))
    below, above = float(grad(jnp.asarray(-1e-9))), float(grad(jnp.asarray(1e-9)))
    assert abs(below - above) < 1e-3 * k * float(C.window(jnp.asarray(-0.42)))
    assert abs(float(grad(jnp.asarray(0.5 * delta)))) > 1.0  # a real force further out
    # over the segment itself the distance is exact: the full force k (1 - d/delta)^2 however deep
    inside = jax.grad(lambda y: C._pair_energy(jnp.array([0.5, y, 0.0, 0.0, 1.0, 0.0]), delta, k))
    for y in (0.5 * delta, 0.05 * delta, 1e-4 * delta):
        assert float(inside(jnp.asarray(y))) == pytest.approx(-k * (1 - y / delta) ** 2, rel=1e-12)
    assert float(C.tail(jnp.asarray(0.0))) == float(C.tail(jnp.asarray(1.0))) == 0.0
    assert float(C.tail(jnp.asarray(-0.5))) == float(C.tail(jnp.asarray(1.5))) == 1.0


def test_no_force_while_clear():
    """A state whose contact pairs are all farther apart than delta feels no contact energy or
    force: results without contact are unchanged wherever the clearance stays above it."""
    sc = _scene(gap=0.5)
    f = np.asarray(sc.mesh.fractions)
    th = jnp.asarray(1.2 * np.sin(2 * np.pi * 0.5 * (f[1:] + f[:-1])))  # an arch, far from itself
    assert float(jr.clearance(th, sc, min_separation=3)) > 0.05
    assert float(C.contact_energy(th, sc)) == 0.0
    assert float(jnp.max(jnp.abs(jax.grad(C.contact_energy)(th, sc)))) == 0.0


@pytest.mark.parametrize("thickness", [THICKNESS, 0.3])
def test_hessian_against_autodiff(thickness, pressed):
    """The suffix-sum Hessian equals autodiff's, both with few pairs that can interact (the
    pressed strip: they are gathered into the K slots) and with more than K (a crumpled
    strip with a thick contact layer: assembled in several chunks of K)."""
    sc = _scene(thickness=thickness, stiffness=10.0)
    th = _angles(0, scale=2.0) if thickness > 0.1 else pressed.theta
    d = jr.discretize(sc)
    p, j = C.contact_pairs(sc)
    z = C._pair_coordinates(C.inextensible_nodes(th, d), p, j)
    mask = C._may_interact(z, thickness)
    live = int(jnp.sum(mask))
    # the pairs left out have no energy (nor, with it, gradient or Hessian)
    e = jax.vmap(C._pair_energy, (0, None, None))(z, thickness, 10.0)
    assert float(jnp.max(jnp.abs(jnp.where(mask, 0.0, e)))) == 0.0 and float(jnp.max(e)) > 0.0
    K = max(64, 2 * N)
    assert (live > K) if thickness > 0.1 else (0 < live <= K), live
    H1 = jax.hessian(C.contact_energy)(th, sc)
    H2 = C.contact_hessian(th, sc)
    assert float(jnp.max(jnp.abs(H1))) > 0.0
    np.testing.assert_allclose(np.asarray(H2), np.asarray(H1), atol=1e-12 * float(jnp.max(jnp.abs(H1))))


def test_gradient_and_hessian_of_the_lagrangian(pressed):
    """The written-out gradient with contact against autodiff of the scalar Lagrangian and
    against central differences; the structured Hessian is the dense form."""
    sc = pressed.scene
    assert float(C.contact_energy(pressed.theta, sc)) > 0.0  # contact is active here
    th, mu = pressed.theta + 1e-3 * _angles(1), pressed.force
    g = jnp.concatenate(lagrangian_gradient(th, mu, sc))
    z = jnp.concatenate([th, mu])
    L = lambda z: lagrangian(z[:N], z[N:], sc)  # noqa: E731
    np.testing.assert_allclose(np.asarray(g), np.asarray(jax.grad(L)(z)), atol=1e-10)
    e = jnp.zeros(N + 2).at[3].set(1.0)
    fd = (L(z + 1e-6 * e) - L(z - 1e-6 * e)) / 2e-6
    assert float(g[3]) == pytest.approx(float(fd), rel=1e-6, abs=1e-8)
    assert isinstance(kkt.structured(th, mu, sc), kkt.BorderedDense)


@pytest.mark.slow  # 10 s of compile: the contact part alone is checked in CI (test_hessian_against_autodiff)
def test_structured_hessian_of_the_lagrangian(pressed):
    """The dense structured Hessian with contact against autodiff's of the scalar Lagrangian."""
    sc = pressed.scene
    th, mu = pressed.theta + 1e-3 * _angles(1), pressed.force
    z = jnp.concatenate([th, mu])
    L = lambda z: lagrangian(z[:N], z[N:], sc)  # noqa: E731
    K = kkt.structured(th, mu, sc)
    np.testing.assert_allclose(np.asarray(K.dense()), np.asarray(jax.hessian(L)(z)), atol=1e-9)


# ------------------------------------------------------------------ dense bordered algebra
@pytest.mark.parametrize("stretch", [False, True])
def test_dense_bordered_algebra(stretch):
    """count_below, the smallest constrained eigenvalues, solve and modes of a BorderedDense
    against dense NumPy: with rigid end constraints (C = 0, eigenvalues of A on the null space
    of P^T) and with a compliance (C negative definite: A - P C^-1 P^T)."""
    rng = np.random.default_rng(3)
    n = 12
    A = rng.normal(size=(n, n))
    A = A + A.T
    P = rng.normal(size=(n, 2))
    Cm = -np.array([[2.0, 0.3], [0.3, 1.0]]) if stretch else np.zeros((2, 2))
    K = kkt.BorderedDense(jnp.asarray(A), jnp.asarray(P), jnp.asarray(Cm))
    if stretch:
        ref = np.linalg.eigvalsh(A - P @ np.linalg.solve(Cm, P.T))
    else:
        Z = np.linalg.qr(P, mode="complete")[0][:, 2:]
        ref = np.linalg.eigvalsh(Z.T @ A @ Z)
    np.testing.assert_allclose(np.asarray(kkt.smallest_eigenvalues(K, 4)), ref[:4], atol=1e-10)
    shifts = jnp.asarray([ref[0] - 0.1, 0.5 * (ref[1] + ref[2]), ref[5] + 1e-6])
    assert np.asarray(kkt.count_below(K, shifts)).tolist() == [0, 2, 6]
    r = rng.normal(size=n + 2)
    a, b = kkt.solve(K, jnp.asarray(r[:n]), jnp.asarray(r[n:]), shift=0.3)
    M = np.block([[A - 0.3 * np.eye(n), P], [P.T, Cm]])
    np.testing.assert_allclose(np.concatenate([a, b]), np.linalg.solve(M, r), rtol=1e-9, atol=1e-10)
    v = np.asarray(kkt.modes(K, kkt.smallest_eigenvalues(K, 2)))
    lam = np.asarray(kkt.smallest_eigenvalues(K, 2))
    for k in range(2):  # (A - lam) v + P w = 0 with P^T v + C w = 0
        w = np.linalg.lstsq(np.vstack([P, Cm]), -np.concatenate([(A - lam[k] * np.eye(n)) @ v[:, k], P.T @ v[:, k]]),
                            rcond=None)[0]
        assert np.linalg.norm((A - lam[k] * np.eye(n)) @ v[:, k] + P @ w) < 1e-6


# ------------------------------------------------------------------ continuous collision bound
@pytest.mark.parametrize("seed", range(6))
def test_step_bound_never_crosses(pressed, seed):
    """Along theta + tau' step, 0 <= tau' <= step_bound, no two parts of the strip meet:
    large random steps from the pressed state, checked at 200 points of the path with the
    independent NumPy crossing test."""
    sc = pressed.scene
    step = _angles(10 + seed, scale=0.5)
    tau = float(C.step_bound(pressed.theta, step, sc))
    assert 0.0 < tau < 1.0  # the pressed legs limit the step
    d = jr.discretize(sc)
    ex = sc.contact.exclusion
    f = np.asarray(sc.mesh.fractions)
    for s in np.linspace(0.0, tau, 200):
        x = np.asarray(C.inextensible_nodes(pressed.theta + s * step, d))
        far = [(i, j) for i, j in np_crossings(x) if f[j] - f[i + 1] >= ex]
        assert not far, (s, far)


def test_landing_push_never_crosses():
    """The push that starts a landing after a loss of stability (`_land`: 0.05 rad along the
    unstable mode) is bounded like a Newton step. The flat strip pressed at G/L = 0.1 with a
    thin contact (0.005 L): the full push that turns the two halves of the strip against
    each other carries the legs through each other; `_land`, which picks the push's side by
    the fold height (both sides tried here), starts and ends clear of itself."""
    from jaxrod.branches._landing import _land
    from jaxrod.branches._continuation import SymmetricAlpha
    from jaxrod.statics import Newton

    eq = jr.initial_state(_scene(thickness=0.005), "up")
    # a thickness an eighth of the segment: a valid state, flagged as under-resolved
    assert eq.result == jr.RESULTS.contact_underresolved
    sc, d = eq.scene, jr.discretize(eq.scene)
    v = jnp.where(jnp.arange(N) < N // 2, 1.0, -1.0)
    v = v / jnp.linalg.norm(v)
    crosses = lambda t: bool(np_crossings(np.asarray(C.inextensible_nodes(t, d))))  # noqa: E731
    assert crosses(eq.theta + 0.05 * v) or crosses(eq.theta - 0.05 * v)
    for up in (True, False):
        t, _, _, landed = _land(sc, SymmetricAlpha(), eq.theta, eq.force, jnp.zeros(()), v, 1.0, up, Newton())
        assert bool(landed.converged) and not crosses(t), up


# ------------------------------------------------------------------ equilibria in contact
def test_pressed_state(pressed):
    """At G/L = 0.1 the contact-free up state of the flat strip passes through itself; with
    contact it is a stable equilibrium, clear of itself, with its legs inside the contact
    thickness and the penetration that the stiffness predicts (line load f: sinks to
    delta (1 - sqrt(f / k)), here under 25 % of delta)."""
    free = jr.initial_state(_scene(contact=False), "up")
    assert free.result == jr.RESULTS.self_intersecting
    eq = pressed
    assert eq.result == jr.RESULTS.successful, jr.RESULTS[eq.result]
    sc = eq.scene
    m = max(N // 10, 2)
    c = float(jr.clearance(eq.theta, sc, min_separation=m))
    delta = float(sc.contact.thickness)
    assert 0.75 * delta < c < delta
    assert not np_crossings(np.asarray(jr.node_positions(eq)))
    assert float(jr.energies(eq)["contact"]) > 0.0
    assert float(jr.stability(eq).eigenvalues[0]) > 0.0


def test_stiffness_limit():
    """The penalty's hard-contact limit: the flat strip pressed at G/L = 0.1 with k = 1e4 to
    1e7 B/L^3. A line load f sinks a node to delta (1 - sqrt(f / k)), so the penetration and
    the contact energy (~ f^1.5 delta / sqrt(k)) fall by about sqrt(10) = 3.16 per decade of
    k while the load is carried by the same nodes (measured: penetration 5.1e-3 -> 1.6e-3
    from 1e4 to 1e5; energy 0.36, 0.13, 0.047, 0.020), and the shape converges to the
    hard-contact state (fold height changes of 7e-4, 2e-4, 3e-5 per decade): every state a
    stable equilibrium that does not cross itself."""
    ks = [1e4, 1e5, 1e6, 1e7]
    pen, energy, fold = [], [], []
    for k in ks:
        # the default thickness, whose measured numbers the docstring gives: on N = 24 segments it is
        # under-resolved, and says so; the penalty's limit is the same question at any mesh
        sc = _scene(stiffness=k, thickness=0.01)
        eq = jr.initial_state(sc, "up")
        assert eq.result == jr.RESULTS.contact_underresolved, (k, jr.RESULTS[eq.result])
        assert float(jr.stability(eq).eigenvalues[0]) > 0.0
        assert not np_crossings(np.asarray(jr.node_positions(eq)))
        pen.append(float(sc.contact.thickness) - float(jr.clearance(eq.theta, sc, min_separation=max(N // 10, 2))))
        energy.append(float(jr.energies(eq)["contact"]))
        fold.append(float(jr.fold_height(eq)))
    assert 2.5 < pen[0] / pen[1] < 4.0, pen
    ratios = np.asarray(energy[:-1]) / np.asarray(energy[1:])
    assert np.all((ratios > 2.0) & (ratios < 4.0)), energy
    steps = np.abs(np.diff(fold))
    assert np.all(steps[1:] < 0.5 * steps[:-1]) and steps[-1] < 1e-4, fold


def test_pressed_states_never_cross():
    """Fuzz: up and down states at gaps 0.04-0.14 and clamp angles within +-30 deg, with
    contact: every one found is a stable equilibrium that does not pass through itself."""
    rng = np.random.default_rng(7)
    found = 0
    for k in range(6):
        g = float(rng.uniform(0.04, 0.14))
        a = float(rng.uniform(-30.0, 30.0))
        psi = float(rng.choice([60.0, 120.0, 180.0]))
        eq = jr.initial_state(_scene(psi, g, a), "up" if k % 2 else "down")
        assert eq.result in (jr.RESULTS.successful, jr.RESULTS.state_not_found), jr.RESULTS[eq.result]
        if eq.result == jr.RESULTS.successful:
            found += 1
            assert not np_crossings(np.asarray(jr.node_positions(eq))), (psi, g, a)
            assert float(jr.stability(eq).eigenvalues[0]) > 0.0
    assert found >= 4


def test_clear_states_unchanged():
    """Where the strip stays more than delta from itself (G/L = 0.3) contact changes nothing:
    the same state to the Newton tolerance."""
    a = jr.initial_state(_scene(60.0, 0.3, 10.0), "up")
    b = jr.initial_state(_scene(60.0, 0.3, 10.0, contact=False), "up")
    assert a.result == b.result == jr.RESULTS.successful
    assert float(jr.clearance(a.theta, a.scene, min_separation=max(N // 10, 2))) > 0.01
    np.testing.assert_allclose(np.asarray(a.theta), np.asarray(b.theta), atol=1e-9)


def test_bad_contact_input():
    for kw, name in [({"thickness": -0.01}, "thickness"), ({"stiffness": 0.0}, "stiffness"),
                     ({"exclusion": 1.5}, "exclusion")]:
        with pytest.raises(ValueError, match=name):
            jr.Contact(**kw)
    with pytest.raises(ValueError, match="contact"):
        jr.make_scene(60, 0.5, contact=0.01)


# ------------------------------------------------------------------ dynamics with contact
def test_undamped_run_with_contact_conserves_energy(pressed):
    """The pressed state at G/L = 0.1 kicked along its lowest mode (the pressed legs slide
    and knock against each other), undamped, 0.5 T: the energy balance closes
    to 1e-3 of the potential energy and no frame passes through itself."""
    sc = pressed.scene
    # the lowest constrained mode (it keeps the right end still), as an angular velocity
    omega0 = 100.0 * jr.stability(pressed).modes[:, 0]
    tr = jr.simulate(sc, pressed.theta, jr.Protocol(), omega0=omega0, t1=0.5, stop_at_snap=False,
                     n_frames=16, energy_tol=1e-3)
    assert tr.result == jr.RESULTS.successful, jr.RESULTS[tr.result]
    E = np.asarray(tr.kinetic + tr.potential - tr.clamp_work)
    ok = np.isfinite(E)
    err = np.abs(E[ok] - E[0]).max() / float(tr.potential[0])
    assert err < 1e-3, err
    assert float(np.max(np.asarray(tr.kinetic))) > 0.1 * float(tr.potential[0])  # a real kick
    for x in np.asarray(tr.positions):
        assert not np_crossings(x)
    ec = np.array([float(C.contact_energy(t, sc)) for t in tr.theta])
    assert np.all(ec[np.isfinite(ec)] > 0.0) and np.ptp(ec) > 0.1 * ec[0]  # in contact throughout, working


# ------------------------------------------------------------------ the phase diagram (the snap paths, the brink after
# clicks and the CLI's clicks are in test_contact_paths.py)
@pytest.mark.slow  # 49 s on 2 cores: contact snap paths at small gaps are in CI through test_contact_paths.py
def test_phase_diagram_with_contact_to_small_gaps():
    """The phase diagram with contact down to G/L = 0.05: every path successful on a small
    grid where the contact-free one is flagged self_intersecting at the small gaps."""
    gaps = [0.05, 0.1, 0.2]
    ds = jr.phase_diagram([60.0, 180.0], gaps, n=48, contact=jr.Contact(), progress=False)
    ok = int(jr.RESULTS.successful._value)
    assert np.all(np.asarray(ds["result_up"]) == ok) and np.all(np.asarray(ds["result_down"]) == ok)
    assert np.all(np.isfinite(np.asarray(ds["alpha_c_up"])))
    assert "thickness 0.01" in ds.attrs["contact"]


# ------------------------------------------------------------------ CLI
def _cli(args, capsys):
    from jaxrod.cli import main

    old = jax.config.jax_enable_x64
    try:
        code = main(args)
    finally:
        jax.config.update("jax_enable_x64", old)
    return code, *capsys.readouterr()


def test_cli_contact_by_default_where_needed(capsys):
    """`jaxrod equilibrium` at G/L = 0.1: by default contact is switched on because the
    contact-free state passes through itself; `--no-contact` reports that state flagged."""
    import json

    base = ["equilibrium", "--psi0", "180", "--gap", "0.1", "--state", "up", "--n", str(N), "--json"]
    code, out, _ = _cli(base, capsys)
    rec = json.loads(out)
    # the default thickness (0.01 L) on segments of 0.042 L: the state is flagged, exit 3
    assert code == 3 and rec["contact"] is True and rec["contact_thickness"] == 0.01
    assert rec["result_code"] == "contact_underresolved"
    code, out, _ = _cli(base + ["--contact-thickness", str(THICKNESS)], capsys)
    rec = json.loads(out)
    assert code == 0 and rec["contact"] is True and rec["contact_thickness"] == THICKNESS
    assert 0.75 * THICKNESS < rec["clearance"] < THICKNESS and rec["contact_energy"] > 0.0
    code, out, _ = _cli(base + ["--no-contact"], capsys)
    rec = json.loads(out)
    assert code == 3 and rec["contact"] is False and rec["result_code"] == "self_intersecting"
    code, out, _ = _cli(["equilibrium", "--psi0", "180", "--gap", "0.5", "--n", str(N), "--json"], capsys)
    rec = json.loads(out)
    assert code == 0 and rec["contact"] is False and rec["clearance"] > 0.01  # not needed: not modelled


@pytest.mark.parametrize("args,name", [(["--contact-thickness", "0"], "thickness"),
                                       (["--contact-thickness", "0.02", "--no-contact"], "contact-thickness")])
def test_cli_bad_contact_options(args, name, capsys):
    code, out, err = _cli(["equilibrium", *args], capsys)
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and name in err and "Traceback" not in err


def test_contact_in_physical_units():
    """`Contact.for_strip`: the physical thickness, and the stiffness 1e5 B/L^3 in the strip's
    own units, so that the same strip in SI units has the same contact as in L = B = 1."""
    st = jr.Strip.from_physical(youngs_modulus=4.5e9, density=1380.0, thickness=250e-6, width=0.02, length=0.2)
    c = jr.Contact.for_strip(st, thickness=250e-6)
    B, L = float(st.bending_stiffness), float(st.length)
    assert float(c.thickness) == 250e-6
    assert float(c.stiffness) == pytest.approx(1e5 * B / L**3, rel=1e-12)
    d = jr.Contact.for_strip(jr.Strip())
    assert float(d.thickness) == pytest.approx(0.01) and float(d.stiffness) == pytest.approx(1e5)


def test_trajectory_through_itself_is_flagged():
    """Psi0 = 180 deg at G/L = 0.1: without contact the snap's saved frames pass through
    themselves, and the run says so (`self_intersecting`, not `successful`)."""
    free = jr.make_scene(180, 0.1, n=24)
    _, tr = jr.snap_dynamics(free, "up")
    assert tr.result == jr.RESULTS.self_intersecting


@pytest.mark.slow  # 15-25 s of a contact program on 2 cores; contact dynamics are in CI elsewhere
def test_trajectory_with_contact_is_valid():
    """The same snap with the contact model at N = 24 is a valid motion (a contact thickness the
    mesh resolves); with the default thickness, too thin for N = 24, the run says so."""
    _, tr = jr.snap_dynamics(jr.make_scene(180, 0.1, n=24, contact=jr.Contact(thickness=THICKNESS)), "up")
    assert tr.result == jr.RESULTS.successful and bool(tr.snapped)
    _, tr = jr.snap_dynamics(jr.make_scene(180, 0.1, n=24, contact=jr.Contact()), "up")
    assert tr.result == jr.RESULTS.contact_underresolved
