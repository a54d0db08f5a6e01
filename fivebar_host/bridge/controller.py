"""The GRBL 1.1 controller a sender talks to, in front of a fivebar machine: `Bridge`.

Bytes from the sender (any transport: `fivebar_host.bridge.serve`) go through
`realtime.InputBuffer`: real-time bytes are acted on at once on the transport's thread
(`?` answered from the last machine status, `!`, `~`, Ctrl-X, jog cancel, overrides); lines
wait for the bridge's own thread, which answers each with exactly one `ok` or `error:N`, in
order, as GRBL does, so a sender's character counting against 128 bytes holds.

A G-code line is parsed and run on a copy of the modal state by fivebar's G-code interpreter
(`fivebar_host.gcode`, read GRBL's way: `policy`), and its moves are solved at once
(`compile.incremental.OnlineCompiler.solve`: reach, joint limits, singularity margins,
joint-space segmentation). A refused move raises ALARM:2 with a `[MSG:…]` before anything of
it moves: the machine is stopped (laser off), the look-ahead dropped, every later line gets
`error:9` until `$X`. Accepted moves wait in the look-ahead buffer until `LOOKAHEAD_MOVES`
are there, the sender pauses for `FLUSH_IDLE_S`, the machine stands idle, or something needs
them run (dwell, pause, end of program, a `$` command); then they are planned as one batch
and handed to the machine thread (`machine.MachineDriver`).

`ok` is bounded as GRBL's is: GRBL answers a line once its block is in the 15-block planner,
so a sender's count of `ok`s is at most 15 blocks (plus its 128-byte buffer) ahead of the
motion. The bridge holds the `ok` of a line whose moves would put more than `ok_window`
(default `OK_WINDOW` = 15) accepted moves ahead of those the machine has run to their end
(`MachineDriver.moves_done`); meanwhile it reads no further line, as GRBL's parser waits for
room in its planner. `ok_window=0` answers as soon as a line is in the look-ahead (up to
`LOOKAHEAD_MOVES` ahead: smoother batches, untruthful progress).

A sender that closes the port after complete lines (GRBL's `stream.py`, `cat file >
port`: every fire-and-forget streamer) leaves the bridge to finish what it received, as GRBL
does: the lines run, the laser under the job's own power. A close in the middle of a line
(or after an overlong line) holds the machine with the laser off; so does every close with
`hold_on_disconnect` (the behaviour before issue 35).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fivebar_host.bridge import codes, policy, scanlines, views
from fivebar_host.bridge.codes import GrblAlarmError, GrblError, ascii_text
from fivebar_host.bridge.machine import MachineDriver
from fivebar_host.bridge.realtime import (
    RT_CYCLE_START,
    RT_HOLD,
    RT_JOG_CANCEL,
    RT_RESET,
    RT_STATUS,
    InputBuffer,
    Overrides,
)
from fivebar_host.bridge.system import run_system
from fivebar_host.compile.emit import DEFAULT_MAX_RATE, firmware_rate
from fivebar_host.compile.incremental import (
    LOOKAHEAD_MOVES,
    Batch,
    MoveRefusedError,
    OnlineCompiler,
    Solved,
    dwell_program,
)
from fivebar_host.config import Profile
from fivebar_host.controllers.fivebar.link import Link
from fivebar_host.gcode import Dwell, GcodeError, ModalState, Move, ProgramFlow, Vec, preparse
from fivebar_host.gcode import errors as gcode_errors
from fivebar_host.program import Program

FLUSH_IDLE_S = 0.05
#: GRBL 1.1's planner: `ok` means the block is one of at most 15 not yet run.
OK_WINDOW = 15
UNLOCK_MSG = "[MSG:'$H'|'$X' to unlock]"


@dataclass(frozen=True)
class PenSync:
    """The sender changed the pen state (Z, M3/M5) without moving: bring the pen there."""

    down: bool


Item = Solved | Dwell | PenSync


class Bridge:
    """GRBL 1.1 in front of the machine behind `link` (module doc)."""

    def __init__(self, link: Link, profile: Profile, *, laser: bool, tolerance_mm: float,
                 origin_mm: tuple[float, float] = (0.0, 0.0), mode: str | None = None,
                 log: Callable[[str], None] | None = None, ok_window: int = OK_WINDOW,
                 hold_on_disconnect: bool = False) -> None:
        self.profile = profile
        self.ok_window = ok_window
        self.hold_on_disconnect = hold_on_disconnect
        self.moves_acked = 0  # accepted moves (not jogs) answered or being answered
        self.laser = laser
        self.log = log or (lambda _: None)
        self.settings = views.Settings()
        if laser:
            self.settings.values[32] = 1
        for n in (110, 111, 112):  # max rates: the profile's pen-up travel feed, mm/min
            self.settings.values[n] = round(profile.motion.travel_feed_mm_s * 60.0, 3)
        self.default_settings = dict(self.settings.values)
        self.view = views.StatusView()
        self.ov = Overrides()
        self.input = InputBuffer(self._realtime)
        self.machine = MachineDriver(link, self._on_fault)
        st = self.machine.status
        mot = profile.motors
        self.compiler = OnlineCompiler(profile, self._mode(mode), tolerance_mm, laser)
        self._raise_step_rate(link)
        home_pt = self.compiler.point_of(np.array(mot.home_rad)) or (0.0, 0.0)
        self.home_point: Vec = (home_pt[0], home_pt[1], 0.0)
        self.default_offsets = ((origin_mm[0], origin_mm[1], 0.0),) + ((0.0, 0.0, 0.0),) * 5
        self.modal = ModalState(offsets=self.default_offsets, g28=self.home_point,
                                g30=self.home_point)
        self.th = self.compiler.angles_of_steps(st.a, st.b)
        self._sync_position()
        self.pending: list[Item] = []
        self.flushing = False  # `flush` is planning the look-ahead into batches
        self.plan_th = self.th
        self.plan_pt = self.modal.position[:2]
        #: the last batch ended with a raster scanline: where it ended in the file (the
        #: machine is at its overscan end; `scanlines.Cursor`)
        self.scan_end: tuple[float, float] | None = None
        self.alarm: int | None = None
        self.locked = not st.homed  # position unknown: GRBL's boot alarm lock
        self.check_mode = False
        self.held = False
        self.homing = False
        self._writer: Callable[[bytes], None] | None = None
        self._wlock = threading.Lock()
        self._reset_req = threading.Event()
        self._jog_cancel_req = threading.Event()
        self._stop = threading.Event()
        self._last_line_at = time.monotonic()
        self._speed = (time.monotonic(), self.modal.position[:2], 0.0)
        self.thread = threading.Thread(target=self._loop, name="grbl-bridge", daemon=True)

    def _mode(self, mode: str | None) -> str:
        """The working mode: the option, else the profile's; "auto": the mode at home."""
        from fivebar_host.compile.modes import mode_at

        m = mode or self.profile.kinematics.working_mode
        if m != "auto":
            return m
        fb, mot = self.profile.geometry, self.profile.motors
        th = np.array(mot.home_rad)
        pt = fb.forward_batch(th.reshape(1, 2), self.profile.kinematics.assembly).points[0]
        return mode_at(fb, th, pt, "+-")

    def _raise_step_rate(self, link: Link) -> None:
        """A profile whose joints may step faster than the firmware's boot `$0` (20,000
        steps/s) gets `$0` raised once, as `fivebar plot` does per job (`compile.emit`),
        so its G0 travel is not refused (error:12); the settings outlive a soft reset."""
        need = self.profile.motion.max_joint_rad_s / self.profile.motors.rad_per_step
        if need > DEFAULT_MAX_RATE:
            rate = firmware_rate(need)
            link.command(f"$0={rate}")
            self.compiler.max_rate_steps_s = rate

    # ------------------------------------------------------------------ life cycle
    def start(self) -> None:
        self.machine.start()
        self.thread.start()

    def close(self) -> None:
        self._stop.set()
        self.input.clear()
        if self.thread.is_alive():
            self.thread.join(5.0)
        self.machine.hold()
        time.sleep(0.2)
        self.machine.close()

    def attach(self, writer: Callable[[bytes], None]) -> None:
        """A sender connected: GRBL's banner (and the unlock hint when locked)."""
        with self._wlock:
            self._writer = writer
        self.view.reset()
        self.send("")
        self.send(views.BANNER)
        if self.alarm is not None or self.locked:
            self.send(UNLOCK_MSG)

    def detach(self, writer: Callable[[bytes], None]) -> None:
        """The sender went away: after complete lines the bridge finishes what it received
        (GRBL does); in the middle of a line, or with `hold_on_disconnect`, it holds the
        machine (laser off) and forgets the input (module doc)."""
        with self._wlock:
            if self._writer != writer:  # bound methods compare equal, never identical
                return
            self._writer = None
        clean = self.input.drop_partial()
        if clean and not self.hold_on_disconnect:
            self.log("sender closed the port after complete lines: finishing them, as GRBL "
                     "does")
            return
        self.input.clear()
        if self.grbl_state() not in ("Idle", "Alarm", "Check"):
            self.held = True
            self.machine.hold()
        self.log("sender disconnected" + ("" if clean else " in the middle of a line")
                 + ": machine held, laser off")

    def send(self, text: str) -> None:
        with self._wlock:
            w = self._writer
            if w is not None:
                try:
                    w(text.encode("ascii", "replace") + b"\r\n")
                except OSError:
                    self._writer = None

    # ------------------------------------------------------------------ state
    def grbl_state(self) -> str:
        if self.alarm is not None or self.locked:
            return "Alarm"
        if self.check_mode:
            return "Check"
        if self.homing:
            return "Home"
        st = self.machine.status
        if self.held or st.state == "Hold":
            return "Hold:0"
        if self.machine.jogging:
            return "Jog"
        if (self.pending or self.flushing or self.machine.busy
                or not self.machine.batches.empty()
                or st.state == "Run" or st.queued):
            return "Run"
        return "Idle"

    def _mpos(self) -> Vec:
        st = self.machine.status
        p = self.compiler.point_of(self.compiler.angles_of_steps(st.a, st.b))
        x, y = p if p is not None else (float("nan"), float("nan"))
        return (x, y, self.modal.position[2])

    def status_report(self) -> str:
        mpos = self._mpos()
        t0, p0, v0 = self._speed
        now = time.monotonic()
        if now - t0 > 0.05:
            v0 = float(np.hypot(mpos[0] - p0[0], mpos[1] - p0[1]) / (now - t0) * 60.0)
            self._speed = (now, mpos[:2], v0)
        laser_on = self.machine.status.laser > 0
        bf = (max(0, views.PLANNER_BLOCKS - len(self.pending)),
              max(0, views.RX_BUFFER - self.input.pending_bytes()))
        acc = ("S" if self.modal.spindle == 3 else "C" if self.modal.spindle == 4 else "")
        acc += "".join(c for k, c in ((8, "F"), (7, "M")) if k in self.modal.coolant)
        return self.view.report(self.grbl_state(), mpos, self.modal.work_offset(),
                                self.settings, bf, (v0, self.modal.s if laser_on else 0.0),
                                self.ov.tuple(), acc)

    # ------------------------------------------------------------------ real-time bytes
    def _realtime(self, byte: int) -> None:
        """Acted on at once, on the transport's thread."""
        if byte == RT_STATUS:
            self.send(self.status_report())
        elif byte == RT_RESET:
            self.input.clear()
            self._reset_req.set()
        elif byte == RT_HOLD:
            if self.machine.jogging:
                self._jog_cancel_req.set()
            elif self.alarm is None and not self.locked and not self.check_mode:
                self.held = True
                self.machine.hold()
        elif byte == RT_CYCLE_START:
            if self.held:
                self.held = False
                self.machine.resume()
        elif byte == RT_JOG_CANCEL:
            if self.machine.jogging or any(getattr(i, "jog", False) for i in self.pending):
                self._jog_cancel_req.set()
        else:
            self.ov.apply(byte)

    # ------------------------------------------------------------------ the bridge thread
    def _loop(self) -> None:
        while not self._stop.is_set():
            if self._reset_req.is_set():
                self._soft_reset()
                continue
            if self._jog_cancel_req.is_set():
                self._jog_cancel_req.clear()
                self._stop_motion()
                continue
            n_moves = sum(isinstance(i, Solved) for i in self.pending)
            open_scan = self._open_scan()
            if (n_moves - open_scan >= LOOKAHEAD_MOVES
                    or n_moves >= scanlines.SCAN_LOOKAHEAD):
                if self.machine.batches.qsize() < 1:
                    self.flush()
                else:
                    time.sleep(0.005)
                continue
            got = self.input.take(0.01 if self.pending else 0.1)
            if got is None:
                # a raster scanline still arriving waits for the sender's pause, not for
                # the machine: it is burned once complete (`scanlines`)
                if self.pending and (time.monotonic() - self._last_line_at > FLUSH_IDLE_S
                                     or (self.machine.idle and not open_scan)):
                    self.flush()
                continue
            self._last_line_at = time.monotonic()
            reply = self.handle_line(*got[:2])
            if self._wait_window():
                self.send(reply)

    def _moves_ahead(self) -> int:
        """Accepted moves the machine has not run to their end."""
        return self.moves_acked - self.machine.moves_done

    def _open_scan(self) -> int:
        """Moves at the end of the look-ahead that form a raster scanline the next line may
        continue (`scanlines.open_tail`; 0 without the laser)."""
        return scanlines.open_tail(self.pending) if self.laser and self.pending else 0

    def _wait_window(self) -> bool:
        """Hold the line's `ok` until at most `ok_window` accepted moves are ahead of the
        motion, running the look-ahead when the machine has nothing else (module doc);
        False when a reset, an alarm or the bridge's end came first (no reply then).

        A raster scanline still arriving is not held (it is burned once complete, so the
        window cannot cut it); once a line ends it, the complete scanline is planned and
        queued at once while the machine runs the one before (`scanlines.complete`), and
        the window holds as usual."""
        if not self.ok_window or self._open_scan():
            return True
        while self._moves_ahead() > self.ok_window:
            if self._reset_req.is_set() or self._stop.is_set() or self.alarm is not None:
                return False
            if self.pending and self.machine.batches.empty():
                if not self.machine.busy:
                    self.flush()
                elif self.laser and (k := scanlines.complete(self.pending)):
                    self.flush(k)
            time.sleep(0.005)
        return True

    def handle_line(self, raw: str, overflow: bool) -> str:
        """One line → its reply (`ok` / `error:N`); output it causes is sent before."""
        try:
            if overflow:
                raise GrblError(gcode_errors.LINE_OVERFLOW, "line too long")
            text = preparse(raw)
            if not text:
                return "ok"
            if text.startswith("$"):
                run_system(self, text)
            else:
                self._gcode(text)
        except GcodeError as e:
            self.log(f"{raw.strip()!r}: error:{e.code} {e.message}")
            return f"error:{e.code}"
        except GrblAlarmError as e:
            self.raise_alarm(e.code, e.message)
            return f"error:{codes.GCODE_LOCK}"
        return "ok"

    # ------------------------------------------------------------------ G-code
    def _gcode(self, text: str) -> None:
        if self.alarm is not None or self.locked or self.machine.jogging:
            raise GrblError(codes.GCODE_LOCK, "alarm or jog state")
        state, actions = policy.run(self.modal, policy.parse(text))
        th = self.th
        items: list[Item] = []
        for act in actions:
            if isinstance(act, Move):
                solved = self._solve(act, th)
                if solved is not None:
                    items.append(solved)
                    th = solved.th[-1]
            elif isinstance(act, Dwell):
                items.append(act)
        was_down = self._pen_wanted(self.modal)
        self.modal, self.th = state, th
        if not self.laser and self._pen_wanted(state) != was_down and not items:
            items.append(PenSync(self._pen_wanted(state)))
        if not self.check_mode:
            self.pending += items
            self.moves_acked += sum(isinstance(i, Solved) for i in items)
        for act in actions:
            if isinstance(act, ProgramFlow):
                self._program_flow(act.code)

    def _pen_wanted(self, st: ModalState | Move) -> bool:
        z = st.position[2] if isinstance(st, ModalState) else st.end[2]
        return (st.z_seen and z <= 0.0) or (st.spindle in (3, 4) and st.s > 0)

    def _power(self, s: float) -> int:
        full = self.settings.values[30]
        if s <= self.settings.values[31] or s <= 0:
            return 0
        return int(min(255, round(255 * min(1.0, s / full) * self.ov.spindle / 100)))

    def _solve(self, mv: Move, th: np.ndarray, jog: bool = False) -> Solved | None:
        if mv.rapid:
            feed = self.profile.motion.travel_feed_mm_s * self.ov.rapid / 100
        else:
            feed = min(mv.feed * self.ov.feed / 100, self.settings.feed_cap_mm_min()) / 60.0
        if self.laser:
            draw = mv.spindle in (3, 4) and self._power(mv.s) > 0
        else:
            draw = self._pen_wanted(mv)
        dynamic = mv.spindle == 4 and bool(self.settings.values[32])
        points = mv.points(self.compiler.tolerance_mm / 2)  # arcs: half the budget
        try:
            return self.compiler.solve(th, (mv.start[0], mv.start[1]), points,
                                       rapid=mv.rapid, draw=draw and not jog, feed_mm_s=feed,
                                       power=self._power(mv.s) if self.laser else 0,
                                       dynamic=dynamic, arc=len(points) > 1, jog=jog)
        except MoveRefusedError as e:  # a soft limit, GRBL's alarm 2
            raise GrblAlarmError(codes.ALARM_SOFT_LIMIT, ascii_text(str(e))) from None

    def _program_flow(self, code: int) -> None:
        if code in (2, 30):
            self.flush()
            if not self.laser:
                self.pending.append(PenSync(False))
                self.flush()
        elif code == 0:
            self.flush()
            self.wait_idle()
            self.held = True
            self.machine.hold()

    # ------------------------------------------------------------------ batches
    def flush(self, upto: int | None = None) -> None:
        """Plan the look-ahead buffer (its first `upto` items) into batches and hand them
        to the machine."""
        n = len(self.pending) if upto is None else upto
        items, self.pending = self.pending[:n], self.pending[n:]
        self.flushing = True  # planning: Run, not Idle, until the batches are queued
        try:
            self._flush(items)
        finally:
            self.flushing = False

    def _flush(self, items: list[Item]) -> None:
        chunk: list[Solved] = []
        for item in [*items, None]:
            if isinstance(item, Solved) and (not chunk or chunk[0].jog == item.jog):
                chunk.append(item)
                continue
            self._submit_chunk(chunk)
            chunk = [item] if isinstance(item, Solved) else []
            if isinstance(item, Dwell):
                self.machine.submit(Batch(dwell_program(item.seconds), item.seconds,
                                          (0, 0)))
            elif isinstance(item, PenSync):
                pen = self.compiler.pen_program(item.down)
                if len(pen):
                    self.machine.submit(Batch(pen, 0.0, (0, 0)))

    def _submit_chunk(self, chunk: list[Solved]) -> None:
        if not chunk:
            return
        cur = scanlines.Cursor(self.plan_th, self.plan_pt, self.scan_end)
        batch = scanlines.plan(self.compiler, cur, chunk, self.log)
        self.plan_th, self.plan_pt, self.scan_end = cur.th, cur.pt, cur.scan_end
        self.machine.submit(batch)

    def wait_idle(self, timeout_s: float = 600.0) -> bool:
        """Wait until everything accepted has run (False on reset or timeout)."""
        deadline = time.monotonic() + timeout_s
        time.sleep(0.15)
        while time.monotonic() < deadline:
            if self._reset_req.is_set() or self.alarm is not None:
                return False
            if not self.pending and not self.flushing and self.machine.idle:
                return True
            time.sleep(0.02)
        return False

    # ------------------------------------------------------------------ jogging, homing
    def jog(self, words: str) -> None:
        """`$J=`: a checked move in mm at its own F, planned and sent at once."""
        if self.alarm is not None or self.locked:
            raise GrblError(codes.GCODE_LOCK, "jog in alarm")
        block = policy.parse(words)
        extra_g = set(block.g) - {"units", "distance", "non_modal"}
        if (extra_g or block.m or block.g.get("non_modal", 530) != 530
                or set(block.values) - set("XYZF")):
            raise GrblError(codes.INVALID_JOG_COMMAND, "only G20/G21/G90/G91/G53 X Y Z F")
        if "F" not in block.values:
            raise GrblError(gcode_errors.UNDEFINED_FEED_RATE, "jog without F")
        if not any(a in block.values for a in "XYZ"):
            raise GrblError(gcode_errors.NO_AXIS_WORDS, "jog without axis words")
        block.g["motion"] = 10
        state, actions = policy.run(self.modal._replace(spindle=5), block)
        mv = actions[0]
        assert isinstance(mv, Move)
        try:
            solved = self._solve(mv, self.th, jog=True)
        except GrblAlarmError as e:
            raise GrblError(codes.TRAVEL_EXCEEDED, e.message) from None
        self.modal = self.modal._replace(position=state.position)
        if solved is not None and not self.check_mode:
            self.th = solved.th[-1]
            self.flush()
            self.pending.append(solved)
            self.flush()
            self.machine.jogging = True

    def home(self) -> None:
        """`$H`: the firmware's homing with endstops ($22=1 and the profile's endstops)."""
        if not self.settings.values[22] or not self.profile.motors.endstops:
            raise GrblError(codes.SETTING_DISABLED, "homing needs $22=1 and endstops")
        self.homing = True
        try:
            self.machine.reset()
            self.machine.submit(Batch(Program.text("$H"), 0.0, (0, 0)))
            self.wait_idle(180.0)
        finally:
            self.homing = False
        self.alarm = None
        self.locked = not self.machine.status.homed
        self._resync()

    def unlock(self) -> None:
        """`$X`: clear the alarm; an unknown position is taken to be the profile's homed
        pose (the arms placed there, as `fivebar home` asks without endstops)."""
        if self.alarm is None and not self.locked:
            return
        if self.locked:
            self.machine.submit(Batch(Program.set_position(0, 0), 0.0, (0, 0)))
            self.wait_idle(10.0)
        self.alarm = None
        self.locked = False
        self._resync()
        self.send("[MSG:Caution: Unlocked]")

    # ------------------------------------------------------------------ stops and alarms
    def _sync_position(self) -> None:
        p = self.compiler.point_of(self.th)
        if p is not None:
            self.modal = self.modal._replace(position=(p[0], p[1], self.modal.position[2]))

    def _resync(self) -> None:
        """After a stop: the parser and the planner start from where the machine is."""
        st = self.machine.status
        self.th = self.plan_th = self.compiler.angles_of_steps(st.a, st.b)
        self._sync_position()
        self.plan_pt = self.modal.position[:2]
        self.scan_end = None
        self.compiler.pen_down = False

    def _stop_motion(self) -> None:
        """Stop now (firmware Ctrl-X: queue cleared, laser off, position kept)."""
        self.pending = []
        self.machine.reset()
        self.moves_acked = self.machine.moves_done  # the rest will never run
        self.held = False
        self._resync()

    def request_reset(self) -> None:
        self._reset_req.set()

    def _soft_reset(self) -> None:
        """Ctrl-X: stop, GRBL's modal state to defaults, banner (alarm kept)."""
        self._reset_req.clear()
        self._stop_motion()
        self.modal = self.modal.after_reset()._replace(g92=(0.0, 0.0, 0.0))
        self._resync()
        self.check_mode = False
        self.attach_banner()

    def attach_banner(self) -> None:
        self.view.reset()
        self.send(views.BANNER)
        if self.alarm is not None or self.locked:
            self.send(UNLOCK_MSG)
            return
        for text in self.settings.startup:
            if text:
                self.send(f">{text}:{self.handle_line(text, False)}")

    def raise_alarm(self, code: int, message: str) -> None:
        """ALARM:<code> and why; the machine stops, laser off; `$X` clears."""
        self._stop_motion()
        self.alarm = code
        self.send(f"ALARM:{code}")
        self.send(f"[MSG:{message}]")
        self.log(f"ALARM:{code} {message}")

    def _on_fault(self, message: str, firmware_alarm: int | None) -> None:
        """A machine-side fault (machine thread): GRBL's nearest alarm."""
        code = codes.FIRMWARE_ALARM.get(firmware_alarm or 0, codes.ALARM_ABORT_CYCLE)
        self.pending = []
        self.moves_acked = self.machine.moves_done
        self.alarm = code
        self.send(f"ALARM:{code}")
        self.send(f"[MSG:machine: {message}]")
        self.log(f"machine fault: {message}")
