"""Pre-compensation of a plan's reference (``--precompensate``, issue 13) and its report.

The ZPETC inverse itself (:mod:`nurbscnc.servo.precompensate`) works on points; here it is
applied to a plan's :class:`~nurbscnc.plan.timing.Reference` (kept near the path, padded so
the dynamics check maps every sample to its piece), wrapped as the reference sampler the
planner's check simulates, and reported on: the compensated reference's own deviation from
the path and the contour error under ±10 % model errors. The compensated reference keeps
the machine's velocity, acceleration and jerk on its samples (:func:`project_onto_limits`,
then the tube optimisation within the same caps).
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from dataclasses import dataclass, fields, replace

import numpy as np

from nurbscnc.geometry.nurbs import NurbsCurve
from nurbscnc.geometry.path import Kind
from nurbscnc.machine.profile import AxisServo, Machine
from nurbscnc.plan.dynamics import CHORD_MM, PathIndex, path_response, windowed_contour_mm
from nurbscnc.plan.lookahead import Plan
from nurbscnc.plan.timing import Reference
from nurbscnc.servo.model import AxisModel, _as_model, contour_error_true, discretise
from nurbscnc.servo.precompensate import (
    REFERENCE_TOLERANCE_MM,
    Compensated,
    along_path_offset_mm,
    limit_to_path,
    perturbed_model,
    precompensate_points,
    zpetc,
)

#: The ±10 % model errors of the sensitivity report: (label, loop gain per axis x, y, z,
#: bandwidth per axis) — :func:`~nurbscnc.servo.precompensate.perturbed_model`: the loop gain
#: moves the closed-loop poles (zeros kept), the bandwidth scales poles and zeros; each both
#: ways on every axis, and with x and y off in opposite directions (what distorts a contour).
SENSITIVITY_CASES = (
    ("loop gain -10 %", (0.9, 0.9, 0.9), (1.0, 1.0, 1.0)),
    ("loop gain +10 %", (1.1, 1.1, 1.1), (1.0, 1.0, 1.0)),
    ("loop gain x -10 %, y, z +10 %", (0.9, 1.1, 1.1), (1.0, 1.0, 1.0)),
    ("loop gain x +10 %, y, z -10 %", (1.1, 0.9, 0.9), (1.0, 1.0, 1.0)),
    ("bandwidth -10 %", (1.0, 1.0, 1.0), (0.9, 0.9, 0.9)),
    ("bandwidth +10 %", (1.0, 1.0, 1.0), (1.1, 1.1, 1.1)),
    ("bandwidth x -10 %, y, z +10 %", (1.0, 1.0, 1.0), (0.9, 1.1, 1.1)),
    ("bandwidth x +10 %, y, z -10 %", (1.0, 1.0, 1.0), (1.1, 0.9, 0.9)),
)


@dataclass(frozen=True)
class Precompensation:
    """What pre-compensation did to a plan's reference (``run --precompensate``).

    ``lead_s`` how much later than planned the tool moves: the inverse's look-ahead, taken
    as a delay so nothing moves before t = 0 [s] (counted in the cycle time);
    ``tail_s`` periods added after the planned stop [s] (none: the inverse's tail is
    blended in, ``end_step_mm`` [mm] over the last ``end_blend_s`` [s]);
    ``reference_deviation_max_mm`` the compensated points' largest distance from the path
    [mm] (cutting samples), kept within ``reference_tolerance_mm``; ``sensitivity`` (label,
    worst contour error [mm]) of the same reference simulated through each model error of
    :data:`SENSITIVITY_CASES`."""

    lead_s: float
    tail_s: float
    reference_deviation_max_mm: float
    sensitivity: tuple[tuple[str, float], ...]
    reference_tolerance_mm: float = float("inf")
    end_step_mm: float = 0.0
    end_blend_s: float = 0.0

    @property
    def sensitivity_max_mm(self) -> float:
        """The worst contour error [mm] over the model errors."""
        return max((e for _, e in self.sensitivity), default=0.0)

    def as_json(self) -> dict:
        """The ``precompensation`` object of ``plan``/``run --json`` (µm, s; a tolerance of
        None is no limit)."""
        tol = self.reference_tolerance_mm
        return {"method": "zpetc", "lead_s": self.lead_s, "tail_s": self.tail_s,
                "reference_tolerance_um": tol * 1000.0 if np.isfinite(tol) else None,
                "reference_deviation_max_um": self.reference_deviation_max_mm * 1000.0,
                "end_step_um": self.end_step_mm * 1000.0, "end_blend_s": self.end_blend_s,
                "sensitivity_contour_max_um": self.sensitivity_max_mm * 1000.0,
                "sensitivity": [{"model_error": k, "contour_max_um": e * 1000.0}
                                for k, e in self.sensitivity]}  # fmt: skip


@dataclass(frozen=True, eq=False)
class Refined(Compensated):
    """A :class:`~nurbscnc.servo.precompensate.Compensated` reference whose offsets across
    the path were then optimised in the tube (:func:`refine_in_tube`): ``history_mm`` the
    largest predicted contour error [mm] before and after each round, ``clipped_mm`` the
    ZPETC reference clipped into the tube, ``projected_mm`` that projected onto the limits
    on the samples (:func:`project_onto_limits`): where the optimisation started."""

    history_mm: tuple[float, ...] = ()
    clipped_mm: np.ndarray | None = None
    projected_mm: np.ndarray | None = None


def _models(machine: Machine) -> list:
    servo = machine.servo
    return [servo.x, servo.y, servo.z]


#: Spacing of the programmed curve's points where the reference tolerance is measured
#: against it (:func:`_fit_margin_mm`) [mm]; the sagitta of the chords is added.
_CURVE_SPACING_MM = 1e-3


def _fit_margin_mm(pieces, piece: np.ndarray, foot_mm: np.ndarray,
                   fit_tolerance_mm: float) -> np.ndarray:  # fmt: skip
    """How far each foot (M, 3) [mm] may be from the programmed path (M,) [mm]: 0 on every
    piece of the programmed path itself; on a PH corner piece of a NURBS (SPEC §6: a fit
    within e of the curve, not on it) its distance to the NURBS span the fit replaces
    (a dense polyline of the curve, exact point-to-segment distance, plus the chords'
    sagitta κ_max c²/8), or ``fit_tolerance_mm`` e where that span is not known.
    Line-line blends (``pieces.ph_rows``) leave the programmed corner by design: there the
    planned path is the path."""
    fit = pieces.kind == Kind.PH
    fit[pieces.ph_rows] = False
    margin = np.zeros(piece.size)
    rows = np.flatnonzero(fit)
    if not rows.size:
        return margin
    # Runs of consecutive fit rows of one segment: one corner region each.
    breaks = np.flatnonzero((np.diff(rows) != 1)
                            | (pieces.segment[rows[1:]] != pieces.segment[rows[:-1]]))
    for group in np.split(rows, breaks + 1):
        sel = np.flatnonzero((piece >= group[0]) & (piece <= group[-1]))
        if not sel.size:
            continue
        lo, hi = pieces.objects.get(group[0] - 1), pieces.objects.get(group[-1] + 1)
        seg = pieces.segment[group[0]]
        lo = lo if group[0] > 0 and pieces.segment[group[0] - 1] == seg else None
        hi = hi if group[-1] + 1 < len(pieces) and pieces.segment[group[-1] + 1] == seg else None
        curve = next((o[0] for o in (lo, hi) if o is not None and isinstance(o[0], NurbsCurve)),
                     None)  # fmt: skip
        if curve is None:
            margin[sel] = fit_tolerance_mm
            continue
        u_lo = lo[2] if lo is not None and lo[0] is curve else curve.u_start
        u_hi = hi[1] if hi is not None and hi[0] is curve else curve.u_end
        length = float(pieces.length_mm[group].sum())
        m = int(np.clip(np.ceil(length / _CURVE_SPACING_MM), 64, 100_000)) + 1
        dense = curve.point(np.linspace(u_lo, u_hi, m))
        chord = float(np.linalg.norm(np.diff(dense, axis=0), axis=1).max())
        kappa = float(pieces.kappa_max_per_mm[group].max())
        sagitta = kappa * chord * chord / 8.0 if np.isfinite(kappa) else chord
        margin[sel] = contour_error_true(foot_mm[sel], dense) + sagitta
    return margin


def _tube_mm(pieces, piece: np.ndarray, foot_mm: np.ndarray, tolerance_mm: float,
             fit_tolerance_mm: float) -> np.ndarray:  # fmt: skip
    """The reference tolerance about each foot [mm] (M,): ``tolerance_mm`` less the foot's
    own distance from the programmed path (:func:`_fit_margin_mm`), so that the reference
    is within ``tolerance_mm`` of the *programmed* path (the triangle inequality)."""
    margin = _fit_margin_mm(pieces, piece, foot_mm, fit_tolerance_mm)
    return np.maximum(tolerance_mm - margin, 0.0)


def _compensate_segment(ref: Reference, pieces, profile, machine: Machine,
                        tolerance_mm: float, fit_tolerance_mm: float | None, refine: bool,
                        first: bool, last: bool = True,
                        ) -> tuple[Reference, Compensated]:  # fmt: skip
    """One segment of :func:`precompensate_reference` (a cut window's samples, or the whole
    reference), compensated as a program of its own (``first``: the program's first, delayed
    by the pre-actuation; else its first sample the planned one, no delay; not ``last``: a
    segment followed by another, its last JOIN_HELD samples the planned ones, so the joint
    always has a solution, :func:`_join_segments`): the ZPETC
    pre-compensated version of a plan's reference (SPEC eq. 25 inverted,
    :func:`~nurbscnc.servo.precompensate.precompensate_points`; F's tail blended in within
    the machine's acceleration and jerk, so it ends with the plan), kept within
    ``tolerance_mm`` of the path (inf: no limit): each compensated point u_k is projected
    onto the ball of that radius (less the foot's own distance from the programmed curve on
    PH corner pieces of a NURBS, :func:`_tube_mm`; the fit tolerance ``fit_tolerance_mm``,
    default the profile's e, where that is not known) about the path point
    its lead d_t (:func:`~nurbscnc.servo.precompensate.along_path_offset_mm`) ahead of the
    planned point, placed exactly at path length s_k + d_t (clamped to the program's ends,
    so the reference is never led past the end point along the path;
    :func:`~nurbscnc.servo.precompensate.limit_to_path`), then projected onto the machine's
    limits on the samples (:func:`project_onto_limits`: V, A, J per axis and the path speed
    by finite differences, or the plan's own where that is above them, in the tube about
    the plan's points; with no tolerance, anywhere) and, with a contour check, optimised in
    the tube within the same caps (:func:`refine_in_tube`). Every other per-sample column is
    padded to the new length (the start repeated ``lead_samples`` times), so the dynamics
    check maps each sample to its piece and path length as before. Wall times restart at
    0 with the servo period."""
    period = machine.servo.period_s
    lim = machine.limits
    comp = precompensate_points(_models(machine), ref.points_mm, period,
                                a_max_mm_s2=lim.a_max_mm_s2, j_max_mm_s3=lim.j_max_mm_s3)
    if not first:
        # A later segment starts at rest at the end of the cut before it, with a rapid: its
        # samples keep their wall times (no delay), so the pre-actuation of the rapid's start
        # (the held samples) is dropped and its first sample is the planned one.
        u = comp.points_mm[comp.lead_samples :].copy()
        u[0] = ref.points_mm[0]
        comp = replace(comp, points_mm=u, lead_samples=0)
    pad = (comp.lead_samples, 0)

    def edge(x):
        return np.pad(x, pad, mode="edge") if x.ndim == 1 else np.pad(x, (pad, (0, 0)), "edge")

    points = comp.points_mm
    s_mm = edge(ref.s_mm)
    if np.isfinite(tolerance_mm):
        s_foot = _s_along(points, edge(ref.points_mm), s_mm, profile)
        starts = profile.piece_start_mm
        piece = np.clip(np.searchsorted(starts, s_foot, side="right") - 1, 0, starts.size - 1)
        foot = pieces.path.place(starts, np.minimum(s_foot, starts[piece]
                                                    + pieces.length_mm[piece]), piece)[0]
        fit = lim.ph_tolerance_mm if fit_tolerance_mm is None else fit_tolerance_mm
        tube = _tube_mm(pieces, piece, foot, tolerance_mm, fit)
        optimise = refine and machine.contour_check
        if optimise:
            # The optimisation measures the tube on polylines of the path (chords ≤ 10 nm
            # inside the curve, dynamics.CHORD_MM): its tube is the smallest of each
            # sample's neighbours' (the foot moves along the path) less twice that, and
            # the clip a chord error more, so the clipped points start inside it.
            near = np.lib.stride_tricks.sliding_window_view(np.pad(tube, 4, mode="edge"), 9)
            tube_in = np.maximum(near.min(axis=1) - 2.0 * CHORD_MM, 0.0)
            tube = np.maximum(tube_in - CHORD_MM, 0.0)
        points = limit_to_path(points, foot, tube)
    held = 1 if last else JOIN_HELD
    if not last:
        # A segment followed by another ends on the plan's own last samples: the joint's
        # rows (the next segment's first samples after these) are then solved by the plan's
        # own next samples at worst (:func:`_join_segments`).
        points = points.copy()
        points[-held:] = ref.points_mm[-held:]
    clipped = points
    # The limits on the samples (module comment "limits on samples"): the clipped ZPETC
    # reference projected onto them, in the tube about the plan's points (or, with no
    # tube, anywhere: a frame of the axes).
    planned = edge(ref.points_mm)
    caps = sample_limits(planned, machine)
    if np.isfinite(tolerance_mm):
        basis, lower, upper = path_frame(planned, s_mm, edge(ref.piece), pieces, profile,
                                         clipped - planned, tube)  # fmt: skip
    else:
        basis = np.broadcast_to(np.eye(3), (points.shape[0], 3, 3))
        lower = np.full((points.shape[0], 3), -np.inf)
        upper = -lower
    points = project_onto_limits(clipped, planned, caps, basis, lower, upper, held=held)
    comp = replace(comp, points_mm=points)
    n_in, n = ref.points_mm.shape[0], points.shape[0]
    # Every per-sample column padded alike (whatever columns the Reference has).
    columns = {f.name: edge(getattr(ref, f.name)) for f in fields(ref)
               if isinstance(getattr(ref, f.name), np.ndarray)
               and getattr(ref, f.name).shape[:1] == (n_in,)}  # fmt: skip
    columns.update(t_s=np.arange(n) * period, points_mm=points)
    if np.isfinite(tolerance_mm):
        # Each sample's path length where its point is (the planned one's plus the lead
        # along the path), so a distance measured near it (windowed_contour_mm) looks at the
        # stretch of path the point is at.
        columns["s_mm"] = s_foot
    out = replace(ref, **columns)
    if np.isfinite(tolerance_mm) and optimise:
        done = refine_in_tube(out, pieces, profile, machine, tube_in, caps=caps, held=held)
        out = replace(out, points_mm=done.points_mm)
        out = replace(out, s_mm=_s_along(done.points_mm, edge(ref.points_mm), s_mm, profile))
        comp = Refined(done.points_mm, comp.lead_samples, comp.end_step_mm,
                       comp.end_blend_samples, done.history_mm, clipped, points)  # fmt: skip
    return out, comp


def _s_along(points_mm: np.ndarray, planned_mm: np.ndarray, s_planned_mm: np.ndarray,
             profile) -> np.ndarray:  # fmt: skip
    """The path length [mm] at which each point of ``points_mm`` is: its planned point's
    plus its lead along the path (:func:`~nurbscnc.servo.precompensate.along_path_offset_mm`),
    within the program."""
    lead = along_path_offset_mm(points_mm, planned_mm)
    return np.clip(s_planned_mm + lead, 0.0, profile.total_length_mm)


# --------------------------------------------------------------------------- cut-window segments
#
# Long programs (issue 13, tort.ngc: 554 s, 74 cut windows, 82 re-plans). The planner checks a
# program cut window by cut window (lookahead.plan_windows), every re-plan of window w with
# the windows before it final and the ones after it placeholders. A whole-reference sampler
# made each of those checks compensate, project and optimise the whole program: O(re-plans ×
# program), more than 3 minutes of CPU on tort without finishing (45 minutes under LinuxCNC's
# limits). Here the compensated reference is made of *segments*, one per cut window's samples
# (from the first sample at the window's first piece to the next window's), each compensated
# as a program of its own (:func:`_compensate_segment`): the ZPETC inverse from rest at its
# first point, F's tail blended in at its end (a cut → rapid junction is a rest, as the end
# of a program is), the clip, the projection onto the limits and the tube optimisation on its
# samples alone. A segment's samples then depend only on its own planned samples, so
#
# - the sampler gives any window of samples exactly (the planner checks the rows it needs,
#   not the program: ``windowed``) and a re-plan of window w costs window w;
# - segments are kept by their planned samples (:data:`_SEGMENTS`, bounded), so the final
#   windows' segments are made once for every later check and for the output
#   (``precompensate_reference`` of the final plan finds them).
#
# What a segment does not see: the tail of the inverse of the cut before it (the IIR part
# decays at |pole| per sample: 0.91 on the paper's axes, 1e-12 after 300 samples, and the
# rapid in between is at least one), and the pre-actuation of its own first samples (the
# look-ahead of F, n_u + d samples: ~nanometres at a rapid's start from rest, where the
# contour is not checked). The planner's check simulates the joined reference with the
# servo's state carried across windows (what the machine does), so neither is assumed away;
# the rows that span two segments (the step between them and the second and third differences
# across it) are checked against the limits and, where they break them, re-projected by
# moving the later segment's first samples (:func:`_join_segments`), which only depend on
# the earlier segment's last three samples. A segment followed by another ends on its plan's
# own last three samples (JOIN_HELD), so those are known without making it (a check of the
# next window reads them from the plan), the joint's caps are the plan's own across it, and
# the plan's own samples of the later segment always solve it (the fallback).

#: Most samples of compensated segments kept across checks (:data:`_SEGMENTS`): 1.5e6
#: samples of 10 columns, 120 MB; the planner needs two at a time (the window checked and the
#: one before it), the output all of the final plan's (made again where evicted).
SEGMENT_CACHE_SAMPLES = 1_500_000
#: Fewest samples of a segment (a shorter cut window's samples join the segment before).
MIN_SEGMENT = 16
#: Samples after a segment's start that the joint's re-projection may move (first try; the
#: whole segment but its last three at worst).
JOIN_PAD = 40
#: Last samples of a segment followed by another that are the plan's own (the third
#: differences across the joint reach three samples back).
JOIN_HELD = 3

_SEGMENTS: OrderedDict = OrderedDict()
#: Joined segments kept (:func:`_join_segments` of a segment after a given tail: the check
#: asks a window's rows in several pieces).
JOINED_KEPT = 16
_JOINED: OrderedDict = OrderedDict()


def _segment_starts(pieces, profile, period_s: float, n: int) -> np.ndarray:
    """Sample indices (S + 1,) where the segments of a reference of ``n`` samples start
    (the first sample at each cut window's first piece, :func:`~nurbscnc.plan.lookahead.
    cut_windows`), and ``n``: strictly increasing, the first 0."""
    from nurbscnc.plan.windows import cut_windows, first_sample_at

    starts = [first_sample_at(pieces, profile, int(a), period_s)
              for a in cut_windows(pieces)[1:].tolist()]  # fmt: skip
    ks = [0]
    for k in starts:  # a segment shorter than MIN_SEGMENT joins the one before it
        if k - ks[-1] >= MIN_SEGMENT and n - k >= MIN_SEGMENT:
            ks.append(int(k))
    return np.asarray([*ks, n], dtype=np.int64)


def _key(ref: Reference, machine: Machine, pieces, options: tuple, first: bool,
         last: bool) -> tuple:  # fmt: skip
    """The cache key of a segment: what its compensation depends on (its planned samples'
    columns, bit for bit; the machine, path and options by identity, the entry holding
    them so an identity is never reused while it is kept)."""
    h = hashlib.blake2b(digest_size=20)
    for f in fields(ref):
        x = np.ascontiguousarray(getattr(ref, f.name))
        h.update(str(x.dtype).encode() + str(x.shape).encode())
        h.update(x.tobytes())
    return (id(machine), id(pieces.path), options, first, last, h.hexdigest())


def _segment(ref: Reference, pieces, profile, machine: Machine, options: tuple,
             first: bool, last: bool) -> tuple[Reference, Compensated]:  # fmt: skip
    """:func:`_compensate_segment` of the planned samples ``ref``, from :data:`_SEGMENTS` when
    made before (least recently used evicted beyond SEGMENT_CACHE_SAMPLES)."""
    key = _key(ref, machine, pieces, options, first, last)
    hit = _SEGMENTS.get(key)
    if hit is not None:
        _SEGMENTS.move_to_end(key)
        return hit[0], hit[1]
    out, comp = _compensate_segment(ref, pieces, profile, machine, *options, first, last)
    _SEGMENTS[key] = (out, comp, machine, pieces.path)
    total = sum(v[0].t_s.size for v in _SEGMENTS.values())
    while total > SEGMENT_CACHE_SAMPLES and len(_SEGMENTS) > 1:
        _, old = _SEGMENTS.popitem(last=False)
        total -= old[0].t_s.size
    return out, comp


def _rows_of(ref: Reference, lo: int, hi: int) -> Reference:
    """Rows lo … hi − 1 of every per-sample column of ``ref``."""
    return replace(ref, **{f.name: getattr(ref, f.name)[lo:hi] for f in fields(ref)})


def _join_segments(prev_tail_mm: np.ndarray, prev_planned_mm: np.ndarray, seg: Reference,
                   planned: Reference, pieces, profile, machine: Machine, tolerance_mm: float,
                   fit_tolerance_mm: float | None) -> Reference:  # fmt: skip
    """Segment ``seg`` (compensated, its planned samples ``planned``) after a segment whose
    last three samples are ``prev_tail_mm`` (3, 3) [mm] (the plan's own ``prev_planned_mm``:
    a segment followed by another ends on them, :data:`JOIN_HELD`): where a difference row
    across the joint (the step, the second and third differences) breaks the limits on the
    samples (the caps of the plan's own samples across it), the segment's first samples are
    projected onto them again (:func:`project_onto_limits`' windows, the earlier segment's
    samples fixed, at most all but the segment's last three); if no window solves it, the
    segment is the plan's own samples (the plan keeps the caps: a joint never breaks them)."""
    m = prev_tail_mm.shape[0]
    u = np.vstack([prev_tail_mm, seg.points_mm])
    r = np.vstack([prev_planned_mm, planned.points_mm])
    head = min(u.shape[0], m + 6)  # every row with a sample on each side of the joint
    if not (limit_excess(u[:head], sample_limits(r[:head], machine)) > 0.0).any():
        return seg
    # The samples a window may move (PROJECT_MAX_WINDOW after the joint) and the rows
    # about them: the frame and caps of those alone (not the whole segment's).
    size = min(u.shape[0], m + PROJECT_MAX_WINDOW + 3)
    whole = u
    u, r = u[:size], r[:size]
    caps = sample_limits(r, machine)
    if np.isfinite(tolerance_mm):
        fit = machine.limits.ph_tolerance_mm if fit_tolerance_mm is None else fit_tolerance_mm
        starts = profile.piece_start_mm
        piece = np.concatenate([np.full(m, planned.piece[0]), planned.piece[: size - m]])
        s_plan = np.concatenate([np.full(m, planned.s_mm[0]), planned.s_mm[: size - m]])
        foot = pieces.path.place(starts, s_plan, piece)[0]
        tube = _tube_mm(pieces, piece, foot, tolerance_mm, fit)
        basis, lower, upper = path_frame(r, s_plan, piece, pieces, profile, u - r, tube)
    else:
        basis = np.broadcast_to(np.eye(3), (u.shape[0], 3, 3))
        lower = np.full((u.shape[0], 3), -np.inf)
        upper = -lower
    last = u.shape[0] - 3
    pad = JOIN_PAD
    while True:
        j1 = min(m + pad, last)
        if j1 <= m or j1 - m > PROJECT_MAX_WINDOW:
            break
        moved = _project_window(u, r, u, caps, basis, lower, upper, m, j1)
        if moved is not None:
            out = u.copy()
            out[m:j1] = moved
            if not (limit_excess(out, caps)[: j1 + 3] > 0.0).any():
                joined = whole[m:].copy()
                joined[: j1 - m] = moved
                return replace(seg, points_mm=joined)
        if j1 == last:
            break
        pad *= 4
    plain = replace(seg, points_mm=planned.points_mm.copy())
    return plain


def _lead_samples(machine: Machine) -> int:
    """The pre-actuation of the ZPETC inverse (:func:`~nurbscnc.servo.precompensate.zpetc`):
    the largest look-ahead of the machine's axes [samples]."""
    period = machine.servo.period_s
    return max(zpetc(discretise(_as_model(m), period, "foh")).lead_samples
               for m in _models(machine) if m is not None)  # fmt: skip


def _compensated_rows(ref_of, pieces, profile, machine: Machine, options: tuple, n: int,
                      lo: int, hi: int) -> tuple[Reference, list]:  # fmt: skip
    """Rows lo … hi − 1 of the compensated reference of a plan of ``n`` planned samples
    (cut-window segments, module comment above; row k + lead ↔ planned sample k, lead the
    pre-actuation at the program's start, :func:`_lead_samples`): the segments covering
    them (:func:`_segment`), each after the first joined to the one before it
    (:func:`_join_segments`: its last three samples, which no join moves).
    ``ref_of(k0, k1)`` gives the planned samples k0 … k1 − 1. Returns the rows and the
    segments' :class:`Compensated` records."""
    period = machine.servo.period_s
    ks = _segment_starts(pieces, profile, period, n)
    lead = _lead_samples(machine)
    begin = ks[:-1] + lead  # the rows of segment i: begin[i] … end[i] − 1
    begin[0] = 0
    end = ks[1:] + lead
    first_i = int(np.searchsorted(end, lo, side="right"))
    last_i = max(int(np.searchsorted(begin, hi, side="left")), first_i + 1)
    parts, comps = [], []
    for i in range(first_i, min(last_i, ks.size - 1)):
        a = int(begin[i])
        if i < ks.size - 2 and lo >= int(end[i]) - JOIN_HELD:
            # Only rows of a segment's held end (the plan's own samples): taken from the
            # plan, the segment not made (a check of the next window reads them).
            parts.append(ref_of(lo - lead, min(hi, int(end[i])) - lead))
            continue
        planned = ref_of(int(ks[i]), int(ks[i + 1]))
        seg, comp = _segment(planned, pieces, profile, machine, options, i == 0,
                             i == ks.size - 2)  # fmt: skip
        if i > 0:
            # The segment before ends on its plan's last JOIN_HELD samples: those are its
            # tail (it need not be made; the planner's re-plans of a later window splice a
            # compacted profile before it, whose samples are the final plan's only there).
            tail = ref_of(int(ks[i]) - JOIN_HELD, int(ks[i])).points_mm
            key = (id(seg), tail.tobytes())  # (seg is held by _SEGMENTS while it is kept)
            joined = _JOINED.get(key)
            if joined is None or joined[0] is not seg:
                joined = (seg, _join_segments(tail, tail, seg, planned, pieces, profile,
                                              machine, *options[:2]))  # fmt: skip
                _JOINED[key] = joined
                while len(_JOINED) > JOINED_KEPT:
                    _JOINED.popitem(last=False)
            seg = joined[1]
        parts.append(_rows_of(seg, max(lo - a, 0), min(hi, int(end[i])) - a))
        comps.append(comp)
    out = replace(parts[0], **{f.name: np.concatenate([getattr(p, f.name) for p in parts])
                                for f in fields(parts[0])})  # fmt: skip
    return replace(out, t_s=np.arange(lo, lo + out.t_s.size) * period), comps


def _joined_records(comps: list, points_mm: np.ndarray) -> Compensated:
    """One record of the segments' ``comps`` for the whole reference ``points_mm``: the
    first segment's pre-actuation, the last one's end blend; with the tube optimisation
    (:class:`Refined`), the largest error of any segment before and after each round (a
    segment that stopped early counted at its last value), the clipped and projected
    references joined."""
    if len(comps) == 1:
        return replace(comps[0], points_mm=points_mm)
    first, last = comps[0], comps[-1]
    if not all(isinstance(c, Refined) for c in comps):
        return Compensated(points_mm, first.lead_samples, last.end_step_mm,
                           last.end_blend_samples)  # fmt: skip
    rounds = max(len(c.history_mm) for c in comps)
    history = np.max([np.pad(np.asarray(c.history_mm), (0, rounds - len(c.history_mm)),
                             mode="edge") for c in comps], axis=0)  # fmt: skip
    return Refined(points_mm, first.lead_samples, last.end_step_mm, last.end_blend_samples,
                   tuple(float(h) for h in history),
                   np.concatenate([c.clipped_mm for c in comps]),
                   np.concatenate([c.projected_mm for c in comps]))  # fmt: skip


def precompensate_reference(ref: Reference, pieces, profile, machine: Machine,
                            tolerance_mm: float = REFERENCE_TOLERANCE_MM,
                            fit_tolerance_mm: float | None = None, refine: bool = True,
                            ) -> tuple[Reference, Compensated]:  # fmt: skip
    """The ZPETC pre-compensated version of a plan's reference ``ref`` (all its samples):
    one segment per cut window (module comment "cut-window segments"), each
    :func:`_compensate_segment` (the inverse, the tube of ``tolerance_mm`` [mm] about the
    path, the limits on the samples, the tube optimisation), joined within the limits; the
    first segment delayed by the inverse's pre-actuation (``lead_samples``), every
    per-sample column padded alike; wall times from 0 at the servo period. A program of one
    cut is one segment: what :func:`_compensate_segment` gives for it."""
    n = ref.t_s.size
    options = (tolerance_mm, fit_tolerance_mm, refine)
    out, comps = _compensated_rows(lambda a, b: _rows_of(ref, a, b), pieces, profile,
                                   machine, options, n, 0, n + _lead_samples(machine))  # fmt: skip
    return out, _joined_records(comps, out.points_mm)


def precompensated_sampler(sampler, machine: Machine,
                           tolerance_mm: float = REFERENCE_TOLERANCE_MM,
                           fit_tolerance_mm: float | None = None):  # fmt: skip
    """The reference sampler (pieces, profile, period_s, k0=0, k1=None) → Reference of
    ``sampler`` followed by :func:`precompensate_reference`: what the dynamics check
    simulates with ``--precompensate`` (it needs no hook in the planner). Rows k0 … k1 − 1
    are made from the segments that hold them (module comment "cut-window segments"), the
    same rows as the whole reference's, so the planner checks a cut window's samples at
    the cost of that window; a sampler without windows (the Taylor recurrence) is sampled
    whole and then cut."""
    from nurbscnc.plan.sampler import FunctionSampler
    from nurbscnc.plan.timing import sample_count

    options = (tolerance_mm, fit_tolerance_mm, True)
    windowed = sampler.windowed

    def sample(pieces, profile, period_s: float, k0: int = 0, k1: int | None = None):
        n = sample_count(pieces, profile, period_s)
        hi = n + _lead_samples(machine) if k1 is None else k1
        if windowed:
            def ref_of(a, b):
                return sampler(pieces, profile, period_s, a, b)
        else:
            whole = sampler(pieces, profile, period_s)

            def ref_of(a, b):
                return _rows_of(whole, a, b)
        return _compensated_rows(ref_of, pieces, profile, machine, options, n, k0, hi)[0]

    return FunctionSampler(sample, windowed, sampler.interpolator)


def _servo_of(model: AxisModel) -> AxisServo:
    """An eq.-25 :class:`AxisServo` holding ``model`` (degrees ≤ 2 over ≤ 4)."""
    num = np.zeros(3)
    den = np.zeros(5)
    n = np.trim_zeros(np.asarray(model.numerator, dtype=float), "f")
    d = np.trim_zeros(np.asarray(model.denominator, dtype=float), "f")
    num[3 - n.size :] = n
    den[5 - d.size :] = d
    return AxisServo(a0=den[4], a1=den[3], a2=den[2], a3=den[1], a4=den[0], b0=num[2],
                     b1=num[1], b2=num[0])  # fmt: skip


def precompensation_report(plan: Plan, planned: Reference, compensated: Reference,
                           comp: Compensated, machine: Machine,
                           tolerance_mm: float = REFERENCE_TOLERANCE_MM) -> Precompensation:
    """The reference's own deviation from the path and the ±10 % model-error sensitivity.

    Deviation: the distance of each compensated point u_k from the path, measured near the
    planned point r_k of the same period (on the path; W = 2|u_k − r_k|,
    :func:`~nurbscnc.plan.dynamics.windowed_contour_mm`: never below the true distance), and
    where that exceeds the tolerance, to the whole path (:class:`PathIndex`).
    Sensitivity: the compensated points simulated through each model of
    :data:`SENSITIVITY_CASES` (:func:`~nurbscnc.plan.dynamics.path_response`, true distance
    to the path), the largest contour error on cutting samples, as the dynamics check counts
    it."""
    pieces, profile = plan.pieces, plan.profile
    pad = (comp.lead_samples, 0)
    r = np.pad(planned.points_mm, (pad, (0, 0)), mode="edge")
    u = compensated.points_mm
    lag = np.sqrt(np.sum((u - r) ** 2, axis=1))
    cut = ~pieces.rapid[compensated.piece]
    dev = windowed_contour_mm(u, lag, compensated.s_mm, pieces, profile)
    index = PathIndex(pieces)
    # Above the tolerance, the distance to the whole path (the window may miss a nearer
    # stretch of path, e.g. the other leg of a hairpin): the true distance.
    sel = np.flatnonzero(dev > min(tolerance_mm, float(lag.max())))
    if sel.size:
        dev[sel] = index.distance_mm(u[sel], dev[sel])
    deviation = float(dev[cut].max()) if cut.any() else 0.0
    eps = machine.limits.contour_tolerance_mm
    rows = []
    for label, gains, bandwidths in SENSITIVITY_CASES:
        servo = machine.servo
        models = {a: None if m is None else _servo_of(perturbed_model(m, k, lam))
                  for a, m, k, lam in zip("xyz", _models(machine), gains, bandwidths)}
        perturbed = replace(machine, servo=replace(servo, **models))
        resp = path_response(compensated, pieces, profile, perturbed, refine_above_mm=eps,
                             index=index)  # fmt: skip
        tail = np.full(resp.contour_mm.size - u.shape[0], not pieces.rapid[-1])
        cutting = np.append(cut, tail)
        err = resp.contour_mm[cutting]
        rows.append((label, float(err.max()) if err.size else 0.0))
    period = machine.servo.period_s
    return Precompensation(comp.lead_samples * period, 0.0, deviation, tuple(rows),
                           tolerance_mm, comp.end_step_mm,
                           comp.end_blend_samples * period)  # fmt: skip


# --------------------------------------------------------------------------- limits on samples
#
# The ZPETC inverse of a jerk-limited profile is not jerk-limited: F ≈ 1 + c_1 s + c_2 s² + …
# adds the planned velocity, acceleration and jerk (scaled) to the reference, so every jerk
# switch of the plan becomes a snap impulse of the compensated one, and the clip into the tube
# adds kinks where it bites (the 9 mm airfoil: 434,795 mm/s³ per axis on the samples against
# J = 50,000). The written reference must keep the machine's limits on its samples (issue 13),
# so the compensated points are projected onto them before anything else looks at them.
#
# The offset δ = u − r from the planned reference r (the planner's output: within the limits,
# on the path) is micrometres, and every limit is linear in it per sample row:
#
#   |Δ²(r + δ)_c| ≤ Ā_i,  |Δ³(r + δ)_c| ≤ J̄_i  (per axis c),  |Δ(r + δ)_c| ≤ V̄_c,i,
#   |Δ(r + δ)| ≤ V̄_i  (the step length: linearised along the step, then checked exactly),
#
# the caps the limit (A T², J T³, V T, per axis the smaller of the path's and the axis' own),
# or where the planned reference is above it already (a path-limited machine keeps A and J
# along the path; per axis its curvature terms can exceed them, e.g. 56,489 mm/s³ on the
# airfoil), its own difference there: never rougher than the plan. δ is written in the frame
# of the path at r_k, δ_k = α_k m_k + β_k t_k (m the in-plane normal, t the tangent), and kept
# in the tube exactly: P(s_k + β) = r_k + β t_k + R with |R| ≤ κ β²/2 (κ the largest curvature
# within |β| along the path, no break in between), so dist(r_k + δ_k, path) ≤ |α_k| + κβ̄²/2:
#
#   |β_k| ≤ β̄_k,   |α_k| ≤ τ_k − κ_k β̄_k²/2.
#
# δ = 0 satisfies everything, so the linear programme
#
#   min Σ |α_k − α*_k| + |β_k − β*_k|   (α*, β*: the clipped ZPETC offset in that frame)
#
# always has a solution; it is solved over windows around the rows the ZPETC reference breaks
# (the rest kept as it is, rows reaching out of a window with their fixed samples), a window
# that cannot be solved with its ends fixed grown until it can (at worst the whole reference,
# whose first and last samples are the plan's).

#: The LP's unit of length [mm] (1 nm): the caps are 0.05 µm (J T³) and HiGHS' feasibility
#: tolerance is absolute.
_LP_UNIT_MM = 1e-6
#: Share of a limit the LPs keep free (the solver's tolerance, rounding): the samples stay
#: within (1 − LIMIT_MARGIN) of the limit where the plan is within it.
LIMIT_MARGIN = 1e-7
#: Samples either side of a row over the caps that its window moves (first try; ×4 a try).
PROJECT_PAD = 40
#: Largest move along the path of the projection [mm] ...
PROJECT_ALONG_MM = 0.1
#: ... and at most the move whose bend off the path (κ β²/2) is this share of the tube.
PROJECT_BEND = 0.5
#: Sides of the polygon in the disc across a path out of the XY plane (path_frame).
TUBE_SIDES = 8
#: Time limit of one projection LP [s].
PROJECT_LP_TIME_S = 5.0
#: Most samples one projection LP moves (memory: HiGHS took 2 GB for a whole 23,000-sample
#: segment of tort.ngc): longer windows are solved in pieces, and windows grow no further
#: (where rows are still broken then, the reference is the plan's own, within the caps).
PROJECT_MAX_WINDOW = 4096


@dataclass(frozen=True, eq=False)
class SampleLimits:
    """The limits on a reference's samples [mm], each a row of differences (np.diff):
    ``step`` (N−1,) the step length (path speed V T), ``axis_step`` (N−1, 3) each axis'
    step (its V_i T; inf: none), ``second`` (N−2, 3) and ``third`` (N−3, 3) each axis'
    second and third differences (A T², J T³, the smaller of the path's and the axis' own),
    every one raised to the planned reference's own difference where that is above the
    limit (:func:`sample_limits`); ``limits`` the machine's (V T, (V_i T), (A_i T²),
    (J_i T³)) the rows were raised from, ``own`` the planned reference's |differences| (its
    step lengths and the |Δ^k| of each axis, k = 1, 2, 3)."""

    step: np.ndarray
    axis_step: np.ndarray
    second: np.ndarray
    third: np.ndarray
    limits: tuple
    own: tuple

    def rows(self, order: int) -> np.ndarray:
        """The per-axis caps of the ``order``-th differences (1, 2, 3) [mm]."""
        return (self.axis_step, self.second, self.third)[order - 1]

    def lp_rows(self, order: int) -> np.ndarray:
        """The caps an LP uses: LIMIT_MARGIN below the limit, never below the plan's own (so
        the plan's points are a solution)."""
        limit = np.asarray(self.limits[order], dtype=float)
        return np.maximum(limit * (1.0 - LIMIT_MARGIN), self.own[order])

    def lp_step(self) -> np.ndarray:
        """The step-length caps an LP uses (as :meth:`lp_rows`)."""
        return np.maximum(float(self.limits[0]) * (1.0 - LIMIT_MARGIN), self.own[0])


def sample_limits(planned_mm: np.ndarray, machine: Machine) -> SampleLimits:
    """The caps of :class:`SampleLimits` for references of the length of ``planned_mm``
    (N, 3) [mm] (the plan's reference, lead-padded): the machine's path limits ``limits``
    and per-axis limits ``axis_limits`` per period T, each row raised to the plan's own."""
    t = machine.servo.period_s
    lim = machine.limits
    v_i, a_i, j_i = machine.axis_limits.as_arrays()
    v = lim.v_max_mm_s * t
    axis_v = v_i * t
    axis_a = np.minimum(lim.a_max_mm_s2, a_i) * t**2
    axis_j = np.minimum(lim.j_max_mm_s3, j_i) * t**3
    r = np.asarray(planned_mm, dtype=float)
    d1, d2, d3 = (np.diff(r, n, axis=0) for n in (1, 2, 3))
    own = (np.sqrt(np.einsum("ij,ij->i", d1, d1)), np.abs(d1), np.abs(d2), np.abs(d3))
    return SampleLimits(np.maximum(v, own[0]), np.maximum(axis_v, own[1]),
                        np.maximum(axis_a, own[2]), np.maximum(axis_j, own[3]),
                        (v, axis_v, axis_a, axis_j), own)  # fmt: skip


def limit_excess(points_mm: np.ndarray, caps: SampleLimits) -> np.ndarray:
    """Per sample (N,): the largest excess [mm] of a difference row it is in over its cap,
    beyond rounding (1e-9 of the cap, and 2^k ulps of the largest coordinate for a k-th
    difference); ≤ 0: every row within its cap."""
    u = np.asarray(points_mm, dtype=float)
    n = u.shape[0]
    out = np.full(n, -np.inf)
    if n < 2:
        return np.zeros(n)
    ulp = float(np.spacing(np.abs(u).max()))
    d1 = np.diff(u, axis=0)
    rows = [(np.sqrt(np.einsum("ij,ij->i", d1, d1)) - caps.step * (1.0 + 1e-9) - 2.0 * ulp, 1)]
    rows += [((np.abs(np.diff(u, k, axis=0)) - caps.rows(k) * (1.0 + 1e-9)
               - 2.0**k * ulp).max(axis=1), k) for k in (1, 2, 3) if n > k]  # fmt: skip
    for over, k in rows:
        for lag in range(k + 1):  # row i covers samples i … i + k
            out[lag : lag + over.size] = np.maximum(out[lag : lag + over.size], over)
    return out


#: The last path's breaks (:func:`_break_lengths_mm`: every segment and joint of a check asks
#: them, 50 ms each on tort.ngc's 362 pieces): (path, its piece starts' bytes, breaks).
_BREAKS: list = []


def _break_lengths_mm(pieces, profile) -> np.ndarray:
    """Path lengths [mm] (sorted) where the path's tangent jumps (a break between two pieces),
    and its two ends (kept for the last path and piece starts)."""
    starts = profile.piece_start_mm
    key = np.ascontiguousarray(starts).tobytes()
    if _BREAKS and _BREAKS[0] is pieces.path and _BREAKS[1] == key:
        return _BREAKS[2]
    out = _breaks_of(pieces, starts, profile.total_length_mm)
    _BREAKS[:] = [pieces.path, key, out]
    return out


def _breaks_of(pieces, starts: np.ndarray, total_mm: float) -> np.ndarray:
    """:func:`_break_lengths_mm` computed."""
    k = starts.size
    rows = np.arange(k)
    t0 = pieces.path.tangents(rows, np.zeros(k))
    t1 = pieces.path.tangents(rows, pieces.length_mm[:k])
    jump = np.sqrt(np.sum((t1[:-1] - t0[1:]) ** 2, axis=1)) > 1e-9
    ends = np.concatenate([[0.0], starts[1:][jump], [total_mm]])
    return np.unique(ends)


def _range_max(values: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """max(values[lo_i … hi_i]) (inclusive) for each i: a sparse table, whole-array."""
    table = [np.asarray(values, dtype=float)]
    while 2 ** len(table) <= table[0].size:
        prev, half = table[-1], 2 ** (len(table) - 1)
        table.append(np.maximum(prev[:-half], prev[half:]))
    level = np.floor(np.log2(np.maximum(hi - lo + 1, 1))).astype(int)
    out = np.empty(lo.size)
    for k in np.unique(level):
        sel = level == k
        out[sel] = np.maximum(table[k][lo[sel]], table[k][hi[sel] - 2**k + 1])
    return out


def path_frame(planned_mm: np.ndarray, s_mm: np.ndarray, piece: np.ndarray, pieces, profile,
               offset_mm: np.ndarray, tube_mm: np.ndarray):  # fmt: skip
    """The frame of the projection (module comment above) at each planned point (N, 3) [mm]
    at path length ``s_mm`` on ``piece``: the basis (N, 2, 3) (in-plane normal m, tangent t
    of the path there), the bounds (N, 2) low and high of (α, β) [mm] keeping r + α m + β t
    within ``tube_mm`` (N,) [mm] of the path, exactly (no break and at most
    κ β̄²/2 ≤ PROJECT_BEND τ of bend within β̄ along it; ``offset_mm`` (N, 3) the wanted
    offset, whose along-path part β̄ need not exceed by more than τ). Where the path or
    the offsets leave the XY plane (a helix, a plunge, a G18/G19 arc: an offset the plane's
    (m, t) cannot hold, so a window's samples could not join the fixed ones beside it),
    a third direction w = t × m (m any normal of a vertical tangent): basis (N, 3, 3) of
    (m, t, w), bounds (N, 3) of (α, β, γ), the LP holding |α| + |γ| within α's bound
    (:func:`_project_window`: within the tube exactly)."""
    starts = profile.piece_start_mm
    loc = s_mm - starts[piece]
    t = pieces.path.tangents(piece, loc)
    m = _plane_normal(t)
    # The largest curvature of the pieces within PROJECT_ALONG_MM along the path (NURBS
    # cells' estimate doubled, as _local_polyline).
    kappa = np.where(pieces.kind == Kind.NURBS, 2.0, 1.0) * np.abs(pieces.kappa_max_per_mm)
    kappa = np.nan_to_num(kappa, nan=np.inf)
    lo_p = np.clip(np.searchsorted(starts, s_mm - PROJECT_ALONG_MM, side="right") - 1, 0,
                   starts.size - 1)  # fmt: skip
    hi_p = np.clip(np.searchsorted(starts, s_mm + PROJECT_ALONG_MM, side="right") - 1, 0,
                   starts.size - 1)  # fmt: skip
    k_near = _range_max(kappa[: starts.size], lo_p, hi_p)
    tube = np.maximum(np.asarray(tube_mm, dtype=float), 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        b_cap = np.minimum(PROJECT_ALONG_MM, np.sqrt(2.0 * PROJECT_BEND * tube / k_near))
    b_cap = np.nan_to_num(b_cap, nan=0.0)
    along = np.abs(np.einsum("ij,ij->i", offset_mm, t))
    b_bar = np.minimum(b_cap, along + tube)
    # No break between r_k and r_k + β t: β within the distance to the nearest break (or
    # end of the path) on its side.
    brk = _break_lengths_mm(pieces, profile)
    i = np.clip(np.searchsorted(brk, s_mm, side="right"), 1, brk.size - 1)
    ahead = np.maximum(brk[i] - s_mm, 0.0)
    behind = np.maximum(s_mm - brk[i - 1], 0.0)
    room = np.maximum(tube - 0.5 * np.where(b_bar > 0.0, k_near, 0.0) * b_bar**2, 0.0)
    has_m = np.any(m != 0.0, axis=1)
    if np.any(t[:, 2] != 0.0) or np.any(np.asarray(offset_mm)[:, 2] != 0.0):
        # A third direction (docstring): m any unit normal of a vertical tangent.
        x = np.array([1.0, 0.0, 0.0])
        m_v = x - np.outer(t @ x, np.ones(3)) * t
        m_v /= np.maximum(np.linalg.norm(m_v, axis=1), 1e-300)[:, None]
        m = np.where(has_m[:, None], m, m_v)
        w = np.cross(t, m)
        w /= np.maximum(np.linalg.norm(w, axis=1), 1e-300)[:, None]
        lower = np.column_stack([-room, -np.minimum(b_bar, behind), -room])
        upper = np.column_stack([room, np.minimum(b_bar, ahead), room])
        return np.stack([m, t, w], axis=1), lower, upper
    lower = np.column_stack([np.where(has_m, -room, 0.0), -np.minimum(b_bar, behind)])
    upper = np.column_stack([np.where(has_m, room, 0.0), np.minimum(b_bar, ahead)])
    return np.stack([m, t], axis=1), lower, upper


def _windows(bad: np.ndarray, pad: int, n: int) -> list[tuple[int, int]]:
    """Windows [j0, j1) of movable samples (1 … n − 2) ``pad`` either side of the samples
    ``bad`` (N,) bool; overlapping ones merged."""
    idx = np.flatnonzero(bad)
    if idx.size == 0:
        return []
    cuts = np.flatnonzero(np.diff(idx) > 2 * pad + 1) + 1
    return [(max(int(g[0]) - pad, 1), min(int(g[-1]) + pad + 1, n - 1))
            for g in np.split(idx, cuts)]  # fmt: skip


def _project_window(u: np.ndarray, r: np.ndarray, target: np.ndarray, caps: SampleLimits,
                    basis: np.ndarray, lower: np.ndarray, upper: np.ndarray, j0: int,
                    j1: int) -> np.ndarray | None:  # fmt: skip
    """The LP of one window (module comment above): samples j0 … j1−1 of ``u`` (N, 3) moved to
    r + Σ_d x_d basis_d, nearest ``target`` in L1 of the frame's coordinates, every
    difference row touching them within the caps, the others as they are; the new
    samples (j1 − j0, 3) [mm], or None (no solution, or the solver gave up)."""
    from scipy.optimize import linprog
    from scipy.sparse import coo_matrix, csr_matrix, eye, hstack, vstack

    n = u.shape[0]
    size, dims = j1 - j0, basis.shape[1]
    b = basis[j0:j1]
    nx = size * dims
    want = np.einsum("kdc,kc->kd", b, target[j0:j1] - r[j0:j1]).ravel() / _LP_UNIT_MM
    base = u.copy()
    base[j0:j1] = r[j0:j1]  # x = 0: the plan's points in the window
    blocks, rhs = [], []
    # |x − x*| ≤ e
    ident = eye(nx, format="csr")
    blocks += [hstack([ident, -ident]), hstack([-ident, -ident])]
    rhs += [want, -want]

    def diff_matrix(order: int, weights: np.ndarray):
        """Rows i (touching the window) of Σ_l c_l (weights · x)_{i+l}: weights (j1 − j0, D)
        per window sample and direction; the rows' indices."""
        coef = np.diff(np.eye(order + 1), n=order, axis=0)[0]
        rows = np.arange(max(j0 - order, 0), min(j1 - 1, n - 1 - order) + 1)
        ri, ci, vals = [], [], []
        for lag, c in enumerate(coef):
            k = rows + lag
            ok = (k >= j0) & (k < j1)
            for d in range(dims):
                ri.append(np.flatnonzero(ok))
                ci.append((k[ok] - j0) * dims + d)
                vals.append(c * weights[k[ok] - j0, d])
        mat = coo_matrix((np.concatenate(vals), (np.concatenate(ri), np.concatenate(ci))),
                         shape=(rows.size, nx)).tocsr()  # fmt: skip
        return mat, rows

    for order in (1, 2, 3):
        cap = caps.lp_rows(order)
        diffs = np.diff(base, order, axis=0)
        for c in range(3):
            if not np.any(basis[j0:j1, :, c]) or not np.any(np.isfinite(cap[:, c])):
                continue
            mat, rows = diff_matrix(order, b[:, :, c])
            keep = np.isfinite(cap[rows, c])
            mat, rows = mat[keep], rows[keep]
            zeros = csr_matrix((rows.size, nx))
            blocks += [hstack([mat, zeros]), hstack([-mat, zeros])]
            rhs += [(cap[rows, c] - diffs[rows, c]) / _LP_UNIT_MM,
                    (cap[rows, c] + diffs[rows, c]) / _LP_UNIT_MM]  # fmt: skip
    if dims == 3:
        # The tube across the path with a third direction (path_frame): (α, γ) within the
        # regular TUBE_SIDES-gon inscribed in the disc of α's bound, turned so that a corner
        # is the target's direction (the clip puts targets on the disc's edge: each stays a
        # solution, and so do its neighbours' nearly).
        # (No tube: the axes' frame, nothing across.)
        room = upper[j0:j1, 0] / _LP_UNIT_MM
        k = np.flatnonzero(np.isfinite(room))
        room = room[k]
        pair = want.reshape(size, 3)[k]
        phi = np.arctan2(pair[:, 2], pair[:, 0])
        half = np.pi / TUBE_SIDES
        for side in range(TUBE_SIDES):
            ang = phi + (2 * side + 1) * half
            mat = coo_matrix((np.concatenate([np.cos(ang), np.sin(ang)]),
                              (np.tile(np.arange(k.size), 2),
                               np.concatenate([3 * k, 3 * k + 2]))),
                             shape=(k.size, 2 * nx)).tocsr()  # fmt: skip
            blocks.append(mat)
            rhs.append(room * np.cos(half))
    # The step length, linearised along the ZPETC reference's step (else the plan's); the
    # solution is checked exactly, and a row it breaks is cut again along its own step (the
    # second-order remainder |w⊥|²/2|w| of a move across the step: sub-nanometre here).
    step_cap = caps.lp_step()
    d1 = np.diff(base, axis=0)

    def step_rows(rows: np.ndarray, direction: np.ndarray):
        """Rows unit_i · Δ(δ)_i of the steps ``rows`` along ``direction`` (rows, 3), and
        their caps less the fixed part unit_i · Δ(base)_i [LP units]."""
        unit = direction / np.maximum(np.sqrt(np.einsum("ij,ij->i", direction, direction)),
                                      1e-300)[:, None]  # fmt: skip
        ri, ci, vals = [], [], []
        for lag, c in enumerate((-1.0, 1.0)):
            k = rows + lag
            ok = (k >= j0) & (k < j1)
            proj = np.einsum("kdc,kc->kd", basis[k[ok]], unit[ok])
            for d in range(dims):
                ri.append(np.flatnonzero(ok))
                ci.append((k[ok] - j0) * dims + d)
                vals.append(c * proj[:, d])
        mat = coo_matrix((np.concatenate(vals), (np.concatenate(ri), np.concatenate(ci))),
                         shape=(rows.size, nx)).tocsr()  # fmt: skip
        cap = (step_cap[rows] - np.einsum("ij,ij->i", unit, d1[rows])) / _LP_UNIT_MM
        return hstack([mat, csr_matrix((rows.size, nx))]), cap

    rows = np.arange(max(j0 - 1, 0), min(j1 - 1, n - 2) + 1)
    d_target = np.diff(target, axis=0)[rows]
    direction = np.where(np.any(d_target != 0.0, axis=1)[:, None], d_target, d1[rows])
    moving = np.any(direction != 0.0, axis=1)  # (a row between two samples at rest: none)
    rows, direction = rows[moving], direction[moving]
    mat, cap = step_rows(rows, direction)
    blocks.append(mat)
    rhs.append(cap)
    bounds = np.column_stack([np.concatenate([lower[j0:j1].ravel() / _LP_UNIT_MM,
                                              np.zeros(nx)]),
                              np.concatenate([upper[j0:j1].ravel() / _LP_UNIT_MM,
                                              np.full(nx, np.inf)])])  # fmt: skip
    cost = np.concatenate([np.zeros(nx), np.ones(nx)])
    for _try in range(4):
        res = linprog(cost, A_ub=vstack(blocks).tocsr(), b_ub=np.concatenate(rhs),
                      bounds=bounds, method="highs",
                      options={"time_limit": PROJECT_LP_TIME_S,
                               "primal_feasibility_tolerance": 1e-9})  # fmt: skip
        if res.status != 0:
            return None
        x = res.x[:nx].reshape(size, dims) * _LP_UNIT_MM
        moved = r[j0:j1] + np.einsum("kd,kdc->kc", x, b)
        trial = u.copy()
        trial[j0:j1] = moved
        lo, hi = max(j0 - 1, 0), min(j1, n - 1)
        d = np.diff(trial[lo : hi + 1], axis=0)
        over = np.sqrt(np.einsum("ij,ij->i", d, d)) > step_cap[lo:hi] * (1.0 + 1e-12)
        if not over.any():
            return moved
        mat, cap = step_rows(np.arange(lo, hi)[over], d[over])
        blocks.append(mat)
        rhs.append(cap)
    return None


def project_onto_limits(target_mm: np.ndarray, planned_mm: np.ndarray, caps: SampleLimits,
                        basis: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                        held: int = 1) -> np.ndarray:  # fmt: skip
    """``target_mm`` (N, 3) [mm] moved, where its differences break ``caps``, to the nearest
    reference (L1 in the frame ``basis`` (N, D, 3) about ``planned_mm``, offsets within
    ``lower`` … ``upper`` (N, D) [mm]) whose differences keep them (module comment above);
    the first and last ``held`` samples, and samples no broken row reaches, as they are. The plan's
    own reference (δ = 0) keeps them, so there is always a solution: if the solver fails
    on the whole reference, or on windows grown to PROJECT_MAX_WINDOW samples (an LP that
    runs out of PROJECT_LP_TIME_S counts as failed), the planned points are returned."""
    r = np.asarray(planned_mm, dtype=float)
    u = np.array(target_mm, dtype=float)
    n = u.shape[0]
    if n < 3:
        return u
    pad = PROJECT_PAD
    m = n - held + 1  # the movable samples: 1 … m − 2
    while True:
        bad = limit_excess(u, caps) > 0.0
        bad[0] = False
        bad[m - 1 :] = False
        windows = _windows(bad, pad, m)
        if not windows:
            return u
        for j0, j1 in windows:
            # (a longer window in pieces of PROJECT_MAX_WINDOW, one after the other)
            for c0 in range(j0, j1, PROJECT_MAX_WINDOW):
                c1 = min(c0 + PROJECT_MAX_WINDOW, j1)
                moved = _project_window(u, r, target_mm, caps, basis, lower, upper, c0, c1)
                if moved is not None:
                    u[c0:c1] = moved
        if windows == [(1, m - 1)] or 2 * pad > PROJECT_MAX_WINDOW:
            bad = limit_excess(u, caps) > 0.0
            return u if not bad.any() else r.copy()
        pad *= 4


# --------------------------------------------------------------------------- tube optimisation
#
# The clip above keeps the ZPETC reference within the tube of radius τ about the path, but
# where the inverse wants more than τ across the path (entering a tight curve, the stop at
# the end) the clipped reference is not the best one in the tube. Here the offsets across the
# path are re-chosen, region by region where the simulated tool is still far from the path,
# to minimise the largest contour error there (a small linear programme on the known model):
#
#   tool   y = H u (per axis, linear: the sampled eq. 25, FOH),
#   error  e_k ≈ σ_k + ν_k · (H Δ)_k   (σ_k = |y_k − q_k|, q_k the nearest path point, ν_k the
#          unit vector from q_k to y_k: the distance to first order),
#   step   Δ_j = a_j m_j + b_j t_j   (m_j the in-plane normal, t_j the tangent of the path
#          at the reference's own foot: across and along it),
#   tube   −τ'_j ≤ μ_j + a_j ≤ τ'_j − κ_j b̄_j²/2   (μ_j the current offset across the path,
#          τ'_j the tube less any offset out of the plane; |b_j| ≤ b̄_j, the bend of a
#          straight move along a curve of curvature κ_j at most REFINE_BEND τ),
#   limits the step lengths |u_{j+1} − u_j| + b_{j+1} − b_j ≤ V T (first order) and the
#          first, second and third differences of u + Δ on every axis within the caps of
#          the limits on the samples (SampleLimits: the machine's, or the plan's own where
#          that is above them; the projection above starts the rounds within them) — or
#          within u's own where it is above them (a start not projected: no step rougher),
#   min z  subject to  |σ_k + Σ_j G_kj (a_j, b_j)| ≤ z  over the region's tool samples,
#
# G_kj = Σ_axes ν_k,c h_c[k − j] (m_j,c, t_j,c) with h_c the axis' impulse response. Then the
# step is applied as the LP sees it (a straight move: its differences are the LP's exactly),
# the reference projected exactly into the tube again (nearest point on the path; to
# rounding a no-op), simulated, and kept only where the true largest error of the region
# went down and it is no faster or rougher than allowed (else halved, then dropped): the
# largest error never increases from round to round. Work per region:
# one dense G of (inputs + reach) × inputs ≤ REFINE_MAX_INPUTS × (REFINE_MAX_INPUTS + reach).

#: Rounds of linearise → LP → simulate (each only keeps what lowers the error).
REFINE_ROUNDS = 8
#: ... stopping early when a round lowers the largest error by less than this [mm].
REFINE_GAIN_MM = 1e-5
#: A region is the tool samples whose contour error exceeds this fraction of ε_max, with the
#: reference samples REFINE_BEFORE_S before it (the response's rise: what can still act) and
#: the tool samples the impulse response reaches after it.
REFINE_THRESHOLD = 0.9
REFINE_BEFORE_S = 0.025
#: The impulse response is followed until it is below this fraction of its peak.
REFINE_REACH = 1e-3
#: Most reference samples one LP moves (a longer region is cut into windows this long).
REFINE_MAX_INPUTS = 120
#: The share of the machine's V T a step's length may use (the first-order length is
#: exact but for the move across the path, orthogonal: its square, sub-nanometre here).
REFINE_SPEED = 0.999
#: A tool sample within this of the last try's [mm] keeps its distance to the path
#: (:func:`refine_in_tube`).
REUSE_MM = 1e-12
#: Time limit of one window's LP [s] (HiGHS; a window not solved in time is left as is).
REFINE_LP_TIME_S = 1.0
#: Chord sagitta of the optimiser's polylines of the path [mm].
REFINE_CHORD_MM = 1e-7
#: Largest move of a reference sample along the path in one round [mm] ...
REFINE_ALONG_MM = 0.02
#: ... and at most the move whose bend off a curve (κ b²/2) is this share of the tube.
REFINE_BEND = 0.2


@dataclass(frozen=True, eq=False)
class Refinement:
    """What the tube optimisation did: ``points_mm`` the reference, ``history_mm`` the
    largest contour error [mm] on the cut before the first round and after each round
    (non-increasing), ``regions`` the windows of the last round."""

    points_mm: np.ndarray
    history_mm: tuple[float, ...]
    regions: int


def _impulse_responses(machine: Machine, length: int) -> np.ndarray:
    """h (length, 3): each axis' sampled eq.-25 impulse response (FOH, the simulation's
    discretisation, :func:`~nurbscnc.servo.model.discretise`); an axis without a model
    follows its reference (h = δ)."""
    from scipy import signal

    from nurbscnc.servo.model import discretise

    h = np.zeros((length, 3))
    impulse = np.zeros(length)
    impulse[0] = 1.0
    for c, m in enumerate(_models(machine)):
        if m is None:
            h[0, c] = 1.0
            continue
        d = discretise(m, machine.servo.period_s, "foh")
        h[:, c] = signal.lfilter(d.b, d.a, impulse)
    return h


def _reach_samples(machine: Machine) -> int:
    """Samples after which every axis' impulse response stays below REFINE_REACH × peak."""
    h = np.abs(_impulse_responses(machine, 2000))
    big = h >= REFINE_REACH * h.max(axis=0)
    return int(max(np.flatnonzero(big.any(axis=1))[-1] + 1, 1))


def _local_polyline(pieces, profile, s_lo_mm: float, s_hi_mm: float) -> np.ndarray:
    """The path between path lengths s_lo and s_hi [mm] (whole pieces) as a dense polyline:
    lines by their ends, curves by chords of sagitta κh²/8 ≤ REFINE_CHORD_MM (κ the
    piece's largest curvature, doubled on NURBS cells as dynamics.path_counts does), so
    a point's foot on it (:func:`nearest_on_polyline`) follows the curve smoothly
    to well below the reference's jerk per period J T³."""
    starts = profile.piece_start_mm
    lo = max(int(np.searchsorted(starts, s_lo_mm, side="right")) - 1, 0)
    hi = min(int(np.searchsorted(starts, s_hi_mm, side="right")), starts.size)
    hi = max(hi, lo + 1)
    sl = slice(lo, hi)
    length = pieces.length_mm[sl]
    kappa = np.where(pieces.kind[sl] == Kind.NURBS, 2.0, 1.0) * np.abs(pieces.kappa_max_per_mm[sl])
    with np.errstate(divide="ignore"):
        h = np.minimum(0.01, np.sqrt(8.0 * REFINE_CHORD_MM / kappa))
    c = np.maximum(np.ceil(length / h).astype(np.int64) + 1, 3)
    c = np.where((pieces.kind[sl] == Kind.LINE) | (length == 0.0), 2, c)
    piece = np.repeat(np.arange(lo, hi), c)
    first = np.repeat(np.cumsum(c) - c, c)
    frac = (np.arange(piece.size) - first) / np.repeat(c - 1, c)
    pts = pieces.path.points_at_fraction(piece, frac)
    # Without the repeated point where one piece ends and the next starts (a segment of
    # rounding length has no direction).
    step = np.sqrt(np.sum(np.diff(pts, axis=0) ** 2, axis=1))
    return pts[np.concatenate([[True], step > 1e-9])]


def nearest_on_polyline(q_mm: np.ndarray, poly_mm: np.ndarray, vertices: int = 8):
    """Nearest points (m, 3), distances (m,) [mm] and unit tangents (m, 3) of the polyline
    ``poly_mm`` (p ≥ 2, 3) for the points ``q_mm`` (m, 3): exact point-to-segment over the
    segments next to the ``vertices`` nearest vertices (a k-d tree)."""
    from scipy.spatial import cKDTree

    p = poly_mm.shape[0]
    k = min(vertices, p)
    _, idx = cKDTree(poly_mm).query(q_mm, k=k)
    idx = np.asarray(idx).reshape(q_mm.shape[0], k)
    seg = np.clip(np.concatenate([idx - 1, idx], axis=1), 0, p - 2)  # (m, 2k)
    a = poly_mm[seg]
    d = poly_mm[seg + 1] - a
    len2 = np.einsum("mij,mij->mi", d, d)
    t = np.einsum("mij,mij->mi", q_mm[:, None, :] - a, d) / np.where(len2 > 0.0, len2, 1.0)
    t = np.clip(t, 0.0, 1.0)
    foot = a + t[..., None] * d
    e = q_mm[:, None, :] - foot
    dist = np.sqrt(np.einsum("mij,mij->mi", e, e))
    best = np.argmin(dist, axis=1)
    rows = np.arange(q_mm.shape[0])
    dd = d[rows, best]
    tangent = dd / np.maximum(np.sqrt(np.einsum("ij,ij->i", dd, dd)), 1e-300)[:, None]
    nearest_on_polyline.segment = seg[rows, best]
    return foot[rows, best], dist[rows, best], tangent


def _plane_normal(tangent: np.ndarray) -> np.ndarray:
    """The unit normal in the XY plane, left of each unit tangent (m, 3) (zero where the
    tangent has no XY part)."""
    m = np.zeros_like(tangent)
    m[:, 0], m[:, 1] = -tangent[:, 1], tangent[:, 0]
    size = np.sqrt(m[:, 0] ** 2 + m[:, 1] ** 2)
    return np.where(size[:, None] > 1e-12, m / np.where(size > 1e-12, size, 1.0)[:, None], 0.0)


def _frame(poly_mm: np.ndarray):
    """The polyline's arc length at its vertices (P,), and a function σ → (points, unit
    tangents, unit XY normals) at arc lengths σ, the tangents and normals interpolated
    linearly between the vertices' (the mean of their two segments'), so they turn smoothly
    along the path rather than jump at each vertex."""
    d = np.diff(poly_mm, axis=0)
    length = np.sqrt(np.einsum("ij,ij->i", d, d))
    unit = d / np.where(length > 0.0, length, 1.0)[:, None]
    t_v = np.concatenate([unit[:1], unit[:-1] + unit[1:], unit[-1:]])
    t_v /= np.maximum(np.sqrt(np.einsum("ij,ij->i", t_v, t_v)), 1e-300)[:, None]
    s_v = np.concatenate([[0.0], np.cumsum(length)])

    def at(sigma):
        i = np.clip(np.searchsorted(s_v, sigma, side="right") - 1, 0, length.size - 1)
        f = np.clip((sigma - s_v[i]) / np.where(length[i] > 0.0, length[i], 1.0), 0.0, 1.0)
        point = poly_mm[i] + f[:, None] * d[i]
        t = (1.0 - f)[:, None] * t_v[i] + f[:, None] * t_v[i + 1]
        t /= np.maximum(np.sqrt(np.einsum("ij,ij->i", t, t)), 1e-300)[:, None]
        return point, t, _plane_normal(t)

    return s_v, at


def _path_coordinates(u_mm: np.ndarray, poly_mm: np.ndarray):
    """Each point's place against the path: arc length σ of its nearest point on the
    polyline, the frame function of :func:`_frame`, the unit tangent and XY normal there,
    its offset μ along that normal [mm] and the rest of its offset (out of the plane)."""
    foot, _, _ = nearest_on_polyline(u_mm, poly_mm)
    seg = nearest_on_polyline.segment
    s_v, at = _frame(poly_mm)
    sigma = s_v[seg] + np.sqrt(np.sum((foot - poly_mm[seg]) ** 2, axis=1))
    point, t, m = at(sigma)
    off = u_mm - point
    mu = np.einsum("ij,ij->i", off, m)
    return sigma, at, t, m, mu, off - mu[:, None] * m


def _into_tube(u_mm: np.ndarray, poly_mm: np.ndarray, tube_mm: np.ndarray) -> np.ndarray:
    """``u_mm`` projected into the ball of radius ``tube_mm`` about its nearest path point
    (the exact tube: its distance to ``poly_mm`` is then at most the tube)."""
    foot, dist, _ = nearest_on_polyline(u_mm, poly_mm)
    scale = np.minimum(1.0, tube_mm / np.where(dist > 0.0, dist, 1.0))
    return foot + (u_mm - foot) * scale[:, None]


def _regions(over: np.ndarray, before: int, reach: int, lo: int, hi: int,
             longest: int) -> list[tuple[int, int, int]]:  # fmt: skip
    """Windows (j0, j1, k1) over the tool samples ``over`` (sorted): reference samples
    j0 … j1−1 move (from ``before`` ahead of a run of over-limit samples to its end, within
    [lo, hi)), tool samples j0 … k1−1 are constrained (``reach`` past j1). Runs whose windows
    would overlap are merged; a window moves at most ``longest`` samples."""
    if over.size == 0:
        return []
    cuts = np.flatnonzero(np.diff(over) > before + reach) + 1
    out = []
    for run in np.split(over, cuts):
        a, b = max(int(run[0]) - before, lo), min(int(run[-1]) + 1, hi)
        for j0 in range(a, b, longest):
            j1 = min(j0 + longest, b)
            out.append((j0, j1, j1 + reach))
    return out


def _difference_rows(u: np.ndarray, j0: int, j1: int, order: int) -> tuple:
    """The ``order``-th differences of a step Δ that is zero outside samples j0 … j1−1, on
    every row they touch (r = j0 − 1 … j1 − 2 + order, Δ_r − … centred as np.diff): the
    matrix D (rows, j1 − j0) with D·Δ[j0:j1] those differences, and the same differences
    of ``u`` (rows, 3) on those rows (edge samples repeated past the ends)."""
    n_in = j1 - j0
    coef = np.diff(np.eye(order + 1), n=order, axis=0)[0]  # e.g. [1, −2, 1]
    rows = n_in + order
    d = np.zeros((rows, n_in))
    for i, c in enumerate(coef):  # row r covers Δ_{j0 − order + r + i}
        cols = np.arange(rows) - order + i
        ok = (cols >= 0) & (cols < n_in)
        d[np.flatnonzero(ok), cols[ok]] = c
    idx = np.clip(np.arange(j0 - order, j1 + order), 0, u.shape[0] - 1)
    du = np.diff(u[idx], n=order, axis=0)  # rows j0 − order … j1 + order − 1 − order
    return d, du[:rows]


def _region_step(u: np.ndarray, y: np.ndarray, cut_out: np.ndarray, movable: np.ndarray,
                 window: tuple[int, int, int], h: np.ndarray, poly: np.ndarray,
                 tube: np.ndarray, caps: SampleLimits, kappa: np.ndarray,
                 ) -> np.ndarray | None:  # fmt: skip
    """The LP step of one ``window`` (j0, j1, k1) (module comment above): (j1 − j0, 3) [mm],
    the move Δ_j = a_j m_j + b_j t_j of each sample across (in-plane normal m) and along
    (tangent t) the path, or None. ``caps`` (:class:`SampleLimits`): the reference's
    steps (their length, to first order, REFINE_SPEED of the cap) and its first, second
    and third differences on every axis stay within the caps less LIMIT_MARGIN (or within
    ``u``'s own, where it was above them already: Δ = 0 is always a solution), so the step
    never makes the reference faster or rougher than the machine's velocity, acceleration
    and jerk (the differences exactly: Δ is applied as it is here, a straight move).
    ``kappa`` (N,) [1/mm] the path's curvature at each sample (the bend of a move along
    it)."""
    from scipy.optimize import linprog

    j0, j1, k1 = window
    k1 = min(k1, y.shape[0])
    ks = np.arange(j0, k1)
    ks = ks[cut_out[ks]]
    if ks.size == 0:
        return None
    q, sigma, tan_out = nearest_on_polyline(y[ks], poly)
    nu = (y[ks] - q) / np.where(sigma > 1e-9, sigma, 1.0)[:, None]
    nu = np.where(sigma[:, None] > 1e-9, nu, _plane_normal(tan_out))
    _sigma, _at, tan_in, m, mu, rest = _path_coordinates(u[j0:j1], poly)
    room = np.sqrt(np.maximum(tube[j0:j1] ** 2 - np.einsum("ij,ij->i", rest, rest), 0.0))
    room *= 1.0 - 1e-6
    fixed = ~movable[j0:j1]
    # The step is applied as the LP sees it, a straight move Δ = a m + b t (so its second
    # and third differences are exactly the LP's); a move b along the tangent of a curve of
    # curvature κ leaves the curve outward by up to κ b²/2, so b is bounded to keep that
    # bend within REFINE_BEND of the tube, and the room across is reduced by it outward.
    k = np.abs(np.nan_to_num(kappa[j0:j1], nan=0.0, posinf=0.0))
    with np.errstate(divide="ignore"):
        b_max = np.minimum(REFINE_ALONG_MM, np.sqrt(2.0 * REFINE_BEND * tube[j0:j1] / k))
    bend = 0.5 * k * b_max**2
    # (never forced to move: the current point is in the tube, so a = 0 stays allowed and
    # the LP always has a solution)
    lo_a = np.where(fixed, 0.0, np.minimum(-room - mu, 0.0))
    hi_a = np.where(fixed, 0.0, np.maximum(room - bend - mu, 0.0))
    along = np.where(fixed, 0.0, b_max)
    # Unknowns x = (a, b, z): Δ_j = a_j m_j + b_j t_j across and along the path.
    basis = np.concatenate([m, tan_in])  # (2J, 3): the direction of each unknown
    lag = ks[:, None] - np.arange(j0, j1)[None, :]  # k − j
    valid = (lag >= 0) & (lag < h.shape[0])
    hk = h[np.clip(lag, 0, h.shape[0] - 1)] * valid[..., None]  # (K, J, 3)
    g = np.hstack([np.einsum("kc,kjc,jc->kj", nu, hk, m),
                   np.einsum("kc,kjc,jc->kj", nu, hk, tan_in)])  # fmt: skip
    ones = -np.ones((ks.size, 1))
    a_ub = [np.hstack([g, ones]), np.hstack([-g, ones])]
    b_ub = [-sigma, sigma]
    n_x = 2 * (j1 - j0)
    # The speed: a move b along the path lengthens the step between samples j and j + 1 by
    # b_{j+1} − b_j (to first order; a move across it, orthogonal, by its square), so that
    # difference stays within what the step's cap leaves (REFINE_SPEED of it: the square).
    d, du = _difference_rows(u, j0, j1, 1)
    step = np.sqrt(np.einsum("ij,ij->i", du, du))
    at = np.clip(np.arange(j0 - 1, j1), 0, caps.step.size - 1)  # the rows' np.diff index
    a_ub.append(np.hstack([np.zeros_like(d), d, np.zeros((d.shape[0], 1))]))
    b_ub.append(np.maximum(REFINE_SPEED * caps.lp_step()[at] - step, 0.0))
    for order in (1, 2, 3):
        d, du = _difference_rows(u, j0, j1, order)
        limit = caps.lp_rows(order)
        at = np.clip(np.arange(j0 - order, j1), 0, limit.shape[0] - 1)
        for c in range(3):
            finite = np.isfinite(limit[at, c])
            if not np.any(basis[:, c]) or not finite.any():
                continue
            rows = np.hstack([d * basis[: j1 - j0, c], d * basis[j1 - j0 :, c]])[finite]
            # (within the cap, or the current reference's own where it is above it)
            cap = np.maximum(limit[at, c], np.abs(du[:, c]))[finite]
            du_c = du[finite, c]
            zero = np.zeros((rows.shape[0], 1))
            a_ub += [np.hstack([rows, zero]), np.hstack([-rows, zero])]
            b_ub += [cap - du_c, cap + du_c]
    bounds = np.column_stack([np.concatenate([lo_a, -along, [0.0]]),
                              np.concatenate([hi_a, along, [np.inf]])])  # fmt: skip
    cost = np.zeros(n_x + 1)
    cost[-1] = 1.0
    res = linprog(cost, A_ub=np.vstack(a_ub), b_ub=np.concatenate(b_ub), bounds=bounds,
                  method="highs", options={"time_limit": REFINE_LP_TIME_S})  # fmt: skip
    if res.status != 0:
        return None
    ab = res.x[:n_x].reshape(2, j1 - j0)
    return ab[0][:, None] * m + ab[1][:, None] * tan_in  # (J, 3): Δ = a m + b t


def _rougher(new_mm: np.ndarray, start_mm: np.ndarray, caps: SampleLimits, lo: int = 0,
             hi: int | None = None) -> np.ndarray:  # fmt: skip
    """Per sample lo … hi−1: whether a difference row of ``new_mm`` within that range that it
    is in (its step length, its first, second and third differences on every axis) exceeds
    its cap of ``caps``, or ``start_mm``'s own where that was above the cap already (the
    reference the optimisation started from, so no allowance adds up over the rounds),
    beyond rounding (1e-9 of the cap, 2^k ulps of the coordinates)."""
    hi = new_mm.shape[0] if hi is None else hi
    new, old = new_mm[lo:hi], start_mm[lo:hi]
    out = np.zeros(hi - lo, dtype=bool)
    if hi - lo < 2:
        return out
    ulp = float(np.spacing(np.abs(new).max()))
    dn, do = np.diff(new, axis=0), np.diff(old, axis=0)
    step_n, step_o = (np.sqrt(np.einsum("ij,ij->i", d, d)) for d in (dn, do))
    rows = [(step_n > np.maximum(caps.step[lo : hi - 1], step_o) * (1.0 + 1e-9) + 2.0 * ulp, 1)]
    for k in (1, 2, 3):
        if hi - lo <= k:
            break
        dn, do = np.abs(np.diff(new, k, axis=0)), np.abs(np.diff(old, k, axis=0))
        cap = np.maximum(caps.rows(k)[lo : hi - k], do) * (1.0 + 1e-9) + 2.0**k * ulp
        rows.append((np.any(dn > cap, axis=1), k))
    for over, k in rows:
        for lag in range(k + 1):  # row i covers samples i … i + k
            out[lag : lag + over.size] |= over
    return out


def _no_rougher(new_mm: np.ndarray, start_mm: np.ndarray, j0: int, j1: int,
                caps: SampleLimits) -> bool:  # fmt: skip
    """Whether every difference row about samples j0 … j1−1 of ``new_mm`` keeps its cap
    (:func:`_rougher`)."""
    lo, hi = max(j0 - 3, 0), min(j1 + 3, new_mm.shape[0])
    return not _rougher(new_mm, start_mm, caps, lo, hi).any()


def refine_in_tube(ref: Reference, pieces, profile, machine: Machine, tube_mm: np.ndarray,
                   rounds: int = REFINE_ROUNDS, gain_mm: float = REFINE_GAIN_MM,
                   caps: SampleLimits | None = None, held: int = 1) -> Refinement:  # fmt: skip
    """The reference ``ref`` (its points within ``tube_mm`` (N,) of the path) with its
    offsets across the path re-chosen where the simulated contour error exceeds
    REFINE_THRESHOLD × ε_max, to minimise the largest error there (module comment above:
    sequential LPs on the known model, each round kept only where it lowers the error).
    Samples at rest, on rapids, the first and the last ``held`` samples do not move. ``caps``
    (:class:`SampleLimits`, default the machine's limits alone) bound the differences of
    the reference (:func:`_region_step`): a reference within them stays within them, one
    above them never gets rougher where it is (:func:`_rougher`)."""
    from scipy import signal

    from nurbscnc.servo.model import discretise

    eps = machine.limits.contour_tolerance_mm
    u = np.array(ref.points_mm, dtype=float)
    n = u.shape[0]
    cut = ~pieces.rapid[ref.piece]
    speed = np.zeros(n)
    if n > 2:
        speed[1:-1] = np.sqrt(np.sum((u[2:] - u[:-2]) ** 2, axis=1))
    movable = cut & (speed > 1e-9)
    movable[0] = False
    movable[n - held :] = False
    index = PathIndex(pieces)
    reach = _reach_samples(machine)
    h = _impulse_responses(machine, reach)
    period = machine.servo.period_s
    before = max(int(round(REFINE_BEFORE_S / period)), 1)
    if caps is None:
        caps = sample_limits(np.zeros_like(u), machine)
    # The path's curvature at each sample (its piece's largest) [1/mm]: the bend bound.
    kappa = np.asarray(pieces.kappa_max_per_mm, dtype=float)[ref.piece]

    # The check's simulation (path_response: each axis from rest at its first point, the
    # last point held until settled, the true distance near the reference and to the whole
    # path above the threshold), its discretisation made once and the settle length of the
    # first reference kept: the same numbers at a fraction of the cost per round.
    first = path_response(ref, pieces, profile, machine, index=index)
    extra = first.actual_mm.shape[0] - n
    discs = [None if m is None else discretise(m, period, "foh") for m in _models(machine)]
    s_out = np.concatenate((ref.s_mm, np.full(extra, ref.s_mm[-1])))
    cut_out = np.append(cut, np.full(extra, cut[-1]))

    # The last response's tool samples and their distances: a try moves the reference in a
    # few regions, so most tool samples are where they were (bit for bit before the first
    # moved input; within 1e-12 mm after the servo's tail has died out) and keep their
    # distance (the distance to a set is 1-Lipschitz: off by at most that much). The global
    # query was 27 s of a 60 s profile of tort.ngc's tube rounds.
    last = {}

    def response(points):
        held = np.vstack([points, np.repeat(points[-1:], extra, axis=0)])
        actual = held.copy()
        for c, d in enumerate(discs):
            if d is not None:
                x = held[:, c] - points[0, c]
                actual[:, c] = signal.lfilter(d.b, d.a, x) + d.dc_gain * points[0, c]
        lag = np.sqrt(np.sum((held - actual) ** 2, axis=1))
        contour = windowed_contour_mm(actual, lag, s_out, pieces, profile)
        sel = np.flatnonzero(contour > REFINE_THRESHOLD * eps)
        if sel.size:
            kept = np.zeros(sel.size, dtype=bool)
            if last:  # measured last time (over the threshold then) at the same place
                kept = last["over"][sel] & np.all(
                    np.abs(actual[sel] - last["actual"][sel]) <= REUSE_MM, axis=1)
                same = sel[kept]
                contour[same] = np.minimum(contour[same], last["contour"][same])
            fresh = sel[~kept]
            if fresh.size:
                contour[fresh] = index.distance_mm(actual[fresh], contour[fresh])
        over = np.zeros(contour.size, dtype=bool)
        over[sel] = True
        last.update(actual=actual, contour=contour.copy(), over=over)
        return actual, np.where(cut_out, contour, 0.0), cut_out

    start = u.copy()
    y, err, cut_out = response(u)
    history = [float(err.max())]
    windows: list = []
    for _ in range(rounds):
        over = np.flatnonzero(err > REFINE_THRESHOLD * eps)
        windows = _regions(over, before, reach, 1, n - 1, REFINE_MAX_INPUTS)
        steps = []
        for j0, j1, k1 in windows:
            # The path under the window's reference and tool samples (the tool within 2|u − y|
            # of its reference along the path, as windowed_contour_mm).
            s_in = ref.s_mm[j0 : min(k1, n)]
            margin = 2.0 * float(np.max(np.abs(u[j0:min(k1, n)] - y[j0:min(k1, n)]))) + 0.05
            poly = _local_polyline(pieces, profile, float(s_in.min()) - margin,
                                   float(s_in.max()) + margin)  # fmt: skip
            step = _region_step(u, y, cut_out, movable, (j0, j1, k1), h, poly, tube_mm,
                                caps, kappa)  # fmt: skip
            steps.append((j0, j1, k1, step, poly))
        steps = [s for s in steps if s[3] is not None]
        if not steps:
            break
        # Each window kept where its own largest error went down and the reference is no
        # rougher there (full step, else half, else a quarter); the windows' tool samples
        # are disjoint, their effects add.
        alpha = np.ones(len(steps))
        done = np.zeros(len(steps), dtype=bool)
        base = u.copy()
        for _attempt in range(3):
            trial = base.copy()
            for i, (j0, j1, _k1, step, poly) in enumerate(steps):
                if done[i]:
                    continue
                moved = base[j0:j1] + alpha[i] * step
                moved = _into_tube(moved, poly, tube_mm[j0:j1])  # (to rounding: a no-op)
                trial[j0:j1] = np.where(movable[j0:j1, None], moved, base[j0:j1])
            y_t, err_t, _ = response(trial)
            for i, (j0, _j1, k1, _step, _poly) in enumerate(steps):
                if done[i]:
                    continue
                k1 = min(k1, err.size)
                if (float(err_t[j0:k1].max()) < float(err[j0:k1].max()) - 1e-9
                        and _no_rougher(trial, start, j0, _j1, caps)):
                    done[i] = True
                    base[j0:_j1] = trial[j0:_j1]
                else:
                    alpha[i] *= 0.5
            if done.all():
                break
        # Windows next to each other were each checked with the other's step in: one whose
        # neighbour was then not kept is taken back where a row across them breaks a cap.
        for _undo in range(len(steps)):
            bad = _rougher(base, start, caps)
            hit = [i for i, (j0, j1, *_rest) in enumerate(steps)
                   if done[i] and bad[max(j0 - 3, 0) : j1 + 3].any()]  # fmt: skip
            if not hit:
                break
            for i in hit:
                j0, j1 = steps[i][:2]
                base[j0:j1] = u[j0:j1]
                done[i] = False
        if not done.any():
            history.append(history[-1])
            break
        y_t, err_t, _ = response(base)
        if float(err_t.max()) > history[-1]:  # a window's tail raised another's: keep none
            history.append(history[-1])
            break
        u, y, err = base, y_t, err_t
        history.append(float(err.max()))
        if history[-2] - history[-1] < gain_mm:
            break
    return Refinement(u, tuple(history), len(windows))
