"""What the commands report about a program and its plan, each number computed once here.

- :func:`program_summary`: the interpreted program (``check``): segment counts, lengths,
  bounding box, feeds, notes;
- :func:`plan_summary`: a plan and its reference points (``plan``, ``run``): pieces, cycle
  time, lower bound (SPEC §10), feed fluctuation (SPEC §3), predicted contour error (SPEC §8);
- :func:`check_soft_limits`: refuse reference points outside the travel envelope (a window
  of them at a time: the first offending point of the first window that has one is the
  program's first);
- :class:`SampleStats`: the summary's numbers of the reference points, window by window.

No I/O: the CLI prints or serialises the dictionaries. The path model (geometry/path.py,
paths.py, nurbs.py) and the lower bound are imported where they are needed: ``check`` of a
program of lines never loads them (start-up time).
"""

from __future__ import annotations

import math
from operator import attrgetter
from typing import TYPE_CHECKING

import numpy as np

from nurbscnc.errors import PlanningError, SourcePos
from nurbscnc.geometry.segments import spiral_arc_length_mm
from nurbscnc.machine.profile import Machine, SoftLimits
from nurbscnc.program.columns import (
    ARC,
    DWELL,
    KINDS,
    LINE,
    NURBS,
    PAUSE,
    RAPID,
    ROTATE,
    segment_columns,
)

if TYPE_CHECKING:  # the annotations only: no import at start-up
    from nurbscnc.plan.timing import Samples


def check_soft_limits(points_mm: np.ndarray, lines: np.ndarray, limits: SoftLimits) -> None:
    """Refuse reference points ``points_mm`` (N, 3) [mm] that leave the travel envelope:
    PlanningError at the first one, with its source line (``lines`` (N,))."""
    bad = np.flatnonzero(~limits.inside(points_mm))
    if not bad.size:
        return
    k = int(bad[0])
    lo, hi = np.asarray(limits.min_mm), np.asarray(limits.max_mm)
    axis = int(np.flatnonzero((points_mm[k] < lo) | (points_mm[k] > hi))[0])
    raise PlanningError(
        f"the path leaves the soft limits: {'XYZ'[axis]} = {points_mm[k, axis]:.4f} mm in "
        f"machine coordinates, outside [{lo[axis]:g}, {hi[axis]:g}] mm",
        SourcePos(int(lines[k]), 1, ""),
    )


def check_rotary_limits(abc_deg, lines: np.ndarray, rotary_axes: dict) -> None:
    """Refuse rotary positions ``abc_deg`` (N, 3) [deg] (None: a program without rotary axes)
    outside an axis's soft limits (``rotary_axes``: the machine's
    :class:`~nurbscnc.machine.model.RotaryAxis` by name): PlanningError at the first one, with
    its source line (``lines`` (N,))."""
    if abc_deg is None or not rotary_axes:
        return
    first, worst = None, None
    for i, name in enumerate(("a", "b", "c")):
        ax = rotary_axes.get(name)
        if ax is None:
            continue
        bad = np.flatnonzero((abc_deg[:, i] < ax.min_deg) | (abc_deg[:, i] > ax.max_deg))
        if bad.size and (first is None or bad[0] < first):
            first, worst = int(bad[0]), (i, ax)
    if first is None:
        return
    i, ax = worst
    raise PlanningError(
        f"the path leaves the soft limits: {'ABC'[i]} = {abc_deg[first, i]:.4f}° in machine "
        f"coordinates, outside [{ax.min_deg:g}, {ax.max_deg:g}]°",
        SourcePos(int(lines[first]), 1, ""),
    )


def segment_length_mm(seg) -> float:
    """Length of one segment [mm] (NURBS by Gauss–Legendre arc length)."""
    if seg.kind == "nurbs":
        from nurbscnc.geometry.nurbs import NurbsCurve

        return float(NurbsCurve.from_segment(seg).length_mm)
    return float(seg.length_mm)


#: Samples of every arc in the summary's bounding box (its extreme points lie between them
#: within the sagitta; the exact box is :func:`nurbscnc.plan.limits.arc_box_mm`).
ARC_BOX_SAMPLES = 65


def segment_lengths_mm(segments, cols) -> np.ndarray:
    """Lengths (n,) [mm] of the segments (``cols``: their columns), the same floats as
    :func:`segment_length_mm` of each: lines and rapids ``math.dist`` of their ends (a C
    loop over the end tuples: numpy's √(Δx² + Δy² + Δz²) may differ from it in the last
    bit), arcs and helices the closed form over all arcs at once (SPEC: the elementwise
    arithmetic of :func:`~nurbscnc.geometry.segments.spiral_arc_length_mm`), NURBS their
    Gauss–Legendre arc length (one curve at a time: few, each a whole block), stops 0."""
    n = len(segments)
    lengths = np.zeros(n)
    straight = np.flatnonzero((cols.kind == LINE) | (cols.kind == RAPID))
    if straight.size == n:
        pick = segments
    else:
        pick = [segments[i] for i in straight.tolist()]
    lengths[straight] = np.fromiter(
        map(math.dist, map(attrgetter("end_mm"), pick), map(attrgetter("start_mm"), pick)),
        dtype=float,
        count=straight.size,
    )
    arcs = cols.rows(ARC).tolist()
    if arcs:
        radii = np.array(
            [
                (
                    segments[i].radius_start_mm,
                    segments[i].radius_end_mm,
                    segments[i].angle_rad,
                    segments[i].helix_mm,
                )
                for i in arcs
            ]
        )
        lengths[arcs] = spiral_arc_length_mm(*radii.T)
    for i in cols.rows(NURBS).tolist():
        lengths[i] = segment_length_mm(segments[i])
    return lengths


def _box_points_mm(prog, cols) -> np.ndarray:
    """The points the summary's bounding box holds, in the order of the per-segment
    definition (a start point, then per segment: a NURBS's control points; a line's, rapid's
    or arc's start and end; an arc's :data:`ARC_BOX_SAMPLES` points): the same array, so
    its minimum is the same float even for −0.0 against 0.0."""
    segments = prog.segments
    moving = (cols.kind != DWELL) & (cols.kind != PAUSE)
    nurbs = cols.rows(NURBS).tolist()
    arcs = cols.rows(ARC)
    count = np.where(moving, 2, 0)
    count[arcs] += ARC_BOX_SAMPLES
    hulls = [
        np.reshape(np.asarray(segments[i].control_points_mm, dtype=float), (-1, 3)) for i in nurbs
    ]
    count[nurbs] = [len(h) for h in hulls]
    first = 1 + np.concatenate(([0], np.cumsum(count)[:-1]))
    points = np.empty((1 + int(count.sum()), 3))
    points[0] = np.asarray(prog.start_mm, dtype=float)
    ends = np.flatnonzero(moving & (cols.kind != NURBS))
    points[first[ends]] = cols.starts_mm[ends]
    points[first[ends] + 1] = cols.ends_mm[ends]
    for i, hull in zip(nurbs, hulls):
        points[first[i] : first[i] + len(hull)] = hull
    if arcs.size:
        from nurbscnc.geometry.paths import geometry_of
    for i in arcs.tolist():
        geom = geometry_of(segments[i])
        at = first[i] + 2
        points[at : at + ARC_BOX_SAMPLES] = geom.point(
            np.linspace(geom.u_start, geom.u_end, ARC_BOX_SAMPLES)
        )
    return points


def _sequential_sum(values: np.ndarray) -> float:
    """Σ values added left to right from 0.0 (``np.cumsum`` is sequential; ``np.sum`` is
    pairwise and may differ in the last bits from a running total)."""
    return float(np.cumsum(values)[-1]) if values.size else 0.0


def program_summary(prog, columns=None, per_segment: bool = True) -> dict:
    """The JSON-able summary of an interpreted program (``check --json``). The bounding box
    holds every end point, the NURBS control points (the convex hull property) and 65
    points of every arc (its extreme points). Whole-array over the segments' columns
    (``columns``: :func:`~nurbscnc.program.columns.segment_columns`, if already read);
    the numbers are those of adding up the segments one by one. ``per_segment`` False:
    ``segments`` lists only the NURBS blocks (what the text report shows), not one entry
    per segment (200,000 dictionaries for a CAM program)."""
    segments = prog.segments
    cols = columns if columns is not None else segment_columns(segments)
    lengths = segment_lengths_mm(segments, cols)
    rapid = cols.kind == RAPID
    feeding = (cols.kind != RAPID) & (cols.kind != DWELL) & (cols.kind != PAUSE)
    feeding &= cols.kind != ROTATE  # X Y Z at rest (its rate is in deg/s)
    feeds = cols.feeds_mm_s[feeding]
    names = cols.names
    shown = np.arange(len(segments)) if per_segment else cols.rows(NURBS)
    entries = [
        {"kind": k, "line": line, "length_mm": length}
        for k, line, length in zip(
            names[shown].tolist(), cols.lines[shown].tolist(), lengths[shown].tolist()
        )
    ]
    for i, k in zip(
        np.flatnonzero(cols.kind[shown] == NURBS).tolist(),
        shown[cols.kind[shown] == NURBS].tolist(),
    ):
        seg = segments[k]
        entries[i].update(
            degree=seg.degree,
            control_points=len(seg.control_points_mm),
            knots=len(seg.knots),
            plane=seg.plane,
        )
    # Kinds counted in the order they first appear (the order of the JSON object).
    codes, first, counts = np.unique(cols.kind, return_index=True, return_counts=True)
    order = np.argsort(first)
    allpts = _box_points_mm(prog, cols)
    return {
        "ok": True,
        "program": prog.name,
        "blocks": prog.blocks,
        "segments": entries,
        "counts": {KINDS[int(codes[k])]: int(counts[k]) for k in order},
        "length_mm": _sequential_sum(lengths[feeding]),
        "rapid_length_mm": _sequential_sum(lengths[rapid]),
        "bounding_box_mm": {"min": allpts.min(axis=0).tolist(), "max": allpts.max(axis=0).tolist()},
        "feed_range_mm_s": {
            "min": float(feeds.min()) if feeds.size else None,
            "max": float(feeds.max()) if feeds.size else None,
        },
        "notes": [{"line": n.line, "message": n.message} for n in prog.notes],
        "errors": [],
    }


def nurbs_step_lengths(pieces, samples: Samples) -> tuple[np.ndarray, np.ndarray]:
    """True arc lengths of the servo steps on NURBS pieces, for the feed fluctuation.

    Returns ``(k, ds_mm)``: the indices k of the steps k → k+1 with both samples on the same
    NURBS curve, and Δs_true = s(u_{k+1}) − s(u_k) [mm], each step's integral on its own
    from the curve's exact arc-length table (:meth:`NurbsCurve.step_lengths
    <nurbscnc.geometry.nurbs.NurbsCurve.step_lengths>`; SPEC §3: fluctuation
    |Δs/(V T_s) − 1| "measured with true arc length").
    ``samples``: reference points with ``piece`` and ``param`` (N,)."""
    from nurbscnc.geometry.path import Kind

    path = pieces.path
    kind = np.take(path.kind, samples.piece)
    cid = np.where(kind == Kind.NURBS, np.take(path.obj_id, samples.piece), -1)
    ds = np.full(max(cid.size - 1, 0), np.nan)  # step k → k+1
    if cid.size:
        cuts = np.flatnonzero(cid[1:] != cid[:-1]) + 1
        edges = np.concatenate(([0], cuts, [cid.size])).tolist()
        for a, z in zip(edges[:-1], edges[1:]):
            if cid[a] >= 0 and z - a > 1:
                ds[a : z - 1] = path.objects[int(cid[a])].step_lengths(samples.param[a:z])
    k = np.flatnonzero((cid[:-1] >= 0) & (cid[:-1] == cid[1:]))
    return k, ds[k]


def feed_fluctuation(plan, samples) -> float | None:
    """Largest |Δs_true/Δs_planned − 1| over servo steps on NURBS pieces moving at ≥ 10 % of
    the highest cap (SPEC §3; true arc length from the curves' exact tables), or None if
    there are none."""
    return SampleStats.of(samples, plan).feed_fluctuation_max


class SampleStats:
    """What the summaries need of a plan's reference points, gathered window by window
    (:meth:`add` each window in order: no whole arrays): the number of samples,
    the highest planned feed [mm/s] and — given the ``plan`` — the feed fluctuation on
    NURBS (:func:`feed_fluctuation`, SPEC §3), whose steps include the one across each join
    of two windows. Equal to the whole-array numbers bit for bit (each step's ratio is the
    same float expression; a maximum does not depend on the grouping)."""

    def __init__(self, plan=None):
        self.pieces = None if plan is None else plan.pieces
        self.fast_mm_s = None if plan is None else 0.1 * float(np.max(plan.caps_mm_s))
        self.count = 0
        self.feed_max_mm_s = -np.inf
        self.feed_fluctuation_max: float | None = None
        self.interpolator = "exact"
        # The last sample of the previous window: its curve (-1: not on a NURBS), parameter
        # on it, planned path length [mm], planned feed [mm/s].
        self._last = (-1, 0.0, 0.0, 0.0)

    @classmethod
    def of(cls, samples: Samples, plan=None) -> SampleStats:
        """The stats of whole samples (one window)."""
        stats = cls(plan)
        stats.add(samples)
        return stats

    def tap(self, windows):
        """Yield ``windows`` unchanged, adding each as it passes (a writer's input): after
        it is yielded, so the writer (another thread, deflating without the interpreter lock)
        has it while its stats are worked out (a 60 mm airfoil's 3,500 samples: 0.7 ms of
        NURBS step lengths). The stats are complete once the windows are exhausted."""
        for w in windows:
            yield w
            self.add(w)

    def add(self, samples: Samples) -> None:
        """Take the next window of samples (``t_s``, ``v_mm_s``, ``s_mm``, ``piece``,
        ``param``, ``interpolator``)."""
        n = int(samples.t_s.size)
        if n == 0:
            return
        self.count += n
        self.feed_max_mm_s = max(self.feed_max_mm_s, float(samples.v_mm_s.max()))
        self.interpolator = str(samples.interpolator)
        if self.pieces is None:
            return
        curve, u_last, s_mm, v = self._last
        k, ds_true = nurbs_step_lengths(self.pieces, samples)
        planned = samples.s_mm[k + 1] - samples.s_mm[k]
        v_k = samples.v_mm_s[k]
        cid = self._first_and_last(samples)
        if curve >= 0 and cid == curve:  # the step across the join, k = −1 → 0
            join = self.pieces.path.objects[cid].step_lengths([u_last, samples.param[0]])
            ds_true = np.r_[join, ds_true]
            planned = np.r_[samples.s_mm[0] - s_mm, planned]
            v_k = np.r_[v, v_k]
        fast = v_k >= self.fast_mm_s
        if fast.any():
            worst = float(np.max(np.abs(ds_true[fast] / planned[fast] - 1.0)))
            if self.feed_fluctuation_max is None or worst > self.feed_fluctuation_max:
                self.feed_fluctuation_max = worst

    def _first_and_last(self, samples: Samples) -> int:
        """The curve of the window's first sample (−1: none; for the step across the join);
        the window's last sample becomes the carried one."""
        from nurbscnc.geometry.path import Kind

        path = self.pieces.path
        ends = samples.piece[[0, -1]]
        kind = np.take(path.kind, ends)
        cid = np.where(kind == Kind.NURBS, np.take(path.obj_id, ends), -1).tolist()
        self._last = (
            cid[1],
            float(samples.param[-1]),
            float(samples.s_mm[-1]),
            float(samples.v_mm_s[-1]),
        )
        return cid[0]


def _bound(summary: dict, lower_bound_s: float | None, cycle_time_s: float) -> None:
    if lower_bound_s is not None:
        summary["lower_bound_s"] = lower_bound_s
        summary["lower_bound_ratio"] = cycle_time_s / lower_bound_s if lower_bound_s > 0 else None


def plan_summary(
    prog,
    machine: Machine,
    samples,
    plan=None,
    check=None,
    algorithm: str = "ph-lookahead",
    cycle_time_s: float | None = None,
    lower_bound: bool = True,
    columns=None,
) -> dict:
    """Numbers that describe a plan (``plan --json``): of the look-ahead ``plan`` with its
    dynamics ``check`` (None: off), or — ``plan`` None — of a baseline ``algorithm``'s
    ``samples``, simulated on the servo model to see its errors. With a plan, ``samples``
    may be whole :class:`~nurbscnc.plan.timing.Samples` or the :class:`SampleStats`
    gathered while the windows were written (the contour error is the check's
    :meth:`Check.contour_stats`).
    ``lower_bound``: False leaves out ``lower_bound_s`` and its ratio (a summary nobody
    reads them from: the kinematic bound costs 0.2 s on a 200,000-line program);
    ``columns``: the program's segment columns if already read."""
    from nurbscnc.plan.lowerbound import program_lower_bound_s
    from nurbscnc.plan.plans import segment_times_s

    curves = plan.pieces.nurbs_curves() if plan is not None else None
    lb = program_lower_bound_s(prog.segments, machine, columns, curves) if lower_bound else None
    if cycle_time_s is None:
        cycle_time_s = plan.cycle_time_s if plan is not None else float(samples.t_s[-1])
    head = {"ok": True, "program": prog.name}
    if plan is None:
        from nurbscnc.servo.simulate import contour_errors, metrics, simulate_reference

        sim = simulate_reference(samples.points_mm, machine)
        m = metrics(sim, None, contour_errors(sim, None)).as_dict()
        summary = {
            **head,
            "algorithm": str(algorithm),
            "cycle_time_s": cycle_time_s,
            "samples": int(samples.t_s.size),
            "period_s": machine.servo.period_s,
            "feed_max_mm_s": float(samples.v_mm_s.max()),
        }
        _bound(summary, lb, cycle_time_s)
        summary.update(
            contour_true_max_um=m["true_max_um"],
            contour_true_rms_um=m["true_rms_um"],
            contour_eq29_max_um=m["contour_max_um"],
            contour_scope="all",  # a baseline's samples do not tell rapids from cuts
        )
        return summary
    stats = samples if isinstance(samples, SampleStats) else SampleStats.of(samples, plan)
    kinds = plan.pieces.kind_counts()  # vectorised: no Piece object per row
    summary = {
        **head,
        "pieces": kinds,
        "piece_count": len(plan.pieces),
        "corner_pieces": kinds.get("ph", 0),
        "cycle_time_s": cycle_time_s,
        "samples": stats.count,
        "period_s": machine.servo.period_s,
        "dynamics": str(plan.dynamics),
        "dynamics_iterations": plan.iterations,
        "feed_max_mm_s": stats.feed_max_mm_s,
        "segment_times_s": segment_times_s(plan, key=str),
        "interpolator": stats.interpolator,
    }
    if stats.feed_fluctuation_max is not None:
        summary["feed_fluctuation_max"] = stats.feed_fluctuation_max
    _bound(summary, lb, cycle_time_s)
    if plan.pieces.smoothed is not None:
        summary["smoothed"] = dict(plan.pieces.smoothed)
    if check is not None:
        summary.update(check.contour_stats(), contour_scope="feed")
    if plan.pieces.rotary is not None:
        summary["rotary"] = rotary_summary(plan.pieces.rotary)
    return summary


def rotary_summary(rotary) -> dict:
    """The planner's entries of a plan's ``rotary`` object (docs/json.md; the app adds where
    the axes end and what the contour check covers): the axes the program uses and its
    rotary-only moves (count, planned time [s])."""
    return {
        "axes": list(rotary.axes),
        "rotate_moves": int(rotary.holds.duration_s.size),
        "rotate_time_s": float(np.sum(rotary.holds.duration_s)),
    }


#: The JSON names (docs/json.md) of the servo metrics
#: (:class:`~nurbscnc.servo.simulate.Metrics` fields): the contour error is
#: ``contour_true_*`` (the distance from the actual point to the path) or ``contour_eq29_*``
#: (|ε| of SPEC eq. 29) in every command, over the samples ``contour_scope`` names ("feed":
#: the feed samples of :mod:`nurbscnc.plan.scope`; "all"), the rapids' own apart as
#: ``contour_rapids_*``.
METRIC_KEYS = {
    "axis_x_max_um": "axis_x_max_um",
    "axis_x_rms_um": "axis_x_rms_um",
    "axis_y_max_um": "axis_y_max_um",
    "axis_y_rms_um": "axis_y_rms_um",
    "contour_max_um": "contour_eq29_max_um",
    "contour_rms_um": "contour_eq29_rms_um",
    "contour_mean_um": "contour_eq29_mean_um",
    "true_max_um": "contour_true_max_um",
    "true_rms_um": "contour_true_rms_um",
    "true_mean_um": "contour_true_mean_um",
    "rapids_true_max_um": "contour_rapids_true_max_um",
    "rapids_eq29_max_um": "contour_rapids_eq29_max_um",
    "contour_scope": "contour_scope",
    "cycle_time_s": "cycle_time_s",
    "settle_time_s": "settle_time_s",
}


def metrics_json(metrics: dict) -> dict:
    """Servo metrics (``Metrics.as_dict()``) under their JSON names (:data:`METRIC_KEYS`)."""
    return {METRIC_KEYS[k]: v for k, v in metrics.items()}


def corner_fits(prog, machine: Machine, split: bool = True) -> list[tuple]:
    """PH quintic fits of every corner region of the program's NURBS blocks (SPEC §5–§6,
    Table 1): (block corners, region, unsplit fit, fit) per region, the fit split to the
    profile's tolerance e unless ``split`` is False (then it is the unsplit one)."""
    from nurbscnc.geometry.nurbs import NurbsCurve
    from nurbscnc.plan.corners import program_corners
    from nurbscnc.plan.phfit import fit_region

    e_um = machine.limits.ph_tolerance_mm * 1000.0
    lim = machine.limits
    rows = []
    for sc in program_corners(prog.segments, lim.a_max_mm_s2, lim.v_max_mm_s):
        curve = NurbsCurve.from_segment(prog.segments[sc.segment_index])
        for r in sc.regions:
            unsplit = fit_region(curve, r.u_a, r.u_b, tolerance_um=e_um, split=False)
            fit = fit_region(curve, r.u_a, r.u_b, tolerance_um=e_um) if split else unsplit
            rows.append((sc, r, unsplit, fit))
    return rows


def corner_polylines(pieces, points_per_piece: int = 50) -> list[np.ndarray]:
    """The PH pieces of a plan as polylines (one (n, 3) array [mm] each, evenly spaced in arc
    length), for the path figures; all pieces in one call to the path model."""
    from nurbscnc.geometry.path import Kind

    rows = np.flatnonzero(pieces.kind == Kind.PH)
    if rows.size == 0:
        return []
    n = points_per_piece
    idx = np.repeat(rows, n)
    s = (pieces.length_mm[rows][:, None] * np.linspace(0.0, 1.0, n)[None, :]).ravel()
    pts = pieces.path.points(idx, s)[0]
    return list(pts.reshape(rows.size, n, 3))
