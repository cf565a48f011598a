"""The equilibrium solution Module."""

from __future__ import annotations

import equinox as eqx
from jaxtyping import Array

from ..model import Scene
from ..results import RESULTS


class Equilibrium(eqx.Module):
    r"""An equilibrium of a scene.

    **Fields:**
    - `theta`: segment tangent angles, shape (N,).
    - `force`: $\mu$, the force the right clamp exerts on the strip (the Lagrange
      multiplier of the end condition); compression is $\mu_x<0$, $P=-\mu_x$.
    - `result`: a [`jaxrod.RESULTS`][] code.
    - `num_steps`: Newton iterations taken.
    - `num_unstable`: number of negative eigenvalues of the constrained Hessian
      (asymmetric modes included); 0 means stable.
    - `scene`: the scene solved.
    """

    theta: Array
    force: Array
    result: RESULTS
    num_steps: Array
    num_unstable: Array
    scene: Scene

    @property
    def converged(self):
        return self.result == RESULTS.successful

    @property
    def stable(self):
        return self.num_unstable == 0
