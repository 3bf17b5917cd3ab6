"""The dynamics check (SPEC §8, eq. 25–29): predicted servo response and contour error.

Each axis's closed-loop model (machine profile) is driven by the planned reference points as
a first-order hold; the contour error is measured both by eq. 29 (from the axis errors and the
tangent angle, XY plane) and as the true distance from the actual point to the commanded path.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbscnc.servo import contour_error_eq29, contour_error_true, simulate_axes


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
    lengths = np.array([p.length_mm for p in pieces])
    counts = np.maximum(np.ceil(lengths / spacing_mm).astype(np.int64), 8)
    counts[lengths == 0.0] = 1
    idx = np.repeat(np.arange(len(pieces)), counts)
    first = np.repeat(np.cumsum(counts) - counts, counts)
    frac = (np.arange(idx.size) - first) / np.repeat(np.maximum(counts - 1, 1), counts)
    s = starts[idx] + frac * lengths[idx]
    s = np.clip(s, 0.0, total)
    return place_points(pieces, profile, s, idx, table=table)


def servo_response(
    reference_mm: np.ndarray, path_mm: np.ndarray, machine, hold: str = "foh"
) -> Response:
    """Simulate every axis on ``reference_mm`` (N, 3) and measure the contour error."""
    servo = machine.servo
    models = [servo.x, servo.y, servo.z]
    actual = simulate_axes(models, reference_mm, servo.period_s, hold=hold, settle=True)
    m = actual.shape[0]
    ref = np.vstack([reference_mm, np.repeat(reference_mm[-1:], m - reference_mm.shape[0], 0)])
    axis_err = ref - actual
    contour = contour_error_true(actual, path_mm)
    # Tangent angle of the reference path for eq. 29 (XY), from its direction of travel.
    d = np.gradient(ref[:, :2], axis=0)
    phi = np.arctan2(d[:, 1], d[:, 0])
    eq29 = contour_error_eq29(axis_err[:, 0], axis_err[:, 1], phi)
    moving = np.hypot(d[:, 0], d[:, 1]) > 0
    eq29 = np.where(moving, eq29, 0.0)
    return Response(actual, axis_err, contour, eq29)
