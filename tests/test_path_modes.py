"""Path-control modes with LinuxCNC 2.9's meaning (issue 13): G61, G61.1, G64, G64 P, G64 Q.

References: the LinuxCNC 2.9 g-code documentation (G61 stops at breaks but not at co-linear
joints, G61.1 at every block end, G64 blends, Q defaults to P); exact point-to-segment
distances and scipy's BSpline for the programmed path (tests/test_wholeprograms.py helpers,
not the blender's own numbers); finite differences of the reference samples; closed forms of
the small-break rule (2v sin(θ/2) against the velocity jump allowed in one servo period).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from nurbscnc.geometry.blend import sub_ph
from nurbscnc.geometry.path import Kind
from nurbscnc.geometry.ph import PHQuintic
from nurbscnc.geometry.segments import BLEND_EXACT_STOP, Line
from nurbscnc.machine.profile import load_machine
from nurbscnc.pipeline import RunOptions, run_program
from nurbscnc.plan.corners import CornerAction, CornerWhy
from nurbscnc.plan.junctions import junction_caps, pass_velocity_jump_mm_s
from nurbscnc.plan.naive import merge_collinear
from nurbscnc.plan.options import LookaheadOptions, PlanOptions
from nurbscnc.plan.program_pieces import segment_pieces
from nurbscnc.program.interpret import interpret_text
from tests.test_wholeprograms import distance_to_path, programmed_path, vertex_deviation

MACHINE = load_machine()
LIM = MACHINE.limits
PERIOD = MACHINE.servo.period_s
PROGRAMS = Path(__file__).resolve().parent / "programs" / "planner"
OFF = LookaheadOptions(dynamics="off")


def run(text: str, lookahead: LookaheadOptions = OFF):
    prog = interpret_text(text)
    return prog, run_program(prog, MACHINE, RunOptions(lookahead=lookahead))


def pentagram(mode: str, feed: int = 3500) -> str:
    text = (PROGRAMS / "modes_pentagram_g61.ngc").read_text().replace("G61", mode)
    return text.replace("F3500", f"F{feed}")


#: The speed cap [mm/s] at a tangent line–arc joint of R 10 mm (the curvature jumps by 0.1 /mm):
#: v²Δκ·3/(4T) ≤ J_max, the acceleration step's jerk on the samples (machine/caps.py).
JUMP_CAP_R10_MM_S = math.sqrt(4.0 * 5e4 * 1e-3 / (3.0 * 0.1))  # 25.82 mm/s


# --- the interpreter: what each mode puts on the segments -------------------------------------


@pytest.mark.parametrize(
    ("words", "blend", "naive"),
    [
        ("", np.inf, 0.0),  # LinuxCNC's default mode: G64 without P
        ("G61", 0.0, 0.0),
        ("G61.1", BLEND_EXACT_STOP, 0.0),
        ("G64", np.inf, 0.0),
        ("G64 P0", np.inf, 0.0),
        ("G64 P0.02", 0.02, 0.02),  # Q defaults to P
        ("G64 P0.02 Q0", 0.02, 0.0),  # Q0 turns the naive CAM detector off
        ("G64 P0.02 Q0.1", 0.02, 0.1),
        ("G20 G64 P0.001 Q0.002", 0.0254, 0.0508),  # inch words in mm
    ],
)
def test_path_mode_words_on_the_segments(words, blend, naive):
    prog = interpret_text(f"{words or 'G21'}\nG1 X1 F600\nX2 Y1\nM2\n")
    lines = [s for s in prog.segments if s.kind == "line"]
    assert len(lines) == 2
    for seg in lines:
        assert seg.blend_mm == pytest.approx(blend, rel=1e-12)
        assert seg.naive_mm == pytest.approx(naive, rel=1e-12)


RS274 = Path("/usr/bin/rs274")


@pytest.mark.skipif(not RS274.exists(), reason="LinuxCNC is not installed (no /usr/bin/rs274)")
def test_path_modes_as_linuxcnc_interprets_them(tmp_path):
    """Each move's path-control values against LinuxCNC's own interpreter (rs274 -g): its
    SET_MOTION_CONTROL_MODE (EXACT_PATH, EXACT_STOP, CONTINUOUS with a tolerance, 0 meaning
    "best speed") and SET_NAIVECAM_TOLERANCE calls in force at each STRAIGHT_FEED."""
    import re
    import subprocess

    words = [
        "G64",
        "G64 P0.02",
        "G64 P0.02 Q0.1",
        "G61",
        "G61.1",
        "G64 P0",
        "G64 Q0.05",
        "G64 P0.3 Q0",
    ]
    text = "G21\n" + "".join(f"{w}\nG1 X{i + 1} F600\n" for i, w in enumerate(words)) + "M2\n"
    program = tmp_path / "modes.ngc"
    program.write_text(text)
    # (in tmp_path: rs274 writes rs274ngc.var into its working folder)
    out = subprocess.run(
        [str(RS274), "-g", str(program)], capture_output=True, text=True, timeout=60, cwd=tmp_path
    ).stdout
    expected, mode, naive = [], None, 0.0
    for line in out.splitlines():
        if m := re.search(r"SET_MOTION_CONTROL_MODE\(CANON_(\w+)(?:, ([\d.]+))?\)", line):
            kind, tol = m.group(1), float(m.group(2) or 0.0)
            mode = {"EXACT_PATH": 0.0, "EXACT_STOP": BLEND_EXACT_STOP}.get(
                kind, tol if tol > 0.0 else np.inf
            )
        elif m := re.search(r"SET_NAIVECAM_TOLERANCE\(([\d.]+)\)", line):
            naive = float(m.group(1))
        elif "STRAIGHT_FEED" in line:
            # LinuxCNC links moves only in continuous mode (emccanon.cc, linkable), whatever
            # naive CAM tolerance G61 / G61.1 leave set: nurbscnc records 0 there.
            expected.append((mode, naive if mode not in (0.0, BLEND_EXACT_STOP) else 0.0))
    lines = [s for s in interpret_text(text).segments if s.kind == "line"]
    assert len(lines) == len(words) == len(expected)
    for seg, (blend, q) in zip(lines, expected):
        assert seg.blend_mm == pytest.approx(blend, rel=1e-9)
        assert seg.naive_mm == pytest.approx(q, rel=1e-9)


def test_negative_q_is_a_clear_error():
    from nurbscnc.errors import NurbsCncError

    with pytest.raises(NurbsCncError, match="Q tolerance must be >= 0"):
        interpret_text("G64 P0.01 Q-1\nG1 X1 F600\nM2\n")


# --- the corner log ----------------------------------------------------------------------------


def _log(text: str, options: PlanOptions | None = None):
    prog = interpret_text(text)
    return segment_pieces(prog.segments, MACHINE, options).corners


@pytest.mark.parametrize("feed", [3500, 600])
def test_corner_log_of_the_pentagram_in_each_mode(feed):
    """Four corners (the fifth vertex is the program end) and the rapid's end, per mode. At
    F3500 the blends within 15 or 20 µm of the 144° tips are so tight (3.5 mm/s) that
    stopping is faster; at F600 blending is."""
    rapid_end = (CornerAction.STOP, CornerWhy.RAPID_FEED)
    blend = (
        (CornerAction.BLEND, CornerWhy.BLENDED)
        if feed == 600
        else (CornerAction.STOP, CornerWhy.STOP_FASTER)
    )
    expect = {
        "G61": (CornerAction.STOP, CornerWhy.EXACT_PATH),
        "G61.1": (CornerAction.STOP, CornerWhy.EXACT_STOP),
        "G64 P0": blend,  # LinuxCNC: P0 is G64 alone
        "G64 P0.02": blend,
        "G64": blend,
    }
    for mode, (action, why) in expect.items():
        log = _log(pentagram(mode, feed))
        assert len(log) == 5, mode
        assert (log.action[0], log.why[0]) == rapid_end
        assert np.all(log.action[1:] == action) and np.all(log.why[1:] == why), mode
        # The star's tips turn by 144° (exterior angle of the {5/2} star polygon).
        # (vertices written to 6 decimals: the angles agree to ~1e-8 rad)
        np.testing.assert_allclose(log.turning_rad[1:], np.radians(144.0), atol=1e-7)
        assert list(log.line) == [3, 5, 6, 7, 8]  # the move that ends at each corner
    log = _log(pentagram("G64 P0.02"), PlanOptions(blend_tolerance_mm=0.0))
    assert np.all(log.why[1:] == CornerWhy.ZERO_TOLERANCE)


def test_corner_log_names_dwells_and_exact_stops_at_tangent_joints():
    text = "G21 G61.1 G0 X-5 Y0\nG1 X10 F600\nX20\nG64\nG4 P0.5\nG1 X20 Y10\nX30 Y10\nM2\n"
    log = _log(text)
    whys = [CornerWhy(w) for w in log.why]
    # rapid end; the co-linear G61.1 joint at X10 stops; the dwell; the G64 90° corner blends
    assert whys == [
        CornerWhy.RAPID_FEED,
        CornerWhy.EXACT_STOP,
        CornerWhy.DWELL_OR_PAUSE,
        CornerWhy.BLENDED,
    ]
    np.testing.assert_allclose(log.turning_rad[1], 0.0, atol=1e-15)


# --- blended output stays within the tolerance (independent distances) -------------------------


@pytest.mark.parametrize("mode", ["G64 P0.02", "G64"])
def test_blended_pentagram_within_the_tolerance(mode):
    prog, r = run(pentagram(mode, 600))  # at F3500 stopping is faster than these blends
    tol = 0.02 if "P" in mode else LIM.path_tolerance_mm
    smp = r.samples.points_mm
    d = distance_to_path(smp, programmed_path(prog), reach=1.0)
    assert d.max() <= tol
    tips = np.array([s.end_mm for s in prog.segments if s.kind == "line"][:-1], float)
    dev = vertex_deviation(smp, tips)
    # Each tip is cut by the blend (most of the tolerance used), never by more than it: the
    # polyline through the samples may cut inside the blend by a chord's sagitta κh²/8.
    pieces = r.plan.pieces
    kappa = pieces.kappa_max_per_mm[pieces.kind == 3].max()
    h = np.linalg.norm(np.diff(smp, axis=0), axis=1).max()
    assert np.all(dev <= tol + kappa * h * h / 8) and np.all(dev >= 0.9 * tol)


def test_line_nurbs_line_corners_are_blended_within_the_tolerance():
    """A 90° line→NURBS and a 90° NURBS→line joint (never blended before issue 13)."""
    text = (
        "G21 G90 G17 G64 P0.01\nG0 X10 Y-10\nG1 X10 Y0 F1200\n"
        "G5.2 X15 Y0 P1 L3\nX15 Y5 P1\nX15 Y10 P1\nG5.3\nG1 X5 Y10\nM2\n"
    )
    prog, r = run(text)
    log = r.plan.pieces.corners
    blends = log.action == CornerAction.BLEND
    assert int(blends.sum()) == 2
    np.testing.assert_allclose(log.turning_rad[blends], np.pi / 2, rtol=1e-6)
    smp = r.samples.points_mm
    d = distance_to_path(smp, programmed_path(prog), reach=1.0)
    assert d.max() <= 0.01 + 1e-6  # + the dense polyline's sagitta bound of the NURBS
    dev = vertex_deviation(smp, np.array([[10.0, 0.0, 0.0], [15.0, 10.0, 0.0]]))
    pieces = r.plan.pieces
    kappa = pieces.kappa_max_per_mm[pieces.kind == 3].max()
    h = np.linalg.norm(np.diff(smp, axis=0), axis=1).max()
    assert np.all(dev <= 0.01 + kappa * h * h / 8) and np.all(dev > 0.005)  # + a sagitta
    assert r.plan.profile.junction_speeds_mm_s[2:-1].min() > 0.0  # no stop after the rapid
    # The NURBS cells carry their block's G64 P (built with it, nurbs_pieces).
    nurbs = pieces.kind == Kind.NURBS
    assert nurbs.sum() > 10 and np.all(pieces.blend_mm[nurbs] == 0.01)


def test_sub_ph_is_the_same_curve():
    """sub_ph(ph, a, b)(t) = ph(a + (b − a)t), its length the arc length between a and b."""
    ph = PHQuintic(np.array([1.0 + 0.2j, 0.7 - 0.4j, 0.3 + 1.1j]), 2.0 - 1.0j)
    a, b = 0.23, 0.81
    sub = sub_ph(ph, a, b)
    t = np.linspace(0.0, 1.0, 101)
    np.testing.assert_allclose(sub.point(t), ph.point(a + (b - a) * t), atol=1e-13)
    s = ph.arc_length(np.array([a, b]))
    assert sub.length_mm == pytest.approx(s[1] - s[0], rel=1e-13)


# --- G61.1 stops at every block end -------------------------------------------------------------


def test_g61_1_stops_at_every_block_end_g61_at_breaks_only():
    """Co-linear and tangent line–arc joints: G61.1 stops at each (samples at rest there),
    G61 passes them at speed (LinuxCNC: exact path stops only where the path breaks)."""
    body = "G0 X0 Y0\nG1 X10 F1800\nX20\nG3 X30 Y10 I0 J10\nG1 Y20\nM2\n"
    ends = np.array([[10.0, 0, 0], [20.0, 0, 0], [30.0, 10, 0]])
    speeds = {}
    for mode in ("G61.1", "G61"):
        prog, r = run(f"G21 G17 {mode}\n{body}")
        p = r.samples.points_mm
        v = np.linalg.norm(np.diff(p, axis=0), axis=1) / PERIOD
        near = [int(np.argmin(np.linalg.norm(p - e, axis=1))) for e in ends]
        # The speed over the servo steps on either side of the sample nearest each end.
        speeds[mode] = np.array([max(v[i - 1], v[min(i, v.size - 1)]) for i in near])
        log = r.plan.pieces.corners
        feed = log.why != CornerWhy.RAPID_FEED
        if mode == "G61.1":
            assert np.all(log.why[feed] == CornerWhy.EXACT_STOP) and feed.sum() == 3
        else:
            assert feed.sum() == 0  # no corner at all: the joints are tangent
    # At rest: a step of the S-curve stop around a vertex moves ≤ J T³/6-ish; 0.05 mm/s bounds.
    assert np.all(speeds["G61.1"] <= 0.05)
    # G61 keeps the feed at the co-linear joint, and slows to the curvature jump's cap at the
    # line–arc joints (R 10 mm).
    assert np.all(speeds["G61"] >= 0.9 * np.array([30.0, JUMP_CAP_R10_MM_S, JUMP_CAP_R10_MM_S]))


# --- small breaks pass at speed ------------------------------------------------------------------


def _cam_polyline(breaks_rad: float, n: int = 200, step_mm: float = 0.5, mode: str = "G64"):
    """A CAM polyline turning by ``breaks_rad`` at each of its n − 1 vertices."""
    heading = np.arange(n) * breaks_rad
    pts = np.cumsum(np.column_stack([np.cos(heading), np.sin(heading)]) * step_mm, axis=0)
    lines = [f"G21 G90 {mode}", "G0 X0 Y0", "F3500"]
    lines += [f"G1 X{x:.12f} Y{y:.12f}" for x, y in pts]
    return "\n".join(lines + ["M2"]) + "\n"


@pytest.mark.parametrize("mode", ["G64", "G61"])
def test_cam_breaks_of_1e_5_rad_pass_at_full_speed(mode):
    # The corner rule itself, so the moves as written: under G64 the default smoothing
    # would fit this dense polyline as one spline, leaving no corner to pass.
    as_written = LookaheadOptions(dynamics="off", plan=PlanOptions(smooth=False))
    prog, r = run(_cam_polyline(1e-5, mode=mode), as_written)
    log = r.plan.pieces.corners
    feed = log.why != CornerWhy.RAPID_FEED
    assert feed.sum() == 199 and np.all(log.action[feed] == CornerAction.PASS)
    assert np.all(log.why[feed] == CornerWhy.SMALL_BREAK)
    assert r.plan.pieces.kind_counts().get("ph", 0) == 0  # no blend needed
    # The points stay on the polyline exactly (no blend cuts anything).
    d = distance_to_path(r.samples.points_mm, programmed_path(prog))
    assert d.max() <= 1e-9
    # As fast as one straight move of the same length (the jerk-limited S-curve of 100 mm).
    _, straight = run("G21 G90 G0 X0 Y0\nF3500\nG1 X100\nM2\n")
    assert r.cycle_time_s == pytest.approx(straight.cycle_time_s, abs=2 * PERIOD)


def test_small_break_rule_at_its_threshold():
    """2v sin(θ/2) ≤ min(A T, J T², 4δ/T): the break just under θ* passes, just over stops
    (G61, long lines: no crowding factor)."""
    dv = min(
        LIM.a_max_mm_s2 * PERIOD, LIM.j_max_mm_s3 * PERIOD**2, 4 * LIM.chord_tolerance_mm / PERIOD
    )
    assert pass_velocity_jump_mm_s(MACHINE) == pytest.approx(dv, rel=1e-15)
    v = LIM.v_max_mm_s
    theta = 2 * np.arcsin(dv / (2 * v))
    for factor, action in ((0.999, CornerAction.PASS), (1.001, CornerAction.STOP)):
        a = Line((0.0, 0.0, 0.0), (10.0, 0.0, 0.0), v, 1)
        t = factor * theta
        b = Line(a.end_mm, (10.0 + 10 * np.cos(t), 10 * np.sin(t), 0.0), v, 2)
        pieces = segment_pieces([a, b], MACHINE)
        assert list(pieces.corners.action) == [action]
        caps = junction_caps(pieces)
        assert (caps[1] > 0) == (action == CornerAction.PASS)


def test_dense_polyline_breaks_add_up_within_a_servo_step():
    """Breaks each under the threshold, on 1 µm moves (50 per servo step at 50 mm/s): their
    jumps add up, so they are not passed at speed (blended under G64 instead)."""
    theta = 0.5 * pass_velocity_jump_mm_s(MACHINE) / (2 * 50.0)
    log = _log(_cam_polyline(theta, n=100, step_mm=0.001).replace("F3500", "F3000"))
    feed = log.why != CornerWhy.RAPID_FEED
    assert not np.any(log.action[feed] == CornerAction.PASS)


# --- G64 Q: the naive CAM detector ---------------------------------------------------------------


def test_g64_q_merges_within_q_of_every_original_vertex():
    rng = np.random.default_rng(13)
    q = 0.01
    x = np.linspace(0.0, 50.0, 501)[1:]
    y = np.where(x < 25.0, 0.0, x - 25.0) + rng.uniform(-0.4 * q, 0.4 * q, x.size)
    text = (
        f"G21 G90 G64 P0.005 Q{q}\nG0 X0 Y0\nF1200\n"
        + "".join(f"G1 X{a:.6f} Y{b:.6f}\n" for a, b in zip(x, y))
        + "M2\n"
    )
    prog = interpret_text(text)
    merged, source = merge_collinear(prog.segments)
    lines = [s for s in merged if s.kind == "line"]
    assert len(lines) < 20  # 500 moves, two straight stretches (≤ 101 moves a line)
    # Every original vertex within Q of the merged polyline (exact point-to-segment).
    starts = np.array([s.start_mm for s in lines], float)
    ends = np.array([s.end_mm for s in lines], float)
    orig = np.array([s.end_mm for s in prog.segments if s.kind == "line"], float)
    d = distance_to_path(orig, (starts, ends, []), reach=1.0)
    assert d.max() <= q
    # The merged path is continuous and ends where the program ends.
    np.testing.assert_array_equal(starts[1:], ends[:-1])
    np.testing.assert_array_equal(ends[-1], orig[-1])
    assert source[-1] == len(prog.segments) - 1
    # Planned as merged: one piece per merged line or blend, samples within P + Q.
    _, r = run(text)
    smp = r.samples.points_mm
    assert distance_to_path(smp, programmed_path(prog), reach=1.0).max() <= 0.005 + q


def test_g64_q_does_not_merge_a_vertex_farther_than_q_or_a_feed_change():
    base = "G21 G90 G64 P0.01 Q0.01\nG0 X0 Y0\n"
    kept = interpret_text(base + "G1 X10 Y0.02 F600\nX20 Y0\nM2\n")
    assert sum(s.kind == "line" for s in merge_collinear(kept.segments)[0]) == 2
    feed = interpret_text(base + "G1 X10 Y0 F600\nX20 Y0 F700\nM2\n")
    assert sum(s.kind == "line" for s in merge_collinear(feed.segments)[0]) == 2
    merged = interpret_text(base + "G1 X10 Y0.005 F600\nX20 Y0\nM2\n")
    assert sum(s.kind == "line" for s in merge_collinear(merged.segments)[0]) == 1


# --- G64 P is no slower than G61 ------------------------------------------------------------------


@pytest.mark.parametrize("feed", [3500, 600])
def test_g64_p_is_never_slower_than_g61_without_the_servo_check(feed):
    """The kinematic plans (dynamics off). Jerk-limited, slowing to a small blend's feed
    (3.5 mm/s at the pentagram's 144° tips at P0.02) takes nearly as long as stopping, and
    the blend is then crossed at that feed: at F3500 the pentagram's corners stop (G64 P0.02
    takes exactly G61's time), at F600 they blend, faster. A square's 90° corners at F3500
    stop at P0.02 (blended, measured: 17.6 ms slower over 3 corners; the estimate says 6.0 ms
    a corner) and blend at P0.2, faster."""
    times = {m: run(pentagram(m, feed))[1].cycle_time_s for m in ("G61", "G64 P0.02")}
    if feed == 3500:
        assert times["G64 P0.02"] == pytest.approx(times["G61"], rel=1e-12)
    else:
        assert times["G64 P0.02"] < times["G61"] - 0.01  # 4 corners
    square = "G21 G90 {}\nG0 X0 Y0\nF3500\nG1 X20\nY20\nX0\nY0\nM2\n"
    t = {m: run(square.format(m))[1].cycle_time_s for m in ("G61", "G64 P0.02", "G64 P0.2")}
    assert t["G64 P0.02"] == pytest.approx(t["G61"], rel=1e-12)  # stops: 6 ms per corner faster
    assert t["G64 P0.2"] < t["G61"] - 0.01


def test_default_mode_blends_like_g64():
    """A program that sets no path mode runs in LinuxCNC's default, G64 without P."""
    _, a = run(pentagram("G64"))
    _, b = run(pentagram(""))
    assert a.cycle_time_s == pytest.approx(b.cycle_time_s, rel=1e-12)
    np.testing.assert_array_equal(a.plan.pieces.corners.action, b.plan.pieces.corners.action)


# --- property: random polylines and arcs, every mode -------------------------------------------


@st.composite
def _random_program(draw):
    """3–8 moves (lines and tangent-or-not arcs) at a random feed, in a random mode."""
    mode = draw(st.sampled_from(["G61", "G61.1", "G64", "G64 P0.005", "G64 P0.05"]))
    feed = draw(st.integers(300, 3500))
    lines = [f"G21 G90 G17 {mode}", "G0 X0 Y0", f"F{feed}"]
    x = y = 0.0
    for _ in range(draw(st.integers(3, 8))):
        dx = draw(st.floats(-20, 20, allow_nan=False)).__round__(3)
        dy = draw(st.floats(-20, 20, allow_nan=False)).__round__(3)
        if abs(dx) + abs(dy) < 0.5:
            continue
        if draw(st.booleans()):
            lines.append(f"G1 X{x + dx:.3f} Y{y + dy:.3f}")
        else:
            r = 0.5 * float(np.hypot(dx, dy)) * draw(st.floats(1.05, 3.0))
            lines.append(f"G{draw(st.sampled_from([2, 3]))} X{x + dx:.3f} Y{y + dy:.3f} R{r:.4f}")
        x, y = x + dx, y + dy
    lines.append(f"G1 X{x + 5:.3f} Y{y:.3f}")
    return mode, "\n".join(lines + ["M2"]) + "\n"


@given(_random_program())
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
def test_random_programs_stay_within_their_tolerance_and_stop_where_logged(case):
    """Every reference point within the mode's tolerance of the programmed path (exact
    distances to lines, dense arcs), 0 for G61 / G61.1; the tool at rest (plan's junction
    speed 0) at every corner logged STOP, and every corner logged once per junction."""
    mode, text = case
    prog, r = run(text)
    tol = {"G61": 0.0, "G61.1": 0.0, "G64": LIM.path_tolerance_mm}.get(mode)
    tol = float(mode.split("P")[1]) if tol is None else tol
    d = distance_to_path(r.samples.points_mm, programmed_path(prog), reach=1.0)
    assert d.max() <= tol + 2e-6  # + the dense arc polylines' sagitta bound (1e-6 mm)
    log = r.plan.pieces.corners
    if mode.startswith("G61"):
        assert not np.any(log.action == CornerAction.BLEND)
    stops = log.point_mm[log.action == CornerAction.STOP]
    junction_points = r.plan.pieces.start_mm.T
    speeds = r.plan.profile.junction_speeds_mm_s[:-1]
    for p in stops:
        at = np.flatnonzero(np.linalg.norm(junction_points - p, axis=1) <= 1e-9)
        assert at.size and np.all(speeds[at] == 0.0)


def test_g64_without_p_uses_the_profiles_path_tolerance():
    """limits.path_tolerance_um (default ε_max) bounds G64's blends: 5 µm here, measured on
    the samples (exact distances to the programmed pentagram; the tips' distance to the
    samples' polyline, which may cut inside the blend by a chord's sagitta)."""
    assert LIM.path_tolerance_mm == LIM.contour_tolerance_mm
    machine = load_machine(overrides={"limits.path_tolerance_um": 5.0})
    assert machine.limits.path_tolerance_mm == pytest.approx(0.005, rel=1e-15)
    prog = interpret_text(pentagram("G64", 300))  # slow enough that blending is faster
    r = run_program(prog, machine, RunOptions(lookahead=OFF))
    smp = r.samples.points_mm
    assert distance_to_path(smp, programmed_path(prog), reach=1.0).max() <= 0.005
    tips = np.array([s.end_mm for s in prog.segments if s.kind == "line"][:-1], float)
    dev = vertex_deviation(smp, tips)  # the corner deviation: the tip's distance to the path
    pieces = r.plan.pieces
    kappa = pieces.kappa_max_per_mm[pieces.kind == 3].max()
    h = np.linalg.norm(np.diff(smp, axis=0), axis=1).max()
    assert np.all(dev >= 0.0045) and np.all(dev <= 0.005 + kappa * h * h / 8)


def test_trimmed_ph_and_nurbs_pieces_are_the_same_curve():
    """A blend trims PH and NURBS pieces too: the trimmed piece's points at arc length t are
    the original's at s0 + t (PH: its own arc-length inversion; NURBS: the same curve)."""
    from nurbscnc.geometry.nurbs import NurbsCurve
    from nurbscnc.plan.blend_rows import trimmed_piece
    from nurbscnc.plan.pieces import Piece

    ph = PHQuintic(np.array([1.0 + 0.2j, 0.7 - 0.4j, 0.3 + 1.1j]), 2.0 - 1.0j)
    piece = Piece(Kind.PH, ph, float(ph.length_mm), 10.0, 0, 1)
    s0, s1 = 0.1 * ph.length_mm, 0.7 * ph.length_mm
    cut = trimmed_piece(piece, s0, s1)
    assert cut.length_mm == pytest.approx(s1 - s0, rel=1e-9)
    t = np.linspace(0.0, s1 - s0, 9)
    np.testing.assert_allclose(cut.points_mm(t), piece.points_mm(s0 + t), atol=1e-9)
    prog = interpret_text(
        "G21 G17\nG1 X10 Y0 F600\nG5.2 X15 Y0 P1 L3\nX15 Y5 P1\nX15 Y10 P1\nG5.3\nM2\n"
    )
    curve = NurbsCurve.from_segment(prog.segments[1])
    s = curve.arc_length(np.array([curve.u_start, curve.u_end]))
    piece = Piece(
        Kind.NURBS, curve, float(s[1] - s[0]), 10.0, 1, 3, curve.u_start, curve.u_end, 0.0
    )
    cut = trimmed_piece(piece, 0.5, piece.length_mm - 0.25)
    t = np.linspace(0.0, cut.length_mm, 9)
    np.testing.assert_allclose(cut.points_mm(t), piece.points_mm(0.5 + t), atol=1e-9)


def test_stops_and_passes_where_linuxcnc_does():
    """LinuxCNC 2.9's own trajectory planner (simulated, recorded in
    programs/planner/modes_tangent_linuxcnc.json): at the co-linear and tangent joints of one
    program G61 and G64 keep the feed (30 mm/s) and G61.1 stops (≈ one servo step of its
    stop, 1.2 mm/s, at the sample nearest the joint). nurbscnc does the same; and on the
    2000-move CAM polyline with 1e-5 rad breaks under G61 it takes no more than 1 % over
    LinuxCNC's time (which passes the breaks too, without a jerk limit)."""
    import json

    ref = json.loads((PROGRAMS / "modes_tangent_linuxcnc.json").read_text())
    ends = np.array(ref["block_ends_mm"], float)
    body = "G0 X0 Y0\nG1 X10 F1800\nX20\nG3 X30 Y10 I0 J10\nG1 Y20\nM2\n"
    for mode, lcnc in ref["modes"].items():
        _, r = run(f"G21 G17 {mode}\n{body}")
        p = r.samples.points_mm
        v = np.linalg.norm(np.diff(p, axis=0), axis=1) / PERIOD
        near = [int(np.argmin(np.linalg.norm(p - e, axis=1))) for e in ends]
        ours = np.array([max(v[i - 1], v[min(i, v.size - 1)]) for i in near])
        stops = np.array(lcnc["speed_at_block_ends_mm_s"]) < 5.0
        assert np.all((ours < 5.0) == stops), mode
        # LinuxCNC (no jerk limit) keeps 30 mm/s at the tangent line–arc joints; nurbscnc
        # keeps to the curvature jump's cap there (its J_max, machine/caps.py).
        keep = np.array([30.0, JUMP_CAP_R10_MM_S, JUMP_CAP_R10_MM_S])
        assert np.all(ours[~stops] >= 0.99 * keep[~stops])
    t_cam = run((PROGRAMS / "modes_cam_breaks_g61.ngc").read_text())[1].cycle_time_s
    assert t_cam <= 1.01 * ref["other_programs_cycle_s"]["modes_cam_breaks_g61.ngc"]


def test_stop_or_blend_estimate_agrees_with_the_planned_profiles(monkeypatch):
    """The decision's estimate (blend_choice._blend_is_faster: jerk-limited transitions t(Δv),
    crossing the blend at its cap) against the planner's own profiles: the pentagram's and a
    square's corners at F3500, P0.02, blended (forced) and stopped (G61); the difference per
    corner agrees within 1 ms and has the estimate's sign."""
    from nurbscnc.plan import blend_choice as pieces_mod

    a, j = LIM.a_max_mm_s2, LIM.j_max_mm_s3
    # t(Δv) and the reach from rest are inverse to each other: d = v·t(v)/2.
    for v in (1.0, 58.3, 200.0):
        t = float(pieces_mod._speed_change_s(v, a, j))
        assert float(pieces_mod._reach_mm_s(v * t / 2.0, a, j)) == pytest.approx(v, rel=1e-12)
    estimate = {}
    real = pieces_mod._blend_is_faster

    def spy(pieces, c, machine):
        lim = machine.limits
        v = np.minimum(pieces.v_cap_mm_s[c.row - 1], pieces.v_cap_mm_s[c.row])
        w = np.minimum(pieces_mod.curvature_cap_mm_s(machine, c.kappa_per_mm, v), v)
        blend = (
            pieces_mod._speed_change_s(v - w, lim.a_max_mm_s2, lim.j_max_mm_s3) * (v - w) / v
            + c.length_mm / w
            - (c.trim_a_mm + c.trim_b_mm) / v
        )
        estimate["d"] = float(np.mean(blend - pieces_mod._speed_change_s(v, a, j)))
        real(pieces, c, machine)
        return np.ones(c.row.size, dtype=bool)  # force the blends

    square = "G21 G90 {}\nG0 X0 Y0\nF3500\nG1 X20\nY20\nX0\nY0\nM2\n"
    for text, corners in ((pentagram("{}"), 4), (square, 3)):
        stop = run(text.format("G61"))[1].cycle_time_s
        monkeypatch.setattr(pieces_mod, "_blend_is_faster", spy)
        blend = run(text.format("G64 P0.02"))[1].cycle_time_s
        monkeypatch.setattr(pieces_mod, "_blend_is_faster", real)
        measured = (blend - stop) / corners
        assert estimate["d"] > 0.0 and measured > 0.0
        assert measured == pytest.approx(estimate["d"], abs=1e-3)
