"""The curve rule's shared blame (nurbscnc.plan.shaping ``_blame``, ``SHARE_RATIO``): pieces
planned as one share their largest blame, but two arcs (or two curves across a jump of the
curvature) only where their own errors are alike, so a helix's first half-turn, which
carries the entry's transient, does not take the whole helix down to its own feed.

Measured independently: the output reference points through ``scipy.signal.lsim`` of SPEC
eq. 25 (tests/servo_reference.py) against the programmed path (bench/contour.py's closed-form
arcs, as tests/test_shaping.py's ``_arc_program_check``), and the helix's feed against the
fastest steady speed on its circle within ε_max, found by bisection on lsim alone.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from nurbscnc.machine.profile import load_machine
from nurbscnc.plan import shaping
from nurbscnc.plan.checkresult import Overs
from tests.servo_reference import lsim_actual_mm
from tests.test_shaping import _arc_program_check, _line_time_s

ROOT = Path(__file__).resolve().parents[1]
PROGRAMS = ROOT / "tests" / "programs" / "planner"
LINUXCNC_LIMITS = ROOT / "bench" / "programs" / "linuxcnc_limits.toml"
DROP_MM = 0.25  # each half-turn of the helices drops 0.25 mm


def _steady_circle_error_mm(machine, radius_mm: float, v_xy_mm_s: float) -> float:
    """The largest radial error [mm] of the tool (lsim) over the last two of six turns of a
    circle of ``radius_mm`` run at the constant speed ``v_xy_mm_s`` (z has no servo model in
    the profile: a helix's error is its circle's)."""
    period = machine.servo.period_s
    w = v_xy_mm_s / radius_mm
    t = np.arange(0.0, 6 * 2 * np.pi / w, period)
    ref = np.column_stack([radius_mm * np.cos(w * t), radius_mm * np.sin(w * t), 0.0 * t])
    tool = lsim_actual_mm(ref, machine, settle_s=0.0)
    tail = t >= 4 * 2 * np.pi / w
    return float(np.abs(np.hypot(tool[tail, 0], tool[tail, 1]) - radius_mm).max())


def _steady_speed_mm_s(machine, radius_mm: float, eps_mm: float) -> float:
    """The XY speed [mm/s] at which the steady circle error is ``eps_mm`` (bisection)."""
    lo, hi = 2.0, 40.0
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        ok = _steady_circle_error_mm(machine, radius_mm, mid) <= eps_mm
        lo, hi = (mid, hi) if ok else (lo, mid)
    return lo


@pytest.mark.parametrize(
    ("name", "radius_mm", "middle", "v_xy_range"),
    [
        ("fusion_arc_into_helix.nc", 0.375, range(9, 24), (14.0, 14.6)),
        ("fusion_turn_into_helix.nc", 0.275, range(12, 27), (11.9, 12.5)),
    ],
)
def test_a_helix_first_half_turn_does_not_slow_the_rest(name, radius_mm, middle, v_xy_range):
    """Fusion 360's helical ramps (LinuxCNC's limits, F1000), entered from a stop. The first
    half-turn carries the entry's transient (0.375 mm: 21.6 µm against 19.4 µm on the
    steady half-turns; 0.275 mm: 26.9 against 24.9 µm) and the blame was shared: the
    helices ran at 13.40 and 12.02 mm/s, 89.9 and 75 ms per half-turn. Now the steady
    half-turns keep their own (85.0 and 72 ms), within 5 % of the time at the steady speed
    whose lsim error is ε_max (bisection); every sample within ε_max (plus the corner
    allowance at G64 vertices) independently."""
    machine = load_machine(LINUXCNC_LIMITS)
    eps_mm = machine.limits.contour_tolerance_mm
    run, err_mm = _arc_program_check(PROGRAMS / name, machine)
    assert err_mm <= eps_mm + 1e-6
    v_xy = _steady_speed_mm_s(machine, radius_mm, eps_mm)
    assert v_xy_range[0] < v_xy < v_xy_range[1]
    half_xy_mm = np.pi * radius_mm
    half_mm = float(np.hypot(half_xy_mm, DROP_MM))
    v_best = v_xy * half_mm / half_xy_mm  # along the helix
    # The 2nd to the 16th half-turn (the 1st starts from a stop, the 17th ends the program).
    times = [_line_time_s(run, line) for line in middle]
    assert max(times) <= half_mm / (0.95 * v_best)


def _overs(err_mm: np.ndarray, pieces: np.ndarray) -> Overs:
    """Over-limit samples 0, 10, 20, … on the given pieces (one sample per run)."""
    n = err_mm.size
    return Overs(
        count=10 * n,
        index=np.arange(n) * 10,
        err_mm=np.asarray(err_mm, float),
        tau_s=np.arange(n) * 0.01,
        run_piece=np.asarray(pieces),
        run_start=np.arange(n) * 10,
        restart_count=np.zeros(0, dtype=np.int64),
        worst_mm=float(np.max(err_mm)),
    )


def test_joined_arcs_share_only_alike_blames():
    """Three joined arcs blamed 21.6, 19.4 and 19.0 µm (no earlier sample in the window):
    the two alike (within SHARE_RATIO) share 19.4, the first keeps 21.6; the cells of one
    curve (no junction between two curves) share 21.6; not joined, each keeps its own."""
    ov = _overs(np.array([21.6e-3, 19.4e-3, 19.0e-3]), np.array([0, 1, 2]))
    sel = np.ones(3, bool)
    joined = np.array([True, True])
    blame = shaping._blame(ov, sel, 15e-3, joined, 0, np.array([True, True]))
    np.testing.assert_allclose(blame, [21.6e-3, 19.4e-3, 19.4e-3], rtol=0, atol=1e-15)
    blame = shaping._blame(ov, sel, 15e-3, joined, 0, np.array([False, False]))
    np.testing.assert_allclose(blame, [21.6e-3, 21.6e-3, 21.6e-3], rtol=0, atol=1e-15)
    blame = shaping._blame(ov, sel, 15e-3, np.array([False, False]), 0)
    np.testing.assert_allclose(blame, [21.6e-3, 19.4e-3, 19.0e-3], rtol=0, atol=1e-15)
