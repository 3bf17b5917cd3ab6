"""The machine profile's schema: its tables and keys, the value checks of every leaf, the
``--set`` overrides applied to a parsed file, and the units the file speaks (SPEC §7-§9)."""

from __future__ import annotations

import math
import sys
import tomllib

from nurbscnc.errors import ConfigError

#: The machine axes, in the order every per-axis tuple uses.
AXES = ("x", "y", "z")
#: The rotary axes a profile may declare (an ``[axis_limits.<a|b|c>]`` table each), degrees.
ROTARY_AXES = ("a", "b", "c")
#: Servo model coefficients of SPEC eq. 25, in the profile's key order.
SERVO_COEFFICIENTS = ("a0", "a1", "a2", "a3", "a4", "b0", "b1", "b2")
#: Keys of the simple (2nd-order) servo form.
SERVO_SIMPLE = ("bandwidth_hz", "damping")
#: Largest damping ratio of the simple form (see :meth:`AxisServo.second_order`).
MAX_DAMPING = 2.0
#: Keys of an ``[axis_limits.<axis>]`` table: velocity [mm/min] (like ``limits.v_max_mm_min``),
#: acceleration [mm/s²] and jerk [mm/s³] of that axis alone.
AXIS_LIMIT_KEYS = ("v_max_mm_min", "a_max_mm_s2", "j_max_mm_s3")
#: Keys of a rotary axis's ``[axis_limits.<a|b|c>]`` table: velocity [deg/min], acceleration
#: [deg/s²], jerk [deg/s³] (required: the table declares the axis), then the optional soft
#: limits [deg, machine coordinates], LinuxCNC's ``WRAPPED_ROTARY`` and the card's steps per
#: degree.
ROTARY_LIMIT_KEYS = ("v_max_deg_min", "a_max_deg_s2", "j_max_deg_s3")
ROTARY_OPTIONAL_KEYS = ("min_deg", "max_deg", "wrapped", "steps_per_deg")
_ROTARY_SCHEMA = {
    **dict.fromkeys(ROTARY_LIMIT_KEYS, "pos"),
    "min_deg": "finite",
    "max_deg": "finite",
    "wrapped": "bool",
    "steps_per_deg": "pos",
}
#: Servo period when the profile gives none [ms] (SPEC §9).
DEFAULT_PERIOD_MS = 1.0

# ---------------------------------------------------------------------------------------------
# Schema. A table is a dict of key -> sub-schema; a leaf is the name of a value check:
#   "pos"    a finite number > 0        "finite"  any finite number
#   "count"  an integer >= 1          "text"    a string (a path)
#   "bool"   true or false
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
SCHEMA: dict = {
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
    # Per-axis limits, beside the path limits of [limits]: a table per axis, every
    # key optional (an absent key leaves that axis to the path limits alone).
    # A rotary axis's table (a, b, c) declares the axis: its v, a, j are required.
    "axis_limits": {
        **{a: dict.fromkeys(AXIS_LIMIT_KEYS, "pos") for a in AXES},
        **{a: _ROTARY_SCHEMA for a in ROTARY_AXES},
    },
    # How programs run on this machine: LinuxCNC's parameter file (work offsets, G92, G28/G30
    # positions) and its user M-code path ([RS274NGC]USER_M_PATH: colon-separated folders).
    # Relative paths are relative to the profile's folder. user_m_timeout_s: the longest a
    # user M-code's executable may run (stream --user-m-timeout overrides it).
    "program": {"var_file": "text", "user_m_path": "text", "user_m_timeout_s": "pos"},
}
_OPTIONAL = frozenset(
    {
        "limits.rapid_mm_min",
        "limits.max_points",
        "limits.path_tolerance_um",
        "servo",
        "servo.period_ms",
        "servo.x",
        "servo.y",
        "servo.z",
    }
)
_OPTIONAL |= {"program", "program.var_file", "program.user_m_path", "program.user_m_timeout_s"}
# [axis_limits]: every table and every key optional.
_OPTIONAL |= {
    "axis_limits",
    *(f"axis_limits.{a}" for a in AXES),
    *(f"axis_limits.{a}.{k}" for a in AXES for k in AXIS_LIMIT_KEYS),
    *(f"axis_limits.{a}" for a in ROTARY_AXES),
    *(f"axis_limits.{a}.{k}" for a in ROTARY_AXES for k in ROTARY_OPTIONAL_KEYS),
}

# ---------------------------------------------------------------------------------------------
# Physically meaningful ranges [low, high] of the numeric leaves, in the file's units, checked
# before any work (a contour tolerance of 1e-300 um would make the planner lower the feed
# for minutes; a period of 1e-300 ms would ask for 1e303 reference points). ``*`` stands for
# any axis. The bounds are generous: a few decades beyond any machine tool on either side.
RANGES: dict[str, tuple[float, float]] = {
    # mm/min: 1 um/min (a creep feed) to 1000 m/min (ten times the fastest linear motors)
    "limits.v_max_mm_min": (1e-3, 1e6),
    "limits.rapid_mm_min": (1e-3, 1e6),
    "axis_limits.*.v_max_mm_min": (1e-3, 1e6),
    # mm/s^2: 1 um/s^2 to 100 g
    "limits.a_max_mm_s2": (1e-3, 1e6),
    "axis_limits.*.a_max_mm_s2": (1e-3, 1e6),
    # mm/s^3: 1 um/s^3 to 1e9 (a linear motor reaches 1e7)
    "limits.j_max_mm_s3": (1e-3, 1e9),
    "axis_limits.*.j_max_mm_s3": (1e-3, 1e9),
    # rotary axes: 0.001 deg/min (a creep) to 1e8 deg/min (4600 rev/s, beyond any spindle
    # run as an axis); deg/s^2 and deg/s^3 as wide; soft limits within the interpreter's
    # coordinate bound; steps per degree as steps.per_mm
    "axis_limits.*.v_max_deg_min": (1e-3, 1e8),
    "axis_limits.*.a_max_deg_s2": (1e-3, 1e9),
    "axis_limits.*.j_max_deg_s3": (1e-3, 1e12),
    "axis_limits.*.min_deg": (-1e9, 1e9),
    "axis_limits.*.max_deg": (-1e9, 1e9),
    "axis_limits.*.steps_per_deg": (1e-3, 1e7),
    # um: 10 nm (ultra-precision) to 10 mm. The contour tolerance stops at 0.1 um, a tenth
    # of the default 1 um step: below it the check's re-plans grow without end (0.1 um takes
    # 4.5 s on programs/naca2415.nc, 0.01 um more than 120 s) for an error no pulse shows.
    "limits.chord_tolerance_um": (1e-2, 1e4),
    "limits.contour_tolerance_um": (1e-1, 1e4),
    "limits.ph_tolerance_um": (1e-2, 1e4),
    "limits.path_tolerance_um": (1e-2, 1e4),
    # 1/mm: a 1 km radius to a 1 um radius
    "limits.kappa_ref_per_mm": (1e-6, 1e3),
    # ms: 10 us to 100 ms per reference point
    "servo.period_ms": (1e-2, 1e2),
    # Hz, and the damping ratio (MAX_DAMPING is its upper end)
    "servo.*.bandwidth_hz": (1e-2, 1e5),
    "servo.*.damping": (1e-2, MAX_DAMPING),
    # SPEC eq. 25's coefficients [1/s^k]: any scale, short of the double's own range (their
    # products in the poles' polynomial must not overflow or vanish)
    **{f"servo.*.{c}": (-1e60, 1e60) for c in ("a0", "a1", "a2", "a3", "b1", "b2")},
    "servo.*.a4": (1e-60, 1e60),
    "servo.*.b0": (1e-60, 1e60),
    # steps/mm: 1 step per m to 10 steps per nm
    "steps.per_mm.*": (1e-3, 1e7),
    # mm: the interpreter's coordinate limit (program/words.py MAX_COORD_MM)
    "soft_limits.*.min_mm": (-1e9, 1e9),
    "soft_limits.*.max_mm": (-1e9, 1e9),
}


def range_of(key: str) -> tuple[float, float] | None:
    """The :data:`RANGES` entry of a dotted key (an axis name matches ``*``), or None."""
    parts = key.split(".")
    for i, part in enumerate(parts):
        if part in AXES or part in ROTARY_AXES:
            wild = ".".join([*parts[:i], "*", *parts[i + 1 :]])
            if wild in RANGES:
                return RANGES[wild]
    return RANGES.get(key)


MM_PER_UM = 1e-3
#: Default of ``limits.max_points``: 50 million reference points, 13.9 h of motion at 1 ms
#: (a few GB of samples in memory today).
DEFAULT_MAX_POINTS = 50_000_000
S_PER_MS = 1e-3
S_PER_MIN = 60.0


class Reporter:
    """Builds ConfigError messages: "<source>: <key> <problem>", marking overridden keys."""

    def __init__(self, source: str, overridden: set[str]):
        self.source = source
        self.overridden = overridden

    def error(self, key: str, problem: str) -> ConfigError:
        note = " (set by override)" if key in self.overridden else ""
        return ConfigError(f"{self.source}: {key} {problem}{note}")


def apply_override(data: dict, key: str, value, source: str) -> None:
    parts = key.split(".")
    schema = SCHEMA
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
    if isinstance(value, str) and schema == "text":
        # a path: the text as given (quotes optional)
        if len(value) >= 2 and value[0] == value[-1] and value[0] in "\"'":
            value = value[1:-1]
    elif isinstance(value, str):
        try:
            value = tomllib.loads(f"v = {value}")["v"]
        except (tomllib.TOMLDecodeError, ValueError, RecursionError):
            # (RecursionError: arrays nested too deep for tomllib's recursive parser)
            raise ConfigError(f"{source}: override {key}: {value[:80]!r} is not a value") from None
    if len(parts) == 3 and parts[0] == "servo":
        # Setting a key of one servo form replaces the other form in that axis's table, so
        # that --set servo.x.bandwidth_hz=… works on a profile with coefficients (and back).
        other = SERVO_COEFFICIENTS if parts[2] in SERVO_SIMPLE else SERVO_SIMPLE
        for k in other:
            table.pop(k, None)
    table[parts[-1]] = value


def check_table(data, schema: dict, prefix: str, rep: Reporter) -> None:
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
            check_table(data[key], sub, full, rep)
        else:
            _check_leaf(data[key], sub, full, rep)


#: Largest count a profile may give (a 32-bit signed integer: what a card register holds).
_COUNT_MAX = 2**31 - 1


def _check_leaf(value, kind: str, key: str, rep: Reporter) -> None:
    if kind == "text":
        if not isinstance(value, str) or "\0" in value:
            raise rep.error(key, f"must be a text (a path), got {value!r}")
        return
    if kind == "bool":
        if not isinstance(value, bool):
            raise rep.error(key, f"must be true or false, got {value!r}")
        return
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
    bounds = range_of(key)
    if bounds is not None and not bounds[0] <= value <= bounds[1]:
        raise rep.error(
            key,
            f"must be >= {bounds[0]:g} and <= {bounds[1]:g} (a physically meaningful range), "
            f"got {value!r}",
        )


def _check_axis(data, key: str, rep: Reporter) -> None:
    """An axis model table: either all of a0…b2 or both of bandwidth_hz and damping."""
    if not isinstance(data, dict):
        raise rep.error(key, f"must be a table, got {data!r}")
    simple = [k for k in SERVO_SIMPLE if k in data]
    coeffs = [k for k in SERVO_COEFFICIENTS if k in data]
    if simple and coeffs:
        raise rep.error(
            key,
            f"mixes the two model forms ({coeffs[0]} and {simple[0]}): give either a0…b2 "
            "(SPEC eq. 25) or bandwidth_hz and damping",
        )
    schema = {k: _AXIS_SCHEMA[k] for k in (SERVO_SIMPLE if simple else SERVO_COEFFICIENTS)}
    check_table(data, schema, key, rep)


def _short(value: int) -> str:
    """An integer as text, its middle elided when it has more than 24 digits."""
    text = str(value)
    return text if len(text) <= 24 else f"{text[:10]}…{text[-6:]} ({len(text.lstrip('-'))} digits)"


# ---------------------------------------------------------------------------------------------
# Defaults. A profile of one's own needs only the path limits of [limits] (v_max_mm_min,
# a_max_mm_s2, j_max_mm_s3): every other key has a documented default, which `profile show`
# marks as such. Unknown keys stay errors.

#: Default of ``steps.max_pulses_per_period`` (a signed byte, as the bundled card), raised to
#: what the profile's fastest axis needs when that is more (see :func:`default_max_pulses`).
DEFAULT_MAX_PULSES = 127
#: The fixed defaults [the file's units]: the paper's tolerances (Table 3) and the bundled
#: machine's servo period, resolution and travel. The derived ones (``limits.rapid_mm_min`` =
#: ``v_max_mm_min``, ``limits.path_tolerance_um`` = ``contour_tolerance_um``,
#: ``steps.max_pulses_per_period``) are filled where their sources are known.
DEFAULTS: dict = {
    "limits.chord_tolerance_um": 1.0,
    "limits.kappa_ref_per_mm": 1.0,
    "limits.contour_tolerance_um": 15.0,
    "limits.ph_tolerance_um": 1.0,
    "limits.max_points": DEFAULT_MAX_POINTS,
    "servo.period_ms": DEFAULT_PERIOD_MS,
    **{f"steps.per_mm.{a}": 1000.0 for a in AXES},
    **{f"soft_limits.{a}.{k}": v for a in AXES for k, v in (("min_mm", -1e3), ("max_mm", 1e3))},
}
_OPTIONAL |= {"steps.max_pulses_per_period"}


def fill_defaults(data: dict) -> set[str]:
    """Fill every key of :data:`DEFAULTS` that ``data`` (a parsed profile) leaves out, in
    place; returns the dotted keys filled. A table that is not a table is left alone (the
    schema check reports it)."""
    filled = set()
    for key, value in DEFAULTS.items():
        *tables, leaf = key.split(".")
        table = data
        for name in tables:
            table = table.setdefault(name, {})
            if not isinstance(table, dict):
                break
        else:
            if leaf not in table:
                table[leaf] = value
                filled.add(key)
    return filled


def default_max_pulses(need_per_period: float) -> int:
    """``steps.max_pulses_per_period`` when the profile gives none: :data:`DEFAULT_MAX_PULSES`,
    or the steps per period the fastest axis needs at the profile's top speed (rounded up)
    when that is more, so that the default never refuses the profile's own speeds."""
    return int(min(max(DEFAULT_MAX_PULSES, math.ceil(need_per_period - 1e-9)), _COUNT_MAX))
