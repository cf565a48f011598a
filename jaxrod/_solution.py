"""Result codes and the equilibrium solution Module."""

from __future__ import annotations

import equinox as eqx
from jaxtyping import Array

from ._rod import Scene


class RESULTS(eqx.Enumeration):
    """Outcome of a solve. Anything but `successful` means the state is not to be trusted."""

    successful = ""
    max_steps_reached = "Newton did not converge within max_steps."
    nonfinite = "The iteration produced a non-finite value (bad parameter or overflow)."
    line_search_failed = "The line search found no decrease of the merit function (diverged)."
    converged_to_saddle = "Newton converged to an equilibrium that is not a local minimum."
    state_not_found = "The requested state (up/down) does not exist here as a stable equilibrium."
    continuation_incomplete = (
        "The continuation ended before a loss of stability or the parameter bound (buffer full, step below "
        "ds_min, or more supercritical stages than allowed): whether the path snaps is unknown; raise "
        "Continuation(max_points=...) or lower ds_min."
    )
    landing_failed = (
        "The strip loses stability at alpha_c, but relaxing it past alpha_c found no equilibrium: the state "
        "it lands in is unknown."
    )


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
