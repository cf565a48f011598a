"""`jaxrod design` and `jaxrod reproduce`: one-line errors with exit 2; slow end-to-end runs."""

import json

import pytest

from jaxrod.cli._main import main


@pytest.mark.parametrize("argv, word", [
    (["design", "--json"], "target"),
    (["design", "--target-alpha-up", "60", "--bounds", "gap=0.3:1.5"], "gap"),
    (["design", "--target-alpha-up", "60", "--bounds", "gap=0.3"], "bounds"),
    (["design", "--target-alpha-up", "60", "--bounds", "alpha=0:1"], "bounds"),
    (["design", "--target-alpha-up", "nan"], "target-alpha-up"),
    (["design", "--target-alpha-up", "60", "--tol", "0"], "tol"),
    (["design", "--target-alpha-up", "60", "--n", "15"], "n"),
    (["design", "--target-alpha-up", "60", "--starts", "0"], "starts"),
    (["design", "--target-alpha-up", "60", "--s0", "-1"], "s0"),
    (["design", "--target-speed", "-5"], "target-speed"),
    (["design", "--target-alpha-up", "60", "--optimizer", "sgd"], "optimizer"),
    (["design", "--target-alpha-up", "60", "--optimizer", "adam:-1"], "optimizer"),
    (["design", "--target-alpha-up", "60", "--optimizer", "adam:fast"], "optimizer"),
    (["design", "--study", "crease-position", "--optimizer", "adam"], "optimizer"),
    (["design", "--target-alpha-up", "60", "--scatter", "psi0=10"], "scatter"),
    (["design", "--target-alpha-up", "60", "--samples", "32"], "samples"),
    (["design", "--target-alpha-up", "60", "--quantile", "0.9", "--scatter", "psi0=10"], "target-alpha-down"),
    (["design", "--target-alpha-up", "60", "--target-alpha-down", "-70", "--quantile", "0.9"], "scatter"),
    (["design", "--target-alpha-up", "60", "--target-alpha-down", "-70", "--quantile", "0.9", "--scatter", "psi=10"],
     "scatter"),
    (["design", "--target-alpha-up", "60", "--target-alpha-down", "-70", "--quantile", "0.9", "--scatter", "psi0=x"],
     "scatter"),
    (["design", "--target-alpha-up", "60", "--target-alpha-down", "-70", "--quantile", "0.9", "--scatter",
      "psi0=-3"], "psi0_deg"),
    (["design", "--target-alpha-up", "60", "--target-alpha-down", "-70", "--quantile", "1.5", "--scatter", "psi0=10"],
     "quantile"),
    (["design", "--target-alpha-up", "60", "--target-alpha-down", "-70", "--quantile", "0.9", "--scatter", "psi0=10",
      "--target-hysteresis", "30"], "target-hysteresis"),
    (["design", "--target-alpha-up", "60", "--target-alpha-down", "-70", "--quantile", "0.9", "--scatter",
      "misalignment=-1"], "misalignment_deg"),
    (["design", "--target-alpha-up", "60", "--target-alpha-down", "-70", "--quantile", "0.9", "--scatter", "psi0=10",
      "--samples", "2"], "samples"),
])
def test_design_bad_input_is_one_line_exit_2(argv, word, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("jaxrod: error:") and word in err and "Traceback" not in err


def test_scatter_spec_is_parsed():
    """`--scatter` names every field of `jaxrod.design.Scatter`, the misalignment included."""
    import jaxrod.design as jd
    from jaxrod.cli._design import _scatter

    assert _scatter("psi0=10,gap=0.02,s0=0.005,misalignment=0.5,uniform") == jd.Scatter(
        psi0_deg=10.0, gap=0.02, s0=0.005, misalignment_deg=0.5, distribution="uniform")
    assert _scatter("misalignment=1") == jd.Scatter(misalignment_deg=1.0)


@pytest.mark.slow
def test_design_cli_json_reaches_targets(capsys):
    code = main(["design", "--target-alpha-up", "60", "--target-alpha-down", "-70", "--n", "40",
                 "--starts", "1", "--json"])
    rec = json.loads(capsys.readouterr().out)
    assert code == 0 and rec["reached"] is True
    assert abs(rec["alpha_c_up"] - 60) <= 0.1 and abs(rec["alpha_c_down"] + 70) <= 0.1
    assert {"psi0_deg", "gap", "s0", "num_reached", "num_starts"} <= set(rec)


@pytest.mark.slow
def test_design_cli_robust_design(capsys):
    """`jaxrod design --quantile 0.9 --scatter psi0=10`: the robust design of the nightly
    library test, through the command line (JSON, exit 0)."""
    code = main(["design", "--target-alpha-up", "70.5184", "--target-alpha-down", "-74.1698", "--quantile", "0.9",
                 "--scatter", "psi0=10", "--samples", "32", "--n", "30", "--psi0", "110", "--gap", "0.55",
                 "--tol", "0.02", "--json"])
    rec = json.loads(capsys.readouterr().out)
    assert code == 0 and rec["result"] == "successful", rec
    assert abs(rec["psi0_deg"] - 120.0) < 0.05 and abs(rec["gap"] - 0.6) < 0.001
    assert {"quantiles_deg", "nominal_deg", "check_probability", "check_sem"} <= set(rec)


@pytest.mark.slow
def test_reproduce_quick_writes_report(tmp_path, capsys):
    assert main(["reproduce", "--out", str(tmp_path), "--quick"]) == 0
    text = (tmp_path / "report.md").read_text()
    assert "73.6 deg" in text and "-80 deg" in text and "not available yet" not in text
    res = json.loads((tmp_path / "results.json").read_text())
    rows = res["sections"]["No snap at Psi0 = 30 deg, G/L = 0.8"]["rows"]
    assert rows[0][2] == "none"
    # snap angles extrapolated from N = 60 and 120 vs Richardson(400, 800) of benchmarks/results/snap.md
    rows = res["sections"]["Snap angles at Psi0 = 60 deg, G/L = 0.5"]["rows"]
    assert abs(float(rows[0][2].split()[0]) - 77.41038) < 0.01, rows[0]
    assert abs(float(rows[1][2].split()[0]) + 82.94718) < 0.01, rows[1]
    assert (tmp_path / "master_curves.png").stat().st_size > 1000
    # dynamics: the N = 60 brink snaps of benchmarks/results/reproduce-quick (RATTLE: 26.502 there)
    plane = res["sections"]["Snap speed plane (Figs. 3d-e)"]["data"]
    assert abs(plane["points"]["30/0.5"]["v_s"] - 26.50) < 0.05 and plane["fit"]["points"] >= 10
    assert plane["fit"]["a"] > 0 and plane["fit"]["b"] > 0
    ratio = res["sections"]["Folded vs unfolded snap speed (Fig. 1c)"]["data"]["ratio"]
    assert 2.0 < ratio < 3.0, ratio
    for name in ("speed_plane.png", "fig1c_fold_speed.png", "fig3_snap/chrono.png", "fig3_snap/speed_map.png",
                 "fig3_snap/energies.png", "fig4_asymmetric/chrono.png"):
        assert (tmp_path / name).stat().st_size > 1000, name


@pytest.mark.parametrize("flag, expect", [(None, "lm"), ("lm", "lm"), ("adam", 0.05), ("adam:0.2", 0.2)])
def test_design_optimizer_option_reaches_optimize(flag, expect, monkeypatch, capsys):
    """`--optimizer lm|adam[:LR]`: the angle design hands `optimize` "lm" or an optax Adam of that
    learning rate (checked by its first update of a unit gradient), and the JSON names it."""
    import jax.numpy as jnp

    import jaxrod.design as ds

    seen = {}
    real = ds.optimize

    def spy(terms, param, z0, **kw):  # records the optimizer, runs a cheap fold-height design instead
        seen["optimizer"] = kw["optimizer"]
        return real((ds.FoldHeight(-0.22, state="down", tol=1e-4),), param, z0, **{**kw, "max_iter": 1})

    monkeypatch.setattr(ds, "optimize", spy)
    argv = ["design", "--target-alpha-up", "60", "--n", "24", "--starts", "1", "--json"]
    main(argv + ([] if flag is None else ["--optimizer", flag]))
    rec = json.loads(capsys.readouterr().out)
    assert rec["optimizer"] == (flag or "lm")
    opt = seen["optimizer"]
    if expect == "lm":
        assert opt == "lm"
    else:
        g = jnp.ones(2)
        upd, _ = opt.update(g, opt.init(g), g)
        assert abs(float(upd[0]) + expect) < 1e-3 * expect  # Adam's first step: -lr sign(g)
