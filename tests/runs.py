"""Running a job in the tests: `run.job.run_job` with an operator made of plain callables.

The tests script a person's answers (confirm, Ctrl-C, a pen change) as small functions; this
turns them into an `Operator`, puts the resume file beside `drawing` (`FileStore`) and opens
nothing: the caller gives an open link (fivebar's `Link` or a `GrblLink`) or a controller.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from fivebar_host.compile import Job
from fivebar_host.compile.model import LayerPause
from fivebar_host.config import Profile
from fivebar_host.controllers.fivebar.controller import FivebarController
from fivebar_host.controllers.fivebar.link import Link
from fivebar_host.controllers.grbl.controller import GrblController
from fivebar_host.controllers.grbl.link import GrblLink
from fivebar_host.run.controller import Controller
from fivebar_host.run.job import RunOptions, RunReport, run_job
from fivebar_host.run.operator import Progress, QuietOperator
from fivebar_host.run.overrides import Overrides
from fivebar_host.run.stops import Copies
from fivebar_host.run.store import FileStore


class ScriptedOperator(QuietOperator):
    """An operator whose answers are the test's functions (None: the quiet answer)."""

    def __init__(self, confirm: Callable[[str], bool],
                 confirm_placed: Callable[[str], bool] | None = None,
                 on_note: Callable[[str], None] | None = None,
                 on_progress: Callable[[Progress], None] | None = None,
                 should_stop: Callable[[], bool] | None = None,
                 on_interrupt: Callable[[], bool] | None = None,
                 on_pause: Callable[[LayerPause], bool] | None = None,
                 on_wait: Callable[[float], None] | None = None,
                 on_copy: Callable[[int], None] | None = None) -> None:
        self._confirm = confirm
        self._placed = confirm_placed or confirm
        self._note = on_note
        self._progress = on_progress
        self._stop = should_stop
        self._interrupt = on_interrupt
        self._pause = on_pause
        self._wait = on_wait
        self._copy = on_copy
        self.attended = on_pause is not None

    def confirm(self, question: str) -> bool:
        return self._confirm(question)

    def confirm_placed(self, question: str) -> bool:
        return self._placed(question)

    def note(self, text: str) -> None:
        if self._note is not None:
            self._note(text)

    def progress(self, p: Progress) -> None:
        if self._progress is not None:
            self._progress(p)

    def should_stop(self) -> bool:
        return self._stop is not None and self._stop()

    def interrupted(self) -> bool:
        return self._interrupt is not None and self._interrupt()

    def pen_change(self, pause: LayerPause) -> bool:
        return self._pause is not None and self._pause(pause)

    def waiting(self, left_s: float) -> None:
        if self._wait is not None:
            self._wait(left_s)

    def copy_started(self, copy: int) -> None:
        if self._copy is not None:
            self._copy(copy)


def controller_of(target: Any, prof: Profile) -> Controller:
    """The controller over an open link (or the controller itself)."""
    if isinstance(target, Link):
        return FivebarController(target, prof)
    if isinstance(target, GrblLink):
        return GrblController(target, prof)
    return target  # type: ignore[no-any-return]


def run_with(target: Any, job: Job, prof: Profile, *, drawing: str | Path, laser: bool,
             confirm: Callable[[str], bool], resume: bool = False,
             overrides: Overrides | None = None, copies: Copies | None = None,
             **answers: Any) -> RunReport:
    """`run_job` on `target` with the scripted answers (`ScriptedOperator`'s keywords)."""
    return run_job(controller_of(target, prof), job, ScriptedOperator(confirm, **answers),
                   FileStore.beside(drawing),
                   RunOptions(laser, resume, copies or Copies(), overrides))
