"""The pieces with their accepted corner blends in place: trimmed pieces (exact
sub-geometries) and the blend rows inserted."""

from __future__ import annotations

from dataclasses import replace as dc_replace

import numpy as np

from nurbscnc.geometry.path import Kind
from nurbscnc.geometry.paths import ArcGeometry, LineGeometry, cross3
from nurbscnc.geometry.ph import PHQuintic
from nurbscnc.machine.caps import MIN_CAP_MM_S, curvature_cap_mm_s
from nurbscnc.machine.profile import Machine
from nurbscnc.plan.blends import Corners
from nurbscnc.plan.cell_spans import row_trims
from nurbscnc.plan.pieces import (
    SCALAR_COLUMNS,
    VECTOR_COLUMNS,
    Piece,
    PieceList,
    empty_columns,
    put_objects,
)
from nurbscnc.plan.turnarounds import servo_cap_mm_s, turn_cells

#: What is left of a line or arc between two blends, if shorter than this [mm], is dropped:
#: such a sliver (two blends that almost meet, e.g. 4e-9 mm) carries no motion worth a piece.
#: The path then jumps by less than this from one blend's end to the next one's start.
MIN_REMAINDER_MM = 1e-6
#: A blend belongs to both moves: its feed is the faster of theirs, as LinuxCNC 2.9's blend
#: arcs take (tp.c blendInitCommonParams: v_req = max of both moves' requested speeds); its
#: own curvature caps it (SPEC eq. 24) and the per-axis limits cap it as every piece
#: (plan/axes.py). The slower move keeps its feed up to where the blend starts: a plunge at
#: F10 into a cut at F30 no longer drags the blend, which may span several of the cut's
#: short moves, down to F10. The blend belongs to that faster move (its segment and source line).
BLEND_FEED = np.maximum


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
        e2=cross3(g.normal, e1),
        radius_start_mm=g.radius_start_mm + t0 * dr,
        radius_end_mm=g.radius_start_mm + t1 * dr,
        angle_rad=(t1 - t0) * g.angle_rad,
        helix_mm=(t1 - t0) * g.helix_mm,
    )


def trimmed_piece(piece: Piece, s0_mm: float, s1_mm: float) -> Piece:
    """``piece`` between arc lengths s0 and s1 [mm] from its start: lines and arcs as new
    geometries (:func:`sub_geometry`), NURBS cells as a narrower parameter range of the same
    curve, PH pieces as the PH quintic of the sub-range
    (:func:`~nurbscnc.geometry.blend.sub_ph`); exact in every case."""
    from nurbscnc.geometry.blend import sub_ph

    g = piece.geometry
    if isinstance(g, LineGeometry | ArcGeometry):
        geom = sub_geometry(piece, s0_mm, s1_mm)
        return dc_replace(
            piece, geometry=geom, length_mm=float(geom.length_mm), u_a=0.0, u_b=float(geom.u_end)
        )
    full = s1_mm >= piece.length_mm
    if isinstance(g, PHQuintic):
        xi = g.param_at_length(np.array([s0_mm, s1_mm]))
        sub = sub_ph(g, float(xi[0]) if s0_mm > 0.0 else 0.0, 1.0 if full else float(xi[1]))
        return dc_replace(piece, geometry=sub, length_mm=float(sub.length_mm))
    u = g.param_at_length(piece.s_a_mm + np.array([s0_mm, s1_mm]))
    return dc_replace(
        piece,
        u_a=float(u[0]) if s0_mm > 0.0 else piece.u_a,
        u_b=piece.u_b if full else float(u[1]),
        s_a_mm=piece.s_a_mm + s0_mm,
        length_mm=float(s1_mm - s0_mm),
    )


def blended_rows(pieces: PieceList, c: Corners, machine: Machine) -> PieceList:
    """The pieces with the accepted blends (``c.ok``) in place: kept rows moved, trimmed
    pieces shortened, blend rows inserted before the piece after their corner."""
    k = len(pieces)
    kind, length = pieces.kind, pieces.length_mm
    ok, corner = c.ok, c.row
    # Which rows survive, and where everything goes.
    has_blend = np.zeros(k, dtype=np.int64)  # blend rows before each row
    own = ok & ~c.absorbed
    has_blend[corner[own]] = [_cells(c, j) for j in np.flatnonzero(own).tolist()]
    # a trim past its piece goes on into the cells of its span (plan/cell_spans.py)
    trim_start, trim_end = row_trims(
        pieces, corner[ok], c.trim_a_mm[ok], c.trim_b_mm[ok], ~c.turn[ok]
    )
    trimmed = (trim_start > 0.0) | (trim_end > 0.0)
    keep = ~trimmed | (length - trim_start - trim_end >= MIN_REMAINDER_MM)
    count = has_blend + keep
    first = np.cumsum(count) - count
    new_row = first + has_blend  # new row of each kept piece
    c.blend_row = first[corner[ok]]
    c.slower_junction = new_row[corner[c.slower]] - 1
    cols = empty_columns(int(count.sum()))
    kept = np.flatnonzero(keep)
    dest = new_row[kept]
    for name in SCALAR_COLUMNS:
        cols[name][dest] = getattr(pieces, name)[kept]
    for name in VECTOR_COLUMNS:
        cols[name][:, dest] = getattr(pieces, name)[:, kept]
    in_objects = np.zeros(k, dtype=bool)
    in_objects[list(pieces.objects)] = True
    objects = {int(new_row[r]): v for r, v in pieces.objects.items() if keep[r] and not trimmed[r]}

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
    sub_pieces = [
        trimmed_piece(pieces[r], float(trim_start[r]), float(length[r] - trim_end[r])) for r in to
    ]
    put_objects(cols, objects, [int(new_row[r]) for r in to], sub_pieces)

    # The line–line blends (columnar PH rows) and the other blends (PH objects), at the
    # faster of both moves' feeds (:data:`BLEND_FEED`), capped by their own curvature.
    cap_a, cap_b = pieces.v_cap_mm_s[corner - 1], pieces.v_cap_mm_s[corner]
    sel = ok & c.lines
    dest = first[corner[sel]]
    src = corner[sel]
    feed = BLEND_FEED(cap_a[sel], cap_b[sel])
    kappa = c.kappa_per_mm[sel]
    cols["kind"][dest] = Kind.PH
    cols["length_mm"][dest] = c.length_mm[sel]
    cols["v_cap_mm_s"][dest] = np.maximum(curvature_cap_mm_s(machine, kappa, feed), MIN_CAP_MM_S)
    # the blend belongs to the move whose feed it runs at (never faster than that move's F)
    of = np.where(cap_a[sel] > cap_b[sel], src - 1, src)
    cols["segment"][dest] = pieces.segment[of]
    cols["line"][dest] = pieces.line[of]
    cols["kappa_max_per_mm"][dest] = kappa
    cols["rapid"][dest] = pieces.rapid[src]
    cols["blend_mm"][dest] = pieces.blend_mm[src]
    cols["tangent_start"][:, dest] = pieces.tangent_end[:, src - 1]
    cols["tangent_end"][:, dest] = pieces.tangent_start[:, src]
    ll_ok = ok[np.flatnonzero(c.lines)]
    w, p0, frame = c.w[ll_ok], c.p0[ll_ok], c.frame[ll_ok]
    p5 = p0 + (w[:, 0] * w[:, 0] + w[:, 0] * w[:, 2] / 3.0 + w[:, 2] * w[:, 2]) / 5.0
    for name, z in (("start_mm", p0), ("end_mm", p5)):
        cols[name][:, dest] = (
            frame[:, 0] + z.real[:, None] * frame[:, 1] + z.imag[:, None] * frame[:, 2]
        ).T
    obj_rows, obj_pieces = _object_blends(pieces, c, machine, ok, first)
    put_objects(cols, objects, obj_rows, obj_pieces)

    # Columnar PH rows: the old ones (moved) and the new line–line blends, in row order.
    ph_rows = np.concatenate((new_row[pieces.ph_rows], dest))
    order = np.argsort(ph_rows, kind="stable")
    return PieceList(
        **cols,
        ph_rows=ph_rows[order],
        ph_w=np.concatenate((pieces.ph_w, w))[order],
        ph_p0=np.concatenate((pieces.ph_p0, p0))[order],
        ph_frame=np.concatenate((pieces.ph_frame, frame))[order],
        objects=objects,
    )


def _object_blends(pieces: PieceList, c: Corners, machine: Machine, ok, first) -> tuple:
    """The rows (in the new columns) and the :class:`Piece` objects of the accepted blends
    at corners with an arc, NURBS or PH piece (``c.obj_blends``): each capped by its own
    curvature at the faster move's feed (:data:`BLEND_FEED`) and by its fit's cap, and
    belonging to that faster move."""
    corner = c.row
    cap_a, cap_b = pieces.v_cap_mm_s[corner - 1], pieces.v_cap_mm_s[corner]
    obj_rows, obj_pieces = [], []
    for j, bl in c.obj_blends.items():
        if not ok[j]:
            continue
        i = int(corner[j])
        feed_j = float(BLEND_FEED(cap_a[j], cap_b[j]))
        cap = max(
            min(
                float(curvature_cap_mm_s(machine, bl.kappa_max_per_mm, feed_j)),
                float(c.cap_mm_s[j]),
            ),
            MIN_CAP_MM_S,
        )
        of_j = i - 1 if cap_a[j] > cap_b[j] else i  # the faster move's
        if _cells(c, j) > 1:  # a turn-around's U, in cells capped by their own curvature
            u_a, u_b, s_a, length, kappa = turn_cells(bl, _cells(c, j))
            caps = np.maximum(
                np.minimum(
                    curvature_cap_mm_s(machine, kappa, feed_j), servo_cap_mm_s(machine, kappa)
                ),
                MIN_CAP_MM_S,
            )
            obj_rows.extend(range(int(first[i]), int(first[i]) + kappa.size))
            obj_pieces.extend(
                Piece(
                    Kind.NURBS,
                    bl.curve,
                    float(length[n]),
                    float(caps[n]),
                    int(pieces.segment[of_j]),
                    int(pieces.line[of_j]),
                    float(u_a[n]),
                    float(u_b[n]),
                    float(s_a[n]),
                    float(kappa[n]),
                    blend_mm=float(pieces.blend_mm[i]),
                    rapid=bool(pieces.rapid[i]),
                )
                for n in range(kappa.size)
            )
            continue
        obj_rows.append(int(first[i]))
        kind, geom = (Kind.PH, bl.ph) if hasattr(bl, "ph") else (Kind.NURBS, bl.curve)
        obj_pieces.append(
            Piece(
                kind,
                geom,
                float(c.length_mm[j]),
                cap,
                int(pieces.segment[of_j]),
                int(pieces.line[of_j]),
                0.0,
                1.0,
                0.0,
                bl.kappa_max_per_mm,
                blend_mm=float(pieces.blend_mm[i]),
                rapid=bool(pieces.rapid[i]),
            )
        )
    return obj_rows, obj_pieces


def _cells(c: Corners, j: int) -> int:
    """Rows the blend of corner ``j`` takes: a turn-around's U its cells, any other one."""
    return int(c.cells[j]) if c.turn[j] else 1
