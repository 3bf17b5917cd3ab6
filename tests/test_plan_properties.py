"""Property tests of the planner + interpolator on random valid NURBS programs (issue 4).

Random G6.2 programs (cubic or quartic, random control points and weights, random feeds) are
interpreted and planned; every property is measured from the samples: T_s spacing, rest at
both ends, programmed end point, feed / acceleration / jerk limits by finite differences of
the sampled path length, points on the programmed curve within e + 0.1 µm (a true distance
to a dense independent polyline of the curve, from scipy's BSpline on homogeneous
coordinates), and no feed fluctuation on exact NURBS pieces.
"""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.interpolate import BSpline

from nurbscnc.machine.profile import load_machine
from nurbscnc.pipeline import RunOptions, run_program
from nurbscnc.plan.options import LookaheadOptions
from nurbscnc.plan.report import nurbs_step_lengths
from nurbscnc.program.interpret import interpret_text
from nurbscnc.servo.model import contour_error_true
from tests.servo_reference import distance_to_polyline_mm, lsim_actual_mm

MACHINE = load_machine()


@st.composite
def nurbs_programs(draw):
    order = draw(st.sampled_from([4, 5]))
    n = draw(st.integers(order + 1, order + 6))
    pts = draw(
        st.lists(
            st.tuples(st.floats(-20, 20), st.floats(-20, 20)), min_size=n, max_size=n, unique=True
        )
    )
    pts = np.array(pts)
    # Keep consecutive control points apart so the curve has no cusp (cusps are exact stops,
    # tested elsewhere) and the program stays a smooth NURBS.
    if np.min(np.linalg.norm(np.diff(pts, axis=0), axis=1)) < 0.5:
        pts = pts + np.arange(n)[:, None] * np.array([1.0, 0.3])
    weights = draw(st.lists(st.floats(0.5, 2.0), min_size=n, max_size=n))
    feed = draw(st.sampled_from([600.0, 1500.0, 3500.0]))
    interior = n - order
    knots = [0.0] * order + [float(i) for i in range(1, interior + 1)] + [interior + 1.0] * order
    x0, y0 = pts[0]
    lines = ["G21 G17 G90 G94", f"G0 X{x0:.6f} Y{y0:.6f}", f"F{feed:g}"]
    for i in range(n):
        head = f"G6.2 P{order} " if i == 0 else ""
        lines.append(f"{head}K{knots[i]:g} X{pts[i, 0]:.6f} Y{pts[i, 1]:.6f} R{weights[i]:.6f}")
    lines += [f"K{k:g}" for k in knots[n:]] + ["M2"]
    return "\n".join(lines)


def _dense_curve(seg, n=200_001):
    """The programmed curve evaluated by scipy (homogeneous B-spline), independent of ours."""
    w = np.asarray(seg.weights)
    hom = np.column_stack([np.asarray(seg.control_points_mm) * w[:, None], w])
    spl = BSpline(np.asarray(seg.knots), hom, seg.degree)
    u = np.linspace(seg.knots[seg.degree], seg.knots[-seg.degree - 1], n)
    h = spl(u)
    return h[:, :3] / h[:, 3:]


def _fd(s, period, order):
    d = np.asarray(s, float)
    for _ in range(order):
        d = np.diff(d)
    return d / period**order


@settings(
    max_examples=12, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)
@given(nurbs_programs())
def test_random_nurbs_programs_keep_every_limit(text):
    prog = interpret_text(text)
    run = run_program(prog, MACHINE, RunOptions(lookahead=LookaheadOptions(dynamics="off")))
    smp = run.samples
    lim, period = MACHINE.limits, MACHINE.servo.period_s
    np.testing.assert_allclose(np.diff(smp.t_s), period, rtol=0, atol=1e-12)
    assert smp.v_mm_s[0] == 0.0 and smp.v_mm_s[-1] == 0.0
    np.testing.assert_allclose(smp.points_mm[-1], prog.segments[-1].end_mm, atol=1e-12)
    np.testing.assert_allclose(smp.points_mm[0], prog.start_mm, rtol=0, atol=1e-12)
    top = max(lim.v_max_mm_s, lim.rapid_mm_s)
    assert _fd(smp.s_mm, period, 1).max() <= top * (1 + 1e-6)
    assert np.abs(_fd(smp.s_mm, period, 2)).max() <= lim.a_max_mm_s2 * (1 + 1e-6)
    assert np.abs(_fd(smp.s_mm, period, 3)).max() <= lim.j_max_mm_s3 * (1 + 1e-6)
    # On the curve (pieces after the rapid): within e + 0.1 µm of the programmed NURBS.
    seg = prog.segments[-1]
    on_curve = smp.piece >= 1
    d = contour_error_true(smp.points_mm[on_curve], _dense_curve(seg))
    assert d.max() <= lim.ph_tolerance_mm + 1e-4
    # Exact interpolation: the true arc length of every NURBS step is the planned one.
    k, ds_true = nurbs_step_lengths(run.plan.pieces, smp)
    planned = smp.s_mm[k + 1] - smp.s_mm[k]
    moving = planned > 1e-6
    if moving.any():
        assert np.max(np.abs(ds_true[moving] / planned[moving] - 1.0)) < 1e-6


@settings(
    max_examples=4, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)
@given(nurbs_programs())
def test_random_nurbs_programs_meet_the_contour_tolerance(text):
    """With the (default) local dynamics check, the planner's reference points through an
    independent servo simulation (scipy.signal.lsim of eq. 25) stay within ε_max of the
    programmed curve (scipy's BSpline) while cutting, allowing the PH fit tolerance e."""
    prog = interpret_text(text)
    smp = run_program(prog, MACHINE).samples
    actual = lsim_actual_mm(smp.points_mm, MACHINE)
    first_cut = int(np.argmax(smp.piece >= 1))  # piece 0 is the rapid to the curve's start
    d = distance_to_polyline_mm(actual[first_cut + 1 :], _dense_curve(prog.segments[-1], 400_001))
    lim = MACHINE.limits
    assert d.max() <= lim.contour_tolerance_mm + lim.ph_tolerance_mm + 1e-5
