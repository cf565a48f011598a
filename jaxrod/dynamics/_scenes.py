r"""Snap scenes: where a dynamic run starts and how the clamps move.

* **brink**: the critical state of the quasi-static path (`jr.snap_angles`:
  `theta_before`, `alpha_c`), the clamps held at $\alpha_c+\delta\alpha$ (`past`, in the
  snapping direction) and the angles nudged by `nudge` (rad, RMS over the strip; default
  [`NUDGE`][] = 0.03 for every entry point) along the unstable mode (the lowest
  eigenvector of the constrained Hessian, sign chosen so the fold moves toward the other
  state), projected back onto the end condition $\sum_ih_i\mathbf t_i=(G,0)$ by
  Gauss-Newton (`nudge_start`). The RMS norm $\sqrt{\sum_ih_i\delta\theta_i^2/L}$ is smooth
  in the design, where a max-norm has kinks, so the snap speed stays differentiable.
* **ramp**: a stable state at $\alpha_0$ (`jr.initial_state` then the clamps ramped at
  `rate` rad/T from rest through $\alpha_c$; symmetric by default.
* **asymmetric**: the left clamp held at its angle, only the right one ramped (the paper's
  Fig. 4).

A symmetric ramp from a mirror-symmetric state never leaves it at a *branch point* (an
asymmetric mode going unstable): nothing but round-off seeds that mode, so the departure is
delayed by ~40 e-foldings of its slow growth. `seed` adds an imperfection of that amplitude
(rad, max-norm), the mirror-breaking shape $\delta\theta(s)=\sin(\pi s/L)$ (even about
$L/2$, while symmetric states have $\theta(s)=-\theta(L-s)$), projected onto the end
condition, as real strips have; it is harmless at a fold.
"""

from __future__ import annotations

import inspect
import math

import equinox as eqx
import jax
import jax.numpy as jnp

from ._equations import Protocol, check_run_settings
from ..energy.geometry import discretize, mode_sign
from ..statics import initial_state
from ..linalg.batched import solve2
from .._misc import check_param
from .._compile import dynamics_jit
from ..branches import snap_angles, snap_routes
from ..results import RESULTS
from ..energy.bending import bending_energy as _bending


NUDGE = 0.03
"""The brink's default nudge (rad, RMS of the angle change along the unstable mode):
`brink`, `snap_dynamics`, `snap_speed`, the CLI and `jaxrod reproduce` all start from it.
The snap speed moves by about 1e-3 relative between small nudges (measured in
`jaxrod.snap_speed`'s docstring); a larger nudge shortens the slow exponential departure."""


def nudge_start(theta_c, mode, scene, direction, nudge):
    r"""The brink's start $\Pi(\theta_c+\epsilon\hat v)$: `theta_c` plus `nudge` $\epsilon$ (rad,
    RMS) times the unstable `mode` scaled to unit RMS norm $\sum_ih_i\hat v_i^2=L$, signed so
    that the fold height moves in `direction` (+1 up, -1 down) to first order (a
    mirror-asymmetric mode, which moves it only to second order, by the mirror convention of
    `jaxrod.energy.geometry.mode_sign`), projected
    ($\Pi$) onto the end condition of `scene` (which holds the clamps of the run)."""
    d = discretize(scene)
    k = scene.mesh.n // 2
    v = mode / jnp.sqrt(jnp.sum(d.h * mode**2) / jnp.sum(d.h))
    dy = jnp.sum((d.h * jnp.cos(theta_c) * v)[:k])  # first-order change of the fold height
    v = v * jax.lax.stop_gradient(mode_sign(direction * dy, d.h, v))
    return project(theta_c + nudge * v, scene)


class Start(eqx.Module):
    """Initial condition of a run: `scene` (clamps at their t = 0 angles), `theta0`,
    `protocol`, `direction` (+1 snap up, -1 down), `alpha_c` (rad, NaN if unknown),
    `bending_before` (bending energy of the critical / start state), `ok` (the statics
    found the state)."""

    scene: object
    theta0: jax.Array
    protocol: Protocol
    direction: float = eqx.field(static=True)
    alpha_c: jax.Array
    bending_before: jax.Array
    ok: jax.Array


@dynamics_jit
def project(theta, scene, steps=8):
    r"""Minimal-norm Gauss-Newton projection onto $\sum_i h_i\mathbf t_i=(G,0)$ (jitted: an
    eager `fori_loop` over a fresh closure would compile again on every call)."""
    d = discretize(scene)
    target = jnp.stack([scene.clamps.gap, jnp.zeros((), theta.dtype)])

    def body(_, th):
        c = jnp.stack([jnp.sum(d.h * jnp.cos(th)), jnp.sum(d.h * jnp.sin(th))]) - target
        A = jnp.stack([-d.h * jnp.sin(th), d.h * jnp.cos(th)])
        return th - A.T @ solve2(A @ A.T, c)

    return jax.lax.fori_loop(0, steps, body, theta)


def mirror_seed(theta, scene, seed):
    """`theta` plus `seed` times the mirror-breaking shape sin(pi s / L) at the segment
    midpoints, projected onto the end condition (see the module docstring)."""
    d = discretize(scene)
    s_mid = jnp.cumsum(d.h) - 0.5 * d.h
    return project(theta + seed * jnp.sin(jnp.pi * s_mid / jnp.sum(d.h)), scene)


def _direction(direction):
    if direction not in ("up", "down"):
        raise ValueError(f"direction must be 'up' or 'down', got {direction!r}")
    return 1.0 if direction == "up" else -1.0


def brink(scene, direction="up", *, nudge=NUDGE, past=1e-3, snap=None, route="first") -> Start:
    """The brink scene (see the module docstring). `snap`: a precomputed
    `jr.snap_angles(scene)` to reuse. `route`: "first" (the critical point where the
    quasi-static path snaps) or "second" (the next critical point of the same branch past
    a branch point, `jr.snap_routes`: the route a fast ramp of a nearly perfect strip
    takes); the nudge is along the mode that goes unstable there."""
    sgn = _direction(direction)
    check_param("nudge", nudge, lo=0.0)
    check_param("past", past, lo=0.0, lo_open=False)
    if route not in ("first", "second"):
        raise ValueError(f"route must be 'first' or 'second', got {route!r}")
    snap = snap_angles(scene) if snap is None else snap
    path = snap.up if sgn > 0 else snap.down
    from .._misc import is_concrete

    if is_concrete(path.snaps) and not bool(path.snaps):
        raise ValueError(f"direction: the quasi-static {direction} path of this scene does not snap "
                         "(jr.snap_angles found no loss of stability), so there is no brink")
    if route == "first":
        alpha_c, theta_c, force_c, mode, exists = (path.alpha_c, path.theta_before, path.force_before, path.mode,
                                                   path.snaps)
    else:
        r = snap_routes(scene, snap=snap)
        r = r.up if sgn > 0 else r.down
        if is_concrete(r.kind2) and int(r.kind2) == 0:
            raise ValueError(f"route: the {direction} path of this scene has no second critical point "
                             "(jr.snap_routes: it snaps at a fold, or its branch reaches the bound)")
        alpha_c, theta_c, force_c, mode, exists = r.alpha_c2, r.theta2, r.force2, r.mode2, r.kind2 != 0
    dtype = jnp.result_type(float)
    return _brink_start(scene, alpha_c, theta_c, force_c, mode, exists, sgn, jnp.asarray(past, dtype),
                        jnp.asarray(nudge, dtype))


@dynamics_jit
def _brink_start(scene, alpha_c, theta_c, force_c, mode, exists, sgn, past, nudge):
    """The brink's start from a refined critical state (`theta_c`, `force_c` at `alpha_c`,
    with its critical `mode`), as one compiled program. The state is used as it is: solving
    it again at `alpha_c` would add nothing to its value, and the implicit derivative of a
    solve at a critical point divides by the Hessian's vanishing eigenvalue, where the
    critical point's own derivative (its extended system's, `jaxrod.critical_point`) is
    the right one."""
    a = alpha_c + sgn * past
    # both clamps at the (mean) angle, about the scene's misalignment (`jaxrod.SymmetricAlpha`)
    half = 0.5 * (scene.clamps.alpha_left - scene.clamps.alpha_right)
    sc_c = eqx.tree_at(lambda s: (s.clamps.alpha_left, s.clamps.alpha_right), scene,
                       (alpha_c + half, alpha_c - half))
    sc_run = eqx.tree_at(lambda s: (s.clamps.alpha_left, s.clamps.alpha_right), scene, (a + half, a - half))
    theta0 = nudge_start(theta_c, mode, sc_run, sgn, nudge)
    ok = exists & jnp.all(jnp.isfinite(theta_c)) & jnp.all(jnp.isfinite(mode))
    return Start(sc_run, theta0, Protocol(a + half, a - half), sgn, alpha_c,
                 _bending(theta_c, sc_c, discretize(sc_c)), ok)


def ramp(scene, direction="up", *, rate=0.5, alpha_start=None, right_only=False, snap=None,
         seed=0.0) -> Start:
    r"""The ramp scene: start at rest in the stable state opposite to `direction` with the
    clamps at `alpha_start` (rad, the mean clamp angle about the scene's misalignment as in
    [`jaxrod.SymmetricAlpha`][]; default $\alpha_c-2^\circ$ in the snapping direction, from
    `jr.snap_angles`), then rotate at `rate` (rad/T, > 0; sign from `direction`). With
    `right_only=True` only the right clamp turns (the left stays at its angle in `scene`
    when `alpha_start` is given, else at 0). `seed` (rad, >= 0): the mirror-breaking
    imperfection of the start (module docstring; 0 keeps the exact equilibrium)."""
    sgn = _direction(direction)
    check_param("rate", rate, lo=0.0)
    check_param("seed", seed, lo=0.0, lo_open=False)
    if alpha_start is not None:
        check_param("alpha_start", alpha_start)
    alpha_c = jnp.nan
    if alpha_start is None:
        if right_only:
            raise ValueError("alpha_start: give the starting right-clamp angle for an asymmetric ramp")
        snap = snap_angles(scene) if snap is None else snap
        path = snap.up if sgn > 0 else snap.down
        alpha_c = path.alpha_c
        alpha_start = alpha_c - sgn * 2.0 * math.pi / 180.0
    aR = alpha_start
    if right_only:
        aL = scene.clamps.alpha_left
    else:  # both clamps at the (mean) angle, about the scene's misalignment (`jaxrod.SymmetricAlpha`)
        half = 0.5 * (jnp.asarray(scene.clamps.alpha_left, float) - jnp.asarray(scene.clamps.alpha_right, float))
        aL, aR = alpha_start + half, alpha_start - half
    sc = eqx.tree_at(lambda s: (s.clamps.alpha_left, s.clamps.alpha_right), scene,
                     (jnp.asarray(aL, float), jnp.asarray(aR, float)))
    eq = initial_state(sc, "down" if sgn > 0 else "up")
    from ..statics import bending_energy

    rl = 0.0 if right_only else sgn * rate
    theta0 = eq.theta if (isinstance(seed, (int, float)) and seed == 0) else mirror_seed(eq.theta, sc, seed)
    return Start(sc, theta0, Protocol(aL, aR, rl, sgn * rate), sgn, alpha_c,
                 bending_energy(eq), eq.result == RESULTS.successful)


class Brink(eqx.Module):
    """The brink scene of [`jaxrod.snap_dynamics`][] (see [`jaxrod.brink`][]): `nudge` along the
    unstable mode, clamps held `past` rad beyond the critical angle, `route` "first" or
    "second"."""

    nudge: float = NUDGE
    past: float = 1e-3
    route: str = "first"


class Ramp(eqx.Module):
    """The ramp scene of [`jaxrod.snap_dynamics`][] (see [`jaxrod.ramp`][]): both clamps turn at
    `rate` rad/T from `alpha_start` (default 2 deg before the snap), `seed` the mirror-breaking
    amplitude."""

    rate: float = 0.5
    alpha_start: float | None = None
    seed: float = 0.0


class Asymmetric(eqx.Module):
    """The asymmetric scene of [`jaxrod.snap_dynamics`][]: only the right clamp turns, at `rate`
    rad/T from `alpha_start` (default 0), the run going on past the snap."""

    rate: float = 0.5
    alpha_start: float | None = None
    seed: float = 0.0


_KIND_DEFAULTS = dict(nudge=NUDGE, past=1e-3, rate=0.5, alpha_start=None, seed=0.0, route="first")


def _kind_settings(kind, given):
    """`snap_dynamics`' scene kind as `(name, settings)` from a `Brink` / `Ramp` / `Asymmetric` or
    a string with the keywords `given`; a keyword that contradicts the object raises."""
    if isinstance(kind, (Brink, Ramp, Asymmetric)):
        fields = {f: getattr(kind, f) for f in kind.__dataclass_fields__}
        for name, value in given.items():
            if name in _KIND_DEFAULTS and _differs(value, _KIND_DEFAULTS[name]):
                if name not in fields:
                    raise ValueError(f"{name}: does not apply to {type(kind).__name__}")
                if _differs(value, fields[name]):
                    raise ValueError(f"{name}: given both as {type(kind).__name__}({name}={fields[name]!r}) "
                                     f"and as {name}={value!r}")
        name = {Brink: "brink", Ramp: "ramp", Asymmetric: "asymmetric"}[type(kind)]
        return name, {**given, **fields}
    if kind not in ("brink", "ramp", "asymmetric"):
        raise ValueError(f"kind must be jaxrod.Brink(...), jaxrod.Ramp(...), jaxrod.Asymmetric(...) or "
                         f"'brink', 'ramp', 'asymmetric', got {kind!r}")
    return kind, given


def _differs(a, b):
    if a is None or b is None or isinstance(a, str) or isinstance(b, str):
        return a is not b and a != b
    try:
        return float(a) != float(b)
    except (TypeError, ValueError):
        return True


def snap_dynamics(scene, direction="up", *, kind="brink", nudge=NUDGE, past=1e-3, rate=0.5,
                  alpha_start=None, snap=None, seed=0.0, route="first", **simulate_kwargs):
    """One dynamic snap: build the `kind` scene (a [`jaxrod.Brink`][], [`jaxrod.Ramp`][] or
    [`jaxrod.Asymmetric`][] with its settings, or the strings "brink", "ramp", "asymmetric" with
    the keywords: `seed` for the ramps, `route` for the brink; see the module docstring) and
    integrate it with [`jaxrod.simulate`][] (its keywords, e.g. `solver=jaxrod.HHT()`).
    Returns (start, trajectory)."""
    from ._simulate import simulate

    kind, ks = _kind_settings(kind, dict(nudge=nudge, past=past, rate=rate, alpha_start=alpha_start,
                                         seed=seed, route=route))
    nudge, past, rate, alpha_start, seed, route = (ks[k] for k in ("nudge", "past", "rate", "alpha_start",
                                                                  "seed", "route"))
    # every setting before any statics are solved (the start state costs a snap_angles)
    if kind not in ("brink", "ramp", "asymmetric"):
        raise ValueError(f"kind must be 'brink', 'ramp' or 'asymmetric', got {kind!r}")
    if route not in ("first", "second"):
        raise ValueError(f"route must be 'first' or 'second', got {route!r}")
    _direction(direction)
    check_param("nudge", nudge, lo=0.0)
    check_param("past", past, lo=0.0, lo_open=False)
    check_param("rate", rate, lo=0.0)
    check_param("seed", seed, lo=0.0, lo_open=False)
    if alpha_start is not None:
        check_param("alpha_start", alpha_start)
    names = inspect.signature(check_run_settings).parameters
    check_run_settings(**{k: v for k, v in simulate_kwargs.items() if k in names})
    if kind == "brink":
        start = brink(scene, direction, nudge=nudge, past=past, snap=snap, route=route)
    elif kind == "ramp":
        start = ramp(scene, direction, rate=rate, alpha_start=alpha_start, snap=snap, seed=seed)
    else:
        start = ramp(scene, direction, rate=rate, alpha_start=0.0 if alpha_start is None else alpha_start,
                     right_only=True, seed=seed)
        simulate_kwargs.setdefault("stop_at_snap", False)
    simulate_kwargs.setdefault("direction", _direction(direction))
    traj = simulate(start.scene, start.theta0, start.protocol, **simulate_kwargs)
    return start, traj
