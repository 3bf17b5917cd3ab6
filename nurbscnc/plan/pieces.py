"""Planner pieces: the piece types, :class:`Piece` and the columnar :class:`PieceList`.

The program's path is cut into pieces the feed profile treats as units
(:func:`~nurbscnc.plan.program_pieces.segment_pieces`). Every piece knows its exact geometry,
its length, its cruise cap (SPEC §7, formulas in :mod:`nurbscnc.machine.caps`) and its unit
tangents at both ends (for the junctions). Its kind is the path model's
:class:`~nurbscnc.geometry.path.Kind` (a rapid is a line with the ``rapid`` flag); everything
that samples the pieces goes through :attr:`PieceList.path`, the
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

import numpy as np

from nurbscnc.geometry.blend import ph_tables
from nurbscnc.geometry.path import Kind, PathTable, ph_power_rows
from nurbscnc.geometry.paths import LineGeometry
from nurbscnc.geometry.ph import PHQuintic
from nurbscnc.plan.corners import CornerLog

#: Summary names of the piece kinds, in summary order ("rapid": a rapid line).
KIND_NAMES = ("line", "rapid", "arc", "ph", "nurbs")


_NAME_OF = {
    Kind.LINE: "line",
    Kind.ARC: "arc",
    Kind.SPIRAL: "arc",
    Kind.PH: "ph",
    Kind.NURBS: "nurbs",
}


@dataclass(frozen=True, eq=False)
class Piece:
    """One piece of the path, as built (arcs, NURBS cells, PH pieces) or read from a row.

    ``kind`` its :class:`~nurbscnc.geometry.path.Kind`; ``geometry`` evaluates it: a
    NurbsCurve (``u_a``..``u_b`` of it, starting at arc length ``s_a_mm`` of the curve), a
    PHQuintic (ξ ∈ [0, 1]), a LineGeometry or an ArcGeometry (``u_a``..``u_b``).
    ``length_mm`` [mm]; ``v_cap_mm_s`` the cruise cap [mm/s]; ``segment`` / ``line`` where
    it came from; ``dwell_after_s`` a dwell [s] at its end (G4); ``stop_after``: the tool
    comes to rest at its end (a dwell, a pause, a G61.1 block end); ``pass_after``: the
    break at its end is small enough to pass at speed
    (:func:`~nurbscnc.plan.junctions.small_breaks`). ``kappa_max_per_mm`` the largest
    curvature on it [1/mm]. ``blend_mm`` the path-control value of its segment
    (:class:`~nurbscnc.geometry.segments.Line`; :func:`~nurbscnc.plan.blends.tolerance_mm`
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
        """ "line", "rapid", "arc", "ph" or "nurbs" (summaries)."""
        return "rapid" if self.rapid else _NAME_OF[Kind(self.kind)]

    def path_row(self) -> tuple:
        """The row of :meth:`PathTable.of <nurbscnc.geometry.path.PathTable.of>` for it."""
        return (
            self.kind,
            self.geometry,
            self.length_mm,
            self.u_a,
            self.u_b,
            self.s_a_mm,
            self.line,
        )

    def points_mm(self, s_local_mm: np.ndarray) -> np.ndarray:
        """Exact points [mm] (m, 3) at arc lengths ``s_local_mm`` from the piece start."""
        s = np.ravel(np.asarray(s_local_mm, dtype=float))
        return PathTable.of([self.path_row()]).points(np.zeros(s.size, np.intp), s)[0]

    def tangent_start(self) -> np.ndarray:
        """Unit tangent at the start (zero at a cusp)."""
        return object_ends([self])[2][0]

    def tangent_end(self) -> np.ndarray:
        """Unit tangent at the end (zero at a cusp)."""
        return object_ends([self])[3][0]


VECTOR_COLUMNS = ("start_mm", "end_mm", "tangent_start", "tangent_end")


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
    #: Junctions where the curvature vector jumps
    #: (:func:`~nurbscnc.plan.junctions.curvature_jumps`): ``jump_rows`` (m,) junction j
    #: between rows j and j + 1, ``jump_kn`` (m, 3) the jump Δ(κn) [1/mm],
    #: ``jump_cap_mm_s`` (m,) the speed cap there
    #: (:func:`~nurbscnc.machine.caps.junction_jump_cap_mm_s`), applied by
    #: :func:`~nurbscnc.plan.junctions.junction_caps`.
    jump_rows: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    jump_kn: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    jump_cap_mm_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: What smoothing fitted (:func:`~nurbscnc.plan.smoothing.smoothing_summary`: runs,
    #: lines, deviation bound [µm]), None when nothing was.
    smoothed: dict | None = None
    #: The rotary axes A B C on every row and the rotary-only moves
    #: (:class:`~nurbscnc.plan.rotary.RotaryPieces`), None for a program without them.
    rotary: object | None = None

    @classmethod
    def of(cls, pieces: Sequence[Piece]) -> PieceList:
        """The columns of a list of :class:`Piece` objects (each kept as its geometry)."""
        cols = empty_columns(len(pieces))
        objects: dict = {}
        put_objects(cols, objects, list(range(len(pieces))), list(pieces))
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
        return Piece(
            kind,
            geom,
            float(self.length_mm[i]),
            float(self.v_cap_mm_s[i]),
            int(self.segment[i]),
            int(self.line[i]),
            u_a,
            u_b,
            s_a,
            float(self.kappa_max_per_mm[i]),
            float(self.dwell_after_s[i]),
            float(self.blend_mm[i]),
            bool(self.rapid[i]),
            bool(self.stop_after[i]),
            bool(self.pass_after[i]),
        )

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
        obj_id = np.full(k, -1, dtype=np.intp) if need_obj else np.broadcast_to(np.intp(-1), (k,))
        objects: tuple = ()
        sub = None
        if rows_obj.size:
            # Their rows (:meth:`Piece.path_row`) straight from the columns and ``objects``,
            # without a Piece each (building those Pieces dominated the path's cost).
            objs = [self.objects[r] for r in rows_obj.tolist()]
            sub = PathTable.of(
                [
                    (kind, g, length, ua, ub, sa, line)
                    for kind, (g, ua, ub, sa), length, line in zip(
                        obj_kind.tolist(),
                        objs,
                        self.length_mm[rows_obj].tolist(),
                        self.line[rows_obj].tolist(),
                    )
                ]
            )
        # PH coefficients in one column per PH row (lines need none: a CAM program's
        # 41 % line rows would hold 184 zero bytes each): the columnar rows' first, in row
        # order, then the object rows' PH pieces.
        sub_ph = np.flatnonzero(sub.ph_slot >= 0) if sub is not None else np.zeros(0, np.intp)
        m = self.ph_rows.size
        ph_s, ph_x, ph_y = (np.zeros((6, m + sub_ph.size)) for _ in range(3))
        ph_sigma = np.zeros((5, m + sub_ph.size))
        ph_slot = np.full(k, -1, dtype=np.intp)
        ph_slot[self.ph_rows] = np.arange(m)
        for lo in range(0, m, CHUNK_ROWS):
            sl = slice(lo, min(lo + CHUNK_ROWS, m))  # the columnar rows' columns only
            rows = self.ph_rows[sl]
            pts, sigma, s, _ = ph_tables(self.ph_w[sl], self.ph_p0[sl])
            ph_s[:, sl], ph_sigma[:, sl], ph_x[:, sl], ph_y[:, sl] = ph_power_rows(s, sigma, pts)
            frame = self.ph_frame[sl]
            origin[:, rows], e1[:, rows], e2[:, rows] = frame[:, 0].T, frame[:, 1].T, frame[:, 2].T
        if sub is not None:
            code[rows_obj] = sub.kind
            objects = sub.objects
            for mine, theirs in (
                (origin, sub.origin_mm),
                (e1, sub.e1),
                (e2, sub.e2),
                (normal, sub.normal),
            ):
                if mine.flags.writeable:
                    mine[:, rows_obj] = theirs
            for mine, theirs in (
                (radius, sub.radius_mm),
                (angle, sub.angle_rad),
                (helix, sub.helix_mm),
                (u_a, sub.u_a),
                (u_b, sub.u_b),
                (s_a, sub.s_a_mm),
                (obj_id, sub.obj_id),
            ):
                if mine.flags.writeable:
                    mine[rows_obj] = theirs
            if sub_ph.size:
                ph_slot[rows_obj[sub_ph]] = m + np.arange(sub_ph.size)
                for mine, theirs in (
                    (ph_s, sub.ph_s),
                    (ph_x, sub.ph_x),
                    (ph_y, sub.ph_y),
                    (ph_sigma, sub.ph_sigma),
                ):
                    mine[:, m:] = theirs[:, sub.ph_slot[sub_ph]]
        return PathTable(
            code,
            self.length_mm,
            self.line,
            self.start_mm,
            self.end_mm,
            origin,
            e1,
            e2,
            normal,
            radius,
            angle,
            helix,
            ph_s,
            ph_sigma,
            ph_x,
            ph_y,
            ph_slot,
            obj_id,
            objects,
            u_a,
            u_b,
            s_a,
        ).frozen()


#: Rows per chunk of the vectorised PH work (bounds the temporaries).
CHUNK_ROWS = 1 << 16


SCALAR_COLUMNS = (
    "kind",
    "length_mm",
    "v_cap_mm_s",
    "segment",
    "line",
    "kappa_max_per_mm",
    "dwell_after_s",
    "blend_mm",
    "rapid",
    "stop_after",
    "pass_after",
)


COLUMN_DTYPES = {
    "kind": np.int8,
    "segment": np.int64,
    "line": np.int64,
    "rapid": bool,
    "stop_after": bool,
    "pass_after": bool,
}


def empty_columns(k: int) -> dict:
    cols = {name: np.zeros(k, dtype=COLUMN_DTYPES.get(name, float)) for name in SCALAR_COLUMNS}
    for name in VECTOR_COLUMNS:
        cols[name] = np.zeros((3, k))
    return cols


def _unit_rows(d: np.ndarray) -> np.ndarray:
    """Rows of ``d`` (m, 3) scaled to unit length (zero rows stay zero)."""
    n = np.sqrt(np.einsum("ij,ij->i", d, d))
    return d / np.where(n > 0.0, n, 1.0)[:, None]


def object_ends(pieces) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
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


def put_objects(cols: dict, objects: dict, rows: list[int], new: list[Piece]) -> None:
    """Write Piece objects ``new`` into the columns at ``rows`` (geometry kept as object)."""
    if not new:
        return
    for r, p in zip(rows, new):
        for name in SCALAR_COLUMNS:
            cols[name][r] = getattr(p, name)
        objects[r] = (p.geometry, p.u_a, p.u_b, p.s_a_mm)
    ends = object_ends(new)
    for name, arr in zip(VECTOR_COLUMNS, ends):
        cols[name][:, rows] = arr.T
