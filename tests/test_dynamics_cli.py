"""`jaxrod snap` / `jaxrod speed-plane`: errors are one line with exit 2; a run prints one JSON object."""

import json

import pytest

from jaxrod.cli._main import main


@pytest.mark.parametrize("argv, name", [
    (["snap", "--gap", "1.5"], "gap"),
    (["snap", "--psi0", "nan"], "psi0"),
    (["snap", "--solver", "rk4"], "solver"),
    (["snap", "--nudge", "-1"], "nudge"),
    (["snap", "--n", "7"], "n"),
    (["snap", "--density", "1000"], "youngs-modulus"),
    (["speed-plane", "--gaps", "0.5,x"], "gaps"),
    (["speed-plane", "--psi0", "200"], "psi0"),
])
def test_bad_input_one_line_exit_2(argv, name, capsys):
    assert main(argv + ["--json"] if argv[0] == "snap" else argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and name in err[0] and "Traceback" not in err[0]


@pytest.mark.slow
def test_snap_json(capsys, tmp_path):
    rc = main(["snap", "--psi0", "30", "--gap", "0.5", "--n", "24", "--json", "--plot", str(tmp_path)])
    out = capsys.readouterr().out.strip().splitlines()
    assert rc == 0 and len(out) == 1
    rec = json.loads(out[0])
    for k in ("alpha_c_deg", "v_s", "t_snap", "bending_energy_before", "kinetic_energy_peak", "energy_drift"):
        assert rec[k] is not None
    # the default RATTLE's energy error is bounded, O(dt^2): 1.4e-3 at N = 24 (its step is the
    # 2e-4 T cap there; jaxrod.dynamics._simulate.DT_CAP); adaptive Tsit5 at 1e-8 conserves it tightly
    assert rec["snapped"] and rec["energy_drift"] < 3e-3, rec["energy_drift"]
    assert (tmp_path / "speed_map.png").exists()
    rc = main(["snap", "--psi0", "30", "--gap", "0.5", "--n", "24", "--json", "--solver", "tsit5", "--rtol", "1e-8"])
    tight = json.loads(capsys.readouterr().out.strip().splitlines()[0])
    assert rc == 0 and tight["snapped"] and tight["energy_drift"] < 1e-5, tight["energy_drift"]
    assert abs(tight["v_s"] - rec["v_s"]) < 1e-2 * rec["v_s"], (tight["v_s"], rec["v_s"])


def test_snap_with_the_implicit_solver(capsys):
    """`--solver hht` runs jaxrod.HHT(): the same snap as RATTLE's within 1e-3 in v_s, in fewer steps."""
    argv = ["snap", "--psi0", "30", "--gap", "0.5", "--n", "24", "--json"]
    rc = main(argv)
    rattle = json.loads(capsys.readouterr().out.strip().splitlines()[0])
    rc2 = main(argv + ["--solver", "hht"])
    hht = json.loads(capsys.readouterr().out.strip().splitlines()[0])
    assert rc == 0 and rc2 == 0 and hht["snapped"] and hht["result"] == "successful"
    assert abs(hht["v_s"] / rattle["v_s"] - 1.0) < 1e-3, (hht["v_s"], rattle["v_s"])
