"""Resume after a fault on a stock GRBL board (`plot --resume --controller grbl`).

**What is exact.** The path: every line is a straight joint-space move whose targets are the
job's steps, so "where on the job" is a question of joint angles only. The stop position:
after a finished hold GRBL keeps its machine position across Ctrl-X, and `?` reports it
(MPos, degrees, 3 decimals = 1/28 step here), so the fault writes it to the resume file in
steps, exactly.

**What is not.** GRBL's `ok` means "parsed and planned" and carries no line number: the
count of `ok`s is an upper bound on what ran (the executing block is one of the last ~16
planned: 15 planner blocks, and oks still in transit). The segment is therefore identified
by searching the joint-space lines of that window (`WINDOW` lines before the last `ok` up to
the last line sent) for the stop position. When two different places in that window pass
through the same angles, the stop cannot be identified: the resume file says so and
`--resume` is refused with the reason (`GrblResumeError`). GRBL keeps no position across a
reboot (opening an Uno's port reboots it) or a power loss and has no "position known" flag,
so `--resume` trusts the board's count only when it still shows the stop position;
otherwise a person confirms the arms are where the job stopped (`--yes` does not answer, as
on fivebar's own path), or, with endstops, the board homes and travels back laser-off.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from fivebar_host.compile import Job
from fivebar_host.config import Profile
from fivebar_host.controllers.grbl.link import GrblError, GrblLink, StreamState
from fivebar_host.controllers.grbl.program import GrblProgram
from fivebar_host.program import line_param
from fivebar_host.run.errors import PowerLossError
from fivebar_host.run.resume import ResumePoint, fingerprint

#: Lines before the last `ok` that may still be executing: GRBL's 15 planner blocks + 1.
WINDOW = 16


class GrblResumeError(GrblError):
    """A GRBL resume that cannot continue exactly (file from another job, the stop not
    identified, the board's position off the stopped segment): nothing was sent."""


def identify(prog: GrblProgram, job: Job, pos: tuple[int, int], state: StreamState
             ) -> tuple[int | None, str]:
    """The first unfinished segment for a board stopped at `pos`, or (None, why not)."""
    lo, hi = state.acked - WINDOW, max(state.sent, state.acked)
    found = prog.candidates(pos, job, lo, hi)
    if len(found) == 1:
        return found[0], ""
    if not found:
        return None, (f"the position A = {pos[0]}, B = {pos[1]} steps lies on none of the "
                      f"lines GRBL may have been executing (lines {max(lo, 0) + 1}..{hi})")
    return None, (f"ambiguous: the path passes A = {pos[0]}, B = {pos[1]} steps in segments "
                  f"{', '.join(str(k) for k in found)}, all within the last lines GRBL may "
                  "have been executing (its ok carries no line number)")


def fault_point(job: Job, prog: GrblProgram, drawing: str | Path, state: StreamState,
                pos: tuple[int, int] | None, reason: str) -> tuple[ResumePoint, str]:
    """The resume file for a stopped GRBL stream and the sentence for the user.

    `pos` is the board's position read after hold + reset, None when it is not trustworthy
    (not read, an alarm, the board restarted)."""
    first = int(prog.segment[: max(state.acked, 0)].max(initial=-1)) + 1
    if pos is None:
        why = f"the stop position is not known ({reason})"
        rp = ResumePoint(str(drawing), fingerprint(job), max(first - WINDOW, 0), None,
                         f"{reason}; not resumable: {why}", job.n_segments)
        return rp, f"{why}: --resume is not possible; home and run the job again"
    k, why = identify(prog, job, pos, state)
    if k is None:
        rp = ResumePoint(str(drawing), fingerprint(job), max(first - WINDOW, 0), pos,
                         f"{reason}; not resumable: {why}", job.n_segments)
        return rp, f"the stopped segment cannot be identified ({why}): --resume is refused"
    rp = ResumePoint(str(drawing), fingerprint(job), k, pos, reason, job.n_segments)
    return rp, (f"The pen stopped at A = {pos[0]}, B = {pos[1]} steps (exact, from MPos), in "
                f"segment {k} of {job.n_segments} (found from the {state.acked} lines GRBL "
                "acknowledged and that position; GRBL reports no line numbers). Segments "
                "before it are drawn; --resume continues from there")


def load_point(rpath: Path, job: Job) -> ResumePoint:
    """The resume file, refused when it belongs to another job or was not resumable."""
    rp = ResumePoint.load(rpath)
    if rp.fingerprint != fingerprint(job) or rp.segments != job.n_segments:
        raise GrblResumeError(f"{rpath}: the resume file belongs to a different job (drawing "
                              "or options changed); run the same command as before with "
                              "--resume. Nothing was sent.")
    if "not resumable:" in rp.reason or rp.position is None:
        raise GrblResumeError(f"{rpath}: this stop cannot be resumed on GRBL: {rp.reason}. "
                              "Nothing was sent.")
    k = rp.next_segment
    if k < job.n_segments and line_param(job.steps[k], job.steps[k + 1], rp.position) is None:
        raise GrblResumeError(f"{rpath}: A = {rp.position[0]}, B = {rp.position[1]} steps does "
                              f"not lie on segment {k}'s joint-space line. Nothing was sent.")
    return rp


def resume_pose(link: GrblLink, job: Job, profile: Profile, rp: ResumePoint,
                confirm_placed: Callable[[str], bool], note: Callable[[str], None],
                travel: Callable[[tuple[int, int], tuple[int, int]], None]) -> tuple[int, int]:
    """Make the board's count agree with the stop position (module doc); returns it."""
    from fivebar_host.controllers.grbl.run import position_steps

    assert rp.position is not None
    stop = rp.position
    st = link.status()
    if st.state != "Idle" and not profile.motors.endstops:
        raise GrblResumeError(f"{link.url}: the board is in {st.state}; clear it ($X) and "
                              "run this command again. Nothing was sent.")
    if st.state == "Idle" and position_steps(link, profile, st) == stop:
        note(f"resuming segment {rp.next_segment} of {job.n_segments} from A = {stop[0]}, "
             f"B = {stop[1]} steps: the board kept its position since the stop (exact)")
        return stop
    if profile.motors.endstops:
        from fivebar_host.controllers.grbl.program import work_offset_line

        link.command("$H", timeout_s=120.0)
        link.command(work_offset_line(profile))
        pos = position_steps(link, profile, link.status())
        note("the board lost its position: homed; travelling back to the stop, laser off")
        travel(pos, stop)
        return stop
    a, b = (math.degrees(profile.motors.home_rad[i]) + stop[i] * 360.0
            / profile.motors.steps_per_rev for i in range(2))
    if not confirm_placed(f"GRBL lost its count since the stop (it rebooted when the port "
                          f"opened, or lost power). Are the arms still exactly where the job "
                          f"stopped (θ1 = {a:.4f}°, θ2 = {b:.4f}°)?"):
        raise PowerLossError(
            f"{link.url}: GRBL's position since the stop is unknown, and --yes does not "
            "answer for where the arms are after a reboot or power loss. Run this command "
            "on a terminal without --yes and confirm there, or home and run the job again. "
            "Nothing was sent.")
    st = link.status()
    link.command(f"G10 L2 P1 X{st.machine[0] - a:.4f} Y{st.machine[1] - b:.4f}")
    pos = position_steps(link, profile, link.status())
    if not np.array_equal(pos, stop):
        raise GrblResumeError(f"{link.url}: the work offset did not take (A = {pos[0]}, "
                              f"B = {pos[1]} steps, wanted {stop}). Nothing was sent.")
    note(f"resuming segment {rp.next_segment} of {job.n_segments} from the confirmed stop "
         f"position A = {stop[0]}, B = {stop[1]} steps")
    return stop
