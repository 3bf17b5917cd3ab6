"""What every plan of one program shares (:class:`Setup`): its pieces, the kinematic levers
(the axes' path limits), the settle rows, the checker; planning and checking given levers."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from nurbscnc.errors import PlanningError
from nurbscnc.machine.profile import Machine
from nurbscnc.plan.allowance import corner_allowance, program_tolerance
from nurbscnc.plan.axes import piece_limits
from nurbscnc.plan.check import Checker
from nurbscnc.plan.junctions import junction_caps, settle_time_s
from nurbscnc.plan.levers import Levers
from nurbscnc.plan.limits import check_point_count
from nurbscnc.plan.options import Dynamics, LookaheadOptions
from nurbscnc.plan.pieces import PieceList
from nurbscnc.plan.plans import Plan, cycle_time_s, profile_over
from nurbscnc.plan.program_pieces import segment_pieces
from nurbscnc.plan.shaping import fallback, shape

#: Plan to this fraction of ε_max so the prediction has a little room (model, rounding).
CONTOUR_MARGIN = 0.99


def _with_dwell(pieces: PieceList, dwell_s: np.ndarray) -> PieceList:
    """``pieces`` with the dwell column ``dwell_s`` (k,) [s]; the path model, independent
    of dwells, built once on ``pieces`` and shared (not rebuilt per re-plan: the check's
    kept polyline knows it by identity)."""
    out = replace(pieces, dwell_after_s=dwell_s)
    out.__dict__["path"] = pieces.path
    return out


class Setup:
    """What every plan of one program shares: its pieces, the kinematic levers (the axes'
    path limits), the settle rows, the checker; :meth:`evaluate` plans and checks levers."""

    def __init__(
        self,
        program,
        machine: Machine,
        options: LookaheadOptions,
        reference,
        keep_reference: bool,
        window: int,
        columns=None,
    ):
        self.machine, self.options = machine, options
        pieces = segment_pieces(
            program.segments, machine, options.plan, columns, program.rotary_axes
        )
        if not len(pieces):
            raise PlanningError("the program has no motion to plan")
        self.pieces = pieces
        path_lim = piece_limits(pieces, machine)  # the axes' limits along each piece
        a_p = np.array(path_lim.a_mm_s2, dtype=float)
        j_p = np.array(path_lim.j_mm_s3, dtype=float)
        k = self.k = len(pieces)
        self.initial = Levers(
            np.minimum(pieces.v_cap_mm_s, path_lim.v_mm_s),
            a_p,
            j_p,
            a_p.copy(),
            j_p.copy(),
            np.zeros(k),
            np.zeros(k, dtype=bool),
            np.zeros(k, dtype=bool),
        )
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
        # The corner allowances with the program's own path tolerances (a smoothed spline's
        # rows keep only the blends' share of it; its ends are the programmed vertices).
        allowance = corner_allowance(
            pieces, machine, program_tolerance(program, machine, options.plan.blend_tolerance_mm)
        )
        self.checker = Checker(
            pieces,
            machine,
            reference,
            self.eps_mm,
            self.settle_rows,
            window,
            keep_reference,
            allowance,
        )
        # The improvement phase's upper brackets: the kinematic levers, or with
        # ``raise_corner_caps`` the caps without the corner heuristic V_cf.
        self.upper = self.initial
        if options.raise_corner_caps and options.dynamics == Dynamics.LOCAL:
            free = _without_corner_feed(program, machine, options, pieces)
            if free is not None:
                self.upper = self.initial.copy()
                self.upper.caps = np.maximum(
                    np.minimum(free.v_cap_mm_s, path_lim.v_mm_s), self.initial.caps
                )
                # The junctions capped by their neighbours' machine caps (the same passable
                # junctions): the profile takes the smaller of the levers' caps anyway.
                self.smooth = np.maximum(self.smooth, junction_caps(free))

    def planned(self, lv: Levers) -> PieceList:
        """The pieces with the settles of the levers ``lv`` in their dwells."""
        return self.planned_settles(lv.settle_s)

    def planned_settles(self, settle_s: np.ndarray) -> PieceList:
        """The pieces with the settles ``settle_s`` (k,) [s] in their dwells."""
        return (
            _with_dwell(self.pieces, self.base_dwell + settle_s)
            if self.settle_rows.size
            else self.pieces
        )

    def any_shaped(self, lv: Levers) -> bool:
        """Whether the levers ``lv`` shaped any piece."""
        return bool(lv.shaped.any())

    def plan_of(self, lv: Levers):
        """The planned pieces (settles in their dwells) and profile of the levers ``lv``."""
        planned = self.planned(lv)
        profile = profile_over(
            planned.length_mm, lv.caps, self.smooth, lv.limits(), self.options.lookahead_pieces
        )
        check_point_count(planned, profile, self.machine)  # before anything is sampled
        return planned, profile

    def evaluate(self, lv: Levers, rows=None, stream=None):
        """Plan with the levers ``lv`` and check (``rows``, ``stream``: one cut window,
        :meth:`Checker.run`): (planned pieces, profile, check)."""
        planned, profile = self.plan_of(lv)
        if self.options.dynamics == Dynamics.OFF:
            return planned, profile, None
        return planned, profile, self.checker.run(planned, profile, rows, stream)

    def shape(self, lv: Levers, result) -> None:
        """One local re-plan of ``lv`` (in place) from the check of ``result``
        (:func:`~nurbscnc.plan.shaping.shape`)."""
        shape(
            lv,
            result[2].overs,
            self.eps_mm,
            result[1],
            self.pieces,
            self.smooth,
            self.settle_rows,
            self.settle_max,
            self.period,
        )

    def fallback(self, lv: Levers, result, stage: int) -> None:
        """The fallback of ``stage`` on ``lv`` (in place) from the check of ``result``
        (:func:`~nurbscnc.plan.shaping.fallback`)."""
        fallback(
            lv,
            result[2].overs,
            self.eps_mm,
            self.pieces,
            self.settle_rows,
            self.settle_max,
            self.period,
            stage,
        )

    def plan(self, lev: Levers, result, iterations: int) -> Plan:
        """The :class:`Plan` of the levers ``lev`` and their ``result``."""
        planned, profile = result[0], result[1]
        initial = self.initial
        feed = lev.caps < initial.caps
        transition = np.zeros(self.k, dtype=bool)
        for f in ("a_up", "j_up", "a_dn", "j_dn"):
            transition |= getattr(lev, f) < getattr(initial, f)
        return Plan(
            planned,
            lev.caps,
            profile,
            iterations,
            cycle_time_s(result),
            self.options.dynamics,
            lev.limits(),
            feed | transition,
            feed,
            transition,
            lev.settle_s,
        )


def _without_corner_feed(
    program, machine: Machine, options: LookaheadOptions, pieces: PieceList
) -> PieceList | None:
    """``pieces`` without the corner heuristic V_cf (SPEC eq. 24) in their caps: made again
    with κ̄ → ∞ (V_cf = F), so a corner piece keeps its physical caps only — the chord
    feed V_af, the normal acceleration √(A/κ), F and V_max. The corner regions (κ_th =
    A/F²) and the fits do not depend on κ̄; None if the pieces came out otherwise than
    ``pieces`` (then nothing is raised)."""
    limits = replace(machine.limits, kappa_ref_per_mm=1e15)
    free = segment_pieces(
        program.segments,
        replace(machine, limits=limits),
        options.plan,
        rotary_axes=program.rotary_axes,
    )
    if len(free) != len(pieces) or not np.array_equal(free.length_mm, pieces.length_mm):
        return None
    if not np.array_equal(junction_caps(free) > 0.0, junction_caps(pieces) > 0.0):
        return None
    return free
