"""Per-axis limits → per-piece path limits (issue 13): plan/axes.py and caps.axis_path_limits.

References are closed forms written here from the geometry: direction cosines of lines, the
tangent and curvature vector of a circle (t = (−sin θ, cos θ), κn = −(cos θ, sin θ)/R,
d(κn)/ds = −t/R²), and the axis acceleration and jerk of a circular motion differentiated by
hand in Cartesian coordinates (not through the Frenet formulas the code uses).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nurbscnc.machine.caps import axis_path_limits
from nurbscnc.machine.profile import load_machine
from nurbscnc.plan.axes import axis_geometry_bounds, piece_limits
from nurbscnc.plan.program_pieces import segment_pieces
from nurbscnc.program.interpret import interpret_text

HEAD = "G21 G90 G17 G61\n"
INF = math.inf


def machine(**axes):
    """The default machine with the path limits raised out of the way (V 10 m/min, A 1e5,
    J 1e7) unless given, and per-axis limits ``x_v`` [mm/min], ``x_a``, ``x_j`` …"""
    over = {
        "limits.v_max_mm_min": 10000.0,
        "limits.a_max_mm_s2": 1e5,
        "limits.j_max_mm_s3": 1e7,
        "steps.per_mm.x": 100.0,
        "steps.per_mm.y": 100.0,
        "steps.per_mm.z": 100.0,
    }
    names = {"v": "v_max_mm_min", "a": "a_max_mm_s2", "j": "j_max_mm_s3"}
    for key, value in axes.items():
        if key.startswith("path_"):
            over[f"limits.{names[key[5]]}" if key[5] != "v" else "limits.v_max_mm_min"] = value
        else:
            over[f"axis_limits.{key[0]}.{names[key[2]]}"] = value
    return load_machine(overrides=over)


def limits_of(program: str, m):
    pieces = segment_pieces(interpret_text(HEAD + program + "M2\n").segments, m)
    return pieces, piece_limits(pieces, m)


def test_no_axis_limits_is_the_path_limits():
    m = load_machine()
    pieces, lim = limits_of("F3000\nG1 X10 Y3\nG2 X20 Y3 I5 J0\n", m)
    assert len(pieces) == 2
    assert np.all(np.isinf(lim.v_mm_s))
    np.testing.assert_array_equal(lim.a_mm_s2, [2450.0, 2450.0])
    np.testing.assert_array_equal(lim.j_mm_s3, [5e4, 5e4])


@pytest.mark.parametrize(("move", "axis"), [("X10", 0), ("Y-7", 1), ("Z3", 2)])
def test_line_along_an_axis_gets_that_axis_limits(move, axis):
    m = machine(
        x_v=1200.0,
        x_a=500.0,
        x_j=1e4,
        y_v=2400.0,
        y_a=800.0,
        y_j=3e4,
        z_v=600.0,
        z_a=200.0,
        z_j=5e3,
    )
    _, lim = limits_of(f"F9000\nG1 {move}\n", m)
    v = (20.0, 40.0, 10.0)[axis]
    a = (500.0, 800.0, 200.0)[axis]
    j = (1e4, 3e4, 5e3)[axis]
    assert lim.v_mm_s[0] == pytest.approx(v, rel=1e-14)
    assert lim.a_mm_s2[0] == pytest.approx(a, rel=1e-14)
    assert lim.j_mm_s3[0] == pytest.approx(j, rel=1e-14)


def test_diagonal_line_direction_cosines():
    # Direction (3, 4, 12)/13: cosines 3/13, 4/13, 12/13.
    m = machine(
        x_v=600.0,
        x_a=100.0,
        x_j=1e3,
        y_v=600.0,
        y_a=300.0,
        y_j=1e3,
        z_v=6000.0,
        z_a=1000.0,
        z_j=1e5,
    )
    _, lim = limits_of("F9000\nG1 X3 Y4 Z12\n", m)
    c = np.array([3.0, 4.0, 12.0]) / 13.0
    assert lim.v_mm_s[0] == pytest.approx(min(10 / c[0], 10 / c[1], 100 / c[2]), rel=1e-13)
    assert lim.a_mm_s2[0] == pytest.approx(min(100 / c[0], 300 / c[1], 1000 / c[2]), rel=1e-13)
    assert lim.j_mm_s3[0] == pytest.approx(min(1e3 / c[0], 1e3 / c[1], 1e5 / c[2]), rel=1e-13)


def test_45_degree_line_runs_sqrt2_faster_but_never_above_the_path_limits():
    # LinuxCNC's simulated mill on both axes: 58.33 mm/s and 2450 mm/s² per axis.
    axes = dict(x_v=3500.0, x_a=2450.0, y_v=3500.0, y_a=2450.0)
    _, lim = limits_of("F9000\nG1 X10 Y10\n", machine(**axes))
    assert lim.v_mm_s[0] == pytest.approx(3500.0 / 60.0 * math.sqrt(2.0), rel=1e-13)
    assert lim.a_mm_s2[0] == pytest.approx(2450.0 * math.sqrt(2.0), rel=1e-13)
    assert lim.j_mm_s3[0] == 1e7  # no axis jerk limit: the path's
    _, lim = limits_of("F9000\nG1 X10 Y10\n", machine(**axes, path_a=2450.0, path_j=5e4))
    assert lim.a_mm_s2[0] == 2450.0
    assert lim.j_mm_s3[0] == 5e4


def test_only_some_keys_given():
    # Only x has a velocity limit: a Y line is untouched, an X line keeps the path A and J.
    m = machine(x_v=600.0)
    _, lim = limits_of("F9000\nG1 X5\nG1 Y5\n", m)
    np.testing.assert_allclose(lim.v_mm_s, [10.0, INF], rtol=1e-14)
    np.testing.assert_array_equal(lim.a_mm_s2, [1e5, 1e5])
    np.testing.assert_array_equal(lim.j_mm_s3, [1e7, 1e7])


def _circle_bounds(th0, th1, r, n=200_001):
    """Exact per-axis maxima of |t_i|, |(κn)_i|, |d(κn)_i/ds| on a CCW XY arc θ0 → θ1 (dense)."""
    th = np.linspace(th0, th1, n)
    t = np.column_stack([-np.sin(th), np.cos(th)])
    kn = -np.column_stack([np.cos(th), np.sin(th)]) / r
    dkn = -t / r**2
    return (np.abs(t).max(0), np.abs(kn).max(0), np.abs(dkn).max(0))


@pytest.mark.parametrize(
    ("th0_deg", "sweep_deg", "r"), [(45, 90, 5.0), (0, 360, 2.0), (10, 30, 20.0), (200, 170, 1.0)]
)
def test_arc_bounds_enclose_the_exact_ones_tightly(th0_deg, sweep_deg, r):
    th0, th1 = math.radians(th0_deg), math.radians(th0_deg + sweep_deg)
    x0, y0 = r * math.cos(th0), r * math.sin(th0)
    x1, y1 = r * math.cos(th1), r * math.sin(th1)
    prog = f"G0 X{x0:.12f} Y{y0:.12f}\nF600\nG3 X{x1:.12f} Y{y1:.12f} I{-x0:.12f} J{-y0:.12f}\n"
    if sweep_deg == 360:
        prog = f"G0 X{r} Y0\nF600\nG3 X{r} Y0 I{-r} J0\n"
    pieces = segment_pieces(interpret_text(HEAD + prog + "M2\n").segments, load_machine())
    t_b, k_b, g_b, kappa = axis_geometry_bounds(pieces)
    t_x, k_x, g_x = _circle_bounds(th0, th1, r)
    h_rad = math.radians(sweep_deg) / 32  # sample spacing as an angle
    assert kappa[1] == pytest.approx(1.0 / r, rel=1e-12)
    # Sound: never below the exact maxima; tight: within what changes in half a sample.
    assert np.all(t_b[1, :2] >= t_x - 1e-12) and np.all(t_b[1, :2] <= t_x + h_rad)
    assert np.all(k_b[1, :2] >= k_x - 1e-12) and np.all(k_b[1, :2] <= k_x + h_rad / r)
    assert np.all(g_b[1, :2] >= g_x * (1 - 1e-12))
    assert np.all(g_b[1, :2] <= g_x + h_rad / r**2)
    # An XY arc has no Z component at all: a slow Z axis never caps it.
    assert t_b[1, 2] == k_b[1, 2] == g_b[1, 2] == 0.0
    # The rapid before it is a line: its bounds are its direction cosines.
    np.testing.assert_allclose(t_b[0], np.abs(pieces.tangent_start[:, 0]), rtol=0, atol=0)


def test_helix_z_component_is_its_pitch():
    pieces = segment_pieces(
        interpret_text(HEAD + "G0 X5 Y0\nF600\nG3 X5 Y0 Z4 I-5 J0\nM2\n").segments, load_machine()
    )
    t_b, k_b, _, kappa = axis_geometry_bounds(pieces)
    circ = 2 * math.pi * 5.0
    tz = 4.0 / math.hypot(circ, 4.0)
    assert t_b[1, 2] == pytest.approx(tz, rel=1e-9)
    assert k_b[1, 2] == pytest.approx(0.0, abs=1e-12)
    # helix curvature r / (r² + c²), c = pitch / 2π
    c = 4.0 / (2 * math.pi)
    assert kappa[1] == pytest.approx(5.0 / (25.0 + c * c), rel=1e-12)


def test_full_circle_linuxcnc_axes_closed_form():
    # LinuxCNC sim axes (58.33 mm/s, 2450 mm/s²), no axis jerk; a circle R at F3000 (50 mm/s).
    # Feed cap min(V, √(A R / 2)); tangential acceleration √(A² − (v² / R)²) at v = 50 mm/s
    # (Cauchy–Schwarz on the orthonormal t, n; the path's own A_max = 2450 caps it too).
    m = machine(x_v=3500.0, x_a=2450.0, y_v=3500.0, y_a=2450.0, path_v=3500.0)
    for r in (0.5, 2.0, 10.0):
        _, lim = limits_of(f"G0 X{r} Y0\nF3000\nG3 X{r} Y0 I{-r} J0\n", m)
        assert lim.v_mm_s[1] == pytest.approx(min(3500 / 60, math.sqrt(2450 * r / 2)), rel=1e-12)
        v = min(50.0, math.sqrt(2450 * r / 2))
        assert lim.a_mm_s2[1] == pytest.approx(math.sqrt(2450**2 - (v * v / r) ** 2), rel=1e-12)


def _worst_circle_axis(v, a, j, r, n=4001):
    """Largest |axis acceleration| and |axis jerk| of a point on a circle of radius r moving
    at speed v with tangential acceleration ±a and jerk ±j, over all phases, from
    x(t) = r cos(φ(t)) differentiated by hand: φ' = v/r, φ'' = a/r, φ''' = j/r,
    x'' = −r(φ'' sin φ + φ'² cos φ), x''' = −r(φ''' sin φ + 3φ'φ'' cos φ − φ'³ sin φ)."""
    phi = np.linspace(0, 2 * np.pi, n)
    w1, worst_a, worst_j = v / r, 0.0, 0.0
    for sa in (-1.0, 1.0):
        w2 = sa * a / r
        acc = -r * (w2 * np.sin(phi) + w1 * w1 * np.cos(phi))
        worst_a = max(worst_a, float(np.abs(acc).max()))
        for sj in (-1.0, 1.0):
            w3 = sj * j / r
            jerk = -r * (w3 * np.sin(phi) + 3 * w1 * w2 * np.cos(phi) - w1**3 * np.sin(phi))
            worst_j = max(worst_j, float(np.abs(jerk).max()))
    return worst_a, worst_j


@pytest.mark.parametrize("r", [0.3, 1.0, 4.0, 25.0])
def test_circle_limits_hold_in_cartesian_closed_form(r):
    # Axis limits with jerk: whatever speed ≤ v̄, |a| ≤ ā and |j| ≤ j̄ the planner picks on
    # the circle, every axis stays within its limits. On a gentle circle at least half of A_i
    # stays tangential; on a tighter one the jerk 3 v a κ of speeding up along the curve
    # takes the rest (R 4 mm at 50 mm/s: 3·50·ā/4 ≤ J/2 − v³G gives ā ≈ 280 mm/s²; R 0.3 mm
    # at 11 mm/s: ā ≈ 72 mm/s²).
    m = machine(x_v=3000.0, x_a=1500.0, x_j=3e4, y_v=3000.0, y_a=1500.0, y_j=3e4)
    _, lim = limits_of(f"G0 X{r} Y0\nF6000\nG3 X{r} Y0 I{-r} J0\n", m)
    v_bar = min(lim.v_mm_s[1], 100.0)
    for v in (v_bar, 0.7 * v_bar, 0.3 * v_bar):
        worst_a, worst_j = _worst_circle_axis(v, lim.a_mm_s2[1], lim.j_mm_s3[1], r)
        assert worst_a <= 1500.0 * (1 + 1e-9)
        assert worst_j <= 3e4 * (1 + 1e-9)
    assert lim.a_mm_s2[1] > 0.0 and lim.j_mm_s3[1] >= 3e4 / 4 * (1 - 1e-12)  # ≥ R_i / 2
    if r >= 20.0:
        assert lim.a_mm_s2[1] >= 1500.0 / 2


# Soundness of the formula for any bounds: the worst case of each inequality of the
# derivation (caps.axis_path_limits docstring) holds.
finite = st.floats(0.01, 1e4)


@settings(max_examples=200, deadline=None)
@given(
    t=st.lists(st.floats(0.0, 1.0), min_size=3, max_size=3),
    kfrac=st.lists(st.floats(0.0, 1.0), min_size=3, max_size=3),
    kappa=st.floats(0.0, 50.0),
    g=st.lists(st.floats(0.0, 1e3), min_size=3, max_size=3),
    v_piece=finite,
    v_i=st.lists(finite, min_size=3, max_size=3),
    a_i=st.lists(finite, min_size=3, max_size=3),
    j_i=st.lists(st.floats(1.0, 1e7), min_size=3, max_size=3),
)
def test_axis_path_limits_satisfy_every_axis_inequality(t, kfrac, kappa, g, v_piece, v_i, a_i, j_i):
    t = np.array([t])
    kb = np.array([kfrac]) * kappa
    gb = np.array([g])
    v, a, j = axis_path_limits(
        t, kb, gb, np.array([kappa]), np.array([v_piece]), v_i, a_i, j_i, 1e9, 1e12
    )
    vb = min(v[0], v_piece)
    assert a[0] > 0 and j[0] > 0
    for i in range(3):
        rel = 1 + 1e-9
        assert vb * t[0, i] <= v_i[i] * rel
        acc_sum = a[0] * t[0, i] + vb * vb * kb[0, i]
        acc_euclid = math.hypot(a[0], vb * vb * kappa)
        assert min(acc_sum, acc_euclid) <= a_i[i] * rel
        assert j[0] * t[0, i] + 3 * vb * a[0] * kb[0, i] + vb**3 * gb[0, i] <= j_i[i] * rel


def test_runs_at_one_cap_share_their_smallest_limits():
    # A NURBS at F600 (every cell at the feed cap, tangent-continuous): one run, so every cell
    # gets the run's smallest acceleration and jerk (the profile plans the run as one unit
    # only when the limits are equal), never more than its own; the line after a stop keeps
    # its own.
    from nurbscnc.machine.caps import axis_path_limits

    m = machine(x_v=3500.0, x_a=2450.0, x_j=5e4, y_v=3500.0, y_a=1000.0, y_j=2e4)
    text = "F600\nG5.2 X1 Y1.5 P1 L4\nX4 Y3 P1\nX8 Y-2 P1\nX12 Y4 P1\nX16 Y0 P1\nG5.3\nG1 X16 Y10\n"
    pieces, lim = limits_of(text, m)
    nurbs = np.flatnonzero(np.asarray(pieces.kind) == 4)
    assert nurbs.size > 10
    v, a, j = lim.v_mm_s, lim.a_mm_s2, lim.j_mm_s3
    caps = np.minimum(pieces.v_cap_mm_s, v)
    assert np.all(caps[nurbs] == 10.0)  # F600 everywhere on the curve
    own = axis_path_limits(
        *axis_geometry_bounds(pieces), pieces.v_cap_mm_s, *m.axis_limits.as_arrays(), 1e5, 1e7
    )
    assert np.all(a[nurbs] == own[1][nurbs].min()) and np.all(j[nurbs] == own[2][nurbs].min())
    assert own[1][nurbs].max() > own[1][nurbs].min()  # the cells differ on their own
    last = len(pieces) - 1  # the Y line after the curve's end (a corner: a stop)
    assert a[last] == pytest.approx(1000.0) and j[last] == pytest.approx(2e4)
