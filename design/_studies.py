r"""Design studies (issue 5), each a function returning a result with an independent check.

(a) `snap_angle_study`: $(\Psi_0, G/L)$ such that $\alpha_{c,\rm up}$ and $\alpha_{c,\rm down}$ hit
    targets (default 60 and -70 deg), $s_0 = 0.02$. Multi-start Levenberg-Marquardt on a coarse
    mesh, the best design refined on the design mesh, then re-checked by an independent
    forward solve (`jaxrod.snap_angles`, no gradients) on a finer mesh.
(b) `fastest_snap_study` (max $v_s$ s.t. $G/L\ge0.3$), (c) `snap_speed_study` ($v_s = 20 v^*$ at
    $\Psi_0 = 90^\circ$) and (d) `actuator_study` (left half, right half, both: the paper's
    Fig. 4) need jaxrod's snap dynamics (issue 4); until it exists they raise
    `NotImplementedError` naming what is missing.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

import jaxrod as jr

from ._critical import design_scene
from ._objectives import AlphaDown, AlphaUp, dynamics_available
from ._optimize import DesignResult, MultiStartResult, optimize
from ._params import Parametrization


@dataclasses.dataclass
class Verification:
    """An independent forward check of a design at a finer mesh `n`."""

    n: int
    alpha_up_deg: float
    alpha_down_deg: float
    errors_deg: tuple
    reached: bool


def verify_snap_angles(result: DesignResult, n: int, tol: float = 0.1) -> Verification:
    """Re-solve the design's snap angles with `jaxrod.snap_angles` at `n` segments and
    compare with its targets (alpha_c_up / alpha_c_down terms, in degrees)."""
    sc = design_scene(jnp.deg2rad(result.psi0_deg), result.gap, result.s0, n)
    r = jr.snap_angles(sc)
    got = {"alpha_c_up": math.degrees(float(r.up.alpha_c)), "alpha_c_down": math.degrees(float(r.down.alpha_c))}
    errs = tuple(abs(got[nm] - float(t)) for nm, t in zip(result.names, np.asarray(result.targets)) if nm in got)
    return Verification(n, got["alpha_c_up"], got["alpha_c_down"], errs,
                        bool(all(e <= tol for e in errs) and all(math.isfinite(e) for e in errs)))


@dataclasses.dataclass
class StudyResult:
    coarse: MultiStartResult
    design: DesignResult
    verification: Verification

    @property
    def reached(self):
        return bool(self.design.reached) and self.verification.reached


def snap_angle_study(alpha_up_deg=60.0, alpha_down_deg=-70.0, *, bounds=None, s0=0.02, starts=4, n_coarse=40,
                     n=160, n_check=320, tol=0.1, max_iter=30, seed=0, progress=True) -> StudyResult:
    """Study (a): find (Psi0, G/L) with the given critical angles (degrees).

    `starts` random starts (uniform in the bounds; default bounds Psi0 in (10, 180) deg,
    G/L in (0.05, 0.95); pass e.g. `bounds={"gap": (0.3, 0.95)}`) run on `n_coarse`
    segments; the best is refined on `n` segments (discretization error of alpha_c
    ~ 1000 deg / N^2, so n = 160 is within ~0.04 deg of converged) and checked at `n_check`."""
    param = Parametrization(free=("psi0_deg", "gap"), bounds=bounds, fixed={"s0": s0})
    z0 = jnp.concatenate([param.from_values(psi0_deg=60.0, gap=0.5)[None],
                          param.sample(jax.random.PRNGKey(seed), max(starts - 1, 0))])
    terms_c = (AlphaUp(alpha_up_deg, tol=tol), AlphaDown(alpha_down_deg, tol=tol))
    coarse = optimize(terms_c, param, z0, n=n_coarse, max_iter=max_iter, progress=progress)
    fine = optimize(terms_c, param, coarse.best.z, n=n, max_iter=max_iter, progress=progress,
                    meta={"study": "a", "coarse_n": n_coarse})
    return StudyResult(coarse, fine.best, verify_snap_angles(fine.best, n_check, tol))


def _needs_dynamics(what):
    if not dynamics_available():
        raise NotImplementedError(f"{what} needs a differentiable snap speed from jaxrod's dynamics "
                                  "(issue 4); not available yet in design")


def fastest_snap_study(min_gap=0.3, **kwargs):
    """Study (b): maximize the snapping speed v_s / v* subject to G/L >= `min_gap`."""
    _needs_dynamics("fastest_snap_study")
    raise NotImplementedError("fastest_snap_study: dynamics API present but not wired yet")  # pragma: no cover


def snap_speed_study(target_speed=20.0, psi0_deg=90.0, **kwargs):
    """Study (c): the gap (and s0) with v_s = `target_speed` v* at Psi0 = `psi0_deg`."""
    _needs_dynamics("snap_speed_study")
    raise NotImplementedError("snap_speed_study: dynamics API present but not wired yet")  # pragma: no cover


def actuator_study(**kwargs):
    """Study (d): a clamp-move program snapping the left half only, the right half only,
    then both (the paper's Fig. 4)."""
    _needs_dynamics("actuator_study")
    raise NotImplementedError("actuator_study: dynamics API present but not wired yet")  # pragma: no cover
