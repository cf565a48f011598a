"""The strip's Lagrangian, stencil by stencil.

`geometry` (the mesh's segment lengths and the crease's natural tangent angle),
`bending` (the discrete bending energy), `lagrangian` (the condensed Lagrangian with the
end condition and its Hessian blocks) and `contact` (the strip's clearance to itself). These
are public modules: the layers above import them by name.

Layer: above model; below linalg and statics.
"""

from . import bending as bending
from . import contact as contact
from . import geometry as geometry
from . import lagrangian as lagrangian
from .contact import clearance as clearance
from .contact import self_intersects as self_intersects
from .geometry import discretize as discretize
