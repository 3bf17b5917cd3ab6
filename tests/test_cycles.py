"""Canned cycles (nurbscnc.program.cycles) against LinuxCNC 2.9, move by move.

The programs ``tests/programs/cycles/*.ngc`` exercise every cycle code, G98/G99, G90/G91, L
repeats, sticky words, the three planes, inch, the initial level below R, and LinuxCNC's
errors; their goldens ``tests/golden/linuxcnc_cycles/`` are LinuxCNC's canonical moves and
spindle events (``make goldens``). A small driver here plays the role the interpreter will:
it reads those (deliberately plain) programs, keeps the modal state and calls
:func:`expand_cycle` for each cycle block. Positions and feeds agree to 1e-9 mm, errors word
for word.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from nurbscnc.errors import ProgramError
from nurbscnc.program.cycles import CODES, CycleState, expand_cycle

ROOT = Path(__file__).resolve().parents[1]
PROGRAMS = ROOT / "tests" / "programs" / "cycles"
GOLDENS = ROOT / "tests" / "golden" / "linuxcnc_cycles"
WORD = re.compile(r"([A-Z@^])\s*([-+]?\d*\.?\d+)")
TOL_MM = 1e-9


def drive(text: str) -> list[dict]:
    """Moves of a plain cycle program, as golden-like dicts; ProgramError gets ``.line``."""
    pos, plane, incremental, retract = [0.0, 0.0, 0.0], "XY", False, "G99"
    scale, feed_mm_s, spindle, motion = 1.0, 0.0, "off", None
    state = CycleState()
    out = []
    for line_no, raw in enumerate(text.splitlines(), 1):
        words = [(k, float(v)) for k, v in WORD.findall(raw.upper())]
        gcodes = [v for k, v in words if k == "G"]
        mcodes = [v for k, v in words if k == "M"]
        axis = {k: v for k, v in words if k not in "GMFS"}
        for k, v in words:
            # LinuxCNC sets the feed before it changes units: "G20 F10" is 10 mm/min when
            # the block starts in mm (the canon keeps the feed as a length per minute).
            if k == "F":
                feed_mm_s = v * scale / 60.0
        for g in gcodes:
            plane = {17: "XY", 18: "ZX", 19: "YZ"}.get(g, plane)
            incremental = {90: False, 91: True}.get(g, incremental)
            retract = {98: "G98", 99: "G99"}.get(g, retract)
            scale = {20: 25.4, 21: 1.0}.get(g, scale)
            if g in (0, 80) or f"G{g:g}" in CODES:
                motion = f"G{g:g}"
        for m in mcodes:
            if m in (3, 4):
                spindle = "cw" if m == 3 else "ccw"
                out.append({"kind": "spindle", "code": f"spindle-{spindle}"})
        if motion == "G0" and axis:
            for i, letter in enumerate("XYZ"):
                if letter in axis:
                    pos[i] = axis[letter] * scale
            out.append({"kind": "traverse", "line": line_no, "end": list(pos)})
            state = CycleState()  # any other motion forgets the initial level
        elif motion == "G80":
            state = CycleState()
        elif motion in CODES and axis:
            cycle_words = {k: (v if k in "PL^" else v * scale) for k, v in axis.items()}
            try:
                res = expand_cycle(
                    motion,
                    cycle_words,
                    incremental=incremental,
                    position_mm=tuple(pos),
                    plane=plane,
                    retract=retract,
                    feed_mm_s=feed_mm_s,
                    state=state,
                    spindle=spindle,
                )
            except ProgramError as exc:
                exc.line = line_no
                raise
            state, pos = res.state, list(res.position_mm)
            for m in res.moves:
                if m.kind in ("rapid", "feed"):
                    move = {
                        "kind": {"rapid": "traverse"}.get(m.kind, m.kind),
                        "line": line_no,
                        "end": list(m.end_mm),
                    }
                    if m.kind == "feed":
                        move["feed_mm_s"] = m.feed_mm_s
                elif m.kind == "dwell":
                    move = {"kind": "dwell", "line": line_no, "seconds": m.dwell_s}
                elif m.kind == "pause":
                    move = {"kind": "pause", "code": "M0"}
                else:
                    move = {"kind": "spindle", "code": m.kind}
                out.append(move)
        for m in mcodes:
            if m in (2, 5, 30):
                spindle = "off"
                out.append({"kind": "spindle", "code": "spindle-stop"})
    return out


def _golden(name: str) -> dict:
    return json.loads((GOLDENS / f"{name}.json").read_text())


NAMES = sorted(p.stem for p in PROGRAMS.glob("*.ngc"))


def test_every_cycle_program_has_a_golden():
    assert NAMES and NAMES == sorted(p.stem for p in GOLDENS.glob("*.json"))
    assert {c for c in CODES} <= {
        f"G{g}" for n in NAMES for g in re.findall(r"G(\d+)", (PROGRAMS / f"{n}.ngc").read_text())
    }


def assert_same_moves(got: list[dict], want: list[dict], lines: bool = True) -> None:
    assert [m["kind"] for m in got] == [m["kind"] for m in want]
    for i, (g, w) in enumerate(zip(got, want)):
        where = f"move {i}: {w}"
        if "end" in w:
            assert np.allclose(g["end"][:3], w["end"][:3], atol=TOL_MM, rtol=0), f"{where} got {g}"
        if "code" in w:
            assert g["code"] == w["code"], where
        if "feed_mm_s" in w:
            assert abs(g["feed_mm_s"] - w["feed_mm_s"]) <= TOL_MM, where
        if "seconds" in w:
            assert abs(g["seconds"] - w["seconds"]) <= 1e-12, where
        if lines and w.get("line") is not None:
            assert g["line"] == w["line"], where


@pytest.mark.parametrize("name", [n for n in NAMES if not n.startswith("err_")])
def test_cycle_moves_match_linuxcnc(name):
    golden = _golden(name)
    assert golden["accepted"] and golden["tolerance_mm"] == 1e-9, golden["record"]
    assert_same_moves(drive((PROGRAMS / f"{name}.ngc").read_text()), golden["moves"])


@pytest.mark.parametrize("name", [n for n in NAMES if n.startswith("err_")])
def test_cycle_errors_match_linuxcnc(name):
    golden = _golden(name)
    assert not golden["accepted"]
    with pytest.raises(ProgramError) as info:
        drive((PROGRAMS / f"{name}.ngc").read_text())
    assert info.value.message == golden["error"]["message"]
    assert info.value.line == golden["error"]["line"]


@pytest.mark.parametrize(
    "incremental, absolute",
    [("g81_g99_inc_l", "g81_g99_abs_l")],
)
def test_g91_form_equals_g90_form(incremental, absolute):
    """The same holes programmed with G91 and L, and with G90 one by one: the same moves
    (for LinuxCNC, and for nurbscnc)."""
    inc = drive((PROGRAMS / f"{incremental}.ngc").read_text())
    ab = drive((PROGRAMS / f"{absolute}.ngc").read_text())
    assert_same_moves(inc, ab, lines=False)
    assert_same_moves(_golden(incremental)["moves"], _golden(absolute)["moves"], lines=False)


def test_state_is_sticky_and_initial_level_kept():
    """A second G81 block keeps R, Z and the initial level; a fresh state forgets them."""
    first = expand_cycle(
        "G81",
        {"X": 1.0, "Y": 1.0, "Z": -1.0, "R": 2.0},
        incremental=False,
        position_mm=(0.0, 0.0, 9.0),
        plane="XY",
        retract="G98",
        feed_mm_s=5.0,
        state=CycleState(),
    )
    assert first.state.initial_level_mm == 9.0 and first.position_mm == (1.0, 1.0, 9.0)
    second = expand_cycle(
        "G81",
        {"X": 3.0},
        incremental=False,
        position_mm=first.position_mm,
        plane="XY",
        retract="G98",
        feed_mm_s=5.0,
        state=first.state,
    )
    assert [m.end_mm for m in second.moves] == [
        (3.0, 1.0, 9.0),
        (3.0, 1.0, 2.0),
        (3.0, 1.0, -1.0),
        (3.0, 1.0, 9.0),
    ]
    with pytest.raises(ProgramError, match="R clearance plane unspecified"):
        expand_cycle(
            "G81",
            {"X": 3.0},
            incremental=False,
            position_mm=first.position_mm,
            plane="XY",
            retract="G98",
            feed_mm_s=5.0,
            state=CycleState(),
        )


@pytest.mark.parametrize("plane", ["ZX", "YZ"])
@pytest.mark.parametrize("code", ["G74", "G84"])
def test_tapping_outside_xy_is_refused(code, plane):
    """LinuxCNC 2.9 taps to interchanged coordinates in G18/G19: refused, not copied."""
    with pytest.raises(ProgramError, match="only supported in the XY plane"):
        expand_cycle(
            code,
            {"X": 1.0, "Y": 1.0, "Z": -1.0, "R": 2.0},
            incremental=False,
            position_mm=(0.0, 0.0, 5.0),
            plane=plane,
            retract="G98",
            feed_mm_s=5.0,
            state=CycleState(),
            spindle="cw",
        )
