"""PH quintic fits of NURBS corner regions (SPEC §6).

A corner region C(u), u ∈ [u_a, u_b], is replaced by the PH quintic Hermite interpolant of
p0 = C(u_a), p5 = C(u_b), d0 = (u_b − u_a)C′(u_a), d1 = (u_b − u_a)C′(u_b) (the factor maps
the NURBS derivative to the PH parameter ξ = (u − u_a)/(u_b − u_a)). The deviation is the true
point-to-curve distance from dense samples of C to the PH curve. While it is too large the
region is split at its parameter midpoint; both halves share C and C′ there, so the joins are
G1 (in fact C1 in ξ, as the halves have equal parameter widths).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbscnc.errors import ConfigError, PlanningError
from nurbscnc.geometry.ph import PHQuintic, hermite_ph, plane_frame
from nurbscnc.geometry.phfoot import point_xy


@dataclass(frozen=True, eq=False)
class PHPiece:
    """One PH quintic replacing C on [``u_a``, ``u_b``]; its deviation from C [µm]."""

    ph: PHQuintic
    u_a: float
    u_b: float
    rms_um: float
    max_um: float


@dataclass(frozen=True, eq=False)
class PHFit:
    """The PH pieces (in parameter order) replacing a corner region, with the overall RMS
    (over all samples of all pieces) and max deviation [µm]."""

    pieces: tuple[PHPiece, ...]
    rms_um: float
    max_um: float

    @property
    def length_mm(self) -> float:
        """Total arc length of the PH pieces [mm]."""
        return float(sum(p.ph.length_mm for p in self.pieces))

    @property
    def u_a(self) -> float:
        return self.pieces[0].u_a

    @property
    def u_b(self) -> float:
        return self.pieces[-1].u_b


def _to_plane(
    vectors_mm: np.ndarray, frame, translate: bool, normal=None
) -> tuple[np.ndarray, np.ndarray]:
    """3-D points/vectors (m, 3) -> (complex plane coordinates, signed off-plane part) [mm];
    ``normal`` e1 × e2 of ``frame`` (origin, e1, e2) if known."""
    origin, e1, e2 = frame[:3]
    v = vectors_mm - origin if translate else vectors_mm
    return v @ e1 + 1j * (v @ e2), v @ (np.cross(e1, e2) if normal is None else normal)


def ph_deviation_um(ph: PHQuintic, points_mm: np.ndarray, normal=None) -> np.ndarray:
    """Distance [µm] from each 3-D point (m, 3) to the PH curve (closest point on ξ ∈ [0, 1]).

    In-plane distance to the foot point (:meth:`PHQuintic.closest_param`; the point there by
    :func:`~nurbscnc.geometry.phfoot.point_xy`, the foot search's own arithmetic) combined
    with the off-plane offset; ``normal`` the curve's plane normal if known.
    """
    q, off = _to_plane(
        np.asarray(points_mm, dtype=float), (ph.origin_mm, ph.e1, ph.e2), True, normal
    )
    xi = ph.closest_param(q)
    cp = ph.control_points
    px, py = point_xy(cp.real, cp.imag, xi)
    return 1e3 * np.hypot(np.hypot(px - q.real, py - q.imag), off)


def _fit_piece(curve, u_a: float, u_b: float, frame, n_samples: int):
    """PH Hermite interpolant of C on [u_a, u_b] and its squared deviations [µm²]; ``frame``
    (origin, e1, e2, e1 × e2)."""
    ends = curve.derivatives(np.array([u_a, u_b]), 1)
    width = u_b - u_a
    normal = frame[3]
    (p0, p5), _ = _to_plane(ends[0], frame, True, normal)
    (d0, d1), _ = _to_plane(width * ends[1], frame, False, normal)
    ph = hermite_ph(p0, p5, d0, d1, *frame[:3])
    u = np.linspace(u_a, u_b, n_samples)
    dev_um = ph_deviation_um(ph, curve.point(u), normal)
    piece = PHPiece(
        ph, float(u_a), float(u_b), float(np.sqrt(np.mean(dev_um**2))), float(dev_um.max())
    )
    return piece, float(np.sum(dev_um**2)), dev_um.size


def fit_region(
    curve,
    u_a: float,
    u_b: float,
    tolerance_um: float = 1.0,
    max_depth: int = 12,
    split: bool = True,
    samples_per_piece: int = 200,
    max_factor: float = 3.0,
) -> PHFit:
    """Fit PH quintics to ``curve`` on [``u_a``, ``u_b``] (SPEC §6).

    ``curve`` has ``point(u) -> (m, 3)`` and ``derivatives(u, order) -> (order + 1, m, 3)``
    [mm]; it must be planar on the region (else :class:`GeometryError`). The deviation of each
    piece is measured at ``samples_per_piece`` parameter-uniform samples of C (end points
    included) as the distance to the PH curve. With ``split``, a piece whose RMS exceeds
    ``tolerance_um`` or whose max exceeds ``max_factor`` × ``tolerance_um`` (the paper's rule:
    3; the planner asks 1, so every reference point is within e of the programmed curve) is
    split at its parameter midpoint, recursively; a piece still failing after ``max_depth``
    halvings raises :class:`PlanningError`. Without ``split`` one piece is returned whatever
    its deviation.
    """
    if not tolerance_um > 0.0:
        raise ConfigError(f"PH fit tolerance must be positive, got {tolerance_um} µm")
    if max_depth < 0 or samples_per_piece < 2:
        raise ConfigError("PH fit needs max_depth >= 0 and samples_per_piece >= 2")
    u_a, u_b = float(u_a), float(u_b)
    if not u_b > u_a:
        raise PlanningError(f"empty corner region [{u_a}, {u_b}]")
    # One plane frame for the whole region, so all pieces share it.
    frame = plane_frame(curve.point(np.linspace(u_a, u_b, 4 * samples_per_piece + 1)))
    frame = (*frame, np.cross(frame[1], frame[2]))

    pieces: list[PHPiece] = []
    sum_sq = 0.0
    count = 0
    # Depth-first, left half first, so pieces come out in parameter order.
    stack = [(u_a, u_b, 0)]
    while stack:
        a, b, depth = stack.pop()
        piece, sq, n = _fit_piece(curve, a, b, frame, samples_per_piece)
        ok = piece.rms_um <= tolerance_um and piece.max_um <= max_factor * tolerance_um
        if ok or not split:
            pieces.append(piece)
            sum_sq += sq
            count += n
            continue
        if depth >= max_depth:
            raise PlanningError(
                f"PH fit of the corner region u = [{u_a:.9g}, {u_b:.9g}] does not reach "
                f"{tolerance_um:g} µm RMS / {max_factor * tolerance_um:g} µm max after {max_depth} "
                f"halvings: piece u = [{a:.9g}, {b:.9g}] deviates {piece.rms_um:.4g} µm RMS, "
                f"{piece.max_um:.4g} µm max"
            )
        mid = 0.5 * (a + b)
        stack.append((mid, b, depth + 1))
        stack.append((a, mid, depth + 1))
    return PHFit(tuple(pieces), float(np.sqrt(sum_sq / count)), max(p.max_um for p in pieces))
