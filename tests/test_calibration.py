"""The calibration math (kinematics.calibration, calibration_analysis) against independent
references: a simulated true machine with known parameters, a finite-difference Jacobian and
scipy.optimize.least_squares as an independent fit."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import least_squares

from fivebar_host.calibrate.pattern import nominal_params, pattern_region
from fivebar_host.compile.steps import absolute_steps
from fivebar_host.config import load_profile
from kinematics.calibration import (
    CalibrationError,
    MachineParams,
    MarkData,
    fit,
    jacobian,
    residuals,
    rotation,
)
from kinematics.calibration_analysis import (
    design_marks,
    shape_errors,
    studentized,
    weak_combinations,
)

PROFILE = load_profile()
MODE = PROFILE.kinematics.working_mode
ASM = PROFILE.kinematics.assembly
Q = PROFILE.motors.rad_per_step
NOMINAL = nominal_params(PROFILE)
REGION = pattern_region(PROFILE, MODE)
REGION_PTS = REGION.points()[::2]


def marks(n: int) -> np.ndarray:
    """Commanded steps (n, 2) of an n-mark design over the pattern region."""
    pts = design_marks(NOMINAL, REGION.points(), n, 10, Q, MODE, ASM, 9.0)
    th = NOMINAL.fivebar().inverse_batch(pts, MODE).require(pts)
    return absolute_steps(th, NOMINAL.home_rad, PROFILE.motors.steps_per_rev).astype(float)


STEPS30 = marks(30)


def random_truth(rng: np.random.Generator) -> MachineParams:
    """Up to ±0.5 mm per length, ±0.5° per home angle (the issue's range)."""
    d = np.concatenate((rng.uniform(-0.5, 0.5, 5), np.radians(rng.uniform(-0.5, 0.5, 2))))
    return MachineParams.from_vector(NOMINAL.vector() + d)


def measure(true: MachineParams, steps: np.ndarray, rng: np.random.Generator,
            sigma: float = 0.05) -> tuple[MarkData, np.ndarray]:
    """Simulated measurement in a random paper frame; returns the data and (φ, tx, ty)."""
    place = np.array([rng.uniform(-math.pi, math.pi), *rng.uniform(-150, 150, 2)])
    p = true.pen_points(steps, Q, ASM)
    y = p @ rotation(place[0]).T + place[1:] + rng.normal(0.0, sigma, p.shape)
    return MarkData(steps, y, Q, ASM), place


def test_jacobian_matches_finite_differences() -> None:
    rng = np.random.default_rng(0)
    data, place = measure(random_truth(rng), STEPS30, rng)
    x = np.concatenate((random_truth(rng).vector(), place))
    jac = jacobian(x, data)
    fd = np.empty_like(jac)
    for k in range(x.size):
        h = 1e-6 * (1.0 if k in (5, 6, 7) else 100.0)
        e = np.zeros_like(x)
        e[k] = h
        fd[:, k] = (residuals(x + e, data) - residuals(x - e, data)) / (2 * h)
    scale = np.abs(fd).max(axis=0)
    assert np.max(np.abs(jac - fd) / scale) < 1e-7


def test_fit_agrees_with_scipy_least_squares() -> None:
    rng = np.random.default_rng(1)
    data, _ = measure(random_truth(rng), STEPS30, rng)
    res = fit(NOMINAL, data)
    x0 = np.concatenate((NOMINAL.vector(), [0.0, 0.0, 0.0]))
    from kinematics.calibration import initial_guess

    x0 = initial_guess(NOMINAL, data)
    ref = least_squares(lambda x: residuals(x, data), x0, method="lm", xtol=1e-15,
                        ftol=1e-15, gtol=1e-15)
    # Same minimum: parameters equal to a tiny fraction of their uncertainty.
    assert np.all(np.abs(res.x - ref.x) < 1e-3 * res.std)
    assert abs(float(res.residual_after.ravel() @ res.residual_after.ravel())
               - 2 * ref.cost) < 1e-9


def test_noise_free_fit_recovers_the_true_machine_exactly() -> None:
    rng = np.random.default_rng(2)
    true = random_truth(rng)
    data, place = measure(true, STEPS30, rng, sigma=0.0)
    res = fit(NOMINAL, data, sigma=0.05)
    assert np.allclose(res.x[:7], true.vector(), atol=1e-7)
    assert np.allclose(res.x[8:], place[1:], atol=1e-6)
    assert res.sigma_source == "given" and res.sigma == 0.05


def test_shape_error_drops_below_target_for_random_true_machines() -> None:
    """The issue's accuracy target: ≤ 0.1 mm max over the pattern's region, and ≤ 1/4 of
    the uncalibrated figure when that is typical (≥ 0.3 mm). The fitted error is a random
    variable (noise 0.05 mm): over many machines its max exceeds 0.1 mm in ~1–3 % of the
    cases (benchmarks/calibration.py), so: ≥ 90 % of cases on target, none wildly off."""
    rng = np.random.default_rng(3)
    before, after = [], []
    for _ in range(20):
        true = random_truth(rng)
        data, _ = measure(true, STEPS30, rng)
        res = fit(NOMINAL, data)
        before.append(np.nanmax(shape_errors(true, NOMINAL, REGION_PTS, MODE, ASM)))
        after.append(np.nanmax(shape_errors(true, res.machine, REGION_PTS, MODE, ASM)))
    b, a = np.array(before), np.array(after)
    assert np.mean(a <= 0.1) >= 0.9 and np.all(a <= 0.15) and np.median(a) <= 0.07, a
    typical = b >= 0.3
    assert typical.sum() >= 15
    assert np.mean(a[typical] <= b[typical] / 4) >= 0.9, (a, b)
    # The profile itself is no shape error at all.
    assert np.nanmax(shape_errors(NOMINAL, NOMINAL, REGION_PTS, MODE, ASM)) < 1e-9


def test_reported_uncertainties_are_honest() -> None:
    """Each true value within 3 reported σ in ≥ 99 % of the cases (σ from the residuals)."""
    rng = np.random.default_rng(4)
    z = []
    for _ in range(60):
        true = random_truth(rng)
        data, place = measure(true, STEPS30, rng)
        res = fit(NOMINAL, data)
        truth = np.concatenate((true.vector(), place))
        d = res.x - truth
        d[7] = (d[7] + math.pi) % (2 * math.pi) - math.pi
        z.append(np.abs(d) / res.std)
    zz = np.array(z)
    assert np.mean(zz[:, :7] <= 3.0) >= 0.99
    # and not absurdly pessimistic: most within 2σ
    assert np.mean(zz[:, :7] <= 2.0) >= 0.85


def test_weak_combinations_name_the_ill_conditioned_directions() -> None:
    rng = np.random.default_rng(5)
    data, _ = measure(random_truth(rng), STEPS30, rng)
    res = fit(NOMINAL, data)
    combos = weak_combinations(res)
    assert len(combos) == 3
    assert combos[0].std_mm >= combos[1].std_mm >= combos[2].std_mm
    # The worst one is much worse than the noise: the trap the issue describes.
    assert combos[0].std_mm > 0.2
    text = combos[1].describe()
    assert "w" in text and "b1" in text and "b2" in text
    # Its σ agrees with the full covariance: var(cᵀx) = cᵀ·C·c.
    c = np.zeros(7)
    for name, v in combos[0].coefficients.items():
        i = ["a1", "b1", "a2", "b2", "w", "h1", "h2"].index(name)
        c[i] = v * (180.0 / math.pi if i >= 5 else 1.0)
    sd = math.sqrt(c @ res.covariance[:7, :7] @ c)
    assert sd == pytest.approx(combos[0].std_mm, rel=0.15)  # small terms were dropped


def test_a_mis_measured_mark_is_an_outlier() -> None:
    rng = np.random.default_rng(6)
    data, _ = measure(random_truth(rng), STEPS30, rng)
    y = data.measured.copy()
    y[7] += (0.8, -0.6)
    res = fit(NOMINAL, MarkData(data.steps, y, Q, ASM))
    t = studentized(res)
    assert int(np.argmax(t)) == 7 and t[7] > 4.0
    assert np.sum(t > 4.0) == 1


def test_too_few_marks_and_non_convergence_are_errors() -> None:
    rng = np.random.default_rng(7)
    data, _ = measure(random_truth(rng), STEPS30[:9], rng)
    with pytest.raises(CalibrationError, match="at least 10"):
        fit(NOMINAL, data)
    data, _ = measure(random_truth(rng), STEPS30, rng)
    with pytest.raises(CalibrationError, match="did not converge in 1 iterations"):
        fit(NOMINAL, data, max_iterations=1)
