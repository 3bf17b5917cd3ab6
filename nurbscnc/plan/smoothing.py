"""Dense CAM polylines as curvature-continuous splines (by default; ``--no-smooth``).

CAM output writes a curved surface pass as thousands of short G1 chords (0.01–1 mm). Under
G64 every vertex is blended, and a blend meets its lines with zero curvature: along a chain
of blends the curvature swings 0 → peak → 0 on every chord, the normal acceleration v²κ
with it, so the jerk limit holds the feed far below the programmed F (a 2,000-line spiral
finishing pass of 0.05 mm chords at F1200–2400: 8.69 s planned, 5.06 s kinematic lower
bound, LinuxCNC 2.9 in 5.57 s without a jerk limit). The shape the CAM system sampled is
smooth; a cubic B-spline through the chords' neighbourhood has continuous curvature, so the
feed is set by the curve's own curvature and the programmed F.

A *run* is a chain of consecutive feed lines, each at most :data:`DENSE_MAX_MM` long, under
G64 (P, or the machine's path tolerance without P) with one path mode, turning
by at most :data:`MAX_TURN_DEG` at each inner vertex (a sharper vertex is a corner the CAM
system meant: the run ends there and the blend handles it), at least :data:`MIN_RUN` lines
and at most :data:`MAX_RUN` (longer runs are cut into runs of that many). Each run becomes
one cubic B-spline: least squares (``scipy.interpolate.make_lsq_spline``'s QR, a banded solve:
:mod:`nurbscnc.geometry.splinefit`)
on the run's vertices at chord-length parameters, with a knot at every K-th vertex, the end
vertices held exactly (weights 1e6, then the end control points set to the end vertices: a
clamped spline starts and ends at them). K is tried from :data:`KNOT_STEPS` (fewest knots
first: the smoothest curve) and the first spline within ``SHARE`` × tolerance of the
polyline, both ways, is taken; a run no K fits stays lines. The spline is then cut by knot
insertion where the programmed feed changes and every :data:`MAX_PIECE` lines, into
segments that join with the spline's own C2 continuity: nothing to blend or stop there.

The deviation bound is conservative. Each spline sample is measured to the polyline chords
within :data:`WINDOW` vertices of its own parameter (the distance to a subset of the chords
is at least the distance to the polyline), each vertex to the chords between spline samples
near it, plus the samples' sagitta bound Δu²·max|C″|/8 (a chord of the spline is at most that
far from the spline between its ends, and the spline's distance to a chord's line rises at
most that far above the interpolation of its sampled values). What the fit did not take
(at least ``1 − SHARE`` of the tolerance: :func:`end_blend_tolerance_mm`) is left to the
blends where a spline meets the lines or splines beside it: the path stays within the
tolerance of the program, as G64 P promises.

On by default wherever a tolerance is granted (G64, G64 P): G64 promises a path within the
tolerance, not the chords, and industrial controls' compressors do the same (Fanuc's G5.1 Q3
"nano smoothing", Siemens' COMPCAD; LinuxCNC's answer is G64 P Q). G61 and G61.1 grant none
and stay exact; ``--no-smooth`` plans every move as written. The plan's summary says what
was fitted (:func:`smoothing_summary`). Each piece the planner cuts
from a spline (cells of ≤ 0.25 mm) reports the source line of the programmed move where it
starts (:meth:`SmoothedRun.line_at`).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import chain

import numpy as np

from nurbscnc.geometry.distinct import distinct_union
from nurbscnc.geometry.segments import Line, Nurbs, blend_tolerance_mm
from nurbscnc.geometry.splinefit import evaluate, evaluate_derivative, insert_knot, lsq_spline
from nurbscnc.plan.rotary import moves_rotary

#: Longest line [mm] a run may hold: a longer line is a straight the CAM system meant.
DENSE_MAX_MM = 1.0
#: Sharpest inner vertex [deg] of a run.
MAX_TURN_DEG = 20.0
#: Fewest and most lines in one fit (the least squares is a banded solve, linear in the
#: run) and most lines in one spline segment (a longer fit is cut, C2, into such pieces).
MIN_RUN = 8
MAX_RUN = 20000
MAX_PIECE = 1000
#: Vertices per knot span tried, fewest knots first.
KNOT_STEPS = (32, 16, 8, 4, 2)
#: Share of the path tolerance the spline may take from the polyline (the rest: the blends
#: at its ends).
SHARE = 0.5
#: Spline samples per polyline chord in the deviation check.
SAMPLES_PER_CHORD = 4
#: Chords either side of a sample's own chord it is measured against (fewer only make the
#: bound larger: it stays an upper bound).
WINDOW = 1
#: Weight of the end vertices in the least squares (1 elsewhere).
END_WEIGHT = 1e6


@dataclass(frozen=True, eq=False)
class SmoothedRun(Nurbs):
    """A run of lines as its spline: a :class:`Nurbs` whose ``blend_mm`` is the share of the
    tolerance left to its end blends (kept under ``--blend-tolerance``, which it already
    counts) and whose ``line`` is its first move's. ``line_u`` (n,): the spline parameter
    where each of its n programmed moves starts (its start vertex's), ``line_numbers`` (n,)
    their source lines."""

    line_u: np.ndarray | None = None
    line_numbers: np.ndarray | None = None
    #: The fit's bound on its two-way distance to its run's polyline [mm]
    #: (:func:`spline_deviation_mm`), and the run's index in the program (the pieces of one
    #: run share it).
    deviation_mm: float = 0.0
    run: int = 0

    smoothed = True

    def line_at(self, u: float) -> int:
        """The source line of the programmed move whose stretch holds parameter ``u``."""
        i = int(np.searchsorted(self.line_u, u, side="right")) - 1
        return int(self.line_numbers[max(i, 0)])


def _runs(
    p0: np.ndarray, p1: np.ndarray, ok: np.ndarray, key: np.ndarray, adjacent: np.ndarray
) -> list[tuple[int, int]]:
    """Runs [a, b) of consecutive candidate lines (module doc), as positions in the columns:
    ``ok`` (m,) candidates, ``key`` (m, c) values whose change breaks a run (the path mode;
    a feed change does not: the spline is cut there, C2),
    ``adjacent`` (m − 1,) line j + 1 follows line j in the program."""
    d = p1 - p0
    length = np.sqrt(np.einsum("ij,ij->i", d, d))
    unit = d / np.where(length > 0.0, length, 1.0)[:, None]
    cos_turn = np.einsum("ij,ij->i", unit[:-1], unit[1:])
    joined = (
        adjacent
        & ok[:-1]
        & ok[1:]
        & np.all(key[1:] == key[:-1], axis=1)
        & (cos_turn >= np.cos(np.radians(MAX_TURN_DEG)))
    )
    # Runs are maximal stretches of `joined` junctions (plus lone candidates, dropped below).
    edges = np.flatnonzero(np.diff(np.concatenate(([False], joined, [False])).astype(np.int8)))
    out = []
    for a, b in zip(edges[0::2].tolist(), edges[1::2].tolist()):
        first, stop = a, b + 1  # junctions a..b−1 join lines a..b
        for lo in range(first, stop, MAX_RUN):
            hi = min(lo + MAX_RUN, stop)
            if hi - lo >= MIN_RUN:
                out.append((lo, hi))
    return out


def _segment_distance_mm(q: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance [mm] from points ``q`` (..., 3) to the segments from ``a`` to ``b`` (..., 3)
    (broadcast together): the exact point-to-segment distance."""
    ab = b - a
    ab2 = np.einsum("...j,...j->...", ab, ab)
    f = np.clip(np.einsum("...j,...j->...", q - a, ab) / np.where(ab2 > 0.0, ab2, 1.0), 0.0, 1.0)
    r = q - a - f[..., None] * ab
    return np.sqrt(np.einsum("...j,...j->...", r, r))


def _windowed_distance_mm(q: np.ndarray, own: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Upper bound [mm] on the distance of each point ``q`` (k, 3) to the polyline ``poly``
    (n, 3): the least distance to its chords ``own − WINDOW … own + WINDOW`` (clipped)."""
    n_chords = poly.shape[0] - 1
    idx = np.clip(own[:, None] + np.arange(-WINDOW, WINDOW + 1)[None, :], 0, n_chords - 1)
    return _segment_distance_mm(q[:, None, :], poly[idx], poly[idx + 1]).min(axis=1)


def spline_deviation_mm(
    knots: np.ndarray, ctrl: np.ndarray, u: np.ndarray, vertices: np.ndarray
) -> float:
    """Upper bound [mm] on the two-way distance (Hausdorff) between the cubic B-spline
    (``knots``, ``ctrl`` (n, 3) [mm]) on [0, 1] and the polyline ``vertices`` (n + 1, 3) at
    chord-length parameters ``u`` (module doc: windowed chord distances plus the samples'
    sagitta bound)."""
    n = vertices.shape[0] - 1
    per = SAMPLES_PER_CHORD
    # Spline samples: `per` per chord, each measured near its own chord.
    frac = np.arange(per) / per
    us = np.concatenate(((u[:-1, None] + frac[None, :] * np.diff(u)[:, None]).ravel(), [1.0]))
    own = np.minimum(np.arange(us.size) // per, n - 1)
    pts = evaluate(knots, ctrl, us)
    to_poly = _windowed_distance_mm(pts, own, vertices)
    # Vertices to the chords between spline samples near them (sample i·per is at u_i).
    to_curve = _windowed_distance_mm(vertices, np.minimum(np.arange(n + 1) * per, us.size - 2), pts)
    # Between samples Δu apart: a chord of the curve is within M Δu²/8 of it (|C″| ≤ M per
    # unit parameter), and the curve's distance to a chord line, whose second derivative is
    # at most M too, exceeds the interpolation of its sampled values by at most as much.
    du = float(np.max(np.diff(us)))
    second = evaluate_derivative(knots, ctrl, us, 2)
    sag = float(np.sqrt(np.einsum("ij,ij->i", second, second)).max()) * du * du / 8.0
    return float(max(to_poly.max(), to_curve.max()) + sag)


def end_blend_tolerance_mm(tolerance_mm: float, deviation_mm: float, reserve_mm: float) -> float:
    """The tolerance [mm] a smoothed run leaves to the blends at its ends: its path
    tolerance P less what the spline may already take, its fit's bound on the two-way
    distance to the run's polyline (``deviation_mm``) and the PH fit tolerance of a corner
    the planner may still find inside it (``reserve_mm``). A blend within the rest of the
    spline and the line beside it is within P of the programmed path (triangle inequality:
    each blend point within P − δ − r of a point of the pieces, those within δ + r of the
    polyline). At least (1 − SHARE)·P, as the fit took at most SHARE·P − r."""
    return tolerance_mm - deviation_mm - reserve_mm


def fit_run(vertices: np.ndarray, tolerance_mm: float):
    """The cubic B-spline (knots (n + 4,), control points (n, 3) [mm], the vertices'
    parameters (k + 1,) and its deviation bound [mm]) of a run's ``vertices`` (k + 1, 3) [mm]
    within ``tolerance_mm`` both ways, ends exact; None when no knot spacing of
    :data:`KNOT_STEPS` fits (module doc)."""
    chord = np.sqrt(np.sum(np.diff(vertices, axis=0) ** 2, axis=1))
    s = np.concatenate(([0.0], np.cumsum(chord)))
    if not s[-1] > 0.0:
        return None
    u = s / s[-1]
    u[-1] = 1.0
    w = np.ones(u.size)
    w[0] = w[-1] = END_WEIGHT
    n = u.size - 1
    for step in KNOT_STEPS:
        if n < 2 * step:  # at least two spans
            continue
        inner = u[step : n - step // 2 : step]
        t = np.concatenate(([0.0] * 4, inner, [1.0] * 4))
        try:
            c = lsq_spline(u, vertices, t, w)
        except (ValueError, np.linalg.LinAlgError):
            continue
        c = np.array(c, dtype=float)
        c[0], c[-1] = vertices[0], vertices[-1]  # clamped: the curve's ends
        deviation_mm = spline_deviation_mm(t, c, u, vertices)
        if deviation_mm <= tolerance_mm:
            return t, c, u, deviation_mm
    return None


def split_spline(knots: np.ndarray, ctrl: np.ndarray, cuts: np.ndarray) -> list[tuple]:
    """The cubic B-spline (``knots`` on [0, 1], ``ctrl``) cut at the parameters ``cuts``
    (increasing, inside (0, 1)) into clamped pieces (knots rescaled to [0, 1], control
    points): each cut knot raised to multiplicity 4 by knot insertion (Boehm; scipy's
    ``BSpline.insert_knot``, :func:`~nurbscnc.geometry.splinefit.insert_knot`), which leaves
    the curve as it is, so the pieces join with the curve's own continuity (C2 where the cut
    was a simple knot or none)."""
    t, c = np.ascontiguousarray(knots, dtype=float), np.ascontiguousarray(ctrl, dtype=float)
    for u0 in np.asarray(cuts, dtype=float).tolist():
        have = int(np.count_nonzero(t == u0))
        if have < 4:
            t, c = insert_knot(t, c, u0, 4 - have)
    out, lo = [], 0.0
    for hi in [*np.asarray(cuts, dtype=float).tolist(), 1.0]:
        first = int(np.searchsorted(t, lo, side="left"))  # the four knots at lo
        last = int(np.searchsorted(t, hi, side="right"))  # past the four knots at hi
        tk = (t[first:last] - lo) / (hi - lo)
        tk[:4], tk[-4:] = 0.0, 1.0
        out.append((tk, c[first : last - 4].copy()))
        lo = hi
    return out


def _turnaround_sides(
    p0: np.ndarray, p1: np.ndarray, cap: np.ndarray, tol: np.ndarray, adjacent, machine, turns
) -> np.ndarray:
    """Lines (indices into the columns) just before and after a turn-around's middle line
    that the planner will round by one U curve: three adjacent lines whose outer two reverse
    the tangent by at least :data:`~nurbscnc.plan.turnarounds.MIN_REVERSAL_DEG`, for which
    :func:`~nurbscnc.plan.turnarounds.turn_choice` takes a U (``cap`` (m,) the lines' feed
    caps [mm/s], ``tol`` (m,) their tolerances [mm]). They stay lines, out of every run:
    the U trims lines, not splines. ``turns``: None or the memo of the answers
    (:func:`~nurbscnc.plan.turnarounds.remembered_turn_choice`)."""
    from nurbscnc.plan.turnarounds import MIN_REVERSAL_DEG, remembered_turn_choice

    d = p1 - p0
    unit = d / np.maximum(np.sqrt(np.einsum("ij,ij->i", d, d)), 1e-300)[:, None]
    reversed_ = np.einsum("ij,ij->i", unit[:-2], unit[2:]) <= np.cos(np.radians(MIN_REVERSAL_DEG))
    middle = np.flatnonzero(adjacent[:-1] & adjacent[1:] & reversed_) + 1
    middle = middle[np.min([tol[middle - 1], tol[middle], tol[middle + 1]], axis=0) > 0.0]
    taken = [
        i
        for i in middle.tolist()
        if remembered_turn_choice(
            turns,
            p0[i - 1 : i + 2],
            p1[i - 1 : i + 2],
            cap[i - 1 : i + 2],
            float(tol[i - 1 : i + 2].min()),
            machine,
        )
        is not None
    ]
    taken = np.asarray(taken, dtype=np.int64)
    return distinct_union(taken - 1, taken + 1)


def smooth_runs(
    segments,
    source: np.ndarray,
    machine,
    blend_override_mm: float | None = None,
    reserve_mm: float = 0.0,
    turns: dict | None = None,
) -> tuple[list, np.ndarray]:
    """The segments with every run of dense feed lines (module doc) replaced by a
    :class:`SmoothedRun` within SHARE × its path tolerance less ``reserve_mm`` (the PH fit
    tolerance of a corner the planner may still find inside the spline), its end blends
    within the rest, and the program index of each result segment (``source`` carried: a
    spline takes its run's last line's). ``machine``: its path tolerance serves G64
    without P (:func:`~nurbscnc.geometry.segments.blend_tolerance_mm`); ``blend_override_mm``:
    ``--blend-tolerance`` (it overrides every mode). ``turns``: None, or a dict that keeps
    the turn-arounds' answers for the planner
    (:func:`~nurbscnc.plan.turnarounds.remembered_turn_choice`)."""
    segs = list(segments)
    is_line = np.fromiter(
        # Lines that turn A B C are left alone: A moves linearly along each of them.
        (type(s) is Line and not s.rapid and not moves_rotary(s) for s in segs),
        dtype=bool,
        count=len(segs),
    )
    rows = np.flatnonzero(is_line)
    if rows.size < MIN_RUN:
        return segs, source
    lines = [segs[i] for i in rows.tolist()]
    m = len(lines)
    p0 = np.fromiter(chain.from_iterable(s.start_mm for s in lines), float, 3 * m).reshape(m, 3)
    p1 = np.fromiter(chain.from_iterable(s.end_mm for s in lines), float, 3 * m).reshape(m, 3)
    feed = np.fromiter((s.feed_mm_s for s in lines), float, m)
    mode = np.fromiter((s.blend_mm for s in lines), float, m)
    tol = (
        np.full(m, float(blend_override_mm))
        if blend_override_mm is not None
        else blend_tolerance_mm(mode, machine.limits.path_tolerance_mm)
    )
    length = np.sqrt(np.sum((p1 - p0) ** 2, axis=1))
    ok = (tol > 0.0) & (length > 0.0) & (length <= DENSE_MAX_MM)
    adjacent = (rows[1:] == rows[:-1] + 1) & np.all(p1[:-1] == p0[1:], axis=1)
    cap = np.maximum(np.minimum(feed, machine.limits.v_max_mm_s), 1e-6)  # as the planner's
    ok[_turnaround_sides(p0, p1, cap, tol, adjacent, machine, turns)] = False
    replaced: dict[int, tuple[int, Nurbs]] = {}  # first row → (last row, spline)
    for a, b in _runs(p0, p1, ok, mode[:, None], adjacent):
        vertices = np.vstack((p0[a : a + 1], p1[a:b]))
        room = SHARE * float(tol[a]) - reserve_mm
        fit = fit_run(vertices, room) if room > 0.0 else None
        if fit is None:
            continue
        knots, ctrl, u, deviation_mm = fit
        # One spline over the run, cut where the feed changes and every MAX_PIECE lines: the
        # cuts keep the spline's C2 (no blend, no break), each piece has its own feed.
        change = np.flatnonzero(feed[a + 1 : b] != feed[a : b - 1]) + 1
        starts = distinct_union(change, np.arange(MAX_PIECE, b - a, MAX_PIECE)).astype(np.int64)
        bounds = [0, *starts.tolist(), b - a]
        numbers = np.fromiter((s.line for s in lines[a:b]), dtype=np.int64, count=b - a)
        for (la, lb), (tk, ck) in zip(
            zip(bounds[:-1], bounds[1:]), split_spline(knots, ctrl, u[starts])
        ):
            lo, hi = u[la], u[lb]
            spline = SmoothedRun(
                3,
                tk,
                ck,
                np.ones(ck.shape[0]),
                float(feed[a + la]),
                int(numbers[la]),
                "XY",
                end_blend_tolerance_mm(float(tol[a]), deviation_mm, reserve_mm),
                line_u=(u[la:lb] - lo) / (hi - lo),
                line_numbers=numbers[la:lb],
                deviation_mm=deviation_mm,
                run=a,
            )
            replaced[int(rows[a + la])] = (int(rows[a + lb - 1]), spline)
    if not replaced:
        return segs, source
    out, origin, i = [], [], 0
    while i < len(segs):
        hit = replaced.get(i)
        if hit is None:
            out.append(segs[i])
            origin.append(int(source[i]))
            i += 1
        else:
            last, spline = hit
            out.append(spline)
            origin.append(int(source[last]))
            i = last + 1
    return out, np.asarray(origin, dtype=np.int64)


def smoothing_summary(segments) -> dict | None:
    """What smoothing did, of the planned ``segments`` (the :class:`SmoothedRun` among
    them counted): ``runs`` fitted, programmed ``lines`` they replace,
    ``deviation_max_um`` the largest fit's bound on its distance to its polyline [µm] (the
    end blends add at most the rest of the tolerance). None: nothing was smoothed."""
    pieces = [s for s in segments if getattr(s, "smoothed", False)]
    if not pieces:
        return None
    return {
        "runs": len({s.run for s in pieces}),
        "lines": int(sum(s.line_numbers.size for s in pieces)),
        "deviation_max_um": 1000.0 * max(s.deviation_mm for s in pieces),
    }
