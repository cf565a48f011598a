"""Crease positions and fold angles as design variables (`jaxrod.design._creases`): the
parametrization, bad input, the snap speed's gradient in the crease set, and the two studies
of `jaxrod.paper` (nightly: each compiles the derivatives of a whole snap path or snap)."""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
import jaxrod.design as jd
import jaxrod.paper as paper
from helpers import central_difference


def test_parametrization_round_trip_and_bounds():
    p = jd.CreaseParametrization(2, positions=(0.1, 0.9), angles_deg=(30.0, 170.0))
    z = p.from_values([0.3, 0.65], [90.0, 120.0])
    c, a = p.to_creases(z)
    np.testing.assert_allclose(np.asarray(c), [0.3, 0.65], atol=1e-12)
    np.testing.assert_allclose(np.degrees(np.asarray(a)), [90.0, 120.0], atol=1e-10)
    c, a = p.to_creases(jnp.asarray([-50.0, 50.0, -50.0, 50.0]))  # far out: still inside the bounds
    assert 0.1 <= float(c[0]) < float(c[1]) <= 0.9 and 30.0 - 1e-9 <= math.degrees(float(a[0])) <= 170.0


@pytest.mark.parametrize("kwargs, match", [
    (dict(m=0), "m"), (dict(m=1.5), "m"), (dict(positions=(0.5, 0.2)), "positions"),
    (dict(positions=(0.0, 0.9)), "positions"), (dict(angles_deg=(30.0, 200.0)), "angles_deg"),
])
def test_parametrization_bad_input(kwargs, match):
    with pytest.raises(ValueError, match=match):
        jd.CreaseParametrization(**kwargs)


@pytest.mark.parametrize("kwargs, match", [
    (dict(gap=1.2), "gap"), (dict(psi0_deg=0.0), "psi0_deg"), (dict(psi0_deg=float("nan")), "psi0_deg"),
    (dict(lo=0.6), "lo"),
])
def test_position_study_bad_input(kwargs, match):
    with pytest.raises(ValueError, match=match):
        paper.crease_position_study(**kwargs)


def test_two_crease_study_bad_input():
    with pytest.raises(ValueError, match="gap"):
        paper.two_crease_study(gap=0.0)
    with pytest.raises(ValueError, match="alpha_up_deg"):
        paper.two_crease_study(alpha_up_deg=float("inf"))


def test_crease_scene_places_the_creases():
    sc = jd.crease_scene(jnp.asarray([0.3, 0.65]), jnp.radians(jnp.asarray([90.0, 120.0])), gap=0.4, n=48)
    cr = sc.strip.creases
    np.testing.assert_allclose(np.asarray(cr.positions), [0.3, 0.65])
    assert float(sc.clamps.gap) == 0.4 and float(sc.strip.psi0) == math.pi and not sc.strip.centred
    ref = jr.make_scene(180.0, 0.4, n=48, creases=[(0.3, 90.0), (0.65, 120.0)])
    np.testing.assert_allclose(np.asarray(jr.discretize(sc).phi0), np.asarray(jr.discretize(ref).phi0), atol=1e-15)


@pytest.mark.slow
def test_snap_speed_gradient_in_the_crease_set():
    """d v_s / d(c_1, c_2, Psi_1, Psi_2) through the RATTLE snap against central differences
    (N = 32; measured agreement 1e-5 relative)."""
    base = jr.make_scene(180.0, 0.5, n=32, creases=[(0.3, 90.0), (0.65, 90.0)])

    def vs(p):
        sc = eqx.tree_at(lambda s: (s.strip.creases.positions, s.strip.creases.angles), base, (p[:2], p[2:]))
        return jr.snap_speed(sc, direction="up")

    p0 = jnp.asarray([0.3, 0.65, math.pi / 2, math.pi / 2])
    g = jax.jit(jax.grad(vs))(p0)
    fd = central_difference(lambda p: vs(p)[None], p0, scale=[0.01, 0.01, 0.1, 0.1])[0]
    np.testing.assert_allclose(np.asarray(g), np.asarray(fd), rtol=1e-4)


@pytest.mark.slow
def test_two_crease_study_reaches_targets_and_speeds_up():
    """Two creases snapping at (55, -110) deg: the targets are held to 0.02 deg at the design
    mesh while v_s grows (measured 9.98 -> 28.16 v* in 12 steps), the snap keeps the strip
    0.01 L clear of itself; the independent check at 2N is clean and agrees on v_s to 2 % and
    on the angles to the design mesh's discretization error (measured 0.26 deg at N = 48)."""
    r = paper.two_crease_study(55.0, -110.0, gap=0.5, n=48, n_check=96, steps=8, progress=False)
    assert r.reached and r.snap_clearance >= 0.01
    assert abs(r.alpha_up_deg - 55.0) < 0.02 and abs(r.alpha_down_deg + 110.0) < 0.02
    assert r.v_s > 1.3 * r.v_s_start
    assert all(b["v_s"] > a["v_s"] for a, b in zip(r.history, r.history[1:]))
    assert r.check.result == "successful"
    assert abs(r.check.v_s / r.v_s - 1.0) < 0.02
    assert max(r.check_errors_deg) < 0.5


@pytest.mark.slow
def test_crease_position_study():
    """Psi0 = 120 deg, G/L = 0.5: W(c) = W(L - c) (mirror symmetry), and the widest loop is the
    centred crease (a cusp of W: its up path snaps at a branch point, any other at a fold),
    wider than the best interior position; the finer mesh agrees to 1 deg."""
    r = paper.crease_position_study(120.0, 0.5, n=48, n_check=96, points=9, progress=False)
    assert r.where == "centre" and r.position == 0.5
    assert r.centre_width_deg > r.interior_width_deg > max(w for w in r.widths_deg[:-1] if w is not None) - 1e-9
    assert abs((r.check.alpha_up_deg - r.check.alpha_down_deg) - r.width_deg) < 2.0
    c = r.grid[2]
    f = jax.jit(jr.snap_angles)
    a = f(jr.make_scene(180.0, 0.5, n=48, creases=[(c, 120.0)]))
    b = f(jr.make_scene(180.0, 0.5, n=48, creases=[(1.0 - c, 120.0)]))
    assert float(a.up.alpha_c) == pytest.approx(float(b.up.alpha_c), abs=1e-8)
    assert float(a.down.alpha_c) == pytest.approx(float(b.down.alpha_c), abs=1e-8)
    assert math.degrees(float(a.up.alpha_c - a.down.alpha_c)) == pytest.approx(r.widths_deg[2], abs=1e-6)


def _fake_studies(monkeypatch, calls, reached=True):
    """The crease studies as stand-ins returning real result objects (the CLI's wiring is
    under test here; the studies themselves are tested above)."""
    def two(up, down, **kw):
        calls.append(("two", up, down, kw))
        chk = jd.CreaseCheck(kw["n_check"], up + 0.2, down - 0.3, 20.5, "successful")
        return paper.TwoCreaseResult((up, down), kw["gap"], kw["n"], [0.3, 0.7], [80.0, 95.0], up + 0.01, down,
                                     20.0, 10.0, 0.02, [], reached, kw["tol_deg"], chk, 1.0)

    def position(psi0, gap, **kw):
        calls.append(("position", psi0, gap, kw))
        chk = jd.CreaseCheck(kw["n_check"], 80.0, -81.0, math.nan, "successful")
        return paper.PositionResult(psi0, gap, kw["n"], [0.1, 0.5], [150.0, 161.0], 0.5, 161.0, "centre", 0.13,
                                    159.9, -1128.0, False, 161.0, chk, chk, 1.0)

    monkeypatch.setattr(paper, "two_crease_study", two)
    monkeypatch.setattr(paper, "crease_position_study", position)


def test_cli_crease_studies(monkeypatch, capsys):
    import json

    from jaxrod.cli._main import main

    calls = []
    _fake_studies(monkeypatch, calls)
    assert main(["design", "--study", "two-creases", "--target-alpha-up", "55", "--target-alpha-down", "-110",
                 "--gap", "0.6", "--json"]) == 0
    rec = json.loads(capsys.readouterr().out)
    assert calls[-1] == ("two", 55.0, -110.0, dict(gap=0.6, n=48, n_check=96, tol_deg=0.02, progress=False))
    assert rec["study"] == "two-creases" and rec["result"] == "successful"
    assert rec["positions"] == [0.3, 0.7] and rec["check"]["n"] == 96 and rec["check_errors_deg"] == pytest.approx([0.2, 0.3])
    assert main(["design", "--study", "crease-position", "--n", "24", "--tol", "0.5", "--json"]) == 0
    rec = json.loads(capsys.readouterr().out)
    assert calls[-1] == ("position", 120.0, 0.5, dict(n=24, n_check=48, progress=False))
    assert rec["where"] == "centre" and rec["result"] == "successful" and rec["interior_smooth"] is False
    # the text report, and a design that misses its targets: exit 3
    _fake_studies(monkeypatch, calls, reached=False)
    assert main(["design", "--study", "two-creases", "--target-alpha-up", "55", "--target-alpha-down", "-110"]) == 3
    out = capsys.readouterr().out
    assert "creases at 0.3000, 0.7000 L" in out and "result target_not_reached" in out


@pytest.mark.parametrize("argv, match", [
    (["--study", "two-creases", "--target-alpha-up", "55"], "needs --target-alpha-up and --target-alpha-down"),
    (["--study", "two-creases", "--target-alpha-up", "55", "--target-alpha-down", "-110", "--psi0", "90"], "psi0"),
    (["--study", "crease-position", "--target-alpha-up", "55"], "no angle targets"),
    (["--study", "crease-position", "--psi0", "180"], "psi0"),
    (["--study", "crease-position", "--gap", "1.2"], "gap"),
    (["--study", "crease-position", "--n", "7"], "n: must be an even"),
    (["--study", "crease-position", "--n", "48", "--check-n", "48"], "check-n"),
    (["--study", "crease-position", "--target-speed", "20"], "target-speed"),
    (["--study", "crease-position", "--free-s0"], "free-s0"),
    (["--study", "crease-position", "--s0", "0.03"], "s0"),
    (["--study", "crease-position", "--starts", "4"], "starts"),
    (["--study", "crease-position", "--tol", "nan"], "tol"),
    (["--target-alpha-up", "55", "--gap", "0.5"], "gap: only used with --study"),
    (["--study", "three-creases"], "invalid choice"),
])
def test_cli_crease_studies_bad_input_exits_2(argv, match, monkeypatch, capsys):
    from jaxrod.cli._main import main

    calls = []
    _fake_studies(monkeypatch, calls)
    try:
        code = main(["design", *argv, "--json"])
    except SystemExit as e:  # argparse's own refusals
        code = e.code
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and match in err[-1] and calls == [], err


@pytest.mark.slow  # the real study at N = 48 (about 1 min on 2 cores)
def test_cli_crease_position_study(capsys):
    import json

    from jaxrod.cli._main import main

    assert main(["design", "--study", "crease-position", "--psi0", "120", "--json"]) == 0
    rec = json.loads(capsys.readouterr().out)
    assert rec["where"] == "centre" and rec["position"] == 0.5 and rec["result"] == "successful"
    assert abs(rec["width_deg"] - 161.54) < 0.01 and rec["check"]["n"] == 96


def test_cli_gap_for_a_crease_set(monkeypatch, capsys):
    """`jaxrod design --target-speed V --crease C:PSI0 ...`: the gap of that strip (a stand-in
    for `crease_gap_for_speed`, whose real run is the nightly test below); bad input exits 2."""
    import json

    from jaxrod.cli._main import main

    calls = []

    def fake(v, creases, **kw):
        calls.append((v, creases, kw))
        return jd.CreaseGapResult(v, kw["psi0_deg"], [[c, math.radians(p), 0.02] for c, p in creases], kw["n"],
                                  0.61, v * 1.001, [[0.5, 20.0], [0.61, v * 1.001]], True, kw["tol"], kw["n_check"],
                                  v * 1.004, "successful", True, 1.0)

    monkeypatch.setattr(jd, "crease_gap_for_speed", fake)
    argv = ["design", "--target-speed", "25", "--crease", "0.3:90", "--crease", "0.7:90"]
    assert main(argv + ["--json"]) == 0
    rec = json.loads(capsys.readouterr().out)
    assert calls[-1] == (25.0, [(0.3, 90.0), (0.7, 90.0)], dict(psi0_deg=180.0, s0=0.02, gap=0.5, bounds=(0.05, 0.95),
                                                               n=48, n_check=96, tol=0.01, max_iter=30))
    assert rec["gap"] == 0.61 and rec["result"] == "successful" and rec["check_result"] == "successful"
    assert main(argv + ["--bounds", "gap=0.4:0.9", "--gap", "0.6", "--n", "24"]) == 0
    assert calls[-1][2]["bounds"] == (0.4, 0.9) and calls[-1][2]["gap"] == 0.6 and calls[-1][2]["n_check"] == 48
    assert "G/L = 0.61000" in capsys.readouterr().out
    for extra, match in ((["--free-s0"], "gap only"), (["--starts", "3"], "starts"), (["--bounds", "s0=0.01:0.03"],
                         "gap only"), (["--speed-tol", "2"], "speed-tol"), (["--psi0", "0"], "psi0")):
        n_calls = len(calls)
        assert main(argv + extra) == 2 and len(calls) == n_calls, extra
        assert match in capsys.readouterr().err
    assert main(["design", "--target-alpha-up", "50", "--crease", "0.3:90"]) == 2
    assert "crease: only used with --target-speed" in capsys.readouterr().err


def test_gap_for_speed_bad_input():
    with pytest.raises(ValueError, match="target_speed"):
        jd.crease_gap_for_speed(-1.0, [(0.3, 90.0)])
    with pytest.raises(ValueError, match="bounds"):
        jd.crease_gap_for_speed(20.0, [(0.3, 90.0)], bounds=(0.5, 0.4))
    with pytest.raises(ValueError, match="gap must lie inside"):
        jd.crease_gap_for_speed(20.0, [(0.3, 90.0)], gap=0.99)
    with pytest.raises(ValueError, match="crease 1 position"):
        jd.crease_gap_for_speed(20.0, [(0.3, 90.0), (1.3, 90.0)])
    # the wrong type, named: no TypeError, no "could not convert string to float"
    for kwargs, name in ((dict(target_speed="x"), "target_speed"), (dict(target_speed=[20.0, 30.0]), "target_speed"),
                         (dict(bounds=0.5), "bounds"), (dict(bounds=("a", 0.9)), "bounds"), (dict(gap="a"), "gap")):
        with pytest.raises(ValueError, match=name):
            jd.crease_gap_for_speed(**({"target_speed": 20.0, "creases": [(0.3, 90.0)]} | kwargs))


@pytest.mark.slow  # Newton through the RATTLE snap of a two-crease strip, then the check (~1 min on 2 cores)
def test_gap_for_speed_of_a_crease_set():
    """Two creases of 90 deg at 0.3 L and 0.65 L: the gap whose snap up runs at 9 v*, by
    Newton on v_s(G) with the autodiff derivative; confirmed at N = 96 within 1 %."""
    r = jd.crease_gap_for_speed(9.0, [(0.3, 90.0), (0.65, 90.0)], n=48, n_check=96)
    assert r.reached and r.confirmed, r
    assert abs(r.v_s - 9.0) <= 0.002 * 9.0 and abs(r.check_v_s - 9.0) <= 0.01 * 9.0
    assert 0.05 < r.gap < 0.95 and len(r.history) <= 10


@pytest.mark.slow  # 13 RATTLE snaps with their gradients (~40 s on 2 cores)
def test_gap_for_speed_backs_off_where_the_strip_passes_through_itself():
    """Toward 12 v* Newton steps to small gaps, where this strip's snap passes through itself
    (below G/L = 0.42 at N = 48: v_s NaN): each such step is halved back toward the last gap
    that had a speed, and the answer is the best gap that had one."""
    r = jd.crease_gap_for_speed(12.0, [(0.3, 90.0), (0.65, 90.0)], n=48, n_check=96)
    h = r.history
    assert any(not math.isfinite(v) for _, v in h)
    for k in range(1, len(h)):
        if not math.isfinite(h[k - 1][1]):
            last = [g for g, v in h[:k] if math.isfinite(v)][-1]
            assert h[k][0] == pytest.approx(0.5 * (last + h[k - 1][0]), abs=1e-12)
    finite = [(g, v) for g, v in h if math.isfinite(v)]
    assert (r.gap, r.v_s) == min(finite, key=lambda gv: abs(gv[1] - 12.0))
    assert r.reached == (abs(r.v_s - 12.0) <= r.tol * 12.0)
