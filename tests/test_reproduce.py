"""`jaxrod reproduce`'s dynamics sections on a small mesh (N = 24): numbers present and finite,
the physics they must obey, and a resumed run that recomputes nothing. The whole quick report
is checked end to end (slow) in test_design_cli.py."""

import json
import math

import pytest

import jaxrod as jr
from jaxrod.paper import reproduce as rp

CFG = dict(n=24, solver="rattle", psis=(30.0, 90.0, 180.0), gaps=(0.3, 0.5))  # the product's integrator


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp("reproduce")
    cache = rp._Cache(str(out / "cache.json"))
    secs = {f.__name__: f(cache, str(out), False, CFG) for f in
            (rp.section_snap_dynamics, rp.section_speed_plane, rp.section_folded_unfolded, rp.section_asymmetric)}
    return out, secs


def test_speed_plane_points_and_fit(report):
    _, secs = report
    _, _, rows, data = secs["section_speed_plane"]
    pts = data["points"]
    assert len(pts) == len(CFG["psis"]) * len(CFG["gaps"])
    snapping = [r for r in pts.values() if r["snaps"]]
    assert len(snapping) >= 4
    for r in snapping:
        # RATTLE's energy error is bounded, O(dt^2): at N = 24 its step is the 2e-4 T cap and the
        # measured error is 0.9e-3 here, 1.1e-3 in jaxrod.dynamics._simulate (DT_CAP); a wrong force
        # or a broken constraint gives O(1) (benchmarks/results/dynamics.md: 6.8e-5 at N = 100)
        assert math.isfinite(r["v_s"]) and r["v_s"] > 0 and r["energy_drift"] < 3e-3, (r["energy_drift"], r)
    # the fit: speed falls with the gap and with the fold angle (the paper's a, b > 0)
    fit = data["fit"]
    assert fit["a"] > 0 and fit["b"] > 0 and fit["v_m"] > 0, fit
    assert [r[2].split()[0] for r in rows] == [f"{fit[k]:.2f}" for k in ("v_m", "a", "b")]
    # at each fold angle v_s decreases with the gap
    for p in CFG["psis"]:
        v = [pts[f"{p:g}/{g:g}"]["v_s"] for g in CFG["gaps"] if pts[f"{p:g}/{g:g}"]["snaps"]]
        assert all(a > b for a, b in zip(v, v[1:])), (p, v)


def test_one_snap_energy_and_speed(report):
    _, secs = report
    _, _, rows, data = secs["section_snap_dynamics"]
    rec = data["record"]
    # clamps held, no dissipation: the kinetic energy cannot exceed the bending energy released
    ratio = rec["kinetic_energy_peak"] / rec["bending_energy_before"]
    assert 0.5 < ratio < 1.0, rec
    assert float(rows[0][2]) == pytest.approx(ratio, abs=0.006)
    fast = data["fastest"]
    assert 0.0 <= fast["s_fastest_25"] <= 1.0 and abs(fast["s_fastest_peak"] - 0.5) < 0.1, fast


def test_folded_faster_than_flat_and_units(report):
    _, secs = report
    _, _, rows, data = secs["section_folded_unfolded"]
    assert data["ratio"] == pytest.approx(data["folded"]["v_s"] / data["flat"]["v_s"])
    assert data["ratio"] > 1.5, data["ratio"]
    # v* = (t / L) sqrt(E / (12 rho)), whatever the width
    for t, v in rp.pet_speed_gauges().items():
        e, rho, length = rp._PET["youngs_modulus"], rp._PET["density"], rp._PET["length"]
        assert v == pytest.approx(t / length * math.sqrt(e / (12 * rho)), rel=1e-12)
    lo, hi = (float(x) for x in rows[1][2].replace(" m/s", "").split(" - "))
    vs = rp.pet_speed_gauges()
    assert lo == pytest.approx(data["folded"]["v_s"] * vs[80e-6], abs=0.06)
    assert hi == pytest.approx(data["folded"]["v_s"] * vs[250e-6], abs=0.06)


def test_asymmetric_near_end_moves_first(report):
    out, secs = report
    _, _, rows, data = secs["section_asymmetric"]
    turn, jump = data["turn"], data["snap"]
    assert turn["disp_near"] > 3 * turn["disp_far"], turn  # the far end stays put while the clamp turns
    assert 0 < data["alpha_snap_deg"] < 180 and math.isfinite(data["record"]["v_s"])
    assert all(math.isfinite(jump[k]) for k in ("disp_near", "disp_far", "speed_near", "speed_far"))
    assert (out / "fig4_asymmetric" / "chrono.png").stat().st_size > 1000


def test_resume_recomputes_nothing(report, monkeypatch):
    out, secs = report

    def boom(*a, **k):
        raise AssertionError("recomputed a cached point")

    monkeypatch.setattr(jr, "snap_dynamics", boom)
    monkeypatch.setattr(jr, "snap_angles", boom)
    cache = rp._Cache(str(out / "cache.json"))
    for f in (rp.section_snap_dynamics, rp.section_speed_plane, rp.section_folded_unfolded, rp.section_asymmetric):
        again = f(cache, str(out), False, CFG)
        assert again[2] == secs[f.__name__][2], f.__name__
    assert json.loads((out / "cache.json").read_text()) == cache.data


def test_cache_of_other_code_is_dropped(tmp_path, monkeypatch):
    """A cache written by other code (another source digest, or none) is not reused: its
    points and its trajectories are dropped; one written by this code is kept."""
    (tmp_path / "traj").mkdir()
    (tmp_path / "traj" / "snap_30_0.5_60_rattle.npz").write_bytes(b"old")
    (tmp_path / "cache.json").write_text(json.dumps({"snap/30/0.8/60": {"alpha_up": 1.0}}))
    cache = rp._Cache(str(tmp_path / "cache.json"))
    assert "snap/30/0.8/60" not in cache.data and not list((tmp_path / "traj").iterdir())
    assert cache.get("k", lambda: 2.0) == 2.0
    again = rp._Cache(str(tmp_path / "cache.json"))
    assert again.data["k"] == 2.0  # same code: kept
    monkeypatch.setattr(rp._Cache, "SOURCE_KEY", "__other__")
    assert "k" not in rp._Cache(str(tmp_path / "cache.json")).data


def test_loops_figure_2ab(tmp_path):
    cache = rp._Cache(str(tmp_path / "cache.json"))
    title, _, rows, data = rp.section_loops(cache, 24, str(tmp_path), False)
    a = data["60/0.5"]
    assert a["up"]["snaps"] and a["down"]["snaps"] and a["up"]["alpha_c"] > 0 > a["down"]["alpha_c"]
    ju, jd = abs(a["up"]["after"] - a["up"]["before"]), abs(a["down"]["after"] - a["down"]["before"])
    assert a["up"]["before"] < 0 < a["up"]["after"] and a["down"]["after"] < 0 < a["down"]["before"]
    assert jd < ju and rows[0][3] == "snap down smaller"  # the paper: the snap-down jump is the smaller one
    b = data["30/0.8"]
    assert not b["up"]["snaps"] and not b["down"]["snaps"] and rows[1][2].startswith("smooth")
    stages = cache.data["loop/60/0.5/24"]["up"]["stages"]
    assert stages and all(len(s["alpha_deg"]) == len(s["fold_height"]) > 2 for s in stages)
    assert (tmp_path / "fig2ab_loops.png").stat().st_size > 1000
