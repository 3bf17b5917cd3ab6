"""The pre-compensation stage (``--precompensate``): the ZPETC inverse of
:mod:`nurbscnc.servo.precompensate` applied to a plan's reference (:mod:`.apply`), the
compensated reference projected onto the machine's limits on its samples (:mod:`.limits`)
and optimised in the tube about the path (:mod:`.tube`, on the path frames of
:mod:`.frame`), and its report (:mod:`.report`)."""

from nurbscnc.precompensation.apply import (
    Refined,
    precompensate_reference,
    precompensated_sampler,
    reference_tube_mm,
)
from nurbscnc.precompensation.limits import (
    SampleLimits,
    limit_excess,
    path_frame,
    project_onto_limits,
    sample_limits,
)
from nurbscnc.precompensation.report import (
    SENSITIVITY_CASES,
    Precompensation,
    precompensation_report,
)
from nurbscnc.precompensation.tube import Refinement, refine_in_tube

__all__ = [
    "SENSITIVITY_CASES",
    "Precompensation",
    "Refined",
    "Refinement",
    "SampleLimits",
    "limit_excess",
    "path_frame",
    "precompensate_reference",
    "precompensated_sampler",
    "precompensation_report",
    "project_onto_limits",
    "reference_tube_mm",
    "refine_in_tube",
    "sample_limits",
]
