#!/usr/bin/python3
"""Record LinuxCNC's canonical moves for NC programs into JSON goldens (the test oracle).

Run with the system Python that has LinuxCNC 2.9's ``gcode`` module (``/usr/bin/python3``);
nurbscnc is not imported. For each program the interpreter is run twice:

* ``gcode.parse`` (LinuxCNC's interpreter with Python canon callbacks, as AXIS previews a
  program) gives every move at full double precision: traverses, feeds, arcs, dwells, probes;
* ``rs274 -g`` (the same interpreter with the stand-alone canon, 4 decimals) gives the calls the
  ``gcode`` module does not pass to Python: program stops (M0, M1, M60) and spindle events.
  Its motion calls are aligned one to one with the ``gcode`` moves (kinds and positions to its
  printed precision); the stops are inserted at their place in that sequence.

Units (decision): every length in a golden is **mm**, feeds **mm/s**, angles (A B C) degrees,
dwells s. The ``gcode`` module always reports lengths in inches (it divides mm values by 25.4),
so they are multiplied by 25.4 here; feeds come as inch/min and become mm/s (× 25.4 / 60).
End points are **machine coordinates of the controlled point**: the program coordinates plus
the G92 offset, turned by the XY rotation (G10 L2 R), plus the G5x offset, plus the tool length
offset (G43) — the order LinuxCNC's canon and preview apply them. An arc's centre is stored as a
point in the plane of the arc's start (its axial coordinate is the start's), transformed the
same way; its ``normal`` is the plane's (+Z for G17, +Y for G18, +X for G19) and ``rotation``
LinuxCNC's signed turn count (> 0 counter-clockwise about the normal; |rotation| - 1 full turns).

Initial state (saved beside the programs so nurbscnc can be given the same): machine in mm
(unit code ``G21``, as nurbscnc's default), start at the origin, block delete on, the tool table
``tests/programs/real/tools.tbl`` (mm) and the parameter file ``tests/programs/real/params.var``
(all offsets zero, G54). Axes X Y Z A B C exist (mask 0o77), U V W do not. Each program runs in
its own directory, so ``o<name> call`` finds ``name.ngc`` beside it.

Usage::

    /usr/bin/python3 tools/record_goldens.py                 # every program in the manifest
    /usr/bin/python3 tools/record_goldens.py --only cds      # names containing "cds"
    /usr/bin/python3 tools/record_goldens.py --stdout FILE   # one program, JSON on stdout
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from lcnc_recorder import Recorder, load_tool_database, read_tool_table  # noqa: E402
from lcnc_rs274 import (  # noqa: E402
    CALL,
    MOTION,
    RS274,
    block_line,
    error_line,
    merge_events,
    rs274_calls,
    rs274_error,
)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
REAL = os.path.join(ROOT, "tests", "programs", "real")
GOLDEN = os.path.join(ROOT, "tests", "golden", "linuxcnc")
TOOLS = os.path.join(REAL, "tools.tbl")
PARAMS = os.path.join(REAL, "params.var")
MANIFEST = os.path.join(REAL, "manifest.json")
LINUXCNC_VERSION = "2.9.0~pre1+git20230208.f1270d6ed7 (Debian linuxcnc-uspace)"
EOF_ERROR = "File ended with no percent sign or program end"


def record(path: str, tools: dict, rotary: bool = False) -> dict:
    """Run LinuxCNC on one program; the golden as a dict."""
    import gcode  # LinuxCNC's interpreter module (only in the system Python)

    with open(path, "rb") as fh:
        digest = hashlib.sha256(fh.read()).hexdigest()
    tmp = tempfile.mkdtemp(prefix="goldens-")
    try:
        var = os.path.join(tmp, "params.var")
        shutil.copy(PARAMS, var)  # LinuxCNC rewrites its parameter file at the end
        canon = Recorder(tools, var)
        canon.rotary = rotary
        cwd = os.getcwd()
        os.chdir(os.path.dirname(os.path.abspath(path)))
        try:
            # Unit code G21; init code F0: the feed starts at zero as on a real machine
            # (the module alone would start it at 1 unit/min and accept G1 without F).
            result, last_line = gcode.parse(os.path.abspath(path), canon, "G21", "F0")
        finally:
            os.chdir(cwd)
        accepted = result <= gcode.MIN_ERROR
        eof_only = not accepted and gcode.strerror(result).startswith(EOF_ERROR)
        moves, alignment, tol_mm = canon.moves, "program refused", 1e-9
        message = gcode.strerror(result).strip()
        if accepted:
            calls, failed_block = rs274_calls(path, tools, PARAMS, tmp)
            moves, alignment, tol_mm = merge_events(canon.moves, calls, tools)
            if failed_block and alignment.startswith("rs274"):
                # The preview accepts what rs274 refuses, where the two disagree (the gcode
                # module keeps the old tool's radius after M6: nc_files/mmount): rs274's
                # refusal, at the block it printed, is the record.
                accepted, alignment = False, "rs274 refuses it (the gcode module accepts it)"
                message = rs274_error(path, tools, tmp)
                last_line = block_line(path, failed_block, moves)
        else:
            last_line = error_line(path, last_line, rs274_calls(path, tools, PARAMS, tmp)[1])
            # A call of a subroutine that is nowhere makes LinuxCNC read to the end of the
            # file looking for it; the line it stops at is not the error's, the message names
            # it: "EOF in file:… seeking o-word: o<name> from line: N".
            seeking = re.search(r"seeking o-word: \S+ from line: (\d+)", gcode.strerror(result))
            if seeking:
                last_line = int(seeking.group(1))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    golden = {
        "program": os.path.relpath(os.path.abspath(path), ROOT),
        "sha256": digest,
        "linuxcnc": LINUXCNC_VERSION,
        "units": "mm, mm/s, s, degrees; machine coordinates",
        "initial_state": {
            "units": "G21",
            "feed": 0.0,
            "start": [0.0] * 6,
            "block_delete": True,
            "tool_table": "tests/programs/real/tools.tbl",
            "parameters": "tests/programs/real/params.var",
        },
        "accepted": accepted,
        "error": None
        if accepted
        else {
            "line": last_line,
            "message": message.replace(ROOT + os.sep, ""),
        },
        "record": alignment,
        "tolerance_mm": tol_mm,
        "messages": canon.messages,
        # A refused program's moves are dropped, except when LinuxCNC only objects to a missing
        # program end (M2/M30/%): a reader that runs such a file to its end is compared with them.
        "moves": moves if accepted or eof_only else [],
    }
    return golden


def record_wrapped(path: str, ini: str) -> dict:
    """``rs274 -g -i INI`` alone on ``path`` (the ``gcode`` module reads no ini file, so
    ``[AXIS_A]WRAPPED_ROTARY`` reaches only rs274's interpreter): its moves, in program units
    and degrees to 4 decimals, taken to machine coordinates by the G5x and G92 offsets it
    prints before them (``SET_G5X_OFFSET``, ``SET_G92_OFFSET``: machine = printed + G92 +
    G5x; a program with an XY rotation is not recorded), and its refusal (message, refused
    block)."""
    with open(path, "rb") as fh:
        digest = hashlib.sha256(fh.read()).hexdigest()
    tmp = tempfile.mkdtemp(prefix="goldens-")
    try:
        res = subprocess.run(
            [RS274, "-g", "-i", os.path.abspath(ini), os.path.abspath(path)],
            cwd=tmp,
            capture_output=True,
            text=True,
            timeout=120,
            stdin=subprocess.DEVNULL,
            env=dict(os.environ, HOME=tmp),
        )
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    moves = []
    g5x, g92 = [0.0] * 6, [0.0] * 6
    for raw in res.stdout.splitlines():
        m = CALL.match(raw)
        if m and m.group(1) == "SET_G5X_OFFSET":
            g5x = [float(v) for v in m.group(2).split(",")[1:7]]
        elif m and m.group(1) == "SET_G92_OFFSET":
            g92 = [float(v) for v in m.group(2).split(",")[:6]]
        elif m and m.group(1) == "SET_XY_ROTATION" and float(m.group(2)) != 0.0:
            raise SystemExit(f"{path}: an XY rotation: not recorded (machine = printed + offsets)")
        elif m and m.group(1) in ("STRAIGHT_TRAVERSE", "STRAIGHT_FEED"):
            printed = [float(v) for v in m.group(2).split(",")]
            end = [round(p + a + b, 4) for p, a, b in zip(printed, g92, g5x)]
            moves.append({"kind": MOTION[m.group(1)], "end": end})
    err = [t.strip() for t in res.stderr.splitlines() if t.strip()]
    refused = len(err) >= 3  # "executing", the message, the refused block
    return {
        "program": os.path.relpath(os.path.abspath(path), ROOT),
        "sha256": digest,
        "linuxcnc": LINUXCNC_VERSION,
        "ini": os.path.relpath(os.path.abspath(ini), ROOT),
        "units": "rs274 -g as printed plus its offsets: machine coordinates, program units "
        "(mm), degrees, 4 decimals",
        "accepted": not refused,
        "error": {"message": err[-2], "block": err[-1]} if refused else None,
        "moves": moves,
    }


def record_wrapped_dir(program_dir: str, golden_dir: str, ini: str) -> None:
    """Every *.ngc of ``program_dir`` through :func:`record_wrapped`, one golden each."""
    os.makedirs(golden_dir, exist_ok=True)
    for name in sorted(f for f in os.listdir(program_dir) if f.endswith(".ngc")):
        golden = record_wrapped(os.path.join(program_dir, name), ini)
        with open(os.path.join(golden_dir, golden_name(name) + ".json"), "w") as fh:
            fh.write(golden_text(golden))
        print(f"{'ok ' if golden['accepted'] else 'ERR'} {name}: {len(golden['moves'])} moves")


def golden_text(golden: dict) -> str:
    """JSON with one compact move per line (diffable, and small enough to commit)."""
    head = json.dumps({k: v for k, v in golden.items() if k != "moves"}, indent=1)
    moves = ",\n".join(json.dumps(m, separators=(",", ":")) for m in golden["moves"])
    return head[:-2] + ',\n "moves": [\n' + moves + "\n]\n}\n"


def golden_name(rel_program: str) -> str:
    """``linuxcnc/nc_files/cds.ngc`` → ``linuxcnc__nc_files__cds``."""
    stem = os.path.splitext(rel_program)[0]
    return stem.replace("/", "__")


def manifest_programs() -> list[str]:
    """Program paths (relative to tests/programs/real) the manifest marks as programs."""
    with open(MANIFEST) as fh:
        entries = json.load(fh)["files"]
    return [e["path"] for e in entries if e["role"] != "subroutine"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", help="record only programs whose path contains this text")
    ap.add_argument("--stdout", metavar="FILE", help="record FILE and print its golden")
    ap.add_argument("--json-out", metavar="OUT", help="with --stdout: write the golden to OUT")
    ap.add_argument(
        "--programs", metavar="DIR", help="record every *.ngc of DIR (not the manifest)"
    )
    ap.add_argument("--goldens", metavar="DIR", help="with --programs: where the goldens go")
    ap.add_argument(
        "--rotary", action="store_true", help="also record the feed mode and canon rate"
    )
    ap.add_argument(
        "--wrapped-ini", metavar="INI", help="with --programs: rs274 -g -i INI only (wrapped A)"
    )
    args = ap.parse_args(argv)
    if args.wrapped_ini:
        record_wrapped_dir(args.programs, args.goldens, args.wrapped_ini)
        return 0
    tools = read_tool_table(TOOLS)
    if args.stdout:
        load_tool_database(TOOLS)
        golden = record(args.stdout, tools, args.rotary)
        if args.json_out:  # the interpreter may print (PRINT, ...) comments on stdout
            with open(args.json_out, "w") as fh:
                json.dump(golden, fh)
        else:
            json.dump(golden, sys.stdout)
        return 0
    golden_dir, program_dir, programs = GOLDEN, REAL, manifest_programs()
    if args.programs:
        program_dir, golden_dir = os.path.abspath(args.programs), os.path.abspath(args.goldens)
        programs = sorted(f for f in os.listdir(program_dir) if f.endswith(".ngc"))
    os.makedirs(golden_dir, exist_ok=True)
    counts = {"accepted": 0, "refused": 0, "crashed": 0}
    for rel in programs:
        if args.only and args.only not in rel:
            continue
        # One process per program: LinuxCNC's interpreter keeps state between parses (G10 L1
        # rewrites the tool table), and a crash of the module must not take the others along.
        out = os.path.join(golden_dir, golden_name(rel) + ".tmp")
        res = subprocess.run(
            [
                sys.executable,
                os.path.abspath(__file__),
                "--stdout",
                os.path.join(program_dir, rel),
                "--json-out",
                out,
                *(["--rotary"] if args.rotary else []),
            ],
            capture_output=True,
            text=True,
        )
        if res.returncode != 0 or not os.path.exists(out):
            print(f"CRASH {rel}: exit {res.returncode}, no golden written: {res.stderr[-1500:]}")
            counts["crashed"] += 1
            continue
        with open(out) as fh:
            golden = json.load(fh)
        os.remove(out)
        counts["accepted" if golden["accepted"] else "refused"] += 1
        with open(os.path.join(golden_dir, golden_name(rel) + ".json"), "w") as fh:
            fh.write(golden_text(golden))
        state = "ok " if golden["accepted"] else "ERR"
        print(
            f"{state} {rel}: {len(golden['moves'])} moves, {golden['record']}"
            + (
                ""
                if golden["accepted"]
                else f" — line {golden['error']['line']}: {golden['error']['message'][:100]}"
            )
        )
    print(
        f"{counts['accepted']} accepted, {counts['refused']} refused by LinuxCNC, "
        f"{counts['crashed']} crashed the recorder"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
