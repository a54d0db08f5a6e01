"""Finishing a segment from a position a little off its line (`run.moves.snap_to_line`): the
move back onto the line goes ahead on every axis, so the resumed stream issues exactly the
steps the segment had left — none backwards, none twice — and far-off positions are refused
(the resume then travels to the segment's start).  Checked against counting by hand."""

from __future__ import annotations

import numpy as np

from fivebar_host.run.moves import SNAP_STEPS, snap_to_line


def _steps_left(s1: np.ndarray, pos: np.ndarray, q: np.ndarray) -> np.ndarray:
    return np.abs(q - pos) + np.abs(s1 - q)


def test_snap_goes_ahead_and_issues_only_the_steps_left() -> None:
    s0, s1 = np.array([0, 0]), np.array([30, -10])
    pos = np.array([12, -2])  # the line at A = 12 is B = -4: two steps off
    snap = snap_to_line(s0, s1, pos)
    assert snap is not None
    t, q = snap
    assert t == 0.4 and q.tolist() == [12, -4]
    assert _steps_left(s1, pos, q).tolist() == np.abs(s1 - pos).tolist()


def test_snap_on_every_axis_ahead_in_both_directions() -> None:
    rng = np.random.default_rng(3)
    for _ in range(500):
        s0 = rng.integers(-500, 500, 2)
        s1 = s0 + rng.integers(-80, 80, 2)
        if not (s1 - s0).any():
            continue
        t = rng.uniform(0.05, 0.95)
        pos = np.rint(s0 + t * (s1 - s0) + rng.uniform(-2.5, 2.5, 2)).astype(np.int64)
        snap = snap_to_line(s0, s1, pos)
        if snap is None:
            continue
        _, q = snap
        # no axis goes backwards: the steps issued are the steps left
        d = s1 - s0
        assert np.all((q - pos) * np.sign(d) >= 0) or np.all(q == s1)
        assert np.all(np.abs(q - (s0 + snap[0] * d)) <= 1.0)


def test_far_off_refused() -> None:
    s0, s1 = np.array([0, 0]), np.array([30, -10])
    assert snap_to_line(s0, s1, np.array([12, 3])) is None  # 7 steps off
    assert SNAP_STEPS < 7
    assert snap_to_line(s0, s1, np.array([-3, 0])) is None  # before the segment
