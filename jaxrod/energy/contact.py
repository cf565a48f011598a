r"""Self-contact check: the clearance between non-neighbouring segments of the strip.

Segment $i$ ($i=0..N-1$) is the closed line segment $[\mathbf x_i,\mathbf x_{i+1}]$
between nodes $\mathbf x_k=\sum_{i<k}h_i(1+\varepsilon_i)\mathbf t_i$,
$\mathbf t_i=(\cos\theta_i,\sin\theta_i)$, node 0 at the left clamp (the positions of
`jaxrod.node_positions`; $\varepsilon=0$ unless the scene stretches and a force is given).
Segments $i$ and $j$ are *neighbours* when $|i-j|<2$: a segment and the two it shares a
node with. The clearance is the smallest distance between non-neighbours,

$$c=\min_{|i-j|\ge 2}\,d_{ij},\qquad
d_{ij}=\min_{\mathbf p\in[\mathbf x_i,\mathbf x_{i+1}],\ \mathbf q\in[\mathbf x_j,\mathbf x_{j+1}]}
|\mathbf p-\mathbf q| ,$$

in the length unit of the node positions (divide by $L$ to compare with $G/L$). A state
with $c=0$ passes through itself and is not a valid configuration of the contact-free model.

For segments $[\mathbf a,\mathbf b]$ and $[\mathbf c,\mathbf d]$, with the orientation
$o(\mathbf a,\mathbf b,\mathbf c)=(\mathbf b-\mathbf a)\times(\mathbf c-\mathbf a)$, the
segments intersect (touching included) when

$$\operatorname{sgn}o(\mathbf a,\mathbf b,\mathbf c)\,\operatorname{sgn}o(\mathbf a,\mathbf b,\mathbf d)\le 0,\quad
\operatorname{sgn}o(\mathbf c,\mathbf d,\mathbf a)\,\operatorname{sgn}o(\mathbf c,\mathbf d,\mathbf b)\le 0$$

and their bounding boxes overlap (which decides collinear segments); then $d=0$ exactly.
Otherwise $d$ is the smallest of the four endpoint-to-segment distances
$|\mathbf p-\mathbf a-t(\mathbf b-\mathbf a)|$,
$t=\operatorname{clip}\big((\mathbf p-\mathbf a)\cdot(\mathbf b-\mathbf a)/|\mathbf b-\mathbf a|^2,0,1\big)$.

Every pair is evaluated at once (index arrays fixed at trace time, $O(N^2)$ memory), so
the functions are jit- and vmap-compatible. The square root is guarded (double `where`),
so the gradient of $c$ is finite wherever the input is (zero where $c=0$). NaN positions
give $c=$ NaN and no intersection flagged.

Segments $i$ and $i+2$ are one segment apart, so $c\le\min_{0<k<N-1}h_k$ for any shape
(equality for a straight stretch): the clearance resolves how closely distant parts of
the strip approach only below the mesh size; `min_separation` $=m$ counts only pairs
$|i-j|\ge m$, which lifts the bound to about $(m-1)h$.

`self_intersects` first runs an $O(N)$ screen that decides most shapes exactly: with
$\mathbf d=(\cos\bar\theta,\sin\bar\theta)$, $\bar\theta$ the midpoint of the range of
the segment angles, and the segment vectors $\mathbf e_k=\mathbf x_{k+1}-\mathbf x_k$, if
every projection $p_k=\mathbf e_k\cdot\mathbf d$ exceeds the tolerance, the strip is strictly
monotone along $\mathbf d$ and segments $i<j-1$ are at least $p_{i+1}>$ `tol` apart along
$\mathbf d$: no crossing, clearance above `tol`. (Any $\mathbf d$ would do; the midpoint makes
the screen pass whenever the angle range is below $\pi$ and the mesh is not too fine.) Only
states that fail the screen pay for the $O(N^2)$ pair check.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .._misc import run_if
from .geometry import discretize
from .lagrangian import positions

TOL = 1e-9
"""Default tolerance of `self_intersects`, relative to the strip length."""


def _cross(u, v):
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def _norm(v):
    """|v| along the last axis with a finite gradient at v = 0 (double `where`); NaN stays NaN."""
    s2 = jnp.sum(v**2, -1)
    zero = s2 == 0
    return jnp.where(zero, 0.0, jnp.sqrt(jnp.where(zero, 1.0, s2)))


def _point_segment(p, a, b):
    r"""$|\mathbf p-\text{closest point of }[\mathbf a,\mathbf b]|$ (a point for $\mathbf a=\mathbf b$)."""
    u = b - a
    l2 = jnp.sum(u**2, -1)
    zero = l2 == 0
    t = jnp.where(zero, 0.0, jnp.sum((p - a) * u, -1) / jnp.where(zero, 1.0, l2))
    t = jnp.clip(t, 0.0, 1.0)
    return _norm(p - a - t[..., None] * u)


def _intersect(a, b, c, d):
    sab = jnp.sign(_cross(b - a, c - a)) * jnp.sign(_cross(b - a, d - a))
    scd = jnp.sign(_cross(d - c, a - c)) * jnp.sign(_cross(d - c, b - c))
    lo1, hi1 = jnp.minimum(a, b), jnp.maximum(a, b)
    lo2, hi2 = jnp.minimum(c, d), jnp.maximum(c, d)
    boxes = jnp.all((lo1 <= hi2) & (lo2 <= hi1), -1)
    return (sab <= 0) & (scd <= 0) & boxes


def pair_distances(x, min_separation: int = 2):
    r"""Distances $d_{ij}$ and intersection flags of all segment pairs $i<j$ with
    $j-i\ge$ `min_separation`, for node positions `x` (N+1, 2).

    Returns `(i, j, d, crosses)`: the index arrays (NumPy, fixed at trace time) and
    $d_{ij}$, `crosses` (shape (P,) each)."""
    n = x.shape[-2] - 1
    i, j = np.triu_indices(n, k=min_separation)
    a, b, c, d = x[..., i, :], x[..., i + 1, :], x[..., j, :], x[..., j + 1, :]
    crosses = _intersect(a, b, c, d)
    dist = jnp.minimum(jnp.minimum(_point_segment(a, c, d), _point_segment(b, c, d)),
                       jnp.minimum(_point_segment(c, a, b), _point_segment(d, a, b)))
    return i, j, jnp.where(crosses, 0.0, dist), crosses


def segment_distances(x, min_separation: int = 2):
    r"""`(clearance, crosses)` of node positions `x` (N+1, 2): the smallest distance
    between segments $i,j$ with $|i-j|\ge$ `min_separation` (an int, default 2: all
    non-neighbours), and whether any two of them intersect (touching included).

    With fewer than `min_separation + 1` segments there is no pair: `(inf, False)`."""
    _, _, d, crosses = pair_distances(x, min_separation)
    c = jnp.min(d, initial=jnp.inf, axis=-1)
    # XLA:CPU's row-wise min of a batch (several rows of ~1000 entries) can drop NaN and
    # return the initial value: NaN is propagated explicitly
    c = jnp.where(jnp.any(jnp.isnan(d), -1), jnp.nan, c)
    return c, jnp.any(crosses, -1)


def _nodes(theta, scene, force):
    d = discretize(scene)
    if force is None:
        e = d.h[:, None] * jnp.stack([jnp.cos(theta), jnp.sin(theta)], -1)
        return jnp.concatenate([jnp.zeros((1, 2), e.dtype), jnp.cumsum(e, 0)])
    return positions(theta, force, scene, d)


def _screen(x, theta, tol):
    """The O(N) screen of the module docstring: True where every segment of the nodes `x`
    projects by more than `tol` onto the mid direction of the angles `theta` (then no two
    non-neighbours are within `tol`). NaN positions fail it."""
    mid = 0.5 * (jnp.max(theta) + jnp.min(theta))
    proj = jnp.diff(x, axis=0) @ jnp.stack([jnp.cos(mid), jnp.sin(mid)])
    return jnp.all(proj > tol)


def clearance(theta, scene, *, force=None, min_separation: int = 2):
    r"""The clearance $c$ of the state `theta` (N,) of `scene` (module docstring), in
    the scene's length unit. Inextensible positions unless `force` (the end force
    $\mu$, e.g. `eq.force`) is given, with which a stretching scene's strains count."""
    return segment_distances(_nodes(theta, scene, force), min_separation)[0]


def self_intersects(theta, scene, tol=None, *, force=None, min_separation: int = 2):
    r"""Whether two non-neighbouring segments of the state `theta` intersect or come
    within `tol` of each other: $c\le$ `tol`. Default `tol` = `TOL` $\cdot L$
    ($10^{-9}$ of the strip length): crossings give $d=0$ exactly (orientation test),
    so they are flagged at any tolerance; the default also catches touching decided
    by rounding. A boolean scalar."""
    L = scene.strip.length
    tol = TOL * L if tol is None else tol
    # a flag carries no derivative: no tangent enters the screen's loop
    theta = jax.lax.stop_gradient(theta)
    force = None if force is None else jax.lax.stop_gradient(force)
    x = _nodes(theta, scene, force)
    monotone = _screen(x, theta, tol)

    def full(x, tol):
        c, crosses = segment_distances(x, min_separation)
        return crosses | (c <= tol)

    return run_if(~monotone, full, jnp.zeros((), bool), (x, jnp.asarray(tol, x.dtype)))
