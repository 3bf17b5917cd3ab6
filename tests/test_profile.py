"""Feed profile over pieces (SPEC §7): closed-form single pieces, the bidirectional scan's
feasibility and local maximality, bounded look-ahead, and the exact piecewise-cubic motion
(property tests on random piece sequences)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import cumulative_trapezoid

from nurbscnc.errors import ConfigError, PlanningError
from nurbscnc.plan.feedrate import max_reachable_speed_scalar, scurve_distance_mm
from nurbscnc.plan.profile import ProfileInput
from nurbscnc.plan.profile_plan import plan_profile
from nurbscnc.plan.scans import plan_profile_pieces, repair_junctions

A = 2450.0  # SPEC §9 Table 3
J = 5.0e4
INF = math.inf


def _plan(lengths, v_max, v_junction, a=A, j=J, lookahead=None):
    """The per-piece planner (every piece boundary a zero-acceleration junction): the
    junction-level properties below are stated for it; plan_profile's merging of
    unconstrained junctions is tested separately (test_merged_*)."""
    return plan_profile_pieces(
        ProfileInput(
            np.asarray(lengths, float),
            np.asarray(v_max, float),
            np.asarray(v_junction, float),
            a,
            j,
            lookahead,
        )
    )


def _rest_to_rest_time(v, length, a=A, j=J):
    """Closed form of one piece rest → v → rest with a cruise (SPEC §7)."""
    t_ramp = v / a + a / j if v >= a * a / j else 2.0 * math.sqrt(v / j)
    d_ramp = v * t_ramp / 2.0
    assert 2 * d_ramp <= length
    return 2.0 * t_ramp + (length - 2.0 * d_ramp) / v


# --------------------------------------------------------------------------- closed forms


@pytest.mark.parametrize("v", [200.0, 3500.0 / 60.0])  # A reached (A²/J = 120) / not reached
def test_single_long_piece_duration_closed_form(v):
    length = 1000.0
    prof = _plan([length], [v], [0.0, 0.0])
    if v >= A * A / J:  # the brief's formula, literally
        d = v * (v / A + A / J) / 2
        expected = 2 * (v / A + A / J) + (length - 2 * d) / v
    else:
        expected = _rest_to_rest_time(v, length)
    assert prof.duration_s == pytest.approx(expected, rel=1e-12)
    assert prof.piece_peak_speed_mm_s[0] == v
    s, vel, acc, jerk, piece = prof.sample(np.array([prof.duration_s / 2, prof.duration_s]))
    assert vel[0] == v and acc[0] == 0.0 and jerk[0] == 0.0
    assert s[1] == length and vel[1] == 0.0 and piece[1] == 0


@pytest.mark.parametrize("length", [0.3, 80.0, 1e-4])
def test_short_piece_peaks_at_the_bisection_peak(length):
    # Rest to rest: 2·D(0 → v_p) = L. A not reached: v_p = (L²J/4)^(1/3), T = 4√(v_p/J);
    # A reached: v_p² + v_p·A²/J − L·A = 0, T = 2(v_p/A + A/J).
    k = A * A / J
    v_free = (length * length * J / 4) ** (1 / 3)
    if v_free < k:
        v_p, t = v_free, 4 * math.sqrt(v_free / J)
    else:
        v_p = (-k + math.sqrt(k * k + 4 * length * A)) / 2
        t = 2 * (v_p / A + A / J)
    prof = _plan([length], [1e4], [0.0, 0.0])
    assert prof.piece_peak_speed_mm_s[0] == pytest.approx(v_p, rel=1e-13)
    assert prof.duration_s == pytest.approx(t, rel=1e-12)
    s, vel, _, _, _ = prof.sample(np.linspace(0, prof.duration_s, 20001))
    assert vel.max() == pytest.approx(v_p, rel=1e-8)  # the sample grid straddles the peak
    assert s[-1] == length


def test_exact_stop_splits_into_independent_pieces():
    lengths, caps = [100.0, 0.3, 500.0], [200.0, 80.0, 3500.0 / 60.0]
    prof = _plan(lengths, caps, [0.0, 0.0, 0.0, 0.0])
    single = [_plan([L], [c], [0.0, 0.0]).duration_s for L, c in zip(lengths, caps)]
    assert prof.duration_s == pytest.approx(sum(single), rel=1e-13)
    np.testing.assert_array_equal(prof.junction_speeds_mm_s, 0.0)
    np.testing.assert_allclose(prof.piece_start_time_s, np.cumsum([0.0] + single[:-1]), rtol=1e-13)


def test_junction_bound_by_the_short_last_piece():
    # A long piece then a 0.05 mm piece ending at rest: the junction is the speed that stops
    # within 0.05 mm: D(v → 0) = v√(v/J) → v = (L²J)^(1/3) (A not reached).
    short = 0.05
    v_ref = (short * short * J) ** (1 / 3)
    prof = _plan([200.0, short], [100.0, 100.0], [0.0, INF, 0.0])
    assert prof.junction_speeds_mm_s[1] == pytest.approx(v_ref, rel=1e-14)
    assert prof.piece_peak_speed_mm_s[1] == prof.junction_speeds_mm_s[1]  # pure deceleration


def test_junction_cap_and_neighbour_cruise_caps():
    prof = _plan([500.0, 500.0, 500.0], [100.0, 30.0, 100.0], [0.0, 80.0, INF, 0.0])
    np.testing.assert_array_equal(prof.junction_speeds_mm_s, [0.0, 30.0, 30.0, 0.0])
    np.testing.assert_array_equal(prof.piece_peak_speed_mm_s, [100.0, 30.0, 100.0])


# ----------------------------------------------------------------------- look-ahead window


def test_lookahead_of_one_piece_stops_within_each_piece():
    # Equal pieces ℓ, no caps: with one piece of look-ahead every junction can only be the
    # speed that still stops within the next piece, (ℓ²J)^(1/3) (A not reached).
    ell, k = 0.02, 30
    prof = _plan([ell] * k, [1e3] * k, [0.0] + [INF] * (k - 1) + [0.0], lookahead=1)
    v_ref = (ell * ell * J) ** (1 / 3)
    np.testing.assert_allclose(prof.junction_speeds_mm_s[1:-1], v_ref, rtol=1e-14)
    unbounded = _plan([ell] * k, [1e3] * k, [0.0] + [INF] * (k - 1) + [0.0])
    assert unbounded.duration_s < prof.duration_s
    assert unbounded.junction_speeds_mm_s.max() > 2 * v_ref


def test_lookahead_covering_the_program_changes_nothing():
    rng = np.random.default_rng(3)
    k = 40
    lengths = 10 ** rng.uniform(-3, 1.5, k)
    caps = rng.uniform(5, 200, k)
    vj = np.r_[0.0, rng.choice([INF, 20.0, 0.0], k - 1, p=[0.7, 0.25, 0.05]), 0.0]
    a = _plan(lengths, caps, vj)
    b = _plan(lengths, caps, vj, lookahead=k)
    np.testing.assert_array_equal(a.junction_speeds_mm_s, b.junction_speeds_mm_s)
    assert a.duration_s == b.duration_s


def _window_bound(lengths, cap, n, i, a=A, j=J):
    """Test oracle: backward scan from rest at junction i + n down to i (plain loop)."""
    k = len(lengths)
    if i + n >= k:
        return INF
    w = 0.0
    for m in range(i + n - 1, i - 1, -1):
        w = min(cap[m], max_reachable_speed_scalar(w, lengths[m], a, j))
    return w


# --------------------------------------------------------------------- property checks


def _check_profile(prof, lengths, v_max, v_junction, a, j, lookahead=None):
    lengths = np.asarray(lengths, float)
    k = lengths.size
    total = float(np.sum(lengths))
    v = prof.junction_speeds_mm_s
    cap = np.asarray(v_junction, float).copy()
    cap[:-1] = np.minimum(cap[:-1], v_max)
    cap[1:] = np.minimum(cap[1:], v_max)
    vscale = max(float(np.max(v_max)), 1.0)

    # Junctions: within caps, at rest at the ends and at exact stops, every piece joins its
    # end speeds, and no junction could be raised alone (local maximality).
    assert v[0] == 0.0 and v[-1] == 0.0
    assert np.all(v <= cap * (1 + 1e-9))
    assert np.all(v[np.asarray(v_junction) == 0.0] == 0.0)
    assert np.all(scurve_distance_mm(v[:-1], v[1:], a, j) <= lengths)
    for i in range(1, k):
        bound = min(
            cap[i],
            max_reachable_speed_scalar(v[i - 1], lengths[i - 1], a, j),
            max_reachable_speed_scalar(v[i + 1], lengths[i], a, j),
        )
        if lookahead is not None:
            w_i = _window_bound(lengths, cap, lookahead, i, a, j)
            bound = min(bound, w_i)
            assert v[i] <= w_i * (1 + 1e-12)
        assert v[i] >= bound * (1 - 1e-12) - 1e-12
    assert np.all(prof.piece_peak_speed_mm_s <= np.asarray(v_max) * (1 + 1e-9))
    assert np.all(prof.piece_peak_speed_mm_s >= np.maximum(v[:-1], v[1:]))

    # Phases: exact evaluation at both ends of every phase.
    t0, dt = prof.phase_start_time_s, prof.phase_duration_s
    s0, v0, a0, jk = (
        prof.phase_s0_mm,
        prof.phase_v0_mm_s,
        prof.phase_a0_mm_s2,
        prof.phase_jerk_mm_s3,
    )
    pi = prof.phase_piece_index
    assert np.all(dt > 0.0) and np.all(np.diff(t0) >= 0.0) and np.all(np.diff(pi) >= 0)
    s1 = s0 + dt * v0 + dt**2 * a0 / 2 + dt**3 * jk / 6
    v1 = v0 + dt * a0 + dt**2 * jk / 2
    a1 = a0 + dt * jk
    assert np.all(np.abs(jk) <= j * (1 + 1e-6))
    assert np.all(np.abs(a0) <= a * (1 + 1e-6)) and np.all(np.abs(a1) <= a * (1 + 1e-6))
    # a is linear within a phase and never changes sign there, so v is monotone: its extremes
    # are the phase ends.
    assert np.all(a0 * a1 >= -((a * 1e-9) ** 2))
    piece_cap = np.asarray(v_max, float)[pi] * (1 + 1e-9)
    assert np.all(v0 <= piece_cap) and np.all(v1 <= piece_cap)
    assert np.all(v0 >= -1e-9 * vscale) and np.all(v1 >= -1e-9 * vscale)
    # Continuity at every phase boundary (including the junctions), and the time chain.
    np.testing.assert_allclose(t0[1:], t0[:-1] + dt[:-1], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(s0[1:], s1[:-1], rtol=0, atol=1e-10)
    np.testing.assert_allclose(v0[1:], v1[:-1], rtol=0, atol=1e-12 * vscale)
    np.testing.assert_allclose(a0[1:], a1[:-1], rtol=0, atol=1e-12 * a)
    # At rest at both ends; total distance.
    assert s0[0] == 0.0 and v0[0] == 0.0 and a0[0] == 0.0
    assert abs(v1[-1]) <= 1e-9 * vscale and abs(a1[-1]) <= 1e-6 * a
    assert abs(s1[-1] - total) <= 1e-9
    assert prof.total_length_mm == pytest.approx(total, rel=0, abs=1e-9)
    assert prof.duration_s == pytest.approx(t0[-1] + dt[-1], rel=1e-12)

    # Sampling: dense, unsorted, outside the time range too.
    t = np.concatenate([np.linspace(-0.1, prof.duration_s * 1.01, 3001), t0, t0 + dt])
    np.random.default_rng(0).shuffle(t)
    s, vel, acc, jerk, piece = prof.sample(t)
    order = np.argsort(t, kind="stable")
    assert np.all(np.diff(s[order]) >= -1e-9)
    assert np.all(vel >= 0.0) and np.all(vel <= np.asarray(v_max)[piece] * (1 + 1e-9))
    assert np.all(np.abs(acc) <= a * (1 + 1e-6)) and np.all(np.abs(jerk) <= j * (1 + 1e-6))
    assert np.all((s >= 0.0) & (s <= prof.total_length_mm))
    starts = np.r_[prof.piece_start_mm, prof.total_length_mm]
    assert np.all(s >= starts[piece] - 1e-9) and np.all(s <= starts[piece + 1] + 1e-9)
    end = prof.sample(np.array([prof.duration_s]))
    assert end[0][0] == prof.total_length_mm and end[1][0] == 0.0 and end[4][0] == k - 1
    np.testing.assert_allclose(
        prof.piece_start_mm, np.r_[0.0, np.cumsum(lengths)[:-1]], rtol=0, atol=1e-9
    )


_length = st.one_of(
    st.just(1e-4), st.floats(1e-4, 1e-2), st.floats(1e-2, 50.0), st.just(500.0), st.just(0.0)
)
_jcap = st.one_of(st.just(INF), st.just(0.0), st.floats(0.5, 300.0))


@st.composite
def _programs(draw):
    k = draw(st.integers(1, 12))
    lengths = draw(st.lists(_length, min_size=k, max_size=k))
    v_max = draw(st.lists(st.floats(1.0, 300.0), min_size=k, max_size=k))
    vj = [0.0] + draw(st.lists(_jcap, min_size=k - 1, max_size=k - 1)) + [0.0]
    a = draw(st.floats(100.0, 1e4))
    j = draw(st.floats(1e3, 1e6))
    lookahead = draw(st.one_of(st.none(), st.integers(1, 5)))
    return lengths, v_max, vj, a, j, lookahead


@settings(max_examples=120, deadline=None)
@given(_programs())
def test_profile_properties(program):
    lengths, v_max, vj, a, j, lookahead = program
    if sum(lengths) == 0.0:
        lengths[0] = 1e-4
    prof = _plan(lengths, v_max, vj, a, j, lookahead)
    _check_profile(prof, lengths, v_max, vj, a, j, lookahead)


def test_profile_properties_on_a_benchmark_like_sequence():
    # Many tiny pieces (PH/NURBS spans) between longer lines, corner caps, exact stops.
    rng = np.random.default_rng(11)
    k = 400
    lengths = np.where(
        rng.random(k) < 0.5, 10 ** rng.uniform(-4, -1, k), 10 ** rng.uniform(-1, 2, k)
    )
    v_max = rng.choice([3500 / 60, 20.0, 200.0], k)
    vj = np.r_[0.0, rng.choice([INF, 0.0, 5.0, 40.0], k - 1, p=[0.6, 0.02, 0.2, 0.18]), 0.0]
    for lookahead in (None, 3):
        prof = _plan(lengths, v_max, vj, lookahead=lookahead)
        _check_profile(prof, lengths, v_max, vj, A, J, lookahead)


def test_sampled_motion_is_self_consistent():
    # v integrates to s and a is dv/dt, on dense samples (independent of the phase algebra).
    prof = _plan(
        [3.0, 0.2, 40.0, 1e-3, 5.0],
        [80.0, 30.0, 200.0, 200.0, 50.0],
        [0.0, INF, 10.0, INF, INF, 0.0],
    )
    t = np.linspace(0.0, prof.duration_s, 200_001)
    s, v, a, _, _ = prof.sample(t)
    s_int = cumulative_trapezoid(v, t, initial=0.0)
    h = t[1] - t[0]
    # Trapezoid rule error ≤ T·h²·max|v''|/12 with |v''| = |jerk| ≤ J.
    assert np.max(np.abs(s_int - s)) <= prof.duration_s * h**2 * J / 12 + 1e-12
    # Central difference of v against a: exact for a linear a, off by ≤ (jump in jerk)·h/4
    # = 2J·h/4 next to a jerk switch.
    dv = np.gradient(v, t)
    assert np.max(np.abs(dv - a)[1:-1]) <= J * h / 2 * (1 + 1e-6)


def test_sample_shapes_and_rest_outside():
    prof = _plan([10.0, 5.0], [50.0, 50.0], [0.0, INF, 0.0])
    t = np.array([[-1.0, 0.0], [prof.duration_s, 1e9]])
    s, v, a, j, piece = prof.sample(t)
    assert s.shape == v.shape == a.shape == j.shape == piece.shape == (2, 2)
    np.testing.assert_array_equal(s, [[0.0, 0.0], [15.0, 15.0]])
    np.testing.assert_array_equal(v, 0.0)
    np.testing.assert_array_equal(piece, [[0, 0], [1, 1]])
    assert j[0, 0] == 0.0 and j[0, 1] == J  # at rest before 0; jerking up from t = 0
    assert prof.piece_start_s is prof.piece_start_mm


def test_zero_length_pieces():
    prof = _plan([0.0, 5.0, 0.0, 0.0, 5.0, 0.0], [10.0] * 6, [0.0] + [INF] * 5 + [0.0])
    v = prof.junction_speeds_mm_s
    assert v[0] == v[1] and v[2] == v[3] == v[4] and v[5] == v[6] == 0.0
    assert set(prof.phase_piece_index.tolist()) == {1, 4}
    all_zero = _plan([0.0, 0.0], [10.0, 10.0], [0.0, INF, 0.0])
    assert all_zero.duration_s == 0.0
    s, v, *_ = all_zero.sample(np.array([0.0, 1.0]))
    np.testing.assert_array_equal(s, 0.0)


def test_repair_lowers_only_what_is_needed():
    lengths = np.array([1.0, 0.01, 1.0])
    v = np.array([0.0, 30.0, 80.0, 0.0])  # 30 → 80 within 0.01 mm is impossible
    out = repair_junctions(v.copy(), lengths, A, J)
    assert np.all(scurve_distance_mm(out[:-1], out[1:], A, J) <= lengths)
    assert np.all(out <= v) and out[0] == 0.0 and out[1] == 30.0
    assert 30.0 < out[2] < 80.0


def test_immutability():
    prof = _plan([1.0], [10.0], [0.0, 0.0])
    with pytest.raises(dataclasses.FrozenInstanceError):
        prof.duration_s = 0.0
    with pytest.raises(ValueError):
        prof.junction_speeds_mm_s[0] = 1.0
    inp = ProfileInput([1.0], [10.0], [0.0, 0.0], A, J)
    assert isinstance(inp.length_mm, np.ndarray) and not inp.length_mm.flags.writeable


@pytest.mark.parametrize(
    "kwargs, err",
    [
        (dict(length_mm=[1.0, 2.0]), PlanningError),  # shape
        (dict(length_mm=[-1.0]), PlanningError),
        (dict(length_mm=[]), PlanningError),
        (dict(v_max_mm_s=[0.0]), PlanningError),
        (dict(v_max_mm_s=[INF]), PlanningError),
        (dict(v_junction_max_mm_s=[1.0, 0.0]), PlanningError),  # must start at rest
        (dict(v_junction_max_mm_s=[0.0, math.nan]), PlanningError),
        (dict(a_max_mm_s2=0.0), ConfigError),
        (dict(j_max_mm_s3=-5.0), ConfigError),
        (dict(lookahead_pieces=0), ConfigError),
        (dict(lookahead_pieces=2.5), ConfigError),
    ],
)
def test_input_validation(kwargs, err):
    base = dict(
        length_mm=[1.0],
        v_max_mm_s=[10.0],
        v_junction_max_mm_s=[0.0, 0.0],
        a_max_mm_s2=A,
        j_max_mm_s3=J,
    )
    base.update(kwargs)
    with pytest.raises(err):
        ProfileInput(**base)


@settings(max_examples=120, deadline=None)
@given(_programs())
def test_merged_profile_keeps_every_limit_and_is_never_slower(program):
    """plan_profile plans runs of equal-cap pieces with unconstraining junctions as one
    piece. Measured on the phases and on dense samples: caps of the piece under each sample,
    |a| ≤ A, |j| ≤ J, continuity, rest at both ends, the exact total length — and it never
    takes longer than planning every piece on its own."""
    lengths, v_max, vj, a, j, _ = program
    inp = ProfileInput(
        np.asarray(lengths, float), np.asarray(v_max, float), np.asarray(vj, float), a, j
    )
    merged = plan_profile(inp)
    pieces = plan_profile_pieces(inp)
    # (a gated flank switches its jerk within GATE_MIN_STEP_S = 0.1 µs of each gate)
    assert merged.duration_s <= pieces.duration_s * (1 + 1e-9) + 1e-6
    dt = merged.phase_duration_s
    a0, jk = merged.phase_a0_mm_s2, merged.phase_jerk_mm_s3
    a1 = a0 + dt * jk
    assert np.all(np.abs(jk) <= j * (1 + 1e-6))
    assert np.all(np.abs(a0) <= a * (1 + 1e-6)) and np.all(np.abs(a1) <= a * (1 + 1e-6))
    total = float(np.sum(lengths))
    assert merged.total_length_mm == pytest.approx(total, abs=1e-9)
    t = np.linspace(0.0, merged.duration_s, 4001)
    s, vel, acc, _, piece = merged.sample(t)
    assert np.all(np.diff(s) >= -1e-12)
    cap = np.asarray(v_max, float)[piece]
    assert np.all(vel <= cap * (1 + 1e-9) + 1e-12)
    # Junction caps hold where the path crosses a junction (speed at the piece start times).
    v_at = merged.sample(merged.piece_start_time_s)[1]
    jcap = np.minimum(np.asarray(vj, float)[:-1], np.inf)
    assert np.all(v_at <= jcap * (1 + 1e-9) + 1e-9)
    assert vel[0] == 0.0 and vel[-1] == 0.0 and s[-1] == merged.total_length_mm


def test_merged_chain_of_short_cells_accelerates_like_one_move():
    """30 cells of 0.02 mm with no constraint between them move like one 0.6 mm move."""
    ell, k = 0.02, 30
    jcap = np.array([0.0] + [INF] * (k - 1) + [0.0])
    inp = ProfileInput(np.full(k, ell), np.full(k, 1e3), jcap, A, J)
    one = plan_profile(
        ProfileInput(np.array([ell * k]), np.array([1e3]), np.array([0.0, 0.0]), A, J)
    )
    merged = plan_profile(inp)
    assert merged.duration_s == pytest.approx(one.duration_s, rel=1e-12)
    assert merged.piece_start_mm.size == k
    # Each cell's start time is where s(t) reaches it.
    s_at = merged.sample(merged.piece_start_time_s)[0]
    np.testing.assert_allclose(s_at, np.arange(k) * ell, atol=1e-12)


def _time_at_length_bisection(profile, s):
    """The plain 64-halving bisection of the whole phase (time_at_length before the Newton
    start): the reference."""
    n = profile.phase_s0_mm.size
    idx = np.clip(np.searchsorted(profile.phase_s0_mm, s, side="right") - 1, 0, n - 1)
    s0, v0 = profile.phase_s0_mm[idx], profile.phase_v0_mm_s[idx]
    a0, jk = profile.phase_a0_mm_s2[idx], profile.phase_jerk_mm_s3[idx]
    lo, hi = np.zeros_like(s), profile.phase_duration_s[idx].copy()
    for _ in range(64):
        mid = 0.5 * (lo + hi)
        below = s0 + mid * (v0 + mid * (0.5 * a0 + mid * (jk / 6.0))) < s
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    return profile.phase_start_time_s[idx] + hi


def test_time_at_length_against_bisection_and_closed_forms():
    from nurbscnc.plan.profile import ProfileInput, time_at_length
    from nurbscnc.plan.profile_plan import plan_profile

    rng = np.random.default_rng(2)
    k = 5000
    length = rng.choice([0.05, 1.0, 20.0], k) * rng.random(k) + 1e-4
    caps = rng.choice([10.0, 40.0, 58.3], k)
    junction = np.zeros(k + 1)  # stops (0) and moving junctions, at random
    junction[1:-1] = np.minimum(caps[:-1], caps[1:]) * rng.choice([0.0, 1.0], k - 1)
    prof = plan_profile(ProfileInput(length, caps, junction, 2450.0, 5e4))
    total = prof.total_length_mm
    s0 = prof.phase_s0_mm
    s = np.concatenate(
        (
            rng.random(40_000) * total,
            s0,
            s0[1:] - 1e-12,
            s0[1:] + 1e-12,
            [0.0, total, total * (1 + 1e-12)],
        )
    )
    s = np.clip(s, 0.0, None)
    got, ref = time_at_length(prof, s), _time_at_length_bisection(prof, s)
    assert np.all(np.abs(got - ref) <= np.spacing(np.maximum(ref, 1e-300)))
    # Closed forms: a cruise phase t = Δs / v, a jerk phase from rest t = ∛(6 Δs / j).
    cruise = np.flatnonzero(
        (prof.phase_jerk_mm_s3 == 0)
        & (prof.phase_a0_mm_s2 == 0)
        & (prof.phase_v0_mm_s > 0)
        & (prof.phase_duration_s > 1e-3)
    )[:200]
    frac = rng.uniform(0.1, 0.9, cruise.size)
    ds = frac * prof.phase_duration_s[cruise] * prof.phase_v0_mm_s[cruise]
    t = time_at_length(prof, s0[cruise] + ds) - prof.phase_start_time_s[cruise]
    # The query s = s0 + Δs is itself rounded to spacing(s) [mm]: at speed v that is
    # spacing(s)/v [s] of time; the times' own rounding adds 1e-13 s.
    v = prof.phase_v0_mm_s[cruise]
    bound = 4.0 * np.spacing(s0[cruise] + ds) / v + 1e-13
    assert np.all(np.abs(t - ds / v) <= bound)
    rest = np.flatnonzero(
        (prof.phase_v0_mm_s == 0) & (prof.phase_a0_mm_s2 == 0) & (prof.phase_jerk_mm_s3 > 0)
    )[:200]
    tau = rng.uniform(0.1, 0.9, rest.size) * prof.phase_duration_s[rest]
    ds = prof.phase_jerk_mm_s3[rest] * tau**3 / 6.0
    t = time_at_length(prof, s0[rest] + ds) - prof.phase_start_time_s[rest]
    v = prof.phase_jerk_mm_s3[rest] * tau**2 / 2.0
    assert np.all(np.abs(t - tau) <= 4.0 * np.spacing(s0[rest] + ds) / v + 1e-13)
    assert cruise.size > 50 and rest.size > 50
