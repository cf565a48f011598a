"""The paper, figure by figure: Marzin et al., "Augmented snap-through instability of folded
strips", its results computed with jaxrod, and the design studies built on its strip.

| the paper | jaxrod |
|---|---|
| Fig. 1c: the folded strip snaps faster | `reproduce.section_folded_unfolded` |
| Figs. 2a-b: the quasi-static loops | `reproduce.section_loops` |
| Fig. 2c: the critical angles | `reproduce.section_master_curves`, `section_snap_angles`, `section_no_snap` |
| Figs. 3a-c: one snap in time | `reproduce.section_snap_dynamics` |
| Figs. 3d-e, Eq. 3: the speed plane | `reproduce.section_speed_plane`, `SPEED_PLANE`, `fit_plane`, `plot_plane` |
| Fig. 4: one clamp turned | `reproduce.section_asymmetric` |
| Fig. 4: launching one ball of three | `fig4_study`, `fig4_bodies`, `FIG4_*`; quasi-statically, `actuator_study` |

`reproduce.run` writes every section as one Markdown report with its figures
(`jaxrod reproduce --out DIR` on the command line).

The design studies ask the paper's questions backwards, each re-checked by an independent
forward solve on a finer mesh: (a) `snap_angle_study`, the strip with given critical angles;
(b) `fastest_snap_study`, the fastest snap above a smallest gap; (c) `snap_speed_study`, the
gap with a given snapping speed; (d) `actuator_study`, the clamp program that snaps the left
half, the right half, then both. Beyond the paper's single crease, `two_crease_study` and
`crease_position_study` place creases.

This package sits on top of `jaxrod` and `jaxrod.design` (the objectives, parametrizations
and `optimize` the studies use); `import jaxrod` does not import it. float64 must be enabled
by the caller.
"""

from . import reproduce as reproduce
from ._actuator import actuator_study as actuator_study
from ._actuator import ActuatorResult as ActuatorResult
from ._actuator import half_heights as half_heights
from ._actuator import half_state as half_state
from ._creases import crease_position_study as crease_position_study
from ._creases import PositionResult as PositionResult
from ._creases import two_crease_study as two_crease_study
from ._creases import TwoCreaseResult as TwoCreaseResult
from ._fig4 import FIG4_BALLS as FIG4_BALLS
from ._fig4 import fig4_bodies as fig4_bodies
from ._fig4 import FIG4_N as FIG4_N
from ._fig4 import FIG4_N_CHECK as FIG4_N_CHECK
from ._fig4 import fig4_objects_json as fig4_objects_json
from ._fig4 import FIG4_PEAKS as FIG4_PEAKS
from ._fig4 import FIG4_PROGRAMS as FIG4_PROGRAMS
from ._fig4 import FIG4_STARTS as FIG4_STARTS
from ._fig4 import fig4_study as fig4_study
from ._fig4 import FIG4_V_LAUNCH as FIG4_V_LAUNCH
from ._fig4 import FIG4_V_SPARE as FIG4_V_SPARE
from ._fig4 import Fig4Result as Fig4Result
from ._speed_plane import fit_plane as fit_plane
from ._speed_plane import plot_plane as plot_plane
from ._speed_plane import SPEED_PLANE as SPEED_PLANE
from ._studies import fastest_snap_study as fastest_snap_study
from ._studies import snap_angle_study as snap_angle_study
from ._studies import snap_speed_study as snap_speed_study
from ._studies import SpeedStudyResult as SpeedStudyResult
from ._studies import SpeedVerification as SpeedVerification
from ._studies import StudyResult as StudyResult
from ._studies import verify_snap_angles as verify_snap_angles
from ._studies import verify_snap_speed as verify_snap_speed
