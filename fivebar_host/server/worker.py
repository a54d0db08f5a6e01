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

import logging
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future
from pathlib import Path
from typing import Any

from fivebar_host import protocol
from fivebar_host.job import Job
from fivebar_host.link import LinkError, LinkFaultError
from fivebar_host.sender import (
    Program,
    Progress,
    ResumePoint,
    SendError,
    build_program,
    resume_path,
    run_job,
)
from fivebar_host.server import store as st_
from fivebar_host.server.control import Control
from fivebar_host.server.jobs import JobOptions, SubmitError
from fivebar_host.server.journal import JournalLink
from fivebar_host.server.machine import ActionError, Live
from fivebar_host.server.recovery import Recovery
from fivebar_host.server.store import JobRecord, ResumeRecord, StreamRecord

log = logging.getLogger("fivebar.serve")


class Worker(Control, Recovery):
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
