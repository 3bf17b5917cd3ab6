"""The profile's rotary axes: ``[axis_limits.a]`` (b, c) tables into ``Machine.rotary_axes``."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import pytest
from click.testing import CliRunner

from nurbscnc.cli.main import main
from nurbscnc.errors import ConfigError
from nurbscnc.machine.discovery import default_profile_text
from nurbscnc.machine.model import RotaryAxis
from nurbscnc.machine.profile import load_machine, parse_machine
from nurbscnc.machine.show import profile_toml

ROOT = Path(__file__).resolve().parents[1]
BENCH_A = ROOT / "bench" / "programs" / "linuxcnc_limits_a.toml"
#: LinuxCNC's sample config sim/axis/wrapped_rotary/wrapped_rotary.ini, [AXIS_A] / [JOINT_3].
WRAPPED_ROTARY_INI_A = {"MAX_VELOCITY": 140.0, "MAX_ACCELERATION": 1000.0}


def with_tables(text: str):
    return parse_machine(default_profile_text() + "\n" + text, "<test>")


def test_a_table_declares_the_axis_in_internal_units():
    m = with_tables(
        "[axis_limits.a]\nv_max_deg_min = 3600.0\na_max_deg_s2 = 400.0\nj_max_deg_s3 = 4e3\n"
        "[axis_limits.c]\nv_max_deg_min = 600\na_max_deg_s2 = 50\nj_max_deg_s3 = 500\n"
        "min_deg = -90\nmax_deg = 270.5\nwrapped = false\nsteps_per_deg = 100\n"
    )
    assert m.rotary_axes == {
        "a": RotaryAxis("a", 60.0, 400.0, 4000.0),
        "c": RotaryAxis("c", 10.0, 50.0, 500.0, -90.0, 270.5, False, 100.0),
    }
    assert math.isinf(m.rotary_axes["a"].min_deg) and m.rotary_axes["a"].max_deg == math.inf


def test_the_bundled_machine_has_no_rotary_axis():
    assert load_machine().rotary_axes == {}


def test_overrides_declare_an_axis():
    m = load_machine(
        None,
        {
            "axis_limits.b.v_max_deg_min": "1200",
            "axis_limits.b.a_max_deg_s2": "100",
            "axis_limits.b.j_max_deg_s3": "1e4",
            "axis_limits.b.wrapped": "true",
        },
    )
    assert m.rotary_axes == {"b": RotaryAxis("b", 20.0, 100.0, 1e4, wrapped=True)}


@pytest.mark.parametrize(
    "table, words",
    [
        ("v_max_deg_min = 60\na_max_deg_s2 = 1\n", "axis_limits.a.j_max_deg_s3 is missing"),
        ("v_max_deg_min = 60\na_max_deg_s2 = 1\nj_max_deg_s3 = 0\n", "j_max_deg_s3 must be > 0"),
        (
            "v_max_deg_min = 60\na_max_deg_s2 = 1\nj_max_deg_s3 = 1\nwrapped = 1\n",
            "axis_limits.a.wrapped must be true or false",
        ),
        (
            "v_max_deg_min = 60\na_max_deg_s2 = 1\nj_max_deg_s3 = 1\nmin_deg = 5\nmax_deg = 5\n",
            "axis_limits.a.min_deg (5) must be < axis_limits.a.max_deg (5)",
        ),
        (
            "v_max_deg_min = 1e9\na_max_deg_s2 = 1\nj_max_deg_s3 = 1\n",
            "axis_limits.a.v_max_deg_min must be >= 0.001 and <= 1e+08",
        ),
        (
            "v_max_deg_min = 60\na_max_deg_s2 = 1\nj_max_deg_s3 = 1\nv_max_mm_min = 5\n",
            "axis_limits.a.v_max_mm_min is not a known key",
        ),
    ],
)
def test_bad_rotary_tables_name_the_key(table, words):
    with pytest.raises(ConfigError, match=None) as info:
        with_tables("[axis_limits.a]\n" + table)
    assert words in str(info.value)


def test_profile_show_lists_the_axis_with_units():
    m = with_tables(
        "[axis_limits.a]\nv_max_deg_min = 3600.0\na_max_deg_s2 = 400.0\nj_max_deg_s3 = 4e3\n"
        "min_deg = -10\nmax_deg = 370\nwrapped = true\n"
    )
    shown = profile_toml(m)
    assert (
        "[axis_limits.a]\n# rotary axis A [degrees]: v_max 60 deg/s, a_max 400 deg/s^2, "
        "j_max 4000 deg/s^3, travel [-10, 370] deg, wrapped"
    ) in shown
    assert tomllib.loads(shown)["axis_limits"]["a"]["wrapped"] is True  # still a profile


def test_bench_profile_has_the_a_axis_of_linuxcncs_wrapped_rotary_sample():
    m = load_machine(str(BENCH_A))
    a = m.rotary_axes["a"]
    assert a.v_max_deg_s == WRAPPED_ROTARY_INI_A["MAX_VELOCITY"]
    assert a.a_max_deg_s2 == WRAPPED_ROTARY_INI_A["MAX_ACCELERATION"]
    assert a.wrapped and a.j_max_deg_s3 == 1e9
    # 140 deg/s at 500 steps/deg: 70 steps per 1 ms period, within the card's 127
    assert a.v_max_deg_s * m.servo.period_s * a.steps_per_deg <= m.steps.max_pulses_per_period
    base = load_machine(str(ROOT / "bench" / "programs" / "linuxcnc_limits.toml"))
    assert (m.limits, m.axis_limits, m.steps, m.soft_limits) == (
        base.limits,
        base.axis_limits,
        base.steps,
        base.soft_limits,
    )


def test_the_app_hands_the_machines_axes_to_the_interpreter():
    """``check`` on the bundled machine refuses the A word (exit 2); the inputs the app builds
    from the A machine let the interpreter run it."""
    from nurbscnc.app.load import load_program
    from nurbscnc.app.varfile import program_inputs

    program = ROOT / "tests" / "programs" / "rotary" / "a_incremental.ngc"
    res = CliRunner().invoke(main, ["check", str(program)])
    assert res.exit_code == 2 and f"{program}:5:4: error: the machine has no A axis" in res.stderr
    interpreted = load_program(str(program), inputs=program_inputs(load_machine(str(BENCH_A))))
    assert interpreted.rotary_axes == ("a",)
    assert interpreted.segments[-1].abc_deg == (360.0, 0.0, 0.0, 270.0, 0.0, 0.0)


def _a_axis(steps_per_deg: float) -> str:
    return (
        "[axis_limits.a]\nv_max_deg_min = 3600.0\na_max_deg_s2 = 400.0\nj_max_deg_s3 = 4e3\n"
        f"steps_per_deg = {steps_per_deg!r}\n"
    )


def test_a_rotary_axis_must_fit_the_pulse_budget():
    """60 deg/s · 3000 steps/deg · 1 ms = 180 steps per period > 127: refused, naming the
    axis; 2000 steps/deg needs 120 ≤ 127."""
    assert with_tables(_a_axis(2000.0)).rotary_axes["a"].steps_per_deg == 2000.0
    with pytest.raises(ConfigError) as exc:
        with_tables(_a_axis(3000.0))
    text = str(exc.value)
    assert "steps.max_pulses_per_period" in text and "= 127 is too small: axis a" in text
    assert "60 deg/s needs 180 steps per 1 ms period" in text
    assert "axis_limits.a.steps_per_deg = 3000" in text


def test_the_default_pulse_budget_covers_a_rotary_axis():
    """Without max_pulses_per_period the default rounds up to the fastest axis's need,
    a rotary axis included: 60 deg/s · 3000 steps/deg · 1 ms = 180."""
    text = default_profile_text().replace("max_pulses_per_period = 127", "")
    m = parse_machine(text + "\n" + _a_axis(3000.0), "<test>")
    assert m.steps.max_pulses_per_period == 180
