r"""Structured linear algebra for the bordered tridiagonal Hessian.

The Hessian of the condensed Lagrangian $\tilde{\mathcal L}(\theta,\mu)$ (see
`jaxrod/energy/lagrangian.py`) has the block form

$$\mathsf K = \begin{pmatrix} T & P \\ P^\top & C\end{pmatrix},\qquad
T\in\mathbb R^{N\times N}\ \text{tridiagonal},\ P\in\mathbb R^{N\times 2},\
C\in\mathbb R^{2\times 2}\ (C=0\ \text{when inextensible}).$$

* It is assembled from 5 Hessian-vector products of the autodiff gradient: three
  colour probes recover the tridiagonal block ($|i-j|\le1$ means columns $i\bmod 3$
  never collide), two unit probes recover the border.
* Solves use `jaxrod.linalg.batched.tridiagonal_solve` (LAPACK `gtsv`; a pivoting scan under `vmap`)
  on three right-hand sides and a $2\times2$ Schur complement $S=C-P^\top T^{-1}P$: $O(N)$.
* Stability: the constrained stiffness problem is $T v + P w = \lambda v$,
  $P^\top v + Cw = 0$. By Haynsworth's inertia additivity the number of its
  eigenvalues below $\sigma$ is
  $\nu(\sigma) = n_-(T-\sigma I) + n_-(S(\sigma)) - 2$, where $n_-(T-\sigma I)$ comes
  from the $LDL^\top$ pivots of the tridiagonal block (a Sturm count) and the $-2$ is the
  two negative directions the end constraints (or the stretching compliance) always
  contribute. $\nu(0)=0$ is strict stability; bisection on $\nu$ gives any eigenvalue.

**With self-contact** (`scene.contact`) the $\theta\theta$ block is $T+H_c$, $H_c$ the dense
contact Hessian (`jaxrod.energy.contact.contact_hessian`): [`structured`][] returns a
[`BorderedDense`][] and every function here dispatches on it: solves are one dense LU of
the $(N+2)\times(N+2)$ matrix, $\nu(\sigma)$ the count of its negative eigenvalues minus 2
(one symmetric eigendecomposition), and the smallest constrained eigenvalues come from one
eigendecomposition of the reduced matrix: $\Pi A\Pi+c\,(I-\Pi)$ with
$\Pi=I-P(P^\top P)^{-1}P^\top$ and $c$ above $A$'s spectrum when $C=0$, else
$A-PC^{-1}P^\top$. $O(N^3)$ instead of $O(N)$: at N = 100 a dense factorization costs
about as much as the contact Hessian's assembly, see `benchmarks/bench_contact.py`.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array

from .batched import eigh as _eigh, solve as _dense_solve, solve2 as _solve2, tridiagonal_solve


class BorderedTridiagonal(NamedTuple):
    lower: Array  # (N,) lower[i] = T[i, i-1], lower[0] = 0
    diag: Array  # (N,)
    upper: Array  # (N,) upper[i] = T[i, i+1], upper[-1] = 0
    border: Array  # (N, 2)
    corner: Array  # (2, 2)

    @property
    def n(self):
        return self.diag.shape[-1]

    def dense(self):
        """The full (N+2)x(N+2) matrix (tests and small problems only)."""
        N = self.n
        T = jnp.diag(self.diag) + jnp.diag(self.upper[:-1], 1) + jnp.diag(self.lower[1:], -1)
        top = jnp.concatenate([T, self.border], axis=1)
        bot = jnp.concatenate([self.border.T, self.corner], axis=1)
        del N
        return jnp.concatenate([top, bot], axis=0)


class BorderedDense(NamedTuple):
    """The bordered Hessian with a dense theta-theta block (self-contact), fields as
    `BorderedTridiagonal` with `block` (N, N) in place of the three diagonals."""

    block: Array  # (N, N)
    border: Array  # (N, 2)
    corner: Array  # (2, 2)

    @property
    def n(self):
        return self.block.shape[-1]

    @property
    def diag(self):
        return jnp.diagonal(self.block, axis1=-2, axis2=-1)

    def dense(self):
        top = jnp.concatenate([self.block, self.border], axis=1)
        bot = jnp.concatenate([self.border.T, self.corner], axis=1)
        return jnp.concatenate([top, bot], axis=0)


def _shifted(K: BorderedDense, shift):
    N = K.n
    dtype = K.block.dtype
    return K.dense() - shift * jnp.diag(jnp.concatenate([jnp.ones(N, dtype), jnp.zeros(2, dtype)]))


def assemble(grad_fn, theta, mu) -> BorderedTridiagonal:
    """Assemble the Hessian of a scalar function from its gradient `grad_fn(theta, mu)`
    (returning `(g_theta, g_mu)`) with 5 Hessian-vector products. Assumes the
    theta-theta block is tridiagonal (true for every energy in jaxrod)."""
    N = theta.shape[0]
    dtype = theta.dtype
    idx = jnp.arange(N)
    colours = (idx[None, :] % 3 == jnp.arange(3)[:, None]).astype(dtype)  # (3, N)
    vt = jnp.concatenate([colours, jnp.zeros((2, N), dtype)], axis=0)
    vm = jnp.concatenate([jnp.zeros((3, 2), dtype), jnp.eye(2, dtype=dtype)], axis=0)

    def hvp(dt, dm):
        return jax.jvp(grad_fn, (theta, mu), (dt, dm))[1]

    ht, hm = jax.vmap(hvp)(vt, vm)  # (5, N), (5, 2)
    diag = ht[idx % 3, idx]
    upper = jnp.where(idx < N - 1, ht[(idx + 1) % 3, idx], 0.0)
    lower = jnp.where(idx > 0, ht[(idx - 1) % 3, idx], 0.0)
    border = ht[3:].T  # (N, 2)
    corner = hm[3:]  # (2, 2)
    return BorderedTridiagonal(lower, diag, upper, border, corner)


def structured(theta, mu, scene, d=None) -> BorderedTridiagonal:
    """The Hessian of the condensed Lagrangian, assembled per stencil (see
    `jaxrod.energy.lagrangian.hessian_blocks`); equal to `assemble` of its gradient."""
    from ..energy.lagrangian import hessian_blocks

    K = BorderedTridiagonal(*hessian_blocks(theta, mu, scene, d))
    if scene.contact is None:
        return K
    from ..energy.contact import contact_hessian

    return BorderedDense(K.dense()[:-2, :-2] + contact_hessian(theta, scene, d), K.border, K.corner)


def matvec(K: BorderedTridiagonal, vt, vm):
    if isinstance(K, BorderedDense):
        return K.block @ vt + K.border @ vm, K.border.T @ vt + K.corner @ vm
    Tv = K.diag * vt + K.upper * jnp.roll(vt, -1) + K.lower * jnp.roll(vt, 1)
    return Tv + K.border @ vm, K.border.T @ vt + K.corner @ vm


def matvec_columns(K: BorderedTridiagonal, Vt, Vm):
    """[`matvec`][] of each column of `Vt` (N, k), `Vm` (2, k)."""
    if isinstance(K, BorderedDense):
        return K.block @ Vt + K.border @ Vm, K.border.T @ Vt + K.corner @ Vm
    Tv = K.diag[:, None] * Vt + K.upper[:, None] * jnp.roll(Vt, -1, axis=0) + K.lower[:, None] * jnp.roll(Vt, 1, axis=0)
    return Tv + K.border @ Vm, K.border.T @ Vt + K.corner @ Vm


def _tri(K, shift, rhs):
    return tridiagonal_solve(K.lower, K.diag - shift, K.upper, rhs)


def solve(K: BorderedTridiagonal, rt, rm, shift=0.0):
    r"""Solve $(\mathsf K-\sigma\,\mathrm{diag}(I,0))\,(a,b) = (r_\theta, r_\mu)$ in $O(N)$."""
    if isinstance(K, BorderedDense):
        x = _dense_solve(_shifted(K, shift), jnp.concatenate([rt, rm]))
        return x[:-2], x[-2:]
    X = _tri(K, shift, jnp.concatenate([rt[:, None], K.border], axis=1))
    S = K.corner - K.border.T @ X[:, 1:]
    b = _solve2(S, rm - K.border.T @ X[:, 0])
    a = X[:, 0] - X[:, 1:] @ b
    return a, b


def solve_columns(K: BorderedTridiagonal, Rt, Rm):
    r"""$\mathsf K\,(A, B) = (R_\theta, R_\mu)$ for $k$ right-hand sides at once (`Rt` of shape
    (N, k), `Rm` (2, k)): one tridiagonal solve with the $k$ columns and the two border
    columns, each column as [`solve`][] computes it alone. Returns `(A, B, nu)` with
    $\nu(0)$, the number of negative constrained eigenvalues, from the same solve's Schur
    complement $S=C-P^\top T^{-1}P$ (`count_below` at zero, without a second solve)."""
    if isinstance(K, BorderedDense):
        X = _dense_solve(K.dense(), jnp.concatenate([Rt, Rm], axis=0))
        return X[:-2], X[-2:], count_below(K, jnp.zeros(1, K.block.dtype))[0]
    k = Rt.shape[1]
    X = _tri(K, 0.0, jnp.concatenate([Rt, K.border], axis=1))
    S = K.corner - K.border.T @ X[:, k:]
    B = jnp.stack([_solve2(S, Rm[:, j] - K.border.T @ X[:, j]) for j in range(k)], axis=1)
    A = X[:, :k] - X[:, k:] @ B
    nu = _pivot_negatives(K, jnp.zeros(1, K.diag.dtype))[0] + _sym2_negatives(S) - 2
    return A, B, nu


def _pivot_negatives(K: BorderedTridiagonal, shifts):
    """n_-(T - sigma I) for a vector of shifts, from the LDL^T pivots (Sturm count)."""
    tiny = jnp.finfo(K.diag.dtype).tiny ** 0.5

    def body(carry, x):
        dprev, count = carry
        di, li = x
        dprev = jnp.where(jnp.abs(dprev) < tiny, -tiny, dprev)
        p = (di - shifts) - li**2 / dprev
        return (p, count + (p < 0)), None

    init = (jnp.ones_like(shifts), jnp.zeros(shifts.shape, jnp.int32))
    (_, count), _ = lax.scan(body, init, (K.diag, K.lower))
    return count


def _sym2_negatives(S):
    """Number of negative eigenvalues of symmetric 2x2 matrices, shape (..., 2, 2)."""
    a, b, c = S[..., 0, 0], 0.5 * (S[..., 0, 1] + S[..., 1, 0]), S[..., 1, 1]
    det = a * c - b * b
    tr = a + c
    return jnp.where(det < 0, 1, jnp.where(tr < 0, 2, 0)).astype(jnp.int32)


def count_below(K: BorderedTridiagonal, shifts):
    r"""$\nu(\sigma)$: number of constrained stiffness eigenvalues below each shift."""
    shifts = jnp.atleast_1d(shifts)
    if isinstance(K, BorderedDense):
        return jax.vmap(lambda sig: jnp.sum(_eigh(_shifted(K, sig))[0] < 0).astype(jnp.int32) - 2)(shifts)
    neg_t = _pivot_negatives(K, shifts)

    def schur(sig):
        X = _tri(K, sig, K.border)
        return K.corner - K.border.T @ X

    S = jax.vmap(schur)(shifts)
    return neg_t + _sym2_negatives(S) - 2


def gershgorin(K: BorderedTridiagonal):
    r = jnp.abs(K.lower) + jnp.abs(K.upper)
    return jnp.min(K.diag - r), jnp.max(K.diag + r)


def smallest_eigenvalues(K: BorderedTridiagonal, k: int = 4, iters: int | None = None):
    r"""The `k` smallest constrained stiffness eigenvalues, by bisection on $\nu(\sigma)$.

    Brackets: $\lambda_j \ge \lambda_{\min}(T)$ and $\lambda_j\le\lambda_{j+2}(T)$
    (interlacing), both inside the Gershgorin interval of $T$. Each bisection step is one
    vectorized Sturm count: $O(kN)$ work per step, `iters` steps (default: enough to reach
    machine precision).
    """
    if isinstance(K, BorderedDense):
        return _dense_smallest(K)[:k]
    lo0, hi0 = gershgorin(K)
    width = hi0 - lo0
    dtype = K.diag.dtype
    if iters is None:
        iters = 64 if dtype == jnp.float64 else 32
    j = jnp.arange(k)
    lo = jnp.full((k,), lo0 - 1e-3 * jnp.abs(width) - 1.0, dtype)
    hi = jnp.full((k,), hi0 + 1e-3 * jnp.abs(width) + 1.0, dtype)

    def body(_, lh):
        lo, hi = lh
        mid = 0.5 * (lo + hi)
        below = count_below(K, mid) > j  # at least j+1 eigenvalues below mid
        return jnp.where(below, lo, mid), jnp.where(below, mid, hi)

    lo, hi = lax.fori_loop(0, iters, body, (lo, hi))
    return 0.5 * (lo + hi)


def _dense_smallest(K: BorderedDense):
    """Every constrained eigenvalue (ascending) of a `BorderedDense` (module docstring)."""
    A, P, C = K.block, K.border, K.corner
    N = K.n
    dtype = A.dtype
    eye = jnp.eye(N, dtype=dtype)
    proj = P @ _solve2(P.T @ P, P.T)  # P (P^T P)^{-1} P^T
    Pi = eye - proj
    c = jnp.max(jnp.sum(jnp.abs(A), 1)) + 1.0
    rigid = jnp.all(C == 0)
    Cs = jnp.where(rigid, jnp.eye(2, dtype=dtype), C)
    M = jnp.where(rigid, Pi @ A @ Pi + c * proj, A - P @ _solve2(Cs, P.T))
    return _eigh(M)[0]  # rigid: the two eigenvalues near c (the constraint directions) come last


def _inverse_iteration(K: BorderedTridiagonal, lam, iterations: int):
    r"""`(v, estimate)`: `iterations` steps of inverse iteration shifted just below `lam`
    ($\sigma=\lambda-10^{-9}\max|\mathrm{diag}\,T|$) from a fixed smooth start, `v` the
    theta part with unit norm and its largest component positive, `estimate` the eigenvalue
    from the last step's Rayleigh quotient of the inverse, $\sigma+v^\top v/v^\top a$ with
    $(\mathsf K-\sigma)\,a=v$."""
    N = K.n
    dtype = K.diag.dtype
    x = jnp.linspace(0.0, 1.0, N, dtype=dtype)
    start = 1.0 + jnp.sin(3.7 * x) + 0.5 * jnp.cos(11.3 * x) + 0.3 * x
    sig = lam - 1e-9 * jnp.maximum(jnp.max(jnp.abs(K.diag)), 1.0)

    def it(_, c):
        v, _est = c
        a, _b = solve(K, v, jnp.zeros(2, dtype), shift=sig)
        return a / jnp.linalg.norm(a), sig + jnp.dot(v, v) / jnp.dot(v, a)

    v, est = lax.fori_loop(0, iterations, it, (start / jnp.linalg.norm(start), jnp.zeros((), dtype)))
    return v * jnp.sign(v[jnp.argmax(jnp.abs(v))]), est


def modes(K: BorderedTridiagonal, eigenvalues, iterations: int = 3):
    """Eigenvectors (theta part, unit norm, largest component positive, columns) by shifted
    inverse iteration."""
    V, _ = jax.vmap(lambda lam: _inverse_iteration(K, lam, iterations))(eigenvalues)  # (k, N)
    return V.T


def critical_pair(K: BorderedTridiagonal):
    r"""The constrained eigenvalue nearest zero and its eigenvector (theta part, unit norm,
    largest component positive as in [`modes`][]): `(v, lam)`, by three steps of shifted
    inverse iteration at $\sigma\approx0$, the eigenvalue from the last step's Rayleigh
    quotient of the inverse (`_inverse_iteration`). Meant for a state next to a critical
    point (a fold or a branch point), where that eigenvalue is about zero and isolated: each
    step reduces the other components by $|\lambda_1-\sigma|/|\lambda_2-\sigma|\ll1$ and the
    eigenvalue's error is the square of the vector's. The vector of
    `modes(K, smallest_eigenvalues(K, 1))` there, at the cost of 3 solves instead of 64
    Sturm counts more."""
    return _inverse_iteration(K, jnp.zeros((), K.diag.dtype), 3)
