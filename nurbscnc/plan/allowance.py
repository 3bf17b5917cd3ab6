"""Corner allowances of the contour guarantee (G64): where a servo sample may leave the
planned path by more than ε_max.

The guarantee (SPEC §8, the contour tolerance ε_max) is kept per checked servo sample a:
its contour error c to the planned path is at most ε_max, **or** its distance to the
programmed vertex V of a G64 corner is at most ε_max + P, P that corner's path tolerance
(:func:`~nurbscnc.geometry.segments.blend_tolerance_mm`: G64 P, the machine's
``path_tolerance_mm`` under G64 without P; none under G61 / G61.1). Both imply a distance
of at most ε_max + P to the programmed path: V lies on it, and the planned path lies within
P of it. Under G64 a blend may leave the programmed path by up to P at such a corner; a
stop there leaves it by nothing, and the servo's overshoot past the vertex (c₂·a at a
deceleration a, SPEC §8: 1 − G(s) ≈ c₂s²) may then use the tolerance the blend left unused.

The check decides on the *effective error* of a sample, e = min(c, |a − V| − P) over its
candidate vertices (c where it has none): the sample is within the guarantee if and only
if e ≤ ε_max. Only samples with c > ε_max need the vertex distance.

Which vertices the planner grants (a subset of the programmed G64 vertices, so any sample
it accepts is accepted by a check that grants them all, bench/contour.py): the junctions of
the planned pieces where two feed moves of different program segments meet at a corner
(the tangent turns), both with a path tolerance P > 0 (the smaller of the two), neither of
zero length, no dwell, pause or exact stop (G61.1) between them, no rotary axis in the
program. Blended corners are not among them (the blend's own rows meet their lines
tangentially; its vertex lies off the planned path). A sample's candidates are the vertices
of the junctions within :data:`NEIGHBOUR_PIECES` pieces of its reference's piece: a stop's
overshoot happens while the reference decelerates into the vertex and leaves it. No
allowance on rapids, on the settle wait after a rapid, nor on the held tail after the
program's end (:class:`~nurbscnc.plan.checkresult.Accumulator`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbscnc.geometry.path import Kind
from nurbscnc.machine.profile import Machine
from nurbscnc.plan.blends import tolerance_mm
from nurbscnc.plan.junctions import SMOOTH_JUNCTION_RAD, junction_turning
from nurbscnc.plan.pieces import PieceList

#: Whether the check grants the corner allowances (tests compare plans with it off).
CORNER_ALLOWANCE = True
#: Pieces on each side of a sample's piece whose junctions are its candidate vertices: the
#: overshoot after a stop lasts ~10–20 ms (SPEC Table 2's axes), in which the reference
#: leaving the vertex from rest crosses at most a few short moves.
NEIGHBOUR_PIECES = 3


@dataclass(frozen=True, eq=False)
class CornerAllowance:
    """The corner allowances of one program's pieces (module doc): per junction j (between
    rows j and j + 1; k − 1 of them) ``vertex_of`` the vertex it is (−1: none), and per
    vertex ``vertex_mm`` (m, 3) [mm] and ``tol_mm`` (m,) its path tolerance P [mm]."""

    vertex_of: np.ndarray
    vertex_mm: np.ndarray
    tol_mm: np.ndarray

    def beyond_mm(self, points_mm: np.ndarray, piece: np.ndarray) -> np.ndarray:
        """min over the candidate vertices V (module doc) of |a − V| − P [mm] for the points
        ``points_mm`` (n, 3) whose references lie on pieces ``piece`` (n,); inf where a
        point has no candidate."""
        n = piece.size
        if n == 0:
            return np.zeros(0)
        k = self.vertex_of.size
        # Junctions p − 1 − K … p + K: the start and end of every piece within K of p.
        offsets = np.arange(-1 - NEIGHBOUR_PIECES, NEIGHBOUR_PIECES + 1)
        j = piece[:, None].astype(np.int64) + offsets[None, :]
        inside = (j >= 0) & (j < k)
        v = np.where(inside, self.vertex_of[np.clip(j, 0, max(k - 1, 0))], -1)
        has = v >= 0
        vi = np.where(has, v, 0)
        d = points_mm[:, None, :] - self.vertex_mm[vi]
        dist = np.sqrt(np.einsum("ijk,ijk->ij", d, d)) - self.tol_mm[vi]
        return np.where(has, dist, np.inf).min(axis=1)

    def effective_mm(
        self, contour_mm: np.ndarray, points_mm: np.ndarray, piece: np.ndarray, eps_mm: float
    ) -> np.ndarray:
        """The effective errors [mm] (module doc) of samples with contour errors
        ``contour_mm`` (n,) at ``points_mm`` (n, 3) on pieces ``piece`` (n,): a copy of
        ``contour_mm`` where it is within ``eps_mm``, min(c, |a − V| − P) above it."""
        out = np.array(contour_mm, dtype=float, copy=True)
        i = np.flatnonzero(out > eps_mm)
        if i.size:
            out[i] = np.minimum(out[i], self.beyond_mm(points_mm[i], piece[i]))
        return out


def corner_allowance(
    pieces: PieceList, machine: Machine, segment_tol_mm=None
) -> CornerAllowance | None:
    """The corner allowances (:class:`CornerAllowance`) of ``pieces``, None where there are
    none (or :data:`CORNER_ALLOWANCE` is off): the junctions of the module doc.
    ``segment_tol_mm(segments)``: the programmed path tolerance [mm] of program segments
    (an index array), read for the spline rows at a vertex only (a smoothed run's spline
    keeps only the blends' share of P in its rows, but ends on the programmed vertex; every
    other row's ``blend_mm`` is its segment's); None: the pieces' own throughout."""
    k = len(pieces)
    if not CORNER_ALLOWANCE or k < 2 or pieces.rotary is not None:
        return None
    tol_row = tolerance_mm(pieces.blend_mm, machine)
    tol = np.minimum(tol_row[:-1], tol_row[1:])
    turning, regular = junction_turning(pieces)
    rapid, length, seg = pieces.rapid, pieces.length_mm, pieces.segment
    blend = pieces.kind == Kind.PH  # corner blends (and PH corner fits): never programmed ends
    blend[pieces.ph_rows] = True
    vertex = (
        (tol > 0.0)
        & ~rapid[:-1]
        & ~rapid[1:]
        & ~pieces.stop_after[:-1]
        & (pieces.dwell_after_s[:-1] == 0.0)
        & (length[:-1] > 0.0)
        & (length[1:] > 0.0)
        & (seg[:-1] != seg[1:])
        & ~blend[:-1]
        & ~blend[1:]
        & (~regular | (turning > SMOOTH_JUNCTION_RAD))
    )
    j = np.flatnonzero(vertex)
    if j.size == 0:
        return None
    tol_a, tol_b = tol_row[j], tol_row[j + 1]
    if segment_tol_mm is not None:  # spline rows (smoothing's among them): the program's P
        for side, rows in ((tol_a, j), (tol_b, j + 1)):
            spline = np.flatnonzero(pieces.kind[rows] == Kind.NURBS)
            if spline.size:
                side[spline] = segment_tol_mm(seg[rows[spline]])
    tol_j = np.minimum(tol_a, tol_b)
    vertex_of = np.full(k - 1, -1, dtype=np.int64)
    vertex_of[j] = np.arange(j.size)
    return CornerAllowance(vertex_of, np.ascontiguousarray(pieces.end_mm[:, j].T), tol_j)


def program_tolerance(program, machine: Machine, override_mm: float | None):
    """``segment_tol_mm`` of :func:`corner_allowance` for ``program`` (its ``segments``):
    G64 P as programmed, the machine's path tolerance under G64 without P, 0 under G61 /
    G61.1 (:func:`~nurbscnc.geometry.segments.blend_tolerance_mm`), or ``override_mm``
    (``--blend-tolerance``) for every segment. Read for the segments asked only."""
    from nurbscnc.geometry.segments import blend_tolerance_mm

    segments = program.segments
    path_mm = machine.limits.path_tolerance_mm

    def tol_mm(index: np.ndarray) -> np.ndarray:
        if override_mm is not None:
            return np.full(index.shape, float(override_mm))
        mode = np.fromiter((segments[i].blend_mm for i in index.tolist()), float, index.size)
        return blend_tolerance_mm(mode, path_mm)

    return tol_mm
