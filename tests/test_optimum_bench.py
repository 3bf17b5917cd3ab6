"""The building blocks of the jerk-limited optimum (bench/optimum.py) against closed forms.

Not timing tests: they check that the benchmark anchor of issue 13 computes what it claims
(the S-curve time on a line, the feed √(A r) on a circle, the servo's steady-state radial
error, the exact time law), so a ratio against it means something.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

import optimum  # noqa: E402

from nurbscnc.machine.profile import load_machine  # noqa: E402

V_MM_S, A_MM_S2, J_MM_S3 = 3500.0 / 60.0, 2450.0, 5.0e4


def _scurve_rest_to_rest_s(length_mm, v, a, j):
    """Rest → v → rest on a line long enough to cruise (SPEC §7): each transition takes
    v/A + A/J when A is reached (v ≥ A²/J), else 2√(v/J), and covers v·T/2."""
    t_tr = v / a + a / j if v * j >= a * a else 2.0 * math.sqrt(v / j)
    return length_mm / v + t_tr


@pytest.mark.parametrize(("a", "j"), [(A_MM_S2, J_MM_S3), (500.0, J_MM_S3)])
def test_line_profile_matches_scurve_time(a, j):
    """A 20 mm line: the LP's time approaches the closed-form S-curve time from below (the
    jerk is bounded between grid intervals), within 0.05 % on 2000 intervals, and its peak
    acceleration is the S-curve's, min(A, √(V J))."""
    s = np.linspace(0.0, 20.0, 2001)
    prof = optimum.jerk_limited_profile(s, np.full(s.size, V_MM_S**2), a, j)
    exact = _scurve_rest_to_rest_s(20.0, V_MM_S, a, j)
    assert exact * (1 - 1e-3) <= prof.time_s <= exact * (1 + 1e-6)
    assert prof.time_s <= exact * (1 + 1e-6)
    peak = min(a, math.sqrt(V_MM_S * j))
    assert np.abs(prof.accel_mm_s2()).max() == pytest.approx(peak, rel=5e-3)
    assert np.abs(prof.jerk_mm_s3()).max() <= j * 1.002


def test_line_without_jerk_is_the_trapezoid():
    """No jerk limit: one LP, the trapezoid L/V + V/A exactly (constant acceleration is exact
    in the time law) when the ends of the ramps, at V²/2A = 0.5 mm from the ends, are grid
    points."""
    a = V_MM_S**2 / (2.0 * 0.5)
    s = np.linspace(0.0, 20.0, 401)
    prof = optimum.jerk_limited_profile(s, np.full(s.size, V_MM_S**2), a, None)
    assert prof.time_s == pytest.approx(20.0 / V_MM_S + V_MM_S / a, rel=1e-9)


def test_time_law_samples_constant_acceleration_exactly():
    """v² = 2 a s is constant acceleration from rest: s(kT) = a (kT)² / 2 at every sample."""
    a = 1000.0
    s = np.linspace(0.0, 2.0, 57)
    prof = optimum.Profile(s, 2.0 * a * s)
    samples = prof.sample_s_mm(1e-3)
    t = np.arange(samples.size) * 1e-3
    assert prof.time_s == pytest.approx(math.sqrt(2.0 * 2.0 / a), rel=1e-12)
    np.testing.assert_allclose(samples[:-1], 0.5 * a * t[:-1] ** 2, rtol=0, atol=1e-12)
    assert samples[-1] == 2.0


def _circle_program(radius_mm: float) -> str:
    """A full circle as an exact rational quadratic G6.2 NURBS (9 control points, weights
    1, √2/2 alternating; knots 0,0,0,¼,¼,½,½,¾,¾,1,1,1) at F3500, centred at the origin."""
    r, w = radius_mm, math.sqrt(0.5)
    pts = [(r, 0), (r, r), (0, r), (-r, r), (-r, 0), (-r, -r), (0, -r), (r, -r), (r, 0)]
    knots = [0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1]
    lines = ["G21 G17 G90 G94", f"G0 X{r} Y0", "F3500"]
    for i, (x, y) in enumerate(pts):
        head = "G6.2 P3 " if i == 0 else ""
        lines.append(f"{head}K{knots[i]} X{x} Y{y} R{1.0 if i % 2 == 0 else w}")
    lines += [f"K{k}" for k in knots[len(pts) :]]
    return "\n".join(lines + ["M2"]) + "\n"


def test_circle_curvature_length_and_feed(tmp_path):
    """On a circle of radius r = 1 mm: arc length 2πr, κ = 1/r, and the feed the kinematic
    optimum holds around it is √(A r) (below V_max and the chord feed V_af(1/r) = 89 mm/s);
    the rest-to-rest time is the S-curve formula on that cruise."""
    program = tmp_path / "circle.nc"
    program.write_text(_circle_program(1.0))
    block = optimum.load_block(program, load_machine(), min_knots=1200)
    assert block.curve.length_mm == pytest.approx(2.0 * math.pi, rel=1e-9)
    np.testing.assert_allclose(block.curve.kappa_at(block.s_mm[1:-1]), 1.0, rtol=1e-9)
    feed = math.sqrt(A_MM_S2 * 1.0)
    np.testing.assert_allclose(np.sqrt(block.cap2_mm2_s2), feed, rtol=1e-12)
    prof = optimum.jerk_limited_profile(block.s_mm, block.cap2_mm2_s2, A_MM_S2, J_MM_S3)
    ramp_mm = feed * math.sqrt(feed / J_MM_S3)  # v·T/2 with T = 2√(v/J): 1.56 mm
    middle = (block.s_mm > ramp_mm + 0.05) & (block.s_mm < 2.0 * math.pi - ramp_mm - 0.05)
    assert middle.sum() > 200
    np.testing.assert_allclose(prof.v_mm_s[middle], feed, rtol=1e-9)
    exact = _scurve_rest_to_rest_s(2.0 * math.pi, feed, A_MM_S2, J_MM_S3)
    assert exact * (1 - 1e-3) <= prof.time_s <= exact * (1 + 1e-6)


def test_servo_steady_circle_radial_error():
    """The servo of SPEC Table 2 on a circle of radius R at speed v (ω = v/R): in steady state
    each axis is its sinusoid times H G(jω), x = R·Re(H G_x(jω) e^{jωt}), y = R·Re(−j H
    G_y(jω) e^{jωt}), H = sinc²(ωT/2) the first-order hold's gain at ω (linear interpolation
    of the 1 ms samples; its images near 1 kHz are filtered out); the transient (slowest pole
    93.7/s) is gone after 2 s: equal within 0.1 nm (the images). The tool runs outside the
    path by ≈ 9.7 µm (SPEC §8). The convolution equals scipy.signal.lsim."""
    machine = load_machine()
    servo = optimum.Servo(machine)
    radius_mm, speed_mm_s = 10.0, V_MM_S
    omega = speed_mm_s / radius_mm
    t = np.arange(0.0, 3.0, 1e-3)
    ref = np.column_stack(
        [radius_mm * np.cos(omega * t), radius_mm * np.sin(omega * t), np.zeros_like(t)]
    )
    tool = servo.tool_mm(ref, settle_s=0.0)

    def response(name):
        ax = machine.servo.axis(name)
        num = np.polyval([ax.b2, ax.b1, ax.b0], 1j * omega)
        den = np.polyval([ax.a4, ax.a3, ax.a2, ax.a1, ax.a0], 1j * omega)
        return num / den

    hold = (math.sin(omega * 5e-4) / (omega * 5e-4)) ** 2
    phasor = hold * np.exp(1j * omega * t[-1000:])
    np.testing.assert_allclose(
        tool[-1000:, 0], radius_mm * np.real(response("x") * phasor), rtol=0, atol=1e-7
    )
    np.testing.assert_allclose(
        tool[-1000:, 1], radius_mm * np.real(-1j * response("y") * phasor), rtol=0, atol=1e-7
    )
    radial_um = (np.hypot(tool[-1000:, 0], tool[-1000:, 1]) - radius_mm) * 1e3
    assert radial_um.mean() == pytest.approx(9.7, abs=0.1)
    import contour

    np.testing.assert_allclose(tool, contour.simulate_tool_mm(ref, settle_s=0.0), atol=1e-9)


def test_generated_airfoils_are_reproducible():
    """The committed generated airfoil programs are what bench/optimum.py writes."""
    for case in optimum.CASES:
        if case.naca:
            text = (ROOT / case.program).read_text()
            assert text == optimum.airfoil_program(case.naca, case.chord_mm)
            assert f"NACA {case.naca}, chord {case.chord_mm:g} mm" in text
