"""The dynamics check computes the reference's direction of travel (eq. 29's tangent angle)
only for the rows whose eq. 29 it evaluates (plan/check.py ``travel_xy``), not for every
row with ``np.gradient``: the same numbers bit for bit, hence the same plans.

- ``travel_xy`` against numpy's ``np.gradient`` (an independent implementation of the
  central and one-sided differences) on random points, every size from a single row up,
  any subset of rows;
- plans and checks with ``travel_xy`` against those with every row's ``np.gradient`` (the
  check before this change) on random programs (tests/test_risk_skip.py's generator) on both
  machine profiles and on the first lines of the corpus CAM programs: every lever, profile
  time, over-limit sample and statistic equal, eq. 29's maximum included.
"""

from __future__ import annotations

import numpy as np
import pytest

from nurbscnc.plan import check as check_module
from nurbscnc.plan.check import travel_xy
from nurbscnc.plan.lookahead import plan_checked
from nurbscnc.program.interpret import interpret_text
from tests.test_risk_skip import CAM_LINES, MACHINES, _cam_programs, _program


@pytest.mark.parametrize("n", [1, 2, 3, 4, 17, 65_538])
def test_travel_xy_is_numpys_gradient_bit_for_bit(n):
    rng = np.random.default_rng(n)
    # Coordinates of a machine's size, with their rounding noise (the differences' last
    # bits are what could differ).
    points = rng.uniform(-800.0, 800.0, (n, 3)) + rng.normal(size=(n, 3)) * 1e-9
    every = np.arange(n)
    some = np.unique(rng.integers(0, n, size=max(n // 3, 1)))
    for rows in (every, some, np.array([0]), np.array([n - 1]), np.zeros(0, dtype=int)):
        got = travel_xy(points, rows)
        if n > 1:
            want = np.gradient(points[:, :2], axis=0)[rows]
        else:  # np.gradient needs two points; the check used zeros then
            want = np.zeros((rows.size, 2))
        assert got.shape == want.shape
        assert got.tobytes() == want.tobytes()


def _gradient_everywhere(points_mm, rows):
    """The check before: np.gradient of every row of the chunk, then the rows asked."""
    rows = np.asarray(rows, dtype=np.intp)
    if points_mm.shape[0] < 2:
        return np.zeros((rows.size, 2))
    return np.gradient(points_mm[:, :2], axis=0)[rows]


def _assert_same(a, b) -> None:
    (plan, chk), (ref_plan, ref_chk) = a, b
    assert plan.iterations == ref_plan.iterations
    assert plan.cycle_time_s == ref_plan.cycle_time_s
    np.testing.assert_array_equal(plan.caps_mm_s, ref_plan.caps_mm_s)
    np.testing.assert_array_equal(plan.settle_s, ref_plan.settle_s)
    for f in ("phase_start_time_s", "phase_jerk_mm_s3", "piece_start_time_s"):
        np.testing.assert_array_equal(getattr(plan.profile, f), getattr(ref_plan.profile, f))
    for f in ("count", "index", "err_mm", "tau_s", "run_piece", "run_start", "restart_count"):
        np.testing.assert_array_equal(getattr(chk.overs, f), getattr(ref_chk.overs, f), f)
    assert chk.contour_stats() == ref_chk.contour_stats()


def _both(text: str, machine, monkeypatch):
    program = interpret_text(text)
    lazy = plan_checked(program, machine, keep_reference=False)
    monkeypatch.setattr(check_module, "travel_xy", _gradient_everywhere)
    everywhere = plan_checked(program, machine, keep_reference=False)
    monkeypatch.undo()
    return lazy, everywhere


@pytest.mark.parametrize("machine", sorted(MACHINES))
def test_random_programs_plan_alike_with_lazy_directions(machine, monkeypatch):
    for seed in range(8):
        lazy, everywhere = _both(_program(seed), MACHINES[machine], monkeypatch)
        _assert_same(lazy, everywhere)
        # Not vacuous: eq. 29 was evaluated (its maximum reads the directions).
        assert lazy[1].contour_stats()["contour_eq29_max_um"] > 0.0


@pytest.mark.skipif(not _cam_programs(), reason="no corpus CAM programs (NURBSCNC_CORPUS)")
@pytest.mark.parametrize("path", _cam_programs(), ids=lambda p: p.name)
def test_corpus_cam_programs_plan_alike_with_lazy_directions(path, monkeypatch):
    text = "\n".join(path.read_text().splitlines()[:CAM_LINES]) + "\nM2\n"
    _assert_same(*_both(text, MACHINES["paper"], monkeypatch))
