"""The planner's dynamics check in windows of servo samples (issue 14): bounded memory,
the same plan.

- the servo simulated window by window with its state carried
  (:class:`nurbscnc.servo.model.AxesStream`) equals the whole-array simulation and, as an
  independent reference, ``scipy.signal.lsim`` of SPEC eq. 25 on the first-order-hold input
  (tests/servo_reference.py);
- with a tiny window (97 samples) the plan (every lever, the settles, cycle time,
  iterations) is the one a window larger than the program gives, and the one the whole
  reference gives (``keep_reference=True``), on programs where shaping is active (the
  ringing servo of tests/test_shaping.py, the fallback alone) and on corpus programs; the
  contour statistics agree to 1e-9 relative (the rms is summed window by window);
- a program with an hour of motion and 42 lines plans under an address-space cap that the
  whole-array check exceeds.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from nurbscnc.machine.profile import load_machine
from nurbscnc.plan import check, converge, windows
from nurbscnc.plan.lookahead import plan_checked
from nurbscnc.plan.options import LookaheadOptions
from nurbscnc.plan.program_pieces import segment_pieces
from nurbscnc.program.interpret import interpret_text
from nurbscnc.servo.model import AxesStream, simulate_axes
from tests.plan_helpers import assert_same_levers
from tests.servo_reference import lsim_actual_mm
from tests.test_shaping import _slow_servo_machine

ROOT = Path(__file__).resolve().parents[1]
PLANNER = ROOT / "tests" / "programs" / "planner"
MACHINE = load_machine()
SLOW = _slow_servo_machine()
TINY = 97  # samples per window: many windows, boundaries everywhere
HUGE = 1 << 30  # one window for the whole program
STATS_REL = 1e-9


@pytest.fixture(autouse=True)
def _every_distance_measured(monkeypatch):
    """The contour statistics compared here are the fully measured ones: the risk skip
    (plan/check.py) leaves the rows it bounds out of the measurement, so which rows those
    are (and the rms, then a bound) depends on the check so far, hence on the window;
    the plans with it on and off are compared in tests/test_risk_skip.py."""
    monkeypatch.setattr(check, "RISK_SKIP", False)


def _reference(n: int, rng) -> np.ndarray:
    """A reference (n, 3) [mm] with the shapes the servo sees: ramps, a stop, steps."""
    t = np.arange(n) * 1e-3
    ref = np.column_stack((5.0 * np.sin(3.0 * t), 20.0 * t - 3.0 * t * t, 0.5 * np.cos(7 * t)))
    ref[n // 3 : n // 2] = ref[n // 3]  # a held stretch (a dwell)
    ref[2 * n // 3 :, 0] += 0.2  # a step
    return ref + rng.normal(scale=1e-4, size=ref.shape)


@pytest.mark.parametrize("machine", [MACHINE, SLOW], ids=["paper", "ringing"])
@pytest.mark.parametrize("sizes", [(1,), (TINY,), (1000, 1, 7, 3000)])
def test_servo_stream_equals_the_whole_simulation_and_lsim(machine, sizes):
    """Window by window (cyclic window ``sizes``), settle tail included: the rows of
    simulate_axes(settle=True) to 1e-12 mm, and lsim (independent) to 1e-9 mm."""
    rng = np.random.default_rng(14)
    ref = _reference(2500, rng)
    servo = machine.servo
    models = [servo.x, servo.y, None]  # z ideal: the reference itself
    whole = simulate_axes(models, ref, servo.period_s, settle=True)
    stream = AxesStream(models, servo.period_s)
    parts, lo, i = [], 0, 0
    while lo < ref.shape[0]:
        hi = min(lo + sizes[i % len(sizes)], ref.shape[0])
        parts.append(stream.step(ref[lo:hi]))
        lo, i = hi, i + 1
    tail = stream.settle()
    parts.append(tail)
    windowed = np.vstack(parts)
    assert windowed.shape == whole.shape and tail.shape[0] > 0
    np.testing.assert_allclose(windowed, whole, rtol=0.0, atol=1e-12)
    settle_s = tail.shape[0] * servo.period_s
    indep = lsim_actual_mm(ref, replace_z(machine), settle_s=settle_s)
    np.testing.assert_allclose(windowed[:, :2], indep[: windowed.shape[0], :2], rtol=0.0, atol=1e-9)


def test_a_copied_stream_goes_on_alone():
    """AxesStream.copy (each cut window's check copies the servo state): the copy and the
    original, stepped apart on different references, each give what an uncopied stream
    given the same rows gives (bit for bit), settle tails included."""
    rng = np.random.default_rng(5)
    servo = MACHINE.servo
    models = [servo.x, servo.y, None]
    head, a, b = _reference(400, rng), _reference(300, rng), _reference(300, rng)
    b += head[-1] - b[0]
    a += head[-1] - a[0]
    stream = AxesStream(models, servo.period_s)
    stream.step(head)
    twin = stream.copy()
    got_a, got_b = stream.step(a), twin.step(b)
    tail_a, tail_b = stream.settle(), twin.settle()
    for rows, got, tail in ((a, got_a, tail_a), (b, got_b, tail_b)):
        alone = AxesStream(models, servo.period_s)
        alone.step(head)
        np.testing.assert_array_equal(alone.step(rows), got)
        np.testing.assert_array_equal(alone.settle(), tail)


def replace_z(machine):
    """``machine`` without a z model (the stream test's z is ideal)."""
    from dataclasses import replace

    return replace(machine, servo=replace(machine.servo, z=None))


def _plan(text: str, machine, **kw):
    return plan_checked(interpret_text(text), machine, **kw)


def _assert_same_plan(a, b, stats: bool = True):
    """Every lever, the settles, the profile's times, cycle time and iterations equal; the
    contour statistics too (``stats``), else those of ``b`` bound those of ``a`` (a program
    of several cuts: its compact check measured each cut against the path up to its end,
    tests/test_cuts.py)."""
    plan_a, check_a = a
    plan_b, check_b = b
    assert plan_a.iterations == plan_b.iterations
    assert plan_a.cycle_time_s == plan_b.cycle_time_s
    assert_same_levers(plan_a, plan_b)
    np.testing.assert_array_equal(
        plan_a.profile.junction_speeds_mm_s, plan_b.profile.junction_speeds_mm_s
    )
    sa, sb = check_a.contour_stats(), check_b.contour_stats()
    assert sa.keys() == sb.keys()
    for key in sa:
        if stats:
            assert sb[key] == pytest.approx(sa[key], rel=STATS_REL, abs=1e-300), key
        else:
            assert sa[key] <= sb[key] * (1 + STATS_REL), key


def _cuts(text: str, machine) -> int:
    """Cut windows of a program (:func:`~nurbscnc.plan.windows.cut_windows`)."""
    pieces = segment_pieces(interpret_text(text).segments, machine, LookaheadOptions().plan)
    return windows.cut_windows(pieces).size


def _windows_agree(text: str, machine, window: int = TINY) -> tuple:
    """Plan with a tiny window, one huge window and the whole kept reference; all equal."""
    tiny = _plan(text, machine, keep_reference=False, window=window)
    huge = _plan(text, machine, keep_reference=False, window=HUGE)
    whole = _plan(text, machine, keep_reference=True)
    assert tiny[1].reference is None and tiny[1].response is None
    assert whole[1].reference is not None
    one_cut = _cuts(text, machine) == 1
    _assert_same_plan(tiny, huge)
    _assert_same_plan(whole, tiny, stats=one_cut)
    # The compact form counts every checked sample (the settle tail included).
    if one_cut:
        assert tiny[1].overs.worst_mm == whole[1].overs.worst_mm
    else:
        assert whole[1].overs.worst_mm <= tiny[1].overs.worst_mm
        assert tiny[1].overs.count == whole[1].overs.count
    assert whole[1].overs.count == whole[1].response.contour_mm.size
    return tiny


@pytest.mark.parametrize(
    "name", ["square_g61_f3000.nc", "pentagram_g61.nc", "modes_cam_breaks_g64p.ngc"]
)
def test_plan_does_not_depend_on_the_window_ringing_servo(name):
    """The ringing servo makes every rule of the shaping work (stops, feed, re-plans and
    the improvement bisection)."""
    plan, _ = _windows_agree(
        (PLANNER / name).read_text(), SLOW, window=TINY if "cam" not in name else 1009
    )
    assert plan.iterations > 0 and plan.shaped_by_contour.any()


def test_plan_does_not_depend_on_the_window_settle_after_rapids():
    """Rapids followed by cuts on the ringing servo: the settles the check sets (they need
    the count of samples before each restart, summed over windows)."""
    text = (
        "G21 G90 G17\nG0 X30 Y0\nG1 X30 Y10 F300\nG0 X0 Y0\nG1 X5 Y5 F1200\nG0 X40 Y40\n"
        "G1 X40 Y0 F3000\nM2\n"
    )
    plan, _ = _windows_agree(text, SLOW)
    assert (plan.settle_s > 0.0).sum() >= 2


def test_plan_does_not_depend_on_the_window_fallback(monkeypatch):
    """The fallback alone (both stages: blamed pieces, then every cutting piece)."""
    monkeypatch.setattr(converge, "LOCAL_ITERATIONS", 0)
    monkeypatch.setattr(converge, "FALLBACK_LOCAL_ITERATIONS", 1)
    plan, _ = _windows_agree((PLANNER / "square_g61_f3000.nc").read_text(), SLOW)
    assert plan.iterations > 1


def test_plan_does_not_depend_on_the_window_airfoil():
    """The paper's NACA 2415 block on its own machine (feed lever on the nose)."""
    plan, _ = _windows_agree((ROOT / "programs" / "naca2415.nc").read_text(), MACHINE)
    assert plan.iterations > 0


def _corpus() -> Path:
    return Path(os.environ.get("NURBSCNC_CORPUS") or ROOT / ".." / "shared" / "corpus").resolve()


@pytest.mark.parametrize(
    "name",
    [
        "linuxcnc/nurbs/G6_Curva_Delfino_v1.ngc",
        "linuxcnc/nurbs/G5_butterfly-xy.ngc",
        "linuxcnc/general/skeleton.ngc",
    ],
)
def test_plan_does_not_depend_on_the_window_corpus(name):
    """Corpus programs (NURBS, arcs, rapids) on the ringing servo."""
    path = _corpus() / name
    if not path.is_file():
        pytest.skip(f"corpus program {path} absent (set NURBSCNC_CORPUS to the corpus folder)")
    _windows_agree(path.read_text(), SLOW, window=1009)


# Today's whole-array check (main 240dbb2) peaks at 1.03 GB of address space (VmPeak; 827 MB
# resident) on this program (42 lines, 4,000 s of motion at F60, 4 M servo samples); the
# windowed one at 367 MB (162 MB resident), the same as for 2,000 s. The cap sits between.
MEMORY_CAP_BYTES = 640 * 2**20
_CHILD = textwrap.dedent("""
    import resource, sys
    cap = int(sys.argv[1])
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
    from nurbscnc.machine.profile import load_machine
    from nurbscnc.plan.lookahead import plan_checked
    from nurbscnc.program.interpret import interpret_text
    lines = ["G21 G90 G17", "G0 X0 Y0", "F60"]
    lines += [f"G1 X{100 * ((i + 1) % 2)} Y{i + 1}" for i in range(40)]
    prog = interpret_text("\\n".join(lines + ["M2"]) + "\\n")
    plan, check = plan_checked(prog, load_machine(), keep_reference=sys.argv[2] == "keep")
    print(plan.cycle_time_s, check.contour_stats()["contour_true_max_um"])
""")


def _child(mode: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    cmd = [sys.executable, "-c", _CHILD, str(MEMORY_CAP_BYTES), mode]
    return subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=600, cwd=ROOT)


def test_an_hour_of_motion_plans_under_a_memory_cap():
    """keep_reference=False plans 4,000 s of motion under the cap; the whole reference and
    response (keep_reference=True, today's check) do not fit under it."""
    ok = _child("compact")
    assert ok.returncode == 0, ok.stderr[-2000:]
    cycle_s, worst_um = map(float, ok.stdout.split())
    assert cycle_s > 3600.0
    assert 0.0 < worst_um <= MACHINE.limits.contour_tolerance_mm * 1000.0
    whole = _child("keep")
    assert whole.returncode != 0 and "MemoryError" in whole.stderr


def test_which_samplers_are_checked_in_windows():
    """Windows only where the sampler says a window gives the whole reference's rows exactly
    (``ReferenceSampler.windowed``): the exact sampler; not the Taylor recurrence
    (sequential: a window would restart it), not a plain function (it promises nothing),
    not one that says ``windowed=False``; a wrapper (the pre-compensated sampler, the CLI's
    announcing one) as the sampler it wraps; and a plan checked whole equals the windowed
    one."""
    from nurbscnc.interpolate.sample import reference_sampler
    from nurbscnc.plan.sampler import EXACT, ForwardingSampler, FunctionSampler, as_sampler
    from nurbscnc.plan.timing import exact_reference
    from nurbscnc.precompensation import precompensated_sampler

    exact, taylor = reference_sampler("exact"), reference_sampler("taylor")
    assert exact.windowed and EXACT.windowed and not taylor.windowed

    def whole_only(pieces, profile, period_s):
        return exact_reference(pieces, profile, period_s)

    def refusing(pieces, profile, period_s, k0=0, k1=None):
        return exact_reference(pieces, profile, period_s, k0, k1)

    refused = FunctionSampler(refusing, windowed=False)
    assert not as_sampler(whole_only).windowed and not refused.windowed
    assert as_sampler(exact) is exact
    for inner in (exact, taylor):
        assert ForwardingSampler(inner).windowed == inner.windowed
        assert precompensated_sampler(inner, SLOW).windowed == inner.windowed
        assert precompensated_sampler(inner, SLOW).interpolator == inner.interpolator
    text = (PLANNER / "square_g61_f3000.nc").read_text()
    _assert_same_plan(
        _plan(text, SLOW, reference=whole_only, keep_reference=False),
        _plan(text, SLOW, keep_reference=False, window=TINY),
    )
    _assert_same_plan(
        _plan(text, SLOW, reference=refused, keep_reference=False),
        _plan(text, SLOW, keep_reference=False, window=TINY),
    )


def test_the_repeated_cut_comparison_is_allclose():
    """windows._close (a repeated cut's columns compared per window) is np.allclose on
    finite values, equal and unequal infinities and NaN, both ways."""
    from nurbscnc.plan.windows import _close

    rng = np.random.default_rng(0)
    values = [0.0, 1.0, np.inf, -np.inf, np.nan, 1e-10, 5.0]
    steps = [0.0, 1e-13, 1e-9, 1e-6, np.inf, -np.inf]
    for _ in range(3000):
        a = rng.choice(values, 8)
        with np.errstate(invalid="ignore"):
            b = a + rng.choice(steps, 8)
        if rng.random() < 0.5:
            a, b = b, a
        for rtol, atol in ((1e-9, 1e-12), (0.0, 1e-9), (1e-9, 0.0)):
            assert _close(a, b, rtol, atol) == np.allclose(a, b, rtol=rtol, atol=atol)
