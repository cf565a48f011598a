r"""The flat strip (Psi0 = 180 deg) against the closed-form clamped-clamped elastica.

First buckled (symmetric) mode of an inextensible strip clamped flat at both ends, with
end shortening $1-G/L$. With the parameter $m$ of the complete elliptic integrals $K(m)$,
$E(m)$ and $k = 4K/L$:

* end shortening $1 - G/L = 2\,(1 - E/K)$,
* compression $P = B k^2 = 16 K^2 B / L^2$ (Euler load $4\pi^2 B/L^2$ at $m\to0$),
* $\sin(\theta/2) = \sqrt m\,\mathrm{sn}(ks\,|\,m)$,
  $y(s) = \frac{2\sqrt m}{k}\,(1-\mathrm{cn}(ks\,|\,m))$,
  $x(s) = \frac{2}{k}\,E(\mathrm{am}(ks)\,|\,m) - s$,
  so the mid-height is $y(L/2) = L\sqrt m / K$ (up state: $y>0$, $\theta>0$ on $[0, L/4]$).

The scheme (midpoint angles, hinge curvature) is second order: errors scale as $1/N^2$
with constants of a few units, which sets the tolerances below.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import brentq
from scipy.integrate import quad
from scipy.special import ellipe, ellipj, ellipk

import jaxrod as jr
from helpers import loglog_slope, solve


NS = (50, 100, 200, 400)


def elastica(gap_ratio, length=1.0):
    """(m, k, P, mid-height) of the first clamped-clamped buckled mode, B = 1."""
    m = brentq(lambda m: 2.0 * (1.0 - ellipe(m) / ellipk(m)) - (1.0 - gap_ratio), 1e-15, 1.0 - 1e-15,
               xtol=1e-16, rtol=4 * np.finfo(float).eps, maxiter=500)
    K = ellipk(m)
    k = 4.0 * K / length
    return m, k, k**2, length * math.sqrt(m) / K


def elastica_shape(gap_ratio, s):
    """Closed-form (x(s), y(s)) of the up state at arclengths s.

    x(s) = (2/k) E(am(ks)|m) - s is evaluated by quadrature of cos(theta) = 1 - 2m sn^2:
    scipy's `ellipeinc` returns wrong values at isolated arguments (scipy 1.17.1, e.g.
    ellipeinc(1.197050186422511, 0.19473136746775688) = 1.5269 instead of 1.1541)."""
    m, k, _, _ = elastica(gap_ratio)
    cn = ellipj(k * s, m)[1]

    def cos_theta(t):
        return 1.0 - 2.0 * m * ellipj(k * t, m)[0] ** 2

    x = np.array([quad(cos_theta, 0.0, si, epsabs=1e-14, epsrel=1e-12, limit=200)[0] for si in np.atleast_1d(s)])
    return x, 2.0 * math.sqrt(m) / k * (1.0 - cn)


def flat_up_state(gap_ratio, n):
    """Up state of the flat strip: Newton straight from the sine-shaped buckled guess."""
    scene = jr.Scene(jr.Strip(psi0=math.pi), jr.Clamps(gap_ratio), jr.Mesh(n))
    eq = solve(scene, jr.buckled_guess(scene, up=True))
    assert eq.result == jr.RESULTS.successful, jr.RESULTS[eq.result]
    assert int(eq.num_unstable) == 0
    return eq


@pytest.fixture(scope="module")
def states():
    """Flat up states at G/L = 0.5 and 0.8 for every N (one compile per N)."""
    return {(g, n): flat_up_state(g, n) for g in (0.5, 0.8) for n in NS}


def test_closed_form_self_consistency():
    # the reference itself: G/L -> 1 gives the Euler load, and x(L) = G
    for g in (0.5, 0.8, 0.999):
        m, k, P, H = elastica(g)
        x, y = elastica_shape(g, np.array([0.0, 0.5, 1.0]))
        assert abs(x[-1] - g) < 1e-12 and abs(y[-1]) < 1e-13 and abs(y[1] - H) < 1e-13
    assert abs(elastica(1 - 1e-9)[2] / (4 * math.pi**2) - 1) < 1e-8


def test_euler_load_limit():
    """G/L = 0.999: P -> 4 pi^2 B/L^2 with the post-buckling correction P/4pi^2 ~ 1 + d/2."""
    N, d = 100, 1e-3
    eq = flat_up_state(1.0 - d, N)
    P = float(jr.compression(eq))
    euler = 4.0 * math.pi**2
    P_exact = elastica(1.0 - d)[2]
    rel = P / euler - 1.0
    print(f"\nflat strip G/L = 0.999, N = {N}: P / (4 pi^2) - 1 = {rel:.4e}; "
          f"(P - P_elastica) / P_elastica = {P / P_exact - 1:.4e} (-pi^2/(3N^2) = {-math.pi**2 / (3 * N**2):.4e})")
    assert abs(rel) < 1e-3
    # the remaining difference to 1 + d/2 is the O(h^2) discretization error (3.3e-4 at N = 100)
    # plus O(d^2) ~ 3e-7
    assert abs(P / euler - (1 + d / 2)) < 4e-4
    # sharper: the discrete Euler load of this scheme is 4 pi^2 (2/h sin(pi h/L))^2 / (2 pi/L)^2
    # = 4 pi^2 (1 - pi^2/(3 N^2) + O(N^-4)); with it the model matches to O(d^2, N^-4) ~ 1e-6
    discrete = P_exact * (2 * N / (2 * math.pi) * math.sin(math.pi / N)) ** 2
    assert abs(P / discrete - 1) < 1e-6
    # and the fold height, y(L/2) = L sqrt(m)/K, to O(h^2)
    H = float(jr.fold_height(eq))
    assert abs(H / elastica(1.0 - d)[3] - 1) < 4.0 / N**2


@pytest.mark.parametrize("gap", [0.5, 0.8])
def test_force_and_height_vs_elliptic(states, gap):
    N = 400
    eq = states[(gap, N)]
    _, _, P, H = elastica(gap)
    eP = float(jr.compression(eq)) / P - 1
    eH = float(jr.fold_height(eq)) / H - 1
    print(f"\nG/L = {gap}, N = {N}: relative error of P {eP:.3e}, of y(L/2) {eH:.3e}")
    # O(h^2) with measured constants |c| < 3.5: 4/N^2 = 2.5e-5
    assert abs(eP) < 4.0 / N**2
    assert abs(eH) < 4.0 / N**2
    # up state: fold above the axis, pushed (compression > 0), end force horizontal
    assert float(jr.fold_height(eq)) > 0 and float(jr.compression(eq)) > 0
    assert abs(float(eq.force[1])) < 1e-9


@pytest.mark.parametrize("gap", [0.5, 0.8])
def test_convergence_order(states, gap):
    _, _, P, H = elastica(gap)
    eP = [float(jr.compression(states[(gap, n)])) - P for n in NS]
    eH = [float(jr.fold_height(states[(gap, n)])) - H for n in NS]
    orderP, orderH = -loglog_slope(NS, eP), -loglog_slope(NS, eH)
    print(f"\nG/L = {gap}: errors of P {np.array(eP) / P} -> order {orderP:.3f}; "
          f"of y(L/2) {np.array(eH) / H} -> order {orderH:.3f}")
    assert 1.8 <= orderP <= 2.3
    assert 1.8 <= orderH <= 2.3
    # errors keep one sign (a clean asymptotic regime, not a lucky cancellation)
    assert len({np.sign(e) for e in eP}) == 1 and len({np.sign(e) for e in eH}) == 1
    # Richardson extrapolation of the two finest meshes hits the closed form: the limit
    # is the elastica, not just some second-order-convergent other value
    P_rich = (4 * float(jr.compression(states[(gap, 400)])) - float(jr.compression(states[(gap, 200)]))) / 3
    H_rich = (4 * float(jr.fold_height(states[(gap, 400)])) - float(jr.fold_height(states[(gap, 200)]))) / 3
    assert abs(P_rich / P - 1) < 1e-8
    assert abs(H_rich / H - 1) < 1e-8


@pytest.mark.parametrize("gap", [0.5, 0.8])
def test_shape_along_strip(states, gap):
    N = 400
    eq = states[(gap, N)]
    s = np.asarray(jr.arclength(eq))
    r = np.asarray(jr.node_positions(eq))
    x, y = elastica_shape(gap, s)
    H = elastica(gap)[3]
    ex = np.max(np.abs(r[:, 0] - x)) / H
    ey = np.max(np.abs(r[:, 1] - y)) / H
    # tangent angles at the segment midpoints: sin(theta/2) = sqrt(m) sn(k s)
    m, k, _, _ = elastica(gap)
    mid = 0.5 * (s[1:] + s[:-1])
    sn = ellipj(k * mid, m)[0]
    theta = 2 * np.arcsin(np.sqrt(m) * sn)
    et = np.max(np.abs(np.asarray(eq.theta) - theta)) / np.max(np.abs(theta))
    print(f"\nG/L = {gap}, N = {N}: max |x - x_exact|/H = {ex:.2e}, max |y - y_exact|/H = {ey:.2e}, "
          f"max |theta - theta_exact|/max theta = {et:.2e}")
    assert ex < 4.0 / N**2 and ey < 4.0 / N**2 and et < 4.0 / N**2
    # sign convention: the up state rises first (theta > 0 on the first quarter)
    assert np.all(np.asarray(eq.theta)[: N // 4] > 0)
    # mirror symmetry theta(s) = -theta(L - s) of the symmetric mode
    th = np.asarray(eq.theta)
    assert np.max(np.abs(th + th[::-1])) < 1e-10


def test_down_state_is_mirror_image():
    """For the flat strip y -> -y is a symmetry: the down state is the mirrored up state."""
    scene = jr.make_scene(180.0, 0.8, n=100)
    up = solve(scene, jr.buckled_guess(scene, up=True))
    down = solve(scene, jr.buckled_guess(scene, up=False))
    assert up.result == jr.RESULTS.successful and down.result == jr.RESULTS.successful
    np.testing.assert_allclose(np.asarray(down.theta), -np.asarray(up.theta), rtol=0, atol=1e-12)
    assert float(jr.compression(down)) == pytest.approx(float(jr.compression(up)), rel=1e-12)
    assert float(jr.fold_height(down)) == pytest.approx(-float(jr.fold_height(up)), rel=1e-12)
    # and independently checked: a stationary point of the Lagrangian
    assert float(jnp.max(jnp.abs(jnp.asarray(jr.node_positions(down))[-1] - jnp.array([0.8, 0.0])))) < 1e-12
