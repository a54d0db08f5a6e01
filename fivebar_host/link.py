"""Serial link to the fivebar firmware: open, handshake, stream with flow control, faults.

The only module of the host program that uses pyserial (besides the URL handlers in
`fivebar_host.devices`, which *are* pyserial ports). Every line goes out numbered and with a
checksum field, its body's CRC-16 and length (docs/protocol.md 5.1), so a corrupted line, a
line that lost or gained bytes, or a lost line is resent and no line runs twice.

Flow control is GRBL's character counting: the bytes of lines sent but not yet answered never
exceed the receive buffer the banner reports. Send-and-wait (one line in flight) is the
fallback for links that lose bytes under load.
"""

from __future__ import annotations

import contextlib
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import serial

from fivebar_host import protocol
from fivebar_host.errors import FivebarError
from fivebar_host.protocol import (
    AlarmPush,
    Banner,
    ErrorReply,
    Message,
    Ok,
    ProtocolError,
    SettingLine,
    StatusReport,
)


class LinkError(FivebarError, RuntimeError):
    """The link failed; the message says where (port, line) and why."""

    exit_code = 3


class NoBannerError(LinkError):
    """No fivebar banner arrived: not our firmware, wrong baud rate, or no device."""


class FirmwareMismatchError(LinkError):
    """The device speaks another protocol version than this host (protocol.PROTOCOL_VERSION).

    Versions are not mixed: version 2 changed the line checksum, so a version 1 firmware
    would refuse every numbered line of this host with ``error:8``.
    """


@dataclass
class LinkFaultError(LinkError):
    """A fault while streaming: an error reply, a timeout, a disconnect, a reset or an alarm.

    `acked` is the index of the first job line not yet answered `ok`; `sent` the number of
    job lines written at least once (the device may have accepted, and run, any of them);
    both are −1 for a fault outside a stream. `status` is the last status report received
    before the fault.
    """

    kind: str  # "error", "timeout", "disconnect", "reset", "alarm", "interrupt"
    message: str
    acked: int
    code: int | None = None
    status: StatusReport | None = None
    sent: int = -1

    def __str__(self) -> str:
        return self.message


@dataclass(frozen=True)
class StreamProgress:
    """Progress of a stream, reported after every reply and status report."""

    sent: int  # job lines written (first transmissions)
    acked: int  # job lines answered ok
    total: int
    done_line: int  # firmware line number of the last block executed
    status: StatusReport | None
    resends: int


@dataclass(frozen=True)
class StreamResult:
    """What a completed stream did: line numbers used, resends, bytes and time."""

    first_line: int
    last_line: int
    bytes_sent: int
    resends: int
    elapsed_s: float
    final_status: StatusReport


def register_url_handlers() -> None:
    """Make `fivebar-mock://` and `fivebar-sim://` known to `serial.serial_for_url`."""
    from fivebar_host.devices import urls

    urls.register()


class Link:
    """A protocol session on one open port (anything with pyserial's Serial interface)."""

    def __init__(self, port: Any, *, url: str = "", reply_timeout_s: float = 10.0,
                 poll_interval_s: float = 0.05) -> None:
        self.port = port
        self.url = url or str(getattr(port, "port", "?"))
        self.reply_timeout_s = reply_timeout_s
        self.poll_interval_s = poll_interval_s
        self.banner: Banner | None = None
        self.last_status: StatusReport | None = None
        self.next_line = 1  # the number the firmware expects next
        self.bytes_sent = 0
        self._buf = b""
        self._pending: deque[Message] = deque()

    # ------------------------------------------------------------------ opening
    @classmethod
    def open(cls, url: str, *, baud: int = 115200, banner_timeout_s: float = 5.0,
             reply_timeout_s: float = 10.0) -> Link:
        """Open `url` (a device path, COM port or pyserial URL) and wait for the banner."""
        register_url_handlers()
        try:
            port = serial.serial_for_url(url, baudrate=baud, timeout=0.02, write_timeout=5.0)
        except ValueError as e:
            raise LinkError(f"{url}: {e}") from e
        except (serial.SerialException, OSError) as e:
            raise LinkError(f"{url}: cannot open the port: {e}") from e
        link = cls(port, url=url, reply_timeout_s=reply_timeout_s)
        try:
            link.handshake(banner_timeout_s)
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
        """Close the port (idempotent)."""
        with contextlib.suppress(serial.SerialException, OSError):
            self.port.close()

    def __enter__(self) -> Link:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ raw I/O
    def _write(self, data: bytes) -> None:
        try:
            self.port.write(data)
        except (serial.SerialException, OSError) as e:
            raise LinkFaultError("disconnect", f"{self.url}: write failed, device gone? ({e})",
                            -1) from e
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
                raise LinkFaultError("disconnect", f"{self.url}: read failed, device gone? ({e})",
                                -1) from e
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
        raise LinkFaultError("timeout", f"{self.url}: no status report within "
                        f"{timeout_s or self.reply_timeout_s:g} s", -1)

    def command(self, body: str, timeout_s: float | None = None) -> None:
        """Send one numbered line and wait for its `ok`; raise LinkFaultError on `error:`."""
        self.stream([body], counting=False, timeout_s=timeout_s)

    def reset(self, timeout_s: float = 5.0) -> Banner:
        """Ctrl-X: the firmware clears its queue, turns the laser off and reboots its state."""
        self._write(protocol.RT_RESET)
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            for msg in self._messages(0.05):
                if isinstance(msg, Banner):
                    self.banner = msg
                    self._pending.clear()
                    st = self.status()
                    self.next_line = st.accepted_line + 1
                    return msg
        raise LinkFaultError("timeout", f"{self.url}: no banner within {timeout_s:g} s after reset",
                        -1)

    def hardware_reset(self, timeout_s: float = 3.0) -> bool:
        """Pulse DTR — an Arduino's auto-reset line — to reboot a controller that no longer
        answers (its laser output goes off with the reboot). True if a banner followed.

        The reboot restarts the line counter (the next line is 1) and keeps the RAM powered:
        the controller keeps its position, `H` and `Ln` done (docs/protocol.md 7)."""
        try:
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

    def wait_idle(self, timeout_s: float, on_status: Callable[[StatusReport], None] | None = None,
                  last_line: int | None = None) -> StatusReport:
        """Poll until the machine is Idle with an empty queue (and `last_line` accepted, so
        every line up to it has run: nothing is left to execute)."""
        deadline = time.monotonic() + timeout_s
        while True:
            st = self.status()
            if on_status is not None:
                on_status(st)
            if st.state == "Alarm":
                info = protocol.CODES.get(st.detail or 0)
                raise LinkFaultError("alarm", f"{self.url}: alarm {st.detail}: "
                                     f"{info.description if info else 'unknown alarm'}",
                                     -1, st.detail, st)
            if st.state == "Idle" and st.queued == 0 and (
                    last_line is None or st.accepted_line >= last_line):
                return st
            if time.monotonic() > deadline:
                raise LinkFaultError("timeout", f"{self.url}: machine still {st.state} after "
                                f"{timeout_s:g} s", -1, status=st)
            time.sleep(self.poll_interval_s)

    # ------------------------------------------------------------------ streaming
    def stream(self, bodies: Sequence[str], *, counting: bool = True,
               on_progress: Callable[[StreamProgress], None] | None = None,
               timeout_s: float | None = None,
               should_stop: Callable[[], bool] | None = None,
               on_interrupt: Callable[[], bool] | None = None) -> StreamResult:
        """Send `bodies` as numbered, checksummed lines; return when every line is `ok`.

        Character counting keeps the unanswered bytes within the banner's `rx:`; with
        `counting=False` one line is in flight at a time. A resend request (error 8, 9, 10)
        rewinds to the number the firmware asks for once the lines in flight are answered; a
        line whose reply never comes (its newline lost) is detected by a status report that
        shows it was not accepted while the firmware is not blocked. Any other error, an
        alarm, a reset banner, a timeout or a disconnect raises `LinkFaultError` with the index of
        the first line not acknowledged.

        When `should_stop()` turns true the machine is held at once (`!`, laser off) and
        `on_interrupt()` decides: True resumes (`~`) and streaming goes on, False (or no
        callback) raises `LinkFaultError("interrupt")`.
        """
        if self.banner is None:
            raise LinkError(f"{self.url}: no handshake yet")
        timeout = timeout_s or self.reply_timeout_s
        budget = self.banner.rx if counting else 1
        first = self.next_line
        encoded = [protocol.encode_line(b, first + i) for i, b in enumerate(bodies)]
        total = len(encoded)
        inflight: deque[tuple[int, int, float]] = deque()  # (job index, bytes, sent at)
        inflight_bytes = 0
        nxt = 0  # next job index to write
        acked = 0
        sent_max = 0
        resends = 0
        rewind_to: int | None = None
        t0 = time.monotonic()
        last_reply = t0  # an ok / error arrived
        last_activity = t0  # any line arrived
        last_poll = t0 - self.poll_interval_s  # ask for a status report at once
        status_at = 0.0
        bytes0 = self.bytes_sent

        def progress() -> None:
            if on_progress is not None:
                st = self.last_status
                on_progress(StreamProgress(sent_max, acked, total,
                                           st.done_line if st else 0, st, resends))

        def fault(kind: str, msg: str, code: int | None = None) -> LinkFaultError:
            self.next_line = first + acked
            return LinkFaultError(kind, f"{self.url}: {msg}", acked, code, self.last_status,
                                  sent_max)

        try:
            while acked < total:
                if should_stop is not None and should_stop():
                    self._write(protocol.RT_HOLD)
                    if on_interrupt is None or not on_interrupt():
                        raise fault("interrupt", f"interrupted by the user at job line "
                                    f"{acked + 1} of {total}")
                    self._write(protocol.RT_RESUME)
                    last_reply = last_activity = time.monotonic()
                # Send what fits (nothing while a rewind waits for the lines in flight).
                while (rewind_to is None and nxt < total
                       and (not inflight or inflight_bytes + len(encoded[nxt]) <= budget)):
                    self._write(encoded[nxt])
                    inflight.append((nxt, len(encoded[nxt]), time.monotonic()))
                    inflight_bytes += len(encoded[nxt])
                    nxt += 1
                    sent_max = max(sent_max, nxt)
                now = time.monotonic()
                if now - last_poll >= self.poll_interval_s:
                    self._write(protocol.RT_STATUS)
                    last_poll = now
                msgs = list(self._pending) + self._messages(0.01)
                self._pending.clear()
                for msg in msgs:
                    last_activity = time.monotonic()
                    if isinstance(msg, StatusReport):
                        self.last_status = msg
                        status_at = last_activity
                        if msg.state == "Alarm":
                            raise fault("alarm", f"alarm {msg.detail} while streaming", msg.detail)
                        progress()
                        continue
                    if isinstance(msg, Banner):
                        self.banner = msg
                        raise fault("reset", "the firmware restarted (banner received) while "
                                    "streaming: its queue is lost")
                    if isinstance(msg, AlarmPush):
                        info = protocol.CODES.get(msg.code)
                        raise fault("alarm", f"ALARM:{msg.code} "
                                    f"({info.description if info else 'unknown alarm'})", msg.code)
                    if isinstance(msg, SettingLine):
                        continue
                    last_reply = last_activity
                    if not inflight:
                        raise fault("error", f"unexpected reply {msg} with no line in flight")
                    idx, nbytes, _ = inflight.popleft()
                    inflight_bytes -= nbytes
                    if isinstance(msg, Ok):
                        if idx == acked:
                            acked += 1
                        progress()
                    elif isinstance(msg, ErrorReply) and msg.resend is not None:
                        want = msg.resend - first
                        if not 0 <= want <= total:
                            raise fault("error", f"firmware asks to resend line {msg.resend}, "
                                        f"outside this job ({first}..{first + total - 1})")
                        rewind_to = want if rewind_to is None else min(rewind_to, want)
                    else:
                        assert isinstance(msg, ErrorReply)
                        info = protocol.CODES.get(msg.code)
                        why = info.description if info else "unknown error code"
                        raise fault("error", f"job line {idx + 1} ({bodies[idx]!r}) refused: "
                                    f"error:{msg.code} {why}", msg.code)
                if rewind_to is not None and not inflight:
                    acked = nxt = rewind_to
                    resends += 1
                    rewind_to = None
                    continue
                now = time.monotonic()
                st = self.last_status
                if (inflight and st is not None and now - last_reply > 0.3
                        and status_at > inflight[0][2] + 0.2
                        and st.queued < self.banner.queue - 1
                        and st.accepted_line < first + inflight[0][0]):
                    # The firmware is free and has had time, yet never accepted the oldest line
                    # in flight: its newline was lost (two lines merged into one rejected line).
                    # Resume from the last line it accepted.
                    acked = nxt = max(0, st.accepted_line + 1 - first)
                    inflight.clear()
                    inflight_bytes = 0
                    rewind_to = None
                    resends += 1
                    last_reply = now
                    continue
                if now - last_activity > timeout:
                    what = (f"job line {inflight[0][0] + 1} ({bodies[inflight[0][0]]!r})"
                            if inflight else "a status report")
                    raise fault("timeout", f"the device went silent: no reply for {timeout:g} s "
                                f"to {what}")
        except LinkFaultError as e:
            if e.acked >= 0:
                raise
            raise fault(e.kind, e.message.removeprefix(f"{self.url}: ")) from e
        self.next_line = first + total
        elapsed = time.monotonic() - t0
        final = self.last_status or self.status()
        return StreamResult(first, first + total - 1, self.bytes_sent - bytes0, resends,
                            elapsed, final)
