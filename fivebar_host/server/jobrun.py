"""One job's run on the machine thread: prepare, stream through `run_job`, finish or stop.

`JobRunner` is the worker's collaborator for one job at a time. A run prepares the job
(compiled again if it is not cached, `server.stored`), records it as the machine thread's
current job with its live progress, parks the arms when they are known to be elsewhere,
and runs it with `run.job.run_job` on the connection's fivebar controller, with the
daemon's operator and resume store (`server.operator`): the store commits the stream record
as each stream starts and loads the resume point from the job's row; the operator's
progress keeps the live progress and the progress writer up to date and still stops the
machine for a cancel or pause once all lines are sent; the pose questions are answered by
`PoseKeeper.answer`, the stop requests by `JobControl`. The run ends done, or — after a
fault, a cancel or a stop — with its resume point recorded in the database and the job held
or cancelled, as its cause calls for (server.worker has the story). A broken link is
recorded like any fault and then raised again, for the worker to reconnect.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from fivebar_host import protocol
from fivebar_host.compile import Job
from fivebar_host.compile.model import LayerPause
from fivebar_host.run.errors import FaultKind, LinkError, LinkFaultError, SendError
from fivebar_host.run.job import RunOptions, RunReport, run_job
from fivebar_host.run.operator import Progress
from fivebar_host.run.overrides import Overrides
from fivebar_host.run.resume import ResumePoint
from fivebar_host.run.stops import planned_time_s
from fivebar_host.server import store as st_
from fivebar_host.server.control import JobControl
from fivebar_host.server.jobs import JobOptions, SubmitError
from fivebar_host.server.journal import ProgressWriter
from fivebar_host.server.operator import DaemonOperator, DatabaseStore
from fivebar_host.server.pose import PoseKeeper
from fivebar_host.server.state import Connection, Live, MachineRecord
from fivebar_host.server.store import JobRecord, JobStore, ResumeRecord
from fivebar_host.server.stored import StoredJobs

log = logging.getLogger("fivebar.serve")


@dataclass
class JobRun:
    """One run of a job: what its steps and `run_job`'s hooks share."""

    conn: Connection
    rec: JobRecord
    job: Job
    opts: JobOptions
    start: int  # first segment of this run
    resume: bool
    user_confirm: bool  # the person confirmed the pose with a resume request
    t0: float  # monotonic start of this run
    base_run: float  # run time of the job's earlier runs
    first_line: int | None = None  # the first line number of the stream now running
    underruns0: int | None = None  # the firmware's underrun count when the stream began
    progress_saved: float = 0.0  # monotonic time progress was last handed to the writer
    overrides: Overrides = field(default_factory=Overrides)  # live feed/power, this run
    copy: int = 1  # the copy (`copies` option) being drawn (`Operator.copy_started`)
    saved: ResumePoint | None = None  # where the run stopped, when it stopped early


class JobRunner:
    """The worker's job run (module docstring); machine thread only. Writes the record's
    current job, live progress and question; `changed` publishes the record."""

    def __init__(self, record: MachineRecord, store: JobStore, jobs: StoredJobs,
                 progress: ProgressWriter, pose: PoseKeeper, control: JobControl,
                 changed: Callable[[], None]) -> None:
        self.record = record
        self.store = store
        self.jobs = jobs
        self.progress = progress
        self.pose = pose
        self.control = control
        self.changed = changed

    def run(self, conn: Connection, rec: JobRecord) -> None:
        """Run (or resume) one job to its end, a fault, a pause that ends in cancel, or stop."""
        run = self._prepare(conn, rec)
        if run is None:
            return
        report = self._stream(run)
        if report is not None:
            self._finish(run, report)

    def _prepare(self, conn: Connection, rec: JobRecord) -> JobRun | None:
        """Make the job current with its live progress; None (job failed) if it cannot
        compile."""
        try:
            job = self.jobs.job(rec)
        except SubmitError as e:
            log.error("job %d: %s", rec.id, e)
            self.store.set_state(rec.id, st_.FAILED, message=str(e))
            self.record.current = None
            self.changed()
            return None
        opts = JobOptions.from_json(rec.options)
        start = rec.resume.next_segment if rec.resume is not None else 0
        state = self.record
        state.current = rec.id
        state.question = None
        user_confirm = state.confirm_once.pop(rec.id, False)
        overrides = Overrides()  # each run starts at 100 % (a resumed job too)
        state.live = Live(rec.id, start, job.n_segments, 0.0,
                          float(job.duration_us[start:].sum()) * 1e-6, overrides=overrides)
        self.changed()
        self.store.update(rec.id, state=st_.RUNNING, message="", question=None,
                          started_at=rec.started_at or time.time())
        log.info("job %d (%s): %s at segment %d of %d", rec.id, rec.name,
                 "resuming" if rec.resume is not None else "starting", start, job.n_segments)
        return JobRun(conn, rec, job, opts, start, rec.resume is not None, user_confirm,
                      time.monotonic(), rec.run_s, overrides=overrides)

    def _stream(self, run: JobRun) -> RunReport | None:
        """Park, then `run_job`; its report, or None once a stop or fault is recorded (a
        broken link is raised again once recorded)."""
        conn = run.conn
        store = DatabaseStore(self.store, run)
        try:
            self.pose.motors_on(conn.link)
            if not run.resume:
                self.pose.park(conn, run.job)
            return run_job(conn.controller, run.job,
                           DaemonOperator(self, self.control, self.pose, run), store,
                           RunOptions(run.opts.laser, run.resume, run.opts.copies_plan(),
                                      run.overrides))
        except SendError as e:
            self.progress.flush()  # before the final record, never after it
            self._after_error(run, e)
            return None
        except LinkError as e:
            self.progress.flush()
            self._after_error(run, SendError(str(e)))
            raise
        finally:
            self.progress.flush()
            self.record.current = None
            self.record.request = None
            self.record.live = None
            self.changed()

    def _finish(self, run: JobRun, report: RunReport) -> None:
        """Record a job that ran to its end."""
        rec, job = run.rec, run.job
        final = run.conn.link.last_status
        underruns = (max(0, final.underruns - run.underruns0 - 1)
                     if run.underruns0 is not None and final is not None else None)
        self.store.update(rec.id, segments_done=job.n_segments, remaining_s=0.0,
                          run_s=run.base_run + report.elapsed_s, underruns=underruns)
        planned = planned_time_s(job, run.opts.copies_plan())
        self.store.set_state(rec.id, st_.DONE, message=(
            f"done: {report.segments} segments in {report.elapsed_s:.1f} s (planned "
            f"{planned:.1f} s), {report.bytes_sent} bytes sent, {report.resends} "
            f"resends; machine at A = {report.final[0]}, B = {report.final[1]}"))
        self.jobs.cache.drop(rec.id)
        self.pose.set(True, final)
        log.info("job %d done in %.1f s (%d resends, %s queue underruns mid-job)", rec.id,
                 report.elapsed_s, report.resends, "?" if underruns is None else underruns)

    # ------------------------------------------------------------------ the operator's answers
    def on_pen_change(self, run: JobRun, pause: LayerPause) -> bool:
        """A pen-change stop (`run.stops`): the machine is idle with the pen up; the job
        waits in the paused state, its reason naming the layer, until the resume request
        (True) or a cancel or stop (False: `run_job` records the exact resume point)."""
        self.store.set_stream(run.rec.id, None)  # the stream before the stop is over
        return self.control.wait_paused(run.conn, run.rec.id, f"pen change: "
                                        f"{pause.describe()}; the pen is up and the machine "
                                        "idle. Change the pen, then resume the job")

    def on_copy(self, run: JobRun, copy: int) -> None:
        """A copy starts: its streams are recorded as this copy's (crash recovery)."""
        run.copy = copy
        live = self.record.live
        if live is not None:
            live.copy = copy
            self.changed()

    def on_wait(self, left_s: float) -> None:
        """The page delay between copies: the live view's time left counts it down."""
        live = self.record.live
        if live is not None:
            live.remaining_s = max(live.remaining_s, left_s)
            self.changed()

    def on_progress(self, run: JobRun, p: Progress) -> None:
        """Keep the live progress and the recorded progress; stop a drained stream on request."""
        link = run.conn.link
        now = time.monotonic()
        live = self.record.live
        if live is not None:
            live.segments_done = p.segments_done
            live.elapsed_s = run.base_run + (now - run.t0)
            live.remaining_s = p.remaining_s
            self.changed()
        st = link.last_status
        if (st is not None and run.underruns0 is None and run.first_line is not None
                and st.done_line >= run.first_line):
            run.underruns0 = st.underruns
        if now - run.progress_saved > 0.25:
            run.progress_saved = now
            self.progress.put(run.rec.id, segments_done=p.segments_done,
                              remaining_s=p.remaining_s, run_s=run.base_run + (now - run.t0))
        if not link.streaming:
            # All lines are sent; run_job waits for the machine to finish them. A
            # cancel (or a pause) still has to stop it: hold here, and give up by raising
            # the interrupt fault run_job handles like any other (hold, reset, record).
            req = self.control.pending_stop()
            if req in ("cancel", "pause"):
                link.realtime(protocol.RT_HOLD)
                if req == "cancel" or not self.control.wait_paused(run.conn, run.rec.id):
                    raise LinkFaultError(FaultKind.INTERRUPT,
                                         f"{link.url}: {self.control.why()}", -1,
                                         status=link.last_status)
                link.realtime(protocol.RT_RESUME)

    # ------------------------------------------------------------------ after a stop or fault
    def _after_error(self, run: JobRun, e: SendError) -> None:
        """Record where a job stopped and put it in the state its cause calls for."""
        cause = e.__cause__
        kind = cause.kind if isinstance(cause, LinkFaultError) else None
        req = self.control.stop_kind()
        rp = self._record_stop(run, kind, req)
        if rp is not None and kind not in (None, FaultKind.DISCONNECT):
            self.pose.set(rp.position is not None, run.conn.link.last_status)
        elif kind is FaultKind.DISCONNECT:
            self.pose.forget()
        self._stopped_state(run.rec, rp, req, e)

    def _record_stop(self, run: JobRun, kind: str | None, req: str | None) -> ResumePoint | None:
        """Record the resume point `run_job` saved in the database, and the run time."""
        rec = run.rec
        rp = run.saved
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
            self.jobs.cache.drop(rec.id)
            log.info("job %d cancelled at %s", rec.id, where)
        elif req == "terminate":
            self.store.set_state(rec.id, st_.HELD, message=(
                f"stopped when the daemon was told to stop, at {where}; laser off. Resume it "
                "with POST /api/jobs/{}/resume".format(rec.id)))
            log.info("job %d stopped for shutdown at %s", rec.id, where)
        elif (question := self.record.question) is not None:
            self.store.set_state(rec.id, st_.HELD, question=question, message=(
                f"waiting for a person: {question} Answer yes on the web page, or on a "
                "terminal following it with `fivebar plot --server`, once it is so "
                "(nothing has moved)."))
            log.warning("job %d held: %s", rec.id, question)
        else:
            self.store.set_state(rec.id, st_.HELD, message=text + (
                f"\nresume it with POST /api/jobs/{rec.id}/resume" if rp is not None else ""))
            log.error("job %d held after a fault: %s", rec.id, text.replace("\n", " | "))
