"""Servo model (SPEC §8): facts of Table 2's model, exact sampled simulation, contour errors.

Oracles: scipy.signal.lsim (linear interpolation of the input = FOH), cont2discrete + dlsim
(ZOH), scipy.signal.freqs (steady sinusoidal response), closed forms of eq. 28, and a brute-force
point-to-polyline distance.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from nurbscnc.errors import ConfigError
from nurbscnc.machine.profile import load_machine
from nurbscnc.servo.model import (
    SETTLE_TOLERANCE_MM,
    AxisModel,
    contour_error_eq29,
    contour_error_true,
    discretise,
    error_series,
    simulate_axes,
    simulate_axis,
)

T_S = 1e-3
V_MM_S = 58.3  # SPEC §8's example feed (≈ V_max = 3500 mm/min)
MACHINE = load_machine()
AXES = {"x": MACHINE.servo.x, "y": MACHINE.servo.y}


def _model(axis):
    return AxisModel.from_servo(AXES[axis])


def _equilibrium_state(A, B, u0):
    # x with A x + B u0 = 0: the model at rest with constant input u0.
    return -np.linalg.solve(A, B[:, 0] * u0)


# --- facts of the model (SPEC §8) ----------------------------------------------------------


def test_poles_x_match_spec_digits():
    p = _model("x").poles()
    real = np.sort(p[np.abs(p.imag) < 1e-9].real)
    cplx = p[p.imag > 1e-9]
    assert real.size == 2 and cplx.size == 1
    assert real[0] == pytest.approx(-315.0, abs=0.5)  # "−315"
    assert real[1] == pytest.approx(-93.7, abs=0.05)  # "−93.7"
    assert cplx[0].real == pytest.approx(-145.0, abs=0.5)  # "−145 ± 211j"
    assert cplx[0].imag == pytest.approx(211.0, abs=0.5)


def test_both_axes_stable_and_y_close_to_x():
    for axis in AXES:
        assert np.all(_model(axis).poles().real < 0.0)
    # Y is a slightly different drive: its poles are within 1.3 % of X's (SPEC prints X's).
    px = np.sort_complex(_model("x").poles())
    py = np.sort_complex(_model("y").poles())
    assert np.all(np.abs(py - px) / np.abs(px) < 0.013)


def test_dc_gain_is_one():
    for axis in AXES:
        m = _model(axis)
        assert m.dc_gain == 1.0
        for hold in ("foh", "zoh"):
            d = discretise(m, T_S, hold)
            # Σa = det(I − Φ) ≈ 1.4e-3 is the cancellation of coefficients of size 1 … 6: even
            # the discretisation by a 50-digit exponential (mpmath), rounded, is 6e-13 off
            # here; with scipy.linalg.expm's and with ours 5e-13 and 1.4e-12.
            assert d.b.sum() / d.a.sum() == pytest.approx(1.0, abs=4e-12)


def test_step_overshoot_and_resonance():
    # SPEC §8: step overshoot ≈ 37 %, resonance ≈ 33 Hz. ZOH of a unit step is exact.
    for axis in AXES:
        r = np.ones(30_000)
        r[0] = 0.0
        y = simulate_axis(_model(axis), r, 1e-5, hold="zoh", settle=False)
        assert y.max() - 1.0 == pytest.approx(0.37, abs=0.005)
        w = np.linspace(50.0, 500.0, 20_001)
        _, h = signal.freqs(AXES[axis].numerator, AXES[axis].denominator, w)
        assert w[np.argmax(np.abs(h))] / (2 * np.pi) == pytest.approx(33.0, abs=0.5)


def test_error_series_closed_forms():
    for a in AXES.values():
        c = error_series(a, order=3)
        c1 = (a.a1 - a.b1) / a.a0  # eq. 28 at s → 0 with a0 = b0: velocity lag
        c2 = ((a.a2 - a.b2) - c1 * a.a1) / a.a0
        assert c[0] == 0.0
        assert c[1] == pytest.approx(c1, rel=1e-14)
        assert c[2] == pytest.approx(c2, rel=1e-12)
        assert c1 == pytest.approx(0.32e-3, abs=0.005e-3)  # "≈ 0.32 ms"
        assert c2 + c1**2 / 2 == pytest.approx(2.85e-5, abs=0.005e-5)  # "≈ 2.85e−5 s²"
        # |G(jω)| = 1 + (c2 + c1²/2)ω² + O(ω⁴): check with scipy's frequency response
        # (relative O(ω²) remainder ≈ 2.6e−5·ω²: 7e−6 at ω = 0.5 rad/s)
        w = 0.5
        _, h = signal.freqs(a.numerator, a.denominator, [w])
        assert abs(h[0]) - 1.0 == pytest.approx((c2 + c1**2 / 2) * w**2, rel=1e-5)


# --- exact sampled simulation ----------------------------------------------------------------


@pytest.mark.parametrize("axis", ["x", "y"])
def test_foh_equals_lsim_random(axis):
    rng = np.random.default_rng(7)
    n = 1500
    r = 12.5 + np.cumsum(rng.normal(0.0, 0.05, n))  # a random walk starting away from 0
    t = np.arange(n) * T_S
    A, B, C, D = signal.tf2ss(AXES[axis].numerator, AXES[axis].denominator)
    _, y_ref, _ = signal.lsim((A, B, C, D), r, t, X0=_equilibrium_state(A, B, r[0]))
    y = simulate_axis(_model(axis), r, T_S, settle=False)
    assert y.shape == (n,)
    np.testing.assert_allclose(y, y_ref, rtol=0, atol=1e-9)


@pytest.mark.parametrize("axis", ["x", "y"])
def test_foh_equals_lsim_ramp(axis):
    n = 800
    t = np.arange(n) * T_S
    r = np.where(t < 0.1, 0.0, V_MM_S * (t - 0.1))
    _, y_ref, _ = signal.lsim((AXES[axis].numerator, AXES[axis].denominator), r, t)
    y = simulate_axis(AXES[axis], r, T_S, settle=False)
    np.testing.assert_allclose(y, y_ref, rtol=0, atol=1e-9)


@pytest.mark.parametrize("axis", ["x", "y"])
def test_zoh_equals_cont2discrete_dlsim(axis):
    rng = np.random.default_rng(11)
    n = 1000
    r = -3.0 + np.cumsum(rng.normal(0.0, 0.05, n))
    A, B, C, D = signal.tf2ss(AXES[axis].numerator, AXES[axis].denominator)
    Ad, Bd, Cd, Dd, _ = signal.cont2discrete((A, B, C, D), T_S, method="zoh")
    x0 = np.linalg.solve(np.eye(Ad.shape[0]) - Ad, Bd[:, 0] * r[0])
    _, y_ref, _ = signal.dlsim((Ad, Bd, Cd, Dd, T_S), r, x0=x0)
    y = simulate_axis(_model(axis), r, T_S, hold="zoh", settle=False)
    np.testing.assert_allclose(y, y_ref[:, 0], rtol=0, atol=1e-9)


@pytest.mark.parametrize("axis", ["x", "y"])
def test_ramp_lag(axis):
    # SPEC §8: velocity lag (a1 − b1)/a0 ≈ 0.32 ms, ≈ 18.7 um at 58.3 mm/s. FOH is exact for a
    # ramp, so after the transient (slowest pole 93 /s; e^(−93·0.5) ≈ 1e−20) the lag is exactly
    # eq. 28's final value V·(a1 − b1)/a0.
    a = AXES[axis]
    t = np.arange(500) * T_S
    r = V_MM_S * t
    lag = r - simulate_axis(a, r, T_S, settle=False)
    assert lag[-1] == pytest.approx(V_MM_S * (a.a1 - a.b1) / a.a0, abs=1e-9)
    assert lag[-1] * 1e3 == pytest.approx(18.7, abs=0.05)
    # A ZOH staircase lags T_s/2 more (SPEC §8); the residual is the 1 kHz ripple at the
    # sampling instants, attenuated by |G| ≈ 4e−3 there: < 0.01 um.
    lag_zoh = r - simulate_axis(a, r, T_S, hold="zoh", settle=False)
    assert lag_zoh[-1] - lag[-1] == pytest.approx(V_MM_S * T_S / 2, abs=1e-5)


def test_settle_appends_held_samples():
    a = AXES["x"]
    r = np.linspace(0.0, 20.0, 400)
    y = simulate_axis(a, r, T_S)  # settle=True
    assert y.size > r.size
    assert abs(y[-1] - 20.0) <= SETTLE_TOLERANCE_MM
    assert abs(y[-2] - 20.0) > SETTLE_TOLERANCE_MM  # no more samples than needed
    # the first N samples are the unsettled simulation, and the tail continues it exactly
    np.testing.assert_array_equal(y[: r.size], simulate_axis(a, r, T_S, settle=False))
    longer = simulate_axis(a, r, T_S, settle=y.size - r.size + 200)
    np.testing.assert_allclose(longer[: y.size], y, rtol=0, atol=1e-12)
    assert np.all(np.abs(longer[y.size - 1 :] - 20.0) <= SETTLE_TOLERANCE_MM)
    assert simulate_axis(None, r, T_S, settle=3).tolist() == r.tolist() + [20.0] * 3


def test_simulate_axes_common_length():
    n = 300
    t = np.arange(n) * T_S
    ref = np.column_stack([10 * np.sin(5 * t), 7 * np.cos(5 * t) - 7, t])
    out = simulate_axes([AXES["x"], AXES["y"], None], ref, T_S)
    extra = out.shape[0] - n
    assert extra > 0
    for j, a in enumerate([AXES["x"], AXES["y"]]):
        np.testing.assert_allclose(
            out[:, j], simulate_axis(a, ref[:, j], T_S, settle=extra), rtol=0, atol=1e-12
        )
        assert np.all(np.abs(out[-1, j] - ref[-1, j]) <= SETTLE_TOLERANCE_MM)
    np.testing.assert_array_equal(out[:n, 2], ref[:, 2])
    assert np.all(out[n:, 2] == ref[-1, 2])


def test_unstable_model_rejected():
    with pytest.raises(ConfigError, match="unstable"):
        AxisModel((1.0,), (1.0, -1.0))
    with pytest.raises(ConfigError, match="degree"):
        AxisModel((1.0, 0.0, 0.0), (1.0, 1.0))


# --- contour error on a steady circle (SPEC §8) ----------------------------------------------

R_MM = 10.0


@pytest.fixture(scope="module")
def circle():
    """Both axes on a CCW circle R = 10 mm at 58.3 mm/s, 1.6 s; steady part after 0.5 s."""
    w = V_MM_S / R_MM
    t = np.arange(1600) * T_S
    theta = w * t
    centre = np.array([3.0, -2.0])
    ref = centre + R_MM * np.column_stack([np.cos(theta), np.sin(theta)])
    act = simulate_axes([AXES["x"], AXES["y"]], ref, T_S, settle=False)
    steady = t >= 0.5
    return dict(w=w, t=t, theta=theta, centre=centre, ref=ref, act=act, steady=steady)


def test_circle_matches_frequency_response(circle):
    # Steady state at the samples: each axis gives |G(jω)|, ∠G(jω) (scipy.signal.freqs) applied
    # to the FOH input's fundamental, whose amplitude is R·sinc²(ωT/2) (linear interpolation =
    # convolution with a triangle). Aliased components are ~1e−8 mm after G.
    w, t, c = circle["w"], circle["t"], circle["centre"]
    foh = np.sinc(w * T_S / (2 * np.pi)) ** 2
    for j, (axis, trig) in enumerate([("x", np.cos), ("y", np.sin)]):
        _, h = signal.freqs(AXES[axis].numerator, AXES[axis].denominator, [w])
        expected = c[j] + R_MM * foh * np.abs(h[0]) * trig(w * t + np.angle(h[0]))
        s = circle["steady"]
        np.testing.assert_allclose(circle["act"][s, j], expected[s], rtol=0, atol=1e-7)


def test_circle_radial_error(circle):
    # SPEC §8: radial error ≈ 2.85e−5 s² × V²κ ≈ 9.7 um at R = 10 mm, 58.3 mm/s. With this
    # model the actual circle is LARGER (|G(jω)| > 1 below the 33 Hz resonance): the tool runs
    # outside by ≈ 9.7 um. Tolerance ±0.1 um covers the SPEC's 2-3 printed digits, the X/Y
    # model difference (0.016 um) and the FOH chord cut R(ωT)²/12 ≈ 0.03 um.
    s = circle["steady"]
    radius = np.linalg.norm(circle["act"][s] - circle["centre"], axis=1)
    outward_um = (radius - R_MM) * 1e3
    expected_um = 2.85e-5 * V_MM_S**2 / R_MM * 1e3
    assert expected_um == pytest.approx(9.7, abs=0.05)
    assert np.all(np.abs(outward_um - expected_um) <= 0.1)


def test_eq29_agrees_with_true_distance_on_circle(circle):
    s = circle["steady"]
    err = circle["ref"] - circle["act"]  # E = R − Y (eq. 26)
    phi = circle["theta"] + np.pi / 2  # tangent angle of the CCW circle
    eps = contour_error_eq29(err[s, 0], err[s, 1], phi[s])
    # dense commanded path: 40 000 chords, sagitta R(2π/40000)²/8 ≈ 3e−8 mm
    u = np.linspace(0.0, 2 * np.pi, 40_001)
    path = circle["centre"] + R_MM * np.column_stack([np.cos(u), np.sin(u)])
    true = contour_error_true(circle["act"][s], path)
    # eq. 29 is signed: positive = right of the direction of travel = outside this circle
    assert np.all(eps > 0)
    # The 18.7 um lag along the path moves the projection by ≈ lag²/(2R) ≈ 0.02 um.
    assert np.max(np.abs(eps - true)) <= 0.1e-3
    assert np.mean(true) * 1e3 == pytest.approx(9.7, abs=0.1)


# --- contour error helpers -----------------------------------------------------------------


def test_eq29_values():
    assert contour_error_eq29(0.0, 2.0, 0.0) == 2.0
    assert contour_error_eq29(2.0, 0.0, np.pi / 2) == pytest.approx(-2.0, rel=1e-15)
    ex, ey, phi = np.array([1.0, 3.0]), np.array([0.5, -1.0]), np.array([0.3, -2.0])
    np.testing.assert_allclose(
        contour_error_eq29(ex, ey, phi), ey * np.cos(phi) - ex * np.sin(phi), rtol=1e-15
    )


def _brute_force_distance(points, path):
    a = path[:-1][None]
    d = np.diff(path, axis=0)[None]
    len2 = np.sum(d * d, axis=-1)
    t = np.sum((points[:, None] - a) * d, axis=-1) / np.where(len2 > 0, len2, 1.0)
    t = np.clip(np.where(len2 > 0, t, 0.0), 0.0, 1.0)
    return np.min(np.linalg.norm(points[:, None] - (a + t[..., None] * d), axis=-1), axis=1)


@pytest.mark.parametrize("dim", [2, 3])
def test_true_distance_is_exact(dim):
    rng = np.random.default_rng(dim)
    # uneven polyline: many short steps, one very long segment, repeated (degenerate) points
    steps = rng.normal(0.0, 0.05, (400, dim))
    steps[150] = 40.0
    steps[[10, 11, 300]] = 0.0
    path = np.cumsum(steps, axis=0)
    lo, hi = path.min(axis=0) - 2.0, path.max(axis=0) + 2.0
    points = rng.uniform(lo, hi, (2000, dim))
    points[:50] = path[rng.integers(0, 400, 50)] + rng.normal(0, 1e-4, (50, dim))
    got = contour_error_true(points, path, k_initial=2)
    np.testing.assert_allclose(got, _brute_force_distance(points, path), rtol=0, atol=1e-12)


def test_true_distance_small_cases():
    path = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    assert contour_error_true(np.array([0.5, 2.0, 0.0]), path) == 2.0
    assert contour_error_true(np.array([[3.0, 4.0, 0.0]]), path[:1]).tolist() == [5.0]
    assert contour_error_true(np.array([[-3.0, 4.0, 0.0]]), path).tolist() == [5.0]


@pytest.mark.parametrize("hold", ["foh", "zoh"])
@pytest.mark.parametrize("axis", ["x", "y"])
def test_discretisation_and_filter_are_scipy_signal_bit_for_bit(axis, hold):
    """The model's own tf2ss gives scipy.signal's state space to the bit; its H(z) is
    scipy.signal's ss2tf of the exact discrete state space by scipy.linalg.expm to 1e-12
    (the exponentials differ by scipy's own error, 7e-12 of an entry, test below; the
    coefficients by 4e-14); its filter (scipy's compiled loop, loaded without scipy.signal)
    is lfilter's: same output and final state, carried across a split."""
    from nurbscnc.servo import model as servo_model

    ax = getattr(MACHINE.servo, axis)
    ours = servo_model._tf2ss(ax.numerator, ax.denominator)
    for got, want in zip(ours, signal.tf2ss(ax.numerator, ax.denominator)):
        assert got.shape == want.shape
        np.testing.assert_array_equal(got, want)
    disc = discretise(ax, MACHINE.servo.period_s, hold)
    # H(z) by scipy.signal from the same exact discrete state space (module doc of
    # nurbscnc.servo.model): ours must be these numbers.
    from scipy import linalg

    A, B, C, D = signal.tf2ss(ax.numerator, ax.denominator)
    n, t = A.shape[0], MACHINE.servo.period_s
    M = np.zeros((n + 2, n + 2))
    M[:n, :n], M[:n, n : n + 1], M[n, n + 1] = A * t, B * t, 1.0
    E = linalg.expm(M if hold == "foh" else M[: n + 1, : n + 1])
    phi, g1 = E[:n, :n], E[:n, n : n + 1]
    if hold == "foh":
        g2 = E[:n, n + 1 : n + 2]
        num, den = signal.ss2tf(phi, g1 + phi @ g2 - g2, C, D + C @ g2)
    else:
        num, den = signal.ss2tf(phi, g1, C, D)
    np.testing.assert_allclose(disc.b, np.ravel(num) / den[0], rtol=1e-12, atol=0.0)
    np.testing.assert_allclose(disc.a, den / den[0], rtol=1e-12, atol=0.0)
    x = np.random.default_rng(3).normal(size=5000).cumsum()
    zi = np.zeros(disc.a.size - 1)
    want_y, want_z = signal.lfilter(disc.b, disc.a, x, zi=zi)
    y1, z1 = servo_model._lfilter(disc.b, disc.a, x[:1234], zi)
    y2, z2 = servo_model._lfilter(disc.b, disc.a, x[1234:], z1)
    np.testing.assert_array_equal(np.concatenate((y1, y2)), want_y)
    np.testing.assert_array_equal(z2, want_z)


def test_the_small_exponential_against_closed_forms_and_scipy():
    """servo.model.expm_small (numpy only, balanced, scaled and squared Taylor): closed
    forms of a rotation, a Jordan block and a diagonal, the Jordan block badly scaled by a
    diagonal similarity (1e-4 … 1e6: e^(DJD⁻¹) = D e^J D⁻¹) to 1e-14 of each entry; and the
    FOH matrices of the machine's axes against scipy.linalg.expm to 1e-10 (scipy's error
    there is 7e-12 against a 50-digit evaluation, ours 1e-15)."""
    from scipy import linalg

    from nurbscnc.servo.model import _tf2ss, expm_small

    w, lam = 0.7, -0.3
    rot = np.array([[0.0, -w], [w, 0.0]])
    np.testing.assert_allclose(
        expm_small(rot), [[np.cos(w), -np.sin(w)], [np.sin(w), np.cos(w)]], rtol=0, atol=1e-15
    )
    jordan = np.array([[lam, 1.0, 0.0], [0.0, lam, 1.0], [0.0, 0.0, lam]])
    want_j = np.exp(lam) * np.array([[1.0, 1.0, 0.5], [0.0, 1.0, 1.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(expm_small(jordan), want_j, rtol=0, atol=1e-15)
    diag = np.diag([-3.0, 0.5, 0.0])
    np.testing.assert_allclose(
        expm_small(diag), np.diag(np.exp([-3.0, 0.5, 0.0])), rtol=1e-14, atol=0
    )
    d = np.array([1e-4, 3e2, 1e6])
    scaled = d[:, None] * jordan / d[None, :]
    want_s = d[:, None] * want_j / d[None, :]
    assert np.all(np.abs(expm_small(scaled) - want_s) <= 1e-14 * np.abs(want_s))
    for axis in (MACHINE.servo.x, MACHINE.servo.y):
        a, b, _, _ = _tf2ss(axis.numerator, axis.denominator)
        n, t = a.shape[0], MACHINE.servo.period_s
        m = np.zeros((n + 2, n + 2))
        m[:n, :n], m[:n, n : n + 1], m[n, n + 1] = a * t, b * t, 1.0
        want = linalg.expm(m)
        assert np.all(np.abs(expm_small(m) - want) <= 1e-10 * np.abs(want))
