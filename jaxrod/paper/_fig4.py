r"""The paper's Fig. 4: three balls struck one after the other by designed clamp programs.

Three balls on a table above the strip ($\Psi_0=60^\circ$, $G/L=0.5$), left, centre and
right (`FIG4_BALLS`), struck one after the other as in the paper: program A turns the left
clamp to launch the right ball and leaves the other two on the table; B, run on the balls A
left (where A left them), turns the right clamp to launch the left ball and leaves the centre
one; C turns both clamps to launch the centre ball, the last one on the table. Each is
designed on the balls the previous programs leave, from a naive start (`FIG4_STARTS`), on the
mesh `FIG4_N`, and the three are re-checked together: one run of the whole sequence
(`jaxrod.design.sequence_program`, the strip reset down between programs) on the finer mesh
`FIG4_N_CHECK` with the three balls, in which each program must launch its ball and spare
those still on the table (`Fig4Result.confirmed`). `FIG4_PEAKS` holds the designed peaks
(`jaxrod actuate --program paper-fig4` runs them).

Each program is designed by `jaxrod.design.design_program` (the loss, its steps and its start
are described in `design/_programs.py`), and the sequence's programs are judged by
`jaxrod.design.sequence_speeds` and `stage_outcome`.
"""

from __future__ import annotations

import dataclasses
import time

import jaxrod as jr
from jaxrod.design import (design_program, remaining_bodies, sequence_program, sequence_speeds, stage_outcome,
                           two_knot_program)

FIG4_BALLS = (("left", (0.05, 0.20)), ("centre", (0.25, 0.465)), ("right", (0.45, 0.20)))
"""Names and centres (L) of the Fig. 4 balls: radius 0.04 L, mass 0.05 lambda L, on a table
with friction deceleration 5 L/T^2. Where they lie decides whether the paper's selectivity
exists at all; measured with `jaxrod.actuate` at N = 48 (the height a ball's centre may have
and still be touched, radius plus contact layer 0.06 L): the side balls lie above what the
near clamp's own turn reaches (program (35, -55) deg reaches y = 0.188 L over the left ball)
and within the far half's snap (0.296 L over the right ball), so a one-clamp program strikes
only the far side's ball; the centre ball lies within the reach of the two-clamp snaps
(0.475-0.487 L) and beyond that of the one-clamp programs that launch a side ball cleanly
((35, -55) deg: 0.456 L). The strike on the centre ball converges in the mesh only well
inside that reach: the program (105, 75) deg launches it at 9.67 / 8.43 v* (N = 32 / 48)
from y = 0.465 L, at 4.55 / 3.31 v* from 0.47 L; from 0.48 L the symmetric program (90, 90)
deg reaches it at N = 16 and 24 (5.83, 5.40 v*) and misses it at N = 32 and 48. With the
side balls at y = 0.10 L, the near clamp's turn brushes its ball (0.7 v*) and slides it
0.07 L, out of the mirrored program's clean reach."""
FIG4_STARTS = {"right": (50.0, -40.0), "left": (-40.0, 50.0), "centre": (120.0, 120.0)}
"""The naive programs the optimizer starts from, peaks (p_L, p_R) in degrees, per target."""
FIG4_PROGRAMS = ("right", "left", "centre")
"""The order of the paper's sequence: one clamp (left turns, right ball), the mirror, both."""
FIG4_PEAKS = ((35.0, -70.0), (-70.0, 35.0), (75.0, 120.0))
"""The peaks (p_L, p_R) in degrees of programs A, B, C as `fig4_study()` designs them (at its
defaults; `benchmarks/bench_actuate.py` reruns it, a nightly test checks they agree); in
the sequence run at `FIG4_N_CHECK` each launches its ball and spares the others."""
FIG4_V_LAUNCH = 5.0
"""Launch speed (v*) a Fig. 4 program must give its ball."""
FIG4_V_SPARE = 1.2
"""Speed (v*) below which a Fig. 4 program must leave the other balls on the table."""
FIG4_N = 32
"""The mesh `fig4_study` designs the programs on (segments): the contact step, not the strip,
sets the step up to N = 32, so a run costs about the same as at N = 16."""
FIG4_N_CHECK = 48
"""The finer mesh of the Fig. 4 re-check (one run of the whole sequence) and of `jaxrod actuate
--program paper-fig4`."""


def fig4_bodies() -> jr.Bodies:
    """The balls of `FIG4_BALLS` on their table."""
    return jr.Bodies([jr.Ball(name, pos, 0.04, 0.05) for name, pos in FIG4_BALLS], table=jr.Table(5.0))


def fig4_objects_json() -> dict:
    """`fig4_bodies` in the JSON of `jaxrod actuate --objects`."""
    return {"balls": [{"name": name, "x": x, "y": y, "radius": 0.04, "mass": 0.05} for name, (x, y) in FIG4_BALLS],
            "table": {"deceleration": 5.0}}


@dataclasses.dataclass
class Fig4Result:
    """`fig4_study`'s three designs (in `FIG4_PROGRAMS` order, each on the balls the ones before
    it left, on the mesh `n`), the `sequence` run of all three on the finer mesh `n_check` with
    the three balls,
    `stage_speeds` (per program: the peak speed of each ball still on the table, v*),
    `confirmed` (in that run each program launched its ball faster than `v_launch` and the
    others stayed below `v_spare`) and `seconds`."""

    designs: list
    sequence: object
    stage_speeds: list
    confirmed: bool
    n: int
    n_check: int
    v_launch: float
    v_spare: float
    seconds: float

    def table(self) -> str:
        """The designs and the sequence's re-check as a Markdown table."""
        names = [n for n, _ in FIG4_BALLS]
        rows = ["| program | target | peaks (p_L, p_R) deg | iterations | balls on the table: peak speed at the design "
                f"mesh (v*) | in the sequence run, N = {self.n_check} (v*) |",
                "|---|---|---|---|---|---|"]
        for lab, d, sp in zip("ABC", self.designs, self.stage_speeds):
            rows.append(f"| {lab} | {d.target} | ({d.peaks_deg[0]:.2f}, {d.peaks_deg[1]:.2f}) | {d.iterations} | "
                        + ", ".join(f"{n} {d.speeds[n]:.2f}" for n in names if n in d.speeds) + " | "
                        + ", ".join(f"{n} {sp[n]:.2f}" for n in names if n in sp) + " |")
        return "\n".join(rows)


def fig4_study(*, n=FIG4_N, n_check=FIG4_N_CHECK, v_launch=FIG4_V_LAUNCH, v_spare=FIG4_V_SPARE, steps=25, scan_deg=15.0,
               scan_size=7, t1=1.8, hold=(), d_hold=0.005) -> Fig4Result:
    """Design the paper's three programs one after the other, each on the balls the previous
    ones leave (module docstring), and re-check them in one sequence run on the finer mesh.
    `hold`: balls that the programs not aimed at them must also leave within `d_hold` (L) of
    their places (`design_program`'s `d_spare`).

    Measured at the defaults (N = 32, re-check N = 48; `benchmarks/results/actuate.md`):
    A (35, -70) deg launches the right ball at 8.58 v* and touches neither other ball; B,
    designed on the left and centre balls A left untouched, is its mirror (-70, 35) deg
    (left ball 8.58 v*, equal to A's to 1e-11); C (75, 120) deg launches the centre ball at
    9.89 v*. Each is the widest-margin program of the 7 x 7 scan, which meets the goal with
    the 10 % margin, so Adam takes no step. The sequence run at N = 48: right 7.56, left
    7.55, centre 8.69 v*, every spared ball at 0.00 v*; `confirmed` is True. Adam alone
    from the naive starts (`scan_deg=None`) finds A in 7 iterations, (42.9, -47.0) deg, but
    it brushes the left and centre balls (0.87, 0.93 v*, moving them 0.08 L), and finds
    neither B nor C: from (-40, 50) and (120, 120) deg the strip misses its ball and the
    loss is flat."""
    tic = time.perf_counter()
    scene = jr.make_scene(60.0, 0.5, n=n)
    theta0 = jr.initial_state(scene, "down").theta
    present = fig4_bodies()
    designs = []
    for target in FIG4_PROGRAMS:
        keep = {nm: d_hold for nm in hold if nm in present.names and nm != target} or None
        d = design_program(scene, present, target, FIG4_STARTS[target], v_launch=v_launch, v_spare=v_spare,
                           d_spare=keep, steps=steps, n_check=n_check, scan_deg=scan_deg, scan_size=scan_size, t1=t1)
        designs.append(d)
        run = jr.actuate(scene, present, two_knot_program(d.peaks_deg), theta0=theta0, t1=t1)
        present = remaining_bodies(present, run, [target])
        if present is None:
            break
    fine = jr.make_scene(60.0, 0.5, n=n_check)
    seq = jr.actuate(fine, fig4_bodies(), sequence_program([d.peaks_deg for d in designs]),
                     theta0=jr.initial_state(fine, "down").theta)
    stages = sequence_speeds(seq, [d.target for d in designs])
    confirmed = bool(seq.result == jr.RESULTS.successful and len(designs) == len(FIG4_PROGRAMS) and all(
        stage_outcome(sp, d.target, v_launch=v_launch, v_spare=v_spare)[2] for d, sp in zip(designs, stages)))
    return Fig4Result(designs=designs, sequence=seq, stage_speeds=stages, confirmed=confirmed, n=n, n_check=n_check,
                      v_launch=v_launch, v_spare=v_spare, seconds=time.perf_counter() - tic)
