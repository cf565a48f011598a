r"""Geometry, material, clamps and discretization of a creased planar strip.

Conventions (see docs/model.md): arclength $s\in[0,L]$, tangent angle $\theta(s)$,
$\mathbf r'(s) = (\cos\theta, \sin\theta)$. The crease is the natural tangent angle

$$\theta_0(s) = \frac{\Psi_0-\pi}{2}\tanh\frac{s-L/2}{s_0},$$

so the fold points up (+y) in the rest shape. Left clamp: $\mathbf r(0)=(0,0)$,
$\theta(0)=+\alpha_L$; right clamp: $\mathbf r(L)=(G,0)$, $\theta(L)=-\alpha_R$.

All float fields are pytree leaves: `jax.grad` and `jax.vmap` work over them.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._misc import check_param


def _leaf(x):
    """A Python scalar as a 0-d JAX array (weakly typed, so dtype promotion is unchanged).

    `eqx.filter_jit` treats Python scalars as static: kept as floats, every new parameter
    value would recompile `solve_equilibrium`, `initial_state`, ... Arrays, NumPy scalars
    and tracers are left as they are."""
    if isinstance(x, (int, float)) and not isinstance(x, (bool, np.generic)):
        return jnp.asarray(float(x))
    return x


def _crease_profile(s, centre, psi, width):
    r"""One crease's natural tangent angle $\frac{\Psi-\pi}{2}\tanh\frac{s-c}{s_0}$."""
    return 0.5 * (psi - jnp.pi) * jnp.tanh((s - centre) / width)


class Creases(eqx.Module):
    r"""A set of $m$ creases: crease $k$ at arclength $c_k$ (a length, in $(0, L)$) with
    fold angle $\Psi_k$ (radians, interior angle, in $(0,\pi]$) and fold width $s_{0,k}$.
    Each adds the single-crease profile of docs/model.md centred at its own $c_k$ to the
    strip's natural tangent angle,

    $$\theta_0(s) \mathrel{+}= \sum_k \frac{\Psi_k-\pi}{2}\tanh\frac{s-c_k}{s_{0,k}},$$

    so every crease points up (+y) in the rest shape, and the total turning of crease $k$
    is $\Psi_k - \pi$. `positions`, `angles` and `widths` are arrays of shape (m,), pytree
    leaves: derivatives with respect to every $c_k$, $\Psi_k$, $s_{0,k}$ are available
    (at a fixed mesh).

    Rule for overlapping creases: two creases overlap when $|c_k-c_l| < 2(s_{0,k}+s_{0,l})$;
    a cluster of overlapping creases acts as one crease of fold angle
    $\pi-\sum_k(\pi-\Psi_k)$, which must stay positive (`ValueError` otherwise). Two
    creases at the same place are one crease of the summed angle.
    """

    positions: jnp.ndarray
    angles: jnp.ndarray
    widths: jnp.ndarray

    def __init__(self, positions, angles, widths=None, *, length=1.0):
        if widths is None:
            widths = 0.02 * length
        xp = lambda v: np if is_concrete_pair(v) else jnp  # noqa: E731  (NumPy until traced)
        vecs = []
        for name, v in (("crease positions", positions), ("crease angles", angles), ("crease widths", widths)):
            v = xp(v).atleast_1d(v)
            if v.ndim != 1 or v.shape[0] < 1:
                raise ValueError(f"{name} must be a non-empty 1-d sequence, got shape {tuple(v.shape)}")
            vecs.append(v)
        pos, ang, wid = vecs
        m = pos.shape[0]
        # one angle or width for every crease
        ang, wid = (xp(v).broadcast_to(v, (m,)) if v.shape[0] == 1 else v for v in (ang, wid))
        if ang.shape[0] != m or wid.shape[0] != m:
            raise ValueError(f"crease angles and widths must have one entry per crease position ({m}), "
                             f"got {ang.shape[0]} and {wid.shape[0]}")
        if is_concrete_pair(pos, ang, wid, length):
            L = float(length)
            pos, ang, wid = (np.asarray(v, float) for v in (pos, ang, wid))
            for k in range(m):
                check_param(f"crease {k} position", float(pos[k]), lo=0.0, hi=L)
                check_param(f"crease {k} angle", math.degrees(float(ang[k])), lo=0.0, hi=180.0, hi_open=False,
                            unit=" deg")
                check_param(f"crease {k} width", float(wid[k]), lo=0.0)
            _check_overlaps(pos, ang, wid)
        self.positions = jnp.asarray(pos)
        self.angles = jnp.asarray(ang)
        self.widths = jnp.asarray(wid)

    @classmethod
    def from_degrees(cls, positions, angles_deg, widths=None, *, length=1.0):
        """Creases with fold angles in degrees (positions and widths as lengths)."""
        return cls(positions, np.radians(np.asarray(angles_deg, float)), widths, length=length)

    @property
    def count(self) -> int:
        return int(self.positions.shape[0])

    def natural_angle(self, s):
        r"""$\sum_k \frac{\Psi_k-\pi}{2}\tanh\frac{s-c_k}{s_{0,k}}$ at arclengths `s`."""
        s = jnp.asarray(s)
        prof = _crease_profile(s[..., None], self.positions, self.angles, self.widths)
        return jnp.sum(prof, axis=-1)

    def mirrored(self, length=1.0) -> "Creases":
        """The set's mirror image about $s = L/2$, crease by crease: crease k takes the
        position $L - c_j$, angle and width of its partner j, the crease of the opposite rank
        along the strip (the k-th from the left pairs with the k-th from the right). A
        mirror-symmetric set is its own image; traced leaves are allowed (the partners come
        from `argsort`, the values are differentiable)."""
        pos = jnp.asarray(self.positions)
        order = jnp.argsort(pos)
        partner = order[::-1][jnp.argsort(order)]
        return eqx.tree_at(lambda c: (c.positions, c.angles, c.widths), self,
                           (length - pos[partner], jnp.asarray(self.angles)[partner],
                            jnp.asarray(self.widths)[partner]))

    def is_mirror_symmetric(self, length=1.0, tol=1e-12) -> bool:
        """Whether the set equals its mirror image about $s = L/2$ (each crease has a partner
        at $L - c_k$ with the same angle and width)."""
        pos, ang, wid = (np.asarray(v, float) for v in (self.positions, self.angles, self.widths))
        for k in range(pos.shape[0]):
            match = ((np.abs(pos - (float(length) - pos[k])) < tol) & (np.abs(ang - ang[k]) < tol)
                     & (np.abs(wid - wid[k]) < tol))
            if not match.any():
                return False
        return True


def _check_overlaps(pos, ang, wid):
    order = np.argsort(pos)
    p, a, w = pos[order], ang[order], wid[order]
    start = 0
    for k in range(1, len(p) + 1):
        if k == len(p) or p[k] - p[k - 1] >= 2.0 * (w[k] + w[k - 1]):
            deficit = float(np.sum(np.pi - a[start:k]))
            if deficit >= np.pi:
                names = ", ".join(f"{q:g}" for q in p[start:k])
                raise ValueError(f"creases at {names} overlap (closer than 2 (s0_k + s0_l)) and fold by "
                                 f"{math.degrees(deficit):g} deg together; overlapping creases must fold by "
                                 f"less than 180 deg in all")
            start = k


def _crease_arrays(strip):
    """`strip`'s creases in `Strip.crease_list` order as NumPy `(positions, angles, widths)`,
    or None where a leaf is traced."""
    cr = strip.creases
    leaves = [strip.length] + ([strip.psi0, strip.s0] if strip.centred else []) + (
        [] if cr is None else [cr.positions, cr.angles, cr.widths])
    if not is_concrete_pair(*leaves):
        return None
    parts = ([(0.5 * float(strip.length), float(strip.psi0), float(strip.s0))] if strip.centred else [])
    arrays = [np.array([p[i] for p in parts], float) for i in range(3)]
    if cr is not None:
        arrays = [np.append(a, np.asarray(b, float)) for a, b in zip(arrays, (cr.positions, cr.angles, cr.widths))]
    return tuple(arrays)


S0_MAX = 0.25
r"""Largest fold width $s_0$ (units of $L$). The centred crease turns by
$(\pi-\Psi_0)\tanh\frac{L}{2s_0}$ within the strip: at $s_0=0.25L$ by 96.4 % of its fold,
at $0.1L$ by 99.99 %; a wider profile would make the strip's fold smaller than $\Psi_0$ says."""


def _one_number(name, value):
    """`ValueError` naming `name` where a concrete `value` is not a single number (a list
    or an array of several values: one scene is built from numbers; batches by `jax.vmap`)."""
    if value is None or not is_concrete_pair(value, 0.0):
        return
    if np.ndim(value) != 0:
        raise ValueError(f"{name} must be one number (a scene is built from numbers; for a batch of scenes "
                         f"use jax.vmap(jr.make_scene) over arrays), got {value!r}")


class Strip(eqx.Module):
    r"""A strip of length $L$, bending stiffness $B$, mass per length $\lambda$, with
    one crease of fold angle $\Psi_0$ (radians, interior angle; $\pi$ = flat) and fold
    width $s_0$ (a length), centred at $s=L/2$, and optionally a set of further creases
    anywhere (`creases`, a [`jaxrod.Creases`][]) whose profiles add to the centred one's:

    $$\theta_0(s) = \frac{\Psi_0-\pi}{2}\tanh\frac{s-L/2}{s_0}
      + \sum_k \frac{\Psi_k-\pi}{2}\tanh\frac{s-c_k}{s_{0,k}}.$$

    A strip of creases elsewhere leaves `psi0` at $\pi$ (no centred crease; that term is
    then exactly zero). Defaults are the nondimensional units of docs/model.md:
    $L=B=\lambda=1$, $s_0=0.02L$.
    """

    psi0: float = math.pi
    s0: float | None = None
    length: float = 1.0
    bending_stiffness: float = 1.0
    line_density: float = 1.0
    creases: Creases | None = None
    centred: bool = eqx.field(static=True, default=True)

    def __init__(self, psi0=math.pi, s0=None, length=1.0, bending_stiffness=1.0, line_density=1.0,
                 creases=None):
        check_param("length", length, lo=0.0)
        check_param("psi0", psi0, lo=0.0, hi=180.0, hi_open=False, unit=" deg", scale=180.0 / math.pi)
        check_param("bending_stiffness", bending_stiffness, lo=0.0)
        check_param("line_density", line_density, lo=0.0)
        if s0 is None:
            s0 = 0.02 * length
        check_param("s0", s0, lo=0.0)
        if is_concrete_pair(s0, length) and np.all(np.asarray(s0, float) > S0_MAX * np.asarray(length, float)):
            raise ValueError(f"s0 must lie in (0, {S0_MAX:g} L]: wider, the crease's profile is cut off by the "
                             f"strip's ends and it turns by less than its fold angle says, got s0={s0!r}")
        if creases is not None and not isinstance(creases, Creases):
            raise ValueError(f"creases must be a jaxrod.Creases or None, got {type(creases).__name__}")
        if creases is not None and is_concrete_pair(creases.positions, length):
            L = float(length)
            if np.any(np.asarray(creases.positions) >= L):
                raise ValueError(f"crease positions must lie in (0, L) = (0, {L:g}), got "
                                 f"{np.asarray(creases.positions).tolist()}")
        self.psi0 = _leaf(psi0)
        self.s0 = _leaf(s0)
        self.length = _leaf(length)
        self.bending_stiffness = _leaf(bending_stiffness)
        self.line_density = _leaf(line_density)
        self.creases = creases
        self.centred = creases is None or not (is_concrete_pair(psi0) and float(psi0) == math.pi)
        arrays = None if creases is None else _crease_arrays(self)
        if arrays is not None:  # the centred crease with the others
            _check_overlaps(*arrays)

    @classmethod
    def from_physical(cls, *, youngs_modulus, density, thickness, width, length, psi0=math.pi, s0=None,
                      creases=None):
        r"""A strip from SI material data: $B = E t^3 w/12$, $\lambda = \rho t w$.

        **Arguments:** `youngs_modulus` $E$ (Pa), `density` $\rho$ (kg/m^3), `thickness`
        $t$ (m), `width` $w$ (m), `length` $L$ (m), `psi0` (rad), `s0` (m; default 0.02 L),
        `creases` (a `Creases` with positions and widths in m).
        """
        for name, v in [("youngs_modulus", youngs_modulus), ("density", density),
                        ("thickness", thickness), ("width", width)]:
            check_param(name, v, lo=0.0)
        B = youngs_modulus * thickness**3 * width / 12.0
        lam = density * thickness * width
        return cls(psi0=psi0, s0=s0, length=length, bending_stiffness=B, line_density=lam, creases=creases)

    @property
    def speed_gauge(self):
        r"""$v^* = \sqrt{B/(\lambda L^2)}$."""
        return jnp.sqrt(self.bending_stiffness / (self.line_density * self.length**2))

    @property
    def time_unit(self):
        r"""$T = L / v^*$."""
        return self.length / self.speed_gauge

    def natural_angle(self, s):
        r"""$\theta_0(s)$: the centred crease's $\frac{\Psi_0-\pi}{2}\tanh\frac{s-L/2}{s_0}$,
        plus the profiles of `creases` when there are any."""
        th = _crease_profile(s, 0.5 * self.length, self.psi0, self.s0)
        if self.creases is not None:
            th = th + self.creases.natural_angle(s)
        return th

    def crease_list(self):
        """Every crease as `(position, angle, width)` arrays of shape (m,): the centred one
        first (`centred`: unless the strip was built with `psi0` = pi and further `creases`),
        then `creases`. The flat strip lists its centred "crease" of angle pi, whose height
        is the midpoint's. The count is fixed by the strip's structure, so it is the same
        under `jit` as outside."""
        parts = []
        if self.centred:
            parts.append((jnp.atleast_1d(0.5 * self.length), jnp.atleast_1d(self.psi0), jnp.atleast_1d(self.s0)))
        if self.creases is not None:
            c = self.creases
            parts.append((c.positions, c.angles, c.widths))
        dtype = jnp.result_type(*(x for p in parts for x in p))
        return tuple(jnp.concatenate([jnp.asarray(p[i], dtype) for p in parts]) for i in range(3))

    def mirrored(self) -> "Strip":
        """The strip's mirror image about $s = L/2$ (the centred crease is its own image;
        `Creases.mirrored` for the others)."""
        if self.creases is None:
            return self
        return eqx.tree_at(lambda s: s.creases, self, self.creases.mirrored(self.length))

    def unfolded(self, u):
        r"""The strip with every fold deficit $\pi-\Psi$ scaled by `u` (0: flat, 1: itself);
        the homotopy that builds initial states walks `u` from 0 to 1."""
        st = eqx.tree_at(lambda s: s.psi0, self, jnp.pi + u * (self.psi0 - jnp.pi))
        if self.creases is not None:
            st = eqx.tree_at(lambda s: s.creases.angles, st, jnp.pi + u * (self.creases.angles - jnp.pi))
        return st


class Clamps(eqx.Module):
    r"""Clamp placement: gap $G$ (right clamp at $(G,0)$) and clamp angles,
    $\theta(0)=+\alpha_L$, $\theta(L)=-\alpha_R$ (radians). Positive angles tilt both
    ends upward toward the inside."""

    gap: float
    alpha_left: float = 0.0
    alpha_right: float = 0.0

    def __init__(self, gap, alpha_left=0.0, alpha_right=0.0):
        check_param("gap", gap, lo=0.0)
        check_param("alpha_left", alpha_left)
        check_param("alpha_right", alpha_right)
        self.gap = _leaf(gap)
        self.alpha_left = _leaf(alpha_left)
        self.alpha_right = _leaf(alpha_right)

    @classmethod
    def symmetric(cls, gap, alpha=0.0):
        """Both clamps rotated by the same angle `alpha` (the paper's Figs. 1-3)."""
        return cls(gap, alpha, alpha)


def _graded_fractions(n: int, ratio: float, width: float, centres=(0.5,)) -> np.ndarray:
    """Node fractions in [0, 1] with density 1 + (ratio-1) sech^2((x-1/2)/width), or with
    several `centres` (fractions of L) 1 + (ratio-1) max_k sech^2((x-c_k)/width), each half
    [0, 1/2], [1/2, 1] graded on its own with n/2 segments (a node stays at L/2)."""
    xi = np.linspace(0.0, 1.0, n + 1)
    if ratio == 1.0:
        return xi
    if tuple(centres) != (0.5,):
        return _graded_halves(n, ratio, width, np.asarray(centres, float))
    a = ratio - 1.0

    def cdf(x):
        return x + a * width * (np.tanh((x - 0.5) / width) + np.tanh(0.5 / width))

    total = cdf(1.0)
    lo, hi = np.zeros_like(xi), np.ones_like(xi)
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        below = cdf(mid) < xi * total
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    x = 0.5 * (lo + hi)
    x[0], x[-1], x[n // 2] = 0.0, 1.0, 0.5
    return x


def _graded_halves(n, ratio, width, centres):
    """`_graded_fractions` for several centres: the density integrated by the trapezoid rule
    on a fine grid, each half inverted on its own (n/2 segments each)."""
    a = ratio - 1.0
    out = []
    for lo, hi in ((0.0, 0.5), (0.5, 1.0)):
        x = np.linspace(lo, hi, 20001)
        dens = 1.0 + a * np.max(1.0 / np.cosh((x[:, None] - centres[None, :]) / width) ** 2, axis=1)
        cdf = np.concatenate([[0.0], np.cumsum(0.5 * (dens[1:] + dens[:-1]) * np.diff(x))])
        target = np.linspace(0.0, cdf[-1], n // 2 + 1)
        out.append(np.interp(target, cdf, x))
    x = np.concatenate([out[0], out[1][1:]])
    x[0], x[-1], x[n // 2] = 0.0, 1.0, 0.5
    return x


class Mesh(eqx.Module):
    r"""Discretization: `n` segments (even, so a node sits at the crease $s=L/2$).

    With `refine > 1` the segments near the crease are `refine` times shorter than far
    from it (density $1+(r-1)\,\mathrm{sech}^2((s/L-1/2)/w)$, $w$ = `width`), so a sharp
    crease does not force a fine mesh everywhere. The mesh is fixed in units of $L$ and
    does not move with $s_0$, so derivatives with respect to $s_0$ are at fixed mesh.

    `centres` (fractions of L, default `(0.5,)`): where to refine, one entry per crease for a
    strip with several (`Mesh.for_strip` takes them from the strip); the density is then
    $1+(r-1)\max_k\mathrm{sech}^2((s/L-c_k)/w)$ and each half of the strip is graded on its
    own, so a node stays at $L/2$ and a mirror-symmetric set of centres gives a
    mirror-symmetric mesh. The mesh, and so derivatives with respect to crease positions,
    stays fixed when the creases move.
    """

    n: int = eqx.field(static=True)
    refine: float = eqx.field(static=True)
    width: float = eqx.field(static=True)
    centres: tuple = eqx.field(static=True, default=(0.5,))
    fractions: tuple = eqx.field(static=True, repr=False)

    def __init__(self, n: int = 100, refine: float = 1.0, width: float = 0.1, centres=(0.5,)):
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)):
            raise ValueError(f"n (number of segments) must be an integer, got {n!r}")
        if n < 8 or n % 2:
            raise ValueError(f"n (number of segments) must be an even integer >= 8, got {n}")
        if not (math.isfinite(refine) and refine >= 1.0):
            raise ValueError(f"refine must be a finite ratio >= 1, got {refine!r}")
        if not (math.isfinite(width) and 0.0 < width <= 1.0):
            raise ValueError(f"width must lie in (0, 1], got {width!r}")
        try:
            centres = tuple(sorted(float(c) for c in np.atleast_1d(np.asarray(centres, float))))
        except (TypeError, ValueError):
            raise ValueError(f"centres must be fractions of L in (0, 1), got {centres!r}") from None
        if not centres or not all(math.isfinite(c) and 0.0 < c < 1.0 for c in centres):
            raise ValueError(f"centres must be fractions of L in (0, 1), got {centres!r}")
        self.n = int(n)
        self.refine = float(refine)
        self.width = float(width)
        self.centres = centres if self.refine != 1.0 else (0.5,)  # a uniform mesh has no centres
        self.fractions = tuple(float(x) for x in _graded_fractions(self.n, self.refine, self.width, centres))

    @classmethod
    def for_strip(cls, strip, n: int = 100, refine: float = 1.0, width: float = 0.1):
        """A mesh refined around every crease of `strip` (concrete positions; a uniform mesh,
        `refine` = 1, needs none)."""
        if refine == 1.0:
            return cls(n, refine, width)
        arrays = _crease_arrays(strip)
        if arrays is None:
            raise ValueError("Mesh.for_strip: the creases must be concrete (not traced) to refine around them")
        return cls(n, refine, width, tuple(arrays[0] / float(strip.length)))

    def spacing_at(self, x):
        """The segment length (fraction of L) of the segment holding fraction `x`."""
        f = np.asarray(self.fractions)
        i = int(np.clip(np.searchsorted(f, x) - 1, 0, self.n - 1))
        return float(f[i + 1] - f[i])

    def __hash__(self):
        return hash((self.n, self.refine, self.width, self.centres))

    def __eq__(self, other):
        return (isinstance(other, Mesh) and (self.n, self.refine, self.width, self.centres)
                == (other.n, other.refine, other.width, other.centres))


class Stretching(eqx.Module):
    r"""Extensible segments: energy $\sum_i \tfrac{K}{2} h_i \varepsilon_i^2$ with axial
    stiffness $K = EA$. Without this term the strip is exactly inextensible (the
    $K\to\infty$ limit); results differ from it by $O(B/(K L^2))$. A PET strip has
    $K L^2/B = 12 L^2/t^2 \sim 10^7$."""

    stiffness: float = 1.0e6

    def __init__(self, stiffness=1.0e6):
        check_param("stiffness", stiffness, lo=0.0)
        self.stiffness = _leaf(stiffness)


class Gravity(eqx.Module):
    r"""Uniform gravity $-g\,\hat y$ acting on the lumped node masses $\lambda\,\ell_i$;
    energy $g\sum_i m_i y_i$. `g` in units of $B/(\lambda L^3)$ when nondimensional."""

    g: float = 9.81

    def __init__(self, g=9.81):
        check_param("g", g)
        self.g = _leaf(g)


CONTACT_THICKNESS = 0.01
"""`Contact`'s default thickness (units of L)."""
CONTACT_STIFFNESS = 1.0e5
"""`Contact`'s default penalty stiffness (units of B / L^3)."""


class Contact(eqx.Module):
    r"""Self-contact of the strip: a smooth penalty between parts of the strip that are not
    neighbours, active where they come within the contact thickness $\delta$ of each other.

    Node $p$ (Voronoi length $w_p$) and segment $j$ interact when segment $j$ lies entirely
    more than `exclusion` $\cdot L$ of arclength away from node $p$; with $d_{pj}$ the node's
    distance from the segment's line and $\psi(t_{pj})$ a smooth window in its projection
    parameter along the segment (1 over its middle, 0 half a segment past its ends, summing to
    1 over consecutive segments; `jaxrod.energy.contact.window`), the energy is

    $$E_c=\sum_p w_p\sum_j \psi(t_{pj})\,\varphi(d_{pj}),\qquad
    \varphi(d)=\frac{k\delta}{3}\Big(1-\frac d\delta\Big)^3\ (d<\delta),\quad 0\ (d\ge\delta),$$

    so $\varphi,\varphi',\varphi''$ all vanish at $d=\delta$: a contact that opens or
    closes is a smooth event for Newton and continuation, not a kink. The force per unit
    length pressing a node against a segment is $k(1-d/\delta)^2$: the load $f$ per unit
    length sinks it to $d=\delta(1-\sqrt{f/k})$, so $k$ (units $B/L^3$) must exceed the
    line loads the scene produces (bending loads of these strips are $10$-$10^3\,B/L^3$).

    - `thickness` $\delta$ (units of L; default 0.01 L): the distance at which the
      centrelines touch, i.e. the strip's thickness $t$ when physical units are used
      (`Contact.for_strip(strip, thickness=t)` for a strip in SI units)
      (PET strips of the paper: $t/L\approx 4\cdot10^{-4}$-$1.3\cdot10^{-3}$). A
      thickness below the mesh size $h$ is allowed (no step passes a node through a segment)
      but the penalty's stiffness $2k/\delta$ then sets the dynamics' step.
    - `stiffness` $k$ (default $10^5\,B/L^3$): a node pressed with $f=10^3\,B/L^3$ sinks to
      $0.9\,\delta$.
    - `exclusion` (static, fraction of L; default 0.1): parts of the strip closer than this
      in arclength never interact (the crease of a tight fold brings its own facets within
      $\delta$ of each other by design).

    Contact is modelled only in scenes that carry it (`Scene(..., contact=Contact())`); the
    Hessian is then dense (see `jaxrod.linalg.kkt`). The contact geometry uses the
    inextensible node positions."""

    thickness: float = 0.01
    stiffness: float = 1.0e5
    exclusion: float = eqx.field(static=True, default=0.1)

    def __init__(self, thickness=CONTACT_THICKNESS, stiffness=CONTACT_STIFFNESS, exclusion=0.1):
        check_param("thickness", thickness, lo=0.0)
        check_param("stiffness", stiffness, lo=0.0)
        check_param("exclusion", exclusion, lo=0.0, hi=1.0)
        self.thickness = _leaf(thickness)
        self.stiffness = _leaf(stiffness)
        self.exclusion = float(exclusion)

    @classmethod
    def for_strip(cls, strip, thickness=None, stiffness=None, exclusion=0.1):
        r"""Contact in the units of `strip` (for example SI, from `Strip.from_physical`): the
        `thickness` is the strip's physical thickness $t$ (default 0.01 L), the stiffness
        $10^5\,B/L^3$ with the strip's own B and L unless given."""
        L, B = strip.length, strip.bending_stiffness
        t = CONTACT_THICKNESS * L if thickness is None else thickness
        k = CONTACT_STIFFNESS * B / L**3 if stiffness is None else stiffness
        return cls(t, k, exclusion)


class Scene(eqx.Module):
    r"""What to model: a strip, its clamps, a mesh, and the optional energy terms.

    Bending with the crease is always present. `stretching=None` (default) makes the
    strip exactly inextensible; `gravity=None` (default) leaves gravity out.
    """

    strip: Strip
    clamps: Clamps
    mesh: Mesh = eqx.field(static=True)
    stretching: Stretching | None = None
    gravity: Gravity | None = None
    contact: Contact | None = None

    def __init__(self, strip, clamps, mesh=None, stretching=None, gravity=None, contact=None):
        self.strip = strip
        self.clamps = clamps
        self.mesh = Mesh() if mesh is None else mesh
        self.stretching = stretching
        self.gravity = gravity
        if contact is not None and not isinstance(contact, Contact):
            raise ValueError(f"contact must be a jaxrod.Contact or None, got {type(contact).__name__}")
        self.contact = contact
        if is_concrete_pair(clamps.gap, strip.length):
            g, L = np.asarray(clamps.gap, float), np.asarray(strip.length, float)
            if np.any(g >= L):
                raise ValueError(f"gap must lie in (0, L) = (0, {float(np.max(L)):g}), got {clamps.gap!r}")
        if strip.creases is not None:
            _warn_unresolved(strip, self.mesh)


def _warn_unresolved(strip, mesh):
    """Warn when a segment at a crease is longer than the crease's width 2 s0_k."""
    import warnings

    arrays = _crease_arrays(strip)
    if arrays is None:
        return
    L = float(strip.length)
    pos, _, wid = arrays
    for c, w in zip(pos, wid):
        h = mesh.spacing_at(c / L) * L
        if h > 2.0 * w:
            hint = "raise n"
            for r in (1.5, 2, 3, 4, 6, 8, 12, 16):
                fine = Mesh(mesh.n, r, mesh.width, tuple(pos / L))
                if all(fine.spacing_at(q / L) * L <= 2.0 * v for q, v in zip(pos, wid)):
                    hint = f"refine the mesh around the creases, e.g. Mesh.for_strip(strip, n={mesh.n}, refine={r:g}) " \
                           f"(--refine {r:g}), or raise n"
                    break
            warnings.warn(f"the crease at s = {c:g} is narrower (2 s0 = {2 * w:g}) than its segment ({h:g}): "
                          f"{hint}", stacklevel=2)
            return


def is_concrete_pair(*xs) -> bool:
    from .._misc import is_concrete

    return all(is_concrete(x) for x in xs)


def parse_creases(creases, length=1.0, s0=0.02):
    """A `Creases` from a `Creases` (returned as is) or a sequence of `(position, psi0_deg)` or
    `(position, psi0_deg, s0)` tuples in units of L and degrees (`s0` defaults to `s0`)."""
    if creases is None or isinstance(creases, Creases):
        return creases
    rows = []
    for k, c in enumerate(creases):
        try:
            row = tuple(float(v) for v in c)
        except (TypeError, ValueError):
            raise ValueError(f"creases[{k}] must be (position, psi0_deg) or (position, psi0_deg, s0), "
                             f"got {c!r}") from None
        if len(row) not in (2, 3):
            raise ValueError(f"creases[{k}] must be (position, psi0_deg) or (position, psi0_deg, s0), got {c!r}")
        rows.append(row if len(row) == 3 else row + (s0,))
    if not rows:
        raise ValueError("creases must hold at least one (position, psi0_deg[, s0]) entry")
    pos, ang, wid = (np.array([r[i] for r in rows]) for i in range(3))
    return Creases.from_degrees(pos * length, ang, wid * length, length=length)


def crease_layout(positions, psi0_deg, s0=0.02):
    """Crease positions (fractions of L) as a sorted tuple, checked for every fold angle in
    `psi0_deg` (degrees; a crease of that angle and width `s0` at each position): inside the
    strip, and no overlap beyond the rule of `Creases`. `ValueError` naming the crease
    otherwise."""
    try:
        layout = tuple(sorted(float(c) for c in positions))
    except (TypeError, ValueError):
        raise ValueError(f"creases must be a sequence of positions in (0, 1), got {positions!r}") from None
    if not layout:
        raise ValueError("creases must hold at least one position")
    for p in np.atleast_1d(np.asarray(psi0_deg, float)):
        Creases.from_degrees(layout, [float(p)] * len(layout), [float(s0)] * len(layout))
    return layout


def layout_strip(psi0, s0, layout=()):
    """The strip of a grid point (phase diagrams, speed planes): the centred crease of fold
    angle `psi0` (rad; traced values allowed) and width `s0`, or with a `layout` (crease
    positions, fractions of L, from [`jaxrod.model.crease_layout`][]) one crease of that
    angle and width at each position and none at the centre."""
    if not layout:
        return Strip(psi0=psi0, s0=s0)
    m = len(layout)
    cr = Creases(np.asarray(layout, float), jnp.full((m,), psi0), jnp.full((m,), s0))
    return Strip(psi0=math.pi, s0=s0, creases=cr)


def make_scene(psi0_deg=60.0, gap=0.5, alpha_deg=0.0, *, alpha_right_deg=None, s0=0.02, n=100,
               refine=1.0, stretching=None, gravity=None, contact=None, creases=None) -> Scene:
    """Convenience constructor in nondimensional units with angles in degrees.

    `alpha_deg` rotates the left clamp, and the right clamp too unless
    `alpha_right_deg` is given (asymmetric actuation). `creases`: further creases, a
    [`jaxrod.Creases`][] or `[(position, psi0_deg[, s0]), ...]` (units of L, degrees); with
    them `psi0_deg` is the centred crease's angle (give 180 for none) and the mesh is refined
    (`refine`) around every crease.
    """
    for name, value in (("psi0", psi0_deg), ("gap", gap), ("s0", s0), ("alpha", alpha_deg),
                        ("alpha_right", alpha_right_deg)):
        _one_number(name, value)
    check_param("psi0", psi0_deg, lo=0.0, hi=180.0, hi_open=False, unit=" deg")
    check_param("gap", gap, lo=0.0, hi=1.0)
    check_param("s0", s0, lo=0.0, hi=S0_MAX, hi_open=False)
    check_param("alpha", alpha_deg)
    d = jnp.pi / 180.0
    a_r = alpha_deg if alpha_right_deg is None else alpha_right_deg
    strip = Strip(psi0=psi0_deg * d, s0=s0, creases=parse_creases(creases, 1.0, s0))
    return Scene(
        strip,
        Clamps(gap, alpha_deg * d, a_r * d),
        Mesh(n, refine) if creases is None else Mesh.for_strip(strip, n, refine),
        stretching=stretching,
        gravity=gravity,
        contact=contact,
    )
