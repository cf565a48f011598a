r"""Linear solves that stay correct, fast and deadlock-free under `vmap` on XLA:CPU.

**Why.** On the CPU, `lax.linalg.tridiagonal_solve`, `jnp.linalg.solve`, `lstsq` and `eigh`
are LAPACK custom calls. Batched (under `vmap`) they split the batch over the CPU thread
pool and wait for the pieces (jaxlib's `ParallelBatchMap`). When two such calls run at
once -- the snap-up and snap-down paths of `snap_angles` are independent, so XLA runs
them concurrently on the pool's threads -- on a machine with few cores each waits for
pieces queued behind the other and the program deadlocks (a `gdb` backtrace shows every
`tf_XLAEigen` thread in `jax::ParallelBatchMap` under `LuDecomposition` resp. `gtsv`; a
`vmap` of 41 `snap_angles` at N = 100 or of 256 equilibrium solves reproduces it;
docs/limitations.md).

**What.** Unbatched, the wrappers below call the same LAPACK routines as the JAX functions
they wrap (same numbers, same speed). Batched:

* [`tridiagonal_solve`][]: a batch small enough for jaxlib to run inline (`INLINE_WORK`,
  e.g. the 3-4 members of jaxrod's own internal `vmap`s) is one batched `gtsv`, as in JAX;
  a larger one below `SCAN_BATCH` loops over the members (one unbatched `gtsv` each);
  from `SCAN_BATCH` on, Gaussian elimination with partial pivoting (`gtsv`'s algorithm)
  runs as two `lax.scan`s over the rows, vectorized over the batch, whose cost is nearly
  flat in the batch size (so it beats the loop on large batches). Nested `vmap`s merge
  their batch axes and choose again;
* [`solve`][] (dense) and [`eigh`][] run the members one after another
  (`jax.custom_batching.sequential_vmap`), each an unbatched LAPACK LU or `syevd`.

Both are wrapped in `lax.custom_linear_solve`, so forward and reverse derivatives (with
respect to the matrix and the right-hand side) are the usual ones of a linear solve.

**Elimination with partial pivoting** (`_gtsv_scan`). Rows $i$ have entries
$(\ell_i, d_i, u_i)$ in columns $(i-1, i, i+1)$. Elimination keeps one *active* row $R$
with entries in columns $(i, i+1)$ only. At step $i$ it is compared with the next row:

* $|R_i| \ge |\ell_{i+1}|$: $R$ is the pivot row (entries $R_i, R_{i+1}, 0$) and the next
  active row is $\text{row}_{i+1} - (\ell_{i+1}/R_i)\,R$;
* otherwise the rows swap: the pivot row is $(\ell_{i+1}, d_{i+1}, u_{i+1})$ (one extra
  superdiagonal, as `gtsv`'s `DU2`) and the next active row is
  $R - (R_i/\ell_{i+1})\,\text{row}_{i+1}$.

The pivot rows form an upper triangular matrix with two superdiagonals; back substitution
is the second scan. Every multiplier is bounded by 1, so the solve is as stable as `gtsv`
on the indefinite Hessian blocks near a snap. A singular matrix gives non-finite values,
which the callers' result codes catch.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax


def _gtsv_scan(lower, diag, upper, rhs):
    """Tridiagonal solve by elimination with partial pivoting, plain XLA (see module doc).
    Row index first: `lower`, `diag`, `upper` of shape (N, *batch), `rhs` (N, *batch, k);
    the trailing batch axes are vectorized inside one scan (a `vmap` of a scan would move
    them in front of the row axis and copy the stacked outputs at every step)."""
    n = diag.shape[0]
    dtype = jnp.result_type(diag, rhs)
    lower, diag, upper, rhs = (jnp.asarray(a, dtype) for a in (lower, diag, upper, rhs))
    if n == 1:
        return rhs / diag[0][..., None]
    zero = jnp.zeros_like(diag[0])

    def forward(active, row):
        r0, r1, rb = active
        l, d, u, b = row
        swap = jnp.abs(l) > jnp.abs(r0)
        # no swap: pivot (r0, r1, 0 | rb), new active = row - f*R, f = l/r0
        # swap:    pivot (l, d, u | b),   new active = R - f*row, f = r0/l
        p0 = jnp.where(swap, l, r0)
        p1 = jnp.where(swap, d, r1)
        p2 = jnp.where(swap, u, zero)
        pb = jnp.where(swap[..., None], b, rb)
        f = jnp.where(swap, r0, l) / p0
        o1 = jnp.where(swap, r1, d)  # the row that is not the pivot ...
        o2 = jnp.where(swap, zero, u)
        ob = jnp.where(swap[..., None], rb, b)
        new = (o1 - f * p1, o2 - f * p2, ob - f[..., None] * pb)  # ... minus f times the pivot
        return new, (p0, p1, p2, pb)

    init = (diag[0], upper[0], rhs[0])
    rows = (lower[1:], diag[1:], jnp.concatenate([upper[1:-1], zero[None]]), rhs[1:])
    (rl, _, rlb), (p0, p1, p2, pb) = lax.scan(forward, init, rows)
    x_last = rlb / rl[..., None]

    def backward(carry, piv):
        x1, x2 = carry  # x_{i+1}, x_{i+2}
        q0, q1, q2, qb = piv
        x = (qb - q1[..., None] * x1 - q2[..., None] * x2) / q0[..., None]
        return (x, x1), x

    _, xs = lax.scan(backward, (x_last, jnp.zeros_like(x_last)), (p0, p1, p2, pb), reverse=True)
    return jnp.concatenate([xs, x_last[None]], axis=0)


def _broadcast(axis_size, in_batched, args):
    return [a if b else jnp.broadcast_to(a, (axis_size,) + a.shape) for a, b in zip(args, in_batched)]


# jaxlib runs a batched LAPACK call inline (no thread-pool tasks, so no deadlock) when
# batch x cost-per-matrix < 2e5 flops, with cost = 5 N k for `gtsv`
# (jaxlib/cpu/lapack_kernels.cc: GetLapackBatchChunkSize). Half of that, for margin:
INLINE_WORK = 100_000
# batches from this size on use the scan; smaller ones loop over unbatched LAPACK calls.
# The loop's cost grows linearly in the batch size B, the scan's is nearly flat in B (XLA:CPU
# runs a loop over vectors op by op, but a loop over scalars, as in the unbatched scan, in
# one kernel): the loop is cheaper for a few members, the scan from a few dozen on (at
# N = 100, 3 right-hand sides, per batched solve inside a compiled loop).
SCAN_BATCH = 48


@jax.custom_batching.custom_vmap
def _tri_primal(lower, diag, upper, rhs):
    return lax.linalg.tridiagonal_solve(lower, diag, upper, rhs)


def _tri_many(lower, diag, upper, rhs):
    """Solve a batch (leading axis on every argument) by the cheapest deadlock-free route."""
    b, n, k = rhs.shape
    if b * 5 * n * k < INLINE_WORK:
        return _tri_direct(lower, diag, upper, rhs)
    if b >= SCAN_BATCH:
        # batch axis last but one (rows first, right-hand sides last): see `_gtsv_scan`
        lower, diag, upper = (jnp.moveaxis(a, 0, -1) for a in (lower, diag, upper))
        return jnp.moveaxis(_gtsv_scan(lower, diag, upper, jnp.moveaxis(rhs, 0, -2)), -2, 0)
    # one member at a time; `_tri_primal` again, so an enclosing vmap is handled by its rule
    return lax.map(lambda a: _tri_primal(*a), (lower, diag, upper, rhs))


@_tri_primal.def_vmap
def _tri_batched(axis_size, in_batched, lower, diag, upper, rhs):
    return _tri_many(*_broadcast(axis_size, in_batched, (lower, diag, upper, rhs))), True


@jax.custom_batching.custom_vmap
def _tri_direct(lower, diag, upper, rhs):
    """A batch small enough for jaxlib to run inline: one batched LAPACK call."""
    return lax.linalg.tridiagonal_solve(lower, diag, upper, rhs)


@_tri_direct.def_vmap
def _tri_direct_batched(axis_size, in_batched, lower, diag, upper, rhs):
    # a vmap around a small batch: merge the two batch axes and choose again
    args = _broadcast(axis_size, in_batched, (lower, diag, upper, rhs))
    merged = [a.reshape((-1,) + a.shape[2:]) for a in args]
    x = _tri_many(*merged)
    return x.reshape(args[3].shape), True


def _tri_matvec(lower, diag, upper, x):
    below = jnp.concatenate([jnp.zeros_like(x[:1]), x[:-1]])
    above = jnp.concatenate([x[1:], jnp.zeros_like(x[:1])])
    return diag[:, None] * x + lower[:, None] * below + upper[:, None] * above


def tridiagonal_matvec(lower, diag, upper, x):
    r"""$A x$ for the tridiagonal $A$ of [`tridiagonal_solve`][]'s layout (`lower[0]` and
    `upper[-1]` ignored); `x` of shape (N, k)."""
    zero = jnp.zeros_like(diag[:1])
    return _tri_matvec(jnp.concatenate([zero, lower[1:]]), diag, jnp.concatenate([upper[:-1], zero]), x)


def tridiagonal_solve(lower, diag, upper, rhs):
    r"""Solve $A x = b$ for tridiagonal $A$, in the layout of
    `lax.linalg.tridiagonal_solve`: `lower[i]` $=A_{i,i-1}$ (`lower[0]` ignored),
    `diag[i]` $=A_{ii}$, `upper[i]` $=A_{i,i+1}$ (`upper[-1]` ignored); `rhs` of shape
    (N, k); returns (N, k). LAPACK `gtsv` unbatched, the scan of the module docstring
    under `vmap`; differentiable in all four arguments."""
    dtype = jnp.result_type(lower, diag, upper, rhs)
    lower, diag, upper, rhs = (jnp.asarray(a, dtype) for a in (lower, diag, upper, rhs))
    zero = jnp.zeros((1,), dtype)
    lower = jnp.concatenate([zero, lower[1:]])
    upper = jnp.concatenate([upper[:-1], zero])
    # A^T: (A^T)[i, i-1] = A[i-1, i] = upper[i-1], (A^T)[i, i+1] = A[i+1, i] = lower[i+1]
    lower_t = jnp.concatenate([zero, upper[:-1]])
    upper_t = jnp.concatenate([lower[1:], zero])
    return lax.custom_linear_solve(
        lambda x: _tri_matvec(lower, diag, upper, x), rhs,
        solve=lambda _, b: _tri_primal(lower, diag, upper, b),
        transpose_solve=lambda _, b: _tri_primal(lower_t, diag, upper_t, b))


@jax.custom_batching.sequential_vmap
def _dense_primal(a, b):
    return jnp.linalg.solve(a, b)


def solve(a, b):
    r"""Dense $A^{-1} b$ (`b` of shape (n,) or (n, k)): one LAPACK LU; under `vmap` the
    members are solved one after another (no batched LAPACK call, see module doc).
    Differentiable in `a` and `b`."""
    dtype = jnp.result_type(a, b)
    a, b = jnp.asarray(a, dtype), jnp.asarray(b, dtype)
    at = a.T
    return lax.custom_linear_solve(lambda x: a @ x, b, solve=lambda _, r: _dense_primal(a, r),
                                   transpose_solve=lambda _, r: _dense_primal(at, r))


@jax.custom_batching.sequential_vmap
def _eigh_primal(a):
    return jnp.linalg.eigh(a)


@jax.custom_jvp
def eigh(a):
    r"""Eigenvalues (ascending) and orthonormal eigenvectors of the symmetric matrix `a`
    (its symmetric part $(A+A^\top)/2$, as `jnp.linalg.eigh`): one LAPACK `syevd`; under
    `vmap` the members run one after another (no batched LAPACK call, see module doc).
    Derivatives by the usual rule for distinct eigenvalues, with $\dot A_s$ the symmetric
    part of the tangent: $\dot w = \mathrm{diag}(V^\top\dot A_s V)$,
    $\dot V = V\,(F\circ V^\top\dot A_s V)$, $F_{ij} = 1/(w_j-w_i)$ off the diagonal, 0 on it."""
    return _eigh_primal(a)


@eigh.defjvp
def _eigh_jvp(primals, tangents):
    (a,), (da,) = primals, tangents
    w, v = eigh(a)
    vdv = v.T @ (0.5 * (da + da.T)) @ v
    eye = jnp.eye(a.shape[-1], dtype=w.dtype)
    f = 1.0 / (w[None, :] - w[:, None] + eye) - eye
    return (w, v), (jnp.diagonal(vdv), v @ (f * vdv))


def solve2(s, r):
    """Closed-form solve of a 2x2 system (Cramer's rule): no LAPACK call at all."""
    det = s[0, 0] * s[1, 1] - s[0, 1] * s[1, 0]
    return jnp.stack([s[1, 1] * r[0] - s[0, 1] * r[1], s[0, 0] * r[1] - s[1, 0] * r[0]]) / det


def lstsq2(p, g):
    r"""Least squares with two columns, $\arg\min_x\|P x - g\|$ for $P$ of shape (n, 2),
    by the normal equations $P^\top P\,x = P^\top g$ (closed form; no LAPACK SVD)."""
    return solve2(p.T @ p, p.T @ g)
