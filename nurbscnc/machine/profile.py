"""The machine profile: every limit and model the planner uses (SPEC §7-§9), from TOML.

A profile is a TOML file (the default one, the paper's benchmark machine, ships as
``nurbscnc/data/default_machine.toml``). The file speaks the units users think in (mm/min, um,
ms); :class:`Machine` holds the same values in the program's internal units (mm, s), each field
named with its unit. Everything is validated on load: a bad value raises
:class:`~nurbscnc.errors.ConfigError` whose message names the dotted key.

The feed formulas the planner and the baselines share (chord-error feed, curvature feed,
sharp-corner curvature threshold) are module-level pure functions here, and
:class:`Machine` offers them with its own parameters filled in.
"""

from __future__ import annotations

import copy
import math
import sys
import tomllib
from dataclasses import dataclass
from importlib import resources

import numpy as np

from nurbscnc.errors import ConfigError, OutputError

#: The machine axes, in the order every per-axis tuple uses.
AXES = ("x", "y", "z")
#: Servo model coefficients of SPEC eq. 25, in the profile's key order.
SERVO_COEFFICIENTS = ("a0", "a1", "a2", "a3", "a4", "b0", "b1", "b2")

# ---------------------------------------------------------------------------------------------
# Schema. A table is a dict of key -> sub-schema; a leaf is the name of a value check:
#   "pos"    a finite number > 0        "finite"  any finite number
#   "count"  an integer >= 1
# Keys listed in _OPTIONAL may be absent; every other key is required, and unknown keys are
# errors (a misspelt key must never silently fall back to a default).
_COEFF_SCHEMA = {
    "a0": "finite",
    "a1": "finite",
    "a2": "finite",
    "a3": "finite",
    "a4": "pos",  # leading coefficient: fixes the sign convention, keeps the model proper
    "b0": "pos",  # b0 / a0 is the DC gain; a servo that does not track has no business here
    "b1": "finite",
    "b2": "finite",
}
_SCHEMA: dict = {
    "limits": {
        "v_max_mm_min": "pos",
        "rapid_mm_min": "pos",
        "a_max_mm_s2": "pos",
        "j_max_mm_s3": "pos",
        "chord_tolerance_um": "pos",
        "kappa_ref_per_mm": "pos",
        "contour_tolerance_um": "pos",
        "ph_tolerance_um": "pos",
    },
    "servo": {"period_ms": "pos", "x": _COEFF_SCHEMA, "y": _COEFF_SCHEMA, "z": _COEFF_SCHEMA},
    "steps": {"max_pulses_per_period": "count", "per_mm": {a: "pos" for a in AXES}},
    "soft_limits": {a: {"min_mm": "finite", "max_mm": "finite"} for a in AXES},
}
_OPTIONAL = frozenset({"limits.rapid_mm_min", "servo.z"})

_MM_PER_UM = 1e-3
_S_PER_MS = 1e-3
_S_PER_MIN = 60.0


# ---------------------------------------------------------------------------------------------
# Derived feed formulas (pure, vectorised; SPEC §5 and §7).


def _as_result(values: np.ndarray):
    """A float for a 0-d result, else the array itself."""
    return float(values) if values.ndim == 0 else values


def kappa_threshold_per_mm(feed_mm_s, a_max_mm_s2: float):
    """Sharp-corner curvature threshold κ_th = A_max / F² [1/mm] (SPEC §5, eq. 15).

    ``feed_mm_s`` [mm/s] scalar or array; a feed ≤ 0 gives ``inf`` (nothing is sharp at rest).
    """
    f = np.asarray(feed_mm_s, dtype=float)
    safe = np.where(f > 0.0, f, 1.0)
    return _as_result(np.where(f > 0.0, a_max_mm_s2 / (safe * safe), np.inf))


def chord_feed_mm_s(kappa_per_mm, period_s: float, chord_tolerance_mm: float):
    """Chord-error feed V_af = (2/T_s)·√(2δ/κ − δ²) [mm/s] (SPEC §7, eq. 23; Yeh & Hsu 2002).

    The chord of one period on a circle of radius 1/κ whose sagitta is δ has half-length
    √(2δ/κ − δ²), for radius ≥ δ. Below radius δ no chord can have a sagitta above the radius,
    so the chord error cannot exceed δ whatever the step: the formula (which would fall to 0
    at radius δ/2 and stall the tool) is held at its radius-δ value 2δ/T_s there, continuous
    and never 0; the normal-acceleration limit governs such tight curves anyway. Curvature is
    unsigned here: ``|kappa|`` is used, so a signed curvature cannot skip the slowdown.
    κ = 0 (straight) gives ``inf``. Never NaN for non-NaN input.
    """
    d = float(chord_tolerance_mm)
    k = np.minimum(np.abs(np.asarray(kappa_per_mm, dtype=float)), 1.0 / d)
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        half_chord_sq = d * (2.0 / k - d)  # 2δ/κ − δ², +inf for κ = 0
        v = (2.0 / period_s) * np.sqrt(np.maximum(half_chord_sq, 0.0))
    return _as_result(np.where(k == 0.0, np.inf, v))


def curvature_feed_mm_s(kappa_per_mm, v_max_mm_s: float, kappa_ref_per_mm: float):
    """Curvature feed V_cf = V_max·κ̄/(κ + κ̄) [mm/s] (SPEC §7, eq. 24; Zhiming 2002).

    ``|kappa|`` is used (unsigned curvature); κ = 0 gives V_max, κ → ∞ gives 0.
    """
    k = np.abs(np.asarray(kappa_per_mm, dtype=float))
    with np.errstate(invalid="ignore"):
        v = v_max_mm_s * kappa_ref_per_mm / (k + kappa_ref_per_mm)
    return _as_result(np.where(np.isinf(k), 0.0, v))


# ---------------------------------------------------------------------------------------------
# The profile, in internal units.


@dataclass(frozen=True)
class Limits:
    """Kinematic limits and tolerances (SPEC §7, Table 3), in mm and s."""

    v_max_mm_s: float  #: feed ceiling V_max
    rapid_mm_s: float  #: G0 traverse rate (defaults to V_max)
    a_max_mm_s2: float  #: acceleration limit A_max
    j_max_mm_s3: float  #: jerk limit J_max
    chord_tolerance_mm: float  #: δ, eq. 23
    kappa_ref_per_mm: float  #: κ̄, eq. 24
    contour_tolerance_mm: float  #: ε_max, SPEC §8
    ph_tolerance_mm: float  #: e, SPEC §6


@dataclass(frozen=True)
class AxisServo:
    """One axis's closed-loop position model (SPEC eq. 25, Table 2).

    G(s) = (b2 s² + b1 s + b0) / (a4 s⁴ + a3 s³ + a2 s² + a1 s + a0), s in 1/s.
    """

    a0: float
    a1: float
    a2: float
    a3: float
    a4: float
    b0: float
    b1: float
    b2: float

    @property
    def numerator(self) -> tuple[float, float, float]:
        """Numerator coefficients, highest power first (scipy.signal order)."""
        return (self.b2, self.b1, self.b0)

    @property
    def denominator(self) -> tuple[float, float, float, float, float]:
        """Denominator coefficients, highest power first (scipy.signal order)."""
        return (self.a4, self.a3, self.a2, self.a1, self.a0)

    def poles(self) -> np.ndarray:
        """The closed-loop poles [1/s] (roots of the denominator)."""
        return np.roots(self.denominator)

    @property
    def dc_gain(self) -> float:
        """G(0) = b0/a0 (1 for a servo with integral action)."""
        return self.b0 / self.a0


@dataclass(frozen=True)
class Servo:
    """Servo period and per-axis models; ``z`` is None when the profile has no z model."""

    period_s: float  #: T_s, one reference point per period
    x: AxisServo
    y: AxisServo
    z: AxisServo | None = None

    def axis(self, name: str) -> AxisServo | None:
        """The model of axis ``name`` ("x", "y", "z"); None means an ideal axis."""
        return getattr(self, name)


@dataclass(frozen=True)
class Steps:
    """Step (pulse) resolution per axis (x, y, z) and the card's per-period pulse ceiling."""

    per_mm: tuple[float, float, float]  #: steps per mm
    max_pulses_per_period: int


@dataclass(frozen=True)
class SoftLimits:
    """Travel box per axis (x, y, z) [mm]."""

    min_mm: tuple[float, float, float]
    max_mm: tuple[float, float, float]

    def inside(self, points_mm) -> np.ndarray:
        """Per point (rows of an (N, 3) array, or one 3-vector): inside the box, bounds included."""
        p = np.asarray(points_mm, dtype=float)
        return np.all((p >= self.min_mm) & (p <= self.max_mm), axis=-1)


@dataclass(frozen=True)
class Machine:
    """A validated machine profile in internal units (mm, s); ``source``: where it came from."""

    limits: Limits
    servo: Servo
    steps: Steps
    soft_limits: SoftLimits
    source: str = "<default>"

    def kappa_threshold_per_mm(self, feed_mm_s):
        """κ_th = A_max / F² [1/mm] at programmed feed ``feed_mm_s`` (SPEC §5)."""
        return kappa_threshold_per_mm(feed_mm_s, self.limits.a_max_mm_s2)

    def chord_feed_mm_s(self, kappa_per_mm):
        """V_af at curvature ``kappa_per_mm`` with this machine's T_s and δ (SPEC eq. 23)."""
        return chord_feed_mm_s(kappa_per_mm, self.servo.period_s, self.limits.chord_tolerance_mm)

    def curvature_feed_mm_s(self, kappa_per_mm, feed_mm_s: float | None = None):
        """V_cf with κ̄ of this machine (SPEC eq. 24); ``feed_mm_s`` defaults to V_max."""
        v = self.limits.v_max_mm_s if feed_mm_s is None else feed_mm_s
        return curvature_feed_mm_s(kappa_per_mm, v, self.limits.kappa_ref_per_mm)

    def corner_feed_mm_s(self, kappa_per_mm, feed_mm_s: float | None = None):
        """V_sp = min(V_af, V_cf) at a corner of peak curvature ``kappa_per_mm`` (SPEC §7)."""
        return _as_result(
            np.minimum(
                np.asarray(self.chord_feed_mm_s(kappa_per_mm)),
                np.asarray(self.curvature_feed_mm_s(kappa_per_mm, feed_mm_s)),
            )
        )


# ---------------------------------------------------------------------------------------------
# Loading and validation.


def default_profile_text() -> str:
    """The text of the packaged default profile (the paper's benchmark machine)."""
    ref = resources.files("nurbscnc").joinpath("data", "default_machine.toml")
    return ref.read_text(encoding="utf-8")


def load_machine(path: str | None = None, overrides: dict | None = None) -> Machine:
    """Load and validate a machine profile.

    ``path`` None loads the packaged default. ``overrides`` maps dotted keys
    (``"limits.a_max_mm_s2"``) to values applied on top of the file before validation; a string
    value is read as a TOML value (``"5e4"`` → 50000.0), so CLI options can pass text through.
    Raises ConfigError (bad content) or OutputError (file unreadable).
    """
    if path is None:
        return parse_machine(default_profile_text(), "<default machine>", overrides)
    try:
        with open(path, encoding="utf-8") as f:
            text = f.read()
    except (OSError, UnicodeDecodeError) as exc:
        raise OutputError(f"cannot read machine profile {path}: {exc}") from exc
    return parse_machine(text, str(path), overrides)


def parse_machine(text: str, source: str = "<string>", overrides: dict | None = None) -> Machine:
    """Parse and validate profile ``text``; ``source`` is used in error messages.

    See :func:`load_machine` for ``overrides``. A TOML syntax error is a ConfigError whose message
    carries tomllib's "(at line L, column C)".
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{source}: invalid TOML: {exc}") from exc
    except ValueError:  # an integer beyond Python's 4300-digit conversion limit
        raise ConfigError(f"{source}: invalid TOML: an integer has more than "
                          f"{sys.get_int_max_str_digits()} digits") from None
    overridden: set[str] = set()
    if overrides:
        data = copy.deepcopy(data)
        for key, value in overrides.items():
            _apply_override(data, str(key), value, source)
            overridden.add(str(key))
    return _build(data, _Reporter(source, overridden))


class _Reporter:
    """Builds ConfigError messages: "<source>: <key> <problem>", marking overridden keys."""

    def __init__(self, source: str, overridden: set[str]):
        self.source = source
        self.overridden = overridden

    def error(self, key: str, problem: str) -> ConfigError:
        note = " (set by override)" if key in self.overridden else ""
        return ConfigError(f"{self.source}: {key} {problem}{note}")


def _apply_override(data: dict, key: str, value, source: str) -> None:
    parts = key.split(".")
    schema = _SCHEMA
    table = data
    for i, part in enumerate(parts):
        if not isinstance(schema, dict) or part not in schema:
            raise ConfigError(f"{source}: override {key!r}: unknown key")
        schema = schema[part]
        if i < len(parts) - 1:
            sub = table.get(part)
            if sub is None:
                sub = table[part] = {}
            elif not isinstance(sub, dict):
                raise ConfigError(f"{source}: {'.'.join(parts[: i + 1])} must be a table")
            table = sub
    if isinstance(schema, dict):
        raise ConfigError(f"{source}: override {key!r} names a table; give a key inside it")
    if isinstance(value, str):
        try:
            value = tomllib.loads(f"v = {value}")["v"]
        except (tomllib.TOMLDecodeError, ValueError):
            raise ConfigError(f"{source}: override {key}: {value[:80]!r} is not a value") from None
    table[parts[-1]] = value


def _check_table(data, schema: dict, prefix: str, rep: _Reporter) -> None:
    """Structure and leaf checks against the schema (unknown, missing, type, range)."""
    if not isinstance(data, dict):
        raise rep.error(prefix or "profile", f"must be a table, got {data!r}")
    for key in data:
        if key not in schema:
            full = f"{prefix}.{key}" if prefix else key
            raise rep.error(full, "is not a known key")
    for key, sub in schema.items():
        full = f"{prefix}.{key}" if prefix else key
        if key not in data:
            if full in _OPTIONAL:
                continue
            raise rep.error(full, "is missing")
        if isinstance(sub, dict):
            _check_table(data[key], sub, full, rep)
        else:
            _check_leaf(data[key], sub, full, rep)


#: Largest count a profile may give (a 32-bit signed integer: what a card register holds).
_COUNT_MAX = 2**31 - 1


def _check_leaf(value, kind: str, key: str, rep: _Reporter) -> None:
    if kind == "count":
        if isinstance(value, bool) or not isinstance(value, int):
            raise rep.error(key, f"must be an integer, got {value!r}")
        if value < 1:
            raise rep.error(key, f"must be >= 1, got {_short(value)}")
        if value > _COUNT_MAX:
            raise rep.error(key, f"must be <= {_COUNT_MAX}, got {_short(value)}")
        return
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise rep.error(key, f"must be a number, got {value!r}")
    if isinstance(value, int) and abs(value) > sys.float_info.max:  # float() would overflow
        raise rep.error(key, f"is too large, got {_short(value)}")
    if not math.isfinite(value):
        raise rep.error(key, f"must be finite, got {value!r}")
    if kind == "pos" and not value > 0:
        raise rep.error(key, f"must be > 0, got {value!r}")


def _short(value: int) -> str:
    """An integer as text, its middle elided when it has more than 24 digits."""
    text = str(value)
    return text if len(text) <= 24 else f"{text[:10]}…{text[-6:]} ({len(text.lstrip('-'))} digits)"


def _axis_servo(table: dict, key: str, rep: _Reporter) -> AxisServo:
    model = AxisServo(**{c: float(table[c]) for c in SERVO_COEFFICIENTS})
    poles = model.poles()
    if not np.all(np.isfinite(poles)) or np.any(poles.real >= 0.0):
        worst = poles[np.argmax(poles.real)]
        raise rep.error(
            key,
            f"is unstable: pole at {worst:.6g} (a4 s^4 + a3 s^3 + a2 s^2 + a1 s + a0 must have "
            "all roots in the left half-plane)",
        )
    return model


def _build(data: dict, rep: _Reporter) -> Machine:
    _check_table(data, _SCHEMA, "", rep)
    lim = data["limits"]
    v_max_mm_s = lim["v_max_mm_min"] / _S_PER_MIN
    # Rapids: no rate in the paper, so an omitted rapid_mm_min means "rapids at V_max".
    rapid_mm_s = lim.get("rapid_mm_min", lim["v_max_mm_min"]) / _S_PER_MIN
    limits = Limits(
        v_max_mm_s=float(v_max_mm_s),
        rapid_mm_s=float(rapid_mm_s),
        a_max_mm_s2=float(lim["a_max_mm_s2"]),
        j_max_mm_s3=float(lim["j_max_mm_s3"]),
        chord_tolerance_mm=float(lim["chord_tolerance_um"]) * _MM_PER_UM,
        kappa_ref_per_mm=float(lim["kappa_ref_per_mm"]),
        contour_tolerance_mm=float(lim["contour_tolerance_um"]) * _MM_PER_UM,
        ph_tolerance_mm=float(lim["ph_tolerance_um"]) * _MM_PER_UM,
    )

    srv = data["servo"]
    servo = Servo(
        period_s=float(srv["period_ms"]) * _S_PER_MS,
        x=_axis_servo(srv["x"], "servo.x", rep),
        y=_axis_servo(srv["y"], "servo.y", rep),
        z=_axis_servo(srv["z"], "servo.z", rep) if "z" in srv else None,
    )

    st = data["steps"]
    steps = Steps(
        per_mm=tuple(float(st["per_mm"][a]) for a in AXES),
        max_pulses_per_period=int(st["max_pulses_per_period"]),
    )
    # A pulse-train card cannot emit more than max_pulses_per_period steps per period on an axis;
    # an axis moving alone at the fastest rate (max of V_max and the rapid rate) must fit.
    v_top_mm_s = max(limits.v_max_mm_s, limits.rapid_mm_s)
    for a, per_mm in zip(AXES, steps.per_mm, strict=True):
        need = v_top_mm_s * servo.period_s * per_mm
        if need > steps.max_pulses_per_period:
            raise rep.error(
                "steps.max_pulses_per_period",
                f"= {steps.max_pulses_per_period} is too small: axis {a} at {v_top_mm_s:.6g} "
                f"mm/s needs {need:.6g} steps per {servo.period_s * 1e3:.6g} ms period "
                f"(steps.per_mm.{a} = {per_mm:.6g})",
            )

    sl = data["soft_limits"]
    for a in AXES:
        lo, hi = sl[a]["min_mm"], sl[a]["max_mm"]
        if not lo < hi:
            raise rep.error(
                f"soft_limits.{a}.min_mm", f"({lo!r}) must be < soft_limits.{a}.max_mm ({hi!r})"
            )
    soft = SoftLimits(
        min_mm=tuple(float(sl[a]["min_mm"]) for a in AXES),
        max_mm=tuple(float(sl[a]["max_mm"]) for a in AXES),
    )
    return Machine(limits=limits, servo=servo, steps=steps, soft_limits=soft, source=rep.source)
