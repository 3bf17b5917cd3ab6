"""Generate the planner benchmark programs of issue 13 (bench/programs/*.nc).

Run from the repository root::

    python bench/programs/make_bench_programs.py

The 9 mm NACA 2415 block at 0°, +45° and −45° is not copied here: the benchmark uses the
bundled ``programs/naca2415.nc``, ``programs/naca2415_rot45.nc`` and
``programs/naca2415_rot-45.nc`` (made by ``programs/make_programs.py``). This script writes:

``naca2415_g52.nc``
    The same 9 mm airfoil as a LinuxCNC ``G5.2 … G5.3`` cubic NURBS (``L4``) with control
    points printed to 6 decimals. G5.2 has no knot words: LinuxCNC implies a clamped uniform
    knot vector, so the interpolating spline of the G6.2 file (knots at the chord-length
    parameters) cannot be copied; instead a cubic B-spline on the uniform knots is fitted by
    least squares to the closed-form airfoil (2000 cosine-spaced points per surface) with the
    sample index as parameter, so the uniform knots are dense where the samples are: at the
    leading and trailing edges. The fit stays within ``G52_FIT_TOL_MM`` of the closed form (it
    is checked when the file is written). Then every control point is rounded to 6 decimals,
    as CAM output is: the curve moves by at most 0.5 µm·√2, but its curvature gets ripples.
``naca2415_g52_rot45.nc``, ``naca2415_g52_rot-45.nc``
    The same G5.2 airfoil rotated by ±45° about the origin (control points rotated, then
    rounded). LinuxCNC 2.9 has no G6.2, so these G5.2 files are what LinuxCNC runs for the
    side-by-side figures of the three airfoil blocks.
``pentagram_g61.nc``, ``pentagram_g64p002.nc``
    A pentagram {5/2} of five 38 mm edges, centre at the origin, first vertex at the top
    (0, R) with R = 19 / sin 72° ≈ 19.98 mm, reached by a ``G0`` from the origin (the rapid is
    part of the cycle time), then five ``G1`` edges at F3500, under ``G61`` and ``G64 P0.02``.
``square_g61_f1000.nc``, ``square_g61_f3000.nc``
    A 20 mm square from the origin, counter-clockwise, under ``G61``, at F1000 and F3000 (a
    higher programmed feed must never give a longer cycle time).

Coordinates are printed with ``fmt`` of programs/make_programs.py (fixed point, trailing zeros
stripped); rerunning the script reproduces the files byte for byte.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
from scipy.interpolate import BSpline, make_lsq_spline

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
GENERATOR = "bench/programs/make_bench_programs.py"

#: Control points of the G5.2 airfoil (a cubic: knots = points + 4).
G52_CONTROL_POINTS = 80
G52_ORDER = 4
G52_DECIMALS = 6
G52_FIT_SAMPLES_PER_SURFACE = 2000
#: Largest allowed distance [mm] of the unrounded fit from the closed-form airfoil samples.
G52_FIT_TOL_MM = 1e-3
PENTAGRAM_EDGE_MM = 38.0
PENTAGRAM_FEED_MM_MIN = 3500.0
SQUARE_EDGE_MM = 20.0


def _bundled_generator():
    """programs/make_programs.py as a module (its airfoil and number format are reused)."""
    path = ROOT / "programs" / "make_programs.py"
    spec = importlib.util.spec_from_file_location("make_programs", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


MP = _bundled_generator()


def uniform_clamped_knots(n_points: int, order: int) -> np.ndarray:
    """LinuxCNC's implied G5.2 knot vector, scaled to [0, 1] (clamped, uniform)."""
    inner = np.linspace(0.0, 1.0, n_points - order + 2)
    return np.concatenate([np.zeros(order - 1), inner, np.ones(order - 1)])


def g52_airfoil_control_mm(chord_mm: float = 9.0) -> np.ndarray:
    """Control points (n, 2) [mm] of the uniform-knot cubic fitted to the airfoil (module doc).

    The first and last control points are the trailing edge exactly (the fit's end points are
    pinned by weighting them 1e6 times the others, then set bitwise).
    """
    pts = MP.airfoil_points_mm(chord_mm, per_surface=G52_FIT_SAMPLES_PER_SURFACE)
    u = np.linspace(0.0, 1.0, len(pts))  # sample index: dense at both edges like the samples
    knots = uniform_clamped_knots(G52_CONTROL_POINTS, G52_ORDER)
    w = np.ones(len(pts))
    w[[0, -1]] = 1e6
    spline = make_lsq_spline(u, pts, knots, k=G52_ORDER - 1, w=w)
    control = np.array(spline.c, dtype=float)
    control[0] = control[-1] = pts[0]
    fit = BSpline(knots, control, G52_ORDER - 1)(u)
    err_mm = float(np.max(np.hypot(*(fit - pts).T)))
    if err_mm > G52_FIT_TOL_MM:
        raise RuntimeError(f"G5.2 airfoil fit {err_mm * 1e3:.2f} µm from the airfoil")
    return control


def g52_airfoil_program(chord_mm: float = 9.0, angle_deg: float = 0.0) -> str:
    """The 9 mm NACA 2415 as ``G5.2 … G5.3`` (L4, weights P1), 6-decimal control points,
    rotated about the origin by ``angle_deg``."""
    control = g52_airfoil_control_mm(chord_mm)
    rotated = ""
    if angle_deg:
        control = MP.rotate_mm(control, angle_deg)
        rotated = f", rotated {angle_deg:+g} deg about the origin"
    xy = [(MP.fmt(x, G52_DECIMALS), MP.fmt(y, G52_DECIMALS)) for x, y in control]
    lines = [
        f"; NACA 2415, chord {MP.fmt(chord_mm)} mm{rotated}, as a LinuxCNC G5.2 cubic NURBS "
        f"(L4, uniform knots), {len(xy)} control points to {G52_DECIMALS} decimals "
        f"(generated by {GENERATOR})",
        "G21 G17 G90 G94",
        f"G0 X{xy[0][0]} Y{xy[0][1]}",
        f"F{MP.fmt(MP.AIRFOIL_FEED_MM_MIN)}",
        # the current point is control point 0; the G5.2 line carries control point 1
        f"G5.2 X{xy[1][0]} Y{xy[1][1]} P1 L{G52_ORDER}",
    ]
    lines += [f"X{x} Y{y} P1" for x, y in xy[2:]]
    lines += ["G5.3", "M2"]
    return "\n".join(lines) + "\n"


def pentagram_vertices_mm(edge_mm: float = PENTAGRAM_EDGE_MM) -> np.ndarray:
    """The 6 points (6, 2) of the pentagram stroke: vertices 0, 2, 4, 1, 3, 0 of a pentagon.

    A pentagram edge joins every second vertex of a regular pentagon of circumradius R: it is
    the chord over 144°, 2 R sin 72° = edge, so R = edge / (2 sin 72°).
    """
    radius_mm = edge_mm / (2.0 * np.sin(np.deg2rad(72.0)))
    order = np.array([0, 2, 4, 1, 3, 0])
    angle = np.deg2rad(90.0 + 72.0 * order)
    return radius_mm * np.column_stack([np.cos(angle), np.sin(angle)])


def pentagram_program(mode: str) -> str:
    """The pentagram at F3500 under the path-control ``mode`` (``G61`` or ``G64 P0.02``)."""
    v = [(MP.fmt(x, 6), MP.fmt(y, 6)) for x, y in pentagram_vertices_mm()]
    lines = [
        f"; Pentagram, five {MP.fmt(PENTAGRAM_EDGE_MM)} mm edges, "
        f"F{MP.fmt(PENTAGRAM_FEED_MM_MIN)}, {mode}, rapid from the origin to the first vertex "
        f"(generated by {GENERATOR})",
        "G21 G17 G90 G94",
        mode,
        "G0 X0 Y0",
        f"G0 X{v[0][0]} Y{v[0][1]}",
        f"F{MP.fmt(PENTAGRAM_FEED_MM_MIN)}",
    ]
    lines += [f"G1 X{x} Y{y}" for x, y in v[1:]]
    lines.append("M2")
    return "\n".join(lines) + "\n"


def square_program(feed_mm_min: float) -> str:
    """A 20 mm square from the origin under G61 at ``feed_mm_min``."""
    e = MP.fmt(SQUARE_EDGE_MM)
    lines = [
        f"; {e} mm square, G61, F{MP.fmt(feed_mm_min)} (generated by {GENERATOR})",
        "G21 G17 G90 G94",
        "G61",
        "G0 X0 Y0",
        f"F{MP.fmt(feed_mm_min)}",
        f"G1 X{e} Y0",
        f"G1 X{e} Y{e}",
        f"G1 X0 Y{e}",
        "G1 X0 Y0",
        "M2",
    ]
    return "\n".join(lines) + "\n"


def build_programs() -> dict[str, str]:
    """File name → program text for every generated benchmark program."""
    return {
        "naca2415_g52.nc": g52_airfoil_program(9.0),
        "naca2415_g52_rot45.nc": g52_airfoil_program(9.0, 45.0),
        "naca2415_g52_rot-45.nc": g52_airfoil_program(9.0, -45.0),
        "pentagram_g61.nc": pentagram_program("G61"),
        "pentagram_g64p002.nc": pentagram_program("G64 P0.02"),
        "square_g61_f1000.nc": square_program(1000.0),
        "square_g61_f3000.nc": square_program(3000.0),
    }


def write_programs(out_dir=HERE) -> list[Path]:
    """Write every benchmark program into ``out_dir`` (programs/make_programs.py's writer:
    ASCII, '\\n' line ends); return the paths."""
    return MP.write_programs(out_dir, build_programs())


if __name__ == "__main__":
    for written in write_programs():
        print(written)
