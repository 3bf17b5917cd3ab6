"""Path segments: the interpreter's output, in absolute mm with feeds in mm/s.

Plain frozen data; numpy vectors are read-only ``float64`` arrays of shape ``(3,)`` (x, y, z).
Every segment carries the 1-based source ``line`` it came from.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from nurbscnc.geometry.compiled import kernels as _kernels


def vec3(values) -> np.ndarray:
    """A read-only float64 copy of a 3-vector [mm]."""
    a = np.array(values, dtype=float).reshape(3)
    a.setflags(write=False)
    return a


def frozen_array(values, dtype=float) -> np.ndarray:
    """A read-only numpy copy of ``values``."""
    a = np.array(values, dtype=dtype)
    a.setflags(write=False)
    return a


#: The unit normal of each plane-select mode; G2 turns clockwise, i.e. a negative angle, about
#: it (RS274/NGC: "clockwise as seen from the positive end of the axis normal to the plane").
PLANE_NORMALS = {"XY": (0.0, 0.0, 1.0), "ZX": (0.0, 1.0, 0.0), "YZ": (1.0, 0.0, 0.0)}
#: The two in-plane axis indices (first, second) of each plane, as RS274/NGC orders them.
PLANE_AXES = {"XY": (0, 1), "ZX": (2, 0), "YZ": (1, 2)}


#: ``blend_mm`` of G64 without P: blend within the machine's path tolerance
#: (``limits.path_tolerance_mm``), LinuxCNC's default mode.
BLEND_MACHINE = float("inf")
#: ``blend_mm`` of G61.1 (exact stop): the tool stops at the end of every block.
BLEND_EXACT_STOP = -1.0


def path_control(path_mode: int, p_mm: float | None) -> float:
    """The ``blend_mm`` a segment carries for path-control mode ``path_mode`` (G × 10: 610,
    611, 640) and the G64 P value ``p_mm`` [mm] (None: no P word). As LinuxCNC 2.9, whose
    interpreter gives ``G64`` and ``G64 P0`` the same canonical call (continuous, tolerance
    0: "best speed"), P0 means G64 without P."""
    if path_mode == 611:
        return BLEND_EXACT_STOP
    if path_mode == 610:
        return 0.0
    return BLEND_MACHINE if not p_mm else float(p_mm)


def blend_tolerance_mm(blend_mm, path_tolerance_mm: float) -> np.ndarray:
    """The path tolerance [mm] of each ``blend_mm`` (:func:`path_control`): G64 P as given,
    G64 without P (:data:`BLEND_MACHINE`) ``path_tolerance_mm`` (the machine's), G61 / G61.1
    (≤ 0) none."""
    b = np.asarray(blend_mm, dtype=float)
    return np.where(np.isinf(b), path_tolerance_mm, np.maximum(b, 0.0))


def spiral_arc_length_mm(radius_start_mm, radius_end_mm, angle_rad, helix_mm, t=1.0):
    """Arc length [mm] from the start to fraction ``t`` ∈ [0, 1] of a circular, helical or
    spiral arc, in closed form (vectorised over every argument).

    The arc (see :class:`Arc` and geometry/paths.py) is C(t) = r(t) E(θ) + t H n with
    r(t) = r0 + t Δr, θ = t Δθ, E(θ) the in-plane unit radius vector. Its speed is
    |C'(t)| = √(a² + w²) with a² = Δr² + H² and w(t) = Δθ r(t) (the three terms Δr E,
    r Δθ E⊥ and H n are orthogonal), and since dw/dt = Δθ Δr the integral is elementary:
    s(t) = [F(w(t)) − F(w0)] / (Δθ Δr) with F(w) = ½ (w √(a² + w²) + a² asinh(w / a)).
    Circles and helices (Δr = 0) give s = t √((r Δθ)² + H²).

    The quotient is written as a divided difference without cancellation (LinuxCNC's spirals
    have Δr of a micrometre): with S = √(a² + w²), w1 = w(t),
        (F(w1) − F(w0)) / (w1 − w0) = (S0 + S1)/4 + (w0 + w1)² / (4 (S0 + S1))
                                      + a²/2 · asinh(D)/D · (w0 + w1) / (w1 S0 + w0 S1),
    D = (w1 − w0)(w1 + w0) / (w1 S0 + w0 S1) (from asinh x − asinh y =
    asinh(x √(1+y²) − y √(1+x²))), and s = t Δθ Δr / (Δθ Δr) × that = t × that.
    """
    c = _spiral_constants(radius_start_mm, radius_end_mm, angle_rad, helix_mm)
    return _spiral_length_at(c, np.asarray(t, dtype=float))[0]


def _spiral_constants(radius_start_mm, radius_end_mm, angle_rad, helix_mm) -> tuple:
    """The t-independent terms of :func:`spiral_arc_length_mm` (r0, Δr, Δθ, a², w0, S0 and
    the circle's length √(w0² + H²)), computed once per arc for a Newton's iterations."""
    r0 = np.asarray(radius_start_mm, dtype=float)
    dr = np.asarray(radius_end_mm, dtype=float) - r0
    dtheta = np.asarray(angle_rad, dtype=float)
    h = np.asarray(helix_mm, dtype=float)
    a2 = dr * dr + h * h
    w0 = dtheta * r0
    s0 = np.sqrt(a2 + w0 * w0)
    return r0, dr, dtheta, a2, w0, s0, np.hypot(w0, h)


def _spiral_length_at(c: tuple, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(s(t) [mm], w(t) = Δθ r(t) [mm]) of the arcs of constants ``c`` (:func:`_spiral_constants`)
    at fractions ``t``: the divided-difference formula of :func:`spiral_arc_length_mm`."""
    r0, dr, dtheta, a2, w0, s0, circle = c
    w1 = dtheta * (r0 + t * dr)
    s1 = np.sqrt(a2 + w1 * w1)
    ssum = s0 + s1
    wsum = w0 + w1
    cross = w1 * s0 + w0 * s1  # same sign as Δθ (r > 0); 0 only when Δθ = 0
    with np.errstate(divide="ignore", invalid="ignore"):
        d = (w1 - w0) * wsum / cross
        asinh_ratio = np.where(d == 0.0, 1.0, np.arcsinh(d) / d)
        log_term = np.where(cross != 0.0, 0.5 * a2 * asinh_ratio * wsum / cross, 0.0)
        mean_speed = 0.25 * ssum + np.where(ssum > 0.0, wsum * wsum / (4.0 * ssum), 0.0)
    # Δθ = 0: the speed is a everywhere (s0 = s1 = a, w = 0): the terms above give a/2 + 0
    # + 0, so the log term's share (a/2) is added back.
    mean_speed = mean_speed + np.where(cross != 0.0, log_term, 0.5 * np.sqrt(a2))
    # Δr = 0: exactly √((r Δθ)² + H²)
    return t * np.where(dr == 0.0, circle, mean_speed), w1


def spiral_t_at_length(
    radius_start_mm, radius_end_mm, angle_rad, helix_mm, s_mm, length_mm, max_iter: int = 50
) -> np.ndarray:
    """Fractions t ∈ [0, 1] with s(t) = s_mm [mm] (clamped to [0, length_mm]) on circular,
    helical or spiral arcs (vectorised over every argument, broadcast together): Newton on
    the closed form :func:`spiral_arc_length_mm`, t ← t − (s(t) − s)/|C'(t)|, from t = s/L.
    s is increasing with a convex or concave speed profile √(a² + w(t)²) (w linear in t), so
    after the first step Newton closes in from one side; each sample stops at
    |s(t) − s| ≤ max(1e-12 mm, 8 ulps of s) or at an ulp of t. One arc (ArcGeometry) and
    all the spiral rows of a path table at once (PathTable) use this same arithmetic.
    The arcs' t-independent terms are computed once; the working set is compacted only when
    less than half of it still moves (per sample the same operations: the same bits)."""
    scalars = (radius_start_mm, radius_end_mm, angle_rad, helix_mm, length_mm)
    if isinstance(s_mm, np.ndarray) and all(isinstance(x, float) for x in scalars):
        if s_mm.shape == (1,):
            one = _spiral_t_one(*map(float, scalars), float(s_mm[0]), max_iter)
            if one is not None:
                return np.array([one])
        elif (
            _kernels is not None
            and s_mm.ndim == 1
            and s_mm.dtype == np.float64
            and all(map(math.isfinite, scalars))
            and np.isfinite(s_mm).all()
            and not np.signbit(s_mm).any()
        ):
            # One arc, many samples (a corner side's polyline): the compiled per-sample
            # Newton of _spiral_t_arrays (the same bits, tests/test_paths.py). Not for
            # s < 0 or −0.0: numpy's clip keeps −0.0 with a scalar lower bound and replaces
            # it with an array one (two loops), so no sample rests on that.
            out = np.empty(s_mm.size)
            _kernels.spiral_t(*map(float, scalars), np.ascontiguousarray(s_mm), max_iter, out)
            return out
    return _spiral_t_arrays(*scalars[:4], s_mm, length_mm, max_iter)


def _spiral_t_arrays(
    radius_start_mm, radius_end_mm, angle_rad, helix_mm, s_mm, length_mm, max_iter: int = 50
) -> np.ndarray:
    """:func:`spiral_t_at_length` on numpy arrays (every argument broadcast together): the
    reference of the compiled ``spiral_t`` and the path of every call with arrays of arcs."""
    scalars = (radius_start_mm, radius_end_mm, angle_rad, helix_mm, length_mm)
    r0, r1, ang, hel, big, s_in = np.broadcast_arrays(
        *(np.asarray(x, dtype=float) for x in (*scalars, s_mm))
    )
    s = np.clip(s_in, 0.0, big)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(big > 0.0, s / big, 0.0)
    eps = np.finfo(float).eps
    tol = np.maximum(1e-12, 8.0 * eps * s)
    active = np.flatnonzero((s > 0.0) & (s < big))
    if not active.size:
        return t
    c = _spiral_constants(r0[active], r1[active], ang[active], hel[active])
    a2 = c[3]
    ta, sa, tola = t[active], s[active], tol[active]
    for _ in range(max_iter):
        length, w = _spiral_length_at(c, ta)
        f = length - sa
        settled = np.abs(f) <= tola
        new_t = np.clip(ta - f / np.sqrt(a2 + w * w), 0.0, 1.0)
        done = settled | (np.abs(new_t - ta) <= 2.0 * eps)
        ta = np.where(settled, ta, new_t)
        n_done = int(np.count_nonzero(done))
        if n_done == done.size:
            break
        if 2 * n_done > done.size:  # compact: the finished samples keep their t
            t[active[done]] = ta[done]
            going = ~done
            active, ta, sa, tola = active[going], ta[going], sa[going], tola[going]
            c = tuple(x[going] for x in c)
            a2 = c[3]
        else:
            # Finished samples must not move again: freeze them by their own tolerance.
            tola = np.where(done, np.inf, tola)
    t[active] = ta
    return t


def _spiral_t_one(r0, r1, dtheta, h, big, s_in, max_iter) -> float | None:
    """:func:`spiral_t_at_length` of one sample of one arc in Python floats (a corner's
    search asks for one point at a time: ~15 numpy calls a Newton step on one-element
    arrays cost 10× the arithmetic). The same operations in the same order as the array
    code, each a correctly rounded IEEE operation on either side (+ − × ÷ √); arcsinh and
    hypot are numpy's own on the scalar: the same bits (tests/test_paths.py compares the
    two). None where the array code's special cases would matter (a value not finite, a
    zero speed): the caller takes the array path."""
    if not all(map(math.isfinite, (r0, r1, dtheta, h, big, s_in))):
        return None
    s = s_in if s_in > 0.0 else 0.0  # np.clip(s, 0, L): max(s, 0) then min(·, L)
    s = s if s < big else big
    t = s / big if big > 0.0 else 0.0
    if not (s > 0.0 and s < big):
        return t
    eps = _EPS
    tol = max(1e-12, 8.0 * eps * s)
    dr = r1 - r0
    a2 = dr * dr + h * h
    w0 = dtheta * r0
    s0 = math.sqrt(a2 + w0 * w0)
    circle = float(np.hypot(w0, h))
    for _ in range(max_iter):
        w1 = dtheta * (r0 + t * dr)
        s1 = math.sqrt(a2 + w1 * w1)
        ssum, wsum = s0 + s1, w0 + w1
        cross = w1 * s0 + w0 * s1
        mean_speed = 0.25 * ssum + (wsum * wsum / (4.0 * ssum) if ssum > 0.0 else 0.0)
        if cross != 0.0:
            d = (w1 - w0) * wsum / cross
            ratio = 1.0 if d == 0.0 else float(np.arcsinh(d)) / d
            mean_speed = mean_speed + 0.5 * a2 * ratio * wsum / cross
        else:
            mean_speed = mean_speed + 0.5 * math.sqrt(a2)
        f = t * (circle if dr == 0.0 else mean_speed) - s
        if not s1 > 0.0:  # the speed √(a² + w²) is s1
            return None
        new_t = t - f / s1
        new_t = new_t if new_t > 0.0 else 0.0
        new_t = new_t if new_t < 1.0 else 1.0
        if abs(f) <= tol:
            return t
        if abs(new_t - t) <= 2.0 * eps:
            return new_t
        t = new_t
    return t


_EPS = float(np.finfo(float).eps)


@dataclass(frozen=True, eq=False, slots=True)
class Line:
    """A straight move from ``start_mm`` to ``end_mm`` [mm] at ``feed_mm_s`` [mm/s].

    ``rapid`` marks G0 (the planner moves it at the machine's rapid rate; ``feed_mm_s`` is 0).
    ``blend_mm`` is the path-control mode in force at its end (:func:`path_control`): the
    G64 P tolerance [mm] (> 0), :data:`BLEND_MACHINE` (G64 without P: the machine's path
    tolerance; also G64 P0), 0 (G61: exact path, sharp corners stop) or :data:`BLEND_EXACT_STOP`
    (G61.1: stop at the end of every block). ``naive_mm``: the G64 Q tolerance [mm] of the
    naive CAM detector (consecutive feed lines within it of one line are merged; 0: off).
    The end points
    are plain ``(x, y, z)`` tuples, not arrays: CAM programs hold millions of lines, and a
    tuple costs a fraction of an array's memory and construction time.
    """

    start_mm: tuple
    end_mm: tuple
    feed_mm_s: float
    line: int
    rapid: bool = False
    blend_mm: float = 0.0
    naive_mm: float = 0.0
    #: The rotary axes A B C [deg, machine coordinates] at the start and the end,
    #: ``(a0, b0, c0, a1, b1, c1)``, moving linearly along the move (trivkins); None when all
    #: six are 0 (a program without rotary axes carries nothing).
    abc_deg: tuple | None = None

    @property
    def kind(self) -> str:
        return "rapid" if self.rapid else "line"

    @property
    def length_mm(self) -> float:
        return math.dist(self.end_mm, self.start_mm)


@dataclass(frozen=True, eq=False)
class Arc:
    """A circular or helical arc (G2/G3).

    The tool turns by ``angle_rad`` (signed: positive is counter-clockwise about ``normal``)
    around ``center_mm`` (in the plane of ``start_mm``), from ``start_mm`` to ``end_mm``, while
    advancing ``helix_mm`` along ``normal``. ``radius_start_mm`` and ``radius_end_mm`` may differ
    by the small amount RS274/NGC tolerates; the radius then changes linearly with the angle.
    """

    start_mm: np.ndarray
    end_mm: np.ndarray
    center_mm: np.ndarray
    normal: np.ndarray
    angle_rad: float
    helix_mm: float
    radius_start_mm: float
    radius_end_mm: float
    feed_mm_s: float
    line: int
    plane: str = "XY"
    blend_mm: float = 0.0
    #: A B C [deg] at the start and the end, ``(a0, b0, c0, a1, b1, c1)``, linear in the arc's
    #: length (LinuxCNC's ARC_FEED); None when all six are 0.
    abc_deg: tuple | None = None

    kind = "arc"

    @property
    def length_mm(self) -> float:
        # Closed form for circles, helices and spirals (:func:`spiral_arc_length_mm`).
        return float(
            spiral_arc_length_mm(
                self.radius_start_mm, self.radius_end_mm, self.angle_rad, self.helix_mm
            )
        )


@dataclass(frozen=True, eq=False)
class Nurbs:
    """A rational B-spline of ``degree`` p (order p + 1) in 3-D.

    ``knots`` (n + p + 1,) clamped and non-decreasing; ``control_points_mm`` (n, 3) [mm];
    ``weights`` (n,) > 0; ``plane`` the plane-select mode it was programmed in.
    """

    degree: int
    knots: np.ndarray
    control_points_mm: np.ndarray
    weights: np.ndarray
    feed_mm_s: float
    line: int
    plane: str = "XY"
    blend_mm: float = 0.0

    kind = "nurbs"

    @property
    def start_mm(self) -> np.ndarray:
        return self.control_points_mm[0]

    @property
    def end_mm(self) -> np.ndarray:
        return self.control_points_mm[-1]


class _AtRest:
    """What the stops (Dwell, Pause) share: no length, no feed, start = end = position."""

    feed_mm_s = 0.0
    length_mm = 0.0

    @property
    def start_mm(self) -> tuple:
        return self.position_mm

    @property
    def end_mm(self) -> tuple:
        return self.position_mm


@dataclass(frozen=True, eq=False)
class Dwell(_AtRest):
    """A timed stop of ``seconds`` [s] at ``position_mm`` (an ``(x, y, z)`` tuple): ``code``
    "G4", or the M code that waits for the motion to end (M64, M65, M66, M68: 0 s)."""

    seconds: float
    position_mm: tuple
    line: int
    code: str = "G4"

    kind = "dwell"


@dataclass(frozen=True, eq=False)
class Pause(_AtRest):
    """A program stop (M0, M1 optional stop, M60 pallet change) at ``position_mm`` (an
    ``(x, y, z)`` tuple): the machine stops there and waits for the operator to resume.
    ``code`` is "M0", "M1" or "M60"; "M6" for a tool change (``tool``: the tool number
    to load); "M100"–"M199" for a user M-code (``argv``: the executable's path, then its
    P and Q as text, as LinuxCNC passes them). ``message``: the operator's text of that
    line (its comment or MSG), "" when it has none.

    Its ``kind`` is "pause"; every stage treats the stop kinds
    (:data:`nurbscnc.geometry.path.STOP_KINDS`) alike: come to rest, hold ``seconds`` (0 here).
    ``code`` tells the operator's stop apart (for ``stream``, which waits there).
    """

    position_mm: tuple
    line: int
    code: str = "M0"
    tool: int | None = None
    message: str = ""
    argv: tuple = ()

    kind = "pause"
    seconds = 0.0


@dataclass(frozen=True, eq=False)
class Rotate(_AtRest):
    """A move of the rotary axes alone (X Y Z stand at ``position_mm``): A B C [deg] from
    ``abc_start_deg`` to ``abc_end_deg`` (3-tuples, machine coordinates). ``feed_deg_s``
    [deg/s] is the programmed rate along √(ΔA² + ΔB² + ΔC²) (LinuxCNC's canon: F in deg/min
    for a rotary-only move; under G93 the interpreter's rate, the length times F), or 0 for a
    G0 (the axes' own rapid rate). ``rapid`` marks G0.

    XYZ stand still, so every stage treats it as a stop (:data:`STOP_KINDS`): the path comes to
    rest, the rotary axes move by their own jerk-limited profile, then the path goes on. Its
    duration is the planner's (the machine's rotary limits), not ``seconds`` (0 here).
    """

    position_mm: tuple
    abc_start_deg: tuple
    abc_end_deg: tuple
    feed_deg_s: float
    line: int
    rapid: bool = False

    kind = "rotate"
    seconds = 0.0


Segment = Line | Arc | Nurbs | Dwell | Pause | Rotate


@dataclass(frozen=True)
class Note:
    """Something the user should know that is not an error (an ignored word, an assumption)."""

    line: int
    message: str


@dataclass(frozen=True, eq=False)
class Program:
    """The interpreted program: ordered segments, start point, notes and block statistics."""

    segments: tuple
    start_mm: np.ndarray
    notes: tuple = ()
    blocks: int = 0
    name: str = "<program>"
    source_lines: tuple = field(default=(), repr=False)
    #: The numbered parameters at the program's end (``{number: value}``, lengths in mm):
    #: what a LinuxCNC parameter file keeps (program/varfile.py).
    parameters: dict = field(default_factory=dict, repr=False)
    #: The offsets in force, one row per change: (first segment, coordinate system name
    #: ("G54"…), its origin, the G92 offset, the tool offset [mm, (x, y, z) each], the XY
    #: rotation [deg]) (program/coords.py); errors name them.
    frames: tuple = field(default=(), repr=False)
    #: The rotary axes the program uses (moves, or holds away from 0), a subset of
    #: ``("a", "b", "c")`` in that order: the columns the outputs add.
    rotary_axes: tuple = ()
    #: A B C [deg] at the program's start (machine coordinates).
    start_abc_deg: tuple = (0.0, 0.0, 0.0)
