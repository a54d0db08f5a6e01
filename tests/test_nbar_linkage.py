"""Host side of the n-bar solver: mechanism files from disk, CSV / JSON output, pictures."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from fivebar_host.report.linkage import plot_simulation
from fivebar_host.report.text.linkage import load_mechanism, summary, write_result
from kinematics.nbar import MechanismError, build_mechanism, simulate, sweep

MECH = Path(__file__).resolve().parent.parent / "configs" / "mechanisms"


def test_load_errors_name_the_file(tmp_path: Path) -> None:
    with pytest.raises(MechanismError, match=r"missing\.toml: cannot read"):
        load_mechanism(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[mechanism]\nkind = 'planar'\n")
    with pytest.raises(MechanismError, match=r"bad\.toml: .*\[joints\]"):
        load_mechanism(bad)
    bad.write_text("[mechanism\n")
    with pytest.raises(MechanismError, match=r"bad\.toml: not valid TOML"):
        load_mechanism(bad)


def test_csv_has_one_row_per_step_with_every_joint(tmp_path: Path) -> None:
    mech = load_mechanism(MECH / "stephenson2.toml")
    sim = sweep(mech, steps=20)
    out = write_result(sim, tmp_path / "s.csv")
    with out.open() as f:
        rows = list(csv.reader(f))
    header, body = rows[0], rows[1:]
    assert len(body) == 21
    assert header[:6] == ["step", "status", "iterations", "substeps", "residual", "input_L1@J1"]
    assert {"J3_a", "J3_b", "J3_c", "J8_x", "J8_y"} <= set(header)
    k = header.index("J8_y")
    assert float(body[7][k]) == pytest.approx(sim.path("J8")[7, 1], abs=1e-12)


def test_json_marks_unreached_steps_and_limits(tmp_path: Path) -> None:
    import tomllib

    spec = tomllib.loads((MECH / "fourbar_crank_rocker.toml").read_text())
    spec["inputs"] = [{"link": "L3", "joint": "J4"}]
    mech = build_mechanism(spec)
    sim = simulate(mech, math.pi / 2 + np.radians(np.arange(0.0, 40.0, 3.0)))
    data = json.loads(write_result(sim, tmp_path / "s.json").read_text())
    assert data["completed"] is False
    assert data["limits"][0]["kind"] == "limit"
    last = data["steps"][-1]
    assert last["status"] == "unreached" and last["joints"]["J3"] == [None, None]
    assert data["steps"][0]["joints"]["J3"] == [4.0, 4.0]


def test_unknown_output_suffix_is_refused(tmp_path: Path) -> None:
    sim = sweep(load_mechanism(MECH / "fourbar_crank_rocker.toml"), steps=2)
    with pytest.raises(ValueError, match=r"\.csv or \.json"):
        write_result(sim, tmp_path / "s.txt")


@pytest.mark.parametrize("name", ["theo_jansen", "spherical_watt1", "five_ss"])
def test_plot_writes_a_picture(tmp_path: Path, name: str) -> None:
    sim = sweep(load_mechanism(MECH / f"{name}.toml"), steps=40)
    out = plot_simulation(sim, tmp_path / f"{name}.png")
    data = out.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000


def test_summary_reports_limits_and_adjustments() -> None:
    sim = sweep(load_mechanism(MECH / "spherical_watt1.toml"))
    text = summary(sim)
    assert "motion limit" in text and "projected onto the unit sphere" in text
    assert "tracer J8" in text


def test_cli_linkage_simulate(tmp_path: Path) -> None:
    from click.testing import CliRunner

    from fivebar_host.cli import main

    out, png = tmp_path / "r.json", tmp_path / "r.png"
    res = CliRunner().invoke(main, ["linkage", "simulate", str(MECH / "five_ss.toml"),
                                    "--steps", "30", "-o", str(out), "--plot", str(png)])
    assert res.exit_code == 0, res.output
    assert "18 unknowns, 18 equations" in res.output and "31 rows, 31 ok" in res.output
    assert len(json.loads(out.read_text())["steps"]) == 31 and png.stat().st_size > 10_000


def test_cli_linkage_reports_limits_and_refuses_bad_files(tmp_path: Path) -> None:
    from click.testing import CliRunner

    from fivebar_host.cli import main

    runner = CliRunner()
    res = runner.invoke(main, ["linkage", "simulate", str(MECH / "spherical_watt1.toml")])
    assert res.exit_code == 0 and res.output.count("motion limit") == 2
    bad = tmp_path / "bad.toml"
    bad.write_text("[mechanism]\nkind = 'planar'\n")
    res = runner.invoke(main, ["linkage", "simulate", str(bad)])
    assert res.exit_code == 2 and "bad.toml" in res.output
    res = runner.invoke(main, ["linkage", "simulate", str(MECH / "five_ss.toml"), "-o",
                               str(tmp_path / "x.txt")])
    assert res.exit_code == 2 and ".csv or .json" in res.output
