r"""RATTLE: a symplectic, exactly constrained step for the strip's link chain (a diffrax solver).

The strip of `jaxrod.dynamics._equations` is a chain of point masses $m_k$ at the nodes joined by
rigid links $|\mathbf x_{i+1}-\mathbf x_i|=h_i$, node 0 at the origin and node $N$ at
$(G,0)$, with the bending energy $V(\mathbf x,t)=E_b(\theta(\mathbf x),\alpha_L(t),\alpha_R(t))$
(plus gravity), $\theta_i=\arg(\mathbf x_{i+1}-\mathbf x_i)$. In Cartesian node coordinates
the Hamiltonian is separable, $H=\sum_k|\mathbf p_k|^2/2m_k+V$, with holonomic constraints
$g_i=\tfrac12(|\Delta\mathbf x_i|^2-h_i^2)=0$, so RATTLE (Andersen, J. Comput. Phys. 52, 24,
1983; Leimkuhler & Skeel 1994) applies: with $G=\partial g/\partial\mathbf x$, $\mathbf f=-\nabla V$,

$$\mathbf v_{1/2}=\mathbf v_0+\tfrac{\Delta t}{2}M^{-1}(\mathbf f_0-G_0^\top\mu),\quad
\mathbf x_1=\mathbf x_0+\Delta t\,\mathbf v_{1/2},\quad g(\mathbf x_1)=0\ \text{(fixes }\mu),$$
$$\mathbf v_1=\mathbf v_{1/2}+\tfrac{\Delta t}{2}M^{-1}(\mathbf f_1-G_1^\top\nu),\quad
G_1\mathbf v_1=0\ \text{(fixes }\nu).$$

It is second order, symplectic and time-reversible on the constraint manifold (energy error
bounded, no drift, when undamped and the clamps are held), keeps every link length and
both ends exact to the Newton tolerance (no Baumgarte term), and costs one bending-energy
gradient per step (first same as last). $\mu$ solves $g(\mathbf x_1(\mu))=0$ by Newton
with its tridiagonal Jacobian ($J_{ii}=-c(m_i^{-1}+m_{i+1}^{-1})\Delta\mathbf x_{1,i}\cdot\Delta\mathbf x_{0,i}$,
$J_{i,i\pm1}=c\,m^{-1}\Delta\mathbf x_{1,i}\cdot\Delta\mathbf x_{0,i\pm1}$, $c=\Delta t^2/2$),
warm-started from the previous step's $\mu$ (`shake_iters` iterations, quadratic
convergence), after which every link's residual $|g_i|/h_i^2$ must be below `shake_tol`
(1e-10): a step whose constraint solve has not converged ends the run with diffrax's
`nonlinear_divergence` (`jaxrod.RESULTS.constraint_solve_failed` in `simulate`) instead of
carrying on from a state off the constraint manifold; $\nu$ from one symmetric tridiagonal solve. Linear stability on an undamped
mode of frequency $\omega_k$: $\omega_k\Delta t<2$; the highest bending mode of the chain
is $\omega_{\max}=4\sqrt{B/\lambda}/h^2$ (measured: 3.99/h^2 at N = 100), hence the default
step $\Delta t=$ `courant`$\cdot h_{\min}^2\sqrt{\lambda/B}$ of `jaxrod.simulate`.

Dissipative forces (damping, drag, hinge viscosity) are velocity dependent: in the second
half kick they are evaluated at $\mathbf v_{1/2}$ (explicit, first order in those terms
only). The clamp work $W$ is integrated by the trapezoidal rule.

The diffrax state stays $y=((\theta,\omega),W)$ (what `simulate` saves and interpolates,
linearly between steps); the solver carries the Cartesian $(\mathbf x,\mathbf v)$, the
forces and $\mu$ in its state. Fixed steps only (no error estimate). `substeps` > 1 takes that many RATTLE steps per
diffrax step (the same scheme; only diffrax's per-step bookkeeping and the saved samples
become `substeps` times sparser).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar

import diffrax as dfx
import jax.numpy as jnp
from jax import lax

import equinox as eqx

from ._equations import applied_forces, inverse_node_mass, kinematics, link_pairs
from ..linalg.batched import tridiagonal_solve


def _tri(lower, diag, upper, rhs):
    return tridiagonal_solve(lower, diag, upper, rhs[:, None])[:, 0]


def _spread(mu, dx):
    """G^T mu: link i pulls node i+1 by +mu_i dx_i and node i by -mu_i dx_i, (N+1, 2)."""
    return link_pairs(mu[:, None] * dx)


def rattle_forces(t, theta, omega, x, v, args):
    r"""`jaxrod.dynamics._equations.applied_forces` from RATTLE's own Cartesian state: the normals
    $\mathbf n_i=(-\Delta y_i,\Delta x_i)/h_i$ from the links and the damping and drag at the
    given node velocities `v`, instead of re-deriving both from $(\theta,\dot\theta)$ by
    trigonometry and cumulative sums (`node_forces`; 25 % of a step at N = 50). Returns
    `(f, clamp power)`."""
    f, power, _ = rattle_forces_and_rates(t, theta, omega, x, v, args)
    return f, power


def rattle_forces_and_rates(t, theta, omega, x, v, args):
    """`rattle_forces` and the clamps' angular rates `(rL, rR)` at `t` (the actuator's
    dissipated power needs them, and reads them here rather than from the program again)."""
    scene, protocol, dissipation, _, d = args
    dx = jnp.diff(x, axis=0)
    nn = jnp.stack([-dx[:, 1], dx[:, 0]], -1) / d.h[:, None]
    f, _, (gL, gR, rL, rR) = applied_forces(t, theta, omega, nn, v, scene, protocol, dissipation, d, x)
    return f, gL * rL + gR * rR, (rL, rR)


def project_velocity(x, w, invm):
    r"""$\mathbf v=\mathbf w-M^{-1}G^\top\nu$ with $G\mathbf v=0$ (every link's length rate
    zero): $A\nu=\Delta\mathbf x\cdot\Delta\mathbf w$, $A$ symmetric tridiagonal."""
    dx = jnp.diff(x, axis=0)
    dw = jnp.diff(w, axis=0)
    diag = (invm[:-1] + invm[1:]) * jnp.sum(dx * dx, -1)
    off = -invm[1:-1] * jnp.sum(dx[1:] * dx[:-1], -1)
    z = jnp.zeros(1, x.dtype)
    nu = _tri(jnp.concatenate([z, off]), diag, jnp.concatenate([off, z]), jnp.sum(dx * dw, -1))
    return w - invm[:, None] * _spread(nu, dx)


def angles(x, v, theta_ref):
    """Link angles (unwrapped next to `theta_ref`) and angular rates from nodes."""
    dx = jnp.diff(x, axis=0)
    dv = jnp.diff(v, axis=0)
    th = jnp.arctan2(dx[:, 1], dx[:, 0])
    th = theta_ref + jnp.remainder(th - theta_ref + jnp.pi, 2 * jnp.pi) - jnp.pi
    r2 = jnp.sum(dx * dx, -1)
    om = (dx[:, 0] * dv[:, 1] - dx[:, 1] * dv[:, 0]) / r2
    return th, om


def shake(x0, v0, f0, mu, invm, h, dt, iters, tol):
    r"""RATTLE's position update: $\mathbf x_1=\mathbf x_0+\Delta t\mathbf v_0+\tfrac{\Delta t^2}2M^{-1}
    (\mathbf f_0-G_0^\top\mu)$ with $\mu$ solving every link's length $g(\mathbf x_1)=0$ by
    `iters` Newton iterations on its tridiagonal Jacobian, warm-started from `mu`. Returns
    `(x1, mu, converged)`, `converged` when every link's residual $|g_i|/h_i^2$ is below `tol`
    (False for NaN)."""
    c = 0.5 * dt**2
    xh = x0 + dt * v0 + c * invm[:, None] * f0
    dx0 = jnp.diff(x0, axis=0)
    h2 = h**2
    z = jnp.zeros(1, x0.dtype)

    def x_of(mu):
        return xh - c * invm[:, None] * _spread(mu, dx0)

    def newton(_, mu):
        dx1 = jnp.diff(x_of(mu), axis=0)
        r = 0.5 * (jnp.sum(dx1 * dx1, -1) - h2)
        diag = -c * (invm[:-1] + invm[1:]) * jnp.sum(dx1 * dx0, -1)
        up = c * invm[1:-1] * jnp.sum(dx1[:-1] * dx0[1:], -1)
        lo = c * invm[1:-1] * jnp.sum(dx1[1:] * dx0[:-1], -1)
        return mu - _tri(jnp.concatenate([z, lo]), diag, jnp.concatenate([up, z]), r)

    mu = lax.fori_loop(0, iters, newton, mu, unroll=True)
    x1 = x_of(mu)
    dx1 = jnp.diff(x1, axis=0)
    residual = jnp.max(jnp.abs(0.5 * (jnp.sum(dx1 * dx1, -1) - h2)) / h2)
    return x1, mu, residual < tol


def substeps(k, t0, t1, carry, state, substep):
    """`k` steps of `substep(ta, tb, carry, state) -> (carry, state, converged)` over equal
    parts of [t0, t1]; returns the carry, the state and whether every step converged."""
    h = (t1 - t0) / k

    def sub(i, c):
        w, st, ok = c
        ta = t0 + i * h
        w, st, ok_i = substep(ta, ta + h, w, st)
        return w, st, ok & ok_i

    init = (carry, state, jnp.ones((), bool))
    return lax.fori_loop(0, k, sub, init) if k > 1 else sub(0, init)


class FixedStepRattle(dfx.AbstractSolver):
    """What the RATTLE solvers share: the constraint solve's settings (`shake_iters` Newton
    iterations to `shake_tol`), `substeps` RATTLE steps per diffrax step, second order, linear
    interpolation between steps, fixed steps only."""

    shake_iters: int = 4
    shake_tol: float = 1e-10
    substeps: int = 1
    term_structure: ClassVar = dfx.AbstractTerm
    interpolation_cls: ClassVar[Callable[..., dfx.LocalLinearInterpolation]] = dfx.LocalLinearInterpolation

    def order(self, terms):
        return 2

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)


class RattleStep(FixedStepRattle):
    """RATTLE for jaxrod's strip (module docstring). Needs `simulate`'s `args`
    `(scene, protocol, dissipation, baumgarte, d)`; `baumgarte` is unused (the end
    conditions are exact)."""

    def init(self, terms, t0, t1, y0, args):
        scene, _, _, _, d = args
        (q, _) = y0
        theta, omega = q[0], q[1]
        invm = inverse_node_mass(d)
        x, v = kinematics(theta, omega, d)
        x = x.at[-1].set(jnp.stack([scene.clamps.gap, jnp.zeros((), x.dtype)]))
        v = project_velocity(x, v.at[-1].set(0.0), invm)
        f, p = rattle_forces(t0, theta, omega, x, v, args)
        mu = jnp.zeros(theta.shape, theta.dtype)
        return x, v, theta, f, p, mu

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        # fixed steps only (ConstantStepSize): made_jump never set, the carried state is y0's.
        # `substeps` RATTLE steps of (t1 - t0) / substeps per diffrax step (diffrax's per-step
        # work -- event, saving, controller -- then runs once per macro step).
        del made_jump
        w1, st1, ok = substeps(self.substeps, t0, t1, y0[1], solver_state,
                               lambda ta, tb, w, st: self._substep(ta, tb, w, args, st))
        x1, v1, th1, _, _, _ = st1
        _, om1 = angles(x1, v1, th1)
        y1 = (jnp.stack([th1, om1]), w1)
        result = dfx.RESULTS.where(ok, dfx.RESULTS.successful, dfx.RESULTS.nonlinear_divergence)
        return y1, None, dict(y0=y0, y1=y1), st1, result

    def _substep(self, t0, t1, w0, args, solver_state):
        """One RATTLE step from the solver state; returns the clamp work, the new state and
        whether the constraint solve converged (every link within `shake_tol`)."""
        _, _, _, _, d = args
        x0, v0, th0, f0, p0, mu = solver_state
        invm = inverse_node_mass(d)
        dt = t1 - t0
        x1, mu, converged = shake(x0, v0, f0, mu, invm, d.h, dt, self.shake_iters, self.shake_tol)
        vh = (x1 - x0) / dt
        th1, omh = angles(x1, vh, th0)
        f1, p1 = rattle_forces(t1, th1, omh, x1, vh, args)
        v1 = project_velocity(x1, vh + 0.5 * dt * invm[:, None] * f1, invm)
        return w0 + 0.5 * dt * (p0 + p1), (x1, v1, th1, f1, p1, mu), converged


class Rattle(eqx.Module):
    r"""Settings of RATTLE (the module docstring) for [`jaxrod.simulate`][] and the verbs built on it.

    **Arguments:** `courant` the step as $\Delta t\le$ `courant`$\,(h_{\min}/L)^2\,T$, in
    (0, 0.5), RATTLE's stability limit being 0.5 (default: 0.45 when the run stops at the
    snap, `RING_COURANT` = 0.05 past it); `substeps` RATTLE steps per diffrax step (default 4
    at the automatic step, 1 with a given `dt`). Fixed steps: the step is set by the
    stiffest bending mode, so its count grows like $N^2$ (see [`jaxrod.HHT`][] for a step set
    by accuracy)."""

    courant: float | None = None
    substeps: int | None = None

    def __check_init__(self):
        from .._misc import check_number

        if self.courant is not None:
            check_number("courant", self.courant, lo=0.0, hi=0.5)
            if not 0.0 < float(self.courant) < 0.5:
                raise ValueError(f"courant must lie in (0, 0.5) (RATTLE's stability limit), got {self.courant!r}")
        if self.substeps is not None and (isinstance(self.substeps, bool) or not isinstance(self.substeps, int)
                                          or self.substeps < 1):
            raise ValueError(f"substeps must be a positive integer, got {self.substeps!r}")
