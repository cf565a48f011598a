r"""Equations of motion of the inextensible creased strip, on the statics' energy.

Same discretization as the statics (`jaxrod.energy`): nodes $s_0=0<\dots<s_N=L$, segment $i$
of fixed length $h_i$ and tangent angle $\theta_i$, node positions
$\mathbf x_k=\sum_{i\le k}h_i\mathbf t_i$, $\mathbf t_i=(\cos\theta_i,\sin\theta_i)$,
$\mathbf n_i=(-\sin\theta_i,\cos\theta_i)$. The potential energy is the very function
the statics minimize, `jaxrod.energy.bending.bending_energy` (clamps as ghost segments,
$\theta_0=\alpha_L(t)$, $\theta_{N+1}=-\alpha_R(t)$), plus gravity $g\sum_k m_k y_k$ and, with
self-contact, the contact energy $E_c(\mathbf x)$ of `jaxrod.energy.contact` (its forces
$-\partial E_c/\partial\mathbf x_k$ act on the nodes; the end nodes are held).
Mass: the lumped node masses $m_k=\lambda\,(h_k+h_{k+1})/2$ of `discretize` (the end
nodes are held by the clamps). Kinetic energy $E_k=\tfrac12\sum_k m_k|\dot{\mathbf x}_k|^2$.

**Equations (a chain of rigid links with point masses).** Generalized forces on the
angles, $Q_i=-\partial(E_b+R)/\partial\theta_i$ (bending, and an optional Rayleigh
dissipation $R=\sum_k \frac{\eta}{2\ell_k}\dot\phi_k^2$ of the hinge rates, a Kelvin-Voigt
bending viscosity $\eta$), act on the nodes as force pairs $\pm (Q_i/h_i)\mathbf n_i$ on
nodes $i$ and $i-1$; node forces $\mathbf f_k$ add gravity $-m_k g\hat y$, viscous damping
$-\gamma m_k\dot{\mathbf x}_k$ and quadratic air drag $-c_d\,\bar\ell_k|\dot{\mathbf x}_k|\dot{\mathbf x}_k$
($\bar\ell_k=m_k/\lambda$). With $T_i$ the tension of link $i$,

$$m_k\ddot{\mathbf x}_k=\mathbf f_k+T_{k+1}\mathbf t_{k+1}-T_k\mathbf t_k\quad(k=1..N-1),\qquad
\mathbf t_i\cdot(\ddot{\mathbf x}_i-\ddot{\mathbf x}_{i-1})=-h_i\dot\theta_i^2,$$

the second being the second time derivative of $|\mathbf x_i-\mathbf x_{i-1}|=h_i$. Node 0
is fixed, node $N$ follows the end constraint $\mathbf x_N=(G,0)$ stabilized by
Baumgarte, $\ddot{\mathbf x}_N=-2\Omega\dot{\mathbf x}_N-\Omega^2(\mathbf x_N-(G,0))$. Eliminating
$\ddot{\mathbf x}$ gives a symmetric tridiagonal system for the $N$ tensions (row $i$:
$c_{i-1}T_{i-1}/m_{i-1}-(1/m_i+1/m_{i-1})T_i+c_iT_{i+1}/m_i=\dots$, $c_i=\mathbf t_i\cdot\mathbf t_{i+1}$,
$1/m_0=1/m_N=0$), one $O(N)$ `tridiagonal_solve`; then
$\ddot\theta_i=\mathbf n_i\cdot(\ddot{\mathbf x}_i-\ddot{\mathbf x}_{i-1})/h_i$. This is exactly
Lagrange's equation $M(\theta)\ddot\theta+\dots=Q-A^\top\mu$ with the dense
$M=J^\top\mathrm{diag}(m)J$, $J_{ki}=h_i\mathbf n_i[i\le k]$, without forming $M$.
Inextensibility is exact by construction; only the two end conditions are integrated.

State: $y=(\theta,\dot\theta)$, shape (2, N). Time in units of the scene's own $T=L/v^*$ if
$L=B=\lambda=1$ (the defaults), else in the units of the strip's fields.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..energy.bending import bending_energy, turning_angles
from ..energy.contact import contact_energy, contact_energy_nodes
from ..energy.geometry import at_arclength, discretize
from ..linalg.batched import tridiagonal_solve
from .._misc import check_bool, check_int, check_number, check_param, check_sign, is_concrete


class Protocol(eqx.Module):
    r"""Clamp angles as functions of time: linear ramps that stop at `t_stop`.

    $\alpha_L(t)=\alpha_{L,0}+\omega_L\,\min(\max(t,0),t_{stop})$, same for $\alpha_R$ (radians,
    the signs of docs/model.md; rates in rad per time unit). `t_stop=inf` ramps for ever."""

    alpha_left0: jax.Array
    alpha_right0: jax.Array
    rate_left: jax.Array
    rate_right: jax.Array
    t_stop: jax.Array

    def __init__(self, alpha_left0=0.0, alpha_right0=0.0, rate_left=0.0, rate_right=0.0, t_stop=jnp.inf):
        for name, v in [("alpha_left0", alpha_left0), ("alpha_right0", alpha_right0),
                        ("rate_left", rate_left), ("rate_right", rate_right)]:
            check_param(name, v)
        if is_concrete(t_stop) and not np.all(np.asarray(t_stop, float) >= 0.0):  # NaN fails too
            raise ValueError(f"t_stop must be >= 0 (inf: ramp for ever), got {t_stop!r}")
        self.alpha_left0 = jnp.asarray(alpha_left0, float)
        self.alpha_right0 = jnp.asarray(alpha_right0, float)
        self.rate_left = jnp.asarray(rate_left, float)
        self.rate_right = jnp.asarray(rate_right, float)
        self.t_stop = jnp.asarray(t_stop, float)

    def angles(self, t):
        """(alpha_L(t), alpha_R(t)) and their rates."""
        tau = jnp.clip(t, 0.0, self.t_stop)
        moving = (t > 0.0) & (t < self.t_stop)
        aL = self.alpha_left0 + self.rate_left * tau
        aR = self.alpha_right0 + self.rate_right * tau
        return aL, aR, jnp.where(moving, self.rate_left, 0.0), jnp.where(moving, self.rate_right, 0.0)


class Dissipation(eqx.Module):
    r"""Optional dissipation (all zero: conservative).

    - `damping` $\gamma$: viscous force $-\gamma\lambda\dot{\mathbf x}$ per length (units 1/T).
    - `drag` $c_d$: quadratic air drag $-c_d|\dot{\mathbf x}|\dot{\mathbf x}$ per length
      ($c_d=\tfrac12\rho_{air}C_Dw$; units $\lambda/L$).
    - `viscosity` $\eta$: Kelvin-Voigt bending viscosity, Rayleigh function
      $\sum_k\frac{\eta}{2\ell_k}\dot\phi_k^2$ (units $B\,T$); damps the fastest bending
      modes most (a dissipation filter)."""

    damping: jax.Array = 0.0
    drag: jax.Array = 0.0
    viscosity: jax.Array = 0.0

    def __init__(self, damping=0.0, drag=0.0, viscosity=0.0):
        for name, v in [("damping", damping), ("drag", drag), ("viscosity", viscosity)]:
            check_param(name, v, lo=0.0, lo_open=False)
        self.damping = jnp.asarray(damping, float)
        self.drag = jnp.asarray(drag, float)
        self.viscosity = jnp.asarray(viscosity, float)


def check_scene(scene):
    """Structural checks at trace time (ValueError naming the parameter)."""
    if scene.stretching is not None:
        raise ValueError("stretching: the dynamics are exactly inextensible; use stretching=None")


def check_run_settings(*, t1=2.0, direction=1.0, stop_at_snap=True, rtol=1e-8, atol=1e-8, dt=None,
                       dissipation=None, baumgarte=20.0, n_fine=None, n_frames=64, frame_window=None,
                       max_steps=None, courant=None, energy_tol=1e-2, constraint_tol=1e-6):
    """The settings of `jaxrod.simulate` (the same names and defaults): ValueError naming
    the first bad one; traced values pass unchecked. `snap_dynamics` calls it before it
    builds its start state, so that a bad setting fails before any statics are solved."""
    check_number("t1", t1, lo=0.0)
    check_sign("direction", direction)
    check_bool("stop_at_snap", stop_at_snap)
    check_number("rtol", rtol, lo=0.0, lo_open=False)
    check_number("atol", atol, lo=0.0, lo_open=False)
    if is_concrete(rtol) and is_concrete(atol) and float(rtol) == 0.0 and float(atol) == 0.0:
        raise ValueError("rtol, atol: at least one must be > 0, got rtol=0, atol=0")
    if dt is not None:
        check_number("dt", dt, lo=0.0)
    if dissipation is not None and not isinstance(dissipation, Dissipation):
        raise ValueError(f"dissipation must be a jaxrod.Dissipation, got {dissipation!r}")
    check_number("baumgarte", baumgarte, lo=0.0, lo_open=False)
    if n_fine is not None:
        check_int("n_fine", n_fine, lo=2)
    check_int("n_frames", n_frames, lo=1)
    if max_steps is not None:
        check_int("max_steps", max_steps, lo=1)
    if courant is not None:
        check_number("courant", courant, lo=0.0, hi=0.5)
    check_number("energy_tol", energy_tol, lo=0.0)
    check_number("constraint_tol", constraint_tol, lo=0.0)
    if frame_window is not None:
        try:
            ta, tb = frame_window
        except (TypeError, ValueError):
            raise ValueError(f"frame_window must be a pair (t_a, t_b), got {frame_window!r}") from None
        check_number("frame_window", ta, lo=0.0, lo_open=False)
        check_number("frame_window", tb, lo=0.0, lo_open=False)
        if all(is_concrete(x) for x in (ta, tb, t1)) and not float(ta) <= float(tb) <= float(t1):
            raise ValueError(f"frame_window must satisfy 0 <= t_a <= t_b <= t1 = {t1!r}, got {frame_window!r}")


def scene_at(scene, aL, aR):
    return eqx.tree_at(lambda s: (s.clamps.alpha_left, s.clamps.alpha_right), scene, (aL, aR))


def kinematics(theta, omega, d):
    """Node positions and velocities, shape (N+1, 2) each."""
    t = jnp.stack([jnp.cos(theta), jnp.sin(theta)], -1)
    n = jnp.stack([-jnp.sin(theta), jnp.cos(theta)], -1)
    zero = jnp.zeros((1, 2), theta.dtype)
    x = jnp.concatenate([zero, jnp.cumsum(d.h[:, None] * t, 0)])
    v = jnp.concatenate([zero, jnp.cumsum((d.h * omega)[:, None] * n, 0)])
    return x, v


def safe_norm(v):
    """|v| along the last axis with a finite gradient at v = 0 (double-where)."""
    s2 = jnp.sum(v**2, -1)
    pos = s2 > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, s2, 1.0)), 0.0)


def potential_energy(theta, scene, d):
    """$E_b$ (the statics' function) plus gravity on the free nodes and the contact energy."""
    e = bending_energy(theta, scene, d)
    if scene.contact is not None:
        e = e + contact_energy(theta, scene, d)
    if scene.gravity is not None:
        x = jnp.cumsum(d.h * jnp.sin(theta))
        e = e + scene.gravity.g * jnp.sum(d.node_mass[1:-1] * x[:-1])
    return e


def kinetic_energy(theta, omega, d):
    _, v = kinematics(theta, omega, d)
    return 0.5 * jnp.sum(d.node_mass[1:-1] * jnp.sum(v[1:-1] ** 2, -1))


def _bending_grads(theta, aL, aR, scene, d):
    """dE_b/dtheta (N,), dE_b/dalpha_L, dE_b/dalpha_R in one reverse pass."""

    def E(th, a_l, a_r):
        return bending_energy(th, scene, d._replace(theta_left=a_l, theta_right=-a_r))

    return jax.grad(E, argnums=(0, 1, 2))(theta, aL, aR)


def inverse_node_mass(d):
    """1/m of the nodes, 0 at the two end nodes (held by the clamps), shape (N+1,)."""
    m = d.node_mass
    return jnp.concatenate([jnp.zeros(1, m.dtype), 1.0 / m[1:-1], jnp.zeros(1, m.dtype)])


def link_pairs(p):
    """Node sums of per-link forces `p` (N, 2): +p_i on node i+1, -p_i on node i, (N+1, 2).
    Pads rather than scatter-adds (XLA:CPU fuses pads; its scatters are loops of their own)."""
    return jnp.pad(p, ((1, 0), (0, 0))) - jnp.pad(p, ((0, 1), (0, 0)))


def applied_forces(t, theta, omega, nn, v, scene, protocol, dissipation, d, x=None):
    r"""The applied node forces $\mathbf f_k$ (N+1, 2) of the module docstring (bending pairs
    $\pm(Q_i/h_i)\mathbf n_i$, hinge viscosity, gravity, damping, drag; no tensions), given the
    link normals `nn` (N, 2) and the node velocities `v` (N+1, 2) that the damping and drag
    act on, and with self-contact the contact forces $-\partial E_c/\partial\mathbf x_k$ at the
    node positions `x` (N+1, 2). Returns `(f, d, (gL, gR, rL, rR))`, `d` with the clamp
    angles at time t, `gL = dE_b/dalpha_L` etc."""
    aL, aR, rL, rR = protocol.angles(t)
    d = d._replace(theta_left=jnp.asarray(aL, theta.dtype), theta_right=-jnp.asarray(aR, theta.dtype))
    gE, gL, gR = _bending_grads(theta, d.theta_left, -d.theta_right, scene, d)
    Q = -gE
    eta = dissipation.viscosity
    full_rate = jnp.concatenate([rL[None], omega, -rR[None]])
    # Rayleigh dissipation: dR/d(omega_i) with phi_k-dot = diff(full_rate)
    phidot = jnp.diff(full_rate)
    tau = eta * phidot / d.ell  # (N+1,) hinge viscous moments
    Q = Q + (tau[1:] - tau[:-1])
    m = d.node_mass
    f = link_pairs((Q / d.h)[:, None] * nn)
    lam = scene.strip.line_density
    if scene.gravity is not None:
        f = f.at[:, 1].add(-m * scene.gravity.g)
    f = f - dissipation.damping * m[:, None] * v
    speed = safe_norm(v)
    f = f - dissipation.drag * (m / lam)[:, None] * speed[:, None] * v
    if scene.contact is not None:
        f = f - jax.grad(contact_energy_nodes)(x, scene, d)
    return f, d, (gL, gR, rL, rR)


def node_forces(t, theta, omega, scene, protocol, dissipation, d):
    r"""`applied_forces` from the angles, with what the tension solve and the clamp power
    need: `(f, x, v, d, (gL, gR, rL, rR))`, `x, v` the node positions and velocities
    (`kinematics`), the normals $\mathbf n_i=(-\sin\theta_i,\cos\theta_i)$."""
    x, v = kinematics(theta, omega, d)
    nn = jnp.stack([-jnp.sin(theta), jnp.cos(theta)], -1)
    f, d, g = applied_forces(t, theta, omega, nn, v, scene, protocol, dissipation, d, x)
    return f, x, v, d, g


def accelerations(t, y, scene, protocol, dissipation, baumgarte, d=None, with_work=False):
    r"""$\ddot\theta(t,\theta,\dot\theta)$, see the module docstring. With `with_work`, also
    the power of the clamps $\partial_{\alpha_L}V\,\dot\alpha_L+\partial_{\alpha_R}V\,\dot\alpha_R$.
    `d`: `discretize(scene)`, reused across calls (only the clamp angles change with t)."""
    theta, omega = y[0], y[1]
    sc = scene
    if d is None:
        d = discretize(scene)
    f, x, v, d, (gL, gR, rL, rR) = node_forces(t, theta, omega, scene, protocol, dissipation, d)
    tt = jnp.stack([jnp.cos(theta), jnp.sin(theta)], -1)
    nn = jnp.stack([-jnp.sin(theta), jnp.cos(theta)], -1)
    invm = inverse_node_mass(d)
    # prescribed accelerations of the end nodes (node N: Baumgarte-stabilized end condition)
    target = jnp.stack([sc.clamps.gap, jnp.zeros((), x.dtype)])
    a_fix = jnp.zeros_like(x).at[-1].set(-2.0 * baumgarte * v[-1] - baumgarte**2 * (x[-1] - target))
    b = invm[:, None] * f + a_fix  # acceleration without tensions
    c = jnp.sum(tt[1:] * tt[:-1], -1)  # (N-1,)
    diag = -(invm[1:] + invm[:-1])
    lower = jnp.concatenate([jnp.zeros(1, c.dtype), c * invm[1:-1]])
    upper = jnp.concatenate([c * invm[1:-1], jnp.zeros(1, c.dtype)])
    rhs = -d.h * omega**2 - jnp.sum(tt * (b[1:] - b[:-1]), -1)
    T = tridiagonal_solve(lower, diag, upper, rhs[:, None])[:, 0]
    F_t = jnp.zeros_like(x).at[:-1].add(T[:, None] * tt).at[1:].add(-T[:, None] * tt)
    a = b + invm[:, None] * F_t
    acc = jnp.sum(nn * (a[1:] - a[:-1]), -1) / d.h
    if with_work:
        return acc, gL * rL + gR * rR
    return acc


def vector_field(t, y, args):
    """diffrax vector field: y = (theta, omega) stacked, shape (2, N)."""
    scene, protocol, dissipation, baumgarte = args
    return jnp.stack([y[1], accelerations(t, y, scene, protocol, dissipation, baumgarte)])


def observables(t, y, scene, protocol, d=None):
    """Fold height, fold speed |dx/dt| at s = L/2, each crease's height and speed (at its
    arclength, `Strip.crease_list` order), bending and kinetic energy, node speeds,
    end-constraint error."""
    theta, omega = y[0], y[1]
    aL, aR, _, _ = protocol.angles(t)
    sc = scene_at(scene, aL, aR)
    if d is None:
        d = discretize(sc)
    d = d._replace(theta_left=jnp.asarray(aL, theta.dtype), theta_right=-jnp.asarray(aR, theta.dtype))
    x, v = kinematics(theta, omega, d)
    k = sc.mesh.n // 2
    speed = safe_norm(v)
    target = jnp.stack([sc.clamps.gap, jnp.zeros((), x.dtype)])
    if sc.strip.creases is None:  # the centred crease sits on node N/2: its height and speed are the fold's
        c_height, c_speed = x[k, 1][None], speed[k][None]
    else:
        cpos = sc.strip.crease_list()[0].astype(x.dtype)
        c_height, c_speed = at_arclength(x, d.s, cpos)[:, 1], safe_norm(at_arclength(v, d.s, cpos))
    return dict(
        fold_height=x[k, 1],
        crease_height=c_height,
        crease_speed=c_speed,
        fold_velocity=v[k],
        fold_speed=speed[k],
        bending=bending_energy(theta, sc, d),
        potential=potential_energy(theta, sc, d),
        kinetic=kinetic_energy(theta, omega, d),
        constraint=safe_norm(x[-1] - target),
        speed=speed,
        positions=x,
    )


__all__ = ["Protocol", "Dissipation", "vector_field", "observables", "turning_angles"]
