"""Imperfection sensitivity (`jaxrod.design._imperfections`): the imperfect strip at zero
amplitude is the nominal one, and the snap angle moves by the laws of the nominal kind: like
eps^(2/3) at a branch point (Koiter), eps^2 at a fold for the crease offset (whose sign is
the mirror image), eps at a fold for the kink."""

from __future__ import annotations

import math

import numpy as np
import pytest

import jaxrod as jr
import jaxrod.design as jd

N = 26


@pytest.mark.parametrize("kind", ["crease_offset", pytest.param("kink", marks=pytest.mark.slow)])
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
    (dict(gap=1.5), "gap"),
    (dict(tolerance=-1.0), "tolerance"),
])
def test_bad_input_names_its_parameter(kwargs, match):
    args = dict(psi0_deg=60.0, gap=0.5, n=N)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        jd.imperfection_sensitivity(args.pop("psi0_deg"), args.pop("gap"), **args)
