r"""Kinematics of the strip: the segments' axial loads and strains and the node positions
they give (`jaxrod.energy.lagrangian` has the energy; docs/model.md the conventions).

Segment $i$ has tangent $t_i=(\cos\theta_i,\sin\theta_i)$, rest length $h_i$ and axial load
$a_i=W_i\sin\theta_i-\mu\cdot t_i$ ($\mu$ the end force, $W_i$ the weight it carries); with
axial stiffness $K$ its strain is $\varepsilon_i=-a_i/K$ (zero when inextensible), and the
nodes are $r_i=\sum_{j\le i}h_j(1+\varepsilon_j)t_j$ from the left clamp at the origin.
"""

from __future__ import annotations

import jax.numpy as jnp

from .geometry import discretize


def gravity_weights(scene, d):
    """$W_i = g\\sum_{j=i}^{N-1} m_j$: weight carried by segment i (fixed end nodes excluded)."""
    if scene.gravity is None:
        return None
    m = d.node_mass.at[0].set(0.0).at[-1].set(0.0)
    tail = jnp.cumsum(m[::-1])[::-1]  # tail[j] = sum_{k>=j} m_k
    return scene.gravity.g * tail[1:]  # segment i (1-based) -> nodes i..N-1


def axial_load(theta, mu, scene, d):
    a = -(mu[0] * jnp.cos(theta) + mu[1] * jnp.sin(theta))
    W = gravity_weights(scene, d)
    if W is not None:
        a = a + W * jnp.sin(theta)
    return a


def strains(theta, mu, scene, d):
    r"""Axial strains $\varepsilon_i=-a_i/K$ (zero when inextensible)."""
    if scene.stretching is None:
        return jnp.zeros_like(theta)
    return -axial_load(theta, mu, scene, d) / scene.stretching.stiffness


def positions(theta, mu, scene, d=None):
    r"""Node positions $r_i=\sum_{j\le i}h_j(1+\varepsilon_j)t_j$, shape (N+1, 2)."""
    if d is None:
        d = discretize(scene)
    eps = strains(theta, mu, scene, d)
    e = (d.h * (1.0 + eps))[:, None] * jnp.stack([jnp.cos(theta), jnp.sin(theta)], -1)
    return jnp.concatenate([jnp.zeros((1, 2), e.dtype), jnp.cumsum(e, axis=0)], axis=0)
