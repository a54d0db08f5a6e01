"""Firmware programs: a compiled job (or a frame, a jog) as firmware line bodies.

Pure (no I/O): the sender streams what these functions build, the daemon rebuilds a stream
from its inputs to check what a controller kept, and the resume logic maps a finished line
back to its job segment through `Program.segment`. Moves the host adds itself (travel back to
a segment, framing, jogs) are checked against the profile's workspace and ramped at
`SAFE_SHARE` of the joint limits, since the job planner does not time them.
"""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fivebar_host import protocol
from fivebar_host.compile import Job, pen_setup_lines, pen_switch_lines
from fivebar_host.compile.steps import absolute_steps, step_angles
from fivebar_host.config import Profile
from fivebar_host.run.errors import SendError

#: Share of the joint speed and acceleration limits used by moves the host adds itself
#: (travel back on resume, jogs, framing): they are not timed by the job planner.
SAFE_SHARE = 0.5


def line_param(p0: ArrayLike, p1: ArrayLike, pos: ArrayLike) -> float | None:
    """Where `pos` lies on the straight joint-space line p0 → p1: t in [0, 1] measured on
    the axis that moves most, when every axis is within one step of the line; else None.
    (The DDA spreads each motor's steps evenly, so a move stopped part-way sits there.)"""
    s0 = np.asarray(p0, dtype=np.float64)
    d = np.asarray(p1, dtype=np.float64) - s0
    q = np.asarray(pos, dtype=np.float64)
    if not d.any():
        return 0.0 if np.array_equal(q, s0) else None
    ax = int(np.argmax(np.abs(d)))
    t = float((q[ax] - s0[ax]) / d[ax])
    if not 0.0 <= t <= 1.0 or not bool(np.all(np.abs(s0 + t * d - q) <= 1.0 + 1e-9)):
        return None
    return t


_G1_WORDS = re.compile(r"\b([AB])(-?\d+)")


@dataclass(frozen=True)
class Program:
    """Firmware line bodies and, per line, the job segment it executes (−1: no segment)."""

    bodies: list[str]
    segment: NDArray[np.int64]

    def finished_segments(self, first_line: int, done_line: int, start: int) -> int:
        """Index of the first segment not finished, given the firmware's last finished line."""
        idx = done_line - first_line
        if idx < 0:
            return start
        idx = min(idx, len(self.bodies) - 1)
        segs = self.segment[: idx + 1]
        segs = segs[segs >= 0]
        return int(segs.max()) + 1 if segs.size else start

    def positions(self, start_position: ArrayLike) -> NDArray[np.int64]:
        """Firmware position after each line, from `start_position` (programs are absolute,
        `G90`; only `G1` lines move)."""
        pos = np.asarray(start_position, dtype=np.int64).copy()
        out = np.empty((len(self.bodies), 2), dtype=np.int64)
        for i, body in enumerate(self.bodies):
            if body.split(" ", 1)[0] == "G1":
                for axis, value in _G1_WORDS.findall(body):
                    pos["AB".index(axis)] = int(value)
            out[i] = pos
        return out

    def on_path(self, first_line: int, done_line: int, start_position: ArrayLike,
                position: ArrayLike) -> bool:
        """Whether `position` is where this program can leave the motors when `done_line`
        is the last line it executed to its end: on the straight joint-space line from the
        position after that line to the end of the next line that moves (within a step)."""
        pts = self.positions(start_position)
        idx = done_line - first_line
        if not -1 <= idx < len(self.bodies):
            return False
        p0 = np.asarray(start_position, dtype=np.int64) if idx < 0 else pts[idx]
        later = pts[idx + 1:]
        moving = np.flatnonzero(np.any(later != p0, axis=1))
        p1 = later[moving[0]] if moving.size else p0
        return line_param(p0, p1, position) is not None


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


def travel_lines(profile: Profile, job_assembly: int, start: ArrayLike,
                 end: ArrayLike, what: str) -> list[str]:
    """Checked, ramped, laser-off G1 lines from `start` to `end` (absolute steps)."""
    check_joint_move(profile, job_assembly, start, end, what)
    mo = profile.motors
    pieces = _ramped_move(start, end, mo.rad_per_step,
                          SAFE_SHARE * profile.motion.max_joint_rad_s,
                          SAFE_SHARE * profile.motion.max_joint_rad_s2)
    return [protocol.g1(a, b, p, 0) for a, b, p in pieces]


def job_bodies(job: Job, profile: Profile, laser: bool, first: int,
               first_line: str | None = None, end: int | None = None
               ) -> tuple[list[str], list[int]]:
    """Firmware lines for segments `first`… `end` − 1 (None: to the job's end) of `job` and
    the segment of each (−1: none). The pen goes up after the last one (a pen-change stop
    may cut a run of drawing segments: `Job.pauses`).

    Laser job (`laser`): `M3 S0` once, then drawing segments carry the profile's power.
    Pen job: S0 everywhere, pen down before and pen up after each run of drawing segments
    (and dwells with the tool on, `Job.tool_on`; `compile.pen_switch_lines`: the servo's
    `M280` with its move and settle time on a pen profile, else `M3 S0` / `M5`). A dwell is
    `G1 P<µs> S<power>` without A/B (`compile.dwell`). `first_line` replaces the first
    segment's G1 (a partial segment). The same encoding as `fivebar convert` (job.encode_lines)."""
    n = job.n_segments if end is None else end
    power = job.power if laser else np.zeros_like(job.power)
    draw = job.tool_on.tolist()
    dwell = job.is_dwell.tolist()
    bodies: list[str] = []
    seg: list[int] = []
    if laser:
        bodies.append(f"{profile.laser.on_command} S0")
        seg.append(-1)
    a = job.steps[1:, 0].tolist()
    b = job.steps[1:, 1].tolist()
    dur = job.duration_us.tolist()
    pw = power.tolist()
    down, up = pen_switch_lines(profile)
    for k in range(first, n):
        if not laser and draw[k] and (k == first or not draw[k - 1]):
            bodies.append(down)
            seg.append(-1)
        line = first_line if (k == first and first_line is not None) else protocol.g1(
            None if dwell[k] else a[k], None if dwell[k] else b[k], dur[k], pw[k])
        bodies.append(line)
        seg.append(k)
        if not laser and draw[k] and (k == n - 1 or not draw[k + 1]):
            bodies.append(up)
            seg.append(-1)
    if not bodies or bodies[-1] != "M5":
        bodies.append("M5")
        seg.append(-1)
    return bodies, seg


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
    bodies = ["G90", *pen_setup_lines(profile), "M5"]
    seg: list[int] = [-1] * len(bodies)
    k = start_segment
    steps = job.steps
    pos = np.asarray(position, dtype=np.int64)
    partial: str | None = None
    if k < job.n_segments and not np.array_equal(pos, steps[k]):
        t = line_param(steps[k], steps[k + 1], pos)
        if t is not None and t > 0.0:
            rest = max(protocol.P_MIN_US, round(float(job.duration_us[k]) * (1.0 - t)))
            at_end = np.array_equal(pos, steps[k + 1])
            pw = int(job.power[k]) if laser and not at_end else 0
            partial = protocol.g1(int(steps[k + 1, 0]), int(steps[k + 1, 1]), rest, pw)
        else:
            back = travel_lines(profile, job.assembly, pos, steps[k],
                                f"travel back to segment {k + 1}")
            bodies += back
            seg += [-1] * len(back)
    more, mseg = job_bodies(job, profile, laser, k, partial, end_segment)
    return Program(bodies + more, np.asarray(seg + mseg, dtype=np.int64))


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
    bodies = ["G90", f"{profile.laser.on_command} S0"]
    bodies += travel_lines(profile, job.assembly, position, st[0], "frame: travel to the outline")
    feed = profile.motion.travel_feed_mm_s
    wmax = SAFE_SHARE * profile.motion.max_joint_rad_s
    seglen = np.hypot(*np.diff(outline, axis=0).T)
    dth = np.abs(np.diff(inv.angles, axis=0)).max(axis=1)
    dur = np.maximum(seglen / feed, dth / wmax)
    for k in range(1, st.shape[0]):
        if np.array_equal(st[k], st[k - 1]):
            continue
        bodies.append(protocol.g1(int(st[k, 0]), int(st[k, 1]),
                                  max(protocol.P_MIN_US, round(float(dur[k - 1]) * 1e6)), 0))
    bodies += travel_lines(profile, job.assembly, st[-1], (0, 0), "frame: return home")
    bodies.append("M5")
    return Program(bodies, np.full(len(bodies), -1, dtype=np.int64))


def jog_lines(profile: Profile, assembly: int, mode: str, position: Sequence[int], *,
              motor: str | None = None, steps: int = 0,
              dxy_mm: tuple[float, float] | None = None, checked: bool = True) -> list[str]:
    """Ramped lines that move one motor by `steps` or the pen by `dxy_mm`.

    `checked=False` is for a motor jog while the position is unknown (setting the arms up
    before homing): the move is not checked against limits or singularities, since nothing
    is known to check against; a pen jog always needs a known position."""
    pos = np.asarray(position, dtype=np.int64)
    if motor is not None:
        target = pos.copy()
        target["AB".index(motor)] += steps
        what = f"jog motor {motor} by {steps} steps"
        if not checked:
            mo = profile.motors
            pieces = _ramped_move(pos, target, mo.rad_per_step,
                                  SAFE_SHARE * profile.motion.max_joint_rad_s,
                                  SAFE_SHARE * profile.motion.max_joint_rad_s2)
            return ["G90", *(protocol.g1(a, b, p, 0) for a, b, p in pieces)]
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
    return ["G90", *travel_lines(profile, assembly, pos, target, what)]
