"""Streaming numbered lines to the firmware: a small state machine over one open `Link`.

`Link.stream` hands its lines to a `Streamer`, which owns everything a stream keeps track of:
the lines in flight, the acknowledged count, a pending rewind, the clocks of the last reply
and the last status report. Each turn of `Streamer.run` honours a stop request, writes what
fits, asks for a status report, reads and acts on what arrived, then checks for a lost line
and for silence. What may be written depends on the phase:

* SENDING — lines are written while their unanswered bytes fit the receive buffer the banner
  reports (GRBL's character counting; one line at a time without counting);
* WAITING — every line is written, replies are awaited;
* DRAINING — the firmware asked for a resend (error 8, 9, 10): nothing is written until the
  lines in flight are answered, then the stream rewinds to the line it asked for;
* DONE — every line is answered `ok`; FAULTED — a `LinkFaultError` was raised.

A line whose reply never comes (its newline was lost, so two lines merged into one refused
line) shows in a status report that has not accepted it while the firmware is free: the stream
rewinds to the line after the last one accepted. Error replies, alarms, a reset banner,
silence and a disconnect fault the stream with the index of the first line not acknowledged.

The stream is a typed `Program` (`fivebar_host.program`); `fivebar_host.wire` writes each wire line
from its items (a G6 line covers several). With `overrides` (`run.overrides`: live feed and
laser power) each item's P and S are taken when its line is first written, with the factors
in force then; once written a line is never changed (a resend sends the same bytes).
Without them every line is encoded up front.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from typing import TYPE_CHECKING

from fivebar_host import protocol, wire
from fivebar_host.program import Kind, Program
from fivebar_host.protocol import (
    AlarmPush,
    Banner,
    ErrorReply,
    Message,
    Ok,
    SettingLine,
    StatusReport,
)
from fivebar_host.run.errors import FaultKind, LinkError, LinkFaultError
from fivebar_host.run.overrides import FEED_MAX_PCT, OverrideEncoder, Overrides

if TYPE_CHECKING:
    from fivebar_host.controllers.fivebar.link import Link

#: A line in flight is suspected lost when no reply came for this long ...
LOST_REPLY_S = 0.3
#: ... and a status report arrived at least this long after the line was written.
LOST_STATUS_AFTER_S = 0.2


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


class Phase(Enum):
    """Where a stream is; see the module docstring."""

    SENDING = "sending"
    WAITING = "waiting"
    DRAINING = "draining"
    DONE = "done"
    FAULTED = "faulted"


#: The transitions a stream may take (a phase may always be entered again).
TRANSITIONS: dict[Phase, frozenset[Phase]] = {
    Phase.SENDING: frozenset({Phase.WAITING, Phase.DRAINING, Phase.FAULTED}),
    Phase.WAITING: frozenset({Phase.SENDING, Phase.DRAINING, Phase.DONE, Phase.FAULTED}),
    Phase.DRAINING: frozenset({Phase.SENDING, Phase.WAITING, Phase.FAULTED}),
    Phase.DONE: frozenset(),
    Phase.FAULTED: frozenset(),
}


class InFlight:
    """The lines written and not yet answered: (job index, job lines covered, bytes, time
    written), oldest first; a G6 wire line covers several job lines (`wire.pack_line`).

    Replies come in the order the lines were written, so each reply answers the oldest."""

    def __init__(self) -> None:
        self.lines: deque[tuple[int, int, int, float]] = deque()
        self.bytes = 0

    def __bool__(self) -> bool:
        return bool(self.lines)

    def fits(self, nbytes: int, budget: int) -> bool:
        """Whether a line of `nbytes` may be written (one line always may, alone)."""
        return not self.lines or self.bytes + nbytes <= budget

    def push(self, index: int, count: int, nbytes: int) -> None:
        self.lines.append((index, count, nbytes, time.monotonic()))
        self.bytes += nbytes

    def pop(self) -> tuple[int, int]:
        """Remove the oldest line; its first job index and how many job lines it covers."""
        index, count, nbytes, _ = self.lines.popleft()
        self.bytes -= nbytes
        return index, count

    def oldest(self) -> tuple[int, float]:
        """Job index of the oldest line and when it was written."""
        index, _, _, at = self.lines[0]
        return index, at

    def clear(self) -> None:
        self.lines.clear()
        self.bytes = 0


class Streamer:
    """One stream of `program` over `link`, from the link's next line number; `run` once.

    Uses the link's raw I/O (`_write`, `_messages`, `_pending`): it is the link's streaming
    half, kept in its own module. Arguments as `Link.stream`."""

    def __init__(self, link: Link, program: Program, *, counting: bool = True,
                 on_progress: Callable[[StreamProgress], None] | None = None,
                 timeout_s: float | None = None,
                 should_stop: Callable[[], bool] | None = None,
                 on_interrupt: Callable[[], bool] | None = None,
                 overrides: Overrides | None = None, pack_lines: bool = True) -> None:
        if link.banner is None:
            raise LinkError(f"{link.url}: no handshake yet")
        self.link = link
        self.program = program
        self.on_progress = on_progress
        self.should_stop = should_stop
        self.on_interrupt = on_interrupt
        self.timeout = timeout_s or link.reply_timeout_s
        self.budget = link.banner.rx if counting else 1
        self.first = link.next_line
        self.encoder = None if overrides is None else OverrideEncoder(program, overrides)
        self.sent_values: list[tuple[int, int]] = []  # (P, S) as sent (overrides), in order
        self.feed_after: list[int] = []  # the encoder's feed factor after each of them
        self.wire: dict[int, tuple[bytes, int]] = {}  # job index → (wire line, lines covered)
        self.absolute = wire.absolute_known(program) if pack_lines else None
        # two packed lines fit the receive buffer, so one is always on its way while the
        # firmware works on the other
        self.limit = min(link.banner.line_max + 1, link.banner.rx // 2)
        self.total = len(program)
        if self.encoder is None:
            j = 0
            while j < self.total:
                j += self._wire(j)[1]
        self.inflight = InFlight()
        self.nxt = 0  # next job index to write
        self.acked = 0
        self.sent_max = 0
        self.resends = 0
        self.rewind_to: int | None = None  # while DRAINING: the job index to resend from
        self.phase = Phase.SENDING if self.total else Phase.WAITING
        self.t0 = time.monotonic()
        self.last_reply = self.t0  # an ok / error arrived
        self.last_activity = self.t0  # any line arrived
        self.last_poll = self.t0 - link.poll_interval_s  # ask for a status report at once
        self.status_at = 0.0
        self.bytes0 = link.bytes_sent

    # ------------------------------------------------------------------ the machine
    def run(self) -> StreamResult:
        """Stream until every line is answered `ok`; LinkFaultError on a fault."""
        try:
            while self.acked < self.total:
                self._turn()
        except LinkFaultError as e:
            self._enter(Phase.FAULTED)
            if e.acked >= 0:
                raise
            # A fault of the link's own I/O (or a callback's): give it this stream's place.
            raise self._fault(e.kind, e.message.removeprefix(f"{self.link.url}: ")) from e
        self._enter(Phase.DONE)
        self.link.next_line = self.first + self.total
        elapsed = time.monotonic() - self.t0
        final = self.link.last_status or self.link.status()
        return StreamResult(self.first, self.first + self.total - 1,
                            self.link.bytes_sent - self.bytes0, self.resends, elapsed, final)

    def _turn(self) -> None:
        """One turn: stop request, write, poll, read and act, then check the link's health."""
        self._check_stop()
        if self.phase is Phase.SENDING:
            self._send_what_fits()
        self._poll_status()
        self._receive()
        if self.phase is Phase.DRAINING and not self.inflight:
            assert self.rewind_to is not None
            self._resend_from(self.rewind_to)
            return
        now = time.monotonic()
        if self._lost_line(now):
            return
        self._check_silence(now)

    def _enter(self, phase: Phase) -> None:
        """Take a transition of `TRANSITIONS` (entering the current phase is a no-op)."""
        if phase is not self.phase:
            assert phase in TRANSITIONS[self.phase], f"stream: {self.phase} → {phase}"
            self.phase = phase

    def _resend_from(self, index: int) -> None:
        """Rewind: the next line written is job line `index`, acknowledged up to it."""
        self.acked = self.nxt = index
        self.resends += 1
        self.rewind_to = None
        self._enter(Phase.SENDING if self.nxt < self.total else Phase.WAITING)

    # ------------------------------------------------------------------ each step of a turn
    def _check_stop(self) -> None:
        """Hold at once when asked to stop; `on_interrupt` resumes, or the stream faults."""
        if self.should_stop is None or not self.should_stop():
            return
        self.link._write(protocol.RT_HOLD)
        if self.on_interrupt is None or not self.on_interrupt():
            raise self._fault(FaultKind.INTERRUPT, f"interrupted by the user at job line "
                              f"{self.acked + 1} of {self.total}")
        self.link._write(protocol.RT_RESUME)
        self.last_reply = self.last_activity = time.monotonic()

    def _send_what_fits(self) -> None:
        """Write lines while their bytes fit the budget; WAITING once all are written."""
        while self.nxt < self.total:
            line, count = self._wire(self.nxt)
            if not self.inflight.fits(len(line), self.budget):
                if self.encoder is not None and self.nxt >= self.sent_max:
                    self._unbuild(self.nxt)  # built again when it fits, overrides then
                break
            self.link._write(line)
            self.inflight.push(self.nxt, count, len(line))
            self.nxt += count
            self.sent_max = max(self.sent_max, self.nxt)
        if self.nxt == self.total:
            self._enter(Phase.WAITING)

    def _values(self, index: int) -> tuple[int, int]:
        """Item `index`'s (P, S) as sent: the items up to it are taken now if they were not
        yet (with the overrides in force); kept once written (`_unbuild` drops the rest)."""
        if self.encoder is None:
            return self.program.rows[3][index], self.program.rows[4][index]
        while len(self.sent_values) <= index:
            self.sent_values.append(self.encoder.values(len(self.sent_values)))
            self.feed_after.append(self.encoder.feed_pct)
        return self.sent_values[index]

    def _unbuild(self, index: int) -> None:
        """Forget the values from item `index` on, none of them written yet, and the wire
        line starting there: the overrides in force when they are taken again apply (an
        override takes effect at the next line written, never changes one written)."""
        assert self.encoder is not None
        del self.sent_values[index:]
        del self.feed_after[index:]
        self.encoder.feed_pct = self.feed_after[-1] if self.feed_after else FEED_MAX_PCT
        self.wire.pop(index, None)

    def _wire(self, index: int) -> tuple[bytes, int]:
        """The wire line that starts at item `index` and how many items it covers (a G6
        several, `wire.pack_line`); kept once built, so a resend sends the same bytes. The
        item after a G6 (read to see whether it joins) stays untaken."""
        got = self.wire.get(index)
        if got is None:
            if self.absolute is None and self.program.rows[0][index] != Kind.RASTER:
                p, s = self._values(index)
                got = protocol.encode_line(wire.body(self.program, index, p, s),
                                           self.first + index), 1
            else:
                absolute = self.absolute is not None and bool(self.absolute[index])
                got = wire.pack_line(self.program, index, self.first + index, absolute,
                                     self.limit, self._values)
                if self.encoder is not None and len(self.sent_values) > index + got[1]:
                    self._unbuild(index + got[1])
            self.wire[index] = got
        return got

    def _text(self, index: int) -> str:
        """Item `index` as a line body, for messages."""
        return wire.body(self.program, index)

    def _poll_status(self) -> None:
        now = time.monotonic()
        if now - self.last_poll >= self.link.poll_interval_s:
            self.link._write(protocol.RT_STATUS)
            self.last_poll = now

    def _receive(self) -> None:
        """Act on what arrived (and what `Link.status` kept meanwhile), in order."""
        msgs = list(self.link._pending) + self.link._messages(0.01)
        self.link._pending.clear()
        for msg in msgs:
            self._handle(msg)

    def _lost_line(self, now: float) -> bool:
        """Rewind when the firmware is free and has had time, yet never accepted the oldest
        line in flight: its newline was lost (two lines merged into one rejected line).
        Resumes from the last line it accepted."""
        st = self.link.last_status
        if not self.inflight or st is None or now - self.last_reply <= LOST_REPLY_S:
            return False
        assert self.link.banner is not None
        index, written_at = self.inflight.oldest()
        if (self.status_at <= written_at + LOST_STATUS_AFTER_S
                or st.queued >= self.link.banner.queue - 1
                or st.accepted_line >= self.first + index):
            return False
        self.inflight.clear()
        self._resend_from(max(0, st.accepted_line + 1 - self.first))
        self.last_reply = now
        return True

    def _check_silence(self, now: float) -> None:
        if now - self.last_activity <= self.timeout:
            return
        if self.inflight:
            index, _ = self.inflight.oldest()
            what = f"job line {index + 1} ({self._text(index)!r})"
        else:
            what = "a status report"
        raise self._fault(FaultKind.TIMEOUT, f"the device went silent: no reply for "
                          f"{self.timeout:g} s to {what}")

    # ------------------------------------------------------------------ messages
    def _handle(self, msg: Message) -> None:
        """One message from the firmware: a status report, a fault, or a reply to a line."""
        self.last_activity = time.monotonic()
        if isinstance(msg, StatusReport):
            self._on_status(msg)
        elif isinstance(msg, Banner):
            self.link.banner = msg
            raise self._fault(FaultKind.RESET, "the firmware restarted (banner received) while "
                              "streaming: its queue is lost")
        elif isinstance(msg, AlarmPush):
            info = protocol.CODES.get(msg.code)
            raise self._fault(FaultKind.ALARM, f"ALARM:{msg.code} "
                              f"({info.description if info else 'unknown alarm'})", msg.code)
        elif not isinstance(msg, SettingLine):
            self._on_reply(msg)

    def _on_status(self, msg: StatusReport) -> None:
        self.link.last_status = msg
        self.status_at = self.last_activity
        if msg.state == "Alarm":
            raise self._fault(FaultKind.ALARM, f"alarm {msg.detail} while streaming", msg.detail)
        self._progress()

    def _on_reply(self, msg: Ok | ErrorReply) -> None:
        """`ok` acknowledges the oldest line in flight; `error:` asks for a resend or faults."""
        self.last_reply = self.last_activity
        if not self.inflight:
            raise self._fault(FaultKind.ERROR, f"unexpected reply {msg} with no line in flight")
        index, count = self.inflight.pop()
        if isinstance(msg, Ok):
            if index == self.acked:
                self.acked += count
            self._progress()
        elif msg.resend is not None:
            self._on_resend_request(msg.resend)
        else:
            info = protocol.CODES.get(msg.code)
            why = info.description if info else "unknown error code"
            fault = self._fault(FaultKind.ERROR, f"job line {index + 1} "
                                f"({self._text(index)!r}) refused: error:{msg.code} {why}",
                                msg.code)
            # A line refused with a plain error was accepted first (protocol 5.2, step 9): its
            # numbers are used. Alone in flight, the next number is known; with later lines on
            # their way, the firmware's own counter says it before the link's next stream.
            if self.inflight:
                self.link.resync_numbering = True
            else:
                self.link.next_line = self.first + index + count
            raise fault

    def _on_resend_request(self, line: int) -> None:
        """DRAINING until the lines in flight are answered, then resend from `line`."""
        want = line - self.first
        if not 0 <= want <= self.total:
            raise self._fault(FaultKind.ERROR, f"firmware asks to resend line {line}, outside "
                              f"this job ({self.first}..{self.first + self.total - 1})")
        self.rewind_to = want if self.rewind_to is None else min(self.rewind_to, want)
        self._enter(Phase.DRAINING)

    # ------------------------------------------------------------------ reporting
    def _progress(self) -> None:
        if self.on_progress is not None:
            st = self.link.last_status
            self.on_progress(StreamProgress(self.sent_max, self.acked, self.total,
                                            st.done_line if st else 0, st, self.resends))

    def _fault(self, kind: FaultKind, msg: str, code: int | None = None) -> LinkFaultError:
        """The fault to raise; the link's next line becomes the first one not acknowledged."""
        self.link.next_line = self.first + self.acked
        return LinkFaultError(kind, f"{self.link.url}: {msg}", self.acked, code,
                              self.link.last_status, self.sent_max)
