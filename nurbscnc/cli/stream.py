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


def plan_job(path: str, machine=None, overrides=(), from_line: int | None = None,
             optional_stop: bool = False, override: float = 1.0, **settings):
    """Plan program ``path`` (from ``from_line`` on: :func:`start_at_line`) as a stream
    :class:`~nurbscnc.output.stream.job.Job`. Returns ``(job, machine)``; everything that can
    be wrong with the input raises here, before any port is touched (the pulse limit too).
    A baseline ``--algorithm`` has no plan to re-plan from: None is returned for the job
    then."""
    from nurbscnc.cli.main import load_machine_cli, load_program
    from nurbscnc.cli.options import run_options
    from nurbscnc.errors import ConfigError
    from nurbscnc.output.stream.feed import WindowFeed
    from nurbscnc.output.stream.job import Job, start_at_line
    from nurbscnc.output.stream.quantise import check_pulse_limit, quantise
    from nurbscnc.pipeline import run_program, window_plans
    from nurbscnc.plan.options import Algorithm

    keys = ("algorithm", "corner_feed", "dynamics", "blend_tolerance", "interpolator",
            "lookahead", "smooth")  # fmt: skip
    options = run_options(**{k: settings[k] for k in keys if k in settings})
    mach = load_machine_cli(machine, overrides)
    prog = load_program(path, not settings.get("no_block_delete", False),
                        settings.get("tool_table"), settings.get("subroutine_path", ()))
    if from_line is not None:
        try:
            prog = start_at_line(prog, from_line)
        except ValueError as exc:
            raise ConfigError(str(exc)) from None
    if options.algorithm != Algorithm.PH_LOOKAHEAD:
        run = run_program(prog, mach, options)
        samples = run.samples
        check_pulse_limit(quantise(samples.points_mm, mach.steps.per_mm, mach.servo.period_s,
                                   samples.line), mach.steps.max_pulses_per_period)  # fmt: skip
        return None, mach

    def pulse_limit(points_mm, lines) -> None:
        # The plan at 100 %: a lower override and a hold only slow down.
        check_pulse_limit(quantise(points_mm, mach.steps.per_mm, mach.servo.period_s, lines),
                          mach.steps.max_pulses_per_period)  # fmt: skip

    # Planned cut window by cut window on a thread while the card runs the first ones
    # (issue 14); the first window is waited for here, so its errors come before the port.
    feed = WindowFeed(window_plans(prog, mach, options, each=pulse_limit))
    job = Job(None, prog, mach, optional_stop=optional_stop, override=override,
              lookahead_pieces=options.lookahead.lookahead_pieces, feed=feed)  # fmt: skip
    return job, mach


class _Operator:
    """What the operator asks, by signal or key: SIGUSR1 / space feed hold, SIGUSR2 / Enter
    continue (after a program stop or a hold), + / - feed override, SIGINT/SIGTERM abort (the
    last two only once the port is open; before, they end the command as usual).

    With a :class:`Job` (a planned program) hold and continue go to the job (a decelerating
    hold along the path); for a point file to the card (HOLD/RESUME: the card stops at the
    next period). A hold asked while the program is still being planned is kept, with a
    message: the stream then waits at the start until continued.
    """

    def __init__(self) -> None:
        self.sender = None
        self.job = None
        self.hold: bool | None = None  # asked before the sender existed

    def attach_job(self, job) -> None:
        self.job = job
        if job is not None and self.hold:
            job.request_hold()
            self.hold = None

    def attach(self, sender) -> None:
        self.sender = sender
        if self.hold is not None and self.job is None:
            (sender.request_hold if self.hold else sender.request_resume)()

    def on_hold(self, *_args) -> None:
        self._feed(True)

    def on_resume(self, *_args) -> None:
        self._feed(False)

    def on_abort(self, *_args) -> None:
        self.sender.request_abort()

    def on_key(self, key: bytes) -> None:
        if key in (b" ", b"h"):
            self._feed(True)
        elif key in (b"\n", b"\r", b"c"):
            self._feed(False)
        elif key in (b"+", b"=", b"-", b"_") and self.job is not None:
            self.job.step_override(1 if key in (b"+", b"=") else -1)

    def _feed(self, hold: bool) -> None:
        if self.job is not None:
            self.job.request_hold() if hold else self.job.resume()
            return
        if self.sender is not None:
            (self.sender.request_hold if hold else self.sender.request_resume)()
            return
        self.hold = hold
        text = ("feed hold asked while planning: the stream will wait at the start "
                "(SIGUSR2 continues)\n" if hold else
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
def _keys(operator: _Operator, enabled: bool):
    """Read single keys from a terminal on stdin (cbreak mode, restored after) in a thread."""
    if not enabled:
        yield
        return
    import select
    import termios
    import tty

    fd = sys.stdin.fileno()
    try:
        saved = termios.tcgetattr(fd)
        tty.setcbreak(fd)
    except (termios.error, OSError):
        yield
        return
    stop = threading.Event()

    def read_keys() -> None:
        while not stop.is_set():
            ready, _, _ = select.select([fd], [], [], 0.1)
            if ready:
                key = os.read(fd, 1)
                if not key:
                    return
                operator.on_key(key)

    thread = threading.Thread(target=read_keys, daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join(1.0)
        with contextlib.suppress(termios.error, OSError):
            termios.tcsetattr(fd, termios.TCSADRAIN, saved)


@contextlib.contextmanager
def _progress_bar(enabled: bool, total: int, keys: bool = False):
    """A rich progress line on stderr; yields a callback for :class:`Sender`. Without it, a
    message still tells when the stream waits for the operator (and why)."""
    from nurbscnc.cli.main import err

    how = "Enter or SIGUSR2 continues" if keys else "SIGUSR2 continues"
    last = {"note": ""}

    def tell(pr) -> None:
        waiting = "waiting:" in pr.note
        if waiting and pr.note != last["note"]:
            why = pr.note.split("waiting: ")[1]
            where = f" at line {pr.line}" if why == "feed hold" and pr.line else ""
            err.print(f"stream: {why}{where}: the card is at rest; {how}", markup=False,
                      highlight=False)  # fmt: skip
        last["note"] = pr.note if waiting else ""

    if not enabled:
        yield tell
        return
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    with Progress(TextColumn("streaming"), BarColumn(), TextColumn("{task.fields[info]}"),
                  TimeElapsedColumn(), console=err, transient=False) as bar:  # fmt: skip
        task = bar.add_task("stream", total=max(total, 1), info="")

        def update(pr) -> None:
            tell(pr)
            info = (f"line {pr.line} · executed {pr.executed} · buffer {pr.fill}/{pr.buffer}"
                    + (f" · {pr.note}" if pr.note else ""))  # fmt: skip
            bar.update(task, completed=pr.executed, total=max(pr.periods, total, 1),
                       info=info.replace("[", "\\["))  # fmt: skip

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
@click.option("--lead", "lead", type=click.IntRange(min=1), default=None, metavar="PERIODS",
              help="Keep at most this many periods queued ahead of the card's execution "
                   "(default: its whole buffer): a feed hold acts that much sooner; at least "
                   "half the card's buffer.")
@click.option("--optional-stop", is_flag=True,
              help="Wait at M1 (optional stop) too; without it M1 is passed.")
@click.option("--feed-override", type=click.IntRange(10, 100), default=100, show_default=True,
              metavar="PERCENT",
              help="Feed override at the start [%]; + / - keys change it by 10 % while "
                   "streaming (10-100 %).")
@click.option("--zero", is_flag=True,
              help="Declare that the card stands at the program's start (sets the card's "
                   "position; protocol version 3) instead of refusing a card elsewhere.")
@click.option("--from-line", type=click.IntRange(min=1), default=None, metavar="N",
              help="Start at source line N (run from line): the program is interpreted "
                   "whole, the tool goes up to a safe Z, across, and down to line N's start.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
@click.option("--json", "as_json", is_flag=True, help="Print the final report as JSON.")
@planning_options
@_handle_errors
def stream(program, port, allow_url, baud, batch, timeout_s, lead, optional_stop, feed_override,
           zero, from_line, quiet, as_json, **settings):  # fmt: skip
    """Stream PROGRAM (.nc/.ngc, or reference points .csv/.npz) to a pulse-train card.

    The program is parsed, interpreted and its geometry checked before the port is opened;
    the motion is planned cut window by cut window while the card runs (each window checked
    against the soft limits and the card's pulse limit before it is sent; the card waits at
    rest at the end of a cut if planning falls behind). At M0 / M60 (and M1 with
    --optional-stop) the card stops at rest and the stream waits: Enter (on a terminal) or
    SIGUSR2 continues. SIGUSR1 or the space key is a feed hold: the tool decelerates along
    the path within the acceleration and jerk limits, stops, and continues on Enter /
    SIGUSR2 (the rest re-planned from rest). + / - change the feed override. Ctrl-C or
    SIGTERM aborts the card at once and exits 130. Exit 0 only when the card reports DONE at
    the program's end position.

    Example: nurbscnc stream part.nc --port /dev/ttyUSB0 --optional-stop
    """
    from nurbscnc.cli.main import err, out
    from nurbscnc.errors import ConfigError
    from nurbscnc.output.stream.sender import Sender, SenderOptions, open_port

    operator = _Operator()
    points_file = program.lower().endswith(POINT_SUFFIXES)
    # Hold/resume are caught from the start: planning a long program takes time, and
    # SIGUSR1's default action would end the command silently.
    with _signals(operator, ("SIGUSR1", "SIGUSR2")):
        job = None
        if points_file and (from_line is not None or feed_override != 100):
            raise ConfigError("--from-line and --feed-override need a program (.nc/.ngc), "
                              "not a file of reference points")  # fmt: skip
        if not points_file:
            job, mach = plan_job(program, from_line=from_line, optional_stop=optional_stop,
                                 override=feed_override / 100.0, **settings)  # fmt: skip
        try:
            if job is None:
                if from_line is not None or feed_override != 100:
                    raise ConfigError("--from-line and --feed-override need the look-ahead "
                                      "planner (--algorithm ph-lookahead)")  # fmt: skip
                pulses, mach = load_pulse_program(program, **settings)
                total = pulses.periods
            else:
                total = int(round(job.plan.cycle_time_s / job.period_s / job.override))
            operator.attach_job(job)
            options = SenderOptions(batch_periods=batch, timeout_s=timeout_s, lead_periods=lead)
            ser = open_port(port, baud=baud, allow_url=allow_url, write_timeout_s=timeout_s,
                            read_wait_s=options.read_wait_s)  # fmt: skip
            show = not (quiet or as_json) and err.is_terminal
            keys = not as_json and sys.stdin is not None and sys.stdin.isatty()
            try:
                with _progress_bar(show, total, keys) as progress, _keys(operator, keys):
                    sender = Sender(ser, options, progress=progress)
                    operator.attach(sender)
                    with _signals(operator, ("SIGINT", "SIGTERM")):
                        if job is None:
                            reports = [sender.stream(pulses, zero=zero)]
                        else:
                            reports = sender.run_job(job, zero=zero)
            finally:
                with contextlib.suppress(Exception):
                    ser.close()
        finally:  # the planner thread stopped before the process may exit
            if job is not None and job.feed is not None:
                job.feed.close()
    last = reports[-1]
    executed = sum(r.executed_periods for r in reports)
    extra = job.report() if job is not None else {"sections": 1}
    if as_json:
        body = {**last.to_json(), "executed_periods": executed,
                "frames_sent": sum(r.frames_sent for r in reports),
                "bytes_sent": sum(r.bytes_sent for r in reports),
                "retransmits": sum(r.retransmits for r in reports),
                "duration_s": sum(r.duration_s for r in reports), **extra}  # fmt: skip
        # "program" as every command names it (standard input is "<stdin>").
        name = "<stdin>" if program == "-" else program
        click.echo(json.dumps({"ok": True, "program": name, **body}))
        return
    holds = extra.get("holds", [])
    hold_text = "".join(f"; feed hold: deceleration began {h['latency_s'] * 1e3:.0f} ms after "
                        f"the request, at rest after {h['stop_s'] * 1e3:.0f} ms"
                        for h in holds)  # fmt: skip
    out.print(
        f"{program}: {executed} periods streamed in {extra['sections']} part(s), "
        f"{sum(r.frames_sent for r in reports)} frames ({sum(r.bytes_sent for r in reports)} "
        f"bytes), {sum(r.retransmits for r in reports)} retransmitted; the card ended at "
        f"{list(last.final_position_steps)} steps{hold_text}",
        markup=False,
    )
    planning = extra.get("planning")
    if planning is not None:
        margin = planning["plan_margin_min_s"]
        out.print(
            f"planning: {planning['windows']} cut window(s); the first planned after "
            f"{planning['first_window_s']:.3f} s, all after "
            + (f"{planning['planned_s']:.3f} s" if planning["planned_s"] is not None
               else "(unfinished)")
            + ("; least margin ahead of the card "
               + (f"{margin:.3f} s" if margin is not None else "— (no window while moving)"))
            + f"; {planning['holds']} planning hold(s), {planning['held_s']:.3f} s held",
            markup=False,
        )
    for note in extra.get("notes", []):
        err.print(f"stream: note: {note['message']}", markup=False, highlight=False)


@click.command("card-position")
@click.option("--port", required=True, help="The card's serial device.")
@click.option("--allow-url", is_flag=True, help="Accept a pyserial URL as --port.")
@click.option("--baud", type=click.IntRange(min=1), default=115200, show_default=True)
@click.option("--set", "set_to", default=None, metavar="X,Y,Z",
              help="Set the card's position [steps] (protocol version 3; not while a stream "
                   "runs), e.g. 0,0,0 after homing.")
@click.option("--timeout", "timeout_s", type=click.FloatRange(min=0.0, min_open=True),
              default=2.0, show_default=True)
@click.option("--json", "as_json", is_flag=True, help="Print state and position as JSON.")
@_handle_errors
def card_position(port, allow_url, baud, set_to, timeout_s, as_json):
    """Read (or --set) the card's position [steps] and state, e.g. to zero a card between two
    streams without restarting it.

    Example: nurbscnc card-position --port /dev/ttyUSB0 --set 0,0,0
    """
    from nurbscnc.output.stream import protocol as p
    from nurbscnc.output.stream.sender import card_position as exchange
    from nurbscnc.output.stream.sender import open_port

    ser = open_port(port, baud=baud, allow_url=allow_url, write_timeout_s=timeout_s)
    try:
        target = _parse_position(set_to, len(set_to.split(","))) if set_to else None
        status = exchange(ser, target, timeout_s)
    finally:
        with contextlib.suppress(Exception):
            ser.close()
    state = p.CardState(status.state).name
    if as_json:
        click.echo(json.dumps({"ok": True, "state": state,
                               "position_steps": list(status.position_steps)}))  # fmt: skip
        return
    click.echo(f"card: {state}, position {list(status.position_steps)} steps")


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
