"""Generate the three CAM-like benchmark programs of the real-CAM set (bench/programs/*.nc).

Run from the repository root::

    python bench/programs/make_cam_programs.py

All three are what CAM output looks like where a planner suffers most: many short ``G1`` moves
under a granted path tolerance. Rerunning the script reproduces the files byte for byte (the
random segment lengths come from a fixed seed).

``raster_ballnose_g64p01.nc``
    3-D ball-nose raster finishing over the surface
    z(x, y) = −2 + 1.5 sin(2π x / 40) cos(2π y / 50) [mm]: serpentine passes along Y (constant
    X within a pass, so every move lies in a Y-Z plane) of ``RASTER_LENGTH_MM`` in
    ``RASTER_STEP_MM`` chords, a ``RASTER_STEPOVER_MM`` step in X at each end (a raster
    turn-around: two 90° corners, the pass reversed), ``G64 P0.1`` at F2000 in mm.
``pcb_isolation_g64p001_inch.nc``
    PCB isolation routing in inch (``G20``) under ``G64 P0.01``: closed contours around round
    pads and around trace outlines (rounded rectangles), each cut as chords of 0.1–0.5 mm
    (random lengths, as pcb2gcode's polygon offsets are), entered by a rapid at clearance
    height and a plunge; F30 in/min.
``vectric_profile_g64.nc``
    A 2.5-D profile as Vectric Aspire / VCarve's LinuxCNC (mm) post writes it: ``G21``,
    ``G64`` without P, a star and the letters "V" and "W" traced as polylines (curved
    strokes in random chords of 0.2–5 mm, straight strokes as single moves) with sharp
    corners of 20–60°, V-carve spikes out of the star's inner corners and back (the tangent
    reversed by about 170°), three depth passes each entered by a zig-zag ramp (reversals of
    170–178° in 3-D) without retracting between them, a rounded border in ``G3`` arcs with a
    lead-in arc and two ``G2`` counters; F1500, plunges F500.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
GENERATOR = "bench/programs/make_cam_programs.py"

RASTER_LENGTH_MM = 60.0
RASTER_STEP_MM = 0.75
RASTER_STEPOVER_MM = 0.5
RASTER_PASSES = 58
RASTER_FEED_MM_MIN = 2000.0
RASTER_CLEAR_MM = 3.0

PCB_MM_PER_IN = 25.4
PCB_CHORD_MIN_MM = 0.1
PCB_CHORD_MAX_MM = 0.5
PCB_FEED_IN_MIN = 30.0
PCB_DEPTH_IN = -0.002
PCB_CLEAR_IN = 0.04
PCB_SEED = 35


def fmt(value: float, decimals: int = 4) -> str:
    """Fixed point, trailing zeros stripped, no negative zero."""
    text = f"{value:.{decimals}f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def surface_z_mm(x_mm: np.ndarray, y_mm: np.ndarray) -> np.ndarray:
    """The raster's surface height [mm] over (x, y) [mm]."""
    return -2.0 + 1.5 * np.sin(2 * np.pi * x_mm / 40.0) * np.cos(2 * np.pi * y_mm / 50.0)


def raster_program() -> str:
    n_steps = round(RASTER_LENGTH_MM / RASTER_STEP_MM)
    y_mm = np.linspace(0.0, RASTER_LENGTH_MM, n_steps + 1)
    out = [
        "( 3-D ball-nose raster finishing, serpentine passes along Y: make_cam_programs.py )",
        "G21 G17 G90 G64 P0.1",
        f"G0 Z{fmt(RASTER_CLEAR_MM)}",
        "G0 X0 Y0",
        f"G1 Z{fmt(float(surface_z_mm(np.array(0.0), np.array(0.0))))} F600",
        f"F{fmt(RASTER_FEED_MM_MIN)}",
    ]
    for k in range(RASTER_PASSES):
        x = k * RASTER_STEPOVER_MM
        ys = y_mm if k % 2 == 0 else y_mm[::-1]
        zs = surface_z_mm(np.full_like(ys, x), ys)
        if k > 0:
            out.append(f"G1 X{fmt(x)} Z{fmt(float(zs[0]))}")
        out.extend(f"G1 Y{fmt(float(y))} Z{fmt(float(z))}" for y, z in zip(ys[1:], zs[1:]))
    out += [f"G0 Z{fmt(RASTER_CLEAR_MM)}", "M2", ""]
    return "\n".join(out)


def _chop(points_in: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A closed outline [in] resampled into chords of 0.1–0.5 mm (random lengths)."""
    closed = np.vstack([points_in, points_in[:1]])
    seg = np.hypot(*np.diff(closed, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    total = s[-1]
    lo, hi = PCB_CHORD_MIN_MM / PCB_MM_PER_IN, PCB_CHORD_MAX_MM / PCB_MM_PER_IN
    steps = rng.uniform(lo, hi, size=int(total / lo) + 2)
    stations = np.cumsum(steps)
    stations = np.concatenate([[0.0], stations[stations < total - lo], [total]])
    return np.column_stack([np.interp(stations, s, closed[:, i]) for i in range(2)])


def _pad(cx: float, cy: float, r: float) -> np.ndarray:
    t = np.linspace(0.0, 2 * np.pi, 720, endpoint=False)
    return np.column_stack([cx + r * np.cos(t), cy + r * np.sin(t)])


def _trace(x0: float, y0: float, x1: float, y1: float, r: float) -> np.ndarray:
    """A rounded rectangle [in] (corner radius r) from (x0, y0) to (x1, y1), CCW."""
    parts = []
    corners = ((x1 - r, y0 + r, -np.pi / 2), (x1 - r, y1 - r, 0.0))
    corners += ((x0 + r, y1 - r, np.pi / 2), (x0 + r, y0 + r, np.pi))
    for cx, cy, a0 in corners:
        t = np.linspace(a0, a0 + np.pi / 2, 90)
        parts.append(np.column_stack([cx + r * np.cos(t), cy + r * np.sin(t)]))
    return np.vstack(parts)


def pcb_program() -> str:
    rng = np.random.default_rng(PCB_SEED)
    outlines = [_pad(0.1 + 0.15 * i, 0.1, 0.045) for i in range(6)]
    outlines += [_pad(0.1 + 0.15 * i, 0.6, 0.045) for i in range(6)]
    outlines += [_trace(0.05, 0.22, 0.95, 0.30, 0.02), _trace(0.05, 0.40, 0.95, 0.48, 0.02)]
    out = [
        "( PCB isolation routing, chords of 0.1-0.5 mm: make_cam_programs.py )",
        "G20 G17 G90 G64 P0.01",
        f"G0 Z{fmt(PCB_CLEAR_IN)}",
    ]
    for outline in outlines:
        pts = _chop(outline, rng)
        out.append(f"G0 X{fmt(float(pts[0, 0]), 5)} Y{fmt(float(pts[0, 1]), 5)}")
        out.append(f"G1 Z{fmt(PCB_DEPTH_IN, 5)} F10")
        out.append(f"F{fmt(PCB_FEED_IN_MIN)}")
        out.extend(f"G1 X{fmt(float(x), 5)} Y{fmt(float(y), 5)}" for x, y in pts[1:])
        out.append(f"G0 Z{fmt(PCB_CLEAR_IN)}")
    out += ["M2", ""]
    return "\n".join(out)


VEC_FEED_MM_MIN = 1500.0
VEC_PLUNGE_MM_MIN = 500.0
VEC_SAFE_MM = 5.0
VEC_DEPTHS_MM = (-1.0, -2.0, -3.0)
VEC_RAMP_MM = 6.0
VEC_SPIKE_MM = 1.2
VEC_SEED = 21


def _chords(points_mm: np.ndarray, rng: np.random.Generator, lo: float, hi: float):
    """An open curve [mm] (dense samples, (n, 2)) as chords of ``lo``–``hi`` mm (random
    lengths, the ends kept): a vector trace of a curved stroke."""
    seg = np.hypot(*np.diff(points_mm, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    stations = np.cumsum(rng.uniform(lo, hi, size=int(s[-1] / lo) + 2))
    stations = np.concatenate([[0.0], stations[stations < s[-1] - 0.5 * lo], [s[-1]]])
    return np.column_stack([np.interp(stations, s, points_mm[:, i]) for i in range(2)])


def _star(cx: float, cy: float, rng: np.random.Generator) -> tuple[np.ndarray, list[int]]:
    """A five-pointed star [mm] (tips of about 40°) whose flanks bow slightly outward,
    traced as chords, closed; and the indices of its inner (concave) corners."""
    r_out, r_in, n = 16.0, 7.0, 5
    pts, inner = [np.array([[cx + r_out, cy]])], []
    t = np.linspace(0.0, 1.0, 80)[:, None]
    for k in range(2 * n):
        ra, rb = (r_out, r_in) if k % 2 == 0 else (r_in, r_out)
        aa, ab = np.pi * k / n, np.pi * (k + 1) / n
        p = np.array([cx + ra * np.cos(aa), cy + ra * np.sin(aa)])
        q = np.array([cx + rb * np.cos(ab), cy + rb * np.sin(ab)])
        normal = np.array([q[1] - p[1], p[0] - q[0]])
        pts.append(_chords(p + t * (q - p) - 0.04 * np.sin(np.pi * t) * normal, rng, 0.2, 2.5)[1:])
        if k % 2 == 0:
            inner.append(sum(len(x) for x in pts) - 1)
    return np.vstack(pts), inner


def _letter_v(x0: float, y0: float) -> np.ndarray:
    """The outline [mm] of a serif-less "V" 22 mm tall (straight strokes: single moves; a
    30° apex outside, a 28° notch inside), closed."""
    return np.array(
        [[0, 22], [4, 22], [9, 5.5], [14, 22], [18, 22], [11, 0], [7, 0], [0, 22]], float
    ) + [x0, y0]


def _letter_w(x0: float, y0: float, rng: np.random.Generator) -> np.ndarray:
    """The outline [mm] of a "W" 22 mm tall whose outer strokes curve (traced as chords)
    and whose inner strokes are straight, sharp corners of 20–60°, closed."""
    corners = np.array(
        [
            [0, 22],
            [4, 22],
            [8, 6],
            [12, 18],
            [16, 18],
            [20, 6],
            [24, 22],
            [28, 22],
            [22, 0],
            [18, 0],
            [14, 13],
            [10, 0],
            [6, 0],
            [0, 22],
        ],
        float,
    ) + [x0, y0]
    out = [corners[:1]]
    t = np.linspace(0.0, 1.0, 60)[:, None]
    for k, (p, q) in enumerate(zip(corners[:-1], corners[1:])):
        if k in (1, 5, 7, 12):  # the curved strokes
            normal = np.array([q[1] - p[1], p[0] - q[0]])
            out.append(
                _chords(p + t * (q - p) + 0.06 * np.sin(np.pi * t) * normal, rng, 0.3, 5.0)[1:]
            )
        else:
            out.append(q[None, :])
    return np.vstack(out)


def _xy(p) -> str:
    return f"X{fmt(float(p[0]), 3)} Y{fmt(float(p[1]), 3)}"


def _ramp_in(out: list, pts: np.ndarray, z_from: float, z_to: float) -> None:
    """A zig-zag ramp from ``z_from`` to ``z_to`` along the outline's start: forward over
    :data:`VEC_RAMP_MM` (its first moves) and back, twice, each leg a quarter of the
    descent (the tangent reversed by about 170° in 3-D at each turn), ending at the start."""
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    k = max(int(np.searchsorted(s, VEC_RAMP_MM)), 1)
    leg = pts[: k + 1]
    z = np.linspace(z_from, z_to, 5)
    for n in range(4):
        path = leg[1:] if n % 2 == 0 else leg[::-1][1:]
        frac = s[1 : k + 1] / s[k]
        zs = z[n] + (z[n + 1] - z[n]) * frac
        out.extend(f"G1 {_xy(p)} Z{fmt(float(zz), 3)}" for p, zz in zip(path, zs))


def _profile(out: list, pts: np.ndarray, spikes: list[int], label: str) -> None:
    """One closed outline cut at every depth of :data:`VEC_DEPTHS_MM`, entered by a plunge
    to the surface and a zig-zag ramp per pass, V-carve spikes at ``spikes`` (out of the
    corner along the incoming direction and back, rising :data:`VEC_SPIKE_MM`/4)."""
    out += [
        f"( {label} )",
        f"G0 Z{fmt(VEC_SAFE_MM)}",
        f"G0 {_xy(pts[0])}",
        "G0 Z1",
        f"G1 Z0 F{fmt(VEC_PLUNGE_MM_MIN)}",
        f"F{fmt(VEC_FEED_MM_MIN)}",
    ]
    z_prev = 0.0
    for depth in VEC_DEPTHS_MM:
        _ramp_in(out, pts, z_prev, depth)
        for i in range(1, len(pts)):
            out.append(f"G1 {_xy(pts[i])}")
            if i in spikes and i + 1 < len(pts):
                u = pts[i] - pts[i - 1]
                u /= np.hypot(*u)
                w = pts[i + 1] - pts[i]
                w /= np.hypot(*w)
                tip = pts[i] + VEC_SPIKE_MM * u
                back = pts[i] + 0.2 * w
                out.append(f"G1 {_xy(tip)} Z{fmt(depth + 0.25 * VEC_SPIKE_MM, 3)}")
                out.append(f"G1 {_xy(back)} Z{fmt(depth, 3)}")
        z_prev = depth
    out.append(f"G0 Z{fmt(VEC_SAFE_MM)}")


def _border(out: list) -> None:
    """A rounded rectangle 100 × 40 mm (corner radius 5, ``G3`` arcs) entered by a lead-in
    arc, two depth passes with a ramp along its bottom edge; and two round counters (``G2``
    full circles in halves)."""
    out += [
        "( Profile border )",
        f"G0 Z{fmt(VEC_SAFE_MM)}",
        "G0 X50 Y-14",
        "G0 Z1",
        f"G1 Z0 F{fmt(VEC_PLUNGE_MM_MIN)}",
    ]
    for depth in VEC_DEPTHS_MM[:2]:
        out += [f"G1 X56 Y-14 Z{fmt(depth)} F{fmt(VEC_FEED_MM_MIN)}", "G1 X50 Y-14"]
        out += [
            "G3 X55 Y-9 I0 J5",
            "G1 X95",
            "G3 X100 Y-4 I0 J5",
            "G1 Y26",
            "G3 X95 Y31 I-5 J0",
            "G1 X5",
            "G3 X0 Y26 I0 J-5",
            "G1 Y-4",
            "G3 X5 Y-9 I5 J0",
            "G1 X55",
            "G3 X50 Y-14 I0 J-5",
        ]
    out.append(f"G0 Z{fmt(VEC_SAFE_MM)}")
    for cx in (78.0, 90.0):
        out += [
            f"( Counter X{fmt(cx)} )",
            f"G0 X{fmt(cx + 3)} Y11",
            "G0 Z1",
            f"G1 Z-1.5 F{fmt(VEC_PLUNGE_MM_MIN)}",
            f"G2 X{fmt(cx - 3)} Y11 I-3 J0 F{fmt(VEC_FEED_MM_MIN)}",
            f"G2 X{fmt(cx + 3)} Y11 I3 J0",
            f"G0 Z{fmt(VEC_SAFE_MM)}",
        ]


def vectric_program() -> str:
    rng = np.random.default_rng(VEC_SEED)
    star, inner = _star(18.0, 11.0, rng)
    out = [
        "( VECTRIC POST REVISION: a 2.5-D profile generated by make_cam_programs.py )",
        "( Tool: End Mill 3 mm, Safe Z 5 mm )",
        "G00 G21 G17 G90 G40 G49 G80",
        "G64",
        "T1 M06",
        f"G00 Z{fmt(VEC_SAFE_MM)}",
        "G00 X0 Y0 S16000 M03",
    ]
    _profile(out, star, inner, "Profile star")
    _profile(out, _letter_v(38.0, 0.0), [], "Profile V")
    _profile(out, _letter_w(60.0, 0.0, rng), [], "Profile W")
    _border(out)
    out += ["G00 X0 Y0", "M05", "M02", ""]
    return "\n".join(out)


def main() -> None:
    (HERE / "raster_ballnose_g64p01.nc").write_text(raster_program())
    (HERE / "pcb_isolation_g64p001_inch.nc").write_text(pcb_program())
    (HERE / "vectric_profile_g64.nc").write_text(vectric_program())


if __name__ == "__main__":
    main()
