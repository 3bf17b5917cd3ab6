"""The effective machine profile as TOML text (``nurbscnc profile show``), and where it came
from for every command's JSON."""

from __future__ import annotations

import json
import math

from nurbscnc.machine.discovery import FOUND_BY_DEFAULT
from nurbscnc.machine.model import Machine
from nurbscnc.machine.schema import SCHEMA


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, str):
        return json.dumps(value)  # a TOML basic string (JSON's escapes are TOML's)
    return repr(float(value))  # shortest round-trip form; valid TOML (validated finite)


def _ordered(table: dict, schema) -> list[str]:
    """Keys of ``table`` in schema order (the order of the template)."""
    order = list(schema) if isinstance(schema, dict) else []
    return sorted(table, key=lambda k: order.index(k) if k in order else len(order))


def _pole_text(p: complex) -> str:
    return f"{p.real:.6g}" if p.imag == 0.0 else f"{p.real:.6g}{p.imag:+.6g}j"


def profile_toml(machine: Machine) -> str:
    """``machine.settings`` as TOML, in the template's key order, with a header saying where
    the profile came from, each key the profile left out marked ``# default``, and, per servo
    axis, its poles (and ω_n for the simple form)."""
    lines = [f"# machine profile: {machine.describe()}"]
    if not machine.contour_check:
        lines.append("# no servo model: contour check off")
    if machine.defaults:
        lines.append("# keys marked '# default' are not in the profile: their default value")

    def emit(table: dict, schema, prefix: str) -> None:
        keys = _ordered(table, schema)
        leaves = [k for k in keys if not isinstance(table[k], dict)]
        if prefix and leaves:
            lines.extend(["", f"[{prefix}]"])
            axis = (
                machine.servo.axis(prefix[6:])
                if prefix in ("servo.x", "servo.y", "servo.z")
                else None
            )
            if axis is not None:
                poles = ", ".join(_pole_text(p) for p in axis.poles())
                wn = axis.natural_frequency_rad_s
                extra = f"; wn = {wn:.6g} rad/s" if wn is not None else ""
                lines.append(f"# poles [1/s]: {poles}{extra}")
            rotary = machine.rotary_axes.get(prefix[12:]) if prefix[:12] == "axis_limits." else None
            if rotary is not None:
                lines.append(_rotary_comment(rotary))
        lines.extend(
            f"{k} = {_toml_value(table[k])}"
            + ("  # default" if (f"{prefix}.{k}" if prefix else k) in machine.defaults else "")
            for k in leaves
        )
        for k in keys:
            if isinstance(table[k], dict):
                sub = schema.get(k, {}) if isinstance(schema, dict) else {}
                emit(table[k], sub, f"{prefix}.{k}" if prefix else k)

    emit(machine.settings, SCHEMA, "")
    return "\n".join(lines) + "\n"


def _rotary_comment(axis) -> str:
    """A rotary axis's limits in internal units, for the comment above its table."""
    text = (
        f"# rotary axis {axis.name.upper()} [degrees]: v_max {axis.v_max_deg_s:.6g} deg/s, "
        f"a_max {axis.a_max_deg_s2:.6g} deg/s^2, j_max {axis.j_max_deg_s3:.6g} deg/s^3"
    )
    if axis.min_deg != -math.inf or axis.max_deg != math.inf:
        text += f", travel [{axis.min_deg:g}, {axis.max_deg:g}] deg"
    if axis.wrapped:
        text += ", wrapped (G90 words are positions in [0, 360), the sign the direction)"
    return text


def profile_info(machine: Machine) -> dict:
    """Where the profile came from, for every command's JSON (key ``machine_profile``)."""
    return {
        "path": None if machine.found_by == FOUND_BY_DEFAULT else machine.source,
        "found_by": machine.found_by,
        "contour_check": machine.contour_check,
    }
