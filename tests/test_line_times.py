"""bench/line_times.py: time per source line, and LinuxCNC's per-line goldens.

Not timing tests: they check the per-line cut the LinuxCNC comparison relies on
(tests/golden/linuxcnc_sim/<case>_lines.json, recorded by ``bench/line_times.py --record``
from run_linuxcnc.sh's 1 ms CSV) against hand counts and a closed form.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

import line_times  # noqa: E402
from contour import motion_span  # noqa: E402

GOLDEN = ROOT / "tests" / "golden" / "linuxcnc_sim"


def test_line_seconds_charges_each_period_to_the_line_it_ends_on():
    """Rest (3 samples), line 7 moving 4 periods, line 9 moving 2, rest: the period k → k + 1
    goes to sample k + 1's line, only within the motion span."""
    x = np.array([0, 0, 0, 1, 2, 3, 4, 5, 6, 6, 6], dtype=float)
    lines = np.array([0, 0, 0, 7, 7, 7, 7, 9, 9, 9, 9])
    pts = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    got = line_times.line_seconds(pts, lines, period_s=1e-3)
    assert got == pytest.approx({7: 4e-3, 9: 2e-3}, abs=1e-15)
    assert sum(got.values()) == pytest.approx(motion_span(pts).seconds, abs=1e-15)


@pytest.mark.parametrize("name", ["3dtest", "tort"])
def test_per_line_golden_sums_to_the_recorded_cycle_time(name):
    """The per-line golden and bench/linuxcnc_reference.json's motion span are one run."""
    golden = json.loads((GOLDEN / f"{name}_lines.json").read_text())
    total = sum(golden["seconds_by_line"].values())
    assert total == pytest.approx(golden["cycle_time_s"], abs=1e-6)
    reference = json.loads((ROOT / "bench" / "linuxcnc_reference.json").read_text())
    case = reference["cases"][name]
    assert case["program_sha256"] == golden["program_sha256"]
    assert total == pytest.approx(case["time_s"], abs=1.5e-3)


def test_3dtest_full_circle_against_its_closed_form():
    """3dtest.ngc line 6, ``g17 g02 i.5 j.5`` at F30 (inch): a full circle of radius
    0.5√2 in at 12.7 mm/s, entered and left at rest (a rapid before, a rapid after). Without a
    jerk limit it takes 2πr/v + v/a; LinuxCNC's per-axis 2450 mm/s² (the normal part v²/r =
    9 mm/s² leaves the tangent nearly all of it): 8.8910 s, within the 1 ms cut of each end."""
    golden = json.loads((GOLDEN / "3dtest_lines.json").read_text())
    radius_mm, v_mm_s = 0.5 * math.sqrt(2.0) * 25.4, 30.0 * 25.4 / 60.0
    closed = 2.0 * math.pi * radius_mm / v_mm_s + v_mm_s / 2450.0
    assert golden["seconds_by_line"]["6"] == pytest.approx(closed, abs=2e-3)
