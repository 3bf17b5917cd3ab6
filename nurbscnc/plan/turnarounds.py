"""Raster turn-arounds (G64 P): two corners around a short middle line blended by one U
curve (:mod:`nurbscnc.geometry.turnaround`) when it is quicker than stopping at both.

Stopping at a corner is not free under the contour check: in the deceleration the servo's
tool leads its reference by c₂·a (SPEC §8: 1 − G(s) ≈ c₁s + c₂s², c₂ = 2.85e-5 s² for the
paper's axes), so a stop that ends at deceleration a overshoots the vertex by about c₂·a
(70 µm at 2450 mm/s²): sin θ of it off the path below a turn of 90°, all of it from 90° to a
full reversal (the vertex is then the overshoot's nearest path point). Keeping it within the
contour tolerance ε of the path, or within ε + P of the vertex of a G64 corner
(:mod:`nurbscnc.plan.allowance`: the overshoot point lies c₂·a from the vertex whatever θ),
costs a deceleration of at most A_s = max(ε/(c₂ · (sin θ below 90°, else 1)), (ε + P)/(r c₂))
into the stop (:func:`stop_deceleration_mm_s2`). The U is
one curve of peak curvature κ crossed at w ≤ √(SHARE · ε / (c₂ κ)) (its steady servo error
c₂ w²κ within :data:`TURN_SERVO_SHARE` of ε; zero curvature at its ends, so no transient
adds to it), and at the normal-acceleration and chord caps of any curve.
"""

from __future__ import annotations

import numpy as np

from nurbscnc.geometry.path import Kind
from nurbscnc.machine.caps import MIN_CAP_MM_S, curvature_cap_mm_s, servo_curve_cap_mm_s
from nurbscnc.machine.profile import Machine
from nurbscnc.plan import allowance
from nurbscnc.plan.blends import Corners, servo_gain_s2
from nurbscnc.plan.pieces import PieceList

#: Least reversal of the tangent across a turn-around [deg]: the angle between the incoming
#: and the outgoing line (a raster's is 180°; a pocket's or an outline's 120–150° turns
#: around a short line are two corners of their own).
MIN_REVERSAL_DEG = 150.0
#: Least time [s] the U must save on the estimate of both stops to be kept: what the estimates
#: miss (the check's slow-downs around the U, a stop's real deceleration). Measured: on the
#: raster (0.5 mm stepovers at F2000) 37 ms estimated, 46 ms saved; on the CamBam enclosure's
#: 0.1 mm stepovers at F500 12 ms estimated, 15 ms lost.
TURN_MARGIN_S = 0.015
#: Share of ε_max the servo's steady curve error may take on a U (its ends are G2 with the
#: lines: the error on it is the steady one; lsim: 13.7 µm against c₂ v²κ = 14.2 µm on the
#: raster's U at v²κ = 500 mm/s²).
TURN_SERVO_SHARE = 0.9
#: Cells a U is cut into, of equal length, each capped by its own peak curvature.
TURN_CELLS = 24


#: The largest overshoot past the vertex of a stop ended at a constant deceleration a, over
#: c₂·a: lsim of SPEC Table 2's axes (the paper's profile and LinuxCNC's limits), stops from
#: 5–58 mm/s at 300–2450 mm/s²: 1.047 (where the deceleration lasts 16–24 ms its onset's
#: ringing adds to the end's; 0.88 from 25 mm/s at 2450 mm/s², where it lasts 10 ms).
STOP_OVERSHOOT_RATIO = 1.05


def stop_deceleration_mm_s2(machine: Machine, turning_rad, tol_mm=0.0) -> np.ndarray:
    """The deceleration [mm/s²] a stop at a corner turning by θ, of path tolerance P =
    ``tol_mm`` [mm] (G64; 0: none), may end with so that the servo's overshoot past the
    vertex stays within the guarantee (module doc): min(A, max(ε / (c₂ s), (ε + P) / (r c₂))),
    r = :data:`STOP_OVERSHOOT_RATIO`,
    s = sin θ below 90° and 1 from 90° on (A without a servo model or check).

    The tool overshoots the vertex C by δ ≈ c₂·a along the incoming tangent t_a (the lead
    of a deceleration a, SPEC §8), at C + δ t_a. Its distance to the path: δ sin θ from the
    outgoing segment while its projection falls on it (θ < 90°); from 90° on it projects
    before the segment's start and past the incoming one's end, so the vertex is its
    nearest path point and all of δ is off the path, up to a full reversal. Its distance to
    the vertex is δ at any θ, so a G64 corner's allowance (within ε + P of the vertex,
    :mod:`nurbscnc.plan.allowance`) holds it while δ ≤ ε + P; δ is at most r·c₂·a. The
    sample is within the guarantee if either holds: the larger bound. lsim of the paper's axes
    (tests/test_turnarounds.py), a stop from 25 mm/s: ended at 2450 mm/s², 43.7 µm at 45°
    and 61.8 µm from 90° to 180°; at ε / (c₂ s) 14.7–14.9 µm off the path; at (ε + P) / (r c₂)
    within ε + P of the vertex (tests/test_corner_allowance.py)."""
    lim = machine.limits
    gain = servo_gain_s2(machine)
    th = np.asarray(turning_rad, dtype=float)
    if gain == 0.0 or not machine.contour_check:
        return np.full(th.shape, lim.a_max_mm_s2)
    off = np.where(th < 0.5 * np.pi, np.sin(th), 1.0)
    eps = lim.contour_tolerance_mm
    with np.errstate(divide="ignore"):
        a_s = eps / (gain * np.maximum(off, 0.0))
    if allowance.CORNER_ALLOWANCE:  # the vertex's ball (none where P = 0: ε/c₂ ≤ ε/(c₂ s))
        tol = np.maximum(np.asarray(tol_mm, dtype=float), 0.0)
        a_s = np.maximum(a_s, (eps + tol) / (STOP_OVERSHOOT_RATIO * gain))
    return np.minimum(lim.a_max_mm_s2, a_s)


def _change_s(dv_mm_s, a_mm_s2, j_mm_s3) -> np.ndarray:
    """Time [s] of a jerk-limited speed change by Δv ≥ 0 (SPEC §7's closed form)."""
    dv = np.maximum(np.asarray(dv_mm_s, dtype=float), 0.0)
    a = np.asarray(a_mm_s2, dtype=float)
    return np.where(dv <= a * a / j_mm_s3, 2.0 * np.sqrt(dv / j_mm_s3), dv / a + a / j_mm_s3)


def line_accel_mm_s2(machine: Machine, unit) -> np.ndarray:
    """The tangential acceleration [mm/s²] a line of unit direction ``unit`` (3, n) allows:
    min(A, min_i A_i / |u_i|) over the axes' own limits."""
    a_axis = machine.axis_limits.as_arrays()[1][:, None]
    u = np.abs(np.asarray(unit, dtype=float))
    with np.errstate(divide="ignore"):
        per_axis = np.where(u > 0.0, a_axis / np.where(u > 0.0, u, 1.0), np.inf).min(axis=0)
    return np.minimum(machine.limits.a_max_mm_s2, per_axis)


def stops_cost_s(v, m_mm, theta1, theta2, accel, machine: Machine, tol_mm: float = 0.0) -> float:
    """Time [s] stopping at both corners adds to cruising at v [mm/s] over the middle line of
    length m [mm]. Each stop at a corner turning by θ is entered and left at A_s(θ) at most
    (:func:`stop_deceleration_mm_s2` of the corners' path tolerance ``tol_mm`` [mm]: the
    servo answers a jump of the acceleration alike at either end of a stop, a linear
    system), each line at its own acceleration ``accel`` (3,):
    the incoming, middle and outgoing lines' [mm/s²] (:func:`line_accel_mm_s2`). A speed
    change covers half its time at v; the middle runs from rest to rest, peaking where its
    two changes meet or at v."""
    j = machine.limits.j_max_mm_s3
    a_in, a_mid, a_out = (float(x) for x in accel)
    s1 = float(stop_deceleration_mm_s2(machine, theta1, tol_mm))
    s2 = float(stop_deceleration_mm_s2(machine, theta2, tol_mm))
    up_a, down_a = min(a_mid, s1), min(a_mid, s2)
    peak = min(v, np.sqrt(2.0 * m_mm / (1.0 / up_a + 1.0 / down_a)))
    up, down = _change_s(peak, up_a, j), _change_s(peak, down_a, j)
    middle = up + down + max(m_mm - 0.5 * peak * (up + down), 0.0) / peak
    enter, leave = _change_s(v, min(a_in, s1), j), _change_s(v, min(a_out, s2), j)
    return float(0.5 * (enter + leave) + middle - m_mm / v)


def turn_cost_s(v, w, length_mm, replaced_mm, accel, machine: Machine) -> float:
    """Time [s] a U of length L crossed at w adds to cruising at v over the ``replaced_mm``
    of corner path: slowing to w on the incoming line and back on the outgoing one (each
    transition covers (v + w)/2 of its time, :func:`stops_cost_s`'s ``accel``), L/w, less
    the replaced path at v."""
    j = machine.limits.j_max_mm_s3
    dv = v - w
    t = _change_s(dv, float(accel[0]), j) + _change_s(dv, float(accel[2]), j)
    return float(0.5 * t * dv / v + length_mm / w - replaced_mm / v)


def turnaround_corners(pieces: PieceList, c: Corners, machine: Machine, memo=None) -> None:
    """Find the turn-arounds among corners ``c`` (two line–line corners around a middle line,
    the tangent reversed by at least :data:`MIN_REVERSAL_DEG` across them), fit each its U
    within the smaller tolerance, trims at most half of each outer line, and keep it where it
    is quicker than both stops by :data:`TURN_MARGIN_S` at least (:func:`turn_cost_s`
    against :func:`stops_cost_s`). A kept
    one is recorded on ``c``: the first corner carries the U (trims: ``d`` of the incoming
    line and the whole middle line), the second is ``absorbed`` (trims: ``d`` of the outgoing
    line, no blend row of its own), both ``turn`` and no longer line–line corners.
    ``memo``: None, or the dict of :func:`turn_choice` answers smoothing already found for
    this program (:func:`remembered_turn_choice`)."""
    m = c.row.size
    if m < 2:
        return
    row = c.row
    pair = (row[1:] == row[:-1] + 1) & c.lines[:-1] & c.lines[1:]
    pair &= (pieces.kind[row[:-1]] == Kind.LINE) & ~pieces.rapid[row[:-1]]
    t_a, t_b = pieces.tangent_end[:, row[:-1] - 1], pieces.tangent_start[:, row[1:]]
    pair &= np.sum(t_a * t_b, axis=0) <= np.cos(np.radians(MIN_REVERSAL_DEG))
    length, cap = pieces.length_mm, pieces.v_cap_mm_s
    taken = -1
    for j in np.flatnonzero(pair).tolist():
        if j <= taken:  # its first corner is the last turn-around's second
            continue
        r = int(row[j])
        bl = remembered_turn_choice(
            memo,
            pieces.start_mm[:, r - 1 : r + 2].T,
            pieces.end_mm[:, r - 1 : r + 2].T,
            cap[r - 1 : r + 2],
            float(min(c.tol_mm[j], c.tol_mm[j + 1])),
            machine,
        )
        if bl is not None:
            taken = j + 1
            _record(c, j, bl, float(length[r]), machine)


def remembered_turn_choice(memo, start_mm, end_mm, cap_mm_s, tol_mm: float, machine):
    """:func:`turn_choice`, its answer kept in ``memo`` (a dict, or None: not kept) under
    the exact bytes of its inputs: smoothing (which keeps a U's outer lines out of its runs)
    and the planner ask it of the same turn-arounds with the same numbers, so the second
    question is a look-up (the same U object, the same bits). ``machine``: one per memo."""
    if memo is None:
        return turn_choice(start_mm, end_mm, cap_mm_s, tol_mm, machine)
    key = b"".join(
        np.ascontiguousarray(x, dtype=float).tobytes()
        for x in (start_mm, end_mm, cap_mm_s, [tol_mm])
    )
    if key not in memo:
        memo[key] = turn_choice(start_mm, end_mm, cap_mm_s, tol_mm, machine)
    return memo[key]


def turn_choice(start_mm: np.ndarray, end_mm: np.ndarray, cap_mm_s, tol_mm: float, machine):
    """The U of a turn-around of three lines (starts and ends (3, 3) [mm], feed caps (3,)
    [mm/s]: incoming, middle, outgoing) within ``tol_mm``, trims at most half of each outer
    line, if it is quicker than both stops by :data:`TURN_MARGIN_S` (:func:`turn_cost_s`
    against :func:`stops_cost_s`); else None. The planner and smoothing (which keeps the
    outer lines out of its runs where a U will be taken) decide alike."""
    from nurbscnc.geometry.turnaround import turn_blend

    d = end_mm - start_mm
    length = np.sqrt(np.sum(d * d, axis=1))
    unit = d / np.maximum(length, 1e-300)[:, None]
    cos = np.clip(np.sum(unit[:-1] * unit[1:], axis=1), -1.0, 1.0)
    turning = np.arccos(cos)
    # Half of each outer line, and no more than a U of the stepover's width needs.
    max_trim = min(0.5 * float(min(length[0], length[2])), float(length[1]) + 2.0 * tol_mm)
    bl = turn_blend(end_mm[0], unit[0], end_mm[1], unit[2], tol_mm, max_trim)
    if bl is None:
        return None
    cap = np.asarray(cap_mm_s, dtype=float)
    v = float(cap.min())
    w = min(_turn_cap_mm_s(machine, bl.kappa_max_per_mm, float(cap.max())), v)
    replaced = bl.trim_a_mm + float(length[1]) + bl.trim_b_mm
    accel = line_accel_mm_s2(machine, unit.T)
    turn_s = turn_cost_s(v, w, bl.length_mm, replaced, accel, machine)
    stops_s = stops_cost_s(v, float(length[1]), turning[0], turning[1], accel, machine, tol_mm)
    return bl if turn_s + TURN_MARGIN_S <= stops_s else None


def _turn_cap_mm_s(machine: Machine, kappa_per_mm: float, feed_mm_s: float) -> float:
    """The U's feed cap [mm/s]: the curvature caps of any curve at the feed, and the servo
    cap of :data:`TURN_SERVO_SHARE` of ε (module doc)."""
    cap = float(curvature_cap_mm_s(machine, kappa_per_mm, feed_mm_s))
    return max(min(cap, float(servo_cap_mm_s(machine, kappa_per_mm))), MIN_CAP_MM_S)


def servo_cap_mm_s(machine: Machine, kappa_per_mm):
    """The servo cap [mm/s] of :data:`TURN_SERVO_SHARE` of ε at curvature κ (elementwise;
    inf without a servo model or contour check)."""
    gain = servo_gain_s2(machine)
    if gain == 0.0 or not machine.contour_check:
        return np.full(np.shape(kappa_per_mm), np.inf)
    eps = TURN_SERVO_SHARE * machine.limits.contour_tolerance_mm
    return servo_curve_cap_mm_s(kappa_per_mm, eps, gain)


def _record(c: Corners, j: int, bl, middle_mm: float, machine: Machine) -> None:
    """Corners j and j + 1 as one turn-around blended by ``bl`` (see
    :func:`turnaround_corners`)."""
    c.turn[j] = c.turn[j + 1] = True
    c.absorbed[j + 1] = True
    c.lines[j] = c.lines[j + 1] = False
    c.obj_blends[j] = bl
    c.ok[j] = c.ok[j + 1] = True
    c.kappa_per_mm[j] = bl.kappa_max_per_mm
    c.length_mm[j] = bl.length_mm
    c.trim_a_mm[j], c.trim_b_mm[j] = bl.trim_a_mm, middle_mm
    c.trim_a_mm[j + 1], c.trim_b_mm[j + 1] = 0.0, bl.trim_b_mm
    c.cap_mm_s[j] = float(servo_cap_mm_s(machine, bl.kappa_max_per_mm))
    c.cells[j] = TURN_CELLS


def turn_cells(bl, n: int) -> tuple[np.ndarray, ...]:
    """The U ``bl`` cut into ``n`` cells of equal length: arrays (n,) of u_a, u_b, s_a [mm],
    length [mm] and peak curvature [1/mm] (the peak over 33 samples of each cell, ends
    included)."""
    curve = bl.curve
    total = float(curve.arc_length(np.array([0.0, 1.0]))[1])
    s = np.linspace(0.0, total, n + 1)
    u = np.asarray(curve.param_at_length(s), dtype=float)
    u[0], u[-1] = 0.0, 1.0
    frac = np.linspace(0.0, 1.0, 33)
    samples = u[:-1, None] + frac[None, :] * np.diff(u)[:, None]
    kappa = np.asarray(curve.curvature(samples.ravel()), dtype=float).reshape(n, -1).max(axis=1)
    return u[:-1], u[1:], s[:-1], np.diff(s), kappa
