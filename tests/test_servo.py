"""Servo joints, host side: the pulse ↔ angle curve (kinematics.servo), the dead band and its
compensation, and the profile's [joints] table (fivebar_host.joints)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fivebar_host.config import ConfigError, load_profile
from fivebar_host.controllers import open_controller
from fivebar_host.errors import FivebarError, UsageError
from kinematics.servo import (
    ServoCurve,
    ServoError,
    dead_band_commands,
    hysteresis,
    quantise_us,
)

SERVO_TOML = """
[joints]
kind = "servo"
refresh_hz = 50.0
pulse_range_us = [[600, 2400], [600, 2400]]
centre_us = [1500, 1500]
centre_deg = [120.0, 60.0]
direction = [1, -1]
us_per_deg = [10.0, 10.0]
speed_s_per_60deg = [0.12, 0.1]
dead_band_deg = [1.0, 0.5]
curve_us = [[600, 1050, 1500, 1950, 2400], [600, 1500, 2400]]
curve_deg = [[28.0, 75.0, 120.0, 163.0, 206.0], [150.0, 60.0, -30.0]]
"""


def test_table_curve_is_exact_on_its_nodes_and_inverts() -> None:
    p = np.array([600.0, 1050.0, 1500.0, 1950.0, 2400.0])
    a = np.radians([28.0, 75.0, 120.0, 163.0, 206.0])
    c = ServoCurve(p, a)
    assert np.array_equal(c.angle(p), a)
    assert np.allclose(c.pulse(a), p, atol=1e-9)
    q = np.linspace(600.0, 2400.0, 101)
    assert np.allclose(c.pulse(c.angle(q)), q, atol=1e-9)
    down = ServoCurve(p, a[::-1])  # a longer pulse turns this one clockwise
    assert np.allclose(down.pulse(down.angle(q)), q, atol=1e-9)
    with pytest.raises(ServoError, match="outside"):
        c.pulse(math.radians(10.0))


def test_cubic_fit_recovers_a_cubic_servo_within_the_noise() -> None:
    rng = np.random.default_rng(3)
    truth = np.polynomial.Polynomial([-0.35, 1.3e-3, 2.0e-8, -4.0e-11])
    p = np.linspace(600.0, 2400.0, 25)
    meas = truth(p) + rng.normal(0.0, math.radians(0.1), p.size)
    c = ServoCurve.fit(p, meas, 3)
    q = np.linspace(600.0, 2400.0, 50)
    assert np.abs(c.angle(q) - truth(q)).max() < math.radians(0.15)
    with pytest.raises(ServoError, match="monotone"):
        ServoCurve(p, np.sin(p / 300.0))


def test_dead_band_compensation_puts_the_output_on_the_targets() -> None:
    """Random targets with many reversals: the hysteresis model driven by the compensated
    commands sits on every target; driven by the targets themselves it lags by up to w/2."""
    rng = np.random.default_rng(5)
    t = np.cumsum(rng.normal(0.0, 0.05, 400)) + 2.0
    w = math.radians(1.0)
    out = hysteresis(dead_band_commands(t, w), w)
    assert np.abs(out - t).max() < 1e-12
    lag = np.abs(hysteresis(t, w) - t).max()
    assert 0.4 * w < lag <= 0.5 * w + 1e-12


def test_servo_profile_pulses_and_refusal(tmp_path: Path) -> None:
    cfg = tmp_path / "servo.toml"
    cfg.write_text(SERVO_TOML)
    prof = load_profile(cfg)
    assert prof.joints is not None and load_profile(None).joints is None
    sj = prof.joints
    assert sj.max_joint_rad_s == pytest.approx((math.pi / 3) / 0.12)
    th = np.radians([[120.0, 60.0], [140.0, 30.0], [130.0, 45.0], [130.0, 45.0]])
    pul = sj.pulses(th)
    assert np.array_equal(pul, quantise_us(pul))  # 0.5 µs steps
    # Back through each servo's curve and dead band: on the targets within the quantum.
    for i, j in enumerate(sj.joints):
        got = hysteresis(j.curve.angle(pul[:, i]), j.dead_band_rad)
        slope = np.abs(np.diff(j.curve.angle_rad) / np.diff(j.curve.pulse_us)).max()
        assert np.abs(got - th[:, i]).max() <= 0.25 * slope + 1e-12
    # GRBL drives no arm servo; fivebar's stepper firmware (the mock) is refused by banner
    with pytest.raises(UsageError, match="servo"):
        open_controller("grbl", "fivebar-grbl://", prof)
    with pytest.raises(FivebarError, match="servo build"):
        open_controller("fivebar", "fivebar-mock://", prof)


@pytest.mark.parametrize(("key", "value", "match"), [
    ("direction", "[1, 1]", "disagrees"),
    ("kind", '"hydraulic"', "kind"),
    ("pulse_range_us", "[[600, 2400], [2400, 600]]", "low < high"),
])
def test_servo_profile_errors_name_the_key(tmp_path: Path, key: str, value: str,
                                           match: str) -> None:
    text = "\n".join(f"{key} = {value}" if line.startswith(f"{key} =") else line
                     for line in SERVO_TOML.splitlines())
    cfg = tmp_path / "bad.toml"
    cfg.write_text(text)
    with pytest.raises(ConfigError, match=match):
        load_profile(cfg)


def test_plotclock_servo_profile_plans_pulses_within_its_servos() -> None:
    """configs/plotclock-servo.toml (the sketch's default servo lines): the dry-run job's
    joint angles map to pulses inside every servo's range, and back onto the angles."""
    from fivebar_host.compile import CompileOptions, compile_job

    root = Path(__file__).resolve().parent.parent
    prof = load_profile(root / "configs" / "plotclock-servo.toml")
    assert prof.joints is not None
    job = compile_job(root / "examples" / "fivebar_text.svg", prof, CompileOptions(fit=True))
    pul = prof.joints.pulses(job.angles_rad)
    assert pul.min() >= 500.0 and pul.max() <= 2500.0
    # The sketch's left servo: 2250 µs at 180°, 650 µs per radian.
    left = prof.joints.joints[0].curve
    assert float(left.pulse(math.pi)) == pytest.approx(2250.0, abs=0.05)
    for i, j in enumerate(prof.joints.joints):
        got = hysteresis(j.curve.angle(pul[:, i]), j.dead_band_rad)
        assert np.abs(got - job.angles_rad[:, i]).max() <= math.radians(0.25 / 11.345) + 1e-9


def test_servo_speed_caps_the_planned_joint_speed(tmp_path: Path) -> None:
    from fivebar_host.compile import CompileOptions
    from fivebar_host.compile.job import with_job_motion

    cfg = tmp_path / "slow.toml"
    cfg.write_text(SERVO_TOML.replace("speed_s_per_60deg = [0.12, 0.1]",
                                      "speed_s_per_60deg = [0.5, 0.3]"))
    prof = load_profile(cfg)
    got = with_job_motion(prof, CompileOptions()).motion.max_joint_rad_s
    assert got == pytest.approx((math.pi / 3) / 0.5)  # the slower servo, below 6 rad/s
