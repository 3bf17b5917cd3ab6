"""LinuxCNC's canon callbacks recorded (``gcode.parse``'s canon object) and its tool database.

Part of ``tools/record_goldens.py`` (its docstring gives the units and the initial state):
the :class:`Recorder` collects the moves in machine mm; :func:`load_tool_database` gives
LinuxCNC 2.9's interpreter its tool table. Run under the system Python with LinuxCNC's
modules; nurbscnc is not imported.
"""

from __future__ import annotations

import atexit
import ctypes
import math
import os
import shutil
import tempfile

INCH_MM = 25.4

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


class _ToolEntry(ctypes.Structure):
    """LinuxCNC's CANON_TOOL_TABLE (112 bytes), copied as raw bytes."""

    _fields_ = [("raw", ctypes.c_char * 112)]


_TOOLDATA = None  # libtooldata, once loaded


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
