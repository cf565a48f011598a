r"""Observables of an equilibrium: shapes, curvature, fold height, energies."""

from __future__ import annotations


from ..energy.bending import curvature as _curvature
from ..energy.geometry import at_arclength, discretize
from ..energy.lagrangian import energies as _energies
from ..energy.lagrangian import positions as _positions
from ..energy.lagrangian import strains as _strains


def node_positions(eq):
    """Node positions, shape (N+1, 2); node 0 at the left clamp, node N at the right."""
    return _positions(eq.theta, eq.force, eq.scene)


def tangent_angles(eq):
    """Segment tangent angles (N,), radians."""
    return eq.theta


def arclength(eq):
    """Node arclengths (N+1,)."""
    return discretize(eq.scene).s


def curvature(eq):
    r"""Curvature $\kappa_k=\phi_k/\ell_k$ at the N+1 hinges (clamps included)."""
    return _curvature(eq.theta, discretize(eq.scene))


def strains(eq):
    return _strains(eq.theta, eq.force, eq.scene, discretize(eq.scene))


def fold_height(eq):
    """$y(L/2)$, the height of the crease node. Up state > 0, down state < 0."""
    return node_positions(eq)[eq.scene.mesh.n // 2, 1]


def crease_points(eq):
    r"""Position $\mathbf r(c_k)$ of every crease (`Strip.crease_list` order: the centred
    crease first, then `Strip.creases`), shape (m, 2); interpolated linearly between nodes."""
    pos, _, _ = eq.scene.strip.crease_list()
    return at_arclength(node_positions(eq), discretize(eq.scene).s, pos.astype(eq.theta.dtype))


def crease_heights(eq):
    """Height $y(c_k)$ of every crease (`crease_points`), shape (m,)."""
    return crease_points(eq)[:, 1]


def energies(eq):
    """Dict with `bending`, `stretching`, `gravity`, `contact` energies and their `total`."""
    e = _energies(eq.theta, eq.force, eq.scene)
    e["total"] = e["bending"] + e["stretching"] + e["gravity"] + e["contact"]
    return e


def bending_energy(eq):
    return energies(eq)["bending"]


def compression(eq):
    r"""End compression $P=-\mu_x = -\partial E/\partial G$ (positive when pushed)."""
    return -eq.force[0]
