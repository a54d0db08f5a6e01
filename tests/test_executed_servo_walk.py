"""The servo run's frames given to their segments (`report.text.executed_servo`): a frame is
a sample every 20 ms, so after a sharp corner cut into short pieces it lies past them, and
after a reversal on the line it came along as near as on the one it goes on."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from fivebar_host.report.text.executed_servo import _segment_of


def _job(targets: list[tuple[int, int]]) -> SimpleNamespace:
    steps = np.array(targets, dtype=np.int64)
    return SimpleNamespace(steps=steps, n_segments=steps.shape[0] - 1)


def test_a_frame_past_a_reversals_short_piece_goes_on_to_the_segment_it_lies_on() -> None:
    # out along x, back by a 2-step piece and the rest of the return, then up
    job = _job([(0, 0), (100, 0), (98, 0), (50, 0), (50, 50)])
    frames = np.array([[40.0, 0], [80, 0], [100, 0], [90, 0], [60, 0], [50, 20], [50, 40]])
    seg = _segment_of(job, frames, 0, 60.0)  # type: ignore[arg-type]
    # on the return the out line is as near (0 steps): either is the frame's segment; once
    # the frame leaves it, the walk finds the segment it lies on past the 2-step piece
    assert seg.tolist()[:5] == [0, 0, 0, 0, 0] and seg.tolist()[5:] == [3, 3]
    # one segment at a time (no reach), the walk stayed on the out line for good
    assert _segment_of(job, frames, 0, 0.0).tolist() == [0] * 7  # type: ignore[arg-type]


def test_the_walk_does_not_jump_beyond_what_an_arm_moves_in_a_frame() -> None:
    # a square: the frame near the start corner is not taken for the closing side
    job = _job([(0, 0), (100, 0), (100, 100), (0, 100), (0, 2)])
    frames = np.array([[10.0, 0], [50, 0], [100, 30]])
    assert _segment_of(job, frames, 0, 60.0).tolist() == [0, 0, 1]  # type: ignore[arg-type]
