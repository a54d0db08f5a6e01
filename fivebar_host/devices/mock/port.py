"""The pyserial side of ``fivebar-mock://``: a port whose other end is ``MockFirmware``.

``MockSerial`` is what ``serial.serial_for_url("fivebar-mock://…")`` returns: opening it
parses the URL and boots (or, on a named machine, DTR-resets) the firmware model; ``write``
delivers bytes one by one with the URL's drop/corrupt faults (real-time bytes are never hit);
``read`` and ``in_waiting`` first advance the device to the clock; a DTR edge resets it as the
Uno's auto-reset circuit does.  ``ledger`` and ``snapshot`` let tests inspect what was
executed and what the device would report, without sending anything.
"""

from __future__ import annotations

import random
import threading
import time
from collections.abc import Callable
from typing import Any, ClassVar, Final

import serial

from fivebar_host import protocol
from fivebar_host.devices.mock.codes import SCHEME
from fivebar_host.devices.mock.firmware import MockFirmware
from fivebar_host.devices.mock.hardware import LedgerEntry, Machine, machine
from fivebar_host.devices.mock.options import MockOptions, parse_mock_url
from fivebar_host.protocol import StatusReport

#: Bytes a corruption may produce: printable, never a real-time byte.
_CORRUPT_BYTES: Final = bytes(c for c in range(0x20, 0x7F) if c not in b"?!~")


class MockSerial(serial.SerialBase):  # type: ignore[misc]  # pyserial has no type hints
    """A pyserial port whose other end is ``MockFirmware`` (see the module docstring).

    Timeouts behave like pyserial's: ``timeout=None`` blocks until ``size`` bytes came,
    0 returns what is there, a number waits up to that many seconds; writes never block.
    Thread-safe: a reader thread may block in ``read`` while another thread writes.
    """

    #: Every mock port opened in this process, oldest first.
    opened: ClassVar[list[MockSerial]] = []
    is_open: bool  # set by SerialBase

    def __init__(self, *args: Any, clock: Callable[[], float] = time.monotonic,
                 **kwargs: Any) -> None:
        self.options = MockOptions()
        self.machine = Machine(None)
        self.firmware: MockFirmware | None = None
        self._clock = clock
        self._cond = threading.Condition()
        self._rng = random.Random(0)
        self._cancel = False
        self._dtr_last = True
        super().__init__(*args, **kwargs)

    # ----------------------------------------------------------------- open / close

    def open(self) -> None:
        """Parse the URL, power the machine up (banner) and mark the port open."""
        if self.is_open:
            raise serial.SerialException("port already open")
        if self._port is None:
            raise serial.SerialException("port must be configured before it can be used")
        self.options = parse_mock_url(str(self._port))
        self._reconfigure_port()
        name = self.options.machine
        m = machine(name) if name is not None else Machine(None)
        with self._cond:
            now = self._clock()
            if m.port is not None and m.port.is_open:
                raise serial.SerialException(
                    f"could not open port {self._port}: [Errno 16] Device or resource busy "
                    f"(machine {name!r} is open)")
            # Opening resets the Uno through DTR: its RAM stays powered, so the new boot finds
            # the .noinit record of the firmware that ran until now.  A machine without one
            # (first open, or after a power cut) is powered up.
            kept = m.firmware.power_off(now) if m.firmware is not None else None
            self.machine = m
            m.true = self.options.true
            m.backlash = self.options.backlash
            self._rng = random.Random(self.options.seed)
            self.firmware = MockFirmware(self.options, m, now, kept)
            m.firmware = self.firmware
            self.firmware.uart.host_baud = self._baudrate
            m.port = self
            self.firmware.check_startup_faults()
            self._dtr_last = self._dtr_state
            self.is_open = True
        MockSerial.opened.append(self)

    def close(self) -> None:
        """Close the port; the device keeps running (its ledger stays readable)."""
        with self._cond:
            self.is_open = False
            self._cond.notify_all()

    def _reconfigure_port(self, force_update: bool = False) -> None:
        """The baud rate is checked like pyserial's loop://, and the firmware learns it: at
        another rate than its own every byte is lost both ways (mock/baud.py)."""
        if not isinstance(self._baudrate, int) or not 0 < self._baudrate < 2**32:
            raise ValueError(f"invalid baudrate: {self._baudrate!r}")
        if self.firmware is not None:
            with self._cond:
                self.firmware.uart.host_baud = self._baudrate

    def _update_dtr_state(self) -> None:
        """DTR going active resets the firmware, like the Uno's auto-reset circuit."""
        if self.is_open and self._dtr_state and not self._dtr_last:
            with self._cond:
                fw = self._fw()
                fw.reboot(self._clock())
                fw.rebooted = False
                fw.stalled = False
                self._cond.notify_all()
        self._dtr_last = self._dtr_state

    def power_cut(self) -> None:
        """``Machine.power_cut`` on this port's firmware (see there)."""
        with self._cond:
            fw = self.firmware
            if fw is None:
                return
            if self.is_open:
                fw.reboot(self._clock(), keep=False)
                fw.rebooted = False
            else:
                fw.power_off(self._clock(), "power-cut")
                self.machine.firmware = None
            self._cond.notify_all()

    def _update_rts_state(self) -> None:
        """RTS is not connected."""

    def _update_break_state(self) -> None:
        """A break does nothing to the device."""

    # ----------------------------------------------------------------- I/O

    def _fw(self) -> MockFirmware:
        if not self.is_open or self.firmware is None:
            raise serial.PortNotOpenError()
        return self.firmware

    def _live(self) -> MockFirmware:
        """The firmware advanced to now; SerialException once the link is broken."""
        fw = self._fw()
        fw.advance(self._clock())
        if fw.disconnected:
            raise serial.SerialException(
                f"{SCHEME}: device disconnected (disconnect_after="
                f"{self.options.disconnect_after})")
        return fw

    @property
    def in_waiting(self) -> int:
        """Bytes the device has sent that were not read yet."""
        with self._cond:
            return len(self._live().out)

    @property
    def out_waiting(self) -> int:
        """Always 0: written bytes reach the device at once."""
        self._fw()
        return 0

    def read(self, size: int = 1) -> bytes:
        """Read up to ``size`` bytes, waiting as the timeouts allow (pyserial semantics)."""
        self._fw()
        timeout, gap = self._timeout, self._inter_byte_timeout
        deadline = None if timeout is None else self._clock() + timeout
        got = bytearray()
        last_byte = 0.0
        with self._cond:
            self._cancel = False
            while True:
                fw = self._live()
                take = min(size - len(got), len(fw.out))
                if take:
                    got += fw.out[:take]
                    del fw.out[:take]
                    last_byte = self._clock()
                if len(got) >= size or timeout == 0 or self._cancel or not self.is_open:
                    break
                now = self._clock()
                limit = deadline
                if gap is not None and got:
                    limit = last_byte + gap if limit is None else min(limit, last_byte + gap)
                if limit is not None and now >= limit:
                    break
                wait = 0.05
                ev = fw.next_event()
                if ev is not None:
                    wait = min(wait, max(0.0, ev[0] - now) + 1e-4)
                if limit is not None:
                    wait = min(wait, limit - now)
                self._cond.wait(max(wait, 0.0))
        return bytes(got)

    def write(self, data: bytes | bytearray | memoryview) -> int:
        """Deliver ``data`` to the device byte by byte, with the URL's line faults."""
        raw = bytes(data)
        with self._cond:
            fw = self._live()
            opt = self.options
            now = self._clock()
            fw.rebooted = False
            for c in raw:
                if not fw.uart.matches():
                    continue  # sent at another rate: framing errors, nothing arrives
                if c not in protocol.REALTIME_BYTES:
                    if opt.drop and self._rng.random() < opt.drop:
                        continue
                    if opt.corrupt and self._rng.random() < opt.corrupt:
                        c = self._rng.choice([b for b in _CORRUPT_BYTES if b != c])
                fw.receive(c, now)
                if fw.rebooted or fw.disconnected:
                    break
            fw.rebooted = False
            self._cond.notify_all()
            if fw.disconnected:
                raise serial.SerialException(
                    f"{SCHEME}: device disconnected (disconnect_after={opt.disconnect_after})")
        return len(raw)

    def flush(self) -> None:
        """Nothing is buffered on the host side."""
        self._fw()

    def reset_input_buffer(self) -> None:
        """Discard what the device sent and was not read yet."""
        with self._cond:
            self._live().out.clear()

    def reset_output_buffer(self) -> None:
        """Nothing waits to be sent: writes reach the device at once."""
        self._fw()

    def cancel_read(self) -> None:
        """Make a blocking ``read`` in another thread return what it has."""
        with self._cond:
            self._cancel = True
            self._cond.notify_all()

    def cancel_write(self) -> None:
        """Writes never block; nothing to cancel."""

    # ----------------------------------------------------------------- inspection

    @property
    def ledger(self) -> list[LedgerEntry]:
        """What the machine executed, block by block (the running block included)."""
        with self._cond:
            fw = self.firmware
            if fw is not None:
                fw.advance(self._clock())
                fw.sync_entry()
            return list(self.machine.ledger)

    def snapshot(self) -> StatusReport:
        """The status report the device would send now (without sending anything)."""
        with self._cond:
            fw = self.firmware
            if fw is None:
                raise serial.PortNotOpenError()
            fw.advance(self._clock())
            msg = protocol.parse_message(fw.status_text())
            assert isinstance(msg, StatusReport)
            return msg

