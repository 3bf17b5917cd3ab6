"""plan --explain (issue 16): the limit that set the feed, on programs where it is known in
closed form.

References are computed by hand here, independently of the planner: the S-curve closed forms
of SPEC §7 (A not reached: T = 2√(Δv/J), D = (v_a + v_b)·T/2; A reached: T = Δv/A + A/J),
the normal-acceleration feed √(A/κ) = √(A·r) on a circle of radius r, the chord-error feed
V_af = (2/T_s)·√(2δ/κ − δ²) (SPEC eq. 23), and the machine's settle time from its poles.
The default machine: V_max 3500 mm/min, A 2450 mm/s², J 5e4 mm/s³, δ 1 µm, T_s 1 ms.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from nurbscnc.cli.main import main
from nurbscnc.machine.profile import load_machine
from nurbscnc.pipeline import RunOptions, run_program
from nurbscnc.plan.corners import CornerAction, CornerWhy
from nurbscnc.plan.explain import LIMIT_OF_KEY, Limit, explain_plan
from nurbscnc.plan.options import LookaheadOptions
from nurbscnc.program.interpret import interpret_text

A, J = 2450.0, 5.0e4
NO_CHECK = RunOptions(lookahead=LookaheadOptions(dynamics="off"))


def explain(text: str, overrides: dict | None = None, options: RunOptions = NO_CHECK):
    prog = interpret_text(text)
    mach = load_machine(None, overrides)
    run = run_program(prog, mach, options)
    return explain_plan(prog, mach, run.plan), run, mach


def row(expl, line: int) -> int:
    (i,) = np.flatnonzero(expl.line == line)
    return int(i)


def scurve_jerk_only(dv: float) -> tuple[float, float]:
    """(time, distance) of an S-curve from rest by dv without reaching A (dv < A²/J)."""
    assert dv < A * A / J
    t = 2.0 * math.sqrt(dv / J)
    return t, dv * t / 2.0


def test_long_line_below_v_max_is_limited_by_its_feed():
    expl, run, _ = explain("G1 X100 F1200\n")  # 20 mm/s < V_max 58.3 mm/s
    i = row(expl, 1)
    assert Limit(int(expl.limit[i])) == Limit.FEED
    assert expl.feed_mm_s[i] == pytest.approx(20.0, rel=1e-12)
    assert expl.peak_mm_s[i] == pytest.approx(20.0, rel=1e-9)
    t_acc, d_acc = scurve_jerk_only(20.0)  # 0.04 s, 0.4 mm each way
    time = 2.0 * t_acc + (100.0 - 2.0 * d_acc) / 20.0
    assert expl.time_s[i] == pytest.approx(time, rel=1e-9)
    assert expl.mean_mm_s[i] == pytest.approx(100.0 / time, rel=1e-9)
    # The acceleration and deceleration are part of the line's feed-limited time: the
    # whole cycle is accounted for, under one limit.
    assert expl.total_by_limit_s() == pytest.approx({"feed": run.cycle_time_s}, rel=1e-12)


def test_feed_above_v_max_is_limited_by_v_max():
    expl, _, _ = explain("G1 X100 F6000\n")  # 100 mm/s > V_max
    i = row(expl, 1)
    assert Limit(int(expl.limit[i])) == Limit.V_MAX
    assert expl.peak_mm_s[i] == pytest.approx(3500.0 / 60.0, rel=1e-9)
    assert expl.feed_mm_s[i] == pytest.approx(100.0, rel=1e-12)


def test_tight_arc_is_limited_by_normal_acceleration():
    # A full circle of radius 0.5 mm at F3500: √(A r) = 35 mm/s; V_af(κ = 2) = 63.2 mm/s.
    r = 0.5
    expl, _, _ = explain(f"G1 X{r} F3500\nG2 X{r} Y0 I-{r} J0\n")
    v_normal = math.sqrt(A * r)
    v_chord = 2000.0 * math.sqrt(2e-3 * r - 1e-6)
    assert v_normal < min(v_chord, 3500.0 / 60.0)
    i = row(expl, 2)
    assert Limit(int(expl.limit[i])) == Limit.NORMAL
    assert expl.peak_mm_s[i] == pytest.approx(v_normal, rel=1e-9)


def test_arc_with_a_tight_chord_tolerance_is_limited_by_chord_error():
    # δ = 0.1 µm: V_af = 2000 √(2δ r − δ²) ≈ √(800 r) < √(2450 r), r = 2 mm.
    r = 2.0
    expl, _, _ = explain(
        f"G1 X{r} F3500\nG2 X{r} Y0 I-{r} J0\n", {"limits.chord_tolerance_um": 0.1}
    )
    d = 1e-4
    v_chord = 2000.0 * math.sqrt(2.0 * d * r - d * d)
    assert v_chord < math.sqrt(A * r)
    i = row(expl, 2)
    assert Limit(int(expl.limit[i])) == Limit.CHORD
    assert expl.peak_mm_s[i] == pytest.approx(v_chord, rel=1e-9)


def test_short_line_is_limited_by_jerk_when_a_is_never_reached():
    # 1 mm at F3000 (50 mm/s): 2·D(0 → 50) = 3.16 mm > 1 mm. The peak solves 2·D(0 → v) = L
    # with D = v·√(v/J) (A not reached): v = (L/2 · √J)^(2/3).
    expl, _, _ = explain("G1 X1 F3000\n")
    v_p = (0.5 * math.sqrt(J)) ** (2.0 / 3.0)
    assert v_p < A * A / J
    i = row(expl, 1)
    assert Limit(int(expl.limit[i])) == Limit.JERK
    assert expl.peak_mm_s[i] == pytest.approx(v_p, rel=1e-9)
    assert expl.time_s[i] == pytest.approx(4.0 * math.sqrt(v_p / J), rel=1e-9)


def test_short_fast_line_is_limited_by_acceleration_distance():
    # V_max 12000 mm/min, F12000 (200 mm/s), 16 mm: the peak is above A²/J = 120 mm/s, so A is
    # reached: D(0 → v) = v·(v/A + A/J)/2, 2·D = L → v²/A + v·A/J − L = 0.
    length = 16.0
    expl, _, _ = explain(
        f"G1 X{length} F12000\n",
        {"limits.v_max_mm_min": 12000.0, "steps.max_pulses_per_period": 255},
    )
    v_p = A / 2.0 * (-A / J + math.sqrt((A / J) ** 2 + 4.0 * length / A))
    assert A * A / J < v_p < 200.0
    i = row(expl, 1)
    assert Limit(int(expl.limit[i])) == Limit.DISTANCE
    assert expl.peak_mm_s[i] == pytest.approx(v_p, rel=1e-9)


def test_g61_corner_stops_and_a_short_line_between_stops_is_a_corner_stop():
    expl, run, _ = explain("G61\nG1 X10 F3000\nG1 Y1\nG1 X0\n")
    # The 1 mm line between two exact stops never reaches F: the corner stops limit it.
    assert Limit(int(expl.limit[row(expl, 3)])) == Limit.CORNER_STOP
    assert Limit(int(expl.limit[row(expl, 2)])) == Limit.FEED  # 10 mm reach F = 50 mm/s
    assert np.all(run.plan.profile.junction_speeds_mm_s[1:-1] == 0.0)


def test_g61_corner_log_says_exact_path():
    expl, _, _ = explain("G61\nG1 X10 F3000\nG1 Y10\n")
    if not len(expl.corners):
        pytest.skip("the planner does not fill plan.pieces.corners yet (modes helper)")
    (c,) = expl.corner_dicts()
    assert (c["action"], c["why"]) == ("stop", "exact_path")
    assert c["line"] == 2 and c["turning_deg"] == pytest.approx(90.0, abs=1e-9)
    assert c["point_mm"] == pytest.approx([10.0, 0.0, 0.0], abs=1e-12)
    assert expl.corners.action[0] == CornerAction.STOP
    assert expl.corners.why[0] == CornerWhy.EXACT_PATH


def test_g64_p_corner_is_blended_at_the_blend_cap():
    # G64 P0.1 at a 90° corner: a PH blend whose peak curvature (≈ 6.6 /mm) caps it below F.
    expl, run, mach = explain("G64 P0.1\nG1 X10 F3000\nG1 Y10\n")
    pieces = run.plan.pieces
    (ph,) = np.flatnonzero(pieces.kind == 3)  # Kind.PH: the blend
    assert Limit(int(expl.piece_limit[ph])) == Limit.BLEND
    kappa = float(pieces.kappa_max_per_mm[ph])
    d = 1e-3
    cap = min(math.sqrt(A / kappa), 2000.0 * math.sqrt(2.0 * d / kappa - d * d), 50.0)
    assert expl.piece_cap_mm_s[ph] == pytest.approx(cap, rel=1e-9)
    assert expl.piece_peak_mm_s[ph] == pytest.approx(cap, rel=1e-9)
    if len(expl.corners):
        (c,) = expl.corner_dicts()
        assert (c["action"], c["why"]) == ("blend", "blended")


def test_contour_check_lowering_is_reported():
    # A 2 mm radius at 50 mm/s: the radial error ≈ 2.85e-5 s² × V²/r ≈ 36 µm > 15 µm
    # (SPEC §8): the dynamics check must lower it.
    expl, run, _ = explain("G1 X2 F3000\nG2 X2 Y0 I-2 J0\n", options=RunOptions())
    pieces, caps = run.plan.pieces, run.plan.caps_mm_s
    lowered = caps < pieces.v_cap_mm_s * (1 - 1e-6)
    assert lowered.any()
    assert np.all(
        (expl.piece_limit == Limit.CONTOUR)
        | ~lowered
        | np.isin(expl.piece_limit, (Limit.DISTANCE, Limit.JERK, Limit.CORNER_STOP))
    )
    i = row(expl, 2)
    assert Limit(int(expl.limit[i])) == Limit.CONTOUR
    assert expl.peak_mm_s[i] < math.sqrt(A * 2.0)


def test_dwell_and_settle_are_charged_to_their_lines():
    """The settle after a rapid is what the dynamics check asked for (planner v2: 0 when the
    error is already within ε_max): a ringing 20 Hz servo needs one, charged to the rapid."""
    from tests.test_shaping import _slow_servo_machine

    prog = interpret_text("G0 X30\nG1 Y10 F300\nG4 P0.5\nG1 Y20\n")
    mach = _slow_servo_machine()
    run = run_program(prog, mach, RunOptions())
    expl = explain_plan(prog, mach, run.plan)
    settle = float(run.plan.settle_s[run.plan.pieces.line == 1].sum())
    assert settle > 0.0

    i_rapid, i_dwell = row(expl, 1), row(expl, 3)
    assert expl.wait_s[i_rapid] == pytest.approx(settle, rel=1e-12)
    assert expl.limit_time_s[i_rapid, Limit.SETTLE] == pytest.approx(settle)
    assert Limit(int(expl.limit[i_rapid])) == Limit.RAPID
    assert expl.kind[i_dwell] == "dwell" and Limit(int(expl.limit[i_dwell])) == Limit.DWELL
    assert expl.wait_s[i_dwell] == pytest.approx(0.5, rel=1e-12)
    assert expl.time_s[i_dwell] == 0.0 and np.isnan(expl.feed_mm_s[i_dwell])
    assert sum(expl.total_by_limit_s().values()) == pytest.approx(run.cycle_time_s, rel=1e-12)


# -- the command ---------------------------------------------------------------------------
@pytest.fixture()
def corner_program(tmp_path):
    path = tmp_path / "corner.nc"
    path.write_text("G61\nG1 X10 F3000\nG1 Y1\nG1 X0\nG4 P0.25\n")
    return str(path)


def test_plan_explain_json(corner_program):
    res = CliRunner().invoke(
        main, ["plan", corner_program, "--json", "--explain", "--dynamics", "off"]
    )
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    ex = out["explain"]
    assert [e["line"] for e in ex["lines"]] == [2, 3, 4, 5]
    by_line = {e["line"]: e for e in ex["lines"]}
    assert by_line[3]["limit"] == "corner_stop"
    assert by_line[5]["limit"] == "dwell" and by_line[5]["wait_s"] == pytest.approx(0.25)
    assert by_line[5]["feed_programmed_mm_s"] is None
    assert by_line[2]["feed_programmed_mm_s"] == pytest.approx(50.0)
    assert set(ex["limit_time_s"]) <= set(LIMIT_OF_KEY)
    assert sum(ex["limit_time_s"].values()) == pytest.approx(out["cycle_time_s"], rel=1e-9)


def test_plan_explain_text_lists_costliest_first(corner_program):
    res = CliRunner().invoke(main, ["plan", corner_program, "--explain", "--dynamics", "off"])
    assert res.exit_code == 0, res.output
    text = res.stdout
    assert "time by limit:" in text and "stop at a corner" in text
    # Line 2 (10 mm) and line 4 (10 mm) cost the most; the G-code is shown.
    body = text[text.index("costliest") :]
    assert body.index("G1 X10 F3000") < body.index("G1 Y1")


def test_plan_explain_all_is_in_program_order(corner_program):
    res = CliRunner().invoke(main, ["plan", corner_program, "--explain-all", "--dynamics", "off"])
    assert res.exit_code == 0, res.output
    body = res.stdout
    positions = [body.index(code) for code in ("G1 X10 F3000", "G1 Y1", "G1 X0", "G4 P0.25")]
    assert positions == sorted(positions)


def test_plan_explain_refuses_a_baseline(corner_program):
    res = CliRunner().invoke(main, ["plan", corner_program, "--explain", "--algorithm", "adaptive"])
    assert res.exit_code == 2


def test_contour_shaping_reported_by_the_planner_is_used():
    # A planner that shapes transitions (plan.shaped_by_contour) instead of lowering caps:
    # a piece that no longer reaches its cap because of it is limited by the contour check.
    import dataclasses

    from nurbscnc.plan.explain import contour_limited

    expl, run, mach = explain("G1 X1 F3000\n")  # the jerk-limited short line
    plan = run.plan
    shaped = type(
        "ShapedPlan",
        (),
        {
            **{f.name: getattr(plan, f.name) for f in dataclasses.fields(plan)},
            "shaped_by_contour": np.array([True]),
        },
    )()
    lowered, by_shape = contour_limited(shaped, plan.pieces.v_cap_mm_s)
    assert not lowered.any() and by_shape.all()
    prog = interpret_text("G1 X1 F3000\n")
    again = explain_plan(prog, mach, shaped)
    assert Limit(int(again.piece_limit[0])) == Limit.CONTOUR
    assert Limit(int(expl.piece_limit[0])) == Limit.JERK


def test_json_lines_equal_the_one_line_entries():
    expl, _, _ = explain("G0 X10\nG1 X30 F600\nG4 P0.5\nG1 X40\nG2 X42 I1\n")
    assert expl.line_dicts() == [expl.line_dict(i) for i in range(expl.line.size)]
    assert [d["kind"] for d in expl.line_dicts()] == ["rapid", "line", "dwell", "line", "arc"]
