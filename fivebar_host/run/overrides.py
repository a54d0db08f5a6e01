"""Live feed and laser-power overrides while a job streams, done honestly in the host.

The firmware has no real-time override bytes (docs/protocol.md section 2), so an override
changes the items of the program (`fivebar_host.program`) the host has not sent yet, as their
lines are written: a moving `G1`'s P is stretched by 100/feed %
(slower only: 10–100 %), every `G1`'s S is scaled by power % (0–100 % of the planned power).
Lines already written — those in the firmware's receive buffer and queue, about 15 segments —
keep their values, so an override takes effect after them; and once written, a line is
never changed (a resend sends the same bytes, docs/protocol.md 5.2).

Why slower only, and why a new feed factor starts only at a rest. The plan (`planner`) holds
the joint speed, the junction jump J and the acceleration on the firmware's staircase. Scaling
the durations of a run of segments by one factor k ≥ 1 divides every speed and every speed
jump by k and stretches the times they happen over, so every limit still holds. Changing the
factor between two moving segments would not: at cruise speed ω a change from 100 % to 50 %
is a jump of ω/2 — many times J. But where the plan stops (a pen switch, a laser power
change, a dwell, the start), both neighbours already meet the rest limits (speed ≤ J and
≤ α·P/2 on each side), and any factors ≤ 1 keep them. So the feed factor in force changes
only at the first line that starts at rest (`starts_at_rest`). Power changes need no rest: a
new power factor applies to the next line written. Durations are rounded up to whole µs
(slower, never faster) and capped at the protocol's largest P (a segment that would last
longer runs at that, still no faster than planned); dwells (a `G1` without A/B) keep their
time (as GRBL's feed override leaves G4 alone) and take the power factor.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field

from fivebar_host import protocol
from fivebar_host.program import ABSENT, Kind, Program

#: Feed override range and step, percent of the planned speed (slower only).
FEED_MIN_PCT = 10
FEED_MAX_PCT = 100
#: Laser power override range, percent of the planned S.
POWER_MIN_PCT = 0
POWER_MAX_PCT = 100
#: One key press changes a factor by this much, percent.
STEP_PCT = 10

@dataclass
class Overrides:
    """The requested feed and power factors, in percent (clamped to their ranges); safe to
    change from another thread while a stream reads them."""

    feed_pct: int = FEED_MAX_PCT
    power_pct: int = POWER_MAX_PCT
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False, compare=False)

    def set(self, feed_pct: int | None = None, power_pct: int | None = None) -> None:
        """Set either factor, clamped to its range."""
        with self._lock:
            if feed_pct is not None:
                self.feed_pct = min(FEED_MAX_PCT, max(FEED_MIN_PCT, int(feed_pct)))
            if power_pct is not None:
                self.power_pct = min(POWER_MAX_PCT, max(POWER_MIN_PCT, int(power_pct)))

    def step(self, feed: int = 0, power: int = 0) -> None:
        """Change the factors by `feed` and `power` steps of `STEP_PCT` (negative: down)."""
        with self._lock:
            f, p = self.feed_pct + feed * STEP_PCT, self.power_pct + power * STEP_PCT
        self.set(f, p)

    def values(self) -> tuple[int, int]:
        """(feed %, power %), read together."""
        with self._lock:
            return self.feed_pct, self.power_pct

    def text(self) -> str:
        """For a progress line: "feed 50% power 80%"."""
        f, p = self.values()
        return f"feed {f}% power {p}%"


def scaled(prog: Program, i: int, feed_pct: int, power_pct: int) -> tuple[int, int]:
    """Item `i`'s (P, S) with the override applied (module doc): a move's P stretched by
    100/feed % (rounded up, at most the protocol's largest P), a move's or a dwell's S
    scaled by power % (rounded down); other items unchanged."""
    k, p, s = int(prog.kind[i]), int(prog.p_us[i]), int(prog.s[i])
    if k not in (Kind.MOVE, Kind.DWELL) or (feed_pct == FEED_MAX_PCT
                                            and power_pct == POWER_MAX_PCT):
        return p, s
    if k == Kind.MOVE:
        p = min(protocol.P_MAX_US, max(p, math.ceil(p * FEED_MAX_PCT / feed_pct)))
    if s != ABSENT:
        s = s * power_pct // POWER_MAX_PCT
    return p, s


class OverrideEncoder:
    """Applies `Overrides` to a program's items in the order they are first written: the
    power factor at once, the feed factor from the next item that starts at rest
    (`Program.starts_at_rest`)."""

    def __init__(self, program: Program, overrides: Overrides) -> None:
        self.program = program
        self.rest = program.starts_at_rest()
        self.overrides = overrides
        self.feed_pct = FEED_MAX_PCT  # the factor in force (changes only at a rest)

    def values(self, i: int) -> tuple[int, int]:
        """Item `i`'s (P, S) as it is to be written (items are asked for once each, in
        order)."""
        feed, power = self.overrides.values()
        if feed != self.feed_pct and self.rest[i]:
            self.feed_pct = feed
        return scaled(self.program, i, self.feed_pct, power)
