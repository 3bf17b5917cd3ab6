"""The dynamics check (SPEC §8, eq. 25–29): predicted servo response and contour error.

Each axis's closed-loop model (machine profile) is driven by the planned reference points as
a first-order hold; the contour error is measured both by eq. 29 (from the axis errors and the
tangent angle, XY plane) and as the true distance from the actual point to the commanded path
(:mod:`nurbscnc.geometry.distance`).

Long programs (:func:`path_response`, what the planner uses). The true distance is first
measured against the path *near the reference point of the same servo period*
(:func:`~nurbscnc.geometry.distance.windowed_contour_mm`: linear in the program length, never
below the true distance). The samples where it exceeds the limit (the few that decide the
check) are then measured against the whole path
(:class:`~nurbscnc.geometry.distance.PathIndex`), so the decision to slow down uses the true
distance as the SPEC defines it — an overshoot past the end of a closed contour onto its own
start is no error.

Everything after the simulation is per sample, so the planner's check measures a window of
samples at a time (:func:`window_response`, the servo simulated with its state carried by
:class:`~nurbscnc.servo.model.AxesStream`) and gets, sample for sample, what
:func:`path_response` gives on the whole reference.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbscnc.geometry.distance import PathIndex, windowed_contour_mm
from nurbscnc.servo.model import contour_error_eq29, simulate_axes


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


def path_response(
    samples,
    pieces,
    profile,
    machine,
    hold: str = "foh",
    refine_above_mm: float | None = None,
    index: PathIndex | None = None,
) -> Response:
    """Simulate every axis on the planned samples and measure the contour error: the
    windowed true distance (module doc), linear in the program length; where it exceeds
    ``refine_above_mm`` (default: never), the distance to the whole path instead
    (:class:`PathIndex`, ``index`` if the caller keeps one), so the samples that decide the
    check get the global true distance (an overshoot past a closed contour's end onto its
    own start is then no error)."""
    ref = samples.points_mm
    n = ref.shape[0]
    servo = machine.servo
    actual = simulate_axes([servo.x, servo.y, servo.z], ref, servo.period_s, hold=hold, settle=True)
    axis_err = np.empty_like(actual)
    np.subtract(ref, actual[:n], out=axis_err[:n])
    np.subtract(ref[-1], actual[n:], out=axis_err[n:])
    lag = np.sqrt(np.einsum("ij,ij->i", axis_err, axis_err))
    s_ref = np.concatenate((samples.s_mm, np.full(actual.shape[0] - n, samples.s_mm[-1])))
    contour = windowed_contour_mm(actual, lag, s_ref, pieces, profile, index)
    del lag, s_ref
    if refine_above_mm is not None:
        sel = np.flatnonzero(contour > refine_above_mm)
        if sel.size:
            index = index or PathIndex(pieces)
            contour[sel] = index.distance_mm(actual[sel], contour[sel])
    # eq. 29 with the tangent angle of the reference's direction of travel (XY); the held
    # tail does not move.
    d = np.zeros((actual.shape[0], 2))
    d[:n] = np.gradient(ref[:, :2], axis=0) if n > 1 else 0.0
    phi = np.arctan2(d[:, 1], d[:, 0])
    eq29 = contour_error_eq29(axis_err[:, 0], axis_err[:, 1], phi)
    eq29 = np.where(np.hypot(d[:, 0], d[:, 1]) > 0, eq29, 0.0)
    return Response(actual, axis_err, contour, eq29)


def window_response(
    points_mm: np.ndarray,
    s_mm: np.ndarray,
    actual_mm: np.ndarray,
    direction_xy: np.ndarray,
    pieces,
    profile,
    refine_above_mm: float | None = None,
    index: PathIndex | None = None,
) -> Response:
    """The response of one window of samples (the windowed dynamics check): the
    reference ``points_mm`` (w, 3) [mm] at path lengths ``s_mm`` (w,), the simulated
    ``actual_mm`` (w, 3) (:class:`~nurbscnc.servo.model.AxesStream`) and the reference's
    direction of travel ``direction_xy`` (w, 2) (its central difference over the whole
    reference; 0 where it does not move). Per sample the same as :func:`path_response`:
    the true distance near the reference point (:func:`windowed_contour_mm`), refined to the
    whole path above ``refine_above_mm``, and eq. 29 (SPEC §8) in the XY plane."""
    axis_err = points_mm - actual_mm
    lag = np.sqrt(np.einsum("ij,ij->i", axis_err, axis_err))
    contour = contour_near_mm(actual_mm, lag, s_mm, pieces, profile, refine_above_mm, index)
    return Response(actual_mm, axis_err, contour, eq29_mm(axis_err, direction_xy))


def contour_near_mm(
    actual_mm: np.ndarray,
    lag_mm: np.ndarray,
    s_mm: np.ndarray,
    pieces,
    profile,
    refine_above_mm: float | None = None,
    index: PathIndex | None = None,
) -> np.ndarray:
    """The contour error [mm] of :func:`window_response` for the actual points ``actual_mm``
    (w, 3) whose references lie ``lag_mm`` (w,) [mm] from them at path lengths ``s_mm``
    (w,): the true distance near the reference point (:func:`windowed_contour_mm`), refined
    to the whole path above ``refine_above_mm``. Per sample: any subset of a window's
    samples gets their numbers bit for bit."""
    contour = windowed_contour_mm(actual_mm, lag_mm, s_mm, pieces, profile, index)
    if refine_above_mm is not None:
        sel = np.flatnonzero(contour > refine_above_mm)
        if sel.size:
            index = index or PathIndex(pieces)
            contour[sel] = index.distance_mm(actual_mm[sel], contour[sel])
    return contour


def eq29_mm(axis_error_mm: np.ndarray, direction_xy: np.ndarray) -> np.ndarray:
    """SPEC eq. 29 [mm] of the axis errors ``axis_error_mm`` (w, 3) [mm] with the tangent
    angle of the reference's direction of travel ``direction_xy`` (w, 2); 0 where it does
    not move."""
    d = direction_xy
    phi = np.arctan2(d[:, 1], d[:, 0])
    eq29 = contour_error_eq29(axis_error_mm[:, 0], axis_error_mm[:, 1], phi)
    return np.where(np.hypot(d[:, 0], d[:, 1]) > 0, eq29, 0.0)
