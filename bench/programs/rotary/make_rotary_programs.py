"""Generate the rotary (4th-axis) benchmark programs of bench/rotary_bench.py.

    .venv/bin/python bench/programs/rotary/make_rotary_programs.py   # rewrites the .ngc files

- ``wrapped_engraving_g94.ngc`` and ``wrapped_engraving_g93.ngc``: single-stroke text "NURBS"
  and a wave band engraved on a cylinder of radius 20 mm turning on A, as a CAM wrapping
  post writes it: the drawing is made in the unwrapped plane (u along the cylinder = X,
  v around it), its curves chorded at ≤ 0.5 mm (the wave at 1 mm), and each point mapped to
  X = u, A = v / r · 180/π [deg] (Z = r − depth, Z zero on the A axis). The G94 version
  writes F in mm/min (LinuxCNC applies it along X Y Z: a move of X and A runs at F along X,
  capped by A's own speed; a move of A alone at F in deg/min); the G93 version writes each
  move's inverse time F = surface feed / surface length [1/min], so that the tool runs at
  600 mm/min on the part's surface, as 4-axis CAM does. Straight strokes around the cylinder
  (u constant) are moves of A alone.
- ``indexer_a90.ngc``: a 4-face indexer: ``G0 A0/90/180/270`` then a 3-axis cut on each face
  (a rounded-rectangle slot with G1 and G3 at F600, Z plunges and retracts), and back to A0.

Every coordinate is a literal number (no parameters or expressions): tests read the ends of
the moves from the text (tests/test_rotary_bench.py).
"""

from __future__ import annotations

import math
from pathlib import Path

HERE = Path(__file__).resolve().parent
#: Cylinder radius [mm] (Z of its surface above the A axis), engraving depth [mm].
RADIUS_MM = 20.0
DEPTH_MM = 0.2
#: Retract height above the surface [mm]; surface feed [mm/min]; plunge feed [mm/min].
CLEAR_MM = 2.0
FEED_MM_MIN = 600.0
PLUNGE_MM_MIN = 100.0
#: Chord length [mm] of the letters' curves and of the wave.
CHORD_MM = 0.5
WAVE_CHORD_MM = 1.0
#: Letter height (around the cylinder) and width (along it), pitch along X [mm].
LETTER_H_MM = 10.0
LETTER_W_MM = 6.0
PITCH_MM = 8.0
HEADER = "G21 G90 G17 G40 G49 G64 P0.01"


def _arc(cu, cv, r, a0_deg, a1_deg, chord=CHORD_MM):
    """Points of a circular arc in the unwrapped plane (u, v) [mm], a0 → a1 (deg, signed
    sweep), chorded at ≤ ``chord`` (the start point left out)."""
    sweep = math.radians(a1_deg - a0_deg)
    n = max(1, math.ceil(abs(sweep) * r / chord))
    return [
        (
            cu + r * math.cos(math.radians(a0_deg) + sweep * k / n),
            cv + r * math.sin(math.radians(a0_deg) + sweep * k / n),
        )
        for k in range(1, n + 1)
    ]


def letters(x0_mm: float, v0_mm: float) -> list[list[tuple[float, float]]]:
    """Single-stroke "NURBS" in the unwrapped plane: strokes of (u, v) points [mm]."""
    h, w = LETTER_H_MM, LETTER_W_MM
    strokes = []
    for i, ch in enumerate("NURBS"):
        u0 = x0_mm + i * PITCH_MM
        if ch == "N":
            pts = [(0, 0), (0, h), (w, 0), (w, h)]
        elif ch == "U":
            r = w / 2
            pts = [(0, h), (0, r), *_arc(r, r, r, 180, 360), (w, h)]
        elif ch == "R":
            r = 2.5
            pts = [(0, 0), (0, h), (w - r, h), *_arc(w - r, h - r, r, 90, -90), (0, h - 2 * r)]
            pts.append((w, 0))
        elif ch == "B":
            r = 2.5
            pts = [(0, 0), (0, h), (w - 3, h), *_arc(w - 3, h - r, r, 90, -90), (0, h - 2 * r)]
            pts += [(w - 3, h - 2 * r), *_arc(w - 3, r, r, 90, -90), (0, 0)]
        else:  # S: two circles, tangent at their meeting point
            r = 2.5
            c = w / 2
            pts = [_arc(c, h - r, r, 0, 30)[-1], *_arc(c, h - r, r, 30, 270)]
            pts += _arc(c, r, r, 90, -150)
        strokes.append([(u0 + u, v0_mm + v) for u, v in pts])
    return strokes


def wave(x0_mm: float) -> list[tuple[float, float]]:
    """A wave band once around the cylinder: u = x0 + 1.5 sin(6 θ), v = r θ, θ in [0, 2π]."""
    circ = 2 * math.pi * RADIUS_MM
    n = math.ceil(circ / WAVE_CHORD_MM)
    return [(x0_mm + 1.5 * math.sin(6 * 2 * math.pi * k / n), circ * k / n) for k in range(n + 1)]


def _a_deg(v_mm: float) -> float:
    return math.degrees(v_mm / RADIUS_MM)


def engraving(inverse_time: bool) -> str:
    """The wrapped engraving, G94 (F in mm/min) or G93 (inverse time)."""
    z_cut, z_up = RADIUS_MM - DEPTH_MM, RADIUS_MM + CLEAR_MM
    feed_mode = "G93" if inverse_time else "G94"
    out = [
        f"(wrapped engraving on a cylinder r = {RADIUS_MM:g} mm turning on A, {feed_mode}:)",
        "(bench/programs/rotary/make_rotary_programs.py; X along the cylinder, A around it)",
        f"{HEADER} G94",
        f"G0 Z{z_up:.3f}",
    ]
    for stroke in [*letters(0.0, 20.0), wave(50.0)]:
        u, v = stroke[0]
        out.append(f"G0 X{u:.4f} A{_a_deg(v):.4f}")
        plunge = f"G1 Z{z_cut:.3f}"
        if inverse_time:
            out.append(f"G93 {plunge} F{PLUNGE_MM_MIN / (z_up - z_cut):.4f}")
        else:
            out.append(f"{plunge} F{PLUNGE_MM_MIN:g}")
            out.append(f"F{FEED_MM_MIN:g}")
        for un, vn in stroke[1:]:
            move = f"G1 X{un:.4f} A{_a_deg(vn):.4f}"
            if inverse_time:
                surface_mm = math.hypot(un - u, vn - v)
                move += f" F{FEED_MM_MIN / surface_mm:.4f}"
            out.append(move)
            u, v = un, vn
        out.append(f"G94 G0 Z{z_up:.3f}" if inverse_time else f"G0 Z{z_up:.3f}")
    out += ["G0 X0", "M2", ""]
    return "\n".join(out)


def indexer() -> str:
    """Four faces at A = 0, 90, 180, 270: a rounded-rectangle slot (12 × 6 mm, corner radius
    2 mm) cut 0.5 mm deep on each, then back to A0."""
    z_cut, z_up = RADIUS_MM - 0.5, RADIUS_MM + CLEAR_MM
    out = [
        "(4-face indexer: G0 A then a 3-axis slot on each face; r = 20 mm stock)",
        "(bench/programs/rotary/make_rotary_programs.py)",
        f"{HEADER} G94",
        f"G0 Z{z_up:.3f}",
    ]
    for a in (0, 90, 180, 270):
        out += [
            f"G0 A{a}",
            "G0 X2 Y-3",
            f"G1 Z{z_cut:.3f} F{PLUNGE_MM_MIN:g}",
            f"G1 X12 F{FEED_MM_MIN:g}",
            "G3 X14 Y-1 I0 J2",
            "G1 Y1",
            "G3 X12 Y3 I-2 J0",
            "G1 X2",
            "G3 X0 Y1 I0 J-2",
            "G1 Y-1",
            "G3 X2 Y-3 I2 J0",
            f"G0 Z{z_up:.3f}",
        ]
    out += ["G0 X0 Y0 A0", "M2", ""]
    return "\n".join(out)


def main() -> None:
    programs = {
        "wrapped_engraving_g94.ngc": engraving(False),
        "wrapped_engraving_g93.ngc": engraving(True),
        "indexer_a90.ngc": indexer(),
    }
    for name, text in programs.items():
        (HERE / name).write_text(text)


if __name__ == "__main__":
    main()
