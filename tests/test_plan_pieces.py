"""Where the planner's pieces end (issue 39): a segment's speed-up and slow-down are cut into
pieces whose ends are rounded to whole steps once. They lie on the line between the segment's
own stepped ends — the line the firmware's DDA runs for the whole segment — so that a piece
of one or two steps keeps its segment's direction; and a travel piece is as long as the pen
really moves between the positions its steps reach (its feed limits that length). The
references: the stepped ends themselves, and the geometry's own forward kinematics."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from fivebar_host.compile import CompileOptions, compile_drawing
from fivebar_host.compile import job as jobmod
from fivebar_host.compile import steps as stepsmod
from fivebar_host.compile.job import Job
from fivebar_host.compile.timing import Planned
from fivebar_host.config import Profile, load_profile
from fivebar_host.toolpath.svg import read_svg

# a zigzag (every corner reverses a joint), a star, and travel between them and a circle
_SVG = ('<svg xmlns="http://www.w3.org/2000/svg" width="60mm" height="40mm" '
        'viewBox="0 0 60 40"><polyline fill="none" stroke="black" points="'
        + " ".join(f"{5 + k * 0.7:.2f},{8 + (4 if k % 2 else 0)}" for k in range(30))
        + '"/><polyline fill="none" stroke="black" points="'
        + " ".join(f"{40 + 8 * np.cos(k * 2.51327):.3f},{28 + 8 * np.sin(k * 2.51327):.3f}"
                   for k in range(11))
        + '"/><circle cx="15" cy="28" r="6" fill="none" stroke="black"/></svg>').encode()


def _compiled() -> tuple[Profile, Job, Planned]:
    """The drawing compiled as `fivebar plot` does, and the planner's pieces on the way
    (`Planned.f1`, which the job drops)."""
    seen: list[Planned] = []
    timing_step = jobmod.plan_timing

    def keep(*args: Any) -> Planned:
        planned = timing_step(*args)
        seen.append(planned)
        return planned

    prof = load_profile()
    jobmod.plan_timing = keep
    try:
        job = compile_drawing(read_svg(_SVG), prof, CompileOptions(validate=False))
    finally:
        jobmod.plan_timing = timing_step
    return prof, job, seen[-1]


@pytest.fixture(scope="module")
def compiled() -> tuple[Profile, Job, Planned]:
    return _compiled()


def test_inner_piece_ends_round_from_their_segments_stepped_line(
        compiled: tuple[Profile, Job, Planned]) -> None:
    _, _, pl = compiled
    assert not pl.slack.shape[0] and not pl.dwell.any()
    st = pl.steps.astype(np.float64)
    whole = np.flatnonzero(pl.f1 >= 1.0)  # pieces that end a segment
    inner = np.flatnonzero(pl.f1 < 1.0)
    assert inner.size > 100  # the ramps were cut
    # each inner piece's segment: it starts where the last whole piece before it ended
    after = np.searchsorted(whole, inner)
    start = np.where(after > 0, whole[np.maximum(after - 1, 0)] + 1, 0)
    end = whole[after] + 1
    line = st[start] + pl.f1[inner, None] * (st[end] - st[start])
    off = np.abs(st[inner + 1] - line).max()
    assert off <= 0.5 + 1e-9, f"an inner piece end {off:.3f} steps off its segment's line"


def test_a_travel_piece_is_as_long_as_the_pen_moves(
        compiled: tuple[Profile, Job, Planned]) -> None:
    prof, job, _ = compiled
    mot = prof.motors
    th = stepsmod.step_angles(job.steps, mot.home_rad, mot.steps_per_rev)
    travel = np.flatnonzero(~job.draw & (np.diff(job.steps, axis=0) != 0).any(axis=1))
    assert travel.size > 10
    fb, asm = prof.geometry, prof.kinematics.assembly
    at = np.array([np.asarray(fb.forward(t, asm)) for t in th])
    reached = np.hypot(*(at[travel + 1] - at[travel]).T)
    assert np.abs(job.length_mm[travel] - reached).max() < 1e-6
