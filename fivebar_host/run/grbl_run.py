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
program's joint-space lines back from the last acknowledged one (`GrblProgram.segment_at`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fivebar_host.compile import Job
from fivebar_host.config import Profile
from fivebar_host.run.grbl_link import (
    GrblError,
    GrblLink,
    GrblSettingsError,
    GrblStatus,
    GrblStreamError,
    StreamState,
)
from fivebar_host.run.grbl_program import (
    GrblProgram,
    from_firmware_lines,
    job_program,
    settings_differences,
    steps_per_degree,
    work_offset_line,
)


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
                 on_interrupt: Callable[[], bool] | None = None) -> GrblReport:
    """Check the settings, make sure of the pose (travel to the job's start if the arms are
    elsewhere, laser off), stream the job and wait for idle. `on_progress` gets the job
    segments acknowledged (planned by GRBL; up to 15 blocks ahead of the pen)."""
    check_settings(link, profile)
    pos = ensure_pose(link, profile, confirm)
    first = (int(job.steps[0, 0]), int(job.steps[0, 1]))
    if pos != first:
        _travel(link, profile, job.assembly, pos, first)
    prog = job_program(job, profile, laser)

    def progress(s: StreamState) -> None:
        if on_progress is not None:
            seg = prog.segment[: s.acked]
            on_progress(int(seg.max()) + 1 if seg.size and seg.max() >= 0 else 0)

    try:
        res = link.stream(prog.lines, on_progress=progress, should_stop=should_stop,
                          on_interrupt=on_interrupt)
        st = link.wait_idle(max(30.0, 3.0 * job.total_time_s))
    except GrblStreamError as e:
        raise _after_fault(link, job, profile, prog, e) from e
    return GrblReport(job.n_segments, len(prog.lines), res.bytes_sent,
                      position_steps(link, profile, st))


def _after_fault(link: GrblLink, job: Job, profile: Profile, prog: GrblProgram,
                 e: GrblStreamError) -> GrblError:
    """Hold, reset (laser off, queue cleared, position kept), read where the pen stopped."""
    try:
        if not e.code.startswith(("ALARM", "Grbl")):
            link.hold()
            link.reset()
        st = link.status()
        pos = position_steps(link, profile, st)
    except GrblError as again:
        return GrblError(f"{e}; then the board could not be read ({again}): reset it and "
                         "home before another job")
    k = prog.segment_at(pos, job, e.state.acked)
    return GrblError(
        f"{e}. Laser off, queue cleared. The pen stopped at A = {pos[0]}, B = {pos[1]} "
        f"steps (exact, from MPos), in segment {k} of {job.n_segments} (found from the "
        f"{e.state.acked} lines GRBL acknowledged and that position; GRBL reports no line "
        "numbers). Segments before it are drawn.")


def _travel(link: GrblLink, profile: Profile, assembly: int, start: tuple[int, int],
            end: tuple[int, int]) -> None:
    """A checked laser-off joint-space travel (fivebar's own, ramped) and wait for it."""
    from fivebar_host.run.program import travel_lines

    bodies = travel_lines(profile, assembly, start, end, "travel to the job's start")
    link.stream(from_firmware_lines(profile, bodies, start))
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


def stream_moves(link: GrblLink, profile: Profile, bodies: list[str],
                 start: tuple[int, int], timeout_s: float = 120.0) -> tuple[int, int]:
    """Run fivebar's checked laser-off lines (jog, frame) on the board; the end position."""
    link.stream(from_firmware_lines(profile, bodies, start))
    return position_steps(link, profile, link.wait_idle(timeout_s))


def angles_text(profile: Profile, pos: tuple[int, int]) -> str:
    """Steps → the motor angles the board's work coordinates show."""
    h = np.degrees(np.asarray(profile.motors.home_rad))
    a = h + np.asarray(pos) / steps_per_degree(profile)
    return f"X {a[0]:.3f}°, Y {a[1]:.3f}°"
