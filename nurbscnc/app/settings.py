"""The option values of the commands that plan, turned into validated option objects.

The CLI's :func:`~nurbscnc.cli.options.planning_options` declares the options; here their
values become a :class:`~nurbscnc.pipeline.RunOptions`. ``plan``, ``run``, ``simulate`` and
``stream`` build theirs with the one function :func:`run_options_of`.
"""

from __future__ import annotations

#: The keyword names of the planning options (besides machine, overrides, and the
#: program-input options no_block_delete, tool_table, subroutine_path).
PLANNING_KEYS = (
    "algorithm",
    "corner_feed",
    "dynamics",
    "blend_tolerance",
    "interpolator",
    "lookahead",
    "precompensate",
    "reference_tolerance",
    "smooth",
)
#: The keyword names of the program-input options.
PROGRAM_INPUT_KEYS = ("no_block_delete", "tool_table", "subroutine_path", "var", "user_m_path")


def run_options(
    algorithm="ph-lookahead",
    corner_feed="piece",
    dynamics="local",
    blend_tolerance=None,
    interpolator="exact",
    lookahead=None,
    precompensate=False,
    reference_tolerance=3.0,
    smooth=False,
):
    """The validated :class:`~nurbscnc.pipeline.RunOptions` of the values of the planning
    options (ConfigError on a bad value); ``blend_tolerance`` [mm], ``reference_tolerance``
    [µm]."""
    from nurbscnc.pipeline import RunOptions  # the planner's imports, only when planning
    from nurbscnc.plan.options import LookaheadOptions, PlanOptions

    plan = PlanOptions(
        corner_feed=corner_feed, blend_tolerance_mm=blend_tolerance, smooth=bool(smooth)
    )
    return RunOptions(
        algorithm=algorithm,
        interpolator=interpolator,
        lookahead=LookaheadOptions(dynamics=dynamics, lookahead_pieces=lookahead, plan=plan),
        precompensate=bool(precompensate),
        reference_tolerance_mm=float(reference_tolerance) * 1e-3,
    )


def run_options_of(settings: dict):
    """:func:`run_options` of the planning options among a command's keyword ``settings``
    (those of :data:`PLANNING_KEYS` it has; the others at their defaults)."""
    return run_options(**{k: settings[k] for k in PLANNING_KEYS if k in settings})
