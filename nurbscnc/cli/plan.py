"""``nurbscnc plan``: plan a program and summarise the plan (``--explain``: why the feed is
what it is; ``--dump-profile``: the jerk-limited profile at every servo period)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import click

from nurbscnc.app.load import display_name, read_program_text
from nurbscnc.app.output import write_profile_dump
from nurbscnc.app.plots import write_plan_plots
from nurbscnc.app.summary import (
    clock_suffix,
    precompensation_text,
    rapids_words,
    rest_text,
    rotary_text,
    scope_words,
    summary_json,
    summary_of,
)
from nurbscnc.cli.common import json_option, make_plan, plot_option, program_argument
from nurbscnc.cli.console import echo_source_line, err, out, progress_display, show_progress
from nurbscnc.cli.handle import handle_errors
from nurbscnc.cli.options import planning_options

if TYPE_CHECKING:
    from rich.console import Console


@click.command()
@program_argument
@json_option
@click.option(
    "--dump-profile",
    type=click.Path(allow_dash=True),
    default=None,
    help="Write t, s, v, a, j, piece at every servo period (CSV, or NPZ by extension).",
)
@click.option(
    "--explain",
    is_flag=True,
    help="Why the feed is what it is: per source line the time, the programmed and "
    "achieved feed and the limit that set it (the costliest lines), the time "
    "under each limit, the corners that stopped and why.",
)
@click.option("--explain-all", is_flag=True, help="As --explain, with every line in program order.")
@plot_option
@planning_options
@handle_errors
def plan(program, as_json, dump_profile, explain, explain_all, plot_dir, **settings):
    """Plan PROGRAM: pieces, corners, cycle time, lower bound, predicted contour error.

    Example: nurbscnc plan programs/naca2415.nc --explain
    """
    explain = explain or explain_all
    _refuse_conflicts(dump_profile, as_json, explain, settings.get("algorithm", "ph-lookahead"))
    # --explain shows the source lines: the program is read once, here (stdin too).
    text = read_program_text(program) if explain else None
    with progress_display(show_progress(as_json), display_name(program)) as say:
        prog, mach, run = make_plan(
            program, **settings, text=text, progress=say, keep_reference=bool(plot_dir)
        )
        say("summarising")
        summary = summary_of(prog, mach, run)
    expl = None
    if explain or plot_dir:
        from nurbscnc.plan.explain import explain_plan

        expl = explain_plan(prog, mach, run.plan) if run.plan is not None else None
    if expl is not None and explain:
        summary["explain"] = expl.as_dict()
    if plot_dir:
        with progress_display(show_progress(as_json), prog.name) as say:
            say("plotting")
            write_plan_plots(run, plot_dir, prog, expl, mach)
    if dump_profile:
        write_profile_dump(dump_profile, run, mach)
    if as_json:
        click.echo(summary_json(summary))
        return
    print_plan_summary(prog, mach, summary, err if dump_profile == "-" else out)
    if explain and expl is not None:  # None: no motion, nothing planned to explain
        print_explanation(expl, out, None if explain_all else EXPLAIN_LINES, text.splitlines())


def _refuse_conflicts(dump_profile, as_json: bool, explain: bool, algorithm: str) -> None:
    """The usage errors of ``plan``'s output options, before anything is read."""
    if dump_profile == "-" and (as_json or explain):
        raise click.UsageError(
            "--dump-profile - and --json/--explain both want stdout; "
            "write the profile to a file or drop --json/--explain"
        )
    baseline = algorithm != "ph-lookahead"
    if dump_profile and baseline:
        raise click.UsageError(
            "--dump-profile needs the look-ahead planner (a baseline has no jerk-limited profile)"
        )
    if explain and baseline:
        raise click.UsageError(
            "--explain needs the look-ahead planner (a baseline has no caps or profile to explain)"
        )


#: Lines ``plan --explain`` shows (the costliest); ``--explain-all`` shows every line.
EXPLAIN_LINES = 20
#: Stopped corners ``plan --explain`` lists.
EXPLAIN_CORNERS = 10


def _feed_text(v_mm_s: float) -> str:
    """A feed [mm/s] as mm/min, the unit of F words ("-" for none)."""
    import numpy as np

    return "-" if not np.isfinite(v_mm_s) else f"{v_mm_s * 60.0:.0f}"


def print_explanation(expl, out: Console, count: int | None, source: list[str]) -> None:
    """The ``plan --explain`` text: time under each limit, the ``count`` costliest lines
    (every line in program order when None), the corners that stopped and why."""
    import numpy as np
    from rich.table import Table
    from rich.text import Text

    from nurbscnc.plan.explain import CORNER_WHY_TEXT, LIMIT_OF_KEY, CornerWhy

    total = expl.cycle_time_s if expl.cycle_time_s > 0 else 1.0
    shares = ", ".join(
        f"{LIMIT_OF_KEY[k].text} {t / total:.1%} ({t:.3f} s)"
        for k, t in expl.total_by_limit_s().items()
    )
    out.print(f"  time by limit: {shares or 'none'}", markup=False)
    n = expl.line.size
    rows = np.arange(n) if count is None else expl.costliest(count)
    which = f"all {n} lines" if count is None else f"the {min(count, n)} costliest of {n} lines"
    table = Table(title=f"{which} (feeds in mm/min)", show_edge=False)
    for col, justify in (
        ("line", "right"),
        ("source", "left"),
        ("time [s]", "right"),
        ("share", "right"),
        ("F", "right"),
        ("peak", "right"),
        ("mean", "right"),
        ("limit", "left"),
    ):
        table.add_column(col, justify=justify)
    for i in rows.tolist():
        line = int(expl.line[i])
        text = source[line - 1] if 0 < line <= len(source) else ""
        shown = echo_source_line(text.strip(), 1, 32)[0]
        t = float(expl.time_s[i] + expl.wait_s[i])
        row = expl.limit_time_s[i]
        limit = expl.limit_text(i)
        if t > 0 and row.max() < t * 0.999:
            limit += f" ({row.max() / t:.0%})"
        table.add_row(
            str(line),
            Text(shown),
            f"{t:.4f}",
            f"{t / total:.1%}",
            _feed_text(float(expl.feed_mm_s[i])),
            _feed_text(float(expl.peak_mm_s[i])),
            _feed_text(float(expl.mean_mm_s[i])),
            limit,
        )
    out.print(table)
    if count is not None and n > count:
        out.print(f"  … {n - count} more lines (plan --explain-all shows every line)", markup=False)
    counts = expl.corner_texts()
    if counts:
        out.print(
            "  corners: " + "; ".join(f"{v} {k}" for k, v in sorted(counts.items())), markup=False
        )
    stops = expl.corner_dicts(stops_only=True)
    for c in stops[:EXPLAIN_CORNERS]:
        x, y, z = c["point_mm"]
        out.print(
            f"  stop at line {c['line']} ({x:.3f}, {y:.3f}, {z:.3f}), a "
            f"{c['turning_deg']:.1f}° turn: {CORNER_WHY_TEXT[CornerWhy[c['why'].upper()]]}",
            markup=False,
        )
    if len(stops) > EXPLAIN_CORNERS:
        out.print(
            f"  … {len(stops) - EXPLAIN_CORNERS} more stopped corners (--json lists every corner)",
            markup=False,
        )


def print_plan_summary(prog, mach, summary: dict, out: Console) -> None:
    """The human summary of ``plan`` on ``out`` (stderr when the profile goes to stdout)."""
    from rich.text import Text

    if summary.get("motion") is False:
        out.print(Text.assemble((prog.name, "bold"), ": ", rest_text(summary)))
        if rotary_text(summary):
            out.print(rotary_text(summary), markup=False)
        return
    if "pieces" in summary:
        out.print(
            Text.assemble(
                (prog.name, "bold"),
                f": {summary['piece_count']} pieces "
                f"({', '.join(f'{v} {k}' for k, v in sorted(summary['pieces'].items()))})",
            )
        )
    else:
        out.print(
            Text.assemble(
                (prog.name, "bold"), f": baseline {summary['algorithm']} (no acceleration limit)"
            )
        )
    out.print(
        f"  cycle time: {summary['cycle_time_s']:.4f} s"
        f"{clock_suffix(summary['cycle_time_s'])} ({summary['samples']} reference points "
        f"at T_s = {summary['period_s'] * 1000:g} ms)"
    )
    if "lower_bound_s" in summary:
        note = "" if "pieces" in summary else "; a baseline ignores A_max and may beat it"
        out.print(
            f"  kinematic lower bound: {summary['lower_bound_s']:.4f} s "
            f"(plan / bound = {summary['lower_bound_ratio']:.3f}{note})"
        )
    if "smoothed" in summary:
        sm = summary["smoothed"]
        out.print(
            f"  smoothed: {sm['lines']} short G1 moves in {sm['runs']} runs as splines, "
            f"within {sm['deviation_max_um']:.2f} µm of the programmed polyline "
            "(--no-smooth: as written)"
        )
    if "feed_fluctuation_max" in summary:
        out.print(
            f"  feed fluctuation on NURBS ({summary['interpolator']} interpolation): "
            f"max {summary['feed_fluctuation_max'] * 100:.2g} %"
        )
    if "contour_true_max_um" in summary:
        how = (
            f"dynamics {summary['dynamics']}, {summary['dynamics_iterations']} re-plans"
            if "pieces" in summary
            else "no dynamics check: a baseline"
        )
        out.print(
            f"  {'predicted' if 'pieces' in summary else 'simulated'} contour error"
            f"{scope_words(summary['contour_scope'])}: "
            f"max {summary['contour_true_max_um']:.2f} µm, RMS "
            f"{'≤ ' if summary.get('contour_bounded_samples') else ''}"
            f"{summary['contour_true_rms_um']:.2f} "
            f"µm (ε_max {mach.limits.contour_tolerance_mm * 1000:g} µm; {how})"
            f"{rapids_words(summary.get('contour_rapids_true_max_um'))}"
        )
    if summary.get("contour_corner_samples"):
        out.print(
            f"  within G64 corners' allowance: {summary['contour_corner_samples']} samples, up "
            f"to {summary['contour_corner_max_um']:.2f} µm from the planned path (within "
            "ε_max + P of the programmed vertex where the plan stops)"
        )
    if rotary_text(summary):
        out.print(rotary_text(summary), markup=False)
    if precompensation_text(summary):
        out.print(precompensation_text(summary), markup=False)
