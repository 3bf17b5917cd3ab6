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
- End: after the planned motion stops, F's slowest modes (the stable zeros of H, the
  controller's near pole-zero cancellations: 0.91 and 0.86 per sample on the paper's axes,
  time constants 11 and 7 ms) would keep moving the compensated reference for tens of
  milliseconds (40 ms until within 0.1 µm on the 9 mm airfoil: the reference stays up to
  10 µm back along the path to hold the tool while the servo's integrator discharges), and
  every sample of that tail is motion time. Instead the compensated reference ends with the
  planned motion (no sample is added): the remaining offset d = r_end − u_end is blended in
  over the last W samples by the quintic smooth step s(x) = x³(10 − 15x + 6x²), s = 1 at the
  last sample (exactly the programmed end point), W the shortest blend whose own
  acceleration and jerk are within the machine's (:func:`end_blend_samples`). The tool then
  overshoots the end point by about the servo's response to d (6–9 µm after a 10 µm
  offset), which the dynamics check simulates like any other error.
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
from nurbscnc.machine.profile import Machine
from nurbscnc.servo.model import AxisModel, DiscreteAxis, as_model, discretise

#: Largest acceleration and jerk of the quintic smooth step s(x) = x³(10 − 15x + 6x²) on
#: x ∈ [0, 1] for a unit step: max |s″| = 10/√3, max |s‴| = 60 (the end blend).
SMOOTH_STEP_ACCEL = 10.0 / np.sqrt(3.0)
SMOOTH_STEP_JERK = 60.0
#: Default largest distance of a pre-compensated reference from the path [mm] (3 µm,
#: :func:`limit_to_path`): if the model is wrong, the reference itself is never far
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
    return InverseFilter(
        num=a,
        den=b_s,
        ahead=ahead,
        lead_samples=delay + unstable.size,
        unstable_zeros=unstable,
        slowest_pole=slowest,
    )


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
    """A pre-compensated reference: ``points_mm`` (N + ``lead_samples``, k) [mm]: the start
    held ``lead_samples`` periods (pre-actuation), then the compensated motion, ending with
    the planned motion at the programmed end point. Sample k + ``lead_samples`` belongs to
    planned sample k. ``end_step_mm`` |d|, the offset of F's tail blended in at the end over
    the last ``end_blend_samples`` periods (module docstring)."""

    points_mm: np.ndarray
    lead_samples: int
    end_step_mm: float = 0.0
    end_blend_samples: int = 0

    @property
    def tail_samples(self) -> int:
        """Periods appended after the planned stop: none (F's tail is blended in)."""
        return 0


def smooth_step(x) -> np.ndarray:
    """The quintic smooth step s(x) = x³(10 − 15x + 6x²): s(0) = 0, s(1) = 1, first and
    second derivatives zero at both ends."""
    x = np.asarray(x, dtype=float)
    return x**3 * (10.0 - 15.0 * x + 6.0 * x * x)


def end_blend_samples(
    step_mm: float, period_s: float, a_max_mm_s2: float = np.inf, j_max_mm_s3: float = np.inf
) -> int:
    """Samples W (≥ 1) of the end blend of a step ``step_mm`` [mm]: the fewest with the
    smooth step's own acceleration 5.774·step/(W·T)² ≤ ``a_max_mm_s2`` and jerk
    60·step/(W·T)³ ≤ ``j_max_mm_s3`` (T = ``period_s``; module docstring)."""
    t_a = np.sqrt(SMOOTH_STEP_ACCEL * step_mm / a_max_mm_s2)
    t_j = np.cbrt(SMOOTH_STEP_JERK * step_mm / j_max_mm_s3)
    return max(1, int(np.ceil(max(t_a, t_j) / period_s - 1e-9)))


def precompensate_points(
    models: Sequence[AxisModel | None],
    points_mm: np.ndarray,
    period_s: float,
    hold: str = "foh",
    a_max_mm_s2: float = np.inf,
    j_max_mm_s3: float = np.inf,
) -> Compensated:
    """Pre-compensate the reference ``points_mm`` (N, k) [mm] for the axis ``models`` (one per
    column; None an ideal axis, left as is) by ZPETC (module docstring, Tomizuka 1987).

    The planned points start and end at rest. The result starts at rest at the first point
    (held ``lead_samples`` periods, the largest look-ahead of any axis), follows u = F r, and
    ends with the planned motion exactly at the last point, F's tail blended in over the
    last samples within ``a_max_mm_s2`` [mm/s²] and ``j_max_mm_s3`` [mm/s³]
    (:func:`end_blend_samples`; inf: a jump in the last period).
    """
    r = np.asarray(points_mm, dtype=float)
    if r.ndim != 2 or r.shape[1] != len(models) or r.shape[0] == 0:
        raise ValueError("points_mm must be (N, k) with k = len(models), N >= 1")
    inverses = [
        None if m is None else zpetc(discretise(as_model(m), period_s, hold)) for m in models
    ]
    present = [f for f in inverses if f is not None]
    if not present:
        raise ConfigError("pre-compensation needs a servo model for at least one axis")
    lead = max(f.lead_samples for f in present)
    n = r.shape[0]
    # The planned points held `lead` periods at the start (the pre-actuation) and at the end
    # (what F looks ahead of the last one).
    ext = np.concatenate([np.repeat(r[:1], lead, axis=0), r, np.repeat(r[-1:], lead, axis=0)])
    u = ext.copy()
    for j, f in enumerate(inverses):
        if f is not None:
            u[:, j] = _compensate(f, ext[:, j], lead)
    u = u[: lead + n]
    u[0] = r[0]  # exact already (u_0 looks at most to the planned first point, at rest)
    d = r[-1] - u[-1]
    step = float(np.sqrt(d @ d))
    w = min(end_blend_samples(step, period_s, a_max_mm_s2, j_max_mm_s3), u.shape[0] - 1)
    if step > 0.0 and w >= 1:
        u[-w:] += smooth_step(np.arange(1, w + 1) / w)[:, None] * d
    u[-1] = r[-1]
    return Compensated(
        points_mm=u, lead_samples=lead, end_step_mm=step, end_blend_samples=w if step > 0.0 else 0
    )


def perturbed_model(model: AxisModel, loop_gain: float = 1.0, bandwidth: float = 1.0) -> AxisModel:
    """A model error of G = N/D for the sensitivity of a pre-compensated reference.

    ``loop_gain`` k: the open loop L = G/(1 − G) = N/(D − N) (a unity-feedback reading of the
    closed loop) scaled by k, G' = kN/(D + (k − 1)N): the closed-loop poles move, the zeros
    (the controller's) stay, G'(0) = G(0) when a0 = b0, and the velocity lag c_1 = (a1 − b1)/a0
    becomes c_1/k (a plant gain or inertia off by 1/k). ``bandwidth`` λ: G'(s) = G(s/λ), every
    pole and zero times λ (a loop λ times faster), c_1/λ, G'(0) = G(0)."""
    model = as_model(model)
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


def limit_to_path(compensated_mm: np.ndarray, foot_mm: np.ndarray, tolerance_mm) -> np.ndarray:
    """Keep a compensated reference within ``tolerance_mm`` of the path.

    ``foot_mm`` (M, k) a point *of the path* for each compensated point u_k (the caller's: the
    path point :func:`along_path_offset_mm` ahead of the planned point). The residual
    e = u − foot is scaled down to length ``tolerance_mm`` (a scalar or (M,) per point)
    where longer: u' = foot + e·min(1, tol/|e|), the point of the ball of radius tol about
    the foot nearest to u (the Euclidean projection onto it), so the distance from u' to
    the path is at most ``tolerance_mm`` by construction. The tool then follows the path
    only as far as the limited reference lets it: the dynamics check, which simulates the
    limited reference, slows down where that is not within ε_max. ``tolerance_mm`` inf: u
    unchanged.
    """
    u = np.asarray(compensated_mm, dtype=float)
    tol = np.asarray(tolerance_mm, dtype=float)
    if not np.any(np.isfinite(tol)):
        return u
    foot = np.asarray(foot_mm, dtype=float)
    e = u - foot
    size = np.sqrt(np.einsum("ij,ij->i", e, e))
    scale = np.minimum(1.0, tol / np.where(size > 0.0, size, 1.0))
    return foot + e * scale[:, None]


def axis_models(machine: Machine) -> list:
    """The servo models of ``machine``'s axes x, y, z (None: an axis without one), in the
    column order of the reference's points."""
    servo = machine.servo
    return [servo.x, servo.y, servo.z]


def lead_samples(machine: Machine) -> int:
    """The pre-actuation of the ZPETC inverse (:func:`zpetc`) for ``machine``: the largest
    look-ahead n_u + d of its axes [samples] (FOH models at the servo period)."""
    period = machine.servo.period_s
    return max(
        zpetc(discretise(as_model(m), period, "foh")).lead_samples
        for m in axis_models(machine)
        if m is not None
    )
