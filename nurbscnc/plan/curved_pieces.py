"""Arc and NURBS segments as pieces: an arc is one piece; a NURBS block is split into its
sharp-corner regions (replaced by their PH quintic pieces, SPEC §6) and the NURBS stretches
between them, cut into capped cells."""

from __future__ import annotations

from dataclasses import replace as dc_replace

import numpy as np

from nurbscnc.errors import NurbsCncError, SourcePos
from nurbscnc.geometry.nurbs import NurbsCurve
from nurbscnc.geometry.path import Kind
from nurbscnc.geometry.paths import geometry_of
from nurbscnc.machine.caps import MIN_CAP_MM_S, corner_cap_mm_s, curvature_cap_mm_s
from nurbscnc.machine.profile import Machine
from nurbscnc.plan.corners import find_corner_regions
from nurbscnc.plan.options import CornerFeed, PlanOptions
from nurbscnc.plan.phfit import fit_region
from nurbscnc.plan.pieces import Piece


def nurbs_curve(seg, machine: Machine) -> NurbsCurve:
    """The curve a NURBS segment is planned on: its own, with a hook of rounding at an end
    (a control leg of 1e-6 mm turning back) removed within the chord tolerance δ, the
    small-break rule's bound on how far a passed break may cut."""
    return NurbsCurve.from_segment(seg).without_end_hooks(machine.limits.chord_tolerance_mm)


def nurbs_pieces(
    seg, index: int, machine: Machine, options: PlanOptions, curve: NurbsCurve | None = None
) -> list[Piece]:
    """A NURBS segment as pieces: PH corner pieces and capped NURBS stretches, on ``curve``
    (default :func:`nurbs_curve`)."""
    lim = machine.limits
    curve = nurbs_curve(seg, machine) if curve is None else curve
    feed = min(seg.feed_mm_s, lim.v_max_mm_s)
    kth = lim.a_max_mm_s2 / (feed * feed)
    regions = find_corner_regions(curve, kth)
    e_um = (options.tolerance_mm or lim.ph_tolerance_mm) * 1000.0
    blend = blend_override(seg, options)
    pieces: list[Piece] = []
    u_prev = curve.u_start
    for region in regions:
        if region.u_a > u_prev:
            pieces.extend(
                _nurbs_stretch(curve, u_prev, region.u_a, seg, index, machine, feed, blend)
            )
        if not np.isfinite(region.kappa_peak_per_mm):
            # A cusp (C′ = 0): a true sharp corner of the programmed curve. No smooth curve
            # can pass it at speed: stop exactly at the cusp (the junction between the two
            # stretches turns by 180°, so its cap is 0), no PH replacement.
            for ua, ub in ((region.u_a, region.u_peak), (region.u_peak, region.u_b)):
                if ub > ua:
                    pieces.extend(_nurbs_stretch(curve, ua, ub, seg, index, machine, feed, blend))
            u_prev = region.u_b
            continue
        region_cap = corner_cap_mm_s(machine, region.kappa_peak_per_mm, feed)
        if options.ph:
            # max ≤ e (not the paper's 3e): every reference point within e of the curve.
            for p in _region_fit(curve, region.u_a, region.u_b, e_um):
                xi = np.linspace(0.0, 1.0, 65)
                k_max = float(np.max(np.abs(p.ph.curvature(xi))))
                k_mean = abs(p.ph.turning_angle_rad()) / max(float(p.ph.length_mm), 1e-300)
                cap = (
                    region_cap
                    if options.corner_feed == CornerFeed.PEAK
                    else corner_cap_mm_s(machine, max(k_max, kth), feed, max(k_mean, kth))
                )
                pieces.append(
                    Piece(
                        Kind.PH,
                        p.ph,
                        float(p.ph.length_mm),
                        cap,
                        index,
                        seg.line,
                        0.0,
                        1.0,
                        0.0,
                        k_max,
                        blend_mm=blend,
                    )
                )
        else:
            s = curve.arc_length(np.array([region.u_a, region.u_b]))
            pieces.append(
                Piece(
                    Kind.NURBS,
                    curve,
                    float(s[1] - s[0]),
                    region_cap,
                    index,
                    seg.line,
                    region.u_a,
                    region.u_b,
                    float(s[0]),
                    region.kappa_peak_per_mm,
                    blend_mm=blend,
                )
            )
        u_prev = region.u_b
    if u_prev < curve.u_end:
        pieces.extend(_nurbs_stretch(curve, u_prev, curve.u_end, seg, index, machine, feed, blend))
    # Pieces shorter than a nanometre (a region clipped by a cusp at a curve end) carry no
    # motion; dropping them changes the path length by less than 1e-9 mm.
    return [p for p in pieces if p.length_mm > 1e-9]


#: Longest PH piece of a corner region [mm]: a region's pieces are cut at least this fine, so
#: each piece's cap (its own peak curvature, :func:`corner_cap_mm_s`) follows the curvature
#: along the corner; a 0.25 mm piece holding the nose of a 9 mm airfoil (κ from 1.6 to
#: 5 /mm) would be capped at its sharpest point all along.
CORNER_CELL_MM = 0.0625


def _region_fit(curve, u_a: float, u_b: float, e_um: float):
    """PH pieces of the corner region [u_a, u_b]: the region cut into parts of equal arc
    length, at most :data:`CORNER_CELL_MM` (at most 64 parts), each fitted
    (:func:`fit_region`, max ≤ e). The parts share C and C′ at their ends (Hermite data), so
    the joins stay G1 as in one fit; a part is halved further by the fit where the deviation
    asks."""
    s = curve.arc_length(np.array([u_a, u_b]))
    n = int(np.clip(np.ceil((s[1] - s[0]) / CORNER_CELL_MM), 1, 64))
    u = curve.param_at_length(np.linspace(s[0], s[1], n + 1))
    u[0], u[-1] = u_a, u_b
    return [
        p
        for a, b in zip(u[:-1], u[1:], strict=True)
        for p in fit_region(curve, float(a), float(b), tolerance_um=e_um, max_factor=1.0).pieces
    ]


#: Longest NURBS cell [mm]: stretches between corners are cut into cells this long or shorter,
#: so that the dynamics check can lower the feed locally (near a stop, say) and not along the
#: whole stretch.
CELL_MM = 0.25


def _nurbs_stretch(curve, u_a, u_b, seg, index, machine, feed, blend_mm) -> list[Piece]:
    """NURBS between corners as cells of ≤ CELL_MM, each capped by min(F, V_af(κ), √(A/κ))
    over 8 curvature samples in it; ``blend_mm`` their segment's blend tolerance
    (:func:`blend_override`)."""
    s_ab = curve.arc_length(np.array([u_a, u_b]))
    n_cells = int(np.clip(np.ceil((s_ab[1] - s_ab[0]) / CELL_MM), 1, 4096))
    s_edges = np.linspace(s_ab[0], s_ab[1], n_cells + 1)
    u_edges = curve.param_at_length(s_edges)
    u_edges[0], u_edges[-1] = u_a, u_b
    sub = 8
    fine = (
        u_edges[:-1, None]
        + (u_edges[1:] - u_edges[:-1])[:, None] * np.linspace(0.0, 1.0, sub + 1)[None, :]
    )
    kappa = curve.curvature(fine.ravel()).reshape(fine.shape)
    # A cusp (κ = inf) sits at a cell end, where the junction is an exact stop anyway: cap the
    # cell by its finite curvature samples (κ grows like s^(-1/2) towards a cusp, so the
    # nearest sample already asks for a low feed).
    kappa = np.where(np.isfinite(kappa), kappa, 0.0)
    kappa = np.column_stack([kappa, _peak_kappa(curve, fine, kappa)])
    # Never a zero cap (κ ≥ 2/δ makes V_af zero): it would stall the tool; 1 µm/s is the floor.
    cell_cap = np.maximum(curvature_cap_mm_s(machine, kappa, feed).min(axis=1), MIN_CAP_MM_S)
    k_cell = kappa.max(axis=1)
    return [
        Piece(
            Kind.NURBS,
            curve,
            float(s_edges[i + 1] - s_edges[i]),
            float(cell_cap[i]),
            index,
            seg.line,
            float(u_edges[i]),
            float(u_edges[i + 1]),
            float(s_edges[i]),
            float(k_cell[i]),
            blend_mm=blend_mm,
        )
        for i in range(n_cells)
    ]


def _peak_kappa(curve, u: np.ndarray, kappa: np.ndarray, rounds: int = 3) -> np.ndarray:
    """The curvature peak [1/mm] of each row of samples (cells × samples at parameters
    ``u``, curvatures ``kappa``), refined: 16 new samples between the neighbours of the
    largest one, ``rounds`` times (a sharp peak between two of the 9 cell samples — a
    near-cusp of a rational NURBS, κ 350 /mm — was missed by 30 %, and the cell's cap
    √(A/κ) with it); past the first round, not the cells whose curvature that round found
    rising to the cell's end. Cusps (κ = inf) count as 0 as in the samples."""
    m, n = u.shape
    best = kappa.max(axis=1)
    rows = np.arange(m)  # the cells still refined: row i of u and kappa is cell rows[i]
    for r in range(rounds):
        at = np.arange(rows.size)
        k = np.argmax(kappa, axis=1)
        lo, hi = u[at, np.maximum(k - 1, 0)], u[at, np.minimum(k + 1, n - 1)]
        u = lo[:, None] + (hi - lo)[:, None] * np.linspace(0.0, 1.0, 17)[None, :]
        kappa = curve.curvature(u.ravel()).reshape(u.shape)
        kappa = np.where(np.isfinite(kappa), kappa, 0.0)
        peak = kappa.max(axis=1)
        rose = peak > best[rows]
        best[rows] = np.maximum(best[rows], peak)
        if r == 0:
            # Done after one round: a cell whose refinement found nothing above its samples
            # and whose largest new sample is an end of the refined interval (the curvature
            # rises to the cell's end there: most cells). Refining those further too changes
            # a peak only rarely, and then by far less than the cap's other margins.
            j = np.argmax(kappa, axis=1)
            on = np.flatnonzero(rose | ((j > 0) & (j < kappa.shape[1] - 1)))
            rows, u, kappa = rows[on], u[on], kappa[on]
            if not rows.size:
                break
        n = u.shape[1]
    return best


def object_pieces(
    seg, index: int, machine: Machine, options: PlanOptions, curve: NurbsCurve | None = None
) -> list[Piece]:
    """The pieces of an arc or NURBS segment (Piece objects; none for a zero-length arc);
    a NURBS segment's on ``curve`` if given (:func:`nurbs_curve`)."""
    if seg.kind == "nurbs":
        try:
            pieces = nurbs_pieces(seg, index, machine, options, curve)
        except NurbsCncError as exc:
            raise exc.with_pos(SourcePos(seg.line)) from None
        line_at = getattr(seg, "line_at", None)  # a smoothed run: each piece its move's line
        return [dc_replace(p, line=line_at(p.u_a)) for p in pieces] if line_at else pieces
    geom = geometry_of(seg)
    length = float(geom.length_mm)
    if length <= 0.0:
        return []
    # Constant curvature (helix: r / (r² + c²)).
    kappa = float(np.max(geom.curvature(np.array([geom.u_start, geom.u_end]))))
    cap = float(curvature_cap_mm_s(machine, kappa, seg.feed_mm_s))
    return [
        Piece(
            Kind.ARC,
            geom,
            length,
            max(cap, 1e-6),
            index,
            seg.line,
            geom.u_start,
            geom.u_end,
            0.0,
            kappa,
            blend_mm=blend_override(seg, options),
        )
    ]


def blend_override(seg, options: PlanOptions) -> float:
    """The blend tolerance [mm] for a segment: the option if given, else its G64 P (a
    smoothed run's own: the part of the tolerance its spline left to its end blends)."""
    if options.blend_tolerance_mm is not None and not getattr(seg, "smoothed", False):
        return float(options.blend_tolerance_mm)
    return float(getattr(seg, "blend_mm", 0.0))
