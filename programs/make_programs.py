"""Generate the bundled sample G-code programs (SPEC §9).

Run from the repository root::

    python programs/make_programs.py

It (re)writes, next to this script:

``naca2415.nc``
    The paper's benchmark: the NACA 2415 airfoil, chord 9 mm, as one closed cubic NURBS (G6.2)
    from the trailing edge over the upper surface to the leading edge and back along the lower
    surface, F3500 (V_max of Table 3).
``naca2415_rot45.nc``, ``naca2415_rot-45.nc``
    The same control points rotated about the origin by +45° and −45° (Table 5).
``naca2415_c40.nc``
    The same airfoil with a 40 mm chord (SPEC §9: "also run larger ones").
``butterfly.nc``
    A smooth closed butterfly curve about 50 mm wide as one cubic NURBS, F2000.
``corners.nc``
    Lines and arcs (G1/G2/G3) with sharp corners under ``G64 P0.01``, for corner blending.

Construction of the NURBS programs: a cubic interpolating B-spline (all weights 1) through
sample points, parametrised by normalised cumulative chord length, built with
``scipy.interpolate.make_interp_spline(k=3)``. Its knot vector is clamped (k + 1 = 4 equal end
knots) and its interior knots are the data parameters (not-a-knot end conditions), so the curve
passes through every sample point and starts/ends exactly on the first/last one.

Output format (Fanuc / LinuxCNC style G6.2, mm, XY plane): the first block ``G6.2 P4`` carries
knot 0, control point 0 and its weight ``R``; every further control point i is one block with
knot i; after the last control point come ``order`` (= 4) knot-only blocks with the remaining
knots, so knots = control points + 4. A ``G0`` to the first control point precedes the G6.2 so
the curve starts at the current position; both are printed from the same string.

Numbers are printed in fixed-point notation with 12 decimals and trailing zeros stripped
(G-code has no exponent notation): the rounding is below 5e-13 mm, far under the 1e-9 mm the
tests ask for. The output depends only on numpy/scipy arithmetic, so rerunning the script
reproduces the committed files byte for byte (``tests/test_programs.py`` checks this).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.interpolate import make_interp_spline

GENERATOR = "programs/make_programs.py"

#: NACA 2415: maximum camber m, its position p, thickness t (fractions of the chord).
NACA_M, NACA_P, NACA_T = 0.02, 0.4, 0.15
#: Thickness polynomial coefficients (x^0.5, x, x^2, x^3, x^4), closed trailing edge (SPEC §9).
NACA_THICKNESS_COEFFS = (0.2969, -0.1260, -0.3516, 0.2843, -0.1036)
#: Cosine-spaced samples per surface (trailing edge and leading edge included).
AIRFOIL_SAMPLES_PER_SURFACE = 40
AIRFOIL_FEED_MM_MIN = 3500.0  # V_max of Table 3
#: Butterfly r(t) = e^{cos t} - 2 cos 4t sampled at this many equal steps of t over [0, 2π].
BUTTERFLY_SAMPLES = 360
#: mm per unit of r: the curve's x extent is 2 × 2.906 units, so it is 50 mm wide.
BUTTERFLY_SCALE_MM = 8.6
BUTTERFLY_FEED_MM_MIN = 2000.0
CORNERS_FEED_MM_MIN = 3000.0
DECIMALS = 12


# --------------------------------------------------------------------------- number format


def fmt(value: float, decimals: int = DECIMALS) -> str:
    """``value`` in fixed-point G-code notation: ``decimals`` places, trailing zeros stripped.

    ``-0`` (a tiny negative rounded away) prints as ``0``.
    """
    text = f"{value:.{decimals}f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


# --------------------------------------------------------------------------- NACA 4-digit


def naca_thickness(x: np.ndarray) -> np.ndarray:
    """Half thickness y_t(x) for unit chord, closed trailing edge (SPEC §9)."""
    a0, a1, a2, a3, a4 = NACA_THICKNESS_COEFFS
    x = np.asarray(x, dtype=float)
    return 5.0 * NACA_T * (a0 * np.sqrt(x) + a1 * x + a2 * x**2 + a3 * x**3 + a4 * x**4)


def naca_camber(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Camber line y_c(x) and its slope dy_c/dx for unit chord (SPEC §9)."""
    m, p = NACA_M, NACA_P
    x = np.asarray(x, dtype=float)
    front = x < p
    yc_front = m / p**2 * (2 * p * x - x**2)
    yc_back = m / (1 - p) ** 2 * ((1 - 2 * p) + 2 * p * x - x**2)
    yc = np.where(front, yc_front, yc_back)
    dyc = np.where(front, 2 * m / p**2 * (p - x), 2 * m / (1 - p) ** 2 * (p - x))
    return yc, dyc


def naca_surface(x: np.ndarray, upper: bool) -> np.ndarray:
    """Surface points (k, 2) for unit chord: y_t offset along the camber normal (SPEC §9).

    Upper: (x − y_t sin θ, y_c + y_t cos θ); lower: (x + y_t sin θ, y_c − y_t cos θ),
    θ = atan(dy_c/dx).
    """
    yt = naca_thickness(x)
    yc, dyc = naca_camber(x)
    theta = np.arctan(dyc)
    sign = 1.0 if upper else -1.0
    return np.column_stack([x - sign * yt * np.sin(theta), yc + sign * yt * np.cos(theta)])


def airfoil_points_mm(
    chord_mm: float, per_surface: int = AIRFOIL_SAMPLES_PER_SURFACE
) -> np.ndarray:
    """Closed sample polygon (2·per_surface − 1, 2) [mm]: TE → upper → LE → lower → TE.

    x = (1 − cos θ)/2 with θ equally spaced on [0, π] (dense at both edges). The leading edge
    (0, 0) is shared by both surfaces and appears once, at index per_surface − 1. At x = 1 the
    closed-form y_t and y_c are exactly 0 but floating point leaves ~1e-16; the trailing edge is
    set to exactly (chord, 0) so the curve starts and ends on the same point bitwise.
    """
    x = 0.5 * (1.0 - np.cos(np.linspace(0.0, np.pi, per_surface)))
    upper = naca_surface(x[::-1], upper=True)  # TE → LE
    lower = naca_surface(x[1:], upper=False)  # LE (excluded, already in upper) → TE
    pts = np.vstack([upper, lower])
    pts[0] = pts[-1] = (1.0, 0.0)
    return chord_mm * pts


# --------------------------------------------------------------------------- butterfly


def butterfly_curve(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Point and derivative d/dt [mm] of the butterfly x = r sin t, y = r cos t.

    r(t) = e^{cos t} − 2 cos 4t (Fay's butterfly without its non-periodic sin^5(t/12) term,
    so one period t ∈ [0, 2π] is a closed curve), scaled by BUTTERFLY_SCALE_MM.
    """
    t = np.asarray(t, dtype=float)
    r = np.exp(np.cos(t)) - 2.0 * np.cos(4.0 * t)
    dr = -np.sin(t) * np.exp(np.cos(t)) + 8.0 * np.sin(4.0 * t)
    point = np.column_stack([r * np.sin(t), r * np.cos(t)])
    deriv = np.column_stack([dr * np.sin(t) + r * np.cos(t), dr * np.cos(t) - r * np.sin(t)])
    return BUTTERFLY_SCALE_MM * point, BUTTERFLY_SCALE_MM * deriv


def butterfly_points_mm(samples: int = BUTTERFLY_SAMPLES) -> np.ndarray:
    """Closed sample polygon (samples + 1, 2) [mm] at equal steps of t; last point = first."""
    pts, _ = butterfly_curve(np.linspace(0.0, 2.0 * np.pi, samples + 1))
    pts[-1] = pts[0]  # sin/cos(2π) are not exactly 0/1 in floating point
    return pts


# --------------------------------------------------------------------------- spline fitting


def chord_length_parameters(points: np.ndarray) -> np.ndarray:
    """Normalised cumulative chord length u_j ∈ [0, 1] of a polygon (k, 2)."""
    steps = np.hypot(*np.diff(points, axis=0).T)
    u = np.concatenate([[0.0], np.cumsum(steps)])
    return u / u[-1]


def interpolating_cubic(points: np.ndarray, end_tangent: np.ndarray | None = None):
    """Cubic interpolating B-spline through ``points`` (k, 2), chord-length parametrised.

    Returns ``(knots, control_points)``: knots (n + 4,) clamped on [0, 1], control points (n, 2).
    Without ``end_tangent`` the ends are not-a-knot (n = k). With it (a direction, used for a
    smooth closed curve) both end derivatives are set to that unit tangent times the polygon's
    length, i.e. about the arc-length speed of the chord-length parameter, which closes the
    curve with a continuous first derivative (n = k + 2).
    """
    u = chord_length_parameters(points)
    if end_tangent is None:
        spline = make_interp_spline(u, points, k=3)
    else:
        length_mm = float(np.sum(np.hypot(*np.diff(points, axis=0).T)))
        d_mm = np.asarray(end_tangent, dtype=float)
        d_mm = d_mm / np.linalg.norm(d_mm) * length_mm
        spline = make_interp_spline(u, points, k=3, bc_type=([(1, d_mm)], [(1, d_mm)]))
    knots = (spline.t - spline.t[0]) / (spline.t[-1] - spline.t[0])
    return knots, np.asarray(spline.c, dtype=float)


def rotate_mm(points: np.ndarray, angle_deg: float) -> np.ndarray:
    """Points (n, 2) rotated counter-clockwise about the origin by ``angle_deg``."""
    a = np.deg2rad(angle_deg)
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    return points @ rot.T


# --------------------------------------------------------------------------- G-code text


def nurbs_program(title: str, knots: np.ndarray, control_mm: np.ndarray, feed_mm_min: float) -> str:
    """A complete G6.2 program (text, '\\n' line ends) for a cubic, unit-weight NURBS."""
    order = 4
    n = len(control_mm)
    if len(knots) != n + order:
        raise ValueError(f"{len(knots)} knots for {n} control points of order {order}")
    xs = [fmt(v) for v in control_mm[:, 0]]
    ys = [fmt(v) for v in control_mm[:, 1]]
    ks = [fmt(v) for v in knots]
    lines = [
        f"; {title} (generated by {GENERATOR})",
        "G21 G17 G90 G94",
        f"G0 X{xs[0]} Y{ys[0]}",
        f"F{fmt(feed_mm_min)}",
        f"G6.2 P{order} K{ks[0]} X{xs[0]} Y{ys[0]} R1",
    ]
    lines += [f"K{ks[i]} X{xs[i]} Y{ys[i]} R1" for i in range(1, n)]
    lines += [f"K{k}" for k in ks[n:]]
    lines.append("M2")
    return "\n".join(lines) + "\n"


def airfoil_program(chord_mm: float, angle_deg: float = 0.0) -> str:
    """The NACA 2415 program at ``chord_mm``, control points rotated by ``angle_deg``."""
    knots, control_mm = interpolating_cubic(airfoil_points_mm(chord_mm))
    title = f"NACA 2415, chord {fmt(chord_mm)} mm"
    if angle_deg:
        control_mm = rotate_mm(control_mm, angle_deg)
        title += f", rotated {angle_deg:+g} deg about the origin"
    title += ", cubic interpolating NURBS"
    return nurbs_program(title, knots, control_mm, AIRFOIL_FEED_MM_MIN)


def butterfly_program() -> str:
    """The butterfly as one closed cubic NURBS, smooth (C1) across its start/end point."""
    _, tangent_mm = butterfly_curve(np.array([0.0]))
    knots, control_mm = interpolating_cubic(butterfly_points_mm(), end_tangent=tangent_mm[0])
    title = (
        "Butterfly r = exp(cos t) - 2 cos 4t, x = r sin t, y = r cos t, t in [0, 2pi], "
        f"x{fmt(BUTTERFLY_SCALE_MM)} mm, closed cubic interpolating NURBS"
    )
    return nurbs_program(title, knots, control_mm, BUTTERFLY_FEED_MM_MIN)


def star_vertices_mm(
    center_mm=(70.0, 20.0), outer_mm: float = 15.0, inner_mm: float = 6.0
) -> np.ndarray:
    """The 10 vertices (10, 2) of a five-pointed star, first one at the top, counter-clockwise."""
    angle = np.deg2rad(90.0 + 36.0 * np.arange(10))
    radius = np.where(np.arange(10) % 2 == 0, outer_mm, inner_mm)
    return np.asarray(center_mm) + radius[:, None] * np.column_stack([np.cos(angle), np.sin(angle)])


def corners_program() -> str:
    """Lines and arcs with sharp and tangent corners, under G64 P0.01 (text)."""
    star = [f"X{fmt(x, 4)} Y{fmt(y, 4)}" for x, y in star_vertices_mm()]
    lines = [
        f"; Corner test: G1/G2/G3 shapes with sharp corners, G64 P0.01 (generated by {GENERATOR})",
        "; G64 P0.01: corners between moves may be blended, staying within 0.01 mm of the path",
        "G21 G17 G90 G94",
        "G64 P0.01",
        "F3000",
        "; Shape 1: 40 x 20 mm rectangle whose right side is a half circle (G3, centre 30 10,",
        "; R10). The arc joins the lines tangentially; the left corners are sharp 90 deg turns.",
        "G0 X0 Y0",
        "G1 X30 Y0",
        "G3 X30 Y20 I0 J10",
        "G1 X0 Y20",
        "G1 X0 Y0",
        "; Shape 2: 20 x 20 mm square with a concave top: a clockwise arc (G2, centre 10 57.5,",
        "; R12.5, dipping to Y45) that meets both vertical sides at non-tangent corners.",
        "G0 X0 Y30",
        "G1 X20 Y30",
        "G1 X20 Y50",
        "G2 X0 Y50 I-10 J7.5",
        "G1 X0 Y30",
        "; Shape 3: five-pointed star polyline, centre 70 20, tip radius 15, notch radius 6:",
        "; ten sharp corners: five convex tips and five reflex notches.",
        f"G0 {star[0]}",
    ]
    lines += [f"G1 {v}" for v in star[1:]]
    lines += [f"G1 {star[0]}", "M2"]
    return "\n".join(lines) + "\n"


def build_programs() -> dict[str, str]:
    """File name → program text for every bundled program."""
    return {
        "naca2415.nc": airfoil_program(9.0),
        "naca2415_rot45.nc": airfoil_program(9.0, 45.0),
        "naca2415_rot-45.nc": airfoil_program(9.0, -45.0),
        "naca2415_c40.nc": airfoil_program(40.0),
        "butterfly.nc": butterfly_program(),
        "corners.nc": corners_program(),
    }


def write_programs(out_dir, programs: dict[str, str] | None = None) -> list[Path]:
    """Write every program (``programs``: name → text; default :func:`build_programs`) into
    ``out_dir`` (ASCII, '\\n' line ends); return the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, text in (build_programs() if programs is None else programs).items():
        path = out / name
        path.write_text(text, encoding="ascii", newline="\n")
        paths.append(path)
    return paths


if __name__ == "__main__":
    for written in write_programs(Path(__file__).resolve().parent):
        print(written)
