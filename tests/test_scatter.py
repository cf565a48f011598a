"""Snap angles under manufacturing scatter (`jaxrod.design._scatter`): every member equals its
single call, the statistics agree with an independent loop of single calls within their
reported sampling error, the mean's gradient with central differences on the same draws, the
score-function gradient with a closed form, and bad input is refused by name."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
import jaxrod.design as jd
from jaxrod.design._critical import design_scene
from jaxrod.design._scatter import _order_interval

N = 24
SCATTER = jd.Scatter(psi0_deg=10.0, gap=0.03, misalignment_deg=1.0)


@pytest.fixture(scope="module")
def stats():
    return jd.scatter_statistics(60.0, 0.5, scatter=SCATTER, samples=16, seed=0, n=N, before_up=(75.0, 80.0),
                                 before_down=(80.0,))


def _single(member):
    """A member (Psi0 deg, G/L, s0/L, misalignment deg) by a single call on a scene built by
    `jr.make_scene` with its clamps at +-misalignment/2."""
    psi_deg, gap, s0, mis = member
    return jr.snap_angles(jr.make_scene(psi_deg, gap, mis / 2, alpha_right_deg=-mis / 2, s0=s0, n=N))


def test_members_equal_their_single_calls(stats):
    """A member of the batch is its single call: the same angles (to 1e-9 deg) and codes."""
    assert stats.members.shape == (16, 4) and not stats.clipped.any()
    np.testing.assert_allclose(stats.members[:, 3], 1.0 * SCATTER.draws(16, 0)[:, 3])
    for m in (0, 7, 15):
        r = _single(stats.members[m])
        for path, st in ((r.up, stats.up), (r.down, stats.down)):
            assert int(path.result._value) == int(st.codes[m])
            np.testing.assert_allclose(st.alpha_deg[m], math.degrees(float(path.alpha_c)), atol=1e-9)


def test_statistics_are_those_of_the_members(stats):
    """Mean, spread, quantiles and probabilities are those of the successful members' angles."""
    for st in (stats.up, stats.down):
        a = st.alpha_deg[np.isfinite(st.alpha_deg)]
        assert st.num_snapping == a.size and st.num_ok >= a.size
        np.testing.assert_allclose(st.mean, a.mean(), rtol=1e-12)
        np.testing.assert_allclose(st.std, a.std(ddof=1), rtol=1e-12)
        np.testing.assert_allclose(st.sem, a.std(ddof=1) / np.sqrt(a.size), rtol=1e-12)
        np.testing.assert_allclose(st.quantiles, np.quantile(a, [0.1, 0.5, 0.9]), rtol=1e-12)
        assert np.all(np.isnan(st.quantile_low) | (st.quantile_low <= st.quantiles))
        assert np.all(np.isnan(st.quantile_high) | (st.quantile_high >= st.quantiles))
        np.testing.assert_allclose(st.probability, [np.mean(np.abs(a) <= b) for b in st.before], rtol=1e-12)
    assert stats.result == jr.RESULTS.successful


def test_statistics_agree_with_an_independent_loop(stats):
    """An independent sample (another seed), each member a single call in a Python loop: the
    means differ by less than 4 combined standard errors."""
    draws = SCATTER.draws(16, seed=1)
    nominal = np.array([60.0, 0.5, 0.02, 0.0])
    widths = np.array([10.0, 0.03, 0.0, 1.0])
    up, down = [], []
    for d in draws:
        r = _single(nominal + widths * d)
        assert r.up.result == jr.RESULTS.successful and r.down.result == jr.RESULTS.successful
        up.append(math.degrees(float(r.up.alpha_c)))
        down.append(math.degrees(float(r.down.alpha_c)))
    for st, loop in ((stats.up, np.array(up)), (stats.down, np.array(down))):
        se = math.hypot(st.sem, loop.std(ddof=1) / math.sqrt(loop.size))
        assert abs(st.mean - loop.mean()) < 4 * se, (st.mean, loop.mean(), se)
        assert 0.3 < st.std / loop.std(ddof=1) < 3.0


@pytest.mark.slow  # the batch's reverse-mode program compiled (CI: each member's implicit derivative in
# test_critical.py and test_gradients.py, the sample quantile's derivative in test_robust.py)
def test_mean_gradient_matches_central_differences():
    """`jax.grad` of `scatter_mean` (the reparametrization estimator) equals central
    differences of the same estimator on the same draws."""
    kw = dict(scatter=SCATTER, samples=4, seed=3, n=N)

    def means(x):
        up, down, _, _ = jd.scatter_mean(x[0], x[1], x[2], **kw)
        return jnp.stack([up, down])

    x = jnp.array([60.0, 0.5, 0.02])
    J = jax.jacrev(means)(x)
    h = jnp.array([1e-3, 1e-5, 1e-6])
    fd = jnp.stack([(means(x + jnp.eye(3)[j] * h[j]) - means(x - jnp.eye(3)[j] * h[j])) / (2 * h[j])
                    for j in range(3)], axis=1)
    assert np.all(np.isfinite(np.asarray(J)))
    np.testing.assert_allclose(J, fd, rtol=2e-5, atol=1e-9)
    _, _, k_up, k_down = jd.scatter_mean(60.0, 0.5, 0.02, **kw)
    assert int(k_up) == 4 and int(k_down) == 4


def test_score_gradient_of_a_closed_form():
    """For alpha = p (the nominal plus the scatter), P(alpha <= a) = Phi((a - mu) / sigma),
    whose derivative in mu is -phi((a - mu) / sigma) / sigma: the score-function estimate is
    within 4 of its standard errors; a parameter without scatter has no score (NaN)."""
    rng = np.random.default_rng(0)
    eps = rng.standard_normal((200_000, 2))
    mu, sigma, a = 1.0, 0.3, 1.2
    event = mu + sigma * eps[:, 0] <= a
    g, se = jd.score_gradient(event, eps, np.array([sigma, 0.0]))
    z = (a - mu) / sigma
    exact = -math.exp(-0.5 * z * z) / math.sqrt(2 * math.pi) / sigma
    assert abs(g[0] - exact) < 4 * se[0] and se[0] < 0.01 * abs(exact)
    assert np.isnan(g[1]) and np.isnan(se[1])


def test_probability_gradient_where_there_is_scatter(stats):
    """The score-function gradient of P(alpha_up <= a) is reported, with its standard error,
    along the scattered parameters (Psi0 and G) only: NaN along s0, which has no scatter."""
    g, se = stats.up.probability_gradient, stats.up.probability_gradient_sem
    assert g.shape == (2, 3) and np.all(np.isfinite(g[:, :2])) and np.all(np.isnan(g[:, 2]))
    assert np.all(se[:, :2] >= 0)


def test_clipped_members_are_counted():
    """A nominal fold angle near the flat strip with a uniform +-10 deg: the members past
    180 deg are clipped into the domain and counted."""
    sc = jd.Scatter(psi0_deg=10.0, distribution="uniform")
    st = jd.scatter_statistics(176.0, 0.5, scatter=sc, samples=16, seed=0, n=N)  # the fixture's program
    draws = sc.draws(16, 0)
    np.testing.assert_array_equal(st.clipped, 176.0 + 10.0 * draws[:, 0] > 180.0)
    assert st.clipped.any() and np.all(st.members[:, 0] <= 180.0)


def test_order_statistic_interval():
    vals = np.arange(1.0, 101.0)
    est, lo, hi = _order_interval(vals, 0.5)
    assert est == 50.5 and lo == 40.0 and hi == 60.0
    est, lo, hi = _order_interval(vals[:5], 0.1)
    assert np.isnan(lo) and hi == 2.0  # ranks 0.5 -+ 1.96 sqrt(0.45): below the first, and 2


@pytest.mark.parametrize("kwargs, match", [
    (dict(scatter=None), "scatter"),
    (dict(samples=1), "samples"),
    (dict(levels=(1.5,)), "levels"),
    (dict(before_up=(-3.0,)), "before_up"),
    (dict(psi0_deg=200.0), "psi0_deg"),
    (dict(gap=1.2), "gap"),
])
def test_bad_input_names_its_parameter(kwargs, match):
    args = dict(psi0_deg=60.0, gap=0.5, scatter=SCATTER, samples=4, n=N)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        jd.scatter_statistics(args.pop("psi0_deg"), args.pop("gap"), **args)


@pytest.mark.parametrize("kwargs, match", [
    (dict(psi0_deg=-1.0), "psi0_deg"),
    (dict(gap=float("nan")), "gap"),
    (dict(distribution="cauchy"), "distribution"),
    (dict(misalignment_deg=-0.5), "misalignment_deg"),
])
def test_bad_scatter_names_its_field(kwargs, match):
    with pytest.raises(ValueError, match=match):
        jd.Scatter(**kwargs)


@pytest.mark.slow
def test_statistics_at_n100_against_a_loop():
    """At N = 100, 256 members of Psi0 +- 10 deg (normal) at G/L = 0.5: the batch's means
    agree with an independent loop of 64 single calls within 4 combined standard errors."""
    sc = jd.Scatter(psi0_deg=10.0)
    st = jd.scatter_statistics(60.0, 0.5, scatter=sc, samples=256, seed=0, n=100)
    up, down = [], []
    for d in sc.draws(64, seed=11):
        r = jr.snap_angles(design_scene(math.radians(60.0 + 10.0 * d[0]), 0.5, 0.02, 100))
        if r.up.result == jr.RESULTS.successful and r.up.snaps:
            up.append(math.degrees(float(r.up.alpha_c)))
        if r.down.result == jr.RESULTS.successful and r.down.snaps:
            down.append(math.degrees(float(r.down.alpha_c)))
    for s, loop in ((st.up, np.array(up)), (st.down, np.array(down))):
        se = math.hypot(s.sem, loop.std(ddof=1) / math.sqrt(loop.size))
        assert abs(s.mean - loop.mean()) < 4 * se, (s.mean, loop.mean(), se)
