"""``rs274 -g``: the canonical calls LinuxCNC's ``gcode`` module does not report (program stops,
spindle events), aligned with the ``gcode`` moves, and rs274's error messages.

Part of ``tools/record_goldens.py``. Run under the system Python; nurbscnc is not imported.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess

from lcnc_recorder import INCH_MM, Recorder

RS274 = "/usr/bin/rs274"


CALL = re.compile(r"^\s*\d+\s+N\S*\s+([A-Z0-9_]+)\((.*)\)\s*$")
MOTION = {
    "STRAIGHT_TRAVERSE": "traverse",
    "STRAIGHT_FEED": "feed",
    "ARC_FEED": "arc",
    "DWELL": "dwell",
    "STRAIGHT_PROBE": "probe",
    "RIGID_TAP": "rigid-tap",
}
_EVENTS = {
    "PROGRAM_STOP": "M0",
    "OPTIONAL_PROGRAM_STOP": "M1",
    "PALLET_SHUTTLE": "M60",
    "STOP_SPINDLE_TURNING": "spindle-stop",
    "START_SPINDLE_CLOCKWISE": "spindle-cw",
    "START_SPINDLE_COUNTERCLOCKWISE": "spindle-ccw",
    "ORIENT_SPINDLE": "spindle-orient",
    "CHANGE_TOOL": "M6",  # M6: the machine stops for the tool change
}


def parse_calls(stdout: str) -> list:
    """rs274's canonical calls [(NAME, [numbers])] from its ``-g`` output: the plane as 1 XY,
    2 YZ, 3 XZ, the length units as 1.0 mm / 0.0 inch, every other call's numbers."""
    calls = []
    for raw in stdout.splitlines():
        m = CALL.match(raw)
        if not m:
            continue
        if m.group(1) == "SELECT_PLANE":
            planes = {"CANON_PLANE_XY": 1, "CANON_PLANE_YZ": 2, "CANON_PLANE_XZ": 3}
            calls.append((m.group(1), [planes.get(m.group(2).strip(), 1)]))
            continue
        if m.group(1) == "USE_LENGTH_UNITS":
            calls.append((m.group(1), [1.0 if "MM" in m.group(2) else 0.0]))
            continue
        nums = []
        for item in m.group(2).replace(" ", ",").split(","):
            try:
                nums.append(float(item))
            except ValueError:
                pass
        calls.append((m.group(1), nums))
    return calls


def run_rs274(path: str, tmp: str) -> subprocess.CompletedProcess:
    """``rs274 -g -b`` on ``path`` (in its own directory, so ``o<name> call`` finds its
    files) with the tool table ``tmp/rs274.tbl`` and parameter file ``tmp/rs274.var``; its
    HOME is ``tmp``: rs274 creates its own tool database in $HOME, which must not overwrite
    the one this process uses. TimeoutExpired after 120 s."""
    return subprocess.run(
        [RS274, "-g", "-b", "-t", os.path.join(tmp, "rs274.tbl"), "-v"]
        + [os.path.join(tmp, "rs274.var"), os.path.abspath(path)],
        cwd=os.path.dirname(os.path.abspath(path)),
        capture_output=True,
        text=True,
        errors="replace",
        timeout=120,
        stdin=subprocess.DEVNULL,
        env=dict(os.environ, HOME=tmp),
    )


def rs274_calls(path: str, tools: dict, params: str, tmp: str) -> tuple[list | None, str]:
    """The canonical calls of ``rs274 -g`` (block delete on): [(NAME, [numbers])], and the
    text of the block it stopped at with an error ("" if none)."""
    if not os.path.exists(RS274):
        return None, ""
    # The stand-alone canon's machine is in inches: give it the same tools in inches.
    tbl = os.path.join(tmp, "rs274.tbl")
    with open(tbl, "w") as fh:
        for t, (pocket, z_mm, d_mm) in tools.items():
            fh.write(f"T{t} P{pocket} Z{z_mm / INCH_MM!r} D{d_mm / INCH_MM!r}\n")
    shutil.copy(params, os.path.join(tmp, "rs274.var"))
    try:
        res = run_rs274(path, tmp)
    except subprocess.TimeoutExpired:
        return None, ""
    err_lines = [t for t in res.stderr.splitlines() if t.strip()]
    failed_block = err_lines[-1].strip() if len(err_lines) >= 3 else ""
    return parse_calls(res.stdout), failed_block


def replay_rs274(calls: list, tools: dict) -> Recorder:
    """Feed rs274's printed calls (program units, 4 decimals) through a Recorder."""
    rec = Recorder(tools, "")
    metric = True
    for name, v in calls:
        k = 1.0 / INCH_MM if metric else 1.0  # program units → inch, as the gcode module
        if name == "USE_LENGTH_UNITS":
            metric = v[0] == 1.0
            continue
        if name in ("STRAIGHT_TRAVERSE", "STRAIGHT_FEED", "STRAIGHT_PROBE"):
            args = [v[0] * k, v[1] * k, v[2] * k, v[3], v[4], v[5], 0.0, 0.0, 0.0]
            rec._linear(MOTION[name], args)
        elif name == "RIGID_TAP":
            rec.rigid_tap(v[0] * k, v[1] * k, v[2] * k)
        elif name == "ARC_FEED":
            rec.arc_feed(
                v[0] * k,
                v[1] * k,
                v[2] * k,
                v[3] * k,
                int(v[4]),
                v[5] * k,
                v[6],
                v[7],
                v[8],
                0.0,
                0.0,
                0.0,
            )
        elif name == "DWELL":
            rec.dwell(v[0])
        elif name == "SET_FEED_RATE":
            rec.set_feed_rate(v[0] * k)
        elif name == "SET_G5X_OFFSET":
            rec.set_g5x_offset(int(v[0]), *[x * k if i < 3 else x for i, x in enumerate(v[1:7])])
        elif name == "SET_G92_OFFSET":
            rec.set_g92_offset(*[x * k if i < 3 else x for i, x in enumerate(v[:6])])
        elif name == "SET_XY_ROTATION":
            rec.set_xy_rotation(v[0])
        elif name == "USE_TOOL_LENGTH_OFFSET":
            rec.tool_offset(*[x * k if i < 3 else x for i, x in enumerate(v[:6])], 0.0, 0.0, 0.0)
        elif name == "SELECT_PLANE":
            rec.set_plane(int(v[0]))
        elif name == "SET_FEED_MODE":  # (spindle, mode): mode 1 is G95, per revolution
            rec.feed_mode = 950 if v[1] == 1 else 940
        elif name == "SET_SPINDLE_SPEED":  # (spindle, rpm)
            rec.speed = v[1]
    return rec


def _moves_agree(a: list, b: list, tol_mm: float) -> bool:
    """Same kinds, and every number equal within ``tol_mm``."""
    if [m["kind"] for m in a] != [m["kind"] for m in b]:
        return False
    for m, n in zip(a, b):
        for key in ("end", "centre", "seconds", "feed_mm_s", "rotation"):
            x, y = m.get(key), n.get(key)
            if (x is None) != (y is None):
                return False
            if x is None:
                continue
            xs, ys = (x, y) if isinstance(x, list) else ([x], [y])
            if any(abs(p - q) > tol_mm * (1.0 + abs(p) * 1e-4) for p, q in zip(xs, ys)):
                return False
    return True


#: rs274 prints 4 decimals of the program's unit (at worst 0.00005 in = 0.00127 mm off); a
#: machine coordinate adds rounded offsets and an XY rotation to it: 2.5 such errors at most.
RS274_TOL_MM = 0.0032


def merge_events(moves: list, calls: list | None, tools: dict) -> tuple[list, str, float]:
    """Cross-check the gcode module's moves with rs274's; insert rs274's stops.

    Returns (moves, how, tolerance_mm). Where the two disagree beyond rs274's printed
    precision, rs274's moves are the record (the ``gcode`` module, a preview, neither loads
    the new tool's data after M6 nor tracks the position after arcs, so a program that
    changes tools can differ); the golden then says so and carries rs274's tolerance.
    """
    if calls is None:
        return moves, "rs274 not available: gcode module only, stops not recorded", 1e-9
    if any(c[0] == "NURBS_FEED" for c in calls):
        return moves, "NURBS: gcode module polyline, not cross-checked", 1e-9
    motion = [c for c in calls if c[0] in MOTION]
    replay = replay_rs274(calls, tools).moves
    if _moves_agree(moves, replay, RS274_TOL_MM):
        base, how, tol = moves, "gcode module, cross-checked with rs274", 1e-9
    else:
        # rs274 prints no line numbers: take the gcode module's while the two make the same
        # move; after their first difference the sequences are shifted (a corner arc one of
        # them makes, the other not), so a line copied by position would be another move's:
        # the rest keeps line 0 ("not known").
        for m, n in zip(replay, moves):
            if not _moves_agree([m], [n], RS274_TOL_MM):
                break
            m["line"] = n["line"]
        base, how, tol = (
            replay,
            (
                "rs274 (4 decimals): the gcode module disagrees "
                f"({len(moves)} vs {len(motion)} moves)"
            ),
            RS274_TOL_MM,
        )
    out, k, shuttle = [], 0, False
    for name, _ in calls:
        if name in MOTION:
            out.append(base[k])
            k += 1
        elif name == "PALLET_SHUTTLE":
            shuttle = True  # M60 (then PROGRAM_STOP) or M30 (then PROGRAM_END)
            continue
        elif name in _EVENTS:
            code = "M60" if name == "PROGRAM_STOP" and shuttle else _EVENTS[name]
            kind = "pause" if code.startswith("M") else "spindle"
            out.append({"kind": kind, "code": code, "line": None})
        shuttle = False
    return out, how, tol


def rs274_error(path: str, tools: dict, tmp: str) -> str:
    """rs274's error message (the line before the failed block it prints on stderr)."""
    res = run_rs274(path, tmp)
    err_lines = [t for t in res.stderr.splitlines() if t.strip()]
    return err_lines[-2].strip() if len(err_lines) >= 2 else ""


def block_line(path: str, failed_block: str, moves: list) -> int:
    """The line of ``failed_block`` (rs274's text of the block it refused): the first line
    with that text at or after the last line a recorded move came from."""
    with open(path, errors="replace") as fh:
        lines = fh.read().splitlines()
    after = max([m.get("line") or 0 for m in moves] or [0])
    for k in range(max(after, 1), len(lines) + 1):
        if lines[k - 1].strip() == failed_block:
            return k
    return 0


def error_line(path: str, reported: int, failed_block: str) -> int:
    """The line LinuxCNC refused. The gcode module reports the line after it when the block
    could not be read (a syntax or word error), the line itself when it could not be executed;
    rs274 prints the refused block's text, which tells the two apart."""
    with open(path, errors="replace") as fh:
        lines = fh.read().splitlines()
    if failed_block and 2 <= reported <= len(lines) + 1:
        if lines[reported - 2].strip() == failed_block:
            return reported - 1
    return reported
