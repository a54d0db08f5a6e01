"""`fivebar calibrate check`: how wrong the old profile draws, taking the fitted one as true.

Over the safe region of the fitted profile's working mode (sampled every `pitch` mm), the
drawing-shape error of the old profile on the fitted machine
(`kinematics.calibration_analysis.shape_errors`: commanded by the old numbers, drawn by the
fitted ones, compared with the intended drawing after the best rigid alignment of the whole
region, since the paper may sit anywhere). The map is drawn by
`fivebar_host.report.calibration.draw_error_map`. Servo profiles map through their
pulse ↔ angle curves and dead bands instead (`servo_check`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fivebar_host.calibrate.pattern import nominal_params, pattern_mode
from fivebar_host.config import Profile
from kinematics.arrays import FloatArray
from kinematics.calibration_analysis import safe_grid, shape_errors


@dataclass(frozen=True)
class ErrorMap:
    """Shape error (ny, nx) mm on the grid xs (nx,), ys (ny,); NaN outside the region."""

    xs: FloatArray
    ys: FloatArray
    error_mm: FloatArray
    mode: str

    @property
    def max_mm(self) -> float:
        return float(np.nanmax(self.error_mm))

    @property
    def median_mm(self) -> float:
        return float(np.nanmedian(self.error_mm))


def error_map(fitted: Profile, old: Profile, mode: str | None = None,
              pitch_mm: float = 1.0) -> ErrorMap:
    """The old profile's predicted drawing-shape error over the fitted profile's safe
    region (module doc). Servo profiles: `servo_check.servo_error_map` (their curves and
    dead bands; both profiles must be servo ones)."""
    if fitted.joints is not None or old.joints is not None:
        from fivebar_host.calibrate.servo_check import servo_error_map

        return servo_error_map(fitted, old, mode, pitch_mm)
    m = pattern_mode(fitted, mode)
    k = fitted.kinematics
    true = nominal_params(fitted)
    grid = safe_grid(true, m, k.min_type1_margin_rad, k.min_type2_margin_rad,
                     fitted.motors.limits_rad, k.assembly, pitch_mm)
    err = np.full(grid.mask.shape, np.nan)
    err[grid.mask] = shape_errors(true, nominal_params(old), grid.points(), m, k.assembly)
    return ErrorMap(grid.xs, grid.ys, err, m)
