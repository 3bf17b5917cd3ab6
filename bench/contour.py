"""Independent contour error of a reference-point stream (issue 13's benchmark measure).

The planner predicts its own contour error; this module measures it again from the output
alone, with none of the planner's code:

1. **Servo** (SPEC §8, eq. 25): each axis's closed-loop transfer function
   G(s) = (b2 s² + b1 s + b0)/(a4 s⁴ + a3 s³ + a2 s² + a1 s + a0) with the coefficients of
   SPEC Table 2 (X and Y; Z follows its reference) is simulated by ``scipy.signal.lsim`` on
   the reference points held linearly between servo periods (``interp=True``, a first-order
   hold), started at rest at the first point; the last point is held for ``settle_s`` so the
   stop's overshoot is seen.
2. **Path**: the programmed path (lines, arcs and helices in closed form, NURBS by
   ``scipy.interpolate.BSpline`` on homogeneous coordinates) as a dense polyline.
3. **Distance**: the true Euclidean distance from each simulated tool point to that polyline
   (point-to-segment distance, minimised over the segments next to the tool point's nearest
   vertices found by a k-d tree), not the distance to the nearest vertex.
4. **The guarantee per sample** (issue 35: ε_max, "plus the path tolerance where a blend may
   leave the programmed path"): a tool sample passes if it lies within ε_max of the
   programmed path, or of the commanded path (the stream's own points as a polyline: what
   the planner planned), or within ε_max + P of the programmed vertex of a G64 corner
   (:func:`g64_vertices`; P that corner's path tolerance). Its *allowed error*
   e = min(d_programmed, d_commanded, |a − V| − P) must be ≤ ε_max; with the commanded path
   within P of the programmed one (``reference_deviation_max_um``) every pass implies a
   distance ≤ ε_max + P to the programmed path. The commanded polyline's chords (1 ms apart)
   lie inside a curve by at most (vT)²κ/8 (0.3 µm at 25 mm/s on a 0.25 mm radius).

The same functions measure LinuxCNC's 1 ms positions and nurbscnc's reference points, so the
two columns of the benchmark table are measured alike.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal
from scipy.interpolate import BSpline
from scipy.spatial import cKDTree

#: SPEC Table 2 (eq. 25): numerator (b2, b1, b0), denominator (a4, a3, a2, a1, a0), per axis.
SPEC_TABLE2 = {
    "x": ((1.471e5, 3.476e7, 1.938e9), (1.00, 6.984e2, 2.135e5, 3.538e7, 1.938e9)),
    "y": ((1.466e5, 3.435e7, 1.904e9), (1.00, 6.948e2, 2.120e5, 3.496e7, 1.904e9)),
}
SERVO_PERIOD_S = 1e-3
#: Vertex spacing of lines in the dense path [mm]: lines are exact as segments, the spacing
#: only lets the k-d tree find the right segments.
LINE_SPACING_MM = 0.01
#: Largest sagitta [mm] of an arc chord in the dense path (h = √(8 r s), h ≤ LINE_SPACING_MM).
ARC_SAGITTA_MM = 1e-6
#: NURBS parameter samples per mm of control polygon (a cubic's speed never exceeds its
#: control polygon's, so this is at least 500 vertices per mm of curve: chord ≤ 2 µm).
NURBS_SAMPLES_PER_MM = 500
#: Nearest vertices whose two adjacent segments are searched for the true nearest segment.
NEAREST_VERTICES = 12


def simulate_tool_mm(
    reference_mm: np.ndarray,
    period_s: float = SERVO_PERIOD_S,
    settle_s: float = 0.3,
    models: dict | None = None,
) -> np.ndarray:
    """Tool positions (M, 3) [mm] at k·period_s of the servo driven by ``reference_mm`` (N, 3).

    ``models`` maps "x"/"y"/"z" to ``(numerator, denominator)`` coefficient tuples in
    descending powers of s (default SPEC Table 2); an axis without a model follows its
    reference. M = N + round(settle_s / period_s): the last reference point is held.
    Each axis starts at rest at its first reference point (zero state on the offset input,
    plus the DC response b0/a0 of that constant start).
    """
    models = SPEC_TABLE2 if models is None else models
    ref = np.asarray(reference_mm, dtype=float)
    extra = int(round(settle_s / period_s))
    ref = np.vstack([ref, np.repeat(ref[-1:], extra, axis=0)])
    t_s = np.arange(ref.shape[0]) * period_s
    tool = ref.copy()
    for axis, name in enumerate("xyz"):
        if name not in models:
            continue
        num, den = (np.asarray(c, dtype=float) for c in models[name])
        dc = num[-1] / den[-1]
        u = ref[:, axis] - ref[0, axis]
        if np.any(u):
            _, y, _ = signal.lsim(signal.lti(num, den), u, t_s, interp=True)
        else:
            y = np.zeros_like(u)
        tool[:, axis] = y + dc * ref[0, axis]
    return tool


# --------------------------------------------------------------------------- dense path


def _line_mm(start, end) -> np.ndarray:
    start, end = np.asarray(start, float), np.asarray(end, float)
    n = max(1, math.ceil(np.linalg.norm(end - start) / LINE_SPACING_MM))
    s = np.linspace(0.0, 1.0, n + 1)[:, None]
    return start + s * (end - start)


def _arc_mm(seg) -> np.ndarray:
    """Dense points of an arc/helix: p(s) = c + r(s)(cos(sθ) e1 + sin(sθ) n×e1) + s·h·n."""
    normal = np.asarray(seg.normal, float)
    normal = normal / np.linalg.norm(normal)
    center = np.asarray(seg.center_mm, float)
    radial = np.asarray(seg.start_mm, float) - center
    radial -= normal * (radial @ normal)
    e1 = radial / np.linalg.norm(radial)
    e2 = np.cross(normal, e1)
    r_max = max(seg.radius_start_mm, seg.radius_end_mm)
    spacing = min(LINE_SPACING_MM, math.sqrt(8.0 * r_max * ARC_SAGITTA_MM))
    length = math.hypot(r_max * seg.angle_rad, seg.helix_mm)
    n = max(2, math.ceil(length / spacing))
    s = np.linspace(0.0, 1.0, n + 1)[:, None]
    r = seg.radius_start_mm + s * (seg.radius_end_mm - seg.radius_start_mm)
    a = s * seg.angle_rad
    pts = center + r * (np.cos(a) * e1 + np.sin(a) * e2) + s * seg.helix_mm * normal
    gap = np.linalg.norm(pts[-1] - np.asarray(seg.end_mm, float))
    if gap > 1e-4:
        raise ValueError(f"arc of line {seg.line}: closed form ends {gap:.2e} mm off its end")
    return pts


def _nurbs_mm(seg) -> np.ndarray:
    """Dense points of a rational B-spline: BSpline(w·P) / BSpline(w) (homogeneous form)."""
    p = int(seg.degree)
    knots = np.asarray(seg.knots, float)
    ctrl = np.asarray(seg.control_points_mm, float)
    w = np.asarray(seg.weights, float)
    polygon_mm = float(np.sum(np.linalg.norm(np.diff(ctrl, axis=0), axis=1)))
    n = max(16, math.ceil(polygon_mm * NURBS_SAMPLES_PER_MM))
    u = np.linspace(knots[p], knots[-p - 1], n + 1)
    num = BSpline(knots, ctrl * w[:, None], p)(u)
    den = BSpline(knots, w, p)(u)
    return num / den[:, None]


def path_polyline_mm(segments) -> np.ndarray:
    """The programmed path of a nurbscnc ``Program.segments`` as a dense polyline (V, 3)."""
    parts = []
    for seg in segments:
        kind = getattr(seg, "kind", None)
        if kind in ("line", "rapid"):
            if seg.length_mm > 0:
                parts.append(_line_mm(seg.start_mm, seg.end_mm))
        elif kind == "arc":
            parts.append(_arc_mm(seg))
        elif kind == "nurbs":
            parts.append(_nurbs_mm(seg))
        elif (
            hasattr(seg, "start_mm")
            and hasattr(seg, "end_mm")
            and kind
            not in (
                "dwell",
                "pause",
            )
        ):
            raise ValueError(f"unknown segment kind {kind!r} (line {seg.line})")
    if not parts:
        raise ValueError("the program has no motion")
    return np.vstack(parts)


# --------------------------------------------------------------------------- distance


def distance_to_polyline_mm(
    points_mm: np.ndarray, polyline_mm: np.ndarray, chunk: int = 50_000
) -> np.ndarray:
    """True distance [mm] from each point (M, 3) to the polyline (V, 3).

    For each point the ``NEAREST_VERTICES`` nearest vertices are found by a k-d tree; the
    distance is the minimum over the segments on both sides of them of the point-to-segment
    distance |p − (a + clip(t, 0, 1)(b − a))|, t = (p − a)·(b − a)/|b − a|².
    """
    pts = np.asarray(points_mm, dtype=float)
    poly = np.asarray(polyline_mm, dtype=float)
    if poly.shape[0] == 1:
        return np.linalg.norm(pts - poly[0], axis=1)
    tree = cKDTree(poly)
    k = min(NEAREST_VERTICES, poly.shape[0])
    out = np.empty(pts.shape[0])
    last = poly.shape[0] - 2  # index of the last segment
    for lo in range(0, pts.shape[0], chunk):
        p = pts[lo : lo + chunk]
        _, idx = tree.query(p, k=k)
        idx = idx.reshape(p.shape[0], k)
        seg = np.concatenate([np.clip(idx - 1, 0, last), np.clip(idx, 0, last)], axis=1)
        a = poly[seg]  # (m, 2k, 3)
        d = poly[seg + 1] - a
        dd = np.einsum("mkj,mkj->mk", d, d)
        t = np.einsum("mkj,mkj->mk", p[:, None, :] - a, d) / np.where(dd > 0, dd, 1.0)
        foot = a + np.clip(t, 0.0, 1.0)[..., None] * d
        out[lo : lo + chunk] = np.min(np.linalg.norm(p[:, None, :] - foot, axis=2), axis=1)
    return out


def g64_vertices(segments, path_tolerance_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """The programmed vertices of G64 corners of ``Program.segments`` and their path
    tolerances: (V (m, 3) [mm], P (m,) [mm]). A vertex is the end of a feed move (line, arc
    or NURBS; not a rapid) that the next segment, also a feed move, starts at (a dwell or
    pause between them is a segment of its own: no vertex), both under G64: ``blend_mm``
    inf is G64 without P (``path_tolerance_mm``, the machine's), > 0 G64 P, ≤ 0 G61 / G61.1
    (none); P the smaller of the two moves'. The program's first start and last end are no
    vertices."""
    feed = ("line", "arc", "nurbs")

    def tol(seg) -> float:
        b = float(getattr(seg, "blend_mm", 0.0))
        return path_tolerance_mm if math.isinf(b) else max(b, 0.0)

    vertices, tols = [], []
    for a, b in zip(segments[:-1], segments[1:]):
        if getattr(a, "kind", None) not in feed or getattr(b, "kind", None) not in feed:
            continue
        if getattr(a, "rapid", False) or getattr(b, "rapid", False):
            continue
        p = min(tol(a), tol(b))
        end, start = np.asarray(a.end_mm, float), np.asarray(b.start_mm, float)
        if p > 0.0 and np.allclose(end, start, rtol=0.0, atol=1e-9):
            vertices.append(end)
            tols.append(p)
    if not vertices:
        return np.zeros((0, 3)), np.zeros(0)
    return np.array(vertices), np.array(tols)


def allowed_error_mm(
    tool_mm: np.ndarray,
    d_programmed_mm: np.ndarray,
    commanded_mm: np.ndarray,
    corners: tuple[np.ndarray, np.ndarray],
    eps_mm: float,
) -> np.ndarray:
    """The allowed error [mm] of each tool sample (M,) (module doc, 4.): its distance to the
    programmed path ``d_programmed_mm`` where that is within ``eps_mm``, else the least of
    it, the distance to the commanded polyline ``commanded_mm`` (N, 3) and |a − V| − P over
    the G64 vertices ``corners`` (:func:`g64_vertices`; the 8 nearest by a k-d tree)."""
    out = np.array(d_programmed_mm, dtype=float, copy=True)
    i = np.flatnonzero(out > eps_mm)
    if i.size == 0:
        return out
    p = tool_mm[i]
    out[i] = np.minimum(out[i], distance_to_polyline_mm(p, commanded_mm))
    vertices, tol = corners
    if vertices.shape[0]:
        k = min(8, vertices.shape[0])
        dist, idx = cKDTree(vertices).query(p, k=k)
        dist, idx = dist.reshape(p.shape[0], k), idx.reshape(p.shape[0], k)
        out[i] = np.minimum(out[i], (dist - tol[idx]).min(axis=1))
    return out


# --------------------------------------------------------------------------- measures


@dataclass(frozen=True)
class Motion:
    """Timing of a reference stream: the span from the last sample at rest before the first
    motion to the first sample at rest after the last (as LinuxCNC's recorder cuts it)."""

    start_index: int
    end_index: int
    period_s: float

    @property
    def seconds(self) -> float:
        return (self.end_index - self.start_index) * self.period_s


def motion_span(reference_mm: np.ndarray, period_s: float = SERVO_PERIOD_S) -> Motion:
    """The motion span of a reference (N, 3): see :class:`Motion`."""
    step = np.linalg.norm(np.diff(reference_mm, axis=0), axis=1)
    moving = np.flatnonzero(step > 0)
    if moving.size == 0:
        return Motion(0, 0, period_s)
    return Motion(int(moving[0]), int(moving[-1]) + 1, period_s)


def slow_drops(
    reference_mm: np.ndarray, period_s: float = SERVO_PERIOD_S, below_mm_s: float = 0.5
) -> int:
    """How many times the reference's speed |Δp|/T falls below ``below_mm_s`` [mm/s] from
    above during the motion (a stop or near-stop inside the program; issue 13 counts them)."""
    speed = np.linalg.norm(np.diff(reference_mm, axis=0), axis=1) / period_s
    fast = speed >= below_mm_s
    return int(np.count_nonzero(fast[:-1] & ~fast[1:]))


def settle_waits(points_mm: np.ndarray, cutting: np.ndarray) -> np.ndarray:
    """(N,) bool: the samples where a controller waits, at rest, at the start of a cut that
    follows a rapid: at the start of each run of ``cutting`` samples after a sample that is
    not, the samples at the run's first point while the reference rests there (it stays, or
    it arrived there a sample before). The tool is still settling from the rapid and nothing
    is being cut (nurbscnc's settle after a rapid, whose samples carry the cut's line: its
    dynamics check measures the cut from its first motion); the tool must be within the
    limit once the reference moves. A cut the reference enters moving has no wait."""
    pts = np.asarray(points_mm, dtype=float)
    cut = np.asarray(cutting, dtype=bool)
    wait = np.zeros(cut.size, dtype=bool)
    for i in (np.flatnonzero(cut[1:] & ~cut[:-1]) + 1).tolist():
        j = i
        while j + 1 < cut.size and cut[j + 1] and np.array_equal(pts[j + 1], pts[i]):
            j += 1
        if j > i or np.array_equal(pts[i], pts[i - 1]):
            wait[i : j + 1] = True
    return wait


def block_start_index(lines: np.ndarray, block_line: int) -> int:
    """Index of the last sample of the motion before the block at ``block_line``: the last
    sample whose source line is positive and below it (the move that brings the tool to the
    block's start). Line 0 (LinuxCNC's "no line") is ignored. 0 when there is none."""
    before = np.flatnonzero((lines > 0) & (lines < block_line))
    return int(before[-1]) if before.size else 0


def block_leave_index(points_mm: np.ndarray, lines: np.ndarray, block_line: int) -> tuple:
    """``(arrive, leave)``: the last sample of the move before the block at ``block_line``
    (:func:`block_start_index`), and the last sample at rest at the block's start after it
    (a wait there, e.g. a settle after the rapid; ``leave == arrive`` when the block starts
    at once). The block's own time runs from ``leave``."""
    arrive = block_start_index(lines, block_line)
    step = np.linalg.norm(np.diff(points_mm[arrive + 1 :], axis=0), axis=1)
    rest = int(np.argmax(step > 0)) if np.any(step > 0) else 0  # rest samples after arrive+1
    return arrive, (arrive + 1 + rest if rest else arrive)


def contour_errors_um(
    reference_mm: np.ndarray,
    polyline_mm: np.ndarray,
    period_s: float = SERVO_PERIOD_S,
    settle_s: float = 0.3,
    models: dict | None = None,
    cutting: np.ndarray | None = None,
    corners: tuple[np.ndarray, np.ndarray] | None = None,
    eps_mm: float = 0.015,
) -> dict:
    """Simulated tool vs path [µm]: ``contour_max_um`` / ``contour_rms_um`` over the samples
    where ``cutting`` (N,) is true (default all; the settle after the end takes the last
    sample's flag), ``contour_max_all_um`` over the whole run, and the reference's own
    largest distance from the path (``reference_deviation_max_um``, cutting samples). With
    ``corners`` (:func:`g64_vertices`): ``contour_allowed_max_um``, the largest allowed
    error (:func:`allowed_error_mm`, ε_max = ``eps_mm``) of the cutting samples, and
    ``contour_allowance_samples``, how many of them are over ε_max from both paths (within
    a corner's allowance or not). The held tail after the stream's end has no allowance."""
    tool = simulate_tool_mm(reference_mm, period_s, settle_s, models)
    err = distance_to_polyline_mm(tool, polyline_mm)
    ref_dev = distance_to_polyline_mm(reference_mm, polyline_mm)
    n = reference_mm.shape[0]
    mask = np.ones(n, bool) if cutting is None else np.asarray(cutting, bool)
    mask_all = np.concatenate([mask, np.repeat(mask[-1:], err.size - n)])
    cut = err[mask_all] if mask_all.any() else err
    extra = {}
    if corners is not None:
        allowed = err.copy()
        allowed[:n] = allowed_error_mm(tool[:n], err[:n], reference_mm, corners, eps_mm)
        tail = np.arange(err.size) >= n  # the end's settle: the commanded path, no vertex
        allowed[tail] = np.minimum(err[tail], distance_to_polyline_mm(tool[tail], reference_mm))
        a = allowed[mask_all] if mask_all.any() else allowed
        over = (a > eps_mm) | (cut > eps_mm)
        extra = {
            "contour_allowed_max_um": float(a.max() * 1e3),
            "contour_allowance_samples": int(np.count_nonzero(over & (a <= eps_mm))),
        }
    return {
        **extra,
        "contour_max_um": float(cut.max() * 1e3),
        "contour_rms_um": float(np.sqrt(np.mean(cut**2)) * 1e3),
        "contour_argmax_s": float(np.flatnonzero(mask_all)[np.argmax(cut)] * period_s)
        if mask_all.any()
        else float(np.argmax(err) * period_s),
        "contour_max_all_um": float(err.max() * 1e3),
        "contour_argmax_all_s": float(np.argmax(err) * period_s),
        "reference_deviation_max_um": float((ref_dev[mask] if mask.any() else ref_dev).max() * 1e3),
    }
