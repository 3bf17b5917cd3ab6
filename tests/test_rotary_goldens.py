"""LinuxCNC's moves for the rotary programs (tests/programs/rotary): the goldens' own checks.

These tests check that the goldens are well-formed and say what LinuxCNC's semantics say (G91
A steps add up, G20 leaves degrees alone, a G93 move takes 1/F minutes, a rotary-only move's
rate is the F word in degrees per minute), that LinuxCNC still says so (re-recorded live when
it is installed), and the differential: nurbscnc's segments are LinuxCNC's moves, six
coordinates and the feed semantics each (tests/linuxcnc_rotary.py), with the refusals at the
word's line and column.

The expected numbers come from the programs' text (F words, increments, formulas), not from
the goldens.
"""

from __future__ import annotations

import hashlib
import json
import math
import shutil
import subprocess
from pathlib import Path

import pytest
from click.testing import CliRunner

from nurbscnc.cli.main import main
from tests.linuxcnc_rotary import WRAPPED_AXES, block_line, compare_rotary, run_rotary

ROOT = Path(__file__).resolve().parents[1]
PROGRAMS = ROOT / "tests" / "programs" / "rotary"
GOLDENS = ROOT / "tests" / "golden" / "linuxcnc_rotary"
RECORDER = ROOT / "tools" / "record_goldens.py"
SYSTEM_PYTHON = "/usr/bin/python3"
RS274 = "/usr/bin/rs274"
NAMES = sorted(p.stem for p in PROGRAMS.glob("*.ngc"))
#: Doubles carried through LinuxCNC's inch conversion and back: a few ulps of 400 mm.
TOL_MM = 1e-12


def golden(name: str) -> dict:
    return json.loads((GOLDENS / f"{name}.json").read_text())


def motions(name: str) -> list[dict]:
    return [m for m in golden(name)["moves"] if m["kind"] not in ("spindle", "pause")]


def test_every_program_has_its_golden_recorded_from_its_text():
    assert len(NAMES) >= 10
    assert sorted(p.stem for p in GOLDENS.glob("*.json")) == NAMES
    for name in NAMES:
        digest = hashlib.sha256((PROGRAMS / f"{name}.ngc").read_bytes()).hexdigest()
        assert golden(name)["sha256"] == digest, name


@pytest.mark.parametrize("name", NAMES)
def test_golden_is_well_formed(name):
    g = golden(name)
    assert g["accepted"] == (not name.startswith("err_")), g["error"]
    if not g["accepted"]:
        assert g["moves"] == [] and g["error"]["line"] >= 1 and g["error"]["message"]
        return
    assert g["record"] == "gcode module, cross-checked with rs274"
    for m in motions(name):
        assert m["kind"] in ("traverse", "feed", "arc", "probe"), m
        assert len(m["end"]) == 6 and all(math.isfinite(v) for v in m["end"])
        if m["kind"] != "traverse":
            assert m["feed_mode"] in ("G93", "G94", "G95")
            assert m["feed_mm_s"] > 0 and m["feed_rate_prog_min"] > 0
            # The canon's rate per minute is in program units: mm (G21) or inch (G20).
            per_min = m["feed_mm_s"] * 60
            assert m["feed_rate_prog_min"] in (
                pytest.approx(per_min, rel=1e-12),
                pytest.approx(per_min / 25.4, rel=1e-12),
            )


def test_refusals_at_the_line_linuxcnc_names():
    assert golden("err_g93_no_f")["error"] == {
        "line": 6,
        "message": "F word missing with inverse time g1 move",
    }
    assert golden("err_two_a_words")["error"] == {
        "line": 4,
        "message": "Multiple a words on one line",
    }


def test_g91_a_steps_add_up():
    feeds = [m for m in motions("a_incremental") if m["kind"] == "feed"]
    steps = [45.0] * 8 + [-90.0]  # the program's G91 A words
    a_deg = [0.0] + [m["end"][3] for m in feeds]
    assert [b - a for a, b in zip(a_deg, a_deg[1:])] == pytest.approx(steps, abs=1e-12)
    assert feeds[-1]["end"][:3] == pytest.approx([5.0, 0.0, 5.0], abs=TOL_MM)


def test_g20_scales_lengths_not_degrees():
    feeds = [m for m in motions("g20_a") if m["kind"] == "feed"]
    # G20: X1, A90; A180; G91 X0.5 A-45; then G21 X10 A30.
    assert [m["end"][0] for m in feeds] == pytest.approx([25.4, 25.4, 38.1, 10.0], abs=TOL_MM)
    assert [m["end"][3] for m in feeds] == pytest.approx([90, 180, 135, 30], abs=1e-12)
    # F20 in G20 is 20 in/min along XYZ: 20 * 25.4 / 60 mm/s; the rotary-only A180 too.
    assert feeds[1]["feed_mm_s"] == pytest.approx(20 * 25.4 / 60, rel=1e-12)
    assert feeds[1]["feed_rate_prog_min"] == pytest.approx(20.0, rel=1e-12)


def test_g20_with_f_in_one_block_sets_f_before_the_switch():
    feeds = [m for m in motions("g20_f_same_block") if m["kind"] == "feed"]
    # "G20 G1 X1 A20 F10": F10 is taken in mm/min (G21 still), and stays 10 mm/min (0.39
    # in/min) after the switch; a rotary-only move then runs at 10 deg/min (FROM_PROG_ANG).
    assert [m["feed_mm_s"] for m in feeds] == pytest.approx([5.0] + [10 / 60] * 3, rel=1e-12)
    assert [m["feed_rate_prog_min"] for m in feeds] == [300.0, 10.0, 10.0, 10.0]
    assert [m["end"][0] for m in feeds] == pytest.approx([10, 25.4, 50.8, 50.8], abs=TOL_MM)
    assert [m["end"][3] for m in feeds] == [10.0, 20.0, 30.0, 40.0]


def _xyz_length_mm(p, q) -> float:
    return math.dist(p[:3], q[:3])


def test_g93_move_takes_one_over_f_minutes():
    moves = motions("g93_inverse_time")
    f_words = [6.0, 2.0, 0.5]  # lines 5, 6, 7
    g93 = [(k, m) for k, m in enumerate(moves) if m.get("feed_mode") == "G93"]
    assert len(g93) == 3
    for (k, m), f in zip(g93, f_words):
        start, end = moves[k - 1]["end"], m["end"]
        xyz_mm = _xyz_length_mm(start, end)
        if xyz_mm > 0:  # LinuxCNC: the time is along XYZ when XYZ move
            time_min = xyz_mm / (m["feed_mm_s"] * 60)
        else:  # rotary-only: the rate is in degrees per minute
            time_min = math.dist(start[3:], end[3:]) / m["feed_rate_prog_min"]
        assert time_min == pytest.approx(1.0 / f, rel=1e-12)
    assert moves[-1]["feed_mode"] == "G94" and moves[-1]["feed_rate_prog_min"] == 500.0


def test_rotary_only_rate_is_the_f_word_in_degrees_per_minute():
    feeds = [m for m in motions("rotary_only") if m["kind"] == "feed"]
    assert [m["feed_rate_prog_min"] for m in feeds] == [3600.0, 1800.0, 900.0]
    assert [m["end"][3:] for m in feeds] == [[90, 0, 0], [-90, 0, 0], [-90, 45, -45]]


def test_mixed_move_feed_is_along_xyz():
    feeds = [m for m in motions("mixed_xyz_a") if m["kind"] == "feed"]
    assert [m["feed_mm_s"] for m in feeds[1:]] == pytest.approx([400 / 60] * 3, rel=1e-12)
    assert [m["end"][3:5] for m in feeds] == [[0, 0], [90, 0], [180, 0], [180, 15]]


def test_g28_g30_move_only_the_named_axes_through_the_point():
    ends = [m["end"] for m in motions("g28_g30_rotary")]
    assert ends[1] == pytest.approx([10, 10, 5, 45, 30, 0], abs=TOL_MM)  # G28 A45: via 45
    assert ends[2] == pytest.approx([10, 10, 5, 0, 30, 0], abs=TOL_MM)  # then A home only
    assert ends[4] == pytest.approx([10, 10, 20, 120, 10, 0], abs=TOL_MM)  # G30 Z20 B10
    assert ends[5] == pytest.approx([10, 10, 0, 120, 0, 0], abs=TOL_MM)  # Z, B to #5183-
    assert ends[-1] == pytest.approx([0] * 6, abs=TOL_MM)  # G28: all home


def test_g10_g92_offsets_in_degrees():
    a_deg = [m["end"][3] for m in motions("offsets_g10_g92_a")]
    # G10 L2 P1 A30; G0 A0 → 30; G1 A90 → 120; G92 A0 there, G0 A45 → 165; G92.1,
    # G10 L20 P2 A10 (G55 A = 165 - 10), G55 A20 → 175; G20 A50 → 205 (degrees untouched);
    # G54 A0 → 30.
    assert a_deg == pytest.approx([0, 30, 120, 165, 175, 205, 30], abs=1e-12)


def test_arcs_carry_a_linearly_to_its_end():
    arcs = [m for m in motions("arc_with_a") if m["kind"] == "arc"]
    assert [m["end"][3] for m in arcs] == pytest.approx([90, 180, 270, 300], abs=1e-12)
    assert [m["rotation"] for m in arcs] == [1, 1, -2, -1]  # P2: one extra full turn
    full = [m for m in motions("arc_full_circle_a") if m["kind"] == "arc"]
    assert full[0]["end"] == pytest.approx([10, 0, 0, 90, 0, 0], abs=TOL_MM)


def test_wrapped_engraving_angles():
    moves = motions("wrapped_engraving")
    # 10 mm around a 10 mm radius: 10 * 180 / (pi * 10) degrees.
    assert moves[3]["end"][3] == pytest.approx(10 * 180 / (math.pi * 10), rel=1e-14)
    wave = [m for m in moves if m["line"] == 18]
    assert [m["end"][3] for m in wave] == pytest.approx([10.0 * i for i in range(1, 37)])
    assert [m["end"][0] for m in wave] == pytest.approx([12 + 0.5 * i for i in range(1, 37)])


def test_b_indexer_steps_a_quarter_turn():
    index = [m["end"][4] for m in motions("b_indexer") if m["line"] == 9]
    assert index == [90.0, 180.0, 270.0, 360.0]


# -- the differential: nurbscnc makes LinuxCNC's moves, six coordinates each -----------------

ACCEPTED = [n for n in NAMES if golden(n)["accepted"] and n != "probe_with_a"]


@pytest.mark.parametrize("name", ACCEPTED)
def test_nurbscnc_makes_linuxcncs_moves(name):
    compare_rotary(golden(name), run_rotary(PROGRAMS / f"{name}.ngc"))


def test_every_accepted_program_is_compared():
    # probe_with_a: LinuxCNC accepts G38.2 with A; nurbscnc runs no probes (refused below).
    assert sorted([*ACCEPTED, "probe_with_a"]) == sorted(n for n in NAMES if golden(n)["accepted"])
    assert len(ACCEPTED) >= 12


@pytest.mark.parametrize(
    "name, index, change",
    [
        ("abc_absolute", 3, lambda m: m["end"].__setitem__(0, m["end"][0] + 2e-9)),
        ("abc_absolute", 3, lambda m: m["end"].__setitem__(3, m["end"][3] + 2e-9)),
        ("rotary_only", 2, lambda m: m["end"].__setitem__(5, m["end"][5] - 2e-9)),
        ("mixed_xyz_a", 1, lambda m: m.__setitem__("feed_mm_s", m["feed_mm_s"] * (1 + 1e-10))),
        ("rotary_only", 1, lambda m: m.__setitem__("feed_rate_prog_min", 3600.0 * (1 + 1e-10))),
        ("abc_absolute", 1, lambda m: m.__setitem__("kind", "feed")),
        ("mixed_xyz_a", 1, lambda m: m.__setitem__("line", 6)),
        ("g93_inverse_time", 2, lambda m: m["end"].__setitem__(0, 10.0 + 2e-7)),
    ],
    ids=["x", "a", "c", "feed", "deg/min", "kind", "line", "x-of-a-rotate"],
)
def test_the_differential_catches_a_small_difference(name, index, change):
    """It fails on a 2e-9 change of one coordinate (A B C included), a feed off by 1e-10,
    a rapid read as a feed, a line number: it is not a test that cannot fail."""
    g = golden(name)
    program = run_rotary(PROGRAMS / f"{name}.ngc")
    compare_rotary(g, program)  # agrees as recorded
    moves = [m for m in g["moves"] if m["kind"] != "spindle"]
    change(moves[index])
    with pytest.raises(AssertionError):
        compare_rotary(g, program)


def test_g93_move_takes_its_inverse_time():
    """Each G93 move's time, its length over its rate, is 1/F minutes (F from the text):
    along XYZ when XYZ move, along √(ΔA²+ΔB²+ΔC²) degrees when only A B C turn."""
    program = run_rotary(PROGRAMS / "g93_inverse_time.ngc")
    moves = {s.line: s for s in program.segments if s.line in (5, 6, 7)}
    for line, f_per_min in ((5, 6.0), (6, 2.0), (7, 0.5)):
        seg = moves[line]
        if seg.kind == "rotate":
            time_s = math.dist(seg.abc_start_deg, seg.abc_end_deg) / seg.feed_deg_s
        else:
            time_s = seg.length_mm / seg.feed_mm_s
        assert time_s == pytest.approx(60.0 / f_per_min, rel=1e-14), line
    assert [moves[n].kind for n in (5, 6, 7)] == ["line", "rotate", "line"]


def test_rotary_only_feed_is_f_in_degrees_per_minute():
    program = run_rotary(PROGRAMS / "rotary_only.ngc")
    rotates = [s for s in program.segments if s.kind == "rotate"]
    # F3600, F1800, F900 deg/min; the G0 at the axes' own rate (0 here).
    assert [s.feed_deg_s for s in rotates] == [60.0, 30.0, 15.0, 0.0]
    assert [s.rapid for s in rotates] == [False, False, False, True]
    assert all(s.position_mm == (0.0, 0.0, 5.0) for s in rotates)
    assert program.rotary_axes == ("a", "b", "c")


def test_g20_with_f_in_one_block_runs_the_next_rotary_move_at_f_deg_min():
    program = run_rotary(PROGRAMS / "g20_f_same_block.ngc")
    last = program.segments[-1]
    # "G20 G1 X1 A20 F10" took F10 before the switch: 10 mm/min along XYZ, 10 deg/min for A.
    assert last.kind == "rotate" and last.feed_deg_s == 10.0 / 60.0
    assert [s.feed_mm_s for s in program.segments[2:4]] == [10.0 / 60.0] * 2


# -- refusals at the word's line and column (exit 2) -------------------------------------------


def _refusal(path: Path, *args: str):
    res = CliRunner().invoke(main, ["check", *args, str(path)])
    assert res.exit_code == 2, res.output
    return res.stderr


def _profile(tmp_path: Path, tables: str) -> Path:
    """The bundled profile with rotary ``tables`` appended (a machine with those axes)."""
    from nurbscnc.machine.discovery import default_profile_text

    path = tmp_path / "rotary.toml"
    path.write_text(default_profile_text() + "\n" + tables)
    return path


A_TABLE = "[axis_limits.a]\nv_max_deg_min = 3600.0\na_max_deg_s2 = 400.0\nj_max_deg_s3 = 4e3\n"


@pytest.mark.parametrize(
    "name, line, col",
    [("err_g93_no_f", 6, 1), ("err_two_a_words", 4, 11)],
)
def test_refused_where_linuxcnc_refuses(name, line, col, tmp_path):
    assert golden(name)["error"]["line"] == line
    path = PROGRAMS / f"{name}.ngc"
    text = _refusal(path, "--machine", str(_profile(tmp_path, A_TABLE)))
    assert f"{path}:{line}:{col}: error: " in text, text


@pytest.mark.parametrize(
    "name, line, col, letter",
    [("abc_absolute", 4, 4, "A"), ("b_indexer", 9, 6, "B"), ("mixed_xyz_a", 7, 12, "B")],
)
def test_a_machine_without_the_axis_refuses_its_word(name, line, col, letter, tmp_path):
    """The bundled profile has no rotary axis; one with A alone refuses the first B word."""
    path = PROGRAMS / f"{name}.ngc"
    args = [] if letter == "A" else ["--machine", str(_profile(tmp_path, A_TABLE))]
    text = _refusal(path, *args)
    want = f"{path}:{line}:{col}: error: the machine has no {letter} axis ("
    assert want in text and f"has no [axis_limits.{letter.lower()}])" in text, text
    source = path.read_text().splitlines()[line - 1]
    assert source in text and " " * (col - 1 + 4) + "^" in text  # the line and its caret


def test_a_word_that_keeps_a_missing_axis_is_carried():
    """``A0`` from a 3-axis post, at A = 0: accepted, the segments carry no rotary axis."""
    from nurbscnc.program.interpret import interpret_text

    program = interpret_text("G0 X1 A0\nG1 X2 Y1 A0. F100\nG91 G1 X1 A0\nM2\n")
    assert [s.end_mm for s in program.segments] == [(1, 0, 0), (2, 1, 0), (3, 1, 0)]
    assert all(s.abc_deg is None for s in program.segments) and program.rotary_axes == ()


def test_check_refuses_the_rotary_probe_for_the_probe(tmp_path):
    path = PROGRAMS / "probe_with_a.ngc"
    text = _refusal(path, "--machine", str(_profile(tmp_path, A_TABLE)))
    assert f"{path}:4:1: error: G38.2" in text


# -- live: LinuxCNC says the same now ----------------------------------------------------------


def _linuxcnc_missing() -> str | None:
    if not Path(RS274).exists():
        return f"LinuxCNC is not installed ({RS274} is missing)"
    if shutil.which(SYSTEM_PYTHON) is None:
        return f"{SYSTEM_PYTHON} is missing"
    probe = subprocess.run([SYSTEM_PYTHON, "-c", "import gcode"], capture_output=True)
    if probe.returncode != 0:
        return f"{SYSTEM_PYTHON} cannot import LinuxCNC's gcode module"
    return None


@pytest.mark.parametrize("name", NAMES)
def test_goldens_are_what_linuxcnc_says_now(name, tmp_path):
    missing = _linuxcnc_missing()
    if missing:
        pytest.skip(missing)
    out = tmp_path / f"{name}.json"
    cmd = [SYSTEM_PYTHON, str(RECORDER), "--rotary", "--stdout", str(PROGRAMS / f"{name}.ngc")]
    res = subprocess.run([*cmd, "--json-out", str(out)], capture_output=True, timeout=300)
    assert res.returncode == 0 and out.exists(), res.stderr[-2000:]
    now, recorded = json.loads(out.read_text()), golden(name)
    if now["accepted"] and name != "probe_with_a":  # the live differential
        compare_rotary(now, run_rotary(PROGRAMS / f"{name}.ngc"))
    assert now["accepted"] == recorded["accepted"] and now["error"] == recorded["error"]
    assert len(now["moves"]) == len(recorded["moves"])
    for a, b in zip(now["moves"], recorded["moves"]):
        assert a.keys() == b.keys()
        for key in a:
            if isinstance(a[key], list):
                assert a[key] == pytest.approx(b[key], abs=1e-9), (key, a, b)
            elif isinstance(a[key], float):
                assert a[key] == pytest.approx(b[key], rel=1e-12), (key, a, b)
            else:
                assert a[key] == b[key], (key, a, b)


# -- wrapped rotary A ([AXIS_A]WRAPPED_ROTARY, rs274 -i only) ----------------------------------

WRAPPED = PROGRAMS / "wrapped"
WRAPPED_GOLDENS = GOLDENS / "wrapped"
WRAPPED_NAMES = sorted(p.stem for p in WRAPPED.glob("*.ngc"))


def wrapped_golden(name: str) -> dict:
    return json.loads((WRAPPED_GOLDENS / f"{name}.json").read_text())


def _unwrap_deg(word: str, current_deg: float) -> float:
    """docs/rotary.md's rule for a G90 word on a wrapped axis: |word| in the current turn,
    then one turn on in the word's sign's direction if it lies behind (the sign of "-0" too)."""
    target = abs(float(word)) + 360.0 * math.floor(current_deg / 360.0)
    if not word.startswith("-") and target < current_deg:
        target += 360.0
    if word.startswith("-") and target > current_deg:
        target -= 360.0
    return target


def test_wrapped_goldens_exist_for_every_program():
    assert sorted(p.stem for p in WRAPPED_GOLDENS.glob("*.json")) == WRAPPED_NAMES
    for name in WRAPPED_NAMES:
        digest = hashlib.sha256((WRAPPED / f"{name}.ngc").read_bytes()).hexdigest()
        assert wrapped_golden(name)["sha256"] == digest, name


def test_wrapped_a_follows_the_sign_rule():
    a_deg = [m["end"][3] for m in wrapped_golden("wrapped_a")["moves"]]
    expected, current = [], 0.0
    for word in ["350", "10", "-350", "-0", "0"]:  # the program's G90 A words, in order
        current = _unwrap_deg(word, current)
        expected.append(current)
    current += 400.0  # G91 A400: incremental moves are not wrapped
    expected.append(current)
    for word in ["90", "-80", "-270"]:
        current = _unwrap_deg(word, current)
        expected.append(current)
    expected.append(current)  # G0 B400: B is not wrapped, A stays
    assert a_deg == expected == [350, 370, 350, 0, 0, 400, 450, 440, 270, 270]
    assert wrapped_golden("wrapped_a")["moves"][-1]["end"][4] == 400.0


def test_wrapped_refusals():
    for name, block in (("err_wrapped_360", "G0 A360"), ("err_wrapped_g92", "G92 A400")):
        g = wrapped_golden(name)
        value = block.split("A")[1]
        message = f"Invalid absolute position {float(value):.2f} for wrapped rotary axis A"
        assert not g["accepted"] and g["error"] == {"message": message, "block": block}


@pytest.mark.parametrize("name", WRAPPED_NAMES)
def test_wrapped_goldens_are_what_rs274_says_now(name, tmp_path):
    missing = _linuxcnc_missing()
    if missing:
        pytest.skip(missing)
    cmd = [SYSTEM_PYTHON, str(RECORDER), "--wrapped-ini", str(WRAPPED / "wrapped.ini")]
    cmd += ["--programs", str(WRAPPED), "--goldens", str(tmp_path)]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    now = json.loads((tmp_path / f"{name}.json").read_text())
    assert now == wrapped_golden(name)
    if now["accepted"]:  # the live differential
        compare_rotary(now, run_rotary(WRAPPED / f"{name}.ngc", WRAPPED_AXES))


@pytest.mark.parametrize("name", ["wrapped_a", "wrapped_offsets"])
def test_nurbscnc_makes_the_wrapped_moves(name):
    """The wrapped axis A of wrapped.ini (B, C not wrapped), to rs274's printed precision."""
    program = run_rotary(WRAPPED / f"{name}.ngc", WRAPPED_AXES)
    compare_rotary(wrapped_golden(name), program)


def test_a_machine_whose_a_is_not_wrapped_goes_elsewhere():
    # The same program on a machine whose A is not wrapped goes elsewhere (A10 is 10).
    plain = run_rotary(WRAPPED / "wrapped_a.ngc")
    with pytest.raises(AssertionError):
        compare_rotary(wrapped_golden("wrapped_a"), plain)


@pytest.mark.parametrize("name", ["err_wrapped_360", "err_wrapped_g92"])
def test_wrapped_refusals_are_linuxcncs(name):
    """LinuxCNC's message, at the block rs274 names, at its A word; the moves before it."""
    from nurbscnc.errors import ProgramError

    g = wrapped_golden(name)
    path = WRAPPED / f"{name}.ngc"
    with pytest.raises(ProgramError) as info:
        run_rotary(path, WRAPPED_AXES)
    line = block_line(path, g["error"]["block"])
    assert info.value.message == g["error"]["message"]
    assert (info.value.pos.line, info.value.pos.column) == (
        line,
        g["error"]["block"].index("A") + 1,
    )
    # Up to the refused line the moves are LinuxCNC's.
    before = (WRAPPED / f"{name}.ngc").read_text().splitlines()[: line - 1]
    from nurbscnc.program.interpret import InterpretOptions, interpret_text

    program = interpret_text("\n".join(before), InterpretOptions(rotary_axes=WRAPPED_AXES))
    compare_rotary(g, program)
