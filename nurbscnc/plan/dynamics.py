"""The dynamics check (SPEC §8, eq. 25–29): predicted servo response and contour error.

Each axis's closed-loop model (machine profile) is driven by the planned reference points as
a first-order hold; the contour error is measured both by eq. 29 (from the axis errors and the
tangent angle, XY plane) and as the true distance from the actual point to the commanded path.

Long programs (:func:`path_response`, what the planner uses). The true distance is measured
against the path *near the reference point of the same servo period*, not against the whole
path: the reference r_k lies on the path, so the nearest path point to the actual point a_k
is within |e_k| = |r_k − a_k| of a_k, hence within 2|e_k| of r_k, and along the path within
2|e_k| of r_k's arc length s_k unless the path folds back onto itself closer than that. The
distance is therefore computed exactly (point to segment) to a dense polyline of the path
restricted to s ∈ [s_k − 2|e_k|, s_k + 2|e_k|] (with the segments crossing its ends). Parts of the path
that come back within 2|e_k| (≈ 30 µm) from far along it are not looked at: the check is
about following the path locally, and the window keeps it linear in the program length (the
global nearest-segment search of :func:`~nurbscnc.servo.contour_error_true` is kept for
short paths and tools). The polyline is exact on lines (their end points) and has a chord
error below :data:`CHORD_MM` on curved pieces; it is built one slab of samples at a time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbscnc.servo import contour_error_eq29, contour_error_true, simulate_axes

#: Chord error of the dense polyline on curved pieces [mm] (0.01 µm).
CHORD_MM = 1e-5
#: Longest chord of the dense polyline on curved pieces [mm].
MAX_SPACING_MM = 0.01
#: Servo samples per slab of the windowed distance.
SLAB = 1 << 15


@dataclass(frozen=True, eq=False)
class Response:
    """Predicted servo response to a reference.

    ``actual_mm`` (M, 3) with M ≥ N (settling samples appended, reference held);
    ``axis_error_mm`` (M, 3) reference − actual; ``contour_mm`` (M,) true distance to the
    path; ``contour_eq29_mm`` (M,) eq. 29 in the XY plane (signed).
    """

    actual_mm: np.ndarray
    axis_error_mm: np.ndarray
    contour_mm: np.ndarray
    contour_eq29_mm: np.ndarray


def dense_path_mm(pieces, profile, spacing_mm: float = 0.002, table=None) -> np.ndarray:
    """The commanded path as a dense polyline [mm]: exact points every ``spacing_mm`` or
    closer (≥ 8 per piece), so its chord error is negligible beside micrometre errors."""
    from nurbscnc.interpolate import place_points

    total = profile.total_length_mm
    starts = profile.piece_start_mm
    lengths = _lengths(pieces)
    counts = np.maximum(np.ceil(lengths / spacing_mm).astype(np.int64), 8)
    counts[lengths == 0.0] = 1
    idx = np.repeat(np.arange(len(pieces)), counts)
    first = np.repeat(np.cumsum(counts) - counts, counts)
    frac = (np.arange(idx.size) - first) / np.repeat(np.maximum(counts - 1, 1), counts)
    s = starts[idx] + frac * lengths[idx]
    s = np.clip(s, 0.0, total)
    return place_points(pieces, profile, s, idx, table=table)


def _lengths(pieces) -> np.ndarray:
    col = getattr(pieces, "length_mm", None)
    if isinstance(col, np.ndarray):
        return col
    return np.array([p.length_mm for p in pieces])


def _eq29(reference_mm: np.ndarray, axis_err: np.ndarray) -> np.ndarray:
    """eq. 29 with the tangent angle of the reference's direction of travel (XY)."""
    d = np.gradient(reference_mm[:, :2], axis=0)
    phi = np.arctan2(d[:, 1], d[:, 0])
    eq29 = contour_error_eq29(axis_err[:, 0], axis_err[:, 1], phi)
    moving = np.hypot(d[:, 0], d[:, 1]) > 0
    return np.where(moving, eq29, 0.0)


def _simulate(reference_mm: np.ndarray, machine, hold: str):
    servo = machine.servo
    models = [servo.x, servo.y, servo.z]
    actual = simulate_axes(models, reference_mm, servo.period_s, hold=hold, settle=True)
    m = actual.shape[0]
    ref = np.vstack([reference_mm, np.repeat(reference_mm[-1:], m - reference_mm.shape[0], 0)])
    return actual, ref


def servo_response(
    reference_mm: np.ndarray, path_mm: np.ndarray, machine, hold: str = "foh"
) -> Response:
    """Simulate every axis on ``reference_mm`` (N, 3) and measure the contour error to the
    whole polyline ``path_mm`` (global nearest-segment search)."""
    actual, ref = _simulate(reference_mm, machine, hold)
    axis_err = ref - actual
    contour = contour_error_true(actual, path_mm)
    return Response(actual, axis_err, contour, _eq29(ref, axis_err))


def path_counts(pieces) -> np.ndarray:
    """Points of the dense polyline on each piece (≥ 2): 2 on lines and rapids (exact),
    else chords of at most min(:data:`MAX_SPACING_MM`, √(8 δ_p / κ)) with δ_p =
    :data:`CHORD_MM` (a chord h on curvature κ is off by κh²/8); κ is the piece's
    ``kappa_max_per_mm``, doubled on NURBS cells (their κ comes from 8 samples)."""
    from nurbscnc.plan.pieces import K_LINE, K_NURBS, K_RAPID

    kind = pieces.kind
    kappa = np.where(kind == K_NURBS, 2.0, 1.0) * np.abs(pieces.kappa_max_per_mm)
    with np.errstate(divide="ignore"):
        h = np.minimum(MAX_SPACING_MM, np.sqrt(8.0 * CHORD_MM / kappa))
    counts = np.maximum(np.ceil(pieces.length_mm / h).astype(np.int64) + 1, 3)
    straight = (kind == K_LINE) | (kind == K_RAPID)
    return np.where(straight | (pieces.length_mm == 0.0), 2, counts)


def windowed_contour_mm(actual_mm: np.ndarray, reference_mm: np.ndarray, s_ref_mm: np.ndarray,
                        pieces, profile, table=None) -> np.ndarray:  # fmt: skip
    """True distance [mm] from each actual point to the path near its reference (module doc).

    ``actual_mm``, ``reference_mm`` (M, 3); ``s_ref_mm`` (M,) the path length of each
    reference point. Exact point-to-segment distances to the dense polyline of
    :func:`path_counts`, from its last point before s − W to its first point after s + W,
    W = 2|r − a|.
    """
    from nurbscnc.interpolate import place_points

    m = actual_mm.shape[0]
    out = np.empty(m)
    counts = path_counts(pieces)
    starts = profile.piece_start_mm
    lengths = pieces.length_mm
    total = profile.total_length_mm
    k = lengths.size
    lag = np.sqrt(np.sum((reference_mm - actual_mm) ** 2, axis=1))
    for lo in range(0, m, SLAB):
        sl = slice(lo, min(lo + SLAB, m))
        s = s_ref_mm[sl]
        w = 2.0 * lag[sl]
        # The pieces the windows touch, and one more on each side.
        p_lo = max(int(np.searchsorted(starts, float((s - w).min()), side="right")) - 2, 0)
        p_hi = min(int(np.searchsorted(starts, float((s + w).max()), side="right")) + 1, k)
        piece = np.repeat(np.arange(p_lo, p_hi), counts[p_lo:p_hi])
        c = counts[p_lo:p_hi]
        first = np.repeat(np.cumsum(c) - c, c)
        frac = (np.arange(piece.size) - first) / np.repeat(c - 1, c)
        ps = np.minimum(starts[piece] + frac * lengths[piece], total)
        pts = place_points(pieces, profile, ps, piece, table=table)
        # Polyline segments [j, j + 1] covering [s − w, s + w]: from the last point before
        # the window to the first one after it.
        a_idx = np.maximum(np.searchsorted(ps, s - w, side="left") - 1, 0)
        b_idx = np.minimum(np.searchsorted(ps, s + w, side="right"), ps.size - 1)
        b_idx = np.maximum(b_idx, np.minimum(a_idx + 1, ps.size - 1))
        q = actual_mm[sl]
        best = np.full(s.size, np.inf)
        for off in range(int((b_idx - a_idx).max())):
            j = a_idx + off
            live = j < b_idx
            j = np.minimum(j, ps.size - 2)
            a = pts[j]
            d = pts[j + 1] - a
            len2 = np.einsum("ij,ij->i", d, d)
            t = np.einsum("ij,ij->i", q - a, d) / np.where(len2 > 0.0, len2, 1.0)
            t = np.clip(np.where(len2 > 0.0, t, 0.0), 0.0, 1.0)
            e = q - a - t[:, None] * d
            dist = np.sqrt(np.einsum("ij,ij->i", e, e))
            best = np.where(live, np.minimum(best, dist), best)
        out[sl] = best
    return out


def path_response(samples, pieces, profile, machine, table=None, hold: str = "foh") -> Response:
    """Simulate every axis on the planned samples and measure the contour error by the
    windowed true distance (module doc) — linear in the program length."""
    actual, ref = _simulate(samples.points_mm, machine, hold)
    axis_err = ref - actual
    n = samples.s_mm.size
    s_ref = np.concatenate((samples.s_mm, np.full(actual.shape[0] - n, samples.s_mm[-1])))
    contour = windowed_contour_mm(actual, ref, s_ref, pieces, profile, table=table)
    return Response(actual, axis_err, contour, _eq29(ref, axis_err))
