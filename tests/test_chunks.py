"""Output in chunks (issue 14): the plan's samples window by window, equal to the whole arrays.

References: the whole-array sampler of the same plan (:func:`sample_plan`, one call over all
rows, as every command used before), and the writers' whole-array output (the files must be
byte-identical). Window sizes 1 (every join), 7 (joins inside runs of NURBS samples, inside
PH corners and dwells) and 4096 (a window holds several pieces).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from nurbscnc.interpolate.sample import sample_chunks, sample_plan
from nurbscnc.machine.profile import load_machine
from nurbscnc.plan.lookahead import plan_program
from nurbscnc.plan.timing import sample_count
from nurbscnc.program.interpret import interpret_text

ROOT = Path(__file__).resolve().parents[1]
MACHINE = load_machine()
PERIOD = MACHINE.servo.period_s
WINDOWS = (1, 7, 4096)
FIELDS = ("t_s", "points_mm", "s_mm", "v_mm_s", "a_mm_s2", "piece", "line", "param")

#: Lines, an arc, a helix, a dwell inside the motion and one after the end, a rapid.
MIXED = """G21 G17 G90 G94
G0 X0 Y0 Z0
G1 X4 F1200
G2 X8 Y0 I2 J0
G4 P0.05
G3 X8 Y4 Z1 I0 J2
G1 X0 Y4 F600
G4 P0.02
M2
"""


def _plan(name: str):
    text = (ROOT / "programs" / name).read_text() if name.endswith(".nc") else name
    return plan_program(interpret_text(text), MACHINE)


@pytest.fixture(scope="module")
def plans():
    return {"naca2415": _plan("naca2415.nc"), "mixed": _plan(MIXED)}


def _joined(chunks, field):
    return np.concatenate([getattr(c, field) for c in chunks])


@pytest.mark.parametrize("interpolator", ["exact", "taylor"])
@pytest.mark.parametrize("window", WINDOWS)
@pytest.mark.parametrize("name", ["naca2415", "mixed"])
def test_chunks_are_the_rows_of_the_whole_samples(plans, name, window, interpolator):
    """Every field of the windows, joined, is bit-identical to the whole samples: the exact
    placement per row, and the Taylor recurrence carried across joins (its runs of NURBS
    samples cross windows of 1 and 7 rows)."""
    plan = plans[name]
    whole = sample_plan(plan.pieces, plan.profile, PERIOD, interpolator)
    chunks = list(sample_chunks(plan.pieces, plan.profile, PERIOD, interpolator, window))
    n = sample_count(plan.pieces, plan.profile, PERIOD)
    assert [c.t_s.size for c in chunks] == [min(window, n - k) for k in range(0, n, window)]
    assert all(c.interpolator == interpolator for c in chunks)
    for field in FIELDS:
        np.testing.assert_array_equal(_joined(chunks, field), getattr(whole, field),
                                      err_msg=field)  # fmt: skip


def test_taylor_windows_continue_the_recurrence(plans):
    """The Taylor points differ from the exact ones inside a run (so a window restarting its
    run at the exact u would show): at window 7 the joins fall inside runs, and the rows
    right after each join still equal the whole recurrence, not the exact placement."""
    plan = plans["naca2415"]
    taylor = sample_plan(plan.pieces, plan.profile, PERIOD, "taylor")
    exact = sample_plan(plan.pieces, plan.profile, PERIOD, "exact")
    firsts = np.arange(7, taylor.t_s.size, 7)
    moved = firsts[np.any(taylor.points_mm[firsts] != exact.points_mm[firsts], axis=1)]
    assert moved.size > 20  # many joins land where Taylor and exact differ
    chunks = list(sample_chunks(plan.pieces, plan.profile, PERIOD, "taylor", 7))
    np.testing.assert_array_equal(_joined(chunks, "points_mm")[moved], taylor.points_mm[moved])


def test_window_must_be_positive(plans):
    plan = plans["mixed"]
    with pytest.raises(ValueError, match="chunk"):
        next(sample_chunks(plan.pieces, plan.profile, PERIOD, "exact", 0))
