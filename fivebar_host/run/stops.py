"""Planned stops of a run: pen changes between layers, copies and the page delay between them.

A job with pen-change stops (`Job.pauses`, `compile.layers`) is streamed in pieces: the
segments up to a stop run as one program that ends with the pen up (laser off), the host
waits until the machine is idle (queue drained, no motion) and asks (`on_pause`: the CLI on
the terminal, the daemon through its pause state); then the next piece streams from exactly
where the machine stands. `--copies N` runs the whole job N times; between copies the arms
are parked at the homed pose (the job's last move), the pen is up, and the host waits
`--page-delay` seconds, polling the machine and honouring a stop request like a stream does.

Quitting at a stop writes the same resume point a fault writes (`run.job.stopped`), exact:
the next segment is the stop's segment, the position the machine's, the copy the one running.
A `--resume` that starts exactly at a pen-change stop does not stop there again (the person
who resumed has changed the pen). The run itself is `run.job.run_job`; this module is the
arithmetic of its stops and copies.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from fivebar_host.compile import Job
from fivebar_host.compile.model import LayerPause


@dataclass(frozen=True)
class Copies:
    """How many times the job runs (`--copies`) and the wait between copies, s."""

    count: int = 1
    page_delay_s: float = 0.0

    def __post_init__(self) -> None:
        if self.count < 1 or self.page_delay_s < 0.0:
            raise ValueError(f"bad copies {self.count} / page delay {self.page_delay_s}")


@dataclass(frozen=True)
class Piece:
    """Segments `begin` … `end` − 1 streamed as one program; `pause` the stop before it."""

    begin: int
    end: int
    pause: LayerPause | None


def pieces(job: Job, start: int, resumed: bool) -> list[Piece]:
    """The programs a run from segment `start` streams, split at the pen-change stops. A
    stop at `start` itself is kept unless the run is `resumed` there (module doc)."""
    cuts = [p for p in job.pauses if p.segment > start or (p.segment == start and not resumed)]
    out: list[Piece] = []
    begin, pause = start, None
    for p in cuts:
        if p.segment > begin:
            out.append(Piece(begin, p.segment, pause))
            begin = p.segment
        pause = p
    out.append(Piece(begin, job.n_segments, pause))
    return [pc for pc in out if pc.end > pc.begin or pc.pause is not None]


def piece_end(job: Job, start: int) -> int | None:
    """The segment a program streamed from `start` ends before: the next pen-change stop
    after it (None: the job's end). Rebuilding a stream needs only its start (`pieces`)."""
    return next((p.segment for p in job.pauses if p.segment > start), None)


def pause_count(job: Job, copies: Copies) -> int:
    """How many times the run stops for a pen change, over all copies."""
    return len(job.pauses) * copies.count


def planned_time_s(job: Job, copies: Copies) -> float:
    """The run's planned time: every copy and the page delays between them (the pen
    changes wait for a person and are not counted)."""
    return copies.count * job.total_time_s + (copies.count - 1) * copies.page_delay_s


def later_copies_s(job: Job, copies: Copies, copy: int) -> float:
    """The planned time of the copies after copy `copy` (1-based), page delays included."""
    return (copies.count - copy) * (job.total_time_s + copies.page_delay_s)


def plan_text(job: Job, copies: Copies, fmt: Callable[[float], str]) -> str:
    """The run's planned time for people, with copies, page delays and pen changes:
    "≈ 1 min 2 s (2 copies of ≈ 25.0 s + 1 page delay of 15 s) + 2 pen changes (wait for
    you)"; just "≈ 25.0 s" for one copy without stops. `fmt` formats a duration."""
    text = f"≈ {fmt(planned_time_s(job, copies))}"
    n = copies.count
    if n > 1:
        text += (f" ({n} copies of ≈ {fmt(job.total_time_s)} + {n - 1} page "
                 f"delay{'s' if n > 2 else ''} of {copies.page_delay_s:g} s)")
    changes = pause_count(job, copies)
    if changes:
        text += f" + {changes} pen change{'s' if changes > 1 else ''} (wait for you)"
    return text
