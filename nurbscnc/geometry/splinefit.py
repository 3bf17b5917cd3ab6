"""Cubic B-spline least squares, evaluation, differentiation and knot insertion: scipy's
``scipy.interpolate`` results (``make_lsq_spline``, ``BSpline.__call__``,
``BSpline.derivative``, ``BSpline.insert_knot``) without importing ``scipy.interpolate``.

Importing ``scipy.interpolate`` costs about 0.45 s of CPU (it pulls in scipy.linalg,
optimize, sparse, special, …), more than the whole plan of a short smoothed program; the
work itself is done by one compiled module, ``scipy/interpolate/_dierckx`` (Dierckx's
FITPACK routines, ported to C++), which needs numpy only. It is loaded alone
(:func:`nurbscnc.scipy_ext.extension`) and called as scipy's own Python code calls it, the
few numpy steps around it written as scipy writes them: the same operations in the same
order, so the same bits (tests/test_splinefit.py compares with scipy.interpolate for
equality). Where this scipy has no such module, scipy.interpolate itself is used.

Splines here are ``(t, c)``: knots ``t`` (n + 4,) and control points ``c`` (n, d), degree 3.
"""

from __future__ import annotations

import numpy as np

from nurbscnc.scipy_ext import extension

DEGREE = 3


def _dierckx():
    """scipy's ``_dierckx`` kernel module alone, or None (another scipy layout)."""
    return extension("interpolate", "_dierckx")


def lsq_spline(x: np.ndarray, y: np.ndarray, t: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Control points (n, d) of the cubic B-spline on knots ``t`` (n + 4,) that fits the
    points ``y`` (m, d) at the non-decreasing parameters ``x`` (m,) in weighted least squares
    (weights ``w`` (m,)): ``scipy.interpolate.make_lsq_spline(x, y, t, 3, w)`` (its default
    method, Givens QR of the banded observation matrix and back substitution; FITPACK's
    fpcurf). Raises ValueError where scipy does for these inputs (parameters outside the
    knots' base interval, decreasing knots or parameters)."""
    x = np.ascontiguousarray(x, dtype=float)
    y = np.ascontiguousarray(y, dtype=float)
    t = np.ascontiguousarray(t, dtype=float)
    w = np.ascontiguousarray(w, dtype=float)
    dierckx = _dierckx()
    if dierckx is None:  # pragma: no cover (another scipy layout)
        from scipy.interpolate import make_lsq_spline

        return np.ascontiguousarray(make_lsq_spline(x, y, t, k=DEGREE, w=w).c)
    k = DEGREE
    if not np.all(np.isfinite(x)) or not np.all(np.isfinite(y)) or not np.all(np.isfinite(t)):
        raise ValueError("Array must not contain infs or NaNs")
    if x.shape[0] < k + 1:
        raise ValueError("Need more x points.")
    if np.any(t[1:] - t[:-1] < 0) or np.any(x[1:] - x[:-1] < 0):
        raise ValueError("Expect non-decreasing knots and parameters.")
    if np.any((x < t[k]) | (x > t[-k])):
        raise ValueError("Parameters outside the base interval.")
    n = t.size - k - 1
    yy = y.reshape(-1, int(np.prod(y.shape[1:])))
    y_w = yy * w[:, None]
    a, offset, nc = dierckx.data_matrix(x, t, k, w)
    dierckx.qr_reduce(a, offset, nc, y_w)  # in place: the triangular factor and Qᵀ y
    c = dierckx.fpback(a, nc, x, yy, t, k, w, y_w)[0]
    return np.ascontiguousarray(c.reshape((n,) + y.shape[1:]))


def evaluate(t: np.ndarray, c: np.ndarray, u, nu: int = 0) -> np.ndarray:
    """The ``nu``-th derivative (len(u), d) of the cubic B-spline (``t``, ``c``) at the
    parameters ``u``, extrapolated outside the base interval:
    ``scipy.interpolate.BSpline(t, c, 3)(u, nu)``."""
    u = np.ascontiguousarray(np.asarray(u, dtype=float).ravel())
    t = np.ascontiguousarray(t, dtype=float)
    c = np.ascontiguousarray(c, dtype=float)
    dierckx = _dierckx()
    if dierckx is None:  # pragma: no cover (another scipy layout)
        from scipy.interpolate import BSpline

        return BSpline(t, c, DEGREE)(u, nu)
    out = dierckx.evaluate_spline(t, c.reshape(c.shape[0], -1), DEGREE, u, nu, True)
    return out.reshape(u.shape + c.shape[1:])


def derivative(t: np.ndarray, c: np.ndarray, nu: int = 1) -> tuple[np.ndarray, np.ndarray, int]:
    """Knots, control points and degree of the ``nu``-th derivative of the cubic B-spline
    (``t``, ``c``): ``BSpline(t, c, 3).derivative(nu)`` (FITPACK's splder; Schumaker,
    Spline Functions, ch. 5: c'ᵢ = k (cᵢ₊₁ − cᵢ) / (tᵢ₊ₖ₊₁ − tᵢ₊₁)); the control points are
    padded with zeros to the knots' length, as FITPACK keeps them."""
    k = DEGREE
    c = np.array(c, dtype=float)
    pad = t.shape[0] - c.shape[0]
    if pad > 0:
        c = np.concatenate((c, np.zeros((pad,) + c.shape[1:])))
    sh = (slice(None),) + (None,) * (c.ndim - 1)
    with np.errstate(invalid="raise", divide="raise"):
        try:
            for _ in range(nu):
                dt = (t[k + 1 : -1] - t[1 : -k - 1])[sh]
                c = (c[1 : -1 - k, ...] - c[: -2 - k, ...]) * k / dt
                c = np.concatenate((c, np.zeros((k,) + c.shape[1:])))
                t = t[1:-1]
                k -= 1
        except FloatingPointError as exc:
            raise ValueError("internal repeated knots: not differentiable") from exc
    return t, c, k


def evaluate_derivative(t: np.ndarray, c: np.ndarray, u, nu: int) -> np.ndarray:
    """``BSpline(t, c, 3).derivative(nu)(u)``: the derivative spline's coefficients
    (:func:`derivative`) evaluated (not the same bits as :func:`evaluate` with ``nu``)."""
    td, cd, kd = derivative(t, c, nu)
    u = np.ascontiguousarray(np.asarray(u, dtype=float).ravel())
    dierckx = _dierckx()
    if dierckx is None:  # pragma: no cover (another scipy layout)
        from scipy.interpolate import BSpline

        return BSpline(td, cd, kd)(u)
    out = dierckx.evaluate_spline(td, cd.reshape(cd.shape[0], -1), kd, u, 0, True)
    return out.reshape(u.shape + cd.shape[1:])


def insert_knot(t: np.ndarray, c: np.ndarray, x: float, m: int = 1):
    """Knots and control points of the cubic B-spline (``t``, ``c``) with the knot ``x``
    inserted ``m`` times (Boehm's algorithm; FITPACK's insert, as
    ``BSpline.insert_knot``): the same curve."""
    dierckx = _dierckx()
    if dierckx is None:  # pragma: no cover (another scipy layout)
        from scipy.interpolate import BSpline

        sp = BSpline(t, c, DEGREE).insert_knot(x, m)
        return sp.t, sp.c
    k = DEGREE
    x = float(x)
    if x < t[k] or x > t[-k - 1]:
        raise ValueError(f"Cannot insert a knot at {x}.")
    tt, cc = np.ascontiguousarray(t, dtype=float).copy(), np.asarray(c).copy()
    for _ in range(m):
        i = dierckx.find_interval(tt, k, x, k, False)
        if i < 0:
            raise ValueError(f"Cannot insert the knot at {x}.")
        if tt[i] == tt[i + k + 1]:
            i -= 1
        t_new = np.r_[tt[: i + 1], x, tt[i + 1 :]]
        c_new = np.zeros((cc.shape[0] + 1,) + cc.shape[1:], dtype=cc.dtype)
        c_new[i + 1 :, ...] = cc[i:, ...]
        for j in range(i, i - k, -1):
            fac = (x - t_new[j]) / (t_new[j + k + 1] - t_new[j])
            c_new[j, ...] = fac * cc[j, ...] + (1.0 - fac) * cc[j - 1, ...]
        c_new[: i - k + 1, ...] = cc[: i - k + 1, ...]
        tt, cc = t_new, c_new
    return tt, cc
