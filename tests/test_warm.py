"""Warm-started snap paths (`jr.snap_angles(scene, near=neighbour)`, `jaxrod.branches._warm`).

A chain of scenes along the gap (Psi0 = 90 deg, N = 24), each started from the previous
one's answer, gives every path its cold call's answer: alpha_c to 1e-9 deg, the same kinds,
codes and landed states, most paths warm. Where the warm start must not be trusted it is not:
a neighbour whose path does not snap, a neighbour past the end of snapping, a critical point
reached the other way (the up path's point offered to the down direction: no stable state
just before it). Gradients through a warm path match central differences; under `vmap` a bad
member does not change the others."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from jaxrod.branches._continuation import SymmetricAlpha
from jaxrod.branches._warm import near_of, warm_critical

N = 24
GAPS = np.linspace(0.40, 0.70, 7)


def _scene(psi0, gap):
    return jr.make_scene(psi0, gap, n=N)


@pytest.fixture(scope="module")
def chain():
    """Cold and warm answers along the gap at Psi0 = 90 deg (the warm chain starts from the
    first cold answer)."""
    cold = [jr.snap_angles(_scene(90.0, float(g))) for g in GAPS]
    warm = [cold[0]]
    for g in GAPS[1:]:
        warm.append(jr.snap_angles(_scene(90.0, float(g)), near=warm[-1]))
    return cold, warm


def _same(c, w, tol_deg=1e-9):
    for name in ("up", "down"):
        pc, pw = getattr(c, name), getattr(w, name)
        assert pc.result == pw.result and pc.start_result == pw.start_result, name
        assert int(pc.kind) == int(pw.kind) and bool(pc.snaps) == bool(pw.snaps), name
        if bool(pc.snaps):
            assert abs(np.degrees(float(pc.alpha_c - pw.alpha_c))) < tol_deg, (name, float(pc.alpha_c),
                                                                               float(pw.alpha_c))
            np.testing.assert_allclose(pw.theta_after, pc.theta_after, atol=1e-6)
            np.testing.assert_allclose(pw.fold_height_before, pc.fold_height_before, atol=1e-9)
        else:
            assert np.isnan(float(pw.alpha_c))


def test_warm_chain_equals_cold_calls(chain):
    cold, warm = chain
    for c, w in zip(cold[1:], warm[1:]):
        _same(c, w)
    n_warm = sum(int(w.up.warm) + int(w.down.warm) for w in warm[1:])
    assert n_warm >= 2 * (len(GAPS) - 1) - 2, n_warm  # a kind may change once along the chain
    # a warm path walked no branch: its first stage holds its start state only
    w = warm[-1]
    if bool(w.up.warm):
        assert int(w.up.branch.count[0]) == 1
        assert not any(bool(c.up.warm) for c in cold)


def test_cold_paths_are_not_warm(chain):
    cold, _ = chain
    assert not any(bool(c.up.warm) or bool(c.down.warm) for c in cold)


def test_neighbour_that_does_not_snap_starts_nothing():
    """Psi0 = 30 deg: the down path stops snapping between G/L = 0.64 and 0.66 (N = 24 moves it
    a little; found here by the cold calls). A neighbour without a snap, and a neighbour that
    snaps offered to a scene past the end of snapping, both give the cold call's answer."""
    gaps = np.linspace(0.55, 0.80, 6)
    cold = [jr.snap_angles(_scene(30.0, float(g))) for g in gaps]
    snaps = [bool(c.down.snaps) for c in cold]
    assert snaps[0] and not snaps[-1], snaps
    k = snaps.index(False)
    # the last snapping neighbour offered to the first scene that does not snap
    w = jr.snap_angles(_scene(30.0, float(gaps[k])), near=cold[k - 1])
    _same(cold[k], w)
    assert not bool(w.down.warm)
    # a neighbour without a snap offered to the next scene
    if k + 1 < len(gaps):
        w = jr.snap_angles(_scene(30.0, float(gaps[k + 1])), near=cold[k])
        _same(cold[k + 1], w)
        assert not bool(w.down.warm)


def test_point_reached_the_other_way_is_rejected(chain):
    """The up path's critical point offered as the start of a path going down: there is no
    stable state just before it in that direction (a fold there is a maximum of alpha, a
    branch point's symmetric branch is unstable past it), so `stable_side` fails, as does
    `on_side`; offered in its own direction every check holds."""
    cold, _ = chain
    par = SymmetricAlpha()
    sc = par.set(_scene(90.0, float(GAPS[1])), 0.0)
    near = near_of(cold[1].up)
    _, accept, checks = warm_critical(sc, near, jnp.ones((), bool), 1.0, par, jnp.pi, 1e-9)
    assert bool(accept) and all(bool(v) for v in checks.values()), {k: bool(v) for k, v in checks.items()}
    # the same point, with the bound check passed by shifting the question to alpha < 0:
    # the direction alone decides `stable_side`
    _, accept, checks = warm_critical(sc, near, jnp.ones((), bool), -1.0, par, jnp.pi, 1e-9)
    assert not bool(accept)
    assert not bool(checks["stable_side"]) and not bool(checks["on_side"])
    assert bool(checks["edge"]) and bool(checks["equilibrium"])


@pytest.mark.slow  # 8-14 s (the derivative's program); CI checks snap-angle derivatives of cold paths, whose rule a warm path shares
def test_gradient_through_a_warm_path(chain):
    """d alpha_c / d Psi0 through a warm path (its polish's implicit derivative, the cold
    path's derivative rule at the same point) equals central differences of cold calls."""
    _, warm = chain
    near = warm[2]
    g0 = float(GAPS[3])

    def alpha(psi0, near):
        r = jr.snap_angles(_scene(psi0, g0), near=near)
        return r.up.alpha_c + r.down.alpha_c, (r.up.warm, r.down.warm)

    gw, flags = jax.grad(alpha, has_aux=True)(90.0, near)
    assert bool(flags[0]) and bool(flags[1])
    h = 1e-3
    fd = (alpha(90.0 + h, None)[0] - alpha(90.0 - h, None)[0]) / (2 * h)
    assert abs(float(gw) - float(fd)) <= 1e-5 * abs(float(fd)), (float(gw), float(fd))


@pytest.mark.slow  # 11-17 s (the vmapped program); CI checks a batch's isolation on cold paths (test_batch.py)
def test_batch_with_a_bad_member(chain):
    """`jax.vmap` over scenes and neighbours: a NaN member is flagged `nonfinite`, and the
    others equal their single warm calls."""
    _, warm = chain
    psis = jnp.array([90.0, jnp.nan, 90.0])
    gaps = jnp.array([GAPS[2], GAPS[2], GAPS[4]])
    nears = jax.tree.map(lambda a, b, c: jnp.stack([a, b, c]), warm[1], warm[1], warm[3])
    scenes = jax.vmap(lambda p, g: jr.make_scene(p, g, n=N))(psis, gaps)
    out = jax.jit(jax.vmap(lambda s, n: jr.snap_angles(s, near=n)))(scenes, nears)
    pick = lambda i: jax.tree.map(lambda x: x[i], out)  # noqa: E731
    assert pick(1).up.result == jr.RESULTS.nonfinite
    for i, (g, n) in ((0, (GAPS[2], warm[1])), (2, (GAPS[4], warm[3]))):
        single = jr.snap_angles(_scene(90.0, float(g)), near=n)
        _same(single, pick(i), tol_deg=1e-9)
        assert bool(pick(i).up.warm) == bool(single.up.warm)


def test_bad_neighbour_is_refused(chain):
    sc = _scene(90.0, 0.5)
    other = jr.SnapAngles(*(eqx.tree_at(lambda p: p.theta_before, p, jnp.zeros(N + 2)) for p in (chain[0][0].up,
                                                                                             chain[0][0].down)))
    with pytest.raises(ValueError, match="same mesh"):
        jr.snap_angles(sc, near=other)
    with pytest.raises(ValueError, match="near"):
        jr.snap_angles(sc, near="previous")
