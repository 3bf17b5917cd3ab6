"""Per-piece path limits from the machine's axis limits (planner v2).

The planner plans along the path with one feed cap, tangential acceleration and jerk per
piece; a real machine limits each axis (LinuxCNC's ``[AXIS_X] MAX_VELOCITY`` …). The profile's
optional ``[axis_limits.<axis>]`` tables give them. :func:`piece_limits` turns them into the
path limits of every piece: the feed [mm/s], the tangential acceleration [mm/s²] and jerk
[mm/s³] that keep every axis within its own limits on that piece, never above the path limits
of ``[limits]`` (which still hold as before: V_max, A_max tangential and normal, J_max
tangential).

What a piece needs for that is, per axis i, bounds over the piece of the unit tangent's
component |t_i| (T_i), of the curvature vector's component |(κn)_i| (K_i) and of its arc-length
derivative |d(κn)_i/ds| (G_i): the axis velocity, acceleration and jerk are v t_i,
a t_i + v²(κn)_i and j t_i + 3va(κn)_i + v³ d(κn)_i/ds (derivation and the split between the
tangential and the normal parts: :func:`nurbscnc.machine.caps.axis_path_limits`).

- Lines (and rapids): T_i = |t_i| exactly, K = G = 0: the caps are exact, e.g. v ≤ V_i/|t_i|.
- Arcs, helices, spirals, PH pieces, NURBS cells: the tangent and the curvature vector are
  sampled at evenly spaced arc lengths of the piece, at least :data:`SAMPLES` and
  :data:`SAMPLES_PER_RADIUS` per radius of curvature 1/κ_max along it (whole-array over all
  curved pieces, in buckets of equal counts), and each bound is the sampled maximum plus
  what the quantity can change within half a sample spacing h: T_i + K_i h/2
  (|dt_i/ds| = |(κn)_i|), K_i + G_i h/2 (never above κ_max), and G_i from the finite
  differences of κn between samples plus the largest change between neighbouring
  differences (covers the chord-vs-arc deficit of a circle's rotating κn). For a circle,
  κn turns at rate κ, so 33 samples over a full circle leave T_i and K_i within 10 % of
  their exact value (less on shorter arcs).

With no per-axis limit in the profile the result is the path limits alone (the planner's
behaviour without per-axis limits). Rotary axes A B C moving along a piece cap it by their
share |dA/ds| (:func:`~nurbscnc.plan.rotary.rotary_limits`), exactly.

A junction passed at speed where the curvature vector jumps (a line tangent into an arc)
steps each axis's acceleration by v²|Δ(κn)_i| — a jerk impulse. The planner's junction caps
bound it (:func:`nurbscnc.machine.caps.junction_jump_cap_mm_s`, a share of each axis's jerk
limit), and the pieces on both sides keep their own jerk to the rest on those axes
(:func:`_jump_reserved`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbscnc.geometry.distinct import distinct
from nurbscnc.geometry.path import Kind
from nurbscnc.machine.caps import JUNCTION_SHARE, axis_path_limits
from nurbscnc.plan.junctions import junction_caps
from nurbscnc.plan.rotary import rotary_limits

#: Fewest samples per curved piece for its tangent and curvature-vector bounds (ends
#: included); more on pieces that turn a lot (:data:`SAMPLES_PER_RADIUS`).
SAMPLES = 33
#: Samples per radius of curvature 1/κ_max along a piece: the curvature vector changes on
#: that length scale, so this resolves its peaks and its derivative.
SAMPLES_PER_RADIUS = 8
#: Most samples per piece (a near-cusp NURBS cell).
MAX_SAMPLES = 4097
#: Samples whose parametric speed |C′| is below this fraction of the piece's largest are
#: treated as at a cusp (their curvature is not a number the axes can follow).
CUSP_SPEED = 1e-6
#: Curved pieces of SAMPLES samples sampled at once (fewer with more samples: bounds the
#: temporaries).
_CHUNK = 1 << 13


@dataclass(frozen=True, eq=False)
class PieceLimits:
    """Path limits of each of k pieces, (k,) each: ``v_mm_s`` feed cap [mm/s] (``inf``: no
    cap beyond the piece's own), ``a_mm_s2`` tangential acceleration [mm/s²], ``j_mm_s3``
    tangential jerk [mm/s³]."""

    v_mm_s: np.ndarray
    a_mm_s2: np.ndarray
    j_mm_s3: np.ndarray


def piece_limits(pieces, machine) -> PieceLimits:
    """The path limits of every piece of ``pieces`` (a PieceList) on ``machine``: per piece
    the feed cap, tangential acceleration and jerk that keep every axis within
    ``machine.axis_limits`` and the path within ``machine.limits`` (module doc)."""
    k = len(pieces)
    lim = machine.limits
    a_path, j_path = float(lim.a_max_mm_s2), float(lim.j_max_mm_s3)
    axis = machine.axis_limits
    rotary = rotary_limits(pieces, machine)
    if not axis.any and rotary is None:
        return PieceLimits(np.full(k, np.inf), np.full(k, a_path), np.full(k, j_path))
    if axis.any:
        t_bound, k_bound, g_bound, kappa = axis_geometry_bounds(pieces)
        v_i, a_i, j_i = axis.as_arrays()
        j_i = _jump_reserved(pieces, j_i)
        v, a, j = axis_path_limits(
            t_bound, k_bound, g_bound, kappa, pieces.v_cap_mm_s, v_i, a_i, j_i, a_path, j_path
        )
    else:
        v, a, j = np.full(k, np.inf), np.full(k, a_path), np.full(k, j_path)
    if rotary is not None:  # A B C linear in s on every piece: their shares |dA/ds| (exact)
        v, a, j = (np.minimum(x, r) for x, r in zip((v, a, j), rotary[:3]))
    a, j = _run_minimum(pieces, np.minimum(pieces.v_cap_mm_s, v), a, j)
    return PieceLimits(v, a, j)


def _jump_reserved(pieces, j_axis_mm_s3: np.ndarray) -> np.ndarray:
    """Per piece and axis (k, 3) the axis jerk limit [mm/s³] the piece's own motion may use:
    J_i, or (1 − :data:`~nurbscnc.machine.caps.JUNCTION_SHARE`) J_i on the axes where the
    curvature vector jumps at one of its ends (``pieces.jump_kn``) or where a small break
    passed at speed (``pieces.pass_after``) steps the velocity: the acceleration step
    (:func:`~nurbscnc.machine.caps.junction_jump_cap_mm_s`) or the velocity step
    (:func:`nurbscnc.plan.junctions.small_breaks`) takes the share, so the two add up to at
    most J_i on the samples."""
    k = len(pieces)
    j_axis = np.asarray(j_axis_mm_s3, dtype=float)
    j = np.broadcast_to(j_axis, (k, 3)).copy()
    rows = np.asarray(pieces.jump_rows, dtype=np.int64)
    hits = np.abs(np.asarray(pieces.jump_kn)) > 0.0 if rows.size else np.zeros((0, 3), bool)
    if k >= 2:
        passed = np.flatnonzero(np.asarray(pieces.pass_after)[:-1])
        step = (
            np.asarray(pieces.tangent_start)[:, passed + 1]
            - np.asarray(pieces.tangent_end)[:, passed]
        ).T  # (m, 3)
        rows = np.concatenate((rows, passed))
        hits = np.concatenate((hits, np.abs(step) > 0.0))
    if rows.size:
        scale = np.where(hits, 1.0 - JUNCTION_SHARE, 1.0)
        for side in (rows, rows + 1):  # the pieces before and after each junction
            np.minimum.at(j, side, j_axis[None, :] * scale)
    return j


def _run_minimum(pieces, caps_mm_s: np.ndarray, a_mm_s2: np.ndarray, j_mm_s3: np.ndarray):
    """``a``, ``j`` lowered to their minimum over each run of pieces with one cruise cap and
    tangent-continuous junctions.

    Why: the feed profile plans such a run (the cells of a NURBS at the programmed feed) as
    one unit only when the pieces' limits are equal too (:func:`~nurbscnc.plan.profile_plan.
    plan_profile`); with the slightly different limits each cell gets from its own geometry,
    it plans cell by cell, with zero acceleration at every cell junction — measured on the
    9 mm NACA 2415 with LinuxCNC's sim axes: 0.85 s instead of 0.79 s. The minimum over the
    run is conservative (every piece keeps within its own limits) and costs little: within a
    run the curvature, hence the limits, changes slowly.
    """
    k = len(pieces)
    if k < 2:
        return a_mm_s2, j_mm_s3
    joined = (junction_caps(pieces)[1:-1] > 0.0) & (caps_mm_s[:-1] == caps_mm_s[1:])
    run = np.concatenate(([0], np.cumsum(~joined)))  # run label of each piece
    starts = np.flatnonzero(np.concatenate(([True], ~joined)))
    a_run = np.minimum.reduceat(a_mm_s2, starts)
    j_run = np.minimum.reduceat(j_mm_s3, starts)
    return a_run[run], j_run[run]


def axis_geometry_bounds(pieces) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per piece and axis (k, 3): bounds T of |t_i| (unit tangent), K of |(κn)_i| [1/mm]
    (curvature vector) and G of |d(κn)_i/ds| [1/mm²] over the piece (module doc); and per
    piece (k,) a bound of the curvature κ [1/mm] (0 on lines)."""
    k = len(pieces)
    t_bound = np.abs(np.asarray(pieces.tangent_start, dtype=float).T).copy()  # lines: exact
    k_bound = np.zeros((k, 3))
    g_bound = np.zeros((k, 3))
    kappa = np.zeros(k)
    kind = np.asarray(pieces.kind)
    length = np.asarray(pieces.length_mm, dtype=float)
    k_rec = np.asarray(pieces.kappa_max_per_mm, dtype=float)
    curved = np.flatnonzero(kind != Kind.LINE)
    path = pieces.path if curved.size else None
    # Samples per piece: at least SAMPLES, and SAMPLES_PER_RADIUS per radius of curvature
    # 1/κ_max along it (a PH corner blend whose curvature peaks at 110 /mm over a few µm
    # needs µm spacing); in power-of-two buckets so each bucket is one whole-array pass.
    want = np.ceil(
        length[curved]
        * np.where(np.isfinite(k_rec[curved]), k_rec[curved], 0.0)
        * SAMPLES_PER_RADIUS
    )
    level = np.ceil(np.log2(np.clip(want, SAMPLES - 1, MAX_SAMPLES - 1))).astype(int)
    for lv in distinct(level).tolist():
        n = (1 << lv) + 1
        group = curved[level == lv]
        step = max(_CHUNK * SAMPLES // n, 1)
        for lo in range(0, group.size, step):
            rows = group[lo : lo + step]
            t_bound[rows], k_bound[rows], g_bound[rows], kappa[rows] = _sampled_bounds(
                path, rows, length[rows], k_rec[rows], kind[rows] == Kind.ARC, n
            )
    return t_bound, k_bound, g_bound, kappa


def _nearest_regular(ok: np.ndarray) -> np.ndarray:
    """(m, n) index of the nearest True of each row of ``ok`` (its own where True; the first
    one of the row by default)."""
    m, n = ok.shape
    col = np.arange(n)
    prev = np.maximum.accumulate(np.where(ok, col, -1), axis=1)
    nxt = np.minimum.accumulate(np.where(ok, col, n)[:, ::-1], axis=1)[:, ::-1]
    use_prev = (prev >= 0) & ((nxt >= n) | (col - prev <= nxt - col))
    out = np.where(use_prev, prev, nxt)
    return np.where(out >= n, 0, out)


def _sampled_bounds(
    path,
    rows: np.ndarray,
    length_mm: np.ndarray,
    kappa_max_per_mm,
    exact_kappa: np.ndarray,
    samples: int,
):
    """T, K, G (m, 3) and κ (m,) of curved pieces ``rows`` from ``samples`` samples each;
    ``exact_kappa`` (m,): the recorded κ_max is exact (circular arcs and helices)."""
    m = rows.size
    frac = np.linspace(0.0, 1.0, samples)
    s = (length_mm[:, None] * frac[None, :]).ravel()
    idx = np.repeat(rows, samples)
    d1, d2 = path.derivatives(idx, s)
    speed2 = np.einsum("ij,ij->i", d1, d1).reshape(m, samples)
    # A cusp (C′ = 0, a doubled control point at a NURBS end) has no tangent, and samples
    # where |C′| is 1e-6 of the piece's largest are numerically at one (κ ~ 1e19): they take
    # the values of their nearest regular sample. The tool passes a cusp at rest (its
    # junction turns by 180°, a stop) and κ grows like s^(-1/2) towards it, so the next
    # sample already holds the feed down (the same rule as the NURBS cells' own caps).
    ok = speed2 > (CUSP_SPEED * CUSP_SPEED) * speed2.max(axis=1, keepdims=True)
    ok &= speed2 > 0.0
    fill = _nearest_regular(ok)
    d1 = d1.reshape(m, samples, 3)[np.arange(m)[:, None], fill]
    d2 = d2.reshape(m, samples, 3)[np.arange(m)[:, None], fill]
    safe2 = np.maximum(speed2[np.arange(m)[:, None], fill], 1e-300)[..., None]
    tan = d1 / np.sqrt(safe2)
    # Curvature vector κn = dt/ds = (C″ − (C″·t) t) / |C′|² (any parametrisation).
    curv = (d2 - np.einsum("mij,mij->mi", d2, tan)[..., None] * tan) / safe2
    none = ~ok.any(axis=1)  # a piece without a regular sample: no bound from it
    tan[none] = 0.0
    curv[none] = 0.0
    h = length_mm / (samples - 1)  # sample spacing [mm]
    with np.errstate(divide="ignore", invalid="ignore"):
        diff = np.diff(curv, axis=1) / np.where(h > 0.0, h, np.inf)[:, None, None]
    g = np.abs(diff).max(axis=1) + np.abs(np.diff(diff, axis=1)).max(axis=1, initial=0.0)
    # κ: exact on arcs and helices (constant); else the largest of the piece's recorded
    # κ_max and the sampled one plus its change within h/2.
    k_rec = np.asarray(kappa_max_per_mm, dtype=float)
    sampled = np.sqrt((curv * curv).sum(axis=2)).max(axis=1)
    kappa = np.where(
        exact_kappa, k_rec, np.maximum(k_rec, sampled + np.sqrt((g * g).sum(axis=1)) * h / 2.0)
    )
    k_b = np.minimum(np.abs(curv).max(axis=1) + g * (h / 2.0)[:, None], kappa[:, None])
    # |dt_i/ds| = |(κn)_i| ≤ K_i: within h/2 of a sample t_i changes by at most K_i h/2 (an
    # XY arc keeps T_z = 0, so a slow Z axis never caps it).
    t_b = np.minimum(np.abs(tan).max(axis=1) + k_b * (h / 2.0)[:, None], 1.0)
    return t_b, k_b, g, kappa
