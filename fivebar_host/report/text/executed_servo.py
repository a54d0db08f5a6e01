"""The executed path of a run on the servo firmware, measured from the arms' pulses.

The servo build sends each arm one pulse per 20 ms frame (docs/protocol.md 6.5); the
emulator traces them (`svA`, `svB`). Each pulse goes through a *true* servo — the
profile's curve (the default), and a dead band (the profile's `dead_band_deg`, or
`?deadband=A,B` degrees: the hysteresis of `kinematics.servo`, Eq. S1) — to the angle
the horn really turns to, the two arms' angles are merged in time and forward kinematics
(the pen off the joint included) gives where the pen was. A frame is a sample, not a
target: it belongs to the segment whose joint-space line it lies nearest (on the joints'
steps: the counts less the dead-band slack the run takes up, compile/backlash.py), walking
forward from the last one (segments are executed in order; past a sharp corner's short
pieces), and a frame on a drawing
segment is measured against its requested curve as the stepper report measures a step
(`executed.executed_path`).

Widths are taken as traced, to the emulated CPU's cycle (1/16 µs): that is the pulse the
servo receives, the firmware's sub-tick edge error (≤ 0.4 µs, benchmarks/servo.py)
included. (They were rounded to the 0.5 µs quantum with a one-quantum flicker held, which
made every moving arm lag its pulses by a quantum: up to a pulse quantum of extra deviation
at the pen, 0.1298 against 0.1095 mm on the same trace of the Plotclock text.)

The bound (issue 38): the tolerance plus the *pulse quantum* at the pen, `pulse_quantum_mm`:
one whole 0.5 µs tick on each arm, the tick's angle the steepest of its curve, mapped
through the Jacobian as the step quantum is (compile/steps.py), the largest over the job's
targets. A whole tick, not the half a stepper's rounding to the nearest step costs: a frame's
width is the arm's DDA count when its previous pulse fell, the segment's tick line
*truncated* (a step is taken at its time, up to 128 µs late, and the frame reads the count
between steps), so each arm lags its line by up to one tick. Measured on the Plotclock text
over ~60 runs: 0.093–0.150 mm against 0.1 + 0.0744 mm; a half-tick bound (0.1372 mm) was
exceeded in 2 of them, by a single frame of one arm 2.5 ticks off its line.
The plan's own rounding is the `[motors]` grid's step quantum (half a grid step); a servo
profile planned on a grid of ticks (configs/plotclock.toml: one step = one tick) makes it
half the pulse quantum, and the run is checked against the tolerance plus the larger.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from fivebar_host.compile import Job
from fivebar_host.compile.timing import PLAN_MIN_PIECE_STEPS
from fivebar_host.config import Profile
from fivebar_host.devices.simtrace import Trace
from fivebar_host.errors import FivebarError
from fivebar_host.report.text.executed import ExecutedPath, distance_on_segments
from kinematics.arrays import FloatArray, IntArray
from kinematics.servo import PULSE_QUANTUM_US, hysteresis

#: The arm servos' trace names.
PINS = ("svA", "svB")


def tick_rad(profile: Profile) -> tuple[float, float]:
    """Each arm's largest joint angle of one pulse quantum (0.5 µs), rad: the steepest
    piece of its curve (a table is piecewise linear, so its steepest piece bounds it)."""
    if profile.joints is None:
        raise FivebarError("the pulse quantum needs a servo profile ([joints])")
    out = []
    for j in profile.joints.joints:
        c = j.curve
        out.append(float(np.max(np.abs(np.diff(c.angle_rad) / np.diff(c.pulse_us))))
                   * PULSE_QUANTUM_US)
    return out[0], out[1]


def pulse_quantum_mm(job: Job, profile: Profile) -> float:
    """The pulse quantum at the pen, mm: the largest pen displacement from each arm off by
    one pulse tick (module doc), ‖J·δθ‖ ≤ ‖J[:, 0]‖·t₀ + ‖J[:, 1]‖·t₁ (triangle
    inequality, as `compile.steps.step_quantum_mm`), over the job's targets."""
    t0, t1 = tick_rad(profile)
    th = np.asarray(job.home_rad) + job.joint_steps * (2.0 * math.pi / job.steps_per_rev)
    fwd = profile.geometry.forward_batch(th, "+" if job.assembly > 0 else "-")
    ok = fwd.valid
    if not ok.any():
        return 0.0
    jac = profile.geometry.jacobian(th[ok], fwd.points[ok])
    q = np.hypot(jac[:, 0, 0], jac[:, 1, 0]) * t0 + np.hypot(jac[:, 0, 1], jac[:, 1, 1]) * t1
    return float(q.max())


def servo_angles(trace: Trace, profile: Profile, deadband_deg: tuple[float, float] | None
                 ) -> tuple[FloatArray, FloatArray]:
    """(times (E,) cycles, joint angles (E, 2) rad): each arm's pulses (as traced, to the
    cycle) through the profile's curve and the true dead band's hysteresis, each at the
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
        us = pul[1:, 1] * 1e6 / trace.freq  # the width the servo receives (module doc)
        th = curve.angle(np.clip(us, lo, hi))
        if deadband_deg is not None and deadband_deg[j] > 0:
            th = hysteresis(th, math.radians(deadband_deg[j]))
        times.append(pul[:-1, 0] + pul[:-1, 1])  # the previous pulse's fall
        angles.append(th)
    return merge_arms(times, angles)


def merge_arms(times: list[FloatArray], angles: list[FloatArray]
               ) -> tuple[FloatArray, FloatArray]:
    """Both arms' angles (each sampled at its own times) on the union of those times where
    both are known, interpolated linearly; frames that repeat the last angles dropped (a
    frame that repeats the last pulses is no motion: the reports count motion events)."""
    t = np.unique(np.concatenate(times))
    t = t[(t >= max(x[0] for x in times)) & (t <= min(x[-1] for x in times))]
    th = np.stack([np.interp(t, times[j], angles[j]) for j in (0, 1)], axis=1)
    moved = np.ones(t.size, dtype=bool)
    moved[1:] = (np.diff(th, axis=0) != 0).any(axis=1)
    return t[moved], th[moved]


def _line_distance(tgt: FloatArray, k: int, q: FloatArray) -> float:
    """Distance, in steps, of `q` to segment k's joint-space line (its target rows)."""
    a, d = tgt[k], tgt[k + 1] - tgt[k]
    dd = float(d @ d)
    s = min(max(float((q - a) @ d) / dd, 0.0), 1.0) if dd > 0 else 0.0
    return float(np.hypot(*(a + s * d - q)))


def _segment_of(job: Job, q: FloatArray, first: int, short_steps: float) -> IntArray:
    """Each frame's segment: from the last frame's one, on to the next (non-empty) segment
    while the frame lies nearer its joint-space line — looking past segments of at most
    `short_steps` that it does not lie nearer (a frame, a sample every 20 ms, lands past the
    short pieces the planner cuts at a sharp corner: a walk one segment at a time stuck
    before them and measured the rest of the run against that segment). Segments run in
    order and a frame is a sample of a continuous path, so the walk never jumps to a far
    segment a travel passes."""
    tgt = job.steps.astype(np.float64)
    n = job.n_segments
    seg = np.full(q.shape[0], -1, dtype=np.int64)
    k = min(first, n - 1)
    span = np.abs(np.diff(tgt, axis=0)).max(axis=1)
    for i in range(q.shape[0]):
        d = _line_distance(tgt, k, q[i])
        j = k + 1
        while j < n:
            if span[j] > 0:
                dj = _line_distance(tgt, j, q[i])
                if dj < d:  # a frame at a junction still belongs to the segment it ends
                    k, d = j, dj
                elif span[j] > short_steps:
                    break
            j += 1
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
    seg = _segment_of(job, q, first_segment, PLAN_MIN_PIECE_STEPS)
    fwd = profile.geometry.forward_batch(th, "+" if job.assembly > 0 else "-")
    dev = np.full(t.size, np.nan)
    draw = np.flatnonzero((seg >= 0) & job.draw[np.maximum(seg, 0)])
    if draw.size:
        dev[draw] = distance_on_segments(job, fwd.points[draw], q[draw], seg[draw])
        dev[draw[~fwd.valid[draw]]] = np.inf
    completed = int(seg.max(initial=first_segment))
    return ExecutedPath(t / trace.freq, grid[keep], fwd.points, seg, dev, completed)
