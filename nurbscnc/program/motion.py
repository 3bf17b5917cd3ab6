"""The motion of a block (step 21 of LinuxCNC's order of execution, convert_motion): the
motion mode in force dispatched to one handler per kind of move — straight, arc, spline,
NURBS, canned cycle — and the moves' end points and feeds (a mixin of the interpreter)."""

from __future__ import annotations

import math
from typing import NamedTuple

from nurbscnc.errors import GeometryError, ProgramError, UnsupportedError
from nurbscnc.geometry.segments import PLANE_AXES, PLANE_NORMALS, Arc, Dwell, Line, Pause, vec3
from nurbscnc.program import arcs
from nurbscnc.program.codes import (
    CANNED_CYCLES,
    G_0,
    G_1,
    G_2,
    G_3,
    G_5,
    G_5_1,
    G_5_2,
    G_5_3,
    G_6_2,
    G_40,
    G_53,
    G_80,
    G_93,
    G_94,
    G_95,
    G_98,
    GM_MOTION,
    GM_NONMODAL,
    fmt_code,
)
from nurbscnc.program.cycles import CycleState, TooManyMoves, expand_cycle
from nurbscnc.program.rotary import ROTARY_LETTERS
from nurbscnc.program.words import (
    AXES,
    CYCLE_WORDS,
    MAX_ARC_TURNS,
    MAX_COORD_MM,
    unused_word_message,
)

_NORMAL_AXIS = {"XY": 2, "ZX": 1, "YZ": 0}
AXES_ABC = (*AXES, *ROTARY_LETTERS)
_CENTER_LETTER = {0: "I", 1: "J", 2: "K"}


class MotionWords(NamedTuple):
    """What a motion handler reads of its block: the words, the letters used so far (the
    handler adds its own), the block's motion code ``(code, column)`` or None, whether it
    has axis words that move (``has_axes``), whether a group-0 code took them
    (``axes_consumed``), G53 (``machine_coords``) and whether a cycle here starts a new run
    of cycle blocks (``fresh_cycle``)."""

    words: dict
    used: set
    motion_code: tuple | None
    has_axes: bool
    axes_consumed: bool
    machine_coords: bool
    fresh_cycle: bool


class Motion:
    """Motion dispatch and the straight and arc moves (mixin of the interpreter)."""

    def motion_block(self, gcodes, words, used, axes_consumed: bool) -> None:
        motion_code = gcodes.get(GM_MOTION)
        machine_coords = gcodes.get(GM_NONMODAL, (None,))[0] == G_53
        # A run of cycle blocks keeps its initial level and sticky words; any other motion
        # mode in between forgets them (LinuxCNC's cycle_il_flag).
        fresh_cycle = self.m.motion not in CANNED_CYCLES
        if machine_coords:
            self.check_g53(motion_code, gcodes[GM_NONMODAL][1])
        if motion_code is not None:
            self.set_motion_mode(motion_code, words, axes_consumed)
        if self.axes_consumed:
            self.axes_consumed = False
            axes_consumed = True
        for letter in "@^":
            if letter in words:
                used.add(letter)
        has_axes = not axes_consumed and (
            "X" in words
            or "Y" in words
            or "Z" in words
            or "@" in words
            or "^" in words
            or "A" in words
            or "B" in words
            or "C" in words
        )
        motion = self.m.motion
        if motion_code is not None and motion_code[0] in (G_5, G_5_1):
            motion = motion_code[0]  # this block's spline; the next line moves as before it
        handler = MOTION_HANDLERS.get(motion)
        if handler is not None:
            handler(
                self,
                motion,
                MotionWords(
                    words, used, motion_code, has_axes, axes_consumed, machine_coords, fresh_cycle
                ),
            )
        used.update(AXES)

    def check_g53(self, motion_code, column: int) -> None:
        """G53 (machine coordinates): only with G0 or G1, G90, and no compensation."""
        mode = motion_code[0] if motion_code else self.m.motion
        if mode not in (G_0, G_1):
            raise self.error("G53 needs G0 or G1 in force", column)
        if not self.m.absolute:
            raise self.error("G53 cannot be used with G91 (incremental)", column)
        if self.m.comp_mode != G_40 and self.m.comp_radius_mm > 0.0:
            raise self.error("Cannot use g53 with cutter radius comp", column)

    def set_motion_mode(self, motion_code, words: dict, axes_consumed: bool) -> None:
        """The block's group-1 code becomes the motion mode (G80 cancels it; G5 and G5.1
        keep the one in force, as LinuxCNC's convert_spline); an open NURBS block ends."""
        code, col = motion_code
        if self.nurbs is not None and code != self.nurbs_code():
            self.finish_nurbs_by_other(code, col)
        if code == G_80:
            self.m.motion = None
            if any(a in words for a in AXES_ABC) and not axes_consumed:
                raise self.error("axis words with G80 (motion cancelled)", col)
        elif code not in (G_5, G_5_1):
            self.m.motion = code

    # -- the handlers, one per kind of motion ------------------------------------------------
    def no_motion(self, motion, b: MotionWords) -> None:
        if b.has_axes:
            words = b.words
            letter = next(a for a in (*AXES_ABC, "@", "^") if a in words)
            raise self.error(
                f"{letter} word with no motion mode in force (G0, G1, G2, G3, G5.2, G6.2)",
                words[letter][1],
            )

    def straight_motion(self, motion, b: MotionWords) -> None:
        if b.has_axes:
            self.straight(b.words, b.machine_coords)

    def arc_motion(self, motion, b: MotionWords) -> None:
        # A block whose axis words a group-0 code took (G10 L2 P1 R45 under modal G2)
        # makes no arc: its R or P belong to that code (LinuxCNC's enhance_block).
        if (
            b.has_axes
            or b.motion_code is not None
            or (not b.axes_consumed and any(k in b.words for k in "IJKR"))
        ):
            self.arc(b.words, b.used)

    def refuse_in_comp(self, motion, b: MotionWords) -> None:
        """Splines and NURBS are not compensated, and carry no rotary axes (A B C words, or
        A B C held away from 0)."""
        turned = next((a for a in ROTARY_LETTERS if a in b.words), None)
        if turned is not None or self.m.abc_hold is not None:
            held = ", ".join(f"{a} {v:g}" for a, v in zip(ROTARY_LETTERS, self.m.rotary) if v)
            raise self.error(
                f"G{fmt_code(motion)} with rotary axes is not supported "
                + (f"({turned} word)" if turned else f"(the rotary axes stand at {held})"),
                b.words[turned][1] if turned else (b.motion_code[1] if b.motion_code else 1),
                UnsupportedError,
            )
        if self.comp is not None:
            raise self.error(
                f"G{fmt_code(motion)} with cutter radius compensation is not supported",
                b.motion_code[1] if b.motion_code else 1,
                UnsupportedError,
            )

    def spline_motion(self, motion, b: MotionWords) -> None:
        self.refuse_in_comp(motion, b)
        if b.has_axes or b.motion_code is not None:
            self.spline(b.words, b.used, motion, b.motion_code)

    def g5_2_motion(self, motion, b: MotionWords) -> None:
        self.refuse_in_comp(motion, b)
        self.g5(b.words, b.used, b.motion_code)

    def g5_3_motion(self, motion, b: MotionWords) -> None:
        self.g5_end(b.motion_code[1] if b.motion_code else 1)

    def g6_2_motion(self, motion, b: MotionWords) -> None:
        self.refuse_in_comp(motion, b)
        self.g6(b.words, b.used, b.motion_code)

    def cycle_motion(self, motion, b: MotionWords) -> None:
        if b.motion_code is not None and not b.has_axes and not b.axes_consumed:
            # LinuxCNC (enhance_block): only G0–G3 may stand without an axis word.
            raise self.error("All axes missing with motion code", b.motion_code[1])
        if b.has_axes or b.motion_code is not None:
            self.canned_cycle(motion, b.words, b.used, b.motion_code, b.fresh_cycle)

    # -- canned cycles (cycles.py) -------------------------------------------------------------
    def canned_cycle(self, code: int, words: dict, used: set, motion_code, fresh: bool) -> None:
        """G73, G74, G81–G89: expanded by cycles.py (LinuxCNC's convert_cycle) in program
        coordinates, then appended as rapids, feeds, dwells and pauses in machine coordinates
        (its spindle stops and starts have no segment). ``fresh``: the first block of a run
        of cycle blocks (a new initial level; sticky words forgotten)."""
        m = self.m
        col = motion_code[1] if motion_code else min(c for _, c in words.values())
        if m.feed_mode == G_93:
            raise self.error("Cannot use inverse time feed with canned cycles", col)
        if m.comp_mode != G_40:
            raise self.error("Cannot use canned cycles with cutter compensation on", col)
        given = self.cycle_words(code, words, used)
        if len(self.segments) + given.get("L", 1) > self.max_moves:  # each repeat moves
            self.over_budget(col, moves=True)
        try:
            result = expand_cycle(
                f"G{code // 10}",
                given,
                incremental=not m.absolute,
                position_mm=tuple(self.prog),
                plane=m.plane,
                retract="G98" if m.retract_mode == G_98 else "G99",
                feed_mm_s=self.feed_mm_s,
                state=CycleState() if fresh else m.cycle,
                spindle=m.spindle,
                max_moves=self.max_moves - len(self.segments),
            )
        except TooManyMoves:
            self.over_budget(col, moves=True)
        except ProgramError as exc:
            raise self.error(exc.message, col) from None
        self.append_cycle(result.moves)
        self.prog = list(result.position_mm)
        m.cycle = result.state

    def cycle_words(self, code: int, words: dict, used: set) -> dict:
        """The words the cycle reads, lengths in mm (LinuxCNC's check_other_codes: besides X
        Y Z R L and polar @ ^ a cycle reads only its own words; a P, Q, I, J or K that
        neither it nor another code of the block (G4, G10, G64, M19, M98: marked used
        before the motion) reads is an error)."""
        reads = "XYZRL@^" + CYCLE_WORDS[code]
        for letter in "PQIJK":
            if letter in words and letter not in reads and letter not in used:
                raise self.error(unused_word_message(letter), words[letter][1])
        given = {}
        scale = self.m.scale
        for letter in reads:
            if letter in words:
                value = words[letter][0]
                given[letter] = value * scale if letter in "XYZRQIJK@" else value
                used.add(letter)
        return given

    def append_cycle(self, moves) -> None:
        """A cycle's moves (program mm) as segments in machine coordinates."""
        line = self.main_line()
        to_machine = self.coords.to_machine
        blend_mm = self.m.blend_mm
        start = tuple(self.pos)
        for move in moves:
            if move.kind in ("rapid", "feed"):
                end = tuple(to_machine(list(move.end_mm)))
                if end != start:
                    self.segments.append(
                        Line(
                            start,
                            end,
                            move.feed_mm_s,
                            line,
                            move.kind == "rapid",
                            blend_mm,
                            0.0,
                            self.m.abc_hold,
                        )
                    )
                start = end
            elif move.kind == "dwell":
                self.segments.append(Dwell(float(move.dwell_s), start, line))
            elif move.kind == "pause":  # G88: the operator takes over (LinuxCNC: M0)
                self.segments.append(Pause(start, line, "M0"))

    # -- end points and feeds ------------------------------------------------------------------
    def target_program(self, words: dict, base=None) -> list:
        """End point [mm, program coordinates] of a move: axis (or polar) words in the units
        and distance mode in force."""
        base = self.prog if base is None else base
        out = list(base)
        scale = self.m.scale
        absolute = self.m.absolute
        for i, letter in enumerate(AXES):
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
            for i, letter in enumerate(AXES):
                if letter in words:
                    out[i] = words[letter][0] * self.m.scale
            return out
        prog_base = None if base is None else self.coords.to_program(base)
        return self.coords.to_machine(self.target_program(words, prog_base))

    def rapid_to_program(self, end_prog, abc_deg: tuple | None = None) -> None:
        """A traverse to ``end_prog`` [mm, program], the rotary axes to ``abc_deg`` [deg,
        machine] (None: they stay)."""
        start = self.pos
        end = self.coords.to_machine(end_prog)
        if abc_deg is not None and abc_deg != self.m.rotary:
            self.rotary_straight(start, end, abc_deg, {}, True)
        elif end != start or self.comp_exit is not None:
            m = self.m
            self.emit(
                Line(
                    tuple(start),
                    tuple(end),
                    0.0,
                    self.main_line(),
                    True,
                    m.blend_mm,
                    0.0,
                    m.abc_hold,
                )
            )
        self.prog = list(end_prog)

    def move_feed_mm_s(self, length_mm: float, words: dict) -> float:
        """The feed [mm/s] of a G1/G2/G3 move of ``length_mm`` (G93: F is 1/minutes)."""
        m = self.m
        if m.feed_mode == G_93:
            if "F" not in words:
                raise self.error("G93 (inverse time) moves need an F word on every line")
            # LinuxCNC's inverse_time_rate_*: at least 0.1 program units per minute.
            return max(length_mm * m.feed, 0.1 * m.scale) / 60.0
        if m.feed_mode == G_95 and m.spindle_rpm <= 0.0:
            raise self.error("G95 feed per revolution with spindle speed S0")
        return self.feed_mm_s

    def straight_feed_mm_s(self, start, end, words: dict, rapid: bool) -> float:
        """The feed [mm/s] along X Y Z of a straight move from machine ``start`` to ``end``
        [mm]: 0 for a rapid, F under G94 (the mm/min set by the last F), else
        :meth:`move_feed_mm_s` of its length; a feed move without a feed is refused."""
        if rapid:
            return 0.0
        m = self.m
        if m.feed_mode == G_94:
            feed = m.feed_mm / 60.0
        else:
            feed = self.move_feed_mm_s(math.dist(start, end), words)
        if feed <= 0.0:
            raise self.error("G1 move with zero feed (set F first)", 1)
        return feed

    # -- straight moves and arcs -------------------------------------------------------------
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
        rapid = m.motion == G_0
        if "A" in words or "B" in words or "C" in words:
            abc1 = self.target_abc(words, machine_coords)
            if abc1 != m.rotary:
                self.rotary_straight(start, end, abc1, words, rapid)
                self.prog = end_prog
                return
        feed = self.straight_feed_mm_s(start, end, words, rapid)
        if end != start or self.comp_exit is not None:  # the exit move may not be zero
            line = self.line_no if self.source is self.main else self.main_line()
            self.emit(
                Line(
                    tuple(start), tuple(end), feed, line, rapid, m.blend_mm, m.naive_mm, m.abc_hold
                )
            )
        self.prog = end_prog

    def arc_turns(self, words: dict, used: set) -> int:
        """The turns of an arc: P (1 without it), LinuxCNC's P rounded within 0.001."""
        if "P" not in words:
            return 1
        used.add("P")
        p, pcol = words["P"]
        if abs(p - round(p)) <= 0.001:  # LinuxCNC (check_other_codes) rounds within it
            p = float(round(p))
        if p != int(p) or p < 1:
            raise self.error(f"arc turns P{p:g} must be a positive integer", pcol)
        if p > MAX_ARC_TURNS:
            raise self.error(f"arc turns P{p:.6g} is out of range (at most {MAX_ARC_TURNS})", pcol)
        return int(p)

    def arc_centre(self, words: dict, s2, e2, ijk, ccw: bool, radius_tol: float, col0: int):
        """The arc's centre (plane coordinates, program mm) from R or from I J K."""
        plane = self.m.plane
        a, b = PLANE_AXES[plane]
        if "R" in words:
            return arcs.center_from_radius(s2, e2, words["R"][0] * self.m.scale, ccw, radius_tol)
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
        return (offs[0], offs[1]) if self.m.arc_absolute else (s2[0] + offs[0], s2[1] + offs[1])

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
            raise self.error(f"{wrong} word given for an arc in the {plane} plane", words[wrong][1])
        turns = self.arc_turns(words, used)
        ccw = self.m.motion == G_3
        spiral_tol, radius_tol = arcs.tolerances(self.m.inch)
        s2, e2 = (start[a], start[b]), (end[a], end[b])
        try:
            center = self.arc_centre(words, s2, e2, ijk, ccw, radius_tol, col0)
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
        abc0 = self.m.rotary
        abc1 = abc0
        if "A" in words or "B" in words or "C" in words:
            abc1 = self.target_abc(words)
            self.refuse_rotary_in_comp(abc0, abc1)
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
                abc_deg=self.m.abc_hold if abc1 == abc0 else abc0 + abc1,
            )
        )
        self.set_rotary_position(abc1, words)
        self.prog = end


#: The handler of each motion mode (None: no motion mode in force); a mode not here moves
#: nothing.
MOTION_HANDLERS = {
    None: Motion.no_motion,
    G_0: Motion.straight_motion,
    G_1: Motion.straight_motion,
    G_2: Motion.arc_motion,
    G_3: Motion.arc_motion,
    G_5: Motion.spline_motion,
    G_5_1: Motion.spline_motion,
    G_5_2: Motion.g5_2_motion,
    G_5_3: Motion.g5_3_motion,
    G_6_2: Motion.g6_2_motion,
    **dict.fromkeys(CANNED_CYCLES, Motion.cycle_motion),
}
