"""A pen-change stop on the real firmware in simavr (pen-servo profile): two Inkscape layers
with `--layer-pause`; the host quits at the stop and resumes. At the stop the controller is
idle, its queue empty, the pen at the up pulse and the motors still; the recorded pulses show
exactly the planned steps, every segment reached, the pen down only while drawing (the
`pen:` line's k = 0 and m = 0)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from layers_support import PEN, layers_text
from runs import run_with
from sim_plot import all_steps, planned_steps

from fivebar_host.compile import CompileOptions, compile_job
from fivebar_host.compile.model import LayerPause
from fivebar_host.config import load_profile
from fivebar_host.controllers.fivebar.link import Link
from fivebar_host.devices.sim import toolchain_missing
from fivebar_host.devices.simtrace import read_trace
from fivebar_host.report.text.executed import executed_path, merge_axes, pen_report
from fivebar_host.run.errors import SendError
from fivebar_host.run.resume import ResumePoint, resume_path

pytestmark = pytest.mark.skipif(toolchain_missing() is not None,
                                reason=f"emulator unavailable: {toolchain_missing()}")

SVG = layers_text(curve=True)


def test_pen_change_on_the_emulator_quit_and_resume_exactly(tmp_path: Path) -> None:
    drawing = tmp_path / "layers.svg"
    drawing.write_text(SVG, encoding="utf-8")
    prof = load_profile(PEN)
    assert prof.pen is not None
    job = compile_job(drawing, prof, CompileOptions(layer_pause=True))
    (pause,) = job.pauses
    trace = tmp_path / "pins.trace"
    link = Link.open(f"fivebar-sim://?trace={trace}")
    seen: list[tuple[LayerPause, str, int, int | None, tuple[int, int], tuple[int, int]]] = []

    def quit_at(p: LayerPause) -> bool:
        st = link.status()
        time.sleep(0.2)
        later = link.status()
        seen.append((p, st.state, st.queued, st.pen, (st.a, st.b), (later.a, later.b)))
        return False

    try:
        with pytest.raises(SendError, match="stopped at the pen change before layer 2/2"):
            run_with(link, job, prof, drawing=drawing, laser=False, confirm=lambda q: True,
                    on_pause=quit_at)
        rp = ResumePoint.load(resume_path(drawing))
        assert rp.next_segment == pause.segment
        asked: list[LayerPause] = []
        run_with(link, job, prof, drawing=drawing, laser=False, confirm=lambda q: True,
                resume=True, on_pause=lambda p: asked.append(p) is None)
        assert asked == []  # resumed at the stop: not asked again
        assert not resume_path(drawing).exists()
    finally:
        link.close()
    ((p, state, queued, pulse, pos, later),) = seen
    assert p == pause and state == "Idle" and queued == 0
    assert pulse == prof.pen.pulse_us(prof.pen.up_position)
    assert pos == later == tuple(job.steps[pause.segment].tolist())
    tr = read_trace(trace)
    assert np.array_equal(all_steps(tr), planned_steps(job))
    t, track = merge_axes(tr.positions("A"), tr.positions("B"))
    ex = executed_path(job, prof, t / tr.freq, track)
    assert ex.segments_completed == job.n_segments
    assert ex.max_deviation_mm <= job.tolerance_mm + job.step_quantum_mm
    rep = pen_report(job, prof, tr.pen_pulses(), tr.freq, ex)
    assert rep.travel_down_steps == 0 and rep.draw_up_steps == 0, rep.line()
    assert rep.lifts == job.pen_downs
