"""The daemon's operator and resume store: how a job's run (`run.job.run_job`) reaches the
people behind the web page and the API, and where it keeps its resume point.

- `DaemonOperator` answers a run's questions on behalf of the machine thread, through the
  worker's collaborators: the pose questions from the daemon's own record or the person's
  confirmation given with the job or the resume request (`PoseKeeper.answer`), holds and
  cancels from the requests other threads make (`JobControl`), pen changes by parking the
  job in the paused state until the resume request, progress into the live progress and the
  database (`JobRunner`).
- `DatabaseStore` keeps the run's resume point in the job's SQLite record (`server.store`)
  instead of a file beside the drawing, and records each stream as it starts (first line
  number, start segment, start position), so that after a crash the firmware's own `Ln`
  counter maps back to the exact segment (`server.recovery`).
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from fivebar_host.compile.model import LayerPause
from fivebar_host.run.errors import SendError
from fivebar_host.run.operator import Progress
from fivebar_host.run.resume import ResumePoint
from fivebar_host.run.store import StreamStart
from fivebar_host.server.store import JobStore, StreamRecord

if TYPE_CHECKING:
    from fivebar_host.server.control import JobControl
    from fivebar_host.server.jobrun import JobRun, JobRunner
    from fivebar_host.server.pose import PoseKeeper

log = logging.getLogger("fivebar.serve")


class DaemonOperator:
    """The run's operator for one job on the machine thread (module doc)."""

    attended = True  # the web page and the API answer pen changes (the paused state)

    def __init__(self, runner: JobRunner, control: JobControl, pose: PoseKeeper,
                 run: JobRun) -> None:
        self.runner = runner
        self.control = control
        self.pose = pose
        self.run = run

    def confirm(self, question: str) -> bool:
        # The person's confirmation given with the submission is for the job's first start;
        # after an interruption only the daemon's own record or a resume request answers.
        run = self.run
        return self.pose.answer(run.conn.link, question, run.opts.confirm and not run.resume,
                                run.user_confirm)

    def confirm_placed(self, question: str) -> bool:
        return self.confirm(question)

    def note(self, text: str) -> None:
        log.warning("job %d: %s", self.run.rec.id, text)

    def progress(self, p: Progress) -> None:
        self.runner.on_progress(self.run, p)

    def should_stop(self) -> bool:
        return self.control.should_stop()

    def interrupted(self) -> bool:
        return self.control.on_interrupt(self.run.conn, self.run.rec.id)

    def pen_change(self, pause: LayerPause) -> bool:
        return self.runner.on_pen_change(self.run, pause)

    def waiting(self, left_s: float) -> None:
        self.runner.on_wait(left_s)

    def copy_started(self, copy: int) -> None:
        self.runner.on_copy(self.run, copy)


class DatabaseStore:
    """A job's resume point in the daemon's database (module doc). `save` keeps the point
    the run stopped at in `JobRun.saved`, for the machine thread to record with the cause it
    knows (`JobRunner._record_stop`); `load` gives the point recorded in the job's row."""

    def __init__(self, store: JobStore, run: JobRun) -> None:
        self.store = store
        self.run = run
        self.name = f"job {run.rec.id}"

    def load(self) -> ResumePoint:
        rec, job = self.run.rec, self.run.job
        if rec.resume is None:
            raise SendError(f"{self.name}: no resume point (nothing was interrupted?)")
        r = rec.resume
        return ResumePoint(str(job.file), rec.fingerprint, r.next_segment, r.position,
                           r.reason, job.n_segments, copy=r.copy)

    def save(self, point: ResumePoint) -> None:
        self.run.saved = point

    def clear(self) -> None:
        self.run.saved = None

    def stream_started(self, stream: StreamStart) -> None:
        """Commit the stream record before its first line is written, and remember its
        first line for the underrun count."""
        self.store.set_stream(self.run.rec.id, StreamRecord(
            stream.first_line, stream.start, stream.start_position, stream.lines, stream.copy))
        self.run.first_line = stream.first_line
        self.run.underruns0 = None

    def hint(self) -> str:
        return ""  # the job's state message says how to resume it
