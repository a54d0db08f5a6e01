"""`fivebar convert` and `fivebar plot`: a drawing to firmware lines, or onto the machine.

Both take the job options generated from `fivebar_host.options`; `plot --server` hands the
same values to a running daemon (`fivebar_host.cli.remote`).
"""

from __future__ import annotations

import signal
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import click

from fivebar_host.cli.common import (
    compile_from_cli,
    confirm_placed,
    confirm_with,
    fail,
    handle_errors,
    job_options,
    main,
    open_link,
    port_option,
    position_text,
    yes_option,
)
from fivebar_host.cli.grbl import controller_option
from fivebar_host.cli.keys import HELP, override_keys
from fivebar_host.cli.remote import server_option
from fivebar_host.cli.stops import ask_pen_change, check_stops, countdown
from fivebar_host.compile.model import LayerPause
from fivebar_host.config import Profile
from fivebar_host.run.overrides import FEED_MAX_PCT, Overrides
from fivebar_host.run.sender import Progress
from fivebar_host.run.stops import Copies, plan_text, planned_time_s


@main.command("convert")
@click.argument("drawing", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              required=True, help="Where to write the firmware lines.")
@click.option("--relative", is_flag=True,
              help="Relative step moves (G91) instead of absolute targets (G90).")
@controller_option
@job_options()
@handle_errors
def convert(drawing: Path, output: Path, relative: bool, controller: str,
            config_path: Path | None, **job_values: Any) -> None:
    """Compile DRAWING (SVG or G-code) into firmware-ready step lines (G1 A B P S).

    Without --laser the job is a pen plot: S0 on every line. With --controller grbl: the
    lines a stock GRBL board runs (G1 X<θA> Y<θB> F in degrees)."""
    from fivebar_host.compile import encode_lines, mode_sequence, write_atomic

    laser = bool(job_values["laser"])
    prof, job = compile_from_cli(drawing, config_path, job_values)
    if controller == "grbl":
        from fivebar_host.cli.grbl import grbl_convert

        grbl_convert(output, prof, job, laser)
        return
    lines = encode_lines(job, prof, relative=relative, laser=laser)
    write_atomic(output, "\n".join(lines) + "\n")
    tool = (f"laser (power up to S{int(job.power.max(initial=0))})" if laser
            else "pen (S0, no laser power)")
    changes = f" ({len(job.mode_changes)} pen-up mode changes)" if job.mode_changes else ""
    pauses = ("; the file runs through its pen-change stops (`fivebar plot` stops there): "
              + ", ".join(f"segment {p.segment} before {p.describe()}" for p in job.pauses)
              if job.pauses else "")
    click.echo(f"wrote {output}: {job.n_segments} segments, mode {mode_sequence(job)}{changes}, "
               f"{tool}, "
               f"≈ {job.total_time_s:.1f} s, max deviation {job.max_dev_mm:.4f} mm{pauses}")


@main.command("plot")
@click.argument("drawing", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--dry-run", is_flag=True,
              help="Run everything except the serial link: preview picture and report.")
@click.option("--preview", "preview_path", type=click.Path(dir_okay=False, path_type=Path),
              default=Path("preview.png"), show_default=True, help="Dry-run picture (PNG).")
@server_option
@port_option
@click.option("--resume", is_flag=True,
              help="Continue an interrupted plot from its resume file (same drawing and options).")
@yes_option
@controller_option
@job_options()
@handle_errors
def plot(drawing: Path, dry_run: bool, preview_path: Path, port: str | None, resume: bool,
         yes: bool, controller: str, config_path: Path | None, **job_values: Any) -> None:
    """Compile and check DRAWING, then plot it on the machine at --port (or --dry-run).

    Everything is checked before anything moves. Ctrl-C holds the machine at once (laser
    off) and asks whether to resume or abort; a fault or an abort leaves a resume file, and
    the same command with --resume continues exactly where the machine stopped.
    """
    if not dry_run and port is None:
        fail("give --port PORT to plot on a machine (e.g. /dev/ttyUSB0 or fivebar-sim:// "
             "for the emulator), or --dry-run for the preview and report")
    from fivebar_host.compile import nbar_opinion
    from fivebar_host.report.preview import draw_preview
    from fivebar_host.report.text.dryrun import report_lines

    laser = bool(job_values["laser"])
    copies = Copies(int(job_values["copies"]), float(job_values["page_delay_s"]))
    prof, job = compile_from_cli(drawing, config_path, job_values)
    if dry_run:
        for line in report_lines(job, nbar_opinion(job, prof), laser=laser, profile=prof,
                                 copies=copies):
            click.echo(line)
        draw_preview(job, prof, preview_path)
        click.echo(f"preview       {preview_path}")
        return
    assert port is not None
    check_stops(job, copies, controller)
    if controller == "grbl":
        from fivebar_host.cli.grbl import grbl_plot

        grbl_plot(port, prof, job, laser=laser, yes=yes, drawing=drawing, resume=resume)
        return
    stream_plot(drawing, port, prof, job, laser=laser, resume=resume, yes=yes,
                 preview_path=preview_path, copies=copies)


def _ask_resume() -> bool:
    """After Ctrl-C: resume or abort (abort without a terminal)."""
    click.echo("\nheld: motion stopped, laser off.", err=True)
    choice = click.prompt("resume or abort?", type=click.Choice(["resume", "abort"]),
                          default="abort", err=True) if sys.stdin.isatty() else "abort"
    return bool(choice == "resume")


def stream_plot(drawing: Path, port: str, prof: Profile, job: Any, *, laser: bool,
                 resume: bool, yes: bool, preview_path: Path, copies: Copies) -> None:
    """Stream a compiled job with a progress bar, Ctrl-C hold/resume/abort, pen changes,
    copies with their countdown, final report."""
    from fivebar_host.report.text.dryrun import format_duration
    from fivebar_host.run.sender import run_job

    click.echo(f"job: {job.n_segments} segments, {job.n_paths} paths, mode {job.mode}, "
               f"{plan_text(job, copies, format_duration)}, max deviation "
               f"{job.max_dev_mm:.4f} mm")
    if prof.pen is not None:
        click.echo("pen plot: the servo lifts the pen (M280) between strokes; laser output "
                   "stays at 0")
    elif not laser:
        click.echo("laser/pen power output stays at 0 (no servo pen in the profile: M3/M5 "
                   "only mark pen down/up); pass --laser to burn")
    interrupted = {"flag": False}
    overrides = Overrides()

    def on_sigint(signum: int, frame: Any) -> None:
        interrupted["flag"] = True

    link = open_link(port, prof)
    previous = signal.signal(signal.SIGINT, on_sigint)
    try:
        with override_keys(overrides) as keys:
            if keys is not None:
                click.echo(HELP)

            def should_stop() -> bool:
                if keys is not None:
                    keys.poll()
                return interrupted["flag"]

            def on_interrupt() -> bool:
                interrupted["flag"] = False
                if keys is None:
                    return _ask_resume()
                with keys.paused():
                    return _ask_resume()

            def on_pause(pause: LayerPause) -> bool:
                interrupted["flag"] = False
                if keys is None:
                    return ask_pen_change(pause)
                with keys.paused():
                    return ask_pen_change(pause)

            shown = overrides if keys is not None else None
            with _progress_display(job.n_segments, shown, laser, copies.count) as on_progress:
                report = run_job(link, job, prof, drawing=drawing, laser=laser,
                                 confirm=confirm_with(yes), resume=resume,
                                 confirm_placed=confirm_placed(yes),
                                 on_progress=on_progress, should_stop=should_stop,
                                 on_interrupt=on_interrupt, on_note=click.echo,
                                 overrides=overrides, on_pause=on_pause, copies=copies,
                                 on_wait=countdown(copies))
    finally:
        signal.signal(signal.SIGINT, previous)
        link.close()
    planned = planned_time_s(job, copies)
    click.echo(f"done: {report.segments} segments in {report.elapsed_s:.1f} s "
               f"(planned {planned:.1f} s), {report.bytes_sent} bytes sent, "
               f"{report.resends} resends; machine at "
               f"{position_text(prof, report.final.a, report.final.b)}")
    trace = getattr(link.port, "trace_path", None)
    if trace is not None and Path(trace).exists() and copies.count == 1:
        _write_executed(job, prof, Path(trace), preview_path, report.start_segment,
                        report.start_position,
                        getattr(getattr(link.port, "options", None), "true", None))


#: Without a terminal (a log file, systemd): a progress line every this many seconds or
#: this share of the job, whichever comes first.
PROGRESS_EVERY_S = 5.0
PROGRESS_EVERY_SHARE = 0.1


@contextmanager
def _progress_display(total: int, overrides: Overrides | None = None,
                      laser: bool = False, copies: int = 1
                      ) -> Iterator[Callable[[Progress], None]]:
    """The progress hook: a progress bar on a terminal; otherwise one line at a steady pace
    ("plotting: 40% (segment 110/275), 4 s elapsed, ≈ 6 s left"), so a log shows that the
    job advances and when it will end. With `overrides` (keys on a terminal) the bar shows
    the requested feed (and, with `laser`, power) and the time left at that feed. With
    `copies` > 1 the share is of all copies and the text names the copy."""
    def text(p: Progress) -> str:
        of = f"copy {p.copy}/{p.copies}, " if p.copies > 1 else ""
        if overrides is None:
            return (f"{of}segment {p.segments_done}/{p.segments_total}, {p.elapsed_s:.0f} s "
                    f"elapsed, ≈ {p.remaining_s:.0f} s left")
        feed, power = overrides.values()
        left = p.remaining_s * FEED_MAX_PCT / feed
        return (f"{of}segment {p.segments_done}/{p.segments_total}, ≈ {left:.0f} s left, "
                f"feed {feed}%" + (f" power {power}%" if laser else ""))

    def overall(p: Progress) -> int:
        return (p.copy - 1) * p.segments_total + p.segments_done

    if not sys.stdout.isatty():
        last = {"t": time.monotonic(), "share": 0.0}

        def log_line(p: Progress) -> None:
            share = overall(p) / max(1, p.segments_total * p.copies)
            now = time.monotonic()
            if (share >= last["share"] + PROGRESS_EVERY_SHARE and share < 1.0) or (
                    now - last["t"] >= PROGRESS_EVERY_S and share > last["share"]):
                click.echo(f"plotting: {100 * share:.0f}% ({text(p)})")
                last.update(t=now, share=share)

        click.echo("plotting")
        yield log_line
        return
    with click.progressbar(length=total * copies, label="plotting", show_eta=False,
                           show_percent=True, item_show_func=lambda s: s) as bar:
        state = {"done": 0}

        def on_progress(p: Progress) -> None:
            if overall(p) > state["done"]:
                bar.update(overall(p) - state["done"], text(p))
                state["done"] = overall(p)

        yield on_progress


def _write_executed(job: Any, prof: Profile, trace: Path, preview_path: Path,
                    first_segment: int, start_position: tuple[int, int],
                    true: tuple[float, ...] | None = None) -> None:
    """After an emulator run: the executed path from the recorded pulses, next to the
    preview (CSV of pen points and their deviation), and its largest deviation. With the
    emulator's `true=` geometry, the pen points are where that machine really draws."""
    from fivebar_host.compile import write_atomic
    from fivebar_host.devices.simtrace import read_trace
    from fivebar_host.report.text.executed import executed_path, merge_axes, pen_report, true_params

    tr = read_trace(trace)
    t, track = merge_axes(tr.positions("A"), tr.positions("B"))
    ex = executed_path(job, prof, t / tr.freq, track, first_segment, start_position,
                       true=true_params(true))
    out = preview_path.with_name(preview_path.stem + ".executed.csv")
    rows = ["t_s,a_steps,b_steps,x_mm,y_mm,segment,deviation_mm"]
    rows += [f"{ti:.6f},{a},{b},{x:.4f},{y:.4f},{sg},{'' if d != d else f'{d:.5f}'}"
             for ti, (a, b), (x, y), sg, d in zip(t / tr.freq, track.tolist(),
                                                  ex.points.tolist(), ex.segment.tolist(),
                                                  ex.deviation_mm.tolist(), strict=True)]
    write_atomic(out, "\n".join(rows) + "\n")
    where = " (drawn by the URL's true= machine)" if true is not None else ""
    click.echo(f"executed path (from the emulator's step pulses{where}): {out}; drawing "
               f"segments' max deviation "
               f"{ex.max_deviation_mm:.4f} mm (bound {job.tolerance_mm:g} + step quantum "
               f"{job.step_quantum_mm:.4f} mm)")
    if prof.pen is not None:
        click.echo(pen_report(job, prof, tr.pen_pulses(), tr.freq, ex).line())
