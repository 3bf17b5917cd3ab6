"""Sorted distinct values of an array: ``np.unique`` and ``np.union1d`` without their
import of ``numpy.ma``.

``np.unique(a)`` asks ``np.ma.is_masked(a)`` before its work when no index, inverse or count
is asked for, and the first such call of a process imports ``numpy.ma`` (10–14 ms of CPU,
paid by every ``plan`` process); the planner calls it on its knots, breakpoints, piece kinds
and index sets. These give the same values (sorted, each once, NaNs as one at the end, as
``np.unique``'s default ``equal_nan``), by its own sorting method: sort, then keep each value
that differs from the one before.
"""

from __future__ import annotations

import numpy as np


def distinct(values) -> np.ndarray:
    """``np.unique(values)``: the sorted distinct values of ``values`` flattened, in its dtype
    (NaNs, sorted last, kept once)."""
    a = np.sort(np.asarray(values), axis=None)
    if a.size < 2:
        return a
    keep = np.empty(a.size, dtype=bool)
    keep[0] = True
    np.not_equal(a[1:], a[:-1], out=keep[1:])
    if a.dtype.kind in "fc" and np.isnan(a[-1]):
        keep[int(np.argmax(np.isnan(a))) + 1 :] = False
    return a[keep]


def distinct_union(*arrays) -> np.ndarray:
    """``np.union1d`` of any number of arrays: the sorted distinct values of them all."""
    return distinct(np.concatenate([np.ravel(a) for a in arrays]))
