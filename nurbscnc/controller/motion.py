"""Motion for the stream controller: play a plan at a feed override, stop it, re-plan the rest.

Pure numpy, no I/O and no clock. A :class:`Motion` is a jerk-limited profile over the pieces
of a plan from some path length on: the whole plan, or the rest of it re-planned from rest
after a feed hold (:func:`resume_motion`, the same planner: :func:`profile_over` over the
remaining pieces with the plan's final caps). :func:`play` turns a motion into servo periods
at a feed override, :func:`stop_phases` gives the shortest jerk-limited stop from a moving
state.

Feed override as time scaling (decision, docs/protocol.md "The controller"). With the profile
``s(τ)`` in profile time τ and the override ``r(u)`` as a function of motion time ``u`` (wall
time without dwells), the machine follows ``s(τ(u))`` with ``dτ/du = r``::

    v = s'·r        a = s''·r² + s'·ṙ        j = s'''·r³ + 3·s''·r·ṙ + s'·r̈

A constant ``r ≤ 1`` keeps ``v·r, a·r², j·r³`` within the limits the plan respected. A change
of ``r`` is a quintic ramp (smootherstep: ``ṙ`` and ``r̈`` continuous, so the jerk stays
bounded); whether a ramp keeps ``|a| ≤ A`` and ``|j| ≤ J`` depends on where it lies (during a
full acceleration ``s''·r²`` leaves no room), so the controller searches the earliest ramp
that does, checking these formulas on every period of it (:func:`ramp_fits`). Dwells do not
scale (a G4 of 2 s lasts 2 s at any override, as in LinuxCNC).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nurbscnc.plan.junctions import junction_caps
from nurbscnc.plan.plans import profile_over
from nurbscnc.plan.profile import Profile, time_at_length
from nurbscnc.plan.timing import dwell_times, wall_to_profile_time

#: Relative slack of the limit checks (rounding of the closed forms).
LIMIT_SLACK = 1e-6


# -- the override law ----------------------------------------------------------------------
@dataclass(frozen=True)
class Rate:
    """The feed override ``r(u)`` over motion time ``u`` [s]: ``r0`` until ``u_a``, a quintic
    ramp (6x⁵ − 15x⁴ + 10x³) to ``r1`` over ``d_s``, then ``r1``. ``F(u) = ∫₀ᵘ r`` is the
    profile time advanced by motion time ``u``."""

    r0: float
    r1: float | None = None
    u_a: float = 0.0
    d_s: float = 0.0

    @property
    def ramping(self) -> bool:
        return self.r1 is not None and self.d_s > 0.0

    @property
    def end_u(self) -> float:
        return self.u_a + self.d_s if self.ramping else 0.0

    @property
    def final(self) -> float:
        return self.r1 if self.ramping else self.r0

    def _x(self, u):
        return np.clip((np.asarray(u, dtype=float) - self.u_a) / self.d_s, 0.0, 1.0)

    def r(self, u) -> np.ndarray:
        u = np.asarray(u, dtype=float)
        if not self.ramping:
            return np.full(u.shape, self.r0)
        x = self._x(u)
        return self.r0 + (self.r1 - self.r0) * x**3 * (10.0 + x * (-15.0 + 6.0 * x))

    def dr(self, u) -> np.ndarray:
        """ṙ [1/s]."""
        u = np.asarray(u, dtype=float)
        if not self.ramping:
            return np.zeros(u.shape)
        x = self._x(u)
        return (self.r1 - self.r0) / self.d_s * 30.0 * x**2 * (1.0 - x) ** 2

    def ddr(self, u) -> np.ndarray:
        """r̈ [1/s²]."""
        u = np.asarray(u, dtype=float)
        if not self.ramping:
            return np.zeros(u.shape)
        x = self._x(u)
        inside = (x > 0.0) & (x < 1.0)
        return np.where(
            inside, (self.r1 - self.r0) / self.d_s**2 * 60.0 * x * (1.0 - x) * (1.0 - 2.0 * x), 0.0
        )

    def integral(self, u) -> np.ndarray:
        """F(u) = ∫₀ᵘ r du [s of profile time]."""
        u = np.asarray(u, dtype=float)
        if not self.ramping:
            return self.r0 * u
        x = self._x(u)
        # ∫ (6x⁵ − 15x⁴ + 10x³) dx = x⁶ − 3x⁵ + 2.5x⁴; after the ramp r1 (the ramp's ∫ is ½).
        ramp = x**4 * (2.5 + x * (-3.0 + x))
        past = np.maximum(np.asarray(u) - self.end_u, 0.0)
        return self.r0 * u + (self.r1 - self.r0) * (self.d_s * ramp + past)

    def inverse(self, tau) -> np.ndarray:
        """u with F(u) = ``tau`` (F is increasing: r > 0); bisection inside the ramp."""
        tau = np.atleast_1d(np.asarray(tau, dtype=float))
        if not self.ramping:
            return tau / self.r0
        lo = np.zeros_like(tau)
        hi = np.maximum(tau / min(self.r0, self.r1), 0.0) + 1e-12
        for _ in range(80):
            mid = 0.5 * (lo + hi)
            below = self.integral(mid) < tau
            lo = np.where(below, mid, lo)
            hi = np.where(below, hi, mid)
        return hi


# -- motions ------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Motion:
    """A profile over ``pieces[first:]`` starting at path length ``s0_mm`` (global) at rest.

    ``piece_start_mm`` (k,) global piece starts of the whole plan; ``dwell_at_s`` /
    ``dwell_s`` the dwells in the profile's own time [s]; ``wait_s`` a dwell still to finish at
    the start (a hold inside a G4).
    """

    pieces: object
    piece_start_mm: np.ndarray
    profile: Profile
    first: int
    s0_mm: float
    dwell_at_s: np.ndarray
    dwell_s: np.ndarray
    wait_s: float = 0.0

    @property
    def duration_s(self) -> float:
        return float(self.profile.duration_s)

    @property
    def end_mm(self) -> float:
        return self.s0_mm + float(self.profile.total_length_mm)

    def state(self, tau_s):
        """(s [mm] global, v [mm/s], a [mm/s²], j [mm/s³], piece global) at profile times."""
        s, v, a, j, piece = self.profile.sample(tau_s)
        return s + self.s0_mm, v, a, j, piece + self.first

    def points(self, s_mm, piece) -> np.ndarray:
        """Points (n, 3) [mm] at global path lengths on global pieces."""
        return self.pieces.path.place(self.piece_start_mm, s_mm, piece)[0]

    def piece_at(self, s_mm) -> np.ndarray:
        """The piece holding global path length ``s_mm`` (the later one at a boundary)."""
        k = self.piece_start_mm.size
        return np.clip(np.searchsorted(self.piece_start_mm, s_mm, side="right") - 1, 0, k - 1)

    def time_of(self, s_mm) -> np.ndarray:
        """Profile times [s] at which the motion reaches global path lengths ``s_mm``."""
        s = np.atleast_1d(np.asarray(s_mm, dtype=float))
        return time_at_length(self.profile, s - self.s0_mm)


def plan_motion(plan) -> Motion:
    """The whole :class:`~nurbscnc.plan.lookahead.Plan` as a motion."""
    at, d = dwell_times(plan.pieces.dwell_after_s, plan.profile)
    return Motion(plan.pieces, plan.profile.piece_start_mm, plan.profile, 0, 0.0, at, d)


def resume_motion(
    plan,
    s_mm: float,
    wait_s: float = 0.0,
    lookahead_pieces: int | None = None,
    caps_mm_s: np.ndarray | None = None,
) -> Motion | None:
    """The rest of ``plan`` from global path length ``s_mm``, planned from rest (SPEC §7: the
    planner's own :func:`~nurbscnc.plan.plans.profile_over` over the remaining pieces,
    with the plan's final caps — or ``caps_mm_s`` (k,), a feed override's raised caps — and
    per-piece limits); None when nothing is left to move."""
    pieces = plan.pieces
    starts = np.asarray(plan.profile.piece_start_mm, dtype=float)
    length = np.asarray(pieces.length_mm, dtype=float)
    k = starts.size
    i0 = int(np.clip(np.searchsorted(starts, s_mm, side="right") - 1, 0, k - 1))
    if s_mm >= starts[i0] + length[i0] and i0 + 1 < k:
        i0 += 1
    left = length[i0:].copy()
    left[0] = max(0.0, starts[i0] + length[i0] - s_mm)
    if left.sum() <= 1e-12 and not np.any(pieces.dwell_after_s[i0:] > 0.0) and wait_s <= 0.0:
        return None
    # The plan's own profile over the rest (its final caps and per-piece limits, so the
    # dynamics check's shaping and the axes' limits still hold), from rest at s_mm.
    smooth = junction_caps(pieces)[i0:].copy()  # > 0 where the path is tangent-continuous
    smooth[0] = 0.0
    caps = plan.caps_mm_s if caps_mm_s is None else caps_mm_s
    profile = profile_over(
        left,
        np.asarray(caps, dtype=float)[i0:],
        smooth,
        plan.limits.tail(i0),
        lookahead_pieces,
    )
    at, d = dwell_times(pieces.dwell_after_s[i0:], profile)
    # The profile's s counts from s_mm; its piece i is the plan's piece i0 + i.
    return Motion(pieces, starts, profile, i0, float(s_mm), at, d, wait_s)


# -- playing a motion ----------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Track:
    """Servo periods of a motion: per sample k (0 = the start) profile time ``tau_s``, motion
    time ``u_s``, global path length ``s_mm``, real speed ``v_mm_s``, acceleration ``a_mm_s2``
    and jerk ``j_mm_s3`` (override applied), ``piece`` and ``points_mm`` (n, 3)."""

    tau_s: np.ndarray
    u_s: np.ndarray
    s_mm: np.ndarray
    v_mm_s: np.ndarray
    a_mm_s2: np.ndarray
    j_mm_s3: np.ndarray
    piece: np.ndarray
    points_mm: np.ndarray

    def __len__(self) -> int:
        return int(self.s_mm.size)

    def head(self, n: int) -> Track:
        return Track(*(getattr(self, f)[:n] for f in self.__dataclass_fields__))

    def then(self, other: Track) -> Track:
        """This track's samples, then ``other``'s from its second (its first is this one's
        last: the same point); ``other``'s motion time counts on from this one's."""
        u0 = self.u_s[-1] if len(self) else 0.0
        return Track(
            *(
                np.concatenate(
                    [getattr(self, f), getattr(other, f)[1:] + (u0 if f == "u_s" else 0)]
                )
                for f in self.__dataclass_fields__
            )
        )


def play(
    motion: Motion,
    tau_a: float,
    tau_b: float,
    rate: Rate,
    period_s: float,
    wait_s: float = 0.0,
    dwell_at_start: bool = False,
    u0: float = 0.0,
    max_samples: int | None = None,
) -> tuple[Track, bool]:
    """Servo periods from profile time ``tau_a`` (sample 0) until the motion reaches
    ``tau_b`` at rest (the last sample, clamped there) at the override ``rate``, whose motion
    time is ``u0`` at sample 0. ``wait_s``: a dwell at the start; dwells inside
    (tau_a, tau_b] are held for their full length (at ``tau_a`` too with ``dwell_at_start``).

    ``max_samples``: stop after that many samples (a chunk; the next one continues from the
    last sample). Returns the track (its ``u_s`` from 0) and whether it reached ``tau_b``.
    """
    lo = (motion.dwell_at_s >= tau_a) if dwell_at_start else (motion.dwell_at_s > tau_a)
    sel = lo & (motion.dwell_at_s <= tau_b)
    f0 = float(rate.integral(u0))
    d_len = motion.dwell_s[sel]
    d_u = rate.inverse(f0 + motion.dwell_at_s[sel] - tau_a) - u0 if sel.any() else d_len * 0
    if wait_s > 0.0:
        d_u = np.concatenate(([0.0], d_u))
        d_len = np.concatenate(([wait_s], d_len))
    u_end = float(rate.inverse(f0 + max(tau_b - tau_a, 0.0))[0]) - u0
    total = u_end + float(d_len.sum())
    n = int(math.ceil(total / period_s - 1e-9)) + 1
    complete = max_samples is None or n <= max_samples
    n = n if complete else max_samples
    t = np.arange(n) * period_s
    u = np.minimum(wall_to_profile_time(t, d_u, d_len), u_end)
    tau = np.minimum(tau_a + (rate.integral(u0 + u) - f0), tau_b)
    tau[0] = tau_a
    if complete:
        tau[-1] = tau_b
        u[-1] = u_end
    s, v, a, j, piece = motion.state(tau)
    r, dr, ddr = rate.r(u0 + u), rate.dr(u0 + u), rate.ddr(u0 + u)
    # Inside a dwell the motion stands: s', s'', s''' are 0 there anyway.
    track = Track(
        tau,
        u,
        s,
        v * r,
        a * r * r + v * dr,
        j * r**3 + 3.0 * a * r * dr + v * ddr,
        piece,
        motion.points(s, piece),
    )
    return track, complete


def ramp_fits(track: Track, a_max: float, j_max: float) -> bool:
    """Every sample within |a| ≤ A and |j| ≤ J (the closed forms of the module docstring)."""
    return bool(
        np.all(np.abs(track.a_mm_s2) <= a_max * (1 + LIMIT_SLACK) + 1e-9)
        and np.all(np.abs(track.j_mm_s3) <= j_max * (1 + LIMIT_SLACK) + 1e-9)
    )


def ramp_duration_s(delta_r: float, v_max: float, a_max: float, j_max: float) -> float:
    """The shortest quintic ramp of ``delta_r`` whose own terms fit the limits at cruise:
    v·|ṙ| ≤ A with max |ṙ| = 1.875·|Δr|/D, and v·|r̈| ≤ J with max |r̈| = (10/√3)·|Δr|/D²."""
    dr = abs(delta_r)
    return max(
        1.875 * dr * v_max / a_max, math.sqrt(10.0 / math.sqrt(3.0) * dr * v_max / j_max), 1e-3
    )


# -- stopping ------------------------------------------------------------------------------------
def stop_phases(v0: float, a0: float, a_max: float, j_max: float) -> list[tuple[float, float]]:
    """The shortest stop from speed ``v0`` [mm/s] and acceleration ``a0`` [mm/s²] within
    |a| ≤ A, |j| ≤ J, as phases (duration [s], jerk [mm/s³]).

    Jerk −J until the acceleration reaches a_min, hold a_min (= −A when reached), then jerk +J
    back to 0 exactly when v = 0. Without the hold: v0 + (a0² − a_min²)/(2J) − a_min²/(2J) = 0,
    so a_min = −√(J·v0 + a0²/2); if that is below −A the hold at −A lasts
    (v0 + a0²/(2J) − A²/J)/A. A state already braking harder than that (a0 < 0 and
    J·v0 < a0²/2: the plan itself is stopping) ends with a gentler jerk a0²/(2·v0) ≤ J.
    """
    v0 = max(float(v0), 0.0)
    a0 = float(np.clip(a0, -a_max, a_max))
    if v0 <= 0.0 and a0 >= 0.0:
        return []
    if a0 < 0.0 and j_max * v0 <= 0.5 * a0 * a0:
        if v0 <= 0.0:
            return []
        j = a0 * a0 / (2.0 * v0)
        return [(-a0 / j, j)]
    a_min = -math.sqrt(j_max * v0 + 0.5 * a0 * a0)
    hold = 0.0
    if a_min < -a_max:
        a_min = -a_max
        hold = (v0 + a0 * a0 / (2.0 * j_max) - a_max * a_max / j_max) / a_max
    return [((a0 - a_min) / j_max, -j_max), (max(hold, 0.0), 0.0), (-a_min / j_max, j_max)]


def phase_states(s0: float, v0: float, a0: float, phases, t_s: np.ndarray):
    """(s, v, a) at times ``t_s`` [s] of constant-jerk ``phases`` from (s0, v0, a0); held
    at rest after the last phase."""
    starts, s_, v_, a_, jerks = [0.0], [s0], [v0], [a0], []
    for dur, jerk in phases:
        s, v, a = s_[-1], v_[-1], a_[-1]
        s_.append(s + dur * (v + dur * (0.5 * a + dur * jerk / 6.0)))
        v_.append(v + dur * (a + 0.5 * dur * jerk))
        a_.append(a + dur * jerk)
        starts.append(starts[-1] + dur)
        jerks.append(jerk)
    jerks.append(0.0)
    t = np.asarray(t_s, dtype=float)
    i = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(starts) - 1)
    tau = t - np.take(starts, i)
    s0a, v0a, a0a = np.take(s_, i), np.take(v_, i), np.take(a_, i)
    ja = np.take(jerks, i)
    last = i == len(starts) - 1  # after the stop: at rest
    v0a = np.where(last, 0.0, v0a)
    a0a = np.where(last, 0.0, a0a)
    s = s0a + tau * (v0a + tau * (0.5 * a0a + tau * ja / 6.0))
    v = v0a + tau * (a0a + 0.5 * tau * ja)
    a = a0a + tau * ja
    return s, np.maximum(v, 0.0), a, ja


def stop_track(
    motion: Motion,
    track: Track,
    k: int,
    a_max: float,
    j_max: float,
    period_s: float,
    s_limit_mm: float,
) -> Track:
    """The shortest jerk-limited stop along the path from sample ``k`` of ``track`` (its
    first sample is sample ``k``), held at most at ``s_limit_mm`` (the next stop)."""
    phases = stop_phases(float(track.v_mm_s[k]), float(track.a_mm_s2[k]), a_max, j_max)
    total = sum(d for d, _ in phases)
    n = int(math.ceil(total / period_s - 1e-9)) + 1
    t = np.arange(n) * period_s
    t[-1] = max(total, 0.0) if n > 1 else 0.0
    s, v, a, j = phase_states(
        float(track.s_mm[k]), float(track.v_mm_s[k]), float(track.a_mm_s2[k]), phases, t
    )
    s = np.minimum(s, s_limit_mm)
    s[-1] = min(s[-1], s_limit_mm)
    v[-1] = a[-1] = 0.0
    piece = motion.piece_at(s)
    piece[0] = track.piece[k]
    points = motion.points(s, piece)
    points[0] = track.points_mm[k]
    return Track(np.full(n, track.tau_s[k]), np.zeros(n), s, v, a, j, piece, points)
