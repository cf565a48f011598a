"""Two-parameter continuation of critical points in (G, alpha):
`jaxrod.continue_critical` follows a fold (snap down) to the cusp where its gap turns and a
branch point (snap up) along the gap; its points are the critical points `snap_angles`
finds independently (continuation in alpha + bisection + extended-system polish) at the
same gaps, and its end is the cusp that `cusp_point` solves directly."""

from __future__ import annotations

import math

import jax
import numpy as np
import pytest

import jaxrod as jr
from jaxrod.branches._critical_curve import END_BOUND, END_TURN


jax.config.update("jax_enable_x64", True)

N = 40
PSI0 = 60.0


def _critical(sc, path):
    return jr.critical_point(sc, path.theta_before, path.force_before, path.alpha_c, path.mode, int(path.kind))


@pytest.fixture(scope="module")
def fold_curve():
    sc = jr.make_scene(PSI0, 0.70, n=N)
    p = jr.snap_angles(sc).down
    assert bool(p.snaps) and int(p.kind) == 1
    cp = _critical(sc, p)
    assert cp.result == jr.RESULTS.successful
    return sc, p, jr.continue_critical(sc, cp)


def test_fold_curve_ends_at_the_cusp(fold_curve):
    """Snap down at Psi0 = 60 deg from G/L = 0.70: the fold is followed toward larger gaps
    until G turns back (END_TURN); that turn is the cusp of the fold pair: the Hermite
    estimate agrees with the directly solved cusp to 1e-4 in G/L (the issue's tolerance),
    and the cusp solved from the curve's last point equals the one solved from the
    snap_angles fold at G/L = 0.70 to 1e-9."""
    sc, p, c = fold_curve
    assert int(c.end_reason) == END_TURN
    k = int(c.count)
    assert 3 <= k < 200
    g = np.asarray(c.gap[:k])
    assert np.all(np.diff(g) > 0)  # the gap grows up to the turn
    direct = jr.cusp_point(sc, p.theta_before, p.force_before, p.alpha_c, p.mode)
    assert direct.result == jr.RESULTS.successful and c.cusp.result == jr.RESULTS.successful
    gc = float(direct.gap)
    assert 0.70 < gc < 0.95
    assert abs(float(c.cusp.gap) - gc) < 1e-9
    assert abs(float(c.end_gap) - gc) < 1e-4
    assert abs(float(c.end_alpha) - float(direct.alpha)) < 1e-3
    assert g[-1] <= gc + 1e-12  # the last point is before the turn


def test_fold_curve_points_are_snap_angles_critical_points(fold_curve):
    """Points of the curve below the snap criterion's end are the alpha_c_down that
    snap_angles finds at the same gap (to 1e-8 rad) with the same fold height."""
    sc, _, c = fold_curve
    k = int(c.count)
    checked = 0
    for i in (1, k // 2):
        g = float(c.gap[i])
        p = jr.snap_angles(jr.make_scene(PSI0, g, n=N)).down
        if not bool(p.snaps):  # past the jump criterion's G* (the fold pair still exists)
            continue
        assert int(p.kind) == 1
        assert abs(float(p.alpha_c) - float(c.alpha[i])) < 1e-8, (g, float(p.alpha_c), float(c.alpha[i]))
        assert abs(float(p.fold_height_before) - float(c.fold_height[i])) < 1e-8
        checked += 1
    assert checked >= 1


def test_branch_point_curve_along_the_gap():
    """Snap up at Psi0 = 60 deg from G/L = 0.5 (a branch point), followed toward smaller
    gaps to the bound 0.42: the points are snap_angles' branch points at those gaps."""
    sc = jr.make_scene(PSI0, 0.5, n=N)
    p = jr.snap_angles(sc).up
    assert int(p.kind) == 2
    c = jr.continue_critical(sc, _critical(sc, p), direction=-1.0, gap_bounds=(0.42, 0.995))
    assert int(c.end_reason) == END_BOUND and int(c.kind) == 2
    k = int(c.count)
    g = np.asarray(c.gap[:k])
    assert np.all(np.diff(g) < 0) and g[-1] < 0.42
    i = k // 2
    q = jr.snap_angles(jr.make_scene(PSI0, float(c.gap[i]), n=N)).up
    assert int(q.kind) == 2 and abs(float(q.alpha_c) - float(c.alpha[i])) < 1e-8
    assert math.isnan(float(c.cusp.gap))


def test_needs_float64_and_kind():
    """Under float32 it refuses with the library's float64 message."""
    sc = jr.make_scene(PSI0, 0.7, n=N)
    p = jr.snap_angles(sc).down
    cp = _critical(sc, p)
    cp32 = jax.tree.map(lambda x: x.astype(np.float32) if hasattr(x, "dtype") and x.dtype == np.float64 else x, cp)
    with pytest.raises(ValueError, match="float64"):
        jr.continue_critical(sc, cp32)
