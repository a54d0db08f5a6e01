"""Timer1's compare writes, from the emulator harness's log (fbsim ``-D``, ``timers=FILE``).

The firmware schedules every step and every pixel change by writing a timer time into a
compare register of the free-running 16-bit Timer1 (OCR1A for the steps, OCR1B for the pixel
timeline).  A compare fires when the count passes its value, so one written at or behind the
count fires only after the timer has wrapped: a whole timer period, 65,536 cycles (4.1 ms at
16 MHz), late, and with it everything scheduled after it.  No code path may do that; the
harness's log shows each write with the count at that instant, so a run can be checked for
every write it made.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from fivebar_host.devices.simtrace import TraceError

#: The log's unit codes: OCR1A's writes ("w", the steps) and OCR1B's ("b", the pixels).
UNITS = {"w": "OCR1A", "b": "OCR1B"}
PERIOD = 1 << 16


@dataclass(frozen=True)
class CompareWrite:
    """One write of a compare register: its cycle, which register, its value and the timer's
    count when the write completed."""

    cycle: int
    register: str
    value: int
    count: int

    @property
    def lead(self) -> int:
        """Cycles from the write to the compare's match, as the 16-bit difference the
        firmware compares (negative or 0: the compare is behind the timer)."""
        d = (self.value - self.count) % PERIOD
        return d - PERIOD if d >= PERIOD // 2 else d


def read_writes(path: str | Path) -> list[CompareWrite]:
    """Every compare write in the log, in order (its reads are skipped); TraceError names
    the first malformed line."""
    out: list[CompareWrite] = []
    with open(path, encoding="ascii") as f:
        for number, line in enumerate(f, start=1):
            parts = line.split()
            if len(parts) != 4 or parts[1] not in ("r", *UNITS) or not all(
                    p.isdigit() for p in (parts[0], parts[2], parts[3])):
                raise TraceError(f"{path}:{number}: {line.strip()!r} is not "
                                 "'<cycle> r|w|b <compare> <count>'")
            if parts[1] != "r":
                out.append(CompareWrite(int(parts[0]), UNITS[parts[1]], int(parts[2]),
                                        int(parts[3])))
    return out


def late_compares(path: str | Path) -> list[CompareWrite]:
    """The writes that armed a compare at or behind the timer's count (module doc)."""
    return [w for w in read_writes(path) if w.lead <= 0]
