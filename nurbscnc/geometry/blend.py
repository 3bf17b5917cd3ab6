"""PH quintic corner blends for junctions of lines and arcs (G64 P, issue 7; SPEC §4, §10).

A corner is the junction of two consecutive path geometries (line or arc) where the tangent
jumps. :func:`blend_corner` trims d off the end of the first and d off the start of the
second and joins the two cut points by a planar PH quintic r(ξ) = p0 + ∫ w² (SPEC §4) whose
ends match the path's points, tangents and (where possible) curvatures. The trim is chosen so
that the Hausdorff distance between the blend and the corner path it replaces is just below
the tolerance: the largest blend, hence the fastest corner, that the tolerance allows.

Construction (G2 Hermite data, a 2 × 2 real solve)
----------------------------------------------------
Write w0 = α e0, w2 = β e2 with e0 = √t0, e2 = ±√t1 (unit complex; t0, t1 the unit tangents
at the cut points in plane coordinates; the sign of e2 makes Re(ē0 e2) > 0, so the tangent
turns the short way). The end curvatures of a PH quintic are (κ = 2 Im(w̄ w′)/|w|⁴, SPEC §4)

    κ(0) = 4 Im(w̄0 w1)/|w0|⁴,    κ(1) = −4 Im(w̄2 w1)/|w2|⁴,

linear in w1. Given α, β > 0, prescribing κ(0) = k0 and κ(1) = k1 (the path's signed
curvatures at the cut points) fixes w1 = (A e2 − B e0)/Im(ē0 e2) with A = k0 α³/4,
B = −k1 β³/4. The end-point condition 5(p5 − p0) = w0² + w0w1 + (2w1² + w0w2)/3 + w1w2 + w2²
leaves two real equations for (α, β).

* Line–line corners (k0 = k1 = 0): w1 = 0 and the equations have a closed-form solution:
  with p5 − p0 = x t0 + y t1 and c = Re(ē0 e2) = cos(θ/2) (θ the turning),
  α²/5 + αβ/(30c) = x, β²/5 + αβ/(30c) = y (one positive root of a quadratic in β/α). The
  blend is **G2** with the lines: κ = 0 at both ends exactly, and
  κ(ξ) = 4ξ(1 − ξ) Im(w̄0 w2)/|w|⁴ keeps one sign (no inflection). It scales with d, so the
  deviation is d times a function of θ (:func:`line_deviation_per_trim`).
* Corners with an arc: damped Newton (analytic Jacobian) from the line solution, directly at
  the full curvatures, else continued through 0.25, 0.5, 0.75, 1 of them. Where it converges
  the blend is **G2** with the arc as well. It does for small enough trims (the arc's
  curvature is then a small perturbation); for large trims into tight arcs no such PH quintic
  exists. The search (below) first looks for the largest G2 blend; if it is shorter than half
  the line estimate, the G1 family (the w1 = 0 quintic: κ = 0 at both ends, a curvature jump
  of the arc's |κ| at its end, as a plain line–arc junction has) is searched too and the
  longer trim wins. ``kappa_jump_per_mm`` reports what was achieved (0 to rounding when G2).

The final w1 is the root of eq. 21 nearest the Newton value, so the end point is met to
rounding whatever the Newton residual (the curvature match is to Newton's accuracy, ~1e-14).
A candidate is rejected if its tangent turns other than the short way (a loop) or its
parametric speed nearly vanishes (a cusp).

Deviation and search
--------------------
The deviation is the Hausdorff distance between the blend and the corner path (cut point on
a → vertex → cut point on b), in the corner plane: from 129 blend samples to the path
(exact distances to lines and circular arcs; spiral arcs as 33-point polylines) and from the
path (its ends, the vertex, 33 points per arc) to the blend (nearest sample refined by Newton
on Re(conj(r − q) r′) = 0; distances to true blend points, so never underestimated). For a
convex blend it is the vertex's distance to the blend. A deviation is accepted up to
tol(1 − 1e-6), a margin for the sampling (below 1e-8 relative in the tests).
The trim d = d_a = d_b starts at the line estimate tol / (deviation per trim) and is updated
by secant steps on deviation(d) = tol(1 − 0.0025), safeguarded by bisection, until
tol(1 − 0.005) ≤ deviation ≤ tol, the trim reaches its cap, or the bracket is 2 % wide.
Line corners take one evaluation (the estimate is exact). The cap is min(max trims, lengths,
4 × the line estimate): an arc curving away from the corner can keep the deviation under the
tolerance for any trim, and such blends would swallow the arc.

Corners out of one plane
------------------------
A helix meeting a line (or an arc leaving the corner plane) cannot be met by a planar PH
quintic at both cut points. :func:`blend_space_corner` joins them by a quintic Bézier that is
G2 with both sides (:func:`space_bezier`: end tangents and curvature vectors), a NURBS piece
for the planner (arc length by its table, not in closed form), with the same equal-trim
search and a two-way sampled Hausdorff deviation (:data:`MAX_EVALS` blends at most).

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
from nurbscnc.geometry.paths import ArcGeometry, LineGeometry
from nurbscnc.geometry.ph import PHQuintic, hermite_ph, plane_frame

#: Junctions turning less than this [rad] are smooth (the planner's SMOOTH_JUNCTION_RAD).
MIN_TURNING_RAD = 1e-6
#: Junctions turning more than π minus this [rad] are reversals: no blend, exact stop.
MIN_REVERSAL_RAD = 1e-6
#: Trims shorter than this [mm] are degenerate: no blend.
MIN_TRIM_MM = 1e-9
#: Relative window below the tolerance where the search stops.
SEARCH_WINDOW = 0.005
#: Relative width of the trim bracket [lo, hi] where the search gives up (the deviation
#: stays below the window there, e.g. where the G2 family ends).
BRACKET_REL = 0.02
#: Most blends built per search.
MAX_EVALS = 16
#: Trim cap as a multiple of the line-corner estimate.
TRIM_CAP_FACTOR = 4.0

#: Least parametric speed σ = |C′(ξ)| of a regular blend, as a fraction of its mean (the
#: length L). A blend slower than this somewhere is a near cusp: between two arcs (R 1 and
#: R 2 mm, a 7° break) a G2 blend with σ(0) = 0.9 % of L turned its curvature from 1 to
#: 11.5 /mm within 0.3 µm, a curvature slope (1.8e5 /mm²) no feed cap sampled along the
#: piece sees, and an axis broke its jerk limit by 16 %. The blends of the corpus and the
#: SPEC programs keep σ ≥ 28 % of L (measured); a family whose members are all slower is
#: left for the G1 family or a stop.
MIN_SPEED_RATIO = 0.05

_N_BLEND = 129
_N_ARC = 33
_XI = np.linspace(0.0, 1.0, _N_BLEND)
_LAMBDAS = (0.25, 0.5, 0.75, 1.0)


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


@dataclass(frozen=True, eq=False)
class _Corner:
    """What every candidate of one corner shares: geometries, a's length, the plane frame
    (origin, e1, e2, normal) and the vertex in plane coordinates."""

    geom_a: object
    geom_b: object
    length_a_mm: float
    origin_mm: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    normal: np.ndarray
    vertex_z: complex


@dataclass(frozen=True, eq=False)
class _Candidate:
    trim_mm: float
    ph: PHQuintic
    deviation_mm: float
    kappa_jump_per_mm: float


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b for 3-vectors (np.cross costs ~30 µs per call on tiny arrays)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])  # fmt: skip


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.sqrt(v @ v)


def _eval(geom, s_mm: float, order: int) -> np.ndarray:
    """Derivatives (order + 1, 3) of ``geom`` at arc length ``s_mm`` from its start."""
    return geom.derivatives(geom.param_at_length(np.array([s_mm])), order)[:, 0, :]


def line_deviation_per_trim(turning_rad):
    """Deviation / trim of the symmetric line–line blend (w1 = 0) turning by θ [mm/mm].

    In a frame with t0 = e^{−iθ/2}, t1 = e^{iθ/2} (bisector 1) and d = 1: α² = 30c/(6c + 1)
    (c = cos θ/2, module doc with x = y = 1), and by symmetry the blend point nearest the
    vertex p0 + t0 is r(½), r(½) − p0 = α²(31/160 t0 + 1/30 + 1/160 t1) (∫₀^½ of the three
    terms of w² = α²(e0²(1 − ξ)⁴ + 2e0e2 ξ²(1 − ξ)² + e2² ξ⁴)). Elementwise on arrays (a
    float for a scalar).
    """
    th = np.asarray(turning_rad, dtype=float)
    c = np.cos(0.5 * th)
    t0, t1 = np.exp(-0.5j * th), np.exp(0.5j * th)
    a2 = 30.0 * c / (6.0 * c + 1.0)
    out = np.abs(t0 - a2 * (31.0 / 160.0 * t0 + 1.0 / 30.0 + 1.0 / 160.0 * t1))
    return float(out) if out.ndim == 0 else out


def _w_line(dp: complex, e0: complex, e2: complex) -> tuple[float, float] | None:
    """(α, β) of the w1 = 0 PH quintic with chord ``dp`` (closed form, module doc)."""
    t0, t1 = e0 * e0, e2 * e2
    # dp = x t0 + y t1 (Cramer's rule on Im(t̄0 ·) and Im(t̄1 ·)).
    det = (t0.conjugate() * t1).imag
    x = -(t1.conjugate() * dp).imag / det
    y = (t0.conjugate() * dp).imag / det
    if not (x > 0.0 and y > 0.0):
        return None
    k = 1.0 / (30.0 * (e0.conjugate() * e2).real)
    # (x/5) r² + k(x − y) r − y/5 = 0 for r = β/α: the positive root, without cancellation.
    qa, qb, qc = 0.2 * x, k * (x - y), -0.2 * y
    disc = np.sqrt(qb * qb - 4.0 * qa * qc)
    r = (-2.0 * qc) / (qb + disc) if qb >= 0.0 else (disc - qb) / (2.0 * qa)
    alpha = float(np.sqrt(x / (0.2 + k * r)))
    return alpha, alpha * r


def _w1(e0: complex, e2: complex, k0: float, k1: float, a: float, b: float) -> complex:
    """w1 giving κ(0) = k0, κ(1) = k1 for w0 = a e0, w2 = b e2 (module doc)."""
    return (0.25 * k0 * a**3 * e2 + 0.25 * k1 * b**3 * e0) / (e0.conjugate() * e2).imag


def _w_g2(dp, e0, e2, k0, k1, ab0, max_iter: int = 30):
    """(α, β) of the PH quintic with chord ``dp`` and end curvatures k0, k1, by damped
    Newton from ``ab0``; None if it does not converge at α, β > 0."""
    s = (e0.conjugate() * e2).imag
    scale = 5.0 * abs(dp)

    def residual(a, b):
        w0, w1, w2 = a * e0, _w1(e0, e2, k0, k1, a, b), b * e2
        f = w0 * w0 + w0 * w1 + (2.0 * w1 * w1 + w0 * w2) / 3.0 + w1 * w2 + w2 * w2 - 5.0 * dp
        return f, w0, w1, w2

    a, b = ab0
    f, w0, w1, w2 = residual(a, b)
    for _ in range(max_iter):
        if abs(f) <= 1e-14 * scale:
            return a, b
        fw1 = w0 + 4.0 * w1 / 3.0 + w2  # ∂F/∂w1; ∂F/∂w0, ∂F/∂w2 below
        dfa = (2.0 * w0 + w1 + w2 / 3.0) * e0 + fw1 * (0.75 * k0 * a * a * e2 / s)
        dfb = (w0 / 3.0 + w1 + 2.0 * w2) * e2 + fw1 * (0.75 * k1 * b * b * e0 / s)
        det = dfa.real * dfb.imag - dfb.real * dfa.imag
        if not (np.isfinite(det) and det != 0.0):
            return None
        da = -(f.real * dfb.imag - dfb.real * f.imag) / det
        db = -(dfa.real * f.imag - f.real * dfa.imag) / det
        step = 1.0
        for _ in range(20):  # damping: stay at α, β > 0 and reduce |F|
            an, bn = a + step * da, b + step * db
            if an > 0.0 and bn > 0.0:
                trial = residual(an, bn)
                if abs(trial[0]) < abs(f):
                    break
            step *= 0.5
        else:
            return None
        a, b = an, bn
        f, w0, w1, w2 = trial
    return (a, b) if abs(f) <= 1e-10 * scale else None


def _eq21_w1(dp: complex, w0: complex, w2: complex, near: complex) -> complex:
    """Root of eq. 21 nearest ``near``: w1 = −¾(w0 + w2) ± ¼√(120Δp − 15w0² − 15w2² + 10w0w2)."""
    root = 0.25 * np.sqrt(complex(120.0 * dp - 15.0 * (w0 * w0 + w2 * w2) + 10.0 * w0 * w2))
    base = -0.75 * (w0 + w2)
    return base + root if abs(base + root - near) <= abs(base - root - near) else base - root


def _signed_curvature(d: np.ndarray, normal: np.ndarray) -> float:
    """κ = (C′ × C″)·n / |C′|³ [1/mm] (positive: turning counter-clockwise about n)."""
    return float(_cross(d[1], d[2]) @ normal / np.sqrt(d[1] @ d[1]) ** 3)


def _to_plane(corner: _Corner, pts: np.ndarray) -> np.ndarray:
    """3-D points (m, 3) [mm] to complex corner-plane coordinates (the corner is planar)."""
    rel = pts - corner.origin_mm
    return rel @ corner.e1 + 1j * (rel @ corner.e2)


def _segment_distance(q: np.ndarray, a: complex, b: complex) -> np.ndarray:
    """Distance [mm] from the points ``q`` to the segment [a, b] (complex plane)."""
    ab = b - a
    ab2 = (ab * ab.conjugate()).real
    t = np.clip((np.conj(ab) * (q - a)).real / ab2, 0.0, 1.0) if ab2 > 0.0 else 0.0
    return np.abs(q - a - t * ab)


def _side(corner: _Corner, geom, s_from: float, s_to: float, z_from: complex,
          z_to: complex):
    """One side of the corner path from arc length ``s_from`` to ``s_to`` of ``geom``
    (end points ``z_from``, ``z_to``): its sample points (complex) and a function giving
    the distance from points to it (a line: exact; a circular arc: exact, ||q − c| − r|
    inside its angular span, else the nearer end; a spiral arc: a 33-point polyline)."""
    if isinstance(geom, LineGeometry):
        return np.array([z_from, z_to]), lambda q: _segment_distance(q, z_from, z_to)
    pts = _to_plane(corner, geom.point(geom.param_at_length(np.linspace(s_from, s_to,
                                                                        _N_ARC))))  # fmt: skip
    pts[0], pts[-1] = z_from, z_to
    if geom.is_spiral:
        def polyline(q):
            return np.min([_segment_distance(q, a, b) for a, b in zip(pts[:-1], pts[1:])],
                          axis=0)  # fmt: skip

        return pts, polyline
    center = _to_plane(corner, geom.origin_mm[None, :])[0]
    radius = geom.radius_start_mm
    # Counter-clockwise in the corner plane when the arc's own sense agrees with its normal.
    ccw = (geom.angle_rad > 0.0) == (float(geom.normal @ corner.normal) > 0.0)
    span = (s_to - s_from) / radius
    r_from = (z_from - center) / abs(z_from - center)

    def arc(q):
        rel = q - center
        psi = np.angle(rel * r_from.conjugate())  # (−π, π], from the start, CCW positive
        psi = np.mod(psi if ccw else -psi, 2.0 * np.pi)
        inside = psi <= span
        ends = np.minimum(np.abs(q - z_from), np.abs(q - z_to))
        return np.where(inside, np.abs(np.abs(rel) - radius), ends)

    return pts, arc


def _deviation(ph: PHQuintic, sides: list, vertex: complex) -> float:
    """Hausdorff distance [mm] between ``ph`` and the corner path (``sides``, module doc)."""
    r = ph.point(_XI)
    # Blend → path: each blend sample to the nearer side.
    h_blend = float(np.minimum(sides[0][1](r), sides[1][1](r)).max())
    # Path → blend: nearest blend sample, refined by Newton on g = Re(conj(r − q) r′) = 0.
    q = np.concatenate((sides[0][0], sides[1][0]))
    d2 = np.abs(r[None, :] - q[:, None]) ** 2
    nearest = np.argmin(d2, axis=1)
    best2 = d2[np.arange(q.size), nearest]
    xi = _XI[nearest]
    for _ in range(3):
        w = ph.preimage(xi)
        e = ph.point(xi) - q
        r1 = w * w
        g = (np.conj(e) * r1).real
        dg = np.abs(r1) ** 2 + (np.conj(e) * 2.0 * w * ph.preimage_derivative(xi)).real
        ok = dg > 0.0
        xi = np.clip(np.where(ok, xi - g / np.where(ok, dg, 1.0), xi), 0.0, 1.0)
    refined2 = np.abs(ph.point(xi) - q) ** 2
    h_path = float(np.sqrt(np.minimum(best2, refined2).max()))
    return max(h_blend, h_path)


def _regular(ph: PHQuintic, turn_rad: float) -> bool:
    """No loop (the tangent turns by ``turn_rad``, the short way) and no (near) cusp."""
    if abs(ph.turning_angle_rad() - turn_rad) > 1e-6:
        return False
    return bool(np.min(np.abs(ph.preimage(_XI)) ** 2) > MIN_SPEED_RATIO * ph.length_mm)


def _candidate(corner: _Corner, trim_mm: float, g2: bool,
               dev_per_trim: float | None = None) -> _Candidate | None:
    """The blend with trim ``trim_mm`` on both sides (G2 family or G1 family) and its
    measured deviation (or ``trim_mm · dev_per_trim`` if given: the line-corner closed
    form); None where the family has no regular member."""
    da = _eval(corner.geom_a, corner.length_a_mm - trim_mm, 2)
    db = _eval(corner.geom_b, trim_mm, 2)
    e1, e2, origin = corner.e1, corner.e2, corner.origin_mm
    z_a = complex((da[0] - origin) @ e1, (da[0] - origin) @ e2)
    z_b = complex((db[0] - origin) @ e1, (db[0] - origin) @ e2)
    t_a, t_b = complex(da[1] @ e1, da[1] @ e2), complex(db[1] @ e1, db[1] @ e2)
    t_a, t_b = t_a / abs(t_a), t_b / abs(t_b)
    u0, u2 = np.sqrt(t_a), np.sqrt(t_b)
    if (u0.conjugate() * u2).real < 0.0:
        u2 = -u2
    cos_half = (u0.conjugate() * u2).real
    if abs((u0.conjugate() * u2).imag) < 1e-12 or cos_half <= 1e-12:
        return None  # parallel or reversed end tangents
    k_a = _signed_curvature(da, corner.normal)
    k_b = _signed_curvature(db, corner.normal)
    dp = z_b - z_a
    ab = _w_line(dp, u0, u2)
    curved = k_a != 0.0 or k_b != 0.0
    ph = None
    if ab is not None:
        k0 = k1 = 0.0
        if g2 and curved:
            full = _w_g2(dp, u0, u2, k_a, k_b, ab)
            if full is None:  # continuation in the curvatures
                for lam in _LAMBDAS:
                    full = _w_g2(dp, u0, u2, lam * k_a, lam * k_b, ab)
                    if full is None:
                        return None
                    ab = full
            ab, k0, k1 = full, k_a, k_b
        a, b = ab
        w0, w2 = a * u0, b * u2
        w1 = _eq21_w1(dp, w0, w2, _w1(u0, u2, k0, k1, a, b))
        ph = PHQuintic(np.array([w0, w1, w2]), z_a, origin, e1, e2)
        if not _regular(ph, 2.0 * np.angle(u0.conjugate() * u2)):
            return None
    elif g2 and curved:
        return None
    else:  # the chord leaves the tangents' cone: the standard Hermite interpolant, G1
        chord = abs(dp)
        ph = hermite_ph(z_a, z_b, chord * t_a, chord * t_b, origin, e1, e2)
        if not _regular(ph, ph.turning_angle_rad()):
            return None
    kappa_ends = ph.curvature(np.array([0.0, 1.0]))
    jump = float(max(abs(kappa_ends[0] - k_a), abs(kappa_ends[1] - k_b)))
    if dev_per_trim is not None:
        return _Candidate(trim_mm, ph, trim_mm * dev_per_trim, jump)
    z_v = corner.vertex_z
    sides = [_side(corner, corner.geom_a, corner.length_a_mm - trim_mm, corner.length_a_mm,
                   z_a, z_v),
             _side(corner, corner.geom_b, 0.0, trim_mm, z_v, z_b)]  # fmt: skip
    return _Candidate(trim_mm, ph, _deviation(ph, sides, z_v), jump)


def _search(corner: _Corner, tol: float, d_start: float, d_cap: float, g2: bool,
            d_floor: float = 0.0, dev_per_trim: float | None = None) -> _Candidate | None:
    """Largest trim ≤ ``d_cap`` with deviation ≤ ``tol`` (secant + bisection, module doc);
    gives up once the family has no member at a trim ≤ ``d_floor``."""
    target = tol * (1.0 - 0.5 * SEARCH_WINDOW)
    # Accept a measured deviation up to tol(1 − 1e-6): margin for the sampled parts of the
    # measurement (blend samples, arc polylines), which are below 1e-8 relative here.
    tol = tol * (1.0 - 1e-6)
    d = min(d_start, d_cap)
    lo, hi = 0.0, np.inf
    best: _Candidate | None = None
    prev = None
    for _ in range(MAX_EVALS):
        cand = _candidate(corner, d, g2, dev_per_trim)
        dev = cand.deviation_mm if cand is not None else None
        if dev is not None and dev <= tol:
            lo, best = d, cand
            if dev >= (1.0 - SEARCH_WINDOW) * tol or d >= d_cap:
                break
        else:
            hi = d
            if cand is None and d <= d_floor:
                break
        d_next = np.nan
        if dev is not None and dev > 0.0:
            if prev is not None and prev[1] != dev:  # secant through the last two
                d_next = d + (target - dev) * (d - prev[0]) / (dev - prev[1])
            else:  # deviation ∝ trim
                d_next = d * target / dev
            prev = (d, dev)
        d_next = min(d_next, d_cap)
        if not lo < d_next < hi:
            d_next = 0.5 * (lo + hi) if np.isfinite(hi) else d_cap
        if np.isfinite(hi) and hi - lo <= BRACKET_REL * hi:
            break
        d = d_next
    return best


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


def _planar_kind(geom, normal: np.ndarray, vertex_mm: np.ndarray | None = None) -> bool:
    """A line, a non-helical arc whose plane is the corner plane (normal ``normal``), or a
    :class:`SubCurve` whose 33 sample points lie in the plane through ``vertex_mm`` (to
    1e-9 of the coordinates' scale)."""
    if isinstance(geom, LineGeometry):
        return True
    if isinstance(geom, ArcGeometry):
        flat = abs(geom.helix_mm) <= 1e-12 * max(1.0, geom.radius_start_mm)
        return flat and bool(np.linalg.norm(_cross(geom.normal, normal)) <= 1e-9)
    if isinstance(geom, SubCurve) and vertex_mm is not None:
        pts = geom.point(np.linspace(geom.u_a, geom.u_b, _N_ARC))
        scale = max(1.0, float(np.abs(pts).max()))
        return bool(np.abs((pts - vertex_mm) @ normal).max() <= 1e-9 * scale)
    return False


def blend_corner(geom_a, geom_b, tolerance_mm: float, max_trim_a_mm: float,
                 max_trim_b_mm: float, measure: bool = True) -> Blend | None:
    """The largest PH quintic blend of the corner within ``tolerance_mm`` [mm] (module doc).

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
    end_a = _eval(geom_a, len_a, 1)
    start_b = _eval(geom_b, 0.0, 1)
    vertex = end_a[0]
    scale = max(1.0, float(np.abs(vertex).max()))
    gap = float(np.sqrt((vertex - start_b[0]) @ (vertex - start_b[0])))
    if gap > 1e-6 * scale:
        raise GeometryError(f"blend_corner: the geometries do not meet (gap {gap:.3g} mm)")
    t_a, t_b = _unit(end_a[1]), _unit(start_b[1])
    n_c = _cross(t_a, t_b)
    turning = float(np.arctan2(np.sqrt(n_c @ n_c), t_a @ t_b))
    if turning < MIN_TURNING_RAD or turning > np.pi - MIN_REVERSAL_RAD:
        return None
    n_c = _unit(n_c)
    if not (_planar_kind(geom_a, n_c, vertex) and _planar_kind(geom_b, n_c, vertex)):
        return None
    origin, e1, e2 = plane_frame(np.array([vertex - t_a, vertex, vertex + t_b]),
                                 tol_mm=1e-12 * scale)  # fmt: skip
    rel = vertex - origin
    corner = _Corner(geom_a, geom_b, len_a, origin, e1, e2, _cross(e1, e2),
                     complex(rel @ e1, rel @ e2))

    d_line = tol * (1.0 - 0.5 * SEARCH_WINDOW) / line_deviation_per_trim(turning)
    d_cap = min(d_max, TRIM_CAP_FACTOR * d_line)
    d_enough = 0.5 * min(d_line, d_cap)  # a G2 blend this long is preferred to any G1 one
    both_lines = isinstance(geom_a, LineGeometry) and isinstance(geom_b, LineGeometry)
    per_trim = line_deviation_per_trim(turning) if both_lines and not measure else None
    best = _search(corner, tol, d_line, d_cap, g2=True, d_floor=d_enough,
                   dev_per_trim=per_trim)  # fmt: skip
    if not both_lines and (best is None or best.trim_mm < d_enough):
        g1 = _search(corner, tol, d_line, d_cap, g2=False)
        if g1 is not None and (best is None or g1.trim_mm > best.trim_mm):
            best = g1
    if best is None or best.trim_mm <= MIN_TRIM_MM:
        return None
    k = np.abs(best.ph.curvature(_XI))
    return Blend(best.ph, best.trim_mm, best.trim_mm, best.deviation_mm, _kappa_max(k),
                 float(np.degrees(turning)), best.kappa_jump_per_mm)


def _kappa_max(k: np.ndarray) -> float:
    """max of samples ``k`` of |κ| on the uniform ξ grid, the peak refined by a parabola."""
    i = int(np.argmax(k))
    if 0 < i < k.size - 1:
        km, k0, kp = k[i - 1], k[i], k[i + 1]
        denom = km - 2.0 * k0 + kp
        if denom < 0.0:
            return float(k0 - 0.125 * (kp - km) ** 2 / denom)
    return float(k[i])


# ---------------------------------------------------------------------------------------------
# Many line–line corners at once (CAM polylines)
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class LineBlends:
    """PH quintic blends of m line–line corners, as arrays (one row a corner).

    ``ok`` (m,) where a blend exists (else the row's other values are meaningless);
    ``trim_a_mm``, ``trim_b_mm`` (m,) cut off the end of the first line and the start of the
    second [mm]; ``w`` (m, 3) complex preimage (α e0, 0, β e2) [√mm]; ``p0`` (m,) complex
    start point in plane coordinates [mm]; ``origin_mm`` (m, 3) (the vertex), ``e1``, ``e2``
    (m, 3) the plane frame; ``turning_rad`` (m,) θ; ``deviation_mm`` (m,) the Hausdorff
    distance to the corner path (symmetric trims: d · :func:`line_deviation_per_trim` (θ),
    exact; unequal trims: |r(½) − V|, a bound from above); ``kappa_max_per_mm`` (m,) the
    peak curvature [1/mm].
    """

    ok: np.ndarray
    trim_a_mm: np.ndarray
    trim_b_mm: np.ndarray
    w: np.ndarray
    p0: np.ndarray
    origin_mm: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    turning_rad: np.ndarray
    deviation_mm: np.ndarray
    kappa_max_per_mm: np.ndarray


def _rows_dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", a, b)


def _line_ab(x: np.ndarray, y: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(α, β) of the w1 = 0 quintic with chord x τ_a + y τ_b (:func:`_w_line`, vectorised)."""
    k = 1.0 / (30.0 * c)
    qa, qb, qc = 0.2 * x, k * (x - y), -0.2 * y
    disc = np.sqrt(qb * qb - 4.0 * qa * qc)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.where(qb >= 0.0, (-2.0 * qc) / (qb + disc), (disc - qb) / (2.0 * qa))
    alpha = np.sqrt(x / (0.2 + k * r))
    return alpha, alpha * r


def _kappa_peak(alpha, beta, c, s, iterations: int = 30) -> np.ndarray:
    """max over ξ of κ = 4αβ s ξ(1 − ξ) / Q², Q = α²(1 − ξ)⁴ + β²ξ⁴ + 2αβc ξ²(1 − ξ)²
    (the curvature of w = α e0 (1 − ξ)² + β e2 ξ²), by bisection on the derivative of
    ln ξ + ln(1 − ξ) − 2 ln Q, which falls from +∞ to −∞ once (one maximum: checked on
    wide random samples; the tests compare with dense sampling). κ is stationary at its
    peak, so an error δ in ξ moves κ by O(δ²): 30 halvings (δ = 2^-30 ≈ 1e-9) give κ to
    rounding (within 1.2e-15 of 52 halvings on 150,000 random blends, as 40 and 52 differ
    among themselves), in 0.6 of the time."""
    lo = np.zeros_like(alpha)
    hi = np.ones_like(alpha)
    a2, b2, ab = alpha * alpha, beta * beta, alpha * beta * c
    a4, b4, ab4 = 4.0 * a2, 4.0 * b2, 4.0 * ab
    # Powers as products (numpy's x**3, x**4 call libm pow per element: 5× slower; the
    # products round differently in the last bit, which moves the root by an ulp at most).
    # The loop below evaluates, operation for operation (the same bits), x = (lo + hi)/2,
    # u = 1 − x, q = a²(u²u²) + b²(x²x²) + (2ab) x² u², dq = (−4a²)(u²u) + 4b²(x²x)
    # + 4ab x u (u − x) and rising = 1/x − 1/u − 2 dq/q > 0, in preallocated buffers.
    ab2, na4 = 2.0 * ab, -a4
    x, u, x2, u2, q, dq, w = (np.empty_like(alpha) for _ in range(7))
    rising = np.empty(alpha.shape, dtype=bool)
    for _ in range(iterations):
        np.add(lo, hi, out=x)
        x *= 0.5
        np.subtract(1.0, x, out=u)
        np.multiply(x, x, out=x2)
        np.multiply(u, u, out=u2)
        np.multiply(u2, u2, out=q)
        q *= a2
        np.multiply(x2, x2, out=w)
        w *= b2
        q += w
        np.multiply(ab2, x2, out=w)
        w *= u2
        q += w
        np.multiply(u2, u, out=dq)
        np.multiply(na4, dq, out=dq)
        np.multiply(x2, x, out=w)
        w *= b4
        dq += w
        np.multiply(ab4, x, out=w)
        w *= u
        np.subtract(u, x, out=x2)  # x² is not needed any more this step
        w *= x2
        dq += w
        dq *= 2.0
        dq /= q
        np.divide(1.0, x, out=w)
        np.divide(1.0, u, out=u2)
        w -= u2
        w -= dq
        np.greater(w, 0.0, out=rising)
        np.copyto(lo, x, where=rising)
        np.logical_not(rising, out=rising)
        np.copyto(hi, x, where=rising)
    x = 0.5 * (lo + hi)
    u = 1.0 - x
    q = a2 * u**4 + b2 * x**4 + 2.0 * ab * x * x * u * u
    return 4.0 * alpha * beta * s * x * u / (q * q)


def line_corner_blends(vertex_mm, t_a, t_b, tolerance_mm, max_trim_a_mm,
                       max_trim_b_mm=None) -> LineBlends:  # fmt: skip
    """The blends of m line–line corners at once (the line path of CAM polylines).

    ``vertex_mm`` (m, 3) the corner points [mm]; ``t_a``, ``t_b`` (m, 3) the unit directions
    of the line ending and of the line starting there; ``tolerance_mm`` (m,) the blend
    tolerance [mm]; ``max_trim_a_mm``, ``max_trim_b_mm`` (m,) the largest trims allowed on
    each line [mm] (the caller's rule: half of each line; ``max_trim_b_mm`` None: the same as
    a, i.e. the symmetric blends :func:`blend_corner` gives line–line corners, to rounding).

    The trims: d = tol (1 − ½·SEARCH_WINDOW) / :func:`line_deviation_per_trim` (θ) — the
    trim the scalar search accepts at its first evaluation — capped on each side by its
    maximum: d_a = min(d, max_a), d_b = min(d, max_b). With cut points V − d_a t_a and
    V + d_b t_b the chord is x τ_a + y τ_b (x = d_a, y = d_b) and the w1 = 0 quintic has
    w0 = α e0, w2 = β e2 in closed form (module doc; e0 = √τ_a, e2 = ±√τ_b with
    Re(ē0 e2) = c = cos θ/2 > 0; τ the tangents in plane coordinates). It is G2 with both
    lines (κ = 0 at the ends) and convex. Equal trims give β = α, α² = 30cd / (6c + 1), and
    the curvature κ(ξ) = 4 s ξ(1 − ξ) / (α² f²), f = (1 − ξ)⁴ + ξ⁴ + 2c ξ²(1 − ξ)²
    (s = sin θ/2): with u = ξ(1 − ξ) ∈ [0, ¼], u/f² grows with u (its derivative has the
    sign of 1 + 4u − 6(1 + c)u², positive on [0, ¼]), so the peak is at ξ = ½:
    κ_max = 64 s / (α² (1 + c)²), and the deviation is exactly d · deviation per trim.
    Unequal trims (one line shorter than 2d: no sliver of line is left between two blends,
    so a polyline of short chords becomes a chain of blends): κ_max by bisection
    (:func:`_kappa_peak`), and the deviation bounded by the distance from the vertex to
    r(½) = p0 + (31/160) α² τ_a + (1/30) αβ e0e2 + (1/160) β² τ_b (the Hausdorff distance of
    a convex blend is the vertex's distance to it, which is at most that); if the bound
    exceeds the tolerance the row falls back to equal trims min(d_a, d_b).

    The plane: a corner in a coordinate plane (both tangents' components along its normal
    within 1e-12) gets that plane's axes (XY, ZX, YZ as :func:`plane_frame`), so the blend
    keeps the normal coordinate exactly; otherwise e1 = t_a, e2 = n × t_a. The origin is the
    vertex. ``ok`` is False, as :func:`blend_corner` returns None, for smooth and reversed
    junctions and trims ≤ MIN_TRIM_MM.
    """
    v = np.asarray(vertex_mm, dtype=float).reshape(-1, 3)
    ta = np.asarray(t_a, dtype=float).reshape(-1, 3)
    tb = np.asarray(t_b, dtype=float).reshape(-1, 3)
    m = v.shape[0]
    tol = np.broadcast_to(np.asarray(tolerance_mm, dtype=float), (m,))
    max_a = np.broadcast_to(np.asarray(max_trim_a_mm, dtype=float), (m,))
    max_b = max_a if max_trim_b_mm is None else np.broadcast_to(
        np.asarray(max_trim_b_mm, dtype=float), (m,))
    cross = np.cross(ta, tb)
    sin_t = np.sqrt(_rows_dot(cross, cross))
    turning = np.arctan2(sin_t, _rows_dot(ta, tb))
    ok = (turning >= MIN_TURNING_RAD) & (turning <= np.pi - MIN_REVERSAL_RAD) & (tol > 0.0)
    # Frame: coordinate planes first (XY, ZX, YZ: e1, e2 axes and the normal axis).
    e1 = np.empty((m, 3))
    e2 = np.empty((m, 3))
    free = np.ones(m, dtype=bool)
    for i, j, k in ((0, 1, 2), (2, 0, 1), (1, 2, 0)):
        lo = np.minimum(np.minimum(-ta[:, k], tb[:, k]), 0.0)
        hi = np.maximum(np.maximum(-ta[:, k], tb[:, k]), 0.0)
        sel = free & (hi - lo <= 1e-12)
        e1[sel] = np.eye(3)[i]
        e2[sel] = np.eye(3)[j]
        free &= ~sel
    if free.any():
        n = cross[free] / np.where(sin_t[free] > 0.0, sin_t[free], 1.0)[:, None]
        e1[free] = ta[free]
        e2[free] = np.cross(n, ta[free])
    tau_a = _rows_dot(ta, e1) + 1j * _rows_dot(ta, e2)
    tau_b = _rows_dot(tb, e1) + 1j * _rows_dot(tb, e2)
    with np.errstate(invalid="ignore", divide="ignore"):
        tau_a = tau_a / np.abs(tau_a)
        tau_b = tau_b / np.abs(tau_b)
        e0 = np.sqrt(tau_a)
        e2c = np.sqrt(tau_b)
        e2c = np.where((np.conj(e0) * e2c).real < 0.0, -e2c, e2c)
        rel = np.conj(e0) * e2c
        c = rel.real
        s = np.abs(rel.imag)
        ok &= (s >= 1e-12) & (c > 1e-12)
        c = np.where(ok, c, 1.0)
        dpt = np.asarray(line_deviation_per_trim(turning))
        d_line = tol * (1.0 - 0.5 * SEARCH_WINDOW) / dpt
        da = np.minimum(d_line, max_a)
        db = np.minimum(d_line, max_b)
        ok &= (np.minimum(max_a, max_b) > MIN_TRIM_MM) & (np.minimum(da, db) > MIN_TRIM_MM)
        da, db = np.where(ok, da, 1.0), np.where(ok, db, 1.0)
        alpha, beta = _line_ab(da, db, c)
        p0 = -da * tau_a
        mid = (p0 + (31.0 / 160.0) * alpha * alpha * tau_a + (alpha * beta / 30.0) * e0 * e2c
               + (1.0 / 160.0) * beta * beta * tau_b)  # fmt: skip
        dev = np.where(da == db, da * dpt, np.abs(mid))
        # Unequal trims beyond the tolerance: back to equal trims (exact closed form).
        back = (da != db) & (dev > tol * (1.0 - 1e-6))
        if back.any():
            d = np.minimum(da, db)
            da, db = np.where(back, d, da), np.where(back, d, db)
            a_b, b_b = _line_ab(d[back], d[back], c[back])
            alpha[back], beta[back] = a_b, b_b
            p0 = -da * tau_a
            dev = np.where(back, d * dpt, dev)
        kappa = 64.0 * s / (alpha * alpha * (1.0 + c) ** 2)
        uneq = np.flatnonzero(ok & (da != db))
        if uneq.size:
            kappa[uneq] = _kappa_peak(alpha[uneq], beta[uneq], c[uneq], s[uneq])
    w = np.zeros((m, 3), dtype=complex)
    w[:, 0] = alpha * e0
    w[:, 2] = beta * e2c
    return LineBlends(ok, da, db, w, p0, v, e1, e2, turning, dev, kappa)


def ph_tables(w: np.ndarray, p0: np.ndarray):
    """Control points (m, 6) complex, σ (m, 5) and s (m, 6) Bernstein coefficients [mm] and
    lengths (m,) [mm] of m PH quintics with preimages ``w`` (m, 3) and starts ``p0`` (m,).

    The formulas of :class:`PHQuintic` (SPEC §4), vectorised: each row equals the object's
    arrays to rounding (numpy's array complex arithmetic may fuse a multiply-add where the
    scalar path does not, so the last bit can differ).
    """
    w0, w1, w2 = w[:, 0], w[:, 1], w[:, 2]
    steps = np.stack([w0 * w0, w0 * w1, (2.0 * w1 * w1 + w0 * w2) / 3.0, w1 * w2, w2 * w2],
                     axis=1)  # fmt: skip
    points = p0[:, None] + np.concatenate((np.zeros((w.shape[0], 1)),
                                           np.cumsum(steps / 5.0, axis=1)), axis=1)  # fmt: skip
    sigma = np.stack([
        np.abs(w0) ** 2,
        (w0 * w1.conjugate()).real,
        (2.0 * np.abs(w1) ** 2 + (w0 * w2.conjugate()).real) / 3.0,
        (w1 * w2.conjugate()).real,
        np.abs(w2) ** 2,
    ], axis=1)  # fmt: skip
    s = np.concatenate((np.zeros((w.shape[0], 1)), np.cumsum(sigma / 5.0, axis=1)), axis=1)
    return points, sigma, s, s[:, -1].copy()


# ---------------------------------------------------------------------------------------------
# Corners out of one plane (a helix meeting a line, an arc leaving the corner plane).


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
    return np.stack([p_a, p_a + chord / 5.0 * t_a,
                     p_a + 2.0 * chord / 5.0 * t_a + chord * chord / 20.0 * k_a,
                     p_b - 2.0 * chord / 5.0 * t_b + chord * chord / 20.0 * k_b,
                     p_b - chord / 5.0 * t_b, p_b], axis=1)  # fmt: skip


def _polyline_distance(q: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Distance [mm] of each point of ``q`` (m, 3) to the polyline ``pts`` (n, 3)."""
    a, ab = pts[:-1], np.diff(pts, axis=0)
    ab2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300)
    rel = q[:, None, :] - a[None, :, :]
    f = np.clip(np.einsum("mnj,nj->mn", rel, ab) / ab2[None, :], 0.0, 1.0)
    diff = rel - f[..., None] * ab[None, :, :]
    # √ is monotone and correctly rounded: the root of the least square is the least root.
    return np.sqrt(np.einsum("mnj,mnj->mn", diff, diff).min(axis=1))


def blend_space_corner(geom_a, geom_b, tolerance_mm: float, max_trim_a_mm: float,
                       max_trim_b_mm: float) -> SpaceBlend | None:  # fmt: skip
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


# ---------------------------------------------------------------------------------------------
# Corners out of one plane, all at once (issue 14: per-piece work whole-array).


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
        return sum(comb(deg, i) * t**i * (1.0 - t) ** (deg - i) * pts[:, i : i + 1, :]
                   for i in range(deg + 1))  # fmt: skip

    d1 = 5 * np.diff(ctrl, axis=1)
    d2 = 4 * np.diff(d1, axis=1)
    return bern(5, ctrl), bern(4, d1), bern(3, d2)


def _polyline_distance_batch(q: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Distance [mm] (m, a) of each point of ``q`` (m, a, 3) to the polyline ``pts``
    (m, b, 3) of its own row: :func:`_polyline_distance` row by row (one 4-D einsum over
    all rows moved 30 MB per call and was slower than the rows' own small ones)."""
    return np.stack([_polyline_distance(qi, pi) for qi, pi in zip(q, pts)])


def blend_space_corners(path, rows_a, rows_b, tolerance_mm, max_trim_a_mm,
                        max_trim_b_mm) -> list[SpaceBlend | None]:  # fmt: skip
    """:func:`blend_space_corner`'s search for m corners at once: the corner between
    path-table pieces ``rows_a`` (m,) and ``rows_b`` (m,) (each a's end meets b's start),
    with tolerances and trim caps (m,) [mm]. Every corner's search takes its next trim in
    lock step, each round one whole-array evaluation of the candidates still searching
    (points, tangents and curvature vectors from the path table; the Béziers batched; the
    two one-way distances per corner). None where no blend is found."""
    from nurbscnc.geometry.nurbs import NurbsCurve

    rows_a, rows_b = np.asarray(rows_a, dtype=np.intp), np.asarray(rows_b, dtype=np.intp)
    m = rows_a.size
    args = [np.broadcast_to(np.asarray(x, dtype=float), (m,))
            for x in (tolerance_mm, max_trim_a_mm, max_trim_b_mm)]  # fmt: skip
    if m > SPACE_CHUNK:  # bounded temporaries
        return [bl for lo in range(0, m, SPACE_CHUNK)
                for bl in blend_space_corners(path, rows_a[lo : lo + SPACE_CHUNK],
                                              rows_b[lo : lo + SPACE_CHUNK],
                                              *(x[lo : lo + SPACE_CHUNK] for x in args))]
    tolerance_mm, max_trim_a_mm, max_trim_b_mm = args
    out: list[SpaceBlend | None] = [None] * m
    if m == 0:
        return out
    tol = np.asarray(tolerance_mm, dtype=float).copy()
    len_a, len_b = path.length_mm[rows_a].astype(float), path.length_mm[rows_b].astype(float)
    d_max = np.minimum.reduce([np.broadcast_to(np.asarray(max_trim_a_mm, float), (m,)),
                               np.broadcast_to(np.asarray(max_trim_b_mm, float), (m,)),
                               len_a, len_b])  # fmt: skip
    vertex, t_a, _ = _frames(path, rows_a, len_a)
    _, t_b, _ = _frames(path, rows_b, np.zeros(m))
    n_c = np.cross(t_a, t_b)
    turning = np.arctan2(np.sqrt(np.einsum("ij,ij->i", n_c, n_c)),
                         np.einsum("ij,ij->i", t_a, t_b))  # fmt: skip
    live = (np.isfinite(tol) & (tol > 0.0) & (d_max > MIN_TRIM_MM) & (turning >= MIN_TURNING_RAD)
            & (turning <= np.pi - MIN_REVERSAL_RAD))  # fmt: skip
    per_trim = np.where(live, line_deviation_per_trim(np.where(live, turning, 1.0)), 1.0)
    d_cap = np.minimum(d_max, TRIM_CAP_FACTOR * tol / per_trim)
    d = np.minimum(d_cap, tol * (1.0 - 0.5 * SEARCH_WINDOW) / per_trim)
    lo, hi = np.zeros(m), d_cap.copy()
    best_d = np.full(m, np.nan)
    best = [None] * m
    last_d, last_dev = np.zeros(m), np.zeros(m)  # the last regular blend's trim, deviation
    xi = np.linspace(0.0, 1.0, _N_SPACE)
    frac = np.linspace(0.0, 1.0, _N_ARC)
    for _ in range(MAX_EVALS):
        act = np.flatnonzero(live)
        if act.size == 0:
            break
        da = d[act]
        p_a, ta, ka = _frames(path, rows_a[act], len_a[act] - da)
        p_b, tb, kb = _frames(path, rows_b[act], da)
        ctrl = space_bezier(p_a, ta, ka, p_b, tb, kb)
        pts, d1, d2 = _bezier_batch(ctrl, xi)
        speed = np.sqrt(np.einsum("mij,mij->mi", d1, d1))
        regular = speed.min(axis=1) > 1e-3 * speed.max(axis=1)
        s = da[:, None] * frac[None, :]
        k_side = frac.size
        side_a = path.points(np.repeat(rows_a[act], k_side),
                             (len_a[act] - da)[:, None].repeat(k_side, axis=1).ravel()
                             + s.ravel())[0].reshape(act.size, k_side, 3)  # fmt: skip
        side_b = path.points(np.repeat(rows_b[act], k_side), s.ravel())[0].reshape(
            act.size, k_side, 3)
        corner = np.concatenate([side_a[:, :-1], vertex[act][:, None, :], side_b[:, 1:]], axis=1)
        dev = np.maximum(_polyline_distance_batch(pts, corner).max(axis=1),
                         _polyline_distance_batch(corner, pts).max(axis=1))
        kappa = np.linalg.norm(np.cross(d1, d2), axis=2) / np.maximum(speed, 1e-300) ** 3
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
                d[c] = 0.5 * (lo[c] + hi[c]) if hi[c] < d_cap[c] or lo[c] > 0.0 else min(
                    2.0 * d[c], d_cap[c])
            if hi[c] - lo[c] <= BRACKET_REL * hi[c]:
                stop[n] = True
        live[act[stop]] = False
    for c in range(m):
        if best[c] is None or not best_d[c] > MIN_TRIM_MM:
            continue
        ctrl_c, dev_c, kmax = best[c]
        curve = NurbsCurve(5, np.array([0.0] * 6 + [1.0] * 6), ctrl_c, np.ones(6))
        out[c] = SpaceBlend(curve, float(best_d[c]), float(best_d[c]), dev_c, kmax,
                            float(np.degrees(turning[c])))
    return out


planar_kind = _planar_kind  # TEMP alias: dropped at the merge (the geometry helper renames it)
