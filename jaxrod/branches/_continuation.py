r"""Pseudo-arclength continuation of equilibria in one parameter, inside `jit`.

The equilibria solve $F(x,\lambda)=\nabla\tilde{\mathcal L}(x;\lambda)=0$ with
$x=(\theta,\mu)$. Steps follow the branch through turning points:

* predictor $x_p = x + \Delta s\,\tau_x$, $\lambda_p=\lambda+\Delta s\,\tau_\lambda$;
* corrector: Newton on $F=0$ together with the arclength condition
  $\langle\tau_x, x-x_p\rangle_W + \tau_\lambda(\lambda-\lambda_p)=0$, whose Jacobian
  $\begin{pmatrix}\mathsf K & F_\lambda\\ c^\top & \tau_\lambda\end{pmatrix}$ is solved by
  block elimination on the structured $\mathsf K$ (plus one step of iterative refinement,
  which keeps it accurate where $\mathsf K$ is nearly singular, at folds); a corrected
  point farther than $|\Delta s|$ from the prediction is rejected like a failed corrector
  (the step is halved): it jumped to another branch;
* new tangent from the same bordered matrix with right-hand side $(0, 1)$, which keeps
  the orientation ($\tau_{\rm old}\cdot\tau_{\rm new}>0$).

$\langle a,b\rangle_W=\sum_i h_i a_{\theta_i} b_{\theta_i}$ (the $L^2$ norm of the angle
field; the force is not part of the arclength). Along the branch the number
$\nu$ of negative eigenvalues of the constrained Hessian (asymmetric modes included) is
recorded at every point. Fixed-size buffers, `lax.while_loop`: jittable and vmappable.
"""

from __future__ import annotations

import abc

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jaxtyping import Array

from ..linalg import kkt
from ..energy.geometry import discretize
from ..energy.contact import self_intersects
from ..energy.lagrangian import lagrangian_gradient, positions
from ..statics import float_scene
from .._lanes import machine_vmap
from .._misc import check_bool, check_int, check_number, check_sign, is_concrete, run_if
from .._compile import jit
from ..results import RESULTS


def require_float64(dtype, what):
    """Continuation and critical-point refinement need float64: in float32 the Sturm
    count near a singular Hessian and the 1e-8 rad refinement are below round-off."""
    if dtype != jnp.float64:
        raise ValueError(
            f"{what} needs float64; enable it with jax.config.update('jax_enable_x64', True) "
            "before building the scene (float32 is supported only by solve_equilibrium and "
            "initial_state, to the tolerance in docs/results.md)"
        )


class AbstractParameter(eqx.Module):
    """The continuation parameter: how to read it from and write it into a scene."""

    @abc.abstractmethod
    def get(self, scene):
        """Current value of the parameter in `scene`."""

    @abc.abstractmethod
    def set(self, scene, value):
        """A copy of `scene` with the parameter set to `value`."""


class SymmetricAlpha(AbstractParameter):
    r"""Both clamps turned together by $\alpha$ (radians) about a fixed misalignment
    $\delta$ = `misalignment` (radians, default 0):
    $\alpha_L=\alpha+\delta/2$, $\alpha_R=\alpha-\delta/2$, so that $\alpha$ is the mean clamp
    angle and $\alpha_L-\alpha_R=\delta$. With $\delta=0$ (the paper's symmetric actuation)
    $\alpha_L=\alpha_R=\alpha$. [`for_scene`][jaxrod.SymmetricAlpha.for_scene] takes
    $\delta$ from a scene's clamps."""

    misalignment: float | jax.Array = 0.0

    @classmethod
    def for_scene(cls, scene) -> "SymmetricAlpha":
        """The actuation that keeps `scene`'s clamp misalignment $\alpha_L-\alpha_R$."""
        return cls(jnp.asarray(scene.clamps.alpha_left) - jnp.asarray(scene.clamps.alpha_right))

    def get(self, scene):
        return 0.5 * (scene.clamps.alpha_left + scene.clamps.alpha_right)

    def set(self, scene, value):
        half = 0.5 * self.misalignment
        return eqx.tree_at(lambda s: (s.clamps.alpha_left, s.clamps.alpha_right), scene,
                           (value + half, value - half))


class LeftAlpha(AbstractParameter):
    r"""The left clamp angle $\alpha_L$ alone (the right one stays fixed)."""

    def get(self, scene):
        return scene.clamps.alpha_left

    def set(self, scene, value):
        return eqx.tree_at(lambda s: s.clamps.alpha_left, scene, value)


class RightAlpha(AbstractParameter):
    r"""The right clamp angle $\alpha_R$ alone."""

    def get(self, scene):
        return scene.clamps.alpha_right

    def set(self, scene, value):
        return eqx.tree_at(lambda s: s.clamps.alpha_right, scene, value)


class Gap(AbstractParameter):
    """The gap G."""

    def get(self, scene):
        return scene.clamps.gap

    def set(self, scene, value):
        return eqx.tree_at(lambda s: s.clamps.gap, scene, value)


CORRECTOR_STEPS = 8
CONTACT_CORRECTOR_STEPS = 16


class Continuation(eqx.Module):
    """Step control of [`jaxrod.continue_branch`][]: initial, smallest and largest
    arclength step, buffer size `max_points`, corrector iterations and tolerance.

    `corrector_steps` None (the default) is 8, or `CONTACT_CORRECTOR_STEPS` = 16 in a scene
    with self-contact, where the stiff penalty can slow the corrector's Newton iterations
    (a corrector that converges sooner stops sooner; at Psi0 = 60 deg, G/L = 0.075, N = 48
    both limits give the same snap angles). `tol` None is 1e-9 in float64."""

    ds: float = eqx.field(static=True, default=0.05)
    ds_min: float = eqx.field(static=True, default=1e-7)
    ds_max: float = eqx.field(static=True, default=0.2)
    max_points: int = eqx.field(static=True, default=400)
    corrector_steps: int | None = eqx.field(static=True, default=None)
    tol: float | None = eqx.field(static=True, default=None)

    def steps_for(self, scene) -> int:
        """The corrector's iteration limit in `scene` (see the class docstring)."""
        if self.corrector_steps is not None:
            return self.corrector_steps
        return CORRECTOR_STEPS if scene.contact is None else CONTACT_CORRECTOR_STEPS

    def __check_init__(self):
        for name in ("ds", "ds_min", "ds_max"):
            check_number(name, getattr(self, name), lo=0.0)
        if self.ds_min > self.ds_max:
            raise ValueError(f"ds_min must not exceed ds_max, got ds_min={self.ds_min!r}, ds_max={self.ds_max!r}")
        check_int("max_points", self.max_points, lo=2)
        if self.corrector_steps is not None:
            check_int("corrector_steps", self.corrector_steps, lo=1)
        if self.tol is not None:
            check_number("tol", self.tol, lo=0.0)


STOP_RUNNING, STOP_FULL, STOP_BOUND, STOP_UNSTABLE, STOP_STEP = -1, 0, 1, 2, 3
"""`Branch.stop`: still running (inside the loop only), the buffer full, the parameter past its
bound, the stability changed, the step below `ds_min`."""


class Branch(eqx.Module):
    """A computed branch: fixed-size buffers, valid up to `count`.

    `lam` parameter values, `theta` (M, N), `force` (M, 2), `tau_lam` the parameter
    component of the unit tangent (its sign change marks a fold), `num_unstable`,
    `fold_height`, `ds` the step that led to each point; `stop` the reason the
    continuation ended (0: buffer full, 1: parameter bound, 2: stability changed,
    3: step too small); `crossing` (M,) whether each point passes through itself
    (`jaxrod.self_intersects`; False past `count`), or None where the branch was not
    checked (the stages inside a snap path, which check the states they report)."""

    lam: Array
    theta: Array
    force: Array
    tau_lam: Array
    num_unstable: Array
    fold_height: Array
    ds: Array
    count: Array
    stop: Array
    crossing: Array | None = None

    @property
    def result(self):
        """`continuation_incomplete` where the branch stopped on a full buffer (`stop` 0) or a
        step below `ds_min` (3); else `self_intersecting` where a point of it passes through
        itself; else `successful` (the bound, 1, or a loss of stability, 2)."""
        crossed = jnp.zeros((), bool) if self.crossing is None else jnp.any(self.crossing, axis=-1)
        return RESULTS.where((self.stop == STOP_FULL) | (self.stop == STOP_STEP), RESULTS.continuation_incomplete,
                             RESULTS.where(crossed, RESULTS.self_intersecting, RESULTS.successful))


def branch_crossings(theta, force, count, scene):
    """(M,) whether each of the first `count` states of `theta` (M, N) passes through itself
    (`jaxrod.self_intersects`; False past `count`): one O(N^2) check per computed point."""
    def body(k, out):
        # under `vmap` the loop runs to the largest count of the batch: a member past its own
        # count checks its first point instead of an unfilled (NaN) row, whose positions would
        # send the whole batch down the screens' slowest path
        valid = k < count
        j = jnp.where(valid, k, 0)
        return out.at[k].set(valid & self_intersects(theta[j], scene, force=force[j]))

    return lax.fori_loop(0, count, body, jnp.zeros(theta.shape[0], bool))


def _discretization(scene, parameter):
    """`sc -> discretize(sc)` for the scenes `parameter.set(scene, lam)`: for the clamp
    angles and the gap (which leave the mesh and the crease as they are) the scene's
    discretization computed once with the clamp tangents of `sc` put in, not the natural
    angles' differences anew at every evaluation."""
    if not isinstance(parameter, (SymmetricAlpha, LeftAlpha, RightAlpha, Gap)):
        return discretize
    d0 = discretize(scene)
    dtype = d0.h.dtype

    def at(sc):
        return d0._replace(theta_left=jnp.asarray(sc.clamps.alpha_left, dtype),
                           theta_right=-jnp.asarray(sc.clamps.alpha_right, dtype))

    return at


def _pieces(scene, parameter):
    """Residual F(x, lam), its lam-derivative and the structured Jacobian."""
    disc = _discretization(scene, parameter)

    def grad_at(t, m, lam):
        sc = parameter.set(scene, lam)
        return lagrangian_gradient(t, m, sc, disc(sc))

    def F(t, m, lam):
        return grad_at(t, m, lam)

    def F_lam(t, m, lam):
        return jax.jvp(lambda ll: grad_at(t, m, ll), (lam,), (jnp.ones_like(lam),))[1]

    def K(t, m, lam):
        sc = parameter.set(scene, lam)
        return kkt.structured(t, m, sc, disc(sc))

    return F, F_lam, K


def _bordered_columns(Kmat, Flam, c, clam, Rt, Rm, Rs):
    r"""Solve [[K, F_lam], [(c, 0)^T, clam]] (dt, dm, dlam) = (r_t, r_m, r_s) for k right-hand
    sides at once (`Rt` (N, k), `Rm` (2, k), `Rs` (k,)), with one step of iterative
    refinement: two structured solves of k + 1 columns in all (`kkt.solve_columns`), the
    column $K^{-1}F_\lambda$ of the first reused by the second. Returns `(Dt, Dm, Dl, nu)`,
    `nu` the unstable count $\nu(0)$ of `Kmat`."""
    k = Rt.shape[1]
    A, B, nu = kkt.solve_columns(Kmat, jnp.concatenate([Rt, Flam[0][:, None]], axis=1),
                                 jnp.concatenate([Rm, Flam[1][:, None]], axis=1))
    bt, bm = A[:, k], B[:, k]
    den = clam - jnp.dot(c, bt)

    def finish(At, Am, rs):
        dl = (rs - c @ At) / den
        return At - bt[:, None] * dl, Am - bm[:, None] * dl, dl

    Dt, Dm, Dl = finish(A[:, :k], B[:, :k], Rs)
    kt, km = kkt.matvec_columns(Kmat, Dt, Dm)
    Et, Em, El = Rt - (kt + Flam[0][:, None] * Dl), Rm - (km + Flam[1][:, None] * Dl), Rs - (c @ Dt + clam * Dl)
    A2, B2, _ = kkt.solve_columns(Kmat, Et, Em)
    et, em, el = finish(A2, B2, El)
    return Dt + et, Dm + em, Dl + el, nu


def _unit_tangent(zt, zm, zl, w):
    nrm = jnp.sqrt(jnp.sum(w * zt**2) + zl**2)
    return zt / nrm, zm / nrm, zl / nrm


def _step_and_tangent(Kmat, Flam, c, clam, g, rs, w):
    r"""The corrector's Newton step for the residual `(g, rs)` and the unit tangent of the
    bordered matrix (right-hand side (0, 0, 1)), as two columns of one bordered solve, and
    $\nu(0)$ of `Kmat`: `((dt, dm, dl), (nt, nm, nl), nu)`."""
    Rt = jnp.stack([-g[0], jnp.zeros_like(g[0])], axis=1)
    Rm = jnp.stack([-g[1], jnp.zeros_like(g[1])], axis=1)
    Rs = jnp.stack([-rs, jnp.ones_like(rs)])
    Dt, Dm, Dl, nu = _bordered_columns(Kmat, Flam, c, clam, Rt, Rm, Rs)
    return (Dt[:, 0], Dm[:, 0], Dl[0]), _unit_tangent(Dt[:, 1], Dm[:, 1], Dl[1], w), nu


def _residual_norm(g, scene):
    st = scene.strip
    return jnp.maximum(jnp.max(jnp.abs(g[0])) * st.length / st.bending_stiffness,
                       jnp.max(jnp.abs(g[1])) / st.length)


def _check_bounds(name, bounds):
    """`bounds` = (lo, hi), lo < hi, neither NaN (infinite ends allowed); traced ends pass."""
    try:
        lo, hi = bounds
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a pair (lo, hi), got {bounds!r}") from None
    for v in (lo, hi):
        if is_concrete(v) and (np.ndim(v) != 0 or isinstance(v, (bool, str)) or np.isnan(float(v))):
            raise ValueError(f"{name} must be a pair of numbers (lo, hi), got {bounds!r}")
    if is_concrete(lo) and is_concrete(hi) and not float(lo) < float(hi):
        raise ValueError(f"{name} must be (lo, hi) with lo < hi, got {bounds!r}")


def _continuation_machine(static, settings, tol, stop_on_instability):
    r"""`continue_branch`'s loop as a machine (`jaxrod._lanes`): inputs `((arrays, p_arrays),
    theta0, force0, lo, hi, direction)`, the scene's and the parameter's arrays (`static` the
    pair of their other leaves), the start
    state, the bounds and the start direction (+1 or -1); result `(buffers, count, stop)`. One pass of the loop is one corrector iteration
    (the residual at the iterate, and where it is above tolerance the Newton step on the
    bordered system of the module docstring); the pass whose iteration decides the step
    (converged, or given up after `steps` iterations or at a non-finite iterate) also records
    the point, takes the new tangent and unstable count from the same bordered solve (two
    more columns of it) and predicts the next point. A batch runs on lanes: each member goes
    from step to step on its own, and the batch costs its members' corrector iterations, not
    its slowest member's."""
    M = settings.max_points

    def unpack(x):
        (arrays, p_arrays), t0, m0, lo, hi, _ = x
        scene = eqx.combine(arrays, static[0])
        parameter = eqx.combine(p_arrays, static[1])
        F, F_lam, Kf = _pieces(scene, parameter)
        disc = _discretization(scene, parameter)
        w = discretize(scene).h
        N = t0.shape[0]

        def fh(t, m, lam):
            sc = parameter.set(scene, lam)
            return positions(t, m, sc, disc(sc))[N // 2, 1]

        return scene, parameter, F, F_lam, Kf, w, fh, lo, hi

    def predicted(t, m, lam, tau, ds):
        return t + ds * tau[0], m + ds * tau[1], lam + ds * tau[2]

    def init(x):
        _, t0, m0, _, _, direction = x
        scene, parameter, F, F_lam, Kf, w, fh, lo, hi = unpack(x)
        dtype, N = t0.dtype, t0.shape[0]
        lam0 = jnp.asarray(parameter.get(scene), dtype)
        K0 = Kf(t0, m0, lam0)
        # initial tangent: K z = -F_lam, tau = (z, 1) * direction, normalized
        zt, zm = kkt.solve(K0, -F_lam(t0, m0, lam0)[0], -F_lam(t0, m0, lam0)[1])
        nrm = jnp.sqrt(jnp.sum(w * zt**2) + 1.0)
        tau0 = (direction * zt / nrm, direction * zm / nrm, direction * jnp.ones((), dtype) / nrm)
        nu0 = kkt.count_below(K0, jnp.zeros(1, dtype))[0]
        buf = dict(
            lam=jnp.full((M,), jnp.nan, dtype).at[0].set(lam0),
            theta=jnp.full((M, N), jnp.nan, dtype).at[0].set(t0),
            force=jnp.full((M, 2), jnp.nan, dtype).at[0].set(m0),
            tau_lam=jnp.full((M,), jnp.nan, dtype).at[0].set(tau0[2]),
            num_unstable=jnp.full((M,), -1, jnp.int32).at[0].set(nu0),
            fold_height=jnp.full((M,), jnp.nan, dtype).at[0].set(fh(t0, m0, lam0)),
            ds=jnp.zeros((M,), dtype),
        )
        ds0 = jnp.asarray(settings.ds, dtype)
        return dict(buf=buf, i=jnp.ones((), jnp.int32), t=t0, m=m0, lam=lam0, tau=tau0, ds=ds0,
                    stop=jnp.full((), STOP_RUNNING, jnp.int32), x=predicted(t0, m0, lam0, tau0, ds0),
                    k=jnp.zeros((), jnp.int32), nu0=nu0)

    def step(x, c):
        scene, parameter, F, F_lam, Kf, w, fh, lo, hi = unpack(x)
        steps = settings.steps_for(scene)
        nu0 = c["nu0"]
        t, m, lam, tau, ds = c["t"], c["m"], c["lam"], c["tau"], c["ds"]
        tp, mp, lp = predicted(t, m, lam, tau, ds)
        cw = w * tau[0]
        xt, xm, xl = c["x"]
        g = F(xt, xm, xl)
        rs = jnp.dot(cw, xt - tp) + tau[2] * (xl - lp)
        Kn, Flam_n = Kf(xt, xm, xl), F_lam(xt, xm, xl)
        (dt, dm, dl), (nt, nm, nl), nu = _step_and_tangent(Kn, Flam_n, cw, tau[2], g, rs, w)
        converged = (_residual_norm(g, scene) <= tol) & (jnp.abs(rs) <= tol)
        k = c["k"] + 1
        tn, mn, ln = (jnp.where(converged, xt, xt + dt), jnp.where(converged, xm, xm + dm),
                      jnp.where(converged, xl, xl + dl))
        finite = jnp.all(jnp.isfinite(tn)) & jnp.isfinite(ln)
        decided = converged | (k >= steps) | ~finite
        # a correction longer than the step itself left the branch for another one (at Psi0 =
        # 60 deg, G/L = 0.075 with contact, a step of 0.025 landed 0.42 away, on an unstable
        # branch 18 deg back): not converged, so the step is halved
        far = jnp.sqrt(jnp.sum(w * (tn - tp) ** 2) + (ln - lp) ** 2) > jnp.abs(ds)
        conv = converged & ~far
        if scene.contact is not None:
            # with self-contact a step must not carry the strip through itself (a penalty
            # cannot undo a crossing): such a point is rejected and the step halved
            conv = conv & ~run_if(conv, lambda a, b, c_: self_intersects(a, parameter.set(scene, b), force=c_),
                                  jnp.zeros((), bool), (tn, ln, mn))
        accept = decided & conv
        i = c["i"]
        buf = c["buf"]
        # row i is written whether or not a point was accepted (otherwise it keeps what it
        # held): one row per pass, never a select over the whole buffer
        row = dict(lam=ln, theta=tn, force=mn, tau_lam=nl, num_unstable=nu, fold_height=fh(tn, mn, ln), ds=ds)
        buf = {key: buf[key].at[i].set(jnp.where(accept, row[key], buf[key][i])) for key in buf}
        i_new = jnp.where(accept, i + 1, i)
        grow = jnp.where(k <= 3, 1.5, 1.0)
        ds_new = jnp.where(decided, jnp.where(conv, jnp.minimum(ds * grow, settings.ds_max), 0.5 * ds), ds)
        out_of_bounds = accept & ((ln < lo) | (ln > hi))
        changed = accept & (nu != nu0) & stop_on_instability
        too_small = decided & (ds_new < settings.ds_min)
        stop = jnp.where(out_of_bounds, STOP_BOUND, jnp.where(changed, STOP_UNSTABLE,
                                                             jnp.where(too_small, STOP_STEP, STOP_RUNNING)))
        stop = jnp.where((stop == STOP_RUNNING) & (i_new >= M), STOP_FULL, stop).astype(jnp.int32)
        keep = lambda new, old: jnp.where(accept, new, old)  # noqa: E731
        t, m, lam = keep(tn, t), keep(mn, m), keep(ln, lam)
        tau = jax.tree.map(keep, (nt, nm, nl), tau)
        # the next iterate: the prediction of the next step once this one is decided
        nxt = predicted(t, m, lam, tau, ds_new)
        x = jax.tree.map(lambda p_, x_: jnp.where(decided, p_, x_), nxt, (tn, mn, ln))
        return dict(buf=buf, i=i_new, t=t, m=m, lam=lam, tau=tau, ds=ds_new, stop=stop, x=x,
                    k=jnp.where(decided, 0, k), nu0=nu0)


    def done(x, c):
        return (c["stop"] != STOP_RUNNING) | (c["i"] >= M)

    def finish(x, c):
        return c["buf"], c["i"], c["stop"]

    return machine_vmap(init, step, done, finish)


@jit
def continue_branch(scene, eq, parameter: AbstractParameter = SymmetricAlpha(), *, direction: float = 1.0,
                    bounds=(-jnp.pi, jnp.pi), settings: Continuation = Continuation(),
                    stop_on_instability: bool = False, check_contact: bool = True) -> Branch:
    r"""Follow the branch of equilibria through `eq` as `parameter` varies.

    **Arguments:**
    - `scene`, `eq`: the scene and an equilibrium of it (the start point).
    - `parameter`: a [`jaxrod.SymmetricAlpha`][] (default), `LeftAlpha`, `RightAlpha`
      or `Gap`.
    - `direction`: +1 to start toward increasing parameter, -1 toward decreasing.
    - `bounds`: stop once the parameter leaves this interval.
    - `stop_on_instability`: stop at the first point whose unstable count differs from
      the start's (a snap candidate).
    - `check_contact`: check every point for self-intersection (`Branch.crossing`; one
      O(N^2) pass per point after the continuation; with self-contact only the start's,
      since every later point was checked before it was accepted, see below).

    With self-contact (`scene.contact`) a corrected point that passes through itself is
    rejected like a corrector that fails (the step is halved): a step cannot carry the
    strip through itself.

    **Returns:** a [`jaxrod.Branch`][].
    """
    check_sign("direction", direction)
    _check_bounds("bounds", bounds)
    if not isinstance(settings, Continuation):
        raise ValueError(f"settings must be a jaxrod.Continuation, got {settings!r}")
    check_bool("stop_on_instability", stop_on_instability)
    check_bool("check_contact", check_contact)
    scene = lax.stop_gradient(float_scene(scene))
    dtype = eq.theta.dtype
    require_float64(dtype, "continue_branch")
    tol = settings.tol if settings.tol is not None else (1e-9 if dtype == jnp.float64 else 1e-3)
    lo, hi = bounds
    arrays, static = eqx.partition(scene, eqx.is_array)
    # the parameter's arrays (a misalignment) travel with the scene's as data, not as a closure
    p_arrays, p_static = eqx.partition(parameter, eqx.is_array)
    p_arrays = lax.stop_gradient(p_arrays)
    x = ((arrays, p_arrays), lax.stop_gradient(eq.theta), lax.stop_gradient(eq.force), jnp.asarray(lo, dtype),
         jnp.asarray(hi, dtype), jnp.asarray(direction, dtype))
    b, count, stop = _continuation_machine((static, p_static), settings, tol, stop_on_instability)(x)
    out = dict(buf=b, i=count, stop=stop)
    M = settings.max_points
    crossing = None
    if check_contact and scene.contact is not None:
        # every later point was checked before it was accepted: only the start is left
        start = self_intersects(b["theta"][0], scene, force=b["force"][0])
        crossing = jnp.zeros(M, bool).at[0].set(start)
    elif check_contact:
        crossing = branch_crossings(b["theta"], b["force"], out["i"], scene)
    return Branch(b["lam"], b["theta"], b["force"], b["tau_lam"], b["num_unstable"], b["fold_height"], b["ds"],
                  out["i"], out["stop"], crossing)
