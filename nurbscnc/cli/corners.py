"""``nurbscnc corners`` and ``nurbscnc ph``: the sharp corners of a program's NURBS blocks
(SPEC §5) and the PH quintic fits of their regions (Table 1)."""

from __future__ import annotations

import json

import click

from nurbscnc.app.load import load_program
from nurbscnc.app.reports import corners_json, ph_json, region_name
from nurbscnc.app.summary import machine_json
from nurbscnc.cli.common import json_option, load_machine_cli, program_argument
from nurbscnc.cli.console import out
from nurbscnc.cli.handle import handle_errors
from nurbscnc.cli.options import machine_options


@click.command()
@program_argument
@json_option
@click.option(
    "--feed",
    type=float,
    default=None,
    help="Feed F [mm/min] for the threshold (default: each block's F, capped by V_max).",
)
@click.option("--amax", type=float, default=None, help="A_max [mm/s²] (default: the profile's).")
@machine_options
@handle_errors
def corners(program, as_json, feed, amax, machine, overrides):
    """Sharp corners of each NURBS block: curvature peaks above κ_th = A_max/F² (SPEC §5).

    Example: nurbscnc corners programs/naca2415.nc --json
    """
    from rich.table import Table

    from nurbscnc.plan.corners import program_corners, tangent_junctions

    mach = load_machine_cli(machine, overrides, {"limits.a_max_mm_s2": amax})
    if feed is not None and not feed > 0:
        raise click.BadParameter("must be > 0", param_hint="--feed")
    prog = load_program(program)
    result = program_corners(
        prog.segments,
        mach.limits.a_max_mm_s2,
        mach.limits.v_max_mm_s,
        feed / 60.0 if feed else None,
    )
    junctions = tangent_junctions(prog.segments)
    if as_json:
        click.echo(json.dumps({**corners_json(result, junctions), **machine_json(mach)}))
        return
    table = Table(title=f"{prog.name}: sharp corners (κ > κ_th = A_max/F²)", show_edge=False)
    for col in (
        "line",
        "κ_th [1/mm]",
        "peak κ [1/mm]",
        "x [mm]",
        "y [mm]",
        "z [mm]",
        "u_a",
        "u_b",
        "length [mm]",
    ):
        table.add_column(col, justify="right")
    count = 0
    for sc in result:
        for r in sc.regions:
            count += 1
            table.add_row(
                str(sc.line),
                f"{sc.kappa_threshold_per_mm:.4g}",
                f"{r.kappa_peak_per_mm:.5g}",
                *(f"{c:.4f}" for c in r.point_mm),
                f"{r.u_a:.6g}",
                f"{r.u_b:.6g}",
                f"{r.length_mm:.4f}",
            )
    if count:
        out.print(table)
    else:
        out.print(f"{prog.name}: no sharp corners in {len(result)} NURBS block(s)")
    sharp = [j for j in junctions if j.angle_deg > 1e-3]
    if sharp:
        out.print(
            f"{len(sharp)} tangent discontinuities between segments "
            f"(largest {max(j.angle_deg for j in sharp):.2f}°)"
        )


@click.command()
@program_argument
@json_option
@click.option(
    "--tolerance-um",
    type=float,
    default=None,
    help="PH fit tolerance e [µm] (default: the profile's, 1 µm).",
)
@click.option("--no-split", is_flag=True, help="Fit one PH quintic per region (no splitting).")
@machine_options
@handle_errors
def ph(program, as_json, tolerance_um, no_split, machine, overrides):
    """PH quintic fits of every corner region: pieces, RMS and max deviation (Table 1 layout).

    Example: nurbscnc ph programs/naca2415.nc --tolerance-um 1
    """
    from rich.table import Table

    from nurbscnc.plan.report import corner_fits

    mach = load_machine_cli(machine, overrides, {"limits.ph_tolerance_um": tolerance_um})
    e_um = mach.limits.ph_tolerance_mm * 1000.0
    prog = load_program(program)
    rows = corner_fits(prog, mach, split=not no_split)
    if as_json:
        click.echo(json.dumps({**ph_json(rows, e_um, no_split), **machine_json(mach)}))
        return
    table = Table(title=f"{prog.name}: PH quintic fits (e = {e_um:g} µm)", show_edge=False)
    for col in (
        "line",
        "region",
        "length [mm]",
        "unsplit RMS [µm]",
        "unsplit max [µm]",
        "pieces",
        "RMS [µm]",
        "max [µm]",
    ):
        table.add_column(col, justify="right")
    for k, (sc, r, unsplit, fit) in enumerate(rows):
        table.add_row(
            str(sc.line),
            region_name(k),
            f"{r.length_mm:.4f}",
            f"{unsplit.rms_um:.4f}",
            f"{unsplit.max_um:.4f}",
            str(len(fit.pieces)),
            f"{fit.rms_um:.4f}",
            f"{fit.max_um:.4f}",
        )
    if rows:
        out.print(table)
    else:
        out.print(f"{prog.name}: no corner regions, nothing to fit")
