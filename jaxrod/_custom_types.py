"""jaxtyping aliases used in public signatures."""

from jaxtyping import Array, ArrayLike, Float, Int


Scalar = Float[Array, ""]
ScalarLike = float | Float[ArrayLike, ""]
Angles = Float[Array, "n"]  # one tangent angle per segment
Nodes = Float[Array, "n+1 2"]  # node positions
Force = Float[Array, "2"]

__all__ = ["Array", "ArrayLike", "Float", "Int", "Scalar", "ScalarLike", "Angles", "Nodes", "Force"]
