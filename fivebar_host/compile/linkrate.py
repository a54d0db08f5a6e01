"""The serial link's floor under segment durations: a plan never asks more bytes a second
than the line carries (issue 20).

The firmware runs every segment for exactly its `P`; the only way a job falls behind its plan
is an empty queue (an underrun), and an underrun stops the arms at once from whatever speed
the plan had them at — a velocity jump the planner's limits were there to prevent, and a
laser that switches off mid-path. Dense drawings at high limits can ask for segments faster
than 115200 baud delivers them (`python benchmarks/link.py`: about 1400 short segments a
second when consecutive durations repeat, about 800 when each carries its own `P`), or
faster than the firmware takes them at any rate. So each
segment gets a floor: the time its share of the wire takes at `LINK_SHARE` of the line's
byte rate, and at least the firmware's own per-segment work (`FIRMWARE_SEGMENT_US`). Each
segment meeting its floor keeps the bytes the firmware needs ahead of the bytes it runs.

The bytes come from the G6 packing (`wire.pack_line`, docs/protocol.md 6.3) through the wire's
own byte model (`wire.segment_bytes`): a segment after the head of a line is an item
`[P<µs>]±da±db`, with `P` only where its duration differs from the one before; a line of at
most `wire.LINE_BYTES` spends about `wire.LINE_OVERHEAD_B` on its number, head segment and
check field; a change of laser power starts a new line. Whether an item
needs `P` depends on the durations the floor decides, so `compile.timing` runs the staircase,
reads the floor off its durations, and repeats while a segment falls short
(`LINK_PASSES` at most: the staircase is nondecreasing in its floors, so every pass only
lengthens segments and the passes settle).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from fivebar_host.config import Profile
from fivebar_host.wire import segment_bytes
from kinematics.arrays import FloatArray, IntArray

#: Share of the line's nominal byte rate (8N1: baud / 10) a plan may use: room for resends
#: after line noise and the status polls, and simavr's 11-bit byte timing (10 695 B/s at
#: 115200, docs/protocol.md 16).
LINK_SHARE = 0.85
#: The firmware's own floor, µs a segment: past 115200 baud the line is no longer the limit,
#: the firmware's work per segment (receive, check, parse, prepare) is: 1000 segments at
#: P = 1000 µs ran with 0-1 underruns at every rate, a planned job asking ~1020 segments/s
#: with `P` on most items with 4-5 at 250000 and above, P = 250 µs with the queue empty
#: once per line (`python benchmarks/link.py`). So a plan asks at most ~900 a second.
FIRMWARE_SEGMENT_US = 1100
#: Segments over which the wire's bytes are averaged (half the firmware's queue).
WINDOW = 8
#: Ratio between neighbouring floor levels (`floor_levels`).
LEVEL_RATIO = 1.06
#: Staircase passes at most (the first with the floor of items without `P`).
LINK_PASSES = 4
#: Segments per block (bounded temporaries on large jobs).
BLOCK = 1 << 16


def bytes_per_s(profile: Profile) -> float:
    """The byte rate a plan may use: `LINK_SHARE` of the rate the link runs at
    (`[serial] link_baud`, negotiated with `$B`; 8N1 is 10 bits a byte)."""
    return profile.serial.link_baud / 10.0 * LINK_SHARE


def window_mean(x: IntArray, width: int) -> FloatArray:
    """Mean of `x` over a window of `width` centred on each element (shorter at the ends)."""
    c = np.concatenate(([0], np.cumsum(x, dtype=np.int64)))
    n = x.shape[0]
    lo = np.clip(np.arange(n) - width // 2, 0, n)
    hi = np.clip(lo + width, 0, n)
    out: FloatArray = (c[hi] - c[lo]) / np.maximum(hi - lo, 1)
    return out


def floor_levels(us: FloatArray) -> IntArray:
    """`us` rounded up to the grid of ratio `LEVEL_RATIO` from `FIRMWARE_SEGMENT_US`: the
    floors of neighbouring segments coincide, so their durations repeat and their items
    need no `P` (a smooth floor would give every item its own)."""
    k = np.ceil(np.log(np.maximum(us, FIRMWARE_SEGMENT_US) / FIRMWARE_SEGMENT_US)
                / np.log(LEVEL_RATIO) - 1e-9)
    out: IntArray = np.ceil(FIRMWARE_SEGMENT_US * LEVEL_RATIO ** np.maximum(k, 0.0)).astype(
        np.int64)
    return out


def _blocks(steps: IntArray, power: NDArray[np.integer[Any]], duration_us: IntArray | None,
            profile: Profile) -> Iterator[tuple[int, int, IntArray]]:
    """(i, j, floor of segments i..j-1) block by block: the mean bytes of the `WINDOW`
    segments around each (the firmware's queue and receive buffer hold more than that, so
    the wire only has to keep up on average over a window) at `bytes_per_s`, at least
    `FIRMWARE_SEGMENT_US`, on the grid of `floor_levels`; 0 for a segment without motion."""
    rate_us = bytes_per_s(profile) * 1e-6
    n = steps.shape[0] - 1
    for i in range(0, n, BLOCK):
        j = min(i + BLOCK, n)
        lo, hi = max(i - WINDOW, 0), min(j + WINDOW, n)
        mean = window_mean(segment_bytes(steps, power, duration_us, lo, hi), WINDOW)
        need = floor_levels(mean[i - lo:j - lo] / rate_us)
        a, b = steps[i:j], steps[i + 1:j + 1]
        need[(a[:, 0] == b[:, 0]) & (a[:, 1] == b[:, 1])] = 0  # (a 2-column all() is slow)
        yield i, j, need


def raise_to_link(floor_us: IntArray, steps: IntArray, power: NDArray[np.integer[Any]],
                  profile: Profile) -> None:
    """Raise `floor_us` (T,) in place to each moving segment's link floor (`_blocks`),
    before there are durations: no item is counted with a `P`."""
    for i, j, need in _blocks(steps, power, None, profile):
        np.maximum(floor_us[i:j], need, out=floor_us[i:j])


def link_floor_us(steps: IntArray, power: NDArray[np.integer[Any]], duration_us: IntArray,
                  profile: Profile) -> IntArray:
    """Every segment's link floor (`_blocks`) with the planned `duration_us` deciding which
    items carry a `P`."""
    out = np.zeros(steps.shape[0] - 1, dtype=np.int64)
    for i, j, need in _blocks(steps, power, duration_us, profile):
        out[i:j] = need
    return out


class Bound(NamedTuple):
    """Moving segments of a plan at their link floor (`bound_segments`)."""

    total: int
    wire: int  # of them, those whose floor is the wire's bytes (above the firmware's own)


def bound_segments(steps: IntArray, power: NDArray[np.integer[Any]], duration_us: IntArray,
                   profile: Profile) -> Bound:
    """How many moving segments of a plan run at their link floor (within 1 µs): where the
    wire or the firmware, not the machine's limits, sets the pace (the dry-run report) —
    and how many of them the wire holds back (a faster link would speed those up)."""
    dur = np.asarray(duration_us, dtype=np.int64)
    floor = link_floor_us(steps, power, dur, profile)
    bound = (floor > 0) & (dur <= floor + 1)
    return Bound(int(bound.sum()), int((bound & (floor > FIRMWARE_SEGMENT_US)).sum()))
