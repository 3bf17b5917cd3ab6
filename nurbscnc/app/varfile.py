"""What a program runs with besides its text: LinuxCNC's parameter file (the work offsets,
G92, the G28/G30 positions) and the user M-code path — found, read, and the parameter file
written back when the program has ended.

The parameter file is, first match wins: ``--var FILE``, ``$NURBSCNC_VAR``, the profile's
``program.var_file`` (relative to the profile's folder). Which commands write it back:
``stream`` (the program ran on the machine) and ``run --write-var``; ``check`` and ``plan``
never. A file that does not exist yet is all zeros (LinuxCNC: "it'll be created in due
course") for a command that writes it; a command that only reads it refuses a missing file
(a mistyped name would silently run every program in machine coordinates).

The user M-code path: the folders of ``--user-m-path`` (repeatable, each may be a
colon-separated list), then those of the profile's ``program.user_m_path`` (colon-separated,
relative to the profile's folder), as LinuxCNC's ``[RS274NGC]USER_M_PATH``: the first folder
holding an executable file named ``M1nn`` (capital M, no extension) serves ``M1nn``; a file
that is not executable is passed over (emctask.cc, emcTaskInit).
"""

from __future__ import annotations

import os
import stat
from dataclasses import dataclass, field

from nurbscnc.errors import ConfigError, OutputError

#: The environment variable naming the parameter file.
ENV_VAR = "NURBSCNC_VAR"
FOUND_BY_OPTION = "--var"
FOUND_BY_ENV = "$" + ENV_VAR
FOUND_BY_PROFILE = "program.var_file"


@dataclass(frozen=True)
class ProgramInputs:
    """The parameter file (``var_path`` or None, ``found_by``; ``parameters`` as read,
    lengths in mm), the user M-code folders ``user_m_dirs`` and the machine's rotary axes
    ``rotary_axes`` (``Machine.rotary_axes``: which A B C exist, which are wrapped, their soft
    limits; empty: a three-axis machine)."""

    var_path: str | None = None
    found_by: str = ""
    parameters: dict = field(default_factory=dict)
    user_m_dirs: tuple = ()
    rotary_axes: dict = field(default_factory=dict)

    def find_user_m(self, code: int) -> str | None:
        """The absolute path of the executable of user M-code ``code`` (100..199), or None."""
        for folder in self.user_m_dirs:
            path = os.path.join(folder, f"M{code}")
            try:
                st = os.stat(path)
            except OSError:
                continue
            if stat.S_ISREG(st.st_mode) and st.st_mode & stat.S_IXUSR:
                return os.path.abspath(path)
        return None

    def interpret_options(self) -> dict:
        """The :class:`~nurbscnc.program.interpret.InterpretOptions` fields they give."""
        return {
            "parameters": dict(self.parameters),
            "find_user_m": self.find_user_m,
            "rotary_axes": dict(self.rotary_axes),
        }


def _profile_folder(machine) -> str:
    source = getattr(machine, "source", "") or ""
    return os.path.dirname(os.path.abspath(source)) if os.path.isfile(source) else os.getcwd()


def _program_settings(machine) -> dict:
    settings = getattr(machine, "settings", None) or {}
    return settings.get("program", {}) or {}


def find_var_file(machine=None, var: str | None = None, env=None) -> tuple[str | None, str]:
    """``(path, found_by)`` of the parameter file (module docstring), ``(None, "")`` when
    none is named."""
    env = os.environ if env is None else env
    if var:
        return str(var), FOUND_BY_OPTION
    if env.get(ENV_VAR):
        return env[ENV_VAR], FOUND_BY_ENV
    named = _program_settings(machine).get("var_file")
    if named:
        named = os.path.expanduser(named)
        return os.path.join(_profile_folder(machine), named), FOUND_BY_PROFILE
    return None, ""


def user_m_dirs(machine=None, user_m_path=()) -> tuple:
    """The user M-code folders (module docstring), tildes expanded."""
    dirs = [d for item in user_m_path for d in str(item).split(":") if d]
    profile = _program_settings(machine).get("user_m_path") or ""
    folder = _profile_folder(machine)
    dirs += [os.path.join(folder, os.path.expanduser(d)) for d in profile.split(":") if d]
    return tuple(os.path.expanduser(d) for d in dirs)


#: The longest a user M-code's executable may run [s] when neither ``--user-m-timeout`` nor
#: the profile's ``program.user_m_timeout_s`` says.
DEFAULT_USER_M_TIMEOUT_S = 60.0


def user_m_timeout_s(machine=None, option_s: float | None = None) -> float:
    """The user M-codes' timeout [s]: ``option_s`` (``--user-m-timeout``), else the
    profile's ``program.user_m_timeout_s``, else :data:`DEFAULT_USER_M_TIMEOUT_S`."""
    if option_s is not None:
        return float(option_s)
    named = _program_settings(machine).get("user_m_timeout_s")
    return float(named) if named is not None else DEFAULT_USER_M_TIMEOUT_S


def read_var_file(path: str, must_exist: bool = True) -> dict:
    """The parameters of the parameter file ``path`` (:func:`~nurbscnc.program.varfile.
    parse_var_text`: ConfigError naming the file and line); ``{}`` for a file that does not
    exist when not ``must_exist``."""
    from nurbscnc.output.inputs import read_input_bytes
    from nurbscnc.program.varfile import parse_var_text

    if not os.path.exists(path):
        if must_exist:
            raise ConfigError(
                f"the parameter file {path} does not exist (a command that writes it back, "
                "stream or run --write-var, creates it)"
            )
        return {}
    data = read_input_bytes(path, f"the parameter file {path}", ConfigError)
    return parse_var_text(data.decode("utf-8", errors="replace"), path)


def program_inputs(machine=None, var=None, user_m_path=(), writes: bool = False) -> ProgramInputs:
    """The parameter file and user M-code folders of a command (``writes``: it writes the
    parameter file back, so a missing one is all zeros)."""
    path, how = find_var_file(machine, var)
    values = read_var_file(path, must_exist=not writes) if path else {}
    if writes and path:
        # checked before the work: a file that cannot be written back loses the offsets
        # the program set (after a whole stream)
        folder = os.path.dirname(os.path.abspath(path))
        if not os.path.isdir(folder):
            raise ConfigError(f"the parameter file {path}: its folder {folder} does not exist")
        if not os.access(folder, os.W_OK) or (
            os.path.exists(path) and not os.access(path, os.W_OK)
        ):
            raise OutputError(f"cannot write the parameter file {path}: Permission denied")
    rotary_axes = dict(getattr(machine, "rotary_axes", None) or {})
    return ProgramInputs(path, how, values, user_m_dirs(machine, user_m_path), rotary_axes)


def write_back(inputs: ProgramInputs, program) -> str | None:
    """Write the program's parameters at its end (``program.parameters``) to the parameter
    file, with the numbers LinuxCNC keeps (the old file's and the required ones); the file's
    path, or None when there is none. The old file is read again just before (its numbers;
    a file made bad meanwhile is a ConfigError and nothing is written)."""
    from nurbscnc.output.varfile import write_var_file
    from nurbscnc.program.varfile import format_var_text

    if inputs.var_path is None:
        return None
    old = read_var_file(inputs.var_path, must_exist=False)
    write_var_file(inputs.var_path, format_var_text(program.parameters, old))
    return inputs.var_path


def work_report(values: dict, machine_mm) -> dict:
    """The active system and the work position [mm] of the machine position ``machine_mm``
    under the parameters ``values`` (:func:`~nurbscnc.program.varfile.work_position_mm`;
    rounded to 1 nm as the machine position): ``{"coordinate_system": "G54",
    "work_position_mm": [x, y, z]}``."""
    from nurbscnc.program.varfile import work_position_mm

    system, work = work_position_mm(values, machine_mm)
    return {"coordinate_system": system, "work_position_mm": [round(v, 6) for v in work]}
