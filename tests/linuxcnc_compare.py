"""Compare nurbscnc's segments with LinuxCNC's canonical moves (a golden of
``tools/record_goldens.py``), move by move.

Used by ``test_linuxcnc_goldens.py`` (committed goldens) and ``test_linuxcnc_live.py`` (LinuxCNC
run on the fly). A golden move is compared with the segment at the same place, after dropping
what has no geometry on either side:

* zero-length straight moves (LinuxCNC emits a canonical call for ``G1 X0`` at X0; nurbscnc
  makes no segment) — a decision: a move that goes nowhere has nothing to compare. "Zero" is
  shorter than ``ZERO_MOVE_MM`` (1e-9 mm, the comparison tolerance) on every axis: LinuxCNC's
  program → machine round trip makes 1e-14 mm "moves" where it rounds (a ``G53`` move under a
  rotated G5x system, ``Z2`` repeated just after a ``G55`` switch: interp/g10-l11,
  camotics/botomata_bottom), which nurbscnc, keeping the machine where it is, does not make;
* LinuxCNC's spindle events (``kind: spindle``): nurbscnc has no spindle segments.

What is compared (``tol`` = the golden's ``tolerance_mm``: 1e-9 mm, or rs274's printed
precision where the golden had to come from rs274):

* kind: traverse ↔ rapid Line, feed ↔ Line, arc ↔ Arc, dwell ↔ Dwell, pause ↔ a segment of kind
  ``pause`` (probe and rigid-tap have no nurbscnc counterpart and fail the comparison);
* the source line (where the golden knows it: LinuxCNC's line 0 means it does not);
* end point (x, y, z) within tol; a program whose golden moves A, B or C is refused on a
  three-axis machine and compared, six coordinates a move, on one with A, B and C
  (``tests/linuxcnc_rotary.py``);
* arc: centre within tol, normal equal to 1e-12, and the turn: the sign of ``angle_rad`` is the
  sign of LinuxCNC's rotation and ``|angle_rad|`` equals the angle LinuxCNC's rotation count
  gives from start, centre and end (compared as an arc length: radius × Δangle within tol);
* feed [mm/s] within tol × max(1, feed) for feeds and arcs; dwell seconds within 1e-12 s.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT / "tests" / "programs" / "real"
GOLDEN = ROOT / "tests" / "golden" / "linuxcnc"
TOOLS = REAL / "tools.tbl"
KNOWN_GAPS = REAL / "KNOWN_GAPS.txt"

#: LinuxCNC errors nurbscnc deliberately does not reproduce: a file without M2/M30/% is run
#: to its end (a CAM trailer-less file is common and harmless).
LENIENT_ERRORS = ("File ended with no percent sign or program end",)


def load_golden(name: str) -> dict:
    with open(GOLDEN / f"{name}.json") as fh:
        return json.load(fh)


def golden_names() -> list[str]:
    return sorted(p.stem for p in GOLDEN.glob("*.json"))


def manifest_roles() -> dict[str, str]:
    """Golden name → role in the manifest (program / refused)."""
    with open(REAL / "manifest.json") as fh:
        files = json.load(fh)["files"]
    return {
        str(Path(e["path"]).with_suffix("")).replace("/", "__"): e["role"]
        for e in files
        if e["role"] != "subroutine"
    }


def read_known_gaps() -> dict[str, str]:
    """KNOWN_GAPS.txt: ``name  missing feature`` lines (``#`` comments) → {name: reason}."""
    gaps = {}
    for raw in KNOWN_GAPS.read_text().splitlines():
        body = raw.split("#", 1)[0].strip()
        if body:
            name, _, reason = body.partition(" ")
            gaps[name] = reason.strip()
    return gaps


def run_nurbscnc(program: Path):
    """nurbscnc's interpretation of ``program`` with the oracle's tool table."""
    from nurbscnc.app.load import load_program

    return load_program(str(program), tool_table=str(TOOLS))


def _segment_kind(seg) -> str:
    kind = seg.kind
    return {"rapid": "traverse", "line": "feed"}.get(kind, kind)


#: A straight move shorter than this on every axis is no move [mm] (see the module docstring).
ZERO_MOVE_MM = 1e-9


def _is_zero_length(kind: str, end, prev) -> bool:
    return (
        kind in ("traverse", "feed")
        and prev is not None
        and all(abs(a - b) <= ZERO_MOVE_MM for a, b in zip(end, prev))
    )


def expected_moves(golden: dict) -> list[dict]:
    """The golden's comparable moves (zero-length straight moves and spindle events dropped)."""
    out, prev = [], list(golden["initial_state"]["start"])
    for m in golden["moves"]:
        if m["kind"] == "spindle":
            continue
        if "end" in m:
            if _is_zero_length(m["kind"], m["end"][:3], prev[:3]) and m["end"][3:] == prev[3:]:
                continue
            m = dict(m, start=prev)
            prev = m["end"]
        out.append(m)
    return out


def actual_segments(program) -> list:
    """nurbscnc's comparable segments: zero-length straight moves dropped, and the stops of
    M64, M65, M66, M68 (a 0 s dwell: the machine waits for the motion to end; LinuxCNC's
    canon has an I/O call there, not a move)."""
    out, prev = [], tuple(float(v) for v in program.start_mm)
    for seg in program.segments:
        if seg.kind == "dwell" and getattr(seg, "code", "G4") != "G4":
            continue
        kind = _segment_kind(seg)
        end = tuple(float(v) for v in seg.end_mm) if hasattr(seg, "end_mm") else None
        if end is not None and _is_zero_length(kind, end, prev):
            continue
        if end is not None:
            prev = end
        out.append(seg)
    return out


def moves_rotary(golden: dict) -> bool:
    """Whether LinuxCNC moves an A, B or C axis in this program."""
    return any("end" in m and any(abs(v) > 1e-12 for v in m["end"][3:]) for m in golden["moves"])


def linuxcnc_angle_rad(start, centre, end, normal, rotation: int) -> float:
    """|Δθ| LinuxCNC turns through: CCW about ``normal`` for rotation > 0, |rotation| - 1
    extra full turns; a full circle when start and end coincide (RS274/NGC, ARC_FEED)."""
    n = np.asarray(normal, float)
    u = np.asarray(start, float) - centre
    v = np.asarray(end, float) - centre
    u -= n * (u @ n)
    v -= n * (v @ n)
    theta = math.atan2(float(n @ np.cross(u, v)), float(u @ v))  # CCW angle u → v in (-π, π]
    if rotation < 0:
        theta = -theta  # measure clockwise
    if theta <= 1e-12:
        theta += 2.0 * math.pi
    return theta + 2.0 * math.pi * (abs(rotation) - 1)


def compare(golden: dict, program, held_back: int = 0) -> None:
    """Raise AssertionError naming the first move where nurbscnc differs from LinuxCNC.

    ``held_back``: how many moves nurbscnc may make past LinuxCNC's last one (see
    :func:`check_golden`: a file without M2 ends LinuxCNC with an error while its cutter
    compensation still holds the last move back; nurbscnc runs the file to its end)."""
    tol = golden["tolerance_mm"]
    want = expected_moves(golden)
    got = actual_segments(program)
    start = np.asarray(program.start_mm, float)
    assert np.allclose(start, golden["initial_state"]["start"][:3], atol=tol, rtol=0), (
        f"start point {start} differs from LinuxCNC's {golden['initial_state']['start'][:3]}"
    )
    for i, (m, seg) in enumerate(zip(want, got)):
        where = f"move {i} (LinuxCNC line {m.get('line')}, nurbscnc line {seg.line})"
        kind = _segment_kind(seg)
        assert kind == m["kind"], f"{where}: LinuxCNC makes a {m['kind']}, nurbscnc a {kind}"
        # LinuxCNC numbers lines from 1; 0 is "not known": rs274 prints no line numbers, so
        # a golden recorded from rs274 has the gcode module's lines only up to the first move
        # where the two differ (tools/record_goldens.py, merge_events).
        if m.get("line"):
            assert seg.line == m["line"], f"{where}: source line differs"
        if "end" in m:
            end = np.asarray(seg.end_mm, float)
            assert np.allclose(end, m["end"][:3], atol=tol, rtol=0), (
                f"{where}: end {end.tolist()} != LinuxCNC {m['end'][:3]}"
            )
        if m["kind"] in ("feed", "arc"):
            f = m["feed_mm_s"]
            assert abs(seg.feed_mm_s - f) <= max(tol, 1e-9) * max(1.0, f), (
                f"{where}: feed {seg.feed_mm_s} mm/s != LinuxCNC {f}"
            )
        if m["kind"] == "arc":
            centre = np.asarray(m["centre"], float)
            assert np.allclose(seg.center_mm, centre, atol=tol, rtol=0), (
                f"{where}: centre {np.asarray(seg.center_mm).tolist()} != LinuxCNC {m['centre']}"
            )
            assert np.allclose(seg.normal, m["normal"], atol=1e-12, rtol=0), (
                f"{where}: normal {np.asarray(seg.normal).tolist()} != LinuxCNC {m['normal']}"
            )
            assert math.copysign(1, seg.angle_rad) == math.copysign(1, m["rotation"]), (
                f"{where}: turns the other way (LinuxCNC rotation {m['rotation']})"
            )
            want_rad = linuxcnc_angle_rad(
                m["start"][:3], centre, m["end"][:3], m["normal"], m["rotation"]
            )
            radius = float(np.linalg.norm(np.asarray(m["end"][:3]) - centre))
            assert abs(abs(seg.angle_rad) - want_rad) * max(radius, 1.0) <= max(tol, 1e-9), (
                f"{where}: turns {abs(seg.angle_rad)} rad, LinuxCNC {want_rad} rad"
            )
        if m["kind"] == "dwell":
            assert abs(seg.seconds - m["seconds"]) <= 1e-12, (
                f"{where}: dwell {seg.seconds} s != LinuxCNC {m['seconds']} s"
            )
    if len(want) < len(got) <= len(want) + held_back:
        return
    assert len(got) == len(want), (
        f"nurbscnc makes {len(got)} moves, LinuxCNC {len(want)} "
        f"(first extra: {(got[len(want)] if len(got) > len(want) else want[len(got)])})"
    )


def check_golden(name: str, role: str, golden: dict, program_path: Path) -> None:
    """The whole check for one program; AssertionError says what differs.

    * LinuxCNC accepts it (or refuses it only for a lenient rule, having made its moves), 3-axis,
      role ``program``: nurbscnc must accept it with the same moves;
    * LinuxCNC refuses it (other than for a lenient rule): nurbscnc must refuse it, at the same
      line;
    * LinuxCNC moves A/B/C: refused on a three-axis machine, LinuxCNC's moves on one with A, B
      and C (:func:`_check_rotary_golden`), whatever the role (the rotary programs the
      manifest calls refused were refused for their rotary motion);
    * role ``refused`` (outside 3-axis milling): nurbscnc must refuse it.
    """
    from nurbscnc.errors import ProgramError

    lenient = not golden["accepted"] and golden["error"]["message"].startswith(LENIENT_ERRORS)
    runs = golden["accepted"] or lenient
    if runs and moves_rotary(golden):
        _check_rotary_golden(golden, program_path)
        return
    must_refuse = role == "refused"
    if runs and not must_refuse:
        try:
            program = run_nurbscnc(program_path)
        except ProgramError as exc:
            line = exc.pos.line if exc.pos else "?"
            raise AssertionError(f"nurbscnc refuses it (line {line}): {exc.message}") from None
        # LinuxCNC's compensation queue holds one move back; its EOF error loses it.
        comp = (
            lenient
            and any(m.get("kind") == "arc" or m.get("kind") == "feed" for m in golden["moves"])
            and _has_comp(program_path)
        )
        compare(golden, program, held_back=1 if comp else 0)
        return
    try:
        run_nurbscnc(program_path)
    except ProgramError as exc:
        if not golden["accepted"] and not must_refuse:
            line = exc.pos.line if exc.pos else None
            assert line == golden["error"]["line"], (
                f"nurbscnc refuses at line {line} ({exc.message}), LinuxCNC at line "
                f"{golden['error']['line']} ({golden['error']['message']})"
            )
        return
    why = "outside 3-axis milling" if must_refuse else golden["error"]["message"]
    raise AssertionError(f"nurbscnc accepts a program it must refuse ({why})")


def _check_rotary_golden(golden: dict, program_path: Path) -> None:
    """A program whose LinuxCNC run turns A, B or C: refused on a three-axis machine (at a
    rotary word: "the machine has no A axis"), LinuxCNC's moves on one with A, B and C (six
    coordinates and the feeds: tests/linuxcnc_rotary.py)."""
    from nurbscnc.errors import ProgramError
    from tests.linuxcnc_rotary import compare_rotary, run_rotary

    try:
        run_nurbscnc(program_path)
    except ProgramError as exc:
        assert "the machine has no" in exc.message, exc.message
    else:
        raise AssertionError("a three-axis machine accepts a program that turns A, B or C")
    compare_rotary(golden, run_rotary(program_path), tol=golden["tolerance_mm"])


def _has_comp(path: Path) -> bool:
    """Does the program turn cutter compensation on (G41/G42, any form)?"""
    import re

    return re.search(r"[gG]\s*4\s*[12]", path.read_text(errors="replace")) is not None
