"""The daemon's machine thread: owns the serial link and runs the queue, one job at a time.

**Threads, and who writes what.**

- The machine thread (`Worker`, this module) alone writes the machine's state: the
  `MachineRecord` (server.state: the connection, whether the pose is trusted, the motors,
  the current job and its live progress, the running job's request, the question waiting
  for a person, the resume confirmations, the stop flags) and the link. Its collaborators —
  `JobRunner` (server.jobrun: one job's run), `JobControl` (server.control: pause, resume,
  cancel, overrides, the stop kind), `Manual` (server.manual: home, jog, pen, motors off,
  clear alarm), `Recovery` (server.recovery: after a restart or a lost link) and
  `PoseKeeper` (server.pose: the pose record, the motors, parking) — run on it, each given
  the record and the services it needs; none inherits from another. After every change it
  publishes an immutable `Snapshot` (server.state) through the `WorkerHandle`.
- HTTP handlers and the daemon's signal handling reach it only through the `WorkerHandle`
  (server.requests): one thread-safe request queue (pause, resume, cancel, overrides, home,
  jog, pen, motors off, clear alarm, terminate, wake), answered through futures where the
  caller needs an answer; they read the last snapshot for status, so hundreds of status
  requests per second never reach the serial port. Submissions, queue order and deletions
  of finished jobs are theirs to write in the database (server.store), which is
  thread-safe; every change of a job's state after it was queued is the machine thread's.
- The progress writer (server.journal) commits a running job's progress on its own thread.

**A job's run.** Each job runs through `run.job.run_job` on fivebar's controller (the same
start-pose checks, program, streaming and fault handling as `fivebar plot --port`), wrapped
as follows:

- **Resume points in SQLite.** The run's resume store is the job's row (server.operator's
  `DatabaseStore`): a resumed run loads its point from there, and the point a stopped run
  saves is recorded there with the cause the machine thread knows.
- **Stream record.** The store commits each stream's first line number, start segment,
  start position and copy before its first line is written. After a crash that record plus
  the firmware's `Ln` counter (which survives a daemon crash when the controller is not
  reset) gives the exact segment the machine reached (server.recovery).
- **Pause / cancel / SIGTERM.** Between lines the stream asks whether to stop (the requests
  waiting are taken first): pause, cancel and a stop hold the machine (`!`, laser off); the
  run then waits while paused (polling `?`), resumes (`~`), or gives up. Cancel gives up at
  once (run_job resets the firmware: queue cleared, laser off). SIGTERM resumes the hold and
  lets the firmware run out of queued lines, so the machine stops at the end of a segment,
  laser off (the firmware switches it off when its queue runs empty), and only then gives
  up: the resume point is then a segment boundary.
- **Questions.** `run_job` asks "are the arms at the home pose?" (no endstops) or "still
  where the job stopped?". The daemon answers yes itself only when it knows: its record of
  the pose is valid and the firmware's count already says what the following `G92` would
  set. Otherwise the person's `confirm` answers (given with the job while the daemon does not
  know the pose, or with a resume request), or the job is held with the question.
- **Parking.** Jobs start at the homed pose; when the pose is known but the arms are
  elsewhere (after a cancel), a checked, laser-off travel brings them home first.
"""

from __future__ import annotations

import contextlib
import logging
import threading

from fivebar_host import protocol
from fivebar_host.controllers.fivebar.controller import FivebarController
from fivebar_host.run.errors import LinkError
from fivebar_host.server.control import JobControl
from fivebar_host.server.jobrun import JobRunner
from fivebar_host.server.journal import JournalLink, ProgressWriter
from fivebar_host.server.manual import Manual
from fivebar_host.server.pose import PoseKeeper
from fivebar_host.server.recovery import Recovery
from fivebar_host.server.requests import (
    Ask,
    JobRequest,
    MachineAction,
    Terminate,
    WorkerHandle,
    refusal,
)
from fivebar_host.server.state import Connection, MachineRecord, Snapshot, WorkerConfig
from fivebar_host.server.store import JobRecord, JobStore
from fivebar_host.server.stored import StoredJobs

log = logging.getLogger("fivebar.serve")


class Worker(threading.Thread):
    """The machine thread (module docstring); `handle` is how other threads reach it."""

    def __init__(self, cfg: WorkerConfig, store: JobStore, jobs: StoredJobs) -> None:
        super().__init__(name="fivebar-machine", daemon=True)
        self.cfg = cfg
        self.store = store
        self.handle = WorkerHandle(cfg.port_url)
        self.record = MachineRecord()
        self.progress = ProgressWriter(store)
        self.pose = PoseKeeper(self.record, store, cfg.profile, self.changed)
        self.control = JobControl(self.record, store, jobs.cache, cfg.drain_timeout_s,
                                  self.poll, self.changed)
        self.manual = Manual(self.record, cfg.profile, self.pose)
        self.runner = JobRunner(self.record, store, jobs, self.progress, self.pose,
                                self.control, self.changed)
        self.recovery = Recovery(store, jobs, cfg.profile, self.pose, cfg.drain_timeout_s,
                                 cfg.auto_resume)

    def changed(self) -> None:
        """Publish the record as it is now (and wake the web page's event streams)."""
        self.handle.publish(Snapshot.of(self.record, self.cfg.port_url))

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
            self.pose.save()
            if self.record.conn is not None:
                self.record.conn.link.close()
                self.record.conn = None
                self.changed()
            self._close_door()

    def _loop(self) -> None:
        """Until told to stop: (re)connect, recover once per connection, answer the requests
        (actions run here, between jobs), run the next job."""
        rec = self.record
        while not rec.terminate:
            if rec.conn is None and not self._connect():
                self.poll(self.cfg.reconnect_s)
                continue
            conn = rec.conn
            assert conn is not None
            try:
                if not rec.recovered:
                    self.recovery.recover(conn.link)
                    rec.recovered = True
                self.poll(0.0)
                if rec.terminate:
                    return
                job = self._claim_next()
                if job is not None:
                    self.runner.run(conn, job)
                    continue
                conn.controller.poll()
                for push in conn.link.take_alarm_pushes():
                    log.error("machine alarm %d while idle (clear it, or home)", push.code)
            except LinkError as e:
                self._disconnected(str(e))
                continue
            self.poll(self.cfg.idle_poll_s)

    # ------------------------------------------------------------------ requests
    def poll(self, timeout_s: float) -> None:
        """Carry out the requests waiting, after waiting up to `timeout_s` for one; each
        answer goes to its future once the record it leaves is published."""
        for ask in self.handle.queue.take(timeout_s):
            self._serve(ask)

    def _serve(self, ask: Ask) -> None:
        req, fut = ask.request, ask.answer
        if fut is not None and not fut.set_running_or_notify_cancel():
            return
        try:
            result = None
            if isinstance(req, JobRequest):
                result = self.control.apply(req)
            elif isinstance(req, MachineAction):
                self.manual.perform(req)
            elif isinstance(req, Terminate):
                self.record.terminate = True
                self.record.hurry = self.record.hurry or req.hurry
        except Exception as e:  # handed to the requester
            self.changed()
            if fut is not None:
                fut.set_exception(e)
            return
        self.changed()
        if fut is not None:
            fut.set_result(result)

    def _close_door(self) -> None:
        """The thread ends: take no more requests; job requests still waiting are carried
        out (they concern the database only now), actions refused."""
        for ask in self.handle.queue.close():
            if isinstance(ask.request, MachineAction) and ask.answer is not None:
                if ask.answer.set_running_or_notify_cancel():
                    ask.answer.set_exception(refusal(ask.request))
            else:
                self._serve(ask)

    def _claim_next(self) -> JobRecord | None:
        """The next queued job, now current; None while a job blocks the queue or none waits.

        Only this thread changes a queued job's state, so a cancel either came first (it is
        no longer queued) or finds it current (and stops it)."""
        job = None if self.store.blocking() is not None else self.store.next_queued()
        if job is not None:
            self.record.current = job.id
            self.record.request = None
            self.changed()
        return job

    # ------------------------------------------------------------------ link
    def _connect(self) -> bool:
        """Open the machine's port; False (and the reason recorded) when it cannot."""
        cfg, rec = self.cfg, self.record
        try:
            opened = JournalLink.open(cfg.port_url, baud=cfg.baud,
                                      banner_timeout_s=cfg.banner_timeout_s,
                                      reply_timeout_s=cfg.reply_timeout_s,
                                      link_baud=cfg.profile.serial.link_baud,
                                      command="fivebar serve", hint=cfg.port_hint)
        except (LinkError, OSError) as e:
            if rec.error != str(e):
                log.warning("cannot open %s: %s (retrying every %g s)", cfg.port_url, e,
                            cfg.reconnect_s)
                rec.error = str(e)
                self.changed()
            return False
        assert isinstance(opened, JournalLink)
        link = opened
        for notice in (link.baud_warning, link.lock and link.lock.note):
            if notice:
                log.warning("%s", notice)
        link.on_status = self.changed
        rec.conn = Connection(link, FivebarController(link, cfg.profile))
        rec.error = None
        st = link.last_status
        assert link.banner is not None and st is not None
        log.info("connected to %s: firmware %s, protocol %d, rx %d bytes, queue %d blocks; "
                 "%s at A = %d, B = %d", cfg.port_url, link.banner.version, link.banner.proto,
                 link.banner.rx, link.banner.queue, st.state, st.a, st.b)
        self.pose.connected(st)
        self.changed()
        return True

    def _disconnected(self, why: str) -> None:
        log.error("link lost: %s", why)
        rec = self.record
        rec.error = why
        if rec.conn is not None:
            rec.conn.link.close()
        rec.conn = None
        rec.recovered = False  # a held job's stream record may be refined on reconnect
        self.changed()

    def _emergency_stop(self) -> None:
        conn = self.record.conn
        if conn is None:
            return
        with contextlib.suppress(Exception):
            conn.link.realtime(protocol.RT_HOLD)
            conn.link.reset()
