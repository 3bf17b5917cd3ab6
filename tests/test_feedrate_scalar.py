"""plan/feedrate.py: the flat scalar closed form keeps the numbers of its reference.

``max_reachable_speed_scalar`` was rewritten for speed (issue 14: its float guard, stepping
v down by ulps, ran on most calls of a 200,000-line spiral); the reference below is the
previous body. Every result must be the same float, and within the distance in floats.
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from nurbscnc.plan.feedrate import _distance_scalar, max_reachable_speed_scalar, scurve_distance_mm


def _reference(v0: float, d: float, a: float, j: float) -> float:
    if d <= 0.0:
        return v0
    a2j = a * a / j
    if d > (2.0 * v0 + a2j) * a / j:
        b = 2.0 * v0 + a2j
        c = 2.0 * a * (d - v0 * a / j)
        v = v0 + 2.0 * c / (b + math.sqrt(b * b + 4.0 * c))
    else:
        p = 2.0 * v0 / j
        r = d / j
        z = 1.5 * r / p * math.sqrt(3.0 / p) if p > 0.0 else 2.0
        if z <= 1.0:
            x = 2.0 * math.sqrt(p / 3.0) * math.sinh(math.asinh(z) / 3.0)
        else:
            u = math.cbrt(0.5 * r + math.sqrt(0.25 * r * r + p * p * p / 27.0))
            x = u - p / (3.0 * u)
        v = v0 + j * x * x
    dv = v - v0
    t = dv / a + a / j if dv * j >= a * a else 2.0 * math.sqrt(dv / j)
    if 0.5 * (v0 + v) * t <= d:
        return v
    step = 1
    while v > v0 and _distance_scalar(v0, v, a, j) > d:
        v = max(v0, v - step * math.ulp(v))
        step *= 2
    return v


def test_same_floats_as_the_reference_on_every_regime():
    rng = np.random.default_rng(3)
    n = 60000
    v0 = np.concatenate(
        [rng.uniform(0.0, 200.0, n // 3), np.zeros(n // 6), 10.0 ** rng.uniform(-6, 3, n // 2)]
    )
    d = 10.0 ** rng.uniform(-12, 2, v0.size)  # from far below an ulp of travel to 100 mm
    d[::11] = 0.0
    a = rng.choice([500.0, 2000.0, 12000.0], v0.size)
    j = rng.choice([1e4, 3e5, 1e7], v0.size)
    guarded = 0
    for args in zip(v0.tolist(), d.tolist(), a.tolist(), j.tolist()):
        got = max_reachable_speed_scalar(*args)
        assert got == _reference(*args) or (math.isnan(got) and math.isnan(_reference(*args)))
        # The float guard: the distance in floats never exceeds the allowance.
        assert _distance_scalar(args[0], got, args[2], args[3]) <= args[1] or got == args[0]
        guarded += got != args[0] and _distance_scalar(args[0], got, args[2], args[3]) > 0.0
    assert guarded > n // 2  # the comparison is not only over trivial cases
    # And the float guard agrees with the array distance function.
    sample = np.array(
        [
            max_reachable_speed_scalar(x, y, 2000.0, 3e5)
            for x, y in zip(v0[:500].tolist(), d[:500].tolist())
        ]
    )
    assert np.all(scurve_distance_mm(v0[:500], sample, 2000.0, 3e5) <= d[:500])


# -- the look-ahead's scans by relaxation (scans.chain_scan) ------------------------------


def _sequential_scan(bound, length, a, j):
    """The recurrence y_0 = 0, y_{n+1} = min(bound_{n+1}, R(y_n, L_n)) as a plain loop."""
    y = [0.0]
    for n in range(length.size):
        y.append(min(bound[n + 1], max_reachable_speed_scalar(y[n], length[n], a[n], j[n])))
    return np.array(y)


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 400), st.integers(0, 2**32 - 1))
def test_the_relaxed_scan_is_the_sequential_one(k, seed):
    """Chords from 0.1 µm to 30 mm, caps from stops to none, per-piece limits: the
    relaxation's speeds are the plain loop's (to the last bits of the transcendental
    functions, numpy's against math's)."""
    from nurbscnc.plan.scans import chain_scan

    rng = np.random.default_rng(seed)
    length = rng.choice([1e-4, 0.05, 1.0, 30.0], k) * rng.random(k)
    bound = rng.choice([0.0, 0.5, 20.0, 58.3, 1e9], k + 1)
    a = 2450.0 * rng.choice([1.0, 0.3], k)
    j = 5e4 * rng.choice([1.0, 0.1], k)
    want = _sequential_scan(bound, length, a, j)
    got = chain_scan(bound, length, a, j)
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=0.0)


def test_the_relaxed_scan_on_a_long_ramp_of_tiny_chords():
    """20,000 chords of 1 µm from rest to a 40 mm/s cap (one S-curve over 1,000s of
    pieces: the chains run long, the scalar finish takes them)."""
    from nurbscnc.plan.scans import chain_scan

    k = 20_000
    length = np.full(k, 1e-3)
    bound = np.full(k + 1, 40.0)
    a, j = np.full(k, 2450.0), np.full(k, 5e4)
    got = chain_scan(bound, length, a, j)
    np.testing.assert_allclose(got, _sequential_scan(bound, length, a, j), rtol=1e-13)
