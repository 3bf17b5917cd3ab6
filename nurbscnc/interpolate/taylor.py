"""The paper's 2nd-order Taylor interpolator on NURBS (SPEC §3, eq. 4–5): the one recurrence.

Used by the interpolator (``interpolator="taylor"``: NURBS pieces of a plan) and by the
paper's baselines (:mod:`nurbscnc.interpolate.baselines`), which set the feed from the
curvature at every step. The recurrence is sequential by nature: a tight scalar loop per run
of NURBS samples.
"""

from __future__ import annotations

from bisect import bisect_right
from math import sqrt

import numpy as np

from nurbscnc.geometry.path import Kind, PathTable, equal_runs
from nurbscnc.geometry.powerform import PowerForm


def taylor_increment(
    v_mm_s: float, a_mm_s2: float, dt_s: float, speed: float, speed2: float, dot: float
) -> float:
    """Δu of one step of the 2nd-order Taylor interpolator (SPEC §3, eq. 4–5):
    Δu = V Δt/|C′| + (Δt²/2)(A/|C′| − V² (C′·C″)/|C′|⁴), with ``speed`` = |C′|, ``speed2`` =
    |C′|² and ``dot`` = C′·C″ at the current u (plain floats: it runs once per servo step)."""
    return v_mm_s * dt_s / speed + 0.5 * dt_s * dt_s * (
        a_mm_s2 / speed - v_mm_s * v_mm_s * dot / (speed2 * speed2)
    )


def taylor_params(
    pf: PowerForm,
    u0: float,
    v_mm_s: np.ndarray,
    a_mm_s2: np.ndarray,
    dt_s: np.ndarray,
    u_min: float,
    u_max: float,
    u_rest=None,
) -> tuple[np.ndarray, np.ndarray]:
    """Parameters u_k of the 2nd-order Taylor interpolator (SPEC §3, eq. 4–5) and their spans.

    u_{k+1} = u_k + V_k Δt_k/|C′| + (Δt_k²/2)(A_k/|C′| − V_k² (C′·C″)/|C′|⁴), C′, C″ at u_k,
    from u_0 = ``u0``; ``v_mm_s``, ``a_mm_s2`` (n,) the feed and tangential acceleration at
    step k, ``dt_s`` (n − 1,) the profile time between samples (T_s, less across a dwell).
    u is kept in [``u_min``, ``u_max``]. Where the profile is at rest (V = A = 0) the next
    step would not move, and if ``u_rest`` (n,) is given u is re-synchronised there to
    ``u_rest`` (the exact parameter): the controller knows where a stopped tool must be.

    The recurrence is sequential, so this is a tight loop over samples with Python floats;
    C′ and C″ come from the knot span's power form (Horner with derivatives, 4 homogeneous
    components) and the quotient rule.
    """
    n = int(np.size(v_mm_s))
    us = [0.0] * n
    js = [0] * n
    if n == 0:
        return np.empty(0), np.empty(0, dtype=np.intp)
    p = pf.degree
    breaks = pf.breaks.tolist()
    centers = pf.centers.tolist()
    last = len(centers) - 1
    # Per span: coefficient rows (x, y, z, w) from degree p − 1 down to 0; the top row apart.
    rows = np.transpose(pf.coeffs, (2, 0, 1))  # (span, k, component)
    top = [tuple(r) for r in rows[:, p, :].tolist()]
    lower = [[tuple(r) for r in span_rows[p - 1 :: -1]] for span_rows in rows.tolist()]
    vs, acs, dts = v_mm_s.tolist(), a_mm_s2.tolist(), dt_s.tolist()
    rest = u_rest.tolist() if u_rest is not None else None
    u = min(max(float(u0), u_min), u_max)
    j = min(max(bisect_right(breaks, u) - 1, 0), last)
    for k in range(n):
        v, acc = vs[k], acs[k]
        if rest is not None and v == 0.0 and acc == 0.0 and u != rest[k]:
            u = rest[k]
            j = min(max(bisect_right(breaks, u) - 1, 0), last)
        us[k] = u
        js[k] = j
        if k == n - 1:
            break
        dt = dts[k]
        x = u - centers[j]
        # Horner with first and second derivative (X2 holds A''/2), 4 components.
        x0, y0, z0, w0 = top[j]
        x1 = y1 = z1 = w1 = x2 = y2 = z2 = w2 = 0.0
        for cx, cy, cz, cw in lower[j]:
            x2 = x2 * x + x1
            y2 = y2 * x + y1
            z2 = z2 * x + z1
            w2 = w2 * x + w1
            x1 = x1 * x + x0
            y1 = y1 * x + y0
            z1 = z1 * x + z0
            w1 = w1 * x + w0
            x0 = x0 * x + cx
            y0 = y0 * x + cy
            z0 = z0 * x + cz
            w0 = w0 * x + cw
        # Quotient rule: C = A/w, C' = (A' − w'C)/w, C''/2 = (A''/2 − w'C' − (w''/2) C)/w.
        iw = 1.0 / w0
        cx, cy, cz = x0 * iw, y0 * iw, z0 * iw
        dx, dy, dz = (x1 - w1 * cx) * iw, (y1 - w1 * cy) * iw, (z1 - w1 * cz) * iw
        ex = (x2 - w1 * dx - w2 * cx) * iw
        ey = (y2 - w1 * dy - w2 * cy) * iw
        ez = (z2 - w1 * dz - w2 * cz) * iw
        speed2 = dx * dx + dy * dy + dz * dz
        speed = sqrt(speed2)
        dot = 2.0 * (dx * ex + dy * ey + dz * ez)  # C'·C''
        u += taylor_increment(v, acc, dt, speed, speed2, dot)
        if u > u_max:
            u = u_max
        elif u < u_min:
            u = u_min
        while j < last and u >= breaks[j + 1]:
            j += 1
        while j > 0 and u < breaks[j]:
            j -= 1
    return np.array(us), np.array(js, dtype=np.intp)


def taylor_nurbs(path: PathTable, samples_piece, tau, v, a, out, param) -> None:
    """Replace the exact NURBS points by the Taylor interpolator's (in place): one recurrence
    per run of consecutive samples on one curve, started at the exact u of the run's first
    sample. ``tau`` (N,) profile times [s], ``v``, ``a`` the planned feed [mm/s] and
    tangential acceleration [mm/s²]; ``out`` (N, 3) points [mm], ``param`` (N,) parameters."""
    kind = np.take(path.kind, samples_piece)
    cid = np.where(kind == Kind.NURBS, np.take(path.obj_id, samples_piece), -1)
    dt = np.diff(tau)
    for a_, z in equal_runs(cid):
        c = int(cid[a_])
        if c < 0:
            continue
        curve = path.objects[c]
        pf = curve.power_form
        u_min = float(path.u_a[samples_piece[a_]])
        u_max = float(path.u_b[samples_piece[z - 1]])
        u, spans = taylor_params(
            pf, param[a_], v[a_:z], a[a_:z], dt[a_ : z - 1], u_min, u_max, u_rest=param[a_:z]
        )
        out[a_:z] = pf.point(u, spans)
        param[a_:z] = u
