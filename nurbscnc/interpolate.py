"""The interpolator: one reference point per servo period T_s (SPEC §4, §10).

Given a planned profile s(t) over the pieces, the reference point at t_k = k·T_s is the point
of the path at arc length s(t_k), placed exactly: PH pieces by Newton on their closed-form
arc length (SPEC §4, eq. 10–12), NURBS pieces by inverting their Gauss–Legendre arc-length
table (SPEC §10), lines and arcs in closed form. Dwells hold the point for their duration.
All per-sample work is whole-array numpy; the only Python loop is over pieces.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class Samples:
    """Reference points at the servo period.

    ``t_s`` (N,) [s] = k·T_s; ``points_mm`` (N, 3) [mm]; ``s_mm`` path length [mm];
    ``v_mm_s`` planned feed [mm/s]; ``a_mm_s2`` tangential acceleration [mm/s²];
    ``piece`` index of the piece; ``line`` source line of that piece.
    """

    t_s: np.ndarray
    points_mm: np.ndarray
    s_mm: np.ndarray
    v_mm_s: np.ndarray
    a_mm_s2: np.ndarray
    piece: np.ndarray
    line: np.ndarray


def dwell_schedule(pieces, profile) -> tuple[np.ndarray, np.ndarray]:
    """Profile times [s] at which dwells start and their durations [s] (sorted)."""
    at, dur = [], []
    for i, p in enumerate(pieces):
        if p.dwell_after_s > 0.0:
            t = profile.piece_start_time_s[i + 1] if i + 1 < len(pieces) else profile.duration_s
            at.append(float(t))
            dur.append(float(p.dwell_after_s))
    return np.asarray(at, dtype=float), np.asarray(dur, dtype=float)


def total_time_s(profile, dwell_durations_s: np.ndarray) -> float:
    """Cycle time [s]: the profile's duration plus all dwells."""
    return float(profile.duration_s + dwell_durations_s.sum())


def wall_to_profile_time(t_wall: np.ndarray, dwell_at_s: np.ndarray, dwell_s: np.ndarray):
    """Map wall-clock times to profile times: during a dwell the profile time stands still."""
    if dwell_at_s.size == 0:
        return t_wall
    offsets = np.concatenate(([0.0], np.cumsum(dwell_s)))
    wall_start = dwell_at_s + offsets[:-1]  # wall time at which dwell j begins
    j = np.searchsorted(wall_start, t_wall, side="right") - 1  # last dwell begun, or -1
    tau = t_wall.copy()
    has = j >= 0
    jj = j[has]
    inside = t_wall[has] < wall_start[jj] + dwell_s[jj]
    tau_has = np.where(inside, dwell_at_s[jj], t_wall[has] - offsets[jj + 1])
    tau[has] = tau_has
    return tau


def place_points(pieces, profile, s_mm: np.ndarray, piece_idx: np.ndarray) -> np.ndarray:
    """Exact points [mm] (N, 3) at path lengths ``s_mm`` on pieces ``piece_idx``.

    Lines and rapids (the bulk of CAM programs) are placed in one vectorised step; every other
    piece kind by its own exact method, one call per piece over all of its samples.
    """
    n = s_mm.size
    out = np.empty((n, 3))
    if n == 0:
        return out
    starts = profile.piece_start_mm
    local = s_mm - starts[piece_idx]
    kinds = np.array([p.kind in ("line", "rapid") for p in pieces])
    lin = kinds[piece_idx]
    if lin.any():
        p0 = np.array([p.geometry.start_mm if kinds[i] else (0.0, 0.0, 0.0)
                       for i, p in enumerate(pieces)], dtype=float)  # fmt: skip
        d = np.array([p.geometry.direction if kinds[i] and p.length_mm > 0 else (0.0, 0.0, 0.0)
                      for i, p in enumerate(pieces)], dtype=float)  # fmt: skip
        idx = piece_idx[lin]
        lengths = np.array([p.length_mm for p in pieces])
        loc = np.clip(local[lin], 0.0, lengths[idx])
        out[lin] = p0[idx] + d[idx] * loc[:, None]
    other = np.flatnonzero(~lin)
    if other.size:
        # Piece indices are non-decreasing in time, so samples come in runs. NURBS cells of one
        # curve are evaluated together (one arc-length inversion over the whole run); every
        # other piece by its own exact method over its samples.
        idx = piece_idx[other]
        is_nurbs = np.array([p.kind == "nurbs" for p in pieces])
        seg = np.array([p.segment for p in pieces])
        s_a = np.array([p.s_a_mm for p in pieces])
        key = np.where(is_nurbs[idx], -1 - seg[idx], idx)
        cuts = np.flatnonzero(np.diff(key)) + 1
        for group in np.split(other, cuts):
            first = int(piece_idx[group[0]])
            piece = pieces[first]
            if piece.kind == "nurbs":
                gi = piece_idx[group]
                s_curve = s_a[gi] + np.clip(local[group], 0.0, lengths_all(pieces)[gi])
                curve = piece.geometry
                out[group] = curve.point(curve.param_at_length(s_curve))
            else:
                out[group] = piece.points_mm(local[group])
    return out


def lengths_all(pieces) -> np.ndarray:
    """Piece lengths [mm] as an array."""
    return np.array([p.length_mm for p in pieces])


def sample_plan(pieces, profile, period_s: float, dwell_at_s=None, dwell_s=None) -> Samples:
    """Reference points at t_k = k·T_s from 0 until the end (SPEC §1, interpolator).

    The last sample is the first k·T_s at or after the end of motion: the tool is at rest at
    the programmed end point there, and every pair of consecutive samples is T_s apart.
    """
    if dwell_at_s is None:
        dwell_at_s, dwell_s = dwell_schedule(pieces, profile)
    total = total_time_s(profile, dwell_s)
    n = int(np.ceil(total / period_s - 1e-9)) + 1
    t = np.arange(n) * period_s
    tau = wall_to_profile_time(t, dwell_at_s, dwell_s)
    s, v, a, _, piece = profile.sample(tau)
    points = place_points(pieces, profile, s, piece)
    lines = np.array([p.line for p in pieces], dtype=np.int64)[piece]
    return Samples(t, points, s, v, a, piece, lines)
