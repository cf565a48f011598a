"""The strip as an actuator: clamp programs, balls, hits, impulses and the energy balance."""

import json
import math
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from jaxrod.dynamics._bodies import body_energy, quadrature_points, strip_body_energy

N = 16
T1 = 1.5
UP = jr.hold_and_move([(100.0, 100.0)], rate=2.0, hold=0.6)  # snaps up near 0.8 T


@pytest.fixture(scope="module")
def scene():
    return jr.make_scene(60.0, 0.5, n=N)


@pytest.fixture(scope="module")
def down(scene):
    eq = jr.initial_state(scene, "down")
    assert eq.result == jr.RESULTS.successful
    return eq.theta


def ball(position=(0.25, 0.30), mass=0.05, name="mid"):
    return jr.Ball(name, position, 0.04, mass)


# ----- programs ---------------------------------------------------------------------------

def test_program_angles_rates_and_json():
    p = jr.Program.from_degrees([0.0, 1.0, 3.0], [0.0, 90.0, 90.0], [0.0, 0.0, -45.0])
    aL, aR, rL, rR = p.angles(0.5)
    assert float(aL) == pytest.approx(math.radians(45.0)) and float(rL) == pytest.approx(math.radians(90.0))
    aL, aR, rL, rR = p.angles(2.0)
    assert float(aR) == pytest.approx(math.radians(-22.5)) and float(rR) == pytest.approx(math.radians(-22.5))
    assert float(rL) == 0.0
    aL, aR, rL, rR = p.angles(5.0)  # held after the last knot
    assert float(aR) == pytest.approx(math.radians(-45.0)) and float(rL) == float(rR) == 0.0
    q = jr.Program.from_json(p.to_json())
    np.testing.assert_allclose(np.asarray(q.alpha_right), np.asarray(p.alpha_right), rtol=1e-15)
    # differentiable in the knot angles and times
    g = jax.grad(lambda a: p.__class__(p.times, a, p.alpha_right).angles(0.25)[0])(p.alpha_left)
    np.testing.assert_allclose(np.asarray(g), [0.75, 0.25, 0.0])
    gt = jax.grad(lambda t: jr.Program(t, p.alpha_left, p.alpha_right).angles(0.5)[0])(p.times)
    assert float(gt[1]) == pytest.approx(-0.5 * math.radians(90.0))
    h = jr.hold_and_move([(30.0, 0.0), (30.0, 60.0)], rate=1.0, hold=0.5)
    np.testing.assert_allclose(np.asarray(h.times), [0.0, math.radians(30), math.radians(30) + 0.5,
                                                     math.radians(90) + 0.5, math.radians(90) + 1.0])


@pytest.mark.parametrize("make, name", [
    (lambda: jr.Program([0.0, 1.0], [0.0], [0.0, 1.0]), "same number of knots"),
    (lambda: jr.Program([0.0, 0.0], [0.0, 1.0], [0.0, 1.0]), "times must increase"),
    (lambda: jr.Program([-1.0, 0.0], [0.0, 1.0], [0.0, 1.0]), "times must start"),
    (lambda: jr.Program([0.0, 1.0], [0.0, float("nan")], [0.0, 1.0]), "alpha_left must be finite"),
    (lambda: jr.Program.from_json({"times": [0.0]}), "alpha_left_deg"),
    (lambda: jr.Program.from_json({"times": [0.0, "x"], "alpha_left_deg": [0, 1], "alpha_right_deg": [0, 1]}),
     "times must be a list of numbers"),
    (lambda: jr.Program.from_json({"times": [0.0, 1.0], "alpha_left_deg": 5, "alpha_right_deg": [0, 1]}),
     "alpha_left_deg must be a list of numbers"),
    (lambda: jr.Ball("a", (0.0,), 0.1, 1.0), "position of ball 'a'"),
    (lambda: jr.Ball("a", (0.0, 0.0), -0.1, 1.0), "radius of ball 'a'"),
    (lambda: jr.Ball("a", (0.0, 0.0), 0.1, 0.0), "mass of ball 'a'"),
    (lambda: jr.Bodies([ball(), ball()]), "names must be unique"),
    (lambda: jr.Bodies([]), "balls must be"),
    (lambda: jr.Bodies([ball()], stiffness=0.0), "stiffness"),
    (lambda: jr.Bodies([ball()], table=jr.Table(), floor=jr.Floor()), "table, floor"),
    (lambda: jr.Table(-1.0), "deceleration"),
    (lambda: jr.damping_from_ringdown(np.arange(10.0), np.ones(10)), "ring-down needs at least 3 peaks"),
])
def test_bad_input_names_the_parameter(make, name):
    with pytest.raises(ValueError, match=name):
        make()


def test_actuate_bad_input(scene):
    b = jr.Bodies([ball()])
    with pytest.raises(ValueError, match="bodies must be"):
        jr.actuate(scene, [ball()], UP)
    with pytest.raises(ValueError, match="program must be"):
        jr.actuate(scene, b, jr.Protocol())
    with pytest.raises(ValueError, match="state must be"):
        jr.actuate(scene, b, UP, state="left")
    with pytest.raises(ValueError, match="courant"):
        jr.actuate(scene, b, UP, courant=0.7)
    with pytest.raises(ValueError, match="courant"):
        jr.actuate(scene, b, UP, solver=jr.Rattle(courant=0.7))
    with pytest.raises(ValueError, match="courant: given both"):
        jr.actuate(scene, b, UP, solver=jr.Rattle(courant=0.3), courant=0.2)
    with pytest.raises(ValueError, match="substeps: given both"):
        jr.actuate(scene, b, UP, solver=jr.Rattle(substeps=2), substeps=3)
    with pytest.raises(ValueError, match="solver"):
        jr.actuate(scene, b, UP, solver=jr.HHT())


def test_actuate_takes_its_settings_from_a_rattle():
    """`solver=jr.Rattle(courant=c, substeps=k)` is `courant=c, substeps=k`; what the object
    leaves out keeps actuate's defaults (0.45, 4)."""
    from jaxrod.dynamics._actuate import _rattle_settings

    assert _rattle_settings(None, None, None) == (0.45, 4)
    assert _rattle_settings(jr.Rattle(courant=0.3, substeps=2), None, None) == (0.3, 2)
    assert _rattle_settings(jr.Rattle(courant=0.3), None, 6) == (0.3, 6)
    assert _rattle_settings(jr.Rattle(), 0.2, None) == (0.2, 4)


# ----- contact law ------------------------------------------------------------------------

def test_contact_forces_are_equal_and_opposite_and_vanish_when_clear():
    """Every contact energy depends on position differences only: the strip's and the balls'
    forces sum to zero (Newton's third law); outside the layer they are exactly zero; a ball
    sliding along a straight strip feels the same energy above a node and between nodes (the
    quadrature's ripple), and the quadrature has converged at the default point count."""
    rng = np.random.default_rng(0)
    x = jnp.asarray(np.cumsum(rng.normal(size=(17, 2)) * 0.05, 0))
    b = jr.Bodies([ball(tuple(np.asarray(x[5]) + [0.0, 0.05])), ball(tuple(np.asarray(x[9]) + [0.03, 0.03]), name="b")])
    xb = b.position
    q = quadrature_points(b, 0.1)
    gx, gb = jax.grad(strip_body_energy, argnums=(0, 1))(x, xb, b, q)
    assert float(jnp.max(jnp.abs(gb))) > 0
    np.testing.assert_allclose(np.asarray(jnp.sum(gx, 0) + jnp.sum(gb, 0)), 0.0, atol=1e-9 * float(jnp.max(jnp.abs(gb))))
    gbb = jax.grad(body_energy)(xb + jnp.array([[0.0, 0.0], [-0.02, 0.0]]), b)
    np.testing.assert_allclose(np.asarray(jnp.sum(gbb, 0)), 0.0, atol=1e-9)
    far = jnp.array([[10.0, 10.0], [20.0, 20.0]])
    assert float(strip_body_energy(x, far, b, q)) == 0.0
    assert float(jnp.max(jnp.abs(jax.grad(strip_body_energy, argnums=1)(x, far, b, q)))) == 0.0
    line = jnp.stack([jnp.linspace(0.0, 1.0, 11), jnp.zeros(11)], -1)
    one = jr.Bodies([jr.Ball("r", (0.0, 0.0), 0.04, 1.0)])
    q1 = quadrature_points(one, 0.1)
    e = np.array([float(strip_body_energy(line, jnp.array([[xc, 0.05]]), one, q1)) for xc in np.linspace(0.3, 0.4, 21)])
    assert e[0] > 0 and np.ptp(e) < 2e-3 * e[0]
    fine = float(strip_body_energy(line, jnp.array([[0.33, 0.05]]), one, 8 * q1))
    assert float(strip_body_energy(line, jnp.array([[0.33, 0.05]]), one, q1)) == pytest.approx(fine, rel=2e-3)


# ----- runs -------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def snap_up(scene, down):
    return jr.actuate(scene, jr.Bodies([ball()]), UP, theta0=down, dissipation=jr.Dissipation(), t1=T1)


def test_a_snap_launches_the_ball_it_strikes(snap_up):
    """One undamped snap up under a ball above the fold: the ball is hit once, its momentum
    is the impulse the strip gave it (to round-off), the energy balance closes, the contact
    layer holds."""
    a = snap_up
    assert a.result == jr.RESULTS.successful, jr.result_name(a.result)
    hits = a.hits()
    assert [h["name"] for h in hits] == ["mid"]
    h = hits[0]
    assert 0.8 < h["time"] < 0.95 and h["launch_speed"] > 15.0
    M = 0.05
    np.testing.assert_allclose(np.asarray(M * a.ball_velocity[-1, 0]), np.asarray(a.impulse[-1, 0]), rtol=1e-10, atol=1e-12)
    assert h["impulse_norm"] == pytest.approx(M * h["launch_speed"], rel=1e-6)
    assert float(a.energy_error) < 5e-3
    assert 0 < float(a.min_clearance[0]) < 0.02  # inside the layer, never through it
    snaps = a.snaps()
    assert [(s["from"], s["to"], s["kind"]) for s in snaps] == [("DD", "UU", "snap")]
    assert snaps[0]["time"] < h["time"]


def test_a_program_that_snaps_nothing_hits_nothing(scene, down):
    """Clamps to 40 deg and back (below the snap angle): no snap, the ball never moves."""
    prog = jr.hold_and_move([(40.0, 40.0), (0.0, 0.0)], rate=2.0, hold=0.2)
    a = jr.actuate(scene, jr.Bodies([ball()]), prog, theta0=down, t1=T1)
    assert a.result == jr.RESULTS.successful, jr.result_name(a.result)
    assert a.hits() == [] and a.snaps() == []
    assert float(jnp.max(jnp.abs(a.ball_velocity))) == 0.0
    assert float(jnp.max(a.fold_height)) < 0.0
    assert float(a.energy_error) < 1e-3


@pytest.mark.slow  # 13 s; CI checks energy conservation with contact (test_self_contact.py) and each launch
def test_energy_balance_closes_over_several_snaps(scene):
    """Up, down, up in one damped run with table friction (clamp work and dissipation in the
    balance): three snaps, the ball struck by the first and slowed to rest by the table."""
    prog = jr.hold_and_move([(100.0, 100.0), (-110.0, -110.0), (100.0, 100.0)], rate=3.0, hold=0.8)
    b = jr.Bodies([ball((0.25, 0.45))], table=jr.Table(20.0))
    a = jr.actuate(scene, b, prog)
    assert a.result == jr.RESULTS.successful, jr.result_name(a.result)
    # the snaps are the fold's crossings; on the way down both halves first cross the clamp
    # line quasi-statically (a drift UU -> DD), then the fold snaps
    events = a.snaps()
    snaps = [e for e in events if e["kind"] == "snap"]
    assert [e["fold"] for e in snaps] == ["up", "down", "up"], events
    assert [(e["from"], e["to"]) for e in snaps] == [("DD", "UU"), ("DD", "DD"), ("DD", "UU")], events
    assert [(e["from"], e["to"]) for e in events if e["kind"] == "drift"] == [("UU", "DD")], events
    assert float(a.energy_error) < 1e-3
    assert float(a.dissipated[-1]) > 0.5 * float(a.clamp_work[-1]) > 0
    assert [h["name"] for h in a.hits()] == ["mid"] and a.hits()[0]["time"] < a.snaps()[1]["time"]
    # friction: the ball stops (a_f = 20: from 20 v* in about 1 T)
    assert float(jnp.linalg.norm(a.ball_velocity[-1, 0])) < 1e-2 * a.hits()[0]["launch_speed"]


def test_penetration_is_flagged(scene, down):
    """A contact layer far too soft for the impact: `object_penetrated`, not a silent pass."""
    a = jr.actuate(scene, jr.Bodies([ball()], stiffness=20.0), UP, theta0=down, t1=T1)
    assert a.result == jr.RESULTS.object_penetrated
    assert float(a.min_clearance[0]) < 0


def test_damping_from_ringdown(scene):
    """gamma back from a synthetic ring-down, and from the fold height of a damped strip
    released from its equilibrium at clamp angles of 5 deg with the clamps held at 0 (small
    oscillations: mass-proportional damping decays every mode as exp(-gamma t / 2))."""
    t = np.linspace(0.0, 10.0, 4001)
    assert jr.damping_from_ringdown(t, 0.3 + np.exp(-0.4 * t) * np.cos(7.0 * t)) == pytest.approx(0.8, rel=2e-3)
    start = jr.initial_state(jr.make_scene(60.0, 0.5, 5.0, n=N), "down").theta
    hold = jr.Program([0.0, 1.0], [0.0, 0.0], [0.0, 0.0])
    a = jr.actuate(scene, jr.Bodies([ball((5.0, 5.0))]), hold, theta0=start, t1=T1,
                   dissipation=jr.Dissipation(damping=4.0))
    assert a.result == jr.RESULTS.successful
    assert jr.damping_from_ringdown(np.asarray(a.t), np.asarray(a.fold_height)) == pytest.approx(4.0, rel=0.05)


@pytest.mark.slow  # 31-33 s on 2 cores (a reverse-mode contact run); CI keeps the v_s and snap-angle gradients
def test_program_gradient_matches_central_differences(scene, down):
    """d(launch speed) / d(knot angles) of a one-clamp program, through the run and the
    contact, against central differences. On the scale of a step the hit's discretization
    error depends on where the hit falls between steps (the launch speed wiggles by ~1e-6 of
    itself per 1e-4 rad), so the differences are taken at h = 3e-7 rad, below that scale."""
    one_clamp = jr.hold_and_move([(70.0, 0.0)], rate=2.0, hold=0.9)
    b = jr.Bodies([ball()])

    def launch(x):
        p = jr.Program(one_clamp.times, x[0], x[1])
        return jr.actuate(scene, b, p, theta0=down, t1=T1).launch_speed[0]

    x0 = jnp.stack([one_clamp.alpha_left, one_clamp.alpha_right])
    g = jax.grad(launch)(x0)
    assert float(launch(x0)) > 5.0
    h = 3e-7
    for k in [(0, 1), (1, 1), (1, 2)]:
        e = jnp.zeros_like(x0).at[k].set(h)
        fd = (launch(x0 + e) - launch(x0 - e)) / (2 * h)
        assert float(g[k]) == pytest.approx(float(fd), rel=2e-3, abs=1e-3), k
    assert abs(float(g[0, 1])) > 0.5


# ----- CLI --------------------------------------------------------------------------------

def test_cli_actuate(tmp_path, capsys):
    """`jaxrod actuate --program FILE --objects FILE --json`: one JSON object with the hits in
    time order, the snaps, the energy error and the code; the same numbers as the API."""
    from jaxrod.cli._main import main

    prog = tmp_path / "p.json"
    prog.write_text(json.dumps({**UP.to_json(), "t1": T1}))
    objs = tmp_path / "o.json"
    objs.write_text(json.dumps({"balls": [{"name": "mid", "x": 0.25, "y": 0.30, "radius": 0.04, "mass": 0.05}]}))
    gif = tmp_path / "run.gif"
    assert main(["actuate", "--program", str(prog), "--objects", str(objs), "--n", str(N), "--undamped",
                 "--json", "--animate", str(gif)]) == 0
    rec = json.loads(capsys.readouterr().out)
    assert rec["result"] == "successful" and gif.stat().st_size > 0
    assert [h["name"] for h in rec["hits"]] == ["mid"] and rec["balls"]["mid"]["hit"] is True
    assert [s["fold"] for s in rec["snaps"] if s["kind"] == "snap"] == ["up"]
    assert rec["energy_error"] < 5e-3
    ref = jr.actuate(jr.make_scene(60.0, 0.5, n=N), jr.Bodies([ball()]), UP, t1=T1, dissipation=jr.Dissipation())
    assert rec["hits"][0]["launch_speed"] == pytest.approx(float(ref.launch_speed[0]), rel=1e-9)


@pytest.mark.parametrize("program, objects, message", [
    (None, None, "program: cannot read"),
    ("{not json", None, "program: .* is not valid JSON"),
    ('{"times": [0, 1]}', None, "alpha_left_deg"),
    ('{"times": [0, 1], "alpha_left_deg": [0, 10], "alpha_right_deg": [0]}', None, "same number of knots"),
    ('{"times": [0, 1], "alpha_left_deg": [0, 10], "alpha_right_deg": [0, 0]}', '{"balls": []}', "balls"),
    ('{"times": [0, 1], "alpha_left_deg": [0, 10], "alpha_right_deg": [0, 0]}',
     '{"balls": [{"name": "a", "x": 0, "y": 1, "radius": -1, "mass": 1}]}', "radius of ball 'a'"),
    ('{"times": [0, 1], "alpha_left_deg": [0, 10], "alpha_right_deg": [0, 0], "t1": -1}', None, "t1"),
])
def test_cli_actuate_bad_input(tmp_path, capsys, program, objects, message):
    from jaxrod.cli._main import main

    args = ["actuate", "--program", str(tmp_path / "p.json")]
    if program is not None:
        (tmp_path / "p.json").write_text(program)
    if objects is not None:
        (tmp_path / "o.json").write_text(objects)
        args += ["--objects", str(tmp_path / "o.json")]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and re.search(message, err), err


# ----- design -----------------------------------------------------------------------------

def test_program_loss_is_zero_exactly_inside_the_goal():
    from jaxrod.design._programs import _loss

    v, moved = jnp.array([0.5, 0.9, 6.0]), jnp.array([0.005, 0.0, 3.0])
    assert float(_loss(v, moved, 0.0, 2, 5.0, 1.0, None, 0.1)) == 0.0
    assert float(_loss(v.at[2].set(5.4), moved, 0.0, 2, 5.0, 1.0, None, 0.1)) > 0  # below (1 + margin) v_launch
    assert float(_loss(v.at[0].set(0.95), moved, 0.0, 2, 5.0, 1.0, None, 0.1)) > 0  # above (1 - margin) v_spare
    assert float(_loss(v, moved, 0.3, 2, 5.0, 1.0, None, 0.1)) == pytest.approx(0.09)  # the reach term
    assert float(_loss(v, moved, 0.0, 2, 5.0, 1.0, 0.01, 0.1)) == 0.0  # the target may move
    assert float(_loss(v, moved.at[0].set(0.0095), 0.0, 2, 5.0, 1.0, 0.01, 0.1)) > 0  # a spared ball may not
    # bounds per ball (design_program's d_spare={"name": distance}): inf where a ball may move
    per_ball = jnp.array([0.01, jnp.inf, jnp.inf])
    far = moved.at[1].set(5.0)
    assert float(_loss(v, far, 0.0, 2, 5.0, 1.0, per_ball, 0.1)) == 0.0
    assert float(_loss(v, far.at[0].set(0.0095), 0.0, 2, 5.0, 1.0, per_ball, 0.1)) > 0
    g = jax.grad(lambda m: _loss(v, m, 0.0, 2, 5.0, 1.0, per_ball, 0.1))(far.at[0].set(0.0095))
    assert np.all(np.isfinite(np.asarray(g))) and float(g[0]) > 0 and float(g[1]) == 0.0
    from jaxrod import design, paper

    with pytest.raises(ValueError, match=r"d_spare: unknown balls \['middle'\]"):
        design.design_program(jr.make_scene(60.0, 0.5, n=N), paper.fig4_bodies(), "right", (50.0, -40.0),
                              d_spare={"middle": 0.01})


def test_descend_undoes_steps_into_a_flat_region():
    """The design descent (Adam with step undoing): on a loss that is flat (zero gradient)
    beyond p = 4, as a program's loss is where it misses every ball, Adam's first step from
    2.5 (lr 2) lands at 4.5; plain Adam stays in the flat region, `descend` undoes the step,
    halves it and converges to the minimum at 3. Rejected iterates (`accept` False) are
    never the best one."""
    optax = pytest.importorskip("optax")
    from jaxrod import design

    def loss(p):
        return jnp.where(p[0] < 4.0, (p[0] - 3.0) ** 2, 100.0), p[0] < 4.0

    vg = jax.value_and_grad(loss, has_aux=True)
    best, history, last = design.descend(vg, jnp.array([2.5]), lr=2.0, steps=30)
    assert history[:2] == [0.25, 100.0]  # the step into the flat region, then undone
    assert best[0] < 1e-6 and abs(float(best[1][0]) - 3.0) < 1e-3 and len(history) <= 31
    opt, p = optax.adam(2.0), jnp.array([2.5])
    state = opt.init(p)
    for _ in range(30):
        upd, state = opt.update(vg(p)[1], state, p)
        p = optax.apply_updates(p, upd)
    assert float(p[0]) > 4.0  # plain Adam: carried into the flat region, never back
    # an iterate that is not accepted is not kept, however low its loss
    best, history, _ = design.descend(vg, jnp.array([2.5]), lr=2.0, steps=5, accept=lambda ok: not ok)
    assert best[0] == 100.0 and float(best[1][0]) >= 4.0


def test_design_program_scan_descent_and_result(monkeypatch, scene):
    """`design_program`'s plumbing with a stand-in run (the real one is the nightly test
    below): the scan picks the widest-margin start, the descent reaches the goal, and the
    result carries the design, its speeds and the re-check's outcome and codes."""
    import types

    from jaxrod import design, paper
    from jaxrod.design import _programs

    def toy(scene, bodies, p, theta0, t1, target):  # the right ball at p_L / 5 v*, the others still
        v = jnp.stack([0.0 * p[0], 0.0 * p[0], p[0] / 5.0])
        return v, jnp.zeros(3), jnp.zeros(()), jr.RESULTS.successful

    monkeypatch.setattr(_programs, "_speeds_and_code", toy)
    monkeypatch.setattr(jr, "initial_state", lambda sc, state: types.SimpleNamespace(theta=jnp.zeros(sc.mesh.n)))
    checked = {}

    def check_run(sc, bodies, program, **kw):
        checked["n"] = sc.mesh.n
        return types.SimpleNamespace(peak_speed=jnp.array([0.5, 0.0, 6.0]), ball_position=bodies.position[None],
                                     result=jr.RESULTS.successful)

    monkeypatch.setattr(jr, "actuate", check_run)
    d = design.design_program(scene, paper.fig4_bodies(), "right", (10.0, 0.0), lr=3.0, steps=30, n_check=24,
                              scan_deg=15.0, scan_size=3)
    assert d.history[0] == pytest.approx((5.5 - 5.0) ** 2 / 25.0)  # the scan's best: p_L = 25, 5 v*
    assert d.reached and d.history[-1] == 0.0 and d.peaks_deg[0] >= 27.5 and d.iterations >= 1
    assert d.speeds["right"] == pytest.approx(d.peaks_deg[0] / 5.0) and d.displaced == {n: 0.0 for n in d.speeds}
    assert checked["n"] == 24 and d.confirmed and d.check == {"left": 0.5, "centre": 0.0, "right": 6.0}
    assert d.codes == ("successful", "successful")


@pytest.mark.slow  # ~2 min on 2 cores (the reverse-mode compile of a three-ball run at N = 32); CI checks
# the program gradient itself against central differences above and the descent on a toy loss
def test_designed_program_launches_its_target_and_spares_the_others():
    """From a program that misses the goal, Adam on the gradient through the run (no scan)
    finds one that launches the right ball faster than 5 v* and leaves the others below
    1.2 v*; an independent run at N = 48 confirms it."""
    from jaxrod import design, paper

    d = design.design_program(jr.make_scene(60.0, 0.5, n=32), paper.fig4_bodies(), "right", (50.0, -40.0),
                              v_launch=5.0, v_spare=1.2, steps=12, n_check=48)
    assert d.reached and d.confirmed, d
    assert d.history[0] > 1.0 and d.history[-1] == 0.0 and d.iterations >= 2
    assert d.check["right"] >= 5.0 and d.check["left"] <= 1.2 and d.check["centre"] <= 1.2


def test_traced_contact_law_is_refused_with_a_clear_message(scene, down):
    """The contact law sets the step, so it must be concrete: under jit a clear ValueError."""
    def f(k):
        return jr.actuate(scene, jr.Bodies([ball()], stiffness=k), UP, theta0=down, t1=T1).launch_speed

    with pytest.raises(ValueError, match="bodies: stiffness, thickness, radius and mass"):
        jax.jit(f)(1e5)


# ----- the paper's Fig. 4 sequence --------------------------------------------------------

def test_sequence_windows_follow_the_program():
    """Each program's window starts where its clamps leave 0 and ends after its reset and
    rest (the last after its hold), as `sequence_program` lays the knots."""
    from jaxrod import design

    peaks = [(40.0, -50.0), (-30.0, 60.0), (120.0, 120.0)]
    prog = design.sequence_program(peaks)
    wins = design.sequence_windows(3)
    assert wins == [(0.0, 4.8), (4.8, 9.6), (9.6, 11.4)]
    assert float(prog.times[-1]) == pytest.approx(11.4)
    for (a, b), (pl, pr) in zip(wins, peaks):
        aL, aR, _, _ = prog.angles(jnp.asarray(a))
        assert float(aL) == float(aR) == 0.0
        aL, aR, _, _ = prog.angles(jnp.asarray(a + 1.0))  # the end of the ramp
        assert math.degrees(float(aL)) == pytest.approx(pl) and math.degrees(float(aR)) == pytest.approx(pr)
    aL, _, _, _ = prog.angles(jnp.asarray(4.8 - 1.0 - 1.0))  # the reset's bottom
    assert math.degrees(float(aL)) == pytest.approx(-110.0)


def _fake_run(names, t, speeds, final_positions, final_speed=0.0, clearance=None):
    """A run's ball samples (host arrays): speeds (n, M) along x, clearances (n, M) (default 1)."""
    import types

    v = np.zeros(speeds.shape + (2,))
    v[..., 0] = speeds
    v[-1, :, 0] = final_speed
    pos = np.zeros_like(v)
    pos[-1] = final_positions
    clear = np.ones(speeds.shape) if clearance is None else np.asarray(clearance, float)
    return types.SimpleNamespace(names=tuple(names), t=np.asarray(t), ball_velocity=v, ball_position=pos,
                                 ball_clearance=clear)


def test_remaining_balls_and_per_program_speeds():
    from jaxrod import design, paper

    b = paper.fig4_bodies()
    run = _fake_run(b.names, np.linspace(0, 1, 5), np.zeros((5, 3)), [[0.0, 0.2], [0.3, 0.5], [9.0, 0.1]])
    left = design.remaining_bodies(b, run, ["right"])
    assert left.names == ("left", "centre")
    np.testing.assert_allclose(np.asarray(left.position), [[0.0, 0.2], [0.3, 0.5]])
    np.testing.assert_allclose(np.asarray(left.velocity), 0.0)
    assert float(left.table.deceleration) == 5.0 and float(left.thickness) == float(b.thickness)
    assert design.remaining_bodies(b, run, ["left", "centre", "right"]) is None
    with pytest.raises(ValueError, match="ball 'left' still moves"):
        design.remaining_bodies(b, _fake_run(b.names, [0, 1], np.zeros((2, 3)), np.zeros((3, 2)), 0.1), ["right"])
    # per program: peak speeds in its window, for the balls still on the table
    t = np.array([0.5, 2.0, 5.0, 7.0, 10.0, 11.0, np.nan])
    sp = np.array([[0.1, 0.0, 7.0], [0.7, 0.2, 5.0], [0.3, 0.0, 1.0], [6.0, 0.5, 0.0], [0.0, 5.5, 0.0],
                   [0.0, 4.0, 0.0], [99.0, 99.0, 99.0]])
    out = design.sequence_speeds(_fake_run(b.names, t, sp, np.zeros((3, 2))), ["right", "left", "centre"])
    assert out == [{"left": 0.7, "centre": 0.2, "right": 7.0}, {"left": 6.0, "centre": 0.5}, {"centre": 5.5}]
    # and their smallest clearances, on the same windows
    cl = 1.0 + sp / 100.0
    cl[6] = -1.0  # a sample past the end (t = nan) is not in any window
    out = design.sequence_clearances(_fake_run(b.names, t, sp, np.zeros((3, 2)), clearance=cl),
                                     ["right", "left", "centre"])
    want = [{"left": 1.001, "centre": 1.0, "right": 1.05}, {"left": 1.003, "centre": 1.0}, {"centre": 1.04}]
    assert [list(o) for o in out] == [list(w) for w in want]
    assert all(o == pytest.approx(w, abs=1e-12) for o, w in zip(out, want))


def test_stage_outcome_defaults_are_the_fig4_goal():
    """`jaxrod.design.stage_outcome` judges a program by the paper's Fig. 4 goal unless told
    otherwise: its default speeds are `jaxrod.paper.FIG4_V_LAUNCH` and `FIG4_V_SPARE`."""
    import inspect

    from jaxrod import design, paper

    defaults = inspect.signature(design.stage_outcome).parameters
    assert defaults["v_launch"].default == paper.FIG4_V_LAUNCH
    assert defaults["v_spare"].default == paper.FIG4_V_SPARE
    assert design.stage_outcome({"left": 0.5, "right": 5.0}, "right") == (["right"], True, True)
    assert design.stage_outcome({"left": 1.3, "right": 5.0}, "right") == (["right"], False, False)


def _fake_actuate(seen, speeds):
    """A stand-in for `jr.actuate` that records its scene's mesh, balls, program and t1 in
    `seen` and returns a run with the ball speeds `speeds` (5 samples, 3 balls)."""
    import types

    t = np.array([1.0, 2.0, 6.0, 10.0, 13.0])  # the last sample: every ball at rest

    def actuate(scene, bodies, program, **kw):
        seen.update(program=program, names=bodies.names, t1=kw.get("t1"), n=scene.mesh.n,
                    position=np.asarray(bodies.position), n_frames=kw.get("n_frames"))
        run = _fake_run(bodies.names, t, np.asarray(speeds, float), np.zeros((3, 2)))
        return types.SimpleNamespace(
            **vars(run), result=jr.RESULTS.successful, hits=lambda: [], snaps=lambda: [],
            energy_error=np.float64(1e-4), hit=np.ones(3, bool), launch_speed=np.ones(3), peak_speed=np.ones(3),
            min_clearance=np.zeros(3), num_steps=np.int64(10))
    return actuate


def test_cli_actuate_mesh_and_balls_defaults(monkeypatch, tmp_path, capsys):
    """`jaxrod actuate`: a program file runs on N = 24 unless --n says otherwise, paper-fig4 on
    the Fig. 4 re-check mesh; without --objects, the balls are `jaxrod.paper.fig4_bodies`;
    `--frames` sets the animation's frames (at least 2)."""
    from jaxrod import paper
    from jaxrod.cli._main import main

    seen = {}
    monkeypatch.setattr(jr, "actuate", _fake_actuate(seen, np.zeros((5, 3))))
    prog = tmp_path / "p.json"
    prog.write_text(json.dumps({"times": [0, 1], "alpha_left_deg": [0, 30], "alpha_right_deg": [0, 0]}))
    for argv, n in [(["--program", str(prog)], 24), (["--program", str(prog), "--n", "16"], 16),
                    (["--program", "paper-fig4", "--n", "32"], 32), (["--program", "paper-fig4"], 48)]:
        main(["actuate", *argv, "--json"])
        capsys.readouterr()
        assert seen["n"] == n, argv
    np.testing.assert_allclose(seen["position"], np.asarray(paper.fig4_bodies().position))
    assert seen["names"] == paper.fig4_bodies().names and seen["n_frames"] == 96
    main(["actuate", "--program", str(prog), "--frames", "300", "--json"])
    assert seen["n_frames"] == 300
    capsys.readouterr()
    assert main(["actuate", "--program", str(prog), "--frames", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "frames" in err


def test_cli_paper_fig4_reports_each_program(monkeypatch, capsys):
    """`jaxrod actuate --program paper-fig4`: the designed peaks in sequence on the three balls;
    per program the balls it launched and whether it spared the others (a stand-in run: the
    real one is the nightly test below); exit 3 when a program launches the wrong ball."""
    from jaxrod import design, paper
    from jaxrod.cli._main import main

    seen = {}

    def fake(speeds):
        return _fake_actuate(seen, speeds)

    good = [[0.3, 0.2, 7.0], [0.5, 0.1, 0.0], [6.0, 0.4, 0.0], [0.0, 5.6, 0.0], [0.0, 0.0, 0.0]]
    monkeypatch.setattr(jr, "actuate", fake(good))
    assert main(["actuate", "--program", "paper-fig4", "--json"]) == 0
    rec = json.loads(capsys.readouterr().out)
    assert seen["names"] == ("left", "centre", "right") and seen["n"] == paper.FIG4_N_CHECK == 48
    assert seen["t1"] == pytest.approx(13.4)
    want = design.sequence_program(paper.FIG4_PEAKS)
    np.testing.assert_allclose(np.asarray(seen["program"].alpha_left), np.asarray(want.alpha_left))
    assert [q["launched"] for q in rec["programs"]] == [["right"], ["left"], ["centre"]]
    assert [q["target"] for q in rec["programs"]] == ["right", "left", "centre"]
    assert rec["programs"][1]["peak_speeds"] == {"left": 6.0, "centre": 0.4}
    assert rec["programs"][1]["min_clearance"] == {"left": 1.0, "centre": 1.0}  # the stand-in's clearances
    assert rec["sequence_confirmed"] is True and rec["result"] == "successful"
    bad = [[0.3, 2.0, 7.0], [0.5, 0.1, 0.0], [6.0, 0.4, 0.0], [0.0, 5.6, 0.0], [0.0, 0.0, 0.0]]  # A knocks the centre ball too
    monkeypatch.setattr(jr, "actuate", fake(bad))
    assert main(["actuate", "--program", "paper-fig4"]) == 3
    out = capsys.readouterr().out
    assert "program A (right): launched right" in out and "sequence_confirmed False" in out
    assert "; clearance left 1.000, centre 1.000 L" in out


@pytest.mark.slow  # the sequence at N = 48 (about 1 min on 2 cores)
def test_cli_paper_fig4_sequence(capsys):
    """The three designed programs in one run on the re-check mesh: A launches the right
    ball, B the left one, C the centre one, each leaving the balls still on the table below
    1.2 v*: exit 0."""
    from jaxrod.cli._main import main

    assert main(["actuate", "--program", "paper-fig4", "--json"]) == 0
    rec = json.loads(capsys.readouterr().out)
    assert rec["result"] == "successful" and rec["sequence_confirmed"] is True and rec["n"] == 48
    assert [q["as_designed"] for q in rec["programs"]] == [True, True, True]
    assert [q["launched"] for q in rec["programs"]] == [["right"], ["left"], ["centre"]]
    assert rec["energy_error"] < 1e-3
    # the spared balls never enter the contact layer (0.02 L)
    assert all(v > 0.02 for q in rec["programs"] for nm, v in q["min_clearance"].items() if nm != q["target"])


@pytest.mark.slow  # the whole study (about 7 min on 2 cores)
def test_fig4_study_designs_the_sequence_it_ships():
    """`fig4_study` designs A, B, C one after the other, each on the balls the ones before it
    left; re-checked together on the finer mesh, each launches its own ball faster than 5 v*
    and leaves the others below 1.2 v*; B is A's mirror image (the scene is symmetric and A
    leaves the left and centre balls in place), to the launch speed; the peaks are those
    `FIG4_PEAKS` ships to the CLI."""
    from jaxrod import paper

    r = paper.fig4_study()
    assert [d.target for d in r.designs] == ["right", "left", "centre"]
    np.testing.assert_allclose([d.peaks_deg for d in r.designs], paper.FIG4_PEAKS, atol=1e-6)
    assert [list(s) for s in r.stage_speeds] == [["left", "centre", "right"], ["left", "centre"], ["centre"]]
    assert r.confirmed and jr.result_name(r.sequence.result) == "successful"
    for d, sp in zip(r.designs, r.stage_speeds):
        assert d.reached and d.confirmed, d
        assert sp[d.target] >= 5.0 and all(v <= 1.2 for nm, v in sp.items() if nm != d.target), sp
    a, b = r.designs[:2]
    assert b.peaks_deg == a.peaks_deg[::-1]
    assert b.speeds["left"] == pytest.approx(a.speeds["right"], rel=1e-9)
