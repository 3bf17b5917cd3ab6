"""Cutter radius compensation (G41/G42/G41.1/G42.1, G40) with LinuxCNC 2.9's behaviour.

Pure and streaming: a :class:`CutterComp` takes the programmed moves of the XY plane one by
one and gives back the compensated moves that are final so far. LinuxCNC's interpreter
(``convert_straight_comp1/comp2``, ``convert_arc_comp1/comp2`` in ``interp_convert.cc`` and its
move queue, ``interp_queue.cc``) is the reference; the rules, in its terms:

* The tool keeps its radius ``r`` to the LEFT (G41) or RIGHT (G42) of the programmed path. A
  negative radius swaps the side (LinuxCNC's rule for tool-table diameters); radius 0 is no
  compensation at all.
* Entry (first move after G41/G42): a line goes from the tool position to the programmed end
  offset by r perpendicular to the entry line (it must be longer than r); an arc keeps its
  programmed end offset along the radius and gets a new centre on the perpendicular bisector.
* Each further move is held back one move: the move before it is only final once the corner
  between them is known. At an outside (convex) corner a corner arc of radius r about the
  programmed corner is inserted (for G0 a rapid to the arc's end instead). At an inside
  (concave) corner the previous move is shortened: its end moves to where the tool touches
  both (line–line: back by r / tan(half the corner); line–arc, arc–line, arc–arc:
  the intersection of the offset paths); a move that would be reversed by that is a gouge.
* Angles within 0.05 rad count as no corner (LinuxCNC's TOLERANCE_CONCAVE_CORNER).
* G40 (:meth:`CutterComp.finish`) ends the held-back move where it is; the next (exit) move
  starts from the compensated point and must be a straight move (the caller checks that, as
  LinuxCNC's "The move just after exiting cutter compensation mode must be straight, not an
  arc").

Moves in and out are :class:`CompMove`: kind 'rapid', 'feed', 'arc' or 'dwell'; positions
(x, y, z) in mm; arcs carry their centre (x, y) and LinuxCNC's signed turn count (+n:
counter-clockwise with n - 1 extra full turns, -n clockwise). Errors are ProgramError with
LinuxCNC's messages; the caller adds line and column.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from nurbscnc.errors import ProgramError

#: LinuxCNC's TOLERANCE_CONCAVE_CORNER [rad]: corners flatter than this are no corner.
CORNER_TOL_RAD = 0.05
#: LinuxCNC's TOLERANCE_EQUAL (on a cosine).
_EQUAL_TOL = 0.0001

MSG_ENTRY_SHORT = "Length of cutter compensation entry move is not greater than the tool radius"
MSG_ENTRY_ARC = "Radius of cutter compensation entry arc is not greater than the tool radius"
MSG_TOOL_TOO_BIG = "Tool radius not less than arc radius with comp"
MSG_ZERO_CORNER = "Zero degree inside corner is invalid for cutter compensation"
MSG_ARC_LINE_GOUGE = (
    "Arc to straight motion makes a corner the compensated tool can't fit in without gouging"
)
MSG_ARC_GOUGE = "Arc move in concave corner cannot be reached by the tool without gouging"
MSG_ARC_ARC_GOUGE = (
    "Arc to arc motion makes a corner the compensated tool can't fit in without gouging"
)
MSG_SAME_CENTRE = "Arc to arc motion is invalid because the arcs have the same center"
MSG_FEED_GOUGE = "Straight feed in concave corner cannot be reached by the tool without gouging"
MSG_RAPID_GOUGE = (
    "Straight traverse in concave corner cannot be reached by the tool without gouging"
)
#: The caller's check after G40 (LinuxCNC's arc_not_allowed).
MSG_ARC_AFTER_EXIT = (
    "The move just after exiting cutter compensation mode must be straight, not an arc"
)


@dataclass(frozen=True)
class CompMove:
    """A move in the XY plane with its Z: programmed (input) or compensated (output).

    ``kind``: 'rapid', 'feed', 'arc' or 'dwell'. ``end_mm``: (x, y, z) [mm]. ``start_mm``:
    where the move starts [mm] (output moves; ignored on input: the programmed path is
    continuous). ``centre_mm``: arc centre (x, y) [mm]. ``turn``: arc turns as LinuxCNC's
    ARC_FEED (+n CCW, -n CW). ``feed_mm_s`` [mm/s]; ``seconds``: dwell time [s]; ``line``:
    source line.
    """

    kind: str
    end_mm: tuple
    feed_mm_s: float = 0.0
    line: int = 0
    centre_mm: tuple | None = None
    turn: int = 0
    seconds: float = 0.0
    start_mm: tuple | None = None


def _find_turn(x1, y1, cx, cy, turn, x2, y2) -> float:
    """Signed angle [rad] an arc of ``turn`` turns sweeps from (x1, y1) to (x2, y2) about (cx,
    cy): LinuxCNC's find_turn (CCW positive; a full turn when the end equals the start)."""
    if turn == 0:
        return 0.0
    alpha = math.atan2(y1 - cy, x1 - cx)
    beta = math.atan2(y2 - cy, x2 - cx)
    if turn > 0:
        if beta <= alpha:
            beta += 2 * math.pi
        return beta - alpha + (turn - 1) * 2 * math.pi
    if alpha <= beta:
        alpha += 2 * math.pi
    return beta - alpha + (turn + 1) * 2 * math.pi


@dataclass
class _Queued:
    """A held-back output move: its end (x, y, z), and for lines the programmed direction."""

    move: CompMove
    direction: tuple = (0.0, 0.0)
    original_turns: float = 0.0


class CutterComp:
    """Cutter radius compensation of one G41/G42 ... G40 stretch (XY plane).

    ``side``: 'left' (G41, G41.1) or 'right' (G42, G42.1); ``radius_mm``: the tool radius [mm]
    (D / 2 for G41.1/G42.1, the tool table's diameter / 2 for G41/G42); ``position_mm``: the
    tool position (x, y, z) when compensation starts [mm]; ``inch``: whether the program is in
    inches (LinuxCNC's tolerance on an arc's turn when its end is moved is 0.001 in inch
    programs and 0.0254 in mm programs — compared with an angle in radians, as it does).
    """

    def __init__(self, side: str, radius_mm: float, position_mm: tuple, inch: bool = False):
        if side not in ("left", "right"):
            raise ValueError(f"side must be 'left' or 'right', not {side!r}")
        if radius_mm < 0.0:
            side, radius_mm = ("right" if side == "left" else "left"), -radius_mm
        self.left = side == "left"
        self.radius_mm = radius_mm
        self.current = tuple(float(v) for v in position_mm)  # the tool (compensated)
        self.programmed = self.current  # the programmed point
        self.emitted = self.current  # where the last output move ended
        self.first = True
        self.queue: list[_Queued] = []
        self.endpoint = None  # start of the queued moves (LinuxCNC's endpoint), if valid
        self.turn_tol = 0.001 if inch else 0.0254

    # -- public ----------------------------------------------------------------------------
    @property
    def position_mm(self) -> tuple:
        """The compensated tool position after the moves given so far [mm]."""
        return self.current

    def move(self, m: CompMove) -> list[CompMove]:
        """Compensate one programmed move; the output moves that are now final."""
        out: list[CompMove] = []
        if m.kind == "dwell":
            if self.radius_mm == 0.0:
                return [replace(m, end_mm=self.current, start_mm=self.current)]
            self.queue.append(_Queued(replace(m, end_mm=self.current)))
            return out
        if self.radius_mm == 0.0:  # LinuxCNC compensates only a positive radius
            start = self.current
            self.current = self.programmed = tuple(m.end_mm)
            self.emitted = self.current
            return [replace(m, start_mm=start)]
        if m.kind in ("rapid", "feed"):
            (self._line1 if self.first else self._line2)(m, out)
        elif m.kind == "arc":
            (self._arc1 if self.first else self._arc2)(m, out)
        else:
            raise ValueError(f"unknown move kind {m.kind!r}")
        return out

    def finish(self) -> list[CompMove]:
        """G40: the held-back moves, ended where they are. Then continue from
        :attr:`position_mm`, the compensated point (the exit move starts there)."""
        out: list[CompMove] = []
        if not self.first and self.radius_mm > 0.0:
            self._move_endpoint_and_flush(self.current[0], self.current[1], out)
        self._dequeue(out)
        return out

    # -- LinuxCNC's queue ------------------------------------------------------------------
    def _dequeue(self, out: list) -> None:
        for q in self.queue:
            m = q.move
            if m.kind == "dwell":
                out.append(replace(m, end_mm=self.emitted, start_mm=self.emitted))
                continue
            out.append(replace(m, start_mm=self.emitted))
            self.emitted = m.end_mm
        self.queue.clear()
        self.endpoint = None

    def _enqueue(self, m: CompMove, direction=(0.0, 0.0), original_turns=0.0) -> None:
        self.queue.append(_Queued(m, direction, original_turns))

    def _move_endpoint_and_flush(self, x: float, y: float, out: list) -> None:
        """Move the XY end of every queued move to (x, y), checking that no line reverses
        and no arc grows (a gouge), then output them."""
        for q in self.queue:
            m = q.move
            if m.kind == "arc":
                cx, cy = m.centre_mm
                if self.endpoint is not None and q.original_turns != 0.0:
                    l2 = _find_turn(self.endpoint[0], self.endpoint[1], cx, cy, m.turn, x, y)
                    if abs(l2) > abs(q.original_turns) + self.turn_tol:
                        raise ProgramError(MSG_ARC_GOUGE)
            elif m.kind in ("rapid", "feed"):
                if self.endpoint is not None:
                    dot = q.direction[0] * (x - self.endpoint[0]) + q.direction[1] * (
                        y - self.endpoint[1]
                    )
                    if dot < 0.0:
                        raise ProgramError(MSG_RAPID_GOUGE if m.kind == "rapid" else MSG_FEED_GOUGE)
            else:
                continue
            q.move = replace(m, end_mm=(x, y, m.end_mm[2]))
        self._dequeue(out)
        self.endpoint = (x, y)

    def _front_arc(self) -> CompMove | None:
        return self.queue[0].move if self.queue and self.queue[0].move.kind == "arc" else None

    def _inside(self, turn: int) -> bool:
        """LinuxCNC's TOOL_INSIDE_ARC: the tool is on the centre's side of the arc."""
        return (self.left and turn > 0) or (not self.left and turn < 0)

    # -- straight moves ----------------------------------------------------------------------
    def _line1(self, m: CompMove, out: list) -> None:
        """Entry line (convert_straight_comp1)."""
        r = self.radius_mm
        cx, cy, _ = self.current
        px, py, pz = m.end_mm
        if math.hypot(px - cx, py - cy) <= r:
            raise ProgramError(MSG_ENTRY_SHORT)
        alpha = math.atan2(py - cy, px - cx) + (math.pi / 2 if self.left else -math.pi / 2)
        end = (px + r * math.cos(alpha), py + r * math.sin(alpha), pz)
        self.endpoint = (cx, cy)
        self._enqueue(replace(m, end_mm=end), (math.cos(alpha), math.sin(alpha)))
        self.first = False
        self.current, self.programmed = end, (px, py, pz)

    def _line2(self, m: CompMove, out: list) -> None:
        """A straight move after the entry (convert_straight_comp2): the corner it makes with
        the move before is convex (go round it), concave (back off the move before) or none."""
        r, small = self.radius_mm, CORNER_TOL_RAD
        cx, cy, cz = self.current
        opx, opy, _ = self.programmed
        px, py, pz = m.end_mm
        if px == opx and py == opy:  # no XY motion: the tool stays where it is
            self._enqueue(replace(m, end_mm=(cx, cy, pz)))
            self.current, self.programmed = (cx, cy, pz), (px, py, pz)
            return
        theta, alpha, beta, gamma = self._line_angles(px, py)
        end = (px + r * math.cos(alpha + gamma), py + r * math.sin(alpha + gamma), pz)
        mid = (opx + r * math.cos(alpha + gamma), opy + r * math.sin(alpha + gamma))
        front = self._front_arc()
        concave = self._line_corner_concave(beta, front)
        if not concave and beta > small:
            self._convex_to_line(m, mid, out)
        elif concave:
            if front is None:
                self._concave_line_to_line(beta, theta, gamma, out)
            else:
                self._concave_arc_to_line(front, px, py, out)
        else:  # no corner (collinear, or tangent arc -> line)
            self._dequeue(out)
            self.endpoint = (cx, cy)
        self._enqueue(replace(m, end_mm=end), (px - opx, py - opy))
        self.current, self.programmed = end, (px, py, pz)

    def _line_angles(self, px: float, py: float) -> tuple:
        """LinuxCNC's angles of a line to (px, py) after the programmed point [rad]: theta
        the direction from it to the tool, alpha the line's direction, beta the turn of the
        corner (0: straight on), gamma the side (+π/2 left, −π/2 right)."""
        cx, cy, _ = self.current
        opx, opy, _ = self.programmed
        theta = math.atan2(cy - opy, cx - opx)
        alpha = math.atan2(py - opy, px - opx)
        if self.left:
            if theta < alpha:
                theta += 2 * math.pi
            beta = theta - alpha - math.pi / 2
            gamma = math.pi / 2
        else:
            if alpha < theta:
                alpha += 2 * math.pi
            beta = alpha - theta - math.pi / 2
            gamma = -math.pi / 2
        return theta, alpha, beta, gamma

    def _line_corner_concave(self, beta: float, front: CompMove | None) -> bool:
        """Whether the corner before a line of turn ``beta`` is concave."""
        small = CORNER_TOL_RAD
        if beta < -small or beta > math.pi + small:
            return True
        # LinuxCNC's "h" shape: stay above and to the side
        return (
            beta > math.pi - small
            and front is not None
            and ((not self.left and front.turn > 0) or (self.left and front.turn < 0))
        )

    def _convex_to_line(self, m: CompMove, mid: tuple, out: list) -> None:
        """A convex corner before a line: the move before ends at the tool, then a corner
        arc about the programmed corner to ``mid`` (for a rapid: a rapid to it)."""
        cx, cy, cz = self.current
        opx, opy, _ = self.programmed
        self._move_endpoint_and_flush(cx, cy, out)
        if m.kind == "feed":
            corner = CompMove(
                "arc", (mid[0], mid[1], cz), m.feed_mm_s, m.line, (opx, opy), -1 if self.left else 1
            )
        else:  # no arc traverse: a rapid to the corner arc's end
            corner = CompMove("rapid", (mid[0], mid[1], cz), 0.0, m.line)
        self._enqueue(corner)
        self._dequeue(out)
        self.endpoint = mid

    def _concave_line_to_line(self, beta: float, theta: float, gamma: float, out: list) -> None:
        """Line -> line, concave: the line before backs off by r / tan(half the corner)."""
        cx, cy, _ = self.current
        halfcorner = (beta + math.pi) / 2.0
        if halfcorner == 0.0:
            raise ProgramError(MSG_ZERO_CORNER)
        retreat = self.radius_mm / math.tan(halfcorner)
        back_x = cx + retreat * math.cos(theta + gamma)
        back_y = cy + retreat * math.sin(theta + gamma)
        self._move_endpoint_and_flush(back_x, back_y, out)

    def _concave_arc_to_line(self, front: CompMove, px: float, py: float, out: list) -> None:
        """Arc -> line, concave: the arc before ends where the offset arc meets the offset
        line."""
        r = self.radius_mm
        opx, opy, _ = self.programmed
        pcx, pcy = front.centre_mm
        oldrad = math.hypot(pcy - front.end_mm[1], pcx - front.end_mm[0])
        base = math.atan2(py - opy, px - opx)
        th = base + math.pi / 2 if front.turn > 0 else base - math.pi / 2
        phi = math.atan2(pcy - opy, pcx - opx)
        inside = self._inside(front.turn)
        oldrad_uncomp = oldrad + r if inside else oldrad - r
        d = oldrad_uncomp * math.cos(th - phi)
        ratio = (d - r if inside else d + r) / oldrad
        if ratio > 1.0 or ratio < -1.0:
            raise ProgramError(MSG_ARC_LINE_GOUGE)
        sign = (-1 if front.turn > 0 else 1) * (1 if inside else -1)
        ang = sign * math.acos(ratio) + th + math.pi
        self._move_endpoint_and_flush(
            pcx + oldrad * math.cos(ang), pcy + oldrad * math.sin(ang), out
        )

    # -- arcs ------------------------------------------------------------------------------
    def _arc1(self, m: CompMove, out: list) -> None:
        """Entry arc (convert_arc_comp1): the programmed centre, the end offset along the
        radius, and a new centre on the bisector of the compensated chord."""
        r = self.radius_mm
        cx, cy, _ = self.current
        ex, ey, ez = m.end_mm
        ccx, ccy = m.centre_mm
        if math.hypot(ex - cx, ey - cy) <= r:
            raise ProgramError(MSG_ENTRY_ARC)
        if self._inside(m.turn):
            gamma = math.atan2(ccy - ey, ccx - ex)
        else:
            gamma = math.atan2(ey - ccy, ex - ccx)
        self.first = False
        self.programmed = (ex, ey, ez)
        ex, ey = ex + r * math.cos(gamma), ey + r * math.sin(gamma)
        b_len = math.hypot(cy - ey, cx - ex) / 2.0
        ab_ang = math.atan2(ccy - ey, ccx - ex)
        a_ang = math.atan2(cy - ey, cx - ex) - ab_ang
        if abs(math.cos(a_ang)) < _EQUAL_TOL:
            raise ProgramError(MSG_TOOL_TOO_BIG)
        c_len = b_len / math.cos(a_ang)
        centre = (ex + c_len * math.cos(ab_ang), ey + c_len * math.sin(ab_ang))
        end = (ex, ey, ez)
        self._enqueue(
            replace(m, end_mm=end, centre_mm=centre),
            (0.0, 0.0),
            _find_turn(cx, cy, centre[0], centre[1], m.turn, ex, ey),
        )
        self.current = end

    def _arc2(self, m: CompMove, out: list) -> None:
        """An arc after the entry (convert_arc_comp2): the corner it makes with the move
        before is concave (back off the move before), convex (a corner arc) or tangent."""
        r, small = self.radius_mm, CORNER_TOL_RAD
        opx, opy, _ = self.programmed
        cx, cy, cz = self.current
        ex, ey, ez = m.end_mm
        ccx, ccy = m.centre_mm
        turn = m.turn
        arc_radius = math.hypot(ccx - ex, ccy - ey)
        theta, delta, beta = self._arc_angles(ccx, ccy, turn)
        inside = self._inside(turn)
        if inside:
            gamma = math.atan2(ccy - ey, ccx - ex)
            if arc_radius <= r:
                raise ProgramError(MSG_TOOL_TOO_BIG)
        else:
            gamma = math.atan2(ey - ccy, ex - ccx)
            delta += math.pi
        new_end = (ex + r * math.cos(gamma), ey + r * math.sin(gamma), ez)
        main_turns = _find_turn(opx, opy, ccx, ccy, turn, ex, ey)
        main = replace(m, end_mm=new_end)
        if beta < -small or beta > math.pi + small or (abs(beta - math.pi) < small and not inside):
            front = self._front_arc()
            if front is None:
                self._concave_line_to_arc(m, theta, beta, arc_radius, inside, out)
            else:
                self._concave_arc_to_arc(m, front, arc_radius, inside, out)
            self._enqueue(main, (0.0, 0.0), main_turns)
        elif beta > small:  # convex: a corner arc, then the arc
            mid = (opx + r * math.cos(delta), opy + r * math.sin(delta))
            self._dequeue(out)
            self._enqueue(
                CompMove(
                    "arc",
                    (mid[0], mid[1], cz),
                    m.feed_mm_s,
                    m.line,
                    (opx, opy),
                    -1 if self.left else 1,
                )
            )
            self._dequeue(out)
            self.endpoint = mid
            self._enqueue(main, (0.0, 0.0), main_turns)
        else:  # tangent: just the arc
            self._dequeue(out)
            self.endpoint = (cx, cy)
            self._enqueue(main, (0.0, 0.0), main_turns)
        self.programmed = (ex, ey, ez)
        self.current = new_end

    def _arc_angles(self, ccx: float, ccy: float, turn: int) -> tuple:
        """LinuxCNC's angles of an arc about (ccx, ccy) after the programmed point [rad]:
        theta the tool's normal direction there, delta the direction to the centre, beta
        the turn of the corner, in (−π/2, 3π/2]."""
        opx, opy, _ = self.programmed
        cx, cy, _ = self.current
        theta = math.atan2(cy - opy, cx - opx)
        theta = theta - math.pi / 2 if self.left else theta + math.pi / 2
        delta = math.atan2(ccy - opy, ccx - opx)
        alpha = delta - math.pi / 2 if turn > 0 else delta + math.pi / 2
        beta = theta - alpha if self.left else alpha - theta
        if beta > 1.5 * math.pi:
            beta -= 2 * math.pi
        elif beta < -math.pi / 2:
            beta += 2 * math.pi
        return theta, delta, beta

    def _concave_line_to_arc(
        self, m: CompMove, theta: float, beta: float, arc_radius: float, inside: bool, out: list
    ) -> None:
        """Line -> arc, concave: the line before ends where it meets the offset arc."""
        r = self.radius_mm
        ccx, ccy = m.centre_mm
        turn = m.turn
        offset = arc_radius * math.sin(beta - math.pi / 2)
        if inside:
            dist = arc_radius - r
            ratio = (offset + r) / dist
            if ratio > 1.0 or ratio < -1.0:
                raise ProgramError(MSG_ARC_GOUGE)
            ang = theta + math.asin(ratio) if turn > 0 else theta - math.asin(ratio)
        else:
            dist = arc_radius + r
            ratio = (offset - r) / dist
            if ratio > 1.0 or ratio < -1.0:
                raise ProgramError(MSG_ARC_GOUGE)
            ang = (
                theta + math.pi - math.asin(ratio)
                if turn > 0
                else theta + math.pi + math.asin(ratio)
            )
        self._move_endpoint_and_flush(ccx + dist * math.cos(ang), ccy + dist * math.sin(ang), out)

    def _concave_arc_to_arc(
        self, m: CompMove, front: CompMove, arc_radius: float, inside: bool, out: list
    ) -> None:
        """Arc -> arc, concave: the arc before ends where the two offset arcs meet."""
        r = self.radius_mm
        ccx, ccy = m.centre_mm
        turn = m.turn
        pcx, pcy = front.centre_mm
        oldrad = math.hypot(pcy - front.end_mm[1], pcx - front.end_mm[0])
        newrad = arc_radius - r if inside else arc_radius + r
        arc_cc = math.hypot(pcy - ccy, pcx - ccx)
        if oldrad == 0 or arc_cc == 0:
            raise ProgramError(MSG_SAME_CENTRE)
        a = (oldrad**2 + arc_cc**2 - newrad**2) / (2 * oldrad * arc_cc)
        if a > 1.0 or a < -1.0:
            raise ProgramError(MSG_ARC_ARC_GOUGE)
        pullback = math.acos(a)
        cc_dir = math.atan2(ccy - pcy, ccx - pcx)
        if self._inside(front.turn):
            direction = cc_dir + pullback if turn > 0 else cc_dir - pullback
        else:
            direction = cc_dir - pullback if turn > 0 else cc_dir + pullback
        self._move_endpoint_and_flush(
            pcx + oldrad * math.cos(direction), pcy + oldrad * math.sin(direction), out
        )
