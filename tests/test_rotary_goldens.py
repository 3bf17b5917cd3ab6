"""LinuxCNC's moves for the rotary programs (tests/programs/rotary): the goldens' own checks.

nurbscnc does not run rotary programs yet (docs/rotary.md plans it). These tests check that
the goldens the later work will be compared with are well-formed and say what LinuxCNC's
semantics say (G91 A steps add up, G20 leaves degrees alone, a G93 move takes 1/F minutes,
a rotary-only move's rate is the F word in degrees per minute), that LinuxCNC still says so
(re-recorded live when it is installed), and pin today's refusal: ``nurbscnc check`` stops
each program with exit 2 at its first rotary word that moves an axis.

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


# -- today's behaviour: nurbscnc refuses rotary motion ---------------------------------------

ROTARY = "rotary axis motion is not supported "
#: The first rotary word that moves an axis (nurbscnc accepts A0 at A0), read off each
#: program: (line, column, message); err_two_a_words is refused for the repeated word first
#: (LinuxCNC too), probe_with_a for G38.2.
REFUSED_AT = {
    "a_incremental": (5, 4, ROTARY + "(A45: A is at 0)"),
    "abc_absolute": (4, 4, ROTARY + "(A45: A is at 0)"),
    "arc_full_circle_a": (4, 12, ROTARY + "(A90: A is at 0)"),
    "arc_with_a": (5, 20, ROTARY + "(A90: A is at 0)"),
    "b_indexer": (9, 6, ROTARY + "(B90: B is at 0)"),
    "err_g93_no_f": (5, 4, ROTARY + "(A90: A is at 0)"),
    "err_two_a_words": (4, 11, "A word repeated in the block"),  # as LinuxCNC
    "g20_f_same_block": (4, 8, ROTARY + "(A10: A is at 0)"),
    "g20_a": (6, 7, ROTARY + "(A90: A is at 0)"),
    "g28_g30_rotary": (3, 15, ROTARY + "(A90: A is at 0)"),
    "g93_inverse_time": (5, 8, ROTARY + "(A90: A is at 0)"),
    "mixed_xyz_a": (5, 8, ROTARY + "(A90: A is at 0)"),
    "offsets_g10_g92_a": (4, 11, ROTARY + "(A30: A is at 0)"),
    "rotary_only": (4, 4, ROTARY + "(A90: A is at 0)"),
    "wrapped_engraving": (9, 7, ROTARY + "(A57.2958: A is at 0)"),
}


def test_every_program_has_an_expected_refusal():
    assert sorted([*REFUSED_AT, "probe_with_a"]) == NAMES


@pytest.mark.parametrize("name", sorted(REFUSED_AT))
def test_check_refuses_rotary_motion_today(name):
    line, col, message = REFUSED_AT[name]
    path = PROGRAMS / f"{name}.ngc"
    res = CliRunner().invoke(main, ["check", str(path)])
    assert res.exit_code == 2, res.output
    text = res.stderr
    assert f"{path}:{line}:{col}: error: {message}\n" in text, text
    source = path.read_text().splitlines()[line - 1]
    assert source in text and " " * (col - 1 + 4) + "^" in text  # the line and its caret


def test_check_refuses_the_rotary_probe_for_the_probe():
    path = PROGRAMS / "probe_with_a.ngc"
    res = CliRunner().invoke(main, ["check", str(path)])
    assert res.exit_code == 2
    assert f"{path}:4:1: error: G38.2" in res.stderr


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
    assert json.loads((tmp_path / f"{name}.json").read_text()) == wrapped_golden(name)
