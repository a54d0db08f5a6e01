"""`fivebar workspace` and `fivebar design` end to end (click runner, in process)."""

from __future__ import annotations

import csv
import json
import math
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fivebar_host.cli import main
from fivebar_host.config import load_profile, parse_profile
from kinematics.workspace import Rect, largest_page_rectangle, point_safety


def _run(args: list[str]) -> tuple[int, str]:
    res = CliRunner().invoke(main, args, catch_exceptions=False)
    return res.exit_code, res.output


def test_workspace_default_profile_prints_figures_and_writes_files(tmp_path: Path) -> None:
    png, js, cs = tmp_path / "w.png", tmp_path / "w.json", tmp_path / "w.csv"
    code, out = _run(["workspace", "-o", str(png), "--json", str(js), "--csv", str(cs),
                      "--page", "60x40"])
    assert code == 0, out
    for label in ("usable area:", "largest page rectangle:", "step quantum in the page: worst",
                  "page 60 x 40 mm: fits"):
        assert label in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 50_000
    data = json.loads(js.read_text())
    prof = load_profile()
    k = prof.kinematics
    rect = largest_page_rectangle(prof.geometry, k.working_mode, k.min_type1_margin_rad,
                                  k.min_type2_margin_rad, prof.motors.limits_rad)
    got = data["page_rectangle"]
    assert (got["x0_mm"], got["y0_mm"], got["width_mm"], got["height_mm"]) == pytest.approx(
        (rect.x0, rect.y0, rect.width, rect.height))
    assert f"{rect.width:.1f} x {rect.height:.1f} mm" in out
    q = data["step_quantum_um"]
    assert 0 < q["median"] <= q["worst"] < 1000
    assert data["page_fits"] is True
    page = Rect(data["page"]["x0_mm"], data["page"]["y0_mm"], 60.0, 40.0)
    assert point_safety(prof.geometry, k.working_mode, page.sample(0.5), k.min_type1_margin_rad,
                        k.min_type2_margin_rad, prof.motors.limits_rad).all()
    with cs.open() as fh:
        rows = list(csv.DictReader(fh))
    assert rows and set(rows[0]) >= {"x_mm", "y_mm", "safe", "mu1_deg", "step1_um", "cond"}
    # CSV transmission angle against Eq. 23 on a few rows.
    fb = prof.geometry
    for r in rows[:: max(1, len(rows) // 50)]:
        c = math.hypot(float(r["x_mm"]), float(r["y_mm"]))
        mu = math.degrees(math.acos((c * c - fb.a1**2 - fb.b1**2) / (-2 * fb.a1 * fb.b1)))
        assert float(r["mu1_deg"]) == pytest.approx(mu, abs=1e-3)


def test_workspace_page_that_does_not_fit_exits_1() -> None:
    code, out = _run(["workspace", "--no-plot", "--page", "300x200", "--mode", "auto"])
    assert code == 1 and "does NOT fit" in out
    # "auto" analyses the mode with the largest page: "+-" (both elbows outward) here.
    assert "working mode +-, assembly +" in out
    code, out = _run(["workspace", "--no-plot", "--page", "300by200"])
    assert code == 2 and "200x150" in out


def test_design_then_workspace_confirms_the_page_fits(tmp_path: Path) -> None:
    """A design returned by `fivebar design` really fits its page when checked with
    `fivebar workspace` on the written profile."""
    prof_path = tmp_path / "design.toml"
    code, out = _run(["design", "--page", "80x50", "--margin-deg", "10", "--candidates", "1500",
                      "--top", "2", "-o", str(prof_path)])
    assert code == 0, out
    assert "evaluated 1500 candidate designs" in out and f"wrote {prof_path}" in out
    text = prof_path.read_text()
    prof = parse_profile(tomllib.loads(text), str(prof_path))
    assert math.degrees(prof.kinematics.min_type2_margin_rad) == pytest.approx(10.0)
    base = load_profile()
    assert prof.motors == base.motors.__class__(**{**base.motors.__dict__,
                                                   "home_rad": prof.motors.home_rad})
    js = tmp_path / "check.json"
    code, out = _run(["workspace", "--config", str(prof_path), "--no-plot", "--page", "80x50",
                      "--json", str(js)])
    assert code == 0, out
    data = json.loads(js.read_text())
    assert data["page_fits"] is True
    # The page placement named in the profile's header is safe, and the home pose written
    # puts the pen at its centre (to the 0.1° rounding of home_deg).
    m = re.search(r"page at x = (-?[\d.]+), y = (-?[\d.]+) mm", text)
    assert m is not None
    page = Rect(float(m[1]), float(m[2]), 80.0, 50.0)
    fb, k = prof.geometry, prof.kinematics
    # the profile records the assembly the page was found in (the machine must be built so)
    assert data["assembly"] == k.assembly
    assert point_safety(fb, k.working_mode, page.sample(0.5), k.min_type1_margin_rad,
                        k.min_type2_margin_rad, prof.motors.limits_rad,
                        assembly=k.assembly).all()
    pen = np.asarray(fb.forward(np.asarray(prof.motors.home_rad), k.assembly))
    # home_deg rounded to 0.1° (≤ 0.05° · ~300 mm/rad per motor), page corner to 0.1 mm.
    assert np.hypot(*(pen - np.asarray(page.center))) < 0.6


def test_workspace_searches_the_configured_assembly_only(tmp_path: Path) -> None:
    """Mode "++" of the default machine has a larger safe rectangle in assembly "-" (below
    the motors) than in "+"; the machine is built in "+", so `fivebar workspace` reports the
    "+" one — and the underside profile (assembly "-") the other."""
    from kinematics.workspace import find_page_rectangle

    prof = load_profile()
    k = prof.kinematics
    args = (prof.geometry, "++", k.min_type1_margin_rad, k.min_type2_margin_rad,
            prof.motors.limits_rad)
    plus = find_page_rectangle(*args, assembly="+").rect
    minus = find_page_rectangle(*args, assembly="-").rect
    assert minus.area > plus.area
    for cfg, rect, sign in ((None, plus, "+"),
                            (Path(__file__).resolve().parent.parent / "configs" / "underside.toml",
                             minus, "-")):
        js = tmp_path / f"w{sign}.json"
        extra = ["--config", str(cfg)] if cfg is not None else []
        code, out = _run(["workspace", "--no-plot", "--mode", "++", "--json", str(js), *extra])
        assert code == 0, out
        data = json.loads(js.read_text())
        assert data["assembly"] == sign
        got = data["page_rectangle"]
        assert (got["x0_mm"], got["y0_mm"], got["width_mm"], got["height_mm"]) == pytest.approx(
            (rect.x0, rect.y0, rect.width, rect.height))


def test_design_impossible_page_fails_cleanly(tmp_path: Path) -> None:
    code, out = _run(["design", "--page", "80x50", "--margin-deg", "85", "--candidates", "200",
                      "-o", str(tmp_path / "x.toml")])
    assert code == 1 and "no design" in out
    assert not (tmp_path / "x.toml").exists()
    code, out = _run(["design", "--page", "80x50", "--motor-spacing", "9:3"])
    assert code == 2
