"""The junctions between pieces: their tangent turning, which breaks are passed at speed
and where the tool stops, the curvature jumps there, and the resulting junction caps."""

from __future__ import annotations

import numpy as np

from nurbscnc.machine.caps import JUNCTION_SHARE
from nurbscnc.machine.profile import Machine
from nurbscnc.plan.pieces import PieceList

#: Junctions whose tangents turn by less than this [rad] are treated as smooth (no stop).
SMOOTH_JUNCTION_RAD = 1e-6


def pass_velocity_jump_mm_s(machine: Machine) -> float:
    """The largest jump [mm/s] of the velocity vector at a tangent break that is passed at
    full speed, with no blend and no slow-down: min(A_max·T, J_max·T², 4δ/T).

    A break where the tangent turns by θ, passed at speed v, changes the velocity vector by
    |Δv| = 2v sin(θ/2) between two servo periods T. On the reference points (one per T) that
    is an acceleration |Δv|/T and a jerk |Δv|/T² (finite differences), and the straight step
    between the two points that straddle the vertex cuts the corner by at most
    (vT/2) sin(θ/2) = |Δv| T/4 (the points themselves stay on the programmed path). So a break
    is within the machine's limits and its chord tolerance δ (SPEC eq. 23) at speed v exactly
    when |Δv| ≤ min(A_max T, J_max T², 4δ/T). With the paper's machine (T = 1 ms, J_max =
    5e4 mm/s³) the jerk term binds: 0.05 mm/s, i.e. θ ≤ 8.6e-4 rad at 58.3 mm/s. Rounded CAM
    output (1e-5 rad) passes; anything larger is blended (G64) or stopped at (G61)."""
    lim = machine.limits
    period = machine.servo.period_s
    return float(
        min(
            lim.a_max_mm_s2 * period,
            lim.j_max_mm_s3 * period**2,
            4.0 * lim.chord_tolerance_mm / period,
        )
    )


def junction_turning(pieces: PieceList) -> tuple[np.ndarray, np.ndarray]:
    """Tangent turning [rad] at each junction (k − 1): atan2(|t_a × t_b|, t_a · t_b)
    (accurate for small angles, arccos of the dot is not), and whether both tangents exist
    (``regular``: not at a cusp or a zero-length piece)."""
    ta, tb = pieces.tangent_end[:, :-1], pieces.tangent_start[:, 1:]
    cross = np.cross(ta, tb, axis=0)
    turning = np.arctan2(np.sqrt(np.sum(cross * cross, axis=0)), np.sum(ta * tb, axis=0))
    regular = (np.sum(ta * ta, axis=0) > 0.0) & (np.sum(tb * tb, axis=0) > 0.0)
    return turning, regular


def small_breaks(
    pieces: PieceList, turning: np.ndarray, regular: np.ndarray, machine: Machine
) -> np.ndarray:
    """Junctions (k − 1) with a break small enough to pass at the smaller neighbouring cruise
    cap v (no blend, no slow-down): 2v sin(θ/2) · max(1, vT / (L/2)) ≤
    :func:`pass_velocity_jump_mm_s`, θ > :data:`SMOOTH_JUNCTION_RAD`, L the shorter
    neighbouring piece (which a blend may later trim to half). The factor counts the breaks
    one servo step vT can cross when the pieces are shorter than it (a dense polyline): their
    jumps add up within one period. It also bounds the polyline's implied normal
    acceleration, v²θ/L ≤ A_max, since the jump allowed is ≤ A_max T.

    With per-axis limits, each axis's share of the jump, v |t_b,i − t_a,i| · crowd, must also
    stay within that axis's min(A_i T, s J_i T²) (the same finite-difference argument per axis:
    a break of 0.42° at 5 mm/s passed the path's 0.05 mm/s rule and put 0.034 mm/s on the Y
    axis, allowed 0.02 mm/s: on the samples a jerk 7,600 mm/s³ over that axis's limit), s =
    :data:`~nurbscnc.machine.caps.JUNCTION_SHARE`: the pieces on both sides keep their own
    jerk to the rest on that axis (:func:`nurbscnc.plan.axes.piece_limits`), as at a
    curvature jump. With all of J_i T² for the jump, an S-curve crossing the break added its
    own jerk: 25,221 mm/s³ on a Y axis of 2e4 (tests/test_smoothing.py)."""
    cap, length = pieces.v_cap_mm_s, pieces.length_mm
    v = np.minimum(cap[:-1], cap[1:])
    half = 0.5 * np.minimum(length[:-1], length[1:])
    # A zero-length neighbour (half = 0) gives an infinite or NaN crowd and jump: such a
    # junction is not ``regular`` and the NaN compares False, so it never passes.
    with np.errstate(divide="ignore", invalid="ignore"):
        crowd = np.maximum(1.0, v * machine.servo.period_s / half)
        jump = 2.0 * v * np.sin(0.5 * turning) * crowd
        small = jump <= pass_velocity_jump_mm_s(machine)
        if machine.axis_limits.any:
            _, a_axis, j_axis = machine.axis_limits.as_arrays()
            period = machine.servo.period_s
            allow = np.minimum(a_axis * period, JUNCTION_SHARE * j_axis * period**2)[:, None]
            step = pieces.tangent_start[:, 1:] - pieces.tangent_end[:, :-1]  # (3, k − 1)
            small &= np.all(np.abs(step) * (v * crowd) <= allow, axis=0)
    return regular & (turning > SMOOTH_JUNCTION_RAD) & small


def passable_junctions(pieces: PieceList, turning: np.ndarray, regular: np.ndarray) -> np.ndarray:
    """Junctions (k − 1) the tool passes at speed as far as the geometry goes: tangent (≤
    :data:`SMOOTH_JUNCTION_RAD`) or a small break (``pass_after``, :func:`small_breaks`)."""
    return regular & ((turning <= SMOOTH_JUNCTION_RAD) | pieces.pass_after[:-1])


def stopped_junctions(pieces: PieceList) -> np.ndarray:
    """Junctions where the tool must stop whatever the geometry (k − 1): a dwell, pause or
    exact stop (``stop_after``), a rapid meeting a feed move, a zero-length piece."""
    rapid, length = pieces.rapid, pieces.length_mm
    return (
        pieces.stop_after[:-1]
        | (rapid[:-1] != rapid[1:])
        | (length[:-1] == 0.0)
        | (length[1:] == 0.0)
    )


#: Curvature-vector jumps below this [1/mm] are rounding (the cells of one NURBS, an arc cut
#: by a blend): no junction cap (at 58 mm/s it would be 2.6e5 mm/s).
MIN_JUMP_PER_MM = 1e-9


def curvature_jumps(pieces: PieceList) -> tuple[np.ndarray, np.ndarray]:
    """Junctions passed at speed (not stops) where the curvature vector κn jumps: their
    indices j (m,) (between rows j and j + 1) and the jumps Δ(κn) = (κn)_start(j+1) −
    (κn)_end(j) (m, 3) [1/mm], those above :data:`MIN_JUMP_PER_MM`. κn = (C″ − (C″·t) t) /
    |C′|² at the pieces' parameter ends (exact). Lines and the columnar line–line blends (G2
    with their lines: κ = 0 at both ends) have κn = 0 there, so only junctions next to an
    object row (arc, NURBS cell, PH piece) are evaluated, the pieces of one geometry in one
    call. A cusp (C′ = 0) gives κn = 0: such a junction is a stop anyway."""
    k = len(pieces)
    obj = np.array(sorted(pieces.objects), dtype=np.int64)
    if k < 2 or obj.size == 0:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3))
    kn_start, kn_end = np.zeros((k, 3)), np.zeros((k, 3))
    by_geometry: dict[int, list[int]] = {}
    for r in obj.tolist():
        by_geometry.setdefault(id(pieces.objects[r][0]), []).append(r)
    for rows in by_geometry.values():
        g = pieces.objects[rows[0]][0]
        u = np.array([pieces.objects[r][1] for r in rows] + [pieces.objects[r][2] for r in rows])
        d = g.derivatives(u, 2)
        d1, d2 = d[1], d[2]
        sp2 = np.einsum("ij,ij->i", d1, d1)
        ok = sp2 > 0.0
        safe = np.where(ok, sp2, 1.0)
        t = d1 / np.sqrt(safe)[:, None]
        kn = np.where(
            ok[:, None], (d2 - np.einsum("ij,ij->i", d2, t)[:, None] * t) / safe[:, None], 0.0
        )
        n = len(rows)
        kn_start[rows], kn_end[rows] = kn[:n], kn[n:]
    near = np.zeros(k, dtype=bool)
    near[obj] = True
    turning, regular = junction_turning(pieces)
    # Passed at speed.
    moving = passable_junctions(pieces, turning, regular) & ~stopped_junctions(pieces)
    j = np.flatnonzero((near[:-1] | near[1:]) & moving)
    dkn = kn_start[j + 1] - kn_end[j]
    big = np.sqrt(np.einsum("ij,ij->i", dkn, dkn)) > MIN_JUMP_PER_MM
    return j[big], dkn[big]


def junction_caps(pieces: PieceList) -> np.ndarray:
    """Cap at each junction [mm/s] (k+1): 0 at the ends and wherever the tool stops
    (:func:`stopped_junctions`: dwells, pauses, exact stops, rapid/feed changes, zero-length
    pieces), at breaks it cannot pass (:func:`passable_junctions`: a turning above
    :data:`SMOOTH_JUNCTION_RAD` and above the small-break rule of
    :func:`pass_velocity_jump_mm_s`, or a zero tangent: a cusp); else the smaller
    neighbouring cruise cap. One vectorised pass over the cached unit tangents."""
    k = len(pieces)
    caps = np.zeros(k + 1)
    if k < 2:
        return caps
    turning, regular = junction_turning(pieces)
    smooth = passable_junctions(pieces, turning, regular) & ~stopped_junctions(pieces)
    cap = pieces.v_cap_mm_s
    caps[1:-1] = np.where(smooth, np.minimum(cap[:-1], cap[1:]), 0.0)
    # Curvature jumps passed at speed: the acceleration step's jerk (junction_jump_cap_mm_s).
    j = pieces.jump_rows + 1
    caps[j] = np.minimum(caps[j], pieces.jump_cap_mm_s)
    return caps


def settle_time_s(machine: Machine) -> float:
    """Time [s] for the slowest servo mode to decay to e⁻⁵ (< 1 %) of its amplitude."""
    slowest = min(
        (
            float(np.min(np.abs(np.real(ax.poles()))))
            for ax in (machine.servo.x, machine.servo.y, machine.servo.z)
            if ax is not None
        ),
        default=np.inf,
    )  # no servo model: ideal axes, nothing to settle (0 s)
    return 5.0 / slowest
