"""The executed segments' exact schedule, fitted to the step edges of an emulator trace, and
the laser's power writes: what `raster.dose` measures the power-change timing against.

Why not the step edges alone: between two edges a motor's position is only known to a step,
and at 40 mm/s a step is 250 µs — linear interpolation between edges is exact inside a
segment (the motor runs at one rate) but not across a segment boundary, where the rate
changes between two edges.  The firmware's schedule is known exactly instead
(fb_fast.h): segment j of C_j = 16 · P_j cycles moving a motor n steps puts its step k
(1 ≤ k ≤ n) at the DDA time floor((2k − 1) · C_j / 2n) after the segment's start, or one
cycle before it, and the next segment starts exactly C_j cycles later.  So each segment's
start is fitted from its own edges — the least of (edge − its DDA offset) over both motors'
steps in it: an edge is never early, it can only be late (a step interrupt held off) — and
each motor's position is exactly linear between the segment's start (its steps at the
start) and its end (C_j later, its steps at the end).  A stall between segments (an
underrun) is simply a later start: the motors rest between the knots.

The steps of the trace are assigned to the job's segments by count from the trace's end
(segment j moves motor i |ΔA| or |ΔB| steps, in order; the job ends with its park move, a
move to the job's start may come before it): `fit_schedule` returns None when the trace
holds fewer steps than the job or its edges do not follow the job's DDA times (a resumed
run), and the caller falls back to the edges.

The power writes: `fbsim -t` traces every write of TCCR2A as `lwrite` (firmware/sim/fbsim.c),
and the firmware's board_laser() (board.h) writes TCCR2A once a call, so its cycles are the
times the firmware put a new power on the laser, whatever the pin showed then (a pin low in
its PWM period shows a change to 0 only at the next expected rise, a restarted period only
at its first rise).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fivebar_host.compile.model import Job
from kinematics.arrays import FloatArray, IntArray

#: The firmware's timer cycles a µs (16 MHz).
CYCLES_PER_US = 16
#: Largest lateness (cycles) of a step edge behind the fitted DDA time that the fit accepts
#: for most edges: more means the trace is not this job's.
FIT_LATE_MAX = 400


@dataclass(frozen=True)
class Schedule:
    """Per job segment: its fitted start (cycles; NaN where it has no step) and length C_j
    (cycles); the motors' exact positions as knots (`Motion`-compatible: times, steps); and
    how late the edges were behind the fitted DDA times (cycles: median, largest)."""

    start: FloatArray
    cycles: FloatArray
    t: tuple[FloatArray, FloatArray]
    x: tuple[FloatArray, FloatArray]
    late_median: float
    late_max: float


def _dda_offsets(n: IntArray, c: FloatArray) -> tuple[IntArray, FloatArray]:
    """For motor steps grouped by segment (n steps in segment j, C_j cycles): each step's
    segment and its DDA offset floor((2k − 1) C / 2n) from the segment's start."""
    seg = np.repeat(np.arange(n.shape[0]), n)
    first = np.repeat(np.cumsum(n) - n, n)
    k = np.arange(seg.shape[0]) - first + 1
    off = np.floor((2 * k - 1) * c[seg] / (2 * n[seg]))
    return seg, off


def fit_schedule(job: Job, step_times: tuple[FloatArray, FloatArray]) -> Schedule | None:
    """The segments' starts fitted to each motor's step rises (module docstring); None when
    the trace's step counts are not the job's or the edges do not follow its DDA times."""
    delta = np.diff(job.steps.astype(np.int64), axis=0)
    n = np.abs(delta)
    c = job.duration_us.astype(np.float64) * CYCLES_PER_US
    seg_count = c.shape[0]
    start = np.full(seg_count, np.inf)
    parts = []
    for i in range(2):
        total = int(n[:, i].sum())
        if total > step_times[i].shape[0]:
            return None
        seg, off = _dda_offsets(n[:, i], c)
        est = step_times[i][step_times[i].shape[0] - total:] - off
        np.minimum.at(start, seg, est)
        parts.append((seg, est))
    moving = np.isfinite(start)
    if not moving.any():
        return None
    late = np.concatenate([est - start[seg] for seg, est in parts])
    late_median = float(np.median(late)) if late.size else 0.0
    late_max = float(late.max(initial=0.0))
    if late_median > FIT_LATE_MAX:
        return None
    j = np.flatnonzero(moving)
    t0 = start[j]
    t1 = t0 + c[j]
    times = np.ravel(np.column_stack((t0, t1)))
    # a fitted start a cycle before the previous segment's end: keep time monotonic
    times = np.maximum.accumulate(times)
    rel = job.steps.astype(np.float64)
    xs = [np.ravel(np.column_stack((rel[j, i], rel[j + 1, i]))) for i in range(2)]
    # a segment without steps (a pure wait) starts where the one before it ended
    out_start = np.where(moving, start, np.nan)
    for k in np.flatnonzero(~moving):
        if k > 0 and np.isfinite(out_start[k - 1]):
            out_start[k] = out_start[k - 1] + c[k - 1]
    return Schedule(out_start, c, (times, times), (xs[0], xs[1]), late_median, late_max)
