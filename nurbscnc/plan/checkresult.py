"""The result of a dynamics check (:class:`Check`, with what the shaping rules need of it,
:class:`Overs`) and how it is gathered: window by window (:class:`Accumulator`) and over a
program's cut windows (:class:`JoinedChecks`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbscnc.plan.dynamics import Response
from nurbscnc.plan.profile import Profile
from nurbscnc.plan.timing import Reference


@dataclass(frozen=True, eq=False)
class Overs:
    """What the shaping rules need of one check, in memory that grows with the pieces and
    the over-limit samples, never with the motion time: ``count`` M checked
    samples (the settle tail included); the over-limit samples (cutting, contour error above
    the check's limit): their ``index`` (q,) in 0…M−1, ``err_mm`` (q,) [mm] and profile time
    ``tau_s`` (q,) [s] (the tail: the end); the piece of every sample, run-length coded
    (pieces follow time): ``run_piece`` (r,) and ``run_start`` (r,) its first sample;
    ``restart_count`` (len(settle rows),): samples whose profile time is at most the start
    of the cut after each rapid; ``worst_mm`` the largest checked error [mm]."""

    count: int
    index: np.ndarray
    err_mm: np.ndarray
    tau_s: np.ndarray
    run_piece: np.ndarray
    run_start: np.ndarray
    restart_count: np.ndarray
    worst_mm: float


@dataclass(frozen=True, eq=False)
class Check:
    """The dynamics check of the final plan (SPEC §8). Always: ``overs``, the compact form
    the shaping rules read (:class:`Overs`) and ``stats``, the contour error statistics of
    the cutting samples (:meth:`contour_stats`). With ``plan_checked(...,
    keep_reference=True)`` also the ``reference`` points it checked
    (:class:`~nurbscnc.plan.timing.Reference`), the predicted servo ``response`` to them and
    ``cutting`` (M,), which response samples are cutting (not on a rapid; the held tail
    after the end counts as the last piece); else these three are None."""

    reference: Reference | None
    response: Response | None
    cutting: np.ndarray | None
    overs: Overs | None = None
    stats: dict | None = None
    #: The compact form of the program's own samples (``overs`` without the held tail a cut
    #: window's check adds, :func:`~nurbscnc.plan.lookahead.plan_windows`; else
    #: ``overs``): what joins windows.
    samples: Overs | None = None
    #: Cutting samples the statistics are over (joining windows).
    cut_samples: int = 0

    def contour_um(self) -> np.ndarray:
        """The true contour error [µm] of the cutting samples (needs the kept response)."""
        if self.response is None:
            raise ValueError("the check kept no per-sample response (keep_reference=False)")
        return self.response.contour_mm[self.cutting] * 1000.0

    def contour_stats(self) -> dict:
        """The check's contour error of the cutting samples [µm] (the feed samples of
        :mod:`nurbscnc.plan.scope`): ``contour_true_max_um``, ``contour_true_rms_um`` (true
        distance to the path) and ``contour_eq29_max_um`` (|ε| of SPEC eq. 29), 0 when nothing
        is cut; and ``contour_rapids_true_max_um``, the largest true distance of the other
        samples (rapids and the settle wait after one; no guarantee), 0 when there are none.
        The summaries use only these; a check that keeps no per-sample arrays gives the same
        numbers from its running statistics (the rms summed window by window: equal to
        rounding), and ``contour_bounded_samples``: how many cutting samples' errors were
        not measured but bounded (the risk skip of :class:`~nurbscnc.plan.check.Checker`:
        the tracking error bounds them, and it is below the largest measured error, so the
        maximum is exact; the rms counts them at their bound, an upper bound then);
        ``contour_corner_max_um`` and ``contour_corner_samples``: the samples over ε_max a
        corner's allowance took (:meth:`Accumulator.corner_stats`)."""
        if self.response is None:
            return dict(self.stats)
        corner = {k: v for k, v in (self.stats or {}).items() if k.startswith("contour_corner_")}
        c = self.contour_um()
        eq29 = np.abs(self.response.contour_eq29_mm[self.cutting]) * 1000.0
        rapids = self.response.contour_mm[~self.cutting] * 1000.0
        return {
            "contour_true_max_um": float(c.max()) if c.size else 0.0,
            "contour_true_rms_um": float(np.sqrt(np.mean(c * c))) if c.size else 0.0,
            "contour_eq29_max_um": float(eq29.max()) if c.size else 0.0,
            "contour_rapids_true_max_um": float(rapids.max()) if rapids.size else 0.0,
            "contour_bounded_samples": 0,
            **corner,
        }


class Accumulator:
    """The running results of one check (:class:`Checker`): over-limit samples, piece
    runs, settle counts and contour statistics (:class:`Overs`)."""

    def __init__(self, checker, profile: Profile):
        self.eps_mm = checker.eps_mm
        # The corner allowances (:mod:`nurbscnc.plan.allowance`): what a sample may use
        # beyond ε_max near a G64 vertex; none on rapids nor the settle after one.
        self.allowance = checker.allowance
        self.rapid, self.after_rapid = checker.rapid, checker.after_rapid
        self.piece_start_s = profile.piece_start_time_s
        self.corner_max = 0.0  # [µm] the largest contour error a corner's allowance took
        self.corner_n = 0  # samples over ε_max within a corner's allowance
        self.t_restart = profile.piece_start_time_s[checker.settle_rows + 1]
        self.count = 0
        self.over: list = []  # (index, err, tau) per window
        self.runs: list = []  # (run piece, run start) per window
        self.last_piece = -1
        self.restart = np.zeros(checker.settle_rows.size, dtype=np.int64)
        self.worst = 0.0
        self.c_max = self.c_sq = self.eq29_max = 0.0
        self.rapids_max = 0.0  # [µm] the samples the guarantee does not cover (plan.scope)
        self.c_n = 0
        self.bounded = 0  # cutting samples whose error is a bound (not measured)
        self.real = None  # (count, worst, restart, over count, run count) before a virtual tail

    def add(
        self,
        resp: Response,
        cutting: np.ndarray,
        tau_s: np.ndarray,
        piece: np.ndarray,
        virtual: bool = False,
        measured: np.ndarray | None = None,
        corner=True,
    ):
        """The next samples: their response, which are checked (``cutting``), profile times
        [s] and pieces. ``virtual``: the held tail of a cut window that the program does not
        end with: it counts for the window's decisions, not in its statistics nor in
        :attr:`Check.samples`. ``measured``: which contour errors were measured (None: all;
        the others are bounds). ``corner`` (bool or (n,)): which samples may use a corner's
        allowance (not the held tail after the program's end). The over-limit samples and
        the worst error are those of the effective error (:meth:`effective_mm`)."""
        if virtual and self.real is None:
            self.real = (
                self.count,
                self.worst,
                self.restart.copy(),
                len(self.over),
                len(self.runs),
            )
        err = np.where(cutting, resp.contour_mm, 0.0)
        if self.allowance is not None:
            contour = err
            err = self.effective_mm(err, resp.actual_mm, piece, tau_s, corner)
            if not virtual:
                took = np.flatnonzero((contour > self.eps_mm) & (err <= self.eps_mm))
                if took.size:
                    self.corner_max = max(self.corner_max, float(contour[took].max()) * 1e3)
                    self.corner_n += int(took.size)
            del contour
        over = np.flatnonzero(err > self.eps_mm)
        self.over.append((over + self.count, err[over], tau_s[over]))
        self.worst = max(self.worst, float(err.max()))
        del err
        starts = np.flatnonzero(np.diff(piece, prepend=self.last_piece) != 0)
        self.runs.append((piece[starts], starts + self.count))
        self.last_piece = int(piece[-1])
        self.restart += np.searchsorted(tau_s, self.t_restart, side="right")
        c = resp.contour_mm[cutting] * 1000.0 if not virtual else np.zeros(0)
        if c.size:
            self.c_max = max(self.c_max, float(c.max()))
            self.c_sq += float(np.dot(c, c))
            self.c_n += c.size
            if measured is not None:
                self.bounded += int(np.count_nonzero(cutting & ~measured))
            self.eq29_max = max(
                self.eq29_max, float(np.abs(resp.contour_eq29_mm[cutting]).max()) * 1000.0
            )
        if not virtual and not cutting.all():
            self.rapids_max = max(self.rapids_max, float(resp.contour_mm[~cutting].max()) * 1e3)
        self.count += cutting.size

    def effective_mm(self, err_mm, actual_mm, piece, tau_s, corner=True) -> np.ndarray:
        """The effective errors [mm] of samples whose checked contour errors are ``err_mm``
        (n,) (:meth:`~nurbscnc.plan.allowance.CornerAllowance.effective_mm`: within ε_max
        of the planned path, or within ε_max + P of a G64 vertex), the tool at
        ``actual_mm`` (n, 3), the reference on pieces ``piece`` at profile times ``tau_s``
        [s]; ``corner`` (bool or (n,)): which may use an allowance at all. No allowance on
        a rapid's samples nor on the settle wait after one (the cut's first piece, until
        its start time)."""
        if self.allowance is None:
            return err_mm
        i = np.flatnonzero(err_mm > self.eps_mm)
        if i.size == 0:
            return err_mm
        p = piece[i]
        ok = ~self.rapid[p] & ~(self.after_rapid[p] & (tau_s[i] <= self.piece_start_s[p]))
        ok &= np.broadcast_to(np.asarray(corner, dtype=bool), err_mm.shape)[i]
        i = i[ok]
        if i.size == 0:
            return err_mm
        out = np.array(err_mm, dtype=float, copy=True)
        out[i] = self.allowance.effective_mm(out[i], actual_mm[i], piece[i], self.eps_mm)
        return out

    #: The accumulator's scalars, as :meth:`state` keeps them after the lists.
    SCALARS = (
        "worst",
        "c_max",
        "c_sq",
        "eq29_max",
        "rapids_max",
        "c_n",
        "bounded",
        "corner_max",
        "corner_n",
        "real",
    )

    def state(self) -> tuple:
        """Everything :meth:`add` has gathered so far (the per-window arrays shared, not
        copied): what :meth:`restore` puts back, to resume a check after a prefix of its
        windows whose samples a re-plan left alike (:class:`~nurbscnc.plan.check.Checker`)."""
        lists = (self.count, list(self.over), list(self.runs), self.last_piece)
        return (*lists, self.restart.copy(), *(getattr(self, k) for k in self.SCALARS))

    def restore(self, state: tuple) -> None:
        """Back to a :meth:`state` (its lists and counts copied: the state stays reusable)."""
        (self.count, over, runs, self.last_piece, restart, *rest) = state
        self.over, self.runs, self.restart = list(over), list(runs), restart.copy()
        for key, value in zip(self.SCALARS, rest, strict=True):
            setattr(self, key, value)

    def corner_stats(self) -> dict:
        """``contour_corner_max_um``: the largest contour error to the planned path [µm] of
        a cutting sample a corner's allowance took (over ε_max, within ε_max + P of a G64
        vertex; 0: none), ``contour_corner_samples``: how many (:mod:`nurbscnc.plan.allowance`)."""
        return {"contour_corner_max_um": self.corner_max, "contour_corner_samples": self.corner_n}

    def check(self) -> Check:
        """The :class:`Check` of everything added (no per-sample arrays)."""
        idx, err, tau = (np.concatenate(x) for x in zip(*self.over))
        piece, start = (np.concatenate(x) for x in zip(*self.runs))
        overs = Overs(self.count, idx, err, tau, piece, start, self.restart, self.worst)
        rms = float(np.sqrt(self.c_sq / self.c_n)) if self.c_n else 0.0
        stats = {
            "contour_true_max_um": self.c_max,
            "contour_true_rms_um": rms,
            "contour_eq29_max_um": self.eq29_max,
            "contour_rapids_true_max_um": self.rapids_max,
            "contour_bounded_samples": self.bounded,
            **self.corner_stats(),
        }
        samples = overs
        if self.real is not None:
            count, worst, restart, n_over, n_runs = self.real
            i, e, t = (np.concatenate(x) for x in zip(*self.over[:n_over]))
            rp, rs = (np.concatenate(x) for x in zip(*self.runs[:n_runs]))
            samples = Overs(count, i, e, t, rp, rs, restart, worst)
        return Check(None, None, None, overs, stats, samples, self.c_n)


class JoinedChecks:
    """The compact :class:`Check` of a program's cut windows, joined as they come, their
    samples one after the other (:attr:`Check.samples`: without the held tails of the
    windows' checks): over-limit samples, piece runs, counts before each restart and
    statistics. No window's check is kept: each holds counts for every restart of the
    program (one per rapid), so keeping them all would grow as cuts × rapids; the counts
    are summed as they come."""

    def __init__(self):
        self.parts: list = []  # per window: (index, err, tau, run piece, run start, count)
        self.restart = None
        self.worst = 0.0
        self.n: list = []
        self.stats: list = []

    def add(self, check: Check) -> None:
        o = check.samples
        self.parts.append((o.index, o.err_mm, o.tau_s, o.run_piece, o.run_start, o.count))
        if self.restart is None:
            self.restart = np.array(o.restart_count, dtype=np.int64)
        else:
            self.restart += o.restart_count
        self.worst = max(self.worst, o.worst_mm)
        self.n.append(check.cut_samples)
        self.stats.append(check.stats)

    def check(self) -> Check:
        off = np.cumsum([0] + [p[5] for p in self.parts])
        cat = np.concatenate
        overs = Overs(
            int(off[-1]),
            cat([p[0] + d for p, d in zip(self.parts, off)]),
            cat([p[1] for p in self.parts]),
            cat([p[2] for p in self.parts]),
            cat([p[3] for p in self.parts]),
            cat([p[4] + d for p, d in zip(self.parts, off)]),
            self.restart,
            self.worst,
        )
        total = sum(self.n)
        stats = self.stats
        rms = (
            float(
                np.sqrt(
                    sum(s["contour_true_rms_um"] ** 2 * m for s, m in zip(stats, self.n)) / total
                )
            )
            if total
            else 0.0
        )
        joined = {
            "contour_true_max_um": max(s["contour_true_max_um"] for s in stats),
            "contour_true_rms_um": rms,
            "contour_eq29_max_um": max(s["contour_eq29_max_um"] for s in stats),
            "contour_rapids_true_max_um": max(s["contour_rapids_true_max_um"] for s in stats),
            "contour_bounded_samples": sum(s["contour_bounded_samples"] for s in stats),
            "contour_corner_max_um": max(s["contour_corner_max_um"] for s in stats),
            "contour_corner_samples": sum(s["contour_corner_samples"] for s in stats),
        }
        return Check(None, None, None, overs, joined, overs, total)
