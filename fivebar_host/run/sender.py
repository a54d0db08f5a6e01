"""Send compiled jobs to the machine: known start pose, streaming, faults and exact resume.

Pure pipeline step over an open `Link` (no click, no pyserial): the CLI and the daemon call it.

A job is a list of firmware lines (`run.moves`), each mapped to the job segment it executes.
While streaming, the firmware's status reports say which line (so which segment) finished
last. On a fault the machine is held (laser off), its position read, the firmware reset (queue
cleared, laser off) and a resume file written next to the drawing (`run.faults`,
`run.resume`): the job's fingerprint, the first segment not known to be finished and the
position. `--resume` continues from exactly there: when the pen stopped inside that segment,
one move finishes the rest of it along the same joint-space line (nothing redrawn); otherwise
a laser-off travel goes back to the segment's start.

When the controller restarts (a reset banner mid-stream, or a hung controller rebooted through
DTR) it keeps its position, `H` and `Ln` done (docs/protocol.md 7, kept across a reset): the
line it finished last maps back to the exact segment, as after a hold. When the link breaks
the position cannot be read at once; the resume file then also describes the stream (its line
numbers and `build_program`'s inputs), and `--resume` reads the kept record from the controller
(opening the port resets an Arduino, which keeps it) and maps it the same way. Only a
controller that lost power (`H:0`) falls back to the last segment a status report confirmed,
and segments after it may be drawn twice.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fivebar_host import protocol
from fivebar_host.compile import Job
from fivebar_host.compile.model import LayerPause
from fivebar_host.config import Profile
from fivebar_host.controllers.fivebar.faults import StreamRun, after_fault
from fivebar_host.controllers.fivebar.link import Link
from fivebar_host.controllers.fivebar.stream import StreamProgress, StreamResult
from fivebar_host.protocol import StatusReport
from fivebar_host.run.errors import LinkFaultError, PowerLossError, SendError
from fivebar_host.run.moves import build_program
from fivebar_host.run.overrides import FEED_MAX_PCT, FEED_MIN_PCT, Overrides
from fivebar_host.run.resume import (
    ResumePoint,
    fingerprint,
    kept_stream_segment,
    redraw_text,
    resume_path,
)
from fivebar_host.run.stops import Copies, later_copies_s, pieces, stopped, wait_between_copies


# ------------------------------------------------------------------ start pose
def ensure_known_pose(link: Link, profile: Profile, confirm: Callable[[str], bool]
                      ) -> StatusReport:
    """Make sure the firmware's step count means what the job assumes (0 = homed pose).

    After power-up the firmware does not know where the arms are (`H:0`; a reset, such as
    the one opening an Arduino's port causes, keeps the position: docs/protocol.md 7): with
    endstops `$H` homes; without them the user confirms that the arms sit at the profile's
    home pose, and `G92 A0 B0` sets the position. Alarm or hold states are refused with what
    to do.
    """
    st = link.status()
    if st.state == "Alarm":
        raise SendError(f"{link.url}: the machine is in alarm {st.detail} "
                        f"({_code_text(st.detail)}); clear it with `fivebar home`")
    if st.state == "Hold":
        raise SendError(f"{link.url}: the machine is on hold; resume or reset it first")
    if st.homed:
        return st
    return home(link, profile, confirm)


def home(link: Link, profile: Profile, confirm: Callable[[str], bool]) -> StatusReport:
    """Home: `$H` with endstops, otherwise confirmation then `G92 A0 B0`."""
    if profile.motors.endstops:
        link.command("$H", timeout_s=120.0)
        return link.wait_idle(120.0)
    h1, h2 = (math.degrees(v) for v in profile.motors.home_rad)
    if not confirm(f"The firmware does not know where the arms are. Are they at the home "
                   f"pose θ1 = {h1:g}°, θ2 = {h2:g}° (motor angles from +x)?"):
        raise SendError("position unknown: place the arms at the home pose and confirm, or "
                        "run `fivebar home`")
    link.command("G92 A0 B0")
    return link.wait_idle(10.0)  # G92 is queued: its ok comes before it takes effect


def _code_text(code: int | None) -> str:
    info = protocol.CODES.get(code or -1)
    return info.description if info else "unknown code"


# ------------------------------------------------------------------ running a job
@dataclass(frozen=True)
class SendReport:
    """What a finished send did."""

    segments: int  # job segments executed by this run
    start_segment: int
    elapsed_s: float
    bytes_sent: int
    resends: int
    final: StatusReport
    start_position: tuple[int, int] = (0, 0)  # firmware steps the run started from


@dataclass(frozen=True)
class Progress:
    """Progress in job terms, for progress bars (`copy` of `copies`, 1-based)."""

    segments_done: int
    segments_total: int
    elapsed_s: float
    remaining_s: float
    copy: int = 1
    copies: int = 1


@dataclass
class _Run:
    """What the pieces of one run share (`run_job`)."""

    link: Link
    job: Job
    profile: Profile
    laser: bool
    rpath: Path
    fingerprint: str
    copies: Copies
    t0: float
    on_progress: Callable[[Progress], None] | None
    should_stop: Callable[[], bool] | None
    on_interrupt: Callable[[], bool] | None
    overrides: Overrides | None
    copy: int = 1
    bytes_sent: int = 0
    resends: int = 0


def run_job(link: Link, job: Job, profile: Profile, *, drawing: str | Path, laser: bool,
            confirm: Callable[[str], bool], resume: bool = False,
            on_progress: Callable[[Progress], None] | None = None,
            should_stop: Callable[[], bool] | None = None,
            on_interrupt: Callable[[], bool] | None = None,
            on_note: Callable[[str], None] | None = None,
            confirm_placed: Callable[[str], bool] | None = None,
            overrides: Overrides | None = None,
            on_pause: Callable[[LayerPause], bool] | None = None,
            copies: Copies | None = None,
            on_wait: Callable[[float], None] | None = None,
            on_copy: Callable[[int], None] | None = None) -> SendReport:
    """Stream `job` (or its remainder with `resume`) and wait until the machine is idle.

    `confirm` answers the first-start question "are the arms at the home pose?" (the CLI's
    `--yes` may answer it). `confirm_placed` answers where the arms are when a resume finds
    a controller that lost power: only a person may answer that (the CLI asks on a terminal
    and never takes `--yes` for it); when it says no, the resume is refused before anything
    moves (`PowerLossError`). Without it, `confirm` answers (the daemon: a person's resume
    request).

    On any fault: hold, read the position, reset the firmware, write the resume file and raise
    `SendError` naming the fault, the position and the last segment executed. `on_note`
    receives what the user should know before a resumed run starts (where it resumes from and
    whether segments may be drawn twice). `overrides` (live feed and laser power,
    `run.overrides`) change the lines not yet written; the resume file maps lines to segments
    by number, so a resume after an override stays exact.

    Planned stops (`run.stops`): at each pen-change stop of `job.pauses` the machine is left
    idle with the pen up and `on_pause` decides (True: go on; False: quit with an exact
    resume file) — a job with stops needs it; `copies` runs the job several times with
    `on_wait` told the seconds left of the page delay between them, and `on_copy` told the
    copy (1-based) each time one starts, a resumed one included, before its first line.
    """
    if job.pauses and on_pause is None:
        raise SendError(f"{job.file}: the job stops for {len(job.pauses)} pen change(s) "
                        f"({', '.join(p.describe() for p in job.pauses)}) and nobody is "
                        "there to answer: plot it with --no-pause, or where a person can")
    run = _Run(link, job, profile, laser, resume_path(drawing), fingerprint(job),
               copies or Copies(), time.monotonic(), on_progress, should_stop, on_interrupt,
               overrides)
    start = 0
    if resume:
        rp = ResumePoint.load(run.rpath)
        if rp.fingerprint != run.fingerprint:
            raise SendError(f"{run.rpath}: the resume file belongs to a different job "
                            "(drawing or options changed); run the same command as before "
                            "with --resume")
        run.copy = rp.copy or 1
        if run.copy > run.copies.count:
            raise SendError(f"{run.rpath}: the job stopped in copy {run.copy}, but only "
                            f"{run.copies.count} copies are asked for now (--copies)")
        start, st = _resume_start(link, job, profile, rp, confirm_placed or confirm,
                                  on_note or (lambda _: None))
    else:
        st = ensure_known_pose(link, profile, confirm)
    first = (start, (st.a, st.b), run.copy)
    while True:
        if on_copy is not None:
            on_copy(run.copy)
        for pc in pieces(job, start, resume):
            if pc.pause is not None:
                assert on_pause is not None
                if not on_pause(pc.pause):
                    raise stopped(link, job, run.rpath, run.fingerprint, pc.begin, st,
                                  run.copy, f"stopped at the pen change before "
                                  f"{pc.pause.describe()}")
            if pc.end > pc.begin:
                st = _stream_piece(run, pc.begin, pc.end, st)
        if run.copy >= run.copies.count:
            break
        if not wait_between_copies(link, run.copies.page_delay_s, should_stop, on_interrupt,
                                   on_wait):
            raise stopped(link, job, run.rpath, run.fingerprint, 0, st, run.copy + 1,
                          f"stopped before copy {run.copy + 1} of {run.copies.count}")
        run.copy += 1
        start, resume = 0, False
    if run.rpath.exists():
        run.rpath.unlink()
    done = job.n_segments - first[0] + (run.copy - first[2]) * job.n_segments
    return SendReport(done, first[0], time.monotonic() - run.t0, run.bytes_sent, run.resends,
                      st, first[1])


def _stream_piece(run: _Run, start: int, end: int, st: StatusReport) -> StatusReport:
    """Stream segments `start` … `end` − 1 from the machine's state `st` and wait until it
    is idle; the final status. A fault writes the resume file (`after_fault`)."""
    link, job = run.link, run.job
    start_position = (st.a, st.b)
    prog = build_program(job, run.profile, run.laser, start, start_position,
                         None if end >= job.n_segments else end)
    durations = job.duration_us.astype(np.float64) * 1e-6
    later = later_copies_s(job, run.copies, run.copy)
    remaining_after = np.concatenate((np.cumsum(durations[::-1])[::-1], [0.0])) + later
    first_line = link.next_line
    last_line = first_line + len(prog) - 1

    def progress(p: StreamProgress) -> None:
        if run.on_progress is None:
            return
        done = prog.finished_segments(first_line, p.done_line, start)
        run.on_progress(Progress(done, job.n_segments, time.monotonic() - run.t0,
                                 float(remaining_after[min(done, job.n_segments)]),
                                 run.copy, run.copies.count))

    try:
        res: StreamResult = link.stream(prog, on_progress=progress,
                                        should_stop=run.should_stop,
                                        on_interrupt=run.on_interrupt,
                                        overrides=run.overrides)
        slowest = FEED_MAX_PCT / FEED_MIN_PCT if run.overrides is not None else 1.0
        final = link.wait_idle(max(30.0, 3.0 * slowest * job.total_time_s), last_line=last_line,
                               on_status=lambda s: progress(StreamProgress(
                                   len(prog), len(prog), len(prog),
                                   s.done_line, s, 0)))
    except LinkFaultError as fault:
        stream = StreamRun(prog, first_line, start, start_position, run.laser,
                           None if end >= job.n_segments else end, run.copy)
        raise after_fault(link, job, stream, fault, run.rpath, run.fingerprint) from fault
    run.bytes_sent += res.bytes_sent
    run.resends += res.resends
    return final


def _resume_start(link: Link, job: Job, profile: Profile, rp: ResumePoint,
                  confirm: Callable[[str], bool], note: Callable[[str], None]
                  ) -> tuple[int, StatusReport]:
    """The segment a resumed run starts at and the status it starts from.

    An exact resume point is used as it is. Without a position the controller's record
    kept across its reset (opening the port resets an Arduino) gives the exact segment when
    it belongs to the interrupted stream (`kept_resume_segment`); otherwise the run starts at
    the last segment a status report confirmed, after homing if the controller lost its
    position, and says how many segments may be drawn twice.
    """
    st = _resumable_status(link)
    start = rp.next_segment
    n = job.n_segments
    if rp.position is None and st.homed and rp.has_stream:
        exact, why = kept_stream_segment(job, profile, rp, st)
        if exact is not None:
            note(f"resume point read from the controller: it kept its position (A = "
                 f"{st.a}, B = {st.b} steps) and its last executed line ({st.done_line}) "
                 f"across its reset; {exact} of {n} segments were executed, continuing "
                 "exactly from there")
            return exact, st
        note(f"the controller's kept record does not belong to the interrupted job ({why}); "
             f"resuming after segment {start} of {n}, the last a status report confirmed, "
             f"from the controller's position (A = {st.a}, B = {st.b} steps): "
             + redraw_text(start, rp.sent_segment))
        return start, st
    if not st.homed:
        return start, _restore_position(link, job, profile, rp, confirm, note)
    if rp.position is None:
        note(f"resuming after segment {start} of {n}, the last a status report confirmed, "
             f"from the controller's position (A = {st.a}, B = {st.b} steps): "
             + redraw_text(start, rp.sent_segment))
    return start, st


def _resumable_status(link: Link) -> StatusReport:
    """The status a resume starts from, once the machine is neither running nor stopped."""
    st = link.status()
    if st.state == "Run":
        # A controller that the port's opening did not reset may still be running the
        # interrupted stream's queue: let it finish, then read where it stopped.
        st = link.wait_idle(120.0)
    if st.state in ("Alarm", "Hold"):
        raise SendError(f"{link.url}: the machine is in {st.state} "
                        f"({_code_text(st.detail)}); clear it before resuming")
    return st


def _restore_position(link: Link, job: Job, profile: Profile, rp: ResumePoint,
                      confirm_placed: Callable[[str], bool], note: Callable[[str], None]
                      ) -> StatusReport:
    """The controller lost power since the fault: its count is 0 and the arms are wherever
    they stopped (or were pushed). With endstops `$H` homes; otherwise a person confirms
    where the arms are (where the job stopped, when that is known, or the home pose). When
    nobody confirms, `PowerLossError` says what to do; nothing has moved."""
    start = rp.next_segment

    def homed_note() -> None:
        if rp.position is None:
            note(f"the controller lost its position (H:0: power was cut since the fault); "
                 f"after homing, resuming after segment {start} of {job.n_segments}, the "
                 f"last a status report confirmed: " + redraw_text(start, rp.sent_segment))

    if profile.motors.endstops:
        link.command("$H", timeout_s=120.0)
        homed_note()
        return link.wait_idle(120.0)
    if rp.position is not None and confirm_placed(
            f"The controller lost power. Are the arms still exactly where the job stopped "
            f"(A = {rp.position[0]}, B = {rp.position[1]} steps)?"):
        link.command(f"G92 A{rp.position[0]} B{rp.position[1]}")
        return link.wait_idle(10.0)  # G92 is queued: its ok comes before it takes effect
    h1, h2 = (math.degrees(v) for v in profile.motors.home_rad)
    if confirm_placed(f"The controller lost power. Are the arms at the home pose "
                      f"θ1 = {h1:g}°, θ2 = {h2:g}° (motor angles from +x)?"):
        homed_note()
        link.command("G92 A0 B0")
        return link.wait_idle(10.0)
    raise PowerLossError(
        f"{link.url}: the controller lost power since the job stopped (H:0): its position is "
        "unknown, and --yes does not answer for where the arms are after a power loss. "
        f"Place the arms at the home pose (θ1 = {h1:g}°, θ2 = {h2:g}°) and run `fivebar home "
        f"--port {link.url}`, then this command again with --resume (or run it on a terminal "
        "without --yes and confirm there). Nothing was sent.")

