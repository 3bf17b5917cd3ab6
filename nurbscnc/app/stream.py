"""What a stream sends, prepared before any port is opened: the pulses of a reference-point
file or of a whole planned run, or the job of a program planned cut window by cut window."""

from __future__ import annotations

from nurbscnc.errors import ConfigError, GeometryError, NurbsCncError, PlanningError

#: The suffixes of reference-point files (``run -o``), streamed as they are.
POINT_SUFFIXES = (".csv", ".npz")


def is_points_file(path: str) -> bool:
    """Whether ``path`` names a file of reference points rather than a program."""
    return path.lower().endswith(POINT_SUFFIXES)


def points_of_file(path: str, mach):
    """The reference points [mm] (N × 3) of the file ``path`` (:data:`POINT_SUFFIXES`),
    checked for the machine ``mach``: not empty, finite, one point per servo period (the
    CSV's 1 µs rounding of t allowed), inside the soft limits (PlanningError or
    ConfigError naming the first offending point). The rotary columns:
    :func:`axes_points_of_file`."""
    return axes_points_of_file(path, mach)[0][:, :3]


def axes_points_of_file(path: str, mach):
    """``(points, axes)``: the file's X Y Z [mm] and, when it has ``a``/``b``/``c`` columns,
    the rotary axes [deg] beside them (N × (3 + k)), ``axes`` their names ("xyz", "xyza",
    …), checked as :func:`points_of_file` and the rotary columns within the axes' soft
    limits ``min_deg``/``max_deg``."""
    import numpy as np

    from nurbscnc.output.files import read_points
    from nurbscnc.output.stream.axes import stream_axes

    data = read_points(path)
    axes = stream_axes(a for a in "abc" if a in data)
    points = np.column_stack([data[a] for a in axes]).astype(float)
    if points.shape[0] == 0:
        raise PlanningError(f"{path}: no reference points")
    if not np.all(np.isfinite(points)):
        raise PlanningError(f"{path}: a reference point is not a finite number")
    period_s = mach.servo.period_s
    dt = np.diff(np.asarray(data["t"], dtype=float))
    # The CSV writes t with 6 decimals (1 µs): allow that rounding, nothing more.
    bad = np.flatnonzero(np.abs(dt - period_s) > 1.01e-6)
    if bad.size:
        k = int(bad[0])
        raise ConfigError(
            f"{path}: points {k + 1} and {k + 2} are {dt[k] * 1e3:.6g} ms apart; the "
            f"machine's servo period is {period_s * 1e3:g} ms (one point per period)"
        )
    inside = mach.soft_limits.inside(points[:, :3])
    if not np.all(inside):
        k = int(np.flatnonzero(~inside)[0])
        raise PlanningError(
            f"{path}: point {k + 1} ({', '.join(f'{v:.4f}' for v in points[k, :3])}) mm is "
            "outside the soft limits"
        )
    rotary_of_points_checked(path, data, mach)
    return points, axes


def rotary_of_points_checked(name: str, data: dict, mach) -> tuple:
    """``(axes, abc_deg)`` of a points file read by :func:`~nurbscnc.output.files.read_points`
    (``name`` its name in messages; :func:`~nurbscnc.output.files.rotary_of_points`), each
    rotary column checked against the machine ``mach``: ConfigError for an axis the machine
    does not have, PlanningError at the first point outside the axis's soft limits
    ``min_deg`` / ``max_deg``. The one check of the rotary columns of ``stream`` and
    ``simulate``."""
    import numpy as np

    from nurbscnc.output.files import ROTARY_COLUMNS, rotary_of_points

    axes, abc_deg = rotary_of_points(data)
    for letter in axes:
        axis = mach.rotary_axes.get(letter)
        if axis is None:
            raise ConfigError(
                f"{name}: a column {letter} but the machine has no {letter.upper()} axis "
                f"([axis_limits.{letter}])"
            )
        column = abc_deg[:, ROTARY_COLUMNS.index(letter)]
        out = (column < axis.min_deg) | (column > axis.max_deg)
        if out.any():
            k = int(np.flatnonzero(out)[0])
            raise PlanningError(
                f"{name}: point {k + 1}: {letter.upper()} {column[k]:.4f} deg is outside "
                f"its soft limits [{axis.min_deg:g}, {axis.max_deg:g}] deg"
            )
    return axes, abc_deg


def pulses_of_points(points_mm, mach, lines=None, axes: str = "xyz"):
    """The :class:`~nurbscnc.output.stream.quantise.PulseProgram` of reference points
    ``points_mm`` (N, len(``axes``)) [mm; deg for A B C] at the machine's steps per mm (and
    per degree: ConfigError for a rotary axis without them) and servo period (``lines``:
    their source lines), checked against the card's pulse limit per period and axis
    (before any port is touched)."""
    from nurbscnc.output.stream.axes import steps_per_unit
    from nurbscnc.output.stream.quantise import check_pulse_limit, quantise

    scale = steps_per_unit(mach, axes)
    pulses = quantise(points_mm, scale, mach.servo.period_s, lines, axes)
    check_pulse_limit(pulses, mach.steps.max_pulses_per_period)
    return pulses


def sample_points(samples):
    """``(points, axes)`` of planned samples: X Y Z [mm] and the rotary axes the program
    uses (``samples.rotary_axes``, from ``samples.abc_deg``) [deg] beside them."""
    import numpy as np

    from nurbscnc.output.stream.axes import stream_axes

    axes = stream_axes(samples.rotary_axes)
    points = np.asarray(samples.points_mm, dtype=float)
    if len(axes) == 3:
        return points, axes
    abc = samples.abc_deg
    if abc is None:
        raise PlanningError(f"the samples move {axes[3:].upper()} but carry no A B C column")
    cols = [np.asarray(abc, dtype=float)[:, "abc".index(a)] for a in axes[3:]]
    return np.column_stack([points, *cols]), axes


def pulses_of_samples(samples, mach):
    """:func:`pulses_of_points` of planned ``samples`` (:func:`sample_points`), each period
    with its source line."""
    points, axes = sample_points(samples)
    return pulses_of_points(points, mach, samples.line, axes)


def needs_whole_plan(options, prog=None) -> bool:
    """Whether a program is planned whole before it is streamed rather than cut window by
    cut window: a baseline ``algorithm`` has no look-ahead plan to cut, and the
    pre-compensated reference (ZPETC) is not causal: each of its samples depends on the
    planned reference ahead of it, to the program's end. A program ``prog`` that moves a
    rotary axis is planned whole too (:func:`program_turns_rotary`)."""
    from nurbscnc.plan.options import Algorithm

    return (
        options.algorithm != Algorithm.PH_LOOKAHEAD
        or options.precompensate
        or (prog is not None and program_turns_rotary(prog))
    )


def program_turns_rotary(prog) -> bool:
    """Whether the program turns a rotary axis (any segment that
    :func:`~nurbscnc.plan.rotary.moves_rotary`: a Rotate, or a move whose A B C change; one
    that only holds them where the card stands streams as an X Y Z program, the card's
    rotary axes standing still). Such a program is streamed planned whole
    (:func:`~nurbscnc.app.staged.staged_job`: section by section, waiting at its stops),
    its samples' A B C beside X Y Z: the controller's re-planning (a feed hold's stop along
    the path, an override above 100 %, run from line) follows the XYZ path length, which
    stands still during a rotary-only move, so a rotary program is not re-planned while it
    runs (a feed hold is the card's own HOLD: :mod:`~nurbscnc.controller.staged`)."""
    from nurbscnc.plan.rotary import moves_rotary

    return bool(prog.rotary_axes) and any(map(moves_rotary, prog.segments))


def is_still(segments) -> bool:
    """Whether ``segments`` make no motion: dwells and program stops only (a Rotate, though
    a stop of the path, turns the rotary axes)."""
    return all(s.kind in ("dwell", "pause") for s in segments)


def stream_job(
    prog,
    mach,
    options,
    from_line: int | None = None,
    optional_stop: bool = False,
    override: float = 1.0,
    tools: dict | None = None,
):
    """What streams the interpreted program ``prog`` (from ``from_line`` on:
    :func:`~nurbscnc.controller.stops.start_at_line`): ``(job, None)``, a
    :class:`~nurbscnc.controller.job.Job` planned cut window by cut window while the
    card runs; or, when :func:`needs_whole_plan`, ``(None, pulses)``: the pulses of the whole
    run (the points ``run`` writes with the same options). Everything that can be wrong
    with the input raises here, before any port is touched (the pulse limit too; for a job,
    the first window's errors). ``tools``: the tool table ``{number: Tool}``, named to the
    operator at a tool change. ``(None, None)``: the program has no motion (offsets, tool
    changes, dwells only): nothing to send."""
    from nurbscnc.controller.feed import WindowFeed
    from nurbscnc.controller.job import Job
    from nurbscnc.controller.stops import start_at_line
    from nurbscnc.pipeline import run_program, window_plans

    if program_turns_rotary(prog) and (from_line is not None or override != 1.0):
        raise ConfigError(
            f"--from-line and --feed-override: this program moves "
            f"{' '.join(a.upper() for a in prog.rotary_axes)}, and a program with rotary "
            "axes is streamed planned whole (no re-planning while it runs)"
        )
    if from_line is not None:
        try:
            prog = start_at_line(prog, from_line)
        except ValueError as exc:
            raise ConfigError(str(exc)) from None
    if is_still(prog.segments):  # stops at the first move
        return None, None
    if program_turns_rotary(prog):
        from nurbscnc.app.staged import staged_job

        return staged_job(prog, mach, options, optional_stop, tools), None
    if needs_whole_plan(options, prog):
        return None, pulses_of_samples(run_program(prog, mach, options).samples, mach)

    def pulse_limit(points_mm, lines) -> None:
        # The plan at 100 %: a lower override and a hold only slow down.
        pulses_of_points(points_mm, mach, lines)

    # Planned cut window by cut window on a thread while the card runs the first ones; the
    # first window is waited for here, so its errors come before the port.
    feed = WindowFeed(window_plans(prog, mach, options, each=pulse_limit))
    job = Job(
        None,
        prog,
        mach,
        optional_stop=optional_stop,
        override=override,
        lookahead_pieces=options.lookahead.lookahead_pieces,
        feed=feed,
        tools=tools,
    )
    return job, None


def position_mm(steps, mach) -> list[float]:
    """The card's position ``steps`` (per axis: X Y Z first, then its rotary axes) in mm,
    X Y Z in machine coordinates: steps over the profile's steps per mm (exact: the steps
    are what the card counts; rounded to 1 nm). The rotary axes: :func:`position_abc_deg`."""
    import numpy as np

    xyz = np.asarray(steps, dtype=float)[: len(mach.steps.per_mm)]
    return [round(v, 6) for v in (xyz / mach.steps.per_mm).tolist()]


def position_abc_deg(steps, mach, axes: str | None = None) -> dict:
    """The rotary axes of the card's position ``steps`` [deg]: ``{"a": 90.0}`` (empty for
    a card of X Y Z), steps over the profile's steps per degree; ``axes`` the position's
    axes ("xyza"; None: from the number of values and the profile,
    :func:`~nurbscnc.output.stream.axes.axes_of_position`)."""
    from nurbscnc.output.stream.axes import axes_of_position, position_units

    if axes is None:
        axes = axes_of_position(len(steps), mach)
    return position_units(steps, mach, axes)[1]


def start_abc(abc: dict) -> tuple[float, float, float]:
    """``(a, b, c)`` [deg] of a :func:`position_abc_deg` (0 for an axis the card lacks)."""
    return tuple(float(abc.get(a, 0.0)) for a in "abc")


def stream_report(program: str, job, reports: list, mach=None, parameters=None) -> dict:
    """The JSON report of a finished stream: the last part's card state
    (:meth:`~nurbscnc.output.stream.sender.StreamReport.to_json`), the counters summed over
    the ``reports`` of every part, and the ``job``'s own report (sections, holds, planning,
    notes; one section without a job), the final position in mm (``mach``: the machine's
    steps per mm), and with the ``parameters`` at the program's end (a parameter file is
    known) the active system and the final work position
    (:func:`~nurbscnc.app.varfile.work_report`). ``program`` is named as every command
    names it (standard input is ``<stdin>``)."""
    extra = job.report() if job is not None else {"sections": 1}
    body = {
        **reports[-1].to_json(),
        "executed_periods": sum(r.executed_periods for r in reports),
        "frames_sent": sum(r.frames_sent for r in reports),
        "bytes_sent": sum(r.bytes_sent for r in reports),
        "retransmits": sum(r.retransmits for r in reports),
        # over every part: lost copies of acknowledged frames / all their copies
        "frame_error_rate": _frame_error_rate(reports),
        "duration_s": sum(r.duration_s for r in reports),
        **_noted(extra, reports),
    }
    if mach is not None:
        final = reports[-1].final_position_steps
        body["final_position_mm"] = position_mm(final, mach)
        abc = position_abc_deg(final, mach, getattr(reports[-1], "axes", None))
        if abc:
            body["final_abc_deg"] = abc
        if parameters is not None:
            from nurbscnc.app.varfile import work_report

            work = work_report(parameters, body["final_position_mm"])
            body["coordinate_system"] = work["coordinate_system"]
            body["final_work_position_mm"] = work["work_position_mm"]
    return {"ok": True, "program": "<stdin>" if program == "-" else program, **body}


def work_text(report: dict) -> str:
    """``"; x, y, z mm in G54"``: the final work position of a :func:`stream_report` (empty
    without one)."""
    work = report.get("final_work_position_mm")
    if not work:
        return ""
    return "; " + ", ".join(f"{v:.4f}" for v in work) + f" mm in {report['coordinate_system']}"


def progress_position(mach, inputs=None, program=None):
    """``where(steps) -> text`` for the progress line: the card's position in mm (machine)
    and, when a parameter file is known (``inputs``:
    :class:`~nurbscnc.app.varfile.ProgramInputs`) and the interpreted ``program`` leaves its
    offsets as they were (its ``parameters`` at the end agree with the file's on every
    coordinate parameter; a program that sets G10/G92 midway would show the wrong system
    for part of the run), the work position in the active system."""
    from nurbscnc.app.varfile import work_report
    from nurbscnc.program.coords import is_coordinate_parameter

    known = inputs is not None and inputs.var_path and program is not None
    start_parameters = inputs.parameters if known else None
    end_parameters = program.parameters if known else None
    same = start_parameters is not None and end_parameters is not None
    if same:
        keys = {k for k in (*start_parameters, *end_parameters) if is_coordinate_parameter(k)}
        same = all(
            float(start_parameters.get(k, 0.0)) == float(end_parameters.get(k, 0.0)) for k in keys
        )

    def where(steps, axes: str | None = None) -> str:
        try:
            abc = position_abc_deg(steps, mach, axes)
        except NurbsCncError:
            return ""
        mm = position_mm(steps, mach)
        text = ", ".join(f"{v:.3f}" for v in mm) + " mm"
        text += "".join(f", {a.upper()} {v:.3f}°" for a, v in abc.items())
        if same:
            work = work_report(start_parameters, mm)
            shown = ", ".join(f"{v:.3f}" for v in work["work_position_mm"])
            text += f" ({work['coordinate_system']} {shown})"
        return text

    return where


def _frame_error_rate(reports: list) -> float:
    """The measured frame error rate of all the parts, weighted by their frames sent."""
    frames = sum(r.frames_sent for r in reports)
    if not frames:
        return 0.0
    return sum(r.frame_error_rate * r.frames_sent for r in reports) / frames


def _noted(extra: dict, reports: list) -> dict:
    """``extra`` (the job's report) with a note on a noisy line, when frames were lost."""
    rate = _frame_error_rate(reports)
    if not rate:
        return extra
    note = (
        f"noisy line: {rate:.1%} of the frames' copies lost or damaged; "
        f"{reports[-1].batch_periods} periods per frame at the end"
    )
    return {**extra, "notes": [*extra.get("notes", []), {"line": None, "message": note}]}


class ProgramStream:
    """A program checked for ``stream`` before any port is opened: the machine ``mach``, the
    run ``options``, the parameter file and user M-code folders ``inputs``
    (:class:`~nurbscnc.app.varfile.ProgramInputs`; the stream writes the file back, so a
    missing one is all zeros), the tool table ``tools``, the program's ``text`` (read by the first
    :meth:`interpret`), and
    ``program``: the program interpreted from machine zero — every error of the text, the
    parameter file, the tool table or a subroutine raises before the card is asked where it
    stands; a GeometryError (an arc's radii, which depend on where the program starts) is
    kept in ``error`` (``program`` None) and decided from the card's position."""

    def __init__(self, path: str, mach, settings: dict) -> None:
        from nurbscnc.app.load import read_tool_table
        from nurbscnc.app.settings import run_options_of
        from nurbscnc.app.varfile import program_inputs

        self.path, self.mach, self.settings = path, mach, settings
        self.options = run_options_of(settings)
        self.inputs = program_inputs(
            mach, settings.get("var"), settings.get("user_m_path", ()), writes=True
        )
        table = settings.get("tool_table")
        self.tools = read_tool_table(table) if table else None
        self.text = None
        self.error = None
        try:
            self.program = self.interpret(None)
        except GeometryError as exc:
            # An arc's radius check depends on where its first move starts (G2 X6 Y1 R2.5
            # is fine from a card 4 mm away, not from machine zero): decided from the card's
            # position, still before anything moves.
            self.program, self.error = None, exc

    def interpret(self, start_mm, start_abc_deg=None):
        """The program interpreted from ``start_mm`` [mm, machine; None: machine zero] and
        A B C = ``start_abc_deg`` [deg; None: 0]."""
        from nurbscnc.app.load import load_program, read_program_text

        if self.text is None:  # read once: a second interpretation starts elsewhere
            self.text = read_program_text(self.path)
        s = self.settings
        return load_program(
            self.path,
            not s.get("no_block_delete", False),
            s.get("tool_table"),
            s.get("subroutine_path", ()),
            text=self.text,
            inputs=self.inputs,
            start_mm=start_mm,
            start_abc_deg=start_abc_deg,
        )

    def still(self) -> bool:
        """Does the program make no motion (offsets, tool changes, dwells only)? Then
        nothing is sent and the card is not asked where it stands."""
        prog = self.program
        return prog is not None and is_still(prog.segments)

    def plan(self, position_steps=None, from_line=None, optional_stop=False, override=1.0):
        """``(job, pulses, program)`` (:func:`stream_job`) of the program started where the
        card stands, ``position_steps`` [steps; machine mm = steps / steps per mm, as
        ``mdi``]: its first move goes from there (a relative program runs relative to it, an
        absolute one to its work positions; ``from_line``'s approach starts there too).
        None: from the program's start at machine zero (``stream --zero`` declares the card
        there). Every error of the plan raises here, before anything is sent."""
        prog = self.program
        if position_steps is not None:
            # X Y Z [mm] and the card's rotary axes [deg] (ConfigError: the card's axes do
            # not agree with the profile's)
            abc = start_abc(position_abc_deg(position_steps, self.mach))
            start_mm = position_mm(position_steps, self.mach)
            if any(start_mm) or any(abc) or prog is None:  # from zero: interpreted already
                prog = self.interpret(start_mm, abc)
        elif prog is None:
            raise self.error
        job, pulses = stream_job(
            prog, self.mach, self.options, from_line, optional_stop, override, self.tools
        )
        return job, pulses, prog
