"""The U curve's search (nurbscnc.geometry.turnaround._best) tests each candidate's regularity
before its distances: the same choice as measuring every candidate fully in order of cost.

The reference is the search as it was before (the full measure of each candidate in order, the
first that passes kept), written out here; the two must agree exactly — the same candidate,
the same deviation, curvature and length floats, or both None — on random turn-arounds:
raster turns (reversed passes a stepover apart), near-reversals, 3-D turns, and the
retraced paths of PCB isolation (back over a few µm just cut), where every candidate the
coarse measure passes is irregular (a cusp between its samples) and no U fits.
"""

from __future__ import annotations

import numpy as np
import pytest

from nurbscnc.geometry import turnaround as ta


def _reference_best(c1, t_a, c2, t_b, d, alpha, tolerance_mm: float):
    """The search with the full measure of every candidate in order of cost."""
    ctrl = ta.turn_controls(c1, t_a, c2, t_b, d, alpha)
    corner_path = np.stack(
        [ctrl[:, 0], np.broadcast_to(c1, ctrl[:, 0].shape), np.broadcast_to(c2, ctrl[:, 0].shape)]
        + [ctrl[:, 5]],
        axis=1,
    )
    dev, kmax, length, regular = ta._measure(ctrl, corner_path, ta.COARSE_CURVE, ta.COARSE_SIDE)
    near = regular & (dev <= tolerance_mm * (1.0 + ta.COARSE_SLACK)) & np.isfinite(kmax)
    cost = np.where(near, length * np.sqrt(kmax), np.inf)
    for i in np.argsort(cost)[: int(near.sum())].tolist():
        dev_i, kmax_i, length_i, regular_i = ta._measure(ctrl[i : i + 1], corner_path[i : i + 1])
        if regular_i[0] and dev_i[0] <= tolerance_mm and np.isfinite(kmax_i[0]):
            return (
                float(d[i]),
                float(alpha[i]),
                float(dev_i[0]),
                float(kmax_i[0]),
                float(length_i[0]),
            )
    return None


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def _turn(rng, kind: str):
    """Corners c1, c2 and unit tangents t_a (in), t_b (out) of a random turn-around."""
    width = rng.uniform(0.05, 1.5)
    c1 = rng.uniform(-50.0, 50.0, 3)
    if kind == "raster":  # a pass, a stepover at 90°, the pass back
        t_a = _unit([1.0, 0.0, 0.0])
        step = _unit([0.0, 1.0, 0.0])
        t_b = -t_a
    elif kind == "reversal":  # 150°–180° between the passes, a short middle line
        ang = np.radians(rng.uniform(150.0, 180.0))
        t_a = _unit([1.0, 0.0, 0.0])
        t_b = _unit([np.cos(ang), np.sin(ang), 0.0])
        step = _unit(t_a * rng.uniform(-0.3, 0.3) + [0.0, 1.0, 0.0])
    elif kind == "retrace":  # PCB isolation: a path back over itself after a few µm on
        width = rng.uniform(0.004, 0.02)
        t_a = _unit([1.0, 0.0, 0.0])
        step = _unit([1.0, rng.uniform(-0.02, 0.02), 0.0])
        t_b = _unit([-1.0, rng.uniform(-0.03, 0.03), 0.0])
    else:  # 3-D: a raster in a tilted plane (ball-nose surfacing)
        t_a = _unit(rng.normal(size=3))
        step = _unit(np.cross(t_a, rng.normal(size=3)))
        t_b = -t_a + rng.normal(scale=0.05, size=3)
        t_b = _unit(t_b)
    c2 = c1 + width * step
    return c1, t_a, c2, t_b, width


@pytest.mark.parametrize("kind", ["raster", "reversal", "retrace", "space"])
def test_the_search_chooses_as_the_full_measure_of_every_candidate(kind, monkeypatch):
    rng = np.random.default_rng({"raster": 1, "reversal": 2, "retrace": 3, "space": 4}[kind])
    measure = ta._measure
    full = {"search": 0, "reference": 0}  # full measures made by each
    counting = ["search"]

    def counted(ctrl, corner_path, n_curve=ta.N_CURVE, n_side=ta.N_ARC):
        full[counting[0]] += n_curve == ta.N_CURVE
        return measure(ctrl, corner_path, n_curve, n_side)

    monkeypatch.setattr(ta, "_measure", counted)
    found = none = 0
    for _ in range(60):
        c1, t_a, c2, t_b, width = _turn(rng, kind)
        tol = float(rng.choice([0.002, 0.005, 0.01, 0.05, 0.1]))
        # Retraced paths: trims of a few % of the retrace (no U fits, all irregular), or
        # larger (irregular candidates first, then a regular one that fits).
        spread = (0.5, 3.0) if kind != "retrace" or rng.random() < 0.5 else (0.03, 0.1)
        max_trim = width * rng.uniform(*spread)
        d = np.repeat(ta.D_FRACTIONS * max_trim, ta.ALPHA_FRACTIONS.size)
        alpha = d * np.tile(ta.ALPHA_FRACTIONS, ta.D_FRACTIONS.size)
        counting[0] = "search"
        got = ta._best(c1, t_a, c2, t_b, d, alpha, tol)
        counting[0] = "reference"
        want = _reference_best(c1, t_a, c2, t_b, d, alpha, tol)
        assert got == want  # the same candidate and the same floats, or both None
        found += got is not None
        none += got is None
    assert none > 0 and found > 0
    if kind == "retrace":  # candidates refused on their regularity alone: no full measure
        assert full["search"] < full["reference"]
