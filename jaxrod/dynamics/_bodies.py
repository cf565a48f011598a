r"""Rigid bodies the strip can strike: balls, a table, a floor, and their contact energies.

**Balls.** Ball $m=1..M$ is a rigid disc in the strip's plane (or the section of a ball
through it): centre $\mathbf c_m$, radius $R_m$, mass $M_m$, translating only (no spin:
without friction between the strip and the ball a spin is never excited). Positions in the
frame of docs/model.md (left clamp at the origin, right clamp at $(G,0)$), units of the scene
($L$, and $\lambda L$ for masses; natural units by default).

**Contact law.** Every contact is the penalty of self-contact (`jaxrod.energy.contact.penalty`)
$\varphi(g)=\frac{k\delta}3(1-g/\delta)^3$ for a gap $g<\delta$, else 0: a soft layer of
thickness $\delta$ (`thickness`, default 0.02 L) whose force grows from zero (with its first
two derivatives, so the dynamics and their gradients stay smooth) to $k$ (`stiffness`,
default $3\cdot10^5$) when the layer is fully compressed. A gap below zero (the layer
exhausted) is an impact too fast for the law: the run says `RESULTS.object_penetrated`.

* strip and ball: $E_{sb}=\sum_m\int_0^L\varphi(|\mathbf c_m-\mathbf r(s)|-R_m)\,ds$, $\mathbf r(s)$
  the strip's centreline (straight between nodes), by the composite midpoint rule with $q$
  points per segment, $q$ such that the points are at most a quarter of the contact patch's
  half-width $\sqrt{2R\delta}$ apart (`quadrature_points`). Point-to-point distances make
  $E_{sb}$ twice continuously differentiable in the positions everywhere (no switch at the
  nodes or the segments' ends, which would make the hit's derivative jump), a ball feels a
  sharp crease's corner like any other part of the strip, and a ball sliding along a straight
  strip feels a ripple of the quadrature's order only. $k$ is here a stiffness per unit
  length: a ball pressed to full compression on a straight strip holds the energy
  $\approx0.30\,k\delta\sqrt{2R\delta}$;
* ball and ball: $\varphi(|\mathbf c_m-\mathbf c_n|-R_m-R_n)$ with the force at full
  compression $k\sqrt{2R\delta}$ ($R$ the smaller radius; `point_stiffness`);
* ball and floor (`Floor(height)`, side view): $\varphi(c_{m,y}-R_m-y_f)$, likewise, with the scene's
  gravity pulling the balls down ($g\sum_mM_mc_{m,y}$);
* table (`Table(deceleration)`, top view: the strip and the balls lie on a table, the
  strip's plane is the table's): a regularized Coulomb friction $-a_fM_m\mathbf v_m/
  \sqrt{|\mathbf v_m|^2+v_\epsilon^2}$ ($a_f=\mu g$, `deceleration`; $v_\epsilon$ = 1e-3 $v^*$)
  that slows a launched ball to rest.

Every contact energy depends only on differences of positions, so the forces on the strip
and on the ball are equal and opposite (Newton's third law holds exactly, and the momentum
a ball gains is the impulse the strip gives it).
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..energy.contact import penalty, point_segment_distance, safe_norm
from .._misc import check_param, is_concrete


BODY_STIFFNESS = 3.0e5
"""Default contact stiffness k of the bodies: per unit length of strip for the strip-ball
contact (B/L^3), the force at full compression for ball-ball and floor contacts (B/L^2)."""
BODY_THICKNESS = 0.02
"""Default contact layer thickness delta of the bodies (L)."""
FRICTION_SPEED = 1e-3
"""Regularization speed v_eps of the table's Coulomb friction (v*)."""


class Ball(eqx.Module):
    """A ball: `name`, centre `position` (x, y), `radius`, `mass`, initial `velocity`
    (default at rest). Units of the scene (L, lambda L, v*)."""

    position: jax.Array
    radius: jax.Array
    mass: jax.Array
    velocity: jax.Array
    name: str = eqx.field(static=True)

    def __init__(self, name, position, radius, mass, velocity=(0.0, 0.0)):
        if not isinstance(name, str) or not name:
            raise ValueError(f"name must be a non-empty string, got {name!r}")
        for label, v in [("position", position), ("velocity", velocity)]:
            if is_concrete(v):
                a = np.asarray(v, dtype=float)
                if a.shape != (2,) or not np.all(np.isfinite(a)):
                    raise ValueError(f"{label} of ball {name!r} must be a finite pair (x, y), got {v!r}")
        check_param(f"radius of ball {name!r}", radius, lo=0.0)
        check_param(f"mass of ball {name!r}", mass, lo=0.0)
        self.name = name
        self.position = jnp.asarray(position, float)
        self.radius = jnp.asarray(radius, float)
        self.mass = jnp.asarray(mass, float)
        self.velocity = jnp.asarray(velocity, float)


class Table(eqx.Module):
    """The table the strip and the balls lie on (top view): sliding friction decelerates a
    moving ball by `deceleration` = mu g (L / T^2)."""

    deceleration: jax.Array

    def __init__(self, deceleration=0.0):
        check_param("deceleration", deceleration, lo=0.0, lo_open=False)
        self.deceleration = jnp.asarray(deceleration, float)


class Floor(eqx.Module):
    """A floor (side view) at `height` y_f below which no ball goes; the scene's gravity pulls
    the balls onto it."""

    height: jax.Array

    def __init__(self, height=0.0):
        check_param("height", height)
        self.height = jnp.asarray(height, float)


class Bodies(eqx.Module):
    """The balls of a run with their contact law (`stiffness` k, `thickness` delta; see the
    module docstring), an optional `table` (friction) and `floor`. Arrays stack the balls in
    the order given: `position`, `velocity` (M, 2), `radius`, `mass` (M,); `names`."""

    position: jax.Array
    velocity: jax.Array
    radius: jax.Array
    mass: jax.Array
    stiffness: jax.Array
    thickness: jax.Array
    table: Table | None
    floor: Floor | None
    names: tuple = eqx.field(static=True)

    def __init__(self, balls, *, stiffness=BODY_STIFFNESS, thickness=BODY_THICKNESS, table=None, floor=None):
        balls = tuple(balls)
        if not balls or not all(isinstance(b, Ball) for b in balls):
            raise ValueError(f"balls must be a non-empty sequence of jaxrod.Ball, got {balls!r}")
        names = tuple(b.name for b in balls)
        if len(set(names)) != len(names):
            raise ValueError(f"balls: names must be unique, got {names}")
        check_param("stiffness", stiffness, lo=0.0)
        check_param("thickness", thickness, lo=0.0)
        if table is not None and not isinstance(table, Table):
            raise ValueError(f"table must be a jaxrod.Table or None, got {table!r}")
        if floor is not None and not isinstance(floor, Floor):
            raise ValueError(f"floor must be a jaxrod.Floor or None, got {floor!r}")
        if table is not None and floor is not None:
            raise ValueError("table, floor: a scene is seen from above (table) or from the side (floor), not both")
        self.names = names
        self.position = jnp.stack([b.position for b in balls])
        self.velocity = jnp.stack([b.velocity for b in balls])
        self.radius = jnp.stack([b.radius for b in balls])
        self.mass = jnp.stack([b.mass for b in balls])
        self.stiffness = jnp.asarray(stiffness, float)
        self.thickness = jnp.asarray(thickness, float)
        self.table = table
        self.floor = floor

    @property
    def count(self) -> int:
        return len(self.names)


def quadrature_points(bodies, h_max) -> int:
    r"""Quadrature points per segment of the strip-ball contact (static), for segments up to
    `h_max` long: the spacing is at most a quarter of the narrowest contact patch's half-width
    $\sqrt{2R\delta}$, and at least 4 points."""
    r = float(np.min(np.asarray(bodies.radius)))
    return int(max(4, math.ceil(4.0 * float(h_max) / math.sqrt(2.0 * r * float(bodies.thickness)))))


def strip_body_energy(x, xb, bodies, q):
    r"""$E_{sb}$ of strip node positions `x` (N+1, 2) and ball centres `xb` (M, 2) by the
    composite midpoint rule with `q` points per segment (`quadrature_points`)."""
    a, b = x[:-1], x[1:]
    seg = safe_norm(b - a)  # (N,)
    u = (jnp.arange(q) + 0.5) / q
    pts = a[:, None, :] + u[None, :, None] * (b - a)[:, None, :]  # (N, q, 2)
    w = jnp.repeat(seg / q, q)
    pts = pts.reshape(-1, 2)

    def one(c, r):
        return jnp.sum(w * penalty(safe_norm(c[None, :] - pts) - r, bodies.thickness, bodies.stiffness))

    return jnp.sum(jax.vmap(one)(xb, bodies.radius))


def point_stiffness(bodies, radius):
    r"""The force at full compression of a ball-ball or ball-floor contact, $k\sqrt{2R\delta}$
    ($R$ the smaller radius): the line stiffness $k$ over the width of a ball's contact patch,
    so that a ball stops on another ball or the floor about as stiffly as on the strip."""
    return bodies.stiffness * jnp.sqrt(2.0 * radius * bodies.thickness)


def body_energy(xb, bodies, gravity=None):
    r"""The balls' energy apart from the strip: ball-ball contacts, the floor and, with a
    floor, gravity $g\sum_mM_mc_{m,y}$ (`gravity`: the scene's `Gravity` or None)."""
    e = jnp.zeros((), xb.dtype)
    m = xb.shape[0]
    if m > 1:
        i, j = np.triu_indices(m, k=1)
        gap = safe_norm(xb[i] - xb[j]) - bodies.radius[i] - bodies.radius[j]
        k = point_stiffness(bodies, jnp.minimum(bodies.radius[i], bodies.radius[j]))
        e = e + jnp.sum(penalty(gap, bodies.thickness, k))
    if bodies.floor is not None:
        gap = xb[:, 1] - bodies.radius - bodies.floor.height
        e = e + jnp.sum(penalty(gap, bodies.thickness, point_stiffness(bodies, bodies.radius)))
        if gravity is not None:
            e = e + gravity.g * jnp.sum(bodies.mass * xb[:, 1])
    return e


def friction_force(vb, bodies):
    """The table's friction on the balls (M, 2) at velocities `vb` (zero without a table)."""
    if bodies.table is None:
        return jnp.zeros_like(vb)
    s = jnp.sqrt(jnp.sum(vb**2, -1) + FRICTION_SPEED**2)
    return -(bodies.table.deceleration * bodies.mass / s)[:, None] * vb


def body_clearance(x, xb, bodies):
    r"""Per ball, the smallest gap (M,): to the strip (distance from the centre to the closest
    point of any segment, minus $R_m$), to the other balls and to the floor. Negative: the
    contact layer is exhausted (`RESULTS.object_penetrated`)."""
    a, b = x[:-1], x[1:]
    d = jax.vmap(lambda c: jnp.min(point_segment_distance(c[None, :], a, b)))(xb) - bodies.radius
    m = xb.shape[0]
    if m > 1:
        sep = safe_norm(xb[:, None, :] - xb[None, :, :]) - bodies.radius[:, None] - bodies.radius[None, :]
        sep = jnp.where(jnp.eye(m, dtype=bool), jnp.inf, sep)
        d = jnp.minimum(d, jnp.min(sep, -1))
    if bodies.floor is not None:
        d = jnp.minimum(d, xb[:, 1] - bodies.radius - bodies.floor.height)
    return d


__all__ = ["Ball", "Bodies", "Floor", "Table", "BODY_STIFFNESS", "BODY_THICKNESS"]
