"""O-words, coordinate systems, line reading and limits of the interpreter.

References: hand-inlined programs (a subroutine call must give exactly the moves of its body
written out), G90 programs (G91 increments summed by hand must give the same end points),
closed forms (expression values), and LinuxCNC's rules as its interpreter applies them
(checked with rs274 / the gcode module where noted; the move-by-move LinuxCNC comparison is
tests/test_interpret_linuxcnc.py).
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nurbscnc.errors import ConfigError, GCodeSyntaxError, NurbsCncError, ProgramError
from nurbscnc.program.interpret import InterpretOptions, interpret_text
from nurbscnc.program.tooltable import parse_tool_table

from .test_interpret import assert_same_program, num


def segs(text: str, **options):
    return interpret_text(text, InterpretOptions(**options)).segments


def ends(text: str, **options) -> np.ndarray:
    return np.array([s.end_mm for s in segs(text, **options)], dtype=float)


# -- subroutines equal their inlined form ---------------------------------------------------
coord = st.integers(-50_000, 50_000).map(lambda k: k / 1000.0)
moves = st.lists(
    st.tuples(st.sampled_from(["G0", "G1"]), coord, coord, coord), min_size=1, max_size=6
)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(body=moves, args=st.lists(coord, min_size=3, max_size=3), turns=st.integers(1, 3))
def test_subroutine_equals_inlined(body, args, turns):
    """A sub whose moves use #1..#3 as offsets, called in a repeat loop, equals the same
    moves written out with the argument values added (segment lines aside)."""
    sub_lines = [f"{g} X[#1 + {num(x)}] Y[#2 + {num(y)}] Z[#3 + {num(z)}]" for g, x, y, z in body]
    called = "\n".join(
        [
            "F600",
            "o<part> sub",
            *sub_lines,
            "o<part> endsub",
            f"o1 repeat [{turns}]",
            f"o<part> call [{num(args[0])}] [{num(args[1])}] [{num(args[2])}]",
            "o1 endrepeat",
            "M2",
        ]
    )
    a, b, c = args
    inline_lines = [f"{g} X{num(a + x)} Y{num(b + y)} Z{num(c + z)}" for g, x, y, z in body]
    inlined = "\n".join(["F600", *(inline_lines * turns), "M2"])
    got, want = segs(called), segs(inlined)
    assert [s.kind for s in got] == [s.kind for s in want]
    for s, w in zip(got, want):
        np.testing.assert_allclose(s.end_mm, w.end_mm, rtol=0, atol=1e-12)
        np.testing.assert_allclose(s.start_mm, w.start_mm, rtol=0, atol=1e-12)
        assert s.feed_mm_s == w.feed_mm_s


@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    points=st.lists(st.tuples(coord, coord, coord), min_size=1, max_size=8),
    units=st.sampled_from(["G21", "G20"]),
)
def test_g91_equals_g90(points, units):
    """The same path as G91 increments and G90 positions (also in inches, also arcs)."""
    absolute = [units, "G90 F100"]
    incremental = [units, "G91 F100"]
    prev = (0.0, 0.0, 0.0)
    for x, y, z in points:
        absolute.append(f"G1 X{num(x)} Y{num(y)} Z{num(z)}")
        incremental.append(
            f"G1 X[{num(x)} - {num(prev[0])}] Y[{num(y)} - {num(prev[1])}] "
            f"Z[{num(z)} - {num(prev[2])}]"
        )
        prev = (x, y, z)
    # a full circle about a centre 1 unit to the right, in both modes (I is incremental)
    absolute.append("G2 I1 J0")
    incremental.append("G2 I1 J0")
    a, b = segs("\n".join(absolute)), segs("\n".join(incremental))
    assert_same_program(a, b, rtol=0, atol=1e-9)


# -- O-word behaviour -------------------------------------------------------------------------
def test_call_arguments_are_local_and_restored():
    prog = "#1 = 7\no1 sub\nG0 X#1 Y#2\n#1 = 99\no1 endsub\no1 call [3]\nG0 Z#1\n"
    np.testing.assert_array_equal(ends(prog), [[3, 0, 0], [3, 0, 7]])


def test_return_value_and_named_scopes():
    prog = """#<_g> = 1
o<f> sub
  #<loc> = [#1 * 2]
  #<_g> = [#<_g> + 1]
  o<f> return [#<loc> + #<_g>]
o<f> endsub
o<f> call [5]
G0 X#<_value> Y#<_value_returned> Z[EXISTS[#<loc>]]
o<f> call [1]
G0 X#<_value> Y#<_g>
"""
    np.testing.assert_array_equal(ends(prog), [[12, 1, 0], [5, 3, 0]])


def test_if_elseif_else_and_loops():
    prog = """#1 = 0
o1 while [#1 LT 5]
  #1 = [#1 + 1]
  o2 if [#1 EQ 1]
    G0 X1
  o2 elseif [#1 EQ 2]
    G0 X2
  o2 elseif [#1 EQ 3]
    o1 continue
  o2 else
    G0 X#1
  o2 endif
  o3 if [#1 EQ 4]
    o1 break
  o3 endif
o1 endwhile
o4 do
  G0 Y[#1]
  #1 = [#1 - 1]
o4 while [#1 GT 2]
o5 repeat [0]
  G0 Z9
o5 endrepeat
o6 repeat [2.7]
  G0 Z[#1]
  #1 = [#1 + 1]
o6 endrepeat
"""
    np.testing.assert_array_equal(
        ends(prog), [[1, 0, 0], [2, 0, 0], [4, 0, 0], [4, 4, 0], [4, 3, 0], [4, 3, 2], [4, 3, 3]]
    )


def test_sub_defined_after_its_call_and_numbered():
    np.testing.assert_array_equal(
        ends("o100 call [2]\nM2\no100 sub\nG0 X#1\no100 endsub\n"), [[2, 0, 0]]
    )


def test_subroutine_file_through_the_loader():
    files = {
        "pocket": ("o<pocket> sub\nG1 X#1 F100\nG1 Y#2 Q5\no<pocket> endsub\n", "pocket.ngc"),
        "ok": ("o<ok> sub\nG0 Z#1\no<ok> endsub\nM2\n", "/lib/ok.ngc"),
    }
    asked = []

    def load(name):
        asked.append(name)
        return files.get(name)

    got = segs("o<ok> call [4]\no<ok> call [5]\nG0 X1\n", load_subroutine=load)
    assert [s.end_mm for s in got] == [(0, 0, 4), (0, 0, 5), (1, 0, 5)]
    assert asked == ["ok"]  # read once
    with pytest.raises(ProgramError) as info:
        segs("G0 X1\no<pocket> call [1] [2]\n", load_subroutine=load)
    # The error names the file, line and column in it, and points at the call line.
    assert info.value.message.startswith("pocket.ngc:3:")
    assert "Q word" in info.value.message
    assert info.value.pos.line == 2


def test_endless_recursion_and_loops_end_quickly():
    start = time.perf_counter()
    with pytest.raises(ProgramError, match="nested calls") as info:
        segs("o1 sub\nG0 X1\no1 call\no1 endsub\no1 call\n", max_call_depth=50)
    assert info.value.pos.line == 3
    with pytest.raises(ProgramError, match="loop iterations") as info:
        segs("o1 do\no1 while [1]\n", max_loop_iterations=1000)
    assert info.value.pos.line == 2
    assert time.perf_counter() - start < 5.0


def test_what_loops_and_repeats_add_is_bounded():
    """The fuzzer's 1,000 blank lines in an endless loop ran 250,000 iterations (250 M
    lines, 3 minutes) before the iteration limit; 100 moves per iteration, or one canned
    cycle with L100000000, filled 4 GB first (MemoryError, exit 1). Executed lines and moves
    beyond one per line of the program are budgets, checked at the line that passes them;
    a cycle's repeats are counted before it expands."""
    body = "\n" * 50
    loop = f"#1 = 0\no1 while [#1 GE 0]\n{body}o1 endwhile\nM2\n"
    with pytest.raises(ProgramError, match="executes more than 1,000 lines") as info:
        segs(loop, extra_lines=1000)
    assert 3 <= info.value.pos.line <= 53  # inside the loop, on its first passes
    moves = "G1 X1 F100\nG1 X0\n" * 5
    with pytest.raises(ProgramError, match="makes more than 100 moves") as info:
        segs(f"o1 repeat [1000]\n{moves}o1 endrepeat\nM2\n", extra_moves=100)
    assert 2 <= info.value.pos.line <= 11
    # exactly at the budget is allowed: 14 lines, 10 × 11 moves = 14 + 96
    assert len(segs(f"o1 repeat [11]\n{moves}o1 endrepeat\nM2\n", extra_moves=96)) == 110
    with pytest.raises(ProgramError, match="makes more than 2,000,000 moves") as info:
        segs("G21 G90 F100\nG91 G81 X0.001 Y0 Z-1 R1 L100000000\nM2\n")
    assert (info.value.pos.line, info.value.pos.column) == (2, 5)
    # a repeat within it: LinuxCNC's rs274 -g makes the same 152 straight moves
    assert len(segs("G90 F100 G0 Z2\nG91 G81 X1 Y0 Z-1 R1 L50\nM2\n")) == 152


def test_pecks_are_counted_before_they_are_made():
    """The fuzzer's G83 with Q 1e-9 mm filled 2.9 GB in 39 s (MemoryError, exit 1), and Q 1e-6
    passed the budget a line late after 17 s: the pecks of a block are counted first."""
    start = time.perf_counter()
    for code in ("G83", "G73"):
        with pytest.raises(ProgramError, match="makes more than 2,000,000 moves") as info:
            segs(f"{code} X0 Y0 Z-1 R0 Q0.000000001 F600\nM2\n")
        assert (info.value.pos.line, info.value.pos.column) == (1, 1)
        with pytest.raises(ProgramError, match="makes more than 100 moves") as info:
            segs(f"G0 Z1\n{code} X0 Y0 Z-1 R0 Q0.5 F600\nX1\nQ0.01 X2\nM2\n", extra_moves=100)
        assert info.value.pos.line == 4
    assert time.perf_counter() - start < 5.0
    # within the budget, LinuxCNC's moves: rs274 -g prints 302 straight moves for this, the
    # second of which (a rapid to the hole's X Y at the initial level) goes nowhere
    ours = segs("G0 Z1\nG83 X0 Y0 Z-1 R0 Q0.01 F600\nM2\n", extra_moves=303)
    assert len(ours) == 301  # within a budget only just large enough (3 lines + 300)
    assert len(segs("G0 Z1\nG73 X0 Y0 Z-1 R0 Q0.01 F600\nM2\n", extra_moves=250)) == 202
    assert len(segs("G90 F100 G0 Z2\nG91 G81 X1 Y0 Z-1 R1 L50\nM2\n", extra_moves=200)) == 152
    with pytest.raises(ProgramError, match="makes more than 290 moves"):
        segs("G0 Z1\nG83 X0 Y0 Z-1 R0 Q0.01 F600\nM2\n", extra_moves=290)


def test_fanuc_program_number_at_the_top():
    assert ends("%\nO1234 (PART 7)\nG0 X1\n%\n").tolist() == [[1, 0, 0]]


# -- reading lines ----------------------------------------------------------------------------
def test_cr_cr_lf_is_one_line_end():
    with pytest.raises(ProgramError) as info:
        segs("G0 X1\r\r\nG0 X2\r\r\nG1 X3\r\n")
    assert info.value.pos.line == 3  # not 5


def test_nothing_after_m2_or_the_closing_percent_is_read():
    assert len(segs("G0 X1\nM2\nG1 X2 $$$ ((\n")) == 1
    assert len(segs("%\nG0 X1\n%\nthis is not G-code\n")) == 1
    # an error before the end is reported, whatever follows
    with pytest.raises(GCodeSyntaxError) as info:
        segs("G0 X1\nG0 X$\nM30\n@@@\n")
    assert info.value.pos.line == 2


def test_program_without_motion():
    prog = interpret_text("G21 S300\nM2\n")
    assert prog.segments == () and prog.blocks == 2


def test_pauses():
    """M0 / M1 / M60 are Pause segments: zero-second stops (kind "pause") with their code."""
    got = segs("G0 X1\nM0\nM1\nG0 Y2\nM60\n")
    assert [(type(s).__name__, s.line, getattr(s, "code", "")) for s in got] == [
        ("Line", 1, ""),
        ("Pause", 2, "M0"),
        ("Pause", 3, "M1"),
        ("Line", 4, ""),
        ("Pause", 5, "M60"),
    ]
    assert got[1].position_mm == (1.0, 0.0, 0.0)
    assert got[1].kind == "pause" and got[1].seconds == 0.0


# -- expressions of any depth -----------------------------------------------------------------
@pytest.mark.parametrize(
    ("expr", "value"),
    [
        ("[1" + "+0.5" * 1000 + "]", 501.0),
        ("#" * 1000 + "1", 1.0),  # #1 = 1, so every # reads #1 again
        ("ABS[" * 1000 + "-2" + "]" * 1000, 2.0),
        ("-" * 1001 + "3", -3.0),
        ("[" * 2000 + "4" + "]" * 2000, 4.0),
    ],
    ids=["sum1000", "hash1000", "abs1000", "neg1001", "brackets2000"],
)
def test_deep_expressions_evaluate(expr, value):
    (line,) = segs(f"#1 = 1\nG1 F100 X{expr}\n")
    assert line.end_mm[0] == value


def test_huge_line_is_refused_quickly():
    start = time.perf_counter()
    with pytest.raises(GCodeSyntaxError, match="line is too long"):
        segs("G1 X" + "[" * 2_000_000 + "1" + "]" * 2_000_000 + "\n")
    assert time.perf_counter() - start < 5.0


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("G4 P" + "9" * 300, "dwell P1e+300 is out of range"),
        ("G1 F100 X99999999999999999999", "X1e+20 is out of range"),
        (
            "F100 G5.2 X0 Y0 P1 L3\nX1 Y1 P1" + "0" * 300 + "\nX2 Y0 P1\nG5.3",
            "NURBS weight P1e+300 is out of range",
        ),
        ("G1 X1 F0." + "0" * 320 + "1", "is out of range"),
        ("F1 G2 X0 Y0 I1 J0 P1000000000", "arc turns P1e+09 is out of range"),
    ],
)
def test_values_no_machine_can_use_are_named(text, message):
    with pytest.raises(ProgramError, match=message.replace("+", r"\+")):
        segs(text)


# -- tool tables -----------------------------------------------------------------------------
def test_tool_table_format_and_g43():
    table = parse_tool_table("T1 P1 Z12.5 D6 ;end mill\n\nt2 p2 x0.5 z-3 d4.0\n; comment\n")
    assert table[1].offset_mm == (0.0, 0.0, 12.5) and table[1].diameter_mm == 6.0
    assert table[2].offset_mm == (0.5, 0.0, -3.0) and table[2].pocket == 2
    got = ends("T1 M6 G43\nG0 Z0\nG43 H2\nG0 X0 Z0\nG49\nG0 X0 Z0\n", tools=table)
    # the M6 stops at the start, then the moves
    np.testing.assert_array_equal(got, [[0, 0, 0], [0, 0, 12.5], [0.5, 0, -3], [0, 0, 0]])


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("T1e400 Z1", "out of range"),
        ("T1 Zx", "not a number"),
        ("P1 Z1", "without a T"),
        ("T1.5 Z1", "non-negative integer"),
        ("T1 K4", "unknown tool table field"),
    ],
)
def test_bad_tool_tables(text, message):
    with pytest.raises(ConfigError, match=message) as info:
        parse_tool_table(text, "tools.tbl")
    assert "tools.tbl:1:" in info.value.message


# -- coordinate systems -----------------------------------------------------------------------
def test_offsets_parameters_and_machine_coordinates():
    prog = """G10 L2 P2 X10 Y20 Z-5
G55 G0 X1 Y1 Z1
G0 X[#5241] Y#5242
G92 X0 Y0
G0 X1
G53 G0 X0 Y0
G92.1
G54 G0 X3
G28.1
G0 X4
G28
"""
    np.testing.assert_allclose(
        ends(prog),
        [[11, 21, -4], [20, 40, -4], [21, 40, -4], [0, 0, -4], [3, 0, -4], [4, 0, -4], [3, 0, -4]],
        rtol=0,
        atol=1e-12,
    )


def test_errors_are_project_errors():
    assert issubclass(ConfigError, NurbsCncError)


def test_m70_m72_m73_save_and_restore_modal_state():
    """LinuxCNC's nc_files/m70m72-demo.ngc in short: state saved, changed, restored."""
    prog = """G21 G90 F200
M70
G20 G91 F5
G1 X1
M72
G1 X1
o1 sub
  M73
  G20 G91
  G1 X1
o1 endsub
o1 call
G1 X2
"""
    got = segs(prog)
    np.testing.assert_allclose([s.end_mm[0] for s in got], [25.4, 1.0, 26.4, 2.0], atol=1e-12)
    # "G20 G91 F5" after G21: F is set before the units change (LinuxCNC), so 5 mm/min.
    assert [s.feed_mm_s * 60 for s in got] == pytest.approx([5, 200, 200, 200])


def test_exists_of_numbered_parameters():
    """LinuxCNC's tests/interp/exists (its expected output: X1 Z1, then X1 Z0): EXISTS[#n]
    says whether n is a parameter number."""
    prog = (
        "#<a>=999\nG0 X EXISTS[#1] Y EXISTS[#99999] Z EXISTS[#<a>]\n#1=2\n#2=99999\n"
        "G0 X EXISTS[##1] Y EXISTS[##2] Z EXISTS[###1]\n"
    )
    np.testing.assert_array_equal(ends(prog), [[1, 0, 1], [1, 0, 0]])


def test_check_finds_subroutine_files(tmp_path):
    """``check``: o<name> call reads name.ngc beside the program, then --subroutine-path."""
    import json

    from click.testing import CliRunner

    from nurbscnc.cli.main import main

    (tmp_path / "lib").mkdir()
    (tmp_path / "beside.ngc").write_text("o<beside> sub\nG1 X#1 F100\no<beside> endsub\n")
    (tmp_path / "lib" / "far.ngc").write_text("o<far> sub\nG1 Y#1 F100\no<far> endsub\nM2\n")
    (tmp_path / "main.ngc").write_text("o<beside> call [2]\no<far> call [3]\nM2\n")
    runner = CliRunner()
    missing = runner.invoke(main, ["check", "--json", str(tmp_path / "main.ngc")])
    assert missing.exit_code == 2
    assert "no file far.ngc was found" in json.loads(missing.stdout)["errors"][0]["message"]
    found = runner.invoke(
        main,
        ["check", "--json", "--subroutine-path", str(tmp_path / "lib"), str(tmp_path / "main.ngc")],
    )
    assert found.exit_code == 0, found.stderr
    data = json.loads(found.stdout)
    assert [(s["kind"], s["line"]) for s in data["segments"]] == [("line", 1), ("line", 2)]
    assert data["bounding_box_mm"]["max"] == [2.0, 3.0, 0.0]


def test_inverse_time_and_per_revolution_feeds():
    """G93: F is 1/minutes, so a move of length L takes 1/F min: feed = L·F/60 mm/s (arcs by
    their length). G95: F mm per revolution at S rpm: F·S mm/min."""
    got = segs(
        "G93 G1 X30 Y40 F2\nG2 X50 Y40 I10 J0 F3\nG94 F600 G1 X0\n"
        "S1000 G95 G1 X10 F0.2\nG20\nG1 X1 F0.01\n"
    )
    assert got[0].feed_mm_s == pytest.approx(50.0 * 2 / 60, rel=1e-15)
    assert got[1].feed_mm_s == pytest.approx(np.pi * 10 * 3 / 60, rel=1e-14)
    assert got[2].feed_mm_s == pytest.approx(10.0, rel=1e-15)
    assert got[3].feed_mm_s == pytest.approx(0.2 * 1000 / 60, rel=1e-15)
    assert got[4].feed_mm_s == pytest.approx(0.01 * 25.4 * 1000 / 60, rel=1e-15)


def test_inverse_time_feeds_as_linuxcnc():
    """LinuxCNC's G93 rate (interp_inverse.cc) is max(0.1, L·F) program units per minute,
    with an arc's L from its start radius (find_arc_length). The feeds its gcode module gave
    for these moves [mm/s], recorded by a differential run: a 1 µm move at F1 (L·F is
    0.001 mm/min: the 0.1 floor), the same in inches, and an arc whose end radius differs
    from its start radius by 1.4e-6 mm (mean radius: 8e-9 relative off)."""
    metric = segs("G21 G90\nG93 G1 X0.001 F1\n")[0].feed_mm_s
    assert metric == pytest.approx(0.001666666666666667, rel=1e-15)  # (was 1.67e-5)
    inch = segs("G20 G90\nG93 G1 X0.001 F1\n")[0].feed_mm_s
    assert inch == pytest.approx(0.042333333333333334, rel=1e-15)
    arc = segs(
        "G21 G90\nG93\nG0 X17.00767 Y-25.82195\n"
        "G3 X6.746468 Y-3.890651 I-19.259902 J4.354841 F124.294\n"
    )[1]
    assert arc.feed_mm_s == pytest.approx(53.99446243988222, rel=1e-14)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(body=moves, turns=st.integers(0, 4))
def test_fanuc_m98_equals_inlined(body, turns):
    """M98 P<n> L<k> runs the O<n> … M99 block k times (L0: not at all) and returns after
    the M98, as the body written out k times; #1..#30 are global (a counter survives)."""
    sub = [f"{g} X[#1 * 0.5 + {num(x)}] Y{num(y)} Z{num(z)}" for g, x, y, z in body]
    called = "\n".join(
        [
            "F600",
            "#1 = 0",
            f"M98 P17 L{turns}",
            "G0 X[#1]",
            "M30",
            "",
            "O17",
            *sub,
            "#1 = [#1 + 1]",
            "M99",
        ]
    )
    inline = []
    for k in range(turns):
        inline += [f"{g} X{num(k * 0.5 + x)} Y{num(y)} Z{num(z)}" for g, x, y, z in body]
    inlined = "\n".join(["F600", *inline, f"G0 X{turns}", "M30"])
    got, want = segs(called), segs(inlined)
    assert [s.kind for s in got] == [s.kind for s in want]
    for s, w in zip(got, want):
        np.testing.assert_allclose(s.end_mm, w.end_mm, rtol=0, atol=1e-12)
        assert s.feed_mm_s == w.feed_mm_s


def test_fanuc_m98_lines_and_nesting():
    text = "G0 X0\nM98 P2 L2\nM30\nO2\nM98 P1 L3\nM99\nO1\nG91 G0 X1\nG90\nM99\n"
    prog = interpret_text(text)
    assert [s.end_mm[0] for s in prog.segments] == [float(k) for k in range(1, 7)]
    assert {s.line for s in prog.segments} == {8}  # the moves carry the sub's own line


def test_g80_beside_a_motion_code():
    """LinuxCNC (rs274 -g, checked): G80 with G0/G1/G2/G81 in one block gives way to the other
    code; G80 alone with axis words stays an error."""
    assert ends("G80 G0 X1\nM2").tolist() == [[1, 0, 0]]
    assert ends("G0 G80 X1\nM2").tolist() == [[1, 0, 0]]
    assert ends("G80 G1 X1 F10\nM2").tolist() == [[1, 0, 0]]
    assert [s.kind for s in segs("G80 G2 X1 I.5 F10\nM2")] == ["arc"]
    assert len(segs("G81 G80 X1 Z-1 R1 F10\nM2")) == 4
    with pytest.raises(ProgramError, match="G80"):
        segs("G80 X1\nM2")


def test_m61_sets_the_loaded_tool_for_g43():
    tools = parse_tool_table("T3 P3 Z2.5 D6\nT4 P4 Z-1 D4\n")
    prog = interpret_text(
        "M61 Q3\nG43\nG0 X0 Y0 Z0\nM61 Q4 G43\nG0 Z0\nM2", InterpretOptions(tools=tools)
    )
    assert [tuple(s.end_mm) for s in prog.segments] == [(0.0, 0.0, 2.5), (0.0, 0.0, -1.0)]


def test_g10_l1_l10_l11_write_the_tool_table():
    """Offsets as LinuxCNC's interp test g10-l1-l10 prints them (#5401..#5403, rs274):
    L10 X1 at X.1 makes the entry -.9; under G10 L2 R45, L10 X1 at the origin makes it
    (-.707, -.707); L11 works in G59.3 without G92. The offset in force changes at G43."""
    tools = parse_tool_table("T1 P1 Z0 D2\n")
    run = lambda text: interpret_text(text, InterpretOptions(tools=tools)).segments  # noqa: E731
    segments = run("T1 M6 G43\nG0 X.1 Y.2 Z.3\nG10 L10 P1 X1\nG0 X2\nG43\nG0 X3\nM2")
    assert [s.kind for s in segments][0] == "pause"  # the M6
    assert [s.end_mm[0] for s in segments[1:]] == [0.1, 2.0, pytest.approx(2.1, abs=1e-15)]
    segments = run("G10 L2 P1 R45\nT1 M6 G43\nG10 L10 P1 X1\nG43\nG0 X2 Y0\nM2")
    # entry (-1/√2, -1/√2): program (2, 0) → machine R45·(2, 0) + entry = (1/√2, 1/√2)
    np.testing.assert_allclose(segments[-1].end_mm, [0.5**0.5, 0.5**0.5, 0.0], atol=1e-15)
    segments = run("G10 L2 P9 Z-27\nG92 Z5\nT1 M6\nG0 G53 Z-30\nG10 L11 P1 Z0\nG43\nG0 Z0\nM2")
    # L11: the entry is -30 - (-27) = -3 (G92 ignored); Z0 is then 0 + G92 (-5) + (-3)
    assert segments[-1].end_mm[2] == -8.0
    segments = run("T1 M6\nG10 L1 P1 Z2.5 R4\nG43\nG0 Z0\nM2")
    assert segments[-1].end_mm[2] == 2.5


def test_g52_local_offset_shares_the_g92_registers():
    """End points recorded from LinuxCNC 2.9 (tools/record_goldens.py on this program)."""
    text = (
        "G21\nG0 X1\nG52 X2 Y3\nG0 X0 Y0\nG52 Z1\nG0 X1 Z0\nG92.2\nG0 X0\nG92.3\nG0 X0.5\n"
        "G52 X0\nG0 X0\nG92.1\nG0 X0 Y0\nM2\n"
    )
    linuxcnc = [[1, 0, 0], [2, 3, 0], [3, 3, 1], [0, 3, 1], [2.5, 3, 1], [0, 3, 1], [0, 0, 1]]
    np.testing.assert_allclose(ends(text), linuxcnc, rtol=0, atol=1e-9)


def test_computed_o_label_call():
    """LinuxCNC's interp test oword-bug315-p2: ``o#<sub> call`` calls the sub numbered #<sub>;
    an expression works too."""
    text = "o5 sub\nG0 X[#1]\no5 endsub\n#<n> = 5\no#<n> call [7]\n#3=2\no[#3*2+1] call [8]\nM2"
    assert ends(text)[:, 0].tolist() == [7.0, 8.0]
    with pytest.raises(ProgramError, match="not an O number"):
        segs("o5 sub\no5 endsub\no[2.5] call\nM2")


def test_o_labels_of_any_length_are_numbers_without_leading_zeros():
    """o0100 and o100 are one label (LinuxCNC reads the number); a label of 5,000 digits is
    read as written (the fuzzer's ``int`` of 20,021 digits raised Python's ValueError: exit 1,
    an internal error), and an unmatched one is the usual error."""
    text = "o0100 sub\nG0 X[#1]\no100 endsub\no00100 call [4]\nM2"
    assert ends(text)[:, 0].tolist() == [4.0]
    label = "1" + "9" * 5000
    assert ends(f"o{label} sub\nG0 X[#1]\no{label} endsub\no0{label} call [3]\nM2")[
        :, 0
    ].tolist() == [3.0]
    with pytest.raises(ProgramError, match="endif without if"):
        segs(f"o1 if [1]\no{label} endif\nM2")


@pytest.mark.parametrize(
    "text",
    [
        "o2 endif\nG0 X1\nM2",
        "o2 else\nG0 X1\no2 endif\nM2",
        "o2 elseif [1]\nG0 X1\no2 endif\nM2",
        "o1 if [1]\nG0 X1\no2 endif\nM2",
    ],
)
def test_else_and_endif_need_their_if(text):
    """LinuxCNC 2.9 (rs274 -g) stops each of these at the unmatched label ("undefined O-word
    label"); nurbscnc ran them, skipping the G0 after a stray else."""
    with pytest.raises(ProgramError, match="without if"):
        segs(text)


@pytest.mark.parametrize(
    "text",
    [
        "o1 while [1]\nG0 X1\no1 break\no1 endwhile\no1 break\nG0 X2\nM2",
        "o1 while [1]\nG0 X1\no1 break\no1 endwhile\no1 continue\nG0 X2\nM2",
        "o1 repeat [2]\nG0 X1\no1 endrepeat\no1 break\nM2",
        "o1 do\nG0 X1\no1 break\no1 while [1]\no1 break\nM2",
    ],
)
def test_break_after_its_loop_is_an_error_not_a_hang(text):
    """A break or continue after its loop's end found the loop before it and jumped to the
    line after that end: itself, for ever (check never returned). It is outside the loop."""
    import signal

    def hung(*_):
        raise AssertionError("the interpreter hung")

    old = signal.signal(signal.SIGALRM, hung)
    signal.alarm(20)
    try:
        with pytest.raises(ProgramError, match="outside a loop"):
            segs(text)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def test_a_second_endif_of_a_closed_if_is_accepted():
    """As LinuxCNC 2.9: the label is known, the extra endif does nothing."""
    assert ends("o1 if [1]\nG0 X1\no1 endif\no1 endif\nM2")[:, 0].tolist() == [1.0]


def test_linuxcnc_errors_a_differential_run_found():
    """Two programs LinuxCNC 2.9 refuses (its rs274 -g, messages word for word) that
    nurbscnc ran: a canned-cycle code with no axis word (only G0–G3 may stand without one:
    enhance_block), and a G88 after M6, which stops the spindle (convert_tool_change); an M3
    in the tool change's block starts it again after the change, as LinuxCNC orders them."""
    with pytest.raises(ProgramError, match="^All axes missing with motion code$") as info:
        segs("G21 G90 F100\nG81 X1 R1 Z-2\nG81\nM2\n")
    assert (info.value.pos.line, info.value.pos.column) == (3, 1)
    with pytest.raises(ProgramError, match="^Spindle not turning in g88$") as info:
        segs("G21 G90 F100 M3 S1000\nT3 M6\nG88 X5 R-1 Z-2 P0.5\nM2\n")
    assert info.value.pos.line == 3
    moves = segs("G21 G90 F100 M3 S1000\nT3 M6 M3\nG88 X5 R-1 Z-2 P0.5\nM2\n")
    # rs274 -g: CHANGE_TOOL, two traverses, the feed down, DWELL(0.5), PROGRAM_STOP (the
    # operator takes over)
    assert [s.kind for s in moves] == ["pause", "rapid", "rapid", "line", "dwell", "pause"]


def test_elseif_after_a_taken_branch_is_still_evaluated():
    """LinuxCNC evaluates the condition of every O-word line it reaches (when it reads the
    line): an elseif met at the end of a taken branch is skipped, but a condition that
    cannot be evaluated is an error there, at that line (rs274 -g: "Negative argument to
    sqrt" at line 3, "Zero or negative argument to ln" at line 5)."""
    with pytest.raises(ProgramError, match="SQRT") as info:
        segs("o1 if [1]\nG4 P1\no1 elseif [SQRT[-1]]\nG4 P2\no1 endif\n")
    assert info.value.pos.line == 3
    with pytest.raises(ProgramError, match="LN") as info:
        segs(
            "o1 if [0]\nG4 P1\no1 elseif [1]\nG4 P2\no1 elseif [LN[-1]]\nG4 P3\no1 else\no1 endif\n"
        )
    assert info.value.pos.line == 5
    dwells = segs("o1 if [0]\nG4 P1\no1 elseif [1]\nG4 P2\no1 elseif [1]\nG4 P3\no1 endif\n")
    assert [d.seconds for d in dwells] == [2.0]


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ("G43", "Cannot change tool offset with cutter radius compensation on"),
        ("G43.1 Z1", "Cannot change tool offset with cutter radius compensation on"),
        ("G49", "Cannot change tool offset with cutter radius compensation on"),
        ("G92 X1", "Cannot change axis offsets with cutter radius comp"),
        ("G52 X1", "Cannot change axis offsets with cutter radius comp"),
        ("G55", "Cannot change coordinate systems with cutter radius compensation on"),
        (
            "G10 L2 P1 X1",
            "Cannot change the active coordinate system with cutter radius compensation on",
        ),
        (
            "G10 L20 P0 X1",
            "Cannot change the active coordinate system with cutter radius compensation on",
        ),
        ("G53 G1 X5", "Cannot use g53 with cutter radius comp"),
        ("G61", "Cannot change control mode with cutter radius compensation on"),
        ("G64 P0.1", "Cannot change control mode with cutter radius compensation on"),
    ],
)
def test_offset_and_mode_changes_while_compensating_are_refused(line, message):
    """LinuxCNC 2.9 refuses each of these while G41/G42 is on (rs274 -g, its words): the
    compensated path would change frame under the tool. nurbscnc kept compensating. A G10
    of another system is allowed, as there."""
    text = f"G21 G90 F600\nG41.1 D2 G1 X10 Y0\n{line}\nG1 X20 Y5\nG40 G1 X30 Y10\nM2\n"
    with pytest.raises(ProgramError, match=f"^{message}$") as info:
        segs(text)
    assert info.value.pos.line == 3
    assert len(segs(text.replace(line, "G10 L2 P2 X1"))) == 3


def test_parameters_as_linuxcnc_reads_them():
    """From a second differential run (rs274 -g for each): #<_value> and the other
    read-only names refuse an assignment; a break in a repeat loop is refused (only while
    and do loops have one); #5400 is the tool an M6 loaded (it read 0: the offsets' range
    claimed it); G41/G42 D0 compensates with the loaded tool's radius (the spindle's
    pocket), not 0."""
    for name in ("_value", "_x", "_coord_system"):
        with pytest.raises(ProgramError, match=f"Cannot assign to read-only parameter #<{name}>"):
            segs(f"#<{name}>=5\nM2\n")
    with pytest.raises(
        ProgramError,
        match="no matching while/do label: 'o1 break' "
        r"\(found 'repeat' in line 2\)",
    ) as info:
        segs("F500\no1 repeat [3]\nG91 G1 X1\no1 break\no1 endrepeat\nM2\n")
    assert info.value.pos.line == 4
    assert segs("T3 M6\nG4 P[#5400]\nM2\n")[1].seconds == 3.0
    tools = parse_tool_table("T2 P2 D3.175\n")
    moves = segs("F600\nT2 M6\nG42 D0 G1 X10 Y0\nG1 X20\nG40 G1 X30 Y10\nM2\n", tools=tools)
    # rs274 -g: CHANGE_TOOL, then (10, -1.5875), (20, -1.5875), (30, 10)
    assert moves[0].code == "M6" and moves[0].tool == 2
    np.testing.assert_allclose(
        [m.end_mm for m in moves[1:]], [(10, -1.5875, 0), (20, -1.5875, 0), (30, 10, 0)], atol=1e-12
    )


def test_break_in_a_repeat_is_refused_even_where_it_is_skipped():
    """LinuxCNC refuses a break or continue of a repeat loop as it reads the line, even in a
    body repeat [0] skips or in a false if (rs274 -g: "no matching while/do label" at that
    line, 3 here)."""
    for text in (
        "o1 repeat [0]\nG4 P1\no1 continue\no1 endrepeat\nG4 P2\nM2\n",
        "o1 repeat [2]\no2 if [0]\no1 continue\no2 endif\nG4 P1\no1 endrepeat\nM2\n",
    ):
        with pytest.raises(
            ProgramError,
            match="no matching while/do label: 'o1 continue' "
            r"\(found 'repeat' in line 1\)",
        ) as info:
            segs(text)
        assert info.value.pos.line == 3


def test_curves_and_feeds_as_linuxcnc():
    """A third differential run (curves and arcs), each against LinuxCNC 2.9 (its gcode
    module's samples, or rs274 -g):
    - G91 G5.2: every control point is an increment from the block's start (find_ends; the
      current point stays there until G5.3), not from the previous point. LinuxCNC's first
      two samples of this block, at u = 1/30 and 2/30 of knots [0, 0, 0, 1, 2, 2, 2];
    - the NURBS runs at the feed in force at G5.3 (rs274: SET_FEED_RATE(300), NURBS_FEED);
    - G5 and G5.1 keep the motion mode (convert_spline sets none): the X Y line after is G1;
    - G5 without I J: −(P, Q) of the last G5, moves between or not, (0, 0) before any;
    - an arc's P within 0.001 of an integer is that integer (check_other_codes);
    - every G93/G94/G95 word clears F (convert_feed_mode): a G1 after a second G94 has no
      feed (rs274: "Cannot do g1 with zero feed rate")."""
    from nurbscnc.geometry.nurbs import NurbsCurve

    prog = segs(
        "G21 G90 F600 G0 X1 Y1\nG91 G5.2 X10 Y0 P1 L3\nX10 Y10 P1\nX0 Y10 P1\nG5.3\nG90\nM2\n"
    )
    curve = NurbsCurve.from_segment(prog[1])
    np.testing.assert_allclose(
        curve.point([1 / 30, 2 / 30])[:, :2],
        [[1.655555555555556, 1.0055555555555558], [2.2888888888888883, 1.0222222222222224]],
        atol=1e-12,
    )
    np.testing.assert_allclose(prog[1].end_mm, (1, 11, 0), atol=1e-12)
    (nurbs,) = segs("G21 G90 F600\nG5.2 X10 Y0 P1 L3\nX10 Y10 P1 F300\nX0 Y10 P1\nG5.3\nM2\n")
    assert nurbs.feed_mm_s == 5.0
    after = segs("G21 G90 F600\nG1 X1\nG5 X10 Y5 I2 J3 P1 Q1\nX20 Y0\nM2\n")
    assert [s.kind for s in after] == ["line", "nurbs", "line"]
    np.testing.assert_allclose(after[2].end_mm, (20, 0, 0), atol=1e-12)
    first = segs("G21 F100\nG5 X1 Y1 P1 Q0\nM2\n")[0]
    np.testing.assert_allclose(first.control_points_mm[1], (0, 0, 0), atol=1e-12)
    later = segs("G21 G90 F600\nG5 X10 Y5 I1 J1 P1 Q2\nG1 X0 Y0\nG5 X10 Y5 P1 Q1\nM2\n")[2]
    np.testing.assert_allclose(later.control_points_mm[1], (-1, -2, 0), atol=1e-12)
    (arc,) = segs("G21 G90 F600\nG2 X10 Y0 I5 P2.9995\nM2\n")
    assert arc.angle_rad == pytest.approx(-5 * np.pi, rel=1e-12)  # rs274: ARC_FEED(…, -3, …)
    with pytest.raises(ProgramError, match="zero feed") as info:
        segs("G21 G94 F600\nG94\nG1 X10\nM2\n")
    assert info.value.pos.line == 3


def test_g52_order_words_as_linuxcnc():
    """LinuxCNC's convert_nurbs takes an L on any line of a G5.2 block, as the order when
    L > 3 and as order 3 otherwise (L0…L3); nurbscnc refused L1 and an L after the first
    line. Both programs match LinuxCNC's samples (the third differential run's check)."""
    (later,) = segs(
        "G21 G90 F600\nG5.2 X10 Y0 P1 L3\nX10 Y10 P1 L4\nX0 Y10 P1\nX0 Y0 P1\nG5.3\nM2\n"
    )
    assert later.degree == 3  # order 4
    (low,) = segs("G21 G90 F600\nG5.2 X10 Y0 P1 L1\nX0 Y10 P1\nG5.3\nM2\n")
    assert low.degree == 2  # order 3


def test_hal_io_and_override_codes_as_linuxcnc():
    """M62–M68 and M50–M53 make no move (LinuxCNC's canon: SET_MOTION_OUTPUT_BIT,
    SET_AUX_OUTPUT_BIT, …; golden divergences.ngc). M64, M65, M66, M68 run once the motion
    before them has ended (emcTaskCheckPreconditions: WAITING_FOR_MOTION), so the tool stops
    there: a 0 s dwell, with the code; M62, M63, M67 go with the motion."""
    text = (
        "G21 F600\nG1 X1\nM62 P0\nG1 X2\nM64 P1\nG1 X3 M63 P0\nM65 P1\nM66 P0 L0\n"
        "M67 E0 Q1.5\nM68 E1 Q2\nM50 P0\nM51\nM52 P1\nM53 P0\nG1 X4\nM2\n"
    )
    got = [(s.kind, getattr(s, "code", None), s.line) for s in segs(text)]
    assert got == [
        ("line", None, 2),
        ("line", None, 4),
        ("dwell", "M64", 5),
        ("line", None, 6),
        ("dwell", "M65", 7),
        ("dwell", "M66", 8),
        ("dwell", "M68", 10),
        ("line", None, 15),
    ]
    assert all(s.seconds == 0.0 for s in segs(text) if s.kind == "dwell")
    # the words as LinuxCNC checks them (rs274 -g's messages)
    for block, message in (
        ("M64", "No valid P word with M64"),
        ("M66 L1", "Need to have either a valid P or a valid E word"),
        ("M67 Q1", "Invalid analog index with M67"),
        ("G1 X1 E2", "E word with no M66, M67 or M68"),
        ("M64 P0 M65 P1", "same modal group"),
        ("M48 M50 P0", "same modal group"),
    ):
        with pytest.raises(ProgramError, match=message):
            segs(f"G21 F600\n{block}\nM2\n")
