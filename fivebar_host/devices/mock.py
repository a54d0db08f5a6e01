"""``fivebar-mock://`` — a pyserial port that is a fivebar controller written in Python.

The mock implements docs/protocol.md the way the firmware (firmware/fivebar/fb_main.c,
fb_proto.c, fb_motion.c) does, so host code and tests can run without hardware and without
the AVR toolchain: the boot banner on open (as the Uno's DTR reset sends it), a receive
buffer of the banner's size whose excess bytes are lost (``error:18``), line framing with
line numbers, the checksum field (CRC-16 and length), strict framing and resend requests,
every command and setting, soft limits, homing and the endstop alarm against simulated
switches, the segment queue with its start rule and its blocking (its slots hold the
waiting blocks and the one executing; a line that needs a slot waits, unanswered, until one
frees), exact DDA step timing, hold / resume / reset, the laser safety rules, and status
reports in the firmware's format.  The contract suite (tests/contract/) runs the same tests
against this mock and the real firmware in simavr.

**Time.**  The simulation is lazy and single-threaded: every call (``read``, ``write``,
``in_waiting``, ``ledger`` ...) first advances the device from the last call to the current
clock, handling each event in time order (segment end, endstop alarm, the 20 ms queue
start delay, the laser silence timeout), so no background thread runs.  Motion runs
``speed`` times faster than the firmware would (a ``G1 … P<us>`` segment takes ``P/speed``
µs of wall time; ``speed=0`` executes every started segment at once); the protocol's own
timers (start delay, ``$6`` laser timeout) run in wall time, because the host's timing
(polling ``?`` every ``$6/2`` ms) is in wall time.  Bytes written arrive at the moment of
the ``write`` call; the main loop handles each byte before the next one arrives, as the
firmware does at 115200 baud.

**URL options** (``fivebar-mock://?speed=10&drop=0.01&seed=1``; unknown options raise
``MockURLError``, a ``ValueError`` and ``serial.SerialException``, naming the option):

- ``speed=F`` (10): motion time factor, see above; 0 = instant.
- ``drop=P`` / ``corrupt=P`` (0): per-byte probability that a host→device byte is lost /
  replaced by another printable byte.  Only line bytes (newlines included) are affected;
  real-time bytes are never dropped and corruption never produces one, so the faults are
  what the checksum, line numbers and resend requests must absorb.
- ``seed=N`` (0): seed of the drop/corrupt random generator (reproducible faults).
- ``disconnect_after=N``: once the N-th line has been handled the link breaks: every read,
  write and ``in_waiting`` raises ``serial.SerialException``.  The device keeps running.
- ``reset_after=N``: once the N-th line has been handled the device resets with its RAM
  powered (a watchdog or brown-out reset, docs/protocol.md section 7 "kept across a reset"):
  motion stops where it is, laser off, queue, line counter, modal state and settings restart
  as at power-on, the banner is sent; the position, ``H`` and ``Ln`` done are kept.  The rest
  of that ``write`` is lost.
- ``power_cut_after=N``: once the N-th line has been handled the controller loses power
  and boots again: as ``reset_after``, but nothing is kept (position 0, ``H:0``, ``Ln:0,0``);
  the motors stay where they physically are.
- ``error_on=K`` / ``error_code=C`` (11): the K-th line, if it would be accepted, is
  answered ``error:C`` instead of being executed, exactly as the firmware answers a refused
  line with that code (the counter advances, a running job holds with ``Hold:2``; codes
  8/9/10 refuse the line with a resend request instead).
- ``stall_after=N``: once the N-th line has been handled the device hangs: no reply, no
  status, no motion; bytes are swallowed; output pins (laser) keep their state.  A DTR
  reset (reopening with the same ``machine``) revives it, keeping the position, ``H`` and
  ``Ln`` done it had when it hung.
- ``endstops=A,B``: switch A (B) is pressed while motor A's (B's) physical position is at
  most A (B) steps — the simavr harness's ``-a``/``-b`` semantics; either may be empty.
- ``rx=N`` (128), ``queue=N`` (16), ``line=N`` (80): buffer sizes, reported in the banner.
- ``version=S`` (1.0.0), ``proto=N`` (2): what the banner claims (for "unknown firmware"
  tests).
- ``machine=NAME``: ports opened with the same name drive one physical machine: its
  physical position, ledger and laser log survive a close/reopen, and opening the port is
  a DTR reset of the firmware still running on it (its motion stops where it is; position,
  ``H`` and ``Ln`` done are kept).  The first open powers the controller up;
  ``machine(NAME).power_cut()`` cuts its power, so the next boot is a power-on again.  A
  second open while the first port is open fails as a busy port.

Lines are counted for the fault options as the device takes them from its receive buffer
(every ``\\n``, refused and empty lines included), from 1 after the port was opened; each
fault fires once per port.

**Resets.**  A DTR edge, a reopen of a named machine, ``reset_after`` and a revived stall are
resets with the RAM powered: the firmware's ``.noinit`` record brings back the position,
``H`` and ``Ln`` done; everything else restarts as at power-on.  Only the first open of a
machine, ``power_cut_after`` and ``Machine.power_cut`` are power-ons.

**What was executed** is recorded per block in ``port.ledger`` (line number, start/end
position, steps issued, laser power, fraction completed, why it stopped early), and the
laser output's changes in ``port.machine.laser_log``; ``port.snapshot()`` is the status
report the device would send now.  ``MockSerial.opened`` lists every port opened in this
process, for tests that need the port a command opened internally.

Known differences from the firmware, all about timing only: replies appear at once (the
firmware transmits at 115200 baud, so a burst of ``?`` can coalesce into fewer reports
there), homing travel is not split into chunks, and the firmware's 4 µs start latency is
not modelled.
"""

from __future__ import annotations

import math
import random
import re
import threading
import time
import urllib.parse
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, ClassVar, Final

import serial

from fivebar_host import protocol
from fivebar_host.protocol import EOL, POS_LIMIT, RESEND_CODES, SETTINGS, StatusReport, crc16

SCHEME: Final = "fivebar-mock"

F_CPU: Final = 16_000_000
CYCLES_PER_US: Final = F_CPU // 1_000_000
START_BLOCKS: Final = 4  # config.h CFG_START_BLOCKS
START_DELAY_S: Final = 0.020  # config.h CFG_START_DELAY_MS
P_MIN_US: Final = protocol.P_MIN_US
P_MAX_US: Final = protocol.P_MAX_US

#: Boot values of the $ settings, in order 0..13 (firmware/fivebar/config.h DEF_*).  Names
#: and ranges come from protocol.SETTINGS; the contract suite compares ``$$`` of both devices.
DEFAULT_SETTINGS: Final = (20000, -100000, 100000, -100000, 100000, 1, 2000, 0, 2000, 100,
                           0, 0, 20000, 0)
S_MAX_RATE, S_A_MIN, S_A_MAX, S_B_MIN, S_B_MAX, S_SOFT, S_LASER_TIMEOUT, S_HOMING = range(8)
S_HOMING_RATE, S_PULLOFF, S_HOME_A, S_HOME_B, S_TRAVEL, S_HOMING_DIR = range(8, 14)

# Reply codes (status.h), by name from the shared table.
_CODE = {c.name: c.code for c in protocol.CODES.values()}
OK: Final = 0
E_INVALID_CHAR: Final = _CODE["INVALID_CHAR"]
E_LINE_TOO_LONG: Final = _CODE["LINE_TOO_LONG"]
E_BAD_NUMBER: Final = _CODE["BAD_NUMBER"]
E_UNKNOWN_COMMAND: Final = _CODE["UNKNOWN_COMMAND"]
E_BAD_WORD: Final = _CODE["BAD_WORD"]
E_MISSING_WORD: Final = _CODE["MISSING_WORD"]
E_OUT_OF_RANGE: Final = _CODE["OUT_OF_RANGE"]
E_CHECKSUM: Final = _CODE["CHECKSUM"]
E_LINE_NUMBER: Final = _CODE["LINE_NUMBER"]
E_NO_CHECKSUM: Final = _CODE["NO_CHECKSUM"]
E_SOFT_LIMIT: Final = _CODE["SOFT_LIMIT"]
E_TOO_FAST: Final = _CODE["TOO_FAST"]
E_BUSY: Final = _CODE["BUSY"]
E_ALARM_LOCK: Final = _CODE["ALARM_LOCK"]
E_MOTORS_OFF: Final = _CODE["MOTORS_OFF"]
E_HOMING_DISABLED: Final = _CODE["HOMING_DISABLED"]
E_UNKNOWN_SETTING: Final = _CODE["UNKNOWN_SETTING"]
E_RX_OVERFLOW: Final = _CODE["RX_OVERFLOW"]
A_ENDSTOP: Final = _CODE["ENDSTOP"]
A_HOMING_FAIL: Final = _CODE["HOMING_FAIL"]
A_HOMING_ABORT: Final = _CODE["HOMING_ABORT"]

_WAIT: Final = -1  # a command that needs a queue slot (or homing) and must wait

_RT_STATUS, _RT_HOLD, _RT_RESUME, _RT_RESET = (ord(b) for b in ("?", "!", "~", "\x18"))
_NL, _CR = 0x0A, 0x0D
#: Bytes a corruption may produce: printable, never a real-time byte.
_CORRUPT_BYTES: Final = bytes(c for c in range(0x20, 0x7F) if c not in b"?!~")


class MockURLError(serial.SerialException, ValueError):
    """A ``fivebar-mock://`` URL with an unknown option or a malformed value."""


# --------------------------------------------------------------------------- URL options


@dataclass(frozen=True)
class MockOptions:
    """The options of one ``fivebar-mock://`` URL (see the module docstring)."""

    speed: float = 10.0
    drop: float = 0.0
    corrupt: float = 0.0
    seed: int = 0
    disconnect_after: int | None = None
    reset_after: int | None = None
    error_on: int | None = None
    error_code: int = E_SOFT_LIMIT
    stall_after: int | None = None
    power_cut_after: int | None = None
    endstops: tuple[int | None, int | None] = (None, None)
    rx: int = 128
    queue: int = 16
    line: int = 80
    version: str = "1.0.0"
    proto: int = protocol.PROTOCOL_VERSION
    machine: str | None = None


def _int_option(key: str, value: str, lo: int, hi: int) -> int:
    try:
        v = int(value)
    except ValueError:
        raise MockURLError(f"{SCHEME}: option {key}={value!r} is not an integer") from None
    if not lo <= v <= hi:
        raise MockURLError(f"{SCHEME}: option {key}={v} outside {lo}..{hi}")
    return v


def _float_option(key: str, value: str, lo: float, hi: float) -> float:
    try:
        v = float(value)
    except ValueError:
        raise MockURLError(f"{SCHEME}: option {key}={value!r} is not a number") from None
    if not (math.isfinite(v) and lo <= v <= hi):
        raise MockURLError(f"{SCHEME}: option {key}={value} outside {lo:g}..{hi:g}")
    return v


_KNOWN = ("speed", "drop", "corrupt", "seed", "disconnect_after", "reset_after", "error_on",
          "error_code", "stall_after", "power_cut_after", "endstops", "rx", "queue", "line",
          "version", "proto", "machine")


def parse_mock_url(url: str) -> MockOptions:
    """Options of a ``fivebar-mock://`` URL; MockURLError names a bad or unknown option."""
    parts = urllib.parse.urlsplit(url)
    if parts.scheme.lower() != SCHEME:
        raise MockURLError(f"expected a {SCHEME}:// URL, got {url!r}")
    if parts.netloc or parts.path.strip("/"):
        raise MockURLError(f"{url}: unexpected {parts.netloc + parts.path!r}; options go "
                           f"after '?', e.g. {SCHEME}://?speed=10")
    try:
        pairs = urllib.parse.parse_qsl(parts.query, keep_blank_values=True, strict_parsing=True)
    except ValueError:
        if parts.query:
            raise MockURLError(f"{url}: malformed options {parts.query!r}") from None
        pairs = []
    opts: dict[str, Any] = {}
    for key, value in pairs:
        if key not in _KNOWN:
            raise MockURLError(f"{SCHEME}: unknown option {key!r} (known: {', '.join(_KNOWN)})")
        if key in opts:
            raise MockURLError(f"{SCHEME}: option {key!r} given twice")
        if key == "speed":
            opts[key] = _float_option(key, value, 0.0, 1e9)
        elif key in ("drop", "corrupt"):
            opts[key] = _float_option(key, value, 0.0, 1.0)
        elif key == "seed":
            opts[key] = _int_option(key, value, -(2**63), 2**63)
        elif key in ("disconnect_after", "stall_after"):
            opts[key] = _int_option(key, value, 0, 2**32)
        elif key in ("reset_after", "power_cut_after", "error_on"):
            opts[key] = _int_option(key, value, 1, 2**32)
        elif key == "error_code":
            code = _int_option(key, value, 1, 255)
            if code not in protocol.CODES or protocol.CODES[code].alarm:
                raise MockURLError(f"{SCHEME}: error_code={code} is not an error code of "
                                   f"status.h")
            opts[key] = code
        elif key == "endstops":
            sides = value.split(",")
            if len(sides) != 2:
                raise MockURLError(f"{SCHEME}: endstops must be 'A,B' (either may be empty), "
                                   f"got {value!r}")
            opts[key] = tuple(
                None if not s.strip() else _int_option(key, s.strip(), -POS_LIMIT, POS_LIMIT)
                for s in sides)
        elif key == "rx":
            opts[key] = _int_option(key, value, 8, 65536)
        elif key == "queue":
            opts[key] = _int_option(key, value, 1, 255)
        elif key == "line":
            opts[key] = _int_option(key, value, 8, 255)
        elif key == "version":
            if not re.fullmatch(r"\S+", value):
                raise MockURLError(f"{SCHEME}: version must be one word, got {value!r}")
            opts[key] = value
        elif key == "proto":
            opts[key] = _int_option(key, value, 0, 2**16)
        else:  # machine
            if not value:
                raise MockURLError(f"{SCHEME}: machine needs a name")
            opts[key] = value
    return MockOptions(**opts)


# --------------------------------------------------------------------------- line parser
# A port of firmware/fivebar/fb_proto.c, quirks included: the mock must answer every line
# with the code the firmware gives it.


@dataclass
class Command:
    """One parsed line: command kind (``""`` for an empty line), words, line number."""

    kind: str = ""  # "", G1 G90 G91 G92 M3 M5 M17 M18 M110 $I $$ $H $X $=
    words: dict[str, int] = field(default_factory=dict)
    n: int | None = None
    setting: int = 0
    value: int = 0


def _is_ws(c: int) -> bool:
    return c in (0x20, 0x09)


def _is_digit(c: int) -> bool:
    return 0x30 <= c <= 0x39


def _upper(c: int) -> int:
    return c - 0x20 if 0x61 <= c <= 0x7A else c


def _is_letter(c: int) -> bool:
    return 0x41 <= _upper(c) <= 0x5A


def _skip_ws(s: bytes, i: int, end: int) -> int:
    while i < end and _is_ws(s[i]):
        i += 1
    return i


def _parse_uint(s: bytes, i: int, end: int, maximum: int) -> tuple[int, int, int]:
    """(status, value, index after the number); a number must end at ws, a letter or end."""
    v = digits = 0
    over = False
    while i < end and _is_digit(s[i]):
        d = s[i] - 0x30
        if v > (maximum - d) // 10:
            over = True
        else:
            v = v * 10 + d
        i += 1
        digits += 1
    if not digits or not (i >= end or _is_ws(s[i]) or _is_letter(s[i])):
        return E_BAD_NUMBER, 0, i
    if over:
        return E_OUT_OF_RANGE, 0, i
    return OK, v, i


def _parse_int(s: bytes, i: int, end: int) -> tuple[int, int, int]:
    neg = False
    if i < end and s[i] in b"+-":
        neg = s[i] == ord("-")
        i += 1
    st, v, i = _parse_uint(s, i, end, 2147483648 if neg else 2147483647)
    return st, -v if neg else v, i


_ALLOWED = {"G1": "ABPS", "G92": "AB", "M3": "S"}
_G_CODES = {1: "G1", 90: "G90", 91: "G91", 92: "G92"}
_M_CODES = {3: "M3", 5: "M5", 17: "M17", 18: "M18", 110: "M110"}


def _parse_dollar(s: bytes, i: int, end: int, cmd: Command) -> int:
    if i >= end:
        return E_UNKNOWN_COMMAND
    c = _upper(s[i])
    if _is_digit(c):
        j = i
        while j < end and _is_digit(s[j]):
            j += 1
        if j >= end or s[j] != ord("="):
            return E_MISSING_WORD if _skip_ws(s, j, end) >= end else E_BAD_NUMBER
        n = 0
        for k in range(i, j):
            n = n * 10 + s[k] - 0x30
            if n > 255:
                return E_UNKNOWN_SETTING
        st, v, j = _parse_int(s, j + 1, end)
        if st != OK:
            return st
        if _skip_ws(s, j, end) < end:
            return E_BAD_WORD
        cmd.kind, cmd.setting, cmd.value = "$=", n, v
        return OK
    kinds = {ord("I"): "$I", ord("$"): "$$", ord("H"): "$H", ord("X"): "$X"}
    if c not in kinds:
        return E_UNKNOWN_COMMAND
    cmd.kind = kinds[c]
    return E_BAD_WORD if _skip_ws(s, i + 1, end) < end else OK


def _check_ranges(cmd: Command) -> int:
    w = cmd.words
    for axis in "AB":
        if axis in w and not -POS_LIMIT <= w[axis] <= POS_LIMIT:
            return E_OUT_OF_RANGE
    if "S" in w and not 0 <= w["S"] <= protocol.POWER_MAX:
        return E_OUT_OF_RANGE
    if "P" in w and not P_MIN_US <= w["P"] <= P_MAX_US:
        return E_OUT_OF_RANGE
    if cmd.kind == "G1" and "P" not in w:
        return E_MISSING_WORD
    if cmd.kind == "G92" and "A" not in w and "B" not in w:
        return E_MISSING_WORD
    return OK


def _parse_body(s: bytes, i: int, end: int, cmd: Command) -> int:
    for k in range(i, end):
        if (s[k] < 0x20 or s[k] > 0x7E) and s[k] != 0x09:
            return E_INVALID_CHAR
    semi = s.find(b";", i, end)
    if semi >= 0:
        end = semi
    i = _skip_ws(s, i, end)
    if i >= end:
        return OK
    c = _upper(s[i])
    if c == ord("$"):
        return _parse_dollar(s, i + 1, end, cmd)
    if c not in (ord("G"), ord("M")):
        return E_UNKNOWN_COMMAND
    st, code, i = _parse_uint(s, i + 1, end, 65535)
    if st != OK:
        return E_UNKNOWN_COMMAND if st == E_OUT_OF_RANGE else st
    kind = (_G_CODES if c == ord("G") else _M_CODES).get(code)
    if kind is None:
        return E_UNKNOWN_COMMAND
    cmd.kind = kind
    allowed = _ALLOWED.get(kind, "")
    while True:
        i = _skip_ws(s, i, end)
        if i >= end:
            break
        w = chr(_upper(s[i]))
        if w not in "ABPS" or w not in allowed or w in cmd.words:
            return E_BAD_WORD
        st, v, i = _parse_int(s, i + 1, end)
        if st != OK:
            return st
        cmd.words[w] = v
    return _check_ranges(cmd)


@dataclass(frozen=True)
class Parsed:
    """The outcome of framing and parsing one line (fb_parse_line)."""

    status: int  # OK or an error code
    last: int  # the line counter afterwards
    accepted: bool  # False for error 8, 9, 10 and a malformed N: the counter is unchanged
    command: Command
    numbered: bool = False  # strict framing afterwards (fb_lines_t.numbered)


def _checksum_field_ok(line: bytes, end: int) -> bool:
    """Whether the checksum field after the last ``*`` (at ``end``) is right (fb_proto.c
    field_ok): ``<crc16>/<len>`` then only spaces or tabs, both decimal without a leading
    zero, the CRC-16 (0..65535) that of the body ``line[:end]`` and the length (0..99)
    ``end``, the body's — the length catches every byte the body lost or gained."""
    nums: list[int] = []
    i = end + 1
    for k in range(2):
        start, v = i, 0
        while i < len(line) and _is_digit(line[i]):
            v = v * 10 + line[i] - 0x30
            if v > 0xFFFF:
                return False
            i += 1
        if i == start or (line[start] == 0x30 and i > start + 1):
            return False
        nums.append(v)
        if k == 0:
            if i >= len(line) or line[i] != ord("/"):
                return False
            i += 1
    crc, body_len = nums
    return (body_len <= 99 and body_len == end and _skip_ws(line, i, len(line)) == len(line)
            and crc16(line[:end]) == crc)


def parse_line(last: int, line: bytes, numbered: bool = False) -> Parsed:
    """Frame and parse one received line (without its newline) as the firmware does.

    On ``error:8/9/10`` and a malformed ``N`` the line is not accepted and ``last`` is
    unchanged; every other outcome accepts it: ``last`` becomes N (M110: its N or 0), or
    last+1 for a line without N, and a parse error is replied after that.

    ``numbered`` is the strict-framing state: once a numbered line was accepted, a line
    without N is refused with ``error:10`` (not accepted, not executed) until an
    unnumbered ``M110`` (which ends it) or a reset.  ``Parsed.numbered`` is the state after
    the line.
    """
    cmd = Command()
    end = len(line)
    star = line.rfind(b"*")
    if star >= 0:
        end = star
        if not _checksum_field_ok(line, end):
            return Parsed(E_CHECKSUM, last, False, cmd, numbered)
    i = _skip_ws(line, 0, end)
    if i < end and _upper(line[i]) == ord("N"):
        if star < 0:
            return Parsed(E_NO_CHECKSUM, last, False, cmd, numbered)
        st, n, i = _parse_uint(line, i + 1, end, 0xFFFFFFFF)
        if st != OK:
            return Parsed(E_BAD_NUMBER, last, False, cmd, numbered)
        cmd.n = n
    st = _parse_body(line, i, end, cmd)
    if st == OK and cmd.kind == "M110":
        return Parsed(OK, cmd.n if cmd.n is not None else 0, True, cmd, cmd.n is not None)
    if cmd.n is not None:
        if cmd.n != (last + 1) & 0xFFFFFFFF:
            return Parsed(E_LINE_NUMBER, last, False, cmd, numbered)
        return Parsed(st, cmd.n, True, cmd, True)
    if numbered:  # strict framing: a numbered host's line that lost its N and checksum
        return Parsed(E_NO_CHECKSUM, last, False, cmd, numbered)
    return Parsed(st, (last + 1) & 0xFFFFFFFF, True, cmd, False)


# --------------------------------------------------------------------------- motion


def steps_done(n: int, cycles: int, elapsed: int) -> int:
    """Steps an axis with ``n`` steps over ``cycles`` has made after ``elapsed`` cycles.

    The firmware's DDA puts step k (1..n) at cycle floor((2k-1)·C / 2n) of the segment.
    """
    if n <= 0 or elapsed < 0:
        return 0
    if elapsed >= cycles:
        return n
    x = 2 * n * (elapsed + 1)
    return min(n, ((x - 1) // cycles + 1) // 2)


def step_cycle(n: int, cycles: int, k: int) -> int:
    """Cycle of step k (1..n) of an axis with n steps over ``cycles``."""
    return ((2 * k - 1) * cycles) // (2 * n)


@dataclass
class _Block:
    """A queued or running block: a segment, a homing move or a synchronous command."""

    kind: str  # G1 G92 M17 M18 home-seek home-pulloff
    line: int
    delta: tuple[int, int] = (0, 0)  # signed steps (G92: the new position)
    cycles: tuple[int, int] = (0, 0)  # DDA length per motor, CPU cycles
    duration_us: float = 0.0  # when the block ends, firmware µs
    power: int = 0
    p_us: int = 0  # commanded duration (G1)


@dataclass
class LedgerEntry:
    """One block the device executed or started — what a step-pulse recorder would see.

    ``start``/``end`` are positions in the firmware's coordinates (G92 and homing move
    them without steps), ``steps`` the signed steps issued per motor.  ``fraction`` is the
    share of the block's time executed (1.0 = completed); ``stopped`` says why it ended
    early ("reset" for Ctrl-X, "alarm", "homing-abort", "reboot" for a reset that keeps the
    position, "power-cut") and is None for a completed or a still running block.
    ``boot`` counts firmware boots of the machine (1 = first).
    """

    boot: int
    kind: str  # G1 G92 M17 M18 home-seek home-pulloff home-set
    line: int
    start: tuple[int, int]
    end: tuple[int, int]
    steps: tuple[int, int]
    power: int
    duration_us: int
    fraction: float
    stopped: str | None = None
    started_s: float = 0.0  # clock time of the block start (time.monotonic by default)

    @property
    def complete(self) -> bool:
        """True when the block ran to its end."""
        return self.fraction >= 1.0


@dataclass(frozen=True)
class KeptRecord:
    """The firmware's ``.noinit`` RAM record: what a reset that leaves the RAM powered keeps
    (docs/protocol.md section 7, "kept across a reset")."""

    position: tuple[int, int]  # A, B in firmware steps
    homed: bool  # H
    done_line: int  # Ln done: the last line executed to its end


@dataclass
class Machine:
    """The physical machine under a mock: motor positions, what was executed, the laser."""

    name: str | None
    phys: list[int] = field(default_factory=lambda: [0, 0])
    ledger: list[LedgerEntry] = field(default_factory=list)
    laser_log: list[tuple[float, int]] = field(default_factory=list)  # (clock s, power)
    boots: int = 0
    firmware: MockFirmware | None = None
    port: MockSerial | None = None

    @property
    def laser(self) -> int:
        """The laser output now (0 = off)."""
        return self.laser_log[-1][1] if self.laser_log else 0

    def power_cut(self) -> None:
        """Cut the controller's power: motion stops where it is, laser off, its RAM is lost.

        With a port open the controller boots again at once as at power-on (banner,
        position 0, ``H:0``, ``Ln:0,0``); otherwise the next open powers it up.  The motors
        stay where they physically are.  Nothing happens before the first open."""
        if self.port is not None:
            self.port.power_cut()


_MACHINES: dict[str, Machine] = {}
_MACHINES_LOCK = threading.Lock()


def machine(name: str) -> Machine:
    """The named machine of ``fivebar-mock://?machine=NAME`` (created if new)."""
    with _MACHINES_LOCK:
        return _MACHINES.setdefault(name, Machine(name))


def forget_machines() -> None:
    """Drop every named machine (tests call it to start from a clean state)."""
    with _MACHINES_LOCK:
        _MACHINES.clear()


def _interval(rate: int) -> int:
    """CPU cycles per step at ``rate`` steps/s, rounded up (fb_main.c interval_for)."""
    return (F_CPU + rate - 1) // rate


class MockFirmware:
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
        self.disconnected = False
        self.rebooted = False  # set by a reboot; MockSerial drops the rest of the write
        self._faults_fired: set[str] = set()
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
        self.pos = list(kept.position) if kept is not None else [0, 0]
        # position set by an executed G92 or a completed $H; kept by Ctrl-X and by a reset
        self.homed = kept.homed if kept is not None else False
        self.alarm = 0
        self.stalled = False
        self.laser = 0
        self._log_laser(now)
        self.cur: _Block | None = None
        self.cur_elapsed = 0.0  # firmware µs of the running block executed
        self.cur_stop_us = 0.0  # where it ends: its duration, or its endstop alarm
        self.cur_alarm = False  # it ends in an endstop alarm
        self.running = False
        self.homing: _Homing | None = None
        self.queue: deque[_Block] = deque()
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
        self.held = False
        self.hold_reason = 0
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
        if not self.stalled:
            self.out += (text + EOL).encode("ascii")

    def status_text(self) -> str:
        """The status report line the firmware would send now (fb_main.c status_report)."""
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
                f"|L:{self.laser}|U:{self.underruns}|H:{int(self.homed)}>")

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

    # ----------------------------------------------------------------- positions, laser

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

    def _set_laser(self, power: int) -> None:
        if power != self.laser:
            self.laser = power
            self._log_laser(self.t)

    def _log_laser(self, now: float) -> None:
        log = self.machine.laser_log
        if not log or log[-1][1] != self.laser:
            log.append((now, self.laser))

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

    def _load(self, blk: _Block) -> None:
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
        self._set_laser(blk.power)

    def _plan_endstop_alarm(self, blk: _Block) -> None:
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

    def _sync_entry(self) -> None:
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
        self._sync_entry()
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

    def _load_next(self) -> bool:
        """Segment boundary: run synchronous blocks, load the next segment (fb_motion.c)."""
        while self.queue:
            blk = self.queue.popleft()
            if blk.kind == "G92":
                self._record_instant("G92", blk.line, blk.delta)
                self.pos = list(blk.delta)
                self.homed = True
                self.done_line = blk.line
                continue
            if blk.kind in ("M17", "M18"):
                self._record_instant(blk.kind, blk.line, (self.pos[0], self.pos[1]))
                self.motors_enabled = blk.kind == "M17"
                self.done_line = blk.line
                continue
            self._load(blk)
            return True
        self.running = False
        self.underruns += 1
        self._set_laser(0)
        return False

    def _start(self) -> None:
        if not self.running and self.queue:
            self.running = True
            self._load_next()

    def _stop(self, why: str) -> None:
        """Stop at once: no further step, laser off, the running block dropped (mo_stop)."""
        if self.cur is not None:
            self._retire(why)
        self.running = False
        self._set_laser(0)

    def _hold(self, reason: int) -> None:
        self.held = True
        self.hold_reason = reason
        self._set_laser(0)

    def _error_hold(self) -> None:
        if not self.held and (self.running or self.queue):
            self._hold(2)

    def _raise_alarm(self, code: int) -> None:
        self._stop("alarm")
        self.queue.clear()
        self.held = False
        self.alarm = code
        self.plan = list(self.pos)
        self._emit(f"ALARM:{code}")

    # ----------------------------------------------------------------- time

    def _next_event(self) -> tuple[float, int] | None:
        """(time, kind) of the next thing that happens without the host: 0 = the running
        block reaches its end (or its endstop alarm), 1 = laser silence timeout, 2 = the
        queue's start delay runs out."""
        events: list[tuple[float, int]] = []
        if self.cur is not None and not self.held:
            events.append((self._wall_until(self.cur_stop_us), 0))
        if self.laser and not self.held:
            events.append((self.last_rx + self.settings[S_LASER_TIMEOUT] / 1000 + 1e-6, 1))
        if (self.queue and not self.running and not self.held and not self.alarm
                and self.homing is None):
            events.append((self.first_queued + START_DELAY_S, 2))
        return min(events) if events else None

    def _move_to(self, t: float) -> None:
        """Let the running block progress up to clock time ``t``."""
        if t <= self.t:
            return
        if self.cur is not None and not self.held:
            self.cur_elapsed = min(self.cur_stop_us,
                                   self.cur_elapsed + self._speed_us(t - self.t))
        self.t = t

    def advance(self, now: float) -> None:
        """Run the device up to clock time ``now``, event by event."""
        if self.stalled:
            self.t = max(self.t, now)
            return
        while True:
            ev = self._next_event()
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
            self._hold(1)
        else:
            self._start()

    def _maybe_start(self) -> None:
        if self.held or self.alarm or self.homing is not None or self.running or not self.queue:
            return
        if (len(self.queue) >= START_BLOCKS or len(self.queue) >= self.opt.queue
                or self.t - self.first_queued >= START_DELAY_S):
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
            elif not self.held and not self.alarm:
                self._hold(0)
        elif c == _RT_RESUME:
            if self.held:
                self.held = False
                if self.cur is not None:
                    self._set_laser(self.cur.power)
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
            self.stalled = True

    def check_startup_faults(self) -> None:
        """Faults that fire after zero lines (``stall_after=0``, ``disconnect_after=0``)."""
        if self.opt.stall_after == 0:
            self._faults_fired.add("stall_after")
            self.stalled = True
        if self.opt.disconnect_after == 0:
            self.disconnected = True

    # ----------------------------------------------------------------- commands

    def _try_execute(self) -> bool:
        """Execute the pending line; False while it has to wait (queue full, homing)."""
        assert self.pending is not None
        st = self._execute(self.pending)
        if st == _WAIT:
            return False
        self.pending = None
        self._finish(st)
        return True

    def _execute(self, c: Command) -> int:
        if self.homing is not None:
            return self.homing.result()
        if self.alarm and c.kind not in ("", "M110", "$I", "$$", "$=", "$H", "$X"):
            return E_ALARM_LOCK
        k = c.kind
        if k == "G1":
            return self._exec_g1(c)
        if k in ("G90", "G91"):
            self.absolute = k == "G90"
            return OK
        if k == "G92":
            if self._queue_full():
                return _WAIT
            target = (c.words.get("A", self.plan[0]), c.words.get("B", self.plan[1]))
            self._push(_Block("G92", self.last, delta=target))
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
        if k in ("M17", "M18"):
            if self._queue_full():
                return _WAIT
            self._push(_Block(k, self.last))
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
        return OK  # empty line, M110

    def _queue_full(self) -> bool:
        """The queue's slots hold the waiting blocks and the one executing (fb_motion.c)."""
        return len(self.queue) + (self.cur is not None) >= self.opt.queue

    def _push(self, blk: _Block) -> None:
        if not self.running and not self.queue:
            self.first_queued = self.t
        self.queue.append(blk)

    def _exec_g1(self, c: Command) -> int:
        if self._queue_full():
            return _WAIT
        w = c.words
        t = list(self.plan)
        for i, axis in enumerate("AB"):
            if axis in w:
                t[i] = w[axis] if self.absolute else self.plan[i] + w[axis]
        if any(abs(v) > POS_LIMIT for v in t):
            return E_OUT_OF_RANGE
        s = self.settings
        if s[S_SOFT] and not (s[S_A_MIN] <= t[0] <= s[S_A_MAX]
                              and s[S_B_MIN] <= t[1] <= s[S_B_MAX]):
            return E_SOFT_LIMIT
        if not self.motors_on and t != self.plan:
            return E_MOTORS_OFF
        p = w["P"]
        cycles = p * CYCLES_PER_US
        delta = (t[0] - self.plan[0], t[1] - self.plan[1])
        min_interval = _interval(s[S_MAX_RATE])
        for d in delta:
            if d and cycles // abs(d) < min_interval:
                return E_TOO_FAST
        if "S" in w:
            self.laser_s = w["S"]
        power = self.laser_s if self.laser_on else 0
        self._push(_Block("G1", self.last, delta, (cycles, cycles), float(p), power, p))
        self.plan = t
        return OK

    def _exec_set(self, c: Command) -> int:
        if c.setting not in SETTINGS:
            return E_UNKNOWN_SETTING
        _, lo, hi = SETTINGS[c.setting]
        if not lo <= c.value <= hi:
            return E_OUT_OF_RANGE
        if self.running or self.queue or self.homing is not None:
            return E_BUSY
        self.settings[c.setting] = c.value
        return OK

    def _exec_home(self) -> int:
        if not self.settings[S_HOMING]:
            return E_HOMING_DISABLED
        if self.running or self.queue or self.held:
            return E_BUSY
        if not self.motors_on:
            return E_MOTORS_OFF
        # the position is unknown until homed: the seek counts from 0 (fb_main.c exec_home)
        self.pos = [0, 0]
        self.plan = [0, 0]
        self.homed = False
        self.homing = _Homing(self)
        self.homing.seek()
        return self.homing.result()


class _Homing:
    """``$H`` in progress (fb_main.c exec_home): seek the switches, pull off, set home."""

    def __init__(self, fw: MockFirmware) -> None:
        self.fw = fw
        s = fw.settings
        self.interval = _interval(s[S_HOMING_RATE])
        self.seek_dir = [1 if s[S_HOMING_DIR] & (1 << i) else -1 for i in range(2)]
        self.code: int | None = None  # the reply once homing has ended
        self.phase = ""

    def _move(self, kind: str, steps: tuple[int, int], duration_cycles: int) -> None:
        fw = self.fw
        cycles = (abs(steps[0]) * self.interval, abs(steps[1]) * self.interval)
        fw.running = True
        fw._load(_Block(kind, fw.last, steps, cycles, duration_cycles / CYCLES_PER_US))
        self.phase = kind

    def seek(self) -> None:
        """Both motors toward their switches; each stops on its own (BLK_HOME)."""
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
        return _WAIT if self.code is None else self.code


# --------------------------------------------------------------------------- the port


class MockSerial(serial.SerialBase):
    """A pyserial port whose other end is ``MockFirmware`` (see the module docstring).

    Timeouts behave like pyserial's: ``timeout=None`` blocks until ``size`` bytes came,
    0 returns what is there, a number waits up to that many seconds; writes never block.
    Thread-safe: a reader thread may block in ``read`` while another thread writes.
    """

    #: Every mock port opened in this process, oldest first.
    opened: ClassVar[list[MockSerial]] = []
    is_open: bool  # set by SerialBase

    def __init__(self, *args: Any, clock: Callable[[], float] = time.monotonic,
                 **kwargs: Any) -> None:
        self.options = MockOptions()
        self.machine = Machine(None)
        self.firmware: MockFirmware | None = None
        self._clock = clock
        self._cond = threading.Condition()
        self._rng = random.Random(0)
        self._cancel = False
        self._dtr_last = True
        super().__init__(*args, **kwargs)

    # ----------------------------------------------------------------- open / close

    def open(self) -> None:
        """Parse the URL, power the machine up (banner) and mark the port open."""
        if self.is_open:
            raise serial.SerialException("port already open")
        if self._port is None:
            raise serial.SerialException("port must be configured before it can be used")
        self.options = parse_mock_url(str(self._port))
        self._reconfigure_port()
        name = self.options.machine
        m = machine(name) if name is not None else Machine(None)
        with self._cond:
            now = self._clock()
            if m.port is not None and m.port.is_open:
                raise serial.SerialException(
                    f"could not open port {self._port}: [Errno 16] Device or resource busy "
                    f"(machine {name!r} is open)")
            # Opening resets the Uno through DTR: its RAM stays powered, so the new boot finds
            # the .noinit record of the firmware that ran until now.  A machine without one
            # (first open, or after a power cut) is powered up.
            kept = m.firmware.power_off(now) if m.firmware is not None else None
            self.machine = m
            self._rng = random.Random(self.options.seed)
            self.firmware = MockFirmware(self.options, m, now, kept)
            m.firmware = self.firmware
            m.port = self
            self.firmware.check_startup_faults()
            self._dtr_last = self._dtr_state
            self.is_open = True
        MockSerial.opened.append(self)

    def close(self) -> None:
        """Close the port; the device keeps running (its ledger stays readable)."""
        with self._cond:
            self.is_open = False
            self._cond.notify_all()

    def _reconfigure_port(self, force_update: bool = False) -> None:
        """Nothing to configure; the baud rate is checked like pyserial's loop://."""
        if not isinstance(self._baudrate, int) or not 0 < self._baudrate < 2**32:
            raise ValueError(f"invalid baudrate: {self._baudrate!r}")

    def _update_dtr_state(self) -> None:
        """DTR going active resets the firmware, like the Uno's auto-reset circuit."""
        if self.is_open and self._dtr_state and not self._dtr_last:
            with self._cond:
                fw = self._fw()
                fw.reboot(self._clock())
                fw.rebooted = False
                fw.stalled = False
                self._cond.notify_all()
        self._dtr_last = self._dtr_state

    def power_cut(self) -> None:
        """``Machine.power_cut`` on this port's firmware (see there)."""
        with self._cond:
            fw = self.firmware
            if fw is None:
                return
            if self.is_open:
                fw.reboot(self._clock(), keep=False)
                fw.rebooted = False
            else:
                fw.power_off(self._clock(), "power-cut")
                self.machine.firmware = None
            self._cond.notify_all()

    def _update_rts_state(self) -> None:
        """RTS is not connected."""

    def _update_break_state(self) -> None:
        """A break does nothing to the device."""

    # ----------------------------------------------------------------- I/O

    def _fw(self) -> MockFirmware:
        if not self.is_open or self.firmware is None:
            raise serial.PortNotOpenError()
        return self.firmware

    def _live(self) -> MockFirmware:
        """The firmware advanced to now; SerialException once the link is broken."""
        fw = self._fw()
        fw.advance(self._clock())
        if fw.disconnected:
            raise serial.SerialException(
                f"{SCHEME}: device disconnected (disconnect_after="
                f"{self.options.disconnect_after})")
        return fw

    @property
    def in_waiting(self) -> int:
        """Bytes the device has sent that were not read yet."""
        with self._cond:
            return len(self._live().out)

    @property
    def out_waiting(self) -> int:
        """Always 0: written bytes reach the device at once."""
        self._fw()
        return 0

    def read(self, size: int = 1) -> bytes:
        """Read up to ``size`` bytes, waiting as the timeouts allow (pyserial semantics)."""
        self._fw()
        timeout, gap = self._timeout, self._inter_byte_timeout
        deadline = None if timeout is None else self._clock() + timeout
        got = bytearray()
        last_byte = 0.0
        with self._cond:
            self._cancel = False
            while True:
                fw = self._live()
                take = min(size - len(got), len(fw.out))
                if take:
                    got += fw.out[:take]
                    del fw.out[:take]
                    last_byte = self._clock()
                if len(got) >= size or timeout == 0 or self._cancel or not self.is_open:
                    break
                now = self._clock()
                limit = deadline
                if gap is not None and got:
                    limit = last_byte + gap if limit is None else min(limit, last_byte + gap)
                if limit is not None and now >= limit:
                    break
                wait = 0.05
                ev = fw._next_event()
                if ev is not None:
                    wait = min(wait, max(0.0, ev[0] - now) + 1e-4)
                if limit is not None:
                    wait = min(wait, limit - now)
                self._cond.wait(max(wait, 0.0))
        return bytes(got)

    def write(self, data: bytes | bytearray | memoryview) -> int:
        """Deliver ``data`` to the device byte by byte, with the URL's line faults."""
        raw = bytes(data)
        with self._cond:
            fw = self._live()
            opt = self.options
            now = self._clock()
            fw.rebooted = False
            for c in raw:
                if c not in protocol.REALTIME_BYTES:
                    if opt.drop and self._rng.random() < opt.drop:
                        continue
                    if opt.corrupt and self._rng.random() < opt.corrupt:
                        c = self._rng.choice([b for b in _CORRUPT_BYTES if b != c])
                fw.receive(c, now)
                if fw.rebooted or fw.disconnected:
                    break
            fw.rebooted = False
            self._cond.notify_all()
            if fw.disconnected:
                raise serial.SerialException(
                    f"{SCHEME}: device disconnected (disconnect_after={opt.disconnect_after})")
        return len(raw)

    def flush(self) -> None:
        """Nothing is buffered on the host side."""
        self._fw()

    def reset_input_buffer(self) -> None:
        """Discard what the device sent and was not read yet."""
        with self._cond:
            self._live().out.clear()

    def reset_output_buffer(self) -> None:
        """Nothing waits to be sent: writes reach the device at once."""
        self._fw()

    def cancel_read(self) -> None:
        """Make a blocking ``read`` in another thread return what it has."""
        with self._cond:
            self._cancel = True
            self._cond.notify_all()

    def cancel_write(self) -> None:
        """Writes never block; nothing to cancel."""

    # ----------------------------------------------------------------- inspection

    @property
    def ledger(self) -> list[LedgerEntry]:
        """What the machine executed, block by block (the running block included)."""
        with self._cond:
            fw = self.firmware
            if fw is not None:
                fw.advance(self._clock())
                fw._sync_entry()
            return list(self.machine.ledger)

    def snapshot(self) -> StatusReport:
        """The status report the device would send now (without sending anything)."""
        with self._cond:
            fw = self.firmware
            if fw is None:
                raise serial.PortNotOpenError()
            fw.advance(self._clock())
            msg = protocol.parse_message(fw.status_text())
            assert isinstance(msg, StatusReport)
            return msg


#: pyserial looks up ``Serial`` in a protocol handler module.
Serial = MockSerial
