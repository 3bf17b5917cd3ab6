"""Interpret parsed blocks with RS274/NGC modal state into path segments.

Input: the blocks of :func:`nurbscnc.program.parse.parse_text` and the source lines; output:
a :class:`~nurbscnc.geometry.segments.Program` of Line / Arc / Nurbs / Dwell segments in
absolute mm with feeds in mm/s. The rules follow LinuxCNC's interpreter (modal groups, the
order of execution within a block, G5.2 and G6.2 NURBS blocks); every departure is a
documented decision and every refusal an error naming the word.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from nurbscnc.errors import GeometryError, ProgramError, SourcePos, UnsupportedError
from nurbscnc.geometry.segments import (
    PLANE_AXES,
    PLANE_NORMALS,
    Arc,
    Dwell,
    Line,
    Note,
    Nurbs,
    Program,
    frozen_array,
    vec3,
)
from nurbscnc.program.parse import Block, parse_text

INCH_MM = 25.4

# G codes as integers (value × 10) and their modal groups, as LinuxCNC numbers them.
_G_GROUP = {
    0: 1, 10: 1, 20: 1, 30: 1, 52: 1, 53: 1, 62: 1, 800: 1,
    40: 0, 530: 0,
    170: 2, 180: 2, 190: 2,
    900: 3, 910: 3,
    901: 4, 911: 4,
    930: 5, 940: 5,
    200: 6, 210: 6,
    400: 7,
    430: 8, 490: 8,
    540: 12, 550: 12, 560: 12, 570: 12, 580: 12, 590: 12,
    610: 13, 611: 13, 640: 13,
    960: 14, 970: 14,
}  # fmt: skip

# G codes that are RS274/NGC but deliberately not executed: the error names the word.
_G_UNSUPPORTED = {
    50: "G5 (cubic spline)",
    51: "G5.1 (quadratic spline)",
    70: "G7 (lathe diameter mode)",
    80: "G8 (lathe radius mode)",
    100: "G10 (set tool/offset data)",
    280: "G28 (return to home)",
    281: "G28.1 (set home)",
    300: "G30 (return to second home)",
    301: "G30.1 (set second home)",
    330: "G33 (spindle-synchronised motion)",
    331: "G33.1 (rigid tapping)",
    382: "G38.2 (probing)",
    383: "G38.3 (probing)",
    384: "G38.4 (probing)",
    385: "G38.5 (probing)",
    410: "G41 (cutter radius compensation)",
    411: "G41.1 (cutter radius compensation)",
    420: "G42 (cutter radius compensation)",
    421: "G42.1 (cutter radius compensation)",
    431: "G43.1 (dynamic tool length offset)",
    432: "G43.2 (additional tool length offset)",
    591: "G59.1 (coordinate system)",
    592: "G59.2 (coordinate system)",
    593: "G59.3 (coordinate system)",
    730: "G73 (canned cycle)",
    760: "G76 (threading cycle)",
    920: "G92 (coordinate offset)",
    921: "G92.1 (coordinate offset)",
    922: "G92.2 (coordinate offset)",
    923: "G92.3 (coordinate offset)",
    950: "G95 (feed per revolution)",
    980: "G98 (canned cycle return)",
    990: "G99 (canned cycle return)",
    **{c: f"G{c // 10} (canned cycle)" for c in range(810, 900, 10)},
}

_M_GROUP = {0: 4, 1: 4, 2: 4, 30: 4, 60: 4, 6: 6, 3: 7, 4: 7, 5: 7, 7: 8, 8: 8, 9: 8}
_M_UNSUPPORTED_TEXT = "M{} is not supported"

_AXES = ("X", "Y", "Z")
_AXIS_INDEX = {"X": 0, "Y": 1, "Z": 2}
_PLANE_OF_G = {170: "XY", 180: "ZX", 190: "YZ"}
_NORMAL_AXIS = {"XY": 2, "ZX": 1, "YZ": 0}
_CENTER_LETTER = {0: "I", 1: "J", 2: "K"}

# RS274/NGC tolerances for arcs whose end radius differs from the start radius (LinuxCNC:
# absolute 0.005 mm / 0.0005 in, relative 0.1 %; beyond 100x the absolute one always an
# error). Within them the arc becomes a spiral whose radius changes linearly with angle.
_ARC_ABS_TOL_MM = 0.005
_ARC_ABS_TOL_IN = 0.0005
_ARC_REL_TOL = 0.001

_FIRST_POINT_TOL_MM = 1e-6


@dataclass(frozen=True)
class InterpretOptions:
    """Settings outside the program: start point [mm], block delete switch, tool table.

    ``tool_lengths_mm`` maps a tool number to its length offset [mm] (G43 H uses it).
    """

    start_mm: tuple = (0.0, 0.0, 0.0)
    block_delete: bool = True
    tool_lengths_mm: dict | None = None
    name: str = "<program>"


def interpret_text(text: str, options: InterpretOptions | None = None) -> Program:
    """Parse and interpret a whole program text (see :func:`interpret`)."""
    if text.startswith("\ufeff"):
        text = text[1:]
    blocks = parse_text(text)
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    return interpret(blocks, lines, options or InterpretOptions())


@dataclass
class _NurbsBuild:
    """A NURBS block being collected line by line (G5.2 ... G5.3, or G6.2 ...)."""

    kind: str  # "G5.2" or "G6.2"
    line: int
    plane: str
    feed_mm_s: float
    order: int = 3
    points: list = field(default_factory=list)
    weights: list = field(default_factory=list)
    knots: list = field(default_factory=list)
    knot_lines: list = field(default_factory=list)
    point_lines: list = field(default_factory=list)
    knot_only: int = 0


class _Interpreter:
    """The modal state machine. One instance per call of :func:`interpret` (local state)."""

    def __init__(self, lines, options: InterpretOptions):
        self.lines = lines
        self.options = options
        self.pos = list(map(float, options.start_mm))
        self.motion = None  # None (no mode), or a G code ×10: 0, 10, 20, 30, 52, 62, 800
        self.plane = "XY"
        self.scale = 1.0  # mm per program unit (25.4 under G20)
        self.absolute = True
        self.arc_absolute = False  # G90.1
        self.feed_mm_s = 0.0
        self.tool_offset_mm = 0.0  # along Z, from G43
        self.blend_mm = 0.0  # G64 P tolerance [mm]; 0: exact stop at corners (G61, G64 alone)
        self.params: dict[int, float] = {}
        self.named: dict[str, float] = {}
        self.segments: list = []
        self.notes: list[Note] = []
        self.nurbs: _NurbsBuild | None = None
        self.noted: set = set()
        self.line_no = 0
        self.ended = False

    # -- errors and notes -------------------------------------------------------------------
    def error(self, message: str, column: int = 1, cls=ProgramError):
        text = self.lines[self.line_no - 1] if 0 < self.line_no <= len(self.lines) else ""
        return cls(message, SourcePos(self.line_no, max(column, 1), text))

    def note_once(self, key, message: str):
        if key not in self.noted:
            self.noted.add(key)
            self.notes.append(Note(self.line_no, message))

    # -- expressions --------------------------------------------------------------------------
    def evaluate(self, value, column: int) -> float:
        if type(value) is float:
            return value
        try:
            result = self._eval(value, column)
        except OverflowError:
            raise self.error("arithmetic overflow in expression", column) from None
        if not math.isfinite(result):
            raise self.error("expression value is not finite (overflow)", column)
        return result

    def _eval(self, v, column: int) -> float:
        if type(v) is float:
            return v
        tag = v[0]
        if tag == "#":
            index_f = self._eval(v[1], column)
            index = int(round(index_f))
            if not 1 <= index <= 5602:
                raise self.error(f"parameter number #{index_f:g} out of range 1..5602", column)
            return self.params.get(index, 0.0)
        if tag == "<":
            if v[1] not in self.named:
                raise self.error(f"named parameter #<{v[1]}> is not defined", column)
            return self.named[v[1]]
        if tag == "neg":
            return -self._eval(v[1], column)
        # Leaves (numbers, parameters) are finite, so checking each operation's result keeps
        # every intermediate finite: SIN, ROUND or a parameter index never sees inf or nan.
        if tag == "op":
            r = self._binop(v[1], self._eval(v[2], column), self._eval(v[3], column), column)
        elif tag == "fn":
            r = self._func(v[1], self._eval(v[2], column), column)
        elif tag == "atan":
            r = math.degrees(math.atan2(self._eval(v[1], column), self._eval(v[2], column)))
        else:
            r = None
        if r is not None:
            if not math.isfinite(r):
                raise self.error("expression value is not finite (overflow)", column)
            return r
        if tag == "exists":
            return 1.0 if v[1] in self.named else 0.0
        raise AssertionError(f"unknown expression {v!r}")  # pragma: no cover

    def _binop(self, op: str, a: float, b: float, column: int) -> float:
        if op == "+":
            return a + b
        if op == "-":
            return a - b
        if op == "*":
            return a * b
        if op == "/":
            if b == 0.0:
                raise self.error("division by zero", column)
            return a / b
        if op == "MOD":
            if b == 0.0:
                raise self.error("MOD by zero", column)
            r = math.fmod(a, b)
            return r + abs(b) if r < 0.0 else r  # LinuxCNC: result in [0, |b|)
        if op == "**":
            if a < 0.0 and b != int(b):
                raise self.error("negative number raised to a non-integer power", column)
            if a == 0.0 and b < 0.0:
                raise self.error("zero raised to a negative power", column)
            return float(a**b)
        if op in ("EQ", "NE", "GT", "GE", "LT", "LE"):
            return float(
                {"EQ": a == b, "NE": a != b, "GT": a > b, "GE": a >= b, "LT": a < b, "LE": a <= b}[
                    op
                ]
            )
        if op == "AND":
            return float(a != 0.0 and b != 0.0)
        if op == "OR":
            return float(a != 0.0 or b != 0.0)
        if op == "XOR":
            return float((a != 0.0) != (b != 0.0))
        raise AssertionError(op)  # pragma: no cover

    def _func(self, name: str, x: float, column: int) -> float:
        if name == "SIN":
            return math.sin(math.radians(x))
        if name == "COS":
            return math.cos(math.radians(x))
        if name == "TAN":
            return math.tan(math.radians(x))
        if name in ("ASIN", "ACOS"):
            if not -1.0 <= x <= 1.0:
                raise self.error(f"{name} argument {x:g} outside [-1, 1]", column)
            return math.degrees(math.asin(x) if name == "ASIN" else math.acos(x))
        if name == "SQRT":
            if x < 0.0:
                raise self.error(f"SQRT of a negative number ({x:g})", column)
            return math.sqrt(x)
        if name == "ABS":
            return abs(x)
        if name == "EXP":
            return math.exp(x)
        if name == "LN":
            if x <= 0.0:
                raise self.error(f"LN of a non-positive number ({x:g})", column)
            return math.log(x)
        if name == "ROUND":
            return float(math.floor(abs(x) + 0.5)) * (1.0 if x >= 0 else -1.0)
        if name == "FIX":
            return float(math.floor(x))
        if name == "FUP":
            return float(math.ceil(x))
        raise AssertionError(name)  # pragma: no cover

    # -- the block ----------------------------------------------------------------------------
    def run(self, blocks) -> None:
        percent_seen = False
        for index, block in enumerate(blocks):
            self.line_no = index + 1
            if block.percent:
                if percent_seen:
                    break  # the second % ends the tape
                percent_seen = True
                continue
            if block.delete and self.options.block_delete:
                continue
            if block.words or block.assigns or block.comments:
                self.block(block)
            if self.ended:
                break
        if self.nurbs is not None:
            build = self.nurbs
            self.line_no = build.line
            if build.kind == "G5.2":
                raise self.error("G5.2 NURBS block has no closing G5.3")
            raise self.error(
                f"G6.2 NURBS block ends with {len(build.knots)} knots; "
                f"knot count must equal control points + order "
                f"({len(build.points)} + {build.order} = {len(build.points) + build.order})"
            )

    def block(self, block: Block) -> None:
        for _, text, _column in block.comments:
            body = text[1:-1].strip() if text.startswith("(") else ""
            if body[:4].upper() == "MSG,":
                self.notes.append(Note(self.line_no, f"message: {body[4:].strip()}"))

        words: dict[str, tuple[float, int]] = {}
        gcodes: dict[int, tuple[int, int]] = {}  # group -> (code, column)
        mcodes: dict[int, tuple[int, int]] = {}
        for letter, raw, column in block.words:
            value = self.evaluate(raw, column)
            if letter == "G":
                code = self._code(value, "G", column)
                if code == 22:
                    # LinuxCNC's own sample G5_Curva_Stella_v1_G5.ngc opens its NURBS block
                    # with "G2.2" and closes it with G5.3; we read it as G5.2 and say so.
                    self.note_once(
                        "g2.2", "G2.2 is not an RS274/NGC code; read as G5.2 (closed by G5.3)"
                    )
                    code = 52
                group = _G_GROUP.get(code)
                if group is None:
                    if code in _G_UNSUPPORTED:
                        raise self.error(
                            f"{_G_UNSUPPORTED[code]} is not supported", column, UnsupportedError
                        )
                    if code == 930:
                        raise self.error("inverse time feed (G93) is not supported", column)
                    raise self.error(f"unknown G code G{_fmt_code(code)}", column)
                if group in gcodes:
                    other = gcodes[group][0]
                    raise self.error(
                        f"G{_fmt_code(other)} and G{_fmt_code(code)} are in the same modal "
                        f"group ({group}) and cannot share a block",
                        column,
                    )
                gcodes[group] = (code, column)
            elif letter == "M":
                code = self._code(value, "M", column)
                if code % 10:
                    raise self.error(f"unknown M code M{code / 10:g}", column)
                code //= 10
                group = _M_GROUP.get(code)
                if group is None:
                    raise self.error(f"M{code} is not supported", column, UnsupportedError)
                if group in mcodes:
                    raise self.error(
                        f"M{mcodes[group][0]} and M{code} are in the same modal group "
                        f"({group}) and cannot share a block",
                        column,
                    )
                mcodes[group] = (code, column)
            else:
                if letter in words:
                    raise self.error(f"{letter} word repeated in the block", column)
                if letter in "ABCUVW":
                    raise self.error(
                        f"axis {letter} is not supported (nurbscnc drives X, Y and Z)",
                        column,
                        UnsupportedError,
                    )
                if letter == "O":
                    raise self.error(
                        "O-words (subroutines, loops, conditionals) are not supported",
                        column,
                        UnsupportedError,
                    )
                if letter == "E":
                    raise self.error(f"unknown word {letter}", column)
                if letter == "N":
                    raise self.error("N (line number) must start the line", column)
                if letter == "D":
                    raise self.error(
                        "D word (cutter compensation) is not supported", column, UnsupportedError
                    )
                words[letter] = (value, column)

        # Parameter assignments take effect at the end of the line (LinuxCNC): evaluate all
        # right-hand sides with the old values first.
        pending = []
        for target, raw, _ in block.assigns:
            value = self.evaluate(raw, 1)
            if target[0] == "#":
                index_f = self.evaluate(target[1], 1)
                index = int(round(index_f))
                if not 1 <= index <= 5602:
                    raise self.error(f"parameter number #{index_f:g} out of range 1..5602")
                pending.append((index, value))
            else:
                pending.append((target[1], value))

        self.execute(words, gcodes, mcodes)

        for key, value in pending:
            if type(key) is int:
                self.params[key] = value
            else:
                self.named[key] = value

    def _code(self, value: float, letter: str, column: int) -> int:
        if not 0.0 <= value < 1e6:  # value * 10 must stay a modest integer
            raise self.error(f"{letter}{value:g} is not a valid {letter} code", column)
        code = round(value * 10.0)
        if abs(value * 10.0 - code) > 1e-6:
            raise self.error(f"{letter}{value:g} is not a valid {letter} code", column)
        return int(code)

    # -- execution in RS274/NGC order ---------------------------------------------------------
    def execute(self, words: dict, gcodes: dict, mcodes: dict) -> None:
        used = set()
        motion_code = gcodes.get(1)
        nonmodal = gcodes.get(0)

        # Feed mode G93/G94.
        if 5 in gcodes and gcodes[5][0] == 930:
            raise self.error("inverse time feed (G93) is not supported", gcodes[5][1])
        # Units come before F in effect? No: RS274/NGC sets F (step 3) before units (step 11),
        # but F is interpreted in the units in force *after* the block (LinuxCNC scales the
        # feed when G20/G21 changes), so read units first.
        if 6 in gcodes:
            self.scale = INCH_MM if gcodes[6][0] == 200 else 1.0
        if "F" in words:
            f, col = words["F"]
            used.add("F")
            if f < 0:
                raise self.error(f"negative feed F{f:g}", col)
            self.feed_mm_s = f * self.scale / 60.0
            if not math.isfinite(self.feed_mm_s):
                raise self.error(f"feed F{f:g} is out of range", col)
        if "S" in words:
            used.add("S")
            if words["S"][0] < 0:
                raise self.error("negative spindle speed", words["S"][1])
        if "T" in words:
            used.add("T")
            t = words["T"][0]
            if t < 0 or t != int(t):
                raise self.error(f"tool number T{t:g} must be a non-negative integer")
        # Spindle, coolant, tool change: recorded, no motion effect.

        # Dwell (group 0, before motion).
        if nonmodal is not None and nonmodal[0] == 40:
            if "P" not in words:
                raise self.error("G4 dwell needs a P word (seconds)", nonmodal[1])
            seconds, col = words["P"]
            used.add("P")
            if seconds < 0:
                raise self.error(f"negative dwell time P{seconds:g}", col)
            self.segments.append(Dwell(float(seconds), tuple(self.pos), self.line_no))

        if 2 in gcodes:
            self.plane = _PLANE_OF_G[gcodes[2][0]]
        if 7 in gcodes:
            pass  # G40: compensation is off already
        if 8 in gcodes:
            code, col = gcodes[8]
            if code == 430:
                tool = words.get("H", words.get("T", (0.0, col)))[0]
                used.add("H")
                table = self.options.tool_lengths_mm
                if table is not None and int(tool) in table:
                    self.tool_offset_mm = float(table[int(tool)])
                else:
                    self.tool_offset_mm = 0.0
                    self.note_once(
                        ("tlo", int(tool)),
                        f"G43 H{int(tool)}: no tool table entry, tool length offset taken as 0",
                    )
            else:
                self.tool_offset_mm = 0.0
        if "H" in words and "H" not in used:
            raise self.error("H word with no G43 to use it", words["H"][1])
        if 12 in gcodes and gcodes[12][0] != 540:
            self.note_once(
                "g5x", "G55-G59: no work offsets are set, so coordinates are used as given"
            )
        if 13 in gcodes:
            code, col = gcodes[13]
            if code == 640:
                self.blend_mm = 0.0
                if "P" in words:
                    used.add("P")
                    if words["P"][0] < 0:
                        raise self.error("G64 P tolerance must be >= 0", words["P"][1])
                    self.blend_mm = words["P"][0] * self.scale
                if "Q" in words:
                    used.add("Q")
            else:
                self.blend_mm = 0.0  # G61 / G61.1: exact path, exact stops
        if 3 in gcodes:
            self.absolute = gcodes[3][0] == 900
        if 4 in gcodes:
            self.arc_absolute = gcodes[4][0] == 901

        machine_coords = nonmodal is not None and nonmodal[0] == 530
        if machine_coords:
            mode = motion_code[0] if motion_code else self.motion
            if mode not in (0, 10):
                raise self.error("G53 needs G0 or G1 in force", nonmodal[1])
            if not self.absolute:
                raise self.error("G53 cannot be used with G91 (incremental)", nonmodal[1])

        # Motion.
        if motion_code is not None:
            code, col = motion_code
            if self.nurbs is not None and code != self.nurbs_code():
                self.finish_nurbs_by_other(code, col)
            if code == 800:
                self.motion = None
                if any(a in words for a in _AXES):
                    raise self.error("axis words with G80 (motion cancelled)", col)
            else:
                self.motion = code
        has_axes = "X" in words or "Y" in words or "Z" in words
        if self.motion is None:
            if has_axes:
                letter = next(a for a in _AXES if a in words)
                raise self.error(
                    f"{letter} word with no motion mode in force (G0, G1, G2, G3, G5.2, G6.2)",
                    words[letter][1],
                )
        elif self.motion in (0, 10):
            if has_axes:
                self.straight(words, machine_coords)
        elif self.motion in (20, 30):
            if has_axes or motion_code is not None or any(k in words for k in "IJKR"):
                self.arc(words, used)
        elif self.motion == 52:
            self.g5(words, used, motion_code)
        elif self.motion == 53:
            self.g5_end(motion_code[1] if motion_code else 1)
        elif self.motion == 62:
            self.g6(words, used, motion_code)
        for letter in _AXES:
            used.add(letter)

        for letter, (_, col) in words.items():
            if letter not in used:
                raise self.error(_unused_word_message(letter), col)

        # Program stop / end (last in the block).
        if 4 in mcodes:
            code = mcodes[4][0]
            if code in (2, 30):
                if self.nurbs is not None:
                    self.finish_nurbs_by_other(None, mcodes[4][1])
                self.ended = True
            elif code == 60:
                raise self.error("M60 (pallet change) is not supported", mcodes[4][1])

    # -- targets --------------------------------------------------------------------------
    def target(self, words: dict, machine_coords: bool = False, base=None) -> list:
        """End point [mm] of a move: axis words in the current units and distance mode."""
        base = self.pos if base is None else base
        out = list(base)
        for i, letter in enumerate(_AXES):
            if letter in words:
                v = words[letter][0] * self.scale
                if machine_coords:
                    out[i] = v
                elif self.absolute:
                    out[i] = v + (self.tool_offset_mm if i == 2 else 0.0)
                else:
                    out[i] = base[i] + v
                if not math.isfinite(out[i]):  # G20 scaling or G91 sums can overflow
                    raise self.error(f"{letter} coordinate is out of range", words[letter][1])
        return out

    def straight(self, words: dict, machine_coords: bool) -> None:
        end = self.target(words, machine_coords)
        rapid = self.motion == 0
        if not rapid and self.feed_mm_s <= 0.0:
            raise self.error("G1 move with zero feed (set F first)", 1)
        if end != self.pos:
            self.segments.append(
                Line(tuple(self.pos), tuple(end), 0.0 if rapid else self.feed_mm_s,
                     self.line_no, rapid, self.blend_mm)
            )  # fmt: skip
        self.pos = end

    def arc(self, words: dict, used: set) -> None:
        plane = self.plane
        a, b = PLANE_AXES[plane]
        n_axis = _NORMAL_AXIS[plane]
        col0 = min((c for _, c in words.values()), default=1)
        if self.feed_mm_s <= 0.0:
            raise self.error("arc move with zero feed (set F first)", col0)
        start = self.pos
        end = self.target(words)
        ijk = [k for k in "IJK" if k in words]
        for k in "IJKR":
            used.add(k)
        if "R" in words and ijk:
            raise self.error("arc with both R and I/J/K words", words["R"][1])
        wrong = _CENTER_LETTER[n_axis]
        if wrong in words:
            raise self.error(
                f"{wrong} word given for an arc in the {plane} plane", words[wrong][1]
            )
        turns = 1
        if "P" in words:
            used.add("P")
            p, pcol = words["P"]
            if p != int(p) or p < 1:
                raise self.error(f"arc turns P{p:g} must be a positive integer", pcol)
            turns = int(p)
        ccw = self.motion == 30
        sa, sb = start[a], start[b]
        ea, eb = end[a], end[b]
        abs_tol = _ARC_ABS_TOL_IN * INCH_MM if self.scale != 1.0 else _ARC_ABS_TOL_MM
        if "R" in words:
            r_signed = words["R"][0] * self.scale
            r = abs(r_signed)
            chord = math.hypot(ea - sa, eb - sb)
            if chord < 1e-12:
                raise self.error("full circle in radius format (R) is not allowed", words["R"][1])
            if r == 0.0:
                raise self.error("arc radius R is zero", words["R"][1])
            half = chord / 2.0
            if half > r:
                if half - r > abs_tol:
                    raise self.error(
                        f"arc radius R{abs(words['R'][0]):g} is smaller than half the distance "
                        f"to the end point",
                        words["R"][1],
                    )
                r = half
            # Centre on the perpendicular bisector; which side follows from direction and the
            # sign of R (negative R: the arc longer than a half circle).
            # sqrt(r² − half²) as a product: r² alone overflows for |R| > 1e154.
            h = math.sqrt(max(r - half, 0.0)) * math.sqrt(r + half)
            ma, mb = (sa + ea) / 2.0, (sb + eb) / 2.0
            ua, ub = (ea - sa) / chord, (eb - sb) / chord
            side = (1.0 if ccw else -1.0) * (1.0 if r_signed > 0 else -1.0)
            ca, cb = ma - side * ub * h, mb + side * ua * h
        else:
            if not ijk:
                raise self.error("arc with neither R nor I/J/K words", col0)
            offsets = {}
            for axis in (a, b):
                letter = _CENTER_LETTER[axis]
                if letter in words:
                    offsets[axis] = words[letter][0] * self.scale
                elif self.arc_absolute:
                    raise self.error(f"{letter} word missing in absolute center arc", col0)
                else:
                    offsets[axis] = 0.0
            if self.arc_absolute:
                ca, cb = offsets[a], offsets[b]
            else:
                ca, cb = sa + offsets[a], sb + offsets[b]
        r0 = math.hypot(sa - ca, sb - cb)
        r1 = math.hypot(ea - ca, eb - cb)
        if not all(map(math.isfinite, (ca, cb, r0, r1))):
            raise self.error("arc centre or radius is out of range", col0, GeometryError)
        if r0 < 1e-9:
            raise self.error("arc radius is zero (centre at the start point)", col0)
        err = abs(r1 - r0)
        rel = err / max(r0, r1)
        if err > 100.0 * abs_tol or (rel > _ARC_REL_TOL and err > abs_tol):
            raise self.error(
                f"radius to end of arc ({r1:.6g} mm) differs from radius to start "
                f"({r0:.6g} mm) by {err:.4g} mm",
                col0,
                GeometryError,
            )
        t0 = math.atan2(sb - cb, sa - ca)
        t1 = math.atan2(eb - cb, ea - ca)
        sweep = t1 - t0
        full = math.hypot(ea - sa, eb - sb) < 1e-12
        if ccw:
            if sweep <= 0.0 or full:
                sweep += 2.0 * math.pi
            if full:
                sweep = 2.0 * math.pi
            sweep += 2.0 * math.pi * (turns - 1)
        else:
            if sweep >= 0.0 or full:
                sweep -= 2.0 * math.pi
            if full:
                sweep = -2.0 * math.pi
            sweep -= 2.0 * math.pi * (turns - 1)
        if not math.isfinite(sweep):
            raise self.error(f"arc turns P{turns} is out of range", col0, GeometryError)
        center = list(start)
        center[a], center[b] = ca, cb
        self.segments.append(
            Arc(
                start_mm=vec3(start),
                end_mm=vec3(end),
                center_mm=vec3(center),
                normal=vec3(PLANE_NORMALS[plane]),
                angle_rad=float(sweep),
                helix_mm=float(end[n_axis] - start[n_axis]),
                radius_start_mm=float(r0),
                radius_end_mm=float(r1),
                feed_mm_s=self.feed_mm_s,
                line=self.line_no,
                plane=plane,
                blend_mm=self.blend_mm,
            )
        )
        self.pos = end

    # -- NURBS: LinuxCNC G5.2 ... G5.3 --------------------------------------------------------
    def nurbs_code(self) -> int:
        return 52 if self.nurbs.kind == "G5.2" else 62

    def finish_nurbs_by_other(self, code, column) -> None:
        build = self.nurbs
        if build.kind == "G5.2":
            if code == 53:
                return
            raise self.error(
                f"G5.2 NURBS block (line {build.line}) not closed by G5.3 before this block",
                column,
            )
        raise self.error(
            f"G6.2 NURBS block (line {build.line}) has {len(build.knots)} knots; knot count "
            f"must equal control points + order "
            f"({len(build.points)} + {build.order} = {len(build.points) + build.order})",
            column,
        )

    def plane_point(self, words: dict, base: list, first_line: bool) -> list | None:
        """A G5.2 control point: both in-plane axes required (LinuxCNC rule)."""
        a, b = PLANE_AXES[self.plane]
        la, lb = _AXES[a], _AXES[b]
        has_a, has_b = la in words, lb in words
        if has_a != has_b:
            col = words[la if has_a else lb][1]
            raise self.error(f"G5.2 control points need both {la} and {lb}", col)
        normal_letter = _AXES[_NORMAL_AXIS[self.plane]]
        if normal_letter in words:
            raise self.error(
                f"{normal_letter} word in a G5.2 block in the {self.plane} plane "
                f"(NURBS are planar)",
                words[normal_letter][1],
            )
        if not has_a:
            return None
        return self.target({la: words[la], lb: words[lb]}, base=base)

    def g5(self, words: dict, used: set, motion_code) -> None:
        used.update("PL")
        if self.nurbs is None or self.nurbs.kind != "G5.2":
            if self.feed_mm_s <= 0.0:
                col = motion_code[1] if motion_code else 1
                raise self.error("cannot make a NURBS with zero feed (set F first)", col)
            self.nurbs = _NurbsBuild("G5.2", self.line_no, self.plane, self.feed_mm_s)
            build = self.nurbs
            point = self.plane_point(words, self.pos, True)
            w0 = 1.0
            if point is None and "P" in words:
                w0 = words["P"][0]
            build.points.append(list(self.pos))
            build.weights.append(w0)
            build.point_lines.append(self.line_no)
            if "L" in words:
                order_f, lcol = words["L"]
                if order_f != int(order_f) or not 2 <= order_f <= 8:
                    raise self.error(f"NURBS order L{order_f:g} must be an integer in 2..8", lcol)
                if order_f > 3:
                    build.order = int(order_f)
                elif order_f < 3:
                    self.note_once(
                        ("L", self.line_no),
                        f"G5.2 L{int(order_f)}: LinuxCNC uses order 3 unless L > 3; order 3 used",
                    )
            if point is not None:
                self._g5_add(words, point)
            return
        build = self.nurbs
        if motion_code is not None and "L" in words:
            raise self.error("L word inside a G5.2 block (only on its first line)",
                             words["L"][1])  # fmt: skip
        if "L" in words:
            raise self.error("L word inside a G5.2 block (only on its first line)",
                             words["L"][1])  # fmt: skip
        point = self.plane_point(words, build.points[-1], False)
        if point is None:
            if "P" in words:
                raise self.error(
                    "P without X and Y is allowed only on the first line of G5.2",
                    words["P"][1],
                )
            return
        self._g5_add(words, point)

    def _g5_add(self, words: dict, point: list) -> None:
        if "P" not in words:
            a, b = PLANE_AXES[self.plane]
            raise self.error(
                "every G5.2 control point needs a positive weight P",
                words[_AXES[a]][1],
            )
        w, col = words["P"]
        if not w > 0.0:
            raise self.error(f"NURBS weight P{w:g} must be > 0", col)
        self.nurbs.points.append(point)
        self.nurbs.weights.append(w)
        self.nurbs.point_lines.append(self.line_no)

    def g5_end(self, column: int) -> None:
        build = self.nurbs
        if build is None or build.kind != "G5.2":
            raise self.error("G5.3 without G5.2 first", column)
        n = len(build.points)
        if n < build.order:
            raise self.error(
                f"G5.2 block has {n} control points; at least the order "
                f"L = {build.order} are needed",
                column,
            )
        knots = g5_knot_vector(n, build.order)
        self.emit_nurbs(build, knots, column)
        self.motion = None  # LinuxCNC: motion mode is cleared by G5.3

    # -- NURBS: G6.2 (Fanuc-style, LinuxCNC G6.2) --------------------------------------------
    def g6(self, words: dict, used: set, motion_code) -> None:
        used.update("KRPQ")
        build = self.nurbs
        has_axes = any(a in words for a in _AXES)
        if build is None:
            if "P" not in words:
                col = motion_code[1] if motion_code else 1
                raise self.error("G6.2 needs P<order> on its first line", col)
            order_f, pcol = words["P"]
            if order_f != int(order_f) or not 2 <= order_f <= 8:
                raise self.error(f"NURBS order P{order_f:g} must be an integer in 2..8", pcol)
            if self.feed_mm_s <= 0.0:
                raise self.error("cannot make a NURBS with zero feed (set F first)", pcol)
            if "Q" in words:
                self.note_once(("Q",), "G6.2 Q (approximation mode) is accepted and ignored")
            self.nurbs = build = _NurbsBuild(
                "G6.2", self.line_no, self.plane, self.feed_mm_s, order=int(order_f)
            )
            first = self.target(words) if has_axes else list(self.pos)
            dist = math.dist(first, self.pos)
            if dist > _FIRST_POINT_TOL_MM:
                raise self.error(
                    "the first G6.2 control point must be the current position "
                    f"({_fmt_point(self.pos)}); it is {dist:.6g} mm away",
                    min((c for _, c in words.values()), default=1),
                )
            self._g6_point(words, list(self.pos))
            return
        if "P" in words:
            raise self.error(
                "P (order) on a G6.2 line inside a NURBS block: the previous block "
                f"(line {build.line}) is not complete",
                words["P"][1],
            )
        if "Q" in words:
            self.note_once(("Q",), "G6.2 Q (approximation mode) is accepted and ignored")
        if has_axes or "R" in words:
            if build.knot_only:
                raise self.error(
                    "control point after knot-only K lines in a G6.2 block",
                    min(c for _, c in words.values()),
                )
            self._g6_point(words, self.target(words, base=build.points[-1]))
            return
        if "K" in words:
            self._g6_knot(words["K"])
            build.knot_only += 1
            if build.knot_only == build.order:
                self.emit_nurbs(build, build.knots, 1)
                self.motion = None
            return
        # A line with only F or nothing motion-related inside the block: nothing to do.

    def _g6_point(self, words: dict, point: list) -> None:
        build = self.nurbs
        if "K" not in words:
            col = min((c for _, c in words.values()), default=1)
            raise self.error("G6.2 control point without its knot K", col)
        if "R" in words:
            w, col = words["R"]
            if not w > 0.0:
                raise self.error(f"NURBS weight R{w:g} must be > 0", col)
        else:
            w = 1.0
        self._g6_knot(words["K"])
        build.points.append(point)
        build.weights.append(w)
        build.point_lines.append(self.line_no)

    def _g6_knot(self, kw) -> None:
        build = self.nurbs
        k, col = kw
        if build.knots and k < build.knots[-1]:
            raise self.error(
                f"knots must be non-decreasing: K{k:g} after K{build.knots[-1]:g}", col
            )
        build.knots.append(k)
        build.knot_lines.append(self.line_no)

    # -- common NURBS validation and output ---------------------------------------------------
    def emit_nurbs(self, build: _NurbsBuild, knots, column: int) -> None:
        n = len(build.points)
        order = build.order
        p = order - 1
        start_line = build.line
        here = self.line_no
        self.line_no = start_line
        try:
            if not 2 <= order <= 8:
                raise self.error(f"NURBS order {order} must be in 2..8")
            if order > n:
                raise self.error(
                    f"NURBS order {order} exceeds the number of control points ({n})"
                )
            k = np.asarray(knots, dtype=float)
            if k.size != n + order:
                raise self.error(
                    f"knot count {k.size} must equal control points + order ({n} + {order})"
                )
            if not np.all(np.isfinite(k)):
                raise self.error("knots must be finite")
            if np.any(np.diff(k) < 0):
                raise self.error("knots must be non-decreasing")
            if np.any(k[:order] != k[0]) or np.any(k[-order:] != k[-1]):
                raise self.error(
                    f"knot vector must be clamped: the first and last {order} knots equal"
                )
            if k[0] == k[-1]:
                raise self.error("all knots are equal")
            interior = k[order:-order]
            if interior.size:
                _, counts = np.unique(interior, return_counts=True)
                if counts.max() > p:
                    raise self.error(
                        f"an interior knot is repeated {counts.max()} times; "
                        f"at most the degree ({p}) is allowed"
                    )
            w = np.asarray(build.weights, dtype=float)
            if not np.all(np.isfinite(w)) or np.any(w <= 0):
                raise self.error("NURBS weights must be finite and > 0")
            if build.feed_mm_s <= 0.0:
                raise self.error("NURBS block with zero feed")
        finally:
            self.line_no = here
        seg = Nurbs(
            degree=p,
            knots=frozen_array(k),
            control_points_mm=frozen_array(build.points),
            weights=frozen_array(w),
            feed_mm_s=build.feed_mm_s,
            line=start_line,
            plane=build.plane,
            blend_mm=self.blend_mm,
        )
        self.segments.append(seg)
        self.pos = list(build.points[-1])
        self.nurbs = None


def g5_knot_vector(n_points: int, order: int) -> list[float]:
    """LinuxCNC's implied G5.2 knots (``nurbs_G5_knot_vector_creator``).

    With n = n_points − 1 and k = order: knot i (0 ≤ i ≤ n + k) is 0 for i < k, i − k + 1 for
    k ≤ i ≤ n and n − k + 2 beyond: clamped, uniform, integer-valued.
    """
    n, k = n_points - 1, order
    return [0.0 if i < k else float(i - k + 1) if i <= n else float(n - k + 2)
            for i in range(n + k + 1)]  # fmt: skip


def _fmt_code(code: int) -> str:
    return str(code // 10) if code % 10 == 0 else f"{code // 10}.{code % 10}"


def _fmt_point(p) -> str:
    return ", ".join(f"{v:.6g}" for v in p)


def _unused_word_message(letter: str) -> str:
    return {
        "I": "I word with no arc (G2/G3) to use it",
        "J": "J word with no arc (G2/G3) to use it",
        "K": "K word with no arc (G2/G3) or G6.2 NURBS to use it",
        "R": "R word with no arc (G2/G3) or G6.2 NURBS to use it",
        "P": "P word with no G4, G64, arc, G5.2 or G6.2 to use it",
        "Q": "Q word with no G64 or G6.2 to use it",
        "L": "L word with no G5.2 to use it",
        "H": "H word with no G43 to use it",
        "F": "F word not used",
    }.get(letter, f"{letter} word not used")


def interpret(blocks, lines, options: InterpretOptions) -> Program:
    """Turn parsed blocks into a :class:`Program` (pure: no I/O, no global state).

    ``lines`` are the source lines (for error messages). Raises :class:`ProgramError`
    subclasses carrying the line, column and source text.
    """
    state = _Interpreter(lines, options)
    state.run(blocks)
    return Program(
        segments=tuple(state.segments),
        start_mm=vec3(options.start_mm),
        notes=tuple(state.notes),
        blocks=sum(1 for b in blocks if b.words or b.assigns),
        name=options.name,
    )
