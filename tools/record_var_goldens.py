#!/usr/bin/python3
"""Record LinuxCNC's moves and the parameter file it writes back, for the programs of
``tests/programs/varfile/`` (each ``NAME.ngc`` with its parameter file ``NAME.var``), into
``tests/golden/varfile/NAME.json`` (the test oracle of tests/test_varfile_linuxcnc.py).

Runs LinuxCNC 2.9's stand-alone interpreter, ``rs274 -g -v FILE``, on a copy of the
parameter file: it reads the file before the program and writes it back at the end
(``Interp::exit``, save_parameters). Its machine unit is the inch (2.9's rs274 has no mm
machine), so the parameter files here are in inches; the test gives nurbscnc (a mm machine)
the same file with every length × 25.4 and compares what it writes back ÷ 25.4.

The moves are rs274's printed calls (4 decimals of the program's mm) replayed through
record_goldens.py's Recorder: machine coordinates of each end point in mm (program + G92,
turned by the XY rotation, + the G5x offset); M6 / M0 / M1 as pauses. The written file is
recorded as LinuxCNC wrote it: ``{"written": [[number, "value text"], ...]}``.

Usage: /usr/bin/python3 tools/record_var_goldens.py            # every program
       /usr/bin/python3 tools/record_var_goldens.py --stdout NAME  # one, JSON on stdout
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from lcnc_rs274 import MOTION, RS274, RS274_TOL_MM, parse_calls, replay_rs274  # noqa: E402
from record_goldens import LINUXCNC_VERSION  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PROGRAMS = os.path.join(ROOT, "tests", "programs", "varfile")
GOLDEN = os.path.join(ROOT, "tests", "golden", "varfile")
_STOPS = {"PROGRAM_STOP": "M0", "OPTIONAL_PROGRAM_STOP": "M1", "CHANGE_TOOL": "M6"}


def record(name: str) -> dict:
    ngc = os.path.join(PROGRAMS, name + ".ngc")
    tmp = tempfile.mkdtemp(prefix="var-goldens-")
    try:
        var = os.path.join(tmp, "params.var")
        shutil.copy(os.path.join(PROGRAMS, name + ".var"), var)
        res = subprocess.run(
            [RS274, "-g", "-v", var, ngc],
            cwd=tmp,
            capture_output=True,
            text=True,
            timeout=60,
            stdin=subprocess.DEVNULL,
            env=dict(os.environ, HOME=tmp),  # rs274's tool database of its own
        )
        calls = parse_calls(res.stdout)
        replay = replay_rs274(calls, {}).moves
        moves, k = [], 0
        for call, _ in calls:
            if call in MOTION:
                move = replay[k]
                k += 1
                moves.append({key: move[key] for key in ("kind", "end") if key in move})
            elif call in _STOPS:
                moves.append({"kind": "pause", "code": _STOPS[call]})
        with open(var) as fh:
            written = [[int(n), v] for n, v in (line.split() for line in fh if line.strip())]
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return {
        "program": os.path.relpath(ngc, ROOT),
        "parameters": os.path.relpath(os.path.join(PROGRAMS, name + ".var"), ROOT),
        "linuxcnc": LINUXCNC_VERSION,
        "command": "rs274 -g -v FILE (inch machine: the parameter file's lengths in inches)",
        "units": "mm; machine coordinates",
        "tolerance_mm": RS274_TOL_MM,
        "ended": "PROGRAM_END" in res.stdout or "FINISH" in res.stdout,
        "moves": moves,
        "written": written,
    }


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--stdout"]:  # one program's golden on stdout (the live test)
        print(json.dumps(record(argv[1])))
        return 0
    os.makedirs(GOLDEN, exist_ok=True)
    for file in sorted(os.listdir(PROGRAMS)):
        if not file.endswith(".ngc"):
            continue
        name = file[:-4]
        golden = record(name)
        with open(os.path.join(GOLDEN, name + ".json"), "w") as fh:
            json.dump(golden, fh, indent=1)
            fh.write("\n")
        print(f"{name}: {len(golden['moves'])} moves, {len(golden['written'])} parameters written")
    return 0


if __name__ == "__main__":
    sys.exit(main())
