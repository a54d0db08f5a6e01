"""Run the real firmware in simavr: build it if needed, start the harness, stop it.

``Emulator`` launches firmware/build/fbsim (the libsimavr harness) on
firmware/build/fivebar.elf and hands back the pseudo-terminal path that a
host opens like a serial port; ``Emulator.control`` resets the AVR (with its
RAM kept, like the Uno's DTR reset, or after a power cut), freezes it, hangs
it (so that its watchdog resets it) or flushes its pin trace through the
harness's command channel.
``FirmwareSession`` is a small synchronous client over such a port (send a
line, read its reply, poll status, stream with character counting) used by
the firmware tests and the benchmark; it is the only place here that needs
pyserial, and imports it lazily.
"""

from __future__ import annotations

import atexit
import os
import select
import shutil
import signal
import subprocess
import threading
import time
import weakref
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, Protocol

from fivebar_host import protocol
from fivebar_host.devices.simtrace import Trace, read_trace
from fivebar_host.errors import FivebarError
from fivebar_host.protocol import Banner, ErrorReply, Message, Ok, StatusReport

#: What CI installs; named in every "toolchain missing" message.
APT_PACKAGES = "gcc-avr avr-libc simavr libsimavr-dev libelf-dev"


class EmulatorError(FivebarError, RuntimeError):
    """The firmware or harness could not be built, started or talked to."""


#: Harnesses started and not yet stopped; stopped at exit so that none outlives the host.
_LIVE: weakref.WeakSet[Emulator] = weakref.WeakSet()


def _stop_live() -> None:
    for emu in list(_LIVE):
        emu.stop()


atexit.register(_stop_live)


def firmware_dir() -> Path:
    """The repository's firmware/ directory (next to fivebar_host/)."""
    return Path(__file__).resolve().parents[2] / "firmware"


def toolchain_missing() -> str | None:
    """Why the emulator cannot be built here, or None when it can."""
    for tool in ("avr-gcc", "make", "gcc"):
        if shutil.which(tool) is None:
            return f"{tool} not found (install: apt-get install {APT_PACKAGES})"
    if not Path("/usr/include/simavr/sim_avr.h").exists():
        return f"libsimavr headers not found (install: apt-get install {APT_PACKAGES})"
    return None


@dataclass(frozen=True)
class BuildPaths:
    """Outputs of ``make -C firmware all sim``."""

    elf: Path
    hex: Path
    harness: Path
    size_report: str  # avr-size output printed by the build


#: Where Debian's arduino-core-avr keeps the bootloaders' source and hex files.
ARDUINO_BOOTLOADERS = Path("/usr/share/arduino/hardware/arduino/avr/bootloaders")


def ensure_built(directory: Path | None = None, bootloaders: bool = False) -> BuildPaths:
    """Build firmware and harness with make (a no-op when up to date); with `bootloaders`
    also Optiboot and ATmegaBOOT for the emulator (`make bootloaders`, build/boot/).

    Raises EmulatorError with the build output when the toolchain is missing
    or the build fails.
    """
    reason = toolchain_missing()
    if reason:
        raise EmulatorError(reason)
    if bootloaders and not (ARDUINO_BOOTLOADERS / "optiboot" / "optiboot.c").exists():
        raise EmulatorError("the bootloaders' source is not installed (install: apt-get "
                            "install arduino-core-avr)")
    fw = directory or firmware_dir()
    proc = subprocess.run(
        ["make", "-s", "-C", str(fw), "all", "sim", *(["bootloaders"] if bootloaders else [])],
        capture_output=True,
        text=True,
        check=False,
    )
    if proc.returncode != 0:
        raise EmulatorError(f"firmware build failed:\n{proc.stdout}\n{proc.stderr}")
    build = fw / "build"
    return BuildPaths(build / "fivebar.elf", build / "fivebar.hex", build / "fbsim", proc.stdout)


#: The harness's control commands (firmware/sim/fbsim.c ``-C``).
CONTROL_COMMANDS = ("reset", "open", "power", "freeze", "hang", "spin", "stepoff", "flush",
                    "dump")


class Emulator:
    """One running harness process; use as a context manager or call start/stop.

    The harness takes control commands on its stdin (``control``): ``reset`` (a reset
    that keeps the RAM, as by the Uno's DTR line), ``open`` (a client reopened the pty:
    its unread output is dropped, then ``reset``), ``power`` (a power cut: the RAM comes
    back random), ``freeze`` (the CPU stops until a reset: a hang that not even the
    watchdog sees), ``hang`` (the firmware spins with interrupts off: its watchdog resets
    it), ``spin`` (the main loop spins, interrupts keep running), ``stepoff`` (the step
    interrupt stops coming, the main loop runs on) and ``flush`` (the trace file is written
    out).  ``hang``, ``spin`` and ``stepoff`` write ``<cycle> <command> 1`` to the trace, and
    the watchdog reset that follows ``<cycle> wdt 1``.
    """

    def __init__(
        self,
        elf: Path,
        harness: Path,
        trace: Path | None = None,
        endstop_a: int | None = None,
        endstop_b: int | None = None,
        realtime: bool = False,
        extra: Sequence[str] = (),
    ) -> None:
        self.elf = elf
        #: More harness options (firmware/sim/fbsim.c: -B bootloader, -F dump file, -H reset
        #: held, -X stuck page, -S state file, -m chip); `elf` may then be "-" (erased flash).
        self.extra = tuple(extra)
        self.dump_path: Path | None = None  # the harness's -F file, where `dump` writes
        self.harness = harness
        self.trace = trace
        self.endstops = (endstop_a, endstop_b)
        self.realtime = realtime
        self.proc: subprocess.Popen[bytes] | None = None
        self.pty: str | None = None
        self.stats = ""
        self.returncode: int | None = None
        self._out = b""  # harness stdout read but not yet consumed
        self._lock = threading.Lock()

    def command(self) -> list[str]:
        """The harness command line (waits for the client: ``-w``; commands on stdin: ``-C``)."""
        cmd = [str(self.harness), "-w", "-C"]
        if self.trace is not None:
            cmd += ["-t", str(self.trace)]
        for flag, value in zip(("-a", "-b"), self.endstops, strict=True):
            if value is not None:
                cmd += [flag, str(value)]
        if self.realtime:
            cmd.append("-R")
        cmd += [*self.extra, str(self.elf)]
        return cmd

    def start(self, timeout: float = 10.0) -> str:
        """Start the harness and return the pty path to open (115200 8N1)."""
        if self.proc is not None:
            raise EmulatorError("emulator already started")
        # Its own session: a Ctrl-C on the terminal reaches the host only (which holds the
        # machine and asks), never the emulated controller, which would stop ("device
        # gone"). It still ends with the host: stop() / atexit, its stdin's end, and
        # PR_SET_PDEATHSIG when the host dies (firmware/sim/fbsim.c).
        self.proc = subprocess.Popen(
            self.command(),
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            start_new_session=True,
        )
        _LIVE.add(self)
        self._out = b""
        line = self._read_line(timeout)
        if not line.startswith("PTY "):
            err = self.stop()
            raise EmulatorError(f"harness did not report its pty (got {line!r}); stderr: {err}")
        self.pty = line.split(maxsplit=1)[1].strip()
        return self.pty

    def _read_line(self, timeout: float) -> str:
        """The next line the harness writes on stdout ('' if none came in time)."""
        assert self.proc is not None and self.proc.stdout is not None
        fd = self.proc.stdout.fileno()
        deadline = time.monotonic() + timeout
        while b"\n" not in self._out:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([fd], [], [], left)[0]:
                return ""
            chunk = os.read(fd, 4096)
            if not chunk:
                return ""
            self._out += chunk
        line, _, self._out = self._out.partition(b"\n")
        return line.decode("ascii", errors="replace")

    def control(self, command: str, timeout: float = 10.0) -> None:
        """Send one control command and wait until the harness has carried it out.

        A reset or freeze takes effect at the next instruction boundary where the
        firmware has interrupts enabled (firmware/sim/fbsim.c)."""
        if command not in CONTROL_COMMANDS:
            raise ValueError(f"unknown harness command {command!r}")
        self._done(command, timeout)

    def byte_at(self, value: int, after_cycles: int, timeout: float = 10.0) -> None:
        """Hand one byte to the firmware's UART ``after_cycles`` emulated cycles from now and
        wait until it is there (the harness's ``byte``): a real-time byte at an instant the
        client picks, where the client's own bytes land at a fixed phase of the firmware's
        timer events (the harness pumps them when a sleeping batch ends)."""
        if not 0 <= value <= 0xFF or not 1 <= after_cycles < 2**31:
            raise ValueError(f"byte {value} after {after_cycles} cycles is out of range")
        self._done(f"byte {value:02x} {after_cycles}", timeout)

    def cycle(self, timeout: float = 10.0) -> int:
        """The emulated CPU cycle count now (the harness's ``cycle`` command)."""
        line = self._ask("cycle", timeout)
        if not line.startswith("ok cycle "):
            raise EmulatorError(f"harness did not answer 'cycle' (got {line!r})")
        return int(line.split()[2])

    def _done(self, command: str, timeout: float) -> None:
        """Send `command` and wait for its acknowledgement, "ok <command>"."""
        line = self._ask(command, timeout)
        if line != f"ok {command}":
            raise EmulatorError(f"harness did not acknowledge {command!r} (got {line!r})")

    def _ask(self, command: str, timeout: float) -> str:
        """Write one command line to the harness and read its answer line."""
        with self._lock:
            proc = self.proc
            if proc is None or proc.stdin is None or proc.poll() is not None:
                raise EmulatorError(f"harness not running (command {command!r})")
            try:
                proc.stdin.write(command.encode() + b"\n")
                proc.stdin.flush()
            except OSError as e:
                raise EmulatorError(f"harness gone (command {command!r}): {e}") from e
            return self._read_line(timeout)

    @property
    def running(self) -> bool:
        """True while the harness process is alive."""
        return self.proc is not None and self.proc.poll() is None

    def stop(self, timeout: float = 5.0) -> str:
        """Stop the harness (SIGTERM) and return its statistics line(s)."""
        if self.proc is None:
            return self.stats
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            _, raw = self.proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            _, raw = self.proc.communicate()
        _LIVE.discard(self)
        err = raw.decode("utf-8", errors="replace")
        self.stats = err
        self.returncode = self.proc.returncode
        self.proc = None
        return err

    def __enter__(self) -> Emulator:
        self.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()


class SerialLike(Protocol):
    """The part of pyserial's Serial that FirmwareSession uses."""

    def write(self, data: bytes, /) -> int | None: ...
    def readline(self) -> bytes: ...
    def close(self) -> None: ...


def open_port(path: str, timeout: float = 5.0) -> Any:
    """Open a pty (or any pyserial URL) at 115200 baud."""
    import serial  # pyserial, imported only where a port is really opened

    return serial.serial_for_url(path, baudrate=115200, timeout=timeout)


class FirmwareSession:
    """Synchronous protocol client: one reply per line, messages kept in order.

    Non-reply lines (status reports, ALARM pushes, banners, $ listings) that
    arrive while waiting for a reply are collected in ``self.messages``.
    """

    def __init__(self, port: SerialLike, timeout: float = 10.0) -> None:
        self.port = port
        self.timeout = timeout
        self.messages: list[Message] = []
        self.banner: Banner | None = None

    def read_message(self) -> Message:
        """Read and decode the next line; EmulatorError on timeout."""
        deadline = time.monotonic() + self.timeout
        partial = b""
        while time.monotonic() < deadline:
            partial += self.port.readline()
            if not partial.endswith(b"\n"):
                continue  # nothing yet, or a line cut by the port's read timeout
            raw, partial = partial, b""
            msg = protocol.parse_message(raw.decode("ascii", errors="replace"))
            if isinstance(msg, Banner):
                self.banner = msg
            return msg
        raise EmulatorError("no line from the firmware before the timeout")

    def wait_banner(self) -> Banner:
        """Read until the banner (after boot or Ctrl-X)."""
        while True:
            msg = self.read_message()
            if isinstance(msg, Banner):
                return msg
            self.messages.append(msg)

    def read_reply(self) -> Ok | ErrorReply:
        """Read until the next ``ok`` / ``error`` reply."""
        while True:
            msg = self.read_message()
            if isinstance(msg, Ok | ErrorReply):
                return msg
            self.messages.append(msg)

    def send(self, body: str, line_number: int | None = None) -> Ok | ErrorReply:
        """Send one line and wait for its reply."""
        self.port.write(protocol.encode_line(body, line_number))
        return self.read_reply()

    def send_raw(self, data: bytes) -> Ok | ErrorReply:
        """Send raw bytes (one line, newline included) and wait for its reply."""
        self.port.write(data)
        return self.read_reply()

    def realtime(self, byte: bytes) -> None:
        """Send one real-time byte (``!``, ``~``, Ctrl-X)."""
        self.port.write(byte)

    def status(self) -> StatusReport:
        """Send ``?`` and return the report (other lines are kept)."""
        self.port.write(protocol.RT_STATUS)
        while True:
            msg = self.read_message()
            if isinstance(msg, StatusReport):
                return msg
            self.messages.append(msg)

    def wait_state(self, states: Iterable[str], poll: float = 0.02) -> StatusReport:
        """Poll status until the state is one of ``states``."""
        wanted = set(states)
        deadline = time.monotonic() + self.timeout
        while time.monotonic() < deadline:
            report = self.status()
            if report.state in wanted and (report.state != "Idle" or report.queued == 0):
                return report
            time.sleep(poll)
        raise EmulatorError(f"firmware never reached {sorted(wanted)}")

    def wait_idle(self, poll: float = 0.02) -> StatusReport:
        """Poll status until Idle with an empty queue."""
        return self.wait_state({"Idle"}, poll)

    def stream(
        self, lines: Sequence[str], rx_size: int | None = None, numbered_from: int | None = None
    ) -> list[Ok | ErrorReply]:
        """Stream lines with character counting; return the replies in order.

        At most ``rx_size`` bytes (the banner's ``rx:``) are unacknowledged
        at any time.  With ``numbered_from`` each line gets N/checksum,
        numbering from that value.
        """
        budget = rx_size or (self.banner.rx if self.banner else 128)
        encoded = [
            protocol.encode_line(body, None if numbered_from is None else numbered_from + i)
            for i, body in enumerate(lines)
        ]
        in_flight: list[int] = []
        replies: list[Ok | ErrorReply] = []
        sent = 0
        while len(replies) < len(encoded):
            while sent < len(encoded) and sum(in_flight) + len(encoded[sent]) <= budget:
                self.port.write(encoded[sent])
                in_flight.append(len(encoded[sent]))
                sent += 1
            replies.append(self.read_reply())
            in_flight.pop(0)
        return replies


@dataclass
class SimDevice:
    """A running emulated firmware with a protocol session on its pty."""

    emulator: Emulator
    port: Any
    session: FirmwareSession
    trace_path: Path

    def close(self) -> None:
        """Close the port and stop the emulator (idempotent)."""
        if self.emulator.proc is not None:
            self.port.close()
            self.emulator.stop()

    def finish(self) -> Trace:
        """Stop the emulator and return the recorded pin trace."""
        self.close()
        return read_trace(self.trace_path)


def start_device(
    build: BuildPaths,
    trace_path: Path,
    endstop_a: int | None = None,
    endstop_b: int | None = None,
    timeout: float = 10.0,
    realtime: bool = False,
) -> SimDevice:
    """Start the harness, open its pty and read the boot banner.

    ``realtime`` throttles emulation to wall-clock speed (harness ``-R``), so
    a host streaming in wall time meets the link at its real rate.
    """
    emu = Emulator(build.elf, build.harness, trace_path, endstop_a, endstop_b, realtime)
    return boot(emu, trace_path, timeout)


def boot(emu: Emulator, trace_path: Path, timeout: float) -> SimDevice:
    """Start `emu`, open its pty and read the boot banner: the device, or the emulator
    stopped and the error raised (the stepper and the servo builds alike)."""
    try:
        port = open_port(emu.start(), timeout=0.5)
    except Exception:
        emu.stop()
        raise
    session = FirmwareSession(port, timeout=timeout)
    device = SimDevice(emu, port, session, trace_path)
    try:
        session.wait_banner()
    except Exception:
        device.close()
        raise
    return device
