"""Families of equilibria: continuation, critical points, snap angles.

Pseudo-arclength continuation in a clamp angle or the gap (`continue_branch`), the fold /
branch point where a path loses stability (`critical_point`, `cusp_point`), the snap angles
of both directions (`snap_angles`, `snap_angles_extrapolated`) and the critical point past
each (`snap_routes`), the gap where snapping ends
(`termination_gap`), the critical curve in (G/L, alpha) (`continue_critical`), the whole
hysteresis loop (`hysteresis`) and the phase diagram over (Psi0, G/L) (`phase_diagram`).

Layer: above statics; below dynamics.
"""

from ._continuation import AbstractParameter as AbstractParameter
from ._continuation import Branch as Branch
from ._continuation import Continuation as Continuation
from ._continuation import continue_branch as continue_branch
from ._continuation import Gap as Gap
from ._continuation import LeftAlpha as LeftAlpha
from ._continuation import RightAlpha as RightAlpha
from ._continuation import SymmetricAlpha as SymmetricAlpha
from ._critical import critical_point as critical_point
from ._critical import located_critical_point as located_critical_point
from ._critical import CriticalPoint as CriticalPoint
from ._critical import cusp_point as cusp_point
from ._critical import mirror_symmetric_part as mirror_symmetric_part
from ._critical import CuspPoint as CuspPoint
from ._critical_curve import continue_critical as continue_critical
from ._critical_curve import CriticalCurve as CriticalCurve
from ._extrapolate import ExtrapolatedPath as ExtrapolatedPath
from ._extrapolate import ExtrapolatedSnapAngles as ExtrapolatedSnapAngles
from ._extrapolate import extrapolate_path as extrapolate_path
from ._extrapolate import refined_scene as refined_scene
from ._extrapolate import richardson as richardson
from ._extrapolate import snap_angles_extrapolated as snap_angles_extrapolated
from ._hysteresis import BRANCH_NAMES as BRANCH_NAMES
from ._hysteresis import Hysteresis as Hysteresis
from ._hysteresis import hysteresis as hysteresis
from ._phase import phase_diagram as phase_diagram
from ._phase import termination_gaps as termination_gaps
from ._routes import Route as Route
from ._routes import snap_routes as snap_routes
from ._routes import SnapRoutes as SnapRoutes
from ._snap import follow_path as follow_path
from ._snap import KIND_NAMES as KIND_NAMES
from ._snap import NEAR_FOLD as NEAR_FOLD
from ._snap import snap_angles as snap_angles
from ._snap import SnapAngles as SnapAngles
from ._snap import SnapPath as SnapPath
from ._termination import termination_gap as termination_gap
from ._termination import TerminationGap as TerminationGap
from ._warm import Near as Near
from ._warm import near_pair as near_pair
from ._warm import unusable_near as unusable_near
