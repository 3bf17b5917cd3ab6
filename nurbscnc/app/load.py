"""Reading a command's inputs: program files (with their subroutine files), tool tables, and
the machine profile with its overrides."""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

from nurbscnc.errors import ConfigError, ProgramError

if TYPE_CHECKING:
    from nurbscnc.geometry.segments import Program
    from nurbscnc.machine.profile import Machine


def display_name(name) -> str:
    """The name a file is reported under: ``<stdin>`` for ``-`` (or None)."""
    return "<stdin>" if name in ("-", None) else str(name)


def read_program_text(path: str) -> str:
    """The program text of ``path`` (``-`` for stdin). UTF-8 (BOM allowed), else Latin-1.

    Non-ASCII bytes are harmless in comments; elsewhere the parser reports them.
    """
    from nurbscnc.output.inputs import read_input_bytes

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
    inputs=None,
    start_mm=None,
    start_abc_deg=None,
) -> Program:
    """Read, parse and interpret a program file.

    ``o<name> call`` of a subroutine the program does not define reads ``name.ngc`` from the
    program's directory, then each directory of ``subroutine_path`` (LinuxCNC's
    SUBROUTINE_PATH); the interpreter gets the reading as a callback and does no I/O itself.
    ``text``, when given, is the program already read (stdin that ``simulate -`` looked at).
    ``inputs``: the parameter file's values and the user M-code folders
    (:class:`~nurbscnc.app.varfile.ProgramInputs`; None: neither). ``start_mm``: where the
    program starts [mm, machine coordinates] (None: machine zero); ``start_abc_deg`` its
    A B C [deg] (None: 0, :func:`start_abc_option`).
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
        block_delete=block_delete,
        tools=tools,
        name=display_name(path),
        load_subroutine=load_subroutine,
        **({} if start_mm is None else {"start_mm": tuple(map(float, start_mm))}),
        **start_abc_option(start_abc_deg),
        **(inputs.interpret_options() if inputs is not None else {}),
    )
    return interpret_text(text, options)


def start_abc_option(start_abc_deg) -> dict:
    """The interpreter's option for a program started at A B C = ``start_abc_deg`` [deg]
    (where the card stands): ``{"start_abc_deg": (a, b, c)}``, or ``{}`` for None or all 0."""
    if start_abc_deg is None or not any(start_abc_deg):
        return {}
    return {"start_abc_deg": tuple(float(v) for v in start_abc_deg)}


def read_tool_table(path: str) -> dict:
    """A LinuxCNC tool table file → ``{tool number: Tool}`` (see program/tooltable.py)."""
    from nurbscnc.output.inputs import read_input_bytes
    from nurbscnc.program.tooltable import parse_tool_table

    data = read_input_bytes(path, f"the tool table {path}", ConfigError)
    return parse_tool_table(data.decode("utf-8", errors="replace"), path)


def override_table(overrides=(), extra: dict | None = None) -> dict:
    """The profile overrides ``{dotted key: value text}`` of ``--set KEY=VALUE`` items and
    of a command's own options ``extra`` (None values left out; ConfigError on an item
    without ``=``)."""
    table = {}
    for item in overrides:
        if "=" not in item:
            raise ConfigError(f"--set wants KEY=VALUE, got {item!r}")
        key, value = item.split("=", 1)
        table[key.strip()] = value.strip()
    table.update({k: v for k, v in (extra or {}).items() if v is not None})
    return table


def load_machine(path, table: dict) -> Machine:
    """The machine profile ``path`` (None: found as
    :func:`~nurbscnc.machine.profile.find_machine` says: $NURBSCNC_MACHINE, ./nurbscnc.toml,
    the user's config folder, the bundled default) with the overrides ``table`` of
    :func:`override_table` applied."""
    from nurbscnc.machine.profile import find_machine
    from nurbscnc.machine.profile import load_machine as load_profile

    found, how = find_machine(path)
    return load_profile(found, table or None, how)
