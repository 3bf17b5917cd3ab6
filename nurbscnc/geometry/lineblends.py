"""PH quintic blends of many line–line corners at once (the line path of CAM polylines):
closed-form trims and preimages, the curvature peak by bisection, and the PH quintics'
control points and arc-length tables as arrays (SPEC §4)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbscnc.geometry.blendrules import (
    MIN_REVERSAL_RAD,
    MIN_TRIM_MM,
    MIN_TURNING_RAD,
    SEARCH_WINDOW,
    line_deviation_per_trim,
)


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


def line_corner_blends(
    vertex_mm, t_a, t_b, tolerance_mm, max_trim_a_mm, max_trim_b_mm=None
) -> LineBlends:
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
    w0 = α e0, w2 = β e2 in closed form (phcorner.py; e0 = √τ_a, e2 = ±√τ_b with
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
    max_b = (
        max_a
        if max_trim_b_mm is None
        else np.broadcast_to(np.asarray(max_trim_b_mm, dtype=float), (m,))
    )
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
        mid = (
            p0
            + (31.0 / 160.0) * alpha * alpha * tau_a
            + (alpha * beta / 30.0) * e0 * e2c
            + (1.0 / 160.0) * beta * beta * tau_b
        )
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
    steps = np.stack([w0 * w0, w0 * w1, (2.0 * w1 * w1 + w0 * w2) / 3.0, w1 * w2, w2 * w2], axis=1)
    points = p0[:, None] + np.concatenate(
        (np.zeros((w.shape[0], 1)), np.cumsum(steps / 5.0, axis=1)), axis=1
    )
    sigma = np.stack(
        [
            np.abs(w0) ** 2,
            (w0 * w1.conjugate()).real,
            (2.0 * np.abs(w1) ** 2 + (w0 * w2.conjugate()).real) / 3.0,
            (w1 * w2.conjugate()).real,
            np.abs(w2) ** 2,
        ],
        axis=1,
    )
    s = np.concatenate((np.zeros((w.shape[0], 1)), np.cumsum(sigma / 5.0, axis=1)), axis=1)
    return points, sigma, s, s[:, -1].copy()
