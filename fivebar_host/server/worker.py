"""The daemon's machine thread: owns the serial link and runs the queue, one job at a time.

Only this thread touches the `Link`. HTTP handlers talk to it through small thread-safe
requests (pause, resume, cancel, home, terminate) and read a snapshot of the machine's last
status report, so hundreds of status requests per second never reach the serial port.

Each job runs through `sender.run_job` (the same start-pose checks, program, streaming and
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
"""

from __future__ import annotations

import contextlib
import logging
import re
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from concurrent.futures import Future
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fivebar_host import protocol
from fivebar_host.compile import Job
from fivebar_host.config import Profile
from fivebar_host.link import Link, LinkError, LinkFaultError, StreamResult
from fivebar_host.protocol import StatusReport
from fivebar_host.sender import (
    Program,
    Progress,
    ResumePoint,
    SendError,
    build_program,
    home,
    kept_resume_segment,
    resume_path,
    run_job,
    travel_lines,
)
from fivebar_host.server import store as st_
from fivebar_host.server.jobs import CompiledCache, JobOptions, SubmitError, compile_upload
from fivebar_host.server.store import JobRecord, JobStore, ResumeRecord, StreamRecord

log = logging.getLogger("fivebar.serve")

_POSITION_Q = re.compile(r"A = (-?\d+), B = (-?\d+)")


class ActionError(RuntimeError):
    """A machine action (home) that cannot be done now; the message says why."""


class JobStateError(RuntimeError):
    """A job request that does not fit the job's state (e.g. pausing a finished job)."""


class JournalLink(Link):
    """A `Link` that reports when a stream starts and when it last heard a status report."""

    on_stream_start: Callable[[Sequence[str], int], None] | None = None
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

    def stream(self, bodies: Sequence[str], **kwargs: Any) -> StreamResult:
        """`Link.stream`, after telling `on_stream_start` the first line number."""
        hook = self.on_stream_start
        if hook is not None and len(bodies) > 1:
            hook(bodies, self.next_line)
        self.streaming = True
        try:
            return super().stream(bodies, **kwargs)
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


@dataclass(frozen=True)
class WorkerConfig:
    """What the worker needs to reach and drive the machine."""

    port_url: str
    profile: Profile
    state_dir: Path
    baud: int
    banner_timeout_s: float
    reply_timeout_s: float
    reconnect_s: float = 2.0
    idle_poll_s: float = 0.25
    auto_resume: bool = False
    drain_timeout_s: float = 120.0


@dataclass
class Live:
    """Progress of the running job, updated on every reply and status report."""

    job_id: int
    segments_done: int
    segments_total: int
    elapsed_s: float
    remaining_s: float
    paused: bool = False


class Worker(threading.Thread):
    """The machine thread (see the module docstring)."""

    def __init__(self, cfg: WorkerConfig, store: JobStore, cache: CompiledCache) -> None:
        super().__init__(name="fivebar-machine", daemon=True)
        self.cfg = cfg
        self.store = store
        self.cache = cache
        self._cv = threading.Condition()
        self._terminate = False
        self._hurry = False
        self._request: str | None = None  # for the running job: pause, resume, cancel
        self._confirm_once: dict[int, bool] = {}
        self._actions: deque[tuple[Callable[[JournalLink], Any], Future[Any]]] = deque()
        self.link: JournalLink | None = None
        self.error: str | None = "not connected yet"
        self.current: int | None = None
        self.live: Live | None = None
        self.pose_known = False
        self.finished = threading.Event()
        self._question: str | None = None
        self._recovered = False
        self.progress = ProgressWriter(store)

    # ================================================================== requests (any thread)
    def notify(self) -> None:
        """Something was queued: look at the queue now."""
        with self._cv:
            self._cv.notify_all()

    def terminate(self, hurry: bool = False) -> None:
        """Stop: the running job stops at a segment boundary (or at once with `hurry`)."""
        with self._cv:
            self._terminate = True
            self._hurry = self._hurry or hurry
            self._cv.notify_all()

    def pause(self, job_id: int) -> None:
        """Hold the running job (laser off at once)."""
        with self._cv:
            if self.current != job_id:
                raise JobStateError(f"job {job_id} is not running")
            if self._request not in ("cancel",):
                self._request = "pause"
            self._cv.notify_all()

    def resume(self, job_id: int, confirm: bool = False) -> None:
        """Continue a paused job, or requeue a held one (at the head of the queue)."""
        with self._cv:
            if self.current == job_id:
                if self._request == "pause" or (self.live is not None and self.live.paused):
                    self._request = "resume"
                    self._cv.notify_all()
                    return
                raise JobStateError(f"job {job_id} is running, not paused")
            rec = self.store.get(job_id)
            if rec is None:
                raise KeyError(job_id)
            if rec.state != st_.HELD:
                raise JobStateError(f"job {job_id} is {rec.state}: only a paused or held job "
                                    "can be resumed")
            self._confirm_once[job_id] = confirm
            self.store.set_state(job_id, st_.QUEUED, message="resume requested")
            self._cv.notify_all()

    def cancel(self, job_id: int) -> None:
        """Cancel a job: the running one stops at once (laser off); others leave the queue."""
        with self._cv:
            if self.current == job_id:
                self._request = "cancel"
                self._cv.notify_all()
                return
            rec = self.store.get(job_id)
            if rec is None:
                raise KeyError(job_id)
            if rec.state in st_.FINAL_STATES:
                raise JobStateError(f"job {job_id} is already {rec.state}")
            self.store.set_state(job_id, st_.CANCELLED, message="cancelled before it ran"
                                 if rec.state == st_.QUEUED and rec.resume is None
                                 else "cancelled while held")
            self.cache.drop(job_id)
            self._cv.notify_all()

    def run_action(self, fn: Callable[[JournalLink], Any], timeout_s: float) -> Any:
        """Run `fn(link)` on the machine thread between jobs; its result or its exception."""
        fut: Future[Any] = Future()
        with self._cv:
            if self._terminate:
                raise ActionError("the daemon is stopping")
            self._actions.append((fn, fut))
            self._cv.notify_all()
        return fut.result(timeout=timeout_s)

    def home(self, at_home: bool, timeout_s: float = 180.0) -> StatusReport:
        """Home the machine: `$H` with endstops, else `G92 A0 B0` once the person confirms."""
        def act(link: JournalLink) -> StatusReport:
            if self.current is not None:
                raise ActionError(f"job {self.current} is running: cancel it before homing")
            if not self.cfg.profile.motors.endstops and not at_home:
                raise ActionError("the machine has no endstops: place the arms at the home pose "
                                  "and confirm with at_home=true")
            home(link, self.cfg.profile, lambda q: at_home)
            st = link.wait_idle(120.0)
            self._set_pose(True, st)
            return st

        if self.link is None:
            raise ActionError(f"the machine is not connected ({self.error})")
        result: StatusReport = self.run_action(act, timeout_s)
        return result

    # ================================================================== snapshot (any thread)
    def machine(self) -> dict[str, Any]:
        """What is known about the machine now (no serial traffic)."""
        link = self.link
        st = link.last_status if link is not None else None
        banner = link.banner if link is not None else None
        return {
            "connected": link is not None,
            "port": self.cfg.port_url,
            "error": self.error,
            "firmware": None if banner is None else {
                "version": banner.version, "protocol": banner.proto, "rx_bytes": banner.rx,
                "queue_blocks": banner.queue, "line_bytes": banner.line_max},
            "state": None if st is None else st.state,
            "detail": None if st is None else st.detail,
            "position": None if st is None else {"a": st.a, "b": st.b},
            "laser": None if st is None else st.laser,
            "queued_blocks": None if st is None else st.queued,
            "done_line": None if st is None else st.done_line,
            "accepted_line": None if st is None else st.accepted_line,
            "underruns": None if st is None else st.underruns,
            "pose_known": self.pose_known,
            "status_age_s": None if link is None or st is None
            else round(time.monotonic() - link.status_at, 3),
        }

    # ================================================================== the thread
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
                action = self._next_action()
                if action is not None:
                    fn, fut = action
                    if fut.set_running_or_notify_cancel():
                        try:
                            fut.set_result(fn(link))
                        except Exception as e:  # handed to the requester
                            fut.set_exception(e)
                    continue
                # Claim the next job under the lock, so a cancel of it either comes first (it
                # is no longer queued) or finds it running (and stops it).
                with self._cv:
                    rec = (None if self.store.blocking() is not None
                           else self.store.next_queued())
                    if rec is not None:
                        self.current = rec.id
                        self._request = None
                if rec is not None:
                    self._run(link, rec)
                    continue
                link.status()
            except LinkError as e:
                self._disconnected(str(e))
                continue
            with self._cv:
                if not self._terminate and not self._actions:
                    self._cv.wait(self.cfg.idle_poll_s)

    def _next_action(self) -> tuple[Callable[[JournalLink], Any], Future[Any]] | None:
        with self._cv:
            return self._actions.popleft() if self._actions else None

    # ------------------------------------------------------------------ link
    def _connect(self) -> bool:
        cfg = self.cfg
        try:
            opened = JournalLink.open(cfg.port_url, baud=cfg.baud,
                                      banner_timeout_s=cfg.banner_timeout_s,
                                      reply_timeout_s=cfg.reply_timeout_s)
        except (LinkError, OSError) as e:
            if self.error != str(e):
                log.warning("cannot open %s: %s (retrying every %g s)", cfg.port_url, e,
                            cfg.reconnect_s)
            self.error = str(e)
            return False
        assert isinstance(opened, JournalLink)
        link = opened
        self.link = link
        self.error = None
        st = link.last_status
        assert link.banner is not None and st is not None
        log.info("connected to %s: firmware %s, protocol %d, rx %d bytes, queue %d blocks; "
                 "%s at A = %d, B = %d", cfg.port_url, link.banner.version, link.banner.proto,
                 link.banner.rx, link.banner.queue, st.state, st.a, st.b)
        # The pose the daemon recorded still holds if this is the same firmware session: its
        # line counter only grows until a reset or reboot (which also zero it). H:1 says the
        # firmware itself knows its position (kept across a reset; lost at power-on).
        facts = self.store.machine()
        rec_line = int(facts.get("accepted_line", 0) or 0)
        same_session = bool(facts.get("pose_known")) and 0 < rec_line <= st.accepted_line
        self.pose_known = (st.homed or same_session) and st.state != "Alarm"
        log.info("machine pose %s", "known (same controller session as before)"
                 if self.pose_known else "unknown until homed or confirmed")
        return True

    def _disconnected(self, why: str) -> None:
        log.error("link lost: %s", why)
        self.error = why
        if self.link is not None:
            self.link.close()
        self.link = None
        self._recovered = False  # a held job's stream record may be refined on reconnect

    def _set_pose(self, known: bool, st: StatusReport | None) -> None:
        """Record whether the position is trusted, with the controller's line counter.

        A reset zeroes the counter, and so does a reboot; a restarted daemon trusts its record
        only when the counter is at least the recorded one and not zero. So after a reset
        one harmless numbered line (`G90`) marks the controller session as this one's."""
        self.pose_known = known
        link = self.link
        if known and link is not None and st is not None and st.accepted_line == 0:
            try:
                link.command("G90")
                st = link.status()
            except LinkError as e:
                log.warning("could not mark the controller session: %s", e)
        self._save_machine(st)

    def _save_machine(self, st: StatusReport | None = None) -> None:
        link = self.link
        st = st or (link.last_status if link is not None else None)
        try:
            if st is None:
                self.store.set_machine(pose_known=self.pose_known)
            else:
                self.store.set_machine(pose_known=self.pose_known,
                                       accepted_line=st.accepted_line, position=[st.a, st.b])
        except Exception:  # pragma: no cover - closing store at shutdown
            log.exception("could not record the machine state")

    def _emergency_stop(self) -> None:
        link = self.link
        if link is None:
            return
        with contextlib.suppress(Exception):
            link.realtime(protocol.RT_HOLD)
            link.reset()

    # ------------------------------------------------------------------ jobs
    def _job(self, rec: JobRecord) -> Job:
        """The compiled job of a record (cached, or compiled again from its upload)."""
        job = self.cache.get(rec.id)
        if job is not None:
            return job
        data = self.store.upload(rec.id)
        if data is None:
            raise SubmitError("gone", f"job {rec.id}: its upload is no longer stored")
        compiled = compile_upload(data, rec.name, JobOptions.from_json(rec.options),
                                  self.cfg.profile)
        if compiled.fingerprint != rec.fingerprint:
            raise SubmitError("changed", f"job {rec.id}: compiling it again gives a different "
                              "job (the daemon's profile or program changed since it was "
                              "submitted); submit it again")
        self.cache.put(rec.id, compiled.job)
        return compiled.job

    def _resume_base(self, job_id: int) -> Path:
        d = self.cfg.state_dir / "resume"
        d.mkdir(mode=0o700, exist_ok=True)
        return d / f"job-{job_id}"

    def _run(self, link: JournalLink, rec: JobRecord) -> None:
        """Run (or resume) one job to its end, a fault, a pause that ends in cancel, or stop."""
        try:
            job = self._job(rec)
        except SubmitError as e:
            log.error("job %d: %s", rec.id, e)
            self.store.set_state(rec.id, st_.FAILED, message=str(e))
            with self._cv:
                self.current = None
            return
        opts = JobOptions.from_json(rec.options)
        prof = self.cfg.profile
        base = self._resume_base(rec.id)
        rpath = resume_path(base)
        resume = rec.resume is not None
        start = rec.resume.next_segment if rec.resume is not None else 0
        if rec.resume is not None:
            ResumePoint(job.file, rec.fingerprint, rec.resume.next_segment, rec.resume.position,
                        rec.resume.reason, job.n_segments).save(rpath)
        else:
            rpath.unlink(missing_ok=True)
        with self._cv:
            self.current = rec.id
            self._question = None
            user_confirm = self._confirm_once.pop(rec.id, False)
        self.live = Live(rec.id, start, job.n_segments, 0.0,
                         float(job.duration_us[start:].sum()) * 1e-6)
        self.store.update(rec.id, state=st_.RUNNING, message="", question=None,
                          started_at=rec.started_at or time.time())
        log.info("job %d (%s): %s at segment %d of %d", rec.id, rec.name,
                 "resuming" if resume else "starting", start, job.n_segments)
        t0 = time.monotonic()
        base_run = rec.run_s
        u0: list[int] = []
        progress_saved = [0.0]
        prog_box: list[tuple[Program, int]] = []

        def on_stream_start(bodies: Sequence[str], first_line: int) -> None:
            st = link.last_status
            if st is None or prog_box:
                return
            try:
                prog = build_program(job, prof, opts.laser, start, (st.a, st.b))
            except SendError:
                return
            if prog.bodies != list(bodies):
                log.debug("job %d: a stream that is not the job's program", rec.id)
                return
            self.store.set_stream(rec.id, StreamRecord(first_line, start, (st.a, st.b),
                                                       len(bodies)))
            prog_box.append((prog, first_line))

        def on_progress(p: Progress) -> None:
            now = time.monotonic()
            live = self.live
            if live is not None:
                live.segments_done = p.segments_done
                live.elapsed_s = base_run + (now - t0)
                live.remaining_s = p.remaining_s
            st = link.last_status
            if st is not None and not u0 and prog_box and st.done_line >= prog_box[0][1]:
                u0.append(st.underruns)
            if now - progress_saved[0] > 0.25:
                progress_saved[0] = now
                self.progress.put(rec.id, segments_done=p.segments_done,
                                  remaining_s=p.remaining_s, run_s=base_run + (now - t0))
            if not link.streaming:
                # All lines are sent; run_job waits for the machine to finish them. A
                # cancel (or a pause) still has to stop it: hold here, and give up by raising
                # the interrupt fault run_job handles like any other (hold, reset, record).
                req = self._stop_kind()
                if req in ("cancel", "pause"):
                    link.realtime(protocol.RT_HOLD)
                    if req == "cancel" or not self._wait_paused(link, rec.id):
                        raise LinkFaultError("interrupt", f"{link.url}: {self._why()}", -1,
                                             status=link.last_status)
                    link.realtime(protocol.RT_RESUME)

        # The person's confirmation given with the submission is for the job's first start;
        # after an interruption only the daemon's own record or a resume request answers.
        job_confirm = opts.confirm and not resume
        try:
            if not resume:
                self._park(link, job)
            link.on_stream_start = on_stream_start
            report = run_job(link, job, prof, drawing=base, laser=opts.laser,
                             confirm=lambda q: self._answer(link, q, job_confirm, user_confirm),
                             resume=resume, on_progress=on_progress,
                             should_stop=self._should_stop, on_interrupt=self._on_interrupt,
                             on_note=lambda text: log.warning("job %d: %s", rec.id, text))
        except SendError as e:
            self.progress.flush()  # before the final record, never after it
            self._after_error(link, rec, job, e, rpath, t0, base_run)
            return
        except LinkError as e:
            self.progress.flush()
            self._after_error(link, rec, job, SendError(str(e)), rpath, t0, base_run)
            self._disconnected(str(e))
            return
        finally:
            link.on_stream_start = None
            self.progress.flush()
            with self._cv:
                self.current = None
                self._request = None
            self.live = None
            rpath.unlink(missing_ok=True)
        underruns = max(0, report.final.underruns - u0[0] - 1) if u0 else None
        self.store.update(rec.id, segments_done=job.n_segments, remaining_s=0.0,
                          run_s=base_run + report.elapsed_s, underruns=underruns)
        self.store.set_state(rec.id, st_.DONE, message=(
            f"done: {report.segments} segments in {report.elapsed_s:.1f} s (planned "
            f"{job.total_time_s:.1f} s), {report.bytes_sent} bytes sent, {report.resends} "
            f"resends; machine at A = {report.final.a}, B = {report.final.b}"))
        self.cache.drop(rec.id)
        self._set_pose(True, report.final)
        log.info("job %d done in %.1f s (%d resends, %s queue underruns mid-job)", rec.id,
                 report.elapsed_s, report.resends, "?" if underruns is None else underruns)

    def _after_error(self, link: JournalLink, rec: JobRecord, job: Job, e: SendError,
                     rpath: Path, t0: float, base_run: float) -> None:
        """Record where a job stopped and put it in the state its cause calls for."""
        cause = e.__cause__
        kind = cause.kind if isinstance(cause, LinkFaultError) else None
        req = self._stop_kind()
        rp: ResumePoint | None = None
        if rpath.exists():
            try:
                rp = ResumePoint.load(rpath)
            except SendError:
                rp = None
        run_s = base_run + (time.monotonic() - t0)
        if rp is not None and kind is not None:
            reason = {"terminate": "the daemon was told to stop; the machine ran out of "
                      "queued lines and stopped at a segment boundary",
                      "pause": "paused", "cancel": "cancelled"}.get(
                          req or "", rp.reason) if kind == "interrupt" else rp.reason
            self.store.set_resume(rec.id, ResumeRecord(rp.next_segment, rp.position, reason))
            if kind != "disconnect":
                # run_job reset the firmware (queue cleared, counter back to 0): the line
                # numbers of this stream mean nothing any more; the resume point is exact.
                self.store.set_stream(rec.id, None)
        self.store.update(rec.id, run_s=run_s)
        if rp is not None and kind not in (None, "disconnect"):
            self._set_pose(rp.position is not None, link.last_status)
        elif kind == "disconnect":
            self.pose_known = False
        where = (f"segment {rp.next_segment} of {rp.segments}, "
                 + (f"A = {rp.position[0]}, B = {rp.position[1]}" if rp and rp.position
                    else "position unknown")) if rp is not None else ""
        text = "\n".join(ln for ln in str(e).splitlines() if not ln.startswith("resume file:"))
        if req == "cancel":
            self.store.set_state(rec.id, st_.CANCELLED,
                                 message=f"cancelled at {where}; laser off (held and reset)")
            self.cache.drop(rec.id)
            log.info("job %d cancelled at %s", rec.id, where)
        elif req == "terminate":
            self.store.set_state(rec.id, st_.HELD, message=(
                f"stopped when the daemon was told to stop, at {where}; laser off. Resume it "
                "with POST /api/jobs/{}/resume".format(rec.id)))
            log.info("job %d stopped for shutdown at %s", rec.id, where)
        elif self._question is not None:
            self.store.set_state(rec.id, st_.HELD, question=self._question, message=(
                f"waiting for a person: {self._question} Answer by resuming the job with "
                "confirm=true once it is so (nothing has moved)."))
            log.warning("job %d held: %s", rec.id, self._question)
        else:
            self.store.set_state(rec.id, st_.HELD, message=text + (
                f"\nresume it with POST /api/jobs/{rec.id}/resume" if rp is not None else ""))
            log.error("job %d held after a fault: %s", rec.id, text.replace("\n", " | "))

    # ------------------------------------------------------------------ stop, pause, cancel
    def _stop_kind(self) -> str | None:
        with self._cv:
            if self._terminate:
                return "terminate"
            return self._request

    def _why(self) -> str:
        kind = self._stop_kind()
        return {"cancel": "job cancelled", "terminate": "the daemon is stopping",
                "pause": "paused"}.get(kind or "", "interrupted")

    def _should_stop(self) -> bool:
        return self._stop_kind() in ("pause", "cancel", "terminate")

    def _on_interrupt(self) -> bool:
        """Called by `Link.stream` with the machine held: True resumes, False gives up."""
        link = self.link
        assert link is not None
        kind = self._stop_kind()
        if kind == "terminate":
            self._drain(link)
            return False
        if kind == "cancel":
            return False
        current = self.current
        assert current is not None
        return self._wait_paused(link, current)

    def _wait_paused(self, link: JournalLink, job_id: int) -> bool:
        """Stay held until resume (True), cancel or stop (False); keeps polling `?`."""
        if self.live is not None:
            self.live.paused = True
        self.store.set_state(job_id, st_.PAUSED, message="paused: held, laser off")
        log.info("job %d paused", job_id)
        try:
            while True:
                kind = self._stop_kind()
                if kind in ("cancel", "terminate"):
                    return False
                if kind == "resume":
                    with self._cv:
                        self._request = None
                    self.store.set_state(job_id, st_.RUNNING, message="")
                    log.info("job %d resumed", job_id)
                    return True
                link.status()
                with self._cv:
                    self._cv.wait(0.2)
        finally:
            if self.live is not None:
                self.live.paused = False

    def _drain(self, link: JournalLink) -> None:
        """Let the held machine run out of queued lines: it stops at a segment's end."""
        link.realtime(protocol.RT_RESUME)
        deadline = time.monotonic() + self.cfg.drain_timeout_s
        while time.monotonic() < deadline:
            with self._cv:
                if self._hurry:
                    log.warning("stopping at once (second signal): the machine holds "
                                "inside a segment")
                    return
            st = link.status()
            if st.state != "Run" and st.queued == 0:
                return
            time.sleep(0.05)
        log.warning("the machine did not run out of queued lines within %g s; holding it",
                    self.cfg.drain_timeout_s)

    # ------------------------------------------------------------------ pose
    def _answer(self, link: JournalLink, question: str, job_confirm: bool,
                person_confirm: bool) -> bool:
        """Answer run_job's pose question (module docstring: Questions)."""
        st = link.last_status
        target: tuple[int, int] | None = None
        if "home pose" in question:
            target = (0, 0)
        else:
            m = _POSITION_Q.search(question)
            if m:
                target = (int(m.group(1)), int(m.group(2)))
        if (self.pose_known and target is not None and st is not None
                and (st.a, st.b) == target):
            log.info("%s yes (the daemon's record and the firmware's count agree)", question)
            self._question = None
            return True
        if person_confirm or (job_confirm and not self.pose_known):
            log.info("%s yes (confirmed by the person who %s the job)", question,
                     "resumed" if person_confirm else "submitted")
            self.pose_known = True
            self._question = None
            return True
        self._question = question
        return False

    def _park(self, link: JournalLink, job: Job) -> None:
        """Bring the arms to the homed pose (checked, laser off) when known to be elsewhere."""
        st = link.status()
        if not self.pose_known or (st.a, st.b) == (0, 0) or st.state != "Idle":
            return
        lines = travel_lines(self.cfg.profile, job.assembly, (st.a, st.b), (0, 0),
                             "park the arms at the home pose before the next job")
        log.info("parking: travel from A = %d, B = %d to the home pose", st.a, st.b)
        res = link.stream(["G90", "M5", *lines])
        link.wait_idle(max(30.0, 3.0 * res.elapsed_s), last_line=res.last_line)

    # ------------------------------------------------------------------ crash recovery
    def _recover(self, link: JournalLink) -> None:
        """After (re)connecting: settle jobs a crash or a lost link left unfinished."""
        for rec in self.store.list(states=(st_.RUNNING, st_.PAUSED)):
            self._recover_job(link, rec)
        for rec in self.store.list(states=(st_.HELD,)):
            if rec.stream is not None:
                self._recover_job(link, rec)
        if self.cfg.auto_resume:
            for rec in self.store.list(states=(st_.HELD,)):
                if rec.resume is not None and rec.question is None:
                    log.info("job %d: resuming automatically (--auto-resume)", rec.id)
                    self.store.set_state(rec.id, st_.QUEUED, message="resumed automatically")

    def _settle(self, link: JournalLink) -> StatusReport:
        """Wait while the controller still runs lines it was given before the host died."""
        deadline = time.monotonic() + self.cfg.drain_timeout_s
        st = link.status()
        while st.state == "Run" and time.monotonic() < deadline:
            time.sleep(0.05)
            st = link.status()
        return st

    def _recover_job(self, link: JournalLink, rec: JobRecord) -> None:
        """Work out exactly where an interrupted job stopped and hold it there."""
        try:
            job = self._job(rec)
        except SubmitError as e:
            self.store.set_state(rec.id, st_.FAILED, message=str(e))
            return
        opts = JobOptions.from_json(rec.options)
        stream = rec.stream
        st = link.status()
        exact: ResumeRecord | None = None
        not_reset = stream is not None and (
            stream.first_line <= st.accepted_line <= stream.first_line + stream.lines - 1)
        if not_reset:
            # The controller was not reset: it kept the lines it had and its line counter.
            st = self._settle(link)
        if stream is not None and (not_reset or st.homed):
            try:
                prog: Program | None = build_program(
                    job, self.cfg.profile, opts.laser, stream.start_segment,
                    stream.start_position)
            except SendError as e:  # the profile's limits changed: no exact mapping
                log.warning("job %d: cannot rebuild its program (%s)", rec.id, e)
                prog = None
            if prog is not None and len(prog.bodies) == stream.lines and st.state != "Alarm":
                if not_reset:
                    if st.state == "Hold" or st.queued:
                        link.reset()  # clears what is queued; position kept, laser off
                    nxt: int | None = prog.finished_segments(stream.first_line, st.done_line,
                                                             stream.start_segment)
                    why = "the controller kept its count"
                elif st.state == "Idle" and not st.queued:
                    # Reset since (opening the port resets an Arduino): it kept its position,
                    # H and the last line it executed (docs/protocol.md 7).
                    floor = (rec.resume.next_segment if rec.resume is not None
                             else rec.segments_done)
                    nxt, why = kept_resume_segment(prog, stream.first_line,
                                                   stream.start_segment,
                                                   stream.start_position, st, floor)
                    if nxt is None:
                        log.warning("job %d: the controller's kept record is not its stream's "
                                    "(%s)", rec.id, why)
                    why = "the controller kept its position and count across its reset"
                else:
                    nxt = None
                if nxt is not None:
                    exact = ResumeRecord(nxt, (st.a, st.b),
                                         f"the daemon lost the machine mid-job; {why} (last "
                                         f"line executed {st.done_line})")
                    self._set_pose(True, link.last_status)
        if exact is not None:
            resume = exact
        elif rec.resume is not None:
            resume = rec.resume
        elif rec.segments_done == 0 and stream is None:
            self.store.set_state(rec.id, st_.QUEUED, message="requeued: the daemon stopped "
                                 "before the job started drawing")
            log.warning("job %d: requeued (the daemon stopped before it started drawing)",
                        rec.id)
            return
        else:
            resume = ResumeRecord(rec.segments_done, None,
                                  "the daemon lost the machine mid-job and the controller was "
                                  "reset: position unknown; segments after the last one the "
                                  "daemon saw finish may be drawn again")
        self.store.set_stream(rec.id, None)
        if resume.next_segment >= job.n_segments:
            self.store.set_resume(rec.id, None)
            self.store.update(rec.id, segments_done=job.n_segments, remaining_s=0.0)
            self.store.set_state(rec.id, st_.DONE,
                                 message="done (finished while the daemon was away)")
            log.info("job %d: finished while the daemon was away", rec.id)
            return
        self.store.set_resume(rec.id, resume)
        remaining = float(np.asarray(job.duration_us[resume.next_segment:]).sum()) * 1e-6
        self.store.update(rec.id, remaining_s=remaining)
        where = (f"A = {resume.position[0]}, B = {resume.position[1]}" if resume.position
                 else "position unknown: home the machine (or confirm) before resuming")
        self.store.set_state(rec.id, st_.HELD, message=(
            f"interrupted ({resume.reason}); resume point: segment {resume.next_segment} of "
            f"{job.n_segments}, {where}. Resume it with POST /api/jobs/{rec.id}/resume"))
        log.warning("job %d recovered: next segment %d of %d (%s)", rec.id,
                    resume.next_segment, job.n_segments, where)
