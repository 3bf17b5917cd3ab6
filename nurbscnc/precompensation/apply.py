"""Applying the ZPETC pre-compensation to a plan's reference: each cut window's samples
compensated as a program of its own (the inverse, kept within the tube about the path,
projected onto the machine's limits, optimised in the tube), the segments joined within the
limits, and the wrapping reference sampler the planner's dynamics check simulates
(:func:`precompensated_sampler`). The inverse itself is :mod:`nurbscnc.servo.precompensate`
(on points); the compensated reference keeps the machine's velocity, acceleration and jerk
on its samples (:func:`~nurbscnc.precompensation.limits.project_onto_limits`, then
:func:`~nurbscnc.precompensation.tube.refine_in_tube` within the same caps)."""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from dataclasses import dataclass, fields, replace

import numpy as np

from nurbscnc.geometry.nurbs import NurbsCurve
from nurbscnc.geometry.path import Kind
from nurbscnc.geometry.polyline import CHORD_MM
from nurbscnc.machine.profile import Machine
from nurbscnc.plan.timing import Reference, joined_rows, rows_of
from nurbscnc.precompensation.limits import (
    PROJECT_MAX_WINDOW,
    limit_excess,
    path_frame,
    project_onto_limits,
    project_window,
    sample_limits,
)
from nurbscnc.precompensation.tube import refine_in_tube
from nurbscnc.servo.model import contour_error_true
from nurbscnc.servo.precompensate import (
    REFERENCE_TOLERANCE_MM,
    Compensated,
    along_path_offset_mm,
    axis_models,
    lead_samples,
    limit_to_path,
    precompensate_points,
)


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


#: Spacing of the programmed curve's points where the reference tolerance is measured
#: against it (:func:`_fit_margin_mm`) [mm]; the sagitta of the chords is added.
_CURVE_SPACING_MM = 1e-3


def _fit_margin_mm(
    pieces, piece: np.ndarray, foot_mm: np.ndarray, fit_tolerance_mm: float
) -> np.ndarray:
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
    breaks = np.flatnonzero(
        (np.diff(rows) != 1) | (pieces.segment[rows[1:]] != pieces.segment[rows[:-1]])
    )
    for group in np.split(rows, breaks + 1):
        sel = np.flatnonzero((piece >= group[0]) & (piece <= group[-1]))
        if not sel.size:
            continue
        lo, hi = pieces.objects.get(group[0] - 1), pieces.objects.get(group[-1] + 1)
        seg = pieces.segment[group[0]]
        lo = lo if group[0] > 0 and pieces.segment[group[0] - 1] == seg else None
        hi = hi if group[-1] + 1 < len(pieces) and pieces.segment[group[-1] + 1] == seg else None
        curve = next(
            (o[0] for o in (lo, hi) if o is not None and isinstance(o[0], NurbsCurve)), None
        )
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


def reference_tube_mm(
    pieces, piece: np.ndarray, foot_mm: np.ndarray, tolerance_mm: float, fit_tolerance_mm: float
) -> np.ndarray:
    """The reference tolerance about each foot [mm] (M,): ``tolerance_mm`` less the foot's
    own distance from the programmed path (:func:`_fit_margin_mm`), so that the reference
    is within ``tolerance_mm`` of the *programmed* path (the triangle inequality)."""
    margin = _fit_margin_mm(pieces, piece, foot_mm, fit_tolerance_mm)
    return np.maximum(tolerance_mm - margin, 0.0)


def _edge(x: np.ndarray, pad: tuple[int, int]) -> np.ndarray:
    """A per-sample column ``x`` (N,) or (N, k) padded by ``pad`` (before, after) samples,
    its end samples repeated."""
    return np.pad(x, pad, mode="edge") if x.ndim == 1 else np.pad(x, (pad, (0, 0)), "edge")


def _segment_inverse(ref: Reference, machine: Machine, first: bool) -> Compensated:
    """The ZPETC inverse of a segment's planned points (SPEC eq. 25 inverted,
    :func:`~nurbscnc.servo.precompensate.precompensate_points`; F's tail blended in within
    the machine's acceleration and jerk, so it ends with the plan); a segment after the
    ``first`` without its pre-actuation."""
    period = machine.servo.period_s
    lim = machine.limits
    comp = precompensate_points(
        axis_models(machine),
        ref.points_mm,
        period,
        a_max_mm_s2=lim.a_max_mm_s2,
        j_max_mm_s3=lim.j_max_mm_s3,
    )
    if not first:
        # A later segment starts at rest at the end of the cut before it, with a rapid: its
        # samples keep their wall times (no delay), so the pre-actuation of the rapid's start
        # (the held samples) is dropped and its first sample is the planned one.
        u = comp.points_mm[comp.lead_samples :].copy()
        u[0] = ref.points_mm[0]
        comp = replace(comp, points_mm=u, lead_samples=0)
    return comp


def _clip_into_tube(
    points: np.ndarray,
    planned: np.ndarray,
    s_mm: np.ndarray,
    pieces,
    profile,
    machine: Machine,
    tolerance_mm: float,
    fit_tolerance_mm: float | None,
    optimise: bool,
):
    """The compensated ``points`` (N, 3) [mm] (their planned points ``planned`` at path
    lengths ``s_mm``) each projected onto the ball of radius ``tolerance_mm`` (less the
    foot's own distance from the programmed curve, :func:`reference_tube_mm`) about the path
    point its lead ahead of the planned point (:func:`_s_along`, clamped to the program's
    ends; :func:`~nurbscnc.servo.precompensate.limit_to_path`). Returns the points, the path
    length of each one's foot, the tube (N,) [mm] and, to ``optimise`` in the tube, the
    optimiser's tube (else None)."""
    s_foot = _s_along(points, planned, s_mm, profile)
    starts = profile.piece_start_mm
    piece = np.clip(np.searchsorted(starts, s_foot, side="right") - 1, 0, starts.size - 1)
    foot = pieces.path.place(
        starts, np.minimum(s_foot, starts[piece] + pieces.length_mm[piece]), piece
    )[0]
    fit = machine.limits.ph_tolerance_mm if fit_tolerance_mm is None else fit_tolerance_mm
    tube = reference_tube_mm(pieces, piece, foot, tolerance_mm, fit)
    tube_in = None
    if optimise:
        # The optimisation measures the tube on polylines of the path (chords ≤ 10 nm
        # inside the curve, dynamics.CHORD_MM): its tube is the smallest of each
        # sample's neighbours' (the foot moves along the path) less twice that, and
        # the clip a chord error more, so the clipped points start inside it.
        near = np.lib.stride_tricks.sliding_window_view(np.pad(tube, 4, mode="edge"), 9)
        tube_in = np.maximum(near.min(axis=1) - 2.0 * CHORD_MM, 0.0)
        tube = np.maximum(tube_in - CHORD_MM, 0.0)
    return limit_to_path(points, foot, tube), s_foot, tube, tube_in


def _projection_frame(
    planned: np.ndarray,
    clipped: np.ndarray,
    s_mm: np.ndarray,
    piece: np.ndarray,
    pieces,
    profile,
    tube,
):
    """The frame of the projection onto the limits: in the tube about the plan's points
    (:func:`~nurbscnc.precompensation.limits.path_frame`, the wanted offsets ``clipped`` −
    ``planned``), or (``tube`` None: no tolerance) anywhere, a frame of the axes. Basis
    (N, D, 3), lower and upper (N, D) [mm]."""
    if tube is not None:
        return path_frame(planned, s_mm, piece, pieces, profile, clipped - planned, tube)
    basis = np.broadcast_to(np.eye(3), (clipped.shape[0], 3, 3))
    lower = np.full((clipped.shape[0], 3), -np.inf)
    upper = -lower
    return basis, lower, upper


def _compensate_segment(
    ref: Reference,
    pieces,
    profile,
    machine: Machine,
    tolerance_mm: float,
    fit_tolerance_mm: float | None,
    refine: bool,
    first: bool,
    last: bool = True,
) -> tuple[Reference, Compensated]:
    """One segment of :func:`precompensate_reference` (a cut window's samples, or the whole
    reference), compensated as a program of its own (``first``: the program's first, delayed
    by the pre-actuation; else its first sample the planned one, no delay; not ``last``: a
    segment followed by another, its last JOIN_HELD samples the planned ones, so the joint
    always has a solution, :func:`_join_segments`): the ZPETC pre-compensated version of a
    plan's reference (:func:`_segment_inverse`), kept within ``tolerance_mm`` of the path
    (inf: no limit; :func:`_clip_into_tube`: the tube less the foot's own distance from the
    programmed curve on PH corner pieces of a NURBS, the fit tolerance ``fit_tolerance_mm``,
    default the profile's e, where that is not known), then projected onto the machine's
    limits on the samples (:func:`~nurbscnc.precompensation.limits.project_onto_limits`:
    V, A, J per axis and the path speed by finite differences, or the plan's own where that
    is above them, in the tube about the plan's points; with no tolerance, anywhere) and,
    with a contour check, optimised in the tube within the same caps
    (:func:`~nurbscnc.precompensation.tube.refine_in_tube`). Every other per-sample column
    is padded to the new length (the start repeated ``lead_samples`` times), so the
    dynamics check maps each sample to its piece and path length as before. Wall times
    restart at 0 with the servo period."""
    period = machine.servo.period_s
    comp = _segment_inverse(ref, machine, first)
    pad = (comp.lead_samples, 0)
    points = comp.points_mm
    s_mm = _edge(ref.s_mm, pad)
    planned = _edge(ref.points_mm, pad)
    finite = bool(np.isfinite(tolerance_mm))
    optimise = finite and refine and machine.contour_check
    tube = tube_in = s_foot = None
    if finite:
        points, s_foot, tube, tube_in = _clip_into_tube(
            points,
            planned,
            s_mm,
            pieces,
            profile,
            machine,
            tolerance_mm,
            fit_tolerance_mm,
            optimise,
        )
    held = 1 if last else JOIN_HELD
    if not last:
        # A segment followed by another ends on the plan's own last samples: the joint's
        # rows (the next segment's first samples after these) are then solved by the plan's
        # own next samples at worst (:func:`_join_segments`).
        points = points.copy()
        points[-held:] = ref.points_mm[-held:]
    clipped = points
    # The limits on the samples (module comment of limits.py): the clipped ZPETC
    # reference projected onto them.
    caps = sample_limits(planned, machine)
    basis, lower, upper = _projection_frame(
        planned, clipped, s_mm, _edge(ref.piece, pad), pieces, profile, tube
    )
    points = project_onto_limits(clipped, planned, caps, basis, lower, upper, held=held)
    comp = replace(comp, points_mm=points)
    n_in, n = ref.points_mm.shape[0], points.shape[0]
    # Every per-sample column padded alike (whatever columns the Reference has).
    columns = {
        f.name: _edge(getattr(ref, f.name), pad)
        for f in fields(ref)
        if isinstance(getattr(ref, f.name), np.ndarray)
        and getattr(ref, f.name).shape[:1] == (n_in,)
    }
    columns.update(t_s=np.arange(n) * period, points_mm=points)
    if finite:
        # Each sample's path length where its point is (the planned one's plus the lead
        # along the path), so a distance measured near it (windowed_contour_mm) looks at the
        # stretch of path the point is at.
        columns["s_mm"] = s_foot
    out = replace(ref, **columns)
    if optimise:
        done = refine_in_tube(out, pieces, profile, machine, tube_in, caps=caps, held=held)
        out = replace(out, points_mm=done.points_mm)
        out = replace(out, s_mm=_s_along(done.points_mm, planned, s_mm, profile))
        comp = Refined(
            done.points_mm,
            comp.lead_samples,
            comp.end_step_mm,
            comp.end_blend_samples,
            done.history_mm,
            clipped,
            points,
        )
    return out, comp


def _s_along(
    points_mm: np.ndarray, planned_mm: np.ndarray, s_planned_mm: np.ndarray, profile
) -> np.ndarray:
    """The path length [mm] at which each point of ``points_mm`` is: its planned point's
    plus its lead along the path (:func:`~nurbscnc.servo.precompensate.along_path_offset_mm`),
    within the program."""
    lead = along_path_offset_mm(points_mm, planned_mm)
    return np.clip(s_planned_mm + lead, 0.0, profile.total_length_mm)


# --------------------------------------------------------------------------- cut-window segments
#
# Long programs: the planner checks a program cut window by cut window
# (lookahead.plan_windows), every re-plan of window w with the windows before it final and
# the ones after it placeholders. A whole-reference sampler would make each of those checks
# compensate, project and optimise the whole program: O(re-plans × program). Here the
# compensated reference is made of *segments*, one per cut window's samples
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

    starts = [
        first_sample_at(pieces, profile, int(a), period_s) for a in cut_windows(pieces)[1:].tolist()
    ]
    ks = [0]
    for k in starts:  # a segment shorter than MIN_SEGMENT joins the one before it
        if k - ks[-1] >= MIN_SEGMENT and n - k >= MIN_SEGMENT:
            ks.append(int(k))
    return np.asarray([*ks, n], dtype=np.int64)


def _key(
    ref: Reference, machine: Machine, pieces, options: tuple, first: bool, last: bool
) -> tuple:
    """The cache key of a segment: what its compensation depends on (its planned samples'
    columns, bit for bit; the machine, path and options by identity, the entry holding
    them so an identity is never reused while it is kept)."""
    h = hashlib.blake2b(digest_size=20)
    for f in fields(ref):
        if getattr(ref, f.name) is None:
            continue
        x = np.ascontiguousarray(getattr(ref, f.name))
        h.update(str(x.dtype).encode() + str(x.shape).encode())
        h.update(x.tobytes())
    return (id(machine), id(pieces.path), options, first, last, h.hexdigest())


def _segment(
    ref: Reference, pieces, profile, machine: Machine, options: tuple, first: bool, last: bool
) -> tuple[Reference, Compensated]:
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


def _join_segments(
    prev_tail_mm: np.ndarray,
    prev_planned_mm: np.ndarray,
    seg: Reference,
    planned: Reference,
    pieces,
    profile,
    machine: Machine,
    tolerance_mm: float,
    fit_tolerance_mm: float | None,
) -> Reference:
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
    tube = s_plan = piece = None
    if np.isfinite(tolerance_mm):
        fit = machine.limits.ph_tolerance_mm if fit_tolerance_mm is None else fit_tolerance_mm
        starts = profile.piece_start_mm
        piece = np.concatenate([np.full(m, planned.piece[0]), planned.piece[: size - m]])
        s_plan = np.concatenate([np.full(m, planned.s_mm[0]), planned.s_mm[: size - m]])
        foot = pieces.path.place(starts, s_plan, piece)[0]
        tube = reference_tube_mm(pieces, piece, foot, tolerance_mm, fit)
    basis, lower, upper = _projection_frame(r, u, s_plan, piece, pieces, profile, tube)
    last = u.shape[0] - 3
    pad = JOIN_PAD
    while True:
        j1 = min(m + pad, last)
        if j1 <= m or j1 - m > PROJECT_MAX_WINDOW:
            break
        moved = project_window(u, r, u, caps, basis, lower, upper, m, j1)
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


def _compensated_rows(
    ref_of, pieces, profile, machine: Machine, options: tuple, n: int, lo: int, hi: int
) -> tuple[Reference, list]:
    """Rows lo … hi − 1 of the compensated reference of a plan of ``n`` planned samples
    (cut-window segments, module comment above; row k + lead ↔ planned sample k, lead the
    pre-actuation at the program's start,
    :func:`~nurbscnc.servo.precompensate.lead_samples`): the segments covering them
    (:func:`_segment`), each after the first joined to the one before it
    (:func:`_join_segments`: its last three samples, which no join moves).
    ``ref_of(k0, k1)`` gives the planned samples k0 … k1 − 1. Returns the rows and the
    segments' :class:`Compensated` records."""
    period = machine.servo.period_s
    ks = _segment_starts(pieces, profile, period, n)
    lead = lead_samples(machine)
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
        seg, comp = _segment(planned, pieces, profile, machine, options, i == 0, i == ks.size - 2)
        if i > 0:
            # The segment before ends on its plan's last JOIN_HELD samples: those are its
            # tail (it need not be made; the planner's re-plans of a later window splice a
            # compacted profile before it, whose samples are the final plan's only there).
            tail = ref_of(int(ks[i]) - JOIN_HELD, int(ks[i])).points_mm
            key = (id(seg), tail.tobytes())  # (seg is held by _SEGMENTS while it is kept)
            joined = _JOINED.get(key)
            if joined is None or joined[0] is not seg:
                joined = (
                    seg,
                    _join_segments(
                        tail, tail, seg, planned, pieces, profile, machine, *options[:2]
                    ),
                )
                _JOINED[key] = joined
                while len(_JOINED) > JOINED_KEPT:
                    _JOINED.popitem(last=False)
            seg = joined[1]
        parts.append(rows_of(seg, slice(max(lo - a, 0), min(hi, int(end[i])) - a)))
        comps.append(comp)
    out = joined_rows(parts)
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
        return Compensated(points_mm, first.lead_samples, last.end_step_mm, last.end_blend_samples)
    rounds = max(len(c.history_mm) for c in comps)
    history = np.max(
        [
            np.pad(np.asarray(c.history_mm), (0, rounds - len(c.history_mm)), mode="edge")
            for c in comps
        ],
        axis=0,
    )
    return Refined(
        points_mm,
        first.lead_samples,
        last.end_step_mm,
        last.end_blend_samples,
        tuple(float(h) for h in history),
        np.concatenate([c.clipped_mm for c in comps]),
        np.concatenate([c.projected_mm for c in comps]),
    )


def precompensate_reference(
    ref: Reference,
    pieces,
    profile,
    machine: Machine,
    tolerance_mm: float = REFERENCE_TOLERANCE_MM,
    fit_tolerance_mm: float | None = None,
    refine: bool = True,
) -> tuple[Reference, Compensated]:
    """The ZPETC pre-compensated version of a plan's reference ``ref`` (all its samples):
    one segment per cut window (module comment "cut-window segments"), each
    :func:`_compensate_segment` (the inverse, the tube of ``tolerance_mm`` [mm] about the
    path, the limits on the samples, the tube optimisation), joined within the limits; the
    first segment delayed by the inverse's pre-actuation (``lead_samples``), every
    per-sample column padded alike; wall times from 0 at the servo period. A program of one
    cut is one segment: what :func:`_compensate_segment` gives for it."""
    n = ref.t_s.size
    options = (tolerance_mm, fit_tolerance_mm, refine)
    out, comps = _compensated_rows(
        lambda a, b: rows_of(ref, slice(a, b)),
        pieces,
        profile,
        machine,
        options,
        n,
        0,
        n + lead_samples(machine),
    )
    return out, _joined_records(comps, out.points_mm)


def precompensated_sampler(
    sampler,
    machine: Machine,
    tolerance_mm: float = REFERENCE_TOLERANCE_MM,
    fit_tolerance_mm: float | None = None,
):
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
        hi = n + lead_samples(machine) if k1 is None else k1
        if windowed:

            def ref_of(a, b):
                return sampler(pieces, profile, period_s, a, b)
        else:
            whole = sampler(pieces, profile, period_s)

            def ref_of(a, b):
                return rows_of(whole, slice(a, b))

        return _compensated_rows(ref_of, pieces, profile, machine, options, n, k0, hi)[0]

    # Not causal: a segment's rows are inverted and optimised from all its planned samples.
    return FunctionSampler(sample, windowed, sampler.interpolator, causal=False)
