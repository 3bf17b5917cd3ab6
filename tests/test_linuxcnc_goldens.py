"""nurbscnc against LinuxCNC 2.9 on real programs, move by move (committed goldens).

The programs are ``tests/programs/real/`` (sources and licences in its SOURCES.md); the goldens
``tests/golden/linuxcnc/`` are LinuxCNC's canonical moves, recorded by ``make goldens``
(``tools/record_goldens.py``; CI does not need LinuxCNC). What is compared, and to which
tolerance, is described in ``tests/linuxcnc_compare.py``.

Programs nurbscnc cannot read or reproduce yet are listed in
``tests/programs/real/KNOWN_GAPS.txt`` (name, then the missing feature): those tests are strict
xfails, so a program that starts to agree fails the suite until it is taken off the list.
"""

from __future__ import annotations

import hashlib

import pytest

from tests.linuxcnc_compare import (
    REAL,
    ROOT,
    check_golden,
    golden_names,
    load_golden,
    manifest_roles,
    read_known_gaps,
)

ROLES = manifest_roles()
GAPS = read_known_gaps()


def _params():
    for name in golden_names():
        marks = []
        if name in GAPS:
            marks.append(pytest.mark.xfail(strict=True, reason=GAPS[name]))
        yield pytest.param(name, marks=marks, id=name)


def test_every_program_has_a_golden_and_every_gap_a_program():
    """The manifest, the goldens and the gap list name the same programs."""
    assert set(golden_names()) == set(ROLES)
    assert set(GAPS) <= set(ROLES), sorted(set(GAPS) - set(ROLES))


@pytest.mark.parametrize("name", list(_params()))
def test_program_against_linuxcnc(name):
    golden = load_golden(name)
    path = ROOT / golden["program"]
    # The golden belongs to this very file (a changed program needs `make goldens`).
    assert hashlib.sha256(path.read_bytes()).hexdigest() == golden["sha256"]
    assert path.is_relative_to(REAL)
    check_golden(name, ROLES[name], golden, path)


@pytest.mark.parametrize(
    "perturb",
    [
        ("end", lambda m: m["end"].__setitem__(0, m["end"][0] + 2e-9)),
        ("centre", lambda m: m["centre"].__setitem__(1, m["centre"][1] - 2e-9)),
        ("rotation", lambda m: m.__setitem__("rotation", -m["rotation"])),
        ("turns", lambda m: m.__setitem__("rotation", m["rotation"] * 2)),
        ("normal", lambda m: m.__setitem__("normal", [0.0, 1.0, 0.0])),
        ("feed", lambda m: m.__setitem__("feed_mm_s", m["feed_mm_s"] * (1 + 1e-8))),
        ("line", lambda m: m.__setitem__("line", m["line"] + 1)),
    ],
    ids=lambda p: p[0],
)
def test_comparison_catches_a_small_difference(perturb):
    """The harness fails on a 2e-9 mm change of one arc (it is not a test that cannot fail)."""
    from tests.linuxcnc_compare import compare, run_nurbscnc

    golden = load_golden("linuxcnc__nc_files__cds")
    program = run_nurbscnc(ROOT / golden["program"])
    compare(golden, program)  # agrees as recorded
    arc = next(m for m in golden["moves"] if m["kind"] == "arc")
    perturb[1](arc)
    with pytest.raises(AssertionError):
        compare(golden, program)
