"""Strips with several creases (`jr.Creases`): identity with the centred crease, mirror
symmetry, the kinds of the critical points against dense eigenvalues, gradients with respect
to the crease positions, the merging limit, the mesh and bad input.

Every scene here has N = 48 on a uniform mesh (2 s0 = 0.04 > h = 0.021), so the
crease scenes share one compiled program per structure (one crease set size)."""

from __future__ import annotations

import json
import math
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from helpers import central_difference, solve

N = 48


def pair(c_left, c_right, psi_left=90.0, psi_right=90.0, gap=0.5):
    """A flat strip with two creases (positions in L, angles in degrees)."""
    return jr.make_scene(180.0, gap, n=N, creases=[(c_left, psi_left), (c_right, psi_right)])


def test_one_centred_crease_is_the_classic_strip():
    """A crease set holding one crease at L/2 turns exactly like the strip's own crease, at
    every stage of the homotopy that builds initial states, so the states are the same to
    round-off (the two are different compiled programs)."""
    a = jr.make_scene(60.0, 0.5, n=N)
    b = jr.make_scene(180.0, 0.5, n=N, creases=[(0.5, 60.0)])
    assert a.strip.creases is None and b.strip.creases.count == 1
    for u in (0.0, 0.3, 1.0):
        da = jr.discretize(eqx.tree_at(lambda s: s.strip, a, a.strip.unfolded(u)))
        db = jr.discretize(eqx.tree_at(lambda s: s.strip, b, b.strip.unfolded(u)))
        np.testing.assert_array_equal(np.asarray(da.phi0), np.asarray(db.phi0))
    ea, eb = jr.initial_state(a, "up"), jr.initial_state(b, "up")
    assert ea.result == eb.result == jr.RESULTS.successful
    np.testing.assert_allclose(np.asarray(ea.theta), np.asarray(eb.theta), rtol=0, atol=1e-13)
    assert float(jr.crease_heights(eb)[0]) == pytest.approx(float(jr.fold_height(ea)), abs=1e-14)


def test_crease_profiles_add():
    """theta0 is the sum of the single-crease profiles; each crease turns by Psi_k - pi."""
    sc = pair(0.3, 0.7, 90.0, 120.0)
    s = jnp.linspace(0.0, 1.0, 1001)
    th = sc.strip.natural_angle(s)
    one = lambda c, p: 0.5 * (math.radians(p) - math.pi) * np.tanh((np.asarray(s) - c) / 0.02)  # noqa: E731
    np.testing.assert_allclose(np.asarray(th), one(0.3, 90.0) + one(0.7, 120.0), atol=1e-15)
    d = jr.discretize(sc)
    left = np.asarray(d.phi0)[: N // 2].sum()  # the crease at 0.3 turns in the left half
    assert left == pytest.approx(math.radians(90.0) - math.pi, abs=1e-6)


def test_two_creases_merge_into_one_of_the_summed_angle():
    """Creases at L/2 -+ d tend, as d -> 0, to one crease of the summed angle: two of 135 deg
    to one of 135 + 135 - 180 = 90 deg, the states' difference falling as d^2 (the profiles'
    first-order terms cancel); 150 and 120 deg (also 90 deg together) as d (they do not).
    At d = 0 the two are one crease exactly."""
    one = jr.initial_state(jr.make_scene(90.0, 0.5, n=N), "up")
    # measured rates, d = 0.01 -> 3e-4: 1.88 ... 2.00 and 1.28 ... 1.03; checked where asymptotic
    for (pa, pb), order in (((135.0, 135.0), 2.0), ((150.0, 120.0), 1.0)):
        errs = []
        for d in (0.0025, 0.00125, 0.000625):
            eq = jr.initial_state(pair(0.5 - d, 0.5 + d, pa, pb), "up")
            assert eq.result == jr.RESULTS.successful
            errs.append(float(jnp.max(jnp.abs(eq.theta - one.theta))))
        rates = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
        assert np.all(np.abs(rates - order) < 0.15), (pa, pb, errs, rates)
        merged = jr.initial_state(pair(0.5, 0.5, pa, pb), "up")
        np.testing.assert_allclose(np.asarray(merged.theta), np.asarray(one.theta), atol=1e-10)


@pytest.fixture(scope="module")
def symmetric_pair():
    return jr.snap_angles(pair(0.25, 0.75))


@pytest.fixture(scope="module")
def asymmetric_pair():
    return jr.snap_angles(pair(0.3, 0.65))


def _reduced_eigenvalues(path, scene):
    sc = jr.SymmetricAlpha().set(scene, path.alpha_c)
    eq = solve(sc, path.theta_before, path.force_before)
    return np.linalg.eigvalsh(np.asarray(jr.dense_reduced_hessian(eq))), eq


def test_symmetric_pair_keeps_mirror_symmetry_and_branch_points(symmetric_pair):
    """A mirror-symmetric set (creases of 90 deg at 0.25 L and 0.75 L, G/L = 0.5): the
    critical states are mirror images of themselves, theta(s) = -theta(L - s), with both
    creases at one height. The up path snaps at a symmetric fold, the down path at a branch
    point; at each, the dense reduced Hessian has one zero eigenvalue and the critical mode
    has the parity its kind says (+1 fold, -1 branch point)."""
    sc = pair(0.25, 0.75)
    assert sc.strip.creases.is_mirror_symmetric(1.0)
    for name, kind in (("up", "fold"), ("down", "branch_point")):
        p = getattr(symmetric_pair, name)
        assert p.result == jr.RESULTS.successful and bool(p.snaps)
        assert jr.KIND_NAMES[int(p.kind)] == kind
        w, eq = _reduced_eigenvalues(p, sc)
        assert abs(w[0]) < 1e-6 * abs(w[1])
        t = np.asarray(p.theta_before)
        assert np.max(np.abs(t + t[::-1])) < 1e-6
        parity = float(jr.statics.mode_parity(p.mode[:, None])[0])
        assert parity > 0.99 if kind == "fold" else parity < -0.99
        h = np.asarray(jr.crease_heights(eq))
        assert h[0] == pytest.approx(h[1], abs=1e-8)


def test_asymmetric_pair_snaps_at_folds(asymmetric_pair):
    """An asymmetric set breaks the pitchfork: every loss of stability is a fold (the lowest
    eigenvalue of the dense reduced Hessian vanishes, and the strip jumps to the other side)."""
    sc = pair(0.3, 0.65)
    assert not sc.strip.creases.is_mirror_symmetric(1.0)
    for name, sgn in (("up", 1.0), ("down", -1.0)):
        p = getattr(asymmetric_pair, name)
        assert p.result == jr.RESULTS.successful and bool(p.snaps)
        assert jr.KIND_NAMES[int(p.kind)] == "fold"
        w, _ = _reduced_eigenvalues(p, sc)
        assert abs(w[0]) < 1e-6 * abs(w[1]) and w[1] > 0
        assert sgn * float(p.fold_height_before) < 0 < sgn * float(p.fold_height_after)


def test_alpha_c_gradient_in_crease_positions_matches_central_differences(asymmetric_pair):
    """d alpha_c / d(c_1, c_2) at the folds of an asymmetric set: the implicit derivative of
    the extended system (`jr.critical_point`, what `snap_angles` differentiates) against
    central differences of its re-solves from the same start."""
    base = pair(0.3, 0.65)

    @jax.jit
    def alpha(c, path):
        sc = eqx.tree_at(lambda s: s.strip.creases.positions, base, c)
        return jr.critical_point(sc, path.theta_before, path.force_before, path.alpha_c, path.mode,
                                 path.kind).alpha

    c0 = jnp.asarray([0.3, 0.65])
    for path in (asymmetric_pair.up, asymmetric_pair.down):
        assert float(alpha(c0, path)) == pytest.approx(float(path.alpha_c), abs=1e-9)
        g = jax.jit(jax.grad(alpha))(c0, path)
        fd = central_difference(lambda c: alpha(c, path)[None], c0, scale=[0.1, 0.1])[0]
        assert np.all(np.abs(np.asarray(g)) > 1e-3)
        np.testing.assert_allclose(np.asarray(g), np.asarray(fd), rtol=1e-6)


def test_branch_point_derivative_is_the_symmetric_familys(symmetric_pair):
    """At the branch point of a symmetric pair (the down path) alpha_c is differentiable
    only along mirror-symmetric changes: spreading the creases apart symmetrically matches
    central differences of re-solves (which stay symmetric); the derivative along a shift of
    both creases (antisymmetric) is zero, so moving one crease counts half of the spread;
    whole snap paths of shifted pairs show why: alpha_c moves the same way for either
    sign of the shift, like |shift|^(2/3) (an imperfect pitchfork)."""
    base = pair(0.25, 0.75)
    path = symmetric_pair.down
    assert jr.KIND_NAMES[int(path.kind)] == "branch_point"

    @jax.jit
    def alpha(c, ang):
        sc = eqx.tree_at(lambda s: (s.strip.creases.positions, s.strip.creases.angles), base, (c, ang))
        return jr.critical_point(sc, path.theta_before, path.force_before, path.alpha_c, path.mode,
                                 path.kind).alpha

    c0, a0 = jnp.asarray([0.25, 0.75]), jnp.radians(jnp.asarray([90.0, 90.0]))
    assert float(alpha(c0, a0)) == pytest.approx(float(path.alpha_c), abs=1e-12)
    gc, ga = jax.jit(jax.grad(alpha, argnums=(0, 1)))(c0, a0)
    gc, ga = np.asarray(gc), np.asarray(ga)
    spread = central_difference(lambda t: alpha(c0 + t[0] * jnp.asarray([-1.0, 1.0]), a0)[None],
                                jnp.zeros(1), scale=[0.1])[0, 0]
    fold = central_difference(lambda t: alpha(c0, a0 + t[0])[None], jnp.zeros(1), scale=[0.1])[0, 0]
    assert abs(float(spread)) > 1e-2 and abs(float(fold)) > 1e-2
    assert gc[1] - gc[0] == pytest.approx(float(spread), rel=1e-6)
    assert ga[0] + ga[1] == pytest.approx(float(fold), rel=1e-6)
    assert abs(gc[0] + gc[1]) < 1e-10 * abs(gc[1]) and gc[1] == pytest.approx(0.5 * float(spread), rel=1e-6)
    assert abs(ga[0] - ga[1]) < 1e-10 * abs(ga[1])
    # the paths of pairs shifted by -d and +d: the same change of alpha_c, growing like d^(2/3)
    change = {}
    for d in (2e-3, -2e-3, 8e-3):
        p = jr.snap_angles(pair(0.25 + d, 0.75 + d)).down
        assert p.result == jr.RESULTS.successful and jr.KIND_NAMES[int(p.kind)] == "fold"
        change[d] = math.degrees(float(p.alpha_c - path.alpha_c))
    assert change[2e-3] == pytest.approx(change[-2e-3], rel=0.05)
    assert 4.0 ** (2 / 3) * 0.8 < change[8e-3] / change[2e-3] < 4.0 ** (2 / 3) * 1.2, change


@pytest.mark.slow
def test_alpha_c_gradient_through_snap_angles(asymmetric_pair):
    """The same derivative through a whole `snap_angles` call (jax.jacrev) against central
    differences of whole calls."""
    base = pair(0.3, 0.65)

    def alpha(c):
        r = jr.snap_angles(eqx.tree_at(lambda s: s.strip.creases.positions, base, c))
        return jnp.stack([r.up.alpha_c, r.down.alpha_c])

    c0 = jnp.asarray([0.3, 0.65])
    J = jax.jacrev(alpha)(c0)
    fd = central_difference(alpha, c0, scale=[0.1, 0.1])
    np.testing.assert_allclose(np.asarray(J), np.asarray(fd), rtol=1e-5)


def test_state_gradients_in_every_crease_parameter():
    """Fold height, crease heights and bending energy of the up state against (c_k, Psi_k,
    s0_k), k = 1, 2: implicit derivatives against central differences of re-solves."""
    base = jr.initial_state(pair(0.3, 0.65, 90.0, 120.0), "up")

    def obs(p):
        cr = jr.Creases(p[0:2], p[2:4], p[4:6])
        sc = eqx.tree_at(lambda s: s.strip.creases, base.scene, cr)
        eq = jr.solve_equilibrium(sc, base.theta, base.force)
        return jnp.concatenate([jnp.stack([jr.fold_height(eq), jr.bending_energy(eq)]), jr.crease_heights(eq)])

    cr = base.scene.strip.creases
    p0 = jnp.concatenate([cr.positions, cr.angles, cr.widths])
    J = jax.jit(jax.jacrev(obs))(p0)
    fd = central_difference(obs, p0, scale=[0.1, 0.1, 1.0, 1.0, 0.02, 0.02])
    scale = np.max(np.abs(np.asarray(fd)), axis=1, keepdims=True)
    assert np.max(np.abs(np.asarray(J) - np.asarray(fd)) / scale) < 1e-6


def test_mesh_refines_around_every_crease():
    """`Mesh.for_strip` grades each half of the strip on its own: a node stays at L/2, the
    segments at the creases are the shortest, and a mirror-symmetric set gives a
    mirror-symmetric mesh."""
    strip = jr.Strip(creases=jr.Creases.from_degrees([0.3, 0.7], [90.0, 90.0]))
    m = jr.Mesh.for_strip(strip, 48, refine=4.0)
    f = np.asarray(m.fractions)
    assert f[24] == 0.5 and f[0] == 0.0 and f[-1] == 1.0
    np.testing.assert_allclose(f, 1.0 - f[::-1], atol=1e-12)
    h = np.diff(f)
    assert m.spacing_at(0.3) < 1.5 * h.min() and m.spacing_at(0.3) < h.max() / 2.5
    asym = jr.Mesh.for_strip(jr.Strip(creases=jr.Creases.from_degrees([0.3, 0.65], [90.0, 90.0])), 48, refine=4.0)
    assert asym.spacing_at(0.65) < 1.5 * np.diff(asym.fractions).min()
    assert jr.Mesh(48, 1.0, centres=(0.3,)) == jr.Mesh(48)  # a uniform mesh has no centres


def test_under_resolved_crease_warns_with_the_fix():
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        jr.make_scene(180.0, 0.5, n=24, creases=[(0.3, 90.0, 0.01)])
    assert len(w) == 1 and "refine" in str(w[0].message)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        jr.make_scene(180.0, 0.5, n=24, refine=8, creases=[(0.3, 90.0, 0.01)])


@pytest.mark.parametrize("creases, match", [
    ([(1.2, 90.0)], "crease 0 position"),
    ([(0.0, 90.0)], "crease 0 position"),
    ([(0.3, 0.0)], "crease 0 angle"),
    ([(0.3, 190.0)], "crease 0 angle"),
    ([(0.3, 90.0, -0.01)], "crease 0 width"),
    ([(0.3, float("nan"))], "crease 0 angle"),
    ([(0.5, 30.0), (0.51, 30.0)], "overlap"),
    ([(0.3,)], r"creases\[0\]"),
    ([], "creases"),
])
def test_bad_creases_name_the_parameter(creases, match):
    with pytest.raises(ValueError, match=match):
        jr.make_scene(180.0, 0.5, n=N, creases=creases)


def test_bad_crease_arrays():
    with pytest.raises(ValueError, match="one entry per crease"):
        jr.Creases([0.3, 0.7], [1.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="creases must be a jaxrod.Creases"):
        jr.Strip(creases=[(0.3, 90.0)])
    with pytest.raises(ValueError, match="overlap"):  # with the centred crease
        jr.make_scene(60.0, 0.5, n=N, creases=[(0.52, 40.0)])


def test_cli_crease_option(capsys):
    """`--crease C:PSI0[:S0]` (repeatable) on `jaxrod equilibrium`: the JSON echoes the set
    and reports each crease's height; --psi0 is 180 (no centred crease) unless given."""
    from jaxrod.cli import main

    assert main(["equilibrium", "--n", str(N), "--crease", "0.3:90", "--crease", "0.65:90:0.02",
                 "--state", "up", "--json"]) == 0
    rec = json.loads(capsys.readouterr().out)
    assert rec["psi0_deg"] == 180.0
    assert rec["creases"] == [{"position": 0.3, "psi0_deg": pytest.approx(90.0), "s0": 0.02},
                              {"position": 0.65, "psi0_deg": pytest.approx(90.0), "s0": 0.02}]
    eq = jr.initial_state(pair(0.3, 0.65), "up")
    np.testing.assert_allclose(rec["crease_heights"], np.asarray(jr.crease_heights(eq)), rtol=1e-9)
    assert rec["fold_height"] == pytest.approx(float(jr.fold_height(eq)), rel=1e-9)


@pytest.mark.parametrize("value", ["0.3", "0.3:x", "1.5:90", "0.3:90:0", "0.3:90:0.02:1"])
def test_cli_bad_crease_exits_2(value, capsys):
    from jaxrod.cli import main

    assert main(["equilibrium", "--n", str(N), "--crease", value]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "crease" in err[0]


def test_crease_points_in_the_dynamics_observables():
    """The dynamics' per-crease observables: each crease's height and speed are the node
    positions and velocities interpolated to its arclength (checked against NumPy on a moving
    state of a two-crease strip); a strip without creases reads them off the fold node."""
    from jaxrod.dynamics._equations import Protocol, kinematics, observables

    sc = pair(0.3, 0.65)
    eq = jr.initial_state(sc, "up")
    omega = jnp.sin(jnp.linspace(0.0, 3.0, N))
    o = observables(0.0, (eq.theta, omega), sc, Protocol(0.0, 0.0))
    d = jr.discretize(sc)
    x, v = (np.asarray(a) for a in kinematics(eq.theta, omega, d))
    s_nodes = np.asarray(d.s)
    for k, c in enumerate((0.3, 0.65)):
        y = np.interp(c, s_nodes, x[:, 1])
        vel = np.array([np.interp(c, s_nodes, v[:, 0]), np.interp(c, s_nodes, v[:, 1])])
        assert float(o["crease_height"][k]) == pytest.approx(y, abs=1e-13)
        assert float(o["crease_speed"][k]) == pytest.approx(np.linalg.norm(vel), rel=1e-12)
    classic = jr.make_scene(60.0, 0.5, n=N)
    e1 = jr.initial_state(classic, "up")
    o1 = observables(0.0, (e1.theta, omega), classic, Protocol(0.0, 0.0))
    assert float(o1["crease_height"][0]) == float(o1["fold_height"])
    assert float(o1["crease_speed"][0]) == float(o1["fold_speed"])


@pytest.mark.slow  # 26 s on 2 cores; CI checks the per-crease observables above
def test_snap_of_a_symmetric_pair_moves_both_creases_alike():
    """A symmetric fold of a mirror-symmetric set (up, creases at 0.25 L and 0.75 L): the
    snap keeps the mirror symmetry, so both creases reach the same peak speed; the run is
    clean and each crease's speed is reported beside the fold's at L/2."""
    r = jr.snap_speed_run(pair(0.25, 0.75), direction="up")
    assert r.result == jr.RESULTS.successful and jr.KIND_NAMES[int(r.kind)] == "fold"
    v = np.asarray(r.v_s_creases)
    assert v.shape == (2,) and np.all(np.isfinite(v)) and v[0] > 1.0
    assert v[0] == pytest.approx(v[1], rel=1e-6)
    assert float(r.v_s) > 0


@pytest.mark.parametrize("value, match", [("0.3,1.2", "crease 1 position"), ("0.5,0.51", "overlap"),
                                          ("x", "creases-at")])
def test_cli_phase_diagram_bad_layout_exits_2(value, match, tmp_path, capsys):
    from jaxrod.cli import main

    assert main(["phase-diagram", "--psi0", "60,90", "--gaps", "0.5", "--n", str(N), "--creases-at", value,
                 "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and match in err[0]


def test_phase_diagram_layout_validated():
    with pytest.raises(ValueError, match="crease 0 position"):
        jr.phase_diagram([90.0], [0.5], n=N, creases=[0.0, 0.5], progress=False)
    with pytest.raises(ValueError, match="creases"):
        jr.phase_diagram([90.0], [0.5], n=N, creases=[], progress=False)


@pytest.mark.slow
def test_phase_diagram_of_a_crease_layout_equals_snap_angles(tmp_path):
    """A phase diagram over (Psi0, G/L) for creases at 0.3 L and 0.7 L, each of fold angle
    Psi0: the same angles and kinds as `snap_angles` on each scene (to the bisection's 1e-6
    deg: the diagram skips the extended-system polish), and a resumed run reads every chunk."""
    psis, gaps = [90.0, 120.0], [0.5, 0.7]
    ds = jr.phase_diagram(psis, gaps, n=N, creases=[0.3, 0.7], out=str(tmp_path), progress=False)
    assert ds.attrs["crease_positions"] == "0.3,0.7"
    for i, p in enumerate(psis):
        for j, g in enumerate(gaps):
            r = jr.snap_angles(jr.make_scene(180.0, g, n=N, creases=[(0.3, p), (0.7, p)]))
            for name in ("up", "down"):
                q = getattr(r, name)
                assert float(ds[f"alpha_c_{name}"].values[i, j]) == pytest.approx(math.degrees(float(q.alpha_c)),
                                                                                 abs=1e-6)
                assert int(ds[f"kind_{name}"].values[i, j]) == int(q.kind)
    again = jr.phase_diagram(psis, gaps, n=N, creases=[0.3, 0.7], out=str(tmp_path), progress=False)
    assert again.attrs["computed_chunks"] == []


@pytest.mark.slow
def test_termination_gap_of_a_crease_layout():
    """Creases of 120 deg at 0.3 L and 0.7 L: both paths snap 0.01 below G* and neither
    0.01 above it. (Their two snaps are the two folds of one S-shaped branch, so both paths
    end at its cusp: measured G* = 0.96146 for both at N = 48.)"""
    tg = jr.termination_gap(120.0, n=N, creases=[0.3, 0.7])
    assert tg.reason_up == tg.reason_down == "cusp"
    for g, snaps in ((tg.gap_up - 0.01, True), (tg.gap_up + 0.01, False)):
        r = jr.snap_angles(pair(0.3, 0.7, 120.0, 120.0, gap=g))
        assert bool(r.up.snaps) is snaps and bool(r.down.snaps) is snaps
        assert r.up.result == r.down.result == jr.RESULTS.successful


@pytest.mark.slow  # 26 s on 2 cores; CI checks the orders of the merging limit above
def test_states_converge_at_second_order_in_n():
    """Fold height, both crease heights and the bending energy of the up state of an
    asymmetric pair (creases on nodes of every mesh, so the heights are node values) at
    N = 96, 192, 384: the differences fall by 4 per doubling (measured orders 2.000, 2.012,
    2.016, 2.000; below N = 96 the creases are not yet resolved and the order wanders
    between 0.9 and 2.6)."""
    q = []
    for n in (96, 192, 384):
        eq = jr.initial_state(jr.make_scene(180.0, 0.5, n=n, creases=[(0.25, 90.0), (0.625, 120.0)]), "up")
        assert eq.result == jr.RESULTS.successful
        q.append(np.concatenate([[float(jr.fold_height(eq))], np.asarray(jr.crease_heights(eq)),
                                 [float(jr.bending_energy(eq))]]))
    d = np.abs(np.diff(np.asarray(q), axis=0))
    order = np.log2(d[0] / d[1])
    assert np.all(np.abs(order - 2.0) < 0.05), order


@pytest.mark.slow
def test_snap_angles_converge_at_second_order_in_n():
    """alpha_c up and down of the same pair at N = 48, 96, 192: order 2 from the last two
    differences (benchmarks/results/creases.md has the table for five sets)."""
    a = []
    for n in (48, 96, 192):
        r = jr.snap_angles(jr.make_scene(180.0, 0.5, n=n, creases=[(0.3, 90.0), (0.65, 120.0)]))
        assert r.up.result == r.down.result == jr.RESULTS.successful
        a.append([float(r.up.alpha_c), float(r.down.alpha_c)])
    d = np.abs(np.diff(np.asarray(a), axis=0))
    order = np.log2(d[0] / d[1])
    assert np.all((order > 1.8) & (order < 2.2)), order
