"""The path near the reference: local polylines of the path and a point's place against
them (nearest point, tangent, in-plane normal, offset across the path), the frames the
limits projection and the tube optimisation write their moves in."""

from __future__ import annotations

import numpy as np

from nurbscnc.geometry.polyline import chord_counts

#: Chord sagitta of the optimiser's polylines of the path [mm].
REFINE_CHORD_MM = 1e-7


def local_polyline(pieces, profile, s_lo_mm: float, s_hi_mm: float) -> np.ndarray:
    """The path between path lengths s_lo and s_hi [mm] (whole pieces) as a dense polyline:
    lines by their ends, curves by chords of sagitta κh²/8 ≤ REFINE_CHORD_MM (κ the
    piece's largest curvature, doubled on NURBS cells:
    :func:`~nurbscnc.geometry.polyline.chord_counts`), so a point's foot on it
    (:func:`nearest_on_polyline`) follows the curve smoothly to well below the reference's
    jerk per period J T³."""
    starts = profile.piece_start_mm
    lo = max(int(np.searchsorted(starts, s_lo_mm, side="right")) - 1, 0)
    hi = min(int(np.searchsorted(starts, s_hi_mm, side="right")), starts.size)
    hi = max(hi, lo + 1)
    sl = slice(lo, hi)
    c = chord_counts(
        pieces.kind[sl], pieces.length_mm[sl], pieces.kappa_max_per_mm[sl], REFINE_CHORD_MM, 0.01
    )
    piece = np.repeat(np.arange(lo, hi), c)
    first = np.repeat(np.cumsum(c) - c, c)
    frac = (np.arange(piece.size) - first) / np.repeat(c - 1, c)
    pts = pieces.path.points_at_fraction(piece, frac)
    # Without the repeated point where one piece ends and the next starts (a segment of
    # rounding length has no direction).
    step = np.sqrt(np.sum(np.diff(pts, axis=0) ** 2, axis=1))
    return pts[np.concatenate([[True], step > 1e-9])]


def nearest_on_polyline(q_mm: np.ndarray, poly_mm: np.ndarray, vertices: int = 8):
    """Nearest points (m, 3), distances (m,) [mm] and unit tangents (m, 3) of the polyline
    ``poly_mm`` (p ≥ 2, 3) for the points ``q_mm`` (m, 3): exact point-to-segment over the
    segments next to the ``vertices`` nearest vertices (a k-d tree)."""
    from scipy.spatial import cKDTree

    p = poly_mm.shape[0]
    k = min(vertices, p)
    _, idx = cKDTree(poly_mm).query(q_mm, k=k)
    idx = np.asarray(idx).reshape(q_mm.shape[0], k)
    seg = np.clip(np.concatenate([idx - 1, idx], axis=1), 0, p - 2)  # (m, 2k)
    a = poly_mm[seg]
    d = poly_mm[seg + 1] - a
    len2 = np.einsum("mij,mij->mi", d, d)
    t = np.einsum("mij,mij->mi", q_mm[:, None, :] - a, d) / np.where(len2 > 0.0, len2, 1.0)
    t = np.clip(t, 0.0, 1.0)
    foot = a + t[..., None] * d
    e = q_mm[:, None, :] - foot
    dist = np.sqrt(np.einsum("mij,mij->mi", e, e))
    best = np.argmin(dist, axis=1)
    rows = np.arange(q_mm.shape[0])
    dd = d[rows, best]
    tangent = dd / np.maximum(np.sqrt(np.einsum("ij,ij->i", dd, dd)), 1e-300)[:, None]
    nearest_on_polyline.segment = seg[rows, best]
    return foot[rows, best], dist[rows, best], tangent


def plane_normal(tangent: np.ndarray) -> np.ndarray:
    """The unit normal in the XY plane, left of each unit tangent (m, 3) (zero where the
    tangent has no XY part)."""
    m = np.zeros_like(tangent)
    m[:, 0], m[:, 1] = -tangent[:, 1], tangent[:, 0]
    size = np.sqrt(m[:, 0] ** 2 + m[:, 1] ** 2)
    return np.where(size[:, None] > 1e-12, m / np.where(size > 1e-12, size, 1.0)[:, None], 0.0)


def polyline_frame(poly_mm: np.ndarray):
    """The polyline's arc length at its vertices (P,), and a function σ → (points, unit
    tangents, unit XY normals) at arc lengths σ, the tangents and normals interpolated
    linearly between the vertices' (the mean of their two segments'), so they turn smoothly
    along the path rather than jump at each vertex."""
    d = np.diff(poly_mm, axis=0)
    length = np.sqrt(np.einsum("ij,ij->i", d, d))
    unit = d / np.where(length > 0.0, length, 1.0)[:, None]
    t_v = np.concatenate([unit[:1], unit[:-1] + unit[1:], unit[-1:]])
    t_v /= np.maximum(np.sqrt(np.einsum("ij,ij->i", t_v, t_v)), 1e-300)[:, None]
    s_v = np.concatenate([[0.0], np.cumsum(length)])

    def at(sigma):
        i = np.clip(np.searchsorted(s_v, sigma, side="right") - 1, 0, length.size - 1)
        f = np.clip((sigma - s_v[i]) / np.where(length[i] > 0.0, length[i], 1.0), 0.0, 1.0)
        point = poly_mm[i] + f[:, None] * d[i]
        t = (1.0 - f)[:, None] * t_v[i] + f[:, None] * t_v[i + 1]
        t /= np.maximum(np.sqrt(np.einsum("ij,ij->i", t, t)), 1e-300)[:, None]
        return point, t, plane_normal(t)

    return s_v, at


def path_coordinates(u_mm: np.ndarray, poly_mm: np.ndarray):
    """Each point's place against the path: arc length σ of its nearest point on the
    polyline, the frame function of :func:`polyline_frame`, the unit tangent and XY normal
    there, its offset μ along that normal [mm] and the rest of its offset (out of the
    plane)."""
    foot, _, _ = nearest_on_polyline(u_mm, poly_mm)
    seg = nearest_on_polyline.segment
    s_v, at = polyline_frame(poly_mm)
    sigma = s_v[seg] + np.sqrt(np.sum((foot - poly_mm[seg]) ** 2, axis=1))
    point, t, m = at(sigma)
    off = u_mm - point
    mu = np.einsum("ij,ij->i", off, m)
    return sigma, at, t, m, mu, off - mu[:, None] * m


def into_tube(u_mm: np.ndarray, poly_mm: np.ndarray, tube_mm: np.ndarray) -> np.ndarray:
    """``u_mm`` projected into the ball of radius ``tube_mm`` about its nearest path point
    (the exact tube: its distance to ``poly_mm`` is then at most the tube)."""
    foot, dist, _ = nearest_on_polyline(u_mm, poly_mm)
    scale = np.minimum(1.0, tube_mm / np.where(dist > 0.0, dist, 1.0))
    return foot + (u_mm - foot) * scale[:, None]
