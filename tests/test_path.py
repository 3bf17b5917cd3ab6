"""The path model (geometry/path.py) against closed forms and geomdl (issue 12).

One table holds a line, a circular arc, a helix, a PH quintic and two spans of a NURBS
curve; every query (points at arc lengths, parameters, tangents, curvature, points at
parameter fractions) is made for all rows at once and checked per row against an
independent reference: the line and the circle/helix in closed form (helix length
√((rθ)² + H²), curvature r/(r² + c²) with c = H/θ), the PH quintic by its hodograph
w(ξ)² integrated with scipy's quad (arc length) and differentiated with numpy's polynomial
class (curvature), the NURBS by geomdl (points and derivatives at the table's parameters,
arc length by quad of geomdl's |C′|).
"""

from __future__ import annotations

import numpy as np
import pytest
from geomdl import NURBS
from numpy.polynomial import Polynomial
from scipy.integrate import quad

from nurbscnc.geometry.nurbs import NurbsCurve
from nurbscnc.geometry.path import Kind, PathTable
from nurbscnc.geometry.paths import ArcGeometry, LineGeometry
from nurbscnc.geometry.ph import PHQuintic

LINE = LineGeometry(np.array([1.0, 2.0, 3.0]), np.array([4.0, -2.0, 15.0]))
R, THETA, H = 7.5, 2.4, 0.0
CIRCLE = ArcGeometry(
    np.array([1.0, 1.0, 0.0]),
    np.array([1.0, 0.0, 0.0]),
    np.array([0.0, 1.0, 0.0]),
    np.array([0.0, 0.0, 1.0]),
    R,
    R,
    THETA,
    0.0,
)
HELIX_H = 3.0
HELIX = ArcGeometry(
    np.array([0.0, 0.0, 0.0]),
    np.array([0.0, 1.0, 0.0]),
    np.array([-1.0, 0.0, 0.0]),
    np.array([0.0, 0.0, 1.0]),
    R,
    R,
    -THETA,
    HELIX_H,
)
PH = PHQuintic(
    np.array([1.0 + 0.5j, 1.4 - 0.3j, 0.6 + 1.2j]),
    2.0 - 1.0j,
    origin_mm=np.array([0.0, 0.0, 5.0]),
    e1=np.array([1.0, 0.0, 0.0]),
    e2=np.array([0.0, 0.6, 0.8]),
)
rng = np.random.default_rng(7)
NPTS = 9
KNOTS = np.r_[[0.0] * 4, np.sort(rng.uniform(0.1, 0.9, NPTS - 4)), [1.0] * 4]
CURVE = NurbsCurve(3, KNOTS, rng.uniform(-30.0, 30.0, (NPTS, 3)), rng.uniform(0.5, 2.0, NPTS))
U_SPLIT = 0.37
S_SPLIT = float(CURVE.arc_length(np.array([U_SPLIT]))[0])


def geomdl_curve() -> NURBS.Curve:
    g = NURBS.Curve(normalize_kv=False)
    g.degree = CURVE.degree
    g.ctrlpts = CURVE.control_points_mm.tolist()
    g.weights = CURVE.weights.tolist()
    g.knotvector = CURVE.knots.tolist()
    return g


@pytest.fixture(scope="module")
def table() -> PathTable:
    rows = [
        (Kind.LINE, LINE, LINE.length_mm, 0.0, LINE.u_end, 0.0, 1),
        (Kind.ARC, CIRCLE, CIRCLE.length_mm, 0.0, CIRCLE.u_end, 0.0, 2),
        (Kind.ARC, HELIX, HELIX.length_mm, 0.0, HELIX.u_end, 0.0, 3),
        (Kind.PH, PH, PH.length_mm, 0.0, 1.0, 0.0, 4),
        (Kind.NURBS, CURVE, S_SPLIT, 0.0, U_SPLIT, 0.0, 5),
        (Kind.NURBS, CURVE, CURVE.length_mm - S_SPLIT, U_SPLIT, 1.0, S_SPLIT, 5),
    ]
    return PathTable.of(rows)


def test_one_kind_numbering(table):
    assert table.kind.tolist() == [Kind.LINE, Kind.ARC, Kind.ARC, Kind.PH, Kind.NURBS, Kind.NURBS]
    assert len(table.objects) == 1  # the two NURBS spans share their curve


def test_lengths_closed_forms(table):
    np.testing.assert_allclose(table.length_mm[0], np.sqrt(9 + 16 + 144), rtol=1e-15)
    np.testing.assert_allclose(table.length_mm[1], R * THETA, rtol=1e-15)
    np.testing.assert_allclose(table.length_mm[2], np.hypot(R * THETA, HELIX_H), rtol=1e-15)
    ph_len, _ = quad(_ph_speed, 0.0, 1.0, epsabs=0.0, epsrel=1e-12)
    np.testing.assert_allclose(table.length_mm[3], ph_len, rtol=1e-12)


def _ph_preimage() -> tuple[Polynomial, Polynomial]:
    """w(ξ) = w0 (1−ξ)² + 2 w1 ξ(1−ξ) + w2 ξ² as a complex numpy polynomial, and w²."""
    w0, w1, w2 = PH.w
    w = Polynomial([w0, 2 * (w1 - w0), w0 - 2 * w1 + w2])
    return w, w * w


def _ph_speed(xi: float) -> float:
    return float(abs(_ph_preimage()[1](xi)))


def _ph_point(xi: np.ndarray) -> np.ndarray:
    z = PH.p0 + _ph_preimage()[1].integ()(xi)
    return PH.origin_mm + z.real[:, None] * PH.e1 + z.imag[:, None] * PH.e2


def test_points_at_arc_length_match_the_closed_forms(table):
    m = 33
    frac = np.linspace(0.0, 1.0, m)
    idx = np.repeat(np.arange(table.size), m)
    s = (table.length_mm[:, None] * frac[None, :]).ravel()
    pts, param = table.points(idx, s)
    pts, param = pts.reshape(table.size, m, 3), param.reshape(table.size, m)
    # Line: start + s · direction.
    d = (LINE.end_mm - LINE.start_mm) / LINE.length_mm
    np.testing.assert_allclose(pts[0], LINE.start_mm + s[:m, None] * d, rtol=0, atol=1e-13)
    # Circle and helix: centre + r (cos θ e1 + sin θ e2) + t H n, θ = t Δθ.
    for row, g in ((1, CIRCLE), (2, HELIX)):
        th = frac * g.angle_rad
        ref = (
            g.origin_mm
            + R * (np.cos(th)[:, None] * g.e1 + np.sin(th)[:, None] * g.e2)
            + (frac * g.helix_mm)[:, None] * g.normal
        )
        np.testing.assert_allclose(pts[row], ref, rtol=0, atol=1e-12)
    # PH: ξ solves ∫₀^ξ |w²| = s (quad), the point is p0 + ∫ w² in the plane frame.
    for xi, target in zip(param[3], frac * table.length_mm[3]):
        np.testing.assert_allclose(
            quad(_ph_speed, 0.0, xi, epsabs=1e-14)[0], target, rtol=0, atol=1e-12
        )
    np.testing.assert_allclose(pts[3], _ph_point(param[3]), rtol=0, atol=1e-12)
    # NURBS: the point is geomdl's C(u) at the table's u, and u has the arc length asked
    # (within the 1e-9 mm of the inversion table, SPEC §10).
    g = geomdl_curve()
    for row in (4, 5):
        ref = np.array([g.evaluate_single(float(u)) for u in param[row]])
        np.testing.assert_allclose(pts[row], ref, rtol=0, atol=1e-11)
        speed = lambda u: float(np.linalg.norm(g.derivatives(u, 1)[1]))  # noqa: E731
        for u, target in zip(param[row][::8], (frac * table.length_mm[row])[::8]):
            lo = float(table.u_a[row])
            breaks = [k for k in np.unique(KNOTS) if lo < k < u]  # |C′| has kinks there
            got = quad(
                speed, lo, float(u), epsabs=1e-12, epsrel=1e-13, limit=400, points=breaks or None
            )[0]
            assert abs(got - target) <= 1e-9


def test_tangents_and_curvature_match_the_closed_forms(table):
    m = 9
    frac = np.linspace(0.0, 1.0, m)
    idx = np.repeat(np.arange(table.size), m)
    s = (table.length_mm[:, None] * frac[None, :]).ravel()
    tan = table.tangents(idx, s).reshape(table.size, m, 3)
    kappa = table.curvature(idx, s).reshape(table.size, m)
    _, param = table.points(idx, s)
    param = param.reshape(table.size, m)
    np.testing.assert_allclose(tan[0], np.broadcast_to(LINE.direction, (m, 3)), atol=1e-15)
    assert np.all(kappa[0] == 0.0)
    np.testing.assert_allclose(kappa[1], 1.0 / R, rtol=1e-13)
    c = HELIX_H / THETA
    np.testing.assert_allclose(kappa[2], R / (R * R + c * c), rtol=1e-13)
    th = frac * THETA
    np.testing.assert_allclose(
        tan[1], -np.sin(th)[:, None] * CIRCLE.e1 + np.cos(th)[:, None] * CIRCLE.e2, atol=1e-14
    )
    # PH: r′ = w², r″ = (w²)′ in the plane; κ = |x′y″ − y′x″| / |r′|³.
    _, w2 = _ph_preimage()
    d1, d2 = w2(param[3]), w2.deriv()(param[3])
    ref_k = np.abs((d1.conjugate() * d2).imag) / np.abs(d1) ** 3
    np.testing.assert_allclose(kappa[3], ref_k, rtol=1e-11)
    ref_t = d1 / np.abs(d1)
    np.testing.assert_allclose(
        tan[3], ref_t.real[:, None] * PH.e1 + ref_t.imag[:, None] * PH.e2, atol=1e-13
    )
    # NURBS: geomdl's derivatives at the table's u.
    g = geomdl_curve()
    for row in (4, 5):
        d = np.array([g.derivatives(float(u), 2) for u in param[row]])
        c1, c2 = d[:, 1], d[:, 2]
        ref_k = np.linalg.norm(np.cross(c1, c2), axis=1) / np.linalg.norm(c1, axis=1) ** 3
        np.testing.assert_allclose(kappa[row], ref_k, rtol=1e-9)
        np.testing.assert_allclose(tan[row], c1 / np.linalg.norm(c1, axis=1)[:, None], atol=1e-12)


def test_points_at_fraction_of_the_parameter_range(table):
    frac = np.array([0.0, 0.25, 0.5, 1.0])
    idx = np.repeat(np.arange(table.size), frac.size)
    f = np.tile(frac, table.size)
    pts = table.points_at_fraction(idx, f).reshape(table.size, frac.size, 3)
    np.testing.assert_allclose(
        pts[0], LINE.start_mm + frac[:, None] * (LINE.end_mm - LINE.start_mm), atol=1e-13
    )
    np.testing.assert_allclose(pts[3], _ph_point(frac), atol=1e-12)
    g = geomdl_curve()
    u = U_SPLIT + frac * (1.0 - U_SPLIT)
    np.testing.assert_allclose(pts[5], [g.evaluate_single(float(x)) for x in u], atol=1e-11)
    # The ends of consecutive rows of one curve meet.
    np.testing.assert_allclose(pts[4, -1], pts[5, 0], atol=1e-12)


def test_arc_lengths_are_clipped_to_the_piece(table):
    idx = np.array([0, 0, 3, 3])
    s = np.array([-1.0, 1e9, -1.0, 1e9])
    pts, _ = table.points(idx, s)
    np.testing.assert_allclose(pts[0], LINE.start_mm, atol=1e-15)
    np.testing.assert_allclose(pts[1], LINE.end_mm, atol=1e-13)
    np.testing.assert_allclose(pts[2], _ph_point(np.array([0.0]))[0], atol=1e-13)
    np.testing.assert_allclose(pts[3], _ph_point(np.array([1.0]))[0], atol=1e-12)


def _ph_params_reference(t: PathTable, i: np.ndarray, s: np.ndarray) -> np.ndarray:
    """The PH Newton as it was before the coefficients were gathered once (issue 14): the
    active set shrinks every step, each Horner gathers its coefficients again."""
    from nurbscnc.geometry.path import PH_MAX_NEWTON, horner_rows

    length = t.length_mm[i]
    i = t.ph_slot[i]  # the rows' PH coefficient columns
    tol = np.maximum(1e-13, 8.0 * np.finfo(float).eps * length)
    xi = np.where(length > 0.0, s / np.where(length > 0.0, length, 1.0), 0.0)
    active = np.arange(xi.size)
    for _ in range(PH_MAX_NEWTON):
        ia, x = i[active], xi[active] - 0.5
        f = horner_rows(t.ph_s, ia, x) - s[active]
        going = np.abs(f) > tol[active]
        if not going.any():
            return xi
        active, ia, x, f = active[going], ia[going], x[going], f[going]
        xi[active] = np.clip(xi[active] - f / horner_rows(t.ph_sigma, ia, x), 0.0, 1.0)
    bad = np.flatnonzero(np.abs(horner_rows(t.ph_s, i, xi - 0.5) - s) > tol)
    lo, hi = np.zeros(bad.size), np.ones(bad.size)
    for _ in range(60):  # the bisection fallback
        mid = 0.5 * (lo + hi)
        below = horner_rows(t.ph_s, i[bad], mid - 0.5) < s[bad]
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    xi[bad] = 0.5 * (lo + hi)
    return xi


def test_ph_newton_gives_the_bits_of_the_shrinking_active_set():
    # Many PH quintics of very different shapes (slow and fast middles: 2 to 8 Newton steps),
    # samples in mixed order, including both ends: the same ξ to the bit.
    rng = np.random.default_rng(11)
    rows = []
    for k in range(40):
        w = rng.normal(size=3) + 1j * rng.normal(size=3)
        w[1] *= rng.uniform(0.0, 3.0)
        rows.append((Kind.PH, PHQuintic(w, complex(*rng.normal(size=2))), 0.0, 0.0, 1.0, 0.0, k))
    rows = [(c, g, g.length_mm, *rest) for c, g, _, *rest in rows]
    t = PathTable.of(rows)
    i = rng.integers(0, t.size, 5000)
    s = rng.uniform(0.0, 1.0, i.size) * t.length_mm[i]
    s[::13], s[::17] = 0.0, t.length_mm[i[::17]]
    got = t.params(i, s)
    np.testing.assert_array_equal(got, _ph_params_reference(t, i, s))
    # And s(ξ) = s to the Newton tolerance, against the polynomial arc length.
    from nurbscnc.geometry.path import horner_rows

    np.testing.assert_allclose(horner_rows(t.ph_s, t.ph_slot[i], got - 0.5), s, rtol=0, atol=1e-12)


def test_ph_rows_columnar_and_objects_share_the_compact_coefficients():
    """A program with line–line blends (columnar PH rows) and line–arc blends (PH objects):
    every PH row of the pieces' path table (its coefficients in column ``ph_slot[row]``)
    gives the points of its own PHQuintic (found by hypothesis: the columnar rows' chunk
    once ran into the objects' columns)."""
    from nurbscnc.machine.profile import load_machine
    from nurbscnc.pipeline import RunOptions, run_program
    from nurbscnc.plan.options import Dynamics, LookaheadOptions
    from nurbscnc.program.interpret import interpret_text

    text = (
        "G21 G90 G17 G94 G64\nG0 X0 Y0 Z0\nG1 X1 Y0.5 F300\nG1 X1 Y1.5\n"
        "G3 X0.540302 Y2.341471 I-1 J0\nG1 X1.540302 Y2.841471\nG1 X1.540302 Y3.841471\n"
        "M2\n"
    )
    options = RunOptions(lookahead=LookaheadOptions(dynamics=Dynamics.OFF))
    pieces = run_program(interpret_text(text), load_machine(), options).plan.pieces
    table = pieces.path
    ph = np.flatnonzero(table.kind == Kind.PH)
    columnar = np.isin(ph, pieces.ph_rows)
    assert columnar.any() and (~columnar).any()  # both kinds of PH row
    assert np.array_equal(np.sort(table.ph_slot[ph]), np.arange(ph.size))
    for r in ph.tolist():
        geom = pieces[r].geometry
        s = np.linspace(0.0, float(table.length_mm[r]), 9)
        got, _ = table.points(np.full(s.size, r), s)
        want = geom.point_mm(geom.param_at_length(s))
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)


def test_path_table_of_nurbs_rows_gathered_whole_is_the_row_by_row_table():
    """PathTable.of on a program's NURBS cells (two curves, one a moved copy): the table
    gathered whole equals the one built row by row, column by column, bit for bit (its
    curves the same objects in the same order)."""
    from nurbscnc.geometry.path import PathTable
    from nurbscnc.machine.profile import load_machine
    from nurbscnc.plan.program_pieces import segment_pieces
    from nurbscnc.program.interpret import interpret_text
    from tests.test_plan_kernels import _airfoil_twice

    pieces = segment_pieces(interpret_text(_airfoil_twice()).segments, load_machine())
    rows_obj = sorted(pieces.objects)
    rows = [
        (
            pieces.kind[r],
            pieces.objects[r][0],
            pieces.length_mm[r],
            *pieces.objects[r][1:],
            pieces.line[r],
        )
        for r in rows_obj
    ]
    whole, by_row = PathTable.of(rows), PathTable.of(rows, bulk=False)
    assert len(whole.objects) == 2 and all(a is b for a, b in zip(whole.objects, by_row.objects))
    for name in whole.__dataclass_fields__:
        a, b = getattr(whole, name), getattr(by_row, name)
        if isinstance(a, np.ndarray):
            assert a.dtype == b.dtype and a.shape == b.shape, name
            assert a.tobytes() == b.tobytes(), name
