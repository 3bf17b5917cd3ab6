"""Reference points [mm, deg] → signed pulse counts per servo period and axis (pure numpy).

A pulse-train card moves an axis by one step per pulse. The card's position after period k is
the sum of the pulses of periods 1 … k, so the pulses must be chosen such that this running sum
is the reference point rounded to whole steps, at *every* period:

    P_k = round(p_k · steps_per_mm)              (the target position in steps)
    n_k = P_k − P_{k−1}                          (pulses in period k, k = 1 … N−1)

which is the same as emitting round(target − emitted so far) each period and carrying the
rounding remainder to the next: the remainder never accumulates, so there is no drift however
long the program. ``round`` is numpy's ``rint`` (half to even), the same rule every period.
A rotary axis is quantised alike with its steps per degree: P_k = round(a_k · steps_per_deg).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbscnc.errors import PlanningError, SourcePos


@dataclass(frozen=True, eq=False)
class PulseProgram:
    """A program as pulses: where it starts and ends [steps] and the counts of every period.

    ``pulses`` (N−1, axes) int64: period k (1-based) moves from point k−1 to point k;
    ``start_steps``/``end_steps`` (axes,) int64; ``period_s`` [s]; ``line`` (N−1,) source line
    of each period (0 when unknown); ``axes`` the axis of each column, "xyz" and then the
    rotary axes the program moves, in the order X Y Z A B C (:mod:`.axes`).
    """

    start_steps: np.ndarray
    end_steps: np.ndarray
    pulses: np.ndarray
    period_s: float
    line: np.ndarray
    axes: str = "xyz"

    @property
    def periods(self) -> int:
        """Number of periods (points − 1)."""
        return int(self.pulses.shape[0])

    @property
    def peak_pulses(self) -> int:
        """The largest |pulse count| of any period and axis (0 for an empty program)."""
        return int(np.abs(self.pulses).max()) if self.pulses.size else 0


def position_steps(points_mm, steps_per_mm) -> np.ndarray:
    """round(p · steps/mm) per point and axis (int64); ``points_mm`` (N, axes) [mm]."""
    scaled = np.asarray(points_mm, dtype=float) * np.asarray(steps_per_mm, dtype=float)
    if not np.all(np.isfinite(scaled)):
        raise PlanningError("a reference point is not a finite number")
    if np.any(np.abs(scaled) >= 2.0**31):
        raise PlanningError("a reference point is beyond ±2³¹ steps (32-bit card position)")
    return np.rint(scaled).astype(np.int64)


def pulses_per_period(points_mm, steps_per_mm) -> tuple[np.ndarray, np.ndarray]:
    """(start_steps (axes,), pulses (N−1, axes)): n_k = P_k − P_{k−1}, P = round(p · steps/mm).

    The running sum start + cumsum(pulses) equals ``position_steps`` at every period exactly
    (integer arithmetic after the one rounding per point).
    """
    steps = position_steps(np.atleast_2d(points_mm), steps_per_mm)
    return steps[0].copy(), np.diff(steps, axis=0)


def quantise(points_mm, steps_per_mm, period_s: float, line=None, axes: str = "") -> PulseProgram:
    """The :class:`PulseProgram` of reference points ``points_mm`` (N, axes) [mm; deg for a
    rotary column] at ``steps_per_mm`` (per column: steps per mm or per degree).

    ``line`` (N,) source line of each point (the period k gets the line of point k);
    ``axes`` the column names (default: the first of "xyzabc").
    """
    pts = np.atleast_2d(np.asarray(points_mm, dtype=float))
    if pts.shape[0] < 1:
        raise PlanningError("no reference points to stream")
    start, pulses = pulses_per_period(pts, steps_per_mm)
    lines = np.zeros(pts.shape[0], dtype=np.int64) if line is None else np.asarray(line)
    return PulseProgram(
        start_steps=start,
        end_steps=start + pulses.sum(axis=0),
        pulses=pulses,
        period_s=float(period_s),
        line=lines[1:].astype(np.int64),
        axes=axes or "xyzabc"[: pts.shape[1]],
    )


def check_pulse_limit(program: PulseProgram, max_pulses_per_period: int, axes: str = "") -> None:
    """PlanningError naming the first period that needs more than ``max_pulses_per_period``.

    The message gives the period, its time [s], the axis, the count and the source line; it is
    raised before anything is sent.
    """
    axes = (axes or program.axes).upper()
    over = np.abs(program.pulses) > max_pulses_per_period
    bad = np.flatnonzero(over.any(axis=1))
    if bad.size == 0:
        return
    k = int(bad[0])
    axis = int(np.flatnonzero(over[k])[0])
    count = int(program.pulses[k, axis])
    line = int(program.line[k]) if program.line.size else 0
    raise PlanningError(
        f"period {k + 1} (t = {(k + 1) * program.period_s:.4f} s) needs {count} pulses on "
        f"{axes[axis]}, more than the card's limit of {max_pulses_per_period} per period "
        f"({abs(count) / program.period_s:.6g} steps/s)",
        SourcePos(line, 1, "") if line > 0 else None,
    )
