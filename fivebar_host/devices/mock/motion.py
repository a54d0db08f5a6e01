"""The motion engine of the mock firmware: the segment queue executing over time.

``MotionCore`` is the part of ``MockFirmware`` that fb_motion.c is in the firmware: the
running block and its exact DDA step schedule, the position (firmware coordinates) and the
physical motor position, the laser output, the queue's start rule and feed hold, the
endstop alarm a block runs into, and the next event that happens without the host (block
end, laser silence timeout, the queue's start delay).  It holds no I/O; the firmware model
(``fivebar_host.devices.mock.firmware``) adds the bytes, lines and commands on top.

Motion runs ``speed`` times faster than the firmware would (``opt.speed``; 0 = a started
block ends at once); the protocol's own timers run in wall (clock) time.
"""

from __future__ import annotations

import math
from collections import deque
from typing import TYPE_CHECKING

from fivebar_host.devices.mock.codes import (
    CYCLES_PER_US,
    S_HOMING,
    S_HOMING_DIR,
    S_LASER_TIMEOUT,
    S_PEN_PARK,
    START_BLOCKS,
    START_DELAY_S,
)
from fivebar_host.devices.mock.hardware import Block, LedgerEntry, Machine, step_cycle, steps_done
from fivebar_host.devices.mock.options import MockOptions

if TYPE_CHECKING:
    from fivebar_host.devices.mock.homing import Homing


class MotionCore:
    """Queue, running block, position and laser of the mock firmware (see the module
    docstring).  ``MockFirmware`` sets every attribute when it boots."""

    opt: MockOptions
    machine: Machine
    t: float  # the clock time the device has been advanced to
    boot: int  # firmware boots of the machine, this one included
    settings: list[int]
    pos: list[int]  # position of the last retired block, firmware steps
    plan: list[int]  # position after everything queued so far
    homed: bool
    alarm: int
    laser: int  # the laser output now
    cur: Block | None  # the running block
    cur_elapsed: float  # firmware µs of the running block executed
    cur_stop_us: float  # where it ends: its duration, or its endstop alarm
    cur_alarm: bool  # it ends in an endstop alarm
    cur_entry: LedgerEntry  # its ledger entry
    running: bool
    homing: Homing | None
    queue: deque[Block]
    held: bool
    hold_reason: int
    done_line: int
    underruns: int
    motors_enabled: bool  # the enable pin: M17/M18 executed
    first_queued: float  # when the first block of an idle queue was queued
    last_rx: float  # when the last byte arrived (laser silence timeout)
    resume_at: float | None  # a '~' lowered a parked pen: the hold ends then
    # G7 scans (fb_raster.c): a scan's timeline runs, its id, its power now, the running
    # block's next change, the pixel ring's bytes in use (mock/raster.py)
    px_run: bool = False
    px_scan: int = 0
    px_power: int = 0
    px_next: int = 0
    ring_used: int = 0

    @property
    def pen_down(self) -> bool:
        """The pen is lowered (a pen servo is set up and away from its park pulse)."""
        return bool(self.settings[S_PEN_PARK]) and self.machine.pen.down

    def position(self) -> tuple[int, int]:
        """Position now in steps (every issued step counted), firmware coordinates."""
        if self.cur is None:
            return self.pos[0], self.pos[1]
        d = self._cur_steps()
        return self.pos[0] + d[0], self.pos[1] + d[1]

    def physical(self) -> tuple[int, int]:
        """Physical motor position: steps issued since the machine was created."""
        p = self.machine.phys
        if self.cur is None:
            return p[0], p[1]
        d = self._cur_steps()
        return p[0] + d[0], p[1] + d[1]

    def _cur_steps(self) -> tuple[int, int]:
        """Signed steps the running block has issued so far (its DDA schedule)."""
        blk = self.cur
        assert blk is not None
        e = int(self.cur_elapsed * CYCLES_PER_US)
        out = []
        for i in range(2):
            n = abs(blk.delta[i])
            k = steps_done(n, blk.cycles[i], e)
            out.append(k if blk.delta[i] >= 0 else -k)
        return out[0], out[1]

    def _set_laser(self, power: int, at: float | None = None) -> None:
        if power != self.laser:
            self.laser = power
            self._log_laser(self.t if at is None else at)

    def _log_laser(self, now: float) -> None:
        log = self.machine.laser_log
        if not log or log[-1][1] != self.laser:
            log.append((now, self.laser))

    def _scan_begins(self, blk: Block, from_rest: bool) -> None:
        """A block starts (fb_motion.c boundary): a G7 scan's first block starts its
        timeline at laser 0; its later blocks keep it running, unless they start from a stop
        (an underrun broke the timeline: dark until the next scan, their runs dropped); any
        other block ends the scan and sets its own power."""
        self.px_next = 0
        if not blk.scan:
            self.px_run = False
            self._set_laser(blk.power)
        elif blk.scan_start:
            self.px_run, self.px_scan, self.px_power = True, blk.scan, 0
            self._set_laser(0)
        elif from_rest or not self.px_run or blk.scan != self.px_scan:
            self.px_run = False
            self.ring_used -= sum(nb for _, _, nb in blk.changes)
            self.px_next = len(blk.changes)
            self._set_laser(0)

    def _pixels_until(self, elapsed_us: float) -> None:
        """The running G7 block's changes up to ``elapsed_us``, each at its own clock time
        (the pixel interrupt's; motion runs ``speed`` times faster than the firmware's)."""
        blk = self.cur
        if blk is None or not blk.changes:
            return
        while self.px_next < len(blk.changes) and blk.changes[self.px_next][0] <= elapsed_us:
            off, power, nbytes = blk.changes[self.px_next]
            self.px_next += 1
            self.ring_used -= nbytes
            if self.px_run:
                self.px_power = power
                self._set_laser(power, self._wall_until(off))

    def _pressed(self, axis: int, phys: int) -> bool:
        e = self.opt.endstops[axis]
        return e is not None and phys <= e

    # ----------------------------------------------------------------- the running block

    def _speed_us(self, wall_s: float) -> float:
        """Firmware µs of motion in ``wall_s`` seconds (inf for speed 0)."""
        return math.inf if self.opt.speed == 0 else wall_s * 1e6 * self.opt.speed

    def _wall_until(self, elapsed_us: float) -> float:
        """Clock time at which the running block reaches ``elapsed_us``."""
        if self.opt.speed == 0:
            return self.t
        return self.t + max(0.0, elapsed_us - self.cur_elapsed) / (1e6 * self.opt.speed)

    def _load(self, blk: Block, from_rest: bool = False) -> None:
        """Start executing a motion block now (fb_motion.c load_next for a MOVE/HOME)."""
        self.cur = blk
        self.cur_elapsed = 0.0
        self.cur_stop_us = blk.duration_us  # when an endstop alarm cuts it short: earlier
        self.cur_alarm = False
        if self.settings[S_HOMING] and blk.kind == "G1":
            self._plan_endstop_alarm(blk)
        self.cur_entry = LedgerEntry(self.boot, blk.kind, blk.line, (self.pos[0], self.pos[1]),
                                     (self.pos[0], self.pos[1]), (0, 0), blk.power,
                                     int(blk.p_us or round(blk.duration_us)), 0.0,
                                     started_s=self.t)
        self.machine.ledger.append(self.cur_entry)
        self._scan_begins(blk, from_rest)

    def _plan_endstop_alarm(self, blk: Block) -> None:
        """Find the first step towards a switch that leaves it pressed (alarm 30).

        With ``$7=1`` a motor stepping in its ``$13`` seek direction while its switch is
        pressed (after the step) raises the alarm; stepping away is allowed (fb_motion.c
        check_endstops).
        """
        first: int | None = None
        for i in range(2):
            n = abs(blk.delta[i])
            e = self.opt.endstops[i]
            seek = 1 if self.settings[S_HOMING_DIR] & (1 << i) else -1
            if e is None or not n or (1 if blk.delta[i] > 0 else -1) != seek:
                continue
            p0 = self.machine.phys[i]
            # the step after which the switch is pressed: p0 - k <= e seeking -, p0 + k <= e +
            k = max(1, p0 - e) if seek < 0 else (1 if p0 + 1 <= e else None)
            if k is not None and k <= n:
                c = step_cycle(n, blk.cycles[i], k)
                first = c if first is None else min(first, c)
        if first is not None:
            self.cur_stop_us = first / CYCLES_PER_US
            self.cur_alarm = True

    def sync_entry(self) -> None:
        """Bring the running block's ledger entry up to date."""
        if self.cur is None:
            return
        d = self._cur_steps()
        e = self.cur_entry
        e.steps = d
        e.end = (e.start[0] + d[0], e.start[1] + d[1])
        dur = self.cur.duration_us
        e.fraction = 1.0 if dur <= 0 else min(1.0, self.cur_elapsed / dur)

    def _retire(self, stopped: str | None) -> None:
        """The running block ends (completed, or stopped early): fold it into the position."""
        assert self.cur is not None
        self.sync_entry()
        d = self.cur_entry.steps
        for i in range(2):
            self.pos[i] += d[i]
            self.machine.phys[i] += d[i]
        if stopped is None:
            self.cur_entry.fraction = 1.0
        else:
            self.cur_entry.stopped = stopped
        self.cur = None

    def _record_instant(self, kind: str, line: int, end: tuple[int, int]) -> None:
        start = (self.pos[0], self.pos[1])
        self.machine.ledger.append(LedgerEntry(self.boot, kind, line, start, end, (0, 0), 0, 0,
                                               1.0, started_s=self.t))

    def _load_next(self, from_rest: bool = False) -> bool:
        """Segment boundary: run synchronous blocks, load the next segment (fb_motion.c)."""
        while self.queue:
            blk = self.queue.popleft()
            if blk.kind == "G92":
                self._record_instant("G92", blk.line, blk.delta)
                self.pos = list(blk.delta)
                self.homed = True
                self.done_line = blk.line
                continue
            if blk.kind == "M280":
                pulse, move_ms, settle_ms = blk.pen
                speed = self.opt.speed or math.inf
                self.machine.pen.start_block(self.t, pulse, move_ms / 1e3 / speed,
                                             move_ms + settle_ms)
                if move_ms + settle_ms == 0:
                    self._record_instant("M280", blk.line, (self.pos[0], self.pos[1]))
                    self.done_line = blk.line
                    continue
            if blk.kind in ("M17", "M18"):
                self._record_instant(blk.kind, blk.line, (self.pos[0], self.pos[1]))
                self.motors_enabled = blk.kind == "M17"
                self.done_line = blk.line
                continue
            self._load(blk, from_rest)
            return True
        self.running = False
        self.underruns += 1
        self.px_run = False
        self._set_laser(0)
        return False

    def _start(self) -> None:
        if not self.running and self.queue:
            self.running = True
            self._load_next(from_rest=True)

    def _stop(self, why: str) -> None:
        """Stop at once: no further step, laser off, the running block dropped (mo_stop)."""
        if self.cur is not None:
            self._retire(why)
        self.running = False
        self.px_run = False
        self.ring_used = 0
        self._set_laser(0)
        self.machine.pen.park_now(self.t, keep=False)

    def _hold(self, reason: int) -> None:
        self.held = True
        self.hold_reason = reason
        self.resume_at = None
        self._set_laser(0)
        self.machine.pen.park_now(self.t, keep=True)

    def _silence(self) -> None:
        """Host silence with the laser on or the pen down (fb_main.c laser_watchdog): a job
        is held; an idle machine only parks its pen."""
        if self.running or self.queue:
            self._hold(1)
        else:
            self.machine.pen.park_now(self.t, keep=True)

    def _resume(self) -> None:
        """The hold ends: the timeline continues, the laser returns to the block's power."""
        self.held = False
        self.resume_at = None
        if self.cur is not None:
            self._set_laser((self.px_power if self.px_run else 0) if self.cur.scan
                            else self.cur.power)

    def _error_hold(self) -> None:
        if not self.held and (self.running or self.queue):
            self._hold(2)


    # ----------------------------------------------------------------- time

    def next_event(self) -> tuple[float, int] | None:
        """(time, kind) of the next thing that happens without the host: 0 = the running
        block reaches its end (or its endstop alarm), 1 = laser (or pen) silence timeout,
        2 = the queue's start delay runs out, 4 = a lowered pen has had its time after `~`."""
        events: list[tuple[float, int]] = []
        if self.cur is not None and not self.held:
            events.append((self._wall_until(self.cur_stop_us), 0))
        if (self.laser or self.pen_down) and not self.held:
            events.append((self.last_rx + self.settings[S_LASER_TIMEOUT] / 1000 + 1e-6, 1))
        if (self.queue and not self.running and not self.held and not self.alarm
                and self.homing is None):
            events.append((self.first_queued + START_DELAY_S, 2))
        if self.resume_at is not None:
            events.append((self.resume_at, 4))
        return min(events) if events else None

    def _move_to(self, t: float) -> None:
        """Let the running block progress up to clock time ``t``."""
        if t <= self.t:
            return
        if self.cur is not None and not self.held:
            elapsed = min(self.cur_stop_us, self.cur_elapsed + self._speed_us(t - self.t))
            self._pixels_until(elapsed)
            self.cur_elapsed = elapsed
        self.t = t

    def _maybe_start(self) -> None:
        if self.held or self.alarm or self.homing is not None or self.running or not self.queue:
            return
        if (len(self.queue) >= START_BLOCKS or len(self.queue) >= self.opt.queue
                or self.t - self.first_queued >= START_DELAY_S):
            self._start()

