"""Imperfection sensitivity (`jaxrod.design._imperfections`): the imperfect strip at zero
amplitude is the nominal one, and the snap angle moves by the laws of the nominal kind: like
eps^(2/3) at a branch point (Koiter), eps^2 at a fold for the crease offset (whose sign is
the mirror image) and for a clamp misalignment, eps at a fold for the kink."""

from __future__ import annotations

import math

import numpy as np
import pytest

import jaxrod as jr
import jaxrod.design as jd

N = 26


@pytest.mark.slow  # a crease set's snap angles compiled (CI: the scenes' construction below, no solve)
@pytest.mark.parametrize("kind", ["crease_offset", "kink", "clamp_misalignment"])
def test_zero_amplitude_is_the_nominal_strip(kind):
    nominal = jr.snap_angles(jr.make_scene(60.0, 0.5, n=N))
    imperfect = jr.snap_angles(jd.imperfect_scene(60.0, 0.5, kind, 0.0, n=N))
    for a, b in ((nominal.up, imperfect.up), (nominal.down, imperfect.down)):
        assert int(a.kind) == int(b.kind)
        np.testing.assert_allclose(math.degrees(float(b.alpha_c)), math.degrees(float(a.alpha_c)), atol=1e-9)


@pytest.fixture(scope="module")
def offset():
    return jd.imperfection_sensitivity(60.0, 0.5, "crease_offset", n=N)


@pytest.mark.slow  # a batch of snap angles compiled for the imperfections (CI: the fit's unit test below)
def test_crease_offset_laws(offset):
    """Psi0 = 60 deg, G/L = 0.5: the snap up is a branch point (2/3), the snap down a fold (2);
    every imperfect path is a fold; the fitted laws hold from the smallest amplitude on."""
    up, down = offset.up, offset.down
    assert (up.nominal_kind, down.nominal_kind) == ("branch_point", "fold")
    assert set(up.kinds) == {"fold"} and set(down.kinds) == {"fold"}
    assert abs(up.exponent - 2 / 3) < 0.02 and abs(down.exponent - 2.0) < 0.02
    assert up.holds[0] == offset.amplitudes[0] and down.holds[0] == offset.amplitudes[0]
    assert abs(up.local_exponents[0] - 2 / 3) < 0.01  # the law's limit at small offsets
    np.testing.assert_allclose(up.change_deg, np.abs(up.alpha_deg - up.nominal_deg))
    assert offset.result == jr.RESULTS.successful


@pytest.mark.slow
def test_figure(offset, tmp_path):
    """The log-log figure is written (a PNG with both directions and their laws)."""
    path = jr.plot_imperfection_sensitivity(offset, tmp_path / "imperfection.png")
    assert path.stat().st_size > 10_000


@pytest.mark.slow
def test_kink_laws():
    s = jd.imperfection_sensitivity(60.0, 0.5, "kink", amplitudes=np.geomspace(1e-3, 1e-1, 5), n=N)
    assert abs(s.up.exponent - 2 / 3) < 0.02 and abs(s.down.exponent - 1.0) < 0.02
    assert s.kind == "kink" and s.up.predicted == pytest.approx(2 / 3) and s.down.predicted == 1.0


def test_imperfect_scenes_carry_their_amplitude():
    """Each imperfection changes the nominal strip where its definition says, by its amplitude
    (no solve): the crease's position, the weak crease's fold angle, the clamps' difference."""
    from jaxrod.design._imperfections import IMPERFECTIONS

    nominal = {k: jd.imperfect_scene(60.0, 0.5, k, 0.0, n=N) for k in IMPERFECTIONS}
    off = jd.imperfect_scene(60.0, 0.5, "crease_offset", 0.01, n=N)
    assert float(off.strip.creases.positions[0]) == pytest.approx(0.51)
    kink = jd.imperfect_scene(60.0, 0.5, "kink", 2.0, n=N)
    np.testing.assert_allclose(np.degrees(np.asarray(kink.strip.creases.angles)), [60.0, 178.0])
    assert float(kink.strip.creases.positions[1]) == pytest.approx(0.25)
    mis = jd.imperfect_scene(60.0, 0.5, "clamp_misalignment", 2.0, n=N)
    assert math.degrees(float(mis.clamps.alpha_left)) == pytest.approx(1.0)
    assert math.degrees(float(mis.clamps.alpha_right)) == pytest.approx(-1.0)
    for k, sc in nominal.items():
        assert float(sc.clamps.alpha_left) == float(sc.clamps.alpha_right) == 0.0, k
        assert float(sc.strip.creases.positions[0]) == 0.5 and math.degrees(float(sc.strip.creases.angles[0])) == \
            pytest.approx(60.0)


def test_symmetric_alpha_keeps_a_misalignment():
    """`SymmetricAlpha(delta)` turns both clamps about the misalignment: alpha_L - alpha_R =
    delta, their mean alpha; `for_scene` reads delta from the scene (no solve)."""
    import jax.numpy as jnp

    sc = jr.make_scene(60.0, 0.5, 3.0, alpha_right_deg=1.0, n=N)
    p = jr.SymmetricAlpha.for_scene(sc)
    assert math.degrees(float(p.misalignment)) == pytest.approx(2.0)
    at = p.set(sc, jnp.deg2rad(10.0))
    assert math.degrees(float(at.clamps.alpha_left)) == pytest.approx(11.0)
    assert math.degrees(float(at.clamps.alpha_right)) == pytest.approx(9.0)
    assert math.degrees(float(p.get(at))) == pytest.approx(10.0)
    plain = jr.SymmetricAlpha().set(sc, 0.25)
    assert float(plain.clamps.alpha_left) == float(plain.clamps.alpha_right) == 0.25


def test_clamp_misalignment_is_mirror_even():
    """A misalignment +eps is the mirror image of -eps: the same snap angles to round-off; the
    branch point of the nominal snap up unfolds into a fold that comes earlier; only the clamps'
    difference matters (a scene built with clamp angles 3 and 2 deg is the 1 deg misalignment)."""
    n = 24  # the plain scene's program of test_scatter.py's single calls
    plus = jr.snap_angles(jr.make_scene(60.0, 0.5, 0.5, alpha_right_deg=-0.5, n=n))
    minus = jr.snap_angles(jr.make_scene(60.0, 0.5, -0.5, alpha_right_deg=0.5, n=n))
    built = jr.snap_angles(jr.make_scene(60.0, 0.5, 3.0, alpha_right_deg=2.0, n=n))
    nominal = jr.snap_angles(jr.make_scene(60.0, 0.5, n=n))
    for a, b, c in ((plus.up, minus.up, built.up), (plus.down, minus.down, built.down)):
        assert a.result == b.result == c.result == jr.RESULTS.successful
        np.testing.assert_allclose(float(a.alpha_c), float(b.alpha_c), rtol=0, atol=1e-10)
        np.testing.assert_allclose(float(a.alpha_c), float(c.alpha_c), rtol=0, atol=1e-10)
    assert jr.KIND_NAMES[int(nominal.up.kind)] == "branch_point" and jr.KIND_NAMES[int(plus.up.kind)] == "fold"
    assert 0.5 < math.degrees(float(nominal.up.alpha_c - plus.up.alpha_c)) < 5.0


@pytest.mark.slow  # a batch of snap angles compiled for the imperfections
def test_clamp_misalignment_laws():
    """The up branch point unfolds like eps^(2/3), the down fold moves like eps^2 (mirror-even)."""
    s = jd.imperfection_sensitivity(60.0, 0.5, "clamp_misalignment", n=N)
    assert (s.up.nominal_kind, s.down.nominal_kind) == ("branch_point", "fold")
    assert abs(s.up.exponent - 2 / 3) < 0.02 and abs(s.down.exponent - 2.0) < 0.02
    assert s.up.holds[0] == s.amplitudes[0]
    assert s.result == jr.RESULTS.successful


def test_brink_keeps_the_misalignment():
    """The brink's clamps (scene and protocol) turn about the scene's misalignment."""
    sc = jr.make_scene(60.0, 0.5, 0.5, alpha_right_deg=-0.5, n=24)
    start = jr.brink(sc, "up")
    assert math.degrees(float(start.scene.clamps.alpha_left - start.scene.clamps.alpha_right)) == pytest.approx(1.0)
    assert math.degrees(float(start.protocol.alpha_left0 - start.protocol.alpha_right0)) == pytest.approx(1.0)
    mean = 0.5 * (start.protocol.alpha_left0 + start.protocol.alpha_right0)
    assert float(mean) == pytest.approx(float(start.alpha_c) + 1e-3, abs=1e-12)


def test_power_law_fit_of_synthetic_changes():
    """The fit alone (no solve): changes C eps^(2/3) that leave the law at the largest
    amplitudes give the exponent, C and the range where the law holds; a path that is not
    successful breaks the run."""
    from types import SimpleNamespace

    from jaxrod.design._imperfections import _direction

    eps = np.geomspace(1e-5, 1e-2, 7)
    change = 2.5 * eps ** (2 / 3) * (1 + np.where(eps > 2e-3, 0.5, 0.0))  # off the law at the last two
    ok = int(jr.RESULTS.successful._value)
    path = SimpleNamespace(snaps=np.ones(7, bool), alpha_c=np.radians(77.0 - change), kind=np.ones(7, int),
                           result=SimpleNamespace(_value=np.full(7, ok)))
    nominal = SimpleNamespace(snaps=True, alpha_c=np.radians(77.0), kind=2, result=SimpleNamespace(_value=ok))
    d = _direction(path, nominal, "crease_offset", eps, 0.05)
    assert d.nominal_kind == "branch_point" and d.predicted == pytest.approx(2 / 3)
    assert d.exponent == pytest.approx(2 / 3, abs=1e-9) and d.coefficient == pytest.approx(2.5, rel=1e-9)
    assert d.holds == (eps[0], eps[4])
    bad = SimpleNamespace(**{**vars(path), "result": SimpleNamespace(_value=np.array([ok, ok, 99, ok, ok, ok, ok]))})
    d = _direction(bad, nominal, "crease_offset", eps, 0.05)
    assert np.isnan(d.alpha_deg[2]) and d.holds == (eps[0], eps[1])  # two runs of one step: the smaller


@pytest.mark.parametrize("kwargs, match", [
    (dict(kind="dent"), "kind"),
    (dict(amplitudes=[1e-3]), "amplitudes"),
    (dict(amplitudes=[1e-2, 1e-3]), "amplitudes"),
    (dict(amplitudes=[1e-3, 0.3]), "amplitudes"),
    (dict(kind="clamp_misalignment", amplitudes=[1.0, 90.0]), "amplitudes"),
    (dict(gap=1.5), "gap"),
    (dict(tolerance=-1.0), "tolerance"),
])
def test_bad_input_names_its_parameter(kwargs, match):
    args = dict(psi0_deg=60.0, gap=0.5, n=N)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        jd.imperfection_sensitivity(args.pop("psi0_deg"), args.pop("gap"), **args)
