"""What a rapid's stop before a cut costs under the 15 µm guarantee (issue 35): lsim study.

    .venv/bin/python bench/rapid_end_study.py

A rapid (G0) along X at 3500 mm/min ends where a cut starts; from the instant its reference
arrives there, the tool (scipy.signal.lsim of the X axis's model in
bench/programs/linuxcnc_limits.toml: SPEC eq. 25, Table 2) must stay within ε = 15 µm of that
point (the settle and the cut's first samples are checked against the cut; worst case, a
cut across the rapid's direction). Shapes of the
stop, each costed as the time it adds to a rapid of fixed length over a stop at the full
deceleration A (whose tool passes the point by c₂·A ≈ 70 µm):

- the S-curve end the contour check gives a rapid's descent: A, then the deceleration ramped
  linearly to 0 over T_r (the same speed change);
- a stop d short of the point at the full A, a wait, then a creep over d at a deceleration
  a ≤ A (a triangle), the whole approach within the axis limit.

Prints the cheapest of each family within ε (a 0.1 ms grid of the reference, sampled at the
servo period as the planner writes it) under two criteria: ``after`` (within ε from the
arrival on: what the contour check enforces on the settle and the cut) and ``always`` (also
never past the point by more than ε while the reference is still on the rapid).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy import signal

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from nurbscnc.machine.profile import load_machine  # noqa: E402

PROFILE = ROOT / "bench" / "programs" / "linuxcnc_limits.toml"
EPS_MM = 0.0145  # ε with 0.5 µm of margin for the grid
FINE_S = 1e-4


def _tool(machine, fine_mm: np.ndarray, v0_mm_s: float, t_arrive_s: float):
    """The X axis's tool (lsim) for a reference that cruises at v0 for 0.3 s, then follows
    ``fine_mm`` (positions every FINE_S, ending at 0, the cut's start); returns the tool
    sampled at the servo period, the index of the first sample at or after the arrival and
    the index where the stop begins."""
    period = machine.servo.period_s
    model = machine.servo.x
    tc = np.arange(0.0, 0.3, period)
    cruise = fine_mm[0] + v0_mm_s * (tc - 0.3)
    ts = np.arange(0.0, t_arrive_s + 0.3, period)
    stop = np.interp(ts, np.arange(fine_mm.size) * FINE_S, fine_mm, right=fine_mm[-1])
    ref = np.concatenate([cruise, stop])
    t = np.arange(ref.size) * period
    system = signal.lti(model.numerator, model.denominator)
    _, y, _ = signal.lsim(system, ref - ref[0], t, interp=True)
    y = y + ref[0] * model.b0 / model.a0
    return y, tc.size + int(np.ceil(t_arrive_s / period - 1e-9)), tc.size


def _cost_s(fine_mm: np.ndarray, t_stop_s: float, v0: float, a: float) -> float:
    """Time added to a rapid of fixed length over the full-A stop: the stop's duration less
    the cruise time its distance replaces, against the full-A stop's v0/2A."""
    return (t_stop_s - (-fine_mm[0]) / v0) - v0 / (2.0 * a)


def _full_stop(v0: float, a: float) -> tuple[np.ndarray, float]:
    t_s = v0 / a
    t = np.arange(0.0, t_s + FINE_S, FINE_S)
    x = v0 * t - 0.5 * a * t * t
    return x - x[-1], t_s


def s_curve_end(machine, v0: float, a: float) -> dict:
    """The cheapest T_r (5 ms grid) of the S-curve end within ε, for each criterion
    (``after``: from the arrival on; ``always``: also never past the point before it):
    (cost [ms], T_r [ms], largest error [µm])."""
    best: dict = {}
    for tr_ms in range(5, 120, 5):
        n = int(round(tr_ms * 1e-3 / FINE_S))
        ramp = a * (1.0 - (np.arange(n) + 0.5) / n)
        n_a = int(round(max(v0 - ramp.sum() * FINE_S, 0.0) / a / FINE_S))
        dec = np.concatenate([np.full(n_a, a), ramp])
        v = np.maximum(v0 - np.cumsum(dec) * FINE_S, 0.0)
        x = np.cumsum(v) * FINE_S
        x = x - x[-1]
        t_s = dec.size * FINE_S
        y, arrive, start = _tool(machine, np.concatenate([x, np.zeros(3000)]), v0, t_s)
        cost = 1e3 * _cost_s(x, t_s, v0, a)
        _keep(best, y, arrive, start, (cost, tr_ms))
    return best


def _keep(best: dict, y: np.ndarray, arrive: int, start: int, row: tuple) -> None:
    """Record ``row`` (cost first) as the best of each criterion it meets."""
    after = float(np.abs(y[arrive:]).max())
    always = max(after, float(y[start:].max()))
    for name, err in (("after", after), ("always", always)):
        if err <= EPS_MM and (name not in best or row[0] < best[name][0]):
            best[name] = (*row, 1e3 * err)


def short_stop_and_creep(machine, v0: float, a: float) -> dict:
    """The cheapest stop short by d, wait, creep over d at ≤ A within ε, per criterion (as
    :func:`s_curve_end`): (cost [ms], d [µm], creep deceleration [mm/s²], wait [ms],
    largest error [µm])."""
    x, t_s = _full_stop(v0, a)
    best: dict = {}
    for d_um in range(10, 75, 3):
        d = d_um * 1e-3
        for a_c in (600.0, 1000.0, 1500.0, 2000.0, a):
            tt = 2.0 * np.sqrt(d / a_c)
            n = max(int(np.ceil(tt / FINE_S)), 1)
            t = np.arange(1, n + 1) * tt / n
            creep = np.where(t <= tt / 2, 0.5 * a_c * t * t, d - 0.5 * a_c * (tt - t) ** 2)
            for wait_ms in range(0, 16):
                wait = np.full(int(round(wait_ms * 1e-3 / FINE_S)), -d)
                fine = np.concatenate([x - d, wait, creep - d, np.zeros(3000)])
                t_arrive = t_s + wait_ms * 1e-3 + tt
                y, arrive, start = _tool(machine, fine, v0, t_arrive)
                cost = 1e3 * _cost_s(fine, t_arrive, v0, a)
                _keep(best, y, arrive, start, (cost, d_um, a_c, wait_ms))
    return best


def main() -> int:
    machine = load_machine(PROFILE)
    v0 = float(machine.limits.rapid_mm_s)
    a = float(machine.axis_limits.as_arrays()[1][0])
    x, t_s = _full_stop(v0, a)
    y, arrive, _ = _tool(machine, np.concatenate([x, np.zeros(3000)]), v0, t_s)
    print(f"rapid {v0:.2f} mm/s, A = {a:.0f} mm/s², servo period {machine.servo.period_s} s")
    print(f"full-A stop: the tool passes the point by {1e3 * float(y[arrive:].max()):.1f} µm")
    for name, rows in (
        ("S-curve end (cost ms, T_r ms, error µm)", s_curve_end(machine, v0, a)),
        (
            "short stop + creep (cost ms, d µm, a mm/s², wait ms, error µm)",
            short_stop_and_creep(machine, v0, a),
        ),
    ):
        for crit, row in rows.items():
            print(f"{name}, {crit}: " + ", ".join(f"{x:.4g}" for x in row))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
