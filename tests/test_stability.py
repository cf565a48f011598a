r"""Structured Hessian, Sturm-count eigenvalues and modes against dense references.

The constrained stiffness problem is $T v + P w = \lambda v$, $P^\top v + C w = 0$
(`jaxrod/linalg/kkt.py`). Dense references: `jax.hessian` of `jr.lagrangian` for the matrix, and
`numpy.linalg.eigvalsh` of `jr.dense_reduced_hessian` for the spectrum.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from helpers import solve, state


def dense_hessian(eq):
    """jax.hessian of the Lagrangian in (theta, mu), as one (N+2)x(N+2) matrix."""
    x = jnp.concatenate([eq.theta, eq.force])
    N = eq.theta.shape[0]
    return jax.hessian(lambda x: jr.lagrangian(x[:N], x[N:], eq.scene))(x)


def blocks(eq):
    Kd = np.asarray(jr.hessian(eq).dense())
    N = eq.theta.shape[0]
    return Kd[:N, :N], Kd[:N, N:], Kd[N:, N:]


@pytest.fixture(scope="module")
def equilibria():
    """Stable states: creased down/up, flat, and with stretching + gravity."""
    down, up = state(60.0, 0.5, "down"), state(60.0, 0.5, "up")
    flat_scene = jr.make_scene(180.0, 0.5, n=100)
    flat = solve(flat_scene, jr.buckled_guess(flat_scene, up=True))
    ext_scene = jr.make_scene(60.0, 0.5, n=100, stretching=jr.Stretching(1e4), gravity=jr.Gravity(1.0))
    ext = solve(ext_scene, down.theta, down.force)
    for eq in (flat, ext):
        assert eq.result == jr.RESULTS.successful
    return {"down": down, "up": up, "flat": flat, "stretching+gravity": ext}


@pytest.fixture(scope="module")
def unstable():
    """Unstable equilibria of the flat strip at G/L = 0.9 from plain Newton (minimize=False):
    the second (antisymmetric, S-shaped) buckling mode and the third (W-shaped) one."""
    scene = jr.make_scene(180.0, 0.9, n=100)
    m = np.asarray(jr.discretize(scene).mid[1:-1])
    plain = jr.Newton(minimize=False)
    out = {}
    for name, guess in [("S", 0.3 * np.sin(3 * np.pi * m)), ("W", 0.3 * np.sin(4 * np.pi * m))]:
        eq = solve(scene, jnp.asarray(guess), solver=plain)
        assert eq.result == jr.RESULTS.successful, (name, jr.RESULTS[eq.result])
        out[name] = eq
    return scene, out


NAMES = ["down", "up", "flat", "stretching+gravity"]


@pytest.mark.parametrize("name", NAMES)
def test_structured_hessian_equals_autodiff(equilibria, name):
    eq = equilibria[name]
    K = np.asarray(jr.hessian(eq).dense())
    H = np.asarray(dense_hessian(eq))
    # measured <= 1e-16 relative
    np.testing.assert_allclose(K, H, rtol=0, atol=1e-13 * np.abs(H).max())
    # and it is really bordered tridiagonal: nothing outside the band in the theta block
    N = eq.theta.shape[0]
    T = H[:N, :N]
    assert np.all(np.abs(np.triu(T, 2)) == 0) and np.all(np.abs(np.tril(T, -2)) == 0)


@pytest.mark.parametrize("name", NAMES)
def test_eigenvalues_match_dense(equilibria, name):
    eq = equilibria[name]
    st = jr.stability(eq, k=4)
    dense = np.linalg.eigvalsh(np.asarray(jr.dense_reduced_hessian(eq)))
    scale = np.abs(np.asarray(jr.hessian(eq).diag)).max()
    # bisection to machine precision: measured <= 5e-16 relative to max |diag|
    np.testing.assert_allclose(np.asarray(st.eigenvalues), dense[:4], rtol=0, atol=1e-12 * scale)
    assert np.all(np.diff(np.asarray(st.eigenvalues)) >= 0)
    assert int(st.num_unstable) == int(np.sum(dense < 0)) == int(eq.num_unstable) == 0
    assert bool(st.stable)


@pytest.mark.parametrize("name", NAMES)
def test_modes_satisfy_constraints_and_eigen_equation(equilibria, name):
    eq = equilibria[name]
    st = jr.stability(eq, k=4)
    T, P, C = blocks(eq)
    V = np.asarray(st.modes)
    lam = np.asarray(st.eigenvalues)
    np.testing.assert_allclose(np.linalg.norm(V, axis=0), 1.0, rtol=1e-12)
    scale = np.abs(T).max()
    for j in range(V.shape[1]):
        v = V[:, j]
        if eq.scene.stretching is None:
            # linearized end conditions: sum_i h_i (-sin theta_i, cos theta_i) v_i = 0,
            # i.e. P^T v = 0 (P = d^2 L / dtheta dmu)
            h = np.asarray(jr.discretize(eq.scene).h)
            th = np.asarray(eq.theta)
            assert abs(np.sum(h * np.sin(th) * v)) < 1e-13 and abs(np.sum(h * np.cos(th) * v)) < 1e-13
            assert np.abs(P.T @ v).max() < 1e-13
            w = np.linalg.lstsq(P, lam[j] * v - T @ v, rcond=None)[0]
        else:
            w = -np.linalg.solve(C, P.T @ v)  # extensible: P^T v + C w = 0
        r = T @ v + P @ w - lam[j] * v
        # measured ~5e-17 relative (3 steps of shifted inverse iteration)
        assert np.abs(r).max() < 1e-11 * scale, (j, np.abs(r).max())


def test_flat_strip_lowest_mode_is_asymmetric(equilibria):
    """Flat strip buckled up: the perturbations that keep the clamps fixed cannot move along
    the buckling mode itself (it changes the end shortening), so the softest mode is the
    antisymmetric S mode, with stiffness ~ h (P_2 - P) where P_2 = 4 x^2 B/L^2
    (tan x = x, x = 4.4934: the second clamped-clamped buckling load, 8.18 pi^2 B/L^2);
    the next is the symmetric one with ~ h (16 pi^2 B/L^2 - P)."""
    # at G/L = 0.5
    st = jr.stability(equilibria["flat"], k=4)
    assert float(st.parity[0]) < -0.999
    assert float(st.parity[1]) > 0.999
    # near the Euler limit, compare with the linearized stiffnesses
    scene = jr.make_scene(180.0, 0.999, n=100)
    eq = solve(scene, jr.buckled_guess(scene, up=True))
    st = jr.stability(eq, k=2)
    h, P = 1.0 / 100, float(jr.compression(eq))
    x = 4.493409457909064
    assert float(st.parity[0]) < -0.999 and float(st.parity[1]) > 0.999
    # O(h^2) and O(1 - G/L) corrections: 2e-3 relative
    assert float(st.eigenvalues[0]) == pytest.approx(h * (4 * x**2 - P), rel=2e-3)
    assert float(st.eigenvalues[1]) == pytest.approx(h * (16 * math.pi**2 - P), rel=2e-3)
    # the mode shapes: antisymmetric means v_i = +v_{N+1-i} (y moves as an S)
    v = np.asarray(st.modes[:, 0])
    np.testing.assert_allclose(v, v[::-1], atol=1e-8)


@pytest.mark.parametrize("name, expected", [("S", 1), ("W", 2)])
def test_unstable_equilibrium_counts(unstable, name, expected):
    scene, eqs = unstable
    eq = eqs[name]
    dense = np.linalg.eigvalsh(np.asarray(jr.dense_reduced_hessian(eq)))
    st = jr.stability(eq, k=4)
    assert int(np.sum(dense < 0)) == expected
    assert int(st.num_unstable) == int(eq.num_unstable) == expected
    assert not bool(st.stable)
    scale = np.abs(np.asarray(jr.hessian(eq).diag)).max()
    np.testing.assert_allclose(np.asarray(st.eigenvalues), dense[:4], rtol=0, atol=1e-12 * scale)
    # physics: the S state has zero mid-height and a higher compression than the first mode
    # (P ~ 8.18 pi^2 B/L^2 near G = L), the W state higher still
    P = float(jr.compression(eq))
    assert P > 4 * 4.4934**2 if name == "S" else P > 16 * math.pi**2 * 0.99
    if name == "S":
        assert abs(float(jr.fold_height(eq))) < 1e-10
    # the minimizing solver never reports such a state as a success
    eq_min = solve(scene, eq.theta, eq.force)
    assert (eq_min.result == jr.RESULTS.converged_to_saddle) or (
        eq_min.result == jr.RESULTS.successful and int(eq_min.num_unstable) == 0)


def test_straight_start_fails_cleanly(unstable):
    """theta = 0 cannot meet G < L, and there the end constraint's linearization (the
    border column h_i sin(theta_i)) vanishes: the KKT matrix is singular. Plain Newton must
    say so with a failure code, not return a state."""
    scene, _ = unstable
    eq = solve(scene, jnp.zeros(100), solver=jr.Newton(minimize=False))
    assert eq.result == jr.RESULTS.nonfinite, jr.RESULTS[eq.result]
