"""The block executor: a parsed block's words read into G and M codes by modal group, then
executed in LinuxCNC's order (interp_execute.cc, execute_block) as a sequence of steps (a
mixin of the interpreter)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import NamedTuple

from nurbscnc.errors import UnsupportedError
from nurbscnc.geometry.segments import Note, Pause
from nurbscnc.program.codes import (
    CANNED_CYCLES,
    G_0,
    G_1,
    G_2_2,
    G_5_2,
    G_80,
    G_GROUP,
    G_REFUSED,
    GM_CONTROL_MODE,
    GM_COORD_SYSTEM,
    GM_CUTTER_COMP,
    GM_DISTANCE,
    GM_FEED_MODE,
    GM_IJK_DISTANCE,
    GM_MOTION,
    GM_NONMODAL,
    GM_PLANE,
    GM_RETURN_MODE,
    GM_TOOL_LENGTH,
    GM_UNITS,
    M_2,
    M_19,
    M_30,
    M_98,
    M_99,
    M_GROUP,
    MM_IO,
    MM_MODAL_STATE,
    MM_OVERRIDE,
    MM_SPINDLE,
    MM_STOP,
    MM_TOOL_CHANGE,
    MM_USER,
    fmt_code,
)
from nurbscnc.program.modes import ModeSetters
from nurbscnc.program.parse import Block
from nurbscnc.program.rotary import RotaryAxes
from nurbscnc.program.words import unused_word_message

_PLAIN_WORDS = frozenset("XYZF")
_COMMON_CODES = {
    float(v): 10 * v for v in (0, 1, 2, 3, 17, 18, 19, 20, 21, 40, 49, 54, 80, 90, 91, 94)
}


def _comment_body(text: str) -> str:
    """A comment's text without its delimiters: ``(…)`` or ``; …``."""
    return (text[1:-1] if text.startswith("(") else text[1:]).strip()


def _msg_text(body: str) -> str | None:
    """The operator's message of a comment body ``MSG, text`` (any case), else None."""
    return body[4:].strip() if body[:4].upper() == "MSG," else None


class BlockExecutor:
    """Reading a block's words and executing them (mixin of the interpreter)."""

    def block(self, block: Block) -> None:
        for _, text, _column in block.comments:
            message = _msg_text(_comment_body(text)) if text.startswith("(") else None
            if message is not None:
                self.notes.append(Note(self.main_line(), f"message: {message}"))
        words, gcodes, mcodes = self.read_words(block)
        if block.assigns:
            self.assign(block)
        if words or gcodes or mcodes:
            before = len(self.segments)
            self.execute(words, gcodes, mcodes)
            if mcodes and block.comments and len(self.segments) > before:
                self.label_pauses(block, before)

    def label_pauses(self, block: Block, first: int) -> None:
        """The block's stops (M0, M1, M60, M6, a user M-code: the segments from ``first``
        on) carry the line's text for the operator: its MSG, else its last comment (the
        one LinuxCNC keeps when a line has several)."""
        message = ""
        for _, text, _column in block.comments:
            body = _comment_body(text)
            msg = _msg_text(body)
            if msg is not None:
                message = msg
                break
            message = body
        if not message:
            return
        for i in range(first, len(self.segments)):
            seg = self.segments[i]
            if type(seg) is Pause and not seg.message:
                self.segments[i] = replace(seg, message=message)

    # -- reading the words -------------------------------------------------------------------
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
                self.bad_letter(letter, column)
            else:
                words[letter] = (value, column)
        return words, gcodes, mcodes

    def bad_letter(self, letter: str, column: int):
        if letter in "UVW":
            raise self.error(
                f"axis {letter} is not supported (nurbscnc drives X, Y and Z)",
                column,
                UnsupportedError,
            )
        if letter == "O":
            raise self.error("O word must start the line (o<label> keyword)", column)
        raise self.error("N (line number) must start the line", column)

    def read_g(self, value: float, column: int, gcodes: dict) -> None:
        code = _COMMON_CODES.get(value)
        if code is None:
            code = self.code_value(value, "G", column)
        if code == G_2_2:
            # LinuxCNC's own sample G5_Curva_Stella_v1_G5.ngc opens its NURBS block with
            # "G2.2" and closes it with G5.3; we read it as G5.2 and say so.
            self.note_once("g2.2", "G2.2 is not an RS274/NGC code; read as G5.2 (closed by G5.3)")
            code = G_5_2
        group = G_GROUP.get(code)
        if group is None:
            if code in G_REFUSED:
                raise self.error(f"{G_REFUSED[code]} is not supported", column, UnsupportedError)
            raise self.error(f"unknown G code G{fmt_code(code)}", column)
        if group in gcodes:
            other = gcodes[group][0]
            if group == GM_MOTION and G_80 in (code, other):
                # LinuxCNC accepts G80 beside another motion code ("G80 G0" in CAM headers
                # and its own tests): the other code is the block's motion.
                if code != G_80:
                    gcodes[group] = (code, column)
                return
            raise self.error(
                f"G{fmt_code(other)} and G{fmt_code(code)} are in the same modal "
                f"group ({group}) and cannot share a block",
                column,
            )
        gcodes[group] = (code, column)

    def read_m(self, value: float, column: int, mcodes: dict) -> None:
        code = self.code_value(value, "M", column)
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

    def code_value(self, value: float, letter: str, column: int) -> int:
        """A G or M word's value × 10 as an integer (G59.3: 593)."""
        if not 0.0 <= value < 1e6:  # value * 10 must stay a modest integer
            raise self.error(f"{letter}{value:g} is not a valid {letter} code", column)
        code = round(value * 10.0)
        if abs(value * 10.0 - code) > 1e-6:
            raise self.error(f"{letter}{value:g} is not a valid {letter} code", column)
        return int(code)

    # -- execution in RS274/NGC order ---------------------------------------------------------
    def execute(self, words: dict, gcodes: dict, mcodes: dict) -> None:
        """One block, in LinuxCNC's order (interp_execute.cc, execute_block): the steps of
        :data:`BEFORE_MOTION` the block calls for, the group-0 codes, the motion, the check
        that every word was used, then the program stops."""
        used: set = set()
        if (
            not mcodes
            and len(gcodes) <= (GM_MOTION in gcodes)
            and _PLAIN_WORDS.issuperset(words)
            and self.plain_move(words, gcodes, mcodes, used)
        ):
            return
        for step in STEPS.select(words, gcodes, mcodes):
            step(self, words, gcodes, mcodes, used)
        moved_by_nonmodal = GM_NONMODAL in gcodes and self.nonmodal(gcodes, words, used)
        self.motion_block(gcodes, words, used, moved_by_nonmodal)
        for letter, (_, col) in words.items():
            if letter not in used:
                raise self.error(unused_word_message(letter), col)
        if mcodes:
            if MM_TOOL_CHANGE in mcodes and self.comp_exit is not None:
                self.refresh_position()
            if MM_STOP in mcodes:
                self.program_stop(words, mcodes[MM_STOP])

    def plain_move(self, words: dict, gcodes: dict, mcodes: dict, used: set) -> bool:
        """The fast path: most CAM lines are "G1 X.. Y.. F.." (the same effect as the full
        order). ``execute`` asks only for blocks of X, Y, Z and F words with no code but a
        motion code; True when the block was such a line (G0 or G1 outside a NURBS block) and
        is done."""
        motion_code = gcodes.get(GM_MOTION)
        motion = self.m.motion if motion_code is None else motion_code[0]
        if (motion == G_0 or motion == G_1) and self.nurbs is None:
            if "F" in words:
                self.set_feed(words, gcodes, mcodes, used)
            self.m.motion = motion
            if "X" in words or "Y" in words or "Z" in words:
                self.straight(words, False)
            return True
        return False

    def orient_words(self, words: dict, gcodes: dict, mcodes: dict, used: set) -> None:
        if mcodes.get(MM_SPINDLE, (0,))[0] == M_19:
            used.update("RQP")  # M19 R<angle> Q<timeout> P<direction>: spindle orientation

    def check_cycle_axes(self, words: dict, gcodes: dict, mcodes: dict, used: set) -> None:
        """A canned cycle moves no rotary axis (LinuxCNC: "Cannot put an a in canned
        cycle")."""
        motion = gcodes[GM_MOTION][0] if GM_MOTION in gcodes else self.m.motion
        if motion in CANNED_CYCLES:
            for letter in "ABC":
                if letter in words:
                    article = "an" if letter == "A" else "a"
                    raise self.error(
                        f"Cannot put {article} {letter.lower()} in canned cycle", words[letter][1]
                    )

    def call_words(self, words: dict, gcodes: dict, mcodes: dict, used: set) -> None:
        if mcodes.get(MM_STOP, (0,))[0] == M_98:
            used.update("PL")  # M98 P<O number> L<repeats>: the call, after the block's moves

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

    # -- program stops ------------------------------------------------------------------------
    def program_stop(self, words: dict, stop) -> None:
        """The block's group-4 M code, the last step: M98 calls, M99 returns, the rest
        stop (:meth:`stop`)."""
        code, col = stop
        if code == M_98:
            self.m98(words, col)
        elif code == M_99:
            self.m99(col)
        else:
            self.stop(code, col)

    def stop(self, code: int, column: int) -> None:
        """M0 / M1 / M60: a Pause segment; M2 / M30: the end (nothing after is read)."""
        if code in (M_2, M_30):
            if self.nurbs is not None:
                self.finish_nurbs_by_other(None, column)
            self.ended = True
            return
        self.pause_at_rest(f"M{code}", column)

    def pause_at_rest(self, code: str, column: int, tool: int | None = None, argv=()) -> None:
        """A :class:`Pause` named ``code`` where the tool stands now (an open NURBS block
        ends first)."""
        if self.nurbs is not None:
            self.finish_nurbs_by_other(None, column)
        # After G40 the tool stands at the compensated point until the exit move.
        position = tuple(self.pos) if self.comp_exit is None else self.comp_exit
        self.segments.append(Pause(position, self.main_line(), code, tool=tool, argv=argv))

    def user_m_code(self, words: dict, gcodes: dict, mcodes: dict, used: set) -> None:
        """M100–M199 P Q: LinuxCNC runs the executable ``M1nn`` found in its user-M path at
        rest, with P and Q as ``"%f"`` arguments (-1 when absent: its block's unset
        p_number, q_number; emctask.cc, user_defined_add_m_code). A code with no executable
        is LinuxCNC's "Unknown M code used"."""
        code, col = mcodes[MM_USER]
        find = self.options.find_user_m
        path = find(code) if find is not None else None
        if path is None:
            raise self.error(
                f"M{code}: no executable named M{code} in the user M-code path "
                "(--user-m-path, the profile's program.user_m_path)",
                col,
            )
        used.update("PQ")
        p = words["P"][0] if "P" in words else -1.0
        q = words["Q"][0] if "Q" in words else -1.0
        self.pause_at_rest(f"M{code}", col, argv=(path, f"{p:f}", f"{q:f}"))


class Step(NamedTuple):
    """One step of the order of execution, ``run(interpreter, words, gcodes, mcodes,
    used)``, and what in a block calls for it: the modal groups of its G codes
    (``g_groups``), of its M codes (``m_groups``) and its word letters (``letters``). A block
    with none of them leaves the step nothing to do: it is not run."""

    run: Callable
    g_groups: tuple = ()
    m_groups: tuple = ()
    letters: str = ""


class StepTable:
    """The steps a block calls for, in their order: each G group, M group and word letter
    maps to a bit mask of the steps it triggers (bit i: step i); the union of a block's
    masks selects its steps, the tuple of each union made once."""

    #: Unions remembered at most (a program has a handful; the bound keeps a generated one's
    #: combinations from growing the memo without end).
    MAX_MEMO = 4096

    def __init__(self, steps: tuple):
        self.steps = steps
        self.g_mask: dict = {}
        self.m_mask: dict = {}
        self.letter_mask: dict = {}
        for i, step in enumerate(steps):
            for table, keys in (
                (self.g_mask, step.g_groups),
                (self.m_mask, step.m_groups),
                (self.letter_mask, step.letters),
            ):
                for key in keys:
                    table[key] = table.get(key, 0) | 1 << i
        self.memo: dict = {0: ()}

    def select(self, words: dict, gcodes: dict, mcodes: dict) -> tuple:
        """The ``run`` of each step the block calls for, in the order of :attr:`steps`."""
        mask = 0
        g_mask, letter_mask = self.g_mask, self.letter_mask
        for group in gcodes:
            mask |= g_mask.get(group, 0)
        if mcodes:
            m_mask = self.m_mask
            for group in mcodes:
                mask |= m_mask.get(group, 0)
        for letter in words:
            mask |= letter_mask.get(letter, 0)
        runs = self.memo.get(mask)
        if runs is None:
            runs = tuple(step.run for i, step in enumerate(self.steps) if mask >> i & 1)
            if len(self.memo) < self.MAX_MEMO:
                self.memo[mask] = runs
        return runs


#: Steps 2–20 of LinuxCNC's order of execution, before the group-0 codes and the motion,
#: each with the codes and words that call for it.
BEFORE_MOTION = (
    Step(ModeSetters.set_feed_mode, g_groups=(GM_FEED_MODE,)),  # G93, G94, G95
    Step(ModeSetters.set_feed, letters="F"),
    # G20, G21 (before S, T: neither depends on the units)
    Step(ModeSetters.set_units, g_groups=(GM_UNITS,)),
    Step(ModeSetters.set_spindle, letters="S"),
    Step(ModeSetters.select_tool, letters="T"),
    Step(ModeSetters.io_codes, m_groups=(MM_IO, MM_OVERRIDE)),  # M62–M68, M50–M53
    Step(ModeSetters.change_tool, m_groups=(MM_TOOL_CHANGE,)),  # M6, M61
    Step(ModeSetters.spindle_on_off, m_groups=(MM_SPINDLE,)),  # M3, M4, M5, M19
    Step(ModeSetters.save_restore_modes, m_groups=(MM_MODAL_STATE,)),  # M70–M73
    Step(BlockExecutor.user_m_code, m_groups=(MM_USER,)),  # M100–M199
    Step(BlockExecutor.orient_words, m_groups=(MM_SPINDLE,)),  # M19's words
    Step(ModeSetters.dwell, g_groups=(GM_NONMODAL,)),  # G4
    Step(ModeSetters.set_plane, g_groups=(GM_PLANE,)),  # G17, G18, G19
    Step(ModeSetters.set_cutter_comp, g_groups=(GM_CUTTER_COMP,), letters="D"),  # G40–G42
    Step(ModeSetters.set_tool_offset, g_groups=(GM_TOOL_LENGTH,), letters="H"),  # G43, G49
    Step(ModeSetters.set_coord_system, g_groups=(GM_COORD_SYSTEM,)),  # G54–G59.3
    Step(ModeSetters.set_path_mode, g_groups=(GM_CONTROL_MODE,)),  # G61, G61.1, G64
    # G90, G91, G90.1, G91.1
    Step(ModeSetters.set_distance_modes, g_groups=(GM_DISTANCE, GM_IJK_DISTANCE)),
    Step(ModeSetters.set_retract_mode, g_groups=(GM_RETURN_MODE,)),  # G98, G99
    Step(BlockExecutor.check_cycle_axes, letters="ABC"),  # A B C with a canned cycle
    Step(RotaryAxes.rotary_words, letters="ABC"),  # A, B, C
    Step(BlockExecutor.call_words, m_groups=(MM_STOP,)),  # M98's words
)

#: :data:`BEFORE_MOTION` indexed by what calls for each step.
STEPS = StepTable(BEFORE_MOTION)
