"""The cut windows of a program (:func:`cut_windows`, :class:`Window`) and what their
re-plans share: a window's own profile (:class:`OwnProfiles`), the levers of cuts seen before
(:class:`SeenWindows`), and the profiles of the windows before and after it, compacted,
stood in for and spliced into one (:func:`compacted`, :func:`placeholder`, :func:`spliced`)."""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from nurbscnc.plan.checkresult import Check
from nurbscnc.plan.levers import Levers
from nurbscnc.plan.pieces import PieceList
from nurbscnc.plan.plans import Limits, Plan, profile_over
from nurbscnc.plan.profile import Profile
from nurbscnc.plan.setup import Setup


@dataclass(frozen=True, eq=False)
class Window:
    """One cut window of :func:`~nurbscnc.plan.lookahead.plan_windows`: ``index``; its
    pieces ``first`` … ``end`` − 1 (the rapids before a cut and the cut, up to the next
    rapid: a rest junction); its servo samples ``k0`` … ``k1`` − 1 (wall time k·T_s within
    it; the last window: to the end); ``plan``: the whole program's plan with this window
    and all before it final (the profile of a window depends only on its own levers and the
    windows before it: the junctions between windows are at rest), the later ones not
    planned yet (their kinematic levers); ``check``: this window's check (compact) and
    ``iterations``: its re-plans."""

    index: int
    first: int
    end: int
    k0: int
    k1: int
    #: Makes :attr:`plan` (on first use: a caller that keeps the last window only, as
    #: :func:`~nurbscnc.plan.lookahead.plan_checked` does, makes one whole-program plan, not
    #: one per window).
    make_plan: Callable[[], Plan] = field(repr=False)
    check: Check | None
    iterations: int

    @functools.cached_property
    def plan(self) -> Plan:
        """The whole program's plan with this window and every window before it final."""
        return self.make_plan()


def cut_windows(pieces: PieceList) -> np.ndarray:
    """Piece index of the start of each cut window (w,) (the first is 0): every rapid that a
    cut precedes starts a window (a cut → rapid junction is a rest,
    :func:`~nurbscnc.plan.junctions.junction_caps`), so a window is the rapids before a cut and
    the cut; the settle after a rapid belongs to the cut after it."""
    rapid = np.asarray(pieces.rapid, dtype=bool)
    return np.concatenate(([0], np.flatnonzero(rapid[1:] & ~rapid[:-1]) + 1))


class OwnProfiles:
    """A cut window's own profile (:func:`~nurbscnc.plan.lookahead.plan_windows`):
    :func:`~nurbscnc.plan.plans.profile_over` of its pieces; for a window whose cut repeats
    an earlier one (a part cut again elsewhere, its levers started from that one's:
    :meth:`SeenWindows.warm`), its rapids' and its cut's planned apart (the junction between
    them is a rest: each is what the whole window's profile gives for its pieces, to the
    rounding of the times after it) and spliced, and the cut's remembered: a cut that
    repeats it with those levers has the same lengths, caps, junctions and limits bit for
    bit, and :func:`profile_over` is a pure function of them, so its profile is taken, not
    planned again. Whether a window is split depends on the windows before it only (a
    program cut short plans its first windows as the whole program does). The last
    :data:`MEMO` cuts' profiles of :data:`MEMO_MIN_PIECES` to :data:`MEMO_PIECES` pieces are
    kept (the key holds the cut's columns)."""

    MEMO = 4
    MEMO_MIN_PIECES = 64
    MEMO_PIECES = 1 << 16

    def __init__(self, st: Setup):
        self.st = st
        self.kept: dict[bytes, Profile] = {}

    def __call__(self, lv: Levers, a: int, b: int, cut: int | None, base: int = 0) -> Profile:
        """The own profile of window a … b − 1; ``cut``: the first piece of its cut when the
        cut repeats an earlier one (:meth:`SeenWindows.warm`), else None; ``base``: the
        piece of the levers' first entry (a window's loop holds those around it only)."""
        st = self.st
        lim = lv.limits()

        def over(lo: int, hi: int) -> Profile:
            m, n = lo - base, hi - base
            return profile_over(
                st.pieces.length_mm[lo:hi],
                lv.caps[m:n],
                st.smooth[lo : hi + 1],
                Limits(
                    lim.a_up_mm_s2[m:n],
                    lim.j_up_mm_s3[m:n],
                    lim.a_down_mm_s2[m:n],
                    lim.j_down_mm_s3[m:n],
                ),
                st.options.lookahead_pieces,
            )

        c = cut
        if (
            c is None
            or c == a
            or st.smooth[c] > 0.0
            or not self.MEMO_MIN_PIECES <= b - c <= self.MEMO_PIECES
            or st.options.lookahead_pieces is not None
        ):
            # Not a repeat; a cut without rapids, a passed junction between them, a cut too
            # short to gain (two profiles and a splice cost more than one) or too long to
            # key, or a bounded look-ahead
            # (which counts the window's pieces): whole.
            return over(a, b)
        smooth = st.smooth[c : b + 1].copy()
        smooth[[0, -1]] = 0.0  # the rests at its ends (what profile_over reads of them)
        key = b"".join(
            np.ascontiguousarray(x).tobytes()
            for x in (
                st.pieces.length_mm[c:b],
                lv.caps[c - base : b - base],
                smooth,
                lim.a_up_mm_s2[c - base : b - base],
                lim.j_up_mm_s3[c - base : b - base],
                lim.a_down_mm_s2[c - base : b - base],
                lim.j_down_mm_s3[c - base : b - base],
            )
        )
        cut = self.kept.get(key)
        if cut is None:
            cut = over(c, b)
            if len(self.kept) >= self.MEMO:
                self.kept.pop(next(iter(self.kept)))
            self.kept[key] = cut
        return spliced([over(a, c), cut])


class SeenWindows:
    """The final levers of the cuts planned so far, to start a cut that repeats one of them
    (a part cut again at another place: the same pieces translated) from that cut's final
    levers instead of the kinematic ones.

    A window is the rapids before a cut and the cut; the cut (from its first feed piece) is
    compared, and warmed with the settle after the rapid before it. Same: as many pieces,
    of the same kinds, rapid, stop, pass and dwell flags, and within 1e-9 (relative; 1e-9 mm
    for positions relative to the cut's first piece; for unit tangents, whose last bits
    carry the coordinates' size: 1.2e-12 apart 560 mm away) in length, curvature, end
    points, tangents and kinematic levers. A warm start is only where the
    levers loop begins: the window is checked as any other, and re-planned from there if
    the check fails (its servo starts from the state the window before left, its own).
    Where it passes at once the cut's plan is the repeated one's (the improvement phase has
    nothing to gain: the first check is the fastest plan): a part cut n times costs the
    first cut's re-plans, not n times them. Found by a key (piece count, kinds, lengths to
    1e-6 mm), then compared in full."""

    _FIELDS = Levers.PER_PIECE

    def __init__(self, st: Setup):
        self.st = st
        self.by_key: dict = {}

    def _cut(self, a: int, b: int) -> int:
        """The first feed piece of window a … b − 1 (b: none)."""
        feed = np.flatnonzero(~np.asarray(self.st.pieces.rapid[a:b], dtype=bool))
        return a + int(feed[0]) if feed.size else b

    def _key(self, c: int, b: int) -> tuple:
        p = self.st.pieces
        return (b - c, np.asarray(p.kind[c:b]).tobytes(), round(float(np.sum(p.length_mm[c:b])), 6))

    def _same(self, c: int, b: int, c2: int) -> bool:
        p, init = self.st.pieces, self.st.initial
        sl, sl2 = slice(c, b), slice(c2, c2 + (b - c))
        for f in ("kind", "rapid", "stop_after", "pass_after", "dwell_after_s"):
            if not np.array_equal(getattr(p, f)[sl], getattr(p, f)[sl2]):
                return False
        close = [
            (p.length_mm, 1e-9, 1e-12),
            (p.kappa_max_per_mm, 1e-9, 1e-12),
            *((getattr(init, f), 1e-9, 0.0) for f in Levers.SCALED),
        ]
        if not all(_close(x[sl], x[sl2], r, t) for x, r, t in close):
            return False
        for f in ("start_mm", "end_mm"):
            x = getattr(p, f)
            if not _close(x[:, sl] - x[:, c : c + 1], x[:, sl2] - x[:, c2 : c2 + 1], 0.0, 1e-9):
                return False
        return all(
            _close(getattr(p, f)[:, sl], getattr(p, f)[:, sl2], 0.0, 1e-9)
            for f in ("tangent_start", "tangent_end")
        )

    def warm(self, final: Levers, a: int, b: int) -> tuple[Levers, int | None]:
        """``final``'s copy, the cut of window a … b − 1 from a repeated cut's final levers,
        and the cut's first piece if there was one (else None)."""
        lev = final.copy()
        c = self._cut(a, b)
        if c == b:
            return lev, None
        for c2, saved, settle in self.by_key.get(self._key(c, b), ()):
            if self._same(c, b, c2):
                for f, x in saved.items():
                    getattr(lev, f)[c:b] = x
                if c > a:  # the settle after the rapid before the cut
                    lev.settle_s[c - 1] = settle
                return lev, c
        return lev, None

    def add(self, lev: Levers, a: int, b: int) -> None:
        c = self._cut(a, b)
        if c < b:
            saved = {f: getattr(lev, f)[c:b].copy() for f in self._FIELDS}
            settle = float(lev.settle_s[c - 1]) if c > a else 0.0
            self.by_key.setdefault(self._key(c, b), []).append((c, saved, settle))


def window_plan(
    st: Setup, lev: Levers, result, parts: list, n: int, later, iterations: int
) -> Plan:
    """The plan of a cut window (:attr:`Window.plan`): the final profiles of windows
    0 … n − 1 (``parts``, shared and only appended to), then the stand-in ``later`` for
    the pieces after (None: the last window), spliced whole."""
    profile = spliced([*parts[:n], *([] if later is None else [later])])
    return st.plan(lev, (result[0], profile, *result[2:]), iterations)


#: Servo periods at the end of the windows before a cut window whose phases its re-plans
#: keep (:func:`compacted`): its check reads the profile from one period before its start.
WINDOW_KEEP_PERIODS = 4


def compacted(profile: Profile, keep_s: float) -> Profile:
    """``profile`` (the planned windows before a cut window, or the stand-in after it) with
    every phase that ends before its last ``keep_s`` seconds merged into one stand-in phase
    from rest (s = j·t³/6 up to where the kept phases start); its per-piece columns (start
    times and lengths, speeds) whole. A cut window's check reads the profile from one
    period before the window's start (profile time runs at most as fast as the wall clock),
    so the merged phases are never read; splicing every phase of the windows before (about
    7 a piece) at every re-plan had made a program of many cuts quadratic."""
    times = profile.phase_start_time_s
    i = int(np.searchsorted(times, profile.duration_s - keep_s, side="right")) - 1
    if i <= 0:
        return profile
    t_i, s_i = float(times[i]), float(profile.phase_s0_mm[i])
    jerk = 6.0 * s_i / t_i**3

    def merged(column, first):
        return np.concatenate(([first], column[i:]))

    return Profile(
        profile.total_length_mm,
        profile.duration_s,
        profile.junction_speeds_mm_s,
        profile.piece_peak_speed_mm_s,
        profile.piece_start_mm,
        profile.piece_start_time_s,
        merged(times, 0.0),
        merged(profile.phase_duration_s, t_i),
        merged(profile.phase_s0_mm, 0.0),
        merged(profile.phase_v0_mm_s, 0.0),
        merged(profile.phase_a0_mm_s2, 0.0),
        merged(profile.phase_jerk_mm_s3, jerk),
        merged(profile.phase_piece_index, 0),
    )


def _close(a: np.ndarray, b: np.ndarray, rtol: float, atol: float) -> bool:
    """``np.allclose(a, b, rtol, atol)`` (equal infinities close, NaN never) without its
    overhead: a repeated cut compares a dozen columns per cut window."""
    with np.errstate(invalid="ignore"):
        near = np.isfinite(b) & (np.abs(a - b) <= atol + rtol * np.abs(b))
        return bool(np.all((a == b) | near))


def placeholder(pieces: PieceList, lev: Levers, first: int, whole=None) -> Profile:
    """A stand-in profile of pieces ``first`` … k − 1 (not planned yet): each piece one phase
    of constant jerk from rest (s = j·t³/6 over its length, the jerk within the piece's
    kinematic limit and the mean speed within its cap), the junctions marked moving (not
    stops) except the first, a rest (the window's end). Only its shape matters (piece
    starts after the planned pieces' end, a clock that runs on; speed and acceleration 0 at
    the window's end, as the real plan has them there): a cut window's check and the stream
    never sample it beyond the window's end. ``whole``: the placeholder of all the pieces
    (``first`` = 0) with the same levers, made once: its rows from ``first`` on, rebased
    (subtractions only: a program of many cuts asks for one per cut)."""
    if whole is not None:
        cut = int(np.searchsorted(whole.phase_piece_index, first))
        t0, s0 = float(whole.piece_start_time_s[first]), float(whole.piece_start_mm[first])
        return Profile(
            whole.total_length_mm - s0,
            whole.duration_s - t0,
            np.append(0.0, whole.junction_speeds_mm_s[first + 1 :]),
            whole.piece_peak_speed_mm_s[first:],
            whole.piece_start_mm[first:] - s0,
            whole.piece_start_time_s[first:] - t0,
            whole.phase_start_time_s[cut:] - t0,
            whole.phase_duration_s[cut:],
            whole.phase_s0_mm[cut:] - s0,
            whole.phase_v0_mm_s[cut:],
            whole.phase_a0_mm_s2[cut:],
            whole.phase_jerk_mm_s3[cut:],
            whole.phase_piece_index[cut:] - first,
        )
    length = np.asarray(pieces.length_mm[first:], dtype=float)
    cap = np.asarray(lev.caps[first:], dtype=float)
    dur = np.maximum(length / cap, np.cbrt(6.0 * length / lev.j_up[first:]))
    start_t = np.concatenate(([0.0], np.cumsum(dur)[:-1]))
    start_s = np.concatenate(([0.0], np.cumsum(length)[:-1]))
    moving = np.flatnonzero(length > 0.0)
    z = np.zeros(moving.size)
    jerk = 6.0 * length[moving] / dur[moving] ** 3
    return Profile(
        float(length.sum()),
        float(dur.sum()),
        np.append(0.0, cap),
        cap.copy(),
        start_s,
        start_t,
        start_t[moving],
        dur[moving],
        start_s[moving],
        z,
        z.copy(),
        jerk,
        moving,
    )


def spliced(parts: list) -> Profile:
    """Profiles of consecutive runs of pieces, each from time 0 and arc length 0, as one
    (times, lengths and piece indices shifted by those before; the junctions between them
    are rests, so the speeds join)."""
    if len(parts) == 1:
        return parts[0]
    t0 = np.cumsum([0.0] + [p.duration_s for p in parts[:-1]])
    s0 = np.cumsum([0.0] + [p.total_length_mm for p in parts[:-1]])
    n0 = np.cumsum([0] + [p.piece_count for p in parts[:-1]])
    cat = np.concatenate
    return Profile(
        float(s0[-1] + parts[-1].total_length_mm),
        float(t0[-1] + parts[-1].duration_s),
        cat([p.junction_speeds_mm_s[:-1] for p in parts] + [parts[-1].junction_speeds_mm_s[-1:]]),
        cat([p.piece_peak_speed_mm_s for p in parts]),
        cat([p.piece_start_mm + s for p, s in zip(parts, s0)]),
        cat([p.piece_start_time_s + t for p, t in zip(parts, t0)]),
        cat([p.phase_start_time_s + t for p, t in zip(parts, t0)]),
        cat([p.phase_duration_s for p in parts]),
        cat([p.phase_s0_mm + s for p, s in zip(parts, s0)]),
        cat([p.phase_v0_mm_s for p in parts]),
        cat([p.phase_a0_mm_s2 for p in parts]),
        cat([p.phase_jerk_mm_s3 for p in parts]),
        cat([p.phase_piece_index + n for p, n in zip(parts, n0)]),
    )


def first_sample_at(planned: PieceList, profile: Profile, piece: int, period_s: float) -> int:
    """The first servo sample k at or after the wall time [s] at which ``piece`` starts
    (its profile time plus the dwells before it): t_k = k·T_s ≥ that time."""
    t_wall = float(profile.piece_start_time_s[piece]) + float(np.sum(planned.dwell_after_s[:piece]))
    return int(np.ceil(t_wall / period_s - 1e-9))
