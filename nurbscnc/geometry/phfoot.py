"""The arithmetic of the foot points on a planar PH quintic (SPEC §4) of
:meth:`~nurbscnc.geometry.ph.PHQuintic.closest_param`: the parameter ξ ∈ [0, 1] of the curve
point nearest to each of many plane points, as the PH fits' deviation needs them (SPEC §6:
200 samples of the NURBS per candidate piece, every candidate of every corner).

It is written out in real numbers, one IEEE operation at a time, so that the compiled kernel
(``geometry/_kernels.c`` ``ph_closest``, one point at a time to its end, without numpy's
temporaries) and the numpy reference give the same bits:

- r(ξ) = Σ_k B_k⁵(ξ) p_k with B_k⁵ = C(5, k) ξ^k (1 − ξ)^(5−k), the powers by repeated
  products, the sum left to right (x and y apart);
- w(ξ) = (1 − ξ)² w0 + 2(1 − ξ)ξ w1 + ξ² w2, w′(ξ) = 2[(w1 − w0)(1 − ξ) + (w2 − w1)ξ];
- g(ξ) = Re(conj(r − q) r′) = ½ d|r − q|²/dξ with r′ = w², and
  g′(ξ) = |r′|² + Re(conj(r − q) r″) with r″ = 2ww′.

The search (``closest_param``): the nearest of ``n_dense`` uniform samples
(squared distance, the first of equal ones), a bracket on the side where g changes sign,
Newton safeguarded by bisection (:func:`~nurbscnc.geometry.ph.bracketed_newton`, ftol 0, at
most 200 steps); without a sign change the nearest sample.
"""

from __future__ import annotations


def point_xy(cp_re, cp_im, x):
    """r(ξ) [mm] as (x, y) arrays: the Bernstein sum written out (module docstring)."""
    t = 1.0 - x
    t2 = t * t
    t3 = t2 * t
    t4 = t3 * t
    x2 = x * x
    x3 = x2 * x
    x4 = x3 * x
    basis = (t4 * t, 5.0 * x * t4, 10.0 * x2 * t3, 10.0 * x3 * t2, 5.0 * x4 * t, x4 * x)
    re = basis[0] * cp_re[0]
    im = basis[0] * cp_im[0]
    for k in range(1, 6):
        re = re + basis[k] * cp_re[k]
        im = im + basis[k] * cp_im[k]
    return re, im


def g_terms(cp_re, cp_im, w_re, w_im, x, q_re, q_im):
    """g(ξ) and g′(ξ) (module docstring) at ``x`` for the points ``q``."""
    t = 1.0 - x
    a0 = t * t
    a1 = 2.0 * (t * x)
    a2 = x * x
    wr = a0 * w_re[0] + a1 * w_re[1] + a2 * w_re[2]
    wi = a0 * w_im[0] + a1 * w_im[1] + a2 * w_im[2]
    dwr = 2.0 * ((w_re[1] - w_re[0]) * t + (w_re[2] - w_re[1]) * x)
    dwi = 2.0 * ((w_im[1] - w_im[0]) * t + (w_im[2] - w_im[1]) * x)
    r1r = wr * wr - wi * wi
    r1i = 2.0 * (wr * wi)
    r2r = 2.0 * (wr * dwr - wi * dwi)
    r2i = 2.0 * (wr * dwi + wi * dwr)
    px, py = point_xy(cp_re, cp_im, x)
    dx = px - q_re
    dy = py - q_im
    g = dx * r1r + dy * r1i
    dg = (r1r * r1r + r1i * r1i) + (dx * r2r + dy * r2i)
    return g, dg
