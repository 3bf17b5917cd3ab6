"""``run --format halstreamer``: the text LinuxCNC's ``streamer`` HAL component plays, one line
per servo period (issue 16, "Run it on a real machine today: LinuxCNC").

The format is checked against the CSV reference points of the same run (read by numpy, not by
our reader). When LinuxCNC is installed (``halrun`` on PATH) the file is also played for real,
headless, under ``halrun``: ``halstreamer`` fills a ``streamer`` FIFO, the streamer drives three
``stepgen`` channels in position mode in a 1 ms thread, and ``sampler``/``halsampler`` record the
streamed commands and the step generators' counts every period. Checked: the streamed values are
the compiled points, period by period, to the file's 1 nm precision; the step counts follow the
compiled points within one step (the step generator reaches period k's command by the end of
period k, so its count is compared with the previous period's point); the run ends on the end
point's step. See /work/shared/tools/linuxcnc-sim/README.md for running LinuxCNC as root here.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from nurbscnc.cli.main import main
from nurbscnc.machine.profile import load_machine
from nurbscnc.output.halstreamer import STREAMER_CFG, halstreamer_lines

ROOT = Path(__file__).resolve().parents[1]
NACA = ROOT / "programs" / "naca2415.nc"
# Slow enough for a step generator whose pulse function runs once per 1 ms period (one step
# per period at most: 1 mm/s at 1000 steps/mm): F45 = 0.75 mm/s. Lines, an arc, a Z move.
SLOW = """G21 G90 G94 G17
G64 P0.001
F45
G1 X0.4 Y0
G3 X0.4 Y0.5 I0 J0.25
G1 X0 Y0.5 Z-0.2
G1 X0 Y0 Z0
"""


def compile_both(tmp_path, program: Path):
    """(halstreamer file text, CSV points (N, 3)) of one program, through the CLI."""
    hs, csv = tmp_path / "part.hs", tmp_path / "part.csv"
    r = CliRunner().invoke(main, ["run", str(program), "--format", "halstreamer", "-o", str(hs)])
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(main, ["run", str(program), "-o", str(csv)])
    assert r.exit_code == 0, r.output
    points = np.loadtxt(csv, delimiter=",", skiprows=1, usecols=(1, 2, 3))
    return hs.read_text(), points


def test_file_is_the_compiled_points(tmp_path):
    text, points = compile_both(tmp_path, NACA)
    lines = text.splitlines()
    header = [ln for ln in lines if ln.startswith("#")]
    data = [ln for ln in lines if not ln.startswith("#")]
    assert lines[: len(header)] == header  # comments only at the top
    assert len(data) == points.shape[0]
    assert f"cfg={STREAMER_CFG}" in text and "1000000 ns" in text
    assert f"# {points.shape[0]} lines" in text
    values = np.array([[float(v) for v in ln.split()] for ln in data])
    assert values.shape == points.shape
    assert np.max(np.abs(values - points)) <= 5e-7 + 1e-12  # six decimals, rounded
    # one line per servo period: the step between lines is at most V_max·T_s
    step = np.linalg.norm(np.diff(values, axis=0), axis=1)
    machine = load_machine()
    assert step.max() <= machine.limits.v_max_mm_s * machine.servo.period_s + 2e-6


def test_lines_format():
    assert halstreamer_lines(np.array([[1.0, -2.5, 1e-9], [-1e-9, 0.0, 123.4567891]])) == (
        "1.000000 -2.500000 0.000000\n0.000000 0.000000 123.456789\n"
    )


def test_batch_writes_hs_files(tmp_path):
    r = CliRunner().invoke(
        main,
        ["run", str(NACA), "--format", "halstreamer", "--output-dir", str(tmp_path), "--jobs", "1"],
    )
    assert r.exit_code == 0, r.output
    assert (tmp_path / "naca2415.hs").read_text().startswith("# nurbscnc")


# --- played by LinuxCNC ----------------------------------------------------------------------


def hal_graph(pins: int, **values) -> str:
    """The HAL file of :func:`play` for ``pins`` streamer pins (x y z, then the rotary
    axes): each pin drives a step generator in position mode; the sampler records the pins,
    then the generators' counts."""
    names = "xyzabc"[:pins]
    lines = [
        "loadrt threads name1=servo period1={period_ns} fp1=1",
        "loadrt streamer depth={depth} cfg={cfg}",
        f"loadrt stepgen step_type={','.join(['2'] * pins)}",
        f"loadrt sampler depth={{depth}} cfg={'f' * pins}{'s' * pins}",
        "addf streamer.0 servo",
        "addf stepgen.make-pulses servo",
        "addf stepgen.capture-position servo",
        "addf stepgen.update-freq servo",
        "addf sampler.0 servo",
    ]
    lines += [
        f"net {n}-cmd streamer.0.pin.{k} => stepgen.{k}.position-cmd sampler.0.pin.{k}"
        for k, n in enumerate(names)
    ]
    lines += [
        f"net {n}-counts stepgen.{k}.counts => sampler.0.pin.{pins + k}"
        for k, n in enumerate(names)
    ]
    lines += [f"setp stepgen.{k}.position-scale {{scale[{k}]}}" for k in range(pins)]
    lines += [f"setp stepgen.{k}.enable 1" for k in range(pins)]
    lines += [
        "loadusr -w halstreamer {stream}",
        "start",
        "loadusr -w halsampler -n {count} {record}",
        "stop",
    ]
    return "\n".join(lines).format(**values) + "\n"


# One LinuxCNC/HAL session at a time on a machine (fixed shared-memory keys): the same lock as
# /work/shared/tools/linuxcnc-sim/run_linuxcnc.sh.
LOCK = os.path.join(os.environ.get("TMPDIR", "/tmp"), "linuxcnc-sim.flock")
# How long to wait for another session's lock before skipping [s]: one session of this file
# is bounded by halrun's 120 s timeout, so 150 s outlasts one; a longer hold (a whole
# LinuxCNC simulation) skips, saying why, rather than stalling the suite's worker.
HAL_LOCK_WAIT_S = float(os.environ.get("NURBSCNC_HAL_LOCK_WAIT_S", "150"))


@contextlib.contextmanager
def hal_lock(wait_s: float = HAL_LOCK_WAIT_S):
    with open(LOCK, "a") as fh:
        deadline = time.monotonic() + wait_s
        while True:
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() > deadline:
                    pytest.skip(f"another LinuxCNC session held {LOCK} for over {wait_s:g} s")
                time.sleep(1.0)
        try:
            if os.path.exists("/tmp/linuxcnc.lock"):
                pytest.skip("a LinuxCNC instance is running (/tmp/linuxcnc.lock)")
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def play(stream_text: str, n_points: int, scale, cfg: str = STREAMER_CFG) -> np.ndarray:
    """Run :func:`hal_graph` (one step generator per pin of the streamer ``cfg``, at the
    steps per unit ``scale``) under halrun; the sampler's rows (count, 2 × pins): the
    streamed values, then the step counts."""
    work = tempfile.mkdtemp(prefix="nurbscnc-hal-")
    try:
        os.chmod(work, 0o755)
        rt = os.path.join(work, "rt")
        os.mkdir(rt)
        os.chmod(rt, 0o777)  # rtapi_app's socket, created under the fallback uid
        stream, record = os.path.join(work, "part.hs"), os.path.join(work, "record.txt")
        Path(stream).write_text(stream_text)
        count = n_points + 50  # the end point held for 50 more periods
        hal = os.path.join(work, "play.hal")
        Path(hal).write_text(
            hal_graph(
                len(cfg),
                period_ns=1_000_000,
                depth=count + 16,
                cfg=cfg,
                scale=scale,
                stream=stream,
                record=record,
                count=count,
            )
        )
        env = dict(os.environ, PATH="/usr/bin:/bin:/usr/sbin:/sbin")
        env.pop("DISPLAY", None)
        if os.geteuid() == 0:  # rtapi_app refuses root without a fallback uid
            env.update(RTAPI_UID="65534", RTAPI_FIFO_PATH=os.path.join(rt, ".rtapi_fifo"))
        with hal_lock():
            try:
                r = subprocess.run(
                    ["halrun", "-f", hal],
                    cwd=work,
                    env=env,
                    timeout=120,
                    capture_output=True,
                    text=True,
                )
            except subprocess.TimeoutExpired:
                subprocess.run(["halrun", "-U"], env=env, timeout=60, capture_output=True)
                raise
        assert r.returncode == 0, r.stdout + r.stderr
        return np.loadtxt(record, ndmin=2)
    finally:
        shutil.rmtree(work, ignore_errors=True)


needs_halrun = pytest.mark.skipif(
    shutil.which("halrun", path="/usr/bin:/bin") is None,
    reason="LinuxCNC is not installed (no halrun): apt-get install linuxcnc-uspace",
)


@needs_halrun
def test_linuxcnc_streamer_plays_the_file_period_by_period(tmp_path):
    # The paper's airfoil at full feed: too fast for the 1 ms step generator of this graph,
    # but the streamed commands must be exactly the compiled points, one per period.
    text, points = compile_both(tmp_path, NACA)
    rec = play(text, points.shape[0], (1000.0, 1000.0, 1000.0))
    n = points.shape[0]
    assert np.max(np.abs(rec[:n, :3] - points)) <= 5e-7 + 1e-12
    assert np.array_equal(rec[n:, :3], np.repeat(rec[n - 1 : n, :3], rec.shape[0] - n, axis=0))


@needs_halrun
def test_linuxcnc_stepgen_follows_within_one_step(tmp_path):
    program = tmp_path / "slow.nc"
    program.write_text(SLOW)
    text, points = compile_both(tmp_path, program)
    scale = load_machine().steps.per_mm  # 1000 steps/mm: one step is 1 µm
    rec = play(text, points.shape[0], scale)
    n = points.shape[0]
    assert np.max(np.abs(rec[:n, :3] - points)) <= 5e-7 + 1e-12
    counts = rec[:, 3:6]
    # count at period k+1 (captured at its start) against the point of period k
    err_steps = np.abs(counts[1 : n + 1] - points * np.asarray(scale))
    assert err_steps.max() <= 1.0
    assert np.array_equal(counts[-1], np.round(points[-1] * np.asarray(scale)))
    assert np.ptp(points[:, 2]) > 0.1 and np.ptp(points[:, 0]) > 0.5  # it did move
