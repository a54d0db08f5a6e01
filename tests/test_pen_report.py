"""The pen line of a run on the emulator (`report.text.executed.pen_report`) judges every
step by the servo pulse before it. The firmware's pulse edges wait for the step interrupt,
so a pulse of the up (or down) position can come some tens of µs short or long — in the
emulator two frames in a row 30.1 µs short during a travel (the run was right; the line said
"travel steps with the pen down 121"). Such a pulse still holds the pen where it was; a frame
of a real move (about 90 µs a frame in configs/pen-servo.toml) does not."""

from __future__ import annotations

import numpy as np
import pytest
from layers_support import PEN, layers_text

from fivebar_host.compile import CompileOptions, compile_drawing
from fivebar_host.compile.job import Job
from fivebar_host.config import Profile, load_profile
from fivebar_host.report.text.executed import ExecutedPath, pen_report
from fivebar_host.toolpath.svg import read_svg

FREQ = 16e6
FRAME_S = 0.020


@pytest.fixture(scope="module")
def job_prof() -> tuple[Job, Profile]:
    prof = load_profile(PEN)
    return compile_drawing(read_svg(layers_text().encode()), prof,
                           CompileOptions(validate=False)), prof


def _report(job: Job, prof: Profile, widths_us: list[float],
            steps: list[tuple[float, int]]) -> tuple[int, int]:
    """(travel steps with the pen down, drawing steps with the pen up) for servo frames of
    `widths_us` and steps at (time s, job segment)."""
    pulses = [(round(i * FRAME_S * FREQ), round(w * 1e-6 * FREQ))
              for i, w in enumerate(widths_us)]
    t = np.array([s for s, _ in steps])
    ex = ExecutedPath(time=t, steps=np.zeros((t.size, 2), dtype=np.int64),
                      points=np.zeros((t.size, 2)),
                      segment=np.array([k for _, k in steps], dtype=np.int64),
                      deviation_mm=np.full(t.size, np.nan), segments_completed=0)
    rep = pen_report(job, prof, pulses, FREQ, ex)
    return rep.travel_down_steps, rep.draw_up_steps


def test_late_edges_leave_the_pen_where_it_is(job_prof: tuple[Job, Profile]) -> None:
    job, prof = job_prof
    assert prof.pen is not None
    up, down = prof.pen.pulse_us(prof.pen.up_position), prof.pen.pulse_us(
        prof.pen.down_position)
    travel = int(np.flatnonzero(~job.draw)[0])
    draw = int(np.flatnonzero(job.draw)[0])
    move = list(np.linspace(up, down, 10)[1:-1])  # ~90 µs a frame, as the profile moves
    frames = [up] * 4 + [up - 45.0, up - 45.0] + [up] * 2 + move + [down] * 8 + [
        down + 45.0, down + 45.0] + [down] * 4
    first_down = 8 + len(move)
    steps = [(4.5 * FRAME_S, travel), (5.5 * FRAME_S, travel),
             ((first_down + 2.5) * FRAME_S, draw), ((first_down + 8.5) * FRAME_S, draw)]
    assert _report(job, prof, frames, steps) == (0, 0)
    # a step in a frame of the move is one with the pen neither up nor down
    moving = [(9.5 * FRAME_S, travel), (10.5 * FRAME_S, draw)]
    assert _report(job, prof, frames, [*steps, *moving]) == (1, 1)
    # two frames 90 µs off the up position are a move, not a late edge
    off = [up] * 4 + [up - 90.0, up - 90.0] + [up] * 4
    assert _report(job, prof, off, [(4.5 * FRAME_S, travel)]) == (1, 0)
