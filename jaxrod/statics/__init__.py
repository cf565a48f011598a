"""One equilibrium and its stability.

Newton on the autodiff Hessian of the condensed Lagrangian (`solve_equilibrium`, `Newton`),
the stability of a state through the inertia of the bordered tridiagonal Hessian
(`stability`, `hessian`, `dense_reduced_hessian`), the up and down states at alpha = 0
(`initial_state`), and the observables of a state (fold height, energies, shapes).

Layer: above model, energy and linalg; below branches.
"""

from ._equilibrium import float_scene as float_scene
from ._equilibrium import Newton as Newton
from ._equilibrium import solve_equilibrium as solve_equilibrium
from ._equilibrium import solve_unflagged as solve_unflagged
from ._initial import buckled_guess as buckled_guess
from ._initial import initial_state as initial_state
from ._initial import initial_state_signed as initial_state_signed
from ._initial import still_tracked as still_tracked
from ._observables import arclength as arclength
from ._observables import bending_energy as bending_energy
from ._observables import compression as compression
from ._observables import curvature as curvature
from ._observables import energies as energies
from ._observables import crease_heights as crease_heights
from ._observables import crease_points as crease_points
from ._observables import fold_height as fold_height
from ._observables import node_positions as node_positions
from ._observables import strains as strains
from ._observables import tangent_angles as tangent_angles
from ._solution import Equilibrium as Equilibrium
from ._stability import dense_reduced_hessian as dense_reduced_hessian
from ._stability import hessian as hessian
from ._stability import mode_parity as mode_parity
from ._stability import Stability as Stability
from ._stability import stability as stability
