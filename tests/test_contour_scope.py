"""One contour metric, one scope (plan.scope): the plan summary, ``simulate``, their JSON and
their text report the contour error of the feed moves, the rapids' apart.

corners.nc has two rapids; on them the tool is farther from the path (15.36 µm) than ε_max,
so a number over every sample would not be the summary's (the cuts reach 15.93 µm only at a
stop's overshoot within ε_max + P of its G64 vertex). ``simulate`` runs its own servo
simulation (nurbscnc.servo.simulate, the convolution form) and measures it the way the
dynamics check measures its IIR recurrence: the two must agree to the simulations'
rounding, sample by sample."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from nurbscnc.app.planning import make_plan
from nurbscnc.app.plots import scoped_series
from nurbscnc.app.simulation import run_contour, run_reference, simulate_points
from nurbscnc.cli.main import main
from nurbscnc.output.plots import RAPIDS_LABEL
from nurbscnc.plan.setup import CONTOUR_MARGIN

CORNERS = str(Path(__file__).resolve().parents[1] / "programs" / "corners.nc")
KEYS = ("contour_true_max_um", "contour_true_rms_um", "contour_rapids_true_max_um")


def _cli(*args) -> str:
    result = CliRunner().invoke(main, list(args))
    assert result.exit_code == 0, result.output
    return result.stdout


@pytest.fixture(scope="module")
def reports():
    return {
        "plan": json.loads(_cli("plan", CORNERS, "--json")),
        "simulate": json.loads(_cli("simulate", CORNERS, "--json")),
        "plan_text": _cli("plan", CORNERS),
        "simulate_text": _cli("simulate", CORNERS),
    }


def test_summary_and_simulate_report_the_same_contour_error(reports):
    plan, sim = reports["plan"], reports["simulate"]
    assert plan["contour_scope"] == sim["contour_scope"] == "feed"
    for key in KEYS:
        if key == "contour_true_rms_um" and plan["contour_bounded_samples"]:
            # The check's risk skip bounded some samples' errors by their tracking error
            # (plan/check.py): the rms counts them at that bound, so it bounds simulate's.
            assert plan[key] >= sim[key] * (1 - 1e-7), key
            continue
        # Two simulations of the same servo (IIR and convolution): per sample they differ by
        # at most 1.2e-7 µm on this program (measured), so 1e-7 relative on ~15 µm.
        assert sim[key] == pytest.approx(plan[key], rel=1e-7, abs=1e-6), key
    # The guarantee holds on the feed moves: within ε_max of the planned path, or within
    # ε_max + P (G64 P0.01) of a vertex the plan stops at, where the summary counts the
    # samples apart (nurbscnc.plan.allowance); the rapids' larger error is reported apart.
    if plan["contour_corner_samples"]:
        assert plan["contour_true_max_um"] == plan["contour_corner_max_um"] <= 15.0 + 10.0
    else:
        assert plan["contour_true_max_um"] <= 15.0
    assert plan["contour_rapids_true_max_um"] > 15.0
    assert sim["contour_rapids_eq29_max_um"] >= 0.0


def test_texts_say_the_same_numbers_and_the_scope(reports):
    plan, sim = reports["plan_text"], reports["simulate_text"]
    want = f"max {reports['plan']['contour_true_max_um']:.2f} µm"
    rapids = f"on rapids: max {reports['plan']['contour_rapids_true_max_um']:.2f} µm"
    assert re.search(r"predicted contour error on feed moves: " + want, plan)
    assert re.search(r"contour error on feed moves \(true distance\): " + want, sim)
    assert rapids in plan and rapids in sim
    assert "not guaranteed" in plan and "not guaranteed" in sim


def test_feed_samples_exclude_every_rapid_sample():
    prog, mach, run = make_plan(CORNERS, keep_reference=True)
    points, path = run_reference(run)
    sim, contour, _ = simulate_points(points, path, mach, "foh")
    contour, feed = run_contour(run, sim, contour, mach)
    n = run.samples.t_s.size
    rapid = np.asarray(run.plan.pieces.rapid)[run.samples.piece]
    assert rapid.any() and not (feed[:n] & rapid).any()
    # Every cut sample after the settle wait counts: on a non-rapid piece and past its
    # piece's start in profile time, or not the first cut after a rapid.
    assert np.array_equal(feed, run.check.cutting)
    # Sample by sample the check's contour error (its own simulation of the servo). Both
    # measure near the reference point and refine to the whole path above a threshold: the
    # check above its planning limit 0.99 ε_max (plan.setup.CONTOUR_MARGIN), simulate above
    # ε_max; between the two the check's refined distance is never the longer (a stop's
    # overshoot within a G64 corner's allowance lands there on corners.nc).
    sim_mm, check_mm = contour.true_mm[feed], run.check.response.contour_mm[feed]
    eps_mm = mach.limits.contour_tolerance_mm
    between = (sim_mm > CONTOUR_MARGIN * eps_mm) & (sim_mm <= eps_mm)
    np.testing.assert_allclose(
        sim_mm[~between], check_mm[~between], rtol=0, atol=1e-9
    )  # [mm]: 1e-6 µm; measured 1.2e-10 mm
    assert np.all(check_mm[between] <= sim_mm[between] + 1e-9)


def test_contour_plot_series_mark_the_rapids():
    t = np.arange(6) * 1e-3
    err = np.array([1.0, 2.0, 30.0, 40.0, 3.0, 4.0])
    feed = np.array([True, True, False, False, True, True])
    series = scoped_series("true distance", t, err, feed)
    cut, air = series["true distance, feed moves"][1], series[RAPIDS_LABEL][1]
    assert np.array_equal(np.isnan(cut), ~feed) and np.array_equal(np.isnan(air), feed)
    assert np.nanmax(cut) == 4.0 and np.nanmax(air) == 40.0
    assert list(scoped_series("x", t, err, None)) == ["x"]
    assert RAPIDS_LABEL not in scoped_series("x", t, err, np.ones(6, dtype=bool))
