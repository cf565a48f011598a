"""jaxrod: differentiable statics and dynamics of creased, snapping elastic strips."""

import importlib.metadata
import os


# jaxlib's CPU LAPACK kernels (the dense solves of the critical-point refinement, eigvalsh)
# come from scipy's OpenBLAS, whose threads fight XLA's own: on a 2-core machine a 205 x 205
# solve took 30x longer with the default thread count. One thread unless the user chose
# (this has an effect only if scipy's OpenBLAS is not loaded yet).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# XLA:CPU can deadlock when a batched LAPACK kernel (a vmapped dense solve: jaxlib's
# ParallelBatchMap on the intra-op Eigen pool) runs inside a while loop that itself runs on
# that pool: with 2 cores the phase diagram (vmapped snap_angles) hung forever, every
# thread waiting (cf. PyAutoFit issues 1528/1530). A single-threaded Eigen pool avoids it
# and costs nothing measurable here (snap_angles at N = 100: 72 ms with, 76 ms without).
# XLA_FLAGS is read when the CPU backend starts, i.e. at the first computation.
if "xla_cpu_multi_thread_eigen" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " --xla_cpu_multi_thread_eigen=false").strip()

from ._continuation import AbstractParameter as AbstractParameter
from ._contact import clearance as clearance
from ._contact import self_intersects as self_intersects
from ._critical_curve import continue_critical as continue_critical
from ._critical_curve import CriticalCurve as CriticalCurve
from ._continuation import Branch as Branch
from ._continuation import continue_branch as continue_branch
from ._continuation import Continuation as Continuation
from ._continuation import Gap as Gap
from ._continuation import LeftAlpha as LeftAlpha
from ._continuation import RightAlpha as RightAlpha
from ._continuation import SymmetricAlpha as SymmetricAlpha
from ._energy.geometry import discretize as discretize
from ._energy.lagrangian import lagrangian as lagrangian
from ._equilibrium import Newton as Newton
from ._equilibrium import solve_equilibrium as solve_equilibrium
from ._initial import buckled_guess as buckled_guess
from ._initial import initial_state as initial_state
from ._kkt import BorderedTridiagonal as BorderedTridiagonal
from ._observables import arclength as arclength
from ._observables import bending_energy as bending_energy
from ._observables import compression as compression
from ._observables import curvature as curvature
from ._observables import energies as energies
from ._observables import fold_height as fold_height
from ._observables import node_positions as node_positions
from ._observables import strains as strains
from ._observables import tangent_angles as tangent_angles
from ._plot import plot_equilibria as plot_equilibria
from ._plot import plot_shape as plot_shape
from ._rod import Clamps as Clamps
from ._rod import Gravity as Gravity
from ._rod import make_scene as make_scene
from ._rod import Mesh as Mesh
from ._rod import Scene as Scene
from ._rod import Stretching as Stretching
from ._rod import Strip as Strip
from ._snap import KIND_NAMES as KIND_NAMES
from ._snap import snap_angles as snap_angles
from ._snap import SnapAngles as SnapAngles
from ._snap import SnapPath as SnapPath
from ._solution import Equilibrium as Equilibrium
from ._solution import RESULTS as RESULTS
from ._stability import dense_reduced_hessian as dense_reduced_hessian
from ._stability import hessian as hessian
from ._stability import Stability as Stability
from ._stability import stability as stability

from ._critical import critical_point as critical_point
from ._critical import CriticalPoint as CriticalPoint
from ._critical import cusp_point as cusp_point
from ._critical import CuspPoint as CuspPoint
from ._termination import termination_gap as termination_gap
from ._termination import TerminationGap as TerminationGap


try:
    __version__ = importlib.metadata.version("jaxrod")
except importlib.metadata.PackageNotFoundError:  # running from a source tree
    __version__ = "0.0.0"
from ._dynamics import Dissipation as Dissipation
from ._dynamics import Protocol as Protocol
from ._dynamics_scenes import brink as brink
from ._dynamics_scenes import ramp as ramp
from ._dynamics_scenes import snap_dynamics as snap_dynamics
from ._snap_speed import snap_speed as snap_speed
from ._dynamics_scenes import Start as Start
from ._dynamics_solve import simulate as simulate
from ._dynamics_solve import Trajectory as Trajectory
from ._hysteresis import BRANCH_NAMES as HYSTERESIS_BRANCHES
from ._hysteresis import hysteresis as hysteresis
from ._hysteresis import Hysteresis as Hysteresis
from ._phase import phase_diagram as phase_diagram
from ._plot import plot_hysteresis as plot_hysteresis
from ._plot import plot_phase_diagram as plot_phase_diagram
from ._extrapolate import ExtrapolatedPath as ExtrapolatedPath
from ._extrapolate import ExtrapolatedSnapAngles as ExtrapolatedSnapAngles
from ._extrapolate import refined_scene as refined_scene
from ._extrapolate import snap_angles_extrapolated as snap_angles_extrapolated
