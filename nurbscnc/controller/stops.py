"""The program's stops as the controller meets them: M0, M1, M60, a tool change (M6) and a
user M-code (M100–M199), at their path lengths in a plan; what the operator is told there;
and run-from-line (:func:`start_at_line`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbscnc.program.codes import USER_M_FIRST, USER_M_LAST


@dataclass(frozen=True)
class Stop:
    """A program stop at global path length ``s_mm``, source ``line``: ``code`` "M0", "M1",
    "M60", "M6" (``tool``: the tool to load) or "M100"–"M199" (``argv``: the executable's
    absolute path, then P and Q as text); ``message``: the operator's text of that line."""

    s_mm: float
    line: int
    code: str
    tool: int | None = None
    message: str = ""
    argv: tuple = ()

    @property
    def user_m(self) -> bool:
        """A user M-code: run its executable at rest instead of waiting for the operator."""
        return is_user_m(self.code)


def is_user_m(code: str) -> bool:
    """Whether ``code`` ("M101") is a user M-code (M100–M199)."""
    return code[:1] == "M" and code[1:].isdigit() and USER_M_FIRST <= int(code[1:]) <= USER_M_LAST


def describe_stop(stop: Stop, tools: dict | None = None) -> str:
    """What the operator is told at ``stop``: "M0 at line 4: <message>"; for a tool change
    the tool and its table entry (length and diameter [mm], comment) from ``tools``
    (``{number: Tool}``, :mod:`nurbscnc.program.tooltable`)."""
    text = f"{stop.code} at line {stop.line}"
    if stop.code == "M6" and stop.tool is not None:
        entry = (tools or {}).get(stop.tool)
        if entry is None:
            text += f": load tool {stop.tool} (not in the tool table)"
        else:
            text += (
                f": load tool {stop.tool} (length {entry.length_mm:g} mm, "
                f"diameter {entry.diameter_mm:g} mm"
            )
            text += f", {entry.comment})" if entry.comment else ")"
    if stop.message:
        text += f": {stop.message}"
    return text


def program_stops(program, plan) -> list[Stop]:
    """The program stops (kind "pause": M0, M1, M60, M6, M100–M199) at their path lengths in
    ``plan``: the end of the last piece made from a segment before the stop."""
    seg = np.asarray(plan.pieces.segment)
    ends = np.asarray(plan.profile.piece_start_mm) + np.asarray(plan.pieces.length_mm)
    out = []
    for i, s in enumerate(program.segments):
        if s.kind != "pause":
            continue
        r = int(np.searchsorted(seg, i, side="left")) - 1
        s_mm = float(ends[r]) if r >= 0 else 0.0
        argv = tuple(str(a) for a in s.argv)
        out.append(Stop(s_mm, int(s.line), str(s.code), s.tool, s.message, argv))
    return out


def start_at_line(program, line: int):
    """The program run from source line ``line`` on, as LinuxCNC's run-from-line: the whole
    program was interpreted (so the segments from ``line`` on carry every modal state set
    before it: units, offsets, plane, feed, tool), the segments before it are dropped, and a
    lead-in brings the tool from the program's start to the start of line ``line`` safely.

    Lead-in (decision; docs/protocol.md): up to Z_safe = the highest Z of the program's start,
    of every point the program reaches before ``line`` and of the target (the clearance the
    program itself used, so it is known to be free and inside the soft limits; +Z is up), a
    rapid across at Z_safe, then down to the target: a rapid when the first move of ``line``
    is a rapid, else at that move's programmed feed (never a rapid plunge into material).
    Raises ValueError when no motion starts at or after ``line``.
    """
    from dataclasses import replace

    from nurbscnc.geometry.segments import Line

    segs = list(program.segments)
    first = next((i for i, s in enumerate(segs) if s.line >= line), None)
    moving = (
        next((i for i in range(first, len(segs)) if segs[i].kind not in ("dwell", "pause")), None)
        if first is not None
        else None
    )
    if moving is None:
        raise ValueError(f"--from-line {line}: no motion at or after line {line}")
    target = np.asarray(segs[moving].start_mm, dtype=float)
    here = np.asarray(program.start_mm, dtype=float)
    before = [np.asarray(s.end_mm, dtype=float)[2] for s in segs[:first]]
    z_safe = float(max([here[2], target[2], *before]))
    feed = segs[moving].feed_mm_s
    plunge_rapid = segs[moving].kind == "rapid" or not feed > 0.0
    path = [
        here,
        np.array([here[0], here[1], z_safe]),
        np.array([target[0], target[1], z_safe]),
        target,
    ]
    lead = []
    for i, (a, b) in enumerate(zip(path[:-1], path[1:])):
        if np.allclose(a, b, rtol=0.0, atol=1e-12):
            continue
        rapid = i < 2 or plunge_rapid
        lead.append(
            Line(
                tuple(a.tolist()),
                tuple(b.tolist()),
                0.0 if rapid else float(feed),
                int(segs[moving].line),
                rapid=rapid,
            )
        )
    return replace(program, segments=tuple(lead + segs[first:]))
