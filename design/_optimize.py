r"""Optimization loops: Levenberg-Marquardt (default) or any optax transformation, over a
batch of starts advanced together (one compiled call per iteration that evaluates every
start: `vmap`-ed, or one after the other with `lax.map`, see `optimize`'s `batch_size`).

Unknowns are the unconstrained $z$ of a [`Parametrization`][] (every iterate feasible).
Residuals $r(z)$ and their Jacobian $J = \partial r/\partial z$ (forward mode through the
implicit derivatives) come from one call per iteration.

* `"lm"`: trial step $\delta = -(J^\top J + \lambda\,\mathrm{diag}(J^\top J) + \lambda\epsilon I)^{-1}J^\top r$,
  capped at $\|\delta\|_\infty\le 2$; the trial is accepted if $\tfrac12\|r\|^2$ decreases
  ($\lambda\leftarrow\lambda/3$), otherwise rejected ($\lambda\leftarrow 4\lambda$).
* optax: `updates = opt.update(J^T r, state, z)`; every feasible iterate is taken.

Each start's snap paths start from its previous iterate's critical points
(`jaxrod.snap_angles(..., near=)`: Newton on the extended system, accepted only where its checks
hold, the whole path walked elsewhere): the same iterates as walking every path, in less than half
the time (benchmarks/results/warm.md). Across devices (`batch_size="devices"`) every path is walked.

A start stops when it *reaches* the targets to `stop_fraction` of their tolerances, when
$\|J^\top r\|_\infty <$ `gtol` (stationary: the target is not reachable from there), when
$\lambda >10^{10}$ (no descent), or after `max_iter` iterations. A design whose residual
is not finite (a state or a snap that does not exist there) is infeasible; such trial
steps are rejected, and a start that is infeasible from the beginning is reported so.
"""

from __future__ import annotations

import functools
import json
import math
import sys
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import jaxrod as jr
from jaxrod.branches import unusable_near
from jaxrod.results import result_from_name, result_name

from ._objectives import evaluate_terms, evaluate_terms_near, term_key, term_numbers
from ._params import NAMES, Parametrization

STATUS = ("running", "reached", "stationary", "no_descent", "max_iter", "infeasible_start")


class _Terms:
    """The terms of a problem, compared and hashed by structure only (`term_key`): the
    static part of a `Problem`, so that problems differing only in targets, tolerances or
    weights (which `Problem.numbers` carries as an array) share one compiled program."""

    def __init__(self, terms):
        self.terms = tuple(terms)
        self._key = tuple(term_key(t) for t in self.terms)

    def __eq__(self, other):
        return isinstance(other, _Terms) and self._key == other._key

    def __hash__(self):
        return hash(self._key)


class Problem(eqx.Module):
    """Terms (a tuple of objective terms), a parametrization and the mesh size `n`.
    `numbers`: the terms' (target, tol, weight), a traced array (see `_Terms`)."""

    structure: _Terms = eqx.field(static=True)
    numbers: jax.Array
    param: Parametrization = eqx.field(static=True)
    n: int = eqx.field(static=True, default=40)

    def __init__(self, terms, param, n=40):
        self.structure = _Terms(terms)
        self.numbers = term_numbers(self.structure.terms)
        self.param = param
        self.n = n

    @property
    def terms(self):
        return self.structure.terms

    def residuals(self, z):
        psi0, gap, s0 = self.param.to_design(z)
        return evaluate_terms(self.terms, psi0, gap, s0, self.n, self.numbers)

    def linearize(self, z, near=None):
        """(r, J, values, codes) at z (codes: each term's `jaxrod.RESULTS` value). With `near`
        (what the previous iterate's snap paths left, `design.Critical.near`; see
        `jaxrod.snap_angles(..., near=)`), the snap paths start from that design's critical
        points, and this design's are returned too: (r, J, values, codes, near)."""
        def f(zz):
            psi0, gap, s0 = self.param.to_design(zz)
            r, v, c, nxt = evaluate_terms_near(self.terms, psi0, gap, s0, self.n, self.numbers, near)
            return r, (r, v, c, nxt)

        J, (r, v, c, nxt) = jax.jacfwd(f, has_aux=True)(z)
        return (r, J, v, c) if near is None else (r, J, v, c, nxt)


@eqx.filter_jit
def _linearize_batch(problem, z, batch_size=None, near=None):
    """(r, J, values, codes) of every start: the one compiled call per iteration. `batch_size`
    None: one `vmap` over all starts; an int: `lax.map` over chunks of that many starts,
    each chunk `vmap`-ed (the same values; bounds the batch that XLA:CPU's batched LAPACK
    kernels see, and the memory). `near` (one per start, or None): see `Problem.linearize`;
    with it the starts' new `near` is returned as a fifth output."""
    if near is None:
        if batch_size is None or batch_size >= z.shape[0]:
            return jax.vmap(problem.linearize)(z)
        return jax.lax.map(problem.linearize, z, batch_size=batch_size)
    one = lambda a: problem.linearize(*a)  # noqa: E731
    if batch_size is None or batch_size >= z.shape[0]:
        return jax.vmap(one)((z, near))
    return jax.lax.map(one, (z, near), batch_size=batch_size)


@functools.lru_cache(maxsize=8)
def _sharded(static, per_device):
    """The starts split across every device (`jaxrod.ShardedMap`): one per problem structure."""
    return jr.ShardedMap(lambda z, dyn: eqx.combine(dyn, static).linearize(z), per_device=per_device)


def _linearize_sharded(problem, z):
    """`_linearize_batch` with the starts split across every device JAX sees (and every
    process after `jax.distributed.initialize()`), `ceil(B / devices)` on each."""
    dyn, static = eqx.partition(problem, eqx.is_array)
    per_device = -(-z.shape[0] // jax.device_count())
    out, _ = _sharded(static, per_device)(np.asarray(z), dyn)
    return out


def _linearize(problem, z, batch_size, near=None):
    """`_linearize_batch` (with `near`: also the starts' new `near`), or split across devices
    (which does not warm-start: `near` is passed on unchanged)."""
    if batch_size == "devices":
        out = _linearize_sharded(problem, z)
        return out if near is None else (*out, near)
    return _linearize_batch(problem, z, batch_size, near)


def _first_near(problem, B):
    """One unusable `near` per start: the first iterate walks its paths (a problem whose terms
    need no snap angle passes it on unchanged)."""
    one = unusable_near(problem.n, jnp.result_type(float))
    return jax.tree.map(lambda x: jnp.broadcast_to(x, (B, 2) + x.shape), one)


def auto_batch_size():
    """`batch_size="auto"`: "devices" (the starts split across devices) where JAX sees more
    than one; else 1 (one start after the other) on the CPU backend, where a large `vmap` is
    slower and can deadlock XLA:CPU, and None (one `vmap`) elsewhere."""
    if jax.device_count() > 1:
        return "devices"
    return 1 if jax.default_backend() == "cpu" else None


def linearize(problem: Problem, z, *, batch_size: int | str | None = "auto"):
    """`Problem.linearize` at the designs `z` (shape (B, P), unconstrained): `(r, J, values,
    codes)`, each with a leading axis B. The evaluation `optimize` runs once per iteration
    (its snap paths walked from the start, without the warm start of `near`), batched as
    `optimize`'s `batch_size` says (the same choices and default)."""
    if isinstance(batch_size, str) and batch_size == "auto":
        batch_size = auto_batch_size()
    return _linearize(problem, jnp.asarray(z), batch_size)


def _loss(r):
    with np.errstate(over="ignore", invalid="ignore"):
        loss = 0.5 * np.sum(r**2, axis=-1)
    return np.where(np.isfinite(loss), loss, np.inf)


def _reached(problem, values, frac):
    targets = np.array([t.target for t in problem.terms])
    tols = np.array([t.tol for t in problem.terms])
    with np.errstate(invalid="ignore"):
        return np.all(np.abs(values - targets) <= frac * tols, axis=-1)


@eqx.filter_jit
def _optax_update(optimizer, g, opt_state, z):
    return jax.vmap(optimizer.update)(g, opt_state, z)


class _Loop:
    """Host-side bookkeeping of the batch (small arrays: B x P); the heavy work is
    `_linearize_batch`."""

    def __init__(self, problem, z0, optimizer, stop_fraction, gtol, max_iter, batch_size=None):
        self.problem, self.opt = problem, optimizer
        self.frac, self.gtol, self.max_iter = stop_fraction, gtol, max_iter
        self.batch_size = batch_size
        # each start's snap paths start from its previous iterate's (`jaxrod.snap_angles(..., near=)`)
        near = _first_near(problem, z0.shape[0])
        out = _linearize(problem, z0, batch_size, near)
        r, J, v, c = (np.asarray(a) for a in out[:4])
        self.near = None if near is None else jax.tree.map(np.asarray, out[4])
        self.z, self.r, self.J, self.values, self.codes = np.asarray(z0), r, J, v, c
        self.loss = _loss(r)
        B = z0.shape[0]
        self.lam = np.full(B, 1e-3)
        self.it = np.zeros(B, int)
        self.status = np.where(np.isfinite(self.loss), np.where(_reached(problem, v, stop_fraction), 1, 0), 5)
        self.opt_state = None if optimizer is None else jax.vmap(optimizer.init)(jnp.asarray(z0))

    def _gradient(self, r, J):
        return np.einsum("bij,bi->bj", J, np.where(np.isfinite(r), r, 0.0))

    def step(self):
        g = self._gradient(self.r, self.J)
        if self.opt is None:
            A = np.einsum("bij,bik->bjk", self.J, self.J)
            P = A.shape[-1]
            D = np.einsum("bjj->bj", A)[:, :, None] * np.eye(P) + 1e-9 * np.eye(P)
            A = A + self.lam[:, None, None] * D
            with np.errstate(all="ignore"):
                dz = -np.linalg.solve(A, g[..., None])[..., 0]
                scale = np.minimum(1.0, 2.0 / (np.max(np.abs(dz), axis=1) + 1e-300))
            dz = np.where(np.isfinite(dz), dz * scale[:, None], 0.0)
            opt_state = None
        else:
            dz, opt_state = _optax_update(self.opt, jnp.asarray(g), self.opt_state, jnp.asarray(self.z))
            dz = np.asarray(dz)
        running = self.status == 0
        z_new = self.z + np.where(running[:, None], dz, 0.0)
        out = _linearize(self.problem, jnp.asarray(z_new), self.batch_size, self.near)
        r, J, v, c = (np.asarray(a) for a in out[:4])
        loss = _loss(r)
        # LM accepts descent only; optax follows its own trajectory, refusing infeasible iterates
        accept = running & ((loss < self.loss) if self.opt is None else np.isfinite(loss))
        self.lam = np.where(running, np.where(accept, np.maximum(self.lam / 3.0, 1e-12), self.lam * 4.0), self.lam)
        a1 = accept[:, None]
        self.z = np.where(a1, z_new, self.z)
        self.r = np.where(a1, r, self.r)
        self.J = np.where(accept[:, None, None], J, self.J)
        self.values = np.where(a1, v, self.values)
        self.codes = np.where(a1, c, self.codes)
        self.loss = np.where(accept, loss, self.loss)
        if self.near is not None:
            self.near = jax.tree.map(
                lambda n, o: np.where(np.reshape(accept, (-1,) + (1,) * (np.ndim(n) - 1)), n, o),
                jax.tree.map(np.asarray, out[4]), self.near)
        if opt_state is not None:
            self.opt_state = jax.tree.map(
                lambda n, o: jnp.where(jnp.reshape(jnp.asarray(running), (-1,) + (1,) * (n.ndim - 1)), n, o),
                opt_state, self.opt_state)
        self.it = self.it + running
        gnorm = np.max(np.abs(self._gradient(self.r, self.J)), axis=1)
        status = np.where(_reached(self.problem, self.values, self.frac), 1,
                          np.where(gnorm < self.gtol, 2,
                                   np.where(self.lam > 1e10, 3, np.where(self.it >= self.max_iter, 4, 0))))
        self.status = np.where(running, status, self.status)


class DesignResult(eqx.Module):
    """The outcome of one start.

    `values` (3,): psi0_deg, gap, s0 of the design; `achieved` (T,): each term's value;
    `targets`, `tols` (T,); `reached`; `loss`; `num_iterations`; `status` (see `STATUS`);
    `history_loss` (I,), `history_values` (I, 3): best-so-far per iteration; `z` the
    unconstrained vector; `names` the term names, `n` the mesh, `meta` JSON-ready metadata;
    `codes` (T,): each term's [`jaxrod.RESULTS`][] value at the design (the verdict of the
    snap path or state it was computed from).

    `result` (a `jaxrod.RESULTS` code): `successful` when every target is reached and every
    term's code is `successful`; `infeasible_start` when the objective was not finite at the
    start; `target_not_reached` when the optimizer stopped short (`message` names the terms
    off target); else the first term's code that is not `successful` (a target reached on a
    path through itself, a substituted start, ...)."""

    values: jax.Array
    achieved: jax.Array
    targets: jax.Array
    tols: jax.Array
    reached: jax.Array
    loss: jax.Array
    num_iterations: jax.Array
    status: str = eqx.field(static=True)
    history_loss: jax.Array = None
    history_values: jax.Array = None
    z: jax.Array = None
    names: tuple = eqx.field(static=True, default=())
    n: int = eqx.field(static=True, default=40)
    meta: str = eqx.field(static=True, default="{}")
    codes: jax.Array = None

    @property
    def result(self):
        if self.status == "infeasible_start":
            return jr.RESULTS.infeasible_start
        if not bool(self.reached):
            return jr.RESULTS.target_not_reached
        for c in ([] if self.codes is None else np.asarray(self.codes).tolist()):
            if int(c) != int(jr.RESULTS.successful._value):
                return result_from_name(result_name(int(c)))
        return jr.RESULTS.successful

    @property
    def psi0_deg(self):
        return float(self.values[0])

    @property
    def gap(self):
        return float(self.values[1])

    @property
    def s0(self):
        return float(self.values[2])

    @property
    def message(self):
        if bool(self.reached):
            return "target reached"
        worst = []
        for nm, a, t, tol in zip(self.names, np.asarray(self.achieved), np.asarray(self.targets),
                                 np.asarray(self.tols)):
            if not (abs(a - t) <= tol):
                worst.append(f"{nm} = {a:.4g} (target {t:g} +- {tol:g})")
        return f"target not reached ({self.status}): " + "; ".join(worst)

    def to_dict(self):
        d = {"psi0_deg": self.psi0_deg, "gap": self.gap, "s0": self.s0, "reached": bool(self.reached),
             "status": self.status, "result": result_name(self.result), "loss": _f(self.loss),
             "num_iterations": int(self.num_iterations), "n": self.n, "message": self.message}
        codes = [None] * len(self.names) if self.codes is None else np.asarray(self.codes).tolist()
        for nm, a, t, c in zip(self.names, np.asarray(self.achieved), np.asarray(self.targets), codes):
            d[nm] = _f(a)
            d[f"target_{nm}"] = float(t)
            if c is not None:
                d[f"result_{nm}"] = result_name(int(c))
        return d

    def save(self, path):
        """Write `path.eqx` (the arrays, `eqx.tree_serialise_leaves`) and `path.json` (metadata)."""
        meta = {"status": self.status, "names": list(self.names), "n": self.n, "meta": json.loads(self.meta),
                "shapes": {"achieved": len(self.names),
                           "history": 0 if self.history_loss is None else int(self.history_loss.shape[0]),
                           "z": 0 if self.z is None else int(self.z.shape[0]),
                           "codes": self.codes is not None},
                "summary": self.to_dict()}
        eqx.tree_serialise_leaves(str(path) + ".eqx", self)
        with open(str(path) + ".json", "w") as f:
            json.dump(meta, f, indent=2)
            f.write("\n")

    @classmethod
    def load(cls, path):
        """Inverse of `save`."""
        with open(str(path) + ".json") as f:
            meta = json.load(f)
        T, I, P = meta["shapes"]["achieved"], meta["shapes"]["history"], meta["shapes"]["z"]
        dt = jnp.result_type(float)
        z = jnp.zeros((), dt)
        skel = cls(values=jnp.zeros(3, dt), achieved=jnp.zeros(T, dt), targets=jnp.zeros(T, dt),
                   tols=jnp.zeros(T, dt), reached=jnp.zeros((), bool), loss=z,
                   num_iterations=jnp.zeros((), jnp.int32), status=meta["status"],
                   history_loss=jnp.zeros(I, dt), history_values=jnp.zeros((I, 3), dt), z=jnp.zeros(P, dt),
                   names=tuple(meta["names"]), n=meta["n"], meta=json.dumps(meta["meta"]),
                   codes=jnp.zeros(T, jnp.int32) if meta["shapes"].get("codes") else None)
        return eqx.tree_deserialise_leaves(str(path) + ".eqx", skel)


def _f(x):
    x = float(x)
    return x if math.isfinite(x) else None


class MultiStartResult(eqx.Module):
    """All starts of one run: `best` (a [`DesignResult`][]), the final `values` (B, 3),
    `losses` (B,), `reached` (B,), `status` (B,) codes into `STATUS`, `num_reached`;
    `result` is the best design's `DesignResult.result`."""

    best: DesignResult
    values: jax.Array
    losses: jax.Array
    reached: jax.Array
    status: jax.Array
    num_reached: int = eqx.field(static=True)
    num_starts: int = eqx.field(static=True)
    wall_time: float = eqx.field(static=True)

    @property
    def result(self):
        return self.best.result


def optimize(terms, param: Parametrization | None = None, z0=None, *, n: int = 40, optimizer="lm",
             max_iter: int = 40, stop_fraction: float = 0.1, gtol: float = 1e-8, progress: bool = True,
             meta: dict | None = None, batch_size: int | str | None = "auto") -> MultiStartResult:
    """Minimize $\\tfrac12\\sum r^2$ of `terms` over the free parameters of `param` from the
    starts `z0` (shape (B, P) unconstrained, or (P,), default: the fixed values), all
    advanced together (one compiled evaluation of every start per iteration). Returns a [`MultiStartResult`][]; its `best` reached the
    targets, or is the lowest-objective design found with a "target not reached" message.

    `optimizer`: "lm" (Levenberg-Marquardt, default) or an `optax.GradientTransformation`.
    `batch_size`: how the starts are batched inside the one compiled call per iteration.
    None: one `vmap` over all starts; an int k: `lax.map` over chunks of k starts, each
    chunk `vmap`-ed (k = 1: one start after the other); "devices": the starts split across
    every device JAX sees and every process (`jaxrod.ShardedMap`), ceil(B / devices) on each;
    "auto" (default): "devices" where JAX sees more than one device, else 1 on the CPU
    backend and None elsewhere. On a CPU one start after the other is the fastest and one
    `vmap` the slowest (`benchmarks/results/design.md` has the multi-start throughput):
    batched, every loop runs as long as its slowest member and XLA:CPU gains nothing from
    the batch, and a `vmap` of starts can run into the XLA:CPU deadlock of
    docs/limitations.md.
    """
    terms = tuple(terms)
    if not terms:
        raise ValueError("terms: at least one objective term is needed")
    if not any(not t.is_constraint for t in terms):
        raise ValueError("terms: at least one term must be an objective, not only constraints")
    if isinstance(n, bool) or not isinstance(n, int) or n < 8 or n % 2:
        raise ValueError(f"n: must be an even integer >= 8, got {n!r}")
    if max_iter < 1:
        raise ValueError(f"max_iter: must be >= 1, got {max_iter}")
    if jnp.result_type(float) != jnp.float64:
        raise ValueError("design needs float64 (the critical angles come from continuation); enable it with "
                         "jax.config.update('jax_enable_x64', True)")
    param = Parametrization() if param is None else param
    if z0 is None:
        z0 = param.from_values()
    z0 = jnp.asarray(z0, jnp.float64)
    if z0.ndim == 1:
        z0 = z0[None]
    if z0.ndim != 2 or z0.shape[1] != param.size:
        raise ValueError(f"z0: expected shape (B, {param.size}), got {tuple(z0.shape)}")
    if not bool(jnp.all(jnp.isfinite(z0))):
        raise ValueError("z0: starts must be finite")
    if not (isinstance(optimizer, str) and optimizer == "lm") and not (
            callable(getattr(optimizer, "init", None)) and callable(getattr(optimizer, "update", None))):
        raise ValueError(f"optimizer must be 'lm' or an optax.GradientTransformation, got {optimizer!r}")
    opt = None if isinstance(optimizer, str) else optimizer
    problem = Problem(terms, param, n)
    t0 = time.perf_counter()
    if isinstance(batch_size, str) and batch_size == "auto":
        batch_size = auto_batch_size()
    if batch_size != "devices" and batch_size is not None and (
            isinstance(batch_size, bool) or not isinstance(batch_size, int) or batch_size < 1):
        raise ValueError(f"batch_size: must be None, 'auto', 'devices' or a positive integer, got {batch_size!r}")
    st = _Loop(problem, z0, opt, stop_fraction, gtol, max_iter, batch_size)
    values_of = jax.jit(jax.vmap(param.values))
    hist_loss, hist_vals = [st.loss.copy()], [np.asarray(values_of(st.z))]
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=max_iter, desc="design", unit="it", file=sys.stderr, leave=False)
    for _ in range(max_iter):
        if not np.any(st.status == 0):
            break
        st.step()
        hist_loss.append(st.loss.copy())
        hist_vals.append(np.asarray(values_of(st.z)))
        if bar is not None:
            bar.update(1)
            bar.set_postfix(best=f"{float(np.min(st.loss)):.3g}", reached=int(np.sum(st.status == 1)),
                            running=int(np.sum(st.status == 0)))
    if bar is not None:
        bar.close()
    status = np.where(st.status == 0, 4, st.status)
    wall = time.perf_counter() - t0
    values = np.asarray(values_of(st.z))
    achieved = np.asarray(st.values)
    targets = np.array([t.target for t in terms])
    tols = np.array([t.tol for t in terms])
    reached = np.all(np.abs(achieved - targets) <= tols, axis=1)
    losses = np.asarray(st.loss)
    order = np.lexsort((np.where(np.isfinite(losses), losses, np.inf), ~reached))
    b = int(order[0])
    H = np.stack(hist_loss)[:, b]
    HV = np.stack(hist_vals)[:, b]
    meta = {"terms": [t.describe() for t in terms], "parametrization": param.describe(),
            "optimizer": "lm" if opt is None else type(optimizer).__name__, **(meta or {})}
    best = DesignResult(values=jnp.asarray(values[b]), achieved=jnp.asarray(achieved[b]),
                        targets=jnp.asarray(targets), tols=jnp.asarray(tols), reached=jnp.asarray(reached[b]),
                        loss=jnp.asarray(losses[b]), num_iterations=jnp.asarray(int(st.it[b]), jnp.int32),
                        status=STATUS[int(status[b])], history_loss=jnp.asarray(H),
                        history_values=jnp.asarray(HV), z=jnp.asarray(st.z[b]),
                        names=tuple(t.describe()["name"] for t in terms), n=n, meta=json.dumps(meta),
                        codes=jnp.asarray(np.asarray(st.codes)[b], jnp.int32))
    return MultiStartResult(best=best, values=jnp.asarray(values), losses=jnp.asarray(losses),
                            reached=jnp.asarray(reached), status=jnp.asarray(status),
                            num_reached=int(reached.sum()), num_starts=int(z0.shape[0]), wall_time=wall)


__all__ = ["optimize", "linearize", "Problem", "DesignResult", "MultiStartResult", "STATUS", "NAMES"]
