"""The operator of a run: who answers a run's questions and hears how it goes.

A run (`run.job.run_job`) asks a person things only a person can know — are the arms at the
home pose, where are they after a power loss, is the new pen in — and tells them where the
job is. Who that person is depends on the face: the terminal of `fivebar plot`
(`cli.operator.TerminalOperator`), the web page and API of the daemon
(`server.operator.DaemonOperator`), nobody at all (`QuietOperator`: scripts, tests). The run
knows only this protocol, so each face answers in its own way and a new face adds no
parameter to the run.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from fivebar_host.compile.model import LayerPause


@dataclass(frozen=True)
class Progress:
    """Progress in job terms, for progress bars (`copy` of `copies`, 1-based)."""

    segments_done: int
    segments_total: int
    elapsed_s: float
    remaining_s: float
    copy: int = 1
    copies: int = 1


class Operator(Protocol):
    """The person (or the daemon standing in for one) a run asks and tells."""

    #: Someone is there to answer a pen change (`pen_change`); a job with pen-change stops
    #: is refused before anything moves when nobody is.
    attended: bool

    def confirm(self, question: str) -> bool:
        """Yes/no about the machine's pose before a job ("are the arms at the home pose?");
        `--yes` may answer it."""
        ...

    def confirm_placed(self, question: str) -> bool:
        """Yes/no about where the arms are after a power loss: only a person may answer
        it (never `--yes`); no moves nothing."""
        ...

    def note(self, text: str) -> None:
        """Something the person should know before the run goes on (where a resume starts,
        what may be drawn twice)."""
        ...

    def progress(self, p: Progress) -> None:
        """The run advanced (called often: keep it quick)."""
        ...

    def should_stop(self) -> bool:
        """Whether to hold the machine now (Ctrl-C, pause, cancel); polled while streaming
        and waiting."""
        ...

    def interrupted(self) -> bool:
        """The machine is held after `should_stop`: True resumes, False gives up (the run
        stops with an exact resume point)."""
        ...

    def pen_change(self, pause: LayerPause) -> bool:
        """The machine is idle with the pen up before `pause`'s layer: True goes on, False
        quits with an exact resume point."""
        ...

    def waiting(self, left_s: float) -> None:
        """The page delay between copies: the seconds left (about 10 times a second)."""
        ...

    def copy_started(self, copy: int) -> None:
        """Copy `copy` (1-based) starts, a resumed one included, before its first line."""
        ...


class QuietOperator:
    """Nobody there: no question is answered yes, nothing is shown, nothing stops the run.

    The base of the faces' operators, which override what they answer."""

    attended = False

    def confirm(self, question: str) -> bool:
        return False

    def confirm_placed(self, question: str) -> bool:
        return False

    def note(self, text: str) -> None:
        return None

    def progress(self, p: Progress) -> None:
        return None

    def should_stop(self) -> bool:
        return False

    def interrupted(self) -> bool:
        return False

    def pen_change(self, pause: LayerPause) -> bool:
        return False

    def waiting(self, left_s: float) -> None:
        return None

    def copy_started(self, copy: int) -> None:
        return None


class Answering(QuietOperator):
    """Nobody there, but the pose questions have a known answer (the daemon's "the arms are
    at the home pose" flag, a script's `--yes`): `confirm` says `yes`; a power loss still
    waits for a person."""

    def __init__(self, yes: bool) -> None:
        self.yes = yes

    def confirm(self, question: str) -> bool:
        return self.yes
