r"""Stability of an equilibrium: smallest eigenvalues and modes of the constrained Hessian.

The stiffness problem is $T v + P w = \lambda v$, $P^\top v + C w = 0$ (see `kkt.py`):
the Hessian of the energy restricted to perturbations that keep both clamps in place,
every mode included, symmetric and asymmetric alike. Eigenvalues come from bisection on
the Sturm-type count $\nu(\sigma)$ ($O(kN)$ per step), modes from shifted inverse
iteration. The mirror symmetry $\theta(s)\to-\theta(L-s)$ splits modes into symmetric
($\delta\theta_i=-\delta\theta_{N+1-i}$, parity $+1$) and asymmetric (parity $-1$).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array

from ..linalg import kkt
from ..linalg.batched import solve2
from .._misc import check_int
from .._compile import jit


class Stability(eqx.Module):
    """`eigenvalues` (k,), ascending; `modes` (N, k) unit vectors in angle space;
    `parity` (k,) in [-1, 1] (+1 symmetric, -1 asymmetric); `num_unstable` (negative
    eigenvalue count over the whole spectrum); `stable`."""

    eigenvalues: Array
    modes: Array
    parity: Array
    num_unstable: Array

    @property
    def stable(self):
        return self.num_unstable == 0


def hessian(eq) -> kkt.BorderedTridiagonal:
    """The bordered tridiagonal Hessian of the condensed Lagrangian at `eq`."""
    scene = jax.lax.stop_gradient(eq.scene)
    return kkt.structured(jax.lax.stop_gradient(eq.theta), jax.lax.stop_gradient(eq.force), scene)


def mode_parity(modes):
    """Overlap of each mode with its mirror image: +1 symmetric, -1 asymmetric."""
    mirrored = -modes[::-1]
    return jnp.sum(modes * mirrored, axis=0)


@jit
def stability(eq, k: int = 4) -> Stability:
    r"""The `k` smallest eigenvalues of the constrained Hessian at `eq`, their modes and
    parities, and the count of negative eigenvalues. `k`: an integer from 1 to N - 2, the
    number of degrees of freedom of an inextensible strip (the end condition removes two;
    an extensible strip has N, but its bisection brackets, $\lambda_j\le\lambda_{j+2}(T)$,
    hold for the N - 2 lowest only: above them it returned the bracket's end, not the
    eigenvalue)."""
    check_int("k", k, lo=1, hi=eq.theta.shape[0] - 2)
    K = hessian(eq)
    lam = kkt.smallest_eigenvalues(K, k)
    V = kkt.modes(K, lam)
    nneg = kkt.count_below(K, jnp.zeros(1, lam.dtype))[0]
    return Stability(lam, V, mode_parity(V), nneg)


def dense_reduced_hessian(eq):
    r"""Dense reference: $Z^\top (T - P C^{+} P^\top) Z$ is not used; instead return the
    eigenvalues of the pencil via the null space of $P^\top$ (inextensible) or the Schur
    form $T - P C^{-1} P^\top$ (extensible). $O(N^3)$, for tests and the naive baseline."""
    K = hessian(eq)
    Kd = K.dense()
    N = K.n
    T, P, C = Kd[:N, :N], Kd[:N, N:], Kd[N:, N:]
    if eq.scene.stretching is None:
        q, _ = jnp.linalg.qr(P, mode="complete")
        Z = q[:, 2:]
        return Z.T @ T @ Z
    return T - P @ solve2(C, P.T)
