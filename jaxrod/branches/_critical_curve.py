r"""Two-parameter continuation: the curve of critical points in the (gap, alpha) plane.

A refined critical point of [`jaxrod.critical_point`][] (a fold in $\alpha$, or a
symmetry-breaking branch point of symmetric actuation) persists as the gap $G$ changes:
its extended system $R(z;G)=0$ ($z=(\theta,\mu,\alpha,v_\theta,v_\mu)$, $2N+5$ equations
for a fold; the $N+3$ symmetric-subspace equations for a branch point, module docstring
of `jaxrod.branches.critical_point`) has one more unknown than equations once $G$ is free, so its
solutions form a curve $w(s)=(z(s),G(s))$, which `continue_critical` follows by
pseudo-arclength continuation:

* tangent $\tau$: $\begin{pmatrix}R_w\\(W\tau_{\rm old})^\top\end{pmatrix}\tau=
  \begin{pmatrix}0\\1\end{pmatrix}$, normalized, $\langle a,b\rangle_W=
  \sum_ih_ia_{\theta_i}b_{\theta_i}+a_\alpha b_\alpha+a_Gb_G$ (the angles, $\alpha$ and $G$;
  the forces and the mode are not part of the arclength);
* predictor $w_p=w+\Delta s\,\tau$, corrector Newton on
  $(R(w),\ \langle\tau,w-w_p\rangle_W)=0$ (dense autodiff Jacobian, as `critical_point`);
* step control: $\Delta s$ grows by 1.5 after a corrector that took at most 3 steps,
  halves after one that failed (not converged in `corrector_steps`, or non-finite);
* the mode normalization $\ell^\top v_\theta=1$ is re-based at every accepted point
  ($\ell=h\odot v_\theta/\sum h v_\theta^2$, which leaves that point a root), so the
  mode may rotate along the curve.

**Where the curve ends** (`end_reason`): `END_TURN` -- $G$ turns back
($\tau_G$ changes sign). For a fold curve that is the **cusp**: $dG/ds=0$ exactly where
the Jacobian of the fold system in $z$ alone is singular, i.e. where the fold's quadratic
coefficient $\tilde{\mathcal L}'''[v,v,v]$ vanishes (the fold pair meets, the snap's jump
shrinks to zero); beyond it the curve comes back as the other fold of the pair. Its gap
is estimated by the Hermite cubic through the two points around the turn
(`end_gap`, $O(\Delta s^3)$) and then solved exactly by [`jaxrod.cusp_point`][] from the
last point before it (`cusp`). `END_BOUND` -- $G$ reached `gap_bounds`; `END_FAILED` --
the step fell below `ds_min` (the extended system became singular: e.g. a branch point
meeting a fold, or a mode lost); `END_MAX_POINTS` -- the buffers are full.

Fixed-size buffers and `lax.while_loop`: one compilation per mesh and buffer size;
`jit`-able. [`jaxrod.termination_gap`][] uses it to follow the fold of the snap-down path
to where it ends (`tests/test_critical_curve.py` checks the points against
`critical_point` at the same gaps and the end against `cusp_point`).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array

from ..linalg import batched
from ._continuation import AbstractParameter, SymmetricAlpha, _check_bounds, require_float64
from ._critical import (CriticalPoint, CuspPoint, KIND_BRANCH_POINT, _fold_pack, _fold_residual, _fold_unpack, _set_gap, _sym_pack, _sym_residual, _sym_unpack, cusp_point)
from ..energy.geometry import discretize
from ..energy.lagrangian import positions
from .._misc import check_int, check_number
from .._compile import jit
from ..results import RESULTS


END_TURN, END_BOUND, END_FAILED, END_MAX_POINTS = 1, 2, 3, 4
END_REASONS = {END_TURN: "turn", END_BOUND: "bound", END_FAILED: "failed", END_MAX_POINTS: "max_points"}


class CriticalCurve(eqx.Module):
    r"""The critical curve traced by [`jaxrod.continue_critical`][]: buffers valid up to
    `count` -- `gap`, `alpha` (rad), `fold_height`, `tau_gap` ($dG/ds$) -- and its end:
    `end_reason` (1 turn, 2 bound, 3 failed, 4 max points; module docstring), `end_gap`,
    `end_alpha` (at a turn: the Hermite estimate; otherwise the last point), `cusp` (a
    [`jaxrod.CuspPoint`][] solved from the last point before a turn of a fold curve;
    its `result` is not successful elsewhere), `kind` (1 fold, 2 branch point), and the
    last point's `theta`, `force`, `mode`."""

    gap: Array
    alpha: Array
    fold_height: Array
    tau_gap: Array
    count: Array
    end_reason: Array
    end_gap: Array
    end_alpha: Array
    cusp: CuspPoint
    kind: Array
    theta: Array
    force: Array
    mode: Array

    @property
    def result(self):
        """`continuation_incomplete` where the curve ended because its corrector failed
        (`end_reason` 3) or its buffer filled (4), else `successful` (a turn or the bound)."""
        return RESULTS.where((self.end_reason == 3) | (self.end_reason == 4), RESULTS.continuation_incomplete,
                             RESULTS.successful)


def _hermite(fa, fb, da, db):
    """Quadratic and cubic coefficients of the Hermite cubic on u in [0, 1] with values
    fa, fb and derivatives da, db at its ends: f(u) = fa + da u + c2 u^2 + c3 u^3."""
    return 3 * (fb - fa) - 2 * da - db, -2 * (fb - fa) + da + db


def _weights(h, N, kind):
    """Arclength weights on w = (theta, mu, alpha, v_theta, v_mu, G): the angles (L^2), alpha
    and G; the forces and the mode do not count (the end force and the mode force are large
    and fast-changing: with them the steps in G were ~200x shorter)."""
    z, o = jnp.zeros, jnp.ones
    if kind == KIND_BRANCH_POINT:
        H = N // 2
        hh = 2.0 * h[:H]  # each half-angle stands for two mirror-image angles
        return jnp.concatenate([hh, z(1, h.dtype), o(1, h.dtype), z(H + 1, h.dtype), o(1, h.dtype)])
    return jnp.concatenate([h, z(2, h.dtype), o(1, h.dtype), z(N + 2, h.dtype), o(1, h.dtype)])


def continue_critical(scene, cp: CriticalPoint, *, direction: float = 1.0, gap_bounds=(0.02, 0.995),
                      parameter: AbstractParameter = SymmetricAlpha(), ds: float = 0.01, ds_min: float = 1e-6,
                      ds_max: float = 0.05, max_points: int = 200, corrector_steps: int = 8,
                      tol: float = 1e-10, kind: int | None = None) -> CriticalCurve:
    r"""Follow the critical point `cp` (refined at the gap of `scene`, e.g.
    `snap_angles(scene).down.critical`) as the gap changes, `direction` +1 toward larger
    gaps, -1 toward smaller ones, until the curve turns in $G$ (a fold curve: the cusp),
    leaves `gap_bounds`, or the step falls below `ds_min` (see the module docstring).
    `kind` (1 fold, 2 branch point; default `cp.kind`, which must then be concrete) selects
    the fold or the branch-point system. Arclength `ds` in the norm of the module docstring; `tol`: the
    corrector's max-norm update tolerance. Returns a [`jaxrod.CriticalCurve`][]."""
    require_float64(cp.theta.dtype, "continue_critical")
    if kind is None:
        if isinstance(cp.kind, jax.core.Tracer):
            raise ValueError("kind: pass kind=1 (fold) or 2 (branch point) when cp.kind is traced (inside jit)")
        kind = int(cp.kind)
    if int(kind) not in (1, 2):
        raise ValueError(f"kind must be 1 (fold) or 2 (branch point), got {kind!r}")
    if direction not in (1.0, -1.0, 1, -1):
        raise ValueError(f"direction must be +1 or -1, got {direction!r}")
    _check_bounds("gap_bounds", gap_bounds)
    check_number("gap_bounds", gap_bounds[0], lo=0.0)  # gaps are positive; hi > lo checked above
    for name, v in (("ds", ds), ("ds_min", ds_min), ("ds_max", ds_max), ("tol", tol)):
        check_number(name, v, lo=0.0)
    if ds_min > ds_max:
        raise ValueError(f"ds_min must not exceed ds_max, got ds_min={ds_min!r}, ds_max={ds_max!r}")
    check_int("max_points", max_points, lo=2)
    check_int("corrector_steps", corrector_steps, lo=1)
    return _continue_critical(scene, cp, float(direction), tuple(float(g) for g in gap_bounds), parameter, float(ds),
                              float(ds_min), float(ds_max), int(max_points), int(corrector_steps), float(tol),
                              int(kind))


@jit
def _continue_critical(scene, cp, direction, gap_bounds, parameter, ds, ds_min, ds_max, max_points, corrector_steps,
                       tol, kind):
    sg = lax.stop_gradient
    scene = sg(scene)
    dtype = cp.theta.dtype
    N = cp.theta.shape[0]
    h = discretize(scene).h
    W = _weights(h, N, kind)
    g0 = jnp.asarray(scene.clamps.gap, dtype)
    if kind == KIND_BRANCH_POINT:
        pack, unpack, residual = _sym_pack, _sym_unpack, _sym_residual
    else:
        pack, unpack, residual = _fold_pack, _fold_unpack, _fold_residual
    z0 = pack(cp.theta, cp.force, cp.alpha, cp.mode, cp.mode_force)
    w0 = jnp.concatenate([z0, g0[None]])
    M = w0.shape[0]
    ia = M - 1  # the gap

    def ell_of(w):
        vt = unpack(w[:-1], N)[3]
        return h * vt / jnp.sum(h * vt**2)

    def R(w, ell):
        return residual(w[:-1], _set_gap(scene, w[-1]), parameter, ell)

    def tangent(w, ell, t_old):
        J = jax.jacfwd(R)(w, ell)
        A = jnp.concatenate([J, (W * t_old)[None]], axis=0)
        t = batched.solve(A, jnp.zeros(M, dtype).at[-1].set(1.0))
        return t / jnp.sqrt(jnp.sum(W * t * t))

    def correct(wp, t, ell):
        def cond(c):
            w, k, done = c
            return (~done) & (k < corrector_steps) & jnp.all(jnp.isfinite(w))

        def body(c):
            w, k, _ = c

            def F(w):
                return jnp.concatenate([R(w, ell), jnp.sum(W * t * (w - wp))[None]])

            dw = batched.solve(jax.jacfwd(F)(w), -F(w))
            return w + dw, k + 1, jnp.max(jnp.abs(dw)) < tol

        w, k, done = lax.while_loop(cond, body, (wp, jnp.zeros((), jnp.int32), jnp.zeros((), bool)))
        return w, k, done & jnp.all(jnp.isfinite(w))

    def fold_height(w):
        t, m, a, _, _ = unpack(w[:-1], N)
        return positions(t, m, parameter.set(_set_gap(scene, w[-1]), a))[N // 2, 1]

    ell0 = ell_of(w0)
    e_g = jnp.zeros(M, dtype).at[ia].set(direction)
    t0 = tangent(w0, ell0, e_g / jnp.sqrt(W[ia]))
    buf = jnp.full((max_points,), jnp.nan, dtype)
    bufs = (buf.at[0].set(g0), buf.at[0].set(cp.alpha), buf.at[0].set(fold_height(w0)), buf.at[0].set(t0[ia]))
    lo, hi = gap_bounds
    # carry: w, tangent, ell, ds, count, reason, previous (w, tangent), buffers
    init = (w0, t0, ell0, jnp.asarray(ds, dtype), jnp.ones((), jnp.int32), jnp.zeros((), jnp.int32), w0, t0, bufs)

    def cond(c):
        return c[5] == 0

    def body(c):
        w, t, ell, step, count, _, _, _, (bg, ba, bf, bt) = c
        wn, k, ok = correct(w + step * t, t, ell)
        # the corrector stays on the hyperplane through the predictor: a point much farther
        # than the step is another branch (e.g. the other fold of the pair near the cusp)
        ok = ok & (jnp.sqrt(jnp.sum(W * (wn - w) ** 2)) < 2.0 * step)

        def accept(_):
            elln = ell_of(wn)
            tn = tangent(wn, elln, t)
            turned = tn[ia] * direction < 0
            out = (wn[ia] < lo) | (wn[ia] > hi)
            full = count + 1 >= max_points
            reason = jnp.where(turned, END_TURN, jnp.where(out, END_BOUND, jnp.where(full, END_MAX_POINTS, 0)))
            nb = (bg.at[count].set(wn[ia]), ba.at[count].set(unpack(wn[:-1], N)[2]), bf.at[count].set(fold_height(wn)),
                  bt.at[count].set(tn[ia]))
            grow = jnp.where(k <= 3, 1.5, 1.0)
            return (wn, tn, elln, jnp.minimum(step * grow, ds_max), count + 1, reason.astype(jnp.int32), w, t, nb)

        def reject(_):
            small = step * 0.5 < ds_min
            return (w, t, ell, step * 0.5, count, jnp.where(small, END_FAILED, 0).astype(jnp.int32), c[6], c[7],
                    (bg, ba, bf, bt))

        return lax.cond(ok, accept, reject, None)

    w, t, ell, step, count, reason, wp, tp, (bg, ba, bf, bt) = lax.while_loop(cond, body, init)
    turn = reason == END_TURN
    # Hermite cubic of G(s) and alpha(s) on the last step [wp, w]: G'(s) = tau_G is zero
    # at s* in (0, S) where the tangent's gap component changes sign.
    S = jnp.sqrt(jnp.sum(W * (w - wp) ** 2))
    g_a, g_b, d_a, d_b = wp[ia], w[ia], tp[ia] * S, t[ia] * S  # derivatives per unit u = s / S
    # G(u) = g_a + d_a u + c2 u^2 + c3 u^3 on [0, 1]
    c2, c3 = _hermite(g_a, g_b, d_a, d_b)
    # G'(u) = d_a + 2 c2 u + 3 c3 u^2 = 0: the root in [0, 1]
    qa, qb, qc = 3 * c3, 2 * c2, d_a
    disc = jnp.sqrt(jnp.maximum(qb * qb - 4 * qa * qc, 0.0))
    r1 = (-qb + disc) / jnp.where(jnp.abs(qa) > 1e-300, 2 * qa, 1.0)
    r2 = (-qb - disc) / jnp.where(jnp.abs(qa) > 1e-300, 2 * qa, 1.0)
    lin = -qc / jnp.where(jnp.abs(qb) > 1e-300, qb, 1.0)
    u = jnp.where(jnp.abs(qa) > 1e-12 * jnp.abs(qb), jnp.where((r1 >= 0) & (r1 <= 1), r1, r2), lin)
    u = jnp.clip(u, 0.0, 1.0)
    g_end = g_a + d_a * u + c2 * u**2 + c3 * u**3
    a_a, a_b = unpack(wp[:-1], N)[2], unpack(w[:-1], N)[2]
    ia_ = N + 2 if kind != KIND_BRANCH_POINT else N // 2 + 1  # alpha
    da_a, da_b = tp[ia_] * S, t[ia_] * S
    e2, e3 = _hermite(a_a, a_b, da_a, da_b)
    a_end = a_a + da_a * u + e2 * u**2 + e3 * u**3
    g_end = jnp.where(turn, g_end, w[ia])
    a_end = jnp.where(turn, a_end, unpack(w[:-1], N)[2])
    # the exact cusp from the last point before the turn (fold curves)
    tq, mq, aq, vq, _ = unpack(wp[:-1], N)
    if kind == KIND_BRANCH_POINT:
        cusp = CuspPoint(*(jnp.full_like(x, jnp.nan) for x in (g0, cp.alpha, cp.theta, cp.force, cp.mode, g0)),
                         num_steps=jnp.zeros((), jnp.int32), result=RESULTS.nonfinite)
    else:
        sc_p = _set_gap(scene, wp[ia])
        cusp = cusp_point(sc_p, tq, mq, aq, vq, parameter=parameter)
        cusp = eqx.tree_at(lambda c: c.result, cusp, RESULTS.where(turn, cusp.result, RESULTS.nonfinite))
    tl, ml, _, vl, _ = unpack(w[:-1], N)
    return CriticalCurve(gap=bg, alpha=ba, fold_height=bf, tau_gap=bt, count=count, end_reason=reason,
                         end_gap=g_end, end_alpha=a_end, cusp=cusp, kind=jnp.asarray(kind, jnp.int32), theta=tl,
                         force=ml, mode=vl / jnp.sqrt(jnp.sum(h * vl**2)))

