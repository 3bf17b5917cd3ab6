#!/usr/bin/python3
"""Record LinuxCNC's canonical moves for NC programs into JSON goldens (the test oracle).

Run with the system Python that has LinuxCNC 2.9's ``gcode`` module (``/usr/bin/python3``);
nurbscnc is not imported. For each program the interpreter is run twice:

* ``gcode.parse`` (LinuxCNC's interpreter with Python canon callbacks, as AXIS previews a
  program) gives every move at full double precision: traverses, feeds, arcs, dwells, probes;
* ``rs274 -g`` (the same interpreter with the stand-alone canon, 4 decimals) gives the calls the
  ``gcode`` module does not pass to Python: program stops (M0, M1, M60) and spindle events.
  Its motion calls are aligned one to one with the ``gcode`` moves (kinds and positions to its
  printed precision); the stops are inserted at their place in that sequence.

Units (decision): every length in a golden is **mm**, feeds **mm/s**, angles (A B C) degrees,
dwells s. The ``gcode`` module always reports lengths in inches (it divides mm values by 25.4),
so they are multiplied by 25.4 here; feeds come as inch/min and become mm/s (× 25.4 / 60).
End points are **machine coordinates of the controlled point**: the program coordinates plus
the G92 offset, turned by the XY rotation (G10 L2 R), plus the G5x offset, plus the tool length
offset (G43) — the order LinuxCNC's canon and preview apply them. An arc's centre is stored as a
point in the plane of the arc's start (its axial coordinate is the start's), transformed the
same way; its ``normal`` is the plane's (+Z for G17, +Y for G18, +X for G19) and ``rotation``
LinuxCNC's signed turn count (> 0 counter-clockwise about the normal; |rotation| - 1 full turns).

Initial state (saved beside the programs so nurbscnc can be given the same): machine in mm
(unit code ``G21``, as nurbscnc's default), start at the origin, block delete on, the tool table
``tests/programs/real/tools.tbl`` (mm) and the parameter file ``tests/programs/real/params.var``
(all offsets zero, G54). Axes X Y Z A B C exist (mask 0o77), U V W do not. Each program runs in
its own directory, so ``o<name> call`` finds ``name.ngc`` beside it.

Usage::

    /usr/bin/python3 tools/record_goldens.py                 # every program in the manifest
    /usr/bin/python3 tools/record_goldens.py --only cds      # names containing "cds"
    /usr/bin/python3 tools/record_goldens.py --stdout FILE   # one program, JSON on stdout
"""

from __future__ import annotations

import argparse
import atexit
import ctypes
import hashlib
import json
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
REAL = os.path.join(ROOT, "tests", "programs", "real")
GOLDEN = os.path.join(ROOT, "tests", "golden", "linuxcnc")
TOOLS = os.path.join(REAL, "tools.tbl")
PARAMS = os.path.join(REAL, "params.var")
MANIFEST = os.path.join(REAL, "manifest.json")
INCH_MM = 25.4
LINUXCNC_VERSION = "2.9.0~pre1+git20230208.f1270d6ed7 (Debian linuxcnc-uspace)"
RS274 = "/usr/bin/rs274"
EOF_ERROR = "File ended with no percent sign or program end"

# The canon's plane numbers and, for each, the axis indices of (first, second, axial)
# coordinates of ARC_FEED and the unit normal.
PLANES = {
    1: ((0, 1, 2), (0.0, 0.0, 1.0)),  # XY (G17)
    2: ((1, 2, 0), (1.0, 0.0, 0.0)),  # YZ (G19)
    3: ((2, 0, 1), (0.0, 1.0, 0.0)),
}  # XZ (G18): first = Z, second = X


def read_tool_table(path: str) -> dict:
    """LinuxCNC tool table → {tool: (pocket, z_mm, diameter_mm)}."""
    tools = {}
    with open(path) as fh:
        for raw in fh:
            body = raw.split(";", 1)[0].split()
            if not body:
                continue
            fields = {w[0].upper(): float(w[1:]) for w in body}
            t = int(fields["T"])
            tools[t] = (int(fields.get("P", t)), fields.get("Z", 0.0), fields.get("D", 0.0))
    return tools


class Recorder:
    """The canon object ``gcode.parse`` calls back; collects moves in machine mm."""

    def __init__(self, tools: dict, parameter_file: str):
        self.parameter_file = parameter_file
        # Tool data by pocket: (toolno, x y z a b c u v w offsets, diameter, front, back, orient).
        self.pockets = {0: (-1,) + (0.0,) * 12 + (0,)}
        for t, (pocket, z_mm, d_mm) in tools.items():
            self.pockets[pocket] = (
                t,
                0.0,
                0.0,
                z_mm,
                0.0,
                0.0,
                0.0,
                0.0,
                0.0,
                0.0,
                d_mm,
                0.0,
                0.0,
                0,
            )
        self.moves = []
        self.messages = []
        self.line = 0
        self.feed_in_min = 0.0
        self.feed_mode = 940
        self.speed = 0.0
        self.plane = 1
        self.rotary = False  # --rotary: also record the feed mode and the canon's rate
        self.units = 210
        self.feed_prog_min = 0.0
        self.g5x = [0.0] * 9
        self.g92 = [0.0] * 9
        self.rotation_deg = 0.0
        self.tool = [0.0] * 9
        self.prog = [0.0] * 9  # current position, program coordinates, inch (as reported)

    # -- state callbacks ------------------------------------------------------------------
    def next_line(self, linecode):
        self.line = linecode.sequence_number
        self.feed_mode = linecode.feed_mode
        self.speed = linecode.speed
        self.units = linecode.units

    def set_plane(self, plane):
        self.plane = plane

    def set_feed_rate(self, rate):
        self.feed_in_min = rate
        # SET_FEED_RATE's own argument (rs274 prints it): the module's in/min back in the
        # program units in effect now, not at the move (G20 F10 sets F before the switch).
        self.feed_prog_min = rate * (INCH_MM if self.units == 210 else 1.0)

    def _reframe(self, change) -> None:
        """Apply ``change`` to the offsets, keeping the current point where it is on the
        machine: its program coordinates ``self.prog`` are expressed again in the new frame
        (machine = R(rotation)·(program + g92) + g5x + tool). Without it the next arc's
        centre took its axial coordinate (the Z of a G17 arc) from the old frame: after a
        G92 then a G18 arc its Y was off by the G92 offset (found by a differential run)."""

        def turn(p, deg):
            c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
            return [p[0] * c - p[1] * s, p[0] * s + p[1] * c, *p[2:]]

        m = turn([self.prog[i] + self.g92[i] for i in range(9)], self.rotation_deg)
        m = [m[i] + self.g5x[i] + self.tool[i] for i in range(9)]
        change()
        q = turn([m[i] - self.g5x[i] - self.tool[i] for i in range(9)], -self.rotation_deg)
        self.prog = [q[i] - self.g92[i] for i in range(9)]

    def set_g5x_offset(self, index, *xyz):
        self._reframe(lambda: setattr(self, "g5x", list(xyz) + [0.0] * (9 - len(xyz))))

    def set_g92_offset(self, *xyz):
        self._reframe(lambda: setattr(self, "g92", list(xyz) + [0.0] * (9 - len(xyz))))

    def set_xy_rotation(self, theta_deg):
        self._reframe(lambda: setattr(self, "rotation_deg", theta_deg))

    def tool_offset(self, *xyz):
        self._reframe(lambda: setattr(self, "tool", list(xyz) + [0.0] * (9 - len(xyz))))

    def change_tool(self, pocket):
        # What LinuxCNC's tool changer (and rs274's canon) does on M6: the pocket's data
        # becomes the spindle's (index 0), so that G41/G42 and G43 see the new tool. The gcode
        # module alone leaves index 0 unchanged (radius 0 for cutter compensation).
        entry = _ToolEntry()
        if _TOOLDATA._Z12tooldata_getP16CANON_TOOL_TABLEi(ctypes.byref(entry), pocket) == 0:
            _TOOLDATA._Z12tooldata_put16CANON_TOOL_TABLEi(entry, 0)

    def message(self, text):
        self.messages.append(text)

    def get_tool(self, pocket):
        return self.pockets.get(pocket, (-1,) + (0.0,) * 12 + (0,))

    def get_external_angular_units(self):
        return 1.0

    def get_external_length_units(self):
        return 1.0  # machine units are mm: the tool table and parameters are in mm

    def get_axis_mask(self):
        return 0o77  # X Y Z A B C

    def get_block_delete(self):
        return True

    def check_abort(self):
        return False

    def __getattr__(self, name):
        # Every other canon call (comment, change_tool, set_traverse_rate, ...) is ignored.
        if name.startswith("__"):
            raise AttributeError(name)
        return lambda *args: None

    # -- geometry -------------------------------------------------------------------------
    def machine(self, p: list) -> list:
        """Program coordinates (inch, degrees) → machine coordinates (mm, degrees)."""
        q = [p[i] + self.g92[i] for i in range(9)]
        if self.rotation_deg:
            t = math.radians(self.rotation_deg)
            c, s = math.cos(t), math.sin(t)
            q[0], q[1] = q[0] * c - q[1] * s, q[0] * s + q[1] * c
        q = [q[i] + self.g5x[i] + self.tool[i] for i in range(9)]
        return [q[i] * INCH_MM if i in (0, 1, 2) else q[i] for i in range(6)]

    def feed_mm_s(self) -> float:
        if self.feed_mode == 950:  # G95: units per revolution times the spindle speed
            return self.feed_in_min * self.speed * INCH_MM / 60.0
        return self.feed_in_min * INCH_MM / 60.0

    def feed_extra(self) -> dict:
        """With --rotary: the feed mode and the argument of the last SET_FEED_RATE, per minute
        in the program units in effect when it was set: the canon's rate along XYZ in those
        units, and its rate in degrees/min when only A B C move (emccanon.cc SET_FEED_RATE:
        FROM_PROG_ANG, no length conversion); under G93 the move's length times F."""
        if not self.rotary:
            return {}
        mode = {930: "G93", 940: "G94", 950: "G95"}.get(self.feed_mode, str(self.feed_mode))
        return {"feed_mode": mode, "feed_rate_prog_min": self.feed_prog_min}

    def _linear(self, kind, args):
        self.prog = list(args)
        move = {"kind": kind, "line": self.line, "end": self.machine(self.prog)}
        if kind != "traverse":
            move["feed_mm_s"] = self.feed_mm_s()
            move.update(self.feed_extra())
        self.moves.append(move)

    def straight_traverse(self, *args):
        self._linear("traverse", args)

    def straight_feed(self, *args):
        self._linear("feed", args)

    def straight_probe(self, *args):
        self._linear("probe", args)

    def rigid_tap(self, x, y, z):
        self._linear("rigid-tap", [x, y, z] + self.prog[3:])

    def arc_feed(
        self, first_end, second_end, first_c, second_c, rotation, axial_end, a, b, c, u, v, w
    ):
        (i1, i2, i3), normal = PLANES[self.plane]
        centre = list(self.prog)
        centre[i1], centre[i2] = first_c, second_c
        end = list(self.prog)
        end[i1], end[i2], end[i3] = first_end, second_end, axial_end
        end[3:] = [a, b, c, u, v, w]
        centre_m = self.machine(centre)
        self.prog = end
        if self.rotation_deg:
            t = math.radians(self.rotation_deg)
            normal = (
                normal[0] * math.cos(t) - normal[1] * math.sin(t),
                normal[0] * math.sin(t) + normal[1] * math.cos(t),
                normal[2],
            )
        self.moves.append(
            {
                "kind": "arc",
                "line": self.line,
                "end": self.machine(end),
                "centre": centre_m[:3],
                "normal": list(normal),
                "rotation": rotation,
                "feed_mm_s": self.feed_mm_s(),
                **self.feed_extra(),
            }
        )

    def dwell(self, seconds):
        self.moves.append({"kind": "dwell", "line": self.line, "seconds": seconds})


# -- rs274 -g: the calls the gcode module does not report -----------------------------------
_CALL = re.compile(r"^\s*\d+\s+N\S*\s+([A-Z0-9_]+)\((.*)\)\s*$")
_MOTION = {
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
    var = os.path.join(tmp, "rs274.var")
    shutil.copy(params, var)
    # rs274 creates its own tool database in $HOME: give it a HOME of its own, so that it
    # does not overwrite the one this process uses.
    env = dict(os.environ, HOME=tmp)
    try:
        res = subprocess.run(
            [RS274, "-g", "-b", "-t", tbl, "-v", var, os.path.abspath(path)],
            cwd=os.path.dirname(os.path.abspath(path)),
            capture_output=True,
            text=True,
            errors="replace",
            timeout=120,
            stdin=subprocess.DEVNULL,
            env=env,
        )
    except subprocess.TimeoutExpired:
        return None, ""
    err_lines = [t for t in res.stderr.splitlines() if t.strip()]
    failed_block = err_lines[-1].strip() if len(err_lines) >= 3 else ""
    calls = []
    for raw in res.stdout.splitlines():
        m = _CALL.match(raw)
        if m:
            nums = []
            if m.group(1) == "SELECT_PLANE":
                nums = [
                    {"CANON_PLANE_XY": 1, "CANON_PLANE_YZ": 2, "CANON_PLANE_XZ": 3}.get(
                        m.group(2).strip(), 1
                    )
                ]
                calls.append((m.group(1), nums))
                continue
            if m.group(1) == "USE_LENGTH_UNITS":
                calls.append((m.group(1), [1.0 if "MM" in m.group(2) else 0.0]))
                continue
            for item in m.group(2).replace(" ", ",").split(","):
                try:
                    nums.append(float(item))
                except ValueError:
                    pass
            calls.append((m.group(1), nums))
    return calls, failed_block


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
            rec._linear(_MOTION[name], args)
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
    motion = [c for c in calls if c[0] in _MOTION]
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
        if name in _MOTION:
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


class _ToolEntry(ctypes.Structure):
    """LinuxCNC's CANON_TOOL_TABLE (112 bytes), copied as raw bytes."""

    _fields_ = [("raw", ctypes.c_char * 112)]


_TOOLDATA = None  # libtooldata, once loaded


def _rs274_error(path: str, tools: dict, tmp: str) -> str:
    """rs274's error message (the line before the failed block it prints on stderr)."""
    env = dict(os.environ, HOME=tmp)
    tbl = os.path.join(tmp, "rs274.tbl")
    var = os.path.join(tmp, "rs274.var")
    res = subprocess.run(
        [RS274, "-g", "-b", "-t", tbl, "-v", var, os.path.abspath(path)],
        cwd=os.path.dirname(os.path.abspath(path)),
        capture_output=True,
        text=True,
        errors="replace",
        timeout=120,
        stdin=subprocess.DEVNULL,
        env=env,
    )
    err_lines = [t for t in res.stderr.splitlines() if t.strip()]
    return err_lines[-2].strip() if len(err_lines) >= 2 else ""


def _block_line(path: str, failed_block: str, moves: list) -> int:
    """The line of ``failed_block`` (rs274's text of the block it refused): the first line
    with that text at or after the last line a recorded move came from."""
    with open(path, errors="replace") as fh:
        lines = fh.read().splitlines()
    after = max([m.get("line") or 0 for m in moves] or [0])
    for k in range(max(after, 1), len(lines) + 1):
        if lines[k - 1].strip() == failed_block:
            return k
    return 0


def _error_line(path: str, reported: int, failed_block: str) -> int:
    """The line LinuxCNC refused. The gcode module reports the line after it when the block
    could not be read (a syntax or word error), the line itself when it could not be executed;
    rs274 prints the refused block's text, which tells the two apart."""
    with open(path, errors="replace") as fh:
        lines = fh.read().splitlines()
    if failed_block and 2 <= reported <= len(lines) + 1:
        if lines[reported - 2].strip() == failed_block:
            return reported - 1
    return reported


def load_tool_database(tools_path: str) -> None:
    """Give LinuxCNC 2.9's interpreter its tool table.

    In 2.9 the interpreter reads tools from a memory-mapped tool database (``$HOME/.tool.mmap``)
    that a running LinuxCNC (or ``rs274``) creates; the ``gcode`` module alone crashes on the
    first T/G43 without it. Create it in this process, under a private ``HOME`` so that other
    LinuxCNC processes on the machine are not disturbed, and load the tool table into it.
    """
    global _TOOLDATA
    home = tempfile.mkdtemp(prefix="goldens-home-")
    atexit.register(shutil.rmtree, home, True)
    os.environ["HOME"] = home
    lib = _TOOLDATA = ctypes.CDLL("/lib/libtooldata.so.0", mode=ctypes.RTLD_GLOBAL)
    lib._Z17tool_mmap_creatorPK13EMC_TOOL_STATi(None, 0)  # tool_mmap_creator(NULL, 0)
    lib._Z13tooldata_initb(0)  # tooldata_init(random_toolchanger = false)
    if lib._Z13tooldata_loadPKcPPc(tools_path.encode(), None) != 0:  # tooldata_load()
        raise SystemExit(f"LinuxCNC could not load the tool table {tools_path}")


def record(path: str, tools: dict, rotary: bool = False) -> dict:
    """Run LinuxCNC on one program; the golden as a dict."""
    import gcode  # LinuxCNC's interpreter module (only in the system Python)

    with open(path, "rb") as fh:
        digest = hashlib.sha256(fh.read()).hexdigest()
    tmp = tempfile.mkdtemp(prefix="goldens-")
    try:
        var = os.path.join(tmp, "params.var")
        shutil.copy(PARAMS, var)  # LinuxCNC rewrites its parameter file at the end
        canon = Recorder(tools, var)
        canon.rotary = rotary
        cwd = os.getcwd()
        os.chdir(os.path.dirname(os.path.abspath(path)))
        try:
            # Unit code G21; init code F0: the feed starts at zero as on a real machine
            # (the module alone would start it at 1 unit/min and accept G1 without F).
            result, last_line = gcode.parse(os.path.abspath(path), canon, "G21", "F0")
        finally:
            os.chdir(cwd)
        accepted = result <= gcode.MIN_ERROR
        eof_only = not accepted and gcode.strerror(result).startswith(EOF_ERROR)
        moves, alignment, tol_mm = canon.moves, "program refused", 1e-9
        message = gcode.strerror(result).strip()
        if accepted:
            calls, failed_block = rs274_calls(path, tools, PARAMS, tmp)
            moves, alignment, tol_mm = merge_events(canon.moves, calls, tools)
            if failed_block and alignment.startswith("rs274"):
                # The preview accepts what rs274 refuses, where the two disagree (the gcode
                # module keeps the old tool's radius after M6: nc_files/mmount): rs274's
                # refusal, at the block it printed, is the record.
                accepted, alignment = False, "rs274 refuses it (the gcode module accepts it)"
                message = _rs274_error(path, tools, tmp)
                last_line = _block_line(path, failed_block, moves)
        else:
            last_line = _error_line(path, last_line, rs274_calls(path, tools, PARAMS, tmp)[1])
            # A call of a subroutine that is nowhere makes LinuxCNC read to the end of the
            # file looking for it; the line it stops at is not the error's, the message names
            # it: "EOF in file:… seeking o-word: o<name> from line: N".
            seeking = re.search(r"seeking o-word: \S+ from line: (\d+)", gcode.strerror(result))
            if seeking:
                last_line = int(seeking.group(1))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    golden = {
        "program": os.path.relpath(os.path.abspath(path), ROOT),
        "sha256": digest,
        "linuxcnc": LINUXCNC_VERSION,
        "units": "mm, mm/s, s, degrees; machine coordinates",
        "initial_state": {
            "units": "G21",
            "feed": 0.0,
            "start": [0.0] * 6,
            "block_delete": True,
            "tool_table": "tests/programs/real/tools.tbl",
            "parameters": "tests/programs/real/params.var",
        },
        "accepted": accepted,
        "error": None
        if accepted
        else {
            "line": last_line,
            "message": message.replace(ROOT + os.sep, ""),
        },
        "record": alignment,
        "tolerance_mm": tol_mm,
        "messages": canon.messages,
        # A refused program's moves are dropped, except when LinuxCNC only objects to a missing
        # program end (M2/M30/%): a reader that runs such a file to its end is compared with them.
        "moves": moves if accepted or eof_only else [],
    }
    return golden


def record_wrapped(path: str, ini: str) -> dict:
    """``rs274 -g -i INI`` alone on ``path`` (the ``gcode`` module reads no ini file, so
    ``[AXIS_A]WRAPPED_ROTARY`` reaches only rs274's interpreter): its moves, in program units
    and degrees to 4 decimals, taken to machine coordinates by the G5x and G92 offsets it
    prints before them (``SET_G5X_OFFSET``, ``SET_G92_OFFSET``: machine = printed + G92 +
    G5x; a program with an XY rotation is not recorded), and its refusal (message, refused
    block)."""
    with open(path, "rb") as fh:
        digest = hashlib.sha256(fh.read()).hexdigest()
    tmp = tempfile.mkdtemp(prefix="goldens-")
    try:
        res = subprocess.run(
            [RS274, "-g", "-i", os.path.abspath(ini), os.path.abspath(path)],
            cwd=tmp,
            capture_output=True,
            text=True,
            timeout=120,
            stdin=subprocess.DEVNULL,
            env=dict(os.environ, HOME=tmp),
        )
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    moves = []
    g5x, g92 = [0.0] * 6, [0.0] * 6
    for raw in res.stdout.splitlines():
        m = _CALL.match(raw)
        if m and m.group(1) == "SET_G5X_OFFSET":
            g5x = [float(v) for v in m.group(2).split(",")[1:7]]
        elif m and m.group(1) == "SET_G92_OFFSET":
            g92 = [float(v) for v in m.group(2).split(",")[:6]]
        elif m and m.group(1) == "SET_XY_ROTATION" and float(m.group(2)) != 0.0:
            raise SystemExit(f"{path}: an XY rotation: not recorded (machine = printed + offsets)")
        elif m and m.group(1) in ("STRAIGHT_TRAVERSE", "STRAIGHT_FEED"):
            printed = [float(v) for v in m.group(2).split(",")]
            end = [round(p + a + b, 4) for p, a, b in zip(printed, g92, g5x)]
            moves.append({"kind": _MOTION[m.group(1)], "end": end})
    err = [t.strip() for t in res.stderr.splitlines() if t.strip()]
    refused = len(err) >= 3  # "executing", the message, the refused block
    return {
        "program": os.path.relpath(os.path.abspath(path), ROOT),
        "sha256": digest,
        "linuxcnc": LINUXCNC_VERSION,
        "ini": os.path.relpath(os.path.abspath(ini), ROOT),
        "units": "rs274 -g as printed plus its offsets: machine coordinates, program units "
        "(mm), degrees, 4 decimals",
        "accepted": not refused,
        "error": {"message": err[-2], "block": err[-1]} if refused else None,
        "moves": moves,
    }


def record_wrapped_dir(program_dir: str, golden_dir: str, ini: str) -> None:
    """Every *.ngc of ``program_dir`` through :func:`record_wrapped`, one golden each."""
    os.makedirs(golden_dir, exist_ok=True)
    for name in sorted(f for f in os.listdir(program_dir) if f.endswith(".ngc")):
        golden = record_wrapped(os.path.join(program_dir, name), ini)
        with open(os.path.join(golden_dir, golden_name(name) + ".json"), "w") as fh:
            fh.write(golden_text(golden))
        print(f"{'ok ' if golden['accepted'] else 'ERR'} {name}: {len(golden['moves'])} moves")


def golden_text(golden: dict) -> str:
    """JSON with one compact move per line (diffable, and small enough to commit)."""
    head = json.dumps({k: v for k, v in golden.items() if k != "moves"}, indent=1)
    moves = ",\n".join(json.dumps(m, separators=(",", ":")) for m in golden["moves"])
    return head[:-2] + ',\n "moves": [\n' + moves + "\n]\n}\n"


def golden_name(rel_program: str) -> str:
    """``linuxcnc/nc_files/cds.ngc`` → ``linuxcnc__nc_files__cds``."""
    stem = os.path.splitext(rel_program)[0]
    return stem.replace("/", "__")


def manifest_programs() -> list[str]:
    """Program paths (relative to tests/programs/real) the manifest marks as programs."""
    with open(MANIFEST) as fh:
        entries = json.load(fh)["files"]
    return [e["path"] for e in entries if e["role"] != "subroutine"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", help="record only programs whose path contains this text")
    ap.add_argument("--stdout", metavar="FILE", help="record FILE and print its golden")
    ap.add_argument("--json-out", metavar="OUT", help="with --stdout: write the golden to OUT")
    ap.add_argument(
        "--programs", metavar="DIR", help="record every *.ngc of DIR (not the manifest)"
    )
    ap.add_argument("--goldens", metavar="DIR", help="with --programs: where the goldens go")
    ap.add_argument(
        "--rotary", action="store_true", help="also record the feed mode and canon rate"
    )
    ap.add_argument(
        "--wrapped-ini", metavar="INI", help="with --programs: rs274 -g -i INI only (wrapped A)"
    )
    args = ap.parse_args(argv)
    if args.wrapped_ini:
        record_wrapped_dir(args.programs, args.goldens, args.wrapped_ini)
        return 0
    tools = read_tool_table(TOOLS)
    if args.stdout:
        load_tool_database(TOOLS)
        golden = record(args.stdout, tools, args.rotary)
        if args.json_out:  # the interpreter may print (PRINT, ...) comments on stdout
            with open(args.json_out, "w") as fh:
                json.dump(golden, fh)
        else:
            json.dump(golden, sys.stdout)
        return 0
    golden_dir, program_dir, programs = GOLDEN, REAL, manifest_programs()
    if args.programs:
        program_dir, golden_dir = os.path.abspath(args.programs), os.path.abspath(args.goldens)
        programs = sorted(f for f in os.listdir(program_dir) if f.endswith(".ngc"))
    os.makedirs(golden_dir, exist_ok=True)
    counts = {"accepted": 0, "refused": 0, "crashed": 0}
    for rel in programs:
        if args.only and args.only not in rel:
            continue
        # One process per program: LinuxCNC's interpreter keeps state between parses (G10 L1
        # rewrites the tool table), and a crash of the module must not take the others along.
        out = os.path.join(golden_dir, golden_name(rel) + ".tmp")
        res = subprocess.run(
            [
                sys.executable,
                os.path.abspath(__file__),
                "--stdout",
                os.path.join(program_dir, rel),
                "--json-out",
                out,
                *(["--rotary"] if args.rotary else []),
            ],
            capture_output=True,
            text=True,
        )
        if res.returncode != 0 or not os.path.exists(out):
            print(f"CRASH {rel}: exit {res.returncode}, no golden written: {res.stderr[-1500:]}")
            counts["crashed"] += 1
            continue
        with open(out) as fh:
            golden = json.load(fh)
        os.remove(out)
        counts["accepted" if golden["accepted"] else "refused"] += 1
        with open(os.path.join(golden_dir, golden_name(rel) + ".json"), "w") as fh:
            fh.write(golden_text(golden))
        state = "ok " if golden["accepted"] else "ERR"
        print(
            f"{state} {rel}: {len(golden['moves'])} moves, {golden['record']}"
            + (
                ""
                if golden["accepted"]
                else f" — line {golden['error']['line']}: {golden['error']['message'][:100]}"
            )
        )
    print(
        f"{counts['accepted']} accepted, {counts['refused']} refused by LinuxCNC, "
        f"{counts['crashed']} crashed the recorder"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
