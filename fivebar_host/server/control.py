"""Pause, resume, cancel, overrides and stop, as the machine thread carries them out.

Other threads ask through the request queue (server.requests); the worker hands each job
request to `JobControl.apply`, which checks it against the machine thread's record and the
database and either answers with an error (`JobStateError`, `KeyError` for an unknown job)
or records it: the running job's request (pause, resume, cancel) in the record, or the new
state of a job that does not run (a held job requeued, a waiting one cancelled). A job's
run asks `should_stop` (the stream, between lines, with the requests waiting taken first):
pause, cancel and a daemon stop hold the machine (`!`, laser off at once); `on_interrupt`
then waits while paused (polling `?`), resumes (`~`), or gives up. Cancel gives up at once;
a stop (SIGTERM) first lets the firmware run out of queued lines, so the machine stops at
the end of a segment (server.worker has the story).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

from fivebar_host import protocol
from fivebar_host.server import store as st_
from fivebar_host.server.jobs import CompiledCache
from fivebar_host.server.requests import Cancel, JobRequest, Pause, Resume, SetOverrides
from fivebar_host.server.state import Connection, JobStateError, MachineRecord
from fivebar_host.server.store import JobStore

log = logging.getLogger("fivebar.serve")

#: How often a paused job polls the machine (and waits for requests meanwhile), s.
PAUSED_POLL_S = 0.2
#: ... and a stopping daemon, while the machine runs out of queued lines, s.
DRAIN_POLL_S = 0.05


class JobControl:
    """The job requests and the stop kind (module docstring); machine thread only.

    `poll(timeout_s)` is the worker's: it takes the requests waiting (up to `timeout_s`
    for the first) and carries them out, `apply` among them; `changed` publishes the
    record."""

    def __init__(self, record: MachineRecord, store: JobStore, cache: CompiledCache,
                 drain_timeout_s: float, poll: Callable[[float], None],
                 changed: Callable[[], None]) -> None:
        self.record = record
        self.store = store
        self.cache = cache
        self.drain_timeout_s = drain_timeout_s
        self.poll = poll
        self.changed = changed

    # ------------------------------------------------------------------ requests
    def apply(self, req: JobRequest) -> tuple[int, int] | None:
        """Carry out a job request (its answer: the overrides in force, or None)."""
        if isinstance(req, Pause):
            self._pause(req.job_id)
        elif isinstance(req, Resume):
            self._resume(req.job_id, req.confirm)
        elif isinstance(req, Cancel):
            self._cancel(req.job_id)
        else:
            return self._set_overrides(req)
        return None

    def _pause(self, job_id: int) -> None:
        rec = self.record
        if rec.current != job_id:
            raise JobStateError(f"job {job_id} is not running")
        if rec.request != "cancel":
            rec.request = "pause"

    def _resume(self, job_id: int, confirm: bool) -> None:
        rec = self.record
        if rec.current == job_id:
            if rec.request == "pause" or (rec.live is not None and rec.live.paused):
                rec.request = "resume"
                return
            raise JobStateError(f"job {job_id} is running, not paused")
        job = self.store.get(job_id)
        if job is None:
            raise KeyError(job_id)
        if job.state != st_.HELD:
            raise JobStateError(f"job {job_id} is {job.state}: only a paused or held job "
                                "can be resumed")
        rec.confirm_once[job_id] = confirm
        self.store.set_state(job_id, st_.QUEUED, message="resume requested")

    def _set_overrides(self, req: SetOverrides) -> tuple[int, int]:
        """The running (or paused) job's live overrides: they change the lines not yet
        written (`run.overrides`): a power change at the next line, a feed change at the
        next rest."""
        live = self.record.live
        if self.record.current != req.job_id or live is None or live.job_id != req.job_id:
            raise JobStateError(f"job {req.job_id} is not running: overrides apply to the "
                                "running job only")
        live.overrides.set(req.feed_pct, req.power_pct)
        log.info("job %d: overrides %s", req.job_id, live.overrides.text())
        return live.overrides.values()

    def _cancel(self, job_id: int) -> None:
        if self.record.current == job_id:
            self.record.request = "cancel"
            return
        job = self.store.get(job_id)
        if job is None:
            raise KeyError(job_id)
        if job.state in st_.FINAL_STATES:
            raise JobStateError(f"job {job_id} is already {job.state}")
        self.store.set_state(job_id, st_.CANCELLED, message="cancelled before it ran"
                             if job.state == st_.QUEUED and job.resume is None
                             else "cancelled while held")
        self.cache.drop(job_id)

    # ------------------------------------------------------------------ stop kind
    def stop_kind(self) -> str | None:
        """What the running job is asked to do: terminate, pause, resume, cancel or None."""
        return "terminate" if self.record.terminate else self.record.request

    def pending_stop(self) -> str | None:
        """`stop_kind` once the requests waiting are carried out."""
        self.poll(0.0)
        return self.stop_kind()

    def why(self) -> str:
        """The stop kind in words, for the interrupt fault's message."""
        return {"cancel": "job cancelled", "terminate": "the daemon is stopping",
                "pause": "paused"}.get(self.stop_kind() or "", "interrupted")

    def should_stop(self) -> bool:
        """Whether to hold the machine now (asked by the stream between lines)."""
        return self.pending_stop() in ("pause", "cancel", "terminate")

    def on_interrupt(self, conn: Connection, job_id: int) -> bool:
        """The machine is held after `should_stop`: True resumes, False gives up."""
        kind = self.stop_kind()
        if kind == "terminate":
            self._drain(conn)
            return False
        if kind == "cancel":
            return False
        return self.wait_paused(conn, job_id)

    def wait_paused(self, conn: Connection, job_id: int,
                    message: str = "paused: held, laser off") -> bool:
        """Stay held (or idle at a pen change) until resume (True), cancel or stop (False);
        keeps polling `?`. `message` is the paused job's reason."""
        live = self.record.live
        if live is not None:
            live.paused = True
            self.changed()
        self.store.set_state(job_id, st_.PAUSED, message=message)
        log.info("job %d %s", job_id, message)
        try:
            while True:
                kind = self.stop_kind()
                if kind in ("cancel", "terminate"):
                    return False
                if kind == "resume":
                    self.record.request = None
                    self.store.set_state(job_id, st_.RUNNING, message="")
                    log.info("job %d resumed", job_id)
                    return True
                conn.controller.poll()
                self.poll(PAUSED_POLL_S)
        finally:
            if live is not None:
                live.paused = False
                self.changed()

    def _drain(self, conn: Connection) -> None:
        """Let the held machine run out of queued lines: it stops at a segment's end."""
        link = conn.link
        link.realtime(protocol.RT_RESUME)
        deadline = time.monotonic() + self.drain_timeout_s
        while time.monotonic() < deadline:
            if self.record.hurry:
                log.warning("stopping at once (second signal): the machine holds inside a "
                            "segment")
                return
            st = link.status()
            if st.state != "Run" and st.queued == 0:
                return
            self.poll(DRAIN_POLL_S)
        log.warning("the machine did not run out of queued lines within %g s; holding it",
                    self.drain_timeout_s)
