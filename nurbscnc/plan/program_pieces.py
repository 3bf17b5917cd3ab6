"""A whole program cut into pieces (:func:`segment_pieces`): lines in columns, arcs and
NURBS blocks as pieces, stops, then the corners decided."""

from __future__ import annotations

from dataclasses import dataclass
from dataclasses import replace as dc_replace

import numpy as np

from nurbscnc.geometry.path import STOP_KINDS, Kind, stop_seconds
from nurbscnc.machine.caps import junction_jump_cap_mm_s
from nurbscnc.machine.profile import Machine
from nurbscnc.plan.blend_choice import apply_blends
from nurbscnc.plan.corner_log import corner_log
from nurbscnc.plan.curved_pieces import object_pieces
from nurbscnc.plan.junctions import curvature_jumps, junction_turning, small_breaks
from nurbscnc.plan.moved_copies import Block, Repeats
from nurbscnc.plan.naive import merge_collinear
from nurbscnc.plan.options import PlanOptions
from nurbscnc.plan.pieces import SCALAR_COLUMNS, VECTOR_COLUMNS, PieceList, empty_columns
from nurbscnc.plan.rotary import (
    plan_holds,
    rate_changes,
    rotary_pieces,
    uses_rotary,
)
from nurbscnc.program.columns import LINE as LINE_CODE
from nurbscnc.program.columns import RAPID as RAPID_CODE
from nurbscnc.program.columns import segment_columns


def segment_pieces(
    segments,
    machine: Machine,
    options: PlanOptions | None = None,
    columns=None,
    rotary_axes: tuple | None = None,
) -> PieceList:
    """All pieces of a program, in order, as a :class:`PieceList`, with its corners decided
    (path-control modes, LinuxCNC 2.9's meaning) and logged in ``corners``.

    With ``options.smooth`` dense CAM polylines become splines first, on the programmed
    vertices (:func:`~nurbscnc.plan.smoothing.smooth_runs`); then runs of nearly collinear
    feed lines under G64 Q are merged (:func:`~nurbscnc.plan.naive.merge_collinear`); the
    ``segment`` column keeps the program's indices. Breaks small enough to pass at speed
    are marked ``pass_after`` (:func:`~nurbscnc.plan.junctions.small_breaks`, every mode but
    at G61.1 block ends); G61.1 stops at the end of every block (``stop_after``); G64
    corners are blended within their tolerance
    (:func:`~nurbscnc.plan.blend_choice.apply_blends`: P, or the machine's path tolerance
    without P or with P0); G61 stops at every other break
    (:func:`~nurbscnc.plan.junctions.junction_caps`);
    :func:`~nurbscnc.plan.corner_log.corner_log` records it all.

    Lines and rapids are gathered into columns in one pass (no object per line); arcs and
    NURBS blocks become pieces one segment at a time. Dwells and pauses (:data:`STOP_KINDS`)
    become ``stop_after`` and ``dwell_after_s`` (their ``seconds``, 0 for a pause) of the
    piece before (or of a zero-length marker when the program starts with a dwell); a rapid
    followed by a feed move stops exactly; the settle there (in-position wait) is set by
    the planner's contour check (:func:`~nurbscnc.plan.lookahead.plan_checked`), at most
    :func:`~nurbscnc.plan.junctions.settle_time_s`, so a rapid's stop overshoot never shows
    up as contour error.
    ``columns``: the segments' :class:`~nurbscnc.program.columns.SegmentColumns` if read
    already (used where smoothing and G64 Q left the segments as they were; their A B C
    columns always). ``rotary_axes``: the program's
    (:attr:`~nurbscnc.geometry.segments.Program.rotary_axes`; None: read off the segments).
    """
    options = options or PlanOptions()
    rotary = None
    # A B C: their columns, the rotary-only moves planned. (A machine without rotary axes
    # runs none: the interpreter refuses their words, so its programs are not read for them.)
    if machine.rotary_axes and uses_rotary(segments):
        own = columns if columns is not None else segment_columns(segments)
        rotary = (own, plan_holds(segments, machine, own), rotary_axes)
    # The turn-arounds' U choices, found by smoothing and asked again by the blends.
    turns: dict = {}
    segs, source, columns = _prepared_segments(segments, machine, options, columns, turns)
    n = len(segs)
    kinds = columns.names.tolist()
    straight = (columns.kind == LINE_CODE) | (columns.kind == RAPID_CODE)
    lines = _line_columns(columns, straight, machine, options)
    curved = np.fromiter((k in ("arc", "nurbs") for k in kinds), dtype=bool, count=n)
    blocks = _curved_blocks(segs, kinds, curved, machine, options)
    counts = np.zeros(n, dtype=np.int64)
    counts[lines.seg_line] = lines.keep
    for i in np.flatnonzero(curved).tolist():
        counts[i] = len(blocks[i].objects) if i in blocks else 0
    first_row = np.cumsum(counts) - counts
    k = int(counts.sum())
    cols = empty_columns(k)
    _put_lines(cols, first_row, lines)
    objects = _put_blocks(cols, first_row, blocks)
    hold_s = {} if rotary is None else _hold_seconds(segments, rotary[1])
    pending = _put_stops(cols, first_row, segs, kinds, ~(straight | curved), hold_s)
    marker = bool(k and pending)
    if marker:
        cols, objects = _with_dwell_marker(cols, objects, pending)
    elif not k and rotary is not None and rotary[1].segment.size:
        cols, marker = _rest_marker(segments, int(rotary[1].segment[0]), pending), True
    _mark_exact_stops(cols, source)
    if rotary is not None:
        rate_changes(cols, segments, (rotary[0].abc_start_deg, rotary[0].abc_end_deg))
    pieces = PieceList(**cols, objects=objects)
    pieces = _corners_decided(pieces, machine, options, segments, rotary, marker, turns)
    if options.smooth:
        from nurbscnc.plan.smoothing import smoothing_summary

        smoothed = smoothing_summary(segs)
        if smoothed is not None:
            pieces = dc_replace(pieces, smoothed=smoothed)
    return pieces


def _prepared_segments(segments, machine: Machine, options: PlanOptions, columns, turns=None):
    """The segments planned (smoothed runs as splines, G64 Q runs merged), the program's
    index of each and their :class:`~nurbscnc.program.columns.SegmentColumns` (``columns``
    when given and still theirs); ``turns``: the memo of smoothing's turn-around answers."""
    lim = machine.limits
    segs, source = list(segments), np.arange(len(segments))
    if options.smooth:  # dense CAM polylines as splines, on the programmed vertices
        from nurbscnc.plan.smoothing import smooth_runs

        reserve = options.tolerance_mm or lim.ph_tolerance_mm  # a PH corner inside a spline
        segs, source = smooth_runs(
            segs, source, machine, options.blend_tolerance_mm, reserve, turns
        )
    segs, merged = merge_collinear(segs)  # G64 Q, on the lines left
    source = source[merged]
    if columns is None or len(source) != len(columns.kind) or options.smooth:
        columns = segment_columns(segs)  # the program's own are for its segments, unchanged
    return segs, source, columns


@dataclass(frozen=True, eq=False)
class _Lines:
    """The line and rapid segments' columns (m,): ``seg_line`` their segment indices,
    ``p0``, ``p1`` (m, 3) end points [mm], ``diff`` p1 − p0, ``length`` [mm], ``rapid``,
    ``cap`` cruise cap [mm/s], ``cols`` (feed, source line, blend) and ``blend`` [mm]
    the blend tolerance, ``keep`` the ones of non-zero length."""

    seg_line: np.ndarray
    p0: np.ndarray
    p1: np.ndarray
    diff: np.ndarray
    length: np.ndarray
    rapid: np.ndarray
    cols: np.ndarray
    cap: np.ndarray
    blend: np.ndarray
    keep: np.ndarray


def _line_columns(columns, straight: np.ndarray, machine: Machine, options: PlanOptions) -> _Lines:
    """The lines' columns (millions in CAM programs): no tuple per line."""
    lim = machine.limits
    seg_line = np.flatnonzero(straight)
    m = seg_line.size
    p0, p1 = columns.starts_mm[seg_line], columns.ends_mm[seg_line]
    diff = p1 - p0
    l_len = np.sqrt(np.einsum("ij,ij->i", diff, diff))
    l_rapid = columns.kind[seg_line] == RAPID_CODE
    # Feed, source line (exact in a float) and blend tolerance.
    l_cols = np.column_stack(
        (columns.feeds_mm_s[seg_line], columns.lines[seg_line], columns.blends_mm[seg_line])
    )
    l_feed = l_cols[:, 0]
    l_cap = np.maximum(np.where(l_rapid, lim.rapid_mm_s, np.minimum(l_feed, lim.v_max_mm_s)), 1e-6)
    if options.blend_tolerance_mm is not None:
        l_blend = np.full(m, float(options.blend_tolerance_mm))
    else:
        l_blend = l_cols[:, 2].copy()
    return _Lines(seg_line, p0, p1, diff, l_len, l_rapid, l_cols, l_cap, l_blend, l_len > 0.0)


def _curved_blocks(
    segs: list, kinds: list, curved: np.ndarray, machine: Machine, options: PlanOptions
) -> dict[int, Block]:
    """The pieces of every arc and NURBS segment, by segment index (none for a zero-length
    arc); a NURBS segment that is an earlier one moved from that one's
    (:class:`~nurbscnc.plan.moved_copies.Repeats`)."""
    blocks: dict[int, Block] = {}
    repeats = Repeats(machine, options)
    for i in np.flatnonzero(curved).tolist():
        if kinds[i] == "nurbs":
            blocks[i] = repeats.block(segs[i], i)
        else:
            pieces = object_pieces(segs[i], i, machine, options)
            if pieces:
                blocks[i] = Block.of(pieces)
    return blocks


def _put_lines(cols: dict, first_row: np.ndarray, lines: _Lines) -> None:
    """Write the non-zero lines into their rows of ``cols``."""
    sel = lines.keep
    rows = first_row[lines.seg_line[sel]]
    cols["kind"][rows] = Kind.LINE
    cols["rapid"][rows] = lines.rapid[sel]
    cols["length_mm"][rows] = lines.length[sel]
    cols["v_cap_mm_s"][rows] = lines.cap[sel]
    cols["segment"][rows] = lines.seg_line[sel]
    cols["line"][rows] = lines.cols[:, 1].astype(np.int64)[sel]
    cols["blend_mm"][rows] = lines.blend[sel]
    cols["start_mm"][:, rows] = lines.p0[sel].T
    cols["end_mm"][:, rows] = lines.p1[sel].T
    direction = lines.diff[sel] / lines.length[sel][:, None]
    cols["tangent_start"][:, rows] = direction.T
    cols["tangent_end"][:, rows] = direction.T


def _put_blocks(cols: dict, first_row: np.ndarray, blocks: dict[int, Block]) -> dict:
    """Write the curved segments' blocks into their rows of ``cols``; their ``objects``."""
    objects = {}
    for i, block in blocks.items():
        r0, m_i = int(first_row[i]), len(block.objects)
        if not m_i:
            continue
        for name in SCALAR_COLUMNS:
            cols[name][r0 : r0 + m_i] = block.scalars[name]
        objects.update(zip(range(r0, r0 + m_i), block.objects))
        for name, arr in zip(VECTOR_COLUMNS, block.ends):
            cols[name][:, r0 : r0 + m_i] = arr.T
    return objects


def _hold_seconds(segments, holds) -> dict:
    """The planned duration [s] of every rotary-only move, by the segment's identity (the
    planned segments are the program's own objects where they are not lines)."""
    return {id(segments[i]): d for i, d in zip(holds.segment.tolist(), holds.duration_s.tolist())}


def _put_stops(
    cols: dict,
    first_row: np.ndarray,
    segs: list,
    kinds: list,
    other: np.ndarray,
    hold_s: dict,
) -> float:
    """Dwells, pauses and rotary-only moves (their planned times ``hold_s`` by identity)
    among the ``other`` segments (neither lines nor curves) as ``stop_after`` and
    ``dwell_after_s`` of the piece before; returns the seconds [s] of those before the
    first piece (for :func:`_with_dwell_marker`)."""
    pending = 0.0
    for i in np.flatnonzero(other).tolist():
        if kinds[i] not in STOP_KINDS:
            continue
        r = int(first_row[i]) - 1  # the last piece before the stop
        seconds = stop_seconds(segs[i]) + hold_s.get(id(segs[i]), 0.0)
        if r >= 0:
            cols["dwell_after_s"][r] += seconds
            cols["stop_after"][r] = True
        else:
            pending += seconds
    return pending


def _with_dwell_marker(cols: dict, objects: dict, pending: float) -> tuple[dict, dict]:
    """The columns and objects with a zero-length marker at the first piece's start that
    carries the ``pending`` dwell [s] of the program's start."""
    first = {name: cols[name][..., :1].copy() for name in cols}
    first["kind"][0] = Kind.LINE
    first["rapid"][0] = False
    first["stop_after"][0] = True
    first["length_mm"][0] = 0.0
    first["v_cap_mm_s"][0] = 1.0
    first["kappa_max_per_mm"][0] = 0.0
    first["dwell_after_s"][0] = pending
    first["blend_mm"][0] = 0.0
    first["end_mm"][:] = first["start_mm"]
    first["tangent_start"][:] = 0.0
    first["tangent_end"][:] = 0.0
    cols = {name: np.concatenate((first[name], cols[name]), axis=-1) for name in cols}
    return cols, {r + 1: v for r, v in objects.items()}


def _rest_marker(segments, first: int, pending: float) -> dict:
    """The columns of one zero-length row at the position of segment ``first`` (a program
    whose only motion is of the rotary axes) carrying the ``pending`` stops [s]."""
    cols = empty_columns(1)
    cols["kind"][0] = Kind.LINE
    cols["stop_after"][0] = True
    cols["v_cap_mm_s"][0] = 1.0
    cols["dwell_after_s"][0] = pending
    cols["segment"][0] = first
    cols["line"][0] = segments[first].line
    cols["start_mm"][:, 0] = cols["end_mm"][:, 0] = segments[first].position_mm
    return cols


def _mark_exact_stops(cols: dict, source: np.ndarray) -> None:
    """A rapid followed by a feed move stops exactly, as does every G61.1 block end; the
    ``segment`` column becomes the program's indices (``source``)."""
    rapid = cols["rapid"]
    settle = np.flatnonzero(rapid[:-1] & ~rapid[1:])
    if settle.size:  # an exact stop; the settle dwell is the planner's (plan_checked)
        cols["stop_after"][settle] = True
    # G61.1 (exact stop): the tool stops at the end of every block, tangent or not.
    seg_col = cols["segment"] = source[cols["segment"]]  # indices of the program's segments
    block_end = (cols["blend_mm"][:-1] < 0.0) & (seg_col[:-1] != seg_col[1:])
    cols["stop_after"][:-1] |= block_end


def _corners_decided(
    pieces: PieceList,
    machine: Machine,
    options: PlanOptions,
    segments,
    rotary,
    marker: bool,
    turns: dict | None = None,
) -> PieceList:
    """The pieces with their corners decided: small breaks passed, G64 corners blended,
    curvature jumps capped, the rotary columns on the final rows (``rotary``: the segments'
    columns, their holds and the program's rotary axes, or None; ``marker``: row 0 carries
    the stops before the first move), every corner logged; ``turns``: smoothing's answers
    at the turn-arounds."""
    if len(pieces) >= 2:
        turning, regular = junction_turning(pieces)
        pieces.pass_after[:-1] = small_breaks(pieces, turning, regular, machine)
    pieces, tried = apply_blends(pieces, machine, turns)
    if rotary is not None:
        pieces = dc_replace(
            pieces, rotary=rotary_pieces(pieces, segments, *rotary[:2], marker, rotary[2])
        )
    rows, dkn = curvature_jumps(pieces)
    cap = junction_jump_cap_mm_s(
        dkn, machine.servo.period_s, machine.limits.j_max_mm_s3, machine.axis_limits.as_arrays()[2]
    )
    return dc_replace(
        pieces,
        corners=corner_log(pieces, tried, machine, options),
        jump_rows=rows,
        jump_kn=dkn,
        jump_cap_mm_s=cap,
    )
