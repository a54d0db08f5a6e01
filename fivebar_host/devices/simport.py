"""`fivebar-sim://` — a pyserial port that is the real firmware running in simavr.

Opening the port builds the firmware and the harness if needed (`make -C firmware all sim`),
starts the harness (which holds the CPU until a client opens its pty, so the boot banner is not
lost) and opens the pty. Closing stops the harness, which flushes its pin trace.

URL options: `fivebar-sim://?trace=PATH&realtime=1&endstops=A,B`
- `trace`: where the harness records every step, direction and laser pin change (default: a
  temporary file, available as `port.trace_path` after close);
- `realtime=1`: throttle emulation to wall-clock speed (otherwise it runs 6–8× faster);
- `endstops=A,B`: simulated endstop switch positions in steps (enables homing tests).
"""

from __future__ import annotations

import tempfile
import urllib.parse
from pathlib import Path
from typing import Any

import serial

from fivebar_host.devices.sim import Emulator, EmulatorError, ensure_built

SCHEME = "fivebar-sim"


def parse_sim_url(url: str) -> dict[str, Any]:
    """Options of a `fivebar-sim://` URL; unknown or malformed options raise ValueError."""
    parts = urllib.parse.urlsplit(url)
    if parts.scheme != SCHEME:
        raise ValueError(f"expected a {SCHEME}:// URL, got {url!r}")
    opts: dict[str, Any] = {"trace": None, "realtime": False, "endstops": (None, None)}
    for key, values in urllib.parse.parse_qs(parts.query, keep_blank_values=True).items():
        value = values[-1]
        if key == "trace":
            opts["trace"] = Path(value)
        elif key == "realtime":
            if value not in ("0", "1"):
                raise ValueError(f"{url}: realtime must be 0 or 1, got {value!r}")
            opts["realtime"] = value == "1"
        elif key == "endstops":
            try:
                a, b = (int(v) for v in value.split(","))
            except ValueError:
                raise ValueError(f"{url}: endstops must be two step counts 'A,B', "
                                 f"got {value!r}") from None
            opts["endstops"] = (a, b)
        else:
            raise ValueError(f"{url}: unknown option {key!r} (known: trace, realtime, endstops)")
    return opts


class Serial(serial.SerialBase):
    """The emulated firmware behind a pyserial interface (delegates to the harness pty)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self._inner: serial.Serial | None = None
        self._emu: Emulator | None = None
        self.trace_path: Path | None = None
        self.stats = ""
        super().__init__(*args, **kwargs)

    def open(self) -> None:
        """Build if needed, start the harness and open its pty."""
        if self._port is None:
            raise serial.SerialException("port must be configured before it can be used")
        if self._inner is not None:
            raise serial.SerialException("port already open")
        try:
            opts = parse_sim_url(str(self._port))
        except ValueError as e:
            raise serial.SerialException(str(e)) from e
        try:
            build = ensure_built()
        except EmulatorError as e:
            raise serial.SerialException(f"{SCHEME}: {e}") from e
        trace = opts["trace"]
        if trace is None:
            trace = Path(tempfile.mkdtemp(prefix="fivebar-sim-")) / "pins.trace"
        self.trace_path = trace
        a, b = opts["endstops"]
        self._emu = Emulator(build.elf, build.harness, trace, a, b, opts["realtime"])
        try:
            pty = self._emu.start()
            self._inner = serial.Serial(pty, baudrate=self._baudrate, timeout=self._timeout,
                                        write_timeout=self._write_timeout)
        except (EmulatorError, serial.SerialException, OSError) as e:
            self._emu.stop()
            self._emu = None
            raise serial.SerialException(f"{SCHEME}: cannot start the emulator: {e}") from e
        self.is_open = True

    def close(self) -> None:
        """Close the pty and stop the harness (idempotent)."""
        if self._inner is not None:
            self._inner.close()
            self._inner = None
        if self._emu is not None:
            self.stats = self._emu.stop()
            self._emu = None
        self.is_open = False

    def _reconfigure_port(self, force_update: bool = False) -> None:
        if self._inner is not None:
            self._inner.timeout = self._timeout
            self._inner.write_timeout = self._write_timeout

    def _port_or_fail(self) -> serial.Serial:
        if self._inner is None:
            raise serial.PortNotOpenError()
        return self._inner

    @property
    def in_waiting(self) -> int:
        return int(self._port_or_fail().in_waiting)

    def read(self, size: int = 1) -> bytes:
        return bytes(self._port_or_fail().read(size))

    def write(self, data: bytes | bytearray | memoryview) -> int:
        n = self._port_or_fail().write(data)
        return int(n or 0)

    def flush(self) -> None:
        self._port_or_fail().flush()

    def reset_input_buffer(self) -> None:
        self._port_or_fail().reset_input_buffer()

    def reset_output_buffer(self) -> None:
        self._port_or_fail().reset_output_buffer()
