"""`--controller grbl` (a stock GRBL 1.1 board in joint space) and `fivebar grbl-settings`.

The commands `plot`, `convert`, `frame`, `jog` and `home` take `--controller fivebar|grbl`;
with `grbl` they hand over to the functions here, so fivebar's own path stays as it was.
"""

from __future__ import annotations

import signal
from pathlib import Path
from typing import Any

import click

from fivebar_host.cli.common import (
    config_option,
    confirm_placed,
    confirm_with,
    handle_errors,
    load,
    main,
    open_link,
)
from fivebar_host.config import Profile

controller_option = click.option(
    "--controller", type=click.Choice(["fivebar", "grbl"]), default="fivebar",
    show_default=True,
    help="fivebar: fivebar's own firmware; grbl: a stock GRBL 1.1 board driven in joint "
    "space (G1 X<θA> Y<θB> in degrees; `fivebar grbl-settings` lists its $ settings).")


@main.command("grbl-settings")
@config_option
@handle_errors
def grbl_settings(config_path: Path | None) -> None:
    """Print the $ settings a stock GRBL 1.1 board needs for this profile (send each line
    to the board once; `--controller grbl` checks them against `$$` before every job)."""
    from fivebar_host.controllers.grbl.program import needed_settings

    prof = load(config_path)
    for s in needed_settings(prof):
        click.echo(f"{s.text():<16} ; {s.why}")


def open_grbl(port: str | None, prof: Profile) -> Any:
    """Open the GRBL board at --port."""
    return open_link(port, prof, controller="grbl")


def grbl_convert(output: Path, prof: Profile, job: Any, laser: bool) -> None:
    """`convert --controller grbl`: the job as the G-code lines the board gets."""
    from fivebar_host.compile import write_atomic
    from fivebar_host.controllers.grbl.program import job_program

    prog = job_program(job, prof, laser)
    write_atomic(output, "\n".join(prog.lines) + "\n")
    click.echo(f"wrote {output}: {len(prog.lines)} GRBL lines (G1 X/Y = motor angles in "
               f"degrees) for {job.n_segments} segments, ≈ {job.total_time_s:.1f} s planned")


def grbl_plot(port: str, prof: Profile, job: Any, *, laser: bool, yes: bool,
              drawing: Path | None = None, resume: bool = False) -> None:
    """`plot --controller grbl`: check the board, stream, Ctrl-C holds (laser off); a
    fault or an abort leaves a resume file, `--resume` continues from it."""
    from fivebar_host.cli.plot import _ask_resume
    from fivebar_host.controllers.grbl.run import angles_text, run_grbl_job

    click.echo(f"job: {job.n_segments} segments, mode {job.mode}, ≈ {job.total_time_s:.1f} s "
               f"planned, max deviation {job.max_dev_mm:.4f} mm; GRBL in joint space")
    flag = {"stop": False}

    def on_sigint(signum: int, frame: Any) -> None:
        flag["stop"] = True

    def on_interrupt() -> bool:
        flag["stop"] = False
        return _ask_resume()

    link = open_grbl(port, prof)
    previous = signal.signal(signal.SIGINT, on_sigint)
    try:
        rep = run_grbl_job(link, job, prof, laser=laser, confirm=confirm_with(yes),
                           should_stop=lambda: flag["stop"], on_interrupt=on_interrupt,
                           drawing=drawing, resume=resume, confirm_placed=confirm_placed(yes),
                           on_note=click.echo)
    finally:
        signal.signal(signal.SIGINT, previous)
        link.close()
    click.echo(f"done: {rep.segments} segments in {rep.lines} GRBL lines, {rep.bytes_sent} "
               f"bytes; board at {angles_text(prof, rep.final)}")


def grbl_home(port: str | None, prof: Profile, yes: bool) -> None:
    """`home --controller grbl`."""
    from fivebar_host.controllers.grbl.run import angles_text, home_grbl

    link = open_grbl(port, prof)
    try:
        pos = home_grbl(link, prof, confirm_with(yes))
    finally:
        link.close()
    click.echo(f"homed: {angles_text(prof, pos)} (work X/Y = motor angles)")


def grbl_moves(port: str | None, prof: Profile, yes: bool, make: Any) -> tuple[int, int]:
    """`jog`/`frame --controller grbl`: settings, pose, then fivebar's checked laser-off
    lines `make(position)` on the board; the end position."""
    from fivebar_host.controllers.grbl.run import check_settings, ensure_pose, stream_moves

    link = open_grbl(port, prof)
    try:
        check_settings(link, prof)
        pos = ensure_pose(link, prof, confirm_with(yes))
        return stream_moves(link, prof, make(pos), pos)
    finally:
        link.close()
