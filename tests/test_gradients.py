"""Implicit derivatives of equilibria against central finite differences of re-solves.

Observables: fold height, bending energy, compression and one tangent angle (theta_37, off
the mirror axis). Parameters: psi0, gap, s0, alpha_left, alpha_right, set separately (one
clamp at a time breaks the mirror symmetry, so the two clamp derivatives must differ).
The finite differences re-solve with Newton from the base state, so they check the whole
chain: Newton, implicit function theorem, the structured solve and its transpose.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from helpers import central_difference, solve, state


K_THETA = 37  # a component off the mirror axis (N = 100)
WHERE = (
    lambda s: s.strip.psi0,
    lambda s: s.clamps.gap,
    lambda s: s.strip.s0,
    lambda s: s.clamps.alpha_left,
    lambda s: s.clamps.alpha_right,
)
SCALE = np.array([1.0, 1.0, 0.02, 1.0, 1.0])  # finite-difference step scale per parameter
# Measured agreement is <= 2e-9 (relative to the largest entry of each row, i.e. per observable);
# the budget is eps^(2/3) ~ 4e-11 times the amplification by Newton's stopping residual and
# the conditioning of the Hessian.
RTOL = 1e-7


def with_params(scene, p):
    for i, where in enumerate(WHERE):
        scene = eqx.tree_at(where, scene, p[i])
    return scene


def params(scene):
    return jnp.stack([jnp.asarray(w(scene), jnp.float64) for w in WHERE])


def observables(eq):
    return jnp.stack([jr.fold_height(eq), jr.bending_energy(eq), jr.compression(eq), eq.theta[K_THETA]])


def obs(p, scene, theta0, mu0):
    return observables(jr.solve_equilibrium(with_params(scene, p), theta0, mu0))


jac_rev = jax.jit(jax.jacrev(obs))
jac_fwd = jax.jit(jax.jacfwd(obs))
jac_fd = jax.jit(lambda p, scene, t, m: central_difference(lambda q: obs(q, scene, t, m), p, SCALE))


def assert_jac_close(J, Jfd, rtol=RTOL):
    # per observable (row): relative to the largest derivative of that observable
    row_scale = np.max(np.abs(Jfd), axis=1, keepdims=True)
    err = np.abs(np.asarray(J) - np.asarray(Jfd)) / row_scale
    assert np.all(np.isfinite(J))
    assert err.max() < rtol, f"max rel. error {err.max():.2e}\nad =\n{np.asarray(J)}\nfd =\n{np.asarray(Jfd)}"
    return err.max()


@pytest.fixture(scope="module", params=["down", "up"])
def base(request):
    eq = state(60.0, 0.5, request.param)
    return request.param, eq, params(eq.scene)


def test_grad_matches_finite_differences(base):
    kind, eq, p = base
    J = jac_rev(p, eq.scene, eq.theta, eq.force)
    Jfd = jac_fd(p, eq.scene, eq.theta, eq.force)
    err = assert_jac_close(J, Jfd)
    print(f"\n{kind}: max relative error jacrev vs central FD = {err:.2e}")
    # every parameter matters for every observable here (no vacuous zero comparisons)
    assert np.all(np.abs(np.asarray(Jfd)) > 1e-4 * np.max(np.abs(np.asarray(Jfd)), axis=1, keepdims=True))
    # one clamp at a time breaks the mirror symmetry: the tangent angle theta_37 responds
    # differently to the left and the right clamp, the symmetric observables identically
    J = np.asarray(J)
    assert abs(J[3, 3] - J[3, 4]) > 1e-2 * abs(J[3, 3])
    np.testing.assert_allclose(J[:3, 3], J[:3, 4], rtol=1e-9)


def test_jacfwd_matches_grad(base):
    _, eq, p = base
    Jr = np.asarray(jac_rev(p, eq.scene, eq.theta, eq.force))
    Jf = np.asarray(jac_fwd(p, eq.scene, eq.theta, eq.force))
    np.testing.assert_allclose(Jf, Jr, rtol=1e-10, atol=1e-12 * np.abs(Jr).max())


def test_grad_under_vmap():
    """Gradient w.r.t. psi0 under vmap over a batch of psi0 equals the per-element grads."""
    eq = state(60.0, 0.5, "down")

    def height(psi0):
        scene = eqx.tree_at(lambda s: s.strip.psi0, eq.scene, psi0)
        return jr.fold_height(jr.solve_equilibrium(scene, eq.theta, eq.force))

    psis = jnp.deg2rad(jnp.array([56.0, 60.0, 63.0]))
    batched = jax.jit(jax.vmap(jax.grad(height)))(psis)
    single = jax.jit(jax.grad(height))
    for i in range(psis.shape[0]):
        assert float(batched[i]) == pytest.approx(float(single(psis[i])), rel=1e-11)
    # plain `jax.grad` (reverse mode without vmap) equals the Jacobian entry checked by FD
    J = jac_rev(params(eq.scene), eq.scene, eq.theta, eq.force)
    assert float(single(psis[1])) == pytest.approx(float(J[0, 0]), rel=1e-10)
    # different fold angles, different slopes (the batch is not a broadcast of one value)
    assert abs(float(batched[0] - batched[2])) > 1e-3 * abs(float(batched[1]))


def test_grad_with_stretching_and_gravity():
    """Gradients through the extensible, gravity-loaded Lagrangian, also w.r.t. K and g."""
    eq0 = state(60.0, 0.5, "down")
    scene = jr.make_scene(60.0, 0.5, n=100, stretching=jr.Stretching(1e4), gravity=jr.Gravity(1.0))
    eq = solve(scene, eq0.theta, eq0.force)
    assert eq.result == jr.RESULTS.successful and int(eq.num_unstable) == 0
    where = WHERE + (lambda s: s.stretching.stiffness, lambda s: s.gravity.g)
    scale = np.concatenate([SCALE, [1e4, 1.0]])

    def f(p):
        sc = eq.scene
        for i, w in enumerate(where):
            sc = eqx.tree_at(w, sc, p[i])
        e = jr.solve_equilibrium(sc, eq.theta, eq.force)
        return jnp.concatenate([observables(e), jr.energies(e)["stretching"][None], jr.energies(e)["gravity"][None]])

    p = jnp.stack([jnp.asarray(w(eq.scene), jnp.float64) for w in where])
    J = jax.jit(jax.jacrev(f))(p)
    Jfd = jax.jit(lambda q: central_difference(f, q, scale))(p)
    err = assert_jac_close(J, Jfd)
    print(f"\nstretching + gravity: max relative error jacrev vs central FD = {err:.2e}")
    # stretching and gravity really are in the model: d(height)/dg and d(P)/dK are nonzero
    J = np.asarray(J)
    # (expected sizes: dy/dg ~ lambda L^3/P ~ 1e-4 here, dP/dK ~ P^2/K^2 ~ 1e-4)
    assert abs(J[0, 6]) > 1e-6 and abs(J[2, 5]) > 1e-8
