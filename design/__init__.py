"""Inverse design of creased snapping strips on top of `jaxrod`.

Objectives (`AlphaUp`, `AlphaDown`, `Hysteresis`, `FoldHeight`, `BendingEnergy`, `Snaps`,
`SnapSpeed`), a feasible parametrization (`Parametrization`), multi-start optimization
(`optimize`, Levenberg-Marquardt or optax), results that save and reload
(`DesignResult.save` / `.load`), differentiable critical angles (`critical_angles`) and the
design studies (`snap_angle_study`, ...), crease positions and angles as design variables
(`CreaseParametrization`, `two_crease_study`, `crease_position_study`), and the statistics of
the snap angles under manufacturing scatter (`Scatter`, `scatter_statistics`, `scatter_mean`) and
under imperfections (`imperfection_sensitivity`), and robust design at a quantile of the scatter
(`robust_design`). float64 must be
enabled by the caller.
"""

from ._actuator import actuator_study as actuator_study
from ._actuator import ActuatorResult as ActuatorResult
from ._actuator import half_heights as half_heights
from ._actuator import half_state as half_state
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
from ._optimize import MultiStartResult as MultiStartResult
from ._optimize import optimize as optimize
from ._optimize import Problem as Problem
from ._optimize import STATUS as STATUS
from ._params import Parametrization as Parametrization
from ._studies import fastest_snap_study as fastest_snap_study
from ._studies import snap_angle_study as snap_angle_study
from ._studies import snap_speed_study as snap_speed_study
from ._studies import StudyResult as StudyResult
from ._studies import verify_snap_angles as verify_snap_angles
from ._studies import SpeedStudyResult as SpeedStudyResult
from ._studies import SpeedVerification as SpeedVerification
from ._studies import verify_snap_speed as verify_snap_speed
from ._programs import descend as descend
from ._programs import design_program as design_program
from ._programs import Fig4Result as Fig4Result
from ._programs import fig4_bodies as fig4_bodies
from ._programs import fig4_objects_json as fig4_objects_json
from ._programs import fig4_study as fig4_study
from ._programs import ProgramDesign as ProgramDesign
from ._programs import FIG4_N as FIG4_N
from ._programs import FIG4_N_CHECK as FIG4_N_CHECK
from ._programs import FIG4_PEAKS as FIG4_PEAKS
from ._programs import FIG4_PROGRAMS as FIG4_PROGRAMS
from ._programs import FIG4_V_LAUNCH as FIG4_V_LAUNCH
from ._programs import FIG4_V_SPARE as FIG4_V_SPARE
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
from ._creases import crease_position_study as crease_position_study
from ._creases import crease_scene as crease_scene
from ._creases import CreaseCheck as CreaseCheck
from ._creases import CreaseParametrization as CreaseParametrization
from ._creases import PositionResult as PositionResult
from ._creases import two_crease_study as two_crease_study
from ._creases import TwoCreaseResult as TwoCreaseResult
