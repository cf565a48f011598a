r"""Self-contact: the clearance between non-neighbouring segments of the strip, and the contact energy.

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
the screen pass whenever the angle range is below $\pi$ and the mesh is not too fine.) A
state that fails it (a folded strip often turns by more than $\pi$) meets a second screen:
if every two segments $|i-j|\ge$ `min_separation` have axis-aligned bounding boxes more than
`tol` apart along $x$ or $y$, no two are within `tol` (four comparisons per pair, about a
tenth of the distance computation's cost). Only the pairs whose boxes come within `tol` can
be within `tol`: the distances and intersection tests run on the first `OVERLAP_PAIRS` of them
(in a tight fold, a few segments on either side of the crease), and on every pair only where
more overlap.

**Contact energy.** With `scene.contact` (a `jaxrod.Contact`), node $p$ and segment $j$
interact when segment $j$ lies more than `exclusion` $\cdot L$ of arclength from node $p$
([`contact_pairs`][], fixed at trace time); the energy is
$E_c=\sum_{(p,j)}w_p\,\psi(t_{pj})\,\varphi(d_{pj})$ with $w_p$ the node's Voronoi length, the
cubic penalty $\varphi$ of `jaxrod.Contact`, $d_{pj}$ the distance of node $p$ from the line
of segment $j$ and $t_{pj}$ its projection parameter along the segment (0 and 1 at its
ends), weighted by the smooth window $\psi$ ([`window`][]: 1 at the segment's middle, 1/2
at its ends, 0 half a segment beyond them), whose values for consecutive segments of a
straight uniform chain sum to 1. In the window's tails, past a segment's ends, the line
distance is rounded off below $\epsilon=0.1\,\delta\,$[`tail`][]$(t)$ ([`smooth_abs`][]):
there the strip has turned away from the segment's line, a node of another part can cross
the line itself, and $\varphi(|s|)$ has a kink in the signed distance $s$ ($\varphi'(0)=-k$):
a jump of the force that stalls Newton's method (at Psi0 = 60 deg, G/L = 0.075, N = 48, a
node 0.42 segments before a segment near the other clamp, with window 0.004, stopped the
continuation). Over the segment itself the distance is exact, so a node pressed into the
layer feels the full force $k(1-d/\delta)^2$ however deep (its distance stays positive:
no step passes it through the segment, see below). So the energy is twice continuously
differentiable. The
distance to the closest point of a segment would switch from the line to an end point at
the segment's ends: a jump of its Hessian, which would make the constrained stiffness jump
past zero (a loss of stability that no eigenvalue passes through smoothly, to which a
critical-point refinement cannot converge). The first contact of two parts of a chain is a
node meeting a segment, and the windows cover every point of the chain; the solvers' steps
are bounded by [`step_bound`][] with the true distances, so no step carries a node through
a segment. In the angles, with $\mathbf x_k=\sum_{i<k}h_i\mathbf t_i$ and
$\mathbf n_i=\mathbf t_i^\perp$,

$$\frac{\partial E_c}{\partial\theta_i}=h_i\mathbf n_i\cdot\mathbf G_{i+1},\qquad
\frac{\partial^2E_c}{\partial\theta_i\partial\theta_j}=h_ih_j\,\mathbf n_i^\top\mathsf S_{i+1,j+1}\mathbf n_j
-\delta_{ij}\,h_i\mathbf t_i\cdot\mathbf G_{i+1},$$

$\mathbf G_k=\sum_{k'\ge k}\partial E_c/\partial\mathbf x_{k'}$ and
$\mathsf S_{kl}=\sum_{k'\ge k,l'\ge l}\partial^2E_c/\partial\mathbf x_{k'}\partial\mathbf x_{l'}$ (suffix
sums); the Cartesian Hessian is assembled from each pair's $6\times6$ Hessian
([`contact_hessian`][]: $O(N^2)$ work, a dense $N\times N$ result).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from .._misc import run_if
from .._compile import traced_once
from .geometry import discretize
from .kinematics import positions

TOL = 1e-9
"""Default tolerance of `self_intersects`, relative to the strip length."""


def _cross(u, v):
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def safe_norm(v):
    """|v| along the last axis with a finite gradient at v = 0 (double `where`); NaN stays NaN."""
    s2 = jnp.sum(v**2, -1)
    zero = s2 == 0
    return jnp.where(zero, 0.0, jnp.sqrt(jnp.where(zero, 1.0, s2)))


def point_segment_distance(p, a, b):
    r"""$|\mathbf p-\text{closest point of }[\mathbf a,\mathbf b]|$ (a point for $\mathbf a=\mathbf b$)."""
    u = b - a
    l2 = jnp.sum(u**2, -1)
    zero = l2 == 0
    t = jnp.where(zero, 0.0, jnp.sum((p - a) * u, -1) / jnp.where(zero, 1.0, l2))
    t = jnp.clip(t, 0.0, 1.0)
    return safe_norm(p - a - t[..., None] * u)


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
    dist = jnp.minimum(jnp.minimum(point_segment_distance(a, c, d), point_segment_distance(b, c, d)),
                       jnp.minimum(point_segment_distance(c, a, b), point_segment_distance(d, a, b)))
    return i, j, jnp.where(crosses, 0.0, dist), crosses


def _component_distances(ax, ay, bx, by, cx, cy, dx, dy):
    """Distance of segments [a, b] and [c, d] and whether they intersect, from the
    coordinates as separate arrays (broadcast against each other): `point_segment_distance`
    and `_intersect` written out per component, so that no axis of length 2 is reduced."""
    def psd(px, py, ax, ay, bx, by):
        ux, uy = bx - ax, by - ay
        l2 = ux * ux + uy * uy
        zero = l2 == 0
        t = jnp.where(zero, 0.0, ((px - ax) * ux + (py - ay) * uy) / jnp.where(zero, 1.0, l2))
        t = jnp.clip(t, 0.0, 1.0)
        ex, ey = px - ax - t * ux, py - ay - t * uy
        s2 = ex * ex + ey * ey
        zero = s2 == 0  # a finite gradient at zero distance, as `safe_norm`'s
        return jnp.where(zero, 0.0, jnp.sqrt(jnp.where(zero, 1.0, s2)))

    def cross(ux, uy, vx, vy):
        return ux * vy - uy * vx

    sab = jnp.sign(cross(bx - ax, by - ay, cx - ax, cy - ay)) * jnp.sign(cross(bx - ax, by - ay, dx - ax, dy - ay))
    scd = jnp.sign(cross(dx - cx, dy - cy, ax - cx, ay - cy)) * jnp.sign(cross(dx - cx, dy - cy, bx - cx, by - cy))
    boxes = ((jnp.minimum(ax, bx) <= jnp.maximum(cx, dx)) & (jnp.minimum(cx, dx) <= jnp.maximum(ax, bx))
             & (jnp.minimum(ay, by) <= jnp.maximum(cy, dy)) & (jnp.minimum(cy, dy) <= jnp.maximum(ay, by)))
    crosses = (sab <= 0) & (scd <= 0) & boxes
    dist = jnp.minimum(jnp.minimum(psd(ax, ay, cx, cy, dx, dy), psd(bx, by, cx, cy, dx, dy)),
                       jnp.minimum(psd(cx, cy, ax, ay, bx, by), psd(dx, dy, ax, ay, bx, by)))
    return jnp.where(crosses, 0.0, dist), crosses


def segment_distances(x, min_separation: int = 2):
    r"""`(clearance, crosses)` of node positions `x` (N+1, 2): the smallest distance
    between segments $i,j$ with $|i-j|\ge$ `min_separation` (an int, default 2: all
    non-neighbours), and whether any two of them intersect (touching included).

    With fewer than `min_separation + 1` segments there is no pair: `(inf, False)`.

    The pairs are evaluated as one $(n, n)$ array by broadcasting the segments' coordinates
    against each other, all but $j-i\ge$ `min_separation` masked out: no gather of pair
    indices, which XLA:CPU runs element by element; the same per-pair formulas as
    `pair_distances`."""
    n = x.shape[-2] - 1
    idx = np.arange(n)
    far = idx[None, :] - idx[:, None] >= min_separation
    if not far.any():
        return jnp.full(x.shape[:-2], jnp.inf, x.dtype), jnp.zeros(x.shape[:-2], bool)
    X, Y = x[..., 0], x[..., 1]
    row = lambda v: v[..., :, None]  # noqa: E731
    col = lambda v: v[..., None, :]  # noqa: E731
    d, crosses = _component_distances(row(X[..., :-1]), row(Y[..., :-1]), row(X[..., 1:]), row(Y[..., 1:]),
                                      col(X[..., :-1]), col(Y[..., :-1]), col(X[..., 1:]), col(Y[..., 1:]))
    d = jnp.where(far, d, jnp.inf)
    crosses = crosses & far
    c = jnp.min(d, axis=(-2, -1))
    # XLA:CPU's min of a batch can drop NaN: NaN is propagated explicitly
    c = jnp.where(jnp.any(jnp.isnan(d), axis=(-2, -1)), jnp.nan, c)
    return c, jnp.any(crosses, axis=(-2, -1))


def contact_pairs(scene):
    """Node and segment indices `(p, j)` (NumPy, fixed at trace time) of the pairs that
    interact under `scene.contact`: segment j lies at least `exclusion` * L of arclength
    away from node p on either side."""
    f = np.asarray(scene.mesh.fractions)
    ex = scene.contact.exclusion
    p = np.arange(f.size)[:, None]
    j = np.arange(f.size - 1)[None, :]
    keep = (f[j] - f[p] >= ex - 1e-12) | (f[p] - f[j + 1] >= ex - 1e-12)
    p, j = np.nonzero(keep)
    return p, j


def penalty(d, thickness, stiffness):
    r"""$\varphi(d)=\frac{k\delta}3(1-d/\delta)^3$ for $d<\delta$, else 0 (see `jaxrod.Contact`)."""
    u = jnp.maximum(1.0 - d / thickness, 0.0)
    return stiffness * thickness / 3.0 * u**3


def _smoothstep(x):
    """0 below 0, 1 above 1, the quintic 6x^5 - 15x^4 + 10x^3 between (C2)."""
    x = jnp.clip(x, 0.0, 1.0)
    return x**3 * (10.0 + x * (-15.0 + 6.0 * x))


def window(t):
    r"""$\psi(t)=S(t+\tfrac12)-S(t-\tfrac12)$: 1 at the middle of a segment,
    $\tfrac12$ at its ends, 0 beyond half a segment past them; consecutive segments' windows
    sum to 1 along a uniform straight chain."""
    return _smoothstep(t + 0.5) - _smoothstep(t - 0.5)


SMOOTHING = 0.1
r"""In a window's tails the line distance is rounded off below $\epsilon=$ `SMOOTHING` $\cdot\,\delta$
([`smooth_abs`][], [`tail`][])."""


def smooth_abs(s, eps):
    r"""$|s|$ for $|s|\ge\epsilon$, and the even quartic
    $\tfrac38\epsilon+\tfrac34 s^2/\epsilon-\tfrac18 s^4/\epsilon^3$ below, which meets it
    with equal value and first two derivatives at $|s|=\epsilon$ (also in $\epsilon$): twice
    continuously differentiable, and smooth at $s=0$, where $|s|$ has a kink. $|s|$ where
    $\epsilon=0$."""
    a = jnp.abs(s)
    pos = eps > 0
    e = jnp.where(pos, eps, 1.0)
    q = s / e
    return jnp.where(a >= eps, a, e * (0.375 + q**2 * (0.75 - 0.125 * q**2)))


def tail(t):
    r"""0 over the segment, $t\in[0,1]$, rising to 1 half a segment past its ends (C2):
    $S(-2t)+S(2t-2)$ with the quintic smoothstep $S$."""
    return _smoothstep(-2.0 * t) + _smoothstep(2.0 * t - 2.0)


def _pair_energy(z, thickness, stiffness):
    r"""$\psi(t)\,\varphi(\bar d_\perp)$ of node z[0:2] and the segment [z[2:4], z[4:6]]: $t$
    the node's projection parameter on the segment, $\bar d_\perp$ its distance to the
    segment's line, rounded off below $\epsilon=0.1\,\delta\,$`tail`$(t)$ ([`smooth_abs`][]):
    exact over the segment itself."""
    t, s = _line_coordinates(z)
    d = smooth_abs(s, SMOOTHING * thickness * tail(t))
    return window(t) * penalty(d, thickness, stiffness)


def _line_coordinates(z):
    """`(t, s)` of node z[..., 0:2] and the segment [z[..., 2:4], z[..., 4:6]]: the node's
    projection parameter along the segment (0 and 1 at its ends) and its signed distance to
    the segment's line."""
    p, a, b = z[..., 0:2], z[..., 2:4], z[..., 4:6]
    u = b - a
    l2 = jnp.sum(u**2, -1)
    return jnp.sum((p - a) * u, -1) / l2, _cross(u, p - a) / jnp.sqrt(l2)


def _voronoi(d):
    h = d.h
    return jnp.concatenate([h[:1] * 0.5, 0.5 * (h[1:] + h[:-1]), h[-1:] * 0.5])


def _pair_coordinates(x, p, j):
    return jnp.concatenate([x[p], x[j], x[j + 1]], -1)  # (P, 6)


def _may_interact(z, thickness):
    """Whether each pair's energy (`_pair_energy`) can be nonzero, (P,): the node within the
    segment's window ($-\tfrac12<t<\tfrac32$) and closer than the thickness to its line (the
    rounded distance is never below the exact one)."""
    t, s = _line_coordinates(z)
    return (t > -0.5) & (t < 1.5) & (jnp.abs(s) < thickness)


def _node_segment_distances(z):
    """Distance from node z[:, 0:2] to the closest point of segment [z[:, 2:4], z[:, 4:6]], (P,)."""
    return point_segment_distance(z[:, 0:2], z[:, 2:4], z[:, 4:6])


@traced_once
def contact_energy_nodes(x, scene, d=None):
    r"""$E_c$ of node positions `x` (N+1, 2) under `scene.contact` (0 without contact)."""
    if scene.contact is None:
        return jnp.zeros((), x.dtype)
    if d is None:
        d = discretize(scene)
    p, j = contact_pairs(scene)
    if p.size == 0:
        return jnp.zeros((), x.dtype)
    c = scene.contact
    e = jax.vmap(_pair_energy, (0, None, None))(_pair_coordinates(x, p, j), c.thickness, c.stiffness)
    return jnp.sum(_voronoi(d)[p] * e)


def inextensible_nodes(theta, d):
    r"""$\mathbf x_k=\sum_{i<k}h_i\mathbf t_i$, shape (N+1, 2), node 0 at the origin."""
    e = d.h[:, None] * jnp.stack([jnp.cos(theta), jnp.sin(theta)], -1)
    return jnp.concatenate([jnp.zeros((1, 2), e.dtype), jnp.cumsum(e, 0)])


@traced_once
def contact_energy(theta, scene, d=None):
    r"""$E_c$ of the angles `theta` (N,) (inextensible positions; 0 without contact)."""
    if d is None:
        d = discretize(scene)
    return contact_energy_nodes(inextensible_nodes(theta, d), scene, d)


CONTACT_RESOLUTION = 2.5
"""Longest segment, in contact thicknesses, on which a state in self-contact is resolved: the snap
angles of Psi0 = 180 deg, G/L = 0.1 with the default `Contact` (thickness 0.01 L) are 81.8, 74.9,
87.1, 86.4 and 87.1 deg at N = 24, 32, 48, 64 and 96 (h = 4.2, 3.1, 2.1, 1.6 and 1.0 thicknesses)."""


def coarse_for_contact(scene, d=None):
    """Whether the mesh's longest segment exceeds `CONTACT_RESOLUTION` contact thicknesses
    (False without contact)."""
    if scene.contact is None:
        return jnp.zeros((), bool)
    if d is None:
        d = discretize(scene)
    return jnp.max(d.h) > CONTACT_RESOLUTION * scene.contact.thickness


def underresolved_contact(theta, scene, d=None):
    """Whether the state `theta` is in self-contact (contact energy above zero) on a mesh too
    coarse for the contact thickness (`coarse_for_contact`; the code `contact_underresolved`).
    False without contact."""
    if scene.contact is None:
        return jnp.zeros((), bool)
    if d is None:
        d = discretize(scene)
    return coarse_for_contact(scene, d) & (contact_energy(theta, scene, d) > 0)


def step_bound(theta, step, scene, d=None, margin=0.9):
    r"""The largest $\tau\in(0,1]$ such that no contact pair (`contact_pairs`) can meet
    along the path $\theta+\tau'\,$`step`, $0\le\tau'\le\tau$ (a conservative continuous
    collision check).

    Turning segment $i$ by $\Delta\theta_i$ moves its end relative to its start by at most
    the arc $h_i|\Delta\theta_i|$, so two points of the strip move relative to each other
    by at most $\sum_i h_i|\Delta\theta_i|$ over the segments between them. With prefix
    sums $P_k=\sum_{i<k}h_i|\mathrm{step}_i|$, node $p$ and segment $j$ close by at most
    $\tau B_{pj}$, $B_{pj}=\max(|P_p-P_j|,|P_p-P_{j+1}|)$, and
    $\tau=\min(1,\min_{pj}\texttt{margin}\,d_{pj}/B_{pj})$ over the pairs not already
    touching ($d_{pj}>0$)."""
    if d is None:
        d = discretize(scene)
    p, j = contact_pairs(scene)
    if p.size == 0:
        return jnp.ones((), theta.dtype)
    x = inextensible_nodes(theta, d)
    dist = _node_segment_distances(_pair_coordinates(x, p, j))
    P = jnp.concatenate([jnp.zeros(1, theta.dtype), jnp.cumsum(d.h * jnp.abs(step))])
    B = jnp.maximum(jnp.abs(P[p] - P[j]), jnp.abs(P[p] - P[j + 1]))
    ok = (dist > 0) & (B > 0)
    tau = jnp.min(jnp.where(ok, margin * dist / jnp.where(ok, B, 1.0), jnp.inf))
    return jnp.clip(jnp.where(jnp.isfinite(tau), tau, 1.0), 0.0, 1.0)


def _live_pairs(theta, scene, d):
    """`(Hx, gx)`: the Hessian and gradient of $E_c$ in the node coordinates, shapes
    (2(N+1), 2(N+1)) and (2(N+1),), assembled from the pairs whose energy can be nonzero
    (`contact_hessian`'s docstring says how)."""
    N = theta.shape[0]
    x = inextensible_nodes(theta, d)
    p, j = contact_pairs(scene)
    c = scene.contact
    w = _voronoi(d)[p]
    z = _pair_coordinates(x, p, j)

    def grad_twice(*a):
        g = jax.grad(_pair_energy)(*a)
        return g, g

    # forward over reverse: each pair's Hessian with its gradient as the by-product
    hess_grad = jax.vmap(jax.jacfwd(grad_twice, has_aux=True), (0, None, None))
    nodes = np.stack([p, j, j + 1], -1)  # (P, 3)
    idx = jnp.asarray((2 * nodes[:, :, None] + np.arange(2)).reshape(-1, 6))  # node-coordinate indices

    def assemble(acc, sel, used):
        # adds the pairs `sel` (where `used`): their Hessians and gradients in the node coordinates
        Hx, gx = acc
        zs, ii = z[sel], idx[sel]
        ws = jnp.where(used, w[sel], 0.0)
        Hp, gp = hess_grad(zs, c.thickness, c.stiffness)
        return Hx.at[ii[:, :, None], ii[:, None, :]].add(Hp * ws[:, None, None]), gx.at[ii].add(gp * ws[:, None])

    n2 = 2 * (N + 1)
    zero = (jnp.zeros((n2, n2), x.dtype), jnp.zeros(n2, x.dtype))
    K = min(max(64, 2 * N), p.size)
    if K == p.size:
        return assemble(zero, jnp.arange(p.size), np.ones(p.size, bool))
    # the pairs whose energy can be nonzero (the others have zero energy, gradient and
    # Hessian), compacted in order: O(P), where a top-K selection by distance would sort all P
    # pairs (a large part of the contact Hessian's time; benchmarks/bench_contact.py times it)
    live = _may_interact(z, c.thickness)
    count = jnp.sum(live)
    chunks = -(-p.size // K)
    order = jnp.nonzero(live, size=chunks * K, fill_value=0)[0]

    def chunk(k, acc):
        slots = k * K + jnp.arange(K)
        sel = jax.lax.dynamic_slice(order, (k * K,), (K,))
        return jax.lax.cond(k * K < count, lambda a: assemble(a, sel, slots < count), lambda a: a, acc)

    return jax.lax.fori_loop(0, chunks, chunk, zero)


@traced_once
def contact_hessian(theta, scene, d=None):
    r"""$\partial^2E_c/\partial\theta^2$, dense (N, N), by the suffix sums of the module
    docstring from the pairs' Cartesian Hessians.

    Only pairs whose energy can be nonzero contribute (`_may_interact`: the node within the
    segment's window and closer than the thickness to its line): they are gathered in order
    into chunks of $K=\max(64,2N)$ fixed slots, and a loop of $\lceil P/K\rceil$ passes over
    the $P$ pairs assembles the chunks that hold any (one pass in the usual state with at
    most $K$ of them, each further pass skipped by a `lax.cond`). So each call site of the
    Hessian compiles one copy of the pair assembly however many chunks there are (a second,
    all-pairs assembly for crowded states would double the contact programs' kernels).
    The contact gradient in the node coordinates (the diagonal term) is assembled from the
    same pairs."""
    if d is None:
        d = discretize(scene)
    N = theta.shape[0]
    Hx, gx = _live_pairs(theta, scene, d)
    Hx = Hx.reshape(N + 1, 2, N + 1, 2)
    gx = gx.reshape(N + 1, 2)
    S = jnp.flip(jnp.cumsum(jnp.flip(Hx, (0, 2)), 0), (0, 2))
    S = jnp.flip(jnp.cumsum(jnp.flip(S, 2), 2), 2)[1:, :, 1:, :]  # (N, 2, N, 2)
    G = jnp.flip(jnp.cumsum(jnp.flip(gx, 0), 0), 0)[1:]  # (N, 2)
    hn = d.h[:, None] * jnp.stack([-jnp.sin(theta), jnp.cos(theta)], -1)
    ht = d.h[:, None] * jnp.stack([jnp.cos(theta), jnp.sin(theta)], -1)
    H = jnp.einsum("ia,iajb,jb->ij", hn, S, hn)
    return H - jnp.diag(jnp.sum(ht * G, -1))


def _nodes(theta, scene, force):
    d = discretize(scene)
    if force is None:
        return inextensible_nodes(theta, d)
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


def _box_overlaps(x, tol, min_separation):
    r"""(n, n) mask of the segment pairs $j-i\ge$ `min_separation` of the nodes `x` whose
    axis-aligned bounding boxes come within `tol` of each other: one comparison of every pair
    by broadcasting (no gather of pair indices, which XLA:CPU runs element by element).
    NaN positions overlap everything."""
    n = x.shape[-2] - 1
    lo = jnp.minimum(x[:-1], x[1:]) - 0.5 * tol
    hi = jnp.maximum(x[:-1], x[1:]) + 0.5 * tol
    apart = jnp.any((lo[:, None, :] > hi[None, :, :]) | (lo[None, :, :] > hi[:, None, :]), axis=-1)
    idx = np.arange(n)
    return ~apart & (idx[None, :] - idx[:, None] >= min_separation)


def _boxes_apart(x, tol, min_separation):
    r"""The $O(N^2)$ comparison screen of the module docstring: True where no two segments
    $|i-j|\ge$ `min_separation` of the nodes `x` have bounding boxes within `tol` of each
    other (then no two are within `tol`). NaN positions fail it."""
    return ~jnp.any(_box_overlaps(x, tol, min_separation))


OVERLAP_PAIRS = 64
"""Segment pairs with overlapping bounding boxes that `self_intersects` measures one by one
(a state with more is measured pair by pair in full)."""


def _overlapping_pairs_touch(x, tol, min_separation):
    """`(near, many)`: whether one of the first `OVERLAP_PAIRS` segment pairs of the nodes
    `x` whose bounding boxes (grown by `tol`) overlap is within `tol` or crosses, and whether
    more pairs than that overlap. Pairs whose boxes are apart are farther than `tol`."""
    n = x.shape[-2] - 1
    overlap = _box_overlaps(x, tol, min_separation).reshape(-1)
    count = jnp.sum(overlap)
    k = min(OVERLAP_PAIRS, n * n)
    # the overlapping pairs are the largest entries of the mask: `top_k` picks all of them
    # where there are at most k (faster on XLA:CPU than `jnp.nonzero` with a size)
    _, flat = lax.top_k(overlap.astype(jnp.float32), k)
    i, j = flat // n, flat % n
    d, crosses = _component_distances(x[i, 0], x[i, 1], x[i + 1, 0], x[i + 1, 1],
                                      x[j, 0], x[j, 1], x[j + 1, 0], x[j + 1, 1])
    return jnp.any(overlap[flat] & (crosses | (d <= tol))), count > k


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
    no = jnp.zeros((), bool)

    def distances(x, tol):
        c, crosses = segment_distances(x, min_separation)
        return crosses | (c <= tol)

    # the second screen only where the first fails (most states pass the first): the pairs
    # whose bounding boxes come within `tol`, of which the first `OVERLAP_PAIRS` are measured
    # (only they can be within `tol`); every pair only where more overlap. Loops of at most
    # one pass one after the other, not one inside the other (nested, under `vmap`, they run
    # much slower than either alone)
    tol = jnp.asarray(tol, x.dtype)
    near, many = run_if(~monotone, functools.partial(_overlapping_pairs_touch, min_separation=min_separation),
                        (no, no), (x, tol))
    return near | run_if(many, distances, no, (x, tol))
