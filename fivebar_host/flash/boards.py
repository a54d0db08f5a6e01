"""Which board is behind a port, from its USB ids, and whether `fivebar flash` can program
it.

The fivebar firmware is for the ATmega328P (Uno, Nano, their clones) through the Arduino
bootloader (STK500v1 over the USB serial adapter). Boards that look similar from the outside
but are another chip or another protocol are refused by their USB ids before anything is
sent, with the reason; an adapter that could be on any board (CH340, FTDI, CP210x) is let
through, and the bootloader's signature check decides."""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Board:
    """What a USB id says about the board: its name and, when it cannot be flashed, why."""

    name: str
    refuse: str = ""  # why fivebar flash cannot program it ('' = it can try)


_R4 = ("an Arduino UNO R4 (Renesas RA4M1, an ARM chip, not an AVR): the fivebar firmware "
       "runs on the ATmega328P only. Use an Uno R3 or a Nano (or a clone with a CH340)")
#: (vendor id, product id) → board; the ids Arduino's board definitions and the adapters use.
BOARDS: dict[tuple[int, int], Board] = {
    (0x2341, 0x0043): Board("Arduino Uno R3"), (0x2341, 0x0001): Board("Arduino Uno"),
    (0x2A03, 0x0043): Board("Arduino Uno R3 (arduino.org)"),
    (0x2341, 0x0243): Board("Arduino Uno R3 (16U2)"),
    (0x1A86, 0x7523): Board("a CH340 USB serial adapter (an Uno or Nano clone)"),
    (0x1A86, 0x55D4): Board("a CH9102 USB serial adapter (an Uno or Nano clone)"),
    (0x0403, 0x6001): Board("an FTDI FT232R adapter (a Nano, Duemilanove or FTDI cable)"),
    (0x10C4, 0xEA60): Board("a CP210x USB serial adapter"),
    (0x2341, 0x0069): Board("Arduino UNO R4 Minima", _R4),
    (0x2341, 0x0369): Board("Arduino UNO R4 Minima (in its bootloader)", _R4),
    (0x2341, 0x1002): Board("Arduino UNO R4 WiFi", _R4),
    (0x2341, 0x006D): Board("Arduino UNO R4 WiFi", _R4),
    (0x2341, 0x0058): Board("Arduino Nano Every", "an Arduino Nano Every (ATmega4809, "
                            "programmed over UPDI, not with the STK500 bootloader): the "
                            "fivebar firmware runs on the ATmega328P only. Use a classic Nano "
                            "(ATmega328P) or an Uno"),
    (0x2341, 0x8036): Board("Arduino Leonardo", "an Arduino Leonardo (ATmega32U4 with the "
                            "Caterina bootloader, AVR109): the fivebar firmware runs on the "
                            "ATmega328P only. Use an Uno or a Nano"),
    (0x2341, 0x0036): Board("Arduino Leonardo (bootloader)", "an Arduino Leonardo "
                            "(ATmega32U4): the fivebar firmware runs on the ATmega328P only"),
    (0x2341, 0x0042): Board("Arduino Mega 2560", "an Arduino Mega 2560 (ATmega2560, "
                            "STK500v2): the fivebar firmware runs on the ATmega328P only. Use "
                            "an Uno or a Nano"),
    (0x2341, 0x0010): Board("Arduino Mega 2560", "an Arduino Mega 2560 (ATmega2560): the "
                            "fivebar firmware runs on the ATmega328P only"),
}


def board_for(usb: tuple[int, int] | None) -> Board | None:
    """The board of a USB id pair (None: not a USB port, or an id this table lacks)."""
    return None if usb is None else BOARDS.get(usb)


def port_usb_id(url: str, port: Any = None) -> tuple[int, int] | None:
    """The USB (vendor, product) ids of `url`: an open emulated port says (`usb_id`, from
    its URL's `usb=`); a device path is looked up in pyserial's port list."""
    if port is not None and hasattr(port, "usb_id"):
        usb: tuple[int, int] | None = port.usb_id
        return usb
    if "://" in url:
        return None
    from serial.tools import list_ports

    real = os.path.realpath(url)
    for info in list_ports.comports():
        if os.path.realpath(info.device) == real and info.vid is not None:
            return (int(info.vid), int(info.pid))
    return None


def describe_usb(usb: tuple[int, int] | None) -> str:
    """"Arduino Uno R3 (USB 2341:0043)", "USB 1234:5678 (unknown)" or "no USB ids"."""
    if usb is None:
        return "no USB ids (not a USB serial port, or not known to the system)"
    board = board_for(usb)
    ids = f"USB {usb[0]:04X}:{usb[1]:04X}"
    return f"{board.name} ({ids})" if board else f"{ids} (not a board fivebar knows)"
