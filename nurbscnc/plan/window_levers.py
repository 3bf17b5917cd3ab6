"""A cut window's levers loop on the pieces around it only
(:func:`~nurbscnc.plan.lookahead.plan_windows`): the levers, the shaping rules' inputs and
the improvement phase's brackets cut to the pieces lo … hi − 1 that hold the window
a … b − 1 (:class:`WindowSetup`), so that each re-plan of a window costs its own pieces, not
the program's k (every lever copy, bisection step, confinement and shaping rule was O(k):
for 320 windows of 500 pieces each, most of the loop's time).

Why the numbers are those of the loop over all k, bit for bit. Every lever outside a … b − 1
is the final one during the window's loop (``confine``), and the shaping rules
(:mod:`~nurbscnc.plan.shaping`) work per piece, per junction or per over-limit sample, whose
pieces all lie in a … b − 1 (the check reads the window's own samples, its virtual end and
its held tail, on piece b − 1 at profile time t_b). Cut to lo … hi − 1 they compute the same
values there; what they change outside a … b − 1 is undone by ``confine`` as before. The
rules' only reach beyond that: the stop junction an over-limit sample is near
(:func:`~nurbscnc.plan.shaping._stop_events`: the first stop at or after τ − 30 ms, the
program's first junction excluded), and the runs of pieces planned as one. So lo is a
junction more than that before every over-limit sample (or the program's start) and
hi = b + 1 (b a rest: no sample is near a junction after it): :meth:`WindowSetup.shape`
checks both on each call and, where they do not hold, applies the rules to the whole
program's levers instead. The one reduction over all k that the loop makes (whether any piece
was shaped) counts the pieces outside lo … hi − 1 from the final levers
(:attr:`WindowSetup.shaped_outside`);
the histories keep the program's junction and piece numbers."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from nurbscnc.plan import shaping
from nurbscnc.plan.levers import Levers
from nurbscnc.plan.pieces import SCALAR_COLUMNS


def _reach_s() -> float:
    """How far before an over-limit sample the rules look back [s]: the stop rule for a stop
    (:func:`~nurbscnc.plan.shaping._stop_events`: τ − STOP_WINDOW_S − period/2), the blame
    over the servo's memory (read when called: the tests change them)."""
    return max(shaping.STOP_WINDOW_S, shaping.STOP_BEFORE_S, shaping.BLAME_WINDOW_S)


def cut_levers(lev: Levers, lo: int, hi: int) -> Levers:
    """The levers of pieces lo … hi − 1 (copies), the histories renumbered from lo."""
    hist = lev.cap_history
    if hist is not None:
        hist = tuple(x[lo:hi].copy() for x in hist)
    return Levers(
        *(getattr(lev, f)[lo:hi].copy() for f in Levers.PER_PIECE),
        hist,
        _renumbered(lev.stop_history, -lo),
    )


def joined_levers(final: Levers, part: Levers, lo: int) -> Levers:
    """``final``'s copy with ``part`` (the levers of pieces lo … lo + len − 1) in its place,
    the histories numbered as the program's (a cap history is the blame, factor and
    strikes of the pieces hit, 0, 1 and 0 elsewhere:
    :func:`~nurbscnc.plan.shaping.local_factors`)."""
    out = final.copy()
    hi = lo + part.caps.size
    for f in Levers.PER_PIECE:
        getattr(out, f)[lo:hi] = getattr(part, f)
    if part.cap_history is not None:
        k = final.caps.size
        hist = []
        for x, neutral in zip(part.cap_history, (0.0, 1.0, 0)):
            full = np.full(k, neutral, dtype=x.dtype)
            full[lo:hi] = x
            hist.append(full)
        out.cap_history = tuple(hist)
    else:
        out.cap_history = None
    out.stop_history = _renumbered(part.stop_history, lo)
    return out


def _renumbered(history: dict | None, shift: int) -> dict | None:
    """A stop history (keys: junction j, or ("settle", rapid row r)) with every number
    shifted by ``shift``."""
    if history is None:
        return None
    return {
        (k + shift if isinstance(k, int) else (k[0], k[1] + shift)): v for k, v in history.items()
    }


@dataclass(frozen=True, eq=False)
class _ProfileCut:
    """What the shaping rules read of a profile, for pieces lo … hi − 1: the junction speeds
    (lo … hi), peaks and start times, and the time of junction hi (``duration_s``)."""

    junction_speeds_mm_s: np.ndarray
    piece_peak_speed_mm_s: np.ndarray
    piece_start_time_s: np.ndarray
    duration_s: float

    @property
    def piece_duration_s(self) -> np.ndarray:
        return np.diff(np.append(self.piece_start_time_s, self.duration_s))


class _PiecesCut:
    """The program's pieces lo … hi − 1 as the shaping rules and the improvement phase read
    them: every per-piece column (:data:`~nurbscnc.plan.pieces.SCALAR_COLUMNS`) cut to the
    span, and the junctions where the curvature vector jumps (``jump_rows``, from lo)."""

    def __init__(self, pieces, lo: int, hi: int):
        for name in SCALAR_COLUMNS:
            setattr(self, name, getattr(pieces, name)[lo:hi])
        jumps = np.asarray(pieces.jump_rows, dtype=np.int64)
        self.jump_rows = jumps[(jumps >= lo) & (jumps < hi - 1)] - lo

    def __len__(self) -> int:
        return self.length_mm.size


class WindowSetup:
    """The :class:`~nurbscnc.plan.setup.Setup` of one cut window's levers loop
    (:func:`~nurbscnc.plan.converge.converge`), its levers those of pieces lo … hi − 1
    (module docstring): a … b − 1 the window, ``final`` the program's levers (the windows
    before final, the later ones kinematic), ``before`` the profile of the pieces before
    the window (None: it is the first), whose times place lo."""

    def __init__(self, st, a: int, b: int, final: Levers, before):
        self.st, self.a, self.b, self.final = st, a, b, final
        self.options, self.eps_mm, self.period = st.options, st.eps_mm, st.period
        self.checker = st.checker
        k = st.k
        lo, hi = self.span(st, a, b, before)
        self.lo, self.hi = lo, hi
        self.initial = cut_levers(st.initial, lo, hi)
        self.upper = self.initial if st.upper is st.initial else cut_levers(st.upper, lo, hi)
        self.pieces = _PiecesCut(st.pieces, lo, hi)
        self.smooth = st.smooth[lo : hi + 1]
        rows = st.settle_rows
        keep = (rows >= lo) & (rows + 1 < hi)
        self.settle_at = np.flatnonzero(keep)  # their places among the program's rows
        self.settle_rows = rows[keep] - lo
        outside = np.ones(k, dtype=bool)
        outside[lo:hi] = False
        self._planned = None  # (settles, planned pieces) of the last plan
        #: Whether a piece outside lo … hi − 1 is shaped.
        self.shaped_outside = bool(np.any(final.shaped & outside))

    @staticmethod
    def span(st, a: int, b: int, before) -> tuple[int, int]:
        """(lo, hi): the last junction twice the rules' reach before the window's start
        (the program's start if none), and the piece after the window's (its end)."""
        lo = 0
        if before is not None and a > 0:
            t_lo = float(before.duration_s) - 2.0 * _reach_s() - 4.0 * st.period
            j = int(np.searchsorted(before.piece_start_time_s[:a], t_lo, side="left")) - 1
            lo = max(j, 0)
        return lo, min(b + 1, st.k)

    def levers(self, lev: Levers) -> Levers:
        """The loop's levers (pieces lo … hi − 1) of the program's ``lev``."""
        return cut_levers(lev, self.lo, self.hi)

    def program_levers(self, part: Levers) -> Levers:
        """The program's levers: the final ones with the loop's ``part`` in place."""
        return joined_levers(self.final, part, self.lo)

    def planned(self, lv: Levers):
        """The program's pieces with the settles of the loop's ``lv`` (the final ones
        elsewhere) in their dwells (:meth:`Setup.planned`); the last ones again while the
        settles are the same (most re-plans change feeds and transitions only)."""
        last = self._planned
        if last is not None and np.array_equal(last[0], lv.settle_s):
            return last[1]
        settle = self.final.settle_s.copy()
        settle[self.lo : self.hi] = lv.settle_s
        planned = self.st.planned_settles(settle)
        self._planned = (lv.settle_s.copy(), planned)
        return planned

    def confine(self, lv: Levers) -> None:
        """Undo changes outside the window a … b − 1 (the final levers there)."""
        lo, a, b = self.lo, self.a - self.lo, self.b - self.lo
        for f in Levers.PER_PIECE:
            x, y = getattr(lv, f), getattr(self.final, f)
            x[:a], x[b:] = y[lo : self.a], y[self.b : self.hi]

    def any_shaped(self, lv: Levers) -> bool:
        """Whether any piece of the program is shaped (``lv`` here, the final elsewhere)."""
        return self.shaped_outside or bool(lv.shaped.any())

    def _exact(self, profile, overs) -> bool:
        """Whether the rules cut to lo … hi − 1 answer these over-limit samples as over all
        pieces (module docstring): no stop at or before lo is reached by any of them, and
        the junction b (a rest) is reached by all before hi is."""
        tau = overs.tau_s
        if tau.size == 0:
            return True
        start = profile.piece_start_time_s
        if self.lo > 0:
            x = float(tau.min()) - shaping.STOP_WINDOW_S - 0.5 * self.period
            if not float(start[self.lo]) < x:
                return False
        if self.hi < self.st.k:
            x = float(tau.max()) - shaping.STOP_WINDOW_S - 0.5 * self.period
            if not (profile.junction_speeds_mm_s[self.b] == 0.0 and float(start[self.b]) >= x):
                return False
        return True

    def _cut(self, profile, overs):
        """The profile and over-limit samples as the rules see pieces lo … hi − 1."""
        lo, hi = self.lo, self.hi
        end = profile.duration_s if hi == self.st.k else profile.piece_start_time_s[hi]
        prof = _ProfileCut(
            profile.junction_speeds_mm_s[lo : hi + 1],
            profile.piece_peak_speed_mm_s[lo:hi],
            profile.piece_start_time_s[lo:hi],
            float(end),
        )
        ov = replace(
            overs,
            run_piece=overs.run_piece - lo,
            restart_count=np.asarray(overs.restart_count)[self.settle_at],
        )
        return prof, ov

    def shape(self, lv: Levers, result) -> None:
        """One local re-plan of ``lv`` (in place; :meth:`Setup.shape` on the program's
        levers, the same numbers: module docstring)."""
        overs, profile = result[2].overs, result[1]
        if not self._exact(profile, overs):
            self._whole(lv, lambda full: self.st.shape(full, result))
            return
        prof, ov = self._cut(profile, overs)
        st = self.st
        shaping.shape(
            lv,
            ov,
            self.eps_mm,
            prof,
            self.pieces,
            self.smooth,
            self.settle_rows,
            st.settle_max,
            self.period,
        )

    def fallback(self, lv: Levers, result, stage: int) -> None:
        """The fallback of ``stage`` on ``lv`` (in place; :meth:`Setup.fallback`)."""
        _, ov = self._cut(result[1], result[2].overs)
        shaping.fallback(
            lv,
            ov,
            self.eps_mm,
            self.pieces,
            self.settle_rows,
            self.st.settle_max,
            self.period,
            stage,
        )

    def _whole(self, lv: Levers, rule) -> None:
        """``rule`` applied to the program's levers, the result taken back into ``lv``."""
        full = self.program_levers(lv)
        rule(full)
        back = self.levers(full)
        for f in Levers.PER_PIECE:
            setattr(lv, f, getattr(back, f))
        lv.cap_history, lv.stop_history = back.cap_history, back.stop_history
