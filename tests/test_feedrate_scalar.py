"""plan/feedrate.py: the flat scalar closed form keeps the numbers of its reference.

``max_reachable_speed_scalar`` was rewritten for speed (issue 14: its float guard, stepping
v down by ulps, ran on most calls of a 200,000-line spiral); the reference below is the
previous body. Every result must be the same float, and within the distance in floats.
"""

from __future__ import annotations

import math

import numpy as np

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
    v0 = np.concatenate([rng.uniform(0.0, 200.0, n // 3), np.zeros(n // 6),
                         10.0 ** rng.uniform(-6, 3, n // 2)])  # fmt: skip
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
    sample = np.array([max_reachable_speed_scalar(x, y, 2000.0, 3e5) for x, y in
                       zip(v0[:500].tolist(), d[:500].tolist())])  # fmt: skip
    assert np.all(scurve_distance_mm(v0[:500], sample, 2000.0, 3e5) <= d[:500])
