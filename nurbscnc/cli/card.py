"""``nurbscnc card-position`` and ``nurbscnc card-sim``: read or set a pulse-train card's
position, and simulate such a card on a pty or loopback TCP."""

from __future__ import annotations

import contextlib
import functools
import json
import signal
import sys
import threading

import click

from nurbscnc.cli.handle import handle_errors
from nurbscnc.errors import ConfigError, NurbsCncError, OutputError


@click.command("card-position")
@click.option("--port", required=True, help="The card's serial device.")
@click.option("--allow-url", is_flag=True, help="Accept a pyserial URL as --port.")
@click.option("--baud", type=click.IntRange(min=1), default=115200, show_default=True)
@click.option(
    "--set",
    "set_to",
    default=None,
    metavar="X,Y,Z[,A,B,C]",
    help="Set the card's position [steps, one per axis it drives: X Y Z and its rotary "
    "axes] (protocol version 3; not while a stream runs), e.g. 0,0,0 after homing.",
)
@click.option(
    "--timeout",
    "timeout_s",
    type=click.FloatRange(min=0.0, min_open=True),
    default=2.0,
    show_default=True,
)
@click.option(
    "--machine",
    type=click.Path(),
    default=None,
    help="Machine profile (TOML) whose steps per mm (and per degree: A B C) give the "
    "position in mm (and degrees). Default: as every command ($NURBSCNC_MACHINE, "
    "./nurbscnc.toml, ...).",
)
@click.option(
    "--var",
    type=click.Path(dir_okay=False),
    default=None,
    metavar="FILE",
    help="LinuxCNC parameter file whose offsets give the work position (default: "
    "$NURBSCNC_VAR, else the profile's program.var_file; none: machine coordinates only).",
)
@click.option("--json", "as_json", is_flag=True, help="Print state and position as JSON.")
@handle_errors
def card_position(port, allow_url, baud, set_to, timeout_s, machine, var, as_json):
    """Read (or --set) the card's position [steps] and state, e.g. to zero a card between two
    streams without restarting it. The position is also given in mm (machine coordinates)
    from the machine profile's steps per mm, and in the active work system's coordinates
    when a parameter file is known (one that does not exist yet: all offsets zero).

    Example: nurbscnc card-position --port /dev/ttyUSB0 --set 0,0,0
    """
    from nurbscnc.app.stream import position_abc_deg, position_mm
    from nurbscnc.app.varfile import find_var_file, read_var_file, work_report
    from nurbscnc.cli.common import load_machine_cli
    from nurbscnc.output.stream import protocol as p
    from nurbscnc.output.stream.sender import card_position as exchange
    from nurbscnc.output.stream.sender import open_port

    mach = load_machine_cli(machine)  # before the port: a bad profile touches no card
    var_path, _how = find_var_file(mach, var)
    values = read_var_file(var_path, must_exist=False) if var_path else None
    ser = open_port(port, baud=baud, allow_url=allow_url, write_timeout_s=timeout_s)
    try:
        target = _parse_position(set_to, len(set_to.split(","))) if set_to else None
        status = exchange(ser, target, timeout_s)
    finally:
        with contextlib.suppress(Exception):
            ser.close()
    state = p.CardState(status.state).name
    steps = list(status.position_steps)
    try:
        abc = position_abc_deg(steps, mach)
    except ConfigError as exc:
        raise ConfigError(f"{exc.message}: no position in mm") from None
    mm = position_mm(steps, mach)
    work = work_report(values, mm) if values is not None else {}
    if as_json:
        body = {"ok": True, "state": state, "position_steps": steps, "position_mm": mm}
        if abc:
            body["position_abc_deg"] = abc
        if values is not None:
            body.update(work, var_file=var_path)
        click.echo(json.dumps(body))
        return
    text = ", ".join(f"{v:.4f}" for v in mm) + " mm"
    text += "".join(f", {a.upper()} {v:.4f}°" for a, v in abc.items())
    text += ", machine coordinates"
    if work:
        shown = ", ".join(f"{v:.4f}" for v in work["work_position_mm"])
        text += f"; {shown} mm in {work['coordinate_system']}"
    click.echo(f"card: {state}, position {steps} steps ({text})")


# -- card-sim ------------------------------------------------------------------------------------
def _card_errors(func):
    """NurbsCncError → ``card-sim: error: message`` and its exit code."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except NurbsCncError as exc:
            from nurbscnc.errors import printable  # (a message may quote a file name)

            click.echo(f"card-sim: error: {printable(exc.message)}", err=True)
            sys.exit(exc.exit_code)

    return wrapper


def _parse_position(text: str, axes: int) -> tuple[int, ...]:
    from nurbscnc.errors import ConfigError

    try:
        values = tuple(int(v) for v in text.split(","))
    except ValueError:
        raise ConfigError(f"--position wants {axes} integers (steps) like 0,0,0") from None
    if len(values) != axes:
        raise ConfigError(f"--position wants {axes} integers, got {len(values)}")
    return values


def _card_axes(text: str) -> tuple[int, str]:
    """``--axes``: ``(count, names)`` of "XYZA" (names) or "3" (a count, unnamed)."""
    text = text.strip()
    if text.isdigit():
        count = int(text)
        if not 1 <= count <= 15:
            raise ConfigError(f"--axes must be 1..15 axes or names like XYZA, got {text}")
        return count, ""
    return len(text), text.lower()


@click.command("card-sim")
@click.option(
    "--listen",
    default=None,
    metavar="HOST:PORT",
    help="Listen on loopback TCP (use with stream --port socket://HOST:PORT "
    "--allow-url) instead of opening a pty; PORT 0 picks a free one.",
)
@click.option(
    "--speed",
    type=click.FloatRange(min=0.0, min_open=True),
    default=1.0,
    show_default=True,
    help="Run N times faster than real time.",
)
@click.option("--fast", is_flag=True, help="Execute periods as fast as they arrive.")
@click.option(
    "--buffer",
    "buffer_periods",
    type=click.IntRange(1, 65535),
    default=256,
    show_default=True,
    help="Buffer size [periods].",
)
@click.option(
    "--start-fill",
    type=click.IntRange(min=1),
    default=None,
    help="Buffered periods that start execution (default: half the buffer).",
)
@click.option(
    "--max-pulses",
    type=click.IntRange(1, 32767),
    default=127,
    show_default=True,
    help="Most pulses per period and axis.",
)
@click.option(
    "--period-ms",
    type=click.FloatRange(min=0.0, min_open=True),
    default=1.0,
    show_default=True,
    help="The card's period.",
)
@click.option(
    "--axes",
    default="XYZ",
    show_default=True,
    help="The axes the card drives, by name in the order XYZABC (e.g. XYZA: a 4th axis; "
    "protocol 4), or their number (1-15).",
)
@click.option(
    "--protocol",
    type=click.Choice(["3", "4"]),
    default=None,
    help="The protocol version it speaks (default: 4 when it drives A, B or C, else 3; "
    "a version-3 card drives X Y Z only).",
)
@click.option(
    "--position",
    default=None,
    metavar="X,Y,Z[,A,B,C]",
    help="Start position [steps, one per axis] (default: all 0).",
)
@click.option(
    "--baud",
    type=click.IntRange(min=1),
    default=None,
    help="Emulate a serial line's byte rate (10 bits per byte) both ways.",
)
@click.option("--drop-rate", type=float, default=0.0, help="Probability a frame is lost.")
@click.option(
    "--corrupt-rate", type=float, default=0.0, help="Probability a frame gets one bit flipped."
)
@click.option("--delay-ms", type=float, default=0.0, help="Delay of every reply [ms].")
@click.option(
    "--reset-after-frames",
    type=click.IntRange(min=1),
    default=None,
    help="Reset (new session, position lost) after N received frames.",
)
@click.option(
    "--stall-after-frames",
    type=click.IntRange(min=0),
    default=None,
    help="Stop answering after N received frames.",
)
@click.option("--seed", type=int, default=None, help="Seed of the fault injection.")
@click.option(
    "--log",
    "log_path",
    type=click.Path(dir_okay=False),
    default=None,
    help="CSV of executed periods: period,x,y,z (pulses; a column per axis).",
)
@click.option(
    "--report",
    "report_path",
    type=click.Path(dir_okay=False),
    default=None,
    help="JSON counters and final state, written at exit.",
)
@click.option("--once", is_flag=True, help="Exit after one stream has ended.")
@_card_errors
def card_sim(
    listen,
    speed,
    fast,
    buffer_periods,
    start_fill,
    max_pulses,
    period_ms,
    axes,
    protocol,
    position,
    baud,
    drop_rate,
    corrupt_rate,
    delay_ms,
    reset_after_frames,
    stall_after_frames,
    seed,
    log_path,
    report_path,
    once,
):
    """Simulate a pulse-train motion card on a pty (its path is printed) or loopback TCP.

    Prints the port to open (a /dev/pts path, or socket://HOST:PORT) on the first line of
    stdout, then serves until SIGINT/SIGTERM (or, with --once, until a stream ended).

    Example: nurbscnc card-sim --fast --log executed.csv
    """
    from nurbscnc.output.files import atomic_output
    from nurbscnc.output.stream.card import (
        CardConfig,
        CardSim,
        Faults,
        PtyEndpoint,
        TcpEndpoint,
        parse_listen,
        serve,
    )

    faults = Faults(
        drop_rate=drop_rate,
        corrupt_rate=corrupt_rate,
        delay_s=delay_ms * 1e-3,
        reset_after_frames=reset_after_frames,
        stall_after_frames=stall_after_frames,
    )
    count, names = _card_axes(axes)
    config = CardConfig(
        axes=count,
        axis_names=names,
        version=int(protocol or 0),
        buffer_periods=buffer_periods,
        max_pulses_per_period=max_pulses,
        period_s=period_ms * 1e-3,
        speed=None if fast else speed,
        start_fill_periods=start_fill,
        position_steps=_parse_position(position, count) if position else (),
        faults=faults,
    )
    card = CardSim(config, seed=seed)
    endpoint = TcpEndpoint(*parse_listen(listen)) if listen else PtyEndpoint()
    stop = threading.Event()
    previous = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        previous[sig] = signal.signal(sig, lambda _s, _f: stop.set())
    click.echo(endpoint.path)
    sys.stdout.flush()
    try:
        log = open(log_path, "w", encoding="utf-8") if log_path else None  # noqa: SIM115
    except OSError as exc:
        endpoint.close()
        for sig, old in previous.items():
            signal.signal(sig, old)
        raise OutputError(f"cannot write the log {log_path}: {exc.strerror or exc}") from None
    try:
        serve(card, endpoint, stop, once=once, baud=baud, log=log)
    finally:
        endpoint.close()
        if log is not None:
            log.close()
        for sig, old in previous.items():
            signal.signal(sig, old)
        if report_path:
            with atomic_output(report_path) as fh:
                json.dump(card.report(), fh)
    state = card.report()
    click.echo(
        f"card-sim: {state['state']}, {state['executed_periods']} periods executed, "
        f"position {state['position_steps']} steps",
        err=True,
    )
