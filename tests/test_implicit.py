"""The implicit integrator (jaxrod.HHT, jaxrod.dynamics._implicit) and its chain solve
(jaxrod.linalg.chain): the solve against a dense one, v_s against RATTLE, energy behaviour,
gradients against central differences, result codes and bad settings. N <= 24 in CI."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from helpers import central_difference
from jaxrod.linalg.chain import chain_solve
from test_dynamics_physics import A0_N16, FD_SCALE, P0, _scene, seeded_ramp_vs

N = 24


def _dense_chain(v, m, d, w, r, c, u=None):
    """The same bordered system formed densely: (J^T m J_u + diag d + D^T w D) y + V^T lam = r,
    V y = c, J_u moving the nodes with u (default v)."""
    n = r.shape[0]
    J = np.tril(np.ones((n, n)))[:, :, None] * np.asarray(v)[None, :, :]  # node k <- link i
    Ju = J if u is None else np.tril(np.ones((n, n)))[:, :, None] * np.asarray(u)[None, :, :]
    M = np.einsum("k,kia,kja->ij", np.asarray(m), J, Ju)
    D = np.diff(np.eye(n + 2), axis=0)[:, 1:-1]
    A = J[-1].T
    Z = np.block([[M + D.T @ (np.asarray(w)[:, None] * D) + np.diag(d), A.T], [A, np.zeros((2, 2))]])
    sol = np.linalg.solve(Z, np.concatenate([r, c]))
    return sol[:n], sol[n:]


def _chain_problem(n, seed, dt=1e-3):
    rng = np.random.default_rng(seed)
    th = rng.normal(size=n)
    h = 1.0 / n
    v = h * np.stack([-np.sin(th), np.cos(th)], -1)
    m = np.full(n, h / dt**2)
    m[-1] = 0.0  # the held end node
    d = 0.3 * rng.normal(size=n)
    w = np.full(n + 1, 1.0 / h)
    return v, m, d, w, rng.normal(size=n), h * rng.normal(size=2)


@pytest.mark.parametrize("n", [2, 7, 60])
@pytest.mark.parametrize("symmetric", [True, False])
def test_chain_solve_matches_dense(n, symmetric):
    """The O(N) sweeps solve the bordered system of the module docstring to round-off, with the
    symmetric mass term and with one that moves the nodes with other vectors u."""
    args = _chain_problem(n, n)
    u = None
    if not symmetric:
        rng = np.random.default_rng(100 + n)
        u = args[0] + 0.3 * rng.normal(size=args[0].shape) / n
    y, lam = jax.jit(chain_solve)(*map(jnp.asarray, args), u=None if u is None else jnp.asarray(u))
    y_ref, lam_ref = _dense_chain(*args, u=u)
    np.testing.assert_allclose(np.asarray(y), y_ref, rtol=1e-9, atol=1e-12 * np.max(np.abs(y_ref)))
    np.testing.assert_allclose(np.asarray(lam), lam_ref, rtol=1e-9, atol=1e-12 * np.max(np.abs(lam_ref)))


def test_chain_solve_batches_member_by_member():
    """Under vmap every member equals its own solve (to round-off: the batched sweep fuses its
    arithmetic differently), and a NaN member leaves the others alone."""
    probs = [_chain_problem(30, s) for s in range(3)]
    stacked = [jnp.asarray(np.stack(x)) for x in zip(*probs)]
    stacked[4] = stacked[4].at[1, 3].set(jnp.nan)
    ys, lams = jax.vmap(chain_solve)(*stacked)
    assert not np.all(np.isfinite(np.asarray(ys[1])))
    for k in (0, 2):
        y, lam = chain_solve(*(jnp.asarray(x) for x in probs[k]))
        np.testing.assert_allclose(np.asarray(ys[k]), np.asarray(y), rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(np.asarray(lams[k]), np.asarray(lam), rtol=1e-12, atol=1e-14)


@pytest.fixture(scope="module")
def brink24():
    return jr.brink(jr.make_scene(30, 0.5, 0, n=N), "up")


def _run(start, **kw):
    return jr.simulate(start.scene, start.theta0, start.protocol, direction=1.0, **(dict(t1=3.0) | kw))


def test_vs_matches_rattle(brink24):
    """jr.HHT() at its defaults gives the brink snap's v_s within 1e-3 of a tight RATTLE run
    (courant 0.1), keeps the right end on its clamp (exactly at the steps; the samples between
    them come from the cubic interpolant, within 1e-6 L), and takes fewer steps."""
    ref = _run(brink24, solver=jr.Rattle(courant=0.1))
    tr = _run(brink24, solver=jr.HHT())
    assert tr.result == jr.RESULTS.successful and bool(tr.snapped)
    assert abs(float(tr.v_s) / float(ref.v_s) - 1.0) < 1e-3
    assert float(jnp.nanmax(jnp.where(jnp.isfinite(tr.constraint), tr.constraint, 0.0))) < 1e-6
    assert int(tr.num_steps) < int(ref.num_steps) / 2


def test_energy_through_the_snap(brink24):
    """Up to the snap's first overshoot, undamped: HHT's default keeps E_k + V - W within 5e-3 of
    its start (measured 1.4e-3 at N = 24: the method is dissipative on the grid-scale modes, not
    energy-decreasing on the nonlinear chain)."""
    hht = _run(brink24, solver=jr.HHT())
    assert hht.result == jr.RESULTS.successful and bool(hht.snapped)
    assert float(hht.energy_drift) < 5e-3


def test_slam_past_the_snap_is_flagged(brink24):
    """Past the snap the strip slams into the other state; there the implicit step is not
    trustworthy (its energy balance drifts by more than 1 %). A run that goes on past the snap
    either stays within the monitor's 1 % or ends with a code at the drift, never a success
    carrying drifted samples: a known limitation (docs: RATTLE for the ringing)."""
    tr = _run(brink24, solver=jr.HHT(), t1=1.5, stop_at_snap=False)
    if tr.result == jr.RESULTS.successful:
        assert float(tr.energy_drift) < 1e-2
    else:
        assert tr.result in (jr.RESULTS.energy_drift, jr.RESULTS.constraint_drift, jr.RESULTS.step_underflow)
        assert float(tr.t_end) < 1.5
        late = np.asarray(tr.t) > float(tr.t_end) + 1e-3
        assert not np.any(np.isfinite(np.asarray(tr.fold_speed)[late]))


def test_vs_of_the_snap_not_of_the_run():
    """v_s is the snap's peak (up to its first overshoot) however long the run goes on;
    v_peak is the whole run's peak. Undamped, a ramp past its snap rings faster than the snap
    itself (measured v_peak 24.0 against v_s 16.95 at N = 24 through t = 3 T); without contact
    the ringing folds the strip through itself, which the run reports (`self_intersecting`)
    without changing its numbers."""
    start = jr.ramp(jr.make_scene(30, 0.5, 0, n=N), "up", rate=0.5)
    solver = jr.Rattle(courant=0.05)  # the same steps and samples on and past the snap
    stop = _run(start, solver=solver, t1=3.0)
    on = _run(start, solver=solver, t1=3.0, stop_at_snap=False)
    assert stop.result == jr.RESULTS.successful and bool(stop.snapped) and float(stop.t_end) < 1.5
    assert on.result in (jr.RESULTS.successful, jr.RESULTS.self_intersecting)
    assert float(on.t_end) == pytest.approx(3.0)
    assert abs(float(on.v_s) - float(stop.v_s)) < 1e-6 * float(stop.v_s)
    assert float(on.v_peak) > 1.2 * float(on.v_s)
    assert float(stop.v_peak) == pytest.approx(float(stop.v_s), rel=1e-12)


@pytest.mark.slow  # 30 s on 2 cores; the default solver's gradients are in CI (test_dynamics_physics)
def test_gradient_matches_central_differences():
    """d v_s / d(Psi0, G, s0) through HHT runs (a fixed step, Newton to 1e-12, all differentiated
    by diffrax's checkpointed reverse pass) equals central differences."""
    n = 16
    p0 = jnp.array(P0)
    base = jr.initial_state(_scene(p0, n, A0_N16), "down")
    solver = jr.HHT(newton_tol=1e-12, newton_iters=30)

    def f(p):
        return seeded_ramp_vs(p, n, A0_N16, base, solver=solver)[:1]

    g = jax.jacrev(f)(p0)
    assert float(f(p0)[0]) > 5.0
    fd = central_difference(f, p0, scale=jnp.asarray(FD_SCALE))
    np.testing.assert_allclose(np.asarray(g[0]), np.asarray(fd[0]), rtol=1e-4,
                               atol=1e-5 * float(jnp.max(jnp.abs(fd))))


def test_newton_failure_is_a_code(brink24):
    """A fixed step whose Newton cannot converge in its iterations ends as newton_failed; an
    adaptive run that cannot find any step ends as step_underflow. Neither reports success."""
    tr = _run(brink24, solver=jr.HHT(newton_iters=1, newton_tol=1e-300), dt=1e-3)
    assert tr.result == jr.RESULTS.newton_failed
    tr = _run(brink24, solver=jr.HHT(newton_iters=1, newton_tol=1e-300))
    assert tr.result == jr.RESULTS.step_underflow


@pytest.mark.parametrize("kw, name", [
    (dict(alpha=0.1), "alpha"), (dict(alpha=-0.5), "alpha"), (dict(alpha=math.nan), "alpha"),
    (dict(tol=0.0), "tol"), (dict(tol=-1e-6), "tol"), (dict(newton_iters=0), "newton_iters"),
    (dict(newton_iters=2.5), "newton_iters"), (dict(newton_tol=0.0), "newton_tol"), (dict(dt0=0.0), "dt0"),
])
def test_bad_hht_settings(kw, name):
    with pytest.raises(ValueError, match=name):
        jr.HHT(**kw)


@pytest.mark.parametrize("kw, name", [(dict(courant=0.7), "courant"), (dict(courant=0.0), "courant"),
                                      (dict(substeps=0), "substeps"), (dict(substeps=True), "substeps")])
def test_bad_rattle_settings(kw, name):
    with pytest.raises(ValueError, match=name):
        jr.Rattle(**kw)


def test_bad_solver_combinations(brink24):
    with pytest.raises(ValueError, match="solver"):
        _run(brink24, solver="implicit")
    with pytest.raises(ValueError, match="courant"):
        _run(brink24, solver=jr.HHT(), courant=0.3)
    with pytest.raises(ValueError, match="substeps"):
        _run(brink24, solver=jr.HHT(), substeps=2)
    with pytest.raises(ValueError, match="courant"):
        _run(brink24, solver=jr.Rattle(courant=0.3), courant=0.2)
    with pytest.raises(ValueError, match="t1"):
        jr.simulate(brink24.scene, brink24.theta0, brink24.protocol, t1=1e12)


@pytest.mark.slow  # 4-7 s; CI checks the Rattle object through actuate and snap_speed
def test_rattle_object_is_the_string(brink24):
    """jr.Rattle(courant=c) runs exactly what solver='rattle', courant=c runs."""
    a = _run(brink24, solver=jr.Rattle(courant=0.3))
    b = _run(brink24, solver="rattle", courant=0.3)
    assert float(a.v_s) == float(b.v_s) and int(a.num_steps) == int(b.num_steps)


@pytest.mark.slow
def test_steps_set_by_accuracy_not_by_the_mesh():
    """From N = 50 to N = 100 RATTLE's step count grows ~4x (its step is the stiffest mode's),
    HHT's by less than 1.5x (its step is the motion's). On the brink's image (the mirror
    convention of `jaxrod.energy.geometry.mode_sign`) their v_s agree within 1e-3 at N = 50 and
    2e-3 at N = 100 (HHT's error grows with N: benchmarks/results/implicit.md); on its mirror
    image, whose motion is the same, within 2e-3 at both (the adaptive step's accept and reject
    decisions differ by round-off there: 1.0e-3 at N = 50), while RATTLE's fixed step gives the
    same v_s on both images to 1e-9."""
    counts = {}
    for n in (50, 100):
        start = jr.brink(jr.make_scene(30, 0.5, n=n), "up", nudge=0.05)
        assert float(jnp.sum(start.theta0)) < 0  # the mirror convention's image
        mirrored = -start.theta0[::-1]
        r = jr.simulate(start.scene, start.theta0, start.protocol, direction=1.0)
        h = jr.simulate(start.scene, start.theta0, start.protocol, direction=1.0, solver=jr.HHT())
        rm = jr.simulate(start.scene, mirrored, start.protocol, direction=1.0)
        hm = jr.simulate(start.scene, mirrored, start.protocol, direction=1.0, solver=jr.HHT())
        assert h.result == jr.RESULTS.successful and hm.result == jr.RESULTS.successful
        assert abs(float(rm.v_s) / float(r.v_s) - 1.0) < 1e-9
        assert abs(float(h.v_s) / float(r.v_s) - 1.0) < (1e-3 if n == 50 else 2e-3)
        assert abs(float(hm.v_s) / float(r.v_s) - 1.0) < 2e-3
        counts[n] = (int(r.num_steps), int(h.num_steps))
    assert counts[100][0] > 3.5 * counts[50][0]
    assert counts[100][1] < 1.5 * counts[50][1]


@pytest.mark.slow
def test_long_run_is_right_or_flagged():
    """5 T past the snap at N = 50 with the default HHT and the default monitors: either a
    successful run whose energy balance stayed within energy_tol, or a run stopped with the
    energy monitor's code before t1; never non-finite samples before its end."""
    start = jr.brink(jr.make_scene(30, 0.5, n=50), "up", nudge=0.05)
    tr = jr.simulate(start.scene, start.theta0, start.protocol, direction=1.0, solver=jr.HHT(), t1=5.0,
                     stop_at_snap=False)
    before = np.asarray(tr.t) <= float(tr.t_end)
    assert np.all(np.isfinite(np.asarray(tr.fold_speed)[before]))
    if tr.result == jr.RESULTS.successful:
        assert float(tr.energy_drift) < 1e-2 and float(tr.t_end) == pytest.approx(5.0)
    else:
        assert tr.result == jr.RESULTS.energy_drift and float(tr.t_end) < 5.0
