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
import os
import re
from dataclasses import dataclass, field

from nurbscnc.errors import GCodeSyntaxError
from nurbscnc.program.parse import Block, parse_line, split_lines

N_LOCAL = 30  # #1..#30 are a subroutine's own

_O_LINE = re.compile(
    r"[ \t]*(?:/[ \t]*)?(?:[nN][ \t]*[0-9][0-9 \t]*(?:\.[0-9 \t]*)?)?[oO][ \t]*[0-9<]"
)


#: An M99 word (the end of a Fanuc subroutine), and comments to strip before looking for it.
_M99 = re.compile(r"(?<![a-z])m\s*0*99(?![0-9.])", re.I)
_COMMENT = re.compile(r"\([^)]*\)|;.*")


def _code(line: str) -> str:
    """A line without its comments."""
    return _COMMENT.sub("", line) if ("(" in line or ";" in line) else line


class Source:
    """One program file: its lines, blocks parsed on demand, and its label index."""

    def __init__(self, lines: list[str], name: str, call_line: int = 0):
        self.lines = lines
        self.name = name
        #: The main program's line that first called this file (0 for the main program).
        self.call_line = call_line
        self._blocks: list[Block | None] = [None] * len(lines)
        self._labels: dict[str, tuple[list[int], list[str]]] | None = None
        self._scopes: tuple[list[int], list[int]] | None = None
        #: Lines with words that the fast lane ran (1), for the block count; None: none yet.
        self.worded: bytearray | None = None
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

    def scope(self, index: int) -> int:
        """The first line index of the subroutine whose definition holds line ``index``
        (-1: the main program's body).

        LinuxCNC names a control label (if, while, do, repeat and their tails) after the
        subroutine being run, "<sub>#<label>" (interp_read.cc, read_o), so one label may head
        a construct in each subroutine and once more in the main program. A subroutine is an
        ``o<n> sub`` … ``o<n> endsub`` definition, or a Fanuc one: an ``O<n>`` line up to the
        next M99 before any other ``O<n>`` line (an ``O<n>`` with no M99 after it is a
        program number, a title).
        """
        if self._scopes is None:
            self._scopes = self._scope_spans()
        starts, ends = self._scopes
        k = bisect.bisect_right(starts, index) - 1
        return starts[k] if k >= 0 and index <= ends[k] else -1

    def _scope_spans(self) -> tuple[list[int], list[int]]:
        """(first, last) line indexes of every subroutine definition, sorted."""
        spans = []
        bare = sorted(
            i
            for indexes, kinds in self.labels().values()
            for i, w in zip(indexes, kinds)
            if w == ""
        )
        for indexes, kinds in self.labels().values():
            for k, kind in enumerate(kinds):
                if kind == "sub":
                    tail = zip(indexes[k + 1 :], kinds[k + 1 :])
                    spans.append(
                        (indexes[k], next((i for i, w in tail if w == "endsub"), len(self.lines)))
                    )
        for k, head in enumerate(bare):
            stop = bare[k + 1] if k + 1 < len(bare) else len(self.lines)
            m99 = next(
                (i for i in range(head + 1, stop) if _M99.search(_code(self.lines[i]))), None
            )
            if m99 is not None:
                spans.append((head, m99))
        spans.sort()
        return [a for a, _ in spans], [b for _, b in spans]

    def find(self, label: str, after: int, keywords, stop=("sub", "endsub")) -> int | None:
        """The first line index > ``after`` carrying ``label`` with a keyword in ``keywords``.

        Only lines in the same scope as ``after`` (:meth:`scope`) are found, and the search
        stops (None) at a keyword in ``stop`` that is not wanted: constructs do not reach
        across subroutine definitions.
        """
        entry = self.labels().get(label)
        if entry is None:
            return None
        indexes, kinds = entry
        scope = self.scope(after)
        for k in range(bisect.bisect_right(indexes, after), len(indexes)):
            if kinds[k] in keywords and self.scope(indexes[k]) == scope:
                return indexes[k]
            if kinds[k] in stop:
                return None
        return None

    def find_before(self, label: str, before: int, keywords) -> int | None:
        """The last line index < ``before`` carrying ``label`` with a keyword in ``keywords``,
        in the same scope as ``before``."""
        entry = self.labels().get(label)
        if entry is None:
            return None
        indexes, kinds = entry
        scope = self.scope(before)
        for k in range(bisect.bisect_left(indexes, before) - 1, -1, -1):
            if kinds[k] in keywords and self.scope(indexes[k]) == scope:
                return indexes[k]
        return None

    def fanuc_start(self, label: str) -> int | None:
        """The line index of the Fanuc subroutine ``O<label>`` (a bare O line) in this file."""
        entry = self.labels().get(label)
        if entry is None:
            return None
        for index, kind in zip(*entry):
            if kind == "":
                return index
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
    fanuc: bool = False  # an M98 call (returns with M99; #1..#30 are not local)
    fanuc_left: int = 0  # M98 L: repeats still to run after this one


class ControlFlow:
    """The O-word handlers (a mixin of the interpreter: it provides ``error``, ``evaluate``,
    ``frames``, ``source``, ``params``, ``globals``, ``options``, ``note_once``)."""

    def oword(self, block: Block, frame: Frame) -> None:
        label, keyword, args, column = block.oword
        here = frame.pc - 1
        if type(label) is tuple:  # "o#<sub> call": the number is computed (LinuxCNC)
            if keyword != "call":
                raise self.error(
                    f"a computed O label (o#… or o[…]) only works with call, not {keyword}", column
                )
            value = self.evaluate(label[1], column)
            if value != int(value) or value < 0:
                raise self.error(f"computed O label {value:g} is not an O number", column)
            label = str(int(value))
        if keyword == "":
            # A program number ("O1234", Fanuc style; LinuxCNC ignores it anywhere).
            if not self.program_name:
                self.program_name = f"O{label}"
                self.note_once(("O", label), f"program number O{label} (a title; ignored)")
            return
        if keyword in ("sub", "if", "do", "repeat") or (
            keyword == "while" and not self._is_do_tail(label, here)
        ):
            self._check_unique(label, here, column)
        handler = getattr(self, "o_" + keyword)
        handler(label, args, column, frame, here)

    def _check_unique(self, label: str, here: int, column: int) -> None:
        """LinuxCNC: one label, one construct ("duplicate O-word label") per subroutine
        (control labels) or per program (subroutine names)."""
        checked = self.source.checked
        if here in checked:
            return
        indexes, kinds = self.source.labels()[label]
        # Subroutine names and control labels are separate name spaces (LinuxCNC accepts
        # "O101 repeat" and "O101 sub" in one file).
        heads = (
            ("sub",)
            if self.source.block(here).oword.keyword == "sub"
            else ("if", "while", "do", "repeat")
        )
        scope = self.source.scope(here) if heads[0] != "sub" else None
        for index, kind in zip(indexes, kinds):
            if index >= here or kind not in heads:
                continue
            if scope is not None and self.source.scope(index) != scope:
                continue
            if kind == "while" and self._is_do_tail(label, index):
                continue
            if kind == "while" and index > here and self.source.block(here).oword.keyword == "do":
                continue
            raise self.error(
                f"duplicate O-word label o{label} (also defined on line {index + 1})", column
            )
        checked.add(here)

    def _cond(self, args, column: int, keyword: str) -> float:
        if len(args) != 1:
            raise self.error(f"{keyword} needs one [condition]", column)
        return self.evaluate(args[0], column)

    def _jump_target(self, label, after, keywords, column, what) -> int:
        target = self.source.find(label, after, keywords)
        if target is None:
            raise self.error(f"o{label} {what}", column)
        return target

    def _count_loop(self, column: int) -> None:
        self.loop_count += 1
        if self.loop_count > self.options.max_loop_iterations:
            raise self.error(
                f"more than {self.options.max_loop_iterations} loop iterations (an endless loop?)",
                column,
            )

    def o_sub(self, label, args, column, frame, here) -> None:
        # A definition met in the flow: skip to after its endsub. LinuxCNC still reads that
        # endsub (read_o evaluates it while skipping): its value, or none, becomes #<_value>
        # and #<_value_returned>, as after a return.
        end = self._jump_target(label, here, ("endsub",), column, "sub without endsub")
        tail = self.source.block(end).oword
        self.line_no = end + 1
        self._set_value(
            self.evaluate(tail.args[0], tail.column, lenient=True) if tail.args else None
        )
        frame.pc = end + 1

    def o_endsub(self, label, args, column, frame, here) -> None:
        self._return(label, args, column, frame)

    def o_return(self, label, args, column, frame, here) -> None:
        self._return(label, args, column, frame)

    def _return(self, label, args, column, frame) -> None:
        if len(self.frames) == 1:
            raise self.error(f"o{label} return/endsub outside a subroutine", column)
        value = self.evaluate(args[0], column) if args else None
        self.frames.pop()
        if frame.m73_state is not None:
            self.restore_state(frame.m73_state)
        caller = self.frames[-1]
        for k, v in enumerate(frame.saved_params, 1):
            if v is None:
                self.params.pop(k, None)
            else:
                self.params[k] = v
        caller.pc = frame.return_to
        self._set_value(value)

    def _set_value(self, value: float | None) -> None:
        """#<_value> and #<_value_returned> after an endsub or return (``value`` None: none
        given), a skipped definition's endsub, or an M99."""
        self.globals["_value"] = value if value is not None else 0.0
        self.globals["_value_returned"] = 1.0 if value is not None else 0.0

    def o_call(self, label, args, column, frame, here) -> None:
        if len(self.frames) > self.options.max_call_depth:
            raise self.error(
                f"o{label} call: more than {self.options.max_call_depth} nested calls "
                f"(endless recursion?)",
                column,
            )
        if len(args) > N_LOCAL:
            raise self.error(f"o{label} call with more than {N_LOCAL} arguments", column)
        values = [self.evaluate(a, column) for a in args]
        source, start = self._find_sub(label, column)
        saved = [self.params.get(k) for k in range(1, N_LOCAL + 1)]
        for k in range(1, N_LOCAL + 1):
            self.params[k] = values[k - 1] if k <= len(values) else 0.0
        call_line = self.main_line() if self.source is self.main else self.main_line()
        # #<_value_returned> keeps its value into the call (rs274 -g: 1 inside a sub called
        # after a skipped definition's endsub [5]); the call's own return sets it.
        self.frames.append(Frame(source, start + 1, label, call_line, frame.pc, saved))

    def m98(self, words: dict, column: int) -> None:
        """``M98 P<n> [L<k>]``: run the Fanuc subroutine that starts at the line ``O<n>`` of
        this file (or the main program) k times (default 1, L0 none), each run ending at its
        M99 (LinuxCNC 2.9's Fanuc-style subroutines). Parameters stay global: #1..#30 are
        not saved and restored as for ``o<n> call``."""
        if "P" not in words:
            raise self.error("M98 needs a P word (the O number of the subroutine)", column)
        p, pcol = words["P"]
        if p != int(p) or p < 0:
            raise self.error(f"M98 P{p:g}: P must be an O number", pcol)
        repeats, lcol = words.get("L", (1.0, column))
        if repeats != int(repeats) or repeats < 0:
            raise self.error(f"M98 L{repeats:g}: L must be a repeat count (0 or more)", lcol)
        if repeats == 0:
            return
        label = str(int(p))
        if len(self.frames) > self.options.max_call_depth:
            raise self.error(
                f"M98 P{label}: more than {self.options.max_call_depth} nested "
                f"calls (endless recursion?)",
                column,
            )
        for source in (self.source, self.main):
            start = source.fanuc_start(label)
            if start is not None:
                break
        else:
            raise self.error(f"M98 P{label}: no subroutine O{label} in the program", pcol)
        caller = self.frames[-1]
        self.frames.append(
            Frame(
                source,
                start + 1,
                label,
                self.main_line(),
                caller.pc,
                fanuc=True,
                fanuc_left=int(repeats) - 1,
            )
        )

    def m99(self, column: int) -> None:
        """M99: the end of a Fanuc subroutine run: again from its O line while M98's L count
        lasts, then back to the line after the M98."""
        frame = self.frames[-1]
        if not frame.fanuc:
            if len(self.frames) == 1:
                raise self.error(
                    "M99 in the main program (LinuxCNC restarts the program: an "
                    "endless loop nurbscnc cannot plan)",
                    column,
                )
            raise self.error(
                f"M99 in subroutine o{frame.label} (it ends with endsub or "
                f"return; M99 ends an M98 subroutine)",
                column,
            )
        # Every M99 ends a run as an endsub without a value (rs274 -g: a second M98 L2 run
        # reads #<_value_returned> 0).
        self._set_value(None)
        if frame.fanuc_left > 0:
            self._count_loop(column)
            frame.fanuc_left -= 1
            frame.pc = frame.source.fanuc_start(frame.label) + 1
            return
        self.frames.pop()
        if frame.m73_state is not None:
            self.restore_state(frame.m73_state)
        self.frames[-1].pc = frame.return_to

    def _find_sub(self, label: str, column: int) -> tuple[Source, int]:
        for source in (self.source, self.main):
            start = source.sub_start(label)
            if start is not None:
                return source, start
        loaded = self.loaded
        if label in loaded:
            return loaded[label], loaded[label].sub_start(label)
        load = self.options.load_subroutine
        name = label[1:-1] if label.startswith("<") else label
        found = load(name) if (load is not None and label.startswith("<")) else None
        if found is None:
            raise self.error(
                f"subroutine o{label} is not defined"
                + (f" (and no file {name}.ngc was found)" if label.startswith("<") else ""),
                column,
            )
        text, file_name = found
        source = Source(split_lines(text), os.path.basename(file_name), self.main_line())
        start = source.sub_start(label)
        if start is None:
            raise self.error(f"file {file_name} does not define o{label} sub", column)
        loaded[label] = source
        return source, start

    def o_if(self, label, args, column, frame, here) -> None:
        if self._cond(args, column, "if"):
            return
        # Try the elseif conditions in turn, then else, then endif.
        at = here
        while True:
            nxt = self._jump_target(
                label, at, ("elseif", "else", "endif"), column, "if without endif"
            )
            blk = self.source.block(nxt)
            if blk.oword.keyword == "elseif":
                saved = self.line_no
                self.line_no = nxt + 1
                ok = self._cond(blk.oword.args, blk.oword.column, "elseif")
                self.line_no = saved
                if ok:
                    frame.pc = nxt + 1
                    return
                at = nxt
                continue
            frame.pc = nxt + 1
            return

    def _after_if(self, label, here, column, keyword) -> None:
        """An elseif, else or endif needs an ``if`` of its label before it (LinuxCNC:
        "undefined O-word label"); a second endif of a closed if is accepted, as LinuxCNC."""
        if self.source.find_before(label, here, ("if",)) is None:
            raise self.error(f"o{label} {keyword} without if", column)

    def o_elseif(self, label, args, column, frame, here) -> None:
        # Reached by running off the end of a taken branch: skip to endif. LinuxCNC reads
        # (evaluates) the condition of every O-word line it reaches, so an elseif [SQRT[-1]]
        # after a taken branch is still an error there: evaluated here too, then unused.
        self._after_if(label, here, column, "elseif")
        self._cond(args, column, "elseif")
        frame.pc = self._jump_target(label, here, ("endif",), column, "elseif without endif") + 1

    def o_else(self, label, args, column, frame, here) -> None:
        self._after_if(label, here, column, "else")
        frame.pc = self._jump_target(label, here, ("endif",), column, "else without endif") + 1

    def o_endif(self, label, args, column, frame, here) -> None:
        self._after_if(label, here, column, "endif")

    def _is_do_tail(self, label: str, here: int) -> bool:
        """A ``while`` that closes a ``do`` loop (no endwhile follows for it)."""
        tails = self.source.do_tails
        if here not in tails:
            do = self.source.find_before(label, here, ("do",))
            tail = do is not None and (
                self.source.find(label, do, ("while", "endwhile")) == here
                and self.source.find(label, here, ("endwhile",)) is None
            )
            tails[here] = tail
        return tails[here]

    def o_while(self, label, args, column, frame, here) -> None:
        if self._is_do_tail(label, here):
            if self._cond(args, column, "while"):
                self._count_loop(column)
                frame.pc = self.source.find_before(label, here, ("do",)) + 1
            return
        if not self._cond(args, column, "while"):
            end = self._jump_target(label, here, ("endwhile",), column, "while without endwhile")
            frame.pc = end + 1

    def o_endwhile(self, label, args, column, frame, here) -> None:
        head = self.source.find_before(label, here, ("while",))
        if head is None:
            raise self.error(f"o{label} endwhile without while", column)
        self._count_loop(column)
        frame.pc = head

    def o_do(self, label, args, column, frame, here) -> None:
        self._jump_target(label, here, ("while",), column, "do without while")

    def o_repeat(self, label, args, column, frame, here) -> None:
        count = self._cond(args, column, "repeat")
        end = self._jump_target(label, here, ("endrepeat",), column, "repeat without endrepeat")
        # A break or continue of this repeat: LinuxCNC refuses it as it reads it, even where
        # it is skipped (repeat [0], a false if), so the whole body is looked at here.
        exit_ = self.source.find(label, here, ("break", "continue"))
        if exit_ is not None and exit_ < end:
            self.line_no = exit_ + 1
            stray = self.source.block(exit_).oword
            self._repeat_has_no_exit(label, stray.keyword, stray.column, here)
        turns = int(count) if count > 0 else 0
        if turns <= 0:
            frame.pc = end + 1
            return
        frame.repeat_left[here] = turns

    def o_endrepeat(self, label, args, column, frame, here) -> None:
        head = self.source.find_before(label, here, ("repeat",))
        if head is None:
            raise self.error(f"o{label} endrepeat without repeat", column)
        left = frame.repeat_left.get(head, 1) - 1
        if left > 0:
            self._count_loop(column)
            frame.repeat_left[head] = left
            frame.pc = head + 1
        else:
            frame.repeat_left.pop(head, None)

    def _loop_of(self, label, here, column, what):
        """(head index, keyword, end index) of the loop ``label`` that contains ``here``."""
        head = self.source.find_before(label, here, ("while", "do", "repeat"))
        if head is None:
            raise self.error(f"o{label} {what} outside a loop", column)
        kind = self.source.block(head).oword.keyword
        if kind == "do":
            end = self.source.find(label, head, ("while",))
        elif kind == "while" and self._is_do_tail(label, head):
            raise self.error(f"o{label} {what} outside a loop", column)
        else:
            end = self.source.find(label, head, ("endwhile" if kind == "while" else "endrepeat",))
        if end is None:
            raise self.error(f"o{label} {what}: the loop has no end", column)
        if end < here:  # after the loop's end: a break there would jump back to itself
            raise self.error(f"o{label} {what} outside a loop", column)
        if kind == "repeat":
            self._repeat_has_no_exit(label, what, column, head)
        return head, kind, end

    def _repeat_has_no_exit(self, label, keyword, column, head) -> None:
        """LinuxCNC (interp_o_word.cc): break and continue belong to while and do loops."""
        raise self.error(
            f"no matching while/do label: 'o{label} {keyword}' (found 'repeat' in line {head + 1})",
            column,
        )

    def o_break(self, label, args, column, frame, here) -> None:
        head, kind, end = self._loop_of(label, here, column, "break")
        frame.repeat_left.pop(head, None)
        frame.pc = end + 1

    def o_continue(self, label, args, column, frame, here) -> None:
        head, kind, end = self._loop_of(label, here, column, "continue")
        self._count_loop(column)
        # while: re-test at the head; do: test at the tail; repeat: count at endrepeat.
        frame.pc = head if kind == "while" else end
