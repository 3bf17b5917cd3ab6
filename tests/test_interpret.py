"""The interpreter (nurbscnc/program/interpret.py) against independent references.

References: unit conversion (G20 input = G21 input × 25.4, golden-free), LinuxCNC's implied
G5.2 knot rule written here from its definition, arc geometry recomputed with vector algebra
(centre, radius, signed sweep about the plane normal of RS274/NGC: G17 +Z, G18 +Y, G19 +X),
Python's math module for expressions (angles in degrees), and RS274/NGC's modal rules.
"""

from __future__ import annotations

import math
from decimal import Decimal

import numpy as np
import pytest

from nurbscnc.errors import NurbsCncError
from nurbscnc.program.interpret import InterpretOptions, g5_knot_vector, interpret_text

INCH = 25.4
NORMAL = {"G17": (0.0, 0.0, 1.0), "G18": (0.0, 1.0, 0.0), "G19": (1.0, 0.0, 0.0)}


def num(x) -> str:
    """A float as G-code digits (no exponent), exactly: the shortest repr written out."""
    return format(Decimal(repr(float(x))), "f")


def run(text: str, **options):
    return interpret_text(text, InterpretOptions(**options))


def segs(text: str, **options):
    return run(text, **options).segments


def fields(seg) -> dict:
    """The numbers of a segment, by name (arrays as float arrays)."""
    names = {
        "line": ("start_mm", "end_mm", "feed_mm_s"),
        "rapid": ("start_mm", "end_mm"),
        "arc": (
            "start_mm",
            "end_mm",
            "center_mm",
            "normal",
            "angle_rad",
            "helix_mm",
            "radius_start_mm",
            "radius_end_mm",
            "feed_mm_s",
        ),
        "nurbs": ("degree", "knots", "control_points_mm", "weights", "feed_mm_s"),
        "dwell": ("seconds", "position_mm"),
    }[seg.kind]
    return {n: np.asarray(getattr(seg, n), dtype=float) for n in names}


def assert_same_program(a, b, rtol=1e-13, atol=1e-12):
    assert [(s.kind, s.line) for s in a] == [(s.kind, s.line) for s in b]
    for sa, sb in zip(a, b):
        fa, fb = fields(sa), fields(sb)
        for name in fa:
            np.testing.assert_allclose(fa[name], fb[name], rtol=rtol, atol=atol, err_msg=name)


# -- units -----------------------------------------------------------------------------------
UNIT_PROGRAM = """G{units} G90 G17
G0 X{a} Y{b} Z{c}
G1 X{d} Y{e} F{f}
G2 X{g} Y{h} I{i} J{j} Z{k}
G3 X{l} Y{m} R{n}
G3 X{l} Y{m} I{o} J{p} P2
G91 G1 X{a} Y{b} Z{c}
G1 X{d}
G90 G4 P1.5
G91 G18 G2 X{z1} Z{z2} R{n}
G90 G17 G5.2 X{q} Y{r} P2 L4
X{s} Y{t} P1
X{u} Y{v} P0.5
X{w} Y{x} P1
G5.3
G6.2 P3 K0 X{w} Y{x} R1 F{y}
K0 X{u} Y{v} R3
K0 X{s} Y{t} R1
K0.5 X{q} Y{r} R1
K1
K1
K1
"""


def unit_values(seed: int) -> dict:
    """Random coordinates (inch) that make valid arcs: arc ends lie on their circles."""
    rng = np.random.default_rng(seed)
    v = {k: float(x) for k, x in zip("abcdefqrstuvwx", rng.uniform(-3, 3, 14))}
    v["f"], v["y"] = float(rng.uniform(1, 20)), float(rng.uniform(1, 20))
    # G2 from (d, e): centre offset (i, j), end at angle phi on that circle, helical Z k.
    v["i"], v["j"] = float(rng.uniform(0.5, 2)), float(rng.uniform(0.5, 2))
    cx, cy = v["d"] + v["i"], v["e"] + v["j"]
    r = math.hypot(v["i"], v["j"])
    phi = float(rng.uniform(0, 2 * math.pi))
    v["g"], v["h"] = cx + r * math.cos(phi), cy + r * math.sin(phi)
    v["k"] = float(rng.uniform(-1, 1))
    # G3 by radius from (g, h) to (l, m), then the reverse full turn by centre back to it.
    v["l"], v["m"] = v["g"] + 1.0, v["h"] - 0.5
    v["n"] = 2.0
    v["z1"], v["z2"] = 0.6, 0.8  # the G18 arc's incremental chord (length 1 < 2R)
    mx, my = (v["g"] + v["l"]) / 2, (v["h"] + v["m"]) / 2
    chord = math.hypot(1.0, 0.5)
    hgt = math.sqrt(v["n"] ** 2 - (chord / 2) ** 2)
    ccx, ccy = mx - hgt * (-0.5) / chord, my + hgt * 1.0 / chord  # left of the chord (G3, R>0)
    v["o"], v["p"] = ccx - v["l"], ccy - v["m"]
    return v


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_inch_input_equals_mm_input_times_25_4(seed):
    """G20 program with numbers v == G21 program with numbers v × 25.4: lines, arcs (IJK, R,
    helical, turns, G18), G91, NURBS (G5.2 and G6.2, whose knots and weights are not
    lengths), feeds and dwell."""
    v = unit_values(seed)
    inch = UNIT_PROGRAM.format(units=20, **{k: num(x) for k, x in v.items()})
    mm = UNIT_PROGRAM.format(units=21, **{k: num(x * INCH) for k, x in v.items()})
    a, b = segs(inch), segs(mm)
    kinds = [s.kind for s in a]
    assert kinds == [
        "rapid",
        "line",
        "arc",
        "arc",
        "arc",
        "line",
        "line",
        "dwell",
        "arc",
        "nurbs",
        "nurbs",
    ]
    assert_same_program(a, b)
    assert a[1].feed_mm_s == pytest.approx(v["f"] * INCH / 60.0, rel=1e-15)
    assert a[-1].feed_mm_s == pytest.approx(v["y"] * INCH / 60.0, rel=1e-15)
    assert a[7].seconds == 1.5  # P of G4 is seconds in both unit systems
    np.testing.assert_array_equal(a[-1].knots, [0, 0, 0, 0.5, 1, 1, 1])
    np.testing.assert_array_equal(a[-1].weights, [1, 3, 1, 1])
    np.testing.assert_array_equal(a[-2].weights, [1, 2, 1, 0.5, 1])
    np.testing.assert_allclose(a[0].end_mm, [v["a"] * INCH, v["b"] * INCH, v["c"] * INCH])


def test_units_switch_mid_program():
    """LinuxCNC (its gcode module, checked): F is read before G20/G21 in a block (RS274/NGC
    order: feed rate at step 3, units at step 12), and a feed keeps its physical value when
    the units change."""
    (line1, line2, line3) = segs("G20 G1 X1 F10\nG21 X30\nG20\nF10 X2")
    assert line1.end_mm == (25.4, 0.0, 0.0)
    # LinuxCNC sets F (step 3) before the units (step 12): "G20 ... F10" in a block that
    # starts in mm is 10 mm/min (its goldens ccomp/mill-zchanges and nc_files/comp311,
    # "g20 f60": 1 mm/s, recorded with the gcode module and rs274).
    assert line1.feed_mm_s == pytest.approx(10 / 60, rel=1e-15)
    assert line2.end_mm == (30.0, 0.0, 0.0)
    # The feed keeps its mm/s value through the units change.
    assert line2.feed_mm_s == line1.feed_mm_s
    assert line3.end_mm == (50.8, 0.0, 0.0)
    assert line3.feed_mm_s == pytest.approx(10 * 25.4 / 60, rel=1e-15)  # G20 was in force


# -- G5.2 knots ------------------------------------------------------------------------------
def linuxcnc_knots(n_points: int, order: int) -> list[float]:
    """nurbs_G5_knot_vector_creator: with n = n_points - 1 and k = order, knot i (0..n+k) is
    0 for i < k, i - k + 1 for k <= i <= n, n - k + 2 for i > n."""
    n, k = n_points - 1, order
    out = []
    for i in range(n + k + 1):
        if i < k:
            out.append(0.0)
        elif i <= n:
            out.append(float(i - k + 1))
        else:
            out.append(float(n - k + 2))
    return out


@pytest.mark.parametrize(
    ("n_points", "order"), [(n, k) for n in range(2, 13) for k in range(2, 9) if k <= n]
)
def test_g5_knot_vector_is_linuxcnc_rule(n_points, order):
    knots = g5_knot_vector(n_points, order)
    assert knots == linuxcnc_knots(n_points, order)
    # What the rule means: clamped (order equal knots at each end), uniform unit steps.
    assert len(knots) == n_points + order
    top = n_points - order + 1
    assert knots[:order] == [0.0] * order and knots[-order:] == [float(top)] * order
    assert np.all(np.diff(knots[order - 1 : len(knots) - order + 1]) == 1.0)


@pytest.mark.parametrize(("n_points", "order"), [(3, 3), (4, 3), (7, 4), (9, 5), (8, 8)])
def test_g5_block_segment(n_points, order):
    """A G5.2 block: current point first (weight 1), then the X Y P lines; LinuxCNC knots."""
    rng = np.random.default_rng(n_points * 10 + order)
    pts = rng.uniform(-50, 50, (n_points - 1, 2)).round(6)
    wts = rng.uniform(0.5, 2.0, n_points - 1).round(6)
    lines = ["G21 G90 F1200", "G0 X1 Y2 Z-3"]
    lines.append(f"G5.2 X{pts[0, 0]:.6f} Y{pts[0, 1]:.6f} P{wts[0]:.6f} L{order}")
    lines += [f"X{x:.6f} Y{y:.6f} P{w:.6f}" for (x, y), w in zip(pts[1:], wts[1:])]
    lines += ["G5.3", "G1 X0"]
    prog = segs("\n".join(lines))
    nurbs = prog[1]
    assert nurbs.kind == "nurbs" and nurbs.line == 3
    assert nurbs.degree == order - 1
    np.testing.assert_array_equal(nurbs.knots, linuxcnc_knots(n_points, order))
    expected_pts = np.vstack([[1.0, 2.0], pts])
    np.testing.assert_array_equal(nurbs.control_points_mm[:, :2], expected_pts)
    np.testing.assert_array_equal(nurbs.control_points_mm[:, 2], -3.0)
    np.testing.assert_array_equal(nurbs.weights, np.r_[1.0, wts])
    assert nurbs.feed_mm_s == 20.0
    # The next move starts at the last control point.
    np.testing.assert_array_equal(prog[2].start_mm, [pts[-1, 0], pts[-1, 1], -3.0])


def test_g5_order_below_three_is_three_as_linuxcnc():
    prog = run("F60\nG5.2 X1 Y1 P1 L2\nX2 Y0 P1\nG5.3")
    assert prog.segments[0].degree == 2
    assert any("order 3 used" in n.message for n in prog.notes)


def test_g6_block_segment():
    """G6.2: P order, K knots as given, R weights, repeated G6.2 allowed, Q noted."""
    prog = run(
        "G21 F600\nG0 X1 Y1\nG6.2 P3 K0 X1 Y1 R1\nK0 X2 Y3 R2\nG6.2 K0 X4 Y1 Z2 R1 Q0.1\n"
        "K2 X5 Y0 Z2 R0.5\nK5\nK5\nK5\nG1 X0"
    )
    nurbs = prog.segments[1]
    assert (nurbs.kind, nurbs.line, nurbs.degree) == ("nurbs", 3, 2)
    np.testing.assert_array_equal(nurbs.knots, [0, 0, 0, 2, 5, 5, 5])
    np.testing.assert_array_equal(
        nurbs.control_points_mm, [[1, 1, 0], [2, 3, 0], [4, 1, 2], [5, 0, 2]]
    )
    np.testing.assert_array_equal(nurbs.weights, [1, 2, 1, 0.5])
    assert nurbs.feed_mm_s == 10.0
    assert prog.segments[2].start_mm == (5.0, 0.0, 2.0)
    assert any("Q" in n.message and "ignored" in n.message for n in prog.notes)


# -- arcs ------------------------------------------------------------------------------------
def ccw_angle(u, v, n) -> float:
    """Counter-clockwise angle about unit normal n from vector u to vector v, in (-pi, pi]."""
    return math.atan2(float(np.dot(n, np.cross(u, v))), float(np.dot(u, v)))


def expected_sweep(start, end, center, normal, ccw: bool, turns: int = 1) -> float:
    """Signed sweep of an RS274/NGC arc: G3 counter-clockwise in (0, 2pi], G2 clockwise in
    [-2pi, 0) (a full circle when the ends coincide), plus whole extra turns for P."""
    n = np.asarray(normal)
    u = np.asarray(start) - center
    v = np.asarray(end) - center
    u -= np.dot(u, n) * n
    v -= np.dot(v, n) * n
    t = ccw_angle(u, v, n)
    if ccw:
        t = t if t > 1e-12 else t + 2 * math.pi
        return t + 2 * math.pi * (turns - 1)
    t = t if t < -1e-12 else t - 2 * math.pi
    return t - 2 * math.pi * (turns - 1)


# In-plane axes (RS274/NGC): G17 X,Y with I,J; G18 Z,X with K,I; G19 Y,Z with J,K.
PLANES = {"G17": ("XY", "IJ", "Z"), "G18": ("ZX", "KI", "Y"), "G19": ("YZ", "JK", "X")}
AXIS = {"X": 0, "Y": 1, "Z": 2}


@pytest.mark.parametrize("plane", ["G17", "G18", "G19"])
@pytest.mark.parametrize("motion", ["G2", "G3"])
@pytest.mark.parametrize("phi_deg", [37.0, 180.0, 301.0, 0.0])
@pytest.mark.parametrize("turns", [1, 3])
def test_arc_center_format(plane, motion, phi_deg, turns):
    """Centre, radius, signed sweep, helical rise and end point of an I/J/K arc."""
    (a, b), (ca, cb), normal_axis = PLANES[plane]
    start = np.array([1.0, -2.0, 3.0])
    off = {ca: 2.0, cb: -1.5}  # centre offsets from the start, in-plane
    center = start.copy()
    center[AXIS[a]] += off[ca]
    center[AXIS[b]] += off[cb]
    r = math.hypot(2.0, -1.5)
    # End on the circle at angle phi from the start's angle, rise 0.75 along the normal.
    n = np.array(NORMAL[plane])
    u = start - center
    w = np.cross(n, u)  # u rotated +90 deg about n
    phi = math.radians(phi_deg)
    end = center + math.cos(phi) * u + math.sin(phi) * w + 0.75 * n
    words = " ".join(f"{ax}{num(end[AXIS[ax]])}" for ax in (a, b, normal_axis))
    text = f"G21 G90 F600\nG0 X1 Y-2 Z3\n{plane} {motion} {words} {ca}{off[ca]} {cb}{off[cb]}" + (
        f" P{turns}" if turns > 1 else ""
    )
    (_, arc) = segs(text)
    assert arc.kind == "arc" and arc.line == 3
    np.testing.assert_allclose(arc.center_mm, center, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(arc.normal, n)
    assert arc.radius_start_mm == pytest.approx(r, rel=1e-14)
    assert arc.radius_end_mm == pytest.approx(r, rel=1e-12)
    sweep = expected_sweep(start, end, center, n, motion == "G3", turns)
    assert arc.angle_rad == pytest.approx(sweep, rel=1e-12, abs=1e-12)
    if phi_deg == 0.0:
        assert abs(arc.angle_rad) == pytest.approx(2 * math.pi * turns, rel=1e-15)
    assert arc.helix_mm == pytest.approx(0.75, rel=1e-14)
    np.testing.assert_allclose(arc.end_mm, end, rtol=0, atol=1e-12)
    assert arc.length_mm == pytest.approx(math.hypot(r * sweep, 0.75), rel=1e-12)


@pytest.mark.parametrize("plane", ["G17", "G18", "G19"])
@pytest.mark.parametrize("motion", ["G2", "G3"])
@pytest.mark.parametrize("radius", [7.5, -7.5, 5.0, -5.0])
def test_arc_radius_format(plane, motion, radius):
    """R format: centre on the chord's bisector at |R| from both ends; R > 0 the short arc
    (|sweep| <= pi), R < 0 the long one; sign of the sweep from G2/G3."""
    (a, b), _, _ = PLANES[plane]
    start = np.zeros(3)
    end = np.zeros(3)
    end[AXIS[a]], end[AXIS[b]] = 6.0, 8.0  # chord 10: R 5 is the half circle
    (arc,) = segs(f"G21 F600 {plane} {motion} {a}6 {b}8 R{radius}")
    c = np.asarray(arc.center_mm)
    assert np.linalg.norm(c - start) == pytest.approx(abs(radius), rel=1e-14)
    assert np.linalg.norm(c - end) == pytest.approx(abs(radius), rel=1e-14)
    n = np.array(NORMAL[plane])
    assert np.dot(c, n) == 0.0  # in the plane of the start point
    assert arc.angle_rad == pytest.approx(
        expected_sweep(start, end, c, n, motion == "G3"), rel=1e-12
    )
    assert (arc.angle_rad > 0) == (motion == "G3")
    if abs(radius) == 5.0:
        assert abs(arc.angle_rad) == pytest.approx(math.pi, rel=1e-15)
    else:
        assert (abs(arc.angle_rad) < math.pi) == (radius > 0)
        # The expected magnitude: 2 asin(chord / 2R), or 2 pi minus it for R < 0.
        short = 2 * math.asin(5.0 / 7.5)
        assert abs(arc.angle_rad) == pytest.approx(
            short if radius > 0 else 2 * math.pi - short, rel=1e-12
        )


def test_arc_radius_format_centre_sides():
    """G2/G3 with +R/-R from (0,0) to (10,0), R = 5 sqrt 2: the four centres by hand."""
    r = 5 * math.sqrt(2)
    cases = {("G2", r): (5, -5), ("G2", -r): (5, 5), ("G3", r): (5, 5), ("G3", -r): (5, -5)}
    for (motion, radius), (cx, cy) in cases.items():
        (arc,) = segs(f"F600 {motion} X10 Y0 R{num(radius)}")
        np.testing.assert_allclose(arc.center_mm, [cx, cy, 0], atol=1e-12)


def test_absolute_arc_centres_g90_1():
    relative = segs("F600 G0 X2 Y3\nG91.1 G2 X8 Y3 I3 J-4")
    absolute = segs("F600 G0 X2 Y3\nG90.1 G2 X8 Y3 I5 J-1")
    assert_same_program(relative, absolute, rtol=0, atol=0)
    np.testing.assert_array_equal(absolute[1].center_mm, [5, -1, 0])
    assert absolute[1].radius_start_mm == 5.0


def test_arc_end_radius_within_tolerance_becomes_spiral():
    """LinuxCNC 2.9 (rs274, checked): end radius 0.028 mm off is accepted, 0.029 mm refused
    (absolute limit 2·0.01·√2 mm when also beyond 0.1 %); the radius varies."""
    (arc,) = segs("F600 G3 X10.028 Y0 I5 J0")
    assert arc.radius_start_mm == 5.0
    assert arc.radius_end_mm == pytest.approx(5.028, abs=1e-12)
    with pytest.raises(NurbsCncError, match="differs"):
        segs("F600 G3 X10.029 Y0 I5 J0")
    # Relative 0.1 % passes below the absolute limit for big radii: 100 mm, 0.09 mm off.
    (big,) = segs("F600 G3 X200.05 Y0 I100 J0")
    assert big.radius_end_mm == pytest.approx(100.05, abs=1e-12)


# -- distance modes, parameters, expressions -------------------------------------------------
def test_incremental_g91():
    prog = segs("G91 F600\nG1 X1 Y2\nX1\nY-0.5 Z3\nG90 X0")
    ends = [s.end_mm for s in prog]
    assert ends == [(1.0, 2.0, 0.0), (2.0, 2.0, 0.0), (2.0, 1.5, 3.0), (0.0, 1.5, 3.0)]
    (arc,) = segs("G91 F600 G0 X5 Y5\nG2 X10 Y0 I5 J0")[1:]
    np.testing.assert_array_equal(arc.end_mm, [15, 5, 0])
    np.testing.assert_array_equal(arc.center_mm, [10, 5, 0])


def test_parameters_take_effect_at_end_of_line():
    prog = segs("#1=1\n#1=5 #2=[#1+1]\nG0 X#2 Y#1\n#1=9 G0 Z#1\nG0 Z#1")
    assert prog[0].end_mm == (2.0, 5.0, 0.0)  # #2 = old #1 + 1
    assert prog[1].end_mm == (2.0, 5.0, 5.0)  # the assignment on this line not yet in force
    assert prog[2].end_mm == (2.0, 5.0, 9.0)
    (seg,) = segs("#<a>=1\n#<A>=5 #<b>=[#<a>+1]\nG0 X#<b> Y#<a>")
    assert seg.end_mm == (2.0, 5.0, 0.0)
    (seg,) = segs("#3=7\n#[#3 - 2]=4\nG0 X#5 Y#[2+1]")  # indirect numbers
    assert seg.end_mm == (4.0, 7.0, 0.0)


def value_of(expr: str, setup: str = "") -> float:
    (seg,) = segs(f"{setup}\nG0 X[{expr}] Y1")
    return seg.end_mm[0]


D = math.radians


@pytest.mark.parametrize(
    ("expr", "expected"),
    [
        ("SIN[30]", math.sin(D(30))),
        ("COS[60]", math.cos(D(60))),
        ("TAN[45]", math.tan(D(45))),
        ("SIN[-123.4]", math.sin(D(-123.4))),
        ("COS[1000]", math.cos(D(1000))),
        ("ASIN[0.5]", math.degrees(math.asin(0.5))),
        ("ACOS[-0.3]", math.degrees(math.acos(-0.3))),
        ("ATAN[1]/[-1]", 135.0),
        ("ATAN[-2]/[3]", math.degrees(math.atan2(-2, 3))),
        ("SQRT[2]", math.sqrt(2)),
        ("ABS[-3.5]", 3.5),
        ("EXP[1.5]", math.exp(1.5)),
        ("LN[10]", math.log(10)),
        ("2**0.5", 2**0.5),
        ("[-2]**3", -8.0),
        ("ROUND[2.5]", 3.0),
        ("ROUND[-2.5]", -3.0),
        ("ROUND[2.4999]", 2.0),
        ("FIX[2.7]", 2.0),
        ("FIX[-2.5]", -3.0),
        ("FUP[2.1]", 3.0),
        ("FUP[-2.7]", -2.0),
        ("7/2", 3.5),
        ("2+3*4", 14.0),
        ("2**3**2", 64.0),
        ("8-2-1", 5.0),
        ("12/3/2", 2.0),
        ("1 EQ 1", 1.0),
        ("1 NE 1", 0.0),
        ("1 GT 2", 0.0),
        ("2 GE 2", 1.0),
        ("1 LT 2", 1.0),
        ("3 LE 2", 0.0),
        ("1 AND 0", 0.0),
        ("0 OR 3", 1.0),
        ("1 XOR 1", 0.0),
        ("1 AND 0 OR 1", 1.0),
        ("0 OR 1 AND 0", 0.0),
        ("1+1 EQ 2", 1.0),
    ],
)
def test_expressions_against_math(expr, expected):
    assert value_of(expr) == pytest.approx(expected, rel=1e-15, abs=1e-15)


@pytest.mark.parametrize(
    ("a", "b", "expected"),
    # LinuxCNC: fmod, then + |b| when negative, so the result lies in [0, |b|).
    [
        (7, 3, 1.0),
        (-7, 3, 2.0),
        (7, -3, 1.0),
        (-7, -3, 2.0),
        (7.5, 2, 1.5),
        (-7.5, 2, 0.5),
        (6, 3, 0.0),
        (-6, 3, 0.0),
    ],
)
def test_mod_sign_rule(a, b, expected):
    assert value_of(f"[{a}] MOD [{b}]") == expected


def test_exists():
    assert value_of("EXISTS[#<a>] + 2 * EXISTS[#<b>]", "#<a>=0") == 1.0


# -- modal state, G53, G43 -------------------------------------------------------------------
def test_g43_tool_table_and_g53_machine_coordinates():
    prog = run("G43 H1\nG0 Z10\nG53 G0 Z10\nG0 Z20\nG49\nG0 Z20", tool_lengths_mm={1: 5.0})
    assert [s.end_mm[2] for s in prog.segments] == [15.0, 10.0, 25.0, 20.0]
    assert prog.notes == ()


def test_g43_without_table_is_zero_with_a_note():
    prog = run("G43 H3\nG0 Z10")
    assert prog.segments[0].end_mm == (0.0, 0.0, 10.0)
    assert any("H3" in n.message and "offset taken as 0" in n.message for n in prog.notes)


def test_g53_uses_program_units():
    prog = segs("G20 G53 G1 X1 F10\nX2")
    assert [s.end_mm[0] for s in prog] == [25.4, 50.8]


def test_start_point_option():
    (seg,) = segs("G0 X5", start_mm=(1.0, 2.0, 3.0))
    assert seg.start_mm == (1.0, 2.0, 3.0) and seg.end_mm == (5.0, 2.0, 3.0)


def test_feed_and_dwell():
    prog = segs("G1 X1 F600\nG4 P2.5\nG1 X2 F90")
    assert prog[0].feed_mm_s == 10.0
    assert (prog[1].kind, prog[1].seconds, prog[1].position_mm) == ("dwell", 2.5, (1.0, 0.0, 0.0))
    assert prog[2].feed_mm_s == 1.5


def test_motion_mode_is_modal_and_g0_is_rapid():
    prog = segs("G0 X1\nY1\nG1 F60 X2\nY2")
    assert [(s.kind, s.end_mm) for s in prog] == [
        ("rapid", (1.0, 0.0, 0.0)),
        ("rapid", (1.0, 1.0, 0.0)),
        ("line", (2.0, 1.0, 0.0)),
        ("line", (2.0, 2.0, 0.0)),
    ]
    assert prog[0].feed_mm_s == 0.0


# -- program structure -----------------------------------------------------------------------
def test_block_delete_switch():
    text = "G0 X1\n/G0 Y5\nG0 Z1"
    assert [s.line for s in segs(text, block_delete=True)] == [1, 3]
    assert [s.line for s in segs(text, block_delete=False)] == [1, 2, 3]


def test_percent_tape_markers():
    prog = segs("%\nG0 X1\n%\nG0 X2 B1\n")  # after the closing %, nothing is read
    assert [(s.line, s.end_mm) for s in prog] == [(2, (1.0, 0.0, 0.0))]


@pytest.mark.parametrize("end", ["M2", "M30", "m02"])
def test_m2_m30_end_the_program(end):
    prog = segs(f"G0 X1\nG0 X2 {end}\nG0 X3\nG0 B1 (not reached: B would be an error)")
    assert [s.end_mm[0] for s in prog] == [1.0, 2.0]  # the motion of the M2 block runs


def test_crlf_and_bom_same_program():
    lf = run("G21 F600\nG1 X1 (MSG, hi)\nG2 X2 Y0 I0.5\n")
    for text in (
        "G21 F600\r\nG1 X1 (MSG, hi)\r\nG2 X2 Y0 I0.5\r\n",
        "\ufeffG21 F600\nG1 X1 (MSG, hi)\r\nG2 X2 Y0 I0.5\n",
    ):
        other = run(text)
        assert_same_program(lf.segments, other.segments, rtol=0, atol=0)
        assert other.notes == lf.notes
    with pytest.raises(NurbsCncError) as info:
        run("\ufeffG0 X1\r\nG1 X2\r\n")
    assert (info.value.pos.line, info.value.pos.column, info.value.pos.text) == (2, 1, "G1 X2")


def test_spaces_inside_words_and_case():
    (seg,) = segs("G 1 X 1 . 5 F 6 0 0")
    assert seg.end_mm == (1.5, 0.0, 0.0) and seg.feed_mm_s == 10.0
    a = run("#<v>=3\nG21 F600 G3 X2 Y0 I1 J0\nG1 X#<v> Y[SIN[30]]")
    b = run("#<V>=3\ng21 f600 g3 x2 y0 i1 j0\ng1 x#<v> y[sin[30]]")
    assert_same_program(a.segments, b.segments, rtol=0, atol=0)


def test_comments_and_msg_notes():
    prog = run("(plain comment)\nG0 X1 (MSG, Hello world) ; trailing\n(msg,lower)\n; (MSG,no)")
    assert [(n.line, n.message) for n in prog.notes] == [
        (2, "message: Hello world"),
        (3, "message: lower"),
    ]
    assert prog.blocks == 1  # blocks with words or assignments


# -- extreme values: an error naming the problem, never a crash or a non-finite segment --------
@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("G[10**300]", "not a valid G code"),
        ("M[10**300]", "not a valid M code"),
        ("G0 X[SIN[10**200 * 10**200]]", "not finite"),
        ("G0 X[[-1] ** [10**200 * 10**200 - 10**200 * 10**200]]", "not finite"),
        ("G0 X[ROUND[10**200 * 10**200 - 10**200 * 10**200]]", "not finite"),
        ("#[10**200 * 10**200]=1", "not finite"),
        ("G20 G0 X[10**307]", "X1e+307 is out of range"),
        ("G91 G0 Y[10**308]\nY[10**308]", "Y1e+308 is out of range"),
        ("G20 F[10**307]", "feed F1e+307 is out of range"),
        ("F1 G3 X1 I0.5 P[10**308]", "out of range"),
    ],
)
def test_overflow_is_a_program_error(text, message):
    with pytest.raises(NurbsCncError, match=message.replace("+", r"\+")):
        run(text)


@pytest.mark.parametrize("radius", ["[10**300]", "[-10**300]", "[10**153]"])
def test_huge_arc_radius_stays_finite(radius):
    """Regression: a centre far away (r² overflowed to a nan centre) is a finite, almost
    straight arc."""
    (arc,) = segs(f"F60 G2 X1 Y0 R{radius}")
    for value in (arc.center_mm, arc.angle_rad, arc.radius_start_mm, arc.radius_end_mm):
        assert np.all(np.isfinite(value))
    assert math.hypot(*(arc.center_mm - arc.start_mm)) == pytest.approx(arc.radius_start_mm)


# -- canned cycles and cutter compensation in the interpreter ----------------------------
def test_cycle_follows_work_offsets():
    """A G81 under G55 (set by G10 L2) makes the G54 program's moves shifted by the offset:
    cycles.py works in program coordinates, the interpreter maps every move to the machine."""
    body = "G0 X0 Y0 Z10\nG98 G81 X5 Y7 Z-2 R2 F120\nX9\nG80\n"
    plain = segs("G21 G90\n" + body)
    shifted = segs("G21 G90\nG10 L2 P2 X100 Y-50 Z3\nG55\n" + body)
    assert len(plain) == len(shifted) == 9  # rapid to 0,0 and two holes of 4 moves each
    for a, b in zip(plain, shifted):
        assert a.rapid == b.rapid and a.feed_mm_s == b.feed_mm_s
        np.testing.assert_allclose(np.subtract(b.end_mm, a.end_mm), (100, -50, 3), atol=1e-12)
    # LinuxCNC's G81 under G98: rapid to the hole, down to R, feed to Z, rapid back to the
    # initial level (10).
    assert [tuple(s.end_mm) for s in plain[1:5]] == [(5, 7, 10), (5, 7, 2), (5, 7, -2), (5, 7, 10)]
    assert plain[3].rapid is False and plain[3].feed_mm_s == pytest.approx(2.0, rel=1e-15)


def test_comp_inside_square_is_the_offset_square():
    """G41.1 D4 (radius 2) on a counter-clockwise square 0..20 entered from inside: every
    corner is concave, so the tool path is the square 2..18 (closed form), with the entry
    and exit moves to and from the centre line of the first side."""
    got = segs("G21 F600\nG0 X10 Y10\nG41.1 D4 G1 X10 Y0\nX20\nY20\nX0\nY0\nX10\nG40 X10 Y10\n")
    ends = [tuple(round(v, 12) for v in s.end_mm[:2]) for s in got[1:]]
    assert ends == [(12, 2), (18, 2), (18, 18), (2, 18), (2, 2), (10, 2), (10, 10)]
    assert got[-1].start_mm[:2] == (10, 2)  # the exit move leaves the compensated point


@pytest.mark.parametrize(("change", "end"), [("", (10.0, 0.0, -1.0)), ("T1 M6", (10.0, 1.0, -1.0))])
def test_tool_change_after_g40_takes_the_compensated_point(change, end):
    """After G40 LinuxCNC's program position is the programmed point (10, 0) while the tool
    stands at the compensated one (10, 1) (1 mm left of +X); a tool change re-reads the
    position from the machine (refresh_actual_position), so Z-1 then stays at (10, 1)
    (LinuxCNC's nc_files/useful-subroutines.ngc does this)."""
    prog = segs(f"G0 X-10 Y0\nG41.1 D2\nG1 X0 Y0 F600\nG1 X10\nG40\n{change}\nG1 Z-1\nM2\n")
    assert prog[-1].start_mm == (10.0, 1.0, 0.0)
    assert prog[-1].end_mm == end
