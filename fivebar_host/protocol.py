"""Wire protocol of the fivebar firmware: encoding and decoding, no I/O.

The contract is docs/protocol.md.  This module mirrors the firmware's reply
codes (firmware/fivebar/status.h; tests/test_protocol_codes.py keeps the two
equal), builds command lines with optional line number and checksum field
(CRC-16 and length), and parses every kind of line the firmware sends: ``ok``,
``error:<code>`` (with ``resend:<n>`` for framing errors), status reports, the
banner, ``ALARM:<code>`` pushes and ``$<n>=<v>`` setting lines.

It is pure so the link, the mock device and the tests share one
implementation of the format.
"""

from __future__ import annotations

import binascii
import re
from dataclasses import dataclass
from typing import Final

from fivebar_host.errors import FivebarError

#: The protocol version this module implements: docs/protocol.md, the banner's ``proto:``.
#: Version 2 replaced the CRC-8 line checksum with a CRC-16 and the body's length
#: (docs/protocol.md 5.1 and 14); version 4 added G7 raster lines (6.4).
PROTOCOL_VERSION: Final = 4

#: The longest body a checksummed line can have: the firmware reads lines of at most 255
#: bytes (the banner's ``line`` limit, 128 bytes for the whole line, is lower), so the
#: length in the checksum field has at most 3 digits.
CHECKSUM_BODY_MAX: Final = 255

#: G7 pixel data (docs/protocol.md 6.4): one byte a power, except the bytes a line cannot
#: carry — newline, CR, the real-time bytes, the checksum's ``*`` — and the escape itself,
#: each sent as PX_ESC, then the byte XOR PX_XOR.
PX_ESC: Final = 0x7D
PX_XOR: Final = 0x40
PX_ESCAPED: Final = frozenset(b"\n\r\x18!*?~}")
#: The G7 pixel period's least and a first change's and a period's largest value, cycles.
PX_T_MIN: Final = 400
PX_T_MAX: Final = 16_000_000
PX_U_MAX: Final = 1_600_000_000
#: The record header a run takes in the firmware's pixel ring (fb_raster.h PX_HEAD).
PX_HEAD: Final = 10

#: The link's rate at every boot, reset and Ctrl-X (docs/protocol.md 1).
BASE_BAUD: Final = 115200
#: The rates `$B=<baud>` accepts: the ones the Uno's 16 MHz makes (U2X, UBRR 16/7/3/1).
BAUD_RATES: Final = (115200, 250000, 500000, 1000000)
#: After a `$B` switch the firmware returns to BASE_BAUD unless a valid line arrives
#: within this many seconds (fb_baud.c BAUD_TRIAL_MS).
BAUD_TRIAL_S: Final = 1.0

#: Real-time bytes: acted on by the firmware at once, never buffered, never
#: answered with ``ok`` and not counted against the receive buffer.
RT_STATUS: Final = b"?"
RT_HOLD: Final = b"!"
RT_RESUME: Final = b"~"
RT_RESET: Final = b"\x18"
REALTIME_BYTES: Final = frozenset(RT_STATUS + RT_HOLD + RT_RESUME + RT_RESET)

#: Reply line terminator sent by the firmware (the host sends ``\n``).
EOL: Final = "\r\n"

#: Ranges enforced by the firmware (firmware/fivebar/config.h).
P_MIN_US: Final = 100
P_MAX_US: Final = 100_000_000
POS_LIMIT: Final = 100_000_000
POWER_MAX: Final = 255
#: Servo pulse range of the pen (M280 S, $14) and the longest M280 move or settle time.
SERVO_MIN_US: Final = 500
SERVO_MAX_US: Final = 2500
PEN_MS_MAX: Final = 10_000


@dataclass(frozen=True)
class Code:
    """One reply code of the firmware: number, status.h name and meaning."""

    code: int
    name: str
    description: str
    alarm: bool = False


def _codes(*items: Code) -> dict[int, Code]:
    return {c.code: c for c in items}


#: Every code of firmware/fivebar/status.h (errors 1-29, alarms 30+).
CODES: Final[dict[int, Code]] = _codes(
    Code(1, "INVALID_CHAR", "byte outside printable ASCII in the line"),
    Code(2, "LINE_TOO_LONG", "line longer than the banner's line: limit"),
    Code(3, "BAD_NUMBER", "word letter not followed by a valid integer"),
    Code(4, "UNKNOWN_COMMAND", "no command, or an unsupported G/M/$ command"),
    Code(5, "BAD_WORD", "word not allowed for the command, or repeated"),
    Code(6, "MISSING_WORD", "a required word is missing"),
    Code(7, "OUT_OF_RANGE", "value outside its documented range"),
    Code(8, "CHECKSUM", "checksum field malformed, or its CRC or length wrong: resend"),
    Code(9, "LINE_NUMBER", "N is not the expected line number: resend"),
    Code(10, "NO_CHECKSUM",
         "line number without checksum, or no number after numbered lines: resend"),
    Code(11, "SOFT_LIMIT", "target outside the soft limits"),
    Code(12, "TOO_FAST", "segment needs a step rate above $0"),
    Code(13, "BUSY", "command needs an idle machine"),
    Code(14, "ALARM_LOCK", "alarm active: clear it with $X or $H"),
    Code(15, "MOTORS_OFF", "motion while the motors are disabled (M18)"),
    Code(16, "HOMING_DISABLED", "$H without endstops ($7=0)"),
    Code(17, "UNKNOWN_SETTING", "no such $ setting"),
    Code(18, "RX_OVERFLOW", "receive buffer overflowed: bytes were lost"),
    Code(19, "NO_PEN", "M280 while no pen servo is set up ($14=0)"),
    Code(30, "ENDSTOP", "endstop hit outside homing", alarm=True),
    Code(31, "HOMING_FAIL", "homing found no switch, or the switch stayed pressed", alarm=True),
    Code(32, "HOMING_ABORT", "homing interrupted by hold or reset", alarm=True),
)

#: Codes after which the host resends from the line number in the reply.
RESEND_CODES: Final = frozenset({8, 9, 10})

#: Hold reasons shown as ``Hold:<reason>`` in status reports.
HOLD_REASONS: Final[dict[int, str]] = {
    0: "host sent !",
    1: "host silent too long while the laser was on or the pen down",
    2: "a line was refused while a job was queued or running",
}

#: The $ settings: number -> (name, minimum, maximum).
SETTINGS: Final[dict[int, tuple[str, int, int]]] = {
    0: ("max_rate_steps_s", 1, 60_000),
    1: ("a_min", -POS_LIMIT, POS_LIMIT),
    2: ("a_max", -POS_LIMIT, POS_LIMIT),
    3: ("b_min", -POS_LIMIT, POS_LIMIT),
    4: ("b_max", -POS_LIMIT, POS_LIMIT),
    5: ("soft_limits", 0, 1),
    6: ("laser_timeout_ms", 100, 60_000),
    7: ("homing_enable", 0, 1),
    8: ("homing_rate_steps_s", 1, 60_000),
    9: ("homing_pulloff", 0, 1_000_000),
    10: ("home_a", -POS_LIMIT, POS_LIMIT),
    11: ("home_b", -POS_LIMIT, POS_LIMIT),
    12: ("homing_travel", 1, 10_000_000),
    13: ("homing_dir_mask", 0, 3),
    14: ("pen_park_us", 0, 2500),
}


class ProtocolError(FivebarError, ValueError):
    """A line does not follow docs/protocol.md (host side or firmware side)."""


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final XOR): the line
    checksum of docs/protocol.md 5.1, 0..65535.

    It replaced CRC-8 in protocol 2 (docs/protocol.md 14): it catches every corruption of
    one byte or of two adjacent bytes; two corrupted bytes apart get through only when the
    CRC happens to match, about once in 65536 instead of once in 256.  A lost or added
    byte is caught by the body's length, which the checksum field carries too
    (checksum_field).  The standard library's `binascii.crc_hqx` is this CRC (it takes the
    initial register value); it runs in C, about 40 times faster than a table-driven loop
    in Python, and the host encodes every job line with it.  The firmware computes the same
    value bit by bit (fb_proto.c); tests/test_line_checksum.py checks both against the
    catalogue's check value 0x29B1 for b"123456789".
    """
    return binascii.crc_hqx(data, 0xFFFF)


def checksum_field(body: bytes) -> bytes:
    """The checksum field that ends a line with this body: ``*<crc16>/<len>``
    (docs/protocol.md 5.1), both numbers decimal without leading zeros.

    The length makes every byte lost from or added to the body a mismatch, which the CRC
    alone would miss about once in 65536.  Raises ProtocolError for a body longer than
    CHECKSUM_BODY_MAX bytes, which the firmware could not hold.
    """
    if len(body) > CHECKSUM_BODY_MAX:
        raise ProtocolError(f"line body of {len(body)} bytes: a checksummed body has at most "
                            f"{CHECKSUM_BODY_MAX}")
    return b"*%d/%d" % (crc16(body), len(body))


def escape_pixels(powers: bytes) -> bytes:
    """G7 pixel data for these powers (docs/protocol.md 6.4): the escape first, so the
    escapes the others add stay single."""
    out = powers.replace(b"}", b"}=")
    for c in b"\n\r\x18!*?~":
        out = out.replace(bytes((c,)), bytes((PX_ESC, c ^ PX_XOR)))
    return out


def unescape_pixels(data: bytes) -> bytes:
    """The powers in G7 pixel data; ProtocolError for a byte that must be escaped or a
    malformed escape (the firmware's error 5)."""
    out = bytearray()
    it = iter(data)
    for c in it:
        if c == PX_ESC:
            nxt = next(it, None)
            if nxt is None or (nxt ^ PX_XOR) not in PX_ESCAPED:
                raise ProtocolError("G7 pixel data: a malformed escape")
            out.append(nxt ^ PX_XOR)
        elif c in PX_ESCAPED:
            raise ProtocolError(f"G7 pixel data: byte {c:#04x} must be escaped")
        else:
            out.append(c)
    return bytes(out)


def escaped_length(powers: bytes) -> int:
    """Bytes the powers take as G7 pixel data."""
    return len(powers) + sum(powers.count(c) for c in PX_ESCAPED)


class G7FormatError(ProtocolError):
    """Malformed G7 data; `kind` is the firmware's reading of it: "escape" (error 5),
    "number" (a cut or too long varint: error 3), "range" (error 7), "form" (error 5)."""

    def __init__(self, message: str, kind: str) -> None:
        super().__init__(message)
        self.kind = kind


@dataclass(frozen=True)
class G7Data:
    """A G7 line's data (docs/protocol.md 6.4): its segments (P µs or None where the segment
    carries none, ΔA, ΔB steps), U and T (cycles; None: not given) and its pixel powers."""

    items: tuple[tuple[int | None, int, int], ...]
    u: int | None
    t: int | None
    powers: bytes


#: The one-byte varints.
_VARINT1 = tuple(bytes((v,)) for v in range(0x80))


def _varint(v: int) -> bytes:
    if 0 <= v < 0x80:
        return _VARINT1[v]
    out = bytearray()
    while True:
        b = v & 0x7F
        v >>= 7
        out.append(b | (0x80 if v else 0))
        if not v:
            return bytes(out)


def write_g7(g: G7Data) -> bytes:
    """The escaped data of a G7 line, after its ``G7:``: the head (segments − 1, whether U
    and T follow), U, T, the P mask, the items (P, then ΔA and ΔB zigzag), the powers."""
    n = len(g.items)
    if not 1 <= n <= 32:
        raise ProtocolError(f"a G7 line has 1..32 segments; got {n}")
    out = bytearray([(n - 1) | (0x20 if g.u is not None else 0) | (0x40 if g.t is not None
                                                                   else 0)])
    for v in (g.u, g.t):
        if v is not None:
            out += _varint(v)
    mask = sum(1 << i for i, (p, _, _) in enumerate(g.items) if p is not None)
    out += mask.to_bytes((n + 7) // 8, "little")
    one = _VARINT1  # (most values are one byte: no call for them)
    for p, da, db in g.items:
        if p is not None:
            out += one[p] if 0 <= p < 0x80 else _varint(p)
        za = 2 * da if da >= 0 else -2 * da - 1  # zigzag
        zb = 2 * db if db >= 0 else -2 * db - 1
        out += one[za] if za < 0x80 else _varint(za)
        out += one[zb] if zb < 0x80 else _varint(zb)
    return escape_pixels(bytes(out) + g.powers)


def read_g7(data: bytes) -> G7Data:
    """The G7 data written by `write_g7`, checked as the firmware checks it (fb_g7.c);
    G7FormatError for a malformed or out-of-range one."""
    try:
        raw = unescape_pixels(data)
    except ProtocolError as e:
        raise G7FormatError(str(e), "escape") from e
    pos = 0

    def byte() -> int:
        nonlocal pos
        if pos >= len(raw):
            raise G7FormatError("G7 data ends early", "number")
        pos += 1
        return raw[pos - 1]

    def varint() -> int:
        x = 0
        for k in range(5):
            b = byte()
            if k == 4 and b > 0x0F:
                raise G7FormatError("a varint past 32 bits", "number")
            x |= (b & 0x7F) << (7 * k)
            if not b & 0x80:
                return x
        raise G7FormatError("a varint of more than 5 bytes", "number")

    if not raw:
        raise G7FormatError("G7 data without a head", "form")
    h = byte()
    if h & 0x80:
        raise G7FormatError("G7 head bit 7 set", "form")
    n = (h & 0x1F) + 1
    u = varint() if h & 0x20 else None
    t = varint() if h & 0x40 else None
    if (u is not None and u > PX_U_MAX) or (t is not None and t > PX_T_MAX):
        raise G7FormatError("G7 U or T out of range", "range")
    if pos + (n + 7) // 8 > len(raw):
        raise G7FormatError("G7 P mask cut", "form")
    mask = int.from_bytes(raw[pos:pos + (n + 7) // 8], "little")
    pos += (n + 7) // 8
    if mask >> n:
        raise G7FormatError("a P bit of a segment the line does not have", "form")
    items = []
    for i in range(n):
        p = varint() if mask >> i & 1 else None
        if p is not None and not P_MIN_US <= p <= P_MAX_US:
            raise G7FormatError(f"P{p} out of range", "range")
        d = []
        for _ in range(2):
            z = varint()
            v = (z >> 1) ^ -(z & 1)
            if abs(v) > POS_LIMIT:
                raise G7FormatError(f"a move of {v} steps", "range")
            d.append(v)
        items.append((p, d[0], d[1]))
    return G7Data(tuple(items), u, t, raw[pos:])


def encode_bytes_line(body: bytes, line_number: int) -> bytes:
    """A numbered line whose body holds bytes (a G7's pixel data): ``N<n> <body>*<crc>/<len>``
    and the newline.  The text part is the caller's; nothing here reads it."""
    raw = b"N%d %s" % (line_number, body)
    return raw + checksum_field(raw) + b"\n"


_FORBIDDEN = re.compile(r"[^\x20-\x7e\t]|[*?!~;]")


def encode_line(body: str, line_number: int | None = None, checksum: bool = False) -> bytes:
    """Encode one command line, ready to write, ending in ``\\n``.

    With ``line_number`` the line becomes ``N<n> <body>*<crc>/<len>`` (a number
    always carries a checksum field, checksum_field); with only ``checksum`` it is
    ``<body>*<crc>/<len>``.  Raises ProtocolError for bodies the firmware would misread
    (real-time bytes, ``*``, ``;``, control characters) and for a checksummed body too long
    for its field.
    """
    if _FORBIDDEN.search(body):
        raise ProtocolError(f"line body {body!r} holds a reserved or non-printable character")
    text = body
    if line_number is not None:
        if not 0 <= line_number <= 0xFFFFFFFF:
            raise ProtocolError(f"line number {line_number} outside 0..4294967295")
        text = f"N{line_number} {body}"
        checksum = True
    raw = text.encode("ascii")
    if checksum:
        raw += checksum_field(raw)
    return raw + b"\n"


@dataclass(frozen=True)
class Ok:
    """``ok``: the line was accepted (queued or done), not necessarily executed."""


@dataclass(frozen=True)
class ErrorReply:
    """``error:<code>`` and, for resend codes, the line number to send next."""

    code: int
    resend: int | None = None

    @property
    def info(self) -> Code:
        """The table entry of the code (KeyError for codes not in status.h)."""
        return CODES[self.code]


@dataclass(frozen=True)
class StatusReport:
    """A ``<...>`` report, the answer to the real-time ``?``."""

    state: str  # Idle, Run, Hold, Home or Alarm
    detail: int | None  # hold reason or alarm code
    a: int
    b: int
    queued: int  # blocks waiting in the queue
    done_line: int  # line number of the last block executed to its end
    accepted_line: int  # line number of the last line accepted
    laser: int  # laser power output now
    underruns: int  # motion stops because the queue ran empty, since reset
    homed: bool = False  # H:1: position set by an executed G92 or a completed $H since power-on
    pen: int | None = None  # P: pen servo pulse now, us (0: no pen); None: firmware without it


@dataclass(frozen=True)
class Banner:
    """The boot banner (also the answer to ``$I``)."""

    version: str
    proto: int
    rx: int  # receive buffer bytes: the character-counting budget
    queue: int  # segment queue blocks
    line_max: int  # longest accepted line without its newline
    #: "servo" for the servo build (`make SERVO=1`: a joint's steps are pulse ticks of
    #: 0.5 µs, docs/protocol.md 6.3), else "stepper"
    joints: str = "stepper"


@dataclass(frozen=True)
class AlarmPush:
    """``ALARM:<code>``: pushed once when an alarm is raised."""

    code: int


@dataclass(frozen=True)
class SettingLine:
    """``$<n>=<value>``: one line of the ``$$`` listing."""

    number: int
    value: int


Message = Ok | ErrorReply | StatusReport | Banner | AlarmPush | SettingLine

_ERROR = re.compile(r"error:(\d+)(?: resend:(\d+))?")
_STATUS = re.compile(
    r"<(Idle|Run|Hold|Home|Alarm)(?::(\d+))?\|A:(-?\d+),B:(-?\d+)\|Q:(\d+)"
    r"\|Ln:(\d+),(\d+)\|L:(\d+)\|U:(\d+)\|H:([01])(?:\|P:(\d+))?>"
)
_BANNER = re.compile(r"fivebar (\S+) proto:(\d+) rx:(\d+) queue:(\d+) line:(\d+)"
                     r"(?: joints:(servo))?")
_BANNER_AT_END = re.compile(_BANNER.pattern + r"\Z")
_ALARM = re.compile(r"ALARM:(\d+)")
_SETTING = re.compile(r"\$(\d+)=(-?\d+)")


def parse_message(line: str) -> Message:
    """Classify and decode one line received from the firmware.

    Trailing ``\\r\\n`` is ignored.  Raises ProtocolError for anything else,
    naming the line, so a corrupted reply is never taken for another.
    """
    text = line.rstrip("\r\n")
    if text == "ok":
        return Ok()
    if m := _ERROR.fullmatch(text):
        code = int(m.group(1))
        resend = int(m.group(2)) if m.group(2) is not None else None
        if (resend is not None) != (code in RESEND_CODES):
            raise ProtocolError(f"error reply {text!r}: resend number does not match the code")
        return ErrorReply(code, resend)
    if m := _STATUS.fullmatch(text):
        state, detail = m.group(1), m.group(2)
        if (detail is not None) != (state in ("Hold", "Alarm")):
            raise ProtocolError(f"status report {text!r}: state detail mismatch")
        return StatusReport(
            state=state,
            detail=int(detail) if detail is not None else None,
            a=int(m.group(3)),
            b=int(m.group(4)),
            queued=int(m.group(5)),
            done_line=int(m.group(6)),
            accepted_line=int(m.group(7)),
            laser=int(m.group(8)),
            underruns=int(m.group(9)),
            homed=m.group(10) == "1",
            pen=int(m.group(11)) if m.group(11) is not None else None,
        )
    if m := _BANNER.fullmatch(text):
        return _banner(m)
    if m := _ALARM.fullmatch(text):
        return AlarmPush(int(m.group(1)))
    if m := _SETTING.fullmatch(text):
        return SettingLine(int(m.group(1)), int(m.group(2)))
    raise ProtocolError(f"unrecognised line from the firmware: {text!r}")


def trailing_banner(line: str) -> Banner | None:
    """The banner a line from the firmware ends with, or None.

    A reset while the firmware is transmitting cuts the line on the wire, and the banner
    the restarted firmware sends is appended to the cut piece: ``okfivebar 1.0.0 proto:2
    ...`` arrives as one line.  Its end is the restart; the piece before it is lost.
    """
    m = _BANNER_AT_END.search(line.rstrip("\r\n"))
    if m is None:
        return None
    return _banner(m)


def _banner(m: re.Match[str]) -> Banner:
    """The Banner of a `_BANNER` match."""
    return Banner(m.group(1), int(m.group(2)), int(m.group(3)), int(m.group(4)),
                  int(m.group(5)), m.group(6) or "stepper")


def is_reply(message: Message) -> bool:
    """True for the messages that answer a line (``ok`` / ``error``)."""
    return isinstance(message, Ok | ErrorReply)
