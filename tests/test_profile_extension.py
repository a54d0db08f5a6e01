"""Profiles with the pen off the joint: [geometry] extension / extension_angle_deg, and the
bundled Plotclock profile compiling a drawing within its bound."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from fivebar_host.compile import CompileOptions, compile_job
from fivebar_host.config import ConfigError, load_profile, merged_document, parse_profile
from kinematics.extension import ExtendedFiveBar
from kinematics.fivebar import FiveBar

ROOT = Path(__file__).resolve().parent.parent


def test_default_profile_keeps_the_pen_on_the_joint() -> None:
    g = load_profile(None).geometry
    assert type(g) is FiveBar


def test_plotclock_profile_is_plotclocks_published_geometry() -> None:
    g = load_profile(ROOT / "configs" / "plotclock.toml").geometry
    assert isinstance(g, ExtendedFiveBar)
    # The sketch's left link: the pen 55.1 mm from the elbow (L2) and 13.2 mm from the
    # joint (L3), 0.621 rad apart at the pen — recovered from b1, e and γ (law of cosines).
    assert g.pen_link == pytest.approx(55.1, abs=2e-3)
    cos_pen = (g.pen_link**2 + g.extension**2 - g.b1**2) / (2 * g.pen_link * g.extension)
    assert math.acos(cos_pen) == pytest.approx(0.621, abs=1e-4)
    assert (g.a1, g.a2, g.b2, g.w) == (35.0, 35.0, 45.0, 25.0)


def test_extension_keys_are_checked() -> None:
    doc, _ = merged_document(None)
    doc["geometry"]["extension"] = -1.0
    with pytest.raises(ConfigError, match="extension"):
        parse_profile(doc, "x.toml")
    doc["geometry"]["extension"] = 90.0
    doc["geometry"]["extension_angle_deg"] = 180.0
    with pytest.raises(ConfigError, match="elbow R1"):
        parse_profile(doc, "x.toml")
    doc["geometry"]["extension_angle_deg"] = 200.0
    with pytest.raises(ConfigError, match="extension_angle_deg"):
        parse_profile(doc, "x.toml")


def test_plotclock_compiles_text_within_its_bound() -> None:
    prof = load_profile(ROOT / "configs" / "plotclock.toml")
    job = compile_job(ROOT / "examples" / "fivebar_text.svg", prof, CompileOptions(fit=True))
    assert 0.0 < job.max_dev_mm <= job.tolerance_mm + job.step_quantum_mm
