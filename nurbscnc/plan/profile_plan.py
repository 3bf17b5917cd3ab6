"""Planning the jerk-limited feed profile over a sequence of pieces, with bidirectional
look-ahead (:func:`plan_profile`).

SPEC §7 (bidirectional scan, S-curve per piece) and §10. Pure 1-D kinematics along the arc
length ``s`` [mm]: a piece is only its length, its cruise cap and the caps at its two ends.

Planning (Python per piece, O(k)):

1. Junction caps: each junction's cap is lowered to the caps of the pieces on both sides
   (the speed is continuous there). The first and last junctions are 0: rest.
2. Backward scan from the program end at rest: ``w_i = min(cap_i, R(w_{i+1}, L_i))``, with
   ``R(v, L)`` the largest speed an S-curve reaches from ``v`` within ``L``
   (:func:`~nurbscnc.plan.feedrate.max_reachable_speed`; the jerk-limited counterpart of
   the ``v² = v0² + 2·A·L`` rule in Klipper's look-ahead over squared velocities).
3. Optional bounded look-ahead of ``N`` pieces: a controller that sees only ``N`` pieces
   ahead must be able to stop at the end of what it sees, so junction ``i`` is also capped by
   the backward scan started at rest at junction ``i + N``; a second backward scan makes the
   lowered caps consistent again.
4. Forward scan from the start at rest: ``v_{i+1} = min(w_{i+1}, R(v_i, L_i))``.
5. Per piece: S-curve up from ``v_i`` to the peak ``v_p`` (the piece cap, or the bisection
   peak of SPEC §7 when the piece is too short to reach it), cruise at ``v_p``, S-curve down
   to ``v_{i+1}``.

Why the scans give a feasible result although ``R`` is *not* monotone in its start speed:
with zero acceleration at both ends, ``D(v0 → v0 + Δv)`` grows with ``v0`` at fixed ``Δv``
(the same jerk ramps, at a higher speed), so a faster start can end slower within the same
length (``dR/dv0 = (2v0 − Δv)/(2v0 + 3Δv)`` while A is not reached); likewise slowing from
``x`` to a full stop can take less distance than slowing to ``x/3``. What the scans need is
only that ``D(lo → hi)`` grows with the *upper* speed ``hi``: a piece of the forward scan
either ends at ``R(v_i)`` (fits by definition), or ends at ``w_{i+1}`` above ``v_i`` (below
``R(v_i)``: fits), or below ``v_i`` with ``v_i ≤ w_i ≤ R(w_{i+1})`` (fits). Every junction is
locally maximal: ``v_i ≥ min(cap_i, R(v_{i−1}, L_{i−1}), R(v_{i+1}, L_i))``, i.e. it cannot be
raised alone. (A lower speed somewhere could, through the non-monotone ``R``, allow a higher
one further on; the scans do not search for that: the result stays safe, not globally
time-optimal.) A float guard in ``R`` and a final repair pass make ``D(v_i → v_{i+1}) ≤ L_i``
hold in floating point too, so every piece has a cruise length ≥ 0.

Planning units (:func:`plan_profile`). The scans above run over *planning units*,
not programmed pieces: every S-curve starts and ends at zero acceleration, so a junction of
units is a single speed number and the joints are trivially continuous in ``v`` and ``a``;
but a chain of short pieces planned one by one pays the ``A/J`` jerk ramps at every junction
and never carries acceleration across one. So pieces are grouped into units between
*planning junctions* — stops, junction caps below both neighbours' cruise caps (corners), the two
ends of each valley of the cap staircase, and joints whose limits differ by more than
:data:`LIMIT_MERGE_RATIO` — and each unit is planned as one piece with the largest of its pieces'
caps and the smallest of their limits. Between planning junctions the caps rise and fall once, so a
unit's speed (up, cruise, down) can only exceed the cap of a piece on its rising or falling flank;
such a piece is made the end (rising flank) or the start (falling flank) of a unit and the plan is
made again (a few rounds at most in practice; each round adds planning junctions, so it
ends). A piece of a unit thus sees the unit's single S-curve, which passes it below its cap
with non-zero acceleration: the descent into an airfoil's nose is one S-curve from the
cruise down to the nose's cap, ending at the nose with ``a = 0`` (the time-optimal way to
meet a constant cap), instead of a step per cell.

Gated flanks. A unit's single S-curve down to its end speed may cross the caps of
a falling staircase (an airfoil's nose fitted in 16 corner cells, 32.5 → 10.5 mm/s; the
cells whose feed the contour check lowered): splitting the unit there ends the deceleration
(a = 0) at every cell it crosses, and the speed sinks below the next caps. Before splitting,
such a flank is planned under *gates* instead (:func:`gated_rise`): the descent, time
reversed, is a rise from the unit's end speed that must be at or below each piece's cap
where that piece starts (the speed falls monotonically, so that is the piece's largest),
taking the largest jerk of +J, 0, −J that can still brake its acceleration to 0 under every
gate ahead, switch instants solved to 1e-12 s; likewise a rise over a rising staircase
(gates at the piece ends). The unit keeps its end speeds and cruise peak; only its cruise
shortens. A gated flank can lose a few 0.1 µs per gate against an exact S-curve; where it
does not fit its unit, the unit is split as before (tests/test_profile_gated.py compares it
with the split and with the relaxation without the staircase).

Per-piece limits. Each piece has its own acceleration and jerk limits, and may
have separate ones for its descent (the S-curve from its peak down to its end speed: the
contour check softens the deceleration into a stop without touching the rise). A unit uses
the smallest rise and descent limits of its pieces, so a transition obeys the limits of
every piece it crosses; at a planning junction the acceleration is zero and only the jerk's
sign may change, so both neighbours' limits hold there. The backward scan uses each unit's
descent limits, the forward scan its rise limits, the peak bisection both. The feasibility
argument above is unchanged (it is per unit). Decision: the smallest limit of a unit can be
a little slower than a piece's own larger one where the transition does not cross the
smaller-limit piece; limits that differ by more than a factor 2 keep their junction.

The result is a :class:`~nurbscnc.plan.profile.Profile`: the motion exactly, as phases of
constant jerk. The scans of step 1–5 are :func:`~nurbscnc.plan.scans.plan_profile_pieces`;
the gated flanks :mod:`nurbscnc.plan.gated` and :mod:`nurbscnc.plan.gated_units`.
"""

from __future__ import annotations

import numpy as np

from nurbscnc.errors import PlanningError
from nurbscnc.plan.feedrate import scurve_distance_mm
from nurbscnc.plan.gated_units import gate_units
from nurbscnc.plan.profile import Profile, ProfileInput, frozen_array, time_at_length
from nurbscnc.plan.scans import plan_profile_pieces

#: A junction between two pieces whose acceleration or jerk limits differ by more than this
#: ratio (smaller / larger) stays a planning junction; below it the pieces may share one
#: planning unit, planned with the smaller limits (see :func:`plan_profile`).
LIMIT_MERGE_RATIO = 0.5


#: Rounds of :func:`plan_profile` that split one offending piece per unit and flank (the
#: least restrictive choice) before every offender is split at once.
SPLIT_ONE_ROUNDS = 3


def _key_junctions(inp: ProfileInput) -> np.ndarray:
    """(k+1,) bool: the junctions that stay planning junctions (zero acceleration there).

    Both ends; every junction whose own cap is below both neighbouring cruise caps (an exact
    stop, a corner); where the limits of the two pieces differ by more than
    :data:`LIMIT_MERGE_RATIO`; and both ends of every *valley*: a run of equal-cap pieces
    whose neighbouring runs (across junctions that are not already planning junctions) both
    have higher caps. Between two planning junctions the caps then rise and fall once
    (unimodal staircase), so a unit's single S-curve up and single S-curve down meet the
    caps or are split by :func:`_cap_violations`.
    """
    k = inp.piece_count
    c = np.asarray(inp.v_max_mm_s)
    jcap = np.asarray(inp.v_junction_max_mm_s)
    key = np.ones(k + 1, dtype=bool)
    left, right = c[:-1], c[1:]
    inner = jcap[1:-1] >= np.minimum(left, right)
    for x in inp.piece_limits():
        lo, hi = np.minimum(x[:-1], x[1:]), np.maximum(x[:-1], x[1:])
        inner &= lo >= LIMIT_MERGE_RATIO * hi
    key[1:-1] = ~inner
    # Runs of equal caps between planning junctions; a run's neighbour across a planning
    # junction counts as −inf (a run next to a stop is not a valley: the stop's own
    # junction is already a planning junction, and a staircase rising from it is one unit).
    step = key[1:-1] | (left != right)  # junction i+1 separates two runs
    bounds = np.flatnonzero(np.concatenate(([True], step, [True])))  # run boundaries
    run_cap = c[bounds[:-1]]
    n = run_cap.size
    if n < 3:
        return key
    left_cap = np.full(n, -np.inf)
    right_cap = np.full(n, -np.inf)
    soft = ~key[bounds[1:-1]]  # between run r and r+1 with no planning junction
    left_cap[1:] = np.where(soft, run_cap[:-1], -np.inf)
    right_cap[:-1] = np.where(soft, run_cap[1:], -np.inf)
    valley = (left_cap > run_cap) & (right_cap > run_cap)
    key[bounds[:-1][valley]] = True
    key[bounds[1:][valley]] = True
    return key


def plan_profile(inp: ProfileInput) -> Profile:
    """Plan the jerk-limited feed profile of ``inp`` (SPEC §7; see the module docstring).

    Acceleration is carried across the junctions where the path is smooth: pieces are
    grouped into *planning units* between planning junctions (:func:`_key_junctions`:
    stops, corner caps, valleys of the cap staircase, large changes of the limits), each
    unit planned as one piece (S-curve up, cruise, S-curve down; limits the smallest of its
    pieces'; cruise cap the largest of its pieces' caps). A unit whose speed then exceeds
    the cap of one of its pieces gets gated flanks (:func:`gated_rise`, module docstring)
    where they fit; else it is split at that piece (:func:`_splits`) and the
    whole plan is made again, until every piece's cap holds; each round adds a planning
    junction, so this ends (at worst with every junction one, :func:`plan_profile_pieces`).
    A run of equal caps is one unit from the start, as is an airfoil's descent from its
    cruise into the nose where the S-curve meets the staircase of the nose cells' caps.
    The result is reported per original piece (start times found by inverting s(t) at the
    piece boundaries), so callers never see the grouping.
    """
    k = inp.piece_count
    if k < 2 or inp.lookahead_pieces is not None:
        # A bounded look-ahead counts programmed pieces (a controller's block buffer): keep
        # every piece a planning unit then.
        return plan_profile_pieces(inp)
    key = _key_junctions(inp)
    rounds = 0
    while not key.all():
        profile, split = _plan_units(inp, key, every=rounds >= SPLIT_ONE_ROUNDS)
        if profile is not None:
            return profile
        key |= split
        rounds += 1
    return plan_profile_pieces(inp)


def _plan_units(
    inp: ProfileInput, key: np.ndarray, every: bool = False, gate: bool = True
) -> tuple[Profile | None, np.ndarray]:
    """The profile with the planning units between the junctions ``key`` (k+1,), reported
    per piece, and the junctions (k+1, bool) that must become planning junctions because a
    unit's speed exceeds one of its pieces' caps (then the profile is None: not valid);
    ``every``: split at every offending piece, not one per unit and flank
    (:func:`_splits`)."""
    k = inp.piece_count
    c = np.asarray(inp.v_max_mm_s)
    jcap = np.asarray(inp.v_junction_max_mm_s)
    first = np.flatnonzero(key[:-1])  # the first piece of each unit
    bounds = np.append(first, k)
    cum = np.concatenate(([0.0], np.cumsum(inp.length_mm)))
    unit_cap = np.maximum.reduceat(c, first)
    jcap_unit = jcap[bounds].copy()
    inner = bounds[1:-1]
    jcap_unit[1:-1] = np.minimum(jcap_unit[1:-1], np.minimum(c[inner - 1], c[inner]))
    if inp.uniform_limits:
        a_up = a_dn = inp.a_max_mm_s2
        j_up = j_dn = inp.j_max_mm_s3
    else:
        a_up, j_up, a_dn, j_dn = (np.minimum.reduceat(x, first) for x in inp.piece_limits())
    unit = plan_profile_pieces(
        ProfileInput(
            cum[bounds[1:]] - cum[bounds[:-1]],
            unit_cap,
            jcap_unit,
            a_up,
            j_up,
            a_decel_mm_s2=a_dn,
            j_decel_mm_s3=j_dn,
        )
    )
    lims = (a_up, j_up, a_dn, j_dn)
    unit_of = np.repeat(np.arange(first.size), np.diff(bounds))
    # Within a unit the speed rises to its peak v_p, cruises over [cruise_from, cruise_to]
    # and falls, so the largest speed on a piece is v_p where the piece touches the cruise,
    # else the larger of its end speeds. Only pieces below their unit's cap can exceed it.
    v_p = unit.piece_peak_speed_mm_s
    d_up = scurve_distance_mm(unit.junction_speeds_mm_s[:-1], v_p, a_up, j_up)
    d_dn = scurve_distance_mm(v_p, unit.junction_speeds_mm_s[1:], a_dn, j_dn)
    low = np.flatnonzero(c < unit_cap[unit_of])
    # Times at which the units' profile reaches every piece boundary (k+1), once per
    # version of it: the offenders read their pieces' ends, the result every piece start
    # (elementwise: the same numbers as asking for each subset).
    at_bounds: list = [None, None]  # (unit profile, its times)

    def bound_times(unit: Profile) -> np.ndarray:
        if at_bounds[0] is not unit:
            at_bounds[:] = [unit, time_at_length(unit, cum)]
        return at_bounds[1]

    def offenders(unit: Profile, d_up: np.ndarray, d_dn: np.ndarray):
        """The pieces whose cap the unit's speed exceeds, and piece_max of the module."""
        cruise_from = cum[bounds[:-1]] + d_up
        cruise_to = cum[bounds[1:]] - d_dn
        lo = np.minimum(cruise_from, cruise_to)
        hi = np.maximum(cruise_from, cruise_to)

        def piece_max(idx: np.ndarray, v_start: np.ndarray, v_end: np.ndarray) -> np.ndarray:
            u = unit_of[idx]
            at_peak = (cum[idx] <= hi[u]) & (cum[idx + 1] >= lo[u])
            return np.where(at_peak, v_p[u], np.maximum(v_start, v_end))

        if not low.size:
            return low, piece_max
        t = bound_times(unit)
        v_ends = unit.sample(np.concatenate((t[low], t[low + 1])))[1]
        over = low[piece_max(low, v_ends[: low.size], v_ends[low.size :]) > c[low] * (1.0 + 1e-12)]
        return over, piece_max

    over, piece_max = offenders(unit, d_up, d_dn)
    if over.size and gate:
        # Flanks over a staircase of caps follow it (gated flanks) where the unit has room.
        unit, d_up, d_dn = gate_units(
            unit, over, c, cum, first, bounds, unit_of, unit_cap, lims, d_up.copy(), d_dn.copy()
        )
        over, piece_max = offenders(unit, d_up, d_dn)
    if over.size:
        return None, _splits(over, c, unit_cap, unit_of, first, k, every)
    piece_start = cum[:-1]
    # Times at which the path reaches each piece start (exact within a unit).
    t_start = bound_times(unit)[:-1].copy()
    t_start[first] = unit.piece_start_time_s
    t_start = np.maximum.accumulate(t_start)
    v_junction = np.empty(k + 1)
    v_junction[:-1] = unit.sample(t_start)[1]
    v_junction[bounds] = unit.junction_speeds_mm_s
    v_piece = piece_max(np.arange(k), v_junction[:-1], v_junction[1:])
    profile = Profile(
        total_length_mm=unit.total_length_mm,
        duration_s=unit.duration_s,
        junction_speeds_mm_s=frozen_array(v_junction),
        piece_peak_speed_mm_s=frozen_array(np.minimum(v_piece, c)),
        piece_start_mm=frozen_array(piece_start),
        piece_start_time_s=frozen_array(t_start),
        phase_start_time_s=unit.phase_start_time_s,
        phase_duration_s=unit.phase_duration_s,
        phase_s0_mm=unit.phase_s0_mm,
        phase_v0_mm_s=unit.phase_v0_mm_s,
        phase_a0_mm_s2=unit.phase_a0_mm_s2,
        phase_jerk_mm_s3=unit.phase_jerk_mm_s3,
        phase_piece_index=frozen_array(first[unit.phase_piece_index], dtype=np.int64),
    )
    return profile, np.zeros(k + 1, dtype=bool)


def _splits(
    over: np.ndarray,
    c: np.ndarray,
    unit_cap: np.ndarray,
    unit_of: np.ndarray,
    first: np.ndarray,
    k: int,
    every: bool = False,
) -> np.ndarray:
    """The junctions (k+1, bool) that become planning junctions for the pieces ``over``
    whose cap their unit's speed exceeds.

    A piece before its unit's first piece at the unit's cap (on the rise) ends its unit
    there (v ≤ its cap at that junction, a = 0); a piece after the last one (on the
    descent) starts a unit. Either way it then lies in a unit whose caps are all ≤ its own
    (the unit's caps rise, then fall). One split per unit and side per round, the one
    nearest the end that side approaches (the rise's first offender, the descent's last):
    its planning junction often clears the other offenders of that side. With ``every``
    (after :data:`SPLIT_ONE_ROUNDS` rounds: a long smooth staircase would otherwise take a
    round per step) every offender is split at once.
    """
    idx = np.arange(k)
    is_top = c == unit_cap[unit_of]
    top_first = np.minimum.reduceat(np.where(is_top, idx, k), first)[unit_of]
    top_last = np.maximum.reduceat(np.where(is_top, idx, -1), first)[unit_of]
    rise = over[over < top_first[over]]
    fall = over[over > top_last[over]][::-1]
    if not every:
        rise = rise[np.unique(unit_of[rise], return_index=True)[1]]
        fall = fall[np.unique(unit_of[fall], return_index=True)[1]]
    if not (rise.size or fall.size):
        raise PlanningError("feed profile: a piece at its unit's cap exceeds it (rounding)")
    split = np.zeros(k + 1, dtype=bool)
    split[rise + 1] = True
    split[fall] = True
    return split
