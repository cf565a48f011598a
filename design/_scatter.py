r"""Manufacturing scatter: the statistics of a design's snap angles when its fold angle, gap
and fold width scatter about their nominal values, and its clamps are misaligned.

A strip made by hand is never the nominal one. A [`Scatter`][] gives the deviations of the
parameters $p=(\Psi_0, G/L, s_0/L, \delta)$ from the nominal design $\bar p$ (whose clamp
misalignment $\delta=\alpha_L-\alpha_R$ is 0; both clamps turn together about it, see
`jaxrod.SymmetricAlpha`) as independent draws,

$$p=\bar p+\sigma\odot\varepsilon,\quad\varepsilon\sim\mathcal N(0,I)\quad(\text{"normal"},\ \sigma\ \text{the standard deviations}),$$
$$p=\bar p+w\odot u,\quad u\sim\mathcal U(-1,1)\quad(\text{"uniform"},\ w\ \text{the half-widths: "}\pm10\text{ deg"}),$$

clipped into the model's domain (`DOMAIN`; the clipped members are counted). The draws come
from a seed and do not depend on $\bar p$ (common random numbers), so two nominal designs are
compared on the same draws and the estimators below are differentiable in $\bar p$.

[`scatter_statistics`][] evaluates `jaxrod.snap_angles` on all $M$ members as one batch
(`jax.vmap`), each member started from the nominal strip's critical points (`near=`, checked;
the same angles and codes as a cold call), and reports, for the snap up and the snap down, over the $M_{ok}$ members whose
path is `successful` (the others are left out and counted by code):

- the mean $\hat\mu$ and standard deviation $s$ of $\alpha_c$, and the mean's standard error
  $s/\sqrt{M_{ok}}$;
- quantiles $\hat q$ (order statistics) with a distribution-free 95 % interval: the order
  statistics of ranks $M_{ok}q\pm1.96\sqrt{M_{ok}q(1-q)}$ (the binomial law of the number of
  members below the true quantile);
- the probability $P(|\alpha_c|\le a)$ that the strip snaps before the clamp angle $a$ (a
  member that does not snap counts as not snapping before $a$), with standard error
  $\sqrt{\hat P(1-\hat P)/M_{ok}}$.

Gradients with respect to the nominal design:

- of the mean, by the reparametrization estimator $\partial_{\bar p}\hat\mu=\frac1{M_{ok}}\sum
  \partial_p\alpha_c(p_m)$, each member's implicit derivative ([`scatter_mean`][] is
  differentiable: `jax.grad` of it);
- of the probability, whose indicator has no derivative, by the score-function (likelihood
  ratio) estimator of the normal law, $\partial_{\bar p_j}P=E\big[\mathbf 1\{|\alpha_c|\le a\}\,
  \varepsilon_j/\sigma_j\big]$ ([`score_gradient`][]): smooth in $\bar p$ even where $\alpha_c$
  itself has a cusp (a branch point meeting a fold), where the reparametrization estimator
  of the mean is not.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import jaxrod as jr
from jaxrod._compile import jit
from jaxrod._misc import check_int, check_number
from jaxrod.results import result_from_name, result_name

from ._critical import design_scene

DOMAIN = ((1.0, 180.0), (0.01, 0.99), (1e-3, 0.25), (-45.0, 45.0))
"""Where a sampled member's (Psi0 in deg, G/L, s0/L, misalignment in deg) is clipped to: the
model's domain."""

Z95 = 1.959963984540054
"""The standard normal's 97.5 % point: the half-width of a 95 % interval in standard errors."""


class Scatter(eqx.Module):
    """The scatter of a design's parameters (module docstring): `psi0_deg` (deg), `gap` and
    `s0` (units of L), `misalignment_deg` (deg, the clamps' difference $\alpha_L-\alpha_R$
    about its nominal 0) are standard deviations for `distribution="normal"`, half-widths for
    `"uniform"`. Zero (the default) keeps a parameter at its nominal value."""

    psi0_deg: float = 0.0
    gap: float = 0.0
    s0: float = 0.0
    distribution: str = eqx.field(static=True, default="normal")
    misalignment_deg: float = 0.0

    def __check_init__(self):
        for name in ("psi0_deg", "gap", "s0", "misalignment_deg"):
            check_number(name, getattr(self, name), lo=0.0, lo_open=False)
        if self.distribution not in ("normal", "uniform"):
            raise ValueError(f"distribution must be 'normal' or 'uniform', got {self.distribution!r}")

    @property
    def widths(self) -> np.ndarray:
        """(Psi0 in rad, G/L, s0/L, misalignment in rad): the standard deviations or half-widths."""
        return np.array([np.deg2rad(float(self.psi0_deg)), float(self.gap), float(self.s0),
                         np.deg2rad(float(self.misalignment_deg))])

    def draws(self, samples: int, seed: int = 0) -> np.ndarray:
        """(`samples`, 4) standard draws, N(0, 1) or U(-1, 1), from `seed` (numpy's PCG64): the
        design's three columns first, then the misalignment's (so that a seed's design draws do
        not depend on whether the clamps scatter)."""
        rng = np.random.default_rng(seed)
        if self.distribution == "normal":
            return np.concatenate([rng.standard_normal((samples, 3)), rng.standard_normal((samples, 1))], axis=1)
        return np.concatenate([rng.uniform(-1.0, 1.0, (samples, 3)), rng.uniform(-1.0, 1.0, (samples, 1))], axis=1)


def _members(nominal, widths, draws):
    """The members' (Psi0 in rad, G/L, s0/L, misalignment in rad), clipped into `DOMAIN`, and
    which were clipped. `nominal`: the design's (Psi0, G/L, s0/L); its misalignment is 0."""
    nominal = jnp.concatenate([nominal, jnp.zeros(1, nominal.dtype)])
    lo = jnp.array([np.deg2rad(DOMAIN[0][0]), DOMAIN[1][0], DOMAIN[2][0], np.deg2rad(DOMAIN[3][0])])
    hi = jnp.array([np.deg2rad(DOMAIN[0][1]), DOMAIN[1][1], DOMAIN[2][1], np.deg2rad(DOMAIN[3][1])])
    p = nominal[None, :] + widths[None, :] * draws
    q = jnp.clip(p, lo, hi)
    return q, jnp.any(q != p, axis=1)


def member_scene(m, n):
    r"""The scene of a member `m` = (Psi0 in rad, G/L, s0/L, misalignment in rad) at mesh `n`:
    the design's scene with its clamps at $\pm\delta/2$ ($\alpha=0$ about the misalignment)."""
    return jr.SymmetricAlpha(m[3]).set(design_scene(m[0], m[1], m[2], n), 0.0)


@jit
def _batch(nominal, widths, draws, n, extrapolate=False):
    """`jax.vmap` of `jaxrod.snap_angles` (or, with `extrapolate`,
    `jaxrod.snap_angles_extrapolated`) over the members: (their parameters, whether clipped,
    the batch of results). Every member starts from the nominal strip's critical points
    (`near=`): the same angles and codes as a cold call (the warm start is checked, and a
    member whose checks fail walks its whole path), at about a third of the cost."""
    q, clipped = _members(nominal, widths, draws)
    angles = jr.snap_angles_extrapolated if extrapolate else jr.snap_angles
    near = angles(member_scene(jnp.concatenate([nominal, jnp.zeros(1, nominal.dtype)]), n))
    snaps = jax.vmap(lambda m: angles(member_scene(m, n), near=near))(q)
    return q, clipped, snaps


def _nominal(psi0_deg, gap, s0):
    check_number("psi0_deg", psi0_deg, lo=DOMAIN[0][0], hi=DOMAIN[0][1], lo_open=False, hi_open=False)
    check_number("gap", gap, lo=0.0, hi=1.0)
    check_number("s0", s0, lo=0.0, hi=DOMAIN[2][1], hi_open=False)


def _checked(scatter, samples, seed, n):
    if not isinstance(scatter, Scatter):
        raise ValueError(f"scatter must be a jaxrod.design.Scatter, got {scatter!r}")
    check_int("samples", samples, lo=2)
    check_int("seed", seed, lo=0)
    check_int("n", n, lo=8)


def scatter_mean(psi0_deg, gap, s0=0.02, *, scatter: Scatter, samples: int = 256, seed: int = 0,
                 n: int = 100, extrapolate: bool = False):
    r"""The sample means of $\alpha_c$ up and down (rad) over the successful members, a
    differentiable function of the nominal design (`jax.grad` gives the reparametrization
    estimator of the module docstring; the draws are fixed by `seed`; `extrapolate`: each
    member by `jaxrod.snap_angles_extrapolated`, meshes `n` and 2 `n`). Returns
    `(mean_up, mean_down, num_ok_up, num_ok_down)`."""
    _checked(scatter, samples, seed, n)
    dtype = jnp.result_type(float)
    nominal = jnp.stack([jnp.deg2rad(jnp.asarray(psi0_deg, dtype)), jnp.asarray(gap, dtype),
                         jnp.asarray(s0, dtype)])
    _, _, r = _batch(nominal, jnp.asarray(scatter.widths, dtype), jnp.asarray(scatter.draws(samples, seed), dtype), n,
                     bool(extrapolate))
    out = []
    for path in (r.up, r.down):
        ok = path.snaps & (path.result == jr.RESULTS.successful)
        k = jnp.sum(ok)
        out.append((jnp.sum(jnp.where(ok, path.alpha_c, 0.0)) / jnp.maximum(k, 1), k))
    return out[0][0], out[1][0], out[0][1], out[1][1]


def score_gradient(event, draws, widths):
    r"""The score-function estimator of $\partial P/\partial\bar p$ for the normal scatter:
    $\frac1M\sum_m\mathbf 1_m\,\varepsilon_m/\sigma$ (`event` (M,) booleans, `draws` (M, P)
    the standard normal draws, `widths` (P,) the standard deviations), with its standard
    error per component. NaN where a width is zero (no scatter: no score)."""
    event = np.asarray(event, float)
    draws = np.asarray(draws, float)
    widths = np.asarray(widths, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        terms = event[:, None] * draws / np.where(widths > 0, widths, np.nan)[None, :]
    m = terms.shape[0]
    return terms.mean(axis=0), terms.std(axis=0, ddof=1) / np.sqrt(m)


class PathStatistics(eqx.Module):
    """The statistics of one snap direction over a scatter (module docstring). Angles in
    degrees (`alpha_deg` (M,), NaN where a member does not snap or is not successful).

    `mean`, `std`, `sem` (the mean's standard error); `quantiles` at `levels`, with
    `quantile_low` / `quantile_high` the 95 % interval of each; `before` the clamp angles
    (deg, magnitudes), `probability` $P(|\\alpha_c|\\le a)$ at each with `probability_sem`;
    `num_ok` the successful members (snapping or not), `num_snapping` those that snap;
    `codes` (M,) each member's `jaxrod.RESULTS` value; `probability_gradient` (A, 3) the
    score-function estimate of $\\partial P/\\partial(\\Psi_0\\ \\text{(deg)}, G, s_0)$ per angle
    (normal scatter only, NaN otherwise and where a width is zero), `probability_gradient_sem`
    its standard error."""

    alpha_deg: np.ndarray
    mean: float
    std: float
    sem: float
    levels: tuple
    quantiles: np.ndarray
    quantile_low: np.ndarray
    quantile_high: np.ndarray
    before: np.ndarray
    probability: np.ndarray
    probability_sem: np.ndarray
    probability_gradient: np.ndarray
    probability_gradient_sem: np.ndarray
    num_ok: int
    num_snapping: int
    codes: np.ndarray


class ScatterStatistics(eqx.Module):
    """What [`scatter_statistics`][] returns: `up` and `down` ([`PathStatistics`][]), the
    members' parameters `members` (M, 4: Psi0 in deg, G/L, s0/L, misalignment in deg), `clipped` (M,) those moved
    into `DOMAIN`, the `scatter`, `samples`, `seed` and mesh `n`.

    `result` (a `jaxrod.RESULTS` code): `successful` where every member of both directions
    is, else the first code of a member that is not (the statistics then hold the successful
    members only: see `num_ok`)."""

    up: PathStatistics
    down: PathStatistics
    members: np.ndarray
    clipped: np.ndarray
    scatter: Scatter
    samples: int
    seed: int
    n: int
    result: jr.RESULTS


def first_failure(*codes):
    """`successful` where every value of the `jaxrod.RESULTS` code arrays `codes` is, else the
    code of the first value that is not (in the order given)."""
    values = np.concatenate([np.ravel(np.asarray(c)) for c in codes])
    bad = values[values != int(jr.RESULTS.successful._value)]
    return jr.RESULTS.successful if bad.size == 0 else result_from_name(result_name(int(bad[0])))


def _order_interval(sorted_vals, q):
    """The q-quantile of sorted values and the order statistics of its 95 % interval."""
    m = len(sorted_vals)
    if m == 0:
        return np.nan, np.nan, np.nan
    est = float(np.quantile(sorted_vals, q))
    half = Z95 * np.sqrt(m * q * (1 - q))
    lo, hi = int(np.floor(m * q - half)), int(np.ceil(m * q + half))
    low = float(sorted_vals[lo - 1]) if lo >= 1 else np.nan
    high = float(sorted_vals[hi - 1]) if hi <= m else np.nan
    return est, low, high


def _path_statistics(path, draws, widths, distribution, levels, before):
    codes = np.asarray(path.result._value)
    ok = codes == int(jr.RESULTS.successful._value)
    snaps = np.asarray(path.snaps) & ok
    alpha = np.where(snaps, np.rad2deg(np.asarray(path.alpha_c)), np.nan)
    vals = np.sort(alpha[snaps])
    k = len(vals)
    mean = float(vals.mean()) if k else np.nan
    std = float(vals.std(ddof=1)) if k > 1 else np.nan
    qs = [_order_interval(vals, q) for q in levels]
    before = np.asarray(before, float)
    m_ok = int(ok.sum())
    events = [snaps[ok] & (np.abs(alpha[ok]) <= a) for a in before]
    prob = np.array([e.mean() if m_ok else np.nan for e in events])
    grads, gsems = [], []
    for a in before:
        if distribution == "normal" and m_ok > 1:
            # with respect to the design (Psi0, G/L, s0/L); the nominal misalignment is not one
            g, s = score_gradient(snaps[ok] & (np.abs(alpha[ok]) <= a), draws[ok][:, :3], widths[:3])
            g, s = g * np.array([np.pi / 180, 1, 1]), s * np.array([np.pi / 180, 1, 1])  # per deg of Psi0
        else:
            g = s = np.full(3, np.nan)
        grads.append(g)
        gsems.append(s)
    return PathStatistics(
        alpha_deg=alpha, mean=mean, std=std, sem=std / np.sqrt(k) if k > 1 else np.nan, levels=tuple(levels),
        quantiles=np.array([q[0] for q in qs]), quantile_low=np.array([q[1] for q in qs]),
        quantile_high=np.array([q[2] for q in qs]), before=before, probability=prob,
        probability_sem=np.sqrt(prob * (1 - prob) / max(m_ok, 1)),
        probability_gradient=np.array(grads).reshape(len(before), 3),
        probability_gradient_sem=np.array(gsems).reshape(len(before), 3),
        num_ok=m_ok, num_snapping=int(snaps.sum()), codes=codes)


def scatter_statistics(psi0_deg, gap, s0=0.02, *, scatter: Scatter, samples: int = 256, seed: int = 0,
                       n: int = 100, levels=(0.1, 0.5, 0.9), before_up=(), before_down=(),
                       extrapolate: bool = False) -> ScatterStatistics:
    r"""The statistics of the snap angles of the design (`psi0_deg`, `gap`, `s0`) under
    `scatter`, from `samples` members drawn from `seed`, each `jaxrod.snap_angles` at mesh
    `n`, evaluated as one batch (module docstring). `levels`: the quantiles to report;
    `before_up` / `before_down`: clamp angles $a$ (deg, magnitudes) at which to report
    $P(|\alpha_c|\le a)$ and its score-function gradient; `extrapolate`: each member by
    `jaxrod.snap_angles_extrapolated` (meshes `n` and 2 `n`: the continuum's angles, about three
    times the cost), where the mesh's own error would rival the spread. float64 must be enabled."""
    _nominal(psi0_deg, gap, s0)
    _checked(scatter, samples, seed, n)
    for name, qs in (("levels", levels),):
        if not all(0.0 < float(q) < 1.0 for q in qs):
            raise ValueError(f"{name} must lie in (0, 1), got {qs!r}")
    for name, angles in (("before_up", before_up), ("before_down", before_down)):
        if not all(np.isfinite(float(a)) and float(a) > 0 for a in angles):
            raise ValueError(f"{name} must be positive clamp angles in degrees, got {angles!r}")
    dtype = jnp.result_type(float)
    if dtype != jnp.float64:
        raise ValueError("scatter_statistics needs float64: jax.config.update('jax_enable_x64', True)")
    draws = scatter.draws(samples, seed)
    widths = scatter.widths
    nominal = jnp.array([np.deg2rad(float(psi0_deg)), float(gap), float(s0)], dtype)
    q, clipped, r = _batch(nominal, jnp.asarray(widths, dtype), jnp.asarray(draws, dtype), n, bool(extrapolate))
    up = _path_statistics(r.up, draws, widths, scatter.distribution, levels, before_up)
    down = _path_statistics(r.down, draws, widths, scatter.distribution, levels, before_down)
    result = first_failure(up.codes, down.codes)
    members = np.asarray(q).copy()
    members[:, [0, 3]] = np.rad2deg(members[:, [0, 3]])
    return ScatterStatistics(up=up, down=down, members=members, clipped=np.asarray(clipped), scatter=scatter,
                             samples=samples, seed=seed, n=n, result=result)

