"""The look-ahead planner: pieces → jerk-limited profile → dynamics check → re-plan.

SPEC §7–§8 and §10. The profile is planned over the whole program (bidirectional scan) with
per-piece limits (:func:`~nurbscnc.plan.axes.piece_limits`: the axes' feed, acceleration and
jerk along each piece); the predicted contour error is then checked with the servo model,
and where it exceeds ε_max the plan is changed and re-planned until the error is within it.

Local shaping (``dynamics="local"``, planner v2, issue 13). Each over-limit sample is
answered where its error is caused, never by the cruise of a whole long piece:

- near the end of a rapid that a cut follows: the settle there (the reference waits at the
  cut's start; 0 until the check needs it, at most 5/|pole| :func:`settle_time_s`); while it
  waits nothing is checked, and the first cut samples are measured against the cut only;
- near a planned stop (from :data:`STOP_BEFORE_S` before to :data:`STOP_WINDOW_S` after
  it): the overshoot of the stop and the corner cut after it. The descent jerk of the run
  of pieces that ends there (and, for samples after the restart, the rise jerk of the run
  that leaves it) is lowered, by 0.95 (ε/e)^(1/p) with p measured from the last try (the
  jerk at the end of a stop is what excites the servo: a softer stop costs milliseconds),
  from at most A·|p| (:func:`_servo_jerk`: a larger jerk is a step to the servo). Where
  that hardly moves the error (:data:`STOP_INEFFECTIVE_P`), the descent's and rise's
  acceleration is lowered with the jerk; only where that fails too does the feed lever
  below take the stop's samples (a 56.6 mm helix of tort.ngc stopping into another plane,
  LinuxCNC's limits: F348 over the whole helix before, 2.96 s; now F500 and a softer stop).
  The same holds for a *slowdown* between two long pieces (:func:`_slowdowns`: a feed drop
  at a junction passed without stopping, each side ≥ :data:`SLOWDOWN_PIECE_S` of motion):
  its error is the transition's, not the cruise of the long piece before it;
- else (a curve): the feed of the pieces in the blamed window (:func:`_blame`,
  :func:`local_factors`): NURBS cells and PH corners are short, so this is the feed over
  that window only. A blamed piece whose jerk is above A·|p| gets that jerk first. A piece
  whose lowered feed twice in a row hardly moved the error is no
  feed lever (a short piece crossed in transition, a ringing servo's error from further
  back): its acceleration and jerk are lowered instead, and the samples near it blame the
  servo's whole memory.

The check converges on every program: after :data:`LOCAL_ITERATIONS` re-plans a fallback
scales every lever (feed, acceleration, jerk) of the blamed pieces, then of all cutting
pieces, and waits the full settles; the servo error goes to 0 with v, a, j. Once a plan is
within ε_max, an improvement phase bisects every shaped lever between its feasible value and
its value before shaping (:data:`IMPROVE_ITERATIONS` re-plans), then tries the feed caps
with the most time to gain alone at that value (:data:`RESTORE_PIECES` re-plans: a joint try
fails on any one lever; a failed restore is shaped again, its stops starting afresh from
their transitions, :data:`RESHAPE_ITERATIONS`), and keeps the fastest plan within ε_max —
when it may gain more than :data:`IMPROVE_MIN_GAIN` of the motion's time (it cannot gain
more than the shaping cost: a long program shaped at a few corners skips six checks for a
few ms). Shaping depends on the programmed feed only through the caps; the bisection leaves
each lever within :data:`IMPROVE_RATIO` of its bound, so plans at two feeds agree to that
resolution (a higher F is never slower by more than it, or than the skipped improvement's
0.03 %: tested on the paper's machine; with bench/programs/linuxcnc_limits.toml, J = 1e9
and no Z servo model, a 4-move program was found 7.8 % slower at F2960 than at F2822: the
shaping is path-dependent).

``dynamics="global"`` is the paper's rule (V_max becomes the feed where the error occurred,
the whole program re-planned; full settles); ``"off"`` plans the kinematics only (no
settles: nothing is checked).

Long programs. Everything per piece is whole-array work on the columns of the
:class:`~nurbscnc.plan.pieces.PieceList` (junctions, dwells, blame), the contour error is
measured near each reference point only (:func:`~nurbscnc.plan.dynamics.path_response`), and
a local re-plan changes the levers of all offending pieces at once, so a program needs a
few iterations, whatever its length. The check runs :data:`CHECK_WINDOW` servo samples at a
time with the servo state carried (:class:`_Checker`, issue 14) and keeps only the
over-limit samples, the piece of every sample run-length coded and running statistics
(:class:`Overs`): its memory grows with the pieces, not with the motion time, and the plan
is the one the whole-array check gives (``plan_checked(..., keep_reference=True)`` keeps the
whole reference and response for plots and reports). Runs of tiny tangent-continuous
pieces at one cap and one set of limits are planned as one by
:func:`~nurbscnc.plan.profile.plan_profile`.
"""
from __future__ import annotations

import functools
import inspect
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace

import numpy as np

from nurbscnc.errors import PlanningError
from nurbscnc.geometry.distance import PathIndex
from nurbscnc.machine.profile import Machine
from nurbscnc.plan.axes import piece_limits
from nurbscnc.plan.dynamics import (
    Response,
    path_response,
    window_response,
)
from nurbscnc.plan.junctions import junction_caps, settle_time_s
from nurbscnc.plan.limits import check_point_count
from nurbscnc.plan.options import Dynamics, LookaheadOptions
from nurbscnc.plan.pieces import PieceList
from nurbscnc.plan.profile import Profile, ProfileInput, same_until_s
from nurbscnc.plan.profile_plan import plan_profile
from nurbscnc.plan.program_pieces import segment_pieces
from nurbscnc.plan.timing import (
    Reference,
    dwell_times,
    exact_reference,
    same_clock_until_s,
    sample_count,
    total_time_s,
)
from nurbscnc.servo.model import AxesStream

#: Plan to this fraction of ε_max so the prediction has a little room (model, rounding).
CONTOUR_MARGIN = 0.99
#: Samples before an over-limit sample whose pieces share the blame (servo memory ≈ 30 ms).
BLAME_WINDOW_S = 0.03
#: An over-limit sample belongs to a stop planned at most this long after it [s] (profile
#: time; the approach) ...
STOP_BEFORE_S = 0.02
#: ... or at most this long before it [s] (the overshoot and the corner cut after it).
STOP_WINDOW_S = 0.03
#: A stop whose error fell as (jerk factor)^p with p below this is no jerk lever: its
#: acceleration is softened with its jerk from then on; if that too moves the error less,
#: it is not softened again (the feed lever takes it).
STOP_INEFFECTIVE_P = 0.2
FEED_ONLY = ("feed",)
#: Re-plans with the local levers before the fallback takes over.
LOCAL_ITERATIONS = 16
#: Fallback re-plans on the blamed pieces before all cutting pieces are scaled.
FALLBACK_LOCAL_ITERATIONS = 8
#: Factor of every lever per fallback re-plan.
FALLBACK_FACTOR = 0.6
#: Re-plans of the improvement phase (bisection of the shaped levers).
IMPROVE_ITERATIONS = 6
#: Then, at most this many feed caps tried alone at their upper brackets, the largest time
#: gains first (:func:`_improve`): under LinuxCNC's limits tort's joint tries all failed on
#: a junction's error while a 17 mm helix kept half its feed (4.6 s) though restoring it
#: alone stayed within ε_max.
RESTORE_PIECES = 3
#: A restore that fails is shaped again, at most this many re-plans, if it gains at least
#: :data:`RESHAPE_MIN_GAIN_S` [s]: the feed lever had taken a stop whose transition (jerk,
#: then acceleration) was never tried with this cap. Under LinuxCNC's limits the rows of
#: cds.ngc's pocket kept F16 (6.77 mm/s) instead of 5.5 mm/s, 2.9 s of its 703 s; on the
#: paper's machine no plan changed.
RESHAPE_ITERATIONS = 3
RESHAPE_MIN_GAIN_S = 0.02
#: Then, if the restore still fails, at most this many re-plans of that cap alone between
#: the plan's and the restore's (false position on the error).
RESTORE_SECANTS = 3
#: The improvement phase runs only if it may gain more than this fraction of the planned
#: motion's time (a cut window's own): what it can gain is at most the time the shaping
#: cost (the plan before shaping is the fastest its levers allow). A long program whose
#: shaping touched a few corners gains a few ms of minutes from it, for six more checks
#: (CAM spirals: 1.9e-4 of 372 s, 3.9e-5 of 1871 s). At 1e-3, tort.ngc's windows (bounds
#: of 3e-4 to 1e-3 each) lost 0.58 s of 563 s under LinuxCNC's limits; at 3e-4 none.
IMPROVE_MIN_GAIN = 3e-4
#: A lever within this ratio of its bracket's upper end is left alone.
IMPROVE_RATIO = 1.005
#: Servo samples per window of the dynamics check: its memory grows with this, not with
#: the motion time (issue 14).
CHECK_WINDOW = 1 << 16
#: Over-limit samples per block of the blame computation.
BLAME_BLOCK = 1 << 12


@dataclass(frozen=True, eq=False)
class Limits:
    """Acceleration [mm/s²] and jerk [mm/s³] limits of each of k pieces, (k,) each: for the
    rise to its peak speed (``up``) and the descent from it (``down``)."""

    a_up_mm_s2: np.ndarray
    j_up_mm_s3: np.ndarray
    a_down_mm_s2: np.ndarray
    j_down_mm_s3: np.ndarray

    def tail(self, first: int) -> Limits:
        """The limits of pieces ``first`` … k − 1."""
        return Limits(self.a_up_mm_s2[first:], self.j_up_mm_s3[first:],
                      self.a_down_mm_s2[first:], self.j_down_mm_s3[first:])  # fmt: skip


@dataclass(frozen=True, eq=False)
class Plan:
    """A complete plan: pieces (with the settles in their dwells), their final caps [mm/s],
    the profile; ``iterations``: re-plans of the dynamics loop (improvement included);
    ``cycle_time_s`` including dwells; the ``dynamics`` rule it was checked with. The
    reference points come from the interpolator
    (:func:`nurbscnc.interpolate.sample.interpolate`), the check's result from
    :func:`plan_checked`."""

    pieces: PieceList
    caps_mm_s: np.ndarray
    profile: Profile
    iterations: int
    cycle_time_s: float
    dynamics: Dynamics
    #: The per-piece acceleration and jerk limits the profile was planned with (the axes'
    #: path limits, lowered where the contour check shaped a transition).
    limits: Limits | None = None
    #: (k,) bool: the contour check changed this piece (its feed cap or a limit is below
    #: the kinematic plan's) — a "contour error" limiting factor.
    shaped_by_contour: np.ndarray | None = None
    #: (k,) bool: the check lowered this piece's feed cap (curve error).
    contour_feed: np.ndarray | None = None
    #: (k,) bool: the check softened this piece's rise or descent (stop overshoot).
    contour_transition: np.ndarray | None = None
    #: (k,) settle [s] waited after piece i (a rapid followed by a cut), set by the check;
    #: included in ``pieces.dwell_after_s``.
    settle_s: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class Overs:
    """What the shaping rules need of one check, in memory that grows with the pieces and
    the over-limit samples, never with the motion time (issue 14): ``count`` M checked
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
    #: window's check adds, :func:`plan_windows`; else ``overs``): what joins windows.
    samples: Overs | None = None
    #: Cutting samples the statistics are over (joining windows).
    cut_samples: int = 0

    def contour_um(self) -> np.ndarray:
        """The true contour error [µm] of the cutting samples (needs the kept response)."""
        if self.response is None:
            raise ValueError("the check kept no per-sample response (keep_reference=False)")
        return self.response.contour_mm[self.cutting] * 1000.0

    def contour_stats(self) -> dict:
        """The check's contour error of the cutting samples [µm]: ``contour_true_max_um``,
        ``contour_true_rms_um`` (true distance to the path) and ``contour_eq29_max_um`` (|ε|
        of SPEC eq. 29); 0 when nothing is cut. The summaries use only these; a check that
        keeps no per-sample arrays gives the same numbers from its running statistics (the
        rms summed window by window: equal to rounding)."""
        if self.response is None:
            return dict(self.stats)
        c = self.contour_um()
        eq29 = np.abs(self.response.contour_eq29_mm[self.cutting]) * 1000.0
        if not c.size:
            return {"contour_true_max_um": 0.0, "contour_true_rms_um": 0.0,
                    "contour_eq29_max_um": 0.0}  # fmt: skip
        return {"contour_true_max_um": float(c.max()),
                "contour_true_rms_um": float(np.sqrt(np.mean(c * c))),
                "contour_eq29_max_um": float(eq29.max())}  # fmt: skip


def profile_over(length_mm: np.ndarray, caps: np.ndarray, smooth: np.ndarray,
                 limits: Limits, window: int | None) -> Profile:  # fmt: skip
    """The jerk-limited profile (SPEC §7) over pieces of ``length_mm`` with cruise caps
    ``caps`` [mm/s], the junctions ``smooth`` (k+1; > 0: tangent-continuous, capped by it and
    the smaller neighbour; the ends are rests) and the per-piece acceleration and jerk
    ``limits``. The planner's profile, and the stream's re-plan of a plan's rest after a
    feed hold (the same pieces from one on, same caps and limits)."""
    k = caps.size
    jcaps = np.zeros(k + 1)
    jcaps[1:-1] = np.where(smooth[1:-1] > 0, np.minimum(np.minimum(caps[:-1], caps[1:]),
                                                        smooth[1:-1]), 0.0)  # fmt: skip
    return plan_profile(ProfileInput(length_mm, caps, jcaps, limits.a_up_mm_s2,
                                     limits.j_up_mm_s3, lookahead_pieces=window,
                                     a_decel_mm_s2=limits.a_down_mm_s2,
                                     j_decel_mm_s3=limits.j_down_mm_s3))  # fmt: skip


def _blame(ov: Overs, sel: np.ndarray, eps_mm: float, joined: np.ndarray,
           window) -> np.ndarray:  # fmt: skip
    """Largest over-limit error [mm] each piece shares the blame for (0: none).

    An over-limit sample (``ov``: those of ``sel`` (q,) bool with error above ``eps_mm``)
    blames the pieces of the ``window`` samples (an int, or one per sample of ``ov``) up to
    it (the servo remembers): sample i
    blames every piece with a sample in [i − window, i], i.e. the runs of
    ``ov.run_start`` from the one holding max(i − window, 0) to the one holding i; each
    piece keeps the largest. Blamed pieces that the profile plans as one (``joined``
    (k−1,): tangent-continuous junction, equal caps) share their largest blame, so their
    caps stay equal and they stay one profile unit (a run of tiny CAM pieces lowered piece
    by piece to slightly different caps would crawl)."""
    k = joined.size + 1
    keep = sel & (ov.err_mm > eps_mm)
    idx, err = ov.index[keep], ov.err_mm[keep]
    win = np.broadcast_to(window, ov.index.shape)[keep]
    blame_run = np.zeros(ov.run_start.size)
    for lo in range(0, idx.size, BLAME_BLOCK):  # (block × window) temporaries at most
        i, e = idx[lo : lo + BLAME_BLOCK], err[lo : lo + BLAME_BLOCK]
        w = win[lo : lo + BLAME_BLOCK]
        r_lo = np.searchsorted(ov.run_start, np.maximum(i - w, 0), side="right") - 1
        span = np.searchsorted(ov.run_start, i, side="right") - r_lo
        rows = np.repeat(np.arange(i.size), span)
        runs = r_lo[rows] + np.arange(rows.size) - np.repeat(np.cumsum(span) - span, span)
        np.maximum.at(blame_run, runs, e[rows])
    blame = np.zeros(k)
    np.maximum.at(blame, ov.run_piece, blame_run)
    hit = blame > 0.0
    link = hit[:-1] & hit[1:] & joined
    if link.any():
        run = np.concatenate(([0], np.cumsum(~link)))  # run label of each piece
        run_max = np.zeros(int(run[-1]) + 1)
        np.maximum.at(run_max, run, blame)
        blame = np.where(hit, run_max[run], 0.0)
    return blame


#: Re-plans in a row in which lowering a piece's feed hardly moved its error before the
#: curve lever leaves its feed alone (a single one is common: the over-limit samples move
#: as the braking moves).
CURVE_STRIKES = 2


def _curve_windows(ov: Overs, ineffective: np.ndarray, narrow: int, wide: int) -> np.ndarray:
    """Blame window [samples] (q,) of each over-limit sample of ``ov``: ``wide`` where the
    ``narrow`` window up to it holds a piece flagged ``ineffective`` (k,) (its feed was
    lowered without effect: the cause lies further back in the servo's memory), else
    ``narrow``."""
    i = ov.index
    if not ineffective.any():
        return np.full(i.size, narrow)
    flagged = np.concatenate(([0], np.cumsum(ineffective[ov.run_piece])))
    r_lo = np.searchsorted(ov.run_start, np.maximum(i - narrow, 0), side="right") - 1
    r_hi = np.searchsorted(ov.run_start, i, side="right") - 1
    return np.where(flagged[r_hi + 1] > flagged[r_lo], wide, narrow)


def local_factors(blame: np.ndarray, eps_mm: float, history=None):
    """Cap factors (k,) of a local re-plan, the history for the next one, and which pieces
    were lowered without effect (k,) bool.

    Every offending piece (``blame`` > 0: the error [mm] it shares) is lowered at once, by
    f = 0.97 (ε/e)^(1/p), clipped to [0.5, 0.97]. The exponent p of error ∝ V^p is 2 for a
    piece hit for the first time (the normal acceleration V²κ drives the servo lag), and is
    measured for a piece hit again, from its last factor and how much its error fell:
    p = ln(e/e_prev) / ln(f_prev), kept in [0.25, 2]. Errors that depend on the feed weakly
    (the overshoot of an exact stop grows with the deceleration, not with V²) thus get a
    strong correction at the second try instead of 3 % per re-plan. A piece whose error
    fell with p below :data:`STOP_INEFFECTIVE_P` in :data:`CURVE_STRIKES` re-plans in a row
    is not the cause (a ringing servo's error from further back): it is reported, not
    lowered (halving it at every re-plan took a 20 Hz servo's program from 46 s to 10 h).
    """
    hit = blame > 0.0
    p = np.full(blame.size, 2.0)
    strikes = np.zeros(blame.size, dtype=np.int8)
    if history is not None:
        prev_blame, prev_factor, prev_strikes = history
        again = hit & (prev_blame > 0.0) & (prev_factor < 1.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            measured = np.log(blame / prev_blame) / np.log(prev_factor)
        known = again & np.isfinite(measured)
        weak = known & (measured < STOP_INEFFECTIVE_P)
        strikes = np.where(weak, np.minimum(prev_strikes, CURVE_STRIKES) + 1, 0).astype(np.int8)
        p = np.where(known, np.clip(measured, 0.25, 2.0), p)
    ineffective = strikes >= CURVE_STRIKES
    ratio = eps_mm / np.where(hit, blame, eps_mm)
    factor = np.where(hit & ~ineffective, np.clip(0.97 * ratio ** (1.0 / p), 0.5, 0.97), 1.0)
    return factor, (blame, factor, strikes), ineffective


def plan_program(program, machine: Machine, options: LookaheadOptions | None = None) -> Plan:
    """Plan a whole interpreted program (SPEC §1: modules 1–4); :func:`plan_checked` without
    the check's result."""
    return plan_checked(program, machine, options)[0]


def _with_dwell(pieces: PieceList, dwell_s: np.ndarray) -> PieceList:
    """``pieces`` with the dwell column ``dwell_s`` (k,) [s]; the path model, independent
    of dwells, built once on ``pieces`` and shared (not rebuilt per re-plan: the check's
    kept polyline knows it by identity)."""
    out = replace(pieces, dwell_after_s=dwell_s)
    out.__dict__["path"] = pieces.path
    return out


@dataclass
class _Levers:
    """What the contour check may change, per piece (k,): the cruise ``caps`` [mm/s], the
    rise and descent limits, the settle dwell after each rapid [s] and which pieces were
    changed (``shaped``); ``history`` of the last factors, for the measured exponents."""

    caps: np.ndarray
    a_up: np.ndarray
    j_up: np.ndarray
    a_dn: np.ndarray
    j_dn: np.ndarray
    settle_s: np.ndarray
    shaped: np.ndarray
    #: Pieces whose feed the curve lever lowered without effect (:func:`local_factors`):
    #: not lowered by it again, and the over-limit samples near them blame the servo's
    #: whole memory (:data:`BLAME_WINDOW_S`) instead of :data:`CURVE_BLAME_WINDOW_S`.
    ineffective: np.ndarray
    cap_history: tuple | None = None
    stop_history: dict | None = None

    def limits(self) -> Limits:
        return Limits(self.a_up, self.j_up, self.a_dn, self.j_dn)

    _SCALED = ("caps", "a_up", "j_up", "a_dn", "j_dn")

    def copy(self) -> _Levers:
        return _Levers(*(getattr(self, f).copy() for f in (*self._SCALED, "settle_s",
                                                           "shaped", "ineffective")),
                       self.cap_history, self.stop_history)  # fmt: skip

    def toward(self, hi: _Levers) -> _Levers | None:
        """Halfway to ``hi`` (geometric means of the scaled levers, arithmetic of the
        settles); None when every lever is within 0.5 % of it."""
        out = self.copy()
        moved = False
        for f in self._SCALED:
            a, b = getattr(self, f), getattr(hi, f)
            far = b > a * IMPROVE_RATIO
            if far.any():
                moved = True
                getattr(out, f)[far] = np.sqrt(a[far] * b[far])
        far = self.settle_s > hi.settle_s + 1e-4
        if far.any():
            moved = True
            out.settle_s[far] = 0.5 * (self.settle_s[far] + hi.settle_s[far])
        return out if moved else None

    def narrowed(self, trial: _Levers, probe: _Levers) -> _Levers:
        """These upper brackets with the levers that ``probe`` (the shaping rule applied
        to ``trial``) lowered set to their ``trial`` values (infeasible there); when the
        rule blames none, every tried lever."""
        out = self.copy()
        blamed = {f: getattr(probe, f) < getattr(trial, f) for f in self._SCALED}
        blamed_settle = probe.settle_s > trial.settle_s
        if not (any(b.any() for b in blamed.values()) or blamed_settle.any()):
            blamed = {f: np.ones(trial.caps.size, dtype=bool) for f in self._SCALED}
            blamed_settle = np.ones(trial.caps.size, dtype=bool)
        for f, b in blamed.items():
            getattr(out, f)[b] = getattr(trial, f)[b]
        out.settle_s[blamed_settle] = trial.settle_s[blamed_settle]
        return out


def _runs(caps: np.ndarray, smooth: np.ndarray, lev: _Levers) -> np.ndarray:
    """Run label (k,) of each piece: the pieces the profile plans as one unit (tangent-
    continuous junctions, equal caps and equal limits; see :func:`plan_profile`)."""
    joined = (smooth[1:-1] > 0) & (caps[:-1] == caps[1:])
    for x in (lev.a_up, lev.j_up, lev.a_dn, lev.j_dn):
        joined &= x[:-1] == x[1:]
    return np.concatenate(([0], np.cumsum(~joined)))


def _stop_events(tau_s: np.ndarray, profile: Profile, period_s: float):
    """For over-limit samples at profile times ``tau_s`` [s], the stop junction each is near
    (−1: none): a junction planned at rest, or a slowdown between long pieces
    (:func:`_slowdowns`), whose profile time τ_j has
    τ_j − :data:`STOP_BEFORE_S` ≤ τ ≤ τ_j + :data:`STOP_WINDOW_S` (the overshoot of a stop
    and the corner cut while the servo still settles from it; during a dwell τ = τ_j)."""
    v = profile.junction_speeds_mm_s
    k = v.size - 1
    stops = np.flatnonzero(v == 0.0)
    stops = stops[stops > 0]  # the start at rest is no stop to soften
    stops = np.union1d(stops, _slowdowns(profile))
    t_stop = np.append(profile.piece_start_time_s, profile.duration_s)[stops]
    tau = tau_s
    if stops.size == 0:
        return np.full(tau.size, -1)
    # The first stop at or after τ − window, if it is not later than τ + before.
    i = np.searchsorted(t_stop, tau - STOP_WINDOW_S - 0.5 * period_s, side="left")
    i = np.minimum(i, stops.size - 1)
    near = (stops.size > 0) & (t_stop[i] <= tau + STOP_BEFORE_S)
    near &= t_stop[i] >= tau - STOP_WINDOW_S - 0.5 * period_s
    return np.where(near, np.minimum(stops[i], k), -1)


#: The pieces on both sides of a slowdown junction (:func:`_slowdowns`) take at least this
#: many seconds of motion each: far longer than the servo's memory (:data:`BLAME_WINDOW_S`),
#: so either feed is the cruise of a whole long piece, which the check must not lower for
#: an error made at its end. (A short piece beside it, a corner's blend, keeps the feed
#: lever: there the error is the blend's curvature, and softening the long piece's descent
#: instead made the paper machine's plunged squares 0.5 % slower.)
SLOWDOWN_PIECE_S = 0.1
#: ... and the speed changes there by more than this factor.
SLOWDOWN_RATIO = 1.05


def _slowdowns(profile: Profile) -> np.ndarray:
    """Junctions (1…k−1) passed without stopping between two long pieces
    (:data:`SLOWDOWN_PIECE_S` each) where the speed changes (:data:`SLOWDOWN_RATIO`): a feed
    drop from an arc into a slow line or plunge. An error made there is the transition's
    (the deceleration on the curve, the step of the curvature at the junction), answered
    like a stop's, by its jerk and then its acceleration, not by the long piece's cruise."""
    v = profile.junction_speeds_mm_s
    peak = profile.piece_peak_speed_mm_s
    dur = profile.piece_duration_s
    j = np.arange(1, v.size - 1)
    long = (dur[j - 1] >= SLOWDOWN_PIECE_S) & (dur[j] >= SLOWDOWN_PIECE_S)
    change = (peak[j - 1] > v[j] * SLOWDOWN_RATIO) | (peak[j] > v[j] * SLOWDOWN_RATIO)
    return j[(v[j] > 0.0) & long & change]


def _settle_extra(lev: _Levers, ov: Overs, near: np.ndarray, profile: Profile,
                  settle_rows: np.ndarray, settle_max_s: float, period_s: float) -> np.ndarray:
    """The settles after rapids (in place): each rapid whose stop transient the over-limit
    samples are near waits longer, past the last of them (plus one period). Returns which
    over-limit samples this answered."""
    over, tau = ov.index, ov.tau_s
    handled = np.zeros(over.size, dtype=bool)
    for i_r, r in enumerate(settle_rows.tolist()):
        hit = near == r + 1
        if not hit.any() or lev.settle_s[r] >= settle_max_s:
            continue
        # Move the restart past the last over-limit sample (plus one period).
        t_restart = profile.piece_start_time_s[r + 1]
        moving = over[hit & (tau > t_restart)]
        extra = period_s
        if moving.size:
            first_moving = int(ov.restart_count[i_r])  # the first sample with τ > restart
            extra = max((int(moving.max()) - first_moving + 2) * period_s, period_s)
        lev.settle_s[r] = min(settle_max_s, lev.settle_s[r] + extra)
        handled |= hit
    return handled


#: Samples before an over-limit sample on a curve whose pieces' feed is lowered [s]: the
#: curve error is quasi-static (the speed and deceleration of the last few milliseconds on
#: that curvature), so the feed is lowered where the error is, and the profile's gated
#: flanks (:func:`~nurbscnc.plan.profile._gated_rise`) brake earlier into the lowered
#: cells at the same A and J; the 30 ms window lowered the cruise of the whole approach.
#: (9 mm NACA 2415 block: 8 ms 0.455 s at 0°, ±45°; 10 ms 0.455–0.459 s; 30 ms 0.462 s.)
CURVE_BLAME_WINDOW_S = 0.008


def _servo_jerk(j_mm_s3: np.ndarray, a_mm_s2: np.ndarray, settle_max_s: float) -> np.ndarray:
    """The jerk [mm/s³] a softening starts from: at most A·|p|, |p| = 5 / ``settle_max_s``
    the slowest servo pole's decay rate [1/s] (:func:`settle_time_s`). A jerk phase shorter
    than the servo's time constant 1/|p| is a step of acceleration to the servo, so lowering
    a larger jerk by a factor changes almost nothing the check sees: with J = 1e9 the stops
    of an arc program were found "ineffective" and its feed crushed instead (16.75 s at
    J = 5e4, 24.4 s at J = 1e9; now 16.72 s). The paper's machine: A·|p| = 2.3e5 > J = 5e4,
    nothing changes."""
    if not np.isfinite(settle_max_s) or settle_max_s <= 0.0:
        return j_mm_s3
    return np.minimum(j_mm_s3, a_mm_s2 * (5.0 / settle_max_s))


def _shape(lev: _Levers, ov: Overs, eps_mm: float, profile: Profile, pieces: PieceList,
           smooth: np.ndarray, settle_rows: np.ndarray, settle_max_s: float,
           period_s: float) -> None:  # fmt: skip
    """One local re-plan (in place) from a check's over-limit samples ``ov``: each is
    answered where its error is caused (module docstring): the settle after a rapid, the
    descent into and the rise out of a stop or a slowdown between long pieces (their jerk,
    then their acceleration), else the feed over the blamed window."""
    k = len(pieces)
    err, tau = ov.err_mm, ov.tau_s
    near = _stop_events(tau, profile, period_s)
    # 1. Settle after a rapid: the rapid's own stop transient, not the cut's motion.
    handled = _settle_extra(lev, ov, near, profile, settle_rows, settle_max_s, period_s)
    # 2. Stops: soften the descent of the run that ends there and, for samples after the
    #    restart, the rise of the run that leaves it.
    runs = _runs(lev.caps, smooth, lev)
    stop_hist = lev.stop_history or {}
    new_hist = {}
    for j in np.unique(near[(near > 0) & ~handled]).tolist():
        hit = (near == j) & ~handled
        e = float(err[hit].max())
        prev = stop_hist.get(j)
        if prev == FEED_ONLY:  # found ineffective before: the feed lever answers it
            new_hist[j] = prev
            continue
        p = 1.0
        accel = prev is not None and prev[2]
        if prev is not None and prev[1] < 1.0 and e > 0.0:
            measured = np.log(e / prev[0]) / np.log(prev[1])
            if np.isfinite(measured):
                if measured < STOP_INEFFECTIVE_P:
                    if accel:
                        # Softening this stop hardly helped: the error is the feed's (a tight
                        # curve into the stop), so the feed lever below takes these samples.
                        new_hist[j] = FEED_ONLY
                        continue
                    accel, measured = True, 1.0  # the jerk was no lever: the acceleration
                p = float(np.clip(measured, 0.25, 2.0))
        f = float(np.clip(0.95 * (eps_mm / e) ** (1.0 / p), 0.3, 0.9))
        new_hist[j] = (e, f, accel)
        if j - 1 >= 0 and not pieces.rapid[j - 1]:
            sel = runs == runs[j - 1]
            lev.j_dn[sel] = _servo_jerk(lev.j_dn[sel], lev.a_dn[sel], settle_max_s) * f
            if accel:
                lev.a_dn[sel] *= f
            lev.shaped |= sel
        t_restart = profile.piece_start_time_s[j] if j < k else np.inf
        if j < k and (tau[hit] > t_restart).any() and not pieces.rapid[j]:
            sel = runs == runs[j]
            lev.j_up[sel] = _servo_jerk(lev.j_up[sel], lev.a_up[sel], settle_max_s) * f
            if accel:
                lev.a_up[sel] *= f
            lev.shaped |= sel
        handled |= hit
    lev.stop_history = new_hist
    # 3. Curves: the feed of the pieces in the blamed window only.
    if not handled.all():
        narrow = max(int(round(CURVE_BLAME_WINDOW_S / period_s)), 1)
        wide = max(int(round(BLAME_WINDOW_S / period_s)), narrow)
        joined = (smooth[1:-1] > 0) & (lev.caps[:-1] == lev.caps[1:])
        history = lev.cap_history
        for _ in range(2):  # once more if pieces were just found ineffective
            window = _curve_windows(ov, lev.ineffective, narrow, wide)
            blame = _blame(ov, ~handled, eps_mm, joined, window)
            factor, lev.cap_history, found = local_factors(blame, eps_mm, history)
            found &= ~lev.ineffective
            lev.ineffective |= found
            if not found.any():
                break
        factor[lev.ineffective] = 1.0
        # A blamed piece whose rise or descent jerk is above what the servo follows (A·|p|,
        # :func:`_servo_jerk`: a step of acceleration to it) gets that jerk first, its feed
        # kept this re-plan (J = 1e9: the line before an arc lost 35 % of its cruise to
        # the step at its end). Never the case on the paper's machine (J < A·|p|).
        blamed = factor < 1.0
        for a_name, j_name in (("a_up", "j_up"), ("a_dn", "j_dn")):
            acc, jerk = getattr(lev, a_name), getattr(lev, j_name)
            servo = _servo_jerk(jerk, acc, settle_max_s)
            soft = blamed & (servo < jerk)
            jerk[soft] = servo[soft]
            factor[soft] = 1.0
            lev.shaped |= soft
        lev.caps *= factor
        lev.shaped |= factor < 1.0
        # Where the feed is no lever (a short piece crossed in transition, the ringing after
        # a stop), the transition is: its acceleration and jerk, by 0.95 ε/e (error ∝ a).
        trans = lev.ineffective & (blame > 0.0)
        if trans.any():
            f_t = np.clip(0.95 * eps_mm / blame[trans], 0.5, 0.9)
            lev.j_up[trans] = _servo_jerk(lev.j_up[trans], lev.a_up[trans], settle_max_s) * f_t
            lev.j_dn[trans] = _servo_jerk(lev.j_dn[trans], lev.a_dn[trans], settle_max_s) * f_t
            lev.a_up[trans] *= f_t
            lev.a_dn[trans] *= f_t
            lev.shaped |= trans


def _fallback(lev: _Levers, ov: Overs, eps_mm: float, pieces: PieceList,
              settle_rows: np.ndarray, settle_max_s: float, period_s: float,
              stage: int) -> None:  # fmt: skip
    """The guaranteed-feasible fallback (in place): every lever of the blamed pieces (stage
    1: within the servo's memory of each over-limit sample of ``ov``; stage 2: all cutting
    pieces) scaled by :data:`FALLBACK_FACTOR` and the settles at their full length. Speed,
    acceleration and jerk → 0 take the servo error → 0, so this ends within ε_max."""
    k = len(pieces)
    f = FALLBACK_FACTOR
    lev.settle_s[settle_rows] = np.maximum(lev.settle_s[settle_rows], settle_max_s)
    if stage == 1:
        window = max(int(round(max(settle_max_s, BLAME_WINDOW_S) / period_s)), 1)
        everything = np.ones(ov.index.size, dtype=bool)
        blame = _blame(ov, everything, eps_mm, np.zeros(k - 1, dtype=bool), window)
        sel = (blame > 0.0) & ~pieces.rapid
    else:
        sel = ~pieces.rapid
    lev.caps[sel] *= f
    for x in (lev.a_up, lev.a_dn, lev.j_up, lev.j_dn):
        x[sel] *= f
    lev.shaped |= sel


def _windowed(sampler) -> bool:
    """Whether the reference sampler gives any window [k0, k1) of its samples exactly (the
    rows of the whole reference): an explicit ``sampler.windows`` says so; else a sampler
    taking ``k0`` and ``k1`` does, unless it runs the Taylor recurrence (sequential: a
    window would restart it). Others (the pre-compensated, non-causal one) are evaluated
    whole."""
    flag = getattr(sampler, "windows", None)
    if flag is not None:
        return bool(flag)
    if getattr(getattr(sampler, "interpolator", None), "value", None) == "taylor":
        return False
    try:
        params = inspect.signature(sampler).parameters
    except (TypeError, ValueError):
        return False
    return "k0" in params and "k1" in params


def _rows(ref: Reference, sl: slice) -> Reference:
    """Rows ``sl`` of every per-sample column of ``ref``."""
    return replace(ref, **{f.name: getattr(ref, f.name)[sl] for f in fields(ref)})


def _joined(first: Reference, then: Reference) -> Reference:
    """The rows of ``first``, then those of ``then``."""
    return replace(first, **{f.name: np.concatenate((getattr(first, f.name),
                                                     getattr(then, f.name)))
                             for f in fields(first)})  # fmt: skip


@dataclass(frozen=True, eq=False)
class _Memo:
    """What :meth:`_Checker.run` keeps of its last check of a window made of one chunk, for
    the next re-plan of that window (:meth:`_Checker._same_rows`): the window (``key``: its
    first sample, whether it ends the program, its last piece; the servo state it started
    from; the path), the profile and dwell schedule it sampled, the chunk's sampled rows
    (``ref``, from row ``a``), and per own row (from chunk row ``own``) the response's
    axis errors, contour and eq. 29 errors and the cutting flags."""

    key: tuple
    stream: AxesStream | None
    path: object
    profile: Profile
    clock: tuple
    a: int
    ref: Reference
    own: int
    axis_error_mm: np.ndarray
    contour_mm: np.ndarray
    contour_eq29_mm: np.ndarray
    cutting: np.ndarray


class _Checker:
    """The dynamics check of one program's plans (SPEC §8), a window of servo samples at a
    time (issue 14): the reference of ``window`` samples (plus one on each side for the
    direction of travel), the servo simulated with its state carried
    (:class:`~nurbscnc.servo.model.AxesStream`), the contour error measured per sample
    (:func:`~nurbscnc.plan.dynamics.window_response`), and only the over-limit samples, the
    piece runs and running statistics kept (:class:`Overs`), unless ``keep`` (the whole
    reference and response, as plots and reports need). A sampler that cannot give windows
    is evaluated whole (one window). Per sample everything is what the whole-array check
    computes, so plans do not depend on the window."""

    def __init__(self, pieces: PieceList, machine: Machine, sampler, eps_mm: float,
                 settle_rows: np.ndarray, window: int, keep: bool):  # fmt: skip
        self.pieces, self.machine, self.sampler = pieces, machine, sampler
        self.eps_mm, self.settle_rows, self.keep = eps_mm, settle_rows, keep
        self.window = max(int(window), 1)
        # Keeping the whole reference and response: one window (today's memory; windows
        # would be concatenated at the end, twice the memory for a moment).
        self.windowed = _windowed(sampler) and not keep
        self.rapid = pieces.rapid
        self.after_rapid = np.zeros(len(pieces), dtype=bool)  # first piece of a cut after a rapid
        self.after_rapid[settle_rows + 1] = True
        self.index = PathIndex(pieces)  # where the pieces are (built on first use)
        # The servo at rest, discretised once (0.5 ms a check): every check starts from a copy.
        servo = machine.servo
        self._at_rest = AxesStream([servo.x, servo.y, servo.z], servo.period_s)
        self._memo: _Memo | None = None  # the last one-chunk check (:meth:`_same_rows`)

    def _windows(self, planned: PieceList, profile: Profile, rows: tuple | None = None,
                 sample=None):  # fmt: skip
        """(reference rows, slice of the window's own rows in them, row of the virtual end
        or None): one row more on each side where there is one (the direction of travel is
        a central difference); with ``rows`` (k0, k1, last, …) only those samples, and
        unless ``last``, after k1 − 1 the row k1 of the program as if it ended with this
        window (:meth:`_end_row`: the next cut window's motion is not planned yet).
        ``sample(a, b)``: rows a … b − 1 of the reference (default: the sampler's)."""
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
            chunks = ((None, max(k0 - 1, 0), min(k0 + self.window + 1, r1 + 1, hi), k0,
                       min(k0 + self.window, r1)) for k0 in range(r0, r1, self.window))
        if sample is None:
            def sample(a, b):
                return self.sampler(planned, profile, period, a, b)
        for whole, a, b, k0, k1 in chunks:
            ref = sample(a, b) if whole is None else _rows(whole, slice(a, b))
            virt = None
            if not last and b == r1 + 1:
                virt = r1 - a
                end = self._end_row(planned, profile, r1, rows[4] + 1)
                ref = replace(ref, **{f.name: np.concatenate((getattr(ref, f.name)[:virt],
                                                              getattr(end, f.name)))
                                      for f in fields(ref)})  # fmt: skip
            yield ref, slice(k0 - a, k1 - a), virt

    def _head(self, planned: PieceList, profile: Profile, end: int) -> tuple:
        """Pieces 0 … ``end`` − 1 of ``planned`` and ``profile`` as a program of their own,
        as far as the contour distance needs them (:class:`_Head`), their
        :class:`~nurbscnc.plan.dynamics.PathIndex` (kept per ``end``) and rapid flags."""
        return (_Head(planned, end), _HeadProfile(profile, end), _HeadIndex(self.index, end),
                self.rapid[:end])  # fmt: skip

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
        return Reference(t, tau, s, np.zeros(1), np.zeros(1), piece, points, param)

    def run(self, planned: PieceList, profile: Profile, rows: tuple | None = None,
            stream: AxesStream | None = None) -> Check:  # fmt: skip
        """Check the plan ``planned``/``profile``: the :class:`Check` of its reference.
        ``rows`` (k0, k1, last, τ_end [s], last piece): only the samples k0 … k1 − 1 (one
        cut window of :func:`plan_windows`), the servo starting from ``stream`` (copied;
        None: at rest at the first sample), then as if the program ended there (``last``
        False: its last sample :meth:`_end_row` and the held tail at profile time τ_end on
        the last piece, on a copy of the servo state, which :attr:`stream_out` then holds
        without them, for the next window)."""
        begins = getattr(self.sampler, "check_begins", None)  # a progress display's hook
        if begins is not None:
            begins(0 if rows is None else rows[0])
        if rows is None and not self.windowed:
            return self._run_whole(planned, profile)
        servo = self.machine.servo
        stream_in = stream
        stream = (self._at_rest if stream is None else stream).copy()
        acc = _Accumulator(self, profile)
        last = end = None
        # The path the error is measured against: the pieces up to this window's end (the
        # program as if it ended there; the whole program for the last window).
        head = None if rows is None or rows[2] else self._head(planned, profile, rows[4] + 1)
        on, prof, index = (planned, profile, self.index) if head is None else head[:3]
        key = None if rows is None else (rows[0], rows[2], rows[4])
        memo, same = self._memo, self._same_rows(planned, profile, key, stream_in)
        self._memo = None
        # The first chunk sampled, as (first row, rows): kept for the next re-plan if the
        # window is that one chunk. Memory: one chunk at most.
        sampled: list = []
        chunks = 0

        def sample(a: int, b: int) -> Reference:
            period = servo.period_s
            if same and a == memo.a:  # the leading rows the last check of it sampled
                j = min(same, b - a)
                ref = _joined(_rows(memo.ref, slice(0, j)),
                              self.sampler(planned, profile, period, a + j, b))  # fmt: skip
            else:
                ref = self.sampler(planned, profile, period, a, b)
            nonlocal chunks
            chunks += 1
            sampled[:] = [(a, ref)] if chunks == 1 else []
            return ref

        for ref, own, virt in self._windows(planned, profile, rows, sample):
            d = np.gradient(ref.points_mm[:, :2], axis=0) if ref.t_s.size > 1 else \
                np.zeros((ref.t_s.size, 2))  # fmt: skip
            if virt is not None:
                end = (_rows(ref, slice(virt, virt + 1)), d[virt : virt + 1])
            # Own rows whose response the last check computed: their reference rows and
            # the rows on each side (the direction of travel) are the same.
            kept = 0
            if chunks > 1:  # a window of several chunks keeps none
                memo = self._memo = None
            elif same and sampled[0][0] == memo.a and own.start == memo.own:
                kept = max(0, min(same - 1, ref.t_s.size - 2, own.stop) - own.start)
                kept = min(kept, memo.contour_mm.size)
            ref = _rows(ref, own)
            actual = stream.step(ref.points_mm)
            resp, cutting = self._respond(ref, actual, d[own], on, prof, index, profile, head,
                                          memo, kept)  # fmt: skip
            acc.add(resp, cutting, ref.tau_s, ref.piece)
            last = ref
            if sampled:  # the first chunk: kept for the next re-plan of a one-chunk window
                self._memo = _Memo(key, stream_in, planned.path, profile,
                                   dwell_times(planned.dwell_after_s, profile), sampled[0][0],
                                   sampled[0][1], own.start, resp.axis_error_mm,
                                   resp.contour_mm, resp.contour_eq29_mm, cutting)  # fmt: skip
        self.stream_out = stream
        virtual = rows is not None and not rows[2]
        if virtual:  # the end of a cut window, as if the program ended there
            stream = stream.copy()
            if end is not None:
                ref, d_end = end
                actual = stream.step(ref.points_mm)
                resp = window_response(ref.points_mm, ref.s_mm, actual, d_end, on, prof,
                                       self.eps_mm, index)  # fmt: skip
                acc.add(resp, self._cutting(ref, resp, profile, head), ref.tau_s, ref.piece,
                        virtual=True)  # fmt: skip
                last = ref
        tail = stream.settle()  # the reference held at its end until the axes settle
        if tail.shape[0]:
            m = tail.shape[0]
            held = np.repeat(last.points_mm[-1:], m, axis=0)
            resp = window_response(held, np.full(m, last.s_mm[-1]), tail, np.zeros((m, 2)),
                                   on, prof, self.eps_mm, index)  # fmt: skip
            tau_end, piece_end = (profile.duration_s, len(planned) - 1) if rows is None \
                else rows[3:5]  # fmt: skip
            acc.add(resp, np.full(m, not self.rapid[piece_end]), np.full(m, tau_end),
                    np.full(m, piece_end), virtual=virtual)  # fmt: skip
        return acc.check()

    def _same_rows(self, planned: PieceList, profile: Profile, key: tuple | None,
                   stream: AxesStream | None) -> int:  # fmt: skip
        """How many leading rows of the kept chunk (:class:`_Memo`) a check of this plan
        samples alike, bit for bit: the same window started from the same servo state on
        the same path, each row's wall time before the dwell schedules differ
        (:func:`~nurbscnc.plan.timing.same_clock_until_s`) and its profile time before the
        profiles do (:func:`~nurbscnc.plan.profile.same_until_s`). The sampler gives each
        row from its own wall time alone (any window of rows is those rows of the whole
        reference), and the response of a row depends on its reference, its neighbours'
        and the servo state only: so a re-plan that changed the profile from some point on
        costs the samples from there on. 0 without a kept chunk."""
        memo = self._memo
        if memo is None or memo.key != key or memo.stream is not stream or \
                memo.path is not planned.path:  # fmt: skip
            return 0
        t_wall = same_clock_until_s(memo.clock, dwell_times(planned.dwell_after_s, profile))
        t_tau = same_until_s(memo.profile, profile)
        return int(min(np.searchsorted(memo.ref.t_s, t_wall, side="left"),
                       np.searchsorted(memo.ref.tau_s, t_tau, side="left")))  # fmt: skip

    def _respond(self, ref: Reference, actual: np.ndarray, direction: np.ndarray, on, prof,
                 index, profile: Profile, head: tuple | None, memo: _Memo | None,
                 kept: int) -> tuple[Response, np.ndarray]:  # fmt: skip
        """The response to the own reference rows ``ref`` (the servo's ``actual``
        positions, the directions of travel) and which rows are checked (:meth:`_cutting`):
        the first ``kept`` rows from ``memo`` (the same numbers), the others computed."""
        new = slice(kept, None)
        resp = window_response(ref.points_mm[new], ref.s_mm[new], actual[new], direction[new],
                               on, prof, self.eps_mm, index)  # fmt: skip
        cutting = self._cutting(_rows(ref, new), resp, profile, head)
        if not kept:
            return resp, cutting

        def joined(old: np.ndarray, now: np.ndarray) -> np.ndarray:
            return np.concatenate((old[:kept], now))

        return (Response(actual, joined(memo.axis_error_mm, resp.axis_error_mm),
                         joined(memo.contour_mm, resp.contour_mm),
                         joined(memo.contour_eq29_mm, resp.contour_eq29_mm)),
                joined(memo.cutting, cutting))  # fmt: skip

    def _run_whole(self, planned: PieceList, profile: Profile) -> Check:
        """The check on the whole reference at once (a sampler without windows, or the
        reference and response kept): :func:`~nurbscnc.plan.dynamics.path_response`."""
        ref = self.sampler(planned, profile, self.machine.servo.period_s)
        resp = path_response(ref, planned, profile, self.machine, refine_above_mm=self.eps_mm,
                             index=self.index)  # fmt: skip
        n, m = ref.t_s.size, resp.contour_mm.size
        cutting = np.append(self._cutting(ref, resp, profile),
                            np.full(m - n, not self.rapid[-1]))  # fmt: skip
        acc = _Accumulator(self, profile)
        acc.add(resp, cutting, np.append(ref.tau_s, np.full(m - n, profile.duration_s)),
                np.append(ref.piece, np.full(m - n, len(planned) - 1)))  # fmt: skip
        if not self.keep:
            return acc.check()
        return replace(acc.check(), reference=ref, response=resp, cutting=cutting)

    def _cutting(self, ref: Reference, resp: Response, profile: Profile,
                 head: tuple | None = None) -> np.ndarray:  # fmt: skip
        """Which reference samples are checked (N,): contour error matters while cutting;
        samples on rapids (air moves) and during the settle after a rapid (the reference
        waits at the cut's start) are not. The first cutting samples after a rapid are
        measured against the cut only (in ``resp``)."""
        waiting = self.after_rapid[ref.piece] & (
            ref.tau_s <= profile.piece_start_time_s[ref.piece])
        index, rapid = (self.index, self.rapid) if head is None else (head[2], head[3])
        _cut_distance_after_rapids(resp, ref, profile, self.after_rapid, waiting, rapid,
                                   index)  # fmt: skip
        return ~self.rapid[ref.piece] & ~waiting


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

    def distance_mm(self, q: np.ndarray, upper_mm: np.ndarray, block: int = 256,
                    exclude: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
        """:meth:`PathIndex.distance_mm` to pieces 0 … end − 1 (less ``exclude`` (end,))."""
        beyond = np.zeros(len(self._index._pieces), dtype=bool)
        beyond[self._end :] = True
        if exclude is not None:
            beyond[: self._end] |= exclude[: self._end]
        return self._index.distance_mm(q, upper_mm, block, beyond)

    def dense_polyline(self, pieces, starts_mm: np.ndarray, total_mm: float, lo: int,
                       hi: int) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
        """The dense polyline of pieces ``lo:hi`` of the head: the whole program's kept
        polyline (:meth:`PathIndex.dense_polyline`: the same numbers as made afresh for the
        head, whose starts are the program's first and whose total clips its end)."""
        return self._index.dense_polyline(pieces, starts_mm, total_mm, lo, hi)


class _HeadProfile:
    """The profile of the first ``end`` pieces (their start lengths and total length)."""

    def __init__(self, profile: Profile, end: int):
        self.piece_start_mm = profile.piece_start_mm[:end]
        self.total_length_mm = float(profile.piece_start_mm[end])


class _Accumulator:
    """The running results of one check (:class:`_Checker`): over-limit samples, piece
    runs, settle counts and contour statistics (:class:`Overs`)."""

    def __init__(self, checker: _Checker, profile: Profile):
        self.eps_mm = checker.eps_mm
        self.t_restart = profile.piece_start_time_s[checker.settle_rows + 1]
        self.count = 0
        self.over: list = []  # (index, err, tau) per window
        self.runs: list = []  # (run piece, run start) per window
        self.last_piece = -1
        self.restart = np.zeros(checker.settle_rows.size, dtype=np.int64)
        self.worst = 0.0
        self.c_max = self.c_sq = self.eq29_max = 0.0
        self.c_n = 0
        self.real = None  # (count, worst, restart, over count, run count) before a virtual tail

    def add(self, resp: Response, cutting: np.ndarray, tau_s: np.ndarray, piece: np.ndarray,
            virtual: bool = False):  # fmt: skip
        """The next samples: their response, which are checked (``cutting``), profile times
        [s] and pieces. ``virtual``: the held tail of a cut window that the program does not
        end with: it counts for the window's decisions, not in its statistics nor in
        :attr:`Check.samples`."""
        if virtual and self.real is None:
            self.real = (self.count, self.worst, self.restart.copy(), len(self.over),
                         len(self.runs))  # fmt: skip
        err = np.where(cutting, resp.contour_mm, 0.0)
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
            self.eq29_max = max(self.eq29_max,
                                float(np.abs(resp.contour_eq29_mm[cutting]).max()) * 1000.0)
        self.count += cutting.size

    def check(self) -> Check:
        """The :class:`Check` of everything added (no per-sample arrays)."""
        idx, err, tau = (np.concatenate(x) for x in zip(*self.over))
        piece, start = (np.concatenate(x) for x in zip(*self.runs))
        overs = Overs(self.count, idx, err, tau, piece, start, self.restart, self.worst)
        rms = float(np.sqrt(self.c_sq / self.c_n)) if self.c_n else 0.0
        stats = {"contour_true_max_um": self.c_max, "contour_true_rms_um": rms,
                 "contour_eq29_max_um": self.eq29_max}  # fmt: skip
        samples = overs
        if self.real is not None:
            count, worst, restart, n_over, n_runs = self.real
            i, e, t = (np.concatenate(x) for x in zip(*self.over[:n_over]))
            rp, rs = (np.concatenate(x) for x in zip(*self.runs[:n_runs]))
            samples = Overs(count, i, e, t, rp, rs, restart, worst)
        return Check(None, None, None, overs, stats, samples, self.c_n)


@dataclass(frozen=True, eq=False)
class Window:
    """One cut window of :func:`plan_windows`: ``index``; its pieces ``first`` … ``end`` − 1
    (the rapids before a cut and the cut, up to the next rapid: a rest junction); its servo
    samples ``k0`` … ``k1`` − 1 (wall time k·T_s within it; the last window: to the end);
    ``plan``: the whole program's plan with this window and all before it final (the
    profile of a window depends only on its own levers and the windows before it: the
    junctions between windows are at rest), the later ones not planned yet (their
    kinematic levers); ``check``: this window's check (compact) and ``iterations``: its
    re-plans."""

    index: int
    first: int
    end: int
    k0: int
    k1: int
    #: Makes :attr:`plan` (on first use: a caller that keeps the last window only, as
    #: :func:`plan_checked` does, makes one whole-program plan, not one per window).
    make_plan: Callable[[], Plan] = field(repr=False)
    check: Check | None
    iterations: int

    @functools.cached_property
    def plan(self) -> Plan:
        """The whole program's plan with this window and every window before it final."""
        return self.make_plan()


def cut_windows(pieces: PieceList) -> np.ndarray:
    """Piece index of the start of each cut window (w,) (the first is 0): every rapid that a
    cut precedes starts a window (a cut → rapid junction is a rest, :func:`junction_caps`),
    so a window is the rapids before a cut and the cut; the settle after a rapid belongs to
    the cut after it."""
    rapid = np.asarray(pieces.rapid, dtype=bool)
    return np.concatenate(([0], np.flatnonzero(rapid[1:] & ~rapid[:-1]) + 1))


class _Setup:
    """What every plan of one program shares: its pieces, the kinematic levers (the axes'
    path limits), the settle rows, the checker; :meth:`evaluate` plans and checks levers."""

    def __init__(self, program, machine: Machine, options: LookaheadOptions, reference,
                 keep_reference: bool, window: int, columns=None):  # fmt: skip
        self.machine, self.options = machine, options
        pieces = segment_pieces(program.segments, machine, options.plan, columns)
        if not len(pieces):
            raise PlanningError("the program has no motion to plan")
        self.pieces = pieces
        path_lim = piece_limits(pieces, machine)  # the axes' limits along each piece
        a_p = np.array(path_lim.a_mm_s2, dtype=float)
        j_p = np.array(path_lim.j_mm_s3, dtype=float)
        k = self.k = len(pieces)
        self.initial = _Levers(np.minimum(pieces.v_cap_mm_s, path_lim.v_mm_s), a_p, j_p,
                               a_p.copy(), j_p.copy(), np.zeros(k), np.zeros(k, dtype=bool),
                               np.zeros(k, dtype=bool))  # fmt: skip
        self.smooth = junction_caps(pieces)  # > 0 where the path is tangent-continuous
        self.period = machine.servo.period_s
        self.eps_mm = machine.limits.contour_tolerance_mm * CONTOUR_MARGIN
        # Rapids followed by a cut: the settle (in-position wait) there is the check's to
        # set (zero while the error is within ε_max). Without the check (``off``: kinematics
        # only) there is nothing to wait for; the paper's global rule has no local lever, so
        # it waits the full settle (the rapid's overshoot then never counts).
        self.settle_rows = np.flatnonzero(pieces.rapid[:-1] & ~pieces.rapid[1:])
        self.settle_max = settle_time_s(machine)
        if options.dynamics == Dynamics.GLOBAL:
            self.initial.settle_s[self.settle_rows] = self.settle_max
        self.base_dwell = pieces.dwell_after_s
        self.checker = _Checker(pieces, machine, reference, self.eps_mm, self.settle_rows,
                                window, keep_reference)  # fmt: skip
        # The improvement phase's upper brackets: the kinematic levers, or with
        # ``raise_corner_caps`` the caps without the corner heuristic V_cf.
        self.upper = self.initial
        if options.raise_corner_caps and options.dynamics == Dynamics.LOCAL:
            free = _without_corner_feed(program, machine, options, pieces)
            if free is not None:
                self.upper = self.initial.copy()
                self.upper.caps = np.maximum(np.minimum(free.v_cap_mm_s, path_lim.v_mm_s),
                                             self.initial.caps)  # fmt: skip
                # The junctions capped by their neighbours' machine caps (the same passable
                # junctions): the profile takes the smaller of the levers' caps anyway.
                self.smooth = np.maximum(self.smooth, junction_caps(free))

    def plan_of(self, lv: _Levers):
        """The planned pieces (settles in their dwells) and profile of the levers ``lv``."""
        planned = _with_dwell(self.pieces, self.base_dwell + lv.settle_s) \
            if self.settle_rows.size else self.pieces  # fmt: skip
        profile = profile_over(planned.length_mm, lv.caps, self.smooth, lv.limits(),
                               self.options.lookahead_pieces)  # fmt: skip
        check_point_count(planned, profile, self.machine)  # before anything is sampled
        return planned, profile

    def evaluate(self, lv: _Levers, rows=None, stream=None):
        """Plan with the levers ``lv`` and check (``rows``, ``stream``: one cut window,
        :meth:`_Checker.run`): (planned pieces, profile, check)."""
        planned, profile = self.plan_of(lv)
        if self.options.dynamics == Dynamics.OFF:
            return planned, profile, None
        return planned, profile, self.checker.run(planned, profile, rows, stream)

    def shape(self, lv: _Levers, result) -> None:
        _shape(lv, result[2].overs, self.eps_mm, result[1], self.pieces, self.smooth,
               self.settle_rows, self.settle_max, self.period)  # fmt: skip

    def fallback(self, lv: _Levers, result, stage: int) -> None:
        _fallback(lv, result[2].overs, self.eps_mm, self.pieces, self.settle_rows,
                  self.settle_max, self.period, stage)  # fmt: skip

    def plan(self, lev: _Levers, result, iterations: int) -> Plan:
        """The :class:`Plan` of the levers ``lev`` and their ``result``."""
        planned, profile = result[0], result[1]
        initial = self.initial
        feed = lev.caps < initial.caps
        transition = np.zeros(self.k, dtype=bool)
        for f in ("a_up", "j_up", "a_dn", "j_dn"):
            transition |= getattr(lev, f) < getattr(initial, f)
        return Plan(planned, lev.caps, profile, iterations, _cycle_time(result),
                    self.options.dynamics, lev.limits(), feed | transition, feed, transition,
                    lev.settle_s)  # fmt: skip


def _without_corner_feed(program, machine: Machine, options: LookaheadOptions,
                         pieces: PieceList) -> PieceList | None:  # fmt: skip
    """``pieces`` without the corner heuristic V_cf (SPEC eq. 24) in their caps: made again
    with κ̄ → ∞ (V_cf = F), so a corner piece keeps its physical caps only — the chord
    feed V_af, the normal acceleration √(A/κ), F and V_max. The corner regions (κ_th =
    A/F²) and the fits do not depend on κ̄; None if the pieces came out otherwise than
    ``pieces`` (then nothing is raised)."""
    limits = replace(machine.limits, kappa_ref_per_mm=1e15)
    free = segment_pieces(program.segments, replace(machine, limits=limits), options.plan)
    if len(free) != len(pieces) or not np.array_equal(free.length_mm, pieces.length_mm):
        return None
    if not np.array_equal(junction_caps(free) > 0.0, junction_caps(pieces) > 0.0):
        return None
    return free


def _converge(st: _Setup, lev: _Levers, evaluate, confine=lambda lv: None, plan_of=None):
    """The levers loop (module docstring) from ``lev`` (changed in place): re-plan until the
    check is within ε_max (local shaping, then the fallback), then the improvement phase.
    ``evaluate(levers)`` → (planned, profile, check); ``confine(levers)`` undoes changes
    outside the levers' scope (a cut window); ``plan_of(levers)`` → (planned, profile, …)
    without the check (default :meth:`_Setup.plan_of`). Returns (final levers, result,
    re-plans)."""
    options, eps_mm, initial = st.options, st.eps_mm, lev.copy()
    iterations = 0
    fastest_s = None  # the cycle time before shaping
    while True:
        result = evaluate(lev)
        if fastest_s is None:
            fastest_s = _cycle_time(result)
        if result[2] is None:
            break
        worst = result[2].overs.worst_mm
        if worst <= eps_mm:
            break
        iterations += 1
        if iterations > options.max_iterations:
            raise PlanningError(
                f"dynamics check: contour error {worst * 1000:.2f} µm still above ε_max after "
                f"{options.max_iterations} re-plans"
            )
        if options.dynamics == Dynamics.GLOBAL:
            # The paper's rule: lower V_max for the whole program. Every cap (cruise and
            # corner: V_cf ∝ V_max) scales with it; error ∝ V²κ gives the factor.
            lev.caps *= min(float(np.sqrt(eps_mm / worst)), 0.98)
            lev.shaped[:] = True
        elif iterations <= LOCAL_ITERATIONS:
            st.shape(lev, result)
        else:
            stage = 1 if iterations <= LOCAL_ITERATIONS + FALLBACK_LOCAL_ITERATIONS else 2
            st.fallback(lev, result, stage)
        confine(lev)
        result = None  # the last check goes first (with keep_reference, hundreds of MB)
    shaped_s = _cycle_time(result)
    if options.dynamics == Dynamics.LOCAL and lev.shaped.any() and _may_gain(result, shaped_s,
                                                                           fastest_s):
        # Improvement: bisect every shaped lever between its feasible value and its value
        # before shaping (geometric means; the settles arithmetically towards 0).
        lev, result, n = _improve(st, lev, result, initial, evaluate, confine)
        iterations += n
    if st.upper is not st.initial and options.dynamics == Dynamics.LOCAL:
        # The corner caps the heuristic V_cf held below the machine's (``raise_corner_caps``;
        # this window's only), bisected the same way from the plan so far up to those caps
        # — after the improvement above, so the plan is never slower than without them.
        hi = lev.copy()
        hi.caps = np.maximum(hi.caps, st.upper.caps)
        confine(hi)
        shaped_s = _cycle_time(result)
        if np.any(hi.caps > lev.caps * IMPROVE_RATIO) and _may_gain(
                result, shaped_s, _cycle_time((plan_of or st.plan_of)(hi))):
            lev, result, n = _improve(st, lev, result, hi, evaluate, confine)
            iterations += n
    return lev, result, iterations


def _improve(st: _Setup, lev: _Levers, result, hi: _Levers, evaluate, confine):
    """The improvement phase (:func:`_converge`) from the feasible levers ``lev`` (their check
    ``result``) towards the upper brackets ``hi``: at most :data:`IMPROVE_ITERATIONS` tries,
    each halfway (:meth:`_Levers.toward`). A try within ε_max is kept if it is faster; a
    failing one narrows the brackets of the levers that the shaping rule blames for it (found
    by applying the rule to a copy). Then the restores: at most :data:`RESTORE_PIECES` feed
    caps, the largest time gains first (:func:`_restore_gains`, at least one servo period),
    each tried alone at its upper bracket and kept if within ε_max and faster; a restore
    that gains at least :data:`RESHAPE_MIN_GAIN_S` and fails is shaped again (at most
    :data:`RESHAPE_ITERATIONS` re-plans, the stops' history cleared so each starts from its
    transition) while the shaping keeps that cap above the plan's, then that cap alone is
    searched between the two by false position (:data:`RESTORE_SECANTS` re-plans). Returns
    (best levers, their result, re-plans)."""
    # A check that keeps its reference and response holds hundreds of MB: then only one
    # plan's is held at a time, and the best plan is re-made at the end if a later try
    # replaced its result; a check without them is small and the best is kept.
    keep_best = not st.checker.keep
    best = best_time = best_worst_mm = best_result = None

    def take(levers, res):  # the best plan so far: these levers, their check
        nonlocal best, best_time, best_worst_mm, best_result
        best, best_time = levers, _cycle_time(res)
        best_worst_mm = res[2].overs.worst_mm
        best_result = res if keep_best else None

    take(lev.copy(), result)
    iterations = 0
    for _ in range(IMPROVE_ITERATIONS):
        trial = best.toward(hi)
        if trial is None:
            break
        result = None
        result = evaluate(trial)
        iterations += 1
        if result[2].overs.worst_mm <= st.eps_mm:
            t = _cycle_time(result)
            if t > best_time:  # a feasible raise that is slower (rare): stop here
                result = None
                break
            take(trial, result)
        else:
            probe = trial.copy()
            st.shape(probe, result)
            confine(probe)
            hi = hi.narrowed(trial, probe)
            result = None
    # Restores: the joint tries raise every lever at once and fail on any one of them, so
    # a feed lowered where it did not help (the error was a junction's, answered later by
    # another lever) stays low. The caps with the most time to gain are tried alone, among
    # those this plan may change (``confine`` keeps a cut window's others at their final).
    reach = best.copy()
    reach.caps = np.maximum(best.caps, hi.caps)
    confine(reach)
    gain = _restore_gains(st, best, reach)
    for p in np.argsort(-gain, kind="stable")[:RESTORE_PIECES].tolist():
        if gain[p] < st.period:
            break
        trial = best.copy()
        trial.caps[p] = reach.caps[p]
        shapes = RESHAPE_ITERATIONS if gain[p] >= RESHAPE_MIN_GAIN_S else 0
        if shapes:
            trial.stop_history = None  # every stop starts again from its transition
        alone = None  # (cap, error [mm]) of the restore alone
        for i in range(shapes + 1):
            result = None
            result = evaluate(trial)
            iterations += 1
            if alone is None:
                alone = (reach.caps[p], result[2].overs.worst_mm)
            if result[2].overs.worst_mm <= st.eps_mm or i == shapes:
                break
            st.shape(trial, result)
            confine(trial)
            if trial.caps[p] <= best.caps[p] * IMPROVE_RATIO:  # nothing left to gain
                break
        if result[2].overs.worst_mm <= st.eps_mm and _cycle_time(result) < best_time:
            take(trial, result)
        else:
            result = None
        if not shapes or best.caps[p] >= alone[0]:
            continue
        # The cap alone, between the plan's (within ε_max; the shaping's if it found one,
        # whose feed lever steps by up to 2×) and the restore's (above it): false position
        # on the error, which grows about linearly with the cruise feed where the cap is
        # what limits it (a line or helix in space whose z has no servo model lags ∝ v off
        # the path).
        lo, hi_cap = (best.caps[p], best_worst_mm), alone
        for _ in range(RESTORE_SECANTS):
            gap = hi_cap[0] - lo[0]
            if gap <= lo[0] * (IMPROVE_RATIO - 1.0):
                break
            slope = (hi_cap[1] - lo[1]) / gap
            cap = lo[0] + (st.eps_mm - lo[1]) / slope if slope > 0.0 else lo[0] + gap / 2
            trial = best.copy()
            trial.caps[p] = min(max(cap, lo[0] + 0.1 * gap), hi_cap[0] - 0.1 * gap)
            result = None
            result = evaluate(trial)
            iterations += 1
            worst = result[2].overs.worst_mm
            if worst > st.eps_mm:
                hi_cap, result = (trial.caps[p], worst), None
                continue
            if _cycle_time(result) >= best_time:  # within ε_max yet slower: stop here
                result = None
                break
            take(trial, result)
            lo = (trial.caps[p], worst)
    if result is None:
        result = best_result if best_result is not None else evaluate(best)
    return best, result, iterations


def _restore_gains(st: _Setup, best: _Levers, hi: _Levers) -> np.ndarray:
    """Per piece, the time [s] its cruise at the cap ``hi.caps`` (the upper bracket where the
    plan may change it) would save over ``best.caps`` (L/c − L/c_hi; 0 where the cap is
    within :data:`IMPROVE_RATIO` of it): the order of :func:`_improve`'s restores."""
    low = hi.caps > best.caps * IMPROVE_RATIO
    length = st.pieces.length_mm
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(low, length / best.caps - length / hi.caps, 0.0)


def _may_gain(result, shaped_s: float, fastest_s: float) -> bool:
    """Whether the improvement phase may gain more than :data:`IMPROVE_MIN_GAIN` of the
    planned motion's time: the shaped plan ``result`` (cycle time ``shaped_s`` [s]) is slower
    than the plan before shaping (``fastest_s`` [s]) by more than that fraction of its own
    motion (a cut window's profile, else the whole cycle time)."""
    span_s = result[3].duration_s if len(result) > 3 else shaped_s
    return shaped_s - fastest_s > IMPROVE_MIN_GAIN * span_s


def plan_checked(program, machine: Machine, options: LookaheadOptions | None = None,
                 reference=exact_reference, keep_reference: bool = True,
                 window: int = CHECK_WINDOW,
                 columns=None) -> tuple[Plan, Check | None]:  # fmt: skip
    """Plan a whole interpreted program and check it (SPEC §1: modules 1–4, §8): pieces,
    profile, then the dynamics check on the plan's reference points, re-planning until the
    predicted contour error is within ε_max. ``reference``: (pieces, profile, period_s,
    k0=0, k1=None) → :class:`~nurbscnc.plan.timing.Reference`, the points k0…k1−1 the check
    simulates (default: the exact ones; the interpolator passes its own,
    :func:`nurbscnc.interpolate.sample.reference_sampler`); a sampler without windows
    (:func:`_windowed`) is called as (pieces, profile, period_s) for all of them; a
    sampler's ``check_begins(k0)``, if it has one, is called as each check begins at sample
    k0 (a progress display: a re-plan may sample only from where its plan changed).

    A program of several cuts (``dynamics="local"``) is planned cut window by cut window
    (:func:`plan_windows`); the plan is the last window's (all windows final) and the check
    the windows' checks joined (with ``keep_reference``: re-run once on it as one program).
    The check runs ``window`` servo samples at a time
    (:class:`_Checker`), so its memory grows with the pieces, not with the motion time; the
    plan does not depend on ``window``. ``keep_reference``: the final :class:`Check` holds
    the whole reference and response (plots, reports, the output); False: only the
    over-limit samples and the statistics (long programs). ``columns``: the program's
    :class:`~nurbscnc.program.columns.SegmentColumns` if read already. Returns the plan and
    the final check (None with ``dynamics="off"``)."""
    options = options or LookaheadOptions()
    st = _Setup(program, machine, options, reference, keep_reference, window, columns)
    if options.dynamics != Dynamics.LOCAL or cut_windows(st.pieces).size == 1:
        lev, result, iterations = _converge(st, st.initial.copy(), st.evaluate)
        return st.plan(lev, result, iterations), result[2]
    whole = st.checker
    st.checker = _Checker(st.pieces, machine, reference, st.eps_mm, st.settle_rows, window,
                          False)  # fmt: skip
    joined = _JoinedChecks()

    def windows():
        for w in _windows_of(st):
            joined.add(w.check)
            yield w

    last = deque(windows(), maxlen=1)[0]  # one window's plan held at a time
    if keep_reference:  # the whole reference and response: one more pass over the samples
        return last.plan, whole.run(last.plan.pieces, last.plan.profile)
    return last.plan, joined.check()


def plan_windows(program, machine: Machine, options: LookaheadOptions | None = None,
                 reference=exact_reference, window: int = CHECK_WINDOW, columns=None):
    """Plan a program cut window by cut window (:func:`cut_windows`), yielding each
    :class:`Window` as soon as it is final: its levers loop (shaping, fallback, improvement)
    sees only its own pieces and samples, the servo starting from the state the previous
    window's final plan left it in (:class:`~nurbscnc.servo.model.AxesStream`), its end
    checked as if the program ended there (the held tail on a copy of that state); the
    plan of a program cut short after window n is the first n windows'. One window (and
    ``dynamics`` other than "local") is :func:`plan_checked`'s plan."""
    options = options or LookaheadOptions()
    st = _Setup(program, machine, options, reference, False, window, columns)
    if options.dynamics != Dynamics.LOCAL or cut_windows(st.pieces).size == 1:
        lev, result, iterations = _converge(st, st.initial.copy(), st.evaluate)
        n = sample_count(result[0], result[1], st.period)
        plan = st.plan(lev, result, iterations)
        yield Window(0, 0, st.k, 0, n, lambda: plan, result[2],
                     iterations)  # fmt: skip
        return
    yield from _windows_of(st)


def _windows_of(st: _Setup):
    """The windows of :func:`plan_windows` (several cuts, local dynamics).

    Each window's profile is planned from its own pieces only (:func:`profile_over` over
    pieces a … b − 1: the junctions at a and b are rests, so nothing outside the window
    changes it): the plan of window w is the final windows before it, then its own profile,
    then a placeholder for the pieces not planned yet (:func:`_placeholder`: never sampled
    before the window's end), spliced into one :class:`Profile` (:func:`_spliced`). A
    re-plan thus costs the window's pieces, not the program's."""
    starts = cut_windows(st.pieces)
    ends = np.append(starts[1:], st.k)
    final = st.initial.copy()  # windows before the current one final, later ones kinematic
    seen = _SeenWindows(st)
    stand_in = _placeholder(st.pieces, st.initial, 0)  # every window's "later", rebased
    stream = None
    parts: list = []  # the final profiles of the windows so far, each from time 0
    done = None  # their splice, compacted (_compacted): what the re-plans put before a window
    keep_s = WINDOW_KEEP_PERIODS * st.period
    total_iterations = 0
    own_profile = _OwnProfiles(st)
    for w, (a, b) in enumerate(zip(starts.tolist(), ends.tolist())):
        is_last = b == st.k
        scope = np.zeros(st.k, dtype=bool)
        scope[a:b] = True
        later = None if is_last else _placeholder(st.pieces, st.initial, b, stand_in)
        # What the re-plans splice around the window's own profile: the windows before and
        # the stand-in after, their phases outside the periods the check reads merged.
        around = (done, None if later is None else _compacted(later, 0.0))

        def confine(lv: _Levers, scope=scope, final=final) -> None:
            for f in (*_Levers._SCALED, "settle_s", "shaped", "ineffective"):
                getattr(lv, f)[~scope] = getattr(final, f)[~scope]

        warm, repeated_cut = seen.warm(final, a, b)

        def plan_of(lv: _Levers, a=a, b=b, around=around, cut=repeated_cut):
            planned = _with_dwell(st.pieces, st.base_dwell + lv.settle_s) \
                if st.settle_rows.size else st.pieces  # fmt: skip
            own = own_profile(lv, a, b, cut)
            profile = _spliced([x for x in (around[0], own, around[1]) if x is not None])
            check_point_count(planned, profile, st.machine)  # before anything is sampled
            return planned, profile, own

        def rows_of(planned, profile, a=a, b=b, is_last=is_last):
            k0 = _first_sample_at(planned, profile, a, st.period)
            if is_last:
                k1 = sample_count(planned, profile, st.period)
                return (k0, k1, True, profile.duration_s, st.k - 1)
            k1 = _first_sample_at(planned, profile, b, st.period)
            return (k0, k1, False, float(profile.piece_start_time_s[b]), b - 1)

        def evaluate(lv: _Levers, plan_of=plan_of, rows_of=rows_of, stream=stream):
            planned, profile, own = plan_of(lv)
            check = st.checker.run(planned, profile, rows_of(planned, profile), stream)
            return planned, profile, check, own, st.checker.stream_out

        lev, result, iterations = _converge(st, warm, evaluate, confine, plan_of)
        seen.add(lev, a, b)
        final = lev
        stream = result[4]  # the servo's state after this window's final plan
        parts.append(result[3])
        done = _compacted(_spliced([x for x in (done, result[3]) if x is not None]), keep_s)
        total_iterations += iterations
        rows = rows_of(result[0], result[1])  # (per-piece columns and duration: whole)
        # The window's plan with every phase (the re-plans' profiles had merged some), made
        # when asked for (O(program) each: a plan per window made many cuts quadratic).
        make = functools.partial(_window_plan, st, lev, result, parts, len(parts), later,
                                 total_iterations)  # fmt: skip
        yield Window(w, a, b, rows[0], rows[1], make, result[2], iterations)


class _OwnProfiles:
    """A cut window's own profile (:func:`_windows_of`): :func:`profile_over` of its pieces;
    for a window whose cut repeats an earlier one (a part cut again elsewhere, its levers
    started from that one's: :meth:`_SeenWindows.warm`), its rapids' and its cut's planned
    apart (the junction between them is a rest: each is what the whole window's profile
    gives for its pieces, to the rounding of the times after it) and spliced, and the cut's
    remembered: a cut that repeats it with those levers has the same lengths, caps,
    junctions and limits bit for bit, and :func:`profile_over` is a pure function of them,
    so its profile is taken, not planned again (2 of the 6 ms a repeated 60 mm airfoil
    cost). Whether a window is split depends on the windows before it only (a program cut
    short plans its first windows as the whole program does). The last :data:`MEMO` cuts'
    profiles of :data:`MEMO_MIN_PIECES` to :data:`MEMO_PIECES` pieces are kept (the key
    holds the cut's columns)."""

    MEMO = 4
    MEMO_MIN_PIECES = 64
    MEMO_PIECES = 1 << 16

    def __init__(self, st: _Setup):
        self.st = st
        self.kept: dict[bytes, Profile] = {}

    def __call__(self, lv: _Levers, a: int, b: int, cut: int | None) -> Profile:
        """The own profile of window a … b − 1; ``cut``: the first piece of its cut when the
        cut repeats an earlier one (:meth:`_SeenWindows.warm`), else None."""
        st = self.st
        lim = lv.limits()

        def over(lo: int, hi: int) -> Profile:
            return profile_over(st.pieces.length_mm[lo:hi], lv.caps[lo:hi],
                                st.smooth[lo : hi + 1],
                                Limits(lim.a_up_mm_s2[lo:hi], lim.j_up_mm_s3[lo:hi],
                                       lim.a_down_mm_s2[lo:hi], lim.j_down_mm_s3[lo:hi]),
                                st.options.lookahead_pieces)  # fmt: skip

        c = cut
        if (c is None or c == a or st.smooth[c] > 0.0
                or not self.MEMO_MIN_PIECES <= b - c <= self.MEMO_PIECES
                or st.options.lookahead_pieces is not None):  # fmt: skip
            # Not a repeat; a cut without rapids, a passed junction between them, a cut too
            # short to gain (two profiles and a splice cost more than one: 2,000
            # plunged squares 3 % slower) or too long to key, or a bounded look-ahead
            # (which counts the window's pieces): whole.
            return over(a, b)
        smooth = st.smooth[c : b + 1].copy()
        smooth[[0, -1]] = 0.0  # the rests at its ends (what profile_over reads of them)
        key = b"".join(np.ascontiguousarray(x).tobytes() for x in (
            st.pieces.length_mm[c:b], lv.caps[c:b], smooth, lim.a_up_mm_s2[c:b],
            lim.j_up_mm_s3[c:b], lim.a_down_mm_s2[c:b], lim.j_down_mm_s3[c:b]))  # fmt: skip
        cut = self.kept.get(key)
        if cut is None:
            cut = over(c, b)
            if len(self.kept) >= self.MEMO:
                self.kept.pop(next(iter(self.kept)))
            self.kept[key] = cut
        return _spliced([over(a, c), cut])


class _SeenWindows:
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
    nothing to gain: the first check is the fastest plan). Ten translated 60 mm airfoils:
    80 re-plans → 8 (the first cut's). Found by a key (piece count, kinds, lengths to
    1e-6 mm), then compared in full."""

    _FIELDS = (*_Levers._SCALED, "settle_s", "shaped", "ineffective")

    def __init__(self, st: _Setup):
        self.st = st
        self.by_key: dict = {}

    def _cut(self, a: int, b: int) -> int:
        """The first feed piece of window a … b − 1 (b: none)."""
        feed = np.flatnonzero(~np.asarray(self.st.pieces.rapid[a:b], dtype=bool))
        return a + int(feed[0]) if feed.size else b

    def _key(self, c: int, b: int) -> tuple:
        p = self.st.pieces
        return (b - c, np.asarray(p.kind[c:b]).tobytes(),
                round(float(np.sum(p.length_mm[c:b])), 6))  # fmt: skip

    def _same(self, c: int, b: int, c2: int) -> bool:
        p, init = self.st.pieces, self.st.initial
        sl, sl2 = slice(c, b), slice(c2, c2 + (b - c))
        for f in ("kind", "rapid", "stop_after", "pass_after", "dwell_after_s"):
            if not np.array_equal(getattr(p, f)[sl], getattr(p, f)[sl2]):
                return False
        close = [(p.length_mm, 1e-9, 1e-12), (p.kappa_max_per_mm, 1e-9, 1e-12),
                 *((getattr(init, f), 1e-9, 0.0) for f in _Levers._SCALED)]  # fmt: skip
        if not all(_close(x[sl], x[sl2], r, t) for x, r, t in close):
            return False
        for f in ("start_mm", "end_mm"):
            x = getattr(p, f)
            if not _close(x[:, sl] - x[:, c : c + 1], x[:, sl2] - x[:, c2 : c2 + 1], 0.0, 1e-9):
                return False
        return all(_close(getattr(p, f)[:, sl], getattr(p, f)[:, sl2], 0.0, 1e-9)
                   for f in ("tangent_start", "tangent_end"))  # fmt: skip

    def warm(self, final: _Levers, a: int, b: int) -> tuple[_Levers, int | None]:
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

    def add(self, lev: _Levers, a: int, b: int) -> None:
        c = self._cut(a, b)
        if c < b:
            saved = {f: getattr(lev, f)[c:b].copy() for f in self._FIELDS}
            settle = float(lev.settle_s[c - 1]) if c > a else 0.0
            self.by_key.setdefault(self._key(c, b), []).append((c, saved, settle))


def _window_plan(st: _Setup, lev: _Levers, result, parts: list, n: int, later,
                 iterations: int) -> Plan:  # fmt: skip
    """The plan of a cut window (:attr:`Window.plan`): the final profiles of windows
    0 … n − 1 (``parts``, shared and only appended to), then the stand-in ``later`` for
    the pieces after (None: the last window), spliced whole."""
    profile = _spliced([*parts[:n], *([] if later is None else [later])])
    return st.plan(lev, (result[0], profile, *result[2:]), iterations)


#: Servo periods at the end of the windows before a cut window whose phases its re-plans
#: keep (:func:`_compacted`): its check reads the profile from one period before its start.
WINDOW_KEEP_PERIODS = 4


def _compacted(profile: Profile, keep_s: float) -> Profile:
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

    return Profile(profile.total_length_mm, profile.duration_s, profile.junction_speeds_mm_s,
                   profile.piece_peak_speed_mm_s, profile.piece_start_mm,
                   profile.piece_start_time_s, merged(times, 0.0),
                   merged(profile.phase_duration_s, t_i), merged(profile.phase_s0_mm, 0.0),
                   merged(profile.phase_v0_mm_s, 0.0), merged(profile.phase_a0_mm_s2, 0.0),
                   merged(profile.phase_jerk_mm_s3, jerk),
                   merged(profile.phase_piece_index, 0))  # fmt: skip


def _close(a: np.ndarray, b: np.ndarray, rtol: float, atol: float) -> bool:
    """``np.allclose(a, b, rtol, atol)`` (equal infinities close, NaN never) without its
    overhead: a repeated cut compares a dozen columns per cut window."""
    with np.errstate(invalid="ignore"):
        near = np.isfinite(b) & (np.abs(a - b) <= atol + rtol * np.abs(b))
        return bool(np.all((a == b) | near))


def _placeholder(pieces: PieceList, lev: _Levers, first: int, whole=None) -> Profile:
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
        return Profile(whole.total_length_mm - s0, whole.duration_s - t0,
                       np.append(0.0, whole.junction_speeds_mm_s[first + 1 :]),
                       whole.piece_peak_speed_mm_s[first:],
                       whole.piece_start_mm[first:] - s0, whole.piece_start_time_s[first:] - t0,
                       whole.phase_start_time_s[cut:] - t0, whole.phase_duration_s[cut:],
                       whole.phase_s0_mm[cut:] - s0, whole.phase_v0_mm_s[cut:],
                       whole.phase_a0_mm_s2[cut:], whole.phase_jerk_mm_s3[cut:],
                       whole.phase_piece_index[cut:] - first)  # fmt: skip
    length = np.asarray(pieces.length_mm[first:], dtype=float)
    cap = np.asarray(lev.caps[first:], dtype=float)
    dur = np.maximum(length / cap, np.cbrt(6.0 * length / lev.j_up[first:]))
    start_t = np.concatenate(([0.0], np.cumsum(dur)[:-1]))
    start_s = np.concatenate(([0.0], np.cumsum(length)[:-1]))
    moving = np.flatnonzero(length > 0.0)
    z = np.zeros(moving.size)
    jerk = 6.0 * length[moving] / dur[moving] ** 3
    return Profile(float(length.sum()), float(dur.sum()), np.append(0.0, cap), cap.copy(),
                   start_s, start_t, start_t[moving], dur[moving], start_s[moving], z,
                   z.copy(), jerk, moving)  # fmt: skip


def _spliced(parts: list) -> Profile:
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
        float(s0[-1] + parts[-1].total_length_mm), float(t0[-1] + parts[-1].duration_s),
        cat([p.junction_speeds_mm_s[:-1] for p in parts] + [parts[-1].junction_speeds_mm_s[-1:]]),
        cat([p.piece_peak_speed_mm_s for p in parts]),
        cat([p.piece_start_mm + s for p, s in zip(parts, s0)]),
        cat([p.piece_start_time_s + t for p, t in zip(parts, t0)]),
        cat([p.phase_start_time_s + t for p, t in zip(parts, t0)]),
        cat([p.phase_duration_s for p in parts]),
        cat([p.phase_s0_mm + s for p, s in zip(parts, s0)]),
        cat([p.phase_v0_mm_s for p in parts]), cat([p.phase_a0_mm_s2 for p in parts]),
        cat([p.phase_jerk_mm_s3 for p in parts]),
        cat([p.phase_piece_index + n for p, n in zip(parts, n0)]))


def _first_sample_at(planned: PieceList, profile: Profile, piece: int, period_s: float) -> int:
    """The first servo sample k at or after the wall time [s] at which ``piece`` starts
    (its profile time plus the dwells before it): t_k = k·T_s ≥ that time."""
    t_wall = float(profile.piece_start_time_s[piece]) + float(
        np.sum(planned.dwell_after_s[:piece]))
    return int(np.ceil(t_wall / period_s - 1e-9))


class _JoinedChecks:
    """The compact :class:`Check` of a program's cut windows, joined as they come, their
    samples one after the other (:attr:`Check.samples`: without the held tails of the
    windows' checks): over-limit samples, piece runs, counts before each restart and
    statistics. No window's check is kept: each holds counts for every restart of the
    program (one per rapid), so keeping them all grew as cuts × rapids (512 MB at 4,000
    cuts); the counts are summed as they come."""

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
        overs = Overs(int(off[-1]), cat([p[0] + d for p, d in zip(self.parts, off)]),
                      cat([p[1] for p in self.parts]), cat([p[2] for p in self.parts]),
                      cat([p[3] for p in self.parts]),
                      cat([p[4] + d for p, d in zip(self.parts, off)]), self.restart,
                      self.worst)  # fmt: skip
        total = sum(self.n)
        stats = self.stats
        rms = float(np.sqrt(sum(s["contour_true_rms_um"] ** 2 * m for s, m in zip(stats, self.n))
                            / total)) if total else 0.0  # fmt: skip
        joined = {"contour_true_max_um": max(s["contour_true_max_um"] for s in stats),
                  "contour_true_rms_um": rms,
                  "contour_eq29_max_um": max(s["contour_eq29_max_um"] for s in stats)}
        return Check(None, None, None, overs, joined, overs, total)


def _cut_distance_after_rapids(response: Response, ref: Reference, profile: Profile,
                               after_rapid: np.ndarray, waiting: np.ndarray, rapid: np.ndarray,
                               index: PathIndex) -> None:  # fmt: skip
    """Measure the first cutting samples after a rapid against the cut only (in place).

    The path the contour error is measured against includes the rapids, so a tool still
    arriving along a rapid looks on the path although the cut has moved off; it is 'on the
    path' only if it is on the cut. Only samples whose distance window (module doc of
    :mod:`~nurbscnc.plan.dynamics`: ±2|e| of arc length) reaches back across the rapid's
    end are affected; their reference lies on the cut, so |e| bounds the distance."""
    n = ref.t_s.size
    lag = np.sqrt(np.einsum("ij,ij->i", response.axis_error_mm[:n], response.axis_error_mm[:n]))
    start = profile.piece_start_mm[ref.piece]
    fix = np.flatnonzero(after_rapid[ref.piece] & ~waiting & (ref.s_mm - 2.0 * lag <= start))
    if fix.size:
        response.contour_mm[fix] = index.distance_mm(response.actual_mm[fix], lag[fix] + 1e-12,
                                                     exclude=rapid)  # fmt: skip


def _cycle_time(result) -> float:
    planned, profile = result[0], result[1]
    return total_time_s(profile, dwell_times(planned.dwell_after_s, profile)[1])


def segment_times_s(plan: Plan, key=None) -> dict:
    """Motion time [s] of each program segment (its pieces' span in the profile), keyed by
    the segment's index, or by ``key(index)`` (``str`` for the JSON summary: one dict made,
    not a second one from the first — a 1,000,000-line program's pair had cost 100 MB at
    the peak of `run --json`)."""
    prof = plan.profile
    ends = np.append(prof.piece_start_time_s[1:], prof.duration_s)
    span = ends - prof.piece_start_time_s
    seg = np.asarray(plan.pieces.segment)
    sums = np.bincount(seg, weights=span)
    present = np.flatnonzero(np.bincount(seg))  # the segments that have pieces, in order
    # (lists, not numpy scalars one by one: 200,000 segments in CAM programs)
    keys = present.tolist()
    return dict(zip(keys if key is None else map(key, keys), sums[present].tolist()))
