"""Progress of long work (compiling a large drawing), told to whoever listens.

A compile of a million tiny paths takes minutes; without a word it looks hung. The pipeline
calls `report(stage, fraction)` at its stages and inside the long loops (the SVG reader by
bytes parsed, path ordering by paths placed), and `estimate(text)` once it knows the size
of the work; nobody listens unless a face installs a listener for the duration of a call
with `listening(fn)` — the terminal (`cli.progress`), the daemon's compiling process (sent
to the page). A context variable carries the listener, so threads and other calls are not
affected, and `report` costs one lookup when nobody listens.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterator
from contextvars import ContextVar
from dataclasses import dataclass


@dataclass(frozen=True)
class Event:
    """One report: the stage ("reading", "ordering paths" …), how far it is (0–1, or None
    when unknown), and `note`: a sentence for the person (the time estimate), if any."""

    stage: str
    fraction: float | None = None
    note: str | None = None


Listener = Callable[[Event], None]
_listener: ContextVar[Listener | None] = ContextVar("fivebar_progress", default=None)


def report(stage: str, fraction: float | None = None) -> None:
    """Tell the listener (if any) that `stage` is `fraction` done."""
    fn = _listener.get()
    if fn is not None:
        fn(Event(stage, None if fraction is None else min(1.0, max(0.0, fraction))))


def estimate(note: str) -> None:
    """Tell the listener (if any) a sentence about the work ahead (its size, its time)."""
    fn = _listener.get()
    if fn is not None:
        fn(Event("estimate", None, note))


def listening() -> bool:
    """Whether anybody listens (skip building reports nobody reads)."""
    return _listener.get() is not None


@contextlib.contextmanager
def listening_with(fn: Listener) -> Iterator[None]:
    """Send the reports made inside the `with` (in this context) to `fn`."""
    token = _listener.set(fn)
    try:
        yield
    finally:
        _listener.reset(token)


class Ticker:
    """Reports a loop's progress at most every `every_s` seconds (a check of the clock every
    `stride` items), so a tight loop pays almost nothing for it."""

    def __init__(self, stage: str, total: int, every_s: float = 0.5, stride: int = 4096
                 ) -> None:
        self.stage = stage
        self.total = max(1, total)
        self.every_s = every_s
        self.stride = stride
        self.active = listening()
        self._next = time.monotonic() + every_s

    def tick(self, done: int) -> None:
        """`done` of `total` items are through."""
        if not self.active or done % self.stride:
            return
        now = time.monotonic()
        if now >= self._next:
            self._next = now + self.every_s
            report(self.stage, done / self.total)
