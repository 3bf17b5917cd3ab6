"""A program that moves a rotary axis, planned whole before the port opens and cut at its
program stops into the sections of a :class:`~nurbscnc.controller.staged.StagedJob`.

Each part between two stops (M0, M1, M60, M6, M100–M199) is planned alone from where the
one before ends — the planner brings the tool to rest at a stop anyway (a stop is a junction
of speed 0), so the parts' plans are the whole plan's — and their samples are quantised as
one point sequence (one rounding per point, the card's position continuous from part to
part), then cut at the parts' ends.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from nurbscnc.errors import PlanningError
from nurbscnc.program.columns import end_abc_deg


def _frames_from(frames, first: int) -> tuple:
    """The program's offset rows (:attr:`Program.frames`) for its segments from ``first``
    on, renumbered from 0 (the row in force at ``first`` becomes the first)."""
    before = [r for r in frames if r[0] <= first]
    head = [(0, *before[-1][1:])] if before else []
    return tuple(head + [(r[0] - first, *r[1:]) for r in frames if r[0] > first])


def program_parts(prog) -> list[tuple[object, object]]:
    """``[(part program or None, stop segment or None), …]``: the segments between two
    program stops (kind "pause") as programs of their own, each starting where the one
    before ends (X Y Z and A B C), with the stop after it (None after the last)."""
    segments = list(prog.segments)
    out = []
    first = 0
    start_mm = tuple(float(v) for v in prog.start_mm)
    abc = tuple(float(v) for v in prog.start_abc_deg)
    for i in [*(k for k, s in enumerate(segments) if s.kind == "pause"), len(segments)]:
        chunk = tuple(segments[first:i])
        part = None
        if chunk:
            part = dataclasses.replace(
                prog,
                segments=chunk,
                start_mm=np.asarray(start_mm, dtype=float),
                frames=_frames_from(prog.frames, first),
                start_abc_deg=abc,
            )
        stop = segments[i] if i < len(segments) else None
        if stop is not None:
            start_mm = tuple(float(v) for v in stop.position_mm)
        abc = end_abc_deg(chunk, abc)
        out.append((part, stop))
        first = i + 1
    return out


def part_points(samples, axes: str, abc_deg) -> np.ndarray:
    """X Y Z [mm] of ``samples`` and the rotary axes of ``axes`` [deg] beside them; a part
    whose samples carry no A B C (its segments none: the axes stand at 0) holds them at
    ``abc_deg``."""
    points = np.asarray(samples.points_mm, dtype=float)
    rotary = axes[3:]
    if not rotary:
        return points
    abc = samples.abc_deg
    if abc is None:
        abc = np.broadcast_to(np.asarray(abc_deg, dtype=float), (points.shape[0], 3))
    cols = [np.asarray(abc, dtype=float)[:, "abc".index(a)] for a in rotary]
    return np.column_stack([points, *cols])


def staged_job(prog, mach, options, optional_stop: bool = False, tools: dict | None = None):
    """The :class:`~nurbscnc.controller.staged.StagedJob` of the interpreted ``prog``:
    every part between its stops planned (``options``), its samples quantised at the
    machine's steps per mm and per degree and checked against the card's pulse limit —
    every error raises here, before any port is opened."""
    from nurbscnc.controller.staged import StagedJob, StagedSection, split_pulses
    from nurbscnc.controller.stops import Stop
    from nurbscnc.output.stream.axes import steps_per_unit, stream_axes
    from nurbscnc.output.stream.quantise import check_pulse_limit, quantise
    from nurbscnc.pipeline import run_program

    axes = stream_axes(prog.rotary_axes)
    scale = steps_per_unit(mach, axes)  # an axis without steps: said before any planning
    pieces, lines, ends, stops = [], [], [], []
    abc = tuple(prog.start_abc_deg)
    total = 0
    for part, stop in program_parts(prog):
        if part is not None:
            samples = run_program(part, mach, options).samples
            pts = part_points(samples, axes, abc)
            line = np.asarray(samples.line, dtype=np.int64)
            if pieces:  # its first point is where the part before ends
                pts, line = pts[1:], line[1:]
            pieces.append(pts)
            lines.append(line)
            total += pts.shape[0]
            abc = end_abc_deg(part.segments, abc)
        ends.append(max(total - 1, 0))
        stops.append(
            None
            if stop is None
            else Stop(
                0.0,
                int(stop.line),
                str(stop.code),
                stop.tool,
                stop.message,
                tuple(str(a) for a in stop.argv),
            )
        )
    if not pieces:
        raise PlanningError("no motion to stream")
    # as app.stream.pulses_of_points: steps per mm and per degree, the card's pulse limit
    pulses = quantise(np.vstack(pieces), scale, mach.servo.period_s, np.concatenate(lines), axes)
    check_pulse_limit(pulses, mach.steps.max_pulses_per_period)
    parts = split_pulses(pulses, ends)
    return StagedJob(
        [StagedSection(p, s) for p, s in zip(parts, stops)],
        mach.servo.period_s,
        optional_stop=optional_stop,
        tools=tools,
    )
