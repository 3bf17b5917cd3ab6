"""One geometric interface for every segment kind: lines, arcs (circle/helix/spiral), NURBS.

Later stages (corner detection, feed planning, interpolation) see a segment only through
:class:`PathGeometry`: a parameter range [u_start, u_end], derivatives with respect to u,
curvature, and the arc-length map s(u) with its inverse. For lines and constant-radius arcs u
*is* the arc length [mm] (so ``param_at_length`` is exact); for a spiral arc (radius changing
with angle) u = (angle fraction) × L and s(u) is a closed form (an elementary integral); for
NURBS u is the knot parameter (:mod:`nurbscnc.geometry.nurbs`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Protocol, runtime_checkable

import numpy as np

from nurbscnc.errors import GeometryError
from nurbscnc.geometry import segments
from nurbscnc.geometry.bspline import (
    curvature_derivative_from_derivatives,
    curvature_from_derivatives,
)
from nurbscnc.geometry.nurbs import NurbsCurve


@runtime_checkable
class PathGeometry(Protocol):
    """What every segment's geometry offers (u arrays in, arrays out; scalars accepted).

    ``derivatives(u, order)`` has shape (order+1, len(u), 3): C, C', ... [mm / unit u^k];
    ``arc_length(u)`` [mm] from u_start; ``param_at_length(s_mm)`` its inverse;
    ``curvature(u)`` κ [1/mm]; ``curvature_derivative(u)`` dκ/du.
    """

    @property
    def u_start(self) -> float: ...

    @property
    def u_end(self) -> float: ...

    @property
    def length_mm(self) -> float: ...

    def derivatives(self, u, order: int = 3) -> np.ndarray: ...

    def point(self, u) -> np.ndarray: ...

    def arc_length(self, u) -> np.ndarray: ...

    def param_at_length(self, s_mm) -> np.ndarray: ...

    def curvature(self, u) -> np.ndarray: ...

    def curvature_derivative(self, u) -> np.ndarray: ...


#: Up to this many parameters, :meth:`ArcGeometry.derivatives` works in Python floats.
FEW_POINTS = 4


def _params(u) -> np.ndarray:
    return np.atleast_1d(np.asarray(u, dtype=float)).ravel()


def _norm(v: np.ndarray) -> float:
    """|v| of a 1-D vector as ``np.linalg.norm`` computes it (√ of ``v.dot(v)``), without its
    argument handling (~4 µs a call)."""
    return math.sqrt(float(v.dot(v)))


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b of two 3-vectors: ``np.cross``'s products and differences (a1 b2 − a2 b1, …), so
    its bits, in Python floats (np.cross costs ~30 µs a call on 3-vectors)."""
    a0, a1, a2 = a.tolist()
    b0, b1, b2 = b.tolist()
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


@dataclass(frozen=True, eq=False)
class LineGeometry:
    """The segment from ``start_mm`` to ``end_mm`` [mm], parameterised by arc length u ∈ [0, L].

    C(u) = start + u t with t the unit direction (t = 0 for a zero-length line). κ = 0.
    """

    start_mm: np.ndarray
    end_mm: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "start_mm", segments.vec3(self.start_mm))
        object.__setattr__(self, "end_mm", segments.vec3(self.end_mm))

    u_start = 0.0

    @cached_property
    def length_mm(self) -> float:
        return float(np.linalg.norm(self.end_mm - self.start_mm))

    @property
    def u_end(self) -> float:
        return self.length_mm

    @cached_property
    def direction(self) -> np.ndarray:
        """Unit tangent t (zero vector for a zero-length line)."""
        length = self.length_mm
        return (self.end_mm - self.start_mm) / length if length > 0.0 else np.zeros(3)

    def derivatives(self, u, order: int = 3) -> np.ndarray:
        """[C, C', 0, ...], shape (order+1, len(u), 3); u clamped to [0, L]."""
        u = np.clip(_params(u), 0.0, self.length_mm)
        out = np.zeros((order + 1, u.size, 3))
        # Interpolate from both ends so u = L gives end_mm exactly (not start + L t).
        length = self.length_mm
        frac = u / length if length > 0.0 else np.zeros_like(u)
        out[0] = self.start_mm + frac[:, None] * (self.end_mm - self.start_mm)
        out[0][frac == 1.0] = self.end_mm
        if order >= 1:
            out[1] = self.direction
        return out

    def point(self, u) -> np.ndarray:
        return self.derivatives(u, 0)[0]

    def arc_length(self, u) -> np.ndarray:
        return np.clip(_params(u), 0.0, self.length_mm)

    def param_at_length(self, s_mm) -> np.ndarray:
        return np.clip(_params(s_mm), 0.0, self.length_mm)

    def curvature(self, u) -> np.ndarray:
        return np.zeros(_params(u).size)

    def curvature_derivative(self, u) -> np.ndarray:
        return np.zeros(_params(u).size)


def _rotated(cos_t: np.ndarray, sin_t: np.ndarray, quarter_turns: int) -> tuple:
    """(cos, sin) of θ + k π/2, exactly (k-th derivative of (cos θ, sin θ) w.r.t. θ)."""
    return [
        (cos_t, sin_t),
        (-sin_t, cos_t),
        (-cos_t, -sin_t),
        (sin_t, -cos_t),
    ][quarter_turns % 4]


@dataclass(frozen=True, eq=False)
class ArcGeometry:
    """A circular, helical or (slightly) spiral arc.

    With fraction t ∈ [0, 1], θ = t Δθ, r(t) = r0 + t (r1 − r0):
    C = origin + r(t) (cos θ e1 + sin θ e2) + t H n, where e1 is the in-plane start direction,
    e2 = n × e1 (so positive Δθ is counter-clockwise about n, G3) and H the helical rise.
    The parameter is u = t L ∈ [0, L] with L the true arc length: for constant radius
    L = hypot(r Δθ, H) and u is exactly arc length; for a spiral L and s(u) are the closed
    form of :func:`segments.spiral_arc_length_mm` (an elementary integral).
    """

    origin_mm: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    normal: np.ndarray
    radius_start_mm: float
    radius_end_mm: float
    angle_rad: float
    helix_mm: float

    @classmethod
    def from_segment(cls, seg: segments.Arc) -> ArcGeometry:
        """Geometry of a ``segments.Arc`` (see its docstring for the conventions)."""
        n = np.asarray(seg.normal, dtype=float)
        n_norm = _norm(n)
        if not n_norm > 0.0:
            raise GeometryError(f"arc on line {seg.line} has a zero normal")
        n = n / n_norm
        d = np.asarray(seg.start_mm, dtype=float) - np.asarray(seg.center_mm, dtype=float)
        axial = float(d @ n)
        d_in = d - axial * n
        d_in_norm = _norm(d_in)
        if not d_in_norm > 0.0:
            raise GeometryError(f"arc on line {seg.line} starts at its center")
        e1 = d_in / d_in_norm
        e2 = cross3(n, e1)
        # The axis point in the start's plane: start = origin + r0 e1 when r0 = |d_in|.
        origin = np.asarray(seg.center_mm, dtype=float) + axial * n
        return cls(
            origin_mm=segments.vec3(origin),
            e1=segments.vec3(e1),
            e2=segments.vec3(e2),
            normal=segments.vec3(n),
            radius_start_mm=float(seg.radius_start_mm),
            radius_end_mm=float(seg.radius_end_mm),
            angle_rad=float(seg.angle_rad),
            helix_mm=float(seg.helix_mm),
        )

    @property
    def is_spiral(self) -> bool:
        return self.radius_end_mm != self.radius_start_mm

    u_start = 0.0

    def _derivatives_t(self, t: np.ndarray, order: int) -> np.ndarray:
        """d^k C / dt^k for t ∈ [0, 1] (Leibniz: r'' = 0, so two terms per order)."""
        dtheta = self.angle_rad
        dr = self.radius_end_mm - self.radius_start_mm
        theta = t * dtheta
        radius = self.radius_start_mm + t * dr
        c, s = np.cos(theta), np.sin(theta)
        e1, e2 = self.e1, self.e2
        out = np.empty((order + 1, t.size, 3))
        for k in range(order + 1):
            ck, sk = _rotated(c, s, k)
            # d^k/dt^k [r E(θ)] = r Δθ^k E(θ + kπ/2) + k r' Δθ^(k−1) E(θ + (k−1)π/2)
            term = (radius * dtheta**k)[:, None] * (ck[:, None] * e1 + sk[:, None] * e2)
            if k >= 1:
                cm, sm = _rotated(c, s, k - 1)
                term += (k * dr * dtheta ** (k - 1)) * (cm[:, None] * e1 + sm[:, None] * e2)
            out[k] = term
        out[0] += self.origin_mm + (t * self.helix_mm)[:, None] * self.normal
        if order >= 1:
            out[1] += self.helix_mm * self.normal
        return out

    @cached_property
    def _frame_floats(self) -> tuple:
        """(e1, e2, origin, normal) as tuples of Python floats (the few-point path)."""
        return tuple(tuple(v.tolist()) for v in (self.e1, self.e2, self.origin_mm, self.normal))

    def _derivatives_few(self, u: list, order: int, scale: float) -> np.ndarray | None:
        """:meth:`derivatives` at a few parameters ``u`` (Python floats) in Python floats: the
        corner searches ask for one point at a time and the pieces for their two ends, where
        ~15 numpy calls on one- or two-element arrays per order cost 10× the arithmetic. The
        same operations in the same order as :meth:`derivatives` (t = u/L, ``np.clip``: a
        value below 0 or above 1 replaced by it, −0.0 kept) and :meth:`_derivatives_t`, each
        a correctly rounded IEEE operation either way (+ − × ÷; a negation and the quarter
        turns are exact); cos and sin are numpy's own on the same array of θ: the same bits
        (tests/test_paths.py compares the two). None for a u that is not finite (the array
        path's special cases)."""
        ts = []
        for x in u:
            t = x / scale
            if not math.isfinite(t):
                return None
            t = 0.0 if t < 0.0 else t
            ts.append(1.0 if t > 1.0 else t)
        dtheta = self.angle_rad
        dr = self.radius_end_mm - self.radius_start_mm
        theta = np.array([t * dtheta for t in ts])
        cos_t, sin_t = np.cos(theta).tolist(), np.sin(theta).tolist()
        (e1x, e1y, e1z), (e2x, e2y, e2z), origin, normal = self._frame_floats
        helix = self.helix_mm
        rows = [[] for _ in range(order + 1)]
        for t, c, s in zip(ts, cos_t, sin_t):
            radius = self.radius_start_mm + t * dr
            rot = ((c, s), (-s, c), (-c, -s), (s, -c))  # E(θ + k π/2), k = 0 … 3
            for k in range(order + 1):
                ck, sk = rot[k % 4]
                rk = radius * dtheta**k
                v = [
                    rk * (ck * e1x + sk * e2x),
                    rk * (ck * e1y + sk * e2y),
                    rk * (ck * e1z + sk * e2z),
                ]
                if k >= 1:
                    cm, sm = rot[(k - 1) % 4]
                    q = k * dr * dtheta ** (k - 1)
                    v = [
                        v[0] + q * (cm * e1x + sm * e2x),
                        v[1] + q * (cm * e1y + sm * e2y),
                        v[2] + q * (cm * e1z + sm * e2z),
                    ]
                if k == 0:
                    rise = t * helix
                    v = [a + (o + rise * n) for a, o, n in zip(v, origin, normal)]
                elif k == 1:
                    v = [a + helix * n for a, n in zip(v, normal)]
                if k >= 1:
                    div = scale**k
                    v = [a / div for a in v]
                rows[k].append(v)
        return np.array(rows)

    def _length_t(self, t) -> np.ndarray:
        """s(t) [mm] from the start, closed form (segments.spiral_arc_length_mm)."""
        return segments.spiral_arc_length_mm(
            self.radius_start_mm, self.radius_end_mm, self.angle_rad, self.helix_mm, t
        )

    @cached_property
    def length_mm(self) -> float:
        """True arc length [mm], closed form: hypot(r Δθ, H) for constant radius, the
        elementary spiral integral otherwise (segments.spiral_arc_length_mm)."""
        if not self.is_spiral:
            return float(np.hypot(self.radius_start_mm * self.angle_rad, self.helix_mm))
        return float(self._length_t(1.0))

    def _param_t_at_length(self, s_mm: np.ndarray, max_iter: int = 50) -> np.ndarray:
        """t ∈ [0, 1] with s(t) = s_mm (clamped): Newton on the closed form
        (:func:`segments.spiral_t_at_length`)."""
        return segments.spiral_t_at_length(
            self.radius_start_mm,
            self.radius_end_mm,
            self.angle_rad,
            self.helix_mm,
            s_mm,
            self.length_mm,
            max_iter,
        )

    @property
    def u_end(self) -> float:
        return self.length_mm

    @property
    def _u_scale(self) -> float:
        """L, or 1 for a degenerate zero-length arc (keeps every quotient finite)."""
        return self.length_mm if self.length_mm > 0.0 else 1.0

    def derivatives(self, u, order: int = 3) -> np.ndarray:
        """[C, C', ...] w.r.t. u = t L, shape (order+1, len(u), 3); u clamped to [0, L]."""
        scale = self._u_scale
        u = _params(u)
        if 0 < u.size <= FEW_POINTS:
            few = self._derivatives_few(u.tolist(), order, scale)
            if few is not None:
                return few
        t = np.clip(u / scale, 0.0, 1.0)
        out = self._derivatives_t(t, order)
        for k in range(1, order + 1):
            out[k] /= scale**k
        return out

    def point(self, u) -> np.ndarray:
        return self.derivatives(u, 0)[0]

    def arc_length(self, u) -> np.ndarray:
        if not self.is_spiral:
            return np.clip(_params(u), 0.0, self.length_mm)
        return self._length_t(np.clip(_params(u) / self._u_scale, 0.0, 1.0))

    def param_at_length(self, s_mm) -> np.ndarray:
        if not self.is_spiral:
            return np.clip(_params(s_mm), 0.0, self.length_mm)
        return self._u_scale * self._param_t_at_length(_params(s_mm))

    def curvature(self, u) -> np.ndarray:
        """κ [1/mm]; r/(r² + c²) with c = H/Δθ on a helix, 1/r on a circle."""
        return curvature_from_derivatives(self.derivatives(u, 2))

    def curvature_derivative(self, u) -> np.ndarray:
        """dκ/du [1/mm²] (0 for constant radius up to rounding)."""
        return curvature_derivative_from_derivatives(self.derivatives(u, 3))


def geometry_of(segment) -> PathGeometry:
    """The :class:`PathGeometry` of a Line, Arc or Nurbs segment. An arc's is built once per
    segment object and kept on it (:func:`arc_geometry`)."""
    if isinstance(segment, segments.Line):
        return LineGeometry(segment.start_mm, segment.end_mm)
    if isinstance(segment, segments.Arc):
        return arc_geometry(segment)
    if isinstance(segment, segments.Nurbs):
        return NurbsCurve.from_segment(segment)
    raise TypeError(f"no path geometry for a {type(segment).__name__}")


def arc_geometry(segment: segments.Arc) -> ArcGeometry:
    """The :class:`ArcGeometry` of an arc segment, built on the first call and kept on the
    segment (both are immutable): the soft-limits box, the pieces and the lower bound ask for
    the same arc, and the geometry's cached length (a closed-form integral on a spiral) is
    then computed once. The same object as a fresh :meth:`ArcGeometry.from_segment`, value
    for value (a deterministic function of the segment's fields)."""
    memo = segment.__dict__
    geom = memo.get("_arc_geometry")
    if geom is None:
        geom = memo["_arc_geometry"] = ArcGeometry.from_segment(segment)
    return geom
