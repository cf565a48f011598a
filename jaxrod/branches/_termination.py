r"""Termination gap $G^\ast(\Psi_0)$: the gap beyond which a snapping path no longer snaps.

Beyond $G^\ast$ the fold height varies continuously with $\alpha$, with no loss of stability
(docs/model.md). Each path (snap up, snap down) is located in two stages:

1. the snap criterion of [`jaxrod.snap_angles`][] ("does it snap at this gap") on a grid
   of gaps $G/L\in(0,1)$ (default 0.05, 0.10, ..., 0.95, 0.99): the bracket is the largest
   grid gap that snaps and the next one, which does not; then bisection of that bracket on
   the same yes/no answer down to `tol` in $G/L$ (default $10^{-5}$): `gap_criterion_*`,
   the midpoint of $[G^\ast_-, G^\ast_+]$ (`bracket_*`), consistent with `snap_angles` and
   the phase diagram by construction (`tests/test_termination.py` checks it just below and
   just above);
2. the exact end of what ends the path, from the state at $G^\ast_-$ (below): the cusp of
   the snap-down fold pair, reached by two-parameter continuation of the fold in (G, alpha)
   ([`jaxrod.continue_critical`][]) and solved there, or the fold in G of the path's start
   state. Where it is located, it is the reported `gap_*` (`gap_source_*`:
   "continuation_cusp", "cusp" or "state_fold"); otherwise `gap_*` is the bisection value
   ("bisection").

At a cusp the two nearly agree: `snap_angles` counts every loss of stability at a fold as
a snap however small its jump (docs/model.md), so its criterion holds until the fold pair, and
with it every loss of stability on the path, ends at the cusp, except within 8e-5 to 7e-4
in G/L of it, where the S the branch makes there is shorter than a continuation step at
the default `Continuation()` (measured at n = 100, benchmarks/results/termination.md: at
60 deg the criterion's gap 0.76206, the cusp 0.762395; `ds_max=0.05` resolves it closer). `gap_*` is the cusp itself. Only at a branch point
does a small jump (a landing less than `jaxrod.branches._snap.JUMP_DISTANCE` away, $L^2$ norm of
the angle field) mean "no snap yet": the strip follows the new stable branch (supercritical).
The reported `jump_*` (the fold height change at $G^\ast_-$) says how large the snap still
is there. Where the start state is lost, the two agree to the bisection tolerance too.

What ends each path (`reason_*`):
- `"cusp"`: just below $G^\ast$ the path loses stability at a fold and the jump is small
  (the fold pair meets);
- `"supercritical"`: the last snap is at a branch point with a small jump (the landing
  state joins the critical state);
- `"start_state_lost"`: the path's start state (up state, or the down state at
  $\alpha=0$) stops existing at $G^\ast_+$;
- `"no_termination"`: it still snaps at the largest grid gap ($G^\ast=1$ reported);
- `"flat_strip_never_stops"`: $\Psi_0=180^\circ$ exactly: the flat strip snaps at every
  gap (docs/model.md; the snap is a jump to the other state, whose size relative to the
  buckle amplitude does not shrink as $G\to L$), $G^\ast=1$. Not scanned: near $G=L$
  the absolute jump falls below `JUMP_DISTANCE` (at $G/L\approx0.979$ for n = 100) and
  `snap_angles` would stop resolving it;
- `"never_snaps"`: no grid gap snaps ($G^\ast$ is NaN).

For a path that ends at a cusp the end is located exactly, independent of the jump
criterion: [`jaxrod.cusp_point`][] solves the fold system augmented by the gap and the
vanishing cubic coefficient $\tilde{\mathcal L}^{(3)}[v,v,v]=0$, from the fold at $G^\ast_-$,
giving the cusp gap $G_c$ (above `gap_criterion_*`) and $dG_c/d\Psi_0$ by implicit
differentiation (`cusp_gap_*`, `dcusp_gap_dpsi0_*`). Between `gap_criterion_*` and $G_c$
the fold pair still exists but its jump is below the snap criterion. The same end is also reached by two-parameter
continuation, as a demanding user would compute it: the fold of the largest grid gap that
snaps is followed in (G, alpha) by [`jaxrod.continue_critical`][] until G turns back, which
for a fold curve is exactly the cusp (`curve_end_gap_*`, Hermite estimate of the turn;
`curve_cusp_gap_*`, the cusp solved from the last point before it; `tests/test_termination.py`
checks both against `cusp_gap_*`). For a path whose start state is lost, the end
is likewise located exactly: the start state (up or down at $\alpha=0$) ends at a fold in
$G$ or turns unstable at a symmetry-breaking branch point in $G$; both extended systems of
[`jaxrod.critical_point`][] are solved with the gap as their parameter (at $\alpha=0$), from
the state at $G^\ast_-$ and its lowest symmetric / asymmetric mode, and the one inside the
bracket is kept (`state_end_kind_*`): `state_fold_gap_*` $=G_f$ and
`dstate_fold_gap_dpsi0_*` $=dG_f/d\Psi_0$ by implicit differentiation. There
$G^\ast=G_f$ exactly (the path snaps up to where its start exists). The bisection gap
`gap_criterion_*` ends a discrete search and has no derivative; the exact ends have one
(`dcusp_gap_dpsi0_*`, `dstate_fold_gap_dpsi0_*`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jax import lax
import numpy as np

from .._misc import check_param
from .._compile import jit
from ..model import crease_layout, make_scene
from ..results import RESULTS, result_name


DEFAULT_GRID = tuple(np.round(np.arange(0.05, 0.951, 0.05), 4)) + (0.99,)
SMALL_JUMP = 0.15  # |fold height change| / L below which the end is "continuous"


class TerminationGap(NamedTuple):
    r"""`gap_up`, `gap_down` ($G^\ast/L$: the exact end where located, see `gap_source_*`,
    else the snap criterion's bisection value `gap_criterion_*`; 1.0 where the path never stops snapping, NaN where it
    never snaps), `bracket_up`/`bracket_down` ($(G^\ast_-, G^\ast_+)$), `reason_up`/
    `reason_down` (see the module docstring), `kind_up`/`kind_down` (instability kind at
    $G^\ast_-$: "fold", "branch_point" or "none"), `alpha_c_up`/`alpha_c_down` (rad, at
    $G^\ast_-$), `jump_up`/`jump_down` (fold-height change of the snap at $G^\ast_-$),
    `evaluations` (number of `snap_angles` calls); for a path that ends at a cusp,
    `cusp_gap_*` the exact cusp of the fold pair ([`jaxrod.cusp_point`][], $G_c\ge G^\ast$) and
    `dcusp_gap_dpsi0_*` $dG_c/d\Psi_0$ (per radian, implicit differentiation); for a path
    whose start state is lost, `state_fold_gap_*` the exact gap $G_f$ where that state (at
    $\alpha=0$) ends, `state_end_kind_*` how ("fold" in $G$, or "branch_point": it turns
    unstable through an asymmetric mode; "none" if not located), and
    `dstate_fold_gap_dpsi0_*` $dG_f/d\Psi_0$; NaN otherwise. For a path that ends at a
    cusp, also the end found by two-parameter continuation of its fold in (G, alpha)
    ([`jaxrod.continue_critical`][], from the largest grid gap that snaps):
    `curve_end_reason_*` ("turn" where G turns back: the cusp), `curve_points_*`,
    `curve_end_gap_*` (the turn, Hermite estimate) and `curve_cusp_gap_*` (the cusp solved
    from the last point before the turn). `gap_criterion_*`: the bisection midpoint of the
    snap criterion; `gap_source_*`: where `gap_*` comes from ("continuation_cusp", "cusp",
    "state_fold", "bisection"; "none" without a search).

    `result_up`, `result_down` ([`jaxrod.RESULTS`][]; `result` the first that is not
    successful): `successful` where the end is located (or is a branch point's, to `tol`);
    `end_not_located` where a cusp or a lost start state ends the path but that end was not
    solved (`gap_*` is then the bisection value, up to ~1e-3 below the end, without a
    derivative); `no_snap` where no gap of the grid snaps; `termination_beyond_grid` where
    the largest gap of the grid still snaps; or the code of a `snap_angles` evaluation that
    decides the bracket (or, for `no_snap`, any gap of the grid) under which "snaps / does
    not snap" is unknown (`continuation_incomplete`, `landing_failed`, `nonfinite`, ...)."""

    psi0_deg: float
    gap_up: float
    gap_down: float
    bracket_up: tuple
    bracket_down: tuple
    reason_up: str
    reason_down: str
    kind_up: str
    kind_down: str
    alpha_c_up: float
    alpha_c_down: float
    jump_up: float
    jump_down: float
    evaluations: int
    cusp_gap_up: float = math.nan
    cusp_gap_down: float = math.nan
    dcusp_gap_dpsi0_up: float = math.nan
    dcusp_gap_dpsi0_down: float = math.nan
    state_fold_gap_up: float = math.nan
    state_fold_gap_down: float = math.nan
    dstate_fold_gap_dpsi0_up: float = math.nan
    dstate_fold_gap_dpsi0_down: float = math.nan
    state_end_kind_up: str = "none"
    state_end_kind_down: str = "none"
    curve_end_gap_up: float = math.nan
    curve_end_gap_down: float = math.nan
    curve_cusp_gap_up: float = math.nan
    curve_cusp_gap_down: float = math.nan
    curve_points_up: int = 0
    curve_points_down: int = 0
    curve_end_reason_up: str = "none"
    curve_end_reason_down: str = "none"
    gap_criterion_up: float = math.nan
    gap_criterion_down: float = math.nan
    gap_source_up: str = "none"
    gap_source_down: str = "none"
    result_up: RESULTS = RESULTS.successful
    result_down: RESULTS = RESULTS.successful

    @property
    def result(self):
        """The code of the pair: the first of `result_up`, `result_down` that leaves a G* in
        doubt (neither `successful` nor `no_snap`), else `no_snap` if a path never snaps,
        else `successful`."""
        codes = (self.result_up, self.result_down)
        for c in codes:
            if c != RESULTS.successful and c != RESULTS.no_snap:
                return c
        return RESULTS.no_snap if any(c == RESULTS.no_snap for c in codes) else RESULTS.successful

    def to_dict(self):
        def clean(x):
            if isinstance(x, float) and not math.isfinite(x):
                return None
            if isinstance(x, tuple):
                return [clean(v) for v in x]
            if isinstance(x, type(RESULTS.successful)):
                return result_name(x)
            return x

        return {k: clean(v) for k, v in self._asdict().items()}


def _with_fold(base, psi0, gap=None):
    """`base` with fold angle `psi0` (rad): its centred crease's, or, for a strip with a crease
    layout (`termination_gap(..., creases=...)`), every crease's; and the gap `gap` if given."""
    if base.strip.creases is None:
        sc = eqx.tree_at(lambda s: s.strip.psi0, base, psi0)
    else:
        cr = base.strip.creases
        sc = eqx.tree_at(lambda s: s.strip.creases.angles, base, jnp.full(cr.angles.shape, psi0, jnp.result_type(psi0)))
    return sc if gap is None else eqx.tree_at(lambda s: s.clamps.gap, sc, gap)


@jit
def _snap_at(base, psi0, gap):
    from ._snap import snap_angles

    scene = _with_fold(base, psi0, gap)
    r = snap_angles(scene)
    from ..statics import initial_state

    has_down = initial_state(scene, "down").result == RESULTS.successful
    has_up = initial_state(scene, "up").result == RESULTS.successful

    def summary(p):
        return dict(snaps=p.snaps, alpha=p.alpha_c, kind=p.kind,
                    jump=p.fold_height_after - p.fold_height_before,
                    theta=p.theta_before, force=p.force_before, mode=p.mode, result=p.result._value)

    return dict(up=summary(r.up), down=summary(r.down), has_up=has_up, has_down=has_down)


def termination_gap(psi0_deg, *, s0=0.02, n=100, tol=1e-5, grid=DEFAULT_GRID,
                    progress=False, creases=None, contact=None) -> TerminationGap:
    r"""The termination gaps $G^\ast/L$ of the snap-up and snap-down paths at fold angle
    `psi0_deg` (degrees), by scan + bisection on [`jaxrod.snap_angles`][] (see the module
    docstring), to `tol` in $G/L$. `creases`: crease positions (fractions of L) for a strip
    with a crease of fold angle `psi0_deg` at each instead of the centred crease (as
    `jaxrod.phase_diagram(..., creases=...)`). `contact`: a `jaxrod.Contact` to model
    self-contact at every gap (the termination gaps lie where the strip stays clear of
    itself, so they do not change; the small gaps of the scan then snap as a real strip
    does instead of being flagged `self_intersecting`; each evaluation costs much more, as
    `benchmarks/results/contact.md` shows). Needs float64.

    Returns a [`jaxrod.TerminationGap`][]. One compilation per `(n, s0 dtype)`; each
    evaluation is one `snap_angles` call."""
    from ._snap import KIND_NAMES

    check_param("psi0", psi0_deg, lo=0.0, hi=180.0, hi_open=False, unit=" deg")
    check_param("s0", s0, lo=0.0)
    check_param("tol", tol, lo=0.0)
    if jnp.zeros(()).dtype != jnp.float64 and not jax.config.jax_enable_x64:
        raise ValueError("termination_gap needs float64; enable it with "
                         "jax.config.update('jax_enable_x64', True)")
    check_param("grid", grid, lo=0.0, hi=1.0)
    grid = sorted(float(g) for g in grid)
    if not grid or grid[0] <= 0.0 or grid[-1] >= 1.0:
        raise ValueError(f"grid must hold gaps in (0, 1), got {grid!r}")
    if creases is None:
        base = make_scene(float(psi0_deg), 0.5, s0=s0, n=n, contact=contact)
    else:  # a crease of fold angle Psi0 at each position (fractions of L)
        layout = crease_layout(creases, float(psi0_deg), s0)
        base = make_scene(180.0, 0.5, s0=s0, n=n, creases=[(c, float(psi0_deg)) for c in layout], contact=contact)
    if float(psi0_deg) == 180.0:
        # the flat strip: no crease, the snap at the branch point keeps its size relative to
        # the buckle amplitude as G -> L (tests/test_termination.py checks it snaps at
        # G/L = 0.95 into the other state with a jump > 2x the critical fold height)
        return TerminationGap(180.0, 1.0, 1.0, (math.nan, math.nan), (math.nan, math.nan),
                              "flat_strip_never_stops", "flat_strip_never_stops", "branch_point", "branch_point",
                              math.nan, math.nan, math.nan, math.nan, 0, gap_criterion_up=1.0, gap_criterion_down=1.0)
    psi = jnp.asarray(math.radians(float(psi0_deg)))
    count = [0]
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(desc=f"G*(psi0={psi0_deg:g})", unit="solve")

    def at(g):
        count[0] += 1
        if bar is not None:
            bar.update(1)
        out = jax.device_get(_snap_at(base, psi, jnp.asarray(float(g))))
        return out

    scan = [(g, at(g)) for g in grid]
    results = {}
    for name in ("up", "down"):
        snaps = [bool(o[name]["snaps"]) for _, o in scan]
        if not any(snaps):
            results[name] = dict(gap=math.nan, bracket=(math.nan, math.nan), reason="never_snaps", kind="none",
                                 alpha=math.nan, jump=math.nan,
                                 result=_uncertain([o[name] for _, o in scan], RESULTS.no_snap,
                                                    allow=("self_intersecting",)))
            continue
        i = max(k for k, s in enumerate(snaps) if s)
        if i == len(grid) - 1:
            o = scan[i][1][name]
            results[name] = dict(gap=1.0, bracket=(grid[-1], 1.0), reason="no_termination",
                                 kind=KIND_NAMES[int(o["kind"])], alpha=float(o["alpha"]), jump=float(o["jump"]),
                                 result=_uncertain([o], RESULTS.termination_beyond_grid))
            continue
        lo, hi = grid[i], grid[i + 1]
        o_lo, o_hi = scan[i][1], scan[i + 1][1]
        while hi - lo > tol:
            mid = 0.5 * (lo + hi)
            o = at(mid)
            if bool(o[name]["snaps"]):
                lo, o_lo = mid, o
            else:
                hi, o_hi = mid, o
        p = o_lo[name]
        kind = KIND_NAMES[int(p["kind"])]
        jump = float(p["jump"])
        start_ok = bool(o_hi["has_down"]) if name == "up" else bool(o_hi["has_up"])
        start_ok_lo = bool(o_lo["has_down"]) if name == "up" else bool(o_lo["has_up"])
        if start_ok_lo and not start_ok:
            reason = "start_state_lost"
        elif abs(jump) < SMALL_JUMP:
            reason = "cusp" if kind == "fold" else "supercritical"
        else:
            reason = "snap_vanishes"
        results[name] = dict(gap=0.5 * (lo + hi), bracket=(lo, hi), reason=reason, kind=kind,
                             alpha=float(p["alpha"]), jump=jump,
                             result=_uncertain([p, o_hi[name]] + [o[name] for _, o in scan[i + 2:]],
                                               RESULTS.successful))
        if reason == "cusp":
            results[name].update(_cusp(base, psi, lo, p))
            # the same end by two-parameter continuation of the critical point in (G, alpha),
            # from the largest grid gap where the path snaps (kind fold there too)
            p_grid = scan[i][1][name]
            if KIND_NAMES[int(p_grid["kind"])] == "fold":
                results[name].update(_curve_end(base, psi, grid[i], p_grid))
        elif reason == "start_state_lost":
            results[name].update(_start_fold(base, psi, lo, hi, "down" if name == "up" else "up"))
    if bar is not None:
        bar.close()
    for r in results.values():
        _exact_end(r)
    u, d = results["up"], results["down"]
    nan = math.nan
    return TerminationGap(float(psi0_deg), u["gap"], d["gap"], u["bracket"], d["bracket"], u["reason"], d["reason"],
                          u["kind"], d["kind"], u["alpha"], d["alpha"], u["jump"], d["jump"], count[0],
                          u.get("cusp", nan), d.get("cusp", nan), u.get("dcusp", nan), d.get("dcusp", nan),
                          u.get("state_fold", nan), d.get("state_fold", nan),
                          u.get("dstate_fold", nan), d.get("dstate_fold", nan),
                          u.get("state_end_kind", "none"), d.get("state_end_kind", "none"),
                          u.get("curve_end_gap", nan), d.get("curve_end_gap", nan),
                          u.get("curve_cusp_gap", nan), d.get("curve_cusp_gap", nan),
                          u.get("curve_points", 0), d.get("curve_points", 0),
                          u.get("curve_end_reason", "none"), d.get("curve_end_reason", "none"),
                          u["gap_criterion"], d["gap_criterion"], u["gap_source"], d["gap_source"],
                          u["result"], d["result"])


# path codes under which a snap_angles evaluation still answers "does it snap here" for the
# bisection: its start state missing or substituted (the start_state_lost end), alpha_c without
# a derivative, or a fold pair not resolved next to a cusp (read as "no snap"; the cusp itself
# is then solved, and reported where found, else the end is `end_not_located`)
_DECIDED = ("successful", "state_not_found", "start_substituted", "derivative_unavailable", "fold_unresolved")


def _uncertain(evaluations, otherwise, allow=()):
    """The first code among the snap-criterion `evaluations` (the `_snap_at` summaries that
    decide the answer) under which "snaps / does not snap" is unknown (a continuation cut
    short, a failed landing, a non-finite solve, a state through itself unless `allow`ed),
    else `otherwise`. A scan that never snaps may `allow` self-intersecting states at the
    smallest gaps: those paths do not snap in the contact-free model either."""
    for o in evaluations:
        name = result_name(int(o["result"]))
        if name not in _DECIDED + tuple(allow):
            return getattr(RESULTS, name)
    return otherwise


def _exact_end(r):
    """Report as `gap` the exact end of the path where it was located, keeping the snap
    criterion's bisection midpoint as `gap_criterion`: a cusp end is where the fold curve,
    continued in (G, alpha), turns (`curve_cusp_gap`; the direct cusp solve `cusp` if the
    continuation did not reach it); a lost start state is its fold in G (`state_fold`).
    Where neither was solved the path's `result` is `end_not_located`."""
    r.setdefault("result", RESULTS.successful)
    r["gap_criterion"] = r["gap"]
    r["gap_source"] = "bisection" if r["reason"] in ("cusp", "supercritical", "snap_vanishes",
                                                     "start_state_lost") else "none"
    if r["reason"] == "cusp":
        lo = r["bracket"][0]
        cands = [("cusp", "cusp")]
        if r.get("curve_end_reason") == "turn":
            cands.insert(0, ("curve_cusp_gap", "continuation_cusp"))
        for key, src in cands:
            g = r.get(key, math.nan)
            if math.isfinite(g) and lo - 1e-6 <= g < 1.0:
                r["gap"], r["gap_source"] = g, src
                break
    elif r["reason"] == "start_state_lost" and math.isfinite(r.get("state_fold", math.nan)):
        r["gap"], r["gap_source"] = r["state_fold"], "state_fold"
    if r["reason"] in ("cusp", "start_state_lost") and r["gap_source"] == "bisection" \
            and r["result"] == RESULTS.successful:
        r["result"] = RESULTS.end_not_located


@jit
def _cusp_gap(base, psi0, gap, theta, force, alpha, mode):
    from ._critical import cusp_point

    def g(p):
        scene = _with_fold(base, p, gap)
        cp = cusp_point(scene, theta, force, alpha, mode)
        return cp.gap, cp.result == RESULTS.successful

    gc, dg, ok = jax.jvp(g, (psi0,), (jnp.ones_like(psi0),), has_aux=True)
    return gc, ok, dg


@jit
def _fold_curve(base, psi0, gap, theta, force, alpha, mode):
    """Refine the fold at `gap` and follow it in (G, alpha) to where it turns in G."""
    from ._critical import critical_point
    from ._critical_curve import continue_critical

    scene = _with_fold(base, psi0, gap)
    cp = critical_point(scene, theta, force, alpha, mode, 1)
    c = continue_critical(scene, cp, kind=1)
    return dict(ok=cp.result == RESULTS.successful, end_gap=c.end_gap, end_reason=c.end_reason, count=c.count,
                cusp_gap=c.cusp.gap, cusp_ok=c.cusp.result == RESULTS.successful)


def _curve_end(base, psi, gap, p):
    """Two-parameter continuation of a fold path's critical point from the grid gap `gap`
    (where it snaps) to the end of its curve (the cusp, where G turns)."""
    from ._critical_curve import END_REASONS

    o = jax.device_get(_fold_curve(base, psi, jnp.asarray(gap), jnp.asarray(p["theta"]), jnp.asarray(p["force"]),
                                   jnp.asarray(p["alpha"]), jnp.asarray(p["mode"])))
    if not bool(o["ok"]):
        return {}
    out = dict(curve_end_reason=END_REASONS.get(int(o["end_reason"]), "none"), curve_points=int(o["count"]),
               curve_end_gap=float(o["end_gap"]))
    if bool(o["cusp_ok"]):
        out["curve_cusp_gap"] = float(o["cusp_gap"])
    return out


def _cusp(base, psi, gap, p):
    """Refine a fold path's end to the cusp of its fold pair, with dG_c/dPsi0."""
    gc, ok, dg = jax.device_get(_cusp_gap(base, psi, jnp.asarray(gap), jnp.asarray(p["theta"]),
                                          jnp.asarray(p["force"]), jnp.asarray(p["alpha"]), jnp.asarray(p["mode"])))
    if not bool(ok) or not gap - 1e-6 <= float(gc) < 1.0:
        return {}
    return dict(cusp=float(gc), dcusp=float(dg))


@jit
def _state_fold_gap(base, psi0, gap, sgn):
    """Where the up (`sgn` +1) or down (-1) state at alpha = 0 ends as the gap grows: a fold
    in G (Moore-Spence system of `jaxrod.critical_point`, the gap as its parameter, from the
    state's lowest mirror-symmetric mode) or a symmetry-breaking branch point in G (the
    reduced system, from its lowest asymmetric mode), both from the state at `gap`, with
    jvp in Psi0 (implicit differentiation). Returns (gaps, ok, dgaps/dPsi0) for (fold, branch
    point)."""
    from ..linalg import kkt
    from ._continuation import Gap
    from ._critical import critical_point
    from ..statics import initial_state_signed
    from ..statics import mode_parity

    sc0 = _with_fold(base, psi0, gap)
    eq = initial_state_signed(lax.stop_gradient(sc0), sgn)
    K = kkt.structured(eq.theta, eq.force, lax.stop_gradient(sc0))
    v = kkt.modes(K, kkt.smallest_eigenvalues(K, 4))
    par = mode_parity(v)
    v_sym = v[:, jnp.argmax(par > 0)]  # the lowest symmetric and the lowest asymmetric mode
    v_asym = v[:, jnp.argmax(par < 0)]

    def g(p):
        sc = _with_fold(sc0, p)
        out, ok = [], []
        for mode, kind in ((v_sym, 1), (v_asym, 2)):
            cp = critical_point(sc, eq.theta, eq.force, gap, mode, kind, parameter=Gap())
            out.append(cp.alpha)
            ok.append((cp.result == RESULTS.successful) & (eq.result == RESULTS.successful))
        return jnp.stack(out), jnp.stack(ok)

    gf, dg, ok = jax.jvp(g, (psi0,), (jnp.ones_like(psi0),), has_aux=True)
    return gf, ok, dg


def _start_fold(base, psi, lo, hi, state):
    """Where the path's start state (`state` at alpha = 0) stops existing (as a stable
    state): the fold or branch point in G of that state, started at the last gap `lo` where
    it exists; accepted only inside the bisection bracket [lo, hi] (to 1e-6), so it is that
    state's end and no other critical point (the first one if both are)."""
    gf, ok, dg = jax.device_get(_state_fold_gap(base, psi, jnp.asarray(lo), 1.0 if state == "up" else -1.0))
    cands = [(float(gf[i]), float(dg[i]), name) for i, name in enumerate(("fold", "branch_point"))
             if bool(ok[i]) and lo - 1e-6 <= float(gf[i]) <= hi + 1e-6]
    if not cands:
        return {}
    g, d, kind = min(cands)
    return dict(state_fold=g, dstate_fold=d, state_end_kind=kind)
