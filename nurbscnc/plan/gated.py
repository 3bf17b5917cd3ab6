"""Gated flanks: a jerk-limited rise under a staircase of speed caps (*gates*), greedy in
time steps (:func:`gated_rise_py`, the specification of the compiled
``_kernels.gated_rise``), remembered per flank (:func:`gated_rise_of`)."""

from __future__ import annotations

import functools
import math

import numpy as np

from nurbscnc.plan.compiled import as_float64
from nurbscnc.plan.compiled import kernels as _kernels  # None: the Python loops

#: Time step [s] of the gated flanks' jerk choice (:func:`gated_rise`): 0.1 ms, a tenth
#: of a servo period; the loss against the continuous optimum is of that order per gate.
GATE_STEP_S = 1e-4
#: Shortest switch step [s] of a gated flank (:func:`_longest`).
GATE_MIN_STEP_S = 1e-7
#: Most steps of one gated flank (a rise of 10 s at 0.1 ms); beyond it the unit is split.
GATE_MAX_STEPS = 100_000
#: Most :data:`GATE_STEP_S` steps of +J taken as one (:func:`gated_rise`'s galloping).
GATE_GALLOP = 64


def _brake_ok(
    x: float, v: float, a: float, j: float, gate_d: list, gate_c: list, first: int
) -> bool:
    """Whether braking the acceleration ``a`` ≥ 0 at once (jerk −j until a = 0, then
    cruising) from position ``x`` [mm] at speed ``v`` passes every gate from ``first`` on:
    v(gate_d[m]) ≤ gate_c[m]. During the brake v = v + a t − j t²/2 rises to
    v + a²/(2j); a gate of cap c with v ≤ c < v + a²/(2j) is passed in time if the brake
    reaches speed c, at t_c = (a − √(a² − 2j(c − v)))/j, no earlier than the gate:
    x(t_c) ≥ d."""
    v_end = v + a * a / (2.0 * j)
    for m in range(first, len(gate_d)):
        c = gate_c[m]
        if c >= v_end:
            continue
        if v > c:
            return False
        t_c = (a - math.sqrt(max(a * a - 2.0 * j * (c - v), 0.0))) / j
        if x + t_c * (v + t_c * (0.5 * a - t_c * j / 6.0)) < gate_d[m]:
            return False
    return True


def _longest(ok, tau: float) -> float:
    """The longest step in [0, ``tau``] [s] that ``ok`` accepts: ``tau`` itself, else found
    by bisection (to 1e-12 s; feasibility falls with the step), 0 when even
    :data:`GATE_MIN_STEP_S` fails (no endless creeping along a gate's boundary).
    An exact switch inside a step makes a flank touch its gates instead of turning a step
    early (a staircase 58 → 12 mm/s then met within 1e-9 s of the exact S-curve)."""
    if ok(tau):
        return tau
    if not ok(GATE_MIN_STEP_S):
        return 0.0
    lo, hi = GATE_MIN_STEP_S, tau
    while hi - lo > 1e-12:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ok(mid) else (lo, mid)
    return lo


def gated_rise(
    v0: float, v_top: float, gate_d, gate_c, a_max: float, j_max: float, dt: float = GATE_STEP_S
):
    """:func:`gated_rise_py`, compiled where :mod:`nurbscnc.plan._kernels` was built (the
    same numbers bit for bit)."""
    if _kernels is None:
        return gated_rise_py(v0, v_top, gate_d, gate_c, a_max, j_max, dt)
    return _kernels.gated_rise(
        float(v0),
        float(v_top),
        as_float64(gate_d),
        as_float64(gate_c),
        float(a_max),
        float(j_max),
        float(dt),
        GATE_MIN_STEP_S,
        GATE_GALLOP,
        GATE_MAX_STEPS,
    )


def gated_rise_py(
    v0: float, v_top: float, gate_d, gate_c, a_max: float, j_max: float, dt: float = GATE_STEP_S
):
    """A rise from (``v0``, a = 0) to (``v_top``, a = 0) under *gates*: at distance
    ``gate_d[m]`` [mm] from the start (increasing) the speed must be ≤ ``gate_c[m]`` [mm/s],
    with |a| ≤ ``a_max``, |j| ≤ ``j_max``, the speed never falling (a ≥ 0).

    This is the flank of a planning unit over a staircase of caps: a rising
    staircase read forwards, or a falling one read backwards (the descent into an airfoil's
    nose, time reversed: jerk keeps its sign, acceleration flips). The speed is non-decreasing,
    so on each piece it is largest at the piece's far end, the gate: a rise that meets every
    gate stays under every cap, without ending its acceleration at each of them (the unit
    split does: a = 0 at every cell).

    Greedy in time steps of ``dt`` (the jerk is piecewise constant, so every step is exact):
    the largest jerk of +J, 0, −J whose new state can still brake its acceleration to 0
    without exceeding ``v_top`` (v + a²/(2J) ≤ v_top) or any gate ahead (:func:`_brake_ok`);
    the target is met exactly by solving for the switch time inside the last step.

    Two shortcuts take the same steps (up to rounding), as feasibility falls with the step
    (the premise of :func:`_longest`). Galloping: after a full +J step, n = 2, 4, … up to
    :data:`GATE_GALLOP` steps of +J are tried as one while none of them could be the last
    rise (a₁ = √(J(v_top − v) + a²/2) is constant under +J, so the step whose end would
    start it is known) nor pass A; if the n-step passes, each of its steps would have.
    While braking, the +J and hold tries test their shortest step first: it fails as long
    as the brake goes on, and then so would the full step.

    Each step is one function (:class:`_Flank` holds the state): the +J step or the last
    rise (:func:`_rise_step`), the hold of ``a`` or the brake into ``v_top``
    (:func:`_hold_step`), the brake (:meth:`_Flank.brake`), the cruise past a gate
    (:meth:`_Flank.cruise_past_gate`); the C kernel's ``rise_loop`` takes the same steps, in
    the same floating-point operations.

    Returns (durations, jerks, distance) — lists of the constant-jerk phases [s], [mm/s³]
    and the distance covered [mm] — or None when no such rise exists (a gate below ``v0``,
    or too many steps).
    """
    f = _Flank(v0, gate_d, gate_c, a_max, j_max)
    tol = v_top * 1e-12
    steps, streak = 0, 0  # streak: dt steps of the last +J step, if full
    while steps < GATE_MAX_STEPS:
        steps += 1
        f.pass_gates()
        if f.a <= 0.0 and f.v >= v_top - tol:
            return f.durs, f.jerks, f.x
        done = None
        if f.a < f.big_a:  # +J, possibly the last rise before the brake into v_top
            done, taken = _rise_step(f, v_top, dt, streak, steps)
            if taken is not None:
                streak, steps = taken
                continue
        streak = 0
        if done is None and f.a > 0.0:  # hold a, possibly until the brake into v_top
            done, held = _hold_step(f, v_top, dt)
            if held:
                continue
        if done is not None:
            for tau, jk in done:
                if tau > 0.0:
                    f.take(tau, jk)
            return f.durs, f.jerks, f.x
        if f.a > 0.0:  # brake: feasible since the last step's check
            f.brake(dt)
            continue
        if not f.cruise_past_gate():
            return None
    return None


class _Flank:
    """The state of a gated rise (:func:`gated_rise_py`): the gates ``gate_d`` [mm],
    ``gate_c`` [mm/s], the limits ``j`` [mm/s³] and ``big_a`` [mm/s²], the position ``x``
    [mm], speed ``v`` [mm/s] and acceleration ``a`` [mm/s²], ``first`` the first gate beyond
    ``x``, ``braking`` whether the last step braked, and the phases so far (``durs`` [s],
    ``jerks`` [mm/s³])."""

    def __init__(self, v0: float, gate_d, gate_c, a_max: float, j_max: float):
        self.j, self.big_a = j_max, a_max
        self.gate_d, self.gate_c = [float(d) for d in gate_d], [float(c) for c in gate_c]
        self.x, self.v, self.a = 0.0, float(v0), 0.0
        self.durs: list = []
        self.jerks: list = []
        self.first = 0
        self.braking = False

    def advance(self, tau: float, jk: float) -> tuple[float, float, float]:
        """The state (x, v, a) after ``tau`` [s] of jerk ``jk`` from the current one."""
        x, v, a = self.x, self.v, self.a
        return (
            x + tau * (v + tau * (0.5 * a + tau * jk / 6.0)),
            v + tau * (a + 0.5 * tau * jk),
            a + tau * jk,
        )

    def take(self, tau: float, jk: float) -> None:
        """Append the phase (``tau``, ``jk``) and move the state over it."""
        self.durs.append(tau)
        self.jerks.append(jk)
        self.x, self.v, self.a = self.advance(tau, jk)

    def pass_gates(self) -> None:
        """Move ``first`` past the gates at or behind ``x``."""
        while self.first < len(self.gate_d) and self.gate_d[self.first] <= self.x:
            self.first += 1

    def passes(self, x1: float, v1: float, a1: float) -> bool:
        """The state after a step: the gates crossed in it (v non-decreasing: v1 is the
        largest), then the brake from it."""
        gate_d, gate_c = self.gate_d, self.gate_c
        m = self.first
        while m < len(gate_d) and gate_d[m] <= x1:
            if v1 > gate_c[m] * (1.0 + 1e-12):
                return False
            m += 1
        return _brake_ok(x1, v1, a1, self.j, gate_d, gate_c, m)

    def finish(self, phases: list) -> bool:
        """Try ending with ``phases`` [(τ, jerk), …] (the last brakes a to 0 at v_top)."""
        xs, vs, as_ = self.x, self.v, self.a
        for tau, jk in phases[:-1]:
            xs, vs, as_ = (
                xs + tau * (vs + tau * (0.5 * as_ + tau * jk / 6.0)),
                vs + tau * (as_ + 0.5 * tau * jk),
                as_ + tau * jk,
            )
        return self.passes(xs, vs, as_)

    def longest(self, jk: float, tau: float) -> float:
        """:func:`_longest` of the step with jerk ``jk``; while braking, the shortest step
        first (:func:`gated_rise_py`)."""
        ok = lambda t: self.passes(*self.advance(t, jk))  # noqa: E731
        if self.braking and not ok(GATE_MIN_STEP_S):
            return 0.0
        return _longest(ok, tau)

    def brake(self, dt: float) -> None:
        """A step of −J of at most ``dt`` [s], ending at a = 0 when the brake is done."""
        self.braking = True
        t_b = self.a / self.j
        tau = min(dt, t_b)
        self.x, self.v, self.a = self.advance(tau, -self.j)
        if tau >= t_b or self.a < 1e-12 * self.big_a:
            self.a = 0.0
        self.durs.append(tau)
        self.jerks.append(-self.j)

    def cruise_past_gate(self) -> bool:
        """At a = 0 with a gate ahead at the speed v: cruise at v just past it (riding its
        cap); False when there is no such gate (no rise exists)."""
        first, v = self.first, self.v
        if first >= len(self.gate_d) or v <= 0.0 or v > self.gate_c[first] * (1.0 + 1e-12):
            return False
        tau = (self.gate_d[first] - self.x) / v * (1.0 + 1e-12) + 1e-15
        self.take(tau, 0.0)
        return True


def _rise_step(
    f: _Flank, v_top: float, dt: float, streak: int, steps: int
) -> tuple[list | None, tuple[int, int] | None]:
    """The +J step of :func:`gated_rise_py` (a < A): the last rise and brake into ``v_top``
    if it starts within this step and passes (returned as ``done``), else a step of +J —
    ``n`` steps at once while galloping (the step whose end would start the last rise is
    known: a₁ = √(J(v_top − v) + a²/2) is constant under +J; one step of margin), else the
    longest single step that passes. Returns (done phases or None, (streak, steps) after a
    step taken, else None)."""
    a, j, big_a = f.a, f.j, f.big_a
    a1 = math.sqrt(j * max(v_top - f.v, 0.0) + 0.5 * a * a)
    if a1 <= min(a + j * dt, big_a):
        phases = [((a1 - a) / j, j), (a1 / j, -j)]
        return (phases if f.finish(phases) else None), None
    n = min(
        2 * streak,
        GATE_GALLOP,
        int((big_a - a) / (j * dt)),
        math.ceil((a1 - a) / (j * dt)) - 2 if a1 <= big_a else GATE_GALLOP,
        GATE_MAX_STEPS - steps + 1,
    )
    if n >= 2 and f.passes(*f.advance(n * dt, j)):
        tau, steps = n * dt, steps + n - 1
    else:
        n, tau = 1, f.longest(j, min(dt, (big_a - a) / j))
    if tau > 0.0:
        streak, f.braking = (n if tau == n * dt else 0), False
        f.take(tau, j)
        return None, (streak, steps)
    return None, None


def _hold_step(f: _Flank, v_top: float, dt: float) -> tuple[list | None, bool]:
    """The hold of :func:`gated_rise_py` (a > 0, no +J step taken): the hold and brake into
    ``v_top`` if it starts within this step and passes (returned as ``done``), else the
    longest hold that passes. Returns (done phases or None, whether a hold was taken)."""
    a, j = f.a, f.j
    t0 = (v_top - f.v - a * a / (2.0 * j)) / a
    if t0 <= dt:
        phases = [(max(t0, 0.0), 0.0), (a / j, -j)]
        return (phases if f.finish(phases) else None), False
    tau = f.longest(0.0, dt)
    if tau > 0.0:
        f.braking = False
        f.take(tau, 0.0)
        return None, True
    return None, False


def merged_phases(durs: list, jerks: list) -> tuple[list, list]:
    """Consecutive phases of equal jerk as one (the cubic continues: exact)."""
    out_d: list = []
    out_j: list = []
    for d, jk in zip(durs, jerks, strict=True):
        if d <= 0.0:
            continue
        if out_j and out_j[-1] == jk:
            out_d[-1] += d
        else:
            out_d.append(d)
            out_j.append(jk)
    return out_d, out_j


#: Fewest gates (capped pieces on a flank) for a gated flank (:func:`gated_rise`, a loop in
#: 0.1 ms steps): a staircase. A flank under one lower cap keeps the split at that piece
#: (a = 0 there): on long G1 spirals nearly every flank has a single gate, and gating those
#: costs far more run time than it gains; an airfoil's nose has many gates per flank.
MIN_GATES = 2


def gated_rise_of(
    v0: float, v1: float, gates_mm: np.ndarray, caps_mm_s: np.ndarray, a: float, j: float
):
    """:func:`gated_rise`, remembered: the check re-plans the profile 5–10 times and each
    plan splits its units several times, asking for the same flanks again. A pure function
    of its numbers, so the memo changes no result; bounded (:data:`GATED_MEMO`). Returns (phases as
    a rise, phases read backwards for a descent, distance [mm]), each phase list merged
    (:func:`merged_phases`; a gated flank has hundreds of 0.1 ms steps: merging them at every ask
    was a large share of a run), or None."""
    return _gated_rise_memo(
        float(v0),
        float(v1),
        np.ascontiguousarray(gates_mm, float).tobytes(),
        np.ascontiguousarray(caps_mm_s, float).tobytes(),
        float(a),
        float(j),
    )


#: Flanks remembered by :func:`gated_rise_of` (each a few kB).
GATED_MEMO = 4096


@functools.lru_cache(maxsize=GATED_MEMO)
def _gated_rise_memo(v0, v1, gates_b: bytes, caps_b: bytes, a, j):
    if _kernels is not None:  # the flank and its merging compiled (the same floats)
        got = _kernels.gated_rise_merged(
            float(v0),
            float(v1),
            gates_b,
            caps_b,
            float(a),
            float(j),
            GATE_STEP_S,
            GATE_MIN_STEP_S,
            GATE_GALLOP,
            GATE_MAX_STEPS,
        )
        if got is None:
            return None
        return (tuple(got[0]), tuple(got[1])), (tuple(got[2]), tuple(got[3])), got[4]
    result = gated_rise(v0, v1, np.frombuffer(gates_b), np.frombuffer(caps_b), a, j)
    if result is None:
        return None
    durs, jerks, distance = result
    # Shared by every caller: immutable. The descent merges the reversed steps (its own
    # sums, in its own order: the same bits as merging at the caller).
    rise = tuple(map(tuple, merged_phases(durs, jerks)))
    fall = tuple(map(tuple, merged_phases(durs[::-1], jerks[::-1])))
    return rise, fall, distance
