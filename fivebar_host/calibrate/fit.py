"""`fivebar calibrate fit`: the fit of the machine's real numbers, its report, fitted.toml.

Runs `kinematics.calibration.fit` on the measured marks and makes it safe to use:

- a measuring frame with y down (a scan's pixel rows) is a mirror image of the paper; it is
  noticed (the mirrored rigid fit of the profile's marks is far better) and y is negated;
- outliers: marks whose externally studentized residual exceeds 4 (`calibration_analysis`)
  are flagged and the fit is repeated without them (up to three rounds, never below the
  minimum number of marks): a robust refit, so one mis-read mark cannot bend the result;
- the report prints every parameter with its 1σ (and where σ came from: the measurement σ
  the user gave, or the residual standard deviation), the residual per mark before (profile,
  best placement) and after, the weakly determined combinations (`weak_combinations`) and
  what matters: the predicted drawing-shape error of the old profile and the fitted
  profile's own 1σ over the pattern's region;
- fitted.toml is the original profile text with the five lengths and home_deg replaced in
  place (comments and other keys kept) and a comment on top saying where they came from; it
  is parsed back before it is written. A fit that fails writes nothing.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fivebar_host.calibrate.measure import Measured, MeasurementError, PatternMarks
from fivebar_host.calibrate.pattern import nominal_params, pattern_region
from fivebar_host.compile import write_atomic
from fivebar_host.config import ConfigError, Profile, parse_profile
from kinematics.arrays import BoolArray, FloatArray
from kinematics.calibration import (
    MIN_MARKS,
    PARAM_NAMES,
    CalibrationError,
    FitResult,
    MachineParams,
    MarkData,
    fit,
    initial_guess,
    model_points,
    rigid_fit,
    rotation,
)
from kinematics.calibration_analysis import (
    OUTLIER_T,
    Combination,
    condition_number,
    predicted_shape_std,
    shape_errors,
    studentized,
    weak_combinations,
)

MAX_ROUNDS = 3
#: A weak combination is warned about when its 1σ exceeds this (mm).
WARN_STD_MM = 0.1


@dataclass(frozen=True)
class Calibration:
    """A finished calibration: the fit (on the kept marks), which marks were kept, the
    studentized residual and model residual (N, 2) of every measured mark, and the
    analysis."""

    result: FitResult
    measured: Measured
    kept: BoolArray
    t_stat: FloatArray
    residual_all: FloatArray
    before_all: FloatArray
    mirrored: bool
    combos: list[Combination]
    condition: float
    old_shape_mm: FloatArray  # old profile's shape error over the region (fitted = truth)
    fitted_std_mm: FloatArray  # the fitted profile's own 1σ over the region

    @property
    def outliers(self) -> list[int]:
        return [int(i) for i in self.measured.ids[~self.kept]]


def _mark_data(pattern: PatternMarks, xy: FloatArray, idx: np.ndarray) -> MarkData:
    return MarkData(pattern.steps[idx].astype(np.float64), xy,
                    2.0 * math.pi / pattern.steps_per_rev, pattern.assembly)


def _is_mirrored(nominal: MachineParams, data: MarkData) -> bool:
    """True when the measured marks match the profile's far better mirrored (y down)."""
    p = nominal.pen_points(data.steps, data.rad_per_step, data.assembly)

    def rms(y: FloatArray) -> float:
        phi, t = rigid_fit(p, y)
        return float(np.sqrt(np.mean(np.sum((p @ rotation(phi).T + t - y) ** 2, axis=1))))

    flipped = data.measured * np.array([1.0, -1.0])
    return rms(flipped) < 0.25 * rms(data.measured)


def _robust_fit(nominal: MachineParams, pattern: PatternMarks, xy: FloatArray,
                measured: Measured, sigma: float | None,
                max_iterations: int) -> tuple[FitResult, BoolArray, FloatArray]:
    """Fit, flag marks with t > OUTLIER_T, refit without them (module doc)."""
    kept = np.ones(measured.ids.size, dtype=bool)
    for _ in range(MAX_ROUNDS):
        res = fit(nominal, _mark_data(pattern, xy[kept], measured.index[kept]), sigma=sigma,
                  max_iterations=max_iterations)
        t = np.full(kept.size, np.nan)
        t[kept] = studentized(res)
        bad = kept & (t > OUTLIER_T)
        if not bad.any() or kept.sum() - bad.sum() < MIN_MARKS:
            return res, kept, t
        kept &= ~bad
    return res, kept, t


def calibrate(profile: Profile, pattern: PatternMarks, measured: Measured, *,
              sigma: float | None = None, max_iterations: int = 100) -> Calibration:
    """The whole fit with its analysis (module doc). Raises CalibrationError."""
    if abs(pattern.steps_per_rev - profile.motors.steps_per_rev) > 1e-9:
        raise MeasurementError(f"{pattern.source}: made for {pattern.steps_per_rev:g} steps "
                               f"per revolution, the profile {profile.source} has "
                               f"{profile.motors.steps_per_rev:g}")
    if pattern.assembly != profile.kinematics.assembly:
        raise MeasurementError(f"{pattern.source}: made for assembly {pattern.assembly}, the "
                               f"profile {profile.source} is {profile.kinematics.assembly}")
    nominal = nominal_params(profile)
    mirrored = _is_mirrored(nominal, _mark_data(pattern, measured.xy, measured.index))
    xy = measured.xy * np.array([1.0, -1.0]) if mirrored else measured.xy
    res, kept, t = _robust_fit(nominal, pattern, xy, measured, sigma, max_iterations)
    all_data = _mark_data(pattern, xy, measured.index)
    resid = model_points(res.x, all_data) - xy
    before = model_points(initial_guess(nominal, _mark_data(pattern, xy[kept],
                                                            measured.index[kept])),
                          all_data) - xy
    region = pattern_region(profile, pattern.mode).points()[::2]
    old = shape_errors(res.machine, nominal, region, pattern.mode, pattern.assembly)
    std = predicted_shape_std(res, region, pattern.mode, pattern.assembly)
    return Calibration(res, measured, kept, t, resid, before, mirrored,
                       weak_combinations(res), condition_number(res), old, std)


# ----------------------------------------------------------------- the report
def _param_lines(cal: Calibration, profile: Profile) -> list[str]:
    res = cal.result
    nom = nominal_params(profile).vector()
    lines = [f"{'parameter':<10}{'profile':>12}{'fitted':>12}{'± 1σ':>10}{'change':>10}"]
    for i, name in enumerate(PARAM_NAMES[:7]):
        ang = name.startswith("h")
        f = math.degrees if ang else float
        unit = "°" if ang else "mm"
        label = f"home{name[1]}" if ang else name
        lines.append(f"{label + ' ' + unit:<10}{f(nom[i]):>12.4f}{f(res.x[i]):>12.4f}"
                     f"{f(res.std[i]):>10.4f}{f(res.x[i] - nom[i]):>+10.4f}")
    lines.append(f"paper: rotation {math.degrees(res.x[7]):.3f}° ± "
                 f"{math.degrees(res.std[7]):.3f}°, offset ({res.x[8]:.3f}, {res.x[9]:.3f}) mm")
    how = ("the measurement σ you gave" if res.sigma_source == "given"
           else "the residual standard deviation")
    lines.append(f"uncertainties: 1σ from the fit's covariance scaled by {how}, "
                 f"{res.sigma:.4f} mm ({res.dof} degrees of freedom)")
    return lines


def _mark_lines(cal: Calibration) -> list[str]:
    lines = [f"{'mark':>5}{'before mm':>11}{'after mm':>10}{'t':>7}"]
    for k, ident in enumerate(cal.measured.ids):
        b = float(np.hypot(*cal.before_all[k]))
        a = float(np.hypot(*cal.residual_all[k]))
        flag = "" if cal.kept[k] else "  OUTLIER: left out of the fit, measure it again"
        t = "" if not np.isfinite(cal.t_stat[k]) else f"{cal.t_stat[k]:.1f}"
        lines.append(f"{int(ident):>5}{b:>11.4f}{a:>10.4f}{t:>7}{flag}")
    return lines


def report_lines(cal: Calibration, profile: Profile) -> list[str]:
    """The text `fivebar calibrate fit` prints."""
    res = cal.result
    kept = int(cal.kept.sum())
    out = [f"fit of {kept} marks ({cal.measured.ids.size} measured) in {res.iterations} "
           f"iterations: rms residual {res.rms_before_mm:.4f} mm with the profile → "
           f"{res.rms_after_mm:.4f} mm fitted"]
    if cal.mirrored:
        out.append("note: the measured frame is mirrored (y down, as in a scan): y was negated")
    out += _param_lines(cal, profile)
    out += _mark_lines(cal)
    if cal.outliers:
        out.append(f"outliers (studentized residual > {OUTLIER_T:g}): marks "
                   f"{', '.join(map(str, cal.outliers))} — refitted without them")
    out.append(f"condition number of the scaled fit: {cal.condition:.0f}")
    weak = [c for c in cal.combos if c.std_mm > WARN_STD_MM]
    if weak:
        out.append("warning: the marks do not pin these combinations down (ill-conditioned), "
                   "so the single parameters above are uncertain:")
    else:
        out.append("least determined combinations:")
    out += [f"  {c.describe()} is determined only to ±{c.std_mm:.3f} mm (1σ)"
            for c in cal.combos]
    out.append("what matters is the drawing, over the pattern's region:")
    out.append(f"  old profile's drawing-shape error (fitted machine as truth): max "
               f"{np.nanmax(cal.old_shape_mm):.3f} mm, median "
               f"{np.nanmedian(cal.old_shape_mm):.3f} mm")
    out.append(f"  fitted profile's own uncertainty: max {np.nanmax(cal.fitted_std_mm):.3f} mm, "
               f"median {np.nanmedian(cal.fitted_std_mm):.3f} mm (1σ)")
    return out


# ----------------------------------------------------------------- fitted.toml
def replace_value(text: str, table: str, key: str, value: str) -> str:
    """Replace `key = …` inside `[table]` keeping the line's comment."""
    lines = text.splitlines(keepends=True)
    current = None
    pat = re.compile(rf"^(\s*{re.escape(key)}\s*=\s*)(.*?)(\s*(#.*)?)(\r?\n)?$")
    for i, line in enumerate(lines):
        head = re.match(r"^\s*\[([^\]]+)\]", line)
        if head:
            current = head.group(1).strip()
            continue
        m = pat.match(line)
        if current == table and m:
            comment = m.group(3) or ""
            pad = max(len(m.group(2)) - len(value), 0) if comment else 0
            lines[i] = f"{m.group(1)}{value}{' ' * pad}{comment}{m.group(5) or ''}"
            return "".join(lines)
    raise ConfigError(f"{table}.{key} not found in the profile text")


def fitted_profile_text(profile_text: str, m: MachineParams, note: str) -> str:
    """The profile text with [geometry] and [motors] home_deg replaced (module doc)."""
    text = profile_text
    for key in ("a1", "b1", "a2", "b2", "w"):
        text = replace_value(text, "geometry", key, f"{getattr(m, key):.4f}")
    home = f"[{math.degrees(m.home1):.5f}, {math.degrees(m.home2):.5f}]"
    text = replace_value(text, "motors", "home_deg", home)
    header = "".join(f"# {line}\n" for line in note.splitlines())
    return header + text


def write_fitted(path: Path, profile: Profile, cal: Calibration, note: str) -> Profile:
    """Write fitted.toml after parsing it back (it must be a valid profile)."""
    import tomllib

    src = Path(profile.source)
    text = fitted_profile_text(src.read_text(encoding="utf-8"), cal.result.machine, note)
    try:
        fitted = parse_profile(tomllib.loads(text), str(path))
    except (ConfigError, tomllib.TOMLDecodeError) as e:
        raise CalibrationError(f"the fitted values do not make a valid profile ({e}); "
                               "nothing was written") from e
    write_atomic(path, text)
    return fitted
