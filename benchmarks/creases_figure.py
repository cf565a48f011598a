#!/usr/bin/env python
"""The two-crease figure of docs/guide.md: the quasi-static hysteresis loop of a strip with two
creases (90 deg at 0.3 L and 0.65 L, G/L = 0.5, N = 96) and its states at alpha = 0 and
just before each snap.

    python benchmarks/creases_figure.py

Writes benchmarks/results/creases_loop.png and creases_shapes.png."""

from __future__ import annotations

import os

import jax

jax.config.update("jax_enable_x64", True)

import jaxrod as jr  # noqa: E402
from jaxrod.plot import plot_equilibria, plot_hysteresis  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))


def main():
    sc = jr.make_scene(180.0, 0.5, n=96, creases=[(0.3, 90.0), (0.65, 90.0)])
    h = jr.hysteresis(sc)
    out = os.path.join(HERE, "results")
    plot_hysteresis(h, os.path.join(out, "creases_loop.png"),
                    title="two creases, 90° at 0.3 L and 0.65 L, G/L = 0.5 (N = 96)")
    eqs, labels = [], []
    for name, p, sgn in (("up", h.snap.up, 1.0), ("down", h.snap.down, -1.0)):
        # 0.5 deg before the critical angle (at it the Hessian is singular)
        a = p.alpha_c - sgn * jax.numpy.radians(0.5)
        eq = jr.solve_equilibrium(jr.SymmetricAlpha().set(sc, a), p.theta_before, p.force_before)
        assert eq.result == jr.RESULTS.successful
        eqs.append(eq)
        labels.append(f"0.5° before snap {name} (α = {float(jax.numpy.degrees(a)):+.1f}°)")
    eqs += [jr.initial_state(sc, "up"), jr.initial_state(sc, "down")]
    labels += ["up state, α = 0", "down state, α = 0"]
    plot_equilibria(eqs, labels, os.path.join(out, "creases_shapes.png"),
                    title="two creases: states at α = 0 and at the snaps (dots: creases)")
    print("alpha_c up/down (deg):", float(jax.numpy.degrees(h.snap.up.alpha_c)),
          float(jax.numpy.degrees(h.snap.down.alpha_c)))


if __name__ == "__main__":
    main()
