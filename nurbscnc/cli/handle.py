"""How the CLI ends a command that failed: every exception becomes a message and an exit
code (:func:`handle_errors`), never a traceback for bad input; SIGTERM and SIGHUP unwind the
command as Ctrl-C does."""

from __future__ import annotations

import contextlib
import functools
import io
import json
import os
import sys

import click

from nurbscnc.app.load import display_name
from nurbscnc.app.summary import error_json, usage_error_json
from nurbscnc.cli.console import err, format_error
from nurbscnc.errors import EXIT_INTERNAL, EXIT_INTERRUPTED, EXIT_IO, NurbsCncError


class Failed(Exception):
    """Raised inside a command to exit with a code after the message was printed."""

    def __init__(self, code: int):
        self.code = code


class Terminated(BaseException):
    """SIGTERM or SIGHUP arrived: unwind (temporary files are removed on the way), then exit
    128 + the signal number, as a process killed by it would report."""

    def __init__(self, signum: int):
        self.signum = signum


#: Exit code when the reader of stdout went away (``| head``): 128 + SIGPIPE, what a shell
#: reports for a Unix tool killed by SIGPIPE (``seq 1 1000000 | head -1`` under pipefail).
EXIT_BROKEN_PIPE = 141


@contextlib.contextmanager
def _terminate_on_signals():
    """SIGTERM/SIGHUP raise :class:`Terminated` while a command runs (main thread only), so
    ``finally`` blocks and :func:`atomic_output` clean up; the old handlers come back after."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def raise_terminated(signum, _frame):
        raise Terminated(signum)

    previous = {}
    for sig in (signal.SIGTERM, signal.SIGHUP):
        previous[sig] = signal.signal(sig, raise_terminated)
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


def _silence_stdout() -> None:
    """Point fd 1 at /dev/null so Python's final flush of a dead stdout says nothing."""
    with contextlib.suppress(OSError, ValueError, AttributeError, io.UnsupportedOperation):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)


def _command_name(kwargs) -> str:
    """The name errors are reported under: the program file (``<stdin>`` for ``-``), the single
    program of ``run``, else ``nurbscnc``."""
    name = kwargs.get("program") or kwargs.get("source")
    programs = kwargs.get("programs")
    if name is None and programs and len(programs) == 1:
        name = programs[0]
    if name is None:
        return "nurbscnc"
    return display_name(getattr(name, "name", name))


def handle_errors(func):
    """Turn every exception into a message and an exit code: never a traceback for input.

    NurbsCncError → its message and code (2 input, 3 files); a closed stdout pipe → quiet, 141;
    another OSError writing stdout (``> /dev/full``) → a message, 3; Ctrl-C → 130; SIGTERM /
    SIGHUP → 143 / 129 (after cleanup); anything else is a bug → a one-line report, 1.
    """

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        filename = _command_name(kwargs)
        try:
            with _terminate_on_signals():
                result = func(*args, **kwargs)
                sys.stdout.flush()  # a full disk or a closed pipe shows here, not at exit
            return result
        except Failed as exc:
            sys.exit(exc.code)
        except NurbsCncError as exc:
            _exit_if_interrupted(exc)
            if kwargs.get("as_json"):
                with contextlib.suppress(OSError):
                    click.echo(json.dumps(error_json(exc)))
            err.print(format_error(exc, filename), markup=False)
            sys.exit(exc.exit_code)
        except BrokenPipeError:
            _silence_stdout()
            sys.exit(EXIT_BROKEN_PIPE)
        except KeyboardInterrupt:
            err.print("interrupted", markup=False)
            sys.exit(EXIT_INTERRUPTED)
        except Terminated as exc:
            sys.exit(128 + exc.signum)
        except click.exceptions.Exit:
            raise
        except click.ClickException:
            raise
        except OSError as exc:
            _exit_if_interrupted(exc)
            # Stages do no I/O and every file we open is wrapped in OutputError: an OSError
            # without a file name is a write to stdout failing (a full disk, a dead device).
            if os.environ.get("NURBSCNC_DEBUG"):
                raise
            what = "write to standard output" if exc.filename is None else f"access {exc.filename}"
            message = f"cannot {what}: {exc.strerror or exc}"
            if exc.filename is None:
                _silence_stdout()
            elif kwargs.get("as_json"):
                echo_json_error(message)
            err.print(f"{filename}: error: {message}", markup=False)
            sys.exit(EXIT_IO)
        except Exception as exc:  # a bug: say so, without a traceback unless asked
            _exit_if_interrupted(exc)
            if os.environ.get("NURBSCNC_DEBUG"):
                raise
            if kwargs.get("as_json"):
                echo_json_error(f"internal error: {type(exc).__name__}: {exc}")
            err.print(
                f"{filename}: internal error: {type(exc).__name__}: {exc}\n"
                "This is a bug in nurbscnc; rerun with NURBSCNC_DEBUG=1 for a traceback.",
                markup=False,
            )
            sys.exit(EXIT_INTERNAL)

    return wrapper


def _exit_if_interrupted(exc: BaseException) -> None:
    """Exit as for the signal if ``exc`` was raised while unwinding from one (Ctrl-C,
    SIGTERM, SIGHUP): a write cut short by the signal can fail again as its file is closed
    on the way out, and that error would otherwise be reported instead of the signal."""
    seen: set = set()
    cause = exc.__context__
    while cause is not None and id(cause) not in seen:
        if isinstance(cause, KeyboardInterrupt):
            err.print("interrupted", markup=False)
            sys.exit(EXIT_INTERRUPTED)
        if isinstance(cause, Terminated):
            sys.exit(128 + cause.signum)
        seen.add(id(cause))
        cause = cause.__context__


def echo_json_error(message: str) -> None:
    """The JSON error object of a failure without a source position, on stdout (a dead
    stdout is ignored: the message goes to stderr anyway)."""
    with contextlib.suppress(OSError):
        click.echo(json.dumps(usage_error_json(message)))
