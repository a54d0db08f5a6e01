"""A plot on a machine from a terminal: the public streaming helper of `fivebar plot --port`
and the vpype plugin's `fivebar plot`.

`plot_on_machine` opens the controller named by `--controller` (`controllers.controller_for`),
runs the compiled job through `run.job.run_job` with the terminal's operator
(`cli.operator.TerminalOperator`) and the resume file beside the drawing (`run.store.FileStore`),
and says what happened; after a run on the emulator it reports the executed path measured
from the recorded step pulses.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import click

from fivebar_host.cli.operator import TerminalOperator
from fivebar_host.compile import Job
from fivebar_host.config import Profile
from fivebar_host.controllers import open_controller
from fivebar_host.run.controller import Controller, Recording
from fivebar_host.run.job import RunOptions, RunReport, run_job
from fivebar_host.run.overrides import Overrides
from fivebar_host.run.stops import Copies, plan_text, planned_time_s
from fivebar_host.run.store import FileStore


@dataclass(frozen=True)
class Plot:
    """What `fivebar plot --port` was asked: the drawing (its resume file lives beside it),
    the machine (URL, controller), and how to run (`--laser`, `--resume`, `--yes`,
    copies); the executed path's CSV goes next to `preview_path`."""

    drawing: Path
    url: str
    controller: str
    laser: bool = False
    resume: bool = False
    yes: bool = False
    copies: Copies = field(default_factory=Copies)
    preview_path: Path = Path("preview.png")


def open_machine(name: str, url: str, profile: Profile) -> Controller:
    """Open the machine and say what the user should know about the connection."""
    controller = open_controller(name, url, profile)
    if controller.notice:
        click.echo(f"warning: {controller.notice}", err=True)
    return controller


def plot_on_machine(plot: Plot, profile: Profile, job: Job) -> RunReport:
    """Stream a compiled job with a progress bar, Ctrl-C hold/resume/abort, pen changes,
    copies with their countdown, the final report (module doc)."""
    from fivebar_host.report.text.dryrun import format_duration

    quality = (f"{job.raster.n_pixels} px at {job.raster.speed_mm_s:.1f} mm/s"
               if job.raster is not None else f"max deviation {job.max_dev_mm:.4f} mm")
    click.echo(f"job: {job.n_segments} segments, {job.n_paths} paths, mode {job.mode}, "
               f"{plan_text(job, plot.copies, format_duration)}, {quality}")
    if job.raster is not None:  # what a burn leaves out (--fill scan: the strokes) is said
        for n in job.notes:
            click.echo(f"note: {n}")
    if profile.pen is not None:
        click.echo("pen plot: the servo lifts the pen (M280) between strokes; laser output "
                   "stays at 0")
    elif not plot.laser:
        click.echo("laser/pen power output stays at 0 (no servo pen in the profile: M3/M5 "
                   "only mark pen down/up); pass --laser to burn")
    controller = open_machine(plot.controller, plot.url, profile)
    operator = TerminalOperator(plot.yes)
    overrides = Overrides() if controller.features.live_overrides is None else None
    options = RunOptions(plot.laser, plot.resume, plot.copies, overrides)
    try:
        with operator.attached(job.n_segments, plot.copies.count, plot.laser, overrides):
            report = run_job(controller, job, operator, FileStore.beside(plot.drawing),
                             options)
    finally:
        controller.close()
    click.echo(f"done: {report.segments} segments in {report.elapsed_s:.1f} s (planned "
               f"{planned_time_s(job, plot.copies):.1f} s), {report.bytes_sent} bytes sent, "
               f"{report.resends} resends; machine at {controller.describe(report.final)}")
    rec = controller.recording()
    if rec is not None and rec.path.exists() and plot.copies.count == 1:
        write_executed(job, profile, rec, plot.preview_path, report)
    return report


def write_executed(job: Job, prof: Profile, rec: Recording, preview_path: Path,
                   report: RunReport) -> None:
    """After an emulator run: the executed path from the recorded pulses, next to the
    preview (CSV of pen points and their deviation), and its largest deviation. With the
    emulator's `true=` geometry, the pen points are where that machine really draws."""
    from fivebar_host.compile import write_atomic
    from fivebar_host.devices.simtrace import read_trace
    from fivebar_host.report.text.executed import (
        executed_path,
        merge_axes,
        pen_report,
        true_params,
    )

    if job.raster is not None:
        from fivebar_host.raster.dose import figures, read_pins
        from fivebar_host.raster.preview import save_burned

        fig = figures(job, prof, read_pins(rec.path))
        click.echo(fig.line())
        burned = preview_path.with_name(preview_path.stem + ".burned.png")
        save_burned(fig, burned)
        click.echo(f"burned image (dose from the step pulses and the laser pin): {burned}; "
                   f"boundary data {burned.with_suffix('.npz')}")
        return
    tr, true = read_trace(rec.path), rec.true
    # the bound's quantum: a step's rounding, or on servos a pulse tick's (the plan's grid
    # step's when that is coarser: executed_servo's module doc)
    quantum, q_name = job.step_quantum_mm, "step quantum"
    if prof.joints is not None:  # the servo build: the arms' pulses through the true servos
        from fivebar_host.report.text.executed_servo import (
            executed_servo_path,
            pulse_quantum_mm,
        )

        ex = executed_servo_path(job, prof, tr, report.start_segment, rec.deadband)
        t_s, track = ex.time, ex.steps
        pulse_q = pulse_quantum_mm(job, prof)
        if job.step_quantum_mm <= pulse_q * (1.0 + 1e-3):  # a grid of ticks (to its 8168.4)
            quantum, q_name = max(pulse_q, job.step_quantum_mm), "pulse quantum"
        else:
            q_name = f"grid step quantum (the pulse quantum {pulse_q:.4f} mm is finer)"
    else:
        # the arms start where the emulated machine kept them (the trace's `start=`)
        t, track = merge_axes(tr.positions("A", tr.start[0]),
                              tr.positions("B", tr.start[1]), tr.start)
        t_s = t / tr.freq
        ex = executed_path(job, prof, t_s, track, report.start_segment,
                           report.start_position, true=true_params(true),
                           backlash=rec.backlash)
    out = preview_path.with_name(preview_path.stem + ".executed.csv")
    rows = ["t_s,a_steps,b_steps,x_mm,y_mm,segment,deviation_mm"]
    rows += [f"{ti:.6f},{a},{b},{x:.4f},{y:.4f},{sg},{'' if d != d else f'{d:.5f}'}"
             for ti, (a, b), (x, y), sg, d in zip(t_s, track.tolist(),
                                                  ex.points.tolist(), ex.segment.tolist(),
                                                  ex.deviation_mm.tolist(), strict=True)]
    write_atomic(out, "\n".join(rows) + "\n")
    given = [k for k, v in (("true=", true), ("backlash=", rec.backlash),
                            ("deadband=", rec.deadband)) if v is not None]
    truth = bool(given)
    where = f" (drawn by the URL's {' and '.join(given)} machine)" if truth else ""
    pulses = "servo" if prof.joints is not None else "step"
    click.echo(f"executed path (from the emulator's {pulses} pulses{where}): {out}; drawing "
               f"segments' max deviation "
               f"{ex.max_deviation_mm:.4f} mm (bound {job.tolerance_mm:g} + {q_name} "
               f"{quantum:.4f} mm)")
    if prof.pen is not None:
        click.echo(pen_report(job, prof, tr.pen_pulses(), tr.freq, ex).line())
    check_deviation(ex.max_deviation_mm, job.tolerance_mm + quantum, out, truth, q_name)


def check_deviation(dev_mm: float, bound_mm: float, csv: Path, true_machine: bool,
                    quantum: str = "step quantum") -> None:
    """A drawing the machine drew farther off than the bound is a failed run, not a
    report line: DeviationError (exit 3) says how far, and the likely causes."""
    from fivebar_host.report.text.executed import DeviationError

    if dev_mm <= bound_mm:
        return
    why = ("the machine as really built (the URL's true=, backlash= or deadband=) differs "
           "from the profile: calibrate it (docs/calibration.md) or set its [motors] "
           "backlash_steps (docs/backlash.md) or [joints] dead_band_deg" if true_machine else
           "the arms were not where the controller's count said: a power loss answered "
           "'yes, they are where the job stopped' while they were elsewhere, or steps lost "
           "to a stall")
    raise DeviationError(f"the machine drew {dev_mm:.2f} mm off the drawing, beyond the "
                         f"bound of {bound_mm:.4f} mm (tolerance + {quantum.split(' (')[0]})"
                         f": {why}. "
                         f"Every point is in {csv}")
