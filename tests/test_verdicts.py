"""Snap paths say what they are: a fold is a snap however small its jump, a substituted or
missing start state is named, a state through itself is flagged, a failed refinement says
its alpha_c has no derivative, and the extrapolated paths carry the codes of both meshes.

All paths run at N = 100 (one compiled `snap_angles`, shared by every scene here)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from helpers import crosses
from jaxrod.branches._snap import KIND_FOLD, _polish
from jaxrod.branches._continuation import SymmetricAlpha

N = 100
OK = jr.RESULTS.successful


def _snap(psi0, gap, **kw):
    return jr.snap_angles(jr.make_scene(psi0_deg=psi0, gap=gap, n=N), **kw)


@pytest.fixture(scope="module")
def cusp_60():
    """The cusp of the snap-down fold pair at Psi0 = 60 deg, solved on its own extended
    system (`jr.cusp_point`) from the fold at G/L = 0.76: the gap where that path stops
    snapping, computed independently of the snap criterion."""
    sc = jr.make_scene(psi0_deg=60, gap=0.76, n=N)
    p = jr.snap_angles(sc).down
    assert int(p.kind) == KIND_FOLD and p.result == OK
    cp = jr.cusp_point(sc, p.theta_before, p.force_before, p.alpha_c, p.mode)
    assert cp.result == OK
    return float(cp.gap)


def test_fold_with_a_small_jump_is_a_snap(cusp_60):
    """Between the old jump criterion's end (G/L = 0.76115) and the cusp the down path
    loses stability at a fold and lands less than 0.1 rad away: that is a snap."""
    g = 0.7618
    assert g < cusp_60
    p = _snap(60, g).down
    assert bool(p.snaps) and int(p.kind) == KIND_FOLD and p.result == OK
    assert 0 < float(p.jump) < 0.1, float(p.jump)
    assert np.isfinite(float(p.alpha_c)) and -62 < np.degrees(float(p.alpha_c)) < -57
    # the landed state is a different, stable equilibrium past alpha_c
    sc = jr.make_scene(psi0_deg=60, gap=g, n=N, alpha_deg=float(np.degrees(p.alpha_c)) - 0.06)
    eq = jr.solve_equilibrium(sc, p.theta_after, p.force_after)
    assert eq.result == OK and int(eq.num_unstable) == 0
    assert float(jnp.max(jnp.abs(eq.theta - p.theta_after))) < 1e-3


@pytest.mark.slow  # 23 s on 2 cores; CI: the fold just below the cusp snaps (above) and the cusp ends the path in termination_gap (test_termination.py)
def test_snapping_ends_at_the_cusp(cusp_60):
    """The down path snaps below the cusp and not far above it. Within ~1e-3 in G/L of the
    cusp the S the branch makes can be shorter than a continuation step: there a path that
    reaches the bound without losing stability but whose tangent all but turned in alpha
    (|tau_lam| < NEAR_FOLD at a computed point) is `fold_unresolved`, never a successful
    "no snap": just below the cusp (where the fold pair exists and is stepped over at the
    default step) and just above it (where it does not). A smaller `ds_max` resolves the
    fold pair just below the cusp; `termination_gap` reports the cusp itself."""
    from jaxrod.branches._snap import NEAR_FOLD

    below = _snap(60, cusp_60 - 8e-4).down
    assert bool(below.snaps) and below.result == OK and int(below.kind) == KIND_FOLD
    for g in (cusp_60 - 1.5e-4, cusp_60 + 3e-4):
        p = _snap(60, g).down
        assert not bool(p.snaps) and p.result == jr.RESULTS.fold_unresolved, (g, jr.RESULTS[p.result])
        br = jax.tree.map(lambda x: x[0], p.branch)
        assert 0 < np.min(np.abs(np.asarray(br.tau_lam)[1:int(br.count)])) < NEAR_FOLD
    far = _snap(60, cusp_60 + 1e-2).down
    assert not bool(far.snaps) and far.result == OK
    assert np.isnan(float(far.alpha_c)) and np.isnan(float(far.jump))
    # the fold pair just below the cusp, resolved with shorter steps
    fine = _snap(60, cusp_60 - 1.5e-4, settings=jr.Continuation(ds=0.01, ds_max=0.01, max_points=1000)).down
    assert bool(fine.snaps) and int(fine.kind) == KIND_FOLD and fine.result == OK, jr.RESULTS[fine.result]


def test_substituted_start_is_named():
    """At Psi0 = 30 deg, G/L = 0.8 the down state does not exist at alpha = 0: the up
    path's start is the snap-down path's end, and says so."""
    r = _snap(30, 0.8)
    down_state = jr.initial_state(jr.make_scene(psi0_deg=30, gap=0.8, n=N), "down")
    assert down_state.result == jr.RESULTS.state_not_found
    assert r.up.start_result == jr.RESULTS.start_substituted
    assert r.down.start_result == OK  # the up state exists
    # where both states exist nothing is substituted
    r2 = _snap(30, 0.5)
    assert r2.up.start_result == OK and r2.down.start_result == OK


def test_states_through_themselves_are_flagged():
    """At G/L = 0.1 the critical states of both paths pass through themselves (checked
    here by an independent crossing test); their paths carry `self_intersecting`, and a
    path of a moderate gap does not."""
    r = _snap(30, 0.1)
    h = np.full(N, 1.0 / N)
    for p in (r.up, r.down):
        assert crosses(p.theta_before, h)
        assert p.result == jr.RESULTS.self_intersecting
    r2 = _snap(60, 0.5)
    for p in (r2.up, r2.down):
        assert not crosses(p.theta_before, h) and p.result == OK
        assert float(jr.clearance(p.theta_before, jr.make_scene(n=N))) > 0


def test_path_through_itself_before_its_snap_is_flagged():
    """At Psi0 = 30 deg, G/L = 0.34 the down path's critical and landed states are clear of
    themselves, but the strip passes through itself on the way there: the path is
    `self_intersecting`, and `branch.crossing` marks exactly the computed points that an
    independent crossing test finds."""
    p = _snap(30, 0.34, continue_after_snap=True).down
    h = np.full(N, 1.0 / N)
    assert bool(p.snaps)
    assert not crosses(p.theta_before, h) and not crosses(p.theta_after, h)
    count = int(p.branch.count[0])
    ref = [crosses(p.branch.theta[0, k], h) for k in range(count)]
    assert any(ref) and not all(ref)
    assert np.asarray(p.branch.crossing[0, :count]).tolist() == ref
    assert not np.any(np.asarray(p.branch.crossing[0, count:]))
    assert p.result == jr.RESULTS.self_intersecting
    # the landed branch after the snap (with `continue_after_snap`) is checked point by point too
    count1 = int(p.branch.count[1])
    assert count1 > 1
    ref1 = [crosses(p.branch.theta[1, k], h) for k in range(count1)]
    assert np.asarray(p.branch.crossing[1, :count1]).tolist() == ref1


def test_failed_refinement_says_no_derivative():
    """Where the located critical point does not solve the extended system to tolerance
    (here: alpha_c moved 1e-4 rad away from the located one), alpha_c stays as given and
    the path reads `derivative_unavailable`, not success."""
    sc = jr.make_scene(psi0_deg=60, gap=0.5, n=N)
    raw = jr.snap_angles(sc, polish=False).up
    assert raw.result == OK and bool(raw.snaps)
    good = _polish(sc, raw, SymmetricAlpha())
    assert good.result == OK and good.refine_result == OK
    moved = eqx.tree_at(lambda p: p.alpha_c, raw, raw.alpha_c + 1e-4)
    bad = _polish(sc, moved, SymmetricAlpha())
    assert bad.result == jr.RESULTS.derivative_unavailable
    assert float(bad.alpha_c) == float(moved.alpha_c)


@pytest.mark.slow  # 16 s on 2 cores; CI checks the combined codes of failed landings and substituted starts (test_extrapolate.py)
def test_extrapolated_paths_carry_both_meshes_codes():
    """A continuation cut short on either mesh is not a clean 'does not snap': the combined
    path takes the code of the mesh that failed (the fine mesh's where both did), and keeps
    both meshes' own codes. (The combination of two runs by `snap_angles_extrapolated` is
    checked end to end in test_extrapolate.py; the cut-short path here is test_snap.py's
    compiled program, N = 40 with a 3-point buffer.)"""
    from jaxrod.branches import extrapolate_path

    cut = jr.snap_angles(jr.make_scene(60.0, 0.5, 0.0, n=40), settings=jr.Continuation(max_points=3), polish=False)
    good = _snap(60.0, 0.5)
    incomplete = jr.RESULTS.continuation_incomplete
    for name in ("up", "down"):
        c, g = getattr(cut, name), getattr(good, name)
        assert c.result == incomplete and g.result == OK and bool(g.snaps) and not bool(c.snaps)
        for coarse, fine in ((c, c), (g, c), (c, g)):
            e = extrapolate_path(coarse, fine)
            assert e.result == incomplete
            assert e.result_coarse == coarse.result and e.result_fine == fine.result
        e = extrapolate_path(g, g)
        assert e.result == OK and bool(e.consistent)


@pytest.mark.parametrize("leaf", ["psi0", "gap"])
def test_nonfinite_parameter_is_named(leaf):
    """A NaN fold angle or gap (traced past the constructor's checks, as in a batch) gives
    `nonfinite` on both paths and their starts, never `state_not_found` or a 'no snap'."""
    sc = jr.make_scene(psi0_deg=60, gap=0.5, n=N)
    get = {"psi0": lambda s: s.strip.psi0, "gap": lambda s: s.clamps.gap}[leaf]
    sc = eqx.tree_at(get, sc, jnp.asarray(np.nan))
    r = jr.snap_angles(sc)
    for p in (r.up, r.down):
        assert p.result == jr.RESULTS.nonfinite and p.start_result == jr.RESULTS.nonfinite
        assert not bool(p.snaps)
    assert jr.initial_state(sc, "down").result == jr.RESULTS.nonfinite
