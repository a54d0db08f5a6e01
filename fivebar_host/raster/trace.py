"""An emulator pin trace (`fbsim -t`) as arrays, and the motion it records: the motors'
positions from their step edges and the pen by forward kinematics (`raster.dose` and
`raster.changes` build on it).

The motion is rebuilt from the step edges alone: a step of motor i at cycle t moves it from
k − 1 to k (signed by its direction pin), and the firmware's DDA puts step k of a constant-
rate segment at the time its continuous position n·t/C passes k − ½, so the motor's
position is the linear interpolation of (t, k − ½·dir) over its steps — the same model the
planner places the pixel boundaries on (`raster.pixels`); `raster.schedule` fits the exact
one (each segment's start from its edges).  The pen is forward kinematics of both motors'
positions at a time.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fivebar_host.compile.model import Job
from fivebar_host.compile.steps import step_angles
from fivebar_host.config import Profile
from fivebar_host.raster.runs import RasterRuns
from kinematics.arrays import FloatArray, IntArray

F_CPU = 16_000_000
#: The laser PWM's period in cycles (Timer2 at F_CPU / 256, config.h CFG_LASER_PWM_DIV 1).
PWM_PERIOD = 256

@dataclass(frozen=True)
class PinTrace:
    """A trace file's events as arrays (cycle, pin index, level), time ordered per pin."""

    cycle: IntArray
    level: IntArray
    pin: IntArray
    names: tuple[str, ...]
    start: tuple[int, int] = (0, 0)  # the motors' steps at the trace's start (its header)

    def of(self, name: str) -> tuple[IntArray, IntArray]:
        """(cycles, levels) of one pin."""
        if name not in self.names:
            z = np.zeros(0, dtype=np.int64)
            return z, z
        sel = self.pin == self.names.index(name)
        return self.cycle[sel], self.level[sel]


def read_pins(path: str | Path) -> PinTrace:
    """The trace file of `fbsim -t` (`<cycle> <pin> <level>` lines) as arrays."""
    text = Path(path).read_text(encoding="ascii")
    start = (0, 0)
    head = text[:text.find("\n")]
    for word in head.split() if head.startswith("#") else ():
        if word.startswith("start="):
            a, b = word[6:].split(",")
            start = (int(a), int(b))
    lines = [ln for ln in text.splitlines() if ln and not ln.startswith("#")]
    tok = " ".join(lines).split()
    names: list[str] = []
    index: dict[str, int] = {}
    pins = np.empty(len(lines), dtype=np.int64)
    for i, name in enumerate(tok[1::3]):
        k = index.get(name)
        if k is None:
            k = index[name] = len(names)
            names.append(name)
        pins[i] = k
    cycle = np.array(tok[0::3], dtype=np.int64)
    level = np.array(tok[2::3], dtype=np.int64)
    return PinTrace(cycle, level, pins, tuple(names), start)


@dataclass(frozen=True)
class Motion:
    """Each motor's continuous position as (times, positions) to interpolate, in steps."""

    t: tuple[FloatArray, FloatArray]
    x: tuple[FloatArray, FloatArray]

    def at(self, cycles: FloatArray) -> FloatArray:
        """Motor positions (N, 2) in steps at the given cycles."""
        return np.stack([np.interp(cycles, self.t[i], self.x[i]) for i in range(2)], axis=1)

    def step_cycles(self) -> FloatArray:
        """Every step's cycle, both motors, sorted."""
        return np.sort(np.concatenate(self.t))


def motion_of(pt: PinTrace) -> Motion:
    """The motors' continuous positions from their step edges (module docstring)."""
    ts, xs = [], []
    for axis in "AB":
        sc, sl = pt.of("step" + axis)
        rise = sc[sl == 1]
        dc, dl = pt.of("dir" + axis)
        if dc.size:
            at = np.searchsorted(dc, rise, side="right") - 1
            lev = np.where(at >= 0, dl[np.maximum(at, 0)], 0)
        else:
            lev = np.zeros(rise.shape[0], dtype=np.int64)
        sign = np.where(lev == 1, 1, -1)
        pos = pt.start["AB".index(axis)] + np.cumsum(sign)
        ts.append(rise.astype(np.float64))
        xs.append(pos - 0.5 * sign)
    return Motion((ts[0], ts[1]), (xs[0], xs[1]))


def pen_at(job: Job, profile: Profile, mo: Motion, cycles: FloatArray) -> FloatArray:
    """The pen (N, 2) mm at the given cycles."""
    th = step_angles(mo.at(cycles), job.home_rad, job.steps_per_rev)  # type: ignore[arg-type]
    res = profile.geometry.forward_batch(th, "+" if job.assembly > 0 else "-")
    out: FloatArray = res.points
    return out


def high_intervals(pt: PinTrace) -> tuple[IntArray, IntArray]:
    """The laser pin's high intervals [rise, fall) in cycles."""
    c, lv = pt.of("laser")
    rise = c[(lv == 1)]
    fall = c[(lv == 0)]
    if rise.size == 0:
        z = np.zeros(0, dtype=np.int64)
        return z, z
    j = np.searchsorted(fall, rise, side="right")
    end = np.where(j < fall.size, fall[np.minimum(j, fall.size - 1)], c.max())
    return rise, end


def grid_coords(r: RasterRuns, pts: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(s, t) mm of machine points in the scan grid's frame."""
    d = pts - np.asarray(r.origin)
    return d @ np.asarray(r.u), d @ np.asarray(r.n)


def pixel_cycles(r: RasterRuns) -> float:
    """A pixel's time at the scan speed, cycles."""
    return r.pitch_mm / r.speed_mm_s * F_CPU
