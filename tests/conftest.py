"""Test configuration: float64 everywhere (set before any array is created)."""

import jax


jax.config.update("jax_enable_x64", True)


def pytest_configure(config):
    # Under `pytest -n 2` keep each test module on one xdist worker: the modules share
    # jitted functions and states through module-scoped fixtures, and compiling is what
    # costs time (seconds per function), so splitting a module would compile twice.
    if getattr(config.option, "dist", "no") == "load":
        config.option.dist = "loadfile"
