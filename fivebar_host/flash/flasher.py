"""`fivebar flash`: write the fivebar firmware to a board through its Arduino bootloader,
verify it by reading it back, and check that the firmware answers.

Steps: refuse a board its USB ids say is not an ATmega328P one; open the port; reset the
board into its bootloader and find the rate it speaks (Optiboot at 115200, the old
ATmegaBOOT at 57600; `baud` forces one); check the chip's signature; write every page,
read every page back and compare; leave the bootloader (which starts the new program);
wait for the firmware's banner on the same port; write the settings the firmware keeps in
its EEPROM (the pen's park pulse, `$14`, on a pen profile). Every failure is a FlashError
of one line: the cause and the fix (`fivebar_host.flash.failures`)."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from fivebar_host.config import Profile
from fivebar_host.flash import failures
from fivebar_host.flash.boards import board_for, describe_usb, port_usb_id
from fivebar_host.flash.hexfile import FlashImage
from fivebar_host.flash.stk500 import PARM_SW_MAJOR, Stk500, Stk500Error
from fivebar_host.protocol import Banner

#: The rates bootloaders speak, tried in this order, and each one's boot section start
#: (the application must end below it).
BAUDS = {115200: ("Optiboot", 0x7E00), 57600: ("ATmegaBOOT", 0x7800)}
PAGE = 128
CPU_HZ = 16_000_000


@dataclass
class FlashReport:
    """What was done: the board, the bootloader, the image, the time, the firmware."""

    url: str
    board: str
    baud: int = 0
    bootloader: str = ""
    signature: bytes = b""
    image_bytes: int = 0
    pages: int = 0
    seconds: float = 0.0  # from the reset into the bootloader to the verified image
    emulated_seconds: float | None = None  # the same in the emulator's CPU time
    banner: Banner | None = None
    settings: list[str] = field(default_factory=list)


Say = Callable[[str], None]


def flash_board(url: str, image: FlashImage, profile: Profile, *, baud: int | None = None,
                say: Say = lambda _: None) -> FlashReport:
    """Flash `image` to the board at `url` (module doc); FlashError on any failure."""
    import serial

    from fivebar_host.controllers import ports

    report = FlashReport(url, describe_usb(None))
    try:  # held for this process first (`controllers.ports`: a second opener is refused)
        port, lock = ports.open_port(url, baudrate=baud or 115200, timeout=0.05,
                                     write_timeout=5.0)
    except (serial.SerialException, OSError, ValueError) as e:
        raise failures.open_failure(url, e) from e
    try:
        usb = port_usb_id(url, port)
        report.board = describe_usb(usb)
        board = board_for(usb)
        if board is not None and board.refuse:
            raise failures.FlashError("board", f"{url}: this is {board.refuse}; nothing was "
                                      "written")
        say(f"board: {report.board}")
        _program(port, url, image, baud, report, say)
        report.banner = _firmware_answers(port, url, profile, report, say)
    except (serial.SerialException, OSError) as e:
        raise failures.open_failure(url, e) from e
    finally:
        ports.close_port(port, lock)
    return report


def _program(port: Any, url: str, image: FlashImage, baud: int | None, report: FlashReport,
             say: Say) -> None:
    """Bootloader, signature, write, verify, leave (module doc)."""
    start = time.monotonic()
    cycle0 = _cycle(port)
    boot = _find_bootloader(port, url, baud, report, say)
    sig = boot.signature()
    report.signature = sig
    if sig != failures.ATMEGA328P:
        raise failures.wrong_signature(url, sig)
    end = BAUDS.get(report.baud, ("", 0x7800))[1]
    if len(image.data) > end:
        raise failures.FlashError("too_big", f"{url}: the image is {len(image.data)} bytes; "
                                  f"the application space below this bootloader ends at "
                                  f"0x{end:04X} ({end} bytes); nothing was written")
    pages = image.pages(PAGE)
    report.image_bytes, report.pages = len(image.data), len(pages)
    try:
        boot.enter()
        say(f"writing {len(image.data)} bytes ({len(pages)} pages of {PAGE})…")
        for addr, page in pages:
            boot.write_page(addr, page)
        say("verifying (reading every page back)…")
        bad = []
        for addr, page in pages:
            got = boot.read_page(addr, PAGE)
            bad += [(addr + i, w, r) for i, (w, r) in enumerate(zip(page, got, strict=True))
                    if w != r]
    except Stk500Error as e:
        raise failures.during(url, "writing and verifying", e) from e
    if bad:
        raise failures.verify_mismatch(url, bad)
    report.seconds = time.monotonic() - start
    cycle1 = _cycle(port)
    if cycle0 is not None and cycle1 is not None:
        report.emulated_seconds = (cycle1 - cycle0) / CPU_HZ
    try:
        boot.leave()
    except Stk500Error as e:
        raise failures.during(url, "leaving the bootloader", e) from e


def _find_bootloader(port: Any, url: str, baud: int | None, report: FlashReport,
                     say: Say) -> Stk500:
    """Reset into the bootloader at each rate until one answers (module doc)."""
    faults: dict[int, Stk500Error] = {}
    for rate in ([baud] if baud else list(BAUDS)):
        port.baudrate = rate
        boot = Stk500(port)
        say(f"resetting the board into its bootloader at {rate} baud…")
        boot.reset()
        try:
            boot.sync()
            major = boot.parameter(PARM_SW_MAJOR)
            version = boot.version()
        except Stk500Error as e:
            faults[rate] = e
            continue
        name = "Optiboot" if major >= 4 else "ATmegaBOOT (the old bootloader)"
        report.baud, report.bootloader = rate, f"{name} {version}"
        say(f"bootloader: {report.bootloader} at {rate} baud")
        return boot
    raise failures.no_bootloader(url, faults)


def _firmware_answers(port: Any, url: str, profile: Profile, report: FlashReport,
                      say: Say) -> Banner:
    """The new firmware's banner on the same port, then its EEPROM settings."""
    from fivebar_host import protocol
    from fivebar_host.controllers.fivebar.link import Link
    from fivebar_host.run.errors import LinkError

    port.baudrate = protocol.BASE_BAUD
    link = Link(port, url=url, reply_timeout_s=profile.serial.reply_timeout_s)
    say("waiting for the new firmware's banner…")
    try:
        banner = link.handshake(max(5.0, profile.serial.banner_timeout_s))
    except LinkError as e:
        raise failures.FlashError("silent", f"{url}: written and verified, but the firmware "
                                  f"does not answer ({e}). Press the reset button; if it "
                                  "still says nothing, check the board's clock (16 MHz)") from e
    if profile.pen is not None:
        park = profile.pen.pulse_us(profile.pen.up_position)
        try:
            link.command(f"$14={park}")
        except LinkError as e:
            raise failures.FlashError("settings", f"{url}: the firmware refused the pen's "
                                      f"park pulse $14={park}: {e}") from e
        report.settings.append(f"$14={park} (the pen's up position, kept in the EEPROM)")
    return banner


def _cycle(port: Any) -> int | None:
    """The emulated CPU's cycle count, on the emulator's port (None on a real one)."""
    fn = getattr(port, "emulated_cycle", None)
    return None if fn is None else int(fn())
