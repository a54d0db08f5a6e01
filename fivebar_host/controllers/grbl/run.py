"""Jobs, homing, jogs and frames on a stock GRBL 1.1 board (`--controller grbl`).

Pure pipeline steps over an open `GrblLink` (no click): settings check, a known pose, the
stream, and what a fault leaves. fivebar's own firmware path (`run.sender`) is untouched.

**Known pose.** GRBL keeps no position across a reboot (opening an Uno's port reboots it: the
machine position restarts at 0 wherever the arms are) and no "position known" flag. With
endstops (`$22=1`) the board boots in alarm and `$H` homes; then `G10 L20 P1 X<home A>
Y<home B>` makes work X/Y the motor angles. Without endstops, machine 0 is where the board
booted, so a person confirms that the arms are where the count says (the home pose after a
boot; `--yes` answers), and `G10 L2 P1 X<−home A> Y<−home B>` sets the same work frame.

**Faults.** GRBL's `ok` means "planned", not "done", and carries no line number, so the count
of `ok`s bounds progress from above only. On an `error:N`, an alarm or the user's abort the
host holds (`!`: GRBL decelerates, and in laser mode turns the laser off while held), resets
(Ctrl-X: queue cleared, laser off; the position is kept because motion had stopped) and
reads MPos: the position is exact, and the segment it lies on is found by searching the
program's joint-space lines around the last acknowledged one, and the resume file is
written; `--resume` continues from it (`run.grbl_resume`: what is exact and what is not).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fivebar_host.compile import Job
from fivebar_host.config import Profile
from fivebar_host.controllers.grbl.link import (
    GrblError,
    GrblLink,
    GrblSettingsError,
    GrblStatus,
    GrblStreamError,
    StreamState,
)
from fivebar_host.controllers.grbl.program import (
    GrblProgram,
    from_program,
    job_program,
    settings_differences,
    steps_per_degree,
    work_offset_line,
)
from fivebar_host.controllers.grbl.resume import fault_point, load_point, resume_pose
from fivebar_host.program import Program
from fivebar_host.run.resume import RESUME_SUFFIX, resume_path


def check_settings(link: GrblLink, profile: Profile) -> None:
    """Refuse a board whose `$$` differs from `fivebar grbl-settings`, listing each."""
    diff = settings_differences(profile, link.settings())
    if diff:
        raise GrblSettingsError(
            f"{link.url}: the board's settings differ from what the profile needs "
            f"(`fivebar grbl-settings` prints them; send each line to the board):\n  "
            + "\n  ".join(diff))


def position_steps(link: GrblLink, profile: Profile, st: GrblStatus) -> tuple[int, int]:
    """fivebar's absolute steps (from the home pose) of a status report: work X/Y are the
    motor angles in degrees (see module doc)."""
    if st.work_reported:
        work = st.machine
    else:
        off = link.work_offset()
        work = (st.machine[0] - off[0], st.machine[1] - off[1])
    spd = steps_per_degree(profile)
    h = [math.degrees(v) for v in profile.motors.home_rad]
    return (round((work[0] - h[0]) * spd), round((work[1] - h[1]) * spd))


def ensure_pose(link: GrblLink, profile: Profile, confirm: Callable[[str], bool]
                ) -> tuple[int, int]:
    """A known pose (module doc) → the position in fivebar's steps."""
    st = link.status()
    h = [math.degrees(v) for v in profile.motors.home_rad]
    if profile.motors.endstops:
        if st.state == "Alarm":
            link.command("$H", timeout_s=120.0)
            link.command(work_offset_line(profile))
            st = link.status()
        return position_steps(link, profile, st)
    if st.state not in ("Idle",):
        raise GrblError(f"{link.url}: the board is in {st.state}; clear it (`$X` in a "
                        "terminal, or reset it) before a job")
    where = (h[0] + st.machine[0], h[1] + st.machine[1])
    at_home = st.machine == (0.0, 0.0)
    question = (f"GRBL restarted its count when the port opened. Are the arms at the home "
                f"pose θ1 = {h[0]:g}°, θ2 = {h[1]:g}° (motor angles from +x)?" if at_home
                else f"Are the arms at θ1 = {where[0]:.3f}°, θ2 = {where[1]:.3f}° (GRBL's "
                f"count since it booted at the home pose)?")
    if not confirm(question):
        raise GrblError("position unknown: place the arms at the home pose, reset the board "
                        "(or reopen its port) and confirm")
    link.command(f"G10 L2 P1 X{-h[0]:.4f} Y{-h[1]:.4f}")
    return position_steps(link, profile, link.status())


@dataclass(frozen=True)
class GrblReport:
    """What a finished GRBL run did."""

    segments: int
    lines: int
    bytes_sent: int
    final: tuple[int, int]  # fivebar steps


def run_grbl_job(link: GrblLink, job: Job, profile: Profile, *, laser: bool,
                 confirm: Callable[[str], bool],
                 on_progress: Callable[[int], None] | None = None,
                 should_stop: Callable[[], bool] | None = None,
                 on_interrupt: Callable[[], bool] | None = None,
                 drawing: str | Path | None = None, resume: bool = False,
                 confirm_placed: Callable[[str], bool] | None = None,
                 on_note: Callable[[str], None] | None = None) -> GrblReport:
    """Check the settings, make sure of the pose (travel to the job's start if the arms are
    elsewhere, laser off), stream the job and wait for idle. `on_progress` gets the job
    segments acknowledged (planned by GRBL; up to 15 blocks ahead of the pen).

    A fault or an abort writes the resume file beside `drawing` (`run.grbl_resume`);
    `resume` continues from it: the half-done segment from the stop position, then the
    rest. `confirm_placed` answers where the arms are when GRBL lost its count (never
    `--yes`; `confirm` when not given)."""
    rpath = resume_path(drawing if drawing is not None else job.file)
    check_settings(link, profile)
    start, at = 0, None
    if resume:
        rp = load_point(rpath, job)
        start, at = rp.next_segment, resume_pose(
            link, job, profile, rp, confirm_placed or confirm, on_note or (lambda _: None),
            lambda p, q: _travel(link, profile, job.assembly, p, q))
    else:
        pos = ensure_pose(link, profile, confirm)
        first = (int(job.steps[0, 0]), int(job.steps[0, 1]))
        if pos != first:
            _travel(link, profile, job.assembly, pos, first)
    prog = job_program(job, profile, laser, start, at)

    def progress(s: StreamState) -> None:
        if on_progress is not None:
            seg = prog.segment[: s.acked]
            on_progress(int(seg.max()) + 1 if seg.size and seg.max() >= 0 else start)

    try:
        res = link.stream(prog.lines, on_progress=progress, should_stop=should_stop,
                          on_interrupt=on_interrupt)
        st = link.wait_idle(max(30.0, 3.0 * job.total_time_s))
    except GrblStreamError as e:
        raise _after_fault(link, job, profile, prog, e, rpath) from e
    if rpath.exists():
        rpath.unlink()
    return GrblReport(job.n_segments - start, len(prog.lines), res.bytes_sent,
                      position_steps(link, profile, st))


def _after_fault(link: GrblLink, job: Job, profile: Profile, prog: GrblProgram,
                 e: GrblStreamError, rpath: Path) -> GrblError:
    """Hold, reset (laser off, queue cleared, position kept), read where the pen stopped,
    write the resume file. After an alarm or a reboot GRBL's position is not trusted."""
    pos: tuple[int, int] | None = None
    reason = f"{e.code or 'fault'}: {e}"
    try:
        if not e.code.startswith(("ALARM", "Grbl")):
            link.hold()
            link.reset()
        st = link.status()
        pos = position_steps(link, profile, st)
        if e.code.startswith(("ALARM", "Grbl")):
            reason += f" (GRBL may have lost its position; it reports A = {pos[0]}, " \
                      f"B = {pos[1]} steps)"
            pos = None
    except GrblError as again:
        reason += f"; then the board could not be read ({again})"
    drawing = rpath.with_name(rpath.name[: -len(RESUME_SUFFIX)])
    rp, where = fault_point(job, prog, drawing, e.state, pos, reason)
    rp.save(rpath)
    return GrblError(f"{e}. Laser off, queue cleared. {where}.\nresume file: {rpath}")


def _travel(link: GrblLink, profile: Profile, assembly: int, start: tuple[int, int],
            end: tuple[int, int]) -> None:
    """A checked laser-off joint-space travel (fivebar's own, ramped) and wait for it."""
    from fivebar_host.run.moves import travel

    moves = travel(profile, assembly, start, end, "travel to the job's start")
    link.stream(from_program(profile, moves, start))
    link.wait_idle(120.0)


def home_grbl(link: GrblLink, profile: Profile, confirm: Callable[[str], bool]
              ) -> tuple[int, int]:
    """`fivebar home --controller grbl`: `$H` with endstops, else the confirmation; checks
    the settings first (a wrong `$100` would put every later move elsewhere)."""
    check_settings(link, profile)
    if profile.motors.endstops:
        link.command("$H", timeout_s=120.0)
        link.command(work_offset_line(profile))
        return position_steps(link, profile, link.status())
    return ensure_pose(link, profile, confirm)


def stream_moves(link: GrblLink, profile: Profile, moves: Program,
                 start: tuple[int, int], timeout_s: float = 120.0) -> tuple[int, int]:
    """Run fivebar's checked laser-off moves (jog, frame) on the board; the end position."""
    link.stream(from_program(profile, moves, start))
    return position_steps(link, profile, link.wait_idle(timeout_s))


def angles_text(profile: Profile, pos: tuple[int, int]) -> str:
    """Steps → the motor angles the board's work coordinates show."""
    h = np.degrees(np.asarray(profile.motors.home_rad))
    a = h + np.asarray(pos) / steps_per_degree(profile)
    return f"X {a[0]:.3f}°, Y {a[1]:.3f}°"
