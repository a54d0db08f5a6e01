"""fivebar's firmware keeps its position, `H` and `Ln` done across a reset (docs/protocol.md 7):
mapping that record back to the exact segment of the stream that ran.

After a fault, a restart or a daemon crash the controller's record says which line it
executed last and where the arms stand; the stream it belongs to is rebuilt from its inputs
(`run.moves.build_program`: start segment, start position, laser, end) and the record is
taken only when it fits that stream: homed, its last line one of the stream's, the position
on the stream's path just after it.
"""

from __future__ import annotations

from numpy.typing import ArrayLike

from fivebar_host.compile import Job
from fivebar_host.config import Profile
from fivebar_host.program import Program
from fivebar_host.protocol import StatusReport
from fivebar_host.run.errors import SendError
from fivebar_host.run.moves import build_program
from fivebar_host.run.resume import ResumePoint


def kept_resume_segment(prog: Program, first_line: int, start: int, start_position: ArrayLike,
                        st: StatusReport, floor: int) -> tuple[int | None, str]:
    """The exact first unfinished segment from a controller's record kept across a reset.

    A reset that leaves the RAM powered keeps the position, `H` and `Ln` done
    (docs/protocol.md 7). `prog` is the stream that ran, from firmware line `first_line`,
    built from segment `start` at `start_position`; `st` is a status report read after the
    reset, motion over. The record is this stream's when `H:1`, its done line is one of the
    stream's lines (or the one before the first), the segment it maps to is not before
    `floor` (a segment a status report of the stream had already confirmed) and the position
    lies on the stream's path just after that line. Returns (segment, "") or (None, why not):
    power was lost, or something else ran on the controller since.
    """
    last = first_line + len(prog) - 1
    if not st.homed:
        return None, "it reports H:0, its position is unknown: it lost power"
    if not first_line - 1 <= st.done_line <= last:
        return None, (f"its last executed line {st.done_line} is not one of the stream's "
                      f"lines {first_line}..{last}")
    nxt = prog.finished_segments(first_line, st.done_line, start)
    if nxt < floor:
        return None, (f"its last executed line {st.done_line} would mean {nxt} segments done, "
                      f"fewer than the {floor} a status report had confirmed")
    if not prog.on_path(first_line, st.done_line, start_position, (st.a, st.b)):
        return None, (f"its position A = {st.a}, B = {st.b} is not on the stream's path after "
                      f"line {st.done_line}")
    return nxt, ""


def kept_stream_segment(job: Job, profile: Profile, rp: ResumePoint, st: StatusReport
                        ) -> tuple[int | None, str]:
    """`kept_resume_segment` for the interrupted stream `rp` describes (`rp.has_stream`).

    The stream is rebuilt from `build_program`'s inputs the resume file kept; it must come
    out as long as the stream that ran. Returns (segment, "") or (None, why not).
    """
    assert (rp.first_line is not None and rp.last_line is not None
            and rp.stream_start is not None and rp.start_position is not None
            and rp.laser is not None)
    try:
        prog = build_program(job, profile, rp.laser, rp.stream_start, rp.start_position,
                             rp.stream_end)
    except SendError as e:
        return None, f"the interrupted stream cannot be rebuilt: {e}"
    if len(prog) != rp.last_line - rp.first_line + 1:
        return None, "the interrupted stream cannot be rebuilt the same"
    return kept_resume_segment(prog, rp.first_line, rp.stream_start, rp.start_position, st,
                               rp.next_segment)
