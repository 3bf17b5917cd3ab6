"""The benchmark's independent contour-error tools (bench/contour.py) against closed forms.

Not timing tests: these check that the measure the planner benchmark relies on is right.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))

import contour  # noqa: E402

from nurbscnc.geometry.segments import Nurbs  # noqa: E402
from nurbscnc.program.interpret import interpret_text  # noqa: E402


def _second_order(wn: float, zeta: float):
    """G(s) = wn² / (s² + 2ζ wn s + wn²) as (numerator, denominator)."""
    return (wn * wn,), (1.0, 2.0 * zeta * wn, wn * wn)


@pytest.mark.parametrize("zeta", [1.0, 0.5])
def test_circle_steady_state_radial_error_matches_gain(zeta):
    """A circle of radius R at angular speed ω through a 2nd-order servo on both axes: in
    steady state the tool runs on a circle of radius R·|G(jω)|, so its distance from the
    path is R(1 − |G(jω)|), |G(jω)| = wn² / √((wn² − ω²)² + (2ζ wn ω)²)."""
    radius_mm, speed_mm_s, period_s = 10.0, 50.0, 1e-3
    wn = 2.0 * math.pi * 5.0
    omega = speed_mm_s / radius_mm
    model = _second_order(wn, zeta)
    t = np.arange(0.0, 4.0, period_s)
    ref = np.column_stack(
        [radius_mm * np.cos(omega * t), radius_mm * np.sin(omega * t), np.zeros_like(t)]
    )
    tool = contour.simulate_tool_mm(ref, period_s, settle_s=0.0, models={"x": model, "y": model})
    theta = np.linspace(0.0, 2.0 * math.pi, 20001)
    circle = np.column_stack(
        [radius_mm * np.cos(theta), radius_mm * np.sin(theta), np.zeros_like(theta)]
    )
    steady = t >= 2.0  # the transient decays as e^(−ζ wn t) < 2e-14 by then
    dist = contour.distance_to_polyline_mm(tool[steady], circle)
    gain = wn**2 / math.hypot(wn**2 - omega**2, 2.0 * zeta * wn * omega)
    expected_mm = radius_mm * (1.0 - gain)
    # the first-order hold of the 1 ms samples scales the circle by sinc²(ωT/2) ≈ 1 − 2e-6
    assert dist == pytest.approx(np.full(dist.shape, abs(expected_mm)), abs=1e-4)


def test_simulate_starts_at_rest_and_follows_a_constant():
    ref = np.tile([3.0, -2.0, 1.0], (50, 1))
    tool = contour.simulate_tool_mm(ref, settle_s=0.01)
    assert tool.shape == (60, 3)
    np.testing.assert_allclose(tool, np.tile([3.0, -2.0, 1.0], (60, 1)), atol=1e-12)


def test_distance_is_to_segments_not_vertices():
    """A polyline with few vertices: the distance is to the segment (closed form), not to
    the nearest vertex."""
    poly = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [10.0, 10.0, 0.0]])
    pts = np.array(
        [
            [5.0, 0.3, 0.0],
            [5.0, -2.0, 1.0],
            [12.0, 5.0, 0.0],
            [13.0, -4.0, 0.0],
            [9.0, 1.0, 0.0],
            [-3.0, 4.0, 0.0],
        ]
    )
    expected = [0.3, math.hypot(2.0, 1.0), 2.0, 5.0, 1.0, 5.0]
    np.testing.assert_allclose(
        contour.distance_to_polyline_mm(pts, poly), expected, rtol=0, atol=1e-12
    )


def test_arc_path_lies_on_its_circle():
    """The dense path of G2/G3 arcs: every vertex at the arc's radius from its centre."""
    prog = interpret_text(
        "G21 G17 G90\nG0 X10 Y0\nG3 X-10 Y0 I-10 J0 F600\nG2 X-30 Y0 I-10 J0\nM2\n"
    )
    arcs = [s for s in prog.segments if s.kind == "arc"]
    first = contour.path_polyline_mm(arcs[:1])  # G3 about the origin: the upper half
    np.testing.assert_allclose(np.hypot(first[:, 0], first[:, 1]), 10.0, atol=1e-9)
    assert first[:, 1].min() == pytest.approx(0.0, abs=1e-9)
    assert first[:, 1].max() == pytest.approx(10.0, abs=1e-6)
    second = contour.path_polyline_mm(arcs[1:])  # G2 about (−20, 0) from X−10: lower half
    np.testing.assert_allclose(np.hypot(second[:, 0] + 20.0, second[:, 1]), 10.0, atol=1e-9)
    assert second[:, 1].max() == pytest.approx(0.0, abs=1e-9)
    assert second[:, 1].min() == pytest.approx(-10.0, abs=1e-6)
    np.testing.assert_allclose(second[[0, -1], 0], [-10.0, -30.0], atol=1e-9)


def test_rational_quarter_circle():
    """The rational quadratic with weights 1, √2/2, 1 is exactly a quarter circle."""
    seg = Nurbs(
        degree=2,
        knots=np.array([0.0, 0, 0, 1, 1, 1]),
        control_points_mm=np.array([[5.0, 0, 0], [5.0, 5.0, 0], [0.0, 5.0, 0]]),
        weights=np.array([1.0, math.sqrt(0.5), 1.0]),
        feed_mm_s=10.0,
        line=1,
    )
    poly = contour.path_polyline_mm([seg])
    np.testing.assert_allclose(np.hypot(poly[:, 0], poly[:, 1]), 5.0, rtol=0, atol=1e-12)
    assert np.max(np.linalg.norm(np.diff(poly, axis=0), axis=1)) < 2.1e-3


def test_motion_span_and_block_start():
    ref = np.zeros((10, 3))
    ref[3:7, 0] = [1.0, 2.0, 3.0, 4.0]
    ref[7:, 0] = 4.0
    span = contour.motion_span(ref)
    assert (span.start_index, span.end_index) == (2, 6)
    assert span.seconds == pytest.approx(0.004)
    lines = np.array([3, 3, 3, 3, 0, 5, 5, 0, 5, 5])
    assert contour.block_start_index(lines, 5) == 3


def test_block_timed_from_the_last_rest_at_its_start():
    """A rapid (line 3) arrives at x = 2, the reference waits there 3 samples (labelled with
    the block's line 5), then the block moves: the block starts at the last rest sample."""
    x = np.array([0.0, 1.0, 1.9, 2.0, 2.0, 2.0, 2.0, 2.5, 3.0, 3.0])
    pts = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    lines = np.array([3, 3, 3, 5, 5, 5, 5, 5, 5, 5])
    assert contour.block_leave_index(pts, lines, 5) == (2, 6)
    lines_blend = np.array([3, 3, 3, 3, 3, 3, 3, 5, 5, 5])  # no wait labelled as the block
    assert contour.block_leave_index(pts, lines_blend, 5) == (6, 6)


def _bench_generator():
    import importlib.util

    path = Path(__file__).resolve().parents[1] / "bench" / "programs" / "make_bench_programs.py"
    spec = importlib.util.spec_from_file_location("make_bench_programs", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_bench_programs_are_reproduced_by_their_generator():
    gen = _bench_generator()
    for name, text in gen.build_programs().items():
        assert (gen.HERE / name).read_text(encoding="ascii") == text, name


def test_pentagram_edges_are_38_mm():
    """Five edges of 38 mm each, closing on the first vertex, every vertex on the circle of
    radius 19 / sin 72° (an edge is the chord over 144°: 2 R sin 72° = 38)."""
    prog = interpret_text((_bench_generator().HERE / "pentagram_g61.nc").read_text())
    edges = [s for s in prog.segments if s.kind == "line"]
    assert [round(s.length_mm, 5) for s in edges] == [38.0] * 5
    assert np.allclose(edges[-1].end_mm, edges[0].start_mm)
    radius = 19.0 / math.sin(math.radians(72.0))
    assert all(math.hypot(*s.end_mm[:2]) == pytest.approx(radius, abs=1e-6) for s in edges)


def test_slow_drops_counts_the_stops():
    """Speeds 1, 0, 1, 0.2, 0.2, 1, 1, 0 mm/s (T = 1 s): three drops below 0.5 mm/s."""
    x = np.cumsum([0.0, 1.0, 0.0, 1.0, 0.2, 0.2, 1.0, 1.0, 0.0])
    pts = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    assert contour.slow_drops(pts, period_s=1.0) == 3


def test_settle_waits_are_the_rest_at_a_cut_start_after_a_rapid():
    """The rapid (line 3) arrives at x = 2; the reference rests there 4 samples labelled with
    the cut's line 5, then moves: those 4 are the wait. A cut entered moving has none, nor
    does a rest inside a cut (a dwell) or a cut at the stream's start."""
    x = np.array([0.0, 1.0, 1.9, 2.0, 2.0, 2.0, 2.0, 2.5, 3.0, 3.0])
    pts = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    cut = np.array([3, 3, 3, 5, 5, 5, 5, 5, 5, 5]) != 3
    np.testing.assert_array_equal(np.flatnonzero(contour.settle_waits(pts, cut)), [3, 4, 5, 6])
    # the rapid's last sample at rest at the start point, the cut's first already there
    cut_late = np.array([3, 3, 3, 3, 5, 5, 5, 5, 5, 5]) != 3
    np.testing.assert_array_equal(np.flatnonzero(contour.settle_waits(pts, cut_late)), [4, 5, 6])
    entered_moving = np.array([3, 3, 3, 3, 3, 3, 3, 5, 5, 5]) != 3
    assert not contour.settle_waits(pts, entered_moving).any()
    assert not contour.settle_waits(pts, np.ones(10, dtype=bool)).any()
