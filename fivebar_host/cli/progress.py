"""Compile progress on the terminal: a bar on a TTY, a line every few seconds otherwise.

Nothing is shown for a compile that is done within `QUIET_S` (most drawings); a time
estimate the pipeline makes before long work (`progress.estimate`) is shown at once. Written
to stderr, so a command's own output (and `convert -o -`-style pipes) stays clean.
"""

from __future__ import annotations

import contextlib
import sys
import time
from collections.abc import Iterator
from typing import TextIO

from fivebar_host.progress import Event, listening_with

#: A compile quicker than this shows no progress at all, s.
QUIET_S = 2.0
#: Without a terminal: at most one line this often, s.
LINE_EVERY_S = 3.0
#: On a terminal: the bar is redrawn at most this often, s.
BAR_EVERY_S = 0.1
BAR_WIDTH = 24


class CompileProgress:
    """Listens to `fivebar_host.progress` and draws what it hears (module doc)."""

    def __init__(self, out: TextIO | None = None, tty: bool | None = None) -> None:
        self.out = out or sys.stderr
        self.tty = self.out.isatty() if tty is None else tty
        self.t0 = time.monotonic()
        self.next_at = self.t0 + QUIET_S
        self.drawn = False  # a bar is on the current line

    def __call__(self, ev: Event) -> None:
        now = time.monotonic()
        if ev.note is not None:
            self._line(f"compiling: {ev.note}")
            return
        if now < self.next_at:
            return
        elapsed = now - self.t0
        pct = "" if ev.fraction is None else f" {100 * ev.fraction:.0f}%"
        if self.tty:
            done = 0 if ev.fraction is None else round(BAR_WIDTH * ev.fraction)
            bar = f" [{'#' * done}{'.' * (BAR_WIDTH - done)}]" if ev.fraction is not None else ""
            self.out.write(f"\r\x1b[Kcompiling: {ev.stage}{bar}{pct} ({elapsed:.0f} s)")
            self.out.flush()
            self.drawn = True
            self.next_at = now + BAR_EVERY_S
        else:
            self._line(f"compiling: {ev.stage}{pct} ({elapsed:.0f} s)")
            self.next_at = now + LINE_EVERY_S

    def _line(self, text: str) -> None:
        if self.drawn:
            self.out.write("\r\x1b[K")
            self.drawn = False
        self.out.write(text + "\n")
        self.out.flush()

    def close(self) -> None:
        """End the bar's line (the command's own output follows)."""
        if self.drawn:
            self.out.write("\r\x1b[K")
            self.out.flush()
            self.drawn = False


@contextlib.contextmanager
def compile_progress() -> Iterator[CompileProgress]:
    """Show the progress of the compiles run inside the `with` (module doc)."""
    shown = CompileProgress()
    try:
        with listening_with(shown):
            yield shown
    finally:
        shown.close()
