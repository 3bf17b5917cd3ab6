"""Sharp-corner detection (SPEC §5, eq. 13–15) and tangent corners between segments.

A sharp corner of a NURBS block is a local maximum of the curvature κ(u) (dκ/du = 0) above
the threshold κ_th = A_max / F² (F the block's feed): there the feed F would need more than
A_max of normal acceleration. Its region [u_a, u_b] extends on each side of the peak to where
κ falls back to κ_th (our rule; the paper does not say). Peaks whose regions touch (κ stays
above κ_th between them) form one region, described by the highest peak.

For G1/G2/G3 paths the corners are the tangent discontinuities between consecutive segments,
reported with their turning angle for the planner.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from nurbscnc.geometry.nurbs import NurbsCurve
from nurbscnc.geometry.path import STOP_KINDS
from nurbscnc.geometry.paths import geometry_of
from nurbscnc.machine.caps import kappa_threshold_per_mm

#: Curvature samples per knot span used to bracket the peaks and the threshold crossings.
SAMPLES_PER_SPAN = 32


@dataclass(frozen=True)
class CornerRegion:
    """A sharp corner of one NURBS curve.

    ``u_peak`` the parameter of the curvature maximum, ``kappa_peak_per_mm`` its curvature
    [1/mm] (``inf`` at a cusp), ``point_mm`` C(u_peak) [mm], ``u_a``/``u_b`` the region's ends,
    ``length_mm`` its arc length [mm], ``kappa_threshold_per_mm`` the κ_th used.
    """

    u_peak: float
    kappa_peak_per_mm: float
    point_mm: tuple
    u_a: float
    u_b: float
    length_mm: float
    kappa_threshold_per_mm: float


@dataclass(frozen=True)
class SegmentCorners:
    """The corner regions of the NURBS segment ``segment_index`` (source ``line``)."""

    segment_index: int
    line: int
    feed_mm_s: float
    kappa_threshold_per_mm: float
    regions: tuple


@dataclass(frozen=True)
class Junction:
    """A tangent discontinuity between segment ``index`` and the next one.

    ``angle_deg`` the turning angle between the end tangent of one and the start tangent of
    the next (0 = tangent-continuous); ``point_mm`` where they meet.
    """

    index: int
    line: int
    point_mm: tuple
    angle_deg: float


class CornerAction(IntEnum):
    """What the planner did at a non-tangent junction (a corner) of the path."""

    BLEND = 0  #: replaced by a blend within the path tolerance, passed at the blend's feed
    PASS = 1  #: a break small enough to pass at speed within the tolerance, not blended
    STOP = 2  #: an exact stop at the vertex


class CornerWhy(IntEnum):
    """Why a corner was treated as it was (the planner's reason, for ``plan --explain``)."""

    BLENDED = 0  #: G64 (with or without P): blended
    SMALL_BREAK = 1  #: the break is within the limits at full speed (passed, not blended)
    EXACT_PATH = 2  #: G61: exact path, sharp corners stop
    EXACT_STOP = 3  #: G61.1: every block end stops
    ZERO_TOLERANCE = 4  #: --blend-tolerance 0 (G64 P0 is G64 without P, as in LinuxCNC)
    NO_BLEND_FITS = 5  #: no blend within the tolerance fits the neighbouring pieces
    NOT_BLENDABLE = 6  #: this kind of joint cannot be blended (a cusp, reversal or 3-D turn)
    DWELL_OR_PAUSE = 7  #: a dwell, pause or program stop at the junction
    RAPID_FEED = 8  #: a rapid meets a feed move (the tool stops between them)
    PROGRAM_END = 9  #: start or end of the program
    STOP_FASTER = 10  #: a blend fits, but it is so tight that stopping is faster
    A_RATE = 11  #: the rate dA/ds of rotary axis A changes: an exact stop
    B_RATE = 12  #: likewise B
    C_RATE = 13  #: likewise C
    ROTARY_MOVES = 14  #: A B C move along the pieces: the corner is not rounded
    ROTATE = 15  #: a rotary-only move (A B C turn, X Y Z at rest) between the pieces


@dataclass(frozen=True, eq=False)
class CornerLog:
    """Every corner of a planned path and what was done there, as columns (n,) each:
    ``line`` the source line of the move that ends at the corner, ``point_mm`` (n, 3) the
    vertex [mm], ``turning_rad`` the angle between the tangents, ``action``
    (:class:`CornerAction` codes) and ``why`` (:class:`CornerWhy` codes)."""

    line: np.ndarray
    point_mm: np.ndarray
    turning_rad: np.ndarray
    action: np.ndarray
    why: np.ndarray

    @classmethod
    def empty(cls) -> CornerLog:
        z = np.zeros(0)
        return cls(z.astype(np.int64), np.zeros((0, 3)), z, z.astype(np.int8), z.astype(np.int8))

    def __len__(self) -> int:
        return int(self.line.size)


def _sample_params(curve: NurbsCurve, per_span: int) -> np.ndarray:
    """Dense parameters: ``per_span`` per non-empty knot span, breakpoints included."""
    bp = curve.breakpoints
    if bp.size < 2:
        return np.array([curve.u_start, curve.u_end])
    t = np.linspace(0.0, 1.0, per_span + 1)[:-1]
    u = (bp[:-1, None] + (bp[1:] - bp[:-1])[:, None] * t[None, :]).ravel()
    return np.append(u, bp[-1])


#: Brent's method tolerances of the corner search (absolute and relative, in u).
BRENT_XTOL = 1e-14
BRENT_RTOL = 1e-14
BRENT_MAXITER = 100  # scipy.optimize.brentq's default


@functools.cache
def _brentq():
    """f(x), a, b → the root of f in [a, b] by Brent's method: ``scipy.optimize.brentq``'s
    compiled loop (``scipy/optimize/_zeros``) loaded by itself
    (:func:`nurbscnc.scipy_ext.extension`: importing scipy.optimize costs 0.4–0.8 s of CPU on
    every NURBS program), with brentq's own guard against NaN values; scipy.optimize.brentq
    where that module is not found. Tolerances :data:`BRENT_XTOL`, :data:`BRENT_RTOL`."""
    from nurbscnc.scipy_ext import extension

    module = extension("optimize", "_zeros")
    if module is None:  # pragma: no cover (another scipy layout)
        from scipy.optimize import brentq

        return lambda f, a, b: brentq(
            f, a, b, xtol=BRENT_XTOL, rtol=BRENT_RTOL, maxiter=BRENT_MAXITER
        )

    def solve(f, a, b):
        def checked(x):
            fx = f(x)
            if math.isnan(fx):
                raise ValueError(f"the function value at x={x} is NaN; solver cannot continue")
            return fx

        return module._brentq(checked, a, b, BRENT_XTOL, BRENT_RTOL, BRENT_MAXITER, (), False, True)

    return solve


def find_corner_regions(
    curve: NurbsCurve, kappa_th_per_mm: float, per_span: int = SAMPLES_PER_SPAN
) -> tuple[CornerRegion, ...]:
    """The sharp-corner regions of ``curve`` for threshold κ_th [1/mm] (SPEC §5).

    Peaks: sign changes + → − of dκ/du between dense samples, refined by Brent's method;
    a peak at a knot where dκ/du jumps, or at an end of the curve, is found the same way
    (the bracket closes on it). Cusps (κ = inf) are peaks where they are sampled. Region ends:
    the crossings κ = κ_th on each side, refined by Brent's method.
    """
    brentq = _brentq()

    u = _sample_params(curve, per_span)
    kappa = curve.curvature(u)
    above = kappa > kappa_th_per_mm
    if not above.any():
        return ()

    def excess(x):
        return float(curve.curvature(np.array([x]))[0] - kappa_th_per_mm)

    def dk(x):
        return float(curve.curvature_derivative(np.array([x]))[0])

    regions = []
    i = 0
    n = u.size
    while i < n:
        if not above[i]:
            i += 1
            continue
        j = i
        while j + 1 < n and above[j + 1]:
            j += 1
        # Samples i..j are above the threshold: one region. Its ends are the crossings.
        u_a = u[0] if i == 0 else brentq(excess, u[i - 1], u[i])
        u_b = u[-1] if j == n - 1 else brentq(excess, u[j], u[j + 1])
        # The highest peak within: the best sample, then the zero of dκ/du next to it.
        k = i + int(np.argmax(kappa[i : j + 1]))
        u_peak = float(u[k])
        if np.isfinite(kappa[k]):
            lo, hi = max(k - 1, 0), min(k + 1, n - 1)
            d_lo, d_hi = dk(u[lo]), dk(u[hi])
            if lo < k and dk(u[k]) > 0 and d_hi < 0:
                lo = k
                d_lo = dk(u[k])
            elif hi > k and dk(u[k]) < 0 and d_lo > 0:
                hi = k
                d_hi = dk(u[k])
            if d_lo > 0 > d_hi:
                u_peak = brentq(dk, u[lo], u[hi])
            elif k == 0 or k == n - 1:
                u_peak = float(u[k])  # the maximum is at an end of the curve
        u_peak = min(max(u_peak, u_a), u_b)
        kappa_peak = float(curve.curvature(np.array([u_peak]))[0])
        if kappa_peak < kappa[k]:  # refinement must never lose the sampled maximum
            u_peak, kappa_peak = float(u[k]), float(kappa[k])
        s = curve.arc_length(np.array([u_a, u_b]))
        regions.append(
            CornerRegion(
                u_peak=float(u_peak),
                kappa_peak_per_mm=kappa_peak,
                point_mm=tuple(float(c) for c in curve.point(np.array([u_peak]))[0]),
                u_a=float(u_a),
                u_b=float(u_b),
                length_mm=float(s[1] - s[0]),
                kappa_threshold_per_mm=float(kappa_th_per_mm),
            )
        )
        i = j + 1
    return tuple(regions)


def program_corners(
    segments, a_max_mm_s2: float, v_max_mm_s: float, feed_override_mm_s: float | None = None
) -> list[SegmentCorners]:
    """Corner regions of every NURBS segment of a program.

    The threshold uses each block's programmed feed capped by V_max [mm/s] (a feed above V_max
    is never run), or ``feed_override_mm_s`` when given.
    """
    result = []
    for index, seg in enumerate(segments):
        if seg.kind != "nurbs":
            continue
        feed = feed_override_mm_s if feed_override_mm_s else seg.feed_mm_s
        feed = min(feed, v_max_mm_s)
        kth = float(kappa_threshold_per_mm(feed, a_max_mm_s2))
        curve = NurbsCurve.from_segment(seg)
        result.append(SegmentCorners(index, seg.line, feed, kth, find_corner_regions(curve, kth)))
    return result


def tangent_junctions(segments, min_angle_deg: float = 1e-6) -> list[Junction]:
    """Tangent discontinuities between consecutive moving segments (dwells are skipped).

    The angle is between the end tangent of one segment and the start tangent of the next.
    """
    moving = [(i, s) for i, s in enumerate(segments) if s.kind not in STOP_KINDS]
    out = []
    for (i, a), (_, b) in zip(moving, moving[1:]):
        ga, gb = geometry_of(a), geometry_of(b)
        ta = ga.derivatives(np.array([ga.u_end]), 1)[1][0]
        tb = gb.derivatives(np.array([gb.u_start]), 1)[1][0]
        na, nb = np.linalg.norm(ta), np.linalg.norm(tb)
        if na == 0.0 or nb == 0.0:
            continue
        cos = float(np.clip(np.dot(ta, tb) / (na * nb), -1.0, 1.0))
        angle = float(np.degrees(np.arccos(cos)))
        if angle > min_angle_deg:
            point = tuple(float(c) for c in np.asarray(a.end_mm, dtype=float))
            out.append(Junction(i, b.line, point, angle))
    return out
