"""Checks before work (issues 14, 15): programs whose work is unbounded — beyond the soft
limits, a motion of days, a billion arc turns, NURBS weights of 1e9…1e308, a subnormal feed —
fail at their line with exit 2, before anything is planned or sampled.

The references are independent: the arc boxes are hand-computed circle extremes, the point
count the servo clock's own sample count, the weight rescaling the same curve with unit
weights."""

from __future__ import annotations

import math

import numpy as np
import pytest
from click.testing import CliRunner

from nurbscnc.cli.main import main
from nurbscnc.errors import GeometryError
from nurbscnc.geometry.nurbs import MAX_WEIGHT_RATIO, NurbsCurve
from nurbscnc.geometry.segments import Nurbs, frozen_array
from nurbscnc.plan.limits import arc_box_mm
from nurbscnc.program.interpret import interpret_text

HEAD = "G21 G90 G17\n"
NURBS = "G1 X0 Y0 F600\nG5.2 X0 Y0 P1 L3\nX10 Y10 P{w}\nX20 Y0 P1\nG5.3\nM2\n"

#: (name, program, "line:column" of the error, words the message must hold). Values no
#: machine can use (a billion turns, a subnormal feed, weights beyond 1e±9) are refused by
#: the interpreter at the word; the rest by the checks before work at the line.
UNBOUNDED = [
    (
        "beyond_soft_limits",
        HEAD + "G1 X1000000 F600\nM2\n",
        "2:1",
        ["soft limits", "X reaches 1e+06 mm", "[-1000, 1000]"],
    ),
    (
        "tiny_feed",
        HEAD + "G1 X1 F0.001\nM2\n",
        "2:1",
        ["60000 s", "60000001 reference points", "limits.max_points = 50000000"],
    ),
    (
        "long_dwell",
        HEAD + "G1 X1 F600\nG4 P100000\nG1 X2\nM2\n",
        "3:1",
        ["100000 s", "limits.max_points"],
    ),
    (
        "billion_turns",
        HEAD + "G1 X0 Y0 F600\nG2 X0 Y0 I1 J0 P1000000000\nM2\n",
        "3:16",
        ["arc turns P1e+09", "at most 100000"],
    ),
    (
        "subnormal_feed",
        HEAD + "G1 X1 F0." + "0" * 320 + "1\nM2\n",
        "2:7",
        ["feed F9.98013e-322 is out of range"],
    ),
    ("weight_1e9", HEAD + NURBS.format(w="1000000000"), "3:1", ["factor of 1e+09"]),
    ("weight_1e20", HEAD + NURBS.format(w="1" + "0" * 20), "4:9", ["weight P1e+20"]),
    ("weight_1e308", HEAD + NURBS.format(w="1" + "0" * 308), "4:9", ["weight P1e+308"]),
    # The fuzzer's find: a weight ~1.26e20 on the G5.2 line made `plan` exit 1 (int(NaN)).
    (
        "weight_fuzz",
        HEAD + "G1 X0 Y0 F600\nG5.2 X0 Y0 P126107250882699979611 L3\nX10 Y10 P1\n"
        "X20 Y0 P1\nG5.3\nM2\n",
        "3:12",
        ["weight P1.26107e+20"],
    ),
]


def invoke(args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.mark.parametrize("command", ["check", "plan", "run"])
@pytest.mark.parametrize("name, text, at, words", UNBOUNDED, ids=[u[0] for u in UNBOUNDED])
def test_unbounded_work_fails_at_its_line(tmp_path, command, name, text, at, words):
    src = tmp_path / f"{name}.nc"
    src.write_text(text)
    out = tmp_path / "x.csv"
    args = [command, src] + (["-o", out] if command == "run" else [])
    result = invoke(args)
    assert result.exit_code == 2, (result.exit_code, result.stderr, result.exception)
    assert f"{src}:{at}: error: " in result.stderr
    for word in words:
        assert word in result.stderr
    assert not out.exists()


def test_many_turns_have_exactly_their_length_in_time(tmp_path):
    """The bound is length / F: 10^5 turns (the interpreter's most) of radius 1 at 600 mm/min
    = 2π·10^4 s, 62.8 million points, over the 50 million cap."""
    src = tmp_path / "t.nc"
    src.write_text(HEAD + "G1 X0 Y0 F600\nG2 X0 Y0 I1 J0 P100000\nM2\n")
    result = invoke(["plan", src])
    assert result.exit_code == 2
    expected = 2.0 * math.pi * 1e5 / 10.0
    assert f"at least {expected:.6g} s" in result.stderr


# -- the point cap: exact against the servo clock's count --------------------------------------
def test_point_cap_is_the_servo_clock_count(tmp_path):
    """max_points = the number of points `run` makes passes; one fewer is refused after the
    profile (the geometry's lower bound, 1 s = 1001 points, is still below it)."""
    src = tmp_path / "p.nc"
    src.write_text(HEAD + "G1 X10 F600\nM2\n")  # 10 mm at 10 mm/s: at least 1 s
    out = tmp_path / "p.csv"
    ok = invoke(["run", src, "-o", out, "--dynamics", "off"])
    assert ok.exit_code == 0, ok.stderr
    n = sum(1 for _ in out.open()) - 1  # header
    assert n > 1001  # acceleration and jerk make the plan longer than its lower bound
    cap = f"limits.max_points={n}"
    assert invoke(["run", src, "-o", out, "--dynamics", "off", "--set", cap]).exit_code == 0
    low = invoke(
        ["run", src, "-o", out, "--dynamics", "off", "--set", f"limits.max_points={n - 1}"]
    )
    assert low.exit_code == 2
    assert f"{src}:2:1: error: the program's motion takes " in low.stderr
    assert f": {n} reference points at T_s = 1 ms, more than limits.max_points = {n - 1};" in (
        low.stderr
    )
    assert "at least" not in low.stderr  # the planned time, not the bound
    before = invoke(["check", src, "--set", "limits.max_points=1000"])
    assert before.exit_code == 2 and "at least 1 s: 1001 reference points" in before.stderr


def test_max_points_must_be_a_count(tmp_path):
    src = tmp_path / "p.nc"
    src.write_text(HEAD + "G1 X10 F600\nM2\n")
    result = invoke(["check", src, "--set", "limits.max_points=0"])
    assert result.exit_code == 2 and "limits.max_points" in result.stderr


# -- soft limits on the geometry: exact arc extremes -------------------------------------------
def arc_of(text):
    prog = interpret_text(HEAD + text)
    return next(s for s in prog.segments if s.kind == "arc")


@pytest.mark.parametrize(
    "text, lo, hi",
    [
        # G2 (clockwise) quarter from (1, 0) to (0, −1) about the origin.
        ("G0 X1 Y0\nG2 X0 Y-1 I-1 J0 F600\n", (0, -1, 0), (1, 0, 0)),
        # G3 half circle from (1, 0) to (−1, 0): it passes y = 1.
        ("G0 X1 Y0\nG3 X-1 Y0 I-1 J0 F600\n", (-1, 0, 0), (1, 1, 0)),
        # A full G3 circle of radius 2 about (3, 4), rising 5 mm in Z (a helix).
        ("G0 X5 Y4 Z0\nG3 X5 Y4 Z5 I-2 J0 F600\n", (1, 2, 0), (5, 6, 5)),
        # ZX plane: G18 G2 from (X0, Z1) about the origin to (X1, Z0), three quarters of a turn.
        ("G18\nG0 X0 Y0 Z1\nG2 X1 Z0 I0 K-1 F600\n", (-1, 0, -1), (1, 0, 1)),
    ],
)
def test_arc_box_is_the_circle_extremes(text, lo, hi):
    box_lo, box_hi = arc_box_mm(arc_of(text))
    np.testing.assert_allclose(box_lo, lo, atol=1e-12)
    np.testing.assert_allclose(box_hi, hi, atol=1e-12)


def test_arc_bulging_past_the_limit_is_refused_at_its_line(tmp_path):
    """End points inside, the arc's top (y = 1000.5) outside: refused before planning; the same
    arc 1 mm lower passes."""
    src = tmp_path / "a.nc"
    src.write_text(HEAD + "G0 X0 Y999\nG3 X0 Y999 I0 J0.75 F600\nM2\n")
    result = invoke(["check", src])
    assert result.exit_code == 2
    assert f"{src}:3:1: error: the arc leaves the soft limits: Y reaches 1000.5 mm" in (
        result.stderr
    )
    src.write_text(HEAD + "G0 X0 Y998\nG3 X0 Y998 I0 J0.75 F600\nM2\n")
    assert invoke(["check", src]).exit_code == 0


def test_nurbs_control_hull_outside_is_refused(tmp_path):
    src = tmp_path / "n.nc"
    src.write_text(HEAD + "G1 X0 Y0 F600\nG5.2 X0 Y0 P1 L3\nX10 Y1200 P1\nX20 Y0 P1\nG5.3\nM2\n")
    result = invoke(["check", src])
    assert result.exit_code == 2
    assert "3:1: error: the nurbs leaves the soft limits: Y reaches 1200 mm" in result.stderr


# -- NURBS weights -----------------------------------------------------------------------------
def nurbs(weights):
    return Nurbs(
        2,
        frozen_array([0, 0, 0, 1, 1, 1]),
        frozen_array([[0, 0, 0], [10, 10, 0], [20, 0, 0]]),
        frozen_array(weights),
        10.0,
        7,
    )


def test_weight_ratio_limit():
    NurbsCurve.from_segment(nurbs([1.0, MAX_WEIGHT_RATIO, 1.0]))
    with pytest.raises(GeometryError) as err:
        NurbsCurve.from_segment(nurbs([1.0, MAX_WEIGHT_RATIO * 1.01, 1.0]))
    assert err.value.pos.line == 7


@pytest.mark.parametrize("scale", [1e-300, 1e200, 8e307])
def test_huge_common_weight_is_the_same_curve(scale):
    """A common factor leaves a rational curve unchanged: weights (1, 2, 1)·scale give the
    curve of (1, 2, 1), point for point (exact: the rescaling is by a power of two)."""
    u = np.linspace(0.0, 1.0, 101)
    ref = NurbsCurve.from_segment(nurbs([1.0, 2.0, 1.0])).point(u)
    got = NurbsCurve.from_segment(nurbs([scale, 2.0 * scale, scale])).point(u)
    assert np.all(np.isfinite(got))
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)
