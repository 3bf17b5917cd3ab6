"""Manual data input: a few blocks run against the card's current position (``nurbscnc mdi``)
and the incremental moves of ``nurbscnc jog``.

The blocks are a program named ``mdi`` (errors read ``mdi:LINE:COL``), interpreted from the
card's position — steps over the profile's steps per mm, machine coordinates — with the
parameter file's offsets, so the work position is machine − offsets (LinuxCNC's MDI). Each
call starts from the interpreter's default modes (G21 G90 G17 G94, no tool offset, the
parameter file's active system): nothing modal carries over from one call to the next but
what the parameter file keeps.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from nurbscnc.errors import ConfigError, NurbsCncError

#: The name the blocks are reported under.
MDI_NAME = "mdi"
#: The axes a jog names, in the card's axis order (A B C when the machine has them).
JOG_AXES = "XYZABC"
#: The most blocks one call runs (they are typed on a command line).
MAX_MDI_LINES = 1000


@dataclass(frozen=True)
class MdiJob:
    """What an MDI call runs: the interpreted ``program`` (its ``parameters`` are written
    back), the ``job`` streamed cut window by cut window or the whole run's ``pulses``
    (:func:`~nurbscnc.app.stream.stream_job`; both None when the blocks move nothing),
    ``stops`` the program's pauses when nothing moves (a user M-code still runs), and
    ``start_mm`` the card's position [mm, machine] the blocks start from."""

    program: object
    job: object = None
    pulses: object = None
    stops: tuple = ()
    start_mm: tuple = ()

    @property
    def moves(self) -> bool:
        """Whether anything is streamed."""
        return self.job is not None or self.pulses is not None


def mdi_lines(blocks) -> list[str]:
    """The lines of the ``blocks`` (command-line arguments, each may hold several lines)."""
    lines = [line.rstrip("\r") for block in blocks for line in str(block).split("\n")]
    if not any(line.strip() for line in lines):
        raise ConfigError("mdi: no block to run")
    if len(lines) > MAX_MDI_LINES:
        raise ConfigError(f"mdi: {len(lines)} lines; at most {MAX_MDI_LINES} (use stream)")
    return lines


def mdi_job(
    blocks, mach, inputs, position_steps, options, tools=None, optional_stop=False
) -> MdiJob:
    """Interpret the ``blocks`` (:func:`mdi_lines`) from the card's position
    ``position_steps`` with the parameter file and user M-codes of ``inputs``
    (:class:`~nurbscnc.app.varfile.ProgramInputs`) and the tool table ``tools``, and plan
    them with the run ``options`` within the machine's limits and soft limits (machine
    coordinates). Every error — of the text, of the soft limits, of the card's pulse limit —
    raises here, before anything is sent, at ``mdi:LINE:COL`` with the block's text."""
    from nurbscnc.app.load import start_abc_option
    from nurbscnc.app.stream import position_abc_deg, position_mm, start_abc, stream_job
    from nurbscnc.program.interpret import InterpretOptions, interpret_text

    lines = mdi_lines(blocks)
    # ConfigError when the card's axes are not the profile's X Y Z and rotary axes
    abc = start_abc(position_abc_deg(position_steps, mach))
    start_mm = tuple(position_mm(position_steps, mach))
    try:
        prog = interpret_text(
            "\n".join(lines),
            InterpretOptions(
                start_mm=start_mm,
                name=MDI_NAME,
                tools=tools,
                **start_abc_option(abc),
                **(inputs.interpret_options() if inputs is not None else {}),
            ),
        )
        if all(s.kind == "pause" for s in prog.segments):
            return MdiJob(prog, stops=tuple(prog.segments), start_mm=start_mm)
        job, pulses = stream_job(prog, mach, options, None, optional_stop, 1.0, tools)
    except NurbsCncError as exc:
        raise _with_text(exc, lines) from None
    return MdiJob(prog, job, pulses, start_mm=start_mm)


def _with_text(exc: NurbsCncError, lines: list[str]) -> NurbsCncError:
    """The error with its block's text for the caret (a planner's error names the line only)."""
    pos = exc.pos
    if pos is not None and not pos.text and 1 <= pos.line <= len(lines):
        exc.pos = dataclasses.replace(pos, text=lines[pos.line - 1])
    return exc


def jog_block(moves, position_steps, mach, feed_mm_min: float | None = None) -> str:
    """The block of a jog: ``moves`` like ``("X+1.5", "Z-0.2", "A+10")`` (axis, signed
    distance [mm; deg for A B C]; an axis at most once) from the card's position
    ``position_steps``, a rapid, or a feed at ``feed_mm_min`` [mm/min; deg/min for a
    rotary-only jog, LinuxCNC's rate]. X Y Z and the unwrapped rotary axes move as one
    absolute move in machine coordinates (``G53 G90``: no work offset, G92 or rotation
    turns a jog). A wrapped axis moves by an incremental word (``G91``): a G53 word of a
    wrapped axis is unwrapped about the program position less the offsets (LinuxCNC's
    ``find_ends``), so with an A work offset it would not land at the card's A + Δ, while
    G91 adds Δ whatever the offsets. A jog of both is two blocks, the G53 move first. A
    rotary axis needs the machine to have it and the card to drive it (ConfigError
    otherwise)."""
    from nurbscnc.app.stream import position_abc_deg, position_mm

    deltas = parse_jog(moves)
    here = position_mm(position_steps, mach)
    abc = position_abc_deg(position_steps, mach)
    absolute, incremental = [], []
    for a, d in sorted(deltas.items()):
        name = JOG_AXES[a]
        if a < 3:
            absolute.append(f"{name}{here[a] + d:.6f}")
            continue
        axis = mach.rotary_axes.get(name.lower())
        if axis is None:
            raise ConfigError(f"jog: the machine has no {name} axis ([axis_limits.{name.lower()}])")
        if name.lower() not in abc:
            raise ConfigError(f"jog: the card does not drive {name} (its position has no {name})")
        if axis.wrapped:
            incremental.append(f"{name}{d:+.6f}")
        else:
            absolute.append(f"{name}{abc[name.lower()] + d:.6f}")
    motion = "G0" if feed_mm_min is None else f"G1 F{feed_mm_min:g}"
    blocks = [f"G90 G53 {motion} {' '.join(absolute)}"] if absolute else []
    if incremental:
        blocks.append(f"G91 {motion} {' '.join(incremental)}")
    return "\n".join(blocks)


def parse_jog(moves) -> dict[int, float]:
    """``{axis index: distance}`` of jog words ``X+1.5``, ``y-2``, ``Z3``, ``A+10`` (mm;
    degrees for A B C; ConfigError naming a bad word)."""
    import math

    out: dict[int, float] = {}
    for word in moves:
        text = str(word).strip()
        axis = JOG_AXES.find(text[:1].upper()) if text else -1
        try:
            distance = float(text[1:])
        except ValueError:
            distance = math.nan
        if axis < 0 or not math.isfinite(distance) or text[1:2] in ("", " "):
            raise ConfigError(
                f"jog: {word!r} is not a move: an axis X, Y, Z (mm) or A, B, C (degrees) and "
                "a distance, like X+1.5, Z-0.2 or A+10"
            )
        if axis in out:
            raise ConfigError(f"jog: axis {JOG_AXES[axis]} named twice")
        out[axis] = distance
    if not out:
        raise ConfigError("jog: no move (e.g. X+1.5)")
    return out
