"""Smoothing by default never leaves the path tolerance (nurbscnc.plan.smoothing, issue 35).

Under G64 dense polylines are fitted by default. The references here are independent of the
smoothing code: the programmed polyline (the interpreter's line segments), exact numpy
point-to-segment distances (tests/servo_reference.py, on the polyline densified to 2 µm:
the distance to the two segments at the nearest vertex, an upper bound of the true
distance), and scipy's own B-spline evaluator on each fitted spline's knots and control
points. Programs: random 2-D and 3-D polylines with raster turn-arounds (a stepover, then
the pass reversed) and reversals (the path going back beside itself), under G64 P and G64;
the corpus's real CAM programs when present; G61 programs stay as written.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest
from scipy.interpolate import BSpline

from nurbscnc.machine.profile import load_machine
from nurbscnc.pipeline import RunOptions, run_program
from nurbscnc.plan.options import LookaheadOptions, PlanOptions
from nurbscnc.plan.smoothing import SHARE, smooth_runs
from nurbscnc.program.interpret import interpret_text
from tests.servo_reference import segment_distance_mm

HERE = Path(__file__).parent
ROOT = HERE.parent
CORPUS = Path(os.environ.get("NURBSCNC_CORPUS") or ROOT.parent / "shared" / "corpus")
CAM_PROGRAMS = (
    "cambam_electric_turtle.nc",
    "cambam_enclosure.nc",
    "fusion360_1110_wall_265bit.nc",
    "pcb2gcode_D1MiniGSR_front.nc",
    "pycut_vise_pockets.nc",
)
#: The paper's benchmark programs: smoothing must leave them as written.
PAPER_PROGRAMS = (
    "programs/naca2415.nc",
    "programs/naca2415_rot45.nc",
    "bench/programs/naca2415_g52.nc",
    "bench/programs/pentagram_g61.nc",
    "bench/programs/pentagram_g64p002.nc",
    "bench/programs/square_g61_f1000.nc",
    "bench/programs/square_g61_f3000.nc",
)


def _dense(vertices: np.ndarray, step_mm: float = 0.002) -> np.ndarray:
    """The polyline through ``vertices`` (n, 3) with extra vertices every ≤ ``step_mm``."""
    out = [vertices[:1]]
    for a, b in zip(vertices[:-1], vertices[1:]):
        n = max(1, math.ceil(float(np.linalg.norm(b - a)) / step_mm))
        out.append(a + np.linspace(0.0, 1.0, n + 1)[1:, None] * (b - a))
    return np.vstack(out)


def _feed_polyline(prog) -> np.ndarray:
    """The programmed feed moves (lines) as one densified polyline [mm]."""
    lines = [s for s in prog.segments if s.kind == "line"]
    v = np.array([lines[0].start_mm] + [s.end_mm for s in lines], dtype=float)
    return _dense(v)


def _raster(rng, three_d: bool) -> np.ndarray:
    """Serpentine passes of random short chords (0.1–0.8 mm) along Y over a random surface,
    a stepover of 0.2–1 mm in X between passes (two 90° turns: the pass reversed)."""
    amp, wx, wy = rng.uniform(0.3, 2.0), rng.uniform(5.0, 30.0), rng.uniform(5.0, 30.0)
    length = rng.uniform(8.0, 20.0)
    stepover = rng.uniform(0.2, 1.0)
    pts, x = [], 0.0
    for k in range(int(rng.integers(3, 6))):
        y = np.concatenate(([0.0], np.cumsum(rng.uniform(0.1, 0.8, 200))))
        y = np.append(y[y < length], length)
        y = y if k % 2 == 0 else y[::-1]
        z = amp * np.sin(x / wx * 2 * np.pi + 0.3) * np.cos(y / wy * 2 * np.pi)
        pts.append(np.column_stack((np.full_like(y, x), y, z if three_d else 0.0 * z)))
        x += stepover
    return np.vstack(pts)


def _curve_with_reversal(rng, three_d: bool) -> np.ndarray:
    """A random smooth curve in short chords (0.05–0.6 mm), then back beside itself (a
    reversal of 170–180°: offset by 0–0.2 mm), then on again."""
    s = np.concatenate(([0.0], np.cumsum(rng.uniform(0.05, 0.6, 120))))
    c = rng.uniform(-1.0, 1.0, (3, 3))
    f = rng.uniform(0.05, 0.3, 3)
    out = np.column_stack(
        [s] + [c[i, 0] * np.sin(f[i] * s) + c[i, 1] * np.cos(0.5 * f[i] * s) for i in (0, 1)]
    )
    xyz = np.column_stack((out[:, 0], out[:, 1], out[:, 2] if three_d else 0.0 * out[:, 0]))
    back = xyz[::-1][1:] + np.array([0.0, rng.uniform(0.0, 0.2), 0.0])
    return np.vstack((xyz, back))


def _program(vertices: np.ndarray, mode: str, feed: float) -> str:
    head = ["G21 G17 G90 G94", mode, f"G0 X{vertices[0, 0]:.4f} Y{vertices[0, 1]:.4f}"]
    head.append(f"G0 Z{vertices[0, 2]:.4f}")
    head.append(f"G1 F{feed:g}")
    body = [f"X{x:.4f} Y{y:.4f} Z{z:.4f}" for x, y, z in vertices[1:]]
    return "\n".join(head + body + ["M2"]) + "\n"


def _options(dynamics="off", smooth=None) -> RunOptions:
    plan = PlanOptions() if smooth is None else PlanOptions(smooth=smooth)
    return RunOptions(lookahead=LookaheadOptions(dynamics=dynamics, plan=plan))


def _spline_distance_mm(seg, polyline: np.ndarray, per_span: int = 40) -> float:
    """The fitted spline ``seg`` by scipy's evaluator at ``per_span`` points per knot span:
    its largest distance to ``polyline`` (densified) [mm]."""
    sp = BSpline(np.asarray(seg.knots), np.asarray(seg.control_points_mm), seg.degree)
    knots = np.unique(np.asarray(seg.knots))
    u = np.unique(
        np.concatenate([np.linspace(a, b, per_span + 1) for a, b in zip(knots[:-1], knots[1:])])
    )
    return float(segment_distance_mm(sp(u), polyline).max())


CASES = [
    (kind, dim, mode, seed)
    for seed in range(3)
    for kind in ("raster", "reversal")
    for dim in (2, 3)
    for mode in ("G64 P0.01 Q0", "G64 P0.1 Q0", "G64")
]


@pytest.mark.parametrize("kind, dim, mode, seed", CASES)
def test_smoothed_plan_stays_within_the_path_tolerance(kind, dim, mode, seed):
    """Every reference point of a feed move and every point of every fitted spline (scipy's
    evaluator) within the path tolerance of the programmed polyline; the splines within
    their share (SHARE) of it and the summary's deviation bound above what is measured;
    something was smoothed (the test is not vacuous)."""
    rng = np.random.default_rng(1000 * seed + 10 * dim + len(mode))
    make = _raster if kind == "raster" else _curve_with_reversal
    vertices = np.round(make(rng, dim == 3), 4)
    machine = load_machine()
    tol_mm = (
        float(mode.split("P")[1].split()[0]) if "P" in mode else (machine.limits.path_tolerance_mm)
    )
    prog = interpret_text(_program(vertices, mode, float(rng.uniform(600, 3000))))
    run = run_program(prog, machine, _options())
    smoothed = run.plan.pieces.smoothed
    assert smoothed is not None and smoothed["runs"] >= 1 and smoothed["lines"] >= 8
    polyline = _feed_polyline(prog)
    s = run.samples
    feed_lines = sorted({g.line for g in prog.segments if g.kind == "line"})
    on_feed = np.isin(s.line, feed_lines)
    dev_mm = segment_distance_mm(s.points_mm[on_feed], polyline)
    assert dev_mm.max() <= tol_mm * (1 + 1e-9)
    # The splines themselves, evaluated by scipy, to the programmed polyline.
    # (the planner's fit: its share less the PH fit tolerance kept for a corner inside)
    reserve_mm = machine.limits.ph_tolerance_mm
    index = np.arange(len(prog.segments))
    segs, _ = smooth_runs(prog.segments, index, machine, None, reserve_mm)
    fitted = [g for g in segs if getattr(g, "smoothed", False)]
    assert len(fitted) >= smoothed["runs"]
    worst_mm = max(_spline_distance_mm(g, polyline) for g in fitted)
    assert worst_mm <= (SHARE * tol_mm - reserve_mm) * (1 + 1e-9)
    # (a straight pass is fitted exactly: both are then rounding, ~1e-16 mm)
    assert 1e-3 * smoothed["deviation_max_um"] >= worst_mm * (1 - 1e-6) - 1e-12


def test_g61_programs_stay_exact():
    """The same dense raster under G61 and G61.1: nothing is fitted, and the plan is the
    one without smoothing, point for point."""
    rng = np.random.default_rng(7)
    vertices = np.round(_raster(rng, True), 4)
    machine = load_machine()
    for mode in ("G61", "G61.1"):
        prog = interpret_text(_program(vertices, mode, 1500.0))
        run = run_program(prog, machine, _options())
        assert run.plan.pieces.smoothed is None
        assert run.plan.pieces.kind_counts().get("nurbs", 0) == 0
        plain = run_program(prog, machine, _options(smooth=False))
        np.testing.assert_array_equal(run.samples.points_mm, plain.samples.points_mm)


@pytest.mark.parametrize("relative", PAPER_PROGRAMS)
def test_paper_programs_are_not_smoothed(relative):
    """The paper's benchmark programs (airfoil NURBS, pentagram and squares of long lines)
    hold no run of short lines: smoothing leaves their segments as written, so their plans
    (Table 4, the airfoil's 0.46 s) are the same with it on."""
    prog = interpret_text((ROOT / relative).read_text())
    segs, source = smooth_runs(prog.segments, np.arange(len(prog.segments)), load_machine())
    assert len(segs) == len(prog.segments)
    assert all(a is b for a, b in zip(segs, prog.segments))


@pytest.mark.parametrize("name", CAM_PROGRAMS)
def test_corpus_cam_splines_stay_within_their_share(name):
    """The corpus's real CAM programs: every fitted spline (scipy's evaluator) within its
    share of the path tolerance of its run's programmed vertices."""
    path = CORPUS / "cam" / name
    if not path.is_file():
        pytest.skip(f"corpus program {path} absent (set NURBSCNC_CORPUS)")
    machine = load_machine(ROOT / "bench" / "programs" / "linuxcnc_limits.toml")
    prog = interpret_text(path.read_text(errors="replace"))
    segs, source = smooth_runs(prog.segments, np.arange(len(prog.segments)), machine)
    fitted = [(g, i) for g, i in zip(segs, source.tolist()) if getattr(g, "smoothed", False)]
    if not fitted:
        pytest.skip(f"{name}: no run of short lines under G64")
    by_line = {g.line: g for g in prog.segments if g.kind == "line"}
    for g, _ in fitted:
        moves = [by_line[int(n)] for n in g.line_numbers]
        v = np.array([moves[0].start_mm] + [m.end_mm for m in moves], dtype=float)
        # the spline's part of the run: from its first move's start to its last move's end
        tol_mm = g.blend_mm / (1.0 - SHARE)  # the spline left (1 − SHARE) × tol to blends
        assert _spline_distance_mm(g, _dense(v), per_span=10) <= SHARE * tol_mm * (1 + 1e-9)
