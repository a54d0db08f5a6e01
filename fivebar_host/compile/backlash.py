"""Backlash of stepper joints: the slack model, and its take-up at every reversal.

The model (a "play" operator, per motor, in steps): the joint's position j stays within the
slack behind the motor's count m, j ∈ [m − B, m]; a motor moving up pushes the joint at
j = m − B, moving down at j = m, and inside the slack the joint does not move:

    j_k = clip(j_{k−1}, m_k − B, m_k)                                             (B1)

Convention: at the homed pose the slack is taken up downward, j = m (the arms were last
moved toward decreasing steps: docs/backlash.md says how to home so).

Compensation. The host plans joint targets t. Sent as motor counts m = t + slack, with
slack = B after the motor last moved up and 0 after it last moved down, they put the joint
exactly on t (B1). When a motor reverses, its slack must change by ±B while its joint stays:
`take_up` inserts, at the reversal point, a segment in which only the reversing motor(s)
move, by ±B, and the other joint waits. Why this way, not a pen-up detour: during the take-up
the motor turns inside the slack, so (B1) the joint — and the pen — do not move at all; the
pen stays down on the drawing where it is, the planner sees a segment like any other (the
other motor slows to the junction limit, waits, and speeds up again), so the take-up costs a
few milliseconds and no drawn accuracy, and no pen lift (a lift and lowering per reversal
would cost hundreds of milliseconds and a mark of its own). On a laser the take-up runs at
power 0 (compile/timing.py), at rest on both sides (the power changes there), so the
standing beam burns no dot.

The job's `steps` are motor counts; `slack` (T+1, 2) holds what the counts exceed the joint
by at every target, so `steps − slack` are the joint's steps, which forward kinematics,
validation and the preview read (`joint_steps`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import ArrayLike

from fivebar_host.compile.segments import Stepped
from kinematics.arrays import IntArray

__all__ = ["joint_steps", "play", "reversal_slack", "take_up"]


def play(track: ArrayLike, backlash: ArrayLike, start_slack: ArrayLike = (0, 0)) -> IntArray:
    """Joint steps (E, 2) of a machine with `backlash` (2,) steps of slack whose motors pass
    through the counts `track` (E, 2) in order (Eq. B1); `start_slack` is m − j at the first
    row (0: taken up downward). Monotone motion between rows is assumed (a G1 block)."""
    m = np.asarray(track, dtype=np.int64).reshape(-1, 2)
    b = np.asarray(backlash, dtype=np.int64).reshape(2)
    out = np.empty_like(m)
    if m.shape[0] == 0:
        return out
    j = m[0] - np.asarray(start_slack, dtype=np.int64).reshape(2)
    mm = m.tolist()
    j0, j1 = int(j[0]), int(j[1])
    b0, b1 = int(b[0]), int(b[1])
    res = []
    for a, c in mm:  # the recurrence is sequential: one pass over the rows
        j0 = min(max(j0, a - b0), a)
        j1 = min(max(j1, c - b1), c)
        res.append((j0, j1))
    out[:] = res
    return out


def reversal_slack(steps: IntArray, backlash: ArrayLike) -> tuple[IntArray, IntArray]:
    """For joint targets `steps` (T+1, 2): the slack after each segment (T, 2), B where the
    motor last moved up, 0 where it last moved down or has not moved (Eq. B1's convention),
    and the slack before each segment (T, 2)."""
    b = np.asarray(backlash, dtype=np.int64).reshape(1, 2)
    d = np.sign(np.diff(np.asarray(steps, dtype=np.int64), axis=0))
    n = d.shape[0]
    after = np.zeros((n, 2), dtype=np.int64)
    for i in range(2):
        moved = np.flatnonzero(d[:, i] != 0)
        if not moved.size:
            continue
        # the last non-zero direction at or before each segment (forward fill)
        last = np.full(n, -1, dtype=np.int64)
        last[moved] = moved
        last = np.maximum.accumulate(last)
        up = np.where(last >= 0, d[np.maximum(last, 0), i] > 0, False)
        after[:, i] = np.where(up, b[0, i], 0)
    before = np.concatenate((np.zeros((1, 2), dtype=np.int64), after[:-1]))
    return after, before


def take_up(sp: Stepped, backlash: tuple[int, int]) -> Stepped:
    """The stepped job with a take-up segment before every segment at which a motor with
    slack reverses (module doc), its steps turned into motor counts and `slack` set. A
    take-up segment keeps its neighbour's pen state and provenance, the pose (angles, pen
    point) of the reversal point and a requested length of 0. No slack: `sp` unchanged."""
    if not any(backlash) or sp.draw.shape[0] == 0:
        return sp
    after, before = reversal_slack(sp.steps, backlash)
    change = (after != before).any(axis=1)  # a take-up before segment k
    at = np.flatnonzero(change)
    if not at.size and not after[-1].any():
        return sp
    # slack at every target: target r ends segment r − 1
    slack_rows = np.concatenate((np.zeros((1, 2), dtype=np.int64), after))
    joint = sp.steps.astype(np.int64)
    # Each take-up ends on the reversal point (target `at`, where segment `at` starts) with
    # the new slack: the joint's steps there plus the slack after the reversal.
    ins_slack = after[at]
    k = at + 1  # the take-up's end is inserted right after the reversal point
    new_steps = np.insert(joint + slack_rows, k, joint[at] + ins_slack, axis=0)
    new_slack = np.insert(slack_rows, k, ins_slack, axis=0)
    # The job ends with the slack taken up downward, as the next job (or the bridge's next
    # batch) assumes: a last take-up (the joint still) where a motor last moved up.
    end = [sp.draw.shape[0]] if after[-1].any() else []
    seg = np.concatenate((at, end)).astype(np.int64)
    src = np.minimum(seg, sp.draw.shape[0] - 1)  # provenance: the next segment (or the last)
    if end:
        new_steps = np.concatenate((new_steps, new_steps[-1:] - new_slack[-1:]))
        new_slack = np.concatenate((new_slack, np.zeros((1, 2), dtype=np.int64)))
    rows = np.concatenate((at, [sp.th.shape[0] - 1] if end else [])).astype(np.int64)
    k = np.concatenate((at + 1, [sp.th.shape[0]] if end else [])).astype(np.int64)
    draw = sp.draw[src]  # the pen keeps its state: the joint does not move
    return replace(
        sp, th=np.insert(sp.th, k, sp.th[rows], axis=0),
        pts=np.insert(sp.pts, k, sp.pts[rows], axis=0),
        draw=np.insert(sp.draw, seg, draw),
        path=np.insert(sp.path, seg, sp.path[src]),
        source=np.insert(sp.source, seg, sp.source[src]),
        line=np.insert(sp.line, seg, sp.line[src]),
        length=np.insert(sp.length, seg, 0.0),
        perm=np.insert(sp.perm, seg, sp.perm[src]),
        steps=new_steps, slack=new_slack)


def joint_steps(steps: IntArray, slack: IntArray) -> IntArray:
    """The joint's steps: motor counts less the slack (no slack recorded: the counts)."""
    if slack.shape[0] == 0:
        return steps
    return np.asarray(steps, dtype=np.int64) - slack

