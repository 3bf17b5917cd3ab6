"""Raster turn-arounds rounded by one U curve (nurbscnc.plan.turnarounds,
nurbscnc.geometry.turnaround).

References independent of the code under test: the U's Bernstein sums in plain numpy, exact
point-to-segment distances to the programmed segments, the servo's Taylor coefficients from
the transfer function's coefficients in closed form, and the independent servo simulation of
tests/servo_reference.py (scipy.signal.lsim) on the planned reference points.
"""

from __future__ import annotations

from dataclasses import replace
from math import comb
from pathlib import Path

import numpy as np
import pytest

from nurbscnc.geometry.blend import line_corner_blends
from nurbscnc.geometry.turnaround import turn_blend
from nurbscnc.machine.profile import load_machine
from nurbscnc.pipeline import RunOptions, run_program
from nurbscnc.plan import allowance, turnarounds
from nurbscnc.plan.corners import CornerAction, CornerWhy
from nurbscnc.plan.options import LookaheadOptions, PlanOptions
from nurbscnc.program.interpret import interpret_text
from tests.servo_reference import lsim_actual_mm, segment_distance_mm, stop_at_vertex_mm

ROOT = Path(__file__).resolve().parent.parent
LINUXCNC_LIMITS = ROOT / "bench" / "programs" / "linuxcnc_limits.toml"


def _segment_distance(q: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact distance [mm] of points q (n, 3) to the segment a–b."""
    ab = b - a
    f = np.clip((q - a) @ ab / max(float(ab @ ab), 1e-300), 0.0, 1.0)
    return np.linalg.norm(q - a - f[:, None] * ab, axis=1)


def _polyline_distance(q: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """Exact distance [mm] of points q (n, 3) to the polyline ``vertices`` (m, 3)."""
    return np.min([_segment_distance(q, a, b) for a, b in zip(vertices[:-1], vertices[1:])], axis=0)


def _bernstein(ctrl: np.ndarray, u: np.ndarray, deriv: int = 0) -> np.ndarray:
    """A Bézier curve (control points ``ctrl`` (k, 3)) or its derivative at ``u``."""
    pts = np.asarray(ctrl, dtype=float)
    for _ in range(deriv):
        pts = (pts.shape[0] - 1) * np.diff(pts, axis=0)
    n = pts.shape[0] - 1
    return sum(comb(n, i) * (u**i * (1 - u) ** (n - i))[:, None] * pts[i] for i in range(n + 1))


CURVES = [
    (width, tol, slope) for width in (0.3, 0.5, 0.8) for tol in (0.05, 0.1) for slope in (0.0, 0.2)
]


@pytest.mark.parametrize("width, tol, slope", CURVES)
def test_u_curve_stays_within_the_tolerance_and_meets_the_lines_g2(width, tol, slope):
    """The U through both corners of a stepover (3-D: the passes climb and fall), evaluated
    by plain Bernstein sums at 20,001 points, within the tolerance of the programmed
    segments, and every programmed point it replaces within the tolerance of it; its ends on
    the lines, tangent to them, with zero curvature; its reported peak curvature the
    sampled one."""
    c1, c2 = np.array([0.0, 60.0, -2.0]), np.array([width, 60.0, -2.0 + 0.3 * width])
    t_a = np.array([0.0, 1.0, slope]) / np.hypot(1.0, slope)
    t_b = np.array([0.0, -1.0, slope]) / np.hypot(1.0, slope)
    bl = turn_blend(c1, t_a, c2, t_b, tol, 0.375)
    assert bl is not None
    ctrl = np.asarray(bl.curve.control_points_mm)
    u = np.linspace(0.0, 1.0, 20001)
    pts = _bernstein(ctrl, u)
    programmed = np.array([c1 - 2.0 * t_a, c1, c2, c2 + 2.0 * t_b])
    assert _polyline_distance(pts, programmed).max() <= tol * (1 + 1e-9)
    # The replaced corner path, densely, to the curve's dense polyline (chord sag ≤ 1e-9 mm).
    p0, p5 = c1 - bl.trim_a_mm * t_a, c2 + bl.trim_b_mm * t_b
    corner = np.vstack(
        [
            a + np.linspace(0.0, 1.0, 400)[:, None] * (b - a)
            for a, b in ((p0, c1), (c1, c2), (c2, p5))
        ]
    )
    step = 50
    assert _polyline_distance(corner, pts[::step]).max() <= tol * (1 + 1e-6) + 1e-6
    np.testing.assert_allclose(ctrl[0], p0, atol=1e-12)
    np.testing.assert_allclose(ctrl[-1], p5, atol=1e-12)
    d1 = _bernstein(ctrl, np.array([0.0, 1.0]), 1)
    d2 = _bernstein(ctrl, np.array([0.0, 1.0]), 2)
    np.testing.assert_allclose(d1[0] / np.linalg.norm(d1[0]), t_a, atol=1e-12)
    np.testing.assert_allclose(d1[1] / np.linalg.norm(d1[1]), t_b, atol=1e-12)
    kappa_ends = np.linalg.norm(np.cross(d1, d2), axis=1) / np.linalg.norm(d1, axis=1) ** 3
    assert kappa_ends.max() <= 1e-9
    d1, d2 = _bernstein(ctrl, u, 1), _bernstein(ctrl, u, 2)
    kappa = np.linalg.norm(np.cross(d1, d2), axis=1) / np.linalg.norm(d1, axis=1) ** 3
    assert bl.kappa_max_per_mm == pytest.approx(kappa.max(), rel=2e-3)
    # Turning 180° within the stepover (widened by the tolerance each side) needs 2/width at
    # least; where the stepover is narrow for the tolerance (≤ 10 tol: a raster's), the U
    # stays below the peak of one 90° blend in the same tolerance.
    assert bl.kappa_max_per_mm >= 2.0 / (width + 2.0 * tol)
    if width > 10.0 * tol:
        return
    m = (c2 - c1) / np.linalg.norm(c2 - c1)
    one = line_corner_blends(
        c1[None], t_a[None], m[None], np.array([tol]), np.array([0.375]), np.array([width / 2])
    )
    assert bl.kappa_max_per_mm < float(one.kappa_max_per_mm[0])


def test_no_u_where_the_tolerance_cannot_hold_one():
    """A 0.5 mm stepover under 15 µm: no U keeps that close to both corners."""
    c1, c2 = np.array([0.0, 0.0, 0.0]), np.array([0.5, 0.0, 0.0])
    assert (
        turn_blend(c1, np.array([0.0, 1.0, 0.0]), c2, np.array([0.0, -1.0, 0.0]), 0.015, 0.3)
        is None
    )


def test_stop_deceleration_is_the_servos_overshoot_bound():
    """A_s = ε / (c₂ sin θ) below 90° and ε / c₂ from 90° to a full reversal, with c₂ of the
    profile's servo in closed form (1 − G(s) = c₁ s + c₂ s² + …: c₁ = (a1 − b1)/a0,
    c₂ = (a2 − b2 − a1 c₁)/a0), capped by A; A without a servo model. (It was the other way
    round: ε / c₂ below 90°, ε / (c₂ sin θ) past it and A at a reversal, where the check's
    stop takes ~41 ms, not the 6 ms of a stop at A.)"""
    machine = load_machine(LINUXCNC_LIMITS)
    lim = machine.limits
    c2 = 0.0
    for ax in (machine.servo.x, machine.servo.y):
        c1 = (ax.a1 - ax.b1) / ax.a0
        c2 = max(c2, abs((ax.a2 - ax.b2 - ax.a1 * c1) / ax.a0 + 0.5 * c1 * c1))
    turns = np.radians([90.0, 45.0, 120.0, 170.0, 180.0, 5.0])
    got = turnarounds.stop_deceleration_mm_s2(machine, turns)
    eps = lim.contour_tolerance_mm
    expected = [eps / c2, eps / (c2 * np.sin(turns[1])), eps / c2, eps / c2, eps / c2]
    np.testing.assert_allclose(got[:5], expected, rtol=1e-9)
    assert got[5] == lim.a_max_mm_s2  # ε / (c₂ sin 5°) is above A
    no_servo = replace(machine, servo=replace(machine.servo, x=None, y=None, z=None))
    np.testing.assert_array_equal(
        turnarounds.stop_deceleration_mm_s2(no_servo, np.radians([90.0])), [lim.a_max_mm_s2]
    )


def _stop_overshoot_um(machine, decel_mm_s2: float, turn_deg: float) -> float:
    """Largest distance [µm] of the tool (lsim, tests/servo_reference.py) to a two-segment
    path turning by ``turn_deg`` at the origin, around a stop there: 0.3 s at 25 mm/s along
    +X, a constant deceleration to rest at the vertex, the mirror image out along the
    outgoing segment (1 ms samples, exact sums of the speeds)."""
    act, dense = stop_at_vertex_mm(machine, decel_mm_s2, turn_deg)
    return 1000.0 * float(segment_distance_mm(act, dense).max())


@pytest.mark.parametrize("turn_deg", [45.0, 60.0, 80.0, 100.0, 150.0, 176.0, 180.0])
def test_stop_overshoot_bound_holds_in_an_independent_simulation(turn_deg):
    """Independently of the planner: stopped at 25 mm/s, the tool overshoots the vertex by
    c₂·a, sin θ of it off the path below 90° and all of it from 90° to a full reversal
    (ended at A = 2450 mm/s²: 43.7 µm at 45°, 61.8 µm from 90° on, all beyond ε), and
    stays within ε when the stop ends at A_s (14.7–14.9 µm)."""
    machine = load_machine(LINUXCNC_LIMITS)
    eps_um = 1000.0 * machine.limits.contour_tolerance_mm
    a_s = float(turnarounds.stop_deceleration_mm_s2(machine, np.radians([turn_deg]))[0])
    at_a = _stop_overshoot_um(machine, 2450.0, turn_deg)
    assert at_a > 2.5 * eps_um
    off = np.sin(np.radians(turn_deg)) if turn_deg < 90.0 else 1.0
    np.testing.assert_allclose(at_a, 61.8 * off, rtol=0.02)
    assert _stop_overshoot_um(machine, a_s, turn_deg) <= eps_um


def _raster_program(passes: int, length_mm: float, stepover_mm: float, tol_mm: float) -> str:
    """Serpentine passes along Y of 0.75 mm chords over a wavy surface, stepover in X."""
    out = [f"G21 G17 G90 G64 P{tol_mm:g}", "G0 Z3", "G0 X0 Y0", "G1 Z-2 F600", "F2000"]
    y = np.linspace(0.0, length_mm, round(length_mm / 0.75) + 1)
    for k in range(passes):
        x = k * stepover_mm
        ys = y if k % 2 == 0 else y[::-1]
        zs = -2.0 + 0.5 * np.sin(2 * np.pi * x / 10.0) * np.cos(2 * np.pi * ys / 12.0)
        if k > 0:
            out.append(f"G1 X{x:.4f} Z{zs[0]:.4f}")
        out.extend(f"G1 Y{a:.4f} Z{b:.4f}" for a, b in zip(ys[1:], zs[1:]))
    return "\n".join(out + ["G0 Z3", "M2", ""])


def _reversal_program(tol_mm: float) -> str:
    """A pass along +X, a 0.5 mm middle line turning 85°, the pass back at 170° from the
    first (another 85°), G64 P."""
    back, side = np.radians(170.0), np.radians(85.0)
    mid = 0.5 * np.array([np.cos(side), np.sin(side)])
    end = mid + 8.0 * np.array([np.cos(back), np.sin(back)])
    return "\n".join(
        [
            f"G21 G17 G90 G64 P{tol_mm:g}",
            "G0 X-8 Y0 Z0",
            "G1 X0 F2000",
            f"G1 X{mid[0]:.6f} Y{mid[1]:.6f}",
            f"G1 X{end[0]:.6f} Y{end[1]:.6f}",
            "M2",
            "",
        ]
    )


def _run(text: str, machine, dynamics: str = "local"):
    prog = interpret_text(text)
    opts = RunOptions(lookahead=LookaheadOptions(dynamics=dynamics, plan=PlanOptions()))
    return prog, run_program(prog, machine, opts)


def _feed_vertices(prog) -> np.ndarray:
    feed = [s for s in prog.segments if s.kind == "line" and not s.rapid]
    return np.array([feed[0].start_mm] + [s.end_mm for s in feed], dtype=float)


CASES = [("raster", 0.1), ("raster", 0.05), ("reversal", 0.1)]


@pytest.fixture
def no_corner_allowance(monkeypatch):
    """The check and the stops' cost without the corner allowances
    (nurbscnc.plan.allowance): a stop's overshoot held within ε_max of the path, as the U's
    choice was made and measured before them (with them, a stop under G64 P0.1 may end at
    A: tests/test_corner_allowance.py)."""
    monkeypatch.setattr(allowance, "CORNER_ALLOWANCE", False)


@pytest.mark.parametrize("kind, tol_mm", CASES)
def test_turnaround_blended_within_tolerance_and_servo_bound(kind, tol_mm, no_corner_allowance):
    """Under LinuxCNC's limits with the contour check (no corner allowance): every
    turn-around is rounded (the corner log says BLEND at both its corners), every planned
    feed point within the path tolerance of the programmed segments, and the tool of the
    independent servo simulation within ε_max of the planned points' polyline and within
    ε_max + tolerance of the programmed segments."""
    machine = load_machine(LINUXCNC_LIMITS)
    text = _raster_program(3, 9.0, 0.5, tol_mm) if kind == "raster" else _reversal_program(tol_mm)
    prog, run = _run(text, machine)
    log = run.plan.pieces.corners
    blended = log.action == CornerAction.BLEND
    sharp = log.turning_rad > np.radians(60.0)
    expected = 4 if kind == "raster" else 2  # two corners per turn-around
    assert int((blended & sharp).sum()) >= expected
    rapid = log.why == CornerWhy.RAPID_FEED  # the plunge's start and the retract
    assert not np.any((log.action == CornerAction.STOP) & sharp & ~rapid)
    s = run.samples
    feed_lines = sorted({g.line for g in prog.segments if g.kind == "line" and not g.rapid})
    on_feed = np.isin(s.line, feed_lines)
    vertices = _feed_vertices(prog)
    assert _polyline_distance(s.points_mm[on_feed], vertices).max() <= tol_mm * (1 + 1e-9)
    actual = lsim_actual_mm(s.points_mm, machine)[: len(s.points_mm)]
    eps = machine.limits.contour_tolerance_mm
    # The planned points (1 ms apart, ≤ 35 µm: chords within 1 µm of the plan) as its path.
    to_plan = _polyline_distance(actual[on_feed], s.points_mm)
    assert to_plan.max() <= eps + 1e-3
    assert _polyline_distance(actual[on_feed], vertices).max() <= eps + tol_mm


def test_turnaround_is_quicker_than_stopping(monkeypatch, no_corner_allowance):
    """The same raster with turn-arounds found (U) and not (the corners stopped, as before),
    no corner allowance: the U saves at least 10 ms a turn-around of the checked plan's time
    (15 ms measured)."""
    machine = load_machine(LINUXCNC_LIMITS)
    text = _raster_program(3, 9.0, 0.5, 0.1)
    _, with_u = _run(text, machine)
    monkeypatch.setattr(turnarounds, "MIN_REVERSAL_DEG", 181.0)  # no turn-around found
    _, stops = _run(text, machine)
    stopped = stops.plan.pieces.corners
    assert int((stopped.action == CornerAction.STOP).sum()) >= 4
    saved_s = stops.plan.cycle_time_s - with_u.plan.cycle_time_s
    assert saved_s >= 2 * 0.010
