"""The dense polyline of a path: the chords that stand for its pieces when distances to it
are measured (SPEC §8: the contour error is a distance to the commanded path).

A piece's chords follow its curvature: a chord h on curvature κ is off the curve by its
sagitta κh²/8, so chords of h = √(8 δ / κ) keep the polyline within δ of the piece. Lines
are exact by their two end points. The κ of a piece is its recorded largest curvature
(``kappa_max_per_mm``), doubled on NURBS cells, whose κ is estimated from 8 samples
(:func:`chord_kappa_per_mm`, the one place of that rule).

``pieces`` is any table of pieces with the columns ``kind`` (:class:`Kind` codes),
``length_mm``, ``kappa_max_per_mm`` (k,) and its :class:`~nurbscnc.geometry.path.PathTable`
``path`` (:class:`nurbscnc.plan.pieces.PieceList`); ``starts_mm`` (k,) the path length at
each piece's start [mm] and ``total_mm`` the path's length [mm].
"""

from __future__ import annotations

import numpy as np

from nurbscnc.geometry.path import Kind

#: Chord error of the dense polyline on curved pieces [mm] (0.01 µm).
CHORD_MM = 1e-5
#: Longest chord of the dense polyline on curved pieces [mm]: a cap behind the chord error
#: (which sets the chords on curves: CHORD_MM) for pieces whose recorded κ may be low.
#: 0.05 mm, not 0.01: at 0.01 the cap set 3/4 of a 60 mm airfoil's points, and the
#: measured chord error stays ≤ CHORD_MM on every NURBS program of the corpus and
#: repository (tests/test_dynamics_window.py).
MAX_SPACING_MM = 0.05
#: Most points of the dense polyline on one piece. The corpus's most is 24,901 (a long
#: NURBS cell of G5_Curva_Delfino); a near-cusp (the fuzzer's control polygon folding back
#: by 1e-10 mm: κ 3e10 /mm on a 0.25 mm cell) asked for 2e8 (1.6 GB, exit 1). Such a piece's
#: chords then miss CHORD_MM near its peak only.
MAX_PIECE_POINTS = 1 << 16


def chord_kappa_per_mm(kind: np.ndarray, kappa_max_per_mm: np.ndarray) -> np.ndarray:
    """The curvature [1/mm] that sets the chords of pieces of kinds ``kind`` (k,) whose
    recorded largest curvature is ``kappa_max_per_mm`` (k,): |κ|, doubled on NURBS cells
    (their κ comes from 8 samples and may miss the cell's peak)."""
    return np.where(kind == Kind.NURBS, 2.0, 1.0) * np.abs(kappa_max_per_mm)


def chord_counts(
    kind: np.ndarray,
    length_mm: np.ndarray,
    kappa_max_per_mm: np.ndarray,
    chord_mm: float,
    max_chord_mm: float,
    max_points: int | None = None,
) -> np.ndarray:
    """Points of a polyline on each piece (k,) [1]: 2 on lines and zero-length pieces (exact),
    else chords of h = min(``max_chord_mm``, √(8 ``chord_mm`` / κ)) (sagitta κh²/8 ≤
    ``chord_mm`` [mm]; κ of :func:`chord_kappa_per_mm`), ⌈L/h⌉ + 1 points, at least 3 and,
    with ``max_points``, at most ``max_points``. The pieces' ``kind`` (:class:`Kind` codes),
    ``length_mm`` L [mm] and ``kappa_max_per_mm`` [1/mm] are (k,) columns."""
    kappa = chord_kappa_per_mm(kind, kappa_max_per_mm)
    with np.errstate(divide="ignore"):
        h = np.minimum(max_chord_mm, np.sqrt(8.0 * chord_mm / kappa))
    if max_points is None:
        counts = np.maximum(np.ceil(length_mm / h).astype(np.int64) + 1, 3)
    else:
        counts = np.clip(np.ceil(length_mm / h), 2.0, max_points - 1).astype(np.int64) + 1
    return np.where((kind == Kind.LINE) | (length_mm == 0.0), 2, counts)


def path_counts(pieces, lo: int = 0, hi: int | None = None) -> np.ndarray:
    """Points of the dense polyline on each piece (≥ 2) of pieces ``lo:hi`` (default all):
    2 on lines and rapids (exact), else chords of at most min(:data:`MAX_SPACING_MM`,
    √(8 δ_p / κ)) with δ_p = :data:`CHORD_MM` (a chord h on curvature κ is off by κh²/8);
    κ is the piece's ``kappa_max_per_mm``, doubled on NURBS cells (their κ comes from 8
    samples); at most :data:`MAX_PIECE_POINTS` a piece (:func:`chord_counts`)."""
    sl = slice(lo, hi)
    return chord_counts(
        pieces.kind[sl],
        pieces.length_mm[sl],
        pieces.kappa_max_per_mm[sl],
        CHORD_MM,
        MAX_SPACING_MM,
        MAX_PIECE_POINTS,
    )


def dense_path_mm(pieces, profile, spacing_mm: float = 0.002) -> np.ndarray:
    """The commanded path as a dense polyline [mm]: exact points every ``spacing_mm`` or
    closer (≥ 8 per piece), so its chord error is negligible beside micrometre errors."""
    total = profile.total_length_mm
    starts = profile.piece_start_mm
    lengths = pieces.length_mm
    counts = np.maximum(np.ceil(lengths / spacing_mm).astype(np.int64), 8)
    counts[lengths == 0.0] = 1
    idx = np.repeat(np.arange(len(pieces)), counts)
    first = np.repeat(np.cumsum(counts) - counts, counts)
    frac = (np.arange(idx.size) - first) / np.repeat(np.maximum(counts - 1, 1), counts)
    s = starts[idx] + frac * lengths[idx]
    s = np.clip(s, 0.0, total)
    return pieces.path.place(starts, s, idx)[0]


def dense_local(pieces, lo: int, hi: int) -> tuple[np.ndarray, np.ndarray]:
    """The pieces (n,) and arc lengths from their starts (n,) [mm] of the dense polyline
    (:func:`path_counts`) of pieces ``lo:hi``: c points a piece at fractions 0, 1/(c − 1),
    …, 1 of its length."""
    c = path_counts(pieces, lo, hi)  # these pieces only: O(window), not O(program)
    piece = np.repeat(np.arange(lo, hi), c)
    first = np.repeat(np.cumsum(c) - c, c)
    frac = (np.arange(piece.size) - first) / np.repeat(c - 1, c)
    return piece, frac * pieces.length_mm[piece]


def dense_polyline(pieces, starts_mm: np.ndarray, total_mm: float, lo: int, hi: int):
    """Path lengths (n,) [mm] and points (n, 3) [mm] of the dense polyline
    (:func:`path_counts`) of pieces ``lo:hi``, the pieces starting at ``starts_mm``. Each
    point is placed at its arc length from its piece's start, so its numbers depend on its
    piece only (not on ``lo``, ``hi`` or the starts)."""
    piece, local = dense_local(pieces, lo, hi)
    return path_lengths(starts_mm, total_mm, piece, local), pieces.path.points(piece, local)[0]


def path_lengths(
    starts_mm: np.ndarray, total_mm: float, piece: np.ndarray, local_mm: np.ndarray
) -> np.ndarray:
    """Path lengths [mm] of the points at ``local_mm`` from the starts of pieces ``piece``,
    the pieces starting at ``starts_mm``, clipped at the path's end ``total_mm``."""
    return np.minimum(starts_mm[piece] + local_mm, total_mm)
