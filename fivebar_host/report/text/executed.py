"""The executed pen path: recorded motor positions → segments → forward kinematics → deviation.

Used after a run on the emulator (`fivebar-sim://`, from its pin trace) or the mock device to
show what the machine really drew, and in the end-to-end tests to prove it: every recorded
position is assigned to the job segment being executed (segments run in order and each ends
exactly on its target), turned into a pen point by forward kinematics of the job's assembly,
and measured against the requested curve of that segment.

With `true` (a `kinematics.calibration.MachineParams`: the machine's real link lengths and
home angles, e.g. the mock's ``true=`` URL option via `true_params`), the pen points are
those of that machine rather than the profile's: what a miscalibrated machine really draws.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from fivebar_host.compile import Job, distance_to_request
from fivebar_host.compile.backlash import play
from fivebar_host.compile.steps import step_angles
from fivebar_host.config import Profile
from fivebar_host.errors import FivebarError
from fivebar_host.program import line_param
from kinematics.arrays import FloatArray, IntArray
from kinematics.calibration import MachineParams
from kinematics.extension import ExtendedFiveBar
from kinematics.fivebar import FiveBar


class DeviationError(FivebarError):
    """The executed path left the drawing by more than its bound (a failed run)."""

    exit_code = 3


@dataclass(frozen=True)
class ExecutedPath:
    """Recorded positions as pen points, with the job segment each belongs to."""

    time: FloatArray  # (E,) event times (any unit: cycles or seconds)
    steps: IntArray  # (E, 2) motor positions after each event
    points: FloatArray  # (E, 2) pen position, mm (forward kinematics)
    segment: IntArray  # (E,) job segment executing (−1 before the first / after the last)
    deviation_mm: FloatArray  # (E,) distance to the requested curve (NaN on travel)
    segments_completed: int  # how many job segments reached their target, in order

    @property
    def max_deviation_mm(self) -> float:
        """Largest deviation over drawing events (0 if none)."""
        d = self.deviation_mm[np.isfinite(self.deviation_mm)]
        return float(d.max()) if d.size else 0.0


def merge_axes(a_events: list[tuple[int, int]], b_events: list[tuple[int, int]],
               start: tuple[int, int] = (0, 0)) -> tuple[FloatArray, IntArray]:
    """Merge per-axis (time, position) step events into one time-ordered (E, 2) track."""
    ta = np.array([t for t, _ in a_events], dtype=np.float64)
    tb = np.array([t for t, _ in b_events], dtype=np.float64)
    pa = np.array([p for _, p in a_events], dtype=np.int64)
    pb = np.array([p for _, p in b_events], dtype=np.int64)
    t = np.concatenate((ta, tb))
    axis = np.concatenate((np.zeros(ta.size, np.int64), np.ones(tb.size, np.int64)))
    pos = np.concatenate((pa, pb))
    order = np.argsort(t, kind="stable")
    t, axis, pos = t[order], axis[order], pos[order]
    track = np.empty((t.size, 2), dtype=np.int64)
    cur = np.array(start, dtype=np.int64)
    for i in range(t.size):  # E events; an O(E) pass, runs once per job
        cur[axis[i]] = pos[i]
        track[i] = cur
    return t, track


def true_params(values: Sequence[float] | None) -> MachineParams | None:
    """A true geometry (a1, b1, a2, b2, w mm, home1, home2 degrees) as MachineParams."""
    if values is None:
        return None
    a1, b1, a2, b2, w, h1, h2 = (float(x) for x in values)
    return MachineParams(a1, b1, a2, b2, w, math.radians(h1), math.radians(h2))


def true_geometry(true: MachineParams, profile_geometry: FiveBar) -> FiveBar:
    """The true machine's five-bar: its lengths, with the profile's pen extension if any
    (`true=` gives the five lengths; the pen's place on link 1 is the profile's)."""
    if isinstance(profile_geometry, ExtendedFiveBar):
        return ExtendedFiveBar(true.a1, true.b1, true.a2, true.b2, true.w,
                               profile_geometry.extension, profile_geometry.extension_angle)
    return true.fivebar()


def ledger_track(ledger: Sequence[Any]) -> tuple[FloatArray, IntArray]:
    """(time, positions) of a mock's ledger: the start and the end of every G1 block."""
    g1 = [e for e in ledger if e.kind == "G1"]
    if not g1:
        return np.zeros(0), np.zeros((0, 2), dtype=np.int64)
    t = np.array([g1[0].started_s] + [e.started_s for e in g1], dtype=np.float64)
    pos = np.array([g1[0].start] + [e.end for e in g1], dtype=np.int64)
    return t, pos


def executed_path(job: Job, profile: Profile, time: FloatArray, track: IntArray,
                  first_segment: int = 0, start_steps: ArrayLike | None = None,
                  true: MachineParams | None = None,
                  backlash: tuple[int, int] | None = None) -> ExecutedPath:
    """Assign recorded positions to the job's segments and measure each drawing point.

    The run started at `start_steps` (default: the start of `first_segment`). A resumed run
    that starts inside `first_segment` (on its joint-space line) finishes it in place; one
    that starts elsewhere (after homing) first travels back to the segment's start, laser
    off: those events belong to no segment (−1) and are not measured against the drawing.
    Assignment walks the events once: an event belongs to the segment being executed, and a
    segment ends at the event whose position equals its target. The pen points are those of
    the joints behind the motor counts (`compile.backlash.play`): with the machine's real
    slack `backlash` (steps per motor; None: the profile's `[motors] backlash_steps`), from
    the slack the job planned at the start.
    """
    tgt = job.steps
    n = job.n_segments
    seg = np.full(track.shape[0], -1, dtype=np.int64)
    k = first_segment
    first_event = 0
    if (start_steps is not None and k < n
            and line_param(tgt[k], tgt[k + 1], start_steps) is None):
        arrived = np.flatnonzero((track == tgt[k]).all(axis=1))
        first_event = int(arrived[0]) + 1 if arrived.size else track.shape[0]

    def skip_empty(k: int) -> int:
        while k < n and np.array_equal(tgt[k], tgt[k + 1]):
            k += 1
        return k

    k = skip_empty(k)
    for i in range(first_event, track.shape[0]):
        if k >= n:
            break
        seg[i] = k
        if track[i, 0] == tgt[k + 1, 0] and track[i, 1] == tgt[k + 1, 1]:
            k = skip_empty(k + 1)
    completed = k
    home = job.home_rad if true is None else true.home_rad
    fb = profile.geometry if true is None else true_geometry(true, profile.geometry)
    lash = profile.motors.backlash_steps if backlash is None else backlash
    joint = track
    if any(lash) or job.slack.shape[0]:
        row = min(first_segment, job.steps.shape[0] - 1)
        start = job.slack[row] if job.slack.shape[0] else (0, 0)
        joint = play(track, lash, np.minimum(start, lash))
    th = step_angles(joint, home, job.steps_per_rev)
    fwd = fb.forward_batch(th, "+" if job.assembly > 0 else "-")
    dev = np.full(track.shape[0], np.nan)
    draw_idx = np.flatnonzero((seg >= 0) & job.draw[np.maximum(seg, 0)])
    if draw_idx.size:
        dev[draw_idx] = distance_on_segments(job, fwd.points[draw_idx], track[draw_idx],
                                             seg[draw_idx])
        dev[draw_idx[~fwd.valid[draw_idx]]] = np.inf
    return ExecutedPath(time, track, fwd.points, seg, dev, completed)


def distance_on_segments(job: Job, e: FloatArray, pos: IntArray, seg: IntArray) -> FloatArray:
    """Distance of pen points `e` on draw segments `seg` to the requested curves, with the
    progress along the segment's dominant axis as the curve-parameter guess."""
    rank = (np.cumsum(job.draw) - 1)[seg]  # index among the draw segments
    s0 = job.steps[seg].astype(np.float64)
    d = job.steps[seg + 1].astype(np.float64) - s0
    ax = np.argmax(np.abs(d), axis=1)
    rows = np.arange(seg.size)
    dd = d[rows, ax]
    s = np.where(dd != 0, (pos[rows, ax] - s0[rows, ax]) / np.where(dd != 0, dd, 1.0), 0.0)
    return distance_to_request(job, e, rank, np.clip(s, 0.0, 1.0))


#: A pulse within this of the profile's up (down) pulse counts as pen up (down), µs: the
#: firmware's 4 µs timer count plus the jitter of its edges, which the step interrupt can
#: delay while steps are dense (firmware/README.md, pen servo: single pulses up to 52 µs
#: off, two frames in a row 30.1 µs short in the emulator — at 30 µs here that run's line
#: said "travel steps with the pen down 121"). Still under the ~90 µs a frame of
#: configs/pen-servo.toml's moves, so a step in a moving frame is one with the pen neither
#: up nor down (a slower move's first and last frames, within 60 µs of its ends, count as
#: there: 60 µs is about 5° of a hobby servo).
PEN_MATCH_US = 60.0


@dataclass(frozen=True)
class PenReport:
    """What the pen servo did during a run, from the recorded pins (docs/protocol.md 6.2):
    lifts, steps on travel segments while the pen was not up, steps on drawing segments
    while it was not down, and the shortest time from a pen move's end (its pulse at the
    new position) to the next step."""

    lifts: int
    travel_down_steps: int
    draw_up_steps: int
    min_settle_ms: float  # inf when no pen move was followed by a step

    def line(self) -> str:
        """`pen: <n> lifts; travel steps with the pen down <k>; …` as `plot` prints it."""
        t = "none" if self.min_settle_ms == float("inf") else f"{self.min_settle_ms:.0f}"
        return (f"pen: {self.lifts} lifts; travel steps with the pen down "
                f"{self.travel_down_steps}; drawing steps with the pen up "
                f"{self.draw_up_steps}; shortest settle before motion {t} ms")


def pen_report(job: Job, profile: Profile, pulses: list[tuple[int, int]], freq: float,
               ex: ExecutedPath) -> PenReport:
    """Check the pen against the steps: `pulses` are the servo's (rise, width) in cycles at
    `freq` Hz (simtrace.Trace.pen_pulses), `ex` the executed path with its time in seconds.

    Each step is judged by the last pulse before it (the servo's command then): on a travel
    segment (or outside the job) it must be the up pulse, on a drawing segment the down
    pulse. A move ends at the first pulse of a run at a new up or down width; its settle is
    the time from there to the next step."""
    pen = profile.pen
    if pen is None or not pulses:
        return PenReport(0, 0, 0, float("inf"))
    up, down = pen.pulse_us(pen.up_position), pen.pulse_us(pen.down_position)
    rise = np.array([r for r, _ in pulses], dtype=np.float64) / freq
    width = np.array([w for _, w in pulses], dtype=np.float64) / freq * 1e6
    if width.size >= 3:  # median of 3: one late edge never flips a frame's state
        width[1:-1] = np.median(np.stack((width[:-2], width[1:-1], width[2:])), axis=0)
    state = np.where(np.abs(width - up) <= PEN_MATCH_US, 1,
                     np.where(np.abs(width - down) <= PEN_MATCH_US, -1, 0))
    at = np.searchsorted(rise, ex.time, side="right") - 1
    step_state = np.where(at >= 0, state[np.maximum(at, 0)], 0)
    drawing = (ex.segment >= 0) & job.draw[np.maximum(ex.segment, 0)]
    travel_down = int(((~drawing) & (step_state != 1)).sum())
    draw_up = int((drawing & (step_state != -1)).sum())
    arrive = np.flatnonzero((state != 0) & np.concatenate(([True], state[1:] != state[:-1])))
    seq = state[arrive]
    lifts = int(((seq[1:] == 1) & (seq[:-1] == -1)).sum())
    settle = float("inf")
    for j, i in enumerate(arrive.tolist()):
        k = int(np.searchsorted(ex.time, rise[i], side="left"))
        end = rise[arrive[j + 1]] if j + 1 < arrive.size else np.inf
        if k < ex.time.size and ex.time[k] < end:
            settle = min(settle, float(ex.time[k] - rise[i]) * 1e3)
    return PenReport(lifts, travel_down, draw_up, settle)
