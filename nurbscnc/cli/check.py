"""``nurbscnc check``: parse, interpret and validate a program without planning it, and
summarise it."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

import click

from nurbscnc.app.check import check_program
from nurbscnc.app.load import display_name
from nurbscnc.app.summary import machine_json
from nurbscnc.cli.common import json_option, load_machine_cli, program_argument
from nurbscnc.cli.console import out, progress_display, show_progress
from nurbscnc.cli.handle import handle_errors
from nurbscnc.cli.options import (
    block_delete_option,
    machine_options,
    subroutine_path_option,
    tool_table_option,
    user_m_path_option,
    var_option,
)

if TYPE_CHECKING:
    from nurbscnc.geometry.segments import Program


@click.command()
@program_argument
@json_option
@block_delete_option
@tool_table_option
@subroutine_path_option
@var_option
@user_m_path_option
@machine_options
@handle_errors
def check(
    program,
    as_json,
    no_block_delete,
    tool_table,
    subroutine_path,
    var,
    user_m_path,
    machine,
    overrides,
):
    """Parse and validate PROGRAM ('-' for stdin) and summarise it.

    Validation includes the machine profile's soft limits on the geometry and its
    limits.max_points on a lower bound of the motion time (no planning), in machine
    coordinates: after the offsets of the parameter file (--var; read, never written).

    Example: nurbscnc check programs/naca2415.nc
    """
    # Said on stderr as every command does: the soft limits and max_points checked are its.
    mach = load_machine_cli(machine, overrides, plans=False)
    with progress_display(show_progress(as_json), display_name(program)) as say:
        prog, summary = check_program(
            program,
            mach,
            not no_block_delete,
            tool_table,
            subroutine_path,
            per_segment=as_json,
            progress=say,
            var=var,
            user_m_path=user_m_path,
        )
    if as_json:
        click.echo(json.dumps({**summary, **machine_json(mach)}))
        return
    print_summary(prog, summary)


def print_summary(prog: Program, s: dict) -> None:
    from rich.table import Table
    from rich.text import Text

    out.print(
        Text.assemble(
            (prog.name, "bold"), f": ok — {s['blocks']} blocks, {len(prog.segments)} segments"
        )
    )
    counts = ", ".join(f"{v} {k}" for k, v in sorted(s["counts"].items())) or "none"
    out.print(f"  segments: {counts}")
    out.print(
        f"  path length: {s['length_mm']:.3f} mm at feed, {s['rapid_length_mm']:.3f} mm rapid"
    )
    lo, hi = s["bounding_box_mm"]["min"], s["bounding_box_mm"]["max"]
    out.print(
        "  bounding box [mm]: "
        + "  ".join(f"{a} {lo[i]:.3f}..{hi[i]:.3f}" for i, a in enumerate("XYZ"))
    )
    if s.get("var_file"):
        start = prog.frames[0][1] if prog.frames else "G54"
        out.print(f"  parameter file: {s['var_file']} ({start} at the start)", markup=False)
    f = s["feed_range_mm_s"]
    if f["min"] is not None:
        out.print(f"  feed [mm/min]: {f['min'] * 60.0:.6g}..{f['max'] * 60.0:.6g}")
    nurbs = [e for e in s["segments"] if e["kind"] == "nurbs"]
    if nurbs:
        table = Table(title="NURBS blocks", show_edge=False)
        for col in ("line", "plane", "degree", "control points", "knots", "length [mm]"):
            table.add_column(col, justify="right")
        for e in nurbs:
            table.add_row(
                str(e["line"]),
                e["plane"],
                str(e["degree"]),
                str(e["control_points"]),
                str(e["knots"]),
                f"{e['length_mm']:.4f}",
            )
        out.print(table)
    for n in s["notes"]:
        out.print(f"  note (line {n['line']}): {n['message']}", markup=False)
