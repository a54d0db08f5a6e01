"""Machine commands: `fivebar home`, `jog` and `frame` (laser off in all three)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from fivebar_host.cli.common import (
    compile_from_cli,
    config_option,
    confirm_with,
    fail,
    handle_errors,
    job_options,
    load,
    main,
    open_link,
    port_option,
    position_text,
    yes_option,
)
from fivebar_host.cli.grbl import controller_option


@main.command("home")
@port_option
@yes_option
@controller_option
@config_option
@handle_errors
def home_cmd(port: str | None, yes: bool, controller: str, config_path: Path | None) -> None:
    """Give the firmware a known position: $H with endstops, else confirm the home pose."""
    from fivebar_host.run.sender import home


    prof = load(config_path)
    if controller == "grbl":
        from fivebar_host.cli.grbl import grbl_home

        grbl_home(port, prof, yes)
        return
    link = open_link(port, prof)
    try:
        st = home(link, prof, confirm_with(yes))
    finally:
        link.close()
    click.echo(f"homed: {position_text(prof, st.a, st.b)}")


@main.command("jog")
@port_option
@click.option("--motor", type=click.Choice(["A", "B"]), default=None,
              help="Move one motor (with --steps).")
@click.option("--steps", type=int, default=0, help="Steps for --motor (signed).")
@click.option("--dx", type=float, default=0.0, help="Move the pen by this much in x, mm.")
@click.option("--dy", type=float, default=0.0, help="Move the pen by this much in y, mm.")
@yes_option
@controller_option
@config_option
@handle_errors
def jog(port: str | None, motor: str | None, steps: int, dx: float, dy: float, yes: bool,
        controller: str, config_path: Path | None) -> None:
    """Move one motor by --steps, or the pen by --dx/--dy mm (laser off).

    A pen move needs a known position (homed) and is checked; a motor move before homing
    (to bring the arms to the home pose) is not checked, and says so."""
    from fivebar_host.run.moves import jog_program
    from fivebar_host.run.sender import ensure_known_pose

    if (motor is None) == (dx == 0.0 and dy == 0.0):
        fail("give either --motor with --steps, or --dx/--dy")
    prof = load(config_path)
    kin = prof.kinematics
    mode = kin.working_mode if kin.working_mode != "auto" else "+-"
    if controller == "grbl":
        from fivebar_host.cli.grbl import grbl_moves

        pos = grbl_moves(port, prof, yes, lambda p: jog_program(
            prof, 1 if kin.assembly == "+" else -1, mode, p, motor=motor, steps=steps,
            dxy_mm=None if motor else (dx, dy), checked=True))
        click.echo(f"at {position_text(prof, *pos)}")
        return
    link = open_link(port, prof)
    try:
        st = link.status()
        checked = st.homed or motor is None
        if checked:
            st = ensure_known_pose(link, prof, confirm_with(yes))
        else:
            click.echo("position unknown (not homed): the motor move is not checked against "
                       "limits or singularities", err=True)
        prog = jog_program(prof, 1 if kin.assembly == "+" else -1, mode, (st.a, st.b),
                           motor=motor, steps=steps, dxy_mm=None if motor else (dx, dy),
                           checked=checked)
        link.stream(prog)
        st = link.wait_idle(60.0)
    finally:
        link.close()
    click.echo(f"at {position_text(prof, st.a, st.b, st.homed)}")


@main.command("frame")
@click.argument("drawing", type=click.Path(dir_okay=False, path_type=Path))
@port_option
@yes_option
@controller_option
@job_options(laser=False)
@handle_errors
def frame(drawing: Path, port: str | None, yes: bool, controller: str,
          config_path: Path | None, **job_values: Any) -> None:
    """Trace the outline (bounding box) of DRAWING's job with the laser off, then go home."""
    from fivebar_host.run.moves import frame_program
    from fivebar_host.run.sender import ensure_known_pose

    prof, job = compile_from_cli(drawing, config_path, job_values)
    if controller == "grbl":
        from fivebar_host.cli.grbl import grbl_moves

        pos = grbl_moves(port, prof, yes, lambda p: frame_program(job, prof, p))
        click.echo(f"framed; back at {position_text(prof, *pos)}")
        return
    link = open_link(port, prof)
    try:
        st = ensure_known_pose(link, prof, confirm_with(yes))
        prog = frame_program(job, prof, (st.a, st.b))
        link.stream(prog)
        st = link.wait_idle(120.0)
    finally:
        link.close()
    x0, y0, x1, y1 = job.placement.machine_bbox
    click.echo(f"framed ({x0:.1f}, {y0:.1f})–({x1:.1f}, {y1:.1f}) mm; back at "
               f"{position_text(prof, st.a, st.b)}")


@main.command("status")
@port_option
@config_option
@handle_errors
def status_cmd(port: str | None, config_path: Path | None) -> None:
    """Where the machine is (motor steps and pen mm) and what it is doing; moves nothing."""
    prof = load(config_path)
    link = open_link(port, prof)
    try:
        st = link.status()
    finally:
        link.close()
    state = st.state + (f" {st.detail}" if st.detail is not None else "")
    click.echo(f"{state}: {position_text(prof, st.a, st.b, st.homed)}; laser "
               f"{'on' if st.laser else 'off'}")
