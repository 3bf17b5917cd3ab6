"""PH quintic corner blends for junctions of lines and arcs (G64 P; SPEC §4, §10).

A corner is the junction of two consecutive path geometries (line or arc) where the tangent
jumps. :func:`blend_corner` trims d off the end of the first and d off the start of the
second and joins the two cut points by a planar PH quintic r(ξ) = p0 + ∫ w² (SPEC §4) whose
ends match the path's points, tangents and (where possible) curvatures. The trim is chosen so
that the Hausdorff distance between the blend and the corner path it replaces is just below
the tolerance: the largest blend, hence the fastest corner, that the tolerance allows.

The planar construction, its deviation and the trim search are in
:mod:`nurbscnc.geometry.phcorner`; many line–line corners at once in
:mod:`nurbscnc.geometry.lineblends`; corners out of one plane in
:mod:`nurbscnc.geometry.spaceblend`; the shared limits in :mod:`nurbscnc.geometry.blendrules`.


Caller's rule (the planner applies it)
--------------------------------------
Blends must not overlap each other or consume more than half of a short segment: pass
``max_trim_a_mm`` = half the length of segment a and ``max_trim_b_mm`` = half the length of
segment b (a segment with blends at both ends thus gives each at most half of itself).
None means "no blend": stop exactly at the corner (reversal, non-planar corner such as a
helix or an arc out of the line's plane, other geometry kinds, degenerate trims), or, for a
turning below :data:`MIN_TURNING_RAD`, treat the junction as smooth.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbscnc.errors import GeometryError
from nurbscnc.geometry.blendrules import (
    MIN_REVERSAL_RAD,
    MIN_TRIM_MM,
    MIN_TURNING_RAD,
    N_ARC,
    SEARCH_WINDOW,
    TRIM_CAP_FACTOR,
    line_deviation_per_trim,
)
from nurbscnc.geometry.lineblends import LineBlends as LineBlends
from nurbscnc.geometry.lineblends import line_corner_blends as line_corner_blends
from nurbscnc.geometry.lineblends import ph_tables as ph_tables
from nurbscnc.geometry.paths import ArcGeometry, LineGeometry
from nurbscnc.geometry.ph import PHQuintic, plane_frame
from nurbscnc.geometry.phcorner import (
    XI,
    Corner,
    cross3,
    derivatives_at_length,
    search_trim,
    unit_vector,
)
from nurbscnc.geometry.spaceblend import SpaceBlend as SpaceBlend
from nurbscnc.geometry.spaceblend import blend_space_corner as blend_space_corner
from nurbscnc.geometry.spaceblend import blend_space_corners as blend_space_corners

# The blends of every kind are imported from here (the planner, plan/pieces.py): the
# "X as X" imports above re-export those of lineblends.py and spaceblend.py.


@dataclass(frozen=True, eq=False)
class Blend:
    """A corner blend.

    ``ph`` the PH quintic (3-D embedded) from the point at arc length L_a − ``trim_a_mm`` of
    the first geometry to the point at arc length ``trim_b_mm`` of the second [mm];
    ``deviation_mm`` the measured Hausdorff distance to the corner path it replaces [mm];
    ``kappa_max_per_mm`` its largest |curvature| [1/mm]; ``turning_deg`` the tangent turning
    at the programmed vertex [deg], in (0, 180); ``kappa_jump_per_mm`` the larger curvature
    mismatch at its two ends [1/mm] (0 to rounding where the blend is G2).
    """

    ph: PHQuintic
    trim_a_mm: float
    trim_b_mm: float
    deviation_mm: float
    kappa_max_per_mm: float
    turning_deg: float
    kappa_jump_per_mm: float = 0.0


class SubCurve:
    """The stretch ``u_a``..``u_b`` of a NURBS curve or PH quintic (a planner piece) as a
    geometry of its own for :func:`blend_corner`: arc length measured from ``u_a`` (where the
    curve's own arc length is ``s_a_mm``), ``length_mm`` long. Its corner side is measured as
    a 33-point polyline, as a spiral arc's (``is_spiral``)."""

    is_spiral = True

    def __init__(self, geometry, u_a: float, u_b: float, s_a_mm: float, length_mm: float):
        self.geometry, self.u_a, self.u_b = geometry, float(u_a), float(u_b)
        self.s_a_mm, self.length_mm = float(s_a_mm), float(length_mm)
        self.u_start, self.u_end = self.u_a, self.u_b

    def param_at_length(self, s_mm) -> np.ndarray:
        s = np.clip(np.asarray(s_mm, dtype=float), 0.0, self.length_mm)
        u = np.asarray(self.geometry.param_at_length(self.s_a_mm + s), dtype=float)
        return np.clip(u, self.u_a, self.u_b)

    def derivatives(self, u, order: int) -> np.ndarray:
        return self.geometry.derivatives(np.asarray(u, dtype=float), order)

    def point(self, u) -> np.ndarray:
        return self.derivatives(u, 0)[0]


def sub_ph(ph: PHQuintic, xi0: float, xi1: float) -> PHQuintic:
    """The part ξ ∈ [xi0, xi1] of ``ph`` as a PH quintic of its own (ξ' ∈ [0, 1], exact).

    With Δ = xi1 − xi0, r̃(t) = r(xi0 + Δt) has hodograph Δ w(xi0 + Δt)² = w̃(t)², so the new
    preimage w̃ = √Δ w(xi0 + Δt) is quadratic in t: Bernstein coefficients w̃(0), w̃(0) +
    w̃′(0)/2, w̃(1) with w̃′(0) = √Δ Δ w′(xi0)."""
    delta = float(xi1) - float(xi0)
    root = np.sqrt(delta)
    ends = ph.preimage(np.array([xi0, xi1]))
    dw0 = ph.preimage_derivative(np.array([xi0]))[0]
    w = root * np.array([ends[0], ends[0] + 0.5 * delta * dw0, ends[1]])
    p0 = ph.point(np.array([xi0]))[0]
    return PHQuintic(w, p0, ph.origin_mm, ph.e1, ph.e2)


def planar_kind(geom, normal: np.ndarray, vertex_mm: np.ndarray | None = None) -> bool:
    """A line, a non-helical arc whose plane is the corner plane (normal ``normal``), or a
    :class:`SubCurve` whose 33 sample points lie in the plane through ``vertex_mm`` (to
    1e-9 of the coordinates' scale)."""
    if isinstance(geom, LineGeometry):
        return True
    if isinstance(geom, ArcGeometry):
        flat = abs(geom.helix_mm) <= 1e-12 * max(1.0, geom.radius_start_mm)
        return flat and bool(np.linalg.norm(cross3(geom.normal, normal)) <= 1e-9)
    if isinstance(geom, SubCurve) and vertex_mm is not None:
        pts = geom.point(np.linspace(geom.u_a, geom.u_b, N_ARC))
        scale = max(1.0, float(np.abs(pts).max()))
        return bool(np.abs((pts - vertex_mm) @ normal).max() <= 1e-9 * scale)
    return False


def blend_corner(
    geom_a,
    geom_b,
    tolerance_mm: float,
    max_trim_a_mm: float,
    max_trim_b_mm: float,
    measure: bool = True,
) -> Blend | None:
    """The largest PH quintic blend of the corner within ``tolerance_mm`` [mm]
    (:mod:`nurbscnc.geometry.phcorner`).

    ``geom_a``, ``geom_b``: consecutive LineGeometry / ArcGeometry / :class:`SubCurve` (a
    NURBS or PH piece); a ends where b starts.
    The trims are equal, d_a = d_b = d ≤ min(max trims, lengths) [mm], with the measured
    Hausdorff deviation in [(1 − 0.005) tol, tol] unless d reached its cap. None for smooth
    (turning < 1e-6 rad) and reversed (> π − 1e-6 rad) junctions, non-planar corners
    (helices, arcs out of the corner plane), other geometry kinds, a zero tolerance and
    degenerate trims (< 1e-9 mm). Raises :class:`GeometryError` for a negative or non-finite
    tolerance and for geometries that do not meet.

    ``measure=False`` skips the dense measurement for line–line corners (about half their
    cost) and reports the closed form d · :func:`line_deviation_per_trim` (θ) instead, which
    the tests check against an independent dense Hausdorff distance to 1e-9 relative;
    corners with arcs are always measured.
    """
    tol = float(tolerance_mm)
    if not np.isfinite(tol) or tol < 0.0:
        raise GeometryError(f"blend tolerance must be finite and ≥ 0, got {tolerance_mm!r} mm")
    len_a, len_b = float(geom_a.length_mm), float(geom_b.length_mm)
    d_max = min(float(max_trim_a_mm), float(max_trim_b_mm), len_a, len_b)
    if tol == 0.0 or not d_max > MIN_TRIM_MM:
        return None
    end_a = derivatives_at_length(geom_a, len_a, 1)
    start_b = derivatives_at_length(geom_b, 0.0, 1)
    vertex = end_a[0]
    scale = max(1.0, float(np.abs(vertex).max()))
    gap = float(np.sqrt((vertex - start_b[0]) @ (vertex - start_b[0])))
    if gap > 1e-6 * scale:
        raise GeometryError(f"blend_corner: the geometries do not meet (gap {gap:.3g} mm)")
    t_a, t_b = unit_vector(end_a[1]), unit_vector(start_b[1])
    n_c = cross3(t_a, t_b)
    turning = float(np.arctan2(np.sqrt(n_c @ n_c), t_a @ t_b))
    if turning < MIN_TURNING_RAD or turning > np.pi - MIN_REVERSAL_RAD:
        return None
    n_c = unit_vector(n_c)
    if not (planar_kind(geom_a, n_c, vertex) and planar_kind(geom_b, n_c, vertex)):
        return None
    origin, e1, e2 = plane_frame(
        np.array([vertex - t_a, vertex, vertex + t_b]), tol_mm=1e-12 * scale
    )
    rel = vertex - origin
    corner = Corner(
        geom_a, geom_b, len_a, origin, e1, e2, cross3(e1, e2), complex(rel @ e1, rel @ e2)
    )

    d_line = tol * (1.0 - 0.5 * SEARCH_WINDOW) / line_deviation_per_trim(turning)
    d_cap = min(d_max, TRIM_CAP_FACTOR * d_line)
    d_enough = 0.5 * min(d_line, d_cap)  # a G2 blend this long is preferred to any G1 one
    both_lines = isinstance(geom_a, LineGeometry) and isinstance(geom_b, LineGeometry)
    per_trim = line_deviation_per_trim(turning) if both_lines and not measure else None
    best = search_trim(corner, tol, d_line, d_cap, g2=True, d_floor=d_enough, dev_per_trim=per_trim)
    if not both_lines and (best is None or best.trim_mm < d_enough):
        g1 = search_trim(corner, tol, d_line, d_cap, g2=False)
        if g1 is not None and (best is None or g1.trim_mm > best.trim_mm):
            best = g1
    if best is None or best.trim_mm <= MIN_TRIM_MM:
        return None
    k = np.abs(best.ph.curvature(XI))
    return Blend(
        best.ph,
        best.trim_mm,
        best.trim_mm,
        best.deviation_mm,
        _kappa_max(k),
        float(np.degrees(turning)),
        best.kappa_jump_per_mm,
    )


def _kappa_max(k: np.ndarray) -> float:
    """max of samples ``k`` of |κ| on the uniform ξ grid, the peak refined by a parabola."""
    i = int(np.argmax(k))
    if 0 < i < k.size - 1:
        km, k0, kp = k[i - 1], k[i], k[i + 1]
        denom = km - 2.0 * k0 + kp
        if denom < 0.0:
            return float(k0 - 0.125 * (kp - km) ** 2 / denom)
    return float(k[i])
