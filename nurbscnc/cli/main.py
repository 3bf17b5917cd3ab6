"""The command-line interface: one click command per pipeline stage.

Only this module (and the serial backend) touches the outside world: it reads programs,
writes outputs atomically, and turns :class:`~nurbscnc.errors.NurbsCncError` into
``file:line:col: error: message`` with the source line and a caret, and an exit code.
"""

from __future__ import annotations

import contextlib
import errno
import functools
import gc
import io
import json
import os
import sys
from typing import TYPE_CHECKING

import click

from nurbscnc import __version__
from nurbscnc.cli.options import (
    block_delete_option,
    machine_options,
    planning_options,
    run_options,
    subroutine_path_option,
    tool_table_option,
)
from nurbscnc.errors import (
    EXIT_INTERNAL,
    EXIT_INTERRUPTED,
    EXIT_IO,
    ConfigError,
    NurbsCncError,
    OutputError,
    ProgramError,
)

# Start-up: this module is imported by every command, by --help and by shell completion, so
# it imports only click and the standard library at the top; numpy, rich, the interpreter
# (lark) and the planner (scipy) are imported by the functions that use them.
if TYPE_CHECKING:
    from rich.console import Console

    from nurbscnc.geometry.segments import Program


def _rich_console_class():
    """The rich Console that leaves a failed write to the caller: on stdout a closed pipe or a
    full disk raises (handle_errors ends quietly with 141, or says so with 3; rich's default
    would exit 1), on stderr it is ignored. The unwritten text is dropped either way. (Built on
    first use: rich is imported when a command prints, not by ``--help``.)"""
    from rich.console import Console

    class _Console(Console):
        def on_broken_pipe(self) -> None:
            raise BrokenPipeError(errno.EPIPE, "Broken pipe")

        def _check_buffer(self) -> None:
            try:
                super()._check_buffer()
            except OSError:
                del self._buffer[:]
                if not self.stderr:
                    raise

    return _Console


class _LazyConsole:
    """Stands for the module's rich Console ``name`` (``out`` or ``err``) until its first use,
    so that importing this module does not import rich: the first use (an attribute:
    ``print``, ``is_terminal``, ...) makes the Console from ``settings`` and puts it in the
    module in the stand-in's place. A stand-in a caller kept (``from ... import err`` before
    any use) forwards every use to that Console: attributes read and set, ``with``."""

    def __init__(self, name: str, **settings):
        object.__setattr__(self, "_name", name)
        object.__setattr__(self, "_settings", settings)
        object.__setattr__(self, "_console", None)

    def _real(self):
        if self._console is None:
            object.__setattr__(self, "_console", _rich_console_class()(**self._settings))
            if globals().get(self._name) is self:
                globals()[self._name] = self._console
        return self._console

    def __getattr__(self, attr: str):
        return getattr(self._real(), attr)

    def __setattr__(self, attr: str, value) -> None:
        setattr(self._real(), attr, value)

    def __enter__(self):
        return self._real().__enter__()

    def __exit__(self, *exc_info):
        return self._real().__exit__(*exc_info)


# Tables keep their width when piped (rich would assume 80 columns and truncate numbers).
# Markup and emoji codes are off: file names, source lines, messages and JSON are user text and
# must print literally (a file "[/].nc", "(:thumbs_up:)" in a comment, "part.nc:100:" would be
# markup or emoji otherwise). Styling goes through rich.text.Text objects only.
out = _LazyConsole("out", highlight=False, markup=False, emoji=False, soft_wrap=True,
                   width=None if sys.stdout.isatty() else 200)  # fmt: skip
err = _LazyConsole("err", stderr=True, highlight=False, markup=False, emoji=False,
                   soft_wrap=True)  # fmt: skip


# -- progress ----------------------------------------------------------------------------------
def show_progress(as_json: bool = False, quiet: bool = False) -> bool:
    """Progress is shown on a terminal only: not when stderr is piped or redirected, not with
    --json or --quiet."""
    return not (as_json or quiet) and err.is_terminal


@contextlib.contextmanager
def progress_display(show: bool, title: str):
    """A one-line rich progress display on stderr (spinner, stage, elapsed time) while the
    block runs, gone afterwards; yields the function that names the current stage (the
    ``progress`` callback the stages are given; one that does nothing when not ``show``).
    The stage and title are user text: printed literally, never as markup."""
    if not show:
        yield lambda _stage: None
        return
    from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    with Progress(SpinnerColumn(), TextColumn("{task.description}", markup=False),
                  TimeElapsedColumn(), console=err, transient=True) as bar:  # fmt: skip
        # The stage first: a narrow terminal cuts the end of the line (a long file name).
        task = bar.add_task(f"starting · {title}", total=None)

        def say(stage: str) -> None:
            bar.update(task, description=f"{stage} · {title}", refresh=True)

        yield say


# -- error reporting ---------------------------------------------------------------------------
#: An echoed source line is cut to about this many characters around the error's column.
SOURCE_ECHO_CHARS = 120
#: A message longer than this is cut (a message quoting a 10 MB word stays readable).
MESSAGE_CHARS = 1000
#: C0, DEL and C1 controls (0x9B is a CSI): no terminal escapes from a file reach the screen.
_CONTROL = {c: "\ufffd" for c in (*range(0x20), *range(0x7F, 0xA0))}


def echo_source_line(text: str, column: int, width: int = SOURCE_ECHO_CHARS) -> tuple[str, int]:
    """The part of a source line shown under an error, and the 0-based caret offset in it.

    Lines up to ``width`` characters are shown whole; longer ones as a ``width``-character
    window around the column with ``…`` where text was cut. Tabs become spaces and control
    characters U+FFFD, one for one, so the caret stays under the column.
    """
    text = text.replace("\t", " ").translate(_CONTROL)
    col = min(max(column, 1) - 1, len(text))
    if len(text) <= width:
        return text, col
    start = max(0, min(col - width // 2, len(text) - width))
    end = start + width
    prefix = "…" if start > 0 else ""
    suffix = "…" if end < len(text) else ""
    return prefix + text[start:end] + suffix, col - start + len(prefix)


def format_error(exc: NurbsCncError, filename: str) -> str:
    """``file:line:col: error: message``, then the source line (cut around the column) and a
    caret under the column."""
    message = exc.message
    if len(message) > MESSAGE_CHARS:
        message = message[:MESSAGE_CHARS] + f"… ({len(exc.message)} characters)"
    message, filename = message.translate(_CONTROL), str(filename).translate(_CONTROL)
    pos = exc.pos
    if pos is None:
        return f"{filename}: error: {message}"
    head = f"{filename}:{pos.line}:{pos.column}: error: {message}"
    if not pos.text:
        return head
    shown, caret = echo_source_line(pos.text, pos.column)
    return f"{head}\n    {shown}\n    {' ' * caret}^"


class _Failed(Exception):
    """Raised inside a command to exit with a code after the message was printed."""

    def __init__(self, code: int):
        self.code = code


class _Terminated(BaseException):
    """SIGTERM or SIGHUP arrived: unwind (temporary files are removed on the way), then exit
    128 + the signal number, as a process killed by it would report."""

    def __init__(self, signum: int):
        self.signum = signum


#: Exit code when the reader of stdout went away (``| head``): 128 + SIGPIPE, what a shell
#: reports for a Unix tool killed by SIGPIPE (``seq 1 1000000 | head -1`` under pipefail).
EXIT_BROKEN_PIPE = 141


@contextlib.contextmanager
def _terminate_on_signals():
    """SIGTERM/SIGHUP raise :class:`_Terminated` while a command runs (main thread only), so
    ``finally`` blocks and :func:`atomic_output` clean up; the old handlers come back after."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def raise_terminated(signum, _frame):
        raise _Terminated(signum)

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
    return _display_name(getattr(name, "name", name))


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
        except _Failed as exc:
            sys.exit(exc.code)
        except NurbsCncError as exc:
            _exit_if_interrupted(exc)
            if kwargs.get("as_json"):
                with contextlib.suppress(OSError):
                    click.echo(json.dumps(_error_json(exc)))
            err.print(format_error(exc, filename), markup=False)
            sys.exit(exc.exit_code)
        except BrokenPipeError:
            _silence_stdout()
            sys.exit(EXIT_BROKEN_PIPE)
        except KeyboardInterrupt:
            err.print("interrupted", markup=False)
            sys.exit(EXIT_INTERRUPTED)
        except _Terminated as exc:
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
                _echo_json_error(message)
            err.print(f"{filename}: error: {message}", markup=False)
            sys.exit(EXIT_IO)
        except Exception as exc:  # a bug: say so, without a traceback unless asked
            _exit_if_interrupted(exc)
            if os.environ.get("NURBSCNC_DEBUG"):
                raise
            if kwargs.get("as_json"):
                _echo_json_error(f"internal error: {type(exc).__name__}: {exc}")
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
        if isinstance(cause, _Terminated):
            sys.exit(128 + cause.signum)
        seen.add(id(cause))
        cause = cause.__context__


def _echo_json_error(message: str) -> None:
    """The JSON error object of a failure without a source position, on stdout (a dead
    stdout is ignored: the message goes to stderr anyway)."""
    with contextlib.suppress(OSError):
        click.echo(json.dumps(usage_error_json(message)))


def _display_name(name) -> str:
    return "<stdin>" if name in ("-", None) else str(name)


def _error_json(exc: NurbsCncError) -> dict:
    pos = exc.pos
    entry = {"line": pos.line if pos else None, "column": pos.column if pos else None,
             "message": exc.message}  # fmt: skip
    return {"ok": False, "errors": [entry]}


# -- reading programs --------------------------------------------------------------------------
def read_program_text(path: str) -> str:
    """The program text of ``path`` (``-`` for stdin). UTF-8 (BOM allowed), else Latin-1.

    Non-ASCII bytes are harmless in comments; elsewhere the parser reports them.
    """
    from nurbscnc.output.files import read_input_bytes

    data = read_input_bytes(path, "the program", ProgramError)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def load_program(
    path: str,
    block_delete: bool = True,
    tool_table: str | None = None,
    subroutine_path: tuple = (),
    text: str | None = None,
) -> Program:
    """Read, parse and interpret a program file.

    ``o<name> call`` of a subroutine the program does not define reads ``name.ngc`` from the
    program's directory, then each directory of ``subroutine_path`` (LinuxCNC's
    SUBROUTINE_PATH); the interpreter gets the reading as a callback and does no I/O itself.
    ``text``, when given, is the program already read (stdin that ``simulate -`` looked at).
    """
    from nurbscnc.program.interpret import InterpretOptions, interpret_text

    if text is None:
        text = read_program_text(path)
    tools = read_tool_table(tool_table) if tool_table else None
    dirs = [os.path.dirname(os.path.abspath(path)) if path != "-" else os.getcwd()]
    dirs += [str(d) for d in subroutine_path]

    def load_subroutine(name: str):
        for folder in dirs:
            for candidate in (name + ".ngc", name.lower() + ".ngc"):
                file_path = os.path.join(folder, candidate)
                if os.path.isfile(file_path):
                    return read_program_text(file_path), file_path
        return None

    options = InterpretOptions(
        block_delete=block_delete, tools=tools, name=_display_name(path),
        load_subroutine=load_subroutine,
    )  # fmt: skip
    return interpret_text(text, options)


def read_tool_table(path: str) -> dict:
    """A LinuxCNC tool table file → ``{tool number: Tool}`` (see program/tooltable.py)."""
    from nurbscnc.output.files import read_input_bytes
    from nurbscnc.program.tooltable import parse_tool_table

    data = read_input_bytes(path, f"the tool table {path}", ConfigError)
    return parse_tool_table(data.decode("utf-8", errors="replace"), path)


# -- the command group -------------------------------------------------------------------------
def usage_error_json(message: str) -> dict:
    """The JSON of an option error (docs/json.md): the shape of a program error, without a
    position."""
    return {"ok": False, "errors": [{"line": None, "column": None, "message": message}]}


#: glibc's ``mallopt`` parameters (malloc.h) and the values set by :func:`_reuse_freed_memory`.
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD, _M_ARENA_MAX = -1, -3, -8
_MMAP_THRESHOLD_BYTES = 32 * 2**20  # glibc's own ceiling for its sliding threshold
_TRIM_THRESHOLD_BYTES = 2**30


def _reuse_freed_memory() -> None:
    """Let glibc's malloc reuse freed blocks below 32 MB instead of giving them back to the
    kernel and faulting fresh pages in for the next one.

    The commands allocate and free the same large numpy temporaries window after window.
    By default glibc trims the top of its heap when more than twice its sliding mmap
    threshold is free, so the next allocation of that size faults every page in again
    (measured: the 200,000-line spiral's ``run`` spent 0.4–0.5 s of 2.5 s in the kernel, on
    215,000 page faults). With the threshold fixed at glibc's ceiling (32 MB) and trimming
    above 1 GB: 113,000 faults, 0.25 s in the kernel, 1.3 % more peak memory. Blocks of 32 MB
    and more are still mapped and unmapped on their own. One arena for every thread: the
    thread that makes ``run``'s points while the output is written
    (:mod:`nurbscnc.output.background`) then reuses the blocks the planner freed instead of
    growing an arena of its own (200,000-line spiral: 38 MB more peak memory without).
    Not glibc (macOS, musl): nothing."""
    try:
        if not os.confstr("CS_GNU_LIBC_VERSION"):
            return
        import ctypes

        libc = ctypes.CDLL(None)
        libc.mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD_BYTES)
        libc.mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD_BYTES)
        libc.mallopt(_M_ARENA_MAX, 1)
    except (ValueError, OSError, AttributeError):  # no confstr name, no libc, no mallopt
        return


class _Group(click.Group):
    """The command group. With ``--json`` among the arguments, an option error (a click
    usage error: unknown option, bad value, missing argument, two options that exclude each
    other) is also printed as JSON on stdout, as a program error is (docs/json.md); the usual
    message still goes to stderr and the exit code stays 2."""

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
        # One BLAS thread unless the user set it: the commands' vector operations are far
        # too small for threads, and OpenBLAS's idle threads spin on the other core
        # (measured: a 1,000,000-line `run` spent 15.5 s of CPU instead of 11.8, tort's
        # `plan` 5.5 s instead of 3.6, and both took longer). Read when numpy is first
        # imported, which the commands do lazily, after this.
        os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
        _reuse_freed_memory()
        args = list(sys.argv[1:] if args is None else args)
        if not standalone_mode or "--json" not in args:
            return super().main(args, prog_name, complete_var, standalone_mode, **extra)
        try:
            code = super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        except click.ClickException as exc:
            _echo_json_error(exc.format_message())
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


program_argument = click.argument("program", type=click.Path(allow_dash=True))
json_option = click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")


# -- check -------------------------------------------------------------------------------------
@main.command()
@program_argument
@json_option
@block_delete_option
@tool_table_option
@subroutine_path_option
@machine_options
@handle_errors
def check(program, as_json, no_block_delete, tool_table, subroutine_path, machine, overrides):
    """Parse and validate PROGRAM ('-' for stdin) and summarise it.

    Validation includes the machine profile's soft limits on the geometry and its
    limits.max_points on a lower bound of the motion time (no planning).

    Example: nurbscnc check programs/naca2415.nc
    """
    from nurbscnc.plan.limits import check_before_work
    from nurbscnc.plan.report import program_summary
    from nurbscnc.program.columns import segment_columns

    mach = load_machine_cli(machine, overrides, announce=False)
    with progress_display(show_progress(as_json), _display_name(program)) as say:
        say("reading and interpreting")
        prog = load_program(program, not no_block_delete, tool_table, subroutine_path)
        say(f"checking {len(prog.segments)} segments")
        columns = segment_columns(prog.segments)  # read once for the checks and the summary
        check_before_work(prog.segments, mach, columns)
        summary = program_summary(prog, columns, per_segment=as_json)
    if as_json:
        click.echo(json.dumps({**summary, **machine_json(mach)}))
        return
    print_summary(prog, summary)


def print_summary(prog: Program, s: dict) -> None:
    from rich.table import Table
    from rich.text import Text

    out.print(Text.assemble((prog.name, "bold"),
                            f": ok — {s['blocks']} blocks, {len(prog.segments)} segments"))
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
                str(e["line"]), e["plane"], str(e["degree"]), str(e["control_points"]),
                str(e["knots"]), f"{e['length_mm']:.4f}",
            )  # fmt: skip
        out.print(table)
    for n in s["notes"]:
        out.print(f"  note (line {n['line']}): {n['message']}", markup=False)




# -- machine profile options -------------------------------------------------------------------
def load_machine_cli(path, overrides=(), extra: dict | None = None, announce: bool = True):
    """The machine profile with ``--set`` and option overrides applied.

    Without ``--machine`` the profile is found as :func:`~nurbscnc.machine.profile.find_machine`
    says ($NURBSCNC_MACHINE, ./nurbscnc.toml, the user's config folder, the bundled default).
    Every command loads its profile here, so this is where it says which one it used: a
    ``machine: FILE (how found)`` line on stderr (not with --json or --quiet, whose JSON
    carries ``machine_profile`` instead, see :func:`machine_json`; nor when the command's data
    goes to stdout, ``-o -``, where a pipeline wants nothing but that data and its errors),
    unless ``announce`` is False (``check``: its output is the program's summary)."""
    from nurbscnc.errors import ConfigError
    from nurbscnc.machine.profile import find_machine, load_machine

    table = {}
    for item in overrides:
        if "=" not in item:
            raise ConfigError(f"--set wants KEY=VALUE, got {item!r}")
        key, value = item.split("=", 1)
        table[key.strip()] = value.strip()
    table.update({k: v for k, v in (extra or {}).items() if v is not None})
    found, how = find_machine(path)
    mach = load_machine(found, table or None, how)
    ctx = click.get_current_context(silent=True)
    if announce and ctx is not None and not ctx.meta.get("nurbscnc.machine_said"):
        ctx.meta["nurbscnc.machine_said"] = True
        to_stdout = "-" in (ctx.params.get("output"), ctx.params.get("dump_profile"))
        if not (ctx.params.get("as_json") or ctx.params.get("quiet") or to_stdout):
            changed = f"; overridden: {', '.join(sorted(table))}" if table else ""
            err.print(f"machine: {mach.describe()}{changed}", markup=False)
            if not mach.contour_check:
                err.print("contour check: off (no servo model in the profile)", markup=False)
    return mach


def machine_json(mach) -> dict:
    """``{"machine_profile": {path, found_by, contour_check}}`` for a command's JSON."""
    from nurbscnc.machine.profile import profile_info

    return {"machine_profile": profile_info(mach)}


# -- corners -----------------------------------------------------------------------------------
@main.command()
@program_argument
@json_option
@click.option("--feed", type=float, default=None,
              help="Feed F [mm/min] for the threshold (default: each block's F, capped by V_max).")
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
        prog.segments, mach.limits.a_max_mm_s2, mach.limits.v_max_mm_s,
        feed / 60.0 if feed else None,
    )  # fmt: skip
    junctions = tangent_junctions(prog.segments)
    if as_json:
        click.echo(json.dumps({**corners_json(result, junctions), **machine_json(mach)}))
        return
    table = Table(title=f"{prog.name}: sharp corners (κ > κ_th = A_max/F²)", show_edge=False)
    for col in ("line", "κ_th [1/mm]", "peak κ [1/mm]", "x [mm]", "y [mm]", "z [mm]",
                "u_a", "u_b", "length [mm]"):  # fmt: skip
        table.add_column(col, justify="right")
    count = 0
    for sc in result:
        for r in sc.regions:
            count += 1
            table.add_row(
                str(sc.line), f"{sc.kappa_threshold_per_mm:.4g}", f"{r.kappa_peak_per_mm:.5g}",
                *(f"{c:.4f}" for c in r.point_mm), f"{r.u_a:.6g}", f"{r.u_b:.6g}",
                f"{r.length_mm:.4f}",
            )  # fmt: skip
    if count:
        out.print(table)
    else:
        out.print(f"{prog.name}: no sharp corners in {len(result)} NURBS block(s)")
    sharp = [j for j in junctions if j.angle_deg > 1e-3]
    if sharp:
        out.print(f"{len(sharp)} tangent discontinuities between segments "
                  f"(largest {max(j.angle_deg for j in sharp):.2f}°)")  # fmt: skip


def corners_json(result, junctions) -> dict:
    import numpy as np

    return {
        "ok": True,
        "blocks": [
            {
                "line": sc.line,
                "segment": sc.segment_index,
                "feed_mm_s": sc.feed_mm_s,
                "kappa_threshold_per_mm": sc.kappa_threshold_per_mm,
                "corners": [
                    {
                        # JSON has no infinity: a cusp's curvature is null.
                        "kappa_peak_per_mm": (r.kappa_peak_per_mm
                                              if np.isfinite(r.kappa_peak_per_mm) else None),
                        "u_peak": r.u_peak,
                        "point_mm": list(r.point_mm),
                        "u_a": r.u_a,
                        "u_b": r.u_b,
                        "length_mm": r.length_mm,
                    }
                    for r in sc.regions
                ],
            }
            for sc in result
        ],
        "junctions": [
            {"segment": j.index, "line": j.line, "point_mm": list(j.point_mm),
             "angle_deg": j.angle_deg}
            for j in junctions
        ],  # fmt: skip
    }


# -- ph ----------------------------------------------------------------------------------------
@main.command()
@program_argument
@json_option
@click.option("--tolerance-um", type=float, default=None,
              help="PH fit tolerance e [µm] (default: the profile's, 1 µm).")
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
    for col in ("line", "region", "length [mm]", "unsplit RMS [µm]", "unsplit max [µm]",
                "pieces", "RMS [µm]", "max [µm]"):  # fmt: skip
        table.add_column(col, justify="right")
    for k, (sc, r, unsplit, fit) in enumerate(rows):
        table.add_row(
            str(sc.line), _region_name(k), f"{r.length_mm:.4f}", f"{unsplit.rms_um:.4f}",
            f"{unsplit.max_um:.4f}", str(len(fit.pieces)), f"{fit.rms_um:.4f}",
            f"{fit.max_um:.4f}",
        )  # fmt: skip
    if rows:
        out.print(table)
    else:
        out.print(f"{prog.name}: no corner regions, nothing to fit")


def _region_name(k: int) -> str:
    """AB, CD, EF, ... as the paper names its regions."""
    letters = "ABCDEFGHIJKLMNOPQRSTUVWXYZ"
    a = (2 * k) % 26
    suffix = "" if k < 13 else str(k // 13)
    return letters[a] + letters[a + 1] + suffix


def ph_json(rows, e_um: float, no_split: bool) -> dict:
    regions = []
    for k, (sc, r, unsplit, fit) in enumerate(rows):
        regions.append({
            "region": _region_name(k),
            "line": sc.line,
            "u_a": r.u_a,
            "u_b": r.u_b,
            "length_mm": r.length_mm,
            "unsplit": {"rms_um": unsplit.rms_um, "max_um": unsplit.max_um},
            "rms_um": fit.rms_um,
            "max_um": fit.max_um,
            "pieces": [
                {
                    "line": sc.line,
                    "u_a": piece.u_a,
                    "u_b": piece.u_b,
                    "control_points_mm": [
                        [float(c) for c in pt] for pt in piece.ph.control_points_mm
                    ],
                    "rms_um": piece.rms_um,
                    "max_um": piece.max_um,
                }
                for piece in fit.pieces
            ],
        })  # fmt: skip
    return {"ok": True, "tolerance_um": e_um, "split": not no_split, "regions": regions}


# -- plots ----------------------------------------------------------------------------------
def plot_option(func):
    return click.option(
        "--plot", "plot_dir", type=click.Path(), default=None,
        help="Write PNG figures into this folder (needs the 'plot' extra: matplotlib).",
    )(func)  # fmt: skip


def write_plan_plots(run, plot_dir: str, prog, expl=None, mach=None) -> list[str]:
    """Figures of one run (PNG files in ``plot_dir``), each titled with the program's name:
    the path (rapids dashed, cuts coloured by feed, PH pieces marked), the feed over time,
    the feed along the path with the programmed F, the path coloured by the limit that set
    the feed (with an explanation ``expl``), the predicted contour error with ε_max."""
    import numpy as np

    from nurbscnc.output import plots
    from nurbscnc.plan.report import corner_polylines

    os.makedirs(plot_dir, exist_ok=True)
    smp = run.samples
    name = prog.name
    pl = run.plan
    rapid = None
    if pl is not None:
        rapid = np.asarray(pl.pieces.rapid)[smp.piece]
    written = [plots.plot_feed_profiles({"feed": (smp.t_s, smp.v_mm_s)},
                                        os.path.join(plot_dir, "feed.png"),
                                        title=f"{name}: feed over time")]  # fmt: skip
    corners = corner_polylines(pl.pieces) if pl is not None else []
    written.append(plots.plot_path(smp.points_mm, corners, os.path.join(plot_dir, "path.png"),
                                   title=f"{name}: tool path", rapid=rapid,
                                   feed_mm_s=smp.v_mm_s))  # fmt: skip
    if pl is not None and expl is not None:
        from nurbscnc.plan.explain import Limit

        starts = np.asarray(pl.profile.piece_start_mm)
        written.append(plots.plot_feed_along(
            smp.s_mm, smp.v_mm_s, starts, starts + np.asarray(pl.pieces.length_mm),
            expl.piece_feed_mm_s, os.path.join(plot_dir, "feed_along.png"),
            cap_mm_s=expl.piece_cap_mm_s, title=f"{name}: feed along the program"))
        written.append(plots.plot_path_limits(
            smp.points_mm, expl.piece_limit[smp.piece], [m.text for m in Limit],
            os.path.join(plot_dir, "limits.png"),
            title=f"{name}: what limits the feed"))  # fmt: skip
    if run.check is not None:
        contour = run.check.response.contour_mm
        t = np.arange(contour.size) * (smp.t_s[1] - smp.t_s[0])
        eps = None if mach is None else mach.limits.contour_tolerance_mm * 1000.0
        written.append(plots.plot_contour_error(
            {"predicted (true distance)": (t, contour * 1000.0)},
            os.path.join(plot_dir, "contour_error.png"),
            title=f"{name}: predicted contour error", eps_max_um=eps))  # fmt: skip
    return written


# -- plan / run --------------------------------------------------------------------------------
def make_plan(program: str, machine=None, overrides=(), dynamics="local", lookahead=None,
              corner_feed="piece", interpolator="exact", blend_tolerance=None,
              algorithm="ph-lookahead", no_block_delete=False, tool_table=None,
              subroutine_path=(), text=None, precompensate=False, reference_tolerance=3.0,
              progress=None, keep_reference=False, smooth=False):  # fmt: skip
    """Load, interpret, plan and interpolate one program; validate soft limits. Returns
    (program, machine, :class:`~nurbscnc.pipeline.Run`).

    The keyword arguments are the options of :func:`planning_options`, ``text``: the
    program already read (see :func:`load_program`), and ``progress``: None or the stage
    callback of :func:`progress_display`; ``keep_reference``: the dynamics check keeps its
    whole reference and response (the contour plot needs them; memory grows with the motion
    time, so only when plots are asked for)."""
    from dataclasses import replace

    from nurbscnc.pipeline import run_program

    options = run_options(algorithm, corner_feed, dynamics, blend_tolerance, interpolator,
                          lookahead, precompensate, reference_tolerance, smooth)  # fmt: skip
    options = replace(options, keep_reference=keep_reference)
    if progress:
        progress("loading the machine profile")
    mach = load_machine_cli(machine, overrides)
    if progress:
        progress("reading and interpreting")
    prog = load_program(program, not no_block_delete, tool_table, subroutine_path, text)
    # The program's objects (a CAM program's 200,000 lines: 600,000 objects) and the modules'
    # live until the plan is made: the cycle collector's full passes need not walk them
    # (measured on the 200k spiral: 0.19 s of collections, 0.12 s of it four full passes).
    # Thawed after, so nothing stays exempt.
    gc.freeze()
    try:
        return prog, mach, run_program(prog, mach, options, progress)
    finally:
        gc.unfreeze()


def summary_json(summary: dict) -> str:
    """The JSON text of a summary, the cycle collector paused while it is made: a long
    program's 200,000 per-line times make as many strings, which set off full collections
    that walk every object of the run (two, 0.08 s, on the 200k spiral) and find nothing —
    the encoder makes no cycles."""
    from nurbscnc.program.fastlane import pause_cyclic_gc

    with pause_cyclic_gc():
        return _json_in_pieces(summary)


#: Entries of a large mapping encoded per ``json.dumps`` call by :func:`_json_in_pieces`.
JSON_PIECE = 8192


def _json_in_pieces(summary: dict) -> str:
    """``json.dumps(summary)``, the same text, with the large mappings (a long program's
    per-line times) encoded :data:`JSON_PIECE` entries per call: the C encoder holds the
    interpreter lock for a whole call, and ``run`` encodes while its output is being
    finished in the other thread (cli ``write_output``), which needs the lock now and then.
    A mapping's text is its entries' joined by ", " inside braces, as json.dumps writes it."""

    def encoded(value) -> str:
        if not (isinstance(value, dict) and len(value) > JSON_PIECE):
            return json.dumps(value)
        items = list(value.items())
        return "{" + ", ".join(json.dumps(dict(items[i : i + JSON_PIECE]))[1:-1]
                               for i in range(0, len(items), JSON_PIECE)) + "}"  # fmt: skip

    if not all(isinstance(k, str) for k in summary):  # json.dumps's own key conversions
        return json.dumps(summary)
    return "{" + ", ".join(f"{json.dumps(k)}: {encoded(v)}" for k, v in summary.items()) + "}"


def clock_suffix(seconds: float) -> str:
    """`` (h:mm:ss)`` for a time of a minute or more (human summaries only), else ``""``.
    Rounded to whole seconds: 545.4 s → `` (0:09:05)``."""
    if not seconds >= 60.0:
        return ""
    minutes, secs = divmod(int(round(seconds)), 60)
    hours, minutes = divmod(minutes, 60)
    return f" ({hours}:{minutes:02d}:{secs:02d})"


def summary_of(prog, mach, run, stats=None, lower_bound: bool = True) -> dict:
    """The plan summary of a run (:func:`nurbscnc.plan.report.plan_summary`). ``stats``: the
    :class:`~nurbscnc.plan.report.SampleStats` gathered while the points were written (None:
    gathered here, window by window, without whole arrays); a baseline is simulated on its
    whole samples. ``lower_bound``: with the kinematic lower bound (the JSON has it)."""
    from nurbscnc.plan.report import SampleStats, plan_summary

    samples = run.samples if run.plan is None else stats
    if samples is None:
        samples = SampleStats(run.plan)
        for window in run.chunks():
            samples.add(window)
    summary = plan_summary(prog, mach, samples, run.plan, run.check, run.algorithm,
                           run.cycle_time_s, lower_bound, run.columns)  # fmt: skip
    if getattr(run, "precompensation", None) is not None:  # --precompensate
        summary["precompensation"] = run.precompensation.as_json()
    return {**summary, **machine_json(mach)}


def precompensation_text(summary: dict) -> str | None:
    """The human line of ``--precompensate`` (None without it)."""
    pre = summary.get("precompensation")
    if pre is None:
        return None
    return (f"  pre-compensated reference (ZPETC): {pre['reference_deviation_max_um']:.2f} µm "
            f"from the path at most; contour error with a ±10 % model error "
            f"≤ {pre['sensitivity_contour_max_um']:.2f} µm; motion delayed "
            f"{pre['lead_s'] * 1000:g} ms for the inverse's look-ahead, reference settles "
            f"{pre['tail_s'] * 1000:g} ms after the stop")


@main.command()
@program_argument
@json_option
@click.option("--dump-profile", type=click.Path(allow_dash=True), default=None,
              help="Write t, s, v, a, j, piece at every servo period (CSV, or NPZ by extension).")
@click.option("--explain", is_flag=True,
              help="Why the feed is what it is: per source line the time, the programmed and "
                   "achieved feed and the limit that set it (the costliest lines), the time "
                   "under each limit, the corners that stopped and why.")
@click.option("--explain-all", is_flag=True,
              help="As --explain, with every line in program order.")
@plot_option
@planning_options
@handle_errors
def plan(program, as_json, dump_profile, explain, explain_all, plot_dir, **settings):
    """Plan PROGRAM: pieces, corners, cycle time, lower bound, predicted contour error.

    Example: nurbscnc plan programs/naca2415.nc --explain
    """
    from nurbscnc.output.files import write_profile

    explain = explain or explain_all
    if dump_profile == "-" and (as_json or explain):
        raise click.UsageError("--dump-profile - and --json/--explain both want stdout; "
                               "write the profile to a file or drop --json/--explain")
    baseline = settings.get("algorithm", "ph-lookahead") != "ph-lookahead"
    if dump_profile and baseline:
        raise click.UsageError("--dump-profile needs the look-ahead planner (a baseline has "
                               "no jerk-limited profile)")
    if explain and baseline:
        raise click.UsageError("--explain needs the look-ahead planner (a baseline has no "
                               "caps or profile to explain)")
    # --explain shows the source lines: the program is read once, here (stdin too).
    text = read_program_text(program) if explain else None
    with progress_display(show_progress(as_json), _display_name(program)) as say:
        prog, mach, run = make_plan(program, **settings, text=text, progress=say,
                                    keep_reference=bool(plot_dir))  # fmt: skip
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
        from nurbscnc.plan.timing import servo_clock

        pl = run.plan
        t, tau = servo_clock(pl.pieces, pl.profile, mach.servo.period_s)
        s, v, a, j, piece = pl.profile.sample(tau)
        write_profile(dump_profile, t, s, v, a, j, piece)
    if as_json:
        click.echo(summary_json(summary))
        return
    print_plan_summary(prog, mach, summary, err if dump_profile == "-" else out)
    if explain:
        print_explanation(expl, out, None if explain_all else EXPLAIN_LINES,
                          text.splitlines())


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

    from nurbscnc.plan.explain import LIMIT_OF_KEY, Limit

    total = expl.cycle_time_s if expl.cycle_time_s > 0 else 1.0
    shares = ", ".join(f"{LIMIT_OF_KEY[k].text} {t / total:.1%} ({t:.3f} s)"
                       for k, t in expl.total_by_limit_s().items())  # fmt: skip
    out.print(f"  time by limit: {shares or 'none'}", markup=False)
    n = expl.line.size
    rows = np.arange(n) if count is None else expl.costliest(count)
    which = f"all {n} lines" if count is None else f"the {min(count, n)} costliest of {n} lines"
    table = Table(title=f"{which} (feeds in mm/min)", show_edge=False)
    for col, justify in (("line", "right"), ("source", "left"), ("time [s]", "right"),
                         ("share", "right"), ("F", "right"), ("peak", "right"),
                         ("mean", "right"), ("limit", "left")):  # fmt: skip
        table.add_column(col, justify=justify)
    for i in rows.tolist():
        line = int(expl.line[i])
        text = source[line - 1] if 0 < line <= len(source) else ""
        shown = echo_source_line(text.strip(), 1, 32)[0]
        t = float(expl.time_s[i] + expl.wait_s[i])
        row = expl.limit_time_s[i]
        limit = Limit(int(expl.limit[i])).text
        if t > 0 and row.max() < t * 0.999:
            limit += f" ({row.max() / t:.0%})"
        table.add_row(str(line), Text(shown), f"{t:.4f}", f"{t / total:.1%}",
                      _feed_text(float(expl.feed_mm_s[i])),
                      _feed_text(float(expl.peak_mm_s[i])),
                      _feed_text(float(expl.mean_mm_s[i])), limit)  # fmt: skip
    out.print(table)
    if count is not None and n > count:
        out.print(f"  … {n - count} more lines (plan --explain-all shows every line)",
                  markup=False)  # fmt: skip
    counts = expl.corner_counts()
    if counts:
        out.print("  corners: " + ", ".join(f"{v} {k}" for k, v in sorted(counts.items())),
                  markup=False)  # fmt: skip
    stops = expl.corner_dicts(stops_only=True)
    for c in stops[:EXPLAIN_CORNERS]:
        x, y, z = c["point_mm"]
        out.print(f"  stop at line {c['line']} ({x:.3f}, {y:.3f}, {z:.3f}), turning "
                  f"{c['turning_deg']:.1f}°: {c['why'].replace('_', ' ')}", markup=False)
    if len(stops) > EXPLAIN_CORNERS:
        out.print(f"  … {len(stops) - EXPLAIN_CORNERS} more stopped corners (--json lists "
                  "every corner)", markup=False)  # fmt: skip


def print_plan_summary(prog, mach, summary: dict, out: Console) -> None:
    """The human summary of ``plan`` on ``out`` (stderr when the profile goes to stdout)."""
    from rich.text import Text

    if "pieces" in summary:
        out.print(Text.assemble((prog.name, "bold"), f": {summary['piece_count']} pieces "
                  f"({', '.join(f'{v} {k}' for k, v in sorted(summary['pieces'].items()))})"))
    else:
        out.print(Text.assemble((prog.name, "bold"), f": baseline {summary['algorithm']} "
                                "(no acceleration limit)"))  # fmt: skip
    out.print(f"  cycle time: {summary['cycle_time_s']:.4f} s"
              f"{clock_suffix(summary['cycle_time_s'])} ({summary['samples']} reference points "
              f"at T_s = {summary['period_s'] * 1000:g} ms)")  # fmt: skip
    if "lower_bound_s" in summary:
        note = "" if "pieces" in summary else "; a baseline ignores A_max and may beat it"
        out.print(f"  kinematic lower bound: {summary['lower_bound_s']:.4f} s "
                  f"(plan / bound = {summary['lower_bound_ratio']:.3f}{note})")  # fmt: skip
    if "feed_fluctuation_max" in summary:
        out.print(f"  feed fluctuation on NURBS ({summary['interpolator']} interpolation): "
                  f"max {summary['feed_fluctuation_max'] * 100:.2g} %")  # fmt: skip
    if "contour_true_max_um" in summary:
        how = (f"dynamics {summary['dynamics']}, {summary['dynamics_iterations']} re-plans"
               if "pieces" in summary else "no dynamics check: a baseline")
        out.print(f"  {'predicted' if 'pieces' in summary else 'simulated'} contour error: "
                  f"max {summary['contour_true_max_um']:.2f} µm, RMS "
                  f"{summary['contour_true_rms_um']:.2f} "
                  f"µm (ε_max {mach.limits.contour_tolerance_mm * 1000:g} µm; {how})")
    if precompensation_text(summary):
        out.print(precompensation_text(summary), markup=False)


@main.command()
@click.argument("programs", nargs=-1, required=True,
                type=click.Path(allow_dash=True))
@click.option("-o", "--output", type=click.Path(allow_dash=True), default=None,
              help="Reference points: .csv, .npz or - (stdout). One program only.")
@click.option("--output-dir", type=click.Path(), default=None,
              help="Batch: write <name>.csv for every program into this folder.")
@click.option("--jobs", type=click.IntRange(min=1), default=None,
              help="Batch worker processes (default: the number of cores).")
@click.option("--format", "fmt", type=click.Choice(["csv", "npz", "halstreamer"]),
              default=None, help="Output format (default: -o's suffix .npz/.hs, else csv; a "
              "format that contradicts the suffix is an error; npz never goes to stdout): "
              "csv, npz, or halstreamer (LinuxCNC streamer text, x y z per servo period; "
              "docs/linuxcnc.md).")
@click.option("--quiet", is_flag=True, help="No summary on stderr.")
@json_option
@plot_option
@planning_options
@handle_errors
def run(programs, output, output_dir, jobs, fmt, quiet, as_json, plot_dir, **settings):
    """Run the whole pipeline: reference points at every servo period.

    Example: nurbscnc run programs/naca2415.nc -o points.csv

    The CSV header is t,x,y,z,feed,piece,line (s, mm, mm, mm, mm/s, piece index, source
    line); the first row is the start point at t = 0, the last the end point at rest.
    """

    if output_dir is None:
        if len(programs) != 1:
            raise click.UsageError("several programs need --output-dir")
        if output is None:
            raise click.UsageError("give -o FILE (.csv, .npz or -) or --output-dir DIR")
        program = programs[0]
        fmt = output_format(output, fmt)
        refuse_overwriting(program, output)
        with progress_display(show_progress(as_json, quiet), _display_name(program)) as say:
            prog, mach, run = make_plan(program, **settings, progress=say,
                                        keep_reference=bool(plot_dir))  # fmt: skip
            if plot_dir:  # the figures need whole arrays: made once, written from them
                _ = run.samples
            say(f"writing {run.sample_count} points")
            # Window by window: the points are made, checked, written and summarised as
            # they come (memory of one window, whatever the motion time); the summary is
            # made while the writer finishes the file. The text line shows points and
            # cycle time only: no kinematic bound to compute.
            def summarise(stats):
                summary = summary_of(prog, mach, run, stats, lower_bound=as_json)
                return summary, summary_json(summary) if as_json else None

            summary, text = write_output(output, fmt, run, mach, prog.name, summarise)
            if plot_dir:
                from nurbscnc.plan.explain import explain_plan

                say("plotting")
                expl = explain_plan(prog, mach, run.plan) if run.plan is not None else None
                write_plan_plots(run, plot_dir, prog, expl, mach)
        if as_json:
            click.echo(text, err=output == "-")
        elif not quiet:
            err.print(f"{prog.name}: {summary['samples']} points, cycle time "
                      f"{summary['cycle_time_s']:.4f} s{clock_suffix(summary['cycle_time_s'])}"
                      f" → {output}", markup=False)  # fmt: skip
            if precompensation_text(summary):
                err.print(precompensation_text(summary), markup=False)
        return
    run_batch(programs, output_dir, jobs, fmt or "csv", quiet, as_json, settings)


#: The format an output suffix names (``run -o``).
SUFFIX_FORMATS = {".csv": "csv", ".npz": "npz", ".hs": "halstreamer"}


def output_format(output: str, fmt: str | None) -> str:
    """The format of ``run -o output``: ``--format`` if given, else the suffix's, else csv.
    A ``--format`` that contradicts a known suffix, or npz to stdout (binary on a terminal or
    a text pipe), is a usage error (exit 2): the two never silently disagree."""
    suffix = os.path.splitext(output)[1].lower() if output != "-" else ""
    implied = SUFFIX_FORMATS.get(suffix)
    if fmt is not None and implied is not None and fmt != implied:
        raise click.UsageError(f"--format {fmt} contradicts the suffix of -o {output} "
                               f"({implied}); drop --format or rename the output")
    fmt = fmt or implied or "csv"
    if output == "-" and fmt == "npz":
        raise click.UsageError("--format npz writes binary and is refused on stdout (-o -); "
                               "give -o FILE.npz")
    return fmt


def write_output(path: str, fmt: str, run, mach, name: str, then=None):
    """Write the reference points of ``run`` (:class:`~nurbscnc.pipeline.Run`) to ``path``:
    a halstreamer file, or CSV/NPZ by suffix, window by window (:meth:`Run.chunks`), the
    windows made in a worker thread while this one writes them
    (:func:`~nurbscnc.output.background.write_while_making`). ``then(stats)``: run in the
    worker once every window is made, while the writer finishes the file, with the
    :class:`~nurbscnc.plan.report.SampleStats` of the points (the summary). Returns its
    result once the file is complete (None without ``then``)."""
    from nurbscnc.output.background import write_while_making
    from nurbscnc.plan.report import SampleStats

    count = run.sample_count
    if fmt == "halstreamer":
        from nurbscnc.output.halstreamer import write_halstreamer_windows

        def write(windows):
            write_halstreamer_windows(path, (w.points_mm for w in windows), count,
                                      mach.servo.period_s, name)  # fmt: skip
    else:
        from nurbscnc.output.files import write_point_windows

        def write(windows):
            write_point_windows(path, windows, count, npz=fmt == "npz" if fmt else None)

    stats = SampleStats(run.plan)
    return write_while_making(write, stats.tap(run.chunks()),
                              None if then is None else lambda: then(stats))  # fmt: skip


def _batch_one(args):
    """Worker: plan one program and write its output; returns a result row (never raises)."""
    program, target, settings = args

    try:
        prog, mach, run = make_plan(program, **settings)
        samples = write_output(target, "halstreamer" if target.endswith(".hs") else "", run,
                               mach, prog.name, lambda stats: stats.count)  # fmt: skip
        return {"program": program, "ok": True, "output": target,
                "cycle_time_s": run.cycle_time_s, "samples": samples}
    except NurbsCncError as exc:
        return {"program": program, "ok": False,
                "error": format_error(exc, _display_name(program)),
                "exit_code": exc.exit_code}  # fmt: skip
    except Exception as exc:  # a bug: report it as such, keep the batch going
        return {"program": program, "ok": False, "exit_code": EXIT_INTERNAL,
                "error": f"{program}: internal error: {type(exc).__name__}: {exc}"}


def batch_targets(programs, output_dir: str, fmt: str) -> list[str]:
    """``output_dir/<stem>.<fmt>`` for every program. Two programs with one stem (``a/x.nc``
    and ``b/x.nc``, or one file given twice) would write one file: refused before anything is
    planned or written (ConfigError, exit 2, naming both), as is ``-`` (stdin has no name)."""
    seen: dict[str, str] = {}
    targets = []
    for program in programs:
        if program == "-":
            raise ConfigError("a batch (--output-dir) cannot read stdin ('-'); use -o")
        stem = os.path.splitext(os.path.basename(program))[0]
        ext = "hs" if fmt == "halstreamer" else fmt
        target = os.path.join(output_dir, f"{stem}.{ext}")
        if target in seen:
            raise ConfigError(f"{seen[target]} and {program} would both write {target}; "
                              "rename one or run them separately")  # fmt: skip
        seen[target] = program
        targets.append(target)
    for program in programs:  # a program that is some program's output (run --output-dir .)
        for target in targets:
            refuse_overwriting(program, target)
    return targets


def refuse_overwriting(program: str, output: str) -> None:
    """ConfigError (exit 2) when ``output`` is the file ``program`` (``run x.nc -o x.nc``, or
    through a link): the points would replace the program they came from."""
    if "-" in (program, output):
        return
    try:
        same = os.path.samefile(program, output)
    except OSError:  # either does not exist (yet): reading the program says why
        return
    if same:
        raise ConfigError(f"the output {output} is the program {program} itself: its points "
                          "would replace it; give another output file")


#: After SIGTERM, SIGHUP or Ctrl-C, a batch's parent is gone within this time [s].
BATCH_STOP_S = 10


def _stop_batch(exc: BaseException) -> None:
    """A batch interrupted by a signal: each worker is told now (it removes its temporary
    file and exits), and the parent ends within :data:`BATCH_STOP_S` whatever the pool's
    own shutdown does next: it can wait for ever on a queue lock a dying worker held (a CI
    run saw SIGTERM leave the parent alive after 30 s). Exit code as for the signal."""
    import multiprocessing
    import signal

    for worker in multiprocessing.active_children():
        worker.terminate()
    code = 128 + exc.signum if isinstance(exc, _Terminated) else EXIT_INTERRUPTED
    signal.signal(signal.SIGALRM, lambda *_: os._exit(code))
    signal.alarm(BATCH_STOP_S)


#: After SIGTERM, SIGHUP or Ctrl-C, a batch worker is gone within this time [s].
WORKER_STOP_S = 3


def _worker_exit(signum, _frame):
    """SystemExit unwinds the worker (atomic_output: no temporary file stays); should the
    unwinding hang (a lock of the pool's queues that a worker killed beside it held, as the
    parent's can: :func:`_stop_batch`), an alarm ends the worker within
    :data:`WORKER_STOP_S` all the same (a full CI run once saw a worker outlive its batch)."""
    import signal

    signal.signal(signal.SIGALRM, lambda *_: os._exit(128 + signum))
    signal.alarm(WORKER_STOP_S)
    sys.exit(128 + signum)


def _worker_init() -> None:
    """A batch worker ends quietly on SIGTERM/SIGHUP/SIGINT (the parent reports)."""
    import signal

    for sig in (signal.SIGTERM, signal.SIGHUP, signal.SIGINT):
        signal.signal(sig, _worker_exit)


def run_batch(programs, output_dir, jobs, fmt, quiet, as_json, settings) -> None:
    import multiprocessing

    from rich.table import Table

    targets = batch_targets(programs, output_dir, fmt)
    try:
        os.makedirs(output_dir, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create the output folder {output_dir}: "
                          f"{exc.strerror or exc}") from None  # fmt: skip
    tasks = [(program, target, settings) for program, target in zip(programs, targets)]
    workers = min(jobs or os.cpu_count() or 1, len(tasks))
    if workers == 1:
        results = [_batch_one(t) for t in tasks]
    else:
        # Leaving the block for any reason (a signal, Ctrl-C) terminates the workers: each
        # removes its temporary file and exits; none goes on writing after we are gone.
        with multiprocessing.Pool(workers, initializer=_worker_init) as pool:
            try:
                results = pool.map(_batch_one, tasks, chunksize=1)
            except (_Terminated, KeyboardInterrupt) as exc:
                _stop_batch(exc)
                raise
    failed = [r for r in results if not r["ok"]]
    if as_json:
        click.echo(json.dumps({"ok": not failed, "results": results}))
    else:
        table = Table(title=f"batch: {len(results)} programs, {len(failed)} failed",
                      show_edge=False)  # fmt: skip
        for col in ("program", "result", "cycle time [s]", "points"):
            table.add_column(col)
        for r in results:
            table.add_row(r["program"], "ok" if r["ok"] else "FAILED",
                          f"{r['cycle_time_s']:.4f}" if r["ok"] else "",
                          str(r["samples"]) if r["ok"] else "")  # fmt: skip
        (err if quiet else out).print(table)
        for r in failed:
            err.print(r["error"], markup=False)
    if failed:
        raise _Failed(max(r["exit_code"] for r in failed))


@main.command()
@click.argument("source", type=click.Path(allow_dash=True))
@json_option
@plot_option
@click.option("--hold", type=click.Choice(["foh", "zoh"]), default="foh",
              help="Reference between samples: linear (foh, as a pulse-train card) or steps.")
@planning_options
@handle_errors
def simulate(source, as_json, plot_dir, hold, **settings):
    """Servo simulation of reference points (CSV/NPZ from `run`) or of a program (planned
    first): axis errors, contour error (eq. 29 and true distance), cycle time.

    Example: nurbscnc simulate points.csv --json
    """
    import numpy as np

    from nurbscnc.output.files import point_header, read_points, read_points_text
    from nurbscnc.servo.simulate import contour_errors, metrics, simulate_reference

    lower = source.lower()
    # stdin is recognised by its content: a points header (from `run -o -`) or a program
    text = read_program_text("-") if source == "-" else None
    if lower.endswith((".csv", ".npz")) or (text is not None and point_header(text)):
        mach = load_machine_cli(settings["machine"], settings["overrides"])
        data = read_points(source) if text is None else read_points_text(text)
        points = np.column_stack([data["x"], data["y"], data["z"]])
        path = points  # the commanded path: the reference polyline itself
        name = _display_name(source)
    else:
        prog, mach, run = make_plan(source, **settings, text=text)
        from nurbscnc.geometry.polyline import dense_path_mm

        points = run.samples.points_mm
        path = points if run.plan is None else dense_path_mm(run.plan.pieces, run.plan.profile)
        name = prog.name
    sim = simulate_reference(points, mach, hold=hold)
    contour = contour_errors(sim, path)
    m = metrics(sim, path, contour).as_dict()
    if plot_dir:
        from nurbscnc.output import plots

        os.makedirs(plot_dir, exist_ok=True)
        plots.plot_contour_error({"contour (true)": (sim.t_s, contour.true_mm * 1000.0),
                                  "contour (eq. 29)": (sim.t_s, np.abs(contour.eq29_mm) * 1000)},
                                 os.path.join(plot_dir, "contour_error.png"),
                                 title=f"{name}: simulated contour error",
                                 eps_max_um=mach.limits.contour_tolerance_mm * 1000.0)
        plots.plot_axis_errors({"servo": (sim.t_s, sim.axis_error_mm[:, 0] * 1000.0,
                                          sim.axis_error_mm[:, 1] * 1000.0)},
                               os.path.join(plot_dir, "axis_errors.png"),
                               title=f"{name}: simulated axis errors")  # fmt: skip
    if as_json:
        from nurbscnc.plan.report import metrics_json

        click.echo(json.dumps({"ok": True, "program": name, "samples": int(points.shape[0]),
                               **metrics_json(m), **machine_json(mach)}))
        return
    out.print(f"{name}: {points.shape[0]} reference points, cycle time {m['cycle_time_s']:.4f} s",
              markup=False)  # fmt: skip
    out.print(f"  axis error X: max {m['axis_x_max_um']:.2f} µm, RMS {m['axis_x_rms_um']:.2f} µm;"
              f" Y: max {m['axis_y_max_um']:.2f} µm, RMS {m['axis_y_rms_um']:.2f} µm",
              markup=False)  # fmt: skip
    out.print(f"  contour error (eq. 29): max {m['contour_max_um']:.2f} µm, RMS "
              f"{m['contour_rms_um']:.2f} µm, mean {m['contour_mean_um']:.2f} µm", markup=False)
    out.print(f"  contour error (true distance): max {m['true_max_um']:.2f} µm, RMS "
              f"{m['true_rms_um']:.2f} µm, mean {m['true_mean_um']:.2f} µm", markup=False)


# -- compare -----------------------------------------------------------------------------------
@main.command()
@program_argument
@json_option
@plot_option
@click.option("--rotate", "angles", type=float, multiple=True,
              help="Rotate the block about Z by this angle [deg]; repeat for Table 5.")
@click.option("--block", type=click.IntRange(min=1), default=1,
              help="Which NURBS block of the program (1-based).")
@click.option("--algorithm", "algorithms", multiple=True,
              type=click.Choice(["adaptive", "curvature", "ph-lookahead", "ours"]),
              help="Only these algorithms (default: all four).")
@machine_options
@handle_errors
def compare(program, as_json, plot_dir, angles, block, algorithms, machine, overrides):
    """The paper's Table 4 (and 5 with several --rotate): adaptive feed, curvature feed, the
    paper's PH look-ahead and our best configuration, each simulated on the servo model.

    Example: nurbscnc compare programs/naca2415.nc --rotate 0 --rotate 45 --rotate -45
    """
    from rich.table import Table

    from nurbscnc.studies.compare import ALGORITHMS, compare_block, nurbs_block, row

    mach = load_machine_cli(machine, overrides)
    prog = load_program(program)
    seg = nurbs_block(prog, block)
    runs = compare_block(seg, mach, tuple(angles) or (0.0,), tuple(algorithms) or ALGORITHMS)
    rows = [row(r) for r in runs]
    if plot_dir:
        write_compare_plots(runs, plot_dir, prog.name, mach.limits.contour_tolerance_mm * 1e3)
    if as_json:
        click.echo(json.dumps({"ok": True, "program": prog.name, "rows": rows,
                               **machine_json(mach)}))
        return
    table = Table(title=f"{prog.name}: NURBS block on line {seg.line} (µm, s)", show_edge=False)
    for col in ("algorithm", "angle", "X max", "X RMS", "Y max", "Y RMS", "eq. 29 max",
                "RMS", "mean", "true max", "time [s]"):  # fmt: skip
        table.add_column(col, justify="right")
    for r in rows:
        table.add_row(r["algorithm"], f"{r['angle_deg']:g}°", *(f"{r[k]:.2f}" for k in (
            "axis_x_max_um", "axis_x_rms_um", "axis_y_max_um", "axis_y_rms_um",
            "contour_eq29_max_um", "contour_eq29_rms_um", "contour_eq29_mean_um",
            "contour_true_max_um")),
            f"{r['cycle_time_s']:.4f}")  # fmt: skip
    out.print(table)


def write_compare_plots(runs, plot_dir: str, name: str | None = None,
                        eps_max_um: float | None = None) -> list[str]:  # fmt: skip
    """Figures 1, 2/4/6 and 7 of the paper for a comparison (PNG files in ``plot_dir``),
    titled with the program's ``name`` when given; ``eps_max_um`` [µm] drawn on the contour
    error figure."""
    head = f"{name}: " if name else ""
    from nurbscnc.output import plots
    from nurbscnc.plan.report import corner_polylines

    os.makedirs(plot_dir, exist_ok=True)
    written = []
    for angle in sorted({r.angle_deg for r in runs}):
        tag = f"{angle:g}deg".replace("-", "m")
        group = [r for r in runs if r.angle_deg == angle]
        ours = next((r for r in group if r.plan is not None), None)
        if ours is not None:
            corners = corner_polylines(ours.plan.pieces)
            written.append(plots.plot_path(ours.path_mm, corners,
                                           os.path.join(plot_dir, f"path_{tag}.png"),
                                           title=f"{head}tool path and corner regions, "
                                                 f"{angle:g}°"))  # fmt: skip
        written.append(plots.plot_feed_profiles(
            {r.algorithm: (r.samples.t_s, r.samples.v_mm_s) for r in group},
            os.path.join(plot_dir, f"feed_{tag}.png"),
            title=f"{head}feed profiles, {angle:g}°"))  # fmt: skip
        written.append(plots.plot_contour_error(
            {r.algorithm: (r.sim_t_s, r.contour_true_um) for r in group},
            os.path.join(plot_dir, f"contour_{tag}.png"),
            title=f"{head}contour error (true distance), {angle:g}°",
            eps_max_um=eps_max_um))  # fmt: skip
        written.append(plots.plot_axis_errors(
            {r.algorithm: (r.sim_t_s, r.axis_error_um[:, 0], r.axis_error_um[:, 1])
             for r in group}, os.path.join(plot_dir, f"axis_{tag}.png"),
            title=f"{head}axis tracking errors, {angle:g}°"))  # fmt: skip
    return written
