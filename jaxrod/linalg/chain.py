r"""The Newton system of the strip's implicit step, solved in $O(N)$ along the chain.

The strip's angles $\theta_1..\theta_N$ place the nodes at $\mathbf X_k=\sum_{i\le k}h_i\mathbf t_i$;
a small change $y=\delta\theta$ moves node $k$ by $\mathbf X_k(y)=\sum_{i\le k}\mathbf v_iy_i$,
$\mathbf v_i=h_i\mathbf n_i$. The implicit step's Newton system is the stationarity of

$$\Phi(y)=\tfrac12\sum_{k=1}^{N}m_k|\mathbf X_k|^2+\tfrac12\sum_{i=1}^Nd_iy_i^2
+\tfrac12\sum_{k=0}^{N}w_k(y_{k+1}-y_k)^2-r^\top y\quad\text{s.t.}\quad\mathbf X_N=\mathbf c,$$

($y_0=y_{N+1}=0$: the clamps), i.e. the bordered system
$(J^\top mJ+\mathrm{diag}\,d+D^\top wD)\,y+V^\top\boldsymbol\lambda=r$, $Vy=\mathbf c$, whose
matrix $J^\top mJ$ (the chain's mass matrix) is dense. It is solved exactly, without forming
it, as a discrete optimal-control problem along the chain: state $z_i=(y_i,\mathbf X_i,
\boldsymbol\lambda)\in\mathbb R^5$, control $y_{i+1}$, transition $\mathbf X_{i+1}=\mathbf X_i+\mathbf v_{i+1}y_{i+1}$.
A backward sweep from the tip carries the quadratic cost-to-go $\tfrac12z^\top P_iz+q_i^\top z$
and eliminates one scalar $y_{i+1}$ per link (a division, no matrix inverse); at the base
($y_0=0$, $\mathbf X_0=0$) a 2x2 solve gives $\boldsymbol\lambda$, and a forward sweep gives $y$.
Both sweeps are `lax.scan`s of scalar arithmetic: $O(N)$ work, vectorized over a batch.
The elimination pivots are the Schur complements of the chain; they are positive where the
matrix is positive definite on the constraint's null space (the implicit step's case, whose
mass term $m_k\propto 1/\Delta t^2$ dominates).
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import lax


def chain_solve(v, m, d, w, r, c):
    r"""Solve the bordered chain system of the module docstring.

    **Arguments:** `v` (N, 2) the node-motion vectors $\mathbf v_i=h_i\mathbf n_i$; `m` (N,)
    the node weights $m_1..m_N$; `d` (N,) the diagonal; `w` (N+1,) the hinge weights
    $w_0..w_N$; `r` (N,) the right-hand side; `c` (2,) the prescribed tip displacement.

    **Returns:** `(y, lam)`, shapes (N,) and (2,).

    State index 0 is $y_i$, 1-2 are $\mathbf X_i$, 3-4 are $\boldsymbol\lambda$; the backward sweep
    carries $[P_i\,|\,q_i]$ as one (5, 6) array and records, per link, the elimination's
    $(\mathbf b,\beta,a)$ with $y_{i+1}=-(\mathbf b\cdot z_i+\beta)/a$.
    """
    n = r.shape[0]; dt = r.dtype
    # state columns 0..4 = P, column 5 = q ; P symmetric
    e0 = jnp.zeros(5, dt).at[0].set(1.0)
    keep = jnp.array([0., 1., 1., 1., 1.], dt)
    K2 = keep[:, None] * keep[None, :]
    E00 = jnp.zeros((5, 5), dt).at[0, 0].set(1.0)
    IX = jnp.diag(jnp.array([0., 1., 1., 0., 0.], dt))
    P = jnp.diag(jnp.stack([w[n], m[n-1], m[n-1], jnp.zeros((), dt), jnp.zeros((), dt)]))
    P = P.at[1, 3].set(1.0).at[3, 1].set(1.0).at[2, 4].set(1.0).at[4, 2].set(1.0)
    q = jnp.zeros(5, dt).at[3].set(-c[0]).at[4].set(-c[1])
    Pq = jnp.concatenate([P, q[:, None]], 1)  # (5, 6)
    m_base = jnp.concatenate([jnp.zeros(1, dt), m[:-1]])
    ones = jnp.ones(n, dt); zeros = jnp.zeros(n, dt)
    E = jnp.stack([ones, v[:, 0], v[:, 1], zeros, zeros], 1)  # (n, 5)
    sc = jnp.stack([w[:n], d, r, m_base], 1)  # (n, 4)

    def back(Pq, inp):
        e, s = inp
        wi, dn, rn, mi = s[0], s[1], s[2], s[3]
        Pe5 = Pq[:, :5] @ e
        a = wi + dn + e @ Pe5
        b = keep * Pe5 - wi * e0
        beta = e @ Pq[:, 5] - rn
        bb = jnp.concatenate([b, jnp.stack([beta])])  # (6,)
        Pn = K2 * Pq[:, :5] + wi * E00 + mi * IX
        qn = keep * Pq[:, 5]
        out = jnp.concatenate([Pn, qn[:, None]], 1) - b[:, None] * bb[None, :] / a
        return out, jnp.concatenate([bb, a[None]])

    Pq, out = lax.scan(back, Pq, (E, sc), reverse=True, unroll=2)
    P = Pq[:, :5]; q = Pq[:, 5]
    p11, p12, p22 = P[3, 3], P[3, 4], P[4, 4]
    det = p11 * p22 - p12 * p12
    lam = jnp.stack([-(p22 * q[3] - p12 * q[4]) / det, -(p11 * q[4] - p12 * q[3]) / det])
    # y_{i+1} = -(b.z + beta)/a with z = (y, X0, X1, lam0, lam1)
    def fwd(carry, inp):
        z3, vv = carry, None
        o, vn = inp
        y = -(o[0] * carry[0] + o[1] * carry[1] + o[2] * carry[2] + o[3] * lam[0] + o[4] * lam[1] + o[5]) / o[6]
        return jnp.stack([y, carry[1] + vn[0] * y, carry[2] + vn[1] * y]), y
    _, y = lax.scan(fwd, jnp.zeros(3, dt), (out, v), unroll=2)
    return y, lam
