"""Servo calibration accuracy: the calibration pattern's max shape error on a simulated true
servo five-bar, uncalibrated vs calibrated (issue 38's goal: calibrated ≤ 0.5 mm with 0.1 mm
measurement noise), and the honesty of the reported uncertainties.

True machines: configs/plotclock.toml's geometry with every length off by up to ±0.5 mm,
each servo's curve non-linear (the profile's line plus up to ±3° of quadratic and cubic
bow and a ripple ±r·sin(πu), r ≤ --ripple (default 0.25°), that no cubic models exactly)
and a 1° dead band on both servos, each servo's offset off by up to ±2°. The pattern:
`pattern_points` marks (8° inside the joint limits), each approached per joint from the side
`approach_signs` gives, drawn with the pulses the *profile* commands, measured in a random
paper frame with Gaussian noise σ per coordinate. The shape error is evaluated on the
pattern's marks (those every model reaches within 500–2500 µs): each model commands the
pulses that under it draw each mark (kinematics.servo_calibration.commanded_pulses) and the
true machine draws them; max |aligned drawn − intended|.

Prints, per true machine: max shape error uncalibrated (the profile as it is), calibrated
with the dead band ignored (fixed at 0), and calibrated; then the coverage (the fraction of
true curve angles and dead bands within 3 reported σ).

Run: PYTHONPATH=. python benchmarks/servo_calibration.py [--machines 20] [--marks 60]
     [--sigma 0.1] [--ripple 0.25]
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).parent.resolve()]
from fivebar_host.config import load_profile  # noqa: E402
from kinematics.calibration import rigid_fit, rotation  # noqa: E402
from kinematics.servo_calibration import (  # noqa: E402
    PULSE_SCALE_US,
    ServoMachine,
    ServoMarks,
    approach_signs,
    commanded_pulses,
    fit_servo,
    pattern_points,
    with_dead_band,
)

PROFILE = load_profile(Path(__file__).resolve().parent.parent / "configs" / "plotclock.toml")
MODE = PROFILE.kinematics.working_mode
ASM = PROFILE.kinematics.assembly


def nominal() -> ServoMachine:
    """The profile's servo machine (its curves as cubics, its dead band)."""
    j = PROFILE.joints
    assert j is not None
    curves = (j.joints[0].curve, j.joints[1].curve)
    return ServoMachine.from_curves(PROFILE.geometry, curves,  # type: ignore[arg-type]
                                    (j.joints[0].dead_band_rad, j.joints[1].dead_band_rad),
                                    (1500.0, 1500.0))


class Truth:
    """A true machine: a `ServoMachine` for the geometry and dead band, with a curve that is
    the cubic plus a ripple (so the fitted cubic is a model, not the truth)."""

    def __init__(self, rng: np.random.Generator, base: ServoMachine, ripple_deg: float
                 ) -> None:
        g = np.array(base.geometry)
        g[:5] += rng.uniform(-0.5, 0.5, 5)
        co = base.coeffs.copy()
        co[:, 0] += np.radians(rng.uniform(-2.0, 2.0, 2))
        co[:, 2:] += np.radians(rng.uniform(-3.0, 3.0, (2, 2)))
        self.ripple = np.radians(rng.uniform(-ripple_deg, ripple_deg, 2))
        self.m = ServoMachine(tuple(g), co, base.centre_us, (math.radians(1.0),) * 2)

    def pen_points(self, pulses: np.ndarray, approach: np.ndarray) -> np.ndarray:
        u = (pulses - np.asarray(self.m.centre_us)) / PULSE_SCALE_US
        th = self.m.angles(pulses, approach) + self.ripple * np.sin(math.pi * u)
        fwd = self.m.fivebar().forward_batch(th, ASM)
        pts = np.asarray(fwd.points).copy()
        pts[~fwd.valid] = np.nan
        return pts


def shape_error(truth: Truth, model: ServoMachine, pts: np.ndarray, s: np.ndarray) -> float:
    """Max shape error (mm) when `model` draws `pts` with approaches `s` on `truth`."""
    drawn = truth.pen_points(commanded_pulses(model, pts, s, MODE), s)
    phi, t = rigid_fit(drawn, pts)
    return float(np.max(np.linalg.norm(drawn @ rotation(phi).T + t - pts, axis=1)))


def trial(rng: np.random.Generator, base: ServoMachine, marks: int, sigma: float,
          ripple_deg: float) -> tuple[float, float, float, float]:
    """(uncalibrated, dead band ignored, calibrated) max mm and the coverage fraction."""
    truth = Truth(rng, base, ripple_deg)
    inset = math.radians(8.0)  # the pattern stays inside the limits (the true curve differs)
    lim = tuple((lo + inset, hi - inset) for lo, hi in PROFILE.motors.limits_rad)
    pts = pattern_points(base, MODE, ASM, lim, (math.radians(15), math.radians(20)), marks)
    mk = pts
    s = approach_signs(marks)
    pulses = commanded_pulses(base, mk, s, MODE)
    place = np.array([rng.uniform(-math.pi, math.pi), *rng.uniform(-100, 100, 2)])
    c, sn = math.cos(place[0]), math.sin(place[0])
    y = truth.pen_points(pulses, s) @ np.array([[c, -sn], [sn, c]]).T + place[1:]
    y = y + rng.normal(0.0, sigma, y.shape)
    drawn = np.isfinite(y).all(axis=1)  # a mark this true machine cannot draw: none on paper
    data = ServoMarks(pulses[drawn], s[drawn], y[drawn], ASM)
    fit = fit_servo(base, data, sigma=sigma)
    ign = fit_servo(with_dead_band(base, (0.0, 0.0)), data, sigma=sigma, fit_dead_band=False)
    pts, ss = mk[drawn], data.approach
    ok = np.ones(pts.shape[0], dtype=bool)  # marks every model reaches (the edge moves)
    for m in (base, ign.machine, fit.machine):
        ok &= m.fivebar().inverse_batch(pts, MODE).valid
        pc = commanded_pulses(m, pts[ok], ss[ok], MODE)
        ok[ok] = ((pc > 500.0) & (pc < 2500.0)).all(axis=1)  # inside the pulse range
    errs = [shape_error(truth, m, pts[ok], ss[ok]) for m in (base, ign.machine, fit.machine)]
    # coverage: the true curve (cubic + ripple) at the pattern's pulses, and the dead bands
    z = []
    for k in range(2):
        p = np.linspace(data.pulses[:, k].min(), data.pulses[:, k].max(), 9)
        pp = np.stack((p, p), axis=1)
        tru = truth.m.curve_angles(pp)[:, k] + truth.ripple[k] * np.sin(
            math.pi * (p - 1500.0) / PULSE_SCALE_US)
        z.extend(np.abs(fit.machine.curve_angles(pp)[:, k] - tru) / fit.curve_std(k, p))
    z.extend(np.abs(fit.x[15:17] - truth.m.dead_band) / fit.std[15:17])
    return errs[0], errs[1], errs[2], float(np.mean(np.array(z) <= 3.0))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--machines", type=int, default=20)
    ap.add_argument("--marks", type=int, default=60)
    ap.add_argument("--sigma", type=float, default=0.1)
    ap.add_argument("--ripple", type=float, default=0.25,
                    help="amplitude bound (°) of the true curves' non-cubic ripple")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    base = nominal()
    print(f"servo calibration on configs/plotclock.toml: {args.marks} marks, σ = "
          f"{args.sigma:g} mm, true dead band 1° both servos, non-linear true curves (ripple "
          f"≤ {args.ripple:g}°)")
    print(f"{'case':>4} {'uncalibrated':>13} {'dead band ignored':>18} {'calibrated':>11} "
          f"{'within 3σ':>10}")
    rows = []
    for k in range(args.machines):
        row = trial(rng, base, args.marks, args.sigma, args.ripple)
        rows.append(row)
        print(f"{k + 1:>4} {row[0]:13.3f} {row[1]:18.3f} {row[2]:11.3f} {row[3]:10.2f}")
    a = np.array(rows)
    for name, f in (("median", np.median), ("max", np.max)):
        print(f"{name} over machines: uncalibrated {f(a[:, 0]):.3f} mm, dead band ignored "
              f"{f(a[:, 1]):.3f} mm, calibrated {f(a[:, 2]):.3f} mm (goal ≤ 0.5 mm)")
    print(f"calibrated ≤ 0.5 mm on {np.mean(a[:, 2] <= 0.5):.0%} of the machines; coverage "
          f"(true curve angles and dead bands within 3 reported σ) {a[:, 3].mean():.3f}")


if __name__ == "__main__":
    main()
