"""The one vocabulary of verdicts: `RESULTS`, the code every object jaxrod returns carries.

Each member's message says what happened and what the user can do; `successful` is the only
code under which a number is to be trusted. Codes are appended, never renumbered, so a stored
integer keeps its meaning.
"""

from __future__ import annotations

import equinox as eqx


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
    start_substituted = (
        "The path's own start state (the down state at alpha = 0 for snap up) does not exist here; the path "
        "started from the state the snap-down path reached (its landing state, or the end of its branch), the "
        "other half of the quasi-static hysteresis protocol. Its alpha_c is not that of a strip prepared in "
        "the named state."
    )
    self_intersecting = (
        "A reported state passes through itself (two segments that are not neighbours cross): the model has "
        "no contact, so the state is not physical; see jaxrod.clearance."
    )
    derivative_unavailable = (
        "The extended-system refinement of the critical point did not converge, so alpha_c is the bisection "
        "value, which carries no derivative (a gradient through it would read zero); the value itself is "
        "within ~1e-8 rad."
    )
    mesh_inconsistent = (
        "The two meshes of the extrapolation disagree (one snaps and the other does not, or the kind "
        "differs: near a termination gap, or where a fold and a branch point cross): nothing was "
        "extrapolated; alpha_c is the fine mesh's value and error the meshes' difference. Refine the mesh."
    )
    no_snap = (
        "The quasi-static path does not snap here, so there is no snap (no brink, no snap speed)."
    )
    snap_not_resolved = (
        "The run did not resolve the snap within t1 (the fold did not cross y = 0, the run did not reach "
        "the overshoot, or the speed peak lies at the end of the run): raise t1."
    )
    energy_drift = (
        "The undamped run's energy balance E_k + V - W left its start value by more than energy_tol (relative "
        "to the energy scale): the step no longer resolves the motion, and the run was stopped there. Use a "
        "smaller step (courant or dt) or an adaptive solver (solver='tsit5')."
    )
    constraint_drift = (
        "The right end drifted from the clamp (G, 0) by more than constraint_tol, and the run was stopped "
        "there: raise baumgarte or tighten rtol/atol (adaptive solvers), or use solver='rattle'."
    )
    constraint_solve_failed = (
        "RATTLE's constraint solve (the link lengths, SHAKE's Newton iteration) did not converge to its "
        "tolerance in a step, and the run was stopped there: the step is too large for the motion; lower "
        "courant or dt."
    )
    steps_exhausted = (
        "The time integration used up max_steps before t1 (or before the snap ended): raise max_steps."
    )
    integration_failed = (
        "The time integrator failed (diffrax's code is in Trajectory.solver_result): lower the step or "
        "change the solver."
    )
