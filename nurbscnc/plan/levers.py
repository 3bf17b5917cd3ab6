"""What the contour check may change of a plan, per piece (:class:`Levers`): the cruise
caps, the rise and descent limits, the settles after rapids; and how the improvement phase
moves them between brackets (:meth:`Levers.toward`, :meth:`Levers.narrowed`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbscnc.plan.plans import Limits

#: A lever within this ratio of its bracket's upper end is left alone.
IMPROVE_RATIO = 1.005


@dataclass
class Levers:
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
    #: Pieces whose feed the curve lever lowered without effect
    #: (:func:`~nurbscnc.plan.shaping.local_factors`): not lowered by it again, and the
    #: over-limit samples near them blame the servo's whole memory
    #: (:data:`~nurbscnc.plan.shaping.BLAME_WINDOW_S`) instead of
    #: :data:`~nurbscnc.plan.shaping.CURVE_BLAME_WINDOW_S`.
    ineffective: np.ndarray
    cap_history: tuple | None = None
    stop_history: dict | None = None

    #: The levers the improvement phase scales (geometric means between brackets).
    SCALED = ("caps", "a_up", "j_up", "a_dn", "j_dn")
    #: Every per-piece column (k,), in field order.
    PER_PIECE = (*SCALED, "settle_s", "shaped", "ineffective")

    def limits(self) -> Limits:
        """The rise and descent limits as the profile takes them."""
        return Limits(self.a_up, self.j_up, self.a_dn, self.j_dn)

    def copy(self) -> Levers:
        """A copy with its own per-piece columns (the histories shared: never changed in
        place)."""
        return Levers(
            *(getattr(self, f).copy() for f in self.PER_PIECE), self.cap_history, self.stop_history
        )

    def toward(self, hi: Levers) -> Levers | None:
        """Halfway to ``hi`` (geometric means of the scaled levers, arithmetic of the
        settles); None when every lever is within 0.5 % of it."""
        out = self.copy()
        moved = False
        for f in self.SCALED:
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

    def narrowed(self, trial: Levers, probe: Levers) -> Levers:
        """These upper brackets with the levers that ``probe`` (the shaping rule applied
        to ``trial``) lowered set to their ``trial`` values (infeasible there); when the
        rule blames none, every tried lever."""
        out = self.copy()
        blamed = {f: getattr(probe, f) < getattr(trial, f) for f in self.SCALED}
        blamed_settle = probe.settle_s > trial.settle_s
        if not (any(b.any() for b in blamed.values()) or blamed_settle.any()):
            blamed = {f: np.ones(trial.caps.size, dtype=bool) for f in self.SCALED}
            blamed_settle = np.ones(trial.caps.size, dtype=bool)
        for f, b in blamed.items():
            getattr(out, f)[b] = getattr(trial, f)[b]
        out.settle_s[blamed_settle] = trial.settle_s[blamed_settle]
        return out
