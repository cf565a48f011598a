"""Motion: the strip's equations of motion, integrators, scenes and the snap speed.

Lagrange's equations of the discrete strip with its inextensible links (`simulate`, RATTLE
by default (`Rattle`), the implicit `HHT`, any diffrax solver), clamp programs (`Protocol`), dissipation (`Dissipation`),
the ready-made scenes (`snap_dynamics`: brink, ramp, asymmetric) and the snap speed of a
design (`snap_speed`) and its map over fold angles and gaps (`speed_plane`, run across
devices by `jaxrod.sweeps`), and the strip as an actuator: piecewise-linear clamp
programs (`Program`) through several snaps, balls it strikes on a table or a floor (`Ball`,
`Bodies`), the hits and the energy balance (`actuate`).

Layer: above branches (a brink starts from a snap angle); below design.
"""

from ._actuate import ACTUATOR_DAMPING as ACTUATOR_DAMPING
from ._actuate import ACTUATOR_VISCOSITY as ACTUATOR_VISCOSITY
from ._actuate import Actuation as Actuation
from ._actuate import actuate as actuate
from ._actuate import damping_from_ringdown as damping_from_ringdown
from ._bodies import Ball as Ball
from ._bodies import Bodies as Bodies
from ._bodies import Floor as Floor
from ._bodies import Table as Table
from ._equations import Dissipation as Dissipation
from ._equations import Protocol as Protocol
from ._implicit import HHT as HHT
from ._program import hold_and_move as hold_and_move
from ._program import Program as Program
from ._rattle import Rattle as Rattle
from ._scenes import Asymmetric as Asymmetric
from ._scenes import brink as brink
from ._scenes import Brink as Brink
from ._scenes import NUDGE as NUDGE
from ._scenes import nudge_start as nudge_start
from ._scenes import ramp as ramp
from ._scenes import Ramp as Ramp
from ._scenes import snap_dynamics as snap_dynamics
from ._scenes import Start as Start
from ._simulate import simulate as simulate
from ._simulate import Trajectory as Trajectory
from ._snap_speed import snap_speed as snap_speed
from ._snap_speed import snap_speed_run as snap_speed_run
from ._snap_speed import SpeedRun as SpeedRun
from ._speed_plane import fit_speed_plane as fit_speed_plane
from ._speed_plane import speed_plane as speed_plane
from ._simulate import SOLVERS as SOLVERS
