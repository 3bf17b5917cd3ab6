"""The windowed dynamics check of a plan (SPEC §8): the reference sampled a window of
servo samples at a time, the servo simulated with its state carried, the contour error
measured per sample, and only what the shaping rules need kept (:class:`Overs`); the result
of a check (:class:`Check`) and of a program's cut windows joined (:class:`JoinedChecks`)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from nurbscnc.geometry.polyline import MAX_PIECE_POINTS, path_counts
from nurbscnc.machine.profile import Machine
from nurbscnc.plan.checkresult import Accumulator, Check
from nurbscnc.plan.dynamics import (
    PathIndex,
    Response,
    contour_near_mm,
    eq29_mm,
    path_response,
    window_response,
)
from nurbscnc.plan.options import Interpolator
from nurbscnc.plan.pieces import PieceList
from nurbscnc.plan.profile import Profile, same_until_s
from nurbscnc.plan.sampler import ReferenceSampler, as_sampler
from nurbscnc.plan.scope import feed_samples
from nurbscnc.plan.timing import (
    Reference,
    dwell_times,
    joined_rows,
    rows_of,
    same_clock_until_s,
    sample_count,
)
from nurbscnc.servo.model import AxesStream

#: Servo samples per window of the dynamics check: its memory grows with this, not with
#: the motion time.
CHECK_WINDOW = 1 << 16
#: Whether the check leaves out the distance to the path where the servo's tracking error
#: bounds it below ε_max (:meth:`Checker._respond`); the tests compare plans with it off.
RISK_SKIP = True
#: What the tracking-error bound adds for the dense polyline the distance is measured to
#: [mm]: its chords stay within ``geometry.polyline.CHORD_MM`` (1e-5 mm) of the path; a
#: hundred times that.
SKIP_MARGIN_MM = 1e-3


def travel_xy(points_mm: np.ndarray, rows) -> np.ndarray:
    """The reference's direction of travel in XY (k, 2) [mm per sample] at ``rows`` (k,)
    of the points ``points_mm`` (n, 3) [mm]: ``np.gradient(points_mm[:, :2], axis=0)[rows]``
    bit for bit — the central difference (p[i+1] − p[i−1]) / 2 inside, the one-sided
    p[1] − p[0] and p[n−1] − p[n−2] at the ends, zeros for a single point — computed for
    those rows only (eq. 29 needs it where the tracking error may raise its maximum)."""
    rows = np.asarray(rows, dtype=np.intp)
    n = points_mm.shape[0]
    if n < 2:
        return np.zeros((rows.size, 2))
    xy = points_mm[:, :2]
    out = xy[np.minimum(rows + 1, n - 1)] - xy[np.maximum(rows - 1, 0)]
    inner = (rows > 0) & (rows < n - 1)
    out[inner] /= 2.0
    return out


def _joined(first: Reference, then: Reference) -> Reference:
    """The rows of ``first``, then those of ``then``."""
    return joined_rows((first, then))


@dataclass(frozen=True, eq=False)
class _Memo:
    """What :meth:`Checker.run` keeps of its last check of a window made of one chunk, for
    the next re-plan of that window (:meth:`Checker._same_rows`): the window (``key``: its
    first sample, whether it ends the program, its last piece; the servo state it started
    from; the path), the profile and dwell schedule it sampled, the chunk's sampled rows
    (``ref``, from row ``a``), and per own row (from chunk row ``own``) the contour errors
    and which of them were measured (the others: their bound, :meth:`Checker._respond`);
    the rest of a row's response is recomputed (the servo runs on every row anyway)."""

    key: tuple
    stream: AxesStream | None
    path: object
    profile: Profile
    clock: tuple
    a: int
    ref: Reference
    own: int
    contour_mm: np.ndarray
    measured: np.ndarray


@dataclass(frozen=True, eq=False)
class _Chunks:
    """What :meth:`Checker.run` keeps of its last check of a window of several chunks, for
    the next re-plan of that window (:meth:`Checker._resume`): the window (``key``, the servo
    state it started from, the path), the profile and dwell schedule it sampled, and per
    chunk but the last (``entries``): its first own row k0, the row after its own rows k1,
    the wall and profile times [s] of the last reference row it read (row k1, the
    direction of travel's neighbour), and the accumulator's state and the servo's state
    after it (:meth:`~nurbscnc.plan.checkresult.Accumulator.state`, a copy of the
    :class:`~nurbscnc.servo.model.AxesStream`). Memory: a servo state and the compact
    results per chunk, never the samples."""

    key: tuple | None
    stream: AxesStream | None
    path: object
    profile: Profile
    clock: tuple
    entries: list


class Checker:
    """The dynamics check of one program's plans (SPEC §8), a window of servo samples at a
    time: the reference of ``window`` samples (plus one on each side for the
    direction of travel), the servo simulated with its state carried
    (:class:`~nurbscnc.servo.model.AxesStream`), the contour error measured per sample
    (:func:`~nurbscnc.plan.dynamics.window_response`), and only the over-limit samples, the
    piece runs and running statistics kept (:class:`Overs`), unless ``keep`` (the whole
    reference and response, as plots and reports need). A sampler that cannot give windows
    is evaluated whole (one window). Per sample everything is what the whole-array check
    computes, so plans do not depend on the window. ``allowance``: the program's corner
    allowances (:func:`~nurbscnc.plan.allowance.corner_allowance`, None: none)."""

    def __init__(
        self,
        pieces: PieceList,
        machine: Machine,
        sampler: ReferenceSampler,
        eps_mm: float,
        settle_rows: np.ndarray,
        window: int,
        keep: bool,
        allowance=None,
    ):
        self.pieces, self.machine = pieces, machine
        self.sampler = as_sampler(sampler)
        self.eps_mm, self.settle_rows, self.keep = eps_mm, settle_rows, keep
        self.window = max(int(window), 1)
        # Keeping the whole reference and response: one window (windows would be
        # concatenated at the end, twice the memory for a moment).
        self.windowed = self.sampler.windowed and not keep
        self.rapid = pieces.rapid
        self.after_rapid = np.zeros(len(pieces), dtype=bool)  # first piece of a cut after a rapid
        self.after_rapid[settle_rows + 1] = True  # the rows of after_rapid_rows(self.rapid)
        self.index = PathIndex(pieces)  # where the pieces are (built on first use)
        # Where a sample may leave the planned path by more than ε_max: within ε_max + P of
        # a G64 vertex (:class:`~nurbscnc.plan.allowance.CornerAllowance` or None; the
        # accumulator decides with it).
        self.allowance = allowance
        # The risk skip (:meth:`_respond`): only where the reference lies on the path (the
        # exact points of a causal sampler; not the Taylor recurrence's nor a
        # pre-compensated reference), and never on rapids, on the first piece of a cut
        # after a rapid (measured against the cut alone) nor on a piece whose dense
        # polyline was capped (its chords may miss the path by more than the margin).
        self.skip = (
            RISK_SKIP and self.sampler.causal and self.sampler.interpolator == Interpolator.EXACT
        )
        self.no_skip = (
            self.rapid | self.after_rapid | (path_counts(pieces) >= MAX_PIECE_POINTS)
            if self.skip
            else None
        )
        # The servo at rest, discretised once: every check starts from a copy.
        servo = machine.servo
        self._at_rest = AxesStream([servo.x, servo.y, servo.z], servo.period_s)
        self._memo: _Memo | None = None  # the last one-chunk check (:meth:`_same_rows`)
        self._chunks: _Chunks | None = None  # the last many-chunk check (:meth:`_resume`)

    def _windows(
        self,
        planned: PieceList,
        profile: Profile,
        rows: tuple | None = None,
        sample=None,
        from_k: int | None = None,
    ):
        """(reference rows, slice of the window's own rows in them, row of the virtual end
        or None): one row more on each side where there is one (the direction of travel is
        a central difference); with ``rows`` (k0, k1, last, …) only those samples, and
        unless ``last``, after k1 − 1 the row k1 of the program as if it ended with this
        window (:meth:`_end_row`: the next cut window's motion is not planned yet).
        ``sample(a, b)``: rows a … b − 1 of the reference (default: the sampler's);
        ``from_k``: the chunks from the one whose own rows start there (windowed only)."""
        period = self.machine.servo.period_s
        n = sample_count(planned, profile, period)
        r0, r1 = (0, n) if rows is None else (rows[0], min(rows[1], n))
        last = rows is None or rows[2]
        hi = n if last else r1 + 1
        if not self.windowed:
            ref = self.sampler(planned, profile, period)
            if rows is None:
                yield ref, slice(0, ref.t_s.size), None
                return
            chunks = [(ref, max(r0 - 1, 0), min(r1 + 1, hi), r0, r1)]
        else:
            chunks = (
                (
                    None,
                    max(k0 - 1, 0),
                    min(k0 + self.window + 1, r1 + 1, hi),
                    k0,
                    min(k0 + self.window, r1),
                )
                for k0 in range(r0 if from_k is None else from_k, r1, self.window)
            )
        if sample is None:

            def sample(a, b):
                return self.sampler(planned, profile, period, a, b)

        for whole, a, b, k0, k1 in chunks:
            ref = sample(a, b) if whole is None else rows_of(whole, slice(a, b))
            virt = None
            if not last and b == r1 + 1:
                virt = r1 - a
                end = self._end_row(planned, profile, r1, rows[4] + 1)
                ref = _joined(rows_of(ref, slice(0, virt)), end)
            yield ref, slice(k0 - a, k1 - a), virt

    def _head(self, planned: PieceList, profile: Profile, end: int) -> tuple:
        """Pieces 0 … ``end`` − 1 of ``planned`` and ``profile`` as a program of their own,
        as far as the contour distance needs them (:class:`_Head`), their
        :class:`~nurbscnc.plan.dynamics.PathIndex` (kept per ``end``) and rapid flags."""
        return (
            _Head(planned, end),
            _HeadProfile(profile, end),
            _HeadIndex(self.index, end),
            self.rapid[:end],
        )

    def _end_row(self, planned: PieceList, profile: Profile, k: int, end: int) -> Reference:
        """Sample ``k`` of the program made of pieces 0 … ``end`` − 1 only (a cut window's
        end; t_k at or after the end of their motion): at rest at the end of piece
        ``end`` − 1, as :func:`~nurbscnc.plan.timing.exact_reference` gives it there (the
        profile time t_k minus the dwells before ``end``)."""
        t = np.array([k * self.machine.servo.period_s])
        dwell = planned.dwell_after_s[:end]
        before = np.cumsum(dwell[dwell > 0.0])
        tau = t - (before[-1] if before.size else 0.0)
        s = np.array([profile.piece_start_mm[end]])
        piece = np.array([end - 1], dtype=np.intp)
        points, param = planned.path.place(profile.piece_start_mm, s, piece)
        abc = None
        if planned.rotary is not None:  # A B C where that piece ends them
            i = end - 1
            rot = planned.rotary
            abc = (rot.abc_start_deg[i] + rot.rate_deg_mm[i] * planned.length_mm[i])[None, :]
        return Reference(t, tau, s, np.zeros(1), np.zeros(1), piece, points, param, abc_deg=abc)

    def run(
        self,
        planned: PieceList,
        profile: Profile,
        rows: tuple | None = None,
        stream: AxesStream | None = None,
    ) -> Check:
        """Check the plan ``planned``/``profile``: the :class:`Check` of its reference.
        ``rows`` (k0, k1, last, τ_end [s], last piece): only the samples k0 … k1 − 1 (one
        cut window of :func:`~nurbscnc.plan.lookahead.plan_windows`), the servo starting
        from ``stream`` (copied; None: at rest at the first sample), then as if the program
        ended there (``last`` False: its last sample :meth:`_end_row` and the held tail at
        profile time τ_end on the last piece, on a copy of the servo state, which
        :attr:`stream_out` then holds without them, for the next window)."""
        self.sampler.check_begins(0 if rows is None else rows[0])
        if rows is None and not self.windowed:
            return self._run_whole(planned, profile)
        servo = self.machine.servo
        stream_in = stream
        stream = (self._at_rest if stream is None else stream).copy()
        acc = Accumulator(self, profile)
        last = end = None
        # The path the error is measured against: the pieces up to this window's end (the
        # program as if it ended there; the whole program for the last window).
        head = None if rows is None or rows[2] else self._head(planned, profile, rows[4] + 1)
        on, prof, index = (planned, profile, self.index) if head is None else head[:3]
        key = None if rows is None else (rows[0], rows[2], rows[4])
        memo, same = self._memo, self._same_rows(planned, profile, key, stream_in)
        self._memo = None
        # The leading chunks a re-plan left alike: their results and the servo state after
        # them taken from the last check (:meth:`_resume`), the check resumed after them.
        r1, from_k, entries = self._resume(planned, profile, rows, key, stream_in)
        if entries:
            acc.restore(entries[-1][4])
            stream = entries[-1][5].copy()
            same = 0  # the one-chunk memo is for a check from the window's first chunk
        # The first chunk sampled, as (first row, rows): kept for the next re-plan if the
        # window is that one chunk. Memory: one chunk at most.
        sampled: list = []
        chunks = 0

        def sample(a: int, b: int) -> Reference:
            period = servo.period_s
            if same and a == memo.a:  # the leading rows the last check of it sampled
                j = min(same, b - a)
                ref = _joined(
                    rows_of(memo.ref, slice(0, j)), self.sampler(planned, profile, period, a + j, b)
                )
            else:
                ref = self.sampler(planned, profile, period, a, b)
            nonlocal chunks
            chunks += 1
            sampled[:] = [(a, ref)] if chunks == 1 else []
            at[0] = a
            return ref

        at = [0]  # the first row of the chunk sampled last

        for ref, own, virt in self._windows(planned, profile, rows, sample, from_k):
            # The direction of travel of the rows that need it (eq. 29), not of every row.
            chunk_mm = ref.points_mm
            if virt is not None:
                end = (rows_of(ref, slice(virt, virt + 1)), travel_xy(chunk_mm, [virt]))
            # The chunk's first and next own rows, the times of the last row it reads.
            span = (at[0] + own.start, at[0] + own.stop, float(ref.t_s[-1]), float(ref.tau_s[-1]))
            # Own rows whose response the last check computed: their reference rows and
            # the rows on each side (the direction of travel) are the same.
            kept = 0
            if chunks > 1:  # a window of several chunks keeps none
                memo = self._memo = None
            elif same and sampled[0][0] == memo.a and own.start == memo.own:
                kept = max(0, min(same - 1, ref.t_s.size - 2, own.stop) - own.start)
                kept = min(kept, memo.contour_mm.size)
            ref = rows_of(ref, own)
            actual = stream.step(ref.points_mm)
            resp, cutting, measured = self._respond(
                ref,
                actual,
                lambda i, pts=chunk_mm, at=own.start: travel_xy(pts, at + i),
                (on, prof, index),
                profile,
                (head, memo, kept),
                (acc.worst, acc.eq29_max, acc.effective_mm),
            )
            acc.add(resp, cutting, ref.tau_s, ref.piece, measured=measured)
            if self.windowed and virt is None and span[1] < r1:
                # A chunk before the window's last: kept for the next re-plan (_resume).
                entries.append((*span, acc.state(), stream.copy()))
            last = ref
            if sampled and from_k is None:  # kept for the next re-plan of a one-chunk window
                self._memo = _Memo(
                    key,
                    stream_in,
                    planned.path,
                    profile,
                    dwell_times(planned.dwell_after_s, profile),
                    sampled[0][0],
                    sampled[0][1],
                    own.start,
                    resp.contour_mm,
                    measured,
                )
        self.stream_out = stream
        if len(entries) > 0 and self.windowed:
            self._chunks = _Chunks(
                key,
                stream_in,
                planned.path,
                profile,
                dwell_times(planned.dwell_after_s, profile),
                entries,
            )
        self._finish(acc, stream, end, last, planned, profile, rows, head, (on, prof, index))
        return acc.check()

    def _resume(
        self,
        planned: PieceList,
        profile: Profile,
        rows: tuple | None,
        key: tuple | None,
        stream: AxesStream | None,
    ) -> tuple[int, int | None, list]:
        """Where a check of this plan may resume (:class:`_Chunks`, the last check's): the
        window's end row r1, the first own row of the first chunk to compute (None: the
        window's first) and the kept chunks before it (each (k0, k1, t [s], τ [s], the
        accumulator's state, the servo's state after it)).

        A chunk is alike, bit for bit, when the window starts at the same row from the same
        servo state on the same path, the chunk's own rows and its neighbour rows are the
        same rows of the window (so it is not the window's last, whose end row moves with
        the profile), and the last row it reads lies before the wall time where the dwell
        schedules differ and the profile time where the profiles do (the reasoning of
        :meth:`_same_rows`: a row's reference depends on its wall time alone, its response
        on its reference, its neighbours' and the servo state). Its contribution to the
        accumulator is then the same: its over-limit samples, piece runs and statistics,
        and its counts before each restart (a restart time that differs lies at or after
        the profile time where the profiles differ, after every row of the chunk in both).
        Nothing is kept for a sampler that is not causal."""
        period = self.machine.servo.period_s
        n = sample_count(planned, profile, period)
        r1 = n if rows is None else min(rows[1], n)
        old, self._chunks = self._chunks, None
        if (
            not self.windowed
            or not self.sampler.causal
            or old is None
            or old.key != key
            or old.stream is not stream
            or old.path is not planned.path
        ):
            return r1, None, []
        t_wall = same_clock_until_s(old.clock, dwell_times(planned.dwell_after_s, profile))
        t_tau = same_until_s(old.profile, profile)
        kept = []
        for entry in old.entries:
            k0, k1, t_s, tau_s = entry[:4]
            if k1 >= r1 or not (t_s < t_wall and tau_s < t_tau):
                break
            kept.append(entry)
        return r1, (kept[-1][1] if kept else None), kept

    def _finish(
        self,
        acc: Accumulator,
        stream: AxesStream,
        end: tuple | None,
        last: Reference,
        planned: PieceList,
        profile: Profile,
        rows: tuple | None,
        head: tuple | None,
        path: tuple,
    ) -> None:
        """The end of a check of :meth:`run`, added to ``acc``: for a cut window that the
        program does not end with, its virtual last sample ``end`` (reference row and
        direction of travel, :meth:`_end_row`) on a copy of the servo state ``stream``;
        then the reference held at its last point (``last``'s) until the axes settle.
        ``path``: what the contour error is measured against (pieces, profile, index)."""
        on, prof, index = path
        virtual = rows is not None and not rows[2]
        if virtual:  # the end of a cut window, as if the program ended there
            stream = stream.copy()
            if end is not None:
                ref, d_end = end
                actual = stream.step(ref.points_mm)
                resp = window_response(
                    ref.points_mm, ref.s_mm, actual, d_end, on, prof, self.eps_mm, index
                )
                acc.add(
                    resp,
                    self._cutting(ref, resp, profile, head),
                    ref.tau_s,
                    ref.piece,
                    virtual=True,
                )
                last = ref
        tail = stream.settle()  # the reference held at its end until the axes settle
        if tail.shape[0]:
            m = tail.shape[0]
            held = np.repeat(last.points_mm[-1:], m, axis=0)
            resp = window_response(
                held,
                np.full(m, last.s_mm[-1]),
                tail,
                np.zeros((m, 2)),
                on,
                prof,
                self.eps_mm,
                index,
            )
            tau_end, piece_end = (
                (profile.duration_s, len(planned) - 1) if rows is None else rows[3:5]
            )
            acc.add(
                resp,
                np.full(m, not self.rapid[piece_end]),
                np.full(m, tau_end),
                np.full(m, piece_end),
                virtual=virtual,
                corner=virtual,  # no corner allowance after the program's end
            )

    def _same_rows(
        self, planned: PieceList, profile: Profile, key: tuple | None, stream: AxesStream | None
    ) -> int:
        """How many leading rows of the kept chunk (:class:`_Memo`) a check of this plan
        samples alike, bit for bit: the same window started from the same servo state on
        the same path, each row's wall time before the dwell schedules differ
        (:func:`~nurbscnc.plan.timing.same_clock_until_s`) and its profile time before the
        profiles do (:func:`~nurbscnc.plan.profile.same_until_s`). The sampler gives each
        row from its own wall time alone (any window of rows is those rows of the whole
        reference), and the response of a row depends on its reference, its neighbours'
        and the servo state only: so a re-plan that changed the profile from some point on
        costs the samples from there on. 0 without a kept chunk, and for a sampler that is
        not causal (:attr:`~nurbscnc.plan.sampler.ReferenceSampler.causal`)."""
        memo = self._memo
        if (
            memo is None
            or not self.sampler.causal
            or memo.key != key
            or memo.stream is not stream
            or memo.path is not planned.path
        ):
            return 0
        t_wall = same_clock_until_s(memo.clock, dwell_times(planned.dwell_after_s, profile))
        t_tau = same_until_s(memo.profile, profile)
        return int(
            min(
                np.searchsorted(memo.ref.t_s, t_wall, side="left"),
                np.searchsorted(memo.ref.tau_s, t_tau, side="left"),
            )
        )

    def _respond(
        self,
        ref: Reference,
        actual: np.ndarray,
        direction,
        path: tuple,
        profile: Profile,
        keeps: tuple,
        so_far: tuple,
    ) -> tuple[Response, np.ndarray, np.ndarray]:
        """The response to the own reference rows ``ref`` (the servo's ``actual``
        positions; ``direction(i)``: the directions of travel of rows i, :func:`travel_xy`),
        which rows are checked (:meth:`_cutting`) and
        which contour errors were measured: those of the first ``kept`` rows from ``memo``
        (the same numbers) where it measured them, the others computed against ``path``
        (pieces, profile, index); ``keeps``: (head, memo, kept); ``so_far``: the check's
        largest error so far [mm] and largest |eq. 29| [µm].

        The risk skip. The reference point r_k lies on the path (the exact sampler) at path
        length s_k, inside the stretch of path the distance is measured to
        (:func:`~nurbscnc.geometry.distance.windowed_contour_mm`: s_k ± 2|r_k − a_k|), so
        the contour error is at most the tracking error |r_k − a_k| plus the dense
        polyline's chord error (:data:`SKIP_MARGIN_MM`): b_k. A row whose b_k is within
        ε_max is never over the limit, and its distance is measured only where b_k exceeds
        the largest error of the check so far (``worst_mm``, then this chunk's rows
        measured first; the effective error of :mod:`~nurbscnc.plan.allowance`, at most
        the largest measured distance): the check's worst error, its over-limit samples and
        so every decision are those of the full measurement, bit for bit. A row left out
        keeps its bound b_k as its contour error (the statistics' rms is then an upper bound,
        ``contour_bounded_samples`` counts them). Likewise |eq. 29| ≤ |r_k − a_k|: it is
        computed only where that exceeds the largest |eq. 29| so far (the maximum, its only
        use, is exact; the others keep the bound)."""
        on, prof, index = path
        head, memo, kept = keeps
        worst_mm, eq29_max_um, effective = so_far
        n = ref.t_s.size
        axis_err = ref.points_mm - actual
        lag = np.sqrt(np.einsum("ij,ij->i", axis_err, axis_err))
        contour = np.empty(n)
        todo = np.ones(n, dtype=bool)
        if kept:
            contour[:kept] = memo.contour_mm[:kept]
            todo[:kept] = ~memo.measured[:kept]

        def measure(rows: np.ndarray) -> None:
            i = np.flatnonzero(rows)
            if i.size:
                contour[i] = contour_near_mm(
                    actual[i], lag[i], ref.s_mm[i], on, prof, self.eps_mm, index
                )

        measured = np.ones(n, dtype=bool)
        if self.skip:
            bound = lag + SKIP_MARGIN_MM
            fixed = self.no_skip[ref.piece]
            first = fixed | (bound > self.eps_mm)
            measure(todo & first)
            # The largest error so far: the rows after a rapid are measured again against
            # the cut alone (:meth:`_cutting`), so they do not count here. Which rows are
            # left out depends on the rows and the check so far only (a kept row counts as
            # a fresh check would count it).
            final = first & ~fixed
            if final.any():  # the effective error (corner allowances), as the check decides
                i = np.flatnonzero(final)
                e = effective(contour[i], actual[i], ref.piece[i], ref.tau_s[i])
                worst_mm = max(worst_mm, float(e.max()))
            second = ~first & (bound > worst_mm)
            measure(todo & second)
            skipped = ~first & ~second
            contour[skipped] = bound[skipped]
            measured = ~skipped
        else:
            measure(todo)
        if RISK_SKIP:
            eq29 = lag.copy()
            # A margin of 1e-9 for the rounding of eq. 29 against |r − a| (µm from mm).
            i = np.flatnonzero(lag * (1000.0 * (1.0 + 1e-9)) > eq29_max_um)
            if i.size:
                eq29[i] = eq29_mm(axis_err[i], direction(i))
        else:
            eq29 = eq29_mm(axis_err, direction(np.arange(n)))
        resp = Response(actual, axis_err, contour, eq29)
        cutting = self._cutting(ref, resp, profile, head)
        return resp, cutting, measured

    def _run_whole(self, planned: PieceList, profile: Profile) -> Check:
        """The check on the whole reference at once (a sampler without windows, or the
        reference and response kept): :func:`~nurbscnc.plan.dynamics.path_response`."""
        ref = self.sampler(planned, profile, self.machine.servo.period_s)
        resp = path_response(
            ref, planned, profile, self.machine, refine_above_mm=self.eps_mm, index=self.index
        )
        n, m = ref.t_s.size, resp.contour_mm.size
        cutting = np.append(self._cutting(ref, resp, profile), np.full(m - n, not self.rapid[-1]))
        acc = Accumulator(self, profile)
        acc.add(
            resp,
            cutting,
            np.append(ref.tau_s, np.full(m - n, profile.duration_s)),
            np.append(ref.piece, np.full(m - n, len(planned) - 1)),
            corner=np.arange(m) < n,  # none on the held tail after the program's end
        )
        if not self.keep:
            return acc.check()
        return replace(acc.check(), reference=ref, response=resp, cutting=cutting)

    def _cutting(
        self, ref: Reference, resp: Response, profile: Profile, head: tuple | None = None
    ) -> np.ndarray:
        """Which reference samples are checked (N,): contour error matters while cutting
        and before it; samples on rapids (air moves) are not, those of the settle after a
        rapid are (the reference waits at the cut's start while the tool still rings from
        the rapid's stop). The settle's samples and the first cutting samples after a
        rapid are measured against the cut only (in ``resp``; :func:`feed_samples`)."""
        index, rapid = (self.index, self.rapid) if head is None else (head[2], head[3])
        return feed_samples(ref, resp, profile, self.rapid, self.after_rapid, index, rapid)


class _Head:
    """The first ``end`` pieces of a :class:`~nurbscnc.plan.pieces.PieceList`, read-only,
    for the contour distance (the columns it reads, cut to ``end``; the path shared)."""

    def __init__(self, pieces: PieceList, end: int):
        self._pieces, self._end = pieces, end

    def __len__(self) -> int:
        return self._end

    def __getattr__(self, name: str):
        value = getattr(self._pieces, name)
        if isinstance(value, np.ndarray) and value.ndim and value.shape[-1] == len(self._pieces):
            return value[..., : self._end]
        return value


class _HeadIndex:
    """The whole program's :class:`~nurbscnc.plan.dynamics.PathIndex` asked about its first
    ``end`` pieces only (the others excluded): the same candidates and distances as an index
    of those pieces, with the dense polylines kept across every cut window's re-plans."""

    def __init__(self, index: PathIndex, end: int):
        self._index, self._end = index, end

    def distance_mm(
        self,
        q: np.ndarray,
        upper_mm: np.ndarray,
        block: int = 256,
        exclude: np.ndarray | None = None,
    ) -> np.ndarray:
        """:meth:`PathIndex.distance_mm` to pieces 0 … end − 1 (less ``exclude`` (end,))."""
        beyond = np.zeros(len(self._index._pieces), dtype=bool)
        beyond[self._end :] = True
        if exclude is not None:
            beyond[: self._end] |= exclude[: self._end]
        return self._index.distance_mm(q, upper_mm, block, beyond)

    def dense_polyline(
        self, pieces, starts_mm: np.ndarray, total_mm: float, lo: int, hi: int
    ) -> tuple[np.ndarray, np.ndarray]:
        """The dense polyline of pieces ``lo:hi`` of the head: the whole program's kept
        polyline (:meth:`PathIndex.dense_polyline`: the same numbers as made afresh for the
        head, whose starts are the program's first and whose total clips its end)."""
        return self._index.dense_polyline(pieces, starts_mm, total_mm, lo, hi)


class _HeadProfile:
    """The profile of the first ``end`` pieces (their start lengths and total length)."""

    def __init__(self, profile: Profile, end: int):
        self.piece_start_mm = profile.piece_start_mm[:end]
        self.total_length_mm = float(profile.piece_start_mm[end])
