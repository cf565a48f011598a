r"""Discrete quantities of a scene: segment, hinge and node data.

Nodes $s_0=0<\dots<s_N=L$; segment $i$ ($i=1..N$) has length $h_i=s_i-s_{i-1}$,
midpoint $m_i$ and one tangent angle $\theta_i$. The clamps act as two extra
"segments" of zero length at $m_0=0$ ($\theta_0=\alpha_L$) and $m_{N+1}=L$
($\theta_{N+1}=-\alpha_R$). Hinge $k=0..N$ sits at node $s_k$ between segments $k$ and
$k+1$ and has length $\ell_k = m_{k+1}-m_k$. The natural turning angles are exact
differences $\bar\phi_k = \theta_0(m_{k+1})-\theta_0(m_k)$, so the crease turns by
exactly $\theta_0(L)-\theta_0(0)$ at any resolution.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array


class Discrete(NamedTuple):
    s: Array  # (N+1,) node arclengths
    h: Array  # (N,) segment lengths
    mid: Array  # (N+2,) segment midpoints incl. the clamps' zero-length segments
    ell: Array  # (N+1,) hinge lengths
    phi0: Array  # (N+1,) natural turning angles
    node_mass: Array  # (N+1,) lumped node masses (ends included)
    theta_left: Array  # clamp tangent at s = 0
    theta_right: Array  # clamp tangent at s = L


def scene_dtype(scene):
    st, cl = scene.strip, scene.clamps
    extra = () if st.creases is None else (st.creases.positions, st.creases.angles, st.creases.widths)
    return jnp.result_type(st.psi0, st.s0, st.length, st.bending_stiffness, cl.gap,
                           cl.alpha_left, cl.alpha_right, *extra, float)


def discretize(scene) -> Discrete:
    st, cl = scene.strip, scene.clamps
    dtype = scene_dtype(scene)
    L = jnp.asarray(st.length, dtype)
    s = L * jnp.asarray(scene.mesh.fractions, dtype)
    h = jnp.diff(s)
    m = 0.5 * (s[1:] + s[:-1])
    mid = jnp.concatenate([s[:1], m, s[-1:]])
    ell = jnp.diff(mid)
    phi0 = jnp.diff(st.natural_angle(mid))
    vor = jnp.concatenate([h[:1] * 0.5, 0.5 * (h[1:] + h[:-1]), h[-1:] * 0.5])
    node_mass = st.line_density * vor
    tl = jnp.asarray(cl.alpha_left, dtype)
    tr = -jnp.asarray(cl.alpha_right, dtype)
    return Discrete(s, h, mid, ell, phi0, node_mass, tl, tr)


def at_arclength(values, s, where):
    """Node `values` (N+1, ...) linearly interpolated to the arclengths `where` (m,), with
    node arclengths `s` (N+1,); differentiable in `values` and in `where`."""
    i = jnp.clip(jnp.searchsorted(s, where, side="right") - 1, 0, s.shape[0] - 2)
    w = (where - s[i]) / (s[i + 1] - s[i])
    w = w.reshape(w.shape + (1,) * (values.ndim - 1))
    return (1.0 - w) * values[i] + w * values[i + 1]


MIRROR_TIE = 1e-10
"""Relative size below which a mode's first-order effect counts as zero in [`mode_sign`][]."""


def mode_sign(effect, h, v):
    r"""The sign (+1.0 or -1.0) to give the mode `v` (segment angles, with segment lengths `h`)
    so that `effect`, the first-order change the mode makes in some observable (a fold height's
    $\sum_{i<N/2}h_i\cos\theta_i\,v_i$, or a difference of fold heights), is non-negative.

    Where `effect` vanishes to round-off, $|{\rm effect}|\le 10^{-10}\sum_ih_i|v_i|$ (the
    mirror-asymmetric mode of a branch point, whose two signs give the mirror images of one
    motion), the sign is the mirror convention instead: the one that makes the mode's mean
    angle $\sum_ih_iv_i$ negative. Round-off then never chooses the image: the same scene gives
    the same one on every machine and every build."""
    scale = jnp.sum(h * jnp.abs(v))
    tie = jnp.abs(effect) <= MIRROR_TIE * scale
    return jnp.where(tie, jnp.where(jnp.sum(h * v) <= 0, 1.0, -1.0), jnp.where(effect >= 0, 1.0, -1.0))
