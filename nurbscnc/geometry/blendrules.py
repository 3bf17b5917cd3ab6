"""The rules every corner blend follows (SPEC §4, §10): when a junction is smooth, reversed or
too short to blend, how the equal-trim search stops, and the closed-form deviation of a
line–line blend per unit of trim, from which every search starts."""

from __future__ import annotations

import numpy as np

#: Junctions turning less than this [rad] are smooth (the planner's SMOOTH_JUNCTION_RAD).
MIN_TURNING_RAD = 1e-6
#: Junctions turning more than π minus this [rad] are reversals: no blend, exact stop.
MIN_REVERSAL_RAD = 1e-6
#: Trims shorter than this [mm] are degenerate: no blend.
MIN_TRIM_MM = 1e-9
#: Relative window below the tolerance where the search stops.
SEARCH_WINDOW = 0.005
#: Relative width of the trim bracket [lo, hi] where the search gives up (the deviation
#: stays below the window there, e.g. where the G2 family ends).
BRACKET_REL = 0.02
#: Most blends built per search.
MAX_EVALS = 16
#: Trim cap as a multiple of the line-corner estimate.
TRIM_CAP_FACTOR = 4.0

#: Least parametric speed σ = |C′(ξ)| of a regular blend, as a fraction of its mean (the
#: length L). A blend slower than this somewhere is a near cusp: between two arcs (R 1 and
#: R 2 mm, a 7° break) a G2 blend with σ(0) = 0.9 % of L turned its curvature from 1 to
#: 11.5 /mm within 0.3 µm, a curvature slope (1.8e5 /mm²) no feed cap sampled along the
#: piece sees, and an axis broke its jerk limit by 16 %. The blends of the corpus and the
#: SPEC programs keep σ ≥ 28 % of L (measured); a family whose members are all slower is
#: left for the G1 family or a stop.
MIN_SPEED_RATIO = 0.05
#: Samples of a curved side of the corner path (its polyline when measured as one) [count].
N_ARC = 33


def line_deviation_per_trim(turning_rad):
    """Deviation / trim of the symmetric line–line blend (w1 = 0) turning by θ [mm/mm].

    In a frame with t0 = e^{−iθ/2}, t1 = e^{iθ/2} (bisector 1) and d = 1: α² = 30c/(6c + 1)
    (c = cos θ/2, :mod:`nurbscnc.geometry.phcorner` with x = y = 1), and by symmetry the
    blend point nearest the vertex p0 + t0 is r(½), r(½) − p0 = α²(31/160 t0 + 1/30 +
    1/160 t1) (∫₀^½ of the three terms of w² = α²(e0²(1 − ξ)⁴ + 2e0e2 ξ²(1 − ξ)² + e2² ξ⁴)).
    Elementwise on arrays (a float for a scalar).
    """
    th = np.asarray(turning_rad, dtype=float)
    c = np.cos(0.5 * th)
    t0, t1 = np.exp(-0.5j * th), np.exp(0.5j * th)
    a2 = 30.0 * c / (6.0 * c + 1.0)
    out = np.abs(t0 - a2 * (31.0 / 160.0 * t0 + 1.0 / 30.0 + 1.0 / 160.0 * t1))
    return float(out) if out.ndim == 0 else out
