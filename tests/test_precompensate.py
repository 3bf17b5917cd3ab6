"""Pre-compensation (issue 13): the ZPETC inverse of the servo model, ``--precompensate``.

The inverse is checked against an independent simulation: ``scipy.signal.lsim`` of the
continuous eq.-25 model on the compensated points (first-order hold), and the theory of
zero-phase-error tracking (Tomizuka 1987) with the sampled zeros taken from
``scipy.signal.cont2discrete(method="foh")``, not from our discretisation:

- a minimum-phase sampled model is inverted exactly: y_k = r_k at every sample;
- with one unstable sampled zero z_u (the paper's axes: z_u ≈ −3.32), G·F is the zero-phase
  filter 1 + β(q − 2 + q⁻¹), β = −z_u/(1 − z_u)², so y_k = r_k + β(r_{k+1} − 2r_k + r_{k−1})
  exactly, and |y − r| ≤ β max|Δ²r| (≈ β T_s² max|r̈|).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from scipy import signal

from nurbscnc.cli.main import main
from nurbscnc.errors import ConfigError
from nurbscnc.geometry.nurbs import NurbsCurve
from nurbscnc.interpolate.sample import sample_plan
from nurbscnc.machine.profile import AxisServo, default_profile_text, load_machine
from nurbscnc.output.files import read_points
from nurbscnc.pipeline import RunOptions, run_program
from nurbscnc.program.interpret import interpret_text
from nurbscnc.servo.model import AxisModel, discretise
from nurbscnc.servo.precompensate import (
    SMOOTH_STEP_ACCEL,
    SMOOTH_STEP_JERK,
    along_path_offset_mm,
    limit_to_path,
    perturbed_model,
    precompensate_points,
    smooth_step,
    zpetc,
)
from tests.servo_reference import distance_to_polyline_mm, lsim_actual_mm, segment_distance_mm

ROOT = Path(__file__).resolve().parents[1]
MACHINE = load_machine()
PERIOD = MACHINE.servo.period_s
AIRFOIL = ROOT / "programs" / "naca2415.nc"


def lsim_axis(num, den, u, period):
    """Independent: the continuous model driven by u (linear between samples), from rest."""
    t = np.arange(u.size) * period
    _, y, _ = signal.lsim(signal.lti(num, den), u - u[0], t, interp=True)
    return y + u[0] * num[-1] / den[-1]


def foh_zeros(num, den, period):
    """The sampled zeros of the FOH equivalent, by scipy (not nurbscnc.servo.model)."""
    b = np.ravel(signal.cont2discrete((num, den), period, method="foh")[0])
    return np.roots(np.trim_zeros(b, "f"))


def smooth_reference(seed: int, n: int = 700) -> np.ndarray:
    """A random smooth 1-D reference [mm] at rest at both ends: low-passed noise integrated
    twice, shaped by a window that is flat zero at both ends."""
    rng = np.random.default_rng(seed)
    acc = signal.lfilter(*signal.butter(2, 0.02), rng.standard_normal(n))
    acc *= np.sin(np.linspace(0.0, np.pi, n)) ** 4
    acc -= acc.mean()  # so the velocity comes back to (nearly) zero
    vel = np.cumsum(acc)
    vel -= np.linspace(0.0, 1.0, n) * vel[-1]
    vel *= np.sin(np.linspace(0.0, np.pi, n)) ** 2
    r = np.cumsum(vel)
    r *= 5.0 / np.abs(r).max()  # a few millimetres
    return np.concatenate([np.zeros(20), r, np.full(80, r[-1])]) + 1.25


PAPER_AXES = [MACHINE.servo.x, MACHINE.servo.y, AxisServo.second_order(40.0, 0.7)]


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("axis", range(len(PAPER_AXES)))
def test_zpetc_on_a_non_minimum_phase_axis_is_the_zero_phase_filter(seed, axis):
    servo = PAPER_AXES[axis]
    num, den = servo.numerator, servo.denominator
    zeros = foh_zeros(num, den, PERIOD)
    unstable = zeros[np.abs(zeros) > 1.0]
    assert unstable.size == 1 and abs(unstable[0].imag) < 1e-12  # one sampling zero < −1
    z_u = unstable[0].real
    beta = -z_u / (1.0 - z_u) ** 2
    r = smooth_reference(seed)
    comp = precompensate_points([servo], r[:, None], PERIOD)
    u = comp.points_mm[:, 0]
    assert comp.lead_samples == 1  # the look-ahead of one unstable zero
    assert u.size == r.size + 1 and u[-1] == r[-1]  # ends with the plan, at its end point
    y = lsim_axis(num, den, np.concatenate([u, np.full(50, u[-1])]), PERIOD)
    planned = np.concatenate(
        [np.full(comp.lead_samples, r[0]), r, np.full(y.size - r.size - comp.lead_samples, r[-1])]
    )
    d2 = np.zeros_like(planned)
    d2[1:-1] = planned[2:] - 2.0 * planned[1:-1] + planned[:-2]
    # Exactly the zero-phase filter at every sample (lsim's own accuracy ~1e-12 mm) but
    # where F's tail was cut (the last sample: no limits given, a jump of end_step_mm) …
    last = u.size - 1
    np.testing.assert_allclose(y[:last], (planned + beta * d2)[:last], rtol=0, atol=1e-9)
    # … after which the tool is off by at most the (tiny, the reference rests 80 periods)
    # step times the model's step-response peak.
    assert comp.end_step_mm < 1e-4
    assert np.abs(y[last:] - planned[last:]).max() <= 1.5 * comp.end_step_mm + 1e-9
    # … so the tracking error is the ZPETC gain error, β·Δ²r, and far below the lag of
    # the uncompensated reference.
    err = np.abs(y - planned)
    assert err.max() <= beta * np.abs(d2).max() + 1e-9
    y_plain = lsim_axis(num, den, np.concatenate([r, np.full(50, r[-1])]), PERIOD)
    plain = np.concatenate([r, np.full(50, r[-1])])
    assert err.max() < 0.05 * np.abs(y_plain - plain).max()


@pytest.mark.parametrize("axis", range(len(PAPER_AXES)))
def test_inverse_frequency_response_against_scipy(axis):
    """H(e^{jω}) of the FOH-sampled model by scipy (cont2discrete + freqz, not our
    discretisation) times F(e^{jω}) of the ZPETC inverse: real and positive at every
    frequency (zero phase), 1 at DC, equal to Tomizuka's 1 − 2|z_u|(1 − cos ωT)/(1 − z_u)²
    for the one unstable sampled zero z_u, so within 1 % of 1 up to ωT = 0.2 (32 Hz at
    1 ms)."""
    servo = PAPER_AXES[axis]
    num, den = servo.numerator, servo.denominator
    b_d, a_d, _ = signal.cont2discrete((num, den), PERIOD, method="foh")
    w = np.linspace(0.0, np.pi, 2001)
    _, h = signal.freqz(np.ravel(b_d), a_d, worN=w)
    f = zpetc(discretise(servo, PERIOD))
    _, iir = signal.freqz(f.num, f.den, worN=w)
    # u_k = Σ_i c_i v_{k+lead−(n_c−1)+i}: F = IIR · Σ_i c_i e^{jω(lead − n_c + 1 + i)}
    shift = f.lead_samples - (f.ahead.size - 1) + np.arange(f.ahead.size)
    fir = np.exp(1j * np.outer(w, shift)) @ f.ahead
    hf = h * iir * fir
    np.testing.assert_allclose(hf.imag, 0.0, atol=1e-8)
    assert hf[0].real == pytest.approx(1.0, abs=1e-9)
    z_u = foh_zeros(num, den, PERIOD)
    z_u = z_u[np.abs(z_u) > 1.0][0].real
    expect = 1.0 - 2.0 * abs(z_u) * (1.0 - np.cos(w)) / (1.0 - z_u) ** 2
    np.testing.assert_allclose(hf.real, expect, rtol=0, atol=1e-7)
    assert np.all(hf.real > 0.0)
    band = w <= 0.2
    assert np.abs(hf[band] - 1.0).max() <= 0.01


@pytest.mark.parametrize(
    "num, den", [((100.0,), (1.0, 100.0)), ((1.0, 300.0, 2e4), (1.0, 200.0, 2e4))]
)
def test_zpetc_on_a_minimum_phase_axis_is_the_exact_inverse(num, den):
    assert np.all(np.abs(foh_zeros(num, den, PERIOD)) < 1.0)
    r = smooth_reference(7)
    comp = precompensate_points([AxisModel(num, den)], r[:, None], PERIOD)
    assert comp.lead_samples == 0
    u = comp.points_mm[:, 0]
    y = lsim_axis(num, den, np.concatenate([u, np.full(20, u[-1])]), PERIOD)
    planned = np.concatenate([r, np.full(y.size - r.size, r[-1])])
    np.testing.assert_allclose(y[: u.size - 1], planned[: u.size - 1], rtol=0, atol=1e-9)
    assert np.abs(y - planned).max() <= 1.5 * comp.end_step_mm + 1e-9


def test_the_inverse_tail_is_blended_in_within_the_limits():
    """A plan that stops abruptly leaves F's slow tail (the stable zeros of H) well above
    zero at the end: it is blended in over the last W samples, W the fewest with the quintic
    smooth step's acceleration and jerk (closed forms, checked here by finite differences)
    within the limits; against the same reference held long enough for the tail to decay."""
    # A 2 mm move in 100 ms (a quintic smooth step) that ends as it arrives: a large tail.
    r = np.concatenate([np.zeros(10), 2.0 * smooth_step(np.linspace(0.0, 1.0, 100))]) + 1.25
    long = np.concatenate([r, np.full(400, r[-1])])
    a_max, j_max = 2450.0, 5e4
    comp = precompensate_points(
        [MACHINE.servo.x], r[:, None], PERIOD, a_max_mm_s2=a_max, j_max_mm_s3=j_max
    )
    free = precompensate_points([MACHINE.servo.x], long[:, None], PERIOD).points_mm[:, 0]
    u = comp.points_mm[:, 0]
    n = r.size + comp.lead_samples
    assert u.size == n and u[0] == r[0] and u[-1] == r[-1]
    d = r[-1] - free[n - 1]
    assert comp.end_step_mm == pytest.approx(abs(d), rel=1e-12) and abs(d) > 1e-3
    t_w = max(np.sqrt(10.0 / np.sqrt(3.0) * abs(d) / a_max), np.cbrt(60.0 * abs(d) / j_max))
    w = int(np.ceil(t_w / PERIOD - 1e-9))
    assert comp.end_blend_samples == w > 1
    blend = u - free[:n]
    np.testing.assert_allclose(blend[: n - w], 0.0, atol=1e-12)
    np.testing.assert_allclose(
        blend[n - w :], d * smooth_step(np.arange(1, w + 1) / w), rtol=0, atol=1e-12
    )
    full = np.concatenate([np.zeros(3), blend, np.full(3, d)])
    assert np.abs(np.diff(full, 2)).max() / PERIOD**2 <= a_max
    assert np.abs(np.diff(full, 3)).max() / PERIOD**3 <= j_max * (1 + 1e-9)
    assert SMOOTH_STEP_ACCEL == pytest.approx(
        np.abs(np.gradient(np.gradient(smooth_step(x := np.linspace(0, 1, 20001)), x), x)).max(),
        rel=1e-3,
    )
    assert SMOOTH_STEP_JERK == pytest.approx(60.0)


def test_perturbed_models_against_closed_forms():
    servo = MACHINE.servo.x
    a0, a1, b1 = servo.a0, servo.a1, servo.b1
    c1 = (a1 - b1) / a0  # velocity lag of eq. 25 with a0 = b0
    for k in (0.9, 1.1):
        m = perturbed_model(servo, loop_gain=k)
        num, den = np.array(m.numerator), np.array(m.denominator)
        assert num[-1] / den[-1] == pytest.approx(servo.dc_gain, rel=1e-12)
        assert (den[-2] - num[-2]) / den[-1] == pytest.approx(c1 / k, rel=1e-9)
        # The zeros stay, the poles are those of D + (k − 1)N.
        np.testing.assert_allclose(
            np.sort_complex(np.roots(num)), np.sort_complex(np.roots(servo.numerator)), rtol=1e-9
        )
    for lam in (0.9, 1.1):
        m = perturbed_model(servo, bandwidth=lam)
        np.testing.assert_allclose(
            np.sort_complex(m.poles()), np.sort_complex(lam * servo.poles()), rtol=1e-9
        )
        assert m.dc_gain == pytest.approx(servo.dc_gain, rel=1e-12)


def test_the_lead_along_the_path_and_the_limit_to_the_path_on_a_circle():
    theta = np.linspace(0.0, 1.0, 200)
    rho = 2.0

    def circle(t):
        return np.column_stack([rho * np.cos(t), rho * np.sin(t), np.zeros_like(t)])

    r = circle(theta)
    radial = r / rho
    tangent = np.column_stack([-np.sin(theta), np.cos(theta), np.zeros_like(theta)])
    u = r + 0.010 * radial + 0.005 * tangent
    lead = along_path_offset_mm(u, r)
    # Central differences give the exact tangent direction up to O(h²) inside.
    np.testing.assert_allclose(lead[1:-1], 0.005, rtol=0, atol=1e-8)
    foot = circle(theta + lead / rho)  # the path point that far along
    out = limit_to_path(u, foot, 0.003)
    # Within the tolerance of the circle (by construction), and along the residual's line.
    np.testing.assert_allclose(
        np.abs(np.linalg.norm(out, axis=1) - rho)[1:-1], 0.003, rtol=0, atol=1e-8
    )
    assert np.all(np.linalg.norm(out - foot, axis=1) <= 0.003 + 1e-15)
    assert np.array_equal(limit_to_path(u, foot, np.inf), u)


# -- the pipeline ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def airfoil():
    prog = interpret_text(AIRFOIL.read_text())
    curve = NurbsCurve.from_segment(prog.segments[1])
    dense = curve.point(np.linspace(curve.u_start, curve.u_end, 400_001))
    return prog, dense


@pytest.fixture(scope="module")
def airfoil_precompensated(airfoil):
    """The airfoil run with ``precompensate`` (the default reference tolerance), once for
    the module: the tests below only read it."""
    return run_program(airfoil[0], MACHINE, RunOptions(precompensate=True))


def _contour_um(points_mm, dense, first_cut):
    actual = lsim_actual_mm(points_mm, MACHINE)
    return distance_to_polyline_mm(actual[first_cut + 1 :], dense) * 1000.0


def test_airfoil_fully_compensated_tool_follows_the_plan(airfoil):
    """With no reference limit, the independently simulated tool is within the PH fit
    tolerance e (the planned corner pieces may leave the NURBS by that) plus 1 µm of the
    curve, while the same plan's uncompensated reference misses ε_max."""
    prog, dense = airfoil
    run = run_program(prog, MACHINE, RunOptions(precompensate=True, reference_tolerance_mm=np.inf))
    smp = run.samples
    lim = MACHINE.limits
    first_cut = int(np.argmax(smp.piece >= 1))
    err = _contour_um(smp.points_mm, dense, first_cut)
    # Until F's tail is blended in at the end, then within ε_max (the check's own bound).
    blend = int(round(run.precompensation.end_blend_s / PERIOD))
    until = smp.points_mm.shape[0] - blend - first_cut - 1
    assert 0 < blend < 40 and run.precompensation.tail_s == 0.0
    assert err[:until].max() <= (lim.ph_tolerance_mm + 0.001) * 1000.0
    assert err.max() <= lim.contour_tolerance_mm * 1000.0
    plain = sample_plan(run.plan.pieces, run.plan.profile, PERIOD)
    err_plain = _contour_um(plain.points_mm, dense, int(np.argmax(plain.piece >= 1)))
    assert err_plain.max() > lim.contour_tolerance_mm * 1000.0
    assert err[:until].max() < 0.05 * err_plain.max()
    # The same plan, the same cycle time but for the look-ahead's one period.
    assert run.cycle_time_s == pytest.approx(run.plan.cycle_time_s + PERIOD, abs=1e-12)


def test_run_precompensate_on_the_airfoil_cli(airfoil, airfoil_precompensated, tmp_path):
    """``run --precompensate`` (default: reference within 3 µm): the written points through
    lsim are within ε_max (+ e) of the curve, well below the uncompensated reference of the
    same plan; the summary reports the deviation (≤ 3 µm) and 8 model errors."""
    prog, dense = airfoil
    out = tmp_path / "p.csv"
    res = CliRunner().invoke(
        main, ["run", str(AIRFOIL), "-o", str(out), "--precompensate", "--json"]
    )
    assert res.exit_code == 0, res.output
    summary = json.loads(res.output.strip().splitlines()[-1])
    pre = summary["precompensation"]
    assert pre["reference_tolerance_um"] == pytest.approx(3.0)
    assert pre["reference_deviation_max_um"] <= 3.0 + 1e-6
    assert len(pre["sensitivity"]) == 8
    assert pre["sensitivity_contour_max_um"] == max(s["contour_max_um"] for s in pre["sensitivity"])
    data = read_points(str(out))
    pts = np.column_stack([data["x"], data["y"], data["z"]])
    piece = np.asarray(data["piece"])
    lim = MACHINE.limits
    err = _contour_um(pts, dense, int(np.argmax(piece >= 1)))
    assert err.max() <= lim.contour_tolerance_mm * 1000.0  # measured from the NURBS itself
    # The written points themselves are within 3 µm of the programmed curve (+ CSV
    # rounding): the PH corner pieces' own fit error e is taken off the tolerance there.
    dev = distance_to_polyline_mm(pts[piece >= 1], dense) * 1000.0
    assert dev.max() <= 3.0 + 0.01
    # The same plan without compensation: the plan was made faster than that allows.
    run = airfoil_precompensated
    assert summary["cycle_time_s"] == pytest.approx(run.cycle_time_s, abs=1e-9)
    plain = sample_plan(run.plan.pieces, run.plan.profile, PERIOD)
    err_plain = _contour_um(plain.points_mm, dense, int(np.argmax(plain.piece >= 1)))
    assert err_plain.max() > lim.contour_tolerance_mm * 1000.0 > err.max()


@pytest.mark.parametrize(
    "text",
    [
        "G21 G90 G0 X0 Y0\nG1 X10 Y3 F3000\n",
        "G21 G90 G0 X0 Y0\nG1 X10 Y3 F3000\nG1 X12 Y-4\nG1 X1 Y0.5\n",
        "G21 G90 G0 X1 Y1\nG1 X5 F2000\nG3 X5 Y5 R2\nG1 X1\n",
    ],
)
def test_the_compensated_reference_starts_and_ends_at_rest_at_the_programmed_points(text):
    prog = interpret_text(text)
    run = run_program(prog, MACHINE, RunOptions(precompensate=True))
    u = run.samples.points_mm
    start, end = np.asarray(prog.start_mm), np.asarray(prog.segments[-1].end_mm)
    assert np.array_equal(u[0], start) and np.array_equal(u[-1], end)
    plain = sample_plan(run.plan.pieces, run.plan.profile, PERIOD).points_mm
    lead = int(round(run.precompensation.lead_s / PERIOD))
    assert lead == 1 and u.shape[0] == plain.shape[0] + lead  # ends with the plan
    # Pre-actuation: nothing moves before the planned motion less the look-ahead.
    first_move = int(np.flatnonzero(np.any(plain != plain[0], axis=1))[0])
    assert np.all(u[: first_move + lead - 1] == start)
    # F's tail blended in within the machine's acceleration (finite differences of the
    # last samples, held at rest after), never past the end point along the last direction.
    held = np.concatenate([u, np.repeat(u[-1:], 3, axis=0)])
    acc = np.linalg.norm(np.diff(held[-60:], 2, axis=0), axis=1) / PERIOD**2
    assert acc.max() <= MACHINE.limits.a_max_mm_s2
    moving = np.flatnonzero(np.any(np.abs(plain - plain[-1]) > 1e-9, axis=1))
    direction = plain[-1] - plain[moving[-1] - 3]
    direction /= np.linalg.norm(direction)
    last = u[lead + moving[-1] - 20 :]
    assert ((last - end) @ direction).max() <= 1e-9
    # And the tool (independent lsim) stays within ε_max of the path at every sample.
    assert run.check.contour_um().max() <= MACHINE.limits.contour_tolerance_mm * 1000.0


def test_precompensate_without_a_servo_model_is_a_clear_error(tmp_path):
    text = default_profile_text()
    lines, skip = [], False
    for line in text.splitlines():
        if line.startswith("["):
            skip = line.strip() in ("[servo.x]", "[servo.y]")
        if not skip:
            lines.append(line)
    profile = tmp_path / "noservo.toml"
    profile.write_text("\n".join(lines) + "\n")
    res = CliRunner().invoke(
        main, ["plan", str(AIRFOIL), "--machine", str(profile), "--precompensate"]
    )
    assert res.exit_code == 2
    assert "pre-compensation needs a servo model" in res.output
    assert "Traceback" not in res.output
    # Without --precompensate the same profile plans (contour check off).
    assert (
        CliRunner().invoke(main, ["plan", str(AIRFOIL), "--machine", str(profile)]).exit_code == 0
    )


def test_precompensate_with_a_baseline_is_refused():
    prog = interpret_text(AIRFOIL.read_text())
    with pytest.raises(ConfigError, match="look-ahead planner"):
        run_program(prog, MACHINE, RunOptions(algorithm="adaptive", precompensate=True))


def test_the_reference_tolerance_is_measured_from_the_programmed_curve(
    airfoil, airfoil_precompensated
):
    """On the PH corner pieces of the airfoil (a fit within e of the NURBS, not on it) the
    tube about each planned path point is the tolerance less that point's distance from the
    programmed curve: against the distance to the test's own dense NURBS polyline."""
    from nurbscnc.geometry.path import Kind
    from nurbscnc.precompensation import reference_tube_mm

    dense = airfoil[1]
    run = airfoil_precompensated
    pieces, profile = run.plan.pieces, run.plan.profile
    rows = np.flatnonzero(pieces.kind == Kind.PH)
    assert rows.size >= 2  # the nose is fitted by PH pieces
    piece = np.repeat(rows, 41)
    s = (
        profile.piece_start_mm[piece]
        + np.tile(np.linspace(0.0, 1.0, 41), rows.size) * pieces.length_mm[piece]
    )
    foot = pieces.path.place(profile.piece_start_mm, s, piece)[0]
    tube = reference_tube_mm(pieces, piece, foot, 0.003, MACHINE.limits.ph_tolerance_mm)
    dist = segment_distance_mm(foot, dense)
    # the fit is off the curve (18 nm at most with 0.0625 mm corner cells, CORNER_CELL_MM)
    assert 1e-5 < dist.max() <= MACHINE.limits.ph_tolerance_mm
    # Never more than the tolerance allows (up to our polyline's sagitta), and no less.
    assert np.all(tube <= 0.003 - dist + 1e-9)
    np.testing.assert_allclose(tube, 0.003 - dist, rtol=0, atol=2e-6)
    # Elsewhere (NURBS stretches, lines) the full tolerance.
    other = np.flatnonzero(pieces.kind != Kind.PH)
    assert np.all(reference_tube_mm(pieces, other, np.zeros((other.size, 3)), 0.003, 1e-3) == 0.003)
