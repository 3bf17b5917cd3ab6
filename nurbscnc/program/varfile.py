"""LinuxCNC's parameter file (``rs274ngc.var``): the numbered parameters that persist between
programs — the G54…G59.3 offsets and rotations, G92 and its enable, the active system, the
G28/G30 positions, and any other parameter the file lists.

Pure: the caller reads the file and passes its text (:func:`parse_var_text`), and writes the
text :func:`format_var_text` makes (``output/varfile.py``, atomically).

The format (LinuxCNC 2.9, rs274ngc_pre.cc ``restore_parameters`` / ``save_parameters``):
one ``<number> <value>`` pair a line, numbers strictly increasing, 1 ≤ number < 5602.
LinuxCNC reads each line with ``sscanf("%d %lf")`` and skips a line that does not match;
nurbscnc refuses it instead (a clear error naming the file and line: a stray line in the
file that holds the work offsets is a mistake worth stopping for). Writing, LinuxCNC keeps
every number the old file had, adds the required ones it lacked
(:data:`REQUIRED_PARAMETERS`), each as ``"%d\\t%f"`` with the value now in force.

Lengths are in the machine's units; nurbscnc's machine unit is the mm.
"""

from __future__ import annotations

import math
import re

from nurbscnc.errors import ConfigError
from nurbscnc.program import coords
from nurbscnc.program.words import MAX_COORD_MM

#: LinuxCNC's RS274NGC_MAX_PARAMETERS: parameter numbers are 1 … 5601 in the file.
VAR_MAX_PARAMETER = 5602


def _required() -> tuple:
    """LinuxCNC's ``Interp::required_parameters`` (interp_array.cc): G28 and G30 homes
    (X Y Z A B C U V W), the G92 flag and offsets, the active system, and each system's nine
    offsets and its rotation."""
    numbers = list(range(5161, 5170)) + list(range(5181, 5190)) + list(range(5210, 5221))
    for system in range(coords.N_SYSTEMS):
        base = coords.SYSTEM_BASE + coords.SYSTEM_STRIDE * system
        numbers += list(range(base, base + 10))
    return tuple(numbers)


#: The parameters LinuxCNC always writes to its parameter file.
REQUIRED_PARAMETERS = _required()

_LINE = re.compile(r"^\s*([+-]?\d+)\s+(\S+)\s*$")


def _length_numbers() -> frozenset:
    """The parameters that hold lengths (X, Y, Z of the homes, G92 and each system): bounded
    like a coordinate."""
    numbers = [coords.G28_BASE + k for k in range(3)] + [coords.G30_BASE + k for k in range(3)]
    numbers += [coords.G92_BASE + k for k in range(3)]
    for system in range(coords.N_SYSTEMS):
        numbers += [coords.SYSTEM_BASE + coords.SYSTEM_STRIDE * system + k for k in range(3)]
    return frozenset(numbers)


#: The parameters that hold lengths [mm] (the others are flags, angles, plain numbers).
LENGTH_PARAMETERS = _length_numbers()


def parse_var_text(text: str, name: str = "<var file>") -> dict[int, float]:
    """The parameters ``{number: value}`` of a parameter file's text (lengths in mm).

    Blank lines are skipped. Raises :class:`ConfigError` naming ``name:line`` for a line
    that is not ``<number> <value>``, a number out of 1…5601 or not above the previous one
    (LinuxCNC: "Parameter file out of order"), a value that is not a finite number, a length
    beyond ±1e9 mm, or an active system (#5220) other than 1…9.
    """
    values: dict[int, float] = {}
    last = 0
    for number, raw in enumerate(text.splitlines(), 1):
        if not raw.strip():
            continue
        where = f"{name}:{number}"
        match = _LINE.match(raw)
        if match is None:
            raise ConfigError(f"{where}: not a parameter line ('<number> <value>'): {raw[:60]!r}")
        index = int(match.group(1))
        try:
            value = float(match.group(2))
        except ValueError:
            raise ConfigError(
                f"{where}: parameter #{index} value {match.group(2)[:40]!r} is not a number"
            ) from None
        if not 0 < index < VAR_MAX_PARAMETER:
            raise ConfigError(f"{where}: parameter number {index} out of range 1..5601")
        if index <= last:
            raise ConfigError(
                f"{where}: parameter #{index} after #{last}: the numbers must increase "
                "(LinuxCNC: parameter file out of order)"
            )
        _check_value(where, index, value)
        values[index] = value
        last = index
    return values


def _check_value(where: str, index: int, value: float) -> None:
    if not math.isfinite(value):
        raise ConfigError(f"{where}: parameter #{index} value {value} is not a finite number")
    if index in LENGTH_PARAMETERS and abs(value) > MAX_COORD_MM:
        raise ConfigError(
            f"{where}: parameter #{index} = {value:g} mm is out of range "
            f"(at most ±{MAX_COORD_MM:g})"
        )
    if index == coords.SYSTEM_INDEX and (
        abs(value - round(value)) > 1e-4 or not 1 <= round(value) <= coords.N_SYSTEMS
    ):
        raise ConfigError(
            f"{where}: parameter #5220 (the active coordinate system) = {value:g}: "
            "must be 1..9 (G54..G59.3)"
        )


def var_numbers(old: dict | None) -> list[int]:
    """The parameter numbers a written file holds: those of the old file and the required
    ones (LinuxCNC's save_parameters), in increasing order."""
    return sorted(set(REQUIRED_PARAMETERS) | set(old or ()))


def format_var_text(values: dict, old: dict | None = None) -> str:
    """The parameter file's text LinuxCNC writes: one ``"%d\\t%f"`` line for each number of
    :func:`var_numbers` ``(old)``, with its value in ``values`` (0 when absent)."""
    return "".join(f"{k}\t{float(values.get(k, 0.0)):f}\n" for k in var_numbers(old))


def work_position_mm(values: dict, machine_mm) -> tuple[str, list]:
    """The active system's name ("G54"…) and the work (program) coordinates [mm] of the
    machine position ``machine_mm`` under the offsets of a parameter file's ``values``
    (lengths in mm; no tool offset): what a controller shows beside the machine position."""
    frame = coords.Coordinates()
    frame.restore(values)
    return coords.SYSTEM_NAMES[frame.system], frame.to_program(list(map(float, machine_mm)))
