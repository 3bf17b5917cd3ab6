"""Feed-cap formulas: every speed limit a piece of path gets from its curvature, in one place.

The elementary formulas of the paper (SPEC §5, §7) are the chord-error feed V_af (eq. 23),
the curvature feed V_cf (eq. 24) and the sharp-corner threshold κ_th = A/F² (eq. 15), all
defined here (:class:`~nurbscnc.machine.profile.Machine` offers them with its own parameters
filled in). Built from them:

- the normal-acceleration feed √(A/κ): at that speed the centripetal acceleration V²κ is A;
- the cruise cap outside corners, min(F, V_max, V_af(κ), √(A/κ))
  (:func:`curvature_cap_mm_s`), and its square (:func:`curvature_cap2_mm2_s2`, what the
  lower bound integrates);
- the corner cap V_sp = min(V_af, V_cf), bounded by F, V_max and √(A/κ)
  (:func:`corner_cap_mm_s`);
- the baselines' feeds (SPEC §9, :func:`baseline_feed_mm_s`).

All speeds in mm/s, curvatures in 1/mm, accelerations in mm/s².
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

__all__ = ["MIN_CAP_MM_S", "baseline_feed_mm_s", "chord_feed_mm_s", "corner_cap_mm_s",
           "curvature_cap2_mm2_s2", "curvature_cap_mm_s", "curvature_feed_mm_s",
           "kappa_threshold_per_mm", "normal_feed_mm_s"]  # fmt: skip


class MachineLike(Protocol):
    """What the caps read of a :class:`nurbscnc.machine.profile.Machine` (its ``limits``
    and ``servo.period_s``). A protocol, not an import: profile.py uses the formulas
    defined here, so this module cannot import it back."""

    @property
    def limits(self): ...

    @property
    def servo(self): ...


#: The lowest cruise cap a piece gets [mm/s]: never a zero cap, which would stall the tool.
MIN_CAP_MM_S = 1e-3


# ---------------------------------------------------------------------------------------------
# The paper's elementary formulas (pure, vectorised; SPEC §5 and §7).


def _as_result(values: np.ndarray):
    """A float for a 0-d result, else the array itself."""
    return float(values) if values.ndim == 0 else values


def kappa_threshold_per_mm(feed_mm_s, a_max_mm_s2: float):
    """Sharp-corner curvature threshold κ_th = A_max / F² [1/mm] (SPEC §5, eq. 15).

    ``feed_mm_s`` [mm/s] scalar or array; a feed ≤ 0 gives ``inf`` (nothing is sharp at rest).
    """
    f = np.asarray(feed_mm_s, dtype=float)
    safe = np.where(f > 0.0, f, 1.0)
    return _as_result(np.where(f > 0.0, a_max_mm_s2 / (safe * safe), np.inf))


def chord_feed_mm_s(kappa_per_mm, period_s: float, chord_tolerance_mm: float):
    """Chord-error feed V_af = (2/T_s)·√(2δ/κ − δ²) [mm/s] (SPEC §7, eq. 23; Yeh & Hsu 2002).

    The chord of one period on a circle of radius 1/κ whose sagitta is δ has half-length
    √(2δ/κ − δ²), for radius ≥ δ. Below radius δ no chord can have a sagitta above the radius,
    so the chord error cannot exceed δ whatever the step: the formula (which would fall to 0
    at radius δ/2 and stall the tool) is held at its radius-δ value 2δ/T_s there, continuous
    and never 0; the normal-acceleration limit governs such tight curves anyway. Curvature is
    unsigned here: ``|kappa|`` is used, so a signed curvature cannot skip the slowdown.
    κ = 0 (straight) gives ``inf``. Never NaN for non-NaN input.
    """
    d = float(chord_tolerance_mm)
    k = np.minimum(np.abs(np.asarray(kappa_per_mm, dtype=float)), 1.0 / d)
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        half_chord_sq = d * (2.0 / k - d)  # 2δ/κ − δ², +inf for κ = 0
        v = (2.0 / period_s) * np.sqrt(np.maximum(half_chord_sq, 0.0))
    return _as_result(np.where(k == 0.0, np.inf, v))


def curvature_feed_mm_s(kappa_per_mm, v_max_mm_s: float, kappa_ref_per_mm: float):
    """Curvature feed V_cf = V_max·κ̄/(κ + κ̄) [mm/s] (SPEC §7, eq. 24; Zhiming 2002).

    ``|kappa|`` is used (unsigned curvature); κ = 0 gives V_max, κ → ∞ gives 0.
    """
    k = np.abs(np.asarray(kappa_per_mm, dtype=float))
    with np.errstate(invalid="ignore"):
        v = v_max_mm_s * kappa_ref_per_mm / (k + kappa_ref_per_mm)
    return _as_result(np.where(np.isinf(k), 0.0, v))


# ---------------------------------------------------------------------------------------------
# Caps built from them.


def normal_feed_mm_s(kappa_per_mm, a_max_mm_s2: float):
    """√(A/κ) [mm/s]: the feed whose normal acceleration V²κ on curvature κ is A (inf at
    κ = 0)."""
    kappa = np.asarray(kappa_per_mm, dtype=float)
    with np.errstate(divide="ignore"):
        return np.sqrt(a_max_mm_s2 / np.maximum(kappa, 1e-300))


def curvature_cap_mm_s(machine: MachineLike, kappa_per_mm, feed_mm_s) -> np.ndarray:
    """Feed cap [mm/s] at curvature κ outside corners: min(F, V_max, V_af(κ), √(A/κ))
    (elementwise; ``feed_mm_s`` F a scalar or an array like ``kappa_per_mm``)."""
    lim = machine.limits
    kappa = np.asarray(kappa_per_mm, dtype=float)
    v_af = np.asarray(chord_feed_mm_s(kappa, machine.servo.period_s, lim.chord_tolerance_mm))
    v_an = normal_feed_mm_s(kappa, lim.a_max_mm_s2)
    return np.minimum(np.minimum(v_af, v_an), np.minimum(feed_mm_s, lim.v_max_mm_s))


def curvature_cap2_mm2_s2(kappa_per_mm, v_top_mm_s: float, a_max_mm_s2: float, period_s: float,
                          chord_mm: float) -> np.ndarray:  # fmt: skip
    """The square of the curvature cap, min(v_top², V_af(κ)², A/κ) [mm²/s²], computed in
    squares (the lower bound works with v²); κ = 0 leaves v_top², κ = inf gives 0."""
    k = np.abs(np.asarray(kappa_per_mm, dtype=float))
    v_af = np.asarray(chord_feed_mm_s(k, period_s, chord_mm), dtype=float)
    with np.errstate(divide="ignore"):
        normal = np.where(k > 0.0, a_max_mm_s2 / k, np.inf)
    return np.minimum(np.minimum(v_top_mm_s * v_top_mm_s, v_af * v_af), normal)


def corner_cap_mm_s(machine: MachineLike, kappa_peak_per_mm: float, feed_mm_s: float,
                    kappa_cf_per_mm: float | None = None) -> float:  # fmt: skip
    """V_sp = min(V_af, V_cf) at a corner of peak curvature κ (SPEC §7), capped by F, V_max
    and the normal-acceleration limit √(A/κ); at least 1e-6 mm/s. ``kappa_cf_per_mm``
    (default: the peak) is the curvature given to V_cf: the physical limits (chord error,
    normal acceleration) always see the peak, while the paper's heuristic slow-down
    V_cf = F κ̄/(κ + κ̄) may be given a piece's mean curvature (turning / length) — at the
    peak of a near-cusp (κ ~ 1e6 /mm) it would otherwise crawl the whole piece at F/κ."""
    lim = machine.limits
    f = min(feed_mm_s, lim.v_max_mm_s)
    kappa_cf = kappa_peak_per_mm if kappa_cf_per_mm is None else kappa_cf_per_mm
    v_af = float(chord_feed_mm_s(kappa_peak_per_mm, machine.servo.period_s,
                                 lim.chord_tolerance_mm))  # fmt: skip
    v_cf = float(curvature_feed_mm_s(kappa_cf, f, lim.kappa_ref_per_mm))
    v_sp = min(v_af, v_cf)
    v_an = (float(np.sqrt(lim.a_max_mm_s2 / kappa_peak_per_mm)) if kappa_peak_per_mm > 0
            else np.inf)  # fmt: skip
    return max(min(v_sp, v_an, feed_mm_s, lim.v_max_mm_s), 1e-6)


def baseline_feed_mm_s(algorithm: str, kappa_per_mm, feed_mm_s: float, machine: MachineLike):
    """A baseline's feed [mm/s] at curvature κ (SPEC §9) with programmed feed F:
    ``adaptive`` min(F', V_af(κ)), ``curvature`` V_cf(κ) with F' = min(F, V_max)."""
    lim = machine.limits
    f = min(feed_mm_s, lim.v_max_mm_s)
    if algorithm == "adaptive":
        v = chord_feed_mm_s(kappa_per_mm, machine.servo.period_s, lim.chord_tolerance_mm)
        return np.minimum(np.asarray(v, dtype=float), f)
    if algorithm == "curvature":
        return np.asarray(curvature_feed_mm_s(kappa_per_mm, f, lim.kappa_ref_per_mm), dtype=float)
    raise ValueError(f"unknown baseline {algorithm!r}")
