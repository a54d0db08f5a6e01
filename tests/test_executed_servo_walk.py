"""The servo run's frames given to their segments (`report.text.executed_servo`): a frame is
a sample every 20 ms, so past a sharp corner it lies beyond the short pieces the planner cut
there, on a segment after them."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from fivebar_host.report.text.executed_servo import _segment_of


def _job(targets: list[tuple[int, int]]) -> SimpleNamespace:
    steps = np.array(targets, dtype=np.int64)
    return SimpleNamespace(steps=steps, n_segments=steps.shape[0] - 1)


def test_a_frame_past_a_corners_short_piece_goes_on_to_the_segment_it_lies_on() -> None:
    # out along x, a 2-step piece at the cusp, back up and left, then up
    job = _job([(0, 0), (100, 0), (98, 2), (50, 50), (50, 100)])
    frames = np.array([[60.0, 0], [100, 0], [90, 10], [70, 30], [50, 70]])
    assert _segment_of(job, frames, 0, 3).tolist() == [0, 0, 2, 2, 3]  # type: ignore[arg-type]
    # one segment at a time (no short piece looked past), the walk stayed on the first
    assert _segment_of(job, frames, 0, 0).tolist() == [0] * 5  # type: ignore[arg-type]


def test_the_walk_stops_at_a_long_segment_the_frame_is_not_nearer() -> None:
    # a square: a frame near the start corner is not taken for the closing side
    job = _job([(0, 0), (100, 0), (100, 100), (0, 100), (0, 2)])
    frames = np.array([[10.0, 0], [50, 0], [100, 30]])
    assert _segment_of(job, frames, 0, 3).tolist() == [0, 0, 1]  # type: ignore[arg-type]
