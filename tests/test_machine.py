"""Machine profile: defaults = the paper's Tables 2 and 3, validation, derived feed formulas."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nurbscnc.errors import ConfigError, OutputError
from nurbscnc.machine.caps import chord_feed_mm_s, curvature_feed_mm_s, kappa_threshold_per_mm
from nurbscnc.machine.profile import (
    Machine,
    default_profile_text,
    load_machine,
    parse_machine,
)

# SPEC §8 Table 2 (paper Table 2), transcribed independently of the TOML file.
TABLE2 = {
    "x": dict(
        a0=1.938e9, a1=3.538e7, a2=2.135e5, a3=6.984e2, a4=1.0, b0=1.938e9, b1=3.476e7, b2=1.471e5
    ),
    "y": dict(
        a0=1.904e9, a1=3.496e7, a2=2.120e5, a3=6.948e2, a4=1.0, b0=1.904e9, b1=3.435e7, b2=1.466e5
    ),
}


@pytest.fixture(scope="module")
def machine() -> Machine:
    return load_machine()


def test_defaults_are_table3(machine):
    lim = machine.limits
    assert lim.v_max_mm_s == 3500.0 / 60.0
    assert lim.rapid_mm_s == lim.v_max_mm_s  # no rapid rate in the paper: rapids at V_max
    assert lim.a_max_mm_s2 == 2450.0
    assert lim.j_max_mm_s3 == 5e4
    assert lim.chord_tolerance_mm == pytest.approx(1e-3, rel=1e-15)
    assert lim.kappa_ref_per_mm == 1.0
    assert lim.contour_tolerance_mm == pytest.approx(15e-3, rel=1e-15)
    assert lim.ph_tolerance_mm == pytest.approx(1e-3, rel=1e-15)
    assert machine.servo.period_s == pytest.approx(1e-3, rel=1e-15)


def test_defaults_are_table2(machine):
    for axis, coeffs in TABLE2.items():
        model = machine.servo.axis(axis)
        for name, value in coeffs.items():
            assert getattr(model, name) == value, (axis, name)
        assert model.dc_gain == 1.0
    assert machine.servo.z is None


def test_defaults_steps_and_soft_limits(machine):
    assert machine.steps.per_mm == (1000.0, 1000.0, 1000.0)
    assert machine.steps.max_pulses_per_period == 127
    assert machine.soft_limits.min_mm == (-1000.0,) * 3
    assert machine.soft_limits.max_mm == (1000.0,) * 3
    inside = machine.soft_limits.inside([[0, 0, 0], [1000, -1000, 0], [1000.001, 0, 0]])
    assert inside.tolist() == [True, True, False]


def test_parse_text_and_file_agree(machine, tmp_path):
    path = tmp_path / "m.toml"
    path.write_text(default_profile_text())
    from_file = load_machine(str(path))
    from_text = parse_machine(default_profile_text(), "x")
    for m in (from_file, from_text):
        assert (m.limits, m.servo, m.steps, m.soft_limits) == (
            machine.limits,
            machine.servo,
            machine.steps,
            machine.soft_limits,
        )
    assert from_file.source == str(path)


def test_missing_file_is_output_error(tmp_path):
    with pytest.raises(OutputError, match="nope.toml"):
        load_machine(str(tmp_path / "nope.toml"))


def test_overrides():
    m = load_machine(
        overrides={
            "limits.a_max_mm_s2": 1000,
            "limits.j_max_mm_s3": "2e4",
            "limits.rapid_mm_min": 6000.0,
            "servo.period_ms": 0.5,
        }
    )
    assert m.limits.a_max_mm_s2 == 1000.0
    assert m.limits.j_max_mm_s3 == 2e4
    assert m.limits.rapid_mm_s == 100.0
    assert m.servo.period_s == 0.5e-3
    # a full z model through overrides
    z = {f"servo.z.{k}": v for k, v in TABLE2["x"].items()}
    assert load_machine(overrides=z).servo.z == load_machine().servo.x


# Each invalid-value class: (overrides, key the message must name, words in the message).
BAD_OVERRIDES = [
    ({"limits.a_max_mm_s2": -5}, "limits.a_max_mm_s2", "must be > 0, got -5"),
    ({"limits.v_max_mm_min": 0}, "limits.v_max_mm_min", "must be > 0"),
    ({"limits.j_max_mm_s3": math.nan}, "limits.j_max_mm_s3", "finite"),
    ({"limits.chord_tolerance_um": math.inf}, "limits.chord_tolerance_um", "finite"),
    ({"servo.period_ms": "fast"}, "servo.period_ms", "not a value"),
    ({"servo.period_ms": "'fast'"}, "servo.period_ms", "must be a number"),
    ({"limits.kappa_ref_per_mm": True}, "limits.kappa_ref_per_mm", "must be a number"),
    ({"steps.max_pulses_per_period": 12.5}, "steps.max_pulses_per_period", "integer"),
    ({"steps.max_pulses_per_period": 0}, "steps.max_pulses_per_period", ">= 1"),
    ({"steps.max_pulses_per_period": 50}, "steps.max_pulses_per_period", "too small"),
    ({"limits.rapid_mm_min": 9000}, "steps.max_pulses_per_period", "too small"),
    ({"steps.per_mm.y": -1000}, "steps.per_mm.y", "> 0"),
    ({"soft_limits.x.min_mm": 5.0, "soft_limits.x.max_mm": 5.0}, "soft_limits.x.min_mm", "<"),
    ({"soft_limits.z.max_mm": -2000.0}, "soft_limits.z.min_mm", "<"),
    # all coefficients positive, yet not Hurwitz: a3·a2·a1 < a1² + a3²·a0 for this a0
    ({"servo.x.a0": 1e13}, "servo.x", "unstable"),
    ({"servo.y.a1": -3.496e7}, "servo.y", "unstable"),
    ({"servo.y.b0": 0.0}, "servo.y.b0", "> 0"),
    ({"servo.z.a0": 1.0}, "servo.z.a1", "missing"),
    ({"limits.v_max": 1.0}, "limits.v_max", "unknown"),
    ({"servo.x": 1.0}, "servo.x", "table"),
]


@pytest.mark.parametrize(("overrides", "key", "words"), BAD_OVERRIDES)
def test_invalid_values_name_the_key(overrides, key, words):
    with pytest.raises(ConfigError) as info:
        load_machine(overrides=overrides)
    assert key in info.value.message
    assert words in info.value.message


def _edit(old: str, new: str) -> str:
    text = default_profile_text()
    assert old in text
    return text.replace(old, new, 1)


BAD_TEXTS = [
    (_edit("a_max_mm_s2 = 2450.0", 'a_max_mm_s2 = "2450"'), "limits.a_max_mm_s2", "number"),
    (_edit("a_max_mm_s2 = 2450.0", "a_max_mm_s2 = nan"), "limits.a_max_mm_s2", "finite"),
    (_edit("a_max_mm_s2 = 2450.0", "a_max_mm_s2 = -inf"), "limits.a_max_mm_s2", "finite"),
    (_edit("a_max_mm_s2 = 2450.0\n", ""), "limits.a_max_mm_s2", "missing"),
    (_edit("b2 = 1.466e5\n", ""), "servo.y.b2", "missing"),
    (_edit("[servo.y]", "[servo.w]"), "servo.w", "not a known key"),
    (_edit("x = 1000.0", "x = 1000.0\nq = 3.0"), "steps.per_mm.q", "not a known key"),
    (_edit("[limits]", "[limit]"), "limit", "not a known key"),
    (_edit("period_ms = 1.0", "period_ms = [1.0]"), "servo.period_ms", "number"),
    ("limits = 3\n", "limits", "must be a table"),
]


@pytest.mark.parametrize(("text", "key", "words"), BAD_TEXTS)
def test_invalid_files_name_the_key(text, key, words):
    with pytest.raises(ConfigError) as info:
        parse_machine(text, "bad.toml")
    assert info.value.message.startswith("bad.toml: ")
    assert key in info.value.message
    assert words in info.value.message


def test_toml_syntax_error_has_line():
    text = _edit("j_max_mm_s3 = 5.0e4", "j_max_mm_s3 = = 5.0e4")
    line = text.splitlines().index("j_max_mm_s3 = = 5.0e4") + 1
    with pytest.raises(ConfigError, match=rf"bad.toml: invalid TOML: .*line {line}\b"):
        parse_machine(text, "bad.toml")


def test_overridden_key_is_marked():
    with pytest.raises(ConfigError, match=r"set by override"):
        load_machine(overrides={"limits.a_max_mm_s2": -1.0})


# --- derived feed formulas (SPEC §5 and §7) ------------------------------------------------


def test_kappa_threshold(machine):
    f = 3500.0 / 60.0
    assert machine.kappa_threshold_per_mm(f) == pytest.approx(2450.0 / f**2, rel=1e-15)
    out = kappa_threshold_per_mm(np.array([0.0, 10.0, -1.0]), 2450.0)
    assert out[0] == math.inf and out[2] == math.inf
    assert out[1] == pytest.approx(24.5, rel=1e-15)


def _chord_feed_geometry(kappa, period_s, delta):
    # Independent derivation: on a circle of radius R the chord whose sagitta is δ has half
    # length √(R² − (R − δ)²); the feed covers one such chord per period.
    r = 1.0 / kappa
    return 2.0 * math.sqrt(r * r - (r - delta) ** 2) / period_s


def test_chord_feed_closed_form(machine):
    for kappa in (1e-3, 0.1, 1.0, 10.0, 1000.0):
        expected = _chord_feed_geometry(kappa, 1e-3, 1e-3)
        assert machine.chord_feed_mm_s(kappa) == pytest.approx(expected, rel=1e-9)
        assert machine.chord_feed_mm_s(-kappa) == machine.chord_feed_mm_s(kappa)
    # R = 10 mm: V_af = 2000·√(0.02 − 1e-6) mm/s
    assert machine.chord_feed_mm_s(0.1) == pytest.approx(2000.0 * math.sqrt(0.019999), rel=1e-14)


def test_chord_feed_edges_never_nan():
    k = np.array([0.0, 2.0 / 1e-3, 3.0 / 1e-3, np.inf, 1e-300, 1.999 / 1e-3])
    v = chord_feed_mm_s(k, 1e-3, 1e-3)
    assert isinstance(v, np.ndarray) and v.shape == k.shape
    assert not np.any(np.isnan(v))
    # Radius ≤ δ: held at the radius-δ value 2δ/T (never 0: the chord error is at most the
    # radius there), continuous with the formula at radius δ.
    floor = 2.0 * 1e-3 / 1e-3
    assert v[0] == np.inf and v[1] == v[2] == v[3] == floor and v[5] == floor
    assert v[4] > 1e140
    assert chord_feed_mm_s(1.0 / 1e-3 * (1 - 1e-12), 1e-3, 1e-3) == pytest.approx(floor)
    assert isinstance(chord_feed_mm_s(0.5, 1e-3, 1e-3), float)


@settings(max_examples=60, deadline=None)
@given(st.floats(min_value=1e-4, max_value=1.0), st.floats(min_value=1e-4, max_value=1e-2))
def test_chord_feed_has_sagitta_delta(kappa_delta, delta):
    # The chord covered in one period deviates from the circle by exactly δ (for radius ≥ δ,
    # i.e. κ ≤ 1/δ, where the chord cuts off the minor arc).
    kappa = kappa_delta / delta
    half_chord = chord_feed_mm_s(kappa, 1e-3, delta) * 1e-3 / 2.0
    r = 1.0 / kappa
    sagitta = r - math.sqrt(max(r * r - half_chord * half_chord, 0.0))
    assert sagitta == pytest.approx(delta, rel=1e-6)


def test_curvature_feed(machine):
    v = machine.limits.v_max_mm_s
    assert machine.curvature_feed_mm_s(0.0) == v
    assert machine.curvature_feed_mm_s(1.0) == pytest.approx(v / 2.0, rel=1e-15)
    assert machine.curvature_feed_mm_s(3.0, feed_mm_s=20.0) == pytest.approx(5.0, rel=1e-15)
    out = curvature_feed_mm_s(np.array([np.inf, -1.0, 9.0]), 40.0, 1.0)
    np.testing.assert_allclose(out, [0.0, 20.0, 4.0], rtol=1e-15)


def test_corner_feed_is_the_minimum(machine):
    k = np.array([0.01, 1.0, 10.0, 100.0])
    expected = np.minimum(machine.chord_feed_mm_s(k), machine.curvature_feed_mm_s(k))
    np.testing.assert_array_equal(machine.corner_feed_mm_s(k), expected)
    # Table 3 machine at κ = 10 /mm: V_cf = 58.33/11 = 5.30 mm/s < V_af = 28.2 mm/s.
    assert machine.corner_feed_mm_s(10.0) == pytest.approx(3500.0 / 60.0 / 11.0, rel=1e-15)
    # δ = 0.01 um: V_af = 2000·√(2e-6 − 1e-10) = 2.83 mm/s governs.
    fine = load_machine(overrides={"limits.chord_tolerance_um": 0.01})
    assert fine.corner_feed_mm_s(10.0) == pytest.approx(2000.0 * math.sqrt(2e-6 - 1e-10), rel=1e-9)


# --- optional and simple servo models (issue 16) --------------------------------------------

from scipy import signal  # noqa: E402

from nurbscnc.machine.discovery import (  # noqa: E402
    FOUND_BY_DEFAULT,
    FOUND_BY_ENV,
    FOUND_BY_LOCAL,
    FOUND_BY_OPTION,
    FOUND_BY_USER,
    find_machine,
)
from nurbscnc.machine.model import AxisServo, natural_frequency_rad_s  # noqa: E402
from nurbscnc.machine.show import profile_toml  # noqa: E402


def _without_servo_axes(text: str) -> str:
    """The default profile with its [servo.x] and [servo.y] tables removed."""
    out, skip = [], False
    for line in text.splitlines():
        if line.startswith("["):
            skip = line in ("[servo.x]", "[servo.y]")
        if not skip:
            out.append(line)
    return "\n".join(out) + "\n"


@pytest.mark.parametrize("zeta", [0.1, 0.3, 0.5, 1 / math.sqrt(2), 0.9, 1.0, 1.5, 2.0])
@pytest.mark.parametrize("f_bw", [5.0, 40.0, 120.0])
def test_simple_form_bandwidth_is_minus_3_db(zeta, f_bw):
    # The closed form for ω_n against scipy.signal.freqs of the plain 2nd-order G(s).
    wn = natural_frequency_rad_s(f_bw, zeta)
    _, h = signal.freqs([wn * wn], [1.0, 2.0 * zeta * wn, wn * wn], worN=[2 * math.pi * f_bw])
    assert abs(h[0]) == pytest.approx(1 / math.sqrt(2), rel=1e-12)
    # ... and it is the only crossing: above f_bw the gain stays below 1/√2.
    _, h = signal.freqs(
        [wn * wn],
        [1.0, 2.0 * zeta * wn, wn * wn],
        worN=2 * math.pi * f_bw * np.linspace(1.001, 50, 400),
    )
    assert np.all(np.abs(h) < 1 / math.sqrt(2))


def test_simple_form_at_butterworth_damping_has_wn_equal_bandwidth():
    assert natural_frequency_rad_s(25.0, 1 / math.sqrt(2)) == pytest.approx(
        2 * math.pi * 25.0, rel=1e-14
    )


@pytest.mark.parametrize("zeta", [0.2, 0.7, 1.0, 2.0])
def test_simple_form_in_eq25_is_the_same_transfer_function(zeta):
    wn = natural_frequency_rad_s(30.0, zeta)
    ax = AxisServo.second_order(30.0, zeta)
    w = np.logspace(0, 5, 300)
    _, h_min = signal.freqs([wn * wn], [1.0, 2 * zeta * wn, wn * wn], worN=w)
    _, h_pad = signal.freqs(ax.numerator, ax.denominator, worN=w)
    assert np.max(np.abs(h_pad - h_min)) < 1e-12
    assert ax.dc_gain == pytest.approx(1.0, rel=1e-15)
    expected = np.roots([1.0, 2 * zeta * wn, wn * wn])
    assert np.sort_complex(ax.poles()) == pytest.approx(np.sort_complex(expected), rel=1e-12)


def test_simple_form_simulates_as_scipy_lsim():
    # The planner's and the simulator's code paths on the eq.-25 form of the simple model,
    # against scipy.signal.lsim of the plain 2nd-order G(s) (lsim: input linear between
    # samples, the first-order hold both use).
    from nurbscnc.servo.model import simulate_axis
    from nurbscnc.servo.simulate import simulate_reference

    zeta, f_bw, T = 0.6, 35.0, 1e-3
    wn = natural_frequency_rad_s(f_bw, zeta)
    t = np.arange(400) * T
    r = np.where(t < 0.1, 0.0, 5.0 * (t - 0.1)) + 0.3 * np.sin(2 * np.pi * 8 * t)
    _, y_ref, _ = signal.lsim(([wn * wn], [1.0, 2 * zeta * wn, wn * wn]), r, t)
    # An override of the simple form's keys replaces the file's coefficients of that axis.
    m = parse_machine(
        default_profile_text(),
        overrides={"servo.x.bandwidth_hz": f_bw, "servo.x.damping": str(zeta)},
    )
    assert m.servo.x == AxisServo.second_order(f_bw, zeta)
    assert m.servo.y == load_machine().servo.y
    y = simulate_axis(m.servo.x, r, T, settle=False)
    assert np.max(np.abs(y - y_ref)) < 1e-9
    sim = simulate_reference(np.column_stack([r, r, r]), m)
    assert np.max(np.abs(sim.actual_mm[: r.size, 0] - y_ref)) < 1e-9
    assert np.array_equal(sim.actual_mm[:, 2], sim.reference_mm[:, 2])  # z: no model, ideal


def test_profile_without_servo_section_has_no_contour_check():
    lines = default_profile_text().splitlines()
    start = lines.index("[servo]")
    stop = lines.index("[steps]")
    m = parse_machine("\n".join(lines[:start] + lines[stop:]))
    assert m.servo.period_s == 1e-3
    assert (m.servo.x, m.servo.y, m.servo.z) == (None, None, None)
    assert not m.servo.modelled and not m.contour_check
    assert m.settings["servo"] == {"period_ms": 1.0}
    assert "contour check off" in profile_toml(m)
    assert load_machine().contour_check


BAD_SIMPLE = [
    ("bandwidth_hz = 40.0\ndamping = 0.7\na0 = 1.0\n", "servo.x", "mixes the two model forms"),
    ("bandwidth_hz = 40.0\n", "servo.x.damping", "missing"),
    ("bandwidth_hz = 40.0\ndamping = 2.5\n", "servo.x.damping", "<= 2"),
    ("bandwidth_hz = -4.0\ndamping = 0.7\n", "servo.x.bandwidth_hz", "> 0"),
    ("bandwidth_hz = 40.0\ndamping = 0.7\ngain = 1.0\n", "servo.x.gain", "not a known key"),
]


@pytest.mark.parametrize(("body", "key", "words"), BAD_SIMPLE)
def test_bad_simple_forms_name_the_key(body, key, words):
    text = _without_servo_axes(default_profile_text()) + "\n[servo.x]\n" + body
    with pytest.raises(ConfigError) as info:
        parse_machine(text, "bad.toml")
    assert key in info.value.message and words in info.value.message


def test_discovery_order(tmp_path):
    cwd, home, xdg = tmp_path / "work", tmp_path / "home", tmp_path / "xdg"
    for d in (cwd, home / ".config" / "nurbscnc", xdg / "nurbscnc"):
        d.mkdir(parents=True)
    env = {"HOME": str(home)}
    assert find_machine(None, env, str(cwd)) == (None, FOUND_BY_DEFAULT)
    home_user = home / ".config" / "nurbscnc" / "machine.toml"
    home_user.write_text("")
    assert find_machine(None, env, str(cwd)) == (str(home_user), FOUND_BY_USER)
    env["XDG_CONFIG_HOME"] = "relative/ignored"  # the XDG spec: relative paths are ignored
    assert find_machine(None, env, str(cwd)) == (str(home_user), FOUND_BY_USER)
    env["XDG_CONFIG_HOME"] = str(xdg)
    assert find_machine(None, env, str(cwd)) == (None, FOUND_BY_DEFAULT)
    (xdg / "nurbscnc" / "machine.toml").write_text("")
    assert find_machine(None, env, str(cwd)) == (
        str(xdg / "nurbscnc" / "machine.toml"),
        FOUND_BY_USER,
    )
    (cwd / "nurbscnc.toml").write_text("")
    assert find_machine(None, env, str(cwd)) == (str(cwd / "nurbscnc.toml"), FOUND_BY_LOCAL)
    env["NURBSCNC_MACHINE"] = ""  # empty: not set
    assert find_machine(None, env, str(cwd))[1] == FOUND_BY_LOCAL
    env["NURBSCNC_MACHINE"] = "/no/such/file.toml"  # set: used (and fails when read)
    assert find_machine(None, env, str(cwd)) == ("/no/such/file.toml", FOUND_BY_ENV)
    assert find_machine("m.toml", env, str(cwd)) == ("m.toml", FOUND_BY_OPTION)
    with pytest.raises(OutputError, match=r"/no/such/file.toml \(from \$NURBSCNC_MACHINE\)"):
        load_machine("/no/such/file.toml", found_by=FOUND_BY_ENV)


# ---------------------------------------------------------------------------------------------
# Per-axis limits (issue 13): [axis_limits.x|y|z], every key optional.


def test_axis_limits_absent_by_default(machine):
    ax = machine.axis_limits
    assert not ax.any
    assert ax.v_max_mm_s == ax.a_max_mm_s2 == ax.j_max_mm_s3 == (math.inf,) * 3
    assert "axis_limits" not in machine.settings


def test_axis_limits_in_internal_units():
    m = load_machine(
        overrides={
            "axis_limits.x.v_max_mm_min": 3500.0,
            "axis_limits.y.a_max_mm_s2": 1200,
            "axis_limits.z.j_max_mm_s3": "2e4",
            "axis_limits.z.v_max_mm_min": 600,
        }
    )
    ax = m.axis_limits
    assert ax.any
    assert ax.v_max_mm_s == (3500.0 / 60.0, math.inf, 10.0)  # mm/min → mm/s
    assert ax.a_max_mm_s2 == (math.inf, 1200.0, math.inf)
    assert ax.j_max_mm_s3 == (math.inf, math.inf, 2e4)
    v, a, j = ax.as_arrays()
    assert v.shape == a.shape == j.shape == (3,)


def test_axis_limits_from_a_file_and_shown_round_trip():
    text = default_profile_text() + (
        "\n[axis_limits.x]\nv_max_mm_min = 3000.0\na_max_mm_s2 = 800.0\nj_max_mm_s3 = 2.0e4\n"
        "\n[axis_limits.z]\nv_max_mm_min = 1200.0\n"
    )
    m = parse_machine(text, "axes.toml")
    assert m.axis_limits.v_max_mm_s == (50.0, math.inf, 20.0)
    assert m.axis_limits.a_max_mm_s2 == (800.0, math.inf, math.inf)
    shown = profile_toml(m)
    assert (
        "[axis_limits.x]\nv_max_mm_min = 3000.0\na_max_mm_s2 = 800.0\nj_max_mm_s3 = 20000.0"
        in shown
    )
    again = parse_machine(shown, "shown.toml")
    assert again.axis_limits == m.axis_limits


def test_axis_velocity_limit_relaxes_the_step_rate_check():
    # 0.5 mm/step·period at 1000 steps/mm: 58.3 mm/s needs 59 steps per period, more than 50;
    # an x axis limited to 45 mm/s (2700 mm/min) needs 45, which fits only if the check uses it.
    base = {"steps.max_pulses_per_period": 50, "steps.per_mm.y": 100.0, "steps.per_mm.z": 100.0}
    with pytest.raises(ConfigError, match="axis x"):
        load_machine(overrides=base)
    m = load_machine(overrides={**base, "axis_limits.x.v_max_mm_min": 2700.0})
    assert m.axis_limits.v_max_mm_s[0] == 45.0


BAD_AXIS = [
    ({"axis_limits.x.v_max_mm_min": 0}, "axis_limits.x.v_max_mm_min", "must be > 0, got 0"),
    ({"axis_limits.y.a_max_mm_s2": -2450}, "axis_limits.y.a_max_mm_s2", "must be > 0"),
    ({"axis_limits.z.j_max_mm_s3": math.inf}, "axis_limits.z.j_max_mm_s3", "finite"),
    ({"axis_limits.x.a_max_mm_s2": "'fast'"}, "axis_limits.x.a_max_mm_s2", "must be a number"),
    ({"axis_limits.x.a_max_mm_s2": True}, "axis_limits.x.a_max_mm_s2", "must be a number"),
    ({"axis_limits.x.accel": 1.0}, "axis_limits.x.accel", "unknown key"),
    ({"axis_limits.w.v_max_mm_min": 1.0}, "axis_limits.w.v_max_mm_min", "unknown key"),
    ({"axis_limits.x": 1.0}, "axis_limits.x", "names a table"),
]


@pytest.mark.parametrize(("overrides", "key", "words"), BAD_AXIS)
def test_invalid_axis_limits_name_the_key(overrides, key, words):
    with pytest.raises(ConfigError) as info:
        load_machine(overrides=overrides)
    assert key in info.value.message
    assert words in info.value.message


BAD_AXIS_TEXTS = [
    ("[axis_limits.x]\nv_max_mm_min = -1.0\n", "axis_limits.x.v_max_mm_min", "> 0"),
    ('[axis_limits.y]\na_max_mm_s2 = "2450"\n', "axis_limits.y.a_max_mm_s2", "number"),
    ("[axis_limits.x]\nmax_velocity = 1.0\n", "axis_limits.x.max_velocity", "not a known key"),
    ("[axis_limits.a]\nv_max_mm_min = 1.0\n", "axis_limits.a", "not a known key"),
    ("[axis_limits]\nx = 3.0\n", "axis_limits.x", "must be a table"),
    ("axis_limits = 3\n", "axis_limits", "must be a table"),
]


@pytest.mark.parametrize(("extra", "key", "words"), BAD_AXIS_TEXTS)
def test_invalid_axis_limit_files_name_the_key(extra, key, words):
    text = (
        (extra + default_profile_text())
        if extra.startswith("axis_limits =")
        else (default_profile_text() + "\n" + extra)
    )
    with pytest.raises(ConfigError) as info:
        parse_machine(text, "bad.toml")
    assert info.value.message.startswith("bad.toml: ")
    assert key in info.value.message
    assert words in info.value.message
