"""B-spline basis functions, rational derivatives and curvature from derivative arrays
(SPEC §2), vectorised over samples.

Everything here works on whole arrays of parameter values at once: the Python loops run over
the degree and derivative order (small), never over samples.

References: L. Piegl & W. Tiller, *The NURBS Book*, 2nd ed. (A2.1 FindSpan, A2.3 DersBasisFuns,
A4.2 RatCurveDerivs).
"""

from __future__ import annotations

from math import comb

import numpy as np

from nurbscnc.geometry.compiled import kernels as _kernels

#: Largest degree the compiled basis derivatives take (``BASIS_MAX_DEGREE`` of
#: geometry/_kernels.c); above it the Python loops run.
_KERNEL_MAX_DEGREE = 15


def as_params(u) -> np.ndarray:
    """Parameters as a 1-D float64 array (a scalar becomes an array of length 1)."""
    return np.atleast_1d(np.asarray(u, dtype=float)).ravel()


# ---------------------------------------------------------------------------------------------
# B-spline basis (Piegl & Tiller A2.1, A2.3), vectorised over samples
# ---------------------------------------------------------------------------------------------


def find_span(knots: np.ndarray, degree: int, u) -> np.ndarray:
    """Knot span index i with knots[i] <= u < knots[i+1] for each u (P&T A2.1).

    Vectorised with ``np.searchsorted``; u at (or beyond) the end maps to the last non-empty
    span n-1 and u before the start to span p, so the result is always a valid span of a clamped
    knot vector (n = len(knots) - p - 1 control points).
    """
    knots = np.asarray(knots, dtype=float)
    n_ctrl = knots.size - degree - 1
    span = np.searchsorted(knots, as_params(u), side="right") - 1
    return np.clip(span, degree, n_ctrl - 1)


def basis_functions(knots: np.ndarray, degree: int, u, spans=None) -> np.ndarray:
    """The p + 1 non-zero B-spline basis functions at many parameters (P&T A2.2).

    Returns (p + 1, m) with row j = N_{spans-p+j, p}(u); ``spans`` from :func:`find_span`
    unless given (an explicit span gives the one-sided polynomial at a knot). The cheap path
    for point evaluation: only the triangle of basis values, no knot-difference table.
    """
    knots = np.asarray(knots, dtype=float)
    u = as_params(u)
    p = degree
    if spans is None:
        spans = find_span(knots, p, u)
    n = np.empty((p + 1, u.size))
    n[0] = 1.0
    left = [None] * (p + 1)
    right = [None] * (p + 1)
    for j in range(1, p + 1):
        left[j] = u - knots[spans + 1 - j]
        right[j] = knots[spans + j] - u
        saved = 0.0
        for r in range(j):
            # The denominator covers [knots[span], knots[span+1]] (a non-empty span): never 0.
            temp = n[r] / (right[r + 1] + left[j - r])
            n[r] = saved + right[r + 1] * temp
            saved = left[j - r] * temp
        n[j] = saved
    return n


def basis_derivatives(
    knots: np.ndarray, degree: int, u, n_ders: int
) -> tuple[np.ndarray, np.ndarray]:
    """Non-zero B-spline basis functions and derivatives at many parameters (P&T A2.3).

    Returns ``(spans, ders)``: ``spans`` (m,) from :func:`find_span`, and ``ders`` of shape
    (m, n_ders + 1, degree + 1) with ``ders[s, k, j]`` = d^k N_{spans[s]-p+j, p}/du^k (u_s).
    Derivatives of order > p are zero. :func:`_basis_derivatives_py`, compiled where the
    geometry's kernels were built (the same numbers bit for bit, without a Python loop per
    (j, r) pair: most calls are for a few parameters).
    """
    knots = np.asarray(knots, dtype=float)
    u = as_params(u)
    spans = find_span(knots, degree, u)
    if _kernels is None or not 0 <= degree <= _KERNEL_MAX_DEGREE:
        return spans, _basis_derivatives_py(knots, degree, u, spans, n_ders)
    ders_t = np.empty((n_ders + 1, degree + 1, u.size))  # [k, r, sample], as the reference
    _kernels.basis_derivatives(
        np.ascontiguousarray(knots),
        np.ascontiguousarray(spans, dtype=np.int64),
        np.ascontiguousarray(u),
        int(degree),
        int(n_ders),
        ders_t,
    )
    return spans, ders_t.transpose(2, 0, 1)


def _basis_derivatives_py(
    knots: np.ndarray, degree: int, u: np.ndarray, spans: np.ndarray, n_ders: int
) -> np.ndarray:
    """The ``ders`` of :func:`basis_derivatives` for parameters ``u`` in knot spans ``spans``
    (P&T A2.3, vectorised over the samples)."""
    p = degree
    m = u.size

    # Arrays keep the sample axis last so every per-(j, r) slice is contiguous.
    # ndu[j, r] (r < j): knot differences; ndu[r, j] (r <= j): basis functions of degree j.
    ndu = np.empty((p + 1, p + 1, m))
    ndu[0, 0] = 1.0
    left = np.empty((p + 1, m))
    right = np.empty((p + 1, m))
    for j in range(1, p + 1):
        left[j] = u - knots[spans + 1 - j]
        right[j] = knots[spans + j] - u
        saved = np.zeros(m)
        for r in range(j):
            # The denominator covers [knots[span], knots[span+1]] (a non-empty span): never 0.
            ndu[j, r] = right[r + 1] + left[j - r]
            temp = ndu[r, j - 1] / ndu[j, r]
            ndu[r, j] = saved + right[r + 1] * temp
            saved = left[j - r] * temp
        ndu[j, j] = saved

    ders_t = np.zeros((n_ders + 1, p + 1, m))  # [k, r, sample]
    ders_t[0] = ndu[:, p]
    n_top = min(n_ders, p)
    a = np.empty((2, p + 1, m))
    for r in range(p + 1):
        a[0, 0] = 1.0
        s1, s2 = 0, 1
        for k in range(1, n_top + 1):
            d = np.zeros(m)
            rk, pk = r - k, p - k
            if r >= k:
                a[s2, 0] = a[s1, 0] / ndu[pk + 1, rk]
                d = a[s2, 0] * ndu[rk, pk]
            j1 = 1 if rk >= -1 else -rk
            j2 = k - 1 if r - 1 <= pk else p - r
            for j in range(j1, j2 + 1):
                a[s2, j] = (a[s1, j] - a[s1, j - 1]) / ndu[pk + 1, rk + j]
                d += a[s2, j] * ndu[rk + j, pk]
            if r <= pk:
                a[s2, k] = -a[s1, k - 1] / ndu[pk + 1, r]
                d += a[s2, k] * ndu[r, pk]
            ders_t[k, r] = d
            s1, s2 = s2, s1
    factor = float(p)
    for k in range(1, n_top + 1):
        ders_t[k] *= factor  # p!/(p-k)!
        factor *= p - k
    return ders_t.transpose(2, 0, 1)


# ---------------------------------------------------------------------------------------------
# Curvature from derivative arrays (shared by NURBS, lines and arcs)
# ---------------------------------------------------------------------------------------------


def curvature_from_derivatives(d: np.ndarray, speed_floor: float = 0.0) -> np.ndarray:
    """κ = |C'×C''| / |C'|³ (SPEC §2, eq. 14) from ``d`` = [C, C', C'', ...] (k, m, 3).

    Where |C'| <= ``speed_floor`` (a cusp or a point) κ = +inf, never NaN.
    """
    c1, c2 = d[1], d[2]
    speed = np.linalg.norm(c1, axis=-1)
    cross = np.linalg.norm(np.cross(c1, c2), axis=-1)
    cusp = speed <= speed_floor
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        kappa = cross / speed**3
    return np.where(cusp, np.inf, kappa)


def curvature_derivative_from_derivatives(d: np.ndarray, speed_floor: float = 0.0) -> np.ndarray:
    """dκ/du of a 3-D curve from ``d`` = [C, C', C'', C''', ...] (k >= 4, m, 3).

    With a = C'×C'' (so a' = C'×C''') and v = |C'|:
    κ = |a|/v³,  d|a|/du = a·a'/|a|,  dv/du = C'·C''/v, hence
    dκ/du = (a·a')/(|a| v³) − 3 |a| (C'·C'')/v⁵.
    In the plane a = (0, 0, x'y''−y'x'') and this is sign(x'y''−y'x'') times SPEC §2's formula.
    Where |a| = 0 (straight piece or inflection, where |κ| has a kink) the first term is taken as
    0 (the mean of the one-sided derivatives); where v <= ``speed_floor`` (cusp) dκ/du = 0.
    """
    c1, c2, c3 = d[1], d[2], d[3]
    a = np.cross(c1, c2)
    a_dot = np.cross(c1, c3)
    a_norm = np.linalg.norm(a, axis=-1)
    speed = np.linalg.norm(c1, axis=-1)
    # |a·a'|/|a| <= |a'|, so the quotient is bounded; only 0/0 needs guarding.
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        d_a_norm = np.where(a_norm > 0.0, np.einsum("ij,ij->i", a, a_dot) / a_norm, 0.0)
        dkappa = d_a_norm / speed**3 - 3.0 * a_norm * np.einsum("ij,ij->i", c1, c2) / speed**5
    dkappa = np.where(speed <= speed_floor, 0.0, dkappa)
    return np.where(np.isfinite(dkappa), dkappa, 0.0)


# ---------------------------------------------------------------------------------------------
# Rational derivatives from homogeneous ones (Piegl & Tiller A4.2)
# ---------------------------------------------------------------------------------------------


def rational_derivatives(hom: np.ndarray) -> np.ndarray:
    """[C, C', ..., C^(k)] (k+1, m, 3) from homogeneous derivatives ``hom`` (k+1, 4, m).

    ``hom[i]`` = [A^(i); w^(i)] (components first); quotient rule (P&T A4.2):
    C^(k) = (A^(k) − Σ_{i=1..k} C(k,i) w^(i) C^(k−i)) / w.
    """
    order = hom.shape[0] - 1
    w = hom[:, 3]
    out = np.empty((order + 1, 3, hom.shape[2]))
    for k in range(order + 1):
        v = hom[k, :3].copy()
        for i in range(1, k + 1):
            v -= comb(k, i) * w[i] * out[k - i]
        out[k] = v / w[0]
    return np.ascontiguousarray(out.transpose(0, 2, 1))
