"""What several commands share: the program argument and the ``--json`` and ``--plot``
options, and loading the machine profile or planning a program with the profile said on
stderr."""

from __future__ import annotations

import click

from nurbscnc.app.load import load_machine, override_table
from nurbscnc.cli.console import err

program_argument = click.argument("program", type=click.Path(allow_dash=True))
json_option = click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")


def plot_option(func):
    return click.option(
        "--plot",
        "plot_dir",
        type=click.Path(),
        default=None,
        help="Write PNG figures into this folder (needs the 'plot' extra: matplotlib).",
    )(func)


def announce_machine(mach, table: dict, plans: bool = True) -> None:
    """Say which machine profile the command uses: a ``machine: FILE (how found)`` line on
    stderr, once per command (not with --json or --quiet, whose JSON carries
    ``machine_profile`` instead, see :func:`~nurbscnc.app.summary.machine_json`; nor when the
    command's data goes to stdout, ``-o -``, where a pipeline wants nothing but that data and
    its errors); ``table``: the overrides applied. ``plans``: the command plans, so a profile
    without a servo model is also said to turn the contour check off."""
    ctx = click.get_current_context(silent=True)
    if ctx is not None and not ctx.meta.get("nurbscnc.machine_said"):
        ctx.meta["nurbscnc.machine_said"] = True
        to_stdout = "-" in (ctx.params.get("output"), ctx.params.get("dump_profile"))
        if not (ctx.params.get("as_json") or ctx.params.get("quiet") or to_stdout):
            changed = f"; overridden: {', '.join(sorted(table))}" if table else ""
            err.print(f"machine: {mach.describe()}{changed}", markup=False)
            if plans and not mach.contour_check:
                err.print("contour check: off (no servo model in the profile)", markup=False)


def load_machine_cli(
    path, overrides=(), extra: dict | None = None, announce: bool = True, plans: bool = True
):
    """The machine profile with ``--set`` and option overrides ``extra`` applied
    (:func:`~nurbscnc.app.load.load_machine`), said on stderr by :func:`announce_machine`
    unless ``announce`` is False; ``plans`` as there (False for ``check``)."""
    table = override_table(overrides, extra)
    mach = load_machine(path, table)
    if announce:
        announce_machine(mach, table, plans)
    return mach


def make_plan(program: str, **settings):
    """:func:`nurbscnc.app.planning.make_plan` with the machine profile said on stderr."""
    from nurbscnc.app.planning import make_plan as plan_program

    return plan_program(program, **settings, announce=announce_machine)


def nothing_to_send(program: str, as_json: bool, var_path: str | None) -> None:
    """``stream`` of a program with no motion (offsets, tool changes, dwells only): the port
    is not opened, exit 0; the program has run, so its parameters were written back to
    ``var_path`` (None: no parameter file)."""
    import json

    if as_json:
        click.echo(json.dumps({"ok": True, "program": program, "motion": False}))
        return
    kept = f"; parameters written to {var_path}" if var_path else ""
    click.echo(
        f"{program}: no motion (offsets, tool changes or dwells only): nothing to send{kept}"
    )
