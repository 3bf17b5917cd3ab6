#!/usr/bin/env python3
"""Copy the real NC programs of tests/programs/real/ out of local git mirrors; write
``manifest.json`` and ``SOURCES.md``.

The mirrors are the snapshots the search tools fetch (``/work/.mirror/<owner>+<name>/repo``);
each file is taken at a fixed commit with ``git show``, never edited. Run it once when the
collection changes; the copies, the manifest and SOURCES.md are committed, so nothing else needs
the mirrors. ``role`` is ``program`` (recorded and compared), ``subroutine`` (called by a
program beside it, not run alone) or ``refused`` (outside 3-axis milling: rotary motion, lathe,
probing, spindle synchronisation — kept to check that nurbscnc refuses it clearly).
"""

from __future__ import annotations

import json
import os
import subprocess

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
REAL = os.path.join(ROOT, "tests", "programs", "real")
MIRRORS = os.environ.get("NURBSCNC_MIRRORS", "/work/.mirror")

LINUXCNC = ("LinuxCNC/linuxcnc", "f1270d6ed71521f6551397a98b7496027cd331b8", "GPL-2.0 (COPYING)")
CAMOTICS = (
    "CauldronDevelopmentLLC/CAMotics",
    "e84665f2fa9d1151f03282ac7e01320bc65e015b",
    "GPL-2.0-or-later (COPYING, LICENSE)",
)
CNCJS = ("cncjs/cncjs", "48550474bd6b0bf375997f2d779f1f440b16aa4d", "MIT (LICENSE)")
BCNC = ("vlachoudis/bCNC", "23103b08f6b233470d6aa91b9cd4615243e9f6a4", "GPL-2.0 (LICENSE.md)")
PCB2GCODE = ("pcb2gcode/pcb2gcode", "765d670c8030b76ed7dc6e2b79aa3fbb791f1688", "GPL-3.0 (COPYING)")
PCB = "testing/gerbv_example/"

TP = "tests/trajectory-planner/circular-arcs/nc_files/"
# (repository tuple, source path, destination under tests/programs/real, role, what it is)
FILES = [
    *[
        (LINUXCNC, f"nc_files/{n}.ngc", f"linuxcnc/nc_files/{n}.ngc", "program", "sample")
        for n in [
            "3dtest",
            "arcspiral",
            "cds",
            "comp-g1",
            "comp",
            "comp311",
            "comp311_2",
            "daisy",
            "factorial",
            "flowsnake",
            "gmoccapy_2_tools_with_cutter_radius_compensation",
            "hole-circle",
            "mmount",
            "nestedcall",
            "offsets",
            "polar",
            "retval",
            "skeleton",
            "spiral",
            "tort",
            "useful-subroutines",
            "3D_Chips",
            "toplevel",
            "roparams",
        ]
    ],
    # (butterfly.ngc and systems.ngc use G5.2 NURBS, which the gcode module turns into a
    # polyline: not comparable move by move; the corpus holds LinuxCNC's NURBS samples.)
    (
        LINUXCNC,
        "nc_files/g20sub.ngc",
        "linuxcnc/nc_files/g20sub.ngc",
        "subroutine",
        "called by nestedcall.ngc",
    ),
    *[
        (LINUXCNC, f"nc_files/{n}.ngc", f"linuxcnc/nc_files/{n}.ngc", "refused", why)
        for n, why in [
            ("b-index", "rotary B axis motion"),
            ("threading", "G33 spindle sync"),
            ("g76", "G76 lathe threading"),
            ("cone", "rotary B axis motion (LinuxCNC also refuses its line 34: W word)"),
        ]
    ],
    # A file that only defines a probing subroutine (G38) and never calls it: no moves.
    (
        LINUXCNC,
        "nc_files/probe-hole.ngc",
        "linuxcnc/nc_files/probe-hole.ngc",
        "program",
        "G38 probing subroutine, defined and not called: no moves",
    ),
    (
        LINUXCNC,
        "nc_files/lathecomp.ngc",
        "linuxcnc/nc_files/lathecomp.ngc",
        "program",
        "G18 (XZ) cutter compensation, lathe profile",
    ),
    # tests/interp: each test.ngc under a name made from its directory.
    *[
        (LINUXCNC, f"tests/interp/{src}", f"linuxcnc/interp/{dst}.ngc", "program", "interp test")
        for src, dst in [
            ("cam-nisley/cam.ngc", "cam-nisley"),
            ("crazy-paths/test.ngc", "crazy-paths"),
            ("do-while-break/test.ngc", "do-while-break"),
            ("exists/test.ngc", "exists"),
            ("flowsnake/flowsnake.ngc", "flowsnake"),
            ("fractional-linenumbers/test.ngc", "fractional-linenumbers"),
            ("g10/g10-l1-l10/test.ngc", "g10-l1-l10"),
            ("g10/g10-l11/test.ngc", "g10-l11"),
            ("g10/g10-l2-while-active/test.ngc", "g10-l2-while-active"),
            ("g10/g10-l20-while-active/test.ngc", "g10-l20-while-active"),
            ("g10/g10-with-g92/test.ngc", "g10-with-g92"),
            ("g52/g52-g92-interaction/g52-g92-interaction.ngc", "g52-g92-interaction"),
            ("g6164/test.ngc", "g6164"),
            *[
                (f"g81/g{p}/g{r}/g{p}-g{r}-g81.ngc", f"g{p}-g{r}-g81")
                for p in (17, 18, 19)
                for r in (98, 99)
            ],
            *[(f"g84/g17/g{r}/g17-g{r}-g84.ngc", f"g17-g{r}-g84") for r in (98, 99)],
            *[
                (f"good/good-arc.{s}.{u}.center-format.ngc", f"good-arc.{s}.{u}")
                for s in ("big", "medium", "small")
                for u in ("imperial", "metric")
            ],
            ("inside-corners/test.ngc", "inside-corners"),
            ("inverse-time-with-comp/inverse.ngc", "inverse-time-with-comp"),
            ("namedparam-bug424/test.ngc", "namedparam-bug424"),
            ("oword-bug315/test.ngc", "oword-bug315"),
            ("oword-bug315-p2/test.ngc", "oword-bug315-p2"),
            ("return-value/test.ngc", "return-value"),
            ("rotation/abs-pts/test.ngc", "rotation-abs-pts"),
            ("rotation/g28/g28.ngc", "rotation-g28"),
            ("rotation/g53/g53.ngc", "rotation-g53"),
            ("m98m99/01-basics/test.ngc", "m98m99-basics"),
            ("m98m99/02-variables/test.ngc", "m98m99-variables"),
            ("m98m99/05-M98-loops/test.ngc", "m98m99-loops"),
            ("m98m99/07-nested-subs/test.ngc", "m98m99-nested-subs"),
            ("m98m99/13-named-program/test-named.ngc", "m98m99-named-program"),
            ("sequence-number/test.ngc", "sequence-number"),
        ]
    ],
    # LinuxCNC's "bad" programs: LinuxCNC refuses them; nurbscnc must refuse them too.
    *[
        (
            LINUXCNC,
            f"tests/interp/bad/{n}.ngc",
            f"linuxcnc/interp-bad/{n}.ngc",
            "program",
            "interp test LinuxCNC refuses",
        )
        for n in [
            "a-in-canned-cycle",
            "ccomp-arcexit",
            "ccomp-gouging",
            "no-feed-rate",
            "no-ijr",
            *[
                f"bad-arc.{s}.{u}.center-format"
                for s in ("big", "medium", "small")
                for u in ("imperial", "metric")
            ],
        ]
    ],
    *[
        (LINUXCNC, f"tests/ccomp/{n}/test.ngc", f"linuxcnc/ccomp/{n}.ngc", "program", "ccomp test")
        for n in ["mill-g90g91g92", "mill-line-arc-entry", "mill-zchanges"]
    ],
    (
        LINUXCNC,
        "tests/ccomp/lathe-comp/test.ngc",
        "linuxcnc/ccomp/lathe-comp.ngc",
        "program",
        "G18 (XZ) cutter compensation, lathe profile",
    ),
    # LinuxCNC 2.9 taps to interchanged coordinates in G18/G19 (nurbscnc/program/cycles.py).
    *[
        (
            LINUXCNC,
            f"tests/interp/g84/g{p}/g{r}/g{p}-g{r}-g84.ngc",
            f"linuxcnc/interp/g{p}-g{r}-g84.ngc",
            "refused",
            "G84 outside G17 (LinuxCNC interchanges the axes)",
        )
        for p in (18, 19)
        for r in (98, 99)
    ],
    (
        LINUXCNC,
        "tests/interp/g33.1/g33.1.ngc",
        "linuxcnc/interp/g33.1.ngc",
        "refused",
        "G33.1 rigid tapping",
    ),
    (
        LINUXCNC,
        "tests/interp/g76/g76only.ngc",
        "linuxcnc/interp/g76only.ngc",
        "refused",
        "G76 lathe threading",
    ),
    # Trajectory-planner test programs (several are CAM output).
    *[
        (LINUXCNC, TP + p, "linuxcnc/tp/" + p.replace("/", "__"), "program", "tp test")
        for p in [
            "arc-feed/basic_xy.ngc",
            "arc-feed/full_xy.ngc",
            "arc-feed/full_xz.ngc",
            "arc-feed/full_yz.ngc",
            "arc-feed/simple_arc2.ngc",
            "arc-feed/simple_arc3.ngc",
            "arc-feed/arc_time.ngc",
            *[
                f"quick-tests/{q}.ngc"
                for q in [
                    "arc-arc-sawtooth",
                    "dodecagon_0.1in",
                    "g0_corners",
                    "linearc-stellabee",
                    "naive_cam_corner1",
                    "naive_cam_reversal",
                    "rapid_3d_corners",
                    "square_spiral",
                    "spiral_tight_circular",
                    "steve",
                    "tangent_helix",
                    "test_diamond",
                    "zigzag_square",
                    "zero_length_move",
                    "arc-arc-planeswitch",
                    "sam-tolerance-issue",
                    "parabolic_varying",
                    "ramp_test",
                    "corner_decel",
                ]
            ],
            *[
                f"performance/{q}.ngc"
                for q in [
                    "cap",
                    "bezel_ex_37tick",
                    "test_12mmflat",
                    "tight-corner-tolerance",
                    "tort-sam-mach3",
                    "spiral_lines",
                    "line-contouring-xz",
                ]
            ],
            *[
                f"violation_checks/{q}.ngc"
                for q in [
                    "spreadsheeterrors",
                    "maxvel_violation_helical",
                    "tangent_lines_smooth",
                    "sam_vel_violation",
                    "machinekit_412",
                ]
            ],
            *[
                f"diagnostic/{q}.ngc"
                for q in ["feed-tracking-test", "helix_slowdown", "modal_state_test", "lineno-test"]
            ],
            "spindle/g95_blend.ngc",
        ]
    ],
    *[
        (LINUXCNC, TP + p, "linuxcnc/tp/" + p.replace("/", "__"), "refused", why)
        for p, why in [
            ("spindle/rigidtap_test.ngc", "G33.1 rigid tapping"),
            ("spindle/g33_simple.ngc", "G33 spindle sync"),
            ("diagnostic/abc_tangent.ngc", "rotary A/B/C motion"),
        ]
    ],
    # CAMotics examples: CAM output (pycam, CAMotics' own TPL CAM) and hand-written O-word code.
    *[
        (CAMOTICS, f"examples/{p}", "camotics/" + p.replace("/", "__"), "program", what)
        for p, what in [
            ("scorpion/scorpion.nc", "CAM output"),
            ("slant_test/slant_test.nc", "hand-written"),
            ("heart/cutout.ngc", "named parameters"),
            ("heart/heart.ngc", "named parameters"),
            ("genes-encoder/genes-encoder.ngc", "O-words (LinuxCNC user program)"),
            ("compass/mt_kazbegi_2013.ngc", "engraving, named parameters"),
            ("compass/sworn_brothers_llc.ngc", "engraving, named parameters"),
            ("compass/text.ngc", "engraving"),
            ("cds/cds.gcode", "CAMotics TPL CAM output"),
            ("buildbotics/buildbotics.gcode", "CAMotics TPL CAM output"),
            ("wave/wave.gcode", "CAMotics TPL CAM output"),
            ("cat/tiny_cat_outline.ngc", "pycam 0.5.1 output"),
            ("compass/top.ngc", "engraving"),
            ("compass/bottom.ngc", "engraving"),
            ("locket/engrave.ngc", "engraving"),
        ]
    ],
    # cncjs examples (a G-code sender for Grbl and friends): jscut CAM output, calibration and
    # arc samples as hobby machines run them.
    *[
        (CNCJS, f"examples/gcode/{p}", "cncjs/" + p.replace("/", "__"), "program", what)
        for p, what in [
            ("jsdc.gcode", "jscut CAM output"),
            ("tball/tball.gcode", "jscut CAM output"),
            ("tball/tball-engrave.gcode", "jscut CAM output, engraving"),
            ("Circle_Diamond_Square_Calibration.gcode", "Shapeoko calibration, numbered lines"),
            ("circle.gcode", "arc sample"),
            ("circle-inch.gcode", "arc sample, inch"),
            ("full-circle-without-xyz.gcode", "full circles without axis words"),
            ("g2-arc.gcode", "arc sample"),
            ("helical-thread-milling.gcode", "helical thread milling, G91"),
            ("arc-ijk.gcode", "arc sample"),
            ("arc-xz-plane.gcode", "G18 arc"),
            ("arc-yz-plane.gcode", "G19 arc"),
        ]
    ],
    # Wave 2 (session 4): larger CAM outputs. CAMotics' examples (pycam, CAMotics TPL, a
    # Vectric-style post, OpenVoronoi V-carving), LinuxCNC's trajectory-planner test programs
    # that are CAM output (SheetCam, BobCAD, gcmc, a plasma post, a Mastercam-style post), a
    # bCNC test file.
    *[
        (CAMOTICS, f"examples/{p}", "camotics/" + p.replace("/", "__"), "program", what)
        for p, what in [
            ("bear/bear.nc", "CAM output (3D relief, ball end)"),
            ("botomata_bottom/botomata_bottom.nc", "CAM output, G10 L2 work offsets"),
            ("compass/compass.ngc", "engraving"),
            ("locket/locket_inside.ngc", "CAM output, 3D"),
            ("locket/locket_outside.ngc", "CAM output, 3D"),
            ("vcarve/vcarve.ngc", "OpenVoronoi V-carving output, inch"),
            ("flower_mold/flower_mold.nc", "CAM output (3D mold), inch"),
        ]
    ],
    *[
        (LINUXCNC, TP + p, "linuxcnc/tp/" + p.replace("/", "__"), "program", what)
        for p, what in [
            ("performance/Cereal.ngc", "CAM output (2D profile)"),
            ("performance/Pasta.ngc", "CAM output (2D profile)"),
            ("performance/LHchips4.ngc", "CAM output (3D ball end)"),
            ("performance/wheels.ngc", "gcmc output"),
            ("performance/blur_torus.ngc", "CAM output (3D torus), inch"),
            ("performance/spiral-circular-segments.ngc", "generated arcs, inch"),
            ("performance/zigzag_0.002_0.001.ngc", "generated short lines, inch"),
            ("performance/short_segments_0.001.ngc", "generated short lines, inch"),
            ("performance/straight_short_lines_X.ngc", "generated short lines"),
            ("XYtests/51MeanderAve.ngc", "SheetCam plasma post output"),
            ("diagnostic/rgh.ngc", "CAM post output with % and N words"),
            ("violation_checks/stellabee-kink-test.ngc", "CAM output, inch"),
            ("violation_checks/stellabee-violation-spirals.ngc", "CAM output, inch"),
        ]
    ],
    (BCNC, "tests/static/sample.gcode", "bcnc/sample.gcode", "program", "bCNC test sample"),
    # pcb2gcode's expected outputs (its regression tests): PCB isolation milling, outlines
    # with bridges, drilling (G81) and mill-drilling, for LinuxCNC, inch and mm.
    *[
        (PCB2GCODE, PCB + p, "pcb2gcode/" + p.replace("/expected/", "__"), "program", what)
        for p, what in [
            ("multivibrator/expected/back.ngc", "pcb2gcode isolation milling, inch"),
            ("multivibrator/expected/milldrill.ngc", "pcb2gcode mill-drilling (helical holes)"),
            ("multivibrator-clockwise/expected/outline.ngc", "pcb2gcode outline, clockwise"),
            ("multivibrator-zchange-absolute/expected/back.ngc", "pcb2gcode, absolute Z"),
            ("lift-mill/expected/outline.ngc", "pcb2gcode outline with bridges"),
            ("slots-with-drill-metric/expected/drill.ngc", "pcb2gcode drilling (G81), mm"),
            ("slots-milldrill-metric/expected/milldrill.ngc", "pcb2gcode milled slots, mm"),
            ("milldrilldiatest/expected/drill.ngc", "pcb2gcode drilling, four tools, mm"),
            ("mill_masking_voronoi/expected/front.ngc", "pcb2gcode Voronoi isolation"),
            ("sharp_corner/expected/back.ngc", "pcb2gcode isolation, sharp corners"),
            ("edge-cuts-inside-cuts/expected/outline.ngc", "pcb2gcode outline with inner cuts"),
            ("example_board_new_default/expected/back.ngc", "pcb2gcode isolation, defaults"),
        ]
    ],
    (
        PCB2GCODE,
        PCB + "example_board_al_linuxcnc/expected/front.ngc",
        "pcb2gcode/example_board_al_linuxcnc__front.ngc",
        "refused",
        "pcb2gcode auto-levelling: G38 probing subroutines",
    ),
    (CNCJS, "examples/gcode/arc-xy-plane.gcode", "cncjs/arc-xy-plane.gcode", "program", "G17 arc"),
]


def main() -> None:
    entries = []
    for (repo, commit, licence), src, dst, role, what in FILES:
        mirror = os.path.join(MIRRORS, repo.replace("/", "+"), "repo")
        data = subprocess.run(
            ["git", "-C", mirror, "show", f"{commit}:{src}"], capture_output=True, check=True
        ).stdout
        path = os.path.join(REAL, dst)
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with open(path, "wb") as fh:
            fh.write(data)
        full = subprocess.run(
            ["git", "-C", mirror, "rev-parse", commit], capture_output=True, text=True, check=True
        ).stdout.strip()
        entries.append(
            {
                "path": dst,
                "repository": repo,
                "source": src,
                "commit": full,
                "licence": licence,
                "role": role,
                "what": what,
                "bytes": len(data),
            }
        )
    with open(os.path.join(REAL, "manifest.json"), "w") as fh:
        json.dump({"files": entries}, fh, indent=1)
        fh.write("\n")
    total = sum(e["bytes"] for e in entries)
    lines = [
        "# Real NC programs (issue 11)",
        "",
        "Copied unchanged from public repositories by `tools/collect_real_programs.py`;",
        "`manifest.json` is the machine-readable form of this table. `role`: **program**",
        "(LinuxCNC's moves are recorded in `tests/golden/linuxcnc/` and compared with nurbscnc's),",
        "**subroutine**",
        '(called by a program beside it), **refused** (outside 3-axis milling; kept as "stays',
        "refused\" examples). The programs are redistributed under their repositories'",
        "licences (GPL-2.0 / GPL-2.0-or-later; MIT for cncjs; GPL-2.0 for bCNC; GPL-3.0 for",
        "pcb2gcode), unchanged, with their origin.",
        "",
        "Initial state used for every program (`make goldens`): `tools.tbl` (LinuxCNC tool-table",
        "format, mm: T1–T4 from LinuxCNC's `tests/interp/cam-nisley/test.tbl` in mm, T5–T99",
        "length 0,",
        "diameter 3 mm) and `params.var` (all offsets zero, G54 active); units G21, start at the",
        "origin, block delete on.",
        "",
        f"{len(entries)} files, {total / 1e6:.2f} MB.",
        "",
        "| file | role | repository | path | commit | licence | what |",
        "|---|---|---|---|---|---|---|",
    ]
    for e in entries:
        lines.append(
            f"| `{e['path']}` | {e['role']} | {e['repository']} | `{e['source']}` | "
            f"{e['commit'][:12]} | {e['licence']} | {e['what']} |"
        )
    with open(os.path.join(REAL, "SOURCES.md"), "w") as fh:
        fh.write("\n".join(lines) + "\n")
    print(f"{len(entries)} files, {total} bytes")


if __name__ == "__main__":
    main()
