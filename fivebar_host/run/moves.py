"""The programs the host streams: a job's remainder from where the machine stands, the
travel back to a segment, the frame of a drawing, jogs (typed `Program`s, `fivebar_host.program`).

Pure (no I/O): the sender streams what these functions build, the daemon rebuilds a stream
from its inputs to check what a controller kept, and the resume logic maps a finished line
back to its job segment through `Program.segment`. Moves the host adds itself (travel back to
a segment, framing, jogs) are checked against the profile's workspace and ramped at
`SAFE_SHARE` of the joint limits, since the job planner does not time them.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from fivebar_host import protocol
from fivebar_host.compile import Job
from fivebar_host.compile.emit import job_program, raster_program, setup, tool_on_item
from fivebar_host.compile.steps import absolute_steps, step_angles
from fivebar_host.config import Profile
from fivebar_host.program import Kind, Program, line_param
from fivebar_host.run.errors import SendError
from kinematics.arrays import IntArray

#: Share of the joint speed and acceleration limits used by moves the host adds itself
#: (travel back on resume, jogs, framing): they are not timed by the job planner.
SAFE_SHARE = 0.5


def _ramped_move(start: ArrayLike, end: ArrayLike, rad_per_step: float,
                 max_rad_s: float, max_rad_s2: float, piece_s: float = 0.02
                 ) -> list[tuple[int, int, int]]:
    """A joint-space straight move from rest to rest as (A, B, P µs) pieces.

    Trapezoidal speed profile on the axis that moves most (v ≤ max_rad_s, a ≤ max_rad_s2),
    cut in pieces of `piece_s`; every piece ends on the straight line, rounded once to steps.
    """
    s0 = np.asarray(start, dtype=np.float64)
    d = np.asarray(end, dtype=np.float64) - s0
    dist = float(np.abs(d).max()) * rad_per_step
    if dist == 0.0:
        return []
    v, a = max_rad_s, max_rad_s2
    t_acc = v / a
    if a * t_acc * t_acc > dist:  # triangle profile
        t_acc = math.sqrt(dist / a)
        v = a * t_acc
    t_cruise = (dist - a * t_acc * t_acc) / v
    total = 2 * t_acc + t_cruise

    def s_at(t: float) -> float:
        if t < t_acc:
            return 0.5 * a * t * t
        if t < t_acc + t_cruise:
            return 0.5 * a * t_acc * t_acc + v * (t - t_acc)
        r = total - t
        return dist - 0.5 * a * r * r

    n = max(1, math.ceil(total / piece_s))
    times = np.linspace(0.0, total, n + 1)
    frac = np.array([min(1.0, s_at(float(t)) / dist) for t in times])
    frac[-1] = 1.0
    pts = np.rint(s0[None, :] + frac[:, None] * d[None, :]).astype(np.int64)
    out: list[tuple[int, int, int]] = []
    t_prev = 0.0
    for i in range(1, n + 1):
        if np.array_equal(pts[i], pts[i - 1]) and i < n:
            continue
        dt = times[i] - t_prev
        t_prev = times[i]
        out.append((int(pts[i, 0]), int(pts[i, 1]), max(protocol.P_MIN_US, round(dt * 1e6))))
    return out


def check_joint_move(profile: Profile, job_assembly: int, start: ArrayLike,
                     end: ArrayLike, what: str) -> None:
    """Refuse a host-added joint-space move that would leave the safe workspace.

    Samples the straight joint-space line every 0.005 rad: the loop must close in the job's
    assembly, the type-2 margin must clear the profile's minimum (the type-1 singularity is
    allowed: the motor drives through it) and the motor angles must stay within limits.
    """
    fb = profile.geometry
    spr = profile.motors.steps_per_rev
    home = profile.motors.home_rad
    th0 = step_angles(np.asarray([start]), home, spr)[0]
    th1 = step_angles(np.asarray([end]), home, spr)[0]
    n = max(2, math.ceil(float(np.abs(th1 - th0).max()) / 0.005) + 1)
    th = th0[None, :] + np.linspace(0.0, 1.0, n)[:, None] * (th1 - th0)[None, :]
    for i, (lo, hi) in enumerate(profile.motors.limits_rad):
        bad = np.flatnonzero((th[:, i] < lo - 1e-9) | (th[:, i] > hi + 1e-9))
        if bad.size:
            raise SendError(f"{what}: motor {i + 1} would reach "
                            f"{math.degrees(th[bad[0], i]):.2f}°, outside its limits "
                            f"[{math.degrees(lo):g}°, {math.degrees(hi):g}°]")
    fwd = fb.forward_batch(th, "+" if job_assembly > 0 else "-")
    if not fwd.valid.all():
        raise SendError(f"{what}: the linkage cannot close along the move (at motor angles "
                        f"{np.degrees(th[np.flatnonzero(~fwd.valid)[0]]).round(2).tolist()}°)")
    m2 = fb.singularity_margins(th, fwd.points)[:, 2] * job_assembly
    worst = int(np.argmin(m2))
    if m2[worst] < profile.kinematics.min_type2_margin_rad:
        p = fwd.points[worst]
        raise SendError(f"{what}: passes within {math.degrees(m2[worst]):.1f}° of a type-2 "
                        f"singularity at ({p[0]:.1f}, {p[1]:.1f}) mm (minimum "
                        f"{math.degrees(profile.kinematics.min_type2_margin_rad):g}°); "
                        "move the arms by hand to the home pose and run `fivebar home`")


def _ramped(profile: Profile, start: ArrayLike, end: ArrayLike) -> Program:
    """Laser-off moves from `start` to `end` at `SAFE_SHARE` of the joint limits."""
    mo = profile.motors
    pieces = _ramped_move(start, end, mo.rad_per_step,
                          SAFE_SHARE * profile.motion.max_joint_rad_s,
                          SAFE_SHARE * profile.motion.max_joint_rad_s2)
    if not pieces:
        return Program.empty()
    a, b, p = np.asarray(pieces, dtype=np.int64).T
    return Program.moves(a, b, p, 0)


def travel(profile: Profile, job_assembly: int, start: ArrayLike, end: ArrayLike,
           what: str) -> Program:
    """Checked, ramped, laser-off moves from `start` to `end` (absolute steps)."""
    check_joint_move(profile, job_assembly, start, end, what)
    return _ramped(profile, start, end)


def slack_travel(profile: Profile, job_assembly: int, start: ArrayLike, end: ArrayLike,
                 end_slack: ArrayLike, what: str) -> Program:
    """`travel` to motor counts `end` whose last move takes each motor's slack up the way
    `end_slack` says (compile/backlash.py Eq. B1): B, the motor last moved up, so it comes
    into `end` from B below; 0, from B above. Whatever the slack was at `start` (a fault may
    stop a motor anywhere in it), a monotone move of B leaves the joint at `end` less
    `end_slack`, as the job (or the rest convention, 0) assumes. No slack: `travel`."""
    b = np.asarray(profile.motors.backlash_steps, dtype=np.int64)
    e = np.asarray(end, dtype=np.int64)
    if not b.any():
        return travel(profile, job_assembly, start, e, what)
    via = e - np.where(np.asarray(end_slack, dtype=np.int64) > 0, b, -b)
    return Program.join([travel(profile, job_assembly, start, via, what),
                         travel(profile, job_assembly, via, e, f"{what} (slack take-up)")])


def build_program(job: Job, profile: Profile, laser: bool, start_segment: int,
                  position: ArrayLike, end_segment: int | None = None) -> Program:
    """The lines that run segments `start_segment`… `end_segment` − 1 (None: to the job's
    end; a pen-change stop ends a program early) of `job` from firmware steps `position`.

    If `position` lies inside segment `start_segment` (on its joint-space line, within one
    step) the first move finishes that segment with the remaining share of its duration;
    otherwise a checked laser-off travel reaches its start first. A position at the
    segment's end (its steps all issued, its time not yet over) gives a minimal laser-off
    line that stands for it, so nothing is redrawn. Power is sent only with `laser` (the
    CLI's explicit `--laser` opt-in).
    """
    parts = [setup(profile, laser)]
    k = start_segment
    steps = job.steps
    pos = np.asarray(position, dtype=np.int64)
    if job.raster is not None:
        return Program.join([*parts, *_raster_rest(job, profile, laser, k, pos, end_segment)])
    partial: Program | None = None
    if k < job.n_segments and not np.array_equal(pos, steps[k]):
        t = line_param(steps[k], steps[k + 1], pos)
        snap = None if t is not None else snap_to_line(steps[k], steps[k + 1], pos)
        if snap is not None:
            t = snap[0]
        if t is not None and t > 0.0:
            rest = max(protocol.P_MIN_US, round(float(job.duration_us[k]) * (1.0 - t)))
            at_end = np.array_equal(pos, steps[k + 1])
            pw = int(job.power[k]) if laser and not at_end else 0
            partial = Program.moves(steps[k + 1, 0], steps[k + 1, 1], rest, pw, k)
            if snap is not None:  # back onto the segment's line first (no segment of its own)
                q = snap[1]
                partial = Program.join([Program.moves(q[0], q[1], protocol.P_MIN_US, pw),
                                        partial])
        else:  # ends with the slack the job has there (Job.slack; none: taken down)
            slack = job.slack[k] if job.slack.shape[0] else np.zeros(2, dtype=np.int64)
            parts.append(slack_travel(profile, job.assembly, pos, steps[k], slack,
                                      f"travel back to segment {k + 1}"))
    parts.append(job_program(job, profile, laser, k, end_segment, partial))
    return Program.join(parts)


#: How far (steps, each axis) a position may lie from a segment's joint-space line and still
#: finish it (`snap_to_line`).
SNAP_STEPS = 3.0


def snap_to_line(s0: IntArray, s1: IntArray, pos: IntArray) -> tuple[float, IntArray] | None:
    """A position near segment s0 → s1 but more than a step off its line: (t, q), q a
    whole-step point of the line ahead of the position on every moving axis (so that the
    move to q and on to s1 issue no step backwards) at the line's parameter t, when every
    axis is within `SNAP_STEPS` of the line; else None.  A segment interrupted again and
    again is finished each time from where it stopped, on a line from there to its end,
    which the DDA follows within a step: a second stop can sit two steps off the segment's
    own line, and with `line_param`'s one step the resume travelled back to the segment's
    start and drew its first part again (a daemon test's link breaking every 9 lines,
    `tests/test_serve.py`).  Moving to q first keeps every later stop within 1.5 steps."""
    d = (s1 - s0).astype(np.float64)
    mov = d != 0.0
    if not mov.any():
        return None
    ax = int(np.argmax(np.abs(d)))
    t = float((pos[ax] - s0[ax]) / d[ax])
    if not 0.0 < t < 1.0 or not bool(np.all(np.abs(s0 + t * d - pos) <= SNAP_STEPS)):
        return None
    ahead = float(np.max((pos[mov] - s0[mov]) / d[mov]))  # the line passes pos's every axis
    if ahead >= 1.0:
        return 1.0, np.asarray(s1, dtype=np.int64)
    on = s0 + ahead * d
    q = np.where(d > 0, np.ceil(on - 1e-9), np.where(d < 0, np.floor(on + 1e-9), s0))
    return ahead, q.astype(np.int64)


def _raster_rest(job: Job, profile: Profile, laser: bool, k: int, pos: IntArray,
                 end_segment: int | None) -> list[Program]:
    """A raster job resumed at segment `k`: inside a scanline it restarts at the scanline's
    start (its overscan: the pen at scan speed again before its next pixel) with the pixels
    it had already reached at power 0, so nothing is burned twice (docs/raster.md)."""
    r = job.raster
    assert r is not None
    k0 = r.restart_segment(k) if k < job.n_segments else k
    lead = None
    if k0 < job.n_segments and not np.array_equal(pos, job.steps[k0]):
        lead = travel(profile, job.assembly, pos, job.steps[k0],
                      f"travel back to segment {k0 + 1}")
    into = _steps_into(job.steps, k, pos) if k < job.n_segments else 0.0
    reached = k if k0 < k or into > 0.0 else None
    return [raster_program(job, profile, laser, k0, end_segment, reached, lead, into)]


def _steps_into(steps: IntArray, k: int, pos: IntArray) -> float:
    """How far into segment k (a fraction of its time) a run stopped at firmware steps
    `pos` had surely got: the time of the last step it issued of the motor with the most
    steps, (i − ½) / n of the segment (the DDA's time of step i of n, fb_fast.h), 0 when
    `pos` is not on the segment's way.  The surely-reached time, not a later guess: a
    pixel changed after it is burned again whole (at most a step's time of it twice),
    never skipped."""
    d = steps[k + 1] - steps[k]
    i = int(np.argmax(np.abs(d)))
    n = abs(int(d[i]))
    done = (int(pos[i]) - int(steps[k, i])) * (1 if d[i] > 0 else -1)
    if n == 0 or not 0 < done <= n:
        return 0.0
    return (done - 0.5) / n


# ------------------------------------------------------------------ framing and jogging
def frame_program(job: Job, profile: Profile, position: Sequence[int],
                  spacing_mm: float = 0.5) -> Program:
    """Lines that trace the job's bounding box with the laser off, then return home.

    The outline is sampled every `spacing_mm`, solved in the job's working mode and checked
    like the job itself (reach, limits, margins); the returns are checked ramped travels.
    """
    fb = profile.geometry
    x0, y0, x1, y1 = job.placement.machine_bbox
    corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]], dtype=np.float64)
    pts = [corners[:1]]
    for p, q in itertools.pairwise(corners):
        n = max(1, math.ceil(float(np.hypot(*(q - p))) / spacing_mm))
        pts.append(p + (q - p) * (np.arange(1, n + 1) / n)[:, None])
    outline = np.concatenate(pts)
    inv = fb.inverse_batch(outline, job.mode)
    if not inv.valid.all():
        i = int(np.flatnonzero(~inv.valid)[0])
        raise SendError(f"frame: outline point ({outline[i, 0]:.2f}, {outline[i, 1]:.2f}) mm "
                        "is out of reach in working mode " + job.mode)
    m = fb.singularity_margins(inv.angles, outline)
    kin = profile.kinematics
    if (np.abs(m[:, :2]).min() < kin.min_type1_margin_rad
            or (m[:, 2] * job.assembly).min() < kin.min_type2_margin_rad):
        raise SendError("frame: the drawing's bounding box comes closer to a singularity than "
                        "the profile allows (the drawing itself may still be fine)")
    st = absolute_steps(inv.angles, profile.motors.home_rad, profile.motors.steps_per_rev)
    to_outline = travel(profile, job.assembly, position, st[0], "frame: travel to the outline")
    feed = profile.motion.travel_feed_mm_s
    wmax = SAFE_SHARE * profile.motion.max_joint_rad_s
    seglen = np.hypot(*np.diff(outline, axis=0).T)
    dth = np.abs(np.diff(inv.angles, axis=0)).max(axis=1)
    dur = np.maximum(seglen / feed, dth / wmax)
    moving = np.flatnonzero(np.any(st[1:] != st[:-1], axis=1)) + 1
    p_us = np.maximum(protocol.P_MIN_US, np.rint(dur[moving - 1] * 1e6)).astype(np.int64)
    trace = Program.moves(st[moving, 0], st[moving, 1], p_us, 0)
    back = travel(profile, job.assembly, st[-1], (0, 0), "frame: return home")
    return Program.join([Program.command(Kind.ABSOLUTE), tool_on_item(profile), to_outline,
                         trace, back, Program.command(Kind.TOOL_OFF)])


def jog_program(profile: Profile, assembly: int, mode: str, position: Sequence[int], *,
                motor: str | None = None, steps: int = 0,
                dxy_mm: tuple[float, float] | None = None, checked: bool = True) -> Program:
    """Ramped moves that move one motor by `steps` or the pen by `dxy_mm`.

    `checked=False` is for a motor jog while the position is unknown (setting the arms up
    before homing): the move is not checked against limits or singularities, since nothing
    is known to check against; a pen jog always needs a known position."""
    pos = np.asarray(position, dtype=np.int64)
    if motor is not None:
        target = pos.copy()
        target["AB".index(motor)] += steps
        what = f"jog motor {motor} by {steps} steps"
        if not checked:  # slack taken up downward, as at rest (slack_travel)
            b = np.asarray(profile.motors.backlash_steps, dtype=np.int64)
            return Program.join([Program.command(Kind.ABSOLUTE),
                                 _ramped(profile, pos, target + b), _ramped(profile,
                                                                            target + b,
                                                                            target)])
    else:
        assert dxy_mm is not None
        fb = profile.geometry
        mo = profile.motors
        th = step_angles(pos[None, :], mo.home_rad, mo.steps_per_rev)
        p = fb.forward_batch(th, "+" if assembly > 0 else "-")
        if not p.valid[0]:
            raise SendError("jog: the current motor position does not close the linkage")
        goal = p.points[0] + np.asarray(dxy_mm)
        inv = fb.inverse_batch(goal[None, :], mode)
        if not inv.valid[0]:
            raise SendError(f"jog: ({goal[0]:.2f}, {goal[1]:.2f}) mm is out of reach in "
                            f"working mode {mode}")
        target = absolute_steps(inv.angles, mo.home_rad, mo.steps_per_rev)[0]
        what = f"jog the pen to ({goal[0]:.2f}, {goal[1]:.2f}) mm"
    # the slack left taken up downward, the rest convention a job starts from (backlash.py)
    return Program.command(Kind.ABSOLUTE) + slack_travel(profile, assembly, pos, target,
                                                         (0, 0), what)
