"""The interpreted program's segments as columns (per-segment work done whole-array).

A CAM program is hundreds of thousands of Line objects; the checks before work and the
``check`` summary want their kinds, end points, feeds and source lines as arrays. Each
column is read here in one pass that runs in C (``map`` of an attribute getter into
``np.fromiter``: no Python frame per segment), once per command.
"""

from __future__ import annotations

from functools import partial
from itertools import chain, repeat
from operator import attrgetter, is_not
from typing import NamedTuple

import numpy as np

from nurbscnc.geometry.segments import Line

#: The segment kinds, in code order: ``SegmentColumns.kind`` holds indexes into this.
KINDS = ("line", "rapid", "arc", "nurbs", "dwell", "pause", "rotate")
LINE, RAPID, ARC, NURBS, DWELL, PAUSE, ROTATE = range(len(KINDS))
_KIND_NAMES = np.array(KINDS)


class SegmentColumns(NamedTuple):
    """Columns of n segments: ``kind`` (n,) int8 codes into :data:`KINDS`, ``starts_mm`` and
    ``ends_mm`` (n, 3) [mm] (a stop: its position, twice; a NURBS: its first and last
    control points), ``feeds_mm_s`` (n,) [mm/s] (0 for rapids and stops), ``lines`` (n,)
    the 1-based source lines, ``blends_mm`` (n,) the path-control code of each move
    (:func:`~nurbscnc.geometry.segments.path_control`; 0 for stops)."""

    kind: np.ndarray
    starts_mm: np.ndarray
    ends_mm: np.ndarray
    feeds_mm_s: np.ndarray
    lines: np.ndarray
    blends_mm: np.ndarray
    abc_start_deg: np.ndarray
    abc_end_deg: np.ndarray

    @property
    def names(self) -> np.ndarray:
        """The kinds as strings (n,)."""
        return _KIND_NAMES[self.kind]

    def rows(self, code: int) -> np.ndarray:
        """Indexes of the segments of kind ``code``."""
        return np.flatnonzero(self.kind == code)


def _points(segments, name: str) -> np.ndarray:
    """One (n, 3) column of points [mm]: tuples (lines, stops) and arrays (arcs, NURBS)
    flattened into one float array without a per-segment array."""
    n = len(segments)
    flat = chain.from_iterable(map(attrgetter(name), segments))
    return np.fromiter(flat, dtype=float, count=3 * n).reshape(n, 3)


def _kind_codes(segments) -> np.ndarray:
    """Kind codes (n,): by class (the kinds of Arc, Nurbs, Dwell, Pause are class
    attributes), a Line's by its ``rapid`` flag (its ``kind`` is a property)."""
    n = len(segments)
    types = list(map(type, segments))
    by_type = {}
    for cls in set(types):
        kind = getattr(cls, "kind", None)
        if not isinstance(kind, str) and cls is not Line:
            raise TypeError(f"a {cls.__name__} segment has no kind")
        by_type[cls] = KINDS.index(kind) if isinstance(kind, str) else LINE
    code = np.fromiter(map(by_type.__getitem__, types), dtype=np.int8, count=n)
    rapid = np.fromiter(map(getattr, segments, repeat("rapid"), repeat(False)), dtype=bool, count=n)
    code[rapid & (code == LINE)] = RAPID
    return code


def _rows(segments, rows: np.ndarray, name: str, width: int) -> np.ndarray:
    """The tuples ``name`` (width each) of the segments ``rows`` as one (m, width) array."""
    picked = map(getattr, map(segments.__getitem__, rows.tolist()), repeat(name))
    flat = np.fromiter(chain.from_iterable(picked), dtype=float, count=width * rows.size)
    return flat.reshape(rows.size, width)


def segment_abc_deg(segments, start_abc_deg=(0.0, 0.0, 0.0), kind=None):
    """A B C [deg, machine coordinates] at the start and the end of every segment, (n, 3)
    each: a Line's or Arc's ``abc_deg`` (None: all six 0, the segments' rule), a Rotate's
    ``abc_start_deg`` / ``abc_end_deg``; a segment without a rotary position (NURBS, dwell,
    pause) holds where the last one that has one ends (``start_abc_deg`` before the first).
    ``kind``: the segments' codes (:data:`KINDS`) if read already. Whole-array: the tuples
    are read in C passes, the holds filled by a running maximum of row indices."""
    n = len(segments)
    kind = _kind_codes(segments) if kind is None else kind
    start = np.asarray(start_abc_deg, dtype=float).reshape(3)
    abc0, abc1 = np.zeros((n, 3)), np.zeros((n, 3))
    moves = np.flatnonzero(kind <= ARC)  # LINE, RAPID, ARC: they carry abc_deg
    if moves.size:
        carriers = segments if moves.size == n else map(segments.__getitem__, moves.tolist())
        six = list(map(getattr, carriers, repeat("abc_deg")))
        has = np.fromiter(map(is_not, six, repeat(None)), dtype=bool, count=moves.size)
        if has.any():
            given = filter(partial(is_not, None), six)
            flat = np.fromiter(chain.from_iterable(given), dtype=float, count=6 * int(has.sum()))
            flat = flat.reshape(-1, 6)
            abc0[moves[has]], abc1[moves[has]] = flat[:, :3], flat[:, 3:]
    rotates = np.flatnonzero(kind == ROTATE)
    if rotates.size:
        abc0[rotates] = _rows(segments, rotates, "abc_start_deg", 3)
        abc1[rotates] = _rows(segments, rotates, "abc_end_deg", 3)
    carries = (kind <= ARC) | (kind == ROTATE)
    hold = np.flatnonzero(~carries)
    if hold.size:
        last = np.maximum.accumulate(np.where(carries, np.arange(n), -1))
        ends = np.concatenate((start[None, :], abc1))
        abc0[hold] = abc1[hold] = ends[last[hold] + 1]
    return abc0, abc1


def end_abc_deg(segments, start_abc_deg=(0.0, 0.0, 0.0)) -> tuple:
    """A B C [deg, machine coordinates] after ``segments`` (from ``start_abc_deg``): the end
    of the last segment with a rotary position, :func:`segment_abc_deg`'s rule (a Line or
    Arc without ``abc_deg`` ends at 0; dwells, pauses and NURBS hold the axes). Reads from
    the end back to the last such segment (usually the last one)."""
    for seg in reversed(segments):
        kind = seg.kind
        if kind == "rotate":
            return tuple(float(v) for v in seg.abc_end_deg)
        if kind in ("line", "rapid", "arc"):
            abc = seg.abc_deg
            return (0.0, 0.0, 0.0) if abc is None else tuple(float(v) for v in abc[3:])
    return tuple(float(v) for v in start_abc_deg)


def segment_columns(segments, start_abc_deg=(0.0, 0.0, 0.0)) -> SegmentColumns:
    """The :class:`SegmentColumns` of a sequence of segments (the same numbers as reading
    each segment's attributes: the floats are copied, not recomputed); A B C from
    ``start_abc_deg`` (the program's :attr:`~nurbscnc.geometry.segments.Program.start_abc_deg`)."""
    n = len(segments)
    kind = _kind_codes(segments)
    abc0, abc1 = segment_abc_deg(segments, start_abc_deg, kind)
    return SegmentColumns(
        kind=kind,
        starts_mm=_points(segments, "start_mm"),
        ends_mm=_points(segments, "end_mm"),
        feeds_mm_s=np.fromiter(map(attrgetter("feed_mm_s"), segments), dtype=float, count=n),
        lines=np.fromiter(map(attrgetter("line"), segments), dtype=np.int64, count=n),
        blends_mm=np.fromiter(
            map(getattr, segments, repeat("blend_mm"), repeat(0.0)), dtype=float, count=n
        ),
        abc_start_deg=abc0,
        abc_end_deg=abc1,
    )
