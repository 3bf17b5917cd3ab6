"""The local re-plan's cap factors (:func:`nurbscnc.plan.shaping.local_factors`) computed on
the pieces hit alone: the same factors, history and ineffective flags, bit for bit, as the
rule written over all k pieces (kept here as the reference), on random blames and
histories (first hits, repeated hits, errors that fell weakly, strikes at the limit)."""

import numpy as np

from nurbscnc.plan.shaping import CURVE_STRIKES, STOP_INEFFECTIVE_P, local_factors


def _local_factors_all_pieces(blame, eps_mm, history=None):
    """The rule of local_factors' docstring over every piece (the reference)."""
    hit = blame > 0.0
    p = np.full(blame.size, 2.0)
    strikes = np.zeros(blame.size, dtype=np.int8)
    if history is not None:
        prev_blame, prev_factor, prev_strikes = history
        again = hit & (prev_blame > 0.0) & (prev_factor < 1.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            measured = np.log(blame / prev_blame) / np.log(prev_factor)
        known = again & np.isfinite(measured)
        weak = known & (measured < STOP_INEFFECTIVE_P)
        strikes = np.where(weak, np.minimum(prev_strikes, CURVE_STRIKES) + 1, 0).astype(np.int8)
        p = np.where(known, np.clip(measured, 0.25, 2.0), p)
    ineffective = strikes >= CURVE_STRIKES
    ratio = eps_mm / np.where(hit, blame, eps_mm)
    factor = np.where(hit & ~ineffective, np.clip(0.97 * ratio ** (1.0 / p), 0.5, 0.97), 1.0)
    return factor, (blame, factor, strikes), ineffective


def _bits(x):
    return np.ascontiguousarray(x).view(np.uint8)


def test_local_factors_on_the_hit_pieces_are_the_whole_array_rule():
    rng = np.random.default_rng(41)
    eps_mm = 0.015
    for _ in range(300):
        k = int(rng.integers(1, 400))
        history = None
        for _ in range(int(rng.integers(1, 6))):  # a run of re-plans, each with its history
            blame = np.where(rng.random(k) < 0.2, rng.uniform(0.0, 0.05, k), 0.0)
            if history is not None and rng.random() < 0.5:  # errors that barely fell
                prev = history[0]
                blame = np.where(prev > 0.0, prev * rng.uniform(0.9, 1.0, k), blame)
            got = local_factors(blame, eps_mm, history)
            ref = _local_factors_all_pieces(blame, eps_mm, history)
            assert np.array_equal(_bits(got[0]), _bits(ref[0]))
            for g, r in zip(got[1], ref[1]):
                assert g.dtype == r.dtype and np.array_equal(_bits(g), _bits(r))
            assert np.array_equal(got[2], ref[2])
            history = got[1]
