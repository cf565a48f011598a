"""Richardson-extrapolated snap angles (`jr.snap_angles_extrapolated`, the CLI default):
agreement with an independent finer pair of meshes, the error estimate, the fallback where
the meshes disagree, the CLI contract."""

import json
import math
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from jaxrod.branches import extrapolate_path


jax.config.update("jax_enable_x64", True)


@pytest.mark.slow  # 40-50 s each (N = 200 and 400 compiled); CI checks the combination and the CLI's default
@pytest.mark.parametrize("psi0, gap", [(60.0, 0.5), (30.0, 0.6)])
def test_extrapolation_agrees_with_finer_meshes(psi0, gap):
    """R(100, 200) against the independent R(200, 400) (N = 400 solved on its own): they
    agree to 2e-3 deg although the N = 100 mesh alone is off by ~0.1 deg (second order)."""
    x = jr.snap_angles_extrapolated(jr.make_scene(psi0, gap, 0.0, n=100))
    a400 = jr.snap_angles(jr.make_scene(psi0, gap, 0.0, n=400))
    for name in ("up", "down"):
        e, p400 = getattr(x, name), getattr(a400, name)
        assert bool(e.snaps) and bool(p400.snaps) and bool(e.consistent)
        assert int(e.kind) == int(p400.kind)
        a200 = float(e.alpha_c_fine)
        ref = float(p400.alpha_c) + (float(p400.alpha_c) - a200) / 3.0
        got = float(e.alpha_c)
        assert abs(math.degrees(got - ref)) < 2e-3, (name, math.degrees(got), math.degrees(ref))
        raw = abs(math.degrees(float(e.alpha_c_coarse) - ref))
        assert raw > 0.02, raw  # the extrapolation is doing real work
        # the estimate of the N = 200 mesh error matches its actual error to 10 %
        actual = abs(math.degrees(a200 - ref))
        assert abs(math.degrees(float(e.error)) / actual - 1.0) < 0.1, (math.degrees(float(e.error)), actual)
        # the observed order from N = 100, 200, 400 is 2
        order = math.log2(abs(float(e.alpha_c_coarse) - a200) / abs(a200 - float(p400.alpha_c)))
        assert abs(order - 2.0) < 0.05, order


def test_refined_scene_keeps_the_grading():
    """The fine mesh of a graded scene is the same smooth map of twice as many points: every
    coarse node is a fine node, so the error of both meshes expands in the same powers of
    1/N and Richardson's combination applies to graded meshes too."""
    for refine in (1.0, 2.0, 3.0):
        coarse = jr.make_scene(60, 0.5, n=30, refine=refine)
        fine = jr.refined_scene(coarse)
        assert (fine.mesh.n, fine.mesh.refine, fine.mesh.width) == (60, refine, coarse.mesh.width)
        c, f = np.asarray(coarse.mesh.fractions), np.asarray(fine.mesh.fractions)
        np.testing.assert_allclose(f[::2], c, rtol=0, atol=1e-15)
        h = np.diff(f)
        assert refine == 1.0 or h.max() / h.min() > 0.8 * refine  # graded indeed


@pytest.mark.slow  # four programs compiled (N = 40, 80, 100, 200)
def test_graded_extrapolation_matches_a_finer_uniform_one():
    """R(40, 80) on a mesh graded at the crease (`refine=2`) against R(100, 200) on a uniform
    one (within 4e-6 deg of R(400, 800) here): within 8e-4 deg, where the uniform R(40, 80) is
    off by 1e-2 deg (benchmarks/results/graded.md)."""
    g = jr.snap_angles_extrapolated(jr.make_scene(60, 0.5, n=40, refine=2))
    u = jr.snap_angles_extrapolated(jr.make_scene(60, 0.5, n=100))
    for name in ("up", "down"):
        a, b = getattr(g, name), getattr(u, name)
        assert bool(a.consistent) and int(a.kind) == int(b.kind)
        assert jr.result_name(a.result) == "successful"
        assert abs(math.degrees(float(a.alpha_c) - float(b.alpha_c))) < 8e-4, name


def _fake(snaps, kind, alpha, result=jr.RESULTS.successful, start=jr.RESULTS.successful, clicks=0):
    return SimpleNamespace(snaps=jnp.asarray(snaps), kind=jnp.asarray(kind), alpha_c=jnp.asarray(alpha),
                           fold_height_before=jnp.asarray(0.1), fold_height_after=jnp.asarray(-0.2),
                           result=result, start_result=start, refine_result=None, clicks=jnp.asarray(clicks))


def test_combination_and_fallback():
    # consistent: (4 a_f - a_c) / 3, error |a_f - a_c| / 3
    e = extrapolate_path(_fake(True, 1, 1.0), _fake(True, 1, 1.3))
    assert bool(e.consistent) and abs(float(e.alpha_c) - 1.4) < 1e-12 and abs(float(e.error) - 0.1) < 1e-12
    assert e.result == jr.RESULTS.successful
    # kinds differ (a fold and a branch point crossing between the meshes): fine value, full difference
    e = extrapolate_path(_fake(True, 1, 1.0), _fake(True, 2, 1.3))
    assert not bool(e.consistent) and float(e.alpha_c) == 1.3 and abs(float(e.error) - 0.3) < 1e-12
    assert e.result == jr.RESULTS.mesh_inconsistent
    # with self-contact, a contact click more on one mesh: its snap is another loss of stability
    e = extrapolate_path(_fake(True, 1, 1.0, clicks=1), _fake(True, 1, 1.3))
    assert not bool(e.consistent) and float(e.alpha_c) == 1.3 and e.result == jr.RESULTS.mesh_inconsistent
    # one mesh snaps, the other does not (near a termination gap): fine mesh's answer, unknown error
    e = extrapolate_path(_fake(True, 1, 1.0), _fake(False, 0, jnp.nan))
    assert not bool(e.consistent) and not bool(e.snaps) and np.isnan(float(e.alpha_c)) and np.isnan(float(e.error))
    assert e.result == jr.RESULTS.mesh_inconsistent
    # neither snaps: no snap, zero error
    e = extrapolate_path(_fake(False, 0, jnp.nan), _fake(False, 0, jnp.nan))
    assert bool(e.consistent) and not bool(e.snaps) and float(e.error) == 0.0
    assert e.result == jr.RESULTS.successful
    # a code of either mesh is the path's code (the fine mesh's first), never a clean "no snap"
    bad = jr.RESULTS.continuation_incomplete
    e = extrapolate_path(_fake(False, 0, jnp.nan, result=bad), _fake(False, 0, jnp.nan))
    assert e.result == bad and e.result_coarse == bad and e.result_fine == jr.RESULTS.successful
    e = extrapolate_path(_fake(False, 0, jnp.nan), _fake(False, 0, jnp.nan, result=jr.RESULTS.landing_failed,
                                                 start=jr.RESULTS.start_substituted))
    assert e.result == jr.RESULTS.landing_failed and e.start_result == jr.RESULTS.start_substituted


def test_cli_defaults_are_extrapolated_at_n_100():
    """`jaxrod snap-angles` extrapolates by default, from N = 100 and 2N (the whole query is
    run nightly below; CI runs the same command's JSON on one mesh in test_snap.py and the
    extrapolation itself through the API above)."""
    from jaxrod.cli._main import DEFAULTS, _build_parser

    assert DEFAULTS["n"] == 100
    args = _build_parser().parse_args(["snap-angles"])
    assert args.extrapolate is True and args.n == 100


def test_cli_default_is_extrapolated(capsys):
    """`jaxrod snap-angles` extrapolates by default, from N and 2N (N = 100 unless --n):
    checked at N = 24 (the default mesh runs the same programs at another size)."""
    from jaxrod.cli._main import main

    assert main(["snap-angles", "--psi0", "60", "--gap", "0.5", "--n", "24", "--json"]) == 0
    rec = json.loads(capsys.readouterr().out)
    x = jr.snap_angles_extrapolated(jr.make_scene(60.0, 0.5, 0.0, n=24))
    assert rec["extrapolated"] is True and rec["n"] == 24 and rec["n_fine"] == 48
    for name in ("up", "down"):
        e = getattr(x, name)
        assert abs(rec[f"alpha_c_{name}_deg"] - math.degrees(float(e.alpha_c))) < 1e-9
        assert abs(rec[f"alpha_c_{name}_deg_n"] - math.degrees(float(e.alpha_c_coarse))) < 1e-9
        assert rec[f"error_estimate_{name}_deg"] > 0 and rec[f"meshes_consistent_{name}"] is True
    # the paper's asymmetry at (60 deg, 0.5): snaps both ways, alpha_c_up < |alpha_c_down|
    assert 0 < rec["alpha_c_up_deg"] < -rec["alpha_c_down_deg"]
    # both meshes' codes and the combined one are successful, the meshes consistent
    for e in (x.up, x.down):
        ok = jr.RESULTS.successful
        assert e.result == ok and e.result_coarse == ok and e.result_fine == ok and bool(e.consistent)
    # the down state does not exist at alpha = 0 at (30 deg, 0.8): the up path starts from the
    # snap-down path's end, which the CLI prints and flags with exit code 3
    assert main(["snap-angles", "--psi0", "30", "--gap", "0.8", "--n", "24", "--json"]) == 3
    rec = json.loads(capsys.readouterr().out)
    assert rec["alpha_c_up_deg"] is None and rec["kind_up"] == "none"
    assert rec["result_up"] == "successful" and rec["result_down"] == "successful"
    assert rec["start_up"] == "start_substituted" and rec["start_down"] == "successful"


@pytest.mark.slow  # 77 s on 2 cores (three reverse-mode compiles); the implicit gradients themselves are
# checked against central differences in CI by test_critical.py and test_gradients.py
def test_extrapolated_gradient_is_the_same_combination():
    """d alpha_R / d Psi0 = (4 d a_2N - d a_N) / 3 (a fixed linear combination of the
    implicit derivatives of the two meshes)."""
    def f(p, n):
        sc = jr.Scene(jr.Strip(psi0=p, s0=0.02), jr.Clamps(0.5), jr.Mesh(n))
        return jr.snap_angles(sc).down.alpha_c

    def fx(p):
        return jr.snap_angles_extrapolated(jr.Scene(jr.Strip(psi0=p, s0=0.02), jr.Clamps(0.5), jr.Mesh(100))).down.alpha_c

    p = jnp.asarray(math.radians(60.0))
    g100, g200, gx = jax.grad(f)(p, 100), jax.grad(f)(p, 200), jax.grad(fx)(p)
    assert abs(float(gx) - (4 * float(g200) - float(g100)) / 3) < 1e-9 * max(1.0, abs(float(gx)))
    assert abs(float(gx)) > 1e-3


@pytest.mark.slow  # four more compiles (N and 2N, with and without the post-snap stage)
@pytest.mark.parametrize("psi0, gap", [(60.0, 0.5), (30.0, 0.6), (180.0, 0.3)])
def test_post_snap_stage_changes_no_angle(psi0, gap):
    """The default skips the landed branch after each snap: the same angles, landed states
    and codes as with it (30 deg, 0.6: the up path starts from the down path's end). The
    numbers agree to round-off, not bit for bit: with and without the stage are two compiled
    programs, which XLA fuses differently (1 ulp seen); the codes agree exactly."""
    sc = jr.make_scene(psi0, gap, 0.0, n=24)
    a, b = jr.snap_angles_extrapolated(sc), jr.snap_angles_extrapolated(sc, continue_after_snap=True)
    for p in ("up", "down"):
        x, y = getattr(a, p), getattr(b, p)
        for f in ("alpha_c", "fold_height_before", "fold_height_after", "error"):
            u, v = np.asarray(getattr(x, f)), np.asarray(getattr(y, f))
            np.testing.assert_allclose(u, v, rtol=1e-13, atol=1e-15, err_msg=(p, f))
            assert np.array_equal(np.isnan(u), np.isnan(v)), (p, f)
        assert x.result == y.result and x.start_result == y.start_result
    assert int(a.fine.up.branch.count[1]) == 0 or int(a.fine.up.stage) == 1


def test_near_must_be_an_extrapolated_result():
    """`near` of the extrapolation is a neighbour's `snap_angles_extrapolated` (both meshes):
    anything else is refused by name before a solve."""
    with pytest.raises(ValueError, match="near"):
        jr.snap_angles_extrapolated(jr.make_scene(60.0, 0.5, n=16), near="previous")


@pytest.mark.slow  # the warm programs of both meshes compiled (CI: the scatter's warm members, test_scatter.py)
def test_extrapolated_from_a_neighbour_equals_cold():
    """Both meshes started from a neighbour's critical points give the cold call's angles and
    codes, with every path warm."""
    near = jr.snap_angles_extrapolated(jr.make_scene(60.0, 0.5, n=20))
    scene = jr.make_scene(63.0, 0.51, n=20)
    cold, warm = jr.snap_angles_extrapolated(scene), jr.snap_angles_extrapolated(scene, near=near)
    for a, b in ((cold.up, warm.up), (cold.down, warm.down)):
        assert a.result == b.result == jr.RESULTS.successful and int(a.kind) == int(b.kind)
        assert abs(float(a.alpha_c) - float(b.alpha_c)) < 1e-9
    assert all(bool(p.warm) for m in (warm.coarse, warm.fine) for p in (m.up, m.down))
