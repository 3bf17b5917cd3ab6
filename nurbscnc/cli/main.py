"""The command-line interface: the command group, its commands, and its own option errors.

Each command is a module of this package (:mod:`nurbscnc.cli.check`, ...) that parses its
options, calls the application layer (:mod:`nurbscnc.app`) and prints; every exception
becomes a message and an exit code there (:func:`nurbscnc.cli.handle.handle_errors`). Here
the commands are put together into :data:`main`, the console script ``nurbscnc``.
"""

from __future__ import annotations

import importlib
import sys

import click

from nurbscnc import __version__
from nurbscnc.app.runtime import tune_process
from nurbscnc.cli.console import err
from nurbscnc.cli.handle import echo_json_error

# Start-up: this module is imported by every command, by --help and by shell completion, so
# it and the command modules import only click and the standard library at the top (and the
# application layer's light modules); numpy, rich, the interpreter (lark) and the planner
# (scipy) are imported by the functions that use them. A command's own module is imported
# when that command is looked up (:data:`COMMANDS`): ``plan`` does not load ``stream``'s
# threads, ``card-sim``'s signals or the other commands' options.

#: The commands: name → (module of :mod:`nurbscnc.cli`, the command's name in it).
COMMANDS = {
    "card-position": ("card", "card_position"),
    "card-sim": ("card", "card_sim"),
    "check": ("check", "check"),
    "compare": ("compare", "compare"),
    "corners": ("corners", "corners"),
    "identify": ("identify", "identify"),
    "jog": ("mdi", "jog"),
    "mdi": ("mdi", "mdi"),
    "ph": ("corners", "ph"),
    "plan": ("plan", "plan"),
    "profile": ("profile", "profile"),
    "run": ("run", "run"),
    "simulate": ("simulate", "simulate"),
    "stream": ("stream", "stream"),
}


class _Group(click.Group):
    """The command group. With ``--json`` among the arguments, an option error (a click
    usage error: unknown option, bad value, missing argument, two options that exclude each
    other) is also printed as JSON on stdout, as a program error is (docs/json.md); the usual
    message still goes to stderr and the exit code stays 2."""

    def list_commands(self, ctx) -> list[str]:
        return sorted(COMMANDS)

    def get_command(self, ctx, cmd_name: str) -> click.Command | None:
        """The command ``cmd_name``, its module imported now (None: no such command)."""
        where = COMMANDS.get(cmd_name)
        if where is None:
            return None
        module, name = where
        return getattr(importlib.import_module(f"nurbscnc.cli.{module}"), name)

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
        tune_process()
        args = list(sys.argv[1:] if args is None else args)
        if not standalone_mode or "--json" not in args:
            return super().main(args, prog_name, complete_var, standalone_mode, **extra)
        try:
            code = super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        except click.ClickException as exc:
            echo_json_error(exc.format_message())
            exc.show()
            sys.exit(exc.exit_code)
        except click.exceptions.Abort:
            err.print("Aborted!", markup=False)
            sys.exit(1)
        # A command returns None; click's Exit (--help, --version) gives its code.
        sys.exit(code if isinstance(code, int) else 0)


@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="nurbscnc")
def main():
    """nurbscnc: NC programs (lines, arcs, NURBS) to reference points at the servo period.

    Exit codes: 0 ok, 1 internal error (a bug), 2 bad program or option, 3 file or port
    trouble, 130 interrupted (143 SIGTERM, 129 SIGHUP), 141 stdout closed by its reader.
    """
