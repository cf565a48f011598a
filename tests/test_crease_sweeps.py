"""Speed planes of a crease layout: a crease of each grid fold angle at each given position.

The strip of a layout point (`jaxrod.model.layout_strip`) is the strip `make_scene` builds
from the same creases; the CLI's point-by-point speed plane passes the layout to the
physics, keeps it among a row's settings (a rerun with another layout reuses nothing) and
writes each crease's speed; the sharded `jaxrod.speed_plane` gives, per point, the numbers of
`jaxrod.snap_speed_run` on that strip (nightly: it compiles the vmapped snap).
"""

from __future__ import annotations

import csv
import json
import types

import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr


def test_layout_strip_is_the_strip_make_scene_builds():
    layout = jr.model.crease_layout([0.7, 0.3], 75.0)
    assert layout == (0.3, 0.7)
    a = jr.model.layout_strip(jnp.radians(75.0), 0.02, layout)
    b = jr.make_scene(180.0, 0.5, s0=0.02, creases=[(0.3, 75.0), (0.7, 75.0)]).strip
    s = jnp.linspace(0.0, 1.0, 401)
    np.testing.assert_allclose(a.natural_angle(s), b.natural_angle(s), rtol=0, atol=1e-15)
    for x, y in zip(a.crease_list(), b.crease_list()):
        np.testing.assert_allclose(x, y, rtol=1e-15)
    assert not a.centred and len(a.crease_list()[0]) == 2
    # no layout: the centred crease
    c = jr.model.layout_strip(jnp.radians(75.0), 0.02)
    np.testing.assert_allclose(c.natural_angle(s), jr.Strip(psi0=jnp.radians(75.0), s0=0.02).natural_angle(s),
                               atol=0)


def _fake(monkeypatch, calls):
    """Stand-ins for the physics: the CLI's bookkeeping is under test. v_s per crease
    depends on the crease's position and angle, so a wrong layout shows in the numbers."""
    def snap_angles(scene):
        cr = zip(*(np.asarray(x) for x in scene.strip.crease_list()))
        calls.append((float(scene.clamps.gap),
                      tuple((round(float(c), 9), round(float(np.degrees(a)), 9)) for c, a, _ in cr)))
        path = types.SimpleNamespace(snaps=True, result=jr.RESULTS.successful)
        return types.SimpleNamespace(up=path, down=path)

    def snap_dynamics(scene, direction, **kw):
        cr = list(zip(*(np.asarray(x) for x in scene.strip.crease_list())))
        g = float(scene.clamps.gap)
        start = types.SimpleNamespace(alpha_c=0.5, bending_before=1.0)
        tr = types.SimpleNamespace(v_s=10.0 + g, t_cross=0.1, kinetic_peak=1.0, num_steps=100, snapped=True,
                                   result=jr.RESULTS.successful,
                                   v_s_creases=np.array([c + np.degrees(a) / 100 for c, a, _ in cr]))
        return start, tr

    monkeypatch.setattr(jr, "snap_angles", snap_angles)
    monkeypatch.setattr(jr, "snap_dynamics", snap_dynamics)


def test_cli_speed_plane_of_a_layout(tmp_path, monkeypatch, capsys):
    from jaxrod.cli._main import main

    calls = []
    _fake(monkeypatch, calls)
    out = tmp_path / "sp"
    argv = ["speed-plane", "--psi0", "60,120", "--gaps", "0.5", "--n", "16", "--out", str(out)]
    assert main(argv + ["--creases-at", "0.7,0.3"]) == 0
    assert calls == [(0.5, ((0.3, 60.0), (0.7, 60.0))), (0.5, ((0.3, 120.0), (0.7, 120.0)))]
    rec = json.loads(capsys.readouterr().out)
    assert rec["creases_at"] == [0.3, 0.7] and rec["points"] == 2
    with open(out / "speed_plane.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["creases_at"] for r in rows] == ["0.3;0.7"] * 2
    assert [[float(v) for v in r["v_s_creases"].split(";")] for r in rows] == [[0.9, 1.3], [1.5, 1.9]]
    # the same layout again: nothing recomputed; the centred crease: every point computed,
    # the layout's rows kept
    calls.clear()
    assert main(argv + ["--creases-at", "0.3,0.7"]) == 0 and calls == []
    assert main(argv) == 0 and [c[1] for c in calls] == [((0.5, 60.0),), ((0.5, 120.0),)]
    with open(out / "speed_plane.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["creases_at"] for r in rows] == ["0.3;0.7", "0.3;0.7", "", ""]
    assert [r["v_s_creases"] for r in rows[2:]] == ["", ""]


@pytest.mark.parametrize("value, match", [("0.3,1.2", "crease 1 position"), ("0.5,0.51", "overlap"),
                                          ("a,b", "creases-at")])
def test_cli_speed_plane_bad_layout_exits_2(value, match, tmp_path, capsys):
    from jaxrod.cli._main import main

    code = main(["speed-plane", "--psi0", "90", "--gaps", "0.5", "--creases-at", value, "--out", str(tmp_path)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and match in err[0], err


def test_speed_plane_bad_layout_names_the_parameter():
    with pytest.raises(ValueError, match="overlap"):
        jr.speed_plane([90.0], [0.5], creases=[0.5, 0.51], progress=False)


@pytest.mark.slow  # compiles the vmapped brink snap of a two-crease strip (~60 s on 2 cores)
def test_speed_plane_of_a_layout_matches_snap_speed_run():
    ds = jr.speed_plane([90.0], [0.5, 0.6], creases=[0.3, 0.65], n=24, progress=False)
    assert ds["v_s_creases"].dims == ("psi0", "gap", "crease")
    np.testing.assert_allclose(ds["crease"].values, [0.3, 0.65])
    assert ds.attrs["crease_positions"] == "0.3,0.65"
    for j, g in enumerate([0.5, 0.6]):
        scene = jr.make_scene(180.0, g, s0=0.02, n=24, creases=[(0.3, 90.0), (0.65, 90.0)])
        r = jr.snap_speed_run(scene)
        assert int(ds["result"].values[0, j]) == int(r.result._value) == int(jr.RESULTS.successful._value)
        np.testing.assert_allclose(ds["v_s"].values[0, j], r.v_s, rtol=1e-9)
        np.testing.assert_allclose(ds["v_s_creases"].values[0, j], r.v_s_creases, rtol=1e-9)
        np.testing.assert_allclose(ds["alpha_c_deg"].values[0, j], np.degrees(r.alpha_c), rtol=1e-10)
