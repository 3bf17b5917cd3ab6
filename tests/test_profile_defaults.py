"""A machine profile of one's own: only ``[limits]`` v_max, a_max and j_max are required;
every other key takes its documented default (``machine/schema.py`` DEFAULTS, the paper's
tolerances and the bundled machine's period, resolution and travel), which ``profile show``
marks ``# default``. Unknown keys stay errors. ``profile init --template router`` writes a
stepper router without a servo model (contour check off)."""

from __future__ import annotations

import json
import math
import tomllib

import pytest
from click.testing import CliRunner

from nurbscnc.cli.main import main
from nurbscnc.errors import ConfigError
from nurbscnc.machine.discovery import template_text
from nurbscnc.machine.profile import default_profile_text, load_machine, parse_machine

MINIMAL = "[limits]\nv_max_mm_min = 6000\na_max_mm_s2 = 1500\nj_max_mm_s3 = 3e4\n"
#: Every key MINIMAL leaves out: the ones profile show must mark.
FILLED = {
    "limits.rapid_mm_min",
    "limits.chord_tolerance_um",
    "limits.kappa_ref_per_mm",
    "limits.contour_tolerance_um",
    "limits.ph_tolerance_um",
    "limits.path_tolerance_um",
    "limits.max_points",
    "servo.period_ms",
    "steps.max_pulses_per_period",
    *(f"steps.per_mm.{a}" for a in "xyz"),
    *(f"soft_limits.{a}.{k}" for a in "xyz" for k in ("min_mm", "max_mm")),
}


def run(args):
    return CliRunner().invoke(main, [str(a) for a in args])


def test_three_limits_are_a_profile():
    m = parse_machine(MINIMAL, "mine.toml")
    lim = m.limits
    assert lim.v_max_mm_s == 100.0 and lim.rapid_mm_s == 100.0
    assert lim.a_max_mm_s2 == 1500.0 and lim.j_max_mm_s3 == 3e4
    # the paper's Table 3 tolerances, in mm
    assert lim.chord_tolerance_mm == pytest.approx(1e-3, rel=1e-15)
    assert lim.kappa_ref_per_mm == 1.0
    assert lim.contour_tolerance_mm == pytest.approx(15e-3, rel=1e-15)
    assert lim.ph_tolerance_mm == pytest.approx(1e-3, rel=1e-15)
    assert lim.path_tolerance_mm == lim.contour_tolerance_mm
    assert lim.max_points == 50_000_000
    assert m.servo.period_s == pytest.approx(1e-3, rel=1e-15)
    assert not m.contour_check  # no servo model
    assert m.steps.per_mm == (1000.0, 1000.0, 1000.0)
    # 100 mm/s x 1 ms x 1000 steps/mm = 100 steps per period: the default 127 holds
    assert m.steps.max_pulses_per_period == 127
    assert m.soft_limits.min_mm == (-1000.0,) * 3 and m.soft_limits.max_mm == (1000.0,) * 3
    assert m.defaults == FILLED


def test_given_keys_are_not_defaults():
    m = parse_machine(MINIMAL + "chord_tolerance_um = 2.5\n[steps.per_mm]\nx = 320.0\n")
    assert m.limits.chord_tolerance_mm == pytest.approx(2.5e-3, rel=1e-15)
    assert m.steps.per_mm == (320.0, 1000.0, 1000.0)
    assert m.defaults == FILLED - {"limits.chord_tolerance_um", "steps.per_mm.x"}


def test_default_pulse_limit_follows_the_fastest_axis():
    """rapid 20,000 mm/min = 333.33 mm/s; x 1 ms x 1000 steps/mm = 333.33 steps: 334."""
    m = parse_machine(MINIMAL.replace("6000", "6000\nrapid_mm_min = 20000"))
    assert m.steps.max_pulses_per_period == math.ceil(20000 / 60 * 1e-3 * 1000) == 334
    # An axis velocity limit bounds what that axis needs: z at 1200 mm/min = 20 steps, and
    # x, y still at the rapid rate.
    text = MINIMAL + "".join(
        f"[axis_limits.{a}]\nv_max_mm_min = {v}\n"
        for a, v in (("x", 9000), ("y", 9000), ("z", 1200))
    )
    m = parse_machine(text.replace("6000", "6000\nrapid_mm_min = 20000"))
    assert m.steps.max_pulses_per_period == 150  # 9000/60 x 1 ms x 1000


def test_required_and_unknown_keys_still_refused():
    with pytest.raises(ConfigError, match="limits.j_max_mm_s3 is missing"):
        parse_machine("[limits]\nv_max_mm_min = 6000\na_max_mm_s2 = 1500\n", "mine.toml")
    with pytest.raises(ConfigError, match="limits.chord_tolerence_um is not a known key"):
        parse_machine(MINIMAL + "chord_tolerence_um = 1\n", "mine.toml")
    with pytest.raises(ConfigError, match="steps.per_mm.w is not a known key"):
        parse_machine(MINIMAL + "[steps.per_mm]\nw = 1\n", "mine.toml")
    with pytest.raises(ConfigError, match="steps must be a table"):
        parse_machine(MINIMAL.replace("[limits]", "steps = 5\n[limits]"), "mine.toml")


def test_show_marks_the_defaults(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text(MINIMAL)
    r = run(["profile", "show", "--machine", path])
    assert r.exit_code == 0, r.output
    marked = set()
    table = ""
    for line in r.stdout.splitlines():
        if line.startswith("["):
            table = line.strip("[]")
        elif " = " in line and line.endswith("# default"):
            marked.add(f"{table}.{line.split(' = ')[0]}")
    assert marked == FILLED
    assert "v_max_mm_min = 6000\n" in r.stdout  # given: not marked
    # the output is itself a profile, and the same machine
    shown = parse_machine(r.stdout)
    assert shown.limits == load_machine(str(path)).limits
    assert shown.steps == load_machine(str(path)).steps
    j = json.loads(run(["profile", "show", "--machine", path, "--json"]).stdout)
    assert set(j["defaults"]) == FILLED
    assert j["profile"]["steps"]["max_pulses_per_period"] == 127


def test_plan_runs_on_a_three_key_profile(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text(MINIMAL)
    r = run(["plan", "programs/corners.nc", "--machine", path])
    assert r.exit_code == 0, r.output
    assert "contour check: off (no servo model in the profile)" in r.stderr


def test_init_router_template(tmp_path):
    r = run(["profile", "init", "--template", "router"])
    assert r.exit_code == 0
    assert r.stdout == template_text("router")
    m = parse_machine(r.stdout, "router.toml")
    assert not m.contour_check and m.servo.x is None and m.servo.y is None
    assert m.steps.per_mm == (320.0, 320.0, 320.0)
    data = tomllib.loads(r.stdout)
    assert "servo" in data and set(data["servo"]) == {"period_ms"}
    # the paper's template stays the default
    assert run(["profile", "init"]).stdout == default_profile_text()
    assert run(["profile", "init", "--template", "paper"]).stdout == default_profile_text()
    target = tmp_path / "router.toml"
    assert run(["profile", "init", target, "--template", "router"]).exit_code == 0
    r = run(["plan", "programs/corners.nc", "--machine", target, "--json"])
    assert r.exit_code == 0, r.output
    j = json.loads(r.stdout)
    assert j["dynamics"] == "off" and j["machine_profile"]["contour_check"] is False
