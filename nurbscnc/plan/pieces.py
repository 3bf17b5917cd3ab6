"""Planner pieces: the program's path cut into pieces the feed profile treats as units.

Each NURBS block is split into its sharp-corner regions (replaced by their PH quintic pieces,
SPEC §6) and the NURBS stretches between them; lines, arcs and rapids are one piece each;
under G64 the corners between pieces are replaced by PH quintic blends (issues 7 and 13).
Every piece knows its exact geometry, its length, its cruise cap (SPEC §7, formulas in
:mod:`nurbscnc.machine.caps`) and its unit tangents at both ends (for the junctions). Its
kind is the path model's :class:`~nurbscnc.geometry.path.Kind` (a rapid is a line with the
``rapid`` flag); everything that samples the pieces goes through :attr:`PieceList.path`, the
:class:`~nurbscnc.geometry.path.PathTable` of all rows.

Storage. CAM programs hold millions of G1 lines, so the pieces live in columns
(:class:`PieceList`: one numpy row a piece) and the line path is built without a Python
object per line: line pieces are their end points, line–line blends their PH preimage and
plane frame (:func:`~nurbscnc.geometry.blend.line_corner_blends`, all corners at once). Arcs,
NURBS cells and the PH pieces of NURBS corners keep a geometry object per piece. Indexing a
PieceList gives a :class:`Piece` (built on demand), so code written for a list of pieces
still works; code that runs over every piece of a long program uses the columns.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field
from dataclasses import replace as dc_replace

import numpy as np

from nurbscnc.errors import GeometryError, NurbsCncError, SourcePos
from nurbscnc.geometry.blend import MIN_REVERSAL_RAD, ph_tables
from nurbscnc.geometry.nurbs import MovedCopies, NurbsCurve
from nurbscnc.geometry.path import STOP_KINDS, Kind, PathTable, ph_power_rows, stop_seconds
from nurbscnc.geometry.paths import ArcGeometry, LineGeometry, geometry_of
from nurbscnc.geometry.ph import PHQuintic
from nurbscnc.geometry.segments import blend_tolerance_mm
from nurbscnc.machine.caps import (
    JUNCTION_SHARE,
    MIN_CAP_MM_S,
    corner_cap_mm_s,
    curvature_cap_mm_s,
    junction_jump_cap_mm_s,
    servo_curve_cap_mm_s,
)
from nurbscnc.machine.profile import Machine
from nurbscnc.plan.corners import CornerAction, CornerLog, CornerWhy, find_corner_regions
from nurbscnc.plan.naive import merge_collinear
from nurbscnc.plan.options import CornerFeed, PlanOptions
from nurbscnc.plan.phfit import fit_region
from nurbscnc.program.columns import LINE as LINE_CODE
from nurbscnc.program.columns import RAPID as RAPID_CODE
from nurbscnc.program.columns import segment_columns

#: Junctions whose tangents turn by less than this [rad] are treated as smooth (no stop).
SMOOTH_JUNCTION_RAD = 1e-6

#: What is left of a line or arc between two blends, if shorter than this [mm], is dropped:
#: such a sliver (two blends that almost meet, e.g. 4e-9 mm) carries no motion worth a piece.
#: The path then jumps by less than this from one blend's end to the next one's start.
MIN_REMAINDER_MM = 1e-6

#: Summary names of the piece kinds, in summary order ("rapid": a rapid line).
KIND_NAMES = ("line", "rapid", "arc", "ph", "nurbs")
_NAME_OF = {Kind.LINE: "line", Kind.ARC: "arc", Kind.SPIRAL: "arc", Kind.PH: "ph",
            Kind.NURBS: "nurbs"}  # fmt: skip


@dataclass(frozen=True, eq=False)
class Piece:
    """One piece of the path, as built (arcs, NURBS cells, PH pieces) or read from a row.

    ``kind`` its :class:`~nurbscnc.geometry.path.Kind`; ``geometry`` evaluates it: a
    NurbsCurve (``u_a``..``u_b`` of it, starting at arc length ``s_a_mm`` of the curve), a
    PHQuintic (ξ ∈ [0, 1]), a LineGeometry or an ArcGeometry (``u_a``..``u_b``).
    ``length_mm`` [mm]; ``v_cap_mm_s`` the cruise cap [mm/s]; ``segment`` / ``line`` where
    it came from; ``dwell_after_s`` a dwell [s] at its end (G4); ``stop_after``: the tool
    comes to rest at its end (a dwell, a pause, a G61.1 block end); ``pass_after``: the
    break at its end is small enough to pass at speed (:func:`_small_break`).
    ``kappa_max_per_mm`` the largest curvature on it [1/mm]. ``blend_mm`` the path-control
    value of its segment (:class:`~nurbscnc.geometry.segments.Line`; :func:`tolerance_mm`
    gives the blend tolerance). ``rapid``: a rapid move (G0).
    """

    kind: Kind
    geometry: object
    length_mm: float
    v_cap_mm_s: float
    segment: int
    line: int
    u_a: float = 0.0
    u_b: float = 1.0
    s_a_mm: float = 0.0
    kappa_max_per_mm: float = 0.0
    dwell_after_s: float = 0.0
    blend_mm: float = 0.0
    rapid: bool = False
    stop_after: bool = False
    pass_after: bool = False

    @property
    def name(self) -> str:
        """"line", "rapid", "arc", "ph" or "nurbs" (summaries)."""
        return "rapid" if self.rapid else _NAME_OF[Kind(self.kind)]

    def path_row(self) -> tuple:
        """The row of :meth:`PathTable.of <nurbscnc.geometry.path.PathTable.of>` for it."""
        return (self.kind, self.geometry, self.length_mm, self.u_a, self.u_b, self.s_a_mm,
                self.line)  # fmt: skip

    def points_mm(self, s_local_mm: np.ndarray) -> np.ndarray:
        """Exact points [mm] (m, 3) at arc lengths ``s_local_mm`` from the piece start."""
        s = np.ravel(np.asarray(s_local_mm, dtype=float))
        return PathTable.of([self.path_row()]).points(np.zeros(s.size, np.intp), s)[0]

    def tangent_start(self) -> np.ndarray:
        """Unit tangent at the start (zero at a cusp)."""
        return _object_ends([self])[2][0]

    def tangent_end(self) -> np.ndarray:
        """Unit tangent at the end (zero at a cusp)."""
        return _object_ends([self])[3][0]


def nurbs_curve(seg, machine: Machine) -> NurbsCurve:
    """The curve a NURBS segment is planned on: its own, with a hook of rounding at an end
    (a control leg of 1e-6 mm turning back) removed within the chord tolerance δ, the
    small-break rule's bound on how far a passed break may cut."""
    return NurbsCurve.from_segment(seg).without_end_hooks(machine.limits.chord_tolerance_mm)


def nurbs_pieces(seg, index: int, machine: Machine, options: PlanOptions,
                 curve: NurbsCurve | None = None) -> list[Piece]:  # fmt: skip
    """A NURBS segment as pieces: PH corner pieces and capped NURBS stretches, on ``curve``
    (default :func:`nurbs_curve`)."""
    lim = machine.limits
    curve = nurbs_curve(seg, machine) if curve is None else curve
    feed = min(seg.feed_mm_s, lim.v_max_mm_s)
    kth = lim.a_max_mm_s2 / (feed * feed)
    regions = find_corner_regions(curve, kth)
    e_um = (options.tolerance_mm or lim.ph_tolerance_mm) * 1000.0
    blend = blend_override(seg, options)
    pieces: list[Piece] = []
    u_prev = curve.u_start
    for region in regions:
        if region.u_a > u_prev:
            pieces.extend(_nurbs_stretch(curve, u_prev, region.u_a, seg, index, machine, feed,
                                         blend))  # fmt: skip
        if not np.isfinite(region.kappa_peak_per_mm):
            # A cusp (C′ = 0): a true sharp corner of the programmed curve. No smooth curve
            # can pass it at speed: stop exactly at the cusp (the junction between the two
            # stretches turns by 180°, so its cap is 0), no PH replacement.
            for ua, ub in ((region.u_a, region.u_peak), (region.u_peak, region.u_b)):
                if ub > ua:
                    pieces.extend(_nurbs_stretch(curve, ua, ub, seg, index, machine, feed, blend))
            u_prev = region.u_b
            continue
        region_cap = corner_cap_mm_s(machine, region.kappa_peak_per_mm, feed)
        if options.ph:
            # max ≤ e (not the paper's 3e): every reference point within e of the curve.
            for p in _region_fit(curve, region.u_a, region.u_b, e_um):
                xi = np.linspace(0.0, 1.0, 65)
                k_max = float(np.max(np.abs(p.ph.curvature(xi))))
                k_mean = abs(p.ph.turning_angle_rad()) / max(float(p.ph.length_mm), 1e-300)
                cap = (region_cap if options.corner_feed == CornerFeed.PEAK
                       else corner_cap_mm_s(machine, max(k_max, kth), feed,
                                        max(k_mean, kth)))  # fmt: skip
                pieces.append(Piece(Kind.PH, p.ph, float(p.ph.length_mm), cap, index, seg.line,
                                    0.0, 1.0, 0.0, k_max, blend_mm=blend))  # fmt: skip
        else:
            s = curve.arc_length(np.array([region.u_a, region.u_b]))
            pieces.append(Piece(Kind.NURBS, curve, float(s[1] - s[0]), region_cap, index,
                                seg.line, region.u_a, region.u_b, float(s[0]),
                                region.kappa_peak_per_mm, blend_mm=blend))  # fmt: skip
        u_prev = region.u_b
    if u_prev < curve.u_end:
        pieces.extend(_nurbs_stretch(curve, u_prev, curve.u_end, seg, index, machine, feed, blend))
    # Pieces shorter than a nanometre (a region clipped by a cusp at a curve end) carry no
    # motion; dropping them changes the path length by less than 1e-9 mm.
    return [p for p in pieces if p.length_mm > 1e-9]


#: Longest PH piece of a corner region [mm]: a region's pieces are cut at least this fine, so
#: each piece's cap (its own peak curvature, :func:`corner_cap_mm_s`) follows the curvature
#: along the corner; a 0.25 mm piece holding the nose of a 9 mm airfoil (κ from 1.6 to
#: 5 /mm) would be capped at its sharpest point all along (issue 13).
CORNER_CELL_MM = 0.0625


def _region_fit(curve, u_a: float, u_b: float, e_um: float):
    """PH pieces of the corner region [u_a, u_b]: the region cut into parts of equal arc
    length, at most :data:`CORNER_CELL_MM` (at most 64 parts), each fitted
    (:func:`fit_region`, max ≤ e). The parts share C and C′ at their ends (Hermite data), so
    the joins stay G1 as in one fit; a part is halved further by the fit where the deviation
    asks."""
    s = curve.arc_length(np.array([u_a, u_b]))
    n = int(np.clip(np.ceil((s[1] - s[0]) / CORNER_CELL_MM), 1, 64))
    u = curve.param_at_length(np.linspace(s[0], s[1], n + 1))
    u[0], u[-1] = u_a, u_b
    return [p for a, b in zip(u[:-1], u[1:], strict=True)
            for p in fit_region(curve, float(a), float(b), tolerance_um=e_um,
                                max_factor=1.0).pieces]  # fmt: skip


#: Longest NURBS cell [mm]: stretches between corners are cut into cells this long or shorter,
#: so that the dynamics check can lower the feed locally (near a stop, say) and not along the
#: whole stretch.
CELL_MM = 0.25


def _nurbs_stretch(curve, u_a, u_b, seg, index, machine, feed, blend_mm) -> list[Piece]:
    """NURBS between corners as cells of ≤ CELL_MM, each capped by min(F, V_af(κ), √(A/κ))
    over 8 curvature samples in it; ``blend_mm`` their segment's blend tolerance
    (:func:`blend_override`)."""
    s_ab = curve.arc_length(np.array([u_a, u_b]))
    n_cells = int(np.clip(np.ceil((s_ab[1] - s_ab[0]) / CELL_MM), 1, 4096))
    s_edges = np.linspace(s_ab[0], s_ab[1], n_cells + 1)
    u_edges = curve.param_at_length(s_edges)
    u_edges[0], u_edges[-1] = u_a, u_b
    sub = 8
    fine = (u_edges[:-1, None] + (u_edges[1:] - u_edges[:-1])[:, None]
            * np.linspace(0.0, 1.0, sub + 1)[None, :])  # fmt: skip
    kappa = curve.curvature(fine.ravel()).reshape(fine.shape)
    # A cusp (κ = inf) sits at a cell end, where the junction is an exact stop anyway: cap the
    # cell by its finite curvature samples (κ grows like s^(-1/2) towards a cusp, so the
    # nearest sample already asks for a low feed).
    kappa = np.where(np.isfinite(kappa), kappa, 0.0)
    kappa = np.column_stack([kappa, _peak_kappa(curve, fine, kappa)])
    # Never a zero cap (κ ≥ 2/δ makes V_af zero): it would stall the tool; 1 µm/s is the floor.
    cell_cap = np.maximum(curvature_cap_mm_s(machine, kappa, feed).min(axis=1), MIN_CAP_MM_S)
    k_cell = kappa.max(axis=1)
    return [Piece(Kind.NURBS, curve, float(s_edges[i + 1] - s_edges[i]), float(cell_cap[i]),
                  index, seg.line, float(u_edges[i]), float(u_edges[i + 1]),
                  float(s_edges[i]), float(k_cell[i]), blend_mm=blend_mm)
            for i in range(n_cells)]  # fmt: skip


def _peak_kappa(curve, u: np.ndarray, kappa: np.ndarray, rounds: int = 3) -> np.ndarray:
    """The curvature peak [1/mm] of each row of samples (cells × samples at parameters
    ``u``, curvatures ``kappa``), refined: 16 new samples between the neighbours of the
    largest one, ``rounds`` times (a sharp peak between two of the 9 cell samples — a
    near-cusp of a rational NURBS, κ 350 /mm — was missed by 30 %, and the cell's cap
    √(A/κ) with it); past the first round, not the cells whose curvature that round found
    rising to the cell's end. Cusps (κ = inf) count as 0 as in the samples."""
    m, n = u.shape
    best = kappa.max(axis=1)
    rows = np.arange(m)  # the cells still refined: row i of u and kappa is cell rows[i]
    for r in range(rounds):
        at = np.arange(rows.size)
        k = np.argmax(kappa, axis=1)
        lo, hi = u[at, np.maximum(k - 1, 0)], u[at, np.minimum(k + 1, n - 1)]
        u = lo[:, None] + (hi - lo)[:, None] * np.linspace(0.0, 1.0, 17)[None, :]
        kappa = curve.curvature(u.ravel()).reshape(u.shape)
        kappa = np.where(np.isfinite(kappa), kappa, 0.0)
        peak = kappa.max(axis=1)
        rose = peak > best[rows]
        best[rows] = np.maximum(best[rows], peak)
        if r == 0:
            # Done after one round: a cell whose refinement found nothing above its samples
            # and whose largest new sample is an end of the refined interval (the curvature
            # rises to the cell's end there: most cells, 4,900 of the 4,950 of ten airfoils).
            # On 65,610 cells of 60 random rational curves (weights 0.05–20) refining them
            # all further changes one peak, by 2e-7.
            j = np.argmax(kappa, axis=1)
            on = np.flatnonzero(rose | ((j > 0) & (j < kappa.shape[1] - 1)))
            rows, u, kappa = rows[on], u[on], kappa[on]
            if not rows.size:
                break
        n = u.shape[1]
    return best


_VECTORS = ("start_mm", "end_mm", "tangent_start", "tangent_end")


@dataclass(frozen=True, eq=False)
class PieceList(Sequence):
    """The pieces of a program as columns, one row a piece (module doc); ``pl[i]`` is a Piece.

    Per row (k,): ``kind`` (:class:`~nurbscnc.geometry.path.Kind` codes), ``length_mm``,
    ``v_cap_mm_s``, ``segment``, ``line``, ``kappa_max_per_mm``, ``dwell_after_s``,
    ``blend_mm``, ``rapid``, ``stop_after``, ``pass_after`` (as in :class:`Piece`); (3, k):
    ``start_mm``, ``end_mm`` the end points [mm] and ``tangent_start``, ``tangent_end`` the
    unit tangents there (zero where the derivative vanishes, at a cusp). Line rows are the
    segment from ``start_mm`` to ``end_mm``. Columnar PH rows (line–line blends): ``ph_rows``
    (m,) their rows (sorted), ``ph_w`` (m, 3) complex preimages, ``ph_p0`` (m,) complex starts,
    ``ph_frame`` (m, 3, 3) origin, e1, e2 of their planes. Every other row has an entry in
    ``objects``: row → (geometry, u_a, u_b, s_a_mm). The geometry of every row, for
    sampling, is :attr:`path`.
    """

    kind: np.ndarray
    length_mm: np.ndarray
    v_cap_mm_s: np.ndarray
    segment: np.ndarray
    line: np.ndarray
    kappa_max_per_mm: np.ndarray
    dwell_after_s: np.ndarray
    blend_mm: np.ndarray
    rapid: np.ndarray
    stop_after: np.ndarray
    pass_after: np.ndarray
    start_mm: np.ndarray
    end_mm: np.ndarray
    tangent_start: np.ndarray
    tangent_end: np.ndarray
    ph_rows: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    ph_w: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), dtype=complex))
    ph_p0: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=complex))
    ph_frame: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 3)))
    objects: dict = field(default_factory=dict)
    #: Every corner and what the planner did there (:class:`~nurbscnc.plan.corners.CornerLog`).
    corners: CornerLog = field(default_factory=CornerLog.empty)
    #: Junctions where the curvature vector jumps (:func:`curvature_jumps`): ``jump_rows``
    #: (m,) junction j between rows j and j + 1, ``jump_kn`` (m, 3) the jump Δ(κn) [1/mm],
    #: ``jump_cap_mm_s`` (m,) the speed cap there
    #: (:func:`~nurbscnc.machine.caps.junction_jump_cap_mm_s`), applied by :func:`junction_caps`.
    jump_rows: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    jump_kn: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    jump_cap_mm_s: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @classmethod
    def of(cls, pieces: Sequence[Piece]) -> PieceList:
        """The columns of a list of :class:`Piece` objects (each kept as its geometry)."""
        cols = _empty_columns(len(pieces))
        objects: dict = {}
        _put_objects(cols, objects, list(range(len(pieces))), list(pieces))
        return cls(**cols, objects=objects)

    def __len__(self) -> int:
        return int(self.kind.size)

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        i = int(index)
        k = len(self)
        if i < 0:
            i += k
        if not 0 <= i < k:
            raise IndexError(f"piece {index} of {k}")
        kind = Kind(int(self.kind[i]))
        obj = self.objects.get(i)
        if obj is not None:
            geom, u_a, u_b, s_a = obj
        elif kind == Kind.LINE:
            geom = LineGeometry(self.start_mm[:, i], self.end_mm[:, i])
            u_a, u_b, s_a = 0.0, float(geom.u_end), 0.0
        else:
            j = int(np.searchsorted(self.ph_rows, i))
            origin, e1, e2 = self.ph_frame[j]
            geom = PHQuintic(self.ph_w[j], self.ph_p0[j], origin, e1, e2)
            u_a, u_b, s_a = 0.0, 1.0, 0.0
        return Piece(kind, geom, float(self.length_mm[i]), float(self.v_cap_mm_s[i]),
                     int(self.segment[i]), int(self.line[i]), u_a, u_b, s_a,
                     float(self.kappa_max_per_mm[i]), float(self.dwell_after_s[i]),
                     float(self.blend_mm[i]), bool(self.rapid[i]),
                     bool(self.stop_after[i]), bool(self.pass_after[i]))  # fmt: skip

    def kind_counts(self) -> dict[str, int]:
        """How many pieces of each kind (names of :data:`KIND_NAMES`, kinds present only)."""
        counts = np.bincount(self.kind, minlength=len(Kind))
        rapid = int(np.count_nonzero(self.rapid & (self.kind == Kind.LINE)))  # blends: "ph"
        named = {name: 0 for name in KIND_NAMES}
        for code, c in enumerate(counts.tolist()):
            named[_NAME_OF[Kind(code)]] += c
        named["line"] -= rapid
        named["rapid"] = rapid
        return {name: c for name, c in named.items() if c}

    def nurbs_curves(self) -> dict[int, object]:
        """The NURBS curve of each segment that has NURBS rows, by segment index: the objects
        its rows are evaluated on, whose arc-length tables are built already once the pieces
        were made (:func:`~nurbscnc.plan.lowerbound.program_lower_bound_s` reuses them)."""
        rows = np.fromiter(self.objects, dtype=np.int64, count=len(self.objects))
        rows = rows[self.kind[rows] == int(Kind.NURBS)]
        seg, first = np.unique(self.segment[rows], return_index=True)  # a row per segment
        return {s: self.objects[r][0] for s, r in zip(seg.tolist(), rows[first].tolist())}

    @functools.cached_property
    def path(self) -> PathTable:
        """The geometry of every row as a :class:`~nurbscnc.geometry.path.PathTable` (built
        once): line rows share ``start_mm``/``end_mm``, columnar PH rows get their power
        coefficients in chunks, object rows come from ``PathTable.of`` on those rows alone;
        columns no row needs are broadcast zeros (no memory)."""
        k = len(self)
        rows_obj = np.array(sorted(self.objects), dtype=np.int64)
        obj_kind = self.kind[rows_obj]
        need_frame = self.ph_rows.size > 0 or bool(np.any(obj_kind != Kind.NURBS))
        need_arc = bool(np.any(obj_kind == Kind.ARC))
        need_obj = bool(np.any((obj_kind == Kind.NURBS) | (obj_kind == Kind.ARC)))

        def zeros(shape, needed, dtype=float):
            if needed:
                return np.zeros(shape, dtype=dtype)
            return np.broadcast_to(np.zeros((), dtype=dtype), shape)

        code = self.kind.copy()
        origin, e1, e2 = (zeros((3, k), need_frame) for _ in range(3))
        normal = zeros((3, k), need_arc)
        radius, angle, helix = (zeros(k, need_arc) for _ in range(3))
        u_a, u_b, s_a = (zeros(k, need_obj) for _ in range(3))
        obj_id = (np.full(k, -1, dtype=np.intp) if need_obj
                  else np.broadcast_to(np.intp(-1), (k,)))  # fmt: skip
        objects: tuple = ()
        sub = None
        if rows_obj.size:
            # Their rows (:meth:`Piece.path_row`) straight from the columns and ``objects``,
            # without a Piece each (4,950 NURBS cells: 26 of the 37 ms this took).
            objs = [self.objects[r] for r in rows_obj.tolist()]
            sub = PathTable.of([(kind, g, length, ua, ub, sa, line) for kind, (g, ua, ub, sa),
                                length, line in zip(obj_kind.tolist(), objs,
                                                    self.length_mm[rows_obj].tolist(),
                                                    self.line[rows_obj].tolist())])  # fmt: skip
        # PH coefficients in one column per PH row (lines need none: a CAM program's
        # 41 % line rows would hold 184 zero bytes each): the columnar rows' first, in row
        # order, then the object rows' PH pieces.
        sub_ph = np.flatnonzero(sub.ph_slot >= 0) if sub is not None else np.zeros(0, np.intp)
        m = self.ph_rows.size
        ph_s, ph_x, ph_y = (np.zeros((6, m + sub_ph.size)) for _ in range(3))
        ph_sigma = np.zeros((5, m + sub_ph.size))
        ph_slot = np.full(k, -1, dtype=np.intp)
        ph_slot[self.ph_rows] = np.arange(m)
        for lo in range(0, m, _CHUNK):
            sl = slice(lo, min(lo + _CHUNK, m))  # the columnar rows' columns only
            rows = self.ph_rows[sl]
            pts, sigma, s, _ = ph_tables(self.ph_w[sl], self.ph_p0[sl])
            ph_s[:, sl], ph_sigma[:, sl], ph_x[:, sl], ph_y[:, sl] = ph_power_rows(s, sigma, pts)
            frame = self.ph_frame[sl]
            origin[:, rows], e1[:, rows], e2[:, rows] = frame[:, 0].T, frame[:, 1].T, frame[:, 2].T
        if sub is not None:
            code[rows_obj] = sub.kind
            objects = sub.objects
            for mine, theirs in ((origin, sub.origin_mm), (e1, sub.e1), (e2, sub.e2),
                                 (normal, sub.normal)):  # fmt: skip
                if mine.flags.writeable:
                    mine[:, rows_obj] = theirs
            for mine, theirs in ((radius, sub.radius_mm), (angle, sub.angle_rad),
                                 (helix, sub.helix_mm), (u_a, sub.u_a), (u_b, sub.u_b),
                                 (s_a, sub.s_a_mm), (obj_id, sub.obj_id)):  # fmt: skip
                if mine.flags.writeable:
                    mine[rows_obj] = theirs
            if sub_ph.size:
                ph_slot[rows_obj[sub_ph]] = m + np.arange(sub_ph.size)
                for mine, theirs in ((ph_s, sub.ph_s), (ph_x, sub.ph_x), (ph_y, sub.ph_y),
                                     (ph_sigma, sub.ph_sigma)):  # fmt: skip
                    mine[:, m:] = theirs[:, sub.ph_slot[sub_ph]]
        return PathTable(code, self.length_mm, self.line, self.start_mm, self.end_mm, origin,
                         e1, e2, normal, radius, angle, helix, ph_s, ph_sigma, ph_x, ph_y,
                         ph_slot, obj_id, objects, u_a, u_b, s_a).frozen()  # fmt: skip


#: Rows per chunk of the vectorised PH work (bounds the temporaries).
_CHUNK = 1 << 16

_SCALARS = ("kind", "length_mm", "v_cap_mm_s", "segment", "line", "kappa_max_per_mm",
            "dwell_after_s", "blend_mm", "rapid", "stop_after", "pass_after")  # fmt: skip
_DTYPES = {"kind": np.int8, "segment": np.int64, "line": np.int64, "rapid": bool,
           "stop_after": bool, "pass_after": bool}  # fmt: skip


def _empty_columns(k: int) -> dict:
    cols = {name: np.zeros(k, dtype=_DTYPES.get(name, float)) for name in _SCALARS}
    for name in _VECTORS:
        cols[name] = np.zeros((3, k))
    return cols


def _unit_rows(d: np.ndarray) -> np.ndarray:
    """Rows of ``d`` (m, 3) scaled to unit length (zero rows stay zero)."""
    n = np.sqrt(np.einsum("ij,ij->i", d, d))
    return d / np.where(n > 0.0, n, 1.0)[:, None]


def _object_ends(pieces) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Start and end points (m, 3) [mm] and unit tangents (m, 3) of pieces with their own
    geometry, from the derivatives at their parameter ends ``u_a``, ``u_b`` (exact); the
    pieces of one geometry (the NURBS cells of one curve) in one evaluation."""
    m = len(pieces)
    out = [np.zeros((m, 3)) for _ in range(4)]
    by_geometry: dict[int, list[int]] = {}
    for i, p in enumerate(pieces):
        by_geometry.setdefault(id(p.geometry), []).append(i)
    for rows in by_geometry.values():
        g = pieces[rows[0]].geometry
        u = np.array([pieces[i].u_a for i in rows] + [pieces[i].u_b for i in rows])
        d = g.derivatives(u, 1)
        n = len(rows)
        out[0][rows], out[1][rows] = d[0][:n], d[0][n:]
        out[2][rows], out[3][rows] = d[1][:n], d[1][n:]
    out[2], out[3] = _unit_rows(out[2]), _unit_rows(out[3])
    return out[0], out[1], out[2], out[3]




def _object_pieces(seg, index: int, machine: Machine, options: PlanOptions,
                   curve: NurbsCurve | None = None) -> list[Piece]:  # fmt: skip
    """The pieces of an arc or NURBS segment (Piece objects; none for a zero-length arc);
    a NURBS segment's on ``curve`` if given (:func:`nurbs_curve`)."""
    if seg.kind == "nurbs":
        try:
            pieces = nurbs_pieces(seg, index, machine, options, curve)
        except NurbsCncError as exc:
            raise exc.with_pos(SourcePos(seg.line)) from None
        line_at = getattr(seg, "line_at", None)  # a smoothed run: each piece its move's line
        return [dc_replace(p, line=line_at(p.u_a)) for p in pieces] if line_at else pieces
    geom = geometry_of(seg)
    length = float(geom.length_mm)
    if length <= 0.0:
        return []
    # Constant curvature (helix: r / (r² + c²)).
    kappa = float(np.max(geom.curvature(np.array([geom.u_start, geom.u_end]))))
    cap = float(curvature_cap_mm_s(machine, kappa, seg.feed_mm_s))
    return [Piece(Kind.ARC, geom, length, max(cap, 1e-6), index, seg.line, geom.u_start,
                  geom.u_end, 0.0, kappa, blend_mm=blend_override(seg, options))]  # fmt: skip


@dataclass(frozen=True, eq=False)
class _Block:
    """The pieces of one arc or NURBS segment as the columns of their :class:`PieceList`
    rows: ``scalars`` (name → (n,)), ``ends`` (start, end, unit tangents at both, each
    (n, 3)) and ``objects`` (geometry, u_a, u_b, s_a_mm) a row."""

    scalars: dict
    ends: tuple
    objects: list

    @classmethod
    def of(cls, pieces: list[Piece]) -> _Block:
        scalars = {name: np.array([getattr(p, name) for p in pieces],
                                  dtype=_DTYPES.get(name, float)) for name in _SCALARS}  # fmt: skip
        return cls(scalars, _object_ends(pieces),
                   [(p.geometry, p.u_a, p.u_b, p.s_a_mm) for p in pieces])  # fmt: skip

    def moved(self, curve: NurbsCurve, old: NurbsCurve, delta_mm: np.ndarray, index: int,
              line: int) -> _Block:  # fmt: skip
        """The block of a segment whose curve ``curve`` is the curve ``old`` of this block
        moved by ``delta_mm`` (:meth:`~nurbscnc.geometry.nurbs.NurbsCurve.translation_from`),
        as segment ``index`` at source line ``line``: the same cells, corners, caps and
        lengths (none of them depends on where the curve lies), the end points moved, the
        NURBS rows on ``curve`` (sharing ``old``'s arc-length tables), the PH corner pieces
        moved with their plane's origin."""
        curve.sharing_tables(old)
        scalars = {name: col.copy() for name, col in self.scalars.items()}
        scalars["segment"][:] = index
        scalars["line"][:] = line
        start, end, t_start, t_end = self.ends
        moved_ph: dict[int, PHQuintic] = {}

        def geometry(g):
            if g is old:
                return curve
            if isinstance(g, PHQuintic):
                if id(g) not in moved_ph:
                    moved_ph[id(g)] = dc_replace(g, origin_mm=g.origin_mm + delta_mm)
                return moved_ph[id(g)]
            raise TypeError(f"a NURBS segment's piece on {type(g).__name__}")  # never: cells, PH

        return _Block(scalars, (start + delta_mm, end + delta_mm, t_start, t_end),
                      [(geometry(g), ua, ub, sa) for g, ua, ub, sa in self.objects])  # fmt: skip


class _Repeats:
    """The NURBS segments of one program planned so far (:func:`segment_pieces`), to plan a
    segment that is one of them moved (a part cut again at another place: ten airfoils
    along X) from that one's pieces instead of again (:meth:`_Block.moved`): a moved copy
    (:class:`~nurbscnc.geometry.nurbs.MovedCopies`) at the same feed and blend tolerance.
    Smoothed runs (a line per piece) are not remembered. Memory: the blocks, which the
    program's pieces hold anyway."""

    def __init__(self, machine: Machine, options: PlanOptions):
        self.machine, self.options = machine, options
        self.copies = MovedCopies()

    def block(self, seg, index: int) -> _Block:
        """The block of NURBS segment ``seg`` (number ``index``)."""
        if getattr(seg, "line_at", None) is not None:
            return _Block.of(_object_pieces(seg, index, self.machine, self.options))
        try:
            curve = nurbs_curve(seg, self.machine)
        except NurbsCncError as exc:
            raise exc.with_pos(SourcePos(seg.line)) from None
        same = (min(seg.feed_mm_s, self.machine.limits.v_max_mm_s),
                blend_override(seg, self.options))  # fmt: skip
        hit = self.copies.find(curve, same)
        if hit is not None:
            (old, block), delta = hit
            return block.moved(curve, old, delta, index, seg.line)
        block = _Block.of(_object_pieces(seg, index, self.machine, self.options, curve))
        self.copies.add(curve, (curve, block), same)
        return block


def segment_pieces(segments, machine: Machine, options: PlanOptions | None = None,
                   columns=None) -> PieceList:  # fmt: skip
    """All pieces of a program, in order, as a :class:`PieceList`, with its corners decided
    (path-control modes, LinuxCNC 2.9's meaning, issue 13) and logged in ``corners``.

    With ``options.smooth`` dense CAM polylines become splines first, on the programmed
    vertices (:func:`~nurbscnc.plan.smoothing.smooth_runs`); then runs of nearly collinear
    feed lines under G64 Q are merged (:func:`~nurbscnc.plan.naive.merge_collinear`); the
    ``segment`` column keeps the program's indices. Breaks small enough to pass at speed
    are marked ``pass_after`` (:func:`_small_break`, every mode but at G61.1 block ends);
    G61.1 stops at the end of every block (``stop_after``); G64 corners are blended within
    their tolerance
    (:func:`apply_blends`: P, or the machine's path tolerance without P or with P0); G61
    stops at every other break (:func:`junction_caps`); :func:`corner_log` records it all.

    Lines and rapids are gathered into columns in one pass (no object per line); arcs and
    NURBS blocks become pieces one segment at a time. Dwells and pauses (:data:`STOP_KINDS`)
    become ``stop_after`` and ``dwell_after_s`` (their ``seconds``, 0 for a pause) of the
    piece before (or of a zero-length marker when the program starts with a dwell); a rapid
    followed by a feed move stops exactly; the settle there (in-position wait) is set by
    the planner's contour check (:func:`~nurbscnc.plan.lookahead.plan_checked`), at most
    :func:`settle_time_s`, so a rapid's stop overshoot never shows up as contour error.
    ``columns``: the segments' :class:`~nurbscnc.program.columns.SegmentColumns` if read
    already (used where smoothing and G64 Q left the segments as they were).
    """
    options = options or PlanOptions()
    lim = machine.limits
    segs, source = list(segments), np.arange(len(segments))
    if options.smooth:  # dense CAM polylines as splines (issue 13), on the programmed vertices
        from nurbscnc.plan.smoothing import smooth_runs

        reserve = options.tolerance_mm or lim.ph_tolerance_mm  # a PH corner inside a spline
        segs, source = smooth_runs(segs, source, machine, options.blend_tolerance_mm, reserve)
    segs, merged = merge_collinear(segs)  # G64 Q, on the lines left
    source = source[merged]
    n = len(segs)
    if columns is None or len(source) != len(columns.kind) or options.smooth:
        columns = segment_columns(segs)  # the program's own are for its segments, unchanged
    kinds = columns.names.tolist()
    straight = (columns.kind == LINE_CODE) | (columns.kind == RAPID_CODE)
    seg_line = np.flatnonzero(straight)
    m = seg_line.size
    # The lines' columns (millions in CAM programs): no tuple per line.
    p0, p1 = columns.starts_mm[seg_line], columns.ends_mm[seg_line]
    diff = p1 - p0
    l_len = np.sqrt(np.einsum("ij,ij->i", diff, diff))
    l_rapid = columns.kind[seg_line] == RAPID_CODE
    # Feed, source line (exact in a float) and blend tolerance.
    l_cols = np.column_stack((columns.feeds_mm_s[seg_line], columns.lines[seg_line],
                              columns.blends_mm[seg_line]))  # fmt: skip
    l_feed = l_cols[:, 0]
    l_cap = np.maximum(np.where(l_rapid, lim.rapid_mm_s, np.minimum(l_feed, lim.v_max_mm_s)),
                       1e-6)  # fmt: skip
    if options.blend_tolerance_mm is not None:
        l_blend = np.full(m, float(options.blend_tolerance_mm))
    else:
        l_blend = l_cols[:, 2].copy()
    l_keep = l_len > 0.0

    counts = np.zeros(n, dtype=np.int64)
    counts[seg_line] = l_keep
    blocks: dict[int, _Block] = {}
    curved = np.fromiter((k in ("arc", "nurbs") for k in kinds), dtype=bool, count=n)
    repeats = _Repeats(machine, options)
    for i in np.flatnonzero(curved).tolist():
        if kinds[i] == "nurbs":
            blocks[i] = repeats.block(segs[i], i)
        else:
            pieces = _object_pieces(segs[i], i, machine, options)
            if pieces:
                blocks[i] = _Block.of(pieces)
        counts[i] = len(blocks[i].objects) if i in blocks else 0
    first_row = np.cumsum(counts) - counts
    k = int(counts.sum())
    cols = _empty_columns(k)

    rows = first_row[seg_line[l_keep]]
    sel = l_keep
    cols["kind"][rows] = Kind.LINE
    cols["rapid"][rows] = l_rapid[sel]
    cols["length_mm"][rows] = l_len[sel]
    cols["v_cap_mm_s"][rows] = l_cap[sel]
    cols["segment"][rows] = seg_line[sel]
    cols["line"][rows] = l_cols[:, 1].astype(np.int64)[sel]
    cols["blend_mm"][rows] = l_blend[sel]
    cols["start_mm"][:, rows] = p0[sel].T
    cols["end_mm"][:, rows] = p1[sel].T
    direction = diff[sel] / l_len[sel][:, None]
    cols["tangent_start"][:, rows] = direction.T
    cols["tangent_end"][:, rows] = direction.T
    del p0, p1, diff, direction

    objects = {}
    for i, block in blocks.items():
        r0, m_i = int(first_row[i]), len(block.objects)
        if not m_i:
            continue
        for name in _SCALARS:
            cols[name][r0 : r0 + m_i] = block.scalars[name]
        objects.update(zip(range(r0, r0 + m_i), block.objects))
        for name, arr in zip(_VECTORS, block.ends):
            cols[name][:, r0 : r0 + m_i] = arr.T

    pending = 0.0
    for i in np.flatnonzero(~(straight | curved)).tolist():
        if kinds[i] not in STOP_KINDS:
            continue
        r = int(first_row[i]) - 1  # the last piece before the dwell or pause
        seconds = stop_seconds(segs[i])
        if r >= 0:
            cols["dwell_after_s"][r] += seconds
            cols["stop_after"][r] = True
        else:
            pending += seconds
    if k and pending:  # a zero-length marker at the first piece's start carries it
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
        objects = {r + 1: v for r, v in objects.items()}
        k += 1
    rapid = cols["rapid"]
    settle = np.flatnonzero(rapid[:-1] & ~rapid[1:])
    if settle.size:  # an exact stop; the settle dwell is the planner's (plan_checked)
        cols["stop_after"][settle] = True
    # G61.1 (exact stop): the tool stops at the end of every block, tangent or not.
    seg_col = cols["segment"] = source[cols["segment"]]  # indices of the program's segments
    block_end = (cols["blend_mm"][:-1] < 0.0) & (seg_col[:-1] != seg_col[1:])
    cols["stop_after"][:-1] |= block_end
    pieces = PieceList(**cols, objects=objects)
    if k >= 2:
        turning, regular = _turning(pieces)
        pieces.pass_after[:-1] = _small_break(pieces, turning, regular, machine)
    pieces, tried = apply_blends(pieces, machine)
    rows, dkn = curvature_jumps(pieces)
    cap = junction_jump_cap_mm_s(dkn, machine.servo.period_s, lim.j_max_mm_s3,
                                 machine.axis_limits.as_arrays()[2])  # fmt: skip
    return dc_replace(pieces, corners=corner_log(pieces, tried, machine, options),
                      jump_rows=rows, jump_kn=dkn, jump_cap_mm_s=cap)  # fmt: skip


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
        kn = np.where(ok[:, None], (d2 - np.einsum("ij,ij->i", d2, t)[:, None] * t)
                      / safe[:, None], 0.0)  # fmt: skip
        n = len(rows)
        kn_start[rows], kn_end[rows] = kn[:n], kn[n:]
    near = np.zeros(k, dtype=bool)
    near[obj] = True
    turning, regular = _turning(pieces)
    moving = _passable(pieces, turning, regular) & ~_stopped(pieces)  # passed at speed
    j = np.flatnonzero((near[:-1] | near[1:]) & moving)
    dkn = kn_start[j + 1] - kn_end[j]
    big = np.sqrt(np.einsum("ij,ij->i", dkn, dkn)) > MIN_JUMP_PER_MM
    return j[big], dkn[big]


def blend_override(seg, options: PlanOptions) -> float:
    """The blend tolerance [mm] for a segment: the option if given, else its G64 P (a
    smoothed run's own: the part of the tolerance its spline left to its end blends)."""
    if options.blend_tolerance_mm is not None and not getattr(seg, "smoothed", False):
        return float(options.blend_tolerance_mm)
    return float(getattr(seg, "blend_mm", 0.0))


def sub_geometry(piece: Piece, s0_mm: float, s1_mm: float):
    """The geometry of ``piece`` between arc lengths s0 and s1 [mm] from its start (lines and
    arcs: a new LineGeometry / ArcGeometry, exact)."""
    g = piece.geometry
    if isinstance(g, LineGeometry):
        p = g.point(np.array([s0_mm, s1_mm]))
        return LineGeometry(p[0], p[1])
    assert isinstance(g, ArcGeometry)
    u = g.param_at_length(np.array([s0_mm, s1_mm]))
    t0, t1 = float(u[0] / g.u_end), float(u[1] / g.u_end)
    th0 = t0 * g.angle_rad
    e1 = np.cos(th0) * g.e1 + np.sin(th0) * g.e2
    dr = g.radius_end_mm - g.radius_start_mm
    return dc_replace(
        g,
        origin_mm=g.origin_mm + t0 * g.helix_mm * g.normal,
        e1=e1,
        e2=np.cross(g.normal, e1),
        radius_start_mm=g.radius_start_mm + t0 * dr,
        radius_end_mm=g.radius_start_mm + t1 * dr,
        angle_rad=(t1 - t0) * g.angle_rad,
        helix_mm=(t1 - t0) * g.helix_mm,
    )


@dataclass(eq=False)
class _Corners:
    """Candidate corners of :func:`apply_blends` and what blending each would do (arrays over
    the m corners): ``row`` the piece after the corner; ``tol_mm`` the blend tolerance;
    ``vertex_mm`` (3, m); ``turning_rad`` the tangent turning there; ``lines`` whether both
    sides are lines; ``line`` the source line of the piece before; ``blend_row`` the row of
    each accepted blend in the blended list; then, per corner, ``ok`` (a blend exists), its
    peak curvature, trims of the piece before (``trim_a_mm``) and after (``trim_b_mm``) and
    length; line–line blends'
    PH data (preimage ``w``, start ``p0``, plane ``frame``, one row per line–line corner) and
    the other blends (PH objects) by corner."""

    row: np.ndarray
    tol_mm: np.ndarray
    vertex_mm: np.ndarray
    turning_rad: np.ndarray
    lines: np.ndarray
    line: np.ndarray
    ok: np.ndarray = None
    blend_row: np.ndarray = None
    kappa_per_mm: np.ndarray = None
    trim_a_mm: np.ndarray = None
    trim_b_mm: np.ndarray = None
    length_mm: np.ndarray = None
    w: np.ndarray = None
    p0: np.ndarray = None
    frame: np.ndarray = None
    obj_blends: dict = field(default_factory=dict)
    #: Corners whose blend fitted but stopping is faster (:func:`_blend_is_faster`), and the
    #: junction of the blended list each such stop is at.
    slower: np.ndarray = None
    slower_junction: np.ndarray = None
    #: A further feed cap of each blend [mm/s] (inf: none): the servo's on space blends.
    cap_mm_s: np.ndarray = None

    def __post_init__(self):
        m = self.row.size
        self.cap_mm_s = np.full(m, np.inf)
        self.ok = np.zeros(m, dtype=bool)
        self.kappa_per_mm, self.length_mm = np.zeros(m), np.zeros(m)
        self.trim_a_mm, self.trim_b_mm = np.zeros(m), np.zeros(m)


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
    return float(min(lim.a_max_mm_s2 * period, lim.j_max_mm_s3 * period**2,
                     4.0 * lim.chord_tolerance_mm / period))  # fmt: skip


def _turning(pieces: PieceList) -> tuple[np.ndarray, np.ndarray]:
    """Tangent turning [rad] at each junction (k − 1): atan2(|t_a × t_b|, t_a · t_b)
    (accurate for small angles, arccos of the dot is not), and whether both tangents exist
    (``regular``: not at a cusp or a zero-length piece)."""
    ta, tb = pieces.tangent_end[:, :-1], pieces.tangent_start[:, 1:]
    cross = np.cross(ta, tb, axis=0)
    turning = np.arctan2(np.sqrt(np.sum(cross * cross, axis=0)), np.sum(ta * tb, axis=0))
    regular = (np.sum(ta * ta, axis=0) > 0.0) & (np.sum(tb * tb, axis=0) > 0.0)
    return turning, regular


def _small_break(pieces: PieceList, turning: np.ndarray, regular: np.ndarray,
                 machine: Machine) -> np.ndarray:  # fmt: skip
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


def _passable(pieces: PieceList, turning: np.ndarray, regular: np.ndarray) -> np.ndarray:
    """Junctions (k − 1) the tool passes at speed as far as the geometry goes: tangent (≤
    :data:`SMOOTH_JUNCTION_RAD`) or a small break (``pass_after``, :func:`_small_break`)."""
    return regular & ((turning <= SMOOTH_JUNCTION_RAD) | pieces.pass_after[:-1])


def _stopped(pieces: PieceList) -> np.ndarray:
    """Junctions where the tool must stop whatever the geometry (k − 1): a dwell, pause or
    exact stop (``stop_after``), a rapid meeting a feed move, a zero-length piece."""
    rapid, length = pieces.rapid, pieces.length_mm
    return (pieces.stop_after[:-1] | (rapid[:-1] != rapid[1:]) | (length[:-1] == 0.0)
            | (length[1:] == 0.0))  # fmt: skip


def tolerance_mm(blend_mm: np.ndarray, machine: Machine) -> np.ndarray:
    """The blend tolerance [mm] of each row from its path-control value (``blend_mm``, see
    :class:`~nurbscnc.geometry.segments.Line`): G64 P as given, G64 without P (inf) the
    machine's ``limits.path_tolerance_mm``, G61 / G61.1 (≤ 0) none."""
    return blend_tolerance_mm(blend_mm, machine.limits.path_tolerance_mm)


def _find_corners(pieces: PieceList, machine: Machine) -> _Corners | None:
    """Corners that may be blended: any two pieces (lines, arcs, NURBS cells, PH pieces; not
    the columnar line–line blends, which meet lines tangentially) of the same kind of motion
    (feed or rapid), with a blend tolerance > 0 (the smaller of the two), no stop between
    them, a break not small enough to pass (:func:`_passable`). The pieces must meet there
    (GeometryError otherwise)."""
    k = len(pieces)
    kind = pieces.kind
    tol_row = tolerance_mm(pieces.blend_mm, machine)
    tol = np.minimum(tol_row[:-1], tol_row[1:])
    turning, regular = _turning(pieces)
    columnar = np.zeros(k, dtype=bool)
    columnar[pieces.ph_rows] = True
    cand = (~columnar[:-1] & ~columnar[1:] & ~_stopped(pieces) & (tol > 0.0) & regular
            & ~_passable(pieces, turning, regular))  # fmt: skip
    corner = np.flatnonzero(cand) + 1
    if corner.size == 0:
        return None
    vertex = pieces.end_mm[:, corner - 1]
    gap = np.sqrt(np.sum((vertex - pieces.start_mm[:, corner]) ** 2, axis=0))
    scale = np.maximum(1.0, np.abs(vertex).max(axis=0))
    if np.any(gap > 1e-6 * scale):
        i = int(corner[np.argmax(gap > 1e-6 * scale)])
        raise GeometryError(f"blend_corner: the geometries do not meet (gap "
                            f"{gap.max():.3g} mm)", SourcePos(int(pieces.line[i])))  # fmt: skip
    is_line = (kind == Kind.LINE) & ~np.isin(np.arange(k), list(pieces.objects))
    lines = is_line[corner - 1] & is_line[corner]
    return _Corners(corner, tol[corner - 1], vertex, turning[corner - 1], lines,
                    pieces.line[corner - 1])


def _blend_line_corners(pieces: PieceList, c: _Corners) -> None:
    """Line–line corners in closed form, in chunks (bounded temporaries), each side trimmed
    up to half of its own line (:func:`~nurbscnc.geometry.blend.line_corner_blends`)."""
    from nurbscnc.geometry.blend import line_corner_blends

    ll = np.flatnonzero(c.lines)
    length = pieces.length_mm
    c.w = np.empty((ll.size, 3), dtype=complex)
    c.p0 = np.empty(ll.size, dtype=complex)
    c.frame = np.empty((ll.size, 3, 3))
    for lo in range(0, ll.size, _CHUNK):
        sl = slice(lo, lo + _CHUNK)
        j = ll[sl]
        r = c.row[j]
        lb = line_corner_blends(c.vertex_mm[:, j].T, pieces.tangent_end[:, r - 1].T,
                                pieces.tangent_start[:, r].T, c.tol_mm[j], 0.5 * length[r - 1],
                                0.5 * length[r])  # fmt: skip
        c.ok[j], c.kappa_per_mm[j] = lb.ok, lb.kappa_max_per_mm
        c.trim_a_mm[j], c.trim_b_mm[j] = lb.trim_a_mm, lb.trim_b_mm
        c.length_mm[j] = ph_tables(lb.w, lb.p0)[3]
        c.w[sl], c.p0[sl] = lb.w, lb.p0
        c.frame[sl, 0], c.frame[sl, 1], c.frame[sl, 2] = lb.origin_mm, lb.e1, lb.e2
        del lb


def _blend_geometry(piece: Piece):
    """The geometry :func:`~nurbscnc.geometry.blend.blend_corner` blends for a piece: lines
    and arcs as they are, NURBS cells and PH pieces as a
    :class:`~nurbscnc.geometry.blend.SubCurve` of their parameter range."""
    from nurbscnc.geometry.blend import SubCurve

    if isinstance(piece.geometry, LineGeometry | ArcGeometry):
        return piece.geometry
    return SubCurve(piece.geometry, piece.u_a, piece.u_b, piece.s_a_mm, piece.length_mm)


def _blend_object_corners(pieces: PieceList, c: _Corners, machine: Machine) -> None:
    """Corners with an arc, NURBS or PH piece (equal trims ≤ half the shorter piece): a
    planar PH blend one corner at a time (:func:`~nurbscnc.geometry.blend.blend_corner`),
    then every corner that has none and turns out of its plane at once, a G2 quintic
    Bézier each (:func:`~nurbscnc.geometry.blend.blend_space_corners`)."""
    from nurbscnc.geometry.blend import blend_corner, blend_space_corners

    space = []
    for j in np.flatnonzero(~c.lines).tolist():
        i = int(c.row[j])
        a, b = pieces[i - 1], pieces[i]
        args = (float(c.tol_mm[j]), 0.5 * a.length_mm, 0.5 * b.length_mm)
        bl = blend_corner(_blend_geometry(a), _blend_geometry(b), *args, measure=False)
        if bl is None:
            space.append(j)
        else:
            _take_blend(c, j, bl)
    if not space:
        return
    js = np.asarray(space, dtype=np.int64)
    js = js[_out_of_plane(pieces, c.row[js] - 1)]  # a 3-D turn no planar blend can round
    if js.size == 0:
        return
    rows = c.row[js]
    length = pieces.length_mm
    blends = blend_space_corners(pieces.path, rows - 1, rows, c.tol_mm[js],
                                 0.5 * length[rows - 1], 0.5 * length[rows])  # fmt: skip
    for j, bl in zip(js.tolist(), blends):
        if bl is not None:
            c.cap_mm_s[j] = servo_blend_cap_mm_s(machine, bl.kappa_max_per_mm)
            _take_blend(c, j, bl)


def _take_blend(c: _Corners, j: int, bl) -> None:
    """Record blend ``bl`` (PH or space) as corner ``j``'s."""
    c.obj_blends[j] = bl
    c.ok[j], c.kappa_per_mm[j] = True, bl.kappa_max_per_mm
    c.length_mm[j] = _blend_length_mm(bl)
    c.trim_a_mm[j], c.trim_b_mm[j] = bl.trim_a_mm, bl.trim_b_mm


#: Share of ε_max the servo's steady curve error may take on a space blend
#: (:func:`servo_blend_cap_mm_s`).
SERVO_BLEND_SHARE = 0.5


def servo_blend_cap_mm_s(machine: Machine, kappa_per_mm: float) -> float:
    """Feed cap [mm/s] of a space blend of peak curvature κ under the contour check: on a
    curve the servo's path grows by (c₂ + c₁²/2)·v²κ (steady circular motion;
    :func:`~nurbscnc.servo.model.error_series`, SPEC §8: 2.85e-5 s² for the paper's axes),
    kept within :data:`SERVO_BLEND_SHARE` · ε_max: v ≤ √(share·ε / (|c₂ + c₁²/2| κ)),
    the largest coefficient over the modelled axes (inf without a servo model). Why:
    the contour check's lever on a short tight blend is the feed of the pieces around it
    (measured on tort.ngc: blends at √(A/κ), 2450 mm/s² of normal acceleration, made the
    check slow 33 mm helices from 50 to 30 mm/s, +33 s over stopping)."""

    gain = servo_gain_s2(machine)
    if gain == 0.0 or not machine.contour_check or kappa_per_mm <= 0.0:
        return np.inf
    eps = SERVO_BLEND_SHARE * machine.limits.contour_tolerance_mm
    return float(servo_curve_cap_mm_s(kappa_per_mm, eps, gain))


def servo_gain_s2(machine: Machine) -> float:
    """The steady curve-error coefficient g = |c₂ + c₁²/2| [s²] of the servo (largest over
    the modelled axes; 0 without a model): the path radius grows by g·V²κ on a curve
    (:func:`~nurbscnc.servo.model.error_series`, SPEC §8: 2.85e-5 s²)."""
    from nurbscnc.servo.model import error_series

    gains = [abs(float(c[2] + 0.5 * c[1] ** 2))
             for ax in (machine.servo.x, machine.servo.y, machine.servo.z) if ax is not None
             for c in (error_series(ax),)]  # fmt: skip
    return max(gains, default=0.0)


def _blend_length_mm(bl) -> float:
    """Length [mm] of a blend: its PH quintic's, or a space blend's curve's."""
    if hasattr(bl, "ph"):
        return float(bl.ph.length_mm)
    s = bl.curve.arc_length(np.array([0.0, 1.0]))
    return float(s[1] - s[0])


def apply_blends(pieces: PieceList, machine: Machine) -> tuple[PieceList, _Corners | None]:
    """Replace corners by PH quintic blends within their tolerance (G64, issues 7 and 13).

    Every corner :func:`_find_corners` admits is blended when a blend fits: as LinuxCNC
    under G64, blending is never weighed against stopping (a blend's feed is capped by its
    peak curvature, and the look-ahead slows to that cap, which is never slower than slowing
    to 0 over the same path). A blend trims at most half of each piece, so blends never
    overlap. Line–line corners are built all at once in closed form
    (:func:`_blend_line_corners`): a polyline of short chords becomes a chain of blends with
    no sliver of line left between them (equal trims where the tolerance binds). Corners
    with an arc, NURBS or PH piece go one at a time (:func:`_blend_object_corners`). The blend
    piece is capped by its peak curvature like any curved piece (chord error, normal
    acceleration). A piece trimmed at both ends to less than :data:`MIN_REMAINDER_MM` is
    dropped. The blends' end tangents are the pieces' own unit tangents (not recomputed from
    trimmed end points), so the junctions of a blended polyline are exactly smooth. The new
    rows are written by :func:`_blended_rows`. Returns the pieces and the corners tried
    (None if none).
    """
    if len(pieces) < 2:
        return pieces, None
    c = _find_corners(pieces, machine)
    if c is None:
        return pieces, None
    _blend_line_corners(pieces, c)
    _blend_object_corners(pieces, c, machine)
    faster = _blend_is_faster(pieces, c, machine)
    c.slower = c.ok & ~faster
    c.ok &= faster
    if not c.ok.any():
        c.slower_junction = c.row[c.slower] - 1
        return pieces, c
    return _blended_rows(pieces, c, machine), c


def _speed_change_s(dv_mm_s, a_mm_s2: float, j_mm_s3: float) -> np.ndarray:
    """Time [s] of a jerk-limited speed change by ``dv_mm_s`` ≥ 0 between two instants of
    zero acceleration (the profile's transitions, SPEC §7): 2√(Δv/J) while Δv ≤ A²/J (the
    acceleration never reaches A), else Δv/A + A/J."""
    dv = np.maximum(np.asarray(dv_mm_s, dtype=float), 0.0)
    return np.where(dv <= a_mm_s2 * a_mm_s2 / j_mm_s3, 2.0 * np.sqrt(dv / j_mm_s3),
                    dv / a_mm_s2 + a_mm_s2 / j_mm_s3)  # fmt: skip


def _reach_mm_s(d_mm, a_mm_s2: float, j_mm_s3: float) -> np.ndarray:
    """The speed [mm/s] a jerk-limited start from rest reaches over ``d_mm`` (ending at zero
    acceleration): the inverse of d = v t(v)/2 with t = :func:`_speed_change_s`, i.e.
    v = (d² J)^(1/3) while v ≤ A²/J, else the root of v²/(2A) + v A/(2J) = d."""
    d = np.maximum(np.asarray(d_mm, dtype=float), 0.0)
    low = np.cbrt(d * d * j_mm_s3)
    b = a_mm_s2 / j_mm_s3  # v² + b A v − 2 A d = 0 with b A = A²/J
    high = 0.5 * (-b * a_mm_s2 + np.sqrt((b * a_mm_s2) ** 2 + 8.0 * a_mm_s2 * d))
    return np.where(low <= a_mm_s2 * a_mm_s2 / j_mm_s3, low, high)


def _blend_is_faster(pieces: PieceList, c: _Corners, machine: Machine) -> np.ndarray:
    """Which corners (m,) pass faster through their blend than stopping at the vertex
    (G64 P: LinuxCNC blends every corner; a blend so tight that crawling through it costs
    more than a stop is not used, so G64 P is never slower than G61 there).

    Estimate, per corner, the time the corner adds to cruising at v over the same span, with
    the profile's transitions (zero acceleration at their ends, :func:`_speed_change_s`
    t(Δv), covering (v + w)/2 · t(Δv)): stopping costs t(v); slowing to the blend's cap w,
    crossing its length L_b at w and speeding up again costs t(v − w)(v − w)/v + L_b/w −
    (d_a + d_b)/v (the blend replaces the trims d_a + d_b of the corner path). v: the smaller
    neighbouring cap, and at most the speed reachable from rest over half the shorter
    neighbour (:func:`_reach_mm_s`, the stop's own bound); w: the blend's curvature cap, as
    :func:`_blended_rows` gives it. On the pentagram (144° tips, P0.02, F3500) this predicts
    81.6 ms against 68.3 ms for the stop: the planner measured 13.3 ms per corner more for the
    blend."""
    m = c.row.size
    faster = np.ones(m, dtype=bool)
    if not c.ok.any():
        return faster
    lim = machine.limits
    a, b = c.row - 1, c.row
    cap = np.minimum(pieces.v_cap_mm_s[a], pieces.v_cap_mm_s[b])
    half = 0.5 * np.minimum(pieces.length_mm[a], pieces.length_mm[b])
    v = np.minimum(cap, _reach_mm_s(half, lim.a_max_mm_s2, lim.j_max_mm_s3))
    w = np.minimum(np.maximum(np.minimum(curvature_cap_mm_s(machine, c.kappa_per_mm, cap),
                                         c.cap_mm_s), MIN_CAP_MM_S), v)  # fmt: skip
    v = np.maximum(v, MIN_CAP_MM_S)
    t_dip = _speed_change_s(v - w, lim.a_max_mm_s2, lim.j_max_mm_s3) * (v - w) / v
    blend = t_dip + c.length_mm / w - (c.trim_a_mm + c.trim_b_mm) / v
    stop = _speed_change_s(v, lim.a_max_mm_s2, lim.j_max_mm_s3)
    faster[c.ok] = (blend <= stop)[c.ok]
    return faster


def _trimmed(piece: Piece, s0_mm: float, s1_mm: float) -> Piece:
    """``piece`` between arc lengths s0 and s1 [mm] from its start: lines and arcs as new
    geometries (:func:`sub_geometry`), NURBS cells as a narrower parameter range of the same
    curve, PH pieces as the PH quintic of the sub-range
    (:func:`~nurbscnc.geometry.blend.sub_ph`); exact in every case."""
    from nurbscnc.geometry.blend import sub_ph

    g = piece.geometry
    if isinstance(g, LineGeometry | ArcGeometry):
        geom = sub_geometry(piece, s0_mm, s1_mm)
        return dc_replace(piece, geometry=geom, length_mm=float(geom.length_mm), u_a=0.0,
                          u_b=float(geom.u_end))  # fmt: skip
    full = s1_mm >= piece.length_mm
    if isinstance(g, PHQuintic):
        xi = g.param_at_length(np.array([s0_mm, s1_mm]))
        sub = sub_ph(g, float(xi[0]) if s0_mm > 0.0 else 0.0, 1.0 if full else float(xi[1]))
        return dc_replace(piece, geometry=sub, length_mm=float(sub.length_mm))
    u = g.param_at_length(piece.s_a_mm + np.array([s0_mm, s1_mm]))
    return dc_replace(piece, u_a=float(u[0]) if s0_mm > 0.0 else piece.u_a,
                      u_b=piece.u_b if full else float(u[1]), s_a_mm=piece.s_a_mm + s0_mm,
                      length_mm=float(s1_mm - s0_mm))  # fmt: skip


def _blended_rows(pieces: PieceList, c: _Corners, machine: Machine) -> PieceList:
    """The pieces with the accepted blends (``c.ok``) in place: kept rows moved, trimmed
    pieces shortened, blend rows inserted before the piece after their corner."""
    k = len(pieces)
    kind, length = pieces.kind, pieces.length_mm
    ok, corner = c.ok, c.row
    # Which rows survive, and where everything goes.
    has_blend = np.zeros(k, dtype=bool)
    has_blend[corner[ok]] = True
    trim_start = np.zeros(k)
    trim_end = np.zeros(k)
    trim_start[corner[ok]] = c.trim_b_mm[ok]
    trim_end[corner[ok] - 1] = c.trim_a_mm[ok]
    trimmed = (trim_start > 0.0) | (trim_end > 0.0)
    keep = ~trimmed | (length - trim_start - trim_end >= MIN_REMAINDER_MM)
    count = has_blend.astype(np.int64) + keep
    first = np.cumsum(count) - count
    new_row = first + has_blend  # new row of each kept piece
    c.blend_row = first[corner[ok]]
    c.slower_junction = new_row[corner[c.slower]] - 1
    cols = _empty_columns(int(count.sum()))
    kept = np.flatnonzero(keep)
    dest = new_row[kept]
    for name in _SCALARS:
        cols[name][dest] = getattr(pieces, name)[kept]
    for name in _VECTORS:
        cols[name][:, dest] = getattr(pieces, name)[:, kept]
    in_objects = np.zeros(k, dtype=bool)
    in_objects[list(pieces.objects)] = True
    objects = {int(new_row[r]): v for r, v in pieces.objects.items()
               if keep[r] and not trimmed[r]}  # fmt: skip

    # Trimmed columnar lines: the sub-segment, end points as LineGeometry.point gives them.
    tl = np.flatnonzero(trimmed & keep & (kind == Kind.LINE) & ~in_objects)
    if tl.size:
        p, q = pieces.start_mm[:, tl], pieces.end_mm[:, tl]
        f0 = trim_start[tl] / length[tl]
        f1 = (length[tl] - trim_end[tl]) / length[tl]
        a_pt = p + f0 * (q - p)
        b_pt = np.where(f1 == 1.0, q, p + f1 * (q - p))
        dest = new_row[tl]
        cols["start_mm"][:, dest] = a_pt
        cols["end_mm"][:, dest] = b_pt
        cols["length_mm"][dest] = np.sqrt(np.sum((b_pt - a_pt) ** 2, axis=0))
    # Trimmed object rows (arcs, NURBS cells, PH pieces): exact sub-pieces.
    to = np.flatnonzero(trimmed & keep & in_objects).tolist()
    sub_pieces = [_trimmed(pieces[r], float(trim_start[r]),
                           float(length[r] - trim_end[r])) for r in to]  # fmt: skip
    _put_objects(cols, objects, [int(new_row[r]) for r in to], sub_pieces)

    # The line–line blends (columnar PH rows) and the other blends (PH objects).
    cap_a, cap_b = pieces.v_cap_mm_s[corner - 1], pieces.v_cap_mm_s[corner]
    sel = ok & c.lines
    dest = first[corner[sel]]
    src = corner[sel]
    feed = np.minimum(cap_a[sel], cap_b[sel])
    kappa = c.kappa_per_mm[sel]
    cols["kind"][dest] = Kind.PH
    cols["length_mm"][dest] = c.length_mm[sel]
    cols["v_cap_mm_s"][dest] = np.maximum(curvature_cap_mm_s(machine, kappa, feed), MIN_CAP_MM_S)
    cols["segment"][dest] = pieces.segment[src]
    cols["line"][dest] = pieces.line[src]
    cols["kappa_max_per_mm"][dest] = kappa
    cols["rapid"][dest] = pieces.rapid[src]
    cols["blend_mm"][dest] = pieces.blend_mm[src]
    cols["tangent_start"][:, dest] = pieces.tangent_end[:, src - 1]
    cols["tangent_end"][:, dest] = pieces.tangent_start[:, src]
    ll_ok = ok[np.flatnonzero(c.lines)]
    w, p0, frame = c.w[ll_ok], c.p0[ll_ok], c.frame[ll_ok]
    p5 = p0 + (w[:, 0] * w[:, 0] + w[:, 0] * w[:, 2] / 3.0 + w[:, 2] * w[:, 2]) / 5.0
    for name, z in (("start_mm", p0), ("end_mm", p5)):
        cols[name][:, dest] = (frame[:, 0] + z.real[:, None] * frame[:, 1]
                               + z.imag[:, None] * frame[:, 2]).T  # fmt: skip
    obj_rows, obj_pieces = [], []
    for j, bl in c.obj_blends.items():
        if not ok[j]:
            continue
        i = int(corner[j])
        feed_j = min(float(cap_a[j]), float(cap_b[j]))
        cap = max(min(float(curvature_cap_mm_s(machine, bl.kappa_max_per_mm, feed_j)),
                      float(c.cap_mm_s[j])), MIN_CAP_MM_S)  # fmt: skip
        obj_rows.append(int(first[i]))
        kind, geom = (Kind.PH, bl.ph) if hasattr(bl, "ph") else (Kind.NURBS, bl.curve)
        obj_pieces.append(Piece(kind, geom, float(c.length_mm[j]), cap,
                                int(pieces.segment[i]), int(pieces.line[i]), 0.0, 1.0, 0.0,
                                bl.kappa_max_per_mm, blend_mm=float(pieces.blend_mm[i]),
                                rapid=bool(pieces.rapid[i])))  # fmt: skip
    _put_objects(cols, objects, obj_rows, obj_pieces)

    # Columnar PH rows: the old ones (moved) and the new line–line blends, in row order.
    ph_rows = np.concatenate((new_row[pieces.ph_rows], dest))
    order = np.argsort(ph_rows, kind="stable")
    return PieceList(**cols, ph_rows=ph_rows[order],
                     ph_w=np.concatenate((pieces.ph_w, w))[order],
                     ph_p0=np.concatenate((pieces.ph_p0, p0))[order],
                     ph_frame=np.concatenate((pieces.ph_frame, frame))[order],
                     objects=objects)  # fmt: skip


def _put_objects(cols: dict, objects: dict, rows: list[int], new: list[Piece]) -> None:
    """Write Piece objects ``new`` into the columns at ``rows`` (geometry kept as object)."""
    if not new:
        return
    for r, p in zip(rows, new):
        for name in _SCALARS:
            cols[name][r] = getattr(p, name)
        objects[r] = (p.geometry, p.u_a, p.u_b, p.s_a_mm)
    ends = _object_ends(new)
    for name, arr in zip(_VECTORS, ends):
        cols[name][:, rows] = arr.T


def corner_log(pieces: PieceList, tried: _Corners | None, machine: Machine,
               options: PlanOptions) -> CornerLog:  # fmt: skip
    """Every corner and what was done there (:class:`~nurbscnc.plan.corners.CornerLog`), in
    path order: the blended corners (``tried``, with the rows of ``pieces`` their blends
    took), and every junction of the final ``pieces`` that is not tangent or where the tool
    stops. Reasons for a stop, first that applies: a rapid meets a feed move; G61.1 block end;
    a dwell or pause; a zero-length piece, a cusp, a reversal or a 3-D turn (a helix, an arc
    or curve out of the corner plane: not blendable); G61.1 / G61 (exact path) /
    ``--blend-tolerance 0`` (zero tolerance) where no tolerance allows a blend; a columnar
    blend meeting a break (not blendable); else no blend fitted within the tolerance (the
    pieces are too short for one, or its PH quintic has a loop or cusp), or one fitted but
    stopping is faster (:func:`_blend_is_faster`)."""
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
        turning, regular = _turning(pieces)
        stopped = _stopped(pieces)
        passable = _passable(pieces, turning, regular)
        corner = stopped | ~regular | (turning > SMOOTH_JUNCTION_RAD)
        j = np.flatnonzero(corner)
        if j.size:
            passed = passable[j] & ~stopped[j]
            act = np.where(passed, CornerAction.PASS, CornerAction.STOP)
            why = np.full(j.size, CornerWhy.SMALL_BREAK, dtype=np.int8)
            st = ~passed
            slower = tried.slower_junction if tried is not None else None
            why[st] = _stop_reasons(pieces, j[st], turning[j[st]], regular[j[st]], machine,
                                    options, slower)  # fmt: skip
            keys.append(j + 1)  # the row after the junction (a blend row's junctions are smooth)
            lines.append(pieces.line[j])
            points.append(pieces.end_mm[:, j].T)
            turns.append(np.where(regular[j], turning[j], np.pi))
            acts.append(act.astype(np.int8))
            whys.append(why.astype(np.int8))
    if not keys:
        return CornerLog.empty()
    order = np.argsort(np.concatenate(keys), kind="stable")
    return CornerLog(np.concatenate(lines).astype(np.int64)[order],
                     np.concatenate(points)[order], np.concatenate(turns)[order],
                     np.concatenate(acts)[order], np.concatenate(whys)[order])  # fmt: skip


def settle_time_s(machine: Machine) -> float:
    """Time [s] for the slowest servo mode to decay to e⁻⁵ (< 1 %) of its amplitude."""
    slowest = min((
        float(np.min(np.abs(np.real(ax.poles()))))
        for ax in (machine.servo.x, machine.servo.y, machine.servo.z)
        if ax is not None
    ), default=np.inf)  # no servo model: ideal axes, nothing to settle (0 s)
    return 5.0 / slowest


def _stop_reasons(pieces: PieceList, j: np.ndarray, turning: np.ndarray, regular: np.ndarray,
                  machine: Machine, options: PlanOptions,
                  slower: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
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
    degenerate = (~regular | (turning > np.pi - MIN_REVERSAL_RAD) | (length[j] == 0.0)
                  | (length[j + 1] == 0.0))  # fmt: skip
    why[degenerate] = CornerWhy.NOT_BLENDABLE
    # Two lines always lie in one plane: only corners with a curved piece can be 3-D turns.
    objects = np.zeros(len(pieces), dtype=bool)
    objects[list(pieces.objects)] = True
    failed = np.flatnonzero((why == CornerWhy.NO_BLEND_FITS) & (objects[j] | objects[j + 1]))
    why[failed[_out_of_plane(pieces, j[failed])]] = CornerWhy.NOT_BLENDABLE
    why[stop_after[j]] = CornerWhy.DWELL_OR_PAUSE
    block_end = (stop_after[j] & (blend[j] < 0.0) & (seg[j] != seg[j + 1])
                 & (pieces.dwell_after_s[j] == 0.0))  # fmt: skip
    why[block_end] = CornerWhy.EXACT_STOP
    why[rapid[j] != rapid[j + 1]] = CornerWhy.RAPID_FEED
    return why


def _out_of_plane(pieces: PieceList, j: np.ndarray) -> np.ndarray:
    """Which junctions ``j`` join pieces that do not lie in the plane of their two tangents
    (a helix, an arc or a curve leaving the corner plane: a 3-D turn no planar blend can
    round). One geometry check per junction: call it on the few that failed to blend."""
    from nurbscnc.geometry.blend import _planar_kind

    out = np.zeros(j.size, dtype=bool)
    for n, r in enumerate(j.tolist()):
        normal = np.cross(pieces.tangent_end[:, r], pieces.tangent_start[:, r + 1])
        size = float(np.linalg.norm(normal))
        if size == 0.0:
            continue
        vertex = pieces.end_mm[:, r]
        out[n] = not all(_planar_kind(_blend_geometry(pieces[i]), normal / size, vertex)
                         for i in (r, r + 1))  # fmt: skip
    return out


def junction_caps(pieces: PieceList) -> np.ndarray:
    """Cap at each junction [mm/s] (k+1): 0 at the ends and wherever the tool stops
    (:func:`_stopped`: dwells, pauses, exact stops, rapid/feed changes, zero-length pieces),
    at breaks it cannot pass (:func:`_passable`: a turning above :data:`SMOOTH_JUNCTION_RAD`
    and above the small-break rule of :func:`pass_velocity_jump_mm_s`, or a zero tangent: a
    cusp); else the smaller neighbouring cruise cap. One vectorised pass over the cached unit
    tangents."""
    k = len(pieces)
    caps = np.zeros(k + 1)
    if k < 2:
        return caps
    turning, regular = _turning(pieces)
    smooth = _passable(pieces, turning, regular) & ~_stopped(pieces)
    cap = pieces.v_cap_mm_s
    caps[1:-1] = np.where(smooth, np.minimum(cap[:-1], cap[1:]), 0.0)
    # Curvature jumps passed at speed: the acceleration step's jerk (junction_jump_cap_mm_s).
    j = pieces.jump_rows + 1
    caps[j] = np.minimum(caps[j], pieces.jump_cap_mm_s)
    return caps
