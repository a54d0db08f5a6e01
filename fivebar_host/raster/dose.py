"""The burned image from the step pulses and the laser pin: the dose per pixel and the
figures of a raster run (`fivebar plot … --port fivebar-sim://` prints them as its
`raster:` line; `benchmarks/raster.py` measures with them).

The motion is rebuilt from the step edges alone: a step of motor i at cycle t moves it from
k − 1 to k (signed by its direction pin), and the firmware's DDA puts step k of a constant-
rate segment at the time its continuous position n·t/C passes k − ½, so the motor's
position is the linear interpolation of (t, k − ½·dir) over its steps — the same model the
planner places the pixel boundaries on (`raster.pixels`).  The pen is forward kinematics of
both motors' positions at a time.

The laser pin's high intervals are cut into chunks of at most `CHUNK` cycles, each burned
where the pen is at its middle: the dose of a pixel is the high time (cycles) spent inside
its cell, and the burned power is 255 · dose / (the pixel's time at the scan speed).

A *change* is where the firmware put a new power on the laser: it restarts the PWM period
there (board.h board_laser writes TCNT2 = MAX − 1), so the rises after it keep a new
phase.  The new period starts two ticks after the write (BOTTOM), on the chip as in simavr;
a pin that was low at the write rises there, but a pin that was high stays high through it
(the write skips the old compare: the pulse runs on to the new one) and shows its first
restarted rise a period later — `change_writes` tells the two apart by the pin's level a
period before the rise.  At each pixel boundary (the pen's crossing
found from the steps) the restarted rise whose write is nearest, within `WINDOW_US` (and
half a pixel), is its change: the pen's distance there from the boundary's point
(placement) and the time between the change and the crossing.  A change whose new phase
falls within `SLACK` of the old one (about one in forty) shows no restart and is not
counted (`Figures.changes_seen` says how many were).

The laser is *on* from a rise to its fall, and across the low part of a PWM period when the
next rise follows within a period: a step then is a step with the laser on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fivebar_host.compile.model import Job
from fivebar_host.compile.steps import step_angles
from fivebar_host.config import Profile
from fivebar_host.raster.runs import RasterRuns
from kinematics.arrays import BoolArray, FloatArray, IntArray

F_CPU = 16_000_000
#: The laser PWM's period in cycles (Timer2 at F_CPU / 256, config.h CFG_LASER_PWM_DIV 1).
PWM_PERIOD = 256
#: Laser high time is burned in chunks of at most this many cycles.
CHUNK = 64
#: A rise this close to a period after the one before is the PWM's own, cycles.
SLACK = 3
#: Cycles from a power change's TCNT2 write (TCNT2 = MAX − 1) to the new period's start.
TICKS = 2
#: ... and to the second new period's start (`change_writes`).
RESTART = PWM_PERIOD + TICKS
#: How far from the crossing a change is looked for, µs.
WINDOW_US = 40.0
#: Pulses shorter than this (or longer than a period less it) make no clean change, cycles.
MIN_PULSE = 8
#: A pause of the steps longer than this inside a scanline is an underrun, s.
STALL_S = 0.002


@dataclass(frozen=True)
class PinTrace:
    """A trace file's events as arrays (cycle, pin index, level), time ordered per pin."""

    cycle: IntArray
    level: IntArray
    pin: IntArray
    names: tuple[str, ...]

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
    return PinTrace(cycle, level, pins, tuple(names))


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
        pos = np.cumsum(sign)
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


def pixel_cycles(r: RasterRuns) -> float:
    """A pixel's time at the scan speed, cycles."""
    return r.pitch_mm / r.speed_mm_s * F_CPU


def restarts(pt: PinTrace) -> tuple[IntArray, IntArray]:
    """The laser pin's rising edges and whether each restarts the PWM's period (it does not
    follow the rise before by a whole number of periods, within `SLACK`)."""
    c, lv = pt.of("laser")
    rise = c[lv == 1]
    gap = np.diff(rise, prepend=-(10**12))
    off = np.mod(gap + SLACK, PWM_PERIOD) > 2 * SLACK
    return rise, off.astype(np.int64)


def crossings(job: Job, profile: Profile, mo: Motion) -> list[tuple[int, FloatArray]]:
    """Per scanline (job order): when the pen crossed each of its pixel boundaries, cycles
    (NaN where it did not), from the step events while the pen was on the scanline's row
    and stretch with its overscan — the scanline's visit of its row (a row is visited once
    per pass), from the overscan's start to its end."""
    r = job.raster
    assert r is not None
    steps = mo.step_cycles()
    s, t = grid_coords(r, pen_at(job, profile, mo, steps))
    row_of = np.floor(t / r.interval_mm).astype(np.int64)
    seen: dict[int, int] = {}
    out: list[tuple[int, FloatArray]] = []
    h = r.pitch_mm
    over = h + 1.5 * r.speed_mm_s ** 2 / (2 * r.accel_mm_s2)  # the overscan and a pixel
    for sl in r.lines:
        on = (row_of == sl.row) & (s > sl.c0 * h - over) & (s < sl.c1 * h + over)
        idx = np.flatnonzero(on)
        visit = seen.get(sl.row, 0)
        seen[sl.row] = visit + 1
        bound = np.full(sl.c1 - sl.c0 + 1, np.nan)
        if idx.size:
            breaks = np.flatnonzero(np.diff(idx) > 1)
            starts = np.concatenate(([0], breaks + 1))
            stops = np.concatenate((breaks + 1, [idx.size]))
            if visit < starts.size:
                sel = idx[starts[visit]:stops[visit]]
                entry = sl.c0 * h if sl.sign > 0 else sl.c1 * h
                sig = (s[sel] - entry) * sl.sign
                # the scan itself: from its overscan's start (the visit's least σ: the move
                # there may pass the row's end first) to its end (the most σ after it)
                lo = int(np.argmin(sig))
                hi = lo + int(np.argmax(sig[lo:])) + 1
                sel, sig = sel[lo:hi], sig[lo:hi]
                order = np.argsort(sig)
                want = np.arange(bound.size) * h
                ok = (want >= sig.min()) & (want <= sig.max())
                bound[ok] = np.interp(want[ok], sig[order], steps[sel][order])
        out.append((sl.row, bound))
    return out


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


def change_writes(pt: PinTrace, restart: IntArray) -> FloatArray:
    """The TCNT2 writes (cycles) behind the restarted rises (`restarts`' flags; module
    docstring).  The write makes the next timer tick BOTTOM, `TICKS` after it: a pin low at
    the write rises there.  A pin high at the write stays high through it (the write skips
    the old compare), falls at the new compare — `TICKS` + the new width after the write —
    and shows its first restarted rise a period later: that is the case where the fall
    before the rise is the new width after the rise's period start, and the write is then
    `RESTART` before the rise."""
    rise, fall = high_intervals(pt)
    k = np.flatnonzero(restart)
    width = fall[k] - rise[k]
    f_prev = np.where(k > 0, fall[np.maximum(k - 1, 0)], -(10**12))
    late = np.abs(f_prev - (rise[k] - PWM_PERIOD + width)) <= SLACK
    out: FloatArray = rise[k].astype(np.float64) - np.where(late, RESTART, TICKS)
    return out


@dataclass(frozen=True)
class Boundaries:
    """The changes found at the pixel boundaries (`boundary_errors`)."""

    placement_mm: FloatArray  # the pen's distance from the boundary at each change
    dt_us: FloatArray  # change − crossing, µs
    clean: int  # boundaries whose change the pin can show (MIN_PULSE)

    @property
    def found(self) -> int:
        """Boundaries whose change was found within `WINDOW_US`."""
        return int(self.dt_us.shape[0])


def _nearest(cand: FloatArray, tau: FloatArray, half: float) -> tuple[BoolArray, FloatArray]:
    """The candidate nearest each crossing, and whether it is within `half`."""
    if cand.size < 2:
        return np.zeros(tau.shape[0], dtype=bool), tau
    k = np.clip(np.searchsorted(cand, tau), 1, cand.size - 1)
    lo, hi = cand[k - 1], cand[k]
    got = np.where(np.abs(lo - tau) < np.abs(hi - tau), lo, hi)
    return np.abs(got - tau) <= half, got


def off_writes(pt: PinTrace) -> FloatArray:
    """The laser-off writes (cycles): falls after which the pin stays low longer than a
    period (board_laser(0) drives the pin low at once)."""
    rise, fall = high_intervals(pt)
    nxt = np.concatenate((rise[1:], [np.iinfo(np.int64).max]))
    out: FloatArray = fall[nxt - fall > PWM_PERIOD + SLACK].astype(np.float64)
    return out


def boundary_errors(job: Job, profile: Profile, mo: Motion, pt: PinTrace) -> Boundaries:
    """The changes at the pixel boundaries the pin shows: a change between two powers of at
    least `MIN_PULSE` and at most 255 − `MIN_PULSE`, or from 0 to any power, is the restarted
    rise whose write (`change_writes`) is nearest the pen's crossing within `WINDOW_US`; a
    change to 0 inside the line is the nearest laser-off fall (`off_writes`).  A change
    farther than `WINDOW_US` from its crossing is not found (`Boundaries.found` < `clean`)."""
    r = job.raster
    assert r is not None
    _, restart = restarts(pt)
    cand_on, cand_off = change_writes(pt, restart), off_writes(pt)
    half = min(0.5 * pixel_cycles(r), WINDOW_US * F_CPU * 1e-6)
    place, dts, clean_n = [], [], 0
    for sl, (_, tau) in zip(r.lines, crossings(job, profile, mo), strict=True):
        before = np.concatenate(([0], sl.change_power[:-1])).astype(np.int64)
        after = sl.change_power.astype(np.int64)
        mid = (after >= MIN_PULSE) & (after <= 255 - MIN_PULSE)
        on = ((mid & (before >= MIN_PULSE) & (before <= 255 - MIN_PULSE))
              | ((before == 0) & (after >= MIN_PULSE)))
        off = (after == 0) & (before > 0)
        off[-1] = False  # the exit: where the ramp's steps leave the crossing loose
        idx = np.flatnonzero((on | off) & np.isfinite(tau))
        clean_n += int(idx.size)
        if not idx.size:
            continue
        f_on, g_on = _nearest(cand_on, tau[idx], half)
        f_off, g_off = _nearest(cand_off, tau[idx], half)
        is_off = off[idx]
        found = np.where(is_off, f_off, f_on)
        got = np.where(is_off, g_off, g_on)
        idx, got = idx[found], got[found]
        dts.append((got - tau[idx]) / F_CPU * 1e6)
        ideal = np.asarray(sl.p0) + np.outer(idx * r.pitch_mm, np.asarray(sl.d))
        place.append(np.hypot(*(pen_at(job, profile, mo, got) - ideal).T))
    return Boundaries(np.concatenate([np.zeros(0), *place]),
                      np.concatenate([np.zeros(0), *dts]), clean_n)


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
    mo = motion_of(pt)
    rise, fall = high_intervals(pt)
    seconds = float(fall.max() - rise.min()) / F_CPU if rise.size else 0.0
    b = boundary_errors(job, profile, mo, pt)
    # steps while the laser is on (module docstring) outside the image
    steps = mo.step_cycles()
    on = laser_on(rise, fall, steps)
    s, t = grid_coords(r, pen_at(job, profile, mo, steps[on]))
    outside = int((~_inside_image(r, s, t)).sum())
    dose = dose_grid(job, profile, pt, mo) * 255.0 / pixel_cycles(r)
    return Figures(r.n_pixels, seconds, _stalls(job, profile, mo, steps),
                   float(b.placement_mm.max(initial=0.0)), float(np.abs(b.dt_us).max(initial=0.0)),
                   outside, dose, b)


def _stalls(job: Job, profile: Profile, mo: Motion, steps: FloatArray) -> int:
    """Underruns inside the image: pauses of the steps while the pen is on a burned stretch,
    longer than `STALL_S` and than 20 times the usual step interval there."""
    r = job.raster
    assert r is not None
    if steps.size < 2:
        return 0
    s, t = grid_coords(r, pen_at(job, profile, mo, steps))
    inside = _inside_image(r, s, t)
    both = inside[1:] & inside[:-1]
    gaps = np.diff(steps)[both]
    if gaps.size == 0:
        return 0
    limit = max(STALL_S * F_CPU, 20.0 * float(np.median(gaps)))
    return int((gaps > limit).sum())
