"""Snap routes: the second critical point of a path (`jr.snap_routes`) and the brink snap at
each route (`jr.brink(..., route=...)`).

References: on the flat strip at G/L = 0.5 the branch point lies at 84.65 deg (continuum)
and the symmetric fold about 1.75 deg later; two independent codes give v_s of about
10.3 v* for the asymmetric snap at the branch point and 18.4 v* for the symmetric one at
the fold.
"""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr

jax.config.update("jax_enable_x64", True)

N = 48  # every test here runs one snap_angles / snap_routes program (the scenes differ in values only)


@pytest.fixture(scope="module")
def flat():
    sc = jr.make_scene(180.0, 0.5, n=N)
    snap = jr.snap_angles(sc)
    return sc, snap, jr.snap_routes(sc, snap=snap)


def test_flat_strip_branch_point_then_fold(flat):
    sc, snap, r = flat
    up, down = r.up, r.down
    assert up.result == jr.RESULTS.successful and down.result == jr.RESULTS.successful
    assert int(up.kind) == 2 and int(up.kind2) == 1  # branch point, then the fold
    a1, a2 = np.degrees(float(up.alpha_c)), np.degrees(float(up.alpha_c2))
    assert a1 == pytest.approx(np.degrees(float(snap.up.alpha_c)), abs=1e-12)
    # the mesh's own angles (second order): 84.29 and 86.02 deg at N = 48 (84.57 and 86.32 at
    # N = 100), about 1.75 deg apart
    assert 84.1 < a1 < 84.7 and 85.8 < a2 < 86.5
    assert np.degrees(float(up.separation)) == pytest.approx(1.75, abs=0.05)
    # mirror symmetry of the flat strip: the down path is the up path mirrored
    assert float(down.alpha_c2) == pytest.approx(-float(up.alpha_c2), abs=1e-9)
    assert int(down.kind2) == 1


def test_second_point_is_the_turning_point_of_the_branch(flat):
    """Independent of the bisection and the extended system: a fine continuation of the
    symmetric branch past the branch point (no stop on instability) turns back in alpha at
    its largest angle; alpha_c2 is that maximum, and the reduced Hessian there has one
    negative (asymmetric) eigenvalue and one near zero with a mirror-symmetric mode."""
    sc, snap, r = flat
    up = r.up
    stage = int(snap.up.stage)
    br = jax.tree.map(lambda x: x[stage], snap.up.branch)
    i = int(br.count) - 1
    par = jr.SymmetricAlpha()
    sc_i = par.set(sc, br.lam[i])
    eq = jr.solve_equilibrium(sc_i, br.theta[i], br.force[i])
    fine = jr.continue_branch(sc_i, eq, direction=1.0, bounds=(0.0, float(up.alpha_c2) + 0.05),
                              settings=jr.Continuation(ds=0.002, ds_max=0.002, max_points=200), check_contact=False)
    lam = np.asarray(fine.lam[: int(fine.count)])
    k = int(np.argmax(lam))
    assert 0 < k < len(lam) - 1  # an interior maximum: the branch turns back
    # the parabola through the three points around the maximum
    c = np.polyfit(np.arange(3.0), lam[k - 1:k + 2], 2)
    lam_max = np.polyval(c, -c[1] / (2 * c[0]))
    assert float(up.alpha_c2) == pytest.approx(lam_max, abs=1e-7)
    eq2 = jr.solve_equilibrium(par.set(sc, up.alpha_c2), up.theta2, up.force2)
    w = np.linalg.eigvalsh(np.asarray(jr.dense_reduced_hessian(eq2)))
    assert w[0] < -1e-3 and abs(w[1]) < 1e-6 * abs(w[2])
    st = jr.stability(eq2, k=2)
    assert float(st.parity[0]) < -0.99 and float(st.parity[1]) > 0.99  # asymmetric unstable, symmetric critical


def test_fold_path_has_no_second_route():
    """Past a fold the branch turns back in alpha: no second route (NaN, kind none), and
    the brink refuses route='second' there with a message naming the parameter."""
    sc = jr.make_scene(90.0, 0.46, s0=0.02, n=N)
    snap = jr.snap_angles(sc)
    r = jr.snap_routes(sc, snap=snap)
    assert int(r.down.kind) == 1 and int(r.down.kind2) == 0
    assert np.isnan(float(r.down.alpha_c2)) and np.isnan(float(r.down.separation))
    assert r.down.result == jr.RESULTS.successful
    # the up path snaps at a branch point and its symmetric branch folds 13.9 deg later
    assert int(r.up.kind) == 2 and int(r.up.kind2) == 1
    assert 10.0 < np.degrees(float(r.up.separation)) < 18.0
    with pytest.raises(ValueError, match="route"):
        jr.brink(sc, "down", snap=snap, route="second")
    with pytest.raises(ValueError, match="route"):
        jr.brink(sc, "up", snap=snap, route="third")


@pytest.mark.slow  # ~45 s (a forward-mode compile of snap_routes); the implicit derivative of a critical
# point it rests on is checked against central differences in CI by test_critical.py
def test_second_critical_angle_gradient_matches_central_differences():
    def a2(psi0):
        sc = jr.make_scene(jnp.degrees(psi0), 0.46, s0=0.02, n=N)
        return jr.snap_routes(sc).up.alpha_c2

    p = np.radians(90.0)
    g = float(jax.jvp(a2, (p,), (1.0,))[1])  # forward mode: one tangent, a cheaper compile than reverse
    h = 1e-5
    fd = (float(a2(p + h)) - float(a2(p - h))) / (2 * h)
    assert np.isfinite(g) and g == pytest.approx(fd, rel=1e-5, abs=1e-8)


def test_each_route_snaps_at_its_own_speed(flat):
    """The flat strip at G/L = 0.5, N = 48: the brink at the branch point snaps
    asymmetrically at ~10.3 v*, the brink at the fold symmetrically at ~18.4 v* (two
    independent codes); adaptive Dopri8 at 1e-8."""
    sc, snap, _ = flat
    speeds, asym = {}, {}
    for route in ("first", "second"):
        start, tr = jr.snap_dynamics(sc, "up", route=route, snap=snap, rtol=1e-8, atol=1e-8)
        assert bool(start.ok) and tr.result == jr.RESULTS.successful and bool(tr.snapped)
        speeds[route] = float(tr.v_s)
        # how far the strip leaves mirror symmetry theta(s) = -theta(L - s) during the snap
        th = np.asarray(tr.theta)
        th = th[np.all(np.isfinite(th), axis=1)]  # frames after the run's stop are inf
        asym[route] = np.max(np.abs(th + th[:, ::-1]))
    assert speeds["first"] == pytest.approx(10.3, rel=0.02)
    assert speeds["second"] == pytest.approx(18.4, rel=0.02)
    assert asym["first"] > 0.3 and asym["second"] < 1e-6


def test_route_map_ends(flat):
    """The two ends of the route map (benchmarks/route_map.py): a slow ramp of an imperfect
    flat strip snaps asymmetrically at the branch point, a fast ramp of a perfect one passes
    it (delayed bifurcation) and snaps symmetrically at the fold, each at its brink's speed."""
    sc, snap, r = flat
    out = {}
    for name, rate, seed in (("slow, imperfect", 0.05, 1e-2), ("fast, perfect", 1.0, 0.0)):
        t1 = (float(r.up.alpha_c2) - float(snap.up.alpha_c) + np.radians(8.0)) / rate + 1.0
        _, tr = jr.snap_dynamics(sc, "up", kind="ramp", rate=rate, seed=seed, snap=snap, t1=t1, n_frames=1024)
        assert tr.result == jr.RESULTS.successful and bool(tr.snapped)
        th, tf = np.asarray(tr.theta), np.asarray(tr.t_frames)
        before = np.all(np.isfinite(th), axis=1) & (tf <= float(tr.t_peak))
        out[name] = float(tr.v_s), float(np.max(np.abs(th[before] + th[before][:, ::-1])))
    v, asym = out["slow, imperfect"]
    assert asym > 0.3 and v == pytest.approx(10.3, rel=0.03)
    v, asym = out["fast, perfect"]
    assert asym < 1e-6 and v == pytest.approx(18.4, rel=0.03)


def test_cli_snap_route_and_clearance(flat, capsys):
    from jaxrod.cli._main import main

    args = ["snap", "--psi0", "180", "--gap", "0.5", "--n", str(N), "--t1", "2", "--json"]
    assert main(args + ["--route", "second"]) == 0
    rec = json.loads(capsys.readouterr().out)
    assert rec["v_s"] == pytest.approx(18.4, rel=0.02)
    assert rec["alpha_c_deg"] == pytest.approx(np.degrees(float(flat[2].up.alpha_c2)), abs=1e-9)
    # the flat strip's lobes stay far apart: about the chord of N/10 segments at least
    assert 0.05 < rec["clearance"] < 0.5
    assert main(["snap", "--psi0", "90", "--gap", "0.46", "--n", str(N), "--direction", "down", "--route", "second",
                 "--json"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "route" in err[0]
