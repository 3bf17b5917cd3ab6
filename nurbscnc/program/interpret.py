"""Interpret G-code into path segments: the executor (LinuxCNC's interp_execute.cc order).

Input: a program text (parsed line by line as execution reaches it, see
:mod:`nurbscnc.program.control`); output: a :class:`~nurbscnc.geometry.segments.Program` of
Line / Arc / Nurbs / Dwell / Pause segments in absolute machine mm with feeds in mm/s. The
rules follow LinuxCNC 2.9's interpreter; every departure is a documented decision and every
refusal an error naming the word.

The jobs are split as LinuxCNC splits them: parsing (parse.py), expressions
(expressions.py), modal groups and state (modal.py), arcs (arcs.py), coordinate systems
(coords.py), O-word control flow (control.py), NURBS and splines (nurbsblock.py), tool
tables (tooltable.py); canned cycles (cycles.py) and cutter compensation (compensation.py)
plug in at :meth:`_Interpreter.canned_cycle` and :meth:`_Interpreter.compensate`.
"""

from __future__ import annotations

import itertools
import math
import operator
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from nurbscnc.errors import GeometryError, NurbsCncError, ProgramError, SourcePos, UnsupportedError
from nurbscnc.geometry.segments import (
    PLANE_AXES,
    PLANE_NORMALS,
    Arc,
    Dwell,
    Line,
    Note,
    Pause,
    Program,
    path_control,
    vec3,
)
from nurbscnc.program import arcs, coords, fastlane
from nurbscnc.program.compensation import MSG_ARC_AFTER_EXIT, CompMove, CutterComp
from nurbscnc.program.control import N_LOCAL, ControlFlow, Frame, Source
from nurbscnc.program.cycles import CycleState, TooManyMoves, expand_cycle
from nurbscnc.program.expressions import MAX_PARAMETER, ExpressionError, evaluate
from nurbscnc.program.fastlane import (
    BulkState,
    make_lines,
    nurbs_words,
    pause_cyclic_gc,
    plain_run,
)
from nurbscnc.program.modal import (
    CANNED_CYCLES,
    G_GROUP,
    G_OF_PLANE,
    G_REFUSED,
    INCH_MM,
    M_GROUP,
    PLANE_OF_G,
    SAVED_BY_M70,
    SYSTEM_OF_G,
    ModalState,
)
from nurbscnc.program.nurbsblock import NurbsBlocks, Splines, g5_knot_vector
from nurbscnc.program.parse import Block, split_lines
from nurbscnc.program.tooltable import Tool

__all__ = ["InterpretOptions", "interpret", "interpret_text", "g5_knot_vector", "INCH_MM"]

_AXES = ("X", "Y", "Z")
_NORMAL_AXIS = {"XY": 2, "ZX": 1, "YZ": 0}
_CENTER_LETTER = {0: "I", 1: "J", 2: "K"}
_PLAIN_WORDS = frozenset("XYZF")
_COMMON_CODES = {float(v): 10 * v for v in (0, 1, 2, 3, 17, 18, 19, 20, 21, 40, 49, 54, 80,
                                             90, 91, 94)}  # fmt: skip
# Bounds on values that are finite but no machine can act on (1e20 mm, a 1e300 s dwell): the
# error names the value instead of letting it overflow or stall a later stage.
MAX_COORD_MM = 1e9  # 1000 km
MAX_DWELL_S = 1e6  # 11.6 days
MAX_FEED_MM_MIN = 1e9
MIN_FEED_MM_MIN = 1e-9  # below: zero-like feeds (denormals such as 1e-321)
MAX_ARC_TURNS = 100_000


@dataclass(frozen=True)
class InterpretOptions:
    """Settings outside the program.

    ``start_mm`` start point [mm, machine]; ``block_delete`` the "/" switch; ``tools`` a
    tool table (``{number: Tool}``, see tooltable.py); ``tool_lengths_mm`` the older
    ``{number: Z length [mm]}`` form; ``load_subroutine(name)`` returns ``(text, file name)``
    of ``name.ngc`` for ``o<name> call`` or None (the CLI searches the program's directory
    and ``--subroutine-path``; the interpreter itself does no I/O); ``max_call_depth`` and
    ``max_loop_iterations`` bound O-word execution (a clear error past them);
    ``extra_lines`` and ``extra_moves`` bound what loops, calls and repeats (``L``) add to
    the program: at most that many executed lines, and moves, beyond one per line of the
    main program (memory grows with the program, not with what it repeats).
    """

    start_mm: tuple = (0.0, 0.0, 0.0)
    block_delete: bool = True
    tool_lengths_mm: dict | None = None
    name: str = "<program>"
    tools: dict | None = None
    load_subroutine: Callable[[str], tuple[str, str] | None] | None = None
    max_call_depth: int = 100
    max_loop_iterations: int = 250_000
    #: Measured here, 2026: a loop runs 0.7–1.4 M lines/s in `check`, and a move holds about
    #: 300 bytes until it is planned: 5 M lines take 3–7 s, 2 M moves 7–11 s and 0.65 GB.
    extra_lines: int = 5_000_000
    extra_moves: int = 2_000_000
    #: Interpret runs of plain G0/G1 lines in bulk (fastlane.py; same segments, faster).
    fast_lane: bool = True


def interpret_text(text: str, options: InterpretOptions | None = None) -> Program:
    """Interpret a whole program text (see :func:`interpret`)."""
    return interpret(None, split_lines(text), options or InterpretOptions())


class _Interpreter(ControlFlow, coords.OffsetCommands, NurbsBlocks, Splines):
    """The executor. One instance per call of :func:`interpret` (local state)."""

    def __init__(self, lines, options: InterpretOptions):
        self.options = options
        self.main = Source(lines, options.name)
        self.lines = lines
        self.m = ModalState()
        self.coords = coords.Coordinates()
        self.prog = list(map(float, options.start_mm))  # program position [mm]
        self.params: dict[int, float] = {}
        self.globals: dict[str, float] = {}
        self.frames = [Frame(self.main, 0)]
        self.source = self.main
        self.segments: list = []
        self.notes: list[Note] = []
        self.nurbs = None
        # G5 without I J: minus the last G5's (P, Q) [mm], (0, 0) before any (LinuxCNC's
        # cycle_i, cycle_j, kept across other moves)
        self.spline_pq = (0.0, 0.0)
        self.noted: set = set()
        self.line_no = 0
        self.ended = False
        self.loop_count = 0
        self.executed = 0  # lines executed, each pass of a loop anew
        self.max_executed = len(lines) + options.extra_lines
        self.max_moves = len(lines) + options.extra_moves
        self.program_name = ""
        self.loaded: dict[str, Source] = {}  # subroutine files read, by label
        self.m70_state = None  # modal state saved by M70
        self.axes_consumed = False  # the block's axis words were data (G43.1), not a move
        self.comp: CutterComp | None = None  # G41/G42 in force: the compensation stream
        self.comp_exit = None  # after G40: the compensated tool position [mm, machine]
        self.comp_plane = "XY"  # the plane of the compensation in force (XY or ZX)
        tools = dict(options.tools or {})
        for number, length in (options.tool_lengths_mm or {}).items():
            tools.setdefault(int(number), Tool(int(number), (0.0, 0.0, float(length))))
        self.tools = tools

    # -- position -------------------------------------------------------------------------
    @property
    def pos(self) -> list:
        """The current machine position [mm]."""
        return self.coords.to_machine(self.prog)

    @pos.setter
    def pos(self, machine) -> None:
        self.prog = self.coords.to_program(machine)

    @property
    def plane(self) -> str:
        return self.m.plane

    @property
    def motion(self):
        return self.m.motion

    @motion.setter
    def motion(self, code) -> None:
        self.m.motion = code

    @property
    def blend_mm(self) -> float:
        return self.m.blend_mm

    @property
    def scale(self) -> float:
        return self.m.scale

    @property
    def feed_mm_s(self) -> float:
        """The feed [mm/s] of G94 / G95 (G93 feeds depend on each move's length)."""
        m = self.m
        if m.feed_mode == 950:
            return m.feed_mm * m.spindle_rpm / 60.0
        return m.feed_mm / 60.0

    # -- errors and notes -------------------------------------------------------------------
    def error(self, message: str, column: int = 1, cls=ProgramError):
        source = self.source
        if source is self.main:
            text = self.lines[self.line_no - 1] if 0 < self.line_no <= len(self.lines) else ""
            return cls(message, SourcePos(self.line_no, max(column, 1), text))
        # In a called file: say where in it, and point at the main program's call line.
        line = self.main_line()
        return cls(
            f"{source.name}:{self.line_no}:{max(column, 1)}: {message}",
            SourcePos(line, 1, self.lines[line - 1] if 0 < line <= len(self.lines) else ""),
        )

    def main_line(self) -> int:
        """The main program's line that is executing (the call line inside a called file)."""
        if self.source is self.main:
            return self.line_no
        for frame in self.frames:
            if frame.source is not self.main:
                return frame.call_line
        return self.line_no

    def note_once(self, key, message: str):
        if key not in self.noted:
            self.noted.add(key)
            self.notes.append(Note(self.main_line(), message))

    # -- parameters -----------------------------------------------------------------------
    def read_numbered(self, index_f: float) -> float:
        index = self._param_index(index_f)
        if index <= N_LOCAL:
            return self.params.get(index, 0.0)
        if index == 5400:  # the tool in the spindle (before the offsets' range claims it)
            return float(self.m.tool_loaded)
        if coords.is_coordinate_parameter(index):
            return self.coords.read(index)
        if 5420 <= index <= 5422:
            return self.prog[index - 5420] / self.m.scale
        return self.params.get(index, 0.0)

    def write_numbered(self, index: int, value: float) -> None:
        if coords.is_coordinate_parameter(index):
            self.coords.write(index, value)
        else:
            self.params[index] = value

    def _param_index(self, index_f: float) -> int:
        index = int(round(index_f))
        if not 1 <= index <= MAX_PARAMETER:
            raise ExpressionError(f"parameter number #{index_f:g} out of range 1..{MAX_PARAMETER}")
        return index

    def read_named(self, name: str) -> float:
        if name.startswith("_"):
            if name in self.globals:
                return self.globals[name]
            value = self._predefined(name)
            if value is not None:
                return value
        elif name in self.frames[-1].named:
            return self.frames[-1].named[name]
        raise ExpressionError(f"named parameter #<{name}> is not defined")

    def declare_named(self, name: str, column: int) -> None:
        """An assignment to ``#<name>`` being read, as LinuxCNC's
        read_named_parameter_setting: a read-only name is an error; a new name exists from
        here on with the value 0, so ``#<h>=[#<h>+5]`` gives 5."""
        if name.startswith("_"):
            if self._predefined(name) is not None:
                raise self.error(f"Cannot assign to read-only parameter #<{name}>", column)
            self.globals.setdefault(name, 0.0)
        else:
            self.frames[-1].named.setdefault(name, 0.0)

    def exists(self, name: str) -> bool:
        if name.startswith("_"):
            return name in self.globals or self._predefined(name) is not None
        return name in self.frames[-1].named

    def _predefined(self, name: str) -> float | None:
        """LinuxCNC's read-only named parameters, as its interp_namedparams.cc computes them
        (``_retract_r_plane`` is 1 under G99, whatever its comment says; ``_task`` 1 as in
        milltask, which makes the motion, not the preview)."""
        m = self.m
        system = self.coords.system  # 1..9 for G54..G59.3
        values = {
            "_x": self.prog[0] / m.scale,
            "_y": self.prog[1] / m.scale,
            "_z": self.prog[2] / m.scale,
            "_metric": float(not m.inch),
            "_imperial": float(m.inch),
            "_absolute": float(m.absolute),
            "_incremental": float(not m.absolute),
            "_feed": m.feed,
            "_rpm": m.spindle_rpm,
            "_current_tool": float(m.tool_loaded),
            "_selected_tool": float(m.tool_selected),
            "_line": float(self.line_no),
            "_motion_mode": float(m.motion if m.motion is not None else 800),
            "_plane": float(G_OF_PLANE[m.plane] * 10),
            "_coord_system": float(530 + 10 * system if system < 7 else 584 + system),
            "_ccomp": float(m.comp_mode),
            "_inverse_time": float(m.feed_mode == 930),
            "_units_per_minute": float(m.feed_mode == 940),
            "_units_per_rev": float(m.feed_mode == 950),
            "_tool_offset": float(any(self.coords.tool_mm)),
            "_retract_r_plane": float(m.retract_mode == 990),
            "_retract_old_z": float(m.retract_mode == 980),
            "_ijk_absolute_mode": float(m.arc_absolute),
            "_lathe_diameter_mode": 0.0,
            "_lathe_radius_mode": 1.0,
            "_spindle_on": float(m.spindle != "off"),
            "_spindle_cw": float(m.spindle == "cw"),
            "_a": m.rotary[0],
            "_b": m.rotary[1],
            "_c": m.rotary[2],
            "_u": 0.0,
            "_v": 0.0,
            "_w": 0.0,
            "_call_level": float(len(self.frames) - 1),
            "_remap_level": 0.0,
            "_value": 0.0,
            "_value_returned": 0.0,
            "_task": 1.0,
            "_vmajor": 2.9,  # LinuxCNC's sscanf("%lf%lf") of its version "2.9.x"
            "_vminor": 0.0,
        }
        return values.get(name)

    def evaluate(self, value, column: int, lenient: bool = False) -> float:
        """The value of an expression; ``lenient``: an undefined named parameter reads 0
        (an endsub's value read while its definition is skipped: LinuxCNC reads it without
        the sub's locals, and does not stop)."""
        if type(value) is float:
            return value
        named = self.read_named
        if lenient:
            def named(name):
                return self.read_named(name) if self.exists(name) else 0.0
        try:
            return evaluate(value, self.read_numbered, named, self.exists)
        except ExpressionError as exc:
            raise self.error(exc.message, column) from None

    # -- the program counter ----------------------------------------------------------------
    def run(self) -> None:
        percent_seen = False
        block_delete = self.options.block_delete
        fast = self.options.fast_lane
        while not self.ended:
            frame = self.frames[-1]
            source = frame.source
            pc = frame.pc
            if pc >= len(source.lines):
                if len(self.frames) > 1:
                    self.line_no = len(source.lines)
                    raise self.error(f"end of file inside subroutine o{frame.label}")
                break
            self.source = source
            if fast and source._blocks[pc] is None and self.comp is None \
                    and self.comp_exit is None and self.m.feed_mode == 940:
                if self.nurbs is None:
                    count = self.bulk(source, pc) if self.m.absolute else 0
                else:
                    count = self.g6_lane(source, frame, pc)
                if count:
                    frame.pc = pc + count
                    self.executed += count
                    if self.executed > self.max_executed or len(self.segments) > self.max_moves:
                        self.over_budget()
                    continue
            self.line_no = pc + 1
            frame.pc = pc + 1
            self.executed += 1
            if self.executed > self.max_executed or len(self.segments) > self.max_moves:
                self.over_budget()
            try:
                block = source._blocks[pc] or source.block(pc)
            except NurbsCncError as exc:
                if source is not self.main and exc.pos is not None:
                    raise self.error(exc.message, exc.pos.column, type(exc)) from None
                raise
            if block.percent:
                if source is self.main:
                    if percent_seen:
                        break  # the second % ends the tape
                    # LinuxCNC (rs274ngc_pre.cc, open): only a % as the first non-blank line
                    # opens a tape; any other % line is a bad character (interp_read.cc).
                    if any(line.strip() for line in self.lines[:pc]):
                        raise self.error(
                            "Bad character '%' used (a % line ends the program only when the "
                            "program's first line is a %)",
                            self.lines[pc].find("%") + 1,
                        )
                    percent_seen = True
                continue
            if block.delete and block_delete:
                continue
            if block.oword is not None:
                self.oword(block, frame)
            elif block.words or block.assigns or block.comments:
                self.block(block)
        self.finish()

    def not_in_comp(self, message: str, column: int) -> None:
        """LinuxCNC's refusals of offset and mode changes while cutter compensation is on
        (interp_convert.cc), with its messages: the compensated path would change frame."""
        if self.m.comp_mode != 400:
            raise self.error(message, column)

    def over_budget(self, column: int = 1, moves: bool = False) -> None:
        """The error of a program past its budget of executed lines or of moves
        (:class:`InterpretOptions` ``extra_lines``, ``extra_moves``), at the line reached."""
        if moves or len(self.segments) > self.max_moves:
            what = f"makes more than {self.options.extra_moves:,} moves"
        else:
            what = f"executes more than {self.options.extra_lines:,} lines"
        raise self.error(f"the program {what} beyond one per line of its own (a loop, call, "
                         f"L repeat or peck (G73, G83 Q) that runs away?)", column)

    def bulk(self, source: Source, pc: int) -> int:
        """Interpret the run of plain straight-move lines at ``source.lines[pc]`` in bulk
        (fastlane.py: the same segments as line by line); returns the lines consumed (0:
        the line is not one the fast lane takes)."""
        m = self.m
        state = BulkState(m.motion, m.feed, m.feed_mm, tuple(self.prog), m.scale)
        run = plain_run(source.lines, pc, state, self.coords.to_machine_array,
                        (MAX_COORD_MM, MIN_FEED_MM_MIN, MAX_FEED_MM_MIN))  # fmt: skip
        if run is None:
            return 0
        if source.worded is None:
            source.worded = bytearray(len(source.lines))
        np.frombuffer(source.worded, dtype=np.uint8)[run.worded] = 1
        blend_mm = m.blend_mm
        if source is self.main:
            numbers = list(map((1).__add__, run.index))  # 1-based
        else:  # in a called file the moves carry the main program's call line
            numbers = [self.main_line()] * len(run.index)
        with pause_cyclic_gc():
            self.segments += make_lines({
                "start_mm": run.starts_mm, "end_mm": run.ends_mm, "feed_mm_s": run.feeds_mm_s,
                "line": numbers, "rapid": run.rapid, "blend_mm": itertools.repeat(blend_mm),
                "naive_mm": itertools.repeat(m.naive_mm)})  # fmt: skip
        new = run.state
        m.motion, m.feed, m.feed_mm = new.motion, new.feed, new.feed_mm
        self.prog = list(new.prog_mm)
        self.line_no = pc + run.count
        return run.count

    def g6_lane(self, source: Source, frame, pc: int) -> int:
        """Inside a G6.2 block, the run of continuation lines at ``source.lines[pc]``
        (:func:`~nurbscnc.program.fastlane.nurbs_words`: a point and its knot, or a knot)
        handed to the block (``g6``) without parsing them: the general path would parse
        each, then run the execution order, which does nothing else for these words (the
        same points, knots, lines and errors: tests/test_interpret_fastlane.py). A run of
        fewer than ``MIN_RUN_LINES`` lines is left to it (see fastlane.py). Returns the lines
        consumed (0: none), up to the one that ends the block."""
        lines = source.lines
        least = fastlane.MIN_RUN_LINES
        end = min(len(lines), pc + least)
        if end - pc < least or any(nurbs_words(lines[i]) is None for i in range(pc, end)):
            return 0
        if source.worded is None:
            source.worded = bytearray(len(source.lines))
        i = pc
        while i < len(lines) and self.nurbs is not None and source._blocks[i] is None:
            words = nurbs_words(lines[i])
            if words is None:
                break
            self.line_no = i + 1
            frame.pc = i + 1
            self.g6(words, set(), None)
            source.worded[i] = 1
            i += 1
        return i - pc

    def finish(self) -> None:
        self.comp_off()  # the end of the program ends compensation as G40 does
        if self.nurbs is not None:
            build = self.nurbs
            self.source = self.main
            self.line_no = build.line
            if build.kind == "G5.2":
                raise self.error("G5.2 NURBS block has no closing G5.3")
            raise self.error(
                f"G6.2 NURBS block ends with {len(build.knots)} knots; "
                f"knot count must equal control points + order "
                f"({len(build.points)} + {build.order} = {len(build.points) + build.order})"
            )

    # -- the block ----------------------------------------------------------------------------
    def block(self, block: Block) -> None:
        for _, text, _column in block.comments:
            body = text[1:-1].strip() if text.startswith("(") else ""
            if body[:4].upper() == "MSG,":
                self.notes.append(Note(self.main_line(), f"message: {body[4:].strip()}"))
        words, gcodes, mcodes = self.read_words(block)
        # Parameter assignments take effect at the end of the line's reading (LinuxCNC):
        # every right-hand side sees the old values.
        pending = []
        for target, raw, column in block.assigns:
            if target[0] != "#":  # a named parameter exists (0) from its assignment's reading
                self.declare_named(target[1], column)
            value = self.evaluate(raw, 1)
            if target[0] == "#":
                index_f = self.evaluate(target[1], 1)
                try:
                    pending.append((self._param_index(index_f), value))
                except ExpressionError as exc:
                    raise self.error(exc.message) from None
            else:
                pending.append((target[1], value))
        for key, value in pending:
            if type(key) is int:
                self.write_numbered(key, value)
            elif key.startswith("_"):
                self.globals[key] = value
            else:
                self.frames[-1].named[key] = value
        if words or gcodes or mcodes:
            self.execute(words, gcodes, mcodes)

    def read_words(self, block: Block):
        words: dict[str, tuple[float, int]] = {}
        gcodes: dict[int, tuple[int, int]] = {}  # group -> (code, column)
        mcodes: dict[int, tuple[int, int]] = {}
        for letter, raw, column in block.words:
            value = raw if type(raw) is float else self.evaluate(raw, column)
            if letter == "G":
                self.read_g(value, column, gcodes)
            elif letter == "M":
                self.read_m(value, column, mcodes)
            elif letter in words:
                raise self.error(f"{letter} word repeated in the block", column)
            elif letter in "UVWON":
                self._bad_letter(letter, column)
            else:
                words[letter] = (value, column)
        return words, gcodes, mcodes

    def _bad_letter(self, letter: str, column: int):
        if letter in "UVW":
            raise self.error(f"axis {letter} is not supported (nurbscnc drives X, Y and Z)",
                             column, UnsupportedError)  # fmt: skip
        if letter == "O":
            raise self.error("O word must start the line (o<label> keyword)", column)
        raise self.error("N (line number) must start the line", column)

    def read_g(self, value: float, column: int, gcodes: dict) -> None:
        code = _COMMON_CODES.get(value)
        if code is None:
            code = self._code(value, "G", column)
        if code == 22:
            # LinuxCNC's own sample G5_Curva_Stella_v1_G5.ngc opens its NURBS block with
            # "G2.2" and closes it with G5.3; we read it as G5.2 and say so.
            self.note_once("g2.2", "G2.2 is not an RS274/NGC code; read as G5.2 (closed by G5.3)")
            code = 52
        group = G_GROUP.get(code)
        if group is None:
            if code in G_REFUSED:
                raise self.error(f"{G_REFUSED[code]} is not supported", column, UnsupportedError)
            raise self.error(f"unknown G code G{_fmt_code(code)}", column)
        if group in gcodes:
            other = gcodes[group][0]
            if group == 1 and 800 in (code, other):
                # LinuxCNC accepts G80 beside another motion code ("G80 G0" in CAM headers
                # and its own tests): the other code is the block's motion.
                if code != 800:
                    gcodes[group] = (code, column)
                return
            raise self.error(
                f"G{_fmt_code(other)} and G{_fmt_code(code)} are in the same modal "
                f"group ({group}) and cannot share a block",
                column,
            )
        gcodes[group] = (code, column)

    def read_m(self, value: float, column: int, mcodes: dict) -> None:
        code = self._code(value, "M", column)
        if code % 10:
            raise self.error(f"unknown M code M{code / 10:g}", column)
        code //= 10
        group = M_GROUP.get(code)
        if group is None:
            raise self.error(f"M{code} is not supported", column, UnsupportedError)
        if group in mcodes:
            raise self.error(
                f"M{mcodes[group][0]} and M{code} are in the same modal group "
                f"({group}) and cannot share a block",
                column,
            )
        mcodes[group] = (code, column)

    def _code(self, value: float, letter: str, column: int) -> int:
        if not 0.0 <= value < 1e6:  # value * 10 must stay a modest integer
            raise self.error(f"{letter}{value:g} is not a valid {letter} code", column)
        code = round(value * 10.0)
        if abs(value * 10.0 - code) > 1e-6:
            raise self.error(f"{letter}{value:g} is not a valid {letter} code", column)
        return int(code)

    # -- execution in RS274/NGC order ---------------------------------------------------------
    def execute(self, words: dict, gcodes: dict, mcodes: dict) -> None:
        """One block, in LinuxCNC's order (interp_execute.cc, execute_block)."""
        used: set = set()
        # The fast path: most CAM lines are "G1 X.. Y.. F.." (same effect as the full order).
        if not mcodes and len(gcodes) <= (1 in gcodes) and _PLAIN_WORDS.issuperset(words):
            motion_code = gcodes.get(1)
            motion = self.m.motion if motion_code is None else motion_code[0]
            if (motion == 0 or motion == 10) and self.nurbs is None:
                if "F" in words:
                    self.set_feed(words, used)
                self.m.motion = motion
                if "X" in words or "Y" in words or "Z" in words:
                    self.straight(words, False)
                return
        self.set_feed_mode(gcodes, words)
        self.set_feed(words, used)
        self.set_units(gcodes)
        self.set_spindle(words, used)
        self.select_tool(words, used)
        self.io_codes(mcodes, words, used)
        if 6 in mcodes:
            if self.m.comp_mode != 400:
                raise self.error("Cannot change tools with cutter radius compensation on",
                                 mcodes[6][1])  # fmt: skip
            if mcodes[6][0] == 6:
                self.m.tool_loaded = self.m.tool_selected  # M6
                # LinuxCNC's convert_tool_change stops the spindle (unless the INI's
                # TOOL_CHANGE_WITH_SPINDLE_ON): a G86 after it refuses a stopped spindle.
                self.m.spindle = "off"
            else:  # M61 Q<tool>: the tool in the spindle is Q (no change is made)
                self.m.tool_loaded = self.m61_tool(words, mcodes[6][1], used)
        if 7 in mcodes:  # after the tool change, as LinuxCNC's order of execution
            self.m.spindle = {3: "cw", 4: "ccw"}.get(mcodes[7][0], "off")  # M5, M19: stopped
        if 10 in mcodes:
            self.modal_save_restore(*mcodes[10])
        if mcodes.get(7, (0,))[0] == 19:
            used.update("RQP")  # M19 R<angle> Q<timeout> P<direction>: spindle orientation
        self.dwell(gcodes, words, used)
        if 2 in gcodes:
            plane = PLANE_OF_G[gcodes[2][0]]
            if self.m.comp_mode != 400 and plane != self.m.plane:
                raise self.error("Cannot change planes with cutter radius compensation on",
                                 gcodes[2][1])  # fmt: skip
            self.m.plane = plane
        self.set_cutter_comp(gcodes, words, used)
        self.set_tool_offset(gcodes, words, used)
        if 12 in gcodes:
            self.not_in_comp("Cannot change coordinate systems with cutter radius compensation "
                             "on", gcodes[12][1])  # fmt: skip
            self.select_system(SYSTEM_OF_G[gcodes[12][0]])
        self.set_path_mode(gcodes, words, used)
        if 3 in gcodes:
            self.m.absolute = gcodes[3][0] == 900
        if 4 in gcodes:
            self.m.arc_absolute = gcodes[4][0] == 901
        if 10 in gcodes:
            self.m.retract_mode = gcodes[10][0]
        motion = gcodes[1][0] if 1 in gcodes else self.m.motion
        if motion in CANNED_CYCLES:
            for letter in "ABC":
                if letter in words:  # LinuxCNC: "Cannot put an a in canned cycle"
                    article = "an" if letter == "A" else "a"
                    raise self.error(f"Cannot put {article} {letter.lower()} in canned cycle",
                                     words[letter][1])  # fmt: skip
        self.check_rotary(words, used)
        if mcodes.get(4, (0,))[0] == 98:
            used.update("PL")  # M98 P<O number> L<repeats>: the call, after the block's moves
        moved_by_nonmodal = self.nonmodal(gcodes, words, used)
        self.motion_block(gcodes, words, used, moved_by_nonmodal)
        for letter, (_, col) in words.items():
            if letter not in used:
                raise self.error(_unused_word_message(letter), col)
        if 6 in mcodes and self.comp_exit is not None:
            self.refresh_position()
        if 4 in mcodes:
            code, col = mcodes[4]
            if code == 98:
                self.m98(words, col)
            elif code == 99:
                self.m99(col)
            else:
                self.stop(code, col)

    def refresh_position(self) -> None:
        """After a tool change (M6, M61) LinuxCNC re-reads the current position before the
        next block (interp_internal.cc, refresh_actual_position): the machine's position
        taken back to program coordinates with the offsets now in force, the new tool length
        offset included (emccanon.cc, unoffset_and_unrotate_pos). nurbscnc's program position
        already keeps the machine where it is through every offset change; the one place it
        differs from the machine is just after G40, where LinuxCNC's interpreter holds the
        programmed point while the tool stands at the compensated one: the tool change makes
        the compensated point the program position (nc_files/useful-subroutines.ngc)."""
        self.pos = self.comp_exit

    def m61_tool(self, words: dict, column: int, used: set) -> int:
        if "Q" not in words:
            raise self.error("M61 needs a Q word (the tool number)", column)
        q, qcol = words["Q"]
        used.add("Q")
        if q != int(q) or q < 0 or q >= 2**31:
            raise self.error(f"M61 Q{q:g}: Q must be a tool number", qcol)
        return int(q)

    def modal_save_restore(self, code: int, column: int) -> None:
        """M70 save, M71 forget, M72 restore the modal state; M73 save it for an automatic
        restore when the current subroutine returns (LinuxCNC)."""
        frame = self.frames[-1]
        if code in (70, 73):
            state = ({name: getattr(self.m, name) for name in SAVED_BY_M70}, self.coords.system)
            if code == 70:
                self.m70_state = state
            else:
                if len(self.frames) == 1:
                    raise self.error("M73 outside a subroutine (nothing to restore it)", column)
                frame.m73_state = state
        elif code == 71:
            self.m70_state = None
        else:
            state = self.m70_state
            if state is None:
                raise self.error("M72 with no state saved by M70", column)
            self.restore_state(state)

    def restore_state(self, state) -> None:
        values, system = state
        for name, value in values.items():
            setattr(self.m, name, value)
        self.select_system(system)

    def set_feed_mode(self, gcodes: dict, words: dict) -> None:
        if 5 in gcodes:
            # LinuxCNC (convert_feed_mode): every G93, G94, G95 word clears F, even for the
            # mode in force; an F in the same block sets it again (it comes after).
            self.m.feed = self.m.feed_mm = 0.0
            self.m.feed_mode = gcodes[5][0]

    def set_units(self, gcodes: dict) -> None:
        # RS274/NGC sets F (step 3) before units (step 12) and LinuxCNC's canon keeps the
        # feed as a length per minute in the units of the moment it was set: "G20 F60" in a
        # block that starts in mm is 60 mm/min (its goldens: ccomp/mill-zchanges, comp311).
        if 6 in gcodes:
            scale = INCH_MM if gcodes[6][0] == 200 else 1.0
            if scale != self.m.scale:
                # LinuxCNC (convert_length_units) converts positions and offsets but not what
                # a cycle remembers (cycle_r, cycle_cc, cycle_il, Q, I, J, K): their numbers are
                # read in the new units (R2 in mm, then G20: R2 inches).
                c, ratio = self.m.cycle, scale / self.m.scale
                self.m.cycle = replace(c, **{f: None if getattr(c, f) is None
                                             else getattr(c, f) * ratio
                                             for f in ("initial_level_mm", "r_mm", "z_mm",
                                                       "q_mm", "i_mm", "j_mm", "k_mm")})
            self.m.scale = scale

    def set_feed(self, words: dict, used: set) -> None:
        if "F" in words:
            f, col = words["F"]
            used.add("F")
            if f < 0:
                raise self.error(f"negative feed F{f:g}", col)
            f_mm = f * self.m.scale
            if not (f_mm == 0.0 or MIN_FEED_MM_MIN <= f_mm <= MAX_FEED_MM_MIN):
                raise self.error(
                    f"feed F{f:.6g} is out of range ({MIN_FEED_MM_MIN:g} to "
                    f"{MAX_FEED_MM_MIN:g} mm/min, or 0)",
                    col,
                )
            self.m.feed = f
            self.m.feed_mm = f * self.m.scale

    def set_spindle(self, words: dict, used: set) -> None:
        if "S" in words:
            used.add("S")
            s, col = words["S"]
            if s < 0:
                raise self.error("negative spindle speed", col)
            self.m.spindle_rpm = s

    def select_tool(self, words: dict, used: set) -> None:
        if "T" in words:
            used.add("T")
            t, col = words["T"]
            if t < 0 or t != int(t) or t >= 2**31:
                raise self.error(f"tool number T{t:g} must be a non-negative integer", col)
            self.m.tool_selected = int(t)

    def io_codes(self, mcodes: dict, words: dict, used: set) -> None:
        """M62–M68 (LinuxCNC's HAL I/O: digital and analog outputs, a wait on an input) and
        M50–M53 (override switches), step 6 and 11 of LinuxCNC's order: no motion of their
        own. M64, M65 (a digital output now), M66 (wait on an input) and M68 (an analog
        output now) run once the motion before them has ended (LinuxCNC's task waits for it,
        emcTaskCheckPreconditions), so the tool stops there: a dwell of 0 s; M62, M63 and
        M67 go with the motion. The words as LinuxCNC checks them (convert_m)."""
        if 5 in mcodes:
            code, col = mcodes[5]
            if code in (62, 63, 64, 65) and "P" not in words:
                raise self.error(f"No valid P word with M{code}", col)
            if code == 66 and "P" not in words and "E" not in words:
                raise self.error("Need to have either a valid P or a valid E word with M66",
                                 col)  # fmt: skip
            if code in (67, 68) and "E" not in words:
                raise self.error(f"Invalid analog index with M{code}", col)
            used.update({66: "PELQ", 67: "EQ", 68: "EQ"}.get(code, "P"))
            if code in (64, 65, 66, 68):
                self.dwell_here(0.0, f"M{code}")
        if mcodes.get(9, (0,))[0] in (50, 51, 52, 53):
            used.add("P")  # P0 switches the override off, P1 (or none) on

    def dwell_here(self, seconds: float, code: str = "G4") -> None:
        """A dwell of ``seconds`` at the current point (the tool at rest there), made by
        ``code``."""
        position = tuple(self.pos) if self.comp_exit is None else self.comp_exit
        dwell = Dwell(float(seconds), position, self.main_line(), code)
        if self.comp is None:
            self.segments.append(dwell)
        else:
            self.comp_moves(CompMove("dwell", self.to_comp(position), line=dwell.line,
                                     seconds=dwell.seconds))  # fmt: skip

    def dwell(self, gcodes: dict, words: dict, used: set) -> None:
        nonmodal = gcodes.get(0)
        if nonmodal is None or nonmodal[0] != 40:
            return
        if "P" not in words:
            raise self.error("G4 dwell needs a P word (seconds)", nonmodal[1])
        seconds, col = words["P"]
        used.add("P")
        if seconds < 0:
            raise self.error(f"negative dwell time P{seconds:g}", col)
        if seconds > MAX_DWELL_S:
            raise self.error(
                f"dwell P{seconds:.6g} is out of range (at most {MAX_DWELL_S:g} s)", col
            )
        self.dwell_here(seconds)

    def set_cutter_comp(self, gcodes: dict, words: dict, used: set) -> None:
        """G40 / G41 / G42 / G41.1 / G42.1 with D: tracked in ``self.m.comp_*``."""
        m = self.m
        if 7 in gcodes:
            code, col = gcodes[7]
            if code != 400 and m.comp_mode != 400:
                raise self.error("cannot turn cutter compensation on when it is already on",
                                 col)  # fmt: skip
            if code == 400:
                m.comp_mode, m.comp_side, m.comp_radius_mm, m.comp_d = 400, None, 0.0, None
                self.comp_off()
            else:
                if m.plane == "YZ":
                    raise self.error("Cutter radius compensation allowed only in XY, XZ planes",
                                     col)  # fmt: skip
                if m.plane == "ZX" and self.coords.rotation_deg:
                    raise self.error("cutter radius compensation in the XZ plane (G18) with a "
                                     "rotated coordinate system (G10 L2 R) is not supported",
                                     col, UnsupportedError)  # fmt: skip
                self.comp_plane = m.plane
                m.comp_mode = code
                m.comp_side = "left" if code in (410, 411) else "right"
                d = words.get("D")
                if code in (411, 421):
                    if d is None:
                        raise self.error(f"G{_fmt_code(code)} needs a D word (diameter)", col)
                    # signed: a negative D swaps the side (LinuxCNC; CutterComp does it)
                    m.comp_radius_mm = d[0] * m.scale / 2.0
                else:
                    # no D, or D0 (LinuxCNC's find_tool_index(0): the spindle's pocket):
                    # the loaded tool
                    number = int(d[0]) if d is not None and d[0] != 0 else m.tool_loaded
                    if d is not None and (d[0] != int(d[0]) or d[0] < 0):
                        raise self.error(f"D{d[0]:g} must be a tool number", d[1])
                    tool = self.tools.get(number)
                    m.comp_radius_mm = tool.diameter_mm / 2.0 if tool is not None else 0.0
                m.comp_d = d[0] if d is not None else None
                start = tuple(self.pos) if self.comp_exit is None else self.comp_exit
                self.comp = CutterComp(m.comp_side, m.comp_radius_mm, self.to_comp(start),
                                       inch=m.inch)  # fmt: skip
                self.comp_exit = None
        if "D" in words and gcodes.get(14, (0,))[0] == 960:
            used.add("D")  # G96 D: the spindle speed limit of constant surface speed
        elif "D" in words:
            if 7 not in gcodes or gcodes[7][0] == 400:
                raise self.error("D word with no G41/G42 to use it", words["D"][1])
            used.add("D")

    def set_tool_offset(self, gcodes: dict, words: dict, used: set) -> None:
        """G43 [H] (tool table), G43.1 (offsets given in the block), G49."""
        if 8 not in gcodes:
            if "H" in words:
                raise self.error("H word with no G43 to use it", words["H"][1])
            return
        code, col = gcodes[8]
        self.not_in_comp("Cannot change tool offset with cutter radius compensation on", col)
        machine = self.pos
        if code == 430:
            used.add("H")
            tool = words["H"][0] if "H" in words else float(self.m.tool_loaded)
            if tool != int(tool) or tool < 0:
                raise self.error(f"H{tool:g} must be a tool number", words["H"][1])
            entry = self.tools.get(int(tool))
            if entry is not None:
                offset = list(entry.offset_mm)
            else:
                offset = [0.0, 0.0, 0.0]
                if int(tool) != 0:
                    self.note_once(
                        ("tlo", int(tool)),
                        f"G43 H{int(tool)}: no tool table entry, tool length offset taken as 0",
                    )
        elif code == 431:
            offset = [0.0, 0.0, 0.0]
            for i, letter in enumerate(_AXES):
                if letter in words:
                    offset[i] = words[letter][0] * self.m.scale
                    used.add(letter)
        else:
            offset = [0.0, 0.0, 0.0]
        self.coords.set_tool(offset)
        self.m.tool_offset_code = code
        self.pos = machine  # the machine stays; the program position changes
        if code == 431:
            self.axes_consumed = True  # its axis words were the offsets, not a move

    def select_system(self, system: int) -> None:
        machine = self.pos
        self.coords.select(system)
        self.pos = machine

    def set_path_mode(self, gcodes: dict, words: dict, used: set) -> None:
        """G61 (exact path), G61.1 (exact stop), G64 [P-] [Q-] (blending), as LinuxCNC 2.9:
        G64 without P blends within the machine's path tolerance; Q (naive CAM tolerance)
        defaults to P, and G64 alone turns the naive CAM detector off."""
        if 13 not in gcodes:
            return
        code, col = gcodes[13]
        self.not_in_comp("Cannot change control mode with cutter radius compensation on", col)
        p_mm = q_mm = None
        if code == 640:
            for letter in "PQ":
                if letter in words:
                    used.add(letter)
                    value, where = words[letter]
                    if value < 0:
                        raise self.error(f"G64 {letter} tolerance must be >= 0", where)
                    if letter == "P":
                        p_mm = value * self.m.scale
                    else:
                        q_mm = value * self.m.scale
        self.m.path_mode = code
        self.m.blend_mm = path_control(code, p_mm)
        self.m.naive_mm = q_mm if q_mm is not None else (p_mm or 0.0)

    def check_rotary(self, words: dict, used: set) -> None:
        """A, B, C: carried while they do not move (``A0.`` in posts), refused when they do."""
        for i, letter in enumerate("ABC"):
            if letter in words:
                value, col = words[letter]
                current = self.m.rotary[i]
                target = current + value if not self.m.absolute else value
                if target != current:
                    raise self.error(
                        f"rotary axis motion is not supported ({letter}{value:g}: "
                        f"{letter} is at {current:g})",
                        col,
                        UnsupportedError,
                    )
                used.add(letter)

    # -- motion ---------------------------------------------------------------------------------
    def motion_block(self, gcodes, words, used, axes_consumed: bool) -> None:
        motion_code = gcodes.get(1)
        machine_coords = gcodes.get(0, (None,))[0] == 530
        # A run of cycle blocks keeps its initial level and sticky words; any other motion
        # mode in between forgets them (LinuxCNC's cycle_il_flag).
        fresh_cycle = self.m.motion not in CANNED_CYCLES
        if machine_coords:
            mode = motion_code[0] if motion_code else self.m.motion
            if mode not in (0, 10):
                raise self.error("G53 needs G0 or G1 in force", gcodes[0][1])
            if not self.m.absolute:
                raise self.error("G53 cannot be used with G91 (incremental)", gcodes[0][1])
            if self.m.comp_mode != 400 and self.m.comp_radius_mm > 0.0:
                raise self.error("Cannot use g53 with cutter radius comp", gcodes[0][1])
        if motion_code is not None:
            code, col = motion_code
            if self.nurbs is not None and code != self.nurbs_code():
                self.finish_nurbs_by_other(code, col)
            if code == 800:
                self.m.motion = None
                if any(a in words for a in _AXES) and not axes_consumed:
                    raise self.error("axis words with G80 (motion cancelled)", col)
            elif code not in (50, 51):  # LinuxCNC's convert_spline keeps the motion mode
                self.m.motion = code
        if self.axes_consumed:
            self.axes_consumed = False
            axes_consumed = True
        for letter in "@^":
            if letter in words:
                used.add(letter)
        has_axes = not axes_consumed and (
            "X" in words or "Y" in words or "Z" in words or "@" in words or "^" in words
        )
        motion = self.m.motion
        if motion_code is not None and motion_code[0] in (50, 51):
            motion = motion_code[0]  # this block's spline; the next line moves as before it
        if motion is None:
            if has_axes:
                letter = next(a for a in (*_AXES, "@", "^") if a in words)
                raise self.error(
                    f"{letter} word with no motion mode in force (G0, G1, G2, G3, G5.2, G6.2)",
                    words[letter][1],
                )
        elif motion in (0, 10):
            if has_axes:
                self.straight(words, machine_coords)
        elif motion in (20, 30):
            # A block whose axis words a group-0 code took (G10 L2 P1 R45 under modal G2)
            # makes no arc: its R or P belong to that code (LinuxCNC's enhance_block).
            if has_axes or motion_code is not None or (
                    not axes_consumed and any(k in words for k in "IJKR")):
                self.arc(words, used)
        elif motion in (50, 51, 52, 62) and self.comp is not None:
            raise self.error(f"G{_fmt_code(motion)} with cutter radius compensation is not "
                             "supported", motion_code[1] if motion_code else 1,
                             UnsupportedError)  # fmt: skip
        elif motion in (50, 51):
            if has_axes or motion_code is not None:
                self.spline(words, used, motion, motion_code)
        elif motion in CANNED_CYCLES:
            if motion_code is not None and not has_axes and not axes_consumed:
                # LinuxCNC (enhance_block): only G0–G3 may stand without an axis word.
                raise self.error("All axes missing with motion code", motion_code[1])
            if has_axes or motion_code is not None:
                self.canned_cycle(motion, words, used, motion_code, fresh_cycle)
        elif motion == 52:
            self.g5(words, used, motion_code)
        elif motion == 53:
            self.g5_end(motion_code[1] if motion_code else 1)
        elif motion == 62:
            self.g6(words, used, motion_code)
        used.update(_AXES)

    def canned_cycle(self, code: int, words: dict, used: set, motion_code, fresh: bool) -> None:
        """G73, G74, G81–G89: expanded by cycles.py (LinuxCNC's convert_cycle) in program
        coordinates, then appended as rapids, feeds, dwells and pauses in machine coordinates
        (its spindle stops and starts have no segment). ``fresh``: the first block of a run
        of cycle blocks (a new initial level; sticky words forgotten)."""
        m = self.m
        col = motion_code[1] if motion_code else min(c for _, c in words.values())
        if m.feed_mode == 930:
            raise self.error("Cannot use inverse time feed with canned cycles", col)
        if m.comp_mode != 400:
            raise self.error("Cannot use canned cycles with cutter compensation on", col)
        # LinuxCNC's check_other_codes: besides X Y Z R L (and polar @ ^) a cycle reads only
        # its own words; a P, Q, I, J or K that neither it nor another code of the block
        # (G4, G10, G64, M19, M98: marked used before the motion) reads is an error.
        reads = "XYZRL@^" + CYCLE_WORDS[code]
        for letter in "PQIJK":
            if letter in words and letter not in reads and letter not in used:
                raise self.error(_unused_word_message(letter), words[letter][1])
        given = {}
        for letter in reads:
            if letter in words:
                value = words[letter][0]
                given[letter] = value * m.scale if letter in "XYZRQIJK@" else value
                used.add(letter)
        if len(self.segments) + given.get("L", 1) > self.max_moves:  # each repeat moves
            self.over_budget(col, moves=True)
        try:
            result = expand_cycle(
                f"G{code // 10}", given, incremental=not m.absolute,
                position_mm=tuple(self.prog), plane=m.plane,
                retract="G98" if m.retract_mode == 980 else "G99", feed_mm_s=self.feed_mm_s,
                state=CycleState() if fresh else m.cycle, spindle=m.spindle,
                max_moves=self.max_moves - len(self.segments),
            )  # fmt: skip
        except TooManyMoves:
            self.over_budget(col, moves=True)
        except ProgramError as exc:
            raise self.error(exc.message, col) from None
        line = self.main_line()
        to_machine = self.coords.to_machine
        start = tuple(self.pos)
        for move in result.moves:
            if move.kind in ("rapid", "feed"):
                end = tuple(to_machine(list(move.end_mm)))
                if end != start:
                    self.segments.append(Line(start, end, move.feed_mm_s, line,
                                              move.kind == "rapid", m.blend_mm))  # fmt: skip
                start = end
            elif move.kind == "dwell":
                self.segments.append(Dwell(float(move.dwell_s), start, line))
            elif move.kind == "pause":  # G88: the operator takes over (LinuxCNC: M0)
                self.segments.append(Pause(start, line, "M0"))
        self.prog = list(result.position_mm)
        m.cycle = result.state

    # -- cutter radius compensation (compensation.py) -------------------------------------
    def to_comp(self, point) -> tuple:
        """A machine point in the frame compensation.py works in (its first two axes are the
        plane): XY as is; for G18 (ZX) the cyclic permutation (x, y, z) → (z, x, y), which
        keeps the handedness, so +Y (the G18 normal) becomes +Z and left stays left."""
        if self.comp_plane == "ZX":
            return (float(point[2]), float(point[0]), float(point[1]))
        return tuple(map(float, point))

    def from_comp(self, point) -> tuple:
        """Inverse of :meth:`to_comp`."""
        if self.comp_plane == "ZX":
            return (float(point[1]), float(point[2]), float(point[0]))
        return tuple(map(float, point))

    def compensate(self, segment) -> None:
        """A programmed Line or Arc (machine mm) into the compensation stream; appends the
        compensated moves that are final so far (the last one is held back for its corner).
        Compensation works in the machine plane (XY, or ZX for G18 through :meth:`to_comp`):
        offsets and the G10 R rotation about Z keep the side of the path, so it is the same
        as compensating in program coordinates (G18 with a rotation is refused)."""
        if isinstance(segment, Arc):
            turns = max(1, math.ceil(abs(segment.angle_rad) / (2.0 * math.pi) - 1e-9))
            centre = self.to_comp(segment.center_mm)
            move = CompMove("arc", self.to_comp(segment.end_mm), segment.feed_mm_s,
                            segment.line, (centre[0], centre[1]),
                            turns if segment.angle_rad > 0 else -turns)  # fmt: skip
        else:
            move = CompMove("rapid" if segment.rapid else "feed", self.to_comp(segment.end_mm),
                            segment.feed_mm_s, segment.line)  # fmt: skip
        self.comp_moves(move)

    def comp_moves(self, move: CompMove) -> None:
        try:
            out = self.comp.move(move)
        except ProgramError as exc:
            raise self.error(exc.message) from None
        self.append_compensated(out)

    def comp_off(self) -> None:
        """G40 (or the program's end): the held-back moves end where they are; the next
        (exit) move starts from the compensated point and must be straight (LinuxCNC)."""
        comp, self.comp = self.comp, None
        if comp is None:
            return
        try:
            out = comp.finish()
        except ProgramError as exc:
            raise self.error(exc.message) from None
        self.append_compensated(out)
        if not comp.first and comp.radius_mm > 0.0:
            self.comp_exit = self.from_comp(comp.position_mm)

    def append_compensated(self, moves) -> None:
        blend_mm = self.m.blend_mm
        plane = self.comp_plane
        back = self.from_comp
        for mv in moves:
            if mv.kind == "dwell":
                self.segments.append(Dwell(mv.seconds, back(mv.end_mm), mv.line))
            elif mv.kind == "arc":
                start, end = tuple(mv.start_mm), tuple(mv.end_mm)
                s2, e2 = start[:2], end[:2]
                sweep = arcs.sweep_rad(s2, e2, mv.centre_mm, mv.turn > 0, abs(mv.turn))
                self.segments.append(Arc(
                    start_mm=vec3(back(start)), end_mm=vec3(back(end)),
                    center_mm=vec3(back((*mv.centre_mm, start[2]))),
                    normal=vec3(PLANE_NORMALS[plane]),
                    angle_rad=float(sweep), helix_mm=end[2] - start[2],
                    radius_start_mm=math.dist(s2, mv.centre_mm),
                    radius_end_mm=math.dist(e2, mv.centre_mm),
                    feed_mm_s=mv.feed_mm_s, line=mv.line, plane=plane, blend_mm=blend_mm,
                ))  # fmt: skip
            elif tuple(mv.start_mm) != tuple(mv.end_mm):
                self.segments.append(Line(back(mv.start_mm), back(mv.end_mm), mv.feed_mm_s,
                                          mv.line, mv.kind == "rapid", blend_mm))  # fmt: skip

    def emit(self, segment) -> None:
        """Append a Line or Arc (through compensation when it is on; the move just after G40
        starts from the compensated point)."""
        if self.comp is not None:
            self.compensate(segment)
            return
        if self.comp_exit is not None:
            if isinstance(segment, Arc):
                raise self.error(MSG_ARC_AFTER_EXIT)
            segment = Line(self.comp_exit, segment.end_mm, segment.feed_mm_s, segment.line,
                           segment.rapid, segment.blend_mm)  # fmt: skip
            self.comp_exit = None
            if segment.start_mm == segment.end_mm:
                return
        self.segments.append(segment)

    def target_program(self, words: dict, base=None) -> list:
        """End point [mm, program coordinates] of a move: axis (or polar) words in the units
        and distance mode in force."""
        base = self.prog if base is None else base
        out = list(base)
        scale = self.m.scale
        absolute = self.m.absolute
        for i, letter in enumerate(_AXES):
            if letter in words:
                v = words[letter][0] * scale
                out[i] = v if absolute else base[i] + v
                if not abs(out[i]) <= MAX_COORD_MM:  # also inf / nan from G20 or G91 sums
                    raise self.error(
                        f"{letter}{words[letter][0]:.6g} is out of range (the position would "
                        f"be beyond ±{MAX_COORD_MM:g} mm)",
                        words[letter][1],
                    )
        if "@" in words or "^" in words:
            self.polar(words, base, out)
        return out

    def polar(self, words: dict, base, out) -> None:
        """``@`` radius and ``^`` angle [deg] about the XY origin (LinuxCNC, checked): under
        G91 both are added to the current point's radius and angle; a missing one keeps the
        current value."""
        for letter in "XY":
            if letter in words:
                raise self.error(f"polar coordinates (@ ^) with {letter}", words[letter][1])
        if self.m.plane != "XY":
            col = words.get("@", words.get("^"))[1]
            raise self.error("polar coordinates (@ ^) are only allowed in the XY plane", col)
        r = math.hypot(base[0], base[1])
        a = math.degrees(math.atan2(base[1], base[0]))
        if "@" in words:
            value = words["@"][0] * self.m.scale
            r = value if self.m.absolute else r + value
        if "^" in words:
            value = words["^"][0]
            a = value if self.m.absolute else a + value
        out[0], out[1] = r * math.cos(math.radians(a)), r * math.sin(math.radians(a))

    def target(self, words: dict, machine_coords: bool = False, base=None) -> list:
        """End point [mm, machine] of a move (``base`` a machine position)."""
        if machine_coords:
            out = list(self.pos if base is None else base)
            for i, letter in enumerate(_AXES):
                if letter in words:
                    out[i] = words[letter][0] * self.m.scale
            return out
        prog_base = None if base is None else self.coords.to_program(base)
        return self.coords.to_machine(self.target_program(words, prog_base))

    def rapid_to_program(self, end_prog) -> None:
        start = self.pos
        end = self.coords.to_machine(end_prog)
        if end != start or self.comp_exit is not None:
            self.emit(Line(tuple(start), tuple(end), 0.0, self.main_line(), True, self.m.blend_mm))
        self.prog = list(end_prog)

    def move_feed_mm_s(self, length_mm: float, words: dict) -> float:
        """The feed [mm/s] of a G1/G2/G3 move of ``length_mm`` (G93: F is 1/minutes)."""
        m = self.m
        if m.feed_mode == 930:
            if "F" not in words:
                raise self.error("G93 (inverse time) moves need an F word on every line")
            # LinuxCNC's inverse_time_rate_*: at least 0.1 program units per minute.
            return max(length_mm * m.feed, 0.1 * m.scale) / 60.0
        if m.feed_mode == 950 and m.spindle_rpm <= 0.0:
            raise self.error("G95 feed per revolution with spindle speed S0")
        return self.feed_mm_s

    def straight(self, words: dict, machine_coords: bool) -> None:
        coords = self.coords
        plain = coords.plain  # no offsets in force: program and machine positions agree
        start = self.prog if plain else coords.to_machine(self.prog)
        if machine_coords:
            end = self.target(words, True)
            end_prog = coords.to_program(end)
        else:
            end_prog = self.target_program(words)
            end = end_prog if plain else coords.to_machine(end_prog)
        m = self.m
        rapid = m.motion == 0
        feed = 0.0
        if not rapid:
            if m.feed_mode == 940:
                feed = m.feed_mm / 60.0
            else:
                feed = self.move_feed_mm_s(math.dist(start, end), words)
            if feed <= 0.0:
                raise self.error("G1 move with zero feed (set F first)", 1)
        if end != start or self.comp_exit is not None:  # the exit move may not be zero
            line = self.line_no if self.source is self.main else self.main_line()
            self.emit(Line(tuple(start), tuple(end), feed, line, rapid, m.blend_mm, m.naive_mm))
        self.prog = end_prog

    def arc(self, words: dict, used: set) -> None:
        plane = self.m.plane
        a, b = PLANE_AXES[plane]
        n_axis = _NORMAL_AXIS[plane]
        col0 = min((c for _, c in words.values()), default=1)
        start = list(self.prog)
        end = self.target_program(words)
        used.update("IJKR")
        ijk = [k for k in "IJK" if k in words]
        if "R" in words and ijk:
            raise self.error("arc with both R and I/J/K words", words["R"][1])
        wrong = _CENTER_LETTER[n_axis]
        if wrong in words:
            raise self.error(f"{wrong} word given for an arc in the {plane} plane",
                             words[wrong][1])  # fmt: skip
        turns = 1
        if "P" in words:
            used.add("P")
            p, pcol = words["P"]
            if abs(p - round(p)) <= 0.001:  # LinuxCNC (check_other_codes) rounds within it
                p = float(round(p))
            if p != int(p) or p < 1:
                raise self.error(f"arc turns P{p:g} must be a positive integer", pcol)
            if p > MAX_ARC_TURNS:
                raise self.error(f"arc turns P{p:.6g} is out of range (at most "
                                 f"{MAX_ARC_TURNS})", pcol)  # fmt: skip
            turns = int(p)
        ccw = self.m.motion == 30
        spiral_tol, radius_tol = arcs.tolerances(self.m.inch)
        s2, e2 = (start[a], start[b]), (end[a], end[b])
        try:
            if "R" in words:
                center = arcs.center_from_radius(s2, e2, words["R"][0] * self.m.scale, ccw,
                                                 radius_tol)  # fmt: skip
            else:
                if not ijk:
                    raise self.error("arc with neither R nor I/J/K words", col0)
                offs = []
                for axis in (a, b):
                    letter = _CENTER_LETTER[axis]
                    if letter in words:
                        offs.append(words[letter][0] * self.m.scale)
                    elif self.m.arc_absolute:
                        raise self.error(f"{letter} word missing in absolute center arc", col0)
                    else:
                        offs.append(0.0)
                center = (offs[0], offs[1]) if self.m.arc_absolute else (
                    s2[0] + offs[0], s2[1] + offs[1])  # fmt: skip
            r0, r1 = arcs.check_radii(s2, e2, center, spiral_tol, radius_tol)
            sweep = arcs.sweep_rad(s2, e2, center, ccw, turns)
        except arcs.ArcError as exc:
            col = words[exc.letter][1] if exc.letter in words else col0
            raise self.error(exc.message, col, GeometryError) from None
        c3 = list(start)
        c3[a], c3[b] = center
        helix = end[n_axis] - start[n_axis]
        # The length G93 divides (LinuxCNC's find_arc_length): the start radius's.
        length = r0 * abs(sweep) if helix == 0.0 else math.hypot(r0 * sweep, helix)
        feed = self.move_feed_mm_s(length, words)
        if feed <= 0.0:
            raise self.error("arc move with zero feed (set F first)", col0)
        to_machine = self.coords.to_machine
        self.emit(
            Arc(
                start_mm=vec3(to_machine(start)),
                end_mm=vec3(to_machine(end)),
                center_mm=vec3(to_machine(c3)),
                normal=vec3(self.coords.rotate_vector(PLANE_NORMALS[plane])),
                angle_rad=float(sweep),
                helix_mm=float(helix),
                radius_start_mm=float(r0),
                radius_end_mm=float(r1),
                feed_mm_s=feed,
                line=self.main_line(),
                plane=plane,
                blend_mm=self.m.blend_mm,
            )
        )
        self.prog = end

    # -- program stops ------------------------------------------------------------------------
    def stop(self, code: int, column: int) -> None:
        """M0 / M1 / M60: a Pause segment; M2 / M30: the end (nothing after is read)."""
        if code in (2, 30):
            if self.nurbs is not None:
                self.finish_nurbs_by_other(None, column)
            self.ended = True
            return
        if self.nurbs is not None:
            self.finish_nurbs_by_other(None, column)
        # After G40 the tool stands at the compensated point until the exit move.
        position = tuple(self.pos) if self.comp_exit is None else self.comp_exit
        self.segments.append(Pause(position, self.main_line(), f"M{code}"))


#: The words a canned cycle reads besides X, Y, Z, R, L and polar @ ^ (LinuxCNC's
#: check_other_codes): P with G74, G82, G84, G86, G88, G89; Q with G73, G83; I, J, K with G87.
CYCLE_WORDS = {730: "Q", 740: "P", 810: "", 820: "P", 830: "Q", 840: "P", 850: "", 860: "P",
               870: "IJK", 880: "P", 890: "P"}  # fmt: skip


def _cycles_reading(letter: str) -> str:
    """The canned cycles that read ``letter`` (:data:`CYCLE_WORDS`), as "G74, G82, …"."""
    return ", ".join(f"G{code // 10}" for code, reads in sorted(CYCLE_WORDS.items())
                     if letter in reads)  # fmt: skip


def _fmt_code(code: int) -> str:
    return str(code // 10) if code % 10 == 0 else f"{code // 10}.{code % 10}"


def _unused_word_message(letter: str) -> str:
    return {
        "I": f"I word with no arc (G2/G3), G5, G5.1, G10 or {_cycles_reading('I')} to use it",
        "J": f"J word with no arc (G2/G3), G5, G5.1, G10 or {_cycles_reading('J')} to use it",
        "K": f"K word with no arc (G2/G3), G6.2 NURBS or {_cycles_reading('K')} to use it",
        "R": "R word with no arc (G2/G3), canned cycle or G6.2 NURBS to use it",
        "P": f"P word with no G4, G10, G64, arc, G5, G5.2, G6.2, {_cycles_reading('P')} or "
             "M98 to use it",
        "Q": f"Q word with no G5, G10, G64, {_cycles_reading('Q')} or G6.2 to use it",
        "L": "L word with no G5.2 or G10 to use it",
        "H": "H word with no G43 to use it",
        "E": "E word with no M66, M67 or M68 to use it",
        "F": "F word not used",
    }.get(letter, f"{letter} word not used")


def interpret(blocks, lines, options: InterpretOptions) -> Program:
    """Interpret a program (pure: no I/O, no global state) into a :class:`Program`.

    ``lines`` are the source lines; they are parsed as execution reaches them. ``blocks``
    (pre-parsed, one per line) is accepted for compatibility and otherwise ignored. Raises
    :class:`ProgramError` subclasses carrying the line, column and source text.
    """
    state = _Interpreter(list(lines), options)
    state.run()
    parsed = state.main._blocks
    blocks = sum(1 for b in filter(None, parsed) if b.words or b.assigns)  # a Block is truthy
    if state.main.worded is not None:  # lines run by the fast lane (and never parsed)
        worded = np.frombuffer(state.main.worded, dtype=np.uint8).astype(bool)
        unparsed = np.fromiter(map(operator.is_, parsed, itertools.repeat(None)), dtype=bool,
                               count=len(parsed))  # fmt: skip
        blocks += int(np.count_nonzero(worded & unparsed))
    return Program(
        segments=tuple(state.segments),
        start_mm=vec3(options.start_mm),
        notes=tuple(state.notes),
        blocks=blocks,
        name=options.name,
    )
