"""jaxrod: differentiable statics and dynamics of creased, snapping elastic strips."""

import importlib
import importlib.metadata
import os
from typing import TYPE_CHECKING as _TYPE_CHECKING


# jaxlib's CPU LAPACK kernels (the dense solves of the critical-point refinement, eigvalsh)
# come from scipy's OpenBLAS, whose threads fight XLA's own: on a machine with few cores the
# default thread count makes a dense solve many times slower (docs/limitations.md). One thread
# unless the user chose (this has an effect only if scipy's OpenBLAS is not loaded yet).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# XLA:CPU can deadlock when a batched LAPACK kernel (a vmapped dense solve: jaxlib's
# ParallelBatchMap on the intra-op Eigen pool) runs inside a while loop that itself runs on
# that pool: on a machine with few cores the phase diagram (vmapped snap_angles) can hang,
# every thread waiting (cf. PyAutoFit issues 1528/1530). A single-threaded Eigen pool avoids
# it and costs no measurable run time (docs/limitations.md).
# XLA_FLAGS is read when the CPU backend starts, i.e. at the first computation.
if "xla_cpu_multi_thread_eigen" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " --xla_cpu_multi_thread_eigen=false").strip()

from .results import RESULTS as RESULTS
from .results import result_name as result_name
from ._compile import clear_caches as clear_caches

# model: what the strip is
from .model import Clamps as Clamps
from .model import Contact as Contact
from .model import Creases as Creases
from .model import Gravity as Gravity
from .model import make_scene as make_scene
from .model import Mesh as Mesh
from .model import Scene as Scene
from .model import Stretching as Stretching
from .model import Strip as Strip

# energy: its Lagrangian and its clearance to itself
from .energy.contact import clearance as clearance
from .energy.contact import self_intersects as self_intersects
from .energy.geometry import discretize as discretize
from .energy.lagrangian import lagrangian as lagrangian

# linalg: the bordered tridiagonal Hessian
from .linalg import BorderedTridiagonal as BorderedTridiagonal

# statics: one equilibrium and its stability
from .statics import arclength as arclength
from .statics import bending_energy as bending_energy
from .statics import buckled_guess as buckled_guess
from .statics import compression as compression
from .statics import curvature as curvature
from .statics import dense_reduced_hessian as dense_reduced_hessian
from .statics import energies as energies
from .statics import Equilibrium as Equilibrium
from .statics import crease_heights as crease_heights
from .statics import fold_height as fold_height
from .statics import hessian as hessian
from .statics import initial_state as initial_state
from .statics import Newton as Newton
from .statics import node_positions as node_positions
from .statics import solve_equilibrium as solve_equilibrium
from .statics import Stability as Stability
from .statics import stability as stability
from .statics import strains as strains
from .statics import tangent_angles as tangent_angles

# branches: continuation, critical points, snap angles, termination, phase diagrams
from .branches import AbstractParameter as AbstractParameter
from .branches import Branch as Branch
from .branches import BRANCH_NAMES as HYSTERESIS_BRANCHES  # noqa: F401 - public name
from .branches import continue_branch as continue_branch
from .branches import continue_critical as continue_critical
from .branches import Continuation as Continuation
from .branches import critical_point as critical_point
from .branches import CriticalCurve as CriticalCurve
from .branches import CriticalPoint as CriticalPoint
from .branches import cusp_point as cusp_point
from .branches import CuspPoint as CuspPoint
from .branches import ExtrapolatedPath as ExtrapolatedPath
from .branches import ExtrapolatedSnapAngles as ExtrapolatedSnapAngles
from .branches import Gap as Gap
from .branches import Hysteresis as Hysteresis
from .branches import hysteresis as hysteresis
from .branches import KIND_NAMES as KIND_NAMES
from .branches import LeftAlpha as LeftAlpha
from .branches import phase_diagram as phase_diagram
from .branches import refined_scene as refined_scene
from .branches import extrapolate_path as extrapolate_path
from .branches import richardson as richardson
from .branches import RightAlpha as RightAlpha
from .branches import Route as Route
from .branches import snap_angles as snap_angles
from .branches import snap_angles_extrapolated as snap_angles_extrapolated
from .branches import SnapAngles as SnapAngles
from .branches import SnapPath as SnapPath
from .branches import snap_routes as snap_routes
from .branches import SnapRoutes as SnapRoutes
from .branches import SymmetricAlpha as SymmetricAlpha
from .branches import termination_gap as termination_gap
from .branches import TerminationGap as TerminationGap

# dynamics: equations of motion, integrators, scenes, snap speed. Imported on first use
# (`__getattr__` below): diffrax, which only the dynamics need, is slow to import, and the
# statics, branches and CLI queries such as `jaxrod snap-angles` do without it.
_DYNAMICS = (
    "ACTUATOR_DAMPING",
    "ACTUATOR_VISCOSITY",
    "Actuation",
    "actuate",
    "Ball",
    "Bodies",
    "damping_from_ringdown",
    "Floor",
    "hold_and_move",
    "Program",
    "Table",
    "brink",
    "Brink",
    "Asymmetric",
    "Ramp",
    "Dissipation",
    "Protocol",
    "HHT",
    "Rattle",
    "ramp",
    "simulate",
    "snap_dynamics",
    "fit_speed_plane",
    "snap_speed",
    "snap_speed_run",
    "SpeedRun",
    "speed_plane",
    "Start",
    "Trajectory",
)

if _TYPE_CHECKING:
    from .dynamics import ACTUATOR_DAMPING as ACTUATOR_DAMPING
    from .dynamics import ACTUATOR_VISCOSITY as ACTUATOR_VISCOSITY
    from .dynamics import Actuation as Actuation
    from .dynamics import actuate as actuate
    from .dynamics import Ball as Ball
    from .dynamics import Bodies as Bodies
    from .dynamics import damping_from_ringdown as damping_from_ringdown
    from .dynamics import Floor as Floor
    from .dynamics import hold_and_move as hold_and_move
    from .dynamics import Program as Program
    from .dynamics import Table as Table
    from .dynamics import brink as brink
    from .dynamics import Brink as Brink
    from .dynamics import Asymmetric as Asymmetric
    from .dynamics import Ramp as Ramp
    from .dynamics import Dissipation as Dissipation
    from .dynamics import Protocol as Protocol
    from .dynamics import HHT as HHT
    from .dynamics import Rattle as Rattle
    from .dynamics import ramp as ramp
    from .dynamics import simulate as simulate
    from .dynamics import snap_dynamics as snap_dynamics
    from .dynamics import fit_speed_plane as fit_speed_plane
    from .dynamics import snap_speed as snap_speed
    from .dynamics import snap_speed_run as snap_speed_run
    from .dynamics import SpeedRun as SpeedRun
    from .dynamics import speed_plane as speed_plane
    from .dynamics import Start as Start
    from .dynamics import Trajectory as Trajectory

# sweeps: batches across devices, processes and hosts
from .sweeps import grid as grid
from .sweeps import ShardedMap as ShardedMap
from .sweeps import sweep as sweep

# plot: figures
from .plot import plot_equilibria as plot_equilibria
from .plot import plot_hysteresis as plot_hysteresis
from .plot import plot_imperfection_sensitivity as plot_imperfection_sensitivity
from .plot import plot_phase_diagram as plot_phase_diagram
from .plot import plot_shape as plot_shape


try:
    __version__ = importlib.metadata.version("jaxrod")
except importlib.metadata.PackageNotFoundError:  # running from a source tree
    __version__ = "0.0.0"


def __getattr__(name):
    """The dynamics' public names (`_DYNAMICS`), imported from `jaxrod.dynamics` on first use."""
    if name in _DYNAMICS:
        value = getattr(importlib.import_module(".dynamics", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_DYNAMICS))
