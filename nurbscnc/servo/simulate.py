"""Independent servo simulation of a reference-point stream (SPEC §8, eq. 25-29).

This is the check the ``simulate`` and ``compare`` commands run on a plan's output. It uses the
same model as the planner's own servo check (:mod:`nurbscnc.servo.model`: per axis G(s) of SPEC
eq. 25, first-order-hold input, exact at the samples) but shares none of its simulation code: the
state space is built here, and the response is a convolution, not an IIR recurrence.

Model. G(s) = (b2 s² + b1 s + b0) / (a4 s⁴ + a3 s³ + a2 s² + a1 s + a0) in controllable
canonical form on the frequency-scaled state w_i = z^(i) / ω_n^i (z the canonical "phase"
variable, D(d/dt) z = u, y = N(d/dt) z, ω_n = (a0/a4)^(1/4)): the diagonal scaling keeps every
entry of A near 1 (Table 2's a0 ≈ 2e9 would otherwise sit beside a4 = 1), which keeps expm
accurate; it is a similarity transform, so the input-output map is unchanged.

First-order hold (FOH). Between samples k and k+1 the reference is linear,
u(kT + τ) = u_k + Δ_k τ/T with Δ_k = u_{k+1} − u_k. Append u and Δ to the state:
d/dt [x; u; Δ] = M [x; u; Δ] with M = [[A, B, 0], [0, 0, 1/T], [0, 0, 0]], so over one period

    expm(M T) = [[Φ, Γ1, Γ2], [0, 1, 1], [0, 0, 1]],
    Φ = e^{AT},  Γ1 = ∫₀ᵀ e^{Aσ} B dσ,  Γ2 = ∫₀ᵀ e^{A(T−σ)} B σ/T dσ,

    x_{k+1} = Φ x_k + Γ1 u_k + Γ2 (u_{k+1} − u_k)                    (exact for linear u).

A zero-order hold (staircase u) is the same with Γ2 = 0.

Response by convolution. The system is linear and time-invariant in the sample sequence, so
the output is fixed by one kernel. Let g_m (m ≥ 1) be the output m periods after the model,
at rest with input 1, sees its input ramp 1 → 0 over the first period: x_1 = Φ x_eq + Γ1 − Γ2,
x_{m+1} = Φ x_m, g_m = C x_m, with x_eq = −A⁻¹B. Equivalently g_m = K − s_m with s the step
response and K = G(0): g is the running complement of the discrete impulse response h
(h_0 = g_0 − g_1 with g_0 = K, h_m = g_m − g_{m+1}), and it decays like h. An input increment
Δr_j = r_j − r_{j−1} (ramped over period j−1 → j) then contributes −g_{k−j+1} Δr_j at sample
k ≥ j, and summing from the machine at rest at r_0 (equilibrium output K r_0):

    y_k = K r_k − Σ_{j ≤ k} g_{k−j+1} Δr_j,
    axis error E_k = r_k − y_k = (1 − K) r_k + (g ⋆ Δr)_k.

The kernel is cut where |g| and |h| fall below 1e-16 of their peaks (the dropped tail is below
double rounding: |tail| ≤ 1e-16·max|g| / (1 − e^{−|Re p|T}), ~1e-15 relative for Table 2), and
the convolution is :func:`scipy.signal.oaconvolve` (overlap-add FFT, O(N log L)). Convolving
with the small increments, not the positions, keeps the rounding relative to the step size, so
the error is accurate to ~1e-15 mm whatever the coordinates. The full convolution also gives the
tail after the last reference sample (Δr = 0 there): the reference is held and samples are
appended until every axis stays within SETTLE_TOLERANCE_MM of its final value.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import linalg, signal

from nurbscnc.errors import ConfigError
from nurbscnc.machine.profile import AXES, AxisServo, Machine
from nurbscnc.servo.model import contour_error_eq29, contour_error_true

#: Settling tolerance: the simulation ends when every axis is this close to rest [mm].
SETTLE_TOLERANCE_MM = 1e-6
#: Relative cut-off of the convolution kernel (below double rounding).
KERNEL_CUTOFF = 1e-16
_HOLDS = ("foh", "zoh")
_MAX_KERNEL = 50_000_000  # samples; a slower model than this is not a servo of this period


# ---------------------------------------------------------------------------------------------
# Discretisation.


def _canonical(axis: AxisServo) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(A, B, C, ω_n): frequency-scaled controllable canonical form of SPEC eq. 25."""
    a = np.array([axis.a0, axis.a1, axis.a2, axis.a3]) / axis.a4  # monic denominator
    b = np.array([axis.b0, axis.b1, axis.b2, 0.0]) / axis.a4
    if not (a[0] > 0 and np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        raise ConfigError("servo model: a0/a4 must be > 0 and all coefficients finite")
    wn = a[0] ** 0.25
    scale = wn ** np.arange(4)  # w_i = z^(i) / wn^i
    # z'''' = u − Σ a_i z^(i)  →  w_3' = (u − Σ a_i wn^i w_i) / wn^3;  w_i' = wn w_{i+1}.
    A = np.zeros((4, 4))
    A[np.arange(3), np.arange(1, 4)] = wn
    A[3, :] = -a * scale / wn**3
    B = np.zeros((4, 1))
    B[3, 0] = 1.0 / wn**3
    C = (b * scale)[None, :]  # y = Σ b_i z^(i) = Σ b_i wn^i w_i
    return A, B, C, wn


@dataclass(frozen=True, eq=False)
class DiscreteServo:
    """One axis sampled exactly: x_{k+1} = Φ x_k + Γ1 u_k + Γ2 (u_{k+1} − u_k), y = C x.

    ``x_eq`` is the state at rest with input 1 (y = ``dc_gain``); ``period_s`` T [s].
    """

    phi: np.ndarray
    gamma1: np.ndarray
    gamma2: np.ndarray
    c: np.ndarray
    x_eq: np.ndarray
    dc_gain: float
    period_s: float
    hold: str
    slowest_rate_per_s: float  #: min |Re p| over the poles [1/s]


def foh_state_space(axis: AxisServo, period_s: float, hold: str = "foh") -> DiscreteServo:
    """Exact sampled state space of ``axis`` at period ``period_s`` [s] (module docstring).

    expm of the augmented matrix [[A, B, 0], [0, 0, I/T], [0, 0, 0]]·T gives Φ, Γ1, Γ2;
    ``hold="zoh"`` sets Γ2 = 0 (staircase input).
    """
    if hold not in _HOLDS:
        raise ConfigError(f"hold must be one of {', '.join(_HOLDS)}, got {hold!r}")
    if not (np.isfinite(period_s) and period_s > 0):
        raise ConfigError(f"servo period must be > 0, got {period_s!r}")
    A, B, C, _ = _canonical(axis)
    poles = np.linalg.eigvals(A)
    if np.any(poles.real >= 0.0):
        raise ConfigError(f"servo model: unstable, poles {poles}")
    n = A.shape[0]
    M = np.zeros((n + 2, n + 2))
    M[:n, :n] = A
    M[:n, n : n + 1] = B
    M[n, n + 1] = 1.0 / period_s
    E = linalg.expm(M * period_s)
    phi, g1, g2 = E[:n, :n], E[:n, n], E[:n, n + 1]
    if hold == "zoh":
        g2 = np.zeros_like(g2)
    x_eq = -np.linalg.solve(A, B[:, 0])
    return DiscreteServo(
        phi=phi,
        gamma1=g1,
        gamma2=g2,
        c=C[0],
        x_eq=x_eq,
        dc_gain=float(axis.b0 / axis.a0),
        period_s=float(period_s),
        hold=hold,
        slowest_rate_per_s=float(np.min(-poles.real)),
    )


def _orbit(phi: np.ndarray, x1: np.ndarray, length: int) -> np.ndarray:
    """Rows x1, Φ x1, Φ² x1, … (``length`` rows), by doubling: log2(length) matrix products."""
    X = x1[None, :]
    P = phi
    while X.shape[0] < length:
        X = np.vstack([X, X @ P.T])  # [x_0..x_{n-1}] then [Φⁿ x_0 .. Φⁿ x_{n-1}]
        P = P @ P
    return X[:length]


def error_kernel(disc: DiscreteServo) -> np.ndarray:
    """g_1, g_2, … (module docstring), cut where |g| and |h| < KERNEL_CUTOFF·peak [1]."""
    x1 = disc.phi @ disc.x_eq + disc.gamma1 - disc.gamma2
    # e^{-40} ≈ 4e-18 < KERNEL_CUTOFF: a first window long enough for the slowest pole.
    length = int(np.clip(np.ceil(40.0 / (disc.slowest_rate_per_s * disc.period_s)), 8, None))
    while True:
        g = _orbit(disc.phi, x1, length) @ disc.c
        h = -np.diff(np.concatenate([[disc.dc_gain], g]))  # h_0 .. h_{L-1}
        big = (np.abs(g) >= KERNEL_CUTOFF * np.max(np.abs(g))) | (
            np.abs(h) >= KERNEL_CUTOFF * np.max(np.abs(h))
        )
        last = int(np.nonzero(big)[0][-1]) if big.any() else 0
        if last < length - 1:
            return g[: last + 1]
        if length >= _MAX_KERNEL:
            raise ConfigError(f"servo model does not decay within {_MAX_KERNEL} periods")
        length *= 2


# ---------------------------------------------------------------------------------------------
# Simulation.


@dataclass(frozen=True, eq=False)
class Simulation:
    """Result of :func:`simulate_reference`: M ≥ N samples at t = k·T.

    ``reference_mm`` is the input held at its last point over the appended settling samples;
    ``axis_error_mm`` = reference − actual per axis (SPEC eq. 26), all (M, 3) [mm].
    ``n_reference`` is N, the number of input samples; ``period_s`` T; ``hold`` the input hold.
    """

    t_s: np.ndarray
    reference_mm: np.ndarray
    actual_mm: np.ndarray
    axis_error_mm: np.ndarray
    n_reference: int
    period_s: float
    hold: str


def _axis_error(disc: DiscreteServo, r: np.ndarray) -> np.ndarray:
    """(1 − K) r + g ⋆ Δr over the N samples and the whole decaying tail (N + L − 1 values)."""
    g = error_kernel(disc)
    dr = np.diff(r, prepend=r[0])  # Δr_0 = 0: at rest at r_0
    e = signal.oaconvolve(dr, g, mode="full") if r.size > 1 else np.zeros(g.size)
    if disc.dc_gain != 1.0:
        e = e + (1.0 - disc.dc_gain) * np.concatenate([r, np.full(e.size - r.size, r[-1])])
    return e


def simulate_reference(points_mm, machine: Machine, hold: str = "foh") -> Simulation:
    """Simulate the machine's servo axes on reference points (N, 3) [mm], one per period.

    Each axis starts at rest at the first point; the reference is linear between samples
    (``hold="foh"``, SPEC §8) or a staircase (``"zoh"``). After the last point the reference is
    held and samples are appended until every axis is within SETTLE_TOLERANCE_MM of its final
    value. An axis without a model (``machine.servo.z`` None) follows its reference exactly.
    Exact at the samples up to rounding (module docstring); cost O(N log N).
    """
    r = np.asarray(points_mm, dtype=float)
    if r.ndim != 2 or r.shape[1] != 3 or r.shape[0] == 0:
        raise ConfigError(f"reference points must be an (N, 3) array with N >= 1, got {r.shape}")
    if not np.all(np.isfinite(r)):
        raise ConfigError("reference points must be finite")
    period_s = machine.servo.period_s
    n = r.shape[0]
    # Per modelled axis: its error over the inputs and the decaying tail, and its final value.
    runs: list[tuple[int, np.ndarray, float]] = []
    for j, name in enumerate(AXES):
        axis = machine.servo.axis(name)
        if axis is not None:
            disc = foh_state_space(axis, period_s, hold)
            runs.append((j, _axis_error(disc, r[:, j]), (1.0 - disc.dc_gain) * r[-1, j]))
    # Settled: one past the last sample whose deviation from the final value exceeds the
    # tolerance (the tail decays, and past the kernel it is the final value to rounding).
    m = n
    for _, e, final in runs:
        bad = np.nonzero(np.abs(e - final) > SETTLE_TOLERANCE_MM)[0]
        if bad.size:
            m = max(m, int(bad[-1]) + 2)
    ref = np.concatenate([r, np.repeat(r[-1:], m - n, axis=0)])
    err = np.zeros((m, 3))
    for j, e, final in runs:
        take = min(m, e.size)
        err[:take, j] = e[:take]
        err[take:, j] = final
    for a in (ref, err):
        a.setflags(write=False)
    act = ref - err
    act.setflags(write=False)
    t = np.arange(m) * period_s
    t.setflags(write=False)
    return Simulation(
        t_s=t,
        reference_mm=ref,
        actual_mm=act,
        axis_error_mm=err,
        n_reference=n,
        period_s=period_s,
        hold=hold,
    )


# ---------------------------------------------------------------------------------------------
# Errors and their summary.


@dataclass(frozen=True, eq=False)
class ContourErrors:
    """Per-sample contour errors of a :class:`Simulation` (M,).

    ``eq29_mm``: ε = −E_x sin φ + E_y cos φ (SPEC eq. 29), signed [mm]; ``phi_rad``: φ, the
    tangent angle of the reference path; ``true_mm``: distance of the actual point to the
    commanded path [mm] (≥ 0).
    """

    eq29_mm: np.ndarray
    true_mm: np.ndarray
    phi_rad: np.ndarray


def tangent_angle_rad(reference_mm) -> np.ndarray:
    """φ_k [rad] of the XY reference path (M, ≥2) by central differences (one-sided at ends).

    Where the reference does not move (zero difference: a stop, the held settling tail) the
    angle of the nearest earlier moving sample is kept (the nearest later one before the first
    move); a path that never moves gets φ = 0.
    """
    r = np.asarray(reference_mm, dtype=float)
    if r.shape[0] < 2:
        return np.zeros(r.shape[0])
    dx = np.gradient(r[:, 0])
    dy = np.gradient(r[:, 1])
    moving = (dx != 0.0) | (dy != 0.0)
    phi = np.arctan2(dy, dx)
    if not moving.any():
        return np.zeros(r.shape[0])
    idx = np.where(moving, np.arange(r.shape[0]), -1)
    idx = np.maximum.accumulate(idx)  # forward fill: last moving index so far
    idx[idx < 0] = int(np.argmax(moving))  # before the first move: the first moving sample
    return phi[idx]


def contour_errors(sim: Simulation, path_mm=None) -> ContourErrors:
    """Contour errors of ``sim`` against the commanded path ``path_mm`` (P, 2|3) [mm].

    eq. 29 uses the XY axis errors and φ from :func:`tangent_angle_rad`. The true error is the
    exact distance from each actual point to the polyline ``path_mm`` in its dimensions (XY for
    (P, 2), XYZ for (P, 3)); ``path_mm`` None uses the reference points themselves (chords of
    the curve, within the chord tolerance of it).
    """
    phi = tangent_angle_rad(sim.reference_mm)
    eq29 = contour_error_eq29(sim.axis_error_mm[:, 0], sim.axis_error_mm[:, 1], phi)
    path = sim.reference_mm[: sim.n_reference] if path_mm is None else path_mm
    path = np.asarray(path, dtype=float)
    if path.ndim != 2 or path.shape[1] not in (2, 3) or path.shape[0] == 0:
        raise ConfigError(f"commanded path must be (P, 2) or (P, 3), got {path.shape}")
    true = contour_error_true(sim.actual_mm[:, : path.shape[1]], path)
    return ContourErrors(eq29_mm=np.atleast_1d(eq29), true_mm=true, phi_rad=phi)


@dataclass(frozen=True)
class Metrics:
    """Summary of a simulation (the paper's Table 4 columns) [µm, s].

    ``contour_*`` are |ε| of SPEC eq. 29 (the paper's measure), ``true_*`` the distance to the
    commanded path; axis errors are |reference − actual| per axis. ``cycle_time_s`` is the time
    of the last reference sample that moves; ``settle_time_s`` the time of the last simulated
    sample (every axis within SETTLE_TOLERANCE_MM of rest).
    """

    axis_x_max_um: float
    axis_x_rms_um: float
    axis_y_max_um: float
    axis_y_rms_um: float
    contour_max_um: float
    contour_rms_um: float
    contour_mean_um: float
    true_max_um: float
    true_rms_um: float
    true_mean_um: float
    cycle_time_s: float
    settle_time_s: float

    def as_dict(self) -> dict[str, float]:
        """Plain floats by field name (for JSON)."""
        return {k: float(v) for k, v in self.__dict__.items()}


def cycle_time_s(sim: Simulation) -> float:
    """Time [s] of the last reference sample that differs from the one before (0: no motion)."""
    moved = np.any(np.diff(sim.reference_mm, axis=0) != 0.0, axis=1)
    return float(sim.t_s[int(np.nonzero(moved)[0][-1]) + 1]) if moved.any() else 0.0


def _um(values_mm: np.ndarray) -> tuple[float, float, float]:
    a = np.abs(values_mm) * 1e3
    return float(a.max()), float(np.sqrt(np.mean(a * a))), float(a.mean())


def metrics(sim: Simulation, path_mm=None, contour: ContourErrors | None = None) -> Metrics:
    """Max / RMS / mean errors [µm] and cycle time [s] of ``sim`` (see :class:`Metrics`).

    ``contour`` (from :func:`contour_errors`) is computed against ``path_mm`` when not given.
    """
    ce = contour_errors(sim, path_mm) if contour is None else contour
    ex, ey = _um(sim.axis_error_mm[:, 0]), _um(sim.axis_error_mm[:, 1])
    c, d = _um(ce.eq29_mm), _um(ce.true_mm)
    return Metrics(
        axis_x_max_um=ex[0],
        axis_x_rms_um=ex[1],
        axis_y_max_um=ey[0],
        axis_y_rms_um=ey[1],
        contour_max_um=c[0],
        contour_rms_um=c[1],
        contour_mean_um=c[2],
        true_max_um=d[0],
        true_rms_um=d[1],
        true_mean_um=d[2],
        cycle_time_s=cycle_time_s(sim),
        settle_time_s=float(sim.t_s[-1]),
    )
