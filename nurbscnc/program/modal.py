"""Modal groups and the modal state (LinuxCNC's interp_internal.hh, setup_struct).

G codes are integers (value × 10: G59.3 is 593). :data:`G_GROUP` gives each executable or
tracked code its modal group, as LinuxCNC numbers them; :data:`G_REFUSED` the codes that are
valid RS274/NGC but that nurbscnc refuses with a clear error (spindle-synchronised motion,
probing, lathe modes, axes it does not drive).

:class:`ModalState` is the state that persists from block to block. The canned-cycle state
(``cycle_*``, ``retract_mode``) and cutter-compensation state (``comp_*``) are tracked here
for :mod:`nurbscnc.program.cycles` and :mod:`nurbscnc.program.compensation`.
"""

from __future__ import annotations

from dataclasses import dataclass

from nurbscnc.program.cycles import CycleState

INCH_MM = 25.4

#: Canned cycle motion codes (group 1): G73, G74, G81–G89.
CANNED_CYCLES = frozenset({730, 740, 810, 820, 830, 840, 850, 860, 870, 880, 890})

G_GROUP = {
    # group 0: non-modal
    40: 0, 100: 0, 280: 0, 281: 0, 300: 0, 301: 0, 520: 0, 530: 0, 920: 0, 921: 0, 922: 0, 923: 0,
    # group 1: motion
    0: 1, 10: 1, 20: 1, 30: 1, 50: 1, 51: 1, 52: 1, 53: 1, 62: 1, 800: 1,
    **{code: 1 for code in CANNED_CYCLES},
    170: 2, 180: 2, 190: 2,
    900: 3, 910: 3,
    901: 4, 911: 4,
    930: 5, 940: 5, 950: 5,
    200: 6, 210: 6,
    400: 7, 410: 7, 411: 7, 420: 7, 421: 7,
    430: 8, 431: 8, 490: 8,
    980: 10, 990: 10,
    540: 12, 550: 12, 560: 12, 570: 12, 580: 12, 590: 12, 591: 12, 592: 12, 593: 12,
    610: 13, 611: 13, 640: 13,
    960: 14, 970: 14,
}  # fmt: skip

#: Valid RS274/NGC codes nurbscnc refuses (the error names them and why).
G_REFUSED = {
    70: "G7 (lathe diameter mode)",
    80: "G8 (lathe radius mode)",
    171: "G17.1 (UV plane: U, V, W axes)",
    181: "G18.1 (WU plane: U, V, W axes)",
    191: "G19.1 (VW plane: U, V, W axes)",
    330: "G33 (spindle-synchronised motion)",
    331: "G33.1 (rigid tapping)",
    382: "G38.2 (probing needs a probe input)",
    383: "G38.3 (probing needs a probe input)",
    384: "G38.4 (probing needs a probe input)",
    385: "G38.5 (probing needs a probe input)",
    432: "G43.2 (additional tool length offset)",
    760: "G76 (threading cycle, spindle-synchronised)",
    700: "G70 (lathe finishing cycle)",
    710: "G71 (lathe roughing cycle)",
    711: "G71.1 (lathe roughing cycle)",
    712: "G71.2 (lathe roughing cycle)",
    720: "G72 (lathe facing cycle)",
    721: "G72.1 (lathe facing cycle)",
    722: "G72.2 (lathe facing cycle)",
}

#: M codes: group as LinuxCNC numbers them (4 stop, 5 HAL I/O, 6 tool change, 7 spindle,
#: 8 coolant, 9 override switches, 10 modal state).
M_GROUP = {0: 4, 1: 4, 2: 4, 30: 4, 60: 4, 98: 4, 99: 4, 62: 5, 63: 5, 64: 5, 65: 5, 66: 5,
           67: 5, 68: 5, 6: 6, 61: 6, 3: 7, 4: 7, 5: 7, 7: 8, 8: 8, 9: 8, 19: 7, 48: 9, 49: 9,
           50: 9, 51: 9, 52: 9, 53: 9, 70: 10, 71: 10, 72: 10, 73: 10}  # fmt: skip

#: What M70 / M73 save and M72 restores (LinuxCNC: units, plane, distance modes, feed mode,
#: path control, F and S; the coordinate system is saved beside these, in the interpreter).
SAVED_BY_M70 = ("plane", "scale", "absolute", "arc_absolute", "feed_mode", "feed", "feed_mm",
                "spindle_rpm", "path_mode", "blend_mm", "naive_mm")  # fmt: skip

PLANE_OF_G = {170: "XY", 180: "ZX", 190: "YZ"}
G_OF_PLANE = {"XY": 17, "ZX": 18, "YZ": 19}
SYSTEM_OF_G = {540: 1, 550: 2, 560: 3, 570: 4, 580: 5, 590: 6, 591: 7, 592: 8, 593: 9}


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
    feed_mode: int = 940  # 930 inverse time, 940 units per minute, 950 units per revolution
    feed: float = 0.0  # the F word in force, as written
    feed_mm: float = 0.0  # F in mm (per minute or per revolution), in the units it was given
    spindle_rpm: float = 0.0
    tool_selected: int = 0  # T
    tool_loaded: int = 0  # M6
    tool_offset_code: int = 490  # 430, 431, 490
    # Path control (group 13), as the segments carry it (geometry.segments.Line.blend_mm):
    # G64 P [mm] > 0; inf for G64 without P or with P0 (the machine's path tolerance,
    # LinuxCNC's default mode); 0 for G61 (exact path); BLEND_EXACT_STOP (< 0) for G61.1.
    blend_mm: float = float("inf")
    path_mode: int = 640
    naive_mm: float = 0.0  # G64 Q [mm]: the naive CAM detector's tolerance (0: off)
    # canned cycles
    retract_mode: int = 990
    cycle: CycleState = CycleState()
    spindle: str = "off"
    # cutter compensation
    comp_mode: int = 400
    comp_side: str | None = None
    comp_radius_mm: float = 0.0
    comp_d: float | None = None
    # rotary axes: nurbscnc carries them only while they do not move
    rotary: tuple = (0.0, 0.0, 0.0)

    @property
    def inch(self) -> bool:
        return self.scale != 1.0
