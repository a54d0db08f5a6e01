"""The mock firmware's motion commands: G1, G6 and G7 segments and the M280 pen block, checked
and queued as fb_exec.c does (every segment of a line checked before any is queued, then one
block per segment as slots free), on top of the queue of ``MotionCore`` (motion.py).  The G7
pixel runs are placed on their blocks by ``ScanPlan`` (raster.py).
"""

from __future__ import annotations

from fivebar_host import protocol
from fivebar_host.devices.mock.codes import (
    CYCLES_PER_US,
    E_MISSING_WORD,
    E_MOTORS_OFF,
    E_NO_PEN,
    E_OUT_OF_RANGE,
    E_SOFT_LIMIT,
    E_TOO_FAST,
    OK,
    S_A_MAX,
    S_A_MIN,
    S_B_MAX,
    S_B_MIN,
    S_MAX_RATE,
    S_PEN_PARK,
    S_SOFT,
    WAIT,
)
from fivebar_host.devices.mock.hardware import Block, step_interval
from fivebar_host.devices.mock.motion import MotionCore
from fivebar_host.devices.mock.parser import Command
from fivebar_host.devices.mock.raster import ScanPlan
from fivebar_host.protocol import POS_LIMIT


class MotionCommands(MotionCore):
    """Segments and pen blocks onto the queue (see the module docstring)."""

    settings: list[int]
    absolute: bool
    laser_on: bool
    laser_s: int
    motors_on: bool
    last: int
    g6_queued: int
    scan: ScanPlan

    def _queue_full(self) -> bool:
        """The queue's slots hold the waiting blocks and the one executing (fb_motion.c)."""
        return len(self.queue) + (self.cur is not None) >= self.opt.queue

    def _push(self, blk: Block) -> None:
        if not self.running and not self.queue:
            self.first_queued = self.t
        self.queue.append(blk)
        self.scan.in_scan = blk.scan > 0

    def _check_segment(self, frm: list[int], t: list[int], p: int) -> int:
        """The G1 checks of a segment from ``frm`` to ``t`` in ``p`` µs, in the firmware's
        order (protocol section 6): range, soft limits, motors off, step rate."""
        if any(abs(v) > POS_LIMIT for v in t):
            return E_OUT_OF_RANGE
        s = self.settings
        if s[S_SOFT] and not (s[S_A_MIN] <= t[0] <= s[S_A_MAX]
                              and s[S_B_MIN] <= t[1] <= s[S_B_MAX]):
            return E_SOFT_LIMIT
        if not self.motors_on and t != frm:
            return E_MOTORS_OFF
        cycles = p * CYCLES_PER_US
        min_interval = step_interval(s[S_MAX_RATE])
        for d in (t[0] - frm[0], t[1] - frm[1]):
            if d and cycles // abs(d) < min_interval:
                return E_TOO_FAST
        return OK

    def _head_target(self, c: Command) -> list[int]:
        w = c.words
        t = list(self.plan)
        for i, axis in enumerate("AB"):
            if axis in w:
                t[i] = w[axis] if self.absolute else self.plan[i] + w[axis]
        return t

    def _exec_g1(self, c: Command, line: int | None = None) -> int:
        """G1 (and a G6's head, numbered `line`): one block, checked first."""
        if self._queue_full():
            return WAIT
        w = c.words
        t = self._head_target(c)
        p = w["P"]
        st = self._check_segment(self.plan, t, p)
        if st != OK:
            return st
        cycles = p * CYCLES_PER_US
        delta = (t[0] - self.plan[0], t[1] - self.plan[1])
        if "S" in w:
            self.laser_s = w["S"]
        power = self.laser_s if self.laser_on else 0
        self._push(Block("G1", self.last if line is None else line, delta, (cycles, cycles),
                         float(p), power, p))
        self.plan = t
        return OK

    def _exec_g6(self, c: Command) -> int:
        """G6 (fb_exec.c exec_g6): every segment checked before any is queued, then the head
        as a G1 and one block per item as slots free, numbered from the line's N."""
        first = (self.last - len(c.items)) & 0xFFFFFFFF
        if not self.g6_queued:
            frm, t, p = list(self.plan), self._head_target(c), c.words["P"]
            st = self._check_segment(frm, t, p)
            for da, db, p in c.items:
                if st != OK:
                    break
                frm, t = t, [t[0] + da, t[1] + db]
                st = self._check_segment(frm, t, p)
            if st != OK:
                return st
            st = self._exec_g1(c, first)
            if st != OK:
                return st
            self.g6_queued = 1
        while self.g6_queued <= len(c.items):
            if self._queue_full():
                return WAIT
            da, db, p = c.items[self.g6_queued - 1]
            cycles = p * CYCLES_PER_US
            power = self.laser_s if self.laser_on else 0
            self._push(Block("G1", (first + self.g6_queued) & 0xFFFFFFFF, (da, db),
                             (cycles, cycles), float(p), power, p))
            self.plan = [self.plan[0] + da, self.plan[1] + db]
            self.g6_queued += 1
        self.g6_queued = 0
        return OK

    def _exec_pen(self, c: Command) -> int:
        """M280: a queued pen block, a dwell of its move + settle time (fb_exec.c)."""
        if not self.settings[S_PEN_PARK]:
            return E_NO_PEN
        if self._queue_full():
            return WAIT
        w = c.words
        move, settle = w.get("R", 0), w.get("D", 0)
        dur = (move + settle) * 1000
        self._push(Block("M280", self.last, duration_us=float(dur), p_us=dur,
                         pen=(w["S"], move, settle)))
        return OK

    def _exec_g7(self, c: Command) -> int:
        """G7 (fb_exec.c exec_g7, docs/protocol.md 6.4): every segment and the pixel run
        checked first, the run placed in the ring (``WAIT`` while it has no room), then one
        block per segment as slots free, numbered from the line's N; the first G7 block after
        any other block, or on an idle machine, starts a scan."""
        sp = self.scan
        first = (self.last - len(c.items) + 1) & 0xFFFFFFFF
        if not sp.checked:
            st = self._g7_check(c)
            if st != OK:
                return st
            sp.checked = True
        if not sp.pushed:
            if self._queue_full():
                return WAIT
            if not sp.room(len(c.pixels), self):
                return WAIT
            sp.push_line(c, idle=not self.running and not self.queue and self.cur is None,
                         dark=not self.laser_on)
            if c.pixels:
                self.ring_used += len(c.pixels) + protocol.PX_HEAD
        while self.g6_queued < len(c.items):
            if self._queue_full():
                return WAIT
            da, db, p = c.items[self.g6_queued]
            p = p or sp.p
            cycles = p * CYCLES_PER_US
            blk = Block("G1", (first + self.g6_queued) & 0xFFFFFFFF, (da, db), (cycles, cycles),
                        float(p), 0, p)
            sp.place(blk, self.g6_queued)
            self._push(blk)
            self.plan = [self.plan[0] + da, self.plan[1] + db]
            self.g6_queued += 1
            sp.p = p
        self.g6_queued = 0
        sp.finish_line(c)
        return OK

    def _g7_check(self, c: Command) -> int:
        """The G1 checks of every segment (the first one's P the modal one), then the run:
        at most what the ring holds, a period of at least ``PX_T_MIN``, every change inside
        the line's segments."""
        frm, p, total = list(self.plan), self.scan.p, 0
        for da, db, q in c.items:
            p = q or p
            if not p:
                return E_MISSING_WORD
            t = [frm[0] + da, frm[1] + db]
            st = self._check_segment(frm, t, p)
            if st != OK:
                return st
            frm, total = t, total + p * CYCLES_PER_US
        return self.scan.check_run(c, total)
