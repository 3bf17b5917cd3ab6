"""The planner and interpolator on the bundled airfoils and on small programs (issue 4).

Every property is measured from the written samples, not taken from the planner's own
bookkeeping: limits by finite differences of the sampled path length, positions against the
programmed geometry by an independent dense polyline, feed fluctuation against chord lengths
corrected by the curvature (arc = chord · (1 + κ²c²/24) + O(c⁵)).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from nurbscnc.cli.main import main
from nurbscnc.geometry.nurbs import NurbsCurve
from nurbscnc.machine.profile import load_machine
from nurbscnc.output.files import read_points
from nurbscnc.pipeline import RunOptions, run_program
from nurbscnc.plan.options import LookaheadOptions
from nurbscnc.plan.plans import segment_times_s
from nurbscnc.program.interpret import interpret_text
from nurbscnc.servo.model import contour_error_true
from tests.servo_reference import distance_to_polyline_mm, lsim_actual_mm

ROOT = Path(__file__).resolve().parents[1]
MACHINE = load_machine()
AIRFOILS = ["naca2415.nc", "naca2415_rot45.nc", "naca2415_rot-45.nc"]


@pytest.fixture(scope="module", params=AIRFOILS)
def airfoil_plan(request):
    prog = interpret_text((ROOT / "programs" / request.param).read_text())
    return prog, run_program(prog, MACHINE)


def _run(prog, **lookahead):
    return run_program(prog, MACHINE, RunOptions(lookahead=LookaheadOptions(**lookahead)))


def _fd(s, period, order):
    d = np.asarray(s, dtype=float)
    for _ in range(order):
        d = np.diff(d)
    return d / period**order


def test_samples_are_one_period_apart_and_start_end_at_rest(airfoil_plan):
    prog, plan = airfoil_plan
    s = plan.samples
    period = MACHINE.servo.period_s
    np.testing.assert_allclose(np.diff(s.t_s), period, rtol=0, atol=1e-15)
    assert s.t_s[0] == 0.0
    np.testing.assert_array_equal(s.points_mm[0], prog.start_mm)
    end = prog.segments[-1].end_mm
    np.testing.assert_allclose(s.points_mm[-1], end, rtol=0, atol=1e-12)
    assert s.v_mm_s[0] == 0.0 and s.v_mm_s[-1] == 0.0


def test_limits_hold_on_the_samples(airfoil_plan):
    """Feed, tangential acceleration and jerk from finite differences of s (a difference of
    a C² piecewise cubic is a weighted mean of its derivative, so the bounds carry over)."""
    _, plan = airfoil_plan
    lim = MACHINE.limits
    period = MACHINE.servo.period_s
    s = plan.samples.s_mm
    assert _fd(s, period, 1).max() <= max(lim.v_max_mm_s, lim.rapid_mm_s) * (1 + 1e-6)
    assert np.abs(_fd(s, period, 2)).max() <= lim.a_max_mm_s2 * (1 + 1e-6)
    assert np.abs(_fd(s, period, 3)).max() <= lim.j_max_mm_s3 * (1 + 1e-6)
    # Positions agree with s: the distance between consecutive points never exceeds Δs.
    chord = np.linalg.norm(np.diff(plan.samples.points_mm, axis=0), axis=1)
    assert np.all(chord <= np.diff(s) + 1e-12)


def test_samples_lie_on_the_programmed_curve(airfoil_plan):
    """Within e + 0.1 µm of the NURBS (PH corner pieces deviate by at most their fit)."""
    prog, plan = airfoil_plan
    curve = NurbsCurve.from_segment(prog.segments[1])
    dense = curve.point(np.linspace(curve.u_start, curve.u_end, 400_001))
    on_curve = plan.samples.piece >= 1  # piece 0 is the rapid to the trailing edge
    d_mm = contour_error_true(plan.samples.points_mm[on_curve], dense)
    e_mm = MACHINE.limits.ph_tolerance_mm
    assert d_mm.max() <= e_mm + 1e-4


def _menger_curvature(a, b, c):
    """Curvature [1/mm] of the circle through three points (4·area / product of sides)."""
    ab, bc, ca = (
        np.linalg.norm(b - a, axis=1),
        np.linalg.norm(c - b, axis=1),
        np.linalg.norm(a - c, axis=1),
    )
    area2 = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    return 2.0 * area2 / np.maximum(ab * bc * ca, 1e-300)


def test_feed_fluctuation_on_exact_pieces_is_below_1e_6(airfoil_plan):
    """Δs planned against the arc between consecutive points, from the chord c and the local
    curvature κ (circle through three consecutive samples): arc = c(1 + κ²c²/24)."""
    _, plan = airfoil_plan
    pts = plan.samples.points_mm
    ds_planned = np.diff(plan.samples.s_mm)[1:-1]
    c = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    kappa = _menger_curvature(pts[:-2], pts[1:-1], pts[2:])  # around sample k, k = 1..N-2
    c_k = c[1:]  # chord k → k+1
    kappa_k = 0.5 * (kappa[:-1] + kappa[1:]) if kappa.size > 1 else kappa
    c_k = c_k[:-1]
    ds_k = ds_planned[:-1] if ds_planned.size > c_k.size else ds_planned
    # The four samples around an interval must lie on one smooth curve: NURBS cells of the
    # programmed curve (one C² curve), or one PH piece; never across a NURBS/PH junction,
    # where the curvature jumps.
    kinds = np.array([p.name for p in plan.plan.pieces])
    curve_key = np.where(kinds == "nurbs", -1, np.arange(kinds.size))[plan.samples.piece]
    same = (
        (curve_key[1:-2] == curve_key[2:-1])
        & (curve_key[2:-1] == curve_key[3:])
        & (curve_key[:-3] == curve_key[1:-2])
    )
    on_curve = plan.samples.piece[1:-2] >= 1
    sel = same & on_curve & (ds_k > 1e-3)
    arc = c_k * (1.0 + (kappa_k * c_k) ** 2 / 24.0)
    fluct = np.abs(arc[sel] / ds_k[sel] - 1.0)
    assert sel.sum() > 350  # the block's samples on one smooth curve (392 at 0.456 s)
    assert fluct.max() < 1e-6


def test_contour_error_within_limit_and_faster_than_paper(airfoil_plan):
    """The planner's reference points through an independent servo simulation
    (scipy.signal.lsim of eq. 25, first-order hold): every actual point while cutting (from
    the first sample on the curve to the end, settling included) is within ε_max of the
    programmed curve, allowing the PH fit tolerance e the corner pieces may deviate by."""
    prog, run = airfoil_plan
    smp = run.samples
    actual = lsim_actual_mm(smp.points_mm, MACHINE)
    first_cut = int(np.argmax(smp.piece >= 1))  # piece 0 is the rapid to the trailing edge
    curve = NurbsCurve.from_segment(prog.segments[1])
    dense = curve.point(np.linspace(curve.u_start, curve.u_end, 400_001))
    d_mm = distance_to_polyline_mm(actual[first_cut + 1 :], dense)
    lim = MACHINE.limits
    assert d_mm.max() <= lim.contour_tolerance_mm + lim.ph_tolerance_mm + 1e-5
    # The check is not idle: the kinematic plan alone misses ε_max on the same curve.
    off = _run(prog, dynamics="off")
    a_off = lsim_actual_mm(off.samples.points_mm, MACHINE)
    first_off = int(np.argmax(off.samples.piece >= 1))
    assert distance_to_polyline_mm(a_off[first_off + 1 :], dense).max() > lim.contour_tolerance_mm
    nurbs_time = segment_times_s(run.plan)[1]
    assert nurbs_time < 0.9455  # the paper's PH look-ahead on its airfoil (Table 4)


def test_dynamics_off_is_kinematic_only_and_no_slower():
    prog = interpret_text((ROOT / "programs" / "naca2415.nc").read_text())
    off = _run(prog, dynamics="off")
    local = run_program(prog, MACHINE)
    assert off.check is None and off.plan.iterations == 0
    assert off.cycle_time_s <= local.cycle_time_s


def test_dwell_holds_position_for_its_duration():
    text = "G21 G90\nG1 X10 F600\nG4 P0.25\nG1 Y10\nM2\n"
    prog = interpret_text(text)
    plan = _run(prog, dynamics="off")
    pts = plan.samples.points_mm
    at_corner = np.all(np.abs(pts - [10.0, 0.0, 0.0]) < 1e-12, axis=1)
    period = MACHINE.servo.period_s
    # At rest at the corner for the dwell (plus the instants of arrival and departure).
    assert at_corner.sum() * period == pytest.approx(0.25, abs=2.5 * period)
    # Straight moves at F = 10 mm/s with S-curve ends: time from closed forms.
    v, a, j = 10.0, MACHINE.limits.a_max_mm_s2, MACHINE.limits.j_max_mm_s3
    t_ramp = 2.0 * np.sqrt(v / j) if v < a * a / j else v / a + a / j
    expected = 2 * (10.0 / v + t_ramp) + 0.25
    assert plan.cycle_time_s == pytest.approx(expected, rel=1e-9)


def test_run_cli_writes_points_csv_and_npz(tmp_path):
    runner = CliRunner()
    csv = tmp_path / "p.csv"
    res = runner.invoke(main, ["run", str(ROOT / "programs" / "naca2415.nc"), "-o", str(csv)])
    assert res.exit_code == 0, res.output
    assert csv.read_text().splitlines()[0] == "t,x,y,z,feed,piece,line"
    data = read_points(str(csv))
    npz = tmp_path / "p.npz"
    res = runner.invoke(main, ["run", str(ROOT / "programs" / "naca2415.nc"), "-o", str(npz)])
    assert res.exit_code == 0, res.output
    arrays = read_points(str(npz))
    np.testing.assert_allclose(arrays["x"], data["x"], atol=1e-9)
    np.testing.assert_array_equal(arrays["line"], data["line"])
    assert data["t"][0] == 0.0 and data["feed"][-1] == 0.0


def test_run_refuses_soft_limit_violation_and_writes_nothing(tmp_path):
    prog = tmp_path / "far.nc"
    prog.write_text("G21\nG1 X10 F600\nG1 X1500\nM2\n")
    out = tmp_path / "out.csv"
    res = CliRunner().invoke(main, ["run", str(prog), "-o", str(out)])
    assert res.exit_code == 2
    assert "soft limits" in res.output
    assert not out.exists()
    assert list(tmp_path.iterdir()) == [prog]  # no temporary file left behind


def test_batch_run_reports_failures_and_writes_the_others(tmp_path):
    good = tmp_path / "good.nc"
    good.write_text("G21\nG1 X5 F600\nM2\n")
    bad = tmp_path / "bad.nc"
    bad.write_text("G21\nG1 X5 F600\nG2 X9 R1\nM2\n")
    outdir = tmp_path / "out"
    # A process of its own, as a user runs it: the workers are forked, and a fork of this
    # test process (threads left by earlier tests, holding locks) can hang in the worker.
    res = subprocess.run(
        [
            sys.executable,
            "-m",
            "nurbscnc",
            "run",
            str(good),
            str(bad),
            "--output-dir",
            str(outdir),
            "--jobs",
            "2",
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 2
    assert (outdir / "good.csv").exists() and not (outdir / "bad.csv").exists()
    assert "bad.nc:3" in res.stderr


@pytest.mark.parametrize("between", ["", "G4 P0\n"])
def test_a_zero_second_dwell_is_a_stop_at_rest(between):
    """A dwell stops the tool whatever its length (a pause is the zero-length case): two
    collinear moves pass their junction at speed, and stop there with "G4 P0" between."""
    prog = interpret_text(f"G21 G90\nG1 X10 F600\n{between}G1 X20\nM2\n")
    run = _run(prog, dynamics="off")
    smp = run.samples
    v_junction = run.plan.profile.junction_speeds_mm_s[1]
    # The sampled feed within 0.1 mm of the joint (from finite differences of s).
    v_fd = np.diff(smp.s_mm) / MACHINE.servo.period_s
    near = np.abs(smp.points_mm[:-1, 0] - 10.0) < 0.1
    if between:
        assert v_junction == 0.0 and v_fd[near].min() < 0.05
    else:
        assert v_junction == pytest.approx(10.0, rel=1e-12)
        assert v_fd[near].min() == pytest.approx(10.0, rel=1e-9)
