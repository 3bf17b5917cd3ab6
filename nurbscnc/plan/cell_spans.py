"""Corner blends that reach across several cells of a curve.

A NURBS stretch is planned as cells of at most 0.25 mm (plan/curved_pieces.py ``CELL_MM``,
so that the contour check can lower the feed locally); a blend at a corner trims at most
half of each neighbouring piece, so a corner between a line and a spline (a plunge into a
smoothed contour, a spline ending on a long line) was trimmed by at most half a cell on
both sides, however much room the tolerance gave: under G64 P0.01 inch a 90° plunge at F10
into a PCB pad's spline ran ~0.4 mm further at F10 than with the pad's chords blended
(0.1 s a plunge). The cells of one curve meet with its own continuity (same curve,
contiguous parameters, no turning): they are one side of the corner for the blend. A
corner's side is that *span* of cells, and the blend may trim up to half of it (so the
blends at both ends of a span never overlap); the trims are then spread over the cells
(:func:`row_trims`): cells the blend covers are dropped, the one it ends in trimmed.
"""

from __future__ import annotations

import numpy as np

from nurbscnc.geometry.path import Kind
from nurbscnc.plan.pieces import PieceList

#: Largest tangent turning [rad] between two cells of one curve that still continue each
#: other (the curve's own G1 continuity, up to rounding).
CONTINUE_RAD = 1e-6
#: Most cells a span walks from its corner (16 cells of 0.25 mm: a trim of up to 2 mm). Two
#: corners' spans in one stretch may then overlap, their trims never do: each is at most half
#: of its span, and the two spans together are at most twice the stretch.
MAX_SPAN_CELLS = 16
#: A side spans only if its cruise cap exceeds the other side's by this factor.
FASTER = 1.001


def _goes_on(pieces: PieceList, r: int) -> bool:
    """Whether junction ``r`` (rows r, r + 1) joins two cells of the same NURBS curve at
    the same parameter with no turning, stop, dwell or pass between them."""
    if not (pieces.kind[r] == Kind.NURBS and pieces.kind[r + 1] == Kind.NURBS):
        return False
    a, b = pieces.objects.get(r), pieces.objects.get(r + 1)
    if a is None or b is None or a[0] is not b[0] or a[2] != b[1]:
        return False
    if pieces.stop_after[r] or pieces.pass_after[r] or pieces.dwell_after_s[r] != 0.0:
        return False
    ta, tb = pieces.tangent_end[:, r], pieces.tangent_start[:, r + 1]
    cross = np.cross(ta, tb)
    return bool(np.arctan2(np.sqrt(cross @ cross), ta @ tb) <= CONTINUE_RAD)


def corner_spans(pieces: PieceList, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For corners at ``rows`` (the piece after each; junction ``row − 1`` is the corner),
    the first row of the span before (``lo``: the piece before and the cells of its curve
    it continues from, at most :data:`MAX_SPAN_CELLS`) and the last row of the span after
    (``hi``). Only the faster side of a corner spans (its cap above the other's by
    :data:`FASTER`): there the blend, run at the faster move's feed, may take more of the
    slower move (a plunge); where both run alike a longer blend saves nothing (Fusion 360's
    lead-outs into a vertical retract at F1000 took 0.4 s longer as span blends on the
    paper's machine), and each side stays its own piece as before."""
    k = len(pieces)
    cap = pieces.v_cap_mm_s
    lo, hi = rows - 1, rows.copy()
    for n, r in enumerate(rows.tolist()):
        a = r - 1
        if cap[a] > cap[r] * FASTER:
            while a > 0 and r - a < MAX_SPAN_CELLS and _goes_on(pieces, a - 1):
                a -= 1
        b = r
        if cap[r] > cap[r - 1] * FASTER:
            while b + 1 < k and b - r + 1 < MAX_SPAN_CELLS and _goes_on(pieces, b):
                b += 1
        lo[n], hi[n] = a, b
    return lo, hi


def span_row(pieces: PieceList, first: int, last: int) -> tuple:
    """The :meth:`~nurbscnc.plan.pieces.Piece.path_row` of rows ``first``..``last`` as one
    piece (cells of one curve: its parameter range from the first's start to the last's
    end; a single row as it is)."""
    if first == last:
        return pieces[first].path_row()
    a, b = pieces.objects[first], pieces.objects[last]
    length = float(np.sum(pieces.length_mm[first : last + 1]))
    return (Kind.NURBS, a[0], length, a[1], b[2], a[3], int(pieces.line[first]))


def row_trims(
    pieces: PieceList,
    rows: np.ndarray,
    trim_a_mm: np.ndarray,
    trim_b_mm: np.ndarray,
    spread: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Per piece (k,), the length [mm] trimmed off its start and off its end by the blends
    of corners at ``rows`` with trims ``trim_a_mm`` (before) and ``trim_b_mm`` (after): on
    the corners ``spread`` (blends of :func:`corner_spans`' sides), a trim longer than its
    piece covers it (trimmed whole, so the piece is dropped) and goes on into the next cell
    of its span (the trims never pass its end, being at most half of it); elsewhere (a
    turn-around's U, which takes its middle line whole) each trim stays on its piece."""
    k = len(pieces)
    length = pieces.length_mm
    trim_start, trim_end = np.zeros(k), np.zeros(k)
    trim_start[rows] = trim_b_mm
    trim_end[rows - 1] = trim_a_mm
    for r in np.flatnonzero(spread & (trim_b_mm > length[rows])).tolist():
        i, rest = int(rows[r]), float(trim_b_mm[r])
        while rest > length[i] and i + 1 < k:
            trim_start[i] = length[i]
            rest -= float(length[i])
            i += 1
        trim_start[i] = rest
    for r in np.flatnonzero(spread & (trim_a_mm > length[rows - 1])).tolist():
        i, rest = int(rows[r]) - 1, float(trim_a_mm[r])
        while rest > length[i] and i > 0:
            trim_end[i] = length[i]
            rest -= float(length[i])
            i -= 1
        trim_end[i] = rest
    return trim_start, trim_end
