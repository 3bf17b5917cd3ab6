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
- the baselines' feeds (SPEC §9, :func:`baseline_feed_mm_s`);
- the path limits that keep every axis within its own velocity, acceleration and jerk
  limits on a piece (:func:`axis_path_limits`);
- the junction cap where the curvature vector jumps (a line into an arc, two arcs of other
  radii): the acceleration steps there, a jerk impulse (:func:`junction_jump_cap_mm_s`).

All speeds in mm/s, curvatures in 1/mm, accelerations in mm/s².
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

__all__ = [
    "JUNCTION_SHARE",
    "MIN_CAP_MM_S",
    "axis_path_limits",
    "baseline_feed_mm_s",
    "chord_feed_mm_s",
    "corner_cap_mm_s",
    "curvature_cap2_mm2_s2",
    "curvature_cap_mm_s",
    "curvature_feed_mm_s",
    "junction_jump_cap_mm_s",
    "kappa_threshold_per_mm",
    "normal_feed_mm_s",
    "rotary_path_limits",
    "servo_curve_cap_mm_s",
]


class MachineLike(Protocol):
    """What the caps read of a :class:`nurbscnc.machine.profile.Machine` (its ``limits``
    and ``servo.period_s``). A protocol, not an import: profile.py uses the formulas
    defined here, so this module cannot import it back."""

    @property
    def limits(self): ...

    @property
    def servo(self): ...


#: Share of each axis's acceleration and jerk limit the normal (centripetal) part may take on
#: a curve (:func:`axis_path_limits`, the feed cap); the tangential part gets the rest.
NORMAL_SHARE = 0.5

#: Share of each axis's jerk limit the acceleration step at a curvature jump may take
#: (:func:`junction_jump_cap_mm_s`); the pieces on both sides of such a junction keep to the
#: rest on that axis (:func:`nurbscnc.plan.axes.piece_limits`).
JUNCTION_SHARE = 0.5

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


def curvature_cap2_mm2_s2(
    kappa_per_mm, v_top_mm_s: float, a_max_mm_s2: float, period_s: float, chord_mm: float
) -> np.ndarray:
    """The square of the curvature cap, min(v_top², V_af(κ)², A/κ) [mm²/s²], computed in
    squares (the lower bound works with v²); κ = 0 leaves v_top², κ = inf gives 0."""
    k = np.abs(np.asarray(kappa_per_mm, dtype=float))
    v_af = np.asarray(chord_feed_mm_s(k, period_s, chord_mm), dtype=float)
    with np.errstate(divide="ignore"):
        normal = np.where(k > 0.0, a_max_mm_s2 / k, np.inf)
    return np.minimum(np.minimum(v_top_mm_s * v_top_mm_s, v_af * v_af), normal)


def corner_cap_mm_s(
    machine: MachineLike,
    kappa_peak_per_mm: float,
    feed_mm_s: float,
    kappa_cf_per_mm: float | None = None,
) -> float:
    """V_sp = min(V_af, V_cf) at a corner of peak curvature κ (SPEC §7), capped by F, V_max
    and the normal-acceleration limit √(A/κ); at least 1e-6 mm/s. ``kappa_cf_per_mm``
    (default: the peak) is the curvature given to V_cf: the physical limits (chord error,
    normal acceleration) always see the peak, while the paper's heuristic slow-down
    V_cf = F κ̄/(κ + κ̄) may be given a piece's mean curvature (turning / length) — at the
    peak of a near-cusp (κ ~ 1e6 /mm) it would otherwise crawl the whole piece at F/κ."""
    lim = machine.limits
    f = min(feed_mm_s, lim.v_max_mm_s)
    kappa_cf = kappa_peak_per_mm if kappa_cf_per_mm is None else kappa_cf_per_mm
    v_af = float(chord_feed_mm_s(kappa_peak_per_mm, machine.servo.period_s, lim.chord_tolerance_mm))
    v_cf = float(curvature_feed_mm_s(kappa_cf, f, lim.kappa_ref_per_mm))
    v_sp = min(v_af, v_cf)
    v_an = float(np.sqrt(lim.a_max_mm_s2 / kappa_peak_per_mm)) if kappa_peak_per_mm > 0 else np.inf
    return max(min(v_sp, v_an, feed_mm_s, lim.v_max_mm_s), 1e-6)


def servo_curve_cap_mm_s(kappa_per_mm, error_mm: float, gain_s2: float):
    """Feed cap [mm/s] at curvature κ [1/mm] that keeps the servo's steady contour error on
    the curve within ``error_mm``: in steady circular motion at speed V the tool's path
    radius grows by g·V²κ (g = |c₂ + c₁²/2| [s²], :func:`nurbscnc.servo.model.error_series`;
    SPEC §8: 2.85e-5 s² for the paper's axes), so V ≤ √(e / (g κ)). ``inf`` where κ = 0 or
    g = 0 (no servo model). Vectorised over ``kappa_per_mm``."""
    k = np.abs(np.asarray(kappa_per_mm, dtype=float))
    with np.errstate(divide="ignore"):
        v = np.sqrt(error_mm / (gain_s2 * k)) if gain_s2 > 0.0 else np.full(k.shape, np.inf)
    return _as_result(np.where(k > 0.0, v, np.inf))


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


def axis_path_limits(
    t_bound,
    k_bound,
    g_bound,
    kappa_per_mm,
    v_piece_mm_s,
    v_axis_mm_s,
    a_axis_mm_s2,
    j_axis_mm_s3,
    a_path_mm_s2: float,
    j_path_mm_s3: float,
):
    """Path limits of k pieces that keep every axis within its own limits.

    Inputs per piece and axis (k, 3): ``t_bound`` T_i ≥ |t_i| (unit tangent), ``k_bound``
    K_i ≥ |(κn)_i| [1/mm] (curvature vector) and ``g_bound`` G_i ≥ |d(κn)_i/ds| [1/mm²], each
    over the whole piece; ``kappa_per_mm`` (k,) κ̄ ≥ κ on the piece [1/mm];
    ``v_piece_mm_s`` (k,) the piece's own cruise cap [mm/s]; the axis
    limits (3,) V_i [mm/s], A_i [mm/s²], J_i [mm/s³] (``inf``: none; J_i may also be given per
    piece, (k, 3): the share left beside a curvature jump); the path limits A, J.
    Returns (k,) each: the feed cap v̄ [mm/s] (``inf`` when no axis caps the feed), the
    tangential acceleration ā [mm/s²] and jerk j̄ [mm/s³].

    Derivation. Along the path p(s(t)) with speed v = ṡ, tangential acceleration a = v̇ and
    jerk j = ä, and dt/ds = κn (Frenet):

        ṗ = v t,    p̈ = a t + v² κn,    p⃛ = j t + 3 v a κn + v³ d(κn)/ds.

    With 0 ≤ v ≤ v̄, |a| ≤ ā, |j| ≤ j̄ on the piece, axis i is within its limits if

        v̄ T_i ≤ V_i,    ā T_i + v̄² K_i ≤ A_i,    j̄ T_i + 3 v̄ ā K_i + v̄³ G_i ≤ J_i.

    Lines have K = G = 0: v̄ = min V_i/T_i, ā = min A_i/T_i, j̄ = min J_i/T_i, exact (direction
    cosines). On curves the normal terms share the axis limits with the tangential ones. The
    split chosen: the normal part may take at most half (:data:`NORMAL_SHARE`) of each axis
    limit, v̄ ≤ √(A_i / (2K_i)) and v̄ ≤ (J_i / (2G_i))^(1/3) (feed caps), and the tangential
    part gets what the normal part leaves at the speed the piece can actually reach, v̄
    (which also counts the piece's own cap: a slow piece leaves more to the tangential part):

        ā ≤ max((A_i − v̄² K_i) / T_i, √(A_i² − v̄⁴ κ̄²))  (≥ A_i / (2 T_i)),
        R_i = J_i − v̄³ G_i                            (≥ J_i / 2),
        ā ≤ R_i / (6 v̄ K_i)                           (the term 3 v̄ ā K_i takes ≤ R_i / 2),
        j̄ ≤ (R_i − 3 v̄ ā K_i) / T_i                   (≥ R_i / (2 T_i)).

    The second form of the acceleration bound: t and n are orthonormal, so t_i² + n_i² ≤ 1
    and by Cauchy–Schwarz |a t_i + v²κ n_i| ≤ √(a² + v⁴κ²); it is the tighter one where an
    axis sees both the whole tangent and the whole normal (T_i = 1, K_i = κ: a full circle),
    giving ā = A_i √3/2 at the half split instead of A_i/2.

    Without axis jerk limits the half split keeps the tangential acceleration at least half
    the axis's, so the planner never crawls into a tight arc; on gentle curves (v̄² K_i small)
    nearly all of A_i remains tangential. With axis jerk limits the coupling 3 v̄ ā K_i can
    be the binding one (speeding up along a curve turns the centripetal acceleration): on
    R = 4 mm at 50 mm/s with J_i = 3e4 it leaves ā ≈ 280 mm/s²; that is the physics of the
    limit, not a margin. The results are capped by the path limits A and J.
    """
    t = np.asarray(t_bound, dtype=float)
    kb = np.asarray(k_bound, dtype=float)
    g = np.asarray(g_bound, dtype=float)
    v_i = np.asarray(v_axis_mm_s, dtype=float)[None, :]
    a_i = np.asarray(a_axis_mm_s2, dtype=float)[None, :]
    j_i = np.asarray(j_axis_mm_s3, dtype=float)
    j_i = j_i if j_i.ndim == 2 else j_i[None, :]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        # Feed caps (k,): velocity, then half the acceleration and jerk for the normal part.
        v_cap = np.min(np.where(t > 0.0, v_i / t, np.inf), axis=1)
        share = NORMAL_SHARE
        v_cap = np.minimum(
            v_cap, np.min(np.where(kb > 0.0, np.sqrt(share * a_i / kb), np.inf), axis=1)
        )
        v_cap = np.minimum(
            v_cap, np.min(np.where(g > 0.0, np.cbrt(share * j_i / g), np.inf), axis=1)
        )
        v_bar = np.minimum(v_cap, np.asarray(v_piece_mm_s, dtype=float))[:, None]
        normal_a = np.where(kb > 0.0, v_bar * v_bar * kb, 0.0)
        a_room = np.where(np.isfinite(a_i), a_i - normal_a, np.inf)
        a_t = np.where(t > 0.0, a_room / t, np.inf)
        kap = np.asarray(kappa_per_mm, dtype=float)[:, None]
        a_t = np.maximum(a_t, np.sqrt(np.maximum(a_i * a_i - (v_bar * v_bar * kap) ** 2, 0.0)))
        rest_j = np.where(np.isfinite(j_i), j_i - np.where(g > 0.0, v_bar**3 * g, 0.0), np.inf)
        coupling = 3.0 * v_bar * kb  # mm/s · 1/mm: the jerk per unit tangential acceleration
        a_t = np.minimum(a_t, np.where(coupling > 0.0, rest_j / (2.0 * coupling), np.inf))
        a_bar = np.minimum(a_t.min(axis=1), a_path_mm_s2)
        j_room = rest_j - np.where(coupling > 0.0, coupling * a_bar[:, None], 0.0)
        j_t = np.where(t > 0.0, j_room / t, np.inf)
        j_bar = np.minimum(j_t.min(axis=1), j_path_mm_s3)
    return v_cap, a_bar, j_bar


def junction_jump_cap_mm_s(
    dkn_per_mm,
    period_s: float,
    j_path_mm_s3: float,
    j_axis_mm_s3=None,
    share: float = JUNCTION_SHARE,
):
    """Speed cap [mm/s] at junctions where the curvature vector κn jumps by ``dkn_per_mm``
    (m, 3) [1/mm]: v ≤ √(4 J T / (3 |Δ(κn)|)) for the path jerk J = J_max, and
    v ≤ √(4 s J_i T / (3 |Δ(κn)_i|)) for each axis i with a jerk limit J_i (``j_axis_mm_s3``
    (3,), ``inf``: none) and share s (:data:`JUNCTION_SHARE`); ``inf`` where nothing jumps.

    Derivation. The planned profile has zero tangential acceleration at every junction
    (:mod:`nurbscnc.plan.profile`), so there the acceleration p̈ = a t + v² κn steps by
    Δp̈ = v² Δ(κn) — on axis i by v² Δ(κn)_i — in no time: a jerk impulse Δp̈ δ(t − t_j).
    On the reference points (one per period T) the third divided difference is the jerk
    averaged with the quadratic B-spline kernel M₂ of width 3T (positive, integral 1, peak
    3/(4T) at its centre), so the impulse shows as Δp̈ · M₂(t_j − t_k) ≤ (3/4) |Δp̈| / T,
    reached when a sample pair straddles t_j symmetrically. Keeping that within a jerk
    budget B gives v² |Δ(κn)| · 3/(4T) ≤ B, i.e. v ≤ √(4 B T / (3 |Δ(κn)|)). Path: B = J_max,
    applied to the normal step (J_max bounds the tangential jerk, which is continuous at the
    junction). Axis i: B = s J_i, and the continuous jerk of the pieces on both sides
    (j t_i + 3 v a (κn)_i + v³ d(κn)_i/ds) keeps to (1 − s) J_i there, so the samples stay
    within J_i. With T = 1 ms, J = 5e4 mm/s³, a line into an R 5 mm arc: 18.3 mm/s; two
    tangent arcs of R 50 and 51 mm (Δκ = 3.9e-4 /mm): 412 mm/s (no cap in practice).
    """
    dkn = np.abs(np.asarray(dkn_per_mm, dtype=float)).reshape(-1, 3)
    with np.errstate(divide="ignore"):
        size = np.sqrt(np.sum(dkn * dkn, axis=1))
        cap = np.sqrt(4.0 * j_path_mm_s3 * period_s / (3.0 * size))
        if j_axis_mm_s3 is not None:
            j_i = np.asarray(j_axis_mm_s3, dtype=float)[None, :]
            per_axis = np.sqrt(4.0 * share * j_i * period_s / (3.0 * dkn))
            cap = np.minimum(cap, per_axis.min(axis=1))
    return cap


def rotary_path_limits(share, v_axis_deg_s, a_axis_deg_s2, j_axis_deg_s3):
    """Path limits of k pieces (or rotary-only moves) that keep every rotary axis within its
    own limits, and the axis that sets the feed.

    ``share`` (k, 3): |dA_i/ds| per piece [deg/mm] (A linear in the XYZ arc length along a
    move, trivkins), or for a rotary-only move the axis's share |ΔA_i| / √(ΔA² + ΔB² + ΔC²)
    of the move (the path then in degrees); the axis limits (3,) V_i [deg/s], A_i [deg/s²],
    J_i [deg/s³]. A_i(s) is linear in s, so the axis's velocity, acceleration and jerk are
    T_i v, T_i a, T_i j with T_i the share (no curvature term: K = G = 0 of
    :func:`axis_path_limits`): v ≤ V_i/T_i, a ≤ A_i/T_i, j ≤ J_i/T_i, exact.
    Returns (k,) each: the feed cap, the acceleration and the jerk (inf where no axis moves)
    and the index (0, 1, 2 for A, B, C) of the axis whose velocity limit sets the feed cap
    (-1 where none does)."""
    t = np.asarray(share, dtype=float)
    out = []
    for lim in (v_axis_deg_s, a_axis_deg_s2, j_axis_deg_s3):
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # tiny share: inf
            x = np.where(t > 0.0, np.asarray(lim, dtype=float)[None, :] / t, np.inf)
        out.append(x)
    v = out[0].min(axis=1) if t.shape[0] else np.zeros(0)
    axis = np.where(np.isfinite(v), np.argmin(out[0], axis=1), -1) if t.shape[0] else v
    return v, out[1].min(axis=1), out[2].min(axis=1), np.asarray(axis, dtype=np.int64)
