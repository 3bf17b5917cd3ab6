"""Jerk-limited (S-curve) speed transitions along arc length: closed forms and inverses.

SPEC §7. A *transition* takes the feed from ``v_a`` to ``v_b`` [mm/s] with the classic
7-phase jerk-limited profile restricted to one direction of change: jerk ``±J`` for ``t_j``,
constant acceleration ``a_p`` for ``t_c``, jerk ``∓J`` for ``t_j``. The acceleration starts
and ends at zero (trapezoidal acceleration, triangular when ``A_max`` is not reached), so
transitions can be chained at any speed without an acceleration jump. With
``Δv = |v_b − v_a|``:

- ``Δv ≥ A²/J`` (A reached):  ``t_j = A/J``, ``t_c = Δv/A − A/J``, ``T = Δv/A + A/J``
- ``Δv < A²/J``:              ``t_j = √(Δv/J)``, ``t_c = 0``,        ``T = 2√(Δv/J)``
- distance ``D = (v_a + v_b)·T/2`` (the acceleration is symmetric about ``T/2``, so the
  speed is antisymmetric about its mean).

``D`` grows strictly with ``v_b`` (both factors grow), so it can be inverted: the largest
speed reachable from ``v_a`` within a distance (:func:`max_reachable_speed`, closed form) and
the peak speed of a piece too short to cruise (:func:`peak_speed`, bisection as in SPEC §7).
These replace the ``v² = v0² + 2·A·d`` rule of constant-acceleration look-ahead (Klipper's
squared-velocity scan), which has no jerk limit.

The array functions accept scalars or numpy arrays (broadcast) and return a ``float`` when
every input is a scalar. :func:`max_reachable_speed_scalar` is the same closed form in plain
``math`` for the planner's sequential scans, where numpy's per-call overhead would dominate.
"""

from __future__ import annotations

import math

import numpy as np

from nurbscnc.errors import ConfigError, PlanningError
from nurbscnc.plan.compiled import kernels as _kernels  # None: the Python loops

__all__ = [
    "check_limits",
    "check_limit_arrays",
    "max_entry_speed",
    "max_reachable_speed",
    "max_reachable_speed_scalar",
    "peak_speed",
    "peak_speed_unchecked",
    "scurve_distance_mm",
    "scurve_duration_s",
    "scurve_timing",
]


def check_limits(a_max_mm_s2: float, j_max_mm_s3: float) -> tuple[float, float]:
    """Validate the acceleration [mm/s²] and jerk [mm/s³] limits; return them as floats.

    Raises :class:`ConfigError` unless both are finite and > 0.
    """
    a = float(a_max_mm_s2)
    j = float(j_max_mm_s3)
    if not (math.isfinite(a) and a > 0.0):
        raise ConfigError(f"a_max_mm_s2 must be finite and > 0, got {a_max_mm_s2!r}")
    if not (math.isfinite(j) and j > 0.0):
        raise ConfigError(f"j_max_mm_s3 must be finite and > 0, got {j_max_mm_s3!r}")
    return a, j


def check_limit_arrays(a_max_mm_s2, j_max_mm_s3):
    """:func:`check_limits` for a scalar or an array of limits each (per piece, planner v2):
    floats when both are scalars, else float64 arrays (every element finite and > 0)."""
    if np.ndim(a_max_mm_s2) == 0 and np.ndim(j_max_mm_s3) == 0:
        return check_limits(a_max_mm_s2, j_max_mm_s3)
    a = np.asarray(a_max_mm_s2, dtype=float)
    j = np.asarray(j_max_mm_s3, dtype=float)
    if not _within(a, 0.0, False):
        raise ConfigError("a_max_mm_s2 must be finite and > 0 (every element)")
    if not _within(j, 0.0, False):
        raise ConfigError("j_max_mm_s3 must be finite and > 0 (every element)")
    return a, j


def _within(x: np.ndarray, low: float, at_low: bool) -> bool:
    """Every element finite and > ``low`` (≥ with ``at_low``): two reductions (a NaN makes
    both comparisons false), the planner's hot path validating its own arrays."""
    if x.size == 0:
        return True
    lo, hi = float(x.min()), float(x.max())
    return (lo >= low if at_low else lo > low) and hi < math.inf


def _speeds(name: str, values) -> np.ndarray:
    """float64 array of finite speeds/distances ≥ 0, or :class:`PlanningError`."""
    arr = np.asarray(values, dtype=float)
    if not _within(arr, 0.0, True):
        raise PlanningError(f"{name} must be finite and >= 0")
    return arr


def _out(x: np.ndarray, scalar: bool):
    return float(x) if scalar else x


# The two distance evaluations below (array and scalar) use the same operations in the same
# order, so they round identically: the planner checks feasibility with one and builds the
# motion with the other.
def _distance_arr(v_a: np.ndarray, v_b: np.ndarray, a: float, j: float) -> np.ndarray:
    dv = np.abs(v_b - v_a)
    t = np.where(dv * j >= a * a, dv / a + a / j, 2.0 * np.sqrt(dv / j))
    return 0.5 * (v_a + v_b) * t


def _distance_scalar(v_a: float, v_b: float, a: float, j: float) -> float:
    dv = abs(v_b - v_a)
    t = dv / a + a / j if dv * j >= a * a else 2.0 * math.sqrt(dv / j)
    return 0.5 * (v_a + v_b) * t


def scurve_timing(v_a_mm_s, v_b_mm_s, a_max_mm_s2: float, j_max_mm_s3: float):
    """Phase times of the S-curve transition ``v_a → v_b`` (SPEC §7).

    Returns ``(t_jerk_s, t_const_s, a_peak_mm_s2)``: the duration of each of the two jerk
    phases, of the constant-acceleration phase, and the peak |acceleration| (``= J·t_jerk``,
    which equals ``A_max`` when it is reached). Total time ``2·t_jerk + t_const``.
    """
    a, j = check_limit_arrays(a_max_mm_s2, j_max_mm_s3)
    scalar = all(np.ndim(x) == 0 for x in (v_a_mm_s, v_b_mm_s, a, j))
    dv = np.abs(_speeds("v_b_mm_s", v_b_mm_s) - _speeds("v_a_mm_s", v_a_mm_s))
    reached = dv * j >= a * a  # Δv ≥ A²/J
    t_j = np.where(reached, a / j, np.sqrt(dv / j))
    # Δv/A − A/J ≥ 0 on this branch; the clamp only removes a rounding -1 ulp at the boundary.
    t_c = np.where(reached, np.maximum(dv / a - a / j, 0.0), 0.0)
    a_p = j * t_j
    return _out(t_j, scalar), _out(t_c, scalar), _out(a_p, scalar)


def scurve_duration_s(v_a_mm_s, v_b_mm_s, a_max_mm_s2: float, j_max_mm_s3: float):
    """Duration T [s] of the S-curve ``v_a → v_b``: ``Δv/A + A/J`` or ``2√(Δv/J)`` (SPEC §7)."""
    a, j = check_limit_arrays(a_max_mm_s2, j_max_mm_s3)
    scalar = all(np.ndim(x) == 0 for x in (v_a_mm_s, v_b_mm_s, a, j))
    dv = np.abs(_speeds("v_b_mm_s", v_b_mm_s) - _speeds("v_a_mm_s", v_a_mm_s))
    t = np.where(dv * j >= a * a, dv / a + a / j, 2.0 * np.sqrt(dv / j))
    return _out(t, scalar)


def scurve_distance_mm(v_a_mm_s, v_b_mm_s, a_max_mm_s2: float, j_max_mm_s3: float):
    """Distance D [mm] covered by the S-curve ``v_a → v_b``: ``(v_a + v_b)·T/2`` (SPEC §7)."""
    a, j = check_limit_arrays(a_max_mm_s2, j_max_mm_s3)
    scalar = all(np.ndim(x) == 0 for x in (v_a_mm_s, v_b_mm_s, a, j))
    d = _distance_arr(_speeds("v_a_mm_s", v_a_mm_s), _speeds("v_b_mm_s", v_b_mm_s), a, j)
    return _out(d, scalar)


_sqrt, _sinh, _asinh, _cbrt, _ulp = math.sqrt, math.sinh, math.asinh, math.cbrt, math.ulp


def max_reachable_speed_scalar(
    v_from_mm_s: float, distance_mm: float, a_max_mm_s2: float, j_max_mm_s3: float
) -> float:
    """Largest ``v ≥ v_from`` [mm/s] with ``D(v_from → v) ≤ distance`` (closed form, plain math).

    Same closed form and float guard as :func:`max_reachable_speed`, without input checks:
    this is the inner loop of the look-ahead scans (the caller validated its inputs), so it
    is written flat, with the math functions bound at module level.
    """
    v0, d, a, j = v_from_mm_s, distance_mm, a_max_mm_s2, j_max_mm_s3
    if d <= 0.0:
        return v0
    a2j = a * a / j
    if d > (2.0 * v0 + a2j) * a / j:
        # A reached: Δv² + b·Δv + c = 0, b = 2v0 + A²/J, c = −2A(d − v0·A/J) < 0;
        # the cancellation-free root 2|c| / (b + √(b² + 4|c|)).
        b = 2.0 * v0 + a2j
        c = 2.0 * a * (d - v0 * a / j)
        v = v0 + 2.0 * c / (b + _sqrt(b * b + 4.0 * c))
    else:
        # A not reached: x = √(Δv/J) solves x³ + p·x − r = 0, p = 2v0/J, r = d/J.
        p = 2.0 * v0 / j
        r = d / j
        z = 1.5 * r / p * _sqrt(3.0 / p) if p > 0.0 else 2.0
        if z <= 1.0:
            x = 2.0 * _sqrt(p / 3.0) * _sinh(_asinh(z) / 3.0)
        else:
            u = _cbrt(0.5 * r + _sqrt(0.25 * r * r + p * p * p / 27.0))
            x = u - p / (3.0 * u)
        v = v0 + j * x * x
    # Float guard: D evaluated in floats (the same operations as _distance_scalar/_arr)
    # must not exceed d. Near Δv = 0, D ~ 2v0·√(Δv/J) is so steep that one ulp of v can
    # change D by several per cent, so step down (by a doubling number of ulps; v0 itself
    # always fits) until it does.
    # The distance is _distance_scalar(v0, v, a, j) written out (v > v0 inside the loop: the
    # first check failing means D(v) > d ≥ D(v0) = 0).
    a2 = a * a
    dv = v - v0
    t = dv / a + a / j if dv * j >= a2 else 2.0 * _sqrt(dv / j)
    step = 1
    while 0.5 * (v0 + v) * t > d:
        v = max(v0, v - step * _ulp(v))
        if v <= v0:
            return v
        step *= 2
        dv = v - v0
        t = dv / a + a / j if dv * j >= a2 else 2.0 * _sqrt(dv / j)
    return v


def max_reachable_speed(v_from_mm_s, distance_mm, a_max_mm_s2: float, j_max_mm_s3: float):
    """Largest ``v_to ≥ v_from`` [mm/s] reachable by an S-curve within ``distance`` [mm].

    Inverts ``D(v_from → v_to) = distance`` in closed form (SPEC §7 closed forms):

    - ``distance > (2v0 + A²/J)·A/J`` (A reached): ``D = (2v0 + Δv)(Δv/A + A/J)/2`` is a
      quadratic in Δv, solved by its cancellation-free root;
    - otherwise ``D = (2v0 + Δv)·2√(Δv/J)/2``; with ``x = √(Δv/J)`` this is the depressed
      cubic ``x³ + (2v0/J)·x − D/J = 0`` with one real root, taken in the hyperbolic form
      ``x = 2√(p/3)·sinh(asinh(z)/3)``, ``z = (3r/2p)√(3/p)`` for ``z ≤ 1`` and Cardano's
      ``x = u − p/(3u)``, ``u = ∛(r/2 + √(r²/4 + p³/27))`` otherwise (each is free of
      cancellation on its side).

    The result is then lowered by whole ulps, if needed, until :func:`scurve_distance_mm`
    of it (in floats) is ≤ ``distance``: a planner chaining these speeds never gets a piece
    that is a rounding too short. (When ``Δv`` is below one ulp of ``v_from`` the answer is
    ``v_from`` or its next float.)

    By the symmetry ``D(v_a → v_b) = D(v_b → v_a)`` this is also the largest speed from which
    one can decelerate to ``v_from`` within ``distance`` (:func:`max_entry_speed`).
    """
    a, j = check_limit_arrays(a_max_mm_s2, j_max_mm_s3)
    scalar = all(np.ndim(x) == 0 for x in (v_from_mm_s, distance_mm, a, j))
    v0, d, a, j = np.broadcast_arrays(
        _speeds("v_from_mm_s", v_from_mm_s), _speeds("distance_mm", distance_mm), a, j
    )
    shape = v0.shape
    v0, d, a, j = v0.ravel(), d.ravel(), a.ravel(), j.ravel()
    v = reach_unchecked(v0, d, a, j)
    return _out(v.reshape(shape), scalar)


def reach_unchecked(v0: np.ndarray, d: np.ndarray, a: np.ndarray, j: np.ndarray) -> np.ndarray:
    """:func:`max_reachable_speed` on validated 1-D float arrays of one length (no checks,
    no broadcasting): the closed form and the float guard, vectorised."""
    a2j = a * a / j
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        # A reached.
        b = 2.0 * v0 + a2j
        c = 2.0 * a * (d - v0 * a / j)
        dv_reached = 2.0 * c / (b + np.sqrt(b * b + 4.0 * c))
        # A not reached.
        p = 2.0 * v0 / j
        r = d / j
        z = 1.5 * r / p * np.sqrt(3.0 / p)
        x_hyp = 2.0 * np.sqrt(p / 3.0) * np.sinh(np.arcsinh(z) / 3.0)
        u = np.cbrt(0.5 * r + np.sqrt(0.25 * r * r + p * p * p / 27.0))
        x_car = u - p / (3.0 * u)
        x = np.where((p > 0.0) & (z <= 1.0), x_hyp, x_car)
        dv_free = j * x * x
    dv = np.where(d > b * a / j, dv_reached, dv_free)
    v = np.where(d > 0.0, v0 + dv, v0)
    # Float guard (see max_reachable_speed_scalar).
    step = 1.0
    bad = np.flatnonzero((v > v0) & (_distance_arr(v0, v, a, j) > d))
    while bad.size:
        v_bad = np.maximum(v0[bad], v[bad] - step * np.spacing(v[bad]))
        v[bad] = v_bad
        bad = bad[(v_bad > v0[bad]) & (_distance_arr(v0[bad], v_bad, a[bad], j[bad]) > d[bad])]
        step *= 2.0
    return v


def max_entry_speed(v_to_mm_s, distance_mm, a_max_mm_s2: float, j_max_mm_s3: float):
    """Largest speed [mm/s] from which an S-curve decelerates to ``v_to`` within ``distance``.

    ``D`` is symmetric in its end speeds, so this is :func:`max_reachable_speed`.
    """
    return max_reachable_speed(v_to_mm_s, distance_mm, a_max_mm_s2, j_max_mm_s3)


def _pair_distance_mm(v_s, v_p, v_e, a, j, a_dn=None, j_dn=None):
    """``D(v_s → v_p) + D(v_p → v_e)`` for arrays already validated (``v_p ≥ v_s, v_e``);
    the descent with ``a_dn, j_dn`` when given (else ``a, j``)."""
    a_dn = a if a_dn is None else a_dn
    j_dn = j if j_dn is None else j_dn
    return _distance_arr(v_s, v_p, a, j) + _distance_arr(v_p, v_e, a_dn, j_dn)


def _distance_slope(v_a: np.ndarray, v_b: np.ndarray, a, j) -> np.ndarray:
    """d/dv_b of ``D(v_a → v_b)`` for v_b ≥ v_a (SPEC §7's D = (v_a + v_b) T / 2 with T =
    Δv/A + A/J, or 2√(Δv/J) where A is not reached): T/2 + (v_a + v_b) T′/2."""
    dv = np.maximum(v_b - v_a, 0.0)
    reached = dv * j >= a * a
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(reached, dv / a + a / j, 2.0 * np.sqrt(dv / j))
        t_prime = np.where(reached, 1.0 / a, 1.0 / np.sqrt(dv * j))
    return 0.5 * t + 0.5 * (v_a + v_b) * t_prime


#: Safeguarded Newton steps of :func:`peak_speed_unchecked` before its closing bisection.
PEAK_NEWTON_STEPS = 8
#: Half-width (relative) of the bracket the closing bisection starts from, about the Newton
#: root, where both its ends check: 2^-40 leaves ~12 halvings to adjacent floats.
PEAK_BRACKET_REL = 2.0**-40


def peak_speed_unchecked(v_s, v_e, length, v_cap, a, j, a_dn=None, j_dn=None) -> np.ndarray:
    """:func:`_peak_speed_py`, compiled where :mod:`nurbscnc.plan._kernels` was built (the
    same floats bit for bit: one loop per piece instead of ~25 rounds of numpy calls)."""
    if _kernels is None:
        return _peak_speed_py(v_s, v_e, length, v_cap, a, j, a_dn, j_dn)
    a_dn = a if a_dn is None else a_dn
    j_dn = j if j_dn is None else j_dn
    cols = np.broadcast_arrays(v_s, v_e, length, v_cap, a, j, a_dn, j_dn)
    shape = cols[0].shape
    out = np.empty(shape)
    _kernels.peak_speeds(
        *(np.ascontiguousarray(x, dtype=np.float64) for x in cols),
        out,
        PEAK_NEWTON_STEPS,
        PEAK_BRACKET_REL,
    )
    return out


def _peak_speed_py(v_s, v_e, length, v_cap, a, j, a_dn=None, j_dn=None) -> np.ndarray:
    """:func:`peak_speed` on validated float arrays, without the feasibility check.

    Returns the largest ``v_p`` in ``[max(v_s, v_e), v_cap]`` whose pair distance is ≤
    ``length`` (``max(v_s, v_e)`` itself when even that does not fit: the caller's rounding).
    The pair distance f(v) = D(v_s → v) + D(v → v_e) rises with v: first
    :data:`PEAK_NEWTON_STEPS` Newton steps on f(v) = length, each kept inside the bracket
    (else the bracket's midpoint: Newton alone can overshoot where A is not reached, f
    being concave there), then a bracket of ±:data:`PEAK_BRACKET_REL` about the Newton
    iterate where its ends check (feasible below, not above), then bisection until the
    bracket is two adjacent floats, keeping the feasible end (so the cruise left over is
    ≥ 0). The same floats as bisection alone, in about 0.6 of its time on CAM pieces (the
    slowest element of an array decides the rounds). ``a, j`` (scalars or arrays) limit the
    rise to ``v_p``, ``a_dn, j_dn`` (default: the same) the descent from it.
    """
    a_dn = a if a_dn is None else a_dn
    j_dn = j if j_dn is None else j_dn
    v_s, v_e, length, v_cap, a, j, a_dn, j_dn = np.broadcast_arrays(
        v_s, v_e, length, v_cap, a, j, a_dn, j_dn
    )
    shape = v_s.shape
    v_s, v_e, length, v_cap, a, j, a_dn, j_dn = (
        np.ravel(x) for x in (v_s, v_e, length, v_cap, a, j, a_dn, j_dn)
    )
    lo = np.maximum(v_s, v_e)
    hi = np.maximum(v_cap, lo)
    out = hi.astype(float, copy=True)
    # A piece of zero length keeps its (equal) end speeds: no bisection down to denormals.
    out[length <= 0.0] = lo[length <= 0.0]
    todo = np.flatnonzero(
        (_pair_distance_mm(v_s, hi, v_e, a, j, a_dn, j_dn) > length) & (length > 0.0)
    )
    out[todo] = lo[todo]
    lo_t, hi_t = lo[todo], hi[todo]
    vs_t, ve_t, len_t = v_s[todo], v_e[todo], length[todo]
    lim_t = (a[todo], j[todo], a_dn[todo], j_dn[todo])
    # Safeguarded Newton: f(lo) ≤ L < f(hi) throughout.
    x = 0.5 * (lo_t + hi_t)
    for _ in range(PEAK_NEWTON_STEPS if todo.size else 0):
        f = _pair_distance_mm(vs_t, x, ve_t, *lim_t) - len_t
        ok = f <= 0.0
        lo_t = np.where(ok, x, lo_t)
        hi_t = np.where(ok, hi_t, x)
        slope = _distance_slope(vs_t, x, *lim_t[:2]) + _distance_slope(ve_t, x, *lim_t[2:])
        with np.errstate(divide="ignore", invalid="ignore"):
            step = x - f / slope
        inside = np.isfinite(step) & (step >= lo_t) & (step <= hi_t)
        x = np.where(inside, step, 0.5 * (lo_t + hi_t))
    # The closing bracket about the Newton iterate, where its ends check.
    if todo.size:
        near_lo = np.maximum(x * (1.0 - PEAK_BRACKET_REL), lo_t)
        near_hi = np.minimum(x * (1.0 + PEAK_BRACKET_REL), hi_t)
        take_lo = _pair_distance_mm(vs_t, near_lo, ve_t, *lim_t) <= len_t
        take_hi = _pair_distance_mm(vs_t, near_hi, ve_t, *lim_t) > len_t
        lo_t = np.where(take_lo, near_lo, lo_t)
        hi_t = np.where(take_hi, near_hi, hi_t)
        out[todo] = lo_t
    for _ in range(1100):  # a float64 bracket collapses in ≤ ~1075 halvings
        mid = 0.5 * (lo_t + hi_t)
        live = (mid > lo_t) & (mid < hi_t)  # else lo, hi are adjacent floats: done
        if not live.all():
            todo, lo_t, hi_t, mid = todo[live], lo_t[live], hi_t[live], mid[live]
            vs_t, ve_t, len_t = vs_t[live], ve_t[live], len_t[live]
            lim_t = tuple(x[live] for x in lim_t)
        if todo.size == 0:
            break
        ok = _pair_distance_mm(vs_t, mid, ve_t, *lim_t) <= len_t
        lo_t = np.where(ok, mid, lo_t)
        hi_t = np.where(ok, hi_t, mid)
        out[todo] = lo_t
    return out.reshape(shape)


def peak_speed(v_s_mm_s, v_e_mm_s, length_mm, v_cap_mm_s, a_max_mm_s2, j_max_mm_s3):
    """Highest speed [mm/s] a piece of ``length`` can peak at between ``v_s`` and ``v_e``.

    ``v_cap`` when ``D(v_s → v_cap) + D(v_cap → v_e) ≤ length`` (the piece cruises at the
    cap), else the ``v_p`` solving ``D(v_s → v_p) + D(v_p → v_e) = length`` by bisection on
    ``[max(v_s, v_e), v_cap]`` (SPEC §7; the sum is strictly increasing in ``v_p``).

    Raises :class:`PlanningError` if ``v_cap < max(v_s, v_e)`` or the piece is too short
    even to go straight from ``v_s`` to ``v_e`` (relative slack 1e-12).
    """
    a, j = check_limits(a_max_mm_s2, j_max_mm_s3)
    scalar = all(np.ndim(x) == 0 for x in (v_s_mm_s, v_e_mm_s, length_mm, v_cap_mm_s))
    v_s, v_e, length, v_cap = np.broadcast_arrays(
        _speeds("v_s_mm_s", v_s_mm_s),
        _speeds("v_e_mm_s", v_e_mm_s),
        _speeds("length_mm", length_mm),
        _speeds("v_cap_mm_s", v_cap_mm_s),
    )
    lo = np.maximum(v_s, v_e)
    if np.any(v_cap < lo):
        raise PlanningError("peak_speed: v_cap is below an end speed")
    need = _pair_distance_mm(v_s, lo, v_e, a, j)
    if np.any(need > length * (1.0 + 1e-12) + 1e-300):
        raise PlanningError("peak_speed: piece too short for its end speeds")
    return _out(peak_speed_unchecked(v_s, v_e, length, v_cap, a, j), scalar)
