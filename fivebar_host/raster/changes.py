"""The power changes at the pixel boundaries of a raster run, from an emulator trace: when
the pen crossed each boundary, when the firmware changed the power there, and the two
figures of the `raster:` line they give (placement, power-change timing; `raster.dose`).

A *crossing* is solved on the pen's path: on the segments' exact schedule
(`raster.schedule`: each segment's start fitted to its step edges, the motors exactly
linear inside it) by Newton on the along-track distance, else interpolated between the step
edges.  A *change* is the firmware's power write, when the trace has them (`lwrite`, every
board_laser() call: `raster.schedule`).  Without them it is found on the laser pin: the
firmware restarts the PWM period there (board.h board_laser writes TCNT2 = MAX − 1), so the
rises after it keep a new phase.  The new period starts two ticks after the write (BOTTOM),
on the chip as in simavr; a pin that was low at the write rises there, but a pin that was
high stays high through it (the write skips the old compare: the pulse runs on to the new
one) and shows its first restarted rise a period later — `change_writes` tells the two
apart by the pin's level a period before the rise.  A change whose new phase falls within
`SLACK` of the old one (about one in forty) shows no restart and is not counted then.

At each pixel boundary the change nearest its crossing, within `WINDOW_US` (and half a
pixel), is its change: the pen's distance there from the boundary's point (placement) and
the time between the change and the crossing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fivebar_host.compile.model import Job
from fivebar_host.config import Profile
from fivebar_host.raster.runs import ScanInfo
from fivebar_host.raster.trace import (
    F_CPU,
    PWM_PERIOD,
    Motion,
    PinTrace,
    grid_coords,
    high_intervals,
    pen_at,
    pixel_cycles,
)
from kinematics.arrays import BoolArray, FloatArray, IntArray

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
#: The largest Newton step when a crossing is solved on the exact motion, cycles.
NEWTON_MAX = 4000.0

def restarts(pt: PinTrace) -> tuple[IntArray, IntArray]:
    """The laser pin's rising edges and whether each restarts the PWM's period (it does not
    follow the rise before by a whole number of periods, within `SLACK`)."""
    c, lv = pt.of("laser")
    rise = c[lv == 1]
    gap = np.diff(rise, prepend=-(10**12))
    off = np.mod(gap + SLACK, PWM_PERIOD) > 2 * SLACK
    return rise, off.astype(np.int64)


def crossings(job: Job, profile: Profile, mo: Motion, samples: FloatArray | None = None
              ) -> list[tuple[int, FloatArray]]:
    """Per scanline (job order): when the pen crossed each of its pixel boundaries, cycles
    (NaN where it did not), from the pen at the motion's knots while it was on the
    scanline's row and stretch with its overscan — the scanline's visit of its row (a row
    is visited once per pass), from the overscan's start to its end.  `samples` given:
    `mo` is the fitted schedule (`schedule.fit_schedule`), exact between its knots too,
    sampled at these cycles (the step edges and the knots); each crossing is then solved
    on the pen's path itself (`_refine`), not interpolated between samples."""
    r = job.raster
    assert r is not None
    exact = samples is not None
    steps = mo.step_cycles() if samples is None else samples
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
                if exact and ok.any():
                    bound[ok] = _refine(job, profile, mo, sl, want[ok], bound[ok])
        out.append((sl.row, bound))
    return out


def _refine(job: Job, profile: Profile, mo: Motion, sl: ScanInfo, want: FloatArray,
            tau: FloatArray) -> FloatArray:
    """Newton on σ(τ) = `want` (σ: the pen's along-track distance from the scanline's entry
    cell edge), from the interpolated τ, on the exact motion: three iterations take the
    sampling's error (σ bends between samples) below a cycle."""
    r = job.raster
    assert r is not None
    entry = sl.c0 * r.pitch_mm if sl.sign > 0 else sl.c1 * r.pitch_mm

    def sigma(c: FloatArray) -> FloatArray:
        s, _ = grid_coords(r, pen_at(job, profile, mo, c))
        out: FloatArray = (s - entry) * sl.sign
        return out

    h = 4.0
    for _ in range(3):
        f0, f1 = sigma(tau - h), sigma(tau + h)
        slope = (f1 - f0) / (2 * h)
        good = slope > 0
        step = np.where(good, (want - 0.5 * (f0 + f1)) / np.where(good, slope, 1.0), 0.0)
        tau = tau + np.clip(step, -NEWTON_MAX, NEWTON_MAX)
    return tau


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


def boundary_errors(job: Job, profile: Profile, mo: Motion, pt: PinTrace,
                    samples: FloatArray | None = None) -> Boundaries:
    """The changes at the pixel boundaries.  With the power writes in the trace (`lwrite`,
    `schedule`): every change to a new power (the exit's 0 too) is the write nearest the
    pen's crossing within `WINDOW_US`.  Without them, those the pin shows: a change between
    two powers of at least `MIN_PULSE` and at most 255 − `MIN_PULSE`, or from 0 to any
    power, is the restarted rise whose write (`change_writes`) is nearest the crossing; a
    change to 0 inside the line is the nearest laser-off fall (`off_writes`).  A change
    farther than `WINDOW_US` from its crossing is not found (`Boundaries.found` < `clean`).
    `samples`: `mo` is the fitted schedule (`crossings`)."""
    r = job.raster
    assert r is not None
    writes = pt.of("lwrite")[0].astype(np.float64)
    if writes.size:
        cand_on = cand_off = writes
    else:
        _, restart = restarts(pt)
        cand_on, cand_off = change_writes(pt, restart), off_writes(pt)
    half = min(0.5 * pixel_cycles(r), WINDOW_US * F_CPU * 1e-6)
    place, dts, clean_n = [], [], 0
    for sl, (_, tau) in zip(r.lines, crossings(job, profile, mo, samples), strict=True):
        before = np.concatenate(([0], sl.change_power[:-1])).astype(np.int64)
        after = sl.change_power.astype(np.int64)
        if writes.size:
            on = (after != before) & (after > 0)
            off = (after == 0) & (before > 0)
        else:
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
