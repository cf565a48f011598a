"""Bad input raises ValueError naming the offending parameter (no solve involved)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import jaxrod as jr


NAN = float("nan")


def raises_naming(name, fn, *args, **kwargs):
    with pytest.raises(ValueError, match=rf"\b{name}\b"):
        fn(*args, **kwargs)


@pytest.mark.parametrize("gap", [0.0, -0.1, 1.0, 1.5, NAN, math.inf])
def test_gap(gap):
    raises_naming("gap", jr.make_scene, 60.0, gap)
    raises_naming("gap", lambda: jr.Scene(jr.Strip(psi0=1.0), jr.Clamps(gap), jr.Mesh(20)))


def test_gap_relative_to_length():
    # G must lie below the actual strip length, not below 1
    raises_naming("gap", lambda: jr.Scene(jr.Strip(length=2.0), jr.Clamps(2.5), jr.Mesh(20)))
    jr.Scene(jr.Strip(length=2.0), jr.Clamps(1.5), jr.Mesh(20))  # fine


@pytest.mark.parametrize("psi0_deg", [0.0, -10.0, 180.5, 360.0, NAN])
def test_psi0(psi0_deg):
    raises_naming("psi0", jr.make_scene, psi0_deg, 0.5)
    raises_naming("psi0", jr.Strip, psi0=math.radians(psi0_deg))


def test_psi0_bounds_are_inclusive_at_flat():
    jr.make_scene(180.0, 0.5)  # flat strip: allowed
    jr.Strip(psi0=math.pi)
    jr.make_scene(1e-3, 0.5)  # a very tight fold is still a fold


@pytest.mark.parametrize("s0", [0.0, -0.02, NAN, 0.26, 0.6])
def test_s0(s0):
    """Fold widths in (0, 0.25 L]: wider, the crease's profile is cut off by the strip's ends
    (at s0 = 0.6 L it would turn by 82 deg for a fold that says 120)."""
    raises_naming("s0", jr.make_scene, 60.0, 0.5, s0=s0)
    raises_naming("s0", jr.Strip, psi0=1.0, s0=s0)


def test_s0_bound_scales_with_length():
    jr.make_scene(60.0, 0.5, s0=0.25)
    jr.Strip(psi0=1.0, s0=0.4, length=2.0)  # 0.2 L
    raises_naming("s0", jr.Strip, psi0=1.0, s0=0.6, length=2.0)


@pytest.mark.parametrize("name, kwargs", [
    ("psi0", dict(psi0_deg=[60.0, 90.0])), ("gap", dict(gap=np.array([0.3, 0.5]))), ("s0", dict(s0=[0.02])),
    ("alpha", dict(alpha_deg=(1.0, 2.0))), ("alpha_right", dict(alpha_right_deg=[1.0, 2.0])),
])
def test_one_number_per_parameter(name, kwargs):
    """A list or an array where make_scene takes one number is refused by name (a batch of
    scenes is `jax.vmap(jr.make_scene)`)."""
    raises_naming(name, jr.make_scene, **kwargs)


@pytest.mark.parametrize("scene", [None, "60/0.5", 0.5])
def test_not_a_scene(scene):
    raises_naming("scene", jr.snap_angles, scene)
    raises_naming("scene", jr.initial_state, scene)


@pytest.mark.parametrize("n", [0, 2, 6, 7, 99, 101])
def test_n_small_or_odd(n):
    raises_naming("n", jr.make_scene, 60.0, 0.5, n=n)
    raises_naming("n", jr.Mesh, n)


@pytest.mark.parametrize("n", [NAN, 100.0, "100", True])
def test_n_not_an_integer(n):
    raises_naming("n", jr.Mesh, n)


def test_n_numpy_integer_accepted():
    assert jr.Mesh(np.int64(100)).n == 100


@pytest.mark.parametrize("kwargs, name", [
    (dict(refine=NAN), "refine"), (dict(refine=0.5), "refine"), (dict(width=NAN), "width"), (dict(width=0.0), "width"),
])
def test_mesh_options(kwargs, name):
    raises_naming(name, jr.Mesh, 100, **kwargs)


@pytest.mark.parametrize("alpha", [NAN, math.inf])
def test_alpha(alpha):
    raises_naming("alpha", jr.make_scene, 60.0, 0.5, alpha)
    raises_naming("alpha_right", jr.make_scene, 60.0, 0.5, 0.0, alpha_right_deg=alpha)
    raises_naming("alpha_left", jr.Clamps, 0.5, alpha, 0.0)
    raises_naming("alpha_right", jr.Clamps, 0.5, 0.0, alpha)


@pytest.mark.parametrize("name", ["length", "bending_stiffness", "line_density"])
@pytest.mark.parametrize("value", [0.0, -1.0, NAN])
def test_strip_material(name, value):
    raises_naming(name, jr.Strip, **{name: value})


@pytest.mark.parametrize("name", ["youngs_modulus", "density", "thickness", "width"])
@pytest.mark.parametrize("value", [0.0, -1.0, NAN])
def test_from_physical(name, value):
    kw = dict(youngs_modulus=4.5e9, density=1380.0, thickness=1.25e-4, width=0.01, length=0.2)
    kw[name] = value
    raises_naming(name, jr.Strip.from_physical, **kw)


def test_from_physical_values():
    st = jr.Strip.from_physical(youngs_modulus=4.5e9, density=1380.0, thickness=1.25e-4, width=0.01, length=0.2)
    assert float(st.bending_stiffness) == pytest.approx(4.5e9 * 1.25e-4**3 * 0.01 / 12, rel=1e-14)
    assert float(st.line_density) == pytest.approx(1380.0 * 1.25e-4 * 0.01, rel=1e-14)
    assert float(st.s0) == pytest.approx(0.02 * 0.2, rel=1e-14)


@pytest.mark.parametrize("value", [0.0, -1.0, NAN])
def test_stretching_stiffness(value):
    raises_naming("stiffness", jr.Stretching, value)


def test_gravity():
    raises_naming("g", jr.Gravity, NAN)


def test_solver_arguments():
    scene = jr.make_scene(60.0, 0.5, n=20)
    raises_naming("theta0", jr.solve_equilibrium, scene, np.zeros(21))
    raises_naming("state", jr.initial_state, scene, "sideways")
    raises_naming("minimize", jr.initial_state, scene, "up", solver=jr.Newton(minimize=False))
