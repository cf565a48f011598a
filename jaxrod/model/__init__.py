"""What the strip is: its material and creases (`Strip`, `Creases`), mesh (`Mesh`), clamps (`Clamps`),
optional stretching, gravity and self-contact (`Contact`), and the `Scene` that bundles them
(`make_scene`).

The bottom layer: it imports nothing else from jaxrod.
"""

from ._scene import Clamps as Clamps
from ._scene import Contact as Contact
from ._scene import Creases as Creases
from ._scene import crease_layout as crease_layout
from ._scene import layout_strip as layout_strip
from ._scene import parse_creases as parse_creases
from ._scene import CONTACT_STIFFNESS as CONTACT_STIFFNESS
from ._scene import CONTACT_THICKNESS as CONTACT_THICKNESS
from ._scene import Gravity as Gravity
from ._scene import make_scene as make_scene
from ._scene import Mesh as Mesh
from ._scene import Scene as Scene
from ._scene import Stretching as Stretching
from ._scene import Strip as Strip
