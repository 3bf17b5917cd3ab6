"""The dynamics check's risk skip (plan/check.py ``Checker._respond``): a sample whose
tracking error |r_k − a_k| plus the dense polyline's chord margin is within ε_max is never
over the limit (its reference point lies on the path inside the stretch the distance is
measured to), so its distance to the path is measured only where that bound exceeds the
largest error found so far.

Two claims, each against something the skip does not compute:

- the bound holds: on every sample it may leave out, the tracking error plus the margin is
  at least the distance the full check measures, and at least the distance from an
  independent servo simulation (scipy.signal.lsim, tests/servo_reference.py) to a dense
  polyline of the path (a k-d tree over its vertices);
- the decisions are the same: over random programs (rapids, plunges, lines and arcs at
  feeds from 300 to 3500 mm/min, G61 and G64) on the paper's machine and under LinuxCNC's
  limits, and over the corpus's CAM programs, the plan (every lever, settle, profile time,
  cycle time, re-plan count) and the check (every over-limit sample, piece runs, restart
  counts, worst error, maximum contour error) equal those of the check that measures every
  sample; only the rms, which counts a bounded sample at its bound, may be larger.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from nurbscnc.geometry.polyline import CHORD_MM, dense_path_mm
from nurbscnc.machine.profile import load_machine
from nurbscnc.plan import check as check_module
from nurbscnc.plan.check import SKIP_MARGIN_MM, Checker
from nurbscnc.plan.lookahead import plan_checked
from nurbscnc.program.interpret import interpret_text
from tests.plan_helpers import assert_same_levers
from tests.servo_reference import distance_to_polyline_mm, lsim_actual_mm

ROOT = Path(__file__).resolve().parents[1]
LCNC = str(ROOT / "bench" / "programs" / "linuxcnc_limits.toml")
MACHINES = {"paper": load_machine(), "linuxcnc": load_machine(LCNC)}
CORPUS = Path(os.environ.get("NURBSCNC_CORPUS", ROOT.parent / "shared" / "corpus"))
#: Lines of each corpus CAM program planned (the whole of the short ones).
CAM_LINES = 400


def _program(seed: int) -> str:
    """A random program of 1–3 cuts: a rapid above the cut's start, a plunge, 2–6 lines and
    arcs in XY (some with z), a retract; feeds 300–3500 mm/min, G61 or G64."""
    rng = np.random.default_rng(seed)
    mode = ("G61", "G64", "G64 P0.02")[seed % 3]
    lines = [f"G21 G17 G90 {mode}", "G0 X0 Y0 Z2"]
    for _ in range(int(rng.integers(1, 4))):
        x, y = rng.uniform(-30.0, 30.0, 2)
        feed = float(rng.choice([300.0, 800.0, 1500.0, 3500.0]))
        lines += [f"G0 X{x:.3f} Y{y:.3f}", f"G1 Z{-rng.uniform(0.2, 1.5):.3f} F{feed / 2:.0f}"]
        for _ in range(int(rng.integers(2, 7))):
            dx, dy = rng.normal(size=2) * float(rng.choice([1.0, 5.0, 15.0]))
            if rng.random() < 0.35:  # a half circle to the side
                r = max(abs(dx), 0.5)
                arc = "G2" if rng.random() < 0.5 else "G3"
                lines.append(f"{arc} X{x + 2 * r:.3f} Y{y:.3f} I{r:.3f} J0 F{feed:.0f}")
                x += 2 * r
                continue
            x, y = x + dx, y + dy
            z = f" Z{-rng.uniform(0.2, 1.5):.3f}" if rng.random() < 0.2 else ""
            lines.append(f"G1 X{x:.3f} Y{y:.3f}{z} F{feed:.0f}")
        lines.append("G0 Z2")
    lines.append("M2")
    return "\n".join(lines) + "\n"


def _both(text: str, machine, monkeypatch):
    """(plan, check) with the skip on, then off."""
    program = interpret_text(text)
    monkeypatch.setattr(check_module, "RISK_SKIP", True)
    on = plan_checked(program, machine, keep_reference=False)
    monkeypatch.setattr(check_module, "RISK_SKIP", False)
    off = plan_checked(program, machine, keep_reference=False)
    return on, off


def _assert_same_decisions(on, off) -> int:
    """The plans and checks of :func:`_both` agree (module doc); returns how many samples
    the skip bounded."""
    (plan, chk), (ref_plan, ref_chk) = on, off
    assert plan.iterations == ref_plan.iterations
    assert plan.cycle_time_s == ref_plan.cycle_time_s
    assert_same_levers(plan, ref_plan)
    for f in ("phase_start_time_s", "phase_jerk_mm_s3", "piece_start_time_s"):
        np.testing.assert_array_equal(getattr(plan.profile, f), getattr(ref_plan.profile, f))
    for f in ("count", "index", "err_mm", "tau_s", "run_piece", "run_start", "restart_count"):
        np.testing.assert_array_equal(getattr(chk.overs, f), getattr(ref_chk.overs, f), f)
    assert chk.overs.worst_mm == ref_chk.overs.worst_mm
    s, r = chk.contour_stats(), ref_chk.contour_stats()
    for key in ("contour_true_max_um", "contour_eq29_max_um", "contour_rapids_true_max_um"):
        assert s[key] == r[key], key
    assert r["contour_bounded_samples"] == 0
    # The rms counts a bounded sample at its bound (sums in another order: 1e-12).
    assert s["contour_true_rms_um"] >= r["contour_true_rms_um"] * (1 - 1e-12)
    if not s["contour_bounded_samples"]:
        assert s["contour_true_rms_um"] == pytest.approx(r["contour_true_rms_um"], rel=1e-12)
    return s["contour_bounded_samples"]


@pytest.mark.parametrize("machine", sorted(MACHINES))
def test_random_programs_plan_alike_with_the_skip(machine, monkeypatch):
    bounded = [
        _assert_same_decisions(*_both(_program(seed), MACHINES[machine], monkeypatch))
        for seed in range(12)
    ]
    # Not vacuous: the skip left samples out on most programs.
    assert sum(b > 0 for b in bounded) >= 9, bounded


def _cam_programs() -> list[Path]:
    cam = CORPUS / "cam"
    return sorted(cam.glob("*.nc")) if cam.is_dir() else []


@pytest.mark.skipif(not _cam_programs(), reason=f"no corpus CAM programs under {CORPUS}/cam")
@pytest.mark.parametrize("path", _cam_programs(), ids=lambda p: p.name)
def test_corpus_cam_programs_plan_alike_with_the_skip(path, monkeypatch):
    """The first :data:`CAM_LINES` lines of each (then M2): their rapids, plunges, arcs,
    corners and the shaping and improvement of their windows."""
    text = "\n".join(path.read_text().splitlines()[:CAM_LINES]) + "\nM2\n"
    bounded = _assert_same_decisions(*_both(text, MACHINES["paper"], monkeypatch))
    assert bounded > 0


@pytest.mark.parametrize("machine", sorted(MACHINES))
def test_the_bound_holds_against_the_check_and_an_independent_simulation(machine, monkeypatch):
    """On every sample the skip may leave out (cutting, not the first piece of a cut after a
    rapid): tracking error + margin ≥ the full check's distance, and ≥ the distance from
    scipy.signal.lsim's actual point to a dense polyline of the path (vertex spacing
    0.5 µm: at most 0.25 µm above the distance to the path itself, within the margin's
    1 µm). And the bound is below ε_max on many samples (the skip has work to leave)."""
    mach = MACHINES[machine]
    monkeypatch.setattr(check_module, "RISK_SKIP", False)
    below = eligible_total = 0
    for seed in range(100, 106):
        plan, chk = plan_checked(interpret_text(_program(seed)), mach)
        ref, resp = chk.reference, chk.response
        n = ref.t_s.size
        eligible = chk.cutting[:n] & ~_no_skip(plan.pieces)[ref.piece]
        bound = np.linalg.norm(ref.points_mm - resp.actual_mm[:n], axis=1) + SKIP_MARGIN_MM
        # The margin is a hundred times what the chords use: the full check's distance
        # exceeds the tracking error by at most the dense polyline's chord error.
        lag = bound - SKIP_MARGIN_MM
        assert np.all(resp.contour_mm[:n][eligible] - lag[eligible] <= 1.5 * CHORD_MM)
        actual = lsim_actual_mm(ref.points_mm, mach, settle_s=0.0)[:n]
        dense = dense_path_mm(plan.pieces, plan.profile, spacing_mm=5e-4)
        independent = distance_to_polyline_mm(actual[eligible], dense)
        assert np.all(independent <= bound[eligible] + 1e-9), seed
        below += int(np.count_nonzero(eligible & (bound < 0.015)))
        eligible_total += int(eligible.sum())
    assert below > 0.2 * eligible_total


def _no_skip(pieces) -> np.ndarray:
    """The pieces the skip never leaves a sample of (:class:`Checker`'s ``no_skip``)."""
    from nurbscnc.plan.scope import after_rapid_rows

    rapid = np.asarray(pieces.rapid, dtype=bool)
    return rapid | after_rapid_rows(rapid)


def test_the_skip_is_only_for_references_on_the_path(monkeypatch):
    """The exact sampler (and a wrapper of it) places every reference point on the path;
    the Taylor recurrence's points and a pre-compensated reference are not on it: no skip."""
    from nurbscnc.interpolate.sample import reference_sampler
    from nurbscnc.plan.program_pieces import segment_pieces
    from nurbscnc.plan.sampler import EXACT, ForwardingSampler
    from nurbscnc.precompensation import precompensated_sampler

    machine = MACHINES["paper"]
    pieces = segment_pieces(interpret_text(_program(1)).segments, machine)
    settle = np.zeros(0, dtype=np.intp)

    def skips(sampler) -> bool:
        return Checker(pieces, machine, sampler, 0.015, settle, 64, False).skip

    monkeypatch.setattr(check_module, "RISK_SKIP", True)
    assert skips(EXACT) and skips(ForwardingSampler(EXACT)) and skips(reference_sampler("exact"))
    assert not skips(reference_sampler("taylor"))
    assert not skips(precompensated_sampler(EXACT, machine))
    monkeypatch.setattr(check_module, "RISK_SKIP", False)
    assert not skips(EXACT)
