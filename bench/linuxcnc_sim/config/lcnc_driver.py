#!/usr/bin/python3
"""Headless LinuxCNC "display": run one G-code program and record the commanded position.

Started by the `linuxcnc` script as the [DISPLAY] program (argv: -ini INIFILE). Environment:
  LCNC_PROGRAM   the program to run (absolute path)
  LCNC_RAW       where halsampler writes its samples (tag line x y z per servo period)
  LCNC_STATUS    where a small JSON status (errors, overruns, wall time) is written
  LCNC_TIMEOUT   seconds before giving up (default 1200)
When this script exits, the `linuxcnc` script shuts LinuxCNC down.

A copy of ../shared/tools/linuxcnc-sim/config/lcnc_driver.py for a machine with any number of
joints (homing waits for every joint the stat reports), used by the 3-axis and the 4-axis
simulations alike, whose run ends only after the machine stayed idle at rest for
``IDLE_END_S`` (the README beside this folder).
"""

import json
import os
import signal
import subprocess
import sys
import time

import linuxcnc

prog = os.environ["LCNC_PROGRAM"]
raw_path = os.environ["LCNC_RAW"]
status_path = os.environ["LCNC_STATUS"]
timeout = float(os.environ.get("LCNC_TIMEOUT", "1200"))
#: How long the machine must stay idle at rest (interpreter idle, queue empty, speed 0) for
#: the run to end [s]: a single status poll saying so ended long runs mid-program.
IDLE_END_S = 2.0
status = {"program": prog, "errors": [], "messages": [], "resumes": 0}


def log(msg):
    print(f"[lcnc_driver] {msg}", file=sys.stderr, flush=True)


def halcmd(*args):
    return subprocess.run(
        ["halcmd", *args], capture_output=True, text=True, check=True
    ).stdout.strip()


def drain_errors(e):
    while True:
        m = e.poll()
        if not m:
            return
        kind, text = m
        if kind in (linuxcnc.NML_ERROR, linuxcnc.OPERATOR_ERROR):
            status["errors"].append(text)
            log(f"error: {text}")
        else:
            status["messages"].append(text)


def task_pid(ini):
    """PID of this instance's milltask (its command line names our INI file), or None."""
    r = subprocess.run(["pgrep", "-f", f"milltask -ini {ini}"], capture_output=True, text=True)
    pids = [int(p) for p in r.stdout.split()]
    return pids[0] if pids else None


def alive(pid):
    try:
        os.kill(pid, 0)
        return True
    except ProcessLookupError:
        return False


def main():
    ini = sys.argv[sys.argv.index("-ini") + 1] if "-ini" in sys.argv else ""
    s = linuxcnc.stat()
    c = linuxcnc.command()
    e = linuxcnc.error_channel()
    t0 = time.time()
    while True:  # task may still be starting
        try:
            s.poll()
            if s.task_state in (
                linuxcnc.STATE_ESTOP,
                linuxcnc.STATE_ESTOP_RESET,
                linuxcnc.STATE_OFF,
                linuxcnc.STATE_ON,
            ):
                break
        except linuxcnc.error:
            pass
        if time.time() - t0 > 60:
            raise SystemExit("task did not come up")
        time.sleep(0.1)

    for state in (linuxcnc.STATE_ESTOP_RESET, linuxcnc.STATE_ON):
        c.state(state)
        c.wait_complete()
    c.mode(linuxcnc.MODE_MANUAL)
    c.wait_complete()
    c.home(-1)  # HOME_SEARCH_VEL = 0: every joint homes in place at 0
    c.wait_complete()
    t1 = time.time()
    while True:
        s.poll()
        joints = s.joints
        if all(s.homed[:joints]):
            break
        if time.time() - t1 > 20:
            raise SystemExit(f"homing did not finish: {s.homed[:joints]}")
        time.sleep(0.05)
    pid = task_pid(ini)
    c.mode(linuxcnc.MODE_AUTO)
    c.wait_complete()
    c.program_open(prog)
    c.wait_complete()
    drain_errors(e)

    raw = open(raw_path, "w")
    sampler = subprocess.Popen(["halsampler", "-t", "-c", "0"], stdout=raw)
    time.sleep(0.2)
    halcmd("setp", "sampler.0.enable", "1")
    time.sleep(0.02)
    t_run = time.time()
    c.auto(linuxcnc.AUTO_RUN, 0)
    started = False
    idle_since = last_key = None
    last_check = time.time()
    while True:
        time.sleep(0.01)
        if pid and time.time() - last_check > 1.0:
            last_check = time.time()
            if not alive(pid):  # seen once at program end: motion done, task gone
                s.poll()
                status["task_died"] = True
                status["warnings"] = [
                    f"milltask exited during the run (interp_state {s.interp_state}, "
                    f"queue {s.queue}, current_vel {s.current_vel})"
                ]
                log(status["warnings"][0])
                break
        s.poll()
        drain_errors(e)
        if s.interp_state != linuxcnc.INTERP_IDLE:
            started = True
        if s.paused or s.interp_state == linuxcnc.INTERP_PAUSED:  # M0/M1: resume at once
            c.auto(linuxcnc.AUTO_RESUME)
            status["resumes"] += 1
            time.sleep(0.05)
            continue
        key = (s.interp_state, s.exec_state, s.task_mode, s.state)
        if key != last_key and len(status.setdefault("transitions", [])) < 200:
            status["transitions"].append(
                [
                    round(time.time() - t_run, 3),
                    *key,
                    s.read_line,
                    s.motion_line,
                    s.queue,
                    s.current_vel,
                ]
            )
            last_key = key
        if (
            started
            and s.interp_state == linuxcnc.INTERP_IDLE
            and s.queue == 0
            and s.current_vel == 0.0
        ):
            if idle_since is None:
                idle_since = time.time()
            if time.time() - idle_since >= IDLE_END_S:
                break
        else:
            idle_since = None
        if not started and time.time() - t_run > 30.0 and s.interp_state == linuxcnc.INTERP_IDLE:
            status["errors"].append(
                f"program did not start (task_mode {s.task_mode}, task_state {s.task_state}, "
                f"exec_state {s.exec_state}, file {s.file!r}, read_line {s.read_line})"
            )
            break
        if time.time() - t_run > timeout:
            status["errors"].append("timeout")
            c.abort()
            break
    status["wall_s"] = time.time() - t_run
    time.sleep(0.1)  # a few more periods at rest
    halcmd("setp", "sampler.0.enable", "0")
    for _ in range(500):
        if int(halcmd("getp", "sampler.0.curr-depth")) == 0:
            break
        time.sleep(0.02)
    time.sleep(0.3)
    sampler.send_signal(signal.SIGINT)
    try:
        sampler.wait(timeout=5)
    except subprocess.TimeoutExpired:
        sampler.kill()
    raw.close()
    status["overruns"] = int(halcmd("getp", "sampler.0.overruns"))
    drain_errors(e)
    if not status.get("task_died"):
        c.state(linuxcnc.STATE_OFF)
        c.wait_complete()
    with open(status_path, "w") as f:
        json.dump(status, f, indent=1)
    log(
        f"done: {status['wall_s']:.2f} s wall, {len(status['errors'])} errors, "
        f"overruns {status['overruns']}"
    )


if __name__ == "__main__":
    try:
        main()
    except BaseException as exc:  # record why, then let linuxcnc shut down
        status["errors"].append(f"driver: {exc!r}")
        with open(status_path, "w") as f:
            json.dump(status, f, indent=1)
        raise
