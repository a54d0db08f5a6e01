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
              "laser": True, "confirm": True, "pen_up_position": 70.0,
              "pen_down_position": 20.5, "pen_up_rate": 300.0, "pen_down_rate": 150.0,
              "pen_up_delay_ms": 80.0, "pen_down_delay_ms": 120.0}
    assert set(values) == {o.name for o in JOB_OPTIONS}
    q = to_query(values)
    pairs = [(k, v) for k, vs in q.items() for v in (vs if isinstance(vs, list) else [vs])]
    assert parse_query(pairs) == values


@pytest.mark.parametrize(("key", "text", "why"), [
    ("tolerance", "99", "within 0.0001..10 mm"),
    ("tolerance", "0", "within"),
    ("tolerance", "nan", "finite"),
    ("scale", "-1", "within"),
    ("scale", "0", "within"),
    ("rotate", "inf", "finite"),
    ("origin", "1;2", "X,Y"),
    ("origin", "1,nan", "finite"),
    ("mode", "+++", "one of"),
    ("fit", "maybe", "true or false"),
    ("scael", "2", "did you mean 'scale'"),
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
                                                     "laser": "true", "confirm": "false"}


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
