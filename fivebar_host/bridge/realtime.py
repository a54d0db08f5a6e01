"""The sender's byte stream as GRBL's serial layer sees it: real-time bytes picked out the
moment they arrive, wherever they are, and everything else assembled into lines.

GRBL 1.1 real-time commands: `?` status, `!` feed hold, `~` cycle start, 0x18 (Ctrl-X) soft
reset, 0x85 jog cancel, 0x90–0x9D feed / rapid / spindle overrides, 0x9E spindle stop,
0xA0/0xA1 coolant toggles; other bytes ≥ 0x80 are ignored. A line ends at `\\n` or `\\r`
(each one: GRBL answers an empty line with `ok`); other control bytes are dropped. A line
longer than `RAW_LINE_MAX` is kept short and marked overflowing (GRBL's `error:11`), so binary
garbage can never grow memory.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

RT_STATUS = 0x3F
RT_HOLD = 0x21
RT_CYCLE_START = 0x7E
RT_RESET = 0x18
RT_JOG_CANCEL = 0x85
RT_SPINDLE_STOP = 0x9E
RAW_LINE_MAX = 256


@dataclass
class Overrides:
    """Feed, rapid and spindle (laser power) overrides in percent, as GRBL keeps them."""

    feed: int = 100
    rapid: int = 100
    spindle: int = 100

    def apply(self, byte: int) -> bool:
        """Act on an override byte (0x90–0x9D); False if it is not one."""
        if 0x90 <= byte <= 0x94:
            step = {0x90: None, 0x91: 10, 0x92: -10, 0x93: 1, 0x94: -1}[byte]
            self.feed = 100 if step is None else min(200, max(10, self.feed + step))
        elif 0x95 <= byte <= 0x97:
            self.rapid = {0x95: 100, 0x96: 50, 0x97: 25}[byte]
        elif 0x99 <= byte <= 0x9D:
            step = {0x99: None, 0x9A: 10, 0x9B: -10, 0x9C: 1, 0x9D: -1}[byte]
            self.spindle = 100 if step is None else min(200, max(10, self.spindle + step))
        else:
            return False
        return True

    def tuple(self) -> tuple[int, int, int]:
        return (self.feed, self.rapid, self.spindle)


class InputBuffer:
    """Bytes from the sender → real-time callbacks (at once) and complete lines (queued)."""

    def __init__(self, on_realtime: Callable[[int], None]) -> None:
        self.on_realtime = on_realtime
        self.lines: deque[tuple[str, bool, int]] = deque()  # (text, overflow, bytes)
        self._partial = bytearray()
        self._partial_bytes = 0
        self._overflow = False
        self._lock = threading.Lock()
        self.cond = threading.Condition(self._lock)

    def feed(self, data: bytes) -> None:
        """Take bytes from the transport (any thread)."""
        for byte in data:
            if byte in (RT_STATUS, RT_HOLD, RT_CYCLE_START, RT_RESET) or byte >= 0x80:
                self.on_realtime(byte)
                continue
            with self._lock:
                self._partial_bytes += 1
                if byte in (0x0A, 0x0D):
                    text = self._partial.decode("ascii", "replace")
                    self.lines.append((text, self._overflow, self._partial_bytes))
                    self._partial.clear()
                    self._partial_bytes = 0
                    self._overflow = False
                    self.cond.notify_all()
                elif byte < 0x20 and byte != 0x09:
                    continue
                elif len(self._partial) >= RAW_LINE_MAX:
                    self._overflow = True
                else:
                    self._partial.append(byte)

    def clear(self) -> None:
        """Ctrl-X: every byte received before it is discarded, as GRBL's buffer reset."""
        with self._lock:
            self.lines.clear()
            self._partial.clear()
            self._partial_bytes = 0
            self._overflow = False
            self.cond.notify_all()

    def drop_partial(self) -> bool:
        """The sender went away: forget a line it did not finish; True when there was none
        (it closed after complete lines, none of them overlong)."""
        with self._lock:
            clean = not self._partial and not self._overflow and not any(
                over for _, over, _ in self.lines)
            self._partial.clear()
            self._partial_bytes = 0
            self._overflow = False
            return clean

    def pending_bytes(self) -> int:
        with self._lock:
            return sum(n for _, _, n in self.lines) + self._partial_bytes

    def take(self, timeout_s: float) -> tuple[str, bool, int] | None:
        """The next complete line, waiting up to `timeout_s`."""
        with self._lock:
            if not self.lines:
                self.cond.wait(timeout_s)
            return self.lines.popleft() if self.lines else None

    def peek_ready(self) -> bool:
        with self._lock:
            return bool(self.lines)
