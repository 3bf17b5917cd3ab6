"""PH quintic corner blends (issue 7): end conditions, G2 continuity and the tolerance, checked
against independent references (Bézier evaluation from the control points, closed-form circle
points, a dense Hausdorff distance by k-d trees refined by scipy's bounded minimiser)."""

from __future__ import annotations

from math import comb

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.optimize import minimize_scalar
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from nurbscnc.errors import GeometryError
from nurbscnc.geometry.blend import (
    blend_corner,
    line_corner_blends,
    line_deviation_per_trim,
    ph_tables,
)
from nurbscnc.geometry.paths import ArcGeometry, LineGeometry
from nurbscnc.geometry.ph import PHQuintic

# --- independent references ------------------------------------------------------------------


def _bezier(cp: np.ndarray, xi: np.ndarray, k: int = 0) -> np.ndarray:
    """k-th derivative of the degree-5 Bézier with control points ``cp`` (6, 3) at ``xi``."""
    n = cp.shape[0] - 1
    diffs = cp.copy()
    for _ in range(k):
        diffs = np.diff(diffs, axis=0)
    m = n - k
    xi = np.asarray(xi, dtype=float)[:, None]
    out = sum(comb(m, j) * xi**j * (1 - xi) ** (m - j) * diffs[j] for j in range(m + 1))
    return out * (np.prod(range(n - k + 1, n + 1)) if k else 1.0)


def _curvature(cp: np.ndarray, xi: np.ndarray, normal=None) -> np.ndarray:
    """κ = |r′ × r″| / |r′|³ (signed by ``normal`` if given) from the control points."""
    d1, d2 = _bezier(cp, xi, 1), _bezier(cp, xi, 2)
    cross = np.cross(d1, d2)
    num = cross @ normal if normal is not None else np.linalg.norm(cross, axis=1)
    return num / np.linalg.norm(d1, axis=1) ** 3


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise distance from points p to segments [a, b] (all (m, 3))."""
    ab = b - a
    ab2 = np.einsum("ij,ij->i", ab, ab)
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.where(ab2 > 0, ab2, 1.0), 0.0, 1.0)
    return np.linalg.norm(p - a - t[:, None] * ab, axis=1)


def _to_polyline(p: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Distance from points p to the polyline ``poly``: the two segments next to the nearest
    vertex (exact for straight pieces; chord sagitta elsewhere, < 1e-11 mm in these tests)."""
    j = cKDTree(poly).query(p)[1]
    last = len(poly) - 1
    return np.min(
        [
            _segment_distance(p, poly[np.clip(j + s, 0, last)], poly[np.clip(j + s + 1, 0, last)])
            for s in (-1, 0)
        ],
        axis=0,
    )


def _hausdorff(blend, geom_a, geom_b, n: int = 4001) -> float:
    """Hausdorff distance between the blend and the corner path it replaces, densely."""
    cp = blend.ph.control_points_mm
    xi = np.linspace(0.0, 1.0, n)
    blend_pts = _bezier(cp, xi)
    la = geom_a.length_mm
    path = np.concatenate(
        (
            geom_a.point(np.linspace(la - blend.trim_a_mm, la, n)),
            geom_b.point(np.linspace(0.0, blend.trim_b_mm, n)),
        )
    )
    h_blend = _to_polyline(blend_pts, path).max()
    dist = _to_polyline(path, blend_pts)
    # Refine the farthest path point (the vertex, for a corner) by a bounded minimisation.
    i = int(np.argmax(dist))
    q = path[i]
    k = int(np.argmin(np.linalg.norm(blend_pts - q, axis=1)))
    lo, hi = xi[max(k - 2, 0)], xi[min(k + 2, n - 1)]
    res = minimize_scalar(
        lambda x: float(np.sum((_bezier(cp, [x])[0] - q) ** 2)),
        bounds=(lo, hi),
        method="bounded",
        options={"xatol": 1e-13},
    )
    h_path = max(np.sqrt(res.fun), np.delete(dist, i).max())
    return float(max(h_blend, h_path))


def _arc(start, tangent, normal, radius, angle) -> ArcGeometry:
    """Circular arc from ``start`` leaving along ``tangent``, counter-clockwise about
    ``normal`` for angle > 0."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    t = np.asarray(tangent, float) / np.linalg.norm(tangent)
    e2 = t * np.sign(angle)
    e1 = np.cross(e2, n)
    return ArcGeometry(
        np.asarray(start, float) - radius * e1, e1, e2, n, radius, radius, angle, 0.0
    )


def _circle_point(center, e1, e2, radius, phi):
    """center + r(cos φ e1 + sin φ e2) (closed form)."""
    return center + radius * (np.cos(phi) * e1 + np.sin(phi) * e2)


def _corner_lines(turning_rad, rot=None, length=10.0, vertex=(0.0, 0.0, 0.0)):
    v = np.asarray(vertex, float)
    ta = np.array([1.0, 0.0, 0.0])
    tb = np.array([np.cos(turning_rad), np.sin(turning_rad), 0.0])
    if rot is not None:
        ta, tb = rot @ ta, rot @ tb
    return LineGeometry(v - length * ta, v), LineGeometry(v, v + length * tb), ta, tb


def _ends(blend):
    cp = blend.ph.control_points_mm
    t0 = _bezier(cp, [0.0], 1)[0]
    t1 = _bezier(cp, [1.0], 1)[0]
    return cp[0], cp[-1], t0 / np.linalg.norm(t0), t1 / np.linalg.norm(t1)


# --- line–line corners -----------------------------------------------------------------------


def test_90_degree_line_corner():
    tol = 0.01
    a, b, ta, tb = _corner_lines(np.pi / 2, vertex=(3.0, -2.0, 1.5))
    blend = blend_corner(a, b, tol, 5.0, 5.0)
    v = np.array([3.0, -2.0, 1.5])
    d = blend.trim_a_mm
    assert blend.trim_b_mm == d
    p0, p5, t0, t1 = _ends(blend)
    assert np.abs(p0 - (v - d * ta)).max() < 1e-12
    assert np.abs(p5 - (v + d * tb)).max() < 1e-12
    assert np.abs(t0 - ta).max() < 1e-12 and np.abs(t1 - tb).max() < 1e-12
    # Stays in the corner's plane z = 1.5 exactly (plane_frame gives the XY axes).
    assert np.all(blend.ph.point_mm(np.linspace(0, 1, 11))[:, 2] == 1.5)
    # G2 with the lines: zero curvature at both ends.
    assert np.abs(_curvature(blend.ph.control_points_mm, np.array([0.0, 1.0]))).max() < 1e-9
    dev = _hausdorff(blend, a, b)
    assert 0.9 * tol <= dev <= tol
    assert 0.995 * tol <= dev <= tol  # the search's window
    assert abs(blend.deviation_mm - dev) < 1e-9 * tol
    # Closed form of the symmetric blend: deviation = d · f(θ).
    assert abs(d * line_deviation_per_trim(np.pi / 2) - dev) < 1e-9 * tol
    assert blend.ph.length_mm < 2 * d  # it cuts the corner
    assert abs(blend.turning_deg - 90.0) < 1e-12
    kappa = np.abs(_curvature(blend.ph.control_points_mm, np.linspace(0, 1, 20001)))
    assert abs(blend.kappa_max_per_mm - kappa.max()) < 1e-6 * kappa.max()
    assert blend.kappa_jump_per_mm < 1e-9


@settings(max_examples=25, deadline=None)
@given(
    turning_deg=st.floats(10.0, 170.0),
    tol=st.floats(1e-3, 0.1),
    rot_deg=st.floats(-180.0, 180.0),
    left=st.booleans(),
)
def test_line_corners_10_to_170_degrees(turning_deg, tol, rot_deg, left):
    turning = np.radians(turning_deg) * (1 if left else -1)
    rot = Rotation.from_euler("z", rot_deg, degrees=True).as_matrix()
    a, b, ta, tb = _corner_lines(turning, rot, length=100.0)
    blend = blend_corner(a, b, tol, 50.0, 50.0)
    d = blend.trim_a_mm
    p0, p5, t0, t1 = _ends(blend)
    assert np.abs(p0 - (-d * ta)).max() < 1e-12 and np.abs(p5 - d * tb).max() < 1e-12
    assert np.abs(t0 - ta).max() < 1e-12 and np.abs(t1 - tb).max() < 1e-12
    assert np.abs(_curvature(blend.ph.control_points_mm, np.array([0.0, 1.0]))).max() * d < 1e-9
    dev = _hausdorff(blend, a, b)
    assert 0.995 * tol <= dev <= tol * (1 + 1e-9)
    assert abs(blend.deviation_mm - dev) < 1e-9 * tol
    assert blend.ph.length_mm < 2 * d
    # The unmeasured fast path: the closed-form deviation is the true one.
    fast = blend_corner(a, b, tol, 50.0, 50.0, measure=False)
    assert abs(fast.deviation_mm - _hausdorff(fast, a, b)) < 1e-9 * tol
    assert 0.995 * tol <= fast.deviation_mm <= tol
    assert abs(blend.turning_deg - turning_deg) < 1e-9
    # No inflection: the curvature keeps one sign.
    k = _curvature(blend.ph.control_points_mm, np.linspace(0.01, 0.99, 99), np.array([0, 0, 1.0]))
    assert np.all(k > 0) or np.all(k < 0)


def test_trims_respect_the_max():
    tol = 0.05
    a, b, ta, tb = _corner_lines(np.pi / 2)
    free = blend_corner(a, b, tol, 5.0, 5.0)
    assert free.trim_a_mm > 0.1
    for max_a, max_b in ((0.1, 5.0), (5.0, 0.1), (0.1, 0.1)):
        blend = blend_corner(a, b, tol, max_a, max_b)
        assert blend.trim_a_mm == blend.trim_b_mm == 0.1
        dev = _hausdorff(blend, a, b)
        assert dev < tol
        assert abs(dev - 0.1 * line_deviation_per_trim(np.pi / 2)) < 1e-9
        p0, p5, _, _ = _ends(blend)
        assert np.abs(p0 + 0.1 * ta).max() < 1e-12 and np.abs(p5 - 0.1 * tb).max() < 1e-12
    # A short segment: never more than its length.
    short = LineGeometry((0, 0, 0), (0, 0.04, 0))
    blend = blend_corner(a, short, tol, 5.0, 5.0)
    assert blend.trim_b_mm == 0.04


@pytest.mark.parametrize("turning", [1e-5, np.radians(0.5)])
def test_near_collinear_polyline_corner(turning):
    # CAM polyline: 0.1 mm segments, nearly collinear. The blend takes half of each segment
    # and stays far inside the tolerance; its curvature is tiny (so the feed stays high).
    a, b, ta, tb = _corner_lines(turning, length=0.1, vertex=(250.0, -120.0, 5.0))
    blend = blend_corner(a, b, 0.01, 0.05, 0.05)
    assert blend.trim_a_mm == blend.trim_b_mm == 0.05
    dev = _hausdorff(blend, a, b)
    assert abs(dev - blend.deviation_mm) < 1e-12
    assert abs(dev - 0.05 * line_deviation_per_trim(turning)) < 1e-12
    # Peak curvature (at ξ = ½ by symmetry): 64 sin(θ/2) / (α²(1 + c)²), α² = 30cd/(6c + 1),
    # c = cos(θ/2); ≈ 3.73 × the mean curvature θ/L, the price of κ = 0 at both ends (G2).
    c = np.cos(turning / 2)
    k_peak = 64 * np.sin(turning / 2) / (30 * c * 0.05 / (6 * c + 1) * (1 + c) ** 2)
    k_dense = np.abs(_curvature(blend.ph.control_points_mm, np.linspace(0, 1, 4001))).max()
    assert abs(blend.kappa_max_per_mm - k_peak) < 1e-6 * k_peak
    assert abs(k_dense - k_peak) < 1e-6 * k_peak
    assert 3.7 < k_peak * blend.ph.length_mm / turning < 3.75


@pytest.mark.parametrize("plane", ["ZX", "YZ"])
def test_coordinate_planes(plane):
    # XY corner with its axes permuted into the ZX (z, x) or YZ (y, z) plane.
    perm = {"ZX": [2, 0, 1], "YZ": [1, 2, 0]}[plane]
    m = np.zeros((3, 3))
    m[perm, [0, 1, 2]] = 1.0
    a, b, ta, tb = _corner_lines(np.radians(60.0), m, vertex=(1.0, 2.0, 3.0))
    blend = blend_corner(a, b, 0.02, 5.0, 5.0)
    normal_axis = perm[2]
    pts = blend.ph.point_mm(np.linspace(0, 1, 101))
    assert np.all(pts[:, normal_axis] == [1.0, 2.0, 3.0][normal_axis])
    ref = blend_corner(*_corner_lines(np.radians(60.0))[:2], 0.02, 5.0, 5.0)
    assert abs(blend.trim_a_mm - ref.trim_a_mm) < 1e-12
    assert 0.995 * 0.02 <= _hausdorff(blend, a, b) <= 0.02


def test_tilted_plane_3d():
    rot = Rotation.from_rotvec([0.3, -0.7, 0.4]).as_matrix()
    v = np.array([10.0, -5.0, 2.0])
    a, b, ta, tb = _corner_lines(np.radians(75.0), rot, vertex=v)
    tol = 0.01
    blend = blend_corner(a, b, tol, 5.0, 5.0)
    d = blend.trim_a_mm
    p0, p5, t0, t1 = _ends(blend)
    assert np.abs(p0 - (v - d * ta)).max() < 1e-12 and np.abs(p5 - (v + d * tb)).max() < 1e-12
    assert np.abs(t0 - ta).max() < 1e-12 and np.abs(t1 - tb).max() < 1e-12
    normal = rot[:, 2]
    pts = blend.ph.point_mm(np.linspace(0, 1, 101))
    assert np.abs((pts - v) @ normal).max() < 1e-12
    dev = _hausdorff(blend, a, b)
    assert 0.995 * tol <= dev <= tol
    flat = blend_corner(*_corner_lines(np.radians(75.0))[:2], tol, 5.0, 5.0)
    assert abs(d - flat.trim_a_mm) < 1e-12 * d  # rotation invariance


# --- corners with arcs -----------------------------------------------------------------------


@pytest.mark.parametrize("radius, sense", [(10.0, 1), (10.0, -1), (2.0, 1), (0.5, 1)])
@pytest.mark.parametrize("turning_deg", [30.0, 90.0, 135.0])
def test_line_to_arc(radius, sense, turning_deg):
    th = np.radians(turning_deg)
    tb = np.array([np.cos(th), np.sin(th), 0.0])
    a = LineGeometry((-10, 0, 0), (0, 0, 0))
    b = _arc((0, 0, 0), tb, (0, 0, 1), radius, sense * 2.0)
    tol = 0.01
    blend = blend_corner(a, b, tol, 5.0, 0.5 * b.length_mm)
    d = blend.trim_b_mm
    assert blend.trim_a_mm == d <= 0.5 * b.length_mm
    # Closed-form circle: centre at −sense·r·(tb rotated by −90°); the point at arc length d.
    n_tb = np.array([-tb[1], tb[0], 0.0])  # tb rotated +90° about z
    center = sense * radius * n_tb
    e1 = -sense * n_tb
    psi = d / radius  # angle swept from the vertex
    p_arc = _circle_point(center, e1, tb, radius, psi)
    t_arc = -np.sin(psi) * e1 + np.cos(psi) * tb
    p0, p5, t0, t1 = _ends(blend)
    assert np.abs(p0 - np.array([-d, 0, 0])).max() < 1e-12
    assert np.abs(p5 - p_arc).max() < 1e-12
    assert np.abs(t0 - [1, 0, 0]).max() < 1e-12 and np.abs(t1 - t_arc).max() < 1e-12
    k = _curvature(blend.ph.control_points_mm, np.array([0.0, 1.0]), np.array([0, 0, 1.0]))
    assert abs(k[0]) < 1e-9 / d  # G2 with the line
    assert abs(k[1] - sense / radius) < 1e-9 / d  # G2 with the arc
    assert blend.kappa_jump_per_mm < 1e-9 / d
    dev = _hausdorff(blend, a, b)
    assert dev <= tol * (1 + 1e-9)
    assert dev >= 0.995 * tol
    assert abs(blend.deviation_mm - dev) < 1e-6 * tol
    assert blend.ph.length_mm < 2 * d


@pytest.mark.parametrize("sense", [1, -1])
def test_arc_to_line(sense):
    radius, tol = 3.0, 0.02
    # The arc ends at the origin heading along +x; the line then leaves at 100°.
    a_rev = _arc((0, 0, 0), (-1, 0, 0), (0, 0, 1), radius, -sense * 1.5)
    end = a_rev.point(a_rev.length_mm)[0]
    # The same circle traversed the other way, ending at the origin with tangent +x.
    a = _arc(end, -a_rev.derivatives([a_rev.length_mm], 1)[1][0], (0, 0, 1), radius, sense * 1.5)
    assert np.abs(a.point(a.length_mm)[0]).max() < 1e-12
    th = np.radians(100.0)
    b = LineGeometry((0, 0, 0), (10 * np.cos(th), 10 * np.sin(th), 0))
    blend = blend_corner(a, b, tol, 0.5 * a.length_mm, 5.0)
    d = blend.trim_a_mm
    p0, p5, t0, t1 = _ends(blend)
    # The point d before the end of a is the point d after the start of the reversed arc.
    assert np.abs(p0 - a_rev.point(d)[0]).max() < 1e-12
    assert np.abs(t0 + a_rev.derivatives([d], 1)[1][0]).max() < 1e-12
    assert np.abs(p5 - d * np.array([np.cos(th), np.sin(th), 0])).max() < 1e-12
    k = _curvature(blend.ph.control_points_mm, np.array([0.0, 1.0]), np.array([0, 0, 1.0]))
    assert abs(k[0] - sense / radius) < 1e-9 / d and abs(k[1]) < 1e-9 / d
    dev = _hausdorff(blend, a, b)
    assert 0.995 * tol <= dev <= tol * (1 + 1e-9)


def test_arc_to_arc():
    tol = 0.01
    a = _arc((-5, -5, 0), (1, 0, 0), (0, 0, 1), 5.0, np.pi / 2)  # ends at (0, 0) heading +y
    assert np.abs(a.point(a.length_mm)[0]).max() < 1e-12
    b = _arc((0, 0, 0), (1, 0, 0), (0, 0, 1), 4.0, -1.0)  # a 90° right corner
    blend = blend_corner(a, b, tol, 1.0, 1.0)
    k = _curvature(blend.ph.control_points_mm, np.array([0.0, 1.0]), np.array([0, 0, 1.0]))
    assert abs(k[0] - 1 / 5.0) < 1e-9 / blend.trim_a_mm
    assert abs(k[1] + 1 / 4.0) < 1e-9 / blend.trim_a_mm
    assert 0.995 * tol <= _hausdorff(blend, a, b) <= tol * (1 + 1e-9)


def test_tight_arc_falls_back_within_tolerance():
    # An arc much tighter than the blend: whatever continuity is reached, the tolerance holds
    # and the reported curvature jump is the measured one.
    th = np.radians(90.0)
    a = LineGeometry((-10, 0, 0), (0, 0, 0))
    b = _arc((0, 0, 0), (np.cos(th), np.sin(th), 0), (0, 0, 1), 0.1, -3.0)
    blend = blend_corner(a, b, 0.01, 5.0, 0.5 * b.length_mm)
    assert blend is not None
    assert _hausdorff(blend, a, b) <= 0.01 * (1 + 1e-9)
    k = _curvature(blend.ph.control_points_mm, np.array([0.0, 1.0]), np.array([0, 0, 1.0]))
    assert abs(max(abs(k[0]), abs(k[1] + 10.0)) - blend.kappa_jump_per_mm) < 1e-6


# --- no blend --------------------------------------------------------------------------------


def test_reversal_and_smooth_junctions_give_none():
    a = LineGeometry((0, 0, 0), (1, 0, 0))
    assert blend_corner(a, LineGeometry((1, 0, 0), (0.5, 0, 0)), 0.01, 0.5, 0.25) is None
    assert blend_corner(a, LineGeometry((1, 0, 0), (2, 0, 0)), 0.01, 0.5, 0.5) is None
    almost = LineGeometry((1, 0, 0), (2, 1e-8, 0))
    assert blend_corner(a, almost, 0.01, 0.5, 0.5) is None
    corner = LineGeometry((1, 0, 0), (1, 1, 0))
    assert blend_corner(a, corner, 0.0, 0.5, 0.5) is None  # zero tolerance: exact stop
    assert blend_corner(a, corner, 0.01, 0.0, 0.5) is None  # degenerate trim


def test_non_planar_corners_give_none():
    a = LineGeometry((0, 0, -1), (0, 0, 0))  # a Z plunge into an XY arc
    b = _arc((0, 0, 0), (1, 0, 0), (0, 0, 1), 2.0, 1.0)
    assert blend_corner(a, b, 0.01, 0.5, 0.5) is None
    helix = ArcGeometry(
        np.array([0.0, 2.0, 0.0]),
        np.array([0.0, -1.0, 0.0]),
        np.array([1.0, 0.0, 0.0]),
        np.array([0.0, 0.0, 1.0]),
        2.0,
        2.0,
        1.0,
        0.5,
    )
    line = LineGeometry((-1, 0, 0), (0, 0, 0))
    assert blend_corner(line, helix, 0.01, 0.5, 0.5) is None


def test_bad_inputs_raise():
    a = LineGeometry((0, 0, 0), (1, 0, 0))
    b = LineGeometry((1, 0, 0), (1, 1, 0))
    with pytest.raises(GeometryError):
        blend_corner(a, b, -0.01, 0.5, 0.5)
    with pytest.raises(GeometryError):
        blend_corner(a, b, float("nan"), 0.5, 0.5)
    with pytest.raises(GeometryError):
        blend_corner(a, LineGeometry((1, 0.1, 0), (1, 1, 0)), 0.01, 0.5, 0.5)


# --- many line–line corners at once (CAM polylines) ------------------------------------------


def _batch_ph(b, i: int) -> PHQuintic:
    return PHQuintic(b.w[i], b.p0[i], b.origin_mm[i], b.e1[i], b.e2[i])


class _B:  # what _hausdorff needs of a blend
    def __init__(self, ph, trim_a, trim_b):
        self.ph, self.trim_a_mm, self.trim_b_mm = ph, trim_a, trim_b


def _random_corners(rng, m: int, planar_every: int = 2):
    v = rng.normal(size=(m, 3)) * 10.0
    ta, tb = rng.normal(size=(m, 3)), rng.normal(size=(m, 3))
    ta[::planar_every, 2] = tb[::planar_every, 2] = 0.0  # every other corner in an XY plane
    ta /= np.linalg.norm(ta, axis=1)[:, None]
    tb /= np.linalg.norm(tb, axis=1)[:, None]
    return v, ta, tb


def test_batch_blends_equal_the_scalar_ones_on_equal_trims():
    """With equal maximum trims the batch gives blend_corner's blends (unmeasured path, the
    closed form the scalar search accepts at once): same trims, control points to 1e-12 mm,
    deviation d · f(θ), peak curvature to the scalar's sampled maximum."""
    rng = np.random.default_rng(7)
    m = 60
    v, ta, tb = _random_corners(rng, m)
    lengths = np.exp(rng.uniform(np.log(0.02), np.log(5.0), size=(m, 2)))
    tol = 10.0 ** rng.uniform(-4, -1, size=m)
    half = 0.5 * lengths.min(axis=1)
    b = line_corner_blends(v, ta, tb, tol, half)
    for i in range(m):
        ga = LineGeometry(v[i] - lengths[i, 0] * ta[i], v[i])
        gb = LineGeometry(v[i], v[i] + lengths[i, 1] * tb[i])
        ref = blend_corner(ga, gb, tol[i], half[i], half[i], measure=False)
        assert (ref is None) == (not b.ok[i])
        if ref is None:
            continue
        assert b.trim_a_mm[i] == b.trim_b_mm[i]
        assert b.trim_a_mm[i] == pytest.approx(ref.trim_a_mm, rel=1e-12)
        cp = _batch_ph(b, i).control_points_mm
        assert np.abs(cp - ref.ph.control_points_mm).max() < 1e-12 * np.abs(v[i]).max()
        assert b.deviation_mm[i] == pytest.approx(ref.deviation_mm, rel=1e-12)
        assert b.kappa_max_per_mm[i] == pytest.approx(ref.kappa_max_per_mm, rel=1e-6)
        assert b.turning_rad[i] == pytest.approx(np.radians(ref.turning_deg), rel=1e-12)


def test_batch_peak_curvature_is_at_the_midpoint_in_closed_form():
    """κ_max = 64 sin(θ/2) / (α² (1 + cos θ/2)²) at ξ = ½, against the curvature of the
    Bézier control points sampled densely (an independent evaluation)."""
    turning = np.radians([1.0, 10.0, 45.0, 90.0, 135.0, 170.0])
    m = turning.size
    ta = np.tile([1.0, 0.0, 0.0], (m, 1))
    tb = np.column_stack([np.cos(turning), np.sin(turning), np.zeros(m)])
    b = line_corner_blends(np.zeros((m, 3)), ta, tb, np.full(m, 0.05), np.full(m, 1.0))
    xi = np.linspace(0.0, 1.0, 200_001)
    for i in range(m):
        k = np.abs(_curvature(_batch_ph(b, i).control_points_mm, xi))
        assert int(np.argmax(k)) == 100_000
        assert b.kappa_max_per_mm[i] == pytest.approx(k.max(), rel=1e-12)


def test_batch_unequal_trims_stay_within_the_tolerance():
    """A short line next to a long one: each side trimmed up to half its own line, no sliver
    left. The blend starts and ends on the lines, tangent to them with zero curvature (G2),
    its dense Hausdorff distance to the corner path is at most the reported deviation, which
    is at most the tolerance, and its peak curvature is the dense maximum."""
    rng = np.random.default_rng(11)
    m = 40
    v, ta, tb = _random_corners(rng, m)
    la = np.exp(rng.uniform(np.log(0.005), np.log(0.5), m))
    lb = np.exp(rng.uniform(np.log(0.5), np.log(5.0), m))
    tol = 10.0 ** rng.uniform(-3, -1, size=m)
    b = line_corner_blends(v, ta, tb, tol, 0.5 * la, 0.5 * lb)
    xi = np.linspace(0.0, 1.0, 100_001)
    unequal = 0
    for i in np.flatnonzero(b.ok):
        ph = _batch_ph(b, i)
        da, db = b.trim_a_mm[i], b.trim_b_mm[i]
        assert da <= 0.5 * la[i] and db <= 0.5 * lb[i]
        unequal += da != db
        cp = ph.control_points_mm
        assert np.abs(cp[0] - (v[i] - da * ta[i])).max() < 1e-12 * max(1, np.abs(v[i]).max())
        assert np.abs(cp[-1] - (v[i] + db * tb[i])).max() < 1e-12 * max(1, np.abs(v[i]).max())
        d0, d1 = _bezier(cp, [0.0], 1)[0], _bezier(cp, [1.0], 1)[0]
        # Control-point differences lose digits: ~ulp(|v|) over |p1 − p0| = |d0|/5.
        tol_t = 50 * np.finfo(float).eps * max(1.0, np.abs(v[i]).max())
        assert np.abs(d0 / np.linalg.norm(d0) - ta[i]).max() < tol_t / np.linalg.norm(d0)
        assert np.abs(d1 / np.linalg.norm(d1) - tb[i]).max() < tol_t / np.linalg.norm(d1)
        k = np.abs(_curvature(cp, xi))
        assert max(k[0], k[-1]) < 1e-9 * k.max()
        assert b.kappa_max_per_mm[i] == pytest.approx(k.max(), rel=1e-7)
        ga = LineGeometry(v[i] - la[i] * ta[i], v[i])
        gb = LineGeometry(v[i], v[i] + lb[i] * tb[i])
        h = _hausdorff(_B(ph, da, db), ga, gb)
        assert h <= b.deviation_mm[i] * (1 + 1e-9) <= tol[i] * (1 + 1e-9)
    assert unequal > m // 2


def test_batch_unequal_trims_fall_back_to_equal_ones_beyond_the_tolerance():
    """θ = 0.3 rad, a line 0.1 × the tolerance trim long before a long one: the unequal blend
    would leave the tolerance (its bound), so both sides get the short side's trim."""
    th, tol = 0.3, 0.2
    d_line = tol * (1 - 0.0025) / line_deviation_per_trim(th)
    b = line_corner_blends(
        np.zeros((1, 3)),
        [[1.0, 0.0, 0.0]],
        [[np.cos(th), np.sin(th), 0]],
        [tol],
        [0.1 * d_line],
        [10 * d_line],
    )
    assert b.ok[0] and b.trim_a_mm[0] == b.trim_b_mm[0] == 0.1 * d_line
    assert b.deviation_mm[0] == pytest.approx(0.1 * tol * (1 - 0.0025), rel=1e-12)


def test_batch_rejects_what_the_scalar_rejects():
    """Smooth (< 1e-6 rad) and reversed junctions, zero tolerance, degenerate trims."""
    ta = np.tile([1.0, 0.0, 0.0], (5, 1))
    tb = np.array(
        [
            [1.0, 0, 0],
            [np.cos(5e-7), np.sin(5e-7), 0],
            [-1.0, 1e-9, 0],
            [0.0, 1.0, 0],
            [0.0, 1.0, 0],
        ]
    )
    b = line_corner_blends(
        np.zeros((5, 3)), ta, tb, [0.01, 0.01, 0.01, 0.0, 0.01], [0.5, 0.5, 0.5, 0.5, 1e-10]
    )
    assert not b.ok.any()


def test_batch_frames_keep_coordinate_planes_exact():
    """Corners in the XY, ZX and YZ planes at an offset keep that coordinate exactly."""
    vertex = np.array([[1.25, -3.5, 7.75]] * 3)
    ta = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, 1.0, 0]])
    tb = np.array([[0.6, 0.8, 0], [0.8, 0, 0.6], [0, 0.6, 0.8]])
    b = line_corner_blends(vertex, ta, tb, np.full(3, 0.05), np.full(3, 0.5))
    for i, axis in enumerate((2, 1, 0)):
        pts = _batch_ph(b, i).point_mm(np.linspace(0, 1, 101))
        assert np.all(pts[:, axis] == vertex[i, axis])


def test_ph_tables_match_the_ph_quintic():
    rng = np.random.default_rng(3)
    w = rng.normal(size=(50, 3)) + 1j * rng.normal(size=(50, 3))
    p0 = rng.normal(size=50) + 1j * rng.normal(size=50)
    pts, sigma, s, length = ph_tables(w, p0)
    for i in range(50):
        ph = PHQuintic(w[i], p0[i])
        np.testing.assert_allclose(pts[i], ph.control_points, rtol=1e-15, atol=1e-15)
        np.testing.assert_allclose(sigma[i], ph.sigma_coeffs, rtol=1e-15, atol=1e-15)
        np.testing.assert_allclose(s[i], ph.s_coeffs, rtol=1e-15, atol=1e-15)
        assert length[i] == pytest.approx(ph.length_mm, rel=1e-15)


# --- corners out of one plane (issue 13) ----------------------------------------------------


def _helix_into_line():
    """A G2 helix (R 7 mm, a quarter turn, Z −3 mm) into a line that leaves its corner
    plane: from the interpreter, as the planner sees them."""
    from nurbscnc.geometry.paths import geometry_of
    from nurbscnc.program.interpret import interpret_text

    prog = interpret_text(
        "G21 G90 G17\nG0 X2 Y-1 Z16\nG2 I0 J7 X9 Y6 Z13 F3000\nG1 X15 Y6 Z10\nM2\n"
    )
    arc, line = (s for s in prog.segments if s.kind in ("arc", "line"))
    return geometry_of(arc), LineGeometry(np.asarray(line.start_mm), np.asarray(line.end_mm))


def _helix_points(c_xy, r, phi0, dphi, z0, dz, n):
    """Closed-form helix points: centre c_xy, radius r, from angle phi0 through dphi."""
    f = np.linspace(0.0, 1.0, n)
    phi = phi0 + f * dphi
    return np.column_stack([c_xy[0] + r * np.cos(phi), c_xy[1] + r * np.sin(phi), z0 + f * dz])


@pytest.mark.parametrize("tol", [0.005, 0.02, 0.1])
def test_space_blend_of_a_helix_into_a_line(tol):
    from nurbscnc.geometry.blend import SEARCH_WINDOW, blend_space_corner

    helix, line = _helix_into_line()
    # The planar PH blend cannot meet a helix: no planar blend exists.
    assert blend_corner(helix, line, tol, 1.0, 1.0) is None
    bl = blend_space_corner(helix, line, tol, 1.0, 1.0)
    assert bl is not None and bl.trim_a_mm == bl.trim_b_mm
    d = bl.trim_a_mm
    # Closed forms of both sides: the helix about (2, 6), R 7, clockwise from −90° through
    # 270° to 0° (Z 16 → 13: pitch c = −3/(3π/2) per radian, arc length √(r² + c²)·3π/2),
    # the line from (9, 6, 13) to (15, 6, 10).
    r, sweep, dz = 7.0, 1.5 * np.pi, -3.0
    c = dz / sweep
    phi_cut = d / np.hypot(r, c)  # the angle of the helix's cut point above 0°
    side_a = _helix_points((2.0, 6.0), r, phi_cut, -phi_cut, 13.0 - c * phi_cut, c * phi_cut, 4001)
    line_dir = np.array([6.0, 0.0, -3.0]) / np.sqrt(45.0)
    np.testing.assert_allclose(side_a[-1], [9.0, 6.0, 13.0], atol=1e-12)
    side_b = np.array([9.0, 6.0, 13.0]) + np.linspace(0.0, d, 4001)[:, None] * line_dir
    corner = np.vstack([side_a, side_b[1:]])
    xi = np.linspace(0.0, 1.0, 20001)
    ctrl = np.asarray(bl.curve.control_points_mm)
    blend = _bezier(ctrl, xi)
    # Ends: the cut points of the closed forms; G1 and G2 there (tangent and curvature
    # vector of the helix, R_xy = 7 with pitch: κ = r/(r² + c²), and the line's zero).
    np.testing.assert_allclose(blend[0], side_a[0], atol=1e-9)
    np.testing.assert_allclose(blend[-1], side_b[-1], atol=1e-9)
    d1, d2 = _bezier(ctrl, np.array([0.0, 1.0]), 1), _bezier(ctrl, np.array([0.0, 1.0]), 2)
    kappa_helix = r / (r * r + c * c)
    k0 = np.linalg.norm(np.cross(d1[0], d2[0])) / np.linalg.norm(d1[0]) ** 3
    k1 = np.linalg.norm(np.cross(d1[1], d2[1])) / np.linalg.norm(d1[1]) ** 3
    assert k0 == pytest.approx(kappa_helix, rel=1e-9)
    assert k1 == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(d1[1] / np.linalg.norm(d1[1]), line_dir, atol=1e-12)
    # Within the tolerance, using most of it (Hausdorff both ways, dense closed forms).
    dev = max(_to_polyline(blend, corner).max(), _to_polyline(corner, blend).max())
    assert dev <= tol * (1 + 1e-6)
    assert dev >= tol * (1.0 - SEARCH_WINDOW) * 0.99
    assert bl.deviation_mm == pytest.approx(dev, rel=1e-3)


@settings(max_examples=25, deadline=None)
@given(
    st.floats(2.0, 30.0),
    st.floats(-6.0, 6.0),
    st.floats(0.3, 2.5),
    st.floats(-3.0, 3.0),
    st.floats(-3.0, 3.0),
    st.sampled_from([0.002, 0.01, 0.05]),
)
def test_space_blends_use_the_tolerance_window(radius, rise, sweep, dx, dz, tol):
    """Random G2 helices (radius, rise, sweep) into a line leaving their plane, whatever the
    turn: the space blend's search (secant steps, then bisection) ends with its deviation in
    [(1 − SEARCH_WINDOW) tol, tol] measured independently (the helix and the line at 4,001
    points of their own, the Bézier at 20,001, Hausdorff both ways), unless the trim reached
    its cap (the sides' lengths, the 1 mm given)."""
    from nurbscnc.geometry.blend import SEARCH_WINDOW, blend_space_corner
    from nurbscnc.geometry.paths import geometry_of
    from nurbscnc.program.interpret import interpret_text

    end = np.array([radius * np.sin(sweep), radius * np.cos(sweep), rise])
    text = (
        f"G21 G90 G17\nG0 X0 Y{radius:.6f} Z0\nG2 I0 J{-radius:.6f} X{end[0]:.6f} "
        f"Y{end[1]:.6f} Z{end[2]:.6f} F3000\nG1 X{end[0] + 5 + dx:.6f} "
        f"Y{end[1] + dx:.6f} Z{end[2] + dz:.6f}\nM2\n"
    )
    arc, line = (s for s in interpret_text(text).segments if s.kind in ("arc", "line"))
    helix = geometry_of(arc)
    seg = LineGeometry(np.asarray(line.start_mm), np.asarray(line.end_mm))
    bl = blend_space_corner(helix, seg, tol, 1.0, 1.0)
    assume(bl is not None)
    d = bl.trim_a_mm
    u = np.linspace(helix.length_mm - d, helix.length_mm, 4001)
    side_a = helix.point(helix.param_at_length(u))
    side_b = seg.point(seg.param_at_length(np.linspace(0.0, d, 4001)))
    corner = np.vstack([side_a, side_b[1:]])
    blend = _bezier(np.asarray(bl.curve.control_points_mm), np.linspace(0.0, 1.0, 20001))
    dev = max(_to_polyline(blend, corner).max(), _to_polyline(corner, blend).max())
    assert dev <= tol * (1 + 1e-6)
    capped = d >= min(1.0, helix.length_mm, seg.length_mm) * (1 - 1e-9)
    assert capped or dev >= tol * (1.0 - SEARCH_WINDOW) * 0.999


def test_planner_blends_3d_turns_within_p():
    """Under G64 P0.02 the helix → line turn (a space blend, a NURBS piece) and the 3-D
    line → line turn (a PH blend in the plane of the two lines) are blended, not stopped: the
    samples of the line–line blend lie in that plane, every sample within P of the path."""
    from nurbscnc.machine.profile import load_machine
    from nurbscnc.pipeline import RunOptions, run_program
    from nurbscnc.plan.corners import CornerAction
    from nurbscnc.plan.options import LookaheadOptions
    from nurbscnc.program.interpret import interpret_text
    from tests.test_wholeprograms import distance_to_path, programmed_path

    # F300: slow enough that the helix blend, capped for the servo (servo_blend_cap_mm_s),
    # beats a stop; at F3000 the corner stops (stop_faster).
    text = (
        "G21 G90 G17 G64 P0.02\nG0 X2 Y-1 Z16\nF300\nG2 I0 J7 X9 Y6 Z13\n"
        "G1 X15 Y6 Z10\nG1 X20 Y10 Z10\nM2\n"
    )
    prog = interpret_text(text)
    r = run_program(prog, load_machine(), RunOptions(lookahead=LookaheadOptions(dynamics="off")))
    log = r.plan.pieces.corners
    feed = log.line > 2
    assert np.all(log.action[feed] == CornerAction.BLEND) and feed.sum() == 2
    pieces = r.plan.pieces
    assert pieces.kind_counts() == {"line": 2, "rapid": 1, "arc": 1, "ph": 1, "nurbs": 1}
    pts = r.samples.points_mm
    ph = np.flatnonzero(np.asarray(pieces.kind) == 3)[0]
    on_ph = pts[r.samples.piece == ph]
    assert on_ph.shape[0] >= 3
    normal = np.cross([6.0, 0.0, -3.0], [5.0, 4.0, 0.0])
    normal /= np.linalg.norm(normal)
    assert np.abs((on_ph - [15.0, 6.0, 10.0]) @ normal).max() <= 1e-9
    assert distance_to_path(pts, programmed_path(prog), reach=1.0).max() <= 0.02 + 1e-6


def test_servo_blend_cap_is_the_steady_circle_error_bound():
    # SPEC §8: on a circle the paper's servo path grows by 2.85e-5 s² · v²κ; a space blend's
    # cap keeps that within ε_max/2: v = √(7.5e-3 mm / (2.85e-5 s² · κ)).
    from nurbscnc.machine.profile import load_machine
    from nurbscnc.plan.blends import servo_blend_cap_mm_s

    m = load_machine()
    for kappa in (0.5, 22.0, 300.0):
        expect = np.sqrt(0.5 * m.limits.contour_tolerance_mm / (2.85e-5 * kappa))
        assert servo_blend_cap_mm_s(m, kappa) == pytest.approx(expect, rel=5e-3)
