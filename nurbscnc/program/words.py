"""What the words of a block may hold: the bounds on their values, the words each canned
cycle reads, and the error for a word that no code of its block used."""

from __future__ import annotations

from nurbscnc.program.codes import G_73, G_74, G_81, G_82, G_83, G_84, G_85, G_86, G_87, G_88, G_89

AXES = ("X", "Y", "Z")

# Bounds on values that are finite but no machine can act on (1e20 mm, a 1e300 s dwell): the
# error names the value instead of letting it overflow or stall a later stage.
MAX_COORD_MM = 1e9  # 1000 km
MAX_ANGLE_DEG = 1e9  # a rotary axis's position: ~2.8 million turns
MAX_DWELL_S = 1e6  # 11.6 days
MAX_FEED_MM_MIN = 1e9
MIN_FEED_MM_MIN = 1e-9  # below: zero-like feeds (denormals such as 1e-321)
MAX_ARC_TURNS = 100_000

#: The words a canned cycle reads besides X, Y, Z, R, L and polar @ ^ (LinuxCNC's
#: check_other_codes): P with G74, G82, G84, G86, G88, G89; Q with G73, G83; I, J, K with G87.
CYCLE_WORDS = {
    G_73: "Q",
    G_74: "P",
    G_81: "",
    G_82: "P",
    G_83: "Q",
    G_84: "P",
    G_85: "",
    G_86: "P",
    G_87: "IJK",
    G_88: "P",
    G_89: "P",
}


def cycles_reading(letter: str) -> str:
    """The canned cycles that read ``letter`` (:data:`CYCLE_WORDS`), as "G74, G82, …"."""
    return ", ".join(
        f"G{code // 10}" for code, reads in sorted(CYCLE_WORDS.items()) if letter in reads
    )


def unused_word_message(letter: str) -> str:
    """The error for a ``letter`` word that no code of its block read."""
    return {
        "I": f"I word with no arc (G2/G3), G5, G5.1, G10 or {cycles_reading('I')} to use it",
        "J": f"J word with no arc (G2/G3), G5, G5.1, G10 or {cycles_reading('J')} to use it",
        "K": f"K word with no arc (G2/G3), G6.2 NURBS or {cycles_reading('K')} to use it",
        "R": "R word with no arc (G2/G3), canned cycle or G6.2 NURBS to use it",
        "P": f"P word with no G4, G10, G64, arc, G5, G5.2, G6.2, {cycles_reading('P')} or "
        "M98 to use it",
        "Q": f"Q word with no G5, G10, G64, {cycles_reading('Q')} or G6.2 to use it",
        "L": "L word with no G5.2 or G10 to use it",
        "H": "H word with no G43 to use it",
        "E": "E word with no M66, M67 or M68 to use it",
        "F": "F word not used",
    }.get(letter, f"{letter} word not used")
