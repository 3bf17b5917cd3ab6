"""The tube optimisation of a compensated reference: its offsets across the path re-chosen
within the tube about the path, by sequential linear programmes on the known servo model,
to lower the largest simulated contour error (:func:`refine_in_tube`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbscnc.geometry.distance import PathIndex, windowed_contour_mm
from nurbscnc.machine.profile import Machine
from nurbscnc.plan.dynamics import path_response
from nurbscnc.plan.timing import Reference
from nurbscnc.precompensation.frame import (
    into_tube,
    local_polyline,
    nearest_on_polyline,
    path_coordinates,
    plane_normal,
)
from nurbscnc.precompensation.limits import SampleLimits, sample_limits
from nurbscnc.servo.precompensate import axis_models

# The clip (:mod:`~nurbscnc.precompensation.apply`) keeps the ZPETC reference within the
# tube of radius τ about the path, but where the inverse wants more than τ across the path
# (entering a tight curve, the stop at the end) the clipped reference is not the best one in
# the tube. Here the offsets across the
# path are re-chosen, region by region where the simulated tool is still far from the path,
# to minimise the largest contour error there (a small linear programme on the known model):
#
#   tool   y = H u (per axis, linear: the sampled eq. 25, FOH),
#   error  e_k ≈ σ_k + ν_k · (H Δ)_k   (σ_k = |y_k − q_k|, q_k the nearest path point, ν_k the
#          unit vector from q_k to y_k: the distance to first order),
#   step   Δ_j = a_j m_j + b_j t_j   (m_j the in-plane normal, t_j the tangent of the path
#          at the reference's own foot: across and along it),
#   tube   −τ'_j ≤ μ_j + a_j ≤ τ'_j − κ_j b̄_j²/2   (μ_j the current offset across the path,
#          τ'_j the tube less any offset out of the plane; |b_j| ≤ b̄_j, the bend of a
#          straight move along a curve of curvature κ_j at most REFINE_BEND τ),
#   limits the step lengths |u_{j+1} − u_j| + b_{j+1} − b_j ≤ V T (first order) and the
#          first, second and third differences of u + Δ on every axis within the caps of
#          the limits on the samples (SampleLimits: the machine's, or the plan's own where
#          that is above them; the projection, :mod:`~nurbscnc.precompensation.limits`,
#          starts the rounds within them) — or within u's own where it is above them (a
#          start not projected: no step rougher),
#   min z  subject to  |σ_k + Σ_j G_kj (a_j, b_j)| ≤ z  over the region's tool samples,
#
# G_kj = Σ_axes ν_k,c h_c[k − j] (m_j,c, t_j,c) with h_c the axis' impulse response. Then the
# step is applied as the LP sees it (a straight move: its differences are the LP's exactly),
# the reference projected exactly into the tube again (nearest point on the path; to
# rounding a no-op), simulated, and kept only where the true largest error of the region
# went down and it is no faster or rougher than allowed (else halved, then dropped): the
# largest error never increases from round to round. Work per region:
# one dense G of (inputs + reach) × inputs ≤ REFINE_MAX_INPUTS × (REFINE_MAX_INPUTS + reach).

#: Rounds of linearise → LP → simulate (each only keeps what lowers the error).
REFINE_ROUNDS = 8
#: ... stopping early when a round lowers the largest error by less than this [mm].
REFINE_GAIN_MM = 1e-5
#: A region is the tool samples whose contour error exceeds this fraction of ε_max, with the
#: reference samples REFINE_BEFORE_S before it (the response's rise: what can still act) and
#: the tool samples the impulse response reaches after it.
REFINE_THRESHOLD = 0.9
REFINE_BEFORE_S = 0.025
#: The impulse response is followed until it is below this fraction of its peak.
REFINE_REACH = 1e-3
#: Most reference samples one LP moves (a longer region is cut into windows this long).
REFINE_MAX_INPUTS = 120
#: The share of the machine's V T a step's length may use (the first-order length is
#: exact but for the move across the path, orthogonal: its square, sub-nanometre here).
REFINE_SPEED = 0.999
#: A tool sample within this of the last try's [mm] keeps its distance to the path
#: (:func:`refine_in_tube`).
REUSE_MM = 1e-12
#: Most simplex iterations of one window's LP (HiGHS; a window not solved within them is
#: left as is). An iteration count, not a time limit: the result must not depend on how
#: fast or how busy the machine is (a 1 s wall-clock limit cut the circle's hardest windows,
#: ~8,200 iterations, ~0.8 s of CPU, whenever other processes shared the cores, and the
#: reference then changed from run to run). A window moves at most REFINE_MAX_INPUTS
#: samples, so an iteration costs at most ~0.1 ms: this bounds a window's LP to a few
#: seconds (a 300-sample window once stalled for minutes) at 5x the hardest seen.
REFINE_LP_MAX_ITER = 40_000
#: Largest move of a reference sample along the path in one round [mm] ...
REFINE_ALONG_MM = 0.02
#: ... and at most the move whose bend off a curve (κ b²/2) is this share of the tube.
REFINE_BEND = 0.2


@dataclass(frozen=True, eq=False)
class Refinement:
    """What the tube optimisation did: ``points_mm`` the reference, ``history_mm`` the
    largest contour error [mm] on the cut before the first round and after each round
    (non-increasing), ``regions`` the windows of the last round."""

    points_mm: np.ndarray
    history_mm: tuple[float, ...]
    regions: int


def _impulse_responses(machine: Machine, length: int) -> np.ndarray:
    """h (length, 3): each axis' sampled eq.-25 impulse response (FOH, the simulation's
    discretisation, :func:`~nurbscnc.servo.model.discretise`); an axis without a model
    follows its reference (h = δ)."""
    from scipy import signal

    from nurbscnc.servo.model import discretise

    h = np.zeros((length, 3))
    impulse = np.zeros(length)
    impulse[0] = 1.0
    for c, m in enumerate(axis_models(machine)):
        if m is None:
            h[0, c] = 1.0
            continue
        d = discretise(m, machine.servo.period_s, "foh")
        h[:, c] = signal.lfilter(d.b, d.a, impulse)
    return h


def _reach_samples(machine: Machine) -> int:
    """Samples after which every axis' impulse response stays below REFINE_REACH × peak."""
    h = np.abs(_impulse_responses(machine, 2000))
    big = h >= REFINE_REACH * h.max(axis=0)
    return int(max(np.flatnonzero(big.any(axis=1))[-1] + 1, 1))


def _regions(
    over: np.ndarray, before: int, reach: int, lo: int, hi: int, longest: int
) -> list[tuple[int, int, int]]:
    """Windows (j0, j1, k1) over the tool samples ``over`` (sorted): reference samples
    j0 … j1−1 move (from ``before`` ahead of a run of over-limit samples to its end, within
    [lo, hi)), tool samples j0 … k1−1 are constrained (``reach`` past j1). Runs whose windows
    would overlap are merged; a window moves at most ``longest`` samples."""
    if over.size == 0:
        return []
    cuts = np.flatnonzero(np.diff(over) > before + reach) + 1
    out = []
    for run in np.split(over, cuts):
        a, b = max(int(run[0]) - before, lo), min(int(run[-1]) + 1, hi)
        for j0 in range(a, b, longest):
            j1 = min(j0 + longest, b)
            out.append((j0, j1, j1 + reach))
    return out


def _difference_rows(u: np.ndarray, j0: int, j1: int, order: int) -> tuple:
    """The ``order``-th differences of a step Δ that is zero outside samples j0 … j1−1, on
    every row they touch (r = j0 − 1 … j1 − 2 + order, Δ_r − … centred as np.diff): the
    matrix D (rows, j1 − j0) with D·Δ[j0:j1] those differences, and the same differences
    of ``u`` (rows, 3) on those rows (edge samples repeated past the ends)."""
    n_in = j1 - j0
    coef = np.diff(np.eye(order + 1), n=order, axis=0)[0]  # e.g. [1, −2, 1]
    rows = n_in + order
    d = np.zeros((rows, n_in))
    for i, c in enumerate(coef):  # row r covers Δ_{j0 − order + r + i}
        cols = np.arange(rows) - order + i
        ok = (cols >= 0) & (cols < n_in)
        d[np.flatnonzero(ok), cols[ok]] = c
    idx = np.clip(np.arange(j0 - order, j1 + order), 0, u.shape[0] - 1)
    du = np.diff(u[idx], n=order, axis=0)  # rows j0 − order … j1 + order − 1 − order
    return d, du[:rows]


def _region_bounds(
    u: np.ndarray,
    movable: np.ndarray,
    j0: int,
    j1: int,
    poly: np.ndarray,
    tube: np.ndarray,
    kappa: np.ndarray,
):
    """The frame and bounds of a window's moves (samples j0 … j1−1): the unit tangents
    t (J, 3) and in-plane normals m (J, 3) of the path at each sample's foot on ``poly``,
    and the bounds [mm] of a (across) and |b| (along): within the tube, a = 0 for a sample
    that may not move."""
    _sigma, _at, tan_in, m, mu, rest = path_coordinates(u[j0:j1], poly)
    room = np.sqrt(np.maximum(tube[j0:j1] ** 2 - np.einsum("ij,ij->i", rest, rest), 0.0))
    room *= 1.0 - 1e-6
    fixed = ~movable[j0:j1]
    # The step is applied as the LP sees it, a straight move Δ = a m + b t (so its second
    # and third differences are exactly the LP's); a move b along the tangent of a curve of
    # curvature κ leaves the curve outward by up to κ b²/2, so b is bounded to keep that
    # bend within REFINE_BEND of the tube, and the room across is reduced by it outward.
    k = np.abs(np.nan_to_num(kappa[j0:j1], nan=0.0, posinf=0.0))
    with np.errstate(divide="ignore"):
        b_max = np.minimum(REFINE_ALONG_MM, np.sqrt(2.0 * REFINE_BEND * tube[j0:j1] / k))
    bend = 0.5 * k * b_max**2
    # (never forced to move: the current point is in the tube, so a = 0 stays allowed and
    # the LP always has a solution)
    lo_a = np.where(fixed, 0.0, np.minimum(-room - mu, 0.0))
    hi_a = np.where(fixed, 0.0, np.maximum(room - bend - mu, 0.0))
    along = np.where(fixed, 0.0, b_max)
    return tan_in, m, lo_a, hi_a, along


def _region_limit_rows(
    u: np.ndarray, j0: int, j1: int, basis: np.ndarray, caps: SampleLimits
) -> tuple[list, list]:
    """The rows of a window's LP keeping the reference within ``caps`` (module comment
    above): its step lengths (first order, REFINE_SPEED of the cap) and its first, second
    and third differences on every axis (within the cap, or ``u``'s own where it is above
    it), over the unknowns (a, b, z) with ``basis`` (2J, 3) the direction of each a and b.
    Blocks and their right-hand sides [mm]."""
    a_ub, b_ub = [], []
    # The speed: a move b along the path lengthens the step between samples j and j + 1 by
    # b_{j+1} − b_j (to first order; a move across it, orthogonal, by its square), so that
    # difference stays within what the step's cap leaves (REFINE_SPEED of it: the square).
    d, du = _difference_rows(u, j0, j1, 1)
    step = np.sqrt(np.einsum("ij,ij->i", du, du))
    at = np.clip(np.arange(j0 - 1, j1), 0, caps.step.size - 1)  # the rows' np.diff index
    a_ub.append(np.hstack([np.zeros_like(d), d, np.zeros((d.shape[0], 1))]))
    b_ub.append(np.maximum(REFINE_SPEED * caps.lp_step()[at] - step, 0.0))
    for order in (1, 2, 3):
        d, du = _difference_rows(u, j0, j1, order)
        limit = caps.lp_rows(order)
        at = np.clip(np.arange(j0 - order, j1), 0, limit.shape[0] - 1)
        for c in range(3):
            finite = np.isfinite(limit[at, c])
            if not np.any(basis[:, c]) or not finite.any():
                continue
            rows = np.hstack([d * basis[: j1 - j0, c], d * basis[j1 - j0 :, c]])[finite]
            # (within the cap, or the current reference's own where it is above it)
            cap = np.maximum(limit[at, c], np.abs(du[:, c]))[finite]
            du_c = du[finite, c]
            zero = np.zeros((rows.shape[0], 1))
            a_ub += [np.hstack([rows, zero]), np.hstack([-rows, zero])]
            b_ub += [cap - du_c, cap + du_c]
    return a_ub, b_ub


def _region_step(
    u: np.ndarray,
    y: np.ndarray,
    cut_out: np.ndarray,
    movable: np.ndarray,
    window: tuple[int, int, int],
    h: np.ndarray,
    poly: np.ndarray,
    tube: np.ndarray,
    caps: SampleLimits,
    kappa: np.ndarray,
) -> np.ndarray | None:
    """The LP step of one ``window`` (j0, j1, k1) (module comment above): (j1 − j0, 3) [mm],
    the move Δ_j = a_j m_j + b_j t_j of each sample across (in-plane normal m) and along
    (tangent t) the path, or None. ``caps`` (:class:`SampleLimits`): the reference's
    steps (their length, to first order, REFINE_SPEED of the cap) and its first, second
    and third differences on every axis stay within the caps less LIMIT_MARGIN (or within
    ``u``'s own, where it was above them already: Δ = 0 is always a solution), so the step
    never makes the reference faster or rougher than the machine's velocity, acceleration
    and jerk (the differences exactly: Δ is applied as it is here, a straight move;
    :func:`_region_limit_rows`). ``kappa`` (N,) [1/mm] the path's curvature at each
    sample (the bend of a move along it, :func:`_region_bounds`)."""
    from scipy.optimize import linprog

    j0, j1, k1 = window
    k1 = min(k1, y.shape[0])
    ks = np.arange(j0, k1)
    ks = ks[cut_out[ks]]
    if ks.size == 0:
        return None
    q, sigma, tan_out = nearest_on_polyline(y[ks], poly)
    nu = (y[ks] - q) / np.where(sigma > 1e-9, sigma, 1.0)[:, None]
    nu = np.where(sigma[:, None] > 1e-9, nu, plane_normal(tan_out))
    tan_in, m, lo_a, hi_a, along = _region_bounds(u, movable, j0, j1, poly, tube, kappa)
    # Unknowns x = (a, b, z): Δ_j = a_j m_j + b_j t_j across and along the path.
    basis = np.concatenate([m, tan_in])  # (2J, 3): the direction of each unknown
    lag = ks[:, None] - np.arange(j0, j1)[None, :]  # k − j
    valid = (lag >= 0) & (lag < h.shape[0])
    hk = h[np.clip(lag, 0, h.shape[0] - 1)] * valid[..., None]  # (K, J, 3)
    g = np.hstack(
        [np.einsum("kc,kjc,jc->kj", nu, hk, m), np.einsum("kc,kjc,jc->kj", nu, hk, tan_in)]
    )
    ones = -np.ones((ks.size, 1))
    a_ub = [np.hstack([g, ones]), np.hstack([-g, ones])]
    b_ub = [-sigma, sigma]
    n_x = 2 * (j1 - j0)
    limit_rows, limit_rhs = _region_limit_rows(u, j0, j1, basis, caps)
    a_ub += limit_rows
    b_ub += limit_rhs
    bounds = np.column_stack(
        [np.concatenate([lo_a, -along, [0.0]]), np.concatenate([hi_a, along, [np.inf]])]
    )
    cost = np.zeros(n_x + 1)
    cost[-1] = 1.0
    res = linprog(
        cost,
        A_ub=np.vstack(a_ub),
        b_ub=np.concatenate(b_ub),
        bounds=bounds,
        method="highs",
        options={"maxiter": REFINE_LP_MAX_ITER},
    )
    if res.status != 0:
        return None
    ab = res.x[:n_x].reshape(2, j1 - j0)
    return ab[0][:, None] * m + ab[1][:, None] * tan_in  # (J, 3): Δ = a m + b t


def _rougher(
    new_mm: np.ndarray, start_mm: np.ndarray, caps: SampleLimits, lo: int = 0, hi: int | None = None
) -> np.ndarray:
    """Per sample lo … hi−1: whether a difference row of ``new_mm`` within that range that it
    is in (its step length, its first, second and third differences on every axis) exceeds
    its cap of ``caps``, or ``start_mm``'s own where that was above the cap already (the
    reference the optimisation started from, so no allowance adds up over the rounds),
    beyond rounding (1e-9 of the cap, 2^k ulps of the coordinates)."""
    hi = new_mm.shape[0] if hi is None else hi
    new, old = new_mm[lo:hi], start_mm[lo:hi]
    out = np.zeros(hi - lo, dtype=bool)
    if hi - lo < 2:
        return out
    ulp = float(np.spacing(np.abs(new).max()))
    dn, do = np.diff(new, axis=0), np.diff(old, axis=0)
    step_n, step_o = (np.sqrt(np.einsum("ij,ij->i", d, d)) for d in (dn, do))
    rows = [(step_n > np.maximum(caps.step[lo : hi - 1], step_o) * (1.0 + 1e-9) + 2.0 * ulp, 1)]
    for k in (1, 2, 3):
        if hi - lo <= k:
            break
        dn, do = np.abs(np.diff(new, k, axis=0)), np.abs(np.diff(old, k, axis=0))
        cap = np.maximum(caps.rows(k)[lo : hi - k], do) * (1.0 + 1e-9) + 2.0**k * ulp
        rows.append((np.any(dn > cap, axis=1), k))
    for over, k in rows:
        for lag in range(k + 1):  # row i covers samples i … i + k
            out[lag : lag + over.size] |= over
    return out


def _no_rougher(
    new_mm: np.ndarray, start_mm: np.ndarray, j0: int, j1: int, caps: SampleLimits
) -> bool:
    """Whether every difference row about samples j0 … j1−1 of ``new_mm`` keeps its cap
    (:func:`_rougher`)."""
    lo, hi = max(j0 - 3, 0), min(j1 + 3, new_mm.shape[0])
    return not _rougher(new_mm, start_mm, caps, lo, hi).any()


def _movable(u: np.ndarray, cut: np.ndarray, held: int) -> np.ndarray:
    """The reference samples (N,) the optimisation may move: on a cut and not at rest (the
    samples either side apart), never the first nor the last ``held``."""
    n = u.shape[0]
    speed = np.zeros(n)
    if n > 2:
        speed[1:-1] = np.sqrt(np.sum((u[2:] - u[:-2]) ** 2, axis=1))
    movable = cut & (speed > 1e-9)
    movable[0] = False
    movable[n - held :] = False
    return movable


class _ToolResponse:
    """The check's simulation of a reference (:func:`~nurbscnc.plan.dynamics.path_response`:
    each axis from rest at its first point, the last point held until settled, the true
    distance near the reference and to the whole path above REFINE_THRESHOLD × ε_max), its
    discretisation made once and the settle length of the first reference ``ref`` kept: the
    same numbers at a fraction of the cost per round.

    The last response's tool samples and their distances are kept: a try moves the
    reference in a few regions, so most tool samples are where they were (bit for bit before
    the first moved input; within 1e-12 mm after the servo's tail has died out) and keep
    their distance (the distance to a set is 1-Lipschitz: off by at most that much), which
    spares most of the global distance queries, the costly part of a round."""

    def __init__(
        self, ref: Reference, pieces, profile, machine: Machine, index: PathIndex, cut: np.ndarray
    ):
        from nurbscnc.servo.model import discretise

        n = ref.points_mm.shape[0]
        period = machine.servo.period_s
        first = path_response(ref, pieces, profile, machine, index=index)
        self.extra = extra = first.actual_mm.shape[0] - n
        self.discs = [
            None if m is None else discretise(m, period, "foh") for m in axis_models(machine)
        ]
        self.s_out = np.concatenate((ref.s_mm, np.full(extra, ref.s_mm[-1])))
        self.cut_out = np.append(cut, np.full(extra, cut[-1]))
        self.pieces, self.profile, self.index = pieces, profile, index
        self.eps = machine.limits.contour_tolerance_mm
        self.last: dict = {}

    def __call__(self, points: np.ndarray):
        """The tool samples of the reference ``points`` (N, 3) [mm] (N + settle, 3), their
        contour errors [mm] (0 off the cut) and which of them are on a cut."""
        from scipy import signal

        last = self.last
        held = np.vstack([points, np.repeat(points[-1:], self.extra, axis=0)])
        actual = held.copy()
        for c, d in enumerate(self.discs):
            if d is not None:
                x = held[:, c] - points[0, c]
                actual[:, c] = signal.lfilter(d.b, d.a, x) + d.dc_gain * points[0, c]
        lag = np.sqrt(np.sum((held - actual) ** 2, axis=1))
        contour = windowed_contour_mm(actual, lag, self.s_out, self.pieces, self.profile)
        sel = np.flatnonzero(contour > REFINE_THRESHOLD * self.eps)
        if sel.size:
            kept = np.zeros(sel.size, dtype=bool)
            if last:  # measured last time (over the threshold then) at the same place
                kept = last["over"][sel] & np.all(
                    np.abs(actual[sel] - last["actual"][sel]) <= REUSE_MM, axis=1
                )
                same = sel[kept]
                contour[same] = np.minimum(contour[same], last["contour"][same])
            fresh = sel[~kept]
            if fresh.size:
                contour[fresh] = self.index.distance_mm(actual[fresh], contour[fresh])
        over = np.zeros(contour.size, dtype=bool)
        over[sel] = True
        last.update(actual=actual, contour=contour.copy(), over=over)
        return actual, np.where(self.cut_out, contour, 0.0), self.cut_out


def _window_steps(
    ref: Reference,
    pieces,
    profile,
    u: np.ndarray,
    y: np.ndarray,
    cut_out: np.ndarray,
    movable: np.ndarray,
    windows: list,
    h: np.ndarray,
    tube_mm: np.ndarray,
    caps: SampleLimits,
    kappa: np.ndarray,
) -> list:
    """The LP step of each of the round's ``windows`` (:func:`_region_step`) that has one:
    (j0, j1, k1, step (j1 − j0, 3) [mm], the window's polyline of the path)."""
    n = u.shape[0]
    steps = []
    for j0, j1, k1 in windows:
        # The path under the window's reference and tool samples (the tool within 2|u − y|
        # of its reference along the path, as windowed_contour_mm).
        s_in = ref.s_mm[j0 : min(k1, n)]
        margin = 2.0 * float(np.max(np.abs(u[j0 : min(k1, n)] - y[j0 : min(k1, n)]))) + 0.05
        poly = local_polyline(
            pieces, profile, float(s_in.min()) - margin, float(s_in.max()) + margin
        )
        step = _region_step(u, y, cut_out, movable, (j0, j1, k1), h, poly, tube_mm, caps, kappa)
        steps.append((j0, j1, k1, step, poly))
    return [s for s in steps if s[3] is not None]


def _try_steps(
    u: np.ndarray,
    err: np.ndarray,
    steps: list,
    movable: np.ndarray,
    tube_mm: np.ndarray,
    start: np.ndarray,
    caps: SampleLimits,
    response: _ToolResponse,
) -> tuple[np.ndarray, np.ndarray]:
    """The reference ``u`` with each window's step of ``steps`` kept where the window's own
    largest error went down and the reference is no rougher there than ``start``'s
    (:func:`_no_rougher`): the full step, else half, else a quarter; the windows' tool
    samples are disjoint, their effects add. Returns the new reference and which windows
    were kept."""
    alpha = np.ones(len(steps))
    done = np.zeros(len(steps), dtype=bool)
    base = u.copy()
    for _attempt in range(3):
        trial = base.copy()
        for i, (j0, j1, _k1, step, poly) in enumerate(steps):
            if done[i]:
                continue
            moved = base[j0:j1] + alpha[i] * step
            moved = into_tube(moved, poly, tube_mm[j0:j1])  # (to rounding: a no-op)
            trial[j0:j1] = np.where(movable[j0:j1, None], moved, base[j0:j1])
        _y_t, err_t, _ = response(trial)
        for i, (j0, j1, k1, _step, _poly) in enumerate(steps):
            if done[i]:
                continue
            k1 = min(k1, err.size)
            if float(err_t[j0:k1].max()) < float(err[j0:k1].max()) - 1e-9 and _no_rougher(
                trial, start, j0, j1, caps
            ):
                done[i] = True
                base[j0:j1] = trial[j0:j1]
            else:
                alpha[i] *= 0.5
        if done.all():
            break
    return base, done


def _take_back_rough(
    base: np.ndarray,
    u: np.ndarray,
    start: np.ndarray,
    steps: list,
    done: np.ndarray,
    caps: SampleLimits,
) -> None:
    """Windows next to each other were each checked with the other's step in: one whose
    neighbour was then not kept is taken back (``base`` set to ``u`` there, ``done``
    cleared; both in place) where a row across them breaks a cap (:func:`_rougher`)."""
    for _undo in range(len(steps)):
        bad = _rougher(base, start, caps)
        hit = [
            i
            for i, (j0, j1, *_rest) in enumerate(steps)
            if done[i] and bad[max(j0 - 3, 0) : j1 + 3].any()
        ]
        if not hit:
            break
        for i in hit:
            j0, j1 = steps[i][:2]
            base[j0:j1] = u[j0:j1]
            done[i] = False


def refine_in_tube(
    ref: Reference,
    pieces,
    profile,
    machine: Machine,
    tube_mm: np.ndarray,
    rounds: int = REFINE_ROUNDS,
    gain_mm: float = REFINE_GAIN_MM,
    caps: SampleLimits | None = None,
    held: int = 1,
) -> Refinement:
    """The reference ``ref`` (its points within ``tube_mm`` (N,) of the path) with its
    offsets across the path re-chosen where the simulated contour error exceeds
    REFINE_THRESHOLD × ε_max, to minimise the largest error there (module comment above:
    sequential LPs on the known model, each round kept only where it lowers the error).
    Samples at rest, on rapids, the first and the last ``held`` samples do not move. ``caps``
    (:class:`SampleLimits`, default the machine's limits alone) bound the differences of
    the reference (:func:`_region_step`): a reference within them stays within them, one
    above them never gets rougher where it is (:func:`_rougher`)."""
    eps = machine.limits.contour_tolerance_mm
    u = np.array(ref.points_mm, dtype=float)
    n = u.shape[0]
    cut = ~pieces.rapid[ref.piece]
    movable = _movable(u, cut, held)
    index = PathIndex(pieces)
    reach = _reach_samples(machine)
    h = _impulse_responses(machine, reach)
    period = machine.servo.period_s
    before = max(int(round(REFINE_BEFORE_S / period)), 1)
    if caps is None:
        caps = sample_limits(np.zeros_like(u), machine)
    # The path's curvature at each sample (its piece's largest) [1/mm]: the bend bound.
    kappa = np.asarray(pieces.kappa_max_per_mm, dtype=float)[ref.piece]
    response = _ToolResponse(ref, pieces, profile, machine, index, cut)

    start = u.copy()
    y, err, cut_out = response(u)
    history = [float(err.max())]
    windows: list = []
    for _ in range(rounds):
        over = np.flatnonzero(err > REFINE_THRESHOLD * eps)
        windows = _regions(over, before, reach, 1, n - 1, REFINE_MAX_INPUTS)
        steps = _window_steps(
            ref, pieces, profile, u, y, cut_out, movable, windows, h, tube_mm, caps, kappa
        )
        if not steps:
            break
        base, done = _try_steps(u, err, steps, movable, tube_mm, start, caps, response)
        _take_back_rough(base, u, start, steps, done, caps)
        if not done.any():
            history.append(history[-1])
            break
        y_t, err_t, _ = response(base)
        if float(err_t.max()) > history[-1]:  # a window's tail raised another's: keep none
            history.append(history[-1])
            break
        u, y, err = base, y_t, err_t
        history.append(float(err.max()))
        if history[-2] - history[-1] < gain_mm:
            break
    return Refinement(u, tuple(history), len(windows))
