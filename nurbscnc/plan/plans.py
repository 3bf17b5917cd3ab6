"""The planner's result: the :class:`Plan` of a program, the per-piece :class:`Limits` it was
planned with, the jerk-limited profile over given levers (:func:`profile_over`), and the
times read from a plan (:func:`cycle_time_s`, :func:`segment_times_s`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbscnc.plan.options import Dynamics
from nurbscnc.plan.pieces import PieceList
from nurbscnc.plan.profile import Profile, ProfileInput
from nurbscnc.plan.profile_plan import plan_profile
from nurbscnc.plan.timing import dwell_times, total_time_s


@dataclass(frozen=True, eq=False)
class Limits:
    """Acceleration [mm/s²] and jerk [mm/s³] limits of each of k pieces, (k,) each: for the
    rise to its peak speed (``up``) and the descent from it (``down``)."""

    a_up_mm_s2: np.ndarray
    j_up_mm_s3: np.ndarray
    a_down_mm_s2: np.ndarray
    j_down_mm_s3: np.ndarray

    def tail(self, first: int) -> Limits:
        """The limits of pieces ``first`` … k − 1."""
        return Limits(
            self.a_up_mm_s2[first:],
            self.j_up_mm_s3[first:],
            self.a_down_mm_s2[first:],
            self.j_down_mm_s3[first:],
        )


@dataclass(frozen=True, eq=False)
class Plan:
    """A complete plan: pieces (with the settles in their dwells), their final caps [mm/s],
    the profile; ``iterations``: re-plans of the dynamics loop (improvement included);
    ``cycle_time_s`` including dwells; the ``dynamics`` rule it was checked with. The
    reference points come from the interpolator
    (:func:`nurbscnc.interpolate.sample.interpolate`), the check's result from
    :func:`~nurbscnc.plan.lookahead.plan_checked`."""

    pieces: PieceList
    caps_mm_s: np.ndarray
    profile: Profile
    iterations: int
    cycle_time_s: float
    dynamics: Dynamics
    #: The per-piece acceleration and jerk limits the profile was planned with (the axes'
    #: path limits, lowered where the contour check shaped a transition).
    limits: Limits | None = None
    #: (k,) bool: the contour check changed this piece (its feed cap or a limit is below
    #: the kinematic plan's) — a "contour error" limiting factor.
    shaped_by_contour: np.ndarray | None = None
    #: (k,) bool: the check lowered this piece's feed cap (curve error).
    contour_feed: np.ndarray | None = None
    #: (k,) bool: the check softened this piece's rise or descent (stop overshoot).
    contour_transition: np.ndarray | None = None
    #: (k,) settle [s] waited after piece i (a rapid followed by a cut), set by the check;
    #: included in ``pieces.dwell_after_s``.
    settle_s: np.ndarray | None = None


def profile_over(
    length_mm: np.ndarray, caps: np.ndarray, smooth: np.ndarray, limits: Limits, window: int | None
) -> Profile:
    """The jerk-limited profile (SPEC §7) over pieces of ``length_mm`` with cruise caps
    ``caps`` [mm/s], the junctions ``smooth`` (k+1; > 0: tangent-continuous, capped by it and
    the smaller neighbour; the ends are rests) and the per-piece acceleration and jerk
    ``limits``. The planner's profile, and the stream's re-plan of a plan's rest after a
    feed hold (the same pieces from one on, same caps and limits)."""
    k = caps.size
    jcaps = np.zeros(k + 1)
    jcaps[1:-1] = np.where(
        smooth[1:-1] > 0, np.minimum(np.minimum(caps[:-1], caps[1:]), smooth[1:-1]), 0.0
    )
    return plan_profile(
        ProfileInput(
            length_mm,
            caps,
            jcaps,
            limits.a_up_mm_s2,
            limits.j_up_mm_s3,
            lookahead_pieces=window,
            a_decel_mm_s2=limits.a_down_mm_s2,
            j_decel_mm_s3=limits.j_down_mm_s3,
        )
    )


def cycle_time_s(result) -> float:
    """The cycle time [s] of a planned ``result`` (planned pieces, profile, …): the
    profile's duration plus the dwells (the settles included)."""
    planned, profile = result[0], result[1]
    return total_time_s(profile, dwell_times(planned.dwell_after_s, profile)[1])


def segment_times_s(plan: Plan, key=None) -> dict:
    """Motion time [s] of each program segment (its pieces' span in the profile), keyed by
    the segment's index, or by ``key(index)`` (``str`` for the JSON summary: one dict made,
    not a second one from the first, whose pair would double the peak memory of a
    million-segment program)."""
    prof = plan.profile
    ends = np.append(prof.piece_start_time_s[1:], prof.duration_s)
    span = ends - prof.piece_start_time_s
    seg = np.asarray(plan.pieces.segment)
    sums = np.bincount(seg, weights=span)
    present = np.flatnonzero(np.bincount(seg))  # the segments that have pieces, in order
    # (lists, not numpy scalars one by one: CAM programs have 1e5 segments)
    keys = present.tolist()
    return dict(zip(keys if key is None else map(key, keys), sums[present].tolist()))
