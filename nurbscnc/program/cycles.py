"""Canned cycles G73, G74, G81–G89 expanded into plain moves, with LinuxCNC 2.9's semantics.

Pure: plain numbers in (already in mm, s, mm/s), plain moves out; the interpreter keeps the
sticky state between blocks (:class:`CycleState`) and adds line and column to errors.

The rules are those of LinuxCNC's ``interp_cycles.cc`` (``convert_cycle``,
``convert_cycle_xy/yz/zx`` and ``CYCLE_MACRO``) and its G-code reference:

* The plane selects the axes: G17 drills along Z at (X, Y); G18 along Y at (Z, X); G19 along X
  at (Y, Z). Below, "Z" means the drilling axis and (A, B) the two plane axes.
* The *initial level* ("old Z") is the drilling-axis position when the first cycle block after
  another motion mode starts; it stays while cycle blocks follow one another (even of
  different codes) and is forgotten by any other motion (G0–G3, G80...): pass a fresh
  ``CycleState()`` then.
* G90: R and Z are absolute, X/Y give the hole (the current position where missing). G91:
  R is an increment from the initial level, Z an increment from R, and X/Y are added to the
  position once per repeat (``L`` repeats, default 1, L0 is an error).
* R below Z is an error. If the initial level is below R, a first rapid raises the drilling
  axis to R (and the cycle then behaves as if started at R).
* Retract level ("clear"): R under G99, the initial level (raised to R if it was below) under
  G98.
* Each repeat: rapid in the plane to the hole (at the current level on the first repeat when it
  is above R, then down to R; otherwise at the clear level and, if that is above R, down to R),
  then the cycle proper (``_CYCLES``).
* Sticky words: when the same cycle continues, a missing R, Z, P, Q (and I J K for G87) keeps
  the last value; a different cycle code needs R and Z again (and P for G82/G86/G88/G89, Q for
  G73/G83, I J K for G87).

G74/G84 (tapping) are LinuxCNC 2.9's *floating-chuck* cycles: a feed in, spindle stop and
reverse, dwell P, feed out, stop and restore — no spindle synchronisation, so they are
expanded here (the spindle events come out as moves of their own kinds; the planner may
ignore them). Only in G17: LinuxCNC 2.9's G74/G84 in G18 and G19 pass the coordinates to its
canon in the wrong order (the tool goes to a point with interchanged axes), which is refused
rather than copied. G74 with an L word is refused, as LinuxCNC does. G73/G83 back off by
LinuxCNC's fixed 0.010 in = 0.254 mm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import NamedTuple

from nurbscnc.errors import ProgramError

#: G73/G83: LinuxCNC's G83_RAPID_DELTA, 0.010 in (0.254 mm in mm programs: the same length).
PECK_CLEARANCE_MM = 0.254

#: plane → (index of first plane axis, second plane axis, drilling axis), as LinuxCNC's
#: cycle_feed/cycle_traverse map (end1, end2, end3) for G17, G18 and G19.
_AXES = {"XY": (0, 1, 2), "ZX": (2, 0, 1), "YZ": (1, 2, 0)}
_LETTER = "XYZ"
_PLANE_NAME = {"XY": "xy", "ZX": "xz", "YZ": "yz"}
CODES = ("G73", "G74", "G81", "G82", "G83", "G84", "G85", "G86", "G87", "G88", "G89")


class TooManyMoves(ProgramError):
    """A cycle block that would make more moves than :func:`expand_cycle` may."""


@dataclass(frozen=True)
class CycleState:
    """What LinuxCNC remembers between cycle blocks (all mm / s; None = not set).

    ``motion``: the cycle code of the last cycle block ("G81" ...), None after other motion;
    ``initial_level_mm``: the drilling-axis position when the run of cycle blocks began
    (LinuxCNC's ``cycle_il``); the rest are the sticky words.
    """

    motion: str | None = None
    initial_level_mm: float | None = None
    r_mm: float | None = None
    z_mm: float | None = None
    p_s: float = 0.0
    q_mm: float = 0.0
    i_mm: float = 0.0
    j_mm: float = 0.0
    k_mm: float = 0.0


@dataclass(frozen=True)
class CycleMove:
    """One step of a cycle: ``kind`` is 'rapid', 'feed', 'dwell', 'pause' (G88: the operator
    retracts), 'spindle-stop', 'spindle-cw', 'spindle-ccw' or 'spindle-orient'.

    ``end_mm`` is the (x, y, z) position after the step [mm]; ``feed_mm_s`` the feed of a
    'feed' [mm/s]; ``dwell_s`` the time of a 'dwell' [s].
    """

    kind: str
    end_mm: tuple
    feed_mm_s: float = 0.0
    dwell_s: float = 0.0


@dataclass(frozen=True)
class CycleResult:
    """The moves of one cycle block, the sticky state after it and the final position [mm]."""

    moves: tuple
    state: CycleState
    position_mm: tuple


class _Emitter:
    """Collects moves in plane coordinates (a, b, c) and maps them to (x, y, z)."""

    def __init__(self, plane: str, feed_mm_s: float, position_mm, limit: float = math.inf):
        self.ia, self.ib, self.ic = _AXES[plane]
        self.feed_mm_s = feed_mm_s
        self.pos = list(position_mm)
        self.moves: list[CycleMove] = []
        self.limit = limit  # most moves: past it, TooManyMoves

    def _append(self, move: CycleMove) -> None:
        self.moves.append(move)
        if len(self.moves) > self.limit:
            raise TooManyMoves("a canned cycle block with more moves than the program may make")

    def _point(self, a, b, c) -> tuple:
        p = [0.0, 0.0, 0.0]
        p[self.ia], p[self.ib], p[self.ic] = a, b, c
        return tuple(p)

    def rapid(self, a, b, c):
        self.pos = list(self._point(a, b, c))
        self._append(CycleMove("rapid", tuple(self.pos)))

    def feed(self, a, b, c):
        self.pos = list(self._point(a, b, c))
        self._append(CycleMove("feed", tuple(self.pos), self.feed_mm_s))

    def event(self, kind: str, dwell_s: float = 0.0):
        self._append(CycleMove(kind, tuple(self.pos), 0.0, dwell_s))


def _spindle_start(direction: str) -> str:
    return "spindle-cw" if direction == "cw" else "spindle-ccw"


def expand_cycle(
    code: str,
    words: dict,
    *,
    incremental: bool,
    position_mm: tuple,
    plane: str,
    retract: str,
    feed_mm_s: float,
    state: CycleState,
    spindle: str = "cw",
    max_moves: float = math.inf,
) -> CycleResult:
    """The moves of one canned-cycle block, in LinuxCNC's order (see the module docstring).

    ``code``: "G73", "G74", "G81" ... "G89". ``words``: the block's cycle words by letter —
    X Y Z R Q I J K [mm, as programmed: absolute under G90, increments under G91], P [s], L
    [count], and polar "@" [mm] / "^" [degrees] in the XY plane. ``position_mm``: the current
    (x, y, z) [mm]. ``plane``: "XY" (G17), "ZX" (G18), "YZ" (G19). ``retract``: "G98" (back
    to the initial level) or "G99" (to R). ``feed_mm_s``: the feed in force [mm/s].
    ``spindle``: "cw", "ccw" or "off" (G74/G84/G86/G87/G88 need it turning).

    The caller checks what is outside the cycle: inverse-time feed and cutter compensation
    (LinuxCNC refuses both with canned cycles), and rotary words. ``max_moves``: the moves
    the block may make; a G73/G83 block certain to make more (Q 1e-9 mm) raises
    :class:`TooManyMoves` before any is made (the caller counts the rest as made).
    Raises ProgramError with LinuxCNC's message (the caller adds line and column).
    """
    _refuse(code, words, plane, feed_mm_s)
    same = state.motion == code
    r_word, z_word, repeats = _levels_and_repeats(code, words, state, plane, same)
    ia, ib, ic = _AXES[plane]
    current = list(position_mm)
    initial = state.initial_level_mm if state.initial_level_mm is not None else current[ic]
    hole = _place(words, incremental, current, plane, r_word, z_word, initial)
    r, c = hole.r, hole.c
    if r < c:
        raise ProgramError(
            f"R less than {_LETTER[ic].lower()} in cycle in {_PLANE_NAME[plane]} plane"
        )

    # A net under the count below: the moves the emitter makes (some go nowhere and make no
    # segment, so twice the budget) never run away, whatever the count missed.
    out = _Emitter(plane, feed_mm_s, position_mm, 2.0 * max_moves + 64)
    old_c = initial
    current_c = current[ic]
    if old_c < r:
        out.rapid(current[ia], current[ib], r)
        old_c = r
        current_c = old_c
    clear = r if retract == "G99" else old_c

    sticky = _STICKY_WORDS.get(code, _no_words)(code, words, state, same)
    if code in ("G73", "G83"):
        _count_pecks(code, sticky.q_mm, r, c, repeats, max_moves)
    a, b = hole.a, hole.b
    for repeat in range(repeats):
        a, b = _next_hole(a, b, hole)
        _approach(out, a, b, r, clear, current_c if repeat == 0 else None)
        _CYCLES[code](
            out,
            a,
            b,
            r,
            clear,
            c,
            sticky.p_s,
            sticky.q_mm,
            (sticky.i_mm, sticky.j_mm, sticky.k_mm, incremental),
            spindle,
            code,
        )

    new_state = replace(
        state,
        motion=code,
        initial_level_mm=initial,
        r_mm=r_word,
        z_mm=z_word,
        p_s=sticky.p_s,
        q_mm=sticky.q_mm,
        i_mm=sticky.i_mm,
        j_mm=sticky.j_mm,
        k_mm=sticky.k_mm,
    )
    final = [0.0, 0.0, 0.0]
    final[ia], final[ib], final[ic] = a, b, clear
    # G87 ends at (a, b, clear) too; G88 ends at the bottom (the operator retracts by hand), as
    # LinuxCNC's canonical moves do; the interpreter's notion of position is (a, b, clear).
    return CycleResult(tuple(out.moves), new_state, tuple(final))


# -- the steps of a cycle block -------------------------------------------------------------
def _refuse(code: str, words: dict, plane: str, feed_mm_s: float) -> None:
    """What LinuxCNC refuses, or nurbscnc refuses rather than copy, before any level."""
    if code not in CODES:
        raise ProgramError(f"{code} is not a canned cycle")
    if code == "G74" and "L" in words:  # LinuxCNC's word check counts G74 out of L's codes
        raise ProgramError(
            "L word with no G10, cutter compensation, canned cycle, digital/analog input, "
            "M98 or NURBS code"
        )
    if code in ("G74", "G84") and plane != "XY":
        raise ProgramError(
            f"{code} is only supported in the XY plane (G17): LinuxCNC 2.9 taps to "
            "coordinates with the axes interchanged in G18 and G19"
        )
    if feed_mm_s == 0.0:
        raise ProgramError("Cannot feed with zero feed rate")


def _levels_and_repeats(code: str, words: dict, state: CycleState, plane: str, same: bool):
    """The R and depth words (sticky while the same cycle goes on) and the repeats L."""
    if "R" not in words and not same:
        raise ProgramError("R clearance plane unspecified in cycle")
    r_word = words.get("R", state.r_mm)
    repeats = words.get("L", 1)
    if repeats == 0:
        raise ProgramError("Cannot do zero repeats of cycle")
    repeats = int(round(repeats))
    depth_letter = _LETTER[_AXES[plane][2]]
    if state.motion != code and depth_letter not in words:
        raise ProgramError(
            f"{depth_letter} value unspecified in {_PLANE_NAME[plane]} plane canned cycle"
        )
    return r_word, words.get(depth_letter, state.z_mm), repeats


class _Hole(NamedTuple):
    """The levels R and bottom ``c`` on the drilling axis, the first hole (a, b) in the plane
    before its increment, and the increments of each repeat (G91: plane and polar) [mm,
    rad]."""

    r: float
    c: float
    a: float
    b: float
    a_inc: float = 0.0
    b_inc: float = 0.0
    radius_inc: float = 0.0
    theta_inc: float = 0.0


def _place(
    words: dict,
    incremental: bool,
    current: list,
    plane: str,
    r_word: float,
    z_word: float,
    initial: float,
) -> _Hole:
    """The levels and the hole: G90 absolute (X Y, or polar @ ^ in XY); G91 R from the
    initial level, the depth from R, X Y (and polar) added once per repeat."""
    ia, ib, _ = _AXES[plane]
    if not incremental:
        if plane == "XY" and ("@" in words or "^" in words):
            radius = words.get("@", math.hypot(current[1], current[0]))
            theta = math.radians(words["^"]) if "^" in words else math.atan2(current[1], current[0])
            a, b = radius * math.cos(theta), radius * math.sin(theta)
        else:
            a = words.get(_LETTER[ia], current[ia])
            b = words.get(_LETTER[ib], current[ib])
        return _Hole(r_word, z_word, a, b)
    radius_inc = theta_inc = 0.0
    if plane == "XY":
        radius_inc = words.get("@", 0.0)
        theta_inc = math.radians(words.get("^", 0.0))
    r = r_word + initial
    return _Hole(
        r,
        r + z_word,
        current[ia],
        current[ib],
        words.get(_LETTER[ia], 0.0),
        words.get(_LETTER[ib], 0.0),
        radius_inc,
        theta_inc,
    )


def _next_hole(a: float, b: float, hole: _Hole) -> tuple:
    """The hole of the next repeat: the increments added (polar ones about the origin)."""
    a, b = a + hole.a_inc, b + hole.b_inc
    if hole.radius_inc or hole.theta_inc:
        if a == 0.0 and b == 0.0:
            raise ProgramError(
                "Incremental motion with polar coordinates is indeterminate when at the origin"
            )
        if hole.radius_inc:
            theta, radius = math.atan2(b, a), math.hypot(b, a) + hole.radius_inc
            a, b = radius * math.cos(theta), radius * math.sin(theta)
        if hole.theta_inc:
            theta, radius = math.atan2(b, a) + hole.theta_inc, math.hypot(b, a)
            a, b = radius * math.cos(theta), radius * math.sin(theta)
    return a, b


def _approach(out, a: float, b: float, r: float, clear: float, first_c: float | None) -> None:
    """Rapid to the hole and down to R: on the first repeat at the current level when it is
    above R (``first_c``), otherwise at the clear level."""
    if first_c is not None and first_c > r:
        out.rapid(a, b, first_c)
        out.rapid(a, b, r)
    else:
        out.rapid(a, b, clear)
        if clear > r:
            out.rapid(a, b, r)


class _Sticky(NamedTuple):
    """The words a cycle family keeps between blocks: dwell P [s], peck Q [mm], back-bore
    I J K [mm]."""

    p_s: float
    q_mm: float
    i_mm: float
    j_mm: float
    k_mm: float


def _no_words(code: str, words: dict, state: CycleState, same: bool) -> _Sticky:
    """G81, G85: no words of their own (the state's are carried on)."""
    return _Sticky(state.p_s, state.q_mm, state.i_mm, state.j_mm, state.k_mm)


def _dwell_words(code: str, words: dict, state: CycleState, same: bool) -> _Sticky:
    """G82, G86, G88, G89: P, required when the cycle changes."""
    if not same and "P" not in words:
        raise ProgramError(f"Dwell time p word missing with {code.lower()}")
    return _no_words(code, words, state, same)._replace(p_s=words.get("P", state.p_s))


def _tap_words(code: str, words: dict, state: CycleState, same: bool) -> _Sticky:
    """G74, G84: an optional P."""
    return _no_words(code, words, state, same)._replace(p_s=words.get("P", state.p_s))


def _peck_words(code: str, words: dict, state: CycleState, same: bool) -> _Sticky:
    """G73, G83: Q, required when the cycle changes."""
    if not same and "Q" not in words:
        raise ProgramError(f"Q word missing with {code.lower()}")
    return _no_words(code, words, state, same)._replace(q_mm=words.get("Q", state.q_mm))


def _back_bore_words(code: str, words: dict, state: CycleState, same: bool) -> _Sticky:
    """G87: I, J and K, all required when the cycle changes."""
    if not same:
        for letter in "IJK":
            if letter not in words:
                raise ProgramError(f"{letter} word missing with g87")
    return _Sticky(
        state.p_s,
        state.q_mm,
        words.get("I", state.i_mm),
        words.get("J", state.j_mm),
        words.get("K", state.k_mm),
    )


def _count_pecks(
    code: str, q_mm: float, r: float, c: float, repeats: int, max_moves: float
) -> None:
    """Pecks counted before they are made: a hole has more than (R − Z)/Q − 2 of them
    (_peck), each a feed and a rapid back that go somewhere, and under G83 the rapid down to
    the last depth too (all but the first's when Q is the 0.254 mm clearance), so more than
    this many moves is certain; fewer are made and counted as made."""
    per_peck = 3.0 if code == "G83" else 2.0
    if q_mm > 0.0 and repeats * (per_peck * ((r - c) / q_mm - 2.0) - 1.0) > max_moves:
        raise TooManyMoves(
            f"{code.lower()} with Q{q_mm:g} mm pecks {r - c:g} mm deep "
            f"{repeats} time(s): more moves than the program may make"
        )


_STICKY_WORDS = {
    "G82": _dwell_words,
    "G86": _dwell_words,
    "G88": _dwell_words,
    "G89": _dwell_words,
    "G74": _tap_words,
    "G84": _tap_words,
    "G73": _peck_words,
    "G83": _peck_words,
    "G87": _back_bore_words,
}


# -- the cycles proper: LinuxCNC's convert_cycle_g8x, from the hole at level R ---------------
def _g81(out, a, b, r, clear, c, p, q, ijk, spindle, code):
    out.feed(a, b, c)
    out.rapid(a, b, clear)


def _g82(out, a, b, r, clear, c, p, q, ijk, spindle, code):
    out.feed(a, b, c)
    out.event("dwell", p)
    out.rapid(a, b, clear)


def _peck(out, a, b, r, clear, c, q, back_to_r: bool):
    """G83 (back to R after each peck) and G73 (back off by the clearance only)."""
    if q <= 0.0:
        raise ProgramError("Negative or zero q value used")
    depth = r - q
    while depth > c:
        out.feed(a, b, depth)
        if back_to_r:
            out.rapid(a, b, r)
        out.rapid(a, b, depth + PECK_CLEARANCE_MM)
        if not depth - q < depth:  # Q under half an ulp of the depth: it would never move on
            raise ProgramError(
                f"Q{q:g} is below the resolution of the depth {depth:g}: the "
                "pecks would never reach the bottom"
            )
        depth -= q
    out.feed(a, b, c)
    out.rapid(a, b, clear)


def _g83(out, a, b, r, clear, c, p, q, ijk, spindle, code):
    _peck(out, a, b, r, clear, c, q, back_to_r=True)


def _g73(out, a, b, r, clear, c, p, q, ijk, spindle, code):
    _peck(out, a, b, r, clear, c, q, back_to_r=False)


def _tap(out, a, b, r, clear, c, p, q, ijk, spindle, code):
    """G84 (right hand) / G74 (left hand) floating-chuck tapping."""
    if spindle == "off":
        raise ProgramError(f"Spindle not turning in {code}")
    if code == "G74" and spindle == "cw":
        raise ProgramError("Spindle turning clockwise in G74")
    if code == "G84" and spindle == "ccw":
        raise ProgramError("Spindle turning counterclockwise in G84")
    out.feed(a, b, c)
    out.event("spindle-stop")
    out.event("spindle-ccw" if code == "G84" else "spindle-cw")
    out.event("dwell", p)
    out.feed(a, b, clear)
    out.event("spindle-stop")
    out.event("spindle-cw" if code == "G84" else "spindle-ccw")


def _g85(out, a, b, r, clear, c, p, q, ijk, spindle, code):
    out.feed(a, b, c)
    out.feed(a, b, r)
    out.rapid(a, b, clear)


def _need_spindle(spindle, code):
    if spindle not in ("cw", "ccw"):
        raise ProgramError(f"Spindle not turning in {code.lower()}")


def _g86(out, a, b, r, clear, c, p, q, ijk, spindle, code):
    _need_spindle(spindle, code)
    out.feed(a, b, c)
    out.event("dwell", p)
    out.event("spindle-stop")
    out.rapid(a, b, clear)
    out.event(_spindle_start(spindle))


def _g87(out, a, b, r, clear, c, p, q, ijk, spindle, code):
    """Back boring: the plane axes' words among I J K offset the tool sideways, the drilling
    axis' word is the top of the counterbore (G17: I, J and K; G18: K, I and J; G19: J, K, I)."""
    _need_spindle(spindle, code)
    *offsets, incremental = ijk  # I, J, K: the offsets along X, Y, Z, whatever the plane
    middle = offsets[out.ic] + (c if incremental else 0.0)
    oa, ob = a + offsets[out.ia], b + offsets[out.ib]
    out.rapid(oa, ob, r)
    out.event("spindle-stop")
    out.event("spindle-orient")
    out.rapid(oa, ob, c)
    out.rapid(a, b, c)
    out.event(_spindle_start(spindle))
    out.feed(a, b, middle)
    out.feed(a, b, c)
    out.event("spindle-stop")
    out.event("spindle-orient")
    out.rapid(oa, ob, c)
    out.rapid(oa, ob, clear)
    out.rapid(a, b, clear)
    out.event(_spindle_start(spindle))


def _g88(out, a, b, r, clear, c, p, q, ijk, spindle, code):
    _need_spindle(spindle, code)
    out.feed(a, b, c)
    out.event("dwell", p)
    out.event("spindle-stop")
    out.event("pause")
    out.event(_spindle_start(spindle))


def _g89(out, a, b, r, clear, c, p, q, ijk, spindle, code):
    out.feed(a, b, c)
    out.event("dwell", p)
    out.feed(a, b, clear)


_CYCLES = {
    "G73": _g73,
    "G74": _tap,
    "G81": _g81,
    "G82": _g82,
    "G83": _g83,
    "G84": _tap,
    "G85": _g85,
    "G86": _g86,
    "G87": _g87,
    "G88": _g88,
    "G89": _g89,
}
