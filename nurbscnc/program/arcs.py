"""Arc centres and sweeps for G2/G3 (LinuxCNC's interp_arc.cc semantics, in mm).

All lengths here are in mm in the plane of the arc: ``(a, b)`` are the plane's first and
second axes (X,Y for G17; Z,X for G18; Y,Z for G19). Errors are raised as
:class:`ArcError` with the letter of the word at fault; the interpreter adds the position.
"""

from __future__ import annotations

import math

INCH_MM = 25.4

# LinuxCNC 2.9 (interp_internal.hh): an IJK arc's end radius may differ from its start radius
# by the "spiral" tolerance: abs 2·0.01·√2 mm (2·0.001·√2 in) when also beyond 0.1 %
# relative, and never by more than 100× the absolute one. Within it the arc becomes a spiral
# whose radius changes linearly with angle.
SPIRAL_ABS_TOL_MM = 2.0 * 0.01 * math.sqrt(2.0)
SPIRAL_ABS_TOL_IN = 2.0 * 0.001 * math.sqrt(2.0)
SPIRAL_REL_TOL = 0.001
# Zero-radius arcs and R arcs too short to reach the end point: RADIUS_TOLERANCE.
RADIUS_TOL_IN = 0.00005
RADIUS_TOL_MM = RADIUS_TOL_IN * INCH_MM
_TINY = 1e-12


class ArcError(Exception):
    """An arc that cannot be made; ``letter`` names the word to point at (or "")."""

    def __init__(self, message: str, letter: str = "", geometry: bool = True):
        super().__init__(message)
        self.message = message
        self.letter = letter
        self.geometry = geometry


def tolerances(inch: bool) -> tuple[float, float]:
    """(spiral absolute tolerance, radius tolerance) [mm] for the units in force."""
    if inch:
        return SPIRAL_ABS_TOL_IN * INCH_MM, RADIUS_TOL_IN * INCH_MM
    return SPIRAL_ABS_TOL_MM, RADIUS_TOL_MM


def center_from_radius(start, end, r_signed: float, ccw: bool, radius_tol: float):
    """Centre (ca, cb) of an R-format arc from ``start`` to ``end`` (plane coordinates [mm]).

    LinuxCNC's arc_data_r: the centre lies on the chord's perpendicular bisector, on the left
    of the chord for (G3, R > 0) or (G2, R < 0); a chord up to ``radius_tol`` longer than the
    diameter is taken as a half circle.
    """
    sa, sb = start
    ea, eb = end
    if ea == sa and eb == sb:
        raise ArcError("full circle in radius format (R) is not allowed", "R")
    r = abs(r_signed)
    if r == 0.0:
        raise ArcError("arc radius R is zero", "R")
    ma, mb = (ea + sa) / 2.0, (eb + sb) / 2.0
    half = math.hypot(ma - ea, mb - eb)
    if half - r > radius_tol:
        raise ArcError(
            f"arc radius R{r:g} mm is smaller than half the distance to the end point "
            f"({half:.6g} mm)",
            "R",
        )
    if half / r > 1.0 - _TINY:
        half = r
    chord_angle = math.atan2(eb - sb, ea - sa)
    left = (not ccw and r_signed > 0) or (ccw and r_signed < 0)
    theta = chord_angle - math.pi / 2 if left else chord_angle + math.pi / 2
    offset = r * math.cos(math.asin(half / r))
    return ma + offset * math.cos(theta), mb + offset * math.sin(theta)


def check_radii(start, end, center, spiral_tol: float, radius_tol: float):
    """(start radius, end radius) [mm]; raises when zero or too different (LinuxCNC rules)."""
    r0 = math.hypot(center[0] - start[0], center[1] - start[1])
    r1 = math.hypot(center[0] - end[0], center[1] - end[1])
    if not all(map(math.isfinite, (center[0], center[1], r0, r1))):
        raise ArcError("arc centre or radius is out of range")
    if r0 < radius_tol or r1 < radius_tol:
        raise ArcError(f"zero-radius arc (start radius {r0:.6g} mm, end radius {r1:.6g} mm)")
    err = abs(r1 - r0)
    rel = err / max(r0, r1)
    if err > 100.0 * spiral_tol or (rel > SPIRAL_REL_TOL and err > spiral_tol):
        raise ArcError(
            f"radius to end of arc ({r1:.6g} mm) differs from radius to start "
            f"({r0:.6g} mm) by {err:.4g} mm"
        )
    return r0, r1


def sweep_rad(start, end, center, ccw: bool, turns: int) -> float:
    """Signed angle [rad] (positive counter-clockwise) from start to end about the centre.

    Start = end is a full circle; ``turns`` − 1 extra full turns are added (G2/G3 P).
    """
    t0 = math.atan2(start[1] - center[1], start[0] - center[0])
    t1 = math.atan2(end[1] - center[1], end[0] - center[0])
    sweep = t1 - t0
    full = math.hypot(end[0] - start[0], end[1] - start[1]) < 1e-12
    if ccw:
        sweep = 2.0 * math.pi if full else (sweep + 2.0 * math.pi if sweep <= 0.0 else sweep)
        sweep += 2.0 * math.pi * (turns - 1)
    else:
        sweep = -2.0 * math.pi if full else (sweep - 2.0 * math.pi if sweep >= 0.0 else sweep)
        sweep -= 2.0 * math.pi * (turns - 1)
    if not math.isfinite(sweep):
        raise ArcError(f"arc turns P{turns} is out of range", "P")
    return sweep
