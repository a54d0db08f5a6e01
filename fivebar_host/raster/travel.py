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

import itertools
import math
from collections.abc import Callable

import numpy as np

from fivebar_host import protocol
from fivebar_host.compile import planner, ramps, staircase
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
    return joint_moves(profile, np.reshape(start, (1, 2)), np.reshape(end, (1, 2)))[0]


def joint_moves(profile: Profile, starts: IntArray, ends: IntArray
                ) -> list[tuple[IntArray, IntArray]]:
    """`joint_move` of every row of `starts` (M, 2) to the same row of `ends`, planned
    together: each move on its own from rest to rest (the planner's steps are per segment,
    and a motionless segment between two moves keeps the staircase from joining them), so
    the pieces are those of one move at a time."""
    mo, motion = profile.motors, profile.motion
    s0, s1 = np.asarray(starts, dtype=np.int64), np.asarray(ends, dtype=np.int64)
    none = (np.zeros((0, 2), dtype=np.int64), np.zeros(0, dtype=np.int64))
    out = [none] * s0.shape[0]
    mv = np.flatnonzero((s0 != s1).any(axis=1))
    if not mv.size:
        return out
    a, b = s0[mv], s1[mv]
    dth = (step_angles(b, mo.home_rad, mo.steps_per_rev)
           - step_angles(a, mo.home_rad, mo.steps_per_rev))
    alpha, jump = motion.max_joint_rad_s2, motion.junction_jump_rad_s
    m = mv.shape[0]
    dist = np.abs(dth).max(axis=1)
    pl = planner.plan(dth, np.zeros(m), np.full(m, np.inf), motion.max_joint_rad_s, alpha,
                      stop_after=np.ones(m, dtype=bool), junction_jump_rad_s=jump,
                      min_duration_s=protocol.P_MIN_US * 1e-6)
    count, f1 = ramps.ramp_fractions(pl, dist, alpha, JUMP_SHARE * jump / alpha,
                                       MIN_PIECE_STEPS * mo.rad_per_step)
    move = np.repeat(np.arange(m), count)
    last = np.cumsum(count) - 1
    targets = np.rint(a[move] + f1[:, None] * (b - a)[move]).astype(np.int64)
    targets[last] = b
    prev = np.empty_like(targets)  # the target before each piece's: its move's start first
    prev[1:] = targets[:-1]
    prev[last[:-1] + 1] = a[1:]
    prev[0] = a[0]
    keep = (targets != prev).any(axis=1)
    targets, move = targets[keep], move[keep]
    first = np.concatenate(([True], move[1:] != move[:-1]))
    prev = np.empty_like(targets)  # the kept target before each kept one
    prev[1:] = targets[:-1]
    prev[first] = a[move[first]]
    dq = (step_angles(targets, mo.home_rad, mo.steps_per_rev)
          - step_angles(prev, mo.home_rad, mo.steps_per_rev))
    lo = planner.cap_durations_us(dq, np.zeros(dq.shape[0]), np.full(dq.shape[0], np.inf),
                                  motion.max_joint_rad_s, protocol.P_MIN_US)
    # a motionless segment before every move but the first: each move starts and ends at
    # rest, and the staircase never looks across it
    sep = np.flatnonzero(first)[1:]
    dur = staircase.enforce_staircase(np.insert(dq, sep, 0.0, axis=0), np.insert(lo, sep, 0),
                                      None, alpha, jump)
    dur = np.delete(dur, sep + np.arange(sep.shape[0]))
    cuts = [*np.flatnonzero(first).tolist(), targets.shape[0]]
    for c0, c1 in itertools.pairwise(cuts):
        out[int(mv[move[c0]])] = (targets[c0:c1], np.asarray(dur[c0:c1], dtype=np.int64))
    return out


def check_move(profile: Profile, checker: PoseChecker, start: IntArray, end: IntArray,
               what: str) -> None:
    """JobError when the straight joint-space move leaves the safe workspace (module doc)."""
    check_moves(profile, checker, np.reshape(start, (1, 2)), np.reshape(end, (1, 2)),
                lambda _i: what)


def check_moves(profile: Profile, checker: PoseChecker, starts: IntArray, ends: IntArray,
                what: Callable[[int], str]) -> None:
    """`check_move` of every row of `starts` (M, 2) to the same row of `ends`, sampled
    together (each sample is checked on its own); the JobError is the first failing move's
    (`what(i)` names move i)."""
    mo = profile.motors
    th0 = step_angles(np.asarray(starts), mo.home_rad, mo.steps_per_rev)
    th1 = step_angles(np.asarray(ends), mo.home_rad, mo.steps_per_rev)
    span = np.abs(th1 - th0).max(axis=1)
    n = [max(2, math.ceil(float(x) / CHECK_RAD) + 1) for x in span]
    lin: dict[int, FloatArray] = {}
    for k in set(n):
        lin[k] = np.linspace(0.0, 1.0, k)
    row = np.repeat(np.arange(th0.shape[0]), n)
    frac = np.concatenate([lin[k] for k in n])
    q = th0[row] + frac[:, None] * (th1 - th0)[row]
    pts, valid = checker.forward(q)
    with np.errstate(all="ignore"):  # (rows whose linkage cannot close are refused first)
        q, _ok1, _ok2 = wrap_to_limits(q, mo.limits_rad)
        code, _ = checker.codes(q, pts, check_type1=False)
    bad = np.flatnonzero(~valid | (code != 0))
    if not bad.size:
        return
    i = int(row[bad[0]])
    rows = slice(int(np.searchsorted(row, i)), int(np.searchsorted(row, i, side="right")))
    q, pts = q[rows], pts[rows]
    if not valid[rows].all():
        raise JobError(f"{what(i)}: the linkage cannot close along the move", None, "reach")
    j = int(np.flatnonzero(code[rows])[0])
    _, m = checker.codes(q[j:j + 1], pts[j:j + 1], check_type1=False)
    raise JobError(f"{what(i)}: at ({pts[j, 0]:.2f}, {pts[j, 1]:.2f}) mm "
                   + checker.explain(int(code[rows][j]), q[j], pts[j], m[0]), None, "reach")


def path_points(profile: Profile, checker: PoseChecker, steps: IntArray) -> FloatArray:
    """Pen points (N, 2) of absolute steps."""
    th = step_angles(steps, profile.motors.home_rad, profile.motors.steps_per_rev)
    pts, _ = checker.forward(th)
    return pts
