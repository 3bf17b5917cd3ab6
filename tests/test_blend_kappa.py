"""geometry/lineblends.py ``_kappa_peak``: the buffered bisection keeps the bits of the
expression form it replaced, and finds the peak of κ(ξ) of the w1 = 0 quintic."""

from __future__ import annotations

import numpy as np

from nurbscnc.geometry.lineblends import _kappa_peak


def _reference(alpha, beta, c, s, iterations):
    lo, hi = np.zeros_like(alpha), np.ones_like(alpha)
    a2, b2, ab = alpha * alpha, beta * beta, alpha * beta * c
    a4, b4, ab4 = 4.0 * a2, 4.0 * b2, 4.0 * ab
    for _ in range(iterations):
        x = 0.5 * (lo + hi)
        u = 1.0 - x
        x2, u2 = x * x, u * u
        q = a2 * (u2 * u2) + b2 * (x2 * x2) + 2.0 * ab * x2 * u2
        dq = -a4 * (u2 * u) + b4 * (x2 * x) + ab4 * x * u * (u - x)
        rising = 1.0 / x - 1.0 / u - 2.0 * dq / q > 0.0
        np.copyto(lo, x, where=rising)
        np.copyto(hi, x, where=~rising)
    x = 0.5 * (lo + hi)
    u = 1.0 - x
    q = a2 * u**4 + b2 * x**4 + 2.0 * ab * x * x * u * u
    return 4.0 * alpha * beta * s * x * u / (q * q)


def test_kappa_peak_bits_and_the_dense_maximum():
    rng = np.random.default_rng(2)
    n = 5000
    alpha = rng.uniform(0.01, 2.0, n)
    beta = alpha * rng.uniform(0.2, 5.0, n)
    c = rng.uniform(0.01, 0.999, n)
    s = np.sqrt(1.0 - c * c)
    got = _kappa_peak(alpha, beta, c, s)
    np.testing.assert_array_equal(got, _reference(alpha, beta, c, s, iterations=30))
    # κ is stationary at its peak: 30 halvings give it to rounding (52 as the reference).
    np.testing.assert_allclose(
        got, _reference(alpha, beta, c, s, iterations=52), rtol=2e-15, atol=0.0
    )
    # The maximum of κ(ξ) = 4αβ s ξ(1 − ξ)/Q² on a dense grid is never above it (to rounding)
    # and comes within the grid's resolution of it.
    xi = np.linspace(0.0, 1.0, 4001)[None, :]
    u = 1.0 - xi
    a, b, cc, ss = (v[:200, None] for v in (alpha, beta, c, s))
    q = a * a * u**4 + b * b * xi**4 + 2.0 * a * b * cc * xi**2 * u**2
    dense = (4.0 * a * b * ss * xi * u / q**2).max(axis=1)
    assert np.all(dense <= got[:200] * (1.0 + 1e-12))
    np.testing.assert_allclose(dense, got[:200], rtol=1e-5)
