"""Recovery of jobs a crash or a lost link left unfinished, after the worker (re)connects.

The database says which jobs were running (or paused, or held with a stream record) when the
daemon lost the machine; the stream record (first line number, start segment, start
position, number of lines) and the controller's own record say where exactly each stopped:

- the controller was not reset: it kept its queue and line counter; once it has run out of
  lines, the last line it executed maps to the first unfinished segment;
- it was reset since (opening the port resets an Arduino) but kept its position, `H` and the
  last line executed (docs/protocol.md 7): `run.resume.kept_resume_segment` checks that record
  is the stream's and maps it;
- otherwise the last resume point recorded, or the last segment the daemon saw finish
  (position unknown), or — if the job never started drawing — back to the queue.

Each stream record names the copy (`copies` option) it drew, and the record of the job the
copy of its last stream, so a job recovers in the copy it was drawing. A recovered job is
held at its resume point — the start of the next copy when a copy but not the last one had
finished — or done, if it finished while the daemon was away; `--auto-resume` queues the
held jobs again that need no person's answer.

`Recovery` is the worker's collaborator for this, called once per connection before any
job runs. It reads the controller's kept record on the link itself (the `Ln` counters and
`H` are fivebar's firmware's) and records a pose it finds exact with `PoseKeeper`.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from fivebar_host.compile import Job
from fivebar_host.config import Profile
from fivebar_host.controllers.fivebar.kept import kept_resume_segment
from fivebar_host.program import Program
from fivebar_host.protocol import StatusReport
from fivebar_host.run.errors import SendError
from fivebar_host.run.moves import build_program
from fivebar_host.run.stops import later_copies_s, piece_end
from fivebar_host.server import store as st_
from fivebar_host.server.jobs import JobOptions, SubmitError
from fivebar_host.server.journal import JournalLink
from fivebar_host.server.pose import PoseKeeper
from fivebar_host.server.store import JobRecord, JobStore, ResumeRecord, StreamRecord
from fivebar_host.server.stored import StoredJobs

log = logging.getLogger("fivebar.serve")


class Recovery:
    """The worker's crash recovery (module docstring); machine thread only."""

    def __init__(self, store: JobStore, jobs: StoredJobs, profile: Profile, pose: PoseKeeper,
                 drain_timeout_s: float, auto_resume: bool) -> None:
        self.store = store
        self.jobs = jobs
        self.profile = profile
        self.pose = pose
        self.drain_timeout_s = drain_timeout_s
        self.auto_resume = auto_resume

    def recover(self, link: JournalLink) -> None:
        """After (re)connecting: settle jobs a crash or a lost link left unfinished."""
        for rec in self.store.list(states=(st_.RUNNING, st_.PAUSED)):
            self._recover_job(link, rec)
        for rec in self.store.list(states=(st_.HELD,)):
            if rec.stream is not None:
                self._recover_job(link, rec)
        if self.auto_resume:
            for rec in self.store.list(states=(st_.HELD,)):
                if rec.resume is not None and rec.question is None:
                    log.info("job %d: resuming automatically (--auto-resume)", rec.id)
                    self.store.set_state(rec.id, st_.QUEUED, message="resumed automatically")

    def _settle(self, link: JournalLink) -> StatusReport:
        """Wait while the controller still runs lines it was given before the host died."""
        deadline = time.monotonic() + self.drain_timeout_s
        st = link.status()
        while st.state == "Run" and time.monotonic() < deadline:
            time.sleep(0.05)
            st = link.status()
        return st

    def _recover_job(self, link: JournalLink, rec: JobRecord) -> None:
        """Work out exactly where an interrupted job stopped and hold it there."""
        try:
            job = self.jobs.job(rec)
        except SubmitError as e:
            self.store.set_state(rec.id, st_.FAILED, message=str(e))
            return
        exact = self._exact_resume(link, rec, job)
        if exact is not None:
            resume = exact
        elif rec.resume is not None:
            resume = rec.resume
        elif rec.segments_done == 0 and rec.stream is None and rec.copy == 1:
            self.store.set_state(rec.id, st_.QUEUED, message="requeued: the daemon stopped "
                                 "before the job started drawing")
            log.warning("job %d: requeued (the daemon stopped before it started drawing)",
                        rec.id)
            return
        else:
            resume = ResumeRecord(rec.segments_done, None,
                                  "the daemon lost the machine mid-job and the controller was "
                                  "reset: position unknown; segments after the last one the "
                                  "daemon saw finish may be drawn again", rec.copy)
        self.store.set_stream(rec.id, None)
        self._hold_recovered(rec, job, resume)

    def _exact_resume(self, link: JournalLink, rec: JobRecord, job: Job) -> ResumeRecord | None:
        """The exact resume point from the stream record and the controller's, if there is one."""
        opts = JobOptions.from_json(rec.options)
        stream = rec.stream
        st = link.status()
        not_reset = stream is not None and (
            stream.first_line <= st.accepted_line <= stream.first_line + stream.lines - 1)
        if not_reset:
            # The controller was not reset: it kept the lines it had and its line counter.
            st = self._settle(link)
        if stream is None or not (not_reset or st.homed):
            return None
        try:
            prog = build_program(job, self.profile, opts.laser, stream.start_segment,
                                 stream.start_position, piece_end(job, stream.start_segment))
        except SendError as e:  # the profile's limits changed: no exact mapping
            log.warning("job %d: cannot rebuild its program (%s)", rec.id, e)
            return None
        if len(prog) != stream.lines or st.state == "Alarm":
            return None
        if not_reset:
            if st.state == "Hold" or st.queued:
                link.reset()  # clears what is queued; position kept, laser off
            nxt: int | None = prog.finished_segments(stream.first_line, st.done_line,
                                                     stream.start_segment)
            why = "the controller kept its count"
        elif st.state == "Idle" and not st.queued:
            nxt, why = self._kept_across_reset(rec, prog, stream, st)
        else:
            return None
        if nxt is None:
            return None
        exact = ResumeRecord(nxt, (st.a, st.b),
                             f"the daemon lost the machine mid-job; {why} (last "
                             f"line executed {st.done_line})", stream.copy)
        self.pose.set(True, link.last_status)
        return exact

    def _kept_across_reset(self, rec: JobRecord, prog: Program, stream: StreamRecord,
                           st: StatusReport) -> tuple[int | None, str]:
        """The segment a reset controller's kept record maps to (position, H, last line)."""
        # Reset since (opening the port resets an Arduino): it kept its position, H and the
        # last line it executed (docs/protocol.md 7).
        floor = rec.resume.next_segment if rec.resume is not None else rec.segments_done
        nxt, why = kept_resume_segment(prog, stream.first_line, stream.start_segment,
                                       stream.start_position, st, floor)
        if nxt is None:
            log.warning("job %d: the controller's kept record is not its stream's (%s)",
                        rec.id, why)
        return nxt, "the controller kept its position and count across its reset"

    def _hold_recovered(self, rec: JobRecord, job: Job, resume: ResumeRecord) -> None:
        """Hold a recovered job at its resume point, or mark it done if it got to the end."""
        opts = JobOptions.from_json(rec.options)
        copies = opts.copies
        if resume.next_segment >= job.n_segments and resume.copy < copies:
            resume = ResumeRecord(0, resume.position, f"{resume.reason}; copy {resume.copy} "
                                  f"of {copies} was finished", resume.copy + 1)
        if resume.next_segment >= job.n_segments:
            self.store.set_resume(rec.id, None)
            self.store.update(rec.id, segments_done=job.n_segments, remaining_s=0.0)
            self.store.set_state(rec.id, st_.DONE,
                                 message="done (finished while the daemon was away)")
            log.info("job %d: finished while the daemon was away", rec.id)
            return
        self.store.set_resume(rec.id, resume)
        remaining = (float(np.asarray(job.duration_us[resume.next_segment:]).sum()) * 1e-6
                     + later_copies_s(job, opts.copies_plan(), resume.copy))
        self.store.update(rec.id, remaining_s=remaining)
        where = (f"A = {resume.position[0]}, B = {resume.position[1]}" if resume.position
                 else "position unknown: home the machine (or confirm) before resuming")
        of_copy = f" of copy {resume.copy} of {copies}" if copies > 1 else ""
        self.store.set_state(rec.id, st_.HELD, message=(
            f"interrupted ({resume.reason}); resume point: segment {resume.next_segment} of "
            f"{job.n_segments}{of_copy}, {where}. Resume it with POST "
            f"/api/jobs/{rec.id}/resume"))
        log.warning("job %d recovered: next segment %d of %d%s (%s)", rec.id,
                    resume.next_segment, job.n_segments, of_copy, where)
