"""Coordinate systems as LinuxCNC keeps them (interp_setup.cc, interp_convert.cc, G10/G92).

A point's machine position [mm] is (LinuxCNC's emccanon ``rotate_and_offset_pos``)::

    machine = R(rotation) · (program + g92) + origin + tool_offset

with ``origin`` and ``rotation`` the active G54…G59.3 system's offset and XY rotation [deg]
(G10 L2 R), ``g92`` the G92 offset and ``tool_offset`` the G43 tool length offset. The
interpreter keeps the PROGRAM position (as LinuxCNC's ``current_x``) and converts with
:meth:`Coordinates.to_machine` / :meth:`Coordinates.to_program`.

The numbered parameters that hold these values are in MACHINE units (LinuxCNC keeps them so:
checked with its interpreter on an inch and a mm machine); nurbscnc's machine unit is the mm,
so a program reads and writes them in mm whatever G20/G21 is in force:

- #5161–#5166 G28 home, #5181–#5186 G30 home (machine coordinates, X Y Z A B C);
- #5210 G92 on (1) or off (0), #5211–#5219 the G92 offset (X Y Z A B C U V W);
- #5220 the active system (1 = G54 … 9 = G59.3);
- #5221 + 20·(n−1) + k: system n's offset on axis k (0..8: X Y Z A B C U V W), +9 its
  rotation R [deg] (no units).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from nurbscnc.errors import UnsupportedError
from nurbscnc.program.codes import (
    G_10,
    G_28,
    G_28_1,
    G_30,
    G_30_1,
    G_40,
    G_52,
    G_92,
    G_92_1,
    G_92_2,
    G_92_3,
    GM_NONMODAL,
)
from nurbscnc.program.tooltable import Tool

_AXES = ("X", "Y", "Z")

G28_BASE = 5161
G30_BASE = 5181
G92_FLAG = 5210
G92_BASE = 5211
SYSTEM_INDEX = 5220
SYSTEM_BASE = 5221
SYSTEM_STRIDE = 20
N_SYSTEMS = 9
#: Names of the coordinate systems, 1-based.
SYSTEM_NAMES = ("", "G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3")


def is_coordinate_parameter(index: int) -> bool:
    """True for the parameters this module owns (they carry lengths that follow the units)."""
    return (
        G28_BASE <= index <= G28_BASE + 5
        or G30_BASE <= index <= G30_BASE + 5
        or G92_FLAG <= index <= SYSTEM_BASE + SYSTEM_STRIDE * N_SYSTEMS - 1
    )


@dataclass
class Coordinates:
    """Offsets and stored positions [mm], the parameter table behind them, the active system.

    ``params`` holds #5161…#5400 in mm (lengths) or as plain numbers (flags, angles);
    ``origin_mm`` / ``rotation_deg`` are the ACTIVE system's values, loaded when a system is
    selected or the active one is changed by G10 (a plain parameter write does not move the
    active origin, as in LinuxCNC).
    """

    params: dict = field(default_factory=dict)
    system: int = 1
    origin_mm: list = field(default_factory=lambda: [0.0, 0.0, 0.0])
    rotation_deg: float = 0.0
    g92_mm: list = field(default_factory=lambda: [0.0, 0.0, 0.0])
    tool_mm: list = field(default_factory=lambda: [0.0, 0.0, 0.0])
    #: The rotary axes' offsets [deg]: the active system's A B C (#5224–#5226 for G54) and
    #: G92's (#5214–#5216). No rotation, no tool offset and no unit scaling act on them:
    #: machine A = program A + G92 A + origin A (LinuxCNC, degrees whatever G20/G21).
    origin_abc_deg: list = field(default_factory=lambda: [0.0, 0.0, 0.0])
    g92_abc_deg: list = field(default_factory=lambda: [0.0, 0.0, 0.0])

    #: The interpreter's segment list: :attr:`frames` says from which segment on each
    #: set of offsets was in force.
    segments: list = field(default_factory=list)

    def __post_init__(self):
        self.params.setdefault(SYSTEM_INDEX, 1.0)
        self.plain = True  # no offset, rotation or tool offset: machine = program
        self.frames: list = []
        self._update_plain()

    def _update_plain(self) -> None:
        self.plain = not (
            any(self.origin_mm) or any(self.g92_mm) or any(self.tool_mm) or self.rotation_deg
        )
        # (first segment, system name, origin, G92, tool [mm], rotation [deg]) for the
        # errors that name the offsets (soft limits): one row per change
        frame = (
            len(self.segments),
            SYSTEM_NAMES[self.system],
            tuple(self.origin_mm),
            tuple(self.g92_mm),
            tuple(self.tool_mm),
            self.rotation_deg,
        )
        if self.frames and self.frames[-1][0] == frame[0]:
            self.frames[-1] = frame
        elif not self.frames or self.frames[-1][1:] != frame[1:]:
            self.frames.append(frame)

    def set_tool(self, offset_mm) -> None:
        """G43 / G43.1 / G49: the tool offset [mm] along X, Y, Z."""
        self.tool_mm = list(offset_mm)
        self._update_plain()

    # -- parameters (machine units: mm) ---------------------------------------------------
    def read(self, index: int) -> float:
        return self.params.get(index, 0.0)

    def write(self, index: int, value: float) -> None:
        self.params[index] = value

    def system_offset_mm(self, system: int) -> list:
        base = SYSTEM_BASE + SYSTEM_STRIDE * (system - 1)
        return [self.params.get(base + k, 0.0) for k in range(3)]

    def system_rotation_deg(self, system: int) -> float:
        return self.params.get(SYSTEM_BASE + SYSTEM_STRIDE * (system - 1) + 9, 0.0)

    def restore(self, values: dict) -> None:
        """The persistent parameters of a parameter file (``{number: value}``, lengths in
        mm) in force before the program, as LinuxCNC's ``Interp::init`` applies them: the
        system #5220 (1..9) active with its offsets and rotation, the G92 offsets
        #5211–#5213 in force when #5210 is not 0."""
        for index, value in values.items():
            if is_coordinate_parameter(index):
                self.params[index] = float(value)
        system = int(self.params.get(SYSTEM_INDEX, 1.0) + 0.0001)
        self._load(system if 1 <= system <= N_SYSTEMS else 1)
        if self.params.get(G92_FLAG, 0.0):
            self.g92_mm = [self.params.get(G92_BASE + k, 0.0) for k in range(3)]
            self.g92_abc_deg = [self.params.get(G92_BASE + k, 0.0) for k in range(3, 6)]
        self._update_plain()

    # -- transforms --------------------------------------------------------------------------
    def to_machine(self, prog) -> list:
        """Machine position [mm] of a program position [mm] (see the module docstring)."""
        if self.plain:
            return list(prog)
        x = prog[0] + self.g92_mm[0]
        y = prog[1] + self.g92_mm[1]
        z = prog[2] + self.g92_mm[2]
        if self.rotation_deg:
            c, s = _cos_sin(self.rotation_deg)
            x, y = c * x - s * y, s * x + c * y
        return [
            x + self.origin_mm[0] + self.tool_mm[0],
            y + self.origin_mm[1] + self.tool_mm[1],
            z + self.origin_mm[2] + self.tool_mm[2],
        ]

    def to_machine_array(self, prog_mm: np.ndarray) -> np.ndarray:
        """:meth:`to_machine` of each row of ``prog_mm`` (n, 3) [mm]: the same operations in
        the same order, elementwise, so each row is the same to the bit."""
        if self.plain:
            return prog_mm
        x = prog_mm[:, 0] + self.g92_mm[0]
        y = prog_mm[:, 1] + self.g92_mm[1]
        z = prog_mm[:, 2] + self.g92_mm[2]
        if self.rotation_deg:
            c, s = _cos_sin(self.rotation_deg)
            x, y = c * x - s * y, s * x + c * y
        return np.column_stack(
            [
                x + self.origin_mm[0] + self.tool_mm[0],
                y + self.origin_mm[1] + self.tool_mm[1],
                z + self.origin_mm[2] + self.tool_mm[2],
            ]
        )

    def to_program(self, machine) -> list:
        """Inverse of :meth:`to_machine`."""
        if self.plain:
            return list(machine)
        x = machine[0] - self.tool_mm[0] - self.origin_mm[0]
        y = machine[1] - self.tool_mm[1] - self.origin_mm[1]
        z = machine[2] - self.tool_mm[2] - self.origin_mm[2]
        if self.rotation_deg:
            c, s = _cos_sin(self.rotation_deg)
            x, y = c * x + s * y, -s * x + c * y
        return [x - self.g92_mm[0], y - self.g92_mm[1], z - self.g92_mm[2]]

    def abc_shift_deg(self) -> tuple:
        """Machine A B C minus program A B C [deg]: the G92 and the active system's offsets."""
        o, g = self.origin_abc_deg, self.g92_abc_deg
        return (o[0] + g[0], o[1] + g[1], o[2] + g[2])

    def rotate_vector(self, v) -> list:
        """A direction (an arc normal) from program to machine axes."""
        if not self.rotation_deg:
            return list(v)
        c, s = _cos_sin(self.rotation_deg)
        return [c * v[0] - s * v[1], s * v[0] + c * v[1], v[2]]

    # -- changes ---------------------------------------------------------------------------
    def select(self, system: int) -> None:
        """G54…G59.3: make ``system`` (1..9) active. Selecting the active system again
        changes nothing (LinuxCNC: "continuing to use same coordinate system"), so a
        parameter written since is not picked up."""
        if system == self.system:
            return
        self._load(system)

    def _load(self, system: int) -> None:
        self.system = system
        self.params[SYSTEM_INDEX] = float(system)
        self.origin_mm = self.system_offset_mm(system)
        base = SYSTEM_BASE + SYSTEM_STRIDE * (system - 1)
        self.origin_abc_deg = [self.params.get(base + k, 0.0) for k in range(3, 6)]
        self.rotation_deg = self.system_rotation_deg(system)
        self._update_plain()

    def set_system(self, system: int, offsets: dict, rotation_deg: float | None) -> None:
        """G10 L2 / L20: set axes (0..2 → mm, 3..5 → A B C [deg]) and the rotation of
        ``system`` (1..9)."""
        base = SYSTEM_BASE + SYSTEM_STRIDE * (system - 1)
        for axis, value in offsets.items():
            self.params[base + axis] = value
        if rotation_deg is not None:
            self.params[base + 9] = rotation_deg
        if system == self.system:
            self._load(system)

    def set_g92(self, offsets: dict) -> None:
        """G92: the offsets (axis 0..2 → mm, 3..5 → A B C [deg]) of the given axes; the
        others keep theirs."""
        for axis, value in offsets.items():
            if axis < 3:
                self.g92_mm[axis] = value
            else:
                self.g92_abc_deg[axis - 3] = value
        self._store_g92(1.0)
        self._update_plain()

    def clear_g92(self, keep_parameters: bool) -> None:
        """G92.1 (zero the parameters too) or G92.2 (keep them for G92.3)."""
        self.g92_mm = [0.0, 0.0, 0.0]
        self.g92_abc_deg = [0.0, 0.0, 0.0]
        self._update_plain()
        if keep_parameters:
            self.params[G92_FLAG] = 0.0
        else:
            for k in range(9):
                self.params[G92_BASE + k] = 0.0
            self.params[G92_FLAG] = 0.0

    def restore_g92(self) -> None:
        """G92.3: the offsets from #5211–#5213."""
        self.g92_mm = [self.params.get(G92_BASE + k, 0.0) for k in range(3)]
        self.g92_abc_deg = [self.params.get(G92_BASE + k, 0.0) for k in range(3, 6)]
        self.params[G92_FLAG] = 1.0
        self._update_plain()

    def _store_g92(self, flag: float) -> None:
        for k in range(3):
            self.params[G92_BASE + k] = self.g92_mm[k]
        if any(self.g92_abc_deg) or any(self.params.get(G92_BASE + k) for k in range(3, 6)):
            for k in range(3):
                self.params[G92_BASE + 3 + k] = self.g92_abc_deg[k]
        self.params[G92_FLAG] = flag

    def home_mm(self, which: int) -> list:
        """The stored G28 (``which`` = 28) or G30 position [mm, machine]."""
        base = G28_BASE if which == 28 else G30_BASE
        return [self.params.get(base + k, 0.0) for k in range(3)]

    def home_abc_deg(self, which: int) -> list:
        """The stored G28 (``which`` = 28) or G30 position of A B C [deg, machine]."""
        base = (G28_BASE if which == 28 else G30_BASE) + 3
        return [self.params.get(base + k, 0.0) for k in range(3)]

    def store_home(self, which: int, machine_mm, abc_deg=None) -> None:
        """G28.1 / G30.1: store the current machine position (and A B C [deg] when given)."""
        base = G28_BASE if which == 28 else G30_BASE
        for k in range(3):
            self.params[base + k] = float(machine_mm[k])
        for k, value in enumerate(abc_deg or ()):
            self.params[base + 3 + k] = float(value)


def _cos_sin(angle_deg: float) -> tuple[float, float]:
    a = math.radians(angle_deg)
    return math.cos(a), math.sin(a)


class OffsetCommands:
    """G10 L2/L20, G28/G30 (and .1), G92 family: a mixin of the interpreter (it provides
    ``error``, ``m``, ``coords``, ``prog``, ``pos``, ``target_program``, ``rapid_to_program``).
    The machine position never jumps when an offset changes: the program position follows.
    """

    def nonmodal(self, gcodes: dict, words: dict, used: set) -> bool:
        """Group-0 codes other than G4; True when they consumed the axis words."""
        if GM_NONMODAL not in gcodes:
            return False
        code, col = gcodes[GM_NONMODAL]
        if code == G_10:
            self.g10(words, used, col)
            return True
        if code in (G_28, G_30):
            self.go_home(28 if code == G_28 else 30, words, used)
            return True
        if code in (G_28_1, G_30_1):
            which = 28 if code == G_28_1 else 30
            self.coords.store_home(which, self.pos, self.home_abc_to_store(which))
            return False
        if code == G_92:
            self.g92(words, used, col)
            return True
        if code == G_52:
            self.g52(words, used, col)
            return True
        if code in (G_92_1, G_92_2, G_92_3):
            machine = self.pos
            if code == G_92_3:
                self.coords.restore_g92()
            else:
                self.coords.clear_g92(keep_parameters=code == G_92_2)
            self.pos = machine
        return False

    def g10(self, words: dict, used: set, col: int) -> None:
        if "L" not in words:
            raise self.error("G10 needs an L word (L2 or L20)", col)
        level, lcol = words["L"]
        if level in (1.0, 10.0, 11.0):
            self._g10_tool(int(level), words, used, col)
            return
        if level not in (2.0, 20.0):
            raise self.error(
                f"G10 L{level:g} is not supported (LinuxCNC's G10 forms for milling are L1, "
                "L2, L10, L11 and L20)",
                lcol,
                UnsupportedError,
            )
        if "P" not in words:
            raise self.error(f"G10 L{level:g} needs P (0 = current, 1..9 = G54..G59.3)", col)
        p, pcol = words["P"]
        if p != int(p) or not 0 <= p <= 9:
            raise self.error(f"G10 L{level:g} P{p:g}: P must be an integer 0..9", pcol)
        used.update("LP" + ("R" if "R" in words else "") + "XYZ")
        system = int(p) or self.coords.system
        if system == self.coords.system:
            self.not_in_comp(
                "Cannot change the active coordinate system with cutter radius compensation on", col
            )
        scale = self.m.scale
        given = {i: words[a][0] * scale for i, a in enumerate(_AXES) if a in words}
        rotation = words["R"][0] if "R" in words else None
        machine = self.pos
        turned = self.abc_offsets(words, wrapped_check=level == 20.0)
        if level == 20.0:
            if rotation is not None:
                raise self.error("R not allowed in G10 L20", words["R"][1])
            given = self._l20_offsets(system, given, machine)
            # A B C: the offset that makes the current position read the word (no rotation,
            # no tool offset on them): origin = machine − G92 − word.
            g92 = self.coords.g92_abc_deg
            for k, value in turned.items():
                turned[k] = self.m.rotary[k - 3] - g92[k - 3] - value
        given.update(turned)
        self.coords.set_system(system, given, rotation)
        self.pos = machine

    def _g10_tool(self, level: int, words: dict, used: set, col: int) -> None:
        """G10 L1 / L10 / L11 P<tool>: write the tool table entry (LinuxCNC; checked against
        its interp tests g10-l1-l10 and g10-l11). The table changes; the offset in force
        changes at the next G43, as in LinuxCNC.

        L1: the given axes are the offsets, R the radius. L10: the offsets that make the
        current position read as the given values once G43 applies them; L11 the same in
        G59.3 with G92 ignored (a tool-setter fixture). For L10/L11 an axis not given keeps
        its reading computed with the entry's own offsets, and X and Y change together when
        the system is rotated (both go through the rotation)."""
        if "P" not in words:
            raise self.error(f"G10 L{level} needs P (the tool number)", col)
        p, pcol = words["P"]
        if p != int(p) or p < 0:
            raise self.error(f"G10 L{level} P{p:g}: P must be a tool number", pcol)
        used.update("LP" + "".join(a for a in "XYZRIJQ" if a in words))
        self.refuse_rotary_tool_offset(words)
        number = int(p)
        scale = self.m.scale
        old = self.tools.get(number) or Tool(number)
        offset = list(old.offset_mm)
        given = {i: words[a][0] * scale for i, a in enumerate(_AXES) if a in words}
        if level == 1:
            for axis, value in given.items():
                offset[axis] = value
        else:
            c = self.coords
            machine = self.pos
            if level == 11:
                origin, rot, g92 = c.system_offset_mm(9), c.system_rotation_deg(9), [0.0] * 3
            else:
                origin, rot, g92 = c.origin_mm, c.rotation_deg, c.g92_mm
            cos, sin = _cos_sin(rot)
            free = [machine[k] - offset[k] - origin[k] for k in range(3)]
            now = [
                cos * free[0] + sin * free[1] - g92[0],
                -sin * free[0] + cos * free[1] - g92[1],
                free[2] - g92[2],
            ]
            want = [given.get(k, now[k]) + g92[k] for k in range(3)]
            turned = [cos * want[0] - sin * want[1], sin * want[0] + cos * want[1], want[2]]
            new = [machine[k] - origin[k] - turned[k] for k in range(3)]
            if 0 in given or 1 in given:
                offset[0], offset[1] = new[0], new[1]
            if 2 in given:
                offset[2] = new[2]
        diameter = 2.0 * words["R"][0] * scale if "R" in words else old.diameter_mm
        self.tools[number] = Tool(number, tuple(offset), diameter, old.pocket)

    def _l20_offsets(self, system: int, given: dict, machine) -> dict:
        """G10 L20: the offsets of ``system`` that make the current position read as the
        given values there (LinuxCNC's convert_setup: X and Y through the system's rotation,
        so both change; an axis not given keeps its current reading)."""
        c = self.coords
        origin = c.system_offset_mm(system)
        rad = math.radians(c.system_rotation_deg(system))
        cos, sin = math.cos(rad), math.sin(rad)
        free = [machine[k] - c.tool_mm[k] - origin[k] for k in range(3)]
        # the current position in the system's own (rotated) coordinates, G92 removed
        now = [
            cos * free[0] + sin * free[1] - c.g92_mm[0],
            -sin * free[0] + cos * free[1] - c.g92_mm[1],
            free[2] - c.g92_mm[2],
        ]
        want = [given.get(k, now[k]) + c.g92_mm[k] for k in range(3)]
        have = [now[k] + c.g92_mm[k] for k in range(3)]
        out = {}
        if 0 in given or 1 in given:
            out[0] = origin[0] + (cos * have[0] - sin * have[1]) - (cos * want[0] - sin * want[1])
            out[1] = origin[1] + (sin * have[0] + cos * have[1]) - (sin * want[0] + cos * want[1])
        if 2 in given:
            out[2] = origin[2] + have[2] - want[2]
        return out

    def g52(self, words: dict, used: set, col: int) -> None:
        """G52 X Y Z: a local origin at the given program coordinates (LinuxCNC keeps it in
        the G92 offsets: it sets them directly, raises #5210, and G92.1/.2/.3 act on it);
        axes not given keep their offset; the machine does not move."""
        self.not_in_comp("Cannot change axis offsets with cutter radius comp", col)
        machine = self.pos
        self.coords.set_g92(
            {i: words[a][0] * self.m.scale for i, a in enumerate(_AXES) if a in words}
            | self.abc_offsets(words, wrapped_check=True)
        )
        used.update(_AXES)
        self.pos = machine

    def g92(self, words: dict, used: set, col: int) -> None:
        if not any(a in words for a in "XYZABC"):
            raise self.error("G92 needs at least one axis word", col)
        self.not_in_comp("Cannot change axis offsets with cutter radius comp", col)
        machine = self.pos
        c = self.coords
        unshifted = [self.prog[k] + c.g92_mm[k] for k in range(3)]
        offsets = {
            i: unshifted[i] - words[a][0] * self.m.scale for i, a in enumerate(_AXES) if a in words
        }
        # A B C: the offset that makes the current position read the word (degrees).
        for k, value in self.abc_offsets(words, wrapped_check=True).items():
            offsets[k] = self.m.rotary[k - 3] - c.origin_abc_deg[k - 3] - value
        c.set_g92(offsets)
        self.pos = machine
        used.update(_AXES)

    def go_home(self, which: int, words: dict, used: set) -> None:
        """G28 / G30: rapid through the intermediate point (axis words) to the stored one.

        With axis words only those axes go home (LinuxCNC); without, all do.
        """
        if self.m.comp_mode != G_40:
            raise self.error(f"G{which} with cutter compensation on")
        home = self.coords.home_mm(which)
        axes = [i for i, a in enumerate(_AXES) if a in words]
        turned = [i for i, a in enumerate("ABC") if a in words]
        home_abc = self.coords.home_abc_deg(which)
        abc = list(self.m.rotary)
        if axes or turned:
            middle = self.target_program(words)
            self.rapid_to_program(middle, self.target_abc(words))
            machine = self.pos
            for i in axes:
                machine[i] = home[i]
            abc = list(self.m.rotary)
            for i in turned:
                abc[i] = home_abc[i]
        else:
            machine = list(home)
            for i, letter in enumerate("ABC"):  # an axis the machine lacks stays
                if self.rotary_axis(letter) is not None:
                    abc[i] = home_abc[i]
        self.rapid_to_program(self.coords.to_program(machine), tuple(abc))
        used.update(_AXES)
