"""The paper's comparison (SPEC §9, Tables 4 and 5): algorithms side by side on one NURBS block.

For a NURBS block of a program (the first by default), optionally rotated about the origin,
each algorithm produces reference points from rest at the block's start to its end; the
independent servo simulation (:mod:`nurbscnc.servo.simulate`) then gives the axis errors, the
contour error (eq. 29 and the true distance to the programmed curve) and the cycle time.

Algorithms:

- ``adaptive``: feed min(F, V_af(κ)), Taylor interpolation, no acceleration limit (Yeh & Hsu);
- ``curvature``: feed V_cf(κ), Taylor interpolation, no acceleration limit (Zhiming);
- ``ph-lookahead``: the paper's method as the paper runs it — PH corners, each corner region
  at V_sp of its peak, jerk-limited look-ahead, Taylor interpolation of NURBS pieces, and the
  global dynamics rule (V_max lowered for the whole block until ε ≤ ε_max);
- ``ours``: our best configuration — PH corners capped piece by piece, exact interpolation
  everywhere, local dynamics (only the offending pieces slowed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from nurbscnc.errors import PlanningError
from nurbscnc.geometry.nurbs import NurbsCurve
from nurbscnc.geometry.segments import Program, frozen_array
from nurbscnc.interpolate.baselines import baseline_samples
from nurbscnc.interpolate.sample import Interpolator, reference_sampler, samples_of
from nurbscnc.machine.profile import Machine
from nurbscnc.plan.lookahead import plan_checked
from nurbscnc.plan.options import CornerFeed, Dynamics, LookaheadOptions, PlanOptions
from nurbscnc.plan.timing import Samples
from nurbscnc.servo.simulate import contour_errors, metrics, simulate_reference

ALGORITHMS = ("adaptive", "curvature", "ph-lookahead", "ours")

#: The paper's Table 4 (airfoil at 0°, µm and s), for side-by-side reports.
PAPER_TABLE4 = {
    "adaptive": {
        "axis_x_max_um": 358.69,
        "axis_x_rms_um": 75.65,
        "axis_y_max_um": 132.56,
        "axis_y_rms_um": 27.31,
        "contour_max_um": 142.79,
        "contour_rms_um": 35.14,
        "contour_mean_um": 16.78,
        "cycle_time_s": 0.3440,
    },
    "curvature": {
        "axis_x_max_um": 195.78,
        "axis_x_rms_um": 41.53,
        "axis_y_max_um": 22.65,
        "axis_y_rms_um": 8.39,
        "contour_max_um": 47.02,
        "contour_rms_um": 12.98,
        "contour_mean_um": 8.50,
        "cycle_time_s": 0.4535,
    },
    "ph-lookahead": {
        "axis_x_max_um": 57.97,
        "axis_x_rms_um": 20.30,
        "axis_y_max_um": 13.98,
        "axis_y_rms_um": 3.56,
        "contour_max_um": 14.11,
        "contour_rms_um": 3.84,
        "contour_mean_um": 2.31,
        "cycle_time_s": 0.9455,
    },
}
#: The paper's Table 5: PH look-ahead contour error max [µm] by orientation.
PAPER_TABLE5 = {0.0: 14.11, 45.0: 14.12, -45.0: 14.12}


@dataclass(frozen=True, eq=False)
class Run:
    """One algorithm on one block: its reference samples, the commanded curve (dense) and
    the simulated metrics (a dict of floats, µm and s)."""

    algorithm: str
    angle_deg: float
    samples: Samples
    path_mm: np.ndarray
    metrics: dict
    contour_true_um: np.ndarray
    contour_eq29_um: np.ndarray
    sim_t_s: np.ndarray
    axis_error_um: np.ndarray
    plan: object | None = None


def nurbs_block(program: Program, block: int = 1):
    """The ``block``-th NURBS segment (1-based) of a program."""
    nurbs = [s for s in program.segments if s.kind == "nurbs"]
    if not nurbs:
        raise PlanningError("compare needs a program with a NURBS block (G5.2 or G6.2)")
    if not 1 <= block <= len(nurbs):
        raise PlanningError(f"--block {block}: the program has {len(nurbs)} NURBS block(s)")
    return nurbs[block - 1]


def rotate_segment(seg, angle_deg: float):
    """The NURBS segment rotated by ``angle_deg`` about the Z axis through the origin."""
    if angle_deg == 0.0:
        return seg
    a = math.radians(angle_deg)
    rot = np.array(
        [[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]]
    )
    return replace(seg, control_points_mm=frozen_array(seg.control_points_mm @ rot.T))


def dense_curve_mm(seg, spacing_mm: float = 0.0005) -> np.ndarray:
    """The programmed curve as a dense polyline [mm] (chord error ≪ 1e-3 µm)."""
    curve = NurbsCurve.from_segment(seg)
    n = max(int(math.ceil(curve.length_mm / spacing_mm)), 64)
    return curve.points_at_length(np.linspace(0.0, curve.length_mm, n + 1))[0]


def _planned(seg, machine: Machine, options: tuple[LookaheadOptions, Interpolator]):
    prog = Program(segments=(seg,), start_mm=seg.start_mm, name="block")
    lookahead, interpolator = options
    plan, check = plan_checked(prog, machine, lookahead, reference_sampler(interpolator))
    return samples_of(check.reference, plan.pieces, interpolator), plan


def algorithm_options(algorithm: str) -> tuple[LookaheadOptions, Interpolator]:
    """The planner and interpolator settings of the two look-ahead algorithms."""
    if algorithm == "ph-lookahead":
        return (
            LookaheadOptions(
                dynamics=Dynamics.GLOBAL, plan=PlanOptions(corner_feed=CornerFeed.PEAK)
            ),
            Interpolator.TAYLOR,
        )
    if algorithm == "ours":
        return (
            LookaheadOptions(
                dynamics=Dynamics.LOCAL, plan=PlanOptions(corner_feed=CornerFeed.PIECE)
            ),
            Interpolator.EXACT,
        )
    raise ValueError(algorithm)


def run_algorithm(algorithm: str, seg, machine: Machine, angle_deg: float = 0.0) -> Run:
    """Reference points of one algorithm on one block, simulated (SPEC §8, §9)."""
    plan = None
    if algorithm in ("adaptive", "curvature"):
        samples = baseline_samples(algorithm, seg, machine)
    else:
        samples, plan = _planned(seg, machine, algorithm_options(algorithm))
    path = dense_curve_mm(seg)
    sim = simulate_reference(samples.points_mm, machine)
    contour = contour_errors(sim, path)
    m = metrics(sim, path, contour).as_dict()
    m["cycle_time_s"] = float(samples.t_s[-1])  # rest to rest, one block
    return Run(
        algorithm,
        angle_deg,
        samples,
        path,
        m,
        contour.true_mm * 1000.0,
        contour.eq29_mm * 1000.0,
        sim.t_s,
        sim.axis_error_mm * 1000.0,
        plan,
    )


def compare_block(seg, machine: Machine, angles_deg=(0.0,), algorithms=ALGORITHMS) -> list[Run]:
    """Every algorithm at every orientation (Table 4 for one angle, Table 5 for several)."""
    runs = []
    for angle in angles_deg:
        rotated = rotate_segment(seg, angle)
        for algorithm in algorithms:
            runs.append(run_algorithm(algorithm, rotated, machine, angle))
    return runs


#: The columns of the paper's Table 4 as the ``compare`` rows name them, in its order [µm]:
#: axis errors (max, RMS) per axis, the eq. 29 contour error (max, RMS, mean), then ours,
#: the true distance to the curve.
TABLE4_COLUMNS = (
    "axis_x_max_um",
    "axis_x_rms_um",
    "axis_y_max_um",
    "axis_y_rms_um",
    "contour_eq29_max_um",
    "contour_eq29_rms_um",
    "contour_eq29_mean_um",
    "contour_true_max_um",
)


def row(run: Run) -> dict:
    """The JSON row of a run (``compare --json``)."""
    from nurbscnc.plan.report import metrics_json

    m = metrics_json(run.metrics)
    keys = (
        "contour_eq29_max_um",
        "contour_eq29_rms_um",
        "contour_eq29_mean_um",
        "contour_true_max_um",
        "contour_true_rms_um",
        "axis_x_max_um",
        "axis_x_rms_um",
        "axis_y_max_um",
        "axis_y_rms_um",
        "cycle_time_s",
    )
    return {"algorithm": run.algorithm, "angle_deg": run.angle_deg, **{k: m[k] for k in keys}}
