"""nurbscnc's segments against LinuxCNC 2.9's canonical moves, move by move.

Programs and goldens live in tests/golden/interp_linuxcnc/: ``name.ngc`` and ``name.json``,
the moves LinuxCNC's own interpreter made (its ``gcode`` Python module, full precision,
recorded by tests/linuxcnc_canon.py and converted to machine mm there). The goldens are
committed, so the comparison runs without LinuxCNC; ``test_live_*`` re-records each program
with the installed LinuxCNC and skips, saying why, when it is not installed.

Compared: the kind and source line of every move; end points and arc centres to 1e-9 mm;
arc direction and turn count; feeds [mm/min] to 1e-9 relative in units-per-minute mode (under
G93 and G95 LinuxCNC passes F through as given; tests/test_interpret_control.py checks the
conversions); dwell times. LinuxCNC emits moves that go nowhere
(nurbscnc drops them) and no canon call for M0/M1/M60 (nurbscnc's Pause segments): both
are skipped.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from nurbscnc.geometry.segments import Pause
from nurbscnc.program.interpret import InterpretOptions, interpret_text
from nurbscnc.program.tooltable import Tool

HERE = Path(__file__).resolve().parent
GOLDEN = HERE / "golden" / "interp_linuxcnc"
PROGRAMS = sorted(p for p in GOLDEN.glob("*.ngc") if p.stem != "splines")
SPLINES = GOLDEN / "splines.ngc"
RECORDER = HERE / "linuxcnc_canon.py"
SYSTEM_PYTHON = "/usr/bin/python3"
TOOLS = {1: Tool(1, (0.0, 0.0, 5.0), 6.0), 2: Tool(2, (0.0, 0.0, 3.0), 4.0)}
TOL_MM = 1e-9


def ours(path: Path):
    return interpret_text(path.read_text(), InterpretOptions(tools=TOOLS, name=path.name))


def linuxcnc_moves(data: dict) -> list[dict]:
    """LinuxCNC's moves without those that go nowhere (start = end, no arc)."""
    pos = [0.0, 0.0, 0.0]
    moves = []
    for move in data["moves"]:
        if move["kind"] in ("line", "rapid"):
            if np.allclose(move["end"], pos, rtol=0, atol=1e-12):
                continue
            pos = move["end"]
        elif move["kind"] == "arc":
            pos = move["end"]
        moves.append(move)
    return moves


def units_per_minute_lines(text: str) -> dict[int, bool]:
    """line → G94 in force there (the test programs switch feed modes on plain lines)."""
    mode, out = "G94", {}
    for number, line in enumerate(text.splitlines(), 1):
        found = re.findall(r"G9[345](?![0-9.])", line.upper())
        if found:
            mode = found[-1]
        out[number] = mode == "G94"
    return out


def compare(path: Path, data: dict) -> None:
    assert data["error"] is None, data["error"]
    prog = ours(path)
    # Pauses and the stops of M64, M65, M66, M68 (0 s dwells: the machine waits for the
    # motion to end there) have no canonical move.
    segments = [
        s for s in prog.segments if not isinstance(s, Pause) and getattr(s, "code", "G4") == "G4"
    ]
    theirs = linuxcnc_moves(data)
    assert [(s.kind, s.line) for s in segments] == [(m["kind"], m["line"]) for m in theirs]
    per_minute = units_per_minute_lines(path.read_text())
    for seg, move in zip(segments, theirs):
        where = f"{path.name}:{seg.line} {seg.kind}"
        if seg.kind == "dwell":
            assert seg.seconds == pytest.approx(move["seconds"], rel=1e-12), where
            continue
        np.testing.assert_allclose(seg.end_mm, move["end"], rtol=0, atol=TOL_MM, err_msg=where)
        if seg.kind == "arc":
            # Centres compared in the arc's plane: LinuxCNC's canon call gives the centre at
            # the end's height along the normal, nurbscnc at the start's.
            diff = np.subtract(seg.center_mm, move["center"])
            diff -= np.dot(diff, seg.normal) * np.asarray(seg.normal)
            np.testing.assert_allclose(diff, 0.0, rtol=0, atol=TOL_MM, err_msg=where)
            turns = math.ceil(abs(seg.angle_rad) / (2 * math.pi) - 1e-9)
            assert math.copysign(turns, seg.angle_rad) == move["turn"], where
        if seg.kind in ("line", "arc") and per_minute[seg.line]:
            assert seg.feed_mm_s * 60.0 == pytest.approx(move["feed_mm_min"], rel=1e-9), where


@pytest.mark.parametrize("path", PROGRAMS, ids=[p.stem for p in PROGRAMS])
def test_golden(path):
    compare(path, json.loads(path.with_suffix(".json").read_text()))


def _linuxcnc_missing() -> str | None:
    if not os.path.exists(SYSTEM_PYTHON):
        return f"{SYSTEM_PYTHON} is absent"
    probe = subprocess.run([SYSTEM_PYTHON, "-c", "import gcode"], capture_output=True)
    if probe.returncode != 0:
        return "LinuxCNC's gcode module is not installed (apt-get install linuxcnc-uspace)"
    return None


@pytest.mark.parametrize("path", PROGRAMS, ids=[p.stem for p in PROGRAMS])
def test_live(path, tmp_path):
    why = _linuxcnc_missing()
    if why:
        pytest.skip(f"live LinuxCNC comparison skipped: {why}")
    # LinuxCNC reads and rewrites rs274ngc.var in its working folder: a fresh copy of the
    # committed one in a temporary folder, so every run starts alike and the repo is not
    # touched.
    shutil.copy(path.parent / "rs274ngc.var", tmp_path / "rs274ngc.var")
    out = subprocess.run(
        [SYSTEM_PYTHON, str(RECORDER), str(path.resolve())],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        check=True,
    )
    compare(path, json.loads(out.stdout))


def test_splines_are_linuxcnc_curves():
    """G5 / G5.1: LinuxCNC samples each spline into N lines at the Bezier parameters k/N;
    nurbscnc's exact NURBS (knots [0…0, 1…1], so u is the Bezier t) must pass through every
    one of those points to 1e-9 mm."""
    from nurbscnc.geometry.nurbs import NurbsCurve

    data = json.loads(SPLINES.with_suffix(".json").read_text())
    assert data["error"] is None
    prog = ours(SPLINES)
    curves = {s.line: s for s in prog.segments if s.kind == "nurbs"}
    assert sorted(curves) == [4, 5, 6]
    for line, seg in curves.items():
        points = np.array([m["end"] for m in data["moves"] if m["line"] == line])
        u = np.arange(1, len(points) + 1) / len(points)
        ours_at_u = NurbsCurve.from_segment(seg).point(u)
        np.testing.assert_allclose(ours_at_u, points, rtol=0, atol=TOL_MM, err_msg=str(line))


# -- tool length offsets, against rs274 (the gcode module has no tool table) ------------------
RS274 = HERE / "golden" / "interp_rs274"


def _rs274_tools() -> dict:
    """The tool table of interp_rs274/tools.tbl: inches there (rs274's unit), mm here."""
    from nurbscnc.program.tooltable import parse_tool_table

    table = parse_tool_table((RS274 / "tools.tbl").read_text())
    return {
        n: Tool(n, tuple(v * 25.4 for v in t.offset_mm), t.diameter_mm * 25.4)
        for n, t in table.items()
    }


def compare_rs274(data: dict) -> None:
    assert data["error"] is None, data["error"]
    prog = interpret_text((RS274 / "tools.ngc").read_text(), InterpretOptions(tools=_rs274_tools()))
    assert [s.kind for s in prog.segments] == [m["kind"] for m in data["moves"]]
    for seg, move in zip(prog.segments, data["moves"]):
        if move["kind"] == "pause":
            assert seg.code == move["code"]
            continue
        # rs274 prints 4 decimals of mm: half a unit of the last digit
        np.testing.assert_allclose(seg.end_mm, move["end"], rtol=0, atol=5e-5, err_msg=seg.line)


def test_tool_offsets_golden():
    compare_rs274(json.loads((RS274 / "tools.json").read_text()))


def test_tool_offsets_live():
    import shutil

    if shutil.which("rs274") is None:
        pytest.skip("live rs274 comparison skipped: LinuxCNC's rs274 is not installed")
    import sys

    sys.path.insert(0, str(HERE))
    try:
        import linuxcnc_canon
    finally:
        sys.path.remove(str(HERE))
    compare_rs274(linuxcnc_canon.record_rs274(RS274 / "tools.ngc", RS274 / "tools.tbl"))
