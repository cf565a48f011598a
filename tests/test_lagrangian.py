"""The written-out gradient and Hessian of the condensed Lagrangian
(`jaxrod.energy.lagrangian`) against autodiff of the scalar Lagrangian, for every energy
term: bending with the crease, inextensible and stretching strips, gravity, asymmetric
clamps, and a graded mesh."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from jaxrod.energy import lagrangian as lag

N = 30
SCENES = {
    "plain": dict(),
    "stretching": dict(stretching=jr.Stretching(50.0)),
    "gravity": dict(gravity=jr.Gravity(3.0)),
    "all": dict(stretching=jr.Stretching(20.0), gravity=jr.Gravity(2.0), alpha_deg=10, alpha_right_deg=-20),
    "graded": dict(refine=4.0, psi0_deg=150),
}


def dense(blocks):
    lower, diag, upper, border, corner = (np.asarray(b) for b in blocks)
    H = np.zeros((N + 2, N + 2))
    H[np.arange(N), np.arange(N)] = diag
    H[np.arange(1, N), np.arange(N - 1)] = lower[1:]
    H[np.arange(N - 1), np.arange(1, N)] = upper[:-1]
    H[:N, N:] = border
    H[N:, :N] = border.T
    H[N:, N:] = corner
    return H


@pytest.mark.parametrize("name", SCENES)
def test_gradient_and_hessian_match_autodiff(name):
    kw = dict(psi0_deg=70, gap=0.4, n=N)
    kw.update(SCENES[name])
    sc = jr.make_scene(**kw)
    rng = np.random.default_rng(3)
    for _ in range(3):
        th = jnp.asarray(rng.normal(size=N))
        mu = jnp.asarray(5 * rng.normal(size=2))
        gt, gm = jax.grad(lag.lagrangian, argnums=(0, 1))(th, mu, sc)
        at, am = jax.jit(lag.lagrangian_gradient)(th, mu, sc)
        scale = float(jnp.max(jnp.abs(gt)))
        np.testing.assert_allclose(at, gt, rtol=0, atol=1e-13 * scale)
        np.testing.assert_allclose(am, gm, rtol=0, atol=1e-13 * scale)
        H = jax.hessian(lambda x: lag.lagrangian(x[:N], x[N:], sc))(jnp.concatenate([th, mu]))
        Hs = dense(jax.jit(lag.hessian_blocks)(th, mu, sc))
        np.testing.assert_allclose(Hs, H, rtol=0, atol=1e-13 * float(jnp.max(jnp.abs(H))))


def test_parameter_derivative_of_the_gradient_matches_autodiff():
    """Implicit differentiation takes the scene-parameter derivative of the written-out
    gradient: it equals the mixed second derivative of the scalar Lagrangian."""
    sc = jr.make_scene(psi0_deg=70, gap=0.4, n=N, stretching=jr.Stretching(40.0), gravity=jr.Gravity(1.0))
    rng = np.random.default_rng(4)
    th, mu = jnp.asarray(rng.normal(size=N)), jnp.asarray(rng.normal(size=2))
    for path in (lambda s: s.strip.psi0, lambda s: s.clamps.gap, lambda s: s.strip.s0):
        def with_p(p, f):
            import equinox as eqx
            return f(eqx.tree_at(path, sc, p))
        p0 = path(sc)
        a = jax.jacfwd(lambda p: jnp.concatenate(with_p(p, lambda s: lag.lagrangian_gradient(th, mu, s))))(p0)
        b = jax.jacfwd(lambda p: jnp.concatenate(with_p(p, lambda s: jax.grad(lag.lagrangian, argnums=(0, 1))(th, mu, s))))(p0)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12 * max(1.0, float(jnp.max(jnp.abs(b)))))
