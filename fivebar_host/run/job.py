"""Run a compiled job on a controller: the one run every face uses.

`run_job(controller, job, operator, store, options)` is what `fivebar plot --port`, the
daemon and the vpype plugin do with a compiled `Job`, on fivebar's firmware or a stock GRBL
board alike (`run.controller.Controller`):

1. refuse what the controller or the operator cannot do, before anything moves
   (`check_features`: one place for every controller);
2. a known start pose (`Controller.ensure_pose`), or, with `options.resume`, the saved
   resume point (`run.store`) checked against the job's fingerprint and mapped onto the
   machine as it is now (`Controller.resume_start`: exact where the controller kept its
   record, a person's confirmation where only they know);
3. the job in pieces between its pen-change stops (`run.stops`), each streamed by the
   controller (`Controller.run_piece`) and waited for; at each stop the operator changes the
   pen (or quits with an exact resume point); `--copies` runs it again after the page delay;
4. a fault, an interrupt or a quit leaves the resume point in the store and raises
   `SendError` saying where the machine stopped and how to continue; a finished run clears
   the store and reports.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from fivebar_host.compile import Job
from fivebar_host.errors import UsageError
from fivebar_host.run.controller import Controller, Piece, Position, check_job
from fivebar_host.run.errors import FaultKind, LinkFaultError, SendError
from fivebar_host.run.operator import Operator, Progress
from fivebar_host.run.overrides import Overrides
from fivebar_host.run.resume import ResumePoint, fingerprint
from fivebar_host.run.stops import Copies, later_copies_s, pieces
from fivebar_host.run.store import ResumeStore

#: How often the page delay polls the machine and the stop request, s.
WAIT_POLL_S = 0.05
#: ... and reads a status report (keeps the link and the daemon's live view fresh), s.
WAIT_STATUS_S = 0.5


@dataclass(frozen=True)
class RunOptions:
    """How to run a job: laser power on (`--laser`), from the saved resume point, how many
    copies with what page delay, and the live overrides a person may change meanwhile."""

    laser: bool = False
    resume: bool = False
    copies: Copies = field(default_factory=Copies)
    overrides: Overrides | None = None


@dataclass(frozen=True)
class RunReport:
    """What a finished run did."""

    segments: int  # job segments executed by this run, over all its copies
    start_segment: int
    elapsed_s: float
    bytes_sent: int
    resends: int
    final: Position  # where the machine stands, idle
    start_position: Position  # where the run started from


def check_features(controller: Controller, job: Job, operator: Operator,
                   options: RunOptions) -> None:
    """Refuse, before anything moves, what this controller or this operator cannot do."""
    check_job(controller.features, job)
    if options.overrides is not None and controller.features.live_overrides is not None:
        raise UsageError(f"live feed and power overrides: {controller.features.live_overrides}")
    dwells = job.is_dwell & (job.power > 0)
    if options.laser and dwells.any() and controller.features.tool_on_dwells is not None:
        k = int(np.flatnonzero(dwells)[0])
        raise UsageError(f"{job.file}: line {int(job.source_line[k])}: a dwell with the "
                         f"laser on: {controller.features.tool_on_dwells}")
    if job.pauses and not operator.attended:
        raise SendError(f"{job.file}: the job stops for {len(job.pauses)} pen change(s) "
                        f"({', '.join(p.describe() for p in job.pauses)}) and nobody is "
                        "there to answer: plot it with --no-pause, or where a person can")


@dataclass
class _Tally:
    """What the pieces of one run share: the clock, the bytes, the progress."""

    job: Job
    operator: Operator
    copies: Copies
    copy: int = 1
    bytes_sent: int = 0
    resends: int = 0
    t0: float = field(default_factory=time.monotonic)
    remaining: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        d = self.job.duration_us.astype(np.float64) * 1e-6
        self.remaining = np.concatenate((np.cumsum(d[::-1])[::-1], [0.0]))

    def done(self, segments: int) -> None:
        """The machine finished the segments before `segments` (of this copy)."""
        n = self.job.n_segments
        k = min(max(segments, 0), n)
        left = float(self.remaining[k]) + later_copies_s(self.job, self.copies, self.copy)
        self.operator.progress(Progress(k, n, time.monotonic() - self.t0, left, self.copy,
                                        self.copies.count))


def run_job(controller: Controller, job: Job, operator: Operator, store: ResumeStore,
            options: RunOptions) -> RunReport:
    """Run `job` (or its remainder, with `options.resume`) and wait until the machine is
    idle (module doc)."""
    check_features(controller, job, operator, options)
    fp = fingerprint(job)
    tally = _Tally(job, operator, options.copies)
    start = 0
    if options.resume:
        point = store.load()
        if point.fingerprint != fp or point.segments != job.n_segments:
            raise SendError(f"{store.name}: the resume file belongs to a different job "
                            "(drawing or options changed); run the same command as before "
                            "with --resume. Nothing was sent.")
        tally.copy = point.copy or 1
        if tally.copy > options.copies.count:
            raise SendError(f"{store.name}: the job stopped in copy {tally.copy}, but only "
                            f"{options.copies.count} copies are asked for now (--copies)")
        start, pos = controller.resume_start(job, point, operator)
    else:
        pos = controller.ensure_pose(operator)
    first = (start, pos, tally.copy)
    resumed = options.resume
    while True:
        operator.copy_started(tally.copy)
        for pc in pieces(job, start, resumed):
            if pc.pause is not None and not operator.pen_change(pc.pause):
                raise stopped(controller, job, store, fp, pc.begin, pos, tally.copy,
                              f"stopped at the pen change before {pc.pause.describe()}")
            if pc.end > pc.begin:
                res = controller.run_piece(Piece(
                    job, pc.begin, pc.end, pos, tally.copy, options.laser, operator, store,
                    options.overrides, tally.done))
                pos = res.position
                tally.bytes_sent += res.bytes_sent
                tally.resends += res.resends
        if tally.copy >= options.copies.count:
            break
        if not wait_between_copies(controller, options.copies.page_delay_s, operator):
            raise stopped(controller, job, store, fp, 0, pos, tally.copy + 1,
                          f"stopped before copy {tally.copy + 1} of {options.copies.count}")
        tally.copy += 1
        start, resumed = 0, False
    store.clear()
    done = job.n_segments - first[0] + (tally.copy - first[2]) * job.n_segments
    return RunReport(done, first[0], time.monotonic() - tally.t0, tally.bytes_sent,
                     tally.resends, pos, first[1])


def stopped(controller: Controller, job: Job, store: ResumeStore, fp: str, segment: int,
            pos: Position, copy: int, why: str) -> SendError:
    """Quit at a planned stop: save the exact resume point and the error that says so (its
    cause an interrupt fault, as a Ctrl-C abort, so the daemon records it the same way)."""
    store.save(ResumePoint(str(job.file), fp, segment, pos, f"interrupt: {why}",
                           job.n_segments, copy=copy))
    fault = LinkFaultError(FaultKind.INTERRUPT, f"{controller.url}: {why}", -1)
    hint = store.hint()
    err = SendError(f"{why}: the machine is idle at A = {pos[0]}, B = {pos[1]} steps, pen up "
                    f"(laser off); {segment} of {job.n_segments} segments of copy {copy} "
                    "done." + (f"\n{hint}" if hint else ""))
    err.__cause__ = fault
    return err


def wait_between_copies(controller: Controller, delay_s: float, operator: Operator) -> bool:
    """Wait `delay_s` with the machine idle, telling the operator the seconds left (about
    10 times a second). A stop request (Ctrl-C) asks the operator as a stream does: True
    goes on waiting, False gives up → False."""
    deadline = time.monotonic() + delay_s
    next_status = 0.0
    while True:
        now = time.monotonic()
        left = deadline - now
        operator.waiting(max(0.0, left))
        if left <= 0.0:
            return True
        if operator.should_stop():
            paused_at = time.monotonic()
            if not operator.interrupted():
                return False
            deadline += time.monotonic() - paused_at  # the countdown goes on from there
        if now >= next_status:
            controller.poll()
            next_status = now + WAIT_STATUS_S
        time.sleep(min(WAIT_POLL_S, max(0.0, left)))
