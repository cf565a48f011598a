r"""Iterative solvers whose batch costs the work of its members, not of its slowest member.

A solver written as a `lax.while_loop` is vmapped by JAX into one loop that runs until the
last member is done, every member doing the work of every pass: a batch of $B$ members costs
$B\cdot\max_b n_b$ passes of work, $n_b$ the passes member $b$ needs. Where the members'
needs differ (the homotopy of a start state that does not exist tries three deformation
paths instead of one; a long continuation path has three times the points of a short one)
most of that work is masked out.

A *machine* is such a solver split into its parts, in the style of optimistix's
`init`/`step`/`terminate`/`postprocess`:

* `init(x) -> state`: the state of a member with inputs `x`;
* `step(x, state) -> state`: one pass of its loop;
* `done(x, state) -> bool`: whether it has finished;
* `finish(x, state) -> out`: its result.

[`run_machine`][] runs one member as `finish(x, while_loop(not done, step, init(x)))`.
[`machine_vmap`][] makes that function's `vmap` a *lane scheduler*: $L\le B$ lanes each hold
one member; each pass steps every lane once (one vectorized `step` of $L$ states); a lane
whose member is done writes its result and takes the next member of the queue. The batch
then costs about $\sum_b n_b/L + \max_b n_b$ passes of $L$ lanes, instead of $\max_b n_b$
passes of $B$. Every member goes through the same `init`, `step` and `finish` as alone: its
numbers are those of its single call, whatever company it keeps (to round-off: a vectorized
step may fuse its arithmetic differently).

`LANES` sets $L$ per platform. On a CPU a wider step buys little per member (its
tridiagonal solves run member by member and a pass is bound by its count of small
operations), while more lanes leave more of the batch waiting at its tail: few lanes are best
there (benchmarks/results/batch_cpu.md). An accelerator needs wide batches: every member gets
a lane of its own.

A whole search made of such machines (`jaxrod.snap_angles`: start states, continuation,
bisection, landing) is wrapped by [`in_turn`][]: on a CPU its batch runs the members one after
another through the single program, which runs faster than any vectorized form there
(benchmarks/results/batch_cpu.md);
elsewhere it is one vectorized program whose machines run on lanes.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax
from jax.custom_batching import custom_vmap

LANES = {"cpu": 4}
"""Lanes of the scheduler per platform (`jax.default_backend()`); platforms not listed run
every member in a lane of its own."""

MIN_QUEUE = {"cpu": 32}
r"""Smallest batch that runs on `LANES` lanes per platform; a smaller one gives every member a
lane of its own (one vectorized loop to its slowest member). With $L$ lanes a batch costs
about $\sum_b n_b + L\max_b n_b$ member-passes, in one loop $B\max_b n_b$: lanes pay once
$B$ is a few times $L$ (on a CPU a batch of 16 and the 5 rows of a phase diagram run faster
as one loop, the 128-scene grid of benchmarks/bench_batch.py faster on lanes)."""


def lanes_for(batch: int) -> int:
    """The number of lanes for a batch of `batch` members on the default platform."""
    backend = jax.default_backend()
    cap = LANES.get(backend)
    if cap is None or batch < MIN_QUEUE.get(backend, 0):
        return batch
    return max(1, min(batch, int(cap)))


def run_machine(init, step, done, finish, x):
    """One member: `finish(x, state)` after `step` has run until `done`."""
    state = lax.while_loop(lambda s: ~done(x, s), lambda s: step(x, s), init(x))
    return finish(x, state)


def _where(pred, a, b):
    """Per-lane select of two pytrees with leading lane axis."""
    def sel(u, v):
        p = pred.reshape(pred.shape + (1,) * (u.ndim - 1))
        return jnp.where(p, u, v)

    return jax.tree.map(sel, a, b)


def run_lanes(init, step, done, finish, xs, lanes: int):
    """Every member of `xs` (a pytree whose leaves have the batch as leading axis) through
    the machine on `lanes` lanes (module docstring). Returns the stacked results."""
    B = jax.tree.leaves(xs)[0].shape[0]
    L = max(1, min(lanes, B))
    take = lambda idx: jax.tree.map(lambda a: a[idx], xs)  # noqa: E731
    idx0 = jnp.arange(L)
    x0 = take(idx0)
    st0 = jax.vmap(init)(x0)
    out_struct = jax.eval_shape(jax.vmap(finish), x0, st0)
    outs0 = jax.tree.map(lambda s: jnp.zeros((B,) + s.shape[1:], s.dtype), out_struct)

    def cond(c):
        return jnp.any(c[1])

    def turnover(c):
        # finished lanes write their member's result and take the next members of the queue,
        # in lane order; a lane left without a member stops
        idx, live, x, st, nxt, outs = c
        fin = live & jax.vmap(done)(x, st)
        o = jax.vmap(finish)(x, st)
        where = jnp.where(fin, idx, B)
        outs = jax.tree.map(lambda buf, v: buf.at[where].set(v, mode="drop"), outs, o)
        new_idx = nxt + jnp.cumsum(fin) - 1
        refill = fin & (new_idx < B)
        idx = jnp.where(refill, new_idx, idx)
        x = _where(refill, take(idx), x)
        st = lax.cond(jnp.any(refill), lambda s: _where(refill, jax.vmap(init)(x), s), lambda s: s, st)
        return idx, jnp.where(fin, refill, live), x, st, jnp.minimum(nxt + jnp.sum(fin), B), outs

    def body(c):
        idx, live, x, st, nxt, outs = c
        any_done = jnp.any(live & jax.vmap(done)(x, st))
        idx, live, x, st, nxt, outs = lax.cond(any_done, turnover, lambda c: c, c)
        # one pass of every lane whose member is not done (a member taken just now may be done
        # before its first pass, as `run_machine` checks before stepping: it is written out at
        # the next pass); a lane without a member keeps its state
        st = _where(live & ~jax.vmap(done)(x, st), jax.vmap(step)(x, st), st)
        return idx, live, x, st, nxt, outs

    c0 = (idx0, jnp.ones(L, bool), x0, st0, jnp.asarray(L, idx0.dtype), outs0)
    return lax.while_loop(cond, body, c0)[5]


def _batched(axis_size, x, batched):
    """The leaves of `x` with the batch axis in front: the unbatched ones broadcast to it."""
    return jax.tree.map(lambda a, b: a if b else jnp.broadcast_to(a, (axis_size,) + jnp.shape(a)), x, batched)


def machine_vmap(init, step, done, finish):
    """`x -> run_machine(init, step, done, finish, x)`, whose `jax.vmap` runs the members on
    lanes (`run_lanes` with `lanes_for(B)` lanes) instead of one loop to the slowest. The
    inputs `x` must be a pytree of arrays; the function is differentiable forward and in
    reverse where its result does not depend on `x` through the loop (the solvers here carry
    their derivatives by the implicit function theorem outside it)."""

    @custom_vmap
    def fun(x):
        return run_machine(init, step, done, finish, x)

    @fun.def_vmap
    def rule(axis_size, in_batched, x):
        (batched,) = in_batched
        if axis_size == 1:  # one member: its own loop, without the scheduler's bookkeeping
            one = jax.tree.map(lambda a, b: a[0] if b else a, x, batched)
            out = jax.tree.map(lambda a: a[None], run_machine(init, step, done, finish, one))
            return out, jax.tree.map(lambda _: True, out)
        xs = _batched(axis_size, x, batched)
        lanes = lanes_for(axis_size)
        if lanes >= axis_size:  # a lane per member: one vectorized loop, no queue to keep
            out = jax.vmap(lambda one: run_machine(init, step, done, finish, one))(xs)
        else:
            out = run_lanes(init, step, done, finish, xs, lanes)
        return out, jax.tree.map(lambda _: True, out)

    return fun


IN_TURN = ("cpu",)
"""Platforms (`jax.default_backend()`) on which [`in_turn`][] runs a batch's members one after
another."""


def in_turn(fn):
    r"""`fn` (a function of one pytree of arrays), whose `jax.vmap` runs the members one after
    another (`lax.map` of the unbatched program) on the platforms of `IN_TURN`, and as one
    vectorized program elsewhere.

    For a search made of nested solver loops (a snap path: start states, continuation,
    bisection, landing) a vectorized batch on a CPU buys little per member (a corrector pass
    costs each member of a large batch nearly what it costs alone: the CPU runs the batched
    arithmetic at about the same rate; docs/limitations.md) and pays for every masked-out
    iteration, every `cond` whose branches both run and every loop that runs to its slowest
    member; a loop of the single program pays for none of them, needs one member's memory and
    compiles the single program. Every member is then its single call exactly. Nested `vmap`s
    loop over every axis.
    Differentiable where `fn`'s result does not depend on its input through the loop (as
    [`machine_vmap`][])."""

    @custom_vmap
    def fun(x):
        return fn(x)

    @fun.def_vmap
    def rule(axis_size, in_batched, x):
        (batched,) = in_batched
        xs = _batched(axis_size, x, batched)
        if jax.default_backend() in IN_TURN:
            out = lax.map(fun, xs)
        else:
            out = jax.vmap(fn)(xs)
        return out, jax.tree.map(lambda _: True, out)

    return fun
