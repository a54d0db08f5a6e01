"""The executed path of a run on the servo firmware, measured from the arms' pulses.

The servo build sends each arm one pulse per 20 ms frame (docs/protocol.md 6.5); the
emulator traces them (`svA`, `svB`). Each pulse goes through a *true* servo — the
profile's curve (the default), and a dead band (the profile's `dead_band_deg`, or
`?deadband=A,B` degrees: the hysteresis of `kinematics.servo`, Eq. S1) — to the angle
the horn really turns to, the two arms' angles are merged in time and forward kinematics
(the pen off the joint included) gives where the pen was. A frame is a sample, not a
target: it belongs to the segment whose joint-space line it lies nearest (on the joints'
steps: the counts less the dead-band slack the run takes up, compile/backlash.py), walking
forward from the last one (segments are executed in order), and a frame on a drawing
segment is measured against its requested curve as the stepper report measures a step
(`executed.executed_path`).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from fivebar_host.compile import Job
from fivebar_host.config import Profile
from fivebar_host.devices.simtrace import Trace
from fivebar_host.errors import FivebarError
from fivebar_host.report.text.executed import ExecutedPath, distance_on_segments
from kinematics.arrays import FloatArray, IntArray
from kinematics.servo import PULSE_QUANTUM_US, hysteresis

#: The arm servos' trace names.
PINS = ("svA", "svB")
#: A measured pulse moves only once it leaves ± one quantum of where it was (Eq. S1 of
#: this width): the firmware's edges jitter by under a quantum (benchmarks/servo.py), which
#: rounds a still servo's width one quantum off now and then.
FLICKER_US = 2 * PULSE_QUANTUM_US


def servo_angles(trace: Trace, profile: Profile, deadband_deg: tuple[float, float] | None
                 ) -> tuple[FloatArray, FloatArray]:
    """(times (E,) cycles, joint angles (E, 2) rad): each arm's pulses (to the 0.5 µs
    quantum) through the profile's curve and the true dead band's hysteresis, each at the
    time its width was taken (the arm's previous fall, board_servo.c), and both arms on
    the union of those times, each interpolated linearly between its own samples (a servo
    moves on between its frames, and arm B's frames start 3 ms after arm A's)."""
    if profile.joints is None:
        raise FivebarError("the executed servo path needs a servo profile ([joints])")
    if deadband_deg is None:  # no `?deadband=`: the true servos have the profile's
        deadband_deg = (math.degrees(profile.joints.joints[0].dead_band_rad),
                        math.degrees(profile.joints.joints[1].dead_band_rad))
    times, angles = [], []
    for j, name in enumerate(PINS):
        pul = np.array([(c, w) for c, w in trace.pulses(name) if c > 0],
                       dtype=np.float64).reshape(-1, 2)
        if pul.shape[0] < 2:
            return np.zeros(0), np.zeros((0, 2))
        curve = profile.joints.joints[j].curve
        lo, hi = curve.range_us
        us = np.rint(pul[1:, 1] * 1e6 / trace.freq / PULSE_QUANTUM_US) * PULSE_QUANTUM_US
        # a pulse one quantum off and back (the edges' sub-µs jitter) is no motion
        us = hysteresis(us, FLICKER_US)
        th = curve.angle(np.clip(us, lo, hi))
        if deadband_deg is not None and deadband_deg[j] > 0:
            th = hysteresis(th, math.radians(deadband_deg[j]))
        times.append(pul[:-1, 0] + pul[:-1, 1])  # the previous pulse's fall
        angles.append(th)
    t = np.unique(np.concatenate(times))
    t = t[(t >= max(x[0] for x in times)) & (t <= min(x[-1] for x in times))]
    th = np.stack([np.interp(t, times[j], angles[j]) for j in (0, 1)], axis=1)
    # a frame that repeats the last pulses is no motion (the reports count motion events)
    moved = np.ones(t.size, dtype=bool)
    moved[1:] = (np.diff(th, axis=0) != 0).any(axis=1)
    return t[moved], th[moved]


def _line_distance(tgt: FloatArray, k: int, q: FloatArray) -> float:
    """Distance, in steps, of `q` to segment k's joint-space line (its target rows)."""
    a, d = tgt[k], tgt[k + 1] - tgt[k]
    dd = float(d @ d)
    s = min(max(float((q - a) @ d) / dd, 0.0), 1.0) if dd > 0 else 0.0
    return float(np.hypot(*(a + s * d - q)))


def _segment_of(job: Job, q: FloatArray, first: int) -> IntArray:
    """Each frame's segment: from the last frame's one, the next (non-empty) segment while
    the frame lies nearer its joint-space line (segments run in order and a frame is a
    sample of a continuous path, so the walk never jumps to a far segment a travel passes)."""
    tgt = job.steps.astype(np.float64)
    n = job.n_segments
    seg = np.full(q.shape[0], -1, dtype=np.int64)
    k = min(first, n - 1)
    empty = (tgt[1:] == tgt[:-1]).all(axis=1)
    for i in range(q.shape[0]):
        d = _line_distance(tgt, k, q[i])
        while True:
            j = k + 1
            while j < n and empty[j]:
                j += 1
            if j >= n:
                break
            d1 = _line_distance(tgt, j, q[i])
            if d1 >= d:  # a frame at a junction still belongs to the segment it ends
                break
            k, d = j, d1
        seg[i] = k
    return seg


def executed_servo_path(job: Job, profile: Profile, trace: Trace, first_segment: int = 0,
                        deadband_deg: tuple[float, float] | None = None) -> ExecutedPath:
    """The executed path of a servo run from its traced pulses (module doc)."""
    t, th = servo_angles(trace, profile, deadband_deg)
    if job.slack.shape[0]:  # frames are where the arms are: the joints' steps, not counts
        job = replace(job, steps=job.joint_steps, slack=job.slack[:0])
    home = np.array(job.home_rad)
    q = (th - home) * (job.steps_per_rev / (2.0 * math.pi))  # on the step grid, unrounded
    # an event is a frame whose position on the grid changed, as a step is one
    grid = np.rint(q).astype(np.int64)
    keep = np.ones(t.size, dtype=bool)
    keep[1:] = (np.diff(grid, axis=0) != 0).any(axis=1)
    t, th, q = t[keep], th[keep], q[keep]
    seg = _segment_of(job, q, first_segment)
    fwd = profile.geometry.forward_batch(th, "+" if job.assembly > 0 else "-")
    dev = np.full(t.size, np.nan)
    draw = np.flatnonzero((seg >= 0) & job.draw[np.maximum(seg, 0)])
    if draw.size:
        dev[draw] = distance_on_segments(job, fwd.points[draw], q[draw], seg[draw])
        dev[draw[~fwd.valid[draw]]] = np.inf
    completed = int(seg.max(initial=first_segment))
    return ExecutedPath(t / trace.freq, grid[keep], fwd.points, seg, dev, completed)
