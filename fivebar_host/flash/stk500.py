"""STK500 version 1, the protocol of the Arduino bootloaders (Optiboot on the Uno, the old
ATmegaBOOT on the Duemilanove and early Nanos), as far as programming the flash needs it.

A small client over any pyserial-like port (`read`, `write`, `dtr`, `reset_input_buffer`):
every command is its bytes then CRC_EOP (0x20); the bootloader answers STK_INSYNC (0x14),
the command's data, then STK_OK (0x10). Addresses are word addresses (LOAD_ADDRESS), pages
are written and read whole (PROG_PAGE / READ_PAGE, memory type 'F'). No library was used:
the only Python one (arduinobootloader 0.0.6) is unmaintained since 2020 and keeps its own
threads and hex reader; these ~150 lines are tested against the real bootloaders in the
emulator (tests/test_flash_sim.py) and cross-checked with avrdude there.

Errors are `Stk500Error` with a `Fault` (no reply, not in sync, failed): what went wrong on
the wire. `fivebar_host.flash.failures` turns them into the cause and the fix."""

from __future__ import annotations

import enum
import time
from typing import Any

from fivebar_host.errors import FivebarError

STK_OK = 0x10
STK_FAILED = 0x11
STK_INSYNC = 0x14
STK_NOSYNC = 0x15
CRC_EOP = 0x20
GET_SYNC = 0x30
GET_PARAMETER = 0x41
ENTER_PROGMODE = 0x50
LEAVE_PROGMODE = 0x51
LOAD_ADDRESS = 0x55
PROG_PAGE = 0x64
READ_PAGE = 0x74
READ_SIGN = 0x75
PARM_SW_MAJOR = 0x81
PARM_SW_MINOR = 0x82


class Fault(enum.Enum):
    """What went wrong on the wire."""

    NO_REPLY = "no reply"
    OUT_OF_SYNC = "not in sync"
    FAILED = "failed"


class Stk500Error(FivebarError):
    """A bootloader did not answer, or not as STK500v1 says."""

    exit_code = 3

    def __init__(self, fault: Fault, message: str, got: bytes = b"") -> None:
        super().__init__(message)
        self.fault = fault
        self.got = got


class Stk500:
    """One bootloader session on an open port (module doc)."""

    def __init__(self, port: Any, timeout_s: float = 1.0) -> None:
        self.port = port
        self.timeout_s = timeout_s

    # ------------------------------------------------------------------ raw I/O
    def _read(self, n: int, timeout_s: float | None = None) -> bytes:
        """Up to `n` bytes, fewer when the time runs out."""
        deadline = time.monotonic() + (self.timeout_s if timeout_s is None else timeout_s)
        out = b""
        while len(out) < n and time.monotonic() < deadline:
            out += self.port.read(n - len(out))
        return out

    def reset(self, low_s: float = 0.1, settle_s: float = 0.05) -> None:
        """Reset the board through DTR (an Uno's auto-reset capacitor; RTS too, for
        adapters wired to it) so that its bootloader starts; input from before the reset
        is dropped."""
        self.port.dtr = False
        self.port.rts = False
        time.sleep(low_s)
        self.port.reset_input_buffer()  # what came after the reset is kept: a program's
        self.port.dtr = True            # banner says what runs instead of a bootloader
        self.port.rts = True
        time.sleep(settle_s)

    # ------------------------------------------------------------------ commands
    def sync(self, tries: int = 6, wait_s: float = 0.3) -> None:
        """GET_SYNC until the bootloader answers INSYNC OK; Stk500Error NO_REPLY when
        nothing came back, OUT_OF_SYNC (with what came) when something else did."""
        got = b""
        for _ in range(tries):
            self.port.write(bytes((GET_SYNC, CRC_EOP)))
            reply = self._read(2, wait_s)
            if reply == bytes((STK_INSYNC, STK_OK)):
                time.sleep(0.05)  # answers to earlier tries, if they arrive late
                self.port.reset_input_buffer()
                return
            got += reply + (self._read(256, 0.1) if reply else b"")  # a whole line
        if got:
            raise Stk500Error(Fault.OUT_OF_SYNC, f"not in sync: got {got[:48]!r}", got)
        raise Stk500Error(Fault.NO_REPLY, "no reply", b"")

    def command(self, body: bytes, reply_len: int = 0, timeout_s: float | None = None
                ) -> bytes:
        """One command: its bytes and CRC_EOP out; INSYNC, `reply_len` bytes and OK back."""
        self.port.write(body + bytes((CRC_EOP,)))
        first = self._read(1, timeout_s)
        if first != bytes((STK_INSYNC,)):
            fault = Fault.NO_REPLY if not first else Fault.OUT_OF_SYNC
            raise Stk500Error(fault, f"command 0x{body[0]:02X}: {fault.value}"
                              + (f" (got {first!r})" if first else ""), first)
        data = self._read(reply_len, timeout_s)
        last = self._read(1, timeout_s)
        if len(data) != reply_len or last != bytes((STK_OK,)):
            raise Stk500Error(Fault.FAILED, f"command 0x{body[0]:02X}: expected {reply_len} "
                              f"bytes and OK, got {data + last!r}", data + last)
        return data

    def parameter(self, which: int) -> int:
        """GET_PARAMETER (e.g. PARM_SW_MAJOR): one byte."""
        return self.command(bytes((GET_PARAMETER, which)), 1)[0]

    def version(self) -> str:
        """The bootloader's software version, "4.4" for Optiboot 4.4."""
        return f"{self.parameter(PARM_SW_MAJOR)}.{self.parameter(PARM_SW_MINOR)}"

    def signature(self) -> bytes:
        """The chip's three signature bytes (1E 95 0F: ATmega328P)."""
        return self.command(bytes((READ_SIGN,)), 3)

    def enter(self) -> None:
        """ENTER_PROGMODE."""
        self.command(bytes((ENTER_PROGMODE,)))

    def leave(self) -> None:
        """LEAVE_PROGMODE: Optiboot then resets into the application (watchdog, 16 ms); the
        old ATmegaBOOT starts it once its wait for another command times out."""
        self.command(bytes((LEAVE_PROGMODE,)))

    def load_address(self, byte_address: int) -> None:
        """LOAD_ADDRESS of a flash byte address (sent as a word address, low byte first)."""
        word = byte_address // 2
        self.command(bytes((LOAD_ADDRESS, word & 0xFF, word >> 8)))

    def write_page(self, byte_address: int, page: bytes) -> None:
        """One flash page at `byte_address` (the bootloader erases and writes it)."""
        self.load_address(byte_address)
        n = len(page)
        self.command(bytes((PROG_PAGE, n >> 8, n & 0xFF, ord("F"))) + page)

    def read_page(self, byte_address: int, n: int) -> bytes:
        """`n` bytes of flash from `byte_address`."""
        self.load_address(byte_address)
        return self.command(bytes((READ_PAGE, n >> 8, n & 0xFF, ord("F"))), n)
