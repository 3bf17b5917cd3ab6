"""Rotary axes A B C in the planner and the interpolators (plan/rotary.py and its callers).

Programs are built by hand (``Line(..., abc_deg=...)``, ``Rotate(...)``) as the interpreter
makes them, and the machine by ``dataclasses.replace(machine, rotary_axes=...)``. The
references are independent of the planner: finite differences of the sampled A B C and
X Y Z against each axis's limits, and the textbook time of a jerk-limited rest-to-rest move
(the 7-phase S-curve, written out here) — not the planner's own functions.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nurbscnc.errors import ConfigError, PlanningError
from nurbscnc.geometry.segments import Arc, Dwell, Line, Program, Rotate
from nurbscnc.machine.model import RotaryAxis
from nurbscnc.machine.profile import load_machine
from nurbscnc.pipeline import RunOptions, run_program
from nurbscnc.plan.explain import explain_plan
from nurbscnc.plan.limits import check_before_work
from nurbscnc.plan.lowerbound import program_lower_bound_s
from nurbscnc.plan.options import LookaheadOptions
from nurbscnc.plan.program_pieces import segment_pieces
from nurbscnc.plan.report import check_rotary_limits

#: The A axis of the tests: 60 deg/s (3600 deg/min), 400 deg/s², 4000 deg/s³.
A_AXIS = RotaryAxis("a", 60.0, 400.0, 4000.0)
B_AXIS = RotaryAxis("b", 30.0, 250.0, 1500.0)
OFF = RunOptions(lookahead=LookaheadOptions(dynamics="off"))


def machine(*axes, **overrides):
    """The default machine (servo period 1 ms) with rotary ``axes`` and profile
    ``overrides``."""
    m = load_machine(overrides=overrides) if overrides else load_machine()
    return dataclasses.replace(m, rotary_axes={ax.name: ax for ax in axes or (A_AXIS,)})


def program(*segments, start=(0.0, 0.0, 0.0), axes=("a",), abc=(0.0, 0.0, 0.0)):
    return Program(segments=tuple(segments), start_mm=start, rotary_axes=axes, start_abc_deg=abc)


def line(p0, p1, f_mm_s, n, a0=None, a1=None, **kw):
    abc = None if a0 is None else (a0, 0.0, 0.0, a1, 0.0, 0.0)
    return Line(tuple(map(float, p0)), tuple(map(float, p1)), f_mm_s, n, abc_deg=abc, **kw)


def ramp_s(v, a, j):
    """Time of a jerk-limited speed change 0 → v at zero acceleration at both ends (the
    trapezoidal acceleration profile; a triangle when v < a²/j)."""
    return v / a + a / j if v >= a * a / j else 2.0 * math.sqrt(v / j)


def rest_to_rest_s(length, v, a, j):
    """The textbook time of a rest-to-rest move of ``length`` under v, a, j (7 phases): the
    distance of a ramp to speed w and back down is w·ramp(w); cruise when V fits, else the
    peak w solves w·ramp(w) = length (closed form in each branch of ramp)."""
    if length >= v * ramp_s(v, a, j):
        return length / v + ramp_s(v, a, j)
    knee = a * a / j
    if length >= knee * ramp_s(knee, a, j):  # w ≥ a²/j: w²/a + w·a/j = length
        w = 0.5 * (-knee + math.sqrt(knee * knee + 4.0 * a * length))
    else:  # w < a²/j: 2·w·√(w/j) = length
        w = (length * length * j / 4.0) ** (1.0 / 3.0)
    return 2.0 * ramp_s(w, a, j)


def differences(x, period_s):
    """Velocity, acceleration and jerk (finite differences) of samples ``x`` (N, …)."""
    v = np.diff(x, axis=0) / period_s
    acc = np.diff(v, axis=0) / period_s
    return v, acc, np.diff(acc, axis=0) / period_s


def assert_axis_within(x, period_s, v_max, a_max, j_max, rel=1e-6):
    peaks = [np.abs(d).max(initial=0.0) for d in differences(x, period_s)]
    assert peaks[0] <= v_max * (1.0 + rel)
    assert peaks[1] <= a_max * (1.0 + rel)
    assert peaks[2] <= j_max * (1.0 + rel)
    return peaks


def assert_span(x, duration_s, period_s):
    """The intervals in which ``x`` changes span the move's ``duration_s``: the first begins
    at most a period before its start, the last ends at most a period after its end."""
    moving = np.flatnonzero(np.diff(x) != 0.0)
    span_s = (moving[-1] + 1 - moving[0]) * period_s
    assert duration_s - 1e-9 <= span_s <= duration_s + 2.0 * period_s + 1e-9
    return moving


# -- rotary-only moves -----------------------------------------------------------------------
@pytest.mark.parametrize(
    ("delta_deg", "f_deg_min"),
    [
        (90.0, 1800.0),  # 30 deg/s < a²/j = 40: the acceleration never reaches 400
        (300.0, 3000.0),  # 50 deg/s ≥ 40: acceleration reached, then cruise
        (2.0, 3000.0),  # too short to reach the rate: a peak below it
        (720.0, 9000.0),  # F above the axis's 3600 deg/min: the axis's own V
    ],
)
def test_rotary_only_move_takes_the_textbook_time(delta_deg, f_deg_min):
    m = machine()
    rot = Rotate((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (delta_deg, 0.0, 0.0), f_deg_min / 60.0, 1)
    run = run_program(program(rot), m, OFF)
    v = min(f_deg_min / 60.0, A_AXIS.v_max_deg_s)
    expected = rest_to_rest_s(delta_deg, v, A_AXIS.a_max_deg_s2, A_AXIS.j_max_deg_s3)
    assert run.cycle_time_s == pytest.approx(expected, rel=1e-9)
    s = run.samples
    a = s.abc_deg[:, 0]
    assert a[0] == 0.0 and a[-1] == pytest.approx(delta_deg, abs=1e-9)
    assert_span(a, expected, m.servo.period_s)
    peak_v, _, _ = assert_axis_within(
        a, m.servo.period_s, A_AXIS.v_max_deg_s, A_AXIS.a_max_deg_s2, A_AXIS.j_max_deg_s3
    )
    if delta_deg > 100.0:  # long enough to cruise: at the rate, within a sample's rounding
        assert peak_v == pytest.approx(v, rel=1e-6)
    assert np.all(s.points_mm == 0.0)  # X Y Z rest


def test_rotary_move_of_two_axes_shares_their_limits():
    """A and B turn together: each within its own limits, the move along √(ΔA² + ΔB²) with
    each axis's limits divided by its share."""
    m = machine(A_AXIS, B_AXIS)
    d = np.array([120.0, -90.0, 0.0])
    start = np.array([10.0, 20.0, 0.0])
    rot = Rotate((0.0, 0.0, 0.0), tuple(start), tuple(start + d), 0.0, 3, rapid=True)
    run = run_program(program(rot, axes=("a", "b")), m, OFF)
    length = float(np.linalg.norm(d))
    share = np.abs(d[:2]) / length
    lim = [
        min(x / s for x, s in zip(limits, share))
        for limits in ((60.0, 30.0), (400.0, 250.0), (4000.0, 1500.0))
    ]
    assert run.cycle_time_s == pytest.approx(rest_to_rest_s(length, *lim), rel=1e-9)
    abc = run.samples.abc_deg
    for i, ax in enumerate((A_AXIS, B_AXIS)):
        assert_axis_within(
            abc[:, i], m.servo.period_s, ax.v_max_deg_s, ax.a_max_deg_s2, ax.j_max_deg_s3
        )
    assert abc[-1, :2] == pytest.approx([130.0, -70.0], abs=1e-9)
    assert run.samples.rotary_axes == ("a", "b")


# -- moves of X Y Z with A --------------------------------------------------------------------
def mixed_program():
    """X with A, a rotary-only move and a dwell between, Y with A the other way, an arc with
    A: every axis's rate changes at every junction."""
    return program(
        line((0, 0, 0), (10, 0, 0), 20.0, 1, 0.0, 30.0),
        line((10, 0, 0), (20, 0, 0), 20.0, 2, 30.0, 30.0),
        Rotate((20.0, 0.0, 0.0), (30.0, 0.0, 0.0), (120.0, 0.0, 0.0), 30.0, 3),
        Dwell(0.1, (20.0, 0.0, 0.0), 4),
        line((20, 0, 0), (20, 10, 0), 20.0, 5, 120.0, 100.0),
        Arc(
            np.array([20.0, 10.0, 0.0]),
            np.array([30.0, 10.0, 0.0]),
            np.array([25.0, 10.0, 0.0]),
            np.array([0.0, 0.0, 1.0]),
            -math.pi,  # clockwise, over the top
            0.0,
            5.0,
            5.0,
            15.0,
            6,
            abc_deg=(100.0, 0.0, 0.0, 190.0, 0.0, 0.0),
        ),
    )


def test_mixed_moves_keep_every_axis_within_its_limits():
    axis_over = {
        f"axis_limits.{ax}.{key}": value
        for ax in "xyz"
        for key, value in (("v_max_mm_min", 1500.0), ("a_max_mm_s2", 500.0), ("j_max_mm_s3", 1e4))
    }
    m = machine(**axis_over)
    run = run_program(mixed_program(), m, OFF)
    s = run.samples
    T = m.servo.period_s
    a = s.abc_deg[:, 0]
    peak = assert_axis_within(a, T, 60.0, 400.0, 4000.0)
    assert peak[0] > 0.9 * 60.0  # the A limit is reached somewhere (the tests bite)
    # X Y Z on the lines (the arc's per-axis bounds are sampled ones: lines only here).
    on_lines = np.isin(s.line, (1, 2, 5))
    xyz = s.points_mm[on_lines]
    assert_axis_within(xyz[:, 0], T, 25.0, 500.0, 1e4)
    assert_axis_within(xyz[:, 1], T, 25.0, 500.0, 1e4)
    assert a[-1] == pytest.approx(190.0, abs=1e-9)
    assert s.points_mm[-1] == pytest.approx([30.0, 10.0, 0.0], abs=1e-9)
    # A follows the path linearly along each move (trivkins): on line 5, A = 120 − 2·y.
    on5 = (s.line == 5) & (s.points_mm[:, 1] > 0.0)  # (the stop before it is labelled 5 too)
    assert s.abc_deg[on5, 0] == pytest.approx(120.0 - 2.0 * s.points_mm[on5, 1], abs=1e-9)


def test_a_rate_sets_the_feed_and_explain_names_the_axis():
    """30 deg/mm at A's 60 deg/s: 2 mm/s along X whatever F says."""
    m = machine()
    prog = program(line((0, 0, 0), (10, 0, 0), 20.0, 1, 0.0, 300.0))
    run = run_program(prog, m, OFF)
    v = np.diff(run.samples.points_mm[:, 0]) / m.servo.period_s
    assert v.max() == pytest.approx(2.0, rel=1e-6)
    expl = explain_plan(prog, m, run.plan)
    entry = expl.line_dicts()[0]
    assert entry["limit"] == "axis" and entry["axis"] == "a"
    assert expl.limit_text(0) == "axis limit (A)"


def test_a_g93_move_takes_its_inverse_time():
    """G93 F2: 10 mm with A 90° in 0.5 min; the interpreter's rate is length × F. On stiff
    limits the ramps fit within a servo period: the move takes 30 s ± a period; on the
    default limits, the textbook time at that feed."""
    f_inverse = 2.0  # per minute
    seg = line((0, 0, 0), (10, 0, 0), 10.0 * f_inverse / 60.0, 1, 0.0, 90.0)
    stiff = machine(
        RotaryAxis("a", 600.0, 1e7, 1e12),
        **{"limits.a_max_mm_s2": 1e6, "limits.j_max_mm_s3": 1e9},
    )
    run = run_program(program(seg), stiff, OFF)
    assert run.cycle_time_s == pytest.approx(60.0 / f_inverse, abs=stiff.servo.period_s)
    m = machine()
    run = run_program(program(seg), m, OFF)
    rate = 9.0  # deg/mm: A's share of the path's acceleration and jerk
    a = min(m.limits.a_max_mm_s2, A_AXIS.a_max_deg_s2 / rate)
    j = min(m.limits.j_max_mm_s3, A_AXIS.j_max_deg_s3 / rate)
    assert run.cycle_time_s == pytest.approx(rest_to_rest_s(10.0, 1.0 / 3.0, a, j), rel=1e-9)


def junction_speed_mm_s(samples, point, period_s):
    """The finite-difference speed at the sample nearest to ``point``."""
    d = np.linalg.norm(samples.points_mm - np.asarray(point), axis=1)
    k = int(np.argmin(d))
    k = min(max(k, 1), d.size - 1)
    return float(np.linalg.norm(samples.points_mm[k] - samples.points_mm[k - 1]) / period_s)


def test_the_tool_stops_where_a_rate_changes_and_passes_where_it_does_not():
    """Three collinear moves: A's rate goes 1 → 2 deg/mm at X10 (a stop), stays 2 at X20
    (passed at speed); G64 everywhere."""
    g64 = math.inf  # blend_mm of G64 without P
    m = machine()
    prog = program(
        line((0, 0, 0), (10, 0, 0), 10.0, 1, 0.0, 10.0, blend_mm=g64),
        line((10, 0, 0), (20, 0, 0), 10.0, 2, 10.0, 30.0, blend_mm=g64),
        line((20, 0, 0), (30, 0, 0), 10.0, 3, 30.0, 50.0, blend_mm=g64),
    )
    run = run_program(prog, m, OFF)
    T = m.servo.period_s
    j_path = m.limits.j_max_mm_s3
    assert junction_speed_mm_s(run.samples, (10, 0, 0), T) <= j_path * T * T
    assert junction_speed_mm_s(run.samples, (20, 0, 0), T) == pytest.approx(10.0, rel=1e-6)
    corners = explain_plan(prog, m, run.plan).corner_dicts()
    assert [(c["line"], c["action"], c["why"]) for c in corners] == [(1, "stop", "a_rate")]


def zigzag_program(n=24):
    """An engraving on a cylinder: X back and forth while A advances by varying steps, G64
    (the corners would be rounded without A)."""
    rng = np.random.default_rng(7)
    x = np.where(np.arange(n + 1) % 2 == 0, 0.0, 4.0) + rng.uniform(-0.5, 0.5, n + 1)
    a = np.cumsum(np.concatenate(([0.0], rng.uniform(2.0, 8.0, n))))
    return (
        program(
            *(
                line((x[i], 0.0, 0.0), (x[i + 1], 0.0, 0.0), 15.0, i + 1, a[i], a[i + 1])
                for i in range(n)
            )
        ),
        x,
        a,
    )


def test_wrapped_engraving_zigzag_stops_at_every_turn_within_the_limits():
    prog, x, a = zigzag_program()
    m = machine(RotaryAxis("a", 40.0, 300.0, 2000.0, wrapped=True))
    run = run_program(prog, m, OFF)
    s = run.samples
    T = m.servo.period_s
    assert_axis_within(s.abc_deg[:, 0], T, 40.0, 300.0, 2000.0)
    assert_axis_within(s.points_mm[:, 0], T, m.limits.v_max_mm_s, 2450.0, 5e4)
    assert s.abc_deg[-1, 0] == pytest.approx(a[-1], abs=1e-9)
    for xi in x[1:-1]:  # a reversal of X and a new A rate at every vertex: the tool stops
        assert junction_speed_mm_s(s, (xi, 0.0, 0.0), T) <= m.limits.j_max_mm_s3 * T * T
    assert run.plan.pieces.kind_counts() == {"line": len(x) - 1}  # nothing blended


# -- programs without rotary axes --------------------------------------------------------------
def corner_program(abc):
    g64 = math.inf
    pts = [(0, 0, 0), (10, 0, 0), (10, 8, 0), (3, 12, 0), (0, 5, 1)]
    return program(
        *(
            line(pts[i], pts[i + 1], 25.0, i + 1, blend_mm=g64)
            if abc is None
            else line(pts[i], pts[i + 1], 25.0, i + 1, abc, abc, blend_mm=g64)
            for i in range(len(pts) - 1)
        )
    )


@pytest.mark.parametrize("abc", [0.0, 90.0])
def test_a_standing_still_plans_the_xyz_path_exactly_as_without(abc):
    """A program whose A never moves (at 0 or held at 90°) plans, blends and samples X Y Z
    bit for bit as the same program without rotary positions."""
    m = machine()
    plain = run_program(corner_program(None), m)
    held = run_program(corner_program(abc), m)
    assert plain.plan.pieces.rotary is None and plain.samples.abc_deg is None
    assert plain.samples.rotary_axes == ()
    assert "ph" in plain.plan.pieces.kind_counts()  # corners blended in both
    np.testing.assert_array_equal(plain.samples.points_mm, held.samples.points_mm)
    np.testing.assert_array_equal(plain.samples.t_s, held.samples.t_s)
    assert np.all(held.samples.abc_deg[:, 0] == abc)


def test_pieces_of_a_program_without_rotary_carry_no_columns():
    pieces = segment_pieces(corner_program(None).segments, load_machine())
    assert pieces.rotary is None


# -- limits and refusals -----------------------------------------------------------------------
# The soft limits of A B C: the interpreter refuses the word that leaves them
# (tests/test_interpret_rotary.py), the samples are checked again here.
def test_rotary_soft_limits_on_samples_name_the_axis_and_line():
    abc = np.zeros((4, 3))
    abc[2, 1] = -5.5
    axes = {"b": RotaryAxis("b", 30.0, 250.0, 1500.0, min_deg=0.0, max_deg=360.0)}
    with pytest.raises(PlanningError, match=r"B = -5\.5000° .* outside \[0, 360\]°") as e:
        check_rotary_limits(abc, np.array([1, 2, 7, 8]), axes)
    assert e.value.pos.line == 7
    check_rotary_limits(abc, np.array([1, 2, 7, 8]), {"a": A_AXIS})  # B not limited: passes


def test_a_move_of_an_axis_the_machine_lacks_is_refused_at_its_line():
    rot = Rotate((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 45.0, 0.0), 10.0, 4)
    with pytest.raises(PlanningError, match="no B axis") as e:
        run_program(program(rot, axes=("b",)), machine(), OFF)
    assert e.value.pos.line == 4


def test_baselines_and_precompensation_refuse_rotary_programs():
    prog = program(line((0, 0, 0), (10, 0, 0), 20.0, 1, 0.0, 30.0))
    with pytest.raises(ConfigError, match="X Y Z only; this program moves A"):
        run_program(prog, machine(), RunOptions(algorithm="adaptive"))
    with pytest.raises(ConfigError, match="X Y Z servos only; this program uses A "):
        run_program(prog, machine(), RunOptions(precompensate=True))
    held = program(line((0, 0, 0), (10, 0, 0), 20.0, 1, 30.0, 30.0), abc=(30.0, 0.0, 0.0))
    with pytest.raises(ConfigError, match="X Y Z servos only; this program uses A "):
        run_program(held, machine(), RunOptions(precompensate=True))


def test_lower_bound_counts_rotary_moves_and_stays_below_the_plan():
    m = machine()
    prog = mixed_program()
    run = run_program(prog, m, OFF)
    bound = program_lower_bound_s(prog.segments, m)
    assert bound <= run.cycle_time_s
    # The rotary-only move alone (90° at 30 deg/s: at least 3 s) is in it.
    assert bound > 3.0


# -- sampling: windows, Taylor, the settle after a rapid --------------------------------------
def test_windows_and_taylor_give_the_whole_samples_a_b_c():
    from nurbscnc.interpolate.sample import sample_chunks, sample_plan

    m = machine()
    run = run_program(mixed_program(), m, OFF)
    pieces, profile = run.plan.pieces, run.plan.profile
    whole = sample_plan(pieces, profile, m.servo.period_s)
    parts = list(sample_chunks(pieces, profile, m.servo.period_s, chunk=997))
    np.testing.assert_array_equal(np.concatenate([p.abc_deg for p in parts]), whole.abc_deg)
    assert all(p.rotary_axes == ("a",) for p in parts)
    taylor = sample_plan(pieces, profile, m.servo.period_s, interpolator="taylor")
    np.testing.assert_array_equal(taylor.abc_deg, whole.abc_deg)


def test_a_rotary_move_after_a_rapid_waits_for_the_settle_then_turns_in_full():
    """G0, then A turns, then G1: with the contour check on, the planner settles after the
    rapid; A turns for its whole planned time inside that stop and has arrived before X Y Z
    move again."""
    m = machine()
    rot = Rotate((10.0, 0.0, 0.0), (0.0, 0.0, 0.0), (45.0, 0.0, 0.0), 20.0, 2)
    prog = program(
        line((0, 0, 0), (10, 0, 0), 0.0, 1, rapid=True),
        rot,
        line((10, 0, 0), (10, 5, 0), 10.0, 3, 45.0, 45.0),
    )
    run = run_program(prog, m)
    s = run.samples
    T = m.servo.period_s
    turn = rest_to_rest_s(45.0, 20.0, A_AXIS.a_max_deg_s2, A_AXIS.j_max_deg_s3)
    assert run.plan.pieces.rotary.holds.duration_s[0] == pytest.approx(turn, rel=1e-9)
    a = s.abc_deg[:, 0]
    moving = assert_span(a, turn, T)
    # X Y Z rest while A turns; Y moves only once A is at 45°.
    held = s.points_mm[moving[0] + 1 : moving[-1] + 1]  # A between its start and its end
    assert np.all(held == held[0]) and held[0] == pytest.approx([10.0, 0.0, 0.0], abs=1e-12)
    assert np.all(a[s.points_mm[:, 1] > 0.0] == 45.0)
    assert_axis_within(a, T, 60.0, 400.0, 4000.0)


def test_a_program_at_rest_keeps_its_rotary_axes_where_they_start():
    prog = program(Dwell(0.01, (0.0, 0.0, 0.0), 1), abc=(30.0, 0.0, 0.0))
    run = run_program(prog, machine())
    assert run.samples.rotary_axes == ("a",)
    assert np.all(run.samples.abc_deg == [30.0, 0.0, 0.0])
    assert run.samples.abc_deg.shape == (11, 3)


def test_a_rotary_move_before_the_first_cut_turns_first():
    m = machine()
    prog = program(
        Rotate((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (-60.0, 0.0, 0.0), 40.0, 1),
        Dwell(0.05, (0.0, 0.0, 0.0), 2),
        line((0, 0, 0), (5, 0, 0), 10.0, 3, -60.0, -60.0),
    )
    run = run_program(prog, m, OFF)
    turn = rest_to_rest_s(60.0, 40.0, A_AXIS.a_max_deg_s2, A_AXIS.j_max_deg_s3)
    cut = rest_to_rest_s(5.0, 10.0, m.limits.a_max_mm_s2, m.limits.j_max_mm_s3)
    assert run.cycle_time_s == pytest.approx(turn + 0.05 + cut, rel=1e-9)
    s = run.samples
    moving = assert_span(s.abc_deg[:, 0], turn, m.servo.period_s)
    assert moving[0] == 0  # from the first period
    assert np.all(s.abc_deg[s.points_mm[:, 0] > 0.0, 0] == -60.0)
    # X waits for the turn and the dwell after it: its first sample off 0 within a period.
    first_x = int(np.flatnonzero(s.points_mm[:, 0] > 0.0)[0]) * m.servo.period_s
    assert turn + 0.05 < first_x <= turn + 0.05 + m.servo.period_s + 1e-12


def test_rotary_time_counts_against_max_points_before_work():
    m = machine(**{"limits.max_points": 5000})
    prog = program(
        line((0, 0, 0), (1, 0, 0), 10.0, 1),
        Rotate((1.0, 0.0, 0.0), (0.0, 0.0, 0.0), (90.0, 0.0, 0.0), 10.0, 2),  # ≥ 9 s
    )
    with pytest.raises(PlanningError, match="limits.max_points = 5000") as e:
        check_before_work(prog.segments, m)
    assert e.value.pos.line == 2


def test_the_corner_log_names_the_rotary_reasons():
    m = machine()
    prog = mixed_program()
    run = run_program(prog, m, OFF)
    corners = explain_plan(prog, m, run.plan).corner_dicts()
    assert [(c["line"], c["why"]) for c in corners] == [
        (1, "a_rate"),  # 3 deg/mm → 0
        (2, "rotate"),  # the rotary-only move (and the dwell) after line 2
        (5, "a_rate"),  # −2 deg/mm → 90/(5π) deg/mm on the arc
    ]
    assert all(c["action"] == "stop" for c in corners)


def test_lower_bound_counts_the_a_feed_cap():
    """30 deg/mm at A's 60 deg/s caps X at 2 mm/s: 10 mm take at least 5 s."""
    m = machine()
    prog = program(line((0, 0, 0), (10, 0, 0), 20.0, 1, 0.0, 300.0))
    bound = program_lower_bound_s(prog.segments, m)
    assert 5.0 <= bound <= run_program(prog, m, OFF).cycle_time_s


@pytest.mark.parametrize("options", [OFF, RunOptions()], ids=["check-off", "check-on"])
@settings(max_examples=20, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.sampled_from(["line", "line", "rotate", "dwell", "rapid"]),
            st.tuples(*(st.floats(-20.0, 20.0),) * 3),
            st.tuples(st.floats(-200.0, 200.0), st.floats(-100.0, 100.0)),
            st.floats(1.0, 60.0),
            st.booleans(),
        ),
        min_size=1,
        max_size=10,
    )
)
def test_random_rotary_programs_keep_every_rotary_axis_within_its_limits(options, moves):
    """Random mixes of moves (G64) with A and B moving or held, rapids, rotary-only moves and
    dwells, with the contour check off and on: A and B within their limits on the samples
    (finite differences), every programmed end reached, the plan no faster than the lower
    bound."""
    m = machine(A_AXIS, B_AXIS)
    segs, p, ab, n = [], (0.0, 0.0, 0.0), (0.0, 0.0), 0
    for kind, q, ab1, f, held in moves:
        n += 1
        ab1 = ab if held else ab1
        if kind == "dwell":
            segs.append(Dwell(0.01, p, n))
            continue
        rapid = kind == "rapid"
        if kind == "rotate" or math.dist(p, q) < 1e-3:
            segs.append(Rotate(p, (*ab, 0.0), (*ab1, 0.0), 0.0 if rapid else f * 2.0, n, rapid))
        else:
            abc = (*ab, 0.0, *ab1, 0.0)
            segs.append(Line(p, q, f, n, rapid, blend_mm=math.inf, abc_deg=abc))
            p = q
        ab = ab1
    prog = program(*segs, axes=("a", "b"))
    run = run_program(prog, m, options)
    s = run.samples
    T = m.servo.period_s
    for i, ax in enumerate((A_AXIS, B_AXIS)):
        x = s.abc_deg[:, i]
        assert_axis_within(x, T, ax.v_max_deg_s, ax.a_max_deg_s2, ax.j_max_deg_s3, rel=1e-5)
    assert s.abc_deg[-1, :2] == pytest.approx(ab, abs=1e-6)
    assert s.points_mm[-1] == pytest.approx(p, abs=1e-6)
    assert program_lower_bound_s(prog.segments, m) <= run.cycle_time_s * (1.0 + 1e-9)


def test_rotary_moves_before_any_cut_start_from_the_program_start():
    """Rotary-only moves before the first cut (held on the zero-length marker row): at t = 0
    A B C are where the first move starts them, not where the cut starts (found by the
    random programs above: B jumped to 73° at the first sample)."""
    m = machine(A_AXIS, B_AXIS)
    prog = program(
        Rotate((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (55.0, 0.0, 0.0), 4.0, 1),
        Rotate((0.0, 0.0, 0.0), (55.0, 0.0, 0.0), (0.0, 0.0, 0.0), 2.0, 2),
        Rotate((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 73.0, 0.0), 2.0, 3),
        Line((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 1.0, 4, abc_deg=(0.0, 73.0, 0.0, 0.0, 0.0, 0.0)),
        axes=("a", "b"),
    )
    s = run_program(prog, m, OFF).samples
    assert np.all(s.abc_deg[0] == 0.0)
    for i, ax in enumerate((A_AXIS, B_AXIS)):
        assert_axis_within(
            s.abc_deg[:, i], m.servo.period_s, ax.v_max_deg_s, ax.a_max_deg_s2, ax.j_max_deg_s3
        )


def test_rotary_moves_of_no_time_before_the_first_cut_leave_its_a_alone():
    """Rotary-only moves that go nowhere before the first cut take no time and have no row of
    their own: the cut's A still runs 0 → 1° (it ended at 0°, the moves taken for holds
    after it)."""
    z = (0.0, 0.0, 0.0)
    prog = program(
        *(Rotate(z, z, z, 2.0, i + 1) for i in range(3)),
        Line(z, (0.0, 0.0, 1.0), 1.0, 4, abc_deg=(0.0, 0.0, 0.0, 1.0, 0.0, 0.0)),
    )
    run = run_program(prog, machine(), OFF)
    assert run.samples.abc_deg[-1] == pytest.approx([1.0, 0.0, 0.0], abs=1e-12)
    assert run.plan.pieces.rotary.hold_row.size == 0


def test_the_check_of_a_cut_window_joins_its_end_row_with_a_b_c():
    """The dynamics check samples a cut window with a virtual end row at rest: it carries
    A B C too (a join of a column with None raised ValueError)."""
    z = (0.0, 0.0, 0.0)
    prog = program(
        Rotate(z, z, (10.0, 0.0, 0.0), 2.0, 1),
        Line(z, (0.0, 0.0, 1.0), 1.0, 2, abc_deg=(10.0, 0.0, 0.0, 10.0, 0.0, 0.0)),
        Line((0.0, 0.0, 1.0), z, 0.0, 3, rapid=True, abc_deg=(10.0, 0.0, 0.0, 10.0, 0.0, 0.0)),
    )
    run = run_program(prog, machine())  # the contour check on, cut at the rapid
    assert run.samples.abc_deg[-1] == pytest.approx([10.0, 0.0, 0.0], abs=1e-12)
    assert run.samples.points_mm[-1] == pytest.approx(z, abs=1e-12)


def test_plan_text_says_what_the_contour_check_covers():
    import io

    from rich.console import Console

    from nurbscnc.app.summary import summary_of
    from nurbscnc.cli.plan import print_plan_summary

    m = machine()
    prog = mixed_program()
    summary = summary_of(prog, m, run_program(prog, m))
    assert summary["rotary"]["axes"] == ["a"] and summary["rotary"]["rotate_moves"] == 1
    turn = rest_to_rest_s(90.0, 30.0, A_AXIS.a_max_deg_s2, A_AXIS.j_max_deg_s3)
    assert summary["rotary"]["rotate_time_s"] == pytest.approx(turn, rel=1e-9)
    buf = io.StringIO()
    print_plan_summary(prog, m, summary, Console(file=buf, width=400))
    text = buf.getvalue()
    assert "rotary axes A (end at A190°): 1 rotary-only move, " in text
    assert "the contour check covers X Y Z only" in text


def test_explain_names_an_xyz_axis_on_a_line():
    """X at 600 mm/min under F1200 along X: the X axis sets the line's feed (10 mm/s)."""
    m = load_machine(
        overrides={
            "axis_limits.x.v_max_mm_min": 600.0,
            "axis_limits.x.a_max_mm_s2": 1000.0,
            "axis_limits.x.j_max_mm_s3": 2e4,
        }
    )
    prog = program(line((0, 0, 0), (30, 0, 0), 20.0, 1), axes=())
    run = run_program(prog, m, OFF)
    entry = explain_plan(prog, m, run.plan).line_dicts()[0]
    assert entry["limit"] == "axis" and entry["axis"] == "x"


def test_a_full_circle_with_a_moves_a_in_step_with_the_angle():
    """G2 full circle (R 5) with A 0 → 360°: A is linear in the arc length, so A = the
    angle turned (in degrees) on every sample, however the arc is cut into pieces."""
    m = machine()
    start, centre = np.array([5.0, 0.0, 0.0]), np.zeros(3)
    arc = Arc(
        start,
        start.copy(),
        centre,
        np.array([0.0, 0.0, 1.0]),
        -2.0 * math.pi,
        0.0,
        5.0,
        5.0,
        10.0,
        1,
        abc_deg=(0.0, 0.0, 0.0, 360.0, 0.0, 0.0),
    )
    s = run_program(program(arc), m, OFF).samples
    turned = -np.unwrap(np.arctan2(s.points_mm[:, 1], s.points_mm[:, 0]))
    assert s.abc_deg[:, 0] == pytest.approx(np.degrees(turned), abs=1e-6)
    assert s.abc_deg[-1, 0] == pytest.approx(360.0, abs=1e-9)


# -- G-code end to end (the interpreter's A words, the benchmark's 4-axis profile) ------------
BENCH = __import__("pathlib").Path(__file__).resolve().parents[1] / "bench" / "programs"


@pytest.mark.parametrize("name", ["wrapped_engraving_g94.ngc", "wrapped_engraving_g93.ngc"])
def test_wrapped_engravings_from_g_code_keep_a_within_its_limits(name):
    """The benchmark's 4-axis engravings (G94 and G93) on LinuxCNC's sim profile with A
    (30 deg/s, 400 deg/s²): A within them on the samples, every G93 line no faster than its
    inverse time, A back at 360° at the end."""
    from nurbscnc.app.planning import make_plan

    path = BENCH / "rotary" / name
    prog, mach, run = make_plan(str(path), machine=str(BENCH / "linuxcnc_sim_a.toml"))
    ax = mach.rotary_axes["a"]
    s = run.samples
    assert s.rotary_axes == ("a",)
    assert_axis_within(s.abc_deg[:, 0], mach.servo.period_s, ax.v_max_deg_s, ax.a_max_deg_s2, 1e9)
    assert s.abc_deg[-1, 0] == pytest.approx(360.0, abs=1e-9)
    if "g93" in name:
        text = path.read_text().splitlines()
        expl = explain_plan(prog, mach, run.plan)
        checked = 0
        for i, line in enumerate(expl.line.tolist()):
            words = text[line - 1].upper().split()
            f = [float(w[1:]) for w in words if w.startswith("F")]
            if f and "G1" in words:  # a rotary-only move's time is its wait (the hold)
                assert expl.time_s[i] + expl.wait_s[i] >= 60.0 / f[0] * (1.0 - 1e-9)
                checked += 1
        assert checked > 200


def test_explain_counts_a_dwell_on_a_rotary_line_as_a_dwell():
    """``G1 X5`` / ``G4 P2 G1 A10 F600`` / ``G1 X10``: line 2 holds a 2 s dwell and a
    rotary-only move; the move's planned time alone is "rotary-only move", the 2 s "dwell"
    (matched by segment, not by source line)."""
    from nurbscnc.plan.explain import Limit

    m = machine()
    prog = program(
        line((0, 0, 0), (5, 0, 0), 10.0, 1),
        Dwell(2.0, (5.0, 0.0, 0.0), 2),
        Rotate((5.0, 0.0, 0.0), (0.0, 0.0, 0.0), (10.0, 0.0, 0.0), 10.0, 2),
        line((5, 0, 0), (10, 0, 0), 10.0, 3, 10.0, 10.0),
    )
    run = run_program(prog, m, OFF)
    expl = explain_plan(prog, m, run.plan)
    i = expl.line.tolist().index(2)
    # The move: 10° at 10 deg/s under A's 400 deg/s², 4000 deg/s³ (rest to rest).
    move_s = rest_to_rest_s(10.0, 10.0, A_AXIS.a_max_deg_s2, A_AXIS.j_max_deg_s3)
    assert expl.limit_time_s[i, Limit.ROTATE] == pytest.approx(move_s, rel=1e-9)
    assert expl.limit_time_s[i, Limit.DWELL] == pytest.approx(2.0, rel=1e-12)


def test_the_samples_name_the_programs_rotary_axes():
    """The planner takes the program's ``rotary_axes`` (here A and C, C standing at 0 in
    these segments) instead of reading them off the segments again: the samples name both."""
    m = machine(A_AXIS, RotaryAxis("c", 60.0, 400.0, 4000.0))
    prog = program(line((0, 0, 0), (10, 0, 0), 20.0, 1, 0.0, 30.0), axes=("a", "c"))
    run = run_program(prog, m, OFF)
    assert run.plan.pieces.rotary.axes == ("a", "c")
    assert run.samples.rotary_axes == ("a", "c")
