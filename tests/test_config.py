"""Machine profiles: the bundled default loads; every kind of bad value names its key."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from fivebar_host import wire
from fivebar_host.cli import main
from fivebar_host.compile.emit import pen_item
from fivebar_host.config import DEFAULT_PROFILE, ConfigError, load_profile, parse_profile


def _doc() -> dict[str, Any]:
    return tomllib.loads(DEFAULT_PROFILE.read_text())


def test_default_profile_loads_with_units_converted() -> None:
    prof = load_profile()
    assert prof.geometry.a1 == 60.0
    assert prof.motors.steps_per_rev == 200 * 16 * 4.0
    assert prof.motors.home_rad[0] == pytest.approx(math.radians(120.0))
    assert prof.motors.limits_rad[1] == pytest.approx((math.radians(10), math.radians(170)))
    assert prof.kinematics.min_type2_margin_rad == pytest.approx(math.radians(15.0))
    assert prof.kinematics.assembly == "+"
    # The home pose must be assemblable: the arms at home_deg close the loop.
    import numpy as np

    res = prof.geometry.forward_batch(np.array([prof.motors.home_rad]), "+")
    assert res.valid.all()
    # ... and in the configured assembly "+" the pen is above the elbows (left of R1→R2).
    r1, r2 = prof.geometry.elbows(np.array([prof.motors.home_rad]))
    d, e = r2[0] - r1[0], res.points[0] - r1[0]
    assert d[0] * e[1] - d[1] * e[0] > 0 and res.points[0, 1] > max(r1[0, 1], r2[0, 1])


def _set(doc: dict[str, Any], table: str, key: str, value: Any) -> dict[str, Any]:
    doc[table][key] = value
    return doc


@pytest.mark.parametrize(("table", "key", "value", "msg"), [
    ("geometry", "a1", -5.0, r"\[geometry\] a1: must be > 0"),
    ("geometry", "w", "wide", r"\[geometry\] w: must be a number"),
    ("geometry", "w", 1000.0, r"\[geometry\].*never meet"),
    ("motors", "microsteps", 0, r"\[motors\] microsteps: must be in \[1, 256\]"),
    ("motors", "microsteps", 16.5, r"\[motors\] microsteps: must be an integer"),
    ("motors", "gear_ratio", 0, r"\[motors\] gear_ratio: must be > 0"),
    ("motors", "home_deg", [200.0, 60.0], r"home_deg\[0\] = 200 lies outside limits_deg\[0\]"),
    ("motors", "limits_deg", [[10, 5], [10, 170]], r"limits_deg\[0\]: need"),
    ("motors", "endstops", "no", r"\[motors\] endstops: must be true or false"),
    ("kinematics", "working_mode", "+", r"working_mode: must be one of"),
    ("kinematics", "assembly", "up", r"\[kinematics\] assembly: must be one of \+, -; got 'up'"),
    ("kinematics", "assembly", 1, r"\[kinematics\] assembly: must be one of \+, -; got 1"),
    ("kinematics", "min_type2_margin_deg", 95.0, r"min_type2_margin_deg: must be ≤ 89"),
    ("motion", "tolerance_mm", 0.0, r"tolerance_mm: must be ≥ 0.0001"),
    ("motion", "draw_feed_mm_s", float("nan"), r"draw_feed_mm_s: must be finite"),
    ("laser", "power", 300, r"\[laser\] power: must be in \[0, 255\]"),
    ("laser", "on_command", "M7", r"on_command: must be one of M3, M4"),
    ("serial", "baud", True, r"\[serial\] baud: must be an integer"),
])
def test_bad_values_name_the_key(table: str, key: str, value: Any, msg: str) -> None:
    with pytest.raises(ConfigError, match=msg):
        parse_profile(_set(_doc(), table, key, value), "p.toml")


def test_unknown_and_missing_keys() -> None:
    doc = _doc()
    doc["motion"]["max_speed"] = 3
    with pytest.raises(ConfigError, match=r"p.toml: \[motion\] unknown key\(s\): max_speed"):
        parse_profile(doc, "p.toml")
    doc = _doc()
    del doc["geometry"]["b2"]
    with pytest.raises(ConfigError, match=r"\[geometry\] b2: missing key"):
        parse_profile(doc, "p.toml")
    doc = _doc()
    del doc["kinematics"]["assembly"]
    with pytest.raises(ConfigError, match=r"p.toml: \[kinematics\] assembly: missing key"):
        parse_profile(doc, "p.toml")
    doc = _doc()
    del doc["laser"]
    with pytest.raises(ConfigError, match=r"missing table \[laser\]"):
        parse_profile(doc, "p.toml")
    doc = _doc()
    doc["extras"] = {}
    with pytest.raises(ConfigError, match=r"unknown table\(s\): extras"):
        parse_profile(doc, "p.toml")


def test_assembly_minus_parses_and_homed_pose_is_checked() -> None:
    prof = parse_profile(_set(_doc(), "kinematics", "assembly", "-"), "p.toml")
    assert prof.kinematics.assembly == "-"
    # a homed pose whose elbows are further apart than b1 + b2 cannot be assembled
    doc = _set(_doc(), "motors", "home_deg", [170.0, 10.0])
    doc["geometry"]["b1"] = doc["geometry"]["b2"] = 40.0
    with pytest.raises(ConfigError, match=r"\[motors\] home_deg = \[170, 10\]: the floating "
                                          r"links cannot close the loop"):
        parse_profile(doc, "p.toml")
    # elbows exactly b1 + b2 apart: the homed pose is a type-2 singularity
    doc = _set(_doc(), "motors", "home_deg", [90.0, 90.0])
    doc["geometry"]["w"] = 180.0
    with pytest.raises(ConfigError, match=r"home_deg = \[90, 90\]: the homed pose is a type-2 "
                                          r"singularity"):
        parse_profile(doc, "p.toml")


def test_unreadable_and_malformed_files(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read profile"):
        load_profile(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[geometry\na1 = 3\n")
    with pytest.raises(ConfigError, match=r"bad.toml: not valid TOML"):
        load_profile(bad)


def test_profile_is_frozen() -> None:
    prof = load_profile()
    with pytest.raises(AttributeError):
        prof.motion.tolerance_mm = 1.0  # type: ignore[misc]


def test_cli_config_check(tmp_path: Path) -> None:
    runner = CliRunner()
    ok = runner.invoke(main, ["config", "check", str(DEFAULT_PROFILE)])
    assert ok.exit_code == 0, ok.output
    assert "steps_per_rev = 12800" in ok.output
    text = DEFAULT_PROFILE.read_text().replace("b1 = 90.0", "b1 = -90.0")
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    res = runner.invoke(main, ["config", "check", str(bad)])
    assert res.exit_code == 2
    assert "[geometry] b1: must be > 0" in res.output


def test_cli_ik_fk_round_trip_and_unreachable() -> None:
    runner = CliRunner()
    res = runner.invoke(main, ["ik", "20", "100", "--mode", "+-"])
    assert res.exit_code == 0, res.output
    assert "θ1 = 139.866190°" in res.output
    res = runner.invoke(main, ["fk", "139.866190", "40.133810"])
    assert res.exit_code == 0
    assert "P = (20.0000" in res.output and "working mode +-" in res.output
    res = runner.invoke(main, ["ik", "300", "0"])
    assert res.exit_code == 2
    assert "beyond arm 1's reach" in res.output


def test_cli_version_and_help() -> None:
    runner = CliRunner()
    assert runner.invoke(main, ["--version"]).output.startswith("fivebar, version")
    assert "five-bar" in runner.invoke(main, ["--help"]).output


def test_a_partial_profile_inherits_the_default_and_says_where(tmp_path: Path) -> None:
    """Only the keys that differ: the rest come from configs/default.toml, and `config show`
    marks each key with its source."""
    from click.testing import CliRunner

    from fivebar_host.cli import main

    part = tmp_path / "mine.toml"
    part.write_text("[geometry]\nb1 = 95.0\nb2 = 95.0\n[motion]\ndraw_feed_mm_s = 25\n")
    mine, default = load_profile(part), load_profile()
    assert (mine.geometry.b1, mine.geometry.b2, mine.motion.draw_feed_mm_s) == (95.0, 95.0, 25.0)
    assert mine.geometry.a1 == default.geometry.a1 and mine.motors == default.motors
    assert mine.motion.travel_feed_mm_s == default.motion.travel_feed_mm_s
    res = CliRunner().invoke(main, ["config", "show", "--config", str(part)])
    assert res.exit_code == 0, res.output
    rows = {ln.split("=")[0].strip(): ln for ln in res.output.splitlines() if "=" in ln}
    assert rows["b1"].endswith("# profile") and "95.0" in rows["b1"]
    assert rows["draw_feed_mm_s"].endswith("# profile")
    assert rows["a1"].endswith("# default") and rows["baud"].endswith("# default")
    n_default = sum(ln.endswith("# default") for ln in rows.values())
    assert f"({n_default} keys from the bundled default" in res.output.splitlines()[0]


@pytest.mark.parametrize(("text", "hint"), [
    ("[motion]\ndraw_feed_mms = 25\n", "did you mean 'draw_feed_mm_s'"),
    ("[moton]\ndraw_feed_mm_s = 25\n", "did you mean 'motion'"),
    ("[geometry]\nB1 = 95.0\n", "did you mean 'b1'"),
])
def test_a_misspelt_key_gets_did_you_mean(tmp_path: Path, text: str, hint: str) -> None:
    p = tmp_path / "typo.toml"
    p.write_text(text)
    with pytest.raises(ConfigError, match=hint):
        load_profile(p)


# ------------------------------------------------------------------ the pen servo ([tool], [pen])
PEN_PROFILE = Path(__file__).resolve().parents[1] / "configs" / "pen-servo.toml"


def _pen_doc() -> dict:
    import tomllib

    return tomllib.loads(PEN_PROFILE.read_text(encoding="utf-8"))


def test_pen_profile_loads_with_its_pulses_and_times() -> None:
    prof = load_profile(PEN_PROFILE)
    assert prof.tool == "pen" and prof.pen is not None
    pen = prof.pen
    assert (pen.pulse_us(pen.up_position), pen.pulse_us(pen.down_position)) == (1800, 1000)
    # 40 points at 200 %/s = 200 ms; at 400 %/s = 100 ms; whole 20 ms frames
    assert (pen.move_ms(True), pen.move_ms(False)) == (200, 100)
    assert wire.bodies(pen_item(prof, True)) == ["M280 S1000 R200 D150"]
    assert wire.bodies(pen_item(prof, False)) == ["M280 S1800 R100 D100"]
    assert load_profile().tool == "laser" and load_profile().pen is None


@pytest.mark.parametrize(("table", "key", "value", "needle"), [
    ("pen", "up_position", 100.5, "[pen] up_position: must be ≤ 100"),
    ("pen", "down_position", -1.0, "[pen] down_position: must be ≥ 0"),
    ("pen", "up_rate", -5.0, "[pen] up_rate: must be > 0"),
    ("pen", "down_rate", 0.0, "[pen] down_rate: must be > 0"),
    ("pen", "up_delay_ms", -1, "[pen] up_delay_ms: must be in [0, 10000]"),
    ("pen", "servo_min_us", 400, "[pen] servo_min_us: must be in [500, 2500]"),
    ("pen", "servo_max_us", 500, "[pen] servo_max_us: must be > servo_min_us"),
    ("pen", "lift", 1, "[pen] unknown key(s): lift"),
    ("tool", "kind", "laser", "[pen]: a pen table on a laser profile"),
    ("tool", "kind", "drill", "[tool] kind: must be one of pen, laser"),
])
def test_pen_profile_errors_name_the_key(table: str, key: str, value: object,
                                         needle: str) -> None:
    doc = _pen_doc()
    doc[table][key] = value
    with pytest.raises(ConfigError) as e:
        parse_profile(doc, "pen.toml")
    assert needle in str(e.value)


def test_a_pen_profile_without_a_pen_table_is_refused() -> None:
    doc = _pen_doc()
    del doc["pen"]
    with pytest.raises(ConfigError, match=r"missing table \[pen\]"):
        parse_profile(doc, "pen.toml")


def test_laser_on_a_pen_profile_is_refused_and_overrides_are_checked() -> None:
    from fivebar_host.config import require_tool, with_pen_overrides

    prof = load_profile(PEN_PROFILE)
    with pytest.raises(ConfigError, match="--laser refused: this profile's tool is a pen"):
        require_tool(prof, laser=True)
    require_tool(prof, laser=False)
    changed = with_pen_overrides(prof, {"pen_down_position": 10.0, "pen_down_delay_ms": 300.0,
                                        "pen_up_rate": None})
    # 55 points at 200 %/s: 275 ms, whole 20 ms frames
    assert changed.pen is not None and wire.bodies(pen_item(changed, True)) == [
        "M280 S700 R280 D300"]
    with pytest.raises(ConfigError, match="must differ"):
        with_pen_overrides(prof, {"pen_down_position": 65.0})
    with pytest.raises(ConfigError, match="no \\[pen\\] table"):
        with_pen_overrides(load_profile(), {"pen_up_position": 50.0})
