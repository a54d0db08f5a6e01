"""Every job option declared once (`fivebar_host.options`): the CLI's options, the daemon's
query parameters and the HTTP client's query all come from the same definitions, so a range,
a name or a default cannot drift between them, and an unknown option is refused everywhere."""

from __future__ import annotations

import math
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from fivebar_host.cli import main
from fivebar_host.errors import FivebarError, OptionError
from fivebar_host.options import (
    JOB_OPTIONS,
    check_values,
    parse_query,
    to_query,
)
from fivebar_host.server.client import plot_options

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def test_query_round_trip_of_every_option() -> None:
    values = {"mode": "auto", "tolerance_mm": 0.2, "origin_mm": (10.5, -95.25), "scale": 0.5,
              "rotate_deg": 30.0, "fit": True, "layers": ("a", "b c"), "keep_order": True,
              "draw_feed_mm_s": 25.0, "travel_feed_mm_s": 60.0, "accel_fraction": 0.5,
              "laser": True, "confirm": True, "no_simplify": True,
              "max_segments": 3e6, "pen_up_position": 70.0,
              "pen_down_position": 20.5, "pen_up_rate": 300.0, "pen_down_rate": 150.0,
              "pen_up_delay_ms": 80.0, "pen_down_delay_ms": 120.0, "layer_pause": True,
              "no_pause": False, "copies": 3, "page_delay_s": 2.5, "gcode_strict": True,
              "hatch_mm": 0.4, "hatch_angle_deg": 30.0, "crosshatch": True,
              "hatch_inset_mm": 0.1, "hiding": True, "hatch_along": "arm1",
              # raster engraving (docs/raster.md)
              "width_mm": 40.0, "height_mm": 12.5, "dpi": 254.0, "line_interval_mm": 0.1,
              "image_mode": "jarvis", "power_min": 10, "power_max": 200, "gamma": 1.8,
              "threshold": 0.4, "negative": True, "scan_angle_deg": 45.0, "one_way": True,
              "passes": 2, "fill": "scan"}
    assert set(values) == {o.name for o in JOB_OPTIONS}
    q = to_query(values)
    pairs = [(k, v) for k, vs in q.items() for v in (vs if isinstance(vs, list) else [vs])]
    assert parse_query(pairs) == values


@pytest.mark.parametrize(("key", "text", "why"), [
    ("tolerance", "99", "within 0.0001..10 mm"),
    ("tolerance", "0", "within"),
    ("tolerance", "nan", "finite"),
    ("tolerance", "1ft", "must be a length such as"),
    ("origin", "1in,4yd", "1in,4in"),
    ("scale", "50 %x", "or a percentage"),
    ("accel", "0", "> 0 and <= 1"),
    ("accel", "150%", "> 0 and <= 1"),
    ("draw_speed", "3ft/s", "must be a speed"),
    ("travel_speed", "0mm/s", "within"),
    ("scale", "-1", "within"),
    ("scale", "0", "within"),
    ("rotate", "inf", "finite"),
    ("origin", "1;2", "X,Y"),
    ("origin", "1,nan", "finite"),
    ("mode", "+++", "one of"),
    ("fit", "maybe", "true or false"),
    ("hatch", "thick", "must be a length such as"),
    ("hatch", "-1mm", "within"),
    ("scael", "2", "did you mean 'scale'"),
    ("copies", "0", "within 1..9999"),
    ("copies", "10000", "within 1..9999"),
    ("copies", "2.5", "whole number"),
    ("page_delay", "-1", "within 0..3600 s"),
    ("page_delay", "3601", "within 0..3600 s"),
    ("page_delay", "61min", "within 0..3600 s"),
    ("page_delay", "1h", "must be a duration such as 15 (s), 15s, 500ms or 1.5min"),
    ("pen_delay_up", "soon", "must be a duration such as 15 (ms)"),
    ("layer_pause", "sometimes", "true or false"),
])
def test_bad_query_values_are_named(key: str, text: str, why: str) -> None:
    with pytest.raises(OptionError) as e:
        parse_query([(key, text)])
    assert e.value.option == key and why in str(e.value)
    assert isinstance(e.value, FivebarError)


def test_one_value_options_refuse_a_second_value() -> None:
    with pytest.raises(OptionError, match="more than once"):
        parse_query([("scale", "2"), ("scale", "3")])
    assert parse_query([("layer", "a"), ("layer", "b")])["layers"] == ("a", "b")


def test_client_refuses_unknown_and_out_of_range_before_sending() -> None:
    with pytest.raises(OptionError, match="did you mean 'scale'"):
        plot_options(scael=2.0)
    with pytest.raises(OptionError, match="tolerance"):
        plot_options(tolerance_mm=20.0)
    assert plot_options(scale=40.0, laser=True) == {"scale": "40.0", "rotate": "0.0",
                                                     "fit": "false", "keep_order": "false",
                                                     "laser": "true", "confirm": "false",
                                                     "no_simplify": "false",
                                                     "layer_pause": "false",
                                                     "no_pause": "false", "copies": "1",
                                                     "page_delay": "15.0", "strict": "false",
                                                     "hatch_angle": "45.0",
                                                     "crosshatch": "false",
                                                     "hatch_inset": "0.0", "hiding": "false",
                                                     "hatch_along": "lines",
                                                     # the raster options' defaults
                                                     "image_mode": "grayscale",
                                                     "power_min": "0", "gamma": "1.0",
                                                     "threshold": "0.5", "negative": "false",
                                                     "scan_angle": "0.0", "one_way": "false",
                                                     "passes": "1", "fill": "outline"}


def _cli_params(command: str) -> dict[str, click.Parameter]:
    cmd = main.commands[command]
    return {p.name: p for p in cmd.params if p.name}


@pytest.mark.parametrize("command", ["plot", "convert", "frame"])
def test_cli_options_are_the_definitions(command: str) -> None:
    params = _cli_params(command)
    for opt in JOB_OPTIONS:
        if not opt.cli or (command == "frame" and opt.name == "laser"):
            assert opt.name not in params
            continue
        p = params[opt.name]
        assert opt.flag in p.opts
        assert p.help is not None and opt.help in p.help


@pytest.mark.parametrize(("args", "why"), [
    (["--copies", "0"], "--copies"), (["--copies", "x"], "whole number"),
    (["--page-delay", "-1"], "--page-delay"),
    (["--layer-pause", "--no-pause"], "contradict"),
])
def test_cli_refuses_bad_copies_and_pauses_naming_the_option(args: list[str], why: str
                                                             ) -> None:
    r = CliRunner().invoke(main, ["plot", str(EXAMPLES / "simple.svg"), "--dry-run", *args])
    assert r.exit_code == 2 and why in r.output, r.output


def test_cli_and_api_refuse_the_same_value_with_the_same_reason() -> None:
    r = CliRunner().invoke(main, ["plot", str(EXAMPLES / "simple.svg"), "--dry-run",
                                  "--tolerance", "99"])
    assert r.exit_code == 2
    with pytest.raises(OptionError) as e:
        parse_query([("tolerance", "99")])
    assert e.value.why in r.output


def test_check_values_fills_defaults_and_checks() -> None:
    v = check_values({"scale": 2})
    assert v["scale"] == 2.0 and v["fit"] is False and v["layers"] == ()
    with pytest.raises(OptionError):
        check_values({"origin_mm": (math.nan, 0.0)})


@pytest.mark.parametrize(("key", "text", "value"), [
    ("tolerance", "0.1mm", 0.1), ("tolerance", "0.004in", 0.004 * 25.4),
    ("tolerance", "0.01cm", 0.1), ("tolerance", "0.1", 0.1),
    ("origin", "1in,4in", (25.4, 101.6)), ("origin", "10, 95", (10.0, 95.0)),
    ("origin", "72pt,96px", (25.4, 25.4)), ("origin", "-1cm,9.5cm", (-10.0, 95.0)),
    ("scale", "50%", 0.5), ("scale", "0.5", 0.5), ("scale", "250%", 2.5),
    ("accel", "50%", 0.5), ("accel", "1", 1.0),
    ("draw_speed", "25", 25.0), ("draw_speed", "25mm/s", 25.0), ("draw_speed", "1in/s", 25.4),
    ("travel_speed", "1200mm/min", 20.0), ("travel_speed", "6 cm / s", 60.0),
    ("pen_delay_up", "250", 250.0), ("pen_delay_up", "0.5s", 500.0),
    ("pen_delay_down", "40ms", 40.0),
])
def test_values_with_units_on_the_api_and_the_cli(key: str, text: str, value: object) -> None:
    """Units are read once, in `fivebar_host.options`: the daemon's query and the CLI take
    the same text (1 in = 25.4 mm, 72 pt and 96 px to the inch, 50% = 0.5)."""
    name = next(o.name for o in JOB_OPTIONS if o.query == key)
    got = parse_query([(key, text)])[name]
    assert got == pytest.approx(value)
    flag = next(o.flag for o in JOB_OPTIONS if o.query == key)
    res = CliRunner().invoke(main, ["convert", str(EXAMPLES / "simple.svg"), "-o", "/dev/null",
                                    flag, text, "--tolerance", "bogus"])
    assert "--tolerance" in res.output  # everything else parsed: the bogus one is named
    if key != "tolerance":
        assert flag not in res.output.split("Error:")[1]


def test_the_page_delay_takes_a_time_unit_on_the_api_and_the_cli(tmp_path: Path) -> None:
    """A duration is read once too: 15, 15s, 500ms and 1.5min are what a person types."""
    for text, seconds in (("15", 15.0), ("15s", 15.0), ("500ms", 0.5), ("1.5min", 90.0)):
        assert parse_query([("page_delay", text)])["page_delay_s"] == pytest.approx(seconds)
    res = CliRunner().invoke(main, ["plot", str(EXAMPLES / "simple.svg"), "--dry-run",
                                    "--copies", "2", "--page-delay", "1.5min",
                                    "--preview", str(tmp_path / "p.png")])
    assert res.exit_code == 0 and "1 page delay of 90 s" in res.output, res.output


@pytest.mark.parametrize(("text", "landscape", "size"), [
    ("A4", False, (210.0, 297.0)), ("a4", True, (297.0, 210.0)), ("A5", False, (148.0, 210.0)),
    ("A3", True, (420.0, 297.0)), ("letter", False, (215.9, 279.4)),
    ("Legal", True, (355.6, 215.9)), ("200x150", False, (200.0, 150.0)),
    ("150x200", True, (200.0, 150.0)), ("8.5inx11in", False, (215.9, 279.4)),
    ("21cm x 29.7cm", False, (210.0, 297.0)), ("200×150", False, (200.0, 150.0)),
])
def test_page_sizes_by_name_and_with_units(text: str, landscape: bool,
                                           size: tuple[float, float]) -> None:
    from fivebar_host.options import parse_page

    assert parse_page(text, landscape) == pytest.approx(size)


@pytest.mark.parametrize("text", ["A7", "200", "x150", "0x150", "200x-1", "1ftx2ft"])
def test_bad_page_sizes_say_what_a_page_looks_like(text: str) -> None:
    res = CliRunner().invoke(main, ["design", "--page", text])
    assert res.exit_code == 2
    assert "page size must" in res.output


def test_speed_options_replace_the_profile_s_motion_values(tmp_path: Path) -> None:
    """--draw-speed/--travel-speed/--accel compile the same job as a profile that says so
    (the independent route: the TOML file), and slower settings take longer."""
    from fivebar_host.compile import CompileOptions, compile_job
    from fivebar_host.config import load_profile

    text = (Path(__file__).resolve().parents[1] / "configs" / "default.toml").read_text()
    slow = tmp_path / "slow.toml"
    slow.write_text(text.replace("draw_feed_mm_s = 40.0", "draw_feed_mm_s = 12.7")
                    .replace("travel_feed_mm_s = 80.0", "travel_feed_mm_s = 30.0")
                    .replace("max_joint_rad_s2 = 60.0", "max_joint_rad_s2 = 15.0"))
    drawing = EXAMPLES / "simple.svg"
    values = parse_query([("draw_speed", "0.5in/s"), ("travel_speed", "1800mm/min"),
                          ("accel", "25%")])
    by_option = compile_job(drawing, load_profile(), CompileOptions(
        draw_feed_mm_s=values["draw_feed_mm_s"], travel_feed_mm_s=values["travel_feed_mm_s"],
        accel_fraction=values["accel_fraction"]))
    by_profile = compile_job(drawing, load_profile(slow))
    assert (by_option.duration_us == by_profile.duration_us).all()
    assert (by_option.steps == by_profile.steps).all()
    default = compile_job(drawing, load_profile())
    assert by_option.total_time_s > 1.5 * default.total_time_s


def test_hatch_takes_a_length_the_word_pen_or_nothing() -> None:
    opt = next(o for o in JOB_OPTIONS if o.name == "hatch_mm")
    assert opt.parse("0.4mm") == pytest.approx(0.4)
    assert opt.parse("0.02in") == pytest.approx(0.508)
    assert opt.parse("pen") == 0.0  # the profile's pen width
    seen: dict[str, object] = {}

    @click.command()
    @click.option(opt.flag, opt.name, type=click.STRING, is_flag=False, flag_value="pen")
    def cmd(hatch_mm: str | None) -> None:
        seen["v"] = hatch_mm

    CliRunner().invoke(cmd, ["--hatch"])
    assert seen["v"] == "pen"
