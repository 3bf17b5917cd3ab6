"""What the sender makes of the card's CAPS and alarms: whether the card can run a program,
and an alarm code's name."""

from __future__ import annotations

from nurbscnc.errors import StreamError
from nurbscnc.output.stream import protocol as p
from nurbscnc.output.stream.quantise import PulseProgram


def check_caps(caps: p.Caps, prog: PulseProgram, position: bool = True) -> None:
    """StreamError unless the card can run ``prog`` (from where it stands: ``position``)."""
    axes = prog.pulses.shape[1] if prog.pulses.ndim == 2 else len(prog.start_steps)
    problems = []
    if caps.version not in p.COMPATIBLE_VERSIONS:
        problems.append(
            f"it speaks protocol version {caps.version}, nurbscnc speaks "
            f"{', '.join(map(str, p.COMPATIBLE_VERSIONS))}"
        )
    if caps.axes != axes:
        problems.append(f"it has {caps.axes} axes, the program has {axes}")
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
