"""A unit profile's flanks replaced by gated flanks (:func:`gate_units`) where a unit's
speed exceeds the caps of its pieces and the gated flanks fit in the unit."""

from __future__ import annotations

import numpy as np

from nurbscnc.plan.feedrate import scurve_timing
from nurbscnc.plan.gated import MIN_GATES, gated_rise_of, merged_phases
from nurbscnc.plan.profile import Profile, frozen_array


def _scurve_phases(tj: float, tc: float, rising: bool, j: float) -> tuple[list, list]:
    """The constant-jerk phases (durations [s], jerks [mm/s³]) of an S-curve (SPEC §7) with
    jerk phases ``tj`` [s] and constant acceleration ``tc`` [s] (:func:`scurve_timing`, for
    all units at once), read from rest of acceleration to rest of acceleration."""
    sign = 1.0 if rising else -1.0
    return merged_phases([tj, tc, tj], [sign * j, 0.0, -sign * j])


def _rows(durs: list, jerks: list, s0: float, v0: float) -> tuple[np.ndarray, float]:
    """(n, 5) rows (duration, jerk, a0, v0, s0) of phases started at rest of acceleration
    at ``s0`` [mm], ``v0`` [mm/s], integrated exactly (cubics), and the end position [mm]
    (the flank's distance is taken from this very sum, so the unit's phases meet to the
    last ulp: a position jump of 1e-12 mm shows as 10 mm/s³ in a 50 µs finite difference)."""
    rows = np.empty((len(durs), 5))
    s, v, a = s0, v0, 0.0
    a_scale = 0.0
    for i, (d, jk) in enumerate(zip(durs, jerks, strict=True)):
        rows[i] = (d, jk, a, v, s)
        s, v, a = (
            s + d * (v + d * (0.5 * a + d * jk / 6.0)),
            v + d * (a + 0.5 * d * jk),
            a + d * jk,
        )
        # A braked acceleration is 0, not the rounding of Σ jerk·duration (2e-12 mm/s²
        # held over a 500 s cruise would raise the speed by 1e-9 mm/s).
        a_scale = max(a_scale, abs(a))
        if abs(a) <= 1e-9 * a_scale:
            a = 0.0
    return rows, s


def _per_unit(unit: np.ndarray, values: np.ndarray, reduce) -> tuple[np.ndarray, np.ndarray]:
    """The distinct ``unit`` numbers (sorted) and ``reduce`` (a ufunc: np.minimum, …) of the
    ``values`` of each."""
    order = np.argsort(unit, kind="stable")
    u = unit[order]
    starts = np.flatnonzero(np.r_[True, u[1:] != u[:-1]])
    return u[starts], reduce.reduceat(values[order], starts)


def gate_units(
    unit: Profile,
    over: np.ndarray,
    c: np.ndarray,
    cum: np.ndarray,
    first: np.ndarray,
    bounds: np.ndarray,
    unit_of: np.ndarray,
    unit_cap: np.ndarray,
    lims,
    d_up: np.ndarray,
    d_dn: np.ndarray,
) -> tuple[Profile, np.ndarray, np.ndarray]:
    """The unit profile with *gated flanks* (:func:`gated_rise`) in the units whose speed
    exceeds the caps ``c`` of the pieces ``over``: a rising flank under the caps of the
    pieces before the unit's first piece at its cap (each a gate at the piece's end), a
    falling flank under those after its last one (gates at the piece starts, planned time
    reversed). The unit keeps its end speeds and peak; it is gated only if both flanks fit
    in its length (else its offenders stay for :func:`_splits`). ``d_up``, ``d_dn``
    (units,): the units' rise and descent distances [mm], updated in place where gated.
    Returns the profile (per unit) and those distances."""
    a_up, j_up, a_dn, j_dn = (
        np.broadcast_to(np.asarray(x, dtype=float), (first.size,)) for x in lims
    )
    v_s, v_e = unit.junction_speeds_mm_s[:-1], unit.junction_speeds_mm_s[1:]
    v_p = unit.piece_peak_speed_mm_s
    # Every unit's S-curve phase times at once (elementwise IEEE operations: the same bits as
    # one unit at a time, without a numpy call per unit and flank).
    tj_up, tc_up, _ = scurve_timing(v_s, v_p, a_up, j_up)
    tj_dn, tc_dn, _ = scurve_timing(v_p, v_e, a_dn, j_dn)
    idx = np.arange(c.size)
    is_top = c == unit_cap[unit_of]
    top_first = np.minimum.reduceat(np.where(is_top, idx, c.size), first)
    top_last = np.maximum.reduceat(np.where(is_top, idx, -1), first)
    phase_rows = {}
    # The offenders' first and last piece per unit (one pass; not a scan of ``over`` per unit).
    units, o_min = _per_unit(unit_of[over], over, np.minimum)
    _, o_max = _per_unit(unit_of[over], over, np.maximum)
    for u, lo_over, hi_over in zip(units.tolist(), o_min.tolist(), o_max.tolist(), strict=True):
        lo, hi = int(bounds[u]), int(bounds[u + 1])  # pieces lo … hi − 1
        n_pre = min(int(top_first[u]), hi) - lo
        n_post = hi - max(int(top_last[u]) + 1, lo)
        gate_pre = lo_over < top_first[u] and n_pre >= MIN_GATES
        gate_post = hi_over > top_last[u] and n_post >= MIN_GATES
        if not (gate_pre or gate_post):  # nothing to gate: the unit is split as before
            continue
        s_a, s_b = cum[lo], cum[hi]
        vs, vp, ve = float(v_s[u]), float(v_p[u]), float(v_e[u])
        rise = _scurve_phases(float(tj_up[u]), float(tc_up[u]), vp >= vs, j_up[u])
        fall = _scurve_phases(float(tj_dn[u]), float(tc_dn[u]), ve >= vp, j_dn[u])
        du, dd = float(d_up[u]), float(d_dn[u])
        pre = np.arange(lo, lo + n_pre)
        post = np.arange(hi - n_post, hi)[::-1]
        ok = True
        if gate_pre:
            g = gated_rise_of(vs, vp, cum[pre + 1] - s_a, c[pre], a_up[u], j_up[u])
            ok = g is not None
            if ok:
                rise, du = g[0], g[2]
        if ok and gate_post:
            g = gated_rise_of(ve, vp, s_b - cum[post], c[post], a_dn[u], j_dn[u])
            ok = g is not None
            if ok:
                fall, dd = g[1], g[2]
        if not ok or du + dd > (s_b - s_a) * (1.0 + 1e-12):
            continue
        up_rows, up_end = _rows(*rise, s_a, vs)
        dn_rows, dd = _rows(*fall, 0.0, vp)
        du = up_end - s_a
        if du + dd > (s_b - s_a) * (1.0 + 1e-12):
            continue
        cruise = max(s_b - s_a - du - dd, 0.0)
        dn_rows[:, 4] += s_b - dd
        mid = np.array([[cruise / vp if vp > 0 else 0.0, 0.0, 0.0, vp, s_a + du]])
        rows = np.concatenate((up_rows, mid if cruise > 0.0 else mid[:0], dn_rows))
        phase_rows[u] = rows
        d_up[u], d_dn[u] = du, dd
    if not phase_rows:
        return unit, d_up, d_dn
    # Every unit's phases, the gated ones replaced; times re-accumulated.
    pu = unit.phase_piece_index
    old = np.column_stack(
        (
            unit.phase_duration_s,
            unit.phase_jerk_mm_s3,
            unit.phase_a0_mm_s2,
            unit.phase_v0_mm_s,
            unit.phase_s0_mm,
        )
    )
    parts, owner = [], []
    for u in range(first.size):
        rows = phase_rows.get(u)
        if rows is None:
            rows = old[pu == u]
        parts.append(rows)
        owner.append(np.full(rows.shape[0], u, dtype=np.int64))
    rows = np.concatenate(parts)
    owner = np.concatenate(owner)
    t0 = np.concatenate(([0.0], np.cumsum(rows[:, 0])))
    unit_t = t0[np.searchsorted(owner, np.arange(first.size), side="left")]
    gated = Profile(
        total_length_mm=unit.total_length_mm,
        duration_s=float(t0[-1]),
        junction_speeds_mm_s=unit.junction_speeds_mm_s,
        piece_peak_speed_mm_s=unit.piece_peak_speed_mm_s,
        piece_start_mm=unit.piece_start_mm,
        piece_start_time_s=frozen_array(unit_t),
        phase_start_time_s=frozen_array(t0[:-1]),
        phase_duration_s=frozen_array(rows[:, 0]),
        phase_s0_mm=frozen_array(rows[:, 4]),
        phase_v0_mm_s=frozen_array(rows[:, 3]),
        phase_a0_mm_s2=frozen_array(rows[:, 2]),
        phase_jerk_mm_s3=frozen_array(rows[:, 1]),
        phase_piece_index=frozen_array(owner, dtype=np.int64),
    )
    return gated, d_up, d_dn
