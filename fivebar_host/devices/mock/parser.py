"""The firmware's line grammar as the mock models it: framing and parsing of one line.

A port of firmware/fivebar/fb_proto.c, quirks included: the mock must answer every line
with the code the firmware gives it (the contract suite compares them byte for byte).
``parse_line`` frames a line (checksum field ``*<crc16>/<len>``, line number ``N``, strict
framing once numbered) and parses its command into a ``Command``; executing it is the
firmware model's business (``fivebar_host.devices.mock.firmware``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from fivebar_host import protocol
from fivebar_host.devices.mock.codes import (
    E_BAD_NUMBER,
    E_BAD_WORD,
    E_CHECKSUM,
    E_INVALID_CHAR,
    E_LINE_NUMBER,
    E_MISSING_WORD,
    E_NO_CHECKSUM,
    E_OUT_OF_RANGE,
    E_UNKNOWN_COMMAND,
    E_UNKNOWN_SETTING,
    OK,
    P_MAX_US,
    P_MIN_US,
)
from fivebar_host.protocol import POS_LIMIT, crc16


@dataclass
class Command:
    """One parsed line: command kind (``""`` for an empty line), words, line number."""

    kind: str = ""  # "", G1 G6 G7 G90 G91 G92 M3 M5 M17 M18 M110 M280 $I $$ $H $X $= $B
    words: dict[str, int] = field(default_factory=dict)
    #: G6: the segments after its head, (ΔA, ΔB, P µs) each; one line number each.
    #: G7: all its segments (P 0 where none was given yet: the modal one applies)
    items: list[tuple[int, int, int]] = field(default_factory=list)
    #: G7: the pixel powers (its data, unescaped)
    pixels: bytes = b""
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


_ALLOWED = {"G1": "ABPS", "G6": "ABPS", "G92": "AB", "M3": "S", "M280": "SRD"}
_G_CODES = {1: "G1", 6: "G6", 7: "G7", 90: "G90", 91: "G91", 92: "G92"}
_M_CODES = {3: "M3", 5: "M5", 17: "M17", 18: "M18", 110: "M110", 280: "M280"}


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
    if c == ord("B") and i + 1 < end and s[i + 1] == ord("="):  # $B=<baud>, checked later
        st, v, j = _parse_int(s, i + 2, end)
        if st != OK:
            return st
        if _skip_ws(s, j, end) < end:
            return E_BAD_WORD
        cmd.kind, cmd.value = "$B", v
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
    if cmd.kind == "M280":  # S is a servo pulse here (fb_proto.c check_ranges)
        if "S" in w and not protocol.SERVO_MIN_US <= w["S"] <= protocol.SERVO_MAX_US:
            return E_OUT_OF_RANGE
        if any(k in w and not 0 <= w[k] <= protocol.PEN_MS_MAX for k in "RD"):
            return E_OUT_OF_RANGE
        if "S" not in w:
            return E_MISSING_WORD
    elif "S" in w and not 0 <= w["S"] <= protocol.POWER_MAX:
        return E_OUT_OF_RANGE
    if "P" in w and not P_MIN_US <= w["P"] <= P_MAX_US:
        return E_OUT_OF_RANGE
    if cmd.kind in ("G1", "G6") and "P" not in w:
        return E_MISSING_WORD
    if cmd.kind == "G92" and "A" not in w and "B" not in w:
        return E_MISSING_WORD
    return OK


def _g7_code_end(s: bytes, i: int, end: int) -> int:
    """The index past the command's code when it is G7, else 0 (fb_proto.c g7_code_end):
    a G7's code may end at its data's ``:``."""
    i = _skip_ws(s, i, end)
    if i >= end or _upper(s[i]) != ord("G"):
        return 0
    code, j = 0, i + 1
    while j < end and _is_digit(s[j]) and code < 1000:
        code = code * 10 + s[j] - 0x30
        j += 1
    return j if code == 7 and j > i + 1 and (j >= end or not _is_digit(s[j])) else 0


def _parse_g7(data: bytes, cmd: Command) -> int:
    """A G7's binary data (fb_g7.c proto_g7_parse, docs/protocol.md 6.4) into the command:
    its items (P 0 where the segment carries none: the modal one applies), U and T, its
    pixels; the firmware's error for a malformed or out-of-range one."""
    try:
        g = protocol.read_g7(data)
    except protocol.G7FormatError as e:
        return {"number": E_BAD_NUMBER, "range": E_OUT_OF_RANGE}.get(e.kind, E_BAD_WORD)
    cmd.items = [(da, db, p or 0) for p, da, db in g.items]
    if g.u is not None:
        cmd.words["U"] = g.u
    if g.t is not None:
        cmd.words["T"] = g.t
    cmd.pixels = g.powers
    return OK


def _parse_body(s: bytes, i: int, end: int, cmd: Command) -> int:
    g7 = _g7_code_end(s, i, end)
    if g7:
        cmd.kind = "G7"
        k = _skip_ws(s, g7, end)
        if k >= end or s[k] != ord(":"):
            return E_MISSING_WORD  # no data: a G7 has at least one segment
        return _parse_g7(s[k + 1:end], cmd)
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
    if kind is None or kind == "G7":
        return E_UNKNOWN_COMMAND
    cmd.kind = kind
    st = _parse_words(s, i, end, cmd)
    return st if st != OK else _check_ranges(cmd)


def _parse_words(s: bytes, i: int, end: int, cmd: Command) -> int:
    """The words after the command (each of A B P S R D at most once, as it allows)."""
    allowed = _ALLOWED.get(cmd.kind, "")
    while True:
        i = _skip_ws(s, i, end)
        if i >= end:
            return OK
        # a G6's items start at a sign, or at a second P; a G7's at a sign or a P
        if cmd.kind == "G6" and (s[i] in b"+-" or (_upper(s[i]) == ord("P")
                                                   and "P" in cmd.words)):
            return _g6_items(s, i, end, cmd)
        w = chr(_upper(s[i]))
        if w not in "ABPSRD" or w not in allowed or w in cmd.words:
            return E_BAD_WORD
        st, v, i = _parse_int(s, i + 1, end)
        if st != OK:
            return st
        cmd.words[w] = v


def _item_num(s: bytes, i: int, end: int) -> tuple[int, int, int]:
    """A G6 item number (fb_proto.c item_num): optional sign, digits, ending at the end,
    a blank, a letter or the next item's sign; |value| ≤ POS_LIMIT."""
    neg = False
    if i < end and s[i] in b"+-":
        neg = s[i] == ord("-")
        i += 1
    v = digits = 0
    over = False
    while i < end and _is_digit(s[i]):
        if v > POS_LIMIT:
            over = True
        else:
            v = v * 10 + s[i] - 0x30
        i += 1
        digits += 1
    if not digits or not (i >= end or _is_ws(s[i]) or _is_letter(s[i]) or s[i] in b"+-"):
        return E_BAD_NUMBER, 0, i
    if over or v > POS_LIMIT:
        return E_OUT_OF_RANGE, 0, i
    return OK, -v if neg else v, i


def _g6_item(s: bytes, i: int, end: int, p: int) -> tuple[int, tuple[int, int, int], int]:
    """One G6 item (fb_proto.c g6_item): ``[P<µs>]<±a><±b>``; (status, (ΔA, ΔB, P), index)."""
    i = _skip_ws(s, i, end)
    if i < end and _upper(s[i]) == ord("P"):
        i += 1
        if i < end and s[i] in b"+-":
            return E_BAD_NUMBER, (0, 0, p), i
        st, p, i = _item_num(s, i, end)
        if st != OK:
            return st, (0, 0, p), i
        if not P_MIN_US <= p <= P_MAX_US:
            return E_OUT_OF_RANGE, (0, 0, p), i
        i = _skip_ws(s, i, end)
    d = [0, 0]
    for k in range(2):
        if i >= end or s[i] not in b"+-":
            return E_BAD_WORD, (0, 0, p), i
        st, d[k], i = _item_num(s, i, end)
        if st != OK:
            return st, (0, 0, p), i
    return OK, (d[0], d[1], p), i


def _g6_items(s: bytes, i: int, end: int, cmd: Command) -> int:
    """The items of a G6 line from ``s[i]`` (fb_proto.c g6_items), into ``cmd.items``."""
    p = cmd.words.get("P", 0)
    while (i := _skip_ws(s, i, end)) < end:
        st, item, i = _g6_item(s, i, end, p)
        if st != OK:
            return st
        cmd.items.append(item)
        p = item[2]
    return OK


@dataclass(frozen=True)
class Parsed:
    """The outcome of framing and parsing one line (proto_parse_line)."""

    status: int  # OK or an error code
    last: int  # the line counter afterwards
    accepted: bool  # False for error 8, 9, 10 and a malformed N: the counter is unchanged
    command: Command
    numbered: bool = False  # strict framing afterwards (fb_lines_t.numbered)


def _checksum_field_ok(line: bytes, end: int) -> bool:
    """Whether the checksum field after the last ``*`` (at ``end``) is right (fb_proto.c
    field_ok): ``<crc16>/<len>`` then only spaces or tabs, both decimal without a leading
    zero, the CRC-16 (0..65535) that of the body ``line[:end]`` and the length (0..255)
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
    return (body_len <= protocol.CHECKSUM_BODY_MAX and body_len == end
            and _skip_ws(line, i, len(line)) == len(line) and crc16(line[:end]) == crc)


def _lost_number(line: bytes, i: int, end: int, star: int) -> bool:
    """Whether a line without N is a numbered line that lost its ``N`` and its ``*``
    (fb_proto.c lost_number, docs/protocol.md 5.2 step 5): it starts with a digit, or it
    has no ``*`` and ends with ``<digit>/<digits>`` and blanks.  No valid line does either,
    so the first numbered line, before strict framing begins, is refused too."""
    if i < end and _is_digit(line[i]):
        return True
    if star >= 0:
        return False
    j = len(line)
    while j > 0 and _is_ws(line[j - 1]):
        j -= 1
    last = j
    while j > 0 and _is_digit(line[j - 1]):
        j -= 1
    return j < last and j >= 2 and line[j - 1] == ord("/") and _is_digit(line[j - 2])


def parse_line(last: int, line: bytes, numbered: bool = False) -> Parsed:
    """Frame and parse one received line (without its newline) as the firmware does.

    On ``error:8/9/10`` and a malformed ``N`` the line is not accepted and ``last`` is
    unchanged; every other outcome accepts it: ``last`` becomes N (M110: its N or 0), or
    last+1 for a line without N, and a parse error is replied after that.

    ``numbered`` is the strict-framing state: once a numbered line was accepted, a line
    without N is refused with ``error:10`` (not accepted, not executed) until an
    unnumbered ``M110`` (which ends it) or a reset.  ``Parsed.numbered`` is the state after
    the line.  In either state a line without N that starts with a digit, or has no ``*``
    and ends with ``<digit>/<digits>``, is refused the same way (``_lost_number``).
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
    elif _lost_number(line, i, end, star):
        return Parsed(E_NO_CHECKSUM, last, False, cmd, numbered)
    st = _parse_body(line, i, end, cmd)
    if st != OK:  # a line accepted with its parse error uses one line number
        cmd.items.clear()
    # a G6 uses one line number per segment (its head's and its items'), a G7 one per item
    extra = max(len(cmd.items) - (cmd.kind == "G7"), 0)
    if st == OK and cmd.kind == "M110":
        return Parsed(OK, cmd.n if cmd.n is not None else 0, True, cmd, cmd.n is not None)
    if cmd.n is not None:
        if cmd.n != (last + 1) & 0xFFFFFFFF:
            return Parsed(E_LINE_NUMBER, last, False, cmd, numbered)
        return Parsed(st, (cmd.n + extra) & 0xFFFFFFFF, True, cmd, True)
    if numbered:  # strict framing: a numbered host's line that lost its N and checksum
        return Parsed(E_NO_CHECKSUM, last, False, cmd, numbered)
    return Parsed(st, (last + 1 + extra) & 0xFFFFFFFF, True, cmd, False)

