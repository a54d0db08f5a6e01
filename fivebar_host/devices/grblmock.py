"""``fivebar-grbl://NAME`` — a stock GRBL 1.1 board as a pyserial port, for tests without one.

No GRBL firmware build is available here, so this is a model of GRBL 1.1h's documented
interface (gnea/grbl wiki: interface, commands, settings, laser mode), written for fivebar's
`--controller grbl` path and its tests, not a port of GRBL's code:

- opening the port is a DTR reset: the banner ``Grbl 1.1h ['$' for help]``, the machine
  position restarts at 0 (GRBL keeps no position across a reboot); ``?dtr=0`` models a
  board whose auto-reset is disabled (or a network link): it still prints its banner (as
  after a Ctrl-X) but keeps the position it had when the port was last closed; `$`
  settings and the G54 offset live in "EEPROM" and survive (per board NAME, for the life
  of the process); with ``$22=1`` the board boots in Alarm (``[MSG:'$H'|'$X' to unlock]``);
- a 128-byte receive ring (127 usable bytes, as GRBL's): bytes beyond it are dropped and
  counted in ``Board.overflow`` — the damaged line then gets GRBL's error, so a sender that
  does not count characters is caught;
- one ``ok`` / ``error:N`` per line, in order; a motion line waits unanswered while the
  15-block planner is full (GRBL's ``plan_buffer_line`` blocks there), so the ring fills;
- real-time bytes taken out of the stream at once: ``?`` (``<Idle|MPos:…|FS:…>``, ``WCO:``
  on the first and every tenth report), ``!`` hold, ``~`` resume, Ctrl-X reset (in motion:
  ``ALARM:3``, position lost as GRBL reports it), extended bytes ignored;
- ``$$``, ``$N=v`` (``$20=1`` without ``$22=1`` is ``error:10``), ``$#``, ``$G``, ``$I``,
  ``$X``, ``$H`` (homes at once: position ``-$27`` on every axis, as GRBL after its pull-off
  toward +); G0, G1 (F in units/min, ``error:22`` without F), G4, G10 L2/L20 P1, G20/G21,
  G54, G90/G91, G92, G94, M2/M30, M3/M4/M5 with S, M8/M9; other G/M words ``error:20``;
- laser mode (``$32=1``): the laser is on only during G1 with M3/M4 and S > 0, never during
  G0 or a hold; without laser mode the spindle output follows M3/M4/M5 alone.

**What is recorded.**  Every executed block: its start and end in machine steps (targets
``lround(machine units × $100)`` in float32, as GRBL's), duration, rate and laser output
(``Board.blocks``); `executed_steps` turns them into a step-by-step track along each block's
straight line (GRBL's Bresenham keeps every axis within one step of it).

**Time and simplifications.**  Lazy, no thread: each call advances the board by the wall
time since the last call × ``speed`` (URL ``?speed=20``).  A block runs at its programmed
rate (capped per axis by ``$110``/``$111``; G0 at the caps) for its whole length: GRBL's
acceleration ramps and junction speeds are not modelled, and a hold stops at once rather
than decelerating at ``$120`` — both affect timing only, never the path.
"""

from __future__ import annotations

import re
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
import serial

SCHEME = "fivebar-grbl"
RX_SIZE = 128  # GRBL's serial receive ring; one slot stays empty
PLANNER_BLOCKS = 15  # BLOCK_BUFFER_SIZE 16 on a 328p, one slot empty
LINE_MAX = 80  # LINE_BUFFER_SIZE
BANNER = "Grbl 1.1h ['$' for help]"

#: GRBL 1.1h's documented defaults (config.h / defaults.h, DEFAULTS_GENERIC).
DEFAULTS: dict[int, float] = {
    0: 10, 1: 25, 2: 0, 3: 0, 4: 0, 5: 0, 6: 0, 10: 1, 11: 0.010, 12: 0.002, 13: 0,
    20: 0, 21: 0, 22: 0, 23: 0, 24: 25.0, 25: 500.0, 26: 250, 27: 1.0, 30: 1000, 31: 0,
    32: 0, 100: 250.0, 101: 250.0, 102: 250.0, 110: 500.0, 111: 500.0, 112: 500.0,
    120: 10.0, 121: 10.0, 122: 10.0, 130: 200.0, 131: 200.0, 132: 200.0,
}
_INTEGER = {0, 1, 2, 3, 4, 5, 6, 10, 13, 20, 21, 22, 23, 26, 30, 31, 32}
_WORD = re.compile(r"([A-Z])([-+]?(?:\d+\.?\d*|\.\d+))")


@dataclass
class Block:
    """One executed (or executing) motion block, machine steps."""

    start: tuple[int, ...]
    end: tuple[int, ...]
    duration_s: float
    rate: float  # units/min actually run
    rapid: bool
    laser: float  # output while moving: S/$30 (0 = off)
    spindle: str  # "M3", "M4", "M5"
    done: float = 0.0  # fraction executed
    t_start: float = -1.0


@dataclass
class Board:
    """What survives a reset (EEPROM) and what the tests read (executed blocks)."""

    name: str
    settings: dict[int, float] = field(default_factory=lambda: dict(DEFAULTS))
    g54: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    blocks: list[Block] = field(default_factory=list)
    overflow: int = 0  # bytes dropped on a full receive ring
    received: list[str] = field(default_factory=list)  # every line processed
    kept: list[int] | None = None  # machine steps when the port closed (for ``dtr=0``)


_BOARDS: dict[str, Board] = {}


def board(name: str, defaults: dict[int, float] | None = None) -> Board:
    """The named board (created with GRBL's defaults, or `defaults`, on first use)."""
    if name not in _BOARDS:
        _BOARDS[name] = Board(name, dict(DEFAULTS if defaults is None else defaults))
    return _BOARDS[name]


def forget_boards() -> None:
    """Drop every named board (tests)."""
    _BOARDS.clear()


def executed_steps(blocks: list[Block]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(time s, (E, 2) X/Y steps, laser on) along every executed block, one event per step
    of the axis that moves most: the straight joint-space line rounded to steps."""
    ts: list[np.ndarray] = []
    ps: list[np.ndarray] = []
    ls: list[np.ndarray] = []
    for b in blocks:
        s0 = np.array(b.start[:2], dtype=np.float64)
        d = np.array(b.end[:2], dtype=np.float64) - s0
        n = max(1, round(np.abs(d).max() * b.done))
        f = np.arange(1, n + 1) / n * b.done
        ps.append(np.rint(s0 + f[:, None] * d).astype(np.int64))
        ts.append(b.t_start + f * b.duration_s)
        ls.append(np.full(n, b.laser > 0 and not b.rapid))
    if not ps:
        return np.zeros(0), np.zeros((0, 2), np.int64), np.zeros(0, bool)
    return np.concatenate(ts), np.concatenate(ps), np.concatenate(ls)


class _Modal:
    """The G-code parser state GRBL keeps between lines."""

    def __init__(self) -> None:
        self.motion = 0
        self.absolute = True
        self.inches = False
        self.feed = 0.0
        self.spindle = "M5"
        self.s = 0.0
        self.g92 = [0.0, 0.0, 0.0]


class GrblMock(serial.SerialBase):  # type: ignore[misc]  # pyserial has no type hints
    """The pyserial port (see the module docstring); thread-safe, writes never block."""

    opened: ClassVar[list[GrblMock]] = []
    #: What a GRBL-family sibling (`devices.grblfamily`) says differently.
    scheme: ClassVar[str] = SCHEME
    banner: ClassVar[str] = BANNER
    defaults: ClassVar[dict[int, float]] = DEFAULTS
    build_info: ClassVar[str] = "[VER:1.1h.20190830:]\r\n[OPT:V,15,128]"

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.board = Board("")
        self._cond = threading.Condition()
        self.speed = 1.0
        super().__init__(*args, **kwargs)

    # ----------------------------------------------------------------- pyserial plumbing
    def open(self) -> None:
        """Parse ``fivebar-grbl://NAME?speed=S`` and boot the board (a DTR reset)."""
        url = str(self._port)
        if not url.startswith(self.scheme + "://"):
            raise serial.SerialException(f"{url}: not a {self.scheme}:// URL")
        rest = url[len(self.scheme) + 3:]
        name, _, query = rest.partition("?")
        dtr_reset = True
        for item in filter(None, query.split("&")):
            key, _, value = item.partition("=")
            if key not in ("speed", "dtr"):
                raise serial.SerialException(f"{url}: unknown option {key!r} (speed=, dtr=)")
            if key == "speed":
                self.speed = float(value)
            else:
                dtr_reset = value != "0"
        self.board = board(f"{self.scheme}:{name}" if self.scheme != SCHEME else name,
                           self.defaults) if name else Board("", dict(self.defaults))
        self._boot()
        if not dtr_reset and self.board.kept is not None:
            self._pos = list(self.board.kept)
        self.is_open = True
        GrblMock.opened.append(self)

    def close(self) -> None:
        """Close the port (the board keeps its record and, for ``dtr=0``, its position)."""
        if hasattr(self, "_pos"):
            self.board.kept = list(self._pos)
        self.is_open = False

    def _reconfigure_port(self, force_update: bool = False) -> None:
        """Nothing to configure."""

    def _update_dtr_state(self) -> None:
        """DTR is not modelled beyond the reset on open."""

    def _update_rts_state(self) -> None:
        """RTS is not connected."""

    def _update_break_state(self) -> None:
        """A break does nothing."""

    @property
    def in_waiting(self) -> int:
        """Bytes the board has sent that were not read yet."""
        with self._cond:
            self._advance()
            return len(self._out)

    def read(self, size: int = 1) -> bytes:
        """Up to `size` bytes, waiting up to the port's timeout for the first."""
        deadline = None if self._timeout is None else time.monotonic() + self._timeout
        while True:
            with self._cond:
                self._advance()
                if self._out:
                    data = bytes(self._out[:size])
                    del self._out[:size]
                    return data
            if deadline is not None and time.monotonic() >= deadline:
                return b""
            time.sleep(0.0005)

    def write(self, data: bytes | bytearray | memoryview) -> int:
        """Bytes arrive at the board: real-time bytes act at once, the rest enter the ring."""
        raw = bytes(data)
        with self._cond:
            self._advance()
            for byte in raw:  # GRBL's main loop takes each line as its last byte arrives
                self._receive(byte)
                if byte in (0x0A, 0x0D):
                    self._advance()
        return len(raw)

    def reset_input_buffer(self) -> None:
        """Forget what the board sent."""
        with self._cond:
            self._out.clear()

    def reset_output_buffer(self) -> None:
        """Nothing is buffered on the way out."""

    # ----------------------------------------------------------------- board state
    def _boot(self, alarm: int | None = None) -> None:
        """Power-up or reset: position 0 (unless kept), queue and modal state cleared."""
        self._out = bytearray()
        self._rx = bytearray()
        self._queue: deque[Block] = deque()
        self._modal = _Modal()
        self._pos = [0, 0, 0]
        self._hold = False
        self._t = 0.0
        self._clock = time.monotonic()
        self._reports = 0
        self._state = "Alarm" if alarm is not None or self.board.settings[22] else "Idle"
        if alarm is not None:
            self._send(f"ALARM:{alarm}")
        self._send("")
        self._send(self.banner)
        if self._state == "Alarm":
            self._send("[MSG:'$H'|'$X' to unlock]")

    def _send(self, text: str) -> None:
        self._out += (text + "\r\n").encode()

    def _receive(self, byte: int) -> None:
        """GRBL's serial ISR: real-time bytes, else into the ring (dropped when full)."""
        if byte == 0x3F:
            self._send(self._status())
        elif byte == 0x21:
            if self._queue and self._state in ("Run", "Idle"):
                self._hold, self._state = True, "Hold:0"
        elif byte == 0x7E:
            if self._hold:
                self._hold = False
                self._state = "Run" if self._queue else "Idle"
        elif byte == 0x18:
            self._reset()
        elif byte >= 0x80:
            pass  # extended real-time commands (overrides, door, jog cancel): not modelled
        elif len(self._rx) >= RX_SIZE - 1:
            self.board.overflow += 1
        else:
            self._rx.append(byte)

    def _reset(self) -> None:
        """Ctrl-X: queue and ring cleared, laser off. Stopped (idle or a finished hold) the
        position survives; in motion GRBL raises ALARM:3 (position possibly lost)."""
        moving = bool(self._queue) and not self._hold
        if self._queue and self._queue[0].done > 0:
            self.board.blocks.append(self._queue[0])
        pos = list(self._pos)
        self._boot(alarm=3 if moving else None)
        self._pos = pos

    def _advance(self) -> None:
        """Run motion up to now (virtual time), then the lines the planner can take."""
        now = time.monotonic()
        dt = (now - self._clock) * self.speed
        self._clock = now
        while dt > 0 and self._queue and not self._hold:
            b = self._queue[0]
            if b.t_start < 0:
                b.t_start = self._t
            left = (1.0 - b.done) * b.duration_s
            step = min(dt, left)
            b.done = 1.0 if step >= left else b.done + step / max(b.duration_s, 1e-12)
            self._t += step
            dt -= step
            self._pos = [round(b.start[i] + b.done * (b.end[i] - b.start[i]))
                         for i in range(3)]
            if b.done >= 1.0:
                self._queue.popleft()
                self.board.blocks.append(b)
        if not self._queue and not self._hold and self._state == "Run":
            self._state = "Idle"
        self._lines()

    def _lines(self) -> None:
        """GRBL's main loop: complete lines from the ring, one reply each."""
        while b"\n" in self._rx or b"\r" in self._rx:
            cut = min(i for i in (self._rx.find(b"\n"), self._rx.find(b"\r")) if i >= 0)
            raw = self._rx[:cut].decode("ascii", "replace")
            line = _clean(raw)
            if _is_motion(line) and len(self._queue) >= PLANNER_BLOCKS:
                return  # the planner is full: this line waits (its ok too)
            del self._rx[:cut + 1]
            if not line:
                continue
            self.board.received.append(line)
            if len(line) >= LINE_MAX:  # comments and blanks never reach GRBL's line buffer
                self._send("error:11")
                continue
            reply = self._line(line)
            self._send(reply)

    # ----------------------------------------------------------------- reports
    def _units(self, axis: int) -> float:
        return self._pos[axis] / self.board.settings[100 + axis]

    def _status(self) -> str:
        """``<State|MPos:x,y,z|FS:f,s>`` (+ ``WCO:`` every tenth report) per ``$10``."""
        mpos = [self._units(i) for i in range(3)]
        wco = [self.board.g54[i] + self._modal.g92[i] for i in range(3)]
        mask = int(self.board.settings[10])
        if mask & 1:
            where = "MPos:" + ",".join(f"{v:.3f}" for v in mpos)
        else:
            where = "WPos:" + ",".join(f"{m - w:.3f}" for m, w in zip(mpos, wco, strict=True))
        b = self._queue[0] if self._queue and not self._hold else None
        parts = [self._state, where]
        if mask & 2:
            parts.append(f"Bf:{PLANNER_BLOCKS - len(self._queue)},{RX_SIZE - 1 - len(self._rx)}")
        parts.append(f"FS:{0 if b is None else round(b.rate)},{round(self._modal.s)}")
        if self._reports % 10 == 0:
            parts.append("WCO:" + ",".join(f"{v:.3f}" for v in wco))
        self._reports += 1
        return "<" + "|".join(parts) + ">"

    def _settings_text(self) -> str:
        rows = []
        for n, v in sorted(self.board.settings.items()):
            rows.append(f"${n}={int(v)}" if n in _INTEGER else f"${n}={v:.3f}")
        return "\r\n".join(rows)

    # ----------------------------------------------------------------- commands
    def _line(self, line: str) -> str:
        """One line's reply (output it causes is sent before)."""
        if line.startswith("$"):
            return self._system(line)
        if self._state == "Alarm":
            return "error:9"
        try:
            return self._gcode(line)
        except _GrblError as e:
            return f"error:{e.code}"

    def _system(self, line: str) -> str:
        """`$` commands (GRBL's system.c)."""
        idle = self._state in ("Idle", "Alarm") and not self._queue
        simple: dict[str, Callable[[], str]] = {
            "$$": self._settings_text, "$I": lambda: self.build_info,
            "$G": self._parser_state, "$#": self._offsets, "$N": lambda: "$N0=\r\n$N1="}
        if line in simple:
            if line == "$$" and not idle:
                return "error:8"
            self._send(simple[line]())
            return "ok"
        if line == "$X":
            if self._state == "Alarm":
                self._send("[MSG:Caution: Unlocked]")
                self._state = "Idle"
            return "ok"
        if line == "$H":
            if not self.board.settings[22]:
                return "error:5"
            pull = self.board.settings[27]
            self._pos = [round(-pull * self.board.settings[100 + i]) for i in range(3)]
            self._state = "Idle"
            return "ok"
        m = re.fullmatch(r"\$(\d+)=([-+]?(?:\d+\.?\d*|\.\d+))", line)
        if m is None:
            return "error:3"
        if not idle:
            return "error:8"
        n, v = int(m.group(1)), float(np.float32(m.group(2)))
        if n not in self.defaults:
            return "error:3"
        if v < 0:
            return "error:4"
        if n == 20 and v and not self.board.settings[22]:
            return "error:10"
        self.board.settings[n] = v
        return "ok"

    def _parser_state(self) -> str:
        md = self._modal
        return (f"[GC:G{md.motion} G54 G17 {'G20' if md.inches else 'G21'} "
                f"{'G90' if md.absolute else 'G91'} G94 {md.spindle} M9 T0 F{md.feed:g} "
                f"S{md.s:g}]")

    def _offsets(self) -> str:
        g54 = ",".join(f"{v:.3f}" for v in self.board.g54)
        g92 = ",".join(f"{v:.3f}" for v in self._modal.g92)
        zero = "0.000,0.000,0.000"
        rows = [f"[G54:{g54}]"] + [f"[G{n}:{zero}]" for n in range(55, 60)]
        rows += [f"[G28:{zero}]", f"[G30:{zero}]", f"[G92:{g92}]", "[TLO:0.000]",
                 "[PRB:0.000,0.000,0.000:0]"]
        return "\r\n".join(rows)

    def _gcode(self, line: str) -> str:
        """A G-code line: modal words, then one motion (GRBL's gc_execute_line, reduced)."""
        words = _words(line)
        md = self._modal
        g = [v for k, v in words if k == "G"]
        m = [v for k, v in words if k == "M"]
        val = {k: v for k, v in words if k not in "GMN"}
        for code in g:
            if code in (20.0, 21.0):
                md.inches = code == 20.0
            elif code in (90.0, 91.0):
                md.absolute = code == 90.0
            elif code not in (0.0, 1.0, 4.0, 10.0, 92.0, 54.0, 94.0, 17.0):
                raise _GrblError(20)
        for code in m:
            if code in (3.0, 4.0, 5.0):
                md.spindle = f"M{int(code)}"
            elif code not in (2.0, 30.0, 8.0, 9.0):
                raise _GrblError(20)
        scale = 25.4 if md.inches else 1.0
        if "F" in val:
            md.feed = val["F"] * scale
        if "S" in val:
            md.s = val["S"]
        axes = [(i, val[a] * scale) for i, a in enumerate("XYZ") if a in val]
        if 10.0 in g:
            return self._g10(val, axes)
        if 92.0 in g:
            cur = [self._units(i) for i in range(3)]
            for i, v in axes:
                md.g92[i] = cur[i] - self.board.g54[i] - v
            return "ok"
        if 4.0 in g:
            self._queue.append(Block(tuple(self._end()), tuple(self._end()),
                                     val.get("P", 0.0), 0.0, True, 0.0, md.spindle))
            self._state = "Run"
            return "ok"
        motion = [c for c in g if c in (0.0, 1.0)]
        if motion:
            md.motion = int(motion[-1])
        if axes:
            return self._move(axes)
        return "ok"

    def _g10(self, val: dict[str, float], axes: list[tuple[int, float]]) -> str:
        """G10 L2 P1 (offset) and G10 L20 P1 (current position becomes the values)."""
        if val.get("P", 1.0) not in (0.0, 1.0) or val.get("L") not in (2.0, 20.0):
            raise _GrblError(20)
        for i, v in axes:
            if val["L"] == 2.0:
                self.board.g54[i] = v
            else:
                self.board.g54[i] = self._units(i) - self._modal.g92[i] - v
        return "ok"

    def _end(self) -> list[int]:
        """The planner's position: the end of the last queued block, else the machine's."""
        return list(self._queue[-1].end) if self._queue else list(self._pos)

    def _move(self, axes: list[tuple[int, float]]) -> str:
        """Queue a G0/G1 block: targets in float32 machine units → steps (lround)."""
        md, st = self._modal, self.board.settings
        rapid = md.motion == 0
        if not rapid and md.feed <= 0:
            raise _GrblError(22)
        start = self._end()
        wco = [self.board.g54[i] + md.g92[i] for i in range(3)]
        end = list(start)
        for i, v in axes:
            cur = start[i] / st[100 + i]
            target = np.float32(v) + np.float32(wco[i]) if md.absolute else np.float32(
                cur) + np.float32(v)
            end[i] = round(float(target) * st[100 + i])
            if st[20] and not -st[130 + i] <= end[i] / st[100 + i] <= 0:
                self._boot(alarm=2)
                self._state = "Alarm"
                return "error:15"
        delta = [(end[i] - start[i]) / st[100 + i] for i in range(3)]
        dist = float(np.sqrt(sum(d * d for d in delta)))
        if dist == 0.0:
            return "ok"
        rate = min([st[110 + i] * dist / abs(d) for i, d in enumerate(delta) if d]
                   + ([] if rapid else [md.feed]))
        on = md.spindle != "M5" and md.s > 0 and (not rapid or not st[32])
        laser = min(1.0, md.s / st[30]) if on and st[30] else 0.0
        self._queue.append(Block(tuple(start), tuple(end), dist / rate * 60.0, rate, rapid,
                                 laser, md.spindle))
        if self._state == "Idle":
            self._state = "Run"
        return "ok"


class _GrblError(Exception):
    """A line refused with GRBL's error code."""

    def __init__(self, code: int) -> None:
        super().__init__(code)
        self.code = code


def _clean(raw: str) -> str:
    """GRBL's pre-parse: blanks and comments dropped, upper case."""
    text = re.sub(r"\([^)]*\)", "", raw.split(";", 1)[0])
    return "".join(text.split()).upper()


def _is_motion(line: str) -> bool:
    return not line.startswith("$") and bool(re.search(r"[XYZ]|G4", line))


def _words(line: str) -> list[tuple[str, float]]:
    """Letter/number pairs; GRBL's error:1 (no letter) and error:2 (bad number)."""
    out: list[tuple[str, float]] = []
    pos = 0
    for m in _WORD.finditer(line):
        if m.start() != pos:
            raise _GrblError(1 if not line[pos].isalpha() else 2)
        out.append((m.group(1), float(np.float32(m.group(2)))))
        pos = m.end()
    if pos != len(line):
        raise _GrblError(1 if not line[pos].isalpha() else 2)
    return out


#: pyserial looks up ``Serial`` in a protocol handler module.
Serial = GrblMock
