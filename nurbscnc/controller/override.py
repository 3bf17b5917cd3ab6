"""The feed override of a running job: below 100 % by time scaling, above it by re-planning.

Below 100 % (decision, docs/protocol.md "The controller"): the motion is played at a rate
``r ≤ 1`` (:class:`~.motion.Rate`), which keeps ``v·r, a·r², j·r³`` within the limits the
plan respected; a change while moving is the earliest quintic ramp that keeps |a| ≤ A and
|j| ≤ J on every period (:func:`apply_override`).

Above 100 % time scaling would exceed them (``a·r²`` with r > 1), so the rest of the program
is **re-planned** from a rest, as after a feed hold (:func:`~.motion.resume_motion`: the
planner's own jerk-limited profile within the plan's per-piece A and J), with raised cruise
caps (:func:`raised_caps`): on the pieces whose cap is their programmed feed F (lines, arcs,
NURBS cells outside corners: a corner's V_cf is below F), the cap becomes
``min(scale·F, the machine's bound)``, the bound being what the planner caps such a piece at
besides F — V_max, the axes' speed limits, the chord and normal-acceleration caps at the
piece's peak curvature (SPEC eq. 22–23, ``machine/caps.py``) — and the card's pulse limit per
period. Caps the dynamics check lowered, rapids and corner blends (PH pieces) keep their
planned caps. The re-plan
starts at the next rest of the motion ahead (a junction at speed 0, a stop, the section's
end): the section is cut there (:func:`cut_at_rest`; the card DONE at rest, the next section
starts at once with the new motion).
"""

from __future__ import annotations

import numpy as np

from nurbscnc.controller.motion import Rate, play, ramp_duration_s, ramp_fits, resume_motion
from nurbscnc.geometry.path import Kind
from nurbscnc.machine.caps import chord_feed_mm_s, normal_feed_mm_s
from nurbscnc.plan.axes import piece_limits

#: Override limits [fraction] and the step of the + / - keys. Above 1: re-planned within the
#: machine's limits (module docstring), so the override asked is an upper bound.
OVERRIDE_MIN, OVERRIDE_MAX, OVERRIDE_STEP = 0.10, 2.0, 0.10
#: Where a ramp may start, after the first period not yet framed [s] (searched in order).
RAMP_OFFSETS_S = tuple(np.round(np.arange(0.0, 2.0, 0.025), 3))
#: Relative tolerance of "the cap is the programmed feed".
FEED_CAP_TOL = 1e-9


def raised_caps(plan, program, machine, scale: float) -> np.ndarray:
    """The cruise caps [mm/s] (k,) of ``plan``'s pieces at a feed override ``scale`` ≥ 1
    (module docstring); ``program`` the interpreted program (the segments' feeds)."""
    caps = np.asarray(plan.caps_mm_s, dtype=float)
    if scale <= 1.0:
        return caps
    pieces = plan.pieces
    k = caps.size
    seg_feed = np.array([float(s.feed_mm_s) for s in program.segments] or [0.0])
    feed = seg_feed[np.asarray(pieces.segment, dtype=np.intp)]
    kind = np.asarray(pieces.kind)
    shaped = plan.contour_feed if plan.contour_feed is not None else np.zeros(k, dtype=bool)
    by_feed = (
        (kind != Kind.PH)
        & ~np.asarray(pieces.rapid, dtype=bool)
        & ~np.asarray(shaped, dtype=bool)
        & (feed > 0.0)
        & (caps >= feed * (1.0 - FEED_CAP_TOL))
    )
    lim = machine.limits
    period_s = machine.servo.period_s
    kappa = np.abs(np.asarray(pieces.kappa_max_per_mm, dtype=float))
    bound = np.minimum(lim.v_max_mm_s, np.asarray(piece_limits(pieces, machine).v_mm_s))
    # Every axis moves at most the path speed: this keeps each period's pulses within the
    # card's limit.
    pulse_mm_s = machine.steps.max_pulses_per_period / (period_s * max(machine.steps.per_mm))
    bound = np.minimum(bound, pulse_mm_s)
    curved = kind != Kind.LINE
    with np.errstate(divide="ignore"):
        curve = np.minimum(
            chord_feed_mm_s(kappa, period_s, lim.chord_tolerance_mm),
            normal_feed_mm_s(kappa, lim.a_max_mm_s2),
        )
    bound = np.where(curved, np.minimum(bound, curve), bound)
    return np.where(by_feed, np.maximum(caps, np.minimum(scale * feed, bound)), caps)


def replan_raised(job, s_mm: float, wait_s: float):
    """The rest of ``job.plan`` from rest at ``s_mm`` (:func:`~.motion.resume_motion`) at the
    feed scale ``job.scale``: with the raised caps when that is faster than with the plan's
    own. (The jerk-limited profile is not monotonic in its caps: with higher caps some short
    pieces come out slower, and on ``programs/butterfly.nc`` the whole rest at 150 % came
    out 1.7 % slower. The override never slows the job down: a note says so instead.)"""
    plain = resume_motion(job.plan, s_mm, wait_s, job.lookahead_pieces)
    if job.scale <= 1.0 or plain is None:
        return plain
    caps = raised_caps(job.plan, job.program, job.machine, job.scale)
    raised = resume_motion(job.plan, s_mm, wait_s, job.lookahead_pieces, caps)
    if raised.duration_s < plain.duration_s:
        return raised
    note = (
        f"feed override {job.scale:.0%}: the rest re-planned at the raised feeds is not "
        "faster than at 100 % (the jerk-limited profile is not monotonic in its caps): it "
        "runs as planned at 100 %"
    )
    if note not in job.notes:
        job.notes.append(note)
    return plain


def rest_times_s(motion) -> np.ndarray:
    """Profile times [s] of the motion's rests after its start: the piece junctions where
    the profile's speed is 0 (sharp corners, stops, dwells) and its end."""
    starts = np.asarray(motion.profile.piece_start_time_s, dtype=float)
    v = motion.profile.sample(starts)[1]
    rests = starts[(v <= 1e-9) & (starts > 0.0)]
    return np.append(rests, motion.duration_s)


def cut_at_rest(job, link) -> None:
    """End the running section at the motion's next rest ahead of the periods framed (not
    beyond the planning horizon; none before the section's end: it applies there): the
    next section re-plans the rest at the override ``job.pending_override``."""
    sec = job.section
    tr = sec.track
    k = link.sent_periods
    if k >= len(tr):
        return
    tau_k = float(tr.tau_s[k])
    rests = rest_times_s(job.motion)
    ahead = rests[(rests > tau_k + 1e-9) & (rests < sec.tau_b - 1e-9)]
    # Within the periods computed so far (a chunk ahead at most): the cut costs a chunk.
    ahead = ahead[ahead <= min(job.horizon_tau(), float(tr.tau_s[-1])) + 1e-12]
    if not ahead.size:
        return
    tail, _ = play(
        job.motion,
        tau_k,
        float(ahead[0]),
        sec.rate,
        job.period_s,
        wait_s=job.wait_at(tr, k),
        u0=float(tr.u_s[k]) - sec.rate_u0_s,
    )
    tail.points_mm[0] = tr.points_mm[k]
    track = tr.head(k + 1).then(tail)
    program = job.pulses_of(track, k, sec.program)
    sec.track, sec.program, sec.tau_b = track, program, float(ahead[0])
    sec.complete, sec.blocked, sec.rescale = True, False, True
    link.program_open = False
    link.replace_unsent(program)


def apply_override(job, link, chunk_periods: int) -> None:
    """Apply ``job.override_wanted`` to the running section: ramp the time scale to
    ``min(wanted, 1)`` (the earliest quintic ramp within A and J); a change of the part above
    100 % waits for the next rest (``job.pending_override``, :func:`cut_at_rest`)."""
    sec = job.section
    wanted = job.override_wanted
    r1 = min(wanted, 1.0)
    rescale = max(wanted, 1.0) != job.scale
    k = link.sent_periods
    tr = sec.track
    u_k = float(tr.u_s[k])
    r_k = float(sec.rate.r(np.array([u_k - sec.rate_u0_s]))[0])
    if abs(r1 - r_k) < 1e-12:
        _done(job, wanted, r1, rescale)
        return
    # A ramp in progress finishes first.
    busy_until = sec.rate.end_u + sec.rate_u0_s - u_k if sec.rate.ramping else 0.0
    v_max = float(np.max(job.plan.profile.piece_peak_speed_mm_s))
    d0 = ramp_duration_s(r1 - r_k, v_max, job.a_max, job.j_max)
    wait = job.wait_at(tr, k)
    for offset in RAMP_OFFSETS_S:
        if offset < busy_until:
            continue
        for d in (d0, 2 * d0, 4 * d0):
            rate = Rate(r_k, r1, float(offset), d)
            # Check the ramp's periods only (cheap), then time the whole rest once.
            tau_w = min(sec.tau_b, float(tr.tau_s[k] + rate.integral(offset + d)))
            window, _ = play(job.motion, float(tr.tau_s[k]), tau_w, rate, job.period_s, wait_s=wait)
            if not ramp_fits(window, job.a_max, job.j_max):
                continue
            tail, complete = play(
                job.motion,
                float(tr.tau_s[k]),
                sec.tau_b,
                rate,
                job.period_s,
                wait_s=wait,
                max_samples=chunk_periods,
            )
            tail, sec.blocked = job.within_horizon(tail, sec.tau_b)
            complete = complete and not sec.blocked
            tail.points_mm[0] = tr.points_mm[k]
            track = tr.head(k + 1).then(tail)
            program = job.pulses_of(track, k, sec.program)
            sec.complete = complete
            link.program_open = not complete
            link.replace_unsent(program)
            sec.track, sec.program = track, program
            sec.rate, sec.rate_u0_s = rate, u_k
            _done(job, wanted, r1, rescale)
            return
    job.notes.append(
        f"no smooth change of the feed override to {r1:.0%} fits the "
        "limits in this section: it applies from the next one"
    )
    sec.override_deferred = True  # pending until the next section starts


def _done(job, wanted: float, r1: float, rescale: bool) -> None:
    """The time scale is ``r1`` now; the part above 100 % (if it changes) at the next rest."""
    job.override, job.override_wanted = (r1, None) if rescale else (wanted, None)
    job.pending_override = wanted if rescale else None
