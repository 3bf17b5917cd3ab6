"""What the planner did at every corner and why (:class:`~nurbscnc.plan.corners.CornerLog`):
blended, passed or stopped, with the reason for each stop."""

from __future__ import annotations

import numpy as np

from nurbscnc.geometry.blend import MIN_REVERSAL_RAD
from nurbscnc.machine.profile import Machine
from nurbscnc.plan.blends import Corners, out_of_plane, tolerance_mm
from nurbscnc.plan.corners import CornerAction, CornerLog, CornerWhy
from nurbscnc.plan.junctions import (
    SMOOTH_JUNCTION_RAD,
    junction_turning,
    passable_junctions,
    stopped_junctions,
)
from nurbscnc.plan.options import PlanOptions
from nurbscnc.plan.pieces import PieceList
from nurbscnc.plan.rotary import different_rates


def corner_log(
    pieces: PieceList, tried: Corners | None, machine: Machine, options: PlanOptions
) -> CornerLog:
    """Every corner and what was done there (:class:`~nurbscnc.plan.corners.CornerLog`), in
    path order: the blended corners (``tried``, with the rows of ``pieces`` their blends
    took), and every junction of the final ``pieces`` that is not tangent or where the tool
    stops. Reasons for a stop, first that applies: a rapid meets a feed move; G61.1 block end;
    a dwell or pause; a zero-length piece, a cusp, a reversal or a 3-D turn (a helix, an arc
    or curve out of the corner plane: not blendable); G61.1 / G61 (exact path) /
    ``--blend-tolerance 0`` (zero tolerance) where no tolerance allows a blend; a columnar
    blend meeting a break (not blendable); else no blend fitted within the tolerance (the
    pieces are too short for one, or its PH quintic has a loop or cusp), or one fitted but
    stopping is faster (:func:`~nurbscnc.plan.blend_choice._blend_is_faster`). With rotary
    axes: a rotary-only move between the pieces; else a rotary axis's rate dA/ds changing
    (A first); and a corner between pieces along which A B C move is never rounded."""
    k = len(pieces)
    keys, lines, points, turns, acts, whys = [], [], [], [], [], []
    if tried is not None and tried.ok.any():
        ok = tried.ok
        keys.append(tried.blend_row)  # the blend's row in ``pieces``
        lines.append(tried.line[ok])
        points.append(tried.vertex_mm[:, ok].T)
        turns.append(tried.turning_rad[ok])
        acts.append(np.full(int(ok.sum()), CornerAction.BLEND, np.int8))
        whys.append(np.full(int(ok.sum()), CornerWhy.BLENDED, np.int8))
    if k >= 2:
        turning, regular = junction_turning(pieces)
        stopped = stopped_junctions(pieces)
        passable = passable_junctions(pieces, turning, regular)
        corner = stopped | ~regular | (turning > SMOOTH_JUNCTION_RAD)
        j = np.flatnonzero(corner)
        if j.size:
            passed = passable[j] & ~stopped[j]
            act = np.where(passed, CornerAction.PASS, CornerAction.STOP)
            why = np.full(j.size, CornerWhy.SMALL_BREAK, dtype=np.int8)
            st = ~passed
            slower = tried.slower_junction if tried is not None else None
            why[st] = _stop_reasons(
                pieces, j[st], turning[j[st]], regular[j[st]], machine, options, slower
            )
            keys.append(j + 1)  # the row after the junction (a blend row's junctions are smooth)
            lines.append(pieces.line[j])
            points.append(pieces.end_mm[:, j].T)
            turns.append(np.where(regular[j], turning[j], np.pi))
            acts.append(act.astype(np.int8))
            whys.append(why.astype(np.int8))
    if not keys:
        return CornerLog.empty()
    order = np.argsort(np.concatenate(keys), kind="stable")
    return CornerLog(
        np.concatenate(lines).astype(np.int64)[order],
        np.concatenate(points)[order],
        np.concatenate(turns)[order],
        np.concatenate(acts)[order],
        np.concatenate(whys)[order],
    )


def _stop_reasons(
    pieces: PieceList,
    j: np.ndarray,
    turning: np.ndarray,
    regular: np.ndarray,
    machine: Machine,
    options: PlanOptions,
    slower: np.ndarray | None = None,
) -> np.ndarray:
    """Why the tool stops at junctions ``j`` (:class:`~nurbscnc.plan.corners.CornerWhy`
    codes; :func:`corner_log` gives the order). Rules are applied last-first, so the first
    rule that applies is the one left."""
    blend, seg, rapid = pieces.blend_mm, pieces.segment, pieces.rapid
    length, stop_after = pieces.length_mm, pieces.stop_after
    tol_row = tolerance_mm(blend, machine)
    tol = np.minimum(tol_row[j], tol_row[j + 1])
    why = np.full(j.size, CornerWhy.NO_BLEND_FITS, dtype=np.int8)
    columnar = np.isin(j, pieces.ph_rows) | np.isin(j + 1, pieces.ph_rows)
    why[columnar] = CornerWhy.NOT_BLENDABLE
    if slower is not None and slower.size:  # a blend fitted, the stop is faster
        why[np.isin(j, slower)] = CornerWhy.STOP_FASTER
    zero = tol == 0.0
    why[zero] = CornerWhy.EXACT_PATH  # G61
    if options.blend_tolerance_mm == 0.0:
        why[zero] = CornerWhy.ZERO_TOLERANCE
    exact_stop = (blend[j] < 0.0) | (blend[j + 1] < 0.0)
    why[zero & exact_stop] = CornerWhy.EXACT_STOP
    degenerate = (
        ~regular
        | (turning > np.pi - MIN_REVERSAL_RAD)
        | (length[j] == 0.0)
        | (length[j + 1] == 0.0)
    )
    why[degenerate] = CornerWhy.NOT_BLENDABLE
    # Two lines always lie in one plane: only corners with a curved piece can be 3-D turns.
    objects = np.zeros(len(pieces), dtype=bool)
    objects[list(pieces.objects)] = True
    failed = np.flatnonzero((why == CornerWhy.NO_BLEND_FITS) & (objects[j] | objects[j + 1]))
    why[failed[out_of_plane(pieces, j[failed])]] = CornerWhy.NOT_BLENDABLE
    rot = pieces.rotary
    if rot is not None:  # A B C: no blends where they move, stops where a rate changes
        rate = rot.rate_deg_mm
        why[np.any(rate[j] != 0.0, axis=1) | np.any(rate[j + 1] != 0.0, axis=1)] = (
            CornerWhy.ROTARY_MOVES
        )
    why[stop_after[j]] = CornerWhy.DWELL_OR_PAUSE
    if rot is not None:
        changes = different_rates(rot.rate_deg_mm)[j]  # (m, 3)
        for axis in (2, 1, 0):  # the first axis that changes names the stop
            why[changes[:, axis]] = (CornerWhy.A_RATE, CornerWhy.B_RATE, CornerWhy.C_RATE)[axis]
        why[np.isin(j, rot.hold_row)] = CornerWhy.ROTATE
    block_end = (
        stop_after[j] & (blend[j] < 0.0) & (seg[j] != seg[j + 1]) & (pieces.dwell_after_s[j] == 0.0)
    )
    why[block_end] = CornerWhy.EXACT_STOP
    why[rapid[j] != rapid[j + 1]] = CornerWhy.RAPID_FEED
    return why
