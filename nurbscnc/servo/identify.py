"""Fit an axis's closed-loop position model from a recorded trace (``nurbscnc identify``).

Input: the commanded position u_k and the actual position y_k of one axis, sampled every T
seconds (e.g. a LinuxCNC ``halsampler`` capture of ``pos-cmd`` and ``pos-fb``). Output: the
model of SPEC eq. 25 (``order=4``: G(s) = (b2 s² + b1 s + b0)/(s⁴ + a3 s³ + a2 s² + a1 s + a0))
or the profile's simple form (``order=2``: G(s) = ω_n²/(s² + 2ζω_n s + ω_n²), printed as
bandwidth and damping), with the fit's quality.

Method: output-error least squares in continuous time. For parameters θ the model's response to
the recorded command is simulated exactly at the samples (scipy.signal.cont2discrete, first-order
hold: the command linear between samples, as the planner assumes, SPEC §8) from rest at the first
command, plus a constant offset c (encoder vs command zero); scipy.optimize.least_squares
minimises Σ (y_k − ŷ_k(θ))². The output error, unlike an equation error, is unbiased under
measurement noise on y.

Parametrisation (always stable, well scaled): the denominator as quadratic factors
s² + 2ζ_i ω_i s + ω_i² with ln ω_i and ln ζ_i free (ζ > 0 keeps every pole in the left
half-plane; ζ > 1 is a pair of real poles); for order 4 the numerator
g·a0·(1 + k1 s/ω_r + k2 s²/ω_r²), ω_r = √(ω_1 ω_2), with DC gain g and k1, k2 of order 1.
Start points: a discrete ARX fit (linear least squares y_k = −Σ a_i y_{k−i} + Σ b_i u_{k−i}),
its poles mapped to s = ln(z)/T, and a coarse grid of 2nd-order models; the best local optimum
wins.

Quality: fit = 1 − ‖y − ŷ‖/‖y − ȳ‖ (NRMSE fit, 1 is perfect), R² = 1 − Σ(y − ŷ)²/Σ(y − ȳ)², the
residual RMS, and for comparison the RMS of the following error u − y.
"""

from __future__ import annotations

import math
import re
import warnings
from dataclasses import dataclass

import numpy as np
from scipy import optimize, signal

from nurbscnc.errors import NurbsCncError, SourcePos

ORDERS = (2, 4)


class TraceError(NurbsCncError):
    """A trace file that cannot be read as samples (exit 2, with the line)."""


# ---------------------------------------------------------------------------------------------
# Reading a trace (pure: text in, arrays out).


@dataclass(frozen=True)
class Trace:
    """Command and actual position [mm] at equally spaced samples, period ``period_s`` [s];
    ``columns`` says which columns of the file they came from (for messages)."""

    command_mm: np.ndarray
    actual_mm: np.ndarray
    period_s: float
    columns: str = ""


#: Header names that mark a column's role (matched case-insensitively against the name's
#: words: "Time (s)", "pos_cmd", "axis.0.motor-pos-fb" all match). A command word wins over
#: a feedback word ("pos-cmd" is the command).
COMMAND_WORDS = frozenset(
    {"cmd", "command", "commanded", "ref", "reference", "setpoint", "sp", "demand", "target"}
)
ACTUAL_WORDS = frozenset(
    {"fb", "feedback", "pos", "position", "actual", "act", "measured", "meas", "encoder", "enc"}
)
TIME_WORDS = frozenset({"t", "time", "timestamp", "sec", "secs", "seconds"})
#: Unit words of a time column's name → seconds per unit (no unit word: seconds).
TIME_UNITS = {"s": 1.0, "sec": 1.0, "secs": 1.0, "seconds": 1.0, "ms": 1e-3, "us": 1e-6}
_WORD = re.compile(r"[^0-9a-z]+")


def _words(name: str) -> set[str]:
    return set(_WORD.split(name.lower().replace("µs", "us"))) - {""}


def _role(name: str) -> str | None:
    """ "cmd", "fb" or "time" for a header name with one of the role words, else None."""
    words = _words(name)
    if words & COMMAND_WORDS:
        return "cmd"
    if words & ACTUAL_WORDS:
        return "fb"
    if words & TIME_WORDS:
        return "time"
    return None


def _column(spec: str, header: list[str] | None, width: int, what: str) -> int:
    """0-based column index from a 1-based number or a header name (any case)."""
    if spec.isdigit():
        k = int(spec) - 1
        if not 0 <= k < width:
            raise TraceError(f"--{what} {spec}: the trace has {width} columns")
        return k
    lowered = [h.lower() for h in header] if header is not None else []
    if spec.lower() not in lowered:
        names = ", ".join(header) if header else "no header line"
        raise TraceError(f"--{what} {spec!r}: no such column ({names})")
    return lowered.index(spec.lower())


def _find_columns(header, width: int, specs: dict) -> dict:
    """Column index (or None for no time column) of "cmd", "fb" and "time": the ``specs``
    given (numbers or names), else the header's names by role (:func:`_role`), else the
    first two columns when that is unambiguous (no header, or a header of two columns)."""
    roles: dict[str, list[int]] = {}
    for k, name in enumerate(header or ()):
        roles.setdefault(_role(name), []).append(k)
    out: dict = {}
    for role, fallback in (("cmd", 0), ("fb", 1), ("time", None)):
        if specs[role] is not None:
            out[role] = _column(specs[role], header, width, role)
            continue
        found = roles.get(role, [])
        if len(found) > 1:
            names = ", ".join(repr(header[k]) for k in found)
            raise TraceError(f"columns {names} all look like --{role}: name one with --{role}")
        if found:
            out[role] = found[0]
        elif header is not None and width > 2 and fallback is not None:
            raise TraceError(
                f"which column is --{role}? The header ({', '.join(header)}) names none "
                f"(e.g. t, cmd, fb): give --cmd and --fb (and --time)"
            )
        else:
            out[role] = fallback
    return out


def _period_of(t: np.ndarray, numbers: list[int], period_s: float | None) -> float:
    """The sample period [s] of a time column ``t`` [s] (uniform within 1 %)."""
    dt = np.diff(t)
    period = float(np.median(dt))
    if not period > 0:
        raise TraceError("the time column does not increase")
    bad = np.flatnonzero(np.abs(dt - period) > 0.01 * period)
    if bad.size:
        k = int(bad[0]) + 1
        raise TraceError(
            f"time step {dt[k - 1]:.6g} s, not the period {period:.6g} s (samples lost?)",
            SourcePos(numbers[k], 1, ""),
        )
    if period_s is not None and abs(period - period_s) > 0.01 * period_s:
        raise TraceError(
            f"the time column's period {period:.6g} s disagrees with --period-ms {period_s * 1e3:g}"
        )
    return period


def parse_trace(
    text: str,
    cmd: str | None = None,
    fb: str | None = None,
    time: str | None = None,
    period_s: float | None = None,
) -> Trace:
    """Read a trace: whitespace- or comma-separated numbers, one sample per line.

    Blank lines and lines starting with ``#`` are skipped; a first line of names is a header,
    never a sample. ``cmd``/``fb``/``time``: column numbers (1-based) or names; not given,
    they are found by the header's names (:data:`COMMAND_WORDS`, :data:`ACTUAL_WORDS`,
    :data:`TIME_WORDS`), else columns 1 and 2 (no header: halsampler's order). The period
    comes from ``period_s`` or from the time column (uniform within 1 %; seconds, or the
    unit its name gives: ``time_ms``, ``t [us]``). halsampler's ``overrun`` line (samples
    lost) is an error. Raises TraceError with the line.
    """
    header, rows, numbers = _read_rows(text)
    data = np.asarray(rows)
    width = data.shape[1]
    col = _find_columns(header, width, {"cmd": cmd, "fb": fb, "time": time})

    def name(k: int) -> str:
        return f"{header[k]!r} (column {k + 1})" if header else f"column {k + 1}"

    columns = f"command {name(col['cmd'])}, actual {name(col['fb'])}"
    if col["time"] is not None:
        unit = next((TIME_UNITS[w] for w in _words(header[col["time"]]) if w in TIME_UNITS), 1.0)
        period = _period_of(data[:, col["time"]] * (unit if header else 1.0), numbers, period_s)
        columns += f", time {name(col['time'])}"
    elif period_s is None:
        raise TraceError("no sample period: give --period-ms, or a time column (--time)")
    else:
        period = float(period_s)
    return Trace(data[:, col["cmd"]].copy(), data[:, col["fb"]].copy(), period, columns)


def _read_rows(text: str) -> tuple[list[str] | None, list[list[float]], list[int]]:
    """(header names or None, rows of numbers, their line numbers) of a trace's text."""
    header: list[str] | None = None
    rows: list[list[float]] = []
    numbers: list[int] = []
    for number, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        fields = line.replace(",", " ").split()
        if line == "overrun":
            raise TraceError(
                "halsampler overrun: samples were lost here (use a deeper sampler "
                "FIFO or record fewer channels)",
                SourcePos(number, 1, raw),
            )
        try:
            values = [float(f) for f in fields]
        except ValueError:
            if header is None and not rows and not any(_is_float(f) for f in fields):
                # a first line of names only; in a CSV a name may hold spaces ("Time (s)")
                header = [f.strip() for f in line.split(",")] if "," in line else fields
                continue
            bad = next(f for f in fields if not _is_float(f))
            raise TraceError(
                f"not a number: {bad!r}", SourcePos(number, raw.find(bad) + 1, raw)
            ) from None
        width = len(header) if header is not None else (len(rows[0]) if rows else len(values))
        if len(values) != width:
            raise TraceError(f"{len(values)} columns, expected {width}", SourcePos(number, 1, raw))
        if not all(math.isfinite(v) for v in values):
            raise TraceError("values must be finite", SourcePos(number, 1, raw))
        rows.append(values)
        numbers.append(number)
    if len(rows) < 20:
        raise TraceError(f"the trace has {len(rows)} samples; at least 20 are needed")
    return header, rows, numbers


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


# ---------------------------------------------------------------------------------------------
# The model family and its simulation.


def _quadratics(theta: np.ndarray, order: int) -> list[tuple[float, float]]:
    """(ω_i, ζ_i) of the denominator's quadratic factors."""
    return [(math.exp(theta[2 * i]), math.exp(theta[2 * i + 1])) for i in range(order // 2)]


def model_tf(theta: np.ndarray, order: int) -> tuple[np.ndarray, np.ndarray]:
    """(numerator, denominator), highest power first, of parameters θ (module docstring)."""
    den = np.array([1.0])
    for w, z in _quadratics(theta, order):
        den = np.polymul(den, [1.0, 2.0 * z * w, w * w])
    a0 = den[-1]
    if order == 2:
        return np.array([a0]), den
    w1, w2 = math.exp(theta[0]), math.exp(theta[2])
    wr = math.sqrt(w1 * w2)
    g, k1, k2 = theta[4], theta[5], theta[6]
    return g * a0 * np.array([k2 / wr**2, k1 / wr, 1.0]), den


def _n_params(order: int) -> int:
    return 2 + 1 if order == 2 else 4 + 3 + 1  # poles (+ g, k1, k2) + offset


def foh_discretise(num, den, period_s: float) -> tuple[np.ndarray, np.ndarray]:
    """H(z) (b, a in powers of z⁻¹) of the strictly proper G = num/den for an input linear
    between samples (FOH), exact at the samples.

    The same maps as scipy.signal.cont2discrete(method="foh") (and nurbscnc.servo.model), in
    closed form on the eigen-decomposition of the companion matrix A = V Λ V⁻¹:
    Φ = V e^{ΛT} V⁻¹, Γ1 = V diag((e^{λT} − 1)/λ) V⁻¹ B, Γ2 = V diag((e^{λT} − 1 − λT)/(λ²T)) V⁻¹ B;
    x_{k+1} = Φ x_k + Γ1 u_k + Γ2 (u_{k+1} − u_k), made causal with ξ = x − Γ2 u. About ten
    times faster than the general matrix exponential, which matters inside the optimiser; for
    (nearly) repeated poles (ill-conditioned V) it falls back to scipy.
    """
    den = np.asarray(den, dtype=float)
    num = np.asarray(num, dtype=float)
    a = den[1:] / den[0]
    n = a.size
    A = np.zeros((n, n))
    A[0, :] = -a
    A[np.arange(1, n), np.arange(n - 1)] = 1.0
    c = np.zeros(n)
    c[n - num.size :] = num / den[0]
    lam, V = np.linalg.eig(A)
    if np.linalg.cond(V) > 1e8:
        with warnings.catch_warnings():  # tiny leading numerator coefficients are expected
            warnings.simplefilter("ignore", signal.BadCoefficients)
            bd, ad, _ = signal.cont2discrete((num, den), period_s, method="foh")
        return np.ravel(bd), np.ravel(ad)
    x = lam * period_s
    e = np.exp(x)
    w = np.linalg.solve(V, np.eye(n, 1, dtype=complex)[:, 0])  # V⁻¹ B, B = e_1
    phi = ((V * e) @ np.linalg.inv(V)).real
    g1 = (V @ (np.expm1(x) / lam * w)).real
    g2 = (V @ ((np.expm1(x) - x) / (lam * lam * period_s) * w)).real
    bd = g1 + phi @ g2 - g2
    ad = np.real(np.poly(e))
    # SISO state space → transfer function: num = det(zI − Φ + Bd c) + (D − 1) det(zI − Φ).
    b = np.real(np.poly(phi - np.outer(bd, c))) + (c @ g2 - 1.0) * ad
    return b, ad


def simulate_model(num, den, command_mm: np.ndarray, period_s: float) -> np.ndarray:
    """Exact sampled response [mm] to a command linear between samples (FOH), starting at
    rest at the first command: G applied to u − u_0, plus G(0)·u_0."""
    bd, ad = foh_discretise(num, den, period_s)
    u0 = command_mm[0]
    return signal.lfilter(bd, ad, command_mm - u0) + (num[-1] / den[-1]) * u0


def _residual(theta, order, u, y, period_s):
    # Far from the optimum a start point may overflow (ω = e^θ beyond a float, for a trace
    # no model of the family describes): a huge residual, never a crash.
    try:
        with np.errstate(all="ignore"):
            num, den = model_tf(theta, order)
            r = simulate_model(num, den, u, period_s) + theta[-1] - y
    except OverflowError:
        r = None
    if r is not None and np.all(np.isfinite(r)):
        return r
    return np.full(y.size, 1e6 * (np.ptp(y) + 1.0))


# ---------------------------------------------------------------------------------------------
# Start points.


def _pairs_from_poles(poles: np.ndarray, order: int) -> list[tuple[float, float]] | None:
    """Group continuous poles into quadratic factors (ω, ζ); None if any is unusable."""
    if poles.size != order or np.any(~np.isfinite(poles)) or np.any(poles.real >= 0):
        return None
    cplx = sorted((p for p in poles if p.imag > 1e-9 * abs(p)), key=abs)
    real = sorted((p.real for p in poles if abs(p.imag) <= 1e-9 * abs(p)), key=abs)
    pairs = [(abs(p), -p.real / abs(p)) for p in cplx]
    if len(real) % 2:
        return None
    for i in range(0, len(real), 2):  # two real poles r1, r2: ω² = r1 r2, 2ζω = −(r1 + r2)
        w = math.sqrt(real[i] * real[i + 1])
        pairs.append((w, -(real[i] + real[i + 1]) / (2.0 * w)))
    return sorted(pairs) if len(pairs) == order // 2 else None


def arx_poles(u: np.ndarray, y: np.ndarray, order: int, period_s: float) -> np.ndarray:
    """Continuous poles s = ln(z)/T of an ARX fit of the given order (linear least squares)."""
    n = order
    rows = y.size - n
    cols = [-y[n - i : n - i + rows] for i in range(1, n + 1)]
    cols += [u[n - i : n - i + rows] for i in range(0, n + 1)]
    cols.append(np.ones(rows))  # offset
    coef, *_ = np.linalg.lstsq(np.column_stack(cols), y[n:], rcond=None)
    z = np.roots(np.concatenate([[1.0], coef[:n]]))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.log(z.astype(complex)) / period_s


def _start_points(u, y, order, period_s) -> list[np.ndarray]:
    starts = []
    pairs = _pairs_from_poles(arx_poles(u, y, order, period_s), order)
    nyquist = math.pi / period_s
    # A grid of well-damped models from 2 Hz to a fifth of the Nyquist frequency.
    for w in np.geomspace(2 * math.pi * 2.0, nyquist / 5.0, 6):
        starts.append([(w, 0.7)] if order == 2 else [(w, 0.7), (3.0 * w, 0.7)])
    if pairs is not None and all(w < nyquist for w, _ in pairs):
        starts.insert(0, pairs)
    out = []
    for p in starts:
        theta = [v for w, z in p for v in (math.log(w), math.log(min(max(z, 0.02), 20.0)))]
        if order == 4:
            theta += [1.0, 0.0, 0.0]  # DC gain 1, no zeros
        theta.append(float(np.mean(y - u)))
        out.append(np.asarray(theta))
    return out


# ---------------------------------------------------------------------------------------------
# The fit.


@dataclass(frozen=True)
class Fit:
    """Result of :func:`fit_axis`. ``numerator``/``denominator`` highest power first (a4 = 1);
    ``poles`` [1/s]; ``offset_mm`` the constant y − G u; quality figures as in the module
    docstring; for order 2 also ``bandwidth_hz`` (−3 dB) and ``damping``."""

    order: int
    numerator: np.ndarray
    denominator: np.ndarray
    poles: np.ndarray
    dc_gain: float
    offset_mm: float
    fit: float
    r2: float
    residual_rms_mm: float
    following_error_rms_mm: float
    samples: int
    period_s: float
    bandwidth_hz: float | None = None
    damping: float | None = None
    delay: int = 0  #: samples by which the actual position was shifted before the fit


def bandwidth_hz(wn: float, zeta: float) -> float:
    """−3 dB bandwidth [Hz] of ω_n²/(s² + 2ζω_n s + ω_n²) (inverse of the profile's formula)."""
    c = 1.0 - 2.0 * zeta * zeta
    r = math.sqrt(c * c + 1.0)
    u2 = c + r if c >= 0.0 else 1.0 / (r - c)
    return wn * math.sqrt(u2) / (2.0 * math.pi)


def fit_axis(trace: Trace, order: int = 4, delay: int = 0) -> Fit:
    """Fit the closed-loop model of one axis to ``trace`` (module docstring).

    ``delay`` [samples]: the actual position is recorded that many periods late (e.g. 1 for a
    LinuxCNC capture whose feedback is read at the start of the period, before the command
    of that period is written): y_{k+delay} is paired with u_k, and the delay is not part of
    the model. Raises TraceError when the command does not move (nothing to identify).
    """
    if order not in ORDERS:
        raise ValueError(f"order must be one of {ORDERS}, got {order}")
    if not 0 <= delay < trace.command_mm.size - 20:
        raise TraceError(
            f"delay {delay} samples does not fit a trace of {trace.command_mm.size} samples"
        )
    u = np.asarray(trace.command_mm, dtype=float)[: trace.command_mm.size - delay]
    y = np.asarray(trace.actual_mm, dtype=float)[delay:]
    if not np.ptp(u) > 0:
        raise TraceError("the command does not move: nothing to identify")
    if not np.ptp(y) > 0:
        raise TraceError("the actual position does not move: is the axis enabled?")
    # Local optimisation from the start with the lowest cost; the others (in order of cost)
    # only while the fit is not yet at the noise floor (fit < 0.98: a local optimum).
    args = (order, u, y, trace.period_s)
    starts = _start_points(u, y, order, trace.period_s)
    costs = [float(np.sum(_residual(th, *args) ** 2)) for th in starts]
    dev = y - y.mean()
    ss_tot = float(dev @ dev)
    best = None
    for i in sorted(range(len(starts)), key=lambda i: costs[i]):
        if best is not None and 1.0 - math.sqrt(2.0 * best.cost / ss_tot) >= 0.98:
            break
        try:
            res = optimize.least_squares(
                _residual, starts[i], args=args, x_scale="jac", method="trf", max_nfev=300
            )
        except (ValueError, np.linalg.LinAlgError, FloatingPointError):
            continue
        if np.all(np.isfinite(res.fun)) and (best is None or res.cost < best.cost):
            best = res
    if best is None:
        raise TraceError("the fit failed from every start point (is the trace one axis?)")
    theta = best.x
    num, den = model_tf(theta, order)
    resid = best.fun
    ss_res = float(resid @ resid)
    extra = {}
    if order == 2:
        w, z = _quadratics(theta, 2)[0]
        extra = {"bandwidth_hz": bandwidth_hz(w, z), "damping": z}
    return Fit(
        order=order,
        numerator=num,
        denominator=den,
        poles=np.roots(den),
        dc_gain=float(num[-1] / den[-1]),
        offset_mm=float(theta[-1]),
        fit=1.0 - math.sqrt(ss_res / ss_tot) if ss_tot > 0 else 0.0,
        r2=1.0 - ss_res / ss_tot if ss_tot > 0 else 0.0,
        residual_rms_mm=math.sqrt(ss_res / y.size),
        following_error_rms_mm=float(np.sqrt(np.mean((u - y) ** 2))),
        samples=int(y.size),
        delay=delay,
        period_s=float(trace.period_s),
        **extra,
    )


#: The least fit (NRMSE, a fraction) a model is printed with (``identify --min-fit``). An axis
#: that tracks its command scores close to 1 with any model near its own: even "no lag"
#: (ŷ = u) scores 1 − RMS(u − y)/σ(y), over 0.99 for a trace that moves millimetres with a
#: following error of tens of µm. Below 0.9 the model misses a tenth of the motion: it does
#: not describe the axis (wrong columns or period, lost samples, another axis's feedback),
#: and the contour check would trust it.
MIN_FIT = 0.9


def require_quality(fit: Fit, min_fit: float = MIN_FIT, columns: str = "") -> None:
    """Refuse (TraceError, exit 2) a fit below ``min_fit`` (:data:`MIN_FIT`), saying why."""
    if fit.fit >= min_fit:
        return
    used = f" ({columns})" if columns else ""
    raise TraceError(
        f"the fit is {fit.fit * 100:.2f} % (NRMSE), below the {min_fit * 100:g} % a servo "
        f"model needs: its response misses the recorded position by "
        f"{fit.residual_rms_mm * 1e3:.4g} um RMS, while the command itself is "
        f"{fit.following_error_rms_mm * 1e3:.4g} um RMS from it. Check the columns{used}, "
        f"the sample period ({fit.period_s * 1e3:g} ms) and that the trace is one axis's "
        f"command and feedback; --min-fit lowers the bar"
    )


def _pole_text(p: complex) -> str:
    return f"{p.real:.5g}" if abs(p.imag) < 1e-12 * abs(p) else f"{p.real:.5g}{p.imag:+.5g}j"


def profile_section(fit: Fit, axis: str = "x", source: str = "", columns: str = "") -> str:
    """The fit as a ``[servo.<axis>]`` profile section, with the quality (and the trace's
    ``columns`` used) in comments."""
    poles = ", ".join(_pole_text(p) for p in sorted(fit.poles, key=lambda p: (abs(p), p.imag)))
    head = [
        f"# nurbscnc identify{': ' + source if source else ''}: {fit.samples} samples at "
        f"T = {fit.period_s * 1e3:g} ms, order {fit.order}"
        + (f", feedback {fit.delay} period(s) late (removed)" if fit.delay else ""),
        f"# fit {fit.fit * 100:.2f} % (NRMSE), R^2 {fit.r2:.6f}, residual RMS "
        f"{fit.residual_rms_mm * 1e3:.3g} um (following error RMS "
        f"{fit.following_error_rms_mm * 1e3:.3g} um)",
        f"# poles [1/s]: {poles}; DC gain {fit.dc_gain:.6g}; offset {fit.offset_mm * 1e3:.3g} um",
        *([f"# columns: {columns}"] if columns else []),
        f"[servo.{axis}]",
    ]
    if fit.order == 2:
        body = [f"bandwidth_hz = {fit.bandwidth_hz:.6g}", f"damping = {fit.damping:.6g}"]
    else:
        den = fit.denominator / fit.denominator[0]
        num = np.concatenate([np.zeros(3 - fit.numerator.size), fit.numerator]) / fit.denominator[0]
        names = ["a4", "a3", "a2", "a1", "a0"]
        body = [f"{k} = {v:.7g}" for k, v in sorted(zip(names, den, strict=True))]
        body += [f"{k} = {v:.7g}" for k, v in zip(["b2", "b1", "b0"], num, strict=True)][::-1]
    # TOML needs a decimal point or exponent for a float; %g may print "1": make it "1.0".
    body = [ln if any(c in ln.split("=")[1] for c in ".e") else ln + ".0" for ln in body]
    return "\n".join(head + body) + "\n"
