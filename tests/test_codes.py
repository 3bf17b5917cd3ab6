"""The named G and M codes (program/codes.py) and the tables built on them."""

from nurbscnc.program import codes
from nurbscnc.program.codes import G_GROUP, G_REFUSED, GM_MOTION, M_GROUP, fmt_code
from nurbscnc.program.motion import MOTION_HANDLERS
from nurbscnc.program.words import CYCLE_WORDS


def test_names_spell_their_values():
    for name, value in vars(codes).items():
        if name.startswith(("G_", "M_")) and isinstance(value, int):
            digits = name[2:].split("_")
            expected = int(digits[0]) * (10 if name[0] == "G" else 1)
            if len(digits) == 2:
                expected += int(digits[1])
            assert value == expected, name


def test_every_motion_code_has_a_handler():
    motion = {code for code, group in G_GROUP.items() if group == GM_MOTION}
    assert motion - {codes.G_80} == set(MOTION_HANDLERS) - {None}
    assert set(CYCLE_WORDS) == set(codes.CANNED_CYCLES)


def test_refused_codes_are_not_executed():
    assert not set(G_REFUSED) & set(G_GROUP)
    assert all(text.startswith(f"G{fmt_code(code)} ") for code, text in G_REFUSED.items())


def test_groups_as_linuxcnc_numbers_them():
    assert G_GROUP[codes.G_41_1] == codes.GM_CUTTER_COMP == 7
    assert G_GROUP[codes.G_59_3] == codes.GM_COORD_SYSTEM == 12
    assert M_GROUP[codes.M_6] == codes.MM_TOOL_CHANGE == 6
    assert fmt_code(codes.G_38_2) == "38.2" and fmt_code(codes.G_1) == "1"
