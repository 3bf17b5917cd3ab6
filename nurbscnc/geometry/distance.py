"""Point-to-path distance (SPEC §8: the contour error is the distance from the actual point
to the commanded path), measured to the dense polyline of the path
(:mod:`nurbscnc.geometry.polyline`).

Two ways. Near a known point of the path (:func:`windowed_contour_mm`): a reference point
r_k lies on the path, so the nearest path point to the actual point a_k is within
|e_k| = |r_k − a_k| of a_k, hence within 2|e_k| of r_k, and along the path within 2|e_k| of
r_k's arc length s_k unless the path comes back to it from farther along. That distance is
computed exactly (point to segment) to the dense polyline restricted to
s ∈ [s_k − 2|e_k|, s_k + 2|e_k|] (plus the segments crossing its ends): linear in the
program length, built one slab of samples at a time. It is never below the true distance.
To the whole path (:class:`PathIndex`): the pieces near a point found by their bounding
balls (bands of centres or k-d trees), then their polylines' segments, so an overshoot past
the end of a closed contour onto its own start is no error. The polyline is exact on lines
(their end points) and has a chord error below :data:`~nurbscnc.geometry.polyline.CHORD_MM`
on curved pieces.

``pieces`` is a table of pieces as :mod:`nurbscnc.geometry.polyline` says, with their end
points ``start_mm``, ``end_mm`` (3, k) [mm] as well; ``profile`` anything with the path
length at each piece's start ``piece_start_mm`` (k,) and ``total_length_mm`` [mm]
(:class:`nurbscnc.plan.profile.Profile`).
"""

from __future__ import annotations

import numpy as np

from nurbscnc.geometry.compiled import kernels as _kernels  # None: the Python loops
from nurbscnc.geometry.distinct import distinct, distinct_union
from nurbscnc.geometry.nurbs import NurbsCurve
from nurbscnc.geometry.path import Kind
from nurbscnc.geometry.polyline import dense_local, dense_polyline, path_counts, path_lengths

#: Servo samples per slab of the windowed distance.
SLAB = 1 << 16


def _geometry_key(g) -> tuple:
    """A key equal for two geometry objects that place the same points bit for bit: a NURBS
    curve's degree, knots, control points and weights (their bytes); any other object is
    only itself."""
    if isinstance(g, NurbsCurve):
        return (
            "nurbs",
            int(g.degree),
            *(np.ascontiguousarray(x).tobytes() for x in (g.knots, g.control_points_mm, g.weights)),
        )
    return ("object", id(g))


def windowed_contour_mm(
    actual_mm: np.ndarray,
    lag_mm: np.ndarray,
    s_ref_mm: np.ndarray,
    pieces,
    profile,
    index: PathIndex | None = None,
) -> np.ndarray:
    """True distance [mm] from each actual point to the path near its reference (module doc).

    ``actual_mm`` (M, 3); ``lag_mm`` (M,) |reference − actual| [mm]; ``s_ref_mm`` (M,) the
    path length of each reference point. Exact point-to-segment distances to the dense polyline of
    :func:`path_counts`, from its last point before s − W to its first point after s + W,
    W = 2|r − a|. ``index`` (kept across the re-plans of one program): its copy of the
    polyline (:meth:`PathIndex.dense_polyline`) instead of placing the points again.
    """
    m = actual_mm.shape[0]
    out = np.empty(m)
    starts = profile.piece_start_mm
    total = profile.total_length_mm
    k = pieces.length_mm.size
    lag = lag_mm
    for lo in range(0, m, SLAB):
        sl = slice(lo, min(lo + SLAB, m))
        s = s_ref_mm[sl]
        w = 2.0 * lag[sl]
        # The pieces the windows touch, and one more on each side.
        p_lo = max(int(np.searchsorted(starts, float((s - w).min()), side="right")) - 2, 0)
        p_hi = min(int(np.searchsorted(starts, float((s + w).max()), side="right")) + 1, k)
        if index is not None:
            ps, pts = index.dense_polyline(pieces, starts, total, p_lo, p_hi)
        else:
            ps, pts = dense_polyline(pieces, starts, total, p_lo, p_hi)
        # Polyline segments [j, j + 1] covering [s − w, s + w]: from the last point before
        # the window to the first one after it.
        a_idx = np.maximum(np.searchsorted(ps, s - w, side="left") - 1, 0)
        b_idx = np.minimum(np.searchsorted(ps, s + w, side="right"), ps.size - 1)
        b_idx = np.maximum(b_idx, np.minimum(a_idx + 1, ps.size - 1))
        # Polyline segment j runs from point j to point j + 1.
        out[sl] = segment_distances(actual_mm[sl], pts[:-1], np.diff(pts, axis=0), a_idx, b_idx)
    return out


def _dot3(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Row-wise dot products of (n, 3) arrays, as (x₀y₀ + x₁y₁) + x₂y₂: one order on every
    machine (einsum's depends on its SIMD path) and the compiled kernel's."""
    return (x[:, 0] * y[:, 0] + x[:, 1] * y[:, 1]) + x[:, 2] * y[:, 2]


def segment_distances(
    q_mm: np.ndarray, a_mm: np.ndarray, d_mm: np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> np.ndarray:
    """For each point ``q_mm[i]`` (m, 3) [mm], the distance [mm] to the nearest of the
    segments a_k + t·d_k, t ∈ [0, 1], k ∈ [``lo[i]``, ``hi[i]``) (inf where that is empty):
    :func:`_segment_distances_py`, compiled where :mod:`nurbscnc.geometry._kernels` was built
    (the same numbers bit for bit, without its (pairs, 3) temporaries)."""
    q, a, d = (np.ascontiguousarray(x, dtype=np.float64) for x in (q_mm, a_mm, d_mm))
    lo = np.ascontiguousarray(lo, dtype=np.int64)
    hi = np.ascontiguousarray(hi, dtype=np.int64)
    if _kernels is None:
        return _segment_distances_py(q, a, d, lo, hi)
    out = np.empty(q.shape[0])
    _kernels.segment_distances(q, a, d, lo, hi, out)
    return out


def _segment_distances_py(
    q: np.ndarray, a: np.ndarray, d: np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> np.ndarray:
    """:func:`segment_distances` in numpy: every (point, segment) pair at once, a point's
    pairs consecutive, the nearest per point by a segmented minimum. Per pair: t =
    (q − a)·d / |d|² clipped to [0, 1] (0 where |d|² = 0), the distance |q − a − t·d|."""
    out = np.full(q.shape[0], np.inf)
    count = np.maximum(hi - lo, 0)
    has = np.flatnonzero(count)
    if not has.size:
        return out
    count = count[has]
    first = np.cumsum(count) - count
    k = np.repeat(lo[has] - first, count) + np.arange(int(count.sum()))
    ak = np.take(a, k, axis=0)  # take: a gather of rows several times faster than a[k]
    dk = np.take(d, k, axis=0)
    qa = np.take(q, np.repeat(has, count), axis=0) - ak
    len2 = _dot3(dk, dk)
    t = _dot3(qa, dk) / np.where(len2 > 0.0, len2, 1.0)
    t = np.clip(np.where(len2 > 0.0, t, 0.0), 0.0, 1.0)
    e = qa - t[:, None] * dk
    out[has] = np.minimum.reduceat(np.sqrt(_dot3(e, e)), first)
    return out


class PathIndex:
    """Where the pieces of a path are, for the few global distance queries of the check.

    A piece of length L from A to B lies in the ball of radius L/2 about (A + B)/2 (every
    point P of it has |P − A| + |P − B| ≤ L). The pieces are grouped by like radii (short
    pieces, L ≤ ``short_mm``, one group; then doublings) and found, per group, in a band of
    centres sorted along one axis, or by k-d trees over the centres where the bands are too
    full (:meth:`candidates`): testing every long piece's ball for every query would make a
    program of many cuts quadratic. Built on first use and kept across the re-plans of one
    program (the geometry does not change).
    """

    #: Most dense-polyline points kept across queries (48 MB); the cache is emptied when full.
    CACHE_POINTS = 2_000_000
    #: Segments per bounding box of a piece's polyline (the coarse level of the search).
    CHUNK = 64

    #: Most points of the windowed check's polyline kept across re-plans (144 MB; a
    #: 1,000,000-line CAM spiral has 4.8e6): the program's first pieces up to this many
    #: points (a sweep from the start reuses them; an evicting cache would miss every time
    #: on a sweep longer than itself).
    DENSE_POINTS = 6_000_000

    #: Points placed at a time when the polyline is filled.
    FILL_BLOCK = 1 << 16

    #: (point, piece) pairs of a program's queries answered without the k-d trees: by testing
    #: every piece's ball, then through the bands (:meth:`_candidates_banded`).
    DIRECT_PAIRS = 20_000_000
    #: Pairs tested against every piece's ball, per piece of the program, before the bands
    #: are made (sorting the centres costs about as much as testing them all this often).
    BAND_AFTER = 16
    #: Pieces of one radius group below which it is tested directly, without a tree.
    TREE_MIN = 32
    #: Programs of at most this many pieces test all (point, piece) pairs of a query block
    #: at once (:meth:`_candidates_direct`); longer ones a point at a time.
    DIRECT_BLOCK_PIECES = 20_000
    #: Candidates of one query block from which pieces repeating another's geometry are
    #: measured once (:meth:`_distinct`).
    DISTINCT_MIN = 64
    #: Programs of at most this many pieces keep every line's two ends (:meth:`_line_ends`,
    #: 48 bytes a piece: 12 MB at most); longer ones place them for each query block.
    LINE_ENDS_PIECES = 1 << 18

    def __init__(self, pieces, short_mm: float = 1.0):
        self._pieces = pieces
        self._direct = 0  # (point, piece) pairs tested directly so far
        self._balls = None  # (centres (k, 3), radii (k,), centres' x (k,)) [mm]
        self._short_mm = short_mm
        self._bands = None  # the radius groups sorted along an axis (_make_bands)
        self._banded = 0  # (point, piece) pairs tested through the bands so far
        self._built = None
        self._counts = None
        self._lines = None  # (line flags, start points, end points): :meth:`_line_ends`
        # The windowed check's dense polyline of pieces [0, filled): its points and
        # per-piece offsets.
        self._dense = None
        # piece → (dense polyline (c, 3) [mm], box lows, box highs (⌈(c−1)/CHUNK⌉, 3) [mm])
        self._polyline: dict[int, tuple] = {}
        self._cached_points = 0
        self._object_keys = None  # per object: the first object of the same geometry

    def _distinct(self, cand: np.ndarray) -> np.ndarray:
        """``cand`` (sorted pieces) without those whose geometry repeats an earlier one of
        ``cand`` bit for bit — a contour cut again at the same place (spring passes,
        multi-pass engraving: without this the check is quadratic in the passes, every
        query measuring every pass): their polylines, hence their distances, are the same
        numbers, and a point's distance is the minimum. Every column that places a piece's points is
        compared (a PH row only with itself); blocks of fewer than :data:`DISTINCT_MIN`
        candidates are left as they are."""
        if cand.size < self.DISTINCT_MIN:
            return cand
        path = self._pieces.path
        if self._object_keys is None:
            first: dict = {}
            self._object_keys = np.array(
                [first.setdefault(_geometry_key(g), i) for i, g in enumerate(path.objects)] + [-1],
                dtype=np.int64,
            )
        obj = np.take(self._object_keys, np.take(path.obj_id, cand))  # −1 → the last: −1
        ph = np.where(np.take(path.ph_slot, cand) >= 0, cand, -1)  # a PH row: only itself
        # One row per candidate of every column that places its points, as the bits of
        # float64s (−0.0 is not 0.0; the integers are exact in a float).
        columns = [
            np.take(c, cand, axis=-1).reshape(-1, cand.size)
            for c in (
                path.kind,
                self._counts,
                path.length_mm,
                path.radius_mm,
                path.angle_rad,
                path.helix_mm,
                path.u_a,
                path.u_b,
                path.s_a_mm,
                path.start_mm,
                path.end_mm,
                path.origin_mm,
                path.e1,
                path.e2,
                path.normal,
            )
        ]
        rows = np.ascontiguousarray(np.vstack([*columns, obj, ph]).T, dtype=np.float64)
        rows = rows.view(np.int64)
        # Rows grouped by a hash of their bits, then compared whole (a collision keeps both).
        h = np.zeros(rows.shape[0], dtype=np.uint64)
        for column in rows.T:
            h = h * np.uint64(1_000_003) ^ column.view(np.uint64)
        _, first, group = np.unique(h, return_index=True, return_inverse=True)
        rep = first[group]
        keep = (rep == np.arange(rows.shape[0])) | np.any(rows != rows[rep], axis=1)
        return cand[keep]

    def _radius_groups(self) -> list[np.ndarray]:
        """The pieces grouped by the radius of their balls: ≤ short_mm/2, then doublings of
        it (a group's radii within a factor 2 of its largest)."""
        _, radius, _ = self._ball_columns()
        r0 = 0.5 * self._short_mm
        with np.errstate(divide="ignore"):
            cls = np.where(radius <= r0, 0, np.ceil(np.log2(radius / r0))).astype(np.int64)
        return [np.flatnonzero(cls == c) for c in distinct(cls).tolist()]

    def _build(self):
        """The k-d trees of :meth:`candidates`: a tree over the centres of each radius group
        (:meth:`_radius_groups`; one of fewer than :data:`TREE_MIN` pieces is tested
        directly), with the group's largest radius R."""
        from scipy.spatial import cKDTree

        centre, radius, _ = self._ball_columns()
        groups = []
        for idx in self._radius_groups():
            tree = cKDTree(centre[idx]) if idx.size >= self.TREE_MIN else None
            groups.append((idx, tree, float(radius[idx].max())))
        self._built = groups

    def _make_bands(self):
        """The bands of :meth:`_candidates_banded`: each radius group's pieces sorted by
        their centres' coordinate along the axis on which those spread most, with that
        coordinate (sorted), the axis and the group's largest radius R."""
        centre, radius, _ = self._ball_columns()
        bands = []
        for idx in self._radius_groups():
            c = centre[idx]
            axis = int(np.argmax(c.max(axis=0) - c.min(axis=0)))
            order = np.argsort(c[:, axis], kind="stable")
            bands.append(
                (idx[order], np.ascontiguousarray(c[order, axis]), axis, float(radius[idx].max()))
            )
        self._bands = bands

    def _ball_columns(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every piece's ball: centres (k, 3) [mm], radii (k,) [mm] and the centres' x (k,)
        [mm], computed once."""
        if self._balls is None:
            pieces = self._pieces
            centre = np.ascontiguousarray(0.5 * (pieces.start_mm + pieces.end_mm).T)
            self._balls = (centre, 0.5 * pieces.length_mm, np.ascontiguousarray(centre[:, 0]))
        return self._balls

    def _near_balls(self, q: np.ndarray, upper_mm: np.ndarray, idx: np.ndarray) -> np.ndarray:
        """The pieces of ``idx`` whose balls come within ``upper_mm`` of some point of
        ``q`` (|q − c| − r ≤ u), all pairs at once, a block of points at a time (≤ 2^20
        pairs)."""
        centre, radius, _ = self._ball_columns()
        c, r = centre[idx], radius[idx]
        near = np.zeros(idx.size, dtype=bool)
        step = max(1, (1 << 20) // max(idx.size, 1))
        for lo in range(0, q.shape[0], step):
            rel = q[lo : lo + step, None, :] - c[None, :, :]
            gap = np.sqrt(np.einsum("mkc,mkc->mk", rel, rel)) - r[None, :]
            near |= np.any(gap <= upper_mm[lo : lo + step, None], axis=0)
        return idx[near]

    def dense_polyline(
        self, pieces, starts_mm: np.ndarray, total_mm: float, lo: int, hi: int
    ) -> tuple[np.ndarray, np.ndarray]:
        """:func:`~nurbscnc.geometry.polyline.dense_polyline` of pieces ``lo:hi`` of the
        program or of a head of it (its first pieces, as a cut window measures against
        them): the same numbers, the points of the program's first :data:`DENSE_POINTS`
        placed once for every re-plan and window (a point depends on its piece only; the
        path lengths, from the starts of this query, are cheap). A query that reaches past
        the kept pieces' end places the pieces from there to ``hi`` and keeps them (the
        check sweeps forward)."""
        dense = self._dense
        if dense is None:
            off = np.concatenate(([0], np.cumsum(path_counts(self._pieces))))
            room = int(np.searchsorted(off, self.DENSE_POINTS, side="right")) - 1
            dense = self._dense = {
                "off": off,
                "room": room,
                "filled": 0,
                "pts": np.empty((int(off[room]), 3)),
            }
        filled, off, room = dense["filled"], dense["off"], dense["room"]
        same_path = pieces.path is self._pieces.path
        if same_path and lo <= filled < min(hi, room):  # place [filled, hi), keep what fits
            keep = min(hi, room)
            piece, local = dense_local(pieces, filled, keep)
            # In blocks: their temporaries are reused, not faulted in at the polyline's
            # size (two arrays of its length), the same points.
            at = int(off[filled])
            for a in range(0, piece.size, self.FILL_BLOCK):
                b = min(a + self.FILL_BLOCK, piece.size)
                dense["pts"][at + a : at + b] = pieces.path.points(piece[a:b], local[a:b])[0]
            dense["filled"] = filled = keep
        if not same_path or hi > filled:
            return dense_polyline(pieces, starts_mm, total_mm, lo, hi)
        piece, local = dense_local(pieces, lo, hi)
        return (
            path_lengths(starts_mm, total_mm, piece, local),
            dense["pts"][int(off[lo]) : int(off[hi])],
        )

    def candidates(self, q: np.ndarray, upper_mm: np.ndarray) -> np.ndarray:
        """Pieces that may hold a path point closer to some point of ``q`` (m, 3) than
        ``upper_mm`` (m,) (sorted piece indices).

        A program's first queries test every piece's ball, up to :data:`BAND_AFTER` pairs
        per piece (and :data:`DIRECT_PAIRS`): the check of a long CAM program asks about a
        dozen points. A program that asks more (one of many cuts asks a few points after
        every rapid) makes the bands and tests the balls in the band about each block of
        points; only one whose bands hold more than :data:`DIRECT_PAIRS` pairs in all (a
        path dense along every axis) builds the k-d trees (importing scipy.spatial and
        building them cost 0.2–0.3 s; one query about each block of points, the balls of
        what it finds then tested against every point). Each finds every piece whose ball
        comes within ``upper_mm`` of some point (the bands and trees exactly those), and a
        piece's polyline lies in its ball, so the distances are the same."""
        k = self._pieces.length_mm.size
        direct = min(self.DIRECT_PAIRS, self.BAND_AFTER * k)
        if self._bands is None and self._built is None and self._direct + q.shape[0] * k <= direct:
            self._direct += q.shape[0] * k
            return self._candidates_direct(q, upper_mm)
        if self._built is None and self._banded <= self.DIRECT_PAIRS:
            return self._candidates_banded(q, upper_mm)
        if self._built is None:
            self._build()
        found = []
        # One tree query for the block: the centres within R + max(u) of the ball about
        # the points' box (every centre a point's query would find), then each ball tested
        # against every point (:meth:`_near_balls`); a query per point cost more than the
        # rest of the distance.
        lows, highs = q.min(axis=0), q.max(axis=0)
        mid, half = 0.5 * (lows + highs), 0.5 * float(np.linalg.norm(highs - lows))
        # (A relative 1e-9 and 1e-6 mm for the rounding of the tree's distances, of the
        # box's middle and of this sum: a wider query only finds more balls to test.)
        reach_mm = (half + float(upper_mm.max())) * (1.0 + 1e-9) + 1e-6
        for idx, tree, r_max in self._built:
            if tree is None:
                found.append(idx)
                continue
            near = tree.query_ball_point(mid, reach_mm + r_max * (1.0 + 1e-9), return_sorted=False)
            if near:
                found.append(idx[np.asarray(near)])
        if not found:
            return np.zeros(0, dtype=np.int64)
        return distinct(self._near_balls(q, upper_mm, np.concatenate(found)))

    def _candidates_banded(self, q: np.ndarray, upper_mm: np.ndarray) -> np.ndarray:
        """:meth:`candidates` through the bands (:meth:`_make_bands`): in each radius group
        (largest radius R), the pieces whose centres lie, along the group's axis, within
        max(u) + R of the points' span on it (a ball within u of a point has its centre
        within u + r of it on every axis), then their balls tested against every point
        (:meth:`_near_balls`). The pairs tested are counted against :data:`DIRECT_PAIRS`."""
        if self._bands is None:
            self._make_bands()
        reach_mm = float(upper_mm.max())
        lows, highs = q.min(axis=0), q.max(axis=0)
        band = []
        for idx, along, axis, r_max in self._bands:
            lo = int(np.searchsorted(along, float(lows[axis]) - reach_mm - r_max, side="left"))
            hi = int(np.searchsorted(along, float(highs[axis]) + reach_mm + r_max, side="right"))
            if hi > lo:
                band.append(idx[lo:hi])
        if not band:
            return np.zeros(0, dtype=np.int64)
        band = np.concatenate(band)
        self._banded += q.shape[0] * band.size
        return distinct(self._near_balls(q, upper_mm, band))

    def _candidates_direct(self, q: np.ndarray, upper_mm: np.ndarray) -> np.ndarray:
        """:meth:`candidates` by testing every piece's ball (centre c = (A + B)/2, radius
        r = L/2) against the points, |q − c| ≤ u + r: all pairs at once, a block of points
        at a time, for programs of up to :data:`DIRECT_BLOCK_PIECES` pieces; beyond, a point
        at a time, first |q_x − c_x| ≤ u + r over all pieces, then the balls of those (a
        long program's check asks a few points of many pieces)."""
        centre, radius, cx = self._ball_columns()
        k = radius.size
        if k <= self.DIRECT_BLOCK_PIECES:
            return self._near_balls(q, upper_mm, np.arange(k))
        found = []
        for p, u in zip(q, upper_mm.tolist()):
            band = np.flatnonzero(np.abs(cx - p[0]) <= u + radius)
            rel = centre[band] - p
            gap = np.sqrt(np.einsum("kc,kc->k", rel, rel)) - radius[band]
            found.append(band[gap <= u])
        return distinct(np.concatenate(found)) if found else np.zeros(0, dtype=np.int64)

    def _piece_polylines(self, cand: np.ndarray) -> list[tuple]:
        """(points, box lows, box highs, None) of the dense polylines (:func:`path_counts`)
        of pieces ``cand`` — (points, None, None, segment directions) for one of at most
        :data:`CHUNK` segments. Each piece's are computed once (every query and re-plan of the
        program asks the same pieces again), the points the same numbers as a fresh
        :meth:`PathTable.points_at_fraction` (its formulas are elementwise); the boxes bound
        runs of :data:`CHUNK` segments."""
        counts = self._counts
        cache = self._polyline
        missing = [j for j in cand.tolist() if j not in cache]
        if missing:
            miss = np.asarray(missing, dtype=np.int64)
            c = counts[miss]
            if self._cached_points + int(c.sum()) > self.CACHE_POINTS:
                cache.clear()
                self._cached_points = 0
                miss = cand
                c = counts[miss]
            piece = np.repeat(miss, c)
            first = np.repeat(np.cumsum(c) - c, c)
            frac = (np.arange(piece.size) - first) / np.repeat(c - 1, c)
            pts = self._pieces.path.points_at_fraction(piece, frac)
            ends = np.cumsum(c).tolist()
            for j, a, z in zip(miss.tolist(), [0, *ends[:-1]], ends):
                p = pts[a:z]
                if z - a - 1 <= self.CHUNK:  # one box: its segments' directions instead
                    cache[j] = (p, None, None, p[1:] - p[:-1])
                    continue
                lo_s, hi_s = np.minimum(p[:-1], p[1:]), np.maximum(p[:-1], p[1:])
                heads = np.arange(0, lo_s.shape[0], self.CHUNK)
                cache[j] = (
                    p,
                    np.minimum.reduceat(lo_s, heads, axis=0),
                    np.maximum.reduceat(hi_s, heads, axis=0),
                    None,
                )
            self._cached_points += int(c.sum())
        return [cache[j] for j in cand.tolist()]

    def _line_ends(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Which pieces are lines whose polyline is their two ends (k,), and those ends
        (k, 3) [mm] (NaN for the others): every line's placed once
        (:meth:`PathTable.points_at_fraction` at 0 and 1: the same numbers as placing them
        for each query block, its formulas being elementwise)."""
        if self._lines is None:
            path = self._pieces.path
            is_line = (np.asarray(path.kind) == Kind.LINE) & (self._counts == 2)
            i = np.flatnonzero(is_line)
            ends = path.points_at_fraction(np.repeat(i, 2), np.tile([0.0, 1.0], i.size))
            a = np.full((is_line.size, 3), np.nan)
            b = np.full((is_line.size, 3), np.nan)
            a[i], b[i] = ends[0::2], ends[1::2]
            self._lines = (is_line, a, b)
        return self._lines

    def _near_segments(self, cand: np.ndarray, lo_q: np.ndarray, hi_q: np.ndarray):
        """Starts and directions (n, 3) [mm] of the polyline segments of pieces ``cand``
        whose bounding boxes meet the box [lo_q, hi_q]: boxes of :data:`CHUNK` segments
        first, then the segments of the boxes that meet it (the same segments as testing
        every one)."""
        starts, dirs = [], []
        # Lines (a polyline of their points at fractions 0 and 1) all at once; the other
        # pieces through their kept polylines.
        path = self._pieces.path
        kept = len(self._counts) <= self.LINE_ENDS_PIECES
        if kept:
            is_line, line_a, line_b = self._line_ends()
            line = np.take(is_line, cand)
        else:
            line = (np.take(path.kind, cand) == Kind.LINE) & (np.take(self._counts, cand) == 2)
        if line.any():
            i = cand[line]
            if kept:
                a, b = line_a[i], line_b[i]
            else:
                ends = path.points_at_fraction(np.repeat(i, 2), np.tile([0.0, 1.0], i.size))
                a, b = ends[0::2], ends[1::2]
            keep = np.all((np.maximum(a, b) >= lo_q) & (np.minimum(a, b) <= hi_q), axis=1)
            starts.append(a[keep])
            dirs.append(b[keep] - a[keep])
            cand = cand[~line]
        for p, lo_c, hi_c, d in self._piece_polylines(cand):
            if d is not None:
                # A polyline of at most CHUNK segments: all of them. A segment whose box
                # misses [lo_q, hi_q] is farther from every query than the block's upper
                # bound, so measuring it changes no distance (the caller keeps the
                # smaller), and it costs less than testing it (numpy calls per piece).
                starts.append(p[:-1])
                dirs.append(d)
                continue
            hit = np.flatnonzero(np.all((hi_c >= lo_q) & (lo_c <= hi_q), axis=1))
            if hit.size == 0:
                continue
            seg = (hit[:, None] * self.CHUNK + np.arange(self.CHUNK)).ravel()
            seg = seg[seg < p.shape[0] - 1]
            a, b = p[seg], p[seg + 1]
            keep = np.all((np.maximum(a, b) >= lo_q) & (np.minimum(a, b) <= hi_q), axis=1)
            starts.append(a[keep])
            dirs.append(b[keep] - a[keep])
        if not starts:
            return np.zeros((0, 3)), np.zeros((0, 3))
        return np.concatenate(starts), np.concatenate(dirs)

    def distance_mm(
        self,
        q: np.ndarray,
        upper_mm: np.ndarray,
        block: int = 256,
        exclude: np.ndarray | None = None,
    ) -> np.ndarray:
        """Distance [mm] from each point of ``q`` (m, 3) to the whole path, for points whose
        distance is known to be at most ``upper_mm`` (m,): exact to the polyline of
        :func:`path_counts` on the candidate pieces, never above ``upper_mm``. ``exclude``
        (k,) bool: pieces that are not part of the path measured against (the rapids, for
        the distance to the cut)."""
        if self._counts is None:
            self._counts = path_counts(self._pieces)
        out = np.array(upper_mm, dtype=float)
        # Blocks of consecutive points (in the caller's order: time) at most ``block`` long
        # and broken where the points jump by more than 1 mm, so each block is compact.
        jump = np.flatnonzero(np.sqrt(np.sum(np.diff(q, axis=0) ** 2, axis=1)) > 1.0) + 1
        edges = distinct_union(jump, np.arange(0, q.shape[0], block), [q.shape[0]])
        for lo, hi in zip(edges[:-1].tolist(), edges[1:].tolist()):
            sl = slice(lo, hi)
            cand = self.candidates(q[sl], out[sl])
            if exclude is not None:
                cand = cand[~exclude[cand]]
            if cand.size == 0:
                continue
            cand = self._distinct(cand)
            # Segments within a piece whose bounding box meets the queries' (widened).
            qb = q[sl]
            reach = float(out[sl].max())
            lo_q, hi_q = qb.min(axis=0) - reach, qb.max(axis=0) + reach
            a, d = self._near_segments(cand, lo_q, hi_q)
            if a.shape[0] == 0:
                continue
            m = hi - lo
            dist = segment_distances(
                qb, a, d, np.zeros(m, dtype=np.int64), np.full(m, a.shape[0], dtype=np.int64)
            )
            out[sl] = np.minimum(out[sl], dist)
        return out
