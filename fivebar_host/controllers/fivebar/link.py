"""Serial link to the fivebar firmware: open, handshake, status, commands, resets.

The only module of the host program that uses pyserial (besides the URL handlers in
`fivebar_host.devices`, which *are* pyserial ports). Every line goes out numbered and with a
checksum field, its body's CRC-16 and length (docs/protocol.md 5.1), so a corrupted line, a
line that lost or gained bytes, or a lost line is resent and no line runs twice.

`Link.stream` sends many lines with flow control; its state machine lives in
`fivebar_host.controllers.fivebar.stream` (character counting, resends, fault detection).
The errors are in `fivebar_host.run.errors`.
"""

from __future__ import annotations

import contextlib
import time
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any

import serial

from fivebar_host import protocol, wire
from fivebar_host.controllers import ports
from fivebar_host.controllers.fivebar.stream import Streamer, StreamProgress, StreamResult
from fivebar_host.controllers.ports import PortLock
from fivebar_host.program import Program
from fivebar_host.protocol import Banner, ErrorReply, Message, Ok, ProtocolError, StatusReport
from fivebar_host.run.errors import (
    FaultKind,
    FirmwareMismatchError,
    LinkError,
    LinkFaultError,
    NoBannerError,
)
from fivebar_host.run.overrides import Overrides

#: How long the link waits for the replies of lines still in flight before it reads the
#: firmware's line counter after a refused line (`Link.resync_numbering`), s.
RESYNC_SETTLE_S = 0.2
#: wait_idle's first pause between status reports; each next one doubles, up to the link's
#: poll interval.  A wait usually starts as a stream ends, with at most the firmware's queue
#: (16 blocks) left to run: a fixed 50 ms pause added up to 50 ms to every job's end (the
#: issue-39 job of `benchmarks/link.py` runs 0.3 s in all).  Five more reports in a long wait.
WAIT_FIRST_POLL_S = 0.003


class Link:
    """A protocol session on one open port (anything with pyserial's Serial interface)."""

    def __init__(self, port: Any, *, url: str = "", reply_timeout_s: float = 10.0,
                 poll_interval_s: float = 0.05, lock: PortLock | None = None) -> None:
        self.port = port
        self.lock = lock  # the port held for this process (`controllers.ports`)
        self.url = url or str(getattr(port, "port", "?"))
        self.reply_timeout_s = reply_timeout_s
        self.poll_interval_s = poll_interval_s
        self.banner: Banner | None = None
        self.last_status: StatusReport | None = None
        self.next_line = 1  # the number the firmware expects next
        # a refused line left later lines in flight: read the counter before the next stream
        self.resync_numbering = False
        self.bytes_sent = 0
        self._buf = b""
        self._pending: deque[Message] = deque()
        self.baud_warning: str | None = None  # set_baud fell back to the base rate: why

    # ------------------------------------------------------------------ opening
    @classmethod
    def open(cls, url: str, *, baud: int = 115200, banner_timeout_s: float = 5.0,
             reply_timeout_s: float = 10.0, link_baud: int | None = None,
             command: str | None = None, hint: str | None = None) -> Link:
        """Hold the port (`controllers.ports`: refused, naming the owner, before anything is
        opened or sent when another process holds it), open `url` (a device path, COM port
        or pyserial URL) and wait for the banner.

        `link_baud` (the profile's `[serial] link_baud`): a faster rate to switch to with
        `set_baud` once connected; if the switch fails the link stays at the base rate and
        `baud_warning` says why. `command` and `hint` go into the port's lock file."""
        try:
            port, lock = ports.open_port(url, command=command, hint=hint, baudrate=baud,
                                         timeout=0.02, write_timeout=5.0)
        except ValueError as e:
            raise LinkError(f"{url}: {e}") from e
        except (serial.SerialException, OSError) as e:
            raise LinkError(ports.open_trouble(url, e)[1]) from e
        link = cls(port, url=url, reply_timeout_s=reply_timeout_s, lock=lock)
        try:
            link.handshake(banner_timeout_s)
            if link_baud is not None and link_baud != link.port.baudrate:
                link.set_baud(link_baud)
        except BaseException:
            link.close()
            raise
        return link

    def handshake(self, timeout_s: float) -> Banner:
        """Wait for the boot banner (opening a port resets an Arduino through DTR).

        If nothing arrives within a third of the timeout the device may have been running
        already (no reset on open): ask with `$I`. A device left in numbered mode by an
        earlier session refuses that unnumbered line with `error:10 resend:<n>`
        (docs/protocol.md 5.2); then ask again as line n. Checks the protocol version, then
        reads the firmware's line counter from a status report.
        """
        deadline = time.monotonic() + timeout_s
        asked = False
        asked_numbered = False
        seen: list[str] = []
        while time.monotonic() < deadline:
            if not asked and time.monotonic() > deadline - 2 * timeout_s / 3:
                self._write(b"\n$I\n")  # a blank line first ends any partial line
                asked = True
            for raw in self._read_raw_lines(0.05):
                try:
                    msg = self._parse(raw)
                except ProtocolError:
                    if raw.strip():
                        seen.append(raw.strip())
                    continue
                if isinstance(msg, Banner):
                    self.banner = msg
                elif (asked and not asked_numbered and isinstance(msg, ErrorReply)
                      and msg.code == 10 and msg.resend is not None):
                    self._write(protocol.encode_line("$I", line_number=msg.resend))
                    asked_numbered = True
            if self.banner is not None:
                break
        if self.banner is None:
            got = f"; it sent: {' | '.join(seen[-3:])[:160]!r}" if seen else "; it sent nothing"
            raise NoBannerError(
                f"{self.url}: no fivebar firmware banner within {timeout_s:g} s{got}. "
                "Is this the fivebar firmware, at the profile's baud rate?")
        if self.banner.proto != protocol.PROTOCOL_VERSION:
            raise FirmwareMismatchError(
                f"{self.url}: firmware {self.banner.version} speaks protocol "
                f"{self.banner.proto}; this host needs protocol {protocol.PROTOCOL_VERSION}. "
                "Update the one that is behind (docs/protocol.md).")
        time.sleep(0.05)
        self._drain_input()
        st = self.status()
        self.next_line = st.accepted_line + 1
        return self.banner

    def close(self) -> None:
        """Close the port and give it up (idempotent)."""
        ports.close_port(self.port, self.lock)

    def __enter__(self) -> Link:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ raw I/O
    def _write(self, data: bytes) -> None:
        try:
            self.port.write(data)
        except (serial.SerialException, OSError) as e:
            raise LinkFaultError(FaultKind.DISCONNECT,
                                 f"{self.url}: write failed, device gone? ({e})", -1) from e
        self.bytes_sent += len(data)

    def _read_raw_lines(self, timeout_s: float) -> list[str]:
        """Lines that complete within `timeout_s` (at least one read attempt)."""
        deadline = time.monotonic() + timeout_s
        out: list[str] = []
        while True:
            try:
                n = self.port.in_waiting
                chunk = self.port.read(n if n else 1)
            except (serial.SerialException, OSError, TypeError) as e:
                raise LinkFaultError(FaultKind.DISCONNECT,
                                     f"{self.url}: read failed, device gone? ({e})", -1) from e
            if chunk:
                self._buf += chunk
                while b"\n" in self._buf:
                    line, self._buf = self._buf.split(b"\n", 1)
                    out.append(line.decode("ascii", errors="replace").rstrip("\r"))
            if out or time.monotonic() >= deadline:
                return out

    def _drain_input(self) -> None:
        """Discard whatever is waiting (used once, after the banner)."""
        self._read_raw_lines(0.0)
        self._buf = b""
        self._pending.clear()

    @staticmethod
    def _parse(raw: str) -> Message:
        """Decode one line from the firmware; a line that ends with a banner is that banner.

        A reset while the firmware was transmitting (DTR, the reset button, a watchdog)
        cuts the line on the wire, and the restarted firmware's banner arrives glued to
        the cut piece, e.g. ``ofivebar 1.0.0 proto:2 ...``: that is a restart, not a
        garbled reply.  ProtocolError for anything else that is not a message.
        """
        try:
            return protocol.parse_message(raw)
        except ProtocolError:
            banner = protocol.trailing_banner(raw)
            if banner is None:
                raise
            return banner

    def _messages(self, timeout_s: float) -> list[Message]:
        """Decode the lines that arrive within `timeout_s`; garbage lines are errors."""
        msgs = []
        for raw in self._read_raw_lines(timeout_s):
            if not raw.strip():
                continue
            try:
                msgs.append(self._parse(raw))
            except ProtocolError as e:
                raise LinkError(f"{self.url}: {e}") from e
        return msgs

    # ------------------------------------------------------------------ simple commands
    def realtime(self, byte: bytes) -> None:
        """Send one real-time byte (`?`, `!`, `~`, Ctrl-X): acted on at once, no reply."""
        if byte not in (protocol.RT_STATUS, protocol.RT_HOLD, protocol.RT_RESUME,
                        protocol.RT_RESET):
            raise ValueError(f"not a real-time byte: {byte!r}")
        self._write(byte)

    def status(self, timeout_s: float | None = None) -> StatusReport:
        """Ask `?` and return the report; replies arriving meanwhile are kept for later."""
        self._write(protocol.RT_STATUS)
        deadline = time.monotonic() + (timeout_s or self.reply_timeout_s)
        while time.monotonic() < deadline:
            for msg in self._messages(0.05):
                if isinstance(msg, StatusReport):
                    self.last_status = msg
                    return msg
                self._pending.append(msg)
        raise LinkFaultError(FaultKind.TIMEOUT, f"{self.url}: no status report within "
                             f"{timeout_s or self.reply_timeout_s:g} s", -1)

    def number_past_kept(self) -> None:
        """Number the next lines past the controller's `Ln` done.  A reset restarts the line
        counter but keeps `Ln` done (docs/protocol.md 7), so a new stream numbered from 1
        could reuse the number of the old stream's last executed line: until its own first
        block ended, `Ln` done would read as one of its lines — its progress and a recovery
        after a fault there mapped the old count onto the new stream (a daemon recovery
        resumed from the wrong segment, `tests/test_serve.py`).  `N<done> M110` sets the
        counter to `done` (section 5.2), so a new stream starts after it and a stale
        `Ln` done is its line before the first: nothing of it done."""
        st = self.status()
        if st.done_line >= self.next_line:
            self.next_line = st.done_line
            self.command("M110")

    def command(self, body: str | Program, timeout_s: float | None = None) -> None:
        """Send one numbered line (or a small program, a line at a time) and wait for its
        `ok`; raise LinkFaultError on `error:`."""
        self.stream([body] if isinstance(body, str) else body, counting=False,
                    timeout_s=timeout_s)

    def reset(self, timeout_s: float = 5.0) -> Banner:
        """Ctrl-X: the firmware clears its queue, turns the laser off and reboots its state.

        It also returns to the base rate (protocol 1): so does the port, and if the banner
        was lost in the switch it is asked for with `$I` (the reset ended numbering)."""
        self._write(protocol.RT_RESET)
        want_ask = self._to_base_baud()
        asked = not want_ask
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if not asked and time.monotonic() > deadline - timeout_s + 0.25:
                self._write(b"\n$I\n")
                asked = True
            for msg in self._messages(0.05):
                if isinstance(msg, Banner):
                    self.banner = msg
                    if want_ask and asked:
                        time.sleep(0.1)  # the replies to the `$I` asked for
                        self._drain_input()
                    self._pending.clear()
                    st = self.status()
                    self.next_line = st.accepted_line + 1
                    return msg
        raise LinkFaultError(FaultKind.TIMEOUT,
                             f"{self.url}: no banner within {timeout_s:g} s after reset", -1)

    def hardware_reset(self, timeout_s: float = 3.0) -> bool:
        """Pulse DTR — an Arduino's auto-reset line — to reboot a controller that no longer
        answers (its laser output goes off with the reboot). True if a banner followed.

        The reboot restarts the line counter (the next line is 1) and keeps the RAM powered:
        the controller keeps its position, `H` and `Ln` done (docs/protocol.md 7)."""
        try:
            self._to_base_baud()  # the rebooted firmware speaks at the base rate
            self.port.dtr = False
            time.sleep(0.05)
            self.port.dtr = True
        except (serial.SerialException, OSError, ValueError):
            return False
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            try:
                msgs = self._messages(0.05)
            except LinkError:
                continue
            for msg in msgs:
                if isinstance(msg, Banner):
                    self.banner = msg
                    self._pending.clear()
                    self.next_line = 1
                    return True
        return False

    def set_baud(self, baud: int, probe_timeout_s: float = 0.5) -> bool:
        """Switch the link to `baud` (`$B`, docs/protocol.md 1.1); True if it runs there.

        The firmware answers `ok` at the old rate and switches; the port follows and a
        probe (`$I`, numbered) must bring the banner and `ok` back. If it does not, the
        firmware returns to the base rate by itself `BAUD_TRIAL_S` after its switch: the
        port does too, the probe is repeated there, `baud_warning` says what happened and
        False is returned. A rate that is not a link rate raises LinkError before anything is
        sent; a firmware that refuses `$B` (one without it: `error:4`) leaves the link at
        the base rate, with the warning, and False.
        """
        if baud not in protocol.BAUD_RATES:
            raise LinkError(f"{self.url}: {baud} baud is not one of "
                            f"{', '.join(map(str, protocol.BAUD_RATES))}")
        try:
            self.command(f"$B={baud}")
        except LinkFaultError as e:
            if e.kind is not FaultKind.ERROR:
                raise
            why = e.message.rsplit(": ", 1)[-1]
            self.baud_warning = (f"{self.url}: the firmware refused $B ({why}); the link "
                                 f"stays at {protocol.BASE_BAUD} baud")
            return False
        switched = time.monotonic()
        self._set_port_baud(baud)
        if self._probe(probe_timeout_s):
            self.baud_warning = None
            return True
        self._set_port_baud(protocol.BASE_BAUD)
        time.sleep(max(0.0, switched + protocol.BAUD_TRIAL_S + 0.2 - time.monotonic()))
        if not self._probe(self.reply_timeout_s):
            raise LinkFaultError(FaultKind.TIMEOUT, f"{self.url}: no answer at {baud} baud "
                                 f"nor back at {protocol.BASE_BAUD} after $B", -1)
        self.baud_warning = (f"{self.url}: no answer at {baud} baud (cable, adapter?); "
                             f"the link stays at {protocol.BASE_BAUD} baud")
        return False

    def _set_port_baud(self, baud: int) -> None:
        """The port's own rate, once what was written has left at the old one."""
        try:
            self.port.flush()
            self.port.baudrate = baud
        except (serial.SerialException, OSError, ValueError) as e:
            raise LinkError(f"{self.url}: cannot set {baud} baud: {e}") from e
        self._buf = b""

    def _to_base_baud(self) -> bool:
        """After a reset of the firmware: back to the base rate; whether the rate changed."""
        if getattr(self.port, "baudrate", protocol.BASE_BAUD) == protocol.BASE_BAUD:
            return False
        with contextlib.suppress(serial.SerialException, OSError):
            self.port.flush()
        time.sleep(0.02)  # what was just written (Ctrl-X) leaves at the old rate
        self._set_port_baud(protocol.BASE_BAUD)
        return True

    def _probe(self, timeout_s: float) -> bool:
        """`$I` as the next numbered line: True once its banner and `ok` are back."""
        self._write(protocol.encode_line("$I", self.next_line))
        deadline = time.monotonic() + timeout_s
        banner = False
        while time.monotonic() < deadline:
            for raw in self._read_raw_lines(0.05):
                try:
                    msg = self._parse(raw)
                except ProtocolError:
                    continue  # bytes garbled by a rate mismatch
                if isinstance(msg, Banner):
                    banner = True
                elif isinstance(msg, Ok) and banner:
                    self.next_line += 1
                    return True
                elif isinstance(msg, ErrorReply) and msg.resend == self.next_line:
                    self._write(protocol.encode_line("$I", self.next_line))  # garbled: again
        return False

    def wait_idle(self, timeout_s: float, on_status: Callable[[StatusReport], None] | None = None,
                  last_line: int | None = None) -> StatusReport:
        """Poll until the machine is Idle with an empty queue (and `last_line` accepted, so
        every line up to it has run: nothing is left to execute)."""
        deadline = time.monotonic() + timeout_s
        pause = min(WAIT_FIRST_POLL_S, self.poll_interval_s)
        while True:
            st = self.status()
            if on_status is not None:
                on_status(st)
            if st.state == "Alarm":
                info = protocol.CODES.get(st.detail or 0)
                raise LinkFaultError(FaultKind.ALARM, f"{self.url}: alarm {st.detail}: "
                                     f"{info.description if info else 'unknown alarm'}",
                                     -1, st.detail, st)
            if st.state == "Idle" and st.queued == 0 and (
                    last_line is None or st.accepted_line >= last_line):
                return st
            if time.monotonic() > deadline:
                raise LinkFaultError(FaultKind.TIMEOUT, f"{self.url}: machine still {st.state} "
                                     f"after {timeout_s:g} s", -1, status=st)
            time.sleep(pause)
            pause = min(2 * pause, self.poll_interval_s)

    # ------------------------------------------------------------------ streaming
    def stream(self, program: Program | Sequence[str], *, counting: bool = True,
               on_progress: Callable[[StreamProgress], None] | None = None,
               timeout_s: float | None = None,
               should_stop: Callable[[], bool] | None = None,
               on_interrupt: Callable[[], bool] | None = None,
               overrides: Overrides | None = None, pack_lines: bool = True) -> StreamResult:
        """Send `program` as numbered, checksummed lines; return when every line is `ok`.

        A program is the typed one (`fivebar_host.program`); hand-written line bodies (commands,
        tests) are read into one by `wire.read_lines`.

        Character counting keeps the unanswered bytes within the banner's `rx:`; with
        `counting=False` one line is in flight at a time. A resend request (error 8, 9, 10)
        rewinds to the number the firmware asks for once the lines in flight are answered; a
        line whose reply never comes (its newline lost) is detected by a status report that
        shows it was not accepted while the firmware is not blocked. Any other error, an
        alarm, a reset banner, a timeout or a disconnect raises `LinkFaultError` with the index of
        the first line not acknowledged.

        When `should_stop()` turns true the machine is held at once (`!`, laser off) and
        `on_interrupt()` decides: True resumes (`~`) and streaming goes on, False (or no
        callback) raises `LinkFaultError(FaultKind.INTERRUPT)`. `overrides` (live feed and
        power, `run.overrides`) apply to the lines not yet written. With `pack_lines` runs of
        moves after a `G90` go out as G6 lines (`wire.pack_line`, protocol 6.3), one line
        number per item as before. See `controllers.fivebar.stream.Streamer`.
        """
        if not isinstance(program, Program):
            program = wire.read_lines(program)
        if self.resync_numbering:
            self.resync_numbering = False
            time.sleep(RESYNC_SETTLE_S)  # the replies of the lines still in flight
            self._drain_input()
            self.next_line = self.status().accepted_line + 1
        return Streamer(self, program, counting=counting, on_progress=on_progress,
                        timeout_s=timeout_s, should_stop=should_stop,
                        on_interrupt=on_interrupt, overrides=overrides,
                        pack_lines=pack_lines).run()
