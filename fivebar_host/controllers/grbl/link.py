"""The serial link to a stock GRBL 1.1 board: banner, `ok`/`error:N`, `$$`, `?` status,
character-counting streaming against its 128-byte receive buffer, feed hold and reset.

GRBL acknowledges a line once it is parsed and planned, not when it has run; its `ok`
carries no line number. Character counting keeps the bytes of unacknowledged lines at most
127 (the ring keeps one slot empty), so nothing is dropped; the count of `ok`s is the count
of lines GRBL accepted, which is all GRBL says about progress. Where the machine is, `?`
says exactly (MPos, in degrees here).
"""

from __future__ import annotations

import re
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import serial

from fivebar_host.controllers import ports
from fivebar_host.controllers.ports import PortLock
from fivebar_host.run.errors import SendError

RX_BUFFER = 128
_STATUS = re.compile(r"^<([A-Za-z]+)(?::(\d))?\|([MW])Pos:([-\d.]+),([-\d.]+)(?:,[-\d.]+)*"
                     r"(.*)>$")
_WCO = re.compile(r"\|WCO:([-\d.]+),([-\d.]+)")
_FS = re.compile(r"\|F(?:S)?:([-\d.]+)")


class GrblError(SendError):
    """A GRBL board refused something or faulted; the message says what and what to do."""


class GrblSettingsError(GrblError):
    """The board's `$$` differs from what the profile needs (the differences listed)."""


@dataclass(frozen=True)
class GrblStatus:
    """One `?` report: state (`Hold:0` keeps its sub-state), position in degrees."""

    state: str
    machine: tuple[float, float]  # MPos X, Y (or WPos when the board reports that)
    work_reported: bool  # True when the report carried WPos instead of MPos
    feed: float
    wco: tuple[float, float] | None

    @property
    def idle(self) -> bool:
        """Idle: nothing queued, nothing moving."""
        return self.state == "Idle"


def parse_status(line: str) -> GrblStatus | None:
    """A `<…>` status report, or None when `line` is not one."""
    m = _STATUS.match(line)
    if m is None:
        return None
    state = m.group(1) + (f":{m.group(2)}" if m.group(2) else "")
    rest = m.group(6)
    w = _WCO.search(rest)
    f = _FS.search(rest)
    return GrblStatus(state, (float(m.group(4)), float(m.group(5))), m.group(3) == "W",
                      float(f.group(1)) if f else 0.0,
                      (float(w.group(1)), float(w.group(2))) if w else None)


@dataclass
class StreamState:
    """What a stream knows: lines sent and acknowledged, bytes in flight, last status."""

    sent: int = 0
    acked: int = 0
    bytes_sent: int = 0
    status: GrblStatus | None = None


class GrblStreamError(GrblError):
    """A stream stopped: an `error:N`, an alarm, a reset, silence, or the user's abort.
    `state.acked` lines were accepted by the board."""

    def __init__(self, message: str, state: StreamState, code: str = "") -> None:
        super().__init__(message)
        self.state = state
        self.code = code


class GrblLink:
    """An open GRBL board."""

    def __init__(self, port: Any, url: str, reply_timeout_s: float = 10.0,
                 lock: PortLock | None = None) -> None:
        self.port = port
        self.lock = lock  # the port held for this process (`controllers.ports`)
        self.url = url
        self.reply_timeout_s = reply_timeout_s
        self.messages: list[str] = []  # [MSG:…] and other feedback, in order
        self._buf = b""
        self._skipped: deque[str] = deque()  # lines passed over while waiting for another
        self.dialect = "GRBL 1.1"  # `dialects.detect` of the banner
        self.banner = ""

    @classmethod
    def open(cls, url: str, *, baud: int = 115200, banner_timeout_s: float = 5.0,
             reply_timeout_s: float = 10.0) -> GrblLink:
        """Hold the port (`controllers.ports`: refused, naming the owner, before anything is
        opened when another process holds it), open it and wait for GRBL's banner (opening
        an Uno resets it); without one, a Ctrl-X asks for it. A board that never says
        `Grbl 1.1` is refused."""
        try:
            port, lock = ports.open_port(url, baudrate=baud, timeout=0.05)
        except ValueError as e:
            raise GrblError(f"{url}: {e}") from e
        except (serial.SerialException, OSError) as e:
            raise GrblError(ports.open_trouble(url, e)[1]) from e
        from fivebar_host.controllers.grbl.dialects import detect

        link = cls(port, url, reply_timeout_s, lock)
        for attempt in range(2):
            line = link._wait_line(lambda s: s.startswith(("Grbl ", "GrblHAL ")),
                                   banner_timeout_s)
            if line is not None:
                dialect = detect(line)
                if dialect is None:
                    link.close()
                    raise GrblError(f"{url}: the board says {line!r}; --controller grbl "
                                    "needs GRBL 1.1, grblHAL or FluidNC")
                link.dialect = dialect
                link.banner = line
                return link
            if attempt == 0:
                port.write(b"\x18")
        link.close()
        raise GrblError(f"{url}: no GRBL banner within {banner_timeout_s:g} s (wrong port, "
                        "baud rate or firmware?)")

    def close(self) -> None:
        """Close the port and give it up."""
        ports.close_port(self.port, self.lock)

    # ------------------------------------------------------------------ lines
    def _readline(self, timeout_s: float) -> str | None:
        """One line from the board (without CR/LF), or None after `timeout_s`."""
        deadline = time.monotonic() + timeout_s
        while b"\n" not in self._buf:
            chunk = self.port.read(256)
            if chunk:
                self._buf += chunk
            elif time.monotonic() >= deadline:
                return None
        line, self._buf = self._buf.split(b"\n", 1)
        return line.decode("ascii", "replace").strip()

    def _wait_line(self, want: Callable[[str], bool], timeout_s: float) -> str | None:
        deadline = time.monotonic() + timeout_s
        while (left := deadline - time.monotonic()) > 0:
            line = self._readline(left)
            if line is not None and want(line):
                return line
            if line:
                self._skipped.append(line)
        return None

    def command(self, line: str, timeout_s: float | None = None) -> list[str]:
        """Send one line and wait for its `ok`: the lines it printed before. `error:N` or
        an alarm raises `GrblError` naming the line. (Not during a stream.)"""
        self._skipped.clear()
        self.port.write(line.encode("ascii") + b"\n")
        out: list[str] = []
        deadline = time.monotonic() + (timeout_s or self.reply_timeout_s)
        while (left := deadline - time.monotonic()) > 0:
            reply = self._readline(left)
            if reply is None:
                break
            if reply == "ok":
                return out
            if reply.startswith(("error:", "ALARM:")):
                raise GrblError(f"{self.url}: the board answered {reply} to {line!r}")
            if reply and not reply.startswith("<"):
                out.append(reply)
        raise GrblError(f"{self.url}: no reply to {line!r} within "
                        f"{timeout_s or self.reply_timeout_s:g} s")

    def settings(self) -> dict[int, float]:
        """The board's `$$` as {number: value}."""
        out = {}
        for row in self.command("$$"):
            m = re.match(r"^\$(\d+)=([-\d.]+)", row)
            if m:
                out[int(m.group(1))] = float(m.group(2))
        return out

    def work_offset(self) -> tuple[float, float]:
        """G54 + G92 offsets (X, Y) from `$#`: work = machine − offset."""
        off = [0.0, 0.0]
        for row in self.command("$#"):
            m = re.match(r"^\[(G54|G92):([-\d.]+),([-\d.]+)", row)
            if m:
                off[0] += float(m.group(2))
                off[1] += float(m.group(3))
        return off[0], off[1]

    def status(self, timeout_s: float = 2.0) -> GrblStatus:
        """Ask `?` and parse the report (other lines seen meanwhile are kept as messages)."""
        self.port.write(b"?")
        line = self._wait_line(lambda s: s.startswith("<"), timeout_s)
        st = parse_status(line) if line is not None else None
        if st is None:
            raise GrblError(f"{self.url}: no status report within {timeout_s:g} s")
        return st

    def wait_idle(self, timeout_s: float, on_status: Callable[[GrblStatus], None] | None
                  = None) -> GrblStatus:
        """Poll `?` every 0.1 s until Idle; an alarm raises."""
        deadline = time.monotonic() + timeout_s
        while True:
            st = self.status()
            if on_status is not None:
                on_status(st)
            if st.idle:
                return st
            if st.state == "Alarm":
                raise GrblError(f"{self.url}: the board is in alarm; see its messages "
                                f"{self.messages[-3:]}")
            if time.monotonic() > deadline:
                raise GrblError(f"{self.url}: not idle after {timeout_s:g} s ({st.state})")
            time.sleep(0.1)

    # ------------------------------------------------------------------ realtime
    def hold(self, timeout_s: float = 30.0) -> GrblStatus:
        """Feed hold (`!`, real-time) and wait until motion has stopped (`Hold:0`). In
        laser mode GRBL turns the laser off for the hold; M4 power already fell with the
        deceleration."""
        self.port.write(b"!")
        deadline = time.monotonic() + timeout_s
        while True:
            st = self.status()
            if st.state in ("Hold:0", "Idle", "Alarm") or time.monotonic() > deadline:
                return st
            time.sleep(0.02)

    def resume(self) -> None:
        """Cycle start (`~`)."""
        self.port.write(b"~")

    def reset(self, timeout_s: float = 5.0) -> None:
        """Soft reset (Ctrl-X): queue and receive buffer cleared, laser off; GRBL keeps the
        position when the machine had stopped (after a finished hold), else raises ALARM:3."""
        self.port.write(b"\x18")
        if self._wait_line(lambda s: s.startswith("Grbl "), timeout_s) is None:
            raise GrblError(f"{self.url}: no banner after a reset")

    # ------------------------------------------------------------------ streaming
    def stream(self, lines: Sequence[str], *,
               on_progress: Callable[[StreamState], None] | None = None,
               should_stop: Callable[[], bool] | None = None,
               on_interrupt: Callable[[], bool] | None = None) -> StreamState:
        """Send `lines` by character counting and wait for every `ok`.

        `should_stop` (Ctrl-C) holds the machine (`!`) and asks `on_interrupt`: True
        resumes (`~`), False raises `GrblStreamError` (the board still holds; the caller
        resets). An `error:N`, an alarm or a reset banner raises at once."""
        st = StreamState()
        self._skipped.clear()
        inflight: deque[int] = deque()
        last_poll = last_heard = time.monotonic()
        i = 0
        while i < len(lines) or inflight:
            if should_stop is not None and should_stop():
                self._interrupted(st, on_interrupt)
            data = (lines[i] + "\n").encode("ascii") if i < len(lines) else b""
            if data and sum(inflight) + len(data) < RX_BUFFER:
                self.port.write(data)
                inflight.append(len(data))
                st.sent, st.bytes_sent, i = st.sent + 1, st.bytes_sent + len(data), i + 1
                continue
            if time.monotonic() - last_poll > 0.2:
                self.port.write(b"?")
                last_poll = time.monotonic()
            reply = self._skipped.popleft() if self._skipped else self._readline(0.05)
            if reply is None:
                if time.monotonic() - last_heard > self.reply_timeout_s:
                    raise GrblStreamError(f"{self.url}: the board went silent for "
                                          f"{self.reply_timeout_s:g} s", st)
                continue
            last_heard = time.monotonic()
            self._take(reply, st, inflight, lines)
            if on_progress is not None:
                on_progress(st)
        return st

    def _take(self, reply: str, st: StreamState, inflight: deque[int],
              lines: Sequence[str]) -> None:
        """One line from the board during a stream."""
        if reply == "ok" and inflight:
            inflight.popleft()
            st.acked += 1
        elif reply.startswith("<"):
            st.status = parse_status(reply) or st.status
        elif reply.startswith("error:") and inflight:
            raise GrblStreamError(f"{self.url}: the board answered {reply} to line "
                                  f"{st.acked + 1} ({lines[st.acked]!r})", st, reply)
        elif reply.startswith(("ALARM:", "Grbl ")):
            raise GrblStreamError(f"{self.url}: the board stopped: {reply}", st, reply)
        elif reply:
            self.messages.append(reply)

    def _interrupted(self, st: StreamState, on_interrupt: Callable[[], bool] | None) -> None:
        """Ctrl-C during a stream: hold, then resume or abort."""
        st.status = self.hold()
        if on_interrupt is not None and on_interrupt():
            self.resume()
            return
        raise GrblStreamError(f"{self.url}: stopped by the user (held, laser off)", st,
                              "abort")
