"""Corner blends (G64): the corners that may be blended and the blend fitted at each (PH
quintics in the plane, G2 space blends for 3-D turns), with their feed caps."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from nurbscnc.errors import GeometryError, SourcePos
from nurbscnc.geometry.blend import ph_tables
from nurbscnc.geometry.path import Kind
from nurbscnc.geometry.paths import ArcGeometry, LineGeometry, cross3
from nurbscnc.geometry.segments import blend_tolerance_mm
from nurbscnc.machine.caps import servo_curve_cap_mm_s
from nurbscnc.machine.profile import Machine
from nurbscnc.plan.junctions import junction_turning, passable_junctions, stopped_junctions
from nurbscnc.plan.pieces import CHUNK_ROWS, Piece, PieceList


@dataclass(eq=False)
class Corners:
    """Candidate corners of :func:`~nurbscnc.plan.blend_choice.apply_blends` and what
    blending each would do (arrays over the m corners): ``row`` the piece after the corner;
    ``tol_mm`` the blend tolerance; ``vertex_mm`` (3, m); ``turning_rad`` the tangent
    turning there; ``lines`` whether both sides are lines; ``line`` the source line of the
    piece before; ``blend_row`` the row of each accepted blend in the blended list; then,
    per corner, ``ok`` (a blend exists), its peak curvature, trims of the piece before
    (``trim_a_mm``) and after (``trim_b_mm``) and length; line–line blends' PH data
    (preimage ``w``, start ``p0``, plane ``frame``, one row per line–line corner) and the
    other blends (PH objects) by corner."""

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
    #: Corners whose blend fitted but stopping is faster
    #: (:func:`~nurbscnc.plan.blend_choice._blend_is_faster`), and the junction of the
    #: blended list each such stop is at.
    slower: np.ndarray = None
    slower_junction: np.ndarray = None
    #: A further feed cap of each blend [mm/s] (inf: none): the servo's on space blends.
    cap_mm_s: np.ndarray = None
    #: Corners of a turn-around (:mod:`nurbscnc.plan.turnarounds`): both corners ``turn``;
    #: the second ``absorbed`` (its trims are the first one's U's, it has no blend row).
    turn: np.ndarray = None
    absorbed: np.ndarray = None
    #: Rows a turn-around's U takes (its cells).
    cells: np.ndarray = None

    def __post_init__(self):
        m = self.row.size
        self.cap_mm_s = np.full(m, np.inf)
        self.ok = np.zeros(m, dtype=bool)
        self.kappa_per_mm, self.length_mm = np.zeros(m), np.zeros(m)
        self.trim_a_mm, self.trim_b_mm = np.zeros(m), np.zeros(m)
        self.turn, self.absorbed = np.zeros(m, dtype=bool), np.zeros(m, dtype=bool)
        self.cells = np.ones(m, dtype=np.int64)


def tolerance_mm(blend_mm: np.ndarray, machine: Machine) -> np.ndarray:
    """The blend tolerance [mm] of each row from its path-control value (``blend_mm``, see
    :class:`~nurbscnc.geometry.segments.Line`): G64 P as given, G64 without P (inf) the
    machine's ``limits.path_tolerance_mm``, G61 / G61.1 (≤ 0) none."""
    return blend_tolerance_mm(blend_mm, machine.limits.path_tolerance_mm)


def find_corners(pieces: PieceList, machine: Machine) -> Corners | None:
    """Corners that may be blended: any two pieces (lines, arcs, NURBS cells, PH pieces; not
    the columnar line–line blends, which meet lines tangentially) of the same kind of motion
    (feed or rapid), with a blend tolerance > 0 (the smaller of the two), no stop between
    them, a break not small enough to pass (:func:`~nurbscnc.plan.junctions.passable_junctions`).
    The pieces must meet there (GeometryError otherwise)."""
    k = len(pieces)
    kind = pieces.kind
    tol_row = tolerance_mm(pieces.blend_mm, machine)
    tol = np.minimum(tol_row[:-1], tol_row[1:])
    turning, regular = junction_turning(pieces)
    columnar = np.zeros(k, dtype=bool)
    columnar[pieces.ph_rows] = True
    cand = (
        ~columnar[:-1]
        & ~columnar[1:]
        & ~stopped_junctions(pieces)
        & (tol > 0.0)
        & regular
        & ~passable_junctions(pieces, turning, regular)
    )
    corner = np.flatnonzero(cand) + 1
    if corner.size == 0:
        return None
    vertex = pieces.end_mm[:, corner - 1]
    gap = np.sqrt(np.sum((vertex - pieces.start_mm[:, corner]) ** 2, axis=0))
    scale = np.maximum(1.0, np.abs(vertex).max(axis=0))
    if np.any(gap > 1e-6 * scale):
        i = int(corner[np.argmax(gap > 1e-6 * scale)])
        raise GeometryError(
            f"blend_corner: the geometries do not meet (gap {gap.max():.3g} mm)",
            SourcePos(int(pieces.line[i])),
        )
    is_line = (kind == Kind.LINE) & ~np.isin(np.arange(k), list(pieces.objects))
    lines = is_line[corner - 1] & is_line[corner]
    return Corners(
        corner, tol[corner - 1], vertex, turning[corner - 1], lines, pieces.line[corner - 1]
    )


def blend_line_corners(pieces: PieceList, c: Corners) -> None:
    """Line–line corners in closed form, in chunks (bounded temporaries), each side trimmed
    up to half of its own line (:func:`~nurbscnc.geometry.blend.line_corner_blends`)."""
    from nurbscnc.geometry.blend import line_corner_blends

    ll = np.flatnonzero(c.lines)
    length = pieces.length_mm
    c.w = np.empty((ll.size, 3), dtype=complex)
    c.p0 = np.empty(ll.size, dtype=complex)
    c.frame = np.empty((ll.size, 3, 3))
    for lo in range(0, ll.size, CHUNK_ROWS):
        sl = slice(lo, lo + CHUNK_ROWS)
        j = ll[sl]
        r = c.row[j]
        lb = line_corner_blends(
            c.vertex_mm[:, j].T,
            pieces.tangent_end[:, r - 1].T,
            pieces.tangent_start[:, r].T,
            c.tol_mm[j],
            0.5 * length[r - 1],
            0.5 * length[r],
        )
        c.ok[j], c.kappa_per_mm[j] = lb.ok, lb.kappa_max_per_mm
        c.trim_a_mm[j], c.trim_b_mm[j] = lb.trim_a_mm, lb.trim_b_mm
        c.length_mm[j] = ph_tables(lb.w, lb.p0)[3]
        c.w[sl], c.p0[sl] = lb.w, lb.p0
        c.frame[sl, 0], c.frame[sl, 1], c.frame[sl, 2] = lb.origin_mm, lb.e1, lb.e2
        del lb


def blend_geometry(piece: Piece):
    """The geometry :func:`~nurbscnc.geometry.blend.blend_corner` blends for a piece: lines
    and arcs as they are, NURBS cells and PH pieces as a
    :class:`~nurbscnc.geometry.blend.SubCurve` of their parameter range."""
    from nurbscnc.geometry.blend import SubCurve

    if isinstance(piece.geometry, LineGeometry | ArcGeometry):
        return piece.geometry
    return SubCurve(piece.geometry, piece.u_a, piece.u_b, piece.s_a_mm, piece.length_mm)


def blend_object_corners(pieces: PieceList, c: Corners, machine: Machine) -> None:
    """Corners with an arc, NURBS or PH piece (equal trims ≤ half the shorter side, a side
    being the piece there with the cells of its curve it continues into:
    :func:`~nurbscnc.plan.cell_spans.corner_spans`): a planar PH blend one corner at a time
    (:func:`~nurbscnc.geometry.blend.blend_corner`), then every corner that has none and
    turns out of its plane at once, a G2 quintic Bézier each
    (:func:`~nurbscnc.geometry.blend.blend_space_corners`)."""
    from nurbscnc.geometry.blend import blend_corner, blend_space_corners
    from nurbscnc.geometry.path import PathTable
    from nurbscnc.plan.cell_spans import corner_spans, span_row

    obj = np.flatnonzero(~c.lines & ~c.turn)
    lo, hi = corner_spans(pieces, c.row[obj])
    span = {j: (int(a), int(b)) for j, a, b in zip(obj.tolist(), lo, hi)}
    length = pieces.length_mm
    space = []
    for j in obj.tolist():
        i = int(c.row[j])
        a, b = span[j]
        if a == i - 1 and b == i:
            ga, gb = blend_geometry(pieces[i - 1]), blend_geometry(pieces[i])
        else:
            ga, gb = (_span_geometry(span_row(pieces, *rs)) for rs in ((a, i - 1), (i, b)))
        half_a, half_b = 0.5 * length[a:i].sum(), 0.5 * length[i : b + 1].sum()
        bl = blend_corner(ga, gb, float(c.tol_mm[j]), half_a, half_b, measure=False)
        if bl is None:
            space.append(j)
        else:
            _take_blend(c, j, bl)
    if not space:
        return
    js = np.asarray(space, dtype=np.int64)
    js = js[out_of_plane(pieces, c.row[js] - 1)]  # a 3-D turn no planar blend can round
    if js.size == 0:
        return
    rows = c.row[js]
    ends = np.array([span[j] for j in js.tolist()], dtype=np.int64).reshape(-1, 2)
    half_a = 0.5 * np.array([length[a:i].sum() for i, (a, _) in zip(rows.tolist(), ends.tolist())])
    half_b = 0.5 * np.array(
        [length[i : b + 1].sum() for i, (_, b) in zip(rows.tolist(), ends.tolist())]
    )
    if np.all((ends[:, 0] == rows - 1) & (ends[:, 1] == rows)):
        path, rows_a, rows_b = pieces.path, rows - 1, rows
    else:  # a table of the corners' sides, spans of cells as one row each
        path = PathTable.of(
            [
                span_row(pieces, *rs)
                for i, (a, b) in zip(rows.tolist(), ends.tolist())
                for rs in ((a, i - 1), (i, b))
            ]
        )
        rows_a = np.arange(0, 2 * rows.size, 2)
        rows_b = rows_a + 1
    blends = blend_space_corners(path, rows_a, rows_b, c.tol_mm[js], half_a, half_b)
    _share_moved_tables(blends)
    found = [(j, bl) for j, bl in zip(js.tolist(), blends) if bl is not None]
    kappa = np.array([bl.kappa_max_per_mm for _, bl in found])
    for (j, bl), cap in zip(found, servo_blend_caps_mm_s(machine, kappa).tolist()):
        c.cap_mm_s[j] = cap
        _take_blend(c, j, bl)


def _span_geometry(row: tuple):
    """The geometry :func:`~nurbscnc.geometry.blend.blend_corner` blends for a span's
    path row (:func:`~nurbscnc.plan.cell_spans.span_row`): a line as it is, cells of a
    curve as a :class:`~nurbscnc.geometry.blend.SubCurve` of their parameter range."""
    from nurbscnc.geometry.blend import SubCurve

    kind, geom, length, u_a, u_b, s_a, _ = row
    if kind != Kind.NURBS:
        return geom
    return SubCurve(geom, u_a, u_b, s_a, length)


def _share_moved_tables(blends: list) -> None:
    """Space blends whose curve is an earlier one's moved (the plunge into each pass of a
    pocket cut again one depth lower) take that curve's arc-length tables s(u) and u(s)
    (:meth:`~nurbscnc.geometry.nurbs.NurbsCurve.sharing_tables`: arc length does not
    depend on where a curve lies) instead of building their own, milliseconds a curve."""
    from nurbscnc.geometry.nurbs import MovedCopies

    copies = MovedCopies()
    for bl in blends:
        if bl is None:
            continue
        hit = copies.find(bl.curve)
        if hit is None:
            copies.add(bl.curve, bl.curve)
        else:
            bl.curve.sharing_tables(hit[0])


def _take_blend(c: Corners, j: int, bl) -> None:
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
    (blends capped at √(A/κ) alone made the check slow the helices around them, costing
    far more than a stop)."""
    return float(servo_blend_caps_mm_s(machine, np.array([float(kappa_per_mm)]))[0])


def servo_blend_caps_mm_s(machine: Machine, kappa_per_mm: np.ndarray) -> np.ndarray:
    """:func:`servo_blend_cap_mm_s` of every peak curvature κ (m,) [1/mm] at once [mm/s]:
    the servo's coefficient found once (its error series is the costly part), then one
    elementwise √ (correctly rounded: the same values as one blend at a time)."""
    kappa = np.asarray(kappa_per_mm, dtype=float)
    out = np.full(kappa.shape, np.inf)
    gain = servo_gain_s2(machine) if kappa.size and machine.contour_check else 0.0
    live = kappa > 0.0
    if gain == 0.0 or not live.any():
        return out
    eps = SERVO_BLEND_SHARE * machine.limits.contour_tolerance_mm
    out[live] = servo_curve_cap_mm_s(kappa[live], eps, gain)
    return out


def servo_gain_s2(machine: Machine) -> float:
    """The steady curve-error coefficient g = |c₂ + c₁²/2| [s²] of the servo (largest over
    the modelled axes; 0 without a model): the path radius grows by g·V²κ on a curve
    (:func:`~nurbscnc.servo.model.error_series`, SPEC §8: 2.85e-5 s²)."""
    from nurbscnc.servo.model import error_series

    gains = [
        abs(float(c[2] + 0.5 * c[1] ** 2))
        for ax in (machine.servo.x, machine.servo.y, machine.servo.z)
        if ax is not None
        for c in (error_series(ax),)
    ]
    return max(gains, default=0.0)


def _blend_length_mm(bl) -> float:
    """Length [mm] of a blend: its PH quintic's, or a space blend's curve's."""
    if hasattr(bl, "ph"):
        return float(bl.ph.length_mm)
    s = bl.curve.arc_length(np.array([0.0, 1.0]))
    return float(s[1] - s[0])


def out_of_plane(pieces: PieceList, j: np.ndarray) -> np.ndarray:
    """Which junctions ``j`` join pieces that do not lie in the plane of their two tangents
    (a helix, an arc or a curve leaving the corner plane: a 3-D turn no planar blend can
    round). One geometry check per junction: call it on the few that failed to blend."""
    from nurbscnc.geometry.blend import planar_kind

    out = np.zeros(j.size, dtype=bool)
    for n, r in enumerate(j.tolist()):
        normal = cross3(pieces.tangent_end[:, r], pieces.tangent_start[:, r + 1])
        size = float(np.linalg.norm(normal))
        if size == 0.0:
            continue
        vertex = pieces.end_mm[:, r]
        out[n] = not all(
            planar_kind(blend_geometry(pieces[i]), normal / size, vertex) for i in (r, r + 1)
        )
    return out
