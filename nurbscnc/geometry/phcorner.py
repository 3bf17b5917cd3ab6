"""One planar corner's PH quintic blend (SPEC §4, eq. 21): the G2 Hermite construction for a
given trim, its Hausdorff deviation from the corner path, and the search for the largest trim
within the tolerance. :func:`~nurbscnc.geometry.blend.blend_corner` sets the corner up.

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
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nurbscnc.geometry.blendrules import (
    BRACKET_REL,
    MAX_EVALS,
    MIN_SPEED_RATIO,
    N_ARC,
    SEARCH_WINDOW,
)
from nurbscnc.geometry.paths import LineGeometry
from nurbscnc.geometry.ph import PHQuintic, hermite_ph

#: Samples ξ of a blend for its deviation and curvature peak [count], and their grid.
N_BLEND = 129
XI = np.linspace(0.0, 1.0, N_BLEND)
#: Fractions of the end curvatures through which the G2 Newton solve is continued.
_LAMBDAS = (0.25, 0.5, 0.75, 1.0)


@dataclass(frozen=True, eq=False)
class Corner:
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
class Candidate:
    trim_mm: float
    ph: PHQuintic
    deviation_mm: float
    kappa_jump_per_mm: float


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b for 3-vectors (np.cross costs ~30 µs per call on tiny arrays)."""
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def unit_vector(v: np.ndarray) -> np.ndarray:
    return v / np.sqrt(v @ v)


def derivatives_at_length(geom, s_mm: float, order: int) -> np.ndarray:
    """Derivatives (order + 1, 3) of ``geom`` at arc length ``s_mm`` from its start."""
    return geom.derivatives(geom.param_at_length(np.array([s_mm])), order)[:, 0, :]


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


def _cdiv_real(z: complex, d: float) -> complex:
    """z / d as numpy divides a complex scalar by a real one (Smith's method on d + 0i: the
    ratio 0/d and the scale 1/(d + 0·ratio) multiply, where Python's complex division
    divides): numpy's bits for Python complex operands (d ≠ 0)."""
    rat = 0.0 / d
    scl = 1.0 / (d + 0.0 * rat)
    return complex((z.real + z.imag * rat) * scl, (z.imag - z.real * rat) * scl)


def _w_g2(dp, e0, e2, k0, k1, ab0, max_iter: int = 30):
    """(α, β) of the PH quintic with chord ``dp`` and end curvatures k0, k1, by damped
    Newton from ``ab0``; None if it does not converge at α, β > 0.

    In Python floats and complex numbers (a few thousand corners, each a few Newton steps on
    scalars): the arithmetic of numpy's complex128 scalars operation for operation — + − ×
    and |·| are the same formulas (a real operand is the complex (x, 0) on both sides), and
    a division by a real takes numpy's form (:func:`_cdiv_real`) — so the same bits
    (tests/test_phcorner_batch.py against the numpy-scalar version kept there)."""
    dp, e0, e2 = complex(dp), complex(e0), complex(e2)
    k0, k1 = float(k0), float(k1)
    s = (e0.conjugate() * e2).imag
    scale = 5.0 * abs(dp)
    g0, g1 = 0.25 * k0, 0.25 * k1

    def residual(a, b):
        w0 = a * e0
        w1 = _cdiv_real(g0 * a**3 * e2 + g1 * b**3 * e0, s)  # _w1
        w2 = b * e2
        f = (
            w0 * w0
            + w0 * w1
            + _cdiv_real(2.0 * w1 * w1 + w0 * w2, 3.0)
            + w1 * w2
            + w2 * w2
            - 5.0 * dp
        )
        return f, w0, w1, w2

    a, b = float(ab0[0]), float(ab0[1])
    f, w0, w1, w2 = residual(a, b)
    for _ in range(max_iter):
        if abs(f) <= 1e-14 * scale:
            return a, b
        fw1 = w0 + _cdiv_real(4.0 * w1, 3.0) + w2  # ∂F/∂w1; ∂F/∂w0, ∂F/∂w2 below
        dfa = (2.0 * w0 + w1 + _cdiv_real(w2, 3.0)) * e0 + fw1 * _cdiv_real(
            0.75 * k0 * a * a * e2, s
        )
        dfb = (_cdiv_real(w0, 3.0) + w1 + 2.0 * w2) * e2 + fw1 * _cdiv_real(
            0.75 * k1 * b * b * e0, s
        )
        det = dfa.real * dfb.imag - dfb.real * dfa.imag
        if not (math.isfinite(det) and det != 0.0):
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
    return float(cross3(d[1], d[2]) @ normal / np.sqrt(d[1] @ d[1]) ** 3)


def _to_plane(corner: Corner, pts: np.ndarray) -> np.ndarray:
    """3-D points (m, 3) [mm] to complex corner-plane coordinates (the corner is planar)."""
    rel = pts - corner.origin_mm
    return rel @ corner.e1 + 1j * (rel @ corner.e2)


def _segment_distance(q: np.ndarray, a: complex, b: complex) -> np.ndarray:
    """Distance [mm] from the points ``q`` to the segment [a, b] (complex plane)."""
    ab = b - a
    ab2 = (ab * ab.conjugate()).real
    t = np.clip((np.conj(ab) * (q - a)).real / ab2, 0.0, 1.0) if ab2 > 0.0 else 0.0
    return np.abs(q - a - t * ab)


def polyline_distance(q: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Distance [mm] from the points ``q`` (m,) to the polyline through ``pts`` (k,) (complex
    plane): the least over its chords of :func:`_segment_distance`, all chords as one
    (chords, points) array. Each chord's row is that function's arithmetic, operand for
    operand (the chord's terms broadcast along the row as the scalar was, |ab|² as the real
    part of ab·āb̄ is, a degenerate chord's foot at its start), so the same bits
    (tests/test_phcorner_batch.py against the chord-by-chord loop)."""
    a = pts[:-1, None]
    ab = pts[1:] - pts[:-1]
    ab2 = ab.real * ab.real + ab.imag * ab.imag
    rel = q[None, :] - a
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.clip((np.conj(ab)[:, None] * rel).real / ab2[:, None], 0.0, 1.0)
    t = np.where((ab2 > 0.0)[:, None], t, 0.0)
    return np.abs(rel - t * ab[:, None]).min(axis=0)


def _side(corner: Corner, geom, s_from: float, s_to: float, z_from: complex, z_to: complex):
    """One side of the corner path from arc length ``s_from`` to ``s_to`` of ``geom``
    (end points ``z_from``, ``z_to``): its sample points (complex) and a function giving
    the distance from points to it (a line: exact; a circular arc: exact, ||q − c| − r|
    inside its angular span, else the nearer end; a spiral arc: a 33-point polyline)."""
    if isinstance(geom, LineGeometry):
        return np.array([z_from, z_to]), lambda q: _segment_distance(q, z_from, z_to)
    pts = _to_plane(corner, geom.point(geom.param_at_length(np.linspace(s_from, s_to, N_ARC))))
    pts[0], pts[-1] = z_from, z_to
    if geom.is_spiral:
        return pts, lambda q: polyline_distance(q, pts)
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
    r = ph.point(XI)
    # Blend → path: each blend sample to the nearer side.
    h_blend = float(np.minimum(sides[0][1](r), sides[1][1](r)).max())
    # Path → blend: nearest blend sample, refined by Newton on g = Re(conj(r − q) r′) = 0.
    q = np.concatenate((sides[0][0], sides[1][0]))
    d2 = np.abs(r[None, :] - q[:, None]) ** 2
    nearest = np.argmin(d2, axis=1)
    best2 = d2[np.arange(q.size), nearest]
    xi = XI[nearest]
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
    return bool(np.min(np.abs(ph.preimage(XI)) ** 2) > MIN_SPEED_RATIO * ph.length_mm)


def _candidate(
    corner: Corner, trim_mm: float, g2: bool, dev_per_trim: float | None = None
) -> Candidate | None:
    """The blend with trim ``trim_mm`` on both sides (G2 family or G1 family) and its
    measured deviation (or ``trim_mm · dev_per_trim`` if given: the line-corner closed
    form); None where the family has no regular member."""
    da = derivatives_at_length(corner.geom_a, corner.length_a_mm - trim_mm, 2)
    db = derivatives_at_length(corner.geom_b, trim_mm, 2)
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
        return Candidate(trim_mm, ph, trim_mm * dev_per_trim, jump)
    z_v = corner.vertex_z
    sides = [
        _side(corner, corner.geom_a, corner.length_a_mm - trim_mm, corner.length_a_mm, z_a, z_v),
        _side(corner, corner.geom_b, 0.0, trim_mm, z_v, z_b),
    ]
    return Candidate(trim_mm, ph, _deviation(ph, sides, z_v), jump)


def search_trim(
    corner: Corner,
    tol: float,
    d_start: float,
    d_cap: float,
    g2: bool,
    d_floor: float = 0.0,
    dev_per_trim: float | None = None,
) -> Candidate | None:
    """Largest trim ≤ ``d_cap`` with deviation ≤ ``tol`` (secant + bisection, module doc);
    gives up once the family has no member at a trim ≤ ``d_floor``."""
    target = tol * (1.0 - 0.5 * SEARCH_WINDOW)
    # Accept a measured deviation up to tol(1 − 1e-6): margin for the sampled parts of the
    # measurement (blend samples, arc polylines), which are below 1e-8 relative here.
    tol = tol * (1.0 - 1e-6)
    d = min(d_start, d_cap)
    lo, hi = 0.0, np.inf
    best: Candidate | None = None
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
