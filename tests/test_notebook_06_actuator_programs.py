"""Notebook 06_actuator_programs.ipynb runs top to bottom in quick mode (JAXROD_QUICK=1, see
notebooks/README.md) and prints what it must: the designed programs reached and confirmed on
the finer mesh, the mirror program the mirror image of the first, every contact of the designed
run below the spare speed except the target's."""

import re

import pytest

pytest.importorskip("nbclient")
pytest.importorskip("nbformat")

from helpers import notebook_text, run_notebook  # noqa: E402

# nightly (`pytest -m slow`): two program designs (reverse-mode compiles of three-ball runs),
# 3-4 min on 2 cores; CI checks the program gradient against central differences
pytestmark = pytest.mark.slow


def test_notebook_06_actuator_programs():
    out = notebook_text(run_notebook("06_actuator_programs.ipynb"))
    assert "quick mode" in out and "FAILED" not in out
    assert "outcome: reached | re-check: confirmed" in out
    peaks = re.search(r"left: peaks \[\s*(\S+)\s+(\S+)\s*\] \| mirror of \[\s*(\S+)\s+(\S+)\s*\]", out)
    assert peaks, out
    a, b, c, e = (float(x) for x in peaks.groups())
    assert abs(a - c) < 0.05 and abs(b - e) < 0.05
    contacts = [(m.group(1), float(m.group(2))) for m in re.finditer(r"contact \d+ with (\w+)\s+at t = \S+ T, "
                                                                     r"leaves at (\S+) v\*", out)]
    assert max(v for n, v in contacts if n == "right") > 5.0, out
    assert all(v < 1.2 for n, v in contacts if n != "right"), out
    assert "animation: actuator.gif" in out
    stages = re.findall(r"program ([ABC]): (\w+) ball at (\S+) v\*, the others at most (\S+) v\*", out)
    assert [(lab, ball) for lab, ball, _, _ in stages] == [("A", "right"), ("B", "left"), ("C", "centre")], out
    assert all(float(v) >= 5.0 and float(o) <= 1.2 for _, _, v, o in stages), stages
