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
        "A reported state passes through itself (two segments that are not neighbours cross), so it is not "
        "physical: model self-contact (jaxrod.Contact; the CLI does so by default where a state needs it); "
        "see jaxrod.clearance."
    )
    derivative_unavailable = (
        "The located critical point does not solve its extended system to tolerance (or that system's "
        "Newton refinement did not converge), so alpha_c carries no derivative (a gradient through it "
        "would read zero); the value itself is the bisection's, within ~1e-8 rad."
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
    end_not_located = (
        "The exact end of the snapping path (the cusp of its fold pair, or the fold in G of its start state) "
        "was not solved: G* is the snap criterion's bisection value, which lies up to ~1e-3 in G/L below "
        "the end and has no derivative. Try another mesh n or a finer tol."
    )
    termination_beyond_grid = (
        "The path still snaps at the largest gap scanned: G* lies above it, and 1.0 is reported. Add gaps "
        "closer to 1 to the grid to locate it."
    )
    target_not_reached = (
        "The optimizer stopped (a stationary point, no descent direction, or max_iter) before every target "
        "was within its tolerance; the design's message names the terms off target: try more starts, more "
        "iterations or wider bounds."
    )
    infeasible_start = (
        "The objective is not finite at the start (the design there does not snap, or its state does not "
        "exist): start elsewhere."
    )
    fold_unresolved = (
        "The path reached the parameter bound without losing stability at any computed point, but its "
        "tangent all but turned in alpha on the way (|tau_lam| < jaxrod.branches.NEAR_FOLD): within ~1e-3 in "
        "G/L of a cusp a fold pair shorter than one continuation step can lie between two computed points, "
        "so whether the path snaps is unknown. Rerun with a smaller Continuation(ds_max), or use "
        "termination_gap, which solves the cusp."
    )
    object_penetrated = (
        "A body went through its contact layer (a gap to the strip, another body or the floor fell below "
        "zero): the impact is too fast for the contact law. Raise Bodies(stiffness=...) or thickness, or "
        "slow the program."
    )
    contact_underresolved = (
        "A reported state is in self-contact on a mesh whose segments are longer than "
        "jaxrod.energy.contact.CONTACT_RESOLUTION (2.5) contact thicknesses: the contact between such "
        "segments is resolved so coarsely that the answer moves by degrees (the snap angles of Psi0 = 180 deg, "
        "G/L = 0.1 with thickness 0.01 L: 81.8 and 74.9 deg at N = 24 and 32, 87.1 deg at N = 48 and 96). "
        "Refine the mesh: N above L / (2.5 thickness), 40 for the default thickness."
    )
    newton_failed = (
        "The implicit step's Newton iteration did not converge at the fixed step dt, and the run was "
        "stopped there: lower dt, or let jaxrod.HHT choose the step (dt=None)."
    )
    step_underflow = (
        "The implicit integrator's step fell below its minimum (1e-12 T): Newton did not converge or the "
        "error test failed at every step size tried. Raise HHT(tol=...) or newton_iters, or check the scene."
    )


def result_name(code) -> str:
    """The member name of a concrete `RESULTS` code (`"successful"`, `"nonfinite"`, ...)."""
    value = int(getattr(code, "_value", code))
    for name, item in RESULTS._name_to_item.items():
        if int(item._value) == value:
            return name
    return "unknown"


def result_from_name(name: str):
    """The `RESULTS` code of a member name (inverse of `result_name`)."""
    return getattr(RESULTS, name)
