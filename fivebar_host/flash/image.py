"""Which firmware image `fivebar flash` writes.

In order: the `--hex FILE` the user gives; in a checkout with avr-gcc, the firmware built
from source (`make -C firmware all`, a no-op when up to date); the hex packaged with the
Python package (`fivebar_host/flash/fivebar.hex`: a release wheel carries the one built by
`make -C firmware package-hex`, so a `pip install fivebar` user needs no avr-gcc). Without
any of them the error says how to get one."""

from __future__ import annotations

import importlib.resources
import shutil
import subprocess
from pathlib import Path

from fivebar_host.errors import UsageError
from fivebar_host.flash.hexfile import FlashImage, parse_hex, read_hex

#: The ATmega328P's flash, bytes.
FLASH_SIZE = 32768
PACKAGED = "fivebar.hex"


def firmware_image(hex_path: Path | None = None) -> tuple[FlashImage, str]:
    """The image to write and where it came from (module doc)."""
    if hex_path is not None:
        return read_hex(hex_path, FLASH_SIZE), str(hex_path)
    from fivebar_host.devices.sim import firmware_dir

    fw = firmware_dir()
    if (fw / "Makefile").exists() and shutil.which("avr-gcc") and shutil.which("make"):
        proc = subprocess.run(["make", "-s", "-C", str(fw), "all"], capture_output=True,
                              text=True, check=False)
        if proc.returncode != 0:
            raise UsageError(f"the firmware did not build (make -C {fw} all):\n"
                             f"{proc.stdout}{proc.stderr}")
        built = fw / "build" / "fivebar.hex"
        return read_hex(built, FLASH_SIZE), f"{built} (built from source)"
    packaged = importlib.resources.files("fivebar_host.flash").joinpath(PACKAGED)
    if packaged.is_file():
        return (parse_hex(packaged.read_text(encoding="ascii"), "packaged fivebar.hex",
                          FLASH_SIZE), "the hex packaged with fivebar")
    raise UsageError("no firmware to write: this installation has no packaged fivebar.hex and "
                     "no avr-gcc to build one. Install the compiler (Debian: apt-get install "
                     "gcc-avr avr-libc) in a checkout, or give --hex FILE (a release's "
                     "fivebar.hex)")
