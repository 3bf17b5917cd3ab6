"""nurbscnc against LinuxCNC 2.9 run on the fly (skipped, saying why, without LinuxCNC).

LinuxCNC is run through ``tools/record_goldens.py`` (the same recorder as ``make goldens``:
LinuxCNC's ``gcode`` module cross-checked with ``rs274``) with the system Python
``/usr/bin/python3``. Two checks:

* the committed goldens are what this LinuxCNC says now (a sample of the real programs is
  recorded again and must give the same golden, number for number);
* a differential on generated programs: seeded random programs of lines, arcs (centre and
  radius format, helical, all three planes, both arc directions, multi-turn), dwells, feeds,
  G90/G91, G20/G21 — what nurbscnc reads today — must give LinuxCNC's moves to 1e-9 mm.
"""

from __future__ import annotations

import json
import math
import random
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from tests.linuxcnc_compare import ROOT, compare, run_nurbscnc

SYSTEM_PYTHON = "/usr/bin/python3"
RS274 = "/usr/bin/rs274"
RECORDER = ROOT / "tools" / "record_goldens.py"


def _linuxcnc_missing() -> str | None:
    if not Path(RS274).exists():
        return f"LinuxCNC is not installed ({RS274} is missing)"
    if shutil.which(SYSTEM_PYTHON) is None:
        return f"{SYSTEM_PYTHON} is missing"
    probe = subprocess.run([SYSTEM_PYTHON, "-c", "import gcode"], capture_output=True)
    if probe.returncode != 0:
        return f"{SYSTEM_PYTHON} cannot import LinuxCNC's gcode module"
    return None


MISSING = _linuxcnc_missing()
pytestmark = pytest.mark.skipif(MISSING is not None, reason=MISSING or "")


def linuxcnc_golden(program: Path, tmp_path: Path) -> dict:
    """LinuxCNC's golden for ``program``, recorded now."""
    out = tmp_path / (program.stem + ".json")
    res = subprocess.run(
        [SYSTEM_PYTHON, str(RECORDER), "--stdout", str(program), "--json-out", str(out)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0 and out.exists(), f"recorder failed: {res.stderr[-2000:]}"
    return json.loads(out.read_text())


# One program of each kind of record: gcode module cross-checked, rs274 fallback (cutter
# compensation after M6), refused by LinuxCNC, stopped at end of file, inch, cycles, arcs,
# and the cycle and compensation goldens.
SAMPLE = [
    "linuxcnc/linuxcnc__nc_files__cds",
    "linuxcnc/linuxcnc__nc_files__comp",
    "linuxcnc/linuxcnc__nc_files__comp311",
    "linuxcnc/linuxcnc__interp__g18-g99-g81",
    "linuxcnc/linuxcnc__interp__good-arc.small.imperial",
    "linuxcnc/linuxcnc__interp-bad__ccomp-gouging",
    "linuxcnc/linuxcnc__tp__arc-feed__full_xz",
    "linuxcnc/camotics__heart__cutout",
    "linuxcnc/camotics__cds__cds",
    "linuxcnc_cycles/g83_peck_inch",
    "linuxcnc_cycles/g19_g87_inc",
    "linuxcnc_cycles/err_g74_l",
    "linuxcnc_comp/arcs_mixed",
    "linuxcnc_comp/err_gouge_line",
]


@pytest.mark.parametrize("name", SAMPLE)
def test_committed_golden_is_what_linuxcnc_says(name, tmp_path):
    committed = json.loads((ROOT / "tests" / "golden" / f"{name}.json").read_text())
    now = linuxcnc_golden(ROOT / committed["program"], tmp_path)
    assert now == committed, f"{name}: LinuxCNC now records something else; run `make goldens`"


def random_program(seed: int) -> str:
    """A program of what nurbscnc reads today, with arcs LinuxCNC accepts by construction.

    Arc end points are put on the start circle (printed to 6 decimals, far inside LinuxCNC's
    end-radius tolerance); the position is tracked in program units for G91 and G20.
    """
    rnd = random.Random(seed)
    inch = rnd.random() < 0.3
    scale = 1 / 25.4 if inch else 1.0
    lines = ["G20" if inch else "G21", "G90 G94 G40 G49 G80", f"F{600 * scale:.3f}"]
    pos = [0.0, 0.0, 0.0]
    planes = {"G17": (0, 1, 2), "G18": (2, 0, 1), "G19": (1, 2, 0)}
    letters = "XYZ"
    centre_letters = "IJK"
    for _ in range(30):
        plane = rnd.choice(list(planes))
        incremental = rnd.random() < 0.3
        mode = "G91" if incremental else "G90"
        kind = rnd.choice(["G0", "G1", "G1", "G2", "G3", "G2", "G3", "G4", "F", "G93"])
        if kind == "G4":
            lines.append(f"G4 P{rnd.uniform(0, 2):.3f}")
            continue
        if kind == "F":
            lines.append(f"F{rnd.uniform(50, 3000) * scale:.3f}")
            continue
        inverse_time = kind == "G93"  # a G1 in inverse time (F: 1/minutes), then back
        if inverse_time:
            kind = rnd.choice(["G1", "G2", "G3"])
        if kind in ("G0", "G1"):
            end = [p + rnd.uniform(-50, 50) * scale for p in pos]
            end = [round(e, 6) for e in end]
        else:
            a, b, n = planes[plane]
            r = rnd.uniform(2, 40) * scale
            phi0 = rnd.uniform(0, 2 * math.pi)
            centre = pos[:]
            centre[a] = pos[a] - r * math.cos(phi0)
            centre[b] = pos[b] - r * math.sin(phi0)
            phi1 = phi0 + rnd.uniform(0.1, 2 * math.pi - 0.1)
            end = pos[:]
            end[a] = round(centre[a] + r * math.cos(phi1), 6)
            end[b] = round(centre[b] + r * math.sin(phi1), 6)
            end[n] = round(pos[n] + rnd.uniform(-5, 5) * scale * (rnd.random() < 0.4), 6)
        words = []
        for i, letter in enumerate(letters):
            value = end[i] - pos[i] if incremental else end[i]
            words.append(f"{letter}{value:.6f}")
        if kind in ("G2", "G3"):
            a, b, _ = planes[plane]
            words += [
                f"{centre_letters[a]}{centre[a] - pos[a]:.6f}",
                f"{centre_letters[b]}{centre[b] - pos[b]:.6f}",
            ]
            if rnd.random() < 0.15:
                words.append("P2")
        if inverse_time:  # short moves at low F meet LinuxCNC's 0.1 units/min floor
            words.append(f"F{rnd.choice([rnd.uniform(1, 200), rnd.uniform(1e-4, 1e-2)]):.6f}")
            lines.append(f"G93 {plane} {mode} {kind} " + " ".join(words))
            lines.append(f"G94 F{600 * scale:.3f}")
        else:
            lines.append(f"{plane} {mode} {kind} " + " ".join(words))
        # Incremental words are rounded relative to the rounded position: track what was
        # written, not what was meant.
        if incremental:
            pos = [pos[i] + float(words[i][1:]) for i in range(3)]
        else:
            pos = [float(words[i][1:]) for i in range(3)]
    lines.append("M2")
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("seed", range(12))
def test_random_programs_match_linuxcnc(seed, tmp_path):
    program = tmp_path / f"random{seed}.ngc"
    program.write_text(random_program(seed))
    golden = linuxcnc_golden(program, tmp_path)
    assert golden["accepted"], f"LinuxCNC refuses the generated program: {golden['error']}"
    assert golden["tolerance_mm"] == 1e-9, golden["record"]
    compare(golden, run_nurbscnc(program))


def random_cycle_program(seed: int) -> str:
    """Canned-cycle blocks with random codes, planes, G90/G91, G98/G99, L, sticky words."""
    rnd = random.Random(1000 + seed)
    inch = rnd.random() < 0.25
    k = 1 / 25.4 if inch else 1.0
    plane = rnd.choice(["G17", "G18", "G19"])
    depth = {"G17": "Z", "G18": "Y", "G19": "X"}[plane]
    others = {"G17": "XY", "G18": "ZX", "G19": "YZ"}[plane]
    lines = [
        f"{'G20' if inch else 'G21'} {plane} G90 F{rnd.uniform(50, 500) * k:.4f}",
        rnd.choice(["M3 S1000", "M4 S1000", "M5"]),
        f"G0 X{rnd.uniform(-20, 20) * k:.4f} Y{rnd.uniform(-20, 20) * k:.4f} "
        f"Z{rnd.uniform(-20, 20) * k:.4f}",
    ]
    code = None
    for _ in range(rnd.randint(2, 6)):
        if code is None or rnd.random() < 0.5:
            codes = ["G73", "G81", "G82", "G83", "G85", "G86", "G87", "G88", "G89"]
            if plane == "G17":  # G74/G84 elsewhere: refused on purpose (see cycles.py)
                codes += ["G74", "G84"]
            code = rnd.choice(codes)
            sticky = False
        else:
            sticky = True  # same code again: words may be left out
        incremental = rnd.random() < 0.4
        # no G98/G99 at all: LinuxCNC's start is G99 (retract to R)
        words = [rnd.choice(["G98", "G99", ""]), "G91" if incremental else "G90", code]
        for letter in others:
            if rnd.random() < 0.8:
                words.append(f"{letter}{rnd.uniform(-15, 15) * k:.4f}")
        if not sticky or rnd.random() < 0.5:
            if incremental:
                words += [
                    f"R{rnd.uniform(-8, 1) * k:.4f}",
                    f"{depth}{rnd.uniform(-9, 0.5) * k:.4f}",
                ]
            else:
                r = rnd.uniform(-5, 10)
                words += [f"R{r * k:.4f}", f"{depth}{(r - rnd.uniform(-0.5, 12)) * k:.4f}"]
        if code in ("G73", "G83") and (not sticky or rnd.random() < 0.3):
            words.append(f"Q{rnd.uniform(-0.2, 4) * k:.4f}")
        dwells = ("G82", "G86", "G88", "G89", "G84", "G74")
        if code in dwells and (not sticky or rnd.random() < 0.3):
            words.append(f"P{rnd.uniform(0, 1):.3f}")
        if code == "G87" and (not sticky or rnd.random() < 0.3):
            words += [
                f"I{rnd.uniform(-2, 2) * k:.4f}",
                f"J{rnd.uniform(-2, 2) * k:.4f}",
                f"K{rnd.uniform(-6, 6) * k:.4f}",
            ]
        if rnd.random() < 0.3:
            words.append(f"L{rnd.randint(1, 4)}")
        lines.append(" ".join(words))
        if rnd.random() < 0.2:
            lines.append(f"G90 G80\nG0 {depth}{rnd.uniform(-5, 15) * k:.4f}")
            code = None
    lines.append("G90 G80\nM2")
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("seed", range(40))
def test_random_cycle_programs_match_linuxcnc(seed, tmp_path):
    """nurbscnc.program.cycles against LinuxCNC on random cycle programs: the same moves and
    spindle events to 1e-9 mm, or the same error at the same line."""
    from nurbscnc.errors import ProgramError
    from tests.test_cycles import assert_same_moves, drive

    text = random_cycle_program(seed)
    program = tmp_path / f"cycles{seed}.ngc"
    program.write_text(text)
    golden = linuxcnc_golden(program, tmp_path)
    if not golden["accepted"]:
        with pytest.raises(ProgramError) as info:
            drive(text)
        assert (info.value.line, info.value.message) == (
            golden["error"]["line"],
            golden["error"]["message"],
        ), text
        return
    assert golden["tolerance_mm"] == 1e-9, golden["record"]
    assert_same_moves(drive(text), golden["moves"])


def random_comp_program(seed: int) -> str:
    """A G41.1/G42.1 stretch of random lines and arcs (often gouging: LinuxCNC's errors must
    come out too), with Z-only moves, a rapid and a dwell now and then."""
    rnd = random.Random(5000 + seed)
    inch = rnd.random() < 0.2
    k = 1 / 25.4 if inch else 1.0
    lines = [
        f"{'G20' if inch else 'G21'} G17 G90 G40 F{rnd.uniform(100, 900) * k:.4f}",
        f"G0 X{-30 * k:.4f} Y{-30 * k:.4f} Z0",
    ]
    side = rnd.choice(["G41.1", "G42.1"])
    lines.append(f"{side} D{rnd.uniform(0.5, 6) * k:.4f}")
    pos = [rnd.uniform(-10, 10), rnd.uniform(-10, 10)]
    lines.append(f"G1 X{pos[0] * k:.4f} Y{pos[1] * k:.4f}")
    pos = [float(f"{pos[0] * k:.4f}") / k, float(f"{pos[1] * k:.4f}") / k]
    for _ in range(rnd.randint(3, 9)):
        roll = rnd.random()
        if roll < 0.1:
            lines.append(f"G1 Z{rnd.uniform(-3, 1) * k:.4f}")
            continue
        if roll < 0.15:
            lines.append(f"G4 P{rnd.uniform(0, 1):.3f}")
            continue
        if roll < 0.6:
            code = "G0" if rnd.random() < 0.1 else "G1"
            end = [pos[0] + rnd.uniform(-30, 30), pos[1] + rnd.uniform(-30, 30)]
            end = [float(f"{e * k:.4f}") / k for e in end]
            lines.append(f"{code} X{end[0] * k:.4f} Y{end[1] * k:.4f}")
        else:
            r = rnd.uniform(3, 25)
            phi0 = rnd.uniform(0, 2 * math.pi)
            centre = [pos[0] - r * math.cos(phi0), pos[1] - r * math.sin(phi0)]
            phi1 = phi0 + rnd.uniform(0.2, 2 * math.pi - 0.2)
            end = [centre[0] + r * math.cos(phi1), centre[1] + r * math.sin(phi1)]
            end = [float(f"{e * k:.4f}") / k for e in end]
            i, j = (centre[0] - pos[0]) * k, (centre[1] - pos[1]) * k
            code = rnd.choice(["G2", "G3"])
            lines.append(f"{code} X{end[0] * k:.4f} Y{end[1] * k:.4f} I{i:.4f} J{j:.4f}")
        pos = end
    lines.append("G40")
    lines.append(f"G1 X{-30 * k:.4f} Y{-30 * k:.4f}")
    lines.append("M2")
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("seed", range(60))
def test_random_comp_programs_match_linuxcnc(seed, tmp_path):
    """nurbscnc.program.compensation against LinuxCNC on random compensated paths: the same
    moves to 1e-9 mm, or the same error at the same line."""
    from nurbscnc.errors import ProgramError
    from tests.test_compensation import drive

    text = random_comp_program(seed)
    program = tmp_path / f"comp{seed}.ngc"
    program.write_text(text)
    golden = linuxcnc_golden(program, tmp_path)
    if not golden["accepted"]:
        with pytest.raises(ProgramError) as info:
            drive(text)
        assert (info.value.line, info.value.message) == (
            golden["error"]["line"],
            golden["error"]["message"],
        ), text
        return
    assert golden["tolerance_mm"] == 1e-9, golden["record"]
    want = [m for m in golden["moves"] if m["kind"] != "spindle"]
    got = drive(text)
    assert [m["kind"] for m in got] == [m["kind"] for m in want], text
    for g, m in zip(got, want):
        if "end" in m:
            assert np.allclose(g["end"], m["end"][:3], atol=1e-9, rtol=0), (text, g, m)
        if m["kind"] == "arc":
            assert np.allclose(g["centre"], m["centre"], atol=1e-9, rtol=0), (text, g, m)
            assert g["rotation"] == m["rotation"], (text, g, m)
