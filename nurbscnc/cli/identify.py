"""``nurbscnc identify TRACE``: fit an axis's closed-loop model from a recorded trace and print
it as a machine-profile section (:mod:`nurbscnc.servo.identify`).

Errors name the trace file (the argument is called ``source``).
"""

from __future__ import annotations

import json

import click

from nurbscnc.cli.handle import handle_errors
from nurbscnc.errors import OutputError


@click.command()
@click.argument("source", metavar="TRACE", type=click.Path(dir_okay=False, allow_dash=True))
@click.option(
    "--axis",
    type=click.Choice(["x", "y", "z"]),
    default="x",
    show_default=True,
    help="Which [servo.<axis>] section to print.",
)
@click.option(
    "--order",
    type=click.Choice(["2", "4"]),
    default="4",
    show_default=True,
    help="4: the paper's model (SPEC eq. 25); 2: bandwidth and damping.",
)
@click.option(
    "--cmd",
    "cmd_col",
    default=None,
    help="Column of the commanded position (1-based number, or header name). Default: the "
    "header's cmd/command/ref/reference/setpoint column, else column 1.",
)
@click.option(
    "--fb",
    "fb_col",
    default=None,
    help="Column of the actual (feedback) position. Default: the header's "
    "fb/feedback/pos/position/actual column, else column 2.",
)
@click.option(
    "--time",
    "time_col",
    default=None,
    help="Column of the time [s, or the unit its name gives: time_ms]; gives the sample "
    "period. Default: the header's t/time column, if any.",
)
@click.option(
    "--period-ms",
    type=click.FloatRange(min=0, min_open=True),
    default=None,
    help="Sample period [ms] (e.g. the servo period of a halsampler capture).",
)
@click.option(
    "--delay",
    type=click.IntRange(min=0),
    default=0,
    show_default=True,
    help="Periods by which the feedback is recorded late (1 for a LinuxCNC capture "
    "whose encoder is read before the period's command is written).",
)
@click.option(
    "--min-fit",
    type=click.FloatRange(0, 100),
    default=None,
    help="Least fit [%, NRMSE] a model is printed with (default 90, servo.identify.MIN_FIT); "
    "below it: exit 2, saying why.",
)
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
@handle_errors
def identify(source, axis, order, cmd_col, fb_col, time_col, period_ms, delay, min_fit, as_json):
    """Fit the closed-loop position model of one axis from TRACE ('-' for stdin): commanded
    and actual position, one sample per line (whitespace or commas; '#' comments; an optional
    header line of column names), e.g. a LinuxCNC halsampler capture of pos-cmd and pos-fb.

    Columns are found by the header's names (t, cmd, fb and the like), else 1 and 2; the
    period from a time column or --period-ms. Prints a [servo.AXIS] profile section with the
    fit's quality (NRMSE fit, R², residual RMS) and poles; a fit below --min-fit (90 %) is
    refused (exit 2). The trace should start at rest and move the axis through steps or fast
    moves. Example: nurbscnc identify trace.txt --period-ms 1 --axis y
    """
    from nurbscnc.output.inputs import read_input_bytes
    from nurbscnc.servo.identify import (
        MIN_FIT,
        fit_axis,
        parse_trace,
        profile_section,
        require_quality,
    )

    data = read_input_bytes(source, "the trace")
    try:
        text = data.decode("utf-8").replace("\r\n", "\n").replace("\r", "\n")
    except UnicodeDecodeError as exc:
        raise OutputError(f"cannot read {source}: {exc}") from exc
    trace = parse_trace(
        text, cmd_col, fb_col, time_col, None if period_ms is None else period_ms * 1e-3
    )
    fit = fit_axis(trace, int(order), delay)
    require_quality(fit, MIN_FIT if min_fit is None else min_fit / 100.0, trace.columns)
    name = "<stdin>" if source == "-" else source
    section = profile_section(fit, axis, name, trace.columns)
    if as_json:
        out = {
            "ok": True,
            "source": name,
            "axis": axis,
            "order": fit.order,
            "samples": fit.samples,
            "period_s": fit.period_s,
            "delay_samples": fit.delay,
            "numerator": fit.numerator.tolist(),
            "denominator": fit.denominator.tolist(),
            "poles": [[p.real, p.imag] for p in fit.poles],
            "dc_gain": fit.dc_gain,
            "offset_um": fit.offset_mm * 1e3,
            "fit": fit.fit,
            "r2": fit.r2,
            "residual_rms_um": fit.residual_rms_mm * 1e3,
            "following_error_rms_um": fit.following_error_rms_mm * 1e3,
            "profile_section": section,
        }
        if fit.order == 2:
            out.update(bandwidth_hz=fit.bandwidth_hz, damping=fit.damping)
        click.echo(json.dumps(out))
        return
    click.echo(section, nl=False)
