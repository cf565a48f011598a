r"""A differentiable snapping speed $v_s$ of a design: `snap_speed(scene, direction)`.

**What it computes.** The *brink* snap of [`jaxrod.brink`][] (the quasi-static snap: the
strip at its critical state, the clamps held just past the critical angle, released from
rest), integrated with a **fixed step**, and its peak fold speed
$v_s=\max_t|\dot{\mathbf x}(L/2,t)|$ in the units of the scene ($v^\ast$ for
$L=B=\lambda=1$, docs/model.md):

1. $\alpha_c$, the critical state $(\theta_c,\mu_c)$ and the unstable mode $v$ of the
   `direction` path from [`jaxrod.snap_angles`][] (continuation + bisection, then refined
   on the extended system by [`jaxrod.critical_point`][], whose result is differentiable
   by the implicit function theorem in every float leaf of the scene);
2. clamps held at $\alpha_c+\sigma\,\delta\alpha$ (`past`; $\sigma=\pm1$ the direction),
   angles $\theta(0)=\Pi(\theta_c+\epsilon\,\hat v)$: `nudge` $\epsilon$ (default
   `jaxrod.dynamics.NUDGE`, as `jaxrod.brink`) times the mode with unit RMS norm
   $\sum_ih_i\hat v_i^2=L$ (smooth in the design, where a max-norm has kinks), its sign
   chosen so that the fold moves toward the other state, projected ($\Pi$) onto the end
   condition by a fixed number of Gauss-Newton steps (`jaxrod.dynamics.nudge_start`); at rest;
3. [`jaxrod.simulate`][] with a fixed step: by default `solver="rattle"` (symplectic,
   links and ends exact) at the largest step $\le\min(0.45\,(h_{\min}/L)^2,\
   2\cdot10^{-4})\,T$ ($T=L^2\sqrt{\lambda/B}$; RATTLE is stable below 0.5 $h^2$) that
   divides the sample spacing, with one sample per step (`n_fine` $\approx t_1/dt$), so
   every sample is a step point; or `solver="tsit5"` at $0.15\,(h/L)^2\,T$ on 8192 samples
   (explicit Runge-Kutta methods are stable only below $\sim0.3\,(h/L)^2T$ for these bending
   waves, measured at $N=48$: Tsit5 stable at $dt=10^{-4}=0.23\,h^2$, unstable at
   $2\times10^{-4}$); up to the snap's first overshoot (the run's event) or `t1`; $v_s$ is
   the maximum of the sampled fold speed, refined by the 7-point polynomial of
   `_refine_peak`. RATTLE is the default: the same $v_s$ as Tsit5 to 5e-4 (table below),
   less forward time from N ~ 24 on, the gap widening with N, and a faster gradient
   (`benchmarks/results/dynamics.md` times the integrators on the brink snap).

**Why it is smooth.** Every step is a smooth map of the design $p=(\Psi_0,G,s_0,\dots)$:
the implicit derivatives of the critical point, a fixed number of projection steps, and a
fixed-step RATTLE or Runge-Kutta map (no step-size controller, whose accept/reject decisions and
step sequence are piecewise constant in $p$); the maximum of the fold speed is
differentiable where it is unique (envelope theorem). The event that ends the run
changes the step count discretely, but it fires after the peak, so $v_s$ does not see it.
Reverse mode goes through diffrax's checkpointed adjoint; forward mode (`jax.jvp`,
`jax.jacfwd`, which design's Levenberg-Marquardt loop uses) is provided by a custom JVP
that computes the gradient in reverse mode once and contracts it with the tangent (so
`jacfwd` costs one reverse pass, not one per parameter; first derivatives only).

**Where it is not differentiable (or not defined).** NaN where the path does not snap
(no loss of stability, `snap_angles(...).snaps` false), where the located critical point
does not solve its extended system (`derivative_unavailable`), where the run does not snap within `t1`, where the integration
is not trustworthy (conservative energy drift above `max_drift`: a step beyond the
stability limit), or where the peak is within three samples of the stop (the fold speed
still rising at the first overshoot, e.g. Psi0 <= 10 deg at G/L = 0.3, N = 24). Not
differentiable where the snap changes kind (fold <-> branch point: the critical state
jumps), near the termination gap $G^\ast(\Psi_0)$ (the snap vanishes), where two fold-speed
maxima of a snap trade places, and for a branch point the mode's sign is a choice of
mirror image (both give the same $v_s$ by symmetry).

**Accuracy** (measured; defaults `nudge` 0.03 RMS, `past` 1e-3). Psi0 = 90 deg, G/L = 0.46,
s0 = 0.02 (the study (c) design; a branch point, alpha_c = 80.80 deg at N = 48). Reference:
`jaxrod.snap_dynamics` (brink, nudge 1e-2 rad max-norm, adaptive Dopri8, rtol = atol =
1e-9) at the same N. RATTLE (the default) and Tsit5 at 0.15 h^2:

| N | RATTLE | steps | Tsit5 | reference | RATTLE vs converged |
|---|---|---|---|---|---|
| 16 | 20.4116 | 3560 | 20.4123 | | +2.0 % |
| 24 | 20.3323 | 3485 | 20.3323 | 20.3454 | +1.6 % |
| 32 | 20.2064 | 3463 | 20.2056 | 20.2198 | +0.95 % |
| 48 | 20.0929 | 3530 | 20.0922 | 20.1053 | +0.39 % |
| 96 | 20.0389 | 14084 | 20.0307 | 20.0379 | +0.12 % |
| 192 | 20.0283 | 56299 | 20.0190 | | +0.07 % |

"Converged": ~20.015-20.025 (Richardson, order 2, of N = 96 and 192: 20.015 from Tsit5,
20.025 from RATTLE; below N ~ 50 the mesh does not resolve the fold, h > s0, and the
convergence is pre-asymptotic). So the design mesh N = 48 is within 0.4 % (1 % asked).
Below N ~ 48 RATTLE's step is capped at 2e-4 T (the crease's fast rotation, not stability,
sets the error there), hence ~3500 steps. The same-N difference from the reference is
mostly the start (nudge 0.03 RMS here vs 0.01 max-norm there): with one start
(`jaxrod.brink`, nudge 0.05 max-norm) Tsit5's fixed step alone differs from Dopri8 1e-9 by 9e-6 at
N = 48 (dt = 1e-4: 20.08297 vs 20.08314), and the brink's v_s moves by 1.1e-3 between
nudges 0.01 and 0.05. RATTLE's energy error is bounded (symplectic) but larger than
Tsit5's: 6e-4 of the start's potential here, up to 2.5e-3 at the fast corner Psi0 = 10 deg,
G/L = 0.3, N = 16 (where RATTLE's v_s is 1.05 % below Tsit5's; 1.8e-4 at N = 48), hence
`max_drift` 1e-2 for RATTLE (a step beyond its stability limit gives ~1e3-1e4) and 1e-3
for the Runge-Kutta schemes. At the study (b) corner G/L = 0.3 (Tsit5): N = 48 vs 96
gives 37.654 vs 37.548 (Psi0 = 30 deg, +0.28 %) and 35.955 vs 35.778 (45 deg, +0.50 %).
A gradient is one reverse pass (checkpointed, a few times the forward cost).

**Smoothness, measured.** At N = 16 the AD gradient equals central differences to
~1e-5 or better when the FD steps are 1e-5 to 3e-4; below ~1e-6 the differences see a
round-off noise of ~5e-8 v* in v_s (the snap amplifies round-off), which is far below any
design tolerance but makes tiny FD steps meaningless.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp

from ._scenes import NUDGE, _brink_start, _direction
from ._implicit import HHT
from ._rattle import Rattle
from ._simulate import FIXED_STEP, HHT_N_FINE, SOLVERS, _rattle_dt_natural, simulate
from .._misc import check_param
from .._compile import dynamics_jit
from ..branches import snap_angles
from ..results import RESULTS


RATTLE_COURANT = 0.45
# RATTLE's energy error is bounded and oscillates (symplectic), O(dt^2): measured up to
# 2.5e-3 of the start's potential at Psi0 = 10 deg, G/L = 0.3, N = 16 (a fast snap), 7e-4 at
# (60 deg, 0.5); one step beyond its stability limit (Courant 0.52 at N = 48) gives 9e3.
RATTLE_MAX_DRIFT = 1e-2


def _solver_key(solver):
    """`snap_speed`'s `solver` as a key: "rattle" (the string or a [`jaxrod.Rattle`][]),
    "hht" (a [`jaxrod.HHT`][]) or another key of `SOLVERS`; `ValueError` naming `solver`."""
    if isinstance(solver, Rattle):
        return "rattle"
    if isinstance(solver, HHT):
        return "hht"
    if isinstance(solver, str) and solver in SOLVERS:
        return solver
    raise ValueError(f"solver must be jaxrod.Rattle(...), jaxrod.HHT(...) or one of {sorted(SOLVERS)}, "
                     f"got {solver!r}")


def _courant(solver):
    """RATTLE's Courant number of `solver` (a `Rattle`'s own, else `RATTLE_COURANT`)."""
    c = getattr(solver, "courant", None) if isinstance(solver, Rattle) else None
    return RATTLE_COURANT if c is None else float(c)


def default_n_fine(scene, solver="rattle", t1=2.0):
    """The default number of samples on [0, t1]: for RATTLE one per step of its natural step
    `min(courant (h_min/L)^2, DT_CAP)` T (courant 0.45 unless a `jaxrod.Rattle` gives it; so
    every sample is a step point and the step is its largest); for `jaxrod.HHT` `HHT_N_FINE`
    (its adaptive steps are interpolated by cubic Hermite polynomials); otherwise 8192 (Tsit5's
    dense output interpolates between steps)."""
    key = _solver_key(solver)
    if key in FIXED_STEP:
        return int(math.ceil(t1 / _rattle_dt_natural(scene, _courant(solver)))) + 1
    return HHT_N_FINE if key == "hht" else 8192


def default_dt(scene, solver="rattle", t1=2.0, n_fine=None):
    r"""The default constant step in units of $T=L^2\sqrt{\lambda/B}$. RATTLE: the largest
    step not above $\min(0.45\,(h_{\min}/L)^2,\ 2\cdot10^{-4})$ that divides the sample
    spacing $t_1/(n_{fine}-1)$ (every sample a step point: RATTLE's output between steps is
    linear); Tsit5 and the other explicit Runge-Kutta schemes: $0.15\,(h_{\min}/L)^2$; `jaxrod.HHT`:
    None (adaptive steps)."""
    key = _solver_key(solver)
    if key in FIXED_STEP:
        if n_fine is None:
            n_fine = default_n_fine(scene, solver, t1)
        grid = t1 / (n_fine - 1)
        return grid / math.ceil(grid / _rattle_dt_natural(scene, _courant(solver)) - 1e-9)
    if key == "hht":
        return None  # adaptive: the step is set by HHT's local error test
    f = scene.mesh.fractions
    h = min(f[i + 1] - f[i] for i in range(scene.mesh.n))
    return 0.15 * float(h) ** 2


class SpeedRun(eqx.Module):
    """Diagnostics of one `snap_speed` run: `v_s` (NaN where not valid), `v_s_raw` (the
    trajectory's value, whatever the checks say), `ok`, `alpha_c` (rad), `kind`,
    `t_peak`, `t_end`, `energy_drift`, `num_steps`, and the checks: `valid` (the path snaps
    and its critical point was refined), `snapped` (the fold crossed y = 0 within `t1`),
    `stopped` (the run ended at the snap's overshoot before `t1`), `peak_before_stop`;
    `result`: `successful` where `v_s` is valid, else the snap path's code (or `no_snap`,
    or `derivative_unavailable` where its critical point carries no derivative), the trajectory's code,
    `snap_not_resolved`, or `energy_drift` (above `max_drift`); `v_s_creases` (m,): each
    crease's peak speed during the snap (`Strip.crease_list` order; NaN where not valid)."""

    v_s: jax.Array
    v_s_raw: jax.Array
    ok: jax.Array
    alpha_c: jax.Array
    kind: jax.Array
    t_peak: jax.Array
    t_end: jax.Array
    energy_drift: jax.Array
    num_steps: jax.Array
    valid: jax.Array
    snapped: jax.Array
    stopped: jax.Array
    peak_before_stop: jax.Array
    result: RESULTS
    v_s_creases: jax.Array


def _run(scene, direction, nudge, past, dt, t1, n_fine, solver, max_drift):
    sgn = _direction(direction)
    snap = snap_angles(scene)
    path = snap.up if sgn > 0 else snap.down
    valid = path.snaps & (path.refine_result == RESULTS.successful)
    alpha_c = jnp.where(valid, path.alpha_c, 0.0)  # keep the run finite where there is no snap
    start = _brink_start(scene, alpha_c, path.theta_before, path.force_before, path.mode, valid, sgn, past, nudge)
    sc_run = start.scene
    max_steps = None if dt is None else int(math.ceil(t1 / dt)) + 10
    st = scene.strip
    T = st.length**2 * jnp.sqrt(st.line_density / st.bending_stiffness)  # dt, t1 are in units of T
    # Integrate in the time tau = t / T: the same motion with lambda' = B / L^4 (T' = 1) and
    # gravity g' = g T^2, so that t1, dt and the save times are concrete numbers (diffrax's
    # checks of them then run at trace time instead of as runtime callbacks, which would keep
    # the compiled program out of JAX's persistent compilation cache); speeds scale by 1 / T.
    sc_run = eqx.tree_at(lambda s: s.strip.line_density, sc_run, st.bending_stiffness / st.length**4)
    if scene.gravity is not None:
        sc_run = eqx.tree_at(lambda s: s.gravity.g, sc_run, scene.gravity.g * T**2)
    tr = simulate(sc_run, start.theta0, start.protocol, t1=t1, dt=dt, solver=solver, direction=sgn,
                  max_steps=max_steps, n_fine=n_fine, n_frames=2)
    spacing = t1 / (n_fine - 1)
    stopped = tr.t_end < t1 - 2 * (spacing if dt is None else dt)
    peak_ok = tr.t_peak < tr.t_end - 3 * spacing
    ok = (valid & tr.snapped & stopped & peak_ok & (tr.energy_drift < max_drift) & jnp.isfinite(tr.v_s)
          & (tr.result == RESULTS.successful))
    v_raw = tr.v_s / T
    good = RESULTS.successful
    path_code = RESULTS.where(path.result != good, path.result,
                              RESULTS.where(path.snaps, RESULTS.derivative_unavailable, RESULTS.no_snap))
    result = RESULTS.where(
        ~valid, path_code,
        RESULTS.where(tr.result != good, tr.result,
                      RESULTS.where(~(tr.snapped & stopped & peak_ok), RESULTS.snap_not_resolved,
                                    RESULTS.where(ok, good, RESULTS.energy_drift))))
    return SpeedRun(jnp.where(ok, v_raw, jnp.nan), v_raw, ok, jnp.where(valid, path.alpha_c, jnp.nan),
                    path.kind, tr.t_peak * T, tr.t_end * T, tr.energy_drift, tr.num_steps, valid, tr.snapped,
                    stopped, peak_ok, result, jnp.where(ok, tr.v_s_creases / T, jnp.nan))


@eqx.filter_custom_jvp
def _speed(scene, *, opts):
    return _run(scene, *opts).v_s


@_speed.def_jvp
def _speed_jvp(primals, tangents, *, opts):
    (scene,), (t_scene,) = primals, tangents
    v, g = eqx.filter_value_and_grad(lambda sc: _run(sc, *opts).v_s)(scene)
    if t_scene is None:
        return v, jnp.zeros_like(v)
    # both trees have the scene's structure, None (symbolic zero) where not differentiated
    dv = jnp.zeros_like(v)
    is_none = lambda x: x is None  # noqa: E731
    for gg, tt in zip(jax.tree.leaves(g, is_leaf=is_none), jax.tree.leaves(t_scene, is_leaf=is_none)):
        if gg is not None and tt is not None:
            dv = dv + jnp.sum(gg * tt)
    return v, dv


def _options(scene, direction, nudge, past, dt, t1, n_fine, solver, max_drift):
    _direction(direction)
    key = _solver_key(solver)
    if isinstance(solver, Rattle):
        if solver.substeps is not None:
            raise ValueError("substeps: snap_speed samples every RATTLE step (n_fine), so Rattle(substeps=...) "
                             "does not apply; give Rattle(courant=...) or the sample count n_fine")
        if dt is None:  # the object's Courant number sets the default step; the run is the string's
            n_fine = default_n_fine(scene, solver, float(t1)) if n_fine is None else n_fine
            dt = default_dt(scene, solver, float(t1), n_fine)
        solver = "rattle"
    check_param("nudge", nudge, lo=0.0)
    check_param("past", past, lo=0.0, lo_open=False)
    check_param("t1", t1, lo=0.0)
    if max_drift is None:
        max_drift = RATTLE_MAX_DRIFT if key in FIXED_STEP or key == "hht" else 1e-3
    check_param("max_drift", max_drift, lo=0.0)
    if n_fine is None:
        n_fine = default_n_fine(scene, solver, float(t1))
    if not isinstance(n_fine, int) or n_fine < 16:
        raise ValueError(f"n_fine: must be an integer >= 16, got {n_fine!r}")
    if dt is None:
        dt = default_dt(scene, solver, float(t1), n_fine)
    if dt is not None:
        check_param("dt", dt, lo=0.0)
    if scene.stretching is not None:
        raise ValueError("stretching: the dynamics are exactly inextensible; use stretching=None")
    return (direction, float(nudge), float(past), None if dt is None else float(dt), float(t1), n_fine, solver,
            float(max_drift))


def snap_speed(scene, direction="up", *, nudge=NUDGE, past=1e-3, dt=None, t1=2.0, n_fine=None, solver="rattle",
               max_drift=None):
    r"""The snapping speed $v_s$ of the `direction` ("up" or "down") quasi-static snap of
    `scene` (symmetric actuation; the scene's clamp angles are ignored), differentiable in
    the scene's float leaves ($\Psi_0$, $G$, $s_0$, ...) in forward and reverse mode.

    The brink snap (start at the critical state nudged by `nudge` rad RMS along the
    unstable mode, clamps held `past` rad beyond $\alpha_c$) integrated by `solver`: a
    [`jaxrod.Rattle`][] or `"rattle"` (default), [`jaxrod.HHT`][] (implicit, adaptive steps) or
    `"tsit5"`, with the constant step `dt` (default: RATTLE's
    $\le\min(c\,h_{\min}^2, 2\cdot10^{-4})$ with the `Rattle`'s Courant number $c$, 0.45 by
    default, Tsit5's $0.15\,h_{\min}^2$, in units of $T$; HHT's steps are adaptive unless `dt`
    is given) on $[0,$`t1`$]$, sampled `n_fine` times (default: every RATTLE step; 4096 for HHT,
    8192 for Tsit5);
    `max_drift` the largest energy drift trusted (default 1e-2 RATTLE, 1e-3 else); the module
    docstring says why that is smooth and where it is not differentiable. Returns NaN where
    there is no snap (or the run failed one of its checks, see the module docstring).
    [`snap_speed_run`][] returns the diagnostics.

    `dt` and `t1` are in units of $T=L^2\sqrt{\lambda/B}$ (so the step count does not depend on
    the units); v_s is in the scene's units ($v^\ast=L/T$).

    **Accuracy** (measured at Psi0 = 90 deg, G/L = 0.46, s0 = 0.02; table in the module
    docstring): at N = 48, within 0.4 % of the converged v_s (Richardson from N = 96, 192),
    6e-4 from `jaxrod.snap_dynamics` with adaptive Dopri8 at rtol = atol = 1e-9 on the same
    mesh (mostly the different nudge); at N = 16, +2 %.
    """
    opts = _options(scene, direction, nudge, past, dt, t1, n_fine, solver, max_drift)
    if any(isinstance(x, jax.core.Tracer) for x in jax.tree.leaves(scene)):
        # already inside a transformation (the caller's jit / jacfwd compiles it): no nested
        # jit of its own (it would only add tracing time)
        return _speed(scene, opts=opts)
    return _speed_jit(scene, opts)


@dynamics_jit
def _speed_jit(scene, opts):
    return _speed(scene, opts=opts)


def snap_speed_run(scene, direction="up", *, nudge=NUDGE, past=1e-3, dt=None, t1=2.0, n_fine=None,
                   solver="rattle", max_drift=None) -> SpeedRun:
    """`snap_speed` with its diagnostics (a [`SpeedRun`][]; not differentiable in forward mode)."""
    opts = _options(scene, direction, nudge, past, dt, t1, n_fine, solver, max_drift)
    return _run_jit(scene, opts)


@dynamics_jit
def _run_jit(scene, opts):
    return _run(scene, *opts)
