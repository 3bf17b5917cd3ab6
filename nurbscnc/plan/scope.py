"""Which servo samples the contour guarantee covers (SPEC §8), the one scope of the contour
error in every report: the dynamics check, the plan summary, ``simulate``, the plots and the
JSON.

The guarantee concerns the feed moves (G1/G2/G3 and NURBS pieces, PH corners, the held end
of a cut): their samples are the *feed* samples, and so are those of the settle wait at the
start of a cut after a rapid (the reference stands at the cut's first point, written with
the cut's line, while the tool still rings from the rapid's stop: the check softens the
rapid's stop until they meet ε_max). Not covered are the rapids' own samples. The settle's
samples and the first moving samples of a cut after a rapid are measured against the cut
only (:func:`feed_samples`)."""

from __future__ import annotations

import numpy as np

from nurbscnc.plan.dynamics import PathIndex, Response
from nurbscnc.plan.profile import Profile
from nurbscnc.plan.timing import Reference


def after_rapid_rows(rapid: np.ndarray) -> np.ndarray:
    """(P,) bool: the pieces that start a cut right after a rapid (``rapid`` (P,) bool)."""
    after = np.zeros(rapid.size, dtype=bool)
    after[np.flatnonzero(rapid[:-1] & ~rapid[1:]) + 1] = True
    return after


def feed_samples(
    ref: Reference,
    response: Response,
    profile: Profile,
    rapid: np.ndarray,
    after_rapid: np.ndarray,
    index: PathIndex,
    index_rapid: np.ndarray | None = None,
) -> np.ndarray:
    """(N,) bool: which of the N reference samples ``ref`` (``t_s`` [s], ``s_mm``,
    ``piece``) the contour guarantee covers (module doc): those not on a rapid piece
    (``rapid`` (P,)). The settle wait and the first moving samples of a cut after a rapid
    (``after_rapid`` (P,), :func:`after_rapid_rows`) are measured against the cut only, in
    ``response.contour_mm`` (in place), by ``index`` (a path of the first pieces only:
    ``index_rapid`` their rapid flags)."""
    exclude = rapid if index_rapid is None else index_rapid
    _cut_distance_after_rapids(response, ref, profile, after_rapid, exclude, index)
    return ~rapid[ref.piece]


def _cut_distance_after_rapids(
    response: Response,
    ref: Reference,
    profile: Profile,
    after_rapid: np.ndarray,
    rapid: np.ndarray,
    index: PathIndex,
) -> None:
    """Measure the settle after a rapid and the first cutting samples after it against the
    cut only (in place).

    The path the contour error is measured against includes the rapids, so a tool still
    arriving along a rapid (or overshooting its end along it) looks on the path although
    the cut leaves in another direction; it is 'on the path' only if it is on the cut.
    Only samples whose distance window (module doc of :mod:`~nurbscnc.plan.dynamics`: ±2|e|
    of arc length) reaches back across the rapid's end are affected (all of the settle's:
    its reference waits at the cut's start); their reference lies on the cut, so |e|
    bounds the distance."""
    n = ref.t_s.size
    lag = np.sqrt(np.einsum("ij,ij->i", response.axis_error_mm[:n], response.axis_error_mm[:n]))
    start = profile.piece_start_mm[ref.piece]
    fix = np.flatnonzero(after_rapid[ref.piece] & (ref.s_mm - 2.0 * lag <= start))
    if fix.size:
        response.contour_mm[fix] = index.distance_mm(
            response.actual_mm[fix], lag[fix] + 1e-12, exclude=rapid
        )
