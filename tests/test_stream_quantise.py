"""Pulse quantisation: the running sum of pulses is round(position · steps/mm) at every period.

The reference is Python's own round() (exact half-to-even on floats) applied point by point
to the same float product, independent of numpy's rint and of differencing.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nurbscnc.errors import PlanningError
from nurbscnc.output.stream.quantise import (
    check_pulse_limit,
    position_steps,
    pulses_per_period,
    quantise,
)


def test_hand_example():
    # 1000 steps/mm: positions 0, 0.4, 1.1, 1.9, 1.2 µm → 0, 0, 1, 2, 1 steps.
    pts = np.array([[0.0, 0, 0], [0.0004, 0, 0], [0.0011, 0, 0], [0.0019, 0, 0], [0.0012, 0, 0]])
    start, pulses = pulses_per_period(pts, (1000.0, 1000.0, 1000.0))
    assert start.tolist() == [0, 0, 0]
    assert pulses[:, 0].tolist() == [0, 1, 1, -1]
    assert not pulses[:, 1:].any()


def test_ties_round_half_to_even_every_period():
    # Exact binary ties: 0.5, 1.5, 2.5 steps → 0, 2, 2 (half to even), never drifting.
    pts = np.array([[0.0, 0, 0], [0.5, 0, 0], [1.5, 0, 0], [2.5, 0, 0], [3.5, 0, 0]])
    prog = quantise(pts, (1.0, 1.0, 1.0), 1e-3)
    assert np.cumsum(prog.pulses[:, 0]).tolist() == [0, 2, 2, 4]


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.tuples(*[st.floats(-500, 500)] * 3), min_size=1, max_size=120),
    st.tuples(*[st.floats(1.0, 5000.0)] * 3),
)
def test_running_sum_is_rounded_position(points, steps_per_mm):
    pts = np.array(points, dtype=float)
    prog = quantise(pts, steps_per_mm, 1e-3)
    running = prog.start_steps + np.vstack([np.zeros((1, 3), int), np.cumsum(prog.pulses, 0)])
    expected = [[round(float(x) * s) for x, s in zip(row, steps_per_mm)] for row in pts]
    assert running.tolist() == expected
    assert prog.end_steps.tolist() == expected[-1]
    assert prog.periods == len(points) - 1


def test_no_drift_over_a_long_program():
    # 200 000 periods of a slow sine at an awkward resolution: the sum still lands exactly.
    t = np.arange(200_000) * 1e-3
    pts = np.column_stack([7.3 * np.sin(t), 0.001 * t, np.full_like(t, 0.3333)])
    spm = (803.7, 1000.0, 333.3)
    prog = quantise(pts, spm, 1e-3)
    running = prog.start_steps + np.cumsum(prog.pulses, axis=0)
    for k in (0, 1, 12345, 99_999, 199_998):
        assert running[k].tolist() == [round(float(x) * s) for x, s in zip(pts[k + 1], spm)]


def test_pulse_limit_names_the_first_offending_period():
    pts = np.zeros((6, 3))
    pts[3:, 1] = -0.128  # period 3 jumps 128 steps backwards on Y
    lines = np.array([10, 11, 12, 13, 14, 15])
    prog = quantise(pts, (1000.0, 1000.0, 1000.0), 1e-3, lines)
    check_pulse_limit(prog, 128)  # at the limit is fine
    with pytest.raises(PlanningError, match=r"period 3 .*-128 pulses on Y.*limit of 127") as e:
        check_pulse_limit(prog, 127)
    assert e.value.pos.line == 13
    assert prog.peak_pulses == 128


def test_positions_beyond_32_bits_are_refused():
    with pytest.raises(PlanningError, match="2³¹"):
        position_steps(np.array([[3e6, 0, 0]]), (1000.0, 1000.0, 1000.0))
    with pytest.raises(PlanningError, match="finite"):
        position_steps(np.array([[np.nan, 0, 0]]), (1000.0, 1000.0, 1000.0))
