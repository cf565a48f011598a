"""The batching-aware linear solves of `jaxrod.linalg.batched`: every dispatch route (one LAPACK
call, an inline batched call, a loop over members, the pivoting scan, nested vmaps) gives
LAPACK's answer, derivatives match the plain solve's, and a vmap that used to deadlock
XLA:CPU (two concurrent batched LAPACK calls) completes."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax import lax

from jaxrod.linalg import batched as L


def bands(rng, shape, n, weak_diagonal=True):
    lo, d, up = rng.normal(size=(3,) + shape + (n,))
    if weak_diagonal:  # force row interchanges in the elimination
        d = 0.1 * d
    return lo, d, up


def dense(lo, d, up):
    return np.diag(d) + np.diag(up[:-1], 1) + np.diag(lo[1:], -1)


@pytest.mark.parametrize("n", [1, 2, 3, 17, 100])
def test_scan_solves_pivoting_systems(n):
    rng = np.random.default_rng(n)
    lo, d, up = bands(rng, (), n)
    b = rng.normal(size=(n, 3))
    A = dense(lo, d, up)
    x = np.asarray(L._gtsv_scan(lo[:, None], d[:, None], up[:, None], b[:, None, :]))[:, 0]
    assert np.abs(A @ x - b).max() < 1e-12 * max(1.0, np.abs(b).max() * np.linalg.cond(A))
    np.testing.assert_allclose(x, np.linalg.solve(A, b), rtol=1e-9, atol=1e-11)


def test_scan_is_stable_where_unpivoted_elimination_is_not():
    # a zero leading pivot: the Thomas algorithm divides by 0, partial pivoting does not
    n = 6
    lo = np.ones(n)
    up = np.ones(n)
    d = np.array([0.0, 2.0, 3.0, 1.0, 2.0, 1.0])
    b = np.arange(1.0, n + 1.0)[:, None]
    x = np.asarray(L._gtsv_scan(lo[:, None], d[:, None], up[:, None], b[:, None, :]))[:, 0]
    np.testing.assert_allclose(x, np.linalg.solve(dense(lo, d, up), b), rtol=1e-12)


# (batch shape, N, k): inline batched LAPACK, a loop over members, the scan, nested vmaps
# choosing each of them after merging their axes
ROUTES = [((4,), 100, 3), ((30,), 400, 2), ((60,), 400, 2), ((3, 50), 12, 2), ((2, 30), 400, 2), ((5, 20), 300, 1)]


@pytest.mark.parametrize("shape,n,k", ROUTES)
def test_batched_routes_equal_lapack(shape, n, k):
    rng = np.random.default_rng(len(shape) * 100 + n)
    lo, d, up = bands(rng, shape, n)
    b = rng.normal(size=shape + (n, k))
    f = L.tridiagonal_solve
    for _ in shape:
        f = jax.vmap(f)
    out = np.asarray(jax.jit(f)(lo, d, up, b)).reshape((-1, n, k))
    flat = [a.reshape((-1,) + a.shape[len(shape):]) for a in (lo, d, up, b)]
    ref = np.stack([np.asarray(lax.linalg.tridiagonal_solve(*(a[i] for a in flat))) for i in range(flat[0].shape[0])])
    np.testing.assert_allclose(out, ref, rtol=1e-8, atol=1e-10)


def test_partly_batched_arguments():
    rng = np.random.default_rng(3)
    lo, d, up = bands(rng, (), 50)
    ds = d + rng.normal(size=(64, 50))
    b = rng.normal(size=(50, 2))
    out = jax.vmap(L.tridiagonal_solve, (None, 0, None, None))(lo, ds, up, b)
    for i in (0, 63):
        np.testing.assert_allclose(out[i], lax.linalg.tridiagonal_solve(lo, ds[i], up, b), rtol=1e-9, atol=1e-11)


@pytest.mark.parametrize("batched", [False, True])
def test_tridiagonal_derivatives_match_lapack(batched):
    rng = np.random.default_rng(5)
    B = 64 if batched else 1
    lo, d, up = bands(rng, (B,), 20, weak_diagonal=False)
    d = d + 4.0
    b = rng.normal(size=(B, 20, 2))

    def loss(solve):
        return lambda lo, d, up, b: jnp.sum(jnp.sin(solve(lo, d, up, b)))

    ours = jax.grad(loss(L.tridiagonal_solve), argnums=(0, 1, 2, 3))
    ref = jax.grad(loss(lax.linalg.tridiagonal_solve), argnums=(0, 1, 2, 3))
    if batched:
        ours, ref = jax.vmap(ours), jax.vmap(ref)
        args = (lo, d, up, b)
    else:
        args = tuple(a[0] for a in (lo, d, up, b))
    for g, r in zip(ours(*args), ref(*args)):
        # lower[0] and upper[-1] lie outside the matrix: LAPACK's rule gives them a
        # (meaningless) cotangent, ours gives 0; compare the entries that exist
        np.testing.assert_allclose(np.asarray(g)[..., 1:-1], np.asarray(r)[..., 1:-1], rtol=1e-9, atol=1e-11)
    def tangent(solve):
        f = lambda *a: jax.jvp(loss(solve), a, a)[1]  # noqa: E731
        return (jax.vmap(f) if batched else f)(*args)

    t, tr = tangent(L.tridiagonal_solve), tangent(lax.linalg.tridiagonal_solve)
    np.testing.assert_allclose(t, tr, rtol=1e-10)


def test_dense_solve_values_and_derivatives():
    rng = np.random.default_rng(7)
    A = rng.normal(size=(4, 9, 9)) + 3 * np.eye(9)
    r = rng.normal(size=(4, 9))
    np.testing.assert_allclose(jax.vmap(L.solve)(A, r), np.linalg.solve(A, r[..., None])[..., 0], rtol=1e-10)
    f = lambda A, r: jnp.sum(jnp.cos(L.solve(A, r)))  # noqa: E731
    g = lambda A, r: jnp.sum(jnp.cos(jnp.linalg.solve(A, r)))  # noqa: E731
    for a, b in zip(jax.vmap(jax.grad(f, (0, 1)))(A, r), jax.vmap(jax.grad(g, (0, 1)))(A, r)):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(jax.jacfwd(L.solve)(A[0], r[0]), jax.jacfwd(jnp.linalg.solve)(A[0], r[0]), rtol=1e-10)


def test_eigh_values_and_derivatives():
    """`eigh` equals `jnp.linalg.eigh` (values, vectors up to sign), batched too, and its
    jvp, grad and vmap(grad) equal jax's own rule (on a sign-invariant function of the
    vectors), with a non-symmetric input symmetrized as jax does."""
    rng = np.random.default_rng(11)
    A = rng.normal(size=(5, 8, 8))
    A = A + np.swapaxes(A, 1, 2)
    w, v = jax.vmap(L.eigh)(A)
    wr, vr = np.linalg.eigh(A)
    np.testing.assert_allclose(w, wr, rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(np.abs(np.sum(v * vr, axis=1)), 1.0, rtol=1e-10)
    f = lambda eig: lambda a: jnp.sum(jnp.sin(eig(a)[0])) + jnp.sum(eig(a)[1][:, 2] ** 2 * jnp.arange(8.0))  # noqa: E731
    for a in (A[0], A[1] + rng.normal(size=(8, 8))):
        np.testing.assert_allclose(jax.grad(f(L.eigh))(a), jax.grad(f(jnp.linalg.eigh))(a), rtol=1e-9, atol=1e-12)
        t = rng.normal(size=(8, 8))
        np.testing.assert_allclose(jax.jvp(f(L.eigh), (a,), (t,))[1], jax.jvp(f(jnp.linalg.eigh), (a,), (t,))[1],
                                   rtol=1e-9)
    np.testing.assert_allclose(jax.vmap(jax.grad(f(L.eigh)))(A), jax.vmap(jax.grad(f(jnp.linalg.eigh)))(A),
                               rtol=1e-9, atol=1e-12)


def test_small_closed_forms():
    rng = np.random.default_rng(9)
    S = rng.normal(size=(2, 2))
    r = rng.normal(size=2)
    np.testing.assert_allclose(L.solve2(S, r), np.linalg.solve(S, r), rtol=1e-12)
    P = rng.normal(size=(30, 2))
    g = rng.normal(size=30)
    np.testing.assert_allclose(L.lstsq2(P, g), np.linalg.lstsq(P, g, rcond=None)[0], rtol=1e-10)


def test_concurrent_batched_solves_do_not_deadlock():
    """The pattern that hung XLA:CPU on 2 cores: two independent branches of one program,
    each with a batched dense LU (jaxlib's ParallelBatchMap waited for tasks queued behind
    the other branch). With `jnp.linalg.solve` in place of `L.solve` this very program sat
    at 0 % CPU until killed on 2 cores; with `L.solve` it runs through. Run in a
    subprocess with a timeout, so a regression fails instead of hanging the suite."""
    code = textwrap.dedent("""
        import jax, jax.numpy as jnp, numpy as np
        jax.config.update("jax_enable_x64", True)
        from jaxrod.linalg import batched as L
        rng = np.random.default_rng(0)
        A = jnp.asarray(rng.normal(size=(2, 41, 205, 205)) + 60 * np.eye(205))
        b = jnp.asarray(rng.normal(size=(2, 41, 205)))
        def two(A, b):
            step = lambda a, r: jax.lax.fori_loop(0, 20, lambda i, x: jax.vmap(L.solve)(a, x + r) * 0.5, r)
            return step(A[0], b[0]), step(A[1], b[1])
        x0, x1 = jax.jit(two)(A, b)
        print("ok", bool(jnp.all(jnp.isfinite(x0)) & jnp.all(jnp.isfinite(x1))))
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=240)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "ok True" in out.stdout
