"""The typed program: what a controller executes, as records, from the compiled job to the
wire.

A `Program` is a sequence of items in parallel arrays, one row an item:

=========  ===============================================================================
kind       `MOVE`, `DWELL`, `PEN`, `TOOL_ON`, `TOOL_OFF`, `ABSOLUTE`, `PEN_PARK`, `TEXT`,
           `RASTER`, `SET_POSITION`
a, b       MOVE, RASTER: the absolute targets, steps from the homed pose (docs/protocol.md
           6). SET_POSITION: the position the firmware takes as its own (`G92 A<a> B<b>`).
           PEN: the servo's move time (R) and settle time (D), ms
p_us       MOVE, DWELL, RASTER: the duration, µs
s          MOVE, DWELL: the laser power 0-255. PEN, PEN_PARK: the servo pulse, µs.
           TOOL_ON: 3 or 4, the enable command (M3 or M4, always at S0).
           TEXT: the index of its line in `texts`.
           RASTER: the index of its G7 line's pixel run in `runs` when the item starts a
           line, −1 for the line's further segments
segment    the job segment the item executes (−1: none)
=========  ===============================================================================

RASTER items are the segments of G7 lines (docs/protocol.md 6.4): a line is the item with
a run and the RASTER items with −1 after it; its run puts `PixelRun.powers[i]` on the laser
at `u + i·t` cycles after the line's first segment starts.

`ABSENT` in a, b or s of a move or a dwell: the word is left out (a hand-written line,
`wire.read_lines`: `G1 A10 P1000` keeps B where it is); the host's own programs give every
word. `TEXT` items carry a command the records do not model (`$H`, `$0=…`), sent as
written and never packed; a position is set by a `SET_POSITION` item, so a link that maps
positions (the servo firmware's ticks) maps it as it maps a move's target.

Every program is absolute (`ABSOLUTE` = G90 in force from there on); a relative encoding is
the wire's choice (`fivebar_host.wire.file_lines`). Programs are built once — a job's
segments with the pen or laser switching (`compile.emit.job_program`, the same for `fivebar
convert`, the sender and the daemon), the host's own checked moves (`run.moves`), the
bridge's batches (`compile.incremental`) — and turned into text by `fivebar_host.wire`
alone, which is also the only model of their bytes. Overrides scale the records' P and S as
they are written (`run.overrides`), never text.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from enum import IntEnum
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike

from kinematics.arrays import BoolArray, IntArray


class Kind(IntEnum):
    """What an item of a `Program` does (module doc for its values)."""

    MOVE = 0
    DWELL = 1
    PEN = 2
    TOOL_ON = 3
    TOOL_OFF = 4
    ABSOLUTE = 5
    PEN_PARK = 6
    TEXT = 7
    RASTER = 8
    SET_POSITION = 9


@dataclass(frozen=True)
class PixelRun:
    """A G7 line's pixels: powers[i] at u + i·t cycles after its first segment starts."""

    u: int
    t: int
    powers: bytes


#: A word a hand-written line leaves out (module doc).
ABSENT = int(np.iinfo(np.int64).min)

FIELDS = ("kind", "a", "b", "p_us", "s", "segment")


@dataclass(frozen=True, eq=False)
class Program:
    """Items in parallel int64 arrays of one length (module doc)."""

    kind: IntArray
    a: IntArray
    b: IntArray
    p_us: IntArray
    s: IntArray
    segment: IntArray
    texts: tuple[str, ...] = ()
    runs: tuple[PixelRun, ...] = ()

    def __len__(self) -> int:
        return int(self.kind.shape[0])

    @cached_property
    def rows(self) -> tuple[list[int], list[int], list[int], list[int], list[int]]:
        """(kind, a, b, p_us, s) as Python lists: the wire reads items one by one while it
        streams, and a list item is many times quicker to read than an array's."""
        return (self.kind.tolist(), self.a.tolist(), self.b.tolist(), self.p_us.tolist(),
                self.s.tolist())

    def __eq__(self, other: object) -> bool:
        return (isinstance(other, Program) and self.texts == other.texts
                and self.runs == other.runs
                and all(np.array_equal(getattr(self, f), getattr(other, f)) for f in FIELDS))

    __hash__ = None  # type: ignore[assignment]

    # ------------------------------------------------------------------ building
    @staticmethod
    def empty() -> Program:
        z = np.zeros(0, dtype=np.int64)
        return Program(z, z, z, z, z, z)

    @staticmethod
    def of(kind: ArrayLike, a: ArrayLike = 0, b: ArrayLike = 0, p_us: ArrayLike = 0,
           s: ArrayLike = 0, segment: ArrayLike = -1) -> Program:
        """Items from columns (scalars broadcast to the length of `kind`)."""
        k = np.atleast_1d(np.asarray(kind, dtype=np.int64))
        def col(v: ArrayLike) -> IntArray:
            return np.broadcast_to(np.asarray(v, dtype=np.int64), k.shape).copy()

        return Program(k, col(a), col(b), col(p_us), col(s), col(segment))

    @staticmethod
    def moves(a: ArrayLike, b: ArrayLike, p_us: ArrayLike, s: ArrayLike = 0,
              segment: ArrayLike = -1) -> Program:
        """MOVE items to absolute targets (a, b)."""
        n = np.atleast_1d(np.asarray(a)).shape[0]
        return Program.of(np.full(n, Kind.MOVE), a, b, p_us, s, segment)

    @staticmethod
    def command(kind: Kind, a: int = 0, b: int = 0, s: int = 0) -> Program:
        """One item that is not a move or a dwell."""
        return Program.of([kind], a, b, 0, s, -1)

    @staticmethod
    def set_position(a: int, b: int) -> Program:
        """One `SET_POSITION` item: the firmware takes (a, b) steps as where it is (G92)."""
        return Program.of([Kind.SET_POSITION], a, b, 0, 0, -1)

    @staticmethod
    def text(line: str) -> Program:
        """One `TEXT` item: a command the records do not model (`$H`, `$0=…`)."""
        return replace(Program.of([Kind.TEXT], s=0), texts=(line,))

    @staticmethod
    def join(parts: Sequence[Program]) -> Program:
        """The items of `parts`, in order."""
        if not parts:
            return Program.empty()
        texts: list[str] = []
        runs: list[PixelRun] = []
        shifted = []
        for p in parts:  # TEXT and RASTER items index the joined tables
            s = p.s
            if p.texts:
                s = np.where(p.kind == Kind.TEXT, s + len(texts), s)
                texts += p.texts
            if p.runs:
                s = np.where((p.kind == Kind.RASTER) & (s >= 0), s + len(runs), s)
                runs += p.runs
            shifted.append(s)
        cols = {f: np.concatenate([getattr(p, f) for p in parts]) for f in FIELDS if f != "s"}
        return Program(s=np.concatenate(shifted), texts=tuple(texts), runs=tuple(runs), **cols)

    def __add__(self, other: Program) -> Program:
        return Program.join([self, other])

    def take(self, index: IntArray | slice) -> Program:
        """The items at `index`, in that order."""
        return Program(self.kind[index], self.a[index], self.b[index], self.p_us[index],
                       self.s[index], self.segment[index], self.texts, self.runs)

    # ------------------------------------------------------------------ reading
    @property
    def is_motion(self) -> BoolArray:
        """Items that move the arms."""
        out: BoolArray = (self.kind == Kind.MOVE) | (self.kind == Kind.RASTER)
        return out

    def starts_at_rest(self) -> BoolArray:
        """Per item, whether the machine is at rest in the plan when it starts: the first
        item, an item after anything but a move (pen switches, setup, a dwell), an item that
        does not move, or a move whose power differs from the move before (the planner stops
        at every power change). `run.overrides` changes the feed factor only there."""
        mv = self.is_motion
        out = np.ones(len(self), dtype=bool)
        if len(self) > 1:
            out[1:] = ~mv[:-1] | ~mv[1:] | (self.s[1:] != self.s[:-1])
        return out

    def positions(self, start_position: ArrayLike) -> IntArray:
        """Firmware position after each item, from `start_position` (moves move, and a
        `SET_POSITION` says where the firmware is)."""
        n = len(self)
        start = np.asarray(start_position, dtype=np.int64)
        mv = np.flatnonzero(self.is_motion | (self.kind == Kind.SET_POSITION))
        out = np.empty((n, 2), dtype=np.int64)
        if n == 0:
            return out
        for axis, col in enumerate((self.a, self.b)):
            given = mv[col[mv] != ABSENT]  # a move without the word keeps the axis
            last = np.full(n, -1, dtype=np.int64)
            last[given] = given
            last = np.maximum.accumulate(last)
            have = last >= 0
            out[:, axis] = start[axis]
            out[have, axis] = col[last[have]]
        return out

    def finished_segments(self, first_line: int, done_line: int, start: int) -> int:
        """Index of the first segment not finished, given the firmware's last finished line
        (one line number per item, from `first_line`)."""
        idx = done_line - first_line
        if idx < 0:
            return start
        idx = min(idx, len(self) - 1)
        segs = self.segment[: idx + 1]
        segs = segs[segs >= 0]
        return int(segs.max()) + 1 if segs.size else start

    def on_path(self, first_line: int, done_line: int, start_position: ArrayLike,
                position: ArrayLike) -> bool:
        """Whether `position` is where this program can leave the motors when `done_line`
        is the last line it executed to its end: on the straight joint-space line from the
        position after that line to the end of the next item that moves (within a step)."""
        pts = self.positions(start_position)
        idx = done_line - first_line
        if not -1 <= idx < len(self):
            return False
        p0 = np.asarray(start_position, dtype=np.int64) if idx < 0 else pts[idx]
        later = pts[idx + 1:]
        moving = np.flatnonzero(np.any(later != p0, axis=1))
        p1 = later[moving[0]] if moving.size else p0
        return line_param(p0, p1, position) is not None


def line_param(p0: ArrayLike, p1: ArrayLike, pos: ArrayLike) -> float | None:
    """Where `pos` lies on the straight joint-space line p0 → p1: t in [0, 1] measured on
    the axis that moves most, when every axis is within one step of the line; else None.
    (The DDA spreads each motor's steps evenly, so a move stopped part-way sits there.)"""
    s0 = np.asarray(p0, dtype=np.float64)
    d = np.asarray(p1, dtype=np.float64) - s0
    q = np.asarray(pos, dtype=np.float64)
    if not d.any():
        return 0.0 if np.array_equal(q, s0) else None
    ax = int(np.argmax(np.abs(d)))
    t = float((q[ax] - s0[ax]) / d[ax])
    if not 0.0 <= t <= 1.0 or not bool(np.all(np.abs(s0 + t * d - q) <= 1.0 + 1e-9)):
        return None
    return t
