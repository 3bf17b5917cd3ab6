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


def points_reference(source: str, text: str | None, mach):
    """``(points, path, rotary)`` of a reference-point file (or of standard input's
    ``text``): the points [mm], the commanded path (the reference polyline itself) and the
    file's rotary axes with their positions, ``(axes, abc_deg (N, 3) [deg] or None)``,
    checked against the machine ``mach`` as ``stream`` checks them
    (:func:`~nurbscnc.app.stream.rotary_of_points_checked`)."""
    import numpy as np

    from nurbscnc.app.stream import rotary_of_points_checked
    from nurbscnc.output.files import read_points, read_points_text

    data = read_points(source) if text is None else read_points_text(text)
    points = np.column_stack([data["x"], data["y"], data["z"]])
    name = "<stdin>" if text is not None else source
    return points, points, rotary_of_points_checked(name, data, mach)


def run_reference(run):
    """``(points, path)`` [mm] of a planned run: its reference points, and the planned path
    densely sampled (:func:`~nurbscnc.plan.dynamics.dense_path_mm`; a baseline's points are
    its own path). Its rotary axes: :func:`run_rotary`."""
    from nurbscnc.geometry.polyline import dense_path_mm

    points = run.samples.points_mm
    path = points if run.plan is None else dense_path_mm(run.plan.pieces, run.plan.profile)
    return points, path


def run_rotary(samples) -> tuple:
    """``(axes, abc_deg)`` of :class:`~nurbscnc.plan.timing.Samples`: the rotary axes the
    program uses and the samples' A B C (N, 3) [deg]; ``((), None)`` without rotary axes."""
    axes = tuple(samples.rotary_axes)
    return (axes, samples.abc_deg) if axes else ((), None)


def rotary_summary(rotary) -> dict:
    """The ``rotary`` object of a simulated reference (docs/json.md, ``simulate``) as a
    summary: the axes of ``rotary`` (``(axes, abc_deg)``) and the last sample's A B C; an
    empty dict without rotary axes. The servo simulation is of X Y Z only (the rotary axes
    are not simulated)."""
    from nurbscnc.app.summary import with_rotary

    axes, abc_deg = rotary
    if not axes:
        return {}
    return with_rotary({}, axes, abc_deg[-1])


def simulate_points(points, path, mach, hold: str):
    """``(simulation, contour errors, metrics dict)`` of the reference ``points`` on the
    machine's servo model, ``hold`` between samples (foh or zoh), the contour errors (SPEC
    eq. 29 and the true distance) measured from ``path``."""
    from nurbscnc.servo.simulate import contour_errors, metrics, simulate_reference

    sim = simulate_reference(points, mach, hold=hold)
    contour = contour_errors(sim, path)
    return sim, contour, metrics(sim, path, contour).as_dict()


def run_contour(run, sim, contour, mach):
    """``(contour, feed)`` of a planned ``run`` simulated as ``sim``: the true contour error
    measured as the dynamics check measures it (:func:`~nurbscnc.plan.dynamics.window_response`
    on the simulated positions: the distance to the path near each reference point, to the
    whole path above ε_max), and ``feed`` (M,) bool, the samples the contour guarantee covers
    (:mod:`nurbscnc.plan.scope`; the held tail counts with the last piece), the first moving
    samples of a cut after a rapid measured against the cut only. So ``simulate`` reports
    the plan summary's number, from its own simulation. ``contour`` unchanged and ``feed``
    None when every sample counts: a baseline, or a reference no plan placed."""
    from dataclasses import replace

    import numpy as np

    from nurbscnc.plan.dynamics import PathIndex, window_response
    from nurbscnc.plan.scope import after_rapid_rows, feed_samples

    smp = run.samples
    if run.plan is None or smp.tau_s is None or run.precompensation is not None:
        return contour, None
    pieces, profile, n = run.plan.pieces, run.plan.profile, smp.t_s.size
    m = sim.actual_mm.shape[0]
    held = np.arange(m).clip(max=n - 1)  # the reference held at its end over the tail
    direction = np.zeros((m, 2))
    direction[:n] = np.gradient(smp.points_mm[:, :2], axis=0) if n > 1 else 0.0
    index = PathIndex(pieces)
    response = window_response(
        smp.points_mm[held],
        smp.s_mm[held],
        sim.actual_mm,
        direction,
        pieces,
        profile,
        refine_above_mm=mach.limits.contour_tolerance_mm,
        index=index,
    )
    rapid = np.asarray(pieces.rapid)
    feed = feed_samples(smp, response, profile, rapid, after_rapid_rows(rapid), index)
    feed = np.append(feed, np.full(m - n, not rapid[-1]))
    return replace(contour, true_mm=response.contour_mm), feed


def scoped_metrics(m: dict, contour, feed) -> dict:
    """The metrics dict ``m`` (:meth:`~nurbscnc.servo.simulate.Metrics.as_dict`) with the
    contour error over the feed samples only (``feed`` (M,) bool; None: all samples are
    feed samples) and the rapids' own beside it: ``rapids_true_max_um``,
    ``rapids_eq29_max_um`` (0 without rapids) and ``contour_scope`` ("feed" or "all")."""
    import numpy as np

    if feed is None:
        return {**m, "rapids_true_max_um": 0.0, "rapids_eq29_max_um": 0.0, "contour_scope": "all"}

    def um(values_mm):
        a = np.abs(values_mm) * 1e3
        if not a.size:
            return 0.0, 0.0, 0.0
        return float(a.max()), float(np.sqrt(np.mean(a * a))), float(a.mean())

    c, d = um(contour.eq29_mm[feed]), um(contour.true_mm[feed])
    return {
        **m,
        "contour_max_um": c[0],
        "contour_rms_um": c[1],
        "contour_mean_um": c[2],
        "true_max_um": d[0],
        "true_rms_um": d[1],
        "true_mean_um": d[2],
        "rapids_true_max_um": um(contour.true_mm[~feed])[0],
        "rapids_eq29_max_um": um(contour.eq29_mm[~feed])[0],
        "contour_scope": "feed",
    }
