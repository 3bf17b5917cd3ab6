"""The kinematic lower bound on cycle time (SPEC §10) against closed forms and brute force."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad
from scipy.optimize import brentq

from nurbscnc.errors import ConfigError, PlanningError
from nurbscnc.geometry.nurbs import NurbsCurve
from nurbscnc.geometry.paths import ArcGeometry, LineGeometry
from nurbscnc.machine.profile import load_machine
from nurbscnc.plan.lowerbound import (
    interval_times_s,
    lower_bound_time_s,
    machine_lower_bound,
    optimal_v2,
    program_lower_bound_s,
)
from nurbscnc.program.interpret import interpret_text

V = 3500.0 / 60.0  # mm/s
A = 2450.0  # mm/s²
TS = 1e-3  # s
DELTA = 1e-3  # mm
LIMITS = {"a_max_mm_s2": A, "period_s": TS, "chord_tolerance_mm": DELTA}
PROGRAMS = Path(__file__).resolve().parent.parent / "programs"


def line(x0, x1):
    return LineGeometry((x0, 0.0, 0.0), (x1, 0.0, 0.0))


def circle(radius_mm, turns=1.0):
    return ArcGeometry(
        origin_mm=np.zeros(3),
        e1=np.array([1.0, 0.0, 0.0]),
        e2=np.array([0.0, 1.0, 0.0]),
        normal=np.array([0.0, 0.0, 1.0]),
        radius_start_mm=radius_mm,
        radius_end_mm=radius_mm,
        angle_rad=2.0 * math.pi * turns,
        helix_mm=0.0,
    )


def trapezoid_s(length_mm, v_mm_s, a_mm_s2=A):
    """Rest-to-rest time with |a| ≤ A, v ≤ V: L/V + V/A, or 2√(L/A) when V is not reached."""
    if length_mm >= v_mm_s**2 / a_mm_s2:
        return length_mm / v_mm_s + v_mm_s / a_mm_s2
    return 2.0 * math.sqrt(length_mm / a_mm_s2)


def chord_feed(radius_mm, delta_mm, period_s=TS):
    return (2.0 / period_s) * math.sqrt(2.0 * delta_mm * radius_mm - delta_mm**2)


# --------------------------------------------------------------------------------------------
# Closed forms on lines and circles


@pytest.mark.parametrize("ds_mm", [0.01, 0.0371, 0.5, 3.0])
@pytest.mark.parametrize("length_mm", [10.0, 1.0, 0.5, 0.01])
def test_line_rest_to_rest_closed_form_on_any_grid(length_mm, ds_mm):
    # Reached V: L/V + V/A; too short: 2√(L/A). Exact on any grid (the cap is constant, and
    # inside an interval the profile is resolved exactly).
    lb = lower_bound_time_s([line(0.0, length_mm)], V, **LIMITS, ds_mm=ds_mm)
    assert lb.time_s == pytest.approx(trapezoid_s(length_mm, V), rel=1e-12)
    s = lb.s_mm
    expected_v = np.sqrt(np.minimum(np.minimum(V * V, 2 * A * s), 2 * A * (length_mm - s)))
    np.testing.assert_allclose(lb.v_mm_s, expected_v, rtol=1e-12, atol=1e-6)
    assert lb.s_mm[0] == 0.0 and lb.s_mm[-1] == pytest.approx(length_mm, rel=1e-15)
    assert lb.t_s[-1] == lb.time_s and np.all(np.diff(lb.t_s) >= 0.0)


def test_line_time_along_the_path_matches_closed_form():
    # t(s) on the accelerating stretch is √(2s/A); on the cruise (s - V²/2A)/V + V/A.
    length = 5.0
    lb = lower_bound_time_s([line(0.0, length)], V, **LIMITS)
    s = lb.s_mm
    s_acc = V * V / (2 * A)
    acc = s <= s_acc
    np.testing.assert_allclose(lb.t_s[acc], np.sqrt(2 * s[acc] / A), rtol=1e-10, atol=1e-13)
    mid = (s > s_acc) & (s < length - s_acc)
    np.testing.assert_allclose(lb.t_s[mid], (s[mid] - s_acc) / V + V / A, rtol=1e-12)


@pytest.mark.parametrize(
    ("radius_mm", "delta_mm", "binding"),
    [
        (5.0, 1e-3, "feed"),  # √(AR) = 110.7, V_af = 200: V = 58.3 binds
        (0.5, 1e-3, "normal"),  # √(AR) = 35.0 < V_af = 63.2 < V
        (1.0, 1e-4, "chord"),  # V_af = 28.3 < √(AR) = 49.5 < V
    ],
)
def test_circle_constant_curvature(radius_mm, delta_mm, binding):
    v_c = min(V, math.sqrt(A * radius_mm), chord_feed(radius_mm, delta_mm))
    expected_binding = {
        V: "feed",
        math.sqrt(A * radius_mm): "normal",
        chord_feed(radius_mm, delta_mm): "chord",
    }[v_c]
    assert expected_binding == binding
    geom = circle(radius_mm)
    lb = lower_bound_time_s([geom], V, a_max_mm_s2=A, period_s=TS, chord_tolerance_mm=delta_mm)
    length = 2.0 * math.pi * radius_mm
    assert length >= v_c**2 / A
    assert lb.time_s == pytest.approx(length / v_c + v_c / A, rel=1e-11)
    assert lb.v_mm_s.max() == pytest.approx(v_c, rel=1e-12)
    np.testing.assert_allclose(lb.v_cap_mm_s[1:-1], v_c, rtol=1e-12)


def test_circle_then_line_accelerates_across_the_junction():
    # R = 0.5: v_c = √(AR) on the circle, then the line accelerates from v_c to V and stops.
    r = 0.5
    v_c = math.sqrt(A * r)
    lc, ll = 2 * math.pi * r, 10.0
    geoms = [circle(r), LineGeometry((r, 0.0, 0.0), (r, ll, 0.0))]
    lb = lower_bound_time_s(geoms, V, **LIMITS)
    expected = (
        v_c / A
        + (lc - v_c**2 / (2 * A)) / v_c
        + (V - v_c) / A
        + (ll - (V**2 - v_c**2) / (2 * A) - V**2 / (2 * A)) / V
        + V / A
    )
    assert lb.time_s == pytest.approx(expected, rel=1e-11)
    # The junction appears twice, at the same s and speed v_c.
    j = lb.piece_start[1]
    assert lb.s_mm[j] == lb.s_mm[j - 1] == pytest.approx(lc, rel=1e-15)
    assert lb.v_mm_s[j] == pytest.approx(v_c, rel=1e-12)
    assert lb.v_mm_s[j - 1] == pytest.approx(v_c, rel=1e-12)


def test_feed_drop_between_pieces():
    # F1 = 50 then F2 = 20 mm/s: slow down to F2 before the junction, not after it.
    v1, v2, l1, l2 = 50.0, 20.0, 6.0, 4.0
    lb = lower_bound_time_s([line(0.0, l1), line(l1, l1 + l2)], [v1, v2], **LIMITS)
    expected = (
        v1 / A
        + (v1 - v2) / A
        + (l1 - v1**2 / (2 * A) - (v1**2 - v2**2) / (2 * A)) / v1
        + (l2 - v2**2 / (2 * A)) / v2
        + v2 / A
    )
    assert lb.time_s == pytest.approx(expected, rel=1e-12)


def test_v_max_caps_the_programmed_feed():
    lb = lower_bound_time_s([line(0.0, 10.0)], 1e9, v_max_mm_s=V, **LIMITS)
    assert lb.time_s == pytest.approx(trapezoid_s(10.0, V), rel=1e-12)


@pytest.mark.parametrize("lengths", [(3.0, 7.0), (0.3, 7.0, 0.2), (5.0, 0.01)])
def test_exact_stops_add_their_decel_and_accel(lengths):
    edges = np.concatenate(([0.0], np.cumsum(lengths)))
    geoms = [line(a, b) for a, b in zip(edges[:-1], edges[1:])]
    smooth = lower_bound_time_s(geoms, V, **LIMITS)
    assert smooth.time_s == pytest.approx(trapezoid_s(sum(lengths), V), rel=1e-12)
    stops = [True] * (len(lengths) - 1) + [False]
    stopped = lower_bound_time_s(geoms, V, **LIMITS, stop_after=stops)
    expected = sum(trapezoid_s(length, V) for length in lengths)
    assert stopped.time_s == pytest.approx(expected, rel=1e-12)
    for j in stopped.piece_start[1:-1]:
        assert stopped.v_mm_s[j] == 0.0 and stopped.v_mm_s[j - 1] == 0.0


def test_zero_length_piece_changes_nothing():
    geoms = [line(0.0, 2.0), line(2.0, 2.0), line(2.0, 5.0)]
    lb = lower_bound_time_s(geoms, V, **LIMITS)
    assert lb.time_s == pytest.approx(trapezoid_s(5.0, V), rel=1e-12)


def test_machine_wrapper_uses_machine_limits_and_rapid_rate():
    machine = load_machine(overrides={"limits.rapid_mm_min": 6000.0})
    geoms = [line(0.0, 20.0), line(20.0, 30.0)]
    lb = machine_lower_bound(geoms, [0.0, 1e9], machine, rapid=[True, False], stop_after=[1, 0])
    expected = trapezoid_s(20.0, 100.0) + trapezoid_s(10.0, V)
    assert lb.time_s == pytest.approx(expected, rel=1e-12)


# --------------------------------------------------------------------------------------------
# The bound is below jerk-limited motion


def scurve_rest_to_rest_s(length_mm, v_mm_s, a_mm_s2, j_mm_s3):
    """Symmetric 7-phase S-curve rest to rest (SPEC §7 closed forms; bisection for the peak)."""

    def ramp_s(dv):
        return (
            dv / a_mm_s2 + a_mm_s2 / j_mm_s3
            if dv >= a_mm_s2**2 / j_mm_s3
            else 2.0 * math.sqrt(dv / j_mm_s3)
        )

    def dist_mm(v):  # D(0 → v) = v T/2
        return v * ramp_s(v) / 2.0

    if 2.0 * dist_mm(v_mm_s) <= length_mm:
        return 2.0 * ramp_s(v_mm_s) + (length_mm - 2.0 * dist_mm(v_mm_s)) / v_mm_s
    peak = brentq(lambda v: 2.0 * dist_mm(v) - length_mm, 0.0, v_mm_s, xtol=1e-14, rtol=1e-15)
    return 2.0 * ramp_s(peak)


@pytest.mark.parametrize("j", [5e5, 5e4])
def test_long_line_bound_is_scurve_minus_jerk_ramps(j):
    # A long line's S-curve: T = L/V + T_ramp(V), T_ramp = V/A + A/J when A is reached
    # (V ≥ A²/J, J = 5e5) and 2√(V/J) otherwise (the default J = 5e4: A²/J = 120 > V). The
    # bound is L/V + V/A: below by exactly T_ramp − V/A.
    length = 10.0
    ramp = V / A + A / j if V >= A * A / j else 2.0 * math.sqrt(V / j)
    t_scurve = length / V + ramp
    assert scurve_rest_to_rest_s(length, V, A, j) == pytest.approx(t_scurve, rel=1e-14)
    lb = lower_bound_time_s([line(0.0, length)], V, **LIMITS)
    assert lb.time_s < t_scurve
    assert t_scurve - lb.time_s == pytest.approx(ramp - V / A, rel=1e-9)


@settings(max_examples=60, deadline=None)
@given(
    length=st.floats(1e-3, 50.0),
    v=st.floats(1.0, 200.0),
    a=st.floats(100.0, 1e4),
    j=st.floats(1e3, 1e6),
)
def test_bound_never_exceeds_a_jerk_limited_line(length, v, a, j):
    lb = lower_bound_time_s(
        [line(0.0, length)], v, a_max_mm_s2=a, period_s=TS, chord_tolerance_mm=DELTA, ds_mm=0.5
    )
    assert lb.time_s == pytest.approx(trapezoid_s(length, v, a), rel=1e-11)
    assert lb.time_s <= scurve_rest_to_rest_s(length, v, a, j) * (1 + 1e-12)


# --------------------------------------------------------------------------------------------
# The kernel against brute force: the O(n²) definition and the time integral by quad


def brute_v2(s, cap2, a):
    return np.min(cap2[None, :] + 2 * a * np.abs(s[:, None] - s[None, :]), axis=1)


def brute_time(s, path_cap2, point_cap2, a):
    """∫ ds / v, v²(x) = min(c(x), min_j point_cap²_j + 2A|x − s_j|), c = path cap² linear.

    Each grid interval is split at every pairwise crossing of all the lines involved (brute
    force), so the integrand is 1/√(linear) on each part, and integrated by quad.
    """
    total = 0.0
    for i in range(s.size - 1):
        h = s[i + 1] - s[i]
        if not h > 0.0:
            continue
        # Lines in the local coordinate x = s − s_i ∈ [0, h]: (slope, value at x = 0).
        # |s − s_j| = (s_i − s_j) + x for j ≤ i and (s_j − s_i) − x for j > i.
        j_lo, j_hi = slice(0, i + 1), slice(i + 1, None)
        slopes = np.concatenate(
            (
                np.full(i + 1, 2 * a),
                np.full(s.size - i - 1, -2 * a),
                [(path_cap2[i + 1] - path_cap2[i]) / h],
            )
        )
        at0 = np.concatenate(
            (
                point_cap2[j_lo] + 2 * a * (s[i] - s[j_lo]),
                point_cap2[j_hi] + 2 * a * (s[j_hi] - s[i]),
                [path_cap2[i]],
            )
        )

        def v2_at(x, slopes=slopes, at0=at0):
            return max(float(np.min(at0 + slopes * x)), 0.0)

        with np.errstate(divide="ignore", invalid="ignore"):
            cross = (at0[None, :] - at0[:, None]) / (slopes[:, None] - slopes[None, :])
        # (Crossings within rounding of an end are dropped: they would leave a sliver of a
        # piece whose ends both round to v = 0.)
        tol = 1e-12 * h
        cross = cross[np.isfinite(cross) & (cross > tol) & (cross < h - tol)]
        cuts = np.unique(np.concatenate(([0.0, h], cross)))
        for x0, x1 in zip(cuts[:-1], cuts[1:]):
            # v² is linear between cuts: v² = w0 cos²(θ/2) + w1 sin²(θ/2) with
            # x = x0 + (x1 − x0) sin²(θ/2), dx = (x1 − x0)/2 sin θ dθ; this removes the 1/√
            # singularity at a rest end and the cancellation of evaluating v² near it.
            w0, w1, half = v2_at(x0), v2_at(x1), 0.5 * (x1 - x0)

            def integrand(theta, w0=w0, w1=w1, half=half):
                c, s_ = math.cos(0.5 * theta), math.sin(0.5 * theta)
                return half * math.sin(theta) / math.sqrt(w0 * c * c + w1 * s_ * s_)

            total += quad(integrand, 0.0, math.pi, epsabs=0.0, epsrel=1e-11)[0]
    return total


@settings(max_examples=30, deadline=None)
@given(
    # Zero steps (duplicate points, as at junctions) or ≥ 1 µm: quad cannot resolve the
    # near-singular 1/v of a stop a few ulps beyond a grid point.
    steps=st.lists(st.just(0.0) | st.floats(1e-3, 2.0), min_size=1, max_size=12),
    caps=st.lists(st.floats(1.0, 80.0), min_size=13, max_size=13),
    stops=st.lists(st.booleans(), min_size=13, max_size=13),
    a=st.floats(50.0, 5000.0),
)
def test_kernel_matches_definition_and_quadrature(steps, caps, stops, a):
    s = np.concatenate(([0.0], np.cumsum(steps)))
    path_cap2 = np.square(caps[: s.size])
    # Rest at both ends and at random interior points (point constraints only).
    at_rest = np.array(stops[: s.size])
    at_rest[[0, -1]] = True
    cap2 = np.where(at_rest, 0.0, path_cap2)
    v2 = optimal_v2(s, cap2, a)
    np.testing.assert_allclose(v2, brute_v2(s, cap2, a), rtol=1e-12, atol=1e-9)
    # Feasible: under the cap, |Δv²| ≤ 2A Δs.
    assert np.all(v2 <= cap2 + 1e-9)
    assert np.all(np.abs(np.diff(v2)) <= 2 * a * np.diff(s) + 1e-9)
    dt = interval_times_s(s, v2, path_cap2, a)
    assert np.all(np.isfinite(dt)) and np.all(dt >= 0.0)
    assert dt.sum() == pytest.approx(brute_time(s, path_cap2, cap2, a), rel=1e-8, abs=1e-15)


def test_tiny_circle_runs_at_the_normal_acceleration_limit():
    # Radius 0.4 µm < δ: the chord error cannot exceed δ, so V_af is held at 2δ/T (never 0)
    # and √(A R) ≈ 0.99 mm/s governs: rest to rest, t = L/v + v/A exactly.
    r = 0.4e-3
    lb = lower_bound_time_s([circle(r)], V, **LIMITS)
    a = LIMITS["a_max_mm_s2"]
    v = math.sqrt(a * r)
    assert lb.time_s == pytest.approx(2 * math.pi * r / v + v / a, rel=1e-9)


@pytest.mark.parametrize(
    ("kwargs", "error"),
    [
        ({"a_max_mm_s2": 0.0}, ConfigError),
        ({"period_s": -1.0}, ConfigError),
        ({"chord_tolerance_mm": math.nan}, ConfigError),
        ({"ds_mm": 0.0}, ConfigError),
        ({"v_max_mm_s": 0.0}, ConfigError),
        ({"stop_after": [True, False, True]}, PlanningError),
    ],
)
def test_bad_inputs(kwargs, error):
    args = {**LIMITS, **kwargs}
    with pytest.raises(error):
        lower_bound_time_s([line(0.0, 1.0), line(1.0, 2.0)], V, **args)


def test_unbounded_speed_is_an_error():
    with pytest.raises(PlanningError, match="ceiling"):
        lower_bound_time_s([line(0.0, 1.0)], math.inf, **LIMITS)
    with pytest.raises(PlanningError, match="empty"):
        lower_bound_time_s([], V, **LIMITS)


def test_one_million_points_in_under_a_second():
    # A 10 m line at ds = 0.01 mm: 1e6 + 1 grid points, sampling included.
    # CPU time, not wall time: other test processes may share the machine.
    t0 = time.process_time()
    lb = lower_bound_time_s([line(0.0, 1e4)], V, **LIMITS)
    elapsed = time.process_time() - t0
    assert lb.s_mm.size == 1_000_001
    assert lb.time_s == pytest.approx(1e4 / V + V / A, rel=1e-10)
    assert elapsed < 1.0  # ~0.45 s measured


# --------------------------------------------------------------------------------------------
# The benchmark: the 9 mm NACA 2415 at F = 3500 mm/min (SPEC §9)


@pytest.fixture(scope="module")
def naca():
    prog = interpret_text((PROGRAMS / "naca2415.nc").read_text())
    (seg,) = [s for s in prog.segments if s.kind == "nurbs"]
    return NurbsCurve.from_segment(seg)


def test_naca_bound_converged_feasible_and_between_independent_bounds(naca):
    machine = load_machine()
    lb = machine_lower_bound([naca], V, machine)
    fine = machine_lower_bound([naca], V, machine, ds_mm=0.0025)
    assert fine.time_s == pytest.approx(lb.time_s, rel=1e-6)

    # Feasible profile.
    assert np.all(lb.v_mm_s <= lb.v_cap_mm_s * (1 + 1e-12))
    assert np.all(np.abs(np.diff(lb.v_mm_s**2)) <= 2 * A * np.diff(lb.s_mm) * (1 + 1e-9) + 1e-9)
    assert lb.length_mm == pytest.approx(naca.length_mm, rel=1e-12)
    # Sampled caps are the formula's: V_af(κ), √(A/κ), V at the grid points.
    kappa = naca.curvature(naca.param_at_length(lb.s_mm[1:-1]))
    cap = np.minimum(np.minimum(V, machine.chord_feed_mm_s(kappa)), np.sqrt(A / kappa))
    np.testing.assert_allclose(lb.v_cap_mm_s[1:-1], cap, rtol=1e-9)

    # Below: rest to rest on a straight path of the same length (|a| ≤ A, v ≤ V), and the
    # point-wise cap alone without tangential acceleration, ∫ ds / min(V, V_af, √(A/κ)) (quad).
    length = naca.length_mm
    assert lb.time_s > trapezoid_s(length, V)

    def inv_cap(u):
        k = naca.curvature(u)[0]
        v = min(V, machine.chord_feed_mm_s(k), math.sqrt(A / k) if k > 0 else math.inf)
        return naca.speed(u)[0] / v

    brk = naca.breakpoints
    no_tangential = sum(quad(inv_cap, a, b, epsrel=1e-10)[0] for a, b in zip(brk[:-1], brk[1:]))
    assert lb.time_s > no_tangential
    # Above: the paper's PH look-ahead (Table 4, jerk-limited and contour-error-limited).
    assert lb.time_s < 0.9455
    # Measured (for the record, SPEC §10): 0.35495 s.
    assert lb.time_s == pytest.approx(0.354955, abs=2e-6)


def test_spiral_arcs_start_coarse_and_give_the_fine_grid_bound(monkeypatch):
    """Arcs whose end radius differs from the start's (spirals: a CAM post's rounding, here
    up to 1e-3 mm over 2-20 mm radii; helical too) start on SPIRAL_DS_MM, not the 0.01 mm
    grid: the bound equals the fine grid's to 1e-9 relative."""
    from nurbscnc.plan import lowerbound

    rng = np.random.default_rng(11)
    lines = ["G21 G17 G90 G94", "G0 X0 Y0 Z0", "F2400"]
    x = 0.0
    for i in range(12):
        r = float(rng.uniform(2.0, 20.0))
        off = float(rng.uniform(-1e-3, 1e-3))
        z = f" Z{-0.5 * (i + 1):.4f}" if i % 3 == 0 else ""
        lines.append(f"G2 X{x + 2 * r + off:.6f} Y0{z} I{r:.6f} J0")
        x += 2 * r + off
        lines.append(f"G1 X{x + 1.0:.6f}")
        x += 1.0
    lines.append("M2")
    prog = interpret_text("\n".join(lines) + "\n")
    machine = load_machine()
    coarse = program_lower_bound_s(prog.segments, machine)
    monkeypatch.setattr(lowerbound, "SPIRAL_DS_MM", lowerbound.DEFAULT_DS_MM)
    fine = program_lower_bound_s(prog.segments, machine)
    assert coarse == pytest.approx(fine, rel=1e-9)
    from nurbscnc.geometry.paths import geometry_of

    arcs = [geometry_of(s) for s in prog.segments if s.kind == "arc"]
    assert sum(g.radius_end_mm != g.radius_start_mm for g in arcs) >= 10  # spirals, all but
    # the arcs whose end happened to round onto the circle


@pytest.mark.parametrize("name", ["naca2415.nc", "butterfly.nc"])
def test_program_bound_nurbs_start_grid_converged(name, monkeypatch):
    """A program's NURBS pieces start on PROGRAM_DS_MM (0.05 mm) in the summary's bound; the
    knots and the bisection make it equal to a 0.0025 mm start to 1e-7 relative (measured
    2.6e-8 on the NACA, 1.5e-9 on the butterfly)."""
    from nurbscnc.plan import lowerbound

    prog = interpret_text((PROGRAMS / name).read_text())
    machine = load_machine()
    coarse = program_lower_bound_s(prog.segments, machine)
    monkeypatch.setattr(lowerbound, "PROGRAM_DS_MM", 0.0025)
    fine = program_lower_bound_s(prog.segments, machine)
    assert coarse == pytest.approx(fine, rel=1e-7)
    assert coarse != fine  # the two grids differ: the comparison is not with itself


@pytest.mark.parametrize("mode", ["G64 P0.01", "G61"])
def test_program_bound_of_a_polyline_run_closed_form(mode):
    """A zig-zag polyline (corners of 0.1–6°) at one feed, then a feed change, a dwell and a
    second run: under G64 P the corners are passed (each run of constant cap is one piece
    of the bound, its inner junctions dropped), rest to rest per run: trapezoids of the
    runs' lengths, the feed change exactly at its junction (closed form below), each
    run shorter by what its corners' blends may cut (a corner of turning θ at most
    s = min(2P tan(θ/2), a + b − |AB|) for legs a, b; a line at most min(L, s_before +
    s_after)); under G61 every corner stops: a trapezoid per line."""
    rng = np.random.default_rng(4)
    lines, pts, x, y, heading = [f"G21 G17 G90 G94 {mode}", "G0 X0 Y0", "F1800"], [], 0.0, 0.0, 0.0
    runs = []
    for feed, n in ((1800.0, 400), (3000.0, 300)):
        steps, turns = [], []
        lines.append(f"F{feed:g}")
        for i in range(n):
            turn = float(rng.choice([-1.0, 1.0]) * rng.uniform(0.1, 6.0)) * math.pi / 180
            heading += turn
            if i:
                turns.append(abs(turn))
            step = float(rng.uniform(0.2, 1.0))
            x, y = x + step * math.cos(heading), y + step * math.sin(heading)
            lines.append(f"G1 X{x:.9f} Y{y:.9f}")
            pts.append((x, y))
            steps.append(step)
        a, b, theta = np.array(steps[:-1]), np.array(steps[1:]), np.array(turns)
        chord = np.sqrt(a * a + b * b + 2.0 * a * b * np.cos(theta))
        save = np.minimum(2.0 * 0.01 * np.tan(theta / 2.0), a + b - chord)
        around = np.r_[save, 0.0] + np.r_[0.0, save]
        runs.append((feed / 60.0, float(np.sum(np.array(steps) - np.minimum(steps, around)))))
        if len(runs) == 1:
            lines.append("G4 P0.5")
    lines.append("M2")
    prog = interpret_text("\n".join(lines) + "\n")
    machine = load_machine()
    got = program_lower_bound_s(prog.segments, machine)
    if mode == "G61":
        seg = np.diff(np.vstack(([0.0, 0.0], pts)), axis=0)
        step = np.hypot(seg[:, 0], seg[:, 1])
        feeds = np.r_[np.full(400, 30.0), np.full(300, min(50.0, V))]
        expected = sum(trapezoid_s(float(s), float(f)) for s, f in zip(step, feeds)) + 0.5
    else:
        expected = sum(trapezoid_s(length, min(v, V)) for v, length in runs) + 0.5
    # The rounded end points move the lengths by 1e-9 mm at most.
    assert got == pytest.approx(expected, rel=1e-9)


def test_program_bound_reuses_the_plans_own_curves_only():
    """The summary's bound takes a plan's NURBS curves (their arc-length tables built) where
    they are the programmed ones: the same bound to the last bit, the plan's curve objects
    in use; a curve the planner changed (an end hook removed) is not the program's and is
    ignored: the bound is then the programmed geometry's, not the changed curve's."""
    from nurbscnc.plan import lowerbound
    from nurbscnc.plan.program_pieces import segment_pieces

    machine = load_machine()
    prog = interpret_text((PROGRAMS / "naca2415.nc").read_text())
    curves = segment_pieces(prog.segments, machine).nurbs_curves()
    (i,) = [i for i, s in enumerate(prog.segments) if s.kind == "nurbs"]
    assert list(curves) == [i]
    assert lowerbound._programmed_geometry(prog.segments[i], curves[i]) is curves[i]
    plain = program_lower_bound_s(prog.segments, machine)
    assert program_lower_bound_s(prog.segments, machine, curves=curves) == plain
    # Another curve (the NACA's control points moved off by 0.1 mm) is refused.
    other = NurbsCurve(
        curves[i].degree, curves[i].knots, curves[i].control_points_mm + 0.1, curves[i].weights
    )
    assert lowerbound._programmed_geometry(prog.segments[i], other) is not other
    assert program_lower_bound_s(prog.segments, machine, curves={i: other}) == plain
