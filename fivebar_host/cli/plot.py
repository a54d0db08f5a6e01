"""`fivebar convert` and `fivebar plot`: a drawing to a controller's lines, or onto the
machine.

Both take the job options generated from `fivebar_host.options`; `plot --server` hands the
same values to a running daemon (`fivebar_host.cli.remote`); `plot --port` runs the job
through `cli.session.plot_on_machine` on the controller `--controller` names.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from fivebar_host.cli.common import (
    compile_from_cli,
    controller_option,
    fail,
    handle_errors,
    job_options,
    main,
    port_option,
    yes_option,
)
from fivebar_host.cli.remote import server_option
from fivebar_host.cli.session import Plot, plot_on_machine
from fivebar_host.cli.stops import check_stops
from fivebar_host.controllers import controller_for
from fivebar_host.run.controller import check_job
from fivebar_host.run.stops import Copies


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
    from fivebar_host.compile import write_atomic

    cls = controller_for(controller)
    prof, job = compile_from_cli(drawing, config_path, job_values)
    out = cls.convert(job, prof, bool(job_values["laser"]), relative)
    write_atomic(output, "\n".join(out.lines) + "\n")
    click.echo(f"wrote {output}: {out.summary}")


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

    DRAWING is an SVG or G-code file, or an image (PNG, JPEG, BMP, GIF, TIFF, WebP) that
    --laser engraves pixel by pixel. Everything is checked before anything moves. Ctrl-C
    holds the machine at once (laser off) and asks whether to resume or abort; a fault or an
    abort leaves a resume file, and the same command with --resume continues exactly where
    the machine stopped.
    """
    plot_file(drawing, dry_run, preview_path, port, resume, yes, controller, config_path,
              job_values)


def plot_file(drawing: Path, dry_run: bool, preview_path: Path, port: str | None,
              resume: bool, yes: bool, controller: str, config_path: Path | None,
              job_values: dict[str, Any]) -> None:
    """`fivebar plot` itself (also `fivebar text --dry-run/--port` on the file it wrote)."""
    if not dry_run and port is None:
        fail("give --port PORT to plot on a machine (e.g. /dev/ttyUSB0 or fivebar-sim:// "
             "for the emulator), or --dry-run for the preview and report")
    from fivebar_host.compile import nbar_opinion
    from fivebar_host.report.preview import draw_preview
    from fivebar_host.report.text.dryrun import report_lines

    laser = bool(job_values["laser"])
    copies = Copies(int(job_values["copies"]), float(job_values["page_delay_s"]))
    if port is not None and not dry_run:
        from fivebar_host.controllers.ports import refuse_if_held

        refuse_if_held(port)  # before compiling: another process owns the machine
    prof, job = compile_from_cli(drawing, config_path, job_values)
    features = controller_for(controller).features
    if not dry_run:
        check_job(features, job)  # before the port opens
    if dry_run and job.raster is not None:
        from fivebar_host.raster import preview

        for line in preview.report_lines(job, laser, copies):
            click.echo(line)
        if features.raster is not None:
            click.echo(f"controller    --controller {controller} cannot engrave it: "
                       f"{features.raster}")
        preview.draw_preview(job, preview_path)
        click.echo(f"preview       {preview_path}")
        return
    if dry_run:
        for line in report_lines(job, nbar_opinion(job, prof), laser=laser, profile=prof,
                                 copies=copies):
            click.echo(line)
        draw_preview(job, prof, preview_path)
        click.echo(f"preview       {preview_path}")
        return
    assert port is not None
    check_stops(job)
    plot_on_machine(Plot(drawing, port, controller, laser, resume, yes, copies, preview_path),
                    prof, job)
