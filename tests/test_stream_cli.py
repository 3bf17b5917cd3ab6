"""The `stream` and `card-sim` commands: safety before the port, exit codes, Ctrl-C, the log.

`stream` runs in-process through click's CliRunner (or in a subprocess for Ctrl-C) against a
card simulator that counts every byte it receives; `card-sim` runs as a subprocess once.
The expected end positions come from the program text (its last point) and the expected
pulses from Python's round() on the points written here, not from the code under test.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import serial
from click.testing import CliRunner

from nurbscnc.cli.card import card_sim
from nurbscnc.cli.stream import stream
from nurbscnc.output.stream import protocol as p
from nurbscnc.output.stream.card import CardConfig, PtyEndpoint
from tests.stream_helpers import card_on

ROOT = Path(__file__).resolve().parents[1]
GOOD = "G21 G90 G17\nG0 X0 Y0\nG1 X5 Y2 F3000\nG1 X8 Y0\nM2\n"  # ends at X8 Y0 → 8000 steps
LATE_ERROR = "G21 G90 G17\nG0 X0 Y0\nG1 X5 Y2 F3000\nG1 X8 Y0\nG2 X10 Y0\nM2\n"  # line 5


def run_stream(args):
    return CliRunner().invoke(stream, [str(a) for a in args])


def write_points(path: Path, points: np.ndarray, period_s: float = 1e-3) -> None:
    """A reference-point CSV as `run -o` writes it (t,x,y,z,feed,piece,line)."""
    n = len(points)
    table = np.column_stack(
        [np.arange(n) * period_s, points, np.zeros(n), np.zeros(n), np.full(n, 3)]
    )
    with open(path, "w") as fh:
        fh.write("t,x,y,z,feed,piece,line\n")
        np.savetxt(
            fh, table, fmt=["%.6f", "%.9f", "%.9f", "%.9f", "%.6f", "%d", "%d"], delimiter=","
        )


def expected_pulses(csv: Path) -> np.ndarray:
    """Pulses of the points as written in ``csv`` (1000 steps/mm), by Python's round()."""
    points = np.loadtxt(csv, delimiter=",", skiprows=1)[:, 1:4]
    steps = [[round(float(v) * 1000.0) for v in row] for row in points]
    return np.diff(np.array(steps), axis=0)


def spiral(n: int) -> np.ndarray:
    t = np.arange(n) * 1e-3
    r = 2.0 + t
    return np.column_stack([r * np.cos(8 * t) - 2.0, r * np.sin(8 * t), 0.5 * t])


def test_stream_program_over_pty_exits_0_at_the_programs_end(tmp_path):
    nc = tmp_path / "part.nc"
    nc.write_text(GOOD)
    with card_on("pty") as (card, ep):
        result = run_stream([nc, "--port", ep.path, "--json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert report["ok"] and report["final_position_steps"] == [8000, 0, 0]
    assert report["expected_position_steps"] == [8000, 0, 0]
    assert report["executed_periods"] == card.executed_periods == report["periods"]
    assert card.position.tolist() == [8000, 0, 0] and card.state.name == "DONE"
    assert set(report) >= {"frames_sent", "retransmits", "duration_s", "bytes_sent"}
    assert report["frame_error_rate"] == 0.0 and report["batch_periods"] == 16


def test_stream_stall_limit_option_reaches_the_sender(tmp_path, monkeypatch):
    import nurbscnc.output.stream.sender as sender_module

    seen = []
    real = sender_module.Sender.__init__

    def capture(self, ser, options, **kwargs):
        seen.append(options)
        real(self, ser, options, **kwargs)

    monkeypatch.setattr(sender_module.Sender, "__init__", capture)
    nc = tmp_path / "part.nc"
    nc.write_text(GOOD)
    with card_on("pty") as (_card, ep):
        result = run_stream([nc, "--port", ep.path, "--stall-limit", "7.5"])
    assert result.exit_code == 0, result.output
    assert seen and seen[0].stall_limit_s == 7.5 and "noisy line" not in result.stderr
    bad = run_stream([nc, "--port", "/dev/null", "--stall-limit", "0"])
    assert bad.exit_code == 2 and "--stall-limit" in bad.stderr


def test_stream_plans_while_streaming_and_reports_the_planning(tmp_path):
    """A program of four cuts (five cut windows) over a pty to the real-time card simulator:
    the card ends at the program's end; the report counts the windows, and the margin, the
    holds and the time held are there (their values depend on the machine's load: holds
    are allowed, at most one per window boundary; the card then waited at rest)."""
    from tests.test_stream_windows import CUTS

    nc = tmp_path / "cuts.nc"
    nc.write_text(CUTS)
    with card_on("pty") as (card, ep):
        result = run_stream([nc, "--port", ep.path, "--json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert report["ok"] and report["final_position_steps"] == [40000, 15000, 5000]
    planning = report["planning"]
    assert planning["windows"] == 5 and planning["planned_s"] >= planning["first_window_s"]
    assert 0 <= planning["holds"] <= 4 and planning["held_s"] >= 0.0
    assert planning["plan_margin_min_s"] is None or planning["plan_margin_min_s"] >= 0.0
    assert card.position.tolist() == [40000, 15000, 5000] and card.state.name == "DONE"


def test_stream_points_file_over_socket_url(tmp_path):
    pts = spiral(600)
    csv = tmp_path / "points.csv"
    write_points(csv, pts)
    with card_on("tcp") as (card, ep):
        refused = run_stream([csv, "--port", ep.path])
        assert refused.exit_code == 2 and "--allow-url" in refused.stderr
        assert card.bytes_received == 0  # nothing reached the card
        result = run_stream([csv, "--port", ep.path, "--allow-url"])
    assert result.exit_code == 0, result.output
    assert np.array_equal(card.executed_pulses(), expected_pulses(csv))
    assert "599 periods streamed" in result.stdout


@pytest.mark.parametrize(
    "setup, args, message",
    [
        ("late", [], "5:4: error: arc with neither R nor I/J/K"),
        ("good", ["--set", "soft_limits.x.max_mm=5"], "soft limits"),
        (
            "jump",
            [],
            "period 250 (t = 0.2500 s) needs 200 pulses on Z, more than the card's limit of 127",
        ),
        ("slow", [], "2 ms apart; the machine's servo period is 1 ms"),
    ],
)
def test_errors_anywhere_in_the_input_send_zero_bytes(tmp_path, setup, args, message):
    if setup in ("late", "good"):
        path = tmp_path / "p.nc"
        path.write_text(LATE_ERROR if setup == "late" else GOOD)
    else:
        pts = spiral(300)
        if setup == "jump":
            pts[:, 2] = 0.0
            pts[250:, 2] = 0.2  # one period near the end moves 0.2 mm = 200 steps
        path = tmp_path / "p.csv"
        write_points(path, pts, 2e-3 if setup == "slow" else 1e-3)
    with card_on("pty") as (card, ep):
        result = run_stream([path, "--port", ep.path, *args])
        time.sleep(0.05)
    assert result.exit_code == 2, result.output
    assert message in result.stderr
    if setup == "good":
        # A plan error from where the card stands: the card was asked where it stands (one
        # STATUS_REQUEST frame) and got nothing else; it is where it was, idle.
        asked = len(p.encode_message(p.StatusRequest()))
        assert card.bytes_received == asked and card.executed_periods == 0
        assert card.position.tolist() == [0, 0, 0] and card.state is p.CardState.IDLE
    else:
        assert card.bytes_received == 0


def test_port_trouble_exits_3(tmp_path):
    nc = tmp_path / "p.nc"
    nc.write_text(GOOD)
    result = run_stream([nc, "--port", tmp_path / "no-such-tty"])
    assert result.exit_code == 3 and "cannot open port" in result.stderr
    ep = PtyEndpoint()
    try:
        holder = serial.Serial(ep.path, exclusive=True)
        result = run_stream([nc, "--port", ep.path])
        holder.close()
    finally:
        ep.close()
    assert result.exit_code == 3 and "busy" in result.stderr


def test_unfit_card_exits_3_before_sending_a_batch(tmp_path):
    # A points file starts where its first point is: a card elsewhere is refused (a program
    # starts where the card stands instead).
    pts = spiral(300)
    csv = tmp_path / "p.csv"
    write_points(csv, pts - pts[0])
    with card_on("pty", CardConfig(speed=None, position_steps=(0, 7, 0))) as (card, ep):
        result = run_stream([csv, "--port", ep.path, "--timeout", "0.5"])
    assert result.exit_code == 3
    assert "the card is at [0, 7, 0] steps" in result.stderr
    assert card.frames_received == 1 and card.executed_periods == 0


def _stream_cmd(args):
    """`nurbscnc stream ...` in a subprocess."""
    return [sys.executable, "-m", "nurbscnc", "stream", *args]


def test_ctrl_c_sends_abort_and_exits_130(tmp_path):
    csv = tmp_path / "long.csv"
    write_points(csv, spiral(8000))  # 8 s of motion: SIGINT arrives long before the end
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    with card_on("pty", CardConfig(speed=1.0)) as (card, ep):
        cmd = _stream_cmd([str(csv), "--port", ep.path, "--quiet"])
        proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, stdout=subprocess.PIPE, env=env)
        try:
            deadline = time.monotonic() + 20.0
            while card.executed_periods < 50 and time.monotonic() < deadline:
                time.sleep(0.02)
            assert card.executed_periods >= 50, "the stream did not start"
            proc.send_signal(signal.SIGINT)
            _, stderr = proc.communicate(timeout=10.0)
        finally:
            if proc.poll() is None:
                proc.kill()
        time.sleep(0.05)
    assert proc.returncode == 130, stderr.decode()
    assert b"interrupted: abort sent, the card stopped" in stderr
    assert card.aborts_received >= 1 and card.state.name == "ABORTED"
    assert card.executed_periods < 4000


def test_card_sim_command_logs_what_it_executed(tmp_path):
    pts = spiral(400)
    csv = tmp_path / "points.csv"
    write_points(csv, pts)
    log, report = tmp_path / "executed.csv", tmp_path / "card.json"
    code = "from nurbscnc.cli.card import card_sim; card_sim(prog_name='card-sim')"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        [
            sys.executable,
            "-c",
            code,
            "--listen",
            "127.0.0.1:0",
            "--fast",
            "--once",
            "--log",
            str(log),
            "--report",
            str(report),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=env,
    )
    try:
        url = proc.stdout.readline().decode().strip()
        assert url.startswith("socket://127.0.0.1:")
        result = run_stream([csv, "--port", url, "--allow-url", "--json"])
        proc.wait(timeout=10.0)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert result.exit_code == 0, result.output
    assert proc.returncode == 0
    logged = np.loadtxt(log, delimiter=",", skiprows=1, dtype=np.int64, ndmin=2)
    assert np.array_equal(logged[:, 0], np.arange(1, 400))
    assert np.array_equal(logged[:, 1:], expected_pulses(csv))
    counters = json.loads(report.read_text())
    assert counters["state"] == "DONE" and counters["executed_periods"] == 399
    assert counters["bytes_received"] == json.loads(result.stdout)["bytes_sent"]


def test_card_sim_listens_on_loopback_only():
    result = CliRunner().invoke(card_sim, ["--listen", "0.0.0.0:0"])
    assert result.exit_code == 2 and "loopback" in result.stderr


def test_sigusr1_while_planning_is_kept_and_the_stream_waits_at_the_start(tmp_path):
    """The operator presses hold while `stream` still plans: the command does not die (the
    signal's default action); it waits at the start, the card untouched, until SIGUSR2, then
    the stream ends."""
    nc = tmp_path / "part.nc"
    nc.write_text(GOOD)
    code = (
        "import os, signal, sys\n"
        "import nurbscnc.app.stream as s\n"
        "plan = s.ProgramStream.plan\n"
        "def planning(*a, **k):\n"
        "    os.kill(os.getpid(), signal.SIGUSR1)  # the hold arrives while planning\n"
        "    return plan(*a, **k)\n"
        "s.ProgramStream.plan = planning\n"
        "from nurbscnc.cli.main import main\n"
        "main(prog_name='nurbscnc')\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    with card_on("pty", CardConfig(speed=1.0)) as (card, ep):
        proc = subprocess.Popen(
            [sys.executable, "-c", code, "stream", str(nc), "--port", ep.path, "--quiet"],
            stderr=subprocess.PIPE,
            stdout=subprocess.PIPE,
            env=env,
        )
        try:
            first = proc.stderr.readline()
            waiting = proc.stderr.readline()  # printed once the stream waits
            time.sleep(0.2)
            untouched = (card.frames_received, card.executed_periods)
            proc.send_signal(signal.SIGUSR2)
            out, stderr = proc.communicate(timeout=20.0)
        finally:
            if proc.poll() is None:
                proc.kill()
    assert proc.returncode == 0, stderr.decode()
    assert b"feed hold asked while planning" in first
    assert b"feed hold" in waiting and b"SIGUSR2 continues" in waiting
    assert untouched == (1, 0)  # only asked where it stands (STATUS_REQUEST) before planning
    assert card.state.name == "DONE" and card.position.tolist() == [8000, 0, 0]


def test_unwritable_card_log_and_directory_program_exit_3(tmp_path):
    """Files that cannot be read or written are exit 3 with a message, never a traceback."""
    result = CliRunner().invoke(
        card_sim, ["--fast", "--once", "--log", str(tmp_path / "missing" / "log.csv")]
    )
    assert result.exit_code == 3, result.output
    assert "cannot write the log" in result.stderr
    assert "Traceback" not in result.output
    result = CliRunner().invoke(stream, [str(tmp_path), "--port", "/dev/null"])
    assert result.exit_code == 3, result.output
    assert "Is a directory" in result.stderr


PAUSED = "G21 G90 G17\nG0 X0 Y0\nG1 X5 F3000\nM0\nG1 X8\nM2\n"  # M0 at X5 (line 4)


def _stream_process(nc, ep) -> subprocess.Popen:
    """``nurbscnc stream NC --port EP --quiet`` as a child process (pipes for its output)."""
    return subprocess.Popen(
        [sys.executable, "-m", "nurbscnc", "stream", str(nc), "--port", ep.path, "--quiet"],
        stderr=subprocess.PIPE,
        stdout=subprocess.PIPE,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )


def test_m0_waits_at_rest_until_sigusr2(tmp_path):
    """At M0 the card stops (DONE at X5: its buffer drained), the command says so and waits;
    SIGUSR2 continues to the end."""
    nc = tmp_path / "part.nc"
    nc.write_text(PAUSED)
    with card_on("pty", CardConfig(speed=None)) as (card, ep):
        proc = _stream_process(nc, ep)
        try:
            waiting = proc.stderr.readline()
            time.sleep(0.3)
            at_stop = (card.state.name, card.position.tolist())
            proc.send_signal(signal.SIGUSR2)
            out, stderr = proc.communicate(timeout=30.0)
        finally:
            if proc.poll() is None:
                proc.kill()
    assert proc.returncode == 0, stderr.decode()
    assert waiting.decode() == "stream: M0 at line 4: the card is at rest; SIGUSR2 continues\n"
    assert at_stop == ("DONE", [5000, 0, 0])
    assert b"in 2 part(s)" in out and card.position.tolist() == [8000, 0, 0]


def test_a_second_stream_starts_where_the_card_stands_or_at_zero_not_a_restart(tmp_path):
    """A program starts where the card stands (as LinuxCNC's): GOOD again from X8 goes back
    to X0 Y0 first (8 mm more travel than from X0), a relative program moves on from X8;
    --zero declares the card at the program's start (machine zero) instead."""
    from nurbscnc.cli.card import card_position

    nc = tmp_path / "part.nc"
    nc.write_text(GOOD)
    rel = tmp_path / "rel.nc"
    rel.write_text("G21 G91 G17\nG1 X2 Y-1 F3000\nM2\n")
    with card_on("pty", CardConfig(speed=None)) as (card, ep):
        first = run_stream([nc, "--port", ep.path, "--quiet", "--json"])
        assert first.exit_code == 0, first.output
        again = run_stream([nc, "--port", ep.path, "--quiet", "--json"])
        assert again.exit_code == 0, again.output
        assert card.positions_set == 0 and card.position.tolist() == [8000, 0, 0]
        # the way back from X8 to X0 (G0) makes the second run longer than the first
        periods = [json.loads(r.stdout)["executed_periods"] for r in (first, again)]
        assert periods[1] > periods[0]
        moved_on = run_stream([rel, "--port", ep.path, "--quiet"])
        assert moved_on.exit_code == 0, moved_on.output
        assert card.position.tolist() == [10000, -1000, 0]  # (8 + 2, 0 - 1) mm · 1000
        read = CliRunner().invoke(card_position, ["--port", ep.path])
        assert read.exit_code == 0
        assert read.stdout == (
            "card: DONE, position [10000, -1000, 0] steps "
            "(10.0000, -1.0000, 0.0000 mm, machine coordinates)\n"
        )
        zeroed = run_stream([nc, "--port", ep.path, "--quiet", "--zero", "--json"])
        assert zeroed.exit_code == 0, zeroed.output
        assert json.loads(zeroed.stdout)["final_position_steps"] == [8000, 0, 0]
        assert card.positions_set == 1  # declared at X0 Y0, then moved 8 mm
        moved = CliRunner().invoke(card_position, ["--port", ep.path, "--set", "0,0,0", "--json"])
        assert json.loads(moved.stdout) == {
            "ok": True,
            "state": "DONE",
            "position_steps": [0, 0, 0],
            "position_mm": [0.0, 0.0, 0.0],
        }
        assert run_stream([rel, "--port", ep.path, "--quiet"]).exit_code == 0
        assert card.position.tolist() == [2000, -1000, 0] and card.positions_set == 2


def test_feed_override_and_from_line_on_the_command_line(tmp_path):
    nc = tmp_path / "part.nc"
    nc.write_text(GOOD)
    periods = {}
    with card_on("pty", CardConfig(speed=None)) as (card, ep):
        for pct in (100, 50):
            res = run_stream([nc, "--port", ep.path, "--json", "--zero", "--feed-override", pct])
            assert res.exit_code == 0, res.output
            body = json.loads(res.stdout)
            assert body["feed_override"] == pct / 100 and body["sections"] == 1
            periods[pct] = body["executed_periods"]
        # Line 4 (G1 X8 Y0) starts at X5 Y2: the lead-in from X0 Y0 (Z stays 0: the highest Z)
        res = run_stream([nc, "--port", ep.path, "--json", "--zero", "--from-line", "4"])
        assert res.exit_code == 0, res.output
        assert card.position.tolist() == [8000, 0, 0]
        bad = run_stream([nc, "--port", ep.path, "--from-line", "99"])
        assert bad.exit_code == 2 and "no motion at or after line 99" in bad.stderr
        pts = run_stream([tmp_path / "x.csv", "--port", ep.path, "--feed-override", "50"])
        assert pts.exit_code == 2 and "need a program" in pts.stderr
    # 50 % doubles the motion time (the program's periods, to a period or two).
    assert abs(periods[50] - 2 * periods[100]) <= 2


def test_ctrl_c_while_waiting_at_m0_exits_130_with_the_cards_position(tmp_path):
    nc = tmp_path / "part.nc"
    nc.write_text(PAUSED)
    with card_on("pty", CardConfig(speed=None)) as (card, ep):
        proc = _stream_process(nc, ep)
        try:
            proc.stderr.readline()  # waiting at M0
            proc.send_signal(signal.SIGINT)
            _, stderr = proc.communicate(timeout=30.0)
        finally:
            if proc.poll() is None:
                proc.kill()
    assert proc.returncode == 130
    assert b"interrupted while waiting (M0 at line 4); the card stands at [5000, 0, 0]" in stderr
    assert card.position.tolist() == [5000, 0, 0]


#: A non-default command-line value of every planning option (cli.options.planning_options).
NON_DEFAULT = {
    "algorithm": ["--algorithm", "adaptive"],
    "corner_feed": ["--corner-feed", "peak"],
    "dynamics": ["--dynamics", "global"],
    "blend_tolerance": ["--blend-tolerance", "0.05"],
    "interpolator": ["--interpolator", "taylor"],
    "lookahead": ["--lookahead", "7"],
    "precompensate": ["--precompensate"],
    "reference_tolerance": ["--reference-tolerance", "5"],
    "smooth": ["--no-smooth"],
}


def test_every_planning_option_has_a_non_default_value_here():
    from nurbscnc.app.settings import PLANNING_KEYS

    assert set(NON_DEFAULT) == set(PLANNING_KEYS)


@pytest.mark.parametrize("key", sorted(NON_DEFAULT))
def test_every_planning_option_reaches_the_streams_planner_as_runs(tmp_path, monkeypatch, key):
    """`stream` and `run` given one planning option at a non-default value plan with equal
    RunOptions (each captured where it reaches its planner; nothing is planned or sent), and
    they differ from the defaults: no option is dropped on the way to the stream."""
    import nurbscnc.app.stream as app_stream
    import nurbscnc.pipeline as pipeline
    from nurbscnc.cli.main import main
    from nurbscnc.pipeline import RunOptions

    nc = tmp_path / "part.nc"
    nc.write_text(GOOD)
    seen = {}

    def planned(name):
        def capture(_prog, _mach, options, *_args, **_kwargs):
            seen[name] = options
            raise KeyboardInterrupt  # stop before anything is planned, written or sent

        return capture

    monkeypatch.setattr(pipeline, "run_program", planned("run"))
    monkeypatch.setattr(app_stream, "stream_job", planned("stream"))
    runner = CliRunner()
    runner.invoke(main, ["run", str(nc), "-o", str(tmp_path / "p.csv"), *NON_DEFAULT[key]])
    with card_on("pty") as (_card, ep):
        runner.invoke(main, ["stream", str(nc), "--port", ep.path, *NON_DEFAULT[key]])
    assert seen["stream"] == seen["run"] != RunOptions()


def test_stream_precompensate_executes_the_compensated_reference(tmp_path):
    """`stream --precompensate` plans the whole program as `run --precompensate` does and
    streams its points: the card executes the compensated reference, quantised to steps, and
    that reference leaves the uncompensated one by more than a step somewhere."""
    from nurbscnc.cli.main import main

    nc = tmp_path / "part.nc"
    nc.write_text(GOOD)
    comp, plain = tmp_path / "comp.csv", tmp_path / "plain.csv"
    runner = CliRunner()
    for args in (["-o", comp, "--precompensate"], ["-o", plain]):
        done = runner.invoke(main, ["run", str(nc), *map(str, args)])
        assert done.exit_code == 0, done.output
    with card_on("pty") as (card, ep):
        result = run_stream([nc, "--port", ep.path, "--precompensate", "--json"])
    assert result.exit_code == 0, result.output
    assert np.array_equal(card.executed_pulses(), expected_pulses(comp))
    executed = np.cumsum(card.executed_pulses(), axis=0)
    uncompensated = np.cumsum(expected_pulses(plain), axis=0)
    n = max(len(executed), len(uncompensated))
    pad = lambda steps: np.vstack([steps, np.repeat(steps[-1:], n - len(steps), axis=0)])  # noqa: E731
    assert np.abs(pad(executed) - pad(uncompensated)).max() > 1


def _counting_opens(monkeypatch) -> list:
    """Every port opened through the sender's ``open_port`` from now on (its path)."""
    from nurbscnc.output.stream import sender

    opened, real = [], sender.open_port

    def counted(port, *args, **kwargs):
        opened.append(port)
        return real(port, *args, **kwargs)

    monkeypatch.setattr(sender, "open_port", counted)
    return opened


def test_stream_opens_the_port_once_to_read_the_card_and_stream(tmp_path, monkeypatch):
    """Reading where the card stands and streaming share one opening of the port: a port
    opened anew may reset a card (DTR on open) or be taken by another program between."""
    nc = tmp_path / "part.nc"
    nc.write_text(GOOD)
    opened = _counting_opens(monkeypatch)
    with card_on("pty") as (card, ep):
        result = run_stream([nc, "--port", ep.path, "--json"])
    assert result.exit_code == 0, result.output
    assert opened == [ep.path]
    assert card.position.tolist() == [8000, 0, 0]


def test_stream_of_a_bad_program_never_opens_the_port(tmp_path, monkeypatch):
    nc = tmp_path / "part.nc"
    nc.write_text(LATE_ERROR)
    opened = _counting_opens(monkeypatch)
    with card_on("pty") as (card, ep):
        result = run_stream([nc, "--port", ep.path])
    assert result.exit_code == 2, result.output
    assert opened == [] and card.report()["executed_periods"] == 0
