"""Why the feed is what it is: the limit that set each piece's and each source line's feed
(``plan --explain``).

For every piece of a plan the explanation recomputes the candidate caps from the formulas
of :mod:`nurbscnc.machine.caps` (called, not copied), whole-array over the pieces:

- programmed F (the segment's feed) and V_max, or the rapid rate for a G0;
- the chord-error feed V_af(κ) (SPEC §7, eq. 23) and the normal-acceleration feed √(A/κ)
  at the piece's peak curvature κ;
- the per-axis path limit of :func:`nurbscnc.plan.axes.piece_limits`;
- the curvature feed V_cf (SPEC eq. 24) enters only the caps of the PH pieces that replace
  a NURBS corner, with the corner's peak or mean curvature (plan option ``corner_feed``),
  which the piece columns do not keep: a corner piece whose cap is below every other
  candidate was set by V_cf (the only formula left);

then which of them is the piece's cruise cap (ties go to the first in :class:`Limit`
order), whether the dynamics check lowered that cap or shaped the piece's transitions
(contour error, SPEC §8: :func:`contour_limited`), and whether the profile reached the cap.
A piece that does not reach its cap is limited by the check's shaping, else by a corner stop
at one of its ends (an exact stop at a tangent discontinuity), else by its length: the
S-curve from its neighbours' junction speeds has no room to reach the cap — with the
acceleration limit reached on the way ("distance": the acceleration distance, or the
look-ahead window), or without ("jerk": J_max kept the acceleration from building up,
SPEC §7's T = 2√(Δv/J) branch). A corner blend (G64 P) is
its own limit: its curvature sets its feed because the corner was blended (not stopped).

Time waited at the end of a piece counts too: programmed dwells (G4; M0/M1/M60 pauses count
0 s) against their own source line ("dwell"), and the in-position settle of the planner
(``dwell_after_s`` beyond the programmed dwells) against the line of the piece it follows
("settle").

Per source line (all executions of one line together): motion time, waiting time, the
programmed feed, the achieved feed (the profile's peak over the line's pieces and its
time-weighted mean, length / motion time), and the time spent under each limit; the
line's limit is the one it spent most of its time under. The corners and what the planner
did there come from the plan's :class:`~nurbscnc.plan.corners.CornerLog`.

No I/O: :class:`Explanation` holds arrays; :meth:`Explanation.as_dict` is the JSON form.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from nurbscnc.geometry.path import STOP_KINDS, Kind, stop_seconds
from nurbscnc.machine.caps import chord_feed_mm_s, normal_feed_mm_s
from nurbscnc.plan.axes import piece_limits
from nurbscnc.plan.corners import CornerAction, CornerLog, CornerWhy
from nurbscnc.plan.junctions import junction_caps

#: Relative tolerance of "equal" caps and speeds (the profile's bisection and the caps'
#: floating point are far tighter; a real difference between two limits is far larger).
REL_TOL = 1e-6


class Limit(IntEnum):
    """What limits the feed (order: the tie-break between equal caps)."""

    FEED = 0  #: the programmed F
    V_MAX = 1  #: the machine's V_max
    RAPID = 2  #: the rapid rate (G0)
    CHORD = 3  #: chord error V_af (SPEC eq. 23)
    NORMAL = 4  #: normal acceleration √(A/κ)
    AXIS = 5  #: a per-axis limit (plan/axes.py)
    CURVATURE = 6  #: curvature feed V_cf (SPEC eq. 24), NURBS corner pieces
    BLEND = 7  #: a corner blend (G64 P): its curvature within the tolerance
    CONTOUR = 8  #: lowered by the dynamics check (contour error, SPEC §8)
    CORNER_STOP = 9  #: an exact stop at a corner at one of the piece's ends
    DISTANCE = 10  #: too short to reach its cap (acceleration / look-ahead distance)
    JERK = 11  #: too short to reach its cap, A_max never reached (jerk-limited)
    SETTLE = 12  #: the in-position wait after a rapid (servo settling)
    DWELL = 13  #: a programmed dwell (G4) or pause
    ROTATE = 14  #: a rotary-only move: X Y Z at rest while A B C turn

    @property
    def key(self) -> str:
        """The JSON name (docs/json.md)."""
        return _KEYS[self]

    @property
    def text(self) -> str:
        """A short human description."""
        return _TEXTS[self]


_KEYS = {
    Limit.FEED: "feed",
    Limit.V_MAX: "v_max",
    Limit.RAPID: "rapid",
    Limit.CHORD: "chord_error",
    Limit.NORMAL: "normal_acceleration",
    Limit.AXIS: "axis",
    Limit.CURVATURE: "curvature",
    Limit.BLEND: "blend",
    Limit.CONTOUR: "contour_error",
    Limit.CORNER_STOP: "corner_stop",
    Limit.DISTANCE: "distance",
    Limit.JERK: "jerk",
    Limit.SETTLE: "settle",
    Limit.DWELL: "dwell",
    Limit.ROTATE: "rotate",
}
# Plain words for the user (the paper's terms, V_max, V_af eq. 23, V_cf eq. 24, are in
# docs/json.md beside the JSON keys).
_TEXTS = {
    Limit.FEED: "programmed F",
    Limit.V_MAX: "machine top speed",
    Limit.RAPID: "rapid rate",
    Limit.CHORD: "chord tolerance",
    Limit.NORMAL: "acceleration on curves",
    Limit.AXIS: "axis limit",
    Limit.CURVATURE: "tight curve",
    Limit.BLEND: "rounded corner",
    Limit.CONTOUR: "contour error",
    Limit.CORNER_STOP: "stop at a corner",
    Limit.DISTANCE: "too short to accelerate",
    Limit.JERK: "too short (jerk limit)",
    Limit.SETTLE: "settling after a rapid",
    Limit.DWELL: "dwell",
    Limit.ROTATE: "rotary-only move",
}

#: The axis names of :attr:`Explanation.piece_axis` and ``line_axis`` codes 0…5.
AXIS_NAMES = ("x", "y", "z", "a", "b", "c")

#: What the planner did at a corner, in plain words (:class:`CornerAction`).
CORNER_ACTION_TEXT = {
    CornerAction.BLEND: "rounded",
    CornerAction.PASS: "passed at speed",
    CornerAction.STOP: "stopped",
}
#: Why, in plain words (:class:`CornerWhy`; the JSON has the enum names).
CORNER_WHY_TEXT = {
    CornerWhy.BLENDED: "within the path tolerance (G64)",
    CornerWhy.SMALL_BREAK: "the bend is small enough to pass at speed",
    CornerWhy.EXACT_PATH: "exact path mode (G61)",
    CornerWhy.EXACT_STOP: "exact stop mode (G61.1)",
    CornerWhy.ZERO_TOLERANCE: "blend tolerance 0",
    CornerWhy.NO_BLEND_FITS: "no rounding fits within the path tolerance",
    CornerWhy.NOT_BLENDABLE: "a cusp, reversal or 3-D turn cannot be rounded",
    CornerWhy.DWELL_OR_PAUSE: "a dwell, pause or program stop",
    CornerWhy.RAPID_FEED: "a rapid meets a cutting move",
    CornerWhy.PROGRAM_END: "start or end of the program",
    CornerWhy.STOP_FASTER: "stopping is quicker than the tight rounding that fits",
    CornerWhy.A_RATE: "A changes rate (the rotary axes move in step: exact stop)",
    CornerWhy.B_RATE: "B changes rate (the rotary axes move in step: exact stop)",
    CornerWhy.C_RATE: "C changes rate (the rotary axes move in step: exact stop)",
    CornerWhy.ROTARY_MOVES: "A B C move along these moves (corners are not rounded)",
    CornerWhy.ROTATE: "a rotary-only move (A B C turn with X Y Z at rest)",
}
N_LIMITS = len(Limit)
#: The :class:`Limit` of each JSON name.
LIMIT_OF_KEY = {key: limit for limit, key in _KEYS.items()}


@dataclass(frozen=True, eq=False)
class Explanation:
    """Why a plan runs at the feed it does (module doc).

    Per piece (k,): ``piece_limit`` (:class:`Limit` codes), ``piece_cap_limit`` what set its
    cruise cap (before the profile), ``piece_cap_mm_s`` its final cap [mm/s],
    ``piece_time_s`` its motion time [s], ``piece_peak_mm_s`` the profile's peak on it
    [mm/s], ``piece_feed_mm_s`` its programmed feed [mm/s] (the rapid rate for a G0).

    Per source line (n,), ascending: ``line``, ``kind`` (the first segment's kind on that
    line: "line", "rapid", "arc", "nurbs", "dwell", "pause"), ``length_mm``, ``time_s``
    motion time [s], ``wait_s`` dwell and settle time [s] after it, ``feed_mm_s`` the
    programmed feed [mm/s] (NaN: none, a dwell), ``peak_mm_s`` and ``mean_mm_s`` the
    achieved feed [mm/s] (peak, and length / motion time; 0 without motion),
    ``limit_time_s`` (n, :data:`N_LIMITS`) the time [s] spent under each limit, ``limit``
    the one with the most.

    ``corners``: the plan's :class:`~nurbscnc.plan.corners.CornerLog`. ``cycle_time_s``
    the plan's cycle time [s].

    ``piece_axis`` (k,) and ``line_axis`` (n,): where the limit is "axis", the axis whose
    limit set the feed (an index into :data:`AXIS_NAMES`: X Y Z on lines, A B C wherever
    they move); for a rotary-only move's line the axis that set its rate; -1 otherwise (or
    an X Y Z limit on a curve, whose binding axis changes along it).
    """

    piece_limit: np.ndarray
    piece_cap_limit: np.ndarray
    piece_cap_mm_s: np.ndarray
    piece_time_s: np.ndarray
    piece_peak_mm_s: np.ndarray
    piece_feed_mm_s: np.ndarray
    line: np.ndarray
    kind: tuple
    length_mm: np.ndarray
    time_s: np.ndarray
    wait_s: np.ndarray
    feed_mm_s: np.ndarray
    peak_mm_s: np.ndarray
    mean_mm_s: np.ndarray
    limit_time_s: np.ndarray
    limit: np.ndarray
    corners: CornerLog
    cycle_time_s: float
    piece_axis: np.ndarray | None = None
    line_axis: np.ndarray | None = None

    def axis_of_line(self, i: int) -> str | None:
        """The axis that set line ``i``'s feed ("x" … "c"), or None."""
        if self.line_axis is None or self.line_axis[i] < 0:
            return None
        return AXIS_NAMES[int(self.line_axis[i])]

    def limit_text(self, i: int) -> str:
        """Line ``i``'s limit in plain words, naming the axis when one set it."""
        text = Limit(int(self.limit[i])).text
        axis = self.axis_of_line(i)
        return text if axis is None else f"{text} ({axis.upper()})"

    def total_by_limit_s(self) -> dict[str, float]:
        """Time [s] the whole program spends under each limit (present ones), largest first."""
        total = self.limit_time_s.sum(axis=0)
        order = np.argsort(-total, kind="stable")
        return {Limit(int(i)).key: float(total[i]) for i in order if total[i] > 0.0}

    def costliest(self, count: int | None = None) -> np.ndarray:
        """Indices of the lines by time (motion + wait), most first; ``count`` of them."""
        order = np.argsort(-(self.time_s + self.wait_s), kind="stable")
        return order if count is None else order[:count]

    def line_dict(self, i: int) -> dict:
        """The JSON entry of line index ``i`` (docs/json.md, ``explain.lines``)."""
        row = self.limit_time_s[i]
        feed = float(self.feed_mm_s[i])
        return {
            "line": int(self.line[i]),
            "kind": self.kind[i],
            "length_mm": float(self.length_mm[i]),
            "time_s": float(self.time_s[i]),
            "wait_s": float(self.wait_s[i]),
            "feed_programmed_mm_s": feed if np.isfinite(feed) else None,
            "feed_peak_mm_s": float(self.peak_mm_s[i]),
            "feed_mean_mm_s": float(self.mean_mm_s[i]),
            "limit": Limit(int(self.limit[i])).key,
            "limit_time_s": {Limit(j).key: float(row[j]) for j in np.flatnonzero(row > 0.0)},
            **self._axis_entry(i),
        }

    def _axis_entry(self, i: int) -> dict:
        """``{"axis": name}`` where an axis set line ``i``'s feed, else nothing."""
        axis = self.axis_of_line(i)
        return {} if axis is None else {"axis": axis}

    def corner_dicts(self, stops_only: bool = False) -> list[dict]:
        """The corners as JSON entries (docs/json.md, ``explain.corners``), from whole
        columns."""
        c = self.corners
        rows = np.flatnonzero(c.action == CornerAction.STOP) if stops_only else slice(None)
        actions = {int(a): a.name.lower() for a in CornerAction}
        whys = {int(w): w.name.lower() for w in CornerWhy}
        return [
            {"line": ln, "point_mm": pt, "turning_deg": deg, "action": actions[a], "why": whys[w]}
            for ln, pt, deg, a, w in zip(
                c.line[rows].tolist(),
                c.point_mm[rows].tolist(),
                np.degrees(c.turning_rad[rows]).tolist(),
                c.action[rows].tolist(),
                c.why[rows].tolist(),
            )
        ]

    def corner_texts(self) -> dict[str, int]:
        """:meth:`corner_counts` in plain words: ``{"stopped: exact path mode (G61)": 3}``."""
        c = self.corners
        keys, counts = np.unique(
            np.stack([c.action, c.why]).astype(np.int64), axis=1, return_counts=True
        )
        return {
            f"{CORNER_ACTION_TEXT[CornerAction(a)]}: {CORNER_WHY_TEXT[CornerWhy(w)]}": int(n)
            for (a, w), n in zip(keys.T.tolist(), counts.tolist())
        }

    def corner_counts(self) -> dict[str, int]:
        """How many corners got each (action, why): ``{"stop/exact_path": 3, ...}``."""
        c = self.corners
        keys, counts = np.unique(
            np.stack([c.action, c.why]).astype(np.int64), axis=1, return_counts=True
        )
        return {
            f"{CornerAction(int(a)).name.lower()}/{CornerWhy(int(w)).name.lower()}": int(n)
            for (a, w), n in zip(keys.T.tolist(), counts.tolist())
        }

    def line_dicts(self) -> list[dict]:
        """Every line's JSON entry (as :meth:`line_dict`, built from whole columns)."""
        keys = [m.key for m in Limit]
        # The nonzero times of each line, in Limit order (most lines have one or two).
        r, c = np.nonzero(self.limit_time_s > 0.0)
        times: list[dict] = [{} for _ in range(self.line.size)]
        for i, j, x in zip(r.tolist(), c.tolist(), self.limit_time_s[r, c].tolist()):
            times[i][keys[j]] = x
        feed = [None if not np.isfinite(f) else f for f in self.feed_mm_s.tolist()]
        limit = [keys[c] for c in self.limit.tolist()]
        return [
            {
                "line": ln,
                "kind": kd,
                "length_mm": le,
                "time_s": t,
                "wait_s": w,
                "feed_programmed_mm_s": f,
                "feed_peak_mm_s": pk,
                "feed_mean_mm_s": mn,
                "limit": lim,
                "limit_time_s": row,
                **self._axis_entry(i),
            }
            for i, (ln, kd, le, t, w, f, pk, mn, lim, row) in enumerate(
                zip(
                    self.line.tolist(),
                    self.kind,
                    self.length_mm.tolist(),
                    self.time_s.tolist(),
                    self.wait_s.tolist(),
                    feed,
                    self.peak_mm_s.tolist(),
                    self.mean_mm_s.tolist(),
                    limit,
                    times,
                )
            )
        ]

    def as_dict(self) -> dict:
        """The ``explain`` object of ``plan --json --explain`` (every line, every corner)."""
        return {
            "limit_time_s": self.total_by_limit_s(),
            "lines": self.line_dicts(),
            "corners": self.corner_dicts(),
            "corner_counts": self.corner_counts(),
        }


# -- attribution, one step each ----------------------------------------------------------------
def contour_limited(plan, cap_before_mm_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """What the dynamics check (contour error, SPEC §8) did to each piece, two masks (k,):
    ``lowered``, its final cap ``plan.caps_mm_s`` is below the cap it had before the check;
    ``shaped``, the check changed its speed transitions (a planner that shapes the descent
    into and the rise out of a stop says so in ``plan.shaped_by_contour``; without that
    field nothing is shaped). The one place that says what "limited by the contour check"
    means."""
    lowered = np.asarray(plan.caps_mm_s) < np.asarray(cap_before_mm_s) * (1.0 - REL_TOL)
    shaped = getattr(plan, "shaped_by_contour", None)
    shaped = np.zeros_like(lowered) if shaped is None else np.asarray(shaped, dtype=bool)
    return lowered, shaped


def acceleration_limits_mm_s2(plan, machine) -> np.ndarray:
    """The tangential acceleration limit [mm/s²] each piece was planned with (k,): the
    smaller of its rise and descent limits when the plan records them (``plan.limits``),
    else the per-axis path limit of :func:`~nurbscnc.plan.axes.piece_limits`."""
    lim = getattr(plan, "limits", None)
    if lim is not None:
        return np.minimum(
            np.asarray(lim.a_up_mm_s2, dtype=float), np.asarray(lim.a_down_mm_s2, dtype=float)
        )
    return np.asarray(piece_limits(plan.pieces, machine).a_mm_s2, dtype=float)


@dataclass(frozen=True, eq=False)
class SegmentColumns:
    """What the explanation reads of the program's n segments, in one pass: ``kind`` (n,)
    names (object array), ``feed_mm_s`` (n,) programmed feeds [mm/s] (0 without one),
    ``line`` (n,) source lines, ``seconds`` (n,) the hold of dwells and pauses [s]."""

    kind: np.ndarray
    feed_mm_s: np.ndarray
    line: np.ndarray
    seconds: np.ndarray

    @classmethod
    def of(cls, segments, holds=None) -> SegmentColumns:
        """``holds``: the plan's rotary-only moves (:class:`~nurbscnc.plan.rotary.Holds`),
        whose planned times are their seconds."""
        rows = [(s.kind, getattr(s, "feed_mm_s", 0.0), s.line) for s in segments]
        kind = np.array([r[0] for r in rows], dtype=object)
        stop = np.flatnonzero(np.isin(kind, STOP_KINDS))
        seconds = np.zeros(len(rows))
        seconds[stop] = [stop_seconds(segments[i]) for i in stop.tolist()]
        if holds is not None:
            seconds[holds.segment] = holds.duration_s
        return cls(
            kind,
            np.array([r[1] for r in rows], dtype=float),
            np.array([r[2] for r in rows], dtype=np.int64),
            seconds,
        )


def piece_feeds_mm_s(seg: SegmentColumns, pieces) -> np.ndarray:
    """The programmed feed [mm/s] of each piece's segment (k,)."""
    return seg.feed_mm_s[np.asarray(pieces.segment, dtype=np.intp)]


def cap_limits(seg: SegmentColumns, pieces, machine) -> tuple[np.ndarray, np.ndarray]:
    """What set each piece's cruise cap (k,) :class:`Limit` codes, and the cap [mm/s] before
    the dynamics check (the piece's own cap and its axis limit): candidates from
    :mod:`nurbscnc.machine.caps` (module doc). :func:`axis_of_pieces` says which axis."""
    lim = machine.limits
    k = len(pieces)
    rapid = np.asarray(pieces.rapid, dtype=bool)
    kappa = np.abs(np.asarray(pieces.kappa_max_per_mm, dtype=float))
    curved = np.asarray(pieces.kind) != Kind.LINE
    feed = piece_feeds_mm_s(seg, pieces)
    axis_v = np.asarray(piece_limits(pieces, machine).v_mm_s, dtype=float)
    inf = np.full(k, np.inf)
    cand = np.empty((6, k))
    cand[Limit.FEED] = np.where(rapid, np.inf, feed)
    cand[Limit.V_MAX] = np.where(rapid, np.inf, lim.v_max_mm_s)
    cand[Limit.RAPID] = np.where(rapid, lim.rapid_mm_s, np.inf)
    cand[Limit.CHORD] = np.where(
        curved, chord_feed_mm_s(kappa, machine.servo.period_s, lim.chord_tolerance_mm), inf
    )
    cand[Limit.NORMAL] = np.where(curved, normal_feed_mm_s(kappa, lim.a_max_mm_s2), inf)
    cand[Limit.AXIS] = axis_v
    cap = np.asarray(pieces.v_cap_mm_s, dtype=float)
    before = np.minimum(cap, axis_v)
    lowest = cand.min(axis=0)
    # Ties go to the first candidate in Limit order (F before V_max, ...).
    code = np.argmax(cand <= lowest * (1.0 + REL_TOL), axis=0)
    # Below every candidate the columns can recompute: V_cf (eq. 24) of a NURBS corner piece.
    code = np.where(before < lowest * (1.0 - REL_TOL), Limit.CURVATURE, code)
    # A blend of a G64 P corner (a PH piece on a line or arc segment) slowed by its curvature.
    on_nurbs = seg.kind[np.asarray(pieces.segment, dtype=np.intp)] == "nurbs"
    blend = (np.asarray(pieces.kind) == Kind.PH) & ~on_nurbs
    slowed = np.isin(code, (Limit.CHORD, Limit.NORMAL, Limit.CURVATURE))
    code = np.where(blend & slowed, Limit.BLEND, code)
    return code.astype(np.int8), before


def axis_of_pieces(pieces, machine, code: np.ndarray) -> np.ndarray:
    """Per piece (k,) the axis (index into :data:`AXIS_NAMES`) whose velocity limit set the
    cap of the pieces whose ``code`` is :attr:`Limit.AXIS`: a rotary axis where its cap
    (:func:`~nurbscnc.plan.rotary.rotary_limits`) is the lowest, else on a line the X Y Z
    axis of the smallest V_i / |t_i| (direction cosines, exact); -1 elsewhere."""
    from nurbscnc.plan.rotary import rotary_limits

    k = len(pieces)
    out = np.full(k, -1, dtype=np.int8)
    axis = code == Limit.AXIS
    if not axis.any():
        return out
    line = axis & (np.asarray(pieces.kind) == Kind.LINE)
    v_xyz = np.full(k, np.inf)
    if machine.axis_limits.any and line.any():
        t = np.abs(np.asarray(pieces.tangent_start, dtype=float)[:, line].T)
        with np.errstate(divide="ignore"):
            per = np.where(t > 0.0, machine.axis_limits.as_arrays()[0][None, :] / t, np.inf)
        out[line] = np.argmin(per, axis=1)
        v_xyz[line] = per.min(axis=1)
    rot = rotary_limits(pieces, machine)
    if rot is not None:
        v_rot, rot_axis = rot[0], rot[3]
        mine = axis & (rot_axis >= 0) & (v_rot <= v_xyz * (1.0 + REL_TOL))
        out[mine] = 3 + rot_axis[mine]
    return out


def profile_extremes(profile) -> tuple[np.ndarray, np.ndarray]:
    """The peak feed [mm/s] and the peak |acceleration| [mm/s²] of the profile on each piece
    (k,), exactly: the jerk is constant within a phase, so v is quadratic and a linear there;
    their extremes lie at the phase ends, at the piece ends, or where a phase's acceleration
    crosses zero (v only). Every such point goes to the piece whose span holds its s."""
    k = profile.piece_count
    starts = np.asarray(profile.piece_start_mm)
    end_t = np.append(profile.piece_start_time_s, profile.duration_s)
    _, v_b, a_b, _, _ = profile.sample(end_t)
    v_b[-1], a_b[-1] = 0.0, 0.0
    peak = np.maximum(v_b[:-1], v_b[1:])
    a_peak = np.maximum(np.abs(a_b[:-1]), np.abs(a_b[1:]))
    d = np.asarray(profile.phase_duration_s)
    s0, v0 = np.asarray(profile.phase_s0_mm), np.asarray(profile.phase_v0_mm_s)
    a0, jk = np.asarray(profile.phase_a0_mm_s2), np.asarray(profile.phase_jerk_mm_s3)
    s1 = s0 + d * (v0 + d * (0.5 * a0 + d * jk / 6.0))
    v1 = v0 + d * (a0 + 0.5 * d * jk)
    a1 = a0 + d * jk
    with np.errstate(divide="ignore", invalid="ignore"):
        tau = np.where(jk != 0.0, -a0 / jk, -1.0)
    inside = (tau > 0.0) & (tau < d)
    ti = tau[inside]
    s_i = s0[inside] + ti * (v0[inside] + ti * (0.5 * a0[inside] + ti * jk[inside] / 6.0))
    v_i = v0[inside] + ti * (a0[inside] + 0.5 * ti * jk[inside])

    def piece_of(s, side):
        return np.clip(np.searchsorted(starts, s, side=side) - 1, 0, k - 1)

    np.maximum.at(peak, piece_of(s0, "right"), v0)
    np.maximum.at(peak, piece_of(s1, "left"), v1)
    np.maximum.at(peak, piece_of(s_i, "right"), v_i)
    np.maximum.at(a_peak, piece_of(s0, "right"), np.abs(a0))
    np.maximum.at(a_peak, piece_of(s1, "left"), np.abs(a1))
    return peak, a_peak


def corner_stop_ends(pieces) -> np.ndarray:
    """Pieces (k,) with an exact stop at a corner at either end: an inner junction whose cap
    is 0 (:func:`~nurbscnc.plan.junctions.junction_caps`) for its geometry — not a dwell or
    pause, not a rapid meeting a feed move, not a zero-length piece."""
    k = len(pieces)
    jc = junction_caps(pieces)
    length = np.asarray(pieces.length_mm)
    rapid = np.asarray(pieces.rapid)
    corner = np.zeros(k + 1, dtype=bool)
    if k > 1:
        corner[1:-1] = (
            (jc[1:-1] == 0.0)
            & ~np.asarray(pieces.stop_after[:-1])
            & (rapid[:-1] == rapid[1:])
            & (length[:-1] > 0.0)
            & (length[1:] > 0.0)
        )
    return corner[:-1] | corner[1:]


def waits_s(seg: SegmentColumns, pieces) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Programmed waits and settling: (the stops' segment indices (m,), their seconds (m,),
    settle [s] after each piece (k,)). A dwell, pause or rotary-only move charges the piece
    before it (the planner's rule: the last piece with a smaller segment index, else the
    first piece); what ``dwell_after_s`` holds beyond that is the planner's own settle
    time."""
    idx = np.flatnonzero(np.isin(seg.kind, STOP_KINDS))
    seconds = seg.seconds[idx]
    k = len(pieces)
    programmed = np.zeros(k)
    if idx.size and k:
        row = np.maximum(np.searchsorted(np.asarray(pieces.segment), idx, side="left") - 1, 0)
        np.add.at(programmed, row, seconds)
    settle = np.maximum(np.asarray(pieces.dwell_after_s, dtype=float) - programmed, 0.0)
    settle[settle < 1e-12] = 0.0
    return idx, seconds, settle


def explain_plan(program, machine, plan) -> Explanation:
    """Why ``plan`` (of ``program`` on ``machine``) runs at the feed it does (module doc)."""
    pieces, profile = plan.pieces, plan.profile
    rotary = getattr(pieces, "rotary", None)
    seg = SegmentColumns.of(program.segments, None if rotary is None else rotary.holds)
    cap_code, before = cap_limits(seg, pieces, machine)
    final = np.asarray(plan.caps_mm_s, dtype=float)
    lowered, shaped = contour_limited(plan, before)
    # Above the cap it had before the check: raised by it (``raise_corner_caps``, with
    # pre-compensation), to where the contour error allowed — the check's limit too.
    raised = final > before * (1.0 + REL_TOL)
    code = np.where(lowered | raised, Limit.CONTOUR, cap_code).astype(np.int8)
    peak, a_peak = profile_extremes(profile)
    short = peak < final * (1.0 - REL_TOL)
    a_lim = acceleration_limits_mm_s2(plan, machine)
    stop = corner_stop_ends(pieces)
    # Below its cap: the check's shaping, else a corner stop, else its length (A reached or
    # not on the way).
    reason = np.where(
        shaped,
        Limit.CONTOUR,
        np.where(
            stop,
            Limit.CORNER_STOP,
            np.where(a_peak >= a_lim * (1.0 - REL_TOL), Limit.DISTANCE, Limit.JERK),
        ),
    )
    code = np.where(short & (np.asarray(pieces.length_mm) > 0.0), reason, code).astype(np.int8)
    t_piece = profile.piece_duration_s
    feed = np.where(
        np.asarray(pieces.rapid), machine.limits.rapid_mm_s, piece_feeds_mm_s(seg, pieces)
    )
    stop_seg, dwell_s, settle = waits_s(seg, pieces)
    dwell_lines = seg.line[stop_seg]
    # A rotary-only move by its segment (a dwell on its source line is not one).
    rotate = seg.kind[stop_seg] == "rotate"

    # Per source line: every piece and every dwell of that line number.
    p_line = np.asarray(pieces.line, dtype=np.int64)
    lines = np.unique(np.concatenate((p_line, dwell_lines)))
    n = lines.size
    pi = np.searchsorted(lines, p_line)
    di = np.searchsorted(lines, dwell_lines)
    length = np.bincount(pi, np.asarray(pieces.length_mm), n)
    time = np.bincount(pi, t_piece, n)
    wait = np.bincount(pi, settle, n) + np.bincount(di, dwell_s, n)
    limit_time = np.bincount(pi * N_LIMITS + code, t_piece, n * N_LIMITS).reshape(n, N_LIMITS)
    limit_time[:, Limit.SETTLE] += np.bincount(pi, settle, n)
    limit_time[:, Limit.DWELL] += np.bincount(di, np.where(rotate, 0.0, dwell_s), n)
    limit_time[:, Limit.ROTATE] += np.bincount(di, np.where(rotate, dwell_s, 0.0), n)
    line_peak = np.zeros(n)
    np.maximum.at(line_peak, pi, peak)
    line_feed = np.full(n, -np.inf)
    np.maximum.at(line_feed, pi, feed)
    line_feed[~np.isfinite(line_feed)] = np.nan
    with np.errstate(divide="ignore", invalid="ignore"):
        mean = np.where(time > 0.0, length / time, 0.0)
    # A dwell line's limit is "dwell" even when it lasts 0 s (a pause).
    best = np.argmax(limit_time, axis=1)
    best = np.where(
        limit_time.max(axis=1) > 0.0,
        best,
        np.where(np.isin(lines, dwell_lines), Limit.DWELL, code_of_line(pi, code, n)),
    )
    piece_axis = axis_of_pieces(pieces, machine, code)
    line_axis = _line_axis(pi, code, t_piece, piece_axis, n)
    line_axis[best != Limit.AXIS] = -1
    if rotary is not None:  # a rotary-only move's line: the axis that set its rate
        h = rotary.holds
        mine = (h.axis >= 0) & (best[np.searchsorted(lines, h.line)] == Limit.ROTATE)
        line_axis[np.searchsorted(lines, h.line[mine])] = 3 + h.axis[mine]
    # The kind of each line's first segment.
    order = np.argsort(seg.line, kind="stable")
    first = order[np.searchsorted(seg.line[order], lines, side="left")]
    kinds = tuple(seg.kind[first].tolist())
    return Explanation(
        code,
        cap_code,
        final,
        t_piece,
        peak,
        feed,
        lines,
        kinds,
        length,
        time,
        wait,
        line_feed,
        line_peak,
        mean,
        limit_time,
        best.astype(np.int8),
        pieces.corners,
        float(plan.cycle_time_s),
        piece_axis,
        line_axis,
    )


def _line_axis(pi: np.ndarray, code: np.ndarray, t_piece, piece_axis, n: int) -> np.ndarray:
    """Per line (n,) the axis of its pieces limited by an axis, the one with the most time
    under it (-1: none)."""
    out = np.full(n, -1, dtype=np.int8)
    has = (code == Limit.AXIS) & (piece_axis >= 0)
    if has.any():
        t = np.zeros((n, len(AXIS_NAMES)))
        np.add.at(t, (pi[has], piece_axis[has]), np.asarray(t_piece)[has])
        some = t.max(axis=1) > 0.0
        out[some] = np.argmax(t[some], axis=1)
    return out


def code_of_line(piece_line_index: np.ndarray, code: np.ndarray, n: int) -> np.ndarray:
    """The limit of the last piece of each line (n,), for lines without time (FEED if none)."""
    out = np.full(n, Limit.FEED, dtype=np.int64)
    out[piece_line_index] = code
    return out
