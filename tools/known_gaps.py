#!/usr/bin/env python3
"""Write tests/programs/real/KNOWN_GAPS.txt: the real programs where nurbscnc does not yet do
what LinuxCNC does, each with the missing feature and the first difference.

Run with the project's environment (``.venv/bin/python tools/known_gaps.py``) after an
interpreter change; the list can only shrink on purpose: ``tests/test_linuxcnc_goldens.py``
marks every listed program as a strict xfail, so a program that starts to agree fails the
suite until this script (or a hand edit) takes it off. Prints the agreement counts.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.linuxcnc_compare import (  # noqa: E402
    KNOWN_GAPS,
    LENIENT_ERRORS,
    ROOT,
    check_golden,
    golden_names,
    load_golden,
    manifest_roles,
    moves_rotary,
)

# First matching fragment of the difference → the feature it shows is missing.
FEATURES = [
    ("O-words", "O-word subroutines / control flow"),
    ("M98", "Fanuc M98/M99 subroutines"),
    ("G10", "G10 L1/L2/L10/L11/L20 (tool and work offsets)"),
    ("G92", "G92 offsets"),
    ("canned cycle", "canned cycles"),
    ("G98", "canned cycles"),
    ("G99", "canned cycles"),
    ("cutter radius compensation", "cutter radius compensation"),
    ("radius to end of arc", "LinuxCNC's arc end-radius tolerance"),
    ("'^'", "polar coordinates @ ^"),
    ("makes a pause", "M0/M1/M60 pause segments"),
    ("M70", "M70-M73 modal state save/restore"),
    ("parameter name", "EXISTS[] / named-parameter syntax"),
    ("G95", "G95 feed per revolution"),
    ("Bad character '%'", "a closing '%' without an opening one is an error"),
    ("G80 and G0", "G80 with a motion code in the same block"),
]


#: Differences kept on purpose (the golden shows the oracle's canon, not a LinuxCNC machine).
DECIDED = {
    "linuxcnc__nc_files__skeleton": (
        "oracle artifact, not fixed on purpose: after T1 M6 G43 H1 the oracle's canons (rs274, "
        "gcode module) re-read the position without the new tool length offset, so LinuxCNC's "
        "preview moves Z 12.7 mm down on the next XY rapid; a LinuxCNC machine (emccanon.cc, "
        "unoffset_and_unrotate_pos) subtracts it and Z stays, as nurbscnc does"
    ),
}


def feature(message: str, name: str = "") -> str:
    if name in DECIDED:
        return DECIDED[name]
    return next((f for frag, f in FEATURES if frag in message), "differs")


def main() -> int:
    roles = manifest_roles()
    gaps, agree, accepted = [], 0, 0
    compared = {"moves": [0, 0], "LinuxCNC refuses": [0, 0], "outside 3-axis": [0, 0]}
    for name in golden_names():
        golden = load_golden(name)
        accepted += golden["accepted"]
        if roles[name] == "refused" or moves_rotary(golden):
            kind = "outside 3-axis"
        elif golden["accepted"] or golden["error"]["message"].startswith(LENIENT_ERRORS):
            kind = "moves"
        else:
            kind = "LinuxCNC refuses"
        compared[kind][1] += 1
        try:
            check_golden(name, roles[name], golden, ROOT / golden["program"])
            agree += 1
            compared[kind][0] += 1
        except AssertionError as exc:
            message = " ".join(str(exc).split())
            gaps.append(f"{name}  {feature(message, name)}: {message[:160]}")
    lines = [
        "# Real programs nurbscnc does not reproduce yet: golden name, missing feature: first",
        "# difference. Written by tools/known_gaps.py; tests/test_linuxcnc_goldens.py expects",
        "# each of these to fail (strict xfail), so the list must shrink as features land.",
        *gaps,
    ]
    KNOWN_GAPS.write_text("\n".join(lines) + "\n")
    print(
        f"{len(golden_names())} programs, LinuxCNC accepts {accepted}, "
        f"nurbscnc agrees with LinuxCNC on {agree}, {len(gaps)} known gaps"
    )
    for kind, (ok, total) in compared.items():
        print(f"  {kind}: {ok} of {total} agree")
    return 0


if __name__ == "__main__":
    sys.exit(main())
