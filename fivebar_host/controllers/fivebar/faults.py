"""After a fault: stop the machine safely, record where it stopped, and say so.

The controller (`controllers.fivebar.controller`) calls `after_fault` with the stream that
ran. The controller answers: hold, read
the position, Ctrl-X — the resume point is exact. It restarted (a reset banner) or hung and
was rebooted through DTR: the status read after the restart shows the record it kept
(position, `H`, `Ln` done: docs/protocol.md 7), exact when it maps onto this stream. The link
broke, or the hung controller gave no status even after DTR: the position is not known yet;
the resume file describes the stream so that `--resume` reads the kept record later.
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass, replace

from fivebar_host import protocol
from fivebar_host.compile import Job
from fivebar_host.controllers.fivebar.kept import kept_resume_segment
from fivebar_host.controllers.fivebar.link import Link
from fivebar_host.program import Program
from fivebar_host.protocol import StatusReport
from fivebar_host.run.errors import FaultKind, LinkError, LinkFaultError, SendError
from fivebar_host.run.resume import ResumePoint, redraw_text
from fivebar_host.run.store import ResumeStore


@dataclass(frozen=True)
class StreamRun:
    """A stream that ran: its program, first firmware line and `build_program`'s inputs."""

    prog: Program
    first_line: int
    start: int
    start_position: tuple[int, int]
    laser: bool
    end: int | None = None  # segment the stream ends before (None: the job's end)
    copy: int = 1  # the copy running (`--copies`)

    def done_segments(self, done_line: int) -> int:
        """First segment not finished when `done_line` is the last line executed."""
        return self.prog.finished_segments(self.first_line, done_line, self.start)


@dataclass
class Stop:
    """What stopping the machine after a fault found out."""

    reset_banner: bool  # the fault was the controller restarting (a banner mid-stream)
    held: StatusReport | None = None  # after the hold: the controller answers
    after: StatusReport | None = None  # after a DTR reboot
    rebooted: bool = False  # rebooted through DTR
    ctrl_x: bool = False  # reset with Ctrl-X, which zeroes `Ln` done

    @property
    def restarted(self) -> bool:
        """The controller restarted: its queue and the host's position are gone."""
        return self.reset_banner or self.rebooted

    @property
    def kept(self) -> StatusReport | None:
        """The status that shows what the controller kept across its restart, if read."""
        if self.rebooted:
            return self.after
        return self.held if self.reset_banner else None

    def laser_text(self) -> str:
        if self.held is not None:
            return "laser off (held and reset)"
        if self.rebooted:
            return "the controller did not answer and was rebooted through DTR: laser off"
        return "laser: the firmware switches it off after its silence timeout"


def stop_machine(link: Link, fault: LinkFaultError) -> Stop:
    """Hold, wait for the motion to end and reset; reboot through DTR when it won't answer.

    Nothing is tried after a disconnect: the port is gone."""
    stop = Stop(reset_banner=fault.kind is FaultKind.RESET)
    if fault.kind is FaultKind.DISCONNECT:
        return stop
    try:
        link.realtime(protocol.RT_HOLD)
        stop.held = wait_stopped(link)
        stop.ctrl_x = True  # Ctrl-X zeroes Ln done: the kept record is read before it
        link.reset()
    except LinkError:
        # No answer: reboot the controller through DTR so its laser output goes off.
        stop.rebooted = link.hardware_reset()
        if stop.rebooted:
            with contextlib.suppress(LinkError):
                stop.after = link.status(timeout_s=2.0)
    return stop


def wait_stopped(link: Link, timeout_s: float = 5.0) -> StatusReport:
    """After `!`, poll until two consecutive reports show the same position (motion over)."""
    deadline = time.monotonic() + timeout_s
    prev = link.status(timeout_s=1.0)
    while time.monotonic() < deadline:
        time.sleep(0.05)
        st = link.status(timeout_s=1.0)
        if (st.a, st.b) == (prev.a, prev.b) and st.state in ("Hold", "Idle", "Alarm"):
            return st
        prev = st
    raise LinkError(f"{link.url}: the machine did not stop within {timeout_s:g} s of hold")


class FaultRecord:
    """Where a faulted stream stopped, as far as is known, for the resume file and the user."""

    def __init__(self, job: Job, stream: StreamRun, fault: LinkFaultError, stop: Stop) -> None:
        self.job = job
        self.stream = stream
        self.fault = fault
        self.stop = stop
        self.n = job.n_segments
        held = stop.held
        # Conservative: the last segment a status report of the stream confirmed.
        seen = fault.status if stop.restarted or held is None else held
        self.next_segment = (stream.done_segments(seen.done_line) if seen is not None
                             else stream.start)
        self.position = None if stop.restarted or held is None else (held.a, held.b)
        self.kept_why = "the controller gave no status after restarting"
        kept = stop.kept
        if kept is not None:
            exact, self.kept_why = kept_resume_segment(
                stream.prog, stream.first_line, stream.start, stream.start_position, kept,
                self.next_segment)
            if exact is not None:
                self.next_segment, self.position = exact, (kept.a, kept.b)
        sent = fault.sent if fault.sent >= 0 else len(stream.prog)
        self.sent_segment = stream.done_segments(stream.first_line + sent - 1)

    def resume_point(self, fingerprint: str) -> tuple[ResumePoint, str]:
        """The resume point to save and the sentence that says where the machine stopped."""
        if self.position is not None:
            return self._exact(fingerprint, self.position)
        if self.stop.ctrl_x:
            return self._restarted_unknown(fingerprint)
        return self._not_known_yet(fingerprint)

    def _point(self, fingerprint: str, position: tuple[int, int] | None) -> ResumePoint:
        return ResumePoint(str(self.job.file), fingerprint, self.next_segment, position,
                           f"{self.fault.kind}: {self.fault}", self.n, copy=self.stream.copy)

    def _exact(self, fingerprint: str, position: tuple[int, int]) -> tuple[ResumePoint, str]:
        nxt, n = self.next_segment, self.n
        at = f"A = {position[0]}, B = {position[1]} steps"
        if self.stop.restarted:
            kept = self.stop.kept
            assert kept is not None
            where = (f"the controller kept its position and its last executed line "
                     f"({kept.done_line}) across the restart: stopped at {at}; last segment "
                     f"executed: {nxt} of {n}")
        else:
            where = f"stopped at {at}; last segment executed: {nxt} of {n}"
        return self._point(fingerprint, position), where

    def _restarted_unknown(self, fingerprint: str) -> tuple[ResumePoint, str]:
        """Restarted without a usable record, and the Ctrl-X has zeroed Ln done since."""
        nxt = self.next_segment
        rp = replace(self._point(fingerprint, None), sent_segment=self.sent_segment)
        where = (f"position unknown: the controller restarted without its position "
                 f"({self.kept_why}); home the machine before resuming. Segments known "
                 f"executed: {nxt} of {self.n}; {redraw_text(nxt, self.sent_segment)}")
        return rp, where

    def _not_known_yet(self, fingerprint: str) -> tuple[ResumePoint, str]:
        """The stream is described so that `--resume` reads the controller's kept record."""
        s, nxt = self.stream, self.next_segment
        rp = replace(self._point(fingerprint, None), first_line=s.first_line,
                     last_line=s.first_line + len(s.prog) - 1, stream_start=s.start,
                     start_position=s.start_position, laser=s.laser,
                     sent_segment=self.sent_segment, stream_end=s.end)
        cause = ("the link broke while the controller was running"
                 if self.fault.kind is FaultKind.DISCONNECT
                 else f"the controller could not be read ({self.kept_why})")
        where = (f"position not known yet: {cause}. Segments known executed: {nxt} of "
                 f"{self.n}. The controller keeps its position and its last executed line "
                 "across a reset (opening the port resets an Arduino): --resume reads them "
                 "from it and continues exactly; only if it loses power first, homing is "
                 f"needed and {redraw_text(nxt, self.sent_segment)}")
        return rp, where


def after_fault(link: Link, job: Job, stream: StreamRun, fault: LinkFaultError,
                store: ResumeStore, fingerprint: str) -> SendError:
    """Stop the machine safely, save the resume point in `store`, and describe it all."""
    stop = stop_machine(link, fault)
    rp, where = FaultRecord(job, stream, fault, stop).resume_point(fingerprint)
    store.save(rp)
    hint = store.hint()
    return SendError(f"{fault}\n{where}; {stop.laser_text()}." + (f"\n{hint}" if hint else ""))
