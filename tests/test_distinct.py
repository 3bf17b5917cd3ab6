"""geometry/distinct.py against numpy's own np.unique and np.union1d: the same values, dtype
and shape, bit for bit (NaNs and signed zeros included), on random arrays with repeats."""

from __future__ import annotations

import numpy as np
import pytest

from nurbscnc.geometry.distinct import distinct, distinct_union


def _same(got: np.ndarray, want: np.ndarray) -> None:
    assert got.dtype == want.dtype and got.shape == want.shape
    assert got.tobytes() == want.tobytes() or np.array_equal(got, want, equal_nan=True)
    if got.dtype.kind == "f":  # the bits too: NaNs where numpy has them, signs of zero
        assert np.array_equal(np.isnan(got), np.isnan(want))
        finite = ~np.isnan(got)
        assert np.array_equal(np.signbit(got[finite]), np.signbit(want[finite]))


@pytest.mark.parametrize("seed", range(40))
def test_distinct_is_np_unique(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(0, 300))
    ints = rng.integers(-20, 20, size=n)
    floats = rng.choice(rng.normal(size=max(1, n // 3)), size=n)  # repeats
    floats[rng.random(n) < 0.05] = np.nan
    grid = rng.integers(0, 5, size=(n // 4 + 1, 3))  # 2-D: flattened as np.unique does
    for a in (ints, floats, ints.astype(np.int32), grid, floats.tolist(), ints[:1], ints[:0]):
        _same(distinct(a), np.unique(a))
    _same(distinct_union(ints, ints[::2] + 7), np.union1d(ints, ints[::2] + 7))
    _same(distinct_union(floats, [3.0]), np.union1d(floats, [3.0]))
    _same(
        distinct_union(ints, np.arange(0, n, 16), [n]),
        np.union1d(np.union1d(ints, np.arange(0, n, 16)), [n]),
    )


def test_distinct_of_special_values():
    a = np.array([np.nan, 1.0, np.inf, -np.inf, np.nan, 1.0, 0.5])
    _same(distinct(a), np.unique(a))  # [-inf, 0.5, 1, inf, nan]
    assert distinct(a).size == 5
    _same(distinct(np.float64(2.5)), np.unique(np.float64(2.5)))
    _same(distinct(np.array([3, 3, 3])), np.array([3]))
