"""The structure of the Hessian and linear solves that stay safe under `vmap`.

`kkt`: the bordered tridiagonal Hessian (assembly from Hessian-vector products, O(N) solves,
Sturm counts of the constrained stiffness, its lowest modes). `batched`: tridiagonal, dense
and eigen solves that neither deadlock nor serialize when batched on XLA:CPU.

Layer: above energy; below statics.
"""

from . import batched as batched
from . import kkt as kkt
from .kkt import BorderedDense as BorderedDense
from .kkt import BorderedTridiagonal as BorderedTridiagonal
