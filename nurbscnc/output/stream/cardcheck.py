"""What the sender makes of the card's CAPS and alarms: whether the card can run a program,
the program widened to the axes the card drives, and an alarm code's name."""

from __future__ import annotations

import dataclasses

import numpy as np

from nurbscnc.errors import CardAxesError, StreamError
from nurbscnc.output.stream import protocol as p
from nurbscnc.output.stream.axes import LINEAR_AXES, names_of, shown
from nurbscnc.output.stream.quantise import PulseProgram


def caps_axes(caps: p.Caps) -> str:
    """The axes the card drives: its mask (version 4), X Y Z before (its axes' count when
    that is not 3: a card of other axes, named by position only)."""
    if caps.version >= p.MASK_VERSION:
        return names_of(caps.axis_mask)
    return LINEAR_AXES if caps.axes == len(LINEAR_AXES) else ""


def axes_problem(caps: p.Caps, prog: PulseProgram) -> str | None:
    """Why the card cannot drive the program's axes (None: it can: every axis the program
    carries is one the card drives; the card's others stand still)."""
    have = caps_axes(caps)
    axes = prog.pulses.shape[1] if prog.pulses.ndim == 2 else len(prog.start_steps)
    if not have or len(prog.axes) != axes:  # unnamed axes: the counts must agree
        return None if caps.axes == axes else f"it has {caps.axes} axes, the program has {axes}"
    missing = [a for a in prog.axes if a not in have]
    if not missing:
        return None
    if caps.version < p.MASK_VERSION:
        return (
            f"the card speaks protocol {caps.version} (X Y Z only); this program moves "
            f"{shown(''.join(missing))}"
        )
    return f"the card drives {shown(have)}; this program moves {shown(''.join(missing))}"


def fit_to_card(prog: PulseProgram, caps: p.Caps, fixed_steps=None) -> PulseProgram:
    """``prog`` with one column per axis the card drives, in its order: an axis the program
    does not carry stands still at ``fixed_steps`` (the card's position of that axis; the
    CAPS's when None). The program unchanged when its axes are the card's."""
    have = caps_axes(caps)
    if not have or prog.axes == have:
        return prog
    stand = caps.position_steps if fixed_steps is None else fixed_steps
    n = prog.periods
    start = np.empty(len(have), dtype=np.int64)
    pulses = np.zeros((n, len(have)), dtype=np.int64)
    for j, name in enumerate(have):
        if name in prog.axes:
            i = prog.axes.index(name)
            start[j] = prog.start_steps[i]
            pulses[:, j] = prog.pulses[:, i]
        else:
            start[j] = int(stand[j])
    return dataclasses.replace(
        prog, start_steps=start, end_steps=start + pulses.sum(axis=0), pulses=pulses, axes=have
    )


def check_caps(caps: p.Caps, prog: PulseProgram, position: bool = True) -> None:
    """StreamError unless the card can run ``prog`` (from where it stands: ``position``);
    ``prog`` already :func:`fit_to_card` when the card drives axes it does not carry."""
    problems = []
    if caps.version not in p.COMPATIBLE_VERSIONS:
        problems.append(
            f"it speaks protocol version {caps.version}, nurbscnc speaks "
            f"{', '.join(map(str, p.COMPATIBLE_VERSIONS))}"
        )
    axes_text = axes_problem(caps, prog)
    if axes_text is not None and axes_text.startswith("the card"):
        raise CardAxesError(axes_text)  # an axis the card does not drive: said alone
    if axes_text is not None:
        problems.append(axes_text)
    period_us = round(prog.period_s * 1e6)
    if caps.period_us != period_us:
        problems.append(
            f"its period is {caps.period_us} µs, the machine's servo period is {period_us} µs"
        )
    if prog.peak_pulses > caps.max_pulses_per_period:
        problems.append(
            f"it takes at most {caps.max_pulses_per_period} pulses per period, "
            f"the program needs {prog.peak_pulses}"
        )
    if caps.state in (p.CardState.RUNNING, p.CardState.HOLD):
        problems.append(f"it is busy ({p.CardState(caps.state).name}) with another stream")
    if problems:
        raise StreamError("the card cannot run this program: " + "; ".join(problems))
    start = tuple(int(v) for v in prog.start_steps)
    if position and tuple(caps.position_steps) != start:
        raise StreamError(
            f"the card is at {list(caps.position_steps)} steps, the program starts at "
            f"{list(start)} steps: move the card there, or give --zero to declare that it "
            "stands at the program's start"
        )


def alarm_name(code: int) -> str:
    try:
        return p.AlarmCode(code).name
    except ValueError:
        return f"#{code}"
