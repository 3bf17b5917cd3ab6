"""The servo simulation of a reference: the reference points of a point file or of a planned
run and the path they should follow, simulated on the machine's servo model."""

from __future__ import annotations


def is_points_source(source: str, text: str | None) -> bool:
    """Whether ``simulate SOURCE`` reads reference points (a .csv/.npz file, or standard
    input ``text`` that starts with a points header, as ``run -o -`` writes) rather than a
    program."""
    from nurbscnc.output.files import point_header

    return source.lower().endswith((".csv", ".npz")) or (
        text is not None and bool(point_header(text))
    )


def points_reference(source: str, text: str | None):
    """``(points, path)`` [mm] of a reference-point file (or of standard input's ``text``):
    the commanded path is the reference polyline itself."""
    import numpy as np

    from nurbscnc.output.files import read_points, read_points_text

    data = read_points(source) if text is None else read_points_text(text)
    points = np.column_stack([data["x"], data["y"], data["z"]])
    return points, points


def run_reference(run):
    """``(points, path)`` [mm] of a planned run: its reference points, and the planned path
    densely sampled (:func:`~nurbscnc.plan.dynamics.dense_path_mm`; a baseline's points are
    its own path)."""
    from nurbscnc.geometry.polyline import dense_path_mm

    points = run.samples.points_mm
    path = points if run.plan is None else dense_path_mm(run.plan.pieces, run.plan.profile)
    return points, path


def simulate_points(points, path, mach, hold: str):
    """``(simulation, contour errors, metrics dict)`` of the reference ``points`` on the
    machine's servo model, ``hold`` between samples (foh or zoh), the contour errors (SPEC
    eq. 29 and the true distance) measured from ``path``."""
    from nurbscnc.servo.simulate import contour_errors, metrics, simulate_reference

    sim = simulate_reference(points, mach, hold=hold)
    contour = contour_errors(sim, path)
    return sim, contour, metrics(sim, path, contour).as_dict()
