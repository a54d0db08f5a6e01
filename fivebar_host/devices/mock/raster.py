"""G7 raster scans in the mock firmware (docs/protocol.md 6.4): the main loop's side of
fb_exec.c's G7 and fb_raster.c's ring.

A G7 line is one or more segments and a run of pixel powers: power i goes on the laser at
U + i·T cycles after the start of the line's first segment.  ``ScanPlan`` is what the
firmware's main loop keeps while it queues them: the modal P and T of G7 lines, the scan id
(consecutive G7 blocks form one scan; the first G7 block after any other block, or on an
idle machine, starts one) and, since the mock executes whole blocks, each change placed on
the block it falls in (``Block.changes``: µs from the block's start, power, ring bytes it
frees).  The pixel interrupt's side — the laser following the changes, a scan broken by an
underrun staying dark — is ``MotionCore`` (motion.py).  The ring's room is modelled in bytes
as the firmware keeps it (a record's 10-byte header and its powers, freed as they are used),
so a line waits for room as the firmware's does.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from fivebar_host import protocol
from fivebar_host.devices.mock.codes import CYCLES_PER_US, E_MISSING_WORD, E_OUT_OF_RANGE, OK
from fivebar_host.devices.mock.hardware import Block

if TYPE_CHECKING:
    from fivebar_host.devices.mock.motion import MotionCore
    from fivebar_host.devices.mock.parser import Command

#: The firmware's pixel ring, bytes (config.h CFG_PX_RING).
PX_RING = 128


@dataclass
class ScanPlan:
    """The G7 state of the firmware's main loop (fb_exec.c): see the module docstring."""

    p: int = 0  # modal P of G7 segments, µs (0: none yet)
    t: int = 0  # modal T, cycles
    scan: int = 0  # id of the scan being queued (1..255)
    in_scan: bool = False  # the last block queued was a G7 block
    time: int = 0  # cycles from the scan's start to the end of its last block queued
    last: int = 0  # cycles from the scan's start to its last change queued
    checked: bool = False  # the pending line passed its checks
    pushed: bool = False  # ... and its run is placed
    new: bool = False  # ... and it starts a scan
    #: the pending line's changes: cycles from its first segment's start, power, ring bytes
    line_changes: list[tuple[int, int, int]] = field(default_factory=list)
    line_starts: list[int] = field(default_factory=list)  # its segments' starts, cycles

    def reset(self) -> None:
        """Ctrl-X, boot: no modal P or T, no scan."""
        self.p = self.t = 0
        self.in_scan = False
        self.line_done()

    def line_done(self) -> None:
        self.checked = self.pushed = self.new = False
        self.line_changes = []
        self.line_starts = []

    def check_run(self, c: Command, total_cycles: int) -> int:
        """The pixel run of a G7 whose segments last ``total_cycles`` (fb_exec.c g7_check)."""
        n = len(c.pixels)
        if not n:
            return OK
        per = c.words.get("T", self.t)
        if n > PX_RING - protocol.PX_HEAD:
            return E_OUT_OF_RANGE
        if n > 1 and not per:
            return E_MISSING_WORD
        if n > 1 and per < protocol.PX_T_MIN:
            return E_OUT_OF_RANGE
        return OK if c.words.get("U", 0) + (n - 1) * per < total_cycles else E_OUT_OF_RANGE

    def room(self, n: int, core: MotionCore) -> bool:
        """Whether the ring takes a run of ``n`` powers now; an idle machine's ring is
        empty (nothing is left to burn)."""
        if not n:
            return True
        if core.cur is None and not core.queue:
            core.ring_used = 0
        return core.ring_used + protocol.PX_HEAD + n <= PX_RING

    def push_line(self, c: Command, idle: bool, dark: bool) -> None:
        """The pending line's run into the ring, and whether it starts a scan."""
        self.new = not self.in_scan or idle
        if self.new:
            self.scan = self.scan % 255 + 1
            self.time = self.last = 0
        starts, at, p = [], 0, self.p
        for _, _, q in c.items:
            p = q or p
            starts.append(at)
            at += p * CYCLES_PER_US
        self.line_starts = starts
        n = len(c.pixels)
        if n:
            u, per = c.words.get("U", 0), c.words.get("T", self.t)
            self.line_changes = [(u + i * per, 0 if dark else c.pixels[i],
                                  1 + (protocol.PX_HEAD if i == 0 else 0)) for i in range(n)]
            self.last = self.time + u + (n - 1) * per
        self.pushed = True

    def place(self, blk: Block, index: int) -> None:
        """Segment ``index`` of the pending line: its scan, and the changes that fall in it."""
        start = self.line_starts[index]
        end = start + blk.cycles[0]
        blk.scan = self.scan
        blk.scan_start = self.new and index == 0
        blk.changes = tuple(((c - start) / CYCLES_PER_US, pw, nb)
                            for c, pw, nb in self.line_changes if start <= c < end)

    def finish_line(self, c: Command) -> None:
        """The pending line is queued whole (``p`` is its last segment's): its segments'
        time joins the scan's, its T is the modal one."""
        self.time += self.line_starts[-1] + self.p * CYCLES_PER_US
        if "T" in c.words:
            self.t = c.words["T"]
