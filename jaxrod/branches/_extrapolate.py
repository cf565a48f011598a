r"""Snap angles extrapolated to the continuum: Richardson extrapolation on two meshes.

The discrete rod is second-order accurate: at a fixed mesh family (uniform, or the same
grading), $\alpha_c(N)=\alpha_c^\ast+c\,N^{-2}+O(N^{-4})$; the measured order is 2.00 at
every point of `benchmarks/results/convergence_alpha_c.md`. At the default $N=100$ the
mesh error is up to 0.17 deg ($s_0=0.02$). From $N$ and $2N$,

$$\alpha_R=\alpha_{2N}+\frac{\alpha_{2N}-\alpha_N}{2^2-1},\qquad
\varepsilon=\frac{|\alpha_{2N}-\alpha_N|}{3},$$

$\varepsilon$ estimating the error of $\alpha_{2N}$ (that of $\alpha_R$ is of higher order:
about $10^{-3}$ deg at $N=100$, see `tests/test_extrapolate.py`). The same combination is
applied to the fold heights before and after the snap. Where the two meshes disagree
(one snaps and the other does not, the kind differs, or, with self-contact, the number of
contact clicks before the snap: near a termination gap or where a fold and a branch point
cross), nothing is extrapolated: the fine-mesh values are
returned with `consistent=False` and the error estimate $|\alpha_{2N}-\alpha_N|$ (NaN
where one mesh does not snap).

Everything is differentiable like [`jaxrod.snap_angles`][] (a fixed linear combination).
"""

from __future__ import annotations

from types import SimpleNamespace

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array

from ..model import Mesh, Scene
from ._snap import SnapAngles, SnapPath, snap_angles
from ..results import RESULTS


ORDER = 2


class ExtrapolatedPath(eqx.Module):
    """One path (`up` or `down`) extrapolated from two meshes.

    `snaps`, `kind` (of the fine mesh), `alpha_c` (rad; NaN if it does not snap),
    `error` (rad, estimated error: of the fine mesh's value, an upper bound for
    `alpha_c`'s own where `consistent`), `alpha_c_coarse`, `alpha_c_fine`,
    `fold_height_before`, `fold_height_after` (extrapolated likewise), `consistent`;
    `result` the verdict on both meshes (the fine mesh's path code if it is not successful,
    else the coarse mesh's, else `mesh_inconsistent` where the meshes disagree, else
    `successful`), `start_result` likewise for the start states, and every code of each mesh:
    `result_coarse`, `result_fine`, `start_result_coarse`, `start_result_fine`,
    `refine_result_coarse`, `refine_result_fine` (None without the refinement)."""

    snaps: Array
    kind: Array
    alpha_c: Array
    error: Array
    alpha_c_coarse: Array
    alpha_c_fine: Array
    fold_height_before: Array
    fold_height_after: Array
    consistent: Array
    result: RESULTS
    start_result: RESULTS
    result_coarse: RESULTS
    result_fine: RESULTS
    start_result_coarse: RESULTS
    start_result_fine: RESULTS
    refine_result_coarse: RESULTS | None = None
    refine_result_fine: RESULTS | None = None


class ExtrapolatedSnapAngles(eqx.Module):
    """`up`, `down`: [`jaxrod.ExtrapolatedPath`][]s; `coarse` and `fine` the two
    [`jaxrod.SnapAngles`][] (at `n_coarse` and `n_fine` segments)."""

    up: ExtrapolatedPath
    down: ExtrapolatedPath
    coarse: SnapAngles
    fine: SnapAngles
    n_coarse: int = eqx.field(static=True)
    n_fine: int = eqx.field(static=True)


def refined_scene(scene: Scene, factor: int = 2) -> Scene:
    """The same scene on a mesh `factor` times finer (same grading)."""
    m = scene.mesh
    return Scene(scene.strip, scene.clamps, Mesh(factor * m.n, m.refine, m.width, m.centres), scene.stretching, scene.gravity,
                 scene.contact)


def richardson(coarse, fine, factor: int = 2):
    r"""Richardson extrapolation of a quantity computed on a mesh and on one `factor` times
    finer, for the discretization's order 2: $q_f+(q_f-q_c)/(\text{factor}^2-1)$."""
    return fine + (fine - coarse) / (factor**ORDER - 1.0)


def extrapolate_path(c: SnapPath, f: SnapPath) -> ExtrapolatedPath:
    r"""One path of [`snap_angles_extrapolated`][] from its coarse (`c`, $N$) and fine (`f`,
    $2N$) [`jaxrod.SnapPath`][]s (module docstring). Reads their `snaps`, `kind`, `clicks`,
    `alpha_c`, `fold_height_before`, `fold_height_after`, `result`, `start_result` and
    `refine_result` only, so the two may also come from separate programs (the CLI runs the
    meshes as two)."""
    r = 2.0**ORDER - 1.0
    consistent = (c.snaps == f.snaps) & (c.kind == f.kind) & (c.clicks == f.clicks)
    both = consistent & f.snaps

    def ex(a, b):
        return jnp.where(both, richardson(a, b), b)

    err = jnp.where(both, jnp.abs(f.alpha_c - c.alpha_c) / r,
                    jnp.where(c.snaps & f.snaps, jnp.abs(f.alpha_c - c.alpha_c), jnp.nan))
    err = jnp.where(~c.snaps & ~f.snaps, 0.0, err)
    ok = RESULTS.successful

    def worst(cr, fr):
        return RESULTS.where(fr != ok, fr, cr)

    result = worst(c.result, f.result)
    result = RESULTS.where((result == ok) & ~consistent, RESULTS.mesh_inconsistent, result)
    return ExtrapolatedPath(
        snaps=f.snaps, kind=f.kind, alpha_c=ex(c.alpha_c, f.alpha_c), error=err,
        alpha_c_coarse=c.alpha_c, alpha_c_fine=f.alpha_c,
        fold_height_before=ex(c.fold_height_before, f.fold_height_before),
        fold_height_after=ex(c.fold_height_after, f.fold_height_after),
        consistent=consistent,
        result=result, start_result=worst(c.start_result, f.start_result),
        result_coarse=c.result, result_fine=f.result,
        start_result_coarse=c.start_result, start_result_fine=f.start_result,
        refine_result_coarse=c.refine_result, refine_result_fine=f.refine_result,
    )


def snap_angles_extrapolated(scene: Scene, *, continue_after_snap: bool = False, near=None,
                             **kwargs) -> ExtrapolatedSnapAngles:
    r"""[`jaxrod.snap_angles`][] on the scene's mesh ($N$) and on one twice as fine, and
    their Richardson extrapolation (module docstring). `kwargs` go to `snap_angles`.
    Costs one `snap_angles` at $N$ plus one at $2N$ (two compilations on first use), run one
    after the other (under `jax.vmap` each member's two meshes).

    `near`: the `snap_angles_extrapolated` of a neighbouring scene with the same mesh, whose
    coarse and fine paths start this scene's (`snap_angles(..., near=)` on each mesh: the
    same angles, from a neighbour's critical point where its checks accept it), or None.

    `continue_after_snap` defaults to False here: the landed branch after each snap (the
    post-snap stage of the hysteresis figures) does not change the critical angles or the
    landed states, and skipping it saves about a quarter of the run; pass True to keep it
    in `coarse` and `fine`."""
    near_coarse = near_fine = None
    if near is not None:
        if not isinstance(near, ExtrapolatedSnapAngles):
            raise ValueError("near must be the jaxrod.snap_angles_extrapolated result of a neighbouring scene "
                             f"(its coarse and fine meshes) or None, got {type(near).__name__}")
        near_coarse, near_fine = near.coarse, near.fine
    fine_scene = refined_scene(scene)
    kwargs = dict(kwargs, continue_after_snap=continue_after_snap)

    fine, coarse = snap_angles(fine_scene, near=near_fine, **kwargs), snap_angles(scene, near=near_coarse, **kwargs)
    up, down = _extrapolate_paths(*(_read(getattr(m, d)) for m in (coarse, fine) for d in ("up", "down")))
    return ExtrapolatedSnapAngles(up=up, down=down, coarse=coarse, fine=fine, n_coarse=scene.mesh.n,
                                  n_fine=fine_scene.mesh.n)


_FIELDS = ("snaps", "kind", "clicks", "alpha_c", "fold_height_before", "fold_height_after", "result", "start_result",
           "refine_result")


def _read(path):
    """The fields of a path that [`extrapolate_path`][] reads."""
    return {k: getattr(path, k) for k in _FIELDS}


@eqx.filter_jit
def _extrapolate_paths(coarse_up, coarse_down, fine_up, fine_down):
    """Both paths' [`extrapolate_path`][] (from the fields it reads) as one small compiled
    program: called eagerly, its few dozen scalar operations would each pay their own
    dispatch, a noticeable part of the whole query on small meshes."""
    ns = lambda d: SimpleNamespace(**d)  # noqa: E731
    return (extrapolate_path(ns(coarse_up), ns(fine_up)), extrapolate_path(ns(coarse_down), ns(fine_down)))
