"""Planner pieces: the program's path cut into pieces the feed profile treats as units.

Each NURBS block is split into its sharp-corner regions (replaced by their PH quintic pieces,
SPEC §6) and the NURBS stretches between them; lines, arcs and rapids are one piece each.
Every piece knows its exact geometry (so the interpolator can place points on it), its
length, its cruise cap (SPEC §7) and the cap of the junction at its start.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbscnc.errors import NurbsCncError, SourcePos
from nurbscnc.geometry.nurbs import NurbsCurve
from nurbscnc.geometry.paths import geometry_of
from nurbscnc.machine import Machine, chord_feed_mm_s
from nurbscnc.plan.corners import find_corner_regions
from nurbscnc.plan.phfit import fit_region

#: The lowest cruise cap a piece gets [mm/s].
MIN_CAP_MM_S = 1e-3

#: Junctions whose tangents turn by less than this [rad] are treated as smooth (no stop).
SMOOTH_JUNCTION_RAD = 1e-6



@dataclass(frozen=True, eq=False)
class Piece:
    """One piece of the path.

    ``kind``: "nurbs" | "ph" | "line" | "arc" | "rapid". ``geometry`` evaluates it:
    a NurbsCurve (``u_a``..``u_b`` of it, starting at arc length ``s_a_mm`` of the curve),
    a PHQuintic, a LineGeometry or an ArcGeometry. ``length_mm`` [mm]; ``v_cap_mm_s`` the
    cruise cap [mm/s]; ``segment`` / ``line`` where it came from; ``dwell_after_s`` a dwell
    [s] at its end (G4). ``kappa_max_per_mm`` the largest curvature on it [1/mm].
    ``blend_mm`` the G64 P tolerance of its segment [mm] (0: exact stop at corners).
    """

    kind: str
    geometry: object
    length_mm: float
    v_cap_mm_s: float
    segment: int
    line: int
    u_a: float = 0.0
    u_b: float = 1.0
    s_a_mm: float = 0.0
    kappa_max_per_mm: float = 0.0
    dwell_after_s: float = 0.0
    blend_mm: float = 0.0

    def points_mm(self, s_local_mm: np.ndarray) -> np.ndarray:
        """Exact points [mm] (m, 3) at arc lengths ``s_local_mm`` from the piece start."""
        s = np.clip(np.asarray(s_local_mm, dtype=float), 0.0, self.length_mm)
        g = self.geometry
        if self.kind == "ph":
            return g.point_mm(g.param_at_length(s))
        if self.kind == "nurbs":
            return g.point(g.param_at_length(self.s_a_mm + s))
        return g.point(g.param_at_length(s))

    def tangent_start(self) -> np.ndarray:
        return self._tangent(0.0)

    def tangent_end(self) -> np.ndarray:
        return self._tangent(self.length_mm)

    def _tangent(self, s_local: float) -> np.ndarray:
        g = self.geometry
        if self.kind == "ph":
            xi = np.array([0.0 if s_local == 0.0 else 1.0])
            d = g.derivatives_mm(xi, 1)[1][0]
        elif self.kind == "nurbs":
            u = np.array([self.u_a if s_local == 0.0 else self.u_b])
            d = g.derivatives(u, 1)[1][0]
        else:
            u = np.array([g.u_start if s_local == 0.0 else g.u_end])
            d = g.derivatives(u, 1)[1][0]
        n = np.linalg.norm(d)
        return d / n if n > 0 else d


@dataclass(frozen=True)
class PlanOptions:
    """Planner choices. ``blend_tolerance_mm``: overrides every segment's G64 P [mm]
    (None: as programmed). ``corner_feed``: "piece" (each PH piece capped by its own peak
    curvature: faster, our default) or "peak" (the whole region at V_sp of the region's peak,
    as the paper does). ``ph``: replace corner regions by PH quintics (False: plan the NURBS
    as it is, capped by the same corner feed)."""

    corner_feed: str = "piece"
    ph: bool = True
    tolerance_um: float | None = None
    blend_tolerance_mm: float | None = None


def _curvature_cap(machine: Machine, kappa, feed_mm_s: float) -> np.ndarray:
    """Feed cap [mm/s] at curvature κ outside corners: min(F, V_max, V_af(κ), √(A/κ))."""
    lim = machine.limits
    kappa = np.asarray(kappa, dtype=float)
    v_af = np.asarray(chord_feed_mm_s(kappa, machine.servo.period_s, lim.chord_tolerance_mm))
    with np.errstate(divide="ignore"):
        v_an = np.sqrt(lim.a_max_mm_s2 / np.maximum(kappa, 1e-300))
    return np.minimum(np.minimum(v_af, v_an), min(feed_mm_s, lim.v_max_mm_s))


def _corner_cap(machine: Machine, kappa_peak: float, feed_mm_s: float) -> float:
    """V_sp = min(V_af, V_cf) at a corner of peak curvature κ (SPEC §7), capped by F and by
    the normal-acceleration limit √(A_max/κ)."""
    lim = machine.limits
    v_sp = float(machine.corner_feed_mm_s(kappa_peak, min(feed_mm_s, lim.v_max_mm_s)))
    v_an = float(np.sqrt(lim.a_max_mm_s2 / kappa_peak)) if kappa_peak > 0 else np.inf
    return max(min(v_sp, v_an, feed_mm_s, lim.v_max_mm_s), 1e-6)


def nurbs_pieces(seg, index: int, machine: Machine, options: PlanOptions) -> list[Piece]:
    """A NURBS segment as pieces: PH corner pieces and capped NURBS stretches."""
    lim = machine.limits
    curve = NurbsCurve.from_segment(seg)
    feed = min(seg.feed_mm_s, lim.v_max_mm_s)
    kth = lim.a_max_mm_s2 / (feed * feed)
    regions = find_corner_regions(curve, kth)
    e_um = options.tolerance_um or lim.ph_tolerance_mm * 1000.0
    pieces: list[Piece] = []
    u_prev = curve.u_start
    for region in regions:
        if region.u_a > u_prev:
            pieces.extend(_nurbs_stretch(curve, u_prev, region.u_a, seg, index, machine, feed))
        if not np.isfinite(region.kappa_peak_per_mm):
            # A cusp (C′ = 0): a true sharp corner of the programmed curve. No smooth curve
            # can pass it at speed: stop exactly at the cusp (the junction between the two
            # stretches turns by 180°, so its cap is 0), no PH replacement.
            for ua, ub in ((region.u_a, region.u_peak), (region.u_peak, region.u_b)):
                if ub > ua:
                    pieces.extend(_nurbs_stretch(curve, ua, ub, seg, index, machine, feed))
            u_prev = region.u_b
            continue
        region_cap = _corner_cap(machine, region.kappa_peak_per_mm, feed)
        if options.ph:
            fit = fit_region(curve, region.u_a, region.u_b, tolerance_um=e_um)
            for p in fit.pieces:
                xi = np.linspace(0.0, 1.0, 65)
                k_max = float(np.max(np.abs(p.ph.curvature(xi))))
                cap = (region_cap if options.corner_feed == "peak"
                       else _corner_cap(machine, max(k_max, kth), feed))  # fmt: skip
                pieces.append(Piece("ph", p.ph, float(p.ph.length_mm), cap, index, seg.line,
                                    p.u_a, p.u_b, 0.0, k_max))  # fmt: skip
        else:
            s = curve.arc_length(np.array([region.u_a, region.u_b]))
            pieces.append(Piece("nurbs", curve, float(s[1] - s[0]), region_cap, index,
                                seg.line, region.u_a, region.u_b, float(s[0]),
                                region.kappa_peak_per_mm))  # fmt: skip
        u_prev = region.u_b
    if u_prev < curve.u_end:
        pieces.extend(_nurbs_stretch(curve, u_prev, curve.u_end, seg, index, machine, feed))
    # Pieces shorter than a nanometre (a region clipped by a cusp at a curve end) carry no
    # motion; dropping them changes the path length by less than 1e-9 mm.
    return [p for p in pieces if p.length_mm > 1e-9]


#: Longest NURBS cell [mm]: stretches between corners are cut into cells this long or shorter,
#: so that the dynamics check can lower the feed locally (near a stop, say) and not along the
#: whole stretch.
CELL_MM = 0.25


def _nurbs_stretch(curve, u_a, u_b, seg, index, machine, feed) -> list[Piece]:
    """NURBS between corners as cells of ≤ CELL_MM, each capped by min(F, V_af(κ), √(A/κ))
    over 8 curvature samples in it."""
    s_ab = curve.arc_length(np.array([u_a, u_b]))
    n_cells = int(np.clip(np.ceil((s_ab[1] - s_ab[0]) / CELL_MM), 1, 4096))
    s_edges = np.linspace(s_ab[0], s_ab[1], n_cells + 1)
    u_edges = curve.param_at_length(s_edges)
    u_edges[0], u_edges[-1] = u_a, u_b
    sub = 8
    fine = (u_edges[:-1, None] + (u_edges[1:] - u_edges[:-1])[:, None]
            * np.linspace(0.0, 1.0, sub + 1)[None, :])  # fmt: skip
    kappa = curve.curvature(fine.ravel()).reshape(fine.shape)
    # A cusp (κ = inf) sits at a cell end, where the junction is an exact stop anyway: cap the
    # cell by its finite curvature samples (κ grows like s^(-1/2) towards a cusp, so the
    # nearest sample already asks for a low feed).
    kappa = np.where(np.isfinite(kappa), kappa, 0.0)
    # Never a zero cap (κ ≥ 2/δ makes V_af zero): it would stall the tool; 1 µm/s is the floor.
    cell_cap = np.maximum(_curvature_cap(machine, kappa, feed).min(axis=1), MIN_CAP_MM_S)
    k_cell = kappa.max(axis=1)
    return [Piece("nurbs", curve, float(s_edges[i + 1] - s_edges[i]), float(cell_cap[i]),
                  index, seg.line, float(u_edges[i]), float(u_edges[i + 1]),
                  float(s_edges[i]), float(k_cell[i]))
            for i in range(n_cells)]  # fmt: skip


def segment_pieces(segments, machine: Machine, options: PlanOptions | None = None) -> list[Piece]:
    """All pieces of a program, in order; dwells become ``dwell_after_s`` of the piece before
    (or of a zero-length marker when the program starts with a dwell)."""
    options = options or PlanOptions()
    lim = machine.limits
    pieces: list[Piece] = []
    pending_dwell = 0.0
    for index, seg in enumerate(segments):
        kind = seg.kind
        if kind == "dwell":
            if pieces:
                last = pieces[-1]
                pieces[-1] = _with_dwell(last, last.dwell_after_s + seg.seconds)
            else:
                pending_dwell += seg.seconds
            continue
        if kind == "nurbs":
            try:
                new = nurbs_pieces(seg, index, machine, options)
            except NurbsCncError as exc:
                raise exc.with_pos(SourcePos(seg.line)) from None
        else:
            geom = geometry_of(seg)
            length = float(geom.length_mm)
            if length <= 0.0:
                continue
            if kind == "rapid":
                cap = lim.rapid_mm_s
                kappa = 0.0
            elif kind == "line":
                cap = min(seg.feed_mm_s, lim.v_max_mm_s)
                kappa = 0.0
            else:  # arc: constant curvature (helix: r / (r² + c²))
                kappa = float(np.max(geom.curvature(np.array([geom.u_start, geom.u_end]))))
                cap = float(_curvature_cap(machine, kappa, seg.feed_mm_s))
            new = [Piece(kind, geom, length, max(cap, 1e-6), index, seg.line,
                         geom.u_start, geom.u_end, 0.0, kappa,
                         blend_mm=blend_override(seg, options))]  # fmt: skip
        if new and pending_dwell and not pieces:
            pieces.append(Piece("line", geometry_of_point(new[0]), 0.0, 1.0, index, seg.line,
                                dwell_after_s=pending_dwell))  # fmt: skip
            pending_dwell = 0.0
        if new and pieces and pieces[-1].kind == "rapid" and new[0].kind != "rapid":
            # In-position check (as G61): wait for the servo to settle after a rapid before
            # cutting, so a rapid's stop overshoot never shows up as contour error.
            pieces[-1] = _with_dwell(pieces[-1], pieces[-1].dwell_after_s + settle_time_s(machine))
        pieces.extend(new)
    return apply_blends(pieces, machine)


def blend_override(seg, options: PlanOptions) -> float:
    """The blend tolerance [mm] for a segment: the option if given, else its G64 P."""
    if options.blend_tolerance_mm is not None:
        return float(options.blend_tolerance_mm)
    return float(getattr(seg, "blend_mm", 0.0))


def sub_geometry(piece: Piece, s0_mm: float, s1_mm: float):
    """The geometry of ``piece`` between arc lengths s0 and s1 [mm] from its start (lines and
    arcs: a new LineGeometry / ArcGeometry, exact)."""
    from dataclasses import replace as dc_replace

    from nurbscnc.geometry.paths import ArcGeometry, LineGeometry

    g = piece.geometry
    if isinstance(g, LineGeometry):
        p = g.point(np.array([s0_mm, s1_mm]))
        return LineGeometry(p[0], p[1])
    assert isinstance(g, ArcGeometry)
    u = g.param_at_length(np.array([s0_mm, s1_mm]))
    t0, t1 = float(u[0] / g.u_end), float(u[1] / g.u_end)
    th0 = t0 * g.angle_rad
    e1 = np.cos(th0) * g.e1 + np.sin(th0) * g.e2
    dr = g.radius_end_mm - g.radius_start_mm
    return dc_replace(
        g,
        origin_mm=g.origin_mm + t0 * g.helix_mm * g.normal,
        e1=e1,
        e2=np.cross(g.normal, e1),
        radius_start_mm=g.radius_start_mm + t0 * dr,
        radius_end_mm=g.radius_start_mm + t1 * dr,
        angle_rad=(t1 - t0) * g.angle_rad,
        helix_mm=(t1 - t0) * g.helix_mm,
    )


def apply_blends(pieces: list[Piece], machine: Machine) -> list[Piece]:
    """Replace corners between line/arc pieces under G64 P by PH quintic blends (issue 7).

    A corner is blended when both pieces are feed lines or arcs with a blend tolerance > 0
    (the smaller of the two is used), no dwell lies between them and their tangents turn;
    the blend may trim at most half of each piece, so blends never overlap. The blend piece
    is capped by its peak curvature like any curved piece (chord error, normal acceleration).
    """
    from dataclasses import replace as dc_replace

    from nurbscnc.plan.blend import blend_corner

    k = len(pieces)
    blends: dict[int, object] = {}
    for i in range(1, k):
        a, b = pieces[i - 1], pieces[i]
        if a.kind not in ("line", "arc") or b.kind not in ("line", "arc"):
            continue
        tol = min(a.blend_mm, b.blend_mm)
        if tol <= 0.0 or a.dwell_after_s > 0.0:
            continue
        blend = blend_corner(a.geometry, b.geometry, tol, 0.5 * a.length_mm, 0.5 * b.length_mm,
                             measure=False)  # fmt: skip
        if blend is not None and _blend_pays(a, b, blend, machine):
            blends[i] = blend
    if not blends:
        return pieces
    out: list[Piece] = []
    for i, p in enumerate(pieces):
        trim_start = blends[i].trim_b_mm if i in blends else 0.0
        trim_end = blends[i + 1].trim_a_mm if i + 1 in blends else 0.0
        if i in blends:
            bl = blends[i]
            feed = min(pieces[i - 1].v_cap_mm_s, p.v_cap_mm_s)
            cap = float(_curvature_cap(machine, bl.kappa_max_per_mm, feed))
            out.append(Piece("ph", bl.ph, float(bl.ph.length_mm), max(cap, MIN_CAP_MM_S),
                             p.segment, p.line, 0.0, 1.0, 0.0, bl.kappa_max_per_mm))  # fmt: skip
        if trim_start or trim_end:
            length = p.length_mm - trim_start - trim_end
            if length <= 1e-9:
                continue  # the two blends met in the middle of this piece
            geom = sub_geometry(p, trim_start, p.length_mm - trim_end)
            p = dc_replace(p, geometry=geom, length_mm=float(geom.length_mm),
                           u_a=0.0, u_b=float(geom.u_end))  # fmt: skip
        out.append(p)
    return out


def _blend_pays(a: Piece, b: Piece, blend, machine: Machine) -> bool:
    """Is passing the corner on the blend faster than stopping exactly at it?

    A blend's feed is capped by its peak curvature (√(A/κ), V_af); with a tight tolerance that
    cap is low, and slowing to it, crossing the blend and speeding up again can take longer
    than an exact stop. Compare both over the same stretch of the original path, with the
    S-curve closed forms (SPEC §7) from the neighbours' cruise feed v.
    """
    from nurbscnc.plan.feedrate import scurve_distance_mm, scurve_duration_s

    lim = machine.limits
    v = min(a.v_cap_mm_s, b.v_cap_mm_s)
    vb = min(float(_curvature_cap(machine, blend.kappa_max_per_mm, v)), v)
    a_max, j_max = lim.a_max_mm_s2, lim.j_max_mm_s3
    d_stop = 2.0 * float(scurve_distance_mm(v, 0.0, a_max, j_max))
    t_stop = 2.0 * float(scurve_duration_s(v, 0.0, a_max, j_max))
    d_slow = 2.0 * float(scurve_distance_mm(v, vb, a_max, j_max))
    t_slow = 2.0 * float(scurve_duration_s(v, vb, a_max, j_max))
    # Original path covered: the slow-down/speed-up stretches plus the trimmed corner.
    d_blend = d_slow + blend.trim_a_mm + blend.trim_b_mm
    t_blend = t_slow + float(blend.ph.length_mm) / vb
    span = max(d_stop, d_blend)
    return t_blend + (span - d_blend) / v < t_stop + (span - d_stop) / v


def settle_time_s(machine: Machine) -> float:
    """Time [s] for the slowest servo mode to decay to e⁻⁵ (< 1 %) of its amplitude."""
    slowest = min(
        float(np.min(np.abs(np.real(ax.poles()))))
        for ax in (machine.servo.x, machine.servo.y, machine.servo.z)
        if ax is not None
    )
    return 5.0 / slowest


def geometry_of_point(piece: Piece):
    """A zero-length line at the start of ``piece`` (carries a leading dwell)."""
    from nurbscnc.geometry.paths import LineGeometry

    p = piece.points_mm(np.array([0.0]))[0]
    return LineGeometry(p, p)


def _with_dwell(piece: Piece, seconds: float) -> Piece:
    from dataclasses import replace

    return replace(piece, dwell_after_s=seconds)


def junction_caps(pieces: list[Piece]) -> np.ndarray:
    """Cap at each junction [mm/s] (k+1): 0 at the ends, at tangent discontinuities, around
    dwells and where rapids meet feed moves; else the smaller neighbouring cruise cap."""
    k = len(pieces)
    caps = np.zeros(k + 1)
    for i in range(1, k):
        a, b = pieces[i - 1], pieces[i]
        if a.dwell_after_s > 0.0 or (a.kind == "rapid") != (b.kind == "rapid"):
            continue
        if a.length_mm == 0.0 or b.length_mm == 0.0:
            continue
        ta, tb = a.tangent_end(), b.tangent_start()
        angle = float(np.arccos(np.clip(np.dot(ta, tb), -1.0, 1.0)))
        if angle <= SMOOTH_JUNCTION_RAD:
            caps[i] = min(a.v_cap_mm_s, b.v_cap_mm_s)
    return caps
