r"""Critical points (folds and symmetry-breaking branch points) as regular roots of an
extended system, refined by Newton's method and differentiated implicitly.

Let $x=(\theta,\mu)\in\mathbb R^{N+2}$, $F(x;\alpha)=\nabla_x\tilde{\mathcal L}$ the
equilibrium residual of [`jaxrod.lagrangian`][] and $\mathsf K=\partial_xF$ the bordered
Hessian (with the end force: $\mathsf K$ is singular exactly when the constrained
stiffness of `jaxrod.linalg.kkt` has a zero eigenvalue, $T v_\theta+Pv_\mu=0$, $P^\top v_\theta=0$).
We use the full $\mathsf K$ on $(\theta,\mu)$ (not the angle space restricted to
$P^\top v=0$): the constraint is then part of $\mathsf K v=0$ and the null vector
$v=(v_\theta,v_\mu)$ carries the change of end force along the mode.

**Fold** (limit point in $\alpha$), the Moore-Spence system in
$z=(\theta,\mu,\alpha,v_\theta,v_\mu)\in\mathbb R^{2N+5}$:

$$F(x;\alpha)=0,\qquad \mathsf K(x;\alpha)\,v=0,\qquad \ell^\top v_\theta=1,$$

regular at a generic fold ($v^\top F_\alpha\ne0$, $\tilde{\mathcal L}'''[v,v,v]\ne0$).

**Branch point** under symmetric actuation. With the mirror
$S(\theta,\mu)=(-\theta_{N+1-i},(\mu_x,-\mu_y))$ the problem is equivariant. At a
symmetry-breaking branch point the full Moore-Spence Jacobian is singular (its null
vector is $(v, w, 0)$ with $\mathsf K w=-\tilde{\mathcal L}'''[v,v,\cdot]$), so the
system is posed on $x\in\mathrm{Fix}(S)$ ($\theta_i=-\theta_{N+1-i}$, $\mu_y=0$) and
$v\in\mathrm{Fix}(-S)$ ($v_{\theta,i}=v_{\theta,N+1-i}$, $v_{\mu_x}=0$): $N+3$ unknowns
$(\theta_{1..N/2},\mu_x,\alpha,v_{\theta,1..N/2},v_{\mu_y})$, and the equations are the
independent halves of $F$ (in $\mathrm{Fix}(S)$) and $\mathsf Kv$ (in $\mathrm{Fix}(-S)$),
plus $\ell^\top v_\theta=1$. This system is regular at a simple symmetry-breaking
bifurcation (Werner & Spence 1984); `tests/test_critical.py` checks its Jacobian's
condition number numerically. [`critical_point`][] solves it in the fold system's
$2N+5$ slots, every unused slot pinned to zero by an equation of its own (`_one_system`):
one residual, one Newton loop, one Jacobian program and one block solve serve both kinds,
and the kind chooses only constant masks (the compiled program of one system, not two).

$\ell = h\odot v_0$ with $v_0$ the starting mode ($h$: segment lengths).

**Jacobian.** $(2N+5)^2$ or $(N+3)^2$, assembled from its sparsity ([`_structured_jacobian`][]): the energy couples only
neighbouring angles, so the rows of $F_\theta$ and $(\mathsf Kv)_\theta$ depend on the
angles $\theta$ and mode angles $v_\theta$ only within $|i-j|\le1$. Three colour probes
($j \bmod 3$) per angle block, one forward-mode probe per remaining column ($\mu$,
$\alpha$, $v_\mu$) and one reverse-mode probe per remaining row (the constraint rows of
$F$ and $\mathsf Kv$, $\ell^\top v_\theta$) give every entry: 11 forward and 5 reverse
probes for the fold system instead of $2N+5$ forward ones (9 and 3 for the branch-point
system on its own, 12 and 6 for the cusp's). Each Newton step solves with it by block elimination
([`_block_solve`][]): two tridiagonal solves for the angle blocks and a Schur complement of
the 5 (3, 6) remaining unknowns, $O(N)$ instead of a dense LU's $O(N^3)$. With
self-contact the angle blocks are dense: `jax.jacfwd` builds the Jacobian and one dense LU
solves with it.

**Derivatives.** The Newton iterations run on `stop_gradient`-ed data; the root $z^\ast$
then carries a custom derivative rule (`_implicit_step`), the implicit-function derivative
$dz^\ast/dp=-J^{-1}\partial_pR$ with $J$ the Jacobian at $z^\ast$, for every float leaf $p$ of
the scene ($\Psi_0$, $G$, $s_0$, the fixed clamp's angle for one-sided actuation, ...),
under `jit`, `vmap`, `grad` and `jvp` (first derivatives; second derivatives through
this step are not exact).

**Located points.** [`located_critical_point`][] gives a point already located to round-off
(the bisection and eigenvalue interpolation of [`jaxrod.snap_angles`][]) the same
derivative without Newton's method: it checks the system's residual there and assembles
$J$ only inside the derivative rule, so a program that only evaluates carries neither the
Newton loop nor the Jacobian.
"""

from __future__ import annotations

from types import SimpleNamespace

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jaxtyping import Array

from ..linalg import batched
from ._continuation import AbstractParameter, Gap, SymmetricAlpha
from ..energy.geometry import discretize
from ..energy.lagrangian import lagrangian_gradient, positions
from .._misc import check_int, check_number, is_concrete
from .._compile import jit
from ..results import RESULTS


KIND_NONE, KIND_FOLD, KIND_BRANCH_POINT = 0, 1, 2
"""The kinds of a critical point (`SnapPath.kind`, `CriticalPoint.kind`): none (no snap), a
fold (limit point in the parameter), a branch point (a mirror-asymmetric mode goes unstable)."""


class CriticalPoint(eqx.Module):
    r"""A refined critical point: `alpha` (the parameter value, rad), `theta`, `force`
    (the critical state), `mode` ($v_\theta$, unit $L^2$ norm, sign as given), `mode_force`
    ($v_\mu$, same scaling), `fold_height` $y(L/2)$, `kind` (1 fold, 2 branch point),
    `residual` (max-norm of the extended system at the root), `num_steps`, `result`
    (a [`jaxrod.RESULTS`][] code: `successful`, `max_steps_reached` or `nonfinite`)."""

    alpha: Array
    theta: Array
    force: Array
    mode: Array
    mode_force: Array
    fold_height: Array
    kind: Array
    residual: Array
    num_steps: Array
    result: RESULTS


def _grad(scene, parameter, t, m, a):
    sc = parameter.set(scene, a)
    return lagrangian_gradient(t, m, sc, discretize(sc))


def _hvp(scene, parameter, t, m, a, vt, vm):
    return jax.jvp(lambda tt, mm: _grad(scene, parameter, tt, mm, a), (t, m), (vt, vm))[1]


# ----- fold: full Moore-Spence system ---------------------------------------------------

def _fold_pack(t, m, a, vt, vm):
    return jnp.concatenate([t, m, a[None], vt, vm])


def _fold_unpack(z, N):
    return z[:N], z[N:N + 2], z[N + 2], z[N + 3:2 * N + 3], z[2 * N + 3:]


def _fold_residual(z, scene, parameter, ell):
    N = ell.shape[0]
    t, m, a, vt, vm = _fold_unpack(z, N)
    gt, gm = _grad(scene, parameter, t, m, a)
    kt, km = _hvp(scene, parameter, t, m, a, vt, vm)
    return jnp.concatenate([gt, gm, kt, km, (jnp.dot(ell, vt) - 1.0)[None]])


# ----- branch point: symmetric state, asymmetric mode -----------------------------------

def _sym_unpack(y, N):
    """y = (a (N/2), mux, alpha, c (N/2), vmuy) -> full (t, m, alpha, vt, vm)."""
    H = N // 2
    a, b, al, c, d = y[:H], y[H], y[H + 1], y[H + 2:2 * H + 2], y[2 * H + 2]
    t = jnp.concatenate([a, -a[::-1]])
    m = jnp.stack([b, jnp.zeros_like(b)])
    vt = jnp.concatenate([c, c[::-1]])
    vm = jnp.stack([jnp.zeros_like(d), d])
    return t, m, al, vt, vm


def _sym_pack(t, m, a, vt, vm):
    H = t.shape[0] // 2
    ts = 0.5 * (t[:H] - t[H:][::-1])
    vs = 0.5 * (vt[:H] + vt[H:][::-1])
    return jnp.concatenate([ts, m[:1], a[None], vs, vm[1:]])


def _sym_residual(y, scene, parameter, ell):
    N = ell.shape[0]
    H = N // 2
    t, m, a, vt, vm = _sym_unpack(y, N)
    gt, gm = _grad(scene, parameter, t, m, a)
    kt, km = _hvp(scene, parameter, t, m, a, vt, vm)
    return jnp.concatenate([gt[:H], gm[:1], kt[:H], km[1:], (jnp.dot(ell, vt) - 1.0)[None]])


# ----- both kinds as one system in the fold system's layout -----------------------------

def _padding(N):
    r"""The branch-point system in the fold system's $2N+5$ slots $(\theta,\mu,\alpha,v_\theta,v_\mu)$
    (numpy): `idx`, `sign` (the full unknowns are `sign * z[idx]`: $\theta=(a,-\bar a)$ from
    the first $N/2$ angle slots, $\mu=(\mu_x,0)$, $v_\theta=(c,\bar c)$, $v_\mu=(0,v_{\mu_y})$,
    $\bar{\ }$ the reversal), `keep` (the rows of the fold residual $(F_\theta,F_\mu,
    (\mathsf Kv)_\theta,(\mathsf Kv)_\mu,\ell^\top v_\theta-1)$ that are the branch-point system's
    equations), `slot` (the slot each other row pins to zero instead) and `used` (the slots of
    the branch-point system's own unknowns $y$, in `_sym_pack`'s order)."""
    H = N // 2
    half = np.concatenate([np.arange(H), np.arange(H)[::-1]])
    idx = np.concatenate([half, [N, N, N + 2], N + 3 + half, [2 * N + 4, 2 * N + 4]])
    sign = np.concatenate([np.ones(H), -np.ones(H), [1.0, 0.0, 1.0], np.ones(N), [0.0, 1.0]])
    first = np.concatenate([np.ones(H), np.zeros(H)])
    keep = np.concatenate([first, [1.0, 0.0], first, [0.0, 1.0, 1.0]])
    slot = np.concatenate([np.arange(N), [N, N + 1], N + 3 + np.arange(N), [2 * N + 3, 2 * N + 4, N + 2]])
    used = np.concatenate([np.arange(H), [N, N + 2], N + 3 + np.arange(H), [2 * N + 4]])
    return idx, sign, keep, slot, used


def _one_system(N, bp, parameter, ell):
    r"""`(expand, res)`: the extended system of a fold, or where `bp` (traced bool) of a
    branch point, as one residual on the fold system's $2N+5$ slots, so that one Newton loop,
    one Jacobian program and one block solve serve both kinds.

    The branch-point system (unknowns $y$, $N+3$) sits in the slots as `_padding` says, and
    every slot it does not use gets the equation "slot = 0":
    $R(z)=k\odot R_{\rm fold}(Ez)+(1-k)\odot Pz$, with $E$ the expansion (`expand`; the
    identity for a fold), $k$ the rows kept and $P$ the slot of each other row. Its Jacobian
    is $\mathrm{diag}(J_{\rm sym}, I)$ up to a permutation, so it is regular exactly where
    the branch-point system is, and it keeps the fold system's sparsity: an angle row
    $i<N/2$ depends on the slots $i-1,i,i+1$ (the mirror image of $\theta_{N/2}$ is slot
    $N/2-1$), a padded row on its own slot."""
    idx, sign, keep, slot, _ = _padding(N)
    # the choice as a float 0 or 1 (a derivative rule may close over float values only)
    b = jnp.asarray(bp, ell.dtype)
    keep = b * keep + (1.0 - b)

    def expand(z):
        return b * (sign * z[idx]) + (1.0 - b) * z

    def res(z, sc):
        return keep * _fold_residual(expand(z), sc, parameter, ell) + (1.0 - keep) * z[slot]

    return expand, res


def _sym_slots(t, m, a, vt, vm):
    """The branch-point system's start (`_sym_pack`) in the fold system's slots (`_padding`),
    the unused slots zero."""
    N = t.shape[0]
    return jnp.zeros(2 * N + 5, t.dtype).at[_padding(N)[4]].set(_sym_pack(t, m, a, vt, vm))


# ----- Newton with an implicit-derivative final step ------------------------------------

def _block_indices(M, n, row_starts, col_starts):
    """The rows and columns of the angle-like blocks (`n` from each start) of an extended
    system with `M` unknowns, and the remaining rows and columns, each in increasing order."""
    j = np.arange(n)
    local_rows = np.concatenate([r + j for r in row_starts])
    local_cols = np.concatenate([c + j for c in col_starts])
    return local_rows, local_cols, np.setdiff1d(np.arange(M), local_rows), np.setdiff1d(np.arange(M), local_cols)


def _structured_jacobian(res, z, n, row_starts, col_starts):
    r"""The Jacobian of `res` at `z` (square), assembled from its sparsity (module docstring).

    `col_starts`: the first columns of the angle-like blocks, `n` columns each; `row_starts`:
    the first rows of the blocks of `n` rows whose row $i$ depends on column $j$ of every
    angle-like block only for $|i-j|\le1$. Those entries come from three colour probes per
    block (forward mode, columns $j \bmod 3$ summed); every other column from its own
    forward probe, every other row from its own reverse probe. Exact (no finite
    differences): equal to `jax.jacfwd(res)(z)` where the sparsity holds. Returns `(J, res(z))`
    (the residual is the linearization's primal: one evaluation serves both)."""
    M = z.shape[0]
    dtype = z.dtype
    j = np.arange(n)
    _, _, dense_rows, dense_cols = _block_indices(M, n, row_starts, col_starts)
    seeds = np.zeros((3 * len(col_starts) + dense_cols.size, M))
    for b, c in enumerate(col_starts):
        for colour in range(3):
            seeds[3 * b + colour, c + j[j % 3 == colour]] = 1.0
    seeds[3 * len(col_starts) + np.arange(dense_cols.size), dense_cols] = 1.0
    out, lin = jax.linearize(res, z)
    JS = jax.vmap(lin)(jnp.asarray(seeds, dtype))  # (probes, M): J @ seed
    # the banded entries of the local rows: row i of a row block, column i + d of a column block
    rr, cc, pp = [], [], []
    for r in row_starts:
        for b, c in enumerate(col_starts):
            for d in (-1, 0, 1):
                i = j[(j + d >= 0) & (j + d < n)]
                rr.append(r + i)
                cc.append(c + i + d)
                pp.append(3 * b + (i + d) % 3)
    rr, cc, pp = (np.concatenate(x) for x in (rr, cc, pp))
    J = jnp.zeros((M, M), dtype)
    J = J.at[:, dense_cols].set(JS[3 * len(col_starts):].T)
    J = J.at[rr, cc].set(JS[pp, rr])
    vjp = jax.linear_transpose(lin, z)  # reverse mode from the same linearization
    rows = jax.vmap(lambda e: vjp(e)[0])(jnp.eye(M, dtype=out.dtype)[dense_rows])
    return J.at[dense_rows].set(rows), out


def _layout(N, kind):
    """`(n, row_starts, col_starts)` of the extended system `kind` of a scene with N segments:
    its two angle-like blocks of `n` unknowns and of `n` equations (see `_structured_jacobian`)."""
    if kind == "sym":
        H = N // 2
        return H, (0, H + 1), (0, H + 2)
    return N, (0, N + 2), (0, N + 3)


def _with_value(res):
    """z -> (`jax.jacfwd(res)(z)`, `res(z)`), the residual evaluated once."""
    def both(z):
        r = res(z)
        return r, r

    return jax.jacfwd(both, has_aux=True)


def _jacobian_fn(res, scene, N, kind):
    """z -> (the Jacobian, the residual) of the extended system `kind` ("fold", "sym" or
    "cusp") of a scene with N segments: structured (`_structured_jacobian`) without
    self-contact, `jax.jacfwd` with it (dense angle blocks)."""
    if scene.contact is not None:
        return _with_value(res)
    n, rows, cols = _layout(N, kind)
    return lambda z: _structured_jacobian(res, z, n, rows, cols)


def _block_solve(J, r, n, row_starts, col_starts):
    r"""$J^{-1} r$ for an extended-system Jacobian of the layout of `_structured_jacobian`,
    in $O(n)$ instead of a dense LU's $O(n^3)$.

    Ordered as (angle-like rows and columns, the rest), $J=\begin{pmatrix}A&U\\W&D\end{pmatrix}$
    with $A=\begin{pmatrix}T_0&0\\B&T_1\end{pmatrix}$: $T_0=\partial F_\theta/\partial\theta$,
    $B=\partial(\mathsf Kv)_\theta/\partial\theta$, $T_1=\partial(\mathsf Kv)_\theta/\partial v_\theta$
    tridiagonal, and $F$ independent of $v$ (the zero block). $A^{-1}$ is two tridiagonal
    solves (LAPACK `gtsv`), the few remaining unknowns ($\mu$, $\alpha$, $v_\mu$; the gap of a
    cusp) come from the small Schur complement $S=D-WA^{-1}U$, and one step of iterative
    refinement with $J$ itself keeps the result at the accuracy of a dense LU where $T_0$ or
    $T_1$ is ill-conditioned (the same block elimination as the continuation's corrector).
    $J$ itself is singular only where the extended system is (not at a regular root)."""
    M = J.shape[0]
    j = np.arange(n)
    (r0, r1), (c0, c1) = row_starts, col_starts
    local_rows, local_cols, dense_rows, dense_cols = _block_indices(M, n, row_starts, col_starts)
    order = np.argsort(np.concatenate([local_cols, dense_cols]))  # (angle-like, rest) -> z's order
    zero = jnp.zeros((), J.dtype)

    def tri(r, c):
        lower = jnp.where(j > 0, J[r + j, c + np.maximum(j - 1, 0)], zero)
        upper = jnp.where(j < n - 1, J[r + j, c + np.minimum(j + 1, n - 1)], zero)
        return lower, J[r + j, c + j], upper

    T0, B, T1 = tri(r0, c0), tri(r1, c0), tri(r1, c1)
    U = J[np.ix_(local_rows, dense_cols)]
    W = J[np.ix_(dense_rows, local_cols)]
    D = J[np.ix_(dense_rows, dense_cols)]

    def solve_a(R):
        X0 = batched.tridiagonal_solve(*T0, R[:n])
        return jnp.concatenate([X0, batched.tridiagonal_solve(*T1, R[n:] - batched.tridiagonal_matvec(*B, X0))])

    # (the solves with U, which depend on J alone, stay apart from those with the right-hand
    # side, so that the solve is a linear map of `r` that JAX can transpose)
    XU = solve_a(U)
    S_inv = batched.solve(D - W @ XU, jnp.eye(dense_rows.size, dtype=J.dtype))

    def once(rhs):
        xr = solve_a(rhs[local_rows][:, None])[:, 0]
        yd = S_inv @ (rhs[dense_rows] - W @ xr)
        return jnp.concatenate([xr - XU @ yd, yd])[order]

    x = once(r)
    return x + once(r - J @ x)


def _neutral_jacobian(M, N, kind, dtype):
    """A stand-in Jacobian where the real one is not available (a system that did not run, or
    failed): nonsingular for `_block_solve` as for a dense LU, so that the derivative rule
    stays finite. The permutation matrix that maps each angle-like column to the
    angle-like row of the same index, and the remaining columns to the remaining rows."""
    local_rows, local_cols, dense_rows, dense_cols = _block_indices(M, *_layout(N, kind))
    P = np.zeros((M, M))
    P[local_rows, local_cols] = 1.0
    P[dense_rows, dense_cols] = 1.0
    return jnp.asarray(P, dtype)


def _solver_fn(scene, N, kind):
    """(J, r) -> J^{-1} r for the extended system `kind`: `_block_solve` without self-contact,
    one dense LU with it (dense angle blocks)."""
    if scene.contact is not None:
        return batched.solve
    n, rows, cols = _layout(N, kind)
    return lambda J, r: _block_solve(J, r, n, rows, cols)


def _newton(res, z0, max_steps, tol_alpha, idx_alpha, jac=None, solve=batched.solve, neutral=None):
    """Plain Newton on res(z) = 0 (`jac`: z -> (Jacobian, residual), default `jax.jacfwd`),
    each step `solve(J, -res(z))` (default: a dense LU).

    Returns `(z, k, done, J, r)`: `J` and `r` the Jacobian and the residual at the returned
    `z` (the implicit step's), from one last pass of the loop that evaluates them and takes
    no step, so that one copy of the residual's and the Jacobian's programs serves the
    iterations, the reported residual and the derivative; `neutral` (default the identity;
    `_neutral_jacobian` for `_block_solve`) and a NaN residual where `z` is not finite."""
    jac = _with_value(res) if jac is None else jac
    neutral = jnp.eye(z0.shape[0], dtype=z0.dtype) if neutral is None else neutral

    def cond(c):
        z, _, _, _, _, final = c
        return (~final) & jnp.all(jnp.isfinite(z))

    def body(c):
        z, k, done, _, _, _ = c
        J, r = jac(z)
        last = done | (k >= max_steps)  # J and r are those at the returned z: no step
        dz = jnp.where(last, 0.0, solve(J, -r))
        converged = (jnp.abs(dz[idx_alpha]) < tol_alpha) & (jnp.max(jnp.abs(dz)) < 1e3 * tol_alpha)
        return z + dz, k + jnp.where(last, 0, 1), done | (~last & converged), J, r, last

    z, k, done, J, r, final = lax.while_loop(cond, body, (z0, jnp.zeros((), jnp.int32), jnp.zeros((), bool), neutral,
                                                          jnp.zeros_like(z0), jnp.zeros((), bool)))
    there = final & jnp.all(jnp.isfinite(z))
    return z, k, done, jnp.where(there, J, neutral), jnp.where(there, r, jnp.nan)


def _implicit_step(res, z, scene, solve=batched.solve, *, J=None, jacobian=None, neutral=None):
    r"""The root `z` of `res(., scene)` with the implicit-function derivative
    $dz/dp=-J^{-1}\partial_pR$ with respect to the float leaves $p$ of `scene`. `J`: the
    Jacobian at `z` (frozen; Newton's last), or None: assembled inside the derivative rule by
    `jacobian` (a residual -> `(z -> (Jacobian, residual))`, as `_jacobian_fn`), `neutral`
    where it is not finite, so that the forward program carries no Jacobian. The value is `z` itself: the solve runs only in
    the derivative rule, not in the forward program."""
    arrays, static = eqx.partition(scene, eqx.is_inexact_array)
    lazy = J is None
    z, J = lax.stop_gradient(z), lax.stop_gradient(neutral if lazy else J)
    # the residual's closed-over traced values (the normalization, a traced part of the scene)
    # become explicit arguments: a derivative rule may not close over tracers
    res_c, consts = jax.closure_convert(lambda z, a: res(z, eqx.combine(a, static)), z, arrays)

    @jax.custom_jvp
    def root(z, J, arrays, consts):
        return z

    @root.defjvp
    def root_jvp(primals, tangents):
        z, J, arrays, consts = primals
        dp = tangents[2]
        if lazy:
            Jz, _ = jacobian(lambda y: res_c(y, arrays, *consts))(z)
            J = jnp.where(jnp.all(jnp.isfinite(Jz)), Jz, J)  # J holds the neutral stand-in
        _, dR = jax.jvp(lambda a: res_c(z, a, *consts), (arrays,), (dp,))
        return z, -solve(J, dR)

    return root(z, J, arrays, lax.stop_gradient(consts))


def extended_jacobian(scene, cp: CriticalPoint, parameter: AbstractParameter = SymmetricAlpha()):
    """The Jacobian of the extended system at a refined critical point (dense; for tests:
    its smallest singular value shows regularity). Uses the system `cp.kind` selects."""
    d = discretize(scene)
    ell = d.h * cp.mode / jnp.sum(d.h * cp.mode**2)  # ell . mode = 1
    if int(cp.kind) == KIND_BRANCH_POINT:
        y = _sym_pack(cp.theta, cp.force, cp.alpha, cp.mode, cp.mode_force)
        return jax.jacfwd(lambda y: _sym_residual(y, scene, parameter, ell))(y)
    z = _fold_pack(cp.theta, cp.force, cp.alpha, cp.mode, cp.mode_force)
    return jax.jacfwd(lambda z: _fold_residual(z, scene, parameter, ell))(z)


@jit
def critical_point(scene, theta, force, alpha, mode, kind, *, parameter: AbstractParameter = SymmetricAlpha(),
                   max_steps: int = 20, tol: float = 1e-12) -> CriticalPoint:
    r"""Refine a critical point of the branch of `scene` under `parameter` by Newton's
    method on its extended system (see the module docstring).

    **Arguments:** `theta`, `force`, `alpha`: a state and parameter value near the critical
    point (e.g. the bisection result of [`jaxrod.snap_angles`][]); `mode`: the angle part
    of the critical mode there (e.g. `jaxrod.linalg.kkt.modes` of the lowest eigenvalue);
    `kind`: 1 fold (full Moore-Spence system), 2 symmetry-breaking branch point
    (symmetric state, asymmetric mode; `parameter` must be `SymmetricAlpha`, or `Gap` for a
    scene with mirror-symmetric clamps, $\alpha_L=\alpha_R$). `kind` may
    be traced (both kinds are one system, see the module docstring). `tol`: Newton stops when
    the $\alpha$ update is below `tol` (rad).

    **Returns:** a [`jaxrod.CriticalPoint`][]; differentiable with respect to every float
    leaf of `scene` by the implicit function theorem.
    """
    if is_concrete(kind) and (np.ndim(kind) != 0 or isinstance(kind, (bool, str))
                              or kind not in (KIND_FOLD, KIND_BRANCH_POINT)):
        raise ValueError(f"kind must be 1 (fold) or 2 (branch point), got {kind!r}")
    check_int("max_steps", max_steps, lo=1)
    check_number("tol", tol, lo=0.0)
    p = _problem(scene, theta, force, alpha, mode, kind, parameter)
    z, k, done, J, r = _newton(p.res_sg, p.z0, max_steps, tol, p.N + 2, p.jac, p.solve, p.neutral)
    finite = jnp.all(jnp.isfinite(z))
    # a failed system is non-finite or singular: its derivative rule uses the start point
    # and a neutral Jacobian, so that the gradient stays finite (a zero cotangent times inf is NaN)
    z_use = jnp.where(finite, z, p.z0)
    J = jnp.where(finite & jnp.all(jnp.isfinite(J)), J, p.neutral)
    z = jnp.where(finite, _implicit_step(p.res, z_use, p.scene_d, p.solve, J=J), z)
    result = RESULTS.where(done & finite, RESULTS.successful,
                           RESULTS.where(finite, RESULTS.max_steps_reached, RESULTS.nonfinite))
    return _critical_point(p, z, jnp.max(jnp.abs(r)), k, result)


def _problem(scene, theta, force, alpha, mode, kind, parameter):
    r"""(A namespace:) the extended system of a critical point of `kind` near (`theta`, `force`, `alpha`)
    with the mode `mode` (normalization $\ell=h\odot v$), its start `z0` in the fold
    system's slots, and the scene its implicit derivative goes through (for a branch point
    the scene's mirror-symmetric part)."""
    dtype = theta.dtype
    N = theta.shape[0]
    sg = lax.stop_gradient
    scene_sg = sg(scene)
    theta, force, alpha, mode = sg(theta), sg(force), sg(jnp.asarray(alpha, dtype)), sg(mode)
    w = discretize(scene_sg).h
    mode = mode / jnp.sqrt(jnp.sum(w * mode**2))
    ell = w * mode  # ell . mode = 1
    # starting mode force: K (v, vm) ~ 0 in its mu rows -> least-squares vm from the theta rows
    gt0 = _hvp(scene_sg, parameter, theta, force, alpha, mode, jnp.zeros(2, dtype))[0]
    P = jax.jacfwd(lambda mm: _grad(scene_sg, parameter, theta, mm, alpha)[0])(force)  # (N, 2)
    vm0 = -batched.lstsq2(P, gt0)
    kind = jnp.asarray(kind)
    # the branch-point system needs a mirror-symmetric problem: symmetric actuation, or the
    # gap of a scene whose clamps are symmetric (alpha_L = alpha_R, e.g. both 0)
    symmetric = isinstance(parameter, (SymmetricAlpha, Gap))
    bp = (kind == KIND_BRANCH_POINT) if symmetric else jnp.zeros((), bool)
    expand, res = _one_system(N, bp, parameter, ell)
    z0 = jnp.where(bp, _sym_slots(theta, force, alpha, mode, vm0), _fold_pack(theta, force, alpha, mode, vm0))
    # A branch point exists only in a mirror-symmetric scene; its derivative is that of
    # the symmetric family, taken through the scene's mirror-symmetric part
    scene_d = scene
    if symmetric:
        scene_d = jax.tree.map(lambda p, q: jnp.where(bp, q, p) if eqx.is_inexact_array(q) else p, scene,
                               mirror_symmetric_part(scene))
    res_sg = lambda z: res(z, scene_sg)  # noqa: E731
    # (the Jacobian's program depends on the scene only through whether it has self-contact)
    jacobian = lambda f: _jacobian_fn(f, scene_sg, N, "fold")  # noqa: E731
    return SimpleNamespace(N=N, kind=kind, z0=z0, w=w, scene=scene, scene_d=scene_d, parameter=parameter, res=res,
                           res_sg=res_sg, expand=expand, jacobian=jacobian, jac=jacobian(res_sg),
                           solve=_solver_fn(scene_sg, N, "fold"),
                           neutral=_neutral_jacobian(z0.shape[0], N, "fold", dtype))


def _critical_point(p, z, residual, num_steps, result):
    t, m, a, vt, vm = _fold_unpack(p.expand(z), p.N)
    nv = jnp.sqrt(jnp.sum(p.w * vt**2))
    sc = p.parameter.set(p.scene, a)
    fh = positions(t, m, sc)[p.N // 2, 1]
    return CriticalPoint(alpha=a, theta=t, force=m, mode=vt / nv, mode_force=vm / nv, fold_height=fh,
                         kind=p.kind.astype(jnp.int32), residual=residual, num_steps=num_steps, result=result)


LOCATED_TOL = 1e-8
"""Largest max-norm residual of the extended system (`jaxrod.critical_point`) at which
[`located_critical_point`][] accepts a located critical point."""


def located_critical_point(scene, theta, force, alpha, mode, kind, *,
                           parameter: AbstractParameter = SymmetricAlpha()) -> CriticalPoint:
    r"""A critical point already located to round-off (the interpolated bisection of
    [`jaxrod.snap_angles`][]) as a [`jaxrod.CriticalPoint`][] of the extended system of
    [`critical_point`][], with its implicit derivative, without Newton's method: `result`
    is `successful` where the system's residual there (`residual`) is at most `LOCATED_TOL`
    (a branch point's state is projected onto the mirror-symmetric states first),
    `nonfinite` where it is not finite, `derivative_unavailable` otherwise.

    The values are the located point's; their derivative with respect to the float leaves
    of `scene` is the implicit-function derivative $-J^{-1}\partial_pR$ of the extended
    system at that point, whose Jacobian $J$ is assembled only where a derivative is taken
    (inside the derivative rule): a program that only evaluates carries the residual alone."""
    p = _problem(scene, theta, force, alpha, mode, kind, parameter)
    r = jnp.max(jnp.abs(p.res_sg(p.z0)))
    z = _implicit_step(p.res, p.z0, p.scene_d, p.solve, jacobian=p.jacobian, neutral=p.neutral)
    result = RESULTS.where(r <= LOCATED_TOL, RESULTS.successful,
                           RESULTS.where(jnp.isfinite(r), RESULTS.derivative_unavailable, RESULTS.nonfinite))
    return _critical_point(p, z, r, jnp.zeros((), jnp.int32), result)


def mirror_symmetric_part(scene):
    r"""The mirror-symmetric part of `scene`: every crease's position, angle and width
    averaged with its mirror partner's (`Strip.mirrored`), and the clamp angles averaged
    ($\alpha_L = \alpha_R$). Equal to `scene` where it is mirror-symmetric; its derivative
    with respect to the scene's leaves is the projection onto mirror-symmetric changes.
    A branch point's implicit derivative goes through it: at a branch point alpha_c is
    differentiable only along mirror-symmetric changes (any other change makes the
    bifurcation imperfect and moves alpha_c like |change|^(2/3)), so the returned
    derivative is that of the symmetric family, zero along antisymmetric changes."""
    st = scene.strip
    if st.creases is not None:
        mir = st.creases.mirrored(st.length)
        avg = [0.5 * (jnp.asarray(a) + b) for a, b in zip((st.creases.positions, st.creases.angles,
                                                          st.creases.widths),
                                                         (mir.positions, mir.angles, mir.widths))]
        st = eqx.tree_at(lambda s: (s.creases.positions, s.creases.angles, s.creases.widths), st, tuple(avg))
    a = 0.5 * (jnp.asarray(scene.clamps.alpha_left) + jnp.asarray(scene.clamps.alpha_right))
    return eqx.tree_at(lambda s: (s.strip, s.clamps.alpha_left, s.clamps.alpha_right), scene, (st, a, a))


# ----- cusp: where a fold pair meets (two-parameter, alpha and the gap) -----------------

def _set_gap(scene, g):
    return eqx.tree_at(lambda s: s.clamps.gap, scene, g)


def _cusp_residual(z, scene, parameter, ell):
    N = ell.shape[0]
    zf, g = z[:-1], z[-1]
    sc = _set_gap(scene, g)
    t, m, a, vt, vm = _fold_unpack(zf, N)
    r = _fold_residual(zf, sc, parameter, ell)
    # cubic coefficient of the fold's normal form: L'''[v, v, v]
    d3 = jax.jvp(lambda tt, mm: _hvp(sc, parameter, tt, mm, a, vt, vm), (t, m), (vt, vm))[1]
    c = jnp.dot(d3[0], vt) + jnp.dot(d3[1], vm)
    return jnp.concatenate([r, c[None]])


class CuspPoint(eqx.Module):
    r"""A cusp of the fold curve in the (gap, alpha) plane: `gap` $G_c$, `alpha`, the critical
    state `theta`, `force`, `mode`, `residual`, `num_steps`, `result`."""

    gap: Array
    alpha: Array
    theta: Array
    force: Array
    mode: Array
    residual: Array
    num_steps: Array
    result: RESULTS


@jit
def cusp_point(scene, theta, force, alpha, mode, *, parameter: AbstractParameter = SymmetricAlpha(),
               max_steps: int = 30, tol: float = 1e-12) -> CuspPoint:
    r"""The cusp where a pair of folds (under `parameter`) meets as the gap varies: Newton on
    the fold system of `critical_point` augmented by the gap $G$ as unknown and the
    degeneracy condition $\tilde{\mathcal L}'''[v,v,v]=0$ (the quadratic coefficient of the
    fold's normal form vanishes), $2N+6$ unknowns. Start from a fold near the cusp (`theta`,
    `force`, `alpha`, `mode`, at the gap of `scene`). Differentiable (implicit function
    theorem, as `critical_point`) with respect to the float leaves of `scene` other than the
    gap, e.g. $dG_c/d\Psi_0$."""
    check_int("max_steps", max_steps, lo=1)
    check_number("tol", tol, lo=0.0)
    dtype = theta.dtype
    N = theta.shape[0]
    sg = lax.stop_gradient
    scene_sg = sg(scene)
    theta, force, alpha, mode = sg(theta), sg(force), sg(jnp.asarray(alpha, dtype)), sg(mode)
    w = discretize(scene_sg).h
    mode = mode / jnp.sqrt(jnp.sum(w * mode**2))
    ell = w * mode
    gt0 = _hvp(scene_sg, parameter, theta, force, alpha, mode, jnp.zeros(2, dtype))[0]
    P = jax.jacfwd(lambda mm: _grad(scene_sg, parameter, theta, mm, alpha)[0])(force)
    vm0 = -batched.lstsq2(P, gt0)
    z0 = jnp.concatenate([_fold_pack(theta, force, alpha, mode, vm0), jnp.asarray(scene_sg.clamps.gap, dtype)[None]])

    def res(z, sc):
        return _cusp_residual(z, sc, parameter, ell)

    jac = _jacobian_fn(lambda z: res(z, scene_sg), scene_sg, N, "cusp")
    solve = _solver_fn(scene_sg, N, "cusp")
    neutral = _neutral_jacobian(z0.shape[0], N, "cusp", dtype)
    z, k, done, J, r = _newton(lambda z: res(z, scene_sg), z0, max_steps, tol, 2 * N + 5, jac=jac, solve=solve,
                               neutral=neutral)
    finite = jnp.all(jnp.isfinite(z))
    z_use = jnp.where(finite, z, z0)
    J = jnp.where(finite & jnp.all(jnp.isfinite(J)), J, neutral)
    r = jnp.max(jnp.abs(r))
    z = jnp.where(finite, _implicit_step(res, z_use, scene, solve, J=J), z)
    t, m, a, vt, vm = _fold_unpack(z[:-1], N)
    result = RESULTS.where(done & finite, RESULTS.successful,
                           RESULTS.where(finite, RESULTS.max_steps_reached, RESULTS.nonfinite))
    return CuspPoint(gap=z[-1], alpha=a, theta=t, force=m, mode=vt / jnp.sqrt(jnp.sum(w * vt**2)),
                     residual=r, num_steps=k, result=result)
