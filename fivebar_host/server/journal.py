"""The machine thread's journalled link and its off-thread progress writer.

`JournalLink` is a `Link` that says whether a stream is running, and remembers when it last
heard a status report (for the snapshot's `status_age_s`), telling
`on_status` (the web page's event stream) that a new one came.
`ProgressWriter` commits running jobs' progress to SQLite on its own thread, so a slow
commit (an fsync on an SD card) never stalls the stream.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

from fivebar_host.controllers.fivebar.link import Link
from fivebar_host.controllers.fivebar.stream import StreamResult
from fivebar_host.program import Program
from fivebar_host.protocol import AlarmPush, StatusReport
from fivebar_host.server.store import JobStore

log = logging.getLogger("fivebar.serve")


class JournalLink(Link):
    """A `Link` that says whether it streams and when it last heard a status report."""

    #: Called (on the machine thread) after every status report; must be quick.
    on_status: Callable[[], None] | None = None
    streaming = False
    status_at = 0.0
    _last: StatusReport | None = None

    @property
    def last_status(self) -> StatusReport | None:
        """The last status report received (set by `status()`, `stream()` ...)."""
        return self._last

    @last_status.setter
    def last_status(self, st: StatusReport | None) -> None:
        self._last = st
        if st is not None:
            self.status_at = time.monotonic()
            hook = self.on_status
            if hook is not None:
                hook()

    def take_alarm_pushes(self) -> list[AlarmPush]:
        """Remove the `ALARM:n` pushes kept from status requests while idle. The status
        report says the machine is in alarm; left here, the push would make the next
        command (clearing the alarm with `$X`, homing) fail as if its own line had
        raised it."""
        pushes = [m for m in self._pending if isinstance(m, AlarmPush)]
        if pushes:
            kept = [m for m in self._pending if not isinstance(m, AlarmPush)]
            self._pending.clear()
            self._pending.extend(kept)
        return pushes

    def stream(self, program: Program | Sequence[str], **kwargs: Any) -> StreamResult:
        """`Link.stream`, with `streaming` true while it runs."""
        self.streaming = True
        try:
            return super().stream(program, **kwargs)
        finally:
            self.streaming = False


class ProgressWriter(threading.Thread):
    """Writes running jobs' progress to the database off the streaming thread.

    A commit is quick, but now and then SQLite checkpoints its journal with an fsync, which
    on an SD card can take longer than the firmware queue lasts; the stream must never wait
    for that. `put` only records the latest values; this thread commits them every 0.5 s.
    `flush` (from the machine thread, at the end of a run) waits for a write in progress and
    commits what is left, so nothing older lands after a job's final record."""

    def __init__(self, store: JobStore, period_s: float = 0.5) -> None:
        super().__init__(name="fivebar-progress", daemon=True)
        self.store = store
        self.period_s = period_s
        self._pending: dict[int, dict[str, Any]] = {}
        self._cv = threading.Condition()
        self._write = threading.Lock()
        self._halt = False

    def put(self, job_id: int, **fields: Any) -> None:
        """Remember the latest progress of a job (written within `period_s`)."""
        with self._cv:
            self._pending.setdefault(job_id, {}).update(fields)

    def flush(self) -> None:
        """Commit what is pending now (after any write already under way)."""
        with self._write:
            with self._cv:
                items, self._pending = self._pending, {}
            for job_id, fields in items.items():
                try:
                    self.store.update(job_id, **fields)
                except Exception:  # pragma: no cover - store closed at shutdown
                    log.exception("could not record the progress of job %d", job_id)

    def stop(self) -> None:
        """Write what is pending and end the thread."""
        with self._cv:
            self._halt = True
            self._cv.notify_all()
        self.join(5.0)

    def run(self) -> None:
        while True:
            with self._cv:
                self._cv.wait(self.period_s)
                stop = self._halt
            self.flush()
            if stop:
                return
