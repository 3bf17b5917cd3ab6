"""The axes a card drives: names X Y Z A B C, the protocol's axis mask, steps per unit.

Protocol version 4 names the axes a card drives by a bit mask over ``X Y Z A B C`` (bit 0 X
… bit 5 C); every position and every period's counts carry one value per driven axis, in
that order. A version-3 card drives X Y Z. Linear axes count steps per mm (the profile's
``[steps.per_mm]``), rotary axes steps per degree (``[axis_limits.<a|b|c>] steps_per_deg``;
0: the axis cannot be streamed).
"""

from __future__ import annotations

import numpy as np

from nurbscnc.errors import ConfigError

#: Every axis a card can drive, in the protocol's order (bit i of the mask is AXIS_NAMES[i]).
AXIS_NAMES = "xyzabc"
#: The linear axes, streamed by every card (a version-3 card drives these only).
LINEAR_AXES = "xyz"


def mask_of(axes: str) -> int:
    """The axis mask of the axis names ``axes`` (e.g. "xyza" → 0b1111)."""
    mask = 0
    for name in axes.lower():
        i = AXIS_NAMES.find(name)
        if i < 0:
            raise ValueError(f"{name!r} is not an axis of {AXIS_NAMES.upper()}")
        mask |= 1 << i
    return mask


def names_of(mask: int) -> str:
    """The axis names of ``mask`` in the protocol's order (0b1011 → "xya")."""
    return "".join(n for i, n in enumerate(AXIS_NAMES) if mask >> i & 1)


def shown(axes: str) -> str:
    """Axis names as an operator reads them: "xya" → "X Y A"."""
    return " ".join(axes.upper())


def stream_axes(rotary_axes=()) -> str:
    """The axes a program's pulses carry: X Y Z and the rotary axes it uses, in order."""
    used = {str(a).lower() for a in rotary_axes}
    return LINEAR_AXES + "".join(a for a in AXIS_NAMES[3:] if a in used)


def card_axes(mach) -> str:
    """The axes a card of the machine ``mach`` drives, as far as the profile tells: X Y Z
    and every rotary axis with steps per degree (the order of a card's positions)."""
    rotary = mach.rotary_axes
    return LINEAR_AXES + "".join(
        a for a in AXIS_NAMES[3:] if a in rotary and rotary[a].steps_per_deg > 0.0
    )


def steps_per_unit(mach, axes: str) -> np.ndarray:
    """Steps per mm (X Y Z) and per degree (A B C) of the axes ``axes`` of the machine
    ``mach``; ConfigError for a rotary axis the profile lacks or gives no steps per degree
    (it cannot be streamed: said before any port is opened)."""
    out = []
    rotary = mach.rotary_axes
    for name in axes:
        if name in LINEAR_AXES:
            out.append(float(mach.steps.per_mm[LINEAR_AXES.index(name)]))
            continue
        axis = rotary.get(name)
        if axis is None:
            raise ConfigError(
                f"the machine profile has no {name.upper()} axis ([axis_limits.{name}]): "
                f"{name.upper()} cannot be streamed"
            )
        if not axis.steps_per_deg > 0.0:
            raise ConfigError(
                f"the machine profile gives no steps per degree for {name.upper()} "
                f"([axis_limits.{name}] steps_per_deg): {name.upper()} cannot be streamed"
            )
        out.append(float(axis.steps_per_deg))
    return np.asarray(out, dtype=float)


def position_units(steps, mach, axes: str) -> tuple[list[float], dict]:
    """``(xyz_mm, abc_deg)`` of a card position ``steps`` over the axes ``axes``: X Y Z in
    mm and ``{"a": deg, …}`` for the rotary ones the profile gives steps per degree (an
    axis without them is left out: its steps have no unit), steps over the machine's steps
    per unit (exact: the steps are what the card counts; rounded to 1 nm / 1 µdeg)."""
    values = np.asarray(steps, dtype=float)
    xyz = [
        round(float(values[axes.index(a)] / s), 6) for a, s in zip(LINEAR_AXES, mach.steps.per_mm)
    ]
    known = card_axes(mach)
    abc = {
        a: round(float(values[i] / steps_per_unit(mach, a)[0]), 6)
        for i, a in enumerate(axes)
        if a not in LINEAR_AXES and a in known
    }
    return xyz, abc


def axes_of_position(count: int, mach) -> str:
    """The axes of a card position of ``count`` values read without a handshake (a STATUS):
    X Y Z for 3 (a version-3 card, or one that drives X Y Z only), else the profile's
    :func:`card_axes` when their number agrees; ConfigError otherwise."""
    if count == len(LINEAR_AXES):
        return LINEAR_AXES
    axes = card_axes(mach)
    if count != len(axes):
        raise ConfigError(
            f"the card has {count} axes, the machine profile {len(axes)} "
            f"({shown(axes)}: X Y Z and the rotary axes with steps_per_deg)"
        )
    return axes
