"""The look-ahead planner: pieces → jerk-limited profile → dynamics check → re-plan.

SPEC §7–§8 and §10. The profile is planned over the whole program (bidirectional scan) with
per-piece limits (:func:`~nurbscnc.plan.axes.piece_limits`: the axes' feed, acceleration and
jerk along each piece); the predicted contour error is then checked with the servo model,
and where it exceeds ε_max the plan is changed and re-planned until the error is within it.

Local shaping (``dynamics="local"``, :mod:`~nurbscnc.plan.shaping`). Each over-limit sample
is answered where its error is caused, never by the cruise of a whole long piece:

- near the end of a rapid that a cut follows: the settle there (the reference waits at the
  cut's start; 0 until the check needs it, at most 5/|pole|
  :func:`~nurbscnc.plan.junctions.settle_time_s`); while it waits nothing is checked, and the
  first cut samples are measured against the cut only;
- near a planned stop (from :data:`~nurbscnc.plan.shaping.STOP_BEFORE_S` before to
  :data:`~nurbscnc.plan.shaping.STOP_WINDOW_S` after it): the overshoot of the stop and the
  corner cut after it. The descent jerk of the run of pieces that ends there (and, for
  samples after the restart, the rise jerk of the run that leaves it) is lowered, by 0.95
  (ε/e)^(1/p) with p measured from the last try (the jerk at the end of a stop is what
  excites the servo: a softer stop costs milliseconds), from at most A·|p| (a larger jerk is
  a step to the servo). Where that hardly moves the error
  (:data:`~nurbscnc.plan.shaping.STOP_INEFFECTIVE_P`), the descent's and rise's acceleration
  is lowered with the jerk; only where that fails too does the feed lever below take the
  stop's samples (a helix stopping into another plane keeps its feed and gets a softer stop
  instead of a feed lowered over the whole helix). The same holds for a *slowdown* between
  two long pieces (a feed drop at a junction passed without stopping, each side ≥
  :data:`~nurbscnc.plan.shaping.SLOWDOWN_PIECE_S` of motion): its error is the transition's,
  not the cruise of the long piece before it;
- else (a curve): the feed of the pieces in the blamed window
  (:func:`~nurbscnc.plan.shaping.local_factors`): NURBS cells and PH corners are short, so
  this is the feed over that window only. A long piece (≥
  :data:`~nurbscnc.plan.shaping.LONG_PIECE_S`) blamed only for samples at its ends keeps its
  feed where another lever answers each of them (the feed of the short piece a sample lies
  on, the long piece's descent into the junction or its rise out of it:
  :func:`~nurbscnc.plan.shaping._long_edges`): a tight arc between two long tangent pieces
  no longer costs their whole cruise. A blamed piece whose jerk is above A·|p| gets that
  jerk first. A piece whose lowered feed twice in a row hardly moved the error is no feed
  lever (a short piece crossed in transition, a ringing servo's error from further back):
  its acceleration and jerk are lowered instead, and the samples near it blame the servo's
  whole memory.

The check converges on every program (:mod:`~nurbscnc.plan.converge`): after
:data:`~nurbscnc.plan.converge.LOCAL_ITERATIONS` re-plans a fallback scales every lever
(feed, acceleration, jerk) of the blamed pieces, then of all cutting pieces, and waits the
full settles; the servo error goes to 0 with v, a, j. Once a plan is within ε_max, an
improvement phase bisects every shaped lever between its feasible value and its value before
shaping, then tries the feed caps with the most time to gain alone at that value (a joint
try fails on any one lever; a failed restore is shaped again, its stops starting afresh from
their transitions), and keeps the fastest plan within ε_max — when it may gain more than
:data:`~nurbscnc.plan.converge.IMPROVE_MIN_GAIN` of the motion's time (it cannot gain more
than the shaping cost: a long program shaped at a few corners skips six checks for a few
ms). Shaping depends on the programmed feed only through the caps; the bisection leaves each
lever within :data:`~nurbscnc.plan.levers.IMPROVE_RATIO` of its bound, so plans at two feeds
agree to that resolution on the paper's machine (a higher F is never slower by more than it,
or than the skipped improvement's gain bound); with a far larger jerk limit and an axis
without a servo model a higher F can be slower: the shaping is path-dependent.

``dynamics="global"`` is the paper's rule (V_max becomes the feed where the error occurred,
the whole program re-planned; full settles); ``"off"`` plans the kinematics only (no
settles: nothing is checked).

Long programs. Everything per piece is whole-array work on the columns of the
:class:`~nurbscnc.plan.pieces.PieceList` (junctions, dwells, blame), the contour error is
measured near each reference point only (:func:`~nurbscnc.plan.dynamics.path_response`), and
a local re-plan changes the levers of all offending pieces at once, so a program needs a few
iterations, whatever its length. The check (:mod:`~nurbscnc.plan.check`) runs
:data:`~nurbscnc.plan.check.CHECK_WINDOW` servo samples at a time with the servo state
carried (:class:`~nurbscnc.plan.check.Checker`) and keeps only the over-limit samples, the
piece of every sample run-length coded and running statistics
(:class:`~nurbscnc.plan.checkresult.Overs`): its memory grows with the pieces, not with the motion
time, and the plan is the one the whole-array check gives (``plan_checked(...,
keep_reference=True)`` keeps the whole reference and response for plots and reports). Runs
of tiny tangent-continuous pieces at one cap and one set of limits are planned as one by
:func:`~nurbscnc.plan.profile_plan.plan_profile`. A program of several cuts is planned cut window
by cut window (:mod:`~nurbscnc.plan.windows`).

This module is the loop: the setup of a program (:class:`~nurbscnc.plan.setup.Setup`), the
levers loop run on it whole or window by window, and the check's result.
"""

from __future__ import annotations

import functools
from collections import deque

import numpy as np

from nurbscnc.machine.profile import Machine
from nurbscnc.plan.check import CHECK_WINDOW, Checker
from nurbscnc.plan.checkresult import Check, JoinedChecks
from nurbscnc.plan.converge import converge
from nurbscnc.plan.levers import Levers
from nurbscnc.plan.limits import check_point_count
from nurbscnc.plan.options import Dynamics, LookaheadOptions
from nurbscnc.plan.plans import Plan
from nurbscnc.plan.sampler import EXACT, ReferenceSampler
from nurbscnc.plan.setup import Setup
from nurbscnc.plan.timing import sample_count
from nurbscnc.plan.window_levers import WindowSetup
from nurbscnc.plan.windows import (
    WINDOW_KEEP_PERIODS,
    OwnProfiles,
    SeenWindows,
    Window,
    compacted,
    cut_windows,
    first_sample_at,
    placeholder,
    spliced,
    window_plan,
)


def plan_program(program, machine: Machine, options: LookaheadOptions | None = None) -> Plan:
    """Plan a whole interpreted program (SPEC §1: modules 1–4); :func:`plan_checked` without
    the check's result."""
    return plan_checked(program, machine, options)[0]


def plan_checked(
    program,
    machine: Machine,
    options: LookaheadOptions | None = None,
    reference: ReferenceSampler = EXACT,
    keep_reference: bool = True,
    window: int = CHECK_WINDOW,
    columns=None,
) -> tuple[Plan, Check | None]:
    """Plan a whole interpreted program and check it (SPEC §1: modules 1–4, §8): pieces,
    profile, then the dynamics check on the plan's reference points, re-planning until the
    predicted contour error is within ε_max. ``reference``: the
    :class:`~nurbscnc.plan.sampler.ReferenceSampler` (pieces, profile, period_s, k0=0,
    k1=None) → :class:`~nurbscnc.plan.timing.Reference` of the points k0…k1−1 the check
    simulates (default: the exact ones; the interpolator passes its own,
    :func:`nurbscnc.interpolate.sample.reference_sampler`); one that is not ``windowed`` is
    called as (pieces, profile, period_s) for all of them (a plain function is taken as
    such, :func:`~nurbscnc.plan.sampler.as_sampler`); its ``check_begins(k0)`` is called as
    each check begins at sample k0 (a progress display: a re-plan may sample only from
    where its plan changed).

    A program of several cuts (``dynamics="local"``) is planned cut window by cut window
    (:func:`plan_windows`); the plan is the last window's (all windows final) and the check
    the windows' checks joined (with ``keep_reference``: re-run once on it as one program).
    The check runs ``window`` servo samples at a time
    (:class:`~nurbscnc.plan.check.Checker`), so its memory grows with the pieces, not with
    the motion time; the plan does not depend on ``window``. ``keep_reference``: the final
    :class:`~nurbscnc.plan.checkresult.Check` holds the whole reference and response (plots,
    reports, the output); False: only the over-limit samples and the statistics (long
    programs). ``columns``: the program's :class:`~nurbscnc.program.columns.SegmentColumns`
    if read already. Returns the plan and the final check (None with ``dynamics="off"``)."""
    options = options or LookaheadOptions()
    st = Setup(program, machine, options, reference, keep_reference, window, columns)
    if options.dynamics != Dynamics.LOCAL or cut_windows(st.pieces).size == 1:
        lev, result, iterations = converge(st, st.initial.copy(), st.evaluate)
        return st.plan(lev, result, iterations), result[2]
    whole = st.checker
    st.checker = Checker(
        st.pieces, machine, reference, st.eps_mm, st.settle_rows, window, False, whole.allowance
    )
    joined = JoinedChecks()

    def windows():
        for w in _windows_of(st):
            joined.add(w.check)
            yield w

    last = deque(windows(), maxlen=1)[0]  # one window's plan held at a time
    if keep_reference:  # the whole reference and response: one more pass over the samples
        return last.plan, whole.run(last.plan.pieces, last.plan.profile)
    return last.plan, joined.check()


def plan_windows(
    program,
    machine: Machine,
    options: LookaheadOptions | None = None,
    reference: ReferenceSampler = EXACT,
    window: int = CHECK_WINDOW,
    columns=None,
):
    """Plan a program cut window by cut window (:func:`~nurbscnc.plan.windows.cut_windows`),
    yielding each :class:`~nurbscnc.plan.windows.Window` as soon as it is final: its levers
    loop (shaping, fallback, improvement) sees only its own pieces and samples, the servo
    starting from the state the previous window's final plan left it in
    (:class:`~nurbscnc.servo.model.AxesStream`), its end checked as if the program ended
    there (the held tail on a copy of that state); the plan of a program cut short after
    window n is the first n windows'. One window (and ``dynamics`` other than "local") is
    :func:`plan_checked`'s plan."""
    options = options or LookaheadOptions()
    st = Setup(program, machine, options, reference, False, window, columns)
    if options.dynamics != Dynamics.LOCAL or cut_windows(st.pieces).size == 1:
        lev, result, iterations = converge(st, st.initial.copy(), st.evaluate)
        n = sample_count(result[0], result[1], st.period)
        plan = st.plan(lev, result, iterations)
        yield Window(0, 0, st.k, 0, n, lambda: plan, result[2], iterations)
        return
    yield from _windows_of(st)


def _windows_of(st: Setup):
    """The windows of :func:`plan_windows` (several cuts, local dynamics).

    Each window's profile is planned from its own pieces only
    (:class:`~nurbscnc.plan.windows.OwnProfiles` over pieces a … b − 1: the junctions at a and
    b are rests, so nothing outside the window changes it): the plan of window w is the
    final windows before it, then its own profile, then a placeholder for the pieces not
    planned yet (:func:`~nurbscnc.plan.windows.placeholder`: never sampled before the
    window's end), spliced into one profile (:func:`~nurbscnc.plan.windows.spliced`). A
    re-plan thus costs the window's pieces, not the program's."""
    starts = cut_windows(st.pieces)
    ends = np.append(starts[1:], st.k)
    final = st.initial.copy()  # windows before the current one final, later ones kinematic
    seen = SeenWindows(st)
    stand_in = placeholder(st.pieces, st.initial, 0)  # every window's "later", rebased
    stream = None
    parts: list = []  # the final profiles of the windows so far, each from time 0
    done = None  # their splice, compacted: what the re-plans put before a window
    keep_s = WINDOW_KEEP_PERIODS * st.period
    total_iterations = 0
    own_profile = OwnProfiles(st)
    for w, (a, b) in enumerate(zip(starts.tolist(), ends.tolist())):
        is_last = b == st.k
        later = None if is_last else placeholder(st.pieces, st.initial, b, stand_in)
        # What the re-plans splice around the window's own profile: the windows before and
        # the stand-in after, their phases outside the periods the check reads merged.
        around = (done, None if later is None else compacted(later, 0.0))

        # The loop works on the levers of the pieces around the window only (the same
        # numbers as on all of them: :mod:`~nurbscnc.plan.window_levers`).
        view = WindowSetup(st, a, b, final, done)
        warm, repeated_cut = seen.warm(final, a, b)
        warm = view.levers(warm)

        def plan_of(lv: Levers, a=a, b=b, around=around, cut=repeated_cut, view=view):
            planned = view.planned(lv)
            own = own_profile(lv, a, b, cut, view.lo)
            profile = spliced([x for x in (around[0], own, around[1]) if x is not None])
            check_point_count(planned, profile, st.machine)  # before anything is sampled
            return planned, profile, own

        def rows_of(planned, profile, a=a, b=b, is_last=is_last):
            k0 = first_sample_at(planned, profile, a, st.period)
            if is_last:
                k1 = sample_count(planned, profile, st.period)
                return (k0, k1, True, profile.duration_s, st.k - 1)
            k1 = first_sample_at(planned, profile, b, st.period)
            return (k0, k1, False, float(profile.piece_start_time_s[b]), b - 1)

        def evaluate(lv: Levers, plan_of=plan_of, rows_of=rows_of, stream=stream):
            planned, profile, own = plan_of(lv)
            check = st.checker.run(planned, profile, rows_of(planned, profile), stream)
            return planned, profile, check, own, st.checker.stream_out

        lev, result, iterations = converge(view, warm, evaluate, view.confine, plan_of)
        lev = view.program_levers(lev)
        seen.add(lev, a, b)
        final = lev
        stream = result[4]  # the servo's state after this window's final plan
        parts.append(result[3])
        done = compacted(spliced([x for x in (done, result[3]) if x is not None]), keep_s)
        total_iterations += iterations
        rows = rows_of(result[0], result[1])  # (per-piece columns and duration: whole)
        # The window's plan with every phase (the re-plans' profiles had merged some), made
        # when asked for (O(program) each: a plan per window made many cuts quadratic).
        make = functools.partial(
            window_plan, st, lev, result, parts, len(parts), later, total_iterations
        )
        yield Window(w, a, b, rows[0], rows[1], make, result[2], iterations)
