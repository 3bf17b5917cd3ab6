"""The shaping rules of the contour check (SPEC §8, module docstring of
:mod:`~nurbscnc.plan.lookahead`): from a check's over-limit samples, which levers of which
pieces to lower — the settle after a rapid, the transitions of a stop or slowdown, the feed
over a blamed window (:func:`shape`) — and the guaranteed-feasible :func:`fallback`."""

from __future__ import annotations

import numpy as np

from nurbscnc.geometry.distinct import distinct, distinct_union
from nurbscnc.geometry.path import Kind
from nurbscnc.plan.checkresult import Overs
from nurbscnc.plan.levers import Levers
from nurbscnc.plan.pieces import PieceList
from nurbscnc.plan.profile import Profile

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
#: Factor of every lever per fallback re-plan.
FALLBACK_FACTOR = 0.6
#: Over-limit samples per block of the blame computation.
BLAME_BLOCK = 1 << 12


#: Blamed neighbours planned as one share their largest blame (:func:`_blame`); across a
#: junction between two curves each its own (:func:`_curve_changes`), only where their own
#: blames are within this ratio. The steady half-turns of a helix differ by < 0.1 %; the
#: first half-turn of Fusion 360's helical ramps at F1000 carries the entry's transient
#: after a stop (0.375 mm: 21.6 against 19.4 µm; 0.275 mm: 26.9 against 24.9 µm), and
#: sharing took the whole helix down to the entry's feed, 7 % below what its steady error
#: allows (lsim).
SHARE_RATIO = 1.03


def _blame(
    ov: Overs,
    sel: np.ndarray,
    eps_mm: float,
    joined: np.ndarray,
    window,
    jumps: np.ndarray | None = None,
) -> np.ndarray:
    """Largest over-limit error [mm] each piece shares the blame for (0: none).

    An over-limit sample (``ov``: those of ``sel`` (q,) bool with error above ``eps_mm``)
    blames the pieces of the ``window`` samples (an int, or one per sample of ``ov``) up to
    it (the servo remembers): sample i
    blames every piece with a sample in [i − window, i], i.e. the runs of
    ``ov.run_start`` from the one holding max(i − window, 0) to the one holding i; each
    piece keeps the largest. Blamed pieces that the profile plans as one (``joined``
    (k−1,): tangent-continuous junction, equal caps) share their largest blame, so their
    caps stay equal and they stay one profile unit (a run of tiny CAM pieces lowered piece
    by piece to slightly different caps would crawl) — except across a junction where one
    curve ends and another begins (``jumps`` (k−1,), default none; :func:`_curve_changes`)
    between pieces whose own blames differ by more than :data:`SHARE_RATIO`: each is
    lowered by its own error."""
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
    if jumps is not None and jumps.any():
        # Two curves each lowered by its own error where they differ: a helix's first
        # half-turn (the entry's transient) or a tight arc would otherwise take the
        # steady half-turns, or the wide arc beside it, down to its own feed.
        with np.errstate(invalid="ignore"):  # 0 · inf where a piece is not hit: no link
            alike = np.maximum(blame[:-1], blame[1:]) <= SHARE_RATIO * np.minimum(
                blame[:-1], blame[1:]
            )
        link &= alike | ~jumps
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
    lowered (halving it at every re-plan would make a slow servo's program crawl).
    """
    # Only the pieces hit are worked on (a window's few among the program's k): elsewhere
    # the factor is 1, no strike, not ineffective (each value the same as over all k).
    hit = np.flatnonzero(blame > 0.0)
    e = blame[hit]
    p = np.full(hit.size, 2.0)
    strikes = np.zeros(blame.size, dtype=np.int8)
    if history is not None:
        prev_blame, prev_factor, prev_strikes = (x[hit] for x in history)
        again = (prev_blame > 0.0) & (prev_factor < 1.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            measured = np.log(e / prev_blame) / np.log(prev_factor)
        known = again & np.isfinite(measured)
        weak = known & (measured < STOP_INEFFECTIVE_P)
        strikes[hit] = np.where(weak, np.minimum(prev_strikes, CURVE_STRIKES) + 1, 0)
        p = np.where(known, np.clip(measured, 0.25, 2.0), p)
    ineffective = strikes >= CURVE_STRIKES
    factor = np.ones(blame.size)
    lowered = ~ineffective[hit]
    factor[hit[lowered]] = np.clip(0.97 * (eps_mm / e[lowered]) ** (1.0 / p[lowered]), 0.5, 0.97)
    return factor, (blame, factor, strikes), ineffective


def _runs(caps: np.ndarray, smooth: np.ndarray, lev: Levers) -> np.ndarray:
    """Run label (k,) of each piece: the pieces the profile plans as one unit (tangent-
    continuous junctions, equal caps and equal limits; see
    :func:`~nurbscnc.plan.profile_plan.plan_profile`)."""
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
    stops = distinct_union(stops, _slowdowns(profile))
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
#: instead made plunged squares slower.)
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


#: A settle whose last extension lowered the largest error of the samples after its
#: restart by less than this factor is no lever for them (the error is the cut's own, made
#: within :data:`STOP_WINDOW_S` of the restart): it is not extended again, and the stop and
#: curve rules answer them. (Extending it to the full settle changed nothing but the time:
#: a helix after a rapid at a higher F waited 54 ms instead of 13 ms, 5 % slower.)
SETTLE_INEFFECTIVE = 0.95


def _settle_extra(
    lev: Levers,
    ov: Overs,
    near: np.ndarray,
    profile: Profile,
    settle_rows: np.ndarray,
    settle_max_s: float,
    period_s: float,
) -> tuple[np.ndarray, dict]:
    """The settles after rapids (in place): each rapid whose stop transient the over-limit
    samples after the restart are near waits longer, past the last of them (plus one
    period), unless its last extension was no lever (:data:`SETTLE_INEFFECTIVE`). Returns
    which over-limit samples this answered and the settles' history entries (key
    ("settle", r): the error and the settle it was measured with, or :data:`FEED_ONLY`).
    Samples during the settle (the reference waiting at the cut's start, τ at the restart)
    are not answered here: the rapid's overshoot is largest as the settle begins, whatever
    its length, so the stop rule answers them with the rapid's descent
    (:func:`_soften_stops`)."""
    over, tau = ov.index, ov.tau_s
    handled = np.zeros(over.size, dtype=bool)
    history, entries = lev.stop_history or {}, {}
    for i_r, r in enumerate(settle_rows.tolist()):
        t_restart = profile.piece_start_time_s[r + 1]
        hit = (near == r + 1) & (tau > t_restart)
        if not hit.any() or lev.settle_s[r] >= settle_max_s:
            continue
        if np.any((near == r + 1) & (tau <= t_restart)):
            # The rapid still overshoots during the settle: its descent is softened this
            # re-plan (the stop rule), which lowers the ringing after the restart too; the
            # settle waits for what is left of it, measured next time.
            handled |= hit
            continue
        key, e = ("settle", r), float(ov.err_mm[hit].max())
        prev = history.get(key)
        if prev == FEED_ONLY or (
            prev is not None and lev.settle_s[r] > prev[1] and e > prev[0] * SETTLE_INEFFECTIVE
        ):
            entries[key] = FEED_ONLY
            continue
        entries[key] = (e, float(lev.settle_s[r]))
        # Move the restart past the last over-limit sample (plus one period).
        first_moving = int(ov.restart_count[i_r])  # the first sample with τ > restart
        extra = max((int(over[hit].max()) - first_moving + 2) * period_s, period_s)
        lev.settle_s[r] = min(settle_max_s, lev.settle_s[r] + extra)
        handled |= hit
    return handled, entries


#: Samples before an over-limit sample on a curve whose pieces' feed is lowered [s]: the
#: curve error is quasi-static (the speed and deceleration of the last few milliseconds on
#: that curvature), so the feed is lowered where the error is, and the profile's gated
#: flanks (:func:`~nurbscnc.plan.gated.gated_rise`) brake earlier into the lowered
#: cells at the same A and J; the 30 ms window lowered the cruise of the whole approach.
CURVE_BLAME_WINDOW_S = 0.008


def _servo_jerk(j_mm_s3: np.ndarray, a_mm_s2: np.ndarray, settle_max_s: float) -> np.ndarray:
    """The jerk [mm/s³] a softening starts from: at most A·|p|, |p| = 5 / ``settle_max_s``
    the slowest servo pole's decay rate [1/s] (:func:`~nurbscnc.plan.junctions.settle_time_s`).
    A jerk phase shorter than the servo's time constant 1/|p| is a step of acceleration to
    the servo, so lowering a larger jerk by a factor changes almost nothing the check sees:
    with a jerk limit far above A·|p| the stops of an arc program were found "ineffective"
    and its feed crushed instead. The paper's machine: A·|p| = 2.3e5 > J = 5e4, nothing
    changes."""
    if not np.isfinite(settle_max_s) or settle_max_s <= 0.0:
        return j_mm_s3
    return np.minimum(j_mm_s3, a_mm_s2 * (5.0 / settle_max_s))


def _curve_changes(pieces: PieceList) -> np.ndarray:
    """Junctions (k−1,) between two curves that are each their own: where the curvature
    vector jumps (``pieces.jump_rows``) and between two arcs (each a program move of
    constant curvature; the half-turns of a helix, whose first one carries the entry's
    transient). Not inside a NURBS or a smoothed run, whose cells are one curve."""
    k = len(pieces)
    out = np.zeros(max(k - 1, 0), dtype=bool)
    out[pieces.jump_rows] = True
    arc = pieces.kind == Kind.ARC
    out |= arc[:-1] & arc[1:]
    return out


def shape(
    lev: Levers,
    ov: Overs,
    eps_mm: float,
    profile: Profile,
    pieces: PieceList,
    smooth: np.ndarray,
    settle_rows: np.ndarray,
    settle_max_s: float,
    period_s: float,
) -> None:
    """One local re-plan (in place) from a check's over-limit samples ``ov``: each is
    answered where its error is caused (module docstring of
    :mod:`~nurbscnc.plan.lookahead`): the settle after a rapid, the descent into and the
    rise out of a stop or a slowdown between long pieces (their jerk, then their
    acceleration), else the feed over the blamed window."""
    near = _stop_events(ov.tau_s, profile, period_s)
    # 1. Settle after a rapid: the rapid's own stop transient, not the cut's motion.
    handled, settles = _settle_extra(lev, ov, near, profile, settle_rows, settle_max_s, period_s)
    # 2. Stops: soften the descent of the run that ends there and, for samples after the
    #    restart, the rise of the run that leaves it.
    _soften_stops(lev, ov, near, handled, eps_mm, profile, pieces, smooth, settle_max_s)
    lev.stop_history = {**lev.stop_history, **settles}
    # 3. Curves: the feed of the pieces in the blamed window only.
    if not handled.all():
        jumps = _curve_changes(pieces)
        _lower_curves(lev, ov, handled, eps_mm, smooth, settle_max_s, period_s, profile, jumps)


def _stop_entry(e_mm: float, prev, eps_mm: float):
    """The history entry of a stop whose samples' largest error is ``e_mm`` [mm], from its
    entry ``prev`` of the last re-plan (None: first hit): :data:`FEED_ONLY` (the feed lever
    answers it), else (e, f, accel): the factor f = 0.95 (ε/e)^(1/p) of its transitions, in
    [0.3, 0.9], p measured from the last try (error ∝ factor^p, 1 at first), and whether
    the acceleration is lowered with the jerk."""
    if prev == FEED_ONLY:  # found ineffective before: the feed lever answers it
        return prev
    e = e_mm
    p = 1.0
    accel = prev is not None and prev[2]
    if prev is not None and prev[1] < 1.0 and e > 0.0:
        measured = np.log(e / prev[0]) / np.log(prev[1])
        if np.isfinite(measured):
            if measured < STOP_INEFFECTIVE_P:
                if accel:
                    # Softening this stop hardly helped: the error is the feed's (a tight
                    # curve into the stop), so the feed lever takes these samples.
                    return FEED_ONLY
                accel, measured = True, 1.0  # the jerk was no lever: the acceleration
            p = float(np.clip(measured, 0.25, 2.0))
    f = float(np.clip(0.95 * (eps_mm / e) ** (1.0 / p), 0.3, 0.9))
    return (e, f, accel)


def _soften(
    a_mm_s2: np.ndarray,
    j_mm_s3: np.ndarray,
    sel: np.ndarray,
    f: float,
    accel: bool,
    settle_max_s: float,
) -> None:
    """Soften the transition (rise or descent) limits ``a_mm_s2``, ``j_mm_s3`` of the pieces
    ``sel`` (in place): the jerk from at most A·|p| (:func:`_servo_jerk`) by ``f``, and with
    ``accel`` the acceleration too."""
    j_mm_s3[sel] = _servo_jerk(j_mm_s3[sel], a_mm_s2[sel], settle_max_s) * f
    if accel:
        a_mm_s2[sel] *= f


def _step_jerk(lev: Levers, i: int, settle_max_s: float) -> bool:
    """Whether piece ``i``'s descent jerk is above what the servo follows (A·|p|,
    :func:`_servo_jerk`): its end is a step of deceleration to the servo, whose overshoot
    grows with the deceleration, so its acceleration is the lever. An independent servo
    simulation of a rest-to-rest 90° G64 stop at 13.3 mm/s under LinuxCNC's limits (A 2450,
    J 1e9; docs/benchmarks.md): the descent at a 1000 with no jerk limit stays within
    13.5 µm and loses 9.4 ms, the jerk lowered to 1e5 instead 13.0 µm and 23.1 ms. Never the
    case on the paper's machine (J < A·|p|)."""
    j = lev.j_dn[i : i + 1]
    return bool(_servo_jerk(j, lev.a_dn[i : i + 1], settle_max_s)[0] < j[0])


def _final_descent(
    lev: Levers, pieces: PieceList, profile: Profile, smooth: np.ndarray, j: int, f: float
) -> np.ndarray:
    """The pieces (k,) bool of the final descent into the stop junction ``j``: the last
    pieces of the run that ends there (tangent-continuous junctions, equal caps; whatever
    their limits), back to where the descent from their peak speed v at the stop's lowered
    acceleration f·a begins: a piece is in it if the path from its end to the stop is
    shorter than v²/(2 f a), v the largest peak speed from it to the stop. The pieces before
    keep their braking (a run of tiny pieces brakes at each of its corners)."""
    k = len(pieces)
    joined = (smooth[1:-1] > 0) & (lev.caps[:-1] == lev.caps[1:])
    run = np.concatenate(([0], np.cumsum(~joined)))
    first = int(np.searchsorted(run, run[j - 1], side="left"))
    idx = np.arange(first, j)[::-1]  # from the stop back to the run's start
    length = pieces.length_mm[idx]
    to_stop = np.cumsum(length) - length  # from each piece's end to the stop [mm]
    v = np.maximum.accumulate(profile.piece_peak_speed_mm_s[idx])
    need = v * v / (2.0 * f * lev.a_dn[j - 1])
    n = int(np.flatnonzero(to_stop < need)[-1]) + 1 if (to_stop < need).any() else 1
    sel = np.zeros(k, dtype=bool)
    sel[idx[:n]] = True  # one stretch, from the farthest piece whose descent reaches the stop
    return sel


def _soften_stops(
    lev: Levers,
    ov: Overs,
    near: np.ndarray,
    handled: np.ndarray,
    eps_mm: float,
    profile: Profile,
    pieces: PieceList,
    smooth: np.ndarray,
    settle_max_s: float,
) -> None:
    """The stop rule (in place; ``handled`` too): for each stop or slowdown junction j the
    unhandled over-limit samples are ``near`` (:func:`_stop_events`), the descent of the run
    of pieces that ends at j and, if a sample is after the restart, the rise of the run
    that leaves it, softened by the factor of :func:`_stop_entry` (none where the feed
    lever answers the stop: those samples stay unhandled). Between two cuts, where the
    descent's jerk is above what the servo follows (:func:`_step_jerk`), the deceleration of
    the final descent (:func:`_final_descent`) is lowered instead, and the rise by √f."""
    k = len(pieces)
    err, tau = ov.err_mm, ov.tau_s
    runs = _runs(lev.caps, smooth, lev)
    stop_hist = lev.stop_history or {}
    new_hist = {}
    for j in distinct(near[(near > 0) & ~handled]).tolist():
        hit = (near == j) & ~handled
        entry = new_hist[j] = _stop_entry(float(err[hit].max()), stop_hist.get(j), eps_mm)
        if entry == FEED_ONLY:
            continue
        f, accel = entry[1], entry[2]
        # A rapid's descent too where it ends at a cut: its overshoot is the settle's error.
        # By its acceleration only at a G64 corner between two cuts (the lsim optimum's
        # case: the overshoot may use the vertex's allowance): the overshoot into a rapid
        # that follows is not checked (its samples are the rapid's), and at an exact stop
        # (G61, G61.1) the jerk softening was the faster (G61 square at F3000, J 1e9:
        # 1.859 against 1.858 s).
        by_accel = 1 <= j < k and not (pieces.rapid[j - 1] or pieces.rapid[j])
        by_accel = by_accel and not pieces.stop_after[j - 1]
        by_accel = by_accel and pieces.blend_mm[j - 1] > 0.0 and pieces.blend_mm[j] > 0.0
        by_accel = by_accel and _step_jerk(lev, j - 1, settle_max_s)
        if j - 1 >= 0 and (not pieces.rapid[j - 1] or j < k and not pieces.rapid[j]):
            if by_accel:
                sel = _final_descent(lev, pieces, profile, smooth, j, f)
                lev.a_dn[sel] = np.minimum(lev.a_dn[sel], f * lev.a_dn[j - 1])
                if accel:
                    lev.j_dn[sel] = _servo_jerk(lev.j_dn[sel], lev.a_dn[sel], settle_max_s) * f
            else:
                sel = runs == runs[j - 1]
                _soften(lev.a_dn, lev.j_dn, sel, f, accel, settle_max_s)
            lev.shaped |= sel
        t_restart = profile.piece_start_time_s[j] if j < k else np.inf
        # The rise after a descent softened by its acceleration by √f only: the overshoot
        # is mostly the descent's (lsim: after a descent at 1000 mm/s² the rise at A with
        # no jerk limit stays within ε_max), yet the servo still rings as the reference
        # restarts. Measured (bench/cam_bench.py, lsim): the rise by f gave Vectric's
        # profile 97.43 against 97.29 s; the rise left at its limits ended stops at the
        # feed lever (3dtest 53.49 against 52.83 s).
        if j < k and (tau[hit] > t_restart).any() and not pieces.rapid[j]:
            sel = runs == runs[j]
            f_up = f if accel or not by_accel else np.sqrt(f)
            _soften(lev.a_up, lev.j_up, sel, f_up, accel, settle_max_s)
            lev.shaped |= sel
        handled |= hit
    lev.stop_history = new_hist


def _curve_factors(
    lev: Levers,
    ov: Overs,
    handled: np.ndarray,
    eps_mm: float,
    smooth: np.ndarray,
    period_s: float,
    jumps: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The curve rule's cap factors (k,) and blame [mm] (k,) of the unhandled over-limit
    samples (:func:`_blame` over :data:`CURVE_BLAME_WINDOW_S`, widened to
    :data:`BLAME_WINDOW_S` near pieces found ineffective; :func:`local_factors`): once more
    if pieces were just found ineffective (their factor 1); ``jumps`` (k−1,) the junctions
    where one curve ends and another begins. Updates ``lev``'s cap history and ineffective flags."""
    narrow = max(int(round(CURVE_BLAME_WINDOW_S / period_s)), 1)
    wide = max(int(round(BLAME_WINDOW_S / period_s)), narrow)
    joined = (smooth[1:-1] > 0) & (lev.caps[:-1] == lev.caps[1:])
    history = lev.cap_history
    for _ in range(2):  # once more if pieces were just found ineffective
        window = _curve_windows(ov, lev.ineffective, narrow, wide)
        blame = _blame(ov, ~handled, eps_mm, joined, window, jumps)
        factor, lev.cap_history, found = local_factors(blame, eps_mm, history)
        found &= ~lev.ineffective
        lev.ineffective |= found
        if not found.any():
            break
    factor[lev.ineffective] = 1.0
    return factor, blame


def _lower_curves(
    lev: Levers,
    ov: Overs,
    handled: np.ndarray,
    eps_mm: float,
    smooth: np.ndarray,
    settle_max_s: float,
    period_s: float,
    profile: Profile,
    jumps: np.ndarray | None = None,
) -> None:
    """The curve rule (in place): the feed of the pieces blamed by the unhandled over-limit
    samples (:func:`_curve_factors`; ``jumps`` (k−1,): where one curve ends and another
    begins); a long piece blamed only at its ends its transition
    there instead (:func:`_long_edges`); a blamed piece whose jerk the servo cannot follow
    gets that jerk instead, and a piece whose feed is no lever its transitions."""
    factor, blame = _curve_factors(lev, ov, handled, eps_mm, smooth, period_s, jumps)
    _long_edges(lev, ov, handled, eps_mm, profile, factor, settle_max_s, period_s)
    # A blamed piece whose rise or descent jerk is above what the servo follows (A·|p|,
    # :func:`_servo_jerk`: a step of acceleration to it) gets that jerk first, its feed
    # kept this re-plan (with a jerk limit far above A·|p| the line before an arc lost a
    # third of its cruise to the step at its end). Never the case on the paper's machine
    # (J < A·|p|).
    blamed = factor < 1.0
    for acc, jerk in ((lev.a_up, lev.j_up), (lev.a_dn, lev.j_dn)):
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


#: A piece whose motion takes at least this long [s] is *long*: lowering its cruise for an
#: error made at one of its ends costs its whole length (a 25 mm arc at 1000 mm/min lost a
#: third of its feed to the 90° turn of the 0.24 mm arc after it).
LONG_PIECE_S = 0.1
#: Over-limit samples this close [s] (profile time) to the start of a long piece are its
#: entry's (the rise out of the junction while the servo still turns the corner).
EDGE_S = BLAME_WINDOW_S


def _long_edges(
    lev: Levers,
    ov: Overs,
    handled: np.ndarray,
    eps_mm: float,
    profile: Profile,
    factor: np.ndarray,
    settle_max_s: float,
    period_s: float,
) -> None:
    """Long pieces (:data:`LONG_PIECE_S`) that the curve rule blamed (``factor`` (k,) < 1)
    only for over-limit samples at their ends keep their cruise (``factor`` set to 1, in
    place) where their transition there is softened instead: the error is the
    transition's where the servo's lag meets the turn (c₂·a along the old tangent, off the
    path once it turns). The descent into the next piece answers the samples on later
    pieces whose :data:`CURVE_BLAME_WINDOW_S` reaches back into the long piece, the rise out
    of its start junction those within :data:`EDGE_S` of its start; each where the speed
    changes there (:data:`SLOWDOWN_RATIO`), by 0.95 ε/e in [0.5, 0.9] (the transient's error
    ∝ the acceleration), the jerk from the servo's (:func:`_servo_jerk`). A long piece with
    an over-limit sample past its entry (its own curvature), or whose ends do not change
    speed, keeps the feed lever, as do the pieces the samples lie on."""
    keep = ~handled & (ov.err_mm > eps_mm)
    if not (keep.any() and (factor < 1.0).any()):
        return
    idx, err, tau = ov.index[keep], ov.err_mm[keep], ov.tau_s[keep]
    run = np.searchsorted(ov.run_start, idx, side="right") - 1
    piece = ov.run_piece[run]
    k = factor.size
    start = profile.piece_start_time_s
    entry = (tau - start[piece]) <= EDGE_S
    own = np.zeros(k)  # samples inside a piece, past its entry: its own curvature
    np.maximum.at(own, piece[~entry], err[~entry])
    first = np.zeros(k)  # samples at a piece's entry
    np.maximum.at(first, piece[entry], err[entry])
    # Samples whose narrow window reaches back into the piece before theirs (one piece
    # back: a long piece is longer than the window).
    narrow = max(int(round(CURVE_BLAME_WINDOW_S / period_s)), 1)
    back = ov.run_piece[np.searchsorted(ov.run_start, np.maximum(idx - narrow, 0), "right") - 1]
    reach = back < piece
    after = np.zeros(k)
    np.maximum.at(after, back[reach], err[reach])
    v = profile.junction_speeds_mm_s
    peak = profile.piece_peak_speed_mm_s
    cand = (profile.piece_duration_s >= LONG_PIECE_S) & (factor < 1.0) & (own == 0.0)
    falls = cand & (after > 0.0) & (peak > v[1:] * SLOWDOWN_RATIO)
    rises = cand & (first > 0.0) & (peak > v[:-1] * SLOWDOWN_RATIO)
    # Spared only if every sample that blames it is answered by another lever: a lowered
    # feed in its window (pieces back…piece) other than a spared one, the rise of its own
    # piece or the descent of the piece before (else the check would see it again: a
    # ringing servo's error from further back is answered by nothing but the long feed).
    lowered = np.concatenate(([0], np.cumsum((factor < 1.0) & ~cand)))
    answered = lowered[piece + 1] > lowered[back]
    answered |= (entry & rises[piece]) | (reach & falls[back])
    unanswered = np.zeros(k + 1, dtype=np.int64)  # pieces back…piece of each: a difference
    np.add.at(unanswered, back[~answered], 1)
    np.add.at(unanswered, piece[~answered] + 1, -1)
    cand &= np.cumsum(unanswered[:-1]) == 0
    falls &= cand
    rises &= cand
    factor[cand] = 1.0
    for sel, e, acc, jerk in (
        (falls, after, lev.a_dn, lev.j_dn),
        (rises, first, lev.a_up, lev.j_up),
    ):
        if sel.any():
            f = np.clip(0.95 * eps_mm / e[sel], 0.5, 0.9)
            jerk[sel] = _servo_jerk(jerk[sel], acc[sel], settle_max_s) * f
            acc[sel] *= f
            lev.shaped |= sel


def fallback(
    lev: Levers,
    ov: Overs,
    eps_mm: float,
    pieces: PieceList,
    settle_rows: np.ndarray,
    settle_max_s: float,
    period_s: float,
    stage: int,
) -> None:
    """The guaranteed-feasible fallback (in place): every lever of the blamed pieces (stage
    1: within the servo's memory of each over-limit sample of ``ov``; stage 2: all cutting
    pieces) scaled by :data:`FALLBACK_FACTOR` and the settles at their full length. Speed,
    acceleration and jerk → 0 take the servo error → 0, so this ends within ε_max."""
    k = len(pieces)
    f = FALLBACK_FACTOR
    lev.settle_s[settle_rows] = np.maximum(lev.settle_s[settle_rows], settle_max_s)
    # The descent of each rapid that ends at a cut: its overshoot is the settle's error.
    descent = np.zeros(k, dtype=bool)
    descent[settle_rows] = True
    if stage == 1:
        window = max(int(round(max(settle_max_s, BLAME_WINDOW_S) / period_s)), 1)
        everything = np.ones(ov.index.size, dtype=bool)
        blame = _blame(ov, everything, eps_mm, np.zeros(k - 1, dtype=bool), window)
        sel = (blame > 0.0) & ~pieces.rapid
        descent &= blame > 0.0
    else:
        sel = ~pieces.rapid
    lev.caps[sel] *= f
    for x in (lev.a_up, lev.a_dn, lev.j_up, lev.j_dn):
        x[sel] *= f
    lev.a_dn[descent] *= f
    lev.j_dn[descent] *= f
    lev.shaped |= sel | descent
