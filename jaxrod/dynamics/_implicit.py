r"""An implicit step for the strip: the HHT-$\alpha$ method on the angles, Newton along the chain.

The strip's equations of motion in its angles $\theta$ (`jaxrod.dynamics._equations`) are
Lagrange's, with the end condition $\mathbf g(\theta)=\sum_ih_i\mathbf t_i-(G,0)=0$ and its
multiplier $\boldsymbol\lambda$ (the clamp's force on the right end):

$$\mathbf R=\underbrace{J^\top m\,\ddot{\mathbf X}}_{\text{inertia}}+\underbrace{\nabla_\theta V-Q_{\rm diss}}_{\mathbf F}
+\underbrace{V^\top\boldsymbol\lambda}_{\text{end}}=0,\qquad
\ddot{\mathbf X}_k=\sum_{i\le k}h_i\,(\mathbf n_i\ddot\theta_i-\mathbf t_i\dot\theta_i^2),$$

$(J^\top\mathbf u)_i=h_i\mathbf n_i\cdot\sum_{k\ge i}\mathbf u_k$, $V_i=h_i\mathbf n_i$. The
Hilber-Hughes-Taylor method (HHT-$\alpha$, $-\tfrac13\le\alpha\le0$) advances
$(\theta,\dot\theta,\ddot\theta)$ by Newmark's relations with $\beta=(1-\alpha)^2/4$,
$\gamma=\tfrac12-\alpha$,

$$\theta_1=\theta_0+\Delta t\,\dot\theta_0+\Delta t^2\big((\tfrac12-\beta)\ddot\theta_0+\beta\ddot\theta_1\big),\qquad
\dot\theta_1=\dot\theta_0+\Delta t\big((1-\gamma)\ddot\theta_0+\gamma\ddot\theta_1\big),$$

and solves $\text{inertia}_1+(1+\alpha)(\mathbf F+V^\top\boldsymbol\lambda)_1-\alpha(\mathbf F+V^\top\boldsymbol\lambda)_0=0$,
$\mathbf g(\theta_1)=0$ (the end condition exact at every step). $\alpha=0$ is the
trapezoidal rule (average acceleration): second order, without numerical dissipation,
and unconditionally stable on linear problems only: on the strip's rotating chain its
energy can grow (measured on the brink snap at N = 100 with a fixed step $10^{-4}T$: the
energy monitor stops it during the snap). $\alpha<0$ damps the grid-scale bending modes
($\rho_\infty=(1+\alpha)/(1-\alpha)$) and leaves the slow motion second-order accurate. The step is not bound by the stiffest mode:
the bending energy is quadratic in $\theta$, so its Hessian $D^\top\mathrm{diag}(B/\ell)D$ is
exact in Newton's matrix.

**Newton.** Unknown $\theta_1$ ($\ddot\theta_1$ and $\dot\theta_1$ follow from Newmark's
relations), matrix: the inertia's derivative $J^\top m\,\tilde J/(\beta\Delta t^2)$, where
$\tilde J$ carries, per link, $\partial\ddot{\mathbf X}/\partial\theta_{1,j}=h_j\big((1-\beta\Delta t^2\dot\theta_j^2)\mathbf n_j
-(2\gamma\Delta t\dot\theta_j+\beta\Delta t^2\ddot\theta_j)\mathbf t_j\big)/(\beta\Delta t^2)$ (the acceleration,
the centripetal term through the rate, the link's own turn; viscous damping likewise), the
bending and hinge-viscosity Hessians exactly ($(1+\alpha)D^\top\tfrac{B+\gamma\eta/(\beta\Delta t)}{\ell}D$),
and the diagonal geometric terms $d_i=-h_i\mathbf t_i\cdot(\mathbf P_i+(1+\alpha)(\boldsymbol\lambda-\mathbf S_i))$
($\mathbf P_i$, $\mathbf S_i$ the tail sums of the nodes' inertial and applied non-bending forces),
bordered by the end condition. `jaxrod.linalg.chain.chain_solve` solves it in $O(N)$
without forming the dense mass matrix. Left out (so Newton is exact only without them): the
contact's, gravity's and air drag's couplings between different links. The predictor
extrapolates the acceleration linearly from the last two steps; the iteration stops when
the residual, scaled by the diagonal of the matrix, and the end condition (over $L$) are
below `newton_tol`, and a step that has not converged after `newton_iters` is rejected
and retried shorter (`step_underflow` below $10^{-12}T$; `newton_failed` at a fixed `dt`).

**Step size.** The local error of Newmark's displacement,
$\mathbf e_\theta=\Delta t^2(\beta-\tfrac16)(\ddot\theta_1-\ddot\theta_0)$, is measured where it
matters, as the nodes' position error $\mathbf e_{X,k}=\sum_{i\le k}h_i\mathbf n_ie_{\theta,i}$;
the step is accepted when $\max_k|\mathbf e_{X,k}|\le$ `tol` $\cdot L$ and adapted by diffrax's
PID controller (error order 3). Grid-scale ringing has tiny node displacements, so it
does not set the step.

**Output.** Cubic Hermite interpolation of $(\theta,\dot\theta)$ from the step's ends and
their rates (diffrax's `ThirdOrderHermitePolynomialInterpolation`), the clamp work $W$ by the
trapezoidal rule.
"""

from __future__ import annotations

from typing import ClassVar

import diffrax as dfx
import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp

from ._equations import accelerations, safe_norm
from ..energy.contact import contact_energy_nodes
from ..linalg.chain import chain_solve


def _tail(u):
    """Reverse cumulative sums over nodes k >= i of node vectors u (N+1, 2): rows i = 1..N."""
    return jnp.cumsum(u[::-1], 0)[::-1][1:]


def _generalized(h, nn, u):
    r"""$(J^\top\mathbf u)_i=h_i\mathbf n_i\cdot\sum_{k\ge i}\mathbf u_k$ for node vectors u (N+1, 2)."""
    return h * jnp.sum(nn * _tail(u), -1)


def _evaluate(t, theta, omega, acc, args):
    r"""What the residual needs at $(t,\theta,\dot\theta,\ddot\theta)$: the inertial generalized
    force $J^\top m\ddot{\mathbf X}$ (N,), $\mathbf F=\nabla_\theta V-Q_{\rm diss}$ (N,), the tail sums
    $\mathbf P_i$, $\mathbf S_i$ of the nodes' inertial and applied (non-bending) forces (N, 2), the
    normals and tangents (N, 2), the clamp power and the end condition's error (2,).

    The bending and hinge-viscosity moments are the hinges' $\tau_k=B(\phi_k-\bar\phi_k)/\ell_k
    +\eta\dot\phi_k/\ell_k$, whose generalized force on link $i$ is $\tau_{i-1}-\tau_i$."""
    scene, protocol, dissipation, _, d = args
    dtype = theta.dtype
    aL, aR, rL, rR = protocol.angles(t)
    aL, aR = jnp.asarray(aL, dtype), jnp.asarray(aR, dtype)
    ct, st = jnp.cos(theta), jnp.sin(theta)
    tt = jnp.stack([ct, st], -1)
    nn = jnp.stack([-st, ct], -1)
    full = jnp.concatenate([aL[None], theta, -aR[None]])
    rate = jnp.concatenate([jnp.asarray(rL, dtype)[None], omega, -jnp.asarray(rR, dtype)[None]])
    tau_b = scene.strip.bending_stiffness * (jnp.diff(full) - d.phi0) / d.ell
    tau = tau_b + dissipation.viscosity * jnp.diff(rate) / d.ell
    F = tau[:-1] - tau[1:]
    power = -tau_b[0] * rL - tau_b[-1] * rR  # dE_b/dalpha_L * rate_L + dE_b/dalpha_R * rate_R
    zero = jnp.zeros((1, 2), dtype)
    # node velocities and accelerations; node 0 fixed
    vel = jnp.concatenate([zero, jnp.cumsum((d.h * omega)[:, None] * nn, 0)])
    inc = d.h[:, None] * (nn * acc[:, None] - tt * (omega**2)[:, None])
    X2 = jnp.concatenate([zero, jnp.cumsum(inc, 0)])
    m = d.node_mass.at[0].set(0.0).at[-1].set(0.0)  # the end nodes are held
    P = _tail(m[:, None] * X2)
    # applied node forces other than the bending pairs
    f = -dissipation.damping * d.node_mass[:, None] * vel
    lam_d = scene.strip.line_density
    f = f - dissipation.drag * (d.node_mass / lam_d)[:, None] * safe_norm(vel)[:, None] * vel
    if scene.gravity is not None:
        f = f.at[:, 1].add(-d.node_mass * scene.gravity.g)
    if scene.contact is not None:
        x = jnp.concatenate([zero, jnp.cumsum(d.h[:, None] * tt, 0)])
        dd = d._replace(theta_left=aL, theta_right=-aR)
        f = f - jax.grad(contact_energy_nodes)(x, scene, dd)
    S = _tail(f)
    F = F - d.h * jnp.sum(nn * S, -1)
    end = jnp.stack([jnp.sum(d.h * ct) - scene.clamps.gap, jnp.sum(d.h * st)])
    inertial = d.h * jnp.sum(nn * P, -1)
    return inertial, F, P, S, nn, tt, power, end


class HHTStep(dfx.AbstractAdaptiveSolver):
    """diffrax solver of the module docstring. `args` as `simulate`'s:
    `(scene, protocol, dissipation, baumgarte, d)` (`baumgarte` unused: the end condition is
    solved at every step)."""

    alpha: float = 0.0
    newton_iters: int = 6
    newton_tol: float = 1e-8
    extrapolate: float = 1.0
    term_structure: ClassVar = dfx.AbstractTerm
    interpolation_cls: ClassVar = dfx.ThirdOrderHermitePolynomialInterpolation

    def order(self, terms):
        return 2

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)

    def init(self, terms, t0, t1, y0, args):
        scene, protocol, dissipation, baumgarte, d = args
        (q, _) = y0
        acc = accelerations(t0, q, scene, protocol, dissipation, baumgarte, d)
        inert, F, P, S, nn, tt, p, end = _evaluate(t0, q[0], q[1], acc, args)
        # the end force of the consistent accelerations: F + V^T lam = -inertia (least squares in lam)
        lam = _end_force(inert + F, d.h, nn)
        G = F + d.h * jnp.sum(nn * lam, -1)
        return acc, acc, jnp.asarray(jnp.inf, q.dtype), lam, G, p, jnp.zeros((), jnp.int32)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        del made_jump
        scene, protocol, dissipation, _, d = args
        a0, a_prev, h_prev, lam0, G0, p0, _ = solver_state
        (q0, w0) = y0
        th0, om0 = q0[0], q0[1]
        h = t1 - t0
        al = self.alpha
        beta = (1.0 - al) ** 2 / 4.0
        gamma = 0.5 - al
        c = beta * h**2
        base_th = th0 + h * om0 + h**2 * (0.5 - beta) * a0
        base_om = om0 + h * (1.0 - gamma) * a0
        L = scene.strip.length
        B = scene.strip.bending_stiffness
        w_hinge = (1.0 + al) * (B + gamma * dissipation.viscosity / (beta * h)) / d.ell
        m_nodes = d.node_mass[1:].at[-1].set(0.0)
        gam_d = dissipation.damping
        # the diagonal of Newton's matrix without its geometric part: scales the residual test
        m_tail = jnp.cumsum(m_nodes[::-1])[::-1] * (1.0 + (1.0 + al) * gamma * h * gam_d) / c
        jac_diag = d.h**2 * m_tail + w_hinge[:-1] + w_hinge[1:]

        def residual(th1, a1, lam1):
            om1 = base_om + h * gamma * a1
            inert, F, P, S, nn, tt, p, end = _evaluate(t1, th1, om1, a1, args)
            Gs = F + d.h * jnp.sum(nn * lam1, -1)
            R = inert + (1.0 + al) * Gs - al * G0
            dgeo = -d.h * jnp.sum(tt * (P + (1.0 + al) * (lam1[None, :] - S)), -1)
            small = (jnp.max(jnp.abs(R) / jac_diag) <= self.newton_tol) & (jnp.max(jnp.abs(end)) <= self.newton_tol * L)
            return (R, end, nn, tt, dgeo, om1), (Gs, p, small)

        def newton(carry):
            th1, a1, lam1, (R, end, nn, tt, dgeo, om1), _, i = carry
            # d(node acceleration + damping)/d(theta_1j) = h_j (cn_j n_j - ct_j t_j) / c: through the
            # acceleration (n_j / c), the rate (centripetal -2 gamma h omega_j t_j / c, damping), and
            # the link's own turn (-a_j t_j - omega_j^2 n_j)
            cn = 1.0 + (1.0 + al) * gam_d * gamma * h - c * om1**2
            ct = 2.0 * gamma * h * om1 + c * a1 + (1.0 + al) * gam_d * c * om1
            u = d.h[:, None] * (cn[:, None] * nn - ct[:, None] * tt)
            dth, dlam = chain_solve(d.h[:, None] * nn, m_nodes / c, dgeo, w_hinge, -R, -end, u=u)
            th1 = th1 + dth
            a1 = a1 + dth / c
            lam1 = lam1 + dlam / (1.0 + al)
            lin, rest = residual(th1, a1, lam1)
            return th1, a1, lam1, lin, rest, i + 1

        def going(carry):
            return (carry[5] < self.newton_iters) & ~carry[4][2]

        # predictor: the acceleration extrapolated linearly from the last two steps
        slope = jnp.where(jnp.isfinite(h_prev), (a0 - a_prev) / jnp.where(jnp.isfinite(h_prev), h_prev, 1.0), 0.0)
        a_pred = a0 + self.extrapolate * h * slope
        th_pred = base_th + c * a_pred
        lin, rest = residual(th_pred, a_pred, lam0)
        init = (th_pred, a_pred, lam0, lin, rest, jnp.zeros((), jnp.int32))
        th1, a1, lam1, (R, end, nn, _, _, _), (G1, p1, ok), iters = eqxi.while_loop(
            going, newton, init, max_steps=self.newton_iters, kind="checkpointed")
        om1 = base_om + h * gamma * a1
        ok = ok & jnp.all(jnp.isfinite(th1)) & jnp.all(jnp.isfinite(om1))
        w1 = w0 + 0.5 * h * (p0 + p1)
        y1 = (jnp.stack([th1, om1]), w1)
        # local error: e_theta = h^2 (beta - 1/6)(a1 - a0), as node displacements
        e_th = h**2 * (beta - 1.0 / 6.0) * (a1 - a0)
        e_x = jnp.cumsum(d.h[:, None] * nn * e_th[:, None], 0)
        e_node = jnp.sqrt(jnp.sum(e_x**2, -1)) / L
        e_node = jnp.where(ok, e_node, jnp.inf)
        y_err = (jnp.stack([e_node, jnp.zeros_like(e_node)]), jnp.zeros((), th0.dtype))
        k0 = (h * jnp.stack([om0, a0]), h * p0)
        k1 = (h * jnp.stack([om1, a1]), h * p1)
        dense = dict(y0=y0, y1=y1, k0=k0, k1=k1)
        result = dfx.RESULTS.where(ok, dfx.RESULTS.successful, dfx.RESULTS.nonlinear_divergence)
        return y1, y_err, dense, (a1, a0, h, lam1, G1, p1, iters), result


def _end_force(Rfree, h, nn):
    r"""$\boldsymbol\lambda$ minimizing $|\mathbf R+V^\top\boldsymbol\lambda|$, $V_i=h_i\mathbf n_i$ (2x2 normal equations)."""
    V = h[:, None] * nn
    A = V.T @ V
    return -jnp.linalg.solve(A, V.T @ Rfree)


class HHT(eqx.Module):
    r"""The implicit HHT-$\alpha$ integrator (the module docstring) for [`jaxrod.simulate`][]:
    a step set by accuracy, not by the stiffest bending mode.

    **Arguments:**

    - `alpha`: numerical dissipation, in $[-\tfrac13, 0]$. Default -0.02: the grid-scale
      bending modes, which a step far beyond their period cannot follow, are damped
      ($\rho_\infty=0.96$) instead of ringing in the error estimate (at 0, the trapezoidal
      rule, they keep the adaptive step small, and its energy can grow on the rotating
      chain: the module docstring).
    - `tol`: the local error allowed per step, as the nodes' position error over $L$
      (default 3e-6; on the brink snap of Psi0 = 30 deg, G/L = 0.5 its $v_s$ error is 2e-4,
      1e-3 and 3e-3 at N = 50, 100 and 200, growing with N: benchmarks/results/implicit.md;
      on the mirror image of that brink 1e-3 at N = 50, where the adaptive step's accept and
      reject decisions differ by round-off).
    - `newton_iters`: Newton iterations per step (default 8); a step that has not converged
      after them is retried shorter.
    - `newton_tol`: Newton's stop: the residual scaled by the diagonal of its matrix and the
      end condition (over $L$) below it (default 1e-8).
    - `dt0`: the first step attempted, in units of $T=L^2\sqrt{\lambda/B}$ (default 1e-4).
    """

    alpha: float = -0.02
    tol: float = 3e-6
    newton_iters: int = 8
    newton_tol: float = 1e-8
    extrapolate: float = 1.0
    dt0: float = 1e-4

    def __check_init__(self):
        from .._misc import check_int, check_number

        check_number("alpha", self.alpha, lo=-1.0 / 3.0, lo_open=False, hi=0.0, hi_open=False)
        check_number("tol", self.tol, lo=0.0)
        check_int("newton_iters", self.newton_iters, lo=1)
        check_number("newton_tol", self.newton_tol, lo=0.0)
        check_number("dt0", self.dt0, lo=0.0)

    def step_solver(self):
        """The diffrax solver that takes the steps."""
        return HHTStep(alpha=self.alpha, newton_iters=self.newton_iters, newton_tol=self.newton_tol)

    def controller(self, dtmin):
        """diffrax's PID controller on the nodes' position error (max norm, error order 3). A step
        below `dtmin` ends the run (`step_underflow`) rather than being accepted unconverged."""
        import optimistix as optx

        return dfx.PIDController(rtol=0.0, atol=self.tol, pcoeff=0.0, icoeff=1.0, norm=optx.max_norm,
                                 dtmin=dtmin, force_dtmin=False)
