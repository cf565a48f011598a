r"""The Newton system of the strip's implicit step, solved in $O(N)$ along the chain.

The strip's angles $\theta_1..\theta_N$ place the nodes at $\mathbf X_k=\sum_{i\le k}h_i\mathbf t_i$;
a small change $y=\delta\theta$ moves node $k$ by $\mathbf X_k(y)=\sum_{i\le k}\mathbf v_iy_i$,
$\mathbf v_i=h_i\mathbf n_i$. The implicit step's Newton system is the stationarity of

$$\Phi(y)=\tfrac12\sum_{k=1}^{N}m_k|\mathbf X_k|^2+\tfrac12\sum_{i=1}^Nd_iy_i^2
+\tfrac12\sum_{k=0}^{N}w_k(y_{k+1}-y_k)^2-r^\top y\quad\text{s.t.}\quad\mathbf X_N=\mathbf c,$$

($y_0=y_{N+1}=0$: the clamps), i.e. the bordered system
$(J^\top mJ+\mathrm{diag}\,d+D^\top wD)\,y+V^\top\boldsymbol\lambda=r$, $Vy=\mathbf c$, whose
matrix $J^\top mJ$ (the chain's mass matrix) is dense. With the inertia's dependence on the
rates kept (Newton's matrix of the implicit step), the mass term becomes $J^\top m\tilde J$, whose
$\tilde J$ moves the nodes with other vectors $\mathbf u_j$: no longer symmetric.

Both are solved exactly, without forming the dense matrix, by Gaussian elimination along
the chain (`chain_solve`): a backward sweep from the tip expresses each link's $y_i$ and the
tail sum of the inertial terms as affine functions of the state before it (the elimination
pivot is one scalar per link: a division, no matrix inverse), a forward sweep carries the
solution as an affine function of $\boldsymbol\lambda$, and the end condition gives
$\boldsymbol\lambda$ (2x2). Both sweeps are `lax.scan`s over small arrays: $O(N)$ work,
vectorized over a batch. The pivots are Schur complements of the chain, positive where the
matrix is positive definite on the constraint's null space (the implicit step's case, whose
mass term $m_k\propto1/\Delta t^2$ dominates).
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import lax


def chain_solve(v, m, d, w, r, c, u=None):
    r"""Solve the chain system of the module docstring, or, with `u`, the one whose mass term is
    not symmetric:
    $v_i\cdot\big(\sum_{k\ge i}m_k\tilde{\mathbf X}_k+\boldsymbol\lambda\big)+d_iy_i+(D^\top wDy)_i=r_i$,
    $\sum_iv_iy_i=\mathbf c$, with $\tilde{\mathbf X}_k=\sum_{j\le k}\mathbf u_jy_j$ (`u` (N, 2), default
    `v`: the symmetric system). Newton's matrix of the implicit step has this form once the
    inertia's dependence on the rates (its Coriolis and centripetal terms) is kept.

    Gaussian elimination along the chain, from the tip: the row of link $i$ gives $y_i$ as an
    affine function of the state $z_{i-1}=(y_{i-1},\tilde{\mathbf X}_{i-1},\boldsymbol\lambda)$ and the
    tail sum $\Pi_i=\sum_{k\ge i}m_k\tilde{\mathbf X}_k+\boldsymbol\lambda$ as another (both carried as
    one (3, 6) array: $[B\,|\,\mathbf b]$ for $\Pi$, $[\alpha\,|\,a]$ for the next $y$). A forward sweep
    then carries $y$, $\tilde{\mathbf X}$ and $\mathbf X=\sum v_jy_j$ as affine functions of
    $\boldsymbol\lambda$ (three columns), and the end condition $\mathbf X_N=\mathbf c$ gives
    $\boldsymbol\lambda$ (2x2, Cramer).

    **Arguments:** `v` (N, 2) the node-motion vectors $\mathbf v_i=h_i\mathbf n_i$; `m` (N,)
    the node weights $m_1..m_N$; `d` (N,) the diagonal; `w` (N+1,) the hinge weights
    $w_0..w_N$; `r` (N,) the right-hand side; `c` (2,) the prescribed tip displacement;
    `u` (N, 2) the vectors the mass term moves with (default `v`).

    **Returns:** `(y, lam)`, shapes (N,) and (2,).
    """
    if u is None:
        u = v
    n = r.shape[0]
    dt = r.dtype
    zeros, ones = jnp.zeros(n, dt), jnp.ones(n, dt)
    keep6 = jnp.array([0., 1., 1., 1., 1., 1.], dt)
    K = jnp.zeros((3, 6), dt).at[0, 3].set(1.0).at[1, 4].set(1.0)   # [B | b] ; [al | a]
    e = jnp.stack([ones, u[:, 0], u[:, 1], zeros, zeros], 1)          # z_i = E z_{i-1} + e y_i
    # per-row constant part of g6: mi*(0,v0,v1,0,0,0) + (di+wl+wr) e0 - r e5, and -wl on coef[0]
    g_const = jnp.stack([d + w[:n] + w[1:], m * v[:, 0], m * v[:, 1], zeros, zeros, -r], 1)
    mxr = jnp.zeros((n, 2, 6), dt).at[:, 0, 1].set(m).at[:, 1, 2].set(m)
    e0 = jnp.zeros(6, dt).at[0].set(1.0)
    inp = (v, e, g_const, w[:n], w[1:], mxr)

    def back(K, x):
        vi, ei, gc, wli, wri, mxi = x
        g6 = vi[0] * K[0] + vi[1] * K[1] - wri * K[2] + gc
        piv = jnp.sum(g6[:5] * ei)
        row2 = (wli * e0 - keep6 * g6) / piv
        BB = K[:2] + mxi
        Be = jnp.sum(BB[:, :5] * ei[None, :], 1)
        top = BB * keep6[None, :] + Be[:, None] * row2[None, :]
        return jnp.concatenate([top, row2[None]], 0), row2

    _, rows = lax.scan(back, K, inp, reverse=True, unroll=2)
    e7 = jnp.stack([ones, u[:, 0], u[:, 1], zeros, zeros, v[:, 0], v[:, 1]], 1)
    Z0 = jnp.zeros((7, 3), dt).at[3, 1].set(1.0).at[4, 2].set(1.0)
    keep7 = jnp.array([0., 1., 1., 1., 1., 1., 1.], dt)[:, None]
    unit = jnp.array([1., 0., 0.], dt)

    def fwd(Z, x):
        row2, ei7 = x
        yn = jnp.sum(row2[:5, None] * Z[:5], 0) + row2[5] * unit
        return keep7 * Z + ei7[:, None] * yn[None, :], yn

    Z, ys = lax.scan(fwd, Z0, (rows, e7), unroll=2)
    Xv = Z[5:7]
    det = Xv[0, 1] * Xv[1, 2] - Xv[0, 2] * Xv[1, 1]
    rhs = c - Xv[:, 0]
    lam = jnp.stack([(rhs[0] * Xv[1, 2] - Xv[0, 2] * rhs[1]) / det, (Xv[0, 1] * rhs[1] - rhs[0] * Xv[1, 1]) / det])
    return ys[:, 0] + ys[:, 1:] @ lam, lam
