"""Which corners are blended (G64): every blend that fits and is not slower than a stop,
applied to the pieces (:func:`apply_blends`)."""

from __future__ import annotations

import numpy as np

from nurbscnc.machine.caps import MIN_CAP_MM_S, NORMAL_SHARE, curvature_cap_mm_s
from nurbscnc.machine.profile import Machine
from nurbscnc.plan.blend_rows import BLEND_FEED, blended_rows
from nurbscnc.plan.blends import Corners, blend_line_corners, blend_object_corners, find_corners
from nurbscnc.plan.pieces import PieceList
from nurbscnc.plan.turnarounds import turnaround_corners


def apply_blends(
    pieces: PieceList, machine: Machine, turns: dict | None = None
) -> tuple[PieceList, Corners | None]:
    """Replace corners by PH quintic blends within their tolerance (G64).

    Every corner :func:`find_corners` admits is blended when a blend fits: as LinuxCNC
    under G64, blending is never weighed against stopping (a blend's feed is capped by its
    peak curvature, and the look-ahead slows to that cap, which is never slower than slowing
    to 0 over the same path). A blend trims at most half of each piece, so blends never
    overlap. Line–line corners are built all at once in closed form
    (:func:`blend_line_corners`): a polyline of short chords becomes a chain of blends with
    no sliver of line left between them (equal trims where the tolerance binds). Corners
    with an arc, NURBS or PH piece go one at a time (:func:`blend_object_corners`). The blend
    piece is capped by its peak curvature like any curved piece (chord error, normal
    acceleration). A piece trimmed at both ends to less than :data:`MIN_REMAINDER_MM` is
    dropped. The blends' end tangents are the pieces' own unit tangents (not recomputed from
    trimmed end points), so the junctions of a blended polyline are exactly smooth. The new
    rows are written by :func:`blended_rows`. Returns the pieces and the corners tried
    (None if none). ``turns``: None, or the turn-arounds' answers smoothing found
    (:func:`~nurbscnc.plan.turnarounds.remembered_turn_choice`).
    """
    if len(pieces) < 2:
        return pieces, None
    c = find_corners(pieces, machine)
    if c is None:
        return pieces, None
    turnaround_corners(pieces, c, machine, turns)
    blend_line_corners(pieces, c)
    blend_object_corners(pieces, c, machine)
    faster = _blend_is_faster(pieces, c, machine) | c.turn
    c.slower = c.ok & ~faster
    c.ok &= faster
    if not c.ok.any():
        c.slower_junction = c.row[c.slower] - 1
        return pieces, c
    return blended_rows(pieces, c, machine), c


def _speed_change_s(dv_mm_s, a_mm_s2: float, j_mm_s3: float) -> np.ndarray:
    """Time [s] of a jerk-limited speed change by ``dv_mm_s`` ≥ 0 between two instants of
    zero acceleration (the profile's transitions, SPEC §7): 2√(Δv/J) while Δv ≤ A²/J (the
    acceleration never reaches A), else Δv/A + A/J."""
    dv = np.maximum(np.asarray(dv_mm_s, dtype=float), 0.0)
    return np.where(
        dv <= a_mm_s2 * a_mm_s2 / j_mm_s3,
        2.0 * np.sqrt(dv / j_mm_s3),
        dv / a_mm_s2 + a_mm_s2 / j_mm_s3,
    )


def _reach_mm_s(d_mm, a_mm_s2: float, j_mm_s3: float) -> np.ndarray:
    """The speed [mm/s] a jerk-limited start from rest reaches over ``d_mm`` (ending at zero
    acceleration): the inverse of d = v t(v)/2 with t = :func:`_speed_change_s`, i.e.
    v = (d² J)^(1/3) while v ≤ A²/J, else the root of v²/(2A) + v A/(2J) = d."""
    d = np.maximum(np.asarray(d_mm, dtype=float), 0.0)
    low = np.cbrt(d * d * j_mm_s3)
    b = a_mm_s2 / j_mm_s3  # v² + b A v − 2 A d = 0 with b A = A²/J
    high = 0.5 * (-b * a_mm_s2 + np.sqrt((b * a_mm_s2) ** 2 + 8.0 * a_mm_s2 * d))
    return np.where(low <= a_mm_s2 * a_mm_s2 / j_mm_s3, low, high)


def _corner_accelerations(
    pieces: PieceList, c: Corners, machine: Machine
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per corner (m,): the tangential acceleration [mm/s²] the piece before may use as it
    leaves the corner's vertex, the piece after as it enters it, and the normal
    acceleration [mm/s²] a blend may use.

    Where only the kinematics decide — rapid corners (never checked) and machines without a
    servo model — they are exact: along a tangent t axis i takes a·|t_i|
    (:func:`~nurbscnc.machine.caps.axis_path_limits`), so the pieces keep a ≤ min_i A_i/|t_i|
    at the corner's ends (exact on lines); on the blend the normal part may take
    :data:`~nurbscnc.machine.caps.NORMAL_SHARE` of A_i on each axis and its curvature
    vector's component on axis i is at most κ, so V²κ ≤ NORMAL_SHARE · min_i A_i (the cap
    the planner's axis limits give a blend is never below √(NORMAL_SHARE · min_i A_i / κ)).
    Elsewhere, and without axis limits, all three are the path's A: under the contour check
    a stop costs more than its kinematics (the deceleration into it is held down to keep the
    servo's overshoot within ε) and so does a blend (its servo cap), and the path-A estimate
    weighs them as measured: the exact kinematics there stopped more corners and cost
    tort.ngc 47 ms and the PCB isolation program 58 ms under LinuxCNC's limits."""
    a_path = float(machine.limits.a_max_mm_s2)
    m = c.row.size
    if not machine.axis_limits.any:
        full = np.full(m, a_path)
        return full, full, full
    a_i = machine.axis_limits.as_arrays()[1]
    with np.errstate(divide="ignore"):
        leave = np.min(a_i[:, None] / np.abs(pieces.tangent_end[:, c.row - 1]), axis=0)
        enter = np.min(a_i[:, None] / np.abs(pieces.tangent_start[:, c.row]), axis=0)
    normal = min(a_path, NORMAL_SHARE * float(np.min(a_i)))
    exact = pieces.rapid[c.row] | (not machine.contour_check)
    return (
        np.where(exact, np.minimum(leave, a_path), a_path),
        np.where(exact, np.minimum(enter, a_path), a_path),
        np.where(exact, normal, a_path),
    )


def _blend_is_faster(pieces: PieceList, c: Corners, machine: Machine) -> np.ndarray:
    """Which corners (m,) pass faster through their blend than stopping at the vertex
    (G64 P: LinuxCNC blends every corner; a blend so tight that crawling through it costs
    more than a stop is not used, so G64 P is never slower than G61 there).

    Estimate, per corner, the time the corner adds to cruising at v over the same span, with
    the profile's transitions (zero acceleration at their ends, :func:`_speed_change_s`
    t(Δv), covering (v + w)/2 · t(Δv)): stopping costs (t_a(v) + t_b(v))/2 (slowing on the
    piece before at its acceleration, speeding up on the piece after at its own); slowing
    to the blend's cap w, crossing its length L_b at w and speeding up again costs
    (t_a(v − w) + t_b(v − w))/2 · (v − w)/v + L_b/w − (d_a + d_b)/v (the blend replaces
    the trims d_a + d_b of the corner path). The accelerations are those the axis limits
    leave (:func:`_corner_accelerations`). v: the smaller neighbouring cap, and at most the
    speed reachable from rest over half the shorter neighbour (:func:`_reach_mm_s`, the
    stop's own bound); w: the blend's curvature cap at the faster move's feed, as
    :func:`~nurbscnc.plan.blend_rows.blended_rows` gives it, within the normal acceleration
    the axes leave it (at most v)."""
    m = c.row.size
    faster = np.ones(m, dtype=bool)
    if not c.ok.any():
        return faster
    lim = machine.limits
    a, b = c.row - 1, c.row
    acc_a, acc_b, acc_n = _corner_accelerations(pieces, c, machine)
    cap = np.minimum(pieces.v_cap_mm_s[a], pieces.v_cap_mm_s[b])
    feed = BLEND_FEED(pieces.v_cap_mm_s[a], pieces.v_cap_mm_s[b])  # the blend's own
    half = 0.5 * np.minimum(pieces.length_mm[a], pieces.length_mm[b])
    v = np.minimum(cap, _reach_mm_s(half, np.minimum(acc_a, acc_b), lim.j_max_mm_s3))
    kappa = np.maximum(c.kappa_per_mm, 1e-300)
    w = np.minimum(
        np.maximum(
            np.minimum(
                np.minimum(curvature_cap_mm_s(machine, c.kappa_per_mm, feed), c.cap_mm_s),
                np.sqrt(acc_n / kappa),
            ),
            MIN_CAP_MM_S,
        ),
        v,
    )
    v = np.maximum(v, MIN_CAP_MM_S)
    j = lim.j_max_mm_s3

    def change_s(dv):  # the mean of slowing on the piece before and speeding up on the next
        return 0.5 * (_speed_change_s(dv, acc_a, j) + _speed_change_s(dv, acc_b, j))

    t_dip = change_s(v - w) * (v - w) / v
    blend = t_dip + c.length_mm / w - (c.trim_a_mm + c.trim_b_mm) / v
    stop = change_s(v)
    faster[c.ok] = (blend <= stop)[c.ok]
    return faster
