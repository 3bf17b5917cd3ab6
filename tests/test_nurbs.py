"""NURBS evaluation, curvature and arc length against independent references.

Oracles: geomdl (P&T A4.2 in pure Python) and scipy.interpolate.BSpline on homogeneous
coordinates [w x, w y, w z, w] with the quotient rule written out here; scipy.integrate.quad for
arc length; closed forms for the circle and the semicubical-parabola cusp.
"""

from __future__ import annotations

from math import comb

import numpy as np
import pytest
from geomdl import NURBS
from scipy.integrate import quad
from scipy.interpolate import BSpline

from nurbscnc.geometry import arclength, inverse, segments
from nurbscnc.geometry.bspline import (
    basis_derivatives,
    basis_functions,
    curvature_derivative_from_derivatives,
    find_span,
)
from nurbscnc.geometry.nurbs import NurbsCurve


def random_curve(rng: np.random.Generator, degree: int) -> NurbsCurve:
    """A random valid curve: clamped knots on [0, 1] with a repeated interior knot if possible."""
    n = int(rng.integers(degree + 1, degree + 9))
    inner = np.sort(rng.uniform(0.0, 1.0, n - degree - 1))
    if inner.size >= 2 and degree >= 2:
        inner[1] = inner[0]  # multiplicity 2 (<= p): C^(p-2) there
    if inner.size >= 3 and degree >= 3:
        inner[2] = inner[0]  # multiplicity 3
    knots = np.r_[[0.0] * (degree + 1), inner, [1.0] * (degree + 1)]
    points = rng.uniform(-50.0, 50.0, (n, 3))
    weights = rng.uniform(0.2, 5.0, n)
    return NurbsCurve(degree, knots, points, weights)


def geomdl_derivatives(curve: NurbsCurve, u: np.ndarray, order: int) -> np.ndarray:
    g = NURBS.Curve(normalize_kv=False)
    g.degree = curve.degree
    g.ctrlpts = curve.control_points_mm.tolist()
    g.weights = curve.weights.tolist()
    g.knotvector = curve.knots.tolist()
    return np.array([g.derivatives(float(x), order) for x in u]).transpose(1, 0, 2)


def scipy_derivatives(curve: NurbsCurve, u: np.ndarray, order: int) -> np.ndarray:
    """Homogeneous B-spline by scipy (de Boor), then the rational quotient rule."""
    w = curve.weights[:, None]
    spline = BSpline(curve.knots, np.hstack((curve.control_points_mm * w, w)), curve.degree)
    hom = np.array([spline(u, nu=k) for k in range(order + 1)])
    out = np.empty((order + 1, u.size, 3))
    for k in range(order + 1):
        v = hom[k, :, :3].copy()
        for i in range(1, k + 1):
            v -= comb(k, i) * hom[i, :, 3:] * out[k - i]
        out[k] = v / hom[0, :, 3:]
    return out


def assert_rel_close(actual: np.ndarray, expected: np.ndarray, rel: float):
    """Per-sample vector error relative to the reference vector's norm."""
    err = np.linalg.norm(actual - expected, axis=-1)
    scale = np.linalg.norm(expected, axis=-1)
    assert np.all(err <= rel * scale), float(np.max(err / scale))


def circle(radius_mm: float) -> NurbsCurve:
    r, h = radius_mm, np.sqrt(0.5)
    points = [
        [r, 0, 0],
        [r, r, 0],
        [0, r, 0],
        [-r, r, 0],
        [-r, 0, 0],
        [-r, -r, 0],
        [0, -r, 0],
        [r, -r, 0],
        [r, 0, 0],
    ]
    weights = [1, h, 1, h, 1, h, 1, h, 1]
    knots = [0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1]
    return NurbsCurve(2, knots, points, weights)


def cusp_cubic() -> NurbsCurve:
    """Bezier form of (x, y) = (s², s³), s = 2u − 1: C'(½) = 0 (a cusp)."""
    points = [[1, -1, 0], [-1 / 3, 1, 0], [-1 / 3, -1, 0], [1, 1, 0]]
    return NurbsCurve(3, [0, 0, 0, 0, 1, 1, 1, 1], points, np.ones(4))


# --------------------------------------------------------------------------------- basis


def test_find_span_matches_definition_including_ends():
    knots = np.array([0, 0, 0, 1, 2, 2, 3, 4, 4, 4], dtype=float)  # p = 2, n = 7
    u = np.array([0.0, 0.5, 1.0, 1.999, 2.0, 2.5, 3.0, 3.9, 4.0])
    expected = [2, 2, 3, 3, 5, 5, 6, 6, 6]  # knots[i] <= u < knots[i+1]; u = end -> last span
    assert find_span(knots, 2, u).tolist() == expected


@pytest.mark.parametrize("degree", [1, 2, 3, 4, 5])
def test_basis_derivatives_match_scipy(degree):
    rng = np.random.default_rng(degree)
    curve = random_curve(rng, degree)
    u = rng.uniform(0.0, 1.0, 40)
    spans, ders = basis_derivatives(curve.knots, degree, u, degree + 1)
    assert ders.shape == (40, degree + 2, degree + 1)
    n = curve.weights.size
    for j in range(degree + 1):
        index = spans - degree + j
        for k in range(degree + 1):
            ref = np.array(
                [BSpline(curve.knots, np.eye(n)[i], degree)(x, nu=k) for i, x in zip(index, u)]
            )
            scale = np.max(np.abs(ders[:, k, :]), axis=1)
            assert np.all(np.abs(ders[:, k, j] - ref) <= 1e-12 * scale)
    np.testing.assert_allclose(ders[:, 0].sum(axis=1), 1.0, rtol=0, atol=1e-14)
    assert np.all(ders[:, degree + 1] == 0.0)  # order > p vanishes


# --------------------------------------------------------------------------- derivatives


@pytest.mark.parametrize("seed", range(20))
def test_derivatives_match_geomdl(seed):
    rng = np.random.default_rng(seed)
    curve = random_curve(rng, degree=seed % 5 + 1)
    u = rng.uniform(0.0, 1.0, 25)
    mine = curve.derivatives(u, 3)
    assert mine.shape == (4, 25, 3)
    ref = geomdl_derivatives(curve, u, 3)
    for k in range(4):
        assert_rel_close(mine[k], ref[k], 1e-12)
    np.testing.assert_allclose(curve.point(u), mine[0], rtol=1e-14)


@pytest.mark.parametrize("seed", range(20, 30))
def test_derivatives_match_scipy_homogeneous(seed):
    rng = np.random.default_rng(seed)
    curve = random_curve(rng, degree=seed % 5 + 1)
    u = rng.uniform(0.0, 1.0, 25)
    mine, ref = curve.derivatives(u, 3), scipy_derivatives(curve, u, 3)
    for k in range(4):
        assert_rel_close(mine[k], ref[k], 1e-12)


def test_end_points_scalars_and_clamping():
    rng = np.random.default_rng(7)
    curve = random_curve(rng, 3)
    np.testing.assert_allclose(curve.point(0.0)[0], curve.control_points_mm[0], atol=1e-12)
    np.testing.assert_allclose(curve.point(1.0)[0], curve.control_points_mm[-1], atol=1e-12)
    assert curve.derivatives(0.3, 2).shape == (3, 1, 3)
    outside = curve.derivatives([-0.5, 1.5], 3)
    np.testing.assert_array_equal(outside, curve.derivatives([0.0, 1.0], 3))
    assert (curve.u_start, curve.u_end) == (0.0, 1.0)


def test_from_segment_copies_the_data():
    seg = segments.Nurbs(
        degree=2,
        knots=segments.frozen_array([0, 0, 0, 1, 1, 1]),
        control_points_mm=segments.frozen_array([[0, 0, 0], [1, 2, 0], [3, 0, 1]]),
        weights=segments.frozen_array([1, 2, 1]),
        feed_mm_s=10.0,
        line=3,
    )
    curve = NurbsCurve.from_segment(seg)
    # Quadratic Bezier, weights (1, 2, 1) at u = ½: (P0 + 4 P1 + P2)/6.
    np.testing.assert_allclose(curve.point(0.5)[0], [7 / 6, 8 / 6, 1 / 6], rtol=1e-15)


# ------------------------------------------------------------------------------ curvature


def test_circle_curvature_and_length():
    radius = 7.5
    curve = circle(radius)
    u = np.linspace(0.0, 1.0, 401)
    np.testing.assert_allclose(np.linalg.norm(curve.point(u), axis=1), radius, rtol=1e-14)
    np.testing.assert_allclose(curve.curvature(u), 1.0 / radius, rtol=1e-12)
    np.testing.assert_allclose(curve.curvature_derivative(u), 0.0, atol=1e-12 / radius)
    assert curve.length_mm == pytest.approx(2 * np.pi * radius, rel=1e-12, abs=0)
    # Each quarter (a knot span) is a quarter of the circle.
    quarters = curve.arc_length([0.25, 0.5, 0.75, 1.0])
    np.testing.assert_allclose(quarters, np.pi * radius * np.array([0.5, 1, 1.5, 2]), rtol=1e-12)


def test_cusp_gives_inf_not_nan():
    curve = cusp_cubic()
    np.testing.assert_array_equal(curve.derivatives(0.5, 1)[1], 0.0)
    near = 0.5 + 2.0**-12  # s = 2^-11 exactly
    u = np.r_[np.linspace(0.0, 1.0, 201), near]
    kappa, dkappa = curve.curvature(u), curve.curvature_derivative(u)
    assert not np.any(np.isnan(kappa)) and not np.any(np.isnan(dkappa))
    assert kappa[100] == np.inf and dkappa[100] == 0.0
    assert np.all(np.isfinite(np.delete(kappa, 100)))
    # κ of (s², s³) is 6/(|s| (4 + 9 s²)^{3/2}): large but finite next to the cusp (the
    # tolerance allows for cancellation in C' ~ s).
    s_near = 2.0**-11
    assert kappa[-1] == pytest.approx(6 / (s_near * (4 + 9 * s_near**2) ** 1.5), rel=1e-9)
    # ∫_{-1}^{1} |s| sqrt(4 + 9 s²) ds = 2 (13^{3/2} − 8)/27.
    assert curve.length_mm == pytest.approx(2 * (13**1.5 - 8) / 27, rel=1e-12, abs=0)
    s = np.linspace(0.0, curve.length_mm, 51)
    np.testing.assert_allclose(curve.arc_length(curve.param_at_length(s)), s, rtol=0, atol=1e-12)


def test_repeated_control_points_stay_finite():
    points = [[0, 0, 0], [0, 0, 0], [1, 2, 0], [3, 1, 1], [3, 1, 1], [4, 4, 4]]
    curve = NurbsCurve(3, [0, 0, 0, 0, 0.4, 0.6, 1, 1, 1, 1], points, [1, 1, 2, 1, 3, 1])
    u = np.linspace(0.0, 1.0, 101)
    kappa, dkappa = curve.curvature(u), curve.curvature_derivative(u)
    assert not np.any(np.isnan(kappa)) and np.all(np.isfinite(dkappa))
    assert kappa[0] == np.inf  # C'(0) = 0 since P0 = P1
    assert np.isfinite(curve.length_mm) and curve.length_mm > 0
    s = np.linspace(0.0, curve.length_mm, 51)
    np.testing.assert_allclose(curve.arc_length(curve.param_at_length(s)), s, rtol=0, atol=1e-12)


def test_zero_length_curve_is_finite():
    curve = NurbsCurve(2, [0, 0, 0, 0.5, 1, 1, 1], np.full((4, 3), 5.0), [1, 2, 3, 1])
    assert curve.length_mm == pytest.approx(0.0, abs=1e-13)
    u = curve.param_at_length([0.0, 1.0])
    assert np.all(np.isfinite(u)) and np.all((u >= 0.0) & (u <= 1.0))
    np.testing.assert_allclose(curve.point(np.linspace(0, 1, 11)), 5.0, rtol=1e-15)
    assert not np.any(np.isnan(curve.curvature([0.0, 0.3, 1.0])))
    assert np.all(np.isfinite(curve.curvature_derivative([0.0, 0.3, 1.0])))


def planar_curve(rng: np.random.Generator, degree: int) -> NurbsCurve:
    c = random_curve(rng, degree)
    points = c.control_points_mm.copy()
    points[:, 2] = 0.0
    return NurbsCurve(degree, c.knots, points, c.weights)


@pytest.mark.parametrize("seed", range(5))
def test_planar_curvature_derivative_matches_spec_formula(seed):
    rng = np.random.default_rng(100 + seed)
    curve = planar_curve(rng, degree=3 + seed % 3)
    u = rng.uniform(0.05, 0.95, 30)
    d = geomdl_derivatives(curve, u, 3)  # independent derivatives
    (x1, y1), (x2, y2), (x3, y3) = (d[k, :, :2].T for k in (1, 2, 3))
    speed2 = x1**2 + y1**2
    cross = x1 * y2 - y1 * x2
    # SPEC §2: dκ/du = [(x'y''' − y'x''')|C'|² − 3(x'y'' − y'x'')(C'·C'')] / |C'|⁵ (signed).
    spec = ((x1 * y3 - y1 * x3) * speed2 - 3 * cross * (x1 * x2 + y1 * y2)) / speed2**2.5
    mine = curve.curvature_derivative(u)
    np.testing.assert_allclose(mine, np.sign(cross) * spec, rtol=1e-10, atol=0)


@pytest.mark.parametrize("seed", range(5))
def test_curvature_derivative_matches_finite_difference(seed):
    rng = np.random.default_rng(200 + seed)
    curve = random_curve(rng, degree=3 + seed % 3)
    # Stay inside knot spans (κ' jumps at low-continuity knots).
    spans = np.unique(curve.knots)
    mids = 0.5 * (spans[:-1] + spans[1:])
    u, h = mids, 1e-5 * np.min(np.diff(spans))
    fd = (curve.curvature(u + h) - curve.curvature(u - h)) / (2 * h)
    mine = curve.curvature_derivative(u)
    scale = np.maximum(np.abs(mine), curve.curvature(u) / np.diff(spans).min())
    assert np.all(np.abs(mine - fd) <= 1e-5 * scale)
    if seed == 0:  # the planar case too
        planar = planar_curve(rng, 3)
        fd = (planar.curvature(u + h) - planar.curvature(u - h)) / (2 * h)
        np.testing.assert_allclose(planar.curvature_derivative(u), fd, rtol=1e-5)


def test_curvature_derivative_is_zero_on_a_straight_line():
    d = np.zeros((4, 3, 3))
    d[1] = [1.0, 2.0, 3.0]
    np.testing.assert_array_equal(curvature_derivative_from_derivatives(d), 0.0)


# ------------------------------------------------------------------------------ arc length


@pytest.mark.parametrize("seed", range(5))
def test_length_matches_adaptive_quadrature(seed):
    rng = np.random.default_rng(300 + seed)
    curve = random_curve(rng, degree=seed % 5 + 1)
    breaks = np.unique(curve.knots)
    ref = sum(
        quad(lambda x: curve.speed(x)[0], a, b, epsabs=0, epsrel=1e-13, limit=500)[0]
        for a, b in zip(breaks[:-1], breaks[1:])
    )
    assert curve.length_mm == pytest.approx(ref, rel=1e-12, abs=0)
    u = rng.uniform(0.0, 1.0, 5)
    partial = [
        quad(
            lambda x: curve.speed(x)[0],
            0.0,
            v,
            points=breaks[1:-1],
            epsabs=0,
            epsrel=1e-13,
            limit=500,
        )[0]
        for v in u
    ]
    np.testing.assert_allclose(curve.arc_length(u), partial, rtol=1e-11)


@pytest.mark.parametrize("seed", range(10))
def test_param_at_length_inverts_arc_length(seed):
    rng = np.random.default_rng(400 + seed)
    curve = random_curve(rng, degree=seed % 5 + 1)
    s = np.r_[0.0, rng.uniform(0.0, curve.length_mm, 200), curve.length_mm]
    u = curve.param_at_length(s)
    assert u[0] == 0.0 and u[-1] == pytest.approx(1.0, abs=1e-14)
    # 1e-12 mm, or the resolution of u itself (an ulp of u moves the point |C'| ulp(u) mm;
    # random knots put |C'| up to ~1e4 mm per unit u, where that is ~1e-12 mm).
    resolution_mm = 2 * np.spacing(u) * curve.speed(u)
    assert np.all(np.abs(curve.arc_length(u) - s) <= np.maximum(1e-12, resolution_mm))
    v = rng.uniform(0.0, 1.0, 50)
    np.testing.assert_allclose(curve.param_at_length(curve.arc_length(v)), v, atol=1e-12)


# ------------------------------------------------------------------- fast evaluation paths


@pytest.mark.parametrize("degree", [1, 2, 3, 5])
def test_basis_functions_match_scipy(degree):
    rng = np.random.default_rng(50 + degree)
    curve = random_curve(rng, degree)
    u = np.r_[rng.uniform(0.0, 1.0, 30), np.unique(curve.knots)]
    spans = find_span(curve.knots, degree, u)
    mine = basis_functions(curve.knots, degree, u)
    n = curve.weights.size
    for j in range(degree + 1):
        ref = [BSpline(curve.knots, np.eye(n)[i], degree)(x) for i, x in zip(spans - degree + j, u)]
        np.testing.assert_allclose(mine[j], ref, rtol=0, atol=1e-14)


@pytest.mark.parametrize("seed", range(8))
def test_power_form_matches_scipy_and_one_sided_at_knots(seed):
    """Each span's centred power form equals the B-spline (scipy oracle) on that span, and at
    an interior knot the span to its left gives the left limit (the derivative may jump)."""
    rng = np.random.default_rng(500 + seed)
    curve = random_curve(rng, degree=seed % 5 + 1)
    pf = curve.power_form
    u = rng.uniform(0.0, 1.0, 40)
    ref = scipy_derivatives(curve, u, 3)
    mine = pf.derivatives(u, None, 3)
    for k in range(4):
        assert_rel_close(mine[k], ref[k], 1e-11)
    np.testing.assert_allclose(pf.point(u), ref[0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(pf.speed(u), np.linalg.norm(ref[1], axis=1), rtol=1e-12)
    # Left limits at interior knots: the left span at the knot vs scipy just left of it.
    knots = pf.breaks[1:-1]
    left = pf.derivatives(knots, np.arange(knots.size), 1)
    h = 1e-6
    below = scipy_derivatives(curve, knots - h, 3)
    limit = below[1] + h * below[2] + 0.5 * h * h * below[3]  # C'(k⁻) to O(h³)
    assert_rel_close(left[1], limit, 1e-10)
    assert_rel_close(left[0], scipy_derivatives(curve, knots, 0)[0], 1e-13)


def test_fast_inversion_falls_back_at_a_cusp():
    """u(s) is not smooth at a cusp (|C'| = 0): the table hands those intervals to Newton,
    and the result is still within 1e-9 mm everywhere, monotone, and on the curve."""
    curve = cusp_cubic()
    table = curve.inverse_table
    assert table.exact.any() and not table.exact.all()
    s = np.linspace(0.0, curve.length_mm, 4001)
    u = curve.param_at_length_fast(s)
    assert np.all(np.abs(curve.arc_length(u) - s) <= 1e-9)
    assert np.all(np.diff(u) >= 0.0)
    points, u2 = curve.points_at_length(s)
    np.testing.assert_array_equal(u2, u)
    np.testing.assert_allclose(points, curve.point(u), rtol=0, atol=1e-14)


def test_fast_inversion_of_a_point_curve_is_finite():
    curve = NurbsCurve(2, [0, 0, 0, 0.5, 1, 1, 1], np.full((4, 3), 5.0), [1, 2, 3, 1])
    points, u = curve.points_at_length([0.0, 1.0])
    assert np.all(np.isfinite(u)) and np.all((u >= 0.0) & (u <= 1.0))
    np.testing.assert_allclose(points, 5.0, rtol=1e-15)


def test_step_lengths_against_quadrature_and_the_circle():
    """Arc lengths of short steps (NurbsCurve.step_lengths, what the feed fluctuation
    measures): each step's integral on its own. Against scipy's adaptive quadrature of the
    speed (scipy B-splines, independent of the curve's own evaluation) over each step,
    steps inside one table interval, across interval ends and knots (a double and a
    triple knot), backwards and of zero length, to 1e-13 relative."""
    rng = np.random.default_rng(5)
    curve = random_curve(rng, 3)
    w = curve.weights[:, None]
    spline = BSpline(curve.knots, np.hstack((curve.control_points_mm * w, w)), 3)

    def speed(u: float) -> float:
        h, dh = spline(u), spline(u, nu=1)
        return float(np.linalg.norm((dh[:3] * h[3] - h[:3] * dh[3]) / (h[3] * h[3])))

    brk = curve.arc_table.breaks
    starts = np.r_[rng.uniform(0.0, 0.999, 300), brk[1:-1] - 1e-4]  # + steps across ends
    u = np.sort(np.r_[starts, starts + rng.uniform(1e-6, 1e-3, starts.size)])
    u = np.r_[u, u[-1], u[5]]  # a zero step, then a long one backwards
    ds = curve.step_lengths(u)
    knots = np.unique(curve.knots)
    for a, b, got in zip(u[:-1], u[1:], ds):
        lo, hi = min(a, b), max(a, b)
        inner = knots[(knots > lo) & (knots < hi)]
        ref = quad(
            speed, lo, hi, points=inner if inner.size else None, epsabs=0.0, epsrel=2e-14, limit=200
        )[0] * (1.0 if b >= a else -1.0)
        assert got == pytest.approx(ref, rel=1e-13, abs=1e-15)
    across = np.searchsorted(brk, u[:-1], "right") != np.searchsorted(brk, u[1:], "right")
    assert across.sum() >= brk.size - 2  # the steps across interval ends were taken
    assert ds[-2] == 0.0 and ds[-1] < 0.0


def _extreme_weight_curve() -> NurbsCurve:
    """A quadratic with one weight of 140,164 among weights of 1 (the fuzzer's G5.2 in G18)."""
    knots = np.array([0.0, 0, 0, 1, 2, 3, 3, 3])
    ctrl = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 2], [0, 0, 2], [0, 0, 0]])
    return NurbsCurve(2, knots, ctrl, np.array([1.0, 1, 1, 140164, 2]))


def test_arc_length_of_an_extreme_weight():
    """|C'(u)| of that curve peaks in a sliver of its spans that 1,024 equal pieces of
    16-point Gauss–Legendre miss: its table said 1.8878 mm for the last span, where a
    2-million-chord polyline measures 2.0000069 mm. The pieces that do not converge at the
    finest equal split are halved where they do not (arclength._halve_pieces); each span now
    agrees with the polyline to its chord error (h²κ/24 per chord: below 3e-9 mm here)."""
    curve = _extreme_weight_curve()
    for lo in (0.0, 1.0, 2.0):
        u = np.linspace(lo, lo + 1.0, 2_000_001)
        chords_mm = np.linalg.norm(np.diff(curve.point(u), axis=0), axis=1).sum()
        span_mm = float(np.diff(curve.arc_length(np.array([lo, lo + 1.0])))[0])
        assert chords_mm <= span_mm + 1e-12  # a polyline is never longer than its curve
        assert span_mm - chords_mm < 3e-9
    assert curve.arc_table.breaks.size <= 2 * arclength.HALVING_MAX_PIECES + 3 * 1024


def test_inverse_table_is_bounded_on_an_extreme_weight(monkeypatch):
    """On that curve u(s) once escaped the inversion's quintics below 0.1 µm and the table's
    intervals doubled at every level, to 3.8 million at depth 35 (24 GB, the OOM killer).
    The table stops at its budget and leaves the rest to the exact Newton inversion, whose
    parameters still invert the curve's arc length to 1e-9 mm. With the arc length right
    (above) this curve needs 638 intervals; a budget below that exercises the rule."""
    monkeypatch.setattr(inverse, "INVERSE_MAX_INTERVALS", 64)
    curve = _extreme_weight_curve()
    table = curve.inverse_table
    initial = int(
        np.sum(np.ceil(np.diff(curve.arc_length(curve.knots[2:6])) / inverse.INVERSE_START_MM))
    )
    assert table.inv_width.size <= max(inverse.INVERSE_MAX_INTERVALS, 16 * initial)
    assert table.exact.any()
    s = np.linspace(0.0, curve.length_mm, 401)
    points, u = curve.points_at_length(s)
    np.testing.assert_allclose(curve.arc_length(u), s, rtol=0, atol=1e-9)
    np.testing.assert_allclose(points, curve.point(u), rtol=0, atol=1e-10)  # two evaluations


@pytest.mark.parametrize("seed", [2, 7, 11])
def test_inverse_table_node_data_equals_a_fresh_evaluation(seed, monkeypatch):
    """The table evaluates each node's derivatives once (an interval's end is the next one's
    start; a split's halves share the new node). Every interval's end data, at every level,
    is bit for bit that of a fresh evaluation at its own ends on its own span (one-sided at
    knots: the end of a span's last interval on that span), on curves with double and triple
    knots and weights 0.2–5 that need several levels of splitting."""
    curve = random_curve(np.random.default_rng(seed), 3)
    pf = curve.power_form
    seen = {"levels": 0, "spans": set()}
    original = inverse._interval_hermite

    def checked(lo, hi, width, d_lo, d_hi, floor):
        span = pf.span_of(lo)  # lo < hi: lo is inside its own span
        np.testing.assert_array_equal(d_lo, pf.derivatives(lo, span, 2))
        np.testing.assert_array_equal(d_hi, pf.derivatives(hi, span, 2))
        seen["levels"] += 1
        seen["spans"].update(span.tolist())
        return original(lo, hi, width, d_lo, d_hi, floor)

    monkeypatch.setattr(inverse, "INVERSE_START_MM", 5.0)  # few first intervals: more levels
    monkeypatch.setattr(inverse, "_interval_hermite", checked)
    table = inverse.InverseArcTable.build(curve, start_mm=5.0)
    assert seen["levels"] >= 3 and len(seen["spans"]) == pf.centers.size >= 2
    assert not table.exact.any()
    s = np.linspace(0.0, curve.length_mm, 2001)
    u, _, _ = table.params(s)
    np.testing.assert_allclose(curve.arc_length(u), s, rtol=0, atol=1e-9)
