"""The rotary axes A, B, C as LinuxCNC 2.9's interpreter runs them (a mixin of the interpreter).

Degrees whatever G20/G21 says (the canon converts angles with ``FROM_PROG_ANG``, the identity);
G90 / G91 as for X Y Z; under G90 a wrapped axis (the profile's ``wrapped``, LinuxCNC's
``[AXIS_A]WRAPPED_ROTARY``) reads its word as a position in [0, 360) reached the way its sign
says (``interp_find.cc``, ``unwrap_rotary``). The interpreter keeps the rotary axes' MACHINE
position (``ModalState.rotary``); program A = machine A − G92 A − the active system's A
(:meth:`~nurbscnc.program.coords.Coordinates.abc_shift_deg`), so an offset change never moves
them.

A straight move whose XYZ length is at most 1e-7 program units but that turns A B C is a
:class:`~nurbscnc.geometry.segments.Rotate` (LinuxCNC's canon: an "angular only" move, F in
degrees per minute; under G93 the interpreter's rate is the rotary length √(ΔA²+ΔB²+ΔC²)
times F, ``interp_find.cc``, ``find_straight_length``); any other move carries its A B C in
``abc_deg``, linear along the XYZ path, its feed along XYZ (LinuxCNC's canon for a move with
XYZ motion, NIST IR6556 §2.1.2.5 A).

A word that would move an axis the machine lacks (``InterpretOptions.rotary_axes`` has no such
name) is refused at the word; a word that keeps it where it is (``A0.`` of a 3-axis post) is
carried. Soft limits (``min_deg``, ``max_deg``) are checked at each move's end here (A B C
move linearly along a move, so its ends bound it), in machine coordinates.
"""

from __future__ import annotations

import math

from nurbscnc.errors import UnsupportedError
from nurbscnc.geometry.segments import Line, Rotate
from nurbscnc.program.codes import G_93, G_95
from nurbscnc.program.coords import SYSTEM_NAMES
from nurbscnc.program.words import MAX_ANGLE_DEG

ROTARY_LETTERS = ("A", "B", "C")
#: LinuxCNC's threshold below which a straight move has no XYZ motion [program units]
#: (``find_straight_length``, the canon's ``cartesian_move``).
XYZ_ZERO = 1e-7
#: A full turn [deg]: a wrapped axis's G90 word must lie strictly inside ±360.
TURN_DEG = 360.0


def wrapped_word_error(value: float, letter: str) -> str:
    """LinuxCNC's refusal of a wrapped axis's absolute word beyond one turn (its %5.2f)."""
    return f"Invalid absolute position {value:5.2f} for wrapped rotary axis {letter}"


def unwrap_deg(word: float, current_deg: float, angle: float | None = None) -> float:
    """The program position [deg] a G90 word takes a wrapped axis to from ``current_deg``:
    |angle| (the word, or for G53 the word less the offsets) in the current turn, one turn
    on (off) when it lies behind (ahead) and the word's sign is + (−); the sign of −0 counts
    (LinuxCNC's ``unwrap_rotary(result, sign_of, angle, current)``)."""
    angle = word if angle is None else angle
    result = abs(angle) + TURN_DEG * math.floor(current_deg / TURN_DEG)
    negative = math.copysign(1.0, word) < 0.0
    if not negative and result < current_deg:
        result += TURN_DEG
    if negative and result > current_deg:
        result -= TURN_DEG
    return result


class RotaryAxes:
    """A B C words, their moves and offsets (mixin of the interpreter: it provides ``m``,
    ``coords``, ``options``, ``comp``, ``comp_exit``, ``segments``, ``error``, ``emit``,
    ``main_line`` and ``move_feed_mm_s``)."""

    def rotary_axis(self, letter: str):
        """The machine's axis ``letter`` (RotaryAxis) or None when it has none."""
        axes = self.options.rotary_axes
        return axes.get(letter.lower()) if axes else None

    def program_abc_deg(self) -> tuple:
        """The current A B C in program coordinates [deg]."""
        shift = self.coords.abc_shift_deg()
        return tuple(r - s for r, s in zip(self.m.rotary, shift, strict=True))

    def rotary_words(self, words: dict, gcodes: dict, mcodes: dict, used: set) -> None:
        """Step of the order of execution for A B C: they are read by the motion or the
        group-0 code of the block (:meth:`target_abc`, :meth:`abc_offsets`)."""
        for letter in ROTARY_LETTERS:
            if letter in words:
                used.add(letter)

    def target_abc(self, words: dict, machine_coords: bool = False) -> tuple:
        """The machine A B C [deg] a move's words take the rotary axes to (G90, G91, G53,
        wrapped axes); the axes without a word stay."""
        shift = self.coords.abc_shift_deg()
        out = list(self.m.rotary)
        for i, letter in enumerate(ROTARY_LETTERS):
            if letter not in words:
                continue
            value, col = words[letter]
            axis = self.rotary_axis(letter)
            current = out[i] - shift[i]
            wrapped = axis is not None and axis.wrapped and (self.m.absolute or machine_coords)
            if wrapped and not -TURN_DEG < value < TURN_DEG:
                raise self.error(wrapped_word_error(value, letter), col)
            if machine_coords and wrapped:
                # LinuxCNC's find_ends for G53 unwraps |word − offsets| about the program
                # position, the word's sign the direction (checked with rs274 -i).
                machine = unwrap_deg(value, current, value - shift[i]) + shift[i]
            elif machine_coords:
                machine = value
            elif not self.m.absolute:
                machine = current + value + shift[i]
            elif wrapped:
                machine = unwrap_deg(value, current) + shift[i]
            else:
                machine = value + shift[i]
            if not abs(machine) <= MAX_ANGLE_DEG:
                raise self.error(
                    f"{letter}{value:.6g} is out of range (the position would be beyond "
                    f"±{MAX_ANGLE_DEG:g} degrees)",
                    col,
                )
            if axis is None and machine != out[i]:
                raise self.error(
                    f"the machine has no {letter} axis ({letter}{value:g} would turn it from "
                    f"{out[i]:g} to {machine:g} degrees; the machine profile has no "
                    f"[axis_limits.{letter.lower()}])",
                    col,
                )
            out[i] = machine
        return tuple(out)

    def check_rotary_limits(self, abc_deg: tuple, words: dict) -> None:
        """The soft limits of each rotary axis at a move's end (machine coordinates), the
        error naming the offsets that put it there, at the axis's word (column 1 without)."""
        shift_origin, shift_g92 = self.coords.origin_abc_deg, self.coords.g92_abc_deg
        for i, letter in enumerate(ROTARY_LETTERS):
            axis = self.rotary_axis(letter)
            if axis is None or axis.min_deg <= abc_deg[i] <= axis.max_deg:
                continue
            offsets = f"{SYSTEM_NAMES[self.coords.system]} offset {letter} {shift_origin[i]:g}"
            if shift_g92[i]:
                offsets += f", G92 {letter} {shift_g92[i]:g}"
            raise self.error(
                f"the move leaves the soft limits: {letter} reaches {abc_deg[i]:.6g} degrees "
                f"in machine coordinates ({offsets}), outside [{axis.min_deg:g}, "
                f"{axis.max_deg:g}] degrees",
                words[letter][1] if letter in words else 1,
            )

    def refuse_rotary_in_comp(self, abc0: tuple, abc1: tuple) -> None:
        """Cutter compensation carries A B C where they stand; turning them under it is not
        supported (its corner moves would need a rotary position of their own)."""
        if self.comp is not None and abc0 != abc1:
            raise self.error(
                "a rotary axis move (A, B, C) with cutter radius compensation on is not supported",
                1,
                UnsupportedError,
            )

    def set_rotary_position(self, abc1: tuple, words: dict) -> None:
        """The rotary axes are now at ``abc1`` [deg, machine]: soft limits checked."""
        if abc1 != self.m.rotary:
            self.check_rotary_limits(abc1, words)
            self.m.set_rotary(abc1)

    def rotary_feed_deg_s(self, abc0: tuple, abc1: tuple, words: dict) -> float:
        """The rate [deg/s] of a G1 of the rotary axes alone: F in deg/min (G94), the rotary
        length times F under G93 (LinuxCNC's floor of 0.1 per minute), F per revolution
        times the spindle speed under G95."""
        m = self.m
        if m.feed_mode == G_93:
            if "F" not in words:
                raise self.error("G93 (inverse time) moves need an F word on every line")
            return max(math.dist(abc0, abc1) * m.feed, 0.1) / 60.0
        if m.feed_mode == G_95:
            if m.spindle_rpm <= 0.0:
                raise self.error("G95 feed per revolution with spindle speed S0")
            return m.feed * m.spindle_rpm / 60.0
        return m.feed / 60.0

    def rotary_straight(self, start, end, abc1: tuple, words: dict, rapid: bool) -> None:
        """A straight move (machine ``start`` → ``end`` [mm]) that turns the rotary axes from
        where they stand to ``abc1`` [deg]: a Rotate when XYZ stay (within
        :data:`XYZ_ZERO` program units), else a Line carrying both ends' A B C."""
        m = self.m
        abc0 = m.rotary
        self.refuse_rotary_in_comp(abc0, abc1)
        origin = self.comp_exit if self.comp_exit is not None else start
        line = self.main_line()
        if math.dist(origin, end) <= XYZ_ZERO * m.scale:
            feed = 0.0 if rapid else self.rotary_feed_deg_s(abc0, abc1, words)
            if not rapid and feed <= 0.0:
                raise self.error("G1 move with zero feed (set F first)", 1)
            self.segments.append(Rotate(tuple(origin), abc0, abc1, feed, line, rapid))
            self.comp_exit = None
        else:
            feed = self.straight_feed_mm_s(start, end, words, rapid)
            self.emit(
                Line(
                    tuple(start), tuple(end), feed, line, rapid, m.blend_mm, m.naive_mm, abc0 + abc1
                )
            )
        self.set_rotary_position(abc1, words)

    def abc_offsets(self, words: dict, wrapped_check: bool) -> dict:
        """The A B C words of G10 / G92 / G52 as ``{3 + i: degrees}`` (never scaled by G20);
        ``wrapped_check``: a wrapped axis refuses |word| ≥ 360 (LinuxCNC's G92 and G10 L20)."""
        out = {}
        for i, letter in enumerate(ROTARY_LETTERS):
            if letter in words:
                value, col = words[letter]
                axis = self.rotary_axis(letter)
                if wrapped_check and axis is not None and axis.wrapped:
                    if not -TURN_DEG < value < TURN_DEG:
                        raise self.error(wrapped_word_error(value, letter), col)
                out[3 + i] = value
        return out

    def home_abc_to_store(self, which: int):
        """A B C [deg, machine] for G28.1 / G30.1, a wrapped axis's taken into [0, 360)
        (LinuxCNC's convert_savehome); None when they and the stored ones are all 0 (nothing
        changes)."""
        if self.m.abc_hold is None:
            return [0.0, 0.0, 0.0] if any(self.coords.home_abc_deg(which)) else None
        out = []
        for letter, value in zip(ROTARY_LETTERS, self.m.rotary, strict=True):
            axis = self.rotary_axis(letter)
            # into [0, 360): LinuxCNC stores 350 for A at -370 (checked with rs274 -i)
            out.append(value % TURN_DEG if axis is not None and axis.wrapped else value)
        return out

    def refuse_rotary_tool_offset(self, words: dict) -> None:
        """Tool offsets on A B C (G10 L1/L10/L11, G43.1 with a rotary word) are not
        supported."""
        for letter in ROTARY_LETTERS:
            if letter in words:
                raise self.error(
                    f"a tool offset on a rotary axis ({letter} word) is not supported",
                    words[letter][1],
                    UnsupportedError,
                )

    def used_rotary_axes(self, start_abc: tuple) -> tuple:
        """The axes ("a", "b", "c") the program moves or holds away from 0 (the segments'
        rotary columns, from ``start_abc`` [deg] on)."""
        used = [v != 0.0 for v in start_abc]
        if not self.m.rotary_seen:
            return ()
        for seg in self.segments:
            kind = seg.kind
            if kind == "rotate":
                ends = (*seg.abc_start_deg, *seg.abc_end_deg)
            elif kind in ("line", "rapid", "arc") and seg.abc_deg is not None:
                ends = seg.abc_deg
            else:
                continue
            for i in range(3):
                used[i] = used[i] or ends[i] != 0.0 or ends[3 + i] != 0.0
        return tuple(name for name, u in zip("abc", used, strict=True) if u)
