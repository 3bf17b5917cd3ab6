"""Record LinuxCNC's canonical moves for a program, in mm: ``/usr/bin/python3 THIS FILE.ngc``.

Runs under the system Python that has LinuxCNC's ``gcode`` module (its interpreter, full
precision through canon callbacks) and prints JSON: ``{"moves": [...], "error": ...}``.
The machine is a mm machine starting in G21 (as nurbscnc assumes). The gcode module hands
canon calls program coordinates in inches; the offsets LinuxCNC
reports (set_g5x_offset, set_g92_offset, set_xy_rotation) are applied here as its own
``rs274.interpret.Translated`` does (g92, then the XY rotation, then g5x), so the moves are
machine positions in mm, as nurbscnc's segments are. Tool table: :data:`TOOLS_MM`.
Used by tests/test_interpret_linuxcnc.py (to record goldens and for the live check).
"""

import json
import math
import sys

IN = 25.4
#: The tool table (LinuxCNC and nurbscnc): number → (Z offset, diameter) [mm].
TOOLS_MM = {1: (5.0, 6.0), 2: (3.0, 4.0)}


class Canon:
    parameter_file = ""

    def __init__(self):
        self.out = []
        self.line = 0
        self.g5x = [0.0] * 3
        self.g92 = [0.0] * 3
        self.rot = 0.0
        self.feed = 0.0
        self.plane = 1
        self.tlo = [0.0] * 3
        self.feed_mode = 0  # CANON_FEED_MODE: 0 units/min, 1 inverse time, 2 units/rev

    def next_line(self, st):
        self.line = st.sequence_number

    def get_external_angular_units(self):
        return 1.0

    def get_external_length_units(self):
        return 1.0  # a mm machine (parameters #5xxx in mm)

    def get_axis_mask(self):
        return 63

    def get_block_delete(self):
        return 1

    def check_abort(self):
        return False

    def get_tool(self, t):
        z, d = TOOLS_MM.get(t, (0.0, 0.0))
        return (t, 0.0, 0.0, z / IN, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, d / IN, 0.0, 0.0, 0)

    def change_tool(self, *a):
        pass

    def comment(self, *a):
        pass

    def message(self, *a):
        pass

    def set_plane(self, p):
        self.plane = p

    def set_feed_rate(self, f):
        self.feed = f

    def set_feed_mode(self, *a):
        self.feed_mode = a[-1]

    def set_traverse_rate(self, *a):
        pass

    def user_defined_function(self, num, p, q):
        self.out.append({"kind": "user", "line": self.line, "m": num})

    def tool_offset(self, *a):
        self.tlo = [a[0] * IN, a[1] * IN, a[2] * IN]

    def set_g5x_offset(self, index, *a):
        self.g5x = [v * IN for v in a[:3]]

    def set_g92_offset(self, *a):
        self.g92 = [v * IN for v in a[:3]]

    def set_xy_rotation(self, r):
        self.rot = r

    def machine(self, p):
        x, y, z = (p[0] * IN + self.g92[0], p[1] * IN + self.g92[1], p[2] * IN + self.g92[2])
        if self.rot:
            c, s = math.cos(math.radians(self.rot)), math.sin(math.radians(self.rot))
            x, y = c * x - s * y, s * x + c * y
        return [
            x + self.g5x[0] + self.tlo[0],
            y + self.g5x[1] + self.tlo[1],
            z + self.g5x[2] + self.tlo[2],
        ]

    def straight_traverse(self, *a):
        self.out.append({"kind": "rapid", "line": self.line, "end": self.machine(a)})

    def straight_feed(self, *a):
        self.out.append(
            {
                "kind": "line",
                "line": self.line,
                "end": self.machine(a),
                "feed_mm_min": self.feed * IN,
                "feed_mode": self.feed_mode,
            }
        )

    def straight_probe(self, *a):
        self.out.append({"kind": "probe", "line": self.line})

    def rigid_tap(self, *a):
        self.out.append({"kind": "tap", "line": self.line})

    def dwell(self, t):
        self.out.append({"kind": "dwell", "line": self.line, "seconds": t})

    def arc_feed(self, e1, e2, c1, c2, turn, e3, *rest):
        # LinuxCNC's plane numbering: 1 XY (e1 = x), 2 YZ (e1 = y), 3 XZ (e1 = z).
        if self.plane == 1:
            end, cen = [e1, e2, e3], [c1, c2, e3]
        elif self.plane == 2:
            end, cen = [e3, e1, e2], [e3, c1, c2]
        else:
            end, cen = [e2, e3, e1], [c2, e3, c1]
        self.out.append(
            {
                "kind": "arc",
                "line": self.line,
                "end": self.machine(end),
                "center": self.machine(cen),
                "turn": turn,
                "feed_mm_min": self.feed * IN,
                "feed_mode": self.feed_mode,
            }
        )


def record(path):
    import gcode

    canon = Canon()
    try:
        result = gcode.parse(path, canon, "G21", "")  # a mm machine starts in G21
        error = None
        if isinstance(result, tuple) and result and result[0] >= 4:  # not open, error
            error = {"code": result[0], "line": result[1]}
    except Exception as exc:  # noqa: BLE001 - reported as data
        error = {"exception": str(exc)}
    return {"moves": canon.out, "error": error}


if __name__ == "__main__":
    print(json.dumps(record(sys.argv[1])))


def record_rs274(path, tool_table):
    """The same moves from LinuxCNC's stand-alone ``rs274 -t TABLE -g FILE`` (4 decimals).

    Used where the gcode module cannot go: it reads tool data from LinuxCNC's shared tool
    database, absent outside a running LinuxCNC (a T word crashes it), while rs274 reads a
    tool table file. rs274's machine unit is the inch (tool table values are inches) and it
    prints program coordinates (mm here) without the tool length offset, which is added.
    Its CHANGE_TOOL (M6) is a pause.
    """
    import re
    import subprocess

    out = subprocess.run(
        ["rs274", "-t", str(tool_table), "-g", str(path)],
        capture_output=True,
        text=True,
        check=False,
    ).stdout
    numbers = re.compile(r"-?\d+\.\d+")
    tlo = [0.0, 0.0, 0.0]
    moves = []
    for text in out.splitlines():
        if "USE_TOOL_LENGTH_OFFSET(" in text:
            tlo = [float(v) for v in numbers.findall(text)[:3]]
        if "CHANGE_TOOL(" in text:  # M6: the machine stops for the tool change
            moves.append({"kind": "pause", "code": "M6"})
        for call, kind in (("STRAIGHT_TRAVERSE(", "rapid"), ("STRAIGHT_FEED(", "line")):
            if call in text:
                p = [float(v) for v in numbers.findall(text.split(call, 1)[1])[:3]]
                moves.append({"kind": kind, "end": [p[k] + tlo[k] for k in range(3)]})
    return {"moves": moves, "error": None if "PROGRAM_END" in out else "no PROGRAM_END"}
