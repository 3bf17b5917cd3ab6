"""Generate the two CAM-like benchmark programs of the real-CAM set (bench/programs/*.nc).

Run from the repository root::

    python bench/programs/make_cam_programs.py

Both are what CAM output looks like where a planner suffers most: many short ``G1`` moves
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


def main() -> None:
    (HERE / "raster_ballnose_g64p01.nc").write_text(raster_program())
    (HERE / "pcb_isolation_g64p001_inch.nc").write_text(pcb_program())


if __name__ == "__main__":
    main()
