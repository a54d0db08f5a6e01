"""One job's run on the machine thread: prepare, stream through `run_job`, finish or stop.

A run prepares the job (compiled again if it is not cached; its resume point written from
the database to the private resume file `run_job` reads), parks the arms when they are known
to be elsewhere, and streams it with `run.sender.run_job`, wired to the worker: the journalled
link's stream-start hook commits the stream record once the stream is checked to be the
job's very program; the progress hook keeps the live snapshot and the progress writer up to
date and still stops the machine for a cancel or pause once all lines are sent; the pose
questions are answered by `MachineState._answer`. The run ends done, or — after a fault, a
cancel or a stop — with its resume point copied back into the database and the job held or
cancelled, as its cause calls for (server.worker has the story).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

from fivebar_host import protocol
from fivebar_host.compile import Job
from fivebar_host.compile.model import LayerPause
from fivebar_host.program import Program
from fivebar_host.run.errors import FaultKind, LinkError, LinkFaultError, SendError
from fivebar_host.run.moves import build_program
from fivebar_host.run.overrides import Overrides
from fivebar_host.run.resume import ResumePoint, resume_path
from fivebar_host.run.sender import Progress, SendReport, run_job
from fivebar_host.run.stops import piece_end, planned_time_s
from fivebar_host.server import store as st_
from fivebar_host.server.control import Control
from fivebar_host.server.jobs import JobOptions, SubmitError
from fivebar_host.server.journal import JournalLink
from fivebar_host.server.machine import Live
from fivebar_host.server.store import JobRecord, ResumeRecord, StreamRecord

log = logging.getLogger("fivebar.serve")


@dataclass
class JobRun:
    """One run of a job: what its steps and `run_job`'s hooks share."""

    link: JournalLink
    rec: JobRecord
    job: Job
    opts: JobOptions
    start: int  # first segment of this run
    base: Path  # the drawing path `run_job` keeps its resume file next to
    rpath: Path  # that resume file
    resume: bool
    user_confirm: bool  # the person confirmed the pose with a resume request
    t0: float  # monotonic start of this run
    base_run: float  # run time of the job's earlier runs
    program: tuple[Program, int] | None = None  # the program streamed, its first line
    underruns0: int | None = None  # the firmware's underrun count when the stream began
    progress_saved: float = 0.0  # monotonic time progress was last handed to the writer
    overrides: Overrides = field(default_factory=Overrides)  # live feed/power, this run
    copy: int = 1  # the copy (`copies` option) being drawn (`run_job`'s on_copy)


class JobRunner(Control):
    """The worker's job run (machine thread; see the module docstring)."""

    def _run(self, link: JournalLink, rec: JobRecord) -> None:
        """Run (or resume) one job to its end, a fault, a pause that ends in cancel, or stop."""
        run = self._prepare(link, rec)
        if run is None:
            return
        report = self._stream(run)
        if report is not None:
            self._finish(run, report)

    def _prepare(self, link: JournalLink, rec: JobRecord) -> JobRun | None:
        """Claim the job and write its resume file; None (job failed) if it cannot compile."""
        try:
            job = self._job(rec)
        except SubmitError as e:
            log.error("job %d: %s", rec.id, e)
            self.store.set_state(rec.id, st_.FAILED, message=str(e))
            with self._cv:
                self.current = None
            return None
        opts = JobOptions.from_json(rec.options)
        base = self._resume_base(rec.id)
        rpath = resume_path(base)
        start = rec.resume.next_segment if rec.resume is not None else 0
        if rec.resume is not None:
            ResumePoint(job.file, rec.fingerprint, rec.resume.next_segment, rec.resume.position,
                        rec.resume.reason, job.n_segments, copy=rec.resume.copy).save(rpath)
        else:
            rpath.unlink(missing_ok=True)
        with self._cv:
            self.current = rec.id
            self._question = None
            user_confirm = self._confirm_once.pop(rec.id, False)
        overrides = Overrides()  # each run starts at 100 % (a resumed job too)
        self.live = Live(rec.id, start, job.n_segments, 0.0,
                         float(job.duration_us[start:].sum()) * 1e-6, overrides=overrides)
        self.store.update(rec.id, state=st_.RUNNING, message="", question=None,
                          started_at=rec.started_at or time.time())
        log.info("job %d (%s): %s at segment %d of %d", rec.id, rec.name,
                 "resuming" if rec.resume is not None else "starting", start, job.n_segments)
        return JobRun(link, rec, job, opts, start, base, rpath, rec.resume is not None,
                      user_confirm, time.monotonic(), rec.run_s, overrides=overrides)

    def _stream(self, run: JobRun) -> SendReport | None:
        """Park, then `run_job`; its report, or None once a stop or fault is recorded."""
        link, rec = run.link, run.rec
        # The person's confirmation given with the submission is for the job's first start;
        # after an interruption only the daemon's own record or a resume request answers.
        job_confirm = run.opts.confirm and not run.resume
        try:
            self._motors_on(link)
            if not run.resume:
                self._park(link, run.job)
            link.on_stream_start = partial(self._on_stream_start, run)
            return run_job(link, run.job, self.cfg.profile, drawing=run.base,
                           laser=run.opts.laser,
                           confirm=lambda q: self._answer(link, q, job_confirm,
                                                          run.user_confirm),
                           resume=run.resume, on_progress=partial(self._on_progress, run),
                           should_stop=self._should_stop, on_interrupt=self._on_interrupt,
                           overrides=run.overrides,
                           on_note=lambda text: log.warning("job %d: %s", rec.id, text),
                           on_pause=partial(self._on_pen_change, run),
                           copies=run.opts.copies_plan(), on_wait=partial(self._on_wait, run),
                           on_copy=partial(self._on_copy, run))
        except SendError as e:
            self.progress.flush()  # before the final record, never after it
            self._after_error(run, e)
            return None
        except LinkError as e:
            self.progress.flush()
            self._after_error(run, SendError(str(e)))
            self._disconnected(str(e))
            return None
        finally:
            link.on_stream_start = None
            self.progress.flush()
            with self._cv:
                self.current = None
                self._request = None
            self.live = None
            run.rpath.unlink(missing_ok=True)

    def _finish(self, run: JobRun, report: SendReport) -> None:
        """Record a job that ran to its end."""
        rec, job = run.rec, run.job
        underruns = (max(0, report.final.underruns - run.underruns0 - 1)
                     if run.underruns0 is not None else None)
        self.store.update(rec.id, segments_done=job.n_segments, remaining_s=0.0,
                          run_s=run.base_run + report.elapsed_s, underruns=underruns)
        planned = planned_time_s(job, run.opts.copies_plan())
        self.store.set_state(rec.id, st_.DONE, message=(
            f"done: {report.segments} segments in {report.elapsed_s:.1f} s (planned "
            f"{planned:.1f} s), {report.bytes_sent} bytes sent, {report.resends} "
            f"resends; machine at A = {report.final.a}, B = {report.final.b}"))
        self.cache.drop(rec.id)
        self._set_pose(True, report.final)
        log.info("job %d done in %.1f s (%d resends, %s queue underruns mid-job)", rec.id,
                 report.elapsed_s, report.resends, "?" if underruns is None else underruns)

    # ------------------------------------------------------------------ run_job's hooks
    def _on_stream_start(self, run: JobRun, program: Program, first_line: int) -> None:
        """Commit the stream record, once the stream is checked to be one of the job's
        programs: from the run's start segment, or — after a pen-change stop or for a
        later copy (`run.stops`) — from a stop's segment or segment 0, each ending at the
        next stop (`piece_end`)."""
        st = run.link.last_status
        if st is None:
            return
        starts = dict.fromkeys([run.start, 0, *(p.segment for p in run.job.pauses)])
        for start in starts:
            try:
                prog = build_program(run.job, self.cfg.profile, run.opts.laser, start,
                                     (st.a, st.b), piece_end(run.job, start))
            except SendError:
                continue
            if prog == program:
                break
        else:
            log.debug("job %d: a stream that is not the job's program", run.rec.id)
            return
        self.store.set_stream(run.rec.id, StreamRecord(first_line, start, (st.a, st.b),
                                                       len(program), run.copy))
        run.program = (prog, first_line)
        run.underruns0 = None

    def _on_pen_change(self, run: JobRun, pause: LayerPause) -> bool:
        """A pen-change stop (`run.stops`): the machine is idle with the pen up; the job
        waits in the paused state, its reason naming the layer, until the resume request
        (True) or a cancel or stop (False: `run_job` records the exact resume point)."""
        self.store.set_stream(run.rec.id, None)  # the stream before the stop is over
        return self._wait_paused(run.link, run.rec.id, f"pen change: {pause.describe()}; "
                                 "the pen is up and the machine idle. Change the pen, then "
                                 "resume the job")

    def _on_copy(self, run: JobRun, copy: int) -> None:
        """A copy starts: its streams are recorded as this copy's (crash recovery)."""
        run.copy = copy
        live = self.live
        if live is not None:
            live.copy = copy
            self.on_change()

    def _on_wait(self, run: JobRun, left_s: float) -> None:
        """The page delay between copies: the live view's time left counts it down."""
        live = self.live
        if live is not None:
            live.remaining_s = max(live.remaining_s, left_s)
            self.on_change()

    def _on_progress(self, run: JobRun, p: Progress) -> None:
        """Keep the live snapshot and the recorded progress; stop a drained stream on request."""
        link = run.link
        now = time.monotonic()
        live = self.live
        if live is not None:
            live.segments_done = p.segments_done
            live.elapsed_s = run.base_run + (now - run.t0)
            live.remaining_s = p.remaining_s
            self.on_change()
        st = link.last_status
        if (st is not None and run.underruns0 is None and run.program is not None
                and st.done_line >= run.program[1]):
            run.underruns0 = st.underruns
        if now - run.progress_saved > 0.25:
            run.progress_saved = now
            self.progress.put(run.rec.id, segments_done=p.segments_done,
                              remaining_s=p.remaining_s, run_s=run.base_run + (now - run.t0))
        if not link.streaming:
            # All lines are sent; run_job waits for the machine to finish them. A
            # cancel (or a pause) still has to stop it: hold here, and give up by raising
            # the interrupt fault run_job handles like any other (hold, reset, record).
            req = self._stop_kind()
            if req in ("cancel", "pause"):
                link.realtime(protocol.RT_HOLD)
                if req == "cancel" or not self._wait_paused(link, run.rec.id):
                    raise LinkFaultError(FaultKind.INTERRUPT, f"{link.url}: {self._why()}", -1,
                                         status=link.last_status)
                link.realtime(protocol.RT_RESUME)

    # ------------------------------------------------------------------ after a stop or fault
    def _after_error(self, run: JobRun, e: SendError) -> None:
        """Record where a job stopped and put it in the state its cause calls for."""
        cause = e.__cause__
        kind = cause.kind if isinstance(cause, LinkFaultError) else None
        req = self._stop_kind()
        rp = self._record_stop(run, kind, req)
        if rp is not None and kind not in (None, FaultKind.DISCONNECT):
            self._set_pose(rp.position is not None, run.link.last_status)
        elif kind is FaultKind.DISCONNECT:
            self.pose_known = False
        self._stopped_state(run.rec, rp, req, e)

    def _record_stop(self, run: JobRun, kind: str | None, req: str | None) -> ResumePoint | None:
        """Copy the resume file `run_job` wrote into the database, and the run time."""
        rec = run.rec
        rp: ResumePoint | None = None
        if run.rpath.exists():
            try:
                rp = ResumePoint.load(run.rpath)
            except SendError:
                rp = None
        run_s = run.base_run + (time.monotonic() - run.t0)
        if rp is not None and kind is not None:
            reason = {"terminate": "the daemon was told to stop; the machine ran out of "
                      "queued lines and stopped at a segment boundary",
                      "pause": "paused", "cancel": "cancelled"}.get(
                          req or "", rp.reason) if kind is FaultKind.INTERRUPT else rp.reason
            self.store.set_resume(rec.id, ResumeRecord(rp.next_segment, rp.position, reason,
                                                       rp.copy or 1))
            if kind is not FaultKind.DISCONNECT:
                # run_job reset the firmware (queue cleared, counter back to 0): the line
                # numbers of this stream mean nothing any more; the resume point is exact.
                self.store.set_stream(rec.id, None)
        self.store.update(rec.id, run_s=run_s)
        return rp

    def _stopped_state(self, rec: JobRecord, rp: ResumePoint | None, req: str | None,
                       e: SendError) -> None:
        """Cancel or hold a stopped job, with a message that says where and why."""
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
