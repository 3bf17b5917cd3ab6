"""``nurbscnc compare``: the paper's Tables 4 and 5, four algorithms on one NURBS block,
each simulated on the servo model."""

from __future__ import annotations

import json

import click

from nurbscnc.app.load import load_program
from nurbscnc.app.plots import write_compare_plots
from nurbscnc.app.summary import machine_json
from nurbscnc.cli.common import json_option, load_machine_cli, plot_option, program_argument
from nurbscnc.cli.console import out
from nurbscnc.cli.handle import handle_errors
from nurbscnc.cli.options import machine_options


@click.command()
@program_argument
@json_option
@plot_option
@click.option(
    "--rotate",
    "angles",
    type=float,
    multiple=True,
    help="Rotate the block about Z by this angle [deg]; repeat for Table 5.",
)
@click.option(
    "--block",
    type=click.IntRange(min=1),
    default=1,
    help="Which NURBS block of the program (1-based).",
)
@click.option(
    "--algorithm",
    "algorithms",
    multiple=True,
    type=click.Choice(["adaptive", "curvature", "ph-lookahead", "ours"]),
    help="Only these algorithms (default: all four).",
)
@machine_options
@handle_errors
def compare(program, as_json, plot_dir, angles, block, algorithms, machine, overrides):
    """The paper's Table 4 (and 5 with several --rotate): adaptive feed, curvature feed, the
    paper's PH look-ahead and our best configuration, each simulated on the servo model.

    Example: nurbscnc compare programs/naca2415.nc --rotate 0 --rotate 45 --rotate -45
    """
    from rich.table import Table

    from nurbscnc.studies.compare import (
        ALGORITHMS,
        TABLE4_COLUMNS,
        compare_block,
        nurbs_block,
        row,
    )

    mach = load_machine_cli(machine, overrides)
    prog = load_program(program)
    seg = nurbs_block(prog, block)
    runs = compare_block(seg, mach, tuple(angles) or (0.0,), tuple(algorithms) or ALGORITHMS)
    rows = [row(r) for r in runs]
    if plot_dir:
        write_compare_plots(runs, plot_dir, prog.name, mach.limits.contour_tolerance_mm * 1e3)
    if as_json:
        click.echo(
            json.dumps({"ok": True, "program": prog.name, "rows": rows, **machine_json(mach)})
        )
        return
    table = Table(title=f"{prog.name}: NURBS block on line {seg.line} (µm, s)", show_edge=False)
    for col in (
        "algorithm",
        "angle",
        "X max",
        "X RMS",
        "Y max",
        "Y RMS",
        "eq. 29 max",
        "RMS",
        "mean",
        "true max",
        "time [s]",
    ):
        table.add_column(col, justify="right")
    for r in rows:
        table.add_row(
            r["algorithm"],
            f"{r['angle_deg']:g}°",
            *(f"{r[k]:.2f}" for k in TABLE4_COLUMNS),
            f"{r['cycle_time_s']:.4f}",
        )
    out.print(table)
