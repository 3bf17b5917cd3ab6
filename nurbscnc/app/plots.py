"""The figures of a command (PNG files; matplotlib, the 'plot' extra): a planned run's, a
simulation's, a comparison's."""

from __future__ import annotations

import os


def write_plan_plots(run, plot_dir: str, prog, expl=None, mach=None) -> list[str]:
    """Figures of one run (PNG files in ``plot_dir``), each titled with the program's name:
    the path (rapids dashed, cuts coloured by feed, PH pieces marked), the feed over time,
    the feed along the path with the programmed F, the path coloured by the limit that set
    the feed (with an explanation ``expl``), the predicted contour error with ε_max."""
    import numpy as np

    from nurbscnc.output import plots
    from nurbscnc.plan.report import corner_polylines

    os.makedirs(plot_dir, exist_ok=True)
    smp = run.samples
    name = prog.name
    pl = run.plan
    rapid = None
    if pl is not None:
        rapid = np.asarray(pl.pieces.rapid)[smp.piece]
    programmed = None
    if expl is not None:
        programmed = (smp.t_s, np.asarray(expl.piece_feed_mm_s)[smp.piece])
    written = [
        plots.plot_feed_profiles(
            {"planned feed": (smp.t_s, smp.v_mm_s)},
            os.path.join(plot_dir, "feed.png"),
            title=f"{name}: feed over time",
            programmed=programmed,
        )
    ]
    corners = corner_polylines(pl.pieces, CORNER_POINTS) if pl is not None else []
    marks, label = slowest_corners(pl, smp) if pl is not None else (None, None)
    written.append(
        plots.plot_path(
            smp.points_mm,
            corners,
            os.path.join(plot_dir, "path.png"),
            title=f"{name}: tool path",
            rapid=rapid,
            feed_mm_s=smp.v_mm_s,
            marks_mm=marks,
            marks_label=label,
        )
    )
    written.append(
        plots.plot_path_sides(
            smp.points_mm,
            os.path.join(plot_dir, "path_side.png"),
            title=f"{name}: path",
            rapid=rapid,
        )
    )
    if pl is not None and expl is not None:
        written += _explained_plots(smp, pl, expl, plot_dir, name)
    if run.check is not None:
        contour = run.check.response.contour_mm
        t = np.arange(contour.size) * (smp.t_s[1] - smp.t_s[0])
        eps = None if mach is None else mach.limits.contour_tolerance_mm * 1000.0
        written.append(
            plots.plot_contour_error(
                scoped_series("predicted (true distance)", t, contour * 1000.0, run.check.cutting),
                os.path.join(plot_dir, "contour_error.png"),
                title=f"{name}: predicted contour error",
                eps_max_um=eps,
            )
        )
    return written


#: Points drawn per corner piece, and the most corners circled on the path figure.
CORNER_POINTS = 12
MARKED_CORNERS = 10


def slowest_corners(plan, smp, count: int = MARKED_CORNERS):
    """``(points (k, 3) [mm], legend)`` of the ``count`` corner pieces (PH) where the
    planned feed is lowest (each piece's slowest sample of ``smp``), to circle on the path
    figure: the corners that cost time, not every corner; ``(None, None)`` without corner
    pieces."""
    import numpy as np

    from nurbscnc.geometry.path import Kind

    ph = np.asarray(plan.pieces.kind) == Kind.PH
    on = ph[smp.piece]
    if not on.any():
        return None, None
    rows = np.flatnonzero(on)
    piece = smp.piece[rows]
    order = np.lexsort((smp.v_mm_s[rows], piece))  # by piece, slowest sample first
    first = order[np.r_[True, piece[order][1:] != piece[order][:-1]]]
    slowest = first[np.argsort(smp.v_mm_s[rows][first], kind="stable")][:count]
    total = int(np.count_nonzero(ph))
    label = (
        f"the {slowest.size} slowest corners (of {total})"
        if slowest.size < total
        else f"corners ({total})"
    )
    return smp.points_mm[rows][slowest], label


def _explained_plots(smp, pl, expl, plot_dir: str, name: str) -> list[str]:
    """The feed along the program with its caps, and the path coloured by the limit that set
    the feed (:mod:`nurbscnc.plan.explain`)."""
    import numpy as np

    from nurbscnc.output import plots
    from nurbscnc.plan.explain import Limit

    starts = np.asarray(pl.profile.piece_start_mm)
    return [
        plots.plot_feed_along(
            smp.s_mm,
            smp.v_mm_s,
            starts,
            starts + np.asarray(pl.pieces.length_mm),
            expl.piece_feed_mm_s,
            os.path.join(plot_dir, "feed_along.png"),
            cap_mm_s=expl.piece_cap_mm_s,
            title=f"{name}: feed along the program",
        ),
        plots.plot_path_limits(
            smp.points_mm,
            expl.piece_limit[smp.piece],
            [m.text for m in Limit],
            os.path.join(plot_dir, "limits.png"),
            title=f"{name}: what limits the feed",
        ),
    ]


def scoped_series(label: str, t_s, err_um, feed) -> dict:
    """Time series ``{name: (t_s, err_um)}`` of a contour error [µm]: the feed samples
    (``feed`` (M,) bool, :mod:`nurbscnc.plan.scope`) as ``label``, the others apart under
    :data:`~nurbscnc.output.plots.RAPIDS_LABEL` (gaps where the other one is drawn);
    ``feed`` None: every sample under ``label``."""
    import numpy as np

    from nurbscnc.output.plots import RAPIDS_LABEL

    if feed is None:
        return {label: (t_s, err_um)}
    series = {f"{label}, feed moves": (t_s, np.where(feed, err_um, np.nan))}
    if not feed.all():
        series[RAPIDS_LABEL] = (t_s, np.where(feed, np.nan, err_um))
    return series


def write_simulate_plots(
    sim, contour, plot_dir: str, name: str, eps_max_um: float, feed=None
) -> None:
    """The simulated contour error (true distance and SPEC eq. 29, with ε_max
    ``eps_max_um`` [µm]; ``feed`` (M,) bool: the feed samples, the rapids' drawn apart) and
    the axis errors of a servo simulation, in µm over time."""
    import numpy as np

    from nurbscnc.output import plots

    os.makedirs(plot_dir, exist_ok=True)
    eq29_um = np.abs(contour.eq29_mm) * 1000.0
    plots.plot_contour_error(
        {
            **scoped_series("true distance", sim.t_s, contour.true_mm * 1000.0, feed),
            ("eq. 29" if feed is None else "eq. 29, feed moves"): (
                sim.t_s,
                eq29_um if feed is None else np.where(feed, eq29_um, np.nan),
            ),
        },
        os.path.join(plot_dir, "contour_error.png"),
        title=f"{name}: simulated contour error",
        eps_max_um=eps_max_um,
    )
    plots.plot_axis_errors(
        {"servo": (sim.t_s, sim.axis_error_mm[:, 0] * 1000.0, sim.axis_error_mm[:, 1] * 1000.0)},
        os.path.join(plot_dir, "axis_errors.png"),
        title=f"{name}: simulated axis errors",
    )


def write_compare_plots(
    runs, plot_dir: str, name: str | None = None, eps_max_um: float | None = None
) -> list[str]:
    """Figures 1, 2/4/6 and 7 of the paper for a comparison (PNG files in ``plot_dir``),
    titled with the program's ``name`` when given; ``eps_max_um`` [µm] drawn on the contour
    error figure."""
    head = f"{name}: " if name else ""
    from nurbscnc.output import plots
    from nurbscnc.plan.report import corner_polylines

    os.makedirs(plot_dir, exist_ok=True)
    written = []
    for angle in sorted({r.angle_deg for r in runs}):
        tag = f"{angle:g}deg".replace("-", "m")
        group = [r for r in runs if r.angle_deg == angle]
        ours = next((r for r in group if r.plan is not None), None)
        if ours is not None:
            corners = corner_polylines(ours.plan.pieces)
            written.append(
                plots.plot_path(
                    ours.path_mm,
                    corners,
                    os.path.join(plot_dir, f"path_{tag}.png"),
                    title=f"{head}tool path and corner regions, {angle:g}°",
                )
            )
        written.append(
            plots.plot_feed_profiles(
                {r.algorithm: (r.samples.t_s, r.samples.v_mm_s) for r in group},
                os.path.join(plot_dir, f"feed_{tag}.png"),
                title=f"{head}feed profiles, {angle:g}°",
            )
        )
        written.append(
            plots.plot_contour_error(
                {r.algorithm: (r.sim_t_s, r.contour_true_um) for r in group},
                os.path.join(plot_dir, f"contour_{tag}.png"),
                title=f"{head}contour error (true distance), {angle:g}°",
                eps_max_um=eps_max_um,
            )
        )
        written.append(
            plots.plot_axis_errors(
                {
                    r.algorithm: (r.sim_t_s, r.axis_error_um[:, 0], r.axis_error_um[:, 1])
                    for r in group
                },
                os.path.join(plot_dir, f"axis_{tag}.png"),
                title=f"{head}axis tracking errors, {angle:g}°",
            )
        )
    return written
