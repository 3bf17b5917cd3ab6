"""Rotary axes A B C in the planner: trivial kinematics, each an independent joint.

A move with X Y Z motion carries A B C linearly along its XYZ arc length (LinuxCNC's
STRAIGHT_FEED / ARC_FEED): on every piece of such a move A(s) = A₀ + (dA/ds)·s, so the axis's
velocity, acceleration and jerk are (dA/ds)·v, (dA/ds)·a and (dA/ds)·j exactly (A is linear
in s: no curvature term). The per-axis path limits follow (:func:`rotary_limits`, the same
rule as a line's direction cosines, :func:`nurbscnc.machine.caps.rotary_path_limits`).

Where some axis's rate dA/ds changes from one piece to the next the tool comes to rest (the
velocity of A would otherwise jump): :func:`rate_changes` marks those junctions as stops
before the corners are decided; pieces on which A B C move are never blended (a blend would
trim the move, and A would no longer end where it is programmed to).

A :class:`~nurbscnc.geometry.segments.Rotate` (a move of A B C alone) is a stop: X Y Z rest
while A B C make one jerk-limited rest-to-rest move along √(ΔA² + ΔB² + ΔC²), planned by the
planner's own profile (:func:`~nurbscnc.plan.profile_plan.plan_profile`, one piece per move,
at rest at both ends: the S-curve closed forms of SPEC §7), each axis within its own limits
scaled by its share |ΔA|/√(ΔA² + ΔB² + ΔC²), the cruise at most the programmed rate (G0: the
axes' own maxima). Its duration enters the servo clock as a dwell does
(``dwell_after_s``): :func:`nurbscnc.plan.timing.rotary_positions` places A B C on every
sample, inside the holds too.

Units: degrees, seconds; a hold's "path" is degrees along the move.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from itertools import repeat
from operator import attrgetter

import numpy as np

from nurbscnc.errors import PlanningError, SourcePos
from nurbscnc.machine.caps import rotary_path_limits
from nurbscnc.plan.profile import Profile, ProfileInput
from nurbscnc.program.columns import ARC, DWELL, RAPID, ROTATE

#: The rotary axes, in column order.
AXES = ("a", "b", "c")
#: Rates dA/ds [deg/mm] that differ by less than this relative amount are the same rate (the
#: quotients ΔA/L of two moves with one ratio may differ in their last bits).
SAME_RATE = 1e-9


def moves_rotary(segment) -> bool:
    """Does a Line or Arc move A, B or C along it (a Rotate always does)?"""
    if segment.kind == "rotate":
        return True
    abc = getattr(segment, "abc_deg", None)
    return abc is not None and tuple(abc[:3]) != tuple(abc[3:])


def uses_rotary(segments) -> bool:
    """Does any segment carry rotary positions (a Line or Arc with ``abc_deg``, a Rotate)?
    A program without them is planned exactly as before (no rotary columns)."""
    # C-level passes (CAM programs hold millions of lines): the kinds by type, then any
    # rotary position (a tuple; None is false).
    if any(getattr(t, "kind", None) == "rotate" for t in set(map(type, segments))):
        return True
    return any(map(getattr, segments, repeat("abc_deg"), repeat(None)))


def row_rates(segment_of_row, length_mm, abc0, abc1) -> tuple[np.ndarray, np.ndarray]:
    """Per piece row (k,): A B C at its start [deg] (k, 3) and their rates dA/ds [deg/mm]
    (k, 3), from the program's segment of each row (``segment_of_row``, non-decreasing) and
    the rows' lengths [mm]: each segment's change spread linearly over the total length of
    its rows, so its last row ends exactly at its programmed end."""
    seg = np.asarray(segment_of_row, dtype=np.int64)
    length = np.asarray(length_mm, dtype=float)
    n = abc0.shape[0]
    seg_len = np.bincount(seg, weights=length, minlength=n)
    with np.errstate(divide="ignore", invalid="ignore"):
        rate_seg = np.where(seg_len[:, None] > 0.0, (abc1 - abc0) / seg_len[:, None], 0.0)
    before = np.cumsum(length) - length  # path length before each row
    first = np.searchsorted(seg, seg, side="left")  # the segment's first row
    offset = before - before[first]
    rate = rate_seg[seg]
    return abc0[seg] + rate * offset[:, None], rate


def different_rates(rate: np.ndarray) -> np.ndarray:
    """Junctions (k − 1) between rows whose rates (k, 3) [deg/mm] differ (:data:`SAME_RATE`),
    per axis (k − 1, 3)."""
    scale = np.maximum(np.abs(rate[:-1]), np.abs(rate[1:]))
    return np.abs(rate[1:] - rate[:-1]) > SAME_RATE * scale


def rate_changes(cols: dict, segments, abc) -> None:
    """Mark, in the piece columns ``cols`` (rows before the corners are decided; ``segment``
    the program's indices), every junction where some axis's rate changes as a stop
    (``stop_after``), and forbid blends on the rows where A B C move (``blend_mm`` at most
    0: G61's exact path; a G61.1 row keeps its own). ``abc``: the segments' A B C at start
    and end (:func:`~nurbscnc.program.columns.segment_abc_deg`)."""
    _, rate = row_rates(cols["segment"], cols["length_mm"], *abc)
    if rate.shape[0] >= 2:
        cols["stop_after"][:-1] |= different_rates(rate).any(axis=1)
    moving = np.any(rate != 0.0, axis=1)
    cols["blend_mm"][moving] = np.minimum(cols["blend_mm"][moving], 0.0)


@dataclass(frozen=True, eq=False)
class Holds:
    """The Rotate moves of a program, (m,) each in program order: ``segment`` their program
    indices, ``line`` source lines, ``abc0_deg`` / ``abc1_deg`` (m, 3) start and end [deg],
    ``duration_s`` their planned times [s], ``profile`` the planned rest-to-rest moves (one
    piece a move, in degrees along it; None when there is none), ``piece`` (m,) each move's
    piece of it, and ``axis`` (m,) the index into :data:`AXES` of the axis whose limits set
    each move's cruise (-1: the programmed rate)."""

    segment: np.ndarray
    line: np.ndarray
    abc0_deg: np.ndarray
    abc1_deg: np.ndarray
    duration_s: np.ndarray
    profile: Profile | None
    piece: np.ndarray
    axis: np.ndarray

    def subset(self, keep: np.ndarray) -> Holds:
        """The moves ``keep`` (a mask), each keeping its piece of the profile."""
        cols = ("segment", "line", "abc0_deg", "abc1_deg", "duration_s", "piece", "axis")
        return replace(self, **{f: getattr(self, f)[keep] for f in cols})

    def at(self, h: np.ndarray, u_s: np.ndarray) -> np.ndarray:
        """A B C [deg] (N, 3) of holds ``h`` (N,) at times ``u_s`` (N,) [s] from their starts
        (clipped to the move: at rest before and after it)."""
        u = np.clip(u_s, 0.0, self.duration_s[h])
        p, piece = self.profile, self.piece[h]
        along = p.sample(p.piece_start_time_s[piece] + u)[0] - p.piece_start_mm[piece]
        d = self.abc1_deg[h] - self.abc0_deg[h]
        total = np.sqrt(np.einsum("ij,ij->i", d, d))
        frac = np.clip(along / np.where(total > 0.0, total, 1.0), 0.0, 1.0)
        frac = np.where(u >= self.duration_s[h], 1.0, frac)
        return self.abc0_deg[h] + d * frac[:, None]


def machine_limits(machine) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The machine's rotary limits (3,) each, in :data:`AXES` order: V [deg/s], A [deg/s²],
    J [deg/s³]; inf for an axis the machine lacks."""
    return tuple(
        np.array([getattr(machine.rotary_axes.get(n), f, np.inf) for n in AXES]) for f in _LIMITS
    )


def rotate_shares(cols, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Of the rotary-only moves at rows ``idx`` of the segment columns ``cols``: their turn
    ΔA ΔB ΔC (m, 3) [deg], length L = √(ΔA² + ΔB² + ΔC²) (m,) [deg] and each axis's share
    |ΔA_i| / L (m, 3) (0 for a move of no length)."""
    d = cols.abc_end_deg[idx] - cols.abc_start_deg[idx]
    length = np.sqrt(np.einsum("ij,ij->i", d, d))
    return d, length, np.abs(d) / np.where(length > 0.0, length, 1.0)[:, None]


def _axis_arrays(machine, used: np.ndarray, lines: np.ndarray):
    """:func:`machine_limits`; PlanningError at the first of the moves ``used`` (m, 3)
    (which axes each turns; ``lines`` (m,) their source lines) that turns an axis the
    machine lacks."""
    for i, name in enumerate(AXES):
        if name not in machine.rotary_axes and used[:, i].any():
            r = int(np.argmax(used[:, i]))
            raise PlanningError(
                f"the machine has no {name.upper()} axis (no [axis_limits.{name}] in its "
                "profile); this move turns it",
                SourcePos(int(lines[r]), 1, ""),
            )
    return machine_limits(machine)


def plan_holds(segments, machine, cols) -> Holds:
    """The Rotate moves of ``segments`` planned (module doc): per move the share
    |ΔA_i| / L of each axis (L = √(ΔA² + ΔB² + ΔC²)), the path limits
    :func:`~nurbscnc.machine.caps.rotary_path_limits` of those shares, the cruise at most
    ``feed_deg_s`` (G0: the axes' limits alone), one rest-to-rest profile per move.
    ``cols``: the segments' :class:`~nurbscnc.program.columns.SegmentColumns`."""
    from nurbscnc.plan.profile_plan import plan_profile

    idx = cols.rows(ROTATE).astype(np.int64)
    m = idx.size
    rot = [segments[i] for i in idx.tolist()]
    line = np.array([s.line for s in rot], dtype=np.int64)
    abc0, abc1 = cols.abc_start_deg[idx], cols.abc_end_deg[idx]
    if m == 0:
        z = np.zeros(0)
        return Holds(idx, line, abc0, abc1, z, None, idx, z.astype(np.int64))
    _, length, share = rotate_shares(cols, idx)
    v_i, a_i, j_i = _axis_arrays(machine, share > 0.0, line)
    v, a, j, axis = rotary_path_limits(share, v_i, a_i, j_i)
    feed = np.array([0.0 if s.rapid else float(s.feed_deg_s) for s in rot])
    bad = ~np.array([s.rapid for s in rot]) & ~(feed > 0.0) & (length > 0.0)
    if bad.any():
        r = int(np.argmax(bad))
        raise PlanningError("a rotary move with no feed rate", SourcePos(int(line[r]), 1, ""))
    programmed = (feed > 0.0) & (feed < v)
    v = np.where(programmed, feed, v)
    axis = np.where(programmed, -1, axis)
    # A move of no length (or of no limited axis) still needs finite positive limits.
    still = (length <= 0.0) | ~np.isfinite(v)
    v, a, j = (np.where(still | ~np.isfinite(x), 1.0, x) for x in (v, a, j))
    profile = plan_profile(ProfileInput(length, v, np.zeros(m + 1), a, j))
    duration = np.where(length > 0.0, profile.piece_duration_s, 0.0)
    return Holds(idx, line, abc0, abc1, duration, profile, np.arange(m), axis.astype(np.int64))


@dataclass(frozen=True, eq=False)
class RotaryPieces:
    """The rotary axes on a :class:`~nurbscnc.plan.pieces.PieceList`: ``axes`` the ones the
    program uses (a subset of :data:`AXES`); per row (k, 3) ``abc_start_deg`` A B C at the
    row's start [deg] and ``rate_deg_mm`` dA/ds [deg/mm] (linear along the row); the holds
    (:class:`Holds`) with ``hold_row`` (m,) the row each follows and ``hold_back_s`` (m,)
    the programmed stop time after it up to that row's end of stops [s] (a settle the
    planner adds comes first); ``end_abc_deg`` (3,) where the program leaves A B C."""

    axes: tuple
    abc_start_deg: np.ndarray
    rate_deg_mm: np.ndarray
    holds: Holds
    hold_row: np.ndarray
    hold_back_s: np.ndarray
    end_abc_deg: np.ndarray


def rotary_pieces(
    pieces, segments, cols, holds: Holds, marker: bool, axes: tuple | None = None
) -> RotaryPieces:
    """The :class:`RotaryPieces` of the final ``pieces`` (rows after blending; ``segment``
    the program's indices) of ``segments``; ``cols``: their
    :class:`~nurbscnc.program.columns.SegmentColumns` (kinds, A B C). ``marker``: row 0
    is the zero-length row that carries the stops before the first move (their holds are
    its own; without one, the moves before the first piece take no time and are left out).
    ``axes``: the program's :attr:`~nurbscnc.geometry.segments.Program.rotary_axes` (None:
    the axes whose position is ever away from 0, the same rule, for segments alone)."""
    abc = (cols.abc_start_deg, cols.abc_end_deg)
    start, rate = row_rates(pieces.segment, pieces.length_mm, *abc)
    k = len(pieces)
    seg = np.asarray(pieces.segment, dtype=np.int64)
    row = np.searchsorted(seg, holds.segment, side="left") - 1
    if marker:
        row = np.maximum(row, 0)
        first = np.flatnonzero(row == 0)
        if first.size:  # the marker holds A B C where the first of its moves starts
            start[0], rate[0] = holds.abc0_deg[first[0]], 0.0
    holds, row = holds.subset(row >= 0), row[row >= 0]
    # Programmed stop time after each hold up to the next piece's segment.
    stop_s = np.zeros(len(segments))
    dwells = cols.rows(DWELL)
    stop_s[dwells] = np.fromiter(
        map(attrgetter("seconds"), map(segments.__getitem__, dwells.tolist())),
        dtype=float,
        count=dwells.size,
    )
    stop_s[holds.segment] = holds.duration_s
    cum = np.cumsum(stop_s)
    after = np.searchsorted(seg, holds.segment, side="right")
    next_seg = np.where(after < k, seg[np.minimum(after, k - 1)], len(segments))
    back = cum[np.maximum(next_seg - 1, 0)] - cum[holds.segment]
    if axes is None:
        used = np.any(abc[0] != 0.0, axis=0) | np.any(abc[1] != 0.0, axis=0)
        axes = tuple(name for name, u in zip(AXES, used.tolist()) if u)
    # Where the program leaves A B C: its last segment's end (the stops after the last
    # piece are this plan's too).
    end = abc[1][-1]
    return RotaryPieces(
        tuple(axes),
        start,
        rate,
        holds,
        row,
        back,
        np.asarray(end, dtype=float),
    )


def rotary_limits(pieces, machine):
    """The path limits (k,) each that keep A B C within their own limits on every piece:
    feed [mm/s], tangential acceleration [mm/s²] and jerk [mm/s³] (inf where no rotary axis
    moves), and the index into :data:`AXES` of the axis that sets the feed (-1: none).
    ``(v, a, j, axis)``, or None for a program without rotary axes."""
    rot = getattr(pieces, "rotary", None)
    if rot is None:
        return None
    share = np.abs(rot.rate_deg_mm)
    moving = np.flatnonzero(np.any(share > 0.0, axis=1))
    v_i, a_i, j_i = _axis_arrays(machine, share[moving] > 0.0, pieces.line[moving])
    return rotary_path_limits(share, v_i, a_i, j_i)


def rotary_time_bounds_s(segments, machine, cols) -> np.ndarray:
    """A lower bound [s] (n,) of every segment's time from its rotary motion: each axis's
    travel |ΔA_i| at its own velocity limit, and a rotary-only move's length at its
    programmed rate (0 where nothing turns, or the machine lacks the axis: the planner
    refuses that move). ``cols``: the segments'
    :class:`~nurbscnc.program.columns.SegmentColumns`."""
    d = np.abs(cols.abc_end_deg - cols.abc_start_deg)
    v = machine_limits(machine)[0]
    t = (d / v[None, :]).max(axis=1) if len(segments) else np.zeros(0)
    rot = cols.rows(ROTATE)
    if rot.size:
        moves = list(map(segments.__getitem__, rot.tolist()))
        feed = np.fromiter(map(attrgetter("feed_deg_s"), moves), dtype=float, count=rot.size)
        rapid = np.fromiter(map(attrgetter("rapid"), moves), dtype=bool, count=rot.size)
        fed = ~rapid & (feed > 0.0)
        length = np.sqrt(np.einsum("ij,ij->i", d[rot], d[rot]))
        t[rot[fed]] = np.maximum(t[rot[fed]], length[fed] / feed[fed])
    return t


def rotate_bounds_s(segments, machine, cols) -> np.ndarray:
    """A lower bound [s] of every rotary-only move's time (m,), without the jerk limit: rest
    to rest at the acceleration A and cruise V of its axes' shares (and its programmed rate),
    L/V + V/A when it reaches V, else 2√(L/A) — never above the planned jerk-limited move.
    ``cols``: the segments' :class:`~nurbscnc.program.columns.SegmentColumns`."""
    idx = cols.rows(ROTATE)
    if not idx.size:
        return np.zeros(0)
    rot = list(map(segments.__getitem__, idx.tolist()))
    _, length, share = rotate_shares(cols, idx)
    v, a, _, _ = rotary_path_limits(share, *machine_limits(machine))
    feed = np.array([np.inf if s.rapid else s.feed_deg_s for s in rot], dtype=float)
    v = np.minimum(v, feed)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # a tiny share: inf
        t = np.where(length >= v * v / a, length / v + v / a, 2.0 * np.sqrt(length / a))
    return np.where(length > 0.0, np.nan_to_num(t, nan=0.0, posinf=0.0), 0.0)


#: The :class:`~nurbscnc.machine.model.RotaryAxis` limits, in the order of
#: :func:`~nurbscnc.machine.caps.rotary_path_limits`.
_LIMITS = ("v_max_deg_s", "a_max_deg_s2", "j_max_deg_s3")


def rotary_feed_caps_mm_s(segments, machine, cols) -> np.ndarray:
    """Per segment (n,) the feed cap [mm/s] its rotary axes set along its XYZ path, the
    smallest V_i / |ΔA_i / L| (inf where nothing turns or there is no XYZ length).
    ``cols``: the segments' :class:`~nurbscnc.program.columns.SegmentColumns`."""
    abc0, abc1 = cols.abc_start_deg, cols.abc_end_deg
    turning = np.flatnonzero((cols.kind <= ARC) & np.any(abc0 != abc1, axis=1))
    cap = np.full(len(segments), np.inf)
    # XYZ lengths: a line's by math.dist (its ``length_mm``, without a Python frame per
    # line), an arc's its own.
    moves = list(map(segments.__getitem__, turning.tolist()))
    straight = cols.kind[turning] <= RAPID
    length = np.fromiter(
        map(math.dist, map(attrgetter("end_mm"), moves), map(attrgetter("start_mm"), moves)),
        dtype=float,
        count=turning.size,
    )
    arcs = np.flatnonzero(~straight)
    length[arcs] = [moves[i].length_mm for i in arcs.tolist()]
    moving = turning[length > 0.0]
    if moving.size:
        rate = np.abs(abc1[moving] - abc0[moving]) / length[length > 0.0, None]
        cap[moving] = rotary_path_limits(rate, *machine_limits(machine))[0]
    return cap
