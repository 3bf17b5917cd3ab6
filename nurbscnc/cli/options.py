"""Command-line options shared by every command that plans: one decorator.

:func:`planning_options` declares the planning options (algorithm, corner feed, dynamics,
blend tolerance, interpolator, look-ahead, pre-compensation) and the machine options
(``--machine``, ``--set``); :func:`~nurbscnc.app.settings.run_options_of` turns their values
into the validated :class:`~nurbscnc.pipeline.RunOptions`. ``plan``, ``run``, ``simulate``
and ``stream`` use the same set.
"""

from __future__ import annotations

import click

from nurbscnc.plan.options import (
    Algorithm,
    CornerFeed,
    Dynamics,
    Interpolator,
)


def _choices(enum_cls) -> click.Choice:
    return click.Choice([m.value for m in enum_cls])


def machine_options(func):
    """``--machine FILE`` and repeatable ``--set KEY=VALUE`` (dotted profile keys)."""
    func = click.option(
        "--set",
        "overrides",
        multiple=True,
        metavar="KEY=VALUE",
        help="Override one profile value, e.g. --set limits.a_max_mm_s2=1000.",
    )(func)
    func = click.option(
        "--machine",
        type=click.Path(),
        default=None,
        help="Machine profile (TOML). Default: $NURBSCNC_MACHINE, ./nurbscnc.toml, "
        "~/.config/nurbscnc/machine.toml, else the bundled paper machine (Tables 2, 3).",
    )(func)
    return func


block_delete_option = click.option(
    "--no-block-delete",
    "no_block_delete",
    is_flag=True,
    help="Execute lines starting with '/' (default: skip them, the switch is on).",
)
tool_table_option = click.option(
    "--tool-table",
    type=click.Path(),
    default=None,
    help="LinuxCNC tool table: lengths for G43 H, diameters for G41/G42 D (default: none).",
)
subroutine_path_option = click.option(
    "--subroutine-path",
    multiple=True,
    type=click.Path(file_okay=False),
    help="Directory searched for o<name> call files name.ngc after the program's own (repeatable).",
)

var_option = click.option(
    "--var",
    type=click.Path(dir_okay=False),
    default=None,
    metavar="FILE",
    help="LinuxCNC parameter file (rs274ngc.var): work offsets G54-G59.3, G92, G28/G30 "
    "positions, read before the program (default: $NURBSCNC_VAR, else the profile's "
    "program.var_file; none: no offsets). stream and run --write-var write it back.",
)
user_m_timeout_option = click.option(
    "--user-m-timeout",
    "user_m_timeout_s",
    type=click.FloatRange(min=0.0, min_open=True),
    default=None,
    metavar="SECONDS",
    help="Longest a user M-code's executable (M100-M199) may run; then it is killed and "
    "the stream stops (exit 3). Default: the profile's program.user_m_timeout_s, else 60.",
)
user_m_path_option = click.option(
    "--user-m-path",
    multiple=True,
    type=click.Path(file_okay=False),
    metavar="DIR[:DIR...]",
    help="Folders searched for user M-code executables M100-M199 (LinuxCNC's USER_M_PATH; "
    "repeatable), before the profile's program.user_m_path.",
)


def program_input_options(func):
    """How a program file is read: block delete, the tool table, the subroutine path, the
    parameter file and the user M-code path."""
    for option in (
        user_m_path_option,
        var_option,
        subroutine_path_option,
        tool_table_option,
        block_delete_option,
    ):
        func = option(func)
    return func


def planning_options(func):
    """The planning options of every command that plans, and the machine options."""
    func = click.option(
        "--algorithm",
        type=_choices(Algorithm),
        default=Algorithm.PH_LOOKAHEAD.value,
        help="The look-ahead planner (default), or one of the paper's baselines: adaptive "
        "(chord-error) feed or curvature feed, Taylor interpolation, no acceleration "
        "limit (SPEC §9).",
    )(func)
    func = click.option(
        "--corner-feed",
        type=_choices(CornerFeed),
        default=CornerFeed.PIECE.value,
        help="PH pieces capped by their own peak curvature (piece, default) or the whole "
        "region by the corner's peak (peak, as the paper).",
    )(func)
    func = click.option(
        "--dynamics",
        type=_choices(Dynamics),
        default=Dynamics.LOCAL.value,
        help="Contour-error check: lower the feed on offending pieces (local, default), for "
        "the whole program (global, the paper's rule), or not at all (off).",
    )(func)
    func = click.option(
        "--blend-tolerance",
        type=click.FloatRange(min=0.0),
        default=None,
        metavar="MM",
        help="Blend every corner by PH quintics within this distance [mm] (overrides the "
        "program's G61/G61.1/G64 P; 0: stop exactly at every corner).",
    )(func)
    func = click.option(
        "--smooth/--no-smooth",
        default=True,
        help="Dense CAM polylines (runs of short G1 moves under G64) become curvature-"
        "continuous cubic B-splines within half the path tolerance (G64 P, else the "
        "machine's), so the jerk limit no longer holds the feed down at every vertex "
        "(default; G61/G61.1 stay exact). --no-smooth: plan every move as written.",
    )(func)
    func = click.option(
        "--interpolator",
        type=_choices(Interpolator),
        default=Interpolator.EXACT.value,
        help="NURBS pieces by exact arc-length inversion (default) or the paper's 2nd-order "
        "Taylor formula.",
    )(func)
    func = click.option(
        "--lookahead",
        type=click.IntRange(min=1),
        default=None,
        help="Look-ahead depth in pieces (default: the whole program).",
    )(func)
    func = click.option(
        "--precompensate",
        is_flag=True,
        default=False,
        help="Feed the servo a pre-compensated reference (zero-phase-error tracking inverse "
        "of the profile's servo model) so the modelled tool follows the planned path; "
        "the summary gives the reference's own deviation from the path and the contour "
        "error under a ±10 % model error. Needs a servo model.",
    )(func)
    func = click.option(
        "--reference-tolerance",
        type=click.FloatRange(min=0.0),
        default=3.0,
        metavar="UM",
        help="With --precompensate: keep the reference within this distance of the path [µm] "
        "(default 3; inf: no limit); the dynamics check slows down where the tool then "
        "misses ε_max.",
    )(func)
    return program_input_options(machine_options(func))


#: ``--timeout`` of the commands that talk to the card (stream, mdi, jog).
link_timeout_option = click.option(
    "--timeout",
    "timeout_s",
    type=click.FloatRange(min=0.0, min_open=True),
    default=2.0,
    show_default=True,
    help="Seconds without an answer from the card before giving up.",
)


#: ``stream --stall-limit``: the user's own limit on a live line that acknowledges nothing.
stall_limit_option = click.option(
    "--stall-limit",
    "stall_limit_s",
    type=click.FloatRange(min=0.0, min_open=True),
    default=None,
    metavar="SECONDS",
    help="Give up when the card answers but acknowledges no frame for this long (default: "
    "a time that grows with the line's measured error rate, from --timeout up to 30 times it).",
)
