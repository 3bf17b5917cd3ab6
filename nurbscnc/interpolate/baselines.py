"""The paper's two baseline interpolators (SPEC §9): adaptive feed and curvature feed.

Both traverse a NURBS block with the 2nd-order Taylor interpolator (SPEC §3, eq. 4–5) and set
the feed at every step from the curvature there, with no acceleration or jerk limit — so the
feed changes abruptly where the curvature does, which is what the paper compares against:

- adaptive (Yeh & Hsu 2002): V_k = min(F, V_af(κ(u_k))), V_af = (2/T_s)√(2δ/κ − δ²);
- curvature (Zhiming 2002): V_k = V_cf(κ(u_k)) = F κ̄ / (κ + κ̄).

The feed is commanded per step (no acceleration term: A_k = 0 in eq. 4, as the feed has no
planned derivative). The tool starts at the block's first point and the last reference point
is the block's end point.
"""

from __future__ import annotations

import numpy as np

from nurbscnc.errors import ConfigError
from nurbscnc.geometry.nurbs import NurbsCurve
from nurbscnc.geometry.path import STOP_KINDS, stop_seconds
from nurbscnc.interpolate.taylor import taylor_increment
from nurbscnc.machine.caps import baseline_feed_mm_s
from nurbscnc.machine.profile import Machine
from nurbscnc.plan.timing import Samples

ALGORITHMS = ("adaptive", "curvature")


def baseline_samples(algorithm: str, seg, machine: Machine, max_steps: int = 10_000_000) -> Samples:
    """Reference points of a NURBS segment under a baseline algorithm (SPEC §3, §9).

    u_{k+1} = u_k + V_k T/|C′| − (T²/2) V_k² (C′·C″)/|C′|⁴, V_k from the curvature at u_k.
    """
    curve = NurbsCurve.from_segment(seg)
    period = machine.servo.period_s
    u_end = curve.u_end
    u = curve.u_start
    us = [u]
    vs = []
    for _ in range(max_steps):
        d = curve.derivatives(np.array([u]), 2)
        d1, d2 = d[1][0], d[2][0]
        speed2 = float(d1 @ d1)
        speed = speed2**0.5
        cross = np.cross(d1, d2)
        kappa = float(np.linalg.norm(cross)) / (speed2 * speed) if speed > 0 else np.inf
        v = float(baseline_feed_mm_s(algorithm, kappa, seg.feed_mm_s, machine))
        vs.append(v)
        # The feed has no planned derivative: A = 0 in eq. 4.
        u = u + taylor_increment(v, 0.0, period, speed, speed2, float(d1 @ d2))
        if u >= u_end:
            us.append(u_end)
            vs.append(0.0)
            break
        us.append(u)
    else:  # pragma: no cover - a feed of ~0 everywhere
        raise RuntimeError("baseline interpolation did not reach the end of the curve")
    u_arr = np.asarray(us)
    points = curve.point(u_arr)
    n = u_arr.size
    s = curve.arc_length(u_arr)
    v_arr = np.asarray(vs)
    return Samples(
        t_s=np.arange(n) * period,
        tau_s=None,
        points_mm=points,
        s_mm=s,
        v_mm_s=v_arr,
        a_mm_s2=np.gradient(v_arr, period) if n > 1 else np.zeros(n),
        piece=np.zeros(n, dtype=np.int64),
        line=np.full(n, seg.line, dtype=np.int64),
        param=None,
    )


def _constant_feed_samples(geom, v_mm_s: float, period: float) -> np.ndarray:
    """Points [mm] every T_s at constant feed along a line or arc (no acceleration limit),
    the segment's end point last."""
    length = float(geom.length_mm)
    n = max(int(np.ceil(length / (v_mm_s * period) - 1e-9)), 1)
    s = np.minimum(np.arange(1, n + 1) * v_mm_s * period, length)
    return geom.point(geom.param_at_length(s))


def baseline_program_samples(algorithm: str, program, machine: Machine) -> Samples:
    """A whole program under a baseline (SPEC §9): NURBS blocks by :func:`baseline_samples`,
    lines and arcs at their programmed feed (rapids at the rapid rate), dwells held — all with
    no acceleration or jerk limit, as the baselines are defined. Rest points between segments
    are simply where one segment's samples end and the next one's begin."""
    from nurbscnc.geometry.paths import geometry_of

    if program.rotary_axes:  # the paper's baselines know X Y Z only
        axes = " ".join(a.upper() for a in program.rotary_axes)
        raise ConfigError(
            f"the baseline {algorithm} interpolates X Y Z only; this program moves {axes} "
            "(use the look-ahead planner, --algorithm ph-lookahead)"
        )
    period = machine.servo.period_s
    lim = machine.limits
    points = [np.asarray(program.start_mm, dtype=float)[None, :]]
    feeds = [np.zeros(1)]
    lines = [np.array([program.segments[0].line if program.segments else 0])]
    for seg in program.segments:
        if seg.kind in STOP_KINDS:  # hold the point where the tool is (a pause: 0 s)
            n = int(round(stop_seconds(seg) / period))
            points.append(np.repeat(points[-1][-1:], n, 0))
            feeds.append(np.zeros(n))
        elif seg.kind == "nurbs":
            smp = baseline_samples(algorithm, seg, machine)
            points.append(smp.points_mm[1:])
            feeds.append(smp.v_mm_s[1:])
        else:
            v = lim.rapid_mm_s if seg.kind == "rapid" else min(seg.feed_mm_s, lim.v_max_mm_s)
            pts = _constant_feed_samples(geometry_of(seg), v, period)
            points.append(pts)
            feeds.append(np.full(len(pts), v))
        lines.append(np.full(len(points[-1]), seg.line))
    pts = np.vstack(points)
    v = np.concatenate(feeds)
    v[-1] = 0.0
    n = pts.shape[0]
    seg_len = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    return Samples(
        t_s=np.arange(n) * period,
        tau_s=None,
        points_mm=pts,
        s_mm=np.concatenate(([0.0], np.cumsum(seg_len))),
        v_mm_s=v,
        a_mm_s2=np.gradient(v, period) if n > 1 else np.zeros(n),
        piece=np.zeros(n, dtype=np.int64),
        line=np.concatenate(lines).astype(np.int64),
        param=None,
    )
