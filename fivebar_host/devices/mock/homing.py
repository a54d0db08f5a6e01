"""``$H`` in the mock firmware: seek the switches, pull off, set the home position.

A port of the homing sequence of fb_home.c (home_cycle): both motors seek their switches at
the ``$8`` rate in their ``$13`` direction, each stopping on its own switch (at most ``$12``
steps), then pull off by ``$9`` steps; a switch not found, or still pressed after the pull
off, is ``ALARM:31``, a ``!`` or Ctrl-X while homing ``ALARM:32``.  The moves run on the
firmware's motion engine; the pending ``$H`` line is answered when homing ends.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from fivebar_host.devices.mock.codes import (
    A_HOMING_ABORT,
    A_HOMING_FAIL,
    CYCLES_PER_US,
    OK,
    S_HOME_A,
    S_HOME_B,
    S_HOMING_DIR,
    S_HOMING_RATE,
    S_PULLOFF,
    S_TRAVEL,
    WAIT,
)
from fivebar_host.devices.mock.hardware import Block, step_cycle, step_interval

if TYPE_CHECKING:
    from fivebar_host.devices.mock.firmware import MockFirmware


class Homing:
    """``$H`` in progress (fb_home.c home_cycle): seek the switches, pull off, set home."""

    def __init__(self, fw: MockFirmware) -> None:
        self.fw = fw
        s = fw.settings
        self.interval = step_interval(s[S_HOMING_RATE])
        self.seek_dir = [1 if s[S_HOMING_DIR] & (1 << i) else -1 for i in range(2)]
        self.code: int | None = None  # the reply once homing has ended
        self.phase = ""

    def _move(self, kind: str, steps: tuple[int, int], duration_cycles: int) -> None:
        fw = self.fw
        cycles = (abs(steps[0]) * self.interval, abs(steps[1]) * self.interval)
        fw.running = True
        fw._load(Block(kind, fw.last, steps, cycles, duration_cycles / CYCLES_PER_US))
        self.phase = kind

    def seek(self) -> None:
        """Both motors toward their switches; each stops on its own (MO_BLK_HOME)."""
        fw = self.fw
        travel = fw.settings[S_TRAVEL]
        steps = [0, 0]
        self.hit = [False, False]
        last_hit = 0
        for i in range(2):
            e = fw.opt.endstops[i]
            p0, d = fw.machine.phys[i], self.seek_dir[i]
            k: int | None = None
            if e is not None:
                if p0 + d <= e:
                    k = 1
                elif d < 0:
                    k = p0 - e
            if k is not None and k <= travel:
                steps[i] = d * k
                self.hit[i] = True
                last_hit = max(last_hit, step_cycle(k, k * self.interval, k))
            else:
                steps[i] = d * travel
        all_hit = all(self.hit)
        self._move("home-seek", (steps[0], steps[1]),
                   last_hit + 1 if all_hit else travel * self.interval)

    def block_done(self) -> None:
        """A homing move ended: go on with the next phase or finish."""
        fw = self.fw
        fw.running = False
        if self.phase == "home-seek":
            if not all(self.hit):
                self._end(A_HOMING_FAIL)
                return
            pulloff = fw.settings[S_PULLOFF]
            if pulloff > 0:
                steps = (-self.seek_dir[0] * pulloff, -self.seek_dir[1] * pulloff)
                self._move("home-pulloff", steps, pulloff * self.interval)
                return
        phys = fw.machine.phys
        if fw._pressed(0, phys[0]) or fw._pressed(1, phys[1]):
            self._end(A_HOMING_FAIL)
            return
        home = (fw.settings[S_HOME_A], fw.settings[S_HOME_B])
        fw._record_instant("home-set", fw.last, home)
        fw.pos = list(home)
        fw.plan = list(home)
        fw.homed = True
        fw.alarm = 0
        self._end(OK)

    def abort(self) -> None:
        """``!`` or Ctrl-X while homing: stop, ALARM:32, reply error:32."""
        self.fw._stop("homing-abort")
        self._end(A_HOMING_ABORT)

    def _end(self, code: int) -> None:
        fw = self.fw
        fw.running = False
        fw.homing = None
        if code != OK:
            fw._raise_alarm(code)
        self.code = code
        # the pending $H is answered now; the main loop goes on with the next line
        if fw.pending is not None and fw.pending.kind == "$H":
            fw.pending = None
            fw._finish(code)

    def result(self) -> int:
        return WAIT if self.code is None else self.code

