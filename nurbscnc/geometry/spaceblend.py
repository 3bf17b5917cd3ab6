"""G2 quintic Bézier blends of corners whose sides leave one plane (a helix meeting a line,
an arc leaving the corner plane), one corner or many in lock step.

A helix meeting a line (or an arc leaving the corner plane) cannot be met by a planar PH
quintic at both cut points. :func:`blend_space_corner` joins them by a quintic Bézier that is
G2 with both sides (:func:`space_bezier`: end tangents and curvature vectors), a NURBS piece
for the planner (arc length by its table, not in closed form), with the same equal-trim
search and a two-way sampled Hausdorff deviation (:data:`MAX_EVALS` blends at most).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbscnc.geometry.blendrules import (
    BRACKET_REL,
    MAX_EVALS,
    MIN_REVERSAL_RAD,
    MIN_TRIM_MM,
    MIN_TURNING_RAD,
    N_ARC,
    SEARCH_WINDOW,
    TRIM_CAP_FACTOR,
    line_deviation_per_trim,
)
from nurbscnc.geometry.distance import segment_distances


@dataclass(frozen=True, eq=False)
class SpaceBlend:
    """A blend of a corner whose sides do not lie in one plane: ``curve`` a quintic Bézier
    (a :class:`~nurbscnc.geometry.nurbs.NurbsCurve`, u ∈ [0, 1]) from the point at arc length
    L_a − ``trim_a_mm`` of the first geometry to the point at ``trim_b_mm`` of the second;
    ``deviation_mm`` its measured Hausdorff distance to the corner path [mm];
    ``kappa_max_per_mm`` its largest curvature [1/mm]; ``turning_deg`` the tangent turning
    at the vertex [deg]."""

    curve: object
    trim_a_mm: float
    trim_b_mm: float
    deviation_mm: float
    kappa_max_per_mm: float
    turning_deg: float


_N_SPACE = 129


def space_bezier(p_a, t_a, k_a, p_b, t_b, k_b) -> np.ndarray:
    """Control points (m, 6, 3) [mm] of the quintic Béziers from ``p_a`` to ``p_b`` (m, 3)
    that are G2 with both ends: unit tangents ``t_a``, ``t_b`` and curvature vectors ``k_a``,
    ``k_b`` [1/mm] (m, 3). With C′(0) = α t_a, C″(0) = α² k_a (no tangential component: the
    curvature vector is C″⊥/|C′|²) and the Bézier end derivatives C′(0) = 5(P1 − P0), C″(0) =
    20(P2 − 2P1 + P0): P1 = P0 + α t_a/5, P2 = P0 + 2α t_a/5 + α² k_a/20, and mirrored at
    the end with β. α = β = |p_b − p_a| (the chord)."""
    chord = np.linalg.norm(p_b - p_a, axis=1)[:, None]
    return np.stack(
        [
            p_a,
            p_a + chord / 5.0 * t_a,
            p_a + 2.0 * chord / 5.0 * t_a + chord * chord / 20.0 * k_a,
            p_b - 2.0 * chord / 5.0 * t_b + chord * chord / 20.0 * k_b,
            p_b - chord / 5.0 * t_b,
            p_b,
        ],
        axis=1,
    )


def blend_space_corner(
    geom_a, geom_b, tolerance_mm: float, max_trim_a_mm: float, max_trim_b_mm: float
) -> SpaceBlend | None:
    """The largest G2 quintic Bézier blend of a corner whose sides leave the plane of its
    two tangents (a helix into a line: the planar PH blend of :func:`blend_corner` cannot
    meet both sides), within ``tolerance_mm`` [mm]: :func:`blend_space_corners` of the one
    corner between two whole geometry objects (LineGeometry, ArcGeometry, NurbsCurve or
    PHQuintic).

    Equal trims d ≤ min(max trims, lengths); the curve is :func:`space_bezier` between the
    cut points (G2: tangents and curvature vectors of both sides). The deviation is the
    Hausdorff distance between its 129 samples and the corner path (33 points a side and the
    vertex, as polylines), each way; d starts at the line corner's estimate and is updated
    by secant steps on the deviation towards tol(1 − 0.2 :data:`SEARCH_WINDOW`) (through 0
    at first: the deviation vanishes with the trim), safeguarded by bisection (at most
    :data:`MAX_EVALS` blends), until the deviation is in [(1 − :data:`SEARCH_WINDOW`) tol,
    tol] or d reached its cap (about 3 blends a corner on tort.ngc, where bisection took 8).
    None: smooth or reversed junctions, no regular candidate within the tolerance, degenerate
    trims.
    """
    from nurbscnc.geometry.path import PathTable, whole_row

    path = PathTable.of([whole_row(geom_a), whole_row(geom_b)])
    return blend_space_corners(path, [0], [1], tolerance_mm, max_trim_a_mm, max_trim_b_mm)[0]


#: Corners evaluated together by :func:`blend_space_corners` (bounds the batched Béziers and
#: sides to a few MB).
SPACE_CHUNK = 128


def _frames(path, rows: np.ndarray, s_mm: np.ndarray):
    """Points, unit tangents and curvature vectors κn = (C″ − (C″·t)t)/|C′|² [1/mm] (m, 3)
    of path-table pieces ``rows`` at arc lengths ``s_mm`` (m,) from their starts (any
    parametrisation gives the same t and κn)."""
    pts = path.points(rows, s_mm)[0]
    d1, d2 = path.derivatives(rows, s_mm)
    speed2 = np.maximum(np.einsum("ij,ij->i", d1, d1), 1e-300)
    t = d1 / np.sqrt(speed2)[:, None]
    k = (d2 - np.einsum("ij,ij->i", d2, t)[:, None] * t) / speed2[:, None]
    return pts, t, k


def _bezier_batch(ctrl: np.ndarray, xi: np.ndarray):
    """Points, first and second derivatives (m, n, 3) of m quintic Béziers ``ctrl``
    (m, 6, 3) at ``xi`` (n,) (Bernstein sums)."""
    from math import comb

    def bern(deg, pts):
        t = xi[None, :, None]
        return sum(
            comb(deg, i) * t**i * (1.0 - t) ** (deg - i) * pts[:, i : i + 1, :]
            for i in range(deg + 1)
        )

    d1 = 5 * np.diff(ctrl, axis=1)
    d2 = 4 * np.diff(d1, axis=1)
    return bern(5, ctrl), bern(4, d1), bern(3, d2)


def _polyline_distance_batch(q: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Distance [mm] (m, a) of each point of ``q`` (m, a, 3) to the polyline ``pts``
    (m, b, 3) of its own row: every row's chords in one table, each point's range of
    chords its row's, one :func:`~nurbscnc.geometry.distance.segment_distances` call (the
    compiled kernel where built: no (a, b, 3) temporaries per row). Its dot products are
    summed in a fixed order, (x0 y0 + x1 y1) + x2 y2, so the distances do not depend on
    numpy's SIMD path as einsum's do; the least distance is the root of the least square
    (√ is monotone and correctly rounded)."""
    m, a = q.shape[0], q.shape[1]
    chords = pts.shape[1] - 1
    lo = np.repeat(np.arange(m, dtype=np.int64) * chords, a)
    dist = segment_distances(
        q.reshape(m * a, 3),
        pts[:, :-1].reshape(m * chords, 3),
        np.diff(pts, axis=1).reshape(m * chords, 3),
        lo,
        lo + chords,
    )
    return dist.reshape(m, a)


def blend_space_corners(
    path, rows_a, rows_b, tolerance_mm, max_trim_a_mm, max_trim_b_mm
) -> list[SpaceBlend | None]:
    """:func:`blend_space_corner`'s search for m corners at once: the corner between
    path-table pieces ``rows_a`` (m,) and ``rows_b`` (m,) (each a's end meets b's start),
    with tolerances and trim caps (m,) [mm]. Every corner's search takes its next trim in
    lock step, each round one whole-array evaluation of the candidates still searching
    (points, tangents and curvature vectors from the path table; the Béziers batched; the
    two one-way distances per corner). None where no blend is found."""
    from nurbscnc.geometry.nurbs import NurbsCurve

    rows_a, rows_b = np.asarray(rows_a, dtype=np.intp), np.asarray(rows_b, dtype=np.intp)
    m = rows_a.size
    args = [
        np.broadcast_to(np.asarray(x, dtype=float), (m,))
        for x in (tolerance_mm, max_trim_a_mm, max_trim_b_mm)
    ]
    if m > SPACE_CHUNK:  # bounded temporaries
        return [
            bl
            for lo in range(0, m, SPACE_CHUNK)
            for bl in blend_space_corners(
                path,
                rows_a[lo : lo + SPACE_CHUNK],
                rows_b[lo : lo + SPACE_CHUNK],
                *(x[lo : lo + SPACE_CHUNK] for x in args),
            )
        ]
    tolerance_mm, max_trim_a_mm, max_trim_b_mm = args
    out: list[SpaceBlend | None] = [None] * m
    if m == 0:
        return out
    tol = np.asarray(tolerance_mm, dtype=float).copy()
    len_a, len_b = path.length_mm[rows_a].astype(float), path.length_mm[rows_b].astype(float)
    d_max = np.minimum.reduce(
        [
            np.broadcast_to(np.asarray(max_trim_a_mm, float), (m,)),
            np.broadcast_to(np.asarray(max_trim_b_mm, float), (m,)),
            len_a,
            len_b,
        ]
    )
    vertex, t_a, _ = _frames(path, rows_a, len_a)
    _, t_b, _ = _frames(path, rows_b, np.zeros(m))
    n_c = np.cross(t_a, t_b)
    turning = np.arctan2(np.sqrt(np.einsum("ij,ij->i", n_c, n_c)), np.einsum("ij,ij->i", t_a, t_b))
    live = (
        np.isfinite(tol)
        & (tol > 0.0)
        & (d_max > MIN_TRIM_MM)
        & (turning >= MIN_TURNING_RAD)
        & (turning <= np.pi - MIN_REVERSAL_RAD)
    )
    per_trim = np.where(live, line_deviation_per_trim(np.where(live, turning, 1.0)), 1.0)
    d_cap = np.minimum(d_max, TRIM_CAP_FACTOR * tol / per_trim)
    d = np.minimum(d_cap, tol * (1.0 - 0.5 * SEARCH_WINDOW) / per_trim)
    lo, hi = np.zeros(m), d_cap.copy()
    best_d = np.full(m, np.nan)
    best = [None] * m
    last_d, last_dev = np.zeros(m), np.zeros(m)  # the last regular blend's trim, deviation
    xi = np.linspace(0.0, 1.0, _N_SPACE)
    frac = np.linspace(0.0, 1.0, N_ARC)
    for _ in range(MAX_EVALS):
        act = np.flatnonzero(live)
        if act.size == 0:
            break
        ctrl, dev, kappa, regular = _candidates(
            path, rows_a[act], rows_b[act], len_a[act], vertex[act], d[act], xi, frac
        )
        ok = regular & (dev <= tol[act])
        stop = np.zeros(act.size, dtype=bool)
        for n, c in enumerate(act.tolist()):  # the scalar bookkeeping of the search
            if ok[n]:
                lo[c], best_d[c] = d[c], d[c]
                best[c] = (ctrl[n].copy(), float(dev[n]), float(kappa[n].max()))
                if dev[n] >= tol[c] * (1.0 - SEARCH_WINDOW) or d[c] >= d_cap[c]:
                    stop[n] = True
                    continue
            else:
                hi[c] = d[c]
            # The next trim: a secant step on the deviation towards tol(1 − 0.2 window), near
            # its top (through the last two regular blends, or through 0: the deviation vanishes
            # with the trim), kept if strictly inside the bracket; else halve the bracket
            # (or double the trim while nothing failed).
            step = np.nan
            if regular[n] and dev[n] > 0.0:
                aim = tol[c] * (1.0 - 0.2 * SEARCH_WINDOW)
                d0, e0 = (last_d[c], last_dev[c]) if last_dev[c] != dev[n] else (0.0, 0.0)
                step = d[c] + (aim - dev[n]) * (d[c] - d0) / (dev[n] - e0)
                last_d[c], last_dev[c] = d[c], float(dev[n])
            if lo[c] < step < hi[c]:
                d[c] = step
            else:
                d[c] = (
                    0.5 * (lo[c] + hi[c])
                    if hi[c] < d_cap[c] or lo[c] > 0.0
                    else min(2.0 * d[c], d_cap[c])
                )
            if hi[c] - lo[c] <= BRACKET_REL * hi[c]:
                stop[n] = True
        live[act[stop]] = False
    for c in range(m):
        if best[c] is None or not best_d[c] > MIN_TRIM_MM:
            continue
        ctrl_c, dev_c, kmax = best[c]
        curve = NurbsCurve(5, np.array([0.0] * 6 + [1.0] * 6), ctrl_c, np.ones(6))
        out[c] = SpaceBlend(
            curve, float(best_d[c]), float(best_d[c]), dev_c, kmax, float(np.degrees(turning[c]))
        )
    return out


def _candidates(path, rows_a, rows_b, len_a, vertex, da, xi, frac):
    """One round of :func:`blend_space_corners`' search, whole-array over the k corners still
    searching: the blend of trims ``da`` (k,) [mm] between pieces ``rows_a`` (of lengths
    ``len_a``) and ``rows_b`` meeting at ``vertex`` (k, 3), sampled at ``xi``, the corner's
    sides at fractions ``frac`` of the trims. Returns the Béziers' control points (k, 6, 3),
    the two-way deviation from the corner (k,) [mm], the curvature samples (k, len(xi))
    [1/mm] and whether each blend is regular (no vanishing speed)."""
    p_a, ta, ka = _frames(path, rows_a, len_a - da)
    p_b, tb, kb = _frames(path, rows_b, da)
    ctrl = space_bezier(p_a, ta, ka, p_b, tb, kb)
    pts, d1, d2 = _bezier_batch(ctrl, xi)
    speed = np.sqrt(np.einsum("mij,mij->mi", d1, d1))
    regular = speed.min(axis=1) > 1e-3 * speed.max(axis=1)
    s = da[:, None] * frac[None, :]
    k_side = frac.size
    side_a = path.points(
        np.repeat(rows_a, k_side),
        (len_a - da)[:, None].repeat(k_side, axis=1).ravel() + s.ravel(),
    )[0].reshape(rows_a.size, k_side, 3)
    side_b = path.points(np.repeat(rows_b, k_side), s.ravel())[0].reshape(rows_a.size, k_side, 3)
    corner = np.concatenate([side_a[:, :-1], vertex[:, None, :], side_b[:, 1:]], axis=1)
    dev = np.maximum(
        _polyline_distance_batch(pts, corner).max(axis=1),
        _polyline_distance_batch(corner, pts).max(axis=1),
    )
    kappa = np.linalg.norm(np.cross(d1, d2), axis=2) / np.maximum(speed, 1e-300) ** 3
    return ctrl, dev, kappa, regular
