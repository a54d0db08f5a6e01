"""The mock firmware: bytes in, lines, commands and replies, boot, reset and faults.

``MockFirmware`` is fb_main.c of the firmware in Python: the receive buffer of the banner's
size whose excess bytes are lost (``error:18``), the real-time bytes (``?`` ``!`` ``~``
Ctrl-X), line assembly and the checks of docs/protocol.md 5.2 in the firmware's order, the
commands and settings, the replies and status reports, the boot banner, resets that keep the
``.noinit`` record and power-ons that do not, and the line-counted fault options of the URL.
The queue and motion underneath are ``MotionCore`` (motion.py), homing is ``Homing``
(homing.py), and the grammar is ``parse_line`` (parser.py).

The simulation is lazy: every call first advances the device to the caller's clock time
(``advance``), handling each event in time order, so no background thread runs.
"""

from __future__ import annotations

from collections import deque

from fivebar_host import protocol
from fivebar_host.devices.mock.baud import UartRate
from fivebar_host.devices.mock.codes import (
    A_ENDSTOP,
    DEFAULT_SETTINGS,
    E_ALARM_LOCK,
    E_BUSY,
    E_CHECKSUM,
    E_HOMING_DISABLED,
    E_LINE_TOO_LONG,
    E_MOTORS_OFF,
    E_OUT_OF_RANGE,
    E_RX_OVERFLOW,
    E_UNKNOWN_SETTING,
    OK,
    S_HOMING,
    S_PEN_PARK,
    WAIT,
)
from fivebar_host.devices.mock.commands import MotionCommands
from fivebar_host.devices.mock.hardware import Block, KeptRecord, Machine
from fivebar_host.devices.mock.homing import Homing
from fivebar_host.devices.mock.options import MockOptions
from fivebar_host.devices.mock.parser import Command, parse_line
from fivebar_host.devices.mock.raster import ScanPlan
from fivebar_host.protocol import EOL, RESEND_CODES, SETTINGS

_RT_STATUS, _RT_HOLD, _RT_RESUME, _RT_RESET = (ord(b) for b in ("?", "!", "~", "\x18"))
_NL, _CR = 0x0A, 0x0D


class MockFirmware(MotionCommands):
    """The firmware's state machine, driven by bytes and by a clock in seconds.

    Pure simulation, no I/O: ``receive`` takes host bytes, ``advance`` runs the device up
    to a time, ``out`` collects what it sends.  ``MockSerial`` wraps it as a pyserial port.
    """

    def __init__(self, options: MockOptions, machine: Machine, now: float,
                 kept: KeptRecord | None = None) -> None:
        self.opt = options
        self.machine = machine
        self.out = bytearray()
        self.t = now
        self.lines_seen = 0  # lines taken from the receive buffer, for the fault options
        self.stalled = False
        self.hung_at: float | None = None  # when a stall_after hang began (the watchdog's)
        self.disconnected = False
        self.rebooted = False  # set by a reboot; MockSerial drops the rest of the write
        self._faults_fired: set[str] = set()
        self.uart = UartRate()  # $B (mock/baud.py); the port sets its host_baud
        self._boot(now, kept)

    # ----------------------------------------------------------------- boot and reset

    def _boot(self, now: float, kept: KeptRecord | None) -> None:
        """Boot (fb_setup): settings to defaults, no alarm, banner.  Position, ``H`` and
        ``Ln`` done come from ``kept`` (a reset that left the RAM powered), else they start
        at 0 (power-on)."""
        m = self.machine
        m.boots += 1
        self.boot = m.boots
        self.settings = list(DEFAULT_SETTINGS)
        if m.pen_park_ee is not None:
            self.settings[S_PEN_PARK] = m.pen_park_ee
        m.pen.setup(now, self.settings[S_PEN_PARK])  # parked up at every boot
        self.pos = list(kept.position) if kept is not None else [0, 0]
        # position set by an executed G92 or a completed $H; kept by Ctrl-X and by a reset
        self.homed = kept.homed if kept is not None else False
        self.alarm = 0
        self.stalled = False
        self.hung_at = None
        self.laser = 0
        self._log_laser(now)
        self.cur = None
        self.cur_elapsed = 0.0  # firmware µs of the running block executed
        self.cur_stop_us = 0.0  # where it ends: its duration, or its endstop alarm
        self.cur_alarm = False  # it ends in an endstop alarm
        self.running = False
        self.homing = None
        self.queue = deque()
        self._reset_state()
        if kept is not None:
            self.done_line = kept.done_line

    def _reset_state(self) -> None:
        """What Ctrl-X resets (fb_main.c do_reset), then the banner."""
        self.rx = bytearray()
        self.rx_overflow = False
        self.line = bytearray()
        self.line_over = False
        self.pending: Command | None = None
        self.g6_queued = 0  # segments of the pending G6 queued so far (1: its head)
        self.scan = ScanPlan()  # G7: modal P and T, the scan being queued (mock/raster.py)
        self.held = False
        self.hold_reason = 0
        self.resume_at = None
        self.queue.clear()
        self.done_line = 0
        self.underruns = 0
        self.last = 0
        self.numbered = False  # strict framing (fb_lines_t.numbered)
        self.absolute = True
        self.laser_on = False
        self.laser_s = 0
        self.motors_on = True  # as planned: M17/M18 queued so far
        self.motors_enabled = True  # the enable pin: M17/M18 executed
        self.plan = list(self.pos)
        self.first_queued = self.t
        self.last_rx = self.t
        self.uart.reset()
        self._emit(self.banner_text())

    def banner_text(self) -> str:
        """The banner line (without its end of line)."""
        o = self.opt
        return f"fivebar {o.version} proto:{o.proto} rx:{o.rx} queue:{o.queue} line:{o.line}"

    def reboot(self, now: float, keep: bool = True) -> None:
        """A reset at ``now``: motion stops where it is, then the firmware boots again.

        ``keep``: the RAM stayed powered (DTR, reset button, watchdog, brown-out), so the
        ``.noinit`` record brings back position, ``H`` and ``Ln`` done; else a power-on."""
        self.advance(now)
        self._reboot_now("reboot" if keep else "power-cut", keep)

    def _reboot_now(self, why: str, keep: bool) -> None:
        self._stop(why)
        kept = self.kept_record() if keep else None
        self.rebooted = True
        self._boot(self.t, kept)

    def kept_record(self) -> KeptRecord:
        """The ``.noinit`` record as it stands now (the firmware keeps it up to date)."""
        a, b = self.position()
        return KeptRecord((a, b), self.homed, self.done_line)

    def power_off(self, now: float, why: str = "reboot") -> KeptRecord:
        """The firmware stops for good (a new one boots on its machine): motion stops where
        it is, laser off.  Returns its ``.noinit`` record, for a reset that keeps the RAM."""
        self.advance(now)
        self._stop(why)
        self.stalled = True  # nothing of it runs any more
        return self.kept_record()

    # ----------------------------------------------------------------- output

    def _emit(self, text: str) -> None:
        if not self.stalled and self.uart.matches():  # else lost on the wire
            self.out += (text + EOL).encode("ascii")

    def status_text(self) -> str:
        """The status report line the firmware would send now (fb_report.c status_report)."""
        if self.alarm:
            state = f"Alarm:{self.alarm}"
        elif self.homing is not None:
            state = "Home"
        elif self.held:
            state = f"Hold:{self.hold_reason}"
        elif self.running or self.queue:
            state = "Run"
        else:
            state = "Idle"
        a, b = self.position()
        return (f"<{state}|A:{a},B:{b}|Q:{len(self.queue)}|Ln:{self.done_line},{self.last}"
                f"|L:{self.laser}|U:{self.underruns}|H:{int(self.homed)}"
                f"|P:{self.machine.pen.pulse(self.t)}>")

    def _finish(self, st: int) -> None:
        """Reply to a line: ``ok`` or ``error:<code>`` (errors hold a running job)."""
        if st == OK:
            self._emit("ok")
            return
        if st in RESEND_CODES:
            self._emit(f"error:{st} resend:{(self.last + 1) & 0xFFFFFFFF}")
            return
        self._error_hold()
        self._emit(f"error:{st}")

    def _raise_alarm(self, code: int) -> None:
        self._stop("alarm")
        self.queue.clear()
        self.held = False
        self.resume_at = None
        self.alarm = code
        self.plan = list(self.pos)
        self._emit(f"ALARM:{code}")

    # ----------------------------------------------------------------- time

    def watchdog_at(self) -> float | None:
        """When the watchdog resets the hung firmware (None: not hung, or no watchdog)."""
        if self.hung_at is None or not self.opt.watchdog:
            return None
        return self.hung_at + self.opt.watchdog / 1000

    def next_event(self) -> tuple[float, int] | None:
        """As ``MotionCore.next_event``; while hung only the watchdog (kind 3) happens."""
        if self.stalled:
            wd = self.watchdog_at()
            return None if wd is None else (wd, 3)
        return super().next_event()

    def _hang(self) -> None:
        """The firmware hangs (``stall_after``): nothing runs, the pins stay as they are,
        until the watchdog or a DTR reset."""
        self.stalled = True
        self.hung_at = self.t

    def _watchdog_reset(self, at: float) -> None:
        """The watchdog's reset of the hung firmware at ``at`` (fb_main.c fb_feed_watchdog):
        the motors stopped where the hang froze them, the laser goes off now, and the
        firmware boots with its ``.noinit`` record, as after any reset that keeps the RAM.
        Unlike a DTR reset it cuts no host write: bytes after it reach the new firmware."""
        self.t = max(self.t, at)
        rebooted = self.rebooted
        self._reboot_now("watchdog", keep=True)
        self.rebooted = rebooted

    def advance(self, now: float) -> None:
        """Run the device up to clock time ``now``, event by event."""
        self.uart.fallback(now)
        if self.stalled:
            wd = self.watchdog_at()
            if wd is None or now < wd:
                self.t = max(self.t, now)
                return
            self._watchdog_reset(wd)
        while True:
            ev = self.next_event()
            if ev is None or ev[0] > now:
                break
            self._move_to(ev[0])
            self._fire(ev[1])
            self._main_loop()
        self._move_to(now)

    def _fire(self, kind: int) -> None:
        if kind == 0:
            assert self.cur is not None
            self.cur_elapsed = self.cur_stop_us
            if self.cur_alarm:
                self._raise_alarm(A_ENDSTOP)
            elif self.homing is not None:
                self._retire(None)
                self.homing.block_done()
            else:
                self._retire(None)
                self.done_line = self.cur_entry.line
                self._load_next()
        elif kind == 1:
            self._silence()
        elif kind == 4:
            self._resume()
        else:
            self._start()

    # ----------------------------------------------------------------- bytes in

    def receive(self, c: int, now: float) -> None:
        """One byte from the host at clock time ``now`` (the receive interrupt)."""
        self.advance(now)
        if self.stalled:
            return
        self.last_rx = now
        if c == _RT_STATUS:
            self._emit(self.status_text())
        elif c == _RT_HOLD:
            if self.homing is not None:
                self.homing.abort()
            elif (not self.held and not self.alarm) or self.resume_at is not None:
                self._hold(0)
        elif c == _RT_RESUME:
            if self.held and self.resume_at is None:
                wait_ms = self.machine.pen.unpark(now)
                if wait_ms:
                    self.resume_at = now + wait_ms / 1000
                else:
                    self._resume()
        elif c == _RT_RESET:
            self._stop("reset")
            if self.homing is not None:
                self.homing.abort()
            self._reset_state()
        elif len(self.rx) >= self.opt.rx:
            self.rx_overflow = True
        else:
            self.rx.append(c)
        self._main_loop()

    def _main_loop(self) -> None:
        """fb_poll until it has nothing to do: start the queue, run the pending line or
        take the next line from the receive buffer."""
        while not self.stalled:
            self._maybe_start()
            if self.pending is not None:
                if not self._try_execute():
                    break
                continue
            nl = self.rx.find(_NL)
            if nl < 0:
                self._assemble(len(self.rx))
                break
            self._assemble(nl)
            del self.rx[:1]  # the newline
            self._handle_line()
            if self.rebooted or self.stalled:
                break
        if not self.stalled:
            self._maybe_start()

    def _assemble(self, count: int) -> None:
        """Move ``count`` bytes from the receive buffer into the line buffer."""
        for c in self.rx[:count]:
            if c == _CR:
                continue
            if len(self.line) < self.opt.line:
                self.line.append(c)
            else:
                self.line_over = True
        del self.rx[:count]

    def _handle_line(self) -> None:
        """One complete line (fb_main.c handle_line): overflow, length, framing, command."""
        data, over = bytes(self.line), self.line_over
        self.line.clear()
        self.line_over = False
        self.lines_seen += 1
        k = self.lines_seen
        if self.rx_overflow:
            self.rx_overflow = False
            self._finish(E_RX_OVERFLOW)
        elif over:  # numbered mode: line noise (merged lines), refused with a resend
            self._finish(E_CHECKSUM if self.numbered else E_LINE_TOO_LONG)
        else:
            before = self.last, self.numbered
            parsed = parse_line(self.last, data, self.numbered)
            self.last, self.numbered = parsed.last, parsed.numbered
            if parsed.status == OK:
                self.uart.valid_line()
            st = parsed.status
            if self.opt.error_on == k and st == OK:
                st = self.opt.error_code  # the injected refusal
                if st in RESEND_CODES:
                    self.last, self.numbered = before
            if st != OK:
                self._finish(st)
            else:
                self.pending = parsed.command
                self._try_execute()
        self._line_faults(k)

    def _line_faults(self, k: int) -> None:
        o = self.opt
        if o.disconnect_after is not None and k >= o.disconnect_after:
            self.disconnected = True
        if o.reset_after == k and "reset_after" not in self._faults_fired:
            self._faults_fired.add("reset_after")
            self._reboot_now("reboot", keep=True)
        if o.power_cut_after == k and "power_cut_after" not in self._faults_fired:
            self._faults_fired.add("power_cut_after")
            self._reboot_now("power-cut", keep=False)
        if (o.stall_after is not None and k >= o.stall_after
                and "stall_after" not in self._faults_fired):
            self._faults_fired.add("stall_after")
            self._hang()

    def check_startup_faults(self) -> None:
        """Faults that fire after zero lines (``stall_after=0``, ``disconnect_after=0``)."""
        if self.opt.stall_after == 0:
            self._faults_fired.add("stall_after")
            self._hang()
        if self.opt.disconnect_after == 0:
            self.disconnected = True

    # ----------------------------------------------------------------- commands

    def _try_execute(self) -> bool:
        """Execute the pending line; False while it has to wait (queue full, homing)."""
        assert self.pending is not None
        st = self._execute(self.pending)
        if st == WAIT:
            return False
        self.pending = None
        self.g6_queued = 0
        self.scan.line_done()
        self._finish(st)
        self.uart.after_reply(self.t)
        return True

    def _execute(self, c: Command) -> int:
        if self.homing is not None:
            return self.homing.result()
        if self.alarm and c.kind not in ("", "M110", "$I", "$$", "$=", "$H", "$X"):
            return E_ALARM_LOCK
        k = c.kind
        if k == "G1":
            return self._exec_g1(c)
        if k == "G6":
            return self._exec_g6(c)
        if k == "G7":
            return self._exec_g7(c)
        if k in ("G90", "G91"):
            self.absolute = k == "G90"
            return OK
        if k == "G92":
            if self._queue_full():
                return WAIT
            target = (c.words.get("A", self.plan[0]), c.words.get("B", self.plan[1]))
            self._push(Block("G92", self.last, delta=target))
            self.plan = list(target)
            return OK
        if k == "M3":
            self.laser_on = True
            if "S" in c.words:
                self.laser_s = c.words["S"]
            return OK
        if k == "M5":
            self.laser_on = False
            return OK
        if k == "M280":
            return self._exec_pen(c)
        if k in ("M17", "M18"):
            if self._queue_full():
                return WAIT
            self._push(Block(k, self.last))
            self.motors_on = k == "M17"
            return OK
        if k == "$I":
            self._emit(self.banner_text())
            return OK
        if k == "$$":
            for i, v in enumerate(self.settings):
                self._emit(f"${i}={v}")
            return OK
        if k == "$H":
            return self._exec_home()
        if k == "$X":
            self.alarm = 0
            self.plan = list(self.pos)
            return OK
        if k == "$=":
            return self._exec_set(c)
        if k == "$B":
            return self.uart.request(c.value)
        return OK  # empty line, M110

    def _exec_set(self, c: Command) -> int:
        if c.setting not in SETTINGS:
            return E_UNKNOWN_SETTING
        _, lo, hi = SETTINGS[c.setting]
        if not lo <= c.value <= hi or (c.setting == S_PEN_PARK
                                       and 0 < c.value < protocol.SERVO_MIN_US):
            return E_OUT_OF_RANGE
        if self.running or self.queue or self.homing is not None:
            return E_BUSY
        self.settings[c.setting] = c.value
        if c.setting == S_PEN_PARK:  # kept in the EEPROM; the pen parks there at once
            self.machine.pen_park_ee = c.value
            self.machine.pen.setup(self.t, c.value)
        return OK

    def _exec_home(self) -> int:
        if not self.settings[S_HOMING]:
            return E_HOMING_DISABLED
        if self.running or self.queue or self.held:
            return E_BUSY
        if not self.motors_on:
            return E_MOTORS_OFF
        # the position is unknown until homed: the seek counts from 0 (fb_home.c home_cycle)
        self.pos = [0, 0]
        self.plan = [0, 0]
        self.homed = False
        self.homing = Homing(self)
        self.homing.seek()
        return self.homing.result()

