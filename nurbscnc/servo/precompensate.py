"""Pre-compensation: a reference that makes the modelled servo follow the planned points.

The servo of each axis is the closed-loop model of SPEC eq. 25, sampled exactly at the servo
period for a first-order-hold input (:func:`nurbscnc.servo.model.discretise`):

    H(z) = z^{-d} B(z⁻¹) / A(z⁻¹),   B(z⁻¹) = B_s(z⁻¹) · B_u(z⁻¹),

with d leading zero coefficients of the numerator (a pure delay; d = 0 for the FOH model, whose
direct feed-through is not zero), B_s the factor with the zeros strictly inside the unit circle
and B_u = Π (1 − z_j z⁻¹) the factor with the others. The sampled 4th-order model of eq. 25 has
relative degree 2, so its FOH equivalent has two sampling zeros, one of them outside the unit
circle (≈ −3.3 at T_s = 1 ms for the paper's axes): H is non-minimum-phase and has no stable
causal inverse.

Zero-phase-error tracking control (ZPETC; M. Tomizuka, "Zero phase error tracking algorithm for
digital control", ASME J. Dyn. Syst. Meas. Control 109 (1987) 65–68) inverts what can be
inverted and phase-cancels the rest:

    F(z) = z^{d} A(z⁻¹) B_u(z) / (B_s(z⁻¹) · B_u(1)²),

so that H(z) F(z) = B_u(z⁻¹) B_u(z) / B_u(1)²: real and positive on the unit circle (no phase
error at any frequency), 1 at DC, and for one unstable zero z_u the gain is
1 − 2|z_u|(1 − cos ωT)/(1 − z_u)² ≈ 1 − β (ωT)² with β = |z_u|/(1 + |z_u|)²: in the time
domain the tool follows y ≈ r + β T_s² r̈ (β = 0.178 for z_u = −3.32: 0.44 µm at 2450 mm/s²).
The poles of F are the stable zeros of H (decaying), the factor B_u(z) looks n_u + d samples
ahead (pre-actuation). With a minimum-phase H (no unstable zero) F is the exact inverse and
the tool follows the reference exactly at the samples.

Boundary conditions (the programmed start and end points are kept):

- Start: the machine is at rest at the first point. F looks ahead n_u + d samples, so the
  compensated reference must start moving that many periods before the planned motion does
  (pre-actuation). Rather than move before t = 0, the planned reference is delayed by
  ``lead_samples`` = n_u + d periods (its start point held), so the first compensated point is
  exactly the programmed start, the machine at rest there, and the pre-actuation happens in
  the held periods: the tool follows the planned motion ``lead_samples`` periods later
  (1 ms on the paper's axes), which the cycle time counts.
- End: after the planned motion stops the decaying modes of F (the stable zeros of H) still
  move the compensated reference by a little; periods are *appended* until it stays within
  ``tail_tolerance_mm`` of the end point, and the last point is exactly the programmed end point
  (a step of at most that tolerance). Whether the reference overshoots the end point on the
  way is a property of the plan (a jerk-limited stop gives none; the tests measure it).
- DC: F is scaled to unit DC gain, so a model whose G(0) ≠ 1 keeps its static error (the
  points at rest are the programmed ones, never scaled).

Everything is whole-array: one ``scipy.signal.lfilter`` per axis (the IIR part A/B_s) and one
``numpy.correlate`` (the look-ahead FIR B_u(z)).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from nurbscnc.errors import ConfigError
from nurbscnc.servo.model import AxisModel, DiscreteAxis, _as_model, discretise

#: The compensated reference's tail ends once it stays this close to the end point [mm]
#: (0.1 µm: a tenth of a 1000 steps/mm step; the last point is then set exactly).
TAIL_TOLERANCE_MM = 1e-4
#: Default largest distance of a pre-compensated reference from the path [mm] (issue 13's
#: 3 µm, :func:`limit_to_path`): if the model is wrong, the reference itself is never far
#: off the path.
REFERENCE_TOLERANCE_MM = 0.003
#: Zeros with |z| ≥ 1 − this are treated as unstable (phase-cancelled, not inverted).
UNIT_CIRCLE_MARGIN = 1e-9


@dataclass(frozen=True, eq=False)
class InverseFilter:
    """The ZPETC inverse F(z) of one sampled axis (module docstring).

    ``num`` A(z⁻¹) and ``den`` B_s(z⁻¹) (powers of z⁻¹) of the causal IIR part; ``ahead``
    the coefficients c_i of B_u(z) = Σ c_i z^i divided by B_u(1)² and by F's DC gain, applied
    as u_k = Σ_i c_i v_{k+i}; ``lead_samples`` = d + n_u, how far F looks ahead [samples];
    ``unstable_zeros`` the phase-cancelled zeros z_j of H; ``slowest_pole`` the largest |pole|
    of F (its decay per sample, < 1).
    """

    num: np.ndarray
    den: np.ndarray
    ahead: np.ndarray
    lead_samples: int
    unstable_zeros: np.ndarray
    slowest_pole: float

    @property
    def gain_error_coefficient(self) -> float:
        """β of y ≈ r + β T_s² r̈ (module docstring): Σ_j −z_j/(1 − z_j)² over the unstable
        zeros (real part; |z_j|/(1 + |z_j|)² for a negative real zero); 0 for an exact
        inverse."""
        z = self.unstable_zeros
        return float(np.real(np.sum(-z / (1.0 - z) ** 2))) if z.size else 0.0


def zpetc(disc: DiscreteAxis) -> InverseFilter:
    """The ZPETC inverse of a sampled axis H(z) = z^{-d} B_s B_u / A (Tomizuka 1987; module
    docstring): F(z) = z^{d} A(z⁻¹) B_u(z) / (B_s(z⁻¹) B_u(1)²), scaled to unit DC gain."""
    b = np.asarray(disc.b, dtype=float)
    a = np.asarray(disc.a, dtype=float)
    nz = np.flatnonzero(np.abs(b) > 1e-14 * np.abs(b).max())
    delay = int(nz[0])
    b = b[delay : int(nz[-1]) + 1]
    zeros = np.roots(b) if b.size > 1 else np.zeros(0)
    bad = np.abs(zeros) >= 1.0 - UNIT_CIRCLE_MARGIN
    stable, unstable = zeros[~bad], zeros[bad]
    b_s = b[0] * np.atleast_1d(np.real(np.poly(stable)))  # B_s(z⁻¹) = b_0 Π (1 − z_i z⁻¹)
    # B_u(z⁻¹) = Π (1 − z_j z⁻¹); B_u(z) has the same coefficients c_i, in powers of z.
    b_u = np.atleast_1d(np.real(np.poly(unstable)))
    dc = a.sum() / (b_s.sum() * b_u.sum())  # F(1) = A(1) B_u(1) / (B_s(1) B_u(1)²)
    ahead = b_u / (b_u.sum() ** 2 * dc)
    slowest = float(np.abs(stable).max()) if stable.size else 0.0
    return InverseFilter(num=a, den=b_s, ahead=ahead, lead_samples=delay + unstable.size,
                         unstable_zeros=unstable, slowest_pole=slowest)  # fmt: skip


def _compensate(inverse: InverseFilter, r_mm: np.ndarray, lead: int) -> np.ndarray:
    """u = F r for the extended reference ``r_mm`` (already held ``lead`` samples at its start
    and long enough at its end): the IIR part from rest, then the look-ahead FIR. Returns
    u of the same length; its last ``inverse.lead_samples`` samples are held at the end."""
    from scipy import signal  # here, not at the top: importing scipy.signal is slow

    r0 = r_mm[0]
    v = signal.lfilter(inverse.num, inverse.den, r_mm - r0)  # from rest: zero state
    # u_k = Σ_i c_i v_{k + d + i} with the delay d folded into lead_samples: c has n_u + 1
    # taps, u_k looks lead_samples ahead.
    d = inverse.lead_samples - (inverse.ahead.size - 1)
    u = np.correlate(v[d:], inverse.ahead, mode="valid") + r0
    return np.concatenate([u, np.full(r_mm.size - u.size, r_mm[-1])])


@dataclass(frozen=True, eq=False)
class Compensated:
    """A pre-compensated reference: ``points_mm`` (M, k) [mm], M = N + ``lead_samples`` +
    ``tail_samples``: the start held ``lead_samples`` periods (pre-actuation), then the
    compensated motion, then ``tail_samples`` periods while the compensation decays after the
    planned stop. Sample k + ``lead_samples`` belongs to planned sample k."""

    points_mm: np.ndarray
    lead_samples: int
    tail_samples: int


def _tail_guess(inverses) -> int:
    # Samples for the slowest pole of F to decay by 1e-6 (at least 16).
    slow = max((f.slowest_pole for f in inverses), default=0.0)
    n = 16 if slow <= 0.0 else int(np.ceil(np.log(1e-6) / np.log(slow)))
    return max(n, 16) + max(f.lead_samples for f in inverses)


def precompensate_points(
    models: Sequence[AxisModel | None],
    points_mm: np.ndarray,
    period_s: float,
    hold: str = "foh",
    tail_tolerance_mm: float = TAIL_TOLERANCE_MM,
) -> Compensated:
    """Pre-compensate the reference ``points_mm`` (N, k) [mm] for the axis ``models`` (one per
    column; None an ideal axis, left as is) by ZPETC (module docstring, Tomizuka 1987).

    The planned points start and end at rest. The result starts at rest at the first point
    (held ``lead_samples`` periods, the largest look-ahead of any axis), follows u = F r, and
    ends exactly at the last point once every axis stays within ``tail_tolerance_mm`` of it.
    """
    r = np.asarray(points_mm, dtype=float)
    if r.ndim != 2 or r.shape[1] != len(models) or r.shape[0] == 0:
        raise ValueError("points_mm must be (N, k) with k = len(models), N >= 1")
    inverses = [None if m is None else zpetc(discretise(_as_model(m), period_s, hold))
                for m in models]  # fmt: skip
    present = [f for f in inverses if f is not None]
    if not present:
        raise ConfigError("pre-compensation needs a servo model for at least one axis")
    lead = max(f.lead_samples for f in present)
    n = r.shape[0]
    tail = _tail_guess(present)
    while True:
        ext = np.concatenate([np.repeat(r[:1], lead, axis=0), r,
                              np.repeat(r[-1:], tail + lead, axis=0)])  # fmt: skip
        u = ext.copy()
        for j, f in enumerate(inverses):
            if f is not None:
                u[:, j] = _compensate(f, ext[:, j], lead)
        # Drop the look-ahead padding; keep samples up to the last one off the end point.
        u = u[: lead + n + tail]
        off = np.flatnonzero(np.any(np.abs(u - r[-1]) > tail_tolerance_mm, axis=1))
        last = int(off[-1]) if off.size else 0
        if last < u.shape[0] - 1 - 8 or tail > 1_000_000:
            break
        tail *= 2  # still moving near the end of the guess: a slower F than expected
    keep = max(last + 2, lead + n)  # at least the planned motion, then the exact end point
    out = u[:keep].copy()
    out[-1] = r[-1]
    out[0] = r[0]  # exact already (u_0 looks at most to the planned first point, at rest)
    return Compensated(points_mm=out, lead_samples=lead, tail_samples=keep - lead - n)


def perturbed_model(model: AxisModel, loop_gain: float = 1.0,
                    bandwidth: float = 1.0) -> AxisModel:  # fmt: skip
    """A model error of G = N/D for the sensitivity of a pre-compensated reference.

    ``loop_gain`` k: the open loop L = G/(1 − G) = N/(D − N) (a unity-feedback reading of the
    closed loop) scaled by k, G' = kN/(D + (k − 1)N): the closed-loop poles move, the zeros
    (the controller's) stay, G'(0) = G(0) when a0 = b0, and the velocity lag c_1 = (a1 − b1)/a0
    becomes c_1/k (a plant gain or inertia off by 1/k). ``bandwidth`` λ: G'(s) = G(s/λ), every
    pole and zero times λ (a loop λ times faster), c_1/λ, G'(0) = G(0)."""
    model = _as_model(model)
    den = np.trim_zeros(np.asarray(model.denominator, dtype=float), "f")
    num = np.trim_zeros(np.asarray(model.numerator, dtype=float), "f")
    num_p = np.zeros(den.size)
    num_p[den.size - num.size :] = num
    new_num = loop_gain * num_p
    new_den = den + (loop_gain - 1.0) * num_p
    # G(s/λ): the coefficient of s^i divided by λ^i (highest power first).
    scale = float(bandwidth) ** -np.arange(den.size - 1, -1, -1)
    return AxisModel(tuple(np.trim_zeros(new_num * scale, "f")), tuple(new_den * scale))


def along_path_offset_mm(compensated_mm: np.ndarray, planned_mm: np.ndarray) -> np.ndarray:
    """d_t = (u_k − r_k)·t̂_k [mm] (M,): how far the compensated point u_k leads the planned
    point r_k along the direction of travel t̂ = ṙ/|ṙ| (central differences; where r stands
    still, the nearest earlier direction, or before the first motion the first one).

    Most of a ZPETC correction is this lead (≈ c_1·v, the velocity lag of eq. 25): the point
    of the path that far along from r_k is where the correction mostly points, and the rest
    (across the path) is what :func:`limit_to_path` bounds.
    """
    u = np.asarray(compensated_mm, dtype=float)
    r = np.asarray(planned_mm, dtype=float)
    tangent = np.gradient(r, axis=0) if r.shape[0] > 1 else np.zeros_like(r)
    norm = np.sqrt(np.einsum("ij,ij->i", tangent, tangent))
    moving = np.flatnonzero(norm > 1e-12)
    if moving.size == 0:
        return np.zeros(r.shape[0])
    # Index of the direction each sample uses: its own, else the last one before it, else
    # (before any motion) the first one.
    src = np.full(r.shape[0], -1)
    src[moving] = moving
    src = np.maximum.accumulate(src)
    src[src < 0] = moving[0]
    t_hat = tangent[src] / norm[src, None]
    return np.einsum("ij,ij->i", u - r, t_hat)


def limit_to_path(compensated_mm: np.ndarray, foot_mm: np.ndarray,
                  tolerance_mm: float) -> np.ndarray:  # fmt: skip
    """Keep a compensated reference within ``tolerance_mm`` of the path.

    ``foot_mm`` (M, k) a point *of the path* for each compensated point u_k (the caller's: the
    path point :func:`along_path_offset_mm` ahead of the planned point). The residual
    e = u − foot is scaled down to length ``tolerance_mm`` where longer:
    u' = foot + e·min(1, tol/|e|), so the distance from u' to the path is at most
    ``tolerance_mm`` by construction. The tool then follows the path only as far as the
    limited reference lets it: the dynamics check, which simulates the limited reference,
    slows down where that is not within ε_max. ``tolerance_mm`` inf: u unchanged.
    """
    u = np.asarray(compensated_mm, dtype=float)
    if not np.isfinite(tolerance_mm):
        return u
    foot = np.asarray(foot_mm, dtype=float)
    e = u - foot
    size = np.sqrt(np.einsum("ij,ij->i", e, e))
    scale = np.minimum(1.0, tolerance_mm / np.where(size > 0.0, size, 1.0))
    return foot + e * scale[:, None]
