"""Independent cross-check of `jr.snap_angles` against AUTO-07p on the same discrete equations.

benchmarks/auto/strip.f90 writes jaxrod's discrete strip (N segment angles, end force,
exact natural turning angles, half-segment hinges at the clamps) as an AUTO-07p equation
file with an analytic Jacobian; AUTO continues it in alpha from jaxrod's alpha = 0 states
and locates folds (LP) and branch points (BP) by its own test functions (sign changes of
the tangent's alpha component and of the determinant of the extended Jacobian). Both
codes solve the same equations, so both critical angles must agree to the accuracy of
AUTO's special-point location (~1e-8 deg here), and the kinds must match: at Psi0 = 60
deg, G/L = 0.5 the snap up is a branch point (asymmetric mode), the snap down a fold.

Skipped when AUTO-07p or gfortran is missing (`apt-get install auto-07p gfortran`).
Runtime: the comparison compiles `snap_angles` (~60 s on 2 cores), so it is marked slow
(`pytest -m slow tests/test_auto_crosscheck.py`); the residual check runs by default (~15 s).
"""

import math
import sys
from pathlib import Path

import jax
import numpy as np
import pytest

import jaxrod as jr


sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks" / "auto"))
import auto_snap  # noqa: E402


OK, WHY = auto_snap.available()
pytestmark = pytest.mark.skipif(not OK, reason=WHY)

N, PSI0, GAP = 40, 60.0, 0.5


@pytest.fixture(scope="module")
def cases(tmp_path_factory):
    sc = jr.make_scene(PSI0, GAP, 0.0, n=N)
    ref = jax.jit(jr.snap_angles)(sc)
    exe, _ = auto_snap.build(tmp_path_factory.mktemp("auto_build"))
    d = jr.discretize(sc)
    out = {}
    for name, start, direction in (("up", "down", 1), ("down", "up", -1)):
        eq = jr.initial_state(sc, start)
        r = auto_snap.run(exe, tmp_path_factory.mktemp(f"auto_{name}"), d, GAP, np.asarray(eq.theta),
                          np.asarray(eq.force), direction, "default", scaling=1)
        out[name] = (getattr(ref, name), r)
    return out


@pytest.mark.slow
@pytest.mark.parametrize("name, kind", [("up", "BP"), ("down", "LP")])
def test_auto_matches_snap_angles(cases, name, kind):
    path, r = cases[name]
    assert bool(path.snaps)
    first = r["first"]
    assert first is not None, f"AUTO found no LP/BP on the {name} path"
    assert auto_snap.TY_NAMES[first["type"]] == kind
    assert jr.KIND_NAMES[int(path.kind)] == {"BP": "branch_point", "LP": "fold"}[kind]
    diff_deg = math.degrees(first["alpha"] - float(path.alpha_c))
    assert abs(diff_deg) < 1e-6, diff_deg


def test_auto_residual_is_jaxrod_gradient(tmp_path):
    """The equation file evaluates exactly jaxrod's gradient: AUTO's first point (the
    start, alpha = 0) is the jaxrod state, unchanged by AUTO's Newton correction."""
    sc = jr.make_scene(PSI0, GAP, 0.0, n=N)
    eq = jr.initial_state(sc, "up")
    exe, _ = auto_snap.build(tmp_path / "b")
    r = auto_snap.run(exe, tmp_path / "r", jr.discretize(sc), GAP, np.asarray(eq.theta), np.asarray(eq.force),
                      -1, "default", scaling=0, NMX=2)
    first = r["rows"][0]
    assert first["alpha"] == 0.0
    l2 = math.sqrt(float(np.sum(np.asarray(eq.theta) ** 2) + np.sum(np.asarray(eq.force) ** 2)))
    assert abs(first["l2norm"] - l2) < 1e-8 * l2
