r"""Clamps placed at the rest shape's own ends: the rest shape is the equilibrium.

With $G = \sum_i h_i\cos\theta_0(m_i)$, $\alpha_L = \theta_0(0)$, $\alpha_R = -\theta_0(L)$ the
discrete rest shape $\theta_i = \theta_0(m_i)$ meets both clamps, its turning angles equal
the natural ones exactly (they are exact differences of $\theta_0$), so it has zero bending
energy and needs no end force. Newton from a perturbed rest shape must find it.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from helpers import residual, solve


def rest_scene(psi0_deg, s0=0.02, n=100):
    strip = jr.Strip(psi0=math.radians(psi0_deg), s0=s0)
    mesh = jr.Mesh(n)
    # discretize a provisional scene only to read the mesh (h, midpoints)
    d = jr.discretize(jr.Scene(strip, jr.Clamps(0.5), mesh))
    m = np.asarray(d.mid[1:-1])
    theta0 = np.asarray(strip.natural_angle(jnp.asarray(m)))
    gap = float(np.sum(np.asarray(d.h) * np.cos(theta0)))
    alpha_l = float(strip.natural_angle(0.0))
    alpha_r = -float(strip.natural_angle(1.0))
    return jr.Scene(strip, jr.Clamps(gap, alpha_l, alpha_r), mesh), theta0, m


@pytest.mark.parametrize("psi0_deg", [30.0, 90.0, 150.0])
def test_rest_shape_is_recovered(psi0_deg):
    scene, theta0, m = rest_scene(psi0_deg)
    # the clamp angles are the rest shape's end tangents: alpha_L = alpha_R = (pi - psi0)/2
    # up to tanh(L / 2 s0) = tanh(25) = 1 - 4e-22
    assert float(scene.clamps.alpha_left) == pytest.approx((math.pi - math.radians(psi0_deg)) / 2, rel=1e-15)
    # start away from it: a perturbation that moves the ends (Newton must restore them)
    start = theta0 + 0.1 * np.sin(3 * np.pi * m) + 0.05 * np.cos(np.pi * m)
    # gtol 1e-12 (default 1e-9): Newton stops at the first iterate below gtol, so with the
    # default the state is only as exact as 1e-9 allows (E_b ~ 1e-18); the float64 floor of
    # the residual is ~ B/h * eps ~ 1e-14
    eq = solve(scene, jnp.asarray(start), solver=jr.Newton(gtol=1e-12))
    assert eq.result == jr.RESULTS.successful, jr.RESULTS[eq.result]
    assert int(eq.num_unstable) == 0
    err = np.max(np.abs(np.asarray(eq.theta) - theta0))
    Eb = float(jr.bending_energy(eq))
    f = np.asarray(eq.force)
    print(f"\npsi0 = {psi0_deg}: max|theta - theta0| = {err:.2e}, E_b = {Eb:.2e}, |mu| = {np.abs(f).max():.2e}")
    assert err < 1e-12
    assert Eb < 1e-20
    assert np.max(np.abs(f)) < 1e-9
    # the solution meets the clamps, and is a stationary point by an independent gradient
    r = np.asarray(jr.node_positions(eq))
    assert np.max(np.abs(r[-1] - [float(scene.clamps.gap), 0.0])) < 1e-14
    rt, rm = residual(eq)
    assert rt < 1e-12 and rm < 1e-12
    # the crease points up in the rest shape (docs/model.md)
    assert float(jr.fold_height(eq)) > 0
    # curvature equals the natural one: phi_k / ell_k = (theta0(m_k+1) - theta0(m_k)) / ell_k
    d = jr.discretize(scene)
    np.testing.assert_allclose(np.asarray(jr.curvature(eq)), np.asarray(d.phi0 / d.ell), rtol=0, atol=1e-8)


@pytest.mark.parametrize("s0", [0.02, 0.002])
def test_total_crease_turning_is_exact(s0):
    """docs/model.md: the discrete natural turning angles add up to theta0(L) - theta0(0) at any
    resolution, also when the crease is narrower than a segment (s0 = 0.002, h = 0.01)."""
    for n in (8, 100):
        scene = jr.Scene(jr.Strip(psi0=math.radians(30.0), s0=s0), jr.Clamps(0.5), jr.Mesh(n))
        d = jr.discretize(scene)
        expected = float(scene.strip.natural_angle(1.0) - scene.strip.natural_angle(0.0))
        assert float(jnp.sum(d.phi0)) == pytest.approx(expected, rel=1e-14, abs=1e-15)
