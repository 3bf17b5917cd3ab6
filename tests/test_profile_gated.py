"""Gated flanks (issue 13): a planning unit's rise or descent follows a staircase of caps with
non-zero acceleration at the cells (:func:`nurbscnc.plan.gated.gated_rise`), where the
unit split of earlier planners ended its acceleration (a = 0) at every cell it crossed.

References, independent of the gated flank's own arithmetic:
- the unit-by-unit plan (``gate=False``: the split at a = 0), which the gated plan must never
  lose to, and the per-piece plan (a = 0 at every junction);
- a relaxation: the same pieces with the staircase's caps raised to the cruise, planned as one
  S-curve into the last cap; fewer constraints, so no plan of the staircase can be faster;
- finite differences of dense samples (|a| ≤ A, |j| ≤ J) and the caps of the piece under
  every sample; for the flank alone, its phases integrated exactly against every gate.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import nurbscnc.plan.profile_plan as profile_mod
from nurbscnc.plan.gated import gated_rise
from nurbscnc.plan.profile import ProfileInput
from nurbscnc.plan.profile_plan import plan_profile
from nurbscnc.plan.scans import plan_profile_pieces
from tests.test_profile_limits import _fd_check

A = 2450.0
J = 5.0e4


def _descent(cells: int, cell_mm: float):
    """8 mm at 58 mm/s, then ``cells`` cells of ``cell_mm`` whose caps fall like
    58·√(1 − 0.97 x/X) (the shape of √(A/κ) into a curve), then 2 mm at 10 mm/s, rest."""
    x = (np.arange(cells) + 0.5) * cell_mm
    down = np.maximum(58.0 * np.sqrt(1.0 - 0.97 * x / (cells * cell_mm)), 10.0)
    caps = np.concatenate(([58.0], down, [10.0]))
    lengths = np.concatenate(([8.0], np.full(cells, cell_mm), [2.0]))
    jcap = np.full(caps.size + 1, math.inf)
    jcap[0] = jcap[-1] = 0.0
    return lengths, caps, jcap


def _split_plan(inp, monkeypatch):
    real = profile_mod._plan_units
    with monkeypatch.context() as m:
        m.setattr(
            profile_mod, "_plan_units", lambda i, key, every=False: real(i, key, every, gate=False)
        )
        return plan_profile(inp)


@pytest.mark.parametrize(
    ("cells", "cell_mm", "gain_s", "to_bound"), [(16, 0.1, 0.010, 1.005), (12, 0.2, 0.010, 1.03)]
)
def test_falling_staircase_is_followed_without_stopping_the_acceleration(
    cells, cell_mm, gain_s, to_bound, monkeypatch
):
    """The descent 58 → 10 mm/s over a falling staircase: every cap and limit holds on the
    samples; the gated plan is ≥ 10 ms faster than the unit split (measured 12.1 and
    11.4 ms) and than the per-piece plan, and no faster than the relaxation (the
    staircase's caps raised to the cruise), within 0.5 % of it on the finer staircase."""
    lengths, caps, jcap = _descent(cells, cell_mm)
    inp = ProfileInput(lengths, caps, jcap, A, J)
    prof = plan_profile(inp)
    split = _split_plan(inp, monkeypatch)
    per_piece = plan_profile_pieces(inp)
    relaxed = plan_profile(
        ProfileInput(
            lengths, np.where(np.arange(caps.size) == caps.size - 1, caps, 58.0), jcap, A, J
        )
    )
    assert prof.duration_s <= split.duration_s - gain_s
    assert prof.duration_s <= per_piece.duration_s - gain_s
    assert prof.duration_s >= relaxed.duration_s - 1e-9
    assert prof.duration_s <= relaxed.duration_s * to_bound
    k = caps.size
    _fd_check(prof, *(np.full(k, x) for x in (A, J, A, J)))
    t = np.linspace(0.0, prof.duration_s, 40001)
    s, vel, _, _, piece = prof.sample(t)
    assert np.all(vel <= caps[piece] * (1 + 1e-9) + 1e-12)
    assert np.all(np.diff(vel[(s > 8.0) & (s < lengths[:-1].sum())]) <= 1e-9)  # monotone
    assert s[-1] == pytest.approx(lengths.sum(), abs=1e-12) and vel[-1] == 0.0


@st.composite
def _gates(draw):
    n = draw(st.integers(1, 8))
    d = np.cumsum([draw(st.floats(0.01, 1.0)) for _ in range(n)])
    c = np.sort([draw(st.floats(2.0, 60.0)) for _ in range(n)])
    v0 = draw(st.floats(0.0, float(c[0])))
    v_top = draw(st.floats(float(c[-1]), 80.0))
    a = draw(st.sampled_from([A, 800.0]))
    return v0, v_top, d, c, a


@settings(max_examples=80, deadline=None, derandomize=True)
@given(_gates())
def test_gated_rise_meets_every_gate_and_ends_at_its_target(case):
    """The flank alone, its phases integrated exactly (cubics, fine sub-steps): the speed is
    non-decreasing, 0 ≤ a ≤ A, |jerk| ≤ J, the speed at every gate's distance within its
    cap, and it ends at the target speed with a = 0 after the distance it reports."""
    v0, v_top, d, c, a_max = case
    got = gated_rise(v0, v_top, d, c, a_max, J)
    assert got is not None
    durs, jerks, dist = got
    assert all(abs(jk) <= J for jk in jerks) and all(t > 0 for t in durs)
    x, v, a = 0.0, v0, 0.0
    xs, vs = [x], [v]
    for t, jk in zip(durs, jerks, strict=True):
        tau = np.linspace(0.0, t, 9)[1:]
        xs.extend(x + tau * (v + tau * (0.5 * a + tau * jk / 6.0)))
        vs.extend(v + tau * (a + 0.5 * tau * jk))
        x, v, a = (
            x + t * (v + t * (0.5 * a + t * jk / 6.0)),
            v + t * (a + 0.5 * t * jk),
            a + t * jk,
        )
        assert -1e-9 * a_max <= a <= a_max * (1 + 1e-9)
    xs, vs = np.array(xs), np.array(vs)
    assert np.all(np.diff(vs) >= -1e-9)
    assert x == pytest.approx(dist, rel=1e-9, abs=1e-12)
    assert v == pytest.approx(v_top, rel=1e-9) and abs(a) <= 1e-6 * a_max
    for dm, cm in zip(d, c, strict=True):
        if dm <= x:
            assert np.interp(dm, xs, vs) <= cm * (1 + 1e-9) + 1e-9
