"""Notebook 08_batched_phase_diagram.ipynb runs top to bottom in quick mode (JAXROD_QUICK=1, see
notebooks/README.md) and shows what it must: a batch of scenes from `jax.vmap(jr.make_scene)`
through `jax.jit(jax.vmap(jr.snap_angles))` with each member's own codes (its first member equal
to its single call), the phase diagram over Psi0 x G/L x s0 as one `jr.phase_diagram(...,
s0=[...])` call (dims `(s0, psi0, gap)`, resumed without recomputing, a row equal to the
single-width diagram, the flat strip's row the same at every width) and its figure."""

import math

import pytest

pytest.importorskip("nbclient")
pytest.importorskip("nbformat")

from helpers import notebook_images, notebook_record, notebook_text, run_notebook  # noqa: E402

# nightly (`pytest -m slow`), like the other notebooks: the batched snap_angles compiles in the
# kernel (~40 s on 2 cores); CI checks the s0 axis in test_phase_diagram.py and batches in test_batch.py
pytestmark = pytest.mark.slow


def test_notebook_08_batched_phase_diagram():
    nb = run_notebook("08_batched_phase_diagram.ipynb")
    out = notebook_text(nb)
    assert "quick mode" in out and "Traceback" not in out
    rows = {(r["psi0"] if not math.isnan(r["psi0"]) else "nan", r["gap"]): r
            for r in notebook_record(nb, "BATCH")["rows"]}
    good = rows[(60.0, 0.5)]
    assert good["result_up"] == good["result_down"] == "successful"
    assert (good["kind_up"], good["kind_down"]) == ("branch_point", "fold")
    assert 70.0 < good["alpha_c_up"] < 85.0 and -90.0 < good["alpha_c_down"] < -75.0
    flat = rows[(180.0, 0.5)]
    assert flat["alpha_c_up"] == pytest.approx(-flat["alpha_c_down"], abs=1e-6)  # the flat strip: symmetric
    no_snap = rows[(30.0, 0.8)]  # the paper's no-snap case
    assert no_snap["kind_up"] == no_snap["kind_down"] == "none" and no_snap["alpha_c_down"] is None
    assert rows[(30.0, 0.34)]["result_down"] == "self_intersecting"
    nan = rows[("nan", 0.5)]
    assert nan["result_up"] == nan["result_down"] == "nonfinite"
    assert notebook_record(nb, "BATCH")["single_diff_deg"] < 1e-6
    ph = notebook_record(nb, "PHASE")
    assert ph["dims"] == ["s0", "psi0", "gap"] and ph["shape"] == [3, 5, 11] and ph["single_dims"] == ["psi0", "gap"]
    assert ph["computed"] == 15 and ph["recomputed"] == 0
    assert ph["row_diff_deg"] <= 1e-9 and ph["same_codes"]
    up = ph["alpha_c_up_05"]  # [s0][psi0] at G/L = 0.5
    iflat = ph["psi0"].index(180.0)
    assert all(abs(row[iflat] - up[0][iflat]) < 1e-9 for row in up)  # no crease: s0 changes nothing
    i30 = ph["psi0"].index(30.0)
    assert max(row[i30] for row in up) - min(row[i30] for row in up) > 0.5  # a wider fold moves the snap
    assert len(notebook_images(nb)) == 1
