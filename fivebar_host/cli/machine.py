"""Machine commands: `fivebar home`, `jog`, `frame` and `status` (laser off in all of them),
on the controller `--controller` names."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from fivebar_host.cli.common import (
    LengthType,
    compile_from_cli,
    config_option,
    controller_option,
    fail,
    handle_errors,
    job_options,
    load,
    machine,
    main,
    port_option,
    yes_option,
)
from fivebar_host.cli.operator import TerminalOperator

LENGTH = LengthType()


@main.command("home")
@port_option
@yes_option
@controller_option
@config_option
@handle_errors
def home_cmd(port: str | None, yes: bool, controller: str, config_path: Path | None) -> None:
    """Give the controller a known position: $H with endstops, else confirm the home pose."""
    c = machine(port, controller, load(config_path))
    try:
        pos = c.home(TerminalOperator(yes))
    finally:
        c.close()
    click.echo(f"homed: {c.describe(pos)}")


@main.command("jog")
@port_option
@click.option("--motor", type=click.Choice(["A", "B"]), default=None,
              help="Move one motor (with --steps).")
@click.option("--steps", type=int, default=0, help="Steps for --motor (signed).")
@click.option("--dx", type=LENGTH, default="0", metavar="LENGTH",
              help="Move the pen by this much in x: mm, or with a unit (5mm, 0.5in, 1cm).")
@click.option("--dy", type=LENGTH, default="0", metavar="LENGTH",
              help="Move the pen by this much in y, like --dx.")
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

    if (motor is None) == (dx == 0.0 and dy == 0.0):
        fail("give either --motor with --steps, or --dx/--dy")
    prof = load(config_path)
    kin = prof.kinematics
    mode = kin.working_mode if kin.working_mode != "auto" else "+-"
    c = machine(port, controller, prof)
    try:
        st = c.status()
        checked = st.homed or motor is None
        if checked:
            pos = c.ensure_pose(TerminalOperator(yes))
        else:
            pos = st.position
            click.echo("position unknown (not homed): the motor move is not checked against "
                       "limits or singularities", err=True)
        prog = jog_program(prof, 1 if kin.assembly == "+" else -1, mode, pos, motor=motor,
                           steps=steps, dxy_mm=None if motor else (dx, dy), checked=checked)
        pos = c.run_moves(prog, pos)
    finally:
        c.close()
    where = (c.describe(pos) if checked
             else f"A = {pos[0]} steps, B = {pos[1]} steps (position unknown: not homed)")
    click.echo(f"at {where}")


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

    prof, job = compile_from_cli(drawing, config_path, job_values)
    c = machine(port, controller, prof)
    try:
        pos = c.ensure_pose(TerminalOperator(yes))
        pos = c.run_moves(frame_program(job, prof, pos), pos)
    finally:
        c.close()
    x0, y0, x1, y1 = job.placement.machine_bbox
    click.echo(f"framed ({x0:.1f}, {y0:.1f})–({x1:.1f}, {y1:.1f}) mm; back at "
               f"{c.describe(pos)}")


@main.command("status")
@port_option
@controller_option
@config_option
@handle_errors
def status_cmd(port: str | None, controller: str, config_path: Path | None) -> None:
    """Where the machine is (motor steps and pen mm) and what it is doing; moves nothing."""
    c = machine(port, controller, load(config_path))
    try:
        st = c.status()
    finally:
        c.close()
    state = st.state + (f" {st.detail}" if st.detail is not None else "")
    a, b = st.position
    where = (c.describe(st.position) if st.homed
             else f"A = {a} steps, B = {b} steps (position unknown: not homed)")
    click.echo(f"{state}: {where}; laser {'on' if st.laser else 'off'}")
