"""The interpreter's rotary axes beyond the goldens (tests/test_rotary_goldens.py holds the
differential against LinuxCNC): the parameter file's A B C offsets, the position parameters,
soft limits, the XYZ-length rule of a Rotate, what cutter compensation, canned cycles, NURBS
and the fast lane do with A B C, and that a program without rotary words is unchanged."""

from __future__ import annotations

import dataclasses

import pytest

from nurbscnc.errors import ProgramError, UnsupportedError
from nurbscnc.machine.model import RotaryAxis
from nurbscnc.program.interpret import InterpretOptions, interpret_text
from nurbscnc.program.varfile import format_var_text, parse_var_text

A = {"a": RotaryAxis("a", 60.0, 400.0, 4000.0)}
ABC = {name: RotaryAxis(name, 60.0, 400.0, 4000.0) for name in "abc"}


def run(text: str, axes=ABC, **options):
    return interpret_text(text, InterpretOptions(rotary_axes=axes, **options))


def segment_fields(program) -> list:
    """Every field of every segment (arrays as tuples), to compare two programs exactly."""

    def plain(value):
        return tuple(value.tolist()) if hasattr(value, "tolist") else value

    return [
        (type(s).__name__, {f.name: plain(getattr(s, f.name)) for f in dataclasses.fields(s)})
        for s in program.segments
    ]


def test_var_file_rotary_offsets_are_read_and_written():
    """#5224 (G54 A) and the G92 A (#5214, in force with #5210 = 1) from the parameter file
    place program A 0 at machine 30 + 5; the program's G10 L2 A and G28.1 go back to it."""
    values = parse_var_text("5210\t1.0\n5214\t5.0\n5220\t1.0\n5224\t30.0\n")
    program = run("G0 A0\nG10 L2 P1 A15\nG0 A10\nG28.1\nM2\n", A, parameters=values)
    rotate = [s for s in program.segments if s.kind == "rotate"]
    assert [s.abc_end_deg[0] for s in rotate] == [35.0, 30.0]  # 0+5+30, then 10+5+15
    params = program.parameters
    assert params[5224] == 15.0 and params[5214] == 5.0 and params[5164] == 30.0
    text = format_var_text(params, values)
    assert "5224\t15.000000\n" in text and "5164\t30.000000\n" in text


def test_position_parameters_read_program_degrees():
    """#5423 and #<_a> are A in program coordinates, unscaled by G20."""
    program = run("G10 L2 P1 A10\nG0 A30\nG20\nG0 X[#5423 / 25.4] Y[#<_a> / 25.4]\nG21\nM2\n", A)
    assert program.segments[-1].end_mm == pytest.approx((30.0, 30.0, 0.0), abs=1e-12)
    assert program.segments[-1].abc_deg == (40.0, 0.0, 0.0) * 2  # machine A: 30 + 10


def test_soft_limits_of_a_rotary_axis_name_the_offset():
    axes = {"a": RotaryAxis("a", 60.0, 400.0, 4000.0, min_deg=-10.0, max_deg=100.0)}
    run("G0 A100\nG0 A-10\nM2\n", axes)  # the bounds are inside
    with pytest.raises(ProgramError) as info:
        run("G10 L2 P1 A20\nG0 A50\nG1 X5 A90 F100\nM2\n", axes)
    exc = info.value
    assert (exc.pos.line, exc.pos.column) == (3, 7)
    assert exc.message == (
        "the move leaves the soft limits: A reaches 110 degrees in machine coordinates "
        "(G54 offset A 20), outside [-10, 100] degrees"
    )


@pytest.mark.parametrize(
    "block, kind",
    [
        ("G1 X0.00000005 A10 F100", "rotate"),  # 5e-8 mm: no XYZ motion (≤ 1e-7)
        ("G1 X0.0000002 A10 F100", "line"),
        ("G20 G1 X0.00000009 A10 F100", "rotate"),  # 9e-8 inch: the rule is in program units
        ("G20 G1 X0.0000002 A10 F100", "line"),
    ],
)
def test_a_move_without_xyz_motion_is_a_rotate(block, kind):
    program = run(block + "\nM2\n", A)
    assert [s.kind for s in program.segments] == [kind]


def test_g95_rotary_only_rate_is_f_per_revolution_times_speed():
    program = run("G95 S600 M3\nG1 A90 F0.5\nM2\n", A)
    assert program.segments[-1].feed_deg_s == 0.5 * 600 / 60


def test_g93_rotary_only_zero_feed_floor():
    """LinuxCNC's inverse_time_rate_straight: at least 0.1 per minute."""
    program = run("G93\nG1 A0.001 F1\nM2\n", A)
    assert program.segments[-1].feed_deg_s == pytest.approx(0.1 / 60, rel=1e-15)


def test_start_position_of_the_rotary_axes():
    program = run("G1 X10 F100\nG1 A20\nM2\n", A, start_abc_deg=(10.0, 0.0, 0.0))
    assert program.start_abc_deg == (10.0, 0.0, 0.0)
    line, rotate = program.segments
    assert line.abc_deg == (10.0, 0.0, 0.0, 10.0, 0.0, 0.0)
    assert rotate.abc_start_deg == (10.0, 0.0, 0.0) and rotate.abc_end_deg == (20.0, 0.0, 0.0)
    assert program.rotary_axes == ("a",)


def test_rotary_axes_used_are_the_ones_away_from_zero():
    assert run("G0 C10\nG0 C0\nM2\n").rotary_axes == ("c",)
    assert run("G0 X1 A0 B0 C0\nM2\n").rotary_axes == ()
    # an offset alone moves nothing: the machine's A stays 0
    assert run("G10 L2 P1 A30\nG0 X1\nM2\n").rotary_axes == ()


def test_fast_lane_carries_a_held_rotary_position():
    lines = "".join(f"G1 X{i} Y{i % 3} F500\n" for i in range(1, 30))
    text = "G0 A30 B-5\n" + lines + "M2\n"
    fast = run(text)
    slow = run(text, fast_lane=False)
    assert segment_fields(fast) == segment_fields(slow)
    assert all(s.abc_deg == (30.0, -5.0, 0.0) * 2 for s in fast.segments[1:])


def test_a_program_without_rotary_words_is_unchanged():
    text = "G0 X1 Y2\nG1 Z-1 F100\nG2 X3 Y2 R1\nG4 P1\nG81 X5 Y5 Z-2 R1\nG80\nM2\n"
    with_axes = run(text)
    without = interpret_text(text, InterpretOptions())
    assert segment_fields(with_axes) == segment_fields(without)
    assert with_axes.rotary_axes == () and with_axes.start_abc_deg == (0.0, 0.0, 0.0)
    assert all(getattr(s, "abc_deg", None) is None for s in with_axes.segments)


def test_cutter_compensation_refuses_turning_a_and_carries_it_held():
    tools = "G0 X-10 Y-10 A30\nG41.1 D2 G1 X0 Y0 F300\n"
    with pytest.raises(UnsupportedError) as info:
        run(tools + "G1 X10 A40\nM2\n")
    assert info.value.pos.line == 3
    program = run(tools + "G1 X10\nG40 G1 X20 Y-10 A0\nM2\n")
    assert [s.abc_deg for s in program.segments[1:-1]] == [(30.0, 0.0, 0.0) * 2] * 3
    assert program.segments[-1].abc_deg == (30.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def test_canned_cycles_carry_a_held_rotary_position_and_refuse_a_words():
    program = run("G0 Z5 A45\nG81 X5 Y5 Z-2 R1 F100\nG80\nM2\n")
    assert all(s.abc_deg == (45.0, 0.0, 0.0) * 2 for s in program.segments[1:])
    with pytest.raises(ProgramError) as info:
        run("G81 X5 Y5 Z-2 R1 A10 F100\nM2\n")
    assert info.value.message == "Cannot put an a in canned cycle"


@pytest.mark.parametrize(
    "text, column",
    [
        ("G0 A10\nG5.2 X0 Y0 P1 L3\nX1 Y1\nX2 Y0\nG5.3\nM2\n", 1),
        ("G1 F100\nG5 X1 Y1 I0.5 J0 P1 Q0 A5\nM2\n", 24),
    ],
)
def test_splines_and_nurbs_refuse_rotary_axes(text, column):
    with pytest.raises(UnsupportedError) as info:
        run(text)
    assert info.value.pos.line == 2 and info.value.pos.column == column
    assert "with rotary axes is not supported" in info.value.message


def test_tool_offsets_on_rotary_axes_are_refused():
    with pytest.raises(UnsupportedError):
        run("G43.1 Z1 A5\nM2\n")
    with pytest.raises(UnsupportedError):
        run("G10 L1 P1 Z5 A2\nM2\n")


def test_missing_axis_refused_in_g28_and_g53_too():
    b_only = {"b": RotaryAxis("b", 60.0, 400.0, 4000.0)}
    for text, col, axes in (("G28 A10\nM2\n", 5, b_only), ("G53 G0 B3\nM2\n", 8, A)):
        with pytest.raises(ProgramError) as info:
            run(text, axes)
        assert info.value.pos.column == col and "the machine has no" in info.value.message
    # G28 without words leaves a missing axis where it is, whatever #5165 holds
    program = run("G0 X5\nG28\nM2\n", A, parameters={5165: 40.0})
    assert program.rotary_axes == ()
