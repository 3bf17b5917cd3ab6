"""The machine profile: every limit and model the planner uses (SPEC §7-§9), from TOML.

A profile is a TOML file (the default one, the paper's benchmark machine, ships as
``nurbscnc/data/default_machine.toml``). The file speaks the units users think in (mm/min, um,
ms); :class:`Machine` holds the same values in the program's internal units (mm, s), each field
named with its unit. Everything is validated on load: a bad value raises
:class:`~nurbscnc.errors.ConfigError` whose message names the dotted key.

The feed formulas the planner and the baselines share (chord-error feed, curvature feed,
sharp-corner curvature threshold) live in :mod:`nurbscnc.machine.caps`; :class:`Machine`
offers them with its own parameters filled in.

Which file: :func:`find_machine` implements the discovery order (``--machine``,
``$NURBSCNC_MACHINE``, ``./nurbscnc.toml``, the user's config folder, the bundled default);
:class:`Machine` remembers where it came from (``source``) and how it was found (``found_by``).

The servo section is optional, and each axis model may be the paper's 4th-order model (SPEC
eq. 25) or a 2nd-order model given by its bandwidth and damping (:meth:`AxisServo.second_order`);
with no axis model the contour check is off (``Machine.servo.modelled`` is False).
"""

from __future__ import annotations

import copy
import math
import os
import sys
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources

import numpy as np

from nurbscnc.errors import ConfigError, OutputError
from nurbscnc.machine import caps

#: The machine axes, in the order every per-axis tuple uses.
AXES = ("x", "y", "z")
#: Servo model coefficients of SPEC eq. 25, in the profile's key order.
SERVO_COEFFICIENTS = ("a0", "a1", "a2", "a3", "a4", "b0", "b1", "b2")
#: Keys of the simple (2nd-order) servo form.
SERVO_SIMPLE = ("bandwidth_hz", "damping")
#: Largest damping ratio of the simple form (see :meth:`AxisServo.second_order`).
MAX_DAMPING = 2.0
#: Keys of an ``[axis_limits.<axis>]`` table: velocity [mm/min] (like ``limits.v_max_mm_min``),
#: acceleration [mm/s²] and jerk [mm/s³] of that axis alone.
AXIS_LIMIT_KEYS = ("v_max_mm_min", "a_max_mm_s2", "j_max_mm_s3")
#: Servo period when the profile gives none [ms] (SPEC §9).
DEFAULT_PERIOD_MS = 1.0

#: Environment variable naming a profile (discovery step 2).
ENV_MACHINE = "NURBSCNC_MACHINE"
#: Profile file looked for in the current folder (discovery step 3).
LOCAL_PROFILE = "nurbscnc.toml"
#: How a profile was found (``Machine.found_by``), in discovery order.
FOUND_BY_OPTION = "--machine"
FOUND_BY_ENV = "$" + ENV_MACHINE
FOUND_BY_LOCAL = "./" + LOCAL_PROFILE
FOUND_BY_USER = "user config"
FOUND_BY_DEFAULT = "bundled default"

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
# An axis table holds one of two forms (checked by _check_axis): the coefficients, or the
# simple form. The schema lists the union so that overrides can name either form's keys.
_AXIS_SCHEMA = {**_COEFF_SCHEMA, "bandwidth_hz": "pos", "damping": "pos"}
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
        "path_tolerance_um": "pos",
        "max_points": "count",
    },
    "servo": {"period_ms": "pos", "x": _AXIS_SCHEMA, "y": _AXIS_SCHEMA, "z": _AXIS_SCHEMA},
    "steps": {"max_pulses_per_period": "count", "per_mm": {a: "pos" for a in AXES}},
    "soft_limits": {a: {"min_mm": "finite", "max_mm": "finite"} for a in AXES},
    # Per-axis limits (issue 13), beside the path limits of [limits]: a table per axis, every
    # key optional (an absent key leaves that axis to the path limits alone).
    "axis_limits": {a: dict.fromkeys(AXIS_LIMIT_KEYS, "pos") for a in AXES},
}
_OPTIONAL = frozenset(
    {"limits.rapid_mm_min", "limits.max_points", "limits.path_tolerance_um", "servo",
     "servo.period_ms", "servo.x", "servo.y", "servo.z"}
)
# [axis_limits]: every table and every key optional.
_OPTIONAL |= {"axis_limits", *(f"axis_limits.{a}" for a in AXES),
              *(f"axis_limits.{a}.{k}" for a in AXES for k in AXIS_LIMIT_KEYS)}  # fmt: skip

_MM_PER_UM = 1e-3
#: Default of ``limits.max_points``: 50 million reference points, 13.9 h of motion at 1 ms
#: (a few GB of samples in memory today).
DEFAULT_MAX_POINTS = 50_000_000
_S_PER_MS = 1e-3
_S_PER_MIN = 60.0


# ---------------------------------------------------------------------------------------------
# Derived feed formulas: defined in nurbscnc.machine.caps (SPEC §5 and §7).


def _as_result(values: np.ndarray):
    """A float for a 0-d result, else the array itself."""
    return float(values) if values.ndim == 0 else values


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
    #: Most reference points a program may make (one per servo period): checked before
    #: anything is sampled, so a program whose motion takes days fails at its line, quickly.
    max_points: int = DEFAULT_MAX_POINTS
    #: The machine's path tolerance [mm]: how far G64 without P may blend a corner away from
    #: the programmed path (LinuxCNC's G64 "best speed", bounded here). None: ε_max.
    path_tolerance_mm: float | None = None

    def __post_init__(self):
        if self.path_tolerance_mm is None:
            object.__setattr__(self, "path_tolerance_mm", self.contour_tolerance_mm)


def natural_frequency_rad_s(bandwidth_hz: float, damping: float) -> float:
    """ω_n [rad/s] of G(s) = ω_n²/(s² + 2ζω_n s + ω_n²) whose −3 dB bandwidth is ``bandwidth_hz``.

    |G(jω)|² = 1/((1 − u²)² + 4ζ²u²) with u = ω/ω_n equals 1/2 where
    u⁴ + (4ζ² − 2)u² − 1 = 0, whose one positive root is u² = 1 − 2ζ² + √(4ζ⁴ − 4ζ² + 2).
    So ω_n = 2π f_bw / √(1 − 2ζ² + √(4ζ⁴ − 4ζ² + 2)); for ζ = 1/√2, ω_n = 2π f_bw.
    """
    c = 1.0 - 2.0 * damping * damping
    r = math.sqrt(c * c + 1.0)  # = √(4ζ⁴ − 4ζ² + 2)
    # c + r without cancellation: for c < 0 use the product of the roots, (c + r)(r − c) = 1.
    u2 = c + r if c >= 0.0 else 1.0 / (r - c)
    return 2.0 * math.pi * bandwidth_hz / math.sqrt(u2)


@dataclass(frozen=True)
class AxisServo:
    """One axis's closed-loop position model (SPEC eq. 25, Table 2).

    G(s) = (b2 s² + b1 s + b0) / (a4 s⁴ + a3 s³ + a2 s² + a1 s + a0), s in 1/s.

    The simple form (:meth:`second_order`) sets ``bandwidth_hz`` and ``damping`` and holds the
    same 2nd-order model in these eq.-25 coefficients, so every consumer of eq. 25 (planner,
    simulation) uses it unchanged; ``poles()`` then gives the model's own two poles.
    """

    a0: float
    a1: float
    a2: float
    a3: float
    a4: float
    b0: float
    b1: float
    b2: float
    bandwidth_hz: float | None = None  #: −3 dB bandwidth of the simple form, else None
    damping: float | None = None  #: damping ratio ζ of the simple form, else None

    @classmethod
    def second_order(cls, bandwidth_hz: float, damping: float) -> AxisServo:
        """G(s) = ω_n²/(s² + 2ζω_n s + ω_n²), ω_n from :func:`natural_frequency_rad_s`.

        Written in eq.-25 form by multiplying numerator and denominator by (s + p)² with
        p = 10 ω_n: G = ω_n²(s + p)² / ((s² + 2ζω_n s + ω_n²)(s + p)²), the same transfer
        function (the pair at −p cancels exactly; it is never a pole of the 2nd-order part for
        ζ ≤ MAX_DAMPING, whose poles lie within ω_n(ζ + √(ζ² − 1)) < 4 ω_n of the origin).
        """
        wn = natural_frequency_rad_s(bandwidth_hz, damping)
        p = 10.0 * wn
        d2, d1, d0 = 1.0, 2.0 * damping * wn, wn * wn  # s² + 2ζω_n s + ω_n²
        q2, q1, q0 = 1.0, 2.0 * p, p * p  # (s + p)²
        return cls(
            a4=d2 * q2,
            a3=d2 * q1 + d1 * q2,
            a2=d2 * q0 + d1 * q1 + d0 * q2,
            a1=d1 * q0 + d0 * q1,
            a0=d0 * q0,
            b2=d0 * q2,
            b1=d0 * q1,
            b0=d0 * q0,
            bandwidth_hz=float(bandwidth_hz),
            damping=float(damping),
        )

    @property
    def simple(self) -> bool:
        """True for the bandwidth/damping form."""
        return self.bandwidth_hz is not None

    @property
    def natural_frequency_rad_s(self) -> float | None:
        """ω_n [rad/s] of the simple form, else None."""
        if not self.simple:
            return None
        return natural_frequency_rad_s(self.bandwidth_hz, self.damping)

    @property
    def numerator(self) -> tuple[float, float, float]:
        """Numerator coefficients, highest power first (scipy.signal order)."""
        return (self.b2, self.b1, self.b0)

    @property
    def denominator(self) -> tuple[float, float, float, float, float]:
        """Denominator coefficients, highest power first (scipy.signal order)."""
        return (self.a4, self.a3, self.a2, self.a1, self.a0)

    def poles(self) -> np.ndarray:
        """The closed-loop poles [1/s]: roots of the denominator, or of s² + 2ζω_n s + ω_n²
        for the simple form (without the cancelled pair of :meth:`second_order`)."""
        if self.simple:
            wn = self.natural_frequency_rad_s
            return np.roots([1.0, 2.0 * self.damping * wn, wn * wn])
        return np.roots(self.denominator)

    @property
    def dc_gain(self) -> float:
        """G(0) = b0/a0 (1 for a servo with integral action)."""
        return self.b0 / self.a0


@dataclass(frozen=True)
class Servo:
    """Servo period and per-axis models; an axis model None means that axis follows its
    reference exactly (no lag). With no model at all (``modelled`` False) the contour check
    is off."""

    period_s: float  #: T_s, one reference point per period
    x: AxisServo | None = None
    y: AxisServo | None = None
    z: AxisServo | None = None

    def axis(self, name: str) -> AxisServo | None:
        """The model of axis ``name`` ("x", "y", "z"); None means an ideal axis."""
        return getattr(self, name)

    @property
    def modelled(self) -> bool:
        """True when at least one axis has a model: the contour check can run."""
        return any(self.axis(a) is not None for a in AXES)


@dataclass(frozen=True)
class AxisLimits:
    """Per-axis limits (x, y, z), each axis on its own [mm, s]; ``inf`` where the profile sets
    none (that axis is then bounded by the path limits alone). The planner turns them into
    path limits per piece (:func:`nurbscnc.plan.axes.piece_limits`)."""

    v_max_mm_s: tuple[float, float, float] = (math.inf,) * 3  #: axis velocity limit
    a_max_mm_s2: tuple[float, float, float] = (math.inf,) * 3  #: axis acceleration limit
    j_max_mm_s3: tuple[float, float, float] = (math.inf,) * 3  #: axis jerk limit

    @property
    def any(self) -> bool:
        """True when some axis has some limit (False: the path limits alone apply)."""
        return any(math.isfinite(x) for x in (*self.v_max_mm_s, *self.a_max_mm_s2,
                                              *self.j_max_mm_s3))  # fmt: skip

    def as_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(3,) arrays of the velocity [mm/s], acceleration [mm/s²], jerk [mm/s³] limits."""
        return (np.array(self.v_max_mm_s, dtype=float), np.array(self.a_max_mm_s2, dtype=float),
                np.array(self.j_max_mm_s3, dtype=float))


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
    """A validated machine profile in internal units (mm, s).

    ``source`` is the file it came from (``"<default machine>"`` for the bundled one),
    ``found_by`` how it was chosen (one of the ``FOUND_BY_*`` constants), ``settings`` the
    effective profile in the file's units (the TOML tables after overrides, optional keys
    filled in with their defaults), for ``profile show``. ``axis_limits`` the optional
    per-axis limits (none: the path limits of ``limits`` alone).
    """

    limits: Limits
    servo: Servo
    steps: Steps
    soft_limits: SoftLimits
    source: str = "<default>"
    found_by: str = FOUND_BY_DEFAULT
    settings: dict = field(default_factory=dict, compare=False, repr=False)
    axis_limits: AxisLimits = field(default_factory=AxisLimits)

    @property
    def contour_check(self) -> bool:
        """Whether the planner's contour (dynamics) check applies: some axis has a model."""
        return self.servo.modelled

    def describe(self) -> str:
        """"<file> (<how it was found>)", for command summaries."""
        if self.found_by == FOUND_BY_DEFAULT:
            return "bundled default (the paper's machine, nurbscnc/data/default_machine.toml)"
        return f"{self.source} ({self.found_by})"

    def kappa_threshold_per_mm(self, feed_mm_s):
        """κ_th = A_max / F² [1/mm] at programmed feed ``feed_mm_s`` (SPEC §5)."""
        return caps.kappa_threshold_per_mm(feed_mm_s, self.limits.a_max_mm_s2)

    def chord_feed_mm_s(self, kappa_per_mm):
        """V_af at curvature ``kappa_per_mm`` with this machine's T_s and δ (SPEC eq. 23)."""
        return caps.chord_feed_mm_s(kappa_per_mm, self.servo.period_s,
                                    self.limits.chord_tolerance_mm)  # fmt: skip

    def curvature_feed_mm_s(self, kappa_per_mm, feed_mm_s: float | None = None):
        """V_cf with κ̄ of this machine (SPEC eq. 24); ``feed_mm_s`` defaults to V_max."""
        v = self.limits.v_max_mm_s if feed_mm_s is None else feed_mm_s
        return caps.curvature_feed_mm_s(kappa_per_mm, v, self.limits.kappa_ref_per_mm)

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


def user_profile_path(environ: Mapping[str, str] | None = None) -> str:
    """The user's profile: ``$XDG_CONFIG_HOME/nurbscnc/machine.toml``, or
    ``~/.config/nurbscnc/machine.toml`` when XDG_CONFIG_HOME is unset, empty or relative (as
    the XDG base-directory spec says)."""
    env = os.environ if environ is None else environ
    base = env.get("XDG_CONFIG_HOME", "")
    if not os.path.isabs(base):
        home = env.get("HOME") or os.path.expanduser("~")
        base = os.path.join(home, ".config")
    return os.path.join(base, "nurbscnc", "machine.toml")


def find_machine(
    path: str | None = None, environ: Mapping[str, str] | None = None, cwd: str | None = None
) -> tuple[str | None, str]:
    """Which profile to load: (file or None for the bundled default, how it was found).

    Order, first match wins: ``path`` (``--machine``); ``$NURBSCNC_MACHINE`` when set and
    non-empty (a missing file is then an error when it is read, never skipped); ``nurbscnc.toml``
    in ``cwd`` (default: the current folder) if it exists; :func:`user_profile_path` if it
    exists; the bundled default. ``environ`` defaults to ``os.environ``.
    """
    env = os.environ if environ is None else environ
    if path is not None:
        return str(path), FOUND_BY_OPTION
    if env.get(ENV_MACHINE):
        return env[ENV_MACHINE], FOUND_BY_ENV
    local = os.path.join(cwd, LOCAL_PROFILE) if cwd is not None else LOCAL_PROFILE
    if os.path.isfile(local):
        return (local if cwd is not None else FOUND_BY_LOCAL), FOUND_BY_LOCAL
    user = user_profile_path(env)
    if os.path.isfile(user):
        return user, FOUND_BY_USER
    return None, FOUND_BY_DEFAULT


#: The longest machine profile read [characters] (the bundled one has about 9,000).
MAX_PROFILE_CHARS = 1 << 20


def load_machine(
    path: str | None = None, overrides: dict | None = None, found_by: str | None = None
) -> Machine:
    """Load and validate a machine profile.

    ``path`` None loads the packaged default. ``overrides`` maps dotted keys
    (``"limits.a_max_mm_s2"``) to values applied on top of the file before validation; a string
    value is read as a TOML value (``"5e4"`` → 50000.0), so CLI options can pass text through.
    ``found_by`` is recorded in ``Machine.found_by`` (default: ``--machine`` for a path, else
    the bundled default). Raises ConfigError (bad content) or OutputError (file unreadable).
    """
    if path is None:
        m = parse_machine(default_profile_text(), "<default machine>", overrides)
        return _with_origin(m, found_by or FOUND_BY_DEFAULT)
    how = f" (from {found_by})" if found_by not in (None, FOUND_BY_OPTION) else ""
    try:
        with open(path, encoding="utf-8") as f:
            text = f.read(MAX_PROFILE_CHARS + 1)
    except (OSError, UnicodeDecodeError) as exc:
        raise OutputError(f"cannot read machine profile {path}{how}: {exc}") from exc
    if len(text) > MAX_PROFILE_CHARS:  # /dev/zero: a stream that never ends
        raise ConfigError(f"machine profile {path}{how} is longer than "
                          f"{MAX_PROFILE_CHARS:,} characters: not a profile")
    return _with_origin(parse_machine(text, str(path), overrides), found_by or FOUND_BY_OPTION)


def _with_origin(machine: Machine, found_by: str) -> Machine:
    return Machine(machine.limits, machine.servo, machine.steps, machine.soft_limits,
                   machine.source, found_by, machine.settings, machine.axis_limits)  # fmt: skip


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
    if len(parts) == 3 and parts[0] == "servo":
        # Setting a key of one servo form replaces the other form in that axis's table, so
        # that --set servo.x.bandwidth_hz=… works on a profile with coefficients (and back).
        other = SERVO_COEFFICIENTS if parts[2] in SERVO_SIMPLE else SERVO_SIMPLE
        for k in other:
            table.pop(k, None)
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
        if sub is _AXIS_SCHEMA:
            _check_axis(data[key], full, rep)
        elif isinstance(sub, dict):
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


def _check_axis(data, key: str, rep: _Reporter) -> None:
    """An axis model table: either all of a0…b2 or both of bandwidth_hz and damping."""
    if not isinstance(data, dict):
        raise rep.error(key, f"must be a table, got {data!r}")
    simple = [k for k in SERVO_SIMPLE if k in data]
    coeffs = [k for k in SERVO_COEFFICIENTS if k in data]
    if simple and coeffs:
        raise rep.error(
            key, f"mixes the two model forms ({coeffs[0]} and {simple[0]}): give either a0…b2 "
            "(SPEC eq. 25) or bandwidth_hz and damping"
        )  # fmt: skip
    schema = {k: _AXIS_SCHEMA[k] for k in (SERVO_SIMPLE if simple else SERVO_COEFFICIENTS)}
    _check_table(data, schema, key, rep)
    if simple and data["damping"] > MAX_DAMPING:
        raise rep.error(f"{key}.damping", f"must be <= {MAX_DAMPING:g}, got {data['damping']!r}")


def _short(value: int) -> str:
    """An integer as text, its middle elided when it has more than 24 digits."""
    text = str(value)
    return text if len(text) <= 24 else f"{text[:10]}…{text[-6:]} ({len(text.lstrip('-'))} digits)"


def _axis_servo(table: dict, key: str, rep: _Reporter) -> AxisServo:
    if "bandwidth_hz" in table:
        return AxisServo.second_order(float(table["bandwidth_hz"]), float(table["damping"]))
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
        max_points=int(lim.get("max_points", DEFAULT_MAX_POINTS)),
        path_tolerance_mm=float(lim.get("path_tolerance_um", lim["contour_tolerance_um"]))
        * _MM_PER_UM,
    )

    srv = data.get("servo", {})
    servo = Servo(
        period_s=float(srv.get("period_ms", DEFAULT_PERIOD_MS)) * _S_PER_MS,
        **{a: _axis_servo(srv[a], f"servo.{a}", rep) for a in AXES if a in srv},
    )

    st = data["steps"]
    steps = Steps(
        per_mm=tuple(float(st["per_mm"][a]) for a in AXES),
        max_pulses_per_period=int(st["max_pulses_per_period"]),
    )
    axis_limits = _axis_limits(data.get("axis_limits", {}))
    # A pulse-train card cannot emit more than max_pulses_per_period steps per period on an axis;
    # an axis moving alone at the fastest rate (max of V_max and the rapid rate, or that axis's
    # own velocity limit when lower) must fit.
    v_path_top_mm_s = max(limits.v_max_mm_s, limits.rapid_mm_s)
    for a, per_mm, v_axis in zip(AXES, steps.per_mm, axis_limits.v_max_mm_s, strict=True):
        v_top_mm_s = min(v_path_top_mm_s, v_axis)
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
    # The effective settings: the tables as given, optional keys filled in with their defaults.
    settings = copy.deepcopy(data)
    settings["limits"].setdefault("rapid_mm_min", lim["v_max_mm_min"])
    settings["limits"].setdefault("max_points", DEFAULT_MAX_POINTS)
    settings["limits"].setdefault("path_tolerance_um", lim["contour_tolerance_um"])
    settings.setdefault("servo", {}).setdefault("period_ms", DEFAULT_PERIOD_MS)
    settings["servo"] = {"period_ms": settings["servo"].pop("period_ms"), **settings["servo"]}
    return Machine(limits=limits, servo=servo, steps=steps, soft_limits=soft, source=rep.source,
                   settings=settings, axis_limits=axis_limits)  # fmt: skip


def _axis_limits(tables: dict) -> AxisLimits:
    """The validated ``[axis_limits]`` tables in internal units (absent keys: ``inf``)."""

    def per_axis(key: str, scale: float) -> tuple[float, float, float]:
        return tuple(float(tables.get(a, {}).get(key, math.inf)) * scale for a in AXES)

    return AxisLimits(v_max_mm_s=per_axis("v_max_mm_min", 1.0 / _S_PER_MIN),
                      a_max_mm_s2=per_axis("a_max_mm_s2", 1.0),
                      j_max_mm_s3=per_axis("j_max_mm_s3", 1.0))  # fmt: skip


# ---------------------------------------------------------------------------------------------
# The effective profile as text (``nurbscnc profile show``).


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    return repr(float(value))  # shortest round-trip form; valid TOML (validated finite)


def _ordered(table: dict, schema) -> list[str]:
    """Keys of ``table`` in schema order (the order of the template)."""
    order = list(schema) if isinstance(schema, dict) else []
    return sorted(table, key=lambda k: order.index(k) if k in order else len(order))


def _pole_text(p: complex) -> str:
    return f"{p.real:.6g}" if p.imag == 0.0 else f"{p.real:.6g}{p.imag:+.6g}j"


def profile_toml(machine: Machine) -> str:
    """``machine.settings`` as TOML, in the template's key order, with a header saying where
    the profile came from and, per servo axis, its poles (and ω_n for the simple form)."""
    lines = [f"# machine profile: {machine.describe()}"]
    if not machine.contour_check:
        lines.append("# no servo model: contour check off")

    def emit(table: dict, schema, prefix: str) -> None:
        keys = _ordered(table, schema)
        leaves = [k for k in keys if not isinstance(table[k], dict)]
        if prefix and leaves:
            lines.extend(["", f"[{prefix}]"])
            axis = machine.servo.axis(prefix[6:]) if prefix in ("servo.x", "servo.y",
                                                                   "servo.z") else None
            if axis is not None:
                poles = ", ".join(_pole_text(p) for p in axis.poles())
                wn = axis.natural_frequency_rad_s
                extra = f"; wn = {wn:.6g} rad/s" if wn is not None else ""
                lines.append(f"# poles [1/s]: {poles}{extra}")
        lines.extend(f"{k} = {_toml_value(table[k])}" for k in leaves)
        for k in keys:
            if isinstance(table[k], dict):
                sub = schema.get(k, {}) if isinstance(schema, dict) else {}
                emit(table[k], sub, f"{prefix}.{k}" if prefix else k)

    emit(machine.settings, _SCHEMA, "")
    return "\n".join(lines) + "\n"


def profile_info(machine: Machine) -> dict:
    """Where the profile came from, for every command's JSON (key ``machine_profile``)."""
    return {
        "path": None if machine.found_by == FOUND_BY_DEFAULT else machine.source,
        "found_by": machine.found_by,
        "contour_check": machine.contour_check,
    }
