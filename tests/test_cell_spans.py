"""Corner blends that reach across several cells of a smoothed spline (nurbscnc.plan.cell_spans).

A plunge at a low feed into a PCB pad's contour of short chords, under G64 P: smoothing fits
the contour with a spline planned in 0.25 mm cells, and the blend at the plunge may now trim
the spline by more than one cell (a span of cells is one side of the corner) and use the
tolerance the fit left (P less its deviation). References independent of the planner: the
programmed segments (plunge line and chords), exact point-to-segment distances
(tests/servo_reference.py), the independent servo simulation (scipy.signal.lsim) and the
programmed G64 vertices read from the segments.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from nurbscnc.machine.profile import load_machine
from nurbscnc.pipeline import RunOptions, run_program
from nurbscnc.plan.options import LookaheadOptions, PlanOptions
from nurbscnc.program.interpret import interpret_text
from tests.servo_reference import (
    beyond_vertex_mm,
    g64_vertices,
    lsim_actual_mm,
    segment_distance_mm,
)

ROOT = Path(__file__).resolve().parent.parent
LINUXCNC_LIMITS = ROOT / "bench" / "programs" / "linuxcnc_limits.toml"
MACHINES = {"default": None, "linuxcnc_limits": LINUXCNC_LIMITS}
#: The plunge [mm] (from Z1 to Z−0.05), the pad's radius [mm] and its tolerance P [mm].
PLUNGE_MM = 1.05
RADIUS_MM = 1.2
P_MM = 0.25


def _pad(radius_mm: float = RADIUS_MM, p_mm: float = P_MM) -> str:
    """A PCB isolation pass: a rapid above the pad, a plunge at F254 (10 in/min), the pad's
    circle in 40 chords of 0.17–0.21 mm (a slightly irregular polygon, as CAM writes it) at
    F762, the retract."""
    rng = np.random.default_rng(3)
    theta = np.cumsum(np.concatenate(([0.0], rng.uniform(0.9, 1.1, 40))))
    theta *= 2.0 * np.pi / theta[-1]
    x, y = radius_mm * np.cos(theta), radius_mm * np.sin(theta)
    lines = [
        "G21 G17 G90 G94",
        f"G64 P{p_mm}",
        "G0 Z1",
        f"G0 X{x[0]:.5f} Y{y[0]:.5f}",
        "G1 Z-0.05 F254",
        "F762",
    ]
    lines += [f"G1 X{a:.5f} Y{b:.5f}" for a, b in zip(x[1:-1], y[1:-1])]
    lines += [f"G1 X{x[0]:.5f} Y{y[0]:.5f}", "G0 Z1", "M2"]
    return "\n".join(lines) + "\n"


def _run(machine, dynamics: str, smooth: bool = True):
    prog = interpret_text(_pad())
    opts = RunOptions(
        lookahead=LookaheadOptions(dynamics=dynamics, plan=PlanOptions(smooth=smooth))
    )
    return prog, run_program(prog, machine, opts)


def _programmed(prog) -> np.ndarray:
    """The feed moves (plunge and chords) as one polyline, densified to 2 µm."""
    feed = [g for g in prog.segments if g.kind == "line"]
    v = np.array([feed[0].start_mm] + [g.end_mm for g in feed], dtype=float)
    out = [v[:1]]
    for a, b in zip(v[:-1], v[1:]):
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / 0.002)))
        out.append(a + np.linspace(0.0, 1.0, n + 1)[1:, None] * (b - a))
    return np.vstack(out)


def _plunge_end(prog) -> np.ndarray:
    """The programmed end of the plunge (the first feed move) [mm]."""
    plunge = next(g for g in prog.segments if g.kind == "line")
    assert plunge.start_mm[2] > plunge.end_mm[2] and plunge.start_mm[0] == plunge.end_mm[0]
    return np.asarray(plunge.end_mm, dtype=float)


@pytest.mark.parametrize("machine_name", list(MACHINES))
def test_plunge_blend_reaches_across_cells_within_the_tolerance(machine_name):
    """Without the contour check: the plunge's blend leaves the plunge line more than one
    cell's half (0.125 mm) before its end (the tool leaves the vertical above
    Z−0.05 + 0.3 mm), every feed sample within P of the programmed plunge and chords, the
    path has no jump (consecutive samples at most v_max·T apart). While a blend could trim
    half a cell only, the tool left the vertical 0.125 mm above the plunge's end at most
    and ran the rest of the plunge at F254."""
    machine = load_machine(MACHINES[machine_name])
    prog, run = _run(machine, "off")
    assert run.plan.pieces.smoothed is not None and run.plan.pieces.smoothed["runs"] == 1
    s = run.samples
    feed_lines = [g.line for g in prog.segments if g.kind == "line"]
    on = np.isin(s.line, feed_lines)
    pts = s.points_mm[on]
    dist = segment_distance_mm(pts, _programmed(prog))
    assert dist.max() <= P_MM * (1.0 + 1e-9)
    assert dist.max() >= 0.5 * P_MM  # the tolerance is used (not vacuous)
    # where the tool leaves the plunge's vertical (x, y of the pad's first vertex)
    start = _plunge_end(prog)
    off_axis = np.hypot(pts[:, 0] - start[0], pts[:, 1] - start[1]) > 1e-6
    assert not off_axis[0] and pts[0, 2] > 0.9  # the plunge starts on the vertical, at Z1
    z_leave = float(pts[np.argmax(off_axis), 2])
    assert z_leave >= start[2] + 0.3
    step = np.linalg.norm(np.diff(s.points_mm, axis=0), axis=1)
    assert step.max() <= machine.limits.v_max_mm_s * machine.servo.period_s * (1.0 + 1e-6)


@pytest.mark.parametrize("machine_name", list(MACHINES))
def test_plunge_blend_across_cells_within_the_guarantee(machine_name):
    """With the contour check: in the independent simulation every feed sample within
    ε_max of the planned points' polyline or within ε_max + P of a programmed G64 vertex
    (+1 µm for the 1 ms chords), and within ε_max + P of the programmed path."""
    machine = load_machine(MACHINES[machine_name])
    prog, run = _run(machine, "local")
    s = run.samples
    actual = lsim_actual_mm(s.points_mm, machine)[: len(s.points_mm)]
    feed_lines = [g.line for g in prog.segments if g.kind == "line"]
    on = np.isin(s.line, feed_lines)
    tool = actual[on]
    eps_mm = machine.limits.contour_tolerance_mm
    d_prog = segment_distance_mm(tool, _programmed(prog))
    d_plan = segment_distance_mm(tool, s.points_mm)
    d_vertex = beyond_vertex_mm(tool, g64_vertices(prog.segments, machine.limits.path_tolerance_mm))
    assert np.minimum(d_plan, d_vertex).max() <= eps_mm + 1e-3
    assert d_prog.max() <= eps_mm + P_MM + 1e-3


def test_blend_takes_whole_cells_and_meets_the_next_one():
    """The pieces after blending (LinuxCNC's limits, smoothing on): the plunge is followed
    by its blend, then by the spline's cells from an arc length past the first cell (the
    cells the blend covers are dropped, the one it ends in trimmed); the blend starts on
    the plunge line and ends on the spline's point there (the curve's own evaluation), and
    every piece starts where the one before ends."""
    from nurbscnc.geometry.path import Kind
    from nurbscnc.plan.curved_pieces import CELL_MM
    from nurbscnc.plan.program_pieces import segment_pieces

    machine = load_machine(LINUXCNC_LIMITS)
    prog = interpret_text(_pad())
    pieces = segment_pieces(prog.segments, machine, PlanOptions())
    plunge = next(
        i for i in range(len(pieces)) if pieces.kind[i] == Kind.LINE and not pieces.rapid[i]
    )
    nurbs = next(i for i in range(plunge + 2, len(pieces)) if pieces.kind[i] == Kind.NURBS)
    assert nurbs == plunge + 2  # one blend row between them
    cell = pieces[nurbs]
    assert cell.s_a_mm > 1.5 * CELL_MM
    # the blend's ends on the plunge's vertical and on the spline (its own evaluation)
    start, end = pieces.start_mm[:, plunge + 1], pieces.end_mm[:, plunge + 1]
    vertex = _plunge_end(prog)
    assert np.hypot(start[0] - vertex[0], start[1] - vertex[1]) <= 1e-9
    on_curve = cell.geometry.derivatives(np.array([cell.u_a]), 0)[0][0]
    np.testing.assert_allclose(end, on_curve, rtol=0, atol=1e-9)
    gaps = np.linalg.norm(pieces.start_mm[:, 1:] - pieces.end_mm[:, :-1], axis=0)
    assert gaps.max() <= 1e-6
