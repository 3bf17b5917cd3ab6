"""The G and M codes and their modal groups by name (LinuxCNC's interp_internal.hh).

G codes are integers, the value × 10, as LinuxCNC stores them: G59.3 is 593, G38.2 is 382
(:meth:`~nurbscnc.program.executor.BlockExecutor.read_g` rounds the word's value × 10). M
codes are the plain value (M6 is 6): RS274/NGC has no M code with a decimal. The modal groups are
numbered as LinuxCNC numbers them (its ``GM_*`` and the M groups of ``convert_m``), so error
messages that name a group say LinuxCNC's number.
"""

from __future__ import annotations

# -- G codes (× 10) ----------------------------------------------------------------------------
G_0 = 0
G_1 = 10
G_2 = 20
G_2_2 = 22  # not RS274/NGC: read as G5.2 (LinuxCNC's own sample opens a NURBS block with it)
G_3 = 30
G_4 = 40
G_5 = 50
G_5_1 = 51
G_5_2 = 52
G_5_3 = 53
G_6_2 = 62
G_7 = 70
G_8 = 80
G_10 = 100
G_17 = 170
G_17_1 = 171
G_18 = 180
G_18_1 = 181
G_19 = 190
G_19_1 = 191
G_20 = 200
G_21 = 210
G_28 = 280
G_28_1 = 281
G_30 = 300
G_30_1 = 301
G_33 = 330
G_33_1 = 331
G_38_2 = 382
G_38_3 = 383
G_38_4 = 384
G_38_5 = 385
G_40 = 400
G_41 = 410
G_41_1 = 411
G_42 = 420
G_42_1 = 421
G_43 = 430
G_43_1 = 431
G_43_2 = 432
G_49 = 490
G_52 = 520
G_53 = 530
G_54 = 540
G_55 = 550
G_56 = 560
G_57 = 570
G_58 = 580
G_59 = 590
G_59_1 = 591
G_59_2 = 592
G_59_3 = 593
G_61 = 610
G_61_1 = 611
G_64 = 640
G_70 = 700
G_71 = 710
G_71_1 = 711
G_71_2 = 712
G_72 = 720
G_72_1 = 721
G_72_2 = 722
G_73 = 730
G_74 = 740
G_76 = 760
G_80 = 800
G_81 = 810
G_82 = 820
G_83 = 830
G_84 = 840
G_85 = 850
G_86 = 860
G_87 = 870
G_88 = 880
G_89 = 890
G_90 = 900
G_90_1 = 901
G_91 = 910
G_91_1 = 911
G_92 = 920
G_92_1 = 921
G_92_2 = 922
G_92_3 = 923
G_93 = 930
G_94 = 940
G_95 = 950
G_96 = 960
G_97 = 970
G_98 = 980
G_99 = 990

# -- M codes (plain) ---------------------------------------------------------------------------
M_0 = 0
M_1 = 1
M_2 = 2
M_3 = 3
M_4 = 4
M_5 = 5
M_6 = 6
M_7 = 7
M_8 = 8
M_9 = 9
M_19 = 19
M_30 = 30
M_48 = 48
M_49 = 49
M_50 = 50
M_51 = 51
M_52 = 52
M_53 = 53
M_60 = 60
M_61 = 61
M_62 = 62
M_63 = 63
M_64 = 64
M_65 = 65
M_66 = 66
M_67 = 67
M_68 = 68
M_70 = 70
M_71 = 71
M_72 = 72
M_73 = 73
M_98 = 98
M_99 = 99
#: User M-codes M100–M199: an executable of that name run at rest (LinuxCNC's
#: USER_DEFINED_FUNCTION, found in PROGRAM_PREFIX and [RS274NGC]USER_M_PATH).
USER_M_FIRST = 100
USER_M_LAST = 199

# -- modal groups of G codes (LinuxCNC's numbers) ------------------------------------------
GM_NONMODAL = 0  # G4, G10, G28, G30, G52, G53, G92 family
GM_MOTION = 1
GM_PLANE = 2
GM_DISTANCE = 3  # G90 / G91
GM_IJK_DISTANCE = 4  # G90.1 / G91.1
GM_FEED_MODE = 5
GM_UNITS = 6
GM_CUTTER_COMP = 7
GM_TOOL_LENGTH = 8
GM_RETURN_MODE = 10  # G98 / G99
GM_COORD_SYSTEM = 12
GM_CONTROL_MODE = 13  # G61 / G61.1 / G64
GM_SPINDLE_MODE = 14  # G96 / G97

# -- modal groups of M codes (LinuxCNC's convert_m) --------------------------------------------
MM_STOP = 4  # M0, M1, M2, M30, M60, M98, M99
MM_IO = 5  # M62–M68
MM_TOOL_CHANGE = 6  # M6, M61
MM_SPINDLE = 7  # M3, M4, M5, M19
MM_COOLANT = 8
MM_OVERRIDE = 9  # M48–M53
MM_MODAL_STATE = 10  # M70–M73
#: M100–M199 (LinuxCNC's group 10, the last of convert_m: after the tool change, the
#: spindle, coolant and the override switches; nurbscnc numbers it 11, its 10 is M70–M73).
MM_USER = 11

#: Canned cycle motion codes (group 1): G73, G74, G81–G89.
CANNED_CYCLES = frozenset({G_73, G_74, G_81, G_82, G_83, G_84, G_85, G_86, G_87, G_88, G_89})

#: Each executable or tracked G code's modal group.
G_GROUP = {
    **dict.fromkeys(
        (G_4, G_10, G_28, G_28_1, G_30, G_30_1, G_52, G_53, G_92, G_92_1, G_92_2, G_92_3),
        GM_NONMODAL,
    ),
    **dict.fromkeys((G_0, G_1, G_2, G_3, G_5, G_5_1, G_5_2, G_5_3, G_6_2, G_80), GM_MOTION),
    **dict.fromkeys(CANNED_CYCLES, GM_MOTION),
    **dict.fromkeys((G_17, G_18, G_19), GM_PLANE),
    **dict.fromkeys((G_90, G_91), GM_DISTANCE),
    **dict.fromkeys((G_90_1, G_91_1), GM_IJK_DISTANCE),
    **dict.fromkeys((G_93, G_94, G_95), GM_FEED_MODE),
    **dict.fromkeys((G_20, G_21), GM_UNITS),
    **dict.fromkeys((G_40, G_41, G_41_1, G_42, G_42_1), GM_CUTTER_COMP),
    **dict.fromkeys((G_43, G_43_1, G_49), GM_TOOL_LENGTH),
    **dict.fromkeys((G_98, G_99), GM_RETURN_MODE),
    **dict.fromkeys((G_54, G_55, G_56, G_57, G_58, G_59, G_59_1, G_59_2, G_59_3), GM_COORD_SYSTEM),
    **dict.fromkeys((G_61, G_61_1, G_64), GM_CONTROL_MODE),
    **dict.fromkeys((G_96, G_97), GM_SPINDLE_MODE),
}

#: Each supported M code's modal group.
M_GROUP = {
    **dict.fromkeys((M_0, M_1, M_2, M_30, M_60, M_98, M_99), MM_STOP),
    **dict.fromkeys((M_62, M_63, M_64, M_65, M_66, M_67, M_68), MM_IO),
    **dict.fromkeys((M_6, M_61), MM_TOOL_CHANGE),
    **dict.fromkeys((M_3, M_4, M_5, M_19), MM_SPINDLE),
    **dict.fromkeys((M_7, M_8, M_9), MM_COOLANT),
    **dict.fromkeys((M_48, M_49, M_50, M_51, M_52, M_53), MM_OVERRIDE),
    **dict.fromkeys((M_70, M_71, M_72, M_73), MM_MODAL_STATE),
    **dict.fromkeys(range(USER_M_FIRST, USER_M_LAST + 1), MM_USER),
}

#: Valid RS274/NGC codes nurbscnc refuses (the error names them and why).
G_REFUSED = {
    G_7: "G7 (lathe diameter mode)",
    G_8: "G8 (lathe radius mode)",
    G_17_1: "G17.1 (UV plane: U, V, W axes)",
    G_18_1: "G18.1 (WU plane: U, V, W axes)",
    G_19_1: "G19.1 (VW plane: U, V, W axes)",
    G_33: "G33 (spindle-synchronised motion)",
    G_33_1: "G33.1 (rigid tapping)",
    G_38_2: "G38.2 (probing needs a probe input)",
    G_38_3: "G38.3 (probing needs a probe input)",
    G_38_4: "G38.4 (probing needs a probe input)",
    G_38_5: "G38.5 (probing needs a probe input)",
    G_43_2: "G43.2 (additional tool length offset)",
    G_76: "G76 (threading cycle, spindle-synchronised)",
    G_70: "G70 (lathe finishing cycle)",
    G_71: "G71 (lathe roughing cycle)",
    G_71_1: "G71.1 (lathe roughing cycle)",
    G_71_2: "G71.2 (lathe roughing cycle)",
    G_72: "G72 (lathe facing cycle)",
    G_72_1: "G72.1 (lathe facing cycle)",
    G_72_2: "G72.2 (lathe facing cycle)",
}


def fmt_code(code: int) -> str:
    """A G code × 10 as written: 410 → "41", 411 → "41.1"."""
    return str(code // 10) if code % 10 == 0 else f"{code // 10}.{code % 10}"
