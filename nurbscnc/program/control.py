"""O-word control flow: sources, label indexes and call frames (LinuxCNC's interp_o_word.cc).

A :class:`Source` is one file's lines, parsed lazily (a line is parsed when execution reaches
it, so a CAM trailer after M2 is never read). Its :class:`LabelIndex` lists, per O label,
the lines that carry it and their keywords, found by a cheap scan for lines starting with
an O word; control flow jumps along these lists:

- ``sub`` … ``endsub``: a definition; execution skips it; ``call`` runs it in a new
  :class:`Frame` (#1–#30 and local named parameters are the frame's own);
- ``if`` / ``elseif`` / ``else`` / ``endif``; ``while`` … ``endwhile``; ``do`` … ``while``;
  ``repeat`` … ``endrepeat``; ``break`` / ``continue`` act on the loop of the same label.
"""

from __future__ import annotations

import bisect
import re
from dataclasses import dataclass, field

from nurbscnc.errors import GCodeSyntaxError
from nurbscnc.program.parse import Block, parse_line

_O_LINE = re.compile(
    r"[ \t]*(?:/[ \t]*)?(?:[nN][ \t]*[0-9][0-9 \t]*(?:\.[0-9 \t]*)?)?[oO][ \t]*[0-9<]"
)


class Source:
    """One program file: its lines, blocks parsed on demand, and its label index."""

    def __init__(self, lines: list[str], name: str, call_line: int = 0):
        self.lines = lines
        self.name = name
        #: The main program's line that first called this file (0 for the main program).
        self.call_line = call_line
        self._blocks: list[Block | None] = [None] * len(lines)
        self._labels: dict[str, tuple[list[int], list[str]]] | None = None
        #: Memos of facts about O lines that do not change while running (loops re-ask them).
        self.checked: set[int] = set()  # construct heads whose label was found unique
        self.do_tails: dict[int, bool] = {}  # line index of a while → closes a do loop?

    def block(self, index: int) -> Block:
        """The block of line ``index`` (0-based), parsed the first time it is asked for."""
        block = self._blocks[index]
        if block is None:
            block = self._blocks[index] = parse_line(self.lines[index], index + 1)
        return block

    def labels(self) -> dict[str, tuple[list[int], list[str]]]:
        """label → (sorted line indexes, their keywords), built on first use."""
        if self._labels is None:
            labels: dict[str, tuple[list[int], list[str]]] = {}
            for index, line in enumerate(self.lines):
                if ("o" in line or "O" in line) and _O_LINE.match(line):
                    try:
                        block = self.block(index)
                    except GCodeSyntaxError:
                        continue  # reported if execution ever reaches the line
                    if block.oword is not None:
                        entry = labels.setdefault(block.oword.label, ([], []))
                        entry[0].append(index)
                        entry[1].append(block.oword.keyword)
            self._labels = labels
        return self._labels

    def find(self, label: str, after: int, keywords, stop=("sub", "endsub")) -> int | None:
        """The first line index > ``after`` carrying ``label`` with a keyword in ``keywords``.

        The search stops (None) at a keyword in ``stop`` that is not wanted: constructs do
        not reach across subroutine definitions.
        """
        entry = self.labels().get(label)
        if entry is None:
            return None
        indexes, kinds = entry
        for k in range(bisect.bisect_right(indexes, after), len(indexes)):
            if kinds[k] in keywords:
                return indexes[k]
            if kinds[k] in stop:
                return None
        return None

    def find_before(self, label: str, before: int, keywords) -> int | None:
        """The last line index < ``before`` carrying ``label`` with a keyword in ``keywords``."""
        entry = self.labels().get(label)
        if entry is None:
            return None
        indexes, kinds = entry
        for k in range(bisect.bisect_left(indexes, before) - 1, -1, -1):
            if kinds[k] in keywords:
                return indexes[k]
        return None

    def sub_start(self, label: str) -> int | None:
        """The line index of ``o<label> sub`` in this file."""
        entry = self.labels().get(label)
        if entry is None:
            return None
        for index, kind in zip(*entry):
            if kind == "sub":
                return index
        return None


@dataclass
class Frame:
    """One level of the call stack: where it runs and its local parameters."""

    source: Source
    pc: int
    label: str = ""
    call_line: int = 0  # line (in the caller's source) of the call, for errors
    return_to: int = 0  # caller's pc after the call
    saved_params: list = field(default_factory=list)  # the caller's #1..#30
    named: dict = field(default_factory=dict)  # local named parameters
    repeat_left: dict = field(default_factory=dict)  # line index of repeat → turns left
    m73_state: tuple | None = None  # modal state saved by M73, restored on return
