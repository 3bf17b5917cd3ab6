"""The modal state (LinuxCNC's interp_internal.hh, setup_struct) and the state each code selects.

G codes are integers (value × 10: G59.3 is 593), named in :mod:`nurbscnc.program.codes`
with their modal groups; the tables here map a code to the state it selects.

:class:`ModalState` is the state that persists from block to block. The canned-cycle state
(``cycle_*``, ``retract_mode``) and cutter-compensation state (``comp_*``) are tracked here
for :mod:`nurbscnc.program.cycles` and :mod:`nurbscnc.program.compensation`.
"""

from __future__ import annotations

from dataclasses import dataclass

from nurbscnc.program.codes import (
    G_17,
    G_18,
    G_19,
    G_40,
    G_49,
    G_54,
    G_55,
    G_56,
    G_57,
    G_58,
    G_59,
    G_59_1,
    G_59_2,
    G_59_3,
    G_64,
    G_94,
    G_99,
)
from nurbscnc.program.cycles import CycleState

INCH_MM = 25.4

#: What M70 / M73 save and M72 restores (LinuxCNC: units, plane, distance modes, feed mode,
#: path control, F and S; the coordinate system is saved beside these, in the interpreter).
SAVED_BY_M70 = (
    "plane",
    "scale",
    "absolute",
    "arc_absolute",
    "feed_mode",
    "feed",
    "feed_mm",
    "spindle_rpm",
    "path_mode",
    "blend_mm",
    "naive_mm",
)

PLANE_OF_G = {G_17: "XY", G_18: "ZX", G_19: "YZ"}
G_OF_PLANE = {"XY": G_17, "ZX": G_18, "YZ": G_19}
SYSTEM_OF_G = {
    G_54: 1,
    G_55: 2,
    G_56: 3,
    G_57: 4,
    G_58: 5,
    G_59: 6,
    G_59_1: 7,
    G_59_2: 8,
    G_59_3: 9,
}


@dataclass
class ModalState:
    """What persists from block to block. Lengths in mm; codes as G × 10.

    Canned cycles (for cycles.py): ``cycle`` the sticky words and initial level of the run of
    cycle blocks in force (a :class:`~nurbscnc.program.cycles.CycleState`, mm and s);
    ``retract_mode`` is 980 (G98: back to the initial level) or 990 (G99: to R); 990 at the
    start, as LinuxCNC 2.9 (its ``retract_mode`` starts at 0, R_PLANE: rs274ngc_pre.cc leaves
    it uninitialised in a zeroed setup; rs274 -g retracts a first G81 to R).
    ``spindle`` is "cw" (M3), "ccw" (M4) or "off" (M5, M19, the start): cycles that stop and
    restart the spindle (G74, G84, G86, G87) need it.
    Cutter compensation (for compensation.py): ``comp_mode`` 400 (G40), 410/420 (G41/G42,
    radius from the tool table by D), 411/421 (G41.1/G42.1, diameter from D);
    ``comp_side`` None, "left" or "right"; ``comp_radius_mm``; ``comp_d`` the D word.
    """

    motion: int | None = None  # None, 0, 10, 20, 30, 50, 51, 52, 53, 62, 800, or a cycle
    plane: str = "XY"
    scale: float = 1.0  # mm per program unit (25.4 under G20)
    absolute: bool = True  # G90 / G91
    arc_absolute: bool = False  # G90.1 / G91.1
    feed_mode: int = G_94  # 930 inverse time, 940 units per minute, 950 units per revolution
    feed: float = 0.0  # the F word in force, as written
    feed_mm: float = 0.0  # F in mm (per minute or per revolution), in the units it was given
    spindle_rpm: float = 0.0
    tool_selected: int = 0  # T
    tool_loaded: int = 0  # M6
    tool_offset_code: int = G_49  # 430, 431, 490
    # Path control (group 13), as the segments carry it (geometry.segments.Line.blend_mm):
    # G64 P [mm] > 0; inf for G64 without P or with P0 (the machine's path tolerance,
    # LinuxCNC's default mode); 0 for G61 (exact path); BLEND_EXACT_STOP (< 0) for G61.1.
    blend_mm: float = float("inf")
    path_mode: int = G_64
    naive_mm: float = 0.0  # G64 Q [mm]: the naive CAM detector's tolerance (0: off)
    # canned cycles
    retract_mode: int = G_99
    cycle: CycleState = CycleState()
    spindle: str = "off"
    # cutter compensation
    comp_mode: int = G_40
    comp_side: str | None = None
    comp_radius_mm: float = 0.0
    comp_d: float | None = None
    # Rotary axes (program/rotary.py): ``rotary`` the machine position of A B C [deg];
    # ``abc_hold`` the ``abc_deg`` of a move that leaves them there, ``rotary * 2``, or None
    # while all three are 0 (a program that never turns one carries nothing);
    # The rate of a move of the rotary axes alone is ``feed`` in deg/min: LinuxCNC's canon
    # takes it from the F word as written (FROM_PROG_ANG), whatever G20/G21 says.
    rotary: tuple = (0.0, 0.0, 0.0)
    abc_hold: tuple | None = None
    rotary_seen: bool = False  # some rotary axis has been away from 0

    def set_rotary(self, abc_deg: tuple) -> None:
        """The rotary axes are now at ``abc_deg`` [deg, machine]."""
        self.rotary = abc_deg
        self.abc_hold = None if abc_deg == (0.0, 0.0, 0.0) else abc_deg * 2
        self.rotary_seen = self.rotary_seen or self.abc_hold is not None

    @property
    def inch(self) -> bool:
        return self.scale != 1.0
