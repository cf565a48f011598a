"""Critical points on the extended system: refinement to 1e-8 rad, regularity at
folds and (symmetry-restricted) branch points, the located points of `snap_angles` as its
roots, implicit gradients against central differences, vmap equals loop, no
recompilation."""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from jaxrod.linalg import kkt
from jaxrod.branches._critical import (_cusp_residual, _fold_residual, _jacobian_fn, _one_system, _padding,
                                      _solver_fn, _sym_residual, extended_jacobian)
from helpers import central_difference, count_compiles


jax.config.update("jax_enable_x64", True)

PSI0, GAP = 60.0, 0.5


@pytest.fixture(scope="module")
def base():
    return jr.make_scene(PSI0, GAP, 0.0)


@pytest.fixture(scope="module")
def snap(base):
    return jax.jit(jr.snap_angles)(base)


def scene_of(base, p):
    """p = (psi0 [rad], gap, s0) as traced leaves."""
    return eqx.tree_at(lambda s: (s.strip.psi0, s.clamps.gap, s.strip.s0), base, (p[0], p[1], p[2]))


P0 = np.array([math.radians(PSI0), GAP, 0.02])


@pytest.fixture(scope="module")
def refine(base):
    """critical_point at parameters p from a fixed start (the path's critical state)."""

    @jax.jit
    def f(p, theta, force, alpha, mode, kind):
        cp = jr.critical_point(scene_of(base, p), theta, force, alpha, mode, kind)
        return cp

    return f


def _start(path):
    return path.theta_before, path.force_before, path.alpha_c, path.mode, path.kind


def test_paths_refined_known_values(snap):
    # values of our solver at n = 100 (see the brief / README): up at a branch point, down at a fold
    assert int(snap.up.kind) == 2 and int(snap.down.kind) == 1
    assert abs(math.degrees(float(snap.up.alpha_c)) - 77.31) < 0.01
    assert abs(math.degrees(float(snap.down.alpha_c)) + 82.89) < 0.01
    for path in (snap.up, snap.down):
        assert path.refine_result == jr.RESULTS.successful


def test_extended_system_converges_to_1e8(snap, base, refine):
    """From a start 2e-3 rad off in alpha (and a perturbed state), Newton on the extended
    system returns to the same critical point to 1e-8 rad; the residuals of the
    equilibrium and of K v = 0 are checked independently of the solver."""
    for path in (snap.up, snap.down):
        t, m, a, v, k = _start(path)
        noise = 1e-3 * jnp.cos(7.0 * jnp.arange(t.shape[0]))
        noise = noise - noise[::-1] if int(k) == 2 else noise  # keep the symmetric state symmetric
        cp = refine(jnp.asarray(P0), t + noise, m, a + 2e-3, v, k)
        assert cp.result == jr.RESULTS.successful
        assert abs(float(cp.alpha - path.alpha_c)) < 1e-8
        assert float(cp.residual) < 1e-10
        sc = jr.SymmetricAlpha().set(base, cp.alpha)
        gt, gm = jax.grad(jr.lagrangian, argnums=(0, 1))(cp.theta, cp.force, sc)
        assert float(jnp.max(jnp.abs(gt))) < 1e-9 and float(jnp.max(jnp.abs(gm))) < 1e-9
        K = kkt.structured(cp.theta, cp.force, sc).dense()
        kv = K @ jnp.concatenate([cp.mode, cp.mode_force])
        assert float(jnp.max(jnp.abs(kv))) < 1e-8 * float(jnp.max(jnp.abs(K)))
        # the critical state has a zero constrained eigenvalue, none below it
        lam = kkt.smallest_eigenvalues(kkt.structured(cp.theta, cp.force, sc), 2)
        assert abs(float(lam[0])) < 1e-7 and float(lam[1]) > 1e-2
        # the mode is asymmetric at the branch point, symmetric at the fold
        parity = float(jnp.sum(cp.mode * -cp.mode[::-1]) / jnp.sum(cp.mode**2))
        assert parity < -0.999 if int(k) == 2 else parity > 0.999


def test_snap_angles_locate_the_extended_systems_root(snap, base, refine):
    """`snap_angles` locates each critical point by bisection and interpolation of the
    eigenvalue that crosses zero, without Newton on the extended system: Newton started
    there moves alpha by at most 1e-12 rad and the state by 1e-8 (a branch point's state is
    the symmetric projection); the located point's residual is below 1e-10."""
    for path in (snap.up, snap.down):
        cp = refine(jnp.asarray(P0), *_start(path))
        assert cp.result == jr.RESULTS.successful
        assert abs(float(cp.alpha - path.alpha_c)) < 1e-12
        assert float(jnp.max(jnp.abs(cp.theta - path.theta_before))) < 1e-8
        located = jr.branches.located_critical_point(base, *_start(path))
        assert located.result == jr.RESULTS.successful and float(located.residual) < 1e-10


@pytest.mark.slow
def test_located_points_are_newton_roots_over_a_grid():
    """Over Psi0 = 30 ... 180 deg x G/L = 0.1 ... 0.9 (5 x 17, N = 100), Newton on the extended
    system started at each snapping path's located critical point moves alpha by at most
    2e-13 rad (measured 1.3e-13), except at G/L = 0.1, Psi0 = 120 deg (a state through
    itself, 5e-11 rad): 1e-10 there; every polish is `successful`."""
    base = jr.make_scene(60.0, 0.5, n=100)

    @jax.jit
    def f(psi0, gap):
        sc = eqx.tree_at(lambda s: (s.strip.psi0, s.clamps.gap), base, (psi0, gap))
        r = jr.snap_angles(sc)
        out = []
        for p in (r.up, r.down):
            cp = jr.critical_point(sc, p.theta_before, p.force_before, p.alpha_c, p.mode, jnp.maximum(p.kind, 1))
            out.append((p.kind, p.refine_result._value, cp.result._value, jnp.abs(cp.alpha - p.alpha_c)))
        return out

    n = 0
    for psi in (30.0, 60.0, 90.0, 120.0, 180.0):
        for gap in np.linspace(0.1, 0.9, 17):
            for kind, refined, newton, diff in f(jnp.radians(psi), gap):
                if int(kind) == 0:
                    continue
                n += 1
                assert int(refined) == 0 and int(newton) == 0
                assert float(diff) < (1e-10 if (psi, round(gap, 2)) == (120.0, 0.1) else 2e-13), (psi, gap)
    assert n == 150


def test_located_critical_point_derivative_and_verdicts(snap, base, refine):
    """`located_critical_point` (no Newton; the Jacobian assembled inside the derivative
    rule) has the derivative of `critical_point` at the same root, d(alpha, fold height) /
    d(Psi0, G, s0) at the branch point and the fold; a point 1e-4 rad off the critical one
    is `derivative_unavailable`, a non-finite one `nonfinite`."""
    @jax.jit
    def loc(p, theta, force, alpha, mode, kind):
        return jr.branches.located_critical_point(scene_of(base, p), theta, force, alpha, mode, kind)

    for path in (snap.up, snap.down):
        start = _start(path)
        J_loc = jax.jacrev(lambda p: _pick(loc(p, *start))[:2])(jnp.asarray(P0))
        J_newton = jax.jacrev(lambda p: _pick(refine(p, *start))[:2])(jnp.asarray(P0))
        assert np.all(np.abs(np.asarray(J_loc)) > 1e-4)
        np.testing.assert_allclose(np.asarray(J_loc), np.asarray(J_newton), rtol=1e-8, atol=1e-12)
        t, m, a, v, k = start
        assert loc(jnp.asarray(P0), t, m, a + 1e-4, v, k).result == jr.RESULTS.derivative_unavailable
        assert loc(jnp.asarray(P0), t * jnp.nan, m, a, v, k).result == jr.RESULTS.nonfinite


@pytest.mark.slow  # 18 s on 2 cores (two creases at N = 48); the ordinary folds' derivatives are in CI
def test_derivative_where_a_fold_meets_a_branch_point():
    """Creases of 90 deg at 0.3 L and 0.7 L, G/L = 0.5, N = 48: the snap-up fold lies where
    the asymmetric mode is critical too, so the fold system's Jacobian is all but singular
    (condition number > 1e10) and Newton on it does not converge from the located point; the
    located point is `successful` and its implicit derivative d alpha_c / dG (the right-hand
    side is mirror-symmetric, orthogonal to the near-null direction) matches central
    differences to 1e-7."""
    base = jr.make_scene(180.0, 0.5, n=48, creases=[(0.3, 90.0), (0.7, 90.0)])

    def alpha(gap):
        return jr.snap_angles(eqx.tree_at(lambda s: s.clamps.gap, base, gap)).up

    p = alpha(0.5)
    assert int(p.kind) == 1 and p.result == jr.RESULTS.successful and p.refine_result == jr.RESULTS.successful
    cp = jr.critical_point(base, p.theta_before, p.force_before, p.alpha_c, p.mode, p.kind)
    s = np.linalg.svd(np.asarray(extended_jacobian(base, cp)), compute_uv=False)
    assert s[0] / s[-1] > 1e10 and cp.result != jr.RESULTS.successful
    g = jax.grad(lambda x: alpha(x).alpha_c)(0.5)
    fd = (alpha(0.5 + 1e-4).alpha_c - alpha(0.5 - 1e-4).alpha_c) / 2e-4
    assert abs(float(g) / float(fd) - 1.0) < 1e-7


def test_critical_pair_is_the_eigenvalue_nearest_zero(snap, base):
    """`kkt.critical_pair` next to a critical point: the eigenvalue of the Sturm bisection
    (`smallest_eigenvalues`) to 1e-9 relative (plus round-off, 1e-13 of the largest diagonal
    entry) and its mode (`modes`) to 1e-9, at the critical states of the branch point and
    the fold moved by +-1e-3 rad (eigenvalues of either sign, 5e-7 to 1e-5 from zero)."""
    for path in (snap.up, snap.down):
        sc = jr.SymmetricAlpha().set(base, path.alpha_c)
        n = path.theta_before.shape[0]
        for eps in (-1e-3, 1e-3):
            K = kkt.structured(path.theta_before + eps * jnp.cos(7.0 * jnp.arange(n)), path.force_before, sc)
            v, lam = kkt.critical_pair(K)
            ref = kkt.smallest_eigenvalues(K, 2)
            assert 1e-7 < abs(float(ref[0])) < 1e-2 < float(ref[1])  # isolated, next to zero
            tol = 1e-9 * abs(float(ref[0])) + 1e-13 * float(jnp.max(jnp.abs(K.diag)))
            assert abs(float(lam - ref[0])) < tol
            v_ref = kkt.modes(K, ref[:1])[:, 0]
            assert abs(abs(float(jnp.dot(v, v_ref))) - 1.0) < 1e-9


def test_extended_jacobians_regular(snap, base, refine):
    """The restricted branch-point system and the fold system are regular (moderate
    condition numbers); the *unrestricted* Moore-Spence system at the branch point is
    singular, which is why the branch point is posed on the symmetric subspace."""
    bp = refine(jnp.asarray(P0), *_start(snap.up))
    fold = refine(jnp.asarray(P0), *_start(snap.down))
    for cp in (bp, fold):
        s = np.linalg.svd(np.asarray(extended_jacobian(base, cp)), compute_uv=False)
        assert s[-1] > 1e-4 and s[0] / s[-1] < 1e7
    d = jr.discretize(base)
    ell = d.h * bp.mode / jnp.sum(d.h * bp.mode**2)
    z = jnp.concatenate([bp.theta, bp.force, bp.alpha[None], bp.mode, bp.mode_force])
    J = jax.jit(jax.jacfwd(lambda z: _fold_residual(z, base, jr.SymmetricAlpha(), ell)))(z)
    s = np.linalg.svd(np.asarray(J), compute_uv=False)
    assert s[-1] / s[0] < 1e-9


def test_branch_point_in_fold_slots_is_the_symmetric_system():
    """The branch-point system posed in the fold system's slots (`_one_system`) is the
    symmetric system plus "slot = 0" for every slot it does not use: at a point of the
    symmetric subspace its residual holds the symmetric system's residual in the kept rows
    and zero elsewhere, and its Jacobian is the symmetric system's beside an identity (the
    rows and columns picked by `_padding`), so it is regular exactly where that is."""
    scene, parameter = jr.make_scene(60, 0.5, n=16), jr.SymmetricAlpha()
    n, H = 16, 8
    rng = np.random.default_rng(3)
    ell = jnp.asarray(rng.normal(size=n))
    y = jnp.asarray(rng.normal(size=n + 3)) * 0.5
    idx, sign, keep, slot, used = _padding(n)
    cols = np.concatenate([np.arange(H), [n, n + 2], n + 3 + np.arange(H), [2 * n + 4]])  # its unknowns
    np.testing.assert_array_equal(used, cols)
    z = jnp.zeros(2 * n + 5).at[cols].set(y)
    res = _one_system(n, True, parameter, ell)[1]
    r, J = jax.jit(lambda z: (res(z, scene), jax.jacfwd(lambda z: res(z, scene))(z)))(z)
    r_sym, J_sym = jax.jit(lambda y: (_sym_residual(y, scene, parameter, ell),
                                      jax.jacfwd(lambda y: _sym_residual(y, scene, parameter, ell))(y)))(y)
    rows = np.flatnonzero(keep)  # the symmetric system's equations, in its own order
    np.testing.assert_allclose(r[rows], r_sym, rtol=0, atol=1e-13)
    np.testing.assert_array_equal(r[keep == 0], 0.0)
    np.testing.assert_allclose(J[np.ix_(rows, cols)], J_sym, rtol=0, atol=1e-12 * float(jnp.max(jnp.abs(J_sym))))
    pads = np.setdiff1d(np.arange(2 * n + 5), cols)
    np.testing.assert_array_equal(J[np.ix_(rows, pads)], 0.0)
    np.testing.assert_array_equal(J[np.ix_(np.flatnonzero(keep == 0), np.arange(2 * n + 5))],
                                  np.eye(2 * n + 5)[slot[keep == 0]])


def _batched(refine, start):
    """vmap over parameter rows (the same batched compile serves FD and the vmap test)."""
    return jax.vmap(lambda p: _pick(refine(p, *start)))


def _pick(cp):
    return jnp.stack([cp.alpha, cp.fold_height, cp.result._value.astype(cp.alpha.dtype)])


def test_gradients_match_central_differences(snap, refine):
    """d alpha_c / d(psi0, G, s0) and d(fold height)/d(...) at the branch point and the fold,
    by implicit differentiation (jax.jacrev through the jitted refinement); the central
    differences re-solve the extended system at p +- h."""
    for path in (snap.up, snap.down):
        start = _start(path)
        J = jax.jacrev(lambda p: _pick(refine(p, *start))[:2])(jnp.asarray(P0))
        fd = central_difference(lambda p: _pick(refine(p, *start))[:2], P0, scale=[1.0, 1.0, 0.02])
        assert np.all(np.abs(np.asarray(J)) > 1e-4)  # every derivative is non-trivial
        np.testing.assert_allclose(np.asarray(J), np.asarray(fd), rtol=1e-6, atol=1e-9)


def test_vmap_equals_loop_bad_member_alone_no_recompile(snap, refine):
    start = _start(snap.down)
    P = np.tile(P0, (3, 1))
    P[:, 1] = [0.49, 0.51, np.nan]
    out = np.asarray(_batched(refine, start)(jnp.asarray(P)))
    ok = out[:, 2] == 0  # RESULTS.successful
    assert ok.tolist() == [True, True, False]
    for i in range(2):
        single = np.asarray(_pick(refine(jnp.asarray(P[i]), *start)))
        np.testing.assert_allclose(out[i], single, rtol=0, atol=1e-12)
    assert abs(out[0, 0] - out[1, 0]) > 1e-3  # different members, not one broadcast
    with count_compiles() as c:
        refine(jnp.asarray(P[0] * [1.0, 1.0, 1.1]), *start)
        _batched(refine, start)(jnp.asarray(P[::-1]))
    assert c[0] == 0


@pytest.mark.slow
def test_snap_angles_gradients_fd(base):
    """jax.grad through snap_angles (the refined critical point) against central differences
    that re-run snap_angles at p +- h, under jit; vmap of snap_angles equals the loop."""

    def f(p):
        r = jr.snap_angles(scene_of(base, p))
        return jnp.stack([r.up.alpha_c, r.down.alpha_c, r.up.fold_height_before, r.down.fold_height_before])

    jf = jax.jit(f)
    J = jax.jit(jax.jacrev(f))(jnp.asarray(P0))
    fd = central_difference(jf, P0, scale=[1.0, 1.0, 0.02])
    np.testing.assert_allclose(np.asarray(J), np.asarray(fd), rtol=1e-6, atol=1e-9)
    g = jax.jit(jax.grad(lambda p: jr.snap_angles(scene_of(base, p)).up.alpha_c))(jnp.asarray(P0))
    np.testing.assert_allclose(np.asarray(g), np.asarray(J[0]), rtol=1e-10)
    # vmap (jit) over parameters equals the loop
    P = np.tile(P0, (2, 1))
    P[1, 1] = 0.55
    Jb = jax.jit(jax.vmap(jax.jacrev(f)))(jnp.asarray(P))
    np.testing.assert_allclose(np.asarray(Jb[0]), np.asarray(J), rtol=1e-9, atol=1e-12)
    J1 = jax.jit(jax.jacrev(f))(jnp.asarray(P[1]))
    np.testing.assert_allclose(np.asarray(Jb[1]), np.asarray(J1), rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("case", ["plain", "gravity_stretching", "creases", "gap", "one_sided", "n8"])
def test_structured_jacobian_equals_autodiff(case):
    """The extended systems' Jacobians assembled from their sparsity (colour probes on the
    angle blocks) equal `jax.jacfwd`'s at arbitrary points, for every system and parameter:
    a term that coupled non-neighbouring angles would show here as an O(1) difference."""
    scenes = {
        "plain": (jr.make_scene(60, 0.5, n=16), jr.SymmetricAlpha()),
        "gravity_stretching": (jr.make_scene(60, 0.4, 10, n=14, stretching=jr.Stretching(1e3),
                                             gravity=jr.Gravity(2.0)), jr.SymmetricAlpha()),
        "creases": (jr.make_scene(90, 0.5, n=40, creases=[(0.3, 120.0), (0.7, 100.0, 0.05)]), jr.SymmetricAlpha()),
        "gap": (jr.make_scene(60, 0.5, 20, n=12), jr.Gap()),
        "one_sided": (jr.make_scene(60, 0.5, 5, alpha_right_deg=-10, n=10), jr.LeftAlpha()),
        "n8": (jr.make_scene(60, 0.5, n=8), jr.SymmetricAlpha()),
    }
    scene, parameter = scenes[case]
    n = scene.mesh.n
    rng = np.random.default_rng(1)
    ell = jnp.asarray(rng.normal(size=n))
    z = jnp.asarray(rng.normal(size=2 * n + 5)) * 0.5
    systems = [("fold", lambda z: _fold_residual(z, scene, parameter, ell), z),
               ("cusp", lambda z: _cusp_residual(z, scene, parameter, ell), jnp.append(z, 0.45))]
    if case != "one_sided":  # the symmetric system needs mirror-symmetric actuation
        systems.append(("sym", lambda y: _sym_residual(y, scene, parameter, ell), z[:n + 3]))
        # the branch-point system in the fold system's slots, as `critical_point` solves it
        systems.append(("fold", lambda z: _one_system(n, True, parameter, ell)[1](z, scene), z))
    for kind, res, x in systems:
        dense, structured = jax.jit(lambda x: (jax.jacfwd(res)(x), _jacobian_fn(res, scene, n, kind)(x)[0]))(x)
        assert structured.shape == dense.shape
        np.testing.assert_allclose(structured, dense, rtol=0, atol=1e-13 * float(jnp.max(jnp.abs(dense))),
                                   err_msg=f"{case} {kind}")
        # the block elimination that solves with it (two tridiagonal solves and a small Schur
        # complement) equals a dense LU; the conditioning of these random points is 1e4-1e6
        # (the cusp system under the Gap parameter has the gap twice: singular, no solve)
        if case == "gap" and kind == "cusp":
            continue
        r = jnp.asarray(rng.normal(size=x.shape[0]))
        x_lu = np.linalg.solve(np.asarray(dense), np.asarray(r))
        x_block = jax.jit(_solver_fn(scene, n, kind))(structured, r)
        np.testing.assert_allclose(x_block, x_lu, rtol=0, atol=1e-11 * float(np.max(np.abs(x_lu))),
                                   err_msg=f"{case} {kind} solve")
