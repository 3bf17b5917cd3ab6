"""The plan in time: dwells, the servo clock and the exact reference points (SPEC §1, §10).

A plan's profile s(τ) runs in *profile time* τ, which stands still during dwells; the servo
runs in wall-clock time t_k = k·T_s. These functions map one to the other and place the
exact reference point of every servo period on the path (through the path model,
:class:`~nurbscnc.geometry.path.PathTable`). The dynamics check uses them on every
re-plan; the interpolator (:mod:`nurbscnc.interpolate.sample`) uses the same ones, so the
check sees exactly the points the interpolator will output (with ``interpolator="exact"``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

import numpy as np

from nurbscnc.plan.profile import Profile

#: Samples per slab when the reference is built (profile evaluation and placement).
SLAB = 1 << 16


def dwell_times(dwell_after_s, profile: Profile) -> tuple[np.ndarray, np.ndarray]:
    """Profile times [s] at which dwells start and their durations [s] (sorted), from the
    ``dwell_after_s`` column (k,) of the pieces the profile plans (a dwell after the last
    piece starts at the end)."""
    dwell_after_s = np.asarray(dwell_after_s, dtype=float)
    i = np.flatnonzero(dwell_after_s > 0.0)
    k = dwell_after_s.size
    nxt = np.minimum(i + 1, k - 1)
    at = np.where(i + 1 < k, profile.piece_start_time_s[nxt], profile.duration_s)
    return at.astype(float), dwell_after_s[i]


def total_time_s(profile: Profile, dwell_durations_s: np.ndarray) -> float:
    """Cycle time [s]: the profile's duration plus all dwells."""
    return float(profile.duration_s + dwell_durations_s.sum())


def _dwell_wall_starts(dwell_at_s: np.ndarray, dwell_s: np.ndarray):
    """Wall times [s] at which the dwells begin, and the dwell time before each (offsets
    (n + 1,): 0, then the running sums of ``dwell_s``)."""
    offsets = np.concatenate(([0.0], np.cumsum(dwell_s)))
    return dwell_at_s + offsets[:-1], offsets


def wall_to_profile_time(t_wall: np.ndarray, dwell_at_s: np.ndarray, dwell_s: np.ndarray):
    """Map wall-clock times [s] to profile times [s]: during a dwell the profile time stands
    still (``dwell_at_s`` profile times at which dwells start, ``dwell_s`` their lengths)."""
    if dwell_at_s.size == 0:
        return t_wall
    wall_start, offsets = _dwell_wall_starts(dwell_at_s, dwell_s)
    j = np.searchsorted(wall_start, t_wall, side="right") - 1  # last dwell begun, or -1
    tau = t_wall.copy()
    has = j >= 0
    jj = j[has]
    inside = t_wall[has] < wall_start[jj] + dwell_s[jj]
    tau_has = np.where(inside, dwell_at_s[jj], t_wall[has] - offsets[jj + 1])
    tau[has] = tau_has
    return tau


def same_clock_until_s(old: tuple, new: tuple) -> float:
    """The wall time [s] before which two dwell schedules (``(dwell_at_s, dwell_s)`` of
    :func:`dwell_times`) map wall time to the same profile time, bit for bit
    (:func:`wall_to_profile_time` at any t below it): the earlier wall start of their first
    dwell that differs in place or length, or that one of them lacks (``inf`` when they
    are the same). Below it, both read the same dwells before t and none at or after it."""
    (at_a, s_a), (at_b, s_b) = old, new
    m = min(at_a.size, at_b.size)
    differ = (at_a[:m] != at_b[:m]) | (s_a[:m] != s_b[:m])
    first = int(np.argmax(differ)) if differ.any() else m
    t = np.inf
    for at, s in ((at_a, s_a), (at_b, s_b)):
        if first < at.size:  # its wall start, as the mapping computes it
            t = min(t, float(_dwell_wall_starts(at, s)[0][first]))
    return t


def sample_count(pieces, profile: Profile, period_s: float) -> int:
    """Number of servo periods of a plan: t_k = k·T_s for k = 0 … N−1, the last one the
    first at or after the end of motion (dwells included)."""
    _, dwell_s = dwell_times(pieces.dwell_after_s, profile)
    return int(np.ceil(total_time_s(profile, dwell_s) / period_s - 1e-9)) + 1


def servo_clock(
    pieces, profile: Profile, period_s: float, k0: int = 0, k1: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Wall times t_k = k·T_s [s] for k in [k0, k1) (default: from 0 to the first one at or
    after the end of motion, :func:`sample_count`), and the profile times τ_k [s] they map
    to (dwells held). Every pair of consecutive samples is T_s apart; the last one is at
    rest at the programmed end point."""
    dwell_at, dwell_s = dwell_times(pieces.dwell_after_s, profile)
    n = sample_count(pieces, profile, period_s)
    k1 = n if k1 is None else min(int(k1), n)
    t = np.arange(int(k0), max(int(k0), k1)) * period_s
    return t, wall_to_profile_time(t, dwell_at, dwell_s)


@dataclass(frozen=True, eq=False)
class Reference:
    """The reference points at the servo period, one row a sample: ``t_s`` (N,) wall time
    [s] = k·T_s, ``tau_s`` (N,) profile time [s], ``s_mm`` path length [mm], ``v_mm_s``
    planned feed [mm/s], ``a_mm_s2`` tangential acceleration [mm/s²], ``piece`` (N,) piece
    index, ``points_mm`` (N, 3) [mm], ``param`` (N,) each point's parameter on its piece's
    geometry (NURBS u, PH ξ, line/arc u [mm]). ``tau_s`` and ``param`` are None where no
    plan made the points (a baseline interpolator's :class:`Samples`).

    Every field is a per-sample column: the planner slices and joins references field by
    field (:func:`rows_of`)."""

    t_s: np.ndarray
    tau_s: np.ndarray | None
    s_mm: np.ndarray
    v_mm_s: np.ndarray
    a_mm_s2: np.ndarray
    piece: np.ndarray
    points_mm: np.ndarray
    param: np.ndarray | None
    #: (N, 3) the rotary axes A B C [deg] at each sample (machine coordinates), None for a
    #: program without rotary axes.
    abc_deg: np.ndarray | None = field(default=None, kw_only=True)


@dataclass(frozen=True, eq=False)
class Samples(Reference):
    """The reference points as the interpolator outputs them: a :class:`Reference` with
    ``line`` (N,) the source line of each sample's piece and ``interpolator`` the name of
    the interpolator that placed the points ("exact" or "taylor"; a baseline's are
    "exact"). The writers, the summary and the studies read these."""

    line: np.ndarray
    interpolator: str = "exact"
    #: The rotary axes the program uses (:attr:`nurbscnc.geometry.segments.Program.rotary_axes`):
    #: the columns of ``abc_deg`` the outputs write, e.g. ``("a",)``.
    rotary_axes: tuple = field(default=(), kw_only=True)


def rows_of(ref: Reference, sl: slice) -> Reference:
    """Rows ``sl`` of every per-sample column of ``ref`` (views); a column that is None and
    the ``interpolator`` name stay as they are."""
    return replace(
        ref,
        **{
            f.name: getattr(ref, f.name)[sl]
            for f in fields(ref)
            if isinstance(getattr(ref, f.name), np.ndarray)
        },
    )


def joined_rows(parts) -> Reference:
    """The rows of every reference of ``parts`` in turn, column by column; a column that is
    None in the first stays None (and the ``interpolator`` name is the first's)."""
    first = parts[0]
    return replace(
        first,
        **{
            f.name: np.concatenate([getattr(p, f.name) for p in parts])
            for f in fields(first)
            if isinstance(getattr(first, f.name), np.ndarray)
        },
    )


def exact_reference(
    pieces, profile: Profile, period_s: float, k0: int = 0, k1: int | None = None
) -> Reference:
    """Reference points at t_k = k·T_s for k in [k0, k1) (:func:`servo_clock`; default all
    of them), each exactly on the path at the profile's s(τ_k) (SPEC §10). Profile and
    placement a slab of samples at a time: flat memory, cache-friendly temporaries; the cost
    stays linear in the number of samples. A window [k0, k1) gives exactly the rows k0…k1−1
    of the whole reference (long programs are sampled window by window)."""
    t, tau = servo_clock(pieces, profile, period_s, k0, k1)
    n = t.size
    path = pieces.path
    s, v, a = np.empty(n), np.empty(n), np.empty(n)
    piece = np.empty(n, dtype=np.intp)
    points, param = np.empty((n, 3)), np.empty(n)
    for lo in range(0, n, SLAB):
        b = slice(lo, min(lo + SLAB, n))
        s[b], v[b], a[b], _, piece[b] = profile.sample(tau[b])
        points[b], param[b] = path.place(profile.piece_start_mm, s[b], piece[b])
    abc = None
    if getattr(pieces, "rotary", None) is not None:
        abc = rotary_positions(pieces, profile, t, tau, s)
    return Reference(t, tau, s, v, a, piece, points, param, abc_deg=abc)


def rotary_positions(pieces, profile: Profile, t_s, tau_s, s_mm) -> np.ndarray:
    """A B C [deg] (N, 3) at wall times ``t_s`` (profile times ``tau_s``, path lengths
    ``s_mm``) of pieces with rotary columns (:class:`~nurbscnc.plan.rotary.RotaryPieces`):
    on a piece, linear in its arc length; inside a hold (a rotary-only move), the hold's
    planned rest-to-rest move; through the rest of a stop, where the last move left them."""
    rot = pieces.rotary
    k = len(pieces)
    length = np.asarray(pieces.length_mm, dtype=float)
    # The row by profile time: at a junction the later row (a hold between two rows has
    # ended once the profile time moves on).
    i = np.searchsorted(profile.piece_start_time_s, tau_s, side="right") - 1
    np.clip(i, 0, k - 1, out=i)
    loc = np.clip(s_mm - profile.piece_start_mm[i], 0.0, length[i])
    abc = rot.abc_start_deg[i] + rot.rate_deg_mm[i] * loc[:, None]
    dwell_after = np.asarray(pieces.dwell_after_s, dtype=float)
    at, dur = dwell_times(dwell_after, profile)
    if dur.size == 0:
        return abc
    rows_d = np.flatnonzero(dwell_after > 0.0)
    wall_start, offsets = _dwell_wall_starts(at, dur)
    j = np.searchsorted(wall_start, t_s, side="right") - 1
    jj = np.maximum(j, 0)
    inside = (j >= 0) & (t_s < wall_start[jj] + dur[jj])
    ended = (j >= 0) & ~inside & (rows_d[jj] == k - 1) & (tau_s >= profile.duration_s)
    abc[ended] = rot.end_abc_deg  # after the stops that end the program
    w = np.flatnonzero(inside)
    if not w.size:
        return abc
    r = rows_d[jj[w]]
    abc[w] = rot.abc_start_deg[r] + rot.rate_deg_mm[r] * length[r][:, None]  # the row's end
    if rot.holds.duration_s.size:
        # Stop time elapsed before each sample and before each hold's start (a settle the
        # planner adds to a row's stop comes before the programmed stops).
        before = np.cumsum(dwell_after) - dwell_after
        elapsed = offsets[jj[w]] + (t_s[w] - wall_start[jj[w]])
        hr = rot.hold_row
        hold_start = before[hr] + dwell_after[hr] - rot.hold_back_s - rot.holds.duration_s
        # (a hold that starts its row's stop starts at its elapsed time, up to rounding)
        h = np.searchsorted(hold_start - 1e-9, elapsed, side="right") - 1
        mine = (h >= 0) & (hr[np.maximum(h, 0)] == r)
        abc[w[mine]] = rot.holds.at(h[mine], elapsed[mine] - hold_start[h[mine]])
    return abc
