"""The fast lane (program/fastlane.py) gives the same program as line-by-line interpretation,
to the bit: every real program, the corpus, the sample programs and generated edge cases are
interpreted both ways and compared field by field (floats by their bit pattern, so even the
sign of a zero counts); error programs must fail with the same message at the same place."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest

from nurbscnc.app.load import load_program
from nurbscnc.errors import NurbsCncError
from nurbscnc.program import fastlane
from nurbscnc.program import interpret as interpret_module
from nurbscnc.program.interpret import InterpretOptions, interpret_text

ROOT = Path(__file__).resolve().parents[1]
CORPUS = Path(os.environ.get("NURBSCNC_CORPUS") or ROOT / ".." / "shared" / "corpus").resolve()
TOOLS = ROOT / "tests" / "programs" / "real" / "tools.tbl"


def _bits(value):
    """A comparable, exact form of a segment field (floats by bit pattern)."""
    if isinstance(value, float):
        return ("f", value.hex(), math.copysign(1.0, value))
    if isinstance(value, np.ndarray):
        return ("a", value.shape, tuple(_bits(float(v)) for v in value.ravel()))
    if isinstance(value, tuple | list):
        return ("t", tuple(_bits(v) for v in value))
    return (type(value).__name__, value)


def _key(program):
    out = []
    for seg in program.segments:
        fields = getattr(seg, "__slots__", None) or tuple(vars(seg))
        out.append(
            (type(seg).__name__, tuple((name, _bits(getattr(seg, name))) for name in fields))
        )
    return out, program.blocks, [(n.line, n.message) for n in program.notes]


def _both(run):
    """``run()`` with the fast lane and without it: (result or error) twice. The fast lane
    takes every run here, down to one line (``MIN_RUN_LINES`` 1: by default runs shorter
    than 8 lines go line by line), so the short edge cases exercise it."""
    results = []
    for slow in (False, True):
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(fastlane, "MIN_RUN_LINES", 1)
            if slow:
                mp.setattr(interpret_module, "plain_run", lambda *a, **k: None)
                mp.setattr(interpret_module, "nurbs_words", lambda line: None)
            try:
                results.append(("ok", _key(run())))
            except NurbsCncError as exc:
                results.append(("error", type(exc).__name__, exc.message, exc.pos))
    return results


def _files():
    files = sorted((ROOT / "tests" / "programs").rglob("*.ngc"))
    files += sorted((ROOT / "tests" / "programs").rglob("*.nc"))
    files += sorted((ROOT / "programs").glob("*.nc"))
    if CORPUS.is_dir():
        files += sorted(CORPUS.rglob("*.ngc"))
    return files


@pytest.mark.parametrize("path", _files(), ids=lambda p: str(p.relative_to(p.parents[1])))
def test_fast_lane_equals_line_by_line(path):
    fast, slow = _both(lambda: load_program(str(path), tool_table=str(TOOLS)))
    assert fast == slow


def test_the_corpus_is_there_or_skipped():
    if not CORPUS.is_dir():
        pytest.skip(f"corpus not found at {CORPUS} (set NURBSCNC_CORPUS)")
    assert any(CORPUS.rglob("*.ngc"))


EDGE_CASES = [
    # modal runs, units, offsets, rotation, tool offsets, zero-length and signed-zero moves
    "G21 G90 G1 F300\nX1 Y2\nX1 Y2\nX-0 Y2\nX0\nZ-1.5 F200\nG0 Z5\nX.5\ny-.25 z+1.\nM2",
    "G20 G90 F10\nG1 X1 Y1\nx2.5\nF0.5\nY3 (a comment)\nY4 ; semicolon\nG0 X0\nM2",
    "G10 L2 P1 X10 Y-3 Z1 R30\nG54 G1 F100\nX1 Y1\nX2\nY3 Z-1\nG92 X0 Y0\nX1\nX2 Y2\nM2",
    "G43.1 Z2.5\nG55\nG1 F50 X1\nX2\nG49\nX3\nM2",
    "N10 G01 X1 F100\nN20 X2\nN30.5 X3\nn40 g00 x0\nG1 X1\nM2",
    # lines the lane must leave to the general path, and errors at the right line
    "G1 X1 F100\nX2\nX1.2.3\nM2",
    "G1 X1 F100\nX2\nG1 X3 F-1\nM2",
    "G0 X1\nX2\nG1 X3\nM2",
    "G1 X1 F100\nX2\nX2000000000\nM2",
    "G1 X1 F100\nX2\n(MSG, hello)\nX3 (msg,again)\nX4\nM2",
    "G1 X1 F100\nG91\nX1\nX1\nG90 X0\nG93 G1 X1 F2\nX2 F3\nG94 X3 F100\nM2",
    "G81 R1 Z-1 F100\nX1 Y1\nX2 Y2\nG80\nG0 X0\nX1 Y1\nM2",
    "G1 X1 F100\nG2 X2 Y1 I0.5\nX3 Y0 I0.5\nG1 X4\nX5\nM2",
    "G1 X1 F100\nX2 F1e9\nM2",
    "G0 X1\nG80\nX2\nM2",
    "G1 X1 F100\nX2\n/X3\nX4\nM2\nX5 garbage",
]
# Runs longer than the first chunk that end inside a chunk: at a line of another kind, at a
# number float() refuses, at an out-of-range value (the run's last chunk is cut there).
_RUN = "".join(f"X{k * 0.1:.1f} Y{k % 3}\n" for k in range(45))
EDGE_CASES += [
    "G1 F100\n" + _RUN + "(MSG, hello)\n" + _RUN + "M2",
    "G1 F100\n" + _RUN + "X1.2.3\n" + _RUN + "M2",
    "G1 F100\n" + _RUN + "X1 Y.\n" + _RUN + "M2",
    "G1 F100\n" + _RUN + "G2 X1 Y1 I0.5\n" + _RUN + "M2",
    "G1 F100\n" + _RUN + "X2000000000\n" + _RUN + "M2",
    "G1 F100\n" + _RUN + "\n\n" + _RUN + "#1=2\nX#1\n" + _RUN + "M2",
]

# Runs whose chunks are longer than parse.MAX_LINE_CHARS in all (8,192 lines of CAM output
# are): read as chunks still; a line over the limit ends the run where it stands (the general
# path reports it), at a chunk's start, inside a chunk, or as the run's first line.
_LONG_RUN = "".join(f"X{k * 0.001:.4f} Y{math.sin(k / 40):.6f} Z-0.05\n" for k in range(9000))
_TOO_LONG = "X1 (" + "c" * 70_000 + ")\n"
EDGE_CASES += [
    "G1 F100\n" + _LONG_RUN + "M2",
    "G1 F100\n" + _LONG_RUN + _TOO_LONG + _LONG_RUN + "M2",
    "G1 F100\n" + _LONG_RUN[: 32 * 40] + _TOO_LONG + "M2",
    "G1 F100\n" + _TOO_LONG + _LONG_RUN + "M2",
]


# G6.2 blocks: continuation lines the NURBS lane reads (points with knots, knot-only lines,
# N numbers, lower case, blanks, weights, G91, G20, offsets) and the lines it leaves to the
# general path (other orders, comments, F, bad numbers), with errors at the right line. A
# clamped cubic (P4): four points at K0, six more, then four knots K7 end the block.
_G6 = "G6.2 P4 K0 X0 Y0 R1\nK0 X0.5 Y0.2 R1\nK0 X1 Y-0.2 R1\nK0 X1.5 Y0 R1\n"
_G6_BODY = "".join(f"K{k} X{k * 1.5 + 2:g} Y{(-1) ** k * 0.5:g} R1\n" for k in range(1, 7))
_G6_END = "K7\nK7\nK7\nK7\n"
EDGE_CASES += [
    "G21 G90 F600\n" + _G6 + _G6_BODY + _G6_END + "G1 X0 Y0\nM2",
    "G21 G90 F600\n" + _G6 + "n5 k1 x4 y.5 r2\nK2X5Y1\n K3 \t X6 Y1 Z0.5 R1.5\nK4 X7 Y0\n"
    "K5 X8\nK6 Y2 R1\n" + _G6_END + "M2",
    "G21 G91 F600\nG6.2 P3 K0 X0 Y0\nK0 X1 Y1\nK0 X1 Y0\n"
    + "".join(f"K{k} X1 Y{k % 2}\n" for k in range(1, 9))
    + "K9\nK9\nK9\nG90\nM2",
    "G20 G10 L2 P1 X1 Y2\nG54 F20\n" + _G6 + _G6_BODY + _G6_END + "M2",
    "G21 F600\n" + _G6 + _G6_BODY.replace("K3 ", "X4 K3 ") + _G6_END + "M2",  # order
    "G21 F600\n" + _G6 + _G6_BODY.replace("K3 X6.5", "K3 X6.5 (c)") + _G6_END + "M2",
    "G21 F600\n" + _G6 + _G6_BODY.replace("K4 ", "K2 ") + _G6_END + "M2",  # knots decrease
    "G21 F600\n" + _G6 + _G6_BODY.replace("K4 X8 Y0.5 R1", "K4 X8 Y0.5 R0") + _G6_END + "M2",
    "G21 F600\n" + _G6 + _G6_BODY.replace("K4 X8", "K4 X1.2.3") + _G6_END + "M2",
    "G21 F600\n" + _G6 + _G6_BODY.replace("K4 X8", "K4 X9e9") + _G6_END + "M2",
    "G21 F600\n" + _G6 + _G6_BODY.replace("K4 X8", "K4 X9999999999") + _G6_END + "M2",
    "G21 F600\n" + _G6 + _G6_BODY + "K7\nK7 X1 Y1\nK7\nK7\nK7\nM2",  # a point after knots
    "G21 F600\n"
    + _G6
    + _G6_BODY.replace("K5 X9.5 Y-0.5 R1", "K5 X9.5 Y-0.5 F300")
    + _G6_END
    + "M2",
    "G21 F600\n" + _G6 + _G6_BODY + _G6_END + "K7\nM2",  # one knot too many: a new line
    "G21 F600\n" + _G6 + _G6_BODY + "K7\nK7\nM2",  # the block never ends
]


@pytest.mark.parametrize("text", EDGE_CASES)
def test_fast_lane_edge_cases(text):
    fast, slow = _both(lambda: interpret_text(text))
    assert fast == slow


def test_fast_lane_runs_in_bulk():
    """A long plain program goes through plain_run in a few calls, not one per line (the
    lane is really used, so the equality tests above compare two different paths)."""
    calls = []
    real = fastlane.plain_run

    def counting(*args, **kwargs):
        calls.append(args[1])
        return real(*args, **kwargs)

    lines = ["G21 G90 G1 F600"] + [f"X{k * 0.01:.3f} Y{math.sin(k / 50):.4f}" for k in range(5000)]
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(interpret_module, "plain_run", counting)
        prog = interpret_text("\n".join(lines + ["M2"]))
    assert len(prog.segments) == 4999  # X0 Y0 from X0 Y0 goes nowhere
    assert len(calls) <= 3
    assert prog.blocks == 5002


def test_long_chunks_are_matched_whole(monkeypatch):
    """A run whose chunks exceed parse.MAX_LINE_CHARS in all (12,000 lines of 31 characters)
    is still matched a chunk at a time: no line is checked alone (each such check costs
    5 µs; pcb2gcode's output made 4,178 of them)."""
    alone = []
    real = fastlane._plain_row
    monkeypatch.setattr(fastlane, "_plain_row", lambda line: alone.append(line) or real(line))
    lines = ["G21 G90 G1 F600"] + [
        f"X{k * 0.01:.6f} Y{math.sin(k / 50):.6f} Z-0.0500" for k in range(12000)
    ]
    # The chunks hold 32, 64, …, 4,096 lines, then the last 3,840 (119,000 characters).
    assert sum(map(len, lines[-3840:])) > fastlane.MAX_LINE_CHARS
    prog = interpret_text("\n".join(lines + ["M2"]))
    assert len(prog.segments) == 12000
    assert len(alone) <= 3  # the first line of each try: the header, the run, M2


def test_g6_lane_reads_a_long_block_without_parsing(monkeypatch):
    """A 2,000-point G6.2 block: its continuation lines go through the NURBS lane (none of
    them parsed), and the program is the one line by line gives."""
    from nurbscnc.program import control

    n = 2000  # points; a clamped uniform cubic: knots 0 ×4, 1 … n − 4, n − 3 ×4
    knots = [0] * 4 + list(range(1, n - 3)) + [n - 3] * 4
    text = (
        "G21 G90 F600\nG6.2 P4 K0 X0 Y0 R1\n"
        + "".join(f"K{knots[k]} X{k * 0.1:.4f} Y{math.sin(k / 30):.5f} R1\n" for k in range(1, n))
        + "".join(f"K{x}\n" for x in knots[n:])
        + "M2\n"
    )
    parsed = []
    real = control.parse_line
    monkeypatch.setattr(control, "parse_line", lambda line, n: parsed.append(n) or real(line, n))
    fast = interpret_text(text)
    assert len(parsed) < 10  # the first lines and M2
    assert fast.blocks == n + 6  # every line has words
    with_lane, line_by_line = _both(lambda: interpret_text(text))
    assert with_lane == line_by_line == ("ok", _key(fast))


def test_options_can_turn_the_lane_off():
    text = "G1 F100\nX1\nX2\nM2"
    on = interpret_text(text)
    off = interpret_text(text, InterpretOptions(fast_lane=False))
    assert _key(on) == _key(off)


def test_make_lines_equals_the_constructor():
    """The bulk Line maker sets every field as Line(...) does (and refuses a missing one)."""
    import dataclasses
    import itertools

    from nurbscnc.geometry.segments import Line
    from nurbscnc.program.fastlane import make_lines

    starts = [(0.0, -0.0, 1.5), (1.0, 2.0, 3.0), (4.0, 5.0, 6.0)]
    ends = [(1.0, 2.0, 3.0), (4.0, 5.0, 6.0), (7.0, 8.0, 9.0)]
    cols = {
        "start_mm": starts,
        "end_mm": ends,
        "feed_mm_s": [0.0, 10.0, 20.5],
        "line": [3, 4, 9],
        "rapid": [True, False, False],
        "blend_mm": itertools.repeat(0.25),
        "naive_mm": itertools.repeat(0.0),
        "abc_deg": itertools.repeat(None),
    }
    made = make_lines(cols)
    want = [
        Line(a, b, f, n, r, 0.25, 0.0)
        for a, b, f, n, r in zip(starts, ends, [0.0, 10.0, 20.5], [3, 4, 9], [True, False, False])
    ]
    assert [type(m) for m in made] == [Line] * 3
    for got, ref in zip(made, want):
        for f in dataclasses.fields(Line):
            assert getattr(got, f.name) == getattr(ref, f.name)
            assert type(getattr(got, f.name)) is type(getattr(ref, f.name))
    with pytest.raises(dataclasses.FrozenInstanceError):
        made[0].line = 5
    with pytest.raises(TypeError):
        make_lines({k: v for k, v in cols.items() if k != "naive_mm"})


def test_a_short_run_goes_line_by_line_and_is_parsed_once(monkeypatch):
    """Runs shorter than MIN_RUN_LINES go line by line, so a loop body's lines are parsed
    once and then run from their blocks: the lane is asked once per short run, not once per
    turn (an endless two-line loop took 36 s to its 250,000-turn limit, the fuzzer's
    timeout; the program is the same either way)."""
    calls = []
    real = fastlane.plain_run

    def counting(*a, **k):
        calls.append(a[1])
        return real(*a, **k)

    monkeypatch.setattr(interpret_module, "plain_run", counting)
    text = (
        "#1 = 0\no1 while [#1 LT 1000]\nG1 X1 F100\nG1 X0\n; back\n#1 = [#1 + 1]\no1 endwhile\nM2\n"
    )
    prog = interpret_text(text)
    assert len(prog.segments) == 2000 and prog.segments[-1].end_mm[0] == 0.0
    assert len(calls) <= len(text.splitlines())  # 1000 before: the plain run at every turn
    fast, slow = _both(lambda: interpret_text(text))
    assert fast == slow
