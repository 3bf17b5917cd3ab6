"""Turn-around blends: one curve through two corners around a short middle line (G64 P).

A raster's turn-around is a pass, a short stepover and the next pass back: two sharp corners
(about 90° each) a fraction of a millimetre apart, the tangent reversed across them. Blended
one corner at a time, each blend gets at most half the stepover and turns 90° within it
(a curvature of about 10 /mm for a 0.5 mm stepover); stopped, the servo overshoots each
corner by c₂·A (SPEC §8: 70 µm at 2450 mm/s²). One curve through both corners turns the
whole 180° over the stepover's width: a U whose peak curvature is about 2/width (4.4 /mm for
0.5 mm), its ends tangent to the passes with zero curvature (G2 with lines).

The curve is a quintic Bézier from the point ``d`` before the first corner (on the incoming
line, tangent t_a) to the point ``d`` after the second (on the outgoing line, tangent t_b):
P0 = C1 − d t_a, P1 = P0 + α t_a, P2 = P0 + 2α t_a, and mirrored at the end
(P5 = C2 + d t_b, P4 = P5 − α t_b, P3 = P5 − 2α t_b). Three collinear control points at
each end make the curvature vanish there (C″(0) = 20(P2 − 2P1 + P0) ∥ t_a), so the U meets
the lines tangentially and curvature-continuously. Over a grid of (d, α) (measured coarsely
first: 33 curve samples against the two vertices; then fully, best first, until one fits), the
U kept is the one of least L·√κ_max (L its length, κ_max its peak curvature:
the time to cross it at the constant feed √(a/κ_max) a normal-acceleration or servo-error
cap allows) whose two-way distance to the corner path P0–C1–C2–P5 (sampled: 129 points of
the curve, 33 per side of the path) is within the tolerance, and whose parametric speed
stays above :data:`~nurbscnc.geometry.blendrules.MIN_SPEED_RATIO` of its mean (no cusp).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbscnc.geometry.blendrules import MIN_SPEED_RATIO, N_ARC
from nurbscnc.geometry.spaceblend import _bezier_batch

#: Samples of the curve in the deviation and curvature measures (as the space blends').
N_CURVE = 129
#: Samples of the curve and of each side of the corner path in the search's coarse measure
#: (2: the vertices, farthest from a U),
#: and how far above the tolerance a coarse deviation may be and still be measured fully.
COARSE_CURVE = 33
COARSE_SIDE = 2
COARSE_SLACK = 0.05
#: The trim d as fractions of its cap, and α as fractions of d, of the first grid.
D_FRACTIONS = np.linspace(0.15, 1.0, 10)
ALPHA_FRACTIONS = np.linspace(0.2, 1.6, 12)


@dataclass(frozen=True, eq=False)
class TurnBlend:
    """A turn-around blend: ``curve`` the quintic Bézier (a
    :class:`~nurbscnc.geometry.nurbs.NurbsCurve`, u ∈ [0, 1]) from the point ``trim_a_mm``
    before the first corner to the point ``trim_b_mm`` after the second; ``deviation_mm``
    its sampled two-way distance to the corner path [mm]; ``kappa_max_per_mm`` its peak
    curvature [1/mm]; ``length_mm`` its length [mm]."""

    curve: object
    trim_a_mm: float
    trim_b_mm: float
    deviation_mm: float
    kappa_max_per_mm: float
    length_mm: float


def turn_controls(c1, t_a, c2, t_b, d, alpha) -> np.ndarray:
    """Control points (n, 6, 3) [mm] of the U curves (module doc) for corners ``c1``, ``c2``
    (3,), unit tangents ``t_a`` (incoming) and ``t_b`` (outgoing) (3,), and trims ``d`` and
    leg lengths ``alpha`` (n,) [mm]."""
    d, alpha = np.asarray(d, float)[:, None], np.asarray(alpha, float)[:, None]
    p0, p5 = c1 - d * t_a, c2 + d * t_b
    return np.stack(
        [
            p0,
            p0 + alpha * t_a,
            p0 + 2.0 * alpha * t_a,
            p5 - 2.0 * alpha * t_b,
            p5 - alpha * t_b,
            p5,
        ],
        axis=1,
    )


def _segment_distance(q: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance [mm] of points ``q`` (..., 3) to the segments ``a``–``b`` (broadcast)."""
    ab = b - a
    ab2 = np.maximum(np.einsum("...j,...j->...", ab, ab), 1e-300)
    f = np.clip(np.einsum("...j,...j->...", q - a, ab) / ab2, 0.0, 1.0)
    r = q - a - f[..., None] * ab
    return np.sqrt(np.einsum("...j,...j->...", r, r))


def _speed_regular(d1: np.ndarray):
    """Parametric speed (n, m) of curves whose first derivatives are ``d1`` (n, m, 3), and
    whether each stays above :data:`MIN_SPEED_RATIO` of its mean (no cusp) (n,)."""
    speed = np.sqrt(np.einsum("mij,mij->mi", d1, d1))
    return speed, speed.min(axis=1) > MIN_SPEED_RATIO * speed.mean(axis=1)


def _measure(ctrl: np.ndarray, corner_path: np.ndarray, n_curve=N_CURVE, n_side=N_ARC):
    """Per candidate (n,): two-way sampled distance to ``corner_path`` (n, 4, 3) [mm], peak
    curvature [1/mm], length [mm] and regularity of the Béziers ``ctrl`` (n, 6, 3), on
    ``n_curve`` samples of the curve and ``n_side`` of each side of the path."""
    xi = np.linspace(0.0, 1.0, n_curve)
    pts, d1, d2 = _bezier_batch(ctrl, xi)
    speed, regular = _speed_regular(d1)
    kappa = np.linalg.norm(np.cross(d1, d2), axis=2) / np.maximum(speed**3, 1e-300)
    # Curve samples to the corner path's three segments.
    a, b = corner_path[:, None, :-1, :], corner_path[:, None, 1:, :]
    to_path = _segment_distance(pts[:, :, None, :], a, b).min(axis=2).max(axis=1)
    # The corner path's samples to the curve's polyline (its 128 chords).
    frac = np.linspace(0.0, 1.0, n_side)[None, :, None, None]
    side = corner_path[:, None, :-1, :] + frac * (corner_path[:, None, 1:, :] - a)
    side = side.reshape(ctrl.shape[0], -1, 3)
    to_curve = (
        _segment_distance(side[:, :, None, :], pts[:, None, :-1, :], pts[:, None, 1:, :])
        .min(axis=2)
        .max(axis=1)
    )
    length = np.linalg.norm(np.diff(pts, axis=1), axis=2).sum(axis=1)
    return np.maximum(to_path, to_curve), kappa.max(axis=1), length, regular


def turn_blend(c1, t_a, c2, t_b, tolerance_mm: float, max_trim_mm: float) -> TurnBlend | None:
    """The U curve (module doc) through corners ``c1`` and ``c2`` [mm] (3,) joining the
    incoming line (unit tangent ``t_a``) to the outgoing one (``t_b``), trims at most
    ``max_trim_mm`` on each line, within ``tolerance_mm`` of the corner path: the candidate of
    least L·√κ_max on a 10 × 12 grid of (d, α) (a finer grid around the best gained 0.3 %
    of L·√κ_max on the raster); None if none fits."""
    from nurbscnc.geometry.nurbs import NurbsCurve

    c1, c2 = np.asarray(c1, float), np.asarray(c2, float)
    t_a, t_b = np.asarray(t_a, float), np.asarray(t_b, float)
    if not (tolerance_mm > 0.0 and max_trim_mm > 0.0):
        return None
    d = np.repeat(D_FRACTIONS * max_trim_mm, ALPHA_FRACTIONS.size)
    alpha = d * np.tile(ALPHA_FRACTIONS, D_FRACTIONS.size)
    best = _best(c1, t_a, c2, t_b, d, alpha, tolerance_mm)
    if best is None:
        return None
    d_k, alpha_k, dev, kmax, length = best
    ctrl = turn_controls(c1, t_a, c2, t_b, [d_k], [alpha_k])[0]
    curve = NurbsCurve(5, np.array([0.0] * 6 + [1.0] * 6), ctrl, np.ones(6))
    return TurnBlend(curve, float(d_k), float(d_k), float(dev), float(kmax), float(length))


def _best(c1, t_a, c2, t_b, d, alpha, tolerance_mm: float):
    """(d, α, deviation, κ_max, length) of the fitting candidate of least L·√κ_max, or None."""
    ctrl = turn_controls(c1, t_a, c2, t_b, d, alpha)
    corner_path = np.stack(
        [ctrl[:, 0], np.broadcast_to(c1, ctrl[:, 0].shape), np.broadcast_to(c2, ctrl[:, 0].shape)]
        + [ctrl[:, 5]],
        axis=1,
    )
    # A coarse measure over the grid (a quarter of the samples), then the full one on the
    # candidates in order of cost until one fits (the full measure decides).
    dev, kmax, length, regular = _measure(ctrl, corner_path, COARSE_CURVE, COARSE_SIDE)
    near = regular & (dev <= tolerance_mm * (1.0 + COARSE_SLACK)) & np.isfinite(kmax)
    cost = np.where(near, length * np.sqrt(kmax), np.inf)
    # Regularity first: it needs the derivatives alone, and decides most candidates (where
    # no U fits, as on PCB paths retraced over a few µm, every one: a cusp between the coarse
    # samples); the same test the full measure makes, so the same choice. The derivatives of
    # all of them at once (elementwise Bernstein sums: each row is its candidate's own), the
    # test on a copy of each row (the array the candidate's full measure makes).
    order = np.argsort(cost)[: int(near.sum())].tolist()
    d1 = _bezier_batch(ctrl[order], np.linspace(0.0, 1.0, N_CURVE))[1] if order else None
    for k, i in enumerate(order):
        if not _speed_regular(d1[k : k + 1].copy())[1][0]:
            continue
        dev_i, kmax_i, length_i, regular_i = _measure(ctrl[i : i + 1], corner_path[i : i + 1])
        if regular_i[0] and dev_i[0] <= tolerance_mm and np.isfinite(kmax_i[0]):
            return (
                float(d[i]),
                float(alpha[i]),
                float(dev_i[0]),
                float(kmax_i[0]),
                float(length_i[0]),
            )
    return None
