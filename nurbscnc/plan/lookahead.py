"""The look-ahead planner: pieces → jerk-limited profile → dynamics check → re-plan.

SPEC §7–§8 and §10. The profile is planned over the whole program (bidirectional scan); the
predicted contour error is then checked with the servo model, and where it exceeds ε_max the
feed cap is lowered — on the offending pieces only (``dynamics="local"``, our default) or for
the whole program (``"global"``, the paper's rule: V_max becomes the feed where the error
occurred) — and the program re-planned, until the error is within the limit.

Long programs. Everything per piece is whole-array work on the columns of the
:class:`~nurbscnc.plan.pieces.PieceList` (junctions, dwells, blame), the contour error is
measured near each reference point only (:func:`~nurbscnc.plan.dynamics.path_response`), and
a local re-plan lowers the caps of all offending pieces at once by their measured ratio, so
a program needs a few iterations, whatever its length. Runs of tiny tangent-continuous
pieces at one cap are planned as one by :func:`~nurbscnc.plan.profile.plan_profile`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbscnc.errors import PlanningError
from nurbscnc.machine.profile import Machine
from nurbscnc.plan.axes import piece_limits
from nurbscnc.plan.dynamics import PathIndex, Response, path_response
from nurbscnc.plan.limits import check_point_count
from nurbscnc.plan.options import Dynamics, LookaheadOptions
from nurbscnc.plan.pieces import PieceList, junction_caps, segment_pieces
from nurbscnc.plan.profile import Profile, ProfileInput, plan_profile
from nurbscnc.plan.timing import Reference, dwell_times, exact_reference, total_time_s

#: Plan to this fraction of ε_max so the prediction has a little room (model, rounding).
CONTOUR_MARGIN = 0.99
#: Samples before an over-limit sample whose pieces share the blame (servo memory ≈ 30 ms).
BLAME_WINDOW_S = 0.03


@dataclass(frozen=True, eq=False)
class Limits:
    """Acceleration [mm/s²] and jerk [mm/s³] limits of each of k pieces, (k,) each: for the
    rise to its peak speed (``up``) and the descent from it (``down``)."""

    a_up_mm_s2: np.ndarray
    j_up_mm_s3: np.ndarray
    a_down_mm_s2: np.ndarray
    j_down_mm_s3: np.ndarray


@dataclass(frozen=True, eq=False)
class Plan:
    """A complete plan: pieces, their final caps [mm/s], the profile; ``iterations`` of the
    dynamics loop; ``cycle_time_s`` including dwells; the ``dynamics`` rule it was checked
    with. The reference points come from the interpolator
    (:func:`nurbscnc.interpolate.sample.interpolate`), the check's result from
    :func:`plan_checked`."""

    pieces: PieceList
    caps_mm_s: np.ndarray
    profile: Profile
    iterations: int
    cycle_time_s: float
    dynamics: Dynamics


@dataclass(frozen=True, eq=False)
class Check:
    """The dynamics check of the final plan (SPEC §8): the ``reference`` points it checked
    (:class:`~nurbscnc.plan.timing.Reference`), the predicted servo ``response`` to them and
    ``cutting`` (M,), which response samples are cutting (not on a rapid; the held tail after
    the end counts as the last piece): those are checked."""

    reference: Reference
    response: Response
    cutting: np.ndarray

    def contour_um(self) -> np.ndarray:
        """The true contour error [µm] of the cutting samples."""
        return self.response.contour_mm[self.cutting] * 1000.0


def _profile(pieces: PieceList, caps: np.ndarray, smooth: np.ndarray, limits: Limits,
             window: int | None) -> Profile:  # fmt: skip
    """The jerk-limited profile (SPEC §7) over the pieces with cruise caps ``caps`` [mm/s],
    the junctions ``smooth`` (> 0: tangent-continuous, capped by the smaller neighbour) and
    the per-piece acceleration and jerk ``limits``."""
    k = len(pieces)
    jcaps = np.zeros(k + 1)
    jcaps[1:-1] = np.where(smooth[1:-1] > 0, np.minimum(caps[:-1], caps[1:]), 0.0)
    return plan_profile(ProfileInput(pieces.length_mm, caps, jcaps, limits.a_up_mm_s2,
                                     limits.j_up_mm_s3, lookahead_pieces=window,
                                     a_decel_mm_s2=limits.a_down_mm_s2,
                                     j_decel_mm_s3=limits.j_down_mm_s3))  # fmt: skip


def _blame(err: np.ndarray, eps_mm: float, piece: np.ndarray, joined: np.ndarray,
           window: int) -> np.ndarray:  # fmt: skip
    """Largest over-limit error [mm] each piece shares the blame for (0: none).

    A sample over the limit blames the pieces of the ``window`` samples up to it (the servo
    remembers): per sample the largest over-limit error in the next ``window`` samples (a
    sliding maximum), then the largest per piece. Blamed pieces that the profile plans as
    one (``joined`` (k−1,): tangent-continuous junction, equal caps) share their largest
    blame, so their caps stay equal and they stay one profile unit (a run of tiny CAM
    pieces lowered piece by piece to slightly different caps would crawl)."""
    from scipy.ndimage import maximum_filter1d

    n = piece.size
    k = joined.size + 1
    over = np.flatnonzero(err > eps_mm)
    e_over = np.zeros(n)
    np.maximum.at(e_over, np.minimum(over, n - 1), err[over])
    size = window + 1
    reach = maximum_filter1d(e_over, size=size, mode="constant", cval=0.0,
                             origin=-(size // 2))  # fmt: skip
    blame = np.zeros(k)
    np.maximum.at(blame, piece, reach)
    hit = blame > 0.0
    link = hit[:-1] & hit[1:] & joined
    if link.any():
        run = np.concatenate(([0], np.cumsum(~link)))  # run label of each piece
        run_max = np.zeros(int(run[-1]) + 1)
        np.maximum.at(run_max, run, blame)
        blame = np.where(hit, run_max[run], 0.0)
    return blame


def local_factors(blame: np.ndarray, eps_mm: float, history=None):
    """Cap factors (k,) of a local re-plan and the history for the next one.

    Every offending piece (``blame`` > 0: the error [mm] it shares) is lowered at once, by
    f = 0.97 (ε/e)^(1/p), clipped to [0.5, 0.97]. The exponent p of error ∝ V^p is 2 for a
    piece hit for the first time (the normal acceleration V²κ drives the servo lag), and is
    measured for a piece hit again, from its last factor and how much its error fell:
    p = ln(e/e_prev) / ln(f_prev), kept in [0.25, 2]. Errors that depend on the feed weakly
    (the overshoot of an exact stop grows with the deceleration, not with V²) thus get a
    strong correction at the second try instead of 3 % per re-plan.
    """
    hit = blame > 0.0
    p = np.full(blame.size, 2.0)
    if history is not None:
        prev_blame, prev_factor = history
        again = hit & (prev_blame > 0.0) & (prev_factor < 1.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            measured = np.log(blame / prev_blame) / np.log(prev_factor)
        p = np.where(again & np.isfinite(measured), np.clip(measured, 0.25, 2.0), p)
    ratio = eps_mm / np.where(hit, blame, eps_mm)
    factor = np.where(hit, np.clip(0.97 * ratio ** (1.0 / p), 0.5, 0.97), 1.0)
    return factor, (blame, factor)


def plan_program(program, machine: Machine, options: LookaheadOptions | None = None) -> Plan:
    """Plan a whole interpreted program (SPEC §1: modules 1–4); :func:`plan_checked` without
    the check's result."""
    return plan_checked(program, machine, options)[0]


def plan_checked(program, machine: Machine, options: LookaheadOptions | None = None,
                 reference=exact_reference) -> tuple[Plan, Check | None]:  # fmt: skip
    """Plan a whole interpreted program and check it (SPEC §1: modules 1–4, §8): pieces,
    profile, then the dynamics check on the plan's reference points, re-planning until the
    predicted contour error is within ε_max. ``reference``: (pieces, profile, period_s) →
    :class:`~nurbscnc.plan.timing.Reference`, the points the check simulates (default: the
    exact ones; the interpolator passes its own,
    :func:`nurbscnc.interpolate.sample.reference_sampler`). Returns the plan and the final
    check (None with ``dynamics="off"``)."""
    options = options or LookaheadOptions()
    pieces = segment_pieces(program.segments, machine, options.plan)
    if not len(pieces):
        raise PlanningError("the program has no motion to plan")
    lim = machine.limits
    path_lim = piece_limits(pieces, machine)  # the axes' limits along each piece
    caps = np.minimum(pieces.v_cap_mm_s, path_lim.v_mm_s)
    a_p = np.asarray(path_lim.a_mm_s2, dtype=float)
    j_p = np.asarray(path_lim.j_mm_s3, dtype=float)
    limits = Limits(a_p, j_p, a_p, j_p)
    smooth = junction_caps(pieces)  # > 0 where the path is tangent-continuous
    rapid = pieces.rapid
    period = machine.servo.period_s
    eps_mm = lim.contour_tolerance_mm * CONTOUR_MARGIN
    check = None
    iterations = 0
    history = None  # the last local re-plan: blame and factor per piece
    index = None  # where the pieces are, for global distances (built if needed)
    while True:
        # The last iteration's reference and response go before the new ones are made (long
        # programs: each is hundreds of MB).
        ref = check = None
        profile = _profile(pieces, caps, smooth, limits, options.lookahead_pieces)
        check_point_count(pieces, profile, machine)  # before anything is sampled
        if options.dynamics == Dynamics.OFF:
            break
        ref = reference(pieces, profile, period)
        index = index or PathIndex(pieces)
        response = path_response(ref, pieces, profile, machine, refine_above_mm=eps_mm,
                                 index=index)  # fmt: skip
        n = ref.t_s.size
        # Contour error matters while cutting: samples on rapids (air moves) are not checked.
        cutting = np.append(~rapid[ref.piece], np.full(response.contour_mm.size - n,
                                                        not rapid[-1]))
        check = Check(ref, response, cutting)
        err = np.where(cutting, response.contour_mm, 0.0)
        worst = float(err.max())
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
            caps = caps * min(float(np.sqrt(eps_mm / worst)), 0.98)
        else:
            window = max(int(round(BLAME_WINDOW_S / period)), 1)
            joined = (smooth[1:-1] > 0) & (caps[:-1] == caps[1:])
            blame = _blame(err, eps_mm, ref.piece, joined, window)
            factor, history = local_factors(blame, eps_mm, history)
            caps = caps * factor
    _, dwell_s = dwell_times(pieces, profile)
    plan = Plan(pieces, caps, profile, iterations, total_time_s(profile, dwell_s),
                options.dynamics)  # fmt: skip
    return plan, check


def segment_times_s(plan: Plan) -> dict[int, float]:
    """Motion time [s] of each program segment (its pieces' span in the profile)."""
    prof = plan.profile
    ends = np.append(prof.piece_start_time_s[1:], prof.duration_s)
    span = ends - prof.piece_start_time_s
    seg = np.asarray(plan.pieces.segment)
    present = np.unique(seg)
    sums = np.bincount(seg, weights=span)
    return {int(s): float(sums[s]) for s in present}
