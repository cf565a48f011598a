r"""Imperfections: how far a small asymmetry of the strip moves its snap angles.

Three imperfections of a strip with one central crease $(\Psi_0, s_0)$, each of amplitude
$\epsilon$, built with `jaxrod.Creases` (the main crease written as a crease at $L/2$, the
strip otherwise flat):

- `"crease_offset"`: the crease at $L/2+\epsilon$ ($\epsilon$ in units of $L$);
- `"kink"`: a second, weak crease of fold angle $180^\circ-\epsilon$ at $L/4$ ($\epsilon$ in
  degrees): a small natural-curvature asymmetry;
- `"clamp_misalignment"`: clamps that differ by $\alpha_L-\alpha_R=\epsilon$ (degrees) while
  they turn together ([`jaxrod.SymmetricAlpha`][]; $\alpha$ is their mean).

At $\epsilon=0$ each is the nominal (mirror-symmetric) strip. Where its snap is a *branch
point* (the mode that goes unstable is mirror-asymmetric), an asymmetry of size $\epsilon$
unfolds the bifurcation into a fold and moves the snap angle like
$|\Delta\alpha_c|=C\epsilon^{2/3}$ (Koiter's law for an asymmetric imperfection of a
symmetric bifurcation). Where it is a *fold* (a symmetric mode), the snap angle moves
smoothly: like $\epsilon^2$ for the crease offset and the misalignment, whose sign is the
mirror image ($\alpha_c(\epsilon)=\alpha_c(-\epsilon)$), like $\epsilon$ for the kink.

[`imperfection_sensitivity`][] computes $\alpha_c$ at the given amplitudes (one batch), the
local exponents $d\log|\Delta\alpha_c|/d\log\epsilon$ between consecutive amplitudes, and a
power law $C\epsilon^\beta$ fitted over the longest run of consecutive amplitudes whose local
exponents stay within `tolerance` of the nominal kind's prediction (the range where the law
holds; amplitudes whose paths are not `successful` break a run).
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import jaxrod as jr
from jaxrod._compile import jit
from jaxrod._misc import check_int, check_number

from ._scatter import first_failure

IMPERFECTIONS = ("crease_offset", "kink", "clamp_misalignment")
KINK_POSITION = 0.25
"""Where the kink imperfection's weak crease sits (units of L)."""

PREDICTED = {("crease_offset", "branch_point"): 2.0 / 3.0, ("crease_offset", "fold"): 2.0,
             ("kink", "branch_point"): 2.0 / 3.0, ("kink", "fold"): 1.0,
             ("clamp_misalignment", "branch_point"): 2.0 / 3.0, ("clamp_misalignment", "fold"): 2.0}
"""The exponent beta of |d alpha_c| = C eps^beta by imperfection and nominal kind."""


def imperfect_scene(psi0_deg, gap, kind: str, amplitude=0.0, *, s0: float = 0.02, n: int = 100):
    """The strip of one central crease (`psi0_deg`, `s0`) at `gap` with the imperfection
    `kind` of `amplitude` (module docstring). `amplitude` may be traced."""
    if kind not in IMPERFECTIONS:
        raise ValueError(f"kind must be one of {', '.join(IMPERFECTIONS)}, got {kind!r}")
    creases = [(0.5, float(psi0_deg), float(s0))]
    if kind == "kink":
        creases.append((KINK_POSITION, 180.0, float(s0)))
    base = jr.make_scene(180.0, float(gap), s0=float(s0), n=n, creases=creases)
    return _with_amplitude(base, kind, jnp.asarray(amplitude, jnp.result_type(float)))


def _with_amplitude(base, kind, amplitude):
    """`base` (the strip at zero amplitude) with the imperfection `kind` of `amplitude`."""
    if kind == "crease_offset":
        return eqx.tree_at(lambda s: s.strip.creases.positions, base,
                           base.strip.creases.positions.at[0].add(amplitude))
    if kind == "clamp_misalignment":
        half = 0.5 * jnp.deg2rad(amplitude)
        return eqx.tree_at(lambda s: (s.clamps.alpha_left, s.clamps.alpha_right), base,
                           (base.clamps.alpha_left + half, base.clamps.alpha_right - half))
    return eqx.tree_at(lambda s: s.strip.creases.angles, base,
                       base.strip.creases.angles.at[1].add(-jnp.deg2rad(amplitude)))


@jit
def _batch(base, amplitudes, kind):
    # the sensitivity differentiates nothing: the paths are not polished (the same angles,
    # without the critical points' implicit derivatives and their verdicts)
    return jax.vmap(lambda a: jr.snap_angles(_with_amplitude(base, kind, a), polish=False))(amplitudes)


class DirectionSensitivity(eqx.Module):
    """One snap direction's sensitivity (see [`ImperfectionSensitivity`][]): `alpha_deg` (A,)
    at the amplitudes (NaN where the path does not snap or is not successful), `change_deg`
    (A,) the change from the nominal, `local_exponents` (A-1,) between consecutive
    amplitudes, `codes` (A,) and `kinds` (A,) of each path; `nominal_deg`, `nominal_kind`;
    `predicted` the exponent of the nominal kind (None where it does not snap); `exponent`
    and `coefficient` of the fitted $|\\Delta\\alpha_c|=C\\epsilon^\\beta$ (deg), over
    `holds` = (smallest, largest amplitude) where the law holds (NaN where fewer than two
    amplitudes do)."""

    alpha_deg: np.ndarray
    change_deg: np.ndarray
    local_exponents: np.ndarray
    codes: np.ndarray
    kinds: np.ndarray
    nominal_deg: float
    nominal_kind: str
    predicted: float | None
    exponent: float
    coefficient: float
    holds: tuple


class ImperfectionSensitivity(eqx.Module):
    """What [`imperfection_sensitivity`][] returns: `up` and `down`
    ([`DirectionSensitivity`][]), the imperfection `kind` and its `amplitudes`, the mesh `n`;
    `result` `successful` where the nominal and every imperfect path are, else the first code
    of one that is not."""

    up: DirectionSensitivity
    down: DirectionSensitivity
    kind: str
    amplitudes: np.ndarray
    n: int
    result: jr.RESULTS


def _direction(path, nominal, kind, amplitudes, tolerance):
    ok_code = int(jr.RESULTS.successful._value)
    codes = np.asarray(path.result._value)
    good = np.asarray(path.snaps) & (codes == ok_code)
    alpha = np.where(good, np.rad2deg(np.asarray(path.alpha_c)), np.nan)
    nominal_ok = bool(nominal.snaps) and int(nominal.result._value) == ok_code
    nominal_deg = math.degrees(float(nominal.alpha_c)) if nominal_ok else math.nan
    nominal_kind = jr.KIND_NAMES[int(nominal.kind)] if nominal_ok else "none"
    change = np.abs(alpha - nominal_deg)
    with np.errstate(divide="ignore", invalid="ignore"):
        logs = np.log(change)
        local = np.diff(logs) / np.diff(np.log(amplitudes))
    predicted = PREDICTED.get((kind, nominal_kind))
    # the longest run of consecutive amplitudes (the smallest first among equals) whose local
    # exponents are finite and within `tolerance` of the prediction (any finite one where
    # there is no prediction)
    fits = np.isfinite(local) & (True if predicted is None else np.abs(local - predicted) <= tolerance * predicted)
    best, start = (0, 0), None
    for j, f in enumerate(np.append(fits, False)):
        if f and start is None:
            start = j
        elif not f and start is not None:
            if j - start > best[1] - best[0]:
                best = (start, j)
            start = None
    exponent = coefficient = math.nan
    holds = (math.nan, math.nan)
    if best[1] > best[0]:
        sl = slice(best[0], best[1] + 1)
        exponent, intercept = np.polyfit(np.log(amplitudes[sl]), logs[sl], 1)
        coefficient = float(np.exp(intercept))
        holds = (float(amplitudes[best[0]]), float(amplitudes[best[1]]))
    return DirectionSensitivity(
        alpha_deg=alpha, change_deg=change, local_exponents=local, codes=codes,
        kinds=np.array([jr.KIND_NAMES[int(v)] for v in np.asarray(path.kind)]), nominal_deg=nominal_deg,
        nominal_kind=nominal_kind, predicted=predicted, exponent=float(exponent), coefficient=coefficient,
        holds=holds)


def imperfection_sensitivity(psi0_deg, gap, kind: str = "crease_offset", amplitudes=None, *, s0: float = 0.02,
                             n: int = 100, tolerance: float = 0.05) -> ImperfectionSensitivity:
    r"""The snap angles of the strip (`psi0_deg`, `gap`, `s0`, mesh `n`) with the imperfection
    `kind` at each of `amplitudes` (increasing, positive; default 7 from 1e-5 to 1e-2: L for
    the crease offset, deg for the kink and the misalignment), beside the nominal strip, with the power law of the
    change and the range where it holds (module docstring; `tolerance` the relative deviation
    of a local exponent from the prediction still counted as holding). float64 must be enabled."""
    check_number("psi0_deg", psi0_deg, lo=0.0, hi=180.0, hi_open=True)
    check_number("gap", gap, lo=0.0, hi=1.0)
    check_number("s0", s0, lo=0.0, hi=0.25, hi_open=False)
    check_int("n", n, lo=8)
    check_number("tolerance", tolerance, lo=0.0)
    if kind not in IMPERFECTIONS:
        raise ValueError(f"kind must be one of {', '.join(IMPERFECTIONS)}, got {kind!r}")
    amplitudes = np.geomspace(1e-5, 1e-2, 7) if amplitudes is None else np.asarray(amplitudes, float)
    if amplitudes.ndim != 1 or amplitudes.size < 2 or not np.all(amplitudes > 0) or np.any(np.diff(amplitudes) <= 0):
        raise ValueError(f"amplitudes must be at least two increasing positive numbers, got {amplitudes!r}")
    if kind == "crease_offset" and amplitudes[-1] >= 0.25:
        raise ValueError(f"amplitudes: a crease offset must stay below 0.25 L, got {amplitudes[-1]!r}")
    if kind == "kink" and amplitudes[-1] >= 180.0:
        raise ValueError(f"amplitudes: a kink must stay below 180 deg, got {amplitudes[-1]!r}")
    if kind == "clamp_misalignment" and amplitudes[-1] >= 90.0:
        raise ValueError(f"amplitudes: a clamp misalignment must stay below 90 deg, got {amplitudes[-1]!r}")
    if jnp.result_type(float) != jnp.float64:
        raise ValueError("imperfection_sensitivity needs float64: jax.config.update('jax_enable_x64', True)")
    base = imperfect_scene(psi0_deg, gap, kind, 0.0, s0=s0, n=n)
    r = _batch(base, jnp.concatenate([jnp.zeros(1), jnp.asarray(amplitudes)]), kind)
    take = lambda tree, sl: jax.tree.map(lambda x: x[sl], tree)  # noqa: E731
    up = _direction(take(r.up, slice(1, None)), take(r.up, 0), kind, amplitudes, tolerance)
    down = _direction(take(r.down, slice(1, None)), take(r.down, 0), kind, amplitudes, tolerance)
    result = first_failure(r.up.result._value, r.down.result._value)
    return ImperfectionSensitivity(up=up, down=down, kind=kind, amplitudes=amplitudes, n=n, result=result)
