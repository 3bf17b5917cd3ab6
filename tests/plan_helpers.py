"""Shared assertions of the planner tests that compare two plans of one program."""

from __future__ import annotations

import numpy as np

#: The rise and descent limits of a plan's ``limits``, per piece.
LIMIT_FIELDS = ("a_up_mm_s2", "j_up_mm_s3", "a_down_mm_s2", "j_down_mm_s3")


def assert_same_levers(a, b, k: int | None = None) -> None:
    """The plans ``a`` and ``b`` have equal caps, rise and descent limits and settles, exactly,
    on every piece (or pieces 0 … k − 1)."""
    np.testing.assert_array_equal(a.caps_mm_s[:k], b.caps_mm_s[:k])
    for f in LIMIT_FIELDS:
        np.testing.assert_array_equal(getattr(a.limits, f)[:k], getattr(b.limits, f)[:k], f)
    np.testing.assert_array_equal(a.settle_s[:k], b.settle_s[:k])
