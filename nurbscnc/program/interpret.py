"""Interpret G-code into path segments: the interpreter's state and its program counter.

Input: a program text (parsed line by line as execution reaches it, see
:mod:`nurbscnc.program.control`); output: a :class:`~nurbscnc.geometry.segments.Program` of
Line / Arc / Nurbs / Dwell / Pause segments in absolute machine mm with feeds in mm/s. The
rules follow LinuxCNC 2.9's interpreter; every departure is a documented decision and every
refusal an error naming the word.

The jobs are split as LinuxCNC splits them: parsing (parse.py), expressions
(expressions.py), the codes and their modal groups (codes.py), modal state (modal.py), the
parameter store (params.py), the block executor in LinuxCNC's order (executor.py) with its
modal setters (modes.py), motion (motion.py), arcs (arcs.py), coordinate systems
(coords.py), O-word control flow (control.py), NURBS and splines (nurbsblock.py), tool
tables (tooltable.py); canned cycles (cycles.py) and cutter compensation (compensation.py,
compstream.py) plug in at ``Motion.canned_cycle`` and ``CompStream.compensate``. This file
runs the program line by line, or in bulk where the fast lane (fastlane.py) can.
"""

from __future__ import annotations

import itertools
import operator
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from nurbscnc.errors import NurbsCncError, ProgramError, SourcePos
from nurbscnc.geometry.segments import Note, Program, vec3
from nurbscnc.program import coords, fastlane
from nurbscnc.program.codes import G_94, G_95
from nurbscnc.program.compensation import CutterComp
from nurbscnc.program.compstream import CompStream
from nurbscnc.program.control import ControlFlow, Frame, Source
from nurbscnc.program.executor import BlockExecutor
from nurbscnc.program.fastlane import (
    BulkState,
    make_lines,
    nurbs_words,
    pause_cyclic_gc,
    plain_run,
)
from nurbscnc.program.modal import INCH_MM, ModalState
from nurbscnc.program.modes import ModeSetters
from nurbscnc.program.motion import Motion
from nurbscnc.program.nurbsblock import NurbsBlocks, Splines, g5_knot_vector
from nurbscnc.program.params import ParameterStore
from nurbscnc.program.parse import split_lines
from nurbscnc.program.rotary import RotaryAxes
from nurbscnc.program.tooltable import Tool
from nurbscnc.program.words import MAX_COORD_MM, MAX_FEED_MM_MIN, MIN_FEED_MM_MIN

__all__ = ["InterpretOptions", "interpret", "interpret_text", "g5_knot_vector", "INCH_MM"]


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
    ``parameters``: the numbered parameters in force before the program (a LinuxCNC
    parameter file's, see varfile.py; lengths in mm): the active system, its offsets, G92,
    the G28/G30 positions; the program's :attr:`~nurbscnc.geometry.segments.Program.parameters`
    are their values at its end. ``find_user_m(code)``: the executable's path of the user
    M-code ``code`` (100..199) or None (the CLI searches the user-M path; no I/O here).
    ``rotary_axes``: the machine's rotary axes by name ("a", "b", "c":
    :class:`~nurbscnc.machine.model.RotaryAxis`, the profile's ``Machine.rotary_axes``; None
    or empty: a three-axis machine, which refuses a word that turns A, B or C; see rotary.py);
    ``start_abc_deg`` their start position [deg, machine].
    """

    start_mm: tuple = (0.0, 0.0, 0.0)
    block_delete: bool = True
    tool_lengths_mm: dict | None = None
    name: str = "<program>"
    tools: dict | None = None
    load_subroutine: Callable[[str], tuple[str, str] | None] | None = None
    max_call_depth: int = 100
    max_loop_iterations: int = 250_000
    #: A move holds about 300 bytes until it is planned: the bounds keep a runaway loop to
    #: seconds of interpreting and its moves to well under a gigabyte.
    extra_lines: int = 5_000_000
    extra_moves: int = 2_000_000
    #: Interpret runs of plain G0/G1 lines in bulk (fastlane.py; same segments, faster).
    fast_lane: bool = True
    parameters: dict | None = None
    find_user_m: Callable[[int], str | None] | None = None
    rotary_axes: dict | None = None
    start_abc_deg: tuple = (0.0, 0.0, 0.0)


def interpret_text(text: str, options: InterpretOptions | None = None) -> Program:
    """Interpret a whole program text (see :func:`interpret`)."""
    return interpret(None, split_lines(text), options or InterpretOptions())


class _Interpreter(
    ControlFlow,
    coords.OffsetCommands,
    NurbsBlocks,
    Splines,
    ParameterStore,
    BlockExecutor,
    ModeSetters,
    Motion,
    RotaryAxes,
    CompStream,
):
    """The interpreter's state; its jobs come from the mixins (see the module docstring).
    One instance per call of :func:`interpret` (local state)."""

    def __init__(self, lines, options: InterpretOptions):
        # At most 29 attributes: CPython 3.11 keeps an instance's attributes inline, with
        # specialised fast attribute access, only while its class's shared keys hold fewer
        # than 30 names; past them every ``self.x`` of the interpreter goes through a dict
        # (several per cent slower on whole programs). State needed by one method stays local.
        self.options = options
        self.main = Source(lines, options.name)
        self.lines = lines
        self.m = ModalState()
        self.segments: list = []
        self.coords = coords.Coordinates(segments=self.segments)
        self.params: dict[int, float] = {}
        if options.parameters:
            self.coords.restore(options.parameters)
            for index, value in options.parameters.items():
                if not coords.is_coordinate_parameter(index):
                    self.params[index] = float(value)
        # program position [mm] of the machine start point
        self.prog = self.coords.to_program(list(map(float, options.start_mm)))
        self.m.set_rotary(tuple(map(float, options.start_abc_deg)))
        self.globals: dict[str, float] = {}
        self.frames = [Frame(self.main, 0)]
        self.source = self.main
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
        if m.feed_mode == G_95:
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

    # -- the program counter ----------------------------------------------------------------
    def run(self) -> None:
        block_delete = self.options.block_delete
        fast = self.options.fast_lane
        percent_seen = False  # the main program opened with a % line
        while not self.ended:
            frame = self.frames[-1]
            source = frame.source
            pc = frame.pc
            if pc >= len(source.lines):
                self.end_of_source(frame)
                break
            self.source = source
            if fast and source._blocks[pc] is None and self.fast_lane(source, frame, pc):
                continue
            block = self.next_block(source, frame, pc)
            if block.percent:
                if source is self.main:
                    if percent_seen:
                        break  # the second % ends the tape
                    self.opening_percent(pc)
                    percent_seen = True
                continue
            if block.delete and block_delete:
                continue
            if block.oword is not None:
                self.oword(block, frame)
            elif block.words or block.assigns or block.comments:
                self.block(block)
        self.finish()

    def end_of_source(self, frame) -> None:
        """The end of a file: the program's end, an error inside a called one."""
        if len(self.frames) > 1:
            self.line_no = len(frame.source.lines)
            raise self.error(f"end of file inside subroutine o{frame.label}")

    def fast_lane(self, source: Source, frame, pc: int) -> bool:
        """The lines at ``pc`` run in bulk where the fast lane takes them (no compensation,
        G94): True when it took some."""
        if self.comp is not None or self.comp_exit is not None or self.m.feed_mode != G_94:
            return False
        if self.nurbs is None:
            count = self.bulk(source, pc) if self.m.absolute else 0
        else:
            count = self.g6_lane(source, frame, pc)
        if not count:
            return False
        frame.pc = pc + count
        self.executed += count
        if self.executed > self.max_executed or len(self.segments) > self.max_moves:
            self.over_budget()
        return True

    def next_block(self, source: Source, frame, pc: int):
        """The block of line ``pc``, which becomes the line executing (parse errors in a
        called file say where in it)."""
        self.line_no = pc + 1
        frame.pc = pc + 1
        self.executed += 1
        if self.executed > self.max_executed or len(self.segments) > self.max_moves:
            self.over_budget()
        try:
            return source._blocks[pc] or source.block(pc)
        except NurbsCncError as exc:
            if source is not self.main and exc.pos is not None:
                raise self.error(exc.message, exc.pos.column, type(exc)) from None
            raise

    def opening_percent(self, pc: int) -> None:
        """The first % line of the main program: it opens a tape only as the program's first
        non-blank line (LinuxCNC's rs274ngc_pre.cc, open); any other % line is a bad
        character (interp_read.cc)."""
        if any(line.strip() for line in self.lines[:pc]):
            raise self.error(
                "Bad character '%' used (a % line ends the program only when the "
                "program's first line is a %)",
                self.lines[pc].find("%") + 1,
            )

    def over_budget(self, column: int = 1, moves: bool = False) -> None:
        """The error of a program past its budget of executed lines or of moves
        (:class:`InterpretOptions` ``extra_lines``, ``extra_moves``), at the line reached."""
        if moves or len(self.segments) > self.max_moves:
            what = f"makes more than {self.options.extra_moves:,} moves"
        else:
            what = f"executes more than {self.options.extra_lines:,} lines"
        raise self.error(
            f"the program {what} beyond one per line of its own (a loop, call, "
            f"L repeat or peck (G73, G83 Q) that runs away?)",
            column,
        )

    def bulk(self, source: Source, pc: int) -> int:
        """Interpret the run of plain straight-move lines at ``source.lines[pc]`` in bulk
        (fastlane.py: the same segments as line by line); returns the lines consumed (0:
        the line is not one the fast lane takes)."""
        m = self.m
        state = BulkState(m.motion, m.feed, m.feed_mm, tuple(self.prog), m.scale)
        run = plain_run(
            source.lines,
            pc,
            state,
            self.coords.to_machine_array,
            (MAX_COORD_MM, MIN_FEED_MM_MIN, MAX_FEED_MM_MIN),
        )
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
            self.segments += make_lines(
                {
                    "start_mm": run.starts_mm,
                    "end_mm": run.ends_mm,
                    "feed_mm_s": run.feeds_mm_s,
                    "line": numbers,
                    "rapid": run.rapid,
                    "blend_mm": itertools.repeat(blend_mm),
                    "naive_mm": itertools.repeat(m.naive_mm),
                    "abc_deg": itertools.repeat(m.abc_hold),
                }
            )
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

    def final_parameters(self) -> dict:
        """The numbered parameters at the program's end (``{number: value}``, lengths in
        mm): what LinuxCNC writes to its parameter file. M2 / M30 make G54 active again
        (#5220 = 1, LinuxCNC's convert_stop); the offsets and G92 stay."""
        values = {**self.params, **self.coords.params}
        if self.ended:
            values[coords.SYSTEM_INDEX] = 1.0
        return values

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


def interpret(blocks, lines, options: InterpretOptions) -> Program:
    """Interpret a program (pure: no I/O, no global state) into a :class:`Program`.

    ``lines`` are the source lines; they are parsed as execution reaches them. ``blocks``
    (pre-parsed, one per line) is accepted for compatibility and otherwise ignored. Raises
    :class:`ProgramError` subclasses carrying the line, column and source text.
    """
    state = _Interpreter(list(lines), options)
    start_abc = tuple(map(float, options.start_abc_deg))
    state.run()
    parsed = state.main._blocks
    blocks = sum(1 for b in filter(None, parsed) if b.words or b.assigns)  # a Block is truthy
    if state.main.worded is not None:  # lines run by the fast lane (and never parsed)
        worded = np.frombuffer(state.main.worded, dtype=np.uint8).astype(bool)
        unparsed = np.fromiter(
            map(operator.is_, parsed, itertools.repeat(None)), dtype=bool, count=len(parsed)
        )
        blocks += int(np.count_nonzero(worded & unparsed))
    return Program(
        segments=tuple(state.segments),
        start_mm=vec3(options.start_mm),
        notes=tuple(state.notes),
        blocks=blocks,
        name=options.name,
        parameters=state.final_parameters(),
        frames=tuple(state.coords.frames),
        rotary_axes=state.used_rotary_axes(start_abc),
        start_abc_deg=start_abc,
    )
