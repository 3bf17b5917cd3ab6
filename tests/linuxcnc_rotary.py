"""Compare nurbscnc's segments with LinuxCNC's moves for programs that turn A, B, C (the
goldens of ``tools/record_goldens.py --rotary`` in ``tests/golden/linuxcnc_rotary/``, and the
wrapped-axis goldens of ``--wrapped-ini`` in its ``wrapped/``), six coordinates a move.

Used by ``test_rotary_goldens.py`` (committed goldens) and its live tests (LinuxCNC run on the
fly). A golden move is compared with the segment at the same place after dropping what has no
motion on either side (LinuxCNC's spindle events; straight moves that move none of the six
axes, within ``ZERO_MOVE``). What is compared:

* kind: traverse ↔ a rapid Line or a rapid Rotate; feed ↔ a Line or a Rotate; arc ↔ an Arc;
  a golden straight move whose XYZ stay (within 1e-7 program units, LinuxCNC's rule) and
  whose A B C turn must be a :class:`~nurbscnc.geometry.segments.Rotate`, any other a Line;
* the source line (where the golden has it);
* the end: X Y Z [mm] and A B C [deg], machine coordinates, within ``tol`` (the golden's
  ``tolerance_mm``, 1e-9, taken for degrees too; rs274's printed precision, half a unit of
  its 4th decimal, for the wrapped goldens, which are in program units);
* the start of A B C: each segment's rotary start is the previous golden move's end (the
  contract: A B C move linearly from there along the segment);
* feeds (goldens with ``feed_mode``): a move with XYZ motion has LinuxCNC's rate along XYZ
  (``feed_mm_s``); a rotary-only move's ``feed_deg_s`` is LinuxCNC's ``SET_FEED_RATE`` in
  degrees per minute / 60; relative tolerance 1e-12;
* arcs: the centre within ``tol`` and the sign of the turn.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from nurbscnc.machine.model import RotaryAxis

ROOT = Path(__file__).resolve().parents[1]
PROGRAMS = ROOT / "tests" / "programs" / "rotary"
GOLDENS = ROOT / "tests" / "golden" / "linuxcnc_rotary"
TOOLS = ROOT / "tests" / "programs" / "real" / "tools.tbl"
#: LinuxCNC's "no XYZ motion" threshold [program units] (find_straight_length, the canon).
XYZ_ZERO = 1e-7
#: rs274 -g prints %.4f: a printed value is within half its last unit of the true one; a
#: wrapped golden's end adds two printed offsets to it (tools/record_goldens.py).
PRINTED_TOL = 3 * 0.5e-4 + 1e-9
#: A move of none of the six axes by more than this is no move (mm, deg).
ZERO_MOVE = 1e-9

#: A rotary machine for the differential: A, B, C with limits that never refuse a golden.
ALL_AXES = {name: RotaryAxis(name, 60.0, 400.0, 4000.0) for name in "abc"}
#: The machine of ``wrapped/wrapped.ini``: A wrapped ([AXIS_A]WRAPPED_ROTARY = 1), B, C not.
WRAPPED_AXES = {**ALL_AXES, "a": RotaryAxis("a", 60.0, 400.0, 4000.0, wrapped=True)}


def run_rotary(program: Path, rotary_axes: dict | None = None, tool_table: bool = True):
    """nurbscnc's interpretation of ``program`` on a machine with ``rotary_axes`` (default
    A, B and C), the goldens' tool table unless not ``tool_table``."""
    from nurbscnc.app.load import load_program
    from nurbscnc.app.varfile import ProgramInputs

    inputs = ProgramInputs(rotary_axes=ALL_AXES if rotary_axes is None else rotary_axes)
    return load_program(str(program), tool_table=str(TOOLS) if tool_table else None, inputs=inputs)


def six(seg) -> tuple:
    """A segment's end: X Y Z [mm], A B C [deg]."""
    if seg.kind == "rotate":
        return (*seg.position_mm, *seg.abc_end_deg)
    abc = seg.abc_deg[3:] if getattr(seg, "abc_deg", None) is not None else (0.0, 0.0, 0.0)
    return (*map(float, seg.end_mm), *abc)


def abc_start(seg) -> tuple:
    """A moving segment's A B C at its start [deg]."""
    if seg.kind == "rotate":
        return tuple(seg.abc_start_deg)
    return tuple(seg.abc_deg[:3]) if seg.abc_deg is not None else (0.0, 0.0, 0.0)


def expected_moves(golden: dict, start=(0.0,) * 6) -> list[dict]:
    """The golden's moves with their start (spindle events and no-moves dropped)."""
    out, prev = [], list(golden.get("initial_state", {}).get("start", start))
    for m in golden["moves"]:
        if m["kind"] == "spindle":
            continue
        if "end" in m:
            if m["kind"] in ("traverse", "feed") and all(
                abs(a - b) <= ZERO_MOVE for a, b in zip(m["end"], prev, strict=True)
            ):
                continue
            m = dict(m, start=prev)
            prev = m["end"]
        out.append(m)
    return out


def actual_segments(program) -> list:
    """nurbscnc's comparable segments: the 0 s dwells of M64–M68 and straight moves of none of
    the six axes (within ``ZERO_MOVE``) dropped, as the XYZ comparison does (LinuxCNC's
    program → machine round trip makes 1e-14 mm moves where nurbscnc, keeping the machine
    where it is, makes none, and the other way round)."""
    out = []
    prev = (*map(float, program.start_mm), *program.start_abc_deg)
    for seg in program.segments:
        if seg.kind == "dwell" and seg.code != "G4":
            continue
        if seg.kind in ("rapid", "line", "rotate", "arc"):
            end = six(seg)
            if seg.kind != "arc" and all(
                abs(a - b) <= ZERO_MOVE for a, b in zip(end, prev, strict=True)
            ):
                continue
            prev = end
        out.append(seg)
    return out


def _kind_of(seg) -> str:
    if seg.kind in ("rapid", "line", "rotate"):
        return "traverse" if seg.rapid else "feed"
    return seg.kind


def compare_rotary(golden: dict, program, tol: float | None = None, scale: float = 1.0) -> None:
    """Raise AssertionError naming the first move where nurbscnc differs from LinuxCNC.

    ``tol``: the end tolerance (default the golden's ``tolerance_mm``); ``scale``: mm per unit
    of the golden's X Y Z (the wrapped goldens are in program units: 1 for G21)."""
    tol = golden.get("tolerance_mm", PRINTED_TOL) if tol is None else tol
    want, got = expected_moves(golden), actual_segments(program)
    for i, (m, seg) in enumerate(zip(want, got)):
        where = f"move {i} (LinuxCNC line {m.get('line')}, nurbscnc line {seg.line})"
        kind = _kind_of(seg)
        assert kind == m["kind"], f"{where}: LinuxCNC makes a {m['kind']}, nurbscnc a {kind}"
        if m.get("line"):
            assert seg.line == m["line"], f"{where}: source line differs"
        if "end" not in m:  # a dwell or a pause: at rest
            if m["kind"] == "dwell":
                assert abs(seg.seconds - m["seconds"]) <= 1e-12, f"{where}: dwell differs"
            continue
        end = np.array(m["end"], float)
        end[:3] *= scale
        start = np.array(m["start"], float)
        start[:3] *= scale
        assert np.allclose(six(seg), end, atol=tol, rtol=0), (
            f"{where}: end {list(six(seg))} != LinuxCNC {end.tolist()}"
        )
        assert np.allclose(abc_start(seg), start[3:], atol=tol, rtol=0), (
            f"{where}: A B C start {abc_start(seg)} != LinuxCNC's previous end {start[3:]}"
        )
        if kind in ("traverse", "feed"):
            xyz_moves = math.dist(start[:3], end[:3]) > XYZ_ZERO * scale + tol
            want_kind = "rotate" if not xyz_moves else ("rapid" if kind == "traverse" else "line")
            assert seg.kind == want_kind, f"{where}: nurbscnc makes a {seg.kind}, not a {want_kind}"
        if "feed_mode" in m and kind in ("feed", "arc"):
            _compare_feed(where, m, seg)
        if m["kind"] == "arc":
            assert np.allclose(seg.center_mm, np.array(m["centre"]) * scale, atol=tol, rtol=0), (
                f"{where}: centre {np.asarray(seg.center_mm).tolist()} != LinuxCNC {m['centre']}"
            )
            assert math.copysign(1, seg.angle_rad) == math.copysign(1, m["rotation"]), where
    assert len(got) == len(want), f"nurbscnc makes {len(got)} moves, LinuxCNC {len(want)}"


def _compare_feed(where: str, m: dict, seg) -> None:
    """The feed semantics: along XYZ [mm/s] when XYZ move, else deg/min of SET_FEED_RATE."""
    if seg.kind == "rotate":
        want = m["feed_rate_prog_min"] / 60.0
        assert abs(seg.feed_deg_s - want) <= 1e-12 * want, (
            f"{where}: {seg.feed_deg_s} deg/s != LinuxCNC {m['feed_rate_prog_min']} deg/min"
        )
    else:
        want = m["feed_mm_s"]
        assert abs(seg.feed_mm_s - want) <= 1e-12 * want, (
            f"{where}: feed {seg.feed_mm_s} mm/s != LinuxCNC {want} mm/s"
        )


def block_line(program: Path, block: str) -> int:
    """The 1-based line of ``program`` whose text is ``block`` (rs274 names the block)."""
    for number, text in enumerate(program.read_text().splitlines(), 1):
        if re.sub(r"\s+", " ", text.strip()) == block:
            return number
    raise AssertionError(f"no line {block!r} in {program}")
