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

This module reads a profile and builds the :class:`Machine`; the schema and its checks are in
:mod:`~nurbscnc.machine.schema`, the machine's types in :mod:`~nurbscnc.machine.model`, the
discovery in :mod:`~nurbscnc.machine.discovery`, the TOML printing in
:mod:`~nurbscnc.machine.show`.

The servo section is optional, and each axis model may be the paper's 4th-order model (SPEC
eq. 25) or a 2nd-order model given by its bandwidth and damping (:meth:`AxisServo.second_order`);
with no axis model the contour check is off (``Machine.servo.modelled`` is False).
"""

from __future__ import annotations

import copy
import math
import sys
import tomllib

import numpy as np

from nurbscnc.errors import ConfigError, OutputError
from nurbscnc.machine.discovery import (
    FOUND_BY_DEFAULT,
    FOUND_BY_OPTION,
    default_profile_text,
)
from nurbscnc.machine.discovery import find_machine as find_machine
from nurbscnc.machine.model import (
    AxisLimits,
    AxisServo,
    Limits,
    Machine,
    RotaryAxis,
    Servo,
    SoftLimits,
    Steps,
)
from nurbscnc.machine.schema import (
    AXES,
    DEFAULT_MAX_POINTS,
    DEFAULT_PERIOD_MS,
    MM_PER_UM,
    ROTARY_AXES,
    S_PER_MIN,
    S_PER_MS,
    SCHEMA,
    SERVO_COEFFICIENTS,
    Reporter,
    apply_override,
    check_table,
    default_max_pulses,
    fill_defaults,
)
from nurbscnc.machine.show import profile_info as profile_info
from nurbscnc.machine.show import profile_toml as profile_toml

# The profile's names are imported from here by every layer above (Machine, SoftLimits,
# AxisServo, AXES, find_machine, default_profile_text, profile_toml, profile_info): this module
# re-exports those defined beside it.

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
        raise ConfigError(
            f"machine profile {path}{how} is longer than "
            f"{MAX_PROFILE_CHARS:,} characters: not a profile"
        )
    return _with_origin(parse_machine(text, str(path), overrides), found_by or FOUND_BY_OPTION)


def _with_origin(machine: Machine, found_by: str) -> Machine:
    return Machine(
        machine.limits,
        machine.servo,
        machine.steps,
        machine.soft_limits,
        machine.source,
        found_by,
        machine.settings,
        machine.axis_limits,
        machine.defaults,
        machine.rotary_axes,
    )


def parse_machine(text: str, source: str = "<string>", overrides: dict | None = None) -> Machine:
    """Parse and validate profile ``text``; ``source`` is used in error messages.

    See :func:`load_machine` for ``overrides``. A TOML syntax error is a ConfigError whose message
    carries tomllib's "(at line L, column C)".
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{source}: invalid TOML: {exc}") from exc
    except RecursionError:  # tomllib parses nested arrays and inline tables recursively
        raise _too_deep(source) from None
    except ValueError:  # an integer beyond Python's 4300-digit conversion limit
        raise ConfigError(
            f"{source}: invalid TOML: an integer has more than "
            f"{sys.get_int_max_str_digits()} digits"
        ) from None
    if _depth_exceeds(data, MAX_NESTING):
        raise _too_deep(source)
    overridden: set[str] = set()
    if overrides:
        data = copy.deepcopy(data)
        for key, value in overrides.items():
            apply_override(data, str(key), value, source)
            overridden.add(str(key))
        if _depth_exceeds(data, MAX_NESTING):  # a value set by an override
            raise _too_deep(source)
    return _build(data, Reporter(source, overridden))


#: Deepest nesting of tables and arrays a profile may have: the schema goes three tables
#: deep (``axis_limits.x.a_max_mm_s2``); anything far deeper is not a profile, and is refused
#: before a recursive walk (a deep copy, a repr) could exhaust the stack.
MAX_NESTING = 32


def _too_deep(source: str) -> ConfigError:
    return ConfigError(
        f"{source}: invalid profile: arrays or tables nested more than {MAX_NESTING} deep"
    )


def _depth_exceeds(data, limit: int) -> bool:
    """Whether tables and arrays in ``data`` nest deeper than ``limit`` (an iterative walk)."""
    stack = [(data, 0)]  # the document itself is not nested
    while stack:
        value, depth = stack.pop()
        if depth > limit:
            return True
        if isinstance(value, dict):
            stack.extend((v, depth + 1) for v in value.values())
        elif isinstance(value, list):
            stack.extend((v, depth + 1) for v in value)
    return False


def _axis_servo(table: dict, key: str, rep: Reporter) -> AxisServo:
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


def _build(data: dict, rep: Reporter) -> Machine:
    defaults = fill_defaults(data)
    check_table(data, SCHEMA, "", rep)
    lim = data["limits"]
    defaults |= {f"limits.{k}" for k in ("rapid_mm_min", "path_tolerance_um") if k not in lim}
    v_max_mm_s = lim["v_max_mm_min"] / S_PER_MIN
    # Rapids: no rate in the paper, so an omitted rapid_mm_min means "rapids at V_max".
    rapid_mm_s = lim.get("rapid_mm_min", lim["v_max_mm_min"]) / S_PER_MIN
    limits = Limits(
        v_max_mm_s=float(v_max_mm_s),
        rapid_mm_s=float(rapid_mm_s),
        a_max_mm_s2=float(lim["a_max_mm_s2"]),
        j_max_mm_s3=float(lim["j_max_mm_s3"]),
        chord_tolerance_mm=float(lim["chord_tolerance_um"]) * MM_PER_UM,
        kappa_ref_per_mm=float(lim["kappa_ref_per_mm"]),
        contour_tolerance_mm=float(lim["contour_tolerance_um"]) * MM_PER_UM,
        ph_tolerance_mm=float(lim["ph_tolerance_um"]) * MM_PER_UM,
        max_points=int(lim.get("max_points", DEFAULT_MAX_POINTS)),
        path_tolerance_mm=float(lim.get("path_tolerance_um", lim["contour_tolerance_um"]))
        * MM_PER_UM,
    )

    srv = data.get("servo", {})
    servo = Servo(
        period_s=float(srv.get("period_ms", DEFAULT_PERIOD_MS)) * S_PER_MS,
        **{a: _axis_servo(srv[a], f"servo.{a}", rep) for a in AXES if a in srv},
    )

    st = data["steps"]
    axis_limits = _axis_limits(data.get("axis_limits", {}))
    rotary_axes = _rotary_axes(data.get("axis_limits", {}), rep)
    # A pulse-train card cannot emit more than max_pulses_per_period steps per period on an axis;
    # an axis moving alone at the fastest rate (max of V_max and the rapid rate, or that axis's
    # own velocity limit when lower) must fit; a rotary axis at its own v_max_deg_s (its rapid
    # rate) must fit too: v_max_deg_s · steps_per_deg · T_s steps per period.
    v_path_top_mm_s = max(limits.v_max_mm_s, limits.rapid_mm_s)
    rotary_steps = {
        name: axis.v_max_deg_s * servo.period_s * axis.steps_per_deg
        for name, axis in rotary_axes.items()
    }
    if "max_pulses_per_period" not in st:
        st["max_pulses_per_period"] = default_max_pulses(
            max(
                *(
                    min(v_path_top_mm_s, v_axis) * servo.period_s * float(st["per_mm"][a])
                    for a, v_axis in zip(AXES, axis_limits.v_max_mm_s, strict=True)
                ),
                *rotary_steps.values(),
            )
        )
        defaults.add("steps.max_pulses_per_period")
    steps = Steps(
        per_mm=tuple(float(st["per_mm"][a]) for a in AXES),
        max_pulses_per_period=int(st["max_pulses_per_period"]),
    )
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
    for name, need in rotary_steps.items():
        axis = rotary_axes[name]
        if need > steps.max_pulses_per_period:
            raise rep.error(
                "steps.max_pulses_per_period",
                f"= {steps.max_pulses_per_period} is too small: axis {name} at "
                f"{axis.v_max_deg_s:.6g} deg/s needs {need:.6g} steps per "
                f"{servo.period_s * 1e3:.6g} ms period (axis_limits.{name}.steps_per_deg = "
                f"{axis.steps_per_deg:.6g})",
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
    return Machine(
        limits=limits,
        servo=servo,
        steps=steps,
        soft_limits=soft,
        source=rep.source,
        settings=settings,
        axis_limits=axis_limits,
        defaults=frozenset(defaults),
        rotary_axes=rotary_axes,
    )


def _rotary_axes(tables: dict, rep: Reporter) -> dict:
    """The rotary axes ``{name: RotaryAxis}`` the ``[axis_limits.<a|b|c>]`` tables declare
    (schema-checked: v, a, j present), in internal units (deg/s, deg/s², deg/s³); soft limits
    ±inf where the table gives none, and ``min_deg`` < ``max_deg`` when both are given."""
    axes = {}
    for name in ROTARY_AXES:
        table = tables.get(name)
        if table is None:
            continue
        lo, hi = table.get("min_deg", -math.inf), table.get("max_deg", math.inf)
        if not lo < hi:
            raise rep.error(
                f"axis_limits.{name}.min_deg",
                f"({lo!r}) must be < axis_limits.{name}.max_deg ({hi!r})",
            )
        axes[name] = RotaryAxis(
            name,
            v_max_deg_s=float(table["v_max_deg_min"]) / S_PER_MIN,
            a_max_deg_s2=float(table["a_max_deg_s2"]),
            j_max_deg_s3=float(table["j_max_deg_s3"]),
            min_deg=float(lo),
            max_deg=float(hi),
            wrapped=bool(table.get("wrapped", False)),
            steps_per_deg=float(table.get("steps_per_deg", 0.0)),
        )
    return axes


def _axis_limits(tables: dict) -> AxisLimits:
    """The validated ``[axis_limits]`` tables in internal units (absent keys: ``inf``)."""

    def per_axis(key: str, scale: float) -> tuple[float, float, float]:
        return tuple(float(tables.get(a, {}).get(key, math.inf)) * scale for a in AXES)

    return AxisLimits(
        v_max_mm_s=per_axis("v_max_mm_min", 1.0 / S_PER_MIN),
        a_max_mm_s2=per_axis("a_max_mm_s2", 1.0),
        j_max_mm_s3=per_axis("j_max_mm_s3", 1.0),
    )
