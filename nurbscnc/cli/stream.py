"""The ``stream`` and ``card-sim`` commands.

``nurbscnc.cli.main`` registers them (``main.add_command``) and imports this module at its end, so
nothing from ``nurbscnc.cli.main`` is imported here at module level (that would be an import
cycle whichever module is imported first): the options are declared here and the CLI helpers
(``handle_errors``, ``make_plan``, ``load_machine_cli``, the consoles) are imported when a
command runs.
"""

from __future__ import annotations

import contextlib
import functools
import json
import os
import signal
import sys
import threading

import click

from nurbscnc.cli.options import planning_options
from nurbscnc.errors import NurbsCncError, OutputError

POINT_SUFFIXES = (".csv", ".npz")


def _handle_errors(func):
    """``nurbscnc.cli.handle_errors``, looked up when the command runs."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        from nurbscnc.cli.main import handle_errors

        return handle_errors(func)(*args, **kwargs)

    return wrapper


# -- building the pulse program (everything before the port is opened) --------------------------
def load_pulse_program(path: str, machine=None, overrides=(), **settings):
    """Plan ``path`` (a program, or a reference-point file .csv/.npz) and quantise it.

    ``settings`` are the values of :func:`~nurbscnc.cli.options.planning_options` (the same
    planning options as ``run``). Returns ``(PulseProgram, Machine)``. Everything that can be
    wrong with the input — syntax, geometry, planning, soft limits, the servo period of a point
    file, the card's pulse limit — raises here, before any port is touched.
    """
    import numpy as np

    from nurbscnc.cli.main import load_machine_cli, make_plan
    from nurbscnc.errors import ConfigError, PlanningError
    from nurbscnc.output.files import read_points
    from nurbscnc.output.stream.quantise import check_pulse_limit, quantise

    if path.lower().endswith(POINT_SUFFIXES):
        mach = load_machine_cli(machine, overrides)
        data = read_points(path)
        points = np.column_stack([data["x"], data["y"], data["z"]]).astype(float)
        if points.shape[0] == 0:
            raise PlanningError(f"{path}: no reference points")
        if not np.all(np.isfinite(points)):
            raise PlanningError(f"{path}: a reference point is not a finite number")
        period_s = mach.servo.period_s
        dt = np.diff(np.asarray(data["t"], dtype=float))
        # The CSV writes t with 6 decimals (1 µs): allow that rounding, nothing more.
        bad = np.flatnonzero(np.abs(dt - period_s) > 1.01e-6)
        if bad.size:
            k = int(bad[0])
            raise ConfigError(
                f"{path}: points {k + 1} and {k + 2} are {dt[k] * 1e3:.6g} ms apart; the "
                f"machine's servo period is {period_s * 1e3:g} ms (one point per period)"
            )
        inside = mach.soft_limits.inside(points)
        if not np.all(inside):
            k = int(np.flatnonzero(~inside)[0])
            raise PlanningError(
                f"{path}: point {k + 1} ({', '.join(f'{v:.4f}' for v in points[k])}) mm is "
                "outside the soft limits"
            )
        pulses = quantise(points, mach.steps.per_mm, period_s)
    else:
        _, mach, plan = make_plan(path, machine, overrides, **settings)
        samples = plan.samples
        pulses = quantise(samples.points_mm, mach.steps.per_mm, mach.servo.period_s,
                          samples.line)  # fmt: skip
    check_pulse_limit(pulses, mach.steps.max_pulses_per_period)
    return pulses, mach


class _Operator:
    """What the operator asks by signal: SIGUSR1 feed hold, SIGUSR2 resume, SIGINT/SIGTERM
    abort (the last two only once the port is open; before, they end the command as usual).

    A hold or resume asked while the program is still being planned is kept, with a message,
    and given to the sender when the stream opens: the card then fills its buffer but does not
    move until SIGUSR2.
    """

    def __init__(self) -> None:
        self.sender = None
        self.hold: bool | None = None  # asked before the sender existed

    def attach(self, sender) -> None:
        self.sender = sender
        if self.hold is not None:
            (sender.request_hold if self.hold else sender.request_resume)()

    def on_hold(self, *_args) -> None:
        self._feed(True)

    def on_resume(self, *_args) -> None:
        self._feed(False)

    def on_abort(self, *_args) -> None:
        self.sender.request_abort()

    def _feed(self, hold: bool) -> None:
        if self.sender is not None:
            (self.sender.request_hold if hold else self.sender.request_resume)()
            return
        self.hold = hold
        text = ("feed hold asked while planning: the card will hold as soon as the stream "
                "opens (SIGUSR2 resumes)\n" if hold else
                "resume asked while planning: no feed hold when the stream opens\n")  # fmt: skip
        # os.write, not print: a signal handler may interrupt a print in progress.
        with contextlib.suppress(OSError):
            os.write(2, b"stream: " + text.encode())


@contextlib.contextmanager
def _signals(operator: _Operator, names: tuple[str, ...]):
    """Route the named signals to ``operator`` (main thread only); restore them after."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    actions = {"SIGUSR1": operator.on_hold, "SIGUSR2": operator.on_resume,
               "SIGINT": operator.on_abort, "SIGTERM": operator.on_abort}  # fmt: skip
    previous = {}
    try:
        for name in names:
            if hasattr(signal, name):
                sig = getattr(signal, name)
                previous[sig] = signal.signal(sig, actions[name])
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


@contextlib.contextmanager
def _progress_bar(enabled: bool, total: int):
    """A rich progress bar on stderr; yields a callback for :class:`Sender` (or None)."""
    if not enabled:
        yield None
        return
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from nurbscnc.cli.main import err

    with Progress(TextColumn("streaming"), BarColumn(), TextColumn("{task.fields[info]}"),
                  TimeElapsedColumn(), console=err, transient=False) as bar:  # fmt: skip
        task = bar.add_task("stream", total=max(total, 1), info="")

        def update(pr) -> None:
            info = (f"sent {pr.sent} · acked {pr.acked} · executed {pr.executed}/{pr.periods}"
                    f" · buffer {pr.fill}/{pr.buffer}")  # fmt: skip
            bar.update(task, completed=pr.executed, info=info)

        yield update


@click.command()
@click.argument("program", type=click.Path())
@click.option("--port", required=True,
              help="The card's serial device, e.g. /dev/ttyUSB0 (opened exclusively).")
@click.option("--allow-url", is_flag=True,
              help="Accept a pyserial URL (socket://HOST:PORT, rfc2217://...) as --port. "
                   "These are unauthenticated network connections.")
@click.option("--baud", type=click.IntRange(min=1), default=115200, show_default=True,
              help="Line rate.")
@click.option("--batch", type=click.IntRange(1, 80), default=16, show_default=True,
              help="Periods per frame (at most 80 with 3 axes).")
@click.option("--timeout", "timeout_s", type=click.FloatRange(min=0.0, min_open=True),
              default=2.0, show_default=True,
              help="Seconds without an answer from the card before giving up.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
@click.option("--json", "as_json", is_flag=True, help="Print the final report as JSON.")
@planning_options
@_handle_errors
def stream(program, port, allow_url, baud, batch, timeout_s, quiet, as_json, **settings):
    """Stream PROGRAM (.nc/.ngc, or reference points .csv/.npz) to a pulse-train card.

    The whole program is planned and checked (soft limits, the card's pulse limit) before the
    port is opened. Ctrl-C or SIGTERM aborts the card at once and exits 130; SIGUSR1 / SIGUSR2
    hold / resume the feed (a hold asked while planning applies when the stream opens). Exit 0
    only when the card reports DONE at the program's end position.

    Example: nurbscnc stream part.nc --port /dev/ttyUSB0
    """
    from nurbscnc.cli.main import err, out
    from nurbscnc.output.stream.sender import Sender, SenderOptions, open_port

    operator = _Operator()
    # Hold/resume are caught from the start: planning a long program takes time, and
    # SIGUSR1's default action would end the command silently.
    with _signals(operator, ("SIGUSR1", "SIGUSR2")):
        pulses, _ = load_pulse_program(program, **settings)
        options = SenderOptions(batch_periods=batch, timeout_s=timeout_s)
        ser = open_port(port, baud=baud, allow_url=allow_url, write_timeout_s=timeout_s,
                        read_wait_s=options.read_wait_s)  # fmt: skip
        show = not (quiet or as_json) and err.is_terminal
        try:
            with _progress_bar(show, pulses.periods) as progress:
                sender = Sender(ser, options, progress=progress)
                operator.attach(sender)
                with _signals(operator, ("SIGINT", "SIGTERM")):
                    report = sender.stream(pulses)
        finally:
            with contextlib.suppress(Exception):
                ser.close()
    if as_json:
        click.echo(json.dumps({"ok": True, "program": program, **report.to_json()}))
        return
    out.print(
        f"{program}: {report.executed_periods} periods streamed in {report.duration_s:.3f} s; "
        f"{report.frames_sent} frames ({report.bytes_sent} bytes), {report.retransmits} "
        f"retransmitted; the card ended at {list(report.final_position_steps)} steps",
        markup=False,
    )


# -- card-sim ------------------------------------------------------------------------------------
def _card_errors(func):
    """NurbsCncError → ``card-sim: error: message`` and its exit code."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except NurbsCncError as exc:
            click.echo(f"card-sim: error: {exc.message}", err=True)
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


@click.command("card-sim")
@click.option("--listen", default=None, metavar="HOST:PORT",
              help="Listen on loopback TCP (use with stream --port socket://HOST:PORT "
                   "--allow-url) instead of opening a pty; PORT 0 picks a free one.")
@click.option("--speed", type=click.FloatRange(min=0.0, min_open=True), default=1.0,
              show_default=True, help="Run N times faster than real time.")
@click.option("--fast", is_flag=True, help="Execute periods as fast as they arrive.")
@click.option("--buffer", "buffer_periods", type=click.IntRange(1, 65535), default=256,
              show_default=True, help="Buffer size [periods].")
@click.option("--start-fill", type=click.IntRange(min=1), default=None,
              help="Buffered periods that start execution (default: half the buffer).")
@click.option("--max-pulses", type=click.IntRange(1, 32767), default=127, show_default=True,
              help="Most pulses per period and axis.")
@click.option("--period-ms", type=click.FloatRange(min=0.0, min_open=True), default=1.0,
              show_default=True, help="The card's period.")
@click.option("--axes", type=click.IntRange(1, 15), default=3, show_default=True)
@click.option("--position", default=None, metavar="X,Y,Z",
              help="Start position [steps] (default: all 0).")
@click.option("--baud", type=click.IntRange(min=1), default=None,
              help="Emulate a serial line's byte rate (10 bits per byte) both ways.")
@click.option("--drop-rate", type=float, default=0.0, help="Probability a frame is lost.")
@click.option("--corrupt-rate", type=float, default=0.0,
              help="Probability a frame gets one bit flipped.")
@click.option("--delay-ms", type=float, default=0.0, help="Delay of every reply [ms].")
@click.option("--reset-after-frames", type=click.IntRange(min=1), default=None,
              help="Reset (new session, position lost) after N received frames.")
@click.option("--stall-after-frames", type=click.IntRange(min=0), default=None,
              help="Stop answering after N received frames.")
@click.option("--seed", type=int, default=None, help="Seed of the fault injection.")
@click.option("--log", "log_path", type=click.Path(dir_okay=False), default=None,
              help="CSV of executed periods: period,x,y,z (pulses).")
@click.option("--report", "report_path", type=click.Path(dir_okay=False), default=None,
              help="JSON counters and final state, written at exit.")
@click.option("--once", is_flag=True, help="Exit after one stream has ended.")
@_card_errors
def card_sim(listen, speed, fast, buffer_periods, start_fill, max_pulses, period_ms, axes,
             position, baud, drop_rate, corrupt_rate, delay_ms, reset_after_frames,
             stall_after_frames, seed, log_path, report_path, once):  # fmt: skip
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

    faults = Faults(drop_rate=drop_rate, corrupt_rate=corrupt_rate, delay_s=delay_ms * 1e-3,
                    reset_after_frames=reset_after_frames,
                    stall_after_frames=stall_after_frames)  # fmt: skip
    config = CardConfig(
        axes=axes, buffer_periods=buffer_periods, max_pulses_per_period=max_pulses,
        period_s=period_ms * 1e-3, speed=None if fast else speed, start_fill_periods=start_fill,
        position_steps=_parse_position(position, axes) if position else (0,) * axes,
        faults=faults,
    )  # fmt: skip
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
    click.echo(f"card-sim: {state['state']}, {state['executed_periods']} periods executed, "
               f"position {state['position_steps']} steps", err=True)  # fmt: skip
