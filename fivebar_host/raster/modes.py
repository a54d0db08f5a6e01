"""Image modes: darkness per pixel → laser power per pixel (0–255), as LightBurn and
LaserGRBL users know them.

* ``grayscale``: power = P_min + (P_max − P_min) · d^γ for darkness d > 0, 0 where d = 0
  (white is never burned, whatever `--power-min`); γ > 1 keeps light tones lighter.
* ``threshold``: P_max where d ≥ the threshold, else 0.
* ``floyd``, ``jarvis``, ``stucki``, ``atkinson``: error diffusion (`raster.dither`),
  P_max where a pixel burns, else 0.
* ``bayer``: ordered dithering with the 8 × 8 Bayer matrix, likewise.

`negative` inverts darkness first (d → 1 − d): a dark photo burned on dark material.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fivebar_host.errors import OptionError
from fivebar_host.raster import dither
from kinematics.arrays import FloatArray

MODES = ("grayscale", "threshold", "floyd", "jarvis", "stucki", "atkinson", "bayer")


@dataclass(frozen=True)
class ImageMode:
    """How darkness becomes power (module docstring)."""

    mode: str = "grayscale"
    power_min: int = 0
    power_max: int = 255
    gamma: float = 1.0
    threshold: float = 0.5
    negative: bool = False

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise OptionError("--image-mode", f"{self.mode!r} is not one of {', '.join(MODES)}")
        if not 0 <= self.power_min <= self.power_max <= 255:
            raise OptionError("--power-min", f"{self.power_min}…{self.power_max} must satisfy "
                              "0 ≤ --power-min ≤ --power-max ≤ 255")
        if not 0.05 <= self.gamma <= 20.0:
            raise OptionError("--gamma", f"{self.gamma:g} is outside 0.05…20")
        if not 0.0 < self.threshold <= 1.0:
            raise OptionError("--threshold", f"{self.threshold:g} is outside (0, 1]")


def to_powers(dark: FloatArray, im: ImageMode) -> NDArray[np.uint8]:
    """Laser power (H, W) uint8 per pixel of darkness (H, W) in [0, 1]."""
    d = np.clip(np.asarray(dark, dtype=np.float64), 0.0, 1.0)
    if im.negative:
        d = 1.0 - d
    if im.mode == "grayscale":
        span = im.power_max - im.power_min
        p = np.rint(im.power_min + span * np.power(d, im.gamma))
        return np.where(d > 0.0, p, 0.0).astype(np.uint8)
    if im.mode == "threshold":
        on = d >= im.threshold
    elif im.mode == "bayer":
        on = dither.ordered(d)
    else:
        on = dither.diffuse(d, dither.KERNELS[im.mode])
    return np.where(on, im.power_max, 0).astype(np.uint8)
