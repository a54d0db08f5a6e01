"""Hobby-servo joints: the pulse ↔ angle curve of one servo and its dead band (pure numpy).

A hobby servo turns to an angle set by the width of a pulse repeated every refresh period.
The relation is not a straight line (BrachioGraph issue 29, Plotclock's per-servo factors):
`ServoCurve` holds it as a strictly monotone table of (pulse µs, joint angle rad), measured
or sampled from a low-order least-squares fit, and maps both ways by piecewise-linear
interpolation (exact on the table's nodes). A servo also has a dead band: its output stops
short of the command by up to half the band, on the side it came from — a hysteresis
("play") of width w in angle:

    out_k = clip(out_{k−1}, cmd_k − w/2, cmd_k + w/2)                            (S1)

`dead_band_commands` plans commands that put the output on the targets under S1: each
target is overshot by w/2 in the direction the joint last moved (the servo analogue of the
stepper's backlash take-up, fivebar_host/compile/backlash.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from kinematics.arrays import FloatArray
from kinematics.errors import FivebarError

__all__ = ["PULSE_QUANTUM_US", "ServoCurve", "ServoError", "dead_band_commands", "hysteresis",
           "quantise_us"]

#: The pulse resolution the servo firmware is to drive at (issue 38: 0.5 µs).
PULSE_QUANTUM_US = 0.5


class ServoError(FivebarError, ValueError):
    """A servo curve that cannot be used, or an angle outside a servo's range."""


def quantise_us(pulse_us: ArrayLike, quantum: float = PULSE_QUANTUM_US) -> FloatArray:
    """Pulse widths rounded to the nearest multiple of `quantum` µs."""
    return np.asarray(np.rint(np.asarray(pulse_us, dtype=np.float64) / quantum) * quantum)


@dataclass(frozen=True, eq=False)
class ServoCurve:
    """Pulse ↔ angle of one servo: a table of pulses (µs, ascending) and the joint angles
    (rad, strictly monotone: increasing when a longer pulse turns the joint
    counter-clockwise, decreasing otherwise) reached there."""

    pulse_us: FloatArray
    angle_rad: FloatArray

    def __post_init__(self) -> None:
        p = np.asarray(self.pulse_us, dtype=np.float64).ravel()
        a = np.asarray(self.angle_rad, dtype=np.float64).ravel()
        if p.shape != a.shape or p.size < 2:
            raise ServoError("a servo curve needs at least two (pulse, angle) pairs of "
                             "equal count")
        if not (np.isfinite(p).all() and np.isfinite(a).all()):
            raise ServoError("a servo curve's pulses and angles must be finite")
        if not (np.diff(p) > 0).all():
            raise ServoError("a servo curve's pulses must ascend strictly")
        da = np.diff(a)
        if not ((da > 0).all() or (da < 0).all()):
            raise ServoError("a servo curve's angles must be strictly monotone in the pulse "
                             "(a servo that turns back as the pulse grows cannot be driven)")
        object.__setattr__(self, "pulse_us", p)
        object.__setattr__(self, "angle_rad", a)

    @classmethod
    def linear(cls, centre_us: float, centre_rad: float, us_per_rad: float,
               range_us: tuple[float, float]) -> ServoCurve:
        """The straight line through (centre_us, centre_rad) with slope 1/us_per_rad (signed:
        negative when a longer pulse turns the joint clockwise), over `range_us`."""
        lo, hi = range_us
        if us_per_rad == 0.0:
            raise ServoError("a servo's µs per degree must not be 0")
        p = np.array([lo, hi], dtype=np.float64)
        return cls(p, centre_rad + (p - centre_us) / us_per_rad)

    @classmethod
    def fit(cls, pulse_us: ArrayLike, angle_rad: ArrayLike, degree: int = 3,
            samples: int = 65) -> ServoCurve:
        """A least-squares polynomial of `degree` through measured (pulse, angle) pairs,
        sampled at `samples` pulses over the measured range (it must stay monotone there)."""
        p = np.asarray(pulse_us, dtype=np.float64).ravel()
        a = np.asarray(angle_rad, dtype=np.float64).ravel()
        if p.size <= degree:
            raise ServoError(f"a degree-{degree} fit needs more than {degree} measurements; "
                             f"got {p.size}")
        poly = np.polynomial.Polynomial.fit(p, a, degree)
        ps = np.linspace(p.min(), p.max(), samples)
        return cls(ps, poly(ps))

    @property
    def range_us(self) -> tuple[float, float]:
        """The pulses the curve covers, µs."""
        return float(self.pulse_us[0]), float(self.pulse_us[-1])

    @property
    def range_rad(self) -> tuple[float, float]:
        """The joint angles the curve covers (low, high), rad."""
        a = self.angle_rad
        return float(min(a[0], a[-1])), float(max(a[0], a[-1]))

    def angle(self, pulse_us: ArrayLike) -> FloatArray:
        """Joint angles (rad) of pulses (µs) inside the curve's range (piecewise linear)."""
        p = np.asarray(pulse_us, dtype=np.float64)
        lo, hi = self.range_us
        if ((p < lo) | (p > hi)).any():
            raise ServoError(f"pulse outside the servo's range [{lo:g}, {hi:g}] µs")
        return np.asarray(np.interp(p, self.pulse_us, self.angle_rad))

    def pulse(self, angle_rad: ArrayLike) -> FloatArray:
        """Pulses (µs) that reach joint angles (rad) inside the curve's range: the exact
        inverse of `angle` (piecewise linear between the same nodes)."""
        a = np.asarray(angle_rad, dtype=np.float64)
        lo, hi = self.range_rad
        tol = 1e-12 * max(1.0, abs(lo), abs(hi))
        if ((a < lo - tol) | (a > hi + tol)).any():
            bad = float(a[(a < lo - tol) | (a > hi + tol)].ravel()[0])
            raise ServoError(f"joint angle {math.degrees(bad):.3f}° outside the servo's range "
                             f"[{math.degrees(lo):.3f}°, {math.degrees(hi):.3f}°]")
        if self.angle_rad[0] < self.angle_rad[-1]:
            return np.asarray(np.interp(a, self.angle_rad, self.pulse_us))
        return np.asarray(np.interp(a, self.angle_rad[::-1], self.pulse_us[::-1]))


def hysteresis(commands: ArrayLike, width: float, start: float | None = None) -> FloatArray:
    """Output angles (N,) of a joint with a dead band of `width` rad driven through the
    commands (N,) in order (Eq. S1); `start` is the output before the first command
    (default: the first command)."""
    c = np.asarray(commands, dtype=np.float64).ravel()
    out = np.empty_like(c)
    if not c.size:
        return out
    h = 0.5 * width
    o = float(c[0]) if start is None else float(start)
    for k, ck in enumerate(c.tolist()):  # sequential: one pass
        o = min(max(o, ck - h), ck + h)
        out[k] = o
    return out


def dead_band_commands(targets: ArrayLike, width: float, start: float | None = None
                       ) -> FloatArray:
    """Commands (N,) that put a joint with a dead band of `width` rad on the targets (N,)
    under Eq. S1: each target overshot by width/2 in the direction of the move into it (the
    last direction where the target repeats). The output starts at `start` (default: the
    first target) and, before any move, the first command is the target itself."""
    t = np.asarray(targets, dtype=np.float64).ravel()
    if not t.size:
        return t.copy()
    s = np.sign(np.diff(np.concatenate(([t[0] if start is None else start], t))))
    moved = np.flatnonzero(s != 0)
    last = np.full(t.size, -1, dtype=np.int64)
    last[moved] = moved
    last = np.maximum.accumulate(last)
    d = np.where(last >= 0, s[np.maximum(last, 0)], 0.0)
    return np.asarray(t + 0.5 * width * d)
