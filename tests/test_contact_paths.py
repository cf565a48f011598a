"""Snap paths with self-contact: `snap_angles` on scenes with `jaxrod.Contact` at N = 48,
against the contact-free paths, the brink snap after contact clicks and the CLI's clicks. One compiled
program serves every scene below (they differ only in float leaves); compiling it is most of
this module's time (about a minute on 2 cores, at the suite's XLA settings)."""

import jax
import numpy as np
import pytest

import jaxrod as jr
from jaxrod.branches._landing import JUMP_DISTANCE
from jaxrod.energy import contact as C
from helpers import np_crossings

N = 48


def _scene(psi0, gap, contact=True):
    return jr.make_scene(psi0, gap, n=N, contact=jr.Contact() if contact else None)


@pytest.fixture(scope="module")
def with_contact():
    """`snap_angles` for scenes with contact (one compiled program for all of them)."""
    return jr.snap_angles


def _no_crossing(theta, scene):
    return not np_crossings(np.asarray(C.inextensible_nodes(theta, jr.discretize(scene))))


def test_clear_path_unchanged(with_contact):
    """Psi0 = 60 deg, G/L = 0.3: the up path stays clear of itself (clearance above the
    thickness), and contact changes its snap angle by less than 1e-9 deg."""
    free = jr.snap_angles(_scene(60.0, 0.3, contact=False))
    r = with_contact(_scene(60.0, 0.3))
    assert free.up.result == r.up.result == jr.RESULTS.successful
    assert float(jr.clearance(free.up.theta_before, _scene(60.0, 0.3), min_separation=5)) > 0.01
    assert abs(np.degrees(float(free.up.alpha_c - r.up.alpha_c))) < 1e-9
    assert int(r.up.clicks) == 0


def test_pressed_paths_snap_without_crossing(with_contact):
    """Psi0 = 60 deg, G/L = 0.2: the contact-free paths pass through themselves (flagged);
    with contact both snap, successful, and no reported state crosses. The down path first
    clicks (pressed legs slip: a landing within JUMP_DISTANCE, the fold stays up, every
    such stage ending at a loss of stability before the snap's angle), then snaps with the
    fold going through y = 0 and a jump above JUMP_DISTANCE."""
    sc = _scene(60.0, 0.2)
    free = jr.snap_angles(_scene(60.0, 0.2, contact=False))
    assert jr.RESULTS.self_intersecting in (free.up.result, free.down.result)
    assert int(free.down.clicks) == 0
    r = with_contact(sc)
    for p in (r.up, r.down):
        assert p.result == jr.RESULTS.successful, jr.RESULTS[p.result]
        assert bool(p.snaps)
        assert _no_crossing(p.theta_before, sc) and _no_crossing(p.theta_after, sc)
    down = r.down
    assert int(down.clicks) >= 1 and int(down.stage) >= int(down.clicks)
    assert float(down.fold_height_before) > 0.0 > float(down.fold_height_after)
    assert float(down.jump) > JUMP_DISTANCE
    stages = jax.tree.map(lambda x: x[: int(down.stage)], down.branch)
    assert np.all(np.asarray(stages.stop) == 2)
    for k in range(int(down.stage)):
        assert float(stages.lam[k, int(stages.count[k]) - 1]) > float(down.alpha_c)


def test_flat_strip_pressed_snaps_symmetrically(with_contact):
    """The flat strip (Psi0 = 180 deg) at G/L = 0.1 with contact: both paths successful,
    mirror images of each other (alpha_c_down = -alpha_c_up to 1e-6 rad)."""
    flat = with_contact(_scene(180.0, 0.1))
    assert flat.up.result == flat.down.result == jr.RESULTS.successful
    assert float(flat.up.alpha_c) == pytest.approx(-float(flat.down.alpha_c), abs=1e-6)


@pytest.mark.slow  # 28 s on 2 cores (a contact dynamics program); the clicks themselves are in CI
def test_brink_snap_after_contact_clicks(with_contact):
    """Psi0 = 60 deg, G/L = 0.2, snap down with contact: the path clicks before it snaps,
    and the brink run from the snap's critical state (`jr.snap_dynamics`, adaptive) snaps:
    the fold goes through y = 0 within 1 T at a speed above 5 v*, and no frame of the run
    passes through itself."""
    sc = _scene(60.0, 0.2)
    r = with_contact(sc)
    assert r.down.result == jr.RESULTS.successful and int(r.down.clicks) >= 1
    start, tr = jr.snap_dynamics(sc, "down", snap=r, t1=1.0, n_frames=16)
    assert bool(start.ok)
    assert tr.result == jr.RESULTS.successful, jr.RESULTS[tr.result]
    assert bool(tr.snapped) and float(tr.v_s) > 5.0
    for x in np.asarray(tr.positions):
        assert not np_crossings(x[np.all(np.isfinite(x), -1)])


@pytest.mark.slow  # 26 s on 2 cores (a CLI program of its own): the clicks themselves are in CI
def test_cli_reports_contact_clicks(with_contact, capsys):
    """`jaxrod snap-angles` with contact prints each path's clicks before its snap (the
    same numbers as the API's `SnapPath.clicks`); without contact it prints none."""
    import json

    from jaxrod.cli import main

    args = ["snap-angles", "--psi0", "60", "--gap", "0.2", "--n", str(N), "--no-extrapolate", "--json"]
    r = with_contact(_scene(60.0, 0.2))
    for extra, contact in ((["--contact-thickness", "0.01"], True), (["--no-contact"], False)):
        old = jax.config.jax_enable_x64
        try:
            assert main(args + extra) in (0, 3)
        finally:
            jax.config.update("jax_enable_x64", old)
        rec = json.loads(capsys.readouterr().out)
        assert rec["contact"] is contact
        if contact:
            assert rec["result_down"] == "successful"
            assert rec["clicks_down"] == int(r.down.clicks) >= 1 and rec["clicks_up"] == int(r.up.clicks)
            assert rec["alpha_c_down_deg"] == pytest.approx(np.degrees(float(r.down.alpha_c)), abs=1e-9)
        else:
            assert "clicks_down" not in rec


@pytest.mark.slow  # 11 s of contact snaps; CI checks the flag on equilibria (test_self_contact.py)
def test_contact_too_thin_for_the_mesh_is_flagged(with_contact):
    """Psi0 = 180 deg, G/L = 0.1 at N = 48 (segments of 0.021 L): with the default thickness (0.01 L,
    2.1 thicknesses a segment) both paths are successful (`test_flat_strip_pressed_snaps_symmetrically`);
    with 0.008 L (2.6 a segment, past `CONTACT_RESOLUTION`) the pressed critical states are flagged
    `contact_underresolved`."""
    from jaxrod.energy.contact import CONTACT_RESOLUTION

    assert 1.0 / N < CONTACT_RESOLUTION * 0.01 and 1.0 / N > CONTACT_RESOLUTION * 0.008
    thin = with_contact(jr.make_scene(180.0, 0.1, n=N, contact=jr.Contact(thickness=0.008)))
    assert thin.up.result == thin.down.result == jr.RESULTS.contact_underresolved
    assert np.isfinite(float(thin.up.alpha_c))  # the values are kept, flagged
