"""Self-contact check (`jaxrod.energy.contact`): segment distances against hand-built answers and
a brute-force reference, real strip states with and without self-crossing, vmap and gradients."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from jaxrod.energy import contact as _contact
from helpers import central_difference, np_crossings


segment_distances = jax.jit(_contact.segment_distances)
pair_batch = jax.jit(jax.vmap(_contact.segment_distances))
clearance = jax.jit(_contact.clearance)
self_intersects = jax.jit(_contact.self_intersects)
clearance_batch = jax.jit(jax.vmap(_contact.clearance, in_axes=(0, None)))
intersects_batch = jax.jit(jax.vmap(_contact.self_intersects, in_axes=(0, None)))
clearance10 = jax.jit(functools.partial(_contact.clearance, min_separation=10))


def chain(a, b, c, d):
    """Nodes of a 3-segment chain whose only non-neighbouring pair is [a, b], [c, d]."""
    return jnp.array([a, b, c, d], jnp.float64)


# ---------------------------------------------------------------- plain numpy references

def np_nodes(theta, h):
    e = h[:, None] * np.stack([np.cos(theta), np.sin(theta)], -1)
    return np.vstack([np.zeros((1, 2)), np.cumsum(e, 0)])


def np_grid_distance(a, b, c, d, m=301):
    """Smallest distance between m points on each segment, and a bound on how much it
    exceeds the true distance (|p(s) - q(t)| is convex in (s, t): half a grid diagonal)."""
    s = np.linspace(0.0, 1.0, m)[:, None]
    p = a + s * (b - a)
    q = c + s * (d - c)
    dist = np.sqrt(((p[:, None, :] - q[None, :, :]) ** 2).sum(-1)).min()
    bound = 0.5 * np.hypot(np.linalg.norm(b - a), np.linalg.norm(d - c)) / (m - 1)
    return dist, bound


# ---------------------------------------------------------------- hand-built segments

CASES = {  # (a, b, c, d): (distance, meet)
    "parallel": (((0, 0), (1, 0), (0, 0.3), (1, 0.3)), (0.3, False)),
    "parallel_offset": (((0, 0), (1, 0), (2, 0.3), (3, 0.3)), (np.hypot(1, 0.3), False)),
    "x_cross": (((0, 0), (1, 1), (0, 1), (1, 0)), (0.0, True)),
    "t_touch": (((0, 0), (2, 0), (0.7, 0), (0.7, 1)), (0.0, True)),
    "t_near": (((0, 0), (2, 0), (0.7, 1e-6), (0.7, 1)), (1e-6, False)),
    "end_to_end": (((0, 0), (1, 0), (1, 0), (1, 1)), (0.0, True)),
    "collinear_overlap": (((0, 0), (2, 0), (1, 0), (3, 0)), (0.0, True)),
    "collinear_inside": (((0, 0), (4, 0), (3, 0), (1, 0)), (0.0, True)),
    "collinear_apart": (((0, 0), (1, 2), (2, 4), (3, 6)), (np.sqrt(5), False)),
    "nearly_parallel": (((0, 0), (1, 0), (0, 1e-3), (1, 2e-3)), (1e-3, False)),
    "nearly_parallel_cross": (((0, 0), (1, 0), (0, 1e-9), (1, -1e-9)), (0.0, True)),
    "point_segment": (((0.5, 1), (0.5, 1), (0, 0), (1, 0)), (1.0, False)),
}


@pytest.mark.parametrize("name", list(CASES))
def test_hand_built(name):
    (a, b, c, d), (want, meet) = CASES[name]
    dist, crosses = segment_distances(chain(a, b, c, d))
    assert float(dist) == pytest.approx(want, rel=1e-12, abs=1e-15)
    assert bool(crosses) is meet
    if meet:
        assert float(dist) == 0.0  # exactly, whatever the rounding of the distances
    # the pair is symmetric: swapping the segments or their directions changes nothing
    for x in (chain(c, d, a, b), chain(b, a, d, c)):
        d2, c2 = segment_distances(x)
        assert float(d2) == pytest.approx(want, rel=1e-12, abs=1e-15) and bool(c2) is meet


def test_slanted_touch_within_tolerance():
    # an end on the other segment, decided by rounding: within the default tolerance
    a, b = np.array([0.0, 0.0]), np.array([0.7, 0.3])
    c = 0.37 * b
    dist, _ = segment_distances(chain(a, b, c, c + np.array([-0.2, 0.5])))
    assert float(dist) <= _contact.TOL


def test_neighbours_excluded():
    # a chain that folds back on itself at once: segments 0 and 1 share a node (excluded),
    # 0 and 2 cross
    x = jnp.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.5], [0.5, -0.5]])
    dist, crosses = segment_distances(x)
    assert float(dist) == 0.0 and bool(crosses)
    dist, crosses = segment_distances(x[:3])  # two segments: no non-neighbouring pair
    assert float(dist) == np.inf and not bool(crosses)


def test_random_against_brute_force():
    rng = np.random.default_rng(0)
    pts = rng.uniform(-1.0, 1.0, (200, 4, 2))
    pts[:50, 2:] = pts[:50, :2] + 0.05 * rng.normal(size=(50, 2, 2))  # nearly coincident
    pts[50:100, 2:] = pts[50:100, :2] + np.array([0.3, 0.1]) * rng.uniform(size=(50, 1, 1))  # parallel
    dist, crosses = map(np.asarray, pair_batch(jnp.asarray(pts)))
    n_meet = 0
    for k, (a, b, c, d) in enumerate(pts):
        ref, bound = np_grid_distance(a, b, c, d)
        assert ref - bound - 1e-12 <= dist[k] <= ref + 1e-12, k
        meet = bool(np_crossings(np.array([a, b, c, d])))
        assert crosses[k] == meet and (dist[k] == 0.0) == meet, k
        n_meet += meet
    assert 20 < n_meet < 180  # both kinds were tested


def test_segment_distance_gradient():
    rng = np.random.default_rng(1)
    f = jax.jit(lambda x: _contact.segment_distances(x.reshape(4, 2))[0])
    g = jax.jit(jax.grad(f))
    n_tested = 0
    for x in rng.uniform(-1.0, 1.0, (12, 8)):
        if float(f(jnp.asarray(x))) < 1e-2:
            continue
        fd = central_difference(lambda y: f(y)[None], x)[0]
        np.testing.assert_allclose(g(jnp.asarray(x)), fd, rtol=1e-6, atol=1e-8)
        n_tested += 1
    assert n_tested >= 3
    # crossing and touching pairs: distance 0, gradient finite (zero)
    for name in ("x_cross", "end_to_end", "collinear_overlap", "point_segment"):
        assert np.all(np.isfinite(g(chain(*CASES[name][0]).reshape(-1)))), name


# ---------------------------------------------------------------- real strip states

@pytest.fixture(scope="module")
def up_state():
    eq = jr.initial_state(jr.make_scene(psi0_deg=60, gap=0.5, n=60), "up")
    assert eq.result == jr.RESULTS.successful
    return eq


@pytest.fixture(scope="module")
def critical_states():
    """The critical states at Psi0 = 30 deg, G/L = 0.1, which pass through themselves."""
    scene = jr.make_scene(psi0_deg=30, gap=0.1, n=60)
    sa = jr.snap_angles(scene, polish=False, continue_after_snap=False)
    assert bool(sa.up.snaps) and bool(sa.down.snaps)
    return scene, (sa.up.theta_before, sa.down.theta_before)


def test_up_state_is_clear(up_state):
    eq = up_state
    c = float(clearance(eq.theta, eq.scene))
    h = np.asarray(jr.discretize(eq.scene).h)
    # segments two apart are one segment apart: the clearance of a smooth shape is h
    assert 0.5 * h.min() < c <= h[1:-1].min() * (1 + 1e-12)
    assert not bool(self_intersects(eq.theta, eq.scene))
    x = np.asarray(jr.node_positions(eq))
    np.testing.assert_allclose(_contact._nodes(eq.theta, eq.scene, None), x, atol=1e-14)
    with_force = jax.jit(lambda t, f, sc: _contact.clearance(t, sc, force=f))
    assert float(with_force(eq.theta, eq.force, eq.scene)) == pytest.approx(c, abs=1e-14)
    assert np_crossings(x) == []
    # the parts of the strip ten segments apart stay well apart (across the crease)
    c10 = float(clearance10(eq.theta, eq.scene))
    assert 0.05 < c10 < 0.2


def test_critical_states_cross(critical_states):
    scene, thetas = critical_states
    h = np.asarray(jr.discretize(scene).h)
    for theta in thetas:
        assert bool(self_intersects(theta, scene))
        assert float(clearance(theta, scene)) == 0.0
        x = np.asarray(_contact._nodes(theta, scene, None))
        np.testing.assert_allclose(x[-1], [0.1, 0.0], atol=1e-10)  # the clamped end
        np.testing.assert_allclose(x, np_nodes(np.asarray(theta), h), atol=1e-14)
        ref = np_crossings(x)
        assert ref, "the numpy check finds no crossing"
        i, j, _, crosses = _contact.pair_distances(jnp.asarray(x))
        assert sorted(zip(i[np.asarray(crosses)].tolist(), j[np.asarray(crosses)].tolist())) == ref


# ---------------------------------------------------------------- vmap, NaN, gradients

def test_vmap_matches_loop(up_state, critical_states):
    scene = up_state.scene  # same mesh as the critical states (n = 60): same node positions
    rng = np.random.default_rng(2)
    thetas = jnp.stack([up_state.theta, up_state.theta + 0.05 * rng.normal(size=60), *critical_states[1]])
    c, s = clearance_batch(thetas, scene), intersects_batch(thetas, scene)
    for k, th in enumerate(thetas):
        assert float(c[k]) == float(clearance(th, scene))
        assert bool(s[k]) == bool(self_intersects(th, scene))
    assert not bool(s[0]) and bool(s[2]) and bool(s[3])
    # a NaN member: NaN clearance, not flagged, the others unchanged
    bad = thetas.at[1, 7].set(jnp.nan)
    c2, s2 = clearance_batch(bad, scene), intersects_batch(bad, scene)
    assert np.isnan(float(c2[1])) and not bool(s2[1])
    keep = np.array([0, 2, 3])
    np.testing.assert_array_equal(c2[keep], c[keep])
    np.testing.assert_array_equal(s2[keep], s[keep])


def test_clearance_gradient(up_state, critical_states):
    eq = up_state
    # the up state is mirror-symmetric, so its closest pairs come in mirror pairs: a
    # perturbation makes the closest pair unique (a min is not differentiable at a tie)
    theta = eq.theta + 1e-3 * np.random.default_rng(3).normal(size=60)
    def f(t):
        return clearance10(t, eq.scene)

    g = jax.jit(jax.grad(f))(theta)
    fd = central_difference(lambda t: f(t)[None], theta)[0]
    assert float(jnp.max(jnp.abs(g))) > 1e-2  # a genuine dependence on the shape
    np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-9)
    # finite everywhere: default neighbours, crossing states, a NaN-free zero clearance
    grad = jax.jit(jax.grad(_contact.clearance))
    assert np.all(np.isfinite(grad(eq.theta, eq.scene)))
    for theta in critical_states[1]:
        assert np.all(np.isfinite(grad(theta, critical_states[0])))


# ---------------------------------------------------------------- branches through themselves

def test_branch_points_through_themselves_are_flagged():
    """`continue_branch` checks every point: from the down state at Psi0 = 30 deg, G/L = 0.2
    (which is clear), alpha increasing to 2.5 rad, the branch turns at folds and comes back
    through states that cross themselves. `Branch.crossing` equals the numpy crossing check
    point by point (some points cross, the first ones do not); the branch fills its buffer,
    so it is `continuation_incomplete`, and had it ended at the bound it would be
    `self_intersecting`. At G/L = 0.5 up to 1 rad the branch is clear and `successful`."""
    import equinox as eqx

    settings = jr.Continuation(max_points=120)
    for gap, bound in ((0.2, 2.5), (0.5, 1.0)):
        scene = jr.make_scene(psi0_deg=30, gap=gap, n=60)
        down = jr.initial_state(scene, "down")
        assert down.result == jr.RESULTS.successful
        br = jr.continue_branch(scene, down, direction=1.0, bounds=(-bound, bound), settings=settings)
        h = np.asarray(jr.discretize(scene).h)
        count = int(br.count)
        ref = [bool(np_crossings(np_nodes(np.asarray(br.theta[k]), h))) for k in range(count)]
        assert np.asarray(br.crossing)[:count].tolist() == ref
        assert not np.any(np.asarray(br.crossing)[count:])
        if gap == 0.2:
            assert not ref[0] and 0 < sum(ref) < count and int(br.stop) == 0
            assert br.result == jr.RESULTS.continuation_incomplete
            assert eqx.tree_at(lambda b: b.stop, br, jnp.asarray(1, jnp.int32)).result == jr.RESULTS.self_intersecting
        else:
            assert not any(ref) and int(br.stop) == 1 and br.result == jr.RESULTS.successful


# ---------------------------------------------------------------- the O(N) screen

def _full_check(theta, scene, tol):
    c, crosses = _contact.segment_distances(_contact._nodes(theta, scene, None))
    return crosses | (c <= tol)


full_batch = jax.jit(jax.vmap(_full_check, in_axes=(0, None, None)))
intersects_tol_batch = jax.jit(jax.vmap(_contact.self_intersects, in_axes=(0, None, None)))


@pytest.mark.parametrize("tol", [1e-9, 3e-3])
def test_screen_never_changes_the_answer(tol):
    """`self_intersects` (screen first, pair check only where the screen fails) equals the
    pair check alone on 600 shapes: smooth ones whose angle range straddles pi (the screen's
    limit), random walks that cross, and shapes whose smallest projection is near `tol`."""
    n = 40
    scene = jr.make_scene(n=n)
    rng = np.random.default_rng(7)
    s = np.linspace(0, 1, n)
    smooth = [a * np.sin(np.pi * k * s + ph) for a, k, ph in
              zip(rng.uniform(0.5, 2.5, 300), rng.integers(1, 4, 300), rng.uniform(0, 2 * np.pi, 300))]
    walks = [np.cumsum(rng.normal(0, 0.6, n)) for _ in range(200)]
    # monotone shapes with one segment almost perpendicular to the mid direction: its
    # projection h sin(eps) sits just above or below tol
    near = []
    for eps in np.geomspace(1e-4, 1e-1, 100):
        th = np.zeros(n)
        th[n // 2] = np.pi / 2 - eps
        th[: n // 2] = -np.pi / 2 + eps
        near.append(th)
    # hairpins: up, a half turn over two segments, down beside the first arm, the arms a
    # gap g apart with g from 0.1 tol to 10 tol (the bounding-box screen's limit)
    h = 1.0 / n
    hairpin = []
    for g in tol * np.geomspace(0.1, 10.0, 60):
        th = np.full(n, np.pi / 2)
        phi = np.arccos(np.clip(g / (2 * h), 0.0, 1.0))  # two segments turn by pi, g across
        th[n // 2] = phi
        th[n // 2 + 1] = -phi
        th[n // 2 + 2:] = -np.pi / 2
        hairpin.append(th)
    thetas = jnp.asarray(np.array(smooth + walks + near + hairpin))
    got = np.asarray(intersects_tol_batch(thetas, scene, tol))
    ref = np.asarray(full_batch(thetas, scene, tol))
    np.testing.assert_array_equal(got, ref)
    one = jax.jit(_contact.self_intersects)
    for k in range(0, len(thetas), 37):  # unbatched, where the screen decides alone
        assert bool(one(thetas[k], scene, tol)) == bool(ref[k])
    assert 20 < ref.sum() < len(ref) - 20  # both answers occur
    # and the screen alone decides a good part of them
    screened = jax.vmap(lambda t: _contact._screen(_contact._nodes(t, scene, None), t, tol))(thetas)
    assert int(np.sum(screened)) > 100 and not np.any(np.asarray(screened) & ref)
    # the bounding-box screen never passes a shape with a pair within tol, and decides shapes
    # the monotone screen cannot (angle range above pi)
    boxed = np.asarray(jax.vmap(lambda t: _contact._boxes_apart(_contact._nodes(t, scene, None), tol, 2))(thetas))
    assert not np.any(boxed & ref)
    assert int(np.sum(boxed & ~np.asarray(screened))) > 20
    hair = ref[-60:]
    assert 0 < hair.sum() < 60  # the hairpins straddle tol


def test_screen_decides_smooth_states(up_state, critical_states):
    """The screen passes for the clear up state (angle range below pi) and fails for the
    crossing critical states: the screen's claim checked on its own."""
    def screen(theta, scene):
        x = _contact._nodes(theta, scene, None)
        return bool(_contact._screen(x, theta, _contact.TOL * scene.strip.length))

    assert screen(up_state.theta, up_state.scene)
    scene, thetas = critical_states
    for th in thetas:
        assert not screen(th, scene)
