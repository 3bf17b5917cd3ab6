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
    return (G28_BASE <= index <= G28_BASE + 5 or G30_BASE <= index <= G30_BASE + 5
            or G92_FLAG <= index <= SYSTEM_BASE + SYSTEM_STRIDE * N_SYSTEMS - 1)  # fmt: skip


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

    def __post_init__(self):
        self.params.setdefault(SYSTEM_INDEX, 1.0)
        self.plain = True  # no offset, rotation or tool offset: machine = program

    def _update_plain(self) -> None:
        self.plain = not (any(self.origin_mm) or any(self.g92_mm) or any(self.tool_mm)
                          or self.rotation_deg)  # fmt: skip

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
        return [x + self.origin_mm[0] + self.tool_mm[0],
                y + self.origin_mm[1] + self.tool_mm[1],
                z + self.origin_mm[2] + self.tool_mm[2]]  # fmt: skip

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
        self.rotation_deg = self.system_rotation_deg(system)
        self._update_plain()

    def set_system(self, system: int, offsets: dict, rotation_deg: float | None) -> None:
        """G10 L2 / L20: set axes (0..2 → mm) and the rotation of ``system`` (1..9)."""
        base = SYSTEM_BASE + SYSTEM_STRIDE * (system - 1)
        for axis, value in offsets.items():
            self.params[base + axis] = value
        if rotation_deg is not None:
            self.params[base + 9] = rotation_deg
        if system == self.system:
            self._load(system)

    def set_g92(self, offsets: dict) -> None:
        """G92: the offsets (axis → mm) of the given axes; the others keep theirs."""
        for axis, value in offsets.items():
            self.g92_mm[axis] = value
        self._store_g92(1.0)
        self._update_plain()

    def clear_g92(self, keep_parameters: bool) -> None:
        """G92.1 (zero the parameters too) or G92.2 (keep them for G92.3)."""
        self.g92_mm = [0.0, 0.0, 0.0]
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
        self.params[G92_FLAG] = 1.0
        self._update_plain()

    def _store_g92(self, flag: float) -> None:
        for k in range(3):
            self.params[G92_BASE + k] = self.g92_mm[k]
        self.params[G92_FLAG] = flag

    def home_mm(self, which: int) -> list:
        """The stored G28 (``which`` = 28) or G30 position [mm, machine]."""
        base = G28_BASE if which == 28 else G30_BASE
        return [self.params.get(base + k, 0.0) for k in range(3)]

    def store_home(self, which: int, machine_mm) -> None:
        """G28.1 / G30.1: store the current machine position."""
        base = G28_BASE if which == 28 else G30_BASE
        for k in range(3):
            self.params[base + k] = float(machine_mm[k])


def _cos_sin(angle_deg: float) -> tuple[float, float]:
    a = math.radians(angle_deg)
    return math.cos(a), math.sin(a)
