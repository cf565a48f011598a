r"""Geometry, material, clamps and discretization of a creased planar strip.

Conventions (see MODEL.md): arclength $s\in[0,L]$, tangent angle $\theta(s)$,
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


class Strip(eqx.Module):
    r"""A strip of length $L$, bending stiffness $B$, mass per length $\lambda$, with
    one crease of fold angle $\Psi_0$ (radians, interior angle; $\pi$ = flat) and fold
    width $s_0$ (a length), centred at $s=L/2$.

    Defaults are the nondimensional units of MODEL.md: $L=B=\lambda=1$, $s_0=0.02L$.
    """

    psi0: float = math.pi
    s0: float | None = None
    length: float = 1.0
    bending_stiffness: float = 1.0
    line_density: float = 1.0

    def __init__(self, psi0=math.pi, s0=None, length=1.0, bending_stiffness=1.0, line_density=1.0):
        check_param("length", length, lo=0.0)
        check_param("psi0", psi0, lo=0.0, hi=180.0, hi_open=False, unit=" deg", scale=180.0 / math.pi)
        check_param("bending_stiffness", bending_stiffness, lo=0.0)
        check_param("line_density", line_density, lo=0.0)
        if s0 is None:
            s0 = 0.02 * length
        check_param("s0", s0, lo=0.0)
        self.psi0 = _leaf(psi0)
        self.s0 = _leaf(s0)
        self.length = _leaf(length)
        self.bending_stiffness = _leaf(bending_stiffness)
        self.line_density = _leaf(line_density)

    @classmethod
    def from_physical(cls, *, youngs_modulus, density, thickness, width, length, psi0=math.pi, s0=None):
        r"""A strip from SI material data: $B = E t^3 w/12$, $\lambda = \rho t w$.

        **Arguments:** `youngs_modulus` $E$ (Pa), `density` $\rho$ (kg/m^3), `thickness`
        $t$ (m), `width` $w$ (m), `length` $L$ (m), `psi0` (rad), `s0` (m; default 0.02 L).
        """
        for name, v in [("youngs_modulus", youngs_modulus), ("density", density),
                        ("thickness", thickness), ("width", width)]:
            check_param(name, v, lo=0.0)
        B = youngs_modulus * thickness**3 * width / 12.0
        lam = density * thickness * width
        return cls(psi0=psi0, s0=s0, length=length, bending_stiffness=B, line_density=lam)

    @property
    def speed_gauge(self):
        r"""$v^* = \sqrt{B/(\lambda L^2)}$."""
        return jnp.sqrt(self.bending_stiffness / (self.line_density * self.length**2))

    @property
    def time_unit(self):
        r"""$T = L / v^*$."""
        return self.length / self.speed_gauge

    def natural_angle(self, s):
        r"""$\theta_0(s) = \frac{\Psi_0-\pi}{2}\tanh\frac{s-L/2}{s_0}$."""
        return 0.5 * (self.psi0 - jnp.pi) * jnp.tanh((s - 0.5 * self.length) / self.s0)


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


def _graded_fractions(n: int, ratio: float, width: float) -> np.ndarray:
    """Node fractions in [0, 1] with density 1 + (ratio-1) sech^2((x-1/2)/width)."""
    xi = np.linspace(0.0, 1.0, n + 1)
    if ratio == 1.0:
        return xi
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


class Mesh(eqx.Module):
    r"""Discretization: `n` segments (even, so a node sits at the crease $s=L/2$).

    With `refine > 1` the segments near the crease are `refine` times shorter than far
    from it (density $1+(r-1)\,\mathrm{sech}^2((s/L-1/2)/w)$, $w$ = `width`), so a sharp
    crease does not force a fine mesh everywhere. The mesh is fixed in units of $L$ and
    does not move with $s_0$, so derivatives with respect to $s_0$ are at fixed mesh.
    """

    n: int = eqx.field(static=True)
    refine: float = eqx.field(static=True)
    width: float = eqx.field(static=True)
    fractions: tuple = eqx.field(static=True, repr=False)

    def __init__(self, n: int = 100, refine: float = 1.0, width: float = 0.1):
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)):
            raise ValueError(f"n (number of segments) must be an integer, got {n!r}")
        if n < 8 or n % 2:
            raise ValueError(f"n (number of segments) must be an even integer >= 8, got {n}")
        if not (math.isfinite(refine) and refine >= 1.0):
            raise ValueError(f"refine must be a finite ratio >= 1, got {refine!r}")
        if not (math.isfinite(width) and 0.0 < width <= 1.0):
            raise ValueError(f"width must lie in (0, 1], got {width!r}")
        self.n = int(n)
        self.refine = float(refine)
        self.width = float(width)
        self.fractions = tuple(float(x) for x in _graded_fractions(self.n, self.refine, self.width))

    def __hash__(self):
        return hash((self.n, self.refine, self.width))

    def __eq__(self, other):
        return (isinstance(other, Mesh) and (self.n, self.refine, self.width)
                == (other.n, other.refine, other.width))


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


def is_concrete_pair(*xs) -> bool:
    from .._misc import is_concrete

    return all(is_concrete(x) for x in xs)


def make_scene(psi0_deg=60.0, gap=0.5, alpha_deg=0.0, *, alpha_right_deg=None, s0=0.02, n=100,
               refine=1.0, stretching=None, gravity=None, contact=None) -> Scene:
    """Convenience constructor in nondimensional units with angles in degrees.

    `alpha_deg` rotates the left clamp, and the right clamp too unless
    `alpha_right_deg` is given (asymmetric actuation).
    """
    check_param("psi0", psi0_deg, lo=0.0, hi=180.0, hi_open=False, unit=" deg")
    check_param("gap", gap, lo=0.0, hi=1.0)
    check_param("s0", s0, lo=0.0)
    check_param("alpha", alpha_deg)
    d = jnp.pi / 180.0
    a_r = alpha_deg if alpha_right_deg is None else alpha_right_deg
    return Scene(
        Strip(psi0=psi0_deg * d, s0=s0),
        Clamps(gap, alpha_deg * d, a_r * d),
        Mesh(n, refine),
        stretching=stretching,
        gravity=gravity,
        contact=contact,
    )
