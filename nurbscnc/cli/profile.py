"""``nurbscnc profile init`` and ``nurbscnc profile show``: the machine profile as a user sees it.

``init`` writes the commented template (the bundled default profile: every key, its unit and
meaning); ``show`` prints the profile a command would use, after discovery, ``--machine`` and
``--set`` (TOML, or JSON).
"""

from __future__ import annotations

import functools
import json
import os
import sys

import click

from nurbscnc.app.summary import error_json, machine_json
from nurbscnc.cli.common import load_machine_cli
from nurbscnc.cli.console import err
from nurbscnc.cli.handle import handle_errors
from nurbscnc.errors import NurbsCncError, OutputError


def _profile_errors(func):
    """:func:`~nurbscnc.cli.handle.handle_errors`, but a user error is reported as
    ``nurbscnc profile: error: …`` (these commands read no program)."""

    @functools.wraps(func)
    def reported(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except NurbsCncError as exc:
            if kwargs.get("as_json"):
                click.echo(json.dumps(error_json(exc)))
            err.print(f"nurbscnc profile: error: {exc.message}", markup=False)
            sys.exit(exc.exit_code)

    return handle_errors(reported)


@click.group()
def profile():
    """The machine profile: write a template, show the one in effect.

    A command finds its profile, first match wins: --machine FILE, $NURBSCNC_MACHINE,
    ./nurbscnc.toml, $XDG_CONFIG_HOME/nurbscnc/machine.toml (~/.config/...), the bundled
    paper machine. See docs/machine-profile.md.
    """


@profile.command("init")
@click.argument("file", required=False, type=click.Path(dir_okay=False, allow_dash=True))
@click.option("--force", is_flag=True, help="Overwrite FILE if it exists.")
@click.option(
    "--template",
    type=click.Choice(["paper", "router"]),
    default="paper",
    show_default=True,
    help="paper: the paper's X-Y table with 4th-order servo models (the bundled default); "
    "router: a stepper-motor router without a servo model (contour check off).",
)
@_profile_errors
def init(file, force, template):
    """Write a commented profile template to FILE (default or '-': stdout).

    Example: nurbscnc profile init nurbscnc.toml --template router
    """
    from nurbscnc.machine.discovery import template_text

    text = template_text(template)
    if file in (None, "-"):
        click.echo(text, nl=False)
        return
    if os.path.exists(file) and not force:
        raise OutputError(f"{file} exists; use --force to overwrite it")
    try:
        with open(file, "w", encoding="utf-8") as f:
            f.write(text)
    except OSError as exc:
        raise OutputError(f"cannot write {file}: {exc}") from exc
    err.print(
        f"wrote {file}: edit it for your machine, then `nurbscnc profile show` "
        f"(found without flags as ./nurbscnc.toml, or with --machine {file})",
        markup=False,
    )


@profile.command("show")
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
@click.option(
    "--machine",
    type=click.Path(dir_okay=False),
    default=None,
    help="Machine profile (TOML); default: found as `nurbscnc profile` says.",
)
@click.option(
    "--set",
    "overrides",
    multiple=True,
    metavar="KEY=VALUE",
    help="Override one profile value, e.g. --set limits.a_max_mm_s2=1000.",
)
@_profile_errors
def show(as_json, machine, overrides):
    """Print the effective machine profile (after discovery, --machine and --set), and the
    parameter file programs read their work offsets from ($NURBSCNC_VAR or program.var_file).

    Example: nurbscnc profile show --set servo.x.bandwidth_hz=40 --set servo.x.damping=0.7
    """
    from nurbscnc.machine.profile import profile_toml

    click.get_current_context().meta["nurbscnc.machine_said"] = True  # the header says it
    from nurbscnc.app.varfile import find_var_file

    mach = load_machine_cli(machine, overrides)
    var_path, found_by = find_var_file(mach)
    if as_json:
        var = {"path": var_path, "found_by": found_by or None}
        click.echo(
            json.dumps(
                {
                    "ok": True,
                    **machine_json(mach),
                    "profile": mach.settings,
                    "var_file": var,
                    "defaults": sorted(mach.defaults),
                }
            )
        )
        return
    click.echo(profile_toml(mach), nl=False)
    said = f"{var_path} ({found_by})" if var_path else "none (no work offsets)"
    click.echo(f"\n# parameter file (--var, $NURBSCNC_VAR, program.var_file): {said}")
