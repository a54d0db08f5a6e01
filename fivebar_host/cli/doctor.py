"""`fivebar wiring` (the pin map) and `fivebar doctor` (a first-run check of the port, the
board, the firmware and the profile, in words)."""

from __future__ import annotations

import math
from pathlib import Path

import click

from fivebar_host.cli.common import config_option, handle_errors, load, main


@main.command("wiring")
@click.option("--board", type=click.Choice(["shield", "bare"]), default="shield",
              show_default=True, help="shield: the Arduino CNC shield (V3, or the Nano's V4); "
              "bare: an Uno or Nano wired to driver boards by hand.")
@click.option("--picture", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Also draw the pin map as a PNG picture (docs/wiring.png).")
def wiring_cmd(board: str, picture: Path | None) -> None:
    """Where each wire goes: steppers, endstops, laser and pen servo (firmware pins)."""
    from fivebar_host.wiring import BOARDS_NOTE, table

    for line in table(board):
        click.echo(line)
    click.echo(BOARDS_NOTE)
    if picture is not None:
        from fivebar_host.report.wiring import draw_wiring

        click.echo(f"picture: {draw_wiring(picture)}")


@main.command("doctor")
@click.option("--port", default=None, metavar="PORT",
              help="The board's port (default: list the serial ports and stop).")
@config_option
@handle_errors
def doctor_cmd(port: str | None, config_path: Path | None) -> None:
    """First-run check: the port, the board, the firmware, the profile's steps per revolution
    and home pose, and what is wrong, in words. Moves nothing."""
    prof = load(config_path)
    m = prof.motors
    h1, h2 = (math.degrees(v) for v in m.home_rad)
    click.echo(f"profile: {config_path or 'the bundled default (configs/default.toml)'}: "
               f"{prof.tool}, {m.steps_per_rev:g} steps per motor revolution "
               f"({m.full_steps} full steps × {m.microsteps} microsteps × gear "
               f"{m.gear_ratio:g}), home pose θ1 = {h1:g}°, θ2 = {h2:g}°, "
               f"{'endstops' if m.endstops else 'no endstops (home by placing the arms)'}")
    if port is None:
        _list_ports()
        return
    problems = _check_port(str(port), prof)
    if problems:
        for p in problems:
            click.echo(f"problem: {p}")
        raise SystemExit(3)
    click.echo("all good: the board answers and the profile fits it")


def _list_ports() -> None:
    from serial.tools import list_ports

    from fivebar_host.flash.boards import describe_usb

    ports = list(list_ports.comports())
    if not ports:
        click.echo("no serial ports: plug the board in (a USB cable that carries data, not a "
                   "charging cable); then `fivebar doctor --port PORT`")
        return
    for info in ports:
        usb = (int(info.vid), int(info.pid)) if info.vid is not None else None
        click.echo(f"port {info.device}: {describe_usb(usb)}")
    click.echo("then: fivebar doctor --port PORT")


def _check_port(url: str, prof: object) -> list[str]:
    """What is wrong with the board at `url` (nothing: an empty list), saying what is right
    on the way."""
    from fivebar_host.config import Profile
    from fivebar_host.controllers.fivebar.link import Link
    from fivebar_host.flash.boards import board_for, describe_usb, port_usb_id
    from fivebar_host.run.errors import LinkError

    assert isinstance(prof, Profile)
    problems = []
    try:
        link = Link.open(url, baud=prof.serial.baud, banner_timeout_s=prof.serial.banner_timeout_s,
                         reply_timeout_s=prof.serial.reply_timeout_s)
    except LinkError as e:
        usb = port_usb_id(url)
        board = board_for(usb)
        click.echo(f"board: {describe_usb(usb)}")
        if board is not None and board.refuse:
            return [f"this is {board.refuse}"]
        return [f"{e} — if the board is new or runs something else, flash it: "
                f"fivebar flash --port {url}"]
    try:
        usb = port_usb_id(url, link.port)
        click.echo(f"board: {describe_usb(usb)}")
        assert link.banner is not None
        click.echo(f"firmware: fivebar {link.banner.version}, protocol {link.banner.proto}")
        st = link.status()
        if st.homed:
            click.echo(f"position: A = {st.a}, B = {st.b} steps, known (homed)")
        else:
            click.echo("position: unknown since power-up: `fivebar home --port "
                       f"{url}` before the first job")
        if st.state == "Alarm":
            problems.append(f"the controller is in alarm {st.detail}: `fivebar home` clears "
                            "it")
    finally:
        link.close()
    return problems

