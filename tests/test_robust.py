"""Robust design (`jaxrod.design._robust`): the differentiable sample quantile, the quantiles'
Jacobian against central differences on the same draws, bad input by name (CI); a robust
two-target design recovered and confirmed by the independent Monte Carlo (nightly)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
import jaxrod.design as jd
from jaxrod.design._robust import _sample_quantile


def test_sample_quantile_is_numpys_over_the_successful_members():
    rng = np.random.default_rng(0)
    v = rng.normal(size=40)
    ok = rng.uniform(size=40) > 0.2
    for q in (0.1, 0.5, 0.9, 0.95):
        np.testing.assert_allclose(_sample_quantile(jnp.asarray(np.where(ok, v, np.nan)), jnp.asarray(ok), q),
                                   np.quantile(v[ok], q), rtol=1e-14)
    # its derivative is that of the members it interpolates: here every member scales with s
    d = jax.jacfwd(lambda s: _sample_quantile(s * jnp.asarray(v), jnp.asarray(ok), 0.9))(1.0)
    np.testing.assert_allclose(d, np.quantile(v[ok], 0.9), rtol=1e-12)


@pytest.mark.slow  # a batched Jacobian compiled (CI: the sample quantile's own derivative above)
def test_quantiles_jacobian_matches_central_differences():
    """The quantiles of a small scatter (N = 16, 8 members, one mesh) differentiated in the
    nominal (Psi0, G): forward mode against central differences on the same draws."""
    kw = dict(scatter=jd.Scatter(psi0_deg=10.0, gap=0.02), quantile=0.75, samples=8, n=16, extrapolate=False)

    def q(x):
        return jd.scatter_quantiles(x[0], x[1], **kw)[0]

    x = jnp.array([90.0, 0.5])
    J = jax.jacfwd(q)(x)
    h = jnp.array([1e-3, 1e-5])
    fd = jnp.stack([(q(x + jnp.eye(2)[j] * h[j]) - q(x - jnp.eye(2)[j] * h[j])) / (2 * h[j]) for j in range(2)], 1)
    assert np.all(np.isfinite(np.asarray(J)))
    np.testing.assert_allclose(J, fd, rtol=1e-5, atol=1e-8)


@pytest.mark.parametrize("kwargs, match", [
    (dict(target_up_deg=-5.0), "target_up_deg"),
    (dict(target_down_deg=30.0), "target_down_deg"),
    (dict(quantile=1.0), "quantile"),
    (dict(scatter="psi0=10"), "scatter"),
    (dict(start=(90.0,)), "start"),
    (dict(start=(190.0, 0.5)), "start psi0_deg"),
    (dict(samples=2), "samples"),
])
def test_bad_input_names_its_parameter(kwargs, match):
    args = dict(target_up_deg=78.0, target_down_deg=-83.0, n=16)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        jd.robust_design(args.pop("target_up_deg"), args.pop("target_down_deg"), **args)


@pytest.mark.slow
def test_robust_design_recovers_a_design_and_the_check_agrees():
    """Targets read off the 0.9 quantiles of Psi0 = 120 deg, G/L = 0.6 under Psi0 +- 10 deg
    (32 members, N = 30 + 60 extrapolated): from (110 deg, 0.55) the optimizer recovers that
    design, and 48 single calls on fresh draws at N = 60 + 120 snap before the targets with
    probability 0.9 within 3 standard errors."""
    sc = jd.Scatter(psi0_deg=10.0)
    q, frac = jd.scatter_quantiles(120.0, 0.6, scatter=sc, quantile=0.9, samples=32, n=30)
    assert np.all(np.asarray(frac) == 1.0)
    r = jd.robust_design(float(q[0]), -float(q[1]), quantile=0.9, scatter=sc, start=(110.0, 0.55), samples=32, n=30,
                         check_samples=48)
    assert r.result == jr.RESULTS.successful, r.message
    assert abs(r.psi0_deg - 120.0) < 1e-3 and abs(r.gap - 0.6) < 1e-5
    np.testing.assert_allclose(r.quantiles, np.asarray(q), atol=0.01)
    assert np.all(np.abs(r.check_probability - 0.9) <= 3 * r.check_sem)
    # the robust targets lie past the nominal strip's angles: the scatter costs about a degree
    assert np.all(r.quantiles > r.nominal)
