"""PH fits of curve regions (SPEC §6), against closed-form test curves."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from nurbscnc.errors import GeometryError, PlanningError
from nurbscnc.plan.phfit import fit_region, ph_deviation_um


class CircleArc:
    """Test-only exact circle arc as a rational quadratic Bézier (closed-form derivatives).

    Centre ``c``, radius ``r`` [mm], from angle ``a0`` to ``a1`` (|a1 − a0| < π), u ∈ [0, 1].
    """

    def __init__(self, r, a0, a1, c=(0.0, 0.0, 0.0)):
        self.r, self.c = r, np.asarray(c, float)
        half = 0.5 * (a1 - a0)
        mid = 0.5 * (a0 + a1)
        self.p = (
            np.array(
                [
                    [np.cos(a0), np.sin(a0), 0.0],
                    [np.cos(mid) / np.cos(half), np.sin(mid) / np.cos(half), 0.0],
                    [np.cos(a1), np.sin(a1), 0.0],
                ]
            )
            * r
            + self.c
        )
        self.w = np.array([1.0, np.cos(half), 1.0])

    def _nd(self, u):
        u = np.asarray(u, float)[:, None]
        b = [(1 - u) ** 2, 2 * u * (1 - u), u**2]
        db = [-2 * (1 - u), 2 - 4 * u, 2 * u]
        n = sum(bk * wk * pk for bk, wk, pk in zip(b, self.w, self.p))
        dn = sum(bk * wk * pk for bk, wk, pk in zip(db, self.w, self.p))
        d = sum(bk * wk for bk, wk in zip(b, self.w))
        dd = sum(bk * wk for bk, wk in zip(db, self.w))
        return n, dn, d, dd

    def point(self, u):
        n, _, d, _ = self._nd(u)
        return n / d

    def derivatives(self, u, order):
        assert order == 1
        n, dn, d, dd = self._nd(u)
        c = n / d
        return np.array([c, (dn - dd * c) / d])


class Cubic:
    """Test-only polynomial cubic Bézier in 3-D (closed-form derivatives)."""

    def __init__(self, pts):
        self.p = np.asarray(pts, float)

    def point(self, u):
        u = np.asarray(u, float)[:, None]
        b = [(1 - u) ** 3, 3 * u * (1 - u) ** 2, 3 * u**2 * (1 - u), u**3]
        return sum(bk * pk for bk, pk in zip(b, self.p))

    def derivatives(self, u, order):
        assert order == 1
        u = np.asarray(u, float)[:, None]
        d = 3 * np.diff(self.p, axis=0)
        db = [(1 - u) ** 2, 2 * u * (1 - u), u**2]
        return np.array([self.point(u[:, 0]), sum(bk * dk for bk, dk in zip(db, d))])


U_TURN = Cubic([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [10.0, 3.0, 0.0], [0.0, 3.0, 0.0]])


def _rotation(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def test_circle_unsplit_error_is_small_and_order_four():
    """Halving the region divides the error by 2⁴: PH quintic C1 Hermite interpolation has
    approximation order 4 (Farouki & Neff 1995), not 6 (that is the C2 PH septic's order)."""
    maxima = []
    for angle in (np.pi / 3, np.pi / 6, np.pi / 12, np.pi / 24):
        arc = CircleArc(10.0, 0.2, 0.2 + angle)
        fit = fit_region(arc, 0.0, 1.0, split=False)
        assert len(fit.pieces) == 1
        assert 0.0 < fit.rms_um < fit.max_um
        # Cross-check with the exact circle: radial error of dense PH samples.
        ph = fit.pieces[0].ph
        radial_um = 1e3 * np.abs(
            np.linalg.norm(ph.point_mm(np.linspace(0, 1, 2001)), axis=1) - 10.0
        )
        assert fit.max_um == pytest.approx(radial_um.max(), rel=1e-3)
        maxima.append(fit.max_um)
    orders = np.log2(np.array(maxima[:-1]) / np.array(maxima[1:]))
    # Measured on R = 10 mm, 60°/30°/15°/7.5°: max 46.09, 2.922, 0.1833, 0.01146 µm;
    # orders 3.979, 3.995, 3.999.
    assert maxima[0] == pytest.approx(46.09, rel=1e-3)
    np.testing.assert_allclose(orders, 4.0, atol=0.05)


def test_deviation_is_true_point_to_curve_distance():
    fit = fit_region(U_TURN, 0.2, 0.6, split=False)
    ph = fit.pieces[0].ph
    u = np.linspace(0.2, 0.6, 23)
    pts = U_TURN.point(u)
    dev = ph_deviation_um(ph, pts)
    xs = np.linspace(0, 1, 4001)
    dense = ph.point_mm(xs)
    for k, q in enumerate(pts):
        g = xs[np.argmin(np.linalg.norm(dense - q, axis=1))]
        res = minimize_scalar(
            lambda x, q=q: np.sum((ph.point_mm([x])[0] - q) ** 2),
            bounds=(max(0.0, g - 1e-3), min(1.0, g + 1e-3)),
            method="bounded",
            options={"xatol": 1e-13},
        )
        oracle_um = 1e3 * np.sqrt(min(res.fun, np.sum((ph.point_mm([g])[0] - q) ** 2)))
        assert dev[k] == pytest.approx(oracle_um, abs=1e-5)
    assert fit.max_um > 10.0  # a real deviation, not a trivial zero


def test_split_fit_meets_tolerance_with_g1_joins():
    tol = 1.0
    fit = fit_region(U_TURN, 0.0, 1.0, tolerance_um=tol)
    pieces = fit.pieces
    assert len(pieces) > 2
    for p in pieces:
        assert p.rms_um <= tol and p.max_um <= 3 * tol
    assert fit.rms_um <= tol and fit.max_um <= 3 * tol
    assert fit.max_um == max(p.max_um for p in pieces)
    # Parameter intervals tile [0, 1] in order.
    assert pieces[0].u_a == 0.0 and pieces[-1].u_b == 1.0
    for left, right in zip(pieces[:-1], pieces[1:]):
        assert left.u_b == right.u_a
        a = left.ph.derivatives_mm([1.0], 1)[:, 0]
        b = right.ph.derivatives_mm([0.0], 1)[:, 0]
        np.testing.assert_allclose(a[0], b[0], rtol=0, atol=1e-12)
        np.testing.assert_allclose(
            a[1] / np.linalg.norm(a[1]), b[1] / np.linalg.norm(b[1]), rtol=0, atol=1e-12
        )
    ends = U_TURN.point(np.array([0.0, 1.0]))
    np.testing.assert_allclose(pieces[0].ph.point_mm([0.0])[0], ends[0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(pieces[-1].ph.point_mm([1.0])[0], ends[1], rtol=0, atol=1e-12)
    # Overall RMS is the RMS over all samples (equal counts per piece).
    assert fit.rms_um == pytest.approx(np.sqrt(np.mean([p.rms_um**2 for p in pieces])), rel=1e-12)
    # The unsplit fit of the same region is far off tolerance.
    assert fit_region(U_TURN, 0.0, 1.0, split=False).rms_um > 100 * tol


def test_fit_is_invariant_under_rigid_motion_into_a_tilted_plane():
    rot = _rotation([1.0, -2.0, 0.5], 0.7)
    shift = np.array([3.0, -4.0, 12.0])
    tilted = Cubic(U_TURN.p @ rot.T + shift)
    flat = fit_region(U_TURN, 0.1, 0.9, tolerance_um=2.0)
    moved = fit_region(tilted, 0.1, 0.9, tolerance_um=2.0)
    assert len(moved.pieces) == len(flat.pieces)
    assert moved.rms_um == pytest.approx(flat.rms_um, rel=1e-6)
    assert moved.max_um == pytest.approx(flat.max_um, rel=1e-6)
    for a, b in zip(flat.pieces, moved.pieces):
        xs = np.linspace(0, 1, 11)
        np.testing.assert_allclose(b.ph.point_mm(xs), a.ph.point_mm(xs) @ rot.T + shift, atol=1e-12)


def test_depth_cap_raises_and_bad_arguments():
    arc = CircleArc(10.0, 0.0, 1.0)
    with pytest.raises(PlanningError, match="halvings"):
        fit_region(arc, 0.0, 1.0, tolerance_um=1e-6, max_depth=2)
    with pytest.raises(PlanningError):
        fit_region(arc, 0.5, 0.5)
    with pytest.raises(GeometryError):
        fit_region(Cubic([[0, 0, 0], [1, 0, 1], [1, 1, -1], [0, 1, 0]]), 0.0, 1.0)


def test_zx_plane_curve_uses_exact_plane_axes():
    # The U-turn drawn in the ZX plane at y = 5: (x, y, z) -> (y_old, 5, x_old).
    zx = Cubic(np.column_stack([U_TURN.p[:, 1], np.full(4, 5.0), U_TURN.p[:, 0]]))
    fit = fit_region(zx, 0.0, 1.0)
    ph = fit.pieces[0].ph
    np.testing.assert_array_equal(ph.e1, [0, 0, 1])
    np.testing.assert_array_equal(ph.e2, [1, 0, 0])
    pts = np.concatenate([p.ph.point_mm(np.linspace(0, 1, 9)) for p in fit.pieces])
    assert np.all(pts[:, 1] == 5.0)
    flat = fit_region(U_TURN, 0.0, 1.0)
    assert fit.rms_um == pytest.approx(flat.rms_um, rel=1e-9)


def test_real_nurbs_circle_matches_closed_form_arc():
    from nurbscnc.geometry.nurbs import NurbsCurve

    # The standard 9-point rational quadratic circle, R = 10 mm about (1, 2, 0.5) in z = 0.5.
    s = np.sqrt(0.5)
    unit = np.array(
        [[1, 0], [1, 1], [0, 1], [-1, 1], [-1, 0], [-1, -1], [0, -1], [1, -1], [1, 0]], float
    )
    centre = np.array([1.0, 2.0, 0.5])
    pts = np.column_stack([10.0 * unit, np.zeros(9)]) + centre
    curve = NurbsCurve(
        2, [0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1], pts, [1, s, 1, s, 1, s, 1, s, 1]
    )
    # Its first span is the quarter arc CircleArc(10, 0, π/2) with u = 4 u_nurbs; the Hermite
    # data (u_b − u_a) C′ do not depend on an affine reparametrisation, so the fits coincide.
    fit = fit_region(curve, 0.05, 0.2, split=False)
    ref = fit_region(CircleArc(10.0, 0.0, np.pi / 2, c=centre), 0.2, 0.8, split=False)
    np.testing.assert_allclose(
        fit.pieces[0].ph.control_points_mm, ref.pieces[0].ph.control_points_mm, atol=1e-12
    )
    assert fit.max_um == pytest.approx(ref.max_um, rel=1e-9)
    # A region across a knot, split to 0.1 µm; radial error of the pieces stays within 3e.
    split = fit_region(curve, 0.2, 0.45, tolerance_um=0.1)
    assert len(split.pieces) > 1 and split.rms_um <= 0.1 and split.max_um <= 0.3
    for p in split.pieces:
        xs = np.linspace(0, 1, 501)
        radial_um = 1e3 * np.abs(np.linalg.norm(p.ph.point_mm(xs) - centre, axis=1) - 10.0)
        assert radial_um.max() <= 0.3 + 1e-6
        assert np.all(p.ph.point_mm(xs)[:, 2] == 0.5)
