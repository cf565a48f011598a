r"""Time integration of the snap with diffrax: solvers, events, the sampled trajectory.

`simulate` integrates $y=((\theta,\dot\theta), W)$ where $W(t)=\int_0^t \partial_tV\,dt$ is the
work done by the rotating clamps (so $E_k+V-W$ is conserved when undamped), with a solver
given as a strategy object:

* [`jaxrod.Rattle`][] (default, also `"rattle"`): RATTLE in the Cartesian node coordinates of
  the link chain (`jaxrod.dynamics._rattle`): symplectic, second order, link lengths and both
  ends exact, one bending gradient per fixed step just below its stability limit
  $\omega_{\max}\Delta t<2$, $\omega_{\max}=4\sqrt{B/\lambda}/h^2$: the step count grows like $N^2$;
* [`jaxrod.HHT`][]: the implicit HHT-$\alpha$ method on the angles (`jaxrod.dynamics._implicit`),
  Newton along the chain in $O(N)$ per iteration, its step set by a local error test on the
  node positions rather than by the stiffest mode;
* any diffrax solver instance, or the strings `"tsit5"`, `"dopri5"`, `"dopri8"` (explicit
  adaptive Runge-Kutta) and `"kvaerno3"`, `"kvaerno5"` (ESDIRK, dense-Jacobian Newton),
  adaptive with a PID step-size controller (`rtol`, `atol`).

The trade between them is measured in benchmarks/results/implicit.md and dynamics.md.
A boolean diffrax `Event` stops the run
once the snap is over: the fold node has crossed $y=0$ in the snapping direction and then
reversed its vertical velocity (its first overshoot), or at `t1`.

Observables (fold height, fold velocity, energies) are saved on a fine uniform grid of
`n_fine` times on $[0,t_1]$ (scalars only, cheap; default 16384, for RATTLE one per diffrax step, i.e. every `substeps` RATTLE steps); angles and node speeds on `n_frames`
times (the chronophotography and the speed map $v(s,t)$). The snapping speed
$v_s=\max_t|\dot{\mathbf x}(L/2,t)|$ is the grid maximum refined by the parabola through the
seven samples around it, maximized (`_refine_peak`), over the snap: up to its first
overshoot, the first sample past the crossing whose vertical fold velocity turns back
(`Trajectory.v_peak` is the whole run's peak, which past the snap includes the slam and
the ringing; the three-point parabola used before
was biased by $2.8\times10^{-4}$ with 4096 samples on $[0,4T]$ for a brink snap of width
$\sim0.016T$, and its bias wiggled with the peak's position between samples, which spoilt
the gradient; keep $t_1$ close to the snap time); it is a smooth function of the parameters where the maximum is unique (the
envelope theorem), so it is differentiated as it is, through diffrax's
`RecursiveCheckpointAdjoint`.
"""

from __future__ import annotations

import math

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._equations import (Dissipation, Protocol, accelerations, check_run_settings, check_scene, kinetic_energy, observables, potential_energy, scene_at)
from .._compile import dynamics_jit
from ..energy.geometry import discretize
from ._implicit import HHT
from ._rattle import Rattle, RattleStep
from ..results import RESULTS


SOLVERS = {
    "tsit5": dfx.Tsit5,
    "dopri5": dfx.Dopri5,
    "dopri8": dfx.Dopri8,
    "kvaerno3": dfx.Kvaerno3,
    "kvaerno5": dfx.Kvaerno5,
    "rattle": RattleStep,
}
EXPLICIT = ("tsit5", "dopri5", "dopri8", "rattle")
FIXED_STEP = ("rattle",)


class Trajectory(eqx.Module):
    """A simulated snap.

    Fine grid `t` (n_fine,; times after the stop are `inf`): `fold_height`, `fold_speed`,
    `bending`, `potential`, `kinetic`, `clamp_work`, `constraint` (end-position error).
    Frames `t_frames` (n_frames,): `theta` (n_frames, N), `positions` (n_frames, N+1, 2),
    `speed` (n_frames, N+1) node speeds. Each crease (`Strip.crease_list` order, m of them):
    `crease_height`, `crease_speed` (n_fine, m) and `v_s_creases` (m,), its peak speed.
    Scalars: `v_s` (the snap's peak fold speed at L/2, up to its first overshoot, units of
    the scene, i.e. v* when L = B = lambda = 1), `t_peak`, `v_peak` (the whole run's peak
    fold speed, the same as `v_s` for a run that stops at the snap), `t_cross` (fold height crosses 0),
    `t_end`, `snapped`, `kinetic_peak`, `energy_drift` (max |E_k+V-W - E(0)| / V(0), NaN when
    damped), `num_steps`, `result` (a [`jaxrod.RESULTS`][] code: `successful` for a run that
    reached `t1` or ended at the snap; `energy_drift`, `constraint_drift`,
    `constraint_solve_failed`, `steps_exhausted`, `integration_failed` or `nonfinite` for a run
    stopped early, whose samples up to `t_end` are those computed before the stop;
    `self_intersecting` for a run that went on but one of whose saved frames passes through
    itself, two non-neighbouring segments crossing: not a motion of the model, which then
    needs `jaxrod.Contact`; `contact_underresolved` for one whose saved frames touch in
    self-contact on a mesh whose segments exceed `jaxrod.energy.contact.CONTACT_RESOLUTION`
    contact thicknesses),
    `solver_result` (diffrax's own code)."""

    t: jax.Array
    fold_height: jax.Array
    fold_speed: jax.Array
    bending: jax.Array
    potential: jax.Array
    kinetic: jax.Array
    clamp_work: jax.Array
    constraint: jax.Array
    t_frames: jax.Array
    theta: jax.Array
    positions: jax.Array
    speed: jax.Array
    v_s: jax.Array
    t_peak: jax.Array
    v_peak: jax.Array
    crease_height: jax.Array
    crease_speed: jax.Array
    v_s_creases: jax.Array
    t_cross: jax.Array
    t_end: jax.Array
    snapped: jax.Array
    kinetic_peak: jax.Array
    energy_drift: jax.Array
    num_steps: jax.Array
    result: RESULTS
    solver_result: dfx.RESULTS


def _field(t, y, args):
    scene, protocol, dissipation, baumgarte, d = args
    q, _ = y
    acc, power = accelerations(t, q, scene, protocol, dissipation, baumgarte, d, with_work=True)
    return jnp.stack([q[1], acc]), power


_PEAK_HALF = 3  # the peak is refined on 2 * 3 + 1 samples
_U = np.arange(-_PEAK_HALF, _PEAK_HALF + 1, dtype=float)
_VINV = np.linalg.inv(np.vander(_U, increasing=True))  # samples -> monomial coefficients in u


def _refine_peak(t, f, upto=None):
    r"""Maximum of samples f on the uniform grid t: the degree-6 polynomial through the 7
    samples around the largest one, maximized by Newton on its derivative (u in samples).

    A 3-point parabola has an error $O((\Delta t/w)^3)$ for a peak of width $w$ that
    oscillates with the peak's position between samples, so $v_s(p)$ gets a wiggle whose
    derivative is $\propto\Delta t^2\,|dt_{peak}/dp|$: at 2048 samples on $[0,1.5T]$ that
    wiggle alone was 10x the true $dv_s/dG$. The 7-point fit moves the error to
    $O((\Delta t/w)^7)$. Falls back to the parabola next to non-finite samples (the stop)."""
    f = jnp.where(jnp.isfinite(f), f, -jnp.inf)
    k = _PEAK_HALF
    pick = f if upto is None else jnp.where(jnp.arange(f.shape[0]) <= upto, f, -jnp.inf)
    i = jnp.clip(jnp.argmax(pick), k, f.shape[0] - 1 - k)
    win = jax.lax.dynamic_slice(f, (i - k,), (2 * k + 1,))
    ok7 = jnp.all(jnp.isfinite(win))
    fm, f0, fp = win[k - 1], win[k], win[k + 1]
    ok = jnp.isfinite(fm) & jnp.isfinite(fp)
    fm, fp = jnp.where(ok, fm, f0), jnp.where(ok, fp, f0)
    den = fm - 2.0 * f0 + fp
    safe = jnp.where(den < 0, den, -1.0)
    u3 = jnp.where(den < 0, 0.5 * (fm - fp) / safe, 0.0)
    v3 = f0 - 0.25 * (fm - fp) * u3
    c = jnp.asarray(_VINV) @ jnp.where(ok7, win, 0.0)
    pows = jnp.arange(2 * k + 1, dtype=f.dtype)

    def d1(u):
        return jnp.sum(pows[1:] * c[1:] * u ** (pows[1:] - 1))

    def d2(u):
        return jnp.sum(pows[2:] * (pows[2:] - 1) * c[2:] * u ** (pows[2:] - 2))

    def newton(_, u):
        h = d2(u)
        return jnp.clip(u - d1(u) / jnp.where(h < 0, h, -1.0), -1.0, 1.0)

    u7 = jax.lax.fori_loop(0, 8, newton, jnp.clip(u3, -1.0, 1.0))
    v7 = jnp.sum(c * u7**pows)
    use7 = ok7 & (d2(u7) < 0)
    u = jnp.where(use7, u7, u3)
    dt = t[1] - t[0]
    return jnp.where(use7, v7, v3), t[i] + u * dt


# RATTLE's step is also capped at DT_CAP T (T = L^2 sqrt(lambda/B)): on coarse meshes
# (N < ~48) the stability bound courant h^2 exceeds it, and there the fast rotation of the
# crease during the snap (rate ~ v_s / s0), not stability, sets the error: measured at N = 24,
# energy error 1.1e-3 at dt = 1.8e-4 T but 1.3e-2 at 7.3e-4 T (v_s error 7e-4).
DT_CAP = 2e-4
# Past the snap (`stop_at_snap=False`) the strip slams into the other state and rings, with
# tensions of ~10^3 B/L^2 at the slam and its energy spreading into the grid-scale bending
# modes (measured at Psi0 = 30 deg, G/L = 0.5, s0 = 0.02): the step of the snap itself
# (courant 0.45) goes unstable ~0.1 T after the crossing, and the energy error of a stable
# step grows like (omega_max dt)^2 = (4 courant)^2 at any N (6 T of ringing: 1.2e-2 at
# courant 0.1, N = 100; 6.5e-4 at courant 0.025, N = 50 and 100). The ringing step is
# RING_COURANT h^2 (capped at DT_CAP): energy error 4.0e-3 over 5.6 T at N = 50, 3.6e-3 over 6 T at N = 100
# (tests/test_long_horizon.py), at 9x the steps of the snap's own step.
RING_COURANT = 0.05
# `jaxrod.HHT`'s default number of fine-grid samples: its dense output is a cubic Hermite
# interpolant, and 4096 samples on [0, 2 T] put ~30 on the brink snap's speed peak (more
# samples cost more time for the same v_s to 1e-5).
HHT_N_FINE = 4096
# The longest fixed-step RATTLE run `simulate` starts (a larger t1 is refused, naming t1).
MAX_FIXED_STEPS = 10**8
# RATTLE steps per diffrax step at the automatic step (see `simulate`).
DEFAULT_SUBSTEPS = 4


# With self-contact the step also resolves the contact's own frequency: a node pressed into a
# segment oscillates at omega_c = sqrt(2 k / (delta lambda)) (the penalty's largest stiffness
# per unit length over the line density), and the step is at most CONTACT_COURANT / omega_c
# (energy error ~ (omega_c dt)^2 while in contact).
CONTACT_COURANT = 0.1


def _contact_dt(scene):
    """The contact's step limit in units of T (1 / omega_c T times CONTACT_COURANT); from the
    scene's contact leaves where they are concrete, else from `jaxrod.Contact`'s defaults."""
    from ..model import CONTACT_STIFFNESS, CONTACT_THICKNESS

    c, st = scene.contact, scene.strip
    try:
        k, delta = float(c.stiffness), float(c.thickness)
        L, B = float(st.length), float(st.bending_stiffness)
    except (TypeError, jax.errors.ConcretizationTypeError):
        k, delta, L, B = CONTACT_STIFFNESS, CONTACT_THICKNESS, 1.0, 1.0
    return CONTACT_COURANT / math.sqrt(2.0 * k * L**4 / (delta * B))


def _rattle_dt_natural(scene, courant):
    """RATTLE's largest step in units of T (static: from the mesh fractions and the contact)."""
    frac_min = float(np.min(np.diff(np.asarray(scene.mesh.fractions))))
    dt = min(courant * frac_min**2, DT_CAP)
    if scene.contact is not None:
        dt = min(dt, _contact_dt(scene))
    return dt


def _default_n_fine(scene, solver, dt, t1, courant, substeps=1):
    """16384 samples; for RATTLE without `dt`, one per (macro) step (natural units, at most
    2^19, at least 2048), so its step is its largest one rather than a divisor of the grid."""
    if solver not in FIXED_STEP or dt is not None or not isinstance(t1, (int, float)) or not 0 < courant < 0.5:
        return 16384
    return int(min(max(math.ceil(t1 / (substeps * _rattle_dt_natural(scene, courant))) + 1, 2048), 2**19))


def _resolve_solver(solver, courant, substeps):
    """`simulate`'s `solver` as `(key, strategy, courant, substeps)`: key "rattle" (a
    [`jaxrod.Rattle`][] or the string), "hht" (a [`jaxrod.HHT`][]), "custom" (a diffrax
    solver) or another key of `SOLVERS`; a `Rattle`'s settings merged with the keywords."""
    if isinstance(solver, Rattle):
        for name, mine, kw in (("courant", solver.courant, courant), ("substeps", solver.substeps, substeps)):
            if mine is not None and kw is not None and mine != kw:
                raise ValueError(f"{name}: given both as Rattle({name}={mine!r}) and as {name}={kw!r}")
        courant = solver.courant if courant is None else courant
        substeps = solver.substeps if substeps is None else substeps
        return "rattle", solver, courant, substeps
    if isinstance(solver, HHT):
        key = "hht"
    elif isinstance(solver, dfx.AbstractSolver):
        key = "custom"
    elif isinstance(solver, str) and solver in SOLVERS:
        key = solver
    else:
        raise ValueError(f"solver must be jaxrod.Rattle(...), jaxrod.HHT(...), a diffrax solver or one of "
                         f"{sorted(SOLVERS)}, got {solver!r}")
    if courant is not None and key != "rattle":
        raise ValueError(f"courant applies to RATTLE only, got solver={solver!r}")
    return key, solver, courant, substeps


def _verdict(sol, finite, implicit=False):
    """jaxrod's code for a diffrax solution whose event is (snap done, energy bad, end bad)
    (see `Trajectory.result`)."""
    sr = sol.result
    res = RESULTS.where(sr == dfx.RESULTS.successful, RESULTS.successful, RESULTS.integration_failed)
    res = RESULTS.where(sr == dfx.RESULTS.max_steps_reached, RESULTS.steps_exhausted, res)
    res = RESULTS.where(sr == dfx.RESULTS.nonlinear_divergence,
                        RESULTS.newton_failed if implicit else RESULTS.constraint_solve_failed, res)
    res = RESULTS.where(sr == dfx.RESULTS.dt_min_reached, RESULTS.step_underflow, res)
    _, energy_bad, constraint_bad = sol.event_mask
    on_event = RESULTS.where(energy_bad, RESULTS.energy_drift,
                             RESULTS.where(constraint_bad, RESULTS.constraint_drift, RESULTS.successful))
    res = RESULTS.where(sr == dfx.RESULTS.event_occurred, on_event, res)
    return RESULTS.where((res == RESULTS.successful) & ~finite, RESULTS.nonfinite, res)


@dynamics_jit
def simulate(scene, theta0, protocol: Protocol, *, omega0=None, t1=2.0, direction=1.0,
             stop_at_snap: bool = True, solver="rattle", rtol=1e-8, atol=1e-8, dt=None,
             dissipation: Dissipation | None = None, baumgarte=20.0, n_fine: int | None = None,
             n_frames: int = 64, frame_window=None, max_steps: int | None = None,
             courant: float | None = None, substeps: int | None = None, energy_tol=1e-2,
             constraint_tol=1e-6) -> Trajectory:
    r"""Integrate the strip from angles `theta0` (and rates `omega0`, default 0) under the
    clamp `protocol` for $t\in[0,t_1]$ (see the module docstring).

    **Arguments:** `direction` +1 for a snap up (fold height rising through 0), -1 down;
    `stop_at_snap` stop at the first overshoot after the crossing; `solver` a
    [`jaxrod.Rattle`][] (default, fixed steps), a [`jaxrod.HHT`][] (implicit, adaptive steps), a
    diffrax solver, or a key of `SOLVERS`; `rtol`, `atol` the PID controller's
    tolerances of the adaptive solvers, or `dt` a constant step (then no error control); `baumgarte` $\Omega$ of the end-condition stabilization;
    `frame_window` (t_a, t_b) the span of the `n_frames` frames (default (0, t1));
    `courant` (`"rattle"` only, when `dt` is None): the step is the largest
    $\Delta t\le\min($`courant`$\,(h_{\min}/L)^2,\ 2\cdot10^{-4})\,T$, $T=L^2\sqrt{\lambda/B}$
    (the cap `DT_CAP` matters below N ~ 48 at courant 0.45; with self-contact also
    $\le 0.1/\omega_c$, $\omega_c=\sqrt{2k/(\delta\lambda)}$ the contact's frequency), with `courant` 0.45 by default when
    the run stops at the snap and 0.05 (`RING_COURANT`) when it goes on past it
    (`stop_at_snap=False`: the slam and the ringing need the smaller step, see
    `RING_COURANT`); the step is the largest that divides the fine-grid spacing
    $t_1/(n_{fine}-1)$, so every fine-grid sample is a step point (no interpolation error in
    $v_s$ or the energies; by default `n_fine` is one sample per step); RATTLE is stable
    below 0.5 (the highest bending mode $4\sqrt{B/\lambda}/h^2$). `substeps` (`"rattle"`
    only): RATTLE steps per diffrax step (default 4 when `dt` is None, i.e. at the automatic
    step, else 1, so that a given `dt` stays RATTLE's step unless `substeps` is given: then
    `dt` is the diffrax step of `substeps` RATTLE steps); the fine grid then samples every
    `substeps`-th step and diffrax's per-step work (event, saving) runs that much less often
    (`benchmarks/results/pyelastica.md` measures the trade: less time for a somewhat larger
    $v_s$ error). `max_steps`: default 200 000, or for `"rattle"` enough fixed
    steps for $t_1$ when $L=B=\lambda=1$; a run that hits it ends with
    `result == RESULTS.steps_exhausted`.

    **Monitors.** The run is stopped, with a code in `Trajectory.result`, as soon as (checked
    after every diffrax step) the energy balance of an undamped run drifts,
    $|E_k+V-W-E(0)|>$`energy_tol`$\cdot\max(|E(0)|, B/L)$ (`RESULTS.energy_drift`; default
    1e-2), the right end leaves the clamp, $|\mathbf x_N-(G,0)|>$`constraint_tol`$\cdot L$
    (`RESULTS.constraint_drift`; default 1e-6), the state is not finite, or RATTLE's constraint
    solve does not converge (`RESULTS.constraint_solve_failed`). Damped runs (any
    `dissipation`) have no energy monitor (their energy is meant to fall).

    **Returns:** a [`jaxrod.Trajectory`][].
    """
    if dissipation is None:
        dissipation = Dissipation()  # (a default instance in the signature would start JAX's backend at import)
    check_run_settings(t1=t1, direction=direction, stop_at_snap=stop_at_snap, rtol=rtol, atol=atol, dt=dt,
                       dissipation=dissipation, baumgarte=baumgarte, n_fine=n_fine, n_frames=n_frames,
                       frame_window=frame_window, max_steps=max_steps, courant=courant,
                       energy_tol=energy_tol, constraint_tol=constraint_tol)
    check_scene(scene)
    solver, strategy, courant, substeps = _resolve_solver(solver, courant, substeps)
    if substeps is None:
        substeps = DEFAULT_SUBSTEPS if (solver == "rattle" and dt is None) else 1
    if isinstance(substeps, bool) or not isinstance(substeps, int) or substeps < 1:
        raise ValueError(f"substeps must be a positive integer, got {substeps!r}")
    if substeps > 1 and solver != "rattle":
        raise ValueError(f"substeps applies to RATTLE only, got solver={strategy!r}")
    dtype = jnp.result_type(theta0)
    from ..energy.geometry import scene_dtype

    if dtype != jnp.float64 or scene_dtype(scene) != jnp.float64:
        raise ValueError("simulate needs float64 angles and scene (jax.config.update('jax_enable_x64', True) "
                         "before building them): float32 cannot resolve the fold speed peak and energy balance")
    theta0 = jnp.asarray(theta0)
    omega0 = jnp.zeros_like(theta0) if omega0 is None else jnp.asarray(omega0, dtype)
    y0 = (jnp.stack([theta0, omega0]), jnp.zeros((), dtype))
    d = discretize(scene)
    args = (scene, protocol, dissipation, jnp.asarray(baumgarte, dtype), d)
    if courant is None:
        courant = 0.45 if stop_at_snap else RING_COURANT
    if n_fine is None:
        n_fine = HHT_N_FINE if solver == "hht" else _default_n_fine(scene, solver, dt, t1, courant, substeps)
    ts = jnp.linspace(0.0, t1, n_fine)
    if frame_window is None:
        frame_window = (0.0, t1)
    tf = jnp.linspace(jnp.asarray(frame_window[0], dtype), jnp.asarray(frame_window[1], dtype), n_frames)

    def obs(t, y, a):
        o = observables(t, y[0], scene, protocol, d)
        return dict(fold_height=o["fold_height"], fold_speed=o["fold_speed"], vy=o["fold_velocity"][1],
                    crease_height=o["crease_height"], crease_speed=o["crease_speed"],
                    bending=o["bending"], potential=o["potential"], kinetic=o["kinetic"],
                    constraint=o["constraint"], work=y[1])

    def frames(t, y, a):
        o = observables(t, y[0], scene, protocol, d)
        return dict(theta=y[0][0], positions=o["positions"], speed=o["speed"])

    saveat = dfx.SaveAt(subs=[dfx.SubSaveAt(ts=ts, fn=obs), dfx.SubSaveAt(ts=tf, fn=frames)])

    k = scene.mesh.n // 2

    def done(t, y, a, **kw):
        th, om = y[0][0][:k], y[0][1][:k]
        fh = jnp.sum(d.h[:k] * jnp.sin(th))
        vy = jnp.sum(d.h[:k] * jnp.cos(th) * om)
        return (direction * fh > 0.0) & (direction * vy < 0.0)

    conservative = (dissipation.damping == 0) & (dissipation.drag == 0) & (dissipation.viscosity == 0)
    st = scene.strip

    def balance(t, y):
        """E_k + V - W of a state y = ((theta, omega), W)."""
        q, w = y
        aL, aR, _, _ = protocol.angles(t)
        dd = d._replace(theta_left=jnp.asarray(aL, dtype), theta_right=-jnp.asarray(aR, dtype))
        th, om = q[0], q[1]
        return kinetic_energy(th, om, dd) + potential_energy(th, scene_at(scene, aL, aR), dd) - w

    e0 = balance(0.0, y0)
    e_scale = jnp.maximum(jnp.abs(e0), st.bending_stiffness / st.length)

    def energy_bad(t, y, a, **kw):
        return conservative & ~(jnp.abs(balance(t, y) - e0) <= energy_tol * e_scale)

    def constraint_bad(t, y, a, **kw):
        th = y[0][0]
        end = jnp.stack([jnp.sum(d.h * jnp.cos(th)) - scene.clamps.gap, jnp.sum(d.h * jnp.sin(th))])
        c = jnp.sqrt(jnp.sum(end**2))
        finite = jnp.all(jnp.isfinite(y[0])) & jnp.isfinite(y[1])
        return ~(c <= constraint_tol * st.length) | ~finite

    snap_done = done if stop_at_snap else (lambda t, y, a, **kw: jnp.zeros((), bool))
    event = dfx.Event((snap_done, energy_bad, constraint_bad))
    if solver in FIXED_STEP and dt is None:
        if not 0.0 < courant < 0.5:
            raise ValueError(f"courant must lie in (0, 0.5) (RATTLE's stability limit), got {courant!r}")
        T = st.length**2 * jnp.sqrt(st.line_density / st.bending_stiffness)
        dt_max = substeps * _rattle_dt_natural(scene, courant) * T
        grid = t1 / (n_fine - 1)
        dt = grid / jnp.ceil(grid / dt_max)
        steps = 0
        if isinstance(t1, (int, float)):  # natural units L = B = lambda = 1
            g = t1 / (n_fine - 1)
            steps = (n_fine - 1) * math.ceil(g / (substeps * _rattle_dt_natural(scene, courant)))
        if steps > MAX_FIXED_STEPS:
            raise ValueError(f"t1: a RATTLE run to t1 = {t1!r} takes {steps:.3g} fixed steps (more than "
                             f"{MAX_FIXED_STEPS:.0e}); shorten t1, or use solver=jaxrod.HHT() whose step is set "
                             "by accuracy")
        if max_steps is None:
            max_steps = max(200_000, steps + 64)
    if max_steps is None:
        max_steps = 200_000
    T = st.length**2 * jnp.sqrt(st.line_density / st.bending_stiffness)
    if solver == "hht" and dt is None:
        controller = strategy.controller(dtmin=1e-12 * T)
        dt0 = strategy.dt0 * T
    elif dt is None:
        controller = dfx.PIDController(rtol=rtol, atol=atol, pcoeff=0.0, icoeff=1.0)
        dt0 = None
    else:
        controller = dfx.ConstantStepSize()
        dt0 = dt
    if solver == "hht":
        slv = strategy.step_solver()
    elif solver == "custom":
        slv = strategy
    elif solver == "rattle":
        slv = RattleStep(substeps=substeps)
    elif solver in EXPLICIT:
        slv = SOLVERS[solver]()
    else:
        slv = SOLVERS[solver](root_finder=dfx.VeryChord(rtol=rtol, atol=atol))
    sol = dfx.diffeqsolve(dfx.ODETerm(_field), slv, 0.0, t1, dt0, y0, args, saveat=saveat,
                          stepsize_controller=controller, event=event, max_steps=max_steps, throw=False)
    o, fr = sol.ys
    t_end = jnp.max(jnp.where(jnp.isfinite(sol.ts[0]), sol.ts[0], 0.0))
    t_end = jnp.maximum(t_end, 0.0)
    fh = o["fold_height"]
    # first crossing of the fold height through 0 in the snapping direction
    s = direction * fh
    cross = (s[:-1] <= 0) & (s[1:] > 0) & jnp.isfinite(s[1:])
    j = jnp.argmax(cross)
    frac = s[j] / jnp.where(cross[j], s[j] - s[j + 1], 1.0)
    t_cross = jnp.where(jnp.any(cross), ts[j] - frac * (ts[1] - ts[0]), jnp.nan)
    snapped = jnp.any(cross)
    # the snap ends at its first overshoot: the first sample past the crossing whose vertical
    # fold velocity has turned back (the whole run where there is none)
    idx = jnp.arange(ts.shape[0])
    back = (idx > j + 1) & (direction * o["vy"] < 0.0) & snapped
    upto = jnp.where(jnp.any(back), jnp.argmax(back), ts.shape[0] - 1)
    v_s, t_peak = _refine_peak(ts, o["fold_speed"], upto)
    v_peak, _ = _refine_peak(ts, o["fold_speed"])
    if scene.strip.creases is None:  # the centred crease's speed is the fold's
        v_s_creases = v_s[None]
    else:
        v_s_creases = jax.vmap(lambda f: _refine_peak(ts, f, upto)[0], in_axes=1)(o["crease_speed"])
    E = o["kinetic"] + o["potential"] - o["work"]
    fin = jnp.isfinite(E)
    drift = jnp.max(jnp.where(fin, jnp.abs(E - E[0]), 0.0)) / jnp.abs(o["potential"][0])
    drift = jnp.where(conservative, drift, jnp.nan)
    kin = jnp.where(jnp.isfinite(o["kinetic"]), o["kinetic"], -jnp.inf)
    result = _verdict(sol, jnp.all(jnp.where(jnp.isfinite(sol.ts[0]), jnp.isfinite(E), True)), solver == "hht")
    # a run whose saved frames pass through themselves is not a physical motion of the model
    from ..energy.contact import self_intersects, underresolved_contact

    shown = jnp.isfinite(sol.ts[1]) & jnp.all(jnp.isfinite(fr["theta"]), -1)
    crossed = jax.vmap(lambda th: self_intersects(jnp.where(jnp.isfinite(th), th, 0.0), scene))(fr["theta"])
    crossed = jnp.any(crossed & shown)
    # ... or whose saved frames touch on a mesh too coarse for the contact thickness
    coarse = jnp.zeros((), bool)
    if scene.contact is not None:
        coarse = jax.vmap(lambda th: underresolved_contact(jnp.where(jnp.isfinite(th), th, 0.0), scene))(fr["theta"])
        coarse = jnp.any(coarse & shown)
    ok = result == RESULTS.successful
    result = RESULTS.where(ok & crossed, RESULTS.self_intersecting,
                           RESULTS.where(ok & coarse, RESULTS.contact_underresolved, result))
    return Trajectory(
        t=ts, fold_height=fh, fold_speed=o["fold_speed"], bending=o["bending"], potential=o["potential"],
        kinetic=o["kinetic"], clamp_work=o["work"], constraint=o["constraint"], t_frames=tf,
        theta=fr["theta"], positions=fr["positions"], speed=fr["speed"], v_s=v_s, t_peak=t_peak, v_peak=v_peak,
        crease_height=o["crease_height"], crease_speed=o["crease_speed"], v_s_creases=v_s_creases,
        t_cross=t_cross, t_end=t_end, snapped=snapped, kinetic_peak=jnp.max(kin), energy_drift=drift,
        num_steps=sol.stats["num_steps"] * substeps,  # RATTLE steps (substeps: 1 otherwise)
        result=result,
        solver_result=sol.result,
    )
