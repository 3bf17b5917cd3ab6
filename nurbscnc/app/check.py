"""Checking a program without planning it: read, interpret, validate against the machine
(soft limits, a lower bound of the motion time within ``limits.max_points``), summarise."""

from __future__ import annotations

from nurbscnc.app.load import load_program
from nurbscnc.app.varfile import program_inputs


def check_program(
    program: str,
    mach,
    block_delete: bool = True,
    tool_table=None,
    subroutine_path=(),
    per_segment: bool = False,
    progress=None,
    var=None,
    user_m_path=(),
):
    """``(program, summary)`` of the program file ``program`` checked for the machine
    ``mach`` (:func:`~nurbscnc.plan.limits.check_before_work`; PlanningError when it fails);
    the summary is :func:`~nurbscnc.plan.report.program_summary`'s, with every segment when
    ``per_segment``, and ``var_file``: the parameter file read (None: none).
    ``progress``: None or a callback named with each stage; ``var``, ``user_m_path``: the
    parameter file and user M-code folders (:func:`~nurbscnc.app.varfile.program_inputs`;
    the file is read, never written)."""
    from nurbscnc.plan.limits import check_before_work
    from nurbscnc.plan.report import program_summary
    from nurbscnc.program.columns import segment_columns

    say = progress or (lambda _stage: None)
    say("reading and interpreting")
    inputs = program_inputs(mach, var, user_m_path)
    prog = load_program(program, block_delete, tool_table, subroutine_path, inputs=inputs)
    say(f"checking {len(prog.segments)} segments")
    # Read once for the checks and the summary.
    columns = segment_columns(prog.segments, prog.start_abc_deg)
    check_before_work(prog.segments, mach, columns, prog.frames)
    summary = program_summary(prog, columns, per_segment=per_segment)
    return prog, {**summary, "var_file": inputs.var_path}
