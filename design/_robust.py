r"""Robust design: a fold angle and a gap whose snap angles meet their targets at a quantile of
the manufacturing scatter, not only at the nominal strip.

The target "snaps up before $a_{up}$ with probability $q$" reads: the $q$-quantile of
$\alpha_{c,up}$ over the scatter equals $a_{up}$; likewise for $|\alpha_{c,down}|$. With the
members drawn once (`jaxrod.design.Scatter`, common random numbers), the sample quantile

$$\hat Q_q=\alpha_{(k)}+f\,(\alpha_{(k+1)}-\alpha_{(k)}),\qquad k+f=q\,(M_{ok}-1)$$

of the successful members' angles (sorted, $\alpha_{(1)}\le\dots$) is a piecewise smooth
function of the nominal design, whose derivative is that of the members it interpolates (each
an implicit derivative of `jaxrod.snap_angles`). [`robust_design`][] solves
$\hat Q_q(\alpha_{up})=a_{up}$, $\hat Q_q(|\alpha_{down}|)=a_{down}$ for $(\Psi_0, G/L)$ by
`optimistix.LevenbergMarquardt` on the residuals in degrees, in the unconstrained variables
$\Psi_0=180^\circ\sigma(z_0)$, $G/L=\sigma(z_1)$ ($\sigma$ the logistic function: every iterate is a
strip), and re-checks the design by an independent Monte Carlo: single `jaxrod.snap_angles`
calls on fresh draws and a mesh twice as fine, whose empirical probabilities
$P(\alpha_{up}\le a_{up})$ and $P(|\alpha_{down}|\le a_{down})$ should be $q$ within their
binomial standard errors.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

import jaxrod as jr
from jaxrod._misc import check_int, check_number
from jaxrod.results import result_from_name

from ._critical import design_scene
from ._scatter import Scatter, _batch, _members, member_scene

BIG = 1e3
"""Stands in (rad) for a member that is not successful when the quantile's members are sorted:
it sorts after every real angle and never enters the quantile while fewer than a fraction
1 - q of the members fail."""


def _sample_quantile(values, ok, q):
    """The q-quantile of `values` over the members where `ok`, linear between order statistics
    (differentiable: the derivative of the members it interpolates)."""
    v = jnp.where(ok, jnp.where(ok, values, 0.0), BIG)
    s = jnp.sort(v)
    m = jnp.sum(ok)
    pos = q * (m - 1)
    k = jnp.clip(jnp.floor(pos).astype(jnp.int32), 0, v.shape[0] - 1)
    f = pos - k
    return s[k] + f * (s[jnp.minimum(k + 1, v.shape[0] - 1)] - s[k])


def scatter_quantiles(psi0_deg, gap, s0=0.02, *, scatter: Scatter, quantile: float, samples: int = 64,
                      seed: int = 0, n: int = 60, extrapolate: bool = True):
    r"""The `quantile` of $\alpha_{c,up}$ and of $|\alpha_{c,down}|$ (deg) over the successful
    members of `scatter` (a differentiable function of the nominal design on fixed draws; module
    docstring), and the fraction of members that are successful and snap, per direction.
    `extrapolate` (default): each member by `jaxrod.snap_angles_extrapolated` (meshes `n` and
    2 `n`), whose error is far below the spread a scatter gives; the mesh's own (0.1-1 deg at
    n = 40-100) is not."""
    dtype = jnp.result_type(float)
    nominal = jnp.stack([jnp.deg2rad(jnp.asarray(psi0_deg, dtype)), jnp.asarray(gap, dtype),
                         jnp.asarray(s0, dtype)])
    _, _, r = _batch(nominal, jnp.asarray(scatter.widths, dtype), jnp.asarray(scatter.draws(samples, seed), dtype), n,
                     bool(extrapolate))
    out, frac = [], []
    for path, sign in ((r.up, 1.0), (r.down, -1.0)):
        ok = path.snaps & (path.result == jr.RESULTS.successful)
        out.append(jnp.rad2deg(_sample_quantile(sign * path.alpha_c, ok, quantile)))
        frac.append(jnp.mean(ok))
    return jnp.stack(out), jnp.stack(frac)


class RobustDesign(eqx.Module):
    """What [`robust_design`][] returns. `psi0_deg`, `gap`, `s0`: the design; `quantiles` (2,)
    the achieved quantiles of $\\alpha_{c,up}$ and $|\\alpha_{c,down}|$ (deg) on the design's
    draws, `targets` (2,); `nominal` (2,) the nominal strip's $\\alpha_{c,up}$,
    $|\\alpha_{c,down}|$ (deg) at the design; `num_steps` of the optimizer.

    The independent check (single calls on `check_samples` fresh draws at mesh `check_n`):
    `check_probability` (2,) the fractions of the successful members with
    $\\alpha_{c,up}\\le a_{up}$ and $|\\alpha_{c,down}|\\le a_{down}$, `check_sem` (2,) their
    binomial standard errors, `check_ok` (2,) the successful members per direction.

    `result`: `successful` where the optimizer converged to the targets (within `tol_deg`)
    and the check agrees with `quantile` within 3 standard errors; `target_not_reached`
    otherwise (`message` says which)."""

    psi0_deg: float
    gap: float
    s0: float
    quantile: float
    quantiles: np.ndarray
    targets: np.ndarray
    nominal: np.ndarray
    num_steps: int
    check_probability: np.ndarray
    check_sem: np.ndarray
    check_ok: np.ndarray
    message: str
    result: jr.RESULTS


def _to_design(z):
    return 180.0 * jax.nn.sigmoid(z[0]), jax.nn.sigmoid(z[1])


def _from_design(psi0_deg, gap):
    logit = lambda p: math.log(p / (1 - p))  # noqa: E731
    return jnp.array([logit(psi0_deg / 180.0), logit(gap)])


def robust_design(target_up_deg, target_down_deg, *, quantile: float = 0.9, scatter: Scatter = Scatter(psi0_deg=10.0),
                  start=(90.0, 0.5), s0: float = 0.02, samples: int = 64, seed: int = 0, n: int = 60,
                  max_steps: int = 30, tol_deg: float = 0.01, check_samples: int = 128,
                  check_n: int | None = None, extrapolate: bool = True) -> RobustDesign:
    r"""The fold angle and gap whose snap angles reach `target_up_deg` ($>0$) and
    `target_down_deg` ($<0$) at `quantile` of `scatter`: $\hat Q_q(\alpha_{up})=a_{up}$ and
    $\hat Q_q(|\alpha_{down}|)=|a_{down}|$ on `samples` members at mesh `n`, from `start`
    (Psi0 deg, G/L) by Levenberg-Marquardt (module docstring), re-checked by `check_samples`
    single calls at `check_n` (default 2 `n`) on fresh draws. `extrapolate` (default): the
    angles of the design and of the check by `jaxrod.snap_angles_extrapolated`, so that the
    two meshes agree far within the scatter's spread. float64 must be enabled."""
    check_number("target_up_deg", target_up_deg, lo=0.0, hi=180.0)
    check_number("target_down_deg", target_down_deg, lo=-180.0, hi=0.0)
    check_number("quantile", quantile, lo=0.0, hi=1.0)
    if not isinstance(scatter, Scatter):
        raise ValueError(f"scatter must be a jaxrod.design.Scatter, got {scatter!r}")
    if not (isinstance(start, (tuple, list)) and len(start) == 2):
        raise ValueError(f"start must be (psi0_deg, gap), got {start!r}")
    check_number("start psi0_deg", start[0], lo=0.0, hi=180.0)
    check_number("start gap", start[1], lo=0.0, hi=1.0)
    check_number("s0", s0, lo=0.0, hi=0.25, hi_open=False)
    check_int("samples", samples, lo=4)
    check_int("seed", seed, lo=0)
    check_int("n", n, lo=8)
    check_int("max_steps", max_steps, lo=1)
    check_number("tol_deg", tol_deg, lo=0.0)
    check_int("check_samples", check_samples, lo=4)
    check_n = 2 * n if check_n is None else check_n
    check_int("check_n", check_n, lo=8)
    if jnp.result_type(float) != jnp.float64:
        raise ValueError("robust_design needs float64: jax.config.update('jax_enable_x64', True)")
    targets = jnp.array([float(target_up_deg), -float(target_down_deg)])

    def residual(z, _):
        psi, g = _to_design(z)
        qs, _ = scatter_quantiles(psi, g, s0, scatter=scatter, quantile=quantile, samples=samples, seed=seed, n=n,
                                  extrapolate=extrapolate)
        return qs - targets

    solver = optx.LevenbergMarquardt(rtol=1e-10, atol=1e-10)
    sol = optx.least_squares(residual, solver, _from_design(*start), max_steps=max_steps, throw=False)
    psi, g = (float(v) for v in _to_design(sol.value))
    qs, _ = scatter_quantiles(psi, g, s0, scatter=scatter, quantile=quantile, samples=samples, seed=seed, n=n,
                              extrapolate=extrapolate)
    qs = np.asarray(qs)
    angles = jr.snap_angles_extrapolated if extrapolate else jr.snap_angles
    nom = angles(design_scene(math.radians(psi), g, s0, n))
    nominal = np.array([math.degrees(float(nom.up.alpha_c)), -math.degrees(float(nom.down.alpha_c))])
    prob, sem, count = _check(psi, g, s0, scatter, targets, samples=check_samples, seed=seed + 7919, n=check_n,
                              angles=angles)
    reached = bool(np.all(np.abs(qs - np.asarray(targets)) <= tol_deg))
    agrees = np.abs(prob - quantile) <= 3 * np.maximum(sem, 1e-12)
    message = []
    if not reached:
        message.append(f"the quantiles {qs.round(4).tolist()} deg miss the targets {np.asarray(targets).tolist()} "
                       f"by more than tol_deg = {tol_deg}")
    for name, a, p_, s_ in zip(("up", "down"), agrees, prob, sem):
        if not a:
            message.append(f"the independent check's P({name}) = {p_:.3f} +- {s_:.3f} is not {quantile}")
    result = jr.RESULTS.successful if not message else result_from_name("target_not_reached")
    return RobustDesign(psi0_deg=psi, gap=g, s0=float(s0), quantile=float(quantile), quantiles=qs,
                        targets=np.asarray(targets), nominal=nominal, num_steps=int(sol.stats["num_steps"]),
                        check_probability=prob, check_sem=sem, check_ok=count, message="; ".join(message),
                        result=result)


def _check(psi0_deg, gap, s0, scatter, targets, *, samples, seed, n, angles):
    """The independent Monte Carlo: single calls of `angles` on fresh draws."""
    members, _ = _members(jnp.array([math.radians(psi0_deg), gap, s0]), jnp.asarray(scatter.widths),
                          jnp.asarray(scatter.draws(samples, seed)))
    hits, oks = np.zeros(2), np.zeros(2)
    for p in np.asarray(members):
        r = angles(member_scene(p, n))
        for j, (path, sign) in enumerate(((r.up, 1.0), (r.down, -1.0))):
            if path.result == jr.RESULTS.successful:
                oks[j] += 1
                hits[j] += bool(path.snaps) and sign * math.degrees(float(path.alpha_c)) <= float(targets[j])
    prob = hits / np.maximum(oks, 1)
    return prob, np.sqrt(prob * (1 - prob) / np.maximum(oks, 1)), oks
