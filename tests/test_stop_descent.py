"""The stop rule's final descent (nurbscnc.plan.shaping ``_soften_stops``,
``_final_descent``): under a jerk limit far above what the servo follows (A·|p|; LinuxCNC's
limits: A 2450 mm/s², J 1e9), a G64 corner the check stops at has the deceleration of its
final descent lowered, not the jerk of the whole run into it. An independent servo
simulation of a rest-to-rest 90° stop at 13.3 mm/s (docs/benchmarks.md): the descent at
1000 mm/s² without a jerk limit stays within 13.5 µm and loses 9.4 ms; the jerk lowered to
1e5 instead 13.0 µm and 23.1 ms.

Measured independently: the output reference points through ``scipy.signal.lsim`` of SPEC
eq. 25 (tests/servo_reference.py) against the programmed path (bench/contour.py, as
tests/test_shaping.py's ``_arc_program_check``: every sample from the first cut on, the
final rapid included, within ε_max of the path or ε_max + P of a G64 vertex). The times
before the change (jerk softening over the whole run): 3.2269 s, 7.5629 s, 1.7355 s.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from nurbscnc.machine.profile import load_machine
from tests.test_shaping import _arc_program_check

ROOT = Path(__file__).resolve().parents[1]
PROGRAMS = ROOT / "tests" / "programs" / "planner"
LINUXCNC_LIMITS = ROOT / "bench" / "programs" / "linuxcnc_limits.toml"


@pytest.mark.parametrize(
    ("name", "before_s", "below_s"),
    [
        # 10 mm square at F800: four stopped 90° corners (the CamBam turtle's pockets).
        ("stop_square_g64.nc", 3.2269, 3.217),
        # Pentagram of radius 10 mm at F800: five stopped 144° turns.
        ("stop_star_g64.nc", 7.5629, 7.5595),
        # 25 chords of 0.2 mm into a stopped 90° corner, then a 5 × 5 mm square's edges.
        ("stop_chords_g64.nc", 1.7355, 1.726),
    ],
)
def test_g64_stops_within_eps_and_faster(name, before_s, below_s):
    """Every sample within ε_max of the path (or ε_max + P of a G64 vertex) in an
    independent lsim, and the program faster than with the jerk softened."""
    machine = load_machine(LINUXCNC_LIMITS)
    run, err_mm = _arc_program_check(PROGRAMS / name, machine)
    assert err_mm <= machine.limits.contour_tolerance_mm + 1e-6
    assert run.plan.cycle_time_s < below_s < before_s


def test_only_the_final_descent_of_a_run_is_lowered():
    """The chords into the stopped corner are one run (tangent, equal caps): the stop's
    lowered deceleration holds on its final descent only (at 13.3 mm/s and ~950 mm/s²,
    v²/(2a) ≈ 0.09 mm: the last chord); the chords before keep the machine's deceleration
    and jerk (the jerk softening lowered the descent jerk of all of them). The stops between
    two cuts are answered by the deceleration, the jerk of their descents left at J."""
    machine = load_machine(LINUXCNC_LIMITS)
    run, _ = _arc_program_check(PROGRAMS / "stop_chords_g64.nc", machine)
    plan = run.plan
    lim = plan.limits
    v = plan.profile.junction_speeds_mm_s
    lines = plan.pieces.line
    chords = np.flatnonzero((lines >= 4) & (lines <= 28))
    last = chords[-1]
    assert v[last + 1] == 0.0  # the corner after the chords is a stop
    a_max = lim.a_up_mm_s2[chords[0]]
    j_max = lim.j_up_mm_s3[chords[0]]
    assert lim.a_down_mm_s2[last] < 0.5 * a_max
    assert np.all(lim.a_down_mm_s2[chords[:-2]] == a_max)
    assert np.all(lim.j_down_mm_s3[chords] == j_max)
    # The corners between the square's cut edges: descent by deceleration, jerk at J.
    edges = np.flatnonzero((lines >= 29) & (lines <= 30))
    assert np.all(v[edges + 1] == 0.0)
    assert np.all(lim.a_down_mm_s2[edges] < a_max)
    assert np.all(lim.j_down_mm_s3[edges] == j_max)
