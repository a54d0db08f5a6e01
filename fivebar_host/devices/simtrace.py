"""Read the pin trace written by the simavr harness (firmware/sim/fbsim.c).

The trace holds one ``<cycle> <pin> <level>`` line per change of a step,
direction, enable or laser pin (plus ``esA``/``esB`` for simulated endstops),
with the emulated CPU cycle of the change.  This module turns it into what
tests and benchmarks check: motor step positions over time (rising step
edges signed by the direction pin), step pulse high and low times, direction set-up
times and the intervals during which the laser was on (PWM pulses merged).
Pure Python, no I/O beyond reading the file.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field
from pathlib import Path

from fivebar_host.errors import FivebarError

AXES = ("A", "B")
#: Timer2 PWM period of the laser output in CPU cycles (F_CPU / 8 / 256).
LASER_PWM_PERIOD = 2048


class TraceError(FivebarError, ValueError):
    """The trace file is malformed."""


@dataclass(frozen=True)
class Step:
    """One step: cycle of the rising edge and its direction (+1 or -1)."""

    cycle: int
    direction: int


@dataclass
class Trace:
    """A parsed trace: per-pin lists of (cycle, level) changes."""

    freq: int
    changes: dict[str, list[tuple[int, int]]] = field(default_factory=dict)
    dir_invert: tuple[bool, bool] = (False, False)
    #: Where the arms stood (motor steps, the harness's count) when the trace began: (0, 0)
    #: for a new machine, where the last run left them for one kept between runs (`-S`).
    start: tuple[int, int] = (0, 0)

    def pin(self, name: str) -> list[tuple[int, int]]:
        """Changes of one pin, in time order (empty if it never changed)."""
        return self.changes.get(name, [])

    def steps(self, axis: str) -> list[Step]:
        """Every step of motor ``axis`` ("A" or "B"), in time order.

        A step is a rising edge of the step pin; its direction is the level
        of the direction pin at that cycle (high = positive unless inverted).
        """
        index = AXES.index(axis)
        dirs = self.pin("dir" + axis)
        dir_cycles = [c for c, _ in dirs]
        out = []
        for cycle, level in self.pin("step" + axis):
            if level != 1:
                continue
            k = bisect.bisect_right(dir_cycles, cycle) - 1
            high = dirs[k][1] == 1 if k >= 0 else False
            positive = high != self.dir_invert[index]
            out.append(Step(cycle, 1 if positive else -1))
        return out

    def positions(self, axis: str, start: int = 0) -> list[tuple[int, int]]:
        """(cycle, position after the step) for every step of ``axis``."""
        pos = start
        out = []
        for step in self.steps(axis):
            pos += step.direction
            out.append((step.cycle, pos))
        return out

    def position_at(self, axis: str, cycle: int, start: int = 0) -> int:
        """Position of ``axis`` at ``cycle`` (steps at exactly ``cycle`` count)."""
        pos = start
        for step in self.steps(axis):
            if step.cycle > cycle:
                break
            pos += step.direction
        return pos

    def pulse_widths(self, axis: str) -> list[int]:
        """High time in cycles of every complete step pulse of ``axis``."""
        widths = []
        rise: int | None = None
        for cycle, level in self.pin("step" + axis):
            if level == 1:
                rise = cycle
            elif rise is not None:
                widths.append(cycle - rise)
                rise = None
        return widths

    def low_widths(self, axis: str) -> list[int]:
        """Low time in cycles between each fall and the next rise of ``axis``'s step pin.

        The drivers' minimum step low time (A4988 1 us, DRV8825 1.9 us) is
        checked against these.
        """
        widths = []
        fall: int | None = None
        risen = False  # the trace's first 0 is the pin's initial level, not a fall
        for cycle, level in self.pin("step" + axis):
            if level == 0 and risen:
                fall = cycle
            elif level == 1:
                risen = True
                if fall is not None:
                    widths.append(cycle - fall)
                    fall = None
        return widths

    def dir_setup(self, axis: str) -> list[int]:
        """Cycles from each direction change to the next step of ``axis``."""
        rises = [s.cycle for s in self.steps(axis)]
        out = []
        for cycle, _ in self.pin("dir" + axis):
            k = bisect.bisect_left(rises, cycle)
            if k < len(rises):
                out.append(rises[k] - cycle)
        return out

    def laser_intervals(self, max_gap: int = 2 * LASER_PWM_PERIOD) -> list[tuple[int, int]]:
        """[start, end) cycle intervals during which the laser output was on.

        High pulses closer than ``max_gap`` cycles are merged, so a PWM
        output counts as one interval; an output still high at the end of
        the trace is closed at its last recorded cycle.
        """
        pulses: list[tuple[int, int]] = []
        rise: int | None = None
        changes = self.pin("laser")
        for cycle, level in changes:
            if level == 1 and rise is None:
                rise = cycle
            elif level == 0 and rise is not None:
                pulses.append((rise, cycle))
                rise = None
        if rise is not None:
            pulses.append((rise, max(rise, self.last_cycle())))
        merged: list[tuple[int, int]] = []
        for start, end in pulses:
            if merged and start - merged[-1][1] <= max_gap:
                merged[-1] = (merged[-1][0], end)
            else:
                merged.append((start, end))
        return merged

    def laser_on_at(self, cycle: int, max_gap: int = 2 * LASER_PWM_PERIOD) -> bool:
        """True if ``cycle`` falls inside a laser-on interval."""
        return any(s <= cycle < e for s, e in self.laser_intervals(max_gap))

    def pen_pulses(self) -> list[tuple[int, int]]:
        """(rising-edge cycle, high time in cycles) of every complete pulse of the pen
        servo's signal (D12: one pulse per 20 ms frame, its width the servo position)."""
        return self.pulses("pen")

    def pulses(self, name: str) -> list[tuple[int, int]]:
        """(rising-edge cycle, high time in cycles) of every complete pulse on the traced
        pin `name`: "pen", or the servo build's arm servos "svA" / "svB" (fbsim -V)."""
        out: list[tuple[int, int]] = []
        rise: int | None = None
        for cycle, level in self.pin(name):
            if level == 1:
                rise = cycle
            elif rise is not None:
                out.append((rise, cycle - rise))
                rise = None
        return out

    def last_cycle(self) -> int:
        """Cycle of the last recorded change (0 for an empty trace)."""
        return max((ch[-1][0] for ch in self.changes.values() if ch), default=0)

    def seconds(self, cycles: int) -> float:
        """Convert emulated cycles to seconds."""
        return cycles / self.freq


def parse_trace(text: str, dir_invert: tuple[bool, bool] = (False, False)) -> Trace:
    """Parse trace text; raises TraceError naming the first bad line."""
    trace = Trace(freq=16_000_000, dir_invert=dir_invert)
    last: dict[str, int] = {}
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        if line.startswith("#"):
            for word in line.split():
                if word.startswith("freq="):
                    trace.freq = int(word[5:])
                elif word.startswith("start="):
                    a, b = word[6:].split(",")
                    trace.start = (int(a), int(b))
            continue
        parts = line.split()
        if len(parts) != 3 or not parts[0].isdigit() or parts[2] not in ("0", "1"):
            raise TraceError(f"trace line {number}: {raw!r} is not '<cycle> <pin> <0|1>'")
        cycle, name, level = int(parts[0]), parts[1], int(parts[2])
        if cycle < last.get(name, 0):
            raise TraceError(f"trace line {number}: time goes backwards for {name}")
        last[name] = cycle
        trace.changes.setdefault(name, []).append((cycle, level))
    return trace


def read_trace(path: str | Path, dir_invert: tuple[bool, bool] = (False, False),
               live: bool = False) -> Trace:
    """Read and parse a trace file written by ``fbsim -t``.

    ``live``: the harness is still writing it, so its buffer may have gone out in the middle
    of a line; the trace then ends at the last complete line. A finished trace with a cut
    line is an error."""
    text = Path(path).read_text(encoding="ascii")
    if live:
        text = text[:text.rfind("\n") + 1]
    return parse_trace(text, dir_invert)
