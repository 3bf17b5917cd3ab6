"""S-curve transition closed forms and their inverses (SPEC §7), against independent oracles:
scipy minimisation of the trapezoidal-acceleration time, quad integration of the jerk phases,
brentq root finding, and exact closed-form special cases."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad
from scipy.optimize import brentq, minimize_scalar

from nurbscnc.errors import ConfigError, PlanningError
from nurbscnc.plan.feedrate import (
    max_entry_speed,
    max_reachable_speed,
    max_reachable_speed_scalar,
    peak_speed,
    scurve_distance_mm,
    scurve_duration_s,
    scurve_timing,
)

A = 2450.0  # SPEC §9 Table 3
J = 5.0e4


def _d_ref(v_a, v_b, a=A, j=J):
    """Test-only distance of the S-curve, written from SPEC §7 independently."""
    dv = abs(v_b - v_a)
    t = dv / a + a / j if dv >= a * a / j else 2.0 * math.sqrt(dv / j)
    return (v_a + v_b) * t / 2.0


def _t_min_oracle(dv, a, j):
    """Minimum time of a trapezoidal acceleration pulse of area dv, peak a_p ≤ a, slopes ≤ j.

    Height a_p, ramps a_p/j: area a_p·(T − a_p/j) = dv, so T(a_p) = dv/a_p + a_p/j; minimise
    numerically over (0, a] (no closed form used; the bounded search never lands exactly on
    the end point, so the end point a_p = a is evaluated as well).
    """

    def t_of(ap):
        return dv / ap + ap / j

    res = minimize_scalar(
        t_of, bounds=(1e-9 * a, a), method="bounded", options={"xatol": 1e-12 * a}
    )
    return min(res.fun, t_of(a))


@pytest.mark.parametrize(
    "v_a, v_b, a, j",
    [
        (0.0, 3500.0 / 60.0, A, J),  # benchmark feed, A not reached (A²/J = 120 mm/s)
        (0.0, 300.0, A, J),  # A reached
        (120.0, 10.0, A, J),  # deceleration, A not reached
        (400.0, 5.0, A, J),  # deceleration, A reached
        (7.0, 7.0 + A * A / J, A, J),  # exactly on the branch boundary
        (1.0, 2.0, 1.0e3, 1.0e8),  # very stiff jerk: almost trapezoidal velocity
    ],
)
def test_scurve_duration_is_the_minimum_time_and_distance_integrates(v_a, v_b, a, j):
    dv = abs(v_b - v_a)
    t = scurve_duration_s(v_a, v_b, a, j)
    assert t == pytest.approx(_t_min_oracle(dv, a, j), rel=1e-9)
    # Integrate the phases (jerk ±j for t_j, 0 for t_c, ∓j for t_j) with quad.
    t_j, t_c, a_p = scurve_timing(v_a, v_b, a, j)
    assert 2 * t_j + t_c == pytest.approx(t, rel=1e-14)
    assert a_p <= a * (1 + 1e-15)
    sign = 1.0 if v_b >= v_a else -1.0

    def acc(tt):
        if tt < t_j:
            return sign * j * tt
        if tt < t_j + t_c:
            return sign * a_p
        return sign * j * max(t - tt, 0.0)

    brk = [t_j, t_j + t_c]

    def vel(tt):
        return v_a + quad(acc, 0.0, tt, points=[p for p in brk if p < tt] or None)[0]

    assert vel(t) == pytest.approx(v_b, rel=1e-10, abs=1e-10)
    dist = quad(vel, 0.0, t, points=brk, epsabs=1e-13, epsrel=1e-12)[0]
    assert scurve_distance_mm(v_a, v_b, a, j) == pytest.approx(dist, rel=1e-9)
    assert scurve_distance_mm(v_a, v_b, a, j) == pytest.approx((v_a + v_b) * t / 2, rel=1e-15)


def test_scurve_arrays_broadcast_and_match_scalars():
    v_a = np.array([0.0, 10.0, 300.0])
    v_b = np.array([[50.0], [500.0]])
    d = scurve_distance_mm(v_a, v_b, A, J)
    assert d.shape == (2, 3)
    for r in range(2):
        for c in range(3):
            assert d[r, c] == pytest.approx(_d_ref(v_a[c], v_b[r, 0]), rel=1e-15)
    assert isinstance(scurve_duration_s(1.0, 2.0, A, J), float)


@pytest.mark.parametrize("bad", [0.0, -1.0, math.inf, math.nan])
def test_bad_limits_are_config_errors(bad):
    with pytest.raises(ConfigError):
        scurve_duration_s(0.0, 1.0, bad, J)
    with pytest.raises(ConfigError):
        max_reachable_speed(0.0, 1.0, A, bad)


def test_bad_speeds_are_planning_errors():
    with pytest.raises(PlanningError):
        scurve_distance_mm(-1.0, 1.0, A, J)
    with pytest.raises(PlanningError):
        max_reachable_speed(1.0, math.nan, A, J)


def test_max_reachable_from_rest_closed_forms():
    # From rest, A not reached: D = v·√(v/J) → v = (d²J)^(1/3).
    d = 0.05
    assert max_reachable_speed(0.0, d, A, J) == pytest.approx((d * d * J) ** (1 / 3), rel=1e-14)
    # A reached: D = v(v/A + A/J)/2 → v² + v·A²/J − 2dA = 0.
    d = 40.0
    k = A * A / J
    v_ref = (-k + math.sqrt(k * k + 8 * d * A)) / 2
    assert max_reachable_speed(0.0, d, A, J) == pytest.approx(v_ref, rel=1e-14)
    assert max_reachable_speed(0.0, 0.0, A, J) == 0.0
    assert max_reachable_speed(17.0, 0.0, A, J) == 17.0


@settings(max_examples=200, deadline=None)
@given(
    v0=st.one_of(st.just(0.0), st.floats(1e-6, 1e3)),
    d=st.floats(1e-7, 1e4),
    a=st.floats(50.0, 2e4),
    j=st.floats(1e3, 1e7),
)
def test_max_reachable_inverts_the_distance(v0, d, a, j):
    v = max_reachable_speed(v0, d, a, j)
    assert v >= v0
    assert scurve_distance_mm(v0, v, a, j) <= d  # float-exact guard
    # Against brentq on the independent distance, where the speed is well conditioned.
    hi = v0 + 1.0
    while _d_ref(v0, hi, a, j) < d:
        hi = v0 + 2 * (hi - v0)
    v_ref = brentq(lambda x: _d_ref(v0, x, a, j) - d, v0, hi, xtol=1e-300, rtol=1e-15)
    assert v - v0 == pytest.approx(v_ref - v0, rel=1e-12, abs=8 * math.ulp(v_ref))
    # Scalar path, array path, and the deceleration twin agree.
    assert max_reachable_speed_scalar(v0, d, a, j) == pytest.approx(v, rel=4e-15)
    assert max_entry_speed(v0, d, a, j) == v


def test_max_reachable_is_continuous_across_the_A_branch():
    v0 = 12.0
    d_thr = (2 * v0 + A * A / J) * A / J  # where Δv = A²/J exactly
    below = max_reachable_speed(v0, d_thr * (1 - 1e-15), A, J)
    at = max_reachable_speed(v0, d_thr, A, J)
    above = max_reachable_speed(v0, d_thr * (1 + 1e-15), A, J)
    assert at - v0 == pytest.approx(A * A / J, rel=1e-13)
    assert below <= at <= above
    assert above - below < 1e-12 * at


def test_max_reachable_array_matches_scalar_elementwise():
    rng = np.random.default_rng(5)
    v0 = rng.uniform(0, 300, 2000)
    d = 10 ** rng.uniform(-8, 3, 2000)
    v = max_reachable_speed(v0, d, A, J)
    ref = np.array([max_reachable_speed_scalar(x, y, A, J) for x, y in zip(v0, d)])
    np.testing.assert_allclose(v, ref, rtol=4e-15, atol=0)
    assert np.all(scurve_distance_mm(v0, v, A, J) <= d)


def test_reach_is_not_monotone_in_the_start_speed():
    # Documented in plan/profile.py: dR/dv0 = (2v0 − Δv)/(2v0 + 3Δv) while A is not reached,
    # negative for Δv > 2v0 (a faster start covers the jerk ramps sooner).
    d = 0.2
    for v0 in (0.0, 1.0, 5.0, 40.0):
        h = 1e-5
        r0 = max_reachable_speed(v0, d, A, J)
        dv = r0 - v0
        assert dv < A * A / J
        slope = max_reachable_speed(v0 + h, d, A, J) - max_reachable_speed(max(v0 - h, 0), d, A, J)
        slope /= (v0 + h) - max(v0 - h, 0)
        assert slope == pytest.approx((2 * v0 - dv) / (2 * v0 + 3 * dv), rel=1e-5, abs=1e-6)
    assert max_reachable_speed(1.0, d, A, J) < max_reachable_speed(0.0, d, A, J)


def test_peak_speed_rest_to_rest_closed_forms():
    # v_s = v_e = 0: 2·D(0→v) = L. A not reached: 2v√(v/J) = L → v = (L²J/4)^(1/3).
    L = 0.3
    v_ref = (L * L * J / 4) ** (1 / 3)
    assert v_ref < A * A / J
    assert peak_speed(0.0, 0.0, L, 1e3, A, J) == pytest.approx(v_ref, rel=1e-14)
    # A reached: v(v/A + A/J) = L.
    L = 80.0
    k = A * A / J
    v_ref = (-k + math.sqrt(k * k + 4 * L * A)) / 2
    assert v_ref > k
    assert peak_speed(0.0, 0.0, L, 1e3, A, J) == pytest.approx(v_ref, rel=1e-14)
    # Long enough to reach the cap: the cap itself, exactly.
    assert peak_speed(0.0, 0.0, 500.0, 100.0, A, J) == 100.0


@settings(max_examples=150, deadline=None)
@given(
    v_s=st.floats(0.0, 200.0),
    v_e=st.floats(0.0, 200.0),
    extra=st.floats(1e-6, 200.0),
    cap_over=st.floats(0.0, 500.0),
)
def test_peak_speed_against_brentq(v_s, v_e, extra, cap_over):
    lo = max(v_s, v_e)
    L = _d_ref(v_s, v_e) + extra
    cap = lo + cap_over
    v_p = peak_speed(v_s, v_e, L, cap, A, J)
    assert lo <= v_p <= cap
    assert scurve_distance_mm(v_s, v_p, A, J) + scurve_distance_mm(v_p, v_e, A, J) <= L
    if _d_ref(v_s, cap) + _d_ref(cap, v_e) <= L:
        assert v_p == cap
    else:

        def f(x):
            return _d_ref(v_s, x) + _d_ref(x, v_e) - L

        ref = brentq(f, lo, cap, xtol=1e-300, rtol=1e-15)
        assert v_p == pytest.approx(ref, rel=1e-13, abs=1e-13)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_peak_speed_is_the_largest_float_that_fits(seed):
    """peak_speed_unchecked (Newton steps, then bisection from a narrow bracket) on 2,000
    random pieces with different rise and descent limits (A not reached, reached, both):
    every v_p fits (pair distance ≤ L) and the next float up does not, unless v_p is the cap
    (the definition, checked with the planner's own float distance)."""
    from nurbscnc.plan.feedrate import _pair_distance_mm, peak_speed_unchecked

    rng = np.random.default_rng(seed)
    n = 2000
    v_s = rng.choice([0.0, 1.0, 10.0, 40.0], n) * rng.random(n)
    v_e = rng.choice([0.0, 1.0, 10.0, 40.0], n) * rng.random(n)
    a, j = rng.choice([2450.0, 500.0], n), rng.choice([5e4, 1e6, 1e9], n)
    a_dn, j_dn = rng.choice([2450.0, 300.0], n), rng.choice([5e4, 1e3], n)
    lo = np.maximum(v_s, v_e)
    straight = scurve_distance_mm(
        np.minimum(v_s, v_e), lo, np.minimum(a, a_dn), np.minimum(j, j_dn)
    )
    length = straight + rng.choice([1e-6, 1e-3, 0.05, 1.0, 30.0], n) * rng.random(n)
    cap = np.maximum(np.full(n, 58.3), lo)
    v_p = peak_speed_unchecked(v_s, v_e, length, cap, a, j, a_dn, j_dn)
    assert np.all((v_p >= lo) & (v_p <= cap))
    fits = _pair_distance_mm(v_s, v_p, v_e, a, j, a_dn, j_dn) <= length
    assert np.all(fits | (v_p == lo))
    up = np.nextafter(v_p, np.inf)
    assert np.all((v_p == cap) | (_pair_distance_mm(v_s, up, v_e, a, j, a_dn, j_dn) > length))


def test_peak_speed_vectorised_and_errors():
    v_p = peak_speed(np.array([0.0, 10.0]), 0.0, np.array([0.3, 1e4]), 100.0, A, J)
    assert v_p.shape == (2,)
    assert v_p[0] == pytest.approx((0.3**2 * J / 4) ** (1 / 3), rel=1e-14)
    assert v_p[1] == 100.0
    with pytest.raises(PlanningError):
        peak_speed(50.0, 0.0, 1e-3, 100.0, A, J)  # cannot even stop within 1 µm
    with pytest.raises(PlanningError):
        peak_speed(50.0, 0.0, 100.0, 40.0, A, J)  # cap below the start speed


# --- caps along curves (issue 13): the servo's steady-error cap and the corner cells -----------


@pytest.mark.parametrize("radius_mm", [0.2, 1.0, 5.0])
def test_servo_curve_cap_keeps_the_lsim_circle_error_within_epsilon(radius_mm):
    # Closed form: v = √(ε r / g) with g = 2.85e-5 s² (SPEC §8); independently, the servo
    # model simulated by scipy.signal.lsim on a circle at that speed settles to a radius
    # error ≤ ε and close to it (the series bound is tight: 94–100 % of ε).
    import sys
    from pathlib import Path

    from nurbscnc.machine.caps import servo_curve_cap_mm_s
    from nurbscnc.machine.profile import load_machine
    from nurbscnc.plan.blends import servo_gain_s2

    sys.path.insert(0, str(Path(__file__).parent))
    from servo_reference import lsim_actual_mm

    m = load_machine()
    eps_mm = m.limits.contour_tolerance_mm
    gain = servo_gain_s2(m)
    assert gain == pytest.approx(2.85e-5, rel=2e-3)
    v = servo_curve_cap_mm_s(1.0 / radius_mm, eps_mm, gain)
    assert v == pytest.approx(math.sqrt(eps_mm * radius_mm / gain), rel=1e-12)
    w = v / radius_mm  # rad/s
    t = np.arange(0.0, 6 * 2 * math.pi / w, 1e-3)
    ref = np.column_stack([radius_mm * np.cos(w * t), radius_mm * np.sin(w * t), 0 * t])
    tool = lsim_actual_mm(ref, m, settle_s=0.0)
    last = t > t[-1] - 2 * math.pi / w  # the last turn: steady state
    grow_mm = np.hypot(tool[last, 0], tool[last, 1]) - radius_mm
    assert grow_mm.max() <= eps_mm
    assert grow_mm.min() >= 0.93 * eps_mm
    assert servo_curve_cap_mm_s(0.0, eps_mm, gain) == math.inf
    assert servo_curve_cap_mm_s(2.0, eps_mm, 0.0) == math.inf


def test_corner_region_pieces_follow_the_curvature_of_a_circle():
    # A rational quarter circle of r = 0.5 mm at F3500 is a corner region (κ = 2 > A/F²):
    # its PH pieces are cut to equal arc lengths ≤ CORNER_CELL_MM, and each is capped by
    # SPEC §7's V_sp at its own curvature, V_cf = F·κ̄/(κ + κ̄) = 58.33/3 mm/s (below
    # V_af(2) = 55.1 and √(A r) = 35 mm/s).
    from nurbscnc.machine.profile import load_machine
    from nurbscnc.plan.curved_pieces import CORNER_CELL_MM
    from nurbscnc.plan.options import PlanOptions
    from nurbscnc.plan.program_pieces import segment_pieces
    from nurbscnc.program.interpret import interpret_text

    r = 0.5
    w = math.sqrt(0.5)
    prog = (
        f"G21 G17 G90 G94\nG0 X{r} Y0\nF3500\nG6.2 P3 K0 X{r} Y0 R1\n"
        f"K0 X{r} Y{r} R{w:.15f}\nK0 X0 Y{r} R1\nK1\nK1\nK1\nM2\n"
    )
    m = load_machine()
    pl = segment_pieces(interpret_text(prog).segments, m, PlanOptions())
    ph = np.flatnonzero(pl.kind == 3)
    n = math.ceil(math.pi * r / 2 / CORNER_CELL_MM)
    assert ph.size == n == len(pl) - 1
    assert np.allclose(pl.length_mm[ph], math.pi * r / 2 / n, rtol=1e-4)
    assert np.allclose(pl.kappa_max_per_mm[ph], 1.0 / r, rtol=3e-3)
    assert np.allclose(pl.v_cap_mm_s[ph], (3500.0 / 60.0) / 3.0, rtol=1e-5)
