"""Memory bounded by the program, not by the motion time (issue 14): ``run`` of a short program
with 1.5 h of slow motion (5.4 million reference points) under an address-space cap.

The cap is the start-up footprint of the same command on a one-move program (measured here,
in a child, as its own VmPeak: the imports' share differs between machines) plus 200 MB.
Whole arrays of the reference points (t, τ, s, v, a, piece, x, y, z, u, line: 88 bytes a
row) need 475 MB for this program, so a ``run`` that holds them fails under the cap.
Measured (this test's program and command, ``run -o points.npz --dynamics off``): main
240dbb2 (whole arrays) peaks at 894 MB VmPeak against 374 MB at start-up and, under this
cap, fails (MemoryError, exit 1); window by window it peaks at 425 MB, capped or not. (The 2 h
version, 7.2 million points: 1058 MB VmPeak / 808 MB peak RSS on 240dbb2, 415 MB / 165 MB
window by window.)
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

pytestmark = pytest.mark.skipif(
    not sys.platform.startswith("linux"), reason="reads VmPeak from /proc (Linux)"
)

#: The child reports its own peak virtual size [kB] on stderr as it exits.
CHILD = r"""
import atexit, os, resource, sys
cap = int(os.environ.get("NURBSCNC_TEST_AS_CAP", "0"))
if cap:  # the cap is set by the child itself, before any import (no preexec_fn in a
    #      threaded parent: a fork there can deadlock before exec)
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
def peak():
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmPeak:"):
                sys.stderr.write("VMPEAK " + line.split()[1] + "\n")
atexit.register(peak)
from nurbscnc.cli.main import main
main(sys.argv[1:])
"""
#: Room above the start-up footprint [bytes]: windows of 64 Ki rows, the NPZ spool's copy
#: block and zlib need a few tens of MB; the whole arrays would need 475 MB.
HEADROOM = 200 * 2**20
FEED_MM_MIN = 40.0  # 0.667 mm/s: 24 moves of 150 mm take 1.5 h


def long_program() -> str:
    corners = [(150, 0), (150, 150), (0, 150), (0, 0)]
    moves = [f"G1 X{x} Y{y}" for x, y in (corners[k % 4] for k in range(24))]
    return "\n".join(["G21 G17 G90 G94", "G0 X0 Y0 Z0", f"F{FEED_MM_MIN:g}", *moves, "M2"]) + "\n"


def run_capped(args, cap_bytes=None):
    env = dict(os.environ, NURBSCNC_TEST_AS_CAP=str(cap_bytes or 0))
    proc = subprocess.run(
        [sys.executable, "-c", CHILD, *args], capture_output=True, text=True, env=env, timeout=900
    )
    peaks = [int(x.split()[1]) for x in proc.stderr.splitlines() if x.startswith("VMPEAK ")]
    return proc, peaks[-1] * 1024 if peaks else None


def test_run_of_hours_of_motion_fits_under_a_cap_whole_arrays_exceed(tmp_path):
    from nurbscnc.machine.profile import load_machine
    from nurbscnc.plan.lookahead import plan_program
    from nurbscnc.plan.options import LookaheadOptions
    from nurbscnc.plan.timing import sample_count
    from nurbscnc.program.interpret import interpret_text

    small = tmp_path / "one.nc"
    small.write_text("G21 G90\nG1 X1 F600\nM2\n")
    proc, startup = run_capped(
        ["run", str(small), "-o", str(tmp_path / "one.npz"), "--dynamics", "off", "--quiet"]
    )
    assert proc.returncode == 0, proc.stderr
    assert startup is not None

    text = long_program()
    prog = tmp_path / "long.nc"
    prog.write_text(text)
    machine = load_machine()
    plan = plan_program(interpret_text(text), machine, LookaheadOptions(dynamics="off"))
    n = sample_count(plan.pieces, plan.profile, machine.servo.period_s)
    assert 5.3e6 < n < 5.5e6  # 1.5 h at 1 ms
    assert 88 * n > 2 * HEADROOM  # whole arrays would not fit: the cap means something

    out = tmp_path / "points.npz"
    proc, peak = run_capped(
        ["run", str(prog), "-o", str(out), "--dynamics", "off", "--json"], startup + HEADROOM
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert peak is not None and peak <= startup + HEADROOM
    summary = json.loads(proc.stdout)
    assert summary["samples"] == n
    with np.load(out) as data:
        t = data["t"]
        assert t.size == n and data["line"].size == n
        assert t[-1] == (n - 1) * machine.servo.period_s
        np.testing.assert_array_equal(data["x"][[0, -1]], [0.0, 0.0])
