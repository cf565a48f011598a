"""Property-based tests (hypothesis) over the input domain of the statics and dynamics.

The promise under test: every result either passes its own independent check or carries a
non-success code (`jr.RESULTS`); never NaN or inf with success; under `vmap` one failing
member never changes another.

Profiles (registered below, chosen with the environment variable HYPOTHESIS_PROFILE):

* ``ci`` (default): derandomized (fixed seeds, the same examples every run), a few examples
  per property; the whole file runs in about a minute on 2 cores, most of it compiling.
* ``nightly``: derandomized too, many more examples. The nightly target runs
  ``HYPOTHESIS_PROFILE=nightly pytest -m slow tests/test_properties.py``: every property has a
  ``*_nightly`` variant marked ``slow`` (deselected by default) that runs the same check with
  the nightly example count and, where it costs another compilation, a wider domain (N in
  {24, 32} instead of 24, the snap-down path and the whole domain for the gradient, the down
  state under vmap, simulate on a float32 scene). The CI tests take the profile's count too, so the
  ``nightly`` profile also enlarges them.

Compilation dominates: every new array shape or static argument compiles the solvers again
(seconds each), so N is drawn from a fixed set and every float parameter reaches the jitted
entry points as a (weakly typed) array leaf of the scene built by `jr.make_scene`; the same
compiled programs then serve every example (`test_new_parameter_values_compile_nothing`).
The checks themselves run in NumPy from the mesh fractions (segment lengths: end condition,
fold height, clearance, mirror images), or through three small jitted helpers compiled once
per N (the dense reduced Hessian, the gradient of `jr.lagrangian`, the bending energy).
"""

from __future__ import annotations

import math
import os

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, event, example, given, note, settings
from hypothesis import strategies as st

import jaxrod as jr
from helpers import count_compiles


# ----------------------------------------------------------------------------------------
# profiles

_COMMON = dict(derandomize=True, deadline=None, database=None, print_blob=True,
               suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much,
                                      HealthCheck.data_too_large])
settings.register_profile("ci", max_examples=8, **_COMMON)
settings.register_profile("nightly", max_examples=200, **_COMMON)
PROFILE = os.environ.get("HYPOTHESIS_PROFILE", "ci")
settings.load_profile(PROFILE)

# examples per test: (ci, nightly). The ``*_nightly`` variants always take the nightly count.
EXAMPLES = {
    "equilibrium": (16, 1000),
    "mirror": (8, 300),
    "flat_mirror": (4, 200),
    "snap": (12, 600),
    "flat_snap": (3, 100),
    "gradient": (2, 60),
    "float32": (2, 30),
    "vmap": (3, 150),
    "trajectory": (3, 150),
    "huge_step": (2, 40),
}


def examples(name, nightly=False):
    ci, night = EXAMPLES[name]
    return night if (nightly or PROFILE == "nightly") else ci


# ----------------------------------------------------------------------------------------
# domain

# Mesh sizes: every (N, entry point, static argument) is one compilation of seconds
# (initial_state: ~4 s per N and state, snap_angles ~10 s, its gradient ~15 s). CI runs
# everything at N = 24; the nightly variants draw N from {24, 32} (equilibria, mirror images,
# snap angles). With N = 32 in CI too the file took 54-66 s instead of 46-56 s (2 shared
# cores): over the budget of about a minute.
N_SNAP = 24
NS_CI = (N_SNAP,)
NS_NIGHTLY = (24, 32)
DEG = math.pi / 180.0

# Plain bounded floats (hypothesis draws the bounds themselves now and then); the named
# extremes (Psi0 = 1, 5, 179.9, 180 deg; G/L = 0.02, 0.98; s0 = 0.008, 0.2) are explicit
# `@example`s, which run in every profile. (Drawing them half of the time through
# `st.one_of(st.sampled_from(...), ...)` spent most CI examples on self-intersecting
# strips at G/L = 0.02, which are flagged and so check little.)
psi0s = st.floats(0.5, 180.0, allow_nan=False, allow_infinity=False)
gaps = st.floats(0.02, 0.98, allow_nan=False, allow_infinity=False)
# from a quarter of the segment length of the finer mesh (1/32) to 0.2
s0s = st.floats(0.008, 0.2, allow_nan=False, allow_infinity=False)
alphas = st.floats(-60.0, 60.0, allow_nan=False, allow_infinity=False)
states = st.sampled_from(["up", "down"])


def scene(psi0, gap, alpha=0.0, s0=0.02, n=24, alpha_right=None):
    """`jr.make_scene` from Python floats: each becomes a weakly typed 0-d array leaf, the
    same abstract value for every example (one compilation per N and static argument)."""
    ar = None if alpha_right is None else float(alpha_right)
    return jr.make_scene(float(psi0), float(gap), float(alpha), alpha_right_deg=ar, s0=float(s0), n=n)


def msg(code):
    """The RESULTS message of a 0-d code (or 'successful')."""
    m = jr.RESULTS[code]
    return m if m else "successful"


def ok(code):
    return bool(code == jr.RESULTS.successful)


def short(code):
    """The first words of a code's message, for hypothesis' statistics (`event`)."""
    return " ".join(msg(code).split()[:5])


# ----------------------------------------------------------------------------------------
# independent checks (NumPy from the mesh fractions; the dense Hessian and the Lagrangian
# gradient through small jitted helpers, compiled once per N)


def seg_lengths(sc):
    return np.diff(np.asarray(sc.mesh.fractions)) * float(sc.strip.length)


def end_error(theta, sc):
    """(sum h cos theta - G, sum h sin theta): the right end's distance from the clamp."""
    h, th = seg_lengths(sc), np.asarray(theta)
    return float(np.sum(h * np.cos(th)) - float(sc.clamps.gap)), float(np.sum(h * np.sin(th)))


def mid_height(theta, sc):
    """y(L/2): the crease node's height, summed over the left half."""
    h, th = seg_lengths(sc), np.asarray(theta)
    k = sc.mesh.n // 2
    return float(np.sum(h[:k] * np.sin(th[:k])))


def clearance(theta, sc):
    """The smallest distance between non-neighbouring segments (|i - j| >= 2) of the polygon
    of `theta`, 0 where two of them cross: NumPy, all pairs (cf. `jaxrod.clearance`)."""
    h, th = seg_lengths(sc), np.asarray(theta)
    x = np.concatenate([np.zeros((1, 2)), np.cumsum(np.stack([h * np.cos(th), h * np.sin(th)], 1), 0)])
    i, j = np.triu_indices(th.shape[0], k=2)
    a, b, c, d = x[i], x[i + 1], x[j], x[j + 1]

    def orient(p, q, r):
        u, v = q - p, r - p
        return u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]

    crossing = ((np.sign(orient(a, b, c)) * np.sign(orient(a, b, d)) < 0)
                & (np.sign(orient(c, d, a)) * np.sign(orient(c, d, b)) < 0))

    def to_segment(p, a, b):
        e = b - a
        t = np.clip(np.sum((p - a) * e, 1) / np.sum(e * e, 1), 0.0, 1.0)
        return np.linalg.norm(p - a - t[:, None] * e, axis=1)

    dist = np.minimum.reduce([to_segment(c, a, b), to_segment(d, a, b), to_segment(a, c, d), to_segment(b, c, d)])
    return float(np.min(np.where(crossing, 0.0, dist)))


# the library flags a state whose clearance is <= 1e-9 L (`jaxrod.energy.contact.TOL`): a successful
# state has more, a flagged one (crossing or touching) less than the margin below
CLEAR_TOL = 1e-9


def check_flag(code, thetas, sc, where):
    """A `self_intersecting` code is confirmed by the NumPy clearance of one of `thetas`."""
    if bool(code == jr.RESULTS.self_intersecting):
        c = min(clearance(t, sc) for t in thetas)
        assert c <= 2 * CLEAR_TOL, f"{where}: flagged self_intersecting, but the clearance is {c:.3e}"


def _strong(sc):
    """The scene with float64 (not weakly typed) leaves, as the solvers return it: one
    cache entry of the jitted helpers for every scene, built or returned."""
    return jtu.tree_map(lambda x: jnp.asarray(x, jnp.float64) if eqx.is_array_like(x) else x, sc)


@eqx.filter_jit
def _dense(theta, force, sc):
    eq = jr.Equilibrium(theta, force, jr.RESULTS.successful, jnp.zeros((), jnp.int32),
                        jnp.zeros((), jnp.int32), sc)
    return jr.dense_reduced_hessian(eq)


_fold_height = eqx.filter_jit(jr.fold_height)


@eqx.filter_jit
def _grad_lagrangian(theta, force, sc):
    return jax.grad(jr.lagrangian, argnums=(0, 1))(theta, force, sc)


@eqx.filter_jit
def _bending(theta, sc):
    eq = jr.Equilibrium(theta, jnp.zeros(2, theta.dtype), jr.RESULTS.successful, jnp.zeros((), jnp.int32),
                        jnp.zeros((), jnp.int32), sc)
    return jr.bending_energy(eq)


def dense_eigs(theta, force, sc):
    """Eigenvalues (ascending) and eigenvectors in angle space of the dense reduced Hessian
    Z^T T Z (Z: an orthonormal basis of the end condition's null space, by QR; the same
    spectrum as the library's constrained pencil)."""
    theta, force, sc = jnp.asarray(theta, jnp.float64), jnp.asarray(force, jnp.float64), _strong(sc)
    H = np.asarray(_dense(theta, force, sc))
    lam, V = np.linalg.eigh(0.5 * (H + H.T))
    # back to angle space: Z from the same QR as dense_reduced_hessian, in NumPy
    h = seg_lengths(sc)
    th = np.asarray(theta)
    P = np.stack([-h * np.sin(th), h * np.cos(th)], axis=1)
    q, _ = np.linalg.qr(P, mode="complete")
    modes = q[:, 2:] @ V
    return lam, modes


def residual(theta, force, sc):
    """Max |dL/dtheta| L/B and max |dL/dmu| / L, recomputed from `jr.lagrangian`."""
    gt, gm = _grad_lagrangian(jnp.asarray(theta, jnp.float64), jnp.asarray(force, jnp.float64), _strong(sc))
    st_ = sc.strip
    return (float(jnp.max(jnp.abs(gt))) * float(st_.length) / float(st_.bending_stiffness),
            float(jnp.max(jnp.abs(gm))) / float(st_.length))


def parity(mode):
    """Overlap of a mode with its mirror image -v[::-1]: +1 symmetric, -1 asymmetric."""
    v = np.asarray(mode) / np.linalg.norm(mode)
    return float(np.sum(v * -v[::-1]))


def asymmetry(theta):
    """max |theta_i + theta_{N+1-i}|: zero for a mirror-symmetric state."""
    th = np.asarray(theta)
    return float(np.max(np.abs(th + th[::-1])))


END_TOL = 1e-8  # end condition (Newton's gtol is 1e-9 on it)
RES_TOL = 1e-8  # Lagrangian gradient (gtol 1e-9; recomputed, so a little slack)
EIG_TOL = 1e-8  # the most negative eigenvalue a stable state may show (units B/L)


def check_equilibrium(eq, sgn, where):
    """The independent checks of a successful equilibrium: finite, end condition, gradient,
    dense stability (matching `num_unstable`), fold height of sign `sgn` (0: not checked)."""
    th, mu, sc = np.asarray(eq.theta), np.asarray(eq.force), eq.scene
    assert np.all(np.isfinite(th)) and np.all(np.isfinite(mu)), f"{where}: non-finite state with success"
    ex, ey = end_error(th, sc)
    assert abs(ex) < END_TOL and abs(ey) < END_TOL, f"{where}: end condition off by ({ex:.3e}, {ey:.3e})"
    rt, rm = residual(th, mu, sc)
    assert rt < RES_TOL and rm < RES_TOL, f"{where}: Lagrangian gradient ({rt:.3e}, {rm:.3e}) with success"
    lam, _ = dense_eigs(th, mu, sc)
    note(f"{where}: dense eigenvalues {lam[:3]}, num_unstable {int(eq.num_unstable)}")
    assert lam[0] > -EIG_TOL * max(1.0, abs(lam[-1])), f"{where}: unstable (dense lambda_min {lam[0]:.3e})"
    assert int(eq.num_unstable) == 0, f"{where}: num_unstable {int(eq.num_unstable)} with success"
    c = clearance(th, sc)
    assert c > 0.5 * CLEAR_TOL, f"{where}: successful state passes through itself (clearance {c:.3e})"
    if sgn:
        y = mid_height(th, sc)
        assert sgn * y > 0, f"{where}: fold height {y:.3e} of the wrong sign"
        y_lib = float(_fold_height(eq))
        assert abs(y_lib - y) < 1e-12, f"{where}: jr.fold_height {y_lib} but y(L/2) = {y}"
    return lam


# ----------------------------------------------------------------------------------------
# 1. equilibria


@st.composite
def equilibrium_cases(draw, ns=NS_CI):
    n = draw(st.sampled_from(ns))
    alpha = draw(alphas)
    alpha_right = draw(st.one_of(st.none(), alphas))  # None: symmetric clamps
    return dict(n=n, state=draw(states), psi0=draw(psi0s), gap=draw(gaps), s0=draw(s0s), alpha=alpha,
                alpha_right=alpha_right)


def prop_equilibrium(case):
    note(f"case {case}")
    sc = scene(case["psi0"], case["gap"], case["alpha"], case["s0"], case["n"], case["alpha_right"])
    eq = jr.initial_state(sc, case["state"])
    note(f"result: {msg(eq.result)}")
    event(f"initial_state {case['state']} N={case['n']}: {short(eq.result)}")
    check_flag(eq.result, [eq.theta], sc, f"initial_state {case}")
    if not ok(eq.result):
        return None  # flagged: nothing to check
    check_equilibrium(eq, 1.0 if case["state"] == "up" else -1.0, f"initial_state {case}")
    return eq


_EXTREMES = [  # the named extremes, at N = 24 and (nightly) again at N = 32
    dict(state="up", psi0=180.0, gap=0.5, s0=0.02, alpha=0.0, alpha_right=None),
    dict(state="down", psi0=1.0, gap=0.5, s0=0.02, alpha=0.0, alpha_right=None),
    dict(state="up", psi0=5.0, gap=0.98, s0=0.2, alpha=60.0, alpha_right=None),
    dict(state="down", psi0=179.9, gap=0.02, s0=0.008, alpha=-60.0, alpha_right=None),
    dict(state="up", psi0=60.0, gap=0.98, s0=0.008, alpha=-60.0, alpha_right=60.0),
    dict(state="down", psi0=30.0, gap=0.8, s0=0.02, alpha=0.0, alpha_right=None),
    dict(state="down", psi0=179.9, gap=0.98, s0=0.2, alpha=60.0, alpha_right=None),
    dict(state="up", psi0=5.0, gap=0.02, s0=0.2, alpha=-60.0, alpha_right=-60.0),
    dict(state="up", psi0=90.0, gap=0.3, s0=0.008, alpha=30.0, alpha_right=-10.0),
]


@settings(max_examples=examples("equilibrium"))
@given(equilibrium_cases())
def test_equilibrium_passes_check_or_is_flagged(case):
    """`initial_state` over Psi0 in (0, 180], G/L in (0, 1), s0 from below the segment
    length to 0.2, clamp angles in [-60, 60] deg (symmetric or not), N = 24 (nightly: 24, 32): success
    means finite, end condition to 1e-8, Lagrangian gradient < 1e-8, every eigenvalue of the
    dense reduced Hessian > -1e-8 (asymmetric modes included) and `num_unstable == 0`, fold
    height of the requested sign."""
    prop_equilibrium(case)


@pytest.mark.slow
@settings(max_examples=examples("equilibrium", nightly=True))
@given(equilibrium_cases(ns=NS_NIGHTLY))
def test_equilibrium_passes_check_or_is_flagged_nightly(case):
    prop_equilibrium(case)


for _c in _EXTREMES:
    test_equilibrium_passes_check_or_is_flagged = example(dict(_c, n=24))(test_equilibrium_passes_check_or_is_flagged)
    test_equilibrium_passes_check_or_is_flagged_nightly = example(dict(_c, n=32))(
        test_equilibrium_passes_check_or_is_flagged_nightly)


# ----------------------------------------------------------------------------------------
# 2. mirror symmetry


MIRROR_TOL = 1e-8


@st.composite
def mirror_cases(draw, ns=NS_CI):
    return dict(n=draw(st.sampled_from(ns)), state=draw(states), psi0=draw(psi0s), gap=draw(gaps),
                s0=draw(s0s), alpha=draw(alphas))


def prop_mirror(case):
    """Symmetric clamps: the state is mirror symmetric (theta = -theta[::-1]) to 1e-8, or it is
    an asymmetric state whose mirror image is an equilibrium too (gradient < 1e-8, stable by
    the dense check, the same energy)."""
    note(f"case {case}")
    eq = prop_equilibrium(dict(case, alpha_right=None))
    if eq is None:
        return
    a = asymmetry(eq.theta)
    note(f"asymmetry max|theta + theta[::-1]| = {a:.3e}")
    event("mirror-symmetric state" if a < MIRROR_TOL else "asymmetric state")
    if a < MIRROR_TOL:
        return
    # an asymmetric state: its mirror image (with the mirrored end force) is an equilibrium
    th_m = -np.asarray(eq.theta)[::-1]
    mu = np.asarray(eq.force)
    mu_m = np.array([mu[0], -mu[1]])
    rt, rm = residual(th_m, mu_m, eq.scene)
    where = f"asymmetric state (asymmetry {a:.3e}) {case}"
    assert rt < RES_TOL and rm < RES_TOL, f"{where}: its mirror image is no equilibrium ({rt:.3e}, {rm:.3e})"
    lam, _ = dense_eigs(th_m, mu_m, eq.scene)
    assert lam[0] > -EIG_TOL * max(1.0, abs(lam[-1])), f"{where}: mirror image unstable ({lam[0]:.3e})"
    e, e_m = (float(_bending(jnp.asarray(t), _strong(eq.scene))) for t in (eq.theta, th_m))
    assert abs(e - e_m) <= 1e-10 * max(1.0, abs(e)), f"{where}: mirror image's energy {e_m} != {e}"


@settings(max_examples=examples("mirror"))
@given(mirror_cases())
@example(dict(n=24, state="up", psi0=180.0, gap=0.5, s0=0.02, alpha=30.0))
@example(dict(n=24, state="down", psi0=60.0, gap=0.3, s0=0.02, alpha=-20.0))
def test_symmetric_clamps_give_mirror_symmetric_states(case):
    prop_mirror(case)


@pytest.mark.slow
@settings(max_examples=examples("mirror", nightly=True))
@given(mirror_cases(ns=NS_NIGHTLY))
def test_symmetric_clamps_give_mirror_symmetric_states_nightly(case):
    prop_mirror(case)


def prop_flat_mirror(n, gap, s0, alpha):
    """Flat strip (Psi0 = 180): y -> -y maps the up state at alpha onto the down state at
    -alpha, so theta_down(-alpha) = -theta_up(alpha) where both exist."""
    note(f"flat strip: n={n}, gap={gap}, s0={s0}, alpha={alpha}")
    up = jr.initial_state(scene(180.0, gap, alpha, s0, n), "up")
    down = jr.initial_state(scene(180.0, gap, -alpha, s0, n), "down")
    note(f"up: {msg(up.result)}; down at -alpha: {msg(down.result)}")
    if not (ok(up.result) and ok(down.result)):
        return
    check_equilibrium(up, 1.0, "flat up")
    check_equilibrium(down, -1.0, "flat down at -alpha")
    d = float(np.max(np.abs(np.asarray(up.theta) + np.asarray(down.theta))))
    assert d < MIRROR_TOL, f"flat strip n={n} gap={gap} alpha={alpha}: up(alpha) != -down(-alpha) by {d:.3e}"


@settings(max_examples=examples("flat_mirror"))
@given(st.sampled_from(NS_CI), gaps, s0s, alphas)
def test_flat_strip_up_and_down_are_reflections(n, gap, s0, alpha):
    prop_flat_mirror(n, gap, s0, alpha)


@pytest.mark.slow
@settings(max_examples=examples("flat_mirror", nightly=True))
@given(st.sampled_from(NS_NIGHTLY), gaps, s0s, alphas)
def test_flat_strip_up_and_down_are_reflections_nightly(n, gap, s0, alpha):
    prop_flat_mirror(n, gap, s0, alpha)


# ----------------------------------------------------------------------------------------
# 3. snap angles (polish=False: the bisection value, one compilation at N = 24)

# |lambda_min| at the reported critical state, relative to the spectrum's largest |lambda|.
# The bisection stops ~2^-24 of a continuation step from the critical point, where the
# lowest eigenvalue (which vanishes linearly in arclength there) is ~1e-8 B/L, against
# max|lambda| ~ 90-130 B/L at N = 24, 32. Measured over 181 snapping paths (uniform
# Psi0 in (0.5, 180), G/L in (0.02, 0.98), s0 in (0.008, 0.2), N = 24 and 32):
# |lambda_min| / max|lambda| <= 1.1e-9 (median 1.1e-10), the next eigenvalue
# lambda_2 / max|lambda| >= 5.5e-5. 1e-6 lies three decades above the one and
# fifty times below the other.
CRIT_REL = 1e-6
SYM_TOL = 1e-6  # the library's own test of a mirror-symmetric critical state


@st.composite
def snap_cases(draw, ns=(N_SNAP,)):
    return dict(n=draw(st.sampled_from(ns)), psi0=draw(psi0s), gap=draw(gaps), s0=draw(s0s))


def check_path(path, name, case, other=None):
    """The independent checks of one `SnapPath` (`name`: 'up' or 'down')."""
    sgn = 1.0 if name == "up" else -1.0
    res, snaps, ac = path.result, bool(path.snaps), float(path.alpha_c)
    where = f"snap {name} {case}"
    note(f"{name}: result {msg(res)!r}, start {msg(path.start_result)!r}, snaps {snaps}, "
         f"alpha_c {math.degrees(ac) if np.isfinite(ac) else ac} deg, kind {int(path.kind)}, jump {float(path.jump)}")
    event(f"{name}: {short(res)}; start {short(path.start_result)}; snaps {snaps}; kind {int(path.kind)}")
    sc0 = scene(case["psi0"], case["gap"], 0.0, case["s0"], case["n"])
    # the reported states: critical, landed, and every computed point of the stages up to the
    # deciding one
    stages = [np.asarray(path.branch.theta[s, :int(path.branch.count[s])]) for s in range(int(path.stage) + 1)]
    reported = [path.theta_before] + ([path.theta_after] if snaps else []) + [t for st_ in stages for t in st_]
    check_flag(res, reported, sc0, where)
    if not ok(res):
        return  # flagged
    c = min(clearance(t, sc0) for t in reported)
    assert c > 0.5 * CLEAR_TOL, f"{where}: successful, but a reported state crosses itself ({c:.3e})"
    if not snaps:
        assert np.isnan(ac), f"{where}: successful, no snap, but alpha_c = {ac}"
        assert int(path.kind) == 0, f"{where}: no snap but kind {int(path.kind)}"
        assert np.isnan(float(path.jump)), f"{where}: no snap but jump {float(path.jump)}"
        return
    assert np.isfinite(ac), f"{where}: snaps with success but alpha_c = {ac}"
    assert abs(ac) <= math.pi, f"{where}: |alpha_c| = {abs(ac)} > pi"
    if ok(path.start_result):
        assert sgn * ac > 0, f"{where}: alpha_c = {ac} has the wrong sign"
    else:  # start_substituted: the path starts from the snap-down path's end, below alpha_c_down
        assert path.start_result == jr.RESULTS.start_substituted, msg(path.start_result)
        # it starts where the snap-down path landed (alpha_c_down - 1e-3), or at the end of its
        # branch (-bound = -pi) where that path did not snap, and increases alpha from there
        lo = float(other.alpha_c) - 1e-3 if bool(other.snaps) else -math.pi
        assert ac > lo - 1e-9, f"{where}: substituted start at {lo}, but alpha_c = {ac}"
    kind = int(path.kind)
    assert kind in (1, 2), f"{where}: snaps but kind {kind}"
    th, mu = np.asarray(path.theta_before), np.asarray(path.force_before)
    assert np.all(np.isfinite(th)) and np.all(np.isfinite(mu)), f"{where}: non-finite critical state"
    # the critical state is an equilibrium of the scene at alpha_c ...
    sc_c = scene(case["psi0"], case["gap"], math.degrees(ac), case["s0"], case["n"])
    ex, ey = end_error(th, sc_c)
    assert abs(ex) < END_TOL and abs(ey) < END_TOL, f"{where}: critical state's end off ({ex:.3e}, {ey:.3e})"
    rt, rm = residual(th, mu, sc_c)
    assert rt < RES_TOL and rm < RES_TOL, f"{where}: critical state's gradient ({rt:.3e}, {rm:.3e})"
    # ... whose dense constrained Hessian is singular: one eigenvalue ~ 0, the rest positive
    lam, modes = dense_eigs(th, mu, sc_c)
    scale = float(np.max(np.abs(lam)))
    note(f"{name}: critical eigenvalues {lam[:3]}, max |lambda| {scale:.3e}, ratio {abs(lam[0]) / scale:.2e}")
    assert abs(lam[0]) < CRIT_REL * scale, \
        f"{where}: critical state not singular: lambda_min {lam[0]:.3e}, max|lambda| {scale:.3e}"
    assert lam[1] > CRIT_REL * scale, f"{where}: a second critical eigenvalue {lam[1]:.3e}"
    # kind: branch point iff the critical mode is mirror-asymmetric (at a symmetric state)
    p, asym = parity(modes[:, 0]), asymmetry(th)
    note(f"{name}: mode parity {p:.6f}, state asymmetry {asym:.3e}")
    if kind == 2:
        assert asym < SYM_TOL and p < -0.99, f"{where}: branch point but parity {p}, asymmetry {asym:.2e}"
    else:
        assert asym >= SYM_TOL or p > 0.99, f"{where}: fold but parity {p}, asymmetry {asym:.2e}"
    # the jump and the landed state: finite, an equilibrium at alpha_c + sgn 1e-3, stable
    jump = float(path.jump)
    assert np.isfinite(jump) and jump > 0, f"{where}: snaps but jump {jump}"
    if kind == 2:
        assert jump > 0.1, f"{where}: a branch-point snap that lands {jump} away (<= JUMP_DISTANCE)"
    ta, ma = np.asarray(path.theta_after), np.asarray(path.force_after)
    assert np.all(np.isfinite(ta)) and np.all(np.isfinite(ma)), f"{where}: non-finite landed state"
    c = clearance(ta, sc0)
    assert c > 0.5 * CLEAR_TOL, f"{where}: successful, but its landed state crosses itself ({c:.3e})"
    sc_a = scene(case["psi0"], case["gap"], math.degrees(ac + sgn * 1e-3), case["s0"], case["n"])
    rt, rm = residual(ta, ma, sc_a)
    assert rt < RES_TOL and rm < RES_TOL, f"{where}: landed state's gradient ({rt:.3e}, {rm:.3e})"
    lam_a, _ = dense_eigs(ta, ma, sc_a)
    assert lam_a[0] > -EIG_TOL * max(1.0, abs(lam_a[-1])), f"{where}: landed state unstable ({lam_a[0]:.3e})"


def prop_snap(case):
    note(f"case {case}")
    r = jr.snap_angles(scene(case["psi0"], case["gap"], 0.0, case["s0"], case["n"]), polish=False)
    check_path(r.down, "down", case)
    check_path(r.up, "up", case, other=r.down)
    return r


@settings(max_examples=examples("snap"))
@given(snap_cases())
@example(dict(n=N_SNAP, psi0=60.0, gap=0.5, s0=0.02))
@example(dict(n=N_SNAP, psi0=30.0, gap=0.8, s0=0.02))
@example(dict(n=N_SNAP, psi0=180.0, gap=0.98, s0=0.02))
@example(dict(n=24, psi0=1.0, gap=0.25, s0=0.125))  # through itself between its start and its snap
def test_snap_angles_pass_check_or_are_flagged(case):
    """`snap_angles(polish=False)` over (Psi0, G/L, s0) at N = 24, each path: success and a
    snap means a finite alpha_c of the path's sign, |alpha_c| <= pi, a critical state that is
    an equilibrium at alpha_c with a singular dense Hessian (one eigenvalue ~ 0), kind 2 iff
    its null mode is mirror-asymmetric, a stable landed state; success and no snap means
    alpha_c NaN, kind none. `self_intersecting` is confirmed, and success checked, on every
    reported state: critical, landed, and each computed point of the deciding stages."""
    prop_snap(case)


@pytest.mark.slow
@settings(max_examples=examples("snap", nightly=True))
@given(snap_cases(ns=NS_NIGHTLY))
def test_snap_angles_pass_check_or_are_flagged_nightly(case):
    prop_snap(case)


def prop_flat_snap(n, gap):
    """Flat strip: alpha_c_down = -alpha_c_up (to 1e-8 rad), the same kind and snap flag."""
    case = dict(n=n, psi0=180.0, gap=gap, s0=0.02)
    r = prop_snap(case)
    if not (ok(r.up.result) and ok(r.down.result)):
        return
    assert bool(r.up.snaps) and bool(r.down.snaps), f"flat strip {case}: a path without a snap"
    d = float(r.up.alpha_c) + float(r.down.alpha_c)
    assert abs(d) < 1e-8, f"flat strip {case}: alpha_c_up + alpha_c_down = {d:.3e} rad"
    assert int(r.up.kind) == int(r.down.kind), (int(r.up.kind), int(r.down.kind))


@settings(max_examples=examples("flat_snap"))
@given(st.sampled_from([N_SNAP]), gaps)
@example(N_SNAP, 0.5)
def test_flat_strip_snaps_symmetrically(n, gap):
    prop_flat_snap(n, gap)


@pytest.mark.slow
@settings(max_examples=examples("flat_snap", nightly=True))
@given(st.sampled_from(NS_NIGHTLY), gaps)
def test_flat_strip_snaps_symmetrically_nightly(n, gap):
    prop_flat_snap(n, gap)


# ----------------------------------------------------------------------------------------
# 4. gradients of alpha_c (polish=True): jax.grad against central differences


def _alpha_c(psi0_deg, gap, s0, path):
    r = jr.snap_angles(jr.make_scene(psi0_deg, gap, 0.0, s0=s0, n=N_SNAP))
    p = getattr(r, path)
    return p.alpha_c, (p.result, p.snaps, p.kind)


# one compiled value-and-gradient per path; the differences reuse it (no vmap: a batched
# snap_angles would be one more compilation)
_value_and_grad = {path: jax.jit(jax.value_and_grad(lambda a, b, c, path=path: _alpha_c(a, b, c, path),
                                                    has_aux=True))
                   for path in ("up", "down")}
# Step in Psi0 (deg). d alpha_c / d Psi0 is small (~3e-4 rad/deg at Psi0 = 60, G/L = 0.5),
# so the rounding error of the polished alpha_c weighs more than usual: measured there, the
# relative error of the central difference is 7e-8 at helpers.FD_STEP = eps^(1/3) = 6e-6 deg,
# 6e-9 at 1e-4, 3e-10 at 1e-3, 4e-8 at 1e-2 and 4e-6 at 1e-1 (truncation). 1e-3 deg; over the
# whole domain (114 snapping paths, both directions) the largest relative error was 8e-9.
PSI_STEP = 1e-3
GRAD_REL = 1e-4


def prop_gradient(path, psi0, gap, s0):
    case = dict(path=path, psi0=psi0, gap=gap, s0=s0)
    note(f"case {case}")
    vg = _value_and_grad[path]
    args = lambda p: (jnp.asarray(p), jnp.asarray(gap), jnp.asarray(s0))  # noqa: E731
    (ac, (res, snaps, kind)), g = vg(*args(psi0))
    note(f"alpha_c {float(ac)}, result {msg(res)!r}, snaps {bool(snaps)}, kind {int(kind)}, grad {float(g)}")
    event(f"{path}: {short(res)}; snaps {bool(snaps)}")
    if bool(res == jr.RESULTS.derivative_unavailable):  # documented: the bisection value, gradient zero
        assert float(g) == 0.0, f"{case}: derivative_unavailable, but the gradient reads {float(g)}"
    if bool(snaps):
        # the polished value against the bisection (polish=False): "within ~1e-8 rad" (measured
        # <= 9.8e-9 over 149 snapping paths); 1e-7 rad
        bis = getattr(jr.snap_angles(scene(psi0, gap, 0.0, s0, N_SNAP), polish=False), path)
        if bool(bis.snaps):
            d = abs(float(ac) - float(bis.alpha_c))
            assert d < 1e-7, f"{case}: polished alpha_c {float(ac)} is {d:.3e} rad from the bisection value"
    if not (ok(res) and bool(snaps)):
        return
    assert np.isfinite(float(g)), f"{case}: successful snapping path, non-finite gradient {float(g)}"
    h = (psi0 + PSI_STEP) - psi0
    (ap, (rp, sp, kp)), _ = vg(*args(psi0 + h))
    (am, (rm, sm, km)), _ = vg(*args(psi0 - h))
    # the difference is meaningful only where both neighbours snap the same way
    assume(ok(rp) and ok(rm) and bool(sp) and bool(sm) and int(kp) == int(kind) == int(km))
    fd = (float(ap) - float(am)) / (2 * h)
    err = abs(float(g) - fd)
    note(f"fd {fd}, |grad - fd| {err:.3e}")
    assert err <= GRAD_REL * abs(fd) + 1e-10, \
        f"{case}: d alpha_c/d Psi0 = {float(g)!r} but central difference {fd!r} (rel {err / abs(fd):.2e})"


grad_psi0s = st.floats(20.0, 175.0, allow_nan=False, allow_infinity=False)
grad_gaps = st.floats(0.2, 0.7, allow_nan=False, allow_infinity=False)
grad_s0s = st.floats(0.015, 0.06, allow_nan=False, allow_infinity=False)


@pytest.mark.slow  # 20 s; CI checks the refinement's gradients, snap_angles' own (test_critical.py)
@settings(max_examples=examples("gradient"))
@given(grad_psi0s, grad_gaps, grad_s0s)
@example(60.0, 0.5, 0.02)
def test_alpha_c_gradient_matches_central_difference(psi0, gap, s0):
    """d alpha_c,up / d Psi0 by `jax.grad` through `snap_angles` (polished) equals the central
    difference to 1e-4 relative, wherever the path snaps successfully (and does so with the
    same kind at Psi0 +- h); the polished alpha_c lies within 1e-7 rad of the bisection value
    (`polish=False`); `derivative_unavailable` reads a zero gradient, as documented. CI: a
    moderate domain (the polish compiles once, ~15 s); nightly: the whole domain, both paths."""
    prop_gradient("up", psi0, gap, s0)


@pytest.mark.slow
@settings(max_examples=examples("gradient", nightly=True))
@given(st.sampled_from(["up", "down"]), psi0s, gaps, s0s)  # the whole domain (measured: rel. error <= 8e-9)
def test_alpha_c_gradient_matches_central_difference_nightly(path, psi0, gap, s0):
    prop_gradient(path, psi0, gap, s0)


# ----------------------------------------------------------------------------------------
# 5. float32


def _float32(sc):
    return jtu.tree_map(lambda x: jnp.asarray(x, jnp.float32) if eqx.is_array(x) else x, sc)


def prop_float32(psi0, gap, full):
    """The documented behaviour: `snap_angles` refuses a float32 scene and `simulate` float32
    angles, with a ValueError naming float64 (`require_float64` and simulate's own check, both
    at trace time). `full` (nightly): also `simulate` on a float32 scene with float64 angles,
    which must be refused too (the mesh would be discretized in float32)."""
    note(f"psi0={psi0}, gap={gap}")
    sc = scene(psi0, gap, 0.0, 0.02, N_SNAP)
    sc32 = _float32(sc)
    with pytest.raises(ValueError, match="float64"):
        jr.snap_angles(sc32, polish=False)
    with pytest.raises(ValueError, match="float64"):
        jr.snap_angles(sc32)
    with pytest.raises(ValueError, match="float64"):
        jr.simulate(sc, jnp.zeros(N_SNAP, jnp.float32), jr.Protocol(), t1=T1)
    if not full:
        return
    eq = jr.initial_state(sc, "up")
    assume(ok(eq.result))
    with pytest.raises(ValueError, match="float64"):
        jr.simulate(sc32, eq.theta, jr.Protocol(), t1=T1, direction=jnp.asarray(-1.0))


@settings(max_examples=examples("float32"))
@given(psi0s, gaps)
def test_float32_is_refused_by_name(psi0, gap):
    prop_float32(psi0, gap, full=False)


@pytest.mark.slow
@settings(max_examples=examples("float32", nightly=True))
@given(st.floats(30.0, 180.0), st.floats(0.3, 0.7))
def test_float32_is_refused_by_name_nightly(psi0, gap):
    prop_float32(psi0, gap, full=True)


# ----------------------------------------------------------------------------------------
# 6. vmap: one bad member changes no other

BATCH = 4


def _batched(state):
    def one(psi0, gap, alpha, s0):
        return jr.initial_state(jr.make_scene(psi0, gap, alpha, s0=s0, n=N_SNAP), state)
    return jax.jit(jax.vmap(one))


_batched_initial = {s: _batched(s) for s in ("up", "down")}
BAD = {"nan_psi0": ("psi0", math.nan), "nan_gap": ("gap", math.nan), "gap_above_L": ("gap", 1.5),
       "nan_s0": ("s0", math.nan), "gap_0.999": ("gap", 0.999)}


def prop_vmap(state, members, bad_index, bad):
    """A batch of `initial_state`s (jax.vmap over psi0, gap, alpha, s0) with one member bad
    (NaN or impossible parameters, traced so the constructor cannot refuse them): every
    member's result code, angles and force equal its unbatched solve (1e-12), and a NaN or
    impossible member is flagged."""
    cols = {k: [m[k] for m in members] for k in ("psi0", "gap", "alpha", "s0")}
    key, value = BAD[bad]
    cols[key][bad_index] = value
    note(f"state {state}, batch {cols}, bad member {bad_index} ({bad})")
    eb = _batched_initial[state](*(jnp.asarray(cols[k]) for k in ("psi0", "gap", "alpha", "s0")))
    codes = np.asarray(eb.result._value)
    event(f"bad member {bad}: {short(jax.tree.map(lambda x: x[bad_index], eb.result))}")
    note(f"batched result codes {codes.tolist()}")
    for i in range(BATCH):
        good = scene(180.0 if i == bad_index and key == "psi0" else cols["psi0"][i],
                     0.5 if i == bad_index and key == "gap" else cols["gap"][i], cols["alpha"][i],
                     0.02 if i == bad_index and key == "s0" else cols["s0"][i], N_SNAP)
        if i == bad_index:  # the bad value as a leaf, past the constructor's checks
            leaf = {"psi0": lambda s: s.strip.psi0, "gap": lambda s: s.clamps.gap, "s0": lambda s: s.strip.s0}[key]
            v = value * DEG if key == "psi0" else value
            good = eqx.tree_at(leaf, good, jnp.asarray(float(v)))
        es = jr.initial_state(good, state)
        where = f"member {i} of {cols} (bad {bad_index}: {bad})"
        assert int(codes[i]) == int(es.result._value), \
            f"{where}: batched code {int(codes[i])} != unbatched {int(es.result._value)} ({msg(es.result)!r})"
        if ok(es.result):
            np.testing.assert_allclose(np.asarray(eb.theta[i]), np.asarray(es.theta), rtol=0, atol=1e-12,
                                       err_msg=where)
            np.testing.assert_allclose(np.asarray(eb.force[i]), np.asarray(es.force), rtol=0,
                                       atol=1e-12 * max(1.0, float(np.max(np.abs(np.asarray(es.force))))),
                                       err_msg=where)
            assert int(eb.num_unstable[i]) == int(es.num_unstable) == 0, where
            check_equilibrium(es, 1.0 if state == "up" else -1.0, where)
    if bad != "gap_0.999":  # NaN or G > L: no state (0.999: a valid, nearly straight strip)
        assert not ok(jax.tree.map(lambda x: x[bad_index], eb.result)), \
            f"bad member {bad_index} ({bad}) reported success: {cols}"
    if bad.startswith("nan_"):  # a NaN parameter is a bad input, not a missing state
        assert int(codes[bad_index]) == int(jr.RESULTS.nonfinite._value), \
            f"bad member {bad_index} ({bad}): {msg(jax.tree.map(lambda x: x[bad_index], eb.result))!r}"


vmap_members = st.lists(st.fixed_dictionaries(dict(
    psi0=st.floats(10.0, 180.0, allow_nan=False), gap=st.floats(0.1, 0.9, allow_nan=False),
    alpha=st.floats(-30.0, 30.0, allow_nan=False), s0=st.floats(0.01, 0.1, allow_nan=False))),
    min_size=BATCH, max_size=BATCH)


_MEMBERS = [dict(psi0=60.0, gap=0.5, alpha=0.0, s0=0.02), dict(psi0=90.0, gap=0.4, alpha=10.0, s0=0.03),
            dict(psi0=150.0, gap=0.6, alpha=-10.0, s0=0.05), dict(psi0=30.0, gap=0.45, alpha=5.0, s0=0.02)]


@settings(max_examples=examples("vmap"))
@given(vmap_members, st.integers(0, BATCH - 1), st.sampled_from(sorted(BAD)))
@example(_MEMBERS, 1, "nan_psi0")
@example(_MEMBERS, 3, "nan_gap")
def test_vmap_bad_member_changes_no_other(members, bad_index, bad):
    prop_vmap("up", members, bad_index, bad)


@pytest.mark.slow
@settings(max_examples=examples("vmap", nightly=True))
@given(states, vmap_members, st.integers(0, BATCH - 1), st.sampled_from(sorted(BAD)))
def test_vmap_bad_member_changes_no_other_nightly(state, members, bad_index, bad):
    prop_vmap(state, members, bad_index, bad)


# ----------------------------------------------------------------------------------------
# 7. trajectories

T1 = 0.3  # static (a Python float): one compilation for every run
ENERGY_TOL = 1e-2  # simulate's default energy_tol: the documented bound of a successful run


def perturb(theta, sc, coeffs, eps):
    """theta + a smooth mirror-breaking shape of amplitude ~eps (sum c_k sin(k pi s), with an
    odd k = 1 term: the odd terms are the mirror-asymmetric ones), projected back onto the end
    condition by Gauss-Newton (to 1e-15)."""
    h = seg_lengths(sc)
    s = np.concatenate([[0.0], np.cumsum(h)])
    m = 0.5 * (s[1:] + s[:-1]) / float(sc.strip.length)
    shape = sum(c * np.sin((k + 1) * np.pi * m) for k, c in enumerate(coeffs))
    th = np.asarray(theta) + eps * shape / np.max(np.abs(shape))
    G = float(sc.clamps.gap)
    for _ in range(20):
        c = np.array([np.sum(h * np.cos(th)) - G, np.sum(h * np.sin(th))])
        if np.max(np.abs(c)) < 1e-15:
            break
        J = np.stack([-h * np.sin(th), h * np.cos(th)])
        th = th - J.T @ np.linalg.solve(J @ J.T, c)
    return jnp.asarray(th)


@st.composite
def trajectory_cases(draw):
    c1 = draw(st.floats(0.3, 1.0)) * draw(st.sampled_from([-1.0, 1.0]))  # the mirror-breaking k = 1 term
    rest = draw(st.lists(st.floats(-1.0, 1.0, allow_nan=False), min_size=3, max_size=3))
    return dict(state=draw(states), psi0=draw(st.floats(30.0, 180.0)), gap=draw(st.floats(0.3, 0.7)),
                alpha=draw(st.floats(-20.0, 20.0)), coeffs=[c1] + rest, eps=draw(st.floats(1e-3, 3e-2)))


def start_of(case):
    sc = scene(case["psi0"], case["gap"], case["alpha"], 0.02, N_SNAP)
    eq = jr.initial_state(sc, case["state"])
    note(f"start state: {msg(eq.result)}")
    event(f"start state {case['state']}: {short(eq.result)}")
    assume(ok(eq.result))
    theta0 = perturb(eq.theta, sc, np.asarray(case["coeffs"]), case["eps"])
    a = case["alpha"] * DEG
    # the opposite direction: the snap-end event (fold past 0 and turning back) cannot fire
    direction = jnp.asarray(-1.0 if case["state"] == "up" else 1.0)
    return sc, theta0, jr.Protocol(a, a), direction


def prop_trajectory(case):
    """A short free run (t1 = 0.3 T, fixed clamps, N = 24) from a stable state perturbed by a
    small mirror-breaking shape: success means finite samples up to t_end, energy balance
    |E_k + V - W - E(0)| <= energy_tol max(|E(0)|, B/L) (W = 0 with fixed clamps, V(0) the
    bending energy of the start), end condition < 1e-9 on the fine grid (step points) and
    < constraint_tol = 1e-6 on the (interpolated) frames."""
    note(f"case {case}")
    sc, theta0, protocol, direction = start_of(case)
    tr = jr.simulate(sc, theta0, protocol, t1=T1, direction=direction)
    where = f"simulate {case}: {msg(tr.result)!r}"
    note(f"result {msg(tr.result)!r}, t_end {float(tr.t_end)}, steps {int(tr.num_steps)}")
    event(f"simulate: {short(tr.result)}")
    if not ok(tr.result):
        return
    t, t_end = np.asarray(tr.t), float(tr.t_end)
    assert np.isfinite(t_end) and 0 < t_end <= T1 + 1e-12, f"{where}: t_end {t_end}"
    Ek, V, W, con = (np.asarray(x) for x in (tr.kinetic, tr.potential, tr.clamp_work, tr.constraint))
    live = t <= t_end * (1 - 1e-12)
    for name, x in (("kinetic", Ek), ("potential", V), ("clamp_work", W), ("constraint", con)):
        assert np.all(np.isfinite(x[live])), f"{where}: non-finite {name} before t_end with success"
    fin = np.isfinite(Ek) & np.isfinite(V) & np.isfinite(W)
    for name in ("v_s", "t_peak", "kinetic_peak", "energy_drift"):
        assert np.isfinite(float(getattr(tr, name))), f"{where}: {name} = {float(getattr(tr, name))} with success"
    assert Ek[0] == 0.0, Ek[0]
    v0 = float(_bending(theta0, _strong(sc)))
    assert abs(V[0] - v0) <= 1e-10 * max(1.0, abs(v0)), f"{where}: V(0) = {V[0]} but E_b(theta0) = {v0}"
    assert np.max(np.abs(W[fin])) == 0.0, f"{where}: clamp work {np.max(np.abs(W[fin]))} with fixed clamps"
    E = Ek + V - W
    drift = float(np.max(np.abs(E[fin] - E[0])))
    scale = max(abs(float(E[0])), 1.0)
    note(f"energy drift {drift:.3e} (relative {drift / scale:.3e}), max constraint {np.max(con[fin]):.3e}")
    assert drift <= ENERGY_TOL * scale, f"{where}: energy balance off by {drift:.3e} (scale {scale:.3e})"
    rel = drift / abs(float(V[0]))  # Trajectory.energy_drift's own definition
    assert abs(float(tr.energy_drift) - rel) <= 1e-9 * max(rel, 1e-6), (float(tr.energy_drift), rel)
    assert np.max(con[np.isfinite(con)]) < 1e-9, f"{where}: constraint {np.max(con[np.isfinite(con)]):.3e}"
    h = seg_lengths(sc)
    th_f = np.asarray(tr.theta)
    okf = np.all(np.isfinite(th_f), axis=1)
    ends = np.stack([np.cos(th_f[okf]) @ h - float(sc.clamps.gap), np.sin(th_f[okf]) @ h])
    # the frames are interpolated (linearly, between RATTLE steps): off the end condition by
    # O(dt^2) (measured 5e-9), within constraint_tol = 1e-6 (the fine grid is exact, above)
    assert np.max(np.abs(ends)) < 1e-6, f"{where}: frames leave the clamp by {np.max(np.abs(ends)):.3e}"


@settings(max_examples=examples("trajectory"))
@given(trajectory_cases())
def test_trajectory_conserves_energy_or_is_flagged(case):
    prop_trajectory(case)


@pytest.mark.slow
@settings(max_examples=examples("trajectory", nightly=True))
@given(trajectory_cases())
def test_trajectory_conserves_energy_or_is_flagged_nightly(case):
    prop_trajectory(case)


def prop_huge_step(case):
    """dt = 1e-2 T (omega_max dt ~ 20, RATTLE is stable below 2), one RATTLE step per diffrax
    step: never a success with garbage, always a stop code."""
    note(f"case {case}")
    sc, theta0, protocol, direction = start_of(case)
    tr = jr.simulate(sc, theta0, protocol, t1=T1, direction=direction, dt=1e-2, substeps=1)
    note(f"result {msg(tr.result)!r}, t_end {float(tr.t_end)}")
    event(f"simulate dt=1e-2: {short(tr.result)}")
    assert not ok(tr.result), f"dt = 1e-2 returned success: {case}, energy_drift {float(tr.energy_drift)}"
    stops = (jr.RESULTS.energy_drift, jr.RESULTS.constraint_drift, jr.RESULTS.constraint_solve_failed,
             jr.RESULTS.nonfinite, jr.RESULTS.integration_failed, jr.RESULTS.steps_exhausted)
    assert any(bool(tr.result == c) for c in stops), f"{case}: not a stop code: {msg(tr.result)!r}"


@settings(max_examples=examples("huge_step"))
@given(trajectory_cases())
def test_huge_step_is_flagged(case):
    prop_huge_step(case)


@pytest.mark.slow
@settings(max_examples=examples("huge_step", nightly=True))
@given(trajectory_cases())
def test_huge_step_is_flagged_nightly(case):
    prop_huge_step(case)


# ----------------------------------------------------------------------------------------
# compilation: new parameter values reuse the compiled programs


def test_new_parameter_values_compile_nothing():
    """After one call per entry point (already compiled by the tests above when the file
    runs as a whole), scenes with new float values compile nothing: `initial_state`,
    `snap_angles(polish=False)`, `simulate` and the checks' helpers."""
    def run(psi0, gap, alpha, s0):
        sc = scene(psi0, gap, alpha, s0, N_SNAP)
        eq = jr.initial_state(sc, "up")
        r = jr.snap_angles(sc, polish=False)
        dense_eigs(eq.theta, eq.force, sc)
        residual(eq.theta, eq.force, sc)
        tr = jr.simulate(sc, eq.theta, jr.Protocol(alpha * DEG, alpha * DEG), t1=T1, direction=jnp.asarray(-1.0))
        return eq, r, tr

    run(60.0, 0.5, 0.0, 0.02)  # warm-up
    with count_compiles() as c:
        eq, r, tr = run(75.0, 0.45, 3.0, 0.03)
        run(150.0, 0.6, -5.0, 0.05)
    assert c[0] == 0, f"{c[0]} compilations for new parameter values"
    assert ok(eq.result) and ok(r.up.result) and ok(tr.result), (msg(eq.result), msg(r.up.result), msg(tr.result))
