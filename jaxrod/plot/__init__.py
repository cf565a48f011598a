"""Figures: shapes, equilibria, hysteresis loops, phase diagrams, snaps and their animations.

Sits on top of the solver (it reads its results); nothing below imports it.
"""

from ._dynamics import animate_actuation as animate_actuation
from ._dynamics import animate_snap as animate_snap
from ._dynamics import plot_snap as plot_snap
from ._statics import phase_figure as phase_figure
from ._statics import plot_equilibria as plot_equilibria
from ._statics import plot_hysteresis as plot_hysteresis
from ._statics import plot_imperfection_sensitivity as plot_imperfection_sensitivity
from ._statics import plot_phase_diagram as plot_phase_diagram
from ._statics import plot_shape as plot_shape
