"""Inverse design of creased snapping strips on top of `jaxrod`.

Objectives (`AlphaUp`, `AlphaDown`, `Hysteresis`, `FoldHeight`, `BendingEnergy`, `Snaps`,
`SnapSpeed`), a feasible parametrization (`Parametrization`), multi-start optimization
(`optimize`, Levenberg-Marquardt or optax), results that save and reload
(`DesignResult.save` / `.load`), differentiable critical angles (`critical_angles`), crease
positions and angles as design variables (`CreaseParametrization`, `crease_scene`) and the gap
for a snap speed (`crease_gap_for_speed`), clamp programs designed by gradient
(`design_program`, `sequence_program`), and the statistics of the snap angles under
manufacturing scatter (`Scatter`, `scatter_statistics`, `scatter_mean`) and under
imperfections (`imperfection_sensitivity`), and robust design at a quantile of the scatter
(`robust_design`). float64 must be enabled by the caller.

The paper's studies and figures built on these tools (`snap_angle_study`, `fig4_study`,
`two_crease_study`, ...) are in `jaxrod.paper`; their old names here still resolve, with a
`DeprecationWarning`.
"""

from ._critical import Critical as Critical
from ._critical import critical_angles as critical_angles
from ._critical import design_scene as design_scene
from ._objectives import AlphaDown as AlphaDown
from ._objectives import AlphaUp as AlphaUp
from ._objectives import BendingEnergy as BendingEnergy
from ._objectives import dynamics_available as dynamics_available
from ._objectives import energy_released as energy_released
from ._objectives import FoldHeight as FoldHeight
from ._objectives import Hysteresis as Hysteresis
from ._objectives import Snaps as Snaps
from ._objectives import SnapSpeed as SnapSpeed
from ._objectives import Term as Term
from ._optimize import DesignResult as DesignResult
from ._optimize import linearize as linearize
from ._optimize import MultiStartResult as MultiStartResult
from ._optimize import optimize as optimize
from ._optimize import Problem as Problem
from ._optimize import STATUS as STATUS
from ._params import Parametrization as Parametrization
from ._programs import descend as descend
from ._programs import design_program as design_program
from ._programs import ProgramDesign as ProgramDesign
from ._programs import remaining_bodies as remaining_bodies
from ._programs import SEQUENCE_TIMING as SEQUENCE_TIMING
from ._programs import sequence_program as sequence_program
from ._programs import sequence_clearances as sequence_clearances
from ._programs import sequence_speeds as sequence_speeds
from ._programs import sequence_windows as sequence_windows
from ._programs import stage_outcome as stage_outcome
from ._programs import two_knot_program as two_knot_program
from ._imperfections import DirectionSensitivity as DirectionSensitivity
from ._imperfections import imperfect_scene as imperfect_scene
from ._imperfections import imperfection_sensitivity as imperfection_sensitivity
from ._imperfections import ImperfectionSensitivity as ImperfectionSensitivity
from ._robust import robust_design as robust_design
from ._robust import RobustDesign as RobustDesign
from ._robust import scatter_quantiles as scatter_quantiles
from ._scatter import PathStatistics as PathStatistics
from ._scatter import Scatter as Scatter
from ._scatter import scatter_mean as scatter_mean
from ._scatter import scatter_statistics as scatter_statistics
from ._scatter import ScatterStatistics as ScatterStatistics
from ._scatter import score_gradient as score_gradient
from ._creases import check_creases as check_creases
from ._creases import crease_gap_for_speed as crease_gap_for_speed
from ._creases import CreaseGapResult as CreaseGapResult
from ._creases import crease_scene as crease_scene
from ._creases import CreaseCheck as CreaseCheck
from ._creases import CreaseParametrization as CreaseParametrization


# The paper's studies, its Fig. 4 scene and the crease studies moved to `jaxrod.paper`. Their
# old names resolve there on first use, with a DeprecationWarning; `jaxrod.paper` is imported
# only then (it sits above this package).
_MOVED_TO_PAPER = frozenset({
    "actuator_study",
    "ActuatorResult",
    "crease_position_study",
    "fastest_snap_study",
    "fig4_bodies",
    "FIG4_N",
    "FIG4_N_CHECK",
    "fig4_objects_json",
    "FIG4_PEAKS",
    "FIG4_PROGRAMS",
    "fig4_study",
    "FIG4_V_LAUNCH",
    "FIG4_V_SPARE",
    "Fig4Result",
    "half_heights",
    "half_state",
    "PositionResult",
    "snap_angle_study",
    "snap_speed_study",
    "SpeedStudyResult",
    "SpeedVerification",
    "StudyResult",
    "two_crease_study",
    "TwoCreaseResult",
    "verify_snap_angles",
    "verify_snap_speed",
})


def __getattr__(name):
    """A name that moved to `jaxrod.paper` (`_MOVED_TO_PAPER`): `jaxrod.paper`'s object, with a
    `DeprecationWarning` naming its new place."""
    if name in _MOVED_TO_PAPER:
        import importlib
        import warnings

        warnings.warn(f"jaxrod.design.{name} moved to jaxrod.paper.{name}; import it from jaxrod.paper",
                      DeprecationWarning, stacklevel=2)
        return getattr(importlib.import_module("jaxrod.paper"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
