"""End to end on the real firmware in simavr: SVG → host → firmware → recorded step pulses →
forward kinematics → deviation from the SVG path; the laser pin only while drawing; an abort
mid-job and an exact resume, counted on the recorded pulses."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from runs import run_with
from sim_plot import compiled_copy, laser_steps, planned_draw_steps

from fivebar_host.controllers.fivebar.link import Link
from fivebar_host.devices.sim import toolchain_missing
from fivebar_host.devices.simtrace import read_trace
from fivebar_host.report.text.executed import executed_path, merge_axes
from fivebar_host.run.errors import SendError
from fivebar_host.run.operator import Progress
from fivebar_host.run.resume import resume_path

pytestmark = pytest.mark.skipif(toolchain_missing() is not None,
                                reason=f"emulator unavailable: {toolchain_missing()}")


def test_svg_to_pulses_within_tolerance_and_laser_only_while_drawing(tmp_path: Path) -> None:
    drawing, prof, job = compiled_copy(tmp_path, "fivebar_text.svg")
    trace = tmp_path / "pins.trace"
    link = Link.open(f"fivebar-sim://?trace={trace}")
    try:
        rep = run_with(link, job, prof, drawing=drawing, laser=True, confirm=lambda q: True)
    finally:
        link.close()
    assert rep.final == (0, 0)
    tr = read_trace(trace)
    t, track = merge_axes(tr.positions("A"), tr.positions("B"))
    ex = executed_path(job, prof, t, track)
    assert ex.segments_completed == job.n_segments  # every segment reached its target
    bound = job.tolerance_mm + job.step_quantum_mm
    assert ex.max_deviation_mm <= bound, (ex.max_deviation_mm, bound)
    # The laser pin is on exactly while drawing: each step event is on iff its segment draws.
    iv = tr.laser_intervals()
    on = np.array([any(s <= c < e for s, e in iv) for c in t.astype(np.int64)])
    drawing_event = job.draw[ex.segment]
    assert np.array_equal(on, drawing_event)
    assert np.array_equal(laser_steps(tr), planned_draw_steps(job))


def test_abort_mid_job_then_resume_draws_each_step_once(tmp_path: Path) -> None:
    drawing, prof, job = compiled_copy(tmp_path, "simple.svg")
    trace = tmp_path / "pins.trace"
    link = Link.open(f"fivebar-sim://?trace={trace}&realtime=1")
    stop = {"now": False}

    def on_progress(p: Progress) -> None:
        if p.segments_done >= job.n_segments // 3:
            stop["now"] = True

    try:
        with pytest.raises(SendError) as ei:
            run_with(link, job, prof, drawing=drawing, laser=True, confirm=lambda q: True,
                    on_progress=on_progress, should_stop=lambda: stop["now"],
                    on_interrupt=lambda: False)
        msg = str(ei.value)
        assert "interrupted by the user" in msg and "stopped at A = " in msg
        assert resume_path(drawing).exists()
        st = link.status()
        assert st.laser == 0 and st.state == "Idle"
        run_with(link, job, prof, drawing=drawing, laser=True, confirm=lambda q: True,
                resume=True)
        assert not resume_path(drawing).exists()
    finally:
        link.close()
    tr = read_trace(trace)
    assert np.array_equal(laser_steps(tr), planned_draw_steps(job))
    a = tr.positions("A")
    b = tr.positions("B")
    assert (a[-1][1], b[-1][1]) == (0, 0)  # back at the homed pose


def test_error_reply_mid_job_then_exact_resume(tmp_path: Path) -> None:
    """A refused line mid-job (soft limit, error:11) on the real firmware: the machine holds
    with the laser off, the host names the fault and position, and the resume draws each
    remaining step once."""
    drawing, prof, job = compiled_copy(tmp_path, "simple.svg")
    # A soft limit ($1 A min, $2 A max, $3 B min, $4 B max) that the first third of the job
    # respects and a later target crosses: the firmware refuses that line.
    third = job.n_segments // 3
    early, late = job.steps[: third + 1], job.steps[third:]
    limits = [(2 + 2 * m, int(early[:, m].max()), bool((late[:, m] > early[:, m].max()).any()))
              for m in (0, 1)]
    limits += [(1 + 2 * m, int(early[:, m].min()), bool((late[:, m] < early[:, m].min()).any()))
               for m in (0, 1)]
    setting, limit = next((k, v) for k, v, crossed in limits if crossed)
    free = 100000 if setting % 2 == 0 else -100000
    trace = tmp_path / "pins.trace"
    link = Link.open(f"fivebar-sim://?trace={trace}")
    try:
        link.command(f"${setting}={limit}")
        with pytest.raises(SendError) as ei:
            run_with(link, job, prof, drawing=drawing, laser=True, confirm=lambda q: True)
        msg = str(ei.value)
        assert "error:11" in msg and "stopped at A = " in msg and "laser off" in msg
        st = link.status()
        assert st.laser == 0
        link.command(f"${setting}={free}")
        run_with(link, job, prof, drawing=drawing, laser=True, confirm=lambda q: True,
                resume=True)
    finally:
        link.close()
    tr = read_trace(trace)
    assert np.array_equal(laser_steps(tr), planned_draw_steps(job))
    assert (tr.positions("A")[-1][1], tr.positions("B")[-1][1]) == (0, 0)


def test_the_executed_path_report_draws_with_the_true_machine(tmp_path: Path) -> None:
    """`fivebar-sim://?true=…` (calibration): the executed-path CSV holds where the machine
    as really built draws the recorded steps — checked against that machine's own forward
    kinematics — and a 0.5 mm longer b1 shows as a deviation beyond the bound, which fails
    the run (exit 3, a message that says why)."""
    import csv

    from click.testing import CliRunner

    from fivebar_host.cli import main
    from fivebar_host.config import load_profile
    from kinematics.fivebar import FiveBar

    true = (60.0, 90.5, 60.0, 90.0, 40.0, 120.0, 60.0)  # default.toml with b1 0.5 mm longer
    preview = tmp_path / "p.png"
    url = "fivebar-sim://?true=" + ",".join(f"{v:g}" for v in true)
    res = CliRunner().invoke(main, ["plot", str(Path(__file__).parents[1] / "examples" /
                                                 "simple.svg"), "--port", url, "--yes",
                                    "--preview", str(preview)])
    assert res.exit_code == 3, res.output  # beyond the bound: a failed run
    assert "error: the machine drew" in res.output and "differs from the profile" in res.output
    line = next(ln for ln in res.output.splitlines() if ln.startswith("executed path"))
    assert "true= machine" in line
    dev = float(line.split("max deviation ")[1].split(" mm")[0])
    bound = float(line.split("(bound ")[1].split(" +")[0]) + float(
        line.split("step quantum ")[1].split(" mm")[0])
    assert dev > bound + 0.1, line
    prof = load_profile(None)
    fb = FiveBar(*true[:5])
    with preview.with_name("p.executed.csv").open() as f:
        rows = list(csv.DictReader(f))
    steps = np.array([[int(r["a_steps"]), int(r["b_steps"])] for r in rows], dtype=float)
    th = np.radians(true[5:]) + steps * prof.motors.rad_per_step
    pts = np.array([fb.forward(t, prof.kinematics.assembly) for t in th[::25]])
    got = np.array([[float(r["x_mm"]), float(r["y_mm"])] for r in rows])[::25]
    assert np.abs(pts - got).max() < 1e-3
