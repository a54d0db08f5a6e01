"""Laser-off moves between scanlines: straight joint-space lines from rest to rest, timed on
the firmware's staircase like a drawing's travel, and checked.

`joint_move` plans the continuous trapezoid (`compile.planner.plan`), cuts its ramps into
pieces whose speeds differ by `JUMP_SHARE` of the junction jump (`ramp_fractions`, new
targets on the same joint-space line, whole steps, at least `MIN_PIECE_STEPS` each), and
raises the pieces' own shortest durations to the least that meet every staircase limit
(`enforce_staircase`).  `check_move` samples the line (every `CHECK_RAD`) through forward
kinematics: the loop must close in the machine's assembly, the joint limits and the type-2
margin hold (the arms may pass a type-1 singularity under power, as any travel may not in a
drawing: here the moves are short steps between neighbouring scanlines, or the way back
of a one-way scan, between two checked poses).
"""

from __future__ import annotations

import math

import numpy as np

from fivebar_host import protocol
from fivebar_host.compile import planner
from fivebar_host.compile.steps import step_angles
from fivebar_host.config import Profile
from fivebar_host.errors import JobError
from fivebar_host.toolpath.segment import PoseChecker, wrap_to_limits
from kinematics.arrays import FloatArray, IntArray

JUMP_SHARE = 0.6
MIN_PIECE_STEPS = 3
CHECK_RAD = 0.005


def joint_move(profile: Profile, start: IntArray, end: IntArray) -> tuple[IntArray, IntArray]:
    """Pieces of the move from absolute steps `start` to `end`: their end targets (K, 2)
    and durations (K,) µs (none when they are equal)."""
    mo, motion = profile.motors, profile.motion
    s0, s1 = np.asarray(start, dtype=np.int64), np.asarray(end, dtype=np.int64)
    if np.array_equal(s0, s1):
        return np.zeros((0, 2), dtype=np.int64), np.zeros(0, dtype=np.int64)
    th = step_angles(np.stack((s0, s1)), mo.home_rad, mo.steps_per_rev)
    dth = (th[1] - th[0])[None, :]
    alpha, jump = motion.max_joint_rad_s2, motion.junction_jump_rad_s
    dist = np.abs(dth).max(axis=1)
    pl = planner.plan(dth, np.zeros(1), np.full(1, np.inf), motion.max_joint_rad_s, alpha,
                      junction_jump_rad_s=jump, min_duration_s=protocol.P_MIN_US * 1e-6)
    _, f1 = planner.ramp_fractions(pl, dist, alpha, JUMP_SHARE * jump / alpha,
                                   MIN_PIECE_STEPS * mo.rad_per_step)
    targets = np.rint(s0[None, :] + f1[:, None] * (s1 - s0)[None, :]).astype(np.int64)
    targets[-1] = s1
    keep = np.concatenate(([True], (np.diff(targets, axis=0) != 0).any(axis=1)))
    keep[0] = bool((targets[0] != s0).any())
    targets = targets[keep]
    all_st = np.concatenate((s0[None, :], targets))
    dq = np.diff(step_angles(all_st, mo.home_rad, mo.steps_per_rev), axis=0)
    lo = planner.cap_durations_us(dq, np.zeros(dq.shape[0]), np.full(dq.shape[0], np.inf),
                                  motion.max_joint_rad_s, protocol.P_MIN_US)
    dur = planner.enforce_staircase(dq, lo, None, alpha, jump)
    return targets, np.asarray(dur, dtype=np.int64)


def check_move(profile: Profile, checker: PoseChecker, start: IntArray, end: IntArray,
               what: str) -> None:
    """JobError when the straight joint-space move leaves the safe workspace (module doc)."""
    mo = profile.motors
    th = step_angles(np.stack((np.asarray(start), np.asarray(end))), mo.home_rad,
                     mo.steps_per_rev)
    n = max(2, math.ceil(float(np.abs(th[1] - th[0]).max()) / CHECK_RAD) + 1)
    q = th[0] + np.linspace(0.0, 1.0, n)[:, None] * (th[1] - th[0])
    pts, valid = checker.forward(q)
    if not valid.all():
        raise JobError(f"{what}: the linkage cannot close along the move", None, "reach")
    q, _ok1, _ok2 = wrap_to_limits(q, mo.limits_rad)
    code, _ = checker.codes(q, pts, check_type1=False)
    bad = np.flatnonzero(code)
    if bad.size:
        i = int(bad[0])
        _, m = checker.codes(q[i:i + 1], pts[i:i + 1], check_type1=False)
        raise JobError(f"{what}: at ({pts[i, 0]:.2f}, {pts[i, 1]:.2f}) mm "
                       + checker.explain(int(code[i]), q[i], pts[i], m[0]), None, "reach")


def path_points(profile: Profile, checker: PoseChecker, steps: IntArray) -> FloatArray:
    """Pen points (N, 2) of absolute steps."""
    th = step_angles(steps, profile.motors.home_rad, profile.motors.steps_per_rev)
    pts, _ = checker.forward(th)
    return pts
