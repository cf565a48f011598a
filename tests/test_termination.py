"""Termination gap G*(Psi0): input checks, the flat strip, the CLI; slow: G* for
Psi0 = 30, 60, 90, 120 deg cross-checked by direct snap_angles calls just below and above."""

from __future__ import annotations

import json
import math

import jax
import numpy as np
import pytest

import jaxrod as jr
from jaxrod.cli._main import main
from jaxrod.results import result_name


jax.config.update("jax_enable_x64", True)


@pytest.mark.parametrize("kw,name", [
    (dict(psi0_deg=0.0), "psi0"), (dict(psi0_deg=181.0), "psi0"), (dict(psi0_deg=float("nan")), "psi0"),
    (dict(psi0_deg=60.0, s0=0.0), "s0"), (dict(psi0_deg=60.0, n=7), "n"), (dict(psi0_deg=60.0, tol=-1.0), "tol"),
])
def test_bad_input_names_parameter(kw, name):
    with pytest.raises(ValueError, match=name):
        jr.termination_gap(**kw)


def test_flat_strip_never_stops():
    """Psi0 = 180 deg: `termination_gap` answers without a scan that both paths snap up to
    G = L (G* = 1, reason "flat_strip_never_stops", kind "branch_point"; no bracket, no
    alpha_c at G*). Checked here at large gaps by direct `snap_angles` calls (N = 40): both
    paths snap, at a branch point, into the other state with a jump larger than twice the
    critical fold height (the snap does not fade as G -> L); symmetric, alpha_c_down =
    -alpha_c_up, because the mirror y -> -y (theta -> -theta, alpha -> -alpha) maps the
    flat strip's snap-up path onto its snap-down path; and alpha_c / sqrt(1 - G/L) -> 2 rad,
    the shallow-arch limit of the linear theory (derived in tests/test_snap_physics.py),
    approached from above with a deviation O(1 - G/L)."""
    from jaxrod.branches._snap import KIND_NAMES

    r = jr.termination_gap(180.0)
    assert r.gap_up == 1.0 and r.gap_down == 1.0
    assert r.reason_up == r.reason_down == "flat_strip_never_stops"
    assert r.gap_criterion_up == r.gap_criterion_down == 1.0 and r.evaluations == 0
    assert all(math.isnan(x) for x in (*r.bracket_up, *r.bracket_down, r.alpha_c_up, r.alpha_c_down))
    d = r.to_dict()
    assert d["bracket_up"] == [None, None] and json.loads(json.dumps(d))["gap_down"] == 1.0

    f = jax.jit(jr.snap_angles)
    ratios = []
    gaps = (0.8, 0.9, 0.95)
    for gap in gaps:
        s = f(jr.make_scene(180.0, gap, 0.0, n=40))
        for name, path in (("up", s.up), ("down", s.down)):
            assert path.result == jr.RESULTS.successful and path.start_result == jr.RESULTS.successful, (gap, name)
            assert bool(path.snaps), (gap, name)
            assert KIND_NAMES[int(path.kind)] == getattr(r, f"kind_{name}") == "branch_point", (gap, name)
            before, after = float(path.fold_height_before), float(path.fold_height_after)
            assert before * after < 0 and abs(after - before) > 2.0 * abs(before), (gap, name, before, after)
        up, down = float(s.up.alpha_c), float(s.down.alpha_c)
        assert up > 0 and abs(up + down) < 1e-9 * up, (gap, up, down)
        ratios.append(up / math.sqrt(1.0 - gap))
    # measured 2.0259, 2.0065, 1.9969: the deviation is linear in 1 - G/L (its steps halve
    # with 1 - G/L: 0.2 -> 0.1 -> 0.05) and its linear extrapolation to G = L is 2 up to the
    # N = 40 discretization (alpha_c ~1 % low there: ~1000 deg / N^2 in
    # benchmarks/results/convergence_alpha_c.md; the extrapolation gives 1.987)
    assert all(abs(q - 2.0) < 0.03 for q in ratios), ratios
    steps = -np.diff(ratios)
    assert np.all(steps > 0) and 1.5 < steps[0] / steps[1] < 2.6, ratios
    assert abs(ratios[-1] - steps[-1] - 2.0) < 0.025, ratios


@pytest.mark.parametrize("argv", [
    ["termination-gap", "--psi0", "0"], ["termination-gap", "--psi0", "nan"], ["termination-gap", "--s0", "-1"],
    ["termination-gap", "--n", "9"], ["termination-gap", "--tol", "0"], ["termination-gap", "--psi0", "abc"],
])
def test_cli_bad_input(argv, capsys):
    assert main(argv) == 2
    out = capsys.readouterr()
    assert out.out == "" and len(out.err.strip().splitlines()) == 1 and "Traceback" not in out.err


def test_reported_gap_is_the_exact_end_where_located():
    """`gap_*` is the exact end of the path where it was found (the cusp by continuation,
    else the direct cusp solve; the start state's fold in G), the bisection value otherwise;
    an end outside the bracket's reach is not taken."""
    from jaxrod.branches._termination import _exact_end

    codes = []

    def res(reason, **kw):
        r = dict(gap=0.6375, bracket=(0.63749, 0.63751), reason=reason, **kw)
        _exact_end(r)
        codes.append((reason, r["gap_source"], result_name(r["result"])))
        return r["gap"], r["gap_source"], r["gap_criterion"]

    assert res("cusp", cusp=0.63852, curve_cusp_gap=0.63851, curve_end_reason="turn") == (
        0.63851, "continuation_cusp", 0.6375)
    # the continuation did not reach the turn: the cusp solved from the bisection's fold
    assert res("cusp", cusp=0.63852, curve_cusp_gap=0.63851, curve_end_reason="max_points") == (
        0.63852, "cusp", 0.6375)
    assert res("cusp", cusp=0.5) == (0.6375, "bisection", 0.6375)  # below the bracket: another point
    assert res("cusp", cusp=float("nan")) == (0.6375, "bisection", 0.6375)
    assert res("start_state_lost", state_fold=0.637504) == (0.637504, "state_fold", 0.6375)
    assert res("start_state_lost") == (0.6375, "bisection", 0.6375)
    assert res("snap_vanishes", cusp=0.63852) == (0.6375, "bisection", 0.6375)
    assert res("never_snaps")[1] == "none"
    # an end that is a cusp or a lost start state but was not solved is flagged, not successful
    for reason, source, code in codes:
        unsolved = reason in ("cusp", "start_state_lost") and source == "bisection"
        assert code == ("end_not_located" if unsolved else "successful"), (reason, source, code)
    assert [c for *_, c in codes].count("end_not_located") == 3


def _fake_scan(monkeypatch, up, down):
    """`termination_gap` over a stand-in snap criterion: `up(g)` / `down(g)` give (snaps,
    result name) at gap g; the path's other outputs are fixed numbers."""
    from jaxrod.branches import _termination

    def fake(base, psi0, gap):
        g = float(gap)

        def one(f):
            snaps, name = f(g)
            return dict(snaps=snaps, alpha=0.5, kind=2 if snaps else 0, jump=0.5, theta=np.zeros(3),
                        force=np.zeros(2), mode=np.zeros(3), result=int(getattr(jr.RESULTS, name)._value))

        return dict(up=one(up), down=one(down), has_up=True, has_down=True)

    monkeypatch.setattr(_termination, "_snap_at", fake)


def test_termination_codes_follow_the_evaluations(monkeypatch):
    """Each path's `result` says whether its G* can be trusted: `no_snap` where no gap snaps,
    `termination_beyond_grid` where the largest gap still snaps, the deciding evaluation's
    code where "snaps / does not snap" is unknown there (a continuation cut short just above
    G*, or anywhere above it), `successful` for a branch point's end found to `tol`; the
    CLI prints the codes and exits 3 on any but `successful` and `no_snap`."""
    ok = lambda s: (lambda g: (s(g), "successful"))  # noqa: E731
    _fake_scan(monkeypatch, ok(lambda g: False), ok(lambda g: True))
    r = jr.termination_gap(60.0, tol=1e-3)
    assert (result_name(r.result_up), result_name(r.result_down)) == ("no_snap", "termination_beyond_grid")
    assert math.isnan(r.gap_up) and r.gap_down == 1.0 and r.result == jr.RESULTS.termination_beyond_grid
    # a branch-point end (kind 2, large jump: "snap_vanishes") located by bisection: trusted
    _fake_scan(monkeypatch, ok(lambda g: g < 0.62), ok(lambda g: g < 0.3))
    r = jr.termination_gap(60.0, tol=1e-3)
    assert r.reason_up == "snap_vanishes" and abs(r.gap_up - 0.62) < 1e-3 and r.result == jr.RESULTS.successful
    assert r.to_dict()["result_up"] == "successful"
    # the gap just above G* (its "no snap") was cut short: G* is not known
    _fake_scan(monkeypatch, lambda g: (g < 0.62, "successful" if g < 0.62 or g > 0.7 else "continuation_incomplete"),
               ok(lambda g: g < 0.3))
    r = jr.termination_gap(60.0, tol=1e-3)
    assert result_name(r.result_up) == "continuation_incomplete" and r.result_down == jr.RESULTS.successful
    # ... or a gap far above it: the last snap may lie there
    _fake_scan(monkeypatch, lambda g: (g < 0.62, "landing_failed" if g == 0.9 else "successful"),
               ok(lambda g: g < 0.3))
    assert result_name(jr.termination_gap(60.0, tol=1e-3).result_up) == "landing_failed"
    # a path that never snaps, with states through themselves at the smallest gaps, still never snaps
    _fake_scan(monkeypatch, lambda g: (False, "self_intersecting" if g < 0.15 else "successful"),
               ok(lambda g: g < 0.3))
    assert result_name(jr.termination_gap(60.0, tol=1e-3).result_up) == "no_snap"


def test_contact_reaches_every_evaluation(monkeypatch):
    """`termination_gap(..., contact=...)` evaluates every gap of its scan and bisection on a
    scene with that contact model (stand-in criterion; the search with the real contact
    program is the nightly `test_termination_gap_with_contact_unchanged`), and without it on
    contact-free scenes."""
    from jaxrod.branches import _termination

    seen = []

    def fake(base, psi0, gap):
        sc = _termination._with_fold(base, psi0, gap)
        seen.append(None if sc.contact is None else (float(sc.contact.thickness), float(sc.contact.stiffness)))
        snaps = float(gap) < 0.62
        one = dict(snaps=snaps, alpha=0.5, kind=2 if snaps else 0, jump=0.5, theta=np.zeros(3), force=np.zeros(2),
                   mode=np.zeros(3), result=int(jr.RESULTS.successful._value))
        return dict(up=one, down=one, has_up=True, has_down=True)

    monkeypatch.setattr(_termination, "_snap_at", fake)
    r = jr.termination_gap(60.0, tol=1e-3, contact=jr.Contact(thickness=0.02, stiffness=3e4))
    assert abs(r.gap_up - 0.62) < 1e-3 and len(seen) > 10
    assert set(seen) == {(0.02, 3e4)}
    seen.clear()
    jr.termination_gap(60.0, tol=1e-3, creases=[0.3, 0.7], contact=jr.Contact())
    assert set(seen) == {(0.01, 1e5)}
    seen.clear()
    jr.termination_gap(60.0, tol=1e-3)
    assert set(seen) == {None}


def test_cli_prints_termination_codes(monkeypatch, capsys):
    ok = lambda s: (lambda g: (s(g), "successful"))  # noqa: E731
    _fake_scan(monkeypatch, ok(lambda g: False), ok(lambda g: g < 0.3))
    assert main(["termination-gap", "--psi0", "60", "--tol", "1e-3", "--json"]) == 0
    rec = json.loads(capsys.readouterr().out)
    assert rec["result_up"] == "no_snap" and rec["result_down"] == "successful"
    _fake_scan(monkeypatch, lambda g: (g < 0.62, "successful" if g < 0.62 or g > 0.7 else "continuation_incomplete"),
               ok(lambda g: g < 0.3))
    assert main(["termination-gap", "--psi0", "60", "--tol", "1e-3"]) == 3
    out = capsys.readouterr()
    assert "result continuation_incomplete" in out.out
    assert out.err.strip() == "jaxrod termination-gap: up: continuation_incomplete (see jaxrod.RESULTS)"


def test_cli_flat_json(capsys):
    assert main(["termination-gap", "--psi0", "180", "--json"]) == 0
    rec = json.loads(capsys.readouterr().out)
    assert rec["gap_up"] == 1.0 and rec["gap_down"] == 1.0 and rec["reason_up"] == "flat_strip_never_stops"
    assert rec["result_up"] == rec["result_down"] == "successful"


@pytest.fixture(scope="module")
def snap():
    f = jax.jit(jr.snap_angles)
    return lambda psi0, gap: f(jr.make_scene(psi0, gap, 0.0))


@pytest.mark.slow
def test_flat_strip_snaps_near_full_gap(snap):
    r = snap(180.0, 0.95)
    for path in (r.up, r.down):
        assert bool(path.snaps) and int(path.kind) == 2
        # lands in the other state (fold height changes sign) with a jump larger than the
        # critical fold height itself: the snap does not shrink relative to the buckle
        before, after = float(path.fold_height_before), float(path.fold_height_after)
        assert before * after < 0 and abs(after - before) > 2.0 * abs(before)


@pytest.mark.slow
def test_termination_gaps_cross_checked(snap):
    """G* for Psi0 = 30, 60, 90, 120 deg to 1e-4 in G/L: by the snap criterion each path snaps
    at G* - 1e-4 and does not at G* + 1e-4 (direct snap_angles calls, not the search's own
    evaluations); the reported G* is the exact end (the cusp reached by continuation, or the
    start state's fold in G), within 1e-5 of the criterion's where the start state is lost and
    above it, by less than 1e-3, at a cusp: the criterion's paths stop snapping where the
    fold pair becomes narrower than a continuation step, 8e-5 to 7e-4 below the cusp
    (benchmarks/results/termination.md); G* grows with Psi0 (the paper);
    Psi0 = 30 deg ends below G/L = 0.8 (no snap there, Fig. 2b)."""
    out = {}
    for psi in (30.0, 60.0, 90.0, 120.0):
        r = jr.termination_gap(psi, tol=1e-5)
        out[psi] = r
        for name in ("up", "down"):
            g = getattr(r, f"gap_criterion_{name}")
            lo, hi = getattr(r, f"bracket_{name}")
            assert 0.0 < g < 1.0 and hi - lo <= 1e-5 and lo <= g <= hi
            below, above = snap(psi, g - 1e-4), snap(psi, g + 1e-4)
            assert bool(getattr(below, name).snaps), (psi, name, g)
            assert not bool(getattr(above, name).snaps), (psi, name, g)
            exact, src = getattr(r, f"gap_{name}"), getattr(r, f"gap_source_{name}")
            if getattr(r, f"reason_{name}") == "start_state_lost":
                assert src == "state_fold" and abs(exact - g) <= 1e-5, (psi, name, exact, g)
            elif getattr(r, f"reason_{name}") == "cusp":
                assert src == "continuation_cusp", (psi, name, src)
                assert exact == getattr(r, f"curve_cusp_gap_{name}")
                assert abs(exact - getattr(r, f"cusp_gap_{name}")) < 1e-8
                assert 0.0 < exact - g < 1e-3, (psi, name, exact, g)
            else:
                assert src == "bisection" and exact == g
        # at every one of these fold angles the snap-down path ends where its fold pair meets, at
        # a cusp (every fold is a snap however small its jump; benchmarks/results/termination.md)
        assert (r.reason_down, r.kind_down) == ("cusp", "fold"), (psi, r.reason_down, r.kind_down)
    for name in ("up", "down"):
        gs = [getattr(out[p], f"gap_{name}") for p in (30.0, 60.0, 90.0, 120.0)]
        assert np.all(np.diff(gs) > 0), (name, gs)
    assert out[30.0].gap_up < 0.8 and out[30.0].gap_down < 0.8
    # Psi0 = 30 deg: the snap-up path ends where the down state at alpha = 0 stops existing
    # (a fold in G of the alpha = 0 branch at G/L ~ 0.645)
    assert out[30.0].reason_up == "start_state_lost" and abs(out[30.0].gap_up - 0.645) < 2e-3
    assert all(math.isfinite(out[p].alpha_c_up) for p in out)


@pytest.mark.slow
def test_cusp_gap_and_derivative_fd(snap):
    """The snap-down path of Psi0 = 60 deg ends at a cusp of its fold pair: the cusp system
    converges (residual, the cubic coefficient vanishes), lies above the snap criterion's G*,
    and dG_c/dPsi0 by implicit differentiation matches central differences that re-solve it."""
    import equinox as eqx
    import jax.numpy as jnp

    from helpers import central_difference

    g0 = 0.7399
    p = snap(60.0, g0).down
    assert int(p.kind) == 1
    base = jr.make_scene(60.0, g0, 0.0)

    @jax.jit
    def gc(x):
        sc = eqx.tree_at(lambda s: s.strip.psi0, base, x[0])
        return jr.cusp_point(sc, p.theta_before, p.force_before, p.alpha_c, p.mode).gap[None]

    x0 = np.array([math.radians(60.0)])
    cp = jr.cusp_point(base, p.theta_before, p.force_before, p.alpha_c, p.mode)
    assert cp.result == jr.RESULTS.successful and float(cp.residual) < 1e-10
    r = jr.termination_gap(60.0, tol=1e-4)
    assert r.gap_criterion_down <= float(cp.gap) < 1.0 and abs(r.cusp_gap_down - float(cp.gap)) < 1e-8
    assert r.gap_source_down == "continuation_cusp" and abs(r.gap_down - float(cp.gap)) < 1e-8
    # the same end by two-parameter continuation of the fold in (G, alpha) from the grid
    assert r.curve_end_reason_down == "turn" and r.curve_points_down >= 3
    assert abs(r.curve_end_gap_down - float(cp.gap)) < 1e-4
    assert abs(r.curve_cusp_gap_down - float(cp.gap)) < 1e-8
    J = jax.jacfwd(gc)(jnp.asarray(x0))
    fd = central_difference(gc, x0)
    assert float(J[0, 0]) > 0  # the cusp moves to larger gaps for wider folds (the paper)
    np.testing.assert_allclose(np.asarray(J), np.asarray(fd), rtol=1e-6)
    np.testing.assert_allclose(r.dcusp_gap_dpsi0_down, float(J[0, 0]), rtol=1e-6)


def test_start_state_fold_in_the_gap_and_derivative_fd():
    """Psi0 = 30 deg: the down state at alpha = 0 ends at a fold in G (the snap-up path's
    'start_state_lost' end). The Moore-Spence system with the gap as parameter converges from
    the state just below it to a G_f where the state exists just below and not just above,
    and dG_f/dPsi0 (implicit differentiation) matches central differences that re-solve it."""
    import jax.numpy as jnp

    from jaxrod.branches._termination import _state_fold_gap

    n = 40
    base = jr.make_scene(30.0, 0.5, 0.0, n=n)
    lo = 0.62  # the down state exists here (G*_up ~ 0.645 at N = 100)
    gfs, oks, dgs = _state_fold_gap(base, jnp.asarray(math.radians(30.0)), jnp.asarray(lo), -1.0)
    gf, ok, dg = float(gfs[0]), bool(oks[0]), float(dgs[0])  # the fold (index 0; 1 is the branch point)
    assert ok and lo < gf < 0.7, gf
    down = lambda g: jr.initial_state(jr.make_scene(30.0, g, 0.0, n=n), "down").result  # noqa: E731
    assert down(gf - 1e-4) == jr.RESULTS.successful
    assert down(gf + 1e-4) == jr.RESULTS.state_not_found
    h = 1e-4
    fd = [float(_state_fold_gap(base, jnp.asarray(math.radians(30.0) + s * h), jnp.asarray(lo), -1.0)[0][0])
          for s in (1.0, -1.0)]
    fd = (fd[0] - fd[1]) / (2 * h)
    assert dg > 0  # wider folds keep their down state to larger gaps (as G*_up(Psi0) rises)
    np.testing.assert_allclose(dg, fd, rtol=1e-5)


@pytest.mark.slow  # ~11 min on 2 cores: the termination search compiled and run with self-contact
def test_termination_gap_with_contact_unchanged():
    """With self-contact modelled (`contact=jr.Contact()`) the termination gaps of Psi0 = 60
    deg at N = 48 equal the contact-free ones: the strip stays clear of itself at the gaps
    where its snaps end, so contact changes no evaluation the search makes there."""
    grid = (0.3, 0.5, 0.7, 0.9)
    free = jr.termination_gap(60.0, n=48, grid=grid, tol=1e-4)
    with_contact = jr.termination_gap(60.0, n=48, grid=grid, tol=1e-4, contact=jr.Contact())
    assert free.result_up == with_contact.result_up == jr.RESULTS.successful
    assert free.result_down == with_contact.result_down == jr.RESULTS.successful
    for name in ("up", "down"):
        a, b = getattr(free, f"gap_{name}"), getattr(with_contact, f"gap_{name}")
        assert np.isfinite(a) and b == pytest.approx(a, abs=1e-9), name
