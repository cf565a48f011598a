"""Study (d), the programmable actuator (jaxrod/paper/_actuator.py): the left-only / right-only /
both program does what it says quasi-statically, re-checked independently at a finer mesh and
dynamically; the gradients it uses match central differences; impossible programs end in a
clear "not reached".

CI versions at N = 24 (checks at N = 48); the converged study is marked slow."""

import math

import numpy as np
import pytest

import jaxrod as jr
import jaxrod.paper as paper
from jaxrod.paper import _actuator as act


PSI0, GAP, BETA = 45.0, 0.5, -126.0  # BETA: close to the optimum of the held angle (-126.26 deg at N = 40)
N, N_CHECK = 24, 48
MARGIN = 3.0  # deg, program_waypoints' default


@pytest.fixture(scope="module")
def program():
    wp, info = act.program_waypoints(PSI0, GAP, BETA, n=N)
    assert wp is not None, info
    return wp, info


@pytest.fixture(scope="module")
def moves(program):
    wp, _ = program
    return act.run_program(jr.make_scene(PSI0, GAP, 0.0, n=N), wp)[1]


def test_half_state_letters():
    assert act.half_state([-0.1, 0.3, 0.2]) == "DU" and act.half_state([0.1, -0.3, -0.2]) == "UD"
    assert act.flipped("DD", "UD") == frozenset("L") and act.flipped("UD", "DU") == frozenset("LR")
    with pytest.raises(ValueError, match="divisible by 4"):
        act.quasi_static_move(jr.make_scene(PSI0, GAP, 0.0, n=30), None, None, (0, 0), (1, 0))


def test_critical_angles_mirror(program):
    """The right clamp's critical angle equals the left one's (mirror symmetry, computed
    independently); the one-sided snap comes before the symmetric one."""
    _, info = program
    assert abs(info["alpha_c_L_deg"] - info["alpha_c_R_deg"]) < 1e-6
    assert 0.0 < info["alpha_c_L_deg"] < info["alpha_c_sym_deg"]


def test_program_does_what_it_says(moves):
    """Step by step: left half only (DD -> UD), reset, right half only (DD -> DU), reset,
    both (DD -> UU), reset; each actuation by one snap of exactly its halves, no drift."""
    assert [act.move_ok(r, k) for k, r in enumerate(moves)] == [True] * 6, [(r.start, r.final) for r in moves]
    left, right, both = moves[0], moves[2], moves[4]
    assert left.snapped == frozenset("L") and right.snapped == frozenset("R") and both.snapped == frozenset("LR")
    # the held half stays below the clamp line, with a margin
    assert left.h_final[2] < -0.05 and right.h_final[0] < -0.05
    assert left.h_final[0] > 0.05 and right.h_final[2] > 0.05
    # the one-sided snaps happen at the critical angles the waypoints were built from
    assert len(left.events) == 1 and len(both.events) == 1


def test_failed_landing_ends_the_move(program, monkeypatch):
    """A snap whose landing finds no stable state (`landing_failed`) ends the move there, with
    letters "??" and not stable: before, the move went on from the NaN state, which read "DD"
    (the N = 48 re-check of the program: every step DD -> DD)."""
    import equinox as eqx
    from jaxrod.branches import _snap

    real = _snap._land

    def no_landing(*args):
        t, m, fa, eq = real(*args)
        return t, m, fa, eqx.tree_at(lambda e: e.result, eq, jr.RESULTS.max_steps_reached)

    monkeypatch.setattr(_snap, "_land", no_landing)
    segment = act._segment.__wrapped__
    monkeypatch.setattr(act, "_segment", eqx.filter_jit(lambda *a: segment(*a)))  # a fresh trace
    wp, _ = program
    sc = jr.make_scene(PSI0, GAP, 0.0, n=N)
    eq = jr.initial_state(act._at(sc, np.radians(wp[0])), "down")
    r = act.quasi_static_move(sc, eq.theta, eq.force, wp[0], wp[1])
    assert act.half_state([np.nan, 0.0, np.nan]) == "??"
    assert r.start == "DD" and r.final == "??" and not r.stable and not act.move_ok(r, 0)
    assert len(r.events) == 1 and r.events[0].before == "DD" and r.events[0].after == "??"


@pytest.mark.slow  # a second mesh compile; the converged study (slow) re-checks at N = 160 too
def test_program_rechecked_at_finer_mesh(program, moves):
    """An independent quasi-static run of the same waypoints on twice the segments: every step
    still does what it says; each actuation snap moves by less than the 3 deg margin the waypoints
    leave past it (measured: 0.1 deg one-sided, 1.6 deg symmetric, the O(1000 deg / N^2)
    discretization error of alpha_c at N = 24; the resets, whose waypoints lie ~100 deg past
    their snaps, move by ~3 deg and are not compared); the end states' half heights by < 0.01."""
    wp, _ = program
    _, fine = act.run_program(jr.make_scene(PSI0, GAP, 0.0, n=N_CHECK), wp)
    assert [act.move_ok(r, k) for k, r in enumerate(fine)] == [True] * 6, [(r.start, r.final) for r in fine]
    for k, (c, f) in enumerate(zip(moves, fine)):
        assert len(c.events) == len(f.events)
        if act.INTENDED[k][2] is not None:
            for ec, ef in zip(c.events, f.events):
                assert np.max(np.abs(np.subtract(ec.alpha_deg, ef.alpha_deg))) < MARGIN
        assert np.max(np.abs(np.subtract(c.h_final, f.h_final))) < 0.01


@pytest.mark.slow  # 66 s; CI checks the quasi-static program and the dynamics of each snap kind elsewhere
def test_dynamic_program_small_n(program, moves):
    """jr.simulate through the same waypoints (damped, clamps ramped at 1 rad/T): after each move
    the strip has settled in the intended state, on the quasi-static end state, and during the
    one-sided moves the held half never changed letter."""
    wp, _ = program
    dyn = act.simulate_program(jr.make_scene(PSI0, GAP, 0.0, n=N), wp, static_moves=moves)
    assert [act.dynamic_ok(d, k) for k, d in enumerate(dyn)] == [True] * 6, \
        [(d.start, d.final, sorted(d.flips), d.kinetic_end, d.distance_to_static) for d in dyn]
    assert dyn[0].h[:, 2].max() < 0 and dyn[2].h[:, 0].max() < 0  # the held half stayed put
    assert dyn[4].v_peak > dyn[0].v_peak  # the symmetric snap is the violent one


@pytest.mark.slow  # 44 s of compiling the FD pipeline; the converged study (slow) checks them too
def test_gradients_match_central_differences(program):
    """d alpha_c^L / d beta and d m1 / d beta (implicit: extended system + equilibrium) vs
    central differences of the whole pipeline (bisection, refinement, landing); the refined
    critical angle is the bisection one of the program's waypoints."""
    checks = act.gradient_checks(PSI0, GAP, BETA, n=N, h=1e-4)
    assert abs(math.degrees(checks[0].value) - program[1]["alpha_c_L_deg"]) < 1e-6
    assert [g.name for g in checks] == ["alpha_c1", "h_L(W1)", "h_R(W1)"]
    for g in checks:
        assert math.isfinite(g.grad) and abs(g.fd) > 1e-3, g
        assert g.rel_error < 1e-5, g


@pytest.mark.slow  # 27 s: the held-angle optimizer's own compile; its derivative is the gradient check's (slow too)
def test_optimized_held_angle():
    """Newton on h_L + h_R = 0 (the implicit derivative shared with the gradient check) from
    beta = -110 deg converges to the balanced landing, a local maximum of m1 = min(h_L, -h_R)
    that beats the start, inside the bounds."""
    beta, m1, hist, local = act.optimize_hold(PSI0, GAP, -110.0, n=N)
    assert -150.0 < beta < -60.0 and local
    assert abs(hist[-1][2]) < 1e-8 and len(hist) <= 8, hist
    assert m1 > hist[0][1] + 0.01, hist


def test_flat_held_clamp_is_not_a_selective_actuator():
    """With the other clamp held flat (beta = 0, the protocol of snap_dynamics(kind='asymmetric'))
    the one-sided snap flips both halves (DD -> UU): the study says "not reached" at step 1."""
    r = paper.actuator_study(PSI0, GAP, 0.0, optimize=False, dynamics=False, check_gradients=False, n=N,
                          n_check=N_CHECK)
    assert not r.reached
    assert r.outcome.startswith("not reached: N = 24 step 1 (left half only")
    assert r.moves[0].start == "DD" and r.moves[0].final == "UU" and r.moves[0].snapped == frozenset("LR")


def test_nothing_snaps_is_not_reached():
    """A tight fold at a large gap (Psi0 = 30 deg, G/L = 0.85) has no down state / no snap: the
    study stops with "not reached" instead of returning a program."""
    r = paper.actuator_study(30.0, 0.85, -90.0, optimize=False, dynamics=False, check_gradients=False, n=N,
                          n_check=N_CHECK)
    assert not r.reached and r.waypoints is None and r.outcome.startswith("not reached")


@pytest.mark.slow
def test_actuator_study_converged():
    """The full study at its defaults (held angle optimized at N = 40, check at N = 80, dynamics at
    N = 32) is reached; at N = 160 the same waypoints still do what they say."""
    r = paper.actuator_study()
    assert r.reached, r.summary()
    assert r.info["local_max"] and r.info["m1"] > 0.1
    assert all(g.rel_error < 1e-5 for g in r.gradients), r.gradients
    _, fine = act.run_program(jr.make_scene(r.psi0_deg, r.gap, 0.0, n=160), r.waypoints)
    assert [act.move_ok(m, k) for k, m in enumerate(fine)] == [True] * 6
    for c, f in zip(r.check, fine):
        assert np.max(np.abs(np.subtract(c.h_final, f.h_final))) < 0.003
