"""Resume after a fault on a stock GRBL board (`plot --resume --controller grbl`): where the
pen stopped, and whether that stop can be resumed (`GrblController.resume_start` then makes
the board's count agree with it).

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

from fivebar_host.compile import Job
from fivebar_host.controllers.grbl.link import GrblError, StreamState
from fivebar_host.controllers.grbl.program import GrblProgram
from fivebar_host.program import line_param
from fivebar_host.run.resume import ResumePoint, fingerprint

Position = tuple[int, int]

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


def fault_point(job: Job, prog: GrblProgram, state: StreamState, pos: Position | None,
                reason: str, copy: int) -> tuple[ResumePoint, str]:
    """The resume point of a stopped GRBL stream and the sentence for the user.

    `pos` is the board's position read after hold + reset, None when it is not trustworthy
    (not read, an alarm, the board restarted)."""
    first = int(prog.segment[: max(state.acked, 0)].max(initial=-1)) + 1
    drawing, fp, n = str(job.file), fingerprint(job), job.n_segments
    if pos is None:
        why = f"the stop position is not known ({reason})"
        rp = ResumePoint(drawing, fp, max(first - WINDOW, 0), None,
                         f"{reason}; not resumable: {why}", n, copy=copy)
        return rp, f"{why}: --resume is not possible; home and run the job again"
    k, why = identify(prog, job, pos, state)
    if k is None:
        rp = ResumePoint(drawing, fp, max(first - WINDOW, 0), pos,
                         f"{reason}; not resumable: {why}", n, copy=copy)
        return rp, f"the stopped segment cannot be identified ({why}): --resume is refused"
    rp = ResumePoint(drawing, fp, k, pos, reason, n, copy=copy)
    return rp, (f"The pen stopped at A = {pos[0]}, B = {pos[1]} steps (exact, from MPos), in "
                f"segment {k} of {n} (found from the {state.acked} lines GRBL acknowledged "
                "and that position; GRBL reports no line numbers). Segments before it are "
                "drawn; --resume continues from there")


def check_point(point: ResumePoint, job: Job) -> Position:
    """The stop position of a saved point, refused when the stop was not resumable or the
    position is off the stopped segment's line (the run checked the job's fingerprint)."""
    if "not resumable:" in point.reason or point.position is None:
        raise GrblResumeError(f"this stop cannot be resumed on GRBL: {point.reason}. "
                              "Nothing was sent.")
    k, pos = point.next_segment, point.position
    if k < job.n_segments and line_param(job.steps[k], job.steps[k + 1], pos) is None:
        raise GrblResumeError(f"A = {pos[0]}, B = {pos[1]} steps does not lie on segment "
                              f"{k}'s joint-space line. Nothing was sent.")
    return pos
