"""Calibration accuracy: the drawing-shape error before and after the fit, the honesty of the
reported uncertainties, and the error against measurement noise and the number of marks.

Simulated true machines: the default profile with every length off by up to ±0.5 mm and each
home angle by up to ±0.5° (uniform), the default pattern's marks (`fivebar calibrate
pattern`'s layout; their steps are the plot's, tests/test_calibrate_cli.py), measured in a
random paper frame with Gaussian noise σ per coordinate. The shape error is the max over the
pattern's region of |aligned drawn − intended| (kinematics.calibration_analysis).

Prints: before/after for several true machines; the coverage (each true value within 3
reported σ); and writes docs/img/calib_noise.png, calib_marks.png, calib_check.png.

Run: python benchmarks/calibration.py [--machines 30] [--coverage 300] [--seed 1]
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).parent.resolve()]
from fivebar_host.calibrate.check import ErrorMap  # noqa: E402
from fivebar_host.calibrate.pattern import (  # noqa: E402
    layout_marks,
    nominal_params,
    pattern_region,
)
from fivebar_host.compile.steps import absolute_steps  # noqa: E402
from fivebar_host.config import load_profile  # noqa: E402
from fivebar_host.report.calibration import draw_error_map, draw_sweep  # noqa: E402
from kinematics.calibration import MachineParams, MarkData, fit, rotation  # noqa: E402
from kinematics.calibration_analysis import shape_errors  # noqa: E402

IMG = Path(__file__).resolve().parent.parent / "docs" / "img"
PROFILE = load_profile()
MODE = PROFILE.kinematics.working_mode
ASM = PROFILE.kinematics.assembly
Q = PROFILE.motors.rad_per_step
NOMINAL = nominal_params(PROFILE)
REGION = pattern_region(PROFILE, MODE)
REGION_PTS = REGION.points()[::2]


def pattern_steps(n: int) -> np.ndarray:
    centres, _, _ = layout_marks(PROFILE, MODE, n)
    th = NOMINAL.fivebar().inverse_batch(centres, MODE).require(centres)
    return absolute_steps(th, NOMINAL.home_rad, PROFILE.motors.steps_per_rev).astype(float)


def random_truth(rng: np.random.Generator) -> MachineParams:
    d = np.concatenate((rng.uniform(-0.5, 0.5, 5), np.radians(rng.uniform(-0.5, 0.5, 2))))
    return MachineParams.from_vector(NOMINAL.vector() + d)


def trial(rng: np.random.Generator, steps: np.ndarray, sigma: float,
          given: bool = False) -> tuple[float, float, np.ndarray, MachineParams]:
    """One simulated calibration: (before max mm, after max mm, |z| per parameter, true)."""
    true = random_truth(rng)
    place = np.array([rng.uniform(-math.pi, math.pi), *rng.uniform(-150, 150, 2)])
    p = true.pen_points(steps, Q, ASM)
    y = p @ rotation(place[0]).T + place[1:] + rng.normal(0.0, sigma, p.shape)
    res = fit(NOMINAL, MarkData(steps, y, Q, ASM), sigma=sigma if given else None)
    before = float(np.nanmax(shape_errors(true, NOMINAL, REGION_PTS, MODE, ASM)))
    after = float(np.nanmax(shape_errors(true, res.machine, REGION_PTS, MODE, ASM)))
    d = res.x - np.concatenate((true.vector(), place))
    d[7] = (d[7] + math.pi) % (2 * math.pi) - math.pi
    return before, after, np.abs(d) / res.std, true


def section_cases(rng: np.random.Generator, steps: np.ndarray) -> None:
    print("1. shape error before → after, default pattern (30 marks), σ = 0.05 mm")
    print(f"{'case':>4} {'Δa1':>6} {'Δb1':>6} {'Δa2':>6} {'Δb2':>6} {'Δw':>6} {'Δh1°':>6} "
          f"{'Δh2°':>6} {'before':>8} {'after':>8} {'ratio':>6}")
    for k in range(8):
        b, a, _, true = trial(rng, steps, 0.05)
        d = true.vector() - NOMINAL.vector()
        d[5:] = np.degrees(d[5:])
        print(f"{k + 1:>4} " + " ".join(f"{v:+6.2f}" for v in d)
              + f" {b:8.3f} {a:8.3f} {a / b:6.3f}")


def section_coverage(rng: np.random.Generator, steps: np.ndarray, n: int) -> None:
    print(f"\n2. uncertainty coverage over {n} random true machines (fraction of true values "
          "within 3 reported σ)")
    for given in (False, True):
        z = np.array([trial(rng, steps, 0.05, given)[2] for _ in range(n)])
        per = " ".join(f"{name} {np.mean(z[:, i] <= 3):.3f}"
                       for i, name in enumerate(("a1", "b1", "a2", "b2", "w", "h1", "h2")))
        src = "σ given (0.05 mm)" if given else "σ from the residuals"
        print(f"  {src}: machine parameters {np.mean(z[:, :7] <= 3):.4f}, placement "
              f"{np.mean(z[:, 7:] <= 3):.4f}; {per}")


def sweep(rng: np.random.Generator, values: list[float], machines: int, *,
          noise: bool) -> tuple[np.ndarray, np.ndarray]:
    before = np.zeros((len(values), machines))
    after = np.zeros_like(before)
    base = pattern_steps(30)
    for i, v in enumerate(values):
        steps = base if noise else pattern_steps(int(v))
        sigma = v if noise else 0.05
        for j in range(machines):
            before[i, j], after[i, j], _, _ = trial(rng, steps, sigma)
        label = f"σ = {v:g} mm" if noise else f"{int(v)} marks"
        print(f"  {label:>14}: after max median {np.median(after[i]):.3f} mm, 90 % "
              f"{np.percentile(after[i], 90):.3f} mm, on target (≤ 0.1) "
              f"{np.mean(after[i] <= 0.1):.0%}; before median {np.median(before[i]):.3f} mm")
    return before, after


def check_map(rng: np.random.Generator, steps: np.ndarray) -> None:
    """The `calibrate check` map for one typical true machine, as the docs show it."""
    true = random_truth(rng)
    err = np.full(REGION.mask.shape, np.nan)
    err[REGION.mask] = shape_errors(true, NOMINAL, REGION.points(), MODE, ASM)
    centres = NOMINAL.pen_points(steps, Q, ASM)
    draw_error_map(ErrorMap(REGION.xs, REGION.ys, err, MODE), IMG / "calib_check.png",
                   "predicted drawing-shape error of the uncalibrated default profile\n"
                   "(a random true machine, ±0.5 mm / ±0.5°)", centres)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--machines", type=int, default=30)
    ap.add_argument("--coverage", type=int, default=300)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    steps = pattern_steps(30)
    section_cases(rng, steps)
    section_coverage(rng, steps, args.coverage)
    print(f"\n3. max shape error against measurement noise ({args.machines} machines each)")
    noise = [0.01, 0.02, 0.05, 0.1, 0.2, 0.5]
    b, a = sweep(rng, noise, args.machines, noise=True)
    IMG.mkdir(parents=True, exist_ok=True)
    draw_sweep(noise, b, a, IMG / "calib_noise.png", "measurement noise σ per coordinate, mm",
               "fitted shape error vs measurement noise (30 marks)", logx=True)
    print(f"\n4. max shape error against the number of marks (σ = 0.05 mm, {args.machines} "
          "machines each)")
    counts = [10.0, 15.0, 20.0, 30.0, 40.0, 50.0, 60.0]
    b, a = sweep(rng, counts, args.machines, noise=False)
    draw_sweep(counts, b, a, IMG / "calib_marks.png", "number of marks",
               "fitted shape error vs number of marks (σ = 0.05 mm)")
    check_map(rng, steps)
    print(f"\ncharts: {IMG / 'calib_noise.png'}, {IMG / 'calib_marks.png'}, "
          f"{IMG / 'calib_check.png'}")


if __name__ == "__main__":
    main()
