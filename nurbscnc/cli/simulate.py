"""``nurbscnc simulate``: the servo simulation of reference points, or of a program planned
first: axis errors, contour error (SPEC eq. 29 and the true distance), cycle time."""

from __future__ import annotations

import json

import click

from nurbscnc.app.load import display_name, read_program_text
from nurbscnc.app.plots import write_simulate_plots
from nurbscnc.app.simulation import (
    is_points_source,
    points_reference,
    rotary_summary,
    run_contour,
    run_reference,
    run_rotary,
    scoped_metrics,
    simulate_points,
)
from nurbscnc.app.summary import machine_json, rapids_words, rotary_text, scope_words
from nurbscnc.cli.common import json_option, load_machine_cli, make_plan, plot_option
from nurbscnc.cli.console import out
from nurbscnc.cli.handle import handle_errors
from nurbscnc.cli.options import planning_options


@click.command()
@click.argument("source", type=click.Path(allow_dash=True))
@json_option
@plot_option
@click.option(
    "--hold",
    type=click.Choice(["foh", "zoh"]),
    default="foh",
    help="Reference between samples: linear (foh, as a pulse-train card) or steps.",
)
@planning_options
@handle_errors
def simulate(source, as_json, plot_dir, hold, **settings):
    """Servo simulation of reference points (CSV/NPZ from `run`) or of a program (planned
    first): axis errors, contour error (eq. 29 and true distance), cycle time.

    Example: nurbscnc simulate points.csv --json
    """
    # stdin is recognised by its content: a points header (from `run -o -`) or a program
    text = read_program_text("-") if source == "-" else None
    if is_points_source(source, text):
        mach = load_machine_cli(settings["machine"], settings["overrides"])
        points, path, rotary = points_reference(source, text, mach)
        name, run = display_name(source), None
    else:
        prog, mach, run = make_plan(source, **settings, text=text)
        points, path = run_reference(run)
        rotary = run_rotary(run.samples)
        name = prog.name
    sim, contour, m = simulate_points(points, path, mach, hold)
    feed = None
    if run is not None:
        contour, feed = run_contour(run, sim, contour, mach)
    m = scoped_metrics(m, contour, feed)
    if plot_dir:
        write_simulate_plots(
            sim, contour, plot_dir, name, mach.limits.contour_tolerance_mm * 1000.0, feed
        )
    if as_json:
        from nurbscnc.plan.report import metrics_json

        click.echo(
            json.dumps(
                {
                    "ok": True,
                    "program": name,
                    "samples": int(points.shape[0]),
                    **metrics_json(m),
                    **rotary_summary(rotary),
                    **machine_json(mach),
                }
            )
        )
        return
    out.print(
        f"{name}: {points.shape[0]} reference points, cycle time {m['cycle_time_s']:.4f} s",
        markup=False,
    )
    out.print(
        f"  axis error X: max {m['axis_x_max_um']:.2f} µm, RMS {m['axis_x_rms_um']:.2f} µm;"
        f" Y: max {m['axis_y_max_um']:.2f} µm, RMS {m['axis_y_rms_um']:.2f} µm",
        markup=False,
    )
    scope = scope_words(m["contour_scope"])
    out.print(
        f"  contour error{scope} (true distance): max {m['true_max_um']:.2f} µm, RMS "
        f"{m['true_rms_um']:.2f} µm, mean {m['true_mean_um']:.2f} µm"
        f"{rapids_words(m['rapids_true_max_um'])}",
        markup=False,
    )
    out.print(
        f"  contour error{scope} (eq. 29): max {m['contour_max_um']:.2f} µm, RMS "
        f"{m['contour_rms_um']:.2f} µm, mean {m['contour_mean_um']:.2f} µm",
        markup=False,
    )
    note = rotary_text(rotary_summary(rotary))
    if note:
        out.print(note, markup=False)
