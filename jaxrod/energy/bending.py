r"""Bending energy of the creased strip (the paper's Eq. 1, discretized).

$$E_b = \frac B2\int_0^L(\theta'-\theta_0')^2\,ds \;\approx\; \sum_{k=0}^{N}
\frac{B}{2\ell_k}\left(\phi_k-\bar\phi_k\right)^2,\qquad \phi_k=\theta_{k+1}-\theta_k,$$

with $\theta_0=\alpha_L$, $\theta_{N+1}=-\alpha_R$ the clamp tangents (see
`geometry.py`). On a uniform mesh this is second-order accurate in $h$.
"""

from __future__ import annotations

import jax.numpy as jnp


def full_angles(theta, d):
    """Segment angles with the two clamp tangents appended: shape (N+2,)."""
    return jnp.concatenate([d.theta_left[None], theta, d.theta_right[None]])


def turning_angles(theta, d):
    r"""$\phi_k = \theta_{k+1}-\theta_k$ at the $N+1$ hinges (clamps included)."""
    return jnp.diff(full_angles(theta, d))


def curvature(theta, d):
    r"""Discrete curvature $\kappa_k=\phi_k/\ell_k$ at the hinges."""
    return turning_angles(theta, d) / d.ell


def bending_energy(theta, scene, d):
    B = scene.strip.bending_stiffness
    dphi = turning_angles(theta, d) - d.phi0
    return 0.5 * B * jnp.sum(dphi**2 / d.ell)
