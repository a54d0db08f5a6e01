"""The daemon's machine thread: owns the serial link and runs the queue, one job at a time.

Only this thread touches the `Link`. HTTP handlers talk to it through small thread-safe
requests (pause, resume, cancel, home, terminate) and read a snapshot of the machine's last
status report, so hundreds of status requests per second never reach the serial port.

Each job runs through `run.job.run_job` (the same start-pose checks, program, streaming and
fault handling as `fivebar plot --port`), wrapped as follows:

- **Resume points in SQLite.** `run_job` keeps its resume point in a file next to the
  drawing; the daemon passes a private path in its state directory, writes the file from the
  database just before a resumed run, and copies it back into the database after a fault. The
  database is the record; the file lives only for the duration of one `run_job` call.
- **Stream record.** A `JournalLink` (a `Link` subclass) calls back just before a stream's
  first line is written; the daemon rebuilds the program from the job, start segment and start
  position, checks that it is the very program being sent, and commits first line number,
  start segment and start position. After a crash that record plus the firmware's `Ln`
  counter (which survives a daemon crash when the controller is not reset) gives the exact
  segment the machine reached.
- **Pause / cancel / SIGTERM.** `should_stop` makes `Link.stream` hold the machine (`!`,
  laser off at once); `on_interrupt` then waits while paused (polling `?`), resumes (`~`), or
  gives up. Cancel gives up at once (run_job resets the firmware: queue cleared, laser off).
  SIGTERM resumes the hold and lets the firmware run out of queued lines, so the machine stops
  at the end of a segment, laser off (the firmware switches it off when its queue runs empty),
  and only then gives up: the resume point is then a segment boundary.
- **Questions.** `run_job` asks "are the arms at the home pose?" (no endstops) or "still
  where the job stopped?". The daemon answers yes itself only when it knows: its record of
  the pose is valid and the firmware's count already says what the following `G92` would
  set. Otherwise the person's `confirm` answers (given with the job while the daemon does not
  know the pose, or with a resume request), or the job is held with the question.
- **Parking.** Jobs start at the homed pose; when the pose is known but the arms are
  elsewhere (after a cancel), a checked, laser-off travel brings them home first.

The `Worker` class here is the thread's main loop; it is composed of one class per concern,
each in its own module: `machine` (shared state, connecting, the pose record and questions,
the snapshot), `control` (pause / resume / cancel / stop requests and actions, the stop kind
`Link.stream` consults), `jobrun` (one job's run and what follows a fault or stop),
`recovery` (where an interrupted job stopped, after a restart or a lost link), `manual`
(jog, motors off, clear alarm) and `journal` (the journalled link and the progress writer).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any

from fivebar_host.run.errors import LinkError
from fivebar_host.server.jobrun import JobRunner
from fivebar_host.server.journal import JournalLink
from fivebar_host.server.machine import ActionError
from fivebar_host.server.manual import Manual
from fivebar_host.server.recovery import Recovery
from fivebar_host.server.store import JobRecord

log = logging.getLogger("fivebar.serve")


class Worker(JobRunner, Manual, Recovery):
    """The machine thread (see the module docstring)."""

    def run(self) -> None:
        """Connect, recover, then run jobs and actions until told to stop."""
        self.progress.start()
        try:
            self._loop()
        except Exception:  # pragma: no cover - last resort: log, stop the machine
            log.exception("machine thread failed")
            self._emergency_stop()
        finally:
            self.progress.stop()
            self._save_machine()
            if self.link is not None:
                self.link.close()
                self.link = None
            for _, fut in list(self._actions):
                fut.set_exception(ActionError("the daemon stopped"))
            self.finished.set()

    def _loop(self) -> None:
        """Until told to stop: (re)connect, recover once per connection, run an action or a job."""
        while True:
            with self._cv:
                if self._terminate:
                    return
            if self.link is None and not self._connect():
                with self._cv:
                    self._cv.wait(self.cfg.reconnect_s)
                continue
            link = self.link
            assert link is not None
            try:
                if not self._recovered:
                    self._recover(link)
                    self._recovered = True
                if self._run_next_action(link):
                    continue
                rec = self._claim_next()
                if rec is not None:
                    self._run(link, rec)
                    continue
                link.status()
                for push in link.take_alarm_pushes():
                    log.error("machine alarm %d while idle (clear it, or home)", push.code)
            except LinkError as e:
                self._disconnected(str(e))
                continue
            with self._cv:
                if not self._terminate and not self._actions:
                    self._cv.wait(self.cfg.idle_poll_s)

    def _run_next_action(self, link: JournalLink) -> bool:
        """Run the next queued action, if any (its result or exception goes to its future)."""
        action = self._next_action()
        if action is None:
            return False
        fn, fut = action
        if fut.set_running_or_notify_cancel():
            try:
                fut.set_result(fn(link))
            except Exception as e:  # handed to the requester
                fut.set_exception(e)
        return True

    def _next_action(self) -> tuple[Callable[[JournalLink], Any], Future[Any]] | None:
        with self._cv:
            return self._actions.popleft() if self._actions else None

    def _claim_next(self) -> JobRecord | None:
        """The next queued job, now current; None while a job blocks the queue or none waits."""
        # Claim the next job under the lock, so a cancel of it either comes first (it
        # is no longer queued) or finds it running (and stops it).
        with self._cv:
            rec = (None if self.store.blocking() is not None
                   else self.store.next_queued())
            if rec is not None:
                self.current = rec.id
                self._request = None
        return rec
