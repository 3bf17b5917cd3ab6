"""The interpreter's side of cutter radius compensation: programmed moves into the
compensation stream of :mod:`nurbscnc.program.compensation` (in its plane frame) and the
compensated moves back out as segments (a mixin of the interpreter)."""

from __future__ import annotations

import math

from nurbscnc.errors import ProgramError
from nurbscnc.geometry.segments import PLANE_NORMALS, Arc, Dwell, Line, vec3
from nurbscnc.program import arcs
from nurbscnc.program.compensation import MSG_ARC_AFTER_EXIT, CompMove


class CompStream:
    """Moves through compensation while G41/G42 is on (mixin of the interpreter: it
    provides ``comp``, ``comp_exit``, ``comp_plane``, ``segments``, ``m`` and ``error``)."""

    def to_comp(self, point) -> tuple:
        """A machine point in the frame compensation.py works in (its first two axes are the
        plane): XY as is; for G18 (ZX) the cyclic permutation (x, y, z) → (z, x, y), which
        keeps the handedness, so +Y (the G18 normal) becomes +Z and left stays left."""
        if self.comp_plane == "ZX":
            return (float(point[2]), float(point[0]), float(point[1]))
        return tuple(map(float, point))

    def from_comp(self, point) -> tuple:
        """Inverse of :meth:`to_comp`."""
        if self.comp_plane == "ZX":
            return (float(point[1]), float(point[2]), float(point[0]))
        return tuple(map(float, point))

    def compensate(self, segment) -> None:
        """A programmed Line or Arc (machine mm) into the compensation stream; appends the
        compensated moves that are final so far (the last one is held back for its corner).
        Compensation works in the machine plane (XY, or ZX for G18 through :meth:`to_comp`):
        offsets and the G10 R rotation about Z keep the side of the path, so it is the same
        as compensating in program coordinates (G18 with a rotation is refused)."""
        if isinstance(segment, Arc):
            turns = max(1, math.ceil(abs(segment.angle_rad) / (2.0 * math.pi) - 1e-9))
            centre = self.to_comp(segment.center_mm)
            move = CompMove(
                "arc",
                self.to_comp(segment.end_mm),
                segment.feed_mm_s,
                segment.line,
                (centre[0], centre[1]),
                turns if segment.angle_rad > 0 else -turns,
            )
        else:
            move = CompMove(
                "rapid" if segment.rapid else "feed",
                self.to_comp(segment.end_mm),
                segment.feed_mm_s,
                segment.line,
            )
        self.comp_moves(move)

    def comp_moves(self, move: CompMove) -> None:
        try:
            out = self.comp.move(move)
        except ProgramError as exc:
            raise self.error(exc.message) from None
        self.append_compensated(out)

    def comp_off(self) -> None:
        """G40 (or the program's end): the held-back moves end where they are; the next
        (exit) move starts from the compensated point and must be straight (LinuxCNC)."""
        comp, self.comp = self.comp, None
        if comp is None:
            return
        try:
            out = comp.finish()
        except ProgramError as exc:
            raise self.error(exc.message) from None
        self.append_compensated(out)
        if not comp.first and comp.radius_mm > 0.0:
            self.comp_exit = self.from_comp(comp.position_mm)

    def append_compensated(self, moves) -> None:
        """The compensated moves as segments; the rotary axes stand where they are while
        compensation is on (RotaryAxes.refuse_rotary_in_comp): each carries that."""
        blend_mm = self.m.blend_mm
        abc_hold = self.m.abc_hold
        plane = self.comp_plane
        back = self.from_comp
        for mv in moves:
            if mv.kind == "dwell":
                self.segments.append(Dwell(mv.seconds, back(mv.end_mm), mv.line))
            elif mv.kind == "arc":
                start, end = tuple(mv.start_mm), tuple(mv.end_mm)
                s2, e2 = start[:2], end[:2]
                sweep = arcs.sweep_rad(s2, e2, mv.centre_mm, mv.turn > 0, abs(mv.turn))
                self.segments.append(
                    Arc(
                        start_mm=vec3(back(start)),
                        end_mm=vec3(back(end)),
                        center_mm=vec3(back((*mv.centre_mm, start[2]))),
                        normal=vec3(PLANE_NORMALS[plane]),
                        angle_rad=float(sweep),
                        helix_mm=end[2] - start[2],
                        radius_start_mm=math.dist(s2, mv.centre_mm),
                        radius_end_mm=math.dist(e2, mv.centre_mm),
                        feed_mm_s=mv.feed_mm_s,
                        line=mv.line,
                        plane=plane,
                        blend_mm=blend_mm,
                        abc_deg=abc_hold,
                    )
                )
            elif tuple(mv.start_mm) != tuple(mv.end_mm):
                self.segments.append(
                    Line(
                        back(mv.start_mm),
                        back(mv.end_mm),
                        mv.feed_mm_s,
                        mv.line,
                        mv.kind == "rapid",
                        blend_mm,
                        abc_deg=abc_hold,
                    )
                )

    def emit(self, segment) -> None:
        """Append a Line or Arc (through compensation when it is on; the move just after G40
        starts from the compensated point)."""
        if self.comp is not None:
            self.compensate(segment)
            return
        if self.comp_exit is not None:
            if isinstance(segment, Arc):
                raise self.error(MSG_ARC_AFTER_EXIT)
            segment = Line(
                self.comp_exit,
                segment.end_mm,
                segment.feed_mm_s,
                segment.line,
                segment.rapid,
                segment.blend_mm,
                abc_deg=segment.abc_deg,
            )
            self.comp_exit = None
            if segment.start_mm == segment.end_mm:
                return
        self.segments.append(segment)
