"""Issue 21: after a resume that homed first, the executed-path report measures drawing
segments only. The travel back from the home pose to the resume point is laser-off travel,
not part of any segment: scoring it against the drawing gave a false max deviation of
tens of mm.

The resume point is exact (a stop at the start of a drawing segment mid-job); the resume runs
on a freshly powered emulator (power-on: H:0) whose arms sit at the home pose, a person says
so, and its step pulses are measured."""

from __future__ import annotations

from pathlib import Path

import pytest
from runs import run_with
from sim_plot import compiled_copy

from fivebar_host.controllers.fivebar.link import Link
from fivebar_host.devices.sim import toolchain_missing
from fivebar_host.devices.simtrace import read_trace
from fivebar_host.report.text.executed import executed_path, merge_axes
from fivebar_host.run.resume import ResumePoint, fingerprint, resume_path

pytestmark = [
    pytest.mark.sim,
    pytest.mark.skipif(toolchain_missing() is not None,
                       reason=f"emulator unavailable: {toolchain_missing()}"),
]


def test_travel_back_after_homing_is_not_scored_as_drawing(tmp_path: Path) -> None:
    drawing, prof, job = compiled_copy(tmp_path, "simple.svg")
    # Stopped on a segment boundary at the start of a drawing segment mid-job (as a hold
    # there records it): the resume continues with that segment, laser on.
    k = int(next(i for i in range(job.n_segments // 3, job.n_segments) if job.draw[i]))
    pos = (int(job.steps[k, 0]), int(job.steps[k, 1]))
    assert pos != (0, 0)
    ResumePoint(str(drawing), fingerprint(job), k, pos, "interrupt: test",
                job.n_segments).save(resume_path(drawing))
    trace = tmp_path / "pins.trace"
    asked: list[str] = []

    def person(question: str) -> bool:  # the arms are at home, not where the job stopped
        asked.append(question)
        return "home pose" in question

    with Link.open(f"fivebar-sim://?trace={trace}") as link:
        rep = run_with(link, job, prof, drawing=drawing, laser=True, confirm=lambda q: False,
                      resume=True, confirm_placed=person)
    assert len(asked) == 2 and "lost power" in asked[0]
    assert rep.start_segment == k and rep.start_position == (0, 0)
    tr = read_trace(trace)
    t, track = merge_axes(tr.positions("A"), tr.positions("B"))
    bound = job.tolerance_mm + job.step_quantum_mm
    ex = executed_path(job, prof, t, track, rep.start_segment, rep.start_position)
    assert ex.segments_completed == job.n_segments
    assert ex.max_deviation_mm <= bound, (ex.max_deviation_mm, bound)
    travel = ex.segment[: int((ex.segment >= 0).argmax())]
    assert travel.size > 10 and (travel == -1).all()  # the travel back: no segment
    # Scored as if the run had started at the segment's start, the travel counts as drawing.
    wrong = executed_path(job, prof, t, track, rep.start_segment)
    assert wrong.max_deviation_mm > 10 * bound
