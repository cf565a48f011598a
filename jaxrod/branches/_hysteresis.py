r"""The quasi-static hysteresis loop of a symmetrically actuated strip (paper Fig. 2a-b, 3c).

Protocol (docs/model.md): start in the down state at $\alpha=0$, raise $\alpha$ until it loses
stability at $\alpha_{c,\rm up}$ and jumps to the up state; from the up state lower
$\alpha$ until $\alpha_{c,\rm down}$ and the jump back down. [`jaxrod.snap_angles`][]
gives the critical angles, their kinds and the states before and after each jump.

Here the two equilibrium branches through the start states (the down state at
$\alpha=0$, or where it does not exist the state `snap_angles` starts its snap-up path
from; and the up state at $\alpha=0$) are followed by pseudo-arclength continuation in
both directions of $\alpha$, past the snap points and through folds, and every point
is marked stable or unstable by its Sturm count $\nu$ (number of negative eigenvalues
of the constrained Hessian, asymmetric modes included). A branch is kept up to the
first point with $\nu>$ `max_unstable` (default 1: the stable parts and the first
unstable part, e.g. the middle branch between two folds), or to $|\alpha|=$ `bound`.

Observables per point: fold height $y(L/2)$ and bending energy
$E_b=\sum_k \frac{B}{2\ell_k}(\phi_k-\bar\phi_k)^2$ (the discrete form of
$\frac B2\int(\theta'-\theta_0')^2ds$). The jumps are vertical segments at
$\alpha_c$ from the critical state to the state it lands in.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array

from ._continuation import Continuation, SymmetricAlpha, continue_branch, require_float64
from ..energy.lagrangian import energies as _energies
from ..energy.lagrangian import positions
from ..statics import float_scene
from .._misc import check_int, check_number
from .._compile import jit
from ._snap import SnapAngles, snap_angles
from ..results import RESULTS
from ..statics import Equilibrium

# the four branches, in this order
BRANCH_NAMES = ("down_start_increasing", "down_start_decreasing", "up_start_increasing", "up_start_decreasing")


class Hysteresis(eqx.Module):
    """The quasi-static loop.

    **Fields** (leading axis of the branch arrays: the 4 branches of `BRANCH_NAMES`, then
    up to `max_points` points; entries past a branch's end are NaN / -1 / False):
    - `alpha` (4, M): clamp angle (rad) along each branch;
    - `fold_height` (4, M), `bending_energy` (4, M);
    - `num_unstable` (4, M): negative-eigenvalue count (0 = stable);
    - `valid` (4, M): the point belongs to the branch (converged, within `max_unstable`);
    - `snap`: the [`jaxrod.SnapAngles`][] (critical angles, kinds, states before/after);
    - `energy_before_up`, `energy_after_up`, `energy_before_down`, `energy_after_down`:
      bending energies at the jumps (NaN if that path does not snap);
    - `crossing` (4, M): the valid point passes through itself (`jaxrod.self_intersects`).

    `result`: the snap-up path's code if it is not successful, else the snap-down's, else
    `self_intersecting` where a valid point of a branch passes through itself.
    """

    alpha: Array
    fold_height: Array
    bending_energy: Array
    num_unstable: Array
    valid: Array
    snap: SnapAngles
    energy_before_up: Array
    energy_after_up: Array
    energy_before_down: Array
    energy_after_down: Array
    crossing: Array

    @property
    def result(self):
        """The loop's code: the snap-up path's if it is not successful, else the snap-down's,
        else `self_intersecting` where a branch point passes through itself."""
        up, down = self.snap.up.result, self.snap.down.result
        paths = RESULTS.where(up != RESULTS.successful, up, down)
        return RESULTS.where((paths == RESULTS.successful) & jnp.any(self.crossing), RESULTS.self_intersecting,
                             paths)


def _energy_at(scene, theta, force, alpha):
    sc = SymmetricAlpha.for_scene(scene).set(scene, alpha)
    return _energies(theta, force, sc)["bending"]


def hysteresis(scene, *, bound: float = jnp.pi, max_unstable: int = 1,
               settings: Continuation = Continuation(max_points=300)) -> Hysteresis:
    r"""The quasi-static hysteresis loop of `scene` under symmetric clamp rotation
    $\alpha_L=\alpha_R=\alpha$ (about the scene's clamp misalignment $\alpha_L-\alpha_R$, if any:
    see [`jaxrod.SymmetricAlpha`][]; $\alpha$ is the mean clamp angle).

    Returns a [`jaxrod.Hysteresis`][]: fold height and bending energy along the four
    half-branches through the down and up start states (stable and unstable points
    marked), and the jumps from [`jaxrod.snap_angles`][]. Needs float64.

    Two compiled pieces, `snap_angles` (shared with every other caller) and the
    vmapped continuation of the four branches, so `hysteresis` itself is not meant to be
    wrapped in `jit`. `bound` in $(0,\pi]$ (rad), `max_unstable` an integer >= 0."""
    check_number("bound", bound, lo=0.0, hi=jnp.pi, hi_open=False)
    check_int("max_unstable", max_unstable, lo=0)
    if not isinstance(settings, Continuation):
        raise ValueError(f"settings must be a jaxrod.Continuation, got {settings!r}")
    scene = float_scene(scene)
    scene = jax.lax.stop_gradient(SymmetricAlpha.for_scene(scene).set(scene, 0.0))
    dtype = jnp.result_type(scene.strip.psi0)
    require_float64(dtype, "hysteresis")
    snap = snap_angles(scene, bound=bound)
    return _branches(scene, snap, bound, max_unstable, settings)


@jit
def _branches(scene, snap, bound, max_unstable, settings):
    parameter = SymmetricAlpha.for_scene(scene)
    dtype = jnp.result_type(scene.strip.psi0)
    # start states: first point of the first stage of each path
    starts_t = jnp.stack([snap.up.branch.theta[0, 0], snap.down.branch.theta[0, 0]])
    starts_m = jnp.stack([snap.up.branch.force[0, 0], snap.down.branch.force[0, 0]])
    starts_l = jnp.stack([snap.up.branch.lam[0, 0], snap.down.branch.lam[0, 0]])
    ok = jnp.stack([snap.up.start_result == RESULTS.successful, snap.down.start_result == RESULTS.successful])
    idx = jnp.array([0, 0, 1, 1])
    direction = jnp.array([1.0, -1.0, 1.0, -1.0], dtype)

    def one(t0, m0, l0, d):
        sc = parameter.set(scene, l0)
        eq = Equilibrium(t0, m0, RESULTS.successful, jnp.zeros((), jnp.int32), jnp.zeros((), jnp.int32), sc)
        br = continue_branch(sc, eq, parameter, direction=d, bounds=(-bound, bound), settings=settings)
        n_pts = br.lam.shape[0]
        inside = jnp.arange(n_pts) < br.count
        too_unstable = (br.num_unstable > max_unstable) | ~inside
        first_bad = jnp.argmax(jnp.concatenate([too_unstable, jnp.ones(1, bool)]))
        valid = jnp.arange(n_pts) < first_bad
        e = jax.vmap(lambda t, m, a: _energy_at(scene, t, m, a))(br.theta, br.force, br.lam)
        return br.lam, br.fold_height, e, br.num_unstable, valid, br.crossing

    lam, fh, e, nu, valid, crossing = jax.vmap(one)(starts_t[idx], starts_m[idx], starts_l[idx], direction)
    valid = valid & ok[idx][:, None]
    crossing = crossing & valid
    nan = jnp.nan
    lam, fh, e = (jnp.where(valid, x, nan) for x in (lam, fh, e))
    nu = jnp.where(valid, nu, -1)

    def jump_energies(p, sign):
        before = _energy_at(scene, p.theta_before, p.force_before, p.alpha_c)
        after = _energy_at(scene, p.theta_after, p.force_after, p.alpha_c + sign * 1e-3)
        return jnp.where(p.snaps, before, nan), jnp.where(p.snaps, after, nan)

    ebu, eau = jump_energies(snap.up, 1.0)
    ebd, ead = jump_energies(snap.down, -1.0)
    return Hysteresis(lam, fh, e, nu, valid, snap, ebu, eau, ebd, ead, crossing)


def fold_height_of(theta, force, scene, alpha):
    """Fold height of angles `theta` at (mean) clamp angle `alpha`, about `scene`'s clamp
    misalignment."""
    sc = SymmetricAlpha.for_scene(scene).set(scene, alpha)
    return positions(theta, force, sc)[sc.mesh.n // 2, 1]
