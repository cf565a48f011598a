"""Inverse design (`design/`): parametrization, objectives, optimizer, results, gradients;
the studies built on them (`jaxrod.paper`).

Fast tests use fold-height objectives (one Newton solve per evaluation); the critical-angle
checks compile `jaxrod.snap_angles` and its sensitivity (about a minute each) and are
marked slow (`pytest -m slow tests/test_design.py`)."""

import json
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod.design as ds
import jaxrod as jr
import jaxrod.paper as paper
from helpers import central_difference, count_compiles


# --- parametrization ------------------------------------------------------------------

def test_parametrization_maps_into_bounds_and_back():
    p = ds.Parametrization(free=("psi0_deg", "gap", "s0"), bounds={"gap": (0.3, 0.9)})
    z = jnp.array([-40.0, 40.0, 0.0])
    v = np.asarray(p.values(z))
    assert 10.0 <= v[0] < 10.0 + 1e-9 and 0.9 - 1e-9 < v[1] <= 0.9 and 0.005 < v[2] < 0.1
    z2 = p.from_values(psi0_deg=73.0, gap=0.45, s0=0.03)
    np.testing.assert_allclose(np.asarray(p.values(z2)), [73.0, 0.45, 0.03], rtol=1e-12)
    zs = p.sample(jax.random.PRNGKey(0), 256)
    vs = np.asarray(jax.vmap(p.values)(zs))
    assert np.all(vs[:, 1] > 0.3) and np.all(vs[:, 1] < 0.9)
    assert p.to_design(z2)[0] == pytest.approx(math.radians(73.0), rel=1e-12)


@pytest.mark.parametrize("kwargs, name", [
    (dict(bounds={"gap": (0.3, 1.2)}), "gap"),
    (dict(bounds={"psi0_deg": (-1.0, 90.0)}), "psi0_deg"),
    (dict(bounds={"s0": (0.0, 0.1)}), "s0"),
    (dict(bounds={"gap": (0.6, 0.3)}), "gap"),
    (dict(bounds={"gap": (float("nan"), 0.3)}), "gap"),
    (dict(free=("alpha",)), "free"),
    (dict(free=("gap",), fixed={"psi0_deg": 200.0}), "psi0_deg"),
])
def test_bad_parametrization_names_the_parameter(kwargs, name):
    with pytest.raises(ValueError, match=name):
        ds.Parametrization(**kwargs)


def test_bad_terms_and_optimizer_inputs():
    with pytest.raises(ValueError, match="tol"):
        ds.AlphaUp(60.0, tol=0.0)
    with pytest.raises(ValueError, match="target"):
        ds.AlphaUp(float("nan"))
    with pytest.raises(ValueError, match="state"):
        ds.FoldHeight(0.1, state="sideways")
    with pytest.raises(ValueError, match="n"):
        ds.optimize((ds.FoldHeight(-0.2),), ds.Parametrization(free=("gap",)), n=15)
    with pytest.raises(ValueError, match="z0"):
        ds.optimize((ds.FoldHeight(-0.2),), ds.Parametrization(free=("gap",)), jnp.zeros((2, 3)), n=16)
    with pytest.raises(ValueError, match="terms"):
        ds.optimize((), ds.Parametrization(free=("gap",)), n=16)
    for bad in ("foo", "adam", None, 3):
        with pytest.raises(ValueError, match="optimizer"):
            ds.optimize((ds.FoldHeight(-0.2),), ds.Parametrization(free=("gap",)), n=16, optimizer=bad)


def test_snap_speed_term_with_and_without_dynamics(monkeypatch):
    """`SnapSpeed` and the two snap-speed studies need `jaxrod.snap_speed`. It exists: the
    term is built (default tol 1 % of the target; unknown `jaxrod.snap_speed` options are
    refused, naming them). Without it (hidden here) the term and both studies refuse with
    NotImplementedError before computing anything. (`actuator_study` is not among them: it
    runs `jaxrod.simulate`, not `snap_speed`.) `jaxrod` imports its dynamics on first use, so
    hiding the name also takes it off the list of names imported that way."""
    assert ds.dynamics_available() and callable(jr.snap_speed)
    t = ds.SnapSpeed(20.0)
    assert (t.target, t.tol, t.weight, t.direction) == (20.0, 0.2, 1.0, "up")
    assert ds.SnapSpeed(-15.0, direction="down", nudge=0.05).describe()["options"] == {"nudge": 0.05}
    with pytest.raises(ValueError, match="options"):
        ds.SnapSpeed(20.0, wobble=1.0)
    monkeypatch.delattr(jr, "snap_speed")
    monkeypatch.setattr(jr, "_DYNAMICS", tuple(n for n in jr._DYNAMICS if n != "snap_speed"))
    assert not ds.dynamics_available()
    with pytest.raises(NotImplementedError, match="dynamics"):
        ds.SnapSpeed(20.0)
    for study in (paper.fastest_snap_study, paper.snap_speed_study):
        with pytest.raises(NotImplementedError, match="dynamics"):
            study(progress=False)


# --- fold-height design (fast) ---------------------------------------------------------

N = 24
PARAM = ds.Parametrization(free=("psi0_deg", "gap"))
TERMS = (ds.FoldHeight(-0.22, state="down", tol=1e-4), ds.BendingEnergy(40.0, state="down", tol=1e-2))


@pytest.fixture(scope="module")
def problem():
    return ds.Problem(TERMS, PARAM, N)


def test_fold_height_gradient_matches_central_difference(problem):
    z = PARAM.from_values(psi0_deg=70.0, gap=0.5)
    r, J, v, codes = problem.linearize(z)
    assert np.all(np.asarray(codes) == int(jr.RESULTS.successful._value))
    Jfd = central_difference(lambda zz: problem.residuals(zz)[0], z)
    assert np.all(np.isfinite(np.asarray(r)))
    np.testing.assert_allclose(np.asarray(J), np.asarray(Jfd), rtol=1e-6, atol=1e-6 * float(jnp.max(jnp.abs(Jfd))))


@pytest.fixture(scope="module")
def multistart():
    z0 = jnp.stack([PARAM.from_values(psi0_deg=70.0, gap=0.5), PARAM.from_values(psi0_deg=100.0, gap=0.4),
                    PARAM.from_values(psi0_deg=50.0, gap=0.6)])
    # batch_size=None: one vmap over the starts (the CPU default, "auto", runs them one by
    # one; test_multistart_under_vmap_equals_loop compares the two)
    return z0, ds.optimize(TERMS, PARAM, z0, n=N, max_iter=25, progress=False, batch_size=None)


def test_multistart_reaches_target_checked_at_finer_mesh(multistart):
    _, res = multistart
    b = res.best
    assert bool(b.reached), b.message
    assert res.num_reached >= 1
    # independent check: a fresh initial_state (homotopy + Newton, no design code); the
    # check at a finer mesh is done for the snap-angle study (slow test below)
    sc = jr.make_scene(b.psi0_deg, b.gap, 0.0, s0=b.s0, n=N)
    eq = jr.initial_state(sc, "down")
    assert abs(float(jr.fold_height(eq)) + 0.22) <= 1e-4
    assert abs(float(jr.bending_energy(eq)) - 40.0) <= 1e-2


def test_multistart_under_vmap_equals_loop(multistart):
    z0, res = multistart
    for i in range(z0.shape[0]):
        one = ds.optimize(TERMS, PARAM, z0[i], n=N, max_iter=25, progress=False)  # batch_size "auto"
        np.testing.assert_allclose(np.asarray(one.values[0]), np.asarray(res.values[i]), rtol=1e-10, atol=1e-12)
        assert bool(one.reached[0]) == bool(res.reached[i])


def test_result_save_and_load_roundtrip(multistart, tmp_path):
    _, res = multistart
    path = str(tmp_path / "best")
    res.best.save(path)
    back = ds.DesignResult.load(path)
    assert back.to_dict() == res.best.to_dict()
    np.testing.assert_array_equal(np.asarray(back.history_loss), np.asarray(res.best.history_loss))
    assert back.names == res.best.names


def test_golden_max_finds_the_maximum_and_keeps_a_better_start():
    from jaxrod.paper._studies import golden_max

    f = lambda x: -(x - 26.5) ** 2 + 1e-4 * math.sin(40 * x)  # noqa: E731  (a max with small wiggles)
    x, v, evals = golden_max(f, 10.0, 60.0, xtol=0.05)
    assert abs(x - 26.5) < 0.05 and v == pytest.approx(f(x))
    assert evals == 2 + math.ceil(math.log(0.05 / 50.0) / math.log((math.sqrt(5) - 1) / 2))
    # a start better than every point the search visits is kept; non-finite values lose
    x, v, _ = golden_max(lambda x: float("nan") if x > 30 else -abs(x - 11.0), 10.0, 40.0, x0=11.0, f0=0.0)
    assert (x, v) == (11.0, 0.0)


def test_psi0_polish_reaches_the_scanned_maximum_on_the_compiled_problem(multistart):
    """`_polish_psi0` (study (b)'s last step) maximizes the first term's value over Psi0 at the
    design's gap; here the fold height of the down state, cheap: checked against a scan."""
    from jaxrod.design._optimize import _linearize_batch
    from jaxrod.paper._studies import _polish_psi0

    _, res = multistart
    b = res.best
    problem = ds.Problem(TERMS, PARAM, N)
    p0 = b.psi0_deg
    d, rec = _polish_psi0(b, TERMS, PARAM, N, window=10.0, xtol=0.02)
    assert rec["psi0_before"] == p0 and rec["v_s_after"] >= rec["v_s_before"]
    assert rec["evaluations"] >= 10 and abs(d.psi0_deg - rec["psi0_after"]) < 1e-12
    assert d.gap == pytest.approx(b.gap, rel=1e-12)  # only Psi0 moves

    def value(p):
        z = np.asarray(b.z).copy()
        z[0] = float(PARAM.from_values(psi0_deg=p)[0])
        return float(np.asarray(_linearize_batch(problem, jnp.asarray(z)[None], 1)[2])[0, 0])

    scan = [value(p) for p in np.linspace(p0 - 10.0, p0 + 10.0, 41)]
    # the polish evaluates through `jaxrod.design.linearize`: `optimize`'s evaluation, batched as it is
    z = jnp.asarray(b.z)[None]
    for got, want in zip(ds.linearize(problem, z), _linearize_batch(problem, z, 1)):
        np.testing.assert_allclose(np.asarray(got), np.asarray(want), rtol=1e-12)
    slope = max(abs(a - c) for a, c in zip(scan, scan[1:])) / 0.5
    assert rec["v_s_after"] >= max(scan) - 0.02 * slope, (rec, max(scan))
    assert rec["v_s_after"] > rec["v_s_before"] + 1e-6  # the fold-target design is not a maximum
    # the returned design is consistent: its values and achieved are those of its z
    r, _, v, _ = problem.linearize(d.z)
    np.testing.assert_allclose(np.asarray(v), np.asarray(d.achieved), rtol=1e-10)
    np.testing.assert_allclose(np.asarray(PARAM.values(d.z)), np.asarray(d.values), rtol=1e-12)
    assert float(d.loss) == pytest.approx(0.5 * float(jnp.sum(r**2)), rel=1e-10)


def test_unreachable_target_reports_best_and_not_reached():
    # the down state's fold height cannot exceed 0 (it would be the up state)
    res = ds.optimize((ds.FoldHeight(+0.3, state="down", tol=1e-4),), PARAM, n=N, max_iter=8, progress=False)
    b = res.best
    assert not bool(b.reached) and res.num_reached == 0
    assert b.message.startswith("target not reached") and "fold_height" in b.message
    assert b.history_loss[-1] <= b.history_loss[0]
    assert b.result == jr.RESULTS.target_not_reached and res.result == b.result
    assert b.to_dict()["result"] == "target_not_reached" and b.to_dict()["result_fold_height"] == "successful"


def test_optax_optimizer_decreases_the_objective():
    optax = pytest.importorskip("optax")
    res = ds.optimize((ds.FoldHeight(-0.22, state="down", tol=1e-4),), PARAM, n=N, optimizer=optax.adam(0.05),
                      max_iter=6, progress=False)
    h = np.asarray(res.best.history_loss)
    assert h[-1] < h[0]


def test_studies_hand_their_optimizer_to_optimize(monkeypatch):
    """Studies (a), (b), (c) run `optimize` with the `optimizer` they are given (a stand-in
    `optimize` records it and stops the study)."""
    from jaxrod.paper import _studies

    class Stop(Exception):
        pass

    seen = []

    def stub(*args, **kw):
        seen.append(kw.get("optimizer"))
        raise Stop

    monkeypatch.setattr(_studies, "optimize", stub)
    opt = object()
    for study in (paper.snap_angle_study, paper.snap_speed_study, paper.fastest_snap_study):
        with pytest.raises(Stop):
            study(optimizer=opt, progress=False)
    with pytest.raises(Stop):
        paper.snap_angle_study(progress=False)
    assert seen == [opt, opt, opt, "lm"]


def test_lm_and_adam_reach_the_same_design():
    """The gap with a given fold height (one free parameter: one design), by Levenberg-Marquardt
    and by Adam on the same compiled problem: both reach it, to the target's tolerance, and LM
    needs fewer iterations (its step solves the Gauss-Newton model; Adam's is a fixed size)."""
    optax = pytest.importorskip("optax")
    param = ds.Parametrization(free=("gap",), fixed={"psi0_deg": 70.0, "s0": 0.02})
    term = (ds.FoldHeight(-0.22, state="down", tol=1e-5),)
    lm = ds.optimize(term, param, n=N, max_iter=40, progress=False).best
    adam = ds.optimize(term, param, n=N, optimizer=optax.adam(0.05), max_iter=200, progress=False).best
    assert bool(lm.reached) and bool(adam.reached), (lm.message, adam.message)
    assert abs(float(lm.achieved[0]) + 0.22) <= 1e-5 and abs(float(adam.achieved[0]) + 0.22) <= 1e-5
    # the fold height's slope in G/L is of order 1: designs within a few tolerances of each other
    assert abs(lm.gap - adam.gap) < 1e-4
    assert int(lm.num_iterations) < int(adam.num_iterations)
    assert json.loads(lm.meta)["optimizer"] == "lm" and json.loads(adam.meta)["optimizer"] != "lm"


# --- critical angles (slow: compiles snap_angles and the sensitivity) -------------------

@pytest.mark.slow
def test_critical_angle_gradients_match_central_difference():
    n = 40

    def f(p):
        c = ds.critical_angles(p[0], p[1], p[2], n)
        return jnp.stack([c.alpha_up, c.alpha_down])

    p = jnp.array([math.radians(60.0), 0.5, 0.02])
    kinds = ds.critical_angles(p[0], p[1], p[2], n)
    assert int(kinds.kind_up) == 2 and int(kinds.kind_down) == 1  # both formulas exercised
    J = jax.jacfwd(f)(p)
    Jr = jax.jacrev(f)(p)
    Jfd = central_difference(f, p)
    scale = float(jnp.max(jnp.abs(Jfd)))
    np.testing.assert_allclose(np.asarray(J), np.asarray(Jfd), atol=1e-6 * scale)
    np.testing.assert_allclose(np.asarray(Jr), np.asarray(J), atol=1e-12 * scale)


@pytest.mark.slow
def test_study_a_reaches_targets_at_finer_mesh():
    res = paper.snap_angle_study(60.0, -70.0, starts=2, n_coarse=40, n=160, n_check=320, progress=False)
    assert bool(res.design.reached), res.design.message
    assert res.verification.reached, res.verification
    assert max(res.verification.errors_deg) <= 0.1


@pytest.mark.slow
def test_unreachable_snap_angle_gives_clear_message():
    res = ds.optimize((ds.AlphaUp(150.0),), ds.Parametrization(), n=40, max_iter=15, progress=False)
    assert not bool(res.best.reached) and res.num_reached == 0
    assert "target not reached" in res.best.message and "alpha_c_up" in res.best.message


def test_design_result_is_the_first_flagged_code_of_a_reached_design():
    """`DesignResult.result` and its JSON: a reached design whose terms were computed on a
    flagged path carries that path's code, not `successful` (the real design on a path
    through itself is the nightly test below)."""
    codes = jnp.asarray([int(jr.RESULTS.successful._value), int(jr.RESULTS.self_intersecting._value),
                         int(jr.RESULTS.start_substituted._value)], jnp.int32)
    one = jnp.ones(3)
    d = ds.DesignResult(values=jnp.asarray([60.0, 0.1, 0.02]), achieved=one, targets=one, tols=one,
                        reached=jnp.asarray(True), loss=jnp.asarray(0.0), num_iterations=jnp.asarray(1),
                        status="converged", codes=codes, names=("alpha_c_up", "alpha_c_down", "hysteresis"))
    assert d.result == jr.RESULTS.self_intersecting
    assert d.to_dict()["result"] == "self_intersecting" and d.to_dict()["result_hysteresis"] == "start_substituted"
    ok = eqx.tree_at(lambda r: r.codes, d, jnp.zeros_like(codes) + int(jr.RESULTS.successful._value))
    assert ok.result == jr.RESULTS.successful
    missed = eqx.tree_at(lambda r: r.reached, d, jnp.asarray(False))
    assert missed.result == jr.RESULTS.target_not_reached


@pytest.mark.slow  # 29 s on 2 cores; CI checks DesignResult.result on flagged codes above
def test_design_carries_the_code_of_its_snap_path():
    """A target reached on a path that is not `successful` is not a success: at Psi0 = 60
    deg, G/L = 0.1 the snap-up path's critical state passes through itself
    (`self_intersecting`); a design that asks for exactly its alpha_c up is reached at once
    and says `self_intersecting`. At G/L = 0.5 the same request is `successful`."""
    from jaxrod.design._optimize import _linearize_batch

    param = ds.Parametrization()
    probe = ds.Problem((ds.AlphaUp(0.0),), param, 40)
    for (psi0, gap), want in (((60.0, 0.1), "self_intersecting"), ((60.0, 0.5), "successful")):
        z = param.from_values(psi0_deg=psi0, gap=gap)
        _, _, v, c = _linearize_batch(probe, z[None], 1)
        assert jr.results.result_name(int(np.asarray(c)[0, 0])) == want
        res = ds.optimize((ds.AlphaUp(float(np.asarray(v)[0, 0])),), param, z0=z, n=40, max_iter=1, progress=False)
        assert bool(res.best.reached)
        assert jr.results.result_name(res.best.result) == want and res.best.to_dict()["result"] == want


@pytest.mark.slow
def test_critical_angle_gradient_agrees_with_snap_angles_own_derivative():
    # two independent implementations: design's fold / branch-point sensitivity at the
    # refined critical state, and jaxrod.snap_angles' extended-system implicit derivative
    n = 40
    p = jnp.array([math.radians(60.0), 0.5, 0.02])
    mine = jax.jacfwd(lambda q: ds.critical_angles(q[0], q[1], q[2], n).alpha_up)(p)
    theirs = jax.grad(lambda q: jr.snap_angles(ds.design_scene(q[0], q[1], q[2], n)).up.alpha_c)(p)
    if float(jnp.max(jnp.abs(theirs))) == 0.0:
        pytest.skip("this jaxrod's snap_angles is not differentiable")
    np.testing.assert_allclose(np.asarray(mine), np.asarray(theirs), atol=1e-7 * float(jnp.max(jnp.abs(mine))))


def test_problems_differing_only_in_targets_share_one_program(problem):
    """Targets, tolerances and weights are data (`Problem.numbers`), not part of the compiled
    program: a problem with other numbers but the same terms reuses the compiled call and
    still gets its own residuals r = sqrt(w) (v - target) / tol."""
    from jaxrod.design._optimize import _linearize_batch

    z = PARAM.from_values(psi0_deg=70.0, gap=0.5)[None]
    r1, _, v1, _ = _linearize_batch(problem, z)
    other = ds.Problem((ds.FoldHeight(-0.3, state="down", tol=1e-3, weight=4.0),
                        ds.BendingEnergy(10.0, state="down", tol=0.5)), PARAM, N)
    with count_compiles() as c:
        r2, _, v2, _ = _linearize_batch(other, z)
    assert c[0] == 0
    np.testing.assert_array_equal(np.asarray(v1), np.asarray(v2))
    v = np.asarray(v2)[0]
    np.testing.assert_allclose(np.asarray(r2)[0], [2.0 * (v[0] + 0.3) / 1e-3, (v[1] - 10.0) / 0.5], rtol=1e-12)
    np.testing.assert_allclose(np.asarray(r1)[0], [(v[0] + 0.22) / 1e-4, (v[1] - 40.0) / 1e-2], rtol=1e-12)


@pytest.mark.slow  # two compiled design programs (~20 s); CI runs every design through the warm path
def test_warm_started_iterations_equal_cold_ones(monkeypatch):
    """Each start's snap paths start from its previous iterate's (`jaxrod.snap_angles(..., near=)`,
    the default): the same designs, codes and losses as iterations that walk every path (measured
    at N = 40, 8 starts: 1.1 s against 3.2 s, values equal to 2e-13)."""
    import jaxrod.design._optimize as opt

    terms = (ds.AlphaUp(target=70.0, tol=0.05), ds.AlphaDown(target=-84.0, tol=0.05))
    param = ds.Parametrization()
    z0 = jnp.asarray(np.random.default_rng(0).normal(size=(3, 2)))
    warm = ds.optimize(terms, param, z0, n=N, progress=False)
    monkeypatch.setattr(opt, "_first_near", lambda problem, b: None)
    cold = ds.optimize(terms, param, z0, n=N, progress=False)
    np.testing.assert_allclose(np.asarray(warm.values), np.asarray(cold.values), rtol=1e-9, atol=1e-10)
    assert np.array_equal(np.asarray(warm.status), np.asarray(cold.status))
    np.testing.assert_allclose(np.asarray(warm.losses), np.asarray(cold.losses), rtol=1e-6, atol=1e-12)
