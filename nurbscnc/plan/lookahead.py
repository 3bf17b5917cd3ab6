"""The look-ahead planner: pieces → jerk-limited profile → dynamics check → re-plan.

SPEC §7–§8 and §10. The profile is planned over the whole program (bidirectional scan); the
predicted contour error is then checked with the servo model, and where it exceeds ε_max the
feed cap is lowered — on the offending pieces only (``dynamics="local"``, our default) or for
the whole program (``"global"``, the paper's rule: V_max becomes the feed where the error
occurred) — and the program re-planned, until the error is within the limit.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from nurbscnc.errors import PlanningError
from nurbscnc.interpolate import (
    PieceTable,
    Samples,
    dwell_schedule,
    sample_plan,
    total_time_s,
)
from nurbscnc.machine import Machine
from nurbscnc.plan.dynamics import Response, dense_path_mm, servo_response
from nurbscnc.plan.pieces import PlanOptions, junction_caps, segment_pieces
from nurbscnc.plan.profile import Profile, ProfileInput, plan_profile

#: Plan to this fraction of ε_max so the prediction has a little room (model, rounding).
CONTOUR_MARGIN = 0.99
#: Samples before an over-limit sample whose pieces share the blame (servo memory ≈ 30 ms).
BLAME_WINDOW_S = 0.03


@dataclass(frozen=True)
class LookaheadOptions:
    """``dynamics``: "local" | "global" | "off"; ``interpolator``: "exact" | "taylor" (NURBS
    pieces by the paper's 2nd-order Taylor formula); ``max_iterations`` of the re-plan loop;
    ``lookahead_pieces``: None (whole program) or a window; ``plan``: piece options."""

    dynamics: str = "local"
    interpolator: str = "exact"
    max_iterations: int = 40
    lookahead_pieces: int | None = None
    plan: PlanOptions = field(default_factory=PlanOptions)


@dataclass(frozen=True, eq=False)
class Plan:
    """A complete plan: pieces, their final caps, the profile, the samples and the predicted
    servo response; ``iterations`` of the dynamics loop; ``cycle_time_s`` including dwells."""

    pieces: list
    caps_mm_s: np.ndarray
    profile: Profile
    samples: Samples
    response: Response | None
    iterations: int
    cycle_time_s: float
    dynamics: str


def _profile(pieces, caps, smooth, machine: Machine, window) -> Profile:
    lim = machine.limits
    lengths = np.array([p.length_mm for p in pieces])
    jcaps = np.zeros(len(pieces) + 1)
    inner = np.minimum(caps[:-1], caps[1:])
    jcaps[1:-1] = np.where(smooth[1:-1] > 0, inner, 0.0)
    return plan_profile(ProfileInput(lengths, caps, jcaps, lim.a_max_mm_s2, lim.j_max_mm_s3,
                                     lookahead_pieces=window))  # fmt: skip


def plan_program(program, machine: Machine, options: LookaheadOptions | None = None) -> Plan:
    """Plan a whole interpreted program (SPEC §1: modules 1–4, then the interpolator)."""
    options = options or LookaheadOptions()
    pieces = segment_pieces(program.segments, machine, options.plan)
    if not pieces:
        raise PlanningError("the program has no motion to plan")
    caps = np.array([p.v_cap_mm_s for p in pieces], dtype=float)
    smooth = junction_caps(pieces)  # > 0 where the path is tangent-continuous
    rapid = np.array([p.kind == "rapid" for p in pieces])
    period = machine.servo.period_s
    eps_mm = machine.limits.contour_tolerance_mm * CONTOUR_MARGIN
    response = None
    iterations = 0
    path = None
    table = PieceTable.of(pieces)  # per-piece arrays for the interpolator, built once
    while True:
        profile = _profile(pieces, caps, smooth, machine, options.lookahead_pieces)
        samples = sample_plan(pieces, profile, period, interpolator=options.interpolator,
                              table=table)  # fmt: skip
        if options.dynamics == "off":
            break
        if path is None:
            path = dense_path_mm(pieces, profile, table=table)
        response = servo_response(samples.points_mm, path, machine)
        n = samples.t_s.size
        # Contour error matters while cutting: samples on rapids (air moves) are not checked.
        cutting = np.append(~rapid[samples.piece], np.full(response.contour_mm.size - n,
                                                            not rapid[-1]))
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
        over = np.flatnonzero(err > eps_mm)
        over_in = np.minimum(over, n - 1)
        if options.dynamics == "global":
            # The paper's rule: lower V_max for the whole program. Every cap (cruise and
            # corner: V_cf ∝ V_max) scales with it; error ∝ V²κ gives the factor.
            caps = caps * min(float(np.sqrt(eps_mm / worst)), 0.98)
        else:
            window = max(int(round(BLAME_WINDOW_S / period)), 1)
            blame = np.zeros(len(pieces))
            for k, e in zip(over_in, err[over]):
                lo = max(k - window, 0)
                for p in np.unique(samples.piece[lo:k + 1]):
                    blame[p] = max(blame[p], e)
            hit = blame > 0
            factor = np.clip(np.sqrt(eps_mm / np.where(hit, blame, eps_mm)) * 0.97, 0.5, 0.97)
            caps = np.where(hit, caps * factor, caps)
    dwell_at, dwell_s = dwell_schedule(pieces, profile)
    return Plan(pieces, caps, profile, samples, response, iterations,
                total_time_s(profile, dwell_s), options.dynamics)  # fmt: skip


def segment_times_s(plan: Plan) -> dict[int, float]:
    """Motion time [s] of each program segment (its pieces' span in the profile)."""
    prof = plan.profile
    ends = np.append(prof.piece_start_time_s[1:], prof.duration_s)
    out: dict[int, float] = {}
    for i, p in enumerate(plan.pieces):
        out[p.segment] = out.get(p.segment, 0.0) + float(ends[i] - prof.piece_start_time_s[i])
    return out
