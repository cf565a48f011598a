r"""Differentiable critical clamp angles $\alpha_{c,\rm up}(\Psi_0, G, s_0)$ and $\alpha_{c,\rm down}$.

The primal values come from [`jaxrod.snap_angles`][] (continuation + bisection, exact to
round-off at the given mesh). Their derivatives with respect to the design
$p=(\Psi_0, G, s_0)$ come from the implicit function theorem applied to the critical point
itself, at the refined critical state $x_c=(\theta_c,\mu_c)$, $\alpha=\alpha_c$, with
$F(x;\alpha,p)=\nabla_x\tilde{\mathcal L}$ the equilibrium residual, $K=\partial_x F$ the
(symmetric, bordered) KKT matrix and $w$ its null vector ($Kw=0$):

* **fold** (limit point in $\alpha$; $w^\top F_\alpha\neq0$). Differentiating $F=0$ along the
  fold and projecting on $w$ (using $w^\top K=0$):
  $$\frac{\partial\alpha_c}{\partial p} = -\frac{w^\top F_p}{w^\top F_\alpha}.$$
* **branch point** (symmetry breaking on the mirror-symmetric branch $x_s(\alpha,p)$; $w$
  antisymmetric so $w^\top F_q=0$). The critical condition is that the eigenvalue
  $\sigma = w^\top K(x_s(q),q)\,w$ of the asymmetric mode vanishes, so
  $$\frac{\partial\alpha_c}{\partial p} = -\frac{\mathrm d\sigma/\mathrm dp}{\mathrm d\sigma/\mathrm d\alpha},\qquad
  \frac{\mathrm d\sigma}{\mathrm dq} = \partial_q(w^\top K w) + \partial_x(w^\top K w)\,x_q,\quad
  x_q = -(K + c\,\hat w\hat w^\top)^{-1}F_q ,$$
  the rank-one shift making the consistent singular system ($F_q\perp w$) uniquely solvable
  with $x_q\perp w$.

Dense $(N+2)\times(N+2)$ linear algebra: this is meant for design meshes ($N\le 400$). It goes
through `jaxrod.linalg.batched` (one LAPACK call per member under `vmap`): the up and down
sensitivities run concurrently, and batched LAPACK calls in two concurrent branches can
deadlock XLA:CPU (see that module).
When `jaxrod.snap_angles` becomes differentiable itself, these rules remain an independent
implementation (the tests compare both with central differences).
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp

import jaxrod as jr
from jaxrod.branches import near_pair
from jaxrod.linalg import batched


class Critical(eqx.Module):
    """Critical angles (radians; NaN where the path does not snap), snap flags and kinds
    (0 none, 1 fold, 2 branch point; see `jaxrod.KIND_NAMES`), and each path's
    [`jaxrod.RESULTS`][] code (`result_up`, `result_down`: `SnapPath.result`)."""

    alpha_up: jax.Array
    alpha_down: jax.Array
    snaps_up: jax.Array
    snaps_down: jax.Array
    kind_up: jax.Array
    kind_down: jax.Array
    result_up: jr.RESULTS
    result_down: jr.RESULTS
    near: object = None


def design_scene(psi0, gap, s0, n):
    """The symmetric scene of a design (psi0 in radians) at alpha = 0 with `n` segments."""
    base = jr.make_scene(60.0, 0.5, 0.0, s0=0.02, n=n)
    psi0, gap, s0 = (jnp.asarray(v, jnp.result_type(float)) for v in (psi0, gap, s0))
    return eqx.tree_at(lambda s: (s.strip.psi0, s.clamps.gap, s.strip.s0), base, (psi0, gap, s0))


def _lag(x, q, n):
    """Condensed Lagrangian as a function of x = (theta, mu) and q = (alpha, psi0, gap, s0)."""
    sc = jr.SymmetricAlpha().set(design_scene(q[1], q[2], q[3], n), q[0])
    return jr.lagrangian(x[:n], x[n:], sc)


def critical_sensitivity(theta, force, alpha, params, kind, n):
    r"""$\partial\alpha_c/\partial(\Psi_0, G, s_0)$ at a refined critical state (see module doc)."""
    x = jnp.concatenate([theta, force])
    q = jnp.concatenate([jnp.reshape(alpha, (1,)), params])
    F = jax.grad(_lag, argnums=0)
    K = jax.hessian(_lag, argnums=0)(x, q, n)
    lam, vec = batched.eigh(K)
    w = vec[:, jnp.argmin(jnp.abs(lam))]
    # fold
    gq = jax.grad(lambda qq: jnp.dot(w, F(x, qq, n)))(q)
    fold = -gq[1:] / gq[0]
    # branch point
    Fq = jax.jacfwd(F, argnums=1)(x, q, n)  # (N+2, 4)
    c = jnp.max(jnp.abs(jnp.diag(K)))
    xq = -batched.solve(K + c * jnp.outer(w, w), Fq)

    def sigma(xx, qq):
        return jnp.dot(w, jax.jvp(lambda y: F(y, qq, n), (xx,), (w,))[1])

    sx, sq = jax.grad(sigma, argnums=(0, 1))(x, q)
    ds = sq + sx @ xq
    branch = -ds[1:] / ds[0]
    return jnp.where(kind == 2, branch, fold)


@functools.partial(jax.custom_jvp, nondiff_argnums=(3,))
def critical_angles(psi0, gap, s0, n: int = 40, near=None) -> Critical:
    r"""[`Critical`][] angles of the design (Psi0 in radians, G/L, s0/L) on an `n`-segment mesh,
    differentiable in (psi0, gap, s0) (forward and reverse mode; see the module docstring).
    `near`: what a neighbouring design's `Critical.near` kept of its paths (an optimizer's
    previous iterate): each path then starts from that design's critical point where the checks
    of `jaxrod.branches._warm` hold (`jaxrod.snap_angles(..., near=)`); `near` carries no
    derivative. `Critical.near` holds this design's, for the next."""
    return _critical_values(psi0, gap, s0, n, near)


def _snap(psi0, gap, s0, n, near):
    r = jr.snap_angles(design_scene(psi0, gap, s0, n), near=near)
    return r, near_pair(r)


def _critical_values(psi0, gap, s0, n, near):
    r, pair = _snap(psi0, gap, s0, n, near)
    return Critical(r.up.alpha_c, r.down.alpha_c, r.up.snaps, r.down.snaps, r.up.kind, r.down.kind,
                    path_code(r.up), path_code(r.down), pair)


def path_code(path):
    """A snap path's verdict for design: its `result`, or its `start_result` where only the
    start is flagged (a substituted start: an alpha_c of the other half of the loop)."""
    return jr.RESULTS.where(path.result == jr.RESULTS.successful, path.start_result, path.result)


@critical_angles.defjvp
def _critical_jvp(n, primals, tangents):
    psi0, gap, s0, near = primals
    dtype = jnp.result_type(float)
    p = jnp.stack([jnp.asarray(v, dtype) for v in primals[:3]])
    dp = jnp.stack([jnp.asarray(v, dtype) for v in tangents[:3]])
    r, pair = _snap(psi0, gap, s0, n, near)
    out, douts = [], []
    for path in (r.up, r.down):
        g = critical_sensitivity(path.theta_before, path.force_before, path.alpha_c, p, path.kind, n)
        out.append(path.alpha_c)
        douts.append(jnp.where(path.snaps, jnp.dot(g, dp), 0.0))
    codes = (path_code(r.up), path_code(r.down))
    prim = Critical(out[0], out[1], r.up.snaps, r.down.snaps, r.up.kind, r.down.kind, *codes, pair)
    zero = lambda a: jnp.zeros(jnp.shape(a), jax.dtypes.float0)  # noqa: E731
    codes = jax.tree.map(zero, codes)
    # the neighbour's data for the next design carries no derivative
    pair_dot = jax.tree.map(lambda a: jnp.zeros_like(a) if jnp.issubdtype(a.dtype, jnp.inexact) else zero(a), pair)
    tan = Critical(douts[0], douts[1], zero(r.up.snaps), zero(r.down.snaps), zero(r.up.kind), zero(r.down.kind),
                   *codes, pair_dot)
    return prim, tan
