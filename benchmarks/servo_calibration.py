"""Servo calibration accuracy: the calibration pattern's max shape error on a simulated true
servo five-bar, uncalibrated vs calibrated (issue 38's goal: calibrated ≤ 0.5 mm with 0.1 mm
measurement noise), and the honesty of the reported uncertainties.

True machines: configs/plotclock.toml's geometry with every length off by up to ±0.5 mm,
each servo's curve non-linear (the profile's line plus up to ±3° of quadratic and cubic
bow and a ripple ±r·sin(πu), r ≤ --ripple (default 0.25°), that no polynomial models
exactly) and a 1° dead band on both servos, each servo's offset off by up to ±2°.

The pattern: `pattern_points` marks (8° inside the joint limits), each approached per joint
from the side `approach_signs` gives, measured in a random paper frame with Gaussian noise
σ per coordinate. With --rounds 2 (the default, `fivebar calibrate pattern --second-round`)
the --marks are two rounds of half as many ticks: the first drawn with the pulses the
*profile* commands, fitted (cubic curves); the same ticks drawn again on a second sheet
(its own placement and noise) with the pulses that first fit commands; both rounds fitted
together (`calibrate fit --also`) from the first fit. The profile's curves are off by up to
~20° at the ends of the range, so the first round's pulses miss by up to ~250 µs those the
truth needs for the pattern's own marks there: a single round (--rounds 1, all ticks drawn
by the profile) leaves the fit to extrapolate, which is where its worst errors were, whatever
the curve's order; the second round measures those pulses. The curves' orders: chosen by
the fit (BIC, `kinematics.servo_calibration`) or fixed by --orders.

The shape error is evaluated on the profile's pattern of --marks marks (those every model
reaches within 500–2500 µs): each model commands the pulses that under it draw each mark
(kinematics.servo_calibration.commanded_pulses) and the true machine draws them; max
|aligned drawn − intended|. The machines, the first sheet and its noise are drawn as for
one round, so every setting sees the same machines (`--rounds 1 --orders 3` is the cubic
single round this benchmark measured before).

Prints, per true machine: max shape error uncalibrated (the profile as it is), calibrated
with the dead band ignored (fixed at 0, cubic curves), and calibrated; then the coverage (the
fraction of true curve angles over the measured pulses and dead bands within 3 reported σ).

Run: PYTHONPATH=. python benchmarks/servo_calibration.py [--machines 20] [--marks 60]
     [--sigma 0.1] [--ripple 0.25] [--rounds 2] [--orders bic]
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).parent.resolve()]
from fivebar_host.config import load_profile  # noqa: E402
from kinematics.calibration import CalibrationError, rigid_fit, rotation  # noqa: E402
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
        co[:, 2:4] += np.radians(rng.uniform(-3.0, 3.0, (2, 2)))
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


def pattern(model: ServoMachine, n: int) -> np.ndarray:
    """The pattern's `n` mark centres laid out by `model`, 8° inside the joint limits (the
    true curve differs)."""
    inset = math.radians(8.0)
    lim = tuple((lo + inset, hi - inset) for lo, hi in PROFILE.motors.limits_rad)
    return pattern_points(model, MODE, ASM, lim, (math.radians(15), math.radians(20)), n)


def draw_round(truth: Truth, model: ServoMachine, pts: np.ndarray, place: np.ndarray,
               noise: np.ndarray, sheet: int) -> ServoMarks:
    """One round of the pattern: ticks ending on `pts` (n, 2), commanded by `model`, drawn by
    the truth on a sheet placed at `place` (φ, tx, ty), measured with `noise` (n, 2) mm; the
    marks the truth cannot draw (or the model not command) are not on the paper."""
    s = approach_signs(pts.shape[0])
    pulses = np.full_like(pts, np.nan)
    can = model.fivebar().inverse_batch(pts, MODE).valid
    pulses[can] = commanded_pulses(model, pts[can], s[can], MODE)
    c, sn = math.cos(place[0]), math.sin(place[0])
    y = truth.pen_points(pulses, s) @ np.array([[c, -sn], [sn, c]]).T + place[1:] + noise
    ok = np.isfinite(y).all(axis=1) & np.isfinite(pulses).all(axis=1)
    return ServoMarks(pulses[ok], s[ok], y[ok], ASM, np.full(int(ok.sum()), sheet))


def join(a: ServoMarks, b: ServoMarks) -> ServoMarks:
    """The marks of two rounds, each on its own sheet."""
    sheet = np.concatenate((a.sheet_of(), b.sheet_of()))
    return ServoMarks(*(np.concatenate((getattr(a, f), getattr(b, f)))
                        for f in ("pulses", "approach", "measured")), ASM, sheet)


def trial(rng: np.random.Generator, base: ServoMachine, marks: int, sigma: float,
          ripple_deg: float, rounds: int, orders: tuple[int, int] | None, seed: int,
          case: int) -> tuple[float, float, float, float]:
    """(uncalibrated, dead band ignored, calibrated) max mm and the coverage fraction. The
    true machine, the first sheet's placement and noise come from `rng` as for one round of
    `marks` ticks (so every setting sees the same machines); a second round's sheet from
    a generator of its own (seed, case)."""
    truth = Truth(rng, base, ripple_deg)
    place = np.array([rng.uniform(-math.pi, math.pi), *rng.uniform(-100, 100, 2)])
    noise = rng.normal(0.0, sigma, (marks, 2))
    first = marks if rounds == 1 else marks // 2
    marks_1 = pattern(base, first)
    data = draw_round(truth, base, marks_1, place, noise[:first], 0)
    start, start_ign = base, with_dead_band(base, (0.0, 0.0))
    if rounds == 2:  # the second half laid out and commanded by the first half's fit
        f1 = fit_servo(base, data, sigma=sigma, orders=(3, 3))
        # the fits of both rounds start from the first round's (its --config)
        start = f1.machine
        start_ign = fit_servo(start_ign, data, sigma=sigma, fit_dead_band=False,
                              orders=(3, 3)).machine
        r2 = np.random.default_rng([seed, case])
        place2 = np.array([r2.uniform(-math.pi, math.pi), *r2.uniform(-100, 100, 2)])
        data = join(data, draw_round(truth, f1.machine, marks_1, place2,
                                     r2.normal(0.0, sigma, (first, 2)), 1))
    fit = fit_servo(start, data, sigma=sigma, orders=orders)
    try:
        ign = fit_servo(start_ign, data, sigma=sigma, fit_dead_band=False, orders=(3, 3))
    except CalibrationError:  # it cannot reach the second round's pulses: from the other fit
        ign = fit_servo(with_dead_band(start, (0.0, 0.0)), data, sigma=sigma,
                        fit_dead_band=False, orders=(3, 3))
    # the shape error on the profile's pattern of `marks` ticks (one round's), the marks
    # every model reaches within 500–2500 µs (the edge moves)
    pts = pattern(base, marks)
    ss = approach_signs(marks)
    ok = np.isfinite(truth.pen_points(commanded_pulses(base, pts, ss, MODE), ss)).all(axis=1)
    for m in (base, ign.machine, fit.machine):
        ok &= m.fivebar().inverse_batch(pts, MODE).valid
        pc = commanded_pulses(m, pts[ok], ss[ok], MODE)
        ok[ok] = ((pc > 500.0) & (pc < 2500.0)).all(axis=1)  # inside the pulse range
    errs = [shape_error(truth, m, pts[ok], ss[ok]) for m in (base, ign.machine, fit.machine)]
    # coverage: the true curve (polynomial + ripple) over the measured pulses, the dead bands
    z = []
    for k in range(2):
        p = np.linspace(data.pulses[:, k].min(), data.pulses[:, k].max(), 9)
        pp = np.stack((p, p), axis=1)
        tru = truth.m.curve_angles(pp)[:, k] + truth.ripple[k] * np.sin(
            math.pi * (p - 1500.0) / PULSE_SCALE_US)
        z.extend(np.abs(fit.machine.curve_angles(pp)[:, k] - tru) / fit.curve_std(k, p))
    z.extend(np.abs(fit.dead_band - truth.m.dead_band) / fit.dead_band_std)
    return errs[0], errs[1], errs[2], float(np.mean(np.array(z) <= 3.0))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--machines", type=int, default=20)
    ap.add_argument("--marks", type=int, default=60)
    ap.add_argument("--sigma", type=float, default=0.1)
    ap.add_argument("--ripple", type=float, default=0.25,
                    help="amplitude bound (°) of the true curves' non-cubic ripple")
    ap.add_argument("--rounds", type=int, choices=(1, 2), default=2,
                    help="the ticks in one round laid out by the profile, or in two: the "
                    "second half laid out and commanded by the first half's fit")
    ap.add_argument("--orders", default="bic",
                    help="the curves' orders: 'bic' (chosen from the marks) or one order")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    base = nominal()
    orders = None if args.orders == "bic" else (int(args.orders), int(args.orders))
    print(f"servo calibration on configs/plotclock.toml: {args.marks} marks, σ = "
          f"{args.sigma:g} mm, true dead band 1° both servos, non-linear true curves (ripple "
          f"≤ {args.ripple:g}°)")
    print(f"{'case':>4} {'uncalibrated':>13} {'dead band ignored':>18} {'calibrated':>11} "
          f"{'within 3σ':>10}")
    rows = []
    for k in range(args.machines):
        row = trial(rng, base, args.marks, args.sigma, args.ripple, args.rounds, orders,
                    args.seed, k)
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
