"""``nurbscnc run``: the whole pipeline, reference points at every servo period, of one
program (``-o``) or of a batch (``--output-dir``, :mod:`nurbscnc.cli.batch`)."""

from __future__ import annotations

import os

import click

from nurbscnc.app.load import display_name
from nurbscnc.app.output import SUFFIX_FORMATS, refuse_overwriting, write_output
from nurbscnc.app.plots import write_plan_plots
from nurbscnc.app.summary import (
    clock_suffix,
    precompensation_text,
    rotary_text,
    summary_json,
    summary_of,
)
from nurbscnc.app.varfile import program_inputs, write_back
from nurbscnc.cli.batch import run_batch
from nurbscnc.cli.common import json_option, make_plan, plot_option
from nurbscnc.cli.console import err, progress_display, show_progress
from nurbscnc.cli.handle import handle_errors
from nurbscnc.cli.options import planning_options
from nurbscnc.errors import ConfigError


@click.command()
@click.argument("programs", nargs=-1, required=True, type=click.Path(allow_dash=True))
@click.option(
    "-o",
    "--output",
    type=click.Path(allow_dash=True),
    default=None,
    help="Reference points: .csv, .npz or - (stdout). One program only.",
)
@click.option(
    "--output-dir",
    type=click.Path(),
    default=None,
    help="Batch: write <name>.csv for every program into this folder.",
)
@click.option(
    "--jobs",
    type=click.IntRange(min=1),
    default=None,
    help="Batch worker processes (default: the number of cores).",
)
@click.option(
    "--format",
    "fmt",
    type=click.Choice(["csv", "npz", "halstreamer"]),
    default=None,
    help="Output format (default: -o's suffix .npz/.hs, else csv; a "
    "format that contradicts the suffix is an error; npz never goes to stdout): "
    "csv, npz, or halstreamer (LinuxCNC streamer text, x y z and the rotary axes used "
    "per servo period; docs/linuxcnc.md).",
)
@click.option("--quiet", is_flag=True, help="No summary on stderr.")
@click.option(
    "--write-var",
    is_flag=True,
    help="Write the parameter file (--var, $NURBSCNC_VAR or the profile's program.var_file) "
    "back once the points are written, as LinuxCNC at the program's end. One program only.",
)
@json_option
@plot_option
@planning_options
@handle_errors
def run(programs, output, output_dir, jobs, fmt, quiet, as_json, plot_dir, **settings):
    """Run the whole pipeline: reference points at every servo period.

    Example: nurbscnc run programs/naca2415.nc -o points.csv

    The CSV header is t,x,y,z,feed,piece,line (s, mm, mm, mm, mm/s, piece index, source
    line), with a, b, c [deg] after z for the rotary axes a program uses; the first row is
    the start point at t = 0, the last the end point at rest.
    """
    if settings.get("write_var") and output_dir is not None:
        raise click.UsageError("--write-var writes one parameter file: give one program and -o")
    if output_dir is None:
        _run_one(programs, output, fmt, quiet, as_json, plot_dir, settings)
        return
    run_batch(programs, output_dir, jobs, fmt or "csv", quiet, as_json, settings)


def _run_one(programs, output, fmt, quiet: bool, as_json: bool, plot_dir, settings) -> None:
    """``run PROGRAM -o OUTPUT``: the points written, then the summary (JSON on stdout, or
    on stderr when the points go to stdout; else a line on stderr unless ``quiet``)."""
    if len(programs) != 1:
        raise click.UsageError("several programs need --output-dir")
    if output is None:
        raise click.UsageError("give -o FILE (.csv, .npz or -) or --output-dir DIR")
    program = programs[0]
    fmt = output_format(output, fmt)
    refuse_overwriting(program, output)
    with progress_display(show_progress(as_json, quiet), display_name(program)) as say:
        prog, summary, text = _write_points(program, output, fmt, as_json, plot_dir, settings, say)
    if as_json:
        click.echo(text, err=output == "-")
    elif not quiet:
        err.print(
            f"{prog.name}: {summary['samples']} points, cycle time "
            f"{summary['cycle_time_s']:.4f} s{clock_suffix(summary['cycle_time_s'])}"
            f" → {output}",
            markup=False,
        )
        if precompensation_text(summary):
            err.print(precompensation_text(summary), markup=False)
        if rotary_text(summary):
            err.print(rotary_text(summary), markup=False)


def _write_points(program, output, fmt, as_json: bool, plot_dir, settings, say):
    """Plan ``program``, write its points to ``output`` and its figures into ``plot_dir``;
    returns (program, summary, the summary's JSON text or None)."""
    prog, mach, run = make_plan(program, **settings, progress=say, keep_reference=bool(plot_dir))
    if plot_dir:  # the figures need whole arrays: made once, written from them
        _ = run.samples
    say(f"writing {run.sample_count} points")

    # Window by window: the points are made, checked, written and summarised as they come
    # (memory of one window, whatever the motion time); the summary is made while the
    # writer finishes the file. The text line shows points and cycle time only: no
    # kinematic bound to compute.
    def summarise(stats):
        summary = summary_of(prog, mach, run, stats, lower_bound=as_json)
        return summary, summary_json(summary) if as_json else None

    summary, text = write_output(output, fmt, run, mach, prog.name, summarise)
    if settings.get("write_var"):
        say("writing the parameter file")
        inputs = program_inputs(mach, settings.get("var"), writes=True)
        if inputs.var_path is None:
            raise ConfigError(
                "--write-var: no parameter file (give --var FILE, $NURBSCNC_VAR or the "
                "profile's program.var_file)"
            )
        write_back(inputs, prog)
    if plot_dir:
        from nurbscnc.plan.explain import explain_plan

        say("plotting")
        expl = explain_plan(prog, mach, run.plan) if run.plan is not None else None
        write_plan_plots(run, plot_dir, prog, expl, mach)
    return prog, summary, text


def output_format(output: str, fmt: str | None) -> str:
    """The format of ``run -o output``: ``--format`` if given, else the suffix's, else csv.
    A ``--format`` that contradicts a known suffix, or npz to stdout (binary on a terminal or
    a text pipe), is a usage error (exit 2): the two never silently disagree."""
    suffix = os.path.splitext(output)[1].lower() if output != "-" else ""
    implied = SUFFIX_FORMATS.get(suffix)
    if fmt is not None and implied is not None and fmt != implied:
        raise click.UsageError(
            f"--format {fmt} contradicts the suffix of -o {output} "
            f"({implied}); drop --format or rename the output"
        )
    fmt = fmt or implied or "csv"
    if output == "-" and fmt == "npz":
        raise click.UsageError(
            "--format npz writes binary and is refused on stdout (-o -); give -o FILE.npz"
        )
    return fmt
