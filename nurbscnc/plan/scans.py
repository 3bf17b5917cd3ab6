"""The look-ahead's scans over pieces (SPEC §7 steps 1–5, module doc of
:mod:`nurbscnc.plan.profile_plan`): backward and forward scans by relaxation, the bounded
look-ahead's window caps, the float repair of the junction speeds, and the profile with
every piece its own planning unit (:func:`plan_profile_pieces`)."""

from __future__ import annotations

import math

import numpy as np

from nurbscnc.errors import PlanningError
from nurbscnc.plan.feedrate import (
    max_reachable_speed,
    max_reachable_speed_scalar,
    peak_speed_unchecked,
    reach_unchecked,
    scurve_distance_mm,
    scurve_timing,
)
from nurbscnc.plan.profile import Profile, ProfileInput, frozen_array


def window_caps(
    cap: np.ndarray,
    length: np.ndarray,
    w_back: np.ndarray,
    n: int,
    a: np.ndarray,
    j: np.ndarray,
) -> np.ndarray:
    """Stop-within-the-window caps of an ``n``-piece look-ahead, (k+1,) [mm/s].

    Junction ``i`` gets the value at ``i`` of the backward scan started at rest at junction
    ``i + n`` (``inf`` where the window reaches the program end: the full scan covers it).
    All chains step back together, vectorised over ``i``. A chain that becomes *equal* to the
    full backward scan ``w_back`` at some junction (typically both hit the same cap or exact
    stop) runs through the same recurrence from there on, so its answer is ``w_back[i]`` and
    it is dropped early.
    """
    k = length.size
    out = np.full(k + 1, np.inf)
    i = np.arange(1, k - n)  # junctions whose window ends inside the program (i + n < k)
    m = i + n
    w = np.zeros(i.size)
    for _ in range(n):
        if i.size == 0:
            break
        m = m - 1
        w = np.minimum(cap[m], max_reachable_speed(w, length[m], a[m], j[m]))
        same = w == w_back[m]
        if same.any():
            out[i[same]] = w_back[i[same]]
            live = ~same
            i, m, w = i[live], m[live], w[live]
    out[i] = w
    return out


#: Below this many live chains :func:`chain_scan` finishes each one in plain floats (a numpy
#: step costs tens of µs whatever its size; the scalar closed form about 1 µs a piece).
CHAIN_SCALAR = 24


def chain_scan(bound: np.ndarray, length: np.ndarray, a: np.ndarray, j: np.ndarray) -> np.ndarray:
    """The speeds (k+1,) [mm/s] of the recurrence ``y_0 = 0``,
    ``y_{n+1} = min(bound_{n+1}, R(y_n, L_n))`` (``R`` the reach of
    :func:`~nurbscnc.plan.feedrate.max_reachable_speed` with piece n's limits ``a_n, j_n``;
    ``bound_0`` unused): the look-ahead's forward scan, and, on reversed arrays, its
    backward scan.

    Solved by relaxation instead of a Python loop over the pieces: start from ``y = bound``
    and recompute, all at once, every ``y_{n+1}`` whose predecessor changed, until nothing
    changes. After round r the first r speeds are final (induction), so this ends; at the
    end every equation holds, and the recurrence has one solution, so it is the scan's.
    The rounds number the longest run of pieces on one S-curve (a few dozen on CAM
    chords); the last few chains run in plain floats (:data:`CHAIN_SCALAR`).
    """
    k = length.size
    y = np.array(bound, dtype=float)
    y[0] = 0.0
    live = np.arange(k)  # n: y_{n+1} to recompute from y_n
    while live.size > CHAIN_SCALAR:
        new = np.minimum(bound[live + 1], reach_unchecked(y[live], length[live], a[live], j[live]))
        changed = new != y[live + 1]
        moved = live[changed] + 1
        y[moved] = new[changed]
        live = moved[moved < k]
    if live.size:
        reach = max_reachable_speed_scalar
        yl, bl, ll, al, jl = (x.tolist() for x in (y, bound, length, a, j))
        for n in live.tolist():
            w = yl[n]
            while n < k:
                w = reach(w, ll[n], al[n], jl[n])
                if bl[n + 1] < w:
                    w = bl[n + 1]
                if w == yl[n + 1]:
                    break
                yl[n + 1] = w
                n += 1
        y = np.array(yl)
    return y


def backward_scan(cap: np.ndarray, length: np.ndarray, a: np.ndarray, j: np.ndarray) -> np.ndarray:
    """``w_i = min(cap_i, R(w_{i+1}, L_i))`` from ``w_k = 0``, ``R`` with piece i's descent
    limits ``a[i], j[i]`` (:func:`chain_scan` on the reversed pieces)."""
    return chain_scan(cap[::-1], length[::-1], a[::-1], j[::-1])[::-1]


def transition_distance_mm(v_a, v_b, a, j, a_dn=None, j_dn=None):
    """``D(v_a → v_b)`` [mm] with the rising limits ``a, j`` where ``v_b > v_a``, else the
    descending ones (default: the same)."""
    if a_dn is None:
        return scurve_distance_mm(v_a, v_b, a, j)
    up = v_b > v_a
    return scurve_distance_mm(v_a, v_b, np.where(up, a, a_dn), np.where(up, j, j_dn))


def repair_junctions(v: np.ndarray, length: np.ndarray, a, j, a_dn=None, j_dn=None) -> np.ndarray:
    """Make ``D(v_i → v_{i+1}) ≤ L_i`` hold in floats for every piece (in place; returned).

    The scans satisfy it mathematically and, with the float guard of the reach function,
    almost always in floats too; a rounding step at the A²/J branch switch of ``D`` can leave
    a piece an ulp short. Such a piece gets the higher of its end speeds lowered by a
    doubling number of ulps; a lowered junction re-checks its other piece. ``a, j`` (and
    ``a_dn, j_dn`` for descents, default the same): scalars or (k,) per piece.
    """
    k = length.size
    lims = [
        np.broadcast_to(np.asarray(x, dtype=float), (k,))
        for x in (a, j, a if a_dn is None else a_dn, j if j_dn is None else j_dn)
    ]
    bad = np.flatnonzero(transition_distance_mm(v[:-1], v[1:], *lims) > length)
    work = [int(x) for x in bad]
    while work:
        i = work.pop()
        step = 1.0
        li = [float(x[i]) for x in lims]
        while transition_distance_mm(v[i], v[i + 1], *li) > length[i]:
            hi, lo = (i, i + 1) if v[i] > v[i + 1] else (i + 1, i)
            v[hi] = max(v[lo], v[hi] - step * math.ulp(v[hi]))
            step *= 2.0
            other = i - 1 if hi == i else i + 1  # the other piece that touches junction hi
            if 0 <= other < k:
                work.append(other)
    return v


def plan_profile_pieces(inp: ProfileInput) -> Profile:
    """Plan with every piece boundary a junction of zero acceleration (the scans below).

    Cost O(k) Python steps for the two scans plus vectorised numpy for the peaks (bisection)
    and the phases; a bounded look-ahead adds O(k·N) vectorised work at worst.
    """
    a, j, a_dn, j_dn = inp.piece_limits()  # (k,) each: rise and descent limits per piece
    length = np.array(inp.length_mm)
    v_max = np.array(inp.v_max_mm_s)
    k = length.size

    # 1. Junction caps, lowered to the neighbouring pieces' cruise caps.
    cap = np.array(inp.v_junction_max_mm_s)
    cap[:-1] = np.minimum(cap[:-1], v_max)
    cap[1:] = np.minimum(cap[1:], v_max)

    # 2. Backward scan from the end at rest.
    w_back = backward_scan(cap, length, a_dn, j_dn)

    # 3. Bounded look-ahead: cap by the stop-within-the-window speeds, then rescan so that
    #    the caps are backward-consistent again (w_i ≤ R(w_{i+1}, L_i)), which is what makes
    #    the forward scan's result feasible (R is not monotone in its start speed: module doc).
    n = inp.lookahead_pieces
    if n is not None and n < k:
        cap = np.minimum(cap, window_caps(cap, length, w_back, n, a_dn, j_dn))
        w_back = backward_scan(cap, length, a_dn, j_dn)

    # 4. Forward scan from the start at rest.
    v = repair_junctions(chain_scan(w_back, length, a, j), length, a, j, a_dn, j_dn)

    # 5. Per piece: peak speed, then the seven phases.
    v_s, v_e = v[:-1], v[1:]
    v_p = peak_speed_unchecked(v_s, v_e, length, v_max, a, j, a_dn, j_dn)
    tj1, tc1, ap1 = scurve_timing(v_s, v_p, a, j)
    tj2, tc2, ap2 = scurve_timing(v_p, v_e, a_dn, j_dn)
    d_acc = scurve_distance_mm(v_s, v_p, a, j)
    d_dec = scurve_distance_mm(v_p, v_e, a_dn, j_dn)
    cruise = np.maximum(length - d_acc - d_dec, 0.0)  # ≥ 0 up to an ulp, by the bisection
    if np.any((cruise > 0.0) & (v_p <= 0.0)):
        raise PlanningError("a piece has length but no reachable speed (length underflow)")
    with np.errstate(divide="ignore", invalid="ignore"):
        t_cr = np.where(cruise > 0.0, cruise / v_p, 0.0)

    bounds = np.concatenate(([0.0], np.cumsum(length)))
    start, end = bounds[:-1], bounds[1:]
    half_j1 = 0.5 * j * tj1 * tj1
    half_j2 = 0.5 * j_dn * tj2 * tj2
    sixth_j1 = j * tj1**3 / 6.0
    sixth_j2 = j_dn * tj2**3 / 6.0
    zero = np.zeros(k)
    dur = np.stack([tj1, tc1, tj1, t_cr, tj2, tc2, tj2], axis=1)
    jerk = np.stack([j, zero, -j, zero, -j_dn, zero, j_dn], axis=1)
    a0 = np.stack([zero, ap1, ap1, zero, zero, -ap2, -ap2], axis=1)
    v0 = np.stack([v_s, v_s + half_j1, v_p - half_j1, v_p, v_p, v_p - half_j2, v_e + half_j2], 1)
    # Positions are anchored at both ends of the piece (the S-curves' closed-form distances),
    # not accumulated, so each piece ends exactly where the next begins. Phase distances:
    # jerk ramp up from v_s: v_s·t + J·t³/6; ramp down into v_p: v_p·t − J·t³/6 (and the
    # mirror images for the deceleration).
    s0 = np.stack(
        [
            start,
            start + (v_s * tj1 + sixth_j1),
            start + d_acc - (v_p * tj1 - sixth_j1),
            start + d_acc,
            end - d_dec,
            end - d_dec + (v_p * tj2 - sixth_j2),
            end - (v_e * tj2 + sixth_j2),
        ],
        axis=1,
    )
    # Times: cumulative sums, so phase starts never decrease (a piece's last phase start is
    # ≤ its end because the row cumsum only adds non-negative durations).
    t_in_piece = np.cumsum(dur, axis=1)
    piece_dur = t_in_piece[:, -1]
    piece_end_time = np.cumsum(piece_dur)
    piece_start_time = np.concatenate(([0.0], piece_end_time[:-1]))
    offsets = np.concatenate((np.zeros((k, 1)), t_in_piece[:, :-1]), axis=1)
    t0 = piece_start_time[:, None] + offsets

    keep = (dur > 0.0).ravel()
    piece_idx = np.repeat(np.arange(k, dtype=np.int64), 7)
    return Profile(
        total_length_mm=float(bounds[-1]),
        duration_s=float(piece_end_time[-1]),
        junction_speeds_mm_s=frozen_array(v),
        piece_peak_speed_mm_s=frozen_array(v_p),
        piece_start_mm=frozen_array(start),
        piece_start_time_s=frozen_array(piece_start_time),
        phase_start_time_s=frozen_array(t0.ravel()[keep]),
        phase_duration_s=frozen_array(dur.ravel()[keep]),
        phase_s0_mm=frozen_array(s0.ravel()[keep]),
        phase_v0_mm_s=frozen_array(v0.ravel()[keep]),
        phase_a0_mm_s2=frozen_array(a0.ravel()[keep]),
        phase_jerk_mm_s3=frozen_array(jerk.ravel()[keep]),
        phase_piece_index=frozen_array(piece_idx[keep], dtype=np.int64),
    )
