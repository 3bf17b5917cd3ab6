"""An independent servo simulation for the contour-error tests (SPEC §8, eq. 25).

Each axis's closed-loop transfer function G(s) = (b2 s² + b1 s + b0)/(a4 s⁴ + … + a0) of the
machine profile is simulated by ``scipy.signal.lsim`` on the reference points held linearly
between samples (``interp=True``: a first-order hold, as a pulse-train card), started at
rest at the first point, with the last point held for ``settle_s`` after the end. The
contour error is the distance from each actual point to a dense polyline of the path,
by a k-d tree over its vertices (a vertex spacing h adds at most h²/(8d) to a distance d).
None of this uses the planner's own simulation or distance code.
"""

from __future__ import annotations

import numpy as np
from scipy import signal
from scipy.spatial import cKDTree


def lsim_actual_mm(points_mm: np.ndarray, machine, settle_s: float = 0.3) -> np.ndarray:
    """Actual positions (M, 3) [mm] of the three axes at k·T_s, M = N + settle_s/T_s."""
    period = machine.servo.period_s
    n = points_mm.shape[0]
    m = n + int(round(settle_s / period))
    ref = np.vstack([points_mm, np.repeat(points_mm[-1:], m - n, axis=0)])
    t = np.arange(m) * period
    actual = ref.copy()  # an axis without a model follows its reference
    models = (machine.servo.x, machine.servo.y, machine.servo.z)
    for axis, model in enumerate(models):
        if model is None:
            continue
        system = signal.lti(model.numerator, model.denominator)
        u = ref[:, axis] - ref[0, axis]  # at rest at the start: zero initial state
        _, y, _ = signal.lsim(system, u, t, interp=True)
        actual[:, axis] = y + ref[0, axis] * model.b0 / model.a0
    return actual


def distance_to_polyline_mm(points_mm: np.ndarray, dense_mm: np.ndarray) -> np.ndarray:
    """Distance [mm] from each point to the nearest vertex of the dense polyline."""
    return cKDTree(dense_mm).query(points_mm)[0]


def segment_distance_mm(points_mm, dense_mm):
    """Exact distance [mm] from each point (M, 3) to the polyline ``dense_mm`` (N, 3): the two
    segments at its nearest vertex (enough for a polyline much denser than the distances)."""
    i = cKDTree(dense_mm).query(points_mm)[1]
    best = np.full(len(points_mm), np.inf)
    for a, b in ((np.maximum(i - 1, 0), i), (i, np.minimum(i + 1, len(dense_mm) - 1))):
        pa, d = dense_mm[a], dense_mm[b] - dense_mm[a]
        t = np.clip(
            np.einsum("ij,ij->i", points_mm - pa, d)
            / np.maximum(np.einsum("ij,ij->i", d, d), 1e-300),
            0.0,
            1.0,
        )
        best = np.minimum(best, np.linalg.norm(points_mm - pa - t[:, None] * d, axis=1))
    return best


def limits_excess(points_mm: np.ndarray, machine, planned_mm: np.ndarray | None = None) -> dict:
    """The largest excess of the samples' finite differences over the machine's limits, per
    kind: "speed" |Δp|/T against V_max, "axis_v", "axis_a", "axis_j" each axis' |Δ^k p|/T^k
    against its limit (the smaller of the path's A_max, J_max and the axis' own; velocity:
    the axis' own, if any) [mm/s^k]; ≤ 0 where every sample keeps it. With ``planned_mm``
    (same length, the plan's own reference), a row where the plan itself is above the limit
    is held to the plan's own difference there instead. An allowance of 1e-9 of the limit and
    2^k·1e-12 mm of rounding of the points. Plain numpy, nothing of the planner's."""
    t = machine.servo.period_s
    lim, ax = machine.limits, machine.axis_limits
    bounds = {
        "speed": (1, lim.v_max_mm_s),
        "axis_v": (1, np.array(ax.v_max_mm_s)),
        "axis_a": (2, np.minimum(lim.a_max_mm_s2, ax.a_max_mm_s2)),
        "axis_j": (3, np.minimum(lim.j_max_mm_s3, ax.j_max_mm_s3)),
    }
    out = {}
    for name, (k, limit) in bounds.items():
        d = np.diff(points_mm, k, axis=0) / t**k
        own = None if planned_mm is None else np.diff(planned_mm, k, axis=0) / t**k
        if name == "speed":
            d = np.linalg.norm(d, axis=1)
            own = None if own is None else np.linalg.norm(own, axis=1)
        cap = np.maximum(limit, np.abs(own)) if own is not None else limit + 0.0 * d
        excess = np.abs(d) - cap * (1.0 + 1e-9) - 2.0**k * 1e-12 / t**k
        out[name] = float(np.max(np.where(np.isfinite(cap), excess, -np.inf), initial=-np.inf))
    return out


def g64_vertices(segments, path_tolerance_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """The programmed vertices of G64 corners (m, 3) [mm] and their path tolerances P (m,)
    [mm], read from a program's segments: the end of a feed move (line, arc, NURBS) that
    the next segment, a feed move too, starts at, both under G64 (``blend_mm`` inf: G64
    without P, ``path_tolerance_mm``; > 0: G64 P; ≤ 0: G61/G61.1, none); P the smaller."""
    feed = ("line", "arc", "nurbs")
    vertices, tols = [], []
    for a, b in zip(segments[:-1], segments[1:]):
        if getattr(a, "kind", None) not in feed or getattr(b, "kind", None) not in feed:
            continue
        p = min(
            path_tolerance_mm if np.isinf(s.blend_mm) else max(float(s.blend_mm), 0.0)
            for s in (a, b)
        )
        if p > 0.0 and np.allclose(a.end_mm, b.start_mm, rtol=0.0, atol=1e-9):
            vertices.append(a.end_mm)
            tols.append(p)
    return np.array(vertices, dtype=float).reshape(-1, 3), np.array(tols)


def beyond_vertex_mm(points_mm: np.ndarray, corners: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """min over the G64 vertices V (``corners``: :func:`g64_vertices`) of |p − V| − P [mm]
    for each point (n, 3) (the 8 nearest by a k-d tree); inf without vertices. A sample with
    this ≤ ε_max lies within a G64 corner's allowance (nurbscnc.plan.allowance)."""
    vertices, tols = corners
    if vertices.shape[0] == 0 or points_mm.shape[0] == 0:
        return np.full(points_mm.shape[0], np.inf)
    k = min(8, vertices.shape[0])
    dist, idx = cKDTree(vertices).query(points_mm, k=k)
    dist, idx = dist.reshape(-1, k), idx.reshape(-1, k)
    return (dist - tols[idx]).min(axis=1)


def stop_at_vertex_mm(machine, decel_mm_s2: float, turn_deg: float) -> tuple:
    """The tool (lsim, :func:`lsim_actual_mm`) around a stop at the vertex (the origin) of a
    two-segment path turning by ``turn_deg``: 0.3 s at 25 mm/s along +X, a constant
    deceleration ``decel_mm_s2`` to rest at the vertex, the mirror image out along the
    outgoing segment (1 ms samples, exact sums of the speeds). Returns (tool points (n, 3),
    the path as a dense polyline) [mm]."""
    period, v = machine.servo.period_s, 25.0
    n = int(np.ceil(v / (decel_mm_s2 * period)))
    ramp = np.maximum(v - decel_mm_s2 * period * np.arange(1, n + 1), 0.0)
    down = np.concatenate([np.full(300, v), ramp])
    x_in = np.cumsum(down) * period
    x_in -= x_in[-1]
    s_out = np.cumsum(np.concatenate([ramp[::-1][1:], np.full(300, v)])) * period
    th = np.radians(turn_deg)
    t_b = np.array([np.cos(th), np.sin(th), 0.0])
    ref = np.vstack([np.column_stack([x_in, 0 * x_in, 0 * x_in]), s_out[:, None] * t_b])
    act = lsim_actual_mm(ref, machine, settle_s=0.0)[200 : down.size + n + 100]
    path = np.vstack([[x_in[0], 0.0, 0.0], [0.0, 0.0, 0.0], s_out[-1] * t_b])
    f = np.linspace(0.0, 1.0, 4001)[:, None]
    dense = np.vstack([path[0] + f * (path[1] - path[0]), path[1] + f[1:] * (path[2] - path[1])])
    return act, dense
