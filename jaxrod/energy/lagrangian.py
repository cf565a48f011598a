r"""The condensed Lagrangian that statics, stability and gradients all differentiate.

Unknowns: segment angles $\theta\in\mathbb R^N$ and the end force $\mu\in\mathbb R^2$,
the force the right clamp exerts on the strip (compression: $\mu_x<0$). Segment $i$ has
stretched length $h_i(1+\varepsilon_i)$, tangent $t_i=(\cos\theta_i,\sin\theta_i)$.
With gravity $g$ on the lumped node masses $m_j$ and $W_i=g\sum_{j\ge i,\,j<N} m_j$,

$$\mathcal L = E_b(\theta) + \sum_i \tfrac K2 h_i\varepsilon_i^2
 + \sum_i h_i(1+\varepsilon_i)\,a_i(\theta_i,\mu) + \mu_x G,\qquad
 a_i = W_i\sin\theta_i - \mu\cdot t_i .$$

Stationarity in $\mu$ is the end condition $\sum_i h_i(1+\varepsilon_i)t_i=(G,0)$.
$\varepsilon$ enters quadratically and is eliminated exactly, $\varepsilon_i=-a_i/K$
(tension $\mu\cdot t_i$ over $K$), giving

$$\tilde{\mathcal L}(\theta,\mu) = E_b + \sum_i h_i a_i - \sum_i \frac{h_i a_i^2}{2K} + \mu_x G .$$

Its Hessian is tridiagonal in $\theta$, bordered by two columns in $\mu$; the inextensible
strip is $K=\infty$ (the last sum dropped). A scene with self-contact adds the contact energy
$E_c(\theta)$ of `jaxrod.energy.contact` (inextensible positions), whose Hessian is dense.

The gradient and Hessian are written out (`lagrangian_gradient`, `hessian_blocks`) rather
than taken by autodiff of $\tilde{\mathcal L}$: with $c_i=\cos\theta_i$, $s_i=\sin\theta_i$,
$a_i=-\mu_xc_i-\mu_ys_i+W_is_i$, $\partial_\theta a_i=\mu_xs_i-\mu_yc_i+W_ic_i$,
$\partial_\theta^2a_i=-a_i$, $\partial_\mu a_i=-(c_i,s_i)$, and the segment term
$f_i=h_i(a_i-a_i^2/2K)$,

$$\nabla f_i=h_i(1-a_i/K)\,\mathbf g_i,\quad
\nabla^2f_i=h_i\Big[(1-a_i/K)\begin{pmatrix}-a_i&s_i&-c_i\\ s_i&0&0\\ -c_i&0&0\end{pmatrix}
-\frac1K\mathbf g_i\mathbf g_i^\top\Big],\quad
\mathbf g_i=(\partial_\theta a_i,-c_i,-s_i)$$

in $(\theta_i,\mu_x,\mu_y)$, and the bending gradient $q_{k-1}-q_k$ with
$q_k=B(\phi_k-\bar\phi_k)/\ell_k$. Autodiff of the scalar Lagrangian gave the same numbers
(tested to round-off) with several times the operations in every compiled program that
solves an equilibrium; the derivatives with respect to scene parameters (implicit
differentiation) are still autodiff of these expressions.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .bending import bending_energy, turning_angles
from .contact import contact_energy
from .geometry import discretize
from .kinematics import axial_load, gravity_weights, positions, strains  # noqa: F401 (public here too)
from .._compile import traced_once


def _segment_terms(theta_i, mu, h_i, W_i, inv_K):
    r"""Per-segment part $h_i a_i - h_i a_i^2/(2K)$ of $\tilde{\mathcal L}$."""
    a = -(mu[0] * jnp.cos(theta_i) + mu[1] * jnp.sin(theta_i)) + W_i * jnp.sin(theta_i)
    return h_i * a - 0.5 * inv_K * h_i * a**2


def _segment_data(scene, d):
    W = gravity_weights(scene, d)
    W = jnp.zeros_like(d.h) if W is None else W
    inv_K = 0.0 if scene.stretching is None else 1.0 / scene.stretching.stiffness
    return W, jnp.asarray(inv_K, d.h.dtype)


@traced_once
def lagrangian(theta, mu, scene, d=None):
    r"""$\tilde{\mathcal L}(\theta,\mu)$, see the module docstring."""
    if d is None:
        d = discretize(scene)
    W, inv_K = _segment_data(scene, d)
    seg = jax.vmap(_segment_terms, in_axes=(0, None, 0, 0, None))(theta, mu, d.h, W, inv_K)
    e = bending_energy(theta, scene, d) + jnp.sum(seg) + mu[0] * scene.clamps.gap
    if scene.contact is not None:
        e = e + contact_energy(theta, scene, d)
    return e


def _segment_derivatives(theta, mu, d, W, inv_K):
    r"""Per segment: $a_i$, $\partial_\theta a_i$, $c_i$, $s_i$ and $h_i(1-a_i/K)$."""
    c, s = jnp.cos(theta), jnp.sin(theta)
    a = -mu[0] * c - mu[1] * s + W * s
    a_t = mu[0] * s - mu[1] * c + W * c
    return a, a_t, c, s, d.h * (1.0 - inv_K * a)


@traced_once
def lagrangian_gradient(theta, mu, scene, d=None):
    r"""$(\partial_\theta\tilde{\mathcal L},\partial_\mu\tilde{\mathcal L})$, shapes (N,)
    and (2,): the equilibrium residual (formulas in the module docstring)."""
    if d is None:
        d = discretize(scene)
    W, inv_K = _segment_data(scene, d)
    a, a_t, c, s, hk = _segment_derivatives(theta, mu, d, W, inv_K)
    q = scene.strip.bending_stiffness * (turning_angles(theta, d) - d.phi0) / d.ell
    g_theta = q[:-1] - q[1:] + hk * a_t
    if scene.contact is not None:
        g_theta = g_theta + jax.grad(contact_energy)(theta, scene, d)
    g_mu = jnp.stack([scene.clamps.gap - jnp.sum(hk * c), -jnp.sum(hk * s)])
    return g_theta, g_mu


@traced_once
def hessian_blocks(theta, mu, scene, d=None):
    r"""The Hessian of $\tilde{\mathcal L}$ as (lower, diag, upper, border, corner),
    assembled per stencil: the bending part is the constant tridiagonal matrix
    $B\,D^\top \mathrm{diag}(1/\ell) D$, the segment terms contribute the $3\times3$
    Hessians in $(\theta_i,\mu)$ of the module docstring. Without the contact energy
    (whose dense Hessian `jaxrod.linalg.kkt.structured` adds)."""
    if d is None:
        d = discretize(scene)
    B = scene.strip.bending_stiffness
    kb = B / d.ell  # (N+1,) hinge stiffnesses
    W, inv_K = _segment_data(scene, d)
    a, a_t, c, s, hk = _segment_derivatives(theta, mu, d, W, inv_K)
    hK = d.h * inv_K
    # rows of h_i [(1 - a_i/K) A_i - g_i g_i^T / K], g_i = (a_t, -c, -s): theta-theta and theta-mu
    h_tt = -hk * a - hK * a_t * a_t
    border = jnp.stack([hk * s + hK * a_t * c, -hk * c + hK * a_t * s], -1)
    corner = -jnp.stack([jnp.stack([jnp.sum(hK * c * c), jnp.sum(hK * c * s)]),
                         jnp.stack([jnp.sum(hK * c * s), jnp.sum(hK * s * s)])])
    diag = kb[:-1] + kb[1:] + h_tt
    off = -kb[1:-1]
    zero = jnp.zeros((1,), theta.dtype)
    upper = jnp.concatenate([off, zero])
    lower = jnp.concatenate([zero, off])
    return lower, diag, upper, border, corner


def energies(theta, mu, scene, d=None):
    """Bending, stretching and gravitational energies (a dict of scalars)."""
    if d is None:
        d = discretize(scene)
    out = {"bending": bending_energy(theta, scene, d)}
    if scene.stretching is not None:
        eps = strains(theta, mu, scene, d)
        out["stretching"] = 0.5 * scene.stretching.stiffness * jnp.sum(d.h * eps**2)
    else:
        out["stretching"] = jnp.zeros((), theta.dtype)
    if scene.gravity is not None:
        y = positions(theta, mu, scene, d)[:, 1]
        out["gravity"] = scene.gravity.g * jnp.sum(d.node_mass[1:-1] * y[1:-1])
    else:
        out["gravity"] = jnp.zeros((), theta.dtype)
    out["contact"] = contact_energy(theta, scene, d)
    return out
