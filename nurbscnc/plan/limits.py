"""Checks before work: soft limits on the geometry, and the number of reference
points, refused before anything is planned or sampled.

- :func:`segment_boxes_mm`: the axis-aligned box of every segment, exact for lines and arcs
  (closed form), the control-point hull for NURBS (convex-hull property of a NURBS with
  positive weights: the curve lies inside the hull of its control points);
- :func:`check_geometry_limits`: PlanningError at the first segment whose box leaves the soft
  limits, naming the axis and value;
- :func:`check_motion_time`: a lower bound of the motion time from the geometry alone (each
  segment's length / min(F, V_max), the rapid rate for G0, dwells their seconds): more
  reference points than ``limits.max_points`` is a PlanningError at the segment that takes
  the most time;
- :func:`check_point_count`: the same cap on the planned cycle time, after the profile and
  before the servo clock is sampled.

Blends (G64 P) and corner PH fits stay within their tolerance of the programmed path; the
sample check (:func:`nurbscnc.plan.report.check_soft_limits`) is the final guard for them.
"""

from __future__ import annotations

import math

import numpy as np

from nurbscnc.errors import PlanningError, SourcePos
from nurbscnc.program.columns import ARC, DWELL, NURBS, PAUSE, RAPID, segment_columns

AXES = "XYZ"


def arc_box_mm(seg) -> tuple[np.ndarray, np.ndarray]:
    """Exact box (lo, hi) (3,) [mm] of a circular arc or helix (a spiral: conservative, the
    larger radius). Along axis a the planar part is r·A·cos(θ − φ) with A = |(e1_a, e2_a)|,
    φ = atan2(e2_a, e1_a): its extremes over the swept angles θ ∈ [0, Δθ] are at the ends and
    at θ = φ + kπ inside; the helical rise t·H·n_a adds [min(0, H n_a), max(0, H n_a)]."""
    from nurbscnc.geometry.paths import arc_geometry

    g = arc_geometry(seg)
    r = max(g.radius_start_mm, g.radius_end_mm)
    th0, th1 = sorted((0.0, g.angle_rad))
    lo, hi = np.empty(3), np.empty(3)
    for a in range(3):
        amp = math.hypot(g.e1[a], g.e2[a])
        phi = math.atan2(g.e2[a], g.e1[a])
        ends = [r * amp * math.cos(th0 - phi), r * amp * math.cos(th1 - phi)]
        # cos(θ − φ) = ±1 at θ = φ + kπ; those inside [th0, th1] (at most two when the arc
        # turns less than 2π; a full turn or more reaches both).
        if th1 - th0 >= 2.0 * math.pi:
            ends += [r * amp, -r * amp]
        else:
            k = math.ceil((th0 - phi) / math.pi)
            while phi + k * math.pi <= th1:
                ends.append(r * amp * (1.0 if k % 2 == 0 else -1.0))
                k += 1
        rise = g.helix_mm * g.normal[a]
        lo[a] = g.origin_mm[a] + min(ends) + min(0.0, rise)
        hi[a] = g.origin_mm[a] + max(ends) + max(0.0, rise)
    return lo, hi


def _columns(segments, columns):
    """The segments' columns (:func:`~nurbscnc.program.columns.segment_columns`), read now
    unless the caller has them."""
    return columns if columns is not None else segment_columns(segments)


def segment_boxes_mm(segments, columns=None) -> tuple[np.ndarray, np.ndarray]:
    """Boxes (lo, hi) (n, 3) [mm] of the segments: lines (and rapids) their end points, arcs
    and helices exact (:func:`arc_box_mm`), NURBS their control points (convex hull; the
    weights are positive), stops their position. Lines, the bulk of CAM programs, in arrays
    (arcs, NURBS and stops are few); ``columns``: the segments' columns if already read."""
    cols = _columns(segments, columns)
    starts, stops = cols.starts_mm, cols.ends_mm
    lo, hi = np.minimum(starts, stops), np.maximum(starts, stops)
    for i in cols.rows(ARC).tolist():
        lo[i], hi[i] = arc_box_mm(segments[i])
    for i in cols.rows(NURBS).tolist():
        cp = np.asarray(segments[i].control_points_mm, dtype=float)
        lo[i], hi[i] = cp.min(axis=0), cp.max(axis=0)
    return lo, hi


def offsets_text(frames, index: int, axis: int) -> str:
    """What puts segment ``index``'s ``axis`` where it is: the coordinate system in force
    and its offset on that axis, with the G92, tool and rotation terms that are not zero
    (``frames``: :attr:`~nurbscnc.geometry.segments.Program.frames`; none: no offsets)."""
    rows = [f for f in frames if f[0] <= index]
    if not rows:
        return "G54, no offset"
    _, system, origin, g92, tool, rotation = rows[-1]
    name = AXES[axis]
    parts = [f"{system} offset {name} {origin[axis]:g}"]
    if g92[axis]:
        parts.append(f"G92 {name} {g92[axis]:g}")
    if tool[axis]:
        parts.append(f"tool offset {name} {tool[axis]:g}")
    if rotation and axis < 2:
        parts.append(f"rotation {rotation:g}°")
    return ", ".join(parts)


def check_geometry_limits(segments, soft_limits, columns=None, frames=()) -> None:
    """PlanningError at the source line of the first segment whose box
    (:func:`segment_boxes_mm`) leaves the soft limits, naming the axis, the value in machine
    coordinates and the offsets that put it there (``frames``: the program's
    :attr:`~nurbscnc.geometry.segments.Program.frames`)."""
    if not len(segments):
        return
    lo, hi = segment_boxes_mm(segments, columns)
    lim_lo, lim_hi = np.asarray(soft_limits.min_mm), np.asarray(soft_limits.max_mm)
    below, above = lo < lim_lo, hi > lim_hi
    bad = np.flatnonzero((below | above).any(axis=1))
    if not bad.size:
        return
    i = int(bad[0])
    a = int(np.flatnonzero(below[i] | above[i])[0])
    value = lo[i, a] if below[i, a] else hi[i, a]
    raise PlanningError(
        f"the {segments[i].kind} leaves the soft limits: {AXES[a]} reaches {value:.6g} mm "
        f"in machine coordinates ({offsets_text(frames, i, a)}), "
        f"outside [{lim_lo[a]:g}, {lim_hi[a]:g}] mm",
        SourcePos(int(segments[i].line), 1, ""),
    )


def segment_time_bounds_s(segments, machine, columns=None) -> np.ndarray:
    """A lower bound [s] (n,) of each segment's motion time: its length (NURBS: the chord
    between its end points) over the fastest it may move, min(F, V_max) (G0: the rapid rate);
    a stop its seconds; at least the time its rotary axes need at their own velocity limits
    (a rotary-only move's at its rate). A feed too small for its length gives inf."""
    lim = machine.limits
    cols = _columns(segments, columns)
    starts, stops = cols.starts_mm, cols.ends_mm
    length = np.sqrt(np.einsum("ij,ij->i", stops - starts, stops - starts))
    for i in cols.rows(ARC).tolist():
        length[i] = segments[i].length_mm
    speed = np.minimum(cols.feeds_mm_s, lim.v_max_mm_s)
    speed[cols.rows(RAPID)] = lim.rapid_mm_s
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        t = np.where(length > 0.0, length / speed, 0.0)
    t = np.where(np.isnan(t), np.inf, t)
    stops = np.flatnonzero((cols.kind == DWELL) | (cols.kind == PAUSE)).tolist()
    if stops:  # (the path model is imported only for programs that have stops)
        from nurbscnc.geometry.path import stop_seconds

        for i in stops:
            t[i] = stop_seconds(segments[i])
    if machine.rotary_axes:  # A B C at their own limits (a rotary-only move's whole time)
        from nurbscnc.plan.rotary import rotary_time_bounds_s

        t = np.maximum(t, rotary_time_bounds_s(segments, machine, cols))
    return t


def _point_count(total_s: float, period_s: float) -> float:
    """Reference points of a motion of ``total_s`` [s]: as many as the servo clock makes
    (nurbscnc.plan.timing.servo_clock: t_k = k T_s from 0 to the first at or after the end);
    inf for an endless one."""
    return math.ceil(total_s / period_s - 1e-9) + 1 if math.isfinite(total_s) else math.inf


def _refuse_points(times_s: np.ndarray, lines, period_s: float, max_points: int, what: str) -> None:
    """PlanningError at the line whose time is the largest when the total time ``times_s``
    [s] needs more than ``max_points`` reference points at ``period_s``."""
    total_s = float(np.sum(times_s))
    points = _point_count(total_s, period_s)
    if points <= max_points:
        return
    i = int(np.argmax(times_s))
    count = str(points) if points < 1e9 else f"{points:.3g}"
    raise PlanningError(
        f"the program's motion takes {what}{total_s:.6g} s: {count} reference points at "
        f"T_s = {period_s * 1000:g} ms, more than limits.max_points = {max_points}; this line "
        f"alone takes {float(times_s[i]):.6g} s",
        SourcePos(int(lines[i]), 1, ""),
    )


def check_motion_time(segments, machine, columns=None) -> None:
    """Refuse a program whose motion takes, at least (:func:`segment_time_bounds_s`), more
    than ``limits.max_points`` servo periods: PlanningError at the segment that takes the
    most time. Cheap: no planning, no sampling."""
    if not len(segments):
        return
    cols = _columns(segments, columns)
    times = segment_time_bounds_s(segments, machine, cols)
    endless = np.flatnonzero(~np.isfinite(times))
    if endless.size:
        # A feed so small (subnormal: 1e-321) that length / feed overflows.
        seg = segments[int(endless[0])]
        raise PlanningError(
            f"feed {seg.feed_mm_s * 60.0:.6g} mm/min is too small for this move: it would "
            "never end",
            SourcePos(int(seg.line), 1, ""),
        )
    _refuse_points(
        times, cols.lines, machine.servo.period_s, machine.limits.max_points, "at least "
    )


def check_before_work(segments, machine, columns=None, frames=()) -> None:
    """Both checks before planning: :func:`check_geometry_limits` (the soft limits; its
    error names the offsets of ``frames``) then :func:`check_motion_time`
    (``limits.max_points``), on the segments' columns (read once; ``columns`` if the caller
    has them)."""
    if not len(segments):
        return
    cols = _columns(segments, columns)
    check_geometry_limits(segments, machine.soft_limits, cols, frames)
    check_motion_time(segments, machine, cols)


def check_point_count(pieces, profile, machine) -> None:
    """Refuse a plan whose cycle time (profile plus dwells) needs more than
    ``limits.max_points`` reference points, before the servo clock is sampled: PlanningError
    at the source line of the segment with the most time (its pieces' span; a dwell counts
    with the piece before it). The total first (one sum): the per-segment times only when
    it is over (a cut window's re-plan calls this for the whole program every time)."""
    total_s = float(profile.duration_s) + float(np.sum(pieces.dwell_after_s))
    if _point_count(total_s, machine.servo.period_s) <= machine.limits.max_points:
        return
    ends = np.append(profile.piece_start_time_s[1:], profile.duration_s)
    span = ends - profile.piece_start_time_s + pieces.dwell_after_s
    seg = np.asarray(pieces.segment)
    times = np.bincount(seg, weights=span)
    lines = np.zeros(times.size, dtype=np.int64)
    lines[seg] = pieces.line
    _refuse_points(times, lines, machine.servo.period_s, machine.limits.max_points, "")
