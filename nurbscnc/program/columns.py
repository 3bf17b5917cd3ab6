"""The interpreted program's segments as columns (per-segment work done whole-array).

A CAM program is hundreds of thousands of Line objects; the checks before work and the
``check`` summary want their kinds, end points, feeds and source lines as arrays. Each
column is read here in one pass that runs in C (``map`` of an attribute getter into
``np.fromiter``: no Python frame per segment), once per command.
"""

from __future__ import annotations

from itertools import chain, repeat
from operator import attrgetter
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


def segment_columns(segments) -> SegmentColumns:
    """The :class:`SegmentColumns` of a sequence of segments (the same numbers as reading
    each segment's attributes: the floats are copied, not recomputed)."""
    n = len(segments)
    return SegmentColumns(
        kind=_kind_codes(segments),
        starts_mm=_points(segments, "start_mm"),
        ends_mm=_points(segments, "end_mm"),
        feeds_mm_s=np.fromiter(map(attrgetter("feed_mm_s"), segments), dtype=float, count=n),
        lines=np.fromiter(map(attrgetter("line"), segments), dtype=np.int64, count=n),
        blends_mm=np.fromiter(
            map(getattr, segments, repeat("blend_mm"), repeat(0.0)), dtype=float, count=n
        ),
    )
