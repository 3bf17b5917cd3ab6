"""The interpolator (SPEC §3, §4, §10): fast exact inversion and the paper's Taylor recurrence.

References: the exact arc-length inverse (Newton on the Gauss–Legendre table,
``NurbsCurve.param_at_length``, itself checked against scipy quad in test_nurbs), each piece's
own exact placement (``Piece.points_mm``), and the closed-form arc length of the rational
quadratic circle: on a quarter with weights (1, cos α, 1), α = π/4, the angle from the
quarter's bisector φ obeys tan(φ/2) = tan(α/2)(2t − 1), t ∈ [0, 1] the span parameter.
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from nurbscnc.errors import ConfigError
from nurbscnc.geometry.nurbs import NurbsCurve
from nurbscnc.geometry.path import Kind
from nurbscnc.interpolate.sample import sample_plan
from nurbscnc.interpolate.taylor import taylor_params
from nurbscnc.machine.profile import load_machine
from nurbscnc.plan.lookahead import plan_program
from nurbscnc.plan.options import LookaheadOptions
from nurbscnc.plan.pieces import Piece, PieceList
from nurbscnc.plan.profile import ProfileInput
from nurbscnc.plan.profile_plan import plan_profile
from nurbscnc.plan.report import nurbs_step_lengths
from nurbscnc.program.interpret import interpret_text

ROOT = Path(__file__).resolve().parents[1]
MACHINE = load_machine()


def program(name: str):
    return interpret_text((ROOT / "programs" / name).read_text())


def program_curve(name: str) -> NurbsCurve:
    seg = next(s for s in program(name).segments if s.kind == "nurbs")
    return NurbsCurve.from_segment(seg)


def random_rational_curve(seed: int, degree: int) -> NurbsCurve:
    """Random clamped knots (one knot of multiplicity p: a C⁰ corner), points, weights."""
    rng = np.random.default_rng(seed)
    n = degree + 12
    inner = np.sort(rng.uniform(0.0, 1.0, n - degree - 1))
    inner[1:degree] = inner[0]  # multiplicity p at inner[0]
    knots = np.r_[[0.0] * (degree + 1), inner, [1.0] * (degree + 1)]
    return NurbsCurve(degree, knots, rng.uniform(-40.0, 40.0, (n, 3)), rng.uniform(0.3, 4.0, n))


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
    knots = [0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1]
    return NurbsCurve(2, knots, points, [1, h, 1, h, 1, h, 1, h, 1])


# ------------------------------------------------------------------ fast arc-length inversion


CURVES = {
    "naca2415": lambda: program_curve("naca2415.nc"),
    "butterfly": lambda: program_curve("butterfly.nc"),
    "random_p3": lambda: random_rational_curve(11, 3),
    "random_p5": lambda: random_rational_curve(12, 5),
}


@pytest.mark.parametrize("name", CURVES)
def test_fast_inversion_matches_exact_newton(name):
    """|s(u_fast) − s| ≤ 1e-9 mm and |u_fast − u_exact|·|C′| ≤ 1e-9 mm, at random arc
    lengths and at the table's own nodes and mid-intervals (where the Hermite error peaks)."""
    curve = CURVES[name]()
    rng = np.random.default_rng(3)
    nodes = curve.inverse_table.s_nodes_mm
    mids = 0.5 * (nodes[:-1] + nodes[1:])
    pick = rng.choice(mids.size, min(mids.size, 1500), replace=False)
    s = np.r_[
        0.0, rng.uniform(0.0, curve.length_mm, 1500), mids[pick], nodes[pick], curve.length_mm
    ]
    u_fast = curve.param_at_length_fast(s)
    u_exact = curve.param_at_length(s)
    assert np.all(np.abs(curve.arc_length(u_fast) - s) <= 1e-9)
    assert np.all(np.abs(u_fast - u_exact) * curve.speed(u_exact) <= 1e-9)
    order = np.argsort(s)
    assert np.all(np.diff(u_fast[order]) >= 0.0)  # monotone in s
    # The points are C(u) (de Boor) to rounding, so they lie on the curve.
    points, u = curve.points_at_length(s)
    np.testing.assert_array_equal(u, u_fast)
    scale = np.abs(curve.control_points_mm).max()
    np.testing.assert_allclose(points, curve.point(u), rtol=0, atol=1e-13 * scale)


def test_fast_inversion_clamps_and_hits_the_ends():
    curve = random_rational_curve(13, 4)
    u = curve.param_at_length_fast([-1.0, 0.0, curve.length_mm, curve.length_mm + 1.0])
    assert u[0] == u[1] == curve.u_start
    assert u[2] == u[3] == pytest.approx(curve.u_end, abs=1e-15)


# ------------------------------------------------------------------------- exact placement


def sampled_plan(name: str) -> SimpleNamespace:
    """A plan (no dynamics check) with its exact reference points as ``samples``."""
    plan = plan_program(program(name), MACHINE, LookaheadOptions(dynamics="off"))
    samples = sample_plan(plan.pieces, plan.profile, MACHINE.servo.period_s)
    return SimpleNamespace(pieces=plan.pieces, profile=plan.profile, samples=samples)


@pytest.fixture(scope="module")
def airfoil_plan():
    return sampled_plan("naca2415.nc")


@pytest.fixture(scope="module")
def corners_plan():
    return sampled_plan("corners.nc")


@pytest.mark.parametrize("which", ["airfoil", "corners"])
def test_exact_samples_match_each_pieces_own_exact_placement(which, airfoil_plan, corners_plan):
    """Vectorised placement (all PH pieces, arcs, lines at once; NURBS by the table) against
    each geometry's own exact inverse, one piece at a time (Newton–bisection on the PH
    polynomial / the NURBS Gauss–Legendre table; lines and arcs in closed form):
    1e-9 mm on NURBS, rounding elsewhere."""
    plan = airfoil_plan if which == "airfoil" else corners_plan
    smp = plan.samples
    starts = plan.profile.piece_start_mm
    kinds = np.array([p.name for p in plan.pieces])[smp.piece]
    assert set(kinds) >= ({"nurbs", "ph"} if which == "airfoil" else {"line", "arc"})
    for i in np.unique(smp.piece):
        sel = smp.piece == i
        piece, g = plan.pieces[i], plan.pieces[i].geometry
        local = np.clip(smp.s_mm[sel] - starts[i], 0.0, piece.length_mm)
        if piece.kind == Kind.PH:
            ref = g.point_mm(g.param_at_length(local))
        elif piece.kind == Kind.NURBS:
            ref = g.point(g.arc_table.param_at_length(piece.s_a_mm + local))
        else:
            ref = g.point(g.param_at_length(local))
        tol = 1e-9 if piece.kind == Kind.NURBS else 1e-12
        assert np.abs(smp.points_mm[sel] - ref).max() <= tol, piece.name
    assert smp.interpolator == "exact"


def test_exact_feed_has_no_fluctuation_on_nurbs(airfoil_plan):
    """True arc length per servo period equals the planned Δs (SPEC §10: no fluctuation)."""
    smp = airfoil_plan.samples
    k, ds = nurbs_step_lengths(airfoil_plan.pieces, smp)
    planned = smp.s_mm[k + 1] - smp.s_mm[k]
    assert k.size > 300  # servo steps on NURBS pieces (~390 on the 9 mm airfoil)
    assert np.all(np.abs(ds - planned) <= 2e-9)
    fast = smp.v_mm_s[k] >= 0.1 * smp.v_mm_s.max()
    assert np.all(np.abs(ds[fast] / planned[fast] - 1.0) <= 1e-8)


def test_unknown_interpolator_is_a_config_error(airfoil_plan):
    with pytest.raises(ConfigError):
        sample_plan(airfoil_plan.pieces, airfoil_plan.profile, 1e-3, interpolator="euler")


# ------------------------------------------------------------------------ Taylor (SPEC §3)

R_MM = 10.0
ALPHA = np.pi / 4
C_TAN = 1.0 / (2.0 * np.tan(ALPHA / 2))  # t = ½ + C_TAN tan ψ (see below)


def quarter_u_derivatives(s_mm):
    """u(s) and du/ds, d²u/ds², d³u/ds³ on the first quarter of ``circle(R_MM)``, closed form.

    With ψ = (s/R − α)/2: t = ½ + C tan ψ, u = t/4, dψ/ds = 1/(2R)."""
    psi = (np.asarray(s_mm) / R_MM - ALPHA) / 2.0
    sec2, tan = 1.0 / np.cos(psi) ** 2, np.tan(psi)
    k = 1.0 / (2.0 * R_MM)
    u = (0.5 + C_TAN * tan) / 4.0
    d1 = C_TAN * sec2 * k / 4.0
    d2 = C_TAN * 2.0 * sec2 * tan * k**2 / 4.0
    d3 = C_TAN * (4.0 * sec2 * tan**2 + 2.0 * sec2**2) * k**3 / 4.0
    return u, d1, d2, d3


def quarter_s(u):
    """s(u) [mm] on the first quarter, closed form."""
    return R_MM * (ALPHA + 2.0 * np.arctan((4.0 * np.asarray(u) - 0.5) / C_TAN))


def taylor_step(curve, s0, v, a, dt):
    """One step of the recurrence from the exact u at s0; returns u_1."""
    u0 = quarter_u_derivatives(s0)[0]
    u, _ = taylor_params(
        curve.power_form, u0, np.array([v, v]), np.array([a, a]), np.array([dt]), 0.0, 1.0
    )
    return u[1]


@pytest.mark.parametrize("accel", [0.0, 3000.0, -3000.0])
def test_taylor_step_is_the_papers_formula(accel):
    """u₁ = u₀ + u′(V T + A T²/2) + u″ V²T²/2 with u′ = 1/|C′|, u″ = −(C′·C″)/|C′|⁴ (eq. 4–5
    with the A term), u′ and u″ here from the closed-form arc length of the circle."""
    curve = circle(R_MM)
    v, dt = 80.0, 1e-3
    assert curve.arc_length(0.25)[0] == pytest.approx(np.pi * R_MM / 2, rel=1e-14)
    for s0 in np.linspace(0.3, 14.0, 9):
        u0, d1, d2, _ = quarter_u_derivatives(s0)
        expected = u0 + d1 * (v * dt + 0.5 * accel * dt * dt) + 0.5 * d2 * (v * dt) ** 2
        got = taylor_step(curve, s0, v, accel, dt)
        assert got - u0 == pytest.approx(expected - u0, rel=1e-11)


@pytest.mark.parametrize("accel", [0.0, 2000.0])
def test_taylor_per_step_error_is_third_order(accel):
    """Per-step arc-length error e(T) = s(u₁) − s₀ − (V T + A T²/2): halving T divides it by 8
    (a 2nd-order method), and at constant feed it matches the leading closed-form term
    −(u‴/u′)(V T)³/6."""
    curve = circle(R_MM)
    v = 60.0
    for s0 in (1.0, 5.5, 11.0):
        errors = []
        for dt in (1e-3, 5e-4, 2.5e-4):
            u1 = taylor_step(curve, s0, v, accel, dt)
            errors.append(quarter_s(u1) - s0 - (v * dt + 0.5 * accel * dt * dt))
        errors = np.array(errors)
        ratios = errors[:-1] / errors[1:]
        assert np.all((ratios > 7.7) & (ratios < 8.3)), ratios
        if accel == 0.0:
            _, d1, _, d3 = quarter_u_derivatives(s0)
            lead = -(d3 / d1) * (v * 2.5e-4) ** 3 / 6.0
            assert errors[-1] == pytest.approx(lead, rel=2e-3)


def circle_plan(feed_mm_s: float):
    curve = circle(R_MM)
    length = curve.length_mm
    piece = Piece(Kind.NURBS, curve, length, feed_mm_s, 0, 1, 0.0, 1.0, 0.0, 1.0 / R_MM)
    profile = plan_profile(ProfileInput([length], [feed_mm_s], [0.0, 0.0], 2000.0, 1e5))
    return curve, PieceList.of([piece]), profile


def test_taylor_points_are_on_the_curve_and_end_exactly():
    """Taylor points are C(u) (exactly on the circle), start and end at the programmed points,
    move monotonically, deviate from the exact points by a little (not zero: it is not the
    exact interpolator), and the feed fluctuation is that of a 2nd-order method."""
    curve, pieces, profile = circle_plan(50.0)
    period = 1e-3
    smp = sample_plan(pieces, profile, period, interpolator="taylor")
    exact = sample_plan(pieces, profile, period)
    assert smp.interpolator == "taylor"
    np.testing.assert_allclose(np.linalg.norm(smp.points_mm, axis=1), R_MM, rtol=2e-15)
    np.testing.assert_allclose(smp.points_mm, curve.point(smp.param), rtol=0, atol=1e-13)
    np.testing.assert_allclose(smp.points_mm[[0, -1]], [[R_MM, 0, 0], [R_MM, 0, 0]], atol=1e-13)
    assert np.all(np.diff(smp.param) >= 0.0)
    gap = np.linalg.norm(smp.points_mm - exact.points_mm, axis=1).max()
    assert 1e-9 < gap < 1e-3
    k, ds = nurbs_step_lengths(pieces, smp)
    planned = smp.s_mm[k + 1] - smp.s_mm[k]
    cruise = smp.v_mm_s[k] >= 0.5 * smp.v_mm_s.max()
    fluct = np.abs(ds[cruise] / planned[cruise] - 1.0)
    assert 1e-8 < fluct.max() < 2e-3


def test_taylor_on_the_airfoil_keeps_ph_pieces_exact(airfoil_plan):
    """Only NURBS samples change under "taylor"; PH, rapid samples stay exact; the fluctuation
    on the airfoil at cruise is in SPEC §3's 0.01–0.2 % band or below."""
    plan = airfoil_plan
    period = MACHINE.servo.period_s
    smp = sample_plan(plan.pieces, plan.profile, period, interpolator="taylor")
    kinds = np.array([p.name for p in plan.pieces])[smp.piece]
    same = kinds != "nurbs"
    np.testing.assert_array_equal(smp.points_mm[same], plan.samples.points_mm[same])
    k, ds = nurbs_step_lengths(plan.pieces, smp)
    planned = smp.s_mm[k + 1] - smp.s_mm[k]
    cruise = smp.v_mm_s[k] >= 0.5 * smp.v_mm_s.max()
    fluct = np.abs(ds[cruise] / planned[cruise] - 1.0)
    assert 1e-6 < fluct.max() < 2e-3
    np.testing.assert_array_equal(smp.points_mm[-1], plan.samples.points_mm[-1])


def test_reference_windows_are_the_rows_of_the_whole_reference(corners_plan):
    """``exact_reference(..., k0, k1)`` gives exactly rows k0…k1−1 of the whole reference
    (long programs are sampled window by window; the windows must join without a seam)."""
    from nurbscnc.plan.timing import exact_reference, sample_count

    plan = corners_plan
    whole = exact_reference(plan.pieces, plan.profile, 1e-3)
    n = sample_count(plan.pieces, plan.profile, 1e-3)
    assert n == whole.t_s.size
    cuts = [0, 1, 17, n // 3, n // 3 + 1, n - 2, n, n + 5]
    parts = [
        exact_reference(plan.pieces, plan.profile, 1e-3, a, b) for a, b in zip(cuts[:-1], cuts[1:])
    ]
    for field in ("t_s", "tau_s", "s_mm", "v_mm_s", "a_mm_s2", "piece", "points_mm", "param"):
        joined = np.concatenate([getattr(p, field) for p in parts])
        np.testing.assert_array_equal(joined, getattr(whole, field), err_msg=field)


def test_samples_are_the_plans_reference_with_lines(corners_plan):
    """The interpolator's samples are the plan's reference rows (the same arrays), with each
    row's source line and the interpolator's name; a window of them (``slice_samples``)
    slices every column and keeps the name, and a baseline's samples (no profile time, no
    parameter) slice as well."""
    from nurbscnc.interpolate.baselines import baseline_program_samples
    from nurbscnc.interpolate.sample import samples_of, slice_samples
    from nurbscnc.plan.timing import Reference, Samples, exact_reference

    plan = corners_plan
    ref = exact_reference(plan.pieces, plan.profile, 1e-3)
    smp = samples_of(ref, plan.pieces, "taylor")
    assert isinstance(smp, Samples) and isinstance(smp, Reference)
    for field in ("t_s", "tau_s", "s_mm", "v_mm_s", "a_mm_s2", "piece", "points_mm", "param"):
        assert getattr(smp, field) is getattr(ref, field), field
    np.testing.assert_array_equal(smp.line, plan.pieces.line[ref.piece])
    part = slice_samples(smp, 5, 40)
    assert part.interpolator == "taylor" and part.t_s.size == 35
    np.testing.assert_array_equal(part.line, smp.line[5:40])
    np.testing.assert_array_equal(part.tau_s, smp.tau_s[5:40])
    base = baseline_program_samples("adaptive", program("corners.nc"), MACHINE)
    assert base.tau_s is None and base.param is None and base.interpolator == "exact"
    cut = slice_samples(base, 1, 4)
    assert cut.param is None and cut.tau_s is None
    np.testing.assert_array_equal(cut.points_mm, base.points_mm[1:4])
