"""The levers loop of one plan (module docstring of :mod:`~nurbscnc.plan.lookahead`):
re-plan until the check is within ε_max (local shaping, then the fallback), then the
improvement phase that bisects the shaped levers back towards their brackets."""

from __future__ import annotations

import numpy as np

from nurbscnc.errors import PlanningError
from nurbscnc.plan.levers import IMPROVE_RATIO, Levers
from nurbscnc.plan.options import Dynamics
from nurbscnc.plan.plans import cycle_time_s
from nurbscnc.plan.setup import Setup

#: Re-plans with the local levers before the fallback takes over.
LOCAL_ITERATIONS = 16
#: Fallback re-plans on the blamed pieces before all cutting pieces are scaled.
FALLBACK_LOCAL_ITERATIONS = 8
#: Re-plans of the improvement phase (bisection of the shaped levers).
IMPROVE_ITERATIONS = 6
#: Then, at most this many feed caps tried alone at their upper brackets, the largest time
#: gains first (:func:`_improve`): a joint try fails on any one lever (a junction's error)
#: while a long piece that kept half its feed may be restored alone within ε_max.
RESTORE_PIECES = 3
#: A restore that fails is shaped again, at most this many re-plans, if it gains at least
#: :data:`RESHAPE_MIN_GAIN_S` [s]: the feed lever had taken a stop whose transition (jerk,
#: then acceleration) was never tried with this cap.
RESHAPE_ITERATIONS = 3
RESHAPE_MIN_GAIN_S = 0.02
#: Then, at most this many halvings of the settles after rapids
#: (:meth:`_Improvement.shorten_settles`).
SETTLE_HALVINGS = 4
#: Then, if the restore still fails, at most this many re-plans of that cap alone between
#: the plan's and the restore's (false position on the error).
RESTORE_SECANTS = 3
#: The improvement phase runs only if it may gain more than this fraction of the planned
#: motion's time (a cut window's own): what it can gain is at most the time the shaping
#: cost (the plan before shaping is the fastest its levers allow). A long program whose
#: shaping touched a few corners gains a few ms of minutes from it, for six more checks;
#: a threshold much above this skips gains worth having in the cut windows of a program of
#: many cuts (each window's bound is its own).
IMPROVE_MIN_GAIN = 3e-4


def converge(st: Setup, lev: Levers, evaluate, confine=lambda lv: None, plan_of=None):
    """The levers loop (module docstring of :mod:`~nurbscnc.plan.lookahead`) from ``lev``
    (changed in place): re-plan until the check is within ε_max (local shaping, then the
    fallback), then the improvement phase. ``evaluate(levers)`` → (planned, profile, check);
    ``confine(levers)`` undoes changes outside the levers' scope (a cut window);
    ``plan_of(levers)`` → (planned, profile, …) without the check (default
    :meth:`Setup.plan_of`). Returns (final levers, result, re-plans)."""
    options, eps_mm, initial = st.options, st.eps_mm, lev.copy()
    iterations = 0
    fastest_s = None  # the cycle time before shaping
    while True:
        result = evaluate(lev)
        if fastest_s is None:
            fastest_s = cycle_time_s(result)
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
    shaped_s = cycle_time_s(result)
    if (
        options.dynamics == Dynamics.LOCAL
        and st.any_shaped(lev)
        and _may_gain(result, shaped_s, fastest_s)
    ):
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
        shaped_s = cycle_time_s(result)
        if np.any(hi.caps > lev.caps * IMPROVE_RATIO) and _may_gain(
            result, shaped_s, cycle_time_s((plan_of or st.plan_of)(hi))
        ):
            lev, result, n = _improve(st, lev, result, hi, evaluate, confine)
            iterations += n
    return lev, result, iterations


def _improve(st: Setup, lev: Levers, result, hi: Levers, evaluate, confine):
    """The improvement phase (:func:`converge`) from the feasible levers ``lev`` (their check
    ``result``) towards the upper brackets ``hi``: at most :data:`IMPROVE_ITERATIONS` tries,
    each halfway (:meth:`_Improvement.bisect`), then the restores of the feed caps with the
    most time to gain, each alone (:meth:`_Improvement.restore`). Returns (best levers,
    their result, re-plans)."""
    run = _Improvement(st, lev, result, evaluate, confine)
    del result
    hi = run.bisect(hi)
    # Restores: the joint tries raise every lever at once and fail on any one of them, so
    # a feed lowered where it did not help (the error was a junction's, answered later by
    # another lever) stays low. The caps with the most time to gain are tried alone, among
    # those this plan may change (``confine`` keeps a cut window's others at their final).
    reach = run.best.copy()
    reach.caps = np.maximum(run.best.caps, hi.caps)
    confine(reach)
    gain = _restore_gains(st, run.best, reach)
    for p in np.argsort(-gain, kind="stable")[:RESTORE_PIECES].tolist():
        if gain[p] < st.period:
            break
        run.restore(p, reach.caps[p], gain[p])
    run.shorten_settles()
    return run.finish()


class _Improvement:
    """One improvement phase (:func:`_improve`): the best plan so far (``best`` levers, their
    cycle time ``best_time`` [s], worst error ``best_worst_mm`` [mm] and ``best_result``),
    the last try's ``result`` and the re-plans made (``iterations``).

    A check that keeps its reference and response holds hundreds of MB: then only one
    plan's is held at a time (a try drops the last one first), and the best plan is re-made
    at the end if a later try replaced its result; a check without them is small and the
    best's result is kept."""

    def __init__(self, st: Setup, lev: Levers, result, evaluate, confine):
        self.st, self.evaluate, self.confine = st, evaluate, confine
        self.keep_best = not st.checker.keep
        self.iterations = 0
        self.result = result
        self.take(lev.copy(), result)

    def take(self, levers: Levers, res) -> None:
        """The best plan so far: these levers, their check."""
        self.best, self.best_time = levers, cycle_time_s(res)
        self.best_worst_mm = res[2].overs.worst_mm
        self.best_result = res if self.keep_best else None

    def attempt(self, levers: Levers) -> float:
        """Plan and check ``levers`` (:attr:`result`; the last one dropped first): the
        worst error [mm]."""
        self.result = None
        self.result = self.evaluate(levers)
        self.iterations += 1
        return self.result[2].overs.worst_mm

    def bisect(self, hi: Levers) -> Levers:
        """At most :data:`IMPROVE_ITERATIONS` tries of the best levers halfway to the upper
        brackets ``hi`` (:meth:`Levers.toward`). A try within ε_max is kept if it is
        faster (a feasible raise that is slower ends the tries); a failing one narrows the
        brackets of the levers that the shaping rule blames for it (found by applying the
        rule to a copy). Returns the brackets."""
        st = self.st
        for _ in range(IMPROVE_ITERATIONS):
            trial = self.best.toward(hi)
            if trial is None:
                break
            if self.attempt(trial) <= st.eps_mm:
                t = cycle_time_s(self.result)
                if t > self.best_time:  # a feasible raise that is slower (rare): stop here
                    self.result = None
                    break
                self.take(trial, self.result)
            else:
                probe = trial.copy()
                st.shape(probe, self.result)
                self.confine(probe)
                hi = hi.narrowed(trial, probe)
                self.result = None
        return hi

    def restore(self, p: int, cap_mm_s: float, gain_s: float) -> None:
        """The feed cap of piece ``p`` tried alone at ``cap_mm_s`` (its upper bracket; the
        cruise there would save ``gain_s`` [s], :func:`_restore_gains`), kept if within
        ε_max and faster. A restore that gains at least :data:`RESHAPE_MIN_GAIN_S` and
        fails is shaped again (at most :data:`RESHAPE_ITERATIONS` re-plans, the stops'
        history cleared so each starts from its transition) while the shaping keeps that
        cap above the plan's; then that cap alone is searched between the two
        (:meth:`secant`)."""
        st = self.st
        before = (self.best, self.best_worst_mm)
        trial = self.best.copy()
        trial.caps[p] = cap_mm_s
        shapes = RESHAPE_ITERATIONS if gain_s >= RESHAPE_MIN_GAIN_S else 0
        if shapes:
            trial.stop_history = None  # every stop starts again from its transition
        alone = None  # (cap, error [mm]) of the restore alone
        for i in range(shapes + 1):
            worst = self.attempt(trial)
            if alone is None:
                alone = (cap_mm_s, worst)
            if worst <= st.eps_mm or i == shapes:
                break
            st.shape(trial, self.result)
            self.confine(trial)
            if trial.caps[p] <= self.best.caps[p] * IMPROVE_RATIO:  # nothing left to gain
                break
        if (
            self.result[2].overs.worst_mm <= st.eps_mm
            and cycle_time_s(self.result) < self.best_time
        ):
            self.take(trial, self.result)
        else:
            self.result = None
        if shapes and self.best.caps[p] < alone[0]:
            self.secant(p, alone)
        elif shapes and self.best is not before[0] and before[0].caps[p] < alone[0]:
            # The reshaped restore holds the cap with softer transitions; the cap alone
            # between the plan's and the restore's, with the transitions as they were, may
            # be faster still (kept only if it is): which of the two wins depends on the
            # feed the search started from, and a higher F must not end slower.
            self.secant(p, alone, before)

    def secant(self, p: int, alone: tuple, base: tuple | None = None) -> None:
        """The cap of piece ``p`` alone, between the plan's (within ε_max; the shaping's if
        it found one, whose feed lever steps by up to 2×) and the restore's ``alone`` (cap,
        error [mm]; above it): at most :data:`RESTORE_SECANTS` re-plans by false position
        on the error, which grows about linearly with the cruise feed where the cap is what
        limits it (a line or helix in space whose z has no servo model lags ∝ v off the
        path). ``base`` (levers, their worst error [mm]): search from those levers instead
        of the best's, keeping a try only if it beats the best (a feasible slower one moves
        the lower end up)."""
        st = self.st
        levers, worst_mm = base if base is not None else (self.best, self.best_worst_mm)
        lo, hi_cap = (levers.caps[p], worst_mm), alone
        for _ in range(RESTORE_SECANTS):
            gap = hi_cap[0] - lo[0]
            if gap <= lo[0] * (IMPROVE_RATIO - 1.0):
                break
            slope = (hi_cap[1] - lo[1]) / gap
            cap = lo[0] + (st.eps_mm - lo[1]) / slope if slope > 0.0 else lo[0] + gap / 2
            trial = levers.copy()
            trial.caps[p] = min(max(cap, lo[0] + 0.1 * gap), hi_cap[0] - 0.1 * gap)
            worst = self.attempt(trial)
            if worst > st.eps_mm:
                hi_cap, self.result = (trial.caps[p], worst), None
                continue
            lo = (trial.caps[p], worst)
            if cycle_time_s(self.result) >= self.best_time:  # within ε_max yet slower
                self.result = None
                if base is None:
                    break
                continue
            self.take(trial, self.result)
            levers = trial

    def shorten_settles(self) -> None:
        """The settles after rapids alone, halved while that is within ε_max and faster (at
        most :data:`SETTLE_HALVINGS` re-plans; none when ``confine`` leaves no settle to
        halve: a cut window's plan would be the same). A settle is extended past the last over-limit
        sample after its restart, as far as the cut's feed carries them, before the rapid's
        descent is softened; the joint tries raise every lever at once and fail on any one:
        so a higher F kept a longer settle than its softened descent needs (31 ms against
        12 ms, 7 % slower)."""
        st = self.st
        for _ in range(SETTLE_HALVINGS):
            trial = self.best.copy()
            long = trial.settle_s >= st.period
            trial.settle_s[long] *= 0.5
            self.confine(trial)
            if not np.any(trial.settle_s != self.best.settle_s):  # none this plan may halve
                break
            if self.attempt(trial) > st.eps_mm or cycle_time_s(self.result) >= self.best_time:
                self.result = None
                break
            self.take(trial, self.result)

    def finish(self) -> tuple:
        """(best levers, their result, re-plans): the best's result re-made if a later try
        replaced it (not counted as a re-plan)."""
        result = self.result
        if result is None:
            result = self.best_result if self.best_result is not None else self.evaluate(self.best)
        return self.best, result, self.iterations


def _restore_gains(st: Setup, best: Levers, hi: Levers) -> np.ndarray:
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
