"""The five-bar robot through the general solver against the closed-form kinematics
(kinematics.fivebar, which shares no code with kinematics.nbar)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from kinematics.fivebar import FiveBar
from kinematics.nbar import (
    MechanismError,
    fivebar_mechanism,
    parse_mechanism,
    sweep,
    validate_fivebar_path,
)

MECH = Path(__file__).resolve().parent.parent / "configs" / "mechanisms"
GEOM = FiveBar(60.0, 90.0, 60.0, 90.0, 40.0)
ODD = FiveBar(55.0, 95.0, 65.0, 85.0, 42.0)


def circle_job(fb: FiveBar, mode: str, n: int = 400) -> np.ndarray:
    """Motor angles of a 25 mm circle drawn in working mode `mode` (closed-form inverse)."""
    t = np.linspace(0.0, 2 * math.pi, n)
    pts = np.stack((20.0 + 25.0 * np.cos(t), 110.0 + 25.0 * np.sin(t)), axis=1)
    res = fb.inverse_batch(pts, mode)
    assert res.valid.all()
    return np.asarray(res.angles)


@pytest.mark.parametrize("fb", [GEOM, ODD], ids=["symmetric", "asymmetric"])
def test_end_effector_equals_closed_form_along_a_trajectory(fb: FiveBar) -> None:
    angles = circle_job(fb, "+-")
    report = validate_fivebar_path(fb, angles, "+")
    assert report.valid.all()
    assert report.max_deviation < 1e-9
    assert report.simulation.completed
    assert "max deviation" in str(report)


def test_other_assembly_mode_is_followed_too() -> None:
    """Same motor angles, assembly '−' (P right of R1→R2): the n-bar result is the mirror
    branch and again matches the closed form."""
    angles = circle_job(GEOM, "+-", 120)
    plus = validate_fivebar_path(GEOM, angles, "+")
    minus = validate_fivebar_path(GEOM, angles, "-")
    assert minus.max_deviation < 1e-9
    assert np.linalg.norm(plus.nbar_points - minus.nbar_points, axis=1).min() > 1.0


def test_validation_flags_rows_without_a_solution() -> None:
    """Floating links of 70 mm: opening the arms to θ = (180°, 0°) pulls the elbows 160 mm
    apart > b1 + b2 = 140. The closed form refuses those rows and the n-bar continuation stops
    at the limit; the report says so instead of giving a number."""
    fb = FiveBar(60.0, 70.0, 60.0, 70.0, 40.0)
    th1 = np.linspace(math.radians(120), math.radians(180), 60)
    th2 = np.linspace(math.radians(60), math.radians(0), 60)
    report = validate_fivebar_path(fb, np.stack((th1, th2), axis=1), "+")
    assert not report.valid.all() and report.valid[:10].all()
    assert report.max_deviation == math.inf
    assert report.simulation.limits and "without a solution" in str(report)
    assert np.nanmax(report.deviation[report.valid]) < 1e-9


def test_mechanism_file_matches_closed_form() -> None:
    """configs/mechanisms/fivebar_robot.toml: P given to 0.01 mm is assembled onto the stated
    90 mm links; the sweep's P equals the closed form at every step."""
    mech = parse_mechanism((MECH / "fivebar_robot.toml").read_text())
    assert any("assembled" in a for a in mech.adjustments)
    assert mech.input0 == pytest.approx([math.radians(120), math.radians(60)])
    sim = sweep(mech, tolerance=1e-12)
    closed = GEOM.forward_batch(sim.inputs, "+")
    assert closed.valid.all()
    assert np.abs(sim.path("P") - closed.points).max() < 1e-9


def test_input_angles_beyond_pi_keep_their_turn() -> None:
    """An initial angle outside (−π, π] is kept (no spurious 2π lead-in)."""
    angles = circle_job(GEOM, "+-", 50) + np.array([2 * math.pi, 0.0])
    report = validate_fivebar_path(GEOM, angles, "+")
    assert report.max_deviation < 1e-9
    assert report.simulation.iterations[0] == 0


def test_first_pose_must_assemble() -> None:
    short = FiveBar(60.0, 50.0, 60.0, 50.0, 40.0)  # elbows 160 mm apart > b1 + b2 = 100
    with pytest.raises(MechanismError, match="do not assemble"):
        fivebar_mechanism(short, [math.radians(180), math.radians(0)], "+")
    with pytest.raises(ValueError, match="assembly"):
        fivebar_mechanism(GEOM, [2.0, 1.0], "x")
