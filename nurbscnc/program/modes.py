"""The modal setters: one step of LinuxCNC's order of execution each (interp_execute.cc,
execute_block), from the feed mode to the retract mode, as a mixin of the interpreter.

Every step has the signature ``step(words, gcodes, mcodes, used)``: the block's words
(``{letter: (value, column)}``), its G and M codes by modal group (``{group: (code,
column)}``, G codes × 10) and the set of letters used so far, which the step adds to.
"""

from __future__ import annotations

from dataclasses import replace

from nurbscnc.errors import UnsupportedError
from nurbscnc.geometry.segments import Dwell, path_control
from nurbscnc.program.codes import (
    G_4,
    G_20,
    G_40,
    G_41,
    G_41_1,
    G_42_1,
    G_43,
    G_43_1,
    G_64,
    G_90,
    G_90_1,
    G_96,
    GM_CONTROL_MODE,
    GM_COORD_SYSTEM,
    GM_CUTTER_COMP,
    GM_DISTANCE,
    GM_FEED_MODE,
    GM_IJK_DISTANCE,
    GM_NONMODAL,
    GM_PLANE,
    GM_RETURN_MODE,
    GM_SPINDLE_MODE,
    GM_TOOL_LENGTH,
    GM_UNITS,
    M_3,
    M_4,
    M_6,
    M_50,
    M_51,
    M_52,
    M_53,
    M_62,
    M_63,
    M_64,
    M_65,
    M_66,
    M_67,
    M_68,
    M_70,
    M_71,
    M_73,
    MM_IO,
    MM_MODAL_STATE,
    MM_OVERRIDE,
    MM_SPINDLE,
    MM_TOOL_CHANGE,
    fmt_code,
)
from nurbscnc.program.compensation import CompMove, CutterComp
from nurbscnc.program.modal import INCH_MM, PLANE_OF_G, SAVED_BY_M70, SYSTEM_OF_G
from nurbscnc.program.words import AXES, MAX_DWELL_S, MAX_FEED_MM_MIN, MIN_FEED_MM_MIN

#: The words of the HAL I/O codes besides P (LinuxCNC's convert_m).
_IO_WORDS = {M_66: "PELQ", M_67: "EQ", M_68: "EQ"}
#: The I/O codes that wait for the motion before them to end (a dwell of 0 s there).
_IO_WAITS = (M_64, M_65, M_66, M_68)
_OVERRIDES = (M_50, M_51, M_52, M_53)  # their P switches the override


class ModeSetters:
    """Steps 2–20 of LinuxCNC's order of execution (mixin of the interpreter: it provides
    ``m``, ``coords``, ``tools``, ``pos``, ``comp``, ``comp_exit``, ``error`` …)."""

    def not_in_comp(self, message: str, column: int) -> None:
        """LinuxCNC's refusals of offset and mode changes while cutter compensation is on
        (interp_convert.cc), with its messages: the compensated path would change frame."""
        if self.m.comp_mode != G_40:
            raise self.error(message, column)

    # -- feed, units, spindle speed, tool selection -------------------------------------------
    def set_feed_mode(self, words: dict, gcodes: dict, mcodes: dict, used: set) -> None:
        if GM_FEED_MODE in gcodes:
            # LinuxCNC (convert_feed_mode): every G93, G94, G95 word clears F, even for the
            # mode in force; an F in the same block sets it again (it comes after).
            self.m.feed = self.m.feed_mm = 0.0
            self.m.feed_mode = gcodes[GM_FEED_MODE][0]

    def set_units(self, words: dict, gcodes: dict, mcodes: dict, used: set) -> None:
        # RS274/NGC sets F (step 3) before units (step 12) and LinuxCNC's canon keeps the
        # feed as a length per minute in the units of the moment it was set: "G20 F60" in a
        # block that starts in mm is 60 mm/min (its goldens: ccomp/mill-zchanges, comp311).
        if GM_UNITS in gcodes:
            scale = INCH_MM if gcodes[GM_UNITS][0] == G_20 else 1.0
            if scale != self.m.scale:
                # LinuxCNC (convert_length_units) converts positions and offsets but not what
                # a cycle remembers (cycle_r, cycle_cc, cycle_il, Q, I, J, K): their numbers are
                # read in the new units (R2 in mm, then G20: R2 inches).
                c, ratio = self.m.cycle, scale / self.m.scale
                self.m.cycle = replace(
                    c,
                    **{
                        f: None if getattr(c, f) is None else getattr(c, f) * ratio
                        for f in (
                            "initial_level_mm",
                            "r_mm",
                            "z_mm",
                            "q_mm",
                            "i_mm",
                            "j_mm",
                            "k_mm",
                        )
                    },
                )
            self.m.scale = scale

    def set_feed(self, words: dict, gcodes: dict, mcodes: dict, used: set) -> None:
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

    def set_spindle(self, words: dict, gcodes: dict, mcodes: dict, used: set) -> None:
        if "S" in words:
            used.add("S")
            s, col = words["S"]
            if s < 0:
                raise self.error("negative spindle speed", col)
            self.m.spindle_rpm = s

    def select_tool(self, words: dict, gcodes: dict, mcodes: dict, used: set) -> None:
        if "T" in words:
            used.add("T")
            t, col = words["T"]
            if t < 0 or t != int(t) or t >= 2**31:
                raise self.error(f"tool number T{t:g} must be a non-negative integer", col)
            self.m.tool_selected = int(t)

    # -- M codes before the motion ------------------------------------------------------------
    def io_codes(self, words: dict, gcodes: dict, mcodes: dict, used: set) -> None:
        """M62–M68 (LinuxCNC's HAL I/O: digital and analog outputs, a wait on an input) and
        M50–M53 (override switches), step 6 and 11 of LinuxCNC's order: no motion of their
        own. M64, M65 (a digital output now), M66 (wait on an input) and M68 (an analog
        output now) run once the motion before them has ended (LinuxCNC's task waits for it,
        emcTaskCheckPreconditions), so the tool stops there: a dwell of 0 s; M62, M63 and
        M67 go with the motion. The words as LinuxCNC checks them (convert_m)."""
        if MM_IO in mcodes:
            code, col = mcodes[MM_IO]
            if code in (M_62, M_63, M_64, M_65) and "P" not in words:
                raise self.error(f"No valid P word with M{code}", col)
            if code == M_66 and "P" not in words and "E" not in words:
                raise self.error("Need to have either a valid P or a valid E word with M66", col)
            if code in (M_67, M_68) and "E" not in words:
                raise self.error(f"Invalid analog index with M{code}", col)
            used.update(_IO_WORDS.get(code, "P"))
            if code in _IO_WAITS:
                self.dwell_here(0.0, f"M{code}")
        if mcodes.get(MM_OVERRIDE, (0,))[0] in _OVERRIDES:
            used.add("P")  # P0 switches the override off, P1 (or none) on

    def change_tool(self, words: dict, gcodes: dict, mcodes: dict, used: set) -> None:
        """M6 (the selected tool into the spindle) or M61 Q (the spindle holds tool Q)."""
        if MM_TOOL_CHANGE in mcodes:
            code, col = mcodes[MM_TOOL_CHANGE]
            if self.m.comp_mode != G_40:
                raise self.error("Cannot change tools with cutter radius compensation on", col)
            if code == M_6:
                self.m.tool_loaded = self.m.tool_selected
                # LinuxCNC's convert_tool_change stops the spindle (unless the INI's
                # TOOL_CHANGE_WITH_SPINDLE_ON): a G86 after it refuses a stopped spindle.
                self.m.spindle = "off"
                # It issues CHANGE_TOOL after the motion before it: the machine stops
                # there for the operator (or the changer), whatever the tool.
                self.pause_at_rest("M6", col, tool=self.m.tool_selected)
            else:  # M61 Q<tool>: the tool in the spindle is Q (no change is made)
                self.m.tool_loaded = self.m61_tool(words, col, used)

    def m61_tool(self, words: dict, column: int, used: set) -> int:
        if "Q" not in words:
            raise self.error("M61 needs a Q word (the tool number)", column)
        q, qcol = words["Q"]
        used.add("Q")
        if q != int(q) or q < 0 or q >= 2**31:
            raise self.error(f"M61 Q{q:g}: Q must be a tool number", qcol)
        return int(q)

    def spindle_on_off(self, words: dict, gcodes: dict, mcodes: dict, used: set) -> None:
        """M3, M4, M5, M19: after the tool change, as LinuxCNC's order of execution."""
        if MM_SPINDLE in mcodes:
            self.m.spindle = {M_3: "cw", M_4: "ccw"}.get(mcodes[MM_SPINDLE][0], "off")

    def save_restore_modes(self, words: dict, gcodes: dict, mcodes: dict, used: set) -> None:
        if MM_MODAL_STATE in mcodes:
            self.modal_save_restore(*mcodes[MM_MODAL_STATE])

    def modal_save_restore(self, code: int, column: int) -> None:
        """M70 save, M71 forget, M72 restore the modal state; M73 save it for an automatic
        restore when the current subroutine returns (LinuxCNC)."""
        frame = self.frames[-1]
        if code in (M_70, M_73):
            state = ({name: getattr(self.m, name) for name in SAVED_BY_M70}, self.coords.system)
            if code == M_70:
                self.m70_state = state
            else:
                if len(self.frames) == 1:
                    raise self.error("M73 outside a subroutine (nothing to restore it)", column)
                frame.m73_state = state
        elif code == M_71:
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

    # -- dwell ------------------------------------------------------------------------------
    def dwell_here(self, seconds: float, code: str = "G4") -> None:
        """A dwell of ``seconds`` at the current point (the tool at rest there), made by
        ``code``."""
        position = tuple(self.pos) if self.comp_exit is None else self.comp_exit
        dwell = Dwell(float(seconds), position, self.main_line(), code)
        if self.comp is None:
            self.segments.append(dwell)
        else:
            self.comp_moves(
                CompMove("dwell", self.to_comp(position), line=dwell.line, seconds=dwell.seconds)
            )

    def dwell(self, words: dict, gcodes: dict, mcodes: dict, used: set) -> None:
        nonmodal = gcodes.get(GM_NONMODAL)
        if nonmodal is None or nonmodal[0] != G_4:
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

    # -- plane, cutter compensation, tool length offset ---------------------------------------
    def set_plane(self, words: dict, gcodes: dict, mcodes: dict, used: set) -> None:
        if GM_PLANE in gcodes:
            code, col = gcodes[GM_PLANE]
            plane = PLANE_OF_G[code]
            if self.m.comp_mode != G_40 and plane != self.m.plane:
                raise self.error("Cannot change planes with cutter radius compensation on", col)
            self.m.plane = plane

    def set_cutter_comp(self, words: dict, gcodes: dict, mcodes: dict, used: set) -> None:
        """G40 / G41 / G42 / G41.1 / G42.1 with D: tracked in ``self.m.comp_*``."""
        m = self.m
        if GM_CUTTER_COMP in gcodes:
            code, col = gcodes[GM_CUTTER_COMP]
            if code != G_40 and m.comp_mode != G_40:
                raise self.error("cannot turn cutter compensation on when it is already on", col)
            if code == G_40:
                m.comp_mode, m.comp_side, m.comp_radius_mm, m.comp_d = G_40, None, 0.0, None
                self.comp_off()
            else:
                self.comp_on(code, col, words.get("D"))
        if "D" in words and gcodes.get(GM_SPINDLE_MODE, (0,))[0] == G_96:
            used.add("D")  # G96 D: the spindle speed limit of constant surface speed
        elif "D" in words:
            if GM_CUTTER_COMP not in gcodes or gcodes[GM_CUTTER_COMP][0] == G_40:
                raise self.error("D word with no G41/G42 to use it", words["D"][1])
            used.add("D")

    def comp_on(self, code: int, col: int, d) -> None:
        """G41 / G42 / G41.1 / G42.1 (``d`` the D word, or None): the compensation stream
        starts at the tool's position."""
        m = self.m
        if m.plane == "YZ":
            raise self.error("Cutter radius compensation allowed only in XY, XZ planes", col)
        if m.plane == "ZX" and self.coords.rotation_deg:
            raise self.error(
                "cutter radius compensation in the XZ plane (G18) with a "
                "rotated coordinate system (G10 L2 R) is not supported",
                col,
                UnsupportedError,
            )
        self.comp_plane = m.plane
        m.comp_mode = code
        m.comp_side = "left" if code in (G_41, G_41_1) else "right"
        m.comp_radius_mm = self.comp_radius_mm(code, col, d)
        m.comp_d = d[0] if d is not None else None
        start = tuple(self.pos) if self.comp_exit is None else self.comp_exit
        self.comp = CutterComp(m.comp_side, m.comp_radius_mm, self.to_comp(start), inch=m.inch)
        self.comp_exit = None

    def comp_radius_mm(self, code: int, col: int, d) -> float:
        """The compensation radius [mm]: D / 2 for G41.1 / G42.1 (signed: a negative D swaps
        the side, LinuxCNC; CutterComp does it); else the radius of tool D in the table, or
        of the loaded tool with no D or D0 (LinuxCNC's find_tool_index(0): the spindle's
        pocket)."""
        m = self.m
        if code in (G_41_1, G_42_1):
            if d is None:
                raise self.error(f"G{fmt_code(code)} needs a D word (diameter)", col)
            return d[0] * m.scale / 2.0
        number = int(d[0]) if d is not None and d[0] != 0 else m.tool_loaded
        if d is not None and (d[0] != int(d[0]) or d[0] < 0):
            raise self.error(f"D{d[0]:g} must be a tool number", d[1])
        tool = self.tools.get(number)
        return tool.diameter_mm / 2.0 if tool is not None else 0.0

    def set_tool_offset(self, words: dict, gcodes: dict, mcodes: dict, used: set) -> None:
        """G43 [H] (tool table), G43.1 (offsets given in the block), G49."""
        if GM_TOOL_LENGTH not in gcodes:
            if "H" in words:
                raise self.error("H word with no G43 to use it", words["H"][1])
            return
        code, col = gcodes[GM_TOOL_LENGTH]
        self.not_in_comp("Cannot change tool offset with cutter radius compensation on", col)
        machine = self.pos
        if code == G_43:
            offset = self.table_tool_offset(words, used)
        elif code == G_43_1:
            self.refuse_rotary_tool_offset(words)
            offset = [0.0, 0.0, 0.0]
            for i, letter in enumerate(AXES):
                if letter in words:
                    offset[i] = words[letter][0] * self.m.scale
                    used.add(letter)
        else:
            offset = [0.0, 0.0, 0.0]
        self.coords.set_tool(offset)
        self.m.tool_offset_code = code
        self.pos = machine  # the machine stays; the program position changes
        if code == G_43_1:
            self.axes_consumed = True  # its axis words were the offsets, not a move

    def table_tool_offset(self, words: dict, used: set) -> list:
        """G43 [H]: the tool table's offset [mm] of tool H (the loaded tool without H)."""
        used.add("H")
        tool = words["H"][0] if "H" in words else float(self.m.tool_loaded)
        if tool != int(tool) or tool < 0:
            raise self.error(f"H{tool:g} must be a tool number", words["H"][1])
        entry = self.tools.get(int(tool))
        if entry is not None:
            return list(entry.offset_mm)
        if int(tool) != 0:
            self.note_once(
                ("tlo", int(tool)),
                f"G43 H{int(tool)}: no tool table entry, tool length offset taken as 0",
            )
        return [0.0, 0.0, 0.0]

    # -- coordinate system, path control, distance and retract modes --------------------------
    def set_coord_system(self, words: dict, gcodes: dict, mcodes: dict, used: set) -> None:
        if GM_COORD_SYSTEM in gcodes:
            code, col = gcodes[GM_COORD_SYSTEM]
            self.not_in_comp(
                "Cannot change coordinate systems with cutter radius compensation on", col
            )
            self.select_system(SYSTEM_OF_G[code])

    def select_system(self, system: int) -> None:
        machine = self.pos
        self.coords.select(system)
        self.pos = machine

    def set_path_mode(self, words: dict, gcodes: dict, mcodes: dict, used: set) -> None:
        """G61 (exact path), G61.1 (exact stop), G64 [P-] [Q-] (blending), as LinuxCNC 2.9:
        G64 without P blends within the machine's path tolerance; Q (naive CAM tolerance)
        defaults to P, and G64 alone turns the naive CAM detector off."""
        if GM_CONTROL_MODE not in gcodes:
            return
        code, col = gcodes[GM_CONTROL_MODE]
        self.not_in_comp("Cannot change control mode with cutter radius compensation on", col)
        p_mm = q_mm = None
        if code == G_64:
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

    def set_distance_modes(self, words: dict, gcodes: dict, mcodes: dict, used: set) -> None:
        """G90 / G91 (axis words) and G90.1 / G91.1 (arc centres)."""
        if GM_DISTANCE in gcodes:
            self.m.absolute = gcodes[GM_DISTANCE][0] == G_90
        if GM_IJK_DISTANCE in gcodes:
            self.m.arc_absolute = gcodes[GM_IJK_DISTANCE][0] == G_90_1

    def set_retract_mode(self, words: dict, gcodes: dict, mcodes: dict, used: set) -> None:
        if GM_RETURN_MODE in gcodes:
            self.m.retract_mode = gcodes[GM_RETURN_MODE][0]
