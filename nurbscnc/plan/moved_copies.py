"""Moved copies of NURBS segments: a segment that is an earlier one moved is planned from
that one's pieces (:class:`Block`, :class:`Repeats`), not again."""

from __future__ import annotations

from dataclasses import dataclass
from dataclasses import replace as dc_replace

import numpy as np

from nurbscnc.errors import NurbsCncError, SourcePos
from nurbscnc.geometry.nurbs import MovedCopies, NurbsCurve
from nurbscnc.geometry.ph import PHQuintic
from nurbscnc.machine.profile import Machine
from nurbscnc.plan.curved_pieces import blend_override, nurbs_curve, object_pieces
from nurbscnc.plan.options import PlanOptions
from nurbscnc.plan.pieces import COLUMN_DTYPES, SCALAR_COLUMNS, Piece, object_ends


@dataclass(frozen=True, eq=False)
class Block:
    """The pieces of one arc or NURBS segment as the columns of their :class:`PieceList`
    rows: ``scalars`` (name → (n,)), ``ends`` (start, end, unit tangents at both, each
    (n, 3)) and ``objects`` (geometry, u_a, u_b, s_a_mm) a row."""

    scalars: dict
    ends: tuple
    objects: list

    @classmethod
    def of(cls, pieces: list[Piece]) -> Block:
        scalars = {
            name: np.array([getattr(p, name) for p in pieces], dtype=COLUMN_DTYPES.get(name, float))
            for name in SCALAR_COLUMNS
        }
        return cls(
            scalars, object_ends(pieces), [(p.geometry, p.u_a, p.u_b, p.s_a_mm) for p in pieces]
        )

    def moved(
        self, curve: NurbsCurve, old: NurbsCurve, delta_mm: np.ndarray, index: int, line: int
    ) -> Block:
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

        return Block(
            scalars,
            (start + delta_mm, end + delta_mm, t_start, t_end),
            [(geometry(g), ua, ub, sa) for g, ua, ub, sa in self.objects],
        )


class Repeats:
    """The NURBS segments of one program planned so far
    (:func:`~nurbscnc.plan.program_pieces.segment_pieces`), to plan a segment that is one
    of them moved (a part cut again at another place: ten airfoils along X) from that one's
    pieces instead of again (:meth:`Block.moved`): a moved copy
    (:class:`~nurbscnc.geometry.nurbs.MovedCopies`) at the same feed and blend tolerance.
    Smoothed runs (:class:`~nurbscnc.plan.smoothing.SmoothedRun`: the passes of a pocket
    cut again one depth lower fit the same spline moved) are remembered apart from program
    NURBS, and a moved copy's pieces take their source lines from its own run
    (:meth:`~nurbscnc.plan.smoothing.SmoothedRun.line_at`, as
    :func:`~nurbscnc.plan.curved_pieces.object_pieces` gives them). Memory: the blocks,
    which the program's pieces hold anyway."""

    def __init__(self, machine: Machine, options: PlanOptions):
        self.machine, self.options = machine, options
        self.copies = MovedCopies()

    def block(self, seg, index: int) -> Block:
        """The block of NURBS segment ``seg`` (number ``index``)."""
        line_at = getattr(seg, "line_at", None)
        try:
            curve = nurbs_curve(seg, self.machine)
        except NurbsCncError as exc:
            raise exc.with_pos(SourcePos(seg.line)) from None
        same = (
            min(seg.feed_mm_s, self.machine.limits.v_max_mm_s),
            blend_override(seg, self.options),
            line_at is not None,
        )
        hit = self.copies.find(curve, same)
        if hit is not None:
            (old, block), delta = hit
            moved = block.moved(curve, old, delta, index, seg.line)
            if line_at is not None:
                moved.scalars["line"][:] = [line_at(ua) for _, ua, _, _ in moved.objects]
            return moved
        block = Block.of(object_pieces(seg, index, self.machine, self.options, curve))
        self.copies.add(curve, (curve, block), same)
        return block
