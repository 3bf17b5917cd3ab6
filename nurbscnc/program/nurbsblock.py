"""NURBS blocks: LinuxCNC's G5.2 … G5.3 and G6.2, and G5 / G5.1 splines as NURBS.

A mixin of the interpreter (it uses its error, position, feed and plane). G5 (cubic) and
G5.1 (quadratic) are Bezier curves, which are NURBS with all weights 1 and the clamped knot
vector [0…0, 1…1] (degree + 1 of each): the conversion is exact.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from nurbscnc.geometry.segments import PLANE_AXES, Nurbs, frozen_array
from nurbscnc.program.codes import G_5, G_5_2, G_5_3, G_6_2, G_40, G_93

_AXES = ("X", "Y", "Z")
_NORMAL_AXIS = {"XY": 2, "ZX": 1, "YZ": 0}
_FIRST_POINT_TOL_MM = 1e-6
# NURBS weights beyond this range (either way) make the curve's rational arithmetic overflow
# or lose all precision (1e308 gives NaN in a solver); LinuxCNC's examples stay within 1e3.
MAX_WEIGHT = 1e9


def _check_weight(interp, letter: str, w: float, col: int) -> None:
    if not 1.0 / MAX_WEIGHT <= w <= MAX_WEIGHT:
        raise interp.error(
            f"NURBS weight {letter}{w:.6g} is out of range ({1 / MAX_WEIGHT:g} to {MAX_WEIGHT:g})",
            col,
        )


@dataclass
class _NurbsBuild:
    """A NURBS block being collected line by line (G5.2 ... G5.3, or G6.2 ...)."""

    kind: str  # "G5.2" or "G6.2"
    line: int
    plane: str
    feed_mm_s: float
    order: int = 3
    points: list = field(default_factory=list)
    weights: list = field(default_factory=list)
    knots: list = field(default_factory=list)
    knot_lines: list = field(default_factory=list)
    point_lines: list = field(default_factory=list)
    knot_only: int = 0


class NurbsBlocks:
    """G5.2 / G6.2 collection and validation (mixin of the interpreter)."""

    # -- NURBS: LinuxCNC G5.2 ... G5.3 --------------------------------------------------------
    def nurbs_code(self) -> int:
        return G_5_2 if self.nurbs.kind == "G5.2" else G_6_2

    def finish_nurbs_by_other(self, code, column) -> None:
        build = self.nurbs
        if build.kind == "G5.2":
            if code == G_5_3:
                return
            raise self.error(
                f"G5.2 NURBS block (line {build.line}) not closed by G5.3 before this block",
                column,
            )
        raise self.error(
            f"G6.2 NURBS block (line {build.line}) has {len(build.knots)} knots; knot count "
            f"must equal control points + order "
            f"({len(build.points)} + {build.order} = {len(build.points) + build.order})",
            column,
        )

    def plane_point(self, words: dict, base: list, first_line: bool) -> list | None:
        """A G5.2 control point: both in-plane axes required (LinuxCNC rule)."""
        a, b = PLANE_AXES[self.plane]
        la, lb = _AXES[a], _AXES[b]
        has_a, has_b = la in words, lb in words
        if has_a != has_b:
            col = words[la if has_a else lb][1]
            raise self.error(f"G5.2 control points need both {la} and {lb}", col)
        normal_letter = _AXES[_NORMAL_AXIS[self.plane]]
        if normal_letter in words:
            raise self.error(
                f"{normal_letter} word in a G5.2 block in the {self.plane} plane "
                f"(NURBS are planar)",
                words[normal_letter][1],
            )
        if not has_a:
            return None
        return self.target({la: words[la], lb: words[lb]}, base=base)

    def g5(self, words: dict, used: set, motion_code) -> None:
        used.update("PL")
        if self.nurbs is None or self.nurbs.kind != "G5.2":
            if self.feed_mm_s <= 0.0:
                col = motion_code[1] if motion_code else 1
                raise self.error("cannot make a NURBS with zero feed (set F first)", col)
            self.nurbs = _NurbsBuild("G5.2", self.line_no, self.plane, self.feed_mm_s)
            build = self.nurbs
            point = self.plane_point(words, self.pos, True)
            w0 = 1.0
            if point is None and "P" in words:
                w0 = words["P"][0]
            build.points.append(list(self.pos))
            build.weights.append(w0)
            build.point_lines.append(self.line_no)
            self._g5_order(words)
            if point is not None:
                self._g5_add(words, point)
            return
        build = self.nurbs
        self._g5_order(words)
        # In G91 each point is an increment from the block's start, not from the previous
        # point: LinuxCNC's current point stays there until G5.3 (find_ends).
        point = self.plane_point(words, build.points[0], False)
        if point is None:
            if "P" in words:
                raise self.error(
                    "P without X and Y is allowed only on the first line of G5.2",
                    words["P"][1],
                )
            return
        self._g5_add(words, point)

    def _g5_order(self, words: dict) -> None:
        """An L word on any line of a G5.2 block, as LinuxCNC's convert_nurbs: the order
        becomes L when L > 3 (at most 8 here), and stays 3 otherwise (L0…L3, with a note)."""
        if "L" not in words:
            return
        order_f, lcol = words["L"]
        if order_f != int(order_f) or not 0 <= order_f <= 8:
            raise self.error(f"NURBS order L{order_f:g} must be an integer up to 8", lcol)
        if order_f > 3:
            self.nurbs.order = int(order_f)
        elif order_f < 3:
            self.note_once(
                ("L", self.line_no),
                f"G5.2 L{int(order_f)}: LinuxCNC uses order 3 unless L > 3; order 3 used",
            )

    def _g5_add(self, words: dict, point: list) -> None:
        if "P" not in words:
            a, b = PLANE_AXES[self.plane]
            raise self.error(
                "every G5.2 control point needs a positive weight P",
                words[_AXES[a]][1],
            )
        w, col = words["P"]
        if not w > 0.0:
            raise self.error(f"NURBS weight P{w:g} must be > 0", col)
        _check_weight(self, "P", w, col)
        self.nurbs.points.append(point)
        self.nurbs.weights.append(w)
        self.nurbs.point_lines.append(self.line_no)

    def g5_end(self, column: int) -> None:
        build = self.nurbs
        if build is None or build.kind != "G5.2":
            raise self.error("G5.3 without G5.2 first", column)
        n = len(build.points)
        if n < build.order:
            raise self.error(
                f"G5.2 block has {n} control points; at least the order "
                f"L = {build.order} are needed",
                column,
            )
        knots = g5_knot_vector(n, build.order)
        if self.feed_mm_s > 0.0:  # LinuxCNC feeds the curve at the F in force at G5.3
            build.feed_mm_s = self.feed_mm_s
        self.emit_nurbs(build, knots, column)
        self.motion = None  # LinuxCNC: motion mode is cleared by G5.3

    # -- NURBS: G6.2 (Fanuc-style, LinuxCNC G6.2) --------------------------------------------
    def g6(self, words: dict, used: set, motion_code) -> None:
        used.update("KRPQ")
        build = self.nurbs
        has_axes = any(a in words for a in _AXES)
        if build is None:
            if "P" not in words:
                col = motion_code[1] if motion_code else 1
                raise self.error("G6.2 needs P<order> on its first line", col)
            order_f, pcol = words["P"]
            if order_f != int(order_f) or not 2 <= order_f <= 8:
                raise self.error(f"NURBS order P{order_f:g} must be an integer in 2..8", pcol)
            if self.feed_mm_s <= 0.0:
                raise self.error("cannot make a NURBS with zero feed (set F first)", pcol)
            if "Q" in words:
                self.note_once(("Q",), "G6.2 Q (approximation mode) is accepted and ignored")
            self.nurbs = build = _NurbsBuild(
                "G6.2", self.line_no, self.plane, self.feed_mm_s, order=int(order_f)
            )
            first = self.target(words) if has_axes else list(self.pos)
            dist = math.dist(first, self.pos)
            if dist > _FIRST_POINT_TOL_MM:
                raise self.error(
                    "the first G6.2 control point must be the current position "
                    f"({_fmt_point(self.pos)}); it is {dist:.6g} mm away",
                    min((c for _, c in words.values()), default=1),
                )
            self._g6_point(words, list(self.pos))
            return
        if "P" in words:
            raise self.error(
                "P (order) on a G6.2 line inside a NURBS block: the previous block "
                f"(line {build.line}) is not complete",
                words["P"][1],
            )
        if "Q" in words:
            self.note_once(("Q",), "G6.2 Q (approximation mode) is accepted and ignored")
        if has_axes or "R" in words:
            if build.knot_only:
                raise self.error(
                    "control point after knot-only K lines in a G6.2 block",
                    min(c for _, c in words.values()),
                )
            self._g6_point(words, self.target(words, base=build.points[-1]))
            return
        if "K" in words:
            self._g6_knot(words["K"])
            build.knot_only += 1
            if build.knot_only == build.order:
                self.emit_nurbs(build, build.knots, 1)
                self.motion = None
            return
        # A line with only F or nothing motion-related inside the block: nothing to do.

    def _g6_point(self, words: dict, point: list) -> None:
        build = self.nurbs
        if "K" not in words:
            col = min((c for _, c in words.values()), default=1)
            raise self.error("G6.2 control point without its knot K", col)
        if "R" in words:
            w, col = words["R"]
            if not w > 0.0:
                raise self.error(f"NURBS weight R{w:g} must be > 0", col)
            _check_weight(self, "R", w, col)
        else:
            w = 1.0
        self._g6_knot(words["K"])
        build.points.append(point)
        build.weights.append(w)
        build.point_lines.append(self.line_no)

    def _g6_knot(self, kw) -> None:
        build = self.nurbs
        k, col = kw
        if build.knots and k < build.knots[-1]:
            raise self.error(
                f"knots must be non-decreasing: K{k:g} after K{build.knots[-1]:g}", col
            )
        build.knots.append(k)
        build.knot_lines.append(self.line_no)

    # -- common NURBS validation and output ---------------------------------------------------
    def emit_nurbs(self, build: _NurbsBuild, knots, column: int) -> None:
        n = len(build.points)
        order = build.order
        p = order - 1
        start_line = build.line
        here = self.line_no
        self.line_no = start_line
        try:
            if not 2 <= order <= 8:
                raise self.error(f"NURBS order {order} must be in 2..8")
            if order > n:
                raise self.error(f"NURBS order {order} exceeds the number of control points ({n})")
            k = np.asarray(knots, dtype=float)
            if k.size != n + order:
                raise self.error(
                    f"knot count {k.size} must equal control points + order ({n} + {order})"
                )
            if not np.all(np.isfinite(k)):
                raise self.error("knots must be finite")
            if np.any(np.diff(k) < 0):
                raise self.error("knots must be non-decreasing")
            if np.any(k[:order] != k[0]) or np.any(k[-order:] != k[-1]):
                raise self.error(
                    f"knot vector must be clamped: the first and last {order} knots equal"
                )
            if k[0] == k[-1]:
                raise self.error("all knots are equal")
            span = float(k[-1] - k[0])
            if not KNOT_SPAN_MIN <= span <= KNOT_SPAN_MAX or max(-k[0], k[-1]) > KNOT_SPAN_MAX:
                # The curve's derivatives scale as 1/span^p: K0 … K3e-300 overflows them
                # (the fuzzer). Knots set only the parametrization: any scale draws the same
                # curve, and 1e-12 … 1e12 plans alike to the last digit.
                raise self.error(
                    f"knots from {k[0]:g} to {k[-1]:g}: their span must lie in "
                    f"{KNOT_SPAN_MIN:g} … {KNOT_SPAN_MAX:g} and no knot beyond ±{KNOT_SPAN_MAX:g} "
                    "(scaling all knots draws the same curve)"
                )
            interior = k[order:-order]
            if interior.size and (interior[0] == k[0] or interior[-1] == k[-1]):
                # An end knot repeated more than the order: the first (last) control points
                # get no weight and the curve does not start (end) at them.
                end = "first" if interior[0] == k[0] else "last"
                times = int(np.count_nonzero(k == (k[0] if end == "first" else k[-1])))
                raise self.error(
                    f"the {end} knot is repeated {times} times; a clamped knot vector repeats "
                    f"it exactly the order ({order}) times"
                )
            if interior.size:
                _, counts = np.unique(interior, return_counts=True)
                if counts.max() > p:
                    raise self.error(
                        f"an interior knot is repeated {counts.max()} times; "
                        f"at most the degree ({p}) is allowed"
                    )
            w = np.asarray(build.weights, dtype=float)
            if not np.all(np.isfinite(w)) or np.any(w <= 0):
                raise self.error("NURBS weights must be finite and > 0")
            if build.feed_mm_s <= 0.0:
                raise self.error("NURBS block with zero feed")
        finally:
            self.line_no = here
        seg = Nurbs(
            degree=p,
            knots=frozen_array(k),
            control_points_mm=frozen_array(build.points),
            weights=frozen_array(w),
            feed_mm_s=build.feed_mm_s,
            line=start_line,
            plane=build.plane,
            blend_mm=self.blend_mm,
        )
        self.segments.append(seg)
        self.pos = list(build.points[-1])
        self.nurbs = None


#: The knot span (last − first) a NURBS block may have, and the largest |knot| (G6.2 K).
KNOT_SPAN_MIN = 1e-12
KNOT_SPAN_MAX = 1e12


def g5_knot_vector(n_points: int, order: int) -> list[float]:
    """LinuxCNC's implied G5.2 knots (``nurbs_G5_knot_vector_creator``).

    With n = n_points − 1 and k = order: knot i (0 ≤ i ≤ n + k) is 0 for i < k, i − k + 1 for
    k ≤ i ≤ n and n − k + 2 beyond: clamped, uniform, integer-valued.
    """
    n, k = n_points - 1, order
    return [
        0.0 if i < k else float(i - k + 1) if i <= n else float(n - k + 2) for i in range(n + k + 1)
    ]


def _fmt_point(p) -> str:
    return ", ".join(f"{v:.6g}" for v in p)


def bezier_nurbs_knots(degree: int) -> list[float]:
    """The knot vector that makes a NURBS of ``degree`` with degree + 1 control points and unit
    weights the Bezier curve of those points: [0]*(degree + 1) + [1]*(degree + 1)."""
    return [0.0] * (degree + 1) + [1.0] * (degree + 1)


class Splines:
    """G5 (cubic) and G5.1 (quadratic) splines as exact NURBS (mixin of the interpreter)."""

    def spline(self, words: dict, used: set, motion: int, motion_code=None) -> None:
        """G5 X Y I J P Q: cubic Bezier from the current point to X Y; the first control point
        is the start + (I, J), the second the end + (P, Q). I, J may be omitted: they are then
        −(P, Q) of the last G5, other moves between or not, or (0, 0) before any (LinuxCNC).
        G5.1 X Y I J: quadratic, the control point start + (I, J). I J P Q are incremental in
        any distance mode; only the XY plane (LinuxCNC). Neither changes the motion mode."""
        name = "G5" if motion == G_5 else "G5.1"
        col0 = motion_code[1] if motion_code else min((c for _, c in words.values()), default=1)
        if self.m.plane != "XY":
            raise self.error(f"{name} splines are only allowed in the XY plane (G17)", col0)
        if "Z" in words:
            raise self.error(f"Z word with {name} (splines are planar)", words["Z"][1])
        if self.m.comp_mode != G_40:
            raise self.error(f"{name} with cutter radius compensation on", col0)
        if self.m.feed_mode == G_93:
            raise self.error(f"{name} in inverse time feed mode (G93) is not supported", col0)
        feed = self.feed_mm_s
        if feed <= 0.0:
            raise self.error(f"{name} spline with zero feed (set F first)", col0)
        scale = self.m.scale
        start = list(self.prog)
        end = self.target_program(words)
        used.update("IJPQ")
        if motion == G_5:
            if "P" not in words or "Q" not in words:
                raise self.error("G5 needs both P and Q (end control point offset)", col0)
            if "I" in words or "J" in words:
                if "I" not in words or "J" not in words:
                    raise self.error("G5 needs both I and J, or neither", col0)
                ij = (words["I"][0] * scale, words["J"][0] * scale)
            else:
                ij = (-self.spline_pq[0], -self.spline_pq[1])
            pq = (words["P"][0] * scale, words["Q"][0] * scale)
            points = [
                start,
                [start[0] + ij[0], start[1] + ij[1], start[2]],
                [end[0] + pq[0], end[1] + pq[1], start[2]],
                end,
            ]
        else:
            if "I" not in words or "J" not in words:
                raise self.error("G5.1 needs both I and J (control point offset)", col0)
            for letter in "PQ":
                if letter in words:
                    raise self.error(f"{letter} word with G5.1", words[letter][1])
            ij = (words["I"][0] * scale, words["J"][0] * scale)
            points = [start, [start[0] + ij[0], start[1] + ij[1], start[2]], end]
        degree = len(points) - 1
        to_machine = self.coords.to_machine
        self.segments.append(
            Nurbs(
                degree=degree,
                knots=frozen_array(bezier_nurbs_knots(degree)),
                control_points_mm=frozen_array([to_machine(p) for p in points]),
                weights=frozen_array([1.0] * len(points)),
                feed_mm_s=feed,
                line=self.main_line(),
                plane="XY",
                blend_mm=self.m.blend_mm,
            )
        )
        self.prog = end
        if motion == G_5:
            self.spline_pq = pq
