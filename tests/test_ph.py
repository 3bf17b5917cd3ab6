"""PH quintics (SPEC §4): CALGO 952 reference values, closed forms vs independent oracles."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad

from nurbscnc.errors import GeometryError
from nurbscnc.geometry.ph import PHQuintic, hermite_ph, hermite_solutions, plane_frame

# CALGO 952 example (SPEC §4).
P0, P1, P4, P5 = 0.8 + 1.4j, 2.4 + 0.8j, 2.6 + 4.2j, 4.2 + 3.6j
D0, D1 = 5 * (P1 - P0), 5 * (P5 - P4)


def _bezier_hodograph(cp: np.ndarray, xi: np.ndarray) -> np.ndarray:
    """r′ of a degree-5 Bézier from its control points (independent of w): 5 Σ Δp_k B_k^4."""
    diffs = 5.0 * np.diff(cp)
    out = np.zeros(xi.shape, dtype=complex)
    for k, dk in enumerate(diffs):
        out += dk * [1, 4, 6, 4, 1][k] * xi**k * (1 - xi) ** (4 - k)
    return out


def _bezier_point(cp: np.ndarray, xi: float) -> complex:
    """de Casteljau evaluation (independent of the Bernstein-matrix code)."""
    pts = list(cp)
    while len(pts) > 1:
        pts = [(1 - xi) * a + xi * b for a, b in zip(pts[:-1], pts[1:])]
    return pts[0]


def test_calgo_952_reference_values():
    ph = hermite_ph(P0, P5, D0, D1)
    cp = ph.control_points
    assert abs(cp[0] - P0) < 1e-12 and abs(cp[1] - P1) < 1e-12
    assert abs(cp[4] - P4) < 1e-12 and abs(cp[5] - P5) < 1e-12
    assert abs(cp[2] - (2.837719 + 2.514034j)) < 1e-6
    assert abs(cp[3] - (2.162281 + 2.485966j)) < 1e-6
    assert abs(ph.length_mm - 4.824) < 5e-4


def test_four_distinct_solutions_all_interpolate():
    sols = hermite_solutions(P0, P5, D0, D1)
    assert len(sols) == 4
    cps = np.array([s.control_points for s in sols])
    for i in range(4):
        for j in range(i + 1, 4):
            assert np.abs(cps[i] - cps[j]).max() > 1e-3
    for s in sols:
        assert abs(s.point(0.0) - P0) < 1e-12
        assert abs(s.point(1.0) - P5) < 1e-12
        assert abs(s.hodograph(0.0) - D0) < 1e-12
        assert abs(s.hodograph(1.0) - D1) < 1e-12
    # The chosen one is the lowest-energy one among the rotation-index-0 pair here.
    chosen = hermite_ph(P0, P5, D0, D1)
    energies = sorted(s.bending_energy() for s in sols)
    assert chosen.bending_energy() == pytest.approx(energies[0], rel=1e-12)


def test_sigma_equals_speed_and_length_equals_quadrature():
    ph = hermite_ph(P0, P5, D0, D1)
    xi = np.linspace(0.0, 1.0, 101)
    speed = np.abs(_bezier_hodograph(ph.control_points, xi))
    np.testing.assert_allclose(ph.sigma(xi), speed, rtol=1e-12, atol=0)
    np.testing.assert_allclose(
        ph.hodograph(xi), _bezier_hodograph(ph.control_points, xi), rtol=1e-12, atol=1e-13
    )
    length, _ = quad(
        lambda t: abs(_bezier_hodograph(ph.control_points, np.array(t))),
        0.0,
        1.0,
        epsabs=0.0,
        epsrel=1e-13,
        limit=200,
    )
    assert ph.length_mm == pytest.approx(length, rel=1e-12)
    part, _ = quad(
        lambda t: abs(_bezier_hodograph(ph.control_points, np.array(t))),
        0.0,
        0.37,
        epsabs=0.0,
        epsrel=1e-13,
        limit=200,
    )
    assert float(ph.arc_length(0.37)) == pytest.approx(part, rel=1e-12)
    for x in (0.0, 0.25, 0.6, 1.0):
        assert abs(ph.point(x) - _bezier_point(ph.control_points, x)) < 1e-13


def test_curvature_and_derivatives_vs_finite_differences():
    ph = hermite_ph(P0, P5, D0, D1)
    xi = np.linspace(0.05, 0.95, 19)
    h = 1e-3
    # Fourth-order central differences of the point.
    r = [ph.point(xi + k * h) for k in (-2, -1, 0, 1, 2)]
    d1 = (r[0] - 8 * r[1] + 8 * r[3] - r[4]) / (12 * h)
    d2 = (-r[0] + 16 * r[1] - 30 * r[2] + 16 * r[3] - r[4]) / (12 * h * h)
    np.testing.assert_allclose(ph.hodograph(xi), d1, atol=1e-9)
    np.testing.assert_allclose(ph.second_derivative(xi), d2, atol=1e-6)
    kappa_fd = (np.conj(d1) * d2).imag / np.abs(d1) ** 3
    np.testing.assert_allclose(ph.curvature(xi), kappa_fd, rtol=1e-6, atol=1e-8)
    # Third derivative: central difference of the (exact) second derivative.
    d3 = (ph.second_derivative(xi + 1e-4) - ph.second_derivative(xi - 1e-4)) / 2e-4
    np.testing.assert_allclose(ph.third_derivative(xi), d3, atol=1e-5)
    # The 3-D layout: (order + 1, m, 3) in the XY plane at z = 0.
    der = ph.derivatives_mm(xi, 3)
    assert der.shape == (4, xi.size, 3)
    np.testing.assert_allclose(
        der[1, :, 0] + 1j * der[1, :, 1], ph.hodograph(xi), rtol=0, atol=1e-15
    )
    np.testing.assert_allclose(
        der[3, :, 0] + 1j * der[3, :, 1], ph.third_derivative(xi), rtol=0, atol=1e-12
    )
    assert np.all(der[:, :, 2] == 0.0)
    # Degree 5: the sixth derivative vanishes, the fifth is constant 5! × (Δ⁵ of control points).
    der6 = ph.derivatives_mm(xi, 6)
    assert np.all(der6[6] == 0.0)
    cp = ph.control_points
    fifth = 120.0 * (cp[5] - 5 * cp[4] + 10 * cp[3] - 10 * cp[2] + 5 * cp[1] - cp[0])
    np.testing.assert_allclose(der6[5, :, 0] + 1j * der6[5, :, 1], fifth, atol=1e-9)


def test_rotation_index_matches_unwrapped_tangent_angle():
    xi = np.linspace(0.0, 1.0, 200001)
    for s in hermite_solutions(P0, P5, D0, D1) + hermite_solutions(0, 1 + 1j, 2, 3j):
        angle = np.unwrap(np.angle(s.hodograph(xi)))
        dense = (angle[-1] - angle[0]) / (2 * np.pi)
        assert s.rotation_index() == pytest.approx(dense, abs=1e-9)
        # ∫κ ds by quadrature agrees too.
        turn, _ = quad(
            lambda t, s=s: float(s.curvature(t) * s.sigma(t)), 0, 1, limit=200, epsabs=1e-12
        )
        assert s.turning_angle_rad() == pytest.approx(turn, abs=1e-9)


def test_quarter_turn_has_quarter_rotation_index_and_straight_line():
    ph = hermite_ph(0, 1 + 1j, 2, 2j)
    assert ph.rotation_index() == pytest.approx(0.25, abs=1e-12)
    line = hermite_ph(0, 3, 3, 3)
    np.testing.assert_allclose(line.w, [np.sqrt(3)] * 3, atol=1e-15)
    assert line.rotation_index() == 0.0
    assert line.length_mm == pytest.approx(3.0, rel=1e-15)


@settings(max_examples=60, deadline=None)
@given(
    chord=st.floats(0.5, 20.0),
    chord_angle=st.floats(-np.pi, np.pi),
    a0=st.floats(-150.0, 150.0),
    a1=st.floats(-150.0, 150.0),
    m0=st.floats(0.3, 3.0),
    m1=st.floats(0.3, 3.0),
    x0=st.floats(-50.0, 50.0),
    y0=st.floats(-50.0, 50.0),
)
def test_chosen_solution_never_loops(chord, chord_angle, a0, a1, m0, m1, x0, y0):
    p0 = complex(x0, y0)
    direction = np.exp(1j * chord_angle)
    p5 = p0 + chord * direction
    d0 = m0 * chord * direction * np.exp(1j * np.radians(a0))
    d1 = m1 * chord * direction * np.exp(1j * np.radians(a1))
    ph = hermite_ph(p0, p5, d0, d1)
    assert abs(ph.rotation_index()) < 1.0
    scale = max(1.0, abs(p0), abs(p5))
    assert abs(ph.point(1.0) - p5) < 1e-12 * scale
    assert abs(ph.point(0.0) - p0) < 1e-12 * scale
    assert abs(ph.hodograph(0.0) - d0) < 1e-12 * max(1.0, abs(d0))
    assert abs(ph.hodograph(1.0) - d1) < 1e-12 * max(1.0, abs(d1))


@settings(max_examples=30, deadline=None)
@given(
    a0=st.floats(-150.0, 150.0),
    a1=st.floats(-150.0, 150.0),
    m0=st.floats(0.3, 3.0),
    m1=st.floats(0.3, 3.0),
    guess=st.floats(0.0, 1.0),
)
def test_param_at_length_inverts_arc_length(a0, a1, m0, m1, guess):
    ph = hermite_ph(
        0, 10, 10 * m0 * np.exp(1j * np.radians(a0)), 10 * m1 * np.exp(1j * np.radians(a1))
    )
    rng = np.random.default_rng(7)
    s = np.concatenate(([0.0, ph.length_mm], rng.uniform(0, ph.length_mm, 200)))
    xi = ph.param_at_length(s)
    assert np.all((xi >= 0) & (xi <= 1))
    assert np.abs(ph.arc_length(xi) - s).max() <= 1e-12
    # A bad (constant) starting guess gives the same answer.
    xi_bad = ph.param_at_length(s, xi_guess=guess)
    assert np.abs(ph.arc_length(xi_bad) - s).max() <= 1e-12
    # Round trip through the parameter.
    xs = np.linspace(0, 1, 51)
    np.testing.assert_allclose(ph.param_at_length(ph.arc_length(xs)), xs, atol=1e-12)


def test_param_at_length_shape_and_range():
    ph = hermite_ph(P0, P5, D0, D1)
    assert ph.param_at_length(0.0).shape == ()
    assert ph.param_at_length(np.zeros((2, 3))).shape == (2, 3)
    assert float(ph.param_at_length(ph.length_mm + 1e-12)) == 1.0
    with pytest.raises(GeometryError):
        ph.param_at_length(ph.length_mm + 1e-3)
    with pytest.raises(GeometryError):
        ph.param_at_length(-1e-3)


def test_closest_param_is_true_foot_point():
    ph = hermite_ph(P0, P5, D0, D1)
    xi0 = np.linspace(0.01, 0.99, 40)
    r1 = ph.hodograph(xi0)
    normal = 1j * r1 / np.abs(r1)
    offset = 1e-3 * np.sin(7 * xi0)  # mm, both sides
    q = ph.point(xi0) + offset * normal
    xi = ph.closest_param(q)
    np.testing.assert_allclose(xi, xi0, atol=1e-12)
    np.testing.assert_allclose(np.abs(ph.point(xi) - q), np.abs(offset), atol=1e-13)
    # Points beyond the ends project onto the end points.
    beyond = np.array([P0 - 0.1 * D0, P5 + 0.1 * D1])
    np.testing.assert_array_equal(ph.closest_param(beyond), [0.0, 1.0])


def test_plane_frame_and_3d_embedding():
    # ZX program: in-plane axes (z, x), exact.
    pts = np.array([[1.0, 2.0, 3.0], [4.0, 2.0, -1.0], [0.5, 2.0, 7.0]])
    origin, e1, e2 = plane_frame(pts)
    np.testing.assert_array_equal(e1, [0, 0, 1])
    np.testing.assert_array_equal(e2, [1, 0, 0])
    assert origin[1] == 2.0
    # A tilted plane: SVD frame, orthonormal, contains the points.
    rng = np.random.default_rng(3)
    n = np.array([1.0, 2.0, 2.0]) / 3.0
    a = np.cross(n, [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    uv = rng.normal(size=(30, 2))
    pts = 5.0 + uv[:, :1] * a + uv[:, 1:] * b
    origin, e1, e2 = plane_frame(pts)
    np.testing.assert_allclose([e1 @ e1, e2 @ e2, e1 @ e2], [1, 1, 0], atol=1e-15)
    np.testing.assert_allclose(np.cross(e1, e2), n, atol=1e-14)
    local = (pts - origin) @ np.array([e1, e2]).T
    np.testing.assert_allclose(origin + local @ np.array([e1, e2]), pts, atol=1e-13)
    with pytest.raises(GeometryError):
        plane_frame(pts + rng.normal(size=pts.shape) * 1e-3 * np.array([[0, 0, 1]]))
    # point_mm maps through the frame.
    ph = hermite_ph(P0, P5, D0, D1, origin, e1, e2)
    z = ph.point(np.array([0.0, 0.3, 1.0]))
    expect = origin + z.real[:, None] * e1 + z.imag[:, None] * e2
    np.testing.assert_allclose(ph.point_mm([0.0, 0.3, 1.0]), expect, atol=1e-14)
    np.testing.assert_allclose(ph.derivatives_mm([0.3], 0)[0], expect[1:2], atol=1e-14)


def test_invalid_hermite_data():
    with pytest.raises(GeometryError):
        hermite_solutions(0, 1, 0, 1)
    with pytest.raises(GeometryError):
        hermite_solutions(0, np.nan, 1, 1)


def test_phquintic_is_frozen_with_readonly_arrays():
    ph = PHQuintic(np.array([1.0, 1.0 + 0.5j, 1.0]), 0.0)
    with pytest.raises(AttributeError):
        ph.p0 = 1.0  # type: ignore[misc]
    with pytest.raises(ValueError):
        ph.control_points[0] = 1.0
