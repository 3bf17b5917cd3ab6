"""Lines and arcs through the PathGeometry interface, against closed forms."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad

from nurbscnc.errors import GeometryError
from nurbscnc.geometry import segments
from nurbscnc.geometry.nurbs import NurbsCurve
from nurbscnc.geometry.paths import ArcGeometry, LineGeometry, PathGeometry, geometry_of


def make_arc(
    center,
    start,
    normal,
    angle_rad,
    helix_mm=0.0,
    radius_end_mm=None,
    plane="XY",
) -> segments.Arc:
    """An Arc segment built the way the Arc docstring defines it (end point by closed form)."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    c, p0 = np.asarray(center, float), np.asarray(start, float)
    d = p0 - c
    d_in = d - (d @ n) * n
    r0 = float(np.linalg.norm(d_in))
    r1 = r0 if radius_end_mm is None else radius_end_mm
    e1 = d_in / r0
    e2 = np.cross(n, e1)
    end = c + (d @ n) * n + r1 * (np.cos(angle_rad) * e1 + np.sin(angle_rad) * e2)
    end = end + helix_mm * n
    return segments.Arc(
        start_mm=segments.vec3(p0),
        end_mm=segments.vec3(end),
        center_mm=segments.vec3(c),
        normal=segments.vec3(n),
        angle_rad=angle_rad,
        helix_mm=helix_mm,
        radius_start_mm=r0,
        radius_end_mm=r1,
        feed_mm_s=20.0,
        line=1,
        plane=plane,
    )


def central_differences(geom, u: np.ndarray, order: int, h: float) -> np.ndarray:
    """d^order C/du^order by central differences of the next lower derivative."""
    lower = order - 1
    return (geom.derivatives(u + h, lower)[lower] - geom.derivatives(u - h, lower)[lower]) / (2 * h)


# ----------------------------------------------------------------------------------- lines


def test_line_closed_forms():
    line = LineGeometry([1.0, 2.0, 3.0], [4.0, 6.0, 3.0])
    assert line.length_mm == 5.0 and line.u_start == 0.0 and line.u_end == 5.0
    u = np.array([0.0, 1.0, 2.5, 5.0])
    d = line.derivatives(u, 3)
    assert d.shape == (4, 4, 3)
    np.testing.assert_array_equal(d[0][[0, -1]], [[1, 2, 3], [4, 6, 3]])
    np.testing.assert_allclose(d[0][2], [2.5, 4.0, 3.0], rtol=1e-15)
    np.testing.assert_array_equal(d[1], np.tile([0.6, 0.8, 0.0], (4, 1)))
    np.testing.assert_array_equal(d[2:], 0.0)
    np.testing.assert_array_equal(line.arc_length(u), u)
    np.testing.assert_array_equal(line.param_at_length([0.0, 3.3, 9.0]), [0.0, 3.3, 5.0])
    np.testing.assert_array_equal(line.curvature(u), 0.0)
    np.testing.assert_array_equal(line.point(2.0), d[0][[1]] * 0 + [[2.2, 3.6, 3.0]])


def test_zero_length_line_is_finite():
    line = LineGeometry([1.0, 1.0, 1.0], [1.0, 1.0, 1.0])
    d = line.derivatives([0.0, 1.0], 3)
    assert line.length_mm == 0.0 and np.all(np.isfinite(d))
    np.testing.assert_array_equal(d[0], [[1, 1, 1], [1, 1, 1]])
    assert np.all(line.curvature([0.0]) == 0.0)


# ------------------------------------------------------------------------------------ arcs


def test_circle_arc_closed_forms():
    r = 12.5
    seg = make_arc([10.0, -3.0, 2.0], [10.0 + r, -3.0, 2.0], (0, 0, 1), 2.0)
    arc = ArcGeometry.from_segment(seg)
    assert arc.length_mm == pytest.approx(2.0 * r, rel=1e-15)
    assert arc.length_mm == pytest.approx(seg.length_mm, rel=1e-15)
    u = np.linspace(0.0, arc.u_end, 57)
    pts = arc.point(u)
    np.testing.assert_allclose(np.linalg.norm(pts - seg.center_mm, axis=1), r, rtol=1e-15)
    np.testing.assert_allclose(pts[[0, -1]], [seg.start_mm, seg.end_mm], rtol=0, atol=1e-12)
    np.testing.assert_allclose(arc.curvature(u), 1.0 / r, rtol=1e-12)
    np.testing.assert_allclose(arc.curvature_derivative(u), 0.0, atol=1e-14)
    # Unit speed: u is arc length, so the map and its inverse are the identity.
    np.testing.assert_allclose(np.linalg.norm(arc.derivatives(u, 1)[1], axis=1), 1.0, rtol=1e-15)
    np.testing.assert_array_equal(arc.arc_length(u), u)
    np.testing.assert_array_equal(arc.param_at_length(u), u)
    # Angle travelled is u/r: the point at u = r π/2 is a quarter turn from the start.
    q = arc.point(r * np.pi / 2)[0]
    np.testing.assert_allclose(q, [10.0, -3.0 + r, 2.0], rtol=0, atol=1e-12)


@pytest.mark.parametrize("turns", [0.3, 1.0, 2.75])
def test_helix_closed_forms(turns):
    r, pitch_mm = 4.0, 3.0
    angle = -2 * np.pi * turns  # G2
    rise = pitch_mm * turns
    seg = make_arc([0, 0, 0], [0, 0, r], (1, 0, 0), angle, helix_mm=rise, plane="YZ")
    arc = ArcGeometry.from_segment(seg)
    c = rise / angle  # pitch/(2π) with the sign of the turn
    assert arc.length_mm == pytest.approx(np.hypot(r * angle, rise), rel=1e-15)
    u = np.linspace(0.0, arc.length_mm, 41)
    np.testing.assert_allclose(arc.curvature(u), r / (r**2 + c**2), rtol=1e-12)
    np.testing.assert_allclose(
        arc.point([0.0, arc.u_end]), [seg.start_mm, seg.end_mm], rtol=0, atol=1e-12
    )
    np.testing.assert_allclose(arc.point(u)[:, 0], rise * u / arc.length_mm, atol=1e-12)
    d = arc.derivatives(u[1:-1], 3)
    for order in (1, 2, 3):
        fd = central_differences(arc, u[1:-1], order, 1e-5)
        np.testing.assert_allclose(d[order], fd, rtol=0, atol=1e-8 * np.abs(d[order]).max())


@pytest.mark.parametrize(
    "plane,first,second",
    [("XY", 0, 1), ("ZX", 2, 0), ("YZ", 1, 2)],
)
def test_g2_g3_orientation_in_each_plane(plane, first, second):
    assert segments.PLANE_AXES[plane] == (first, second)
    normal = segments.PLANE_NORMALS[plane]
    start = np.zeros(3)
    start[first] = 2.0
    for angle, sign in ((np.pi / 2, 1.0), (-np.pi / 2, -1.0)):  # G3, G2 quarter turns
        arc = ArcGeometry.from_segment(make_arc(np.zeros(3), start, normal, angle, plane=plane))
        expected = np.zeros(3)
        expected[second] = 2.0 * sign  # G3: first axis -> second axis (counter-clockwise)
        np.testing.assert_allclose(arc.point(arc.u_end)[0], expected, rtol=0, atol=1e-15)
        mid = arc.point(0.5 * arc.u_end)[0]
        np.testing.assert_allclose(mid[[first, second]], np.sqrt(2) * np.array([1, sign]))
        # The signed turn about the plane normal has the sign of the angle.
        d = arc.derivatives(0.0, 1)
        turn = np.cross(d[0][0], d[1][0]) @ np.asarray(normal)
        assert np.sign(turn) == sign


def test_arc_center_off_the_start_plane():
    # The centre lies 5 mm below the start's plane: geometry uses the in-plane radius 3 and
    # keeps the start's height; the helical rise is then added along the normal.
    seg = make_arc([0.0, 0.0, -5.0], [3.0, 0.0, 0.0], (0, 0, 1), np.pi, helix_mm=1.0)
    arc = ArcGeometry.from_segment(seg)
    np.testing.assert_allclose(arc.point(0.0)[0], [3.0, 0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(arc.point(arc.u_end)[0], [-3.0, 0.0, 1.0], atol=1e-14)


def test_spiral_arc_length_and_inverse():
    r0, r1, angle, rise = 5.0, 5.2, 1.5 * np.pi, 0.7
    seg = make_arc([1, 2, 3], [6, 2, 3], (0, 0, 1), angle, helix_mm=rise, radius_end_mm=r1)
    arc = ArcGeometry.from_segment(seg)

    def speed_t(t):  # |d/dt (r(t) (cos, sin)(Δθ t), H t)| with r' = r1 − r0
        return np.sqrt(((r0 + t * (r1 - r0)) * angle) ** 2 + (r1 - r0) ** 2 + rise**2)

    ref = quad(speed_t, 0.0, 1.0, epsabs=0, epsrel=1e-13)[0]
    assert arc.length_mm == pytest.approx(ref, rel=1e-13)
    assert arc.u_end == arc.length_mm
    np.testing.assert_allclose(
        arc.point([0.0, arc.u_end]), [seg.start_mm, seg.end_mm], rtol=0, atol=1e-12
    )
    s = np.linspace(0.0, arc.length_mm, 33)
    np.testing.assert_allclose(arc.arc_length(arc.param_at_length(s)), s, rtol=0, atol=1e-12)
    t = np.array([0.2, 0.6])
    partial = [quad(speed_t, 0.0, x, epsabs=0, epsrel=1e-13)[0] for x in t]
    np.testing.assert_allclose(arc.arc_length(t * arc.length_mm), partial, rtol=1e-13)
    u = np.linspace(0.1, 0.9, 9) * arc.length_mm
    d = arc.derivatives(u, 3)
    for order in (1, 2, 3):
        fd = central_differences(arc, u, order, 1e-5)
        np.testing.assert_allclose(d[order], fd, rtol=0, atol=1e-8 * np.abs(d[order]).max())
    # Curvature of a plane spiral with a small rise stays near 1/r.
    kappa = arc.curvature([0.0, arc.u_end])
    assert 0.95 / r0 < kappa[0] < 1.0 / r0 and 0.95 / r1 < kappa[1] < 1.0 / r1
    h = 1e-4
    fd = (arc.curvature(u + h) - arc.curvature(u - h)) / (2 * h)
    np.testing.assert_allclose(arc.curvature_derivative(u), fd, rtol=1e-6)


def test_degenerate_arc_is_rejected():
    seg = make_arc([0, 0, 0], [1, 0, 0], (0, 0, 1), 1.0)
    bad = segments.Arc(
        seg.start_mm, seg.end_mm, seg.start_mm, seg.normal, 1.0, 0.0, 0.0, 0.0, 1.0, 9
    )
    with pytest.raises(GeometryError):
        ArcGeometry.from_segment(bad)


# ---------------------------------------------------------------------------------- factory


def test_geometry_of_each_segment_kind():
    line = segments.Line(segments.vec3([0, 0, 0]), segments.vec3([1, 0, 0]), 5.0, 1)
    arc = make_arc([0, 0, 0], [1, 0, 0], (0, 0, 1), 1.0)
    nurbs = segments.Nurbs(
        degree=1,
        knots=segments.frozen_array([0, 0, 1, 1]),
        control_points_mm=segments.frozen_array([[0, 0, 0], [3, 4, 0]]),
        weights=segments.frozen_array([1, 1]),
        feed_mm_s=5.0,
        line=2,
    )
    geoms = [geometry_of(s) for s in (line, arc, nurbs)]
    assert [type(g) for g in geoms] == [LineGeometry, ArcGeometry, NurbsCurve]
    assert all(isinstance(g, PathGeometry) for g in geoms)
    assert geoms[2].length_mm == pytest.approx(5.0, rel=1e-15)
    for g in geoms:
        d = g.derivatives(np.array([g.u_start, g.u_end]), 3)
        assert d.shape == (4, 2, 3)
        np.testing.assert_allclose(g.arc_length([g.u_start, g.u_end]), [0.0, g.length_mm])
    with pytest.raises(TypeError):
        geometry_of(segments.Dwell(1.0, segments.vec3([0, 0, 0]), 3))


def _quad_length(r0, r1, angle, rise, t):
    """Reference: scipy's adaptive quadrature of the speed √((r(t) Δθ)² + Δr² + H²)."""
    dr = r1 - r0
    return quad(
        lambda x: np.sqrt(((r0 + x * dr) * angle) ** 2 + dr * dr + rise * rise),
        0.0,
        t,
        epsabs=0,
        epsrel=5e-14,
        limit=200,
    )[0]


@pytest.mark.parametrize("seed", range(4))
def test_spiral_closed_form_against_quadrature(seed):
    """segments.spiral_arc_length_mm (closed form) equals scipy.integrate.quad to 1e-12
    relative on random circles, helices and spirals: LinuxCNC-sized radius changes (1e-6 mm
    and 1e-12 mm, where a naive (F(w1) − F(w0))/(Δθ Δr) loses every digit), large ones,
    several turns, both directions, partial fractions t."""
    rng = np.random.default_rng(seed)
    for _ in range(250):
        r0 = rng.uniform(0.01, 50.0)
        dr = rng.choice([rng.uniform(-0.9 * r0, 5.0), rng.uniform(-1e-6, 1e-6), 1e-12, 0.0])
        angle = rng.choice([-1.0, 1.0]) * rng.uniform(1e-4, 20.0)
        rise = rng.choice([0.0, rng.uniform(-20.0, 20.0)])
        t = rng.choice([1.0, rng.uniform(0.0, 1.0)])
        got = float(segments.spiral_arc_length_mm(r0, r0 + dr, angle, rise, t))
        assert got == pytest.approx(_quad_length(r0, r0 + dr, angle, rise, t), rel=1e-12)


def test_helix_and_degenerate_closed_forms():
    # helix: √((r θ)² + h²) exactly; no turn: the straight rise √(Δr² + H²)
    assert segments.spiral_arc_length_mm(3.0, 3.0, 2.5, 4.0) == np.hypot(7.5, 4.0)
    assert segments.spiral_arc_length_mm(1.0, 2.0, 0.0, 3.0) == pytest.approx(
        np.sqrt(10.0), rel=1e-15
    )
    assert segments.spiral_arc_length_mm(1.0, 1.5, 2.0, 0.0, 0.0) == 0.0


def test_spiral_inverse_to_1e12_mm():
    """param_at_length inverts the closed form to 1e-12 mm on a LinuxCNC-sized spiral (radius
    change 1e-6 mm over three turns) and a large one."""
    for r1, angle in ((5.000001, 6 * np.pi), (9.0, -3.0)):
        seg = make_arc([1, 2, 3], [6, 2, 3], (0, 0, 1), angle, helix_mm=2.0, radius_end_mm=r1)
        arc = ArcGeometry.from_segment(seg)
        s = np.linspace(0.0, arc.length_mm, 101)
        np.testing.assert_allclose(arc.arc_length(arc.param_at_length(s)), s, rtol=0, atol=1e-12)
        assert arc.length_mm == pytest.approx(_quad_length(5.0, r1, angle, 2.0, 1.0), rel=1e-12)


def test_segment_arc_length_is_exact_for_spirals():
    seg = make_arc([0, 0, 0], [5, 0, 0], (0, 0, 1), 4.0, helix_mm=1.0, radius_end_mm=7.0)
    assert seg.length_mm == pytest.approx(_quad_length(5.0, 7.0, 4.0, 1.0, 1.0), rel=1e-13)


def _spiral_t_reference(r0, r1, ang, hel, s_in, big, max_iter=50):
    """The spiral Newton as it was before its constants were hoisted (issue 14): the whole
    closed form every step on a shrinking active set."""
    s = np.clip(s_in, 0.0, big)
    t = np.where(big > 0.0, s / np.where(big > 0.0, big, 1.0), 0.0)
    dr, eps = r1 - r0, np.finfo(float).eps
    a2 = dr * dr + hel * hel
    tol = np.maximum(1e-12, 8.0 * eps * s)
    active = np.flatnonzero((s > 0.0) & (s < big))
    for _ in range(max_iter):
        if not active.size:
            break
        ta = t[active]
        f = (
            segments.spiral_arc_length_mm(r0[active], r1[active], ang[active], hel[active], ta)
            - s[active]
        )
        w = ang[active] * (r0[active] + ta * dr[active])
        new_t = np.clip(ta - f / np.sqrt(a2[active] + w * w), 0.0, 1.0)
        done = (np.abs(f) <= tol[active]) | (np.abs(new_t - ta) <= 2.0 * eps)
        t[active] = np.where(np.abs(f) <= tol[active], ta, new_t)
        active = active[~done]
    return t


def _random_spirals(rng, n):
    """``n`` spiral arcs (start and end radius [mm], swept angle [rad], helix rise [mm]) and
    their lengths [mm]: circles, near-circles, growing and shrinking spirals, helices, and
    every 50th of zero angle (a straight helix or a point)."""
    r0 = rng.uniform(0.5, 50.0, n)
    r1 = r0 + rng.choice([0.0, 1e-6, 1e-3, 0.5, -0.3, 5.0], n) * rng.uniform(0.0, 1.0, n)
    ang = rng.uniform(-12.0, 12.0, n)
    ang[::50] = 0.0
    hel = rng.choice([0.0, 0.0, 2.0, -7.0], n)
    return r0, r1, ang, hel, segments.spiral_arc_length_mm(r0, r1, ang, hel)


def test_spiral_newton_gives_the_bits_of_the_reference_and_inverts_the_length():
    rng = np.random.default_rng(5)
    n = 20000
    r0, r1, ang, hel, big = _random_spirals(rng, n)
    s = rng.uniform(0.0, 1.0, n) * big
    s[::7], s[::9] = 0.0, big[::9]
    t = segments.spiral_t_at_length(r0, r1, ang, hel, s, big)
    np.testing.assert_array_equal(t, _spiral_t_reference(r0, r1, ang, hel, s, big))
    # Few samples of one arc at a time (the blends' calls): the same bits.
    for k in range(0, 60, 3):
        sk = s[k] * np.linspace(0.0, 1.0, 9)
        np.testing.assert_array_equal(
            segments.spiral_t_at_length(r0[k], r1[k], ang[k], hel[k], sk, big[k]),
            _spiral_t_reference(*np.broadcast_arrays(r0[k], r1[k], ang[k], hel[k], sk, big[k])),
        )
    # One sample of one arc (the corner searches' calls, a scalar path): the same bits.
    for k in range(n):
        args = (float(r0[k]), float(r1[k]), float(ang[k]), float(hel[k]))
        one = segments.spiral_t_at_length(*args, np.array([s[k]]), float(big[k]))
        assert one.shape == (1,) and one[0] == t[k], k
    # And s(t) = s: against the integral of the speed √(Δr² + H² + (Δθ r(t))²).
    for k in range(0, n, 2003):

        def speed(u, k=k):
            return np.sqrt(
                (r1[k] - r0[k]) ** 2 + hel[k] ** 2 + (ang[k] * (r0[k] + u * (r1[k] - r0[k]))) ** 2
            )

        assert quad(speed, 0.0, t[k], epsabs=1e-13, epsrel=1e-13)[0] == pytest.approx(
            s[k], rel=1e-10, abs=1e-9
        )


def _arc_derivatives_reference(geom: ArcGeometry, u: np.ndarray, order: int) -> np.ndarray:
    """The array arithmetic of ArcGeometry.derivatives, written out here (the one-point path
    must give its bits)."""
    scale = geom.length_mm if geom.length_mm > 0.0 else 1.0
    t = np.clip(u / scale, 0.0, 1.0)
    dtheta, dr = geom.angle_rad, geom.radius_end_mm - geom.radius_start_mm
    theta, radius = t * dtheta, geom.radius_start_mm + t * dr
    c, s = np.cos(theta), np.sin(theta)
    turns = [(c, s), (-s, c), (-c, -s), (s, -c)]
    out = np.empty((order + 1, t.size, 3))
    for k in range(order + 1):
        ck, sk = turns[k % 4]
        term = (radius * dtheta**k)[:, None] * (ck[:, None] * geom.e1 + sk[:, None] * geom.e2)
        if k >= 1:
            cm, sm = turns[(k - 1) % 4]
            term += (k * dr * dtheta ** (k - 1)) * (cm[:, None] * geom.e1 + sm[:, None] * geom.e2)
        out[k] = term
    out[0] += geom.origin_mm + (t * geom.helix_mm)[:, None] * geom.normal
    if order >= 1:
        out[1] += geom.helix_mm * geom.normal
    for k in range(1, order + 1):
        out[k] /= scale**k
    return out


def test_arc_derivatives_at_a_few_points_give_the_bits_of_the_array_code():
    rng = np.random.default_rng(11)
    for trial in range(3000):
        normal = rng.normal(size=3) if trial % 3 else np.array([0.0, 0.0, rng.choice([-1, 1])])
        center = rng.uniform(-500.0, 500.0, 3)
        start = center + rng.uniform(-60.0, 60.0, 3)
        r_end = None if trial % 4 else float(rng.uniform(0.5, 40.0))
        helix = float(rng.choice([0.0, 0.0, 3.0, -11.0]))
        try:
            geom = ArcGeometry.from_segment(
                make_arc(center, start, normal, float(rng.uniform(-9.0, 9.0)), helix, r_end)
            )
        except GeometryError:
            continue
        length = geom.length_mm
        us = [rng.uniform(0.0, 1.0) * length, 0.0, -0.0, length, -1.0, 1.5 * length + 1.0]
        sets = [[u] for u in us] + [us[:2], us[2:5], us[1:5], list(rng.uniform(0, length, 7))]
        for u in sets:
            for order in range(4):
                few = geom.derivatives(np.array(u), order)
                ref = _arc_derivatives_reference(geom, np.array(u), order)
                assert few.shape == (order + 1, len(u), 3)
                assert few.tobytes() == ref.tobytes(), (trial, u, order)
            assert (
                geom.derivatives(u[0], 2).tobytes()
                == geom.derivatives(np.array(u[:1]), 2).tobytes()
            )
    # A parameter that is not finite takes the array path: NaN stays NaN.
    assert np.isnan(geom.derivatives(np.array([np.nan]), 1)).all()


@pytest.mark.skipif(
    segments._kernels is None, reason="the geometry kernels were not built (no C compiler)"
)
def test_compiled_spiral_inversion_gives_the_bits_of_the_array_code(monkeypatch):
    rng = np.random.default_rng(8)
    n = 4000
    r0, r1, ang, hel, big = _random_spirals(rng, n)
    for k in range(n):
        args = (float(r0[k]), float(r1[k]), float(ang[k]), float(hel[k]), float(big[k]))
        s = np.linspace(rng.uniform(0.0, 0.5), rng.uniform(0.5, 1.0), 33) * big[k]
        s[:4] = 0.0, -0.0, big[k], -1.0
        s[4] = big[k] + 1.0
        got = segments.spiral_t_at_length(*args[:4], s, args[4])
        ref = segments._spiral_t_arrays(*args[:4], s, args[4])
        assert got.tobytes() == ref.tobytes(), k
        # few Newton steps: the cap on the iterations is the array code's too
        short = segments.spiral_t_at_length(*args[:4], s, args[4], 2)
        assert short.tobytes() == segments._spiral_t_arrays(*args[:4], s, args[4], 2).tobytes()
    # The kernel takes the samples without −0.0 (those above went to the array code).
    arrays = segments._spiral_t_arrays

    def refuse(*_args):
        raise AssertionError("array path taken")

    monkeypatch.setattr(segments, "_spiral_t_arrays", refuse)
    s = np.linspace(0.0, 1.2, 33) * big[1]
    got = segments.spiral_t_at_length(
        float(r0[1]), float(r1[1]), float(ang[1]), float(hel[1]), s, float(big[1])
    )
    assert got.tobytes() == arrays(r0[1], r1[1], ang[1], hel[1], s, big[1]).tobytes()


def test_cross3_and_norm_give_numpys_bits():
    from nurbscnc.geometry.paths import _norm, cross3

    rng = np.random.default_rng(12)
    for _ in range(20000):
        a, b = rng.normal(size=(2, 3)) * 10.0 ** rng.uniform(-6, 6, (2, 1))
        assert cross3(a, b).tobytes() == np.cross(a, b).tobytes()
        assert _norm(a) == float(np.linalg.norm(a))
    m = rng.normal(size=(3, 5))  # columns of a (3, n) table, as the pieces' tangents
    assert cross3(m[:, 1], m[:, 2]).tobytes() == np.cross(m[:, 1], m[:, 2]).tobytes()


def test_arc_frame_is_the_one_np_cross_and_norm_give():
    rng = np.random.default_rng(13)
    for trial in range(2000):
        normal = rng.normal(size=3)
        center = rng.uniform(-500.0, 500.0, 3)
        start = center + rng.uniform(-60.0, 60.0, 3)
        seg = make_arc(center, start, normal, float(rng.uniform(-9.0, 9.0)), 1.0)
        geom = ArcGeometry.from_segment(seg)
        n = np.asarray(seg.normal, dtype=float)
        n = n / float(np.linalg.norm(n))
        d = np.asarray(seg.start_mm, dtype=float) - np.asarray(seg.center_mm, dtype=float)
        axial = float(d @ n)
        d_in = d - axial * n
        e1 = d_in / np.linalg.norm(d_in)
        assert geom.e1.tobytes() == e1.tobytes(), trial
        assert geom.e2.tobytes() == np.cross(n, e1).tobytes(), trial
        assert geom.normal.tobytes() == n.tobytes()
        assert geom.origin_mm.tobytes() == (np.asarray(seg.center_mm) + axial * n).tobytes()


def _assert_same_arc(a: ArcGeometry, b: ArcGeometry):
    for name in ("origin_mm", "e1", "e2", "normal"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    for name in ("radius_start_mm", "radius_end_mm", "angle_rad", "helix_mm", "length_mm"):
        assert getattr(a, name) == getattr(b, name)


def test_arc_geometry_is_built_once_per_segment_and_equals_a_fresh_build():
    """geometry_of keeps an arc's geometry on its segment (the soft-limits box, the pieces and
    the lower bound share it): the same object on every call, bit for bit a fresh build, its
    own for each segment (a changed copy gets its own), and a degenerate arc still refused
    on every call (nothing kept)."""
    from dataclasses import replace

    from nurbscnc.plan.limits import arc_box_mm

    spiral = make_arc([1, 2, 3], [6, 2, 3], (0, 0, 1), 1.5 * np.pi, 0.7, radius_end_mm=5.2)
    circle = make_arc([0, 0, 0], [2, 0, 0], (0, 0, 1), -0.5 * np.pi)
    shared = geometry_of(spiral)
    assert geometry_of(spiral) is shared and geometry_of(circle) is not shared
    _assert_same_arc(shared, ArcGeometry.from_segment(spiral))
    _assert_same_arc(geometry_of(circle), ArcGeometry.from_segment(circle))
    lo, hi = arc_box_mm(spiral)
    assert geometry_of(spiral) is shared
    moved = replace(spiral, center_mm=np.asarray(spiral.center_mm) + 1.0)
    assert geometry_of(moved) is not shared
    _assert_same_arc(geometry_of(moved), ArcGeometry.from_segment(moved))
    assert not np.array_equal(geometry_of(moved).origin_mm, shared.origin_mm)
    # The boxes from the shared geometry against dense points of fresh builds.
    fresh = ArcGeometry.from_segment(spiral)
    pts = fresh.point(np.linspace(0.0, fresh.u_end, 20001))
    assert np.all(pts >= lo - 1e-12) and np.all(pts <= hi + 1e-12)
    c_lo, c_hi = arc_box_mm(circle)  # a circle's box is exact (a spiral's: the larger radius)
    fresh = ArcGeometry.from_segment(circle)
    pts = fresh.point(np.linspace(0.0, fresh.u_end, 20001))
    np.testing.assert_allclose(pts.min(axis=0), c_lo, rtol=0, atol=1e-7)
    np.testing.assert_allclose(pts.max(axis=0), c_hi, rtol=0, atol=1e-7)
    bad = segments.Arc(
        circle.start_mm, circle.end_mm, circle.start_mm, circle.normal, 1.0, 0.0, 0.0, 0.0, 1.0, 9
    )
    for _ in range(2):
        with pytest.raises(GeometryError):
            geometry_of(bad)
