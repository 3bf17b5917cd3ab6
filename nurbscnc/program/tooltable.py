"""LinuxCNC tool tables: ``T<n> P<pocket> X.. Y.. Z.. D<diameter> ;comment`` per line.

Pure: the caller reads the file and passes its text. LinuxCNC's format (tooldata.cc): each
line holds words of a letter and a number, in any order, then an optional ``;`` comment;
T is required; X Y Z (and A B C U V W) are the tool offsets along each axis, D the
diameter, P the pocket, I J Q lathe data (ignored here). Values are in the machine's units,
which nurbscnc takes as mm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from nurbscnc.errors import ConfigError

_OFFSET_LETTERS = "XYZABCUVW"
_KNOWN = set(_OFFSET_LETTERS) | set("TPDIJQ")


@dataclass(frozen=True)
class Tool:
    """One tool: offsets [mm] along X, Y, Z (G43 uses them) and diameter [mm] (G41/G42);
    ``comment``: the line's text after ``;`` (named to the operator at a tool change)."""

    number: int
    offset_mm: tuple = (0.0, 0.0, 0.0)
    diameter_mm: float = 0.0
    pocket: int = 0
    comment: str = ""

    @property
    def length_mm(self) -> float:
        return self.offset_mm[2]


def parse_tool_table(text: str, name: str = "<tool table>") -> dict[int, Tool]:
    """Parse a LinuxCNC tool table text into ``{tool number: Tool}``.

    Raises :class:`ConfigError` naming ``name:line`` and the bad field (a value that is not a
    finite number, such as ``T1e400``, a tool number that is not a non-negative integer).
    """
    table: dict[int, Tool] = {}
    for number, raw in enumerate(text.splitlines(), 1):
        body = raw.split(";", 1)[0].split()
        if not body:
            continue
        fields: dict[str, float] = {}
        for item in body:
            letter, value_text = item[:1].upper(), item[1:]
            if letter not in _KNOWN:
                raise ConfigError(f"{name}:{number}: unknown tool table field {item[:40]!r}")
            try:
                value = float(value_text)
            except ValueError:
                raise ConfigError(
                    f"{name}:{number}: bad tool table field {item[:40]!r} (not a number)"
                ) from None
            if not math.isfinite(value):
                raise ConfigError(
                    f"{name}:{number}: tool table value {item[:40]!r} is out of range"
                )
            fields[letter] = value
        if "T" not in fields:
            raise ConfigError(f"{name}:{number}: tool table line without a T word")
        t = fields["T"]
        if t != int(t) or not 0 <= t < 2**31:
            raise ConfigError(f"{name}:{number}: tool number T{t:g} must be a non-negative integer")
        diameter = fields.get("D", 0.0)
        if diameter < 0.0:
            raise ConfigError(f"{name}:{number}: negative tool diameter D{diameter:g}")
        table[int(t)] = Tool(
            number=int(t),
            offset_mm=(fields.get("X", 0.0), fields.get("Y", 0.0), fields.get("Z", 0.0)),
            diameter_mm=diameter,
            pocket=int(fields.get("P", 0.0)) if abs(fields.get("P", 0.0)) < 2**31 else 0,
            comment=raw.split(";", 1)[1].strip() if ";" in raw else "",
        )
    return table
