"""Servo calibration (kinematics.servo_calibration): a known synthetic true machine recovered
within its reported uncertainty, a fit that ignores the dead band failing, the drawing-shape
error before and after.

The measurements are simulated independently of the fit's closed form (SC1): each joint is
driven through the real command sequence — a pen-up approach point short of every mark on
the side the pattern asks, then the mark — by `kinematics.servo.hysteresis` (the dead band as
a play, Eq. S1) on the true curve's angles, and the pen is placed by `ExtendedFiveBar`.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fivebar_host.config import load_profile
from kinematics.calibration import CalibrationError, rigid_fit, rotation
from kinematics.extension import ExtendedFiveBar
from kinematics.servo import hysteresis
from kinematics.servo_calibration import (
    DEAD,
    ServoMachine,
    ServoMarks,
    approach_signs,
    commanded_pulses,
    fit_servo,
    pattern_points,
    pattern_shape_error,
    with_dead_band,
)

ROOT = Path(__file__).resolve().parent.parent
PROFILE = load_profile(ROOT / "configs" / "plotclock.toml")
MODE, ASM = PROFILE.kinematics.working_mode, PROFILE.kinematics.assembly
SIGMA = 0.05


def nominal() -> ServoMachine:
    j = PROFILE.joints
    assert j is not None and isinstance(PROFILE.geometry, ExtendedFiveBar)
    return ServoMachine.from_curves(
        PROFILE.geometry, (j.joints[0].curve, j.joints[1].curve),
        (j.joints[0].dead_band_rad, j.joints[1].dead_band_rad), (1500.0, 1500.0))


def true_machine() -> ServoMachine:
    """Lengths off by up to 0.4 mm, curves bowed by up to 2.5°, a 1° and a 1.4° dead band."""
    base = nominal()
    g = np.array(base.geometry)
    g[:5] += [0.3, -0.4, 0.2, 0.35, -0.25]
    co = base.coeffs.copy()
    co[:, 0] += np.radians([1.2, -0.8])
    co[:, 2] += np.radians([2.0, -1.5])
    co[:, 3] += np.radians([-2.5, 1.8])
    return ServoMachine(tuple(g), co, base.centre_us, (math.radians(1.0), math.radians(1.4)))


def drawn_by_sequence(true: ServoMachine, pulses: np.ndarray, approach: np.ndarray
                      ) -> np.ndarray:
    """Where `true` puts the pen at each mark when every mark's pulses are preceded by an
    approach command 4° short on the side `approach` says (hysteresis per joint)."""
    cmd = true.curve_angles(pulses)  # the angle each mark's pulse commands
    seq = np.empty((2 * cmd.shape[0], 2))
    seq[0::2] = cmd - np.radians(4.0) * approach
    seq[1::2] = cmd
    out = np.stack([hysteresis(seq[:, k], true.dead_band[k]) for k in range(2)], axis=1)
    fwd = true.fivebar().forward_batch(out[1::2], ASM)
    pts = np.asarray(fwd.points).copy()
    pts[~fwd.valid] = np.nan  # a mark the true machine cannot reach is not on the paper
    return pts


def synthetic_marks(rng: np.random.Generator, n: int = 60, approach: np.ndarray | None = None
                    ) -> tuple[ServoMachine, ServoMarks, np.ndarray]:
    base, true = nominal(), true_machine()
    inset = math.radians(8.0)
    lim = tuple((lo + inset, hi - inset) for lo, hi in PROFILE.motors.limits_rad)
    pts = pattern_points(base, MODE, ASM, lim, (math.radians(15), math.radians(20)), n)
    s = approach_signs(n) if approach is None else approach
    pulses = commanded_pulses(base, pts, s, MODE)
    y = drawn_by_sequence(true, pulses, s) @ rotation(0.7).T + [40.0, -12.0]
    ok = np.isfinite(y).all(axis=1)
    assert ok.sum() >= n - 3
    y = y[ok] + rng.normal(0.0, SIGMA, (int(ok.sum()), 2))
    return true, ServoMarks(pulses[ok], s[ok], y, ASM), pts[ok]


def test_sequence_simulation_matches_the_closed_form() -> None:
    """The hysteresis of the real command sequence puts the arm where SC1 says."""
    true = true_machine()
    s = approach_signs(12)
    pulses = np.column_stack((np.linspace(1100, 2200, 12), np.linspace(900, 2000, 12)))
    np.testing.assert_allclose(drawn_by_sequence(true, pulses, s),
                               true.pen_points(pulses, s, ASM), atol=1e-9)


def test_pulses_for_inverts_the_curves() -> None:
    m = true_machine()
    p = np.column_stack((np.linspace(700, 2300, 9), np.linspace(2300, 700, 9)))
    np.testing.assert_allclose(m.pulses_for(m.curve_angles(p)), p, atol=1e-6)


def test_known_machine_recovered_within_its_uncertainty() -> None:
    true, marks, _ = synthetic_marks(np.random.default_rng(7))
    res = fit_servo(nominal(), marks, sigma=SIGMA)
    free = res.free[:DEAD.stop]  # the geometry, the chosen orders' coefficients, dead bands
    z = np.abs(res.x[:DEAD.stop] - true.vector())[free] / res.std[:DEAD.stop][free]
    assert np.all(z <= 4.0), dict(zip(np.flatnonzero(free), z.round(2), strict=True))
    # the fit explains the marks to the noise: χ²/dof near 1
    chi2 = float(np.sum(res.residual_after ** 2)) / SIGMA ** 2 / res.dof
    assert 0.6 < chi2 < 1.5
    # the dead bands, each to better than 0.15°
    assert np.all(np.abs(np.degrees(res.dead_band - true.dead_band)) < 0.15)
    # the curves over the pattern's pulses: within 4σ of the truth at every pulse
    for k in range(2):
        p = np.linspace(marks.pulses[:, k].min(), marks.pulses[:, k].max(), 11)
        pp = np.column_stack((p, p))
        err = np.abs(res.machine.curve_angles(pp)[:, k] - true.curve_angles(pp)[:, k])
        assert np.all(err <= 4.0 * res.curve_std(k, p))


def test_shape_error_calibrated_within_goal() -> None:
    true, marks, pts = synthetic_marks(np.random.default_rng(8))
    res = fit_servo(nominal(), marks, sigma=SIGMA)
    s = marks.approach
    before = np.nanmax(pattern_shape_error(true, nominal(), pts, s, MODE, ASM))
    after = np.nanmax(pattern_shape_error(true, res.machine, pts, s, MODE, ASM))
    assert before > 2.0
    assert after <= 0.5
    # the truth itself draws the pattern exactly
    assert np.nanmax(pattern_shape_error(true, true, pts, s, MODE, ASM)) < 1e-6


def test_ignoring_the_dead_band_fails() -> None:
    """Fixed at 0, the dead band leaves residuals far above the noise, and the drawing off."""
    true, marks, pts = synthetic_marks(np.random.default_rng(9))
    ign = fit_servo(with_dead_band(nominal(), (0.0, 0.0)), marks, sigma=SIGMA,
                    fit_dead_band=False)
    full = fit_servo(nominal(), marks, sigma=SIGMA)
    assert ign.rms_after_mm > 3.0 * math.sqrt(2.0) * SIGMA
    assert full.rms_after_mm < 1.3 * math.sqrt(2.0) * SIGMA
    s = marks.approach
    e_ign = np.nanmax(pattern_shape_error(true, ign.machine, pts, s, MODE, ASM))
    e_full = np.nanmax(pattern_shape_error(true, full.machine, pts, s, MODE, ASM))
    assert e_ign > 2.0 * e_full
    assert e_ign > 0.5


def test_one_sided_approach_leaves_the_dead_band_undetermined() -> None:
    """Every mark approached from the same side: the dead band is not identifiable from the
    curve offset, and the fit says so (a huge or infinite σ), not a confident number."""
    n = 60
    _, marks, _ = synthetic_marks(np.random.default_rng(10), n, np.ones((n, 2)))
    res = fit_servo(nominal(), marks, sigma=SIGMA)
    assert np.all(res.dead_band_std > math.radians(5.0))


def test_too_few_marks_refused() -> None:
    _, marks, _ = synthetic_marks(np.random.default_rng(11), 60)
    few = ServoMarks(marks.pulses[:10], marks.approach[:10], marks.measured[:10], ASM)
    with pytest.raises(CalibrationError, match="at least"):
        fit_servo(nominal(), few)


def test_rigid_fit_recovers_placement() -> None:
    """The helper the shape error uses (a sanity check of the alignment)."""
    src = np.random.default_rng(1).normal(size=(10, 2))
    dst = src @ rotation(0.3).T + [1.0, 2.0]
    phi, t = rigid_fit(src, dst)
    assert phi == pytest.approx(0.3)
    np.testing.assert_allclose(t, [1.0, 2.0])
