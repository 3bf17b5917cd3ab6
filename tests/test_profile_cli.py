"""``nurbscnc profile init/show``, profile discovery, and every command saying which profile it
used (issue 16, "My machine"). In-process with click's CliRunner (stdout and stderr apart); the
environment is isolated per test (HOME, XDG_CONFIG_HOME, NURBSCNC_MACHINE, current folder)."""

from __future__ import annotations

import json
import re
import tomllib
from pathlib import Path

import pytest
from click.testing import CliRunner

from nurbscnc.cli.main import main
from nurbscnc.machine.profile import default_profile_text, load_machine, parse_machine
from nurbscnc.machine.schema import SCHEMA

ROOT = Path(__file__).resolve().parents[1]
CORNERS = ROOT / "programs" / "corners.nc"


@pytest.fixture()
def env(tmp_path, monkeypatch):
    """A clean folder as cwd and an empty home: only what a test writes is found."""
    work, home = tmp_path / "work", tmp_path / "home"
    work.mkdir()
    home.mkdir()
    monkeypatch.chdir(work)
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.delenv("XDG_CONFIG_HOME", raising=False)
    monkeypatch.delenv("NURBSCNC_MACHINE", raising=False)
    return tmp_path


def run(args):
    return CliRunner().invoke(main, [str(a) for a in args])


def profile_with(a_max: float) -> str:
    """The template with another A_max (a value that tells the files apart)."""
    text = default_profile_text()
    assert "a_max_mm_s2 = 2450.0\n" in text
    return text.replace("a_max_mm_s2 = 2450.0\n", f"a_max_mm_s2 = {a_max}\n", 1)


def same(a, b) -> bool:
    """Two machines with the same values (wherever they were loaded from)."""
    return (a.limits, a.servo, a.steps, a.soft_limits) == (
        b.limits,
        b.servo,
        b.steps,
        b.soft_limits,
    )


def leaf_keys(schema, prefix=""):
    for key, sub in schema.items():
        full = f"{prefix}.{key}" if prefix else key
        if isinstance(sub, dict):
            yield from leaf_keys(sub, full)
        else:
            yield full


def test_init_to_stdout_is_the_bundled_default(env):
    for args in (["profile", "init"], ["profile", "init", "-"]):
        r = run(args)
        assert r.exit_code == 0, r.output
        assert r.stdout == default_profile_text()
    assert same(parse_machine(r.stdout), load_machine())


def test_template_documents_every_key_with_its_unit():
    text = default_profile_text()
    for full in leaf_keys(SCHEMA):
        key = full.rsplit(".", 1)[-1]
        # each key appears as a setting, or commented out (optional keys, alternative forms)
        assert re.search(rf"^#?\s*{re.escape(key)} = ", text, re.M), full
    for unit in ("[mm/min]", "[mm/s^2]", "[mm/s^3]", "[um]", "[1/mm]", "[ms]", "[Hz]", "[mm"):
        assert unit in text


def test_init_file_refuses_to_overwrite(env):
    target = env / "work" / "m.toml"
    r = run(["profile", "init", target])
    assert r.exit_code == 0 and target.read_text() == default_profile_text()
    target.write_text("mine\n")
    r = run(["profile", "init", target])
    assert r.exit_code == 3
    assert "exists; use --force" in r.stderr and "Traceback" not in r.output
    assert target.read_text() == "mine\n"
    r = run(["profile", "init", target, "--force"])
    assert r.exit_code == 0 and target.read_text() == default_profile_text()


def test_show_round_trips_with_overrides(env):
    r = run(
        [
            "profile",
            "show",
            "--set",
            "limits.a_max_mm_s2=1234",
            "--set",
            "servo.z.bandwidth_hz=40",
            "--set",
            "servo.z.damping=0.7",
        ]
    )
    assert r.exit_code == 0, r.output
    assert r.stdout.startswith("# machine profile: bundled default")
    shown = parse_machine(r.stdout)
    expected = load_machine(
        overrides={"limits.a_max_mm_s2": 1234, "servo.z.bandwidth_hz": 40, "servo.z.damping": 0.7}
    )
    assert same(shown, expected)
    data = tomllib.loads(r.stdout)
    assert data["limits"]["rapid_mm_min"] == 3500.0  # optional key shown with its default
    assert data["servo"]["z"] == {"bandwidth_hz": 40, "damping": 0.7}
    j = json.loads(run(["profile", "show", "--json", "--set", "limits.a_max_mm_s2=1234"]).stdout)
    assert j["profile"]["limits"]["a_max_mm_s2"] == 1234
    assert j["machine_profile"] == {
        "path": None,
        "found_by": "bundled default",
        "contour_check": True,
    }


def test_show_bad_override_is_exit_2(env):
    r = run(["profile", "show", "--set", "limits.a_max_mm_s2=-1"])
    assert r.exit_code == 2
    assert "limits.a_max_mm_s2 must be > 0" in r.stderr and "Traceback" not in r.output


@pytest.mark.parametrize("where", ["option", "env", "local", "xdg", "home", "default"])
def test_discovery_order_through_the_cli(env, monkeypatch, where):
    # Every candidate exists with its own A_max; the highest-ranked one present must win.
    files = {
        "option": env / "opt.toml",
        "env": env / "env.toml",
        "local": env / "work" / "nurbscnc.toml",
        "xdg": env / "xdg" / "nurbscnc" / "machine.toml",
        "home": env / "home" / ".config" / "nurbscnc" / "machine.toml",
    }
    order = list(files) + ["default"]
    a_max = {name: 1000.0 + 10 * i for i, name in enumerate(order)}
    a_max["default"] = 2450.0
    found_by = {
        "option": "--machine",
        "env": "$NURBSCNC_MACHINE",
        "local": "./nurbscnc.toml",
        "xdg": "user config",
        "home": "user config",
        "default": "bundled default",
    }
    for name in order[order.index(where) : -1]:  # this one and every lower-ranked one
        files[name].parent.mkdir(parents=True, exist_ok=True)
        files[name].write_text(profile_with(a_max[name]))
    if files.get("env", Path()).exists():
        monkeypatch.setenv("NURBSCNC_MACHINE", str(files["env"]))
    if files["xdg"].exists():
        monkeypatch.setenv("XDG_CONFIG_HOME", str(env / "xdg"))
    args = ["profile", "show", "--json"]
    if files["option"].exists():
        args += ["--machine", files["option"]]
    r = run(args)
    assert r.exit_code == 0, r.output
    j = json.loads(r.stdout)
    assert j["profile"]["limits"]["a_max_mm_s2"] == a_max[where]
    assert j["machine_profile"]["found_by"] == found_by[where]
    if where == "local":
        assert j["machine_profile"]["path"] == "./nurbscnc.toml"
    elif where != "default":
        assert j["machine_profile"]["path"] == str(files[where])


def test_env_profile_missing_is_exit_3(env, monkeypatch):
    monkeypatch.setenv("NURBSCNC_MACHINE", str(env / "nope.toml"))
    r = run(["profile", "show"])
    assert r.exit_code == 3
    assert "nope.toml (from $NURBSCNC_MACHINE)" in r.stderr


def test_commands_say_which_profile(env):
    (env / "work" / "nurbscnc.toml").write_text(profile_with(2400.0))
    r = run(["plan", CORNERS, "--dynamics", "off"])
    assert r.exit_code == 0, r.output
    assert "machine: ./nurbscnc.toml (./nurbscnc.toml)" in r.stderr
    r = run(["plan", CORNERS, "--dynamics", "off", "--json"])
    j = json.loads(r.stdout)
    assert j["machine_profile"] == {
        "path": "./nurbscnc.toml",
        "found_by": "./nurbscnc.toml",
        "contour_check": True,
    }
    assert "machine:" not in r.stderr  # JSON mode: the key says it
    r = run(["corners", CORNERS, "--json"])
    assert json.loads(r.stdout)["machine_profile"]["found_by"] == "./nurbscnc.toml"
    # check too: its soft limits and max_points are the profile's
    r = run(["check", CORNERS])
    assert r.exit_code == 0, r.output
    assert r.stderr.splitlines()[0] == "machine: ./nurbscnc.toml (./nurbscnc.toml)"
    r = run(["check", CORNERS, "--json"])
    assert "machine:" not in r.stderr
    assert json.loads(r.stdout)["machine_profile"]["found_by"] == "./nurbscnc.toml"


def test_no_servo_model_turns_the_contour_check_off(env):
    lines = default_profile_text().splitlines()
    text = "\n".join(lines[: lines.index("[servo]")] + lines[lines.index("[steps]") :])
    (env / "work" / "nurbscnc.toml").write_text(text)
    r = run(["plan", CORNERS])
    assert r.exit_code == 0, r.output
    assert "contour check: off (no servo model in the profile)" in r.stderr
    assert "contour error" not in r.stdout
    r = run(["check", CORNERS])  # check plans nothing: no word on a contour check
    assert r.exit_code == 0 and r.stderr.startswith("machine: ./nurbscnc.toml")
    assert "contour check" not in r.stderr
    j = json.loads(run(["plan", CORNERS, "--json"]).stdout)
    assert j["dynamics"] == "off" and j["dynamics_iterations"] == 0
    assert j["machine_profile"]["contour_check"] is False
    assert not any(key.startswith("contour_") for key in j)
