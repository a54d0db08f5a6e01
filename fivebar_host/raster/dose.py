"""The burned image from the step pulses and the laser pin: the dose per pixel and the
figures of a raster run (`fivebar plot … --port fivebar-sim://` prints them as its
`raster:` line; `benchmarks/raster.py` measures with them).  The trace and the motion it
records: `raster.trace`; the segments' exact schedule: `raster.schedule`; the power changes
at the pixel boundaries: `raster.changes`.

The laser pin's high intervals are cut into chunks of at most `CHUNK` cycles, each burned
where the pen is at its middle: the dose of a pixel is the high time (cycles) spent inside
its cell, and the burned power is 255 · dose / (the pixel's time at the scan speed).

The laser is *on* from a rise to its fall, and across the low part of a PWM period when the
next rise follows within a period: a step then is a step with the laser on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fivebar_host.compile.model import Job
from fivebar_host.config import Profile
from fivebar_host.raster.changes import Boundaries, boundary_errors, crossings
from fivebar_host.raster.runs import RasterRuns
from fivebar_host.raster.schedule import fit_schedule
from fivebar_host.raster.trace import (
    F_CPU,
    PWM_PERIOD,
    Motion,
    PinTrace,
    grid_coords,
    high_intervals,
    motion_of,
    pen_at,
    pixel_cycles,
    read_pins,
)
from kinematics.arrays import BoolArray, FloatArray, IntArray

__all__ = ["CHUNK", "F_CPU", "LAG_AFTER_S", "PWM_PERIOD", "STALL_S", "Boundaries", "Figures",
           "Motion", "PinTrace", "crossings", "dose_grid", "figures", "grid_coords",
           "high_intervals", "lagging_at", "laser_on", "motion_of", "pen_at", "pixel_cycles",
           "read_pins", "stall_times"]

#: Laser high time is burned in chunks of at most this many cycles.
CHUNK = 64
#: A pause of the steps longer than this inside a scanline is an underrun, s.
STALL_S = 0.002
#: A stall up to this long after the emulator caught up with the wall clock is put down
#: to its lag (`lagging_at`): the firmware's queue holds about 30 ms at the fastest scan.
LAG_AFTER_S = 0.05

def dose_grid(job: Job, profile: Profile, pt: PinTrace, mo: Motion) -> FloatArray:
    """Laser-high cycles inside each cell of the scan grid (R, C) (module docstring)."""
    r = job.raster
    assert r is not None
    rise, fall = high_intervals(pt)
    n = np.maximum(1, -(-(fall - rise) // CHUNK))
    start = np.repeat(rise, n)
    k = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)
    length = np.repeat(fall - rise, n)
    lo = start + k * CHUNK
    hi = np.minimum(lo + CHUNK, start + length)
    s, t = grid_coords(r, pen_at(job, profile, mo, 0.5 * (lo + hi)))
    rows, cols = r.target.shape
    ci = np.floor(s / r.pitch_mm).astype(np.int64)
    ri = np.floor(t / r.interval_mm).astype(np.int64)
    inside = (ci >= 0) & (ci < cols) & (ri >= 0) & (ri < rows)
    out = np.zeros(rows * cols)
    np.add.at(out, ri[inside] * cols + ci[inside], (hi - lo)[inside])
    return out.reshape(rows, cols)


@dataclass(frozen=True)
class Figures:
    """The figures of a raster run (module docstring), printed as the `raster:` line."""

    pixels: int
    seconds: float
    underruns: int
    placement_mm: float
    change_us: float
    outside_steps: int
    dose: FloatArray  # burned power per cell (R, C), 255 = full power for a pixel's time
    boundaries: Boundaries
    #: the underruns' cycles, and whether each came while the emulator lagged (`lagging_at`)
    stalls: FloatArray = field(default_factory=lambda: np.zeros(0))
    stalls_lagging: BoolArray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    #: emulated seconds from the first step to the last (the machine's own time: fbsim -R
    #: pauses with the wall clock where it lagged, which a host's elapsed time includes)
    motion_s: float = 0.0

    @property
    def rate(self) -> float:
        return self.pixels / self.seconds if self.seconds > 0 else 0.0

    def line(self) -> str:
        """The `raster:` line."""
        return (f"raster: {self.pixels} px in {self.seconds:.2f} s = {self.rate:.0f} px/s, "
                f"{self.underruns} underruns; burned image from the step pulses: pixel "
                f"placement max {self.placement_mm:.3f} mm, power changes within "
                f"{self.change_us:.1f} µs of the pixel boundaries, laser on outside the image "
                f"{self.outside_steps} steps")


def _inside_image(r: RasterRuns, s: FloatArray, t: FloatArray, margin: float = 0.0
                  ) -> BoolArray:
    """Whether grid points lie on a burned stretch of their row (between its scanline's
    first and last cell, widened by `margin` mm)."""
    rows, _cols = r.target.shape
    ri = np.floor(t / r.interval_mm).astype(np.int64)
    span = np.zeros((rows, 2))
    span[:, 0] = math.inf
    for sl in r.lines:
        span[sl.row] = (min(span[sl.row, 0], sl.c0 * r.pitch_mm),
                        max(span[sl.row, 1], sl.c1 * r.pitch_mm))
    ok = (ri >= 0) & (ri < rows)
    rc = np.clip(ri, 0, rows - 1)
    out: BoolArray = ok & (s >= span[rc, 0] - margin) & (s <= span[rc, 1] + margin)
    return out


def laser_on(rise: IntArray, fall: IntArray, cycles: FloatArray) -> BoolArray:
    """Whether the laser is on at each of `cycles` (module docstring: a high interval, or
    the low between two rises less than a period apart)."""
    if not rise.size:
        return np.zeros(cycles.shape[0], dtype=bool)
    joined = np.concatenate((rise[1:] - fall[:-1] < PWM_PERIOD, [False]))
    # merged intervals: a start where the one before was not joined to it
    start = np.concatenate(([True], ~joined[:-1]))
    first = rise[start]
    ends = fall[np.concatenate((np.flatnonzero(start)[1:] - 1, [fall.size - 1]))]
    j = np.searchsorted(first, cycles, side="right") - 1
    out: BoolArray = (j >= 0) & (cycles < ends[np.maximum(j, 0)])
    return out


def figures(job: Job, profile: Profile, pt: PinTrace) -> Figures:
    """The figures of a raster run from its trace (module docstring)."""
    r = job.raster
    assert r is not None
    edges = motion_of(pt)
    sched = fit_schedule(job, edges.t)
    mo, samples = edges, None
    if sched is not None:  # the segments' exact schedule (`schedule`)
        mo = Motion(sched.t, sched.x)
        samples = np.unique(np.concatenate((edges.step_cycles(), sched.t[0])))
    rise, fall = high_intervals(pt)
    seconds = float(fall.max() - rise.min()) / F_CPU if rise.size else 0.0
    b = boundary_errors(job, profile, mo, pt, samples)
    # steps while the laser is on (module docstring) outside the image
    steps = edges.step_cycles()
    on = laser_on(rise, fall, steps)
    s, t = grid_coords(r, pen_at(job, profile, mo, steps[on]))
    outside = int((~_inside_image(r, s, t)).sum())
    dose = dose_grid(job, profile, pt, mo) * 255.0 / pixel_cycles(r)
    stalls = stall_times(job, profile, edges, steps)
    return Figures(r.n_pixels, seconds, int(stalls.shape[0]),
                   float(b.placement_mm.max(initial=0.0)), float(np.abs(b.dt_us).max(initial=0.0)),
                   outside, dose, b, stalls, lagging_at(pt, stalls),
                   float(steps[-1] - steps[0]) / F_CPU if steps.size else 0.0)


def stall_times(job: Job, profile: Profile, mo: Motion, steps: FloatArray) -> FloatArray:
    """Underruns inside the image: the cycles where the steps paused while the pen was on a
    burned stretch, longer than `STALL_S` and than 20 times the usual step interval there."""
    r = job.raster
    assert r is not None
    none = np.zeros(0)
    if steps.size < 2:
        return none
    s, t = grid_coords(r, pen_at(job, profile, mo, steps))
    inside = _inside_image(r, s, t)
    both = inside[1:] & inside[:-1]
    gaps = np.diff(steps)[both]
    if gaps.size == 0:
        return none
    limit = max(STALL_S * F_CPU, 20.0 * float(np.median(gaps)))
    out: FloatArray = steps[:-1][both][gaps > limit]
    return out


def lagging_at(pt: PinTrace, cycles: FloatArray) -> BoolArray:
    """Whether the emulator (fbsim -R) had fallen behind the wall clock at each of `cycles`
    or within `LAG_AFTER_S` before: the trace's `lag` events.  The harness then runs flat
    out to catch up, and the host has to keep pace with that: a stall there says the machine
    running the emulator was busy, not that the link or the firmware fell short."""
    c, lv = pt.of("lag")
    start, end = c[lv == 1], c[lv == 0]
    out = np.zeros(cycles.shape[0], dtype=bool)
    for a in start.tolist():
        later = end[end >= a]
        b = (later.min() if later.size else np.iinfo(np.int64).max // 2) + LAG_AFTER_S * F_CPU
        out |= (cycles >= a) & (cycles <= b)
    return out
