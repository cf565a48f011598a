r"""The strip as an actuator: a clamp program, balls it strikes, the hits and the energy balance.

`actuate(scene, bodies, program)` integrates the strip (the equations of
`jaxrod.dynamics._equations`) together with the balls of `bodies` (`jaxrod.dynamics._bodies`)
under a clamp `program` (`jaxrod.Program`, any number of knots, so one run can hold several
snaps), from a stable state at the program's first angles.

**Integrator.** RATTLE for the strip (`jaxrod.dynamics._rattle`) and velocity Verlet for the
balls, in one step: half kick of both with the forces at $t_n$, drift (the strip's positions
projected back onto its links), forces at $t_{n+1}$, second half kick (the strip's velocities
projected onto the links' tangents). The contacts are conservative forces of the positions, so
the coupled step stays symplectic when undamped. Dissipative forces (the strip's `Dissipation`,
the table's friction) are evaluated at the half-step velocities as in `simulate`.

**Step.** $\Delta t=\min(\text{courant}\,h_{\min}^2,\ 2\cdot10^{-4},\ 0.2/\omega_b,\ 1/\gamma_{\max})$
in units of $T$: $\omega_b$ the frequency of the stiffest contact (`_body_omega`), so that the
contact's own oscillation is resolved with about 30 steps, and
$\gamma_{\max}=16\eta/(\lambda h_{\min}^4)$ the damping rate the hinge viscosity $\eta$ gives the
highest bending mode ($\omega_{\max}^2=16B/(\lambda h^4)$, rate $\eta\omega_{\max}^2/B$), which the
explicit kicks must resolve (with $\eta$ = 1e-2 a run at N = 32 and the contact's step failed
its constraint solve). Measured: the energy balance of one undamped snap that strikes a
ball closes below 5e-3 at N = 16 (`tests/test_actuate.py`), with the default dissipation to
4e-5 for one designed program and 1.4e-4 over three programs in sequence
(`benchmarks/results/actuate.md`).

**Bookkeeping** (one sample per diffrax step of `substeps` RATTLE steps):

* energy balance $E=E_k+E_{k,b}+V+E_c-W+D$, conserved: strip and ball kinetic energies,
  $V$ the strip's potential (bending, gravity, self-contact), $E_c$ the bodies' contact,
  floor and gravity energy, $W$ the clamps' work (trapezoidal rule on their power
  $\partial_{\alpha_L}V\dot\alpha_L+\partial_{\alpha_R}V\dot\alpha_R$) and $D$ the energy
  dissipated (trapezoidal rule on the power the strip and the balls lose to the damping, drag,
  hinge viscosity and table friction; for the viscosity that is the Rayleigh dissipation $2R$
  less the power the turning clamps feed their own hinges' viscous moments). `energy_error` is $\max_t|E(t)-E(0)|$ over $\max(|E(0)|,\max_t|W|,\max_tD,B/L)$;
* the impulse $\mathbf J_m(t)=\int_0^t\mathbf F_m\,dt$ the strip gives each ball, by the same
  trapezoidal rule as the ball's velocity update, so that $M_m(\mathbf v_m-\mathbf v_m(0))=\mathbf J_m$
  when nothing else touches the ball;
* hits: ball $m$ is hit at the first sample where the strip pushes it ($|\mathbf F_m|>0$:
  the penalty is exactly zero outside the layer); it is released at the first sample after
  that without contact. `launch_velocity` is its velocity at release (at the end if never
  released), `impulse_first` the impulse of that first contact, `peak_speed` its largest
  speed over the run.

**Verdicts** (`result`): `successful`; `constraint_solve_failed` (RATTLE's link solve did not
converge: the run stops there); `nonfinite`; `steps_exhausted`; `object_penetrated` (a ball's
contact layer was exhausted: some gap went below zero; raise `stiffness` or `thickness`);
`energy_drift` (`energy_error` above `energy_tol`); `state_not_found` (no stable start state
at the program's first angles).
"""

from __future__ import annotations

import math

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._bodies import Bodies, body_clearance, body_energy, friction_force, quadrature_points, strip_body_energy
from ._equations import Dissipation, check_scene, inverse_node_mass, kinematics, kinetic_energy, potential_energy, scene_at
from ._program import Program
from ._rattle import FixedStepRattle, angles, project_velocity, rattle_forces_and_rates, shake, substeps
from ._simulate import DT_CAP
from ..energy.contact import safe_norm
from ..energy.geometry import discretize, scene_dtype
from ..results import RESULTS
from .._misc import check_int, check_number
from .._compile import dynamics_jit


BODY_COURANT = 0.2
"""The step is at most BODY_COURANT / omega_b (see the module docstring)."""
ACTUATOR_DAMPING = 1.0
r"""Default viscous damping $\gamma$ of `actuate` (1/T): the strip's ring-down decays as
$e^{-\gamma t/2}$, to 1/e in 2 T, so that holds of a few T let the strip settle between
snaps. Calibrate it for a real strip with `damping_from_ringdown`."""
ACTUATOR_VISCOSITY = 1e-3
r"""Default hinge viscosity $\eta$ of `actuate` ($B\,T$; a damping ratio of a few percent on the
fundamental): it damps the grid-scale bending modes that ring after a snap. Without it a
ball's launch speed depends on the phase of that ringing at the hit. Measured at
$\Psi_0=60^\circ$, $G/L=0.5$, N = 16, the right ball of `jaxrod.paper.fig4_bodies` under the
program (60, -30) deg: without viscosity its speed goes up and down (15.48, 15.52, 15.56,
15.56, 15.54, ...) as the left peak moves by 0.25 deg, so a gradient misleads a design; with
it the speed rises evenly by 0.0195 v* per 0.25 deg, and is 6 % lower (14.57 against 15.54)."""


def _dissipated_power(omega, v, vb, rates, args):
    """Power of the dissipative forces at node velocities `v`, angular rates `omega`, ball
    velocities `vb` and clamp rates `rates = (rL, rR)` (damping, drag, hinge viscosity, table
    friction)."""
    scene, _, dissipation, bodies, d = args
    m = d.node_mass
    s2 = jnp.sum(v**2, -1)
    lam = scene.strip.line_density
    p = dissipation.damping * jnp.sum(m * s2) + dissipation.drag * jnp.sum((m / lam) * s2 * safe_norm(v))
    rL, rR = rates
    full_rate = jnp.concatenate([rL[None], omega, -rR[None]])
    tau = dissipation.viscosity * jnp.diff(full_rate) / d.ell  # hinge viscous moments
    # minus the power of the viscous generalized forces on the angles: 2R less the power the
    # turning clamps put into their own hinges' viscous moments (those moments are the
    # clamps' to supply, not the strip's to lose)
    p = p - jnp.sum((tau[1:] - tau[:-1]) * omega)
    return p - jnp.sum(friction_force(vb, bodies) * vb)


def _forces(t, theta, omega, x, v, xb, vb, args, q):
    """Strip node forces, clamp power, ball forces, the strip's force on each ball and the
    dissipated power (`q`: the contact's quadrature points per segment)."""
    scene, program, dissipation, bodies, d = args
    f, clamp_power, rates = rattle_forces_and_rates(t, theta, omega, x, v, (scene, program, dissipation, None, d))
    gx, gb = jax.grad(strip_body_energy, argnums=(0, 1))(x, xb, bodies, q)
    fs = -gb
    fb = fs - jax.grad(body_energy)(xb, bodies, scene.gravity) + friction_force(vb, bodies)
    return f - gx, clamp_power, fb, fs, _dissipated_power(omega, v, vb, rates, args)


class RattleBodies(FixedStepRattle):
    """RATTLE for the strip and velocity Verlet for the balls in one step (module docstring).
    State `y = (q, acc, xb, vb, J)`: `q` (2, N) angles and rates, `acc` (W, D), ball
    positions and velocities (M, 2), impulses (M, 2). `args = (scene, program, dissipation,
    bodies, d)`; `quadrature` the contact's points per segment."""

    quadrature: int = 8

    def init(self, terms, t0, t1, y0, args):
        scene, _, _, _, d = args
        q, _, xb, vb, _ = y0
        theta, omega = q[0], q[1]
        invm = inverse_node_mass(d)
        x, v = kinematics(theta, omega, d)
        x = x.at[-1].set(jnp.stack([scene.clamps.gap, jnp.zeros((), x.dtype)]))
        v = project_velocity(x, v.at[-1].set(0.0), invm)
        f, p, fb, fs, pd = _forces(t0, theta, omega, x, v, xb, vb, args, self.quadrature)
        mu = jnp.zeros(theta.shape, theta.dtype)
        return x, v, theta, f, p, fb, fs, pd, mu

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        del made_jump  # fixed steps only
        rest, st1, ok = substeps(self.substeps, t0, t1, y0[1:], solver_state,
                                 lambda ta, tb, r, st: self._substep(ta, tb, r, args, st))
        x1, v1, th1 = st1[:3]
        _, om1 = angles(x1, v1, th1)
        y1 = (jnp.stack([th1, om1]), *rest)
        result = dfx.RESULTS.where(ok, dfx.RESULTS.successful, dfx.RESULTS.nonlinear_divergence)
        return y1, None, dict(y0=y0, y1=y1), st1, result

    def _substep(self, t0, t1, rest, args, st):
        """One step; `rest` = (acc, xb, vb, J), the state but the angles (which the macro step
        reads off the solver state once at its end)."""
        _, _, _, bodies, d = args
        x0, v0, th0, f0, p0, fb0, fs0, pd0, mu = st
        acc, xb0, vb0, J = rest
        invm = inverse_node_mass(d)
        minv = 1.0 / bodies.mass
        dt = t1 - t0
        x1, mu, converged = shake(x0, v0, f0, mu, invm, d.h, dt, self.shake_iters, self.shake_tol)
        vh = (x1 - x0) / dt
        vbh = vb0 + 0.5 * dt * minv[:, None] * fb0
        xb1 = xb0 + dt * vbh
        th1, omh = angles(x1, vh, th0)
        f1, p1, fb1, fs1, pd1 = _forces(t1, th1, omh, x1, vh, xb1, vbh, args, self.quadrature)
        v1 = project_velocity(x1, vh + 0.5 * dt * invm[:, None] * f1, invm)
        vb1 = vbh + 0.5 * dt * minv[:, None] * fb1
        acc1 = acc + 0.5 * dt * jnp.stack([p0 + p1, pd0 + pd1])
        rest1 = (acc1, xb1, vb1, J + 0.5 * dt * (fs0 + fs1))
        return rest1, (x1, v1, th1, f1, p1, fb1, fs1, pd1, mu), converged


def _no_field(t, y, args):
    """The term diffrax asks for; RattleBodies computes its own forces and never calls it."""
    return jax.tree.map(jnp.zeros_like, y)


class Actuation(eqx.Module):
    r"""A run of `actuate` (see the module docstring).

    Samples `t` (n,): `fold_height`, `height_left`, `height_right` (y at L/4, L/2, 3L/4),
    `kinetic`, `potential` (strip), `ball_kinetic`, `body_energy` (contacts, floor, ball
    gravity), `clamp_work`, `dissipated`, `energy` (the balance E, conserved), `alpha_left`,
    `alpha_right` (rad); per ball (n, M, 2) `ball_position`, `ball_velocity`, `strip_force`,
    `impulse`, and `ball_clearance` (n, M). Frames `t_frames` (F,): `positions` (F, N+1, 2),
    `ball_frames` (F, M, 2). Per ball (M,): `hit`, `t_hit`, `t_release` (NaN if none),
    `impulse_first` (M, 2), `launch_velocity` (M, 2), `launch_speed`, `peak_speed`,
    `min_clearance`, `ball_radius`. Scalars: `energy_error`, `strip_mass` ($\lambda L$), `num_steps`, `result` ([`jaxrod.RESULTS`][]).
    `names`: the balls' names."""

    t: jax.Array
    fold_height: jax.Array
    height_left: jax.Array
    height_right: jax.Array
    kinetic: jax.Array
    potential: jax.Array
    ball_kinetic: jax.Array
    body_energy: jax.Array
    clamp_work: jax.Array
    dissipated: jax.Array
    energy: jax.Array
    alpha_left: jax.Array
    alpha_right: jax.Array
    ball_position: jax.Array
    ball_velocity: jax.Array
    strip_force: jax.Array
    impulse: jax.Array
    ball_clearance: jax.Array
    t_frames: jax.Array
    positions: jax.Array
    ball_frames: jax.Array
    hit: jax.Array
    t_hit: jax.Array
    t_release: jax.Array
    impulse_first: jax.Array
    launch_velocity: jax.Array
    launch_speed: jax.Array
    peak_speed: jax.Array
    min_clearance: jax.Array
    energy_error: jax.Array
    strip_mass: jax.Array
    ball_radius: jax.Array
    num_steps: jax.Array
    result: RESULTS
    names: tuple = eqx.field(static=True)

    def hits(self) -> list[dict]:
        """Every contact of the strip with a ball, in time order (host-side): `name`, `time`
        (the first sample in contact), `impulse` (the strip's impulse over that contact, a
        vector, and `impulse_norm`), `launch_velocity` and `launch_speed` (the ball's velocity at
        the first sample after it), `contact` (1 for a ball's first contact, 2 for its second,
        ...). A ball's first contact is the one `launch_speed` and `impulse_first` report."""
        t = np.asarray(self.t)
        ok = np.isfinite(t)
        force = np.sqrt(np.sum(np.asarray(self.strip_force)[ok] ** 2, -1))
        J, vel = np.asarray(self.impulse)[ok], np.asarray(self.ball_velocity)[ok]
        t = t[ok]
        out = []
        for m, name in enumerate(self.names):
            on = np.concatenate([[0], (force[:, m] > 0).astype(int), [0]])
            starts, ends = np.nonzero(np.diff(on) == 1)[0], np.nonzero(np.diff(on) == -1)[0]
            for c, (a, b) in enumerate(zip(starts, ends)):
                after = min(b, t.size - 1)
                dJ = J[after, m] - (J[a - 1, m] if a > 0 else 0.0)
                v = vel[after, m]
                out.append(dict(name=name, time=float(t[a]), impulse=[float(dJ[0]), float(dJ[1])],
                                impulse_norm=float(np.hypot(*dJ)), launch_velocity=[float(v[0]), float(v[1])],
                                launch_speed=float(np.hypot(*v)), contact=c + 1))
        return sorted(out, key=lambda h: h["time"])

    def snaps(self, *, min_speed=2.0, merge=0.1) -> list[dict]:
        r"""The strip's changes of state in time order (host-side): snaps and drifts.

        The state is the signs of the heights at $L/4$, $L/2$, $3L/4$ (`height_left`,
        `fold_height`, `height_right`). Sign changes less than `merge` apart form one event, and
        an event that ends where it began (a flicker) is dropped. Each event gives `time` (its
        first change), `from` and `to` (the half-state labels before and after: "D"/"U" for the
        signs of the left and right quarter heights, left first, as in the design package's
        actuator study), `halves` (those that flipped), `fold` ("up", "down" or None: the fold's
        own crossing), `speed` (the strip's largest RMS speed $\sqrt{2E_k/(\lambda L)}$ within
        `merge` of the event) and `kind`: "snap" when that speed exceeds `min_speed` (v*), else
        "drift" (a quasi-static crossing of the clamp line)."""
        t = np.asarray(self.t)
        ok = np.isfinite(t)
        t = t[ok]
        sg = np.stack([np.asarray(self.height_left)[ok] > 0, np.asarray(self.fold_height)[ok] > 0,
                       np.asarray(self.height_right)[ok] > 0], -1)
        rms = np.sqrt(2.0 * np.maximum(np.asarray(self.kinetic)[ok], 0.0) / float(self.strip_mass))
        changes = np.nonzero(np.any(sg[1:] != sg[:-1], -1))[0] + 1
        groups = []
        for k in changes:
            if groups and t[k] - t[groups[-1][1]] < merge:
                groups[-1][1] = k
            else:
                groups.append([k, k])

        def label(x):
            return ("U" if x[0] else "D") + ("U" if x[2] else "D")

        out = []
        for a, b in groups:
            before, after = sg[a - 1], sg[b]
            if np.array_equal(before, after):
                continue
            win = (t >= t[a] - merge) & (t <= t[b] + merge)
            speed = float(np.max(rms[win]))
            fold = None if before[1] == after[1] else ("up" if after[1] else "down")
            out.append({"time": float(t[a]), "from": label(before), "to": label(after),
                        "halves": [side for side, q in (("left", 0), ("right", 2)) if before[q] != after[q]],
                        "fold": fold, "speed": speed, "kind": "snap" if speed > min_speed else "drift"})
        return out


def damping_from_ringdown(t, y):
    r"""The viscous damping $\gamma$ (1/time) of a measured ring-down `y(t)` (a displacement
    of the strip, e.g. its fold height, sampled at times `t` after the last snap).

    Mass-proportional damping $-\gamma\lambda\dot{\mathbf x}$ decays every mode of the strip
    as $e^{-\gamma t/2}$, so $\gamma=-2s$, $s$ the slope of $\ln$ of the oscillation's peak
    amplitudes against time: the logarithmic decrement, fitted by least squares to one peak
    per half cycle (the largest $|y-\bar y|$ between consecutive crossings of $\bar y$, the
    last third's mean). Needs at least three half cycles; ValueError otherwise."""
    t = np.asarray(t, float)
    y = np.asarray(y, float)
    if t.shape != y.shape or t.ndim != 1 or t.size < 8:
        raise ValueError("t, y must be 1-d arrays of the same length (at least 8 samples)")
    yc = y - np.mean(y[2 * y.size // 3:])
    cross = np.nonzero(np.signbit(yc[1:]) != np.signbit(yc[:-1]))[0] + 1
    peaks = [a + int(np.argmax(np.abs(yc[a:b]))) for a, b in zip(cross[:-1], cross[1:])]
    peaks = np.asarray(peaks, int)
    if peaks.size < 3:
        raise ValueError(f"y: a ring-down needs at least 3 peaks (half cycles), found {peaks.size}")
    s = np.polyfit(t[peaks], np.log(np.abs(yc[peaks])), 1)[0]
    return -2.0 * s


def _body_omega(bodies, scene):
    r"""$\omega_b$ of the module docstring: the larger of a strip element's frequency on the
    contact, $\sqrt{2k/(\delta\lambda)}$, and the lightest ball's on a patch of the largest
    radius, $\sqrt{2k\sqrt{2R\delta}/(\delta M)}$ (from concrete leaves)."""
    k, delta = float(bodies.stiffness), float(bodies.thickness)
    r_max, m_min = float(np.max(np.asarray(bodies.radius))), float(np.min(np.asarray(bodies.mass)))
    lam = float(scene.strip.line_density)
    return max(math.sqrt(2.0 * k / (delta * lam)), math.sqrt(2.0 * k * math.sqrt(2.0 * r_max * delta) / (delta * m_min)))


@dynamics_jit
def _run(scene, bodies, program, theta0, dissipation, t1, dt, substeps, n_samples, n_frames, energy_tol, quad):
    dtype = theta0.dtype
    d = discretize(scene)
    args = (scene, program, dissipation, bodies, d)
    n = scene.mesh.n
    ts = jnp.linspace(0.0, t1, n_samples)
    tf = jnp.linspace(0.0, t1, n_frames)

    def strip_at(t, q):
        aL, aR, _, _ = program.angles(t)
        dd = d._replace(theta_left=jnp.asarray(aL, dtype), theta_right=-jnp.asarray(aR, dtype))
        x, v = kinematics(q[0], q[1], dd)
        return aL, aR, dd, x, v

    y0 = (jnp.stack([theta0, jnp.zeros_like(theta0)]), jnp.zeros(2, dtype), bodies.position.astype(dtype),
          bodies.velocity.astype(dtype), jnp.zeros_like(bodies.position, dtype=dtype))

    def obs(t, y, a):
        # the contact is evaluated at the sampled state (one value-and-gradient pass): the
        # step's own force, read through diffrax's linear interpolation between steps, would
        # mark a sample next to a contact as touching by an interpolation weight of 1e-12
        q, acc, xb, vb, J = y
        aL, aR, dd, x, _ = strip_at(t, q)
        e_contact, g_contact = jax.value_and_grad(strip_body_energy, argnums=1)(x, xb, bodies, quad)
        return dict(
            fold_height=x[n // 2, 1], height_left=x[n // 4, 1], height_right=x[(3 * n) // 4, 1],
            kinetic=kinetic_energy(q[0], q[1], dd),
            potential=potential_energy(q[0], scene_at(scene, aL, aR), dd),
            ball_kinetic=0.5 * jnp.sum(bodies.mass * jnp.sum(vb**2, -1)),
            body_energy=e_contact + body_energy(xb, bodies, scene.gravity),
            work=acc[0], dissipated=acc[1], alpha_left=aL, alpha_right=aR,
            ball_position=xb, ball_velocity=vb, strip_force=-g_contact, impulse=J,
            ball_clearance=body_clearance(x, xb, bodies))

    def frames(t, y, a):
        q, _, xb, _, _ = y
        _, _, _, x, _ = strip_at(t, q)
        return dict(positions=x, ball_frames=xb)

    saveat = dfx.SaveAt(subs=[dfx.SubSaveAt(ts=ts, fn=obs), dfx.SubSaveAt(ts=tf, fn=frames)])
    steps = int(n_samples - 1) + 8
    sol = dfx.diffeqsolve(dfx.ODETerm(_no_field), RattleBodies(quadrature=quad, substeps=substeps), 0.0, t1, dt, y0, args,
                          saveat=saveat, stepsize_controller=dfx.ConstantStepSize(), max_steps=steps,
                          throw=False)
    o, fr = sol.ys
    reached = jnp.isfinite(sol.ts[0])
    energy = o["kinetic"] + o["ball_kinetic"] + o["potential"] + o["body_energy"] - o["work"] + o["dissipated"]
    fin = reached & jnp.isfinite(energy)
    e0 = energy[0]
    scale = jnp.maximum(jnp.maximum(jnp.abs(e0), jnp.max(jnp.where(fin, jnp.abs(o["work"]), 0.0))),
                        jnp.maximum(jnp.max(jnp.where(fin, o["dissipated"], 0.0)),
                                    scene.strip.bending_stiffness / scene.strip.length))
    err = jnp.max(jnp.where(fin, jnp.abs(energy - e0), 0.0)) / scale
    # hits
    fmag = jnp.sqrt(jnp.sum(o["strip_force"] ** 2, -1))  # (n, M)
    touching = (fmag > 0) & reached[:, None]
    hit = jnp.any(touching, 0)
    i_hit = jnp.argmax(touching, 0)
    idx = jnp.arange(ts.shape[0])[:, None]
    after = (idx > i_hit[None, :]) & ~touching & reached[:, None]
    released = jnp.any(after, 0)
    i_last = jnp.maximum(jnp.sum(reached) - 1, 0)
    i_rel = jnp.where(released, jnp.argmax(after, 0), i_last)
    cols = jnp.arange(bodies.count)
    vrel = o["ball_velocity"][i_rel, cols]
    J_first = o["impulse"][i_rel, cols] - jnp.where((i_hit > 0)[:, None], o["impulse"][jnp.maximum(i_hit - 1, 0), cols], 0.0)
    speed = safe_norm(o["ball_velocity"])
    peak = jnp.max(jnp.where(reached[:, None], speed, 0.0), 0)
    min_clear = jnp.min(jnp.where(reached[:, None], o["ball_clearance"], jnp.inf), 0)
    nanv = jnp.full_like(ts[0], jnp.nan)
    sr = sol.result
    res = RESULTS.where(sr == dfx.RESULTS.successful, RESULTS.successful, RESULTS.integration_failed)
    res = RESULTS.where(sr == dfx.RESULTS.max_steps_reached, RESULTS.steps_exhausted, res)
    res = RESULTS.where(sr == dfx.RESULTS.nonlinear_divergence, RESULTS.constraint_solve_failed, res)
    finite_all = jnp.all(jnp.where(reached, jnp.isfinite(energy), True))
    res = RESULTS.where((res == RESULTS.successful) & ~finite_all, RESULTS.nonfinite, res)
    res = RESULTS.where((res == RESULTS.successful) & (jnp.min(min_clear) < 0), RESULTS.object_penetrated, res)
    res = RESULTS.where((res == RESULTS.successful) & ~(err <= energy_tol), RESULTS.energy_drift, res)
    return Actuation(
        t=jnp.where(reached, ts, jnp.inf), fold_height=o["fold_height"], height_left=o["height_left"],
        height_right=o["height_right"], kinetic=o["kinetic"], potential=o["potential"],
        ball_kinetic=o["ball_kinetic"], body_energy=o["body_energy"], clamp_work=o["work"],
        dissipated=o["dissipated"], energy=energy, alpha_left=o["alpha_left"], alpha_right=o["alpha_right"],
        ball_position=o["ball_position"], ball_velocity=o["ball_velocity"], strip_force=o["strip_force"],
        impulse=o["impulse"], ball_clearance=o["ball_clearance"], t_frames=tf, positions=fr["positions"],
        ball_frames=fr["ball_frames"], hit=hit, t_hit=jnp.where(hit, ts[i_hit], nanv),
        t_release=jnp.where(hit & released, ts[i_rel], nanv), impulse_first=jnp.where(hit[:, None], J_first, 0.0),
        launch_velocity=jnp.where(hit[:, None], vrel, 0.0),
        launch_speed=jnp.where(hit, safe_norm(vrel), 0.0), peak_speed=peak,
        min_clearance=min_clear, energy_error=err,
        strip_mass=scene.strip.line_density * scene.strip.length, ball_radius=bodies.radius, num_steps=sol.stats["num_steps"] * substeps,
        result=res, names=bodies.names)


ACTUATE_COURANT, ACTUATE_SUBSTEPS = 0.45, 4
"""`actuate`'s default RATTLE settings: the strip's step factor and steps per sample."""


def _rattle_settings(solver, courant, substeps):
    """`(courant, substeps)` from `actuate`'s `solver` (None or a `jaxrod.Rattle`, merged with
    the keywords as `jaxrod.simulate` merges them) and keywords, defaults filled in."""
    from ._rattle import Rattle
    from ._simulate import _resolve_solver

    if solver is not None and not isinstance(solver, Rattle):
        raise ValueError(f"solver: actuate integrates the strip and its balls with RATTLE; give "
                         f"jaxrod.Rattle(courant=..., substeps=...) or None, got {solver!r}")
    if solver is not None:
        _, _, courant, substeps = _resolve_solver(solver, courant, substeps)
    return (ACTUATE_COURANT if courant is None else courant, ACTUATE_SUBSTEPS if substeps is None else substeps)


def actuate(scene, bodies: Bodies, program: Program, *, theta0=None, state="down", t1=None,
            dissipation: Dissipation | None = None, courant=None, substeps=None, sample_dt=None,
            n_frames=96, energy_tol=1e-2, solver=None) -> Actuation:
    r"""Run the clamp `program` on the strip of `scene` with the balls of `bodies` (module
    docstring).

    **Arguments:** `theta0` the start angles (default: the stable `state`, "down" or "up", of
    `scene` at the program's first clamp angles, `jaxrod.initial_state`); `t1` the end time
    (default: the program's last knot plus 2 T); `dissipation` (default
    `Dissipation(damping=ACTUATOR_DAMPING, viscosity=ACTUATOR_VISCOSITY)`; `Dissipation()`
    for an undamped run);
    `courant` the strip's step factor (RATTLE, below 0.5; default 0.45); `substeps` RATTLE steps
    per sample (default 4); `solver` a [`jaxrod.Rattle`][] carrying them instead (the balls'
    contact is integrated with the strip's RATTLE steps: no other solver here; a keyword that
    contradicts the object is refused by name);
    `sample_dt` the sample spacing (default: one sample per `substeps` steps); `n_frames`
    frames for animations; `energy_tol` the energy balance's tolerance (`energy_drift`).

    **Returns:** an [`jaxrod.Actuation`][].
    """
    from ..statics import initial_state

    if not isinstance(bodies, Bodies):
        raise ValueError(f"bodies must be a jaxrod.Bodies, got {bodies!r}")
    if not isinstance(program, Program):
        raise ValueError(f"program must be a jaxrod.Program, got {program!r}")
    check_scene(scene)
    if scene_dtype(scene) != jnp.float64:
        raise ValueError("actuate needs a float64 scene (jax.config.update('jax_enable_x64', True) before "
                         "building it): float32 cannot hold the energy balance over thousands of contact steps")
    if state not in ("down", "up"):
        raise ValueError(f"state must be 'down' or 'up', got {state!r}")
    courant, substeps = _rattle_settings(solver, courant, substeps)
    check_number("courant", courant, lo=0.0, hi=0.5)
    check_int("substeps", substeps, lo=1)
    check_int("n_frames", n_frames, lo=2)
    check_number("energy_tol", energy_tol, lo=0.0)
    if dissipation is None:
        dissipation = Dissipation(damping=ACTUATOR_DAMPING, viscosity=ACTUATOR_VISCOSITY)
    if not isinstance(dissipation, Dissipation):
        raise ValueError(f"dissipation must be a jaxrod.Dissipation, got {dissipation!r}")
    if t1 is None:
        t1 = float(program.duration) + 2.0
    check_number("t1", t1, lo=0.0)
    frac_min = float(np.min(np.diff(np.asarray(scene.mesh.fractions))))
    st = scene.strip
    T = float(st.length) ** 2 * math.sqrt(float(st.line_density) / float(st.bending_stiffness))
    dt = min(courant * frac_min**2, DT_CAP) * T
    try:
        omega_b = _body_omega(bodies, scene)
    except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError):
        raise ValueError("bodies: stiffness, thickness, radius and mass set the step and must be concrete "
                         "(call actuate outside jit; positions, velocities and the program may be traced)") from None
    dt = min(dt, BODY_COURANT / omega_b)
    eta = float(dissipation.viscosity)
    if eta > 0:  # the explicit hinge viscosity's own limit (module docstring)
        h_min = frac_min * float(st.length)
        dt = min(dt, float(st.line_density) * h_min**4 / (16.0 * eta))
    macro = dt * substeps
    if sample_dt is not None:
        check_number("sample_dt", sample_dt, lo=0.0)
        macro = min(macro, float(sample_dt))
    n_samples = int(math.ceil(float(t1) / macro)) + 1
    macro = float(t1) / (n_samples - 1)
    ok = jnp.ones((), bool)
    if theta0 is None:
        aL, aR, _, _ = program.angles(0.0)
        eq = initial_state(scene_at(scene, aL, aR), state)
        theta0, ok = eq.theta, eq.result == RESULTS.successful
    theta0 = jnp.asarray(theta0, jnp.float64)
    quad = quadrature_points(bodies, np.max(np.diff(np.asarray(scene.mesh.fractions))) * float(st.length))
    act = _run(scene, bodies, program, theta0, dissipation, float(t1), macro, int(substeps), n_samples,
               int(n_frames), float(energy_tol), quad)
    return eqx.tree_at(lambda a: a.result, act, RESULTS.where(ok, act.result, RESULTS.state_not_found))


__all__ = ["Actuation", "actuate", "damping_from_ringdown", "RattleBodies", "ACTUATOR_DAMPING", "ACTUATOR_VISCOSITY",
           "BODY_COURANT"]
