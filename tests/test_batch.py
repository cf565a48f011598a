"""Honest batches of snap angles: what users write, `jax.vmap(jr.snap_angles)` over scenes
built by `jax.vmap(jr.make_scene)`, gives every member what its single call gives.

One batch of N = 24 scenes holds ordinary snapping members next to every kind of bad one: a
NaN fold angle, a start state that does not exist (the down state at alpha = 0 of a tight
fold at a large gap), a path that does not snap, a state through itself, and (in a second,
small batch, since the `Continuation` settings are shared by the batch) a member that
exhausts its step budget. Each keeps its own code, each equals its single call
`jr.snap_angles(jr.make_scene(psi0, gap, n=N))` (same `snaps`, `kind`, `result`,
`start_result`, `stop`, `refine_result`; alpha_c to 1e-6 deg; NaN exactly where the single
call has NaN), and no member's numbers change with the company it keeps (the good members
are the same, to 1e-9 deg, in a batch of good members only and in another order).

On a CPU the batch runs its members one after another through the single program
(`jaxrod._lanes.in_turn`), the user's default there. Nightly the same tests run the
accelerators' form on the CPU: one vectorized program whose solver loops run on 3 lanes
(`jaxrod._lanes`: fewer lanes than members, so members finish and others take their lanes
mid-run), as a batch larger than the default lanes would.

Four programs are compiled: the single call and the batch, each with the default settings
and with the small step budget (~10 s and ~17 s each on 2 cores at XLA -O0); everything else
reuses them (`batched.lower(scenes).compile()` included)."""

from __future__ import annotations

import functools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr


jax.config.update("jax_enable_x64", True)

N = 24
NAN = float("nan")

# label: (Psi0 deg, G/L), what each member exercises as its single call at N = 24 says
# (checked in `test_members_are_what_they_claim_to_be`)
GOOD = {
    "60/0.5": (60.0, 0.5),     # snaps up at a branch point, down at a fold
    "120/0.6": (120.0, 0.6),   # the same kinds, another place
    "flat": (180.0, 0.5),      # the flat strip: snaps both ways at a branch point
}
BAD = {
    "nan": (NAN, 0.5),         # a NaN fold angle: both paths `nonfinite`
    "no start": (30.0, 0.9),   # no down state at alpha = 0: snap up `start_substituted`
    "no snap": (30.0, 0.8),    # the paper's "no snap" (Psi0 = 30 deg, G/L = 0.8): snap down from the
                               # up state, which exists (snap up `start_substituted` too: the down
                               # state ends near G/L = 0.645)
    "through": (30.0, 0.34),   # contact-free model at a small gap: snap down `self_intersecting`
}
MEMBERS = {**GOOD, **BAD}
LABELS = list(MEMBERS)
IGOOD = [LABELS.index(k) for k in GOOD]

# The step budget: `Continuation(max_points=BUDGET)` stops the down path of Psi0 = 30 deg,
# G/L = 0.9 (27 points to the bound at N = 24) while the others finish well inside it (the
# stage that decides them: 10-13 points, landed branch 12-14)
BUDGET = 20
BUDGET_SETTINGS = jr.Continuation(max_points=BUDGET)
BUDGET_LABELS = ["60/0.5", "no start", "120/0.6"]
BUDGET_BAD = 1

ALPHA_TOL_DEG = 1e-6  # batch vs single call
COMPANY_TOL_DEG = 1e-9  # a member in one batch vs the same member in another
PATHS = ("up", "down")
FIELDS = ("alpha_c", "fold_height_before", "fold_height_after", "jump")  # scalars, NaN where absent


def make_scenes(labels):
    """The batch as users build it: `jax.vmap(jr.make_scene)` over (Psi0, G/L) arrays."""
    p, g = (jnp.asarray(x, jnp.float64) for x in zip(*(MEMBERS[k] for k in labels)))
    return jax.vmap(lambda p, g: jr.make_scene(p, g, n=N))(p, g)


def single_scene(psi0, gap):
    """`jr.make_scene(psi0, gap, n=N)`; a NaN fold angle, which `make_scene` rejects when it
    is concrete, is set on the built scene (traced in the batch, it passes unchecked)."""
    if math.isnan(psi0):
        return eqx.tree_at(lambda s: s.strip.psi0, jr.make_scene(60.0, gap, n=N), jnp.asarray(NAN))
    return jr.make_scene(psi0, gap, n=N)


def code(x, i=None):
    """A RESULTS code (of member i of a batch) as an int."""
    v = np.asarray(x._value)
    return int(v if i is None else v[i])


def path_record(path, i=None):
    """The numbers and codes of one snap path (member i of a batched path), as plain Python."""
    pick = (lambda a: np.asarray(a)) if i is None else (lambda a: np.asarray(a)[i])
    return dict(
        snaps=bool(pick(path.snaps)),
        kind=int(pick(path.kind)),
        result=code(path.result, i),
        start_result=code(path.start_result, i),
        refine_result=code(path.refine_result, i),
        stop=int(pick(path.stop)),
        **{f: float(pick(getattr(path, f))) for f in FIELDS},
    )


def records(r, i=None):
    return {name: path_record(getattr(r, name), i) for name in PATHS}


def describe(rec):
    return {k: (jr.result_name(v) if k.endswith("result") else v) for k, v in rec.items()}


def assert_same_member(got, want, alpha_tol_deg, where):
    """Same codes and kinds, alpha_c within `alpha_tol_deg`, NaN exactly where `want` has NaN
    (every scalar of `FIELDS`); returns |d alpha_c| in degrees (0 where neither snaps)."""
    for k in ("snaps", "kind", "result", "start_result", "refine_result", "stop"):
        assert got[k] == want[k], (where, k, describe(got), describe(want))
    for f in FIELDS:
        assert math.isnan(got[f]) == math.isnan(want[f]), (where, f, got[f], want[f])
    if math.isnan(want["alpha_c"]):
        return 0.0
    d = abs(math.degrees(got["alpha_c"] - want["alpha_c"]))
    assert d <= alpha_tol_deg, (where, "alpha_c deg", math.degrees(got["alpha_c"]), math.degrees(want["alpha_c"]))
    return d


# ---------------------------------------------------------------------------- fixtures

@pytest.fixture(scope="module", autouse=True,
                params=["in_turn", pytest.param("vectorized", marks=pytest.mark.slow)])
def mode(request):
    """The batch's form (read when a batch is traced): the platform's default (`in_turn` on a
    CPU), or the accelerators' vectorized program with its loops on 3 lanes."""
    from jaxrod import _lanes

    key = jax.default_backend()
    saved = [(table, dict(table)) for table in (_lanes.LANES, _lanes.MIN_QUEUE)]
    saved_turn = _lanes.IN_TURN
    if request.param == "vectorized":
        _lanes.LANES[key], _lanes.MIN_QUEUE[key] = 3, 0
        _lanes.IN_TURN = ()
    yield request.param
    _lanes.IN_TURN = saved_turn
    for table, old in saved:
        table.clear()
        table.update(old)


@pytest.fixture(scope="module")
def batched(mode):
    """What users write: one `jax.jit` of `jax.vmap(jr.snap_angles)` (the default settings),
    compiled once for the batch size of `MEMBERS` and reused by every batch of that size."""
    return jax.jit(jax.vmap(jr.snap_angles))


@pytest.fixture(scope="module")
def scenes(mode):
    return make_scenes(LABELS)


@pytest.fixture(scope="module")
def batch(batched, scenes):
    return jax.block_until_ready(batched(scenes))


@pytest.fixture(scope="module")
def singles():
    """Each member's own single call, `jr.snap_angles(jr.make_scene(psi0, gap, n=N))`, by label."""
    return {k: records(jr.snap_angles(single_scene(*MEMBERS[k]))) for k in LABELS}


@pytest.fixture(scope="module")
def budget(mode):
    """The small batch under `Continuation(max_points=BUDGET)` (its own program, the settings
    being static), the same batch with the exhausted member replaced by a copy of the first,
    and the members' single calls with the same settings."""
    run = jax.jit(jax.vmap(functools.partial(jr.snap_angles, settings=BUDGET_SETTINGS)))
    mixed = jax.block_until_ready(run(make_scenes(BUDGET_LABELS)))
    good = [k if i != BUDGET_BAD else BUDGET_LABELS[0] for i, k in enumerate(BUDGET_LABELS)]
    alone = jax.block_until_ready(run(make_scenes(good)))
    one = [records(jr.snap_angles(single_scene(*MEMBERS[k]), settings=BUDGET_SETTINGS)) for k in BUDGET_LABELS]
    return mixed, alone, one


# ---------------------------------------------------------------------------- tests

def test_members_are_what_they_claim_to_be(singles):
    """The scenes exercise what the batch tests claim (read off their single calls at N = 24,
    so a change of the model that moves a member out of its regime fails here, by name, rather
    than leaving the batch tests vacuous): the good members snap both ways with successful
    codes (the flat strip at a branch point both ways, the creased ones up at a branch point and
    down at a fold); the NaN member is `nonfinite` on both paths (start and path) and reports
    no number; at Psi0 = 30 deg, G/L = 0.9 the down state does not exist at alpha = 0, so snap
    up starts from the end of snap down (`start_substituted`; `start_result` says whether a
    path's own start existed) and neither path snaps; at G/L = 0.8 (the paper's no-snap case)
    neither path snaps: kind none, successful, stopped at the bound |alpha| = pi; at
    G/L = 0.34 snap down passes through itself (`self_intersecting`, the contact-free model)
    while snap up is a clean branch point."""
    R = jr.RESULTS
    ok = code(R.successful)
    for k in GOOD:
        for name in PATHS:
            p = singles[k][name]
            assert p["snaps"] and p["result"] == ok and p["start_result"] == ok, (k, name, describe(p))
    assert singles["flat"]["up"]["kind"] == singles["flat"]["down"]["kind"] == 2
    for k in ("60/0.5", "120/0.6"):
        assert singles[k]["up"]["kind"] == 2 and singles[k]["down"]["kind"] == 1, k
    for name in PATHS:
        p = singles["nan"][name]
        assert p["result"] == p["start_result"] == code(R.nonfinite), describe(p)
        assert not p["snaps"] and p["kind"] == 0 and all(math.isnan(p[f]) for f in FIELDS)
    p = singles["no start"]
    assert p["up"]["start_result"] == code(R.start_substituted), describe(p["up"])
    assert p["down"]["start_result"] == ok, describe(p["down"])
    for k in ("no start", "no snap"):
        for name in PATHS:
            q = singles[k][name]
            assert not q["snaps"] and q["kind"] == 0 and q["result"] == ok, (k, name, describe(q))
            assert q["stop"] == 1 and math.isnan(q["alpha_c"])  # reached the bound
    assert singles["no snap"]["down"]["start_result"] == ok
    p = singles["through"]
    assert p["down"]["snaps"] and p["down"]["result"] == code(R.self_intersecting), describe(p["down"])
    assert p["up"]["snaps"] and p["up"]["result"] == ok, describe(p["up"])


def test_every_member_equals_its_single_call(batch, singles):
    """Every member of the mixed batch, good or bad, gets what its own single call gets: the
    same `snaps`, `kind`, `result`, `start_result`, `refine_result` and `stop` on both paths,
    alpha_c within 1e-6 deg (measured: 2.1e-12 deg at most), and NaN in alpha_c, the fold
    heights before and after and the jump exactly where the single call has NaN. So a bad
    member keeps its own code and spreads nothing to the others, and nothing the batch does
    (its while loops run until the slowest member is done, the others masked) shows in a
    member's result."""
    worst = 0.0
    for i, k in enumerate(LABELS):
        got = records(batch, i)
        for name in PATHS:
            worst = max(worst, assert_same_member(got[name], singles[k][name], ALPHA_TOL_DEG, (k, name)))
    print(f"max |d alpha_c| batch vs single: {worst:.3g} deg")


def test_no_member_changes_with_its_company(batched, scenes, batch):
    """No member's numbers change with the company it keeps: the good members of the mixed
    batch equal (alpha_c to 1e-9 deg, every code, the NaN pattern) the same members in a batch
    of the same size whose bad members are replaced by copies of a good scene (Psi0 = 60 deg,
    G/L = 0.5; the same compiled program), the copies equal that member, and every member
    equals itself in the mixed batch reversed (measured: identical to the bit)."""
    first = LABELS[IGOOD[0]]
    good_only = [k if i in IGOOD else first for i, k in enumerate(LABELS)]
    alone = jax.block_until_ready(batched(make_scenes(good_only)))
    rev = jax.block_until_ready(batched(jax.tree.map(lambda x: x[::-1], scenes)))
    n = len(LABELS)
    worst = 0.0
    for i, k in enumerate(LABELS):
        want = records(batch, i)
        got = records(alone, i)
        for name in PATHS:
            ref = want[name] if i in IGOOD else records(batch, IGOOD[0])[name]
            worst = max(worst, assert_same_member(got[name], ref, COMPANY_TOL_DEG, (good_only[i], name, "good only")))
        got = records(rev, n - 1 - i)
        for name in PATHS:
            worst = max(worst, assert_same_member(got[name], want[name], COMPANY_TOL_DEG, (k, name, "reversed")))
    print(f"max |d alpha_c| across company: {worst:.3g} deg")


def test_member_that_exhausts_its_step_budget(budget):
    """A member whose continuation needs more points than the batch's shared
    `Continuation(max_points=20)` (Psi0 = 30 deg, G/L = 0.9: its snap-down path runs 27 points
    to the bound at N = 24) is `continuation_incomplete` (buffer full, `stop` 0), with no
    angle: not a silent "no snap"; its snap up, started from where that incomplete path ended
    (`start_substituted`), is incomplete too. Its neighbours finish inside the budget and snap
    with successful codes. Every member equals its single call with the same settings, and
    the neighbours' numbers are the same (1e-9 deg) in a batch without the exhausted member."""
    mixed, alone, one = budget
    R = jr.RESULTS
    assert one[BUDGET_BAD]["down"]["stop"] == 0  # the buffer filled
    assert one[BUDGET_BAD]["up"]["start_result"] == code(R.start_substituted)
    worst = 0.0
    for i, k in enumerate(BUDGET_LABELS):
        got = records(mixed, i)
        for name in PATHS:
            worst = max(worst, assert_same_member(got[name], one[i][name], ALPHA_TOL_DEG, (k, name, "budget")))
            if i == BUDGET_BAD:
                assert got[name]["result"] == code(R.continuation_incomplete), describe(got[name])
                assert not got[name]["snaps"] and math.isnan(got[name]["alpha_c"])
            else:
                assert got[name]["snaps"] and got[name]["result"] == code(R.successful), describe(got[name])
                other = records(alone, i)[name]
                worst = max(worst, assert_same_member(other, got[name], COMPANY_TOL_DEG,
                                                      (k, name, "budget, good only")))
    print(f"max |d alpha_c| (budget batch): {worst:.3g} deg")


def test_budget_changes_nothing_for_members_inside_it(budget, singles):
    """The small step budget is only a buffer size for the members that finish inside it: their
    codes and alpha_c (to 1e-9 deg) are those of the default settings."""
    mixed, _, _ = budget
    for i, k in enumerate(BUDGET_LABELS):
        if i != BUDGET_BAD:
            got = records(mixed, i)
            for name in PATHS:
                assert_same_member(got[name], singles[k][name], COMPANY_TOL_DEG, (k, name))


def test_lower_compile_is_jaxs_own(batched, scenes, batch):
    """`jax.jit(jax.vmap(jr.snap_angles)).lower(scenes).compile()` works: `lower` is JAX's own
    (an instance attribute `lower` on jaxrod's entry point would be copied onto the vmapped
    function by `functools.wraps` and trace the unbatched call with batched scenes), and the
    compiled program gives the plain batched call's numbers to the last bit."""
    assert "lower" not in getattr(batched, "__dict__", {})  # nothing shadows PjitFunction.lower
    lowered = batched.lower(scenes)
    assert isinstance(lowered, jax.stages.Lowered)
    got = jax.block_until_ready(lowered.compile()(scenes))
    for i, k in enumerate(LABELS):
        for name in PATHS:
            assert_same_member(records(got, i)[name], records(batch, i)[name], 0.0, (k, name, "compiled"))


def test_no_nonfinite_number_reported_as_success(batch, budget):
    """Across both batches: a path that snaps has a finite alpha_c and a kind; one that does
    not has alpha_c NaN and kind none; a successful snapping path has finite fold heights
    before the snap and after it (it landed); the NaN member reports nothing as successful."""
    mixed, _, _ = budget
    ok = code(jr.RESULTS.successful)
    for r, labels in ((batch, LABELS), (mixed, BUDGET_LABELS)):
        for i, k in enumerate(labels):
            for name, p in records(r, i).items():
                if p["snaps"]:
                    assert math.isfinite(p["alpha_c"]) and p["kind"] in (1, 2), (k, name, describe(p))
                else:
                    assert math.isnan(p["alpha_c"]) and p["kind"] == 0, (k, name, describe(p))
                if p["snaps"] and p["result"] == ok:
                    assert math.isfinite(p["fold_height_before"]) and math.isfinite(p["fold_height_after"]), \
                        (k, name, describe(p))
                if k == "nan":
                    assert p["result"] != ok and p["start_result"] != ok, (k, name, describe(p))
