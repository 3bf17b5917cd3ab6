"""Planning one program file from a command's option values: load, interpret, plan,
interpolate (:func:`~nurbscnc.pipeline.run_program`)."""

from __future__ import annotations

from nurbscnc.app.load import load_machine, load_program, override_table
from nurbscnc.app.runtime import frozen_objects
from nurbscnc.app.settings import run_options
from nurbscnc.app.varfile import program_inputs


def make_plan(
    program: str,
    machine=None,
    overrides=(),
    dynamics="local",
    lookahead=None,
    corner_feed="piece",
    interpolator="exact",
    blend_tolerance=None,
    algorithm="ph-lookahead",
    no_block_delete=False,
    tool_table=None,
    subroutine_path=(),
    text=None,
    precompensate=False,
    reference_tolerance=3.0,
    progress=None,
    keep_reference=False,
    smooth=False,
    announce=None,
    var=None,
    user_m_path=(),
    write_var=False,
):
    """Load, interpret, plan and interpolate one program; validate soft limits. Returns
    (program, machine, :class:`~nurbscnc.pipeline.Run`).

    The keyword arguments are the values of the CLI's planning options, ``text``: the
    program already read (see :func:`~nurbscnc.app.load.load_program`), and ``progress``:
    None or a callback named with each stage; ``keep_reference``: the dynamics check keeps
    its whole reference and response (the contour plot needs them; memory grows with the
    motion time, so only when plots are asked for); ``announce``: None or a callback given
    the machine and its overrides once the profile is loaded (the CLI says which profile it
    used); ``var``, ``user_m_path``: the parameter file and the user M-code folders
    (:func:`~nurbscnc.app.varfile.program_inputs`; ``write_var``: the caller writes the file
    back, so a missing one is all zeros). The program's ``parameters`` are what it writes."""
    from dataclasses import replace

    from nurbscnc.pipeline import run_program

    options = run_options(
        algorithm,
        corner_feed,
        dynamics,
        blend_tolerance,
        interpolator,
        lookahead,
        precompensate,
        reference_tolerance,
        smooth,
    )
    options = replace(options, keep_reference=keep_reference)
    if progress:
        progress("loading the machine profile")
    table = override_table(overrides)
    mach = load_machine(machine, table)
    if announce is not None:
        announce(mach, table)
    if progress:
        progress("reading and interpreting")
    inputs = program_inputs(mach, var, user_m_path, writes=write_var)
    prog = load_program(
        program, not no_block_delete, tool_table, subroutine_path, text, inputs=inputs
    )
    with frozen_objects():
        return prog, mach, run_program(prog, mach, options, progress)
