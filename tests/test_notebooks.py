"""The notebooks run top to bottom in quick mode (JAXROD_QUICK=1) with nbclient.

01 (equilibria, stability, hysteresis) runs by default; 02 (snap-angle design: compiles the
critical-angle sensitivity and the design loop) and 03 (snap-speed design: compiles the
differentiable dynamics for each study, minutes even in quick mode) are marked slow.
Notebooks are committed without outputs (checked here too)."""

import os
from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")

NB = Path(__file__).resolve().parent.parent / "notebooks"


def _run(name, timeout=600):
    nb = nbformat.read(NB / name, as_version=4)
    assert all(c.get("outputs", []) == [] for c in nb.cells if c.cell_type == "code"), "commit without outputs"
    old = os.environ.get("JAXROD_QUICK")
    os.environ["JAXROD_QUICK"] = "1"
    try:
        nbclient.NotebookClient(nb, timeout=timeout, kernel_name="python3",
                                resources={"metadata": {"path": str(NB)}}).execute()
    finally:
        if old is None:
            os.environ.pop("JAXROD_QUICK", None)
        else:
            os.environ["JAXROD_QUICK"] = old
    return nb


def _text(nb):
    return "\n".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []))


def test_notebook_01_getting_started():
    out = _text(_run("01_getting_started.ipynb"))
    assert "quick mode" in out and "snap up: alpha_c" in out


@pytest.mark.slow
def test_notebook_02_snap_angle_design():
    out = _text(_run("02_snap_angle_design.ipynb"))
    assert "'reached': True" in out and "target not reached" in out


@pytest.mark.slow  # ~4 min in quick mode on 2 busy cores; its functions are tested in test_reproduce.py
def test_notebook_05_paper_figures():
    out = _text(_run("05_paper_figures.ipynb"))
    assert "quick mode" in out and "jaxrod's plane:" in out and "which part jumps:" in out
    assert "not available" not in out


@pytest.mark.slow
def test_notebook_03_snap_speed_design():
    out = _text(_run("03_snap_speed_design.ipynb"))
    assert "quick mode" in out and "target reached" in out and "target not reached" in out
    assert "fastest snap found" in out


@pytest.mark.slow  # ~4 min in quick mode on 2 busy cores (110 s CPU); its functions are tested in test_actuator.py
def test_notebook_04_programmable_actuator():
    out = _text(_run("04_programmable_actuator.ipynb"))
    assert "quick mode" in out and "outcome: reached" in out and "not reached: N = 24 step 1" in out
    assert "FAILED" not in out


def test_notebooks_committed_without_outputs():
    for path in sorted(NB.glob("*.ipynb")):
        nb = nbformat.read(path, as_version=4)
        for c in nb.cells:
            if c.cell_type == "code":
                assert c.get("outputs", []) == [] and c.get("execution_count") is None, path.name
