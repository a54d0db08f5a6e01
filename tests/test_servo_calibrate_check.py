"""`fivebar calibrate check` on servo profiles (issue 38): the old profile's predicted
drawing error on the fitted machine, through the pulse ↔ angle curves and the dead bands.

The reference is analytic: a fitted machine whose arm-A curve sits 1° above the old one's
and whose arm-B dead band is 2° against the old 1° turns the joints to IK(p) + (1°,
−s_B·0.5°) where the old profile asks for IK(p) (the pulses cancel out), so the drawn points
follow from the geometry alone; they are aligned here by an independent Kabsch fit."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fivebar_host.calibrate.check import error_map
from fivebar_host.cli import main
from fivebar_host.config import load_profile
from kinematics.calibration import CalibrationError

ROOT = Path(__file__).resolve().parent.parent
PLOTCLOCK = ROOT / "configs" / "plotclock.toml"


def _fitted(tmp_path: Path) -> Path:
    text = PLOTCLOCK.read_text(encoding="utf-8")
    assert "centre_deg = [113.89, 51.13]" in text and "dead_band_deg = [1.0, 1.0]" in text
    text = text.replace("centre_deg = [113.89, 51.13]", "centre_deg = [114.89, 51.13]")
    text = text.replace("dead_band_deg = [1.0, 1.0]", "dead_band_deg = [1.0, 2.0]")
    out = tmp_path / "fitted.toml"
    out.write_text(text, encoding="utf-8")
    return out


def _kabsch_errors(drawn: np.ndarray, want: np.ndarray) -> np.ndarray:
    """|R·drawn + t − want| after the least-squares rotation and shift (SVD)."""
    cd, cw = drawn.mean(axis=0), want.mean(axis=0)
    u, _, vt = np.linalg.svd((drawn - cd).T @ (want - cw))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    r = vt.T @ np.diag([1.0, d]) @ u.T
    return np.asarray(np.linalg.norm((drawn - cd) @ r.T + cw - want, axis=1))


def test_same_profile_draws_no_error() -> None:
    prof = load_profile(PLOTCLOCK)
    em = error_map(prof, prof)
    assert np.isfinite(em.error_mm).sum() > 1000
    assert em.max_mm < 1e-9


def test_curve_offset_and_dead_band_match_the_analytic_drawing(tmp_path: Path) -> None:
    fitted, old = load_profile(_fitted(tmp_path)), load_profile(PLOTCLOCK)
    em = error_map(fitted, old)
    gx, gy = np.meshgrid(em.xs, em.ys)
    ok = np.isfinite(em.error_mm)
    pts = np.stack((gx[ok], gy[ok]), axis=1)
    th = old.geometry.inverse_batch(pts, "+-").require(pts)
    drawn, want = [], []
    for _s_a, s_b in ((1, 1), (-1, -1), (1, -1), (-1, 1)):
        d = np.array([math.radians(1.0), -s_b * math.radians(0.5)])
        fwd = fitted.geometry.forward_batch(th + d, "+")
        assert fwd.valid.all()
        drawn.append(fwd.points)
        want.append(pts)
    err = _kabsch_errors(np.concatenate(drawn), np.concatenate(want)).reshape(4, -1).max(0)
    np.testing.assert_allclose(em.error_mm[ok], err, atol=1e-6)
    assert 0.3 < em.max_mm < 5.0  # a degree and a half-degree of dead band: about a mm


def test_dead_band_alone_is_seen(tmp_path: Path) -> None:
    text = PLOTCLOCK.read_text(encoding="utf-8").replace("dead_band_deg = [1.0, 1.0]",
                                                         "dead_band_deg = [2.0, 1.0]")
    (tmp_path / "wide.toml").write_text(text, encoding="utf-8")
    em = error_map(load_profile(tmp_path / "wide.toml"), load_profile(PLOTCLOCK))
    # half a degree short on arm A, one way or the other by the approach: not a rigid motion
    assert em.max_mm > 0.1


def test_stepper_against_servo_is_refused() -> None:
    with pytest.raises(CalibrationError, match="stepper profile"):
        error_map(load_profile(ROOT / "configs" / "default.toml"), load_profile(PLOTCLOCK))


def test_cli_maps_a_servo_profile(tmp_path: Path) -> None:
    res = CliRunner().invoke(main, ["calibrate", "check", "--config", str(_fitted(tmp_path)),
                                    "--old", str(PLOTCLOCK), "-o", str(tmp_path / "c.png")])
    assert res.exit_code == 0, res.output
    assert "drawing-shape error max" in res.output and (tmp_path / "c.png").stat().st_size
    bad = CliRunner().invoke(main, ["calibrate", "check", "--config",
                                    str(ROOT / "configs" / "default.toml"), "--old",
                                    str(PLOTCLOCK), "-o", str(tmp_path / "d.png")])
    assert bad.exit_code != 0 and "stepper profile" in bad.output
    assert not (tmp_path / "d.png").exists()
