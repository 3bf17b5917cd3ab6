"""A kinematic lower bound on cycle time (SPEC §10, third bullet).

The fastest any controller could run a path, rest to rest, under the *point-wise* limits only:

* speed:          v ≤ min(V_max, the piece's programmed feed)
* chord error:    v ≤ V_af(κ) = (2/T_s)·√(2δ/κ − δ²)                  (SPEC §7, eq. 23)
* normal accel.:  κ v² ≤ A_max
* tangential:     |dv/dt| ≤ A_max, i.e. |d(v²)/ds| ≤ 2 A_max
* exact stops:    v = 0 at the start, the end, and after every piece flagged ``stop_after``.

There is no jerk limit and the normal and tangential limits are applied separately (not to
|a| as a whole), so every real plan (jerk-limited S-curves, PH corners, re-planning after the
dynamics check) takes at least this long: the bound says how far a plan is from the limit.

Method. The path is sampled on an arc-length grid s_0 < ... < s_n (one grid over all pieces;
each junction appears twice, as the last point of one piece and the first of the next, so a
feed change or a stop acts exactly at the junction). ``cap²`` is the squared speed cap at the
grid points and is taken linear in s between them. The optimum is then known in closed form:

    v²(s) = min( cap²(s), min_j [cap²_j + 2A|s − s_j|] )

(the min over a segment of a linear function plus a cone is attained at its ends or at s
itself). At the grid points this is a forward and a backward pass over squared speeds
(Klipper's look-ahead), done without a Python loop as running minima:

    forward:  min_{j≤i} (cap²_j + 2A(s_i − s_j)) = 2A s_i + cummin_i (cap²_j − 2A s_j)
    backward: min_{j≥i} (cap²_j + 2A(s_j − s_i)) = −2A s_i + reverse-cummin (cap²_j + 2A s_j)

Inside a grid interval v² is the minimum of three lines (the interpolated cap, the cone up
from the left point, the cone down to the right point), i.e. at most three stretches of
constant acceleration; on each the time is exact: Δt = 2Δs/(v_a + v_b), also when one end is
at rest. So the bound is *exact* (to rounding) for any cap whose square is linear in s
between grid points: constant caps (lines, circles) on any grid, whatever the grid spacing.

The only approximation is the linear interpolation of cap² between samples. The grid starts
at spacing ≤ ``ds_mm`` (default 0.01 mm, plus the knots of NURBS pieces; spiral arcs, whose
curvature is analytic, at ``SPIRAL_DS_MM``; a program's NURBS in the summary's bound at
``PROGRAM_DS_MM``) and every interval
is bisected, level by level, while cap² at its midpoint differs from the mean of its ends by
more than ``cap_rel_tol`` (default 1e-5) of its value; a relative error ε in v² is ε/2 in v
and at most about that in time, so the bound is accurate to well below 0.01 % on smooth
paths (measured on the 9 mm NACA 2415: changing ``ds_mm`` 0.01 → 0.0025 mm moves it by
< 1e-6 relative).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from nurbscnc.errors import ConfigError, PlanningError
from nurbscnc.geometry.nurbs import MovedCopies, NurbsCurve
from nurbscnc.geometry.path import Kind, PathTable, stop_seconds, whole_row
from nurbscnc.geometry.paths import geometry_of
from nurbscnc.geometry.segments import blend_tolerance_mm
from nurbscnc.machine.caps import curvature_cap2_mm2_s2
from nurbscnc.machine.profile import Machine
from nurbscnc.plan.rotary import rotary_feed_caps_mm_s, rotate_bounds_s
from nurbscnc.program.columns import DWELL, LINE, PAUSE, RAPID, ROTATE, segment_columns

#: Default largest grid spacing [mm] (SPEC §10).
DEFAULT_DS_MM = 0.01
#: Default bisection tolerance on cap² (relative, at interval midpoints).
DEFAULT_CAP_REL_TOL = 1e-5
#: Bisection levels at most: the finest spacing is ds / 2^levels (0.01 mm → 2.4 nm).
MAX_LEVELS = 12
#: Largest starting grid spacing on spiral arcs [mm] (then bisected like every grid).
SPIRAL_DS_MM = 0.5
#: Starting grid spacing [mm] of a program's NURBS pieces in :func:`program_lower_bound_s`
#: (the summary's bound). Their knots are on the grid (the curvature is smooth between them)
#: and the bisection refines every interval to ``cap_rel_tol``, so the start hardly matters:
#: against a 0.0025 mm start the bound moves by 2.6e-8 relative on the 9 mm NACA 2415,
#: 1.5e-9 on the butterfly, 3e-12 on ten 60 mm airfoils (the tests check 1e-7), and takes
#: half the time of a 0.01 mm start on the airfoils (0.09 → 0.04 s). A peak missed between
#: grid points could only lower the bound (a higher cap): it stays a lower bound.
PROGRAM_DS_MM = 0.05


@dataclass(frozen=True, eq=False)
class LowerBound:
    """The time-optimal speed profile under point-wise limits (see the module docstring).

    ``s_mm`` (n,) the arc-length grid from the path start, non-decreasing (junctions appear
    twice); ``v_mm_s`` (n,) the optimal speed there; ``v_cap_mm_s`` (n,) the point-wise cap
    (0 at rest points); ``t_s`` (n,) the time at which the optimal motion passes each point
    (``t_s[-1] == time_s``); ``piece_start`` (k+1,) grid index of each piece's first point,
    and n at the end (piece i is ``slice(piece_start[i], piece_start[i+1])``).
    """

    time_s: float
    s_mm: np.ndarray
    v_mm_s: np.ndarray
    v_cap_mm_s: np.ndarray
    t_s: np.ndarray
    piece_start: np.ndarray

    @property
    def length_mm(self) -> float:
        """Total path length [mm]."""
        return float(self.s_mm[-1]) if self.s_mm.size else 0.0


# ---------------------------------------------------------------------------------------------
# The 1-D kernel: grid + cap² -> optimal v² and exact time.


def optimal_v2(s_mm: np.ndarray, cap2: np.ndarray, a_max_mm_s2: float) -> np.ndarray:
    """v²_i = min_j (cap²_j + 2A|s_i − s_j|) [mm²/s²] on a non-decreasing grid ``s_mm``.

    The forward and backward passes over squared speeds as running minima (no Python loop);
    ``cap2`` [mm²/s²] must be finite. O(n).
    """
    two_a = 2.0 * a_max_mm_s2
    # Shift s to the grid's middle: halves the size of 2A s and so the cancellation error.
    x = s_mm - 0.5 * (s_mm[0] + s_mm[-1])
    fwd = two_a * x + np.minimum.accumulate(cap2 - two_a * x)
    bwd = np.minimum.accumulate((cap2 + two_a * x)[::-1])[::-1] - two_a * x
    return np.maximum(np.minimum(np.minimum(fwd, bwd), cap2), 0.0)


def interval_times_s(
    s_mm: np.ndarray, v2: np.ndarray, cap2: np.ndarray, a_max_mm_s2: float
) -> np.ndarray:
    """Exact time [s] of each grid interval (n−1,) for the profile of :func:`optimal_v2`.

    ``v2`` the optimal v² at the grid points; ``cap2`` the path's cap² there, interpolated
    linearly in between (without the rest points' zeros: those constrain the point only).

    On [s_i, s_i + h] (x = s − s_i) v² is the minimum of three lines: the cone up from the left
    point F = a + 2A x, the interpolated cap C = c0 + m x and the cone down to the right point
    B = b + 2A(h − x). The minimum is concave, so its active lines come in order of decreasing
    slope: F, then C (only if |m| < 2A and F meets C before B does: x_FC < x_BC), then B;
    otherwise F then B, meeting at x_FB. So v² is linear (constant acceleration) on
    [0, x1], [x1, x2], [x2, h], each timed exactly by Δt = 2Δx/(v_a + v_b). A zero-length
    stretch takes no time; a stretch of positive length at v = 0 takes forever (inf).
    """
    two_a = 2.0 * a_max_mm_s2
    h = np.diff(s_mm)
    a, b = v2[:-1], v2[1:]
    c0 = cap2[:-1]
    with np.errstate(divide="ignore", invalid="ignore"):
        m = np.where(h > 0.0, (cap2[1:] - c0) / h, 0.0)
        x_fb = (b - a + two_a * h) / (2.0 * two_a)
        x_fc = (c0 - a) / (two_a - m)
        x_bc = (b + two_a * h - c0) / (two_a + m)
    cap_active = (np.abs(m) < two_a) & (x_fc < x_bc)
    x1 = np.clip(np.where(cap_active, x_fc, x_fb), 0.0, h)
    x2 = np.clip(np.where(cap_active, x_bc, x_fb), x1, h)

    def v_at(x):
        w = np.minimum(np.minimum(a + two_a * x, b + two_a * (h - x)), c0 + m * x)
        return np.sqrt(np.maximum(w, 0.0))

    def stretch(dx, va, vb):
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(dx > 0.0, 2.0 * dx / (va + vb), 0.0)

    va, v1, v2_, vb = np.sqrt(a), v_at(x1), v_at(x2), np.sqrt(b)
    return stretch(x1, va, v1) + stretch(x2 - x1, v1, v2_) + stretch(h - x2, v2_, vb)


# ---------------------------------------------------------------------------------------------
# Sampling the pieces: curvature from the path model (PathTable), whole arrays over all pieces.


def _sample_rows(
    path: PathTable, rows: np.ndarray, cap2_of, ds_mm: float, rel_tol: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Arc-length grids (from each piece's start) and cap² on them for the pieces ``rows`` of
    ``path``, all pieces at once (see the module docstring): ``(s, cap², sizes)`` with the
    pieces' grids one after the other, ``sizes`` (len(rows),) their point counts.

    ``cap2_of(kappa, j)`` gives cap² [mm²/s²] at curvatures ``kappa`` [1/mm] on the pieces
    ``rows[j]``. Each piece starts on ``ceil(L/ds)`` equal steps plus its NURBS knots (where
    the curvature may jump); then every interval whose midpoint cap² differs from the mean of
    its ends by more than ``rel_tol`` is bisected, level by level, over all pieces together.
    """
    length = np.take(path.length_mm, rows)
    # Spiral arcs start coarser (:data:`SPIRAL_DS_MM`): their curvature is analytic and
    # monotone in the radius, nothing hides between grid points, and the bisection below
    # refines where cap² bends (CAM arcs whose end radii differ by rounding, 1e-7 mm, are
    # spirals: tort.ngc's 118 took 0.3 s on the 0.01 mm grid).
    spacing = np.where(np.take(path.kind, rows) == Kind.SPIRAL, max(ds_mm, SPIRAL_DS_MM), ds_mm)
    steps = np.where(length > 0.0, np.maximum(1, np.ceil(length / spacing)), 1).astype(np.int64)
    owner = np.repeat(np.arange(rows.size), steps + 1)
    first = np.concatenate(([0], np.cumsum(steps + 1)))
    s = (np.arange(owner.size) - first[owner]) * (length / steps)[owner]
    s[first[1:] - 1] = length  # as np.linspace(0, L, n + 1): i·(L/n), exactly L at the end
    # NURBS knots on the grid (their arc lengths from the curve's arc-length table).
    knot_j, knot_s = [], []
    for j in np.flatnonzero((np.take(path.kind, rows) == Kind.NURBS) & (length > 0.0)).tolist():
        curve = path.objects[int(path.obj_id[rows[j]])]
        at = np.clip(curve.arc_length(curve.breakpoints) - path.s_a_mm[rows[j]], 0.0, length[j])
        knot_j.append(np.full(at.size, j))
        knot_s.append(at)
    if knot_s:
        owner = np.concatenate([owner, *knot_j])
        s = np.concatenate([s, *knot_s])
        order = np.lexsort((s, owner))
        owner, s = owner[order], s[order]
        keep = np.ones(s.size, dtype=bool)
        keep[1:] = (owner[1:] != owner[:-1]) | (s[1:] != s[:-1]) | (length[owner[1:]] == 0.0)
        owner, s = owner[keep], s[keep]

    is_line = np.take(path.kind, rows) == Kind.LINE

    def cap2_at(j, s_local):
        # κ = 0 on lines by definition, also on a zero-length one (whose C′ = 0 would
        # otherwise read as a cusp, κ = inf, and stop the tool there).
        kappa = np.zeros(j.size)
        curved = np.flatnonzero(~is_line[j])
        if curved.size:
            kappa[curved] = path.curvature(np.take(rows, j[curved]), s_local[curved])
        return cap2_of(kappa, j)

    c2 = cap2_at(owner, s)
    points, values, owners = [s], [c2], [owner]
    inner = np.flatnonzero(owner[1:] == owner[:-1])  # intervals inside one piece
    j, lo, hi = owner[inner], s[inner], s[inner + 1]
    c_lo, c_hi = c2[inner], c2[inner + 1]
    for _ in range(MAX_LEVELS):
        keep = hi > lo
        j, lo, hi, c_lo, c_hi = j[keep], lo[keep], hi[keep], c_lo[keep], c_hi[keep]
        if not lo.size:
            break
        mid = 0.5 * (lo + hi)
        c_mid = cap2_at(j, mid)
        mean = 0.5 * (c_lo + c_hi)
        bad = np.abs(c_mid - mean) > rel_tol * np.maximum(c_mid, mean)
        if not bad.any():
            break
        points.append(mid[bad])
        values.append(c_mid[bad])
        owners.append(j[bad])
        # Both halves of every bad interval, grouped by piece (one run per piece for the
        # path model's per-piece evaluations; the order within a level does not matter).
        halves = np.argsort(np.concatenate((j[bad], j[bad])), kind="stable")
        j = np.concatenate((j[bad], j[bad]))[halves]
        lo = np.concatenate((lo[bad], mid[bad]))[halves]
        hi = np.concatenate((mid[bad], hi[bad]))[halves]
        c_lo = np.concatenate((c_lo[bad], c_mid[bad]))[halves]
        c_hi = np.concatenate((c_mid[bad], c_hi[bad]))[halves]
    if len(points) == 1:  # no refinement: the grid is in order already
        return s, c2, np.bincount(owner, minlength=rows.size)
    s_all, owner_all = np.concatenate(points), np.concatenate(owners)
    order = np.lexsort((s_all, owner_all))
    sizes = np.bincount(owner_all, minlength=rows.size)
    return s_all[order], np.concatenate(values)[order], sizes


def _per_piece(values, n: int, name: str, dtype) -> np.ndarray:
    arr = np.asarray(values, dtype=dtype)
    if arr.ndim == 0:
        return np.full(n, arr, dtype=dtype)
    if arr.shape != (n,):
        raise PlanningError(f"{name} must be a scalar or have one value per piece ({n})")
    return arr


def lower_bound_time_s(
    geometries: Sequence,
    v_program_mm_s,
    *,
    a_max_mm_s2: float,
    period_s: float,
    chord_tolerance_mm: float,
    v_max_mm_s: float = math.inf,
    stop_after=None,
    ds_mm: float | None = None,
    cap_rel_tol: float = DEFAULT_CAP_REL_TOL,
) -> LowerBound:
    """Kinematic lower bound on the time [s] to run ``geometries`` in order, rest to rest.

    Parameters
    ----------
    geometries
        The pieces end to end, each a LineGeometry, ArcGeometry, NurbsCurve (whole) or
        PHQuintic; they become rows of a :class:`~nurbscnc.geometry.path.PathTable`, the path
        model every sample of curvature comes from.
    v_program_mm_s
        Speed ceiling per piece [mm/s] (programmed feed, rapid rate), scalar or one per piece.
    a_max_mm_s2
        A_max, bounding both the tangential |dv/dt| and the normal κv² acceleration.
    period_s, chord_tolerance_mm
        T_s and δ of the chord-error feed V_af (SPEC §7, eq. 23).
    v_max_mm_s
        A global ceiling applied on top of ``v_program_mm_s`` (default none).
    stop_after
        Per-piece booleans: the tool must be at rest after that piece (e.g. a tangent
        discontinuity). The start and the end are always at rest.
    ds_mm
        Largest grid spacing [mm] (default 0.01 mm); see the module docstring for the
        adaptive refinement (``cap_rel_tol``) and the accuracy.

    Raises ConfigError for bad limits or options, PlanningError for inconsistent inputs or
    when the cap is zero over a stretch of path (the bound is then infinite).
    """
    ds = DEFAULT_DS_MM if ds_mm is None else float(ds_mm)
    for name, value in (
        ("a_max_mm_s2", a_max_mm_s2),
        ("period_s", period_s),
        ("chord_tolerance_mm", chord_tolerance_mm),
        ("ds_mm", ds),
        ("cap_rel_tol", cap_rel_tol),
    ):
        if not (math.isfinite(value) and value > 0.0):
            raise ConfigError(f"{name} must be a finite number > 0, got {value!r}")
    if not v_max_mm_s > 0.0:
        raise ConfigError(f"v_max_mm_s must be > 0, got {v_max_mm_s!r}")
    pieces = list(geometries)
    k = len(pieces)
    if k == 0:
        raise PlanningError("lower bound of an empty path")
    v_top = np.minimum(_per_piece(v_program_mm_s, k, "v_program_mm_s", float), v_max_mm_s)
    if not np.all(np.isfinite(v_top) & (v_top > 0.0)):
        raise PlanningError("every piece needs a finite speed ceiling > 0 [mm/s]")
    stops = (
        np.zeros(k, dtype=bool)
        if stop_after is None
        else _per_piece(stop_after, k, "stop_after", bool)
    )

    path = PathTable.of([whole_row(g) for g in pieces])

    def cap2_of(kappa, j):
        return curvature_cap2_mm2_s2(kappa, v_top[j], a_max_mm_s2, period_s, chord_tolerance_mm)

    s_local, c2, sizes = _sample_rows(path, np.arange(k), cap2_of, ds, cap_rel_tol)
    piece_start = np.concatenate(([0], np.cumsum(sizes)))
    # Piece offsets: the sum of the grids' last points (each piece's length), in order.
    ends = s_local[piece_start[1:] - 1]
    offset = np.concatenate(([0.0], np.cumsum(ends)[:-1]))
    s_mm = s_local + np.repeat(offset, sizes)
    return _solve(s_mm, c2, piece_start, stops, a_max_mm_s2)


def _solve(
    s_mm: np.ndarray,
    path_cap2: np.ndarray,
    piece_start: np.ndarray,
    stops: np.ndarray,
    a_max_mm_s2: float,
) -> LowerBound:
    """The bound on the grid ``s_mm`` (absolute s [mm], piece i on
    ``piece_start[i]:piece_start[i+1]``) with the path's cap² ``path_cap2``, at rest at both
    ends and after the pieces flagged in ``stops``."""
    # Rest at the start, at the end and at every exact stop (both copies of the junction):
    # point constraints for the passes; between grid points the path's own cap still holds.
    cap2 = path_cap2.copy()
    cap2[0] = 0.0
    cap2[-1] = 0.0
    last = piece_start[1:] - 1
    cap2[last[stops]] = 0.0
    cap2[piece_start[1:-1][stops[:-1]]] = 0.0

    v2 = optimal_v2(s_mm, cap2, a_max_mm_s2)
    dt = interval_times_s(s_mm, v2, path_cap2, a_max_mm_s2)
    if not np.all(np.isfinite(dt)):
        i = int(np.flatnonzero(~np.isfinite(dt))[0])
        raise PlanningError(
            f"the speed cap is zero on the path from s = {s_mm[i]:.6g} mm to "
            f"{s_mm[i + 1]:.6g} mm (curvature above 2/δ?): no finite cycle time"
        )
    t_s = np.concatenate(([0.0], np.cumsum(dt)))
    return LowerBound(
        time_s=float(t_s[-1]),
        s_mm=s_mm,
        v_mm_s=np.sqrt(v2),
        v_cap_mm_s=np.sqrt(cap2),
        t_s=t_s,
        piece_start=piece_start,
    )


def machine_lower_bound(
    geometries: Sequence,
    v_program_mm_s,
    machine: Machine,
    *,
    rapid=None,
    stop_after=None,
    ds_mm: float | None = None,
) -> LowerBound:
    """:func:`lower_bound_time_s` with ``machine``'s A_max, T_s, δ and V_max.

    Feeds are capped at V_max; pieces flagged in ``rapid`` (per-piece booleans) run at the
    machine's rapid rate instead, whatever ``v_program_mm_s`` says for them.
    """
    lim = machine.limits
    k = len(geometries)
    top = np.minimum(_per_piece(v_program_mm_s, k, "v_program_mm_s", float), lim.v_max_mm_s)
    if rapid is not None:
        top = np.where(_per_piece(rapid, k, "rapid", bool), lim.rapid_mm_s, top)
    return lower_bound_time_s(
        geometries,
        top,
        a_max_mm_s2=lim.a_max_mm_s2,
        period_s=machine.servo.period_s,
        chord_tolerance_mm=lim.chord_tolerance_mm,
        stop_after=stop_after,
        ds_mm=ds_mm,
    )


def _programmed_geometry(segment, known=None):
    """The geometry of ``segment`` (:func:`~nurbscnc.geometry.paths.geometry_of`), or
    ``known`` when it is the same NURBS curve (degree, knots, control points, weights equal:
    the same curve, whatever tables ``known`` has built)."""
    geom = geometry_of(segment)
    if known is None or not isinstance(geom, NurbsCurve) or not isinstance(known, NurbsCurve):
        return geom
    same = geom.degree == known.degree and all(
        np.array_equal(getattr(geom, f), getattr(known, f))
        for f in ("knots", "control_points_mm", "weights")
    )
    return known if same else geom


def _moved_copies(path: PathTable, rows: np.ndarray, top: np.ndarray):
    """The rows of ``path`` to grid among ``rows`` (whole-curve rows, cap ceilings ``top``):
    (own, copy_of) — ``own`` the positions in ``rows`` gridded, ``copy_of`` (len(rows),)
    for each row the position in ``own`` whose grid it takes: itself, or a NURBS curve of
    which it is a moved copy (:class:`~nurbscnc.geometry.nurbs.MovedCopies`) at the same
    ceiling."""
    copy_of = np.arange(rows.size)
    copies = MovedCopies()
    is_nurbs = np.take(path.kind, rows) == Kind.NURBS
    for j in np.flatnonzero(is_nurbs).tolist():
        curve = path.objects[int(path.obj_id[rows[j]])]
        hit = copies.find(curve, (float(top[j]),))
        if hit is not None:
            copy_of[j] = hit[0]
        else:
            copies.add(curve, j, (float(top[j]),))
    own = np.flatnonzero(copy_of == np.arange(rows.size))
    return own, np.searchsorted(own, copy_of)


def program_lower_bound_s(segments, machine: Machine, columns=None, curves=None) -> float:
    """The lower bound [s] for a whole program's segments (SPEC §10): its own geometry (not
    the PH replacements), rest to rest, with exact stops at tangent discontinuities (turning
    > 1e-6 rad; except corners under G64 P, which a blend may pass at speed), at dwells
    (whose durations are added) and where rapids meet feed moves. No jerk limit, no servo
    settling: nothing can be faster.

    Linear in the program length with small constants: lines (and rapids) are read from the
    segments' columns (:func:`~nurbscnc.program.columns.segment_columns`; ``columns`` if the
    caller has them), length and direction from their end points, κ = 0, without a geometry
    object each; arcs and NURBS blocks become the rows of one path model
    (:class:`~nurbscnc.geometry.path.PathTable`, the programmed geometry, one row a
    segment), which gives their lengths, end tangents and curvature. Pieces of constant
    curvature (lines, circular and helical arcs) need no grid inside them — their cap is
    constant, and the bound is exact on any grid for such caps (module doc) — so they are
    sampled at their two ends only; NURBS and spiral arcs get the adaptive grid of
    :func:`lower_bound_time_s`, all such pieces at once.

    ``curves``: None, or NURBS curves by segment index (a plan's,
    :meth:`~nurbscnc.plan.pieces.PieceList.nurbs_curves`), used where a curve is the
    segment's own (the same degree, knots, control points and weights): their arc-length
    tables are built already (building them again was most of the bound's time on NURBS
    programs). A curve the planner changed (an end hook removed) is not the programmed one
    and is not used.
    """
    lim = machine.limits
    segments = segments if isinstance(segments, (list, tuple)) else list(segments)
    cols = columns if columns is not None else segment_columns(segments)
    is_stop = (cols.kind == DWELL) | (cols.kind == PAUSE) | (cols.kind == ROTATE)
    stops = np.flatnonzero(is_stop).tolist()
    dwell = float(sum(stop_seconds(segments[i]) for i in stops))
    if machine.rotary_axes:  # rotary-only moves rest to rest, A B C's feed caps (trivkins)
        dwell += float(np.sum(rotate_bounds_s(segments, machine, cols)))
    index = np.flatnonzero(~is_stop)
    m = int(index.size)
    if not m:
        return dwell
    kind = cols.kind[index]
    rapid = kind == RAPID
    straight = rapid | (kind == LINE)
    feed = np.where(rapid, 1.0, cols.feeds_mm_s[index])
    top = np.where(rapid, lim.rapid_mm_s, np.minimum(feed, lim.v_max_mm_s))
    if machine.rotary_axes:
        top = np.minimum(top, rotary_feed_caps_mm_s(segments, machine, cols)[index])
    if not np.all(np.isfinite(top) & (top > 0.0)):
        raise PlanningError("every piece needs a finite speed ceiling > 0 [mm/s]")
    length, t_start, t_end = _straight_ends(cols, index, straight)
    cap2 = np.where(straight, top * top, 0.0)  # constant-cap pieces: their cap²
    # Arcs and NURBS blocks: one path-model row each (the programmed geometry, whole).
    curved = np.flatnonzero(~straight)
    path = PathTable.of(
        [
            whole_row(_programmed_geometry(segments[i], (curves or {}).get(i)), segments[i].line)
            for i in index[curved].tolist()
        ]
    )
    grid_rows = _curved_ends(path, curved, top, machine, length, t_start, t_end, cap2)
    s_grid, c2_grid, grid_sizes = _grids(path, grid_rows, top[curved[grid_rows]], machine)
    grid_start = np.concatenate(([0], np.cumsum(grid_sizes)))
    sampled = curved[grid_rows]  # the gridded pieces
    length[sampled] = s_grid[grid_start[1:] - 1]
    stop = _exact_stops(t_start, t_end, cols.blends_mm[index], index, rapid)
    tolerance_mm = blend_tolerance_mm(cols.blends_mm[index], lim.path_tolerance_mm)
    constant = ~np.isin(np.arange(m), sampled)  # not gridded: lines, rapids, arcs
    length -= _blend_savings_mm(t_start, t_end, tolerance_mm, stop, length, constant, straight)
    s_mm, path_cap2, piece_start, last = _bound_points(
        length, cap2, stop, sampled, s_grid, c2_grid, grid_sizes, grid_start
    )
    bound = _solve(s_mm, path_cap2, piece_start, stop[last], lim.a_max_mm_s2)
    return float(bound.time_s) + dwell


def _straight_ends(
    cols, index: np.ndarray, straight: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lengths [mm] (m,) and start and end tangents (m, 3) of the pieces ``index`` of the
    columns ``cols``, filled for the ``straight`` ones (lines, rapids: the end-point
    difference, not normalised) and zero elsewhere."""
    m = int(index.size)
    length = np.zeros(m)
    t_start = np.zeros((m, 3))
    t_end = np.zeros((m, 3))
    li = np.flatnonzero(straight)
    d = cols.ends_mm[index[li]]
    d -= cols.starts_mm[index[li]]  # in place: one (m, 3) array, not four
    t_start[li] = t_end[li] = d
    length[li] = np.sqrt(np.einsum("ij,ij->i", d, d))
    return length, t_start, t_end


def _curved_ends(
    path: PathTable,
    curved: np.ndarray,
    top: np.ndarray,
    machine: Machine,
    length: np.ndarray,
    t_start: np.ndarray,
    t_end: np.ndarray,
    cap2: np.ndarray,
) -> np.ndarray:
    """Fill the ``curved`` pieces' (rows of ``path``) lengths [mm], unit end tangents and,
    for constant curvature (circles, helices), cap² [mm²/s²] (top speeds ``top``); returns
    the rows of ``path`` that need a grid (spirals and NURBS)."""
    lim = machine.limits
    rows = np.arange(curved.size)
    length[curved] = path.length_mm
    # Unit tangents at both ends, one evaluation (start, end interleaved: one run a piece).
    ends = path.tangents(
        np.repeat(rows, 2), np.column_stack((np.zeros(rows.size), path.length_mm)).ravel()
    )
    t_start[curved], t_end[curved] = ends[0::2], ends[1::2]
    # Constant curvature (circles, helices): one cap² each; spirals and NURBS: a grid.
    const = path.kind == Kind.ARC
    cap2[curved[const]] = curvature_cap2_mm2_s2(
        path.curvature(rows[const], np.zeros(int(const.sum()))),
        top[curved[const]],
        lim.a_max_mm_s2,
        machine.servo.period_s,
        lim.chord_tolerance_mm,
    )
    return rows[~const]


def _grids(
    path: PathTable, grid_rows: np.ndarray, top_grid: np.ndarray, machine: Machine
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The adaptive grids of the rows ``grid_rows`` of ``path`` (top speeds ``top_grid``
    [mm/s]): the points [mm] from each row's start and their cap² [mm²/s²], all rows in
    order, and each row's number of points. A curve that is another one moved (a part cut
    again elsewhere) at the same top speed has its grid and caps (κ does not depend on
    where the curve lies): sampled once."""
    lim = machine.limits
    period, chord, a_max = machine.servo.period_s, lim.chord_tolerance_mm, lim.a_max_mm_s2
    own, copy_of = _moved_copies(path, grid_rows, top_grid)

    def cap2_of(kappa, j):
        return curvature_cap2_mm2_s2(kappa, top_grid[own[j]], a_max, period, chord)

    s_own, c2_own, own_sizes = _sample_rows(
        path, grid_rows[own], cap2_of, PROGRAM_DS_MM, DEFAULT_CAP_REL_TOL
    )
    grid_sizes = own_sizes[copy_of]
    at = np.repeat(np.cumsum(own_sizes)[copy_of] - np.cumsum(grid_sizes), grid_sizes)
    take = at + np.arange(at.size)
    return s_own[take], c2_own[take], grid_sizes


def _exact_stops(
    t_start: np.ndarray, t_end: np.ndarray, blend: np.ndarray, index: np.ndarray, rapid: np.ndarray
) -> np.ndarray:
    """Whether the tool stops exactly after each piece (m,): tangent discontinuities
    (turning > 1e-6 rad) not under G64 P (``blend`` > 0 on both sides), dwells (a gap in
    the segment ``index``), rapid/feed changes; the last piece's entry False."""
    ta, tb = t_end[:-1], t_start[1:]
    cross = np.cross(ta, tb)
    turning = np.arctan2(
        np.sqrt(np.einsum("ij,ij->i", cross, cross)), np.einsum("ij,ij->i", ta, tb)
    )
    regular = (np.einsum("ij,ij->i", ta, ta) > 0.0) & (np.einsum("ij,ij->i", tb, tb) > 0.0)
    corner = regular & (turning > 1e-6) & ~(np.minimum(blend[:-1], blend[1:]) > 0.0)
    stop = np.zeros(index.size, dtype=bool)
    stop[:-1] = corner | (index[1:] != index[:-1] + 1) | (rapid[1:] != rapid[:-1])
    return stop


def _blend_savings_mm(
    t_start: np.ndarray,
    t_end: np.ndarray,
    tolerance_mm: np.ndarray,
    stop: np.ndarray,
    length: np.ndarray,
    constant: np.ndarray,
    straight: np.ndarray,
) -> np.ndarray:
    """How much shorter [mm] (m,) each constant-cap piece (``constant``) may be in any plan:
    a corner between pieces that both grant a path tolerance P (G64, G64 P; not at a stop)
    may be cut by a blend, which the plan then runs instead of the corner.

    A blend is a convex curve tangent to both legs at its ends A and B, within P of them
    (its Hausdorff distance to the corner path, :mod:`~nurbscnc.geometry.lineblends`), so
    it crosses the bisector at a point M with |VM| cos(θ/2) ≤ P (V the vertex, θ the
    turning); its length is at least |AM| + |MB| ≥ |AV| + |VB| − 2|VM| sin(θ/2) (the
    projections onto the legs), so a corner saves at most s = 2P tan(θ/2), whatever the
    legs; between two lines (``straight``) of lengths a and b also at most a + b − |AB|
    with A, B their far ends (a + b − |chord| grows with both trims). Blends do not
    overlap, so a piece loses at most min(L, s_before + s_after): the savings each blend
    makes on its two legs are then covered, leg by leg, and the bound stays below every
    plan (on a V-carve's dense 25 µm corners the blended path is 2.4 % shorter than the
    programmed one). Pieces on a grid (NURBS, spirals) keep their length; a blend next to
    one is covered by the constant piece on its other side (or not at all, the rare
    corner between two such pieces)."""
    ta, tb = t_end[:-1], t_start[1:]
    cross = np.cross(ta, tb)
    turning = np.arctan2(
        np.sqrt(np.einsum("ij,ij->i", cross, cross)), np.einsum("ij,ij->i", ta, tb)
    )
    regular = (np.einsum("ij,ij->i", ta, ta) > 0.0) & (np.einsum("ij,ij->i", tb, tb) > 0.0)
    tol = np.minimum(tolerance_mm[:-1], tolerance_mm[1:])
    cut = regular & (turning > 1e-6) & (tol > 0.0) & ~stop[:-1]
    half = 0.5 * turning
    with np.errstate(divide="ignore", over="ignore"):
        save = np.where(cut, 2.0 * tol * np.tan(np.minimum(half, 0.5 * np.pi)), 0.0)
    save = np.where(cut & (half >= 0.5 * np.pi - 1e-12), np.inf, save)  # a reversal
    a, b = length[:-1], length[1:]
    chord = np.sqrt(np.maximum(a * a + b * b + 2.0 * a * b * np.cos(turning), 0.0))
    lines = straight[:-1] & straight[1:]
    save = np.where(lines, np.minimum(save, a + b - chord), save)
    around = np.zeros(length.size)
    around[:-1] += save
    around[1:] += save
    return np.where(constant, np.minimum(length, around), 0.0)


def _bound_points(
    length: np.ndarray,
    cap2: np.ndarray,
    stop: np.ndarray,
    sampled: np.ndarray,
    s_grid: np.ndarray,
    c2_grid: np.ndarray,
    grid_sizes: np.ndarray,
    grid_start: np.ndarray,
):
    """The bound's grid along the whole path: points ``s_mm`` [mm], their cap²
    [mm²/s²], each piece's first point and each piece's last programmed piece (the bound's
    pieces are groups of programmed ones).

    Runs of constant-cap pieces with neither a stop nor a change of cap between them are
    one piece of the bound: their cap is constant along the run, and the bound is exact on
    any grid for such a cap (module doc), so the run's inner junctions are dropped (a CAM
    polyline under G64 P is one run, two points instead of two a line). Gridded pieces
    (``sampled``: their points ``s_grid`` from their starts and caps ``c2_grid``) stay
    pieces of their own."""
    m = length.size
    offset = np.concatenate(([0.0], np.cumsum(length)))
    simple = np.ones(m, dtype=bool)
    simple[sampled] = False
    join = simple[:-1] & simple[1:] & ~stop[:-1] & (cap2[:-1] == cap2[1:])
    first = np.flatnonzero(np.r_[True, ~join])  # each group's first piece
    last = np.r_[first[1:], m] - 1  # and its last
    group_of_sampled = np.searchsorted(first, sampled)  # a gridded piece is its own group
    g_simple = simple[first]
    # Grids: two points on constant-cap groups, the adaptive grid elsewhere.
    sizes = np.full(first.size, 2, dtype=np.int64)
    sizes[group_of_sampled] = grid_sizes
    piece_start = np.concatenate(([0], np.cumsum(sizes)))
    s_mm = np.empty(int(piece_start[-1]))
    path_cap2 = np.empty_like(s_mm)
    at = piece_start[:-1][g_simple]
    s_mm[at], s_mm[at + 1] = offset[first[g_simple]], offset[last[g_simple] + 1]
    path_cap2[at] = path_cap2[at + 1] = cap2[first[g_simple]]
    # The gridded pieces' points, scattered to their places in one step.
    dest = np.repeat(piece_start[group_of_sampled] - grid_start[:-1], grid_sizes) + np.arange(
        s_grid.size
    )
    s_mm[dest] = s_grid + np.repeat(offset[sampled], grid_sizes)
    path_cap2[dest] = c2_grid
    return s_mm, path_cap2, piece_start, last
