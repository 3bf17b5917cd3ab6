"""The rational B-spline curve NurbsCurve (SPEC §2, §10 first bullet): its evaluation,
curvature and arc length over the basis (bspline.py), power form (powerform.py) and
arc-length tables (arclength.py, inverse.py); the weights' checks; the moved-copy search.

References: L. Piegl & W. Tiller, *The NURBS Book*, 2nd ed. (A2.1 FindSpan, A2.3 DersBasisFuns,
A4.2 RatCurveDerivs).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from nurbscnc.geometry.arclength import ArcLengthTable
from nurbscnc.geometry.bspline import (
    _KERNEL_MAX_DEGREE,
    as_params,
    basis_derivatives,
    basis_functions,
    curvature_derivative_from_derivatives,
    curvature_from_derivatives,
    find_span,
    rational_derivatives,
)
from nurbscnc.geometry.compiled import kernels as _kernels
from nurbscnc.geometry.distinct import distinct
from nurbscnc.geometry.inverse import InverseArcTable
from nurbscnc.geometry.powerform import PowerForm

if TYPE_CHECKING:  # pragma: no cover - typing only
    from nurbscnc.geometry.segments import Nurbs

#: A point whose speed |C'| is at most this fraction of the curve's characteristic speed
#: (bounding-box diagonal / parameter range) is treated as a cusp: κ = +inf, dκ/du = 0.
CUSP_SPEED_FRACTION = 1e-12

#: Control points of two curves that agree within this many ulps of the coordinates' size,
#: relative to their first control points, make one a moved copy of the other
#: (:meth:`NurbsCurve.translation_from`).
MOVED_ULPS = 8
#: Rounding of the relative control points in :meth:`NurbsCurve.shape_key` [mm].
MOVED_KEY_MM = 1e-6


# ---------------------------------------------------------------------------------------------
# The rational curve
# ---------------------------------------------------------------------------------------------


def _readonly(values, shape_tail=()) -> np.ndarray:
    a = np.array(values, dtype=float)
    if shape_tail:
        a = a.reshape((-1, *shape_tail))
    a.setflags(write=False)
    return a


#: Largest ratio of a NURBS block's largest to smallest weight. Beyond it the curve is a
#: polygon with corners of radius ~ (edge length) / ratio, whose arc-length tables need
#: millions of cells (weight 1e9: 28 million, 2 GB), and past ~1e154 w·P overflows to NaN.
#: CAM programs use weights within a factor of a few of 1.
MAX_WEIGHT_RATIO = 1e6
#: Weights are rescaled by a power of two (exact: the rational curve is unchanged, bit for bit)
#: when the largest is outside [2^-20, 2^20], so w·P cannot overflow or lose precision.
_WEIGHT_SCALE_RANGE = 20


def sane_weights(seg) -> np.ndarray:
    """The weights of a NURBS segment, refused (GeometryError at its line) when not all
    finite and > 0 or when max/min exceeds :data:`MAX_WEIGHT_RATIO`; scaled by a power of two
    when their size would overflow w·P (the curve Σ N w P / Σ N w is unchanged by a common
    factor)."""
    from nurbscnc.errors import GeometryError, SourcePos

    w = np.asarray(seg.weights, dtype=float)
    pos = SourcePos(int(seg.line), 1, "")
    if w.size == 0 or not np.all(np.isfinite(w) & (w > 0.0)):
        raise GeometryError("NURBS weights must be finite and > 0", pos)
    hi, lo = float(w.max()), float(w.min())
    if hi > MAX_WEIGHT_RATIO * lo:
        raise GeometryError(
            f"NURBS weights {lo:.6g} to {hi:.6g} differ by a factor of {hi / lo:.3g}, more than "
            f"{MAX_WEIGHT_RATIO:g} (the curve would be a polygon with near-zero-radius corners)",
            pos,
        )
    exp = int(np.frexp(hi)[1])
    if abs(exp) > _WEIGHT_SCALE_RANGE:
        w = np.ldexp(w, -exp)
    return w


class MovedCopies:
    """The curves met so far, to find the one a curve is a moved copy of
    (:meth:`NurbsCurve.translation_from`): candidates by :meth:`NurbsCurve.shape_key` and
    the caller's ``extra`` key (what else must be the same: a feed, a speed ceiling), at most
    :data:`BUCKET` a key (a bound on the comparisons, whatever the program)."""

    BUCKET = 4

    def __init__(self):
        self._seen: dict[tuple, list] = {}

    def find(self, curve: NurbsCurve, extra: tuple = ()):
        """(value, Δ (3,) [mm]) of the curve met before that ``curve`` is moved by Δ, or
        None."""
        for other, value in self._seen.get((curve.shape_key(), extra), ()):
            delta = curve.translation_from(other)
            if delta is not None:
                return value, delta
        return None

    def add(self, curve: NurbsCurve, value, extra: tuple = ()) -> None:
        """Remember ``curve`` with ``value`` (unless its key holds :data:`BUCKET` already)."""
        bucket = self._seen.setdefault((curve.shape_key(), extra), [])
        if len(bucket) < self.BUCKET:
            bucket.append((curve, value))


@dataclass(frozen=True, eq=False)
class NurbsCurve:
    """A rational B-spline curve C(u) = Σ N_{i,p} w_i P_i / Σ N_{i,p} w_i (SPEC §2, eq. 1).

    ``knots`` (n+p+1,) clamped; ``control_points_mm`` (n, 3) [mm]; ``weights`` (n,) > 0. The
    input is assumed valid (the interpreter validates). Parameters passed to the evaluation
    methods are clamped to [u_start, u_end]. The arc-length table is built lazily, once.
    Satisfies :class:`nurbscnc.geometry.paths.PathGeometry`.
    """

    degree: int
    knots: np.ndarray
    control_points_mm: np.ndarray
    weights: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "degree", int(self.degree))
        object.__setattr__(self, "knots", _readonly(self.knots))
        object.__setattr__(self, "control_points_mm", _readonly(self.control_points_mm, (3,)))
        object.__setattr__(self, "weights", _readonly(self.weights))

    @classmethod
    def from_segment(cls, seg: Nurbs) -> NurbsCurve:
        """The curve of a ``segments.Nurbs`` (its weights checked: :func:`sane_weights`)."""
        return cls(seg.degree, seg.knots, seg.control_points_mm, sane_weights(seg))

    def without_end_hooks(self, max_deviation_mm: float) -> NurbsCurve:
        """The curve with tiny hooks at its ends removed, or itself if it has none.

        A hook: the first control leg P1 − P0 (or the last, P_{n−2} − P_{n−1}) is shorter
        than the next one and points back from it (a negative dot product), so the curve
        leaves its end in one direction and turns round within |P1 − P0| — what rounding
        does to a least-squares fit whose P1 should sit on P0 (a sharp trailing edge as
        G5.2 with 6-decimal control points: a 1e-6 mm leg, curvature 4e8 /mm, crawled at
        √(A/κ) = 2.6 µm/s). The hook is removed by moving P1 onto the ray from P0 towards P2,
        ℓ = min(0.9·tol / max R1 − |P1 − P0|, |P2 − P0|/3) from P0: the curve then leaves P0
        along P2 − P0 with zero curvature (C′ ∥ C″ there), regular. It moves by
        |ΔP1| · R1(u) ≤ (|P1 − P0| + ℓ) max R1 ≤ 0.9 ``max_deviation_mm`` [mm] (R1 the rational
        basis function of P1, its maximum taken over 257 samples of its support); no change
        where |P1 − P0| alone exceeds that.
        """
        p, ctrl = self.degree, np.array(self.control_points_mm)
        n = ctrl.shape[0]
        if n < 3:
            return self
        changed = False
        for end, inner, nxt in ((0, 1, 2), (n - 1, n - 2, n - 3)):
            leg, after = ctrl[inner] - ctrl[end], ctrl[nxt] - ctrl[inner]
            size = float(np.linalg.norm(leg))
            if not 0.0 < size < float(np.linalg.norm(after)) or float(leg @ after) >= 0.0:
                continue
            lo, hi = self.knots[inner], self.knots[inner + p + 1]  # support of R_inner
            u = np.linspace(lo, hi, 257)
            spans = find_span(self.knots, p, u)
            basis = basis_functions(self.knots, p, u, spans).T  # (m, p+1): spans−p..spans
            col = inner - (spans - p)
            w = self.weights
            idx = (spans - p)[:, None] + np.arange(p + 1)[None, :]
            r = np.where(
                (col >= 0) & (col <= p),
                basis[np.arange(u.size), np.clip(col, 0, p)]
                * w[inner]
                / np.sum(basis * w[idx], axis=1),
                0.0,
            )
            # P1 onto the ray P0 → P2, as far as the deviation allows (at most a third of
            # |P2 − P0|): |ΔP1| ≤ |P1 − P0| + ℓ, times max R1 ≤ 0.9 of the tolerance.
            if not r.max() > 0.0:
                # R1 vanishes (an end knot repeated beyond the order: its span holds no
                # parameter of the curve; programs refuse such knots): no hook to move.
                continue
            room = 0.9 * max_deviation_mm / float(r.max()) - size
            chord = ctrl[nxt] - ctrl[end]
            far = float(np.linalg.norm(chord))
            if room > 0.0 and far > 0.0:
                ctrl[inner] = ctrl[end] + min(room, far / 3.0) * chord / far
                changed = True
        if not changed:
            return self
        return NurbsCurve(p, self.knots, ctrl, self.weights)

    def shape_key(self) -> tuple:
        """A key that moved copies of one curve (:meth:`translation_from`) share, to find
        candidates by: degree, knots and weights (bytes), and the control points relative to
        the first rounded to :data:`MOVED_KEY_MM`. Two copies 1e-12 mm apart fall on either
        side of a rounding boundary about once in 2,000 curves of 80 control points: that
        copy is then planned afresh, with the same result."""
        rel = self.control_points_mm - self.control_points_mm[0]
        return (
            self.degree,
            self.knots.tobytes(),
            self.weights.tobytes(),
            (np.round(rel / MOVED_KEY_MM) + 0.0).tobytes(),
        )  # (+0.0: no −0.0)

    def translation_from(self, other: NurbsCurve) -> np.ndarray | None:
        """The translation Δ (3,) [mm] that moves ``other`` onto this curve, or None if it is
        not such a copy: the same degree, knots and weights bit for bit, and control points
        P_i − P_0 within :data:`MOVED_ULPS` ulps of the coordinates' size (a part programmed
        again at another place: its decimal coordinates round differently, 1.4e-14 mm on a
        60 mm airfoil moved by 70 mm). The difference of the two curves is then a NURBS of
        control points that small (convex hull), far below any tolerance of the planner."""
        if (
            self.degree != other.degree
            or self.control_points_mm.shape != other.control_points_mm.shape
            or not np.array_equal(self.knots, other.knots)
            or not np.array_equal(self.weights, other.weights)
        ):
            return None
        mine, theirs = self.control_points_mm, other.control_points_mm
        size = max(float(np.abs(mine).max()), float(np.abs(theirs).max()))
        gap = np.abs((mine - mine[0]) - (theirs - theirs[0]))
        if not np.all(gap <= MOVED_ULPS * np.finfo(float).eps * size):
            return None
        return mine[0] - theirs[0]

    def sharing_tables(self, other: NurbsCurve) -> NurbsCurve:
        """This curve, its arc-length tables s(u) and u(s) (:attr:`arc_table`,
        :attr:`inverse_table`) those of ``other``, of which it is a moved copy
        (:meth:`translation_from`): arc length does not depend on where the curve lies, and
        the tables cost milliseconds a curve (4 of a 60 mm airfoil's 8). Points still come
        from this curve's own control points."""
        self.__dict__["arc_table"] = other.arc_table  # cached_property storage
        self.__dict__["inverse_table"] = other.inverse_table
        return self

    @property
    def u_start(self) -> float:
        return float(self.knots[self.degree])

    @property
    def u_end(self) -> float:
        return float(self.knots[-self.degree - 1])

    @property
    def breakpoints(self) -> np.ndarray:
        """Distinct knots in [u_start, u_end] (where derivatives may jump)."""
        k = self.knots[self.degree : self.knots.size - self.degree]
        return distinct(k)

    @cached_property
    def _homogeneous(self) -> np.ndarray:
        """Control points in homogeneous form [w x, w y, w z, w] (n, 4)."""
        w = self.weights[:, None]
        return np.hstack((self.control_points_mm * w, w))

    @cached_property
    def homogeneous_t(self) -> np.ndarray:
        """The homogeneous control points components first, (4, n), for (4, m) gathers."""
        return np.ascontiguousarray(self._homogeneous.T)

    @cached_property
    def speed_floor(self) -> float:
        """Speed |C'| [mm/unit u] at or below which a point counts as a cusp (κ = inf)."""
        diag_mm = float(np.linalg.norm(np.ptp(self.control_points_mm, axis=0)))
        span = self.u_end - self.u_start
        if diag_mm == 0.0 or not span > 0.0:
            # All control points equal: the curve is a point; |C'| is pure rounding noise.
            return np.inf
        return CUSP_SPEED_FRACTION * diag_mm / span

    def derivatives(self, u, order: int = 3) -> np.ndarray:
        """[C, C', ..., C^(order)] at u: shape (order+1, len(u), 3) [mm / unit u^k].

        Homogeneous B-spline derivatives A^(k), w^(k) from :func:`basis_derivatives`, then the
        quotient rule (P&T A4.2): C^(k) = (A^(k) − Σ_{i=1..k} C(k,i) w^(i) C^(k−i)) / w.
        :meth:`_derivatives_py`, compiled where the geometry's kernels were built (the same
        numbers bit for bit, one parameter at a time without numpy's temporaries: most calls
        are for one to a few parameters, Brent's steps and the PH fits' ends).
        """
        p = self.degree
        if _kernels is None or not 0 <= p <= _KERNEL_MAX_DEGREE or order > 2 * _KERNEL_MAX_DEGREE:
            return self._derivatives_py(np.clip(as_params(u), self.u_start, self.u_end), order)
        u = np.ascontiguousarray(as_params(u))  # the clip and spans in the kernel
        out = np.empty((order + 1, u.size, 3))
        _kernels.nurbs_derivatives_at(
            self._knots_c, u, self.u_start, self.u_end, p, int(order), self.homogeneous_t, out
        )
        return out

    @cached_property
    def _knots_c(self) -> np.ndarray:
        """The knot vector as a contiguous float64 array (the kernel's buffer)."""
        return np.ascontiguousarray(self.knots, dtype=np.float64)

    def _derivatives_py(self, u: np.ndarray, order: int) -> np.ndarray:
        """:meth:`derivatives` at clipped parameters ``u`` in numpy (the reference)."""
        p = self.degree
        pw = self.homogeneous_t
        # Contract basis × control points one basis index j at a time, components first:
        # (4, m) gathers and multiply-adds over contiguous rows, several times faster than an
        # einsum over (m, k, p+1, 4).
        if order == 0:
            spans = find_span(self.knots, p, u)
            basis = basis_functions(self.knots, p, u, spans)
            first = spans - p
            acc = basis[0] * np.take(pw, first, axis=1)
            for j in range(1, p + 1):
                acc += basis[j] * np.take(pw, first + j, axis=1)
            return np.ascontiguousarray((acc[:3] / acc[3]).T)[None]
        spans, ders = basis_derivatives(self.knots, p, u, order)
        first = spans - p
        hom = np.zeros((order + 1, 4, u.size))
        for j in range(p + 1):
            rows = np.take(pw, first + j, axis=1)
            for k in range(min(order, p) + 1):
                hom[k] += ders[:, k, j] * rows
        return rational_derivatives(hom)

    def point(self, u) -> np.ndarray:
        """C(u) [mm], shape (len(u), 3)."""
        return self.derivatives(u, 0)[0]

    def speed(self, u) -> np.ndarray:
        """|C'(u)| [mm per unit u]."""
        return np.linalg.norm(self.derivatives(u, 1)[1], axis=-1)

    def curvature(self, u) -> np.ndarray:
        """κ(u) = |C'×C''|/|C'|³ [1/mm] (SPEC §2, eq. 14); +inf at cusps, never NaN."""
        return curvature_from_derivatives(self.derivatives(u, 2), self.speed_floor)

    def curvature_derivative(self, u) -> np.ndarray:
        """dκ/du [1/mm per unit u]; see :func:`curvature_derivative_from_derivatives`."""
        return curvature_derivative_from_derivatives(self.derivatives(u, 3), self.speed_floor)

    @cached_property
    def power_form(self) -> PowerForm:
        """Each knot span in centred power form (built on first use); see :class:`PowerForm`."""
        return PowerForm.of(self)

    @cached_property
    def arc_table(self) -> ArcLengthTable:
        """The arc-length table over the knot spans (built on first use). The integrand
        |C′| comes from the power form (same values as de Boor to rounding, faster)."""
        return ArcLengthTable.build(self.power_form.speed, self.breakpoints)

    @cached_property
    def inverse_table(self) -> InverseArcTable:
        """The fast inversion table u(s) (built on first use); see :class:`InverseArcTable`."""
        return InverseArcTable.build(self)

    @property
    def length_mm(self) -> float:
        """Total arc length [mm] (SPEC §10)."""
        return self.arc_table.length_mm

    def arc_length(self, u) -> np.ndarray:
        """s(u) [mm] from u_start."""
        return self.arc_table.arc_length(u)

    def step_lengths(self, u) -> np.ndarray:
        """Arc lengths [mm] of the steps between consecutive parameters ``u``
        (:meth:`ArcLengthTable.step_lengths`)."""
        return self.arc_table.step_lengths(u)

    def param_at_length(self, s_mm) -> np.ndarray:
        """u with s(u) = s_mm [mm] (to 1e-12 mm); s clamped to [0, length_mm]."""
        return self.arc_table.param_at_length(s_mm)

    def _params_fast(self, s_mm) -> tuple[np.ndarray, np.ndarray]:
        """(u, knot span) at arc lengths ``s_mm`` by the inversion table; exact Newton where
        the table says so."""
        s = np.clip(as_params(s_mm), 0.0, self.length_mm)
        u, spans, exact = self.inverse_table.params(s)
        if exact.any():
            u[exact] = self.arc_table.param_at_length(s[exact])
            spans[exact] = self.power_form.span_of(u[exact])
        return u, spans

    def param_at_length_fast(self, s_mm) -> np.ndarray:
        """u with s(u) = s_mm [mm] to 1e-9 mm (in practice ~1e-11 mm), by the quintic Hermite
        inversion table (SPEC §10; see :class:`InverseArcTable`): a table look-up and a
        degree-5 polynomial per sample, no iteration. s clamped to [0, length_mm]."""
        return self._params_fast(s_mm)[0]

    def points_at_length(self, s_mm) -> tuple[np.ndarray, np.ndarray]:
        """(C(u), u) at arc lengths ``s_mm`` [mm]: u from :meth:`param_at_length_fast`, the
        points (m, 3) [mm] exactly on the curve (power-form evaluation on u's knot span)."""
        u, spans = self._params_fast(s_mm)
        return self.power_form.point(u, spans), u
