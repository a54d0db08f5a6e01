"""`fivebar flash`: the firmware onto a board through its Arduino bootloader, verified."""

from __future__ import annotations

from pathlib import Path

import click

from fivebar_host.cli.common import config_option, fail, handle_errors, load, main


@main.command("flash")
@click.option("--port", default=None, metavar="PORT",
              help="The board's serial port: /dev/ttyUSB0, /dev/ttyACM0, COM3, or "
              "'fivebar-sim://?bootloader=optiboot' (the emulated Uno).")
@click.option("--hex", "hex_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="Write this Intel HEX file instead of the fivebar firmware "
              "built from source (or packaged with fivebar).")
@click.option("--baud", type=click.Choice(["115200", "57600"]), default=None,
              help="The bootloader's rate (default: try Optiboot's 115200, then the old "
              "bootloader's 57600).")
@config_option
@handle_errors
def flash_cmd(port: str | None, hex_path: Path | None, baud: str | None,
              config_path: Path | None) -> None:
    """Write the fivebar firmware to an Arduino Uno or Nano (ATmega328P) and check it.

    Builds the firmware if needed, resets the board into its bootloader, writes and reads
    back every page, waits for the firmware's banner, then writes the settings it keeps in
    its EEPROM (the pen's park pulse on a pen profile)."""
    from fivebar_host.flash.flasher import flash_board
    from fivebar_host.flash.image import firmware_image

    if port is None:
        fail("give --port PORT (the board's serial port; `fivebar doctor` lists them)")
    prof = load(config_path)
    image, source = firmware_image(hex_path)
    click.echo(f"firmware: {source}, {len(image.data)} bytes")
    r = flash_board(str(port), image, prof, baud=int(baud) if baud else None,
                    say=lambda msg: click.echo(msg))
    emulated = (f"; {r.emulated_seconds:.2f} s of emulated time"
                if r.emulated_seconds is not None else "")
    click.echo(f"written and verified: {r.image_bytes} bytes in {r.pages} pages at {r.baud} "
               f"baud in {r.seconds:.2f} s{emulated}")
    assert r.banner is not None
    click.echo(f"the firmware answers: fivebar {r.banner.version}, protocol {r.banner.proto}")
    for s in r.settings:
        click.echo(f"EEPROM: {s}")
    if not r.settings:
        click.echo("EEPROM: nothing to write (the firmware keeps only the pen's park pulse "
                   "there; steps per revolution and the home pose live in the profile)")
