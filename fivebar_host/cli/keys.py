"""Override keys on a terminal while `fivebar plot` streams: `-` / `+` (or `=`) feed down /
up, `[` / `]` laser power down / up, each by `run.overrides.STEP_PCT`.

The terminal is put in cbreak mode (keys arrive at once, unechoed; Ctrl-C still sends
SIGINT, so the hold/resume prompt works as before) only when stdin is a terminal, and is
restored on every way out. Keys are read without blocking (`select` with no wait) when the
stream polls, between its turns, so no thread reads the terminal and nothing competes with
the prompt: while it asks, the reader is paused and the terminal is back in its own mode.
"""

from __future__ import annotations

import os
import select
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any, TextIO

from fivebar_host.run.overrides import Overrides

#: key → (feed steps, power steps)
KEYS: dict[str, tuple[int, int]] = {
    "-": (-1, 0), "_": (-1, 0), "+": (1, 0), "=": (1, 0), "[": (0, -1), "]": (0, 1)}

HELP = ("keys: - / + feed 10–100 %, [ / ] laser power 0–100 % (in 10 % steps; they reach the "
        "lines not yet sent, after the ≈ 15 segments the controller already holds; feed "
        "changes where the plan stops: pen lifts, power changes, dwells)")


def apply_keys(text: str, overrides: Overrides) -> bool:
    """Apply every override key in `text` (other characters are ignored); whether any
    factor changed."""
    before = overrides.values()
    for ch in text:
        feed, power = KEYS.get(ch, (0, 0))
        if feed or power:
            overrides.step(feed, power)
    return overrides.values() != before


class KeyReader:
    """Reads the keys waiting on file descriptor `fd` without blocking and applies them."""

    def __init__(self, fd: int, overrides: Overrides) -> None:
        self.fd = fd
        self.overrides = overrides
        self.paused_now = False

    def poll(self) -> bool:
        """Apply the keys that arrived since the last poll; whether a factor changed."""
        if self.paused_now:
            return False
        data = b""
        while select.select([self.fd], [], [], 0)[0]:
            chunk = os.read(self.fd, 64)
            if not chunk:  # end of input
                break
            data += chunk
        return apply_keys(data.decode("ascii", "ignore"), self.overrides)

    @contextmanager
    def paused(self) -> Iterator[None]:
        """No key reading, and the terminal in its own mode, for a prompt."""
        self.paused_now = True
        try:
            with _cooked(self.fd):
                yield
        finally:
            self.paused_now = False


@contextmanager
def _cooked(fd: int) -> Iterator[None]:
    """The terminal's mode from before `override_keys` (a no-op on a non-terminal)."""
    saved = _SAVED.get(fd)
    if saved is None:
        yield
        return
    import termios
    import tty

    termios.tcsetattr(fd, termios.TCSADRAIN, saved)
    try:
        yield
    finally:
        tty.setcbreak(fd, termios.TCSADRAIN)


_SAVED: dict[int, Any] = {}  # fd → its termios attributes before cbreak


@contextmanager
def override_keys(overrides: Overrides, stream: TextIO | None = None
                  ) -> Iterator[KeyReader | None]:
    """A `KeyReader` on `stream` (stdin) in cbreak mode while the block runs, the terminal
    restored after it; None (no keys) when `stream` is not a terminal."""
    stream = stream if stream is not None else sys.stdin
    try:
        fd = stream.fileno()
    except (OSError, ValueError, AttributeError):  # pytest's capture, a closed stdin
        yield None
        return
    if not os.isatty(fd):
        yield None
        return
    import termios
    import tty

    _SAVED[fd] = termios.tcgetattr(fd)
    try:
        tty.setcbreak(fd, termios.TCSADRAIN)
        yield KeyReader(fd, overrides)
    finally:
        termios.tcsetattr(fd, termios.TCSADRAIN, _SAVED.pop(fd))
