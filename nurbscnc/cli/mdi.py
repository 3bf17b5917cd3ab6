"""``nurbscnc mdi`` and ``nurbscnc jog``: a few blocks, or an incremental move, run against
the card's current position — interpreted from there with the parameter file's offsets,
planned within the machine's limits and soft limits, streamed, and the parameter file
written back."""

from __future__ import annotations

import json

import click

from nurbscnc.cli import console
from nurbscnc.cli.handle import handle_errors
from nurbscnc.cli.options import (
    link_timeout_option,
    planning_options,
    stall_limit_option,
    user_m_timeout_option,
)
from nurbscnc.errors import StreamError


def _link_options(func):
    """The card's port and the stream's options (as ``stream``'s)."""
    for option in reversed(
        (
            click.option("--port", required=True, help="The card's serial device."),
            click.option("--allow-url", is_flag=True, help="Accept a pyserial URL as --port."),
            click.option("--baud", type=click.IntRange(min=1), default=115200, show_default=True),
            click.option(
                "--batch",
                type=click.IntRange(1, 80),
                default=16,
                show_default=True,
                help="Periods per frame.",
            ),
            link_timeout_option,
            stall_limit_option,
            user_m_timeout_option,
            click.option("--quiet", is_flag=True, help="No progress bar."),
            click.option("--json", "as_json", is_flag=True, help="Print the report as JSON."),
        )
    ):
        func = option(func)
    return func


@click.command()
@click.argument("blocks", nargs=-1, required=True)
@click.option(
    "--optional-stop", is_flag=True, help="Wait at M1 (optional stop) too; without it M1 is passed."
)
@_link_options
@planning_options
def mdi(blocks, **kwargs):
    """Run BLOCKS (one or more G-code lines; each argument may hold several lines) from the
    card's current position, as LinuxCNC's MDI.

    The card's position (steps over the profile's steps per mm: machine coordinates) is
    where the blocks start; the parameter file (--var, $NURBSCNC_VAR, the profile's
    program.var_file) gives the work offsets, so X3 Y4 is a work position, machine =
    work + offsets. The blocks are checked and planned within the profile's limits and soft
    limits before anything moves (an error: mdi:LINE:COL, exit 2, the card not moved,
    nothing written); then streamed; then the parameter file is written back (atomically):
    G10 L20 P1 X0 Y0 Z0 makes the card's position G54's zero without moving it. G28/G30 go
    to the stored positions; M0/M6 wait at rest (Enter or SIGUSR2); M100-M199 run their
    executable. Each call starts from the default modes (G21 G90 G17 G94, no tool offset).

    Example: nurbscnc mdi "G10 L20 P1 X0 Y0 Z0" --port /dev/ttyUSB0
    """
    _run(program="mdi", blocks=blocks, jog=None, **kwargs)


@click.command()
@click.argument("moves", nargs=-1, required=True)
@click.option(
    "--feed",
    "feed_mm_min",
    type=click.FloatRange(min=0.0, min_open=True),
    default=None,
    metavar="MM_PER_MIN",
    help="Move at this feed (G1) instead of the rapid rate (G0); deg/min for a jog of "
    "A, B or C alone (LinuxCNC's rate).",
)
@_link_options
@planning_options
def jog(moves, feed_mm_min, **kwargs):
    """Move the card by MOVES (per axis, machine axes: X+1.5 Y-2 Z0.5 in mm, A+10 in
    degrees when the machine has an A axis and the card drives it) from where it stands:
    one straight move in machine coordinates (G53: work offsets, G92 and a rotated system
    leave a jog alone; a wrapped rotary axis turns by an incremental G91 move, after the
    X Y Z move when both are jogged), within the profile's limits and soft limits. The parameter
    file is read (its G28/G30 positions are untouched) and written back like mdi's.

    Example: nurbscnc jog X+1.5 Z-0.2 --port /dev/ttyUSB0
    """
    _run(program="jog", blocks=None, jog=(moves, feed_mm_min), optional_stop=False, **kwargs)


@handle_errors
def _run(program, blocks, jog, port, allow_url, baud, batch, timeout_s, **kwargs):
    """Both commands (``program``: the name errors are reported under)."""
    from nurbscnc.app.load import read_tool_table
    from nurbscnc.app.mdi import jog_block, mdi_job
    from nurbscnc.app.settings import run_options_of
    from nurbscnc.app.stream import progress_position
    from nurbscnc.app.varfile import program_inputs, user_m_timeout_s, write_back
    from nurbscnc.cli.common import load_machine_cli
    from nurbscnc.cli.controls import card_at_rest, card_port

    settings = dict(kwargs)
    as_json, quiet = settings.pop("as_json"), settings.pop("quiet")
    optional_stop = settings.pop("optional_stop")
    timeout_m_s = settings.pop("user_m_timeout_s")
    stall_limit_s = settings.pop("stall_limit_s")
    options = run_options_of(settings)
    mach = load_machine_cli(settings.get("machine"), settings.get("overrides", ()))
    inputs = program_inputs(mach, settings.get("var"), settings.get("user_m_path", ()), writes=True)
    table = settings.get("tool_table")
    tools = read_tool_table(table) if table else None
    link = {
        "port": port,
        "baud": baud,
        "allow_url": allow_url,
        "batch": batch,
        "timeout_s": timeout_s,
        "lead": None,
        "stall_limit_s": stall_limit_s,
        "user_m_timeout_s": user_m_timeout_s(mach, timeout_m_s),
        "mach": mach,
    }
    with card_port(link) as link["ser"]:
        steps = card_at_rest(link["ser"], timeout_s)
        if jog is not None:
            blocks = [jog_block(jog[0], steps, mach, jog[1])]
        job = mdi_job(blocks, mach, inputs, steps, options, tools, optional_stop)
        link["where"] = progress_position(mach, inputs, job.program)
        final = _execute(job, link, quiet, as_json) if job.moves else list(steps)
    if not job.moves:
        _run_stops(job.stops, link)
    written = write_back(inputs, job.program)
    if written is None and _sets_offsets(job.program):
        console.err.print(
            f"{program}: note: no parameter file (--var, $NURBSCNC_VAR, program.var_file): "
            "the offsets and positions set here are not kept",
            markup=False,
            highlight=False,
        )
    _report(program, job, steps, final, written, mach, as_json)


def _sets_offsets(prog) -> bool:
    """Whether the blocks changed a coordinate parameter (G10, G92, G28.1, a G54-G59.3
    choice) — what only the parameter file keeps."""
    from nurbscnc.program.coords import SYSTEM_INDEX, is_coordinate_parameter

    default = {SYSTEM_INDEX: 1.0}  # G54, all offsets zero
    return any(
        is_coordinate_parameter(k) and v != default.get(k, 0.0) for k, v in prog.parameters.items()
    )


def _execute(job, link: dict, quiet: bool, as_json: bool) -> list[int]:
    """Stream the blocks' motion (the controller's section loop, as ``stream``); the card's
    final position [steps]."""
    from nurbscnc.cli.controls import Operator, routed_signals
    from nurbscnc.cli.stream import _send

    operator = Operator()
    with routed_signals(operator, ("SIGUSR1", "SIGUSR2")):
        try:
            if job.job is not None:
                total = int(round(job.job.plan.cycle_time_s / job.job.period_s))
            else:
                total = job.pulses.periods
            operator.attach_job(job.job)
            reports = _send(link, operator, job.job, job.pulses, total, False, quiet, as_json)
        finally:
            if job.job is not None and job.job.feed is not None:
                job.job.feed.close()
    return list(reports[-1].final_position_steps)


def _run_stops(stops, link: dict) -> None:
    """Blocks that move nothing: a user M-code's executable runs (the card is at rest); a
    program stop or tool change has nothing to wait for."""
    from nurbscnc.cli.controls import user_m_runner
    from nurbscnc.controller.stops import is_user_m

    run = user_m_runner(link["user_m_timeout_s"], console.err)
    for stop in stops:
        code = getattr(stop, "code", "")
        if is_user_m(code):
            result = run(stop)
            if result.returncode != 0:
                why = (
                    f"did not end within {result.timeout_s:g} s and was killed"
                    if result.returncode is None
                    else f"exited with status {result.returncode}"
                )
                raise StreamError(f"line {stop.line}: {code} ({stop.argv[0]}) {why}")


def _report(program: str, job, start_steps, final_steps, written, mach, as_json: bool) -> None:
    """What the call did: JSON on stdout, or a line."""
    from nurbscnc.app.stream import position_abc_deg, position_mm
    from nurbscnc.app.varfile import work_report

    final_mm = position_mm(final_steps, mach)
    final_abc = position_abc_deg(final_steps, mach)
    body = {
        "ok": True,
        "command": program,
        "moved": job.moves,
        "start_position_steps": list(map(int, start_steps)),
        "start_position_mm": list(job.start_mm),
        "final_position_steps": list(map(int, final_steps)),
        "final_position_mm": final_mm,
        **work_report(job.program.parameters, final_mm),
        "var_file": written,
    }
    if final_abc:
        body["final_abc_deg"] = final_abc
    if as_json:
        click.echo(json.dumps(body))
        return
    mm = ", ".join(f"{v:.4f}" for v in final_mm)
    mm += "".join(f", {a.upper()} {v:.4f}°" for a, v in final_abc.items())
    wk = ", ".join(f"{v:.4f}" for v in body["work_position_mm"])
    what = "moved to" if job.moves else "stands at"
    kept = f"; parameter file {written} written" if written else "; no parameter file"
    console.out.print(
        f"{program}: the card {what} {list(final_steps)} steps ({mm} mm machine; "
        f"{body['coordinate_system']} {wk} mm){kept}",
        markup=False,
    )
