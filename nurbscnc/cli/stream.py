"""``nurbscnc stream``: stream a program (planned while the card runs) or a file of
reference points to a pulse-train card, with the operator's feed hold, continue, override
and abort."""

from __future__ import annotations

import contextlib
import json
import sys

import click

from nurbscnc.app.stream import (
    ProgramStream,
    axes_points_of_file,
    is_points_file,
    position_mm,
    progress_position,
    pulses_of_points,
    stream_report,
    work_text,
)
from nurbscnc.app.varfile import user_m_timeout_s as user_m_timeout
from nurbscnc.app.varfile import write_back
from nurbscnc.cli import console
from nurbscnc.cli.common import load_machine_cli, nothing_to_send
from nurbscnc.cli.controls import (
    Operator,
    card_at_rest,
    card_port,
    key_reader,
    routed_signals,
    user_m_runner,
)
from nurbscnc.cli.handle import handle_errors
from nurbscnc.cli.options import (
    link_timeout_option,
    planning_options,
    stall_limit_option,
    user_m_timeout_option,
)
from nurbscnc.errors import ConfigError


# -- what is sent (everything before the port is opened) -----------------------------------------
def load_pulse_program(path: str, machine=None, overrides=(), **_settings):
    """The pulses of the reference-point file ``path`` (.csv/.npz) and the machine. Everything
    that can be wrong with the file — the servo period of its points, the soft limits, the
    card's pulse limit — raises here, before any port is touched. Returns
    ``(PulseProgram, Machine)``."""
    mach = load_machine_cli(machine, overrides)
    points, axes = axes_points_of_file(path, mach)
    return pulses_of_points(points, mach, None, axes), mach


@contextlib.contextmanager
def _progress_bar(enabled: bool, total: int, keys: bool = False, where=None):
    """A rich progress line on stderr; yields a callback for :class:`Sender`. Without it, a
    message still tells when the stream waits for the operator (and why). ``where(steps)``:
    the card's position as text."""
    err = console.err
    how = "Enter or SIGUSR2 continues" if keys else "SIGUSR2 continues"
    last = {"note": ""}

    def tell(pr) -> None:
        waiting = "waiting:" in pr.note
        if waiting and pr.note != last["note"]:
            why = pr.note.split("waiting: ")[1]
            where = f" at line {pr.line}" if why == "feed hold" and pr.line else ""
            err.print(
                f"stream: {why}{where}: the card is at rest; {how}", markup=False, highlight=False
            )
        last["note"] = pr.note if waiting else ""

    if not enabled:
        yield tell
        return
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    with Progress(
        TextColumn("streaming"),
        BarColumn(),
        TextColumn("{task.fields[info]}"),
        TimeElapsedColumn(),
        console=err,
        transient=False,
    ) as bar:
        task = bar.add_task("stream", total=max(total, 1), info="")

        def update(pr) -> None:
            tell(pr)
            info = f"line {pr.line} · executed {pr.executed} · buffer {pr.fill}/{pr.buffer}"
            at = where(pr.position_steps, pr.axes) if where and pr.position_steps else ""
            info += (f" · {at}" if at else "") + (f" · {pr.note}" if pr.note else "")
            bar.update(
                task,
                completed=pr.executed,
                total=max(pr.periods, total, 1),
                info=info.replace("[", "\\["),
            )

        yield update


@click.command()
@click.argument("program", type=click.Path())
@click.option(
    "--port",
    required=True,
    help="The card's serial device, e.g. /dev/ttyUSB0 (opened exclusively).",
)
@click.option(
    "--allow-url",
    is_flag=True,
    help="Accept a pyserial URL (socket://HOST:PORT, rfc2217://...) as --port. "
    "These are unauthenticated network connections.",
)
@click.option(
    "--baud", type=click.IntRange(min=1), default=115200, show_default=True, help="Line rate."
)
@click.option(
    "--batch",
    type=click.IntRange(1, 80),
    default=16,
    show_default=True,
    help="Periods per frame (at most 80 with 3 axes, 59 with 4, 38 with 6).",
)
@link_timeout_option
@stall_limit_option
@click.option(
    "--lead",
    "lead",
    type=click.IntRange(min=1),
    default=None,
    metavar="PERIODS",
    help="Keep at most this many periods queued ahead of the card's execution "
    "(default: its whole buffer): a feed hold acts that much sooner; at least "
    "half the card's buffer.",
)
@click.option(
    "--optional-stop", is_flag=True, help="Wait at M1 (optional stop) too; without it M1 is passed."
)
@click.option(
    "--feed-override",
    type=click.IntRange(10, 200),
    default=100,
    show_default=True,
    metavar="PERCENT",
    help="Feed override at the start [%]; + / - keys change it by 10 % while streaming "
    "(10-200 %; above 100 % the rest is re-planned from the next rest with the programmed "
    "feeds raised, within the machine's V, A and J).",
)
@click.option(
    "--zero",
    is_flag=True,
    help="Run the program from machine zero and declare that the card stands at its start "
    "(sets the card's position; protocol version 3) instead of starting where the card "
    "stands; for a points file, instead of refusing a card elsewhere.",
)
@click.option(
    "--from-line",
    type=click.IntRange(min=1),
    default=None,
    metavar="N",
    help="Start at source line N (run from line): the program is interpreted "
    "whole, the tool goes up to a safe Z, across, and down to line N's start.",
)
@user_m_timeout_option
@click.option("--quiet", is_flag=True, help="No progress bar.")
@click.option("--json", "as_json", is_flag=True, help="Print the final report as JSON.")
@planning_options
@handle_errors
def stream(
    program,
    port,
    allow_url,
    baud,
    batch,
    timeout_s,
    stall_limit_s,
    lead,
    optional_stop,
    feed_override,
    zero,
    from_line,
    user_m_timeout_s,
    quiet,
    as_json,
    **settings,
):
    """Stream PROGRAM (.nc/.ngc, or reference points .csv/.npz) to a pulse-train card.

    The program is parsed and interpreted before the port is opened; then the card's
    position is read (refused while a stream runs on it or in ALARM) and the program runs
    from there, as LinuxCNC's (its first move goes from where the card stands; --zero: from
    machine zero instead). A points file's first point must be where the card stands. The
    motion is planned cut window by cut window while the card runs (each window checked
    against the soft limits and the card's pulse limit before it is sent; the card waits at
    rest at the end of a cut if planning falls behind). At M0 / M60 (and M1 with
    --optional-stop) the card stops at rest and the stream waits: Enter (on a terminal) or
    SIGUSR2 continues. SIGUSR1 or the space key is a feed hold: the tool decelerates along
    the path within the acceleration and jerk limits, stops, and continues on Enter /
    SIGUSR2 (the rest re-planned from rest). A program that turns a rotary axis (A, B, C)
    and a points file are not re-planned while they run: their feed hold is the card's own
    HOLD, which stops the steps at the next servo period WITHOUT deceleration (the axes
    stop at once, beyond their acceleration and jerk limits), and --from-line and
    --feed-override are refused. + / - change the feed override. Ctrl-C or
    SIGTERM aborts the card at once and exits 130. Exit 0 only when the card reports DONE at
    the program's end position. The parameter file (--var) is read before and written back
    (atomically) once the card is DONE: G10 L2/L20, G92, G28.1/G30.1 persist.

    Example: nurbscnc stream part.nc --port /dev/ttyUSB0 --optional-stop
    """
    operator = Operator()
    points_file = is_points_file(program)
    # Hold/resume are caught from the start: planning a long program takes time, and
    # SIGUSR1's default action would end the command silently.
    with routed_signals(operator, ("SIGUSR1", "SIGUSR2")):
        job = pulses = inputs = prog = None
        if points_file and (from_line is not None or feed_override != 100):
            raise ConfigError(
                "--from-line and --feed-override need a program (.nc/.ngc), "
                "not a file of reference points"
            )
        mach = load_machine_cli(settings.get("machine"), settings.get("overrides", ()))
        link = {
            "port": port,
            "baud": baud,
            "allow_url": allow_url,
            "batch": batch,
            "timeout_s": timeout_s,
            "stall_limit_s": stall_limit_s,
            "lead": lead,
            "user_m_timeout_s": user_m_timeout(mach, user_m_timeout_s),
            "mach": mach,
        }
        if not points_file:
            # Checked before the port; then planned from where the card stands (--zero:
            # from machine zero, the card declared there).
            setup = ProgramStream(program, mach, settings)
            inputs = setup.inputs
            if setup.still():  # no motion: it ran, its parameters persist
                return nothing_to_send(program, as_json, write_back(inputs, setup.program))
        else:  # read and checked before the port
            pulses, mach = load_pulse_program(program, **settings)
        with card_port(link) as link["ser"]:
            if not points_file:
                here = None if zero else card_at_rest(link["ser"], timeout_s)
                job, pulses, prog = setup.plan(
                    here, from_line, optional_stop, feed_override / 100.0
                )
            try:
                if job is None:
                    if from_line is not None or feed_override != 100:
                        raise ConfigError(_needs_the_job(settings))
                    total = pulses.periods
                else:
                    total = int(round(job.plan.cycle_time_s / job.period_s / job.override))
                operator.attach_job(job)
                link["where"] = progress_position(mach, inputs, prog)
                reports = _send(link, operator, job, pulses, total, zero, quiet, as_json)
                if inputs is not None:  # the program ran to its end: its offsets persist
                    write_back(inputs, prog)
            finally:  # the planner thread stopped before the process may exit
                if job is not None and job.feed is not None:
                    job.feed.close()
    parameters = prog.parameters if inputs is not None and inputs.var_path else None
    _print_report(program, job, reports, as_json, mach, parameters)


def _needs_the_job(settings) -> str:
    """Why ``--from-line`` and ``--feed-override`` are refused for a program planned whole."""
    if settings.get("algorithm", "ph-lookahead") != "ph-lookahead":
        return (
            "--from-line and --feed-override need the look-ahead planner (--algorithm ph-lookahead)"
        )
    return (
        "--from-line and --feed-override need the look-ahead planner without "
        "--precompensate (a pre-compensated program is streamed as planned whole)"
    )


def _send(
    link: dict, operator: Operator, job, pulses, total: int, zero: bool, quiet: bool, as_json: bool
) -> list:
    """Stream the ``job`` (through the controller's section loop) or the ``pulses`` without
    one on the card's open port (``link``: ``ser``, the link options, the user M-codes'
    timeout ``user_m_timeout_s`` and the machine ``mach``, for positions in mm), with the
    operator's keys and signals routed; returns the sender's reports (one per part of the
    stream)."""
    from nurbscnc.controller.run import run_job
    from nurbscnc.output.stream.sender import Sender, SenderOptions

    options = SenderOptions(
        batch_periods=link["batch"],
        timeout_s=link["timeout_s"],
        lead_periods=link["lead"],
        stall_limit_s=link["stall_limit_s"],
    )
    ser = link["ser"]
    show = not (quiet or as_json) and console.err.is_terminal
    keys = not as_json and sys.stdin is not None and sys.stdin.isatty()
    with (
        _progress_bar(show, total, keys, link.get("where")) as progress,
        key_reader(operator, keys),
    ):
        sender = Sender(ser, options, progress=progress)
        operator.attach(sender)
        with routed_signals(operator, ("SIGINT", "SIGTERM")):
            if job is None:
                return [sender.stream(pulses, zero=zero)]
            sender.job = job
            return run_job(
                job,
                sender,
                sender.wait_idle,
                zero=zero,
                run_user_m=user_m_runner(
                    link["user_m_timeout_s"], console.err, lambda: sender.abort_requested
                ),
                positions_mm=lambda steps: position_mm(steps, link["mach"]),
            )


def _print_report(program: str, job, reports: list, as_json: bool, mach, parameters=None) -> None:
    """The stream's final report: JSON on stdout, or a line on stdout (and one on the
    planning), notes on stderr; ``parameters``: the program's at its end, when a parameter
    file is known (the final work position)."""
    report = stream_report(program, job, reports, mach, parameters)
    if as_json:
        click.echo(json.dumps(report))
        return
    holds = report.get("holds", [])
    hold_text = "".join(
        f"; feed hold: deceleration began {h['latency_s'] * 1e3:.0f} ms after "
        f"the request, at rest after {h['stop_s'] * 1e3:.0f} ms"
        for h in holds
    )
    console.out.print(
        f"{program}: {report['executed_periods']} periods streamed in {report['sections']} "
        f"part(s), {report['frames_sent']} frames ({report['bytes_sent']} bytes), "
        f"{report['retransmits']} retransmitted; the card ended at "
        f"{list(reports[-1].final_position_steps)} steps "
        f"({', '.join(f'{v:.4f}' for v in report['final_position_mm'])} mm"
        + "".join(f", {a.upper()} {v:.4f}°" for a, v in report.get("final_abc_deg", {}).items())
        + f"{work_text(report)}){hold_text}",
        markup=False,
    )
    planning = report.get("planning")
    if planning is not None:
        console.out.print(_planning_text(planning), markup=False)
    for note in report.get("notes", []):
        console.err.print(f"stream: note: {note['message']}", markup=False, highlight=False)


def _planning_text(planning: dict) -> str:
    """The line on the planning of a stream planned while the card ran, in plain words (the
    JSON's ``windows`` are the parts the program is planned in, one per cut)."""
    margin = planning["plan_margin_min_s"]
    parts = planning["windows"]
    return (
        f"planning: {parts} part{'' if parts == 1 else 's'} planned while the card ran; "
        f"the first ready after {planning['first_window_s']:.3f} s, all "
        + (
            f"after {planning['planned_s']:.3f} s"
            if planning["planned_s"] is not None
            else "not before the stream ended"
        )
        + (
            f"; the planner stayed at least {margin:.3f} s ahead of the card"
            if margin is not None
            else "; no part was planned while the card moved"
        )
        + f"; the card waited for the planner {planning['holds']} time"
        + ("" if planning["holds"] == 1 else "s")
        + f", {planning['held_s']:.3f} s in all"
    )
