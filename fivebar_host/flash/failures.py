"""The ways flashing a board fails, each as one line: what happened, the likely cause and
the fix (the failures makers meet most: avrdude's `stk500_recv(): programmer is not
responding`, `not in sync`, a wrong signature, a verify mismatch, a busy port, permission
denied on /dev/ttyUSB0)."""

from __future__ import annotations

from fivebar_host.errors import FivebarError
from fivebar_host.flash.stk500 import Fault, Stk500Error
from fivebar_host.protocol import Banner, trailing_banner

#: The ATmega328P's signature, and the chips a maker may find on a board instead.
ATMEGA328P = bytes((0x1E, 0x95, 0x0F))
CHIPS = {ATMEGA328P: "ATmega328P", bytes((0x1E, 0x95, 0x14)): "ATmega328 (not P)",
         bytes((0x1E, 0x94, 0x06)): "ATmega168", bytes((0x1E, 0x94, 0x0B)): "ATmega168P",
         bytes((0x1E, 0x93, 0x0A)): "ATmega88P", bytes((0x1E, 0x93, 0x07)): "ATmega8"}


class FlashError(FivebarError):
    """Flashing failed; the message says why and what to do. `kind` names the failure."""

    exit_code = 3

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


def open_failure(url: str, exc: BaseException) -> FlashError:
    """A port that would not open: busy, permission, missing, or another OS error
    (`controllers.ports.open_trouble`)."""
    from fivebar_host.controllers.ports import open_trouble

    return FlashError(*open_trouble(url, exc))


def no_bootloader(url: str, faults: dict[int, Stk500Error]) -> FlashError:
    """No bootloader answered at any rate tried: no reply at all, or bytes that are not a
    bootloader's (out of sync)."""
    rates = " nor ".join(f"{b} baud" for b in faults)
    got = b"".join(e.got for e in faults.values())
    if not got:
        return FlashError("no_reply", f"{url}: no reply from a bootloader at {rates} "
                          "(avrdude: 'programmer is not responding'). Likely: RESET held "
                          "(a shield or a wire on RESET: unplug the shield), no bootloader on "
                          "the chip (burn one with an ISP, e.g. Arduino as ISP), the wrong "
                          "port, or a board that does not reset on DTR (press its reset "
                          "button as the flash starts)")
    text = got.decode("ascii", errors="replace")
    banner = _banner(text)
    if banner is not None:
        return FlashError("out_of_sync", f"{url}: the board answered as the fivebar firmware "
                          f"{banner.version} (its banner), not as a bootloader: no bootloader ran "
                          "after the reset (none on the chip, or auto-reset cut). Press the "
                          "reset button as the flash starts, or burn a bootloader with an ISP")
    return FlashError("out_of_sync", f"{url}: the board answers but not as a bootloader (not "
                      f"in sync: got {got[:24]!r}): another program on the chip without a "
                      "bootloader, a rate none of "
                      f"{', '.join(map(str, faults))} baud (--baud), or noise on the line")


def wrong_signature(url: str, sig: bytes) -> FlashError:
    """The chip is not an ATmega328P."""
    chip = CHIPS.get(sig, "an unknown chip")
    return FlashError("signature", f"{url}: the chip's signature is {sig.hex(' ').upper()} "
                      f"({chip}), not the ATmega328P's 1E 95 0F: the fivebar firmware needs "
                      "an ATmega328P (32 KB flash, 2 KB RAM). Use an Uno or a Nano with a "
                      "328P; nothing was written")


def verify_mismatch(url: str, bad: list[tuple[int, int, int]]) -> FlashError:
    """Read-back differs: (address, written, read) of the first differing bytes."""
    at, want, got = bad[0]
    pages = sorted({a // 128 for a, _, _ in bad})
    return FlashError("verify", f"{url}: verify failed: flash byte 0x{at:04X} reads "
                      f"0x{got:02X} where 0x{want:02X} was written ({len(bad)} bytes differ, "
                      f"in page{'s' if len(pages) > 1 else ''} "
                      f"{', '.join(map(str, pages[:6]))}): the flash did not take the write "
                      "(worn cells or lock bits). The board holds a broken program: flash "
                      "again; if the same address fails, the chip is worn or locked")


def during(url: str, what: str, exc: Stk500Error) -> FlashError:
    """A bootloader that stopped answering in the middle."""
    return FlashError("lost", f"{url}: the bootloader stopped answering while {what} "
                      f"({exc}): a loose cable, a board that reset (power), or noise. Flash "
                      "again; the old program is gone until a flash completes")


def classify(url: str, exc: BaseException) -> FlashError | None:
    """A FlashError for an OS or pyserial error on `url` (None for anything else)."""
    import serial

    if isinstance(exc, (serial.SerialException, OSError)):
        return open_failure(url, exc)
    return None


def _banner(text: str) -> Banner | None:
    """The firmware's banner among the lines a board sent, if any."""
    for line in text.splitlines():
        banner = trailing_banner(line.strip())
        if banner is not None:
            return banner
    return None


__all__ = [
    "ATMEGA328P",
    "Fault",
    "FlashError",
    "Stk500Error",
    "classify",
    "during",
    "no_bootloader",
    "open_failure",
    "verify_mismatch",
    "wrong_signature",
]
