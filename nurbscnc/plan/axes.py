"""Per-piece path limits from the machine's axis limits (planner v2, issue 13).

The planner plans along the path with one tangential acceleration and jerk per piece; a
real machine limits each axis. :func:`piece_limits` turns the machine's limits into the path
limits of every piece: the feed [mm/s], the tangential acceleration [mm/s²] and jerk
[mm/s³] that keep every axis within its own limits on that piece.

This first version has no per-axis limits in the machine profile yet: every piece gets the
path limits of the profile (V_max is already in each piece's ``v_cap_mm_s``), which is the
planner's behaviour so far.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class PieceLimits:
    """Path limits of each of k pieces, (k,) each: ``v_mm_s`` feed cap [mm/s] (``inf``: no
    cap beyond the piece's own), ``a_mm_s2`` tangential acceleration [mm/s²], ``j_mm_s3``
    tangential jerk [mm/s³]."""

    v_mm_s: np.ndarray
    a_mm_s2: np.ndarray
    j_mm_s3: np.ndarray


def piece_limits(pieces, machine) -> PieceLimits:
    """The path limits of every piece of ``pieces`` (a PieceList) on ``machine``."""
    k = len(pieces)
    lim = machine.limits
    return PieceLimits(np.full(k, np.inf), np.full(k, float(lim.a_max_mm_s2)),
                       np.full(k, float(lim.j_max_mm_s3)))  # fmt: skip
