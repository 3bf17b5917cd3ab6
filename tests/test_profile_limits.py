"""Per-piece acceleration and jerk limits in the feed profile (planner v2, issue 13).

The profile is sampled densely and differentiated by finite differences of s(t) alone (an
independent check of the phases the planner built): within each piece the tangential
acceleration stays within that piece's rise limit (a > 0) or descent limit (a < 0), the jerk
within the larger of the limits of the pieces the difference stencil touches; the closed
form of a single rest-to-rest piece gives the exact duration with its own limits.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nurbscnc.errors import PlanningError
from nurbscnc.plan.profile import ProfileInput
from nurbscnc.plan.profile_plan import plan_profile
from nurbscnc.plan.scans import plan_profile_pieces

H = 5e-5  # finite-difference step [s]


def _fd_check(prof, a_up, j_up, a_dn, j_dn):
    """Finite-difference acceleration and jerk of s(t) against the per-piece limits."""
    t = np.arange(-3 * H, prof.duration_s + 3 * H, H)
    s, _, _, _, piece = prof.sample(t)
    acc = (s[2:] - 2 * s[1:-1] + s[:-2]) / H**2  # centred on t[1:-1]
    p_mid = piece[1:-1]
    # A second difference of a piecewise cubic is off by at most J·H (a jerk jump inside the
    # stencil); rounding of s (|s| ≤ 30 mm) adds 4·ulp(30)/H².
    slack_a = np.maximum(j_up, j_dn).max() * H + 4 * math.ulp(30.0) / H**2
    lo = np.minimum(piece[:-2], piece[2:])
    hi = np.maximum(piece[:-2], piece[2:])
    up_lim = np.maximum(a_up[lo], a_up[hi])
    dn_lim = np.maximum(a_dn[lo], a_dn[hi])
    assert np.all(acc <= up_lim + slack_a)
    assert np.all(-acc <= dn_lim + slack_a)
    # Third differences (stencil t[i-1] … t[i+2]): within a cubic exact, across a phase
    # boundary a mean of the two jerks.
    jerk = (s[3:] - 3 * s[2:-1] + 3 * s[1:-2] - s[:-3]) / H**3
    lo = np.minimum(piece[:-3], piece[3:])
    hi = np.maximum(piece[:-3], piece[3:])
    j_lim = np.maximum.reduce([j_up[lo], j_up[hi], j_dn[lo], j_dn[hi]])
    # s is rounded to a few ulps (the cubic in Horner form); the stencil sums 8 of them.
    assert np.all(np.abs(jerk) <= j_lim * (1 + 1e-6) + 64 * math.ulp(30.0) / H**3)
    return acc, p_mid


def test_single_piece_closed_form_with_its_own_limits():
    """One piece, rise limits (a1, j1), descent limits (a2, j2): duration = T_up + cruise +
    T_down with T = v/A + A/J (A reached) of each side (SPEC §7)."""
    v, length = 50.0, 20.0
    a1, j1, a2, j2 = 1000.0, 4e4, 500.0, 1e4  # A²/J = 25, 25 < v: A reached
    prof = plan_profile(
        ProfileInput([length], [v], [0.0, 0.0], [a1], [j1], a_decel_mm_s2=[a2], j_decel_mm_s3=[j2])
    )
    t1, t2 = v / a1 + a1 / j1, v / a2 + a2 / j2
    d = v * (t1 + t2) / 2
    assert prof.duration_s == pytest.approx(t1 + t2 + (length - d) / v, rel=1e-12)
    acc, _ = _fd_check(prof, np.array([a1]), np.array([j1]), np.array([a2]), np.array([j2]))
    # The limits are used, not only respected: the peaks reach them.
    assert acc.max() == pytest.approx(a1, rel=2e-3)
    assert -acc.min() == pytest.approx(a2, rel=2e-3)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(
    st.lists(
        st.tuples(
            st.floats(0.05, 6.0),
            st.floats(5.0, 60.0),
            st.floats(200.0, 3000.0),
            st.floats(5e3, 8e4),
            st.floats(200.0, 3000.0),
            st.floats(5e3, 8e4),
            st.sampled_from([0.0, math.inf]),
        ),
        min_size=1,
        max_size=8,
    ),
    st.booleans(),
)
def test_random_pieces_honour_their_limits(rows, merged):
    """Random pieces, each with its own rise/descent limits, junctions stop or pass."""
    length, v, a1, j1, a2, j2, jc = (np.array(c, dtype=float) for c in zip(*rows))
    jcap = np.concatenate(([0.0], jc[1:], [0.0]))
    inp = ProfileInput(length, v, jcap, a1, j1, a_decel_mm_s2=a2, j_decel_mm_s3=j2)
    prof = plan_profile(inp) if merged else plan_profile_pieces(inp)
    assert prof.total_length_mm == pytest.approx(length.sum(), rel=1e-12)
    _fd_check(prof, a1, j1, a2, j2)
    # Junction speeds within the caps; rest at the ends.
    vj = prof.junction_speeds_mm_s
    assert vj[0] == 0.0 and vj[-1] == 0.0
    assert np.all(vj[1:-1] <= np.minimum(v[:-1], v[1:]) * (1 + 1e-12))


def test_lower_limits_on_one_piece_change_only_that_piece():
    """Lowering the descent limits of the last piece slows that piece only: the earlier
    pieces' timing (a long cruise separates them) is unchanged."""
    length = np.array([30.0, 30.0])
    v = np.array([50.0, 50.0])
    jcap = np.array([0.0, 0.0, 0.0])
    base = plan_profile(ProfileInput(length, v, jcap, 2450.0, 5e4))
    soft = plan_profile(
        ProfileInput(
            length, v, jcap, 2450.0, 5e4, a_decel_mm_s2=[2450.0, 300.0], j_decel_mm_s3=[5e4, 3e3]
        )
    )
    assert soft.piece_start_time_s[1] == pytest.approx(base.piece_start_time_s[1], rel=1e-14)
    t2 = v[1] / 300.0 + 300.0 / 3e3  # A²/J = 30 < 50: A reached (SPEC §7)
    t2_base = 2.0 * math.sqrt(v[1] / 5e4)  # A²/J = 120 > 50: triangular acceleration
    d_extra = v[1] * (t2 - t2_base) / 2  # distance the longer descent covers beyond base
    expected = base.duration_s + (t2 - t2_base) - d_extra / v[1]
    assert soft.duration_s == pytest.approx(expected, rel=1e-12)


def test_limit_shapes_are_checked():
    with pytest.raises(PlanningError, match="one per piece"):
        ProfileInput([1.0, 1.0], [5.0, 5.0], [0.0, 0.0, 0.0], [100.0, 100.0, 100.0], 1e4)
