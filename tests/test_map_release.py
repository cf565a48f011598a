"""The suite's guard against the per-process memory-mapping limit (tests/conftest.py):
compiled XLA:CPU programs hold mappings until JAX's caches let them go, and
`release_compiled_programs` lets them go once a threshold is passed."""

import sys

import jax
import jax.numpy as jnp
import pytest

from conftest import map_count, map_limit, release_compiled_programs

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")


def test_compiled_programs_hold_mappings_until_released():
    @jax.jit
    def g(x):
        return jnp.sin(x) @ jnp.cos(x).T + x.sum()

    release_compiled_programs(0)  # start from empty caches
    start = map_count()
    for n in range(2, 42):  # 40 shapes, 40 executables
        g(jnp.ones((n, n))).block_until_ready()
    held = map_count()
    assert held - start >= 40, (start, held)  # at least one mapping per executable
    assert release_compiled_programs(held + 1) is None  # under the threshold: nothing done
    before, after = release_compiled_programs(held - 1)
    assert before >= held and after < start + (held - start) / 4, (start, held, after)
    assert 1000 <= map_limit()
