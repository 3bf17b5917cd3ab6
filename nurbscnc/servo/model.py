"""Servo model: what the machine actually does with the reference points (SPEC §8, eq. 25-29).

Each axis is the closed-loop position model of SPEC eq. 25,
G(s) = (b2 s² + b1 s + b0) / (a4 s⁴ + a3 s³ + a2 s² + a1 s + a0), driven by one reference point
per servo period T_s.

Discretisation. Between samples the reference is taken as piecewise linear (first-order hold,
FOH: a pulse-train card spreads a period's pulses over the period), so the sampled response is
computed exactly, not approximated: with (A, B, C, D) a state-space form of G and

    expm([[A·T, B·T, 0], [0, 0, 1], [0, 0, 0]]) = [[Φ, Γ1, Γ2], [0, 1, 1], [0, 0, 1]],

x_{k+1} = Φ x_k + Γ1 u_k + Γ2 (u_{k+1} − u_k) holds exactly for an input linear on the period.
The substitution ξ_k = x_k − Γ2 u_k makes this causal, ξ_{k+1} = Φ ξ_k + (Γ1 + ΦΓ2 − Γ2) u_k,
y_k = C ξ_k + (D + CΓ2) u_k, whose transfer function H(z) (built once per model) is applied by
scipy's compiled IIR recurrence (the one behind ``scipy.signal.lfilter``, :func:`_lfilter`):
the per-sample work is one compiled loop, no Python loop.
A zero-order hold (staircase input; Φ, Γ1 alone) is available for comparison; it lags T_s/2 more.

The machine starts at rest at the first reference point: the filter runs on r − r_0 from a zero
state and the equilibrium G(0)·r_0 is added back.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from nurbscnc.errors import ConfigError
from nurbscnc.machine.profile import AxisServo

#: Settling tolerance of ``simulate_axis(..., settle=True)`` [mm].
SETTLE_TOLERANCE_MM = 1e-6
#: Longest tail ``settle=True`` may append before declaring the model unusable [samples].
_MAX_SETTLE_SAMPLES = 10_000_000
_HOLDS = ("foh", "zoh")


@dataclass(frozen=True)
class AxisModel:
    """A stable, proper continuous transfer function num(s)/den(s) (coefficients highest first).

    For SPEC eq. 25: ``numerator = (b2, b1, b0)``, ``denominator = (a4, a3, a2, a1, a0)``.
    """

    numerator: tuple[float, ...]
    denominator: tuple[float, ...]

    def __post_init__(self):
        num = np.trim_zeros(np.asarray(self.numerator, dtype=float), "f")
        den = np.trim_zeros(np.asarray(self.denominator, dtype=float), "f")
        if den.size < 2 or not np.all(np.isfinite(den)) or not np.all(np.isfinite(num)):
            raise ConfigError("servo model: denominator must have degree >= 1, finite values")
        if num.size > den.size:
            raise ConfigError("servo model: numerator degree exceeds denominator degree")
        if np.any(np.roots(den).real >= 0.0):
            raise ConfigError(f"servo model: unstable, poles {np.roots(den)}")

    @classmethod
    def from_servo(cls, axis: AxisServo) -> AxisModel:
        """The model of one profile axis (SPEC eq. 25, Table 2)."""
        return cls(tuple(axis.numerator), tuple(axis.denominator))

    def poles(self) -> np.ndarray:
        """Closed-loop poles [1/s]."""
        return np.roots(np.trim_zeros(np.asarray(self.denominator, dtype=float), "f"))

    @property
    def dc_gain(self) -> float:
        """G(0): ratio of the constant coefficients."""
        return float(self.numerator[-1] / self.denominator[-1])


@dataclass(frozen=True, eq=False)
class DiscreteAxis:
    """The exact sampled equivalent of an :class:`AxisModel`: H(z) for ``lfilter``.

    ``b``, ``a`` in powers of z⁻¹ (a[0] = 1); ``dc_gain`` the continuous G(0), used for the
    equilibrium at the starting point.
    """

    b: np.ndarray
    a: np.ndarray
    period_s: float
    hold: str
    dc_gain: float


def as_model(model) -> AxisModel:
    """``model`` as an :class:`AxisModel` (SPEC eq. 25): itself, or the model of an
    :class:`~nurbscnc.machine.profile.AxisServo`'s coefficients; TypeError for anything else."""
    if isinstance(model, AxisModel):
        return model
    if isinstance(model, AxisServo):
        return AxisModel.from_servo(model)
    raise TypeError(f"expected AxisModel or AxisServo, got {type(model).__name__}")


@functools.cache
def _linear_filter():
    """The compiled direct-form-II-transposed IIR loop of ``scipy.signal.lfilter``, called as
    f(b, a, x, axis, zi) → (y, zf).

    Importing ``scipy.signal`` costs 1–3 s of CPU (it pulls in scipy.stats, optimize,
    spatial, …) for one loop that takes milliseconds, so its extension module
    ``scipy/signal/_sigtools`` is loaded on its own (:func:`nurbscnc.scipy_ext.extension`;
    it needs numpy only): the same code, the same bits as ``lfilter``. A numpy replacement
    was measured and rejected: a banded triangular solve (BLAS ``dtbsv``) of the
    same recurrence is 27× slower and, being direct form I, differs by 4e-11 mm on a 100 mm
    signal — as much as lfilter's own rounding (3e-11 mm against the recurrence in extended
    precision), so no other arithmetic agrees with it to 1e-12 mm. Falls back to
    ``scipy.signal.lfilter`` where the module is not found.
    """
    from nurbscnc.scipy_ext import extension

    module = extension("signal", "_sigtools")
    if module is not None:
        return module._linear_filter
    from scipy.signal import lfilter  # pragma: no cover (another scipy layout)

    return lambda b, a, x, axis, zi: lfilter(b, a, x, axis=axis, zi=zi)  # pragma: no cover


def _lfilter(b: np.ndarray, a: np.ndarray, x: np.ndarray, zi: np.ndarray):
    """``scipy.signal.lfilter(b, a, x, zi=zi)`` for 1-D float arrays, a[0] = 1: (y, zf)."""
    return _linear_filter()(b, a, np.ascontiguousarray(x, dtype=float), -1, zi)


def _tf2ss(num, den):
    """Controllable canonical state space (A (n, n), B (n, 1), C (1, n), D (1, 1)) of the
    continuous num(s)/den(s), the arithmetic of ``scipy.signal.tf2ss`` (the tests compare the
    discretisation with scipy.signal's)."""
    den = np.trim_zeros(np.asarray(den, dtype=float), "f")
    num = np.atleast_1d(np.asarray(num, dtype=float))
    num, den = num / den[0], den / den[0]
    lead = 0  # leading numerator coefficients that are zero (|c| ≤ 1e-14, as scipy)
    while lead < num.size - 1 and abs(num[lead]) <= 1e-14:
        lead += 1
    num = num[lead:]
    k = den.size
    num = np.concatenate((np.zeros(k - num.size), num))[None, :]
    A = np.r_[-np.array([den[1:]]), np.eye(k - 2, k - 1)]
    B = np.eye(k - 1, 1)
    C = num[:, 1:] - np.outer(num[:, 0], den[1:])
    D = num[:, :1]
    return A, B, C, D


def _ss2tf(A, B, C, D):
    """Numerator and denominator (powers of z⁻¹ for a discrete system) of the single-input,
    single-output (A, B, C, D), the arithmetic of ``scipy.signal.ss2tf``:
    den = det(zI − A), num = det(zI − A + BC) + (D − 1)·den."""
    den = np.poly(A)
    num = np.poly(A - np.dot(B, C)) + (D[0] - 1) * den
    return num, den


def _balance(m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(D⁻¹ M D, d) with D = diag(d) of powers of 2 that make each row and column of the
    result alike in size (Parlett & Reinsch's balancing, as LAPACK's gebal; powers of 2: no
    rounding). The companion matrix of eq. 25 times T spans 1e-3 … 2e6; balanced, its norm
    is that of its eigenvalues times T (≲ 1)."""
    b = np.array(m, dtype=float)
    d = np.ones(b.shape[0])
    for _ in range(64):
        done = True
        for i in range(b.shape[0]):
            c = float(np.abs(b[:, i]).sum() - abs(b[i, i]))
            r = float(np.abs(b[i, :]).sum() - abs(b[i, i]))
            if c == 0.0 or r == 0.0:
                continue
            f, total = 1.0, c + r
            while c < r / 2.0:
                c, r, f = c * 2.0, r / 2.0, f * 2.0
            while c >= r * 2.0:
                c, r, f = c / 2.0, r * 2.0, f / 2.0
            if c + r < 0.95 * total:
                done = False
                d[i] *= f
                b[:, i] *= f
                b[i, :] /= f
        if done:
            break
    return b, d


def expm_small(m: np.ndarray) -> np.ndarray:
    """e^M of a small square matrix (the discretisation's augmented 6 × 6 one), numpy only.

    Balanced first (:func:`_balance`: e^M = D e^(D⁻¹MD) D⁻¹), then scaling and squaring:
    X = B/2^s with ‖X‖∞ ≤ 1/8, the Taylor series of e^X to degree 20 (its remainder below
    (1/8)²¹/21! ≈ 1e-38), squared s times. On eq. 25's models at T = 1 ms it agrees with a
    40-digit evaluation (mpmath) to 1e-15 relative, where scipy.linalg.expm (Padé 13, no
    balancing) is 7e-12 off. Written here because importing scipy.linalg costs 0.1 s of
    every ``run`` and ``plan`` (import what a command needs) for one 6 × 6
    exponential; the tests compare it with scipy.linalg.expm."""
    b, d = _balance(m)
    norm = float(np.abs(b).sum(axis=1).max())
    s = max(0, int(np.ceil(np.log2(norm / 0.125)))) if norm > 0.125 else 0
    x = b / 2.0**s
    eye = np.eye(b.shape[0])
    e = eye
    for k in range(20, 0, -1):  # Horner: I + X/1 (I + X/2 (… (I + X/20)))
        e = eye + (x @ e) / k
    for _ in range(s):
        e = e @ e
    return e * d[:, None] / d[None, :]


def discretise(model: AxisModel | AxisServo, period_s: float, hold: str = "foh") -> DiscreteAxis:
    """Exact discretisation of ``model`` at ``period_s`` [s] for a FOH or ZOH input.

    See the module docstring for the augmented-matrix construction (Franklin, Powell &
    Workman, "Digital Control of Dynamic Systems", §6.3.2 for the FOH equivalent).
    """
    model = as_model(model)
    if hold not in _HOLDS:
        raise ValueError(f"hold must be one of {_HOLDS}, got {hold!r}")
    if not (np.isfinite(period_s) and period_s > 0):
        raise ConfigError(f"servo period must be > 0, got {period_s!r}")
    A, B, C, D = _tf2ss(model.numerator, model.denominator)
    n = A.shape[0]
    if hold == "zoh":
        M = np.zeros((n + 1, n + 1))
        M[:n, :n] = A * period_s
        M[:n, n:] = B * period_s
        E = expm_small(M)
        Ad, Bd, Cd, Dd = E[:n, :n], E[:n, n:], C, D
    else:
        M = np.zeros((n + 2, n + 2))
        M[:n, :n] = A * period_s
        M[:n, n : n + 1] = B * period_s
        M[n, n + 1] = 1.0  # the input's increment over one period, (u_{k+1} − u_k)
        E = expm_small(M)
        phi, g1, g2 = E[:n, :n], E[:n, n : n + 1], E[:n, n + 1 : n + 2]
        Ad, Bd = phi, g1 + phi @ g2 - g2
        Cd, Dd = C, D + C @ g2
    num, den = _ss2tf(Ad, Bd, Cd, Dd)
    b = np.asarray(num, dtype=float).ravel()
    a = np.asarray(den, dtype=float).ravel()
    b, a = b / a[0], a / a[0]
    b.setflags(write=False)
    a.setflags(write=False)
    return DiscreteAxis(b=b, a=a, period_s=float(period_s), hold=hold, dc_gain=model.dc_gain)


@functools.lru_cache(maxsize=64)
def _settle_chunk(model: AxisModel, period_s: float) -> int:
    # About five time constants of the slowest pole per chunk (at least 16 samples). Kept per
    # model (frozen, hashed by its coefficients): np.roots per call was 0.1 ms of every
    # cut window's check.
    slowest = float(np.min(np.abs(model.poles().real)))
    return int(np.clip(np.ceil(5.0 / (slowest * period_s)), 16, _MAX_SETTLE_SAMPLES // 10))


def _run(disc: DiscreteAxis, reference_mm: np.ndarray, extra: int, auto_chunk: int):
    """Simulate; append ``extra`` held samples, then (auto_chunk > 0) more until settled.

    Returns (y, n_settle): y has at least N + extra samples; n_settle is the number of appended
    samples such that the last kept sample and all after it are within SETTLE_TOLERANCE_MM of
    the final value (0 when auto_chunk == 0).
    """
    r = np.asarray(reference_mm, dtype=float)
    r0 = r[0]
    zi = np.zeros(max(disc.a.size, disc.b.size) - 1)
    y, zf = _lfilter(disc.b, disc.a, r - r0, zi)
    parts = [y]
    held = r[-1] - r0
    if extra > 0:
        yh, zf = _lfilter(disc.b, disc.a, np.full(extra, held), zf)
        parts.append(yh)
    n_settle = 0
    if auto_chunk > 0:
        final = disc.dc_gain * held
        # Extend by chunks until one whole chunk (≥ 5 slowest time constants) is within the
        # tolerance: the free response of a stable model decays, so it stays there afterwards.
        for _ in range(_MAX_SETTLE_SAMPLES // auto_chunk):
            yh, zf = _lfilter(disc.b, disc.a, np.full(auto_chunk, held), zf)
            parts.append(yh)
            if np.all(np.abs(yh - final) <= SETTLE_TOLERANCE_MM):
                break
        else:
            raise ConfigError(
                f"servo model does not settle to {SETTLE_TOLERANCE_MM} mm within "
                f"{_MAX_SETTLE_SAMPLES} samples"
            )
        y_all = np.concatenate(parts)
        bad = np.nonzero(np.abs(y_all - final) > SETTLE_TOLERANCE_MM)[0]
        n_settle = max(0, int(bad[-1]) + 2 - r.size) if bad.size else 0
        return y_all + disc.dc_gain * r0, n_settle
    return np.concatenate(parts) + disc.dc_gain * r0, n_settle


def _settle_arg(settle) -> tuple[int, bool]:
    if isinstance(settle, bool):
        return 0, settle
    if isinstance(settle, int | np.integer) and settle >= 0:
        return int(settle), False
    raise ValueError(f"settle must be a bool or a count >= 0, got {settle!r}")


def simulate_axis(
    model: AxisModel | AxisServo | None,
    reference_mm: np.ndarray,
    period_s: float,
    hold: str = "foh",
    settle: bool | int = True,
) -> np.ndarray:
    """Actual axis position [mm] at each sample for the reference ``reference_mm`` (N,) [mm].

    The machine starts at rest at ``reference_mm[0]``; the reference is linear between samples
    (``hold="foh"``) or a staircase (``"zoh"``). ``settle=True`` appends samples with the
    reference held at its last value until the output stays within 1e-6 mm
    (SETTLE_TOLERANCE_MM) of its final value, so the result is longer than the input; an int
    appends exactly that many samples; False returns N samples. ``model`` None is an ideal axis
    (output = reference). Exact at the samples (SPEC §8; module docstring).
    """
    r = np.asarray(reference_mm, dtype=float)
    if r.ndim != 1 or r.size == 0:
        raise ValueError("reference_mm must be a non-empty 1-D array")
    extra, auto = _settle_arg(settle)
    if model is None:
        return np.concatenate([r, np.full(extra, r[-1])])
    model = as_model(model)
    disc = discretise(model, period_s, hold)
    y, n_settle = _run(disc, r, extra, _settle_chunk(model, period_s) if auto else 0)
    return y[: r.size + (n_settle if auto else extra)]


def simulate_axes(
    models: Sequence[AxisModel | AxisServo | None],
    reference_mm: np.ndarray,
    period_s: float,
    hold: str = "foh",
    settle: bool | int = True,
) -> np.ndarray:
    """Simulate several axes, column j of ``reference_mm`` (N, k) through ``models[j]``.

    Returns (M, k) [mm]; with ``settle=True`` every axis gets the same number of appended held
    samples, the largest any axis needs to settle (see :func:`simulate_axis`). A ``None`` model
    is an ideal axis (e.g. z when the profile has no z model).
    """
    r = np.asarray(reference_mm, dtype=float)
    if r.ndim != 2 or r.shape[1] != len(models) or r.shape[0] == 0:
        raise ValueError("reference_mm must be (N, k) with k = len(models), N >= 1")
    extra, auto = _settle_arg(settle)
    discs = [
        None if m is None else (discretise(as_model(m), period_s, hold), as_model(m))
        for m in models
    ]
    runs: list[np.ndarray | None] = []
    n_common = extra
    for j, d in enumerate(discs):
        if d is None:
            runs.append(None)
            continue
        y, n_settle = _run(d[0], r[:, j], extra, _settle_chunk(d[1], period_s) if auto else 0)
        runs.append(y)
        n_common = max(n_common, n_settle)
    n_total = r.shape[0] + n_common
    out = np.empty((n_total, len(models)))
    for j, y in enumerate(runs):
        if y is None:
            out[:, j] = np.concatenate([r[:, j], np.full(n_common, r[-1, j])])
            continue
        if y.size < n_total:  # this axis stopped extending earlier: rerun to the common length
            y, _ = _run(discs[j][0], r[:, j], n_common, 0)
        out[:, j] = y[:n_total]
    return out


def error_series(model: AxisModel | AxisServo, order: int = 3) -> np.ndarray:
    """Taylor coefficients c_0..c_{order−1} of 1 − G(s) = Σ c_k s^k about s = 0.

    The error of eq. 26-28 at low frequency: c_0 = 1 − G(0) (0 for DC gain 1), c_1 [s] the
    velocity lag ((a1 − b1)/a0 for eq. 25 with a0 = b0), c_2 [s²] the acceleration term. In
    steady circular motion at speed V and curvature κ the path radius grows by
    (c_2 + c_1²/2)·V²κ (|G(jω)| ≈ 1 + (c_2 + c_1²/2)ω²), SPEC §8's ≈ 2.85e−5 s² × V²κ.
    """
    m = as_model(model)
    den = np.asarray(m.denominator, dtype=float)[::-1]  # ascending powers
    num = np.zeros_like(den)
    num[: len(m.numerator)] = np.asarray(m.numerator, dtype=float)[::-1]
    p = den - num  # 1 − N/D = (D − N)/D
    c = np.zeros(order)
    for k in range(order):  # power-series division, a handful of terms
        acc = p[k] if k < p.size else 0.0
        for j in range(1, min(k, den.size - 1) + 1):
            acc -= den[j] * c[k - j]
        c[k] = acc / den[0]
    return c


def contour_error_eq29(ex_mm, ey_mm, phi_rad):
    """Contour error ε = −E_x sin φ + E_y cos φ [mm] (SPEC §8, eq. 29), vectorised.

    E = reference − actual per axis (eq. 26), φ the tangent angle of the commanded path at the
    reference point. Signed: positive when the actual point lies to the right of the path
    direction (outside a counter-clockwise circle).
    """
    ex = np.asarray(ex_mm, dtype=float)
    ey = np.asarray(ey_mm, dtype=float)
    phi = np.asarray(phi_rad, dtype=float)
    out = -ex * np.sin(phi) + ey * np.cos(phi)
    return float(out) if out.ndim == 0 else out


def _point_segment_distance(p, a, d, len2):
    """|p − nearest point of segment a + t·d, t ∈ [0, 1]|; broadcasts over leading axes."""
    safe = np.where(len2 > 0.0, len2, 1.0)
    t = np.clip(np.einsum("...i,...i->...", p - a, d) / safe, 0.0, 1.0)
    t = np.where(len2 > 0.0, t, 0.0)
    return np.linalg.norm(p - (a + t[..., None] * d), axis=-1)


def contour_error_true(actual_xyz, path_points_xyz, k_initial: int = 8) -> np.ndarray:
    """Exact distance [mm] from each actual point (M, d) to the polyline ``path_points_xyz``.

    Candidate segments come from a KD-tree over segment midpoints (k nearest). The answer is
    exact: a segment whose midpoint is farther than the k-th nearest midpoint is at least
    (that distance − half the longest segment) away, so when that bound is ≥ the best distance
    found, no unexamined segment can be nearer. Points where the bound fails are re-queried
    with k doubled (only those points), up to all segments.
    """
    from scipy.spatial import cKDTree

    p = np.asarray(actual_xyz, dtype=float)
    path = np.asarray(path_points_xyz, dtype=float)
    single = p.ndim == 1
    p = np.atleast_2d(p)
    if path.ndim != 2 or path.shape[0] == 0 or path.shape[1] != p.shape[1]:
        raise ValueError("path_points_xyz must be (N, d) with the actual points' d, N >= 1")
    if path.shape[0] == 1:
        out = np.linalg.norm(p - path[0], axis=1)
        return out[0] if single else out
    a = path[:-1]
    d = np.diff(path, axis=0)
    len2 = np.einsum("ij,ij->i", d, d)
    n_seg = a.shape[0]
    half_max = 0.5 * float(np.sqrt(len2.max()))
    tree = cKDTree(a + 0.5 * d)
    out = np.empty(p.shape[0])
    todo = np.arange(p.shape[0])
    k = min(max(1, int(k_initial)), n_seg)
    block = max(1, 4_000_000 // k)  # bound the (points × k × d) candidate arrays
    while todo.size:
        unresolved = []
        for start in range(0, todo.size, block):
            rows = todo[start : start + block]
            dist_mid, idx = tree.query(p[rows], k=k)
            dist_mid = dist_mid.reshape(rows.size, k)
            idx = idx.reshape(rows.size, k)
            dseg = _point_segment_distance(p[rows][:, None, :], a[idx], d[idx], len2[idx])
            best = dseg.min(axis=1)
            if k == n_seg:
                ok = np.ones(rows.size, dtype=bool)
            else:
                ok = dist_mid[:, -1] - half_max >= best
            out[rows[ok]] = best[ok]
            unresolved.append(rows[~ok])
        todo = np.concatenate(unresolved)
        k = min(2 * k, n_seg)
        block = max(1, 4_000_000 // k)
    return out[0] if single else out


class AxesStream:
    """Several axes simulated window by window, the filter state carried from one window to
    the next (SPEC §8, eq. 25; long programs): :meth:`step` on consecutive
    windows of the reference (w, k) [mm] gives the rows of :func:`simulate_axes` for those
    samples, and :meth:`settle` the tail that ``simulate_axes(..., settle=True)`` appends
    (the reference held at its last point until every axis is within
    :data:`SETTLE_TOLERANCE_MM` of its final value). Memory: the filter state, whatever the
    number of samples. ``models[j]`` None is an ideal axis (output = reference)."""

    def __init__(
        self, models: Sequence[AxisModel | AxisServo | None], period_s: float, hold: str = "foh"
    ):
        self._models = [None if m is None else as_model(m) for m in models]
        self._discs = [None if m is None else discretise(m, period_s, hold) for m in self._models]
        self._period_s = float(period_s)
        self._r0: np.ndarray | None = None  # the first reference point [mm]
        self._last: np.ndarray | None = None  # the last reference point seen [mm]
        self._y_last = np.zeros(len(models))  # last filter output (offset removed) [mm]
        self._zi = [
            None if d is None else np.zeros(max(d.a.size, d.b.size) - 1) for d in self._discs
        ]

    def copy(self) -> AxesStream:
        """An independent copy of the stream's state (the filter states and the points seen;
        the models and their discretisations, immutable, shared): what ``copy.deepcopy``
        gives, without copying the models (a tenth of a millisecond per cut window)."""
        other = object.__new__(AxesStream)
        other.__dict__.update(self.__dict__)
        other._r0 = None if self._r0 is None else self._r0.copy()
        other._last = None if self._last is None else self._last.copy()
        other._y_last = self._y_last.copy()
        other._zi = [None if z is None else z.copy() for z in self._zi]
        return other

    def step(self, reference_mm: np.ndarray) -> np.ndarray:
        """Actual positions (w, k) [mm] for the next ``reference_mm`` (w, k) rows; the first
        call's first row is where the machine starts at rest."""
        r = np.asarray(reference_mm, dtype=float)
        if r.ndim != 2 or r.shape[1] != len(self._models):
            raise ValueError("reference_mm must be (w, k) with k = len(models)")
        if r.shape[0] == 0:
            return np.empty_like(r)
        if self._r0 is None:
            self._r0 = r[0].copy()
        out = np.empty_like(r)
        for j, d in enumerate(self._discs):
            if d is None:
                out[:, j] = r[:, j]
                continue
            y, self._zi[j] = _lfilter(d.b, d.a, r[:, j] - self._r0[j], self._zi[j])
            self._y_last[j] = y[-1]
            out[:, j] = y + d.dc_gain * self._r0[j]
        self._last = r[-1].copy()
        return out

    def _settle_count(self, j: int) -> int:
        """Held samples axis j needs (the rule of :func:`_run` with ``auto_chunk``)."""
        d, model = self._discs[j], self._models[j]
        held = self._last[j] - self._r0[j]
        final = d.dc_gain * held
        chunk = _settle_chunk(model, self._period_s)
        zf = self._zi[j]
        done = 0
        for _ in range(_MAX_SETTLE_SAMPLES // chunk):
            yh, zf = _lfilter(d.b, d.a, np.full(chunk, held), zf)
            bad = np.flatnonzero(np.abs(yh - final) > SETTLE_TOLERANCE_MM)
            if bad.size:  # the last held sample out of tolerance so far
                last_bad = done + int(bad[-1])
            done += chunk
            if not bad.size:
                break
        else:
            raise ConfigError(
                f"servo model does not settle to {SETTLE_TOLERANCE_MM} mm "
                f"within {_MAX_SETTLE_SAMPLES} samples"
            )
        if done > chunk:  # some chunk before the last was out of tolerance
            return last_bad + 2
        return 1 if abs(self._y_last[j] - final) > SETTLE_TOLERANCE_MM else 0

    def settle(self) -> np.ndarray:
        """The held tail (T, k) [mm] after the last window: T the most samples any axis needs
        to settle (as :func:`simulate_axes` with ``settle=True``)."""
        if self._last is None:
            raise ValueError("settle() before any step()")
        counts = [0 if d is None else self._settle_count(j) for j, d in enumerate(self._discs)]
        n = max(counts)
        out = np.empty((n, len(self._models)))
        for j, d in enumerate(self._discs):
            if d is None:
                out[:, j] = self._last[j]
                continue
            held = self._last[j] - self._r0[j]
            y, _ = _lfilter(d.b, d.a, np.full(n, held), self._zi[j])
            out[:, j] = y + d.dc_gain * self._r0[j]
        return out
